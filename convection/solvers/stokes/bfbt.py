"""The weighted BFBt approximation of the Stokes Schur complement (``stokes.schur: wbfbt``).

The block preconditioner of the iterative Stokes solvers
(:func:`convection.solvers.stokes.solver.block_schur_options`) needs an approximate inverse of the Schur
complement ``S = -D A^-1 G`` (PETSc's sign; ``A`` the velocity block, ``G = B^T`` the pressure gradient
``-(p, div v)``, ``D`` the divergence ``-(q, div u)``). The default, ``-M_p / eta`` (``stokes.schur: mass``),
is spectrally equivalent to ``S`` with a constant viscosity but degrades as the viscosity contrast grows:
on nsinker (benchmarks/nsinker, 8^3, an exact velocity solve) the outer iterations triple from a contrast
of 1e2 to 1e6. The weighted BFBt of Rudi, Stadler and Ghattas (2017, SIAM J. Sci. Comput. 39(5),
S272-S297) is the least-squares commutator with a viscosity weight::

    S^-1 ~ -(D W G)^-1 (D W A W G) (D W G)^-1,    W = diag(M_u(sqrt(eta)))^-1

``M_u(sqrt(eta))`` is the velocity mass matrix weighted by ``sqrt(eta)``; its diagonal stands for the
lumped matrix of the paper (the rows of a P2 mass matrix on tetrahedra sum to negative values at the
vertices, so row-sum lumping is not an option). ``L = D W G`` is a Poisson-like matrix on the pressure
space, formed once per viscosity (``MatMatMult``); each application solves with it twice by one cycle
of algebraic multigrid (a KSP under the options prefix ``fieldsplit_p_wbfbt_``, BoomerAMG by default)
and multiplies once with ``K`` (for ``A``) and with ``G``, ``D`` (taken from ``K``). Rows of ``G`` on
the strong velocity conditions are zero in ``K``, so ``L`` sees the interior velocities only; the
boundary-modified weights of the paper are not done.

:class:`WeightedBFBt` is a petsc4py Python preconditioner: the Stokes linear system
(:class:`convection.solvers.stokes.linear.StokesLinearSystem`) owns one, sets it as the Schur
complement's PC (``fieldsplit_p_pc_type python``) and updates it when the operator changes.

Measured on nsinker (4 sinkers, benchmarks/nsinker/README.md): with an exact velocity solve at 4^3,
14 -> 40 iterations from DR 1e2 to 1e6 against 28 -> 161 for ``-M_p / eta``; with the SOR multigrid at
8^3 on one rank 28 -> 49 against 37 -> 138. On two ranks the SOR multigrid's velocity solve (SOR within
each rank) is the limit and w-BFBt does not help it at DR 1e6 (8^3: 639 against 286).
"""

from __future__ import annotations

from typing import Any

import dolfinx
import dolfinx.fem.petsc
import numpy as np
from petsc4py import PETSc

from convection.solvers.petsc_options import SCALAR_AMG
from convection.solvers.stokes.forms import StokesForms
from convection.solvers.stokes.linear import StokesLinearSystem

__all__ = ["SCHUR_APPROXIMATIONS", "WeightedBFBt", "WeightedBFBtSystem", "schur_options"]

SCHUR_APPROXIMATIONS: dict[str, str] = {
    "mass": "-M_p / eta, the viscosity-scaled pressure mass matrix (the default)",
    "wbfbt": "weighted BFBt (Rudi et al. 2017), weights sqrt(eta): far fewer iterations at large viscosity "
             "contrasts where the velocity solve is good (benchmarks/nsinker)",
}
"""The Schur complement approximations of ``stokes.schur``."""

PREFIX = "wbfbt_"
"""The options prefix of the Poisson-like solves, after the Schur complement's PC's (``fieldsplit_p_``)."""


def schur_options(schur: str, user: dict[str, Any] | None = None, /, *, solver: str = "iterative",
                  iterative: bool = True) -> dict[str, Any]:
    """The Stokes solver's PETSc options ``stokes.schur`` sets (but those the ``user``'s options set).

    Raises:
        ValueError: An unknown approximation, or one other than ``mass`` with a direct ``solver``.
    """
    if schur not in SCHUR_APPROXIMATIONS or (schur != "mass" and not iterative):
        raise ValueError(f"Schur complement approximation {schur!r}: one of {list(SCHUR_APPROXIMATIONS)}, and "
                         f"only 'mass' with the {solver} solver")
    if schur == "mass":
        return {}
    options = {"fieldsplit_p_pc_type": "python", f"fieldsplit_p_{PREFIX}ksp_type": "preonly",
               **{f"fieldsplit_p_{PREFIX}{key}": value for key, value in SCALAR_AMG.items()}}
    return {key: value for key, value in options.items() if key not in (user or {})}


