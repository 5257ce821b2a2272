"""The placement-method registry stands apart from the methods (the place stage's settings list
its names without importing them); importing the methods fills it, in the documented order."""

from __future__ import annotations

import pytest

from markerplace.errors import UserError
from markerplace.plan.place import methods
from markerplace.plan.place.method_registry import PLACEMENT_METHODS


def test_the_methods_register_into_the_one_registry_in_order():
    assert methods.PLACEMENT_METHODS is PLACEMENT_METHODS
    assert PLACEMENT_METHODS.names() == ("omp", "random", "uniform", "human", "expected-recall")
    assert all(issubclass(cls, methods.PlacementMethod) for cls in PLACEMENT_METHODS.values())
    with pytest.raises(UserError, match=r"^--method 'greedy' is not known: use one of omp, random"):
        PLACEMENT_METHODS.lookup("greedy")
