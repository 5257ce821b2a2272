"""RGB-D in, mesh out: TSDF fusion of posed RGB-D frames, and simulated scans of the built-in scenes.

* :mod:`.frames`: the markerplace and TUM RGB-D frame layouts (reading, writing, validation);
* :mod:`.fuse`: TSDF fusion and marching cubes into a vertex-coloured mesh;
* :mod:`.simulate`: a scanning walk through a built-in scene with a depth-sensor noise model;
* :mod:`.cli`: the ``markerplace fuse`` command and ``scene export --as-scan``.
"""
