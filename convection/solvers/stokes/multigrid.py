"""Geometric multigrid on the Stokes velocity block (``stokes.solver: multigrid``).

The block preconditioner of the iterative Stokes solvers (:func:`convection.solvers.stokes.solver.block_schur_options`)
needs one approximate solve with the velocity block ``A`` (``2 eta eps(u) : eps(v)`` on vector
P2) per outer iteration. Algebraic multigrid (BoomerAMG) on P2 elasticity-type operators needs
more outer iterations the finer the mesh (38 per time step at 16³ on the 3D thick layer, issue 34).
Geometric multigrid uses the meshes the run's mesh was refined from: a box of ``n`` cells per side
nests in the box of ``2 n`` (:meth:`convection.geometry.box.BoxDomain.create_mesh_levels`), so the
coarse velocity spaces ``V_0 ⊂ V_1 ⊂ ... ⊂ V_L = V`` (the same element on each mesh) are nested and
the prolongation from level ``l - 1`` to ``l`` is exact interpolation
(:func:`fembase.multigrid.prolongation`: ``P[i, j] = phi_j(x_i)``).

One V-cycle of PETSc's PCMG replaces the AMG cycle:

- coarse operators by Galerkin products, ``A_{l-1} = P_l^T A_l P_l`` (PETSc's ``pc_mg_galerkin``),
  so they carry the viscosity (and a varying one's contrasts) of the fine operator exactly, and the
  strong conditions' unit rows with it; they are formed again only when ``A`` changes; on several
  ranks by PETSc's all-at-once product, which keeps no intermediate (:data:`GALERKIN_PRODUCT`);
- two Chebyshev steps with point-Jacobi preconditioning before and after the coarse correction on
  every level (the Chebyshev interval ``[0.1, 1.1] lambda_max``, PETSc's default, with
  ``lambda_max`` estimated at each set-up by GMRES steps):

  - with a constant viscosity 4 steps, not PETSc's 10: the same iterations from 8^3 to 16^3 (and
    with smooth contrasts of 1e4 and 1e6: 13 14 / 32 32 / 47 47 against 13 14 / 32 32 / 48 48; 2D
    64^2 and 256^2 within one), for half the estimate's cost, 4 % of a 16^3 thick-layer step,
    where the semi-implicit term changes the operator every solve (a set-up then serves several
    solves, :mod:`convection.solvers.stokes.lagged`);
  - with a variable viscosity 10 (:data:`VARIABLE_VISCOSITY_ESTIMATE_STEPS`): a sharp contrast's stiff
    modes are local, and 4 steps miss them, so the Chebyshev interval ends below ``lambda_max`` and
    the smoother amplifies them. A 1e3 layer in the unit cube at 16^3, 2 ranks: 169 outer iterations
    with 4 steps, 84 with 10 or 20 (a smooth 1e3 contrast: 24 and 25). nsinker: benchmarks/nsinker;
- an exact solve on the coarsest level (``redundant``: every rank factorises the small coarsest
  operator, LU by MUMPS), the same on any rank count. A fixed shell's coarsest level is gmsh's
  shell at a few times the cell size, thousands of cells (:meth:`convection.geometry.shell.ShellDomain.mesh_levels`):
  PETSc's own LU took 4.9 of the 6.5 s set-up there (gmsh size 0.485, 1929 cells, 2 ranks), MUMPS
  brings the set-up to 3.0 s.

At large viscosity contrasts (the nsinker problem, ``benchmarks/nsinker``: DR = 1e4 and more) point-Jacobi
Chebyshev stalls; ``stokes.multigrid.smoother: sor`` smooths with Chebyshev on SOR (symmetric sweeps on each
rank, block Jacobi between ranks) instead (:data:`MULTIGRID_SMOOTHERS`), with ``lambda_max`` from 10 GMRES
steps, whatever the viscosity: on one rank SOR's spectrum is bounded and 4 steps do, but block Jacobi between
ranks widens it and 4 steps underestimate it (nsinker 8^3, 2 ranks, DR 1e6 with ``stokes.schur: wbfbt``: 639
outer iterations with 4 steps, 73 with 10, 74 with 20). The default stays Jacobi: where the contrasts are
smooth SOR needs the same iterations, each dearer (a 1e3 contrast in T at 16^3: 24 and 24), and on nsinker
at 16^3 with w-BFBt about as many at 1.5 times the time (8.25 against 5.25 s at DR 1e2, benchmarks/nsinker).

PETSc options under ``fieldsplit_u_`` (``stokes.petsc_options``) change any of this, e.g.
``fieldsplit_u_mg_levels_ksp_max_it: 3``.

The prolongations are built once for the mesh; the coarse spaces are dropped after that. PETSc's
fieldsplit creates the velocity block's PC when the block preconditioner is first set up, so
:class:`VelocityMultigrid` hands the prolongations to it then
(:meth:`convection.solvers.stokes.linear.StokesLinearSystem.solve`).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

import dolfinx
from mpi4py import MPI
from petsc4py import PETSc

from convection.schema import Names, param
from fembase.dolfinx_compat import element_degree, function_space
from fembase.location import Located
from fembase.multigrid import prolongation

__all__ = ["GALERKIN_PRODUCT", "GEOMETRIC_MULTIGRID", "MULTIGRID_SMOOTHERS", "MultigridSettings", "VelocityMultigrid",
           "galerkin_products"]

MAX_LEVELS = 12
"""Most multigrid levels a config may ask for (4096 times fewer cells per side on the coarsest)."""


MULTIGRID_SMOOTHERS: dict[str, str] = {
    "jacobi": "two Chebyshev steps with point-Jacobi on every level, lambda_max from 4 GMRES steps (10 with a "
              "variable viscosity; the default)",
    "sor": "two Chebyshev steps with SOR (on each rank) on every level, lambda_max from 10 GMRES steps: robust at "
           "large viscosity contrasts (benchmarks/nsinker)",
}
"""The level smoothers of ``stokes.multigrid.smoother``."""

_ESTIMATE_STEPS = "fieldsplit_u_mg_levels_ksp_chebyshev_esteig_steps"
VARIABLE_VISCOSITY_ESTIMATE_STEPS = 10
"""GMRES steps of every level's ``lambda_max`` estimate when the viscosity varies (4 when it is constant):
module docstring. Also on curved levels (a shell's), where 4 steps fall short as well:
configs/shell_plates.yaml at gmsh size 0.125 (3 levels, 123 456 cells, 2 ranks), first solve: 250 outer
iterations with 4 steps, 21 with 10 (4 smoothing steps instead of 2: 196); BoomerAMG on the same mesh: 81."""

_SMOOTHER_OPTIONS: dict[str, dict[str, Any]] = {
    "jacobi": {},
    # Point-Jacobi Chebyshev stalls on nsinker's contrasts (8^3, 4 sinkers: > 1000 outer iterations from
    # DR = 1e4 on): its 4-step lambda_max estimate is too low there (20 steps: 220 at 1e6). Chebyshev on
    # SOR-preconditioned levels needs 37 / 68 / 138 at DR 1e2 / 1e4 / 1e6 (an exact velocity solve: 30 / 56 / 89).
    # On several ranks SOR is block Jacobi between them, and lambda_max needs 10 estimate steps (module docstring).
    "sor": {"fieldsplit_u_mg_levels_pc_type": "sor", _ESTIMATE_STEPS: VARIABLE_VISCOSITY_ESTIMATE_STEPS},
}


@dataclass(frozen=True)
class MultigridSettings:
    """The ``stokes.multigrid`` config section (``stokes.solver: multigrid``)."""

    levels: int = param(0, minimum=0, maximum=MAX_LEVELS,
                        help="meshes in the hierarchy, the run's mesh included (box: each coarser has half the cells "
                             "per side); 0: halve while every count is even and stays >= 2 (16 -> 8 -> 4 -> 2: 4); "
                             "an adaptive mesh adds its refinement rounds above the base (convection/adapt/levels.py); "
                             "a fixed shell: gmsh's shell at resolution * 2^(levels-1) refined uniformly levels-1 "
                             "times, 0: as many as keep its cells at most half the thickness")
    rebuild_steps: int = param(10, minimum=1,
                               help="solves a preconditioner serves at most while only the semi-implicit buoyancy's "
                                    "term changes (a linear solve, constant viscosity); 1: set up at every solve "
                                    "(convection/solvers/stokes/lagged.py)")
    rebuild_dt_change: float = param(0.25, minimum=0.0,
                                     help="the kept preconditioner is set up again when the step changed by more than "
                                          "this fraction since its set-up")
    smoother: str = param("jacobi", choices=Names(MULTIGRID_SMOOTHERS),
                          help="level smoother: jacobi (Chebyshev/point-Jacobi, the default) or sor (Chebyshev/SOR, "
                               "robust at viscosity contrasts of 1e4 and more, benchmarks/nsinker)")

    def petsc_options(self, user: Mapping[str, Any] | None = None, levels: int | None = None, /, *,
                      variable_viscosity: bool = False, curved: bool = False) -> dict[str, Any]:
        """The Stokes solver's PETSc options this section sets: the smoother's (with a ``variable_viscosity``
        or ``curved`` levels the Chebyshev bound from :data:`VARIABLE_VISCOSITY_ESTIMATE_STEPS`), but for
        those the ``user``'s options (``stokes.petsc_options``) set, and ``fieldsplit_u_pc_mg_levels`` when
        ``levels`` is given."""
        options = dict(_SMOOTHER_OPTIONS[self.smoother])
        if variable_viscosity or curved:
            options[_ESTIMATE_STEPS] = VARIABLE_VISCOSITY_ESTIMATE_STEPS
        options = {key: value for key, value in options.items() if key not in (user or {})}
        return options if levels is None else {**options, "fieldsplit_u_pc_mg_levels": levels}

GEOMETRIC_MULTIGRID: dict[str, Any] = {
    "pc_type": "mg",
    "pc_mg_galerkin": "both",
    "mg_levels_ksp_type": "chebyshev",
    "mg_levels_ksp_max_it": 2,
    "mg_levels_ksp_chebyshev_esteig_steps": 4,
    "mg_levels_pc_type": "jacobi",
    "mg_coarse_ksp_type": "preonly",
    "mg_coarse_pc_type": "redundant",
    "mg_coarse_redundant_pc_type": "lu",
    "mg_coarse_redundant_pc_factor_mat_solver_type": "mumps",
}
"""PCMG options of the velocity block (without the ``fieldsplit_u_`` prefix): see the module
docstring. ``pc_mg_levels`` is added by the solver from the number of meshes."""


GALERKIN_PRODUCT = "allatonce"
"""PETSc's algorithm for the Galerkin products ``P^T A P`` on several ranks (``matptap_via``, while the
PCMG sets itself up: :func:`galerkin_products`). PETSc's default (``scalable``) keeps the intermediate
``A P`` of every level for the next numeric product; the all-at-once product of Kong et al. (2019) forms
``P^T A P`` without it, at about twice the time of a numeric product. 3D thick layer on 2 ranks: peak
resident size 475 -> 424 MB a rank at 16^3; the whole run to t = 0.002 3.6 % longer (96 against 93 s,
best of three; benchmarks/performance/log/2026-12-07_memory_ptap.md). ``PETSC_OPTIONS="-matptap_via
scalable"`` brings PETSc's default back. On one rank (sequential matrices) PETSc has no such algorithm;
its default stays."""


@contextmanager
def galerkin_products(comm: PETSc.Comm | MPI.Comm, /) -> Iterator[None]:
    """PETSc's options database asks for :data:`GALERKIN_PRODUCT` in the products of the set-ups run
    inside (on several ranks; unless ``matptap_via`` is set already). The option is global: PETSc reads
    it from the product matrix, which has no prefix, at a product's symbolic stage. Not collective."""
    options = PETSc.Options()
    if comm.size == 1 or options.hasName("matptap_via"):
        yield
        return
    options["matptap_via"] = GALERKIN_PRODUCT
    try:
        yield
    finally:
        options.delValue("matptap_via")


