"""Physical units: the scaling's numbers against hand-computed ones, the conversion of a config
written in units into the nondimensional one, and back to the user's units."""

import math

import pytest

from convection.config.loader import dump_config, load_config
from convection.config.units import apply_scaling, scaling_of
from convection.physics.scaling import UNIT_KINDS, ColumnUnits, Scaling, parse_quantity, registry
from convection.schema import ConfigError

MANTLE = {"length": "660 km", "viscosity": "1e21 Pa s", "density": "3300 kg/m^3", "gravity": "9.81 m/s^2",
          "thermal_expansivity": "3e-5 1/K", "temperature_difference": "1300 K", "reference_temperature": "273 K"}
YEAR = 365.25 * 86400.0


def test_scales_and_numbers_by_hand():
    s = Scaling.from_section(MANTLE)
    L, eta0, kappa = 660e3, 1e21, 1e-6
    assert s.time == pytest.approx(L**2 / kappa, rel=1e-15)
    assert s.rayleigh() == pytest.approx(3300 * 3e-5 * 1300 * 9.81 * L**3 / (eta0 * kappa), rel=1e-14)
    assert s.buoyancy_number(100.0) == pytest.approx(100 * 9.81 * L**3 / (eta0 * kappa), rel=1e-14)
    # a velocity in units of kappa / L, a stress in eta0 kappa / L^2, a viscosity in eta0 (exactly)
    assert s.nondimensional(parse_quantity("5 cm/yr")) == pytest.approx(0.05 / YEAR / (kappa / L), rel=1e-14)
    assert s.nondimensional(parse_quantity("100 MPa")) == pytest.approx(1e8 / (eta0 * kappa / L**2), rel=1e-14)
    assert s.nondimensional(parse_quantity("1e23 Pa s")) == pytest.approx(100.0, rel=1e-15)
    assert s.nondimensional(parse_quantity("1e21 Pa*s")) == 1.0
    assert s.nondimensional(parse_quantity("1e-15 1/s")) == pytest.approx(1e-15 * L**2 / kappa, rel=1e-14)
    # a temperature value counts from T0; a difference does not; degC and K agree
    assert s.nondimensional(parse_quantity("1573 K"), absolute=True) == pytest.approx(1.0, rel=1e-15)
    assert s.nondimensional(parse_quantity("1299.85 degC"), absolute=True) == pytest.approx(1.0, rel=1e-12)
    assert s.nondimensional(parse_quantity("650 K")) == pytest.approx(0.5, rel=1e-15)
    with pytest.raises(ConfigError, match="offset"):
        s.nondimensional(parse_quantity("20 degC"))


@pytest.mark.parametrize("kind", sorted(UNIT_KINDS))
def test_back_to_output_units_inverts(kind):
    s = Scaling.from_section(MANTLE)
    unit = s.units[kind]
    value = 7.25
    nondimensional = s.nondimensional(registry().Quantity(value, unit), absolute=kind == "temperature")
    assert s.dimensional(kind, nondimensional) == pytest.approx(value, rel=1e-12)


def test_column_units_header_and_row():
    s = Scaling.from_section(MANTLE)
    units = ColumnUnits(s, ["step", "time", "vrms", "T_mean", "nusselt"],
                        {"time": "time", "vrms": "velocity", "T_mean": "temperature"})
    assert units.header == ["step", "time [Myr]", "vrms [cm/yr]", "T_mean [K]", "nusselt"]
    row = units.convert({"step": 3, "time": 1.0, "vrms": 1.0, "T_mean": 0.5, "nusselt": 4.5})
    assert row["step"] == 3 and row["nusselt"] == 4.5
    assert row["time [Myr]"] == pytest.approx(660e3**2 / 1e-6 / YEAR / 1e6, rel=1e-12)
    assert row["vrms [cm/yr]"] == pytest.approx(1e-6 / 660e3 * YEAR * 100, rel=1e-12)
    assert row["T_mean [K]"] == pytest.approx(273 + 650, rel=1e-15)


BLOCK = {
    "scaling": {"length": "500 km", "viscosity": "1e21 Pa s", "density": "3200 kg/m^3", "gravity": "9.81 m/s^2"},
    "mesh": {"cells": [8, 8], "upper": ["500 km", "500 km"]},
    "physics": {"viscosity": {"background": "1e21 Pa s"}},
    "materials": {"block": {"initial": "abs(x - 250*km) < 50*km and abs(z - 350*km) < 50*km",
                            "density": "3300 kg/m^3", "viscosity": "1e23 Pa s"}},
    "energy": {"enabled": False},
    "initial": {"temperature": "0"},
    "time": {"end": "10 Myr"},
    "output": {"directory": "out"},
}


