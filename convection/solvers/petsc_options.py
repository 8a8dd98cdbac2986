"""Per-object PETSc options that leave the global options database when the object goes away.

Each solver uses its own options prefix so several solvers can coexist with different settings.
PETSc's options database is global and limited (512 entries by default): a run that rebuilds its
solvers after every mesh adaptation would exhaust it, so the entries are removed again when the
solver that set them is garbage collected. :func:`destroy_petsc_objects` frees solvers
explicitly, at the same point on every rank.

Each PDE solver lists its linear solvers as :class:`LinearSolver` entries (name, description,
default options) built from the same pieces: :data:`MUMPS_LU` (direct; on several ranks
:func:`reproducible_lu`, which gives the same bits in every run) and :func:`krylov_options`
(iterative: Krylov method, stopping rule, then the preconditioner).

Nothing happens at import: the solvers set what they need when they are made
(:meth:`PetscSolver.prepare_process`: the global option ``vec_mdot_use_gemv = false`` unless it is
set already, :func:`reproducible_vector_kernels`, the process's cache of compiled forms,
:mod:`fembase.jit_cache`, and glibc's heap settings, :mod:`fembase.heap`).
"""

from __future__ import annotations

import itertools
import re
import weakref
from dataclasses import dataclass
from types import MappingProxyType
from collections.abc import Callable, Iterator, Mapping, Sequence
from typing import Any, ClassVar, TypeVar

from petsc4py import PETSc

from convection.schema import short_repr
from fembase import jit_cache
from fembase.heap import return_freed_memory
from fembase.registry import Registry
from fembase.state import Stateful

__all__ = ["PetscSolver",
    "check_petsc_options",
    "HAS_HYPRE",
    "MUMPS_LU",
    "SCALAR_AMG",
    "reproducible_lu",
    "reproducible_vector_kernels",
    "LinearSolver",
    "destroy_petsc_objects",
    "krylov_options",
    "linear_solvers",
    "set_owned_options",
]

_PETSC_WORD = re.compile(r"[A-Za-z0-9_]+")
_VIEWER_WORDS = frozenset({"view", "monitor", "reason", "draw", "log", "viewer", "lg", "dump", "history"})
"""Words of PETSc option names whose value is a viewer (``ksp_view``, ``ksp_monitor_true_residual``,
``ksp_converged_reason``, ``mat_view``, ...)."""
_PRINTING_VIEWERS = ("", "ascii")
_STANDARD_STREAMS = ("", "stdout", "stderr")


def check_petsc_options(options: dict[str, Any]) -> str | None:
    """PETSc options must be plain ``name: scalar`` pairs, and a viewer option may only print
    (``ascii`` to stdout/stderr, any format): a viewer that names a file (``ascii:/some/path``),
    writes PETSc's default file (``binary``) or opens a window (``draw``) is refused, since PETSc
    would create it outside the run folder."""
    for name, value in options.items():
        if not isinstance(name, str) or not _PETSC_WORD.fullmatch(name):
            return f"option name {short_repr(name)} must be letters, digits and _ (without the leading -)"
        if value is not None and not isinstance(value, (str, int, float)):
            return f"option {name}: the value must be a number, text, true/false or null, got {short_repr(value)}"
        if _VIEWER_WORDS.isdisjoint(name.lower().split("_")) or value is None or isinstance(value, bool):
            continue
        kind, _, rest = str(value).partition(":")
        filename = rest.partition(":")[0]
        if kind.strip().lower() not in _PRINTING_VIEWERS or filename.strip() not in _STANDARD_STREAMS:
            return (f"option {name}: {short_repr(value)} would make PETSc write a file or open a window outside "
                    "the run folder; viewers may only print (e.g. ascii, ::ascii_info_detail)")
    return None


