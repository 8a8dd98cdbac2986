"""Migration of particles between ranks: ghost-cell path, global fallback, lost particles."""

import numpy as np
import pytest
from mpi4py import MPI

import dolfinx.geometry
import dolfinx.mesh

from fembase.dolfinx_compat import bounding_box_tree, compute_collisions
from fembase.geometry import cell_nodes, locate_owned, pull_back, push_forward
from particles import Swarm
from particles.parallel.migration import Migrator, migrate, migrator_for


def _locate_local(mesh, x):
    """Owned or ghost local cell containing each point (-1 if none), like a transport step would."""
    tdim = mesh.topology.dim
    cmap = mesh.topology.index_map(tdim)
    n = cmap.size_local + cmap.num_ghosts
    points = np.zeros((x.shape[0], 3))
    points[:, : x.shape[1]] = x
    tree = bounding_box_tree(mesh, tdim, np.arange(n, dtype=np.int32))
    colliding = dolfinx.geometry.compute_colliding_cells(mesh, compute_collisions(tree, points), points)
    cells = np.full(x.shape[0], -1, dtype=np.int32)
    for i in range(x.shape[0]):
        links = colliding.links(i)
        if len(links):
            cells[i] = links.min()
    return cells


def _midpoint_swarm(mesh):
    swarm = Swarm(mesh)
    swarm.add_property("tag", 2)
    owned = np.arange(swarm.num_owned_cells, dtype=np.int32)
    x = cell_nodes(mesh, owned).mean(axis=1)
    ids = np.asarray(mesh.topology.original_cell_index, dtype=np.int64)[owned]
    props = np.stack([2.0 * ids, -1.0 * ids], axis=1)
    swarm.add(ids, x, pull_back(mesh, owned, x), owned, props)
    return swarm


def _gather_ids(comm, ids):
    return np.sort(np.concatenate(comm.allgather(ids)))


def _moved(ids, x):
    """Small shift (neighbour), point reflection (far: fallback), far outside (lost), or stay."""
    x = x.copy()
    kind = ids % 4
    x[kind == 0] += np.array([0.09, 0.05])
    x[kind == 1] = 1.0 - x[kind == 1]
    x[kind == 2] += np.array([3.0, 0.0])
    x = np.clip(x, -10.0, 10.0)
    x[(kind == 0)] = np.clip(x[kind == 0], 0.0, 1.0)
    return x


def _check_owned_and_contained(swarm):
    mesh = swarm.mesh
    ok = True
    try:
        swarm.check_invariants()
    except AssertionError:
        ok = False
    loc = locate_owned(mesh, swarm.x)
    ok &= bool(np.all(loc.cells >= 0))
    # The particle's own cell contains it: x = Phi_K(xref) and xref in the reference triangle.
    ok &= bool(np.allclose(push_forward(mesh, swarm.cells, swarm.xref), swarm.x, atol=1e-12))
    xr = swarm.xref
    ok &= bool(np.all(xr >= -1e-10) and np.all(xr.sum(axis=1) <= 1 + 1e-10))
    return ok


def _move_and_locate_locally(comm, mesh, swarm, x) -> int:
    """Move the particles to ``x``, locate them in this rank's local cells only (-1 elsewhere),
    sort; returns the global number left unlocated (for migration to resolve)."""
    swarm.x = x
    swarm.cells = _locate_local(mesh, swarm.x)
    inside = swarm.cells >= 0
    swarm.xref = np.full_like(swarm.xref, np.nan)
    swarm.xref[inside] = pull_back(mesh, swarm.cells[inside], swarm.x[inside])
    swarm.sort()
    return comm.allreduce(int(np.count_nonzero(~inside)), op=MPI.SUM)


def _into_ghost_cells(mesh, ids, x):
    """Move "staying" particles (ids % 4 == 3) to the midpoints of this rank's ghost cells, one
    each, so that some particles land in ghost cells whatever the partition (the shift of
    :func:`_moved` may reach none: seen with DOLFINx 0.11's partition on 3 ranks)."""
    im = mesh.topology.index_map(mesh.topology.dim)
    ghosts = np.arange(im.size_local, im.size_local + im.num_ghosts, dtype=np.int32)
    staying = np.flatnonzero(ids % 4 == 3)[: ghosts.size]
    x = x.copy()
    x[staying] = dolfinx.mesh.compute_midpoints(mesh, mesh.topology.dim, ghosts[: staying.size])[:, :2]
    return x


