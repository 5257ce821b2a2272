"""Whole commands as short chains of named stages: plan, evaluate, check."""
