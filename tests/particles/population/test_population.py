"""Population control: bounds per cell, unique ids, counts, property initialisation, rank independence."""

import numpy as np
import pytest
from mpi4py import MPI

import dolfinx.mesh

from particles import Swarm
from particles.generation import generate
from particles.population.control import PopulationControl, control_population


def _swarm(comm, n=8, num=600, seed=2):
    mesh = dolfinx.mesh.create_unit_square(comm, n, n)
    swarm = Swarm(mesh)
    # strongly varying density: crowded on the left, empty cells on the right
    generate(swarm, "random_density", num_particles=num, seed=seed, density=lambda x: np.exp(-12.0 * x[:, 0]))
    swarm.add_property("tag")
    swarm.add_property("vec", 2)
    swarm.property("tag")[:, 0] = swarm.ids
    swarm.property("vec")[:] = swarm.x
    return swarm


def _gathered(comm, swarm):
    ids = np.concatenate(comm.allgather(swarm.ids))
    x = np.concatenate(comm.allgather(swarm.x))
    props = np.concatenate(comm.allgather(swarm.properties))
    order = np.argsort(ids)
    return ids[order], x[order], props[order]


def _inside_own_cells(swarm):
    return bool(np.allclose(swarm.geometry.push_forward(swarm.cells, swarm.xref), swarm.x, atol=1e-12)
                and np.all(swarm.geometry.inside(swarm.xref)))


def test_bounds_ids_and_default_initialisation():
    swarm = _swarm(MPI.COMM_SELF)
    counts = swarm.particles_per_cell()
    assert counts.max() > 12 and counts.min() == 0
    old_ids, old_x, old_props = swarm.ids.copy(), swarm.x.copy(), swarm.properties.copy()
    old_cells = swarm.cells.copy()
    stats = control_population(swarm, min_per_cell=4, max_per_cell=12, seed=7, step=3)
    counts = swarm.particles_per_cell()
    assert counts.min() >= 4 and counts.max() <= 12
    swarm.check_invariants()
    assert _inside_own_cells(swarm)
    assert stats.added > 0 and stats.removed > 0
    assert stats.global_after - stats.global_before == stats.added - stats.removed == \
        swarm.num_particles - old_ids.shape[0]
    new = swarm.ids > old_ids.max()
    assert np.count_nonzero(new) == stats.added
    assert np.array_equal(np.sort(swarm.ids[new]), old_ids.max() + 1 + np.arange(stats.added))
    # default hook: nearest old particle of the same cell (brute force), else finite filled values
    had_old = np.bincount(old_cells, minlength=swarm.num_owned_cells) > 0
    rows = np.flatnonzero(new)
    for r in rows[had_old[swarm.cells[rows]]][:50]:
        same = np.flatnonzero(old_cells == swarm.cells[r])
        nearest = same[np.argmin(np.linalg.norm(old_x[same] - swarm.x[r], axis=1))]
        assert np.array_equal(swarm.properties[r], old_props[nearest])
    orphans = rows[~had_old[swarm.cells[rows]]]
    assert orphans.size > 0 and np.all(np.isfinite(swarm.properties[orphans]))
    assert np.all(swarm.property("vec")[orphans, 0] <= old_x[:, 0].max() + 1e-12)


def test_deterministic_and_hook():
    a, b, c = _swarm(MPI.COMM_SELF), _swarm(MPI.COMM_SELF), _swarm(MPI.COMM_SELF)
    seen = []

    def hook(swarm, rows):
        seen.append(rows.copy())
        swarm.property("tag")[rows, 0] = -1.0

    control_population(a, min_per_cell=3, max_per_cell=6, seed=1, step=5, initialise=hook)
    control_population(b, min_per_cell=3, max_per_cell=6, seed=1, step=5)
    control_population(c, min_per_cell=3, max_per_cell=6, seed=1, step=6)
    assert np.array_equal(a.ids, b.ids) and np.array_equal(a.x, b.x)
    assert not np.array_equal(np.sort(a.ids), np.sort(c.ids)) or not np.allclose(np.sort(a.x[:, 0]), np.sort(c.x[:, 0]))
    assert np.array_equal(np.flatnonzero(a.property("tag")[:, 0] == -1.0), seen[0])
    assert np.all(a.ids[seen[0]] >= 600)


def test_parameters_validated():
    with pytest.raises(ValueError):
        PopulationControl(min_per_cell=-1)
    with pytest.raises(ValueError):
        PopulationControl(min_per_cell=5, max_per_cell=4)
    swarm = _swarm(MPI.COMM_SELF)
    stats = PopulationControl().apply(swarm)
    assert stats.global_added == stats.global_removed == 0


@pytest.mark.mpi
def test_parallel_bounds_ids_and_rank_independence():
    comm = MPI.COMM_WORLD
    swarm = _swarm(comm)
    before = swarm.global_num_particles()
    stats = control_population(swarm, min_per_cell=4, max_per_cell=10, seed=3, step=1)
    counts = swarm.particles_per_cell()
    lo = comm.allreduce(int(counts.min(initial=10**9)), op=MPI.MIN)
    hi = comm.allreduce(int(counts.max(initial=0)), op=MPI.MAX)
    ok_cells = comm.allreduce(_inside_own_cells(swarm), op=MPI.LAND)
    ids, x, props = _gathered(comm, swarm)
    serial = _swarm(MPI.COMM_SELF)
    s_stats = control_population(serial, min_per_cell=4, max_per_cell=10, seed=3, step=1)
    s_order = np.argsort(serial.ids)
    same = ids.shape == serial.ids.shape and np.array_equal(ids, serial.ids[s_order]) and \
        np.allclose(x, serial.x[s_order], atol=1e-13) and np.allclose(props, serial.properties[s_order], atol=1e-12)
    assert lo >= 4 and hi <= 10 and ok_cells
    assert np.unique(ids).shape[0] == ids.shape[0]
    assert stats.global_after == ids.shape[0] == before + stats.global_added - stats.global_removed
    assert stats.global_added == comm.allreduce(stats.added) and stats.global_removed == comm.allreduce(stats.removed)
    assert stats.global_added > 0 and stats.global_removed > 0
    assert (stats.global_added, stats.global_removed) == (s_stats.global_added, s_stats.global_removed)
    assert comm.allreduce(bool(same), op=MPI.LAND)
