"""Known-tag maps for localization systems: WPILib / PhotonVision, apriltag_ros (ROS 1 and ROS 2),
TagSLAM; one module per format, each a class registered in
:data:`markerplace.report.tagmaps.format.TAG_MAP_FORMATS`, written by
:func:`markerplace.report.tagmaps.write.write_tag_maps`.

Every file holds the placed tags' poses in one frame, metres:

* the **model frame** (default): markerplace's world, z up, in the user's coordinates (the file's
  coordinates rotated to z up and scaled to metres; the loader's recentring is undone, see
  :mod:`markerplace.scene.worldframe`);
* the **file axes** (``*_yup.*`` for a y-up file such as any glTF): the same poses with the
  loader's up-axis rotation undone, ``p_file_axes = R^T p_model`` with ``R`` the loader's
  ``world_from_file`` rotation (:func:`markerplace.scene.loader.up_rotation`); still metres.

Each format has its own tag frame; docs/tag_maps.md has the pictures in words. In short, with
markerplace's marker frame M (origin at the tag centre, z out of the wall towards viewers, x to
a facing viewer's right, y up):

* WPILib / PhotonVision ``AprilTagFieldLayout`` JSON: tag frame W with x out of the visible
  face, y to a facing viewer's right, z up: ``world_from_W = world_from_marker @ MARKER_FROM_WPILIB``.
* apriltag_ros tag bundle YAML: its tag frame is M (object corners (+-s/2, +-s/2, 0)
  counter-clockwise from the bottom-left, z out of the tag): the layout pose is ``world_from_marker``,
  the bundle frame is the model frame.
* TagSLAM ``bodies`` YAML: its tag frame is M too (object corners (+-s/2, +-s/2, 0) from the
  bottom-left); rotations are rotation vectors (axis x angle, radians).
* ROS 2 (the ``apriltag_ros`` node of christianrauch/apriltag_ros, the AprilTag node of ROS 2
  Humble/Jazzy): a parameter file (``tag.ids``/``frames``/``sizes``, family ``36h11``, pose
  estimation ``pnp``) and a YAML launch file of ``tf2_ros static_transform_publisher`` nodes,
  ``map`` -> ``map_tag36h11_<id>`` per tag. The node's tag frame is M (its ``pnp`` object points
  are (-s/2, -s/2, 0), (s/2, -s/2, 0), (s/2, s/2, 0), (-s/2, s/2, 0) for the detector's corners
  BL, BR, TR, TL), and it publishes ``camera optical frame -> tag36h11_<id>``, so
  ``map_from_camera = map_from_(map_tag36h11_<id>) @ inverse(camera_from_(tag36h11_<id>))``: the
  two tag frames are one physical frame under two names (a tf2 frame has one parent).

Numbers are written with Python's shortest round-trip repr (never ``-0.0``:
:func:`markerplace.runtime.atomic_io.clean_float` without rounding), so reading a file back gives the
poses to the last bit of the quaternion / rotation-vector conversion (well under 1e-9).
"""
