"""Particles on a mesh whose nodes move (particles/relocation/moving_mesh.py): every particle found again in the
moved cells, none lost; those the sinking top leaves outside are moved down onto it (with the
swarm's ``inward``) or lost (without); the advection path applies the same rule. Collective checks."""

from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI

import dolfinx.mesh

from fembase.dolfinx_compat import refine_keeping_partition
from fembase.evaluation import locate
from particles import Swarm
from particles.advection import Advector
from particles.relocation.new_mesh import move_to_mesh
from particles.relocation.moving_mesh import follow_mesh


def _swarm(comm, n_per_rank: int = 3000) -> Swarm:
    mesh = dolfinx.mesh.create_unit_square(comm, 16, 16)
    swarm = Swarm(mesh)
    # The same points on every rank, each kept where its cell is owned: the particle set does not
    # depend on the partition (two meshes made in turn may be partitioned differently).
    pts = np.random.default_rng(11).random((n_per_rank * comm.size, 2))
    found = locate(mesh, pts, geometry=swarm.geometry)
    ok = (found.cells >= 0) & (found.cells < swarm.num_owned_cells)
    ids = np.flatnonzero(ok)
    swarm.add(ids, pts[ok], found.xref[ok], found.cells[ok])
    return swarm


def _sink(mesh, amount: float) -> None:
    """The top sinks by ``amount (1 + cos 2 pi x) / 2``, every node in proportion to its height."""
    x = mesh.geometry.x
    x[:, 1] -= x[:, 1] * amount * 0.5 * (1.0 + np.cos(2.0 * np.pi * x[:, 0]))


def _global(comm, value) -> int:
    return comm.allreduce(int(value), op=MPI.SUM)


def _check_located(swarm: Swarm) -> None:
    ok = swarm.cells >= 0
    assert swarm.comm.allreduce(bool(ok.all()), op=MPI.LAND)
    assert np.allclose(swarm.geometry.push_forward(swarm.cells, swarm.xref), swarm.x, atol=1e-12)
    assert np.all(swarm.cells < swarm.num_owned_cells)


def test_follow_mesh_pulls_particles_under_the_sinking_top(world):
    swarm = _swarm(world)
    total = swarm.global_num_particles()
    before = {i: x for part in world.allgather({int(i): x.copy() for i, x in zip(swarm.ids, swarm.x)})
              for i, x in part.items()}  # particles may change rank
    _sink(swarm.mesh, 0.05)
    swarm.inward = lambda x: np.tile([0.0, -1.0], (x.shape[0], 1))
    stats = follow_mesh(swarm)
    assert stats.lost == 0 and swarm.global_num_particles() == total
    _check_located(swarm)
    # The particles under the new top kept their positions; the others only moved down, onto it.
    top = 1.0 - 0.05 * 0.5 * (1.0 + np.cos(2.0 * np.pi * swarm.x[:, 0]))  # the top (at the nodes; linear between)
    moved = np.array([not np.array_equal(before[int(i)], x) for i, x in zip(swarm.ids, swarm.x)], dtype=bool)
    start = np.array([before[int(i)] for i in swarm.ids]).reshape(-1, 2)
    assert np.array_equal(start[moved, 0], swarm.x[moved, 0])
    assert np.all(swarm.x[moved, 1] < start[moved, 1])
    assert np.all(np.abs(swarm.x[moved, 1] - top[moved]) < 2e-3)  # linear between nodes: within the chord's sag
    assert stats.pulled_in == _global(world, moved.sum()) > 0


def test_without_inward_the_passed_particles_are_lost(world):
    kept, lost = _swarm(world), _swarm(world)
    for swarm in (kept, lost):
        _sink(swarm.mesh, 0.05)
    kept.inward = lambda x: np.tile([0.0, -1.0], (x.shape[0], 1))
    a, b = follow_mesh(kept), follow_mesh(lost)
    assert a.lost == 0 and b.pulled_in == 0
    assert b.lost == a.pulled_in > 0


def test_advection_step_pulls_in_particles_that_leave_through_the_top(world):
    """Particles moving up out of the (fixed) top during a step are kept with ``inward``: the same
    count arrives, every one inside."""
    swarm = _swarm(world)
    total = swarm.global_num_particles()
    swarm.inward = lambda x: np.tile([0.0, -1.0], (x.shape[0], 1))
    stats = Advector(swarm, integrator="rk2").step_callable(
        lambda x, t: np.tile([0.0, 0.05], (x.shape[0], 1)), 0.0, 1.0)
    assert stats.global_lost == 0 and swarm.global_num_particles() == total
    assert _global(world, stats.pulled_in) > 0
    _check_located(swarm)
    assert world.allreduce(float(swarm.x[:, 1].max(initial=0.0)), op=MPI.MAX) <= 1.0 + 1e-12


@pytest.mark.parametrize("amount", [0.02, -0.02])
def test_mesh_moved_updates_the_cell_geometry(amount):
    """The cell maps follow the nodes: a particle's push-forward after follow_mesh is its position."""
    swarm = _swarm(MPI.COMM_SELF, 500)
    _sink(swarm.mesh, amount)
    swarm.inward = lambda x: np.tile([0.0, -1.0], (x.shape[0], 1))
    follow_mesh(swarm)
    _check_located(swarm)
    assert np.allclose(swarm.geometry.coords, swarm.mesh.geometry.x[:, :2])


def test_a_move_to_a_coarser_mesh_pulls_in_the_particles_above_its_chords(world):
    """A particle in a fine mesh's raised top cells lies above the coarse mesh's straight top (the
    chord of the fine surface): :func:`particles.relocation.new_mesh.move_to_mesh` moves it down onto that
    top with ``inward``, and loses it without. The fine mesh is refined from the coarse one on each
    cell's rank (as the adaptivity's meshes are)."""
    coarse = dolfinx.mesh.create_unit_square(world, 4, 4)
    fine = refine_keeping_partition(coarse)
    x = fine.geometry.x
    bump = np.isclose(x[:, 1], 1.0) & np.isclose(np.mod(x[:, 0] * 8, 2.0), 1.0)  # x = 1/8, 3/8, ...
    x[bump, 1] += 0.02
    swarm = Swarm(fine)
    # the same points on every rank (just under each raised node, above y = 1), kept where owned
    pts = np.column_stack([np.arange(1, 8, 2) / 8.0, np.full(4, 1.01)])
    found = locate(fine, pts, geometry=swarm.geometry)
    ok = (found.cells >= 0) & (found.cells < swarm.num_owned_cells)
    swarm.add(np.flatnonzero(ok), pts[ok], found.xref[ok], found.cells[ok])
    assert swarm.global_num_particles() == 4
    counts = {}
    for inward in (True, False):
        swarm.inward = (lambda p: np.tile([0.0, -1.0], (p.shape[0], 1))) if inward else None
        moved, stats = move_to_mesh(swarm, coarse)
        counts[inward] = stats
        if inward:
            assert moved.global_num_particles() == 4
            _check_located(moved)
            assert np.all(np.abs(moved.x[:, 1] - 1.0) < 1e-12)  # on the top, inside to round-off
    assert counts[True].pulled_in == 4 and counts[True].lost == 0
    assert counts[False].pulled_in == 0 and counts[False].lost == 4
