"""Taylor-Hood Stokes solver for the Boussinesq momentum and mass equations.

Weak form (find ``u in V_D``, ``p in Q`` such that for all ``v in V_0``, ``q in Q``)::

    (2 eta eps(u), eps(v)) - (p, div v) = ((Ra T - Rb C) e_z, v)
                            -(q, div u) = 0

on a vector P(k) / scalar P(k-1) pair (k = 2: Taylor-Hood P2-P1). With a variable viscosity the
cell integrals use a quadrature of degree ``3 k``. Boundary conditions are
:class:`~convection.geometry.boundary.VelocityBC` per box side or shell boundary (``inner``/``outer``); on
a box side free slip is a zero Dirichlet condition on the normal velocity component, on a curved
shell boundary it is imposed weakly by symmetric Nitsche terms
(:func:`convection.geometry.boundary.nitsche_free_slip`, penalty ``nitsche_penalty eta / h``). When every
side fixes the normal velocity the pressure is only defined up to a constant: the
constant-pressure null space is attached to the operator (iterative solver) or removed by pinning
one pressure dof (direct solver, exact once the continuity right-hand side sums to zero, which
:meth:`~convection.solvers.stokes.linear.StokesLinearSystem._consistent_continuity` ensures), and the pressure is then
normalised to zero mean, ``int p dx = 0``. When both shell boundaries are free slip, rigid
rotations about the origin (one in 2D, three in 3D) also solve the homogeneous problem; the
solution's rotational part (its L2 projection onto the rotations) is removed after every solve.
The rotations are only nearly in the discrete null space (``u . n`` of a rotation vanishes on the
circle, not exactly on the curved cells' boundary, so the Nitsche penalty pins them weakly with a
small eigenvalue): the operator is regular, so they are not given to PETSc as a null space (MINRES
stagnates with an inexact one).

The solve has three parts, one module each: the discretisation (spaces, strong conditions and
forms: :mod:`convection.solvers.stokes.forms`), the linear system (matrices, vectors, null spaces and the
KSP's life cycle: :mod:`convection.solvers.stokes.linear`) and the buoyancy predictor
(:mod:`convection.physics.buoyancy`). :class:`StokesSolver` ties them together: it picks the linear solver
from the registry below, rebuilds the forms when the fields change and normalises the solution.

Solvers (``solver=``, names in :data:`STOKES_SOLVER_NAMES`):
    ``"auto"`` (the default): ``"iterative"`` in 3D (``"iterative_gamg"`` for a shell with free
        slip on both surfaces: its rigid rotations, see :func:`resolve_solver`), ``"direct"`` in 2D.
        A run of a config goes further: on a fixed 3D box whose cells halve at least twice it makes
        the coarser boxes, and on a fixed spherical shell of gmsh size at most an eighth of its
        thickness the levels by refinement, and uses ``"multigrid"``
        (:func:`convection.config.loader.multigrid_levels`).
    ``"direct"``: MUMPS LU of the monolithic (block) system; the factorisation is reused while the
        viscosity is constant.
    ``"iterative"``: FGMRES, right-preconditioned by the upper block-triangular Schur
        preconditioner ``[[A, B^T], [0, -M_p/eta]]^-1`` (PETSc fieldsplit): one BoomerAMG V-cycle
        on the velocity block ``A`` (systems AMG: the velocity components are the AMG's
        "functions", no pre-smoothing), one symmetric SOR sweep on the viscosity-scaled pressure
        mass matrix. Stops at ``|b - K x| <= 1e-7 |b|`` (``ksp_rtol``), starting from the
        previous solution. See :func:`block_schur_options`.
    ``"iterative_gamg"``: the same with PETSc's smoothed-aggregation GAMG on ``A``, given the
        rigid-body modes (:func:`convection.solvers.stokes.nullspace.rigid_body_modes`) as near-null space.
    ``"multigrid"``: the same with one V-cycle of geometric multigrid on ``A``, over the meshes the
        mesh is nested in (``coarse_meshes``; a box of n cells per side nests in the box of 2 n):
        Galerkin coarse operators, two Chebyshev/Jacobi steps per level, LU on the coarsest
        (:mod:`convection.solvers.stokes.multigrid`). Its iteration count does not grow with the mesh.
        A semi-implicit buoyancy's term goes into its preconditioning matrix too (on a box), and
        the hierarchy is set up again every solve: at the 3D thick layer's CFL step (16^3) 13
        iterations a step instead of 18-25, for a set-up that costs less than those iterations.
        The AMG solvers keep their hierarchy instead (their set-up costs more than it saves).

Measured on unit cubes (benchmarks/performance/README.md): BoomerAMG needs fewer iterations than
GAMG, each cheaper, and sets up 5-10 times faster (which matters when the viscosity, hence ``A``,
changes every step).
"""

from __future__ import annotations

import dataclasses
import functools
import time
from collections.abc import Callable, Collection, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar, NamedTuple

import dolfinx

