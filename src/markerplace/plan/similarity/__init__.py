"""Look-alike stage: how many points of the model each SIFT point could be mistaken for."""