def _run_migration(comm, ghost_mode=dolfinx.mesh.GhostMode.shared_facet, *, into_ghosts=False):
    mesh = dolfinx.mesh.create_unit_square(comm, 12, 12, ghost_mode=ghost_mode)
    swarm = _midpoint_swarm(mesh)
    n0 = swarm.global_num_particles()
    ids0 = _gather_ids(comm, swarm.ids)
    x = _moved(swarm.ids, swarm.x)
    if into_ghosts:
        x = _into_ghost_cells(mesh, swarm.ids, x)
    n_unlocated = _move_and_locate_locally(comm, mesh, swarm, x)
    stats = migrate(swarm)
    return mesh, swarm, n0, ids0, stats, n_unlocated


@pytest.mark.mpi
@pytest.mark.parametrize("ghost_mode", [dolfinx.mesh.GhostMode.shared_facet, dolfinx.mesh.GhostMode.none])
def test_migrate_ghost_fallback_lost(ghost_mode):
    comm = MPI.COMM_WORLD
    mesh, swarm, n0, ids0, stats, n_unlocated = _run_migration(comm, ghost_mode, into_ghosts=True)
    expected_lost = ids0[ids0 % 4 == 2]
    ids = _gather_ids(comm, swarm.ids)
    ok = _check_owned_and_contained(swarm)
    ok &= bool(np.allclose(swarm.property("tag"), np.stack([2.0 * swarm.ids, -1.0 * swarm.ids], axis=1)))
    assert comm.allreduce(ok, op=MPI.LAND)
    assert stats.global_lost == expected_lost.shape[0]
    assert swarm.global_num_particles() == n0 - stats.global_lost
    np.testing.assert_array_equal(ids, np.setdiff1d(ids0, expected_lost))
    assert stats.global_fallback_sent > 0
    assert (stats.global_sent > 0) == (ghost_mode == dolfinx.mesh.GhostMode.shared_facet)
    assert stats.global_received == stats.global_sent + n_unlocated - stats.global_lost


@pytest.mark.mpi
def test_migrate_positions_preserved():
    """Every particle arrives with exactly the position it was given (compare with serial)."""
    comm = MPI.COMM_WORLD
    _, swarm, _, _, _, _ = _run_migration(comm)
    ids = np.concatenate(comm.allgather(swarm.ids))
    x = np.concatenate(comm.allgather(swarm.x))
    _, serial, _, _, _, _ = _run_migration(MPI.COMM_SELF)
    order, sorder = np.argsort(ids), np.argsort(serial.ids)
    np.testing.assert_array_equal(ids[order], serial.ids[sorder])
    np.testing.assert_array_equal(x[order], serial.x[sorder])


@pytest.mark.mpi
def test_migrator_neighbours_symmetric():
    comm = MPI.COMM_WORLD
    mesh = dolfinx.mesh.create_unit_square(comm, 6, 6)
    m = migrator_for(mesh)
    assert migrator_for(mesh) is m
    pairs = comm.allgather([int(r) for r in m.neighbours])
    assert all(comm.rank in pairs[r] for r in pairs[comm.rank])
    assert comm.rank not in pairs[comm.rank]


def test_migrate_serial_removes_unlocated():
    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_SELF, 4, 4)
    swarm = _midpoint_swarm(mesh)
    n = swarm.num_particles
    swarm.cells[:3] = -1
    swarm.sort()
    stats = migrate(swarm, migrator=Migrator(mesh))
    assert stats.lost == stats.global_lost == 3
    assert stats.sent == stats.received == 0
    assert swarm.num_particles == n - 3
    swarm.check_invariants()