from convection.physics.approximation import BoussinesqApproximation
from convection.deform.surface import SurfaceTerms
from convection.geometry.boundary import VelocityBC, has_rotation_null_space
from convection.geometry.box import BoxDomain
from convection.geometry.domain import Domain
from convection.physics.buoyancy import SemiImplicitBuoyancy
from convection.solvers.stokes.nullspace import (  # noqa: F401 (imported from here)
    PressureMean, RigidRotations, pressure_normaliser, rigid_body_modes,
)
from convection.schema import MAX_DEGREE, MAX_ENTRIES, ConfigError, Names, param, subsection
from convection.solvers.petsc_options import (
    HAS_HYPRE, MUMPS_LU, LinearSolver, PetscSolver, check_petsc_options, krylov_options, linear_solvers,
    reproducible_lu, set_owned_options,
)
from convection.solvers.stokes.bfbt import SCHUR_APPROXIMATIONS, WeightedBFBtSystem, schur_options
from convection.solvers.stokes.forms import StokesDiscretisation, StokesForms
from convection.solvers.stokes.linear import StokesLinearSystem
from convection.solvers.stokes.lagged import LaggedPreconditioner, assemble_operator
from convection.solvers.stokes.multigrid import GEOMETRIC_MULTIGRID, MultigridSettings, VelocityMultigrid
from convection.solvers.stokes.nonlinear import NonlinearResult, NonlinearSettings, NonlinearStokes
from fembase.dolfinx_compat import coordinate_map
from fembase.registry import Registry
from fembase.state import State

_BOOMERAMG_SYSTEMS: dict[str, Any] = {
    # Systems AMG ("unknown" approach: PETSc passes the block size gdim as hypre's number of
    # functions, so only like components couple), HMIS coarsening with ext+i interpolation, one level
    # of aggressive coarsening and 2 interpolation entries per row: operator complexity ~1.1.
    "pc_type": "hypre",
    "pc_hypre_type": "boomeramg",
    "pc_hypre_boomeramg_coarsen_type": "HMIS",
    "pc_hypre_boomeramg_interp_type": "ext+i",
    "pc_hypre_boomeramg_strong_threshold": 0.5,
    "pc_hypre_boomeramg_agg_nl": 1,
    "pc_hypre_boomeramg_P_max": 2,
    # No pre-smoothing: half the cost of a V-cycle for a few more outer iterations (FGMRES does not
    # need a symmetric preconditioner).
    "pc_hypre_boomeramg_grid_sweeps_down": 0,
}

_GAMG_RIGID_BODY: dict[str, Any] = {
    "pc_type": "gamg",  # smoothed aggregation; uses the rigid-body near-null space
    "pc_gamg_reuse_interpolation": True,  # re-setup after a viscosity change: Galerkin products only
}


def block_schur_options(velocity: dict[str, Any], /, *, rtol: float = 1e-7) -> dict[str, Any]:
    """FGMRES with the upper block-triangular preconditioner ``[[A, B^T], [0, S]]^-1``.

    ``A^-1`` is one application of the ``velocity`` preconditioner (``pc_*`` options, given
    without the ``fieldsplit_u_`` prefix); the Schur complement ``S = -B A^-1 B^T`` is replaced by
    ``-M_p / eta`` (the viscosity-scaled pressure mass matrix, the ``(1, 1)`` block of the
    preconditioning matrix), inverted by one symmetric SOR sweep. PETSc takes ``B^T`` from the
    preconditioning matrix, which therefore holds it (:mod:`convection.solvers.stokes.forms`).
    FGMRES is right preconditioned,
    so ``rtol`` bounds the true residual: ``|b - K x| <= rtol |b|`` (PETSc measures against
    ``|b|`` also when the initial guess is nonzero). The default 1e-7 (as ASPECT's) leaves the
    velocity within about 1e-6 (relative L2) of the exact discrete solution; with the previous
    step's solution as the initial guess a time step needs about two thirds of the iterations of
    a solve from zero.
    """
    return krylov_options(
        "fgmres",
        {
            "ksp_gmres_restart": 100,  # vectors are allocated as needed
            "pc_type": "fieldsplit",
            "pc_fieldsplit_type": "schur",
            "pc_fieldsplit_schur_fact_type": "upper",
            "pc_fieldsplit_schur_precondition": "a11",
            "fieldsplit_u_ksp_type": "preonly",
            **{f"fieldsplit_u_{key}": value for key, value in velocity.items()},
            "fieldsplit_p_ksp_type": "preonly",
            "fieldsplit_p_pc_type": "sor",
        },
        rtol=rtol,
        atol=1e-14,
        max_it=1000,
    )


@dataclass(frozen=True)
class StokesLinearSolver(LinearSolver):
    """A linear solver of :class:`StokesSolver` (an entry of :data:`STOKES_SOLVERS`).

    Attributes (beyond :class:`LinearSolver`'s):
        nested: Geometric multigrid over the meshes the mesh is nested in (``coarse_meshes``): its
            semi-implicit buoyancy term goes into the preconditioning matrix, which may lag.
        needs_hypre: Uses hypre's BoomerAMG (refused by a PETSc without hypre).
    """

    nested: bool = False
    needs_hypre: bool = False


