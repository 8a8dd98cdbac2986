"""Prolongation between Lagrange spaces on nested meshes, for geometric multigrid.

A fine mesh made by refining a coarse one (:func:`fembase.dolfinx_compat.refine_keeping_partition`:
every fine cell inside a coarse cell of the same rank) makes the coarse Lagrange space a subspace
of the fine one of the same degree. The prolongation ``P`` maps coarse coefficients to the fine
coefficients of the same function: a Lagrange degree of freedom is the value at its node, so

    P[i, j] = phi_j(x_i),

the coarse basis function ``j`` at the node ``x_i`` of fine dof ``i`` (block-diagonal over the
components of a vector space). Each rank builds the rows of its owned fine dofs: it finds their
nodes in its coarse cells (owned or ghost; the refinement keeps a fine cell on its parent's rank),
tabulates the coarse element there with basix and keeps the entries above 1e-14 (a node of the
refined mesh sits at a vertex, an edge midpoint or a face point of its coarse cell, where most
basis functions vanish). ``P^T`` is the restriction; ``P^T A P`` the Galerkin coarse operator.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from petsc4py import PETSc

import dolfinx.fem

from fembase.dolfinx_compat import cell_dofmap
from fembase.geometry import locate
from fembase.location import Located

__all__ = ["apply", "owned_nodes", "prolongation"]

_DROP = 1e-14
"""Basis values smaller than this are left out of ``P`` (exact zeros up to rounding)."""


def owned_nodes(V: dolfinx.fem.FunctionSpace) -> npt.NDArray[np.float64]:
    """The nodes of ``V``'s owned dofs (blocks), shape=(n_owned, gdim)."""
    gdim = V.mesh.geometry.dim
    n = V.dofmap.index_map.size_local
    return np.ascontiguousarray(V.tabulate_dof_coordinates()[:n, :gdim])


def prolongation(coarse: dolfinx.fem.FunctionSpace, fine: dolfinx.fem.FunctionSpace, /, *,
                 located: Located | None = None) -> PETSc.Mat:
    """The prolongation matrix from ``coarse`` to ``fine`` (module docstring; collective).

    Args:
        coarse: A Lagrange space (scalar or blocked vector) on the coarse mesh.
        fine: The same element on a mesh refined from it, each fine cell on its coarse parent's rank.
        located: The coarse cell and reference point of each owned fine node
            (:func:`owned_nodes`), found by the caller, e.g. through the straight cells behind
            curved meshes (:class:`convection.adapt.levels.MeshLevels`); None: the nodes are
            looked for in ``coarse``'s cells.

    Returns:
        An assembled AIJ matrix of global shape (dim fine, dim coarse), rows and columns in the
        spaces' global dof numbering (blocked: ``dof * bs + component``).

    Raises:
        ValueError: The elements differ, or a fine node lies in no coarse cell of its rank (the
            meshes are not nested on this partition); raised on every rank.
    """
    if coarse.ufl_element() != fine.ufl_element():
        raise ValueError(f"prolongation between different elements: {coarse.ufl_element()} and {fine.ufl_element()}")
    comm = fine.mesh.comm
    bs = fine.dofmap.index_map_bs
    if located is None:
        located = locate(coarse.mesh, owned_nodes(fine))
    missing = int(np.count_nonzero(located.cells < 0))
    if comm.allreduce(missing) > 0:
        raise ValueError(f"{comm.allreduce(missing)} fine nodes lie in no coarse cell of their rank: the meshes "
                         "are not nested on this partition")
    element = coarse.element.basix_element
    values = element.tabulate(0, located.xref)[0, :, :, 0]  # (n_owned, dofs per cell)
    local = cell_dofmap(coarse)[located.cells]  # (n_owned, dofs per cell), local block indices
    coarse_map = coarse.dofmap.index_map
    columns = coarse_map.local_to_global(local.ravel().astype(np.int32)).reshape(local.shape)
    fine_map = fine.dofmap.index_map
    n_fine, n_coarse = fine_map.size_local, coarse_map.size_local
    keep = np.abs(values) > _DROP
    # CSR of the owned rows: block row i, component k -> row i*bs + k, columns coarse*bs + k
    shape = (n_fine, bs, values.shape[1])
    mask = np.broadcast_to(keep[:, None, :], shape)
    indices = (columns[:, None, :] * bs + np.arange(bs)[None, :, None])[mask].astype(PETSc.IntType)
    data = np.broadcast_to(values[:, None, :], shape)[mask]
    indptr = np.zeros(n_fine * bs + 1, dtype=PETSc.IntType)
    np.cumsum(mask.sum(axis=2).ravel(), out=indptr[1:])
    P = PETSc.Mat().createAIJ(((n_fine * bs, fine_map.size_global * bs), (n_coarse * bs, coarse_map.size_global * bs)),
                              csr=(indptr, indices, data), comm=comm)
    P.assemble()
    return P


def apply(P: PETSc.Mat, coarse: npt.ArrayLike, /) -> npt.NDArray[np.float64]:
    """``P`` times a coarse coefficient vector: this rank's owned coarse values in, its owned fine
    values out (blocked: ``dof * bs + component``). Collective. The PETSc vectors are destroyed at
    once, on every rank together: left to the garbage collector, which runs at different times on
    different ranks, a parallel vector's destruction can deadlock a later collective call."""
    x, y = P.createVecRight(), P.createVecLeft()
    try:
        x.array[:] = np.asarray(coarse, dtype=np.float64)[: x.getLocalSize()]
        P.mult(x, y)
        return y.array.copy()
    finally:
        x.destroy()
        y.destroy()