class WeightedBFBt:
    """The w-BFBt Schur complement preconditioner (module docstring), a petsc4py Python PC context.

    Args:
        V: The velocity space (vector Lagrange).
        component: ``V.sub(0).collapse()``: the scalar space and its map into ``V``'s unrolled local dofs.
        index_sets: The velocity and pressure rows of the block operator (global numbering, owned).
        constant_pressure: The constant pressure solves the homogeneous problem (``L``'s null space).

    Attributes:
        form: The weights' form of the last :meth:`update` (``a_weights`` of
            :class:`~convection.solvers.stokes.forms.StokesForms`).
    """

    def __init__(self, V: dolfinx.fem.FunctionSpace, component: tuple[dolfinx.fem.FunctionSpace, np.ndarray],
                 index_sets: tuple[PETSc.IS, PETSc.IS], /, *, constant_pressure: bool) -> None:
        self.V, (self.W, self.W_to_V) = V, component
        self.is_u, self.is_p = index_sets
        self.form: Any = None
        comm = V.mesh.comm
        self.null_space = PETSc.NullSpace().create(constant=True, comm=comm) if constant_pressure else None
        self.ksp = PETSc.KSP().create(comm)
        self.K: PETSc.Mat | None = None
        self.G: PETSc.Mat | None = None
        self.D: PETSc.Mat | None = None
        self.L: PETSc.Mat | None = None
        self.weights: PETSc.Vec | None = None  # W = diag(M_u(sqrt(eta)))^-1 on the owned velocity dofs
        self._mass: PETSc.Mat | None = None
        self._WG: PETSc.Mat | None = None  # W G
        self._work: tuple[PETSc.Vec, ...] = ()

    def set_prefix(self, prefix: str, /) -> None:
        """Give the Poisson-like solves the options under ``prefix`` + :data:`PREFIX`."""
        self.ksp.setOptionsPrefix(prefix + PREFIX)
        self.ksp.setFromOptions()

    def update(self, K: PETSc.Mat, /, *, blocks: PETSc.Mat | None = None) -> None:
        """Take the operator ``K`` (``A`` at every application) and the blocks ``G``, ``D`` of ``blocks``
        (default ``K``: where ``K`` gets its values later, the matrix whose blocks it will have); assemble
        :attr:`form` (``sqrt(eta)`` times the scalar mass form on the component space): ``W``, then
        ``L = D W G``. Collective."""
        self.K = K
        blocks = K if blocks is None else blocks
        self._assemble_weights(self.form)
        reuse = self.L is not None
        self.G = blocks.createSubMatrix(self.is_u, self.is_p, submat=self.G)
        self.D = blocks.createSubMatrix(self.is_p, self.is_u, submat=self.D)
        WG = self.G.copy(self._WG, structure=PETSc.Mat.Structure.SAME_NONZERO_PATTERN if reuse else None)
        WG.diagonalScale(L=self.weights)
        self._WG = WG
        self.L = self.D.matMult(WG, result=self.L)
        if self.null_space is not None:
            self.L.setNullSpace(self.null_space)
        self.ksp.setOperators(self.L)
        if not self._work:
            z, _ = K.createVecs()
            self._work = (z, z.duplicate(), self.G.createVecs()[1], self.L.createVecs()[0])

    def attach(self, pc: PETSc.PC, /) -> None:
        """Be the Python PC ``pc`` (the Schur complement's, of type python from the options). Not collective."""
        if pc.getType() != "python":
            raise ValueError(f"the Schur complement's preconditioner is {pc.getType()!r}, not python: "
                             "stokes.petsc_options changed fieldsplit_p_pc_type")
        if pc.getPythonContext() is not self:
            pc.setPythonContext(self)

    def _assemble_weights(self, form: Any) -> None:
        if self._mass is None:
            self._mass = dolfinx.fem.petsc.create_matrix(form)
        self._mass.zeroEntries()
        dolfinx.fem.petsc.assemble_matrix(self._mass, form)
        self._mass.assemble()
        diagonal = dolfinx.fem.Function(self.W)
        n_w = self.W.dofmap.index_map.size_local
        diagonal.x.array[:n_w] = self._mass.getDiagonal().array_r
        diagonal.x.scatter_forward()
        bs = self.V.dofmap.index_map_bs
        spread = np.zeros((self.V.dofmap.index_map.size_local + self.V.dofmap.index_map.num_ghosts) * bs)
        for c in range(bs):
            spread[self.W_to_V + c] = diagonal.x.array
        owned = spread[:self.V.dofmap.index_map.size_local * bs]
        if self.weights is None:
            self.weights = PETSc.Vec().createMPI((owned.size, PETSc.DECIDE), comm=self.V.mesh.comm)
        self.weights.array[:] = 1.0 / owned

    # ------------------------------------------------------------------ the petsc4py PC interface
    def setUp(self, pc: PETSc.PC) -> None:
        """Nothing: :meth:`update` has set everything up for the current operator."""

    def apply(self, pc: PETSc.PC, x: PETSc.Vec, y: PETSc.Vec) -> None:
        """``y = -L^-1 D W A W G L^-1 x``. Collective."""
        z, Kz, u, p = self._work
        K, G, D = self.K, self.G, self.D
        assert K is not None and G is not None and D is not None, "update() first"
        n_u = u.getLocalSize()
        rhs = x.copy()
        if self.null_space is not None:
            self.null_space.remove(rhs)
        self.ksp.solve(rhs, p)
        G.mult(p, u)
        u.pointwiseMult(u, self.weights)
        z.zeroEntries()
        z.array[:n_u] = u.array_r
        K.mult(z, Kz)  # (A W G p, D W G p): the velocity part
        u.array[:] = Kz.array_r[:n_u]
        u.pointwiseMult(u, self.weights)
        D.mult(u, rhs)
        self.ksp.solve(rhs, y)
        y.scale(-1.0)
        if self.null_space is not None:
            self.null_space.remove(y)
        rhs.destroy()

    def destroy(self, pc: PETSc.PC | None = None) -> None:
        """Free the matrices, vectors and the inner KSP now (collective); nothing when the PC it serves
        goes (``pc``: petsc4py's call), as the Stokes linear system frees it."""
        if pc is not None:
            return
        for obj in (self.ksp, self.G, self.D, self._WG, self.L, self.weights, self._mass, self.null_space, *self._work):
            if obj is not None:
                obj.destroy()
        self.G = self.D = self._WG = self.L = self.weights = self._mass = self.null_space = None
        self._work = ()


