"""Evaluation reporting: recall tables, paired intervals and the report page, from stored predictions."""
