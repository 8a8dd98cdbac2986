"""The block-preconditioned Krylov Stokes solvers (3D default): iterations flat in h, also with a
1e3 viscosity contrast, serial and under MPI; agreement with MUMPS to the solver tolerance; warm
start; the rigid-body near-null space; the "auto" choice."""

from __future__ import annotations


import numpy as np
import pytest
import ufl
import dolfinx
import dolfinx.fem.petsc
from mpi4py import MPI

from convection.physics.approximation import BoussinesqApproximation
from convection.geometry.boundary import VelocityBC
from convection.geometry.box import SIDES_2D, SIDES_3D
from convection.config.loader import SCHEMA
from convection.solvers.stokes.solver import STOKES_SOLVER_NAMES, StokesSolver, resolve_solver, rigid_body_modes
from convection.solvers.petsc_options import HAS_HYPRE
from fembase.dolfinx_compat import function_space
from _helpers import ITERATIVE, needs_hypre

from benchmarks.performance import stokes3d  # the benchmark's problem

FREE_SLIP_3D = {side: VelocityBC("free_slip") for side in SIDES_3D}


def _norm(comm, f) -> float:
    return float(np.sqrt(comm.allreduce(dolfinx.fem.assemble_scalar(dolfinx.fem.form(ufl.inner(f, f) * ufl.dx)),
                                        op=MPI.SUM)))


def _cube_problem(n: int, viscosity: str, comm=MPI.COMM_WORLD, shift: float = 0.0):
    """Unit cube of n^3 cubes (6 tets each), Ra = 1e6, the problem of benchmarks/performance/stokes3d.py:
    T as in the 3D thick-layer config, viscosity "constant"; "temperature" (a smooth 1e3 contrast);
    "layer" (a sharp 1e3 contrast). Returns (mesh, T Function, C or None, approximation)."""
    mesh = dolfinx.mesh.create_unit_cube(comm, n, n, n)
    T, C, approximation = stokes3d.problem(mesh, viscosity)
    if shift:
        T.interpolate(stokes3d.temperature(viscosity, shift))
    return mesh, T, C, approximation


def _iterations_by_size(viscosity: str, sizes=(4, 6, 8), solver: str = "iterative") -> list[int]:
    counts = []
    for n in sizes:
        mesh, T, C, approx = _cube_problem(n, viscosity)
        stokes = StokesSolver(mesh, approx, bcs=FREE_SLIP_3D, solver=solver)
        counts.append(stokes.solve(T, C).iterations)
        stokes.destroy()
    return counts


def _check_flat(counts: list[int], *, growth: float = 1.4, last_step: int = 6) -> None:
    # Halving h (4^3 -> 8^3) adds less than 40 %; a preconditioner without multigrid doubles the count.
    # Measured serially with a constant viscosity: 22 26 27 (Debian 12), 21 26 28 (Debian 13's
    # hypre); with the smooth contrast 34 34 37 (Debian 12). Since the preconditioning matrix holds
    # B^T the counts are lower, so the mesh-dependent part of BoomerAMG's weighs more (the bound was
    # 30 % when the counts were ~10 higher).
    assert max(counts) <= growth * min(counts), counts
    assert counts[-1] - counts[-2] <= last_step, counts


@needs_hypre
@pytest.mark.parametrize("viscosity", ["constant", "temperature"])
def test_iterations_flat_in_h(viscosity):
    _check_flat(_iterations_by_size(viscosity))


@pytest.mark.mpi
@needs_hypre
@pytest.mark.parametrize("viscosity", ["constant", "temperature"])
def test_iterations_flat_in_h_parallel(viscosity):
    # BoomerAMG's parallel setup is not bit-reproducible here (the same 2-rank solve took 86 or 97
    # iterations in repeated runs), so the parallel bound leaves room for that noise; still far
    # below the doubling of a preconditioner without multigrid.
    _check_flat(_iterations_by_size(viscosity), growth=1.5, last_step=10)


def _check_matches_mumps(viscosity: str, solver: str, rtol: float, n: int = 4, reference: str = "direct") -> None:
    """The distance to the reference solution (relative L2) is a modest multiple of rtol. The
    reference is MUMPS, or (in parallel, where MUMPS without iterative refinement is only 4e-6 to
    6e-5 accurate) the other iterative solver at rtol 1e-11.

    The residual bounds the error only through the operator's conditioning, which the viscosity
    contrast worsens: measured up to ~10 rtol with the smooth contrast; with the sharp one 38–76
    rtol in ten 2-rank runs on the development machine (the partition and BoomerAMG's parallel
    setup vary run to run) and 122 rtol once on the CI machine, hence 300. A wrong operator or a
    lost ghost update gives errors of order one."""
    comm = MPI.COMM_WORLD
    factor = 300 if viscosity == "layer" else 30
    mesh, T, C, approx = _cube_problem(n, viscosity)
    options = {"ksp_rtol": 1e-11} if reference != "direct" else None
    direct = StokesSolver(mesh, approx, bcs=FREE_SLIP_3D, solver=reference, petsc_options=options)
    direct.solve(T, C)
    stokes = StokesSolver(mesh, approx, bcs=FREE_SLIP_3D, solver=solver, petsc_options={"ksp_rtol": rtol})
    result = stokes.solve(T, C)
    assert result.iterations < 300
    assert _norm(comm, stokes.u - direct.u) < factor * rtol * _norm(comm, direct.u)
    assert _norm(comm, stokes.p - direct.p) < factor * rtol * _norm(comm, direct.p)


