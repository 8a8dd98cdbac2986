"""Stokes solver: manufactured-solution convergence orders, null space, variable viscosity, MPI."""

from __future__ import annotations

import numpy as np
import pytest
import ufl
import dolfinx
from mpi4py import MPI

from convection.physics.approximation import BoussinesqApproximation, ViscosityLaw
from convection.geometry.boundary import VelocityBC
from convection.geometry.box import SIDES_2D, SIDES_3D
from convection.solvers.stokes.solver import StokesSolver
from convection.solvers.petsc_options import HAS_HYPRE
from _helpers import ITERATIVE, needs_hypre

FREE_SLIP = {s: VelocityBC("free_slip") for s in SIDES_2D}
NO_SLIP = {s: VelocityBC("no_slip") for s in SIDES_2D}


def _integral(comm, expr) -> float:
    return comm.allreduce(dolfinx.fem.assemble_scalar(dolfinx.fem.form(expr)), op=MPI.SUM)


def _manufactured(kind: str, x):
    """Exact (u, p, eta, C, law, bcs) whose body force is purely vertical, so it can be expressed
    as the buoyancy Ra T e_z with T = f_z / Ra.

    The horizontal momentum balance -div(2 eta eps(u))_x + p_x = 0 is solved for p by integrating
    in x: for u = curl(f(x) g(y)) and eta = eta(y) (with f = g = sin(pi s) the shear strain
    f g'' - f'' g vanishes) this gives the closed forms below.
    """
    pi = ufl.pi
    if kind == "no_slip":
        u = ufl.as_vector([pi * ufl.sin(pi * x[0]) ** 2 * ufl.sin(2 * pi * x[1]),
                           -pi * ufl.sin(2 * pi * x[0]) * ufl.sin(pi * x[1]) ** 2])
        p = 2 * pi**2 * ufl.sin(2 * pi * x[0]) * ufl.sin(2 * pi * x[1]) \
            - 2 * pi**3 * x[0] * ufl.sin(2 * pi * x[1])
        return u, p, 1.0, None, ViscosityLaw(), NO_SLIP
    u = ufl.as_vector([pi * ufl.sin(pi * x[0]) * ufl.cos(pi * x[1]),
                       -pi * ufl.cos(pi * x[0]) * ufl.sin(pi * x[1])])
    if kind == "free_slip":
        eta, C, law = 1.0, None, ViscosityLaw()
    elif kind == "variable_viscosity":
        # geometric mixing of (0.1, 10) with C = y: eta = 0.1 * 100**y, a 100x contrast.
        eta, C, law = 0.1 * ufl.exp(x[1] * np.log(100.0)), x[1], ViscosityLaw((0.1, 10.0))
    else:
        raise ValueError(kind)
    p = 2 * pi**2 * eta * ufl.cos(pi * x[0]) * ufl.cos(pi * x[1])
    return u, p, eta, C, law, FREE_SLIP


def _errors(n: int, kind: str, solver: str, comm=MPI.COMM_WORLD, Ra: float = 10.0, petsc_options=None):
    """L2 errors of velocity and (mean-free) pressure, the solve result and the solver, on an n x n
    mesh."""
    mesh = dolfinx.mesh.create_unit_square(comm, n, n)
    x = ufl.SpatialCoordinate(mesh)
    u_ex, p_ex, eta, C, law, bcs = _manufactured(kind, x)
    force = -ufl.div(2 * eta * ufl.sym(ufl.grad(u_ex))) + ufl.grad(p_ex)
    assert _integral(comm, force[0] ** 2 * ufl.dx) < 1e-20  # the force really is vertical
    approx = BoussinesqApproximation(Ra=Ra, viscosity=law)
    stokes = StokesSolver(mesh, approx, bcs=bcs, solver=solver, petsc_options=petsc_options)
    result = stokes.solve(force[1] / Ra, C)
    e_u = np.sqrt(_integral(comm, ufl.inner(stokes.u - u_ex, stokes.u - u_ex) * ufl.dx))
    p_mean_ex = _integral(comm, p_ex * ufl.dx)
    p_mean_h = _integral(comm, stokes.p * ufl.dx)
    e_p = np.sqrt(_integral(comm, (stokes.p - p_mean_h - p_ex + p_mean_ex) ** 2 * ufl.dx))
    return e_u, e_p, result, stokes


