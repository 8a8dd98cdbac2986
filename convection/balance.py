"""Weighted partitioning of a mesh for load balancing (seed paper: cell weight 1 + W n_particles).

:func:`weighted_partitioner` gives ``dolfinx.mesh.create_mesh`` a cell partitioner that cuts the
cells, in the order they are passed, into ``nparts`` contiguous blocks of (nearly) equal total
weight — a space-filling-curve partition when the cells are passed sorted along a curve
(:func:`morton_order`). Cells that share a facet with another block are ghosted there, as
``GhostMode.shared_facet`` requires. The cut needs every cell's weight: pass all cells from one
rank (the others pass none), which suits coarse base meshes that are refined afterwards.
"""

from __future__ import annotations

from typing import Any, Callable

import numpy as np
import numpy.typing as npt

import dolfinx.cpp.graph
import dolfinx.cpp.mesh

__all__ = ["block_owners", "morton_order", "weighted_partitioner"]


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
