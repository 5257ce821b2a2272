"""The testbed on real photographs (``markerplace evaluate --frames DIR``).

* :mod:`.split`: the fixed block split of a sequence into map and query frames;
* :mod:`.images`: per-frame work on the executor: the real frame with a placement's tags
  composited in (or a render of the fused surface at the frame's pose), SIFT lifted by the
  frame's depth, the tags the real detector finds;
* :mod:`.localize`: each placement's map database and the localization of the query frames;
* :mod:`.report`: the recall tables, the paired intervals and the simulation gap table.

The chain itself is :mod:`markerplace.pipelines.evaluate_frames`.
"""
