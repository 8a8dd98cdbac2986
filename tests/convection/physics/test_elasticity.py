"""Maxwell visco-elasticity (convection/physics/elasticity.py): the factors, the materials' moduli,
the old stress's load in the Stokes forms (an elastic rebound with a closed form), and the config's
checks and units."""

import numpy as np
import pytest
from mpi4py import MPI

import dolfinx.fem
import dolfinx.mesh
import ufl
import yaml

from convection.config.loader import load_config
from convection.config.units import scaling_of
from convection.geometry.boundary import VelocityBC
from convection.physics.approximation import BoussinesqApproximation
from convection.physics.elasticity import Elasticity, stress_labels
from convection.physics.scaling import parse_quantity
from convection.schema import ConfigError
from convection.solvers.stokes.solver import StokesSolver
from fembase.dolfinx_compat import function_space


def test_factors_are_moresi_s():
    """eta_ve = eta G dt/(eta + G dt), chi = eta_ve/(G dt); dt_e = infinity (rate 0): the viscous limit."""
    law = Elasticity(shear_modulus=3.0)
    eta, dt = 2.0, 0.25
    assert law.viscosity(eta, None, 1 / dt) == pytest.approx(eta * 3.0 * dt / (eta + 3.0 * dt), rel=1e-15)
    assert law.memory(eta, None, 1 / dt) == pytest.approx(law.viscosity(eta, None, 1 / dt) / (3.0 * dt), rel=1e-15)
    assert (law.viscosity(eta, None, 0.0), law.memory(eta, None, 0.0)) == (eta, 0.0)
    with pytest.raises(ValueError, match="> 0"):
        Elasticity(shear_modulus=1.0, material_moduli=(0.0,))
    assert stress_labels(2) == ("elastic_stress_xx", "elastic_stress_yy", "elastic_stress_xy")
    assert len(stress_labels(3)) == 6


def test_moduli_mix_as_compliances():
    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_WORLD, 2, 2)
    law = Elasticity(shear_modulus=1.0, material_moduli=(4.0, None))
    assert law.is_variable and not Elasticity(2.0, (None, 2.0)).is_variable
    c1, c2 = 0.5, 0.25  # 1/G = 0.25/1 + 0.5/4 + 0.25/1
    value = dolfinx.fem.assemble_scalar(dolfinx.fem.form(law.modulus((c1 + 0 * ufl.SpatialCoordinate(mesh)[0], c2))
                                                          * ufl.dx(domain=mesh)))
    assert mesh.comm.allreduce(value) == pytest.approx(1 / (0.25 + 0.125 + 0.25), rel=1e-12)


@pytest.mark.parametrize("gdim", [2, 3])
def test_elastic_rebound_of_a_free_block(gdim):
    """A block prestressed by tau_xx = -tau_yy = s, free slip on the faces through the origin, free
    on the others: the stress's load drives u = e (x, -y, 0) with e = -s / (2 G dt_e), and the new
    stress 2 eta_ve eps + chi tau is zero (the elastic strain -tau / (2 G) recovered in one step)."""
    if gdim == 2:
        mesh = dolfinx.mesh.create_unit_square(MPI.COMM_WORLD, 3, 3)
        slip, prestress = ("left", "bottom"), (1.0, -1.0, 0.0)
    else:
        mesh = dolfinx.mesh.create_unit_cube(MPI.COMM_WORLD, 2, 2, 2)
        slip, prestress = ("left", "front", "bottom"), (1.0, -1.0, 0.0, 0.0, 0.0, 0.0)
    approximation = BoussinesqApproximation(Ra=0.0)
    approximation.elasticity = Elasticity(shear_modulus=2.0)
    stokes = StokesSolver(mesh, approximation, bcs={name: VelocityBC("free_slip") for name in slip}, solver="direct")
    D = function_space(mesh, "DG", 0)
    s, dt = 0.3, 0.5
    fields = {}
    for label, value in zip(stress_labels(gdim), prestress):
        fields[label] = dolfinx.fem.Function(D)
        fields[label].x.array[:] = s * value
    stokes.solve(0.0, None, dt=0.0, fields=fields)  # no step yet: the viscous flow, no load
    assert np.abs(stokes.u.x.array).max() < 1e-12
    stokes.solve(0.0, None, dt=dt, fields=fields)
    e = -s / (2 * 2.0 * dt)
    exact = dolfinx.fem.Function(stokes.u.function_space)
    exact.interpolate(lambda x: np.stack([e * x[0], -e * x[1], *([0 * x[2]] if gdim == 3 else [])]))
    assert np.abs(stokes.u.x.array - exact.x.array).max() < 1e-10 * abs(e)
    same = dict(zip(stress_labels(gdim), fields.values()))  # a new mapping of the same fields: forms and operator kept
    assert stokes.solve(0.0, None, dt=dt, fields=same).assemblies == 0
    assert stokes.solve(0.0, None, dt=2 * dt, fields=same).assemblies == 1  # dt_e changed: eta_ve did
    rate = 1 / dt
    law = approximation.elasticity
    assert 2 * law.viscosity(1.0, None, rate) * e + law.memory(1.0, None, rate) * s == pytest.approx(0.0, abs=1e-15)


BOX = {"mesh": {"cells": [2, 2]}, "physics": {"Ra": 0.0, "elasticity": {"enabled": True}},
       "initial": {"temperature": "0"}, "energy": {"enabled": False}, "time": {"end": 1.0},
       "output": {"directory": "unused"},
       "particles": {"enabled": True, "generator": {"name": "random_uniform", "particles_per_cell": 4},
                     "properties": ["elastic_stress"]}}


