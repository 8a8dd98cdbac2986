"""A multigrid preconditioner kept over several steps while only the semi-implicit buoyancy's term
changes (:class:`LaggedPreconditioner`).

With a semi-implicit buoyancy (:class:`convection.physics.buoyancy.SemiImplicitBuoyancy`) the
Stokes operator ``K = K_0 + theta dt max(d rho / d up, 0) (u . e_up)(v . e_up)`` changes every
step with ``dt`` and the fields, also where the viscosity is constant. The geometric multigrid of a
linear solve is preconditioned by the operator itself
(:class:`convection.solvers.stokes.linear.StokesLinearSystem`), so each change would set it up
again: fieldsplit extracts the velocity block, PCMG forms the Galerkin coarse operators
``P^T A P`` and Chebyshev estimates each level's largest eigenvalue — 0.19 s of a 1.11 s step of
the 16^3 thick layer (2 ranks, PETSc ``-log_view``). The term is a small, slowly varying part of
the velocity block, so a preconditioner set up a few steps earlier serves as well: the outer
Krylov solver still solves with the current operator to the same tolerance, only its
preconditioner lags.

The preconditioner is set up again (:meth:`LaggedPreconditioner.due`) when

- it was set up ``steps`` solves ago (the fields moved on), or
- the step changed by more than the factor ``1 + dt_change`` either way since (the term is
  proportional to ``dt``; a term smaller than the operator's, after ``dt`` grew, costs most:
  on the 16^3 thick layer's first steps, where ``dt`` grows 1.5x a step, a preconditioner set up
  without the term takes 18-25 iterations where a current one takes 13-14),

and always when the operator's fixed part changes (a variable viscosity, a new mesh): the lag is
then not used at all.

Measured on the 16^3 thick layer to t = 0.002 (2 ranks, one sitting, 95 steps): 86.7 s set up
every solve, 76.6 s with ``steps = 10, dt_change = 0.25`` (the defaults; 11.9 and 12.0 iterations a
step) and 75.9 s with 20 and 0.5. Against a run at ``ksp_rtol = 1e-10``, vrms along the run differs
by at most 5.7e-3 (relative) set up every solve and 3.3e-3 with the defaults at the usual 1e-7: the
lag's difference is the solver tolerance's; at 1e-10 the two agree to 5e-10.

**Restart.** A run resumed from a checkpoint must continue as the run that wrote it did, so the
checkpoint keeps what the kept preconditioner was set up from: the step ``dt`` then, how many solves
ago, and the term's coefficient Functions (temperature, projected fractions) as they were
(:meth:`LaggedPreconditioner.state`). The first solve after a restart that keeps the
preconditioner sets it up from these (the operator with the saved values and ``dt``), then solves
with the current operator: the same preconditioner, bit for bit, as the uninterrupted run's.
"""

from __future__ import annotations

import time
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from typing import TYPE_CHECKING, Any

import dolfinx

from fembase.dolfinx_compat import element_degree, function_space, is_discontinuous, is_lagrange, value_size
from fembase.state import State

if TYPE_CHECKING:
    from convection.physics.buoyancy import SemiImplicitBuoyancy
    from convection.solvers.stokes.forms import StokesForms
    from convection.solvers.stokes.linear import StokesLinearSystem

__all__ = ["LaggedPreconditioner", "assemble_operator"]


def _description(V: dolfinx.fem.FunctionSpace, /) -> list[Any]:
    """``[family, degree, components]`` of a Lagrange space (JSON for a checkpoint's scalars)."""
    return ["DG" if is_discontinuous(V) else "Lagrange", element_degree(V), value_size(V)]


