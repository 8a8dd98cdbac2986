"""Energy solver: BDF2 time order (uniform and variable steps), spatial order with SUPG,
consistency of SUPG on exactly representable solutions, history transfer, MPI."""

from __future__ import annotations

import numpy as np
import pytest
import ufl
import dolfinx
from mpi4py import MPI

from convection.physics.approximation import BoussinesqApproximation
from convection.geometry.boundary import TemperatureBC
from convection.geometry.box import SIDES_2D
from convection.solvers.transport import TransportSolver
from fembase.dolfinx_compat import function_space

A_ADV = 2.0
LAMBDA = 2 * np.pi**2 + A_ADV**2 / 4
ZERO_SIDES = {s: TemperatureBC("dirichlet", 0.0) for s in SIDES_2D}


def _decaying_mode(t: float):
    """Exact solution of dT/dt + a dT/dx = lap T, T = 0 on the unit square's boundary:
    T = exp(-lambda t) exp(a x / 2) sin(pi x) sin(pi y), lambda = 2 pi^2 + a^2 / 4."""
    return lambda x: (np.exp(-LAMBDA * t) * np.exp(A_ADV * x[0] / 2)
                      * np.sin(np.pi * x[0]) * np.sin(np.pi * x[1]))


def _velocity(mesh, values):
    V = function_space(mesh, "Lagrange", 2, shape=(mesh.geometry.dim,))
    u = dolfinx.fem.Function(V)
    u.interpolate(values)
    return u


def _uniform_flow(x):
    return np.vstack([np.full(x.shape[1], A_ADV), np.zeros(x.shape[1])])


def _l2(comm, expr) -> float:
    return float(np.sqrt(comm.allreduce(
        dolfinx.fem.assemble_scalar(dolfinx.fem.form(expr * ufl.dx)), op=MPI.SUM)))


def _decay_error(n, degree, dts, comm=MPI.COMM_WORLD, stabilisation="supg"):
    mesh = dolfinx.mesh.create_unit_square(comm, n, n)
    energy = TransportSolver(mesh, BoussinesqApproximation(Ra=1.0), bcs=ZERO_SIDES, degree=degree,
                          stabilisation=stabilisation)
    energy.set_initial(_decaying_mode(0.0))
    u = _velocity(mesh, _uniform_flow)
    orders = [energy.step(u, dt).order for dt in dts]
    assert orders[0] == 1 and set(orders[1:]) <= {2}
    exact = dolfinx.fem.Function(function_space(mesh, "Lagrange", degree + 2))
    exact.interpolate(_decaying_mode(float(np.sum(dts))))
    return _l2(comm, (energy.T - exact) ** 2)


def _steps(num: int, ratio: float, t_final: float = 0.1) -> np.ndarray:
    weights = np.array([1.0 if i % 2 == 0 else ratio for i in range(num)])
    return weights / weights.sum() * t_final


@pytest.mark.parametrize("ratio", [1.0, 2.5])
def test_bdf2_is_second_order_in_time(ratio):
    """Uniform steps and steps alternating in length by a factor 2.5 (variable-step BDF2)."""
    nums = (8, 16, 32)
    errors = [_decay_error(12, 3, _steps(k, ratio)) for k in nums]
    slope = np.polyfit(np.log(1.0 / np.asarray(nums)), np.log(errors), 1)[0]
    assert slope > 1.8, (slope, errors)


def _boundary_layer(n: int, stabilisation: str, a: float = 40.0):
    """Steady -T'' + a T' = 0, T(0) = 1, T(1) = 0 reached by one huge implicit step; returns the
    L2 error and the overshoot max(T) - 1."""
    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_WORLD, n, n)
    bcs = {"left": TemperatureBC("dirichlet", 1.0), "right": TemperatureBC("dirichlet", 0.0)}
    energy = TransportSolver(mesh, BoussinesqApproximation(Ra=1.0), bcs=bcs,
                          stabilisation=stabilisation)
    energy.set_initial(lambda x: 1.0 - x[0])
    u = _velocity(mesh, lambda x: np.vstack([np.full(x.shape[1], a), np.zeros(x.shape[1])]))
    energy.step(u, 1e8)
    x = ufl.SpatialCoordinate(mesh)[0]
    exact = (ufl.exp(a * x) - np.exp(a)) / (1.0 - np.exp(a))
    t_max = mesh.comm.allreduce(np.max(energy.T.x.array), op=MPI.MAX)
    return _l2(mesh.comm, (energy.T - exact) ** 2), t_max - 1.0