STOKES_SOLVERS: Registry[StokesLinearSolver] = linear_solvers(
    "Stokes",
    StokesLinearSolver(
        "direct", "MUMPS LU on the monolithic Taylor-Hood system (on several ranks: gathered on rank 0, reproducible)",
        MUMPS_LU, reproducible_lu, iterative=False),
    StokesLinearSolver(
        "iterative",
        "FGMRES + block-triangular Schur preconditioner: BoomerAMG (systems) on velocity, SOR on -M_p/eta",
        block_schur_options(_BOOMERAMG_SYSTEMS), needs_hypre=True,
    ),
    StokesLinearSolver(
        "iterative_gamg",
        "FGMRES + block-triangular Schur preconditioner: GAMG with rigid-body modes on velocity, SOR on -M_p/eta",
        block_schur_options(_GAMG_RIGID_BODY),
    ),
    StokesLinearSolver(
        "multigrid",
        "FGMRES + block-triangular Schur preconditioner: geometric multigrid on velocity (nested boxes, Galerkin "
        "coarse operators, Chebyshev/Jacobi smoothing), SOR on -M_p/eta",
        # Three symmetric SOR sweeps on the pressure mass matrix (one for the AMG solvers): as good
        # as its exact inverse here, 27 -> 19 iterations on 16^3 cubes (2 ranks), for little
        # next to a V-cycle (benchmarks/scaling/stokes_multigrid.md).
        {**block_schur_options(GEOMETRIC_MULTIGRID), "fieldsplit_p_pc_sor_its": 3}, nested=True,
    ),
)
"""Registry of the linear-solver setups of :class:`StokesSolver` (lowercase name -> description and
default PETSc options): ready entries, asked. A ``stokes.solver`` choice (:data:`STOKES_SOLVER_CHOICES`)
is built into one of them."""

AUTO = "auto"
"""Solver name resolved by the mesh: ``"iterative"`` in 3D, ``"direct"`` in 2D (see :func:`resolve_solver`)."""


@dataclass(frozen=True)
class StokesSettings:
    """The ``stokes`` config section: the parameters of :class:`StokesSolver` (its keyword arguments
    of the same names take their defaults from here)."""

    degree: int = param(2, minimum=2, maximum=MAX_DEGREE, help="velocity degree (pressure degree - 1)")
    solver: str = param(AUTO, choices=Names(lambda: STOKES_SOLVER_CHOICES),
                        help="auto: multigrid (FGMRES + block preconditioner, geometric multigrid) on a fixed 3D box "
                             "whose cells halve twice or a fixed spherical shell whose gmsh size is at most 1/8 of "
                             "its thickness, else iterative (AMG) in 3D (iterative_gamg for a shell free slip on "
                             "both surfaces), direct (MUMPS) in 2D")
    petsc_options: Mapping[str, Any] = param({}, check=check_petsc_options, max_items=MAX_ENTRIES,
                                             help="extra PETSc options for the Stokes solver (e.g. ksp_rtol: 1e-6); "
                                                  "viewers may only print")
    nonlinear: NonlinearSettings = subsection(NonlinearSettings)
    multigrid: MultigridSettings = subsection(MultigridSettings)
    schur: str = param("mass", choices=Names(SCHUR_APPROXIMATIONS),
                       help="Schur complement approximation of the iterative solvers: mass (-M_p/eta, SOR; the "
                            "default) or wbfbt (weighted BFBt, two AMG cycles on a weighted pressure Poisson matrix: "
                            "fewer iterations at large viscosity contrasts where the velocity solve is good, "
                            "benchmarks/nsinker); not with direct")
    buoyancy_theta: float = param(0.0, minimum=0.0, maximum=1.0,
                                  help="0: buoyancy of the current fields; 0 < theta <= 1: buoyancy predicted at "
                                       "t + theta dt along the flow, the material moved in the velocity so solved "
                                       "(semi-implicit, stabilises dense interfaces against the 'drunken sailor' "
                                       "oscillation; 0.5: second order in time; 1: no swinging at steps far above an "
                                       "interface's relaxation time, e.g. sticky air under a slow slab)")


@dataclass(frozen=True)
class StokesSolverContext:
    """What a ``stokes.solver`` choice is built for (:meth:`StokesSolverChoice.build`).

    Attributes:
        gdim: The dimension of the mesh.
        rotations: The velocity has the rigid rotations as near-null modes (a shell free slip on
            both surfaces: :func:`convection.geometry.boundary.has_rotation_null_space`).
    """

    gdim: int
    rotations: bool = False


