"""Running stages: cached artifacts and the executors that spread per-image work."""