@pytest.mark.parametrize("stabilisation", ["supg", "none"])
def test_spatial_order_p2(stabilisation):
    """Steady advection-diffusion with a smooth layer (a = 5): L2 error slope of P2 ~ 3."""
    ns = (8, 16, 32)
    errors = [_boundary_layer(n, stabilisation, a=5.0)[0] for n in ns]
    slope = np.polyfit(np.log(1.0 / np.asarray(ns)), np.log(errors), 1)[0]
    assert slope > 2.8, (slope, errors)


def test_supg_damps_boundary_layer_oscillations():
    """Cell Peclet number a h / 2 = 2.5 at n = 8: Galerkin P2 overshoots by ~7%, SUPG by at most
    a fifth of that, and SUPG converges under refinement."""
    _, overshoot_galerkin = _boundary_layer(8, "none")
    assert overshoot_galerkin > 0.03
    results = [_boundary_layer(n, "supg") for n in (8, 16, 32)]
    assert max(r[1] for r in results) < overshoot_galerkin / 5, (overshoot_galerkin, results)
    assert results[-1][0] < results[0][0] / 10, results


def test_supg_keeps_conduction_profile_exact_under_shear():
    """T = 1 - z with horizontal shear u = (sin(pi z), 0): u . grad T = 0, so T must stay the
    conduction profile to round-off (SUPG is consistent; P2 represents T exactly)."""
    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_WORLD, 8, 8)
    bcs = {"bottom": TemperatureBC("dirichlet", 1.0), "top": TemperatureBC("dirichlet", 0.0)}
    energy = TransportSolver(mesh, BoussinesqApproximation(Ra=1.0), bcs=bcs)
    energy.set_initial(lambda x: 1.0 - x[1])
    u = _velocity(mesh, lambda x: np.vstack([50 * np.sin(np.pi * x[1]), np.zeros(x.shape[1])]))
    for dt in (0.01, 0.02, 0.005):
        energy.step(u, dt)
    z = ufl.SpatialCoordinate(mesh)[1]
    assert _l2(mesh.comm, (energy.T - (1.0 - z)) ** 2) < 1e-10


def test_internal_heating_steady_state():
    """lap T = -H, T = 0 at z = 0, 1: T = H z (1 - z) / 2 (quadratic: exact in P2)."""
    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_WORLD, 4, 4)
    bcs = {"bottom": TemperatureBC("dirichlet", 0.0), "top": TemperatureBC("dirichlet", 0.0)}
    energy = TransportSolver(mesh, BoussinesqApproximation(Ra=1.0, H=3.0), bcs=bcs, solver="direct")
    energy.set_initial(lambda x: np.zeros(x.shape[1]))
    u = _velocity(mesh, lambda x: np.vstack([np.ones(x.shape[1]), np.zeros(x.shape[1])]))
    for _ in range(2):
        energy.step(u, 1e9)
    z = ufl.SpatialCoordinate(mesh)[1]
    assert _l2(mesh.comm, (energy.T - 1.5 * z * (1 - z)) ** 2) < 1e-9


def test_transfer_from_continues_bdf2_history():
    """Stepping, transferring the state to a fresh solver, and stepping on equals stepping on."""
    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_WORLD, 8, 8)
    approx = BoussinesqApproximation(Ra=1.0)
    dts = _steps(6, 1.7, 0.03)
    reference = TransportSolver(mesh, approx, bcs=ZERO_SIDES)
    first = TransportSolver(mesh, approx, bcs=ZERO_SIDES)
    for solver in (reference, first):
        solver.set_initial(_decaying_mode(0.0))
    u = _velocity(mesh, _uniform_flow)
    for dt in dts[:3]:
        reference.step(u, dt)
        first.step(u, dt)
    second = TransportSolver(mesh, approx, bcs=ZERO_SIDES)
    second.transfer_from(first, lambda src, dst: dst.interpolate(src))
    assert second.dt_old == first.dt_old and second.steps == 3
    u2 = _velocity(mesh, _uniform_flow)  # a different velocity Function, as after remeshing
    for dt in dts[3:]:
        assert reference.step(u, dt).order == 2
        assert second.step(u2, dt).order == 2
    assert np.allclose(second.T.x.array, reference.T.x.array, rtol=1e-8, atol=1e-12)


