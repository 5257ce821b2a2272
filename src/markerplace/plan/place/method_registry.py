"""The registry of placement methods (``--method``, ``--methods``), apart from the methods
themselves so that the place stage's settings can list its names without importing them.
The methods register in :mod:`markerplace.plan.place.methods`.

Each method's own settings (its frozen ``Config``) live in
:attr:`markerplace.plan.place.config.PlacementConfig.methods`: a frozen dataclass with one field
per registered method (:func:`method_settings`), so that the settings machinery
(:mod:`markerplace.settings`: flags, bounds, ``--config`` files, ``config.json``, cache keys)
sees ``placement.methods.<method>.<key>`` like any other setting.
"""

from __future__ import annotations

from dataclasses import field, make_dataclass

from markerplace.registry import Registry

__all__ = ["PLACEMENT_METHODS", "method_settings", "settings_name"]

PLACEMENT_METHODS = Registry("placement method", "--method")
"""Every placement method by name, in registration order (``--method``, ``--methods``)."""

_CLASSES: dict[tuple, type] = {}


def settings_name(method: str) -> str:
    """The field of ``PlacementConfig.methods`` (and the ``[placement.methods.NAME]`` table of a
    ``--config`` file) that holds the settings of ``method``: its name with ``-`` as ``_``
    (``expected-recall`` -> ``expected_recall``)."""
    return method.replace("-", "_")


def method_settings():
    """The default settings of every registered method: an instance of a frozen dataclass with
    one field per method (:func:`settings_name`), each the method's ``default_conf``.

    The dataclass is built from the registry as it is now (one class per set of registered
    methods, reused), so a method registered later (a plugin, a test's toy) gets its field in
    every config made after it.

    Raises:
        ValueError: a method name that makes no Python identifier (a programming error).
    """
    key = tuple((name, cls, cls.default_conf) for name, cls in PLACEMENT_METHODS.items())
    cls = _CLASSES.get(key)
    if cls is None:
        specs = []
        for name, method in PLACEMENT_METHODS.items():
            attr = settings_name(name)
            if not attr.isidentifier():
                raise ValueError(f"placement method {name!r}: its name must make a Python identifier with - as _")
            specs.append((attr, type(method.default_conf), field(default=method.default_conf)))
        cls = make_dataclass("MethodSettings", specs, frozen=True)
        cls.__doc__ = "The own settings of each registered placement method, by method (- as _)."
        cls.__module__ = __name__
        _CLASSES[key] = cls
    return cls()
