"""Registry: dict behaviour, role-named errors, registration checks."""

from dataclasses import dataclass

import pytest

from particles.advection import INTEGRATORS
from particles.generation import GENERATORS
from particles.interpolation import INTERPOLATORS
from particles.properties import PROPERTIES
from fembase.params import param
from fembase.registry import Configured, Registry


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


class _Gadget(Configured):
    """A plugin of the one shape that keeps its settings."""

    name = "gadget"
    description = "a test plugin"

    @dataclass(frozen=True)
    class Settings:
        size: int = param(help="the size")
        colour: str = param("red", help="the colour")


def test_settings_are_made_by_name_and_build_keeps_them():
    reg = Registry("particle widget", (_Gadget,))
    settings = reg.settings("gadget", size=3)
    assert settings == _Gadget.Settings(3, "red")
    made = reg.build("gadget", settings, None)
    assert isinstance(made, _Gadget) and made.settings is settings
    assert made == _Gadget(_Gadget.Settings(3)) != _Gadget(_Gadget.Settings(4))
    assert hash(made) == hash(_Gadget(_Gadget.Settings(3))) and repr(made).startswith("_Gadget(")
    with pytest.raises(ValueError, match=r"^particle widget 'gadget' has no parameter 'shape'; its parameters: "
                                         r"\['colour', 'size'\]$"):
        reg.settings("gadget", size=3, shape="round")
    with pytest.raises(ValueError, match=r"^particle widget 'gadget' needs the parameter 'size'$"):
        reg.settings("gadget", colour="blue")
    with pytest.raises(ValueError, match=r"unknown particle widget 'widget'"):
        reg.settings("widget")
    with pytest.raises(TypeError, match=r"_Gadget takes a _Gadget.Settings, got dict"):
        _Gadget({"size": 3})