def test_unknown_names_are_rejected():
    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_WORLD, 2, 2)
    approx = BoussinesqApproximation(Ra=1.0)
    with pytest.raises(ValueError, match="valid names"):
        TransportSolver(mesh, approx, bcs={}, stabilisation="upwind")
    with pytest.raises(ValueError, match="valid names"):
        TransportSolver(mesh, approx, bcs={}, solver="magic")
    with pytest.raises(ValueError, match="valid names"):
        TemperatureBC("robin", 1.0)


@pytest.mark.mpi
def test_parallel_decay_error_equals_serial():
    dts = _steps(6, 1.5, 0.05)
    e_parallel = _decay_error(10, 2, dts, comm=MPI.COMM_WORLD)
    e_serial = _decay_error(10, 2, dts, comm=MPI.COMM_SELF)
    assert abs(e_parallel - e_serial) < 1e-7 * e_serial


def _range_between_nodes(T) -> tuple[float, float]:
    """min and max of a P2 field everywhere (its exact P4 interpolant's nodal values), over all ranks."""
    mesh = T.function_space.mesh
    fine = dolfinx.fem.Function(function_space(mesh, "Lagrange", 4))
    fine.interpolate(T)
    values = fine.x.array
    return (mesh.comm.allreduce(float(values.min()), op=MPI.MIN), mesh.comm.allreduce(float(values.max()), op=MPI.MAX))


def test_bounded_initial_temperature_stays_within_the_expression(world):
    """A sharp blob (1 inside a circle, 0 outside) on P2: the nodal interpolant overshoots between the
    nodes by up to 1/8 of the jump (measured -0.124 / 1.125 at the P4 nodes); the bounded one stays in [0, 1] and equals
    the expression at the vertices."""
    from convection.solvers.transport import interpolate_initial

    mesh = dolfinx.mesh.create_unit_square(world, 16, 16)
    blob = lambda x: ((x[0] - 0.5) ** 2 + (x[1] - 0.5) ** 2 < 0.3**2).astype(float)  # noqa: E731
    T = dolfinx.fem.Function(function_space(mesh, "Lagrange", 2))
    interpolate_initial(T, blob)
    low, high = _range_between_nodes(T)
    assert low < -0.1 and high > 1.1
    interpolate_initial(T, blob, bounded=True)
    low, high = _range_between_nodes(T)
    assert low >= -1e-12 and high <= 1.0 + 1e-12
    linear = dolfinx.fem.Function(function_space(mesh, "Lagrange", 1))
    linear.interpolate(blob)
    back = dolfinx.fem.Function(function_space(mesh, "Lagrange", 1))
    back.interpolate(T)
    assert np.allclose(back.x.array, linear.x.array, rtol=0.0, atol=1e-12)  # the vertices keep the expression's values


def test_bounded_initial_temperature_from_a_config():
    """``initial.temperature_bounded: true`` reaches the model's temperature: a hot blob (1) in the
    conductive profile 1 - z (0.5 at its centre's depth), which the boundary values keep: on P2 it
    rises above 1 between the nodes, bounded it stays within [0, 1]."""
    from convection import load_config
    from convection.app.factory import build_model
    from _runs import CONFIGS

    sharp = "where((x - 0.5)**2 + (z - 0.5)**2 < 0.09, 1.0, 1 - z)"
    sets = ["mesh.cells=[12,12]", f"initial.temperature={sharp}"]
    ranges = {}
    for bounded in (False, True):
        config = load_config(CONFIGS / "blankenbach_1a.yaml", [*sets, f"initial.temperature_bounded={bounded}"])
        model = build_model(config)
        ranges[bounded] = _range_between_nodes(model.T)
        model.destroy()
    assert ranges[False][1] > 1.1  # measured 1.175
    assert ranges[True][0] >= -1e-12 and ranges[True][1] <= 1.0 + 1e-12