class LaggedPreconditioner:
    """When the Stokes preconditioner is set up again, and what the kept one was set up from
    (module docstring).

    Args:
        mesh: the mesh of the solver.
        steps: solves a preconditioner serves at most (``1``: set up at every solve).
        dt_change: the relative change of ``dt`` since the set-up that sets it up again.

    Attributes:
        dt: the step of the last set-up (None before the first).
        age: solves since the last set-up (0 at it).
        pending: a checkpoint gave back the state: the next kept solve must set the preconditioner
            up from the saved values first (:meth:`saved_values`).
    """

    def __init__(self, mesh: dolfinx.mesh.Mesh, steps: int, dt_change: float, /) -> None:
        if steps < 1:
            raise ValueError(f"a preconditioner serves at least one solve, got steps={steps}")
        if not dt_change >= 0.0:
            raise ValueError(f"the step's relative change must be >= 0, got {dt_change}")
        self.mesh = mesh
        self.steps, self.dt_change = int(steps), float(dt_change)
        self.dt: float | None = None
        self.age = 0
        self.pending = False
        self._saved: list[dolfinx.fem.Function] = []

    @staticmethod
    def supports(coefficients: Sequence[Any], /) -> bool:
        """Whether a checkpoint can keep these coefficients (Functions on Lagrange spaces)."""
        return all(isinstance(c, dolfinx.fem.Function) and is_lagrange(c.function_space) for c in coefficients)

    def due(self, dt: float, /) -> bool:
        """Whether the solve with step ``dt`` sets the preconditioner up again."""
        if self.dt is None or self.age + 1 >= self.steps:
            return True
        factor = 1.0 + self.dt_change
        return not self.dt / factor <= dt <= self.dt * factor

    def set_up(self, dt: float, coefficients: Sequence[dolfinx.fem.Function], /) -> None:
        """Record a set-up with step ``dt`` and the term's ``coefficients`` (copied)."""
        if len(self._saved) != len(coefficients) or any(
                s.function_space is not c.function_space for s, c in zip(self._saved, coefficients)):
            self._saved = [dolfinx.fem.Function(c.function_space) for c in coefficients]
        for saved, c in zip(self._saved, coefficients):
            saved.x.array[:] = c.x.array
        self.dt, self.age, self.pending = float(dt), 0, False

    def kept(self) -> None:
        """Record a solve with the kept preconditioner."""
        self.age += 1
        self.pending = False

    @contextmanager
    def saved_values(self, coefficients: Sequence[dolfinx.fem.Function], dt: Any, /) -> Iterator[None]:
        """Within: the ``coefficients`` hold the values of the last set-up and the Constant ``dt``
        its step; their current values are put back after. Collective (interpolation)."""
        if len(coefficients) != len(self._saved):
            raise RuntimeError(f"the semi-implicit term has {len(coefficients)} coefficients, the checkpoint "
                               f"kept {len(self._saved)}")
        current = [c.x.array.copy() for c in coefficients]
        dt_current = float(dt.value)
        try:
            for c, saved in zip(coefficients, self._saved):
                c.interpolate(saved)  # the same element on the same mesh: the values copied
                c.x.scatter_forward()
            dt.value = self.dt
            yield
        finally:
            for c, values in zip(coefficients, current):
                c.x.array[:] = values
            dt.value = dt_current

    # ------------------------------------------------------------------ checkpoints
    def state(self) -> State:
        """The step and age of the last set-up and the coefficients' values then."""
        return State(fields={f"lagged_{i}": f for i, f in enumerate(self._saved)},
                     scalars={"dt": self.dt, "age": self.age,
                              "spaces": [_description(f.function_space) for f in self._saved]})

    def restore(self, scalars: Mapping[str, Any], /) -> dict[str, dolfinx.fem.Function]:
        """Take the saved step and age back; returns Functions for the saved coefficients."""
        self.dt = None if scalars["dt"] is None else float(scalars["dt"])
        self.age = int(scalars["age"])
        self._saved = []
        for family, degree, components in scalars["spaces"]:
            shape = None if components == 1 else (int(components),)
            self._saved.append(dolfinx.fem.Function(function_space(self.mesh, family, int(degree), shape=shape)))
        self.pending = self.dt is not None
        return {f"lagged_{i}": f for i, f in enumerate(self._saved)}



def assemble_operator(system: StokesLinearSystem, forms: StokesForms, term: SemiImplicitBuoyancy, /, *,
                      refresh: bool, lag: LaggedPreconditioner | None) -> float:
    """Assemble the operator (:meth:`StokesLinearSystem.assemble_operator`) for a solve that keeps
    the preconditioner of ``lag`` (None: a solve that does not). Where a checkpoint gave that
    preconditioner back (``lag.pending``), set it up first, from the operator with the saved term
    (the run that wrote the checkpoint had it so). Returns the seconds of that set-up. Collective."""
    if lag is None or not lag.pending:
        system.assemble_operator(forms, refresh=refresh)
        return 0.0
    with lag.saved_values(term.coefficients(), term.dt):
        system.assemble_operator(forms, refresh=refresh)
        t0 = time.perf_counter()
        system.set_up_preconditioner()
        seconds = time.perf_counter() - t0
    system.assemble_operator(forms, refresh=False)
    return seconds
