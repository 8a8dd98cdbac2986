"""RK2 advection across ranks: nothing lost or duplicated, positions equal to a 1-rank run."""

import numpy as np
import pytest
from mpi4py import MPI

import dolfinx.fem
import dolfinx.mesh

from _helpers import plugin
from fembase.dolfinx_compat import function_space
from particles import Swarm
from particles.advection import Advector
from particles.generation import RandomUniform, generate

N_CELLS = 16
N_PARTICLES = 1200
N_STEPS = 200


def _cellular_flow(x):
    """u = curl of psi = sin^2(pi x) sin^2(pi y) / pi: one closed vortex, zero velocity on the walls."""
    sx, cx = np.sin(np.pi * x[0]), np.cos(np.pi * x[0])
    sy, cy = np.sin(np.pi * x[1]), np.cos(np.pi * x[1])
    return np.stack([2.0 * sx * sx * sy * cy, -2.0 * sx * cx * sy * sy])


def _advect(comm):
    mesh = dolfinx.mesh.create_unit_square(comm, N_CELLS, N_CELLS)
    V = function_space(mesh, "Lagrange", 2, shape=(mesh.geometry.dim,))
    u = dolfinx.fem.Function(V)
    u.interpolate(_cellular_flow)
    swarm = Swarm(mesh)
    generate(swarm, plugin(RandomUniform, N_PARTICLES, seed=17))
    ids0 = np.sort(np.concatenate(comm.allgather(swarm.ids)))
    umax = 1.0  # max |u| of the cellular flow
    dt = 0.5 * (1.0 / N_CELLS) / umax  # CFL 0.5
    advector = Advector(swarm, integrator="rk2")
    sent = lost = 0
    for _ in range(N_STEPS):
        stats = advector.step(u, u, dt)
        sent += stats.sent
        lost += stats.global_lost
    swarm.check_invariants()
    ids = np.concatenate(comm.allgather(swarm.ids))
    x = np.concatenate(comm.allgather(swarm.x))
    order = np.argsort(ids)
    return ids0, ids[order], x[order], comm.allreduce(sent), lost


@pytest.mark.mpi
def test_rk2_rotation_conserves_particles_and_matches_serial():
    comm = MPI.COMM_WORLD
    ids0, ids, x, sent, lost = _advect(comm)
    ref_ids0, ref_ids, ref_x, _, ref_lost = _advect(MPI.COMM_SELF)
    assert sent > 0  # particles really crossed rank boundaries
    assert lost == ref_lost == 0
    np.testing.assert_array_equal(ids0, np.arange(N_PARTICLES))
    np.testing.assert_array_equal(ids, ids0)
    np.testing.assert_array_equal(ref_ids, ids0)
    np.testing.assert_allclose(x, ref_x, rtol=0.0, atol=1e-12)
    # The flow really moved the particles (half a turn or more near the centre).
    assert np.max(np.linalg.norm(x - _initial_positions(comm), axis=1)) > 0.3


def _initial_positions(comm):
    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_SELF, N_CELLS, N_CELLS)
    swarm = Swarm(mesh)
    generate(swarm, plugin(RandomUniform, N_PARTICLES, seed=17))
    return swarm.x[np.argsort(swarm.ids)]
