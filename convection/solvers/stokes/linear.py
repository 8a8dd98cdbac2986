"""The linear Stokes system ``K x = b`` in PETSc: matrices, vectors, null spaces and the KSP's life cycle.

``x = (u, p)`` has PETSc's block layout: on each rank its owned velocity dofs (block size gdim),
then its owned pressure dofs. :class:`StokesLinearSystem` assembles the forms of
:class:`convection.solvers.stokes.forms.StokesForms` and solves; it does not know the physics.

- **Operator**: ``K`` with the strong conditions (unit diagonal on their rows and columns). It is
  re-assembled only when the caller says it changed (new forms, or a variable viscosity); the
  preconditioner (AMG hierarchy, LU factorisation) is then set up again, otherwise reused. With a
  semi-implicit buoyancy the operator is ``K = K_0 + term``: ``K_0`` is kept, copied into ``K``
  every solve and the term (which changes with the fields and ``dt``) added to the velocity
  block, skipping the Dirichlet rows and columns; on a box, where the term lives in the vertical
  component's block, ``K_0`` is assembled into ``K`` and only that block's fixed entries are kept
  (:class:`convection.solvers.stokes.axis_block.AxisBlock`).
- **Preconditioner** (iterative solvers): the matrix ``P = [[A, B^T], [B, -M_p / eta]]``
  (assembled with ``K_0``; the semi-implicit term goes into its velocity block too where
  ``term_in_preconditioner``, on a box), PETSc fieldsplit on the velocity and pressure index sets
  (it takes the Schur factorisation's off-diagonal blocks from ``P``); the velocity set carries
  the block size gdim (AMG nodes) and the rigid-body modes as near-null space
  (:func:`convection.solvers.stokes.nullspace.rigid_body_modes`). Where ``P``'s velocity and
  coupling blocks are the operator's (``term_in_preconditioner`` and ``operator_preconditions``:
  the geometric multigrid of a linear solve), ``P`` is ``K`` itself and ``-M_p / eta`` a matrix of
  its own, fieldsplit's Schur preconditioning matrix (``user`` in place of ``a11``): the same
  preconditioner without a third copy of the velocity block (a quarter of the memory at 32^3)
  and without adding the term to it every solve. ``K`` is then a MATNEST (one matrix per block,
  :func:`fembase.dolfinx_compat.create_nest_matrix`; where a vector-form term needs a copy ``K_0``
  of the whole operator, monolithic), whose blocks fieldsplit takes as they are: no copy of the
  velocity and coupling blocks (16^3 thick layer on 2 ranks: 61 MB per rank, 1.1 kB per Stokes
  unknown). The multigrid's finest level then works with the current velocity block also while a
  lagged preconditioner is kept (:mod:`convection.solvers.stokes.lagged`: its coarse operators,
  Jacobi diagonals and Chebyshev bounds stay those of its set-up), where the copy froze it too.
  With ``stokes.schur: wbfbt`` the Schur complement's PC is the weighted BFBt
  (:class:`convection.solvers.stokes.bfbt.WeightedBFBtSystem`, this class's).
- **Constant pressure** (when it solves the homogeneous problem): a Krylov solver gets it as
  ``K``'s null space and ``b`` is made orthogonal to it; a direct solver instead pins one pressure
  dof (:meth:`convection.geometry.domain.Domain.pressure_pin`, a zero pressure block holds its
  diagonal) and makes the continuity right-hand side sum to zero (:func:`consistent_continuity`),
  so both solve the same system.
- **Warm start**: ``x`` starts from the current ``u``, ``p`` (a Krylov solver's nonzero initial
  guess; a direct solver ignores it), and the solution is written back to them.
"""

from __future__ import annotations

import time

import dolfinx
import dolfinx.fem.petsc
from mpi4py import MPI
from petsc4py import PETSc

from convection.geometry.domain import Domain
from convection.solvers.stokes.nullspace import constant_pressure_null_space, rigid_body_modes
from convection.solvers.petsc_options import destroy_petsc_objects
from convection.solvers.stokes.forms import StokesForms
from convection.solvers.stokes.axis_block import SemiImplicitOperator
from convection.solvers.stokes.multigrid import VelocityMultigrid
from fembase.dolfinx_compat import (DirichletBC, assemble_block_matrix, assemble_block_vector,
                                    create_block_matrix, create_block_vector, create_nest_matrix)

__all__ = ["StokesLinearSystem", "consistent_continuity", "owned_sizes", "pack_solution", "unpack_solution"]


