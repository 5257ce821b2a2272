"""The registry of placement methods (``--method``, ``--methods``), apart from the methods
themselves so that the place stage's settings can list its names without importing them.
The methods register in :mod:`markerplace.plan.place.methods`."""

from __future__ import annotations

from markerplace.registry import Registry

__all__ = ["PLACEMENT_METHODS"]

PLACEMENT_METHODS = Registry("placement method", "--method")
"""Every placement method by name, in registration order (``--method``, ``--methods``)."""
