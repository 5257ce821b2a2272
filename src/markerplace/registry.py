"""Registries: interchangeable parts chosen by name (glue-factory style).

Marker models (:data:`markerplace.plan.score.marker_models.MARKER_MODELS`), placement methods
(:data:`markerplace.plan.place.methods.PLACEMENT_METHODS`) and localizers
(:data:`markerplace.localization.localizer.LOCALIZERS`) are classes kept in a :class:`Registry`,
a dict from name to class. Everything that lists choices (CLI ``choices=`` and help, validation
messages, evaluation, report tables) reads the registry, so adding a part means writing its
class next to the others with ``@REGISTRY.register``, and nothing else.

A registered class has

* ``name``: the string users type (``--method omp``); unique within its registry;
* ``summary``: a few words for help texts (``"the paper's greedy"``);
* ``Config``: a frozen dataclass of the part's own settings, each with a documented default,
  and ``default_conf = Config()``. Instances are built with ``cls(**overrides)`` (see each base
  class); unknown setting names are a :class:`TypeError` from ``dataclasses.replace``.

Registration order is the order of every listing (help, tables).
"""

from __future__ import annotations

import dataclasses

from markerplace.errors import UserError


class Registry(dict):
    """Name -> class for one kind of part, in registration order.

    Attributes:
        kind: what the parts are, for messages (``"placement method"``).
        option: the command-line option that chooses one (``"--method"``), for messages.
        base: the base class every part subclasses (its contract), or None; with a base, a
            part's ``default_conf`` must also be an instance of the base's ``default_conf``'s
            class (the settings the base promises).
    """

    def __init__(self, kind: str, option: str, base: type | None = None):
        super().__init__()
        self.kind = kind
        self.option = option
        self.base = base

    def register(self, cls: type) -> type:
        """Class decorator: add ``cls`` under ``cls.name``.

        Raises:
            ValueError: no ``name``/``summary``, a name already taken, or a ``default_conf`` that
                is not a frozen dataclass instance (programming errors, not user errors).
        """
        name = getattr(cls, "name", None)
        if not isinstance(name, str) or not name or "," in name or name != name.strip():
            raise ValueError(f"{cls.__name__}: a registered {self.kind} needs a non-empty name without commas")
        if name in self:
            raise ValueError(f"{self.kind} {name!r} is registered twice ({self[name].__name__}, {cls.__name__})")
        if not isinstance(getattr(cls, "summary", None), str):
            raise ValueError(f"{cls.__name__}: a registered {self.kind} needs a one-line summary")
        conf = getattr(cls, "default_conf", None)
        if not (dataclasses.is_dataclass(conf) and not isinstance(conf, type)
                and type(conf).__dataclass_params__.frozen):
            raise ValueError(f"{cls.__name__}: default_conf must be a frozen dataclass instance")
        if self.base is not None and not (isinstance(cls, type) and issubclass(cls, self.base)
                                          and isinstance(conf, type(self.base.default_conf))):
            raise ValueError(f"{cls.__name__}: a registered {self.kind} subclasses {self.base.__name__} and its "
                             f"Config subclasses {type(self.base.default_conf).__name__}")
        self[name] = cls
        return cls

    def lookup(self, name: str) -> type:
        """The class registered as ``name``.

        Raises:
            UserError: one line naming the option and every known name.
        """
        try:
            return self[name]
        except (KeyError, TypeError):
            raise UserError(f"{self.option} {name!r} is not known: use one of {', '.join(self)}") from None

    def names(self) -> tuple[str, ...]:
        """Registered names in registration order."""
        return tuple(self)

    def help(self) -> str:
        """``"omp (the paper's greedy), random (...)"``: every name with its summary."""
        return ", ".join(f"{n} ({c.summary})" for n, c in self.items())

    def __repr__(self) -> str:
        return f"Registry({self.kind!r}: {', '.join(self)})"


def configure(default_conf, overrides: dict):
    """``default_conf`` with ``overrides`` applied (``dataclasses.replace``): the settings of a
    registered part built with ``cls(**overrides)``."""
    return dataclasses.replace(default_conf, **overrides) if overrides else default_conf
