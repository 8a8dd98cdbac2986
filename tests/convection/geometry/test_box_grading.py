"""``mesh.grading``: a box's cells bunched towards both ends of an axis (the map
``s - g sin(2 pi s) / (2 pi)`` per direction). The mesh fills the same box, its nodes are the map of
the uniform ones, the cells at the ends are ``1 - g`` and those in the middle ``1 + g`` times the
uniform size, on any rank count; the config checks refuse a grading of the wrong length or size."""

from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI

from convection.geometry.box import BoxDomain, BoxSpec, graded
from convection.geometry.mesh import cell_volumes


def test_the_map_fixes_the_ends_and_the_middle_and_is_monotone():
    s = np.linspace(0.0, 1.0, 1001)
    for g in (0.0, 0.3, 0.9):
        y = graded(s, g)
        np.testing.assert_allclose(y[[0, 500, -1]], [0.0, 0.5, 1.0], atol=1e-15)
        assert np.all(np.diff(y) > 0)
        slope = np.gradient(y, s)
        assert slope[0] == pytest.approx(1.0 - g, abs=1e-5)
        assert slope[500] == pytest.approx(1.0 + g, abs=1e-5)


@pytest.mark.parametrize("cell_type", ["simplex", "box"])
def test_a_graded_box_fills_the_box_with_cells_bunched_at_the_ends(world, cell_type):
    """Collective: volume, extent and the vertical node positions of a 3D box graded in z."""
    n, g = 10, 0.5
    spec = BoxSpec((4, 3, n), (0.0, -1.0, 2.0), (2.0, 0.5, 3.0), cell_type=cell_type, grading=(0.0, 0.0, g))
    mesh = BoxDomain.from_spec(spec).create_mesh(world)
    num_owned = mesh.topology.index_map(3).size_local
    volume = world.allreduce(float(np.sum(cell_volumes(mesh)[:num_owned])), op=MPI.SUM)
    assert volume == pytest.approx(2.0 * 1.5 * 1.0, rel=1e-12)
    x = mesh.geometry.x
    lo = world.allreduce(float(x[:, 2].min()), op=MPI.MIN)
    hi = world.allreduce(float(x[:, 2].max()), op=MPI.MAX)
    assert (lo, hi) == pytest.approx((2.0, 3.0), abs=1e-14)
    heights = np.unique(np.round(np.concatenate(world.allgather(x[:, 2])), 12))
    np.testing.assert_allclose(heights, 2.0 + graded(np.linspace(0.0, 1.0, n + 1), g), atol=1e-12)
    layers = np.diff(heights)
    assert layers[0] == pytest.approx(layers[-1], rel=1e-12)
    assert layers[0] < (1.0 - g / 2) / n < (1.0 + g / 2) / n < layers[n // 2]
    # x and y are not graded
    np.testing.assert_allclose(np.unique(np.round(np.concatenate(world.allgather(x[:, 0])), 12)),
                               np.linspace(0.0, 2.0, 5), atol=1e-12)


def test_grading_is_checked_with_the_config(tmp_path):
    from convection.config.loader import load_config
    from convection.schema import ConfigError

    base = {"name": "g", "mesh": {"cells": [8, 8]}, "physics": {"Ra": 1.0e4}, "time": {"end": 0.1},
            "output": {"directory": str(tmp_path)}}
    config = load_config(None, document={**base, "mesh": {"cells": [8, 8], "grading": [0, 0.5]}})
    assert tuple(config["mesh"]["grading"]) == (0, 0.5)
    with pytest.raises(ConfigError, match="mesh.grading'.*2 entries like mesh.cells"):
        load_config(None, document={**base, "mesh": {"cells": [8, 8], "grading": [0, 0, 0.5]}})
    with pytest.raises(ConfigError, match=r"mesh.grading\[1\]'.*<= 0.9"):
        load_config(None, document={**base, "mesh": {"cells": [8, 8], "grading": [0, 0.95]}})
    with pytest.raises(ConfigError, match="not graded"):
        load_config(None, document={**base, "mesh": {"cells": [8, 8], "grading": [0, 0.5]},
                                    "stokes": {"solver": "multigrid"}})
