"""Transport (advection-diffusion) of a scalar field: continuous Galerkin P(k), SUPG, variable-step BDF2.

Used for the temperature (the energy equation) and, with zero diffusivity and no heating, for
advected composition fields. Equation::

    dT/dt + u . grad T = kappa lap T + H,

with kappa = 1 for the temperature (kappa = 0 without heating advects a composition field), and
Dirichlet or insulating (zero-flux, natural) sides. Time discretisation: variable-step BDF2
(BDF1 = backward Euler on the first step, when no history exists). With ``dt_n = t^{n+1} - t^n``
and ``omega = dt_n / dt_{n-1}``::

    (a0 T^{n+1} + a1 T^n + a2 T^{n-1}) / dt_n + u* . grad T^{n+1} - lap T^{n+1} - H = 0,
    a0 = (1 + 2 omega) / (1 + omega),   a1 = -(1 + omega),   a2 = omega^2 / (1 + omega),

which is second order for any step ratio. An approximation with adiabatic and shear heating
(:mod:`convection.physics.compressible`: EBA, TALA) gives the equation a heat capacity ``c`` and a
heating ``q`` instead, ``c (dT/dt + u . grad T) = lap T + q``, discretised alike
(:meth:`TransportSolver.residual`). The velocity ``u`` passed to :meth:`TransportSolver.step`
is the latest one (``u^n``, computed from ``T^n``); to keep the coupled scheme second order it is
extrapolated to the new time level, ``u* = (1 + omega) u^n - omega u^{n-1}``, when the previous
velocity is known (``velocity_extrapolation=True``, the default); otherwise ``u* = u^n``.

Weak form with SUPG (``stabilisation="supg"``): for all test functions ``w``::

    F(T^{n+1}; w) = (d_t T, w) + (u* . grad T^{n+1}, w) + (grad T^{n+1}, grad w) - (H, w)
                  + sum_K (tau_K u* . grad w, R(T^{n+1}))_K = 0,
    R(T) = d_t T + u* . grad T - lap T - H    (strong residual, cellwise),
    tau_K = ((2 a0 / dt)^2 + (2 |u*| / h)^2 + 9 (4 / h^2)^2)^(-1/2),   h = h_K / k,

with ``d_t T = (a0 T^{n+1} + a1 T^n + a2 T^{n-1}) / dt_n``. All cell integrals use a
quadrature of degree ``3 k`` (exact for the Galerkin terms with a P(k) velocity). SUPG is consistent (``R`` vanishes
for the exact solution), so it does not disturb solutions it can represent exactly.
``stabilisation="none"`` drops the last term.

The same residual ``F`` evaluated at the current solution and tested with a function that is 1 on
one side's dofs gives the consistent boundary flux ``int_side grad T . n ds``
(:func:`convection.postprocess.diagnostics.boundary_flux`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, NamedTuple

import dolfinx
import dolfinx.fem.petsc
import numpy as np
import ufl
from petsc4py import PETSc

from convection.physics.approximation import BoussinesqApproximation
from convection.physics.compressible import EnergyTerms
from convection.geometry.boundary import TemperatureBC, temperature_dirichlet_bcs
from convection.geometry.box import BoxDomain
from convection.geometry.domain import Domain
from convection.geometry.mesh import cell_diameter
from convection.schema import MAX_DEGREE, Names, param
from convection.solvers.petsc_options import (
    HAS_HYPRE, MUMPS_LU, SCALAR_AMG, reproducible_lu, LinearSolver, PetscSolver, krylov_options, linear_solvers,
    set_owned_options,
)
from fembase.dolfinx_compat import create_vector, element_degree, function_space, petsc_vector
from fembase.registry import Registry
from fembase.state import State

STABILISATIONS: dict[str, str] = {
    "supg": "streamline-upwind Petrov-Galerkin with the residual of the full equation",
    "none": "plain Galerkin",
}
"""Registry of advection stabilisations (lowercase name -> one-line description)."""

TRANSPORT_SOLVERS: Registry[LinearSolver] = linear_solvers(
    "transport",
    LinearSolver(
        "iterative",
        "GMRES + BoomerAMG" if HAS_HYPRE else "GMRES + GAMG (this PETSc has no hypre for BoomerAMG)",
        krylov_options("gmres", SCALAR_AMG, rtol=1e-10, atol=1e-14, max_it=1000),
    ),
    LinearSolver("direct", "MUMPS LU (on several ranks: gathered on rank 0, reproducible)", MUMPS_LU, reproducible_lu,
                 iterative=False),
)
"""Registry of linear solvers for the transport equation (lowercase name -> description and default
PETSc options)."""


@dataclass(frozen=True)
class EnergySettings:
    """The ``energy`` config section: whether and how the temperature is solved (a
    :class:`TransportSolver`, whose ``degree`` and ``stabilisation`` take their defaults from here)."""

    enabled: bool = param(True, help="false: temperature stays at its initial value (e.g. Ra = 0)")
    degree: int = param(2, minimum=1, maximum=MAX_DEGREE, help="temperature degree (Lagrange)")
    stabilisation: str = param("supg", choices=Names(STABILISATIONS),
                               help="stabilisation of the advection-diffusion equation of the temperature")


_DEFAULTS = EnergySettings()


def bdf_coefficients(dt: float, dt_old: float | None, /) -> tuple[float, tuple[float, float, float], int]:
    """``(omega, (a0, a1, a2), order)`` of the step ``dt`` after ``dt_old`` (module docstring): BDF1
    on the first step (``dt_old`` None), then variable-step BDF2 with ``omega = dt / dt_old``."""
    if dt_old is None:
        return 0.0, (1.0, -1.0, 0.0), 1
    omega = dt / dt_old
    return omega, ((1.0 + 2.0 * omega) / (1.0 + omega), -(1.0 + omega), omega**2 / (1.0 + omega)), 2


class TransportResult(NamedTuple):
    """Outcome of :meth:`TransportSolver.step`.

    Attributes:
        iterations: Krylov iterations (1 for the direct solver).
        order: order of the BDF formula used (1 on the first step, then 2).
        dt: the time step taken.
    """

    iterations: int
    order: int
    dt: float


def interpolate_initial(f: dolfinx.fem.Function, expression: Callable[[np.ndarray], np.ndarray], /, *,
                        bounded: bool = False) -> None:
    """Set ``f`` to the interpolant of ``expression`` (x shape=(3, n) -> shape=(n,)).

    A field of degree ``k > 1`` interpolates at every node; between the nodes its polynomial
    overshoots a sharp step (on a P2 edge with nodal values 1, 1, 0 it reaches 1.125, with 0, 0, 1
    -0.125: 1/8 of the jump). With ``bounded`` ``f`` is the piecewise-linear interpolant at the
    vertices (exact in the P(k) space), so ``min expression <= f <= max expression`` at the vertices
    holds everywhere; it blurs a sharp edge over one cell instead.
    """
    if not bounded or element_degree(f.function_space) <= 1:
        f.interpolate(expression)
        return
    linear = dolfinx.fem.Function(function_space(f.function_space.mesh, "Lagrange", 1))
    linear.interpolate(expression)
    f.interpolate(linear)


def heated_residual(solver: TransportSolver, terms: EnergyTerms, T_new: Any, dtT: Any, u: Any, w: Any, dt: Any,
                    coef: Any, dx: Any) -> Any:
    """The residual of ``c (d_t T + u . grad T) - kappa lap T - q = 0`` with an approximation's heat
    capacity ``c`` and heating ``q`` (:meth:`TransportSolver.residual` of ``solver``; ``d_t T`` is
    ``dtT``); SUPG weighs the equation divided by ``c``."""
    capacity, heating = terms
    kappa, degree = solver.diffusivity, solver.degree
    transport = capacity * (dtT + ufl.dot(u, ufl.grad(T_new)))
    F = (transport * w + kappa * ufl.inner(ufl.grad(T_new), ufl.grad(w)) - heating * w) * dx
    if solver.stabilisation == "supg":
        h = cell_diameter(solver.mesh) / degree
        u_norm = ufl.sqrt(ufl.dot(u, u) + 1e-30)
        diffusion = 4.0 * kappa / (capacity * h**2)
        tau = ((2.0 * coef[0] / dt) ** 2 + (2.0 * u_norm / h) ** 2 + 9.0 * diffusion ** 2) ** -0.5
        strong = transport - kappa * ufl.div(ufl.grad(T_new)) - heating
        F += tau * ufl.dot(u, ufl.grad(w)) * strong / capacity * dx
    return F


class TransportSolver(PetscSolver):
    """Advection-diffusion solver for the temperature (equations in the module docstring).

    Args:
        mesh: the mesh (2D or 3D).
        approximation: physics parameters (uses the internal heating ``H``).
        bcs: temperature condition per boundary name; missing boundaries are insulating.
        domain: the domain whose boundaries ``bcs`` names (default: the box the mesh fills,
            :meth:`convection.geometry.box.BoxDomain.around`; none needed without ``bcs``).
        degree: polynomial degree of the temperature space.
        stabilisation: ``"supg"`` | ``"none"``.
        solver: ``"iterative"`` | ``"direct"``.
        petsc_options: extra PETSc options overriding the defaults (without prefix).
        velocity_extrapolation: extrapolate the velocity to the new time level (see above).
        diffusivity: factor of the diffusion term (1 for the nondimensional temperature; 0 gives
            pure advection, e.g. an advected composition field).
        heating: include the internal heating ``H`` of the approximation.
        name: name of the solution Function (field output).

    Attributes:
        T: current temperature ``T^n`` (P(degree) Function).
        T_old: previous temperature ``T^{n-1}``.
        dt_old: previous time step (``None`` before the first step).
        steps: number of steps taken.
    """

    KIND = "transport"
    SOLVERS = TRANSPORT_SOLVERS
    PETSC_OBJECTS = ("ksp", "_A", "_b")

    def __init__(self, mesh: dolfinx.mesh.Mesh, approximation: BoussinesqApproximation, /, *,
                 bcs: dict[str, TemperatureBC], domain: Domain | None = None, degree: int = _DEFAULTS.degree,
                 stabilisation: str = _DEFAULTS.stabilisation,
                 solver: str = "iterative", petsc_options: dict | None = None, velocity_extrapolation: bool = True,
                 diffusivity: float = 1.0, heating: bool = True, name: str = "temperature") -> None:
        if diffusivity < 0.0:
            raise ValueError(f"diffusivity must not be negative, got {diffusivity}")
        if stabilisation not in STABILISATIONS:
            raise ValueError(
                f"Unknown stabilisation {stabilisation!r}; valid names: {sorted(STABILISATIONS)}"
            )
        self.prepare_process()
        self.mesh = mesh
        self.approximation = approximation
        self.bcs = dict(bcs)
        self.domain = domain if domain is not None or not self.bcs else BoxDomain.around(mesh)
        self.degree = degree
        self.stabilisation = stabilisation
        self.velocity_extrapolation = velocity_extrapolation
        self.diffusivity = float(diffusivity)
        self.heating = heating

        self.V = function_space(mesh, "Lagrange", degree)
        self.T = dolfinx.fem.Function(self.V, name=name)
        self.T_old = dolfinx.fem.Function(self.V, name=f"{name}_old")
        self.T_old2 = dolfinx.fem.Function(self.V, name=f"{name}_old2")
        self._T_new = dolfinx.fem.Function(self.V)
        self.dt_old: float | None = None
        self.steps = 0
        self._dirichlet = temperature_dirichlet_bcs(self.V, self.bcs, self.domain)

        # BDF coefficients and step of the step being taken, and of the last step taken.
        self._dt = dolfinx.fem.Constant(mesh, PETSc.ScalarType(1.0))
        self._coef = dolfinx.fem.Constant(mesh, np.zeros(3, dtype=PETSc.ScalarType))
        self._dt_last = dolfinx.fem.Constant(mesh, PETSc.ScalarType(1.0))
        self._coef_last = dolfinx.fem.Constant(mesh, np.zeros(3, dtype=PETSc.ScalarType))

        self._u_adv: dolfinx.fem.Function | None = None
        self._u_prev: dolfinx.fem.Function | None = None
        self._a = self._L = None
        self._A: PETSc.Mat | None = None
        self._b: PETSc.Vec | None = None
        # compiled forms of diagnostics on these fields (convection.postprocess.diagnostics)
        self.forms: dict[Any, Any] = {}
        self.name = name
        options = self._create_ksp(mesh.comm, solver, petsc_options)
        set_owned_options(self, self._prefix, options)

    def settings(self) -> dict[str, Any]:
        return {"bcs": self.bcs, "domain": self.domain, "degree": self.degree, "stabilisation": self.stabilisation,
                "solver": self.solver,
                "petsc_options": self._user_options, "velocity_extrapolation": self.velocity_extrapolation,
                "diffusivity": self.diffusivity, "heating": self.heating, "name": self.name}

    # ------------------------------------------------------------------ forms
    def residual(self, T_new: Any, T_n: Any, T_nm1: Any, u: Any, w: Any, dt: Any, coef: Any) -> Any:
        """UFL residual ``F(T_new; w)`` (module docstring) with BDF coefficients ``coef`` (a0,
        a1, a2) and step ``dt``. ``T_new`` may be a TrialFunction (bilinear + linear parts) or a
        Function (a functional of ``w``)."""
        H = self.approximation.H if self.heating else 0.0
        kappa = self.diffusivity
        dx = ufl.dx(domain=self.mesh, metadata={"quadrature_degree": 3 * self.degree})
        dtT = (coef[0] * T_new + coef[1] * T_n + coef[2] * T_nm1) / dt
        terms = self.heating and self.approximation.energy_terms(T_new, T_n, u, ufl.SpatialCoordinate(self.mesh))
        if terms:  # EBA, TALA (convection.physics.compressible)
            return heated_residual(self, terms, T_new, dtT, u, w, dt, coef, dx)
        F = (dtT * w + ufl.dot(u, ufl.grad(T_new)) * w) * dx
        if kappa != 0.0:
            F += kappa * ufl.inner(ufl.grad(T_new), ufl.grad(w)) * dx
        if H != 0.0:
            F -= H * w * dx
        if self.stabilisation == "supg":
            h = cell_diameter(self.mesh) / self.degree
            u_norm = ufl.sqrt(ufl.dot(u, u) + 1e-30)
            tau = ((2.0 * coef[0] / dt) ** 2 + (2.0 * u_norm / h) ** 2 + 9.0 * (4.0 * kappa / h**2) ** 2) ** -0.5
            strong = dtT + ufl.dot(u, ufl.grad(T_new)) - H
            if kappa != 0.0:
                strong -= kappa * ufl.div(ufl.grad(T_new))
            F += tau * ufl.dot(u, ufl.grad(w)) * strong * dx
        return F

    def _ensure_forms(self, u: dolfinx.fem.Function) -> None:
        if self._u_adv is not None and self._u_adv.function_space == u.function_space:
            return
        Vu = u.function_space
        self._u_adv = dolfinx.fem.Function(Vu, name="advecting_velocity")
        if self._u_prev is not None and self._u_prev.function_space != Vu:
            u_prev = dolfinx.fem.Function(Vu)
            u_prev.interpolate(self._u_prev)  # same mesh: exact when the elements match
            self._u_prev = u_prev
        Tt, w = ufl.TrialFunction(self.V), ufl.TestFunction(self.V)
        F = self.residual(Tt, self.T, self.T_old, self._u_adv, w, self._dt, self._coef)
        zero = dolfinx.fem.Constant(self.mesh, PETSc.ScalarType(0.0))
        self._a = dolfinx.fem.form(ufl.lhs(F))
        self._L = dolfinx.fem.form(ufl.rhs(F) + zero * w * ufl.dx)
        if self._A is None:
            self._A = dolfinx.fem.petsc.create_matrix(self._a)
            self._b = create_vector(self._L)
            self.ksp.setOperators(self._A)
            self.ksp.setFromOptions()
            if TRANSPORT_SOLVERS[self.solver].iterative:
                self.ksp.setInitialGuessNonzero(True)

    # ------------------------------------------------------------------ state
    def set_initial(self, expression: Callable[[np.ndarray], np.ndarray], /, *, bounded: bool = False) -> None:
        """Set ``T`` (and the history) to ``expression(x)``, x shape=(3, n) -> shape=(n,); the
        Dirichlet values are imposed on the result. Resets the time history.

        Args:
            bounded: :func:`interpolate_initial`'s ``bounded``.
        """
        interpolate_initial(self.T, expression, bounded=bounded)
        dolfinx.fem.petsc.set_bc(petsc_vector(self.T), self._dirichlet)
        self.T.x.scatter_forward()
        for f in (self.T_old, self.T_old2):
            f.x.array[:] = self.T.x.array
        self.dt_old = None
        self.steps = 0
        self._u_prev = None
        self._coef_last.value[:] = 0.0

    def step(self, u: dolfinx.fem.Function, dt: float) -> TransportResult:
        """Advance ``T`` by ``dt`` with the latest velocity ``u``. Collective.

        Args:
            u: velocity Function (any vector space on this mesh), at the current time level.
            dt: time step (> 0).

        Returns:
            Iterations, BDF order used and ``dt``.
        """
        if not dt > 0.0:
            raise ValueError(f"time step must be positive, got {dt}")
        self._ensure_forms(u)
        omega, coef, order = bdf_coefficients(dt, self.dt_old)
        self._dt.value = dt
        self._coef.value[:] = coef
        if self.velocity_extrapolation and self._u_prev is not None and order == 2:
            self._u_adv.x.array[:] = (1.0 + omega) * u.x.array - omega * self._u_prev.x.array
        else:
            self._u_adv.x.array[:] = u.x.array

        self._A.zeroEntries()
        dolfinx.fem.petsc.assemble_matrix(self._A, self._a, bcs=self._dirichlet)
        self._A.assemble()
        with self._b.localForm() as b_local:
            b_local.set(0.0)
        dolfinx.fem.petsc.assemble_vector(self._b, self._L)
        dolfinx.fem.petsc.apply_lifting(self._b, [self._a], bcs=[self._dirichlet])
        self._b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        dolfinx.fem.petsc.set_bc(self._b, self._dirichlet)

        self._T_new.x.array[:] = self.T.x.array
        self.ksp.solve(self._b, petsc_vector(self._T_new))
        reason = self.ksp.getConvergedReason()
        if reason < 0:
            raise RuntimeError(f"Energy solver did not converge (PETSc reason {reason})")
        self._T_new.x.scatter_forward()

        self.T_old2.x.array[:] = self.T_old.x.array
        self.T_old.x.array[:] = self.T.x.array
        self.T.x.array[:] = self._T_new.x.array
        if self.velocity_extrapolation:
            if self._u_prev is None:
                self._u_prev = dolfinx.fem.Function(u.function_space)
            self._u_prev.x.array[:] = u.x.array
        self._dt_last.value = dt
        self._coef_last.value[:] = coef
        self.dt_old = dt
        self.steps += 1
        iterations = self.ksp.getIterationNumber() if TRANSPORT_SOLVERS[self.solver].iterative else 1
        return TransportResult(int(iterations), order, float(dt))

    def state(self) -> State:
        """The time history: ``T`` (T^n), ``T_old``, ``T_old2`` and the scalars (previous step,
        steps taken, the last BDF step)."""
        return State(fields={"T": self.T, "T_old": self.T_old, "T_old2": self.T_old2},
                     scalars={"dt_old": self.dt_old, "steps": self.steps, "dt_last": float(self._dt_last.value),
                              "coef_last": [float(c) for c in self._coef_last.value]})

    def restore(self, scalars: Mapping[str, Any], /) -> dict[str, dolfinx.fem.Function]:
        """Take the history's scalars back; returns its Functions for the checkpoint to fill."""
        self.dt_old = scalars["dt_old"]
        self.steps = int(scalars["steps"])
        self._dt_last.value = scalars["dt_last"]
        self._coef_last.value[:] = scalars["coef_last"]
        return self.state().fields

    def last_step_residual(self, u: Any, w: Any, /) -> Any:
        """UFL residual ``F(T; w)`` of the last step taken (module docstring) with velocity ``u``:
        the last step's BDF time derivative, zero before the first step. Tested with a function
        that is 1 on a side's dofs it gives the consistent boundary flux
        (:func:`convection.postprocess.diagnostics.boundary_flux`)."""
        return self.residual(self.T, self.T_old, self.T_old2, u, w, self._dt_last, self._coef_last)

    # ------------------------------------------------------------------ adaptivity
    def transfer_from(
        self,
        old: TransportSolver,
        transfer: Callable[[dolfinx.fem.Function, dolfinx.fem.Function], None],
    ) -> None:
        """Copy the full time history (``T``, ``T_old``, ``T_old2``, previous velocity, previous
        steps) from a solver on the old mesh, using ``transfer(src_on_old, dst_on_new)``. The
        Dirichlet values are re-imposed on the transferred temperatures. Collective."""
        for src, dst in ((old.T, self.T), (old.T_old, self.T_old), (old.T_old2, self.T_old2)):
            transfer(src, dst)
            dolfinx.fem.petsc.set_bc(petsc_vector(dst), self._dirichlet)
            dst.x.scatter_forward()
        if old._u_prev is not None:
            element = old._u_prev.function_space.ufl_element()
            self._u_prev = dolfinx.fem.Function(function_space(self.mesh, element))
            transfer(old._u_prev, self._u_prev)
            self._u_prev.x.scatter_forward()
            self._u_adv = None
        else:
            self._u_prev = None
        self.dt_old = old.dt_old
        self.steps = old.steps
        self._dt_last.value = old._dt_last.value
        self._coef_last.value[:] = old._coef_last.value