@pytest.mark.mpi
def test_fallback_points_on_partition_boundaries_kept_once():
    """Unlocated particles at mesh vertices (many shared by ranks): each kept by the lowest finder."""
    comm = MPI.COMM_WORLD
    mesh = dolfinx.mesh.create_unit_square(comm, 6, 6, ghost_mode=dolfinx.mesh.GhostMode.none)
    swarm = Swarm(mesh)
    vertices = np.array([[i / 6, j / 6] for i in range(7) for j in range(7)])
    if comm.rank == 0:
        # Rank 0 offers all of them; only other ranks are candidates.
        swarm.add(np.arange(49), vertices, np.full((49, 2), np.nan), np.full(49, -1, dtype=np.int32))
    stats = migrate(swarm)
    found = locate_owned(mesh, vertices).cells >= 0 if comm.rank > 0 else np.zeros(49, dtype=bool)
    found_by = np.array(comm.allgather(found))  # (size, 49)
    finder = np.where(found_by.any(axis=0), np.argmax(found_by, axis=0), -1)
    holders = np.concatenate([np.full(len(i), r) for r, i in enumerate(comm.allgather(swarm.ids))])
    ids = np.concatenate(comm.allgather(swarm.ids))
    ok = comm.allreduce(_check_owned_and_contained(swarm), op=MPI.LAND)
    assert ok
    np.testing.assert_array_equal(np.sort(ids), np.flatnonzero(finder >= 0))
    np.testing.assert_array_equal(holders, finder[ids])
    assert stats.global_lost == np.count_nonzero(finder < 0)
    if comm.size > 2:
        assert np.any(found_by.sum(axis=0) > 1)  # the tie rule was exercised


@pytest.mark.mpi
def test_migrate_without_sort_then_sort_matches_sorted_migration():
    """migrate(sort=False) leaves arrived rows appended and departed rows marked; the sort after it
    gives exactly what migrate() gives (same rows in the same order), and the stage table travels."""
    comm = MPI.COMM_WORLD
    results = []
    mesh = dolfinx.mesh.create_unit_square(comm, 12, 12)
    for sort in (True, False):
        swarm = _midpoint_swarm(mesh)
        swarm.x = _moved(swarm.ids, swarm.x)
        swarm.cells = _locate_local(mesh, swarm.x)
        inside = swarm.cells >= 0
        swarm.xref = np.full_like(swarm.xref, np.nan)
        swarm.xref[inside] = pull_back(mesh, swarm.cells[inside], swarm.x[inside])
        swarm.stage_table(3)[:] = swarm.ids[:, None] * np.array([1.0, -1.0, 0.5])
        n_before = swarm.num_particles
        stats = migrate(swarm, sort=sort)
        if not sort:
            assert swarm.num_particles == n_before + stats.received  # departed rows still counted
            swarm.sort()
        results.append((swarm.ids.copy(), swarm.x.copy(), swarm.stage.copy(), swarm.offsets.copy(), stats))
        ok = _check_owned_and_contained(swarm)
        ok &= bool(np.array_equal(swarm.stage, swarm.ids[:, None] * np.array([1.0, -1.0, 0.5])))
        assert comm.allreduce(ok, op=MPI.LAND)
    for a, b in zip(results[0][:4], results[1][:4]):
        np.testing.assert_array_equal(a, b)
    assert results[0][4] == results[1][4]


@pytest.mark.mpi
def test_unlocated_particles_settled_by_neighbours_without_the_global_fallback(monkeypatch):
    """On two ranks the other rank is every unlocated particle's only candidate and a neighbour: the
    particles travel with the ghost-cell messages and the collective fallback never runs."""
    comm = MPI.COMM_WORLD
    if comm.size != 2:
        pytest.skip("needs exactly two ranks")
    calls = []
    original = Migrator._fallback
    monkeypatch.setattr(Migrator, "_fallback", lambda self, *a: calls.append(1) or original(self, *a))
    mesh = dolfinx.mesh.create_unit_square(comm, 12, 12)
    swarm = _midpoint_swarm(mesh)
    ids0 = _gather_ids(comm, swarm.ids)
    # point reflection: most particles land far from their rank's cells
    n_unlocated = _move_and_locate_locally(comm, mesh, swarm, 1.0 - swarm.x)
    stats = migrate(swarm, migrator=Migrator(mesh))
    assert n_unlocated > 0 and stats.global_fallback_sent == n_unlocated
    assert comm.allreduce(len(calls), op=MPI.SUM) == 0
    assert stats.global_lost == 0
    np.testing.assert_array_equal(_gather_ids(comm, swarm.ids), ids0)
    assert comm.allreduce(_check_owned_and_contained(swarm), op=MPI.LAND)
    ok = bool(np.allclose(swarm.property("tag"), np.stack([2.0 * swarm.ids, -1.0 * swarm.ids], axis=1)))
    assert comm.allreduce(ok, op=MPI.LAND)
