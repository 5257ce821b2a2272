"""Planning at a real RGB-D sequence's own camera poses from its own images (``plan --frames``).

One module per job: :mod:`.poses` (which frames, their intrinsics and pose fields),
:mod:`.surface` (the surface fused from the frames, or the user's mesh), :mod:`.candidates`
(tag spots on that surface), :mod:`.layout` (floor, top-down grid, the
:class:`~markerplace.plan.discretize.artifact.Discretization`) and :mod:`.observe` (SIFT and
tag visibility from the real images). The pipeline is
:func:`markerplace.pipelines.plan_frames.prepare_frames`.
"""
