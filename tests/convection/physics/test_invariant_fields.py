"""The output fields strain_rate_II = sqrt(eps:eps/2) and stress_II = 2 eta strain_rate_II on a flow
known exactly: pure shear u = (x - 1/2, 1/2 - z) prescribed on every side of the unit square (it
solves the Stokes problem with Ra = 0), eps = diag(1, -1), so strain_rate_II = 1 and
stress_II = 2 eta; and the viscosity written where it varies."""

from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI

from convection import build_model, load_config

SHEAR = {"kind": "prescribed", "value": ["x - 0.5", "0.5 - z"]}


def _fields(tmp_path, **extra):
    document = {"mesh": {"cells": [6, 6]}, "physics": {"Ra": 0.0}, "energy": {"enabled": False},
                "time": {"end": 1.0}, "initial": {"temperature": "0"},
                "boundary": {"velocity": {side: SHEAR for side in ("left", "right", "bottom", "top")}},
                "output": {"directory": str(tmp_path / "out"), "progress": "none"}, **extra}
    model = build_model(load_config(None, document=document), comm=MPI.COMM_WORLD)
    model.start()
    return model.fields()


def _owned(f):
    return f.x.array[: f.function_space.dofmap.index_map.size_local]


def test_pure_shear_invariants(tmp_path):
    fields = _fields(tmp_path)
    assert "viscosity" not in fields  # constant viscosity: nothing to show
    assert np.allclose(_owned(fields["strain_rate_II"]), 1.0, atol=1e-9)
    assert np.allclose(_owned(fields["stress_II"]), 2.0, atol=1e-9)


def test_viscosity_of_materials_is_written(tmp_path):
    fields = _fields(tmp_path, materials={"stiff": {"initial": "x < 0.5", "viscosity": 10.0}},
                     composition={"source": "static", "degree": 0})
    eta = _owned(fields["viscosity"])
    assert eta.min() == pytest.approx(1.0) and eta.max() == pytest.approx(10.0)
    assert np.allclose(_owned(fields["stress_II"]), 2.0 * eta * _owned(fields["strain_rate_II"]), rtol=1e-9)