def reproducible_vector_kernels() -> None:
    """Make PETSc's multiple dot products (``VecMDot``, the Gram-Schmidt step of GMRES and FGMRES)
    give the same bits in every run of the same problem. Not collective; call before the solvers
    create their vectors (:meth:`PetscSolver.prepare_process` does, first thing in every solver).

    Since PETSc 3.20 (Debian 13 has 3.22), ``VecMDot`` calls BLAS ``gemv`` by default
    (``-vec_mdot_use_gemv``). OpenBLAS's ``dgemv`` rounds differently depending on how the
    vectors happen to be aligned in memory, which changes from run to run: the same transport
    system, solved twice from the same matrix, right-hand side and initial guess, gave different
    last bits in about half of the runs (any preconditioner: BoomerAMG, GAMG, ILU; with
    ``OMP_NUM_THREADS=OPENBLAS_NUM_THREADS=1`` too), so a resumed run could not continue bit for
    bit. PETSc's own unrolled kernel (the only one in PETSc 3.18, Debian 12) is deterministic:
    6 of 6 runs identical. An option set by the user (command line, ``PETSC_OPTIONS``) is kept.
    """
    options = PETSc.Options()
    if not options.hasName("vec_mdot_use_gemv"):
        options["vec_mdot_use_gemv"] = False
    # Read it back once: that marks it used, so that a process that never makes a Krylov solver
    # (``convection check``) gets no "options you set that were not used" warning on its stdout from
    # PetscFinalize (Debian 13's PETSc lists unused options by default; PETSc 3.18 does not know this
    # option at all).
    options.getBool("vec_mdot_use_gemv")


MUMPS_LU: Mapping[str, Any] = MappingProxyType(
    {"ksp_type": "preonly", "pc_type": "lu", "pc_factor_mat_solver_type": "mumps"}
)
"""Direct solve: one MUMPS LU factorisation, no Krylov iterations (read-only; copy with ``dict``)."""

HAS_HYPRE: bool = bool(PETSc.Sys.hasExternalPackage("hypre"))
"""Whether this PETSc has hypre (BoomerAMG): Debian's has, the PETSc inside PyPI's DOLFINx wheel
(dolfinx-solver-real 0.11, PETSc 3.25) has not."""

SCALAR_AMG: Mapping[str, Any] = MappingProxyType(
    {"pc_type": "hypre", "pc_hypre_type": "boomeramg"} if HAS_HYPRE else
    {"pc_type": "gamg", "pc_gamg_agg_nsmooths": 0, "mg_levels_ksp_type": "richardson", "mg_levels_pc_type": "sor"}
)
"""Algebraic multigrid for a scalar problem: hypre's BoomerAMG, or PETSc's own GAMG where PETSc has
no hypre (read-only). GAMG aggregates without smoothing the prolongator and smooths with SOR
instead of Chebyshev: both defaults estimate eigenvalues from random vectors, and a resumed run
(a fresh preconditioner) would then not continue bit for bit."""