@pytest.mark.parametrize("rtol", [1e-5, 1e-9])
@pytest.mark.parametrize("viscosity", ["temperature", "layer"])
@pytest.mark.parametrize("solver", [ITERATIVE, "iterative_gamg"])
def test_matches_mumps_to_the_solver_tolerance(solver, viscosity, rtol):
    _check_matches_mumps(viscosity, solver, rtol)


@pytest.mark.mpi
@needs_hypre  # held against the other AMG
@pytest.mark.parametrize("viscosity", ["temperature", "layer"])
@pytest.mark.parametrize("solver", [ITERATIVE, "iterative_gamg"])
def test_matches_mumps_to_the_solver_tolerance_parallel(solver, viscosity):
    other = "iterative_gamg" if solver == "iterative" else "iterative"
    _check_matches_mumps(viscosity, solver, 1e-7, reference=other)


@needs_hypre
def test_warm_start_from_the_previous_solution():
    mesh, T, C, approx = _cube_problem(6, "temperature")
    stokes = StokesSolver(mesh, approx, bcs=FREE_SLIP_3D)
    assert stokes.solver == "iterative"  # "auto" in 3D
    cold = stokes.solve(T, C).iterations
    assert stokes.solve(T, C).iterations == 0  # already converged: |b - K x| <= rtol |b|
    _, T_next, _, _ = _cube_problem(6, "temperature", shift=0.005)  # T moved by 0.005 in x
    T.x.array[:] = T_next.x.array
    assert 0 < stokes.solve(T, C).iterations < 0.8 * cold


@pytest.mark.parametrize("solver", [ITERATIVE, "iterative_gamg"])
def test_velocity_block_carries_block_size_and_rigid_body_modes(solver):
    mesh, T, C, approx = _cube_problem(2, "constant")
    stokes = StokesSolver(mesh, approx, bcs=FREE_SLIP_3D, solver=solver)
    stokes.solve(T, C)
    velocity_ksp, _ = stokes.ksp.getPC().getFieldSplitSubKSP()
    A = velocity_ksp.getOperators()[1]
    assert A.getBlockSize() == 3
    assert A.getNearNullSpace() is not None


def _check_rigid_body_modes(mesh) -> None:
    gdim = mesh.geometry.dim
    V = function_space(mesh, "Lagrange", 2, shape=(mesh.geometry.dim,))
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    A = dolfinx.fem.petsc.assemble_matrix(
        dolfinx.fem.form(ufl.inner(ufl.sym(ufl.grad(u)), ufl.sym(ufl.grad(v))) * ufl.dx))
    A.assemble()
    modes = rigid_body_modes(V).getVecs()
    assert len(modes) == (3 if gdim == 2 else 6)
    y = A.createVecLeft()
    for i, mode in enumerate(modes):
        assert [round(mode.dot(other), 12) for other in modes] == [float(i == j) for j in range(len(modes))]
        A.mult(mode, y)  # no boundary conditions: rigid motions have zero strain
        assert y.norm() < 1e-10 * A.norm()


@pytest.mark.parametrize("gdim", [2, 3])
def test_rigid_body_modes_have_zero_strain(gdim):
    comm = MPI.COMM_WORLD
    mesh = dolfinx.mesh.create_unit_square(comm, 5, 3) if gdim == 2 else dolfinx.mesh.create_unit_cube(comm, 3, 2, 2)
    _check_rigid_body_modes(mesh)


@pytest.mark.mpi
def test_rigid_body_modes_have_zero_strain_parallel():
    _check_rigid_body_modes(dolfinx.mesh.create_unit_cube(MPI.COMM_WORLD, 3, 4, 2))


def test_auto_is_iterative_in_3d_and_direct_in_2d():
    assert resolve_solver("auto", 3) == ("iterative" if HAS_HYPRE else "iterative_gamg")
    assert resolve_solver("auto", 2) == "direct"
    assert resolve_solver("iterative_gamg", 2) == "iterative_gamg"
    assert SCHEMA["stokes"]["solver"].default == "auto"
    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_WORLD, 2, 2)
    stokes = StokesSolver(mesh, BoussinesqApproximation(Ra=1.0), bcs={s: VelocityBC("free_slip") for s in SIDES_2D})
    assert stokes.solver == "direct" and not stokes.is_iterative
    assert stokes.on_mesh(mesh).solver == "direct"
    with pytest.raises(ValueError, match="valid names: .*'auto'"):
        resolve_solver("amg", 3)
    assert set(STOKES_SOLVER_NAMES) == {"auto", "direct", "iterative", "iterative_gamg", "multigrid"}