def _with(**changes):
    document = {key: dict(value) if isinstance(value, dict) else value for key, value in BOX.items()}
    for path, value in changes.items():
        node = document
        *parents, last = path.split("__")
        for key in parents:
            node = node.setdefault(key, {})
        node[last] = value
    return document


def test_config_is_checked_when_read():
    assert load_config(None, document=_with())["physics"]["elasticity"]["shear_modulus"] == 1.0
    assert load_config(None, document={k: v for k, v in BOX.items() if k != "particles"}
                       | {"physics": {"Ra": 0.0}})["physics"]["elasticity"]["enabled"] is False
    cases = [(_with(physics__elasticity={"enabled": True, "shear_modulus": 0.0}), "physics.elasticity.shear_modulus"),
             (_with(particles__properties=["plastic_strain"]), "carry 'elastic_stress'"),
             (_with(physics__elasticity={"enabled": False}), "needs physics.elasticity.enabled"),
             (_with(physics__elasticity={"enabled": True, "dt_e": 1.0}), "dt_e")]
    for document, needle in cases:
        with pytest.raises(ConfigError, match=needle):
            load_config(None, document=document)


def test_shear_modulus_has_units():
    scaling = {"length": "100 km", "viscosity": "1e21 Pa s", "density": "3300 kg/m^3", "gravity": "9.81 m/s^2"}
    document = _with(physics__elasticity={"enabled": True, "shear_modulus": "1e10 Pa"}) | {"scaling": scaling}
    document["materials"] = {"plate": {"initial": "z > 0.9", "shear_modulus": "3e10 Pa"}}
    config = load_config(None, document=document)
    units = scaling_of(config)
    stress = units.nondimensional(parse_quantity("1e10 Pa"))
    assert config["physics"]["elasticity"]["shear_modulus"] == pytest.approx(stress, rel=1e-12)
    assert config["materials"]["plate"]["shear_modulus"] == pytest.approx(3 * stress, rel=1e-12)
    document["physics"]["elasticity"]["shear_modulus"] = "1e10 m"
    with pytest.raises(ConfigError, match="shear_modulus"):
        load_config(None, document=document)


def test_check_refuses_in_one_line(tmp_path):
    from _runs import error_line, run_cli

    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(_with(physics__elasticity={"enabled": True, "shear_modulus": -3.0})))
    line = error_line(run_cli(["check", str(path)]), 2, "physics.elasticity.shear_modulus")
    assert "> 0" in line


def test_averaged_factors_are_a_share_of_the_step():
    """tau <- (1 - r) R tau R^T + r (2 eta_ve eps + chi R tau R^T) = 2 (r eta_ve) eps + (1 - r (1 - chi)) R tau R^T."""
    eta_ve, chi, r = 0.3, 0.7, 0.25
    viscosity, memory = Elasticity.averaged(eta_ve, chi, r)
    tau, eps = 1.3, -0.4
    assert 2 * viscosity * eps + memory * tau == pytest.approx((1 - r) * tau + r * (2 * eta_ve * eps + chi * tau),
                                                               rel=1e-15)
    assert Elasticity.averaged(eta_ve, chi, 1.0) == pytest.approx((eta_ve, chi), rel=1e-15)
    with pytest.raises(ValueError, match="elastic time step"):
        Elasticity(1.0, (), 0.0)


def test_elastic_time_step_is_checked_and_has_units():
    fixed = {"enabled": True, "elastic_time_step": 0.5}
    assert load_config(None, document=_with(physics__elasticity=fixed, time__dt_max=0.5)
                       )["physics"]["elasticity"]["elastic_time_step"] == 0.5
    assert load_config(None, document=_with())["physics"]["elasticity"]["elastic_time_step"] is None
    cases = [(_with(physics__elasticity=fixed | {"elastic_time_step": 0.0}, time__dt_max=0.5), "> 0"),
             (_with(physics__elasticity=fixed), "set time.dt_max"),
             (_with(physics__elasticity=fixed, time__dt_max=0.6), "at most elastic_time_step")]
    for document, needle in cases:
        with pytest.raises(ConfigError, match=f"physics.elasticity.elastic_time_step.*{needle}"):
            load_config(None, document=document)
    with pytest.raises(ConfigError, match="time.dt_initial.*elastic_time_step"):
        load_config(None, document=_with(physics__elasticity=fixed, time__dt_max=0.5, time__dt_initial=0.6))
    scaling = {"length": "100 km", "viscosity": "1e21 Pa s", "density": "3300 kg/m^3", "gravity": "9.81 m/s^2"}
    document = _with(physics__elasticity=fixed | {"elastic_time_step": "10 kyr"}, time__dt_max="5 kyr",
                     time__end="20 kyr") | {"scaling": scaling}
    config = load_config(None, document=document)
    assert config["physics"]["elasticity"]["elastic_time_step"] == pytest.approx(
        2 * config["time"]["dt_max"], rel=1e-12)
    assert config["physics"]["elasticity"]["elastic_time_step"] == pytest.approx(
        scaling_of(config).nondimensional(parse_quantity("10 kyr")), rel=1e-12)
    document["physics"]["elasticity"]["elastic_time_step"] = "10 km"
    with pytest.raises(ConfigError, match="elastic_time_step"):
        load_config(None, document=document)


def test_check_refuses_a_short_elastic_time_step_in_one_line(tmp_path):
    from _runs import error_line, run_cli

    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(_with(physics__elasticity={"enabled": True, "elastic_time_step": 0.1},
                                         time__dt_max=0.2)))
    error_line(run_cli(["check", str(path)]), 2, "physics.elasticity.elastic_time_step")
