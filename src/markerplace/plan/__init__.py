"""Planning: discretize -> observe -> similarity -> score -> place (the OMP pipeline)."""
