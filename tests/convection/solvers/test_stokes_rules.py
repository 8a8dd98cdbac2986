"""The rules tying the Stokes settings to the viscosity are one check
(:func:`convection.solvers.stokes.solver.check_viscosity_rules`): the config front end and a solver
built in Python refuse the same settings with the same message."""

from __future__ import annotations

import dolfinx.mesh
import pytest
from mpi4py import MPI

from convection.config.loader import load_config
from convection.geometry.boundary import VelocityBC
from convection.physics.approximation import BoussinesqApproximation, ViscosityLaw
from convection.physics.rheology import build_law
from convection.schema import ConfigError
from convection.solvers.stokes.nonlinear import NonlinearSettings
from convection.solvers.stokes.solver import StokesSolver

LAW = {"name": "drucker_prager", "cohesion": 1.0, "friction_angle": 30.0}
SIDES = ("left", "right", "bottom", "top")


def _python(stokes: dict) -> ConfigError:
    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_WORLD, 2, 2)
    approximation = BoussinesqApproximation(Ra=1.0, viscosity=ViscosityLaw(laws=(build_law(LAW, "law"),)))
    with pytest.raises(ConfigError) as raised:
        StokesSolver(mesh, approximation, bcs={s: VelocityBC("free_slip") for s in SIDES},
                     buoyancy_theta=stokes.get("buoyancy_theta", 0.0),
                     nonlinear=NonlinearSettings(**stokes.get("nonlinear", {})))
    return raised.value


def _config(stokes: dict) -> ConfigError:
    document = {"mesh": {"cells": [2, 2]}, "physics": {"Ra": 1.0, "viscosity": {"law": LAW}}, "stokes": stokes,
                "time": {"end": 0.1}, "output": {"directory": "unused"}}
    with pytest.raises(ConfigError) as raised:
        load_config(None, document=document)
    return raised.value


@pytest.mark.parametrize("stokes, key", [
    ({"buoyancy_theta": 0.5, "nonlinear": {"method": "picard"}}, "stokes.buoyancy_theta"),
    ({"nonlinear": {"method": "newton"}}, "stokes.nonlinear.method"),
])
def test_config_and_solver_refuse_with_one_message(stokes, key):
    from_python, from_config = _python(stokes), _config(stokes)
    assert f"'{key}'" in str(from_config)
    assert str(from_python) == str(from_config)


def test_a_traction_free_side_lets_newton_run_with_a_pressure_dependent_viscosity():
    document = {"mesh": {"cells": [2, 2]}, "physics": {"Ra": 1.0, "viscosity": {"law": LAW}},
                "boundary": {"velocity": {"top": None}}, "stokes": {"nonlinear": {"method": "newton"}},
                "time": {"end": 0.1}, "output": {"directory": "unused"}}
    assert load_config(None, document=document)["stokes"]["nonlinear"]["method"] == "newton"
