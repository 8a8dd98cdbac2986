"""A steady start (``initial.steady``): the steady equations solved for ``(u, p, T)`` at once by
Newton's method, before the first time step.

A steady benchmark (Blankenbach et al. 1989; the steady cases of King et al. 2010) is otherwise
reached by stepping through the whole transient, thousands of steps. Worse, a strongly
temperature-dependent viscosity may never get there from a sinusoidal start: Blankenbach case 2b
falls into a time-dependent flow from the sinusoid on every mesh tried, although its published
steady flow is stable (a run started from it stays there; benchmarks/blankenbach/README.md). The
steady start finds that flow directly.

Equations (the run's spaces: velocity P(k), pressure P(k-1), temperature the energy equation's
P(m); the run's strong conditions; test functions ``v``, ``q``, ``s``)::

    (2 eta(T) eps(u), eps(v)) - (p, div v) - (f(T), v) = 0        momentum, f the buoyancy
                                           -(q, div u) = 0        mass
        (u . grad T, s) + (grad T, grad s) - (H, s)     = 0        energy (Galerkin, no SUPG)

with the viscosity law and the body force of the run's approximation. Newton's method for this
system converges from close enough only, and the conduction state ``u = 0`` is a solution too, so
it is reached in two stages:

1. **Pseudo-transient continuation** of the isoviscous problem (``eta = 1``) from
   ``initial.temperature``: backward-Euler steps ``(T - T_old) / dt`` added to the energy
   equation, each solved by Newton, with ``dt = 1e-3`` growing by 1.5 a step (the transient of the
   isoviscous flow, ever more implicit) until a step changes ``T`` by less than ``1e-8``, or 40
   steps.
2. **Continuation in the viscosity contrast**: the viscosity ``eta^s`` for ``s = 0.25, 0.5, 0.75,
   1`` (``eta^s = exp(s ln eta)``: for Frank-Kamenetskii ``eta = exp(-gamma_T T + gamma_z d)``
   the exponents scaled by ``s``), Newton at each ``s`` from the previous solution; a failed
   Newton halves the step in ``s`` (down to 1/64).

Each Newton iteration solves the Jacobian (UFL's derivative) by MUMPS LU (on several ranks gathered
on rank 0, :func:`~convection.solvers.petsc_options.reproducible_lu`, so that two runs give the
same bits); it stops when the residual's norm falls below ``1e-9`` times its first value, or
``1e-10``. The result's temperature becomes the run's initial temperature; the time steps then
relax it to the time-stepper's own steady state (which has SUPG): for Blankenbach 2b at 50 x 20
graded cells the run's Nu and vrms then change by less than 0.1 %
(benchmarks/blankenbach/README.md).

The steady start needs a Boussinesq energy equation without composition and a viscosity that
depends on the temperature and depth only, in a box (:func:`check_steady_start` says what refuses it).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import dolfinx.fem
import dolfinx.fem.petsc
import numpy as np
import ufl
from mpi4py import MPI
from petsc4py import PETSc

from convection.schema import ConfigError
from convection.geometry.boundary import TemperatureBC, temperature_dirichlet_bcs, velocity_dirichlet_bcs
from convection.solvers.petsc_options import reproducible_lu, set_owned_options
from convection.solvers.stokes.nonlinear import homogeneous
from fembase.dolfinx_compat import (assemble_block_matrix, assemble_block_vector, create_block_matrix,
                                    create_block_vector, petsc_vector)

__all__ = ["SteadyResult", "check_steady_start", "solve_steady"]

PSEUDO_DT0, PSEUDO_MIN_DT, PSEUDO_GROWTH, PSEUDO_STEPS, PSEUDO_CHANGE = 1e-3, 1e-7, 1.5, 100, 1e-8
CONTRAST_STEPS, MIN_CONTRAST_STEP = (0.25, 0.5, 0.75, 1.0), 1.0 / 64
NEWTON_RTOL, NEWTON_ATOL, NEWTON_MAX_IT = 1e-9, 1e-10, 12


@dataclass(frozen=True)
class SteadyResult:
    """What the steady start did: Newton iterations in all, pseudo-time steps, contrast steps."""

    newton_iterations: int
    pseudo_steps: int
    contrast_steps: int


def check_steady_start(*, approximation: str, composition: bool, particles: bool, energy: bool, free_surface: bool,
                       box: bool, viscosity_depends_on: frozenset[str], elasticity: bool, phases: bool) -> None:
    """The cross-key checks of ``initial.steady: true`` (the model's traits as the config gives them).

    Raises:
        ConfigError: one line naming ``initial.steady`` and what it cannot be used with.
    """
    reasons = (
        (approximation != "boussinesq", f"physics.approximation {approximation} (it solves the Boussinesq equations)"),
        (composition, "a composition or materials (it solves for the temperature and the flow only)"),
        (particles, "particles (it solves for the temperature and the flow only)"),
        (not energy, "energy.enabled: false (nothing to make steady)"),
        (free_surface, "a free surface (it keeps the mesh fixed)"),
        (not box, "this mesh.geometry (boxes only: a curved boundary's weak free slip is not in its equations)"),
        (not viscosity_depends_on <= {"temperature", "depth"},
         "a viscosity that depends on more than the temperature and the depth"),
        (elasticity, "physics.elasticity (it solves the viscous equations)"),
        (phases, "phase_transitions (its energy equation has no latent heat)"),
    )
    for refused, why in reasons:
        if refused:
            raise ConfigError(f"config key 'initial.steady': cannot be used with {why}")


class _Blocks:
    """The unknowns ``(u, p, T)`` as Functions and as one PETSc block vector (owned dofs of each in turn)."""

    def __init__(self, functions: list[dolfinx.fem.Function]) -> None:
        self.functions = functions
        self.sizes = [f.function_space.dofmap.index_map.size_local * f.function_space.dofmap.index_map_bs
                      for f in functions]

    def to_functions(self, x: PETSc.Vec, /) -> None:
        array, offset = x.getArray(readonly=True), 0
        for f, n in zip(self.functions, self.sizes):
            f.x.array[:n] = array[offset:offset + n]
            f.x.scatter_forward()
            offset += n

    def from_functions(self, x: PETSc.Vec, /) -> None:
        array, offset = x.getArray(), 0
        for f, n in zip(self.functions, self.sizes):
            array[offset:offset + n] = f.x.array[:n]
            offset += n


class _SteadyProblem:
    """The residual and Jacobian forms of the steady (or pseudo-transient) system, and Newton's method."""

    def __init__(self, stokes: Any, temperature: Any) -> None:
        d = stokes.discretisation
        mesh = d.mesh
        self.comm = mesh.comm
        self.u, self.p = dolfinx.fem.Function(d.V), dolfinx.fem.Function(d.Q)
        self.T = dolfinx.fem.Function(temperature.V)
        self.T.x.array[:] = temperature.T.x.array
        self.T_old = dolfinx.fem.Function(temperature.V)
        self.contrast = dolfinx.fem.Constant(mesh, PETSc.ScalarType(0.0))
        self.inverse_dt = dolfinx.fem.Constant(mesh, PETSc.ScalarType(0.0))
        approximation = d.approximation
        x = ufl.SpatialCoordinate(mesh)
        v, q, s = ufl.TestFunction(d.V), ufl.TestFunction(d.Q), ufl.TestFunction(temperature.V)
        u, p, T = self.u, self.p, self.T
        eta = ufl.exp(self.contrast * ufl.ln(approximation.viscosity(T, None, x=x)))
        f = approximation.buoyancy(T, None, mesh.geometry.dim, x=x)
        metadata = {"quadrature_degree": 3 * d.degree} if approximation.is_variable_viscosity else {}
        dx = ufl.dx(domain=mesh, metadata=metadata)
        F = [2.0 * eta * ufl.inner(ufl.sym(ufl.grad(u)), ufl.sym(ufl.grad(v))) * dx
             - p * ufl.div(v) * dx - ufl.inner(f, v) * dx,
             -q * ufl.div(u) * dx,
             (self.inverse_dt * (T - self.T_old) * s + ufl.dot(u, ufl.grad(T)) * s
              + ufl.inner(ufl.grad(T), ufl.grad(s)) - approximation.H * s) * dx]
        unknowns = (u, p, T)
        self.F = dolfinx.fem.form(F)
        J = [[ufl.derivative(Fi, w, ufl.TrialFunction(w.function_space)) for w in unknowns] for Fi in F]
        zero = dolfinx.fem.Constant(mesh, PETSc.ScalarType(0.0))
        J[1][1] = zero * ufl.TrialFunction(d.Q) * q * dx  # holds a pinned pressure dof's diagonal
        self.J = dolfinx.fem.form(J)
        # Strong conditions: the unknowns take their values; Newton's corrections are zero there.
        velocity = velocity_dirichlet_bcs(d.V, d.bcs, d.domain)
        thermal = temperature_dirichlet_bcs(temperature.V, temperature.bcs, temperature.domain)
        zero_T = {side: TemperatureBC(bc.kind, 0.0 if bc.spec.needs_value else None)
                  for side, bc in temperature.bcs.items()}
        self.homogeneous = (velocity_dirichlet_bcs(d.V, homogeneous(d.bcs), d.domain)
                            + temperature_dirichlet_bcs(temperature.V, zero_T, temperature.domain))
        if stokes.has_pressure_null_space:
            self.homogeneous.append(d.domain.pressure_pin(d.Q))
        for bc, w in [(bc, u) for bc in velocity] + [(bc, T) for bc in thermal]:
            dolfinx.fem.petsc.set_bc(petsc_vector(w), [bc])
        for w in unknowns:
            w.x.scatter_forward()
        self.blocks = _Blocks([u, p, T])
        self.A = create_block_matrix(self.J)
        self.b = create_block_vector(self.F)
        self.dx, self.x, self.saved = self.b.duplicate(), self.b.duplicate(), self.b.duplicate()
        self.ksp = PETSc.KSP().create(self.comm)
        if self.comm.size == 1:
            self.ksp.setType("preonly")
            pc = self.ksp.getPC()
            pc.setType("lu")
            pc.setFactorSolverType("mumps")
        else:  # gathered on rank 0: a parallel MUMPS factorisation differs in the last bits from run to run
            prefix = f"steady{id(self)}_"
            self.ksp.setOptionsPrefix(prefix)
            set_owned_options(self, prefix, reproducible_lu(self.comm.size))
            self.ksp.setFromOptions()

    def residual(self) -> float:
        """Assemble ``F`` at the unknowns into :attr:`b` (zero on the strong conditions' rows); its norm."""
        with self.b.localForm() as local:
            local.set(0.0)
        assemble_block_vector(self.b, self.F, self.J, bcs=self.homogeneous)
        return float(self.b.norm())

    def newton(self) -> int | None:
        """Newton's method from the current unknowns; its iterations, or None if it failed (the
        unknowns then back where they started)."""
        x = self.x
        self.blocks.from_functions(x)
        x.copy(self.saved)
        first = self.residual()
        norm = first
        for iteration in range(NEWTON_MAX_IT + 1):
            if norm <= max(NEWTON_RTOL * first, NEWTON_ATOL):
                return iteration
            if not math.isfinite(norm) or iteration == NEWTON_MAX_IT or norm > 1e6 * max(first, 1.0):
                break
            self.A.zeroEntries()
            assemble_block_matrix(self.A, self.J, bcs=self.homogeneous)
            self.A.assemble()
            self.ksp.setOperators(self.A)
            self.ksp.solve(self.b, self.dx)
            if self.ksp.getConvergedReason() < 0:
                break
            x.axpy(-1.0, self.dx)
            self.blocks.to_functions(x)
            norm = self.residual()
        self.blocks.to_functions(self.saved)
        return None

    def destroy(self) -> None:
        for obj in (self.A, self.b, self.dx, self.x, self.saved, self.ksp):
            obj.destroy()


def _relax(problem: _SteadyProblem, where: str, /) -> tuple[int, int]:
    """Pseudo-transient continuation from the unknowns to a steady state of the current problem
    (module docstring): backward-Euler steps of growing length, a failed one retried at a quarter of
    its length; returns (Newton iterations, steps). Raises RuntimeError naming ``where`` on failure."""
    iterations, steps, dt = 0, 0, PSEUDO_DT0
    while steps < PSEUDO_STEPS:
        problem.T_old.x.array[:] = problem.T.x.array
        problem.inverse_dt.value = 1.0 / dt
        its = problem.newton()
        if its is None:  # too long a step in the transient: a quarter of it
            dt /= 4.0
            if dt < PSEUDO_MIN_DT:
                problem.inverse_dt.value = 0.0
                raise RuntimeError(f"steady start: Newton failed {where} at pseudo-time step {steps + 1}")
            continue
        steps += 1
        iterations += its
        change = problem.comm.allreduce(float(np.abs(problem.T.x.array - problem.T_old.x.array).max(initial=0.0)),
                                        op=MPI.MAX)
        if change < PSEUDO_CHANGE:
            break
        dt *= PSEUDO_GROWTH
    problem.inverse_dt.value = 0.0
    return iterations, steps


def solve_steady(stokes: Any, temperature: Any, /) -> SteadyResult:
    """Set ``temperature.T`` to the steady state (module docstring), from its current value.
    ``stokes``: the run's :class:`~convection.solvers.stokes.solver.StokesSolver` (spaces, velocity
    conditions, approximation); ``temperature``: its :class:`~convection.solvers.transport.TransportSolver`.
    Collective.

    Raises:
        RuntimeError: Newton failed (on every rank), with the stage it failed in.
    """
    problem = _SteadyProblem(stokes, temperature)
    try:
        iterations, pseudo = _relax(problem, "on the isoviscous flow")
        s, step, stages = 0.0, CONTRAST_STEPS[0], 0
        while s < 1.0:
            target = min(1.0, s + step)
            problem.contrast.value = target
            its = problem.newton()
            if its is None:  # from too far: the transient at this contrast, from the last state
                try:
                    its, steps = _relax(problem, f"at viscosity contrast exponent s = {target:.4g}")
                except RuntimeError:
                    step /= 2
                    if step < MIN_CONTRAST_STEP:
                        raise
                    continue
                pseudo += steps
            iterations += its
            stages += 1
            s = target
        temperature.set_initial(problem.T)
    finally:
        problem.destroy()
    return SteadyResult(iterations, pseudo, stages)
