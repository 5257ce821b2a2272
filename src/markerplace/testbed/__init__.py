"""The simulation testbed: test poses, map databases per placement, localization, recall."""