class StokesSolverChoice:
    """A ``stokes.solver`` choice (an entry of :data:`STOKES_SOLVER_CHOICES`): built from the
    ``stokes`` section (:class:`StokesSettings`, its ``Settings``) in a :class:`StokesSolverContext`
    into the linear-solver setup of :data:`STOKES_SOLVERS` that runs.

    Attributes:
        name, description: The config name and one line.
        nested: Geometric multigrid over the meshes the mesh is nested in (the run makes them).
        by_mesh: Picked by the mesh: a run of a config may make it the multigrid
            (:func:`convection.config.loader.nested_levels`).
    """

    name: ClassVar[str]
    description: ClassVar[str]
    Settings: ClassVar[type] = StokesSettings
    nested: ClassVar[bool] = False
    by_mesh: ClassVar[bool] = False

    @classmethod
    def build(cls, settings: StokesSettings, context: StokesSolverContext, /) -> StokesLinearSolver:
        """The setup of :data:`STOKES_SOLVERS` of the same name.

        Raises:
            ValueError: It uses hypre's BoomerAMG, which this PETSc does not have.
        """
        setup = STOKES_SOLVERS[cls.name]
        if setup.needs_hypre and not HAS_HYPRE:
            raise ValueError(f"Stokes solver {cls.name!r} uses hypre's BoomerAMG, which this PETSc does not have; "
                             "use 'iterative_gamg' or 'direct'")
        return setup


def _choice(setup: StokesLinearSolver, /) -> type[StokesSolverChoice]:
    """The choice of the setup ``setup`` itself."""
    return type(f"StokesSolver_{setup.name}", (StokesSolverChoice,), {
        "__doc__": f"``stokes.solver: {setup.name}``: {setup.description}.", "name": setup.name,
        "description": setup.description, "nested": setup.nested})


class AutoStokesSolver(StokesSolverChoice):
    """The choice ``"auto"``: a solver of :data:`STOKES_SOLVERS` picked by the mesh (:func:`resolve_solver`)."""

    name = AUTO
    description = ("multigrid in 3D on a fixed box whose cells halve twice (e.g. 16^3, 20^3) or a fixed spherical "
                   "shell whose gmsh size is at most 1/8 of its thickness, else iterative in 3D (iterative_gamg for "
                   "a shell with free slip on both surfaces), direct in 2D")
    by_mesh = True

    @classmethod
    def build(cls, settings: StokesSettings, context: StokesSolverContext, /) -> StokesLinearSolver:
        """``"iterative"`` in 3D (``"iterative_gamg"`` with rotations or without hypre), ``"direct"`` in 2D."""
        if context.gdim == 3:
            picked = "iterative_gamg" if context.rotations or not HAS_HYPRE else "iterative"
        else:
            picked = "direct"
        return STOKES_SOLVER_CHOICES.build(picked, dataclasses.replace(settings, solver=picked), context)


STOKES_SOLVER_CHOICES: Registry[type[StokesSolverChoice]] = Registry(
    "Stokes solver", (AutoStokesSolver, *(_choice(setup) for setup in STOKES_SOLVERS.values())))
"""What ``StokesSolver(solver=...)`` and the config's ``stokes.solver`` accept: ``"auto"`` and one
choice per entry of :data:`STOKES_SOLVERS`; each builds a setup of :data:`STOKES_SOLVERS`."""

STOKES_SOLVER_NAMES: tuple[str, ...] = tuple(STOKES_SOLVER_CHOICES)
"""Every name ``StokesSolver(solver=...)`` and the config's ``stokes.solver`` accept."""


_DEFAULTS = StokesSettings()


def check_viscosity_rules(depends_on: Collection[str], /, *, buoyancy_theta: float, method: str,
                          pressure_level_free: bool) -> None:
    """The rules that tie the Stokes settings to the viscosity, stated once for the config check
    and for :class:`StokesSolver`: a semi-implicit buoyancy needs a viscosity that does not depend
    on the flow, and Newton's method with a pressure-dependent viscosity needs a defined pressure
    level (a traction-free side).

    Args:
        depends_on: What the viscosity laws read (:attr:`ViscosityLaw.depends_on`: ``"strain_rate"``,
            ``"pressure"``, ``"field:<name>"``, ...).
        buoyancy_theta, method: ``stokes.buoyancy_theta`` and ``stokes.nonlinear.method``.
        pressure_level_free: Every side has a velocity condition (the pressure is determined up
            to a constant).

    Raises:
        ConfigError: A rule is broken (one line naming the key).
    """
    if {"strain_rate", "pressure"} & set(depends_on) and buoyancy_theta != 0.0:
        raise ConfigError("config key 'stokes.buoyancy_theta': the semi-implicit buoyancy is not available with a "
                          "viscosity that depends on the flow (strain rate or pressure)")
    if "pressure" in depends_on and pressure_level_free and method == "newton":
        raise ConfigError("config key 'stokes.nonlinear.method': newton with a pressure-dependent viscosity "
                          "(drucker_prager) needs a defined pressure level: leave a side traction free (null) or "
                          "use picard")


CoarseMeshes = Sequence[dolfinx.mesh.Mesh] | Callable[[dolfinx.mesh.Mesh], Sequence[dolfinx.mesh.Mesh]]
"""The meshes a multigrid's levels are made of, coarse to fine, or a collective callable making them
from the fine mesh."""


