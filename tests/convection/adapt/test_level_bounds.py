"""Geometric refinement: adaptivity.min_level_where / max_level_where bound every cell's level by
position (and time), with or without the indicator; the same mesh on 1, 2 and 3 ranks."""

from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI

import dolfinx.mesh

from convection import build_model, load_config
from convection.adapt.adaptivity import LevelBounds
from convection.config.loader import ConfigError


def _model(tmp_path, comm, **adapt):
    document = {"mesh": {"cells": [8, 8]}, "physics": {"Ra": 1e4}, "time": {"end": 0.01},
                "adaptivity": {"enabled": True, "max_level": 3, "every": 1, **adapt},
                "output": {"directory": str(tmp_path / "out"), "progress": "none"}}
    return build_model(load_config(None, document=document), comm=comm)


def _levels_and_heights(model):
    mesh = model.mesh
    owned = np.arange(mesh.topology.index_map(2).size_local, dtype=np.int32)
    z = dolfinx.mesh.compute_midpoints(mesh, 2, owned)[:, 1]
    return model.adaptivity.hierarchy.levels(mesh), z


def test_bounds_alone_shape_the_mesh(tmp_path):
    model = _model(tmp_path, MPI.COMM_WORLD, refine_fraction=0.0, coarsen_fraction=0.0,
                   min_level_where="3*(z > 0.75)", max_level_where="1 + 2*(z > 0.5)")
    levels, z = _levels_and_heights(model)
    assert np.all(levels[z > 0.75 + 1 / 8] == 3)  # at least 3 there, and 3 is max_level
    assert np.all(levels[z < 0.5 - 1 / 8] <= 1)   # at most 1 below the middle
    comm = model.comm
    assert comm.allreduce(int((levels == 3).sum())) > 0 and comm.allreduce(int((levels == 0).sum())) > 0


def test_bounds_clip_the_indicator(tmp_path):
    """With the indicator refining everywhere it may, a cap of level 1 in the left half holds."""
    model = _model(tmp_path, MPI.COMM_WORLD, refine_fraction=1.0, coarsen_fraction=0.0,
                   max_level_where="1 + 2*(x > 0.5)")
    mesh = model.mesh
    owned = np.arange(mesh.topology.index_map(2).size_local, dtype=np.int32)
    x = dolfinx.mesh.compute_midpoints(mesh, 2, owned)[:, 0]
    levels = model.adaptivity.hierarchy.levels(mesh)
    assert np.all(levels[x < 0.5 - 1 / 8] <= 1)
    assert model.comm.allreduce(int((levels[x > 0.5 + 1 / 8] >= 2).sum())) > 0


def test_time_enters():
    bounds = LevelBounds("2*(t > 1)", None, gdim=2)
    points = np.zeros((3, 3))
    wanted = np.zeros(3, dtype=np.int32)
    assert bounds.clip(wanted, points, 0.5).tolist() == [0, 0, 0]
    assert bounds.clip(wanted, points, 1.5).tolist() == [2, 2, 2]


@pytest.mark.mpi
def test_same_mesh_on_every_rank_count(tmp_path):
    comm = MPI.COMM_WORLD
    model = _model(tmp_path / str(comm.rank), comm, refine_fraction=0.0, coarsen_fraction=0.0,
                   min_level_where="3*(z > 0.75)", max_level_where="1 + 2*(z > 0.5)")
    if comm.rank == 0:
        serial = _model(tmp_path / "serial", MPI.COMM_SELF, refine_fraction=0.0, coarsen_fraction=0.0,
                        min_level_where="3*(z > 0.75)", max_level_where="1 + 2*(z > 0.5)")
    total = model.num_cells
    if comm.rank == 0:
        assert total == serial.num_cells


def test_config_errors():
    base = {"mesh": {"cells": [4, 4]}, "physics": {"Ra": 1.0}, "time": {"end": 1.0}, "output": {"directory": "o"}}
    with pytest.raises(ConfigError, match="'adaptivity.min_level_where': only with adaptivity.enabled"):
        load_config(None, document={**base, "adaptivity": {"min_level_where": "1"}})
    with pytest.raises(ConfigError, match="'adaptivity.max_level_where'"):
        load_config(None, document={**base, "adaptivity": {"enabled": True, "max_level_where": "q"}})