def _slope(ns, errors) -> float:
    h = 1.0 / np.asarray(ns, dtype=float)
    return float(np.polyfit(np.log(h), np.log(errors), 1)[0])


@pytest.mark.parametrize("kind", ["no_slip", "free_slip", "variable_viscosity"])
def test_taylor_hood_convergence_orders_direct(kind):
    ns = (8, 16, 32)
    results = [_errors(n, kind, "direct") for n in ns]
    slope_u = _slope(ns, [r[0] for r in results])
    slope_p = _slope(ns, [r[1] for r in results])
    assert slope_u > 2.8, slope_u
    assert slope_p > 1.9, slope_p
    assert max(r[2].residual_norm for r in results) < 1e-9


def _norm(comm, f) -> float:
    return float(np.sqrt(_integral(comm, ufl.inner(f, f) * ufl.dx)))


@pytest.mark.parametrize("solver", [ITERATIVE, "iterative_gamg"])
@pytest.mark.parametrize("kind", ["no_slip", "free_slip", "variable_viscosity"])
def test_iterative_matches_direct_to_the_solver_tolerance(kind, solver):
    """The relative residual tolerance rtol bounds the distance to the MUMPS solution: measured
    below 10 rtol (relative L2) for velocity and pressure."""
    rtol = 1e-8
    e_u_d, e_p_d, _, direct = _errors(16, kind, "direct")
    e_u_i, e_p_i, result, stokes = _errors(16, kind, solver, petsc_options={"ksp_rtol": rtol})
    comm = MPI.COMM_WORLD
    assert result.iterations < 200
    for mine, theirs in ((stokes.u, direct.u), (stokes.p, direct.p)):
        reference = mine.copy()  # the same mesh built again: the same dof layout
        reference.x.array[:] = theirs.x.array
        assert _norm(comm, mine - reference) < 30 * rtol * _norm(comm, reference)
    assert abs(e_u_i - e_u_d) < 1e-4 * e_u_d
    assert abs(e_p_i - e_p_d) < 1e-4 * e_p_d


@needs_hypre
def test_iterative_convergence_order():
    ns = (8, 16, 32)
    results = [_errors(n, "free_slip", "iterative") for n in ns]
    assert _slope(ns, [r[0] for r in results]) > 2.8
    assert _slope(ns, [r[1] for r in results]) > 1.9
    iterations = [r[2].iterations for r in results]
    assert max(iterations) < 1.5 * min(iterations) + 10  # mesh-independent preconditioner


@pytest.mark.parametrize("gdim", [2, 3])
@pytest.mark.parametrize("solver", ["direct", ITERATIVE])
def test_hydrostatic_state_is_exact(gdim, solver):
    """Uniform T in a free-slip box [0,2]x[0,1](x[0,1]): u = 0, p = Ra T (z - mean z)."""
    comm = MPI.COMM_WORLD
    if gdim == 2:
        mesh = dolfinx.mesh.create_rectangle(comm, [[0.0, 0.0], [2.0, 1.0]], [8, 4])
        sides = SIDES_2D
    else:
        mesh = dolfinx.mesh.create_box(comm, [[0.0, 0.0, 0.0], [2.0, 1.0, 1.0]], [4, 2, 2])
        sides = SIDES_3D
    Ra = 7.0
    stokes = StokesSolver(mesh, BoussinesqApproximation(Ra=Ra),
                          bcs={s: VelocityBC("free_slip") for s in sides}, solver=solver,
                          petsc_options={"ksp_rtol": 1e-10} if solver == "iterative" else None)
    stokes.solve(1.0, None)
    z = ufl.SpatialCoordinate(mesh)[gdim - 1]
    assert _integral(comm, ufl.inner(stokes.u, stokes.u) * ufl.dx) < 1e-16
    assert _integral(comm, (stokes.p - Ra * (z - 0.5)) ** 2 * ufl.dx) < 1e-16


def test_prescribed_uniform_flow_3d():
    comm = MPI.COMM_WORLD
    mesh = dolfinx.mesh.create_unit_cube(comm, 3, 3, 3)
    value = (1.0, -0.5, 0.25)
    stokes = StokesSolver(mesh, BoussinesqApproximation(Ra=0.0),
                          bcs={s: VelocityBC("prescribed", value) for s in SIDES_3D}, solver="direct")
    stokes.solve(0.0, None)
    u_ex = ufl.as_vector(value)
    assert _integral(comm, ufl.inner(stokes.u - u_ex, stokes.u - u_ex) * ufl.dx) < 1e-20
    assert _integral(comm, stokes.p**2 * ufl.dx) < 1e-20


