"""Cell-sorted storage invariants of particles.Swarm."""

import numpy as np
import pytest
from mpi4py import MPI

import dolfinx.mesh

from particles import Swarm


@pytest.fixture
def mesh():
    return dolfinx.mesh.create_unit_square(MPI.COMM_SELF, 4, 4)


def _random_batch(rng, swarm, m, start_id):
    cells = rng.integers(0, swarm.num_owned_cells, m).astype(np.int32)
    return np.arange(start_id, start_id + m), rng.random((m, 2)), rng.random((m, 2)), cells


def test_add_keeps_cells_sorted_and_offsets(mesh):
    rng = np.random.default_rng(1)
    swarm = Swarm(mesh)
    swarm.add_property("c", 1, value=0.0)
    for batch in range(3):
        ids, x, xref, cells = _random_batch(rng, swarm, 50, 50 * batch)
        swarm.add(ids, x, xref, cells, properties=ids[:, None].astype(float))
    swarm.check_invariants()
    assert swarm.num_particles == 150
    for k in range(swarm.num_owned_cells):
        rows = swarm.cell_slice(k)
        assert np.all(swarm.cells[rows] == k)
    # properties travel with their particle through the sort
    assert np.array_equal(swarm.property("c")[:, 0], swarm.ids.astype(float))


def test_remove_and_property_columns(mesh):
    rng = np.random.default_rng(2)
    swarm = Swarm(mesh)
    ids, x, xref, cells = _random_batch(rng, swarm, 40, 0)
    swarm.add(ids, x, xref, cells)
    swarm.add_property("v", 2, value=1.0)
    swarm.add_property("w", 1, value=3.0)
    assert swarm.property("w").shape == (40, 1) and np.all(swarm.property("w") == 3.0)
    swarm.remove_property("v")
    assert swarm.layout("w").start == 0 and swarm.num_property_columns == 1
    removed = swarm.remove(swarm.ids % 2 == 0)
    assert removed == 20 and swarm.num_particles == 20
    swarm.check_invariants()
    with pytest.raises(KeyError, match="known"):
        swarm.property("nope")