class VelocityMultigrid:
    """The prolongations between the velocity spaces of nested meshes, handed to a PCMG.

    Args:
        V: The velocity space (vector Lagrange) on the finest mesh.
        coarse_meshes: The coarser meshes, coarse to fine, each nested in the next and the last in
            ``V``'s mesh, every cell on the rank of the coarser cell it lies in
            (:meth:`convection.geometry.domain.Domain.create_mesh_levels` without its last mesh).
            Collective.
        locate: Where the owned nodes of a finer space lie in a coarser mesh (cells and reference
            points; None: looked for in its cells), for curved levels whose cells are nested
            through their straight cells only (:meth:`convection.adapt.levels.MeshLevels.locate`).

    Raises:
        ValueError: No coarse mesh, or the meshes are not nested on this partition (every rank).
    """

    def __init__(self, V: dolfinx.fem.FunctionSpace, coarse_meshes: Sequence[dolfinx.mesh.Mesh], /, *,
                 locate: Callable[[dolfinx.mesh.Mesh, dolfinx.fem.FunctionSpace], Located | None] | None = None
                 ) -> None:
        if not coarse_meshes:
            raise ValueError("geometric multigrid needs at least one coarser mesh")
        degree = element_degree(V)
        shape = (V.mesh.geometry.dim,)
        spaces = [function_space(mesh, "Lagrange", degree, shape=shape) for mesh in coarse_meshes] + [V]
        self.interpolations: list[PETSc.Mat] = [
            prolongation(coarse, fine, located=locate(coarse.mesh, fine) if locate is not None else None)
            for coarse, fine in zip(spaces, spaces[1:])]
        self.unknowns = [space.dofmap.index_map.size_global * space.dofmap.index_map_bs for space in spaces]
        self._block: int | None = None  # the handle of the velocity block the PCMG is set up for

    @property
    def attached(self) -> bool:
        """Whether a velocity block's KSP has the prolongations (:meth:`attach`)."""
        return self._block is not None

    def keep(self, fieldsplit: PETSc.PC, reuse: bool, /) -> None:
        """Keep the set-up of the velocity block's PCMG (``reuse``) with the outer ``fieldsplit``
        PC's, or let it follow its matrix again, where that matrix is the Stokes operator's own
        block (a MATNEST's, which changes with every solve). Nothing before :meth:`attach`. Not
        collective by itself.

        PCMG itself and its finest level's smoother, whose operator is that block, are kept: the
        smoother's Jacobi would otherwise take the block's new diagonal at every solve. The kept
        smoother applies the current block with the diagonal and Chebyshev bounds of the set-up
        (Chebyshev estimates them only at a set-up); the coarser levels' Galerkin operators are
        those of the set-up anyway."""
        if not self.attached:
            return
        pc = fieldsplit.getFieldSplitSubKSP()[0].getPC()
        pc.setReusePreconditioner(reuse)
        pc.getMGSmoother(pc.getMGLevels() - 1).getPC().setReusePreconditioner(reuse)

    @property
    def levels(self) -> int:
        """The number of levels, the finest included."""
        return len(self.interpolations) + 1

    def configure(self, pc: PETSc.PC, /) -> None:
        """Give the velocity block's PC (of type mg, with :attr:`levels` levels from the options) the
        prolongations. Not collective by itself (PETSc's calls are)."""
        if pc.getType() != "mg" or pc.getMGLevels() != self.levels:
            raise ValueError(f"the velocity preconditioner is {pc.getType()!r} with {pc.getMGLevels()} levels, "
                             f"not mg with {self.levels}: stokes.petsc_options changed fieldsplit_u_pc_type")
        for level, P in enumerate(self.interpolations, start=1):
            pc.setMGInterpolation(level, P)

    def attach(self, ksp: PETSc.KSP, /, *, changed: bool = False) -> None:
        """Keep the velocity block's KSP (from fieldsplit, after its PC was set up) on a PCMG with
        these prolongations over its current matrix. Collective.

        The first call hands the prolongations to the PC fieldsplit made (:meth:`configure`). PCMG
        keeps the finest operator (and the matrix of its residuals) it first set up with unless
        the KSP's is that same matrix; when fieldsplit has made the velocity block anew, the PC is
        replaced by a new one from the same options, so that nothing of the old block is used.

        ``changed``: the block's values changed since the last solve. PCMG then updates its
        coarser (Galerkin) operators in place but hands them to their smoothers only the first
        time, so Chebyshev would keep the eigenvalue bounds of its first set-up on those levels
        (the finest level's smoother gets its operator every time): the preconditioner would
        depend on the run's history, and a resumed run would part from one that went on. Their
        operators are handed again, which makes each estimate its bounds anew at the set-up.

        The PCMG is set up here, from the block's current values, not at its first use: where the
        block is the operator's own (:meth:`keep`) it changes after the set-up (a restart sets the
        kept preconditioner up from the checkpoint's saved term, then assembles the current one:
        :func:`convection.solvers.stokes.lagged.assemble_operator`); and the Galerkin products
        take :data:`GALERKIN_PRODUCT` (:func:`galerkin_products`).
        """
        self._attach(ksp, changed)
        with galerkin_products(ksp.getComm()):
            ksp.setUp()

    def _attach(self, ksp: PETSc.KSP, changed: bool, /) -> None:
        A, P = ksp.getOperators()
        if self._block == P.handle:
            if changed:
                pc = ksp.getPC()
                for level in range(1, pc.getMGLevels() - 1):
                    smoother = pc.getMGSmoother(level)
                    smoother.setOperators(*smoother.getOperators())
            return
        if self._block is not None:
            old = ksp.getPC()
            pc = PETSc.PC().create(old.getComm())
            pc.setOptionsPrefix(old.getOptionsPrefix())
            ksp.setPC(pc)  # the KSP holds it (and drops the old PC)
            pc.destroy()
            ksp.setOperators(A, P)
            pc = ksp.getPC()
            pc.setFromOptions()
        self.configure(ksp.getPC())
        self._block = P.handle

    def destroy(self) -> None:
        """Free the prolongation matrices (collective)."""
        for P in self.interpolations:
            P.destroy()
        self.interpolations = []
