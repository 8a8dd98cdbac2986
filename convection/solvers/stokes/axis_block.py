"""The Stokes operator with the semi-implicit buoyancy's term (:class:`SemiImplicitOperator`), and a
velocity-velocity term that couples one velocity component only, added to the Stokes matrix
through its scalar form (:class:`AxisBlock`).

The semi-implicit buoyancy (:class:`convection.physics.buoyancy.SemiImplicitBuoyancy`) adds
``c (u . e_up)(v . e_up)`` to the velocity block every solve. On a box ``e_up = e_k`` (the last
axis), so the term lives in the ``(k, k)`` component block only: of the ``(d n)^2`` entries of a
cell's vector element matrix (n scalar P2 basis functions, 900 in 3D) ``n^2`` (100) are nonzero.
The matrix insertion dominates the assembly (measured at 16^3 on one rank: 0.35 s through the
vector form, 0.033 s for the scalar form ``c u_k v_k`` on the component's own space), so the term
is assembled as that scalar form into a matrix ``M`` of the component space and copied into the
Stokes matrix.

The result is the same as adding the vector form into ``A = A0`` (a copy of the fixed operator),
cell after cell: ``M`` starts from ``A0``'s ``(k, k)`` entries, receives each cell's contributions
in the same order and the other ranks' contributions at its assembly (as ``A`` would), and its
entries then replace ``A``'s. On one rank that is the same to the last bit; on several, PETSc sums
the contributions a rank sends to another's rows before sending them, in an order that depends on
everything it sends (the vector form also sends the other components' zeros), so a few entries
differ in the last place (measured: 1-2 of 17 000 per rank at 4^3, relative 1.5e-16). Rows and columns of strong
velocity conditions keep ``A0``'s values (the conditions on component ``k`` are skipped in ``M``'s
assembly; the element matrices of the scalar and the vector form agree entry by entry, checked in
tests/convection/solvers/test_axis_block.py). ``A``'s other entries are never touched: they are
``A0``'s.
"""

from __future__ import annotations

from typing import Any

import dolfinx
import dolfinx.fem.petsc
import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

import dolfinx.cpp as _cpp

from fembase.dolfinx_compat import assemble_block_matrix, assemble_matrix_into

__all__ = ["AxisBlock", "SemiImplicitOperator"]


class AxisBlock:
    """The ``(k, k)`` component block of the Stokes matrix, assembled from a scalar form.

    Args:
        A: The Stokes matrix (monolithic, from :func:`fembase.dolfinx_compat.create_block_matrix`),
            assembled at least once (its nonzero pattern fixed).
        V: The velocity space (vector Lagrange, block size ``d``).
        velocity_rows: ``A``'s local indices of ``V``'s local dofs, unrolled (``d`` per node, owned
            then ghosts), shape=(d (owned + ghosts),).
        axis: The component ``k``.
        W: ``V.sub(k).collapse()``'s space; ``W_to_V``: its map, shape=(owned + ghosts,), into
            ``V``'s unrolled local dofs.
        form: A scalar bilinear cell form on ``W`` (compiled; it gives the pattern of ``M``).
        bcs: The strong velocity conditions (on ``V`` or its components; their rows and columns
            are skipped). Collective.
    """

    def __init__(self, A: PETSc.Mat, V: dolfinx.fem.FunctionSpace, velocity_rows: np.ndarray, axis: int,
                 W: dolfinx.fem.FunctionSpace, W_to_V: np.ndarray, form: Any, bcs: list[Any], /) -> None:
        self.axis = axis
        self.W = W
        self.M = dolfinx.fem.petsc.create_matrix(form)
        # The pattern: PETSc drops preallocated entries that nothing was set in at assembly.
        assemble_matrix_into(self.M, form, [])
        self.M.assemble()
        self._bcs = _component_conditions(V, bcs, axis, W, W_to_V)
        # W's local dofs (owned, ghosts) -> A's global rows
        a_local = np.asarray(velocity_rows, dtype=np.int32)[np.asarray(W_to_V, dtype=np.int64)]
        a_global = A.getLGMap()[0].apply(a_local.astype(PETSc.IntType))  # (rows, columns): the same map
        imap = W.dofmap.index_map
        # M's owned rows (its CSR, global W columns) in A's global numbering. M's rows are W's owned
        # dofs in order; its columns may be dofs this rank does not hold (couplings from another
        # rank's cells): each owner tells their A index.
        indptr, columns, _ = self.M.getValuesCSR()
        self._indptr = indptr.astype(PETSc.IntType)
        self._columns = columns.astype(PETSc.IntType)
        owned_a = a_global[: imap.size_local].astype(np.int64)
        self._rows_a = owned_a.astype(PETSc.IntType)
        self._columns_a = _owned_values(V.mesh.comm, owned_a, imap.local_range[0],
                                        np.asarray(columns, dtype=np.int64)).astype(PETSc.IntType)
        self._a0_values: np.ndarray | None = None

    def take_fixed(self, A0: PETSc.Mat, /) -> None:
        """Read the fixed operator's ``(k, k)`` entries (after every change of ``A0``). ``A0`` has
        ``A``'s layout and pattern. Collective.

        The block is taken out of ``A0`` as a matrix of its own (its rows and columns those of
        ``W``), so that only its entries pass through numpy: the whole operator's arrays (a
        value, a column and two 8-byte keys an entry) were a transient of 160 MB per rank at
        16^3 on 2 ranks, the run's largest (issue 50)."""
        rows = PETSc.IS().createGeneral(self._rows_a, comm=A0.getComm())
        block = A0.createSubMatrix(rows, rows)  # row i, column j: W's global dofs i, j
        rows.destroy()
        indptr, columns, values = block.getValuesCSR()
        block.destroy()
        counts = np.diff(indptr)
        width = np.int64(self.W.dofmap.index_map.size_global)
        keys = np.repeat(np.arange(len(counts), dtype=np.int64), counts) * width + columns  # increasing
        wanted = np.repeat(np.arange(len(self._indptr) - 1, dtype=np.int64), np.diff(self._indptr)) * width
        wanted += self._columns
        at = np.searchsorted(keys, wanted)
        if np.any(at >= len(keys)) or np.any(keys[np.minimum(at, len(keys) - 1)] != wanted):
            raise RuntimeError("the component block's pattern is not within the Stokes matrix's")
        self._a0_values = values[at]

    def add(self, A: PETSc.Mat, form: Any, /, *also: PETSc.Mat) -> None:
        """``A``'s ``(k, k)`` entries := ``A0``'s plus the scalar ``form`` on ``W``
        (:meth:`take_fixed` first); finalises ``A``. The matrices ``also`` (the same rows and
        columns, the same ``(k, k)`` block in their pattern and ``A0``'s values in it, e.g. the
        preconditioning matrix) get the same entries. Collective."""
        if self._a0_values is None:
            raise RuntimeError("AxisBlock.add before take_fixed")
        M = self.M
        M.setValuesCSR(self._indptr, self._columns, self._a0_values)  # INSERT into the owned rows
        M.assemble(PETSc.Mat.AssemblyType.FLUSH)  # PETSc needs one between inserting and adding
        assemble_matrix_into(M, form, self._bcs)
        M.assemble()
        _, _, values = M.getValuesCSR()
        for target in (A, *also):
            target.setValuesIJV(self._indptr, self._columns_a, values, addv=PETSc.InsertMode.INSERT_VALUES,
                                rowmap=self._rows_a)
            target.assemble()

    def destroy(self) -> None:
        self.M.destroy()


