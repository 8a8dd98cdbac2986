"""Per-object PETSc options that leave the global options database when the object goes away.

Each solver uses its own options prefix so several solvers can coexist with different settings.
PETSc's options database is global and limited (512 entries by default): a run that rebuilds its
solvers after every mesh adaptation would exhaust it, so the entries are removed again when the
solver that set them is garbage collected. :func:`destroy_petsc_objects` frees solvers
explicitly, at the same point on every rank.

Each PDE solver lists its linear solvers as :class:`LinearSolver` entries (name, description,
default options) built from the same two pieces: :data:`MUMPS_LU` (direct) and
:func:`krylov_options` (iterative: Krylov method, stopping rule, then the preconditioner).
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any, Mapping, Sequence

from petsc4py import PETSc

__all__ = [
    "MUMPS_LU",
    "LinearSolver",
    "destroy_petsc_objects",
    "krylov_options",
    "linear_solvers",
    "set_owned_options",
]

MUMPS_LU: Mapping[str, Any] = MappingProxyType(
    {"ksp_type": "preonly", "pc_type": "lu", "pc_factor_mat_solver_type": "mumps"}
)
"""Direct solve: one MUMPS LU factorisation, no Krylov iterations (read-only; copy with ``dict``)."""


def krylov_options(ksp_type: str, /, preconditioner: Mapping[str, Any], *, rtol: float, atol: float,
                   max_it: int) -> dict[str, Any]:
    """Options of an iterative solve: Krylov method and stopping rule, then the preconditioner.

    Args:
        ksp_type: PETSc Krylov method (``"gmres"``, ``"minres"``, ...).
        preconditioner: ``pc_*`` (and sub-solver) options, appended unchanged.
        rtol: Relative residual tolerance ``ksp_rtol``.
        atol: Absolute residual tolerance ``ksp_atol``.
        max_it: Iteration cap ``ksp_max_it``.
    """
    return {"ksp_type": ksp_type, "ksp_rtol": rtol, "ksp_atol": atol, "ksp_max_it": max_it, **preconditioner}


@dataclass(frozen=True)
class LinearSolver:
    """One linear-solver setup a PDE solver offers (its ``solver=`` choice).

    Attributes:
        name: Lowercase name.
        description: One line for listings.
        options: Default PETSc options without the solver's prefix (read-only; copy with ``dict``).
    """

    name: str
    description: str
    options: Mapping[str, Any]

    def __post_init__(self) -> None:
        object.__setattr__(self, "options", MappingProxyType(dict(self.options)))

    def options_with(self, overrides: Mapping[str, Any] | None = None, /) -> dict[str, Any]:
        """The default options updated by ``overrides`` (a new dict)."""
        return {**self.options, **(overrides or {})}


def linear_solvers(*solvers: LinearSolver) -> dict[str, LinearSolver]:
    """Registry of the linear solvers a PDE solver offers, by name."""
    return {solver.name: solver for solver in solvers}


def _clear(prefix: str, keys: list[str]) -> None:
    opts = PETSc.Options()
    for key in keys:
        opts.delValue(prefix + key)


def set_owned_options(owner: object, prefix: str, options: Mapping[str, Any], /) -> None:
    """Set ``prefix + key = value`` for every option; remove them when ``owner`` is collected."""
    opts = PETSc.Options()
    for key, value in options.items():
        opts[prefix + key] = value
    weakref.finalize(owner, _clear, prefix, list(options))


def destroy_petsc_objects(owner: object, names: Sequence[str], /) -> None:
    """Destroy the PETSc objects held in ``owner``'s attributes ``names`` and set them to None.

    Collective: call on every rank at the same point. Destroying some parallel objects
    communicates (a MUMPS factorisation, for one); left to Python's garbage collector, which runs
    at different times on different ranks, that can deadlock a run that replaces its solvers
    (adaptivity, load balancing).
    """
    for name in names:
        obj = getattr(owner, name, None)
        if obj is not None:
            obj.destroy()
            setattr(owner, name, None)