def owned_sizes(V: dolfinx.fem.FunctionSpace, Q: dolfinx.fem.FunctionSpace, /) -> tuple[int, int]:
    """Owned velocity dofs (unrolled: nodes times block size) and owned pressure dofs."""
    return V.dofmap.index_map.size_local * V.dofmap.index_map_bs, Q.dofmap.index_map.size_local


def pack_solution(u: dolfinx.fem.Function, p: dolfinx.fem.Function, x: PETSc.Vec, /) -> None:
    """Copy the owned values of ``u`` and ``p`` into the block vector ``x``."""
    n_u, n_p = owned_sizes(u.function_space, p.function_space)
    x.array[:n_u] = u.x.array[:n_u]
    x.array[n_u:] = p.x.array[:n_p]


def unpack_solution(x: PETSc.Vec, u: dolfinx.fem.Function, p: dolfinx.fem.Function, /) -> None:
    """Copy the block vector ``x`` into ``u`` and ``p`` and update their ghosts (collective)."""
    n_u, n_p = owned_sizes(u.function_space, p.function_space)
    u.x.array[:n_u] = x.array_r[:n_u]
    p.x.array[:n_p] = x.array_r[n_u:n_u + n_p]
    u.x.scatter_forward()
    p.x.scatter_forward()


def _operator_matrices(forms: StokesForms, preconditions: bool, /) -> tuple[PETSc.Mat, PETSc.Mat | None]:
    """``K`` for ``forms`` and, where a vector-form semi-implicit term needs it (not on a box's
    axis), ``K_0``, its copy without the term. ``K`` is a MATNEST where it is its own
    preconditioning matrix (``preconditions``) and has no copy (module docstring)."""
    copy_a0 = forms.a_si is not None and forms.a_si_component is None
    nest = preconditions and not copy_a0
    A = create_nest_matrix(forms.a) if nest else create_block_matrix(forms.a)
    return A, create_block_matrix(forms.a) if copy_a0 else None


def consistent_continuity(vec: PETSc.Vec, V: dolfinx.fem.FunctionSpace, Q: dolfinx.fem.FunctionSpace,
                          pin: DirichletBC, /) -> None:
    """Make the continuity part of the block vector ``vec`` sum to zero, then zero the row of the
    pressure ``pin`` (direct solver with a pressure null space). Collective.

    The constant pressure is in the null space of the (symmetric) operator, so the system is
    solvable only if the continuity part of ``b`` sums to zero: the discrete flux of the
    prescribed velocities, ``int u . n ds``, must vanish. A velocity tangent to a circle or
    sphere, interpolated on the curved (or straight) cells, has a small flux, and pinning a
    pressure dof would put the whole defect into that one dof's continuity equation. Removing
    the mean instead spreads it over the domain, as the iterative solvers' null space does, so
    both solve the same system. With zero velocity data the continuity part is exactly zero
    and nothing changes."""
    n_u, n_p = owned_sizes(V, Q)
    g = vec.array[n_u:n_u + n_p]
    total = V.mesh.comm.allreduce(float(g.sum()), op=MPI.SUM)
    if total != 0.0:
        g -= total / Q.dofmap.index_map.size_global
    pinned = pin.dof_indices()[0]
    g[pinned[pinned < n_p]] = 0.0


def split_velocity_pressure(pc: PETSc.PC, is_u: PETSc.IS, is_p: PETSc.IS, near_null_space: PETSc.NullSpace,
                            gdim: int, /) -> None:
    """Make ``pc`` a fieldsplit on the velocity rows ``is_u`` and the pressure rows ``is_p`` (global
    numbering), the velocity block with block size ``gdim`` and ``near_null_space`` (the rigid-body
    modes). Collective.

    Fieldsplit attaches an IS's "nearnullspace" to the extracted velocity block, and the IS block
    size (one node = gdim dofs) becomes that block's block size (AMG nodes)."""
    pc.setType("fieldsplit")
    is_u.setBlockSize(gdim)
    is_u.compose("nearnullspace", near_null_space)
    pc.setFieldSplitIS(("u", is_u), ("p", is_p))


def schur_preconditioning_matrix(pc: PETSc.PC, S: PETSc.Mat, /) -> None:
    """Let the fieldsplit ``pc`` precondition its Schur complement with ``S`` (``user``) where its
    options ask for the preconditioning matrix's ``(1, 1)`` block (``a11``, the default), which
    ``S`` stands for. Not collective by itself."""
    asked = PETSc.Options(pc.getOptionsPrefix()).getString("pc_fieldsplit_schur_precondition", "a11")
    if asked.lower() == "a11":
        pc.setFieldSplitSchurPreType(PETSc.PC.SchurPreType.USER, S)