class SemiImplicitOperator:
    """The Stokes operator with the semi-implicit buoyancy's term, ``A = A0 + term``
    (:class:`convection.physics.buoyancy.SemiImplicitBuoyancy`), kept up to date each solve.

    Args:
        A: The operator to hold ``A0 + term`` (:func:`fembase.dolfinx_compat.create_block_matrix`).
        A0: The fixed operator (assembled by the caller whenever its forms or viscosity change);
            None on a box: the caller assembles it into ``A`` itself, whose entries outside the
            vertical component's block are never changed, and the block keeps its fixed values.
        V, Q: The velocity and pressure spaces.
        velocity_bcs: The strong velocity conditions (skipped rows and columns of the term).
        bcs: All strong conditions of ``A`` (for its first assembly: its nonzero pattern).

    On a box the term has the vertical component only and goes through its scalar form
    (:class:`AxisBlock`); otherwise its vector form is added to a copy of ``A0``, cell by cell.
    """

    def __init__(self, A: PETSc.Mat, A0: PETSc.Mat | None, V: dolfinx.fem.FunctionSpace, Q: dolfinx.fem.FunctionSpace,
                 velocity_bcs: list[Any], bcs: list[Any], /) -> None:
        self.A, self.A0, self.V, self.Q = A, A0, V, Q
        self._velocity_bcs, self._bcs = list(velocity_bcs), list(bcs)
        self._rows: PETSc.IS | None = None
        self.block: AxisBlock | None = None
        self._fixed_taken = False  # whether the block holds A0's current entries

    def update(self, forms: Any, /, *, refresh: bool, preconditioner: PETSc.Mat | None = None) -> bool:
        """``A := A0 + forms.a_si`` (``refresh``: ``A0`` changed since the last call); finalises
        ``A``. Collective.

        Args:
            preconditioner: A preconditioning matrix whose velocity block is ``A0``'s (assembled
                when ``A0`` was): on a box its ``(k, k)`` entries get the term too.

        Returns:
            Whether ``preconditioner`` got the term (on a box; the vector form is not added to it).
        """
        A, A0 = self.A, self.A0
        if not A.isAssembled():  # once: A gets A0's nonzero pattern
            assemble_block_matrix(A, forms.a, bcs=self._bcs)
            A.assemble()
        if forms.a_si_component is not None:
            # One velocity component (a box): the scalar form's block replaces A's (k, k) entries;
            # A's other entries stay A0's (copied when A0 changed).
            block = self._component_block(forms.a_si_component)
            if refresh or not self._fixed_taken:
                if A0 is not None:
                    A0.copy(A, structure=PETSc.Mat.Structure.SAME_NONZERO_PATTERN)
                elif not refresh:  # A's block holds the last term, not the fixed values
                    raise RuntimeError("the semi-implicit term's block changed without the operator's refresh")
                block.take_fixed(self._velocity_block())
                self._fixed_taken = True
            others = () if preconditioner is None else (preconditioner,)
            block.add(self._velocity_block(), forms.a_si_component[3], *others)
            if A.getType() == "nest":
                A.assemble()  # its state follows its block's change: the preconditioner is set up again
            return preconditioner is not None
        assert A0 is not None, "the vector form adds to A0's copy"
        A0.copy(A, structure=PETSc.Mat.Structure.SAME_NONZERO_PATTERN)
        # Into A's (0, 0) block, skipping the Dirichlet rows and columns (their unit diagonal is in A).
        rows = self._velocity_rows()
        sub = A.getLocalSubMatrix(rows, rows)
        assemble_matrix_into(sub, forms.a_si, self._bcs)
        A.restoreLocalSubMatrix(rows, rows, sub)
        A.assemble()
        return False

    def _velocity_rows(self) -> PETSc.IS:
        """The velocity dofs' rows in A's local (unrolled) numbering, owned then ghosts."""
        if self._rows is None:
            spaces = [(self.V.dofmap.index_map, self.V.dofmap.index_map_bs), (self.Q.dofmap.index_map, 1)]
            self._rows = _cpp.la.petsc.create_index_sets(spaces)[0]
        return self._rows

    def _velocity_block(self) -> PETSc.Mat:
        """The matrix that holds ``A``'s velocity block: ``A``, or its ``(0, 0)`` block where ``A``
        is a MATNEST (:func:`fembase.dolfinx_compat.create_nest_matrix`)."""
        return self.A.getNestSubMatrix(0, 0) if self.A.getType() == "nest" else self.A

    def _component_block(self, component: tuple[int, Any, np.ndarray, Any]) -> AxisBlock:
        axis, W, W_to_V, form = component
        block = self.block
        if block is None or block.axis != axis or block.W is not W:
            if block is not None:
                block.destroy()
            if self.A.getType() == "nest":  # the block's local rows are V's unrolled local dofs
                index_map = self.V.dofmap.index_map
                rows = np.arange(self.V.dofmap.index_map_bs * (index_map.size_local + index_map.num_ghosts),
                                 dtype=np.int32)
            else:
                rows = self._velocity_rows().getIndices()
            block = AxisBlock(self._velocity_block(), self.V, rows, axis, W, W_to_V, form, self._velocity_bcs)
            self.block = block
            self._fixed_taken = False
        return block

    def destroy(self) -> None:
        """Free the component block and the index set (collective)."""
        for obj in (self.block, self._rows):
            if obj is not None:
                obj.destroy()
        self.block, self._rows = None, None


