"""Imaging: one engine renders a pose, extracts features, lifts them to 3D and tests which
markers are in view; one container holds the features of many images on disk."""