def _levels_of(mesh: dolfinx.mesh.Mesh, solver: str, coarse_meshes: CoarseMeshes, /
               ) -> tuple[str, tuple[dolfinx.mesh.Mesh, ...]]:
    """The solver for ``mesh`` and, for the multigrid, the coarser meshes it is nested in
    (collective with a callable ``coarse_meshes``).

    An adaptive mesh that has none (a repartition left it unrefined: the boxes below its base no
    longer nest in it rank by rank, :class:`convection.adapt.levels.MeshLevels`) is solved with
    the AMG block preconditioner until a mesh has levels again.

    Raises:
        ValueError: The multigrid without coarser meshes for a fixed mesh.
    """
    if not STOKES_SOLVERS[solver].nested:
        return solver, ()
    coarse = tuple(coarse_meshes(mesh) if callable(coarse_meshes) else coarse_meshes)
    if coarse:
        return solver, coarse
    if callable(coarse_meshes):
        return ("iterative" if HAS_HYPRE else "iterative_gamg"), ()
    raise ValueError("the multigrid Stokes solver needs the coarser meshes the mesh is nested in "
                     "(coarse_meshes=, Domain.create_mesh_levels)")


def _linear_system(schur: str, discretisation: StokesDiscretisation, /) -> Callable[..., StokesLinearSystem]:
    """The linear system's class for the Schur approximation ``schur`` (``stokes.schur``)."""
    if schur == "mass":
        return StokesLinearSystem
    return functools.partial(WeightedBFBtSystem, component=discretisation.component_space(0))


def _free_surfaces(surface: SurfaceTerms | None, /) -> dict[str, VelocityBC]:
    """The free surfaces as velocity conditions (for the rotations: a free surface lets them)."""
    return {name: VelocityBC("free_surface") for name in (surface.names if surface is not None else ())}


def resolve_solver(name: str, gdim: int, /, *, rotations: bool = False) -> str:
    """The registry name behind ``name``: ``"auto"`` is ``"iterative"`` in 3D (``"iterative_gamg"``
    when ``rotations``, i.e. both shell surfaces are free slip) and ``"direct"`` in 2D, any other
    name is itself.

    In 2D MUMPS is exact and cheap: with a constant viscosity it reuses its factorisation (0.03 s
    per solve at 64 x 64 P2-P1, against ~0.5 s for a cold iterative solve), and 2D runs keep the
    results they had before the iterative solver became the 3D default.

    A spherical shell with free slip on both surfaces has the three rigid rotations as near-null
    modes of the velocity block (the Nitsche penalty pins them only weakly, see the module
    docstring). BoomerAMG does not see them and FGMRES stalls: 510 iterations from zero and 765
    warm-started at gmsh size 0.35 (P2 geometry, Ra = 1e4), 661 / 567 at 0.5. GAMG is given the
    rigid-body modes, rotations included, as its near-null space: 54 / 13 at 0.35, 74 / 40 at 0.5,
    and its velocity agrees with MUMPS's to 2e-6 (BoomerAMG's to 4e-5).

    A PETSc without hypre (the one in PyPI's DOLFINx wheel) has no BoomerAMG: there ``"auto"`` is
    ``"iterative_gamg"`` in 3D, and ``"iterative"`` is refused (ValueError).
    """
    if name not in STOKES_SOLVER_CHOICES:
        raise ValueError(f"Unknown Stokes solver {name!r}; valid names: {list(STOKES_SOLVER_NAMES)}")
    settings = dataclasses.replace(_DEFAULTS, solver=name)
    return STOKES_SOLVER_CHOICES.build(name, settings, StokesSolverContext(gdim, rotations)).name


def _same_objects(a: Any, b: Any) -> bool:
    """True when ``a`` and ``b`` are the same objects, element by element for tuples and lists."""
    if isinstance(a, (tuple, list)) and isinstance(b, (tuple, list)):
        return len(a) == len(b) and all(_same_objects(x, y) for x, y in zip(a, b))
    return a is b


class StokesResult(NamedTuple):
    """Outcome of :meth:`StokesSolver.solve`.

    Attributes:
        iterations: Krylov iterations (1 for the direct solver).
        residual_norm: Euclidean norm of the true residual ``b - K x`` of the assembled system.
        assembly_seconds: Time spent assembling the operator and the right-hand side.
        solve_seconds: Time spent in the linear solver (with the residual check).
        setup_seconds: The part of ``solve_seconds`` spent setting up the preconditioner (AMG
            hierarchy, LU factorisation): after every operator change, i.e. every solve with a
            variable viscosity, once otherwise.
        nonlinear: The nonlinear iteration's outcome (a viscosity that depends on the flow), or
            None (a linear solve).
        assemblies: How many times this solve assembled the operator anew: 1 or 0 for a linear
            solve (0: the viscosity and the mesh did not change, the last operator was kept; the
            semi-implicit buoyancy's term is added to it), the nonlinear iterations otherwise.
    """

    iterations: int
    residual_norm: float
    assembly_seconds: float = 0.0
    solve_seconds: float = 0.0
    setup_seconds: float = 0.0
    nonlinear: NonlinearResult | None = None
    assemblies: int = 0


