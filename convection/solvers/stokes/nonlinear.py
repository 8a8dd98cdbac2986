"""Nonlinear Stokes solves: Picard (defect correction) and Newton (PETSc SNES with a line search).

With a viscosity that depends on the flow (:mod:`convection.physics.rheology`: power-law creep, yielding)
the Stokes problem ``F(x) = 0``, ``x = (u, p)``, is nonlinear::

    F(x) = a(eta(x); x, (v, q)) - L(v, q)
         = (2 eta(x) eps(u), eps(v)) - (p, div v) - (f, v) - (q, div u)  (+ Nitsche terms on shells)

- **Picard**: ``x_{k+1}`` solves the linear problem with the viscosity frozen at ``x_k``,
  ``A(x_k) x_{k+1} = b``: the linear solver of :mod:`convection.solvers.stokes.solver` once per iteration;
  converges linearly.
- **Newton**: ``J(x_k) dx = -F(x_k)``, ``x_{k+1} = x_k + lambda dx``, with ``J`` UFL's derivative of
  ``F`` (the viscosity's derivative included) and the step length ``lambda`` from PETSc's line
  search (``bt``: backtracking on ``|F|``). Newton starts after Picard has brought the residual below
  ``switch_tolerance`` (from rest, Newton's first steps are far outside its basin); converges
  quadratically near the solution. An iterative linear solver is preconditioned with the Picard
  operator's blocks (symmetric positive definite), as ASPECT does. Where the line search fails (SNES
  diverges before ``max_iterations``, e.g. at the kinks of a yield law), :data:`RESTART_PICARD`
  Picard iterations are made and Newton starts again.

Both stop when the **relative residual** ``|F(x_k)| / |b|`` is at most ``rtol``, with ``b`` the
right-hand side of the first linearised system of the solve (forcing and lifted boundary
velocities); ``F`` vanishes on the rows of strong conditions (``x`` satisfies them after the first
Picard step) and is orthogonal to the constant pressure when the pressure has a null space. Not
reaching ``rtol`` in ``max_iterations`` raises :class:`NonlinearSolveError` (a solver failure: the
run ends as a blow-up, exit code 3, with one line).

Limitation (refused at construction): Newton with a pressure-dependent law (Drucker-Prager) when
the pressure is only defined up to a constant (every side fixes the normal velocity) — the
viscosity would then depend on the arbitrary pressure level; use Picard, or leave a side traction
free.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, NamedTuple

from petsc4py import PETSc

from convection.geometry.boundary import VelocityBC, velocity_dirichlet_bcs
from convection.schema import Names, param

if TYPE_CHECKING:
    from convection.solvers.stokes.forms import StokesDiscretisation
    from convection.solvers.stokes.linear import StokesLinearSystem

__all__ = ["LINE_SEARCHES", "NONLINEAR_METHODS", "NonlinearResult", "NonlinearSettings", "NonlinearSolveError",
           "NonlinearStokes"]

NONLINEAR_METHODS: dict[str, str] = {
    "picard": "defect correction: the linear problem with the viscosity of the previous iterate",
    "newton": "Newton's method (PETSc SNES, exact Jacobian from UFL) after Picard reached switch_tolerance",
}
"""Registry of nonlinear Stokes methods (name -> one-line description)."""

LINE_SEARCHES: dict[str, str] = {
    "bt": "backtracking (cubic) on the residual norm",
    "basic": "full Newton steps",
    "l2": "secant search on the residual norm",
    "cp": "critical point (for problems with an energy)",
}
"""Registry of SNES line searches for Newton (name -> one-line description)."""


RESTART_PICARD = 3
"""Picard iterations between two Newton solves when Newton's line search fails."""


class NonlinearSolveError(RuntimeError):
    """The nonlinear iteration did not reach its tolerance (a solver failure)."""


@dataclass(frozen=True)
class NonlinearSettings:
    """The ``stokes.nonlinear`` config section (the parameters of :class:`NonlinearStokes`).

    Attributes:
        method: a name in :data:`NONLINEAR_METHODS`.
        rtol: relative residual ``|F| / |b|`` to reach.
        max_iterations: most nonlinear iterations (Picard and Newton together) per solve.
        switch_tolerance: Newton takes over once Picard's relative residual is below this.
        line_search: a name in :data:`LINE_SEARCHES` (Newton).
    """

    method: str = param("newton", choices=Names(NONLINEAR_METHODS),
                        help="for a viscosity that depends on the flow: picard (defect correction) or newton "
                             "(SNES, after picard reached switch_tolerance)")
    rtol: float = param(1e-6, exclusive_minimum=0.0, maximum=0.5,
                        help="stop at |F(u, p)| <= rtol |b| (b: forcing and lifted boundary velocities)")
    max_iterations: int = param(50, minimum=1, maximum=10_000,
                                help="most nonlinear iterations per solve; more is a solver failure (exit 3)")
    switch_tolerance: float = param(0.1, exclusive_minimum=0.0, maximum=1.0,
                                    help="newton: Picard iterations until the relative residual is below this")
    line_search: str = param("bt", choices=Names(LINE_SEARCHES), help="newton: PETSc SNES line search")

    def __post_init__(self) -> None:
        if self.method not in NONLINEAR_METHODS:
            raise ValueError(f"unknown nonlinear method {self.method!r}; valid: {sorted(NONLINEAR_METHODS)}")
        if self.line_search not in LINE_SEARCHES:
            raise ValueError(f"unknown line search {self.line_search!r}; valid: {sorted(LINE_SEARCHES)}")
        if not (0.0 < self.rtol < 1.0 and 0.0 < self.switch_tolerance <= 1.0 and self.max_iterations >= 1):
            raise ValueError(f"invalid nonlinear settings {self}")


