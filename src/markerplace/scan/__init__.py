"""RGB-D in, mesh out: TSDF fusion of posed RGB-D frames, and simulated scans of the built-in scenes.

* :mod:`.frameset`: frame-set types, pose checks, ``intrinsics.json`` (shared by the layouts);
* :mod:`.frames`: the markerplace frame layout (reading, writing) and ``open_frameset`` for every layout;
* :mod:`.tum`: the TUM RGB-D layout (reading, timestamp association);
* :mod:`.sevenscenes`, :mod:`.nerfstudio`, :mod:`.stray`: the 7-Scenes, nerfstudio ``transforms.json``
  and Stray Scanner layouts;
* :mod:`.images`: a frame's images as fusion wants them (undistorted colour, depth at its size);
* :mod:`.up`: the up axis (``--up``, estimates from the cameras and the mesh, the rotation to +z);
* :mod:`.fuse`: TSDF fusion and marching cubes into a vertex-coloured mesh;
* :mod:`.walk`: the scanning walk through a built-in scene (positions, doorways, poses);
* :mod:`.depth_noise`: the depth-sensor noise model (Kinect-like: noise, quantization, dropouts);
* :mod:`.simulate`: the frame simulator and the whole simulated scan (walk, frames, fusion).

The ``markerplace fuse`` command and ``scene export --as-scan`` live in :mod:`markerplace.cli.scan`.
"""
