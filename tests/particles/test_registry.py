"""Registry: dict behaviour, role-named errors, registration checks."""

from dataclasses import dataclass

import pytest

from particles.advection import INTEGRATORS
from particles.generation import GENERATORS
from particles.interpolation import INTERPOLATORS
from particles.properties import PROPERTIES
from fembase.registry import Registry


@dataclass(frozen=True)
class _Thing:
    size: int = 1
    name = "thing"
    description = "a test entry"


def test_registry_is_a_dict_with_a_role():
    reg = Registry("particle widget", (_Thing,))
    assert "thing" in reg and sorted(reg) == ["thing"] and reg["thing"] is _Thing
    assert reg.role == "particle widget"
    assert reg.create("thing", size=3) == _Thing(3)
    assert reg.describe() == {"thing": "a test entry"}
    with pytest.raises(ValueError, match=r"unknown particle widget 'gadget'; valid: \['thing'\]"):
        reg.create("gadget")
    with pytest.raises(ValueError, match="registered twice"):
        reg.register(_Thing)


def test_register_is_a_decorator_and_checks_lowercase():
    reg: Registry[type] = Registry("particle widget")

    @reg.register
    class Lower:
        name = "lower"
        description = "ok"

    assert reg.lookup("lower") is Lower
    with pytest.raises(ValueError, match="not lowercase"):
        @reg.register
        class Upper:
            name = "Upper"
            description = "bad"


@pytest.mark.parametrize("registry", [GENERATORS, INTERPOLATORS, PROPERTIES, INTEGRATORS])
def test_every_role_describes_every_entry(registry):
    described = registry.describe()
    assert sorted(described) == sorted(registry) and all(described.values())
    with pytest.raises(ValueError, match=f"unknown {registry.role} 'nope'"):
        registry.lookup("nope")
