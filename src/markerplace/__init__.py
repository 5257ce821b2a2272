"""markerplace: plan fiducial marker (AprilTag) placement for visual localization (OMP)."""

__version__ = "0.1.0"