def _component_conditions(V: dolfinx.fem.FunctionSpace, bcs: list[Any], axis: int,
                          W: dolfinx.fem.FunctionSpace, W_to_V: np.ndarray) -> list[Any]:
    """The strong conditions on component ``axis`` of ``V``, as zero conditions on ``W``'s dofs (the
    rows and columns the assembly skips)."""
    bs = V.dofmap.index_map_bs
    V_to_W = np.full(bs * (V.dofmap.index_map.size_local + V.dofmap.index_map.num_ghosts), -1, dtype=np.int64)
    V_to_W[np.asarray(W_to_V, dtype=np.int64)] = np.arange(len(W_to_V))
    dofs = []
    for bc in bcs:
        indices, _ = bc.dof_indices()  # unrolled local dofs of V (also for a condition on V.sub(i))
        w = V_to_W[np.asarray(indices, dtype=np.int64)]
        dofs.append(w[w >= 0])
    if not dofs:
        return []
    w_dofs = np.unique(np.concatenate(dofs)).astype(np.int32)
    return [dolfinx.fem.dirichletbc(PETSc.ScalarType(0.0), w_dofs, W)]


def _owned_values(comm: MPI.Comm, owned: np.ndarray, start: int, wanted: np.ndarray) -> np.ndarray:
    """``values[g]`` for global indices ``wanted`` (shape=(m,)), where every rank holds the values of
    its contiguous owned range ``[start, start + len(owned))`` in ``owned``. Collective."""
    starts = np.asarray(comm.allgather(int(start)), dtype=np.int64)
    owner = np.searchsorted(starts, wanted, side="right") - 1
    order = np.argsort(owner, kind="stable")
    counts = np.bincount(owner, minlength=comm.size).astype(np.int64)
    asked = np.asarray(wanted[order], dtype=np.int64)
    received_counts = np.empty(comm.size, dtype=np.int64)
    comm.Alltoall(counts, received_counts)
    requests = np.empty(int(received_counts.sum()), dtype=np.int64)
    comm.Alltoallv([asked, counts], [requests, received_counts])
    answers = owned[requests - start]
    replies = np.empty(len(wanted), dtype=np.int64)
    comm.Alltoallv([answers, received_counts], [replies, counts])
    out = np.empty(len(wanted), dtype=np.int64)
    out[order] = replies
    return out