class WeightedBFBtSystem(StokesLinearSystem):
    """:class:`~convection.solvers.stokes.linear.StokesLinearSystem` with the w-BFBt Schur complement PC
    (an iterative solver; ``stokes.schur: wbfbt``): made at :meth:`setup`, updated with the preconditioning
    matrix (the weights of the forms of the last :meth:`assemble_operator`; a Newton step's ``P`` takes
    them from there too: their viscosity is the iterate's) and set as the Schur complement's Python PC
    before every set-up.

    Args:
        component: The velocity's component space (:meth:`StokesDiscretisation.component_space`).
        Others: as :class:`~convection.solvers.stokes.linear.StokesLinearSystem`'s.
    """

    def __init__(self, *args: Any, component: tuple[dolfinx.fem.FunctionSpace, np.ndarray], **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        if not self.iterative:
            raise ValueError("the weighted BFBt needs an iterative solver")
        self._component = component
        self.bfbt: WeightedBFBt | None = None

    def setup(self, forms: StokesForms, /) -> None:
        super().setup(forms)
        self.bfbt = WeightedBFBt(self.V, self._component, self.index_sets(), constant_pressure=self.pressure_null_space)
        self.bfbt.set_prefix(self.ksp.getOptionsPrefix() + "fieldsplit_p_")

    def assemble_operator(self, forms: StokesForms, /, *, refresh: bool) -> None:
        if self.bfbt is not None:
            self.bfbt.form = forms.a_weights
        super().assemble_operator(forms, refresh=refresh)

    def _assemble_preconditioning(self, a_pc: list) -> None:
        super()._assemble_preconditioning(a_pc)
        if self.bfbt is not None:
            self.bfbt.update(self._A, blocks=self._A if self._A0 is None else self._A0)

    def prepare_preconditioner(self) -> None:
        super().prepare_preconditioner()  # the outer PC set up (with a multigrid), or not
        pc = self.ksp.getPC()
        pc.setUp()
        if self.bfbt is not None:
            self.bfbt.attach(pc.getFieldSplitSubKSP()[1].getPC())

    def destroy(self) -> None:
        if self.bfbt is not None:
            self.bfbt.destroy()
            self.bfbt = None
        super().destroy()
