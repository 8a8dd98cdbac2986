"""Every number a YAML user writes is a number: ``1e3``, ``1.0e3``, ``1E-3``, ``.5`` (YAML 1.1, which
PyYAML follows, reads most of these as text), in a config file, in ``--set`` and in free-form values
such as a material's viscosity or a law's parameters."""

from pathlib import Path

import pytest

from convection.config.files import safe_load
from convection.config.loader import load_config

ROOT = Path(__file__).resolve().parents[3]
GOOD = ROOT / "configs" / "blankenbach_1a.yaml"


@pytest.mark.parametrize("text, value", [
    ("1e3", 1000.0), ("1.0e3", 1000.0), ("1E-3", 1e-3), (".5", 0.5), ("-.5", -0.5), ("+2.5e-7", 2.5e-7),
    ("1.0e+3", 1000.0), ("3.", 3.0), ("-1e-2", -0.01),
])
def test_yaml_12_floats(text, value):
    read = safe_load(f"x: {text}", "test")["x"]
    assert isinstance(read, float) and read == value


@pytest.mark.parametrize("text, value", [("1000", 1000), ("0x10", 16), ("true", True), ("abc", "abc"),
                                         ("'1e3'", "1e3"), ("1e", "1e"), ("e3", "e3"), ("1.2.3", "1.2.3")])
def test_other_scalars_unchanged(text, value):
    read = safe_load(f"x: {text}", "test")["x"]
    assert read == value and type(read) is type(value)


def test_material_viscosity_and_law_parameters(tmp_path):
    path = tmp_path / "block.yaml"
    path.write_text(GOOD.read_text() + """
materials:
  block: {initial: "z > 0.4", Rb: 1.0e3, viscosity: 1.0e3}
  lid: {initial: "z > 0.9", viscosity: {name: exponential, eta0: 1e3, gamma_T: .5}}
""")
    config = load_config(path)
    assert config["materials"]["block"]["viscosity"] == 1000.0
    assert config["materials"]["lid"]["viscosity"]["eta0"] == 1000.0
    assert config["materials"]["lid"]["viscosity"]["gamma_T"] == 0.5
    config = load_config(path, ["materials.block.viscosity=1e3", "materials.block.Rb=-2.5E+2"])
    assert config["materials"]["block"]["viscosity"] == 1000.0 and config["materials"]["block"]["Rb"] == -250.0