def velocity_pressure_sets(K: PETSc.Mat, V: dolfinx.fem.FunctionSpace, Q: dolfinx.fem.FunctionSpace, /
                           ) -> tuple[PETSc.IS, PETSc.IS]:
    """The velocity and pressure rows of the block matrix ``K`` (global numbering, owned rows). Collective."""
    n_u, n_p = owned_sizes(V, Q)
    start = K.getOwnershipRange()[0]
    comm = V.mesh.comm
    return (PETSc.IS().createStride(n_u, start, 1, comm=comm),
            PETSc.IS().createStride(n_p, start + n_u, 1, comm=comm))


def true_residual_norm(K: PETSc.Mat, x: PETSc.Vec, b: PETSc.Vec, /) -> float:
    """Euclidean norm of the true residual ``b - K x``. Collective."""
    residual = b.duplicate()
    K.mult(x, residual)
    residual.aypx(-1.0, b)
    norm = float(residual.norm())
    residual.destroy()
    return norm


class StokesLinearSystem:
    """Block matrices and vectors of the Stokes system and the KSP that solves it (module docstring).

    Args:
        u: velocity Function: the initial guess, overwritten by the solution.
        p: pressure Function: the same.
        ksp: the KSP to drive, its options already under its prefix before :meth:`setup`.
        dirichlet: the strong velocity conditions.
        domain: the domain (where to pin the pressure).
        iterative: True for a Krylov solver with the fieldsplit preconditioner, False for LU.
        pressure_null_space: whether the constant pressure solves the homogeneous problem.
        multigrid: the prolongations of a geometric multigrid on the velocity block (the options
            must make the velocity block's PC ``mg``), handed to it at the first solve; or None.
        term_in_preconditioner: whether the semi-implicit buoyancy's term goes into ``P`` too, on
            a box (the preconditioner is then set up every solve; worth it for the multigrid).
        operator_preconditions: with ``term_in_preconditioner``, ``P`` is the operator itself (no
            Newton Jacobian takes the operator's place); see the module docstring.

    Attributes:
        pinned: True when a pressure dof is pinned (direct solver with a pressure null space); the
            forms then need a pressure-pressure block.
    """

    PETSC_OBJECTS = ("_A", "_A0", "_P", "_S", "_b", "_x", "_null_space", "_near_null_space", "multigrid", "_term")

    def __init__(self, u: dolfinx.fem.Function, p: dolfinx.fem.Function, ksp: PETSc.KSP, /, *,
                 dirichlet: list, domain: Domain, iterative: bool, pressure_null_space: bool,
                 multigrid: VelocityMultigrid | None = None, term_in_preconditioner: bool = False,
                 operator_preconditions: bool = False) -> None:
        self.u, self.p, self.ksp, self.multigrid = u, p, ksp, multigrid
        self.term_in_preconditioner, self.operator_preconditions = term_in_preconditioner, operator_preconditions
        self.V, self.Q = u.function_space, p.function_space
        self.iterative, self.pressure_null_space = iterative, pressure_null_space
        self.pinned = pressure_null_space and not iterative
        self._lifted = list(dirichlet)  # the pin's value 0 lifts nothing: not in the right-hand side
        self._bcs = self._lifted + ([domain.pressure_pin(self.Q)] if self.pinned else [])
        self._A: PETSc.Mat | None = None
        self._A0: PETSc.Mat | None = None  # the operator without the semi-implicit term
        self._term: SemiImplicitOperator | None = None  # A = A0 + the semi-implicit buoyancy's term
        self._P: PETSc.Mat | None = None
        self._S: PETSc.Mat | None = None  # -M_p / eta where the operator is the preconditioning matrix
        self._preconditioner_changed = False  # P's values changed since the last solve
        self._b: PETSc.Vec | None = None
        self._x: PETSc.Vec | None = None
        self._null_space: PETSc.NullSpace | None = None
        self._near_null_space: PETSc.NullSpace | None = None

    @property
    def is_set_up(self) -> bool:
        """Whether :meth:`setup` has run."""
        return self._A is not None

    @property
    def A(self) -> PETSc.Mat | None:
        """The assembled operator ``K`` (with the semi-implicit term), None before :meth:`setup`."""
        return self._A

    @property
    def bcs(self) -> list:
        """All strong conditions: the velocity's, then the pressure pin if :attr:`pinned`."""
        return self._bcs

    @property
    def iterations(self) -> int:
        """Krylov iterations of the last solve (1 for the direct solver)."""
        return self.ksp.getIterationNumber() if self.iterative else 1

    # ------------------------------------------------------------------ setup
    def setup(self, forms: StokesForms, /) -> None:
        """Create the matrices and vectors for ``forms``' layout and configure the KSP. Collective.

        The matrices serve any later forms on the same spaces (same sparsity)."""
        operator_preconditions = self.iterative and self.term_in_preconditioner and self.operator_preconditions
        self._A, self._A0 = _operator_matrices(forms, operator_preconditions)
        self._b = create_block_vector(forms.L)
        self._x = self._b.duplicate()
        if operator_preconditions:
            self._S = dolfinx.fem.petsc.create_matrix(forms.a_pc[1][1])
        elif self.iterative:
            self._P = create_block_matrix(forms.a_pc)
        if self.pressure_null_space and self.iterative:
            n_u = self.V.dofmap.index_map.size_local * self.V.dofmap.index_map_bs
            self._null_space = constant_pressure_null_space(self._b, n_u)
        if not self.iterative:
            self.ksp.setOperators(self._A)
            self.ksp.setFromOptions()
            return
        self.ksp.setOperators(self._A, self.P)
        self._near_null_space = rigid_body_modes(self.V)
        split_velocity_pressure(self.ksp.getPC(), *self.index_sets(), self._near_null_space,
                                self.V.mesh.geometry.dim)
        self.ksp.setFromOptions()
        self.ksp.setInitialGuessNonzero(True)
        if self._S is not None:
            schur_preconditioning_matrix(self.ksp.getPC(), self._S)

    def index_sets(self) -> tuple[PETSc.IS, PETSc.IS]:
        """:func:`velocity_pressure_sets` of ``K``. Collective."""
        return velocity_pressure_sets(self._A, self.V, self.Q)

    # ------------------------------------------------------------------ assembly
    def assemble_operator(self, forms: StokesForms, /, *, refresh: bool) -> None:
        """Assemble ``K`` (and ``P``): the fixed part only when ``refresh`` (the forms or their
        viscosity changed), the semi-implicit term always. Collective."""
        fixed = self._A if self._A0 is None else self._A0
        if refresh:
            fixed.zeroEntries()
            assemble_block_matrix(fixed, forms.a, bcs=self._bcs)
            fixed.assemble()
            self._assemble_preconditioning(forms.a_pc)
        if forms.a_si is not None:
            # The semi-implicit term changes A with the fields and dt: A = A0 + term. The
            # preconditioning matrix P gets it too where term_in_preconditioner (the preconditioner
            # is then set up every solve); otherwise P, hence the preconditioner, stays while the
            # viscosity is constant.
            if self._term is None:
                self._term = SemiImplicitOperator(self._A, self._A0, self.V, self.Q, self._lifted, self._bcs)
            with_term = self._P if self.term_in_preconditioner else None
            if self._term.update(forms, refresh=refresh, preconditioner=with_term) or self._S is not None:
                self._preconditioner_changed = True
        if refresh or forms.a_si is not None:
            if self._null_space is not None:
                self._A.setNullSpace(self._null_space)

    def assemble_rhs(self, forms: StokesForms, /) -> None:
        """Assemble ``b`` (boundary values lifted with ``forms.a_lift``), consistent with the
        constant-pressure null space. Collective."""
        with self._b.localForm() as b_local:
            b_local.set(0.0)
        # The pin is left out of the right-hand side: its row keeps the value _consistent_continuity needs.
        assemble_block_vector(self._b, forms.L, forms.a_lift, bcs=self._lifted)
        if self._null_space is not None:
            self._null_space.remove(self._b)
        elif self.pinned:
            consistent_continuity(self._b, self.V, self.Q, self._bcs[-1])

    # ------------------------------------------------------------------ nonlinear solves
    @property
    def x(self) -> PETSc.Vec:
        """The solution vector ``(u, p)`` (block layout); :meth:`pack` fills it from ``u``, ``p``."""
        return self._x

    @property
    def b(self) -> PETSc.Vec:
        """The right-hand side of the last :meth:`assemble_rhs`."""
        return self._b

    @property
    def P(self) -> PETSc.Mat | None:
        """The preconditioning matrix (iterative solvers: :attr:`A` where it is the operator), None
        otherwise."""
        return self._A if self._S is not None else self._P

    def pack(self) -> None:
        """Copy ``u``, ``p`` into :attr:`x`."""
        pack_solution(self.u, self.p, self._x)

    def unpack(self, x: PETSc.Vec, /) -> None:
        """Copy the block vector ``x`` into ``u``, ``p`` (ghosts updated). Collective."""
        unpack_solution(x, self.u, self.p)

    def assemble_residual(self, F: PETSc.Vec, F_forms: list, J_forms: list, homogeneous: list, /) -> None:
        """The nonlinear residual ``F(u, p)`` of the current ``u``, ``p`` into ``F``: the residual
        forms, zero on the rows of the strong conditions (``homogeneous``: the same conditions with
        value 0; ``u`` satisfies them), orthogonal to the constant pressure, or, with a pinned pressure, with the
        continuity rows made consistent as the right-hand side is. Collective."""
        with F.localForm() as f_local:
            f_local.set(0.0)
        assemble_block_vector(F, F_forms, J_forms, bcs=homogeneous)
        if self._null_space is not None:
            self._null_space.remove(F)
        elif self.pinned:
            consistent_continuity(F, self.V, self.Q, self._bcs[-1])

    def assemble_jacobian(self, J_forms: list, a_pc: list | None, /) -> None:
        """Newton's Jacobian into the operator matrix (unit diagonal on the strong conditions'
        rows and columns) and, for an iterative solver, the Picard preconditioning matrix ``a_pc``
        at the current iterate into ``P``. Collective."""
        self._A.zeroEntries()
        assemble_block_matrix(self._A, J_forms, bcs=self._bcs)
        self._A.assemble()
        if self._null_space is not None:
            self._A.setNullSpace(self._null_space)
        if a_pc is not None:
            self._assemble_preconditioning(a_pc)

    def _assemble_preconditioning(self, a_pc: list) -> None:
        matrix = self._S if self._S is not None else self._P  # P is the operator: only -M_p / eta
        if matrix is not None:
            matrix.zeroEntries()
            if matrix is self._S:
                dolfinx.fem.petsc.assemble_matrix(matrix, a_pc[1][1], bcs=[])
            else:
                assemble_block_matrix(matrix, a_pc, bcs=self._bcs)
            matrix.assemble()
            self._preconditioner_changed = True

    # ------------------------------------------------------------------ solve
    def prepare_preconditioner(self) -> None:
        """Before a solve with the current ``P`` (linear, or a Newton step's): give the geometric
        multigrid its prolongations, on the velocity block fieldsplit holds now (extracted at the
        outer PC's set-up, a no-op when ``P`` did not change; a Newton step's may make it anew), and
        tell it whether ``P`` changed (:meth:`VelocityMultigrid.attach`). Collective; nothing without
        a multigrid. The PCMG sets itself up here."""
        if self.multigrid is None:
            return
        pc = self.ksp.getPC()
        pc.setUp()
        self.multigrid.attach(pc.getFieldSplitSubKSP()[0], changed=self._preconditioner_changed)
        self._preconditioner_changed = False

    def solve(self, *, reuse_preconditioner: bool = False) -> float:
        """Solve ``K x = b`` from ``x = (u, p)`` and write ``x`` back to ``u``, ``p``. Collective.

        ``reuse_preconditioner``: keep the last set-up although ``P`` changed
        (:mod:`convection.solvers.stokes.lagged`). Returns the seconds of the preconditioner's set-up.

        Raises:
            RuntimeError: the KSP diverged.
        """
        t1 = time.perf_counter()
        pack_solution(self.u, self.p, self._x)
        self.set_up_preconditioner(reuse=reuse_preconditioner)
        setup_seconds = time.perf_counter() - t1
        self.ksp.solve(self._b, self._x)
        reason = self.ksp.getConvergedReason()
        if reason < 0:
            raise RuntimeError(f"Stokes solver did not converge (PETSc reason {reason})")
        unpack_solution(self._x, self.u, self.p)
        return setup_seconds

    def set_up_preconditioner(self, *, reuse: bool = False) -> None:
        """Set the preconditioner up for the current ``P`` (a no-op unless ``P`` changed), or keep
        the last one (``reuse``: the solves use it until a call without). Collective."""
        pc = self.ksp.getPC()
        pc.setReusePreconditioner(reuse)
        if self.multigrid is not None and self._A.getType() == "nest":  # the velocity block is K's own
            self.multigrid.keep(pc, reuse)
        if not reuse:
            self.prepare_preconditioner()
            self.ksp.setUp()

    def residual_norm(self) -> float:
        """:func:`true_residual_norm` of the last solve. Collective."""
        return true_residual_norm(self._A, self._x, self._b)

    def destroy(self) -> None:
        """Free the matrices, vectors and null spaces now (collective; not the KSP, which the caller owns)."""
        destroy_petsc_objects(self, self.PETSC_OBJECTS)