def reproducible_lu(ranks: int, /) -> dict[str, Any]:
    """Direct solve on ``ranks`` ranks that gives the same bits in every run: PETSc's ``telescope``
    preconditioner gathers the system on rank 0, which factorises it with sequential MUMPS, and
    scatters the solution back.

    A parallel MUMPS factorisation schedules its work dynamically, so two runs of the same system on
    the same ranks differ in the last bits (measured: from the first step of van Keken 1a on 2 ranks,
    also with METIS or AMF ordering, sequential analysis or ScaLAPACK off), and a resumed run could
    not continue bit for bit. On van Keken 1a to t = 300 (17 000 unknowns, 2 ranks, best of three)
    the run took 6.69 s against 6.30 s with parallel MUMPS (Stokes solve 3.5 s against 3.0 s);
    ``redundant`` (every rank factorises the whole system) is as fast (6.64 s) but needs the
    factorisation's memory on every rank (benchmarks/scaling/direct_solver_sitting.sh).
    Options of the inner solver take the ``telescope_`` prefix (e.g. ``telescope_mat_mumps_icntl_14``).
    """
    return {"ksp_type": "preonly", "pc_type": "telescope", "pc_telescope_reduction_factor": ranks,
            "telescope_ksp_type": "preonly", "telescope_pc_type": "lu",
            "telescope_pc_factor_mat_solver_type": "mumps"}



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
        parallel_options: The defaults on a given number of ranks (more than one), when they differ
            from ``options`` (None: ``options``).
        iterative: A Krylov solve (it counts iterations and starts from the previous solution);
            False: a direct factorisation.
    """

    name: str
    description: str
    options: Mapping[str, Any]
    parallel_options: Callable[[int], Mapping[str, Any]] | None = None
    iterative: bool = True

    def __post_init__(self) -> None:
        object.__setattr__(self, "options", MappingProxyType(dict(self.options)))

    def options_with(self, overrides: Mapping[str, Any] | None = None, /, *, ranks: int = 1) -> dict[str, Any]:
        """The default options on ``ranks`` ranks updated by ``overrides`` (a new dict)."""
        defaults = self.parallel_options(ranks) if ranks > 1 and self.parallel_options is not None else self.options
        return {**defaults, **(overrides or {})}


def linear_solvers(kind: str, /, *solvers: L) -> Registry[L]:
    """Registry of the linear solvers a PDE solver of ``kind`` (``"Stokes"``, ...) offers, by name."""
    return Registry(f"{kind} solver", solvers)


L = TypeVar("L", bound=LinearSolver)


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


class PetscSolver(Stateful):
    """Life cycle shared by the PDE solvers: a named linear-solver setup, a PETSc KSP with its own
    options prefix, explicit destruction, and a copy of the solver on another mesh.

    Subclasses set :attr:`KIND`, :attr:`SOLVERS` (their registry of setups) and
    :attr:`PETSC_OBJECTS`, call :meth:`_create_ksp` in their constructor and implement
    :meth:`settings` (the keyword arguments that rebuild them).
    """

    KIND: ClassVar[str] = "pde"
    SOLVERS: ClassVar[Mapping[str, LinearSolver]] = {}
    PETSC_OBJECTS: ClassVar[tuple[str, ...]] = ("ksp",)
    _instances: ClassVar[Iterator[int]] = itertools.count()

    mesh: Any
    approximation: Any

    @staticmethod
    def prepare_process() -> None:
        """What every solver needs of the process, set once (idempotent; not collective): PETSc's
        reproducible vector kernels (:func:`reproducible_vector_kernels`), the process's cache
        of compiled forms and elements (:func:`fembase.jit_cache.install`) and a C heap that
        returns freed memory, which loading PETSc turned off (:func:`fembase.heap.return_freed_memory`).
        Subclasses call it first in their constructor, before they make any vector."""
        reproducible_vector_kernels()
        jit_cache.install()
        return_freed_memory()

    def _create_ksp(self, comm: Any, solver: str, petsc_options: Mapping[str, Any] | None) -> dict[str, Any]:
        """Check ``solver``, create the KSP under a fresh prefix; returns the full option set."""
        if solver not in self.SOLVERS:
            raise ValueError(f"Unknown {self.KIND} solver {solver!r}; valid names: {sorted(self.SOLVERS)}")
        self.solver = solver
        self._user_options = dict(petsc_options or {})
        self._prefix = f"{self.KIND.lower()}{next(PetscSolver._instances)}_"
        self.ksp = PETSc.KSP().create(comm)
        self.ksp.setOptionsPrefix(self._prefix)
        return self.SOLVERS[solver].options_with(petsc_options, ranks=comm.size)

    def settings(self) -> dict[str, Any]:
        """The keyword arguments that build this solver again (without mesh and approximation)."""
        raise NotImplementedError

    def on_mesh(self, mesh: Any, /) -> Any:
        """A solver with the same settings on another mesh (collective; fields zero, no history)."""
        return type(self)(mesh, self.approximation, **self.settings())

    def destroy(self) -> None:
        """Free the PETSc solver, matrices and vectors now (collective; see :func:`destroy_petsc_objects`)."""
        destroy_petsc_objects(self, self.PETSC_OBJECTS)

