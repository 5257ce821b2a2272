"""Registries: parts by name in registration order, with their programming errors refused at
registration and an unknown name a one-line user error."""

from __future__ import annotations

from dataclasses import dataclass

import pytest

from markerplace.errors import UserError
from markerplace.registry import Registry, configure


@dataclass(frozen=True)
class _Conf:
    size: float = 1.0


def _part(name, summary="a part", conf=_Conf()):
    return type(f"Part_{name}", (), {"name": name, "summary": summary, "default_conf": conf})


def test_names_lookup_and_help_keep_registration_order():
    reg = Registry("toy part", "--toy")
    for name in ("zeta", "alpha", "mid"):
        reg.register(_part(name, f"the {name} one"))
    assert reg.names() == ("zeta", "alpha", "mid")
    assert reg.lookup("alpha").name == "alpha"
    assert reg.help() == "zeta (the zeta one), alpha (the alpha one), mid (the mid one)"
    with pytest.raises(UserError, match=r"^--toy 'beta' is not known: use one of zeta, alpha, mid$"):
        reg.lookup("beta")
    with pytest.raises(UserError, match="is not known"):
        reg.lookup(["not", "hashable"])


@pytest.mark.parametrize("cls, needle", [
    (_part(""), "non-empty name without commas"),
    (_part("a,b"), "non-empty name without commas"),
    (_part(" a"), "non-empty name without commas"),
    (_part("a", summary=None), "one-line summary"),
    (_part("a", conf=None), "frozen dataclass instance"),
    (_part("a", conf=_Conf), "frozen dataclass instance"),  # the class, not an instance
])
def test_registration_refuses_a_malformed_part(cls, needle):
    with pytest.raises(ValueError, match=needle):
        Registry("toy part", "--toy").register(cls)


def test_a_name_registers_once_and_configure_replaces_fields():
    reg = Registry("toy part", "--toy")
    reg.register(_part("a"))
    with pytest.raises(ValueError, match="registered twice"):
        reg.register(_part("a"))
    assert configure(_Conf(), {"size": 2.5}) == _Conf(2.5) and configure(_Conf(), {}) == _Conf()
