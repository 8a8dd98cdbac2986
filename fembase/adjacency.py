"""Which local cells of a mesh touch which: the vertex-to-cell adjacency, the cells sharing a vertex
with each cell and the cell across each facet.

The particles' transport step orders its neighbour search by these (seed paper 2.4) and takes its
first guess across a facet; :class:`fembase.geometry.CellGeometry` holds one
:class:`CellAdjacency` per mesh.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

__all__ = ["CellAdjacency", "unique_pairs"]


class CellAdjacency:
    """The adjacency of the local cells (owned + ghost) of a mesh through their vertices.

    Args:
        vertices: Geometry node of each vertex of each cell, shape=(num_local_cells, num_vertices), int32.
        num_nodes: Number of geometry nodes (the vertex-to-cell adjacency has a row for each).

    Attributes:
        v2c_offsets, v2c_cells: CSR vertex-to-cell adjacency over geometry nodes (int64 / int32).
        max_valence: Largest number of cells sharing a vertex (0 without cells).
    """

    def __init__(self, vertices: npt.NDArray[np.int32], num_nodes: int, /) -> None:
        self.vertices = vertices
        self.num_cells, self.num_vertices = vertices.shape
        vnodes = vertices.reshape(-1)
        owner = np.repeat(np.arange(self.num_cells, dtype=np.int32), self.num_vertices)
        order = np.argsort(vnodes, kind="stable")
        self.v2c_cells = np.ascontiguousarray(owner[order])
        counts = np.bincount(vnodes, minlength=num_nodes)
        self.v2c_offsets = np.zeros(num_nodes + 1, dtype=np.int64)
        np.cumsum(counts, out=self.v2c_offsets[1:])
        self.max_valence = int(counts.max()) if counts.size else 0
        self._c2c: tuple[npt.NDArray[np.int64], npt.NDArray[np.int32]] | None = None
        self._facet_nbrs: npt.NDArray[np.int32] | None = None

    @property
    def vertex_neighbours(self) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int32]]:
        """CSR ``(offsets, cells)`` of the cells sharing a vertex with each cell (itself excluded)."""
        if self._c2c is None:
            nv, nc = self.num_vertices, self.num_cells
            vnodes = self.vertices.reshape(-1)
            starts = self.v2c_offsets[vnodes]
            lengths = self.v2c_offsets[vnodes + 1] - starts
            seg = np.cumsum(lengths) - lengths
            idx = np.repeat(starts - seg, lengths) + np.arange(int(lengths.sum()))
            owner = np.repeat(np.repeat(np.arange(nc, dtype=np.int64), nv), lengths)
            pairs = unique_pairs(np.stack([owner, self.v2c_cells[idx].astype(np.int64)], axis=1))
            pairs = pairs[pairs[:, 0] != pairs[:, 1]]
            offsets = np.zeros(nc + 1, dtype=np.int64)
            np.cumsum(np.bincount(pairs[:, 0], minlength=nc), out=offsets[1:])
            self._c2c = (offsets, pairs[:, 1].astype(np.int32))
        return self._c2c

    @property
    def facet_neighbours(self) -> npt.NDArray[np.int32]:
        """Local cell across the facet opposite each vertex of each cell (the facet that vertex's
        barycentric coordinate measures), shape=(num_local_cells, num_vertices), int32; -1 on the
        boundary of this rank's owned + ghost cells. Built on first use (simplices)."""
        if self._facet_nbrs is None:
            nv, nc = self.num_vertices, self.num_cells
            verts = self.vertices.astype(np.int64)
            faces = np.concatenate([np.sort(np.delete(verts, i, axis=1), axis=1) for i in range(nv)])
            cell = np.tile(np.arange(nc, dtype=np.int64), nv)
            local = np.repeat(np.arange(nv, dtype=np.int64), nc)
            order = np.lexsort(faces.T[::-1])
            f = faces[order]
            same = np.flatnonzero(np.all(f[1:] == f[:-1], axis=1))
            a, b = order[same], order[same + 1]
            nbrs = np.full((nc, nv), -1, dtype=np.int32)
            nbrs[cell[a], local[a]] = cell[b]
            nbrs[cell[b], local[b]] = cell[a]
            self._facet_nbrs = nbrs
        return self._facet_nbrs


def unique_pairs(pairs: npt.NDArray[np.int64]) -> npt.NDArray[np.int64]:
    """The distinct rows of an integer table ``pairs`` (shape=(n, 2)), sorted lexicographically:
    ``np.unique(pairs, axis=0)`` by one packed int64 key per row (several times faster)."""
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    if pairs.shape[0] == 0:
        return pairs.copy()
    low = pairs.min(axis=0)
    span = pairs.max(axis=0) - low + 1
    if float(span[0]) * float(span[1]) >= 2.0**62:
        return np.unique(pairs, axis=0)
    keys = np.unique((pairs[:, 0] - low[0]) * span[1] + (pairs[:, 1] - low[1]))
    return np.stack([keys // span[1] + low[0], keys % span[1] + low[1]], axis=1)