class StokesSolver(PetscSolver):
    """Stokes solver on a fixed mesh (see the module docstring for equations and solvers).

    Three components do the work: :class:`~convection.solvers.stokes.forms.StokesDiscretisation` (spaces,
    strong conditions, forms), :class:`~convection.solvers.stokes.linear.StokesLinearSystem` (matrices,
    null spaces, the KSP) and, with ``buoyancy_theta > 0``,
    :class:`~convection.physics.buoyancy.SemiImplicitBuoyancy` (the predicted buoyancy's operator term).
    This class chooses the linear solver, rebuilds the forms when the fields change, and normalises
    the solution (zero-mean pressure, no rigid rotation).

    Args:
        mesh: box mesh (2D or 3D).
        approximation: physics parameters and viscosity law.
        bcs: velocity condition per boundary name (see :mod:`convection.geometry.boundary`); boundaries
            not listed are traction free.
        domain: the domain (:mod:`convection.geometry.domain`; its boundary names, how free slip is
            imposed, where the pressure is pinned). Default: the box the mesh fills
            (:meth:`convection.geometry.box.BoxDomain.around`).
        degree: velocity degree ``k >= 2``; the pressure has degree ``k - 1``.
        solver: a name in :data:`STOKES_SOLVER_NAMES`: ``"auto"`` (iterative in 3D, GAMG's for a
            shell free slip on both surfaces; direct in 2D), ``"direct"``, ``"iterative"`` or ``"iterative_gamg"``.
        petsc_options: extra PETSc options overriding the defaults (without prefix), e.g.
            ``{"ksp_rtol": 1e-6}``.
        nitsche_penalty: penalty factor of the weak free-slip condition on curved boundaries
            (default ``10 (degree + 1)^2``).
        buoyancy_theta: 0 (the default): the buoyancy of the current fields; ``0 < theta <= 1``:
            the buoyancy predicted at ``t + theta dt`` along the flow
            (:class:`convection.physics.buoyancy.SemiImplicitBuoyancy`; ``dt`` is given to :meth:`solve`).
        nonlinear: Picard or Newton settings (:mod:`convection.solvers.stokes.nonlinear`), used when the
            viscosity depends on the flow (default: :class:`NonlinearSettings`'s defaults).
        multigrid, schur: The ``stokes.multigrid`` settings (how many levels the caller makes), ``stokes.schur``.
        surface: The free surfaces' terms (:mod:`convection.deform.surface`; not in ``bcs``), or None.
        coarse_meshes: The meshes ``mesh`` is nested in, coarse to fine
            (:meth:`convection.geometry.domain.Domain.create_mesh_levels`), or what gives them for a
            mesh (:class:`convection.adapt.levels.MeshLevels`: also for the meshes of an adaptive
            run, :meth:`on_mesh`; its ``locate``, if it has one, finds the nodes of a finer level in
            a coarser one: curved levels): required by ``solver="multigrid"``, ignored otherwise.

    Attributes:
        u: velocity, vector P(degree) Function; also the initial guess of the next iterative solve.
        p: pressure, P(degree-1) Function (zero mean when the pressure has a null space).
        V, Q: the velocity and pressure spaces; solver: the registry name in use (``"auto"`` resolved).
        is_iterative: True for the Krylov solvers.
        discretisation: the spaces and forms.
        linear_system: the matrices, vectors and KSP (:attr:`ksp`).
        forms: the forms of the fields of the last :meth:`prepare` (None before).
    """

    KIND = "Stokes"
    SOLVERS = STOKES_SOLVERS
    PETSC_OBJECTS = ("_nonlinear", "ksp", "linear_system")

    def __init__(self, mesh: dolfinx.mesh.Mesh, approximation: BoussinesqApproximation, /, *,
                 bcs: dict[str, VelocityBC], domain: Domain | None = None, degree: int = _DEFAULTS.degree,
                 solver: str = _DEFAULTS.solver, petsc_options: Mapping[str, Any] | None = None,
                 nitsche_penalty: float | None = None, buoyancy_theta: float = _DEFAULTS.buoyancy_theta,
                 nonlinear: NonlinearSettings = _DEFAULTS.nonlinear, multigrid: MultigridSettings = _DEFAULTS.multigrid,
                 coarse_meshes: CoarseMeshes = (), schur: str = _DEFAULTS.schur,
                 surface: SurfaceTerms | None = None) -> None:
        if degree < 2:
            raise ValueError("Taylor-Hood needs velocity degree >= 2")
        self.prepare_process()
        self.mesh = mesh
        self.approximation = approximation
        self.bcs = dict(bcs)
        self.domain = domain if domain is not None else BoxDomain.around(mesh)
        self.domain.check_boundary_names(self.bcs)
        self.degree = degree
        self.nitsche_penalty = float(10 * (degree + 1) ** 2 if nitsche_penalty is None else nitsche_penalty)
        self.has_rotation_null_space = has_rotation_null_space({**self.bcs, **_free_surfaces(surface)}, self.domain)
        self.buoyancy_theta = float(buoyancy_theta)
        self.nonlinear_settings, self.multigrid_settings, self.schur = nonlinear, multigrid, schur
        self.is_nonlinear = approximation.is_nonlinear
        self._coarse_meshes = coarse_meshes
        check_viscosity_rules(approximation.viscosity_law.depends_on, buoyancy_theta=self.buoyancy_theta,
                              method=nonlinear.method, pressure_level_free=set(self.domain.boundaries) <= set(self.bcs))
        self._semi_implicit = (SemiImplicitBuoyancy(mesh, approximation, self.buoyancy_theta)
                               if self.buoyancy_theta != 0.0 else None)
        self._asked_solver = solver
        resolved = resolve_solver(solver, mesh.geometry.dim, rotations=self.has_rotation_null_space)
        name, coarse = _levels_of(mesh, resolved, coarse_meshes)
        self._petsc_options = self._create_ksp(mesh.comm, name, petsc_options)
        kind = STOKES_SOLVERS[name]
        self.is_iterative = kind.iterative
        self._petsc_options.update(schur_options(schur, self._user_options, solver=name, iterative=kind.iterative))
        self.surface = surface
        self.discretisation = StokesDiscretisation(mesh, approximation, domain=self.domain, bcs=self.bcs, degree=degree,
                                                   nitsche_penalty=self.nitsche_penalty, surface=surface)
        self.V, self.Q = self.discretisation.V, self.discretisation.Q
        hierarchy = None
        if kind.nested:
            hierarchy = VelocityMultigrid(self.V, coarse, locate=getattr(coarse_meshes, "locate", None))
            self._petsc_options.update(multigrid.petsc_options(
                self._user_options, hierarchy.levels, variable_viscosity=approximation.is_variable_viscosity,
                curved=coordinate_map(mesh).degree > 1))
        self.u = dolfinx.fem.Function(self.V, name="velocity")
        self.p = dolfinx.fem.Function(self.Q, name="pressure")

        self.has_pressure_null_space = all(s in self.bcs for s in self.domain.boundaries)
        self._rotations = RigidRotations(self.V) if self.has_rotation_null_space else None
        self.linear_system: StokesLinearSystem | None = _linear_system(schur, self.discretisation)(
            self.u, self.p, self.ksp, dirichlet=self.discretisation.dirichlet, domain=self.domain,
            iterative=self.is_iterative, pressure_null_space=self.has_pressure_null_space, multigrid=hierarchy,
            term_in_preconditioner=kind.nested, operator_preconditions=kind.nested and not self.is_nonlinear)
        self._pressure_mean = pressure_normaliser(self.linear_system, self.discretisation)

        lags = (kind.nested and not self.is_nonlinear and self._semi_implicit is not None
                and not approximation.is_variable_viscosity and multigrid.rebuild_steps > 1)
        self._lag = LaggedPreconditioner(mesh, multigrid.rebuild_steps, multigrid.rebuild_dt_change) if lags else None
        self.forms: StokesForms | None = None
        self._forms_key: tuple[Any, Any] | None = None
        self._operator_current = False
        self._nonlinear = (NonlinearStokes(self.discretisation, self.linear_system, self.nonlinear_settings,
                                           normalise=self._normalise_pressure) if self.is_nonlinear else None)

    @property
    def description(self) -> str:
        """The linear solver in use, for the run's closing lines: ``"multigrid (3 levels)"``,
        ``"iterative"``, ...; ``"auto"`` resolved."""
        multigrid = self.linear_system.multigrid if self.linear_system is not None else None
        return self.solver if multigrid is None else f"{self.solver} ({multigrid.levels} levels)"

    def settings(self) -> dict[str, Any]:
        return {"bcs": self.bcs, "domain": self.domain, "degree": self.degree, "solver": self._asked_solver,
                "petsc_options": self._user_options,
                "nitsche_penalty": self.nitsche_penalty, "buoyancy_theta": self.buoyancy_theta,
                "nonlinear": self.nonlinear_settings, "multigrid": self.multigrid_settings, "schur": self.schur,
                "coarse_meshes": self._coarse_meshes, "surface": self.surface}

    def prepare(self, T: Any, C: Any = None, /, *, fields: dict[str, Any] | None = None) -> StokesForms:
        """The forms for ``T`` and ``C`` (arguments as in :meth:`solve`): built again unless these
        very objects were prepared last; the linear algebra is set up on the first call.
        Collective. :meth:`solve` calls it; call it first to change the returned forms (e.g.
        ``stokes.forms = forms._replace(L=...)``, same spaces), which the next solve with the same
        ``T`` and ``C`` then uses."""
        key = (T, C, tuple(sorted((fields or {}).items(), key=lambda item: item[0])))
        if self._forms_key is None or not _same_objects(self._forms_key, key):
            flow = {"u": self.u, "p": self.p, "fields": fields or {}}
            self.forms = self.discretisation.forms(T, C, pressure_block=self.linear_system.pinned,
                                                   preconditioner=self.is_iterative, weights=self.schur == "wbfbt",
                                                   semi_implicit=self._semi_implicit, flow=flow)
            if self._forms_key is not None and self._lag is not None:
                self._lag.dt = None  # new forms: set the preconditioner up at the next solve
            self._forms_key = key
            self._operator_current = False
            if not self.linear_system.is_set_up:
                set_owned_options(self, self._prefix, self._petsc_options)
                self.linear_system.setup(self.forms)
        return self.forms

    def solve(self, T: Any, C: Any = None, /, *, dt: float = 0.0,
              fields: dict[str, Any] | None = None) -> StokesResult:
        """Solve for ``(u, p)`` given temperature ``T`` and composition ``C``. Collective.

        Args:
            T: temperature (Function, UFL expression or number).
            C: composition: ``None``, one material fraction (Function of any degree, UFL
                expression or number) or a tuple of them, one per material (see
                :func:`convection.physics.approximation.fractions`).
            dt: the coming step, for a semi-implicit buoyancy (``buoyancy_theta > 0``), and elasticity's
                ``dt_e`` (0: the viscous flow); ignored otherwise.
            fields: named mesh fields the viscosity laws read (e.g. ``{"plastic_strain": f}``).

        Returns:
            Iteration count, true residual norm and timings. An iterative solve starts from the
            current ``u``, ``p`` (the previous solution) and stops at ``|b - K x| <= rtol |b|``.
        """
        forms = self.prepare(T, C, fields=fields)
        t0 = time.perf_counter()
        if self.discretisation.set_steps(dt):  # a free surface's stabilisation, elasticity's dt_e (issue 48)
            self._operator_current = False
        if self._nonlinear is not None:
            result = self._nonlinear.solve(forms, self._forms_key, T, C, fields)
            if self._rotations is not None:
                self._rotations.remove(self.u)
            self._operator_current = False
            seconds = time.perf_counter() - t0
            return StokesResult(result.linear_iterations, result.residual, 0.0, seconds, 0.0, result,
                                assemblies=result.iterations)
        if self._semi_implicit is not None:
            self._semi_implicit.update(dt)
        refresh = not self._operator_current or self.approximation.is_variable_viscosity
        lag = self._lagged()
        reuse = lag is not None and not lag.due(dt)
        restart_setup = assemble_operator(self.linear_system, forms, self._semi_implicit, refresh=refresh,
                                          lag=lag if reuse else None)
        self._operator_current = True
        self.linear_system.assemble_rhs(forms)

        t1 = time.perf_counter()
        setup_seconds = self.linear_system.solve(reuse_preconditioner=reuse) + restart_setup
        if lag is not None:
            if reuse:
                lag.kept()
            else:
                lag.set_up(dt, self._semi_implicit.coefficients())
        self._normalise_pressure()
        if self._rotations is not None:
            self._rotations.remove(self.u)
        norm = self.linear_system.residual_norm()
        return StokesResult(int(self.linear_system.iterations), norm, t1 - t0, time.perf_counter() - t1,
                            setup_seconds, assemblies=int(refresh))

    def mesh_moved(self) -> None:
        """The mesh's nodes moved (a free surface): a new operator and rotations at the next solve."""
        self._operator_current = False
        if self._rotations is not None:
            self._rotations.mesh_moved()

    def _lagged(self) -> LaggedPreconditioner | None:
        """The lag of the preconditioner, None where it is set up at every operator change (also
        where a checkpoint could not keep the term's coefficients)."""
        if self._lag is not None and not LaggedPreconditioner.supports(self._semi_implicit.coefficients()):
            self._lag = None
        return self._lag

    def _normalise_pressure(self) -> None:
        """Shift the pressure to zero mean where the constant pressure (ALA: its mode) is free (collective)."""
        if self._pressure_mean is not None:
            self._pressure_mean.normalise()

    # ------------------------------------------------------------------ checkpoints
    def state(self) -> State:
        """The solution (the next iterative solve's initial guess) and, where the preconditioner
        lags, what it was set up from (:meth:`LaggedPreconditioner.state`, under ``preconditioner``)."""
        out = State(fields={"u": self.u, "p": self.p})
        if self._lag is not None:
            lagged = self._lag.state()
            out.fields.update({f"preconditioner/{name}": f for name, f in lagged.fields.items()})
            out.scalars["preconditioner"] = lagged.scalars
        return out

    def restore(self, scalars: Mapping[str, Any], /) -> dict[str, dolfinx.fem.Function]:
        """The Functions a checkpoint fills: ``u``, ``p`` and the lagged preconditioner's."""
        out = {"u": self.u, "p": self.p}
        if self._lag is not None and "preconditioner" in scalars:
            out.update({f"preconditioner/{k}": f for k, f in self._lag.restore(scalars["preconditioner"]).items()})
        return out

    # ------------------------------------------------------------------ adaptivity
    def transfer_from(self, old: StokesSolver,
                      transfer: Callable[[dolfinx.fem.Function, dolfinx.fem.Function], None]) -> None:
        """Copy ``u`` and ``p`` (the initial guess) from ``old``, a solver on the previous mesh, by
        ``transfer(src_on_old_mesh, dst_on_new_mesh)`` (e.g. interpolation between non-matching
        meshes). Collective."""
        transfer(old.u, self.u)
        transfer(old.p, self.p)
        self.u.x.scatter_forward()
        self.p.x.scatter_forward()
