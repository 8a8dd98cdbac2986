"""Runge-Kutta advection: convergence orders on rigid rotation, closed-form error, time dependence."""

import math

import numpy as np
import pytest
from mpi4py import MPI

import dolfinx.fem
import dolfinx.mesh

from _helpers import swarm_at
from fembase.dolfinx_compat import function_space
from particles.advection import INTEGRATORS, Advector, get_integrator

OMEGA = 2.0 * math.pi
RADIUS = 0.3


def _square(comm=MPI.COMM_SELF, n=8):
    return dolfinx.mesh.create_rectangle(comm, [np.array([-1.0, -1.0]), np.array([1.0, 1.0])], [n, n])


def _ring_swarm(mesh, count=8):
    phi = 2 * np.pi * (np.arange(count) + 0.25) / count
    return swarm_at(mesh, RADIUS * np.stack([np.cos(phi), np.sin(phi)], axis=1))


def _rotation(mesh, omega=OMEGA, degree=1):
    V = function_space(mesh, "Lagrange", degree, shape=(mesh.geometry.dim,))
    u = dolfinx.fem.Function(V)
    u.interpolate(lambda x: np.stack([-omega * x[1], omega * x[0]]))
    return u


def _revolution_error(name, steps, mesh, u):
    swarm = _ring_swarm(mesh)
    x0 = {int(i): p.copy() for i, p in zip(swarm.ids, swarm.x)}
    adv = Advector(swarm, integrator=name)
    for _ in range(steps):
        adv.step(u, u, 1.0 / steps)
    swarm.check_invariants()
    return max(np.linalg.norm(p - x0[int(i)]) for i, p in zip(swarm.ids, swarm.x))


def _closed_form(order, steps):
    z = 1j * OMEGA / steps
    amplification = sum(z**k / math.factorial(k) for k in range(order + 1))
    return abs(amplification**steps - 1.0) * RADIUS


@pytest.mark.parametrize(
    "name, steps",
    [("euler", [400, 800, 1600, 3200]), ("rk2", [50, 100, 200, 400]), ("rk4", [20, 40, 80, 160])],
)
def test_rigid_rotation_order_and_closed_form(name, steps):
    mesh = _square()
    u = _rotation(mesh)  # linear: reproduced exactly by P1
    order = get_integrator(name).order
    errors = np.array([_revolution_error(name, n, mesh, u) for n in steps])
    slope = -np.polyfit(np.log(steps), np.log(errors), 1)[0]
    assert abs(slope - order) < 0.1, (slope, errors)
    exact = np.array([_closed_form(order, n) for n in steps])
    assert np.allclose(errors, exact, rtol=1e-6), (errors, exact)


def test_time_dependent_rotation_linear_interpolation_caps_order():
    """omega(t) = 1.5 pi (1 + t^2) turns by exactly 2 pi over t in [0, 1]."""
    mesh = _square()
    V = function_space(mesh, "Lagrange", 1, shape=(mesh.geometry.dim,))

    def field(t):
        f = dolfinx.fem.Function(V)
        w = 1.5 * np.pi * (1 + t * t)
        f.interpolate(lambda x: np.stack([-w * x[1], w * x[0]]))
        return f

    def exact_velocity(x, t):
        w = 1.5 * np.pi * (1 + t * t)
        return np.stack([-w * x[:, 1], w * x[:, 0]], axis=1)

    slopes = {}
    for name in ("rk2", "rk4"):
        for exact_in_time in (False, True):
            errors, steps = [], [40, 80, 160]
            for n in steps:
                swarm = _ring_swarm(mesh)
                start = dict(zip(swarm.ids.tolist(), swarm.x.copy()))
                adv = Advector(swarm, integrator=name)
                dt = 1.0 / n
                u_new = field(0.0)
                for i in range(n):
                    u_old, u_new = u_new, field((i + 1) * dt)
                    if exact_in_time:
                        adv.step_callable(exact_velocity, i * dt, dt)
                    else:
                        adv.step(u_old, u_new, dt)
                errors.append(max(np.linalg.norm(p - start[i]) for i, p in zip(swarm.ids.tolist(), swarm.x)))
            slopes[name, exact_in_time] = -np.polyfit(np.log(steps), np.log(errors), 1)[0]
    assert abs(slopes["rk2", False] - 2) < 0.15
    assert abs(slopes["rk4", False] - 2) < 0.15  # linear-in-time velocity: O(dt^2)
    assert abs(slopes["rk2", True] - 2) < 0.15
    assert abs(slopes["rk4", True] - 4) < 0.2


def test_unknown_integrator_lists_valid_names():
    with pytest.raises(ValueError, match="euler.*rk2.*rk4"):
        get_integrator("rk3")
    assert set(INTEGRATORS) == {"euler", "rk2", "rk4"}


def test_stage_columns_removed_and_properties_kept():
    mesh = _square()
    swarm = _ring_swarm(mesh)
    swarm.add_property("tag", 1)
    swarm.property("tag")[:, 0] = swarm.ids
    adv = Advector(swarm, integrator="rk4")
    stats = adv.step(_rotation(mesh), _rotation(mesh), 0.05)
    assert swarm.property_names == ["tag"]
    assert np.array_equal(swarm.property("tag")[:, 0], swarm.ids)
    assert sum(stats.transport) == 4 * swarm.num_particles and stats.lost == 0


@pytest.mark.mpi
def test_rotation_across_ranks_carries_stage_data():
    comm = MPI.COMM_WORLD
    mesh = _square(comm, n=12)
    u = _rotation(mesh)
    swarm = _ring_swarm(mesh, count=64)
    n0 = swarm.global_num_particles()
    start = {int(i): p for i, p in zip(np.concatenate(comm.allgather(swarm.ids)),
                                        np.concatenate(comm.allgather(swarm.x)))}
    adv = Advector(swarm, integrator="rk4")
    steps = 40
    sent = 0
    for _ in range(steps):
        sent += adv.step(u, u, 1.0 / steps).sent
    err = max((np.linalg.norm(p - start[int(i)]) for i, p in zip(swarm.ids, swarm.x)), default=0.0)
    assert comm.allreduce(sent, op=MPI.SUM) > 0
    assert swarm.global_num_particles() == n0 == 64
    assert comm.allreduce(err, op=MPI.MAX) == pytest.approx(_closed_form(4, steps), rel=1e-6)
    assert comm.allreduce(swarm.property_names == [], op=MPI.LAND)