class NonlinearResult(NamedTuple):
    """Outcome of one nonlinear solve.

    Attributes:
        iterations: nonlinear iterations (Picard + Newton).
        picard_iterations: of which Picard.
        residual: the final relative residual ``|F| / |b|``.
        history: the relative residual before each iteration and at the end, shape (iterations + 1,).
        linear_iterations: Krylov iterations summed over the linear solves (1 per direct solve).
    """

    iterations: int
    picard_iterations: int
    residual: float
    history: tuple[float, ...]
    linear_iterations: int


def homogeneous(bcs: dict[str, VelocityBC]) -> dict[str, VelocityBC]:
    """The same conditions with zero values (prescribed -> no slip: the same dofs)."""
    return {side: bc.spec.homogeneous(bc) for side, bc in bcs.items()}


class NonlinearStokes:
    """Picard and Newton iterations of a Stokes problem (module docstring).

    Args:
        discretisation: The spaces, conditions and forms
            (:class:`~convection.solvers.stokes.forms.StokesDiscretisation`).
        system: The linear system whose matrices, vectors, ``u`` and ``p`` are used
            (:class:`~convection.solvers.stokes.linear.StokesLinearSystem`).
        settings: Method and tolerances.
        normalise: Normalises the pressure after a solve (zero mean where the constant pressure is
            free; nothing otherwise).
    """

    def __init__(self, discretisation: StokesDiscretisation, system: StokesLinearSystem, settings: NonlinearSettings,
                 /, *, normalise: Callable[[], None]) -> None:
        self.discretisation = discretisation
        self.system = system
        self.settings = settings
        self._normalise = normalise
        domain = discretisation.domain
        self._homogeneous = velocity_dirichlet_bcs(discretisation.V, homogeneous(discretisation.bcs), domain)
        if system.pinned:
            self._homogeneous.append(domain.pressure_pin(discretisation.Q))
        self._F: PETSc.Vec | None = None
        self._snes: PETSc.SNES | None = None
        self._newton_forms: tuple[Any, Any] | None = None
        self._newton_key: Any = None

    # ------------------------------------------------------------------ pieces
    def _forms(self, key: Any, T: Any, C: Any, fields: Any) -> tuple[Any, Any]:
        if self._newton_forms is None or self._newton_key is not key:
            system = self.system
            self._newton_forms = self.discretisation.nonlinear_forms(
                T, C, system.u, system.p, fields=fields, pressure_block=system.pinned)
            self._newton_key = key
        return self._newton_forms

    def _residual_norm(self, F_forms: Any, J_forms: Any) -> float:
        system = self.system
        if self._F is None:
            self._F = system.b.duplicate()
        system.assemble_residual(self._F, F_forms, J_forms, self._homogeneous)
        return float(self._F.norm())

    # ------------------------------------------------------------------ solve
    def solve(self, forms: Any, key: Any, T: Any, C: Any, fields: Any) -> NonlinearResult:
        """Iterate from the current ``u``, ``p`` to the relative residual ``rtol``. Collective.

        Args:
            forms: the Picard forms (viscosity at the iterate ``u``, ``p``).
            key: identifies the fields the forms were built for (the Newton forms are rebuilt
                when it changes).
            T, C, fields: as in :meth:`convection.solvers.stokes.solver.StokesSolver.solve`.

        Raises:
            NonlinearSolveError: ``rtol`` not reached within ``max_iterations``.
        """
        settings = self.settings
        system = self.system
        F_forms, J_forms = self._forms(key, T, C, fields)
        system.assemble_operator(forms, refresh=True)  # the lifting of b uses the operator at the iterate
        system.assemble_rhs(forms)
        reference = float(system.b.norm())
        if reference == 0.0 or not math.isfinite(reference):
            reference = 1.0
        history = [self._residual_norm(F_forms, J_forms) / reference]
        newton = settings.method == "newton"
        switch = settings.switch_tolerance if newton else 0.0  # 0: no switch
        # Picard until converged, or (Newton) until the switch tolerance; at least once, as the
        # residual is measured with homogeneous boundary values and cannot see an iterate that
        # misses prescribed velocities (a sheared box at rest has residual 0).
        picard, linear = self._picard(forms, F_forms, J_forms, reference, history, switch,
                                      budget=settings.max_iterations, first=True)
        iterations = picard
        while newton and history[-1] > settings.rtol and math.isfinite(history[-1]) and \
                iterations < settings.max_iterations:
            its, lin, residuals, diverged = self._newton(forms, F_forms, J_forms, reference,
                                                         settings.max_iterations - iterations)
            iterations += its
            linear += lin
            history.extend(residuals)
            if not diverged or history[-1] <= settings.rtol:
                break
            # The line search failed (e.g. at a yield law's kink): a few Picard iterations, then Newton again.
            more, lin = self._picard(forms, F_forms, J_forms, reference, history, 0.0,
                                     budget=min(RESTART_PICARD, settings.max_iterations - iterations), first=False)
            picard += more
            iterations += more
            linear += lin
        self._normalise()
        if not history[-1] <= settings.rtol:
            raise NonlinearSolveError(
                f"nonlinear Stokes solve ({settings.method}) did not reach the relative residual "
                f"{settings.rtol:g} in {iterations} iterations (reached {history[-1]:.3g}); try more "
                "stokes.nonlinear.max_iterations, picard, or viscosity bounds")
        return NonlinearResult(iterations, picard, history[-1], tuple(history), linear)

    def _picard(self, forms: Any, F_forms: Any, J_forms: Any, reference: float, history: list[float], switch: float,
                *, budget: int, first: bool) -> tuple[int, int]:
        """Picard iterations until the relative residual is at most ``rtol`` or (``switch > 0``) ``switch``,
        at most ``budget``; ``first``: the operator and the right-hand side are assembled at the
        iterate, and one iteration is made in any case. Appends the residuals to ``history``; returns
        (iterations, linear iterations)."""
        system = self.system
        picard = linear = 0
        while (first and picard == 0) or (history[-1] > self.settings.rtol and picard < budget):
            if history[-1] <= switch and (picard > 0 or not first):
                break
            if picard > 0 or not first:
                system.assemble_operator(forms, refresh=True)
                system.assemble_rhs(forms)
            system.solve()
            self._normalise()
            linear += int(system.iterations)
            picard += 1
            history.append(self._residual_norm(F_forms, J_forms) / reference)
            if not math.isfinite(history[-1]):
                break
        return picard, linear

    def _newton(self, forms: Any, F_forms: Any, J_forms: Any, reference: float,
                max_iterations: int) -> tuple[int, int, list[float], bool]:
        """SNES Newton from the current iterate; returns (iterations, linear iterations, relative
        residuals after each iteration, whether SNES diverged: its line search failed)."""
        system = self.system
        residuals: list[float] = []

        def function(snes: PETSc.SNES, x: PETSc.Vec, F: PETSc.Vec) -> None:
            system.unpack(x)
            system.assemble_residual(F, F_forms, J_forms, self._homogeneous)

        def jacobian(snes: PETSc.SNES, x: PETSc.Vec, J: PETSc.Mat, P: PETSc.Mat) -> None:
            system.unpack(x)
            system.assemble_jacobian(J_forms, forms.a_pc)
            # SNES sets these operators next; the multigrid must be on the velocity block of this P.
            system.ksp.setOperators(J, P)
            system.prepare_preconditioner()

        def monitor(snes: PETSc.SNES, its: int, norm: float) -> None:
            if its > 0:
                residuals.append(float(norm) / reference)

        if self._snes is None:
            snes = PETSc.SNES().create(self.discretisation.mesh.comm)
            snes.setKSP(system.ksp)
            # petsc4py 3.18 has no line-search object: the type goes through the options database,
            # read once here and removed again.
            prefix = f"{system.ksp.getOptionsPrefix()}nonlinear_"
            snes.setOptionsPrefix(prefix)
            options = PETSc.Options()
            options[f"{prefix}snes_type"] = "newtonls"
            options[f"{prefix}snes_linesearch_type"] = self.settings.line_search
            snes.setFromOptions()
            for key in ("snes_type", "snes_linesearch_type"):
                options.delValue(f"{prefix}{key}")
            self._snes = snes
        snes = self._snes
        if self._F is None:
            self._F = system.b.duplicate()
        snes.setFunction(function, self._F)
        P = system.P if system.P is not None else system.A
        snes.setJacobian(jacobian, system.A, P)
        snes.setTolerances(rtol=0.0, atol=self.settings.rtol * reference, stol=0.0, max_it=max_iterations)
        snes.cancelMonitor()
        snes.setMonitor(monitor)
        snes.setConvergenceHistory(reset=True)
        guess = system.ksp.getInitialGuessNonzero()
        system.ksp.setInitialGuessNonzero(False)  # a Newton increment starts from zero
        system.pack()
        x = system.x
        try:
            snes.solve(None, x)
        finally:
            system.ksp.setInitialGuessNonzero(guess)
        system.unpack(x)
        diverged = snes.getConvergedReason() < 0 and snes.getIterationNumber() < max_iterations
        return int(snes.getIterationNumber()), int(snes.getLinearSolveIterations()), residuals, diverged

    def destroy(self) -> None:
        """Free the SNES and the residual vector (collective)."""
        for name in ("_snes", "_F"):
            obj = getattr(self, name)
            if obj is not None:
                obj.destroy()
                setattr(self, name, None)
