"""Weighted partitioning of a mesh for load balancing (seed paper: cell weight 1 + W n_particles).

:func:`weighted_partitioner` gives ``dolfinx.mesh.create_mesh`` a cell partitioner that cuts the
cells, in the order they are passed, into ``nparts`` contiguous blocks of (nearly) equal total
weight — a space-filling-curve partition when the cells are passed sorted along a curve
(:func:`morton_order`). Cells that share a facet with another block are ghosted there, as
``GhostMode.shared_facet`` requires. The cut needs every cell's weight: pass all cells from one
rank (the others pass none), which suits coarse base meshes that are refined afterwards.

:class:`CellLayout` is such a base mesh gathered on rank 0 in a rank-independent order (the
*canonical* cell index), and :func:`create_weighted_mesh` distributes it again with given weights;
:class:`convection.adaptivity.MeshHierarchy` uses both to repartition its base mesh (load balancing
with cell weights 1 + W n_particles summed over each base cell's descendants).
"""

from __future__ import annotations

from typing import Any, Callable, NamedTuple

import numpy as np
import numpy.typing as npt

from mpi4py import MPI

import dolfinx.cpp.graph
import dolfinx.cpp.mesh
import dolfinx.mesh
import ufl

__all__ = ["CellLayout", "WeightedMesh", "block_owners", "create_weighted_mesh", "gather_cell_layout", "morton_order",
           "weighted_partitioner"]


def block_owners(weights: npt.NDArray[np.float64], nparts: int, /) -> npt.NDArray[np.int32]:
    """Owner of each item when the sequence is cut into ``nparts`` blocks of equal weight.

    Args:
        weights: Positive weights in curve order, shape=(n,).
        nparts: Number of blocks.

    Returns:
        Block index per item, shape=(n,), int32, non-decreasing.
    """
    w = np.asarray(weights, dtype=np.float64)
    if w.size == 0:
        return np.zeros(0, dtype=np.int32)
    if np.any(w <= 0.0):
        raise ValueError("partition weights must be positive")
    centre = (np.cumsum(w) - 0.5 * w) / w.sum()  # each item goes where its weight's midpoint falls
    return np.minimum((centre * nparts).astype(np.int32), nparts - 1)


def morton_order(points: npt.NDArray[np.float64], /, *, bits: int = 16) -> npt.NDArray[np.int64]:
    """Indices sorting ``points`` (shape=(n, d)) along a Morton (Z-order) curve."""
    p = np.asarray(points, dtype=np.float64)
    if p.shape[0] == 0:
        return np.zeros(0, dtype=np.int64)
    lo, hi = p.min(axis=0), p.max(axis=0)
    q = ((p - lo) / np.where(hi > lo, hi - lo, 1.0) * (2**bits - 1)).astype(np.int64)
    key = np.zeros(p.shape[0], dtype=np.int64)
    for bit in range(bits):
        for axis in range(p.shape[1]):
            key |= ((q[:, axis] >> bit) & 1) << (bit * p.shape[1] + axis)
    return np.argsort(key, kind="stable")


def weighted_partitioner(weights: npt.NDArray[np.float64], /) -> Callable[..., Any]:
    """A cell partitioner for ``dolfinx.mesh.create_mesh(..., partitioner=...)``.

    Args:
        weights: Weight of each cell this rank passes to ``create_mesh``, in the same order,
            shape=(num_cells_passed,) (all cells on one rank, none elsewhere).
    """
    weights = np.asarray(weights, dtype=np.float64)

    def graph_partitioner(comm: Any, nparts: int, graph: Any, ghosting: bool) -> Any:
        n = graph.num_nodes
        if n != weights.shape[0]:
            raise ValueError(f"weighted partitioner: {weights.shape[0]} weights for {n} cells on this rank")
        owner = block_owners(weights, nparts)
        destinations: list[int] = []
        offsets = [0]
        for i in range(n):
            destinations.append(int(owner[i]))
            if ghosting:
                others = {int(owner[j]) for j in graph.links(i) if 0 <= j < n} - {int(owner[i])}
                destinations.extend(sorted(others))
            offsets.append(len(destinations))
        return dolfinx.cpp.graph.AdjacencyList_int32(
            np.asarray(destinations, dtype=np.int32), np.asarray(offsets, dtype=np.int32)
        )

    return dolfinx.cpp.mesh.create_cell_partitioner(graph_partitioner)


