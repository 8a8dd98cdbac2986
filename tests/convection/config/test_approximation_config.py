"""physics.approximation and physics.reference: the default is Boussinesq, and a config whose
approximation and reference state disagree is refused at check time, naming the key."""

from pathlib import Path

import pytest

from convection.config.loader import load_config
from convection.config.settings import run_settings
from convection.schema import ConfigError

ROOT = Path(__file__).resolve().parents[3]
KING = ROOT / "configs" / "king_tala.yaml"
BLANKENBACH = ROOT / "configs" / "blankenbach_1a.yaml"


def test_the_default_is_boussinesq():
    physics = run_settings(load_config(BLANKENBACH)).physics
    assert physics.approximation == "boussinesq" and physics.reference.Di == 0.0


def test_king_config_is_tala():
    physics = run_settings(load_config(KING)).physics
    assert (physics.approximation, physics.reference.Di, physics.reference.surface_temperature) == ("tala", 0.25, 0.091)


@pytest.mark.parametrize("config, overrides, key", [
    (KING, ["physics.reference.Di=-0.5"], "physics.reference.Di"),
    (KING, ["physics.reference.gruneisen=0"], "physics.reference.gruneisen"),
    (KING, ["physics.approximation=bla"], "physics.approximation"),
    (KING, ["physics.approximation=ala", "physics.reference.Di=0"], "physics.reference.Di': physics.approximation ala"),
    (KING, ["physics.reference.heat_capacity_ratio=1.1"], "physics.reference.heat_capacity_ratio': only with "
                                                          "physics.approximation ala"),
    (BLANKENBACH, ["physics.reference.heat_capacity_ratio=1.2"], "physics.reference.heat_capacity_ratio': only"),
    (KING, ["physics.approximation=ala", "physics.reference.heat_capacity_ratio=0.5"],
     "physics.reference.heat_capacity_ratio"),
    (KING, ["physics.approximation=ala", "stokes.solver=iterative"], "stokes.solver': physics.approximation ala "
                                                                     "needs the direct"),
    (KING, ["physics.reference.Di=0"], "physics.reference.Di': physics.approximation tala needs"),
    (BLANKENBACH, ["physics.reference.Di=0.5"],
     "physics.reference.Di': only with physics.approximation eba or tala or ala"),
    (KING, ["energy.enabled=false"], "energy.enabled"),
    (KING, ["stokes.buoyancy_theta=0.5"], "stokes.buoyancy_theta"),
    (KING, ["materials={lid: {initial: 'z > 0.8', Rb: 1}}"], "physics.approximation': tala's shear heating"),
    (KING, ["physics.viscosity.law={name: power_law, n: 3}"], "physics.approximation"),
])
def test_inconsistent_configs_are_refused(config, overrides, key):
    with pytest.raises(ConfigError, match="config key '" + key):
        load_config(config, overrides)


def test_a_temperature_dependent_viscosity_is_taken():
    load_config(KING, ["physics.approximation=eba", "physics.viscosity.temperature_law=frank_kamenetskii",
                       "physics.viscosity.gamma=2"])


def test_ala_is_taken_with_the_direct_solver():
    physics = run_settings(load_config(KING, ["physics.approximation=ala", "physics.reference.heat_capacity_ratio=1.2",
                                              "stokes.solver=auto"])).physics
    assert (physics.approximation, physics.reference.heat_capacity_ratio) == ("ala", 1.2)
