"""Discretize stage: feasible camera poses on an eye-level plane and candidate tag spots on walls."""