def test_traction_free_top_has_no_null_space():
    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_WORLD, 4, 4)
    bcs = {s: VelocityBC("free_slip") for s in ("left", "right", "bottom")}
    stokes = StokesSolver(mesh, BoussinesqApproximation(Ra=1.0), bcs=bcs)
    assert not stokes.has_pressure_null_space
    stokes.solve(1.0, None)
    # Zero traction on top pins the pressure: hydrostatic p = Ra (z - 1), u = 0.
    z = ufl.SpatialCoordinate(mesh)[1]
    assert _integral(mesh.comm, (stokes.p - (z - 1.0)) ** 2 * ufl.dx) < 1e-16


def test_unknown_names_are_rejected():
    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_WORLD, 2, 2)
    with pytest.raises(ValueError, match="valid names"):
        StokesSolver(mesh, BoussinesqApproximation(Ra=1.0), bcs=FREE_SLIP, solver="magic")
    with pytest.raises(ValueError, match="valid names"):
        VelocityBC("sticky")
    with pytest.raises(ValueError, match="valid names"):
        StokesSolver(mesh, BoussinesqApproximation(Ra=1.0), bcs={"up": VelocityBC("no_slip")})


def test_transfer_from_copies_state():
    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_WORLD, 4, 4)
    approx = BoussinesqApproximation(Ra=1.0)
    old = StokesSolver(mesh, approx, bcs=FREE_SLIP)
    old.solve(ufl.SpatialCoordinate(mesh)[0], None)
    new = StokesSolver(mesh, approx, bcs=FREE_SLIP, solver="iterative" if HAS_HYPRE else "iterative_gamg")

    def copy(src, dst):
        dst.interpolate(src)

    new.transfer_from(old, copy)
    assert np.allclose(new.u.x.array, old.u.x.array)
    assert np.allclose(new.p.x.array, old.p.x.array)


@pytest.mark.mpi
@pytest.mark.parametrize("solver", ["direct", ITERATIVE])
def test_parallel_errors_equal_serial(solver):
    options = {"ksp_rtol": 1e-11} if solver == "iterative" else None
    e_u, e_p, _, _ = _errors(16, "variable_viscosity", solver, comm=MPI.COMM_WORLD, petsc_options=options)
    e_u_s, e_p_s, _, _ = _errors(16, "variable_viscosity", "direct", comm=MPI.COMM_SELF)
    assert abs(e_u - e_u_s) < 1e-7 * e_u_s
    assert abs(e_p - e_p_s) < 1e-7 * e_p_s


@pytest.mark.parametrize("solver", [ITERATIVE, "iterative_gamg"])
def test_3d_variable_viscosity_iterative_matches_direct(solver):
    """Frank-Kamenetskii viscosity (contrast 100) with a composition layer in a free-slip cube:
    the iterative solvers give MUMPS's velocity field to within their tolerance."""
    comm = MPI.COMM_WORLD
    mesh = dolfinx.mesh.create_unit_cube(comm, 4, 4, 4)
    x = ufl.SpatialCoordinate(mesh)
    T = 1.0 - x[2] + 0.1 * ufl.cos(ufl.pi * x[0]) * ufl.cos(ufl.pi * x[1]) * ufl.sin(ufl.pi * x[2])
    C = ufl.conditional(ufl.lt(x[2], 0.2), 1.0, 0.0)
    law = ViscosityLaw((1.0, 10.0), temperature_law="frank_kamenetskii", gamma=np.log(100.0))
    approx = BoussinesqApproximation(Ra=1e4, Rb=5e3, viscosity=law)
    bcs = {s: VelocityBC("free_slip") for s in SIDES_3D}
    rtol = 1e-8
    solutions = []
    for name, options in (("direct", None), (solver, {"ksp_rtol": rtol})):
        stokes = StokesSolver(mesh, approx, bcs=bcs, solver=name, petsc_options=options)
        result = stokes.solve(T, C)
        solutions.append(stokes.u)
        assert result.iterations < 300
    norm = _norm(comm, solutions[0])
    assert norm > 1.0
    assert _norm(comm, solutions[0] - solutions[1]) < 30 * rtol * norm