def test_dimensional_config_is_the_nondimensional_one():
    """The block written in units resolves to the numbers written by hand; saved and read again
    (a restart reads config.yaml) it is the same config."""
    import yaml

    config = load_config(None, document=BLOCK)
    L, kappa = 500e3, 1e-6
    assert config["mesh"]["upper"] == [1.0, 1.0]
    assert config["physics"]["Ra"] == 0.0  # no energy equation: no Ra needed
    assert config["physics"]["viscosity"]["background"] == 1.0
    block = config["materials"]["block"]
    assert block["Rb"] == pytest.approx(100 * 9.81 * L**3 / (1e21 * kappa), rel=1e-14)
    assert block["viscosity"] == pytest.approx(100.0, rel=1e-14) and block["density"] is None
    assert config["time"]["end"] == pytest.approx(10e6 * YEAR / (L**2 / kappa), rel=1e-14)
    assert load_config(None, document=yaml.safe_load(dump_config(config))) == config
    by_hand = {key: value for key, value in BLOCK.items() if key != "scaling"}
    by_hand = {**by_hand, "mesh": {"cells": [8, 8], "upper": [1.0, 1.0]}, "physics": {"viscosity": {"background": 1.0}},
               "time": {"end": config["time"]["end"]},
               "materials": {"block": {"initial": BLOCK["materials"]["block"]["initial"], "Rb": block["Rb"],
                                       "viscosity": block["viscosity"]}},
               "initial": {"temperature": "0", "constants": {"km": 1e3 / L}}}
    plain = load_config(None, document=by_hand)
    assert {k: v for k, v in plain.items() if k not in ("scaling", "initial")} == \
        {k: v for k, v in config.items() if k not in ("scaling", "initial")}


def test_unit_constants_in_expressions():
    config = load_config(None, document=BLOCK)
    constants = scaling_of(config).expression_constants()
    assert constants["km"] == pytest.approx(1 / 500) and constants["m"] == pytest.approx(1 / 500e3)
    assert constants["Myr"] == pytest.approx(1e6 * YEAR / (500e3**2 / 1e-6))


def test_thermal_model_gets_its_rayleigh_number():
    document = {"scaling": MANTLE, "mesh": {"cells": [4, 4]}, "time": {"end": "1 Myr"}, "output": {"directory": "o"},
                "boundary": {"temperature": {"top": {"dirichlet": "273 K"}, "bottom": {"dirichlet": "1573 K"}}}}
    config = load_config(None, document=document)
    assert config["physics"]["Ra"] == pytest.approx(Scaling.from_section(MANTLE).rayleigh(), rel=1e-15)
    assert config["boundary"]["temperature"]["top"] == {"dirichlet": 0.0}
    assert config["boundary"]["temperature"]["bottom"]["dirichlet"] == pytest.approx(1.0, rel=1e-15)
    with pytest.raises(ConfigError, match="'physics.Ra': 1000.0 given, but the scaling gives Ra"):
        load_config(None, document={**document, "physics": {"Ra": 1e3}})


@pytest.mark.parametrize("change, needle", [
    ({"time": {"end": "10 Myr"}, "scaling": None}, "'time.end': '10 Myr' has a unit; a model with units needs the "
                                                    "scaling section"),
    ({"time": {"end": "10 km"}}, "'time.end'"),
    ({"scaling": {**BLOCK["scaling"], "length": "500 kg"}}, "'scaling.length': '500 kg' is not of [length]"),
    ({"scaling": {**BLOCK["scaling"], "length": "-5 km"}}, "'scaling.length': must be positive"),
    ({"scaling": {**BLOCK["scaling"], "gravity": None}}, "'scaling.gravity': needed by this model"),
    ({"materials": {"block": {"initial": "x < 0.5", "density": 3300}}}, "'materials.block.density': expected a "
                                                                       "density with a unit"),
    ({"materials": {"block": {"initial": "x < 0.5", "density": "3300 kg/m^3", "Rb": 5}}}, "'materials.block.Rb'"),
    ({"physics": {"Ra": "5 km"}}, "'physics.Ra': a nondimensional number"),
    ({"time": {"end": "10 Mjr"}}, "'time.end': '10 Mjr' is not a number with a unit pint knows"),
    ({"energy": {"enabled": True}}, "'physics.Ra': required value missing"),
])
def test_unit_mistakes_name_the_key(change, needle):
    document = {**BLOCK, **change}
    if document.get("scaling") is None:
        document.pop("scaling")
        document["mesh"] = {"cells": [8, 8]}
        document["physics"] = {}
        document["materials"] = {}
    with pytest.raises(ConfigError) as err:
        load_config(None, document=document)
    assert needle in str(err.value)
    assert "\n" not in str(err.value)


def test_nondimensional_configs_untouched():
    document = {"mesh": {"cells": [4, 4]}, "physics": {"Ra": 1e4}, "time": {"end": 0.1}, "output": {"directory": "o"}}
    assert apply_scaling(document) is document
    assert scaling_of(load_config(None, document=document)) is None


def test_heating_per_mass():
    document = {"scaling": {**MANTLE, "heat_capacity": "1250 J/kg/K"}, "mesh": {"cells": [4, 4]},
                "physics": {"H": "5e-12 W/kg"}, "time": {"end": "1 Myr"}, "output": {"directory": "o"}}
    config = load_config(None, document=document)
    t0 = 660e3**2 / 1e-6
    assert config["physics"]["H"] == pytest.approx(5e-12 / 1250 * t0 / 1300, rel=1e-12)
    assert math.isfinite(config["physics"]["Ra"])