class CellLayout(NamedTuple):
    """A simplex mesh held whole on rank 0 (empty arrays elsewhere), cells in canonical order.

    Attributes:
        points: Vertex coordinates, shape=(num_points, gdim) (rank 0).
        cells: Vertex indices of each cell, shape=(num_cells, num_vertices), int64 (rank 0).
        curve_order: Cells sorted along a Morton curve of their midpoints, shape=(num_cells,),
            int64, on every rank.
        num_cells: Global number of cells (every rank).
    """

    points: npt.NDArray[np.float64]
    cells: npt.NDArray[np.int64]
    curve_order: npt.NDArray[np.int64]
    num_cells: int


def gather_cell_layout(mesh: dolfinx.mesh.Mesh, canonical: npt.NDArray[np.int64], /) -> CellLayout:
    """Gather a P1 simplex mesh on rank 0 (collective).

    Args:
        mesh: The distributed mesh.
        canonical: Rank-independent index of each owned cell, shape=(num_owned_cells,), int64,
            a permutation of 0..num_cells-1 over all ranks (e.g. ``topology.original_cell_index``).
    """
    comm = mesh.comm
    tdim, gdim = mesh.topology.dim, mesh.geometry.dim
    num_owned = mesh.topology.index_map(tdim).size_local
    dofs = mesh.geometry.dofmap.array.reshape(-1, tdim + 1)[:num_owned]
    corners = mesh.geometry.x[dofs][:, :, :gdim].reshape(num_owned, -1)
    gathered = comm.gather((np.asarray(canonical[:num_owned], dtype=np.int64), corners), root=0)
    num_cells = int(mesh.topology.index_map(tdim).size_global)
    if comm.rank == 0:
        index = np.concatenate([g[0] for g in gathered])
        coords = np.concatenate([g[1] for g in gathered]).reshape(-1, tdim + 1, gdim)
        if not np.array_equal(np.sort(index), np.arange(num_cells)):
            raise ValueError("canonical cell indices are not a permutation of the global cells")
        coords = coords[np.argsort(index)]
        # Coordinates of a shared vertex are bit-identical on every rank (one source), so exact
        # matching joins the cells again.
        points, inverse = np.unique(coords.reshape(-1, gdim), axis=0, return_inverse=True)
        cells = inverse.reshape(num_cells, tdim + 1).astype(np.int64)
        order = morton_order(coords.mean(axis=1))
    else:
        points, cells, order = np.zeros((0, gdim)), np.zeros((0, tdim + 1), dtype=np.int64), None
    order = comm.bcast(order, root=0)
    return CellLayout(points, cells, np.asarray(order, dtype=np.int64), num_cells)


class WeightedMesh(NamedTuple):
    """A mesh created by :func:`create_weighted_mesh` and the canonical index of its local cells."""

    mesh: dolfinx.mesh.Mesh
    canonical: npt.NDArray[np.int64]  # shape=(num_owned + num_ghost cells,)


def create_weighted_mesh(
    comm: MPI.Comm, layout: CellLayout, weights: npt.NDArray[np.float64] | None, domain: ufl.Mesh, /
) -> WeightedMesh:
    """Distribute ``layout`` in contiguous blocks of equal weight along its Morton curve (collective).

    Args:
        comm: Communicator of the new mesh.
        layout: The gathered mesh (:func:`gather_cell_layout`).
        weights: Weight per canonical cell, shape=(num_cells,) (read on rank 0 only); None = 1 each.
        domain: The coordinate element (``ufl.Mesh``) of the mesh.
    """
    order = layout.curve_order
    if comm.rank == 0:
        w = np.ones(layout.num_cells) if weights is None else np.asarray(weights, dtype=np.float64)
        cells, points, w_curve = layout.cells[order], layout.points, w[order]
    else:
        cells, points = layout.cells, layout.points
        w_curve = np.zeros(0)
    mesh = dolfinx.mesh.create_mesh(comm, cells, points, domain, ghost_mode=dolfinx.mesh.GhostMode.shared_facet,
                                    partitioner=weighted_partitioner(w_curve))
    original = np.asarray(mesh.topology.original_cell_index, dtype=np.int64)
    return WeightedMesh(mesh, order[original])
