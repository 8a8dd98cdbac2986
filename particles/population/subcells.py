"""Equal-volume sub-cells of a reference cell, for the density-based population control and the
distribution score.

A reference cell is split into ``B = g**tdim`` sub-cells of equal volume (``g``: the granularity):

- **Hypercubes** (interval, quadrilateral, hexahedron): the ``g**tdim`` grid cells of width ``1/g``.
- **Simplices** (triangle, tetrahedron): the map ``s_i = x_i + x_{i+1} + ... + x_tdim`` (volume
  preserving, ``det = 1``) takes the reference simplex ``{x >= 0, sum x <= 1}`` onto the Kuhn
  simplex ``{1 >= s_1 >= s_2 >= ... >= s_tdim >= 0}``. The Freudenthal (Kuhn) triangulation of
  the grid of width ``1/g`` fills it with exactly ``g**tdim`` congruent simplices: the sub-cell
  of a point is the grid cell ``k = floor(g s)`` together with the order ``pi`` of its fractional
  parts ``f = g s - k`` (``f_pi1 >= f_pi2 >= ...``); that sub-cell has the vertices
  ``(k, k + e_pi1, k + e_pi1 + e_pi2, ...) / g``. For a triangle and ``g = 2`` these are the four
  triangles of a uniform refinement.

All arithmetic is elementwise, so equal inputs give equal bits on every partition.
"""

from __future__ import annotations

import itertools
import math

import basix
import numpy as np
import numpy.typing as npt

__all__ = ["SubCells"]

_SIMPLEX = (basix.CellType.interval, basix.CellType.triangle, basix.CellType.tetrahedron)
_HYPERCUBE = (basix.CellType.quadrilateral, basix.CellType.hexahedron)


def _to_kuhn(xhat: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """``s_i = sum_{j >= i} x_j``: reference simplex -> Kuhn simplex, shape=(p, d) -> (p, d)."""
    return np.cumsum(xhat[:, ::-1], axis=1)[:, ::-1]


def _from_kuhn(s: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """Inverse of :func:`_to_kuhn`: ``x_i = s_i - s_{i+1}``, ``x_d = s_d``; shape=(p, d)."""
    x = s.copy()
    x[:, :-1] -= s[:, 1:]
    return x


class SubCells:
    """The ``g**tdim`` equal-volume sub-cells of a reference cell.

    Args:
        cell: The reference cell type (interval, triangle, tetrahedron, quadrilateral or hexahedron).
        granularity: ``g >= 1``, sub-cells per direction.

    Attributes:
        tdim: Topological dimension.
        granularity: ``g``.
        num: Number of sub-cells, ``g**tdim``.
        simplex: Whether the cell is a simplex (Kuhn sub-simplices) rather than a hypercube (grid).
        corners: The grid cell ``k`` of every sub-cell, shape=(num, tdim), int64.
        orders: For simplices the order ``pi`` of every sub-cell, shape=(num, tdim), int64.
        centroids: Reference coordinates of the sub-cells' centroids, shape=(num, tdim), float64.
    """

    def __init__(self, cell: basix.CellType, granularity: int) -> None:
        if granularity < 1:
            raise ValueError("granularity must be >= 1")
        if cell not in _SIMPLEX and cell not in _HYPERCUBE:
            raise ValueError(f"no sub-cells for the cell type {cell}")
        self.simplex = cell in _SIMPLEX
        self.tdim = len(basix.topology(cell)) - 1
        self.granularity = g = int(granularity)
        self.num = g ** self.tdim
        d = self.tdim
        grid = np.array(list(itertools.product(range(g), repeat=d)), dtype=np.int64).reshape(-1, d)
        if not self.simplex:
            self.corners = grid
            self.orders = np.tile(np.arange(d, dtype=np.int64), (self.num, 1))
            self.centroids = (grid + 0.5) / g
        else:
            perms = np.array(list(itertools.permutations(range(d))), dtype=np.int64).reshape(-1, d)
            corners = np.repeat(grid, perms.shape[0], axis=0)
            orders = np.tile(perms, (grid.shape[0], 1))
            centroid_p = corners + self._offsets(orders, np.full((corners.shape[0], d), 1.0 / (d + 1)))
            s = centroid_p / g
            inside = np.all(s[:, :-1] >= s[:, 1:], axis=1) & (s[:, 0] <= 1) & (s[:, -1] >= 0)
            self.corners, self.orders = corners[inside], orders[inside]
            self.centroids = _from_kuhn(s[inside])
            assert self.corners.shape[0] == self.num
        self._lookup = np.full(g ** d * math.factorial(d), -1, dtype=np.int64)
        self._lookup[self._code(self.corners, self.orders)] = np.arange(self.num)

    def _code(self, corners: npt.NDArray[np.int64], orders: npt.NDArray[np.int64]) -> npt.NDArray[np.int64]:
        """An integer per (grid cell, order) pair, shape=(p,)."""
        g, d = self.granularity, self.tdim
        cell = np.zeros(corners.shape[0], dtype=np.int64)
        for t in range(d):
            cell = cell * g + corners[:, t]
        rank = np.zeros(corners.shape[0], dtype=np.int64)  # Lehmer code of the order
        for t in range(d):
            smaller = np.sum(orders[:, t + 1:] < orders[:, t : t + 1], axis=1)
            rank = rank * (d - t) + smaller
        return cell * math.factorial(d) + rank

    @staticmethod
    def _offsets(orders: npt.NDArray[np.int64], a: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """``sum_j a_j (v_j - v_0)`` with ``v_j - v_0 = e_pi1 + ... + e_pij``; shape=(p, d)."""
        p, d = a.shape
        out = np.zeros((p, d))
        rows = np.arange(p)
        tail = np.zeros(p)
        for j in range(d - 1, -1, -1):  # coordinate pi_j gets a_j + a_{j+1} + ... + a_d
            tail = tail + a[:, j]
            out[rows, orders[:, j]] = tail
        return out

    def index(self, xhat: npt.NDArray[np.float64]) -> npt.NDArray[np.int64]:
        """The sub-cell of each reference point, shape=(p, tdim) -> (p,), int64 in ``[0, num)``.

        Points on a face between sub-cells go to one of them; points a rounding error outside
        the reference cell go to the nearest sub-cell.
        """
        g = self.granularity
        xhat = np.asarray(xhat, dtype=np.float64).reshape(-1, self.tdim)
        p = (_to_kuhn(xhat) if self.simplex else xhat) * g
        k = np.clip(np.floor(p), 0, g - 1).astype(np.int64)
        if not self.simplex:
            return self._lookup[self._code(k, np.tile(np.arange(self.tdim, dtype=np.int64), (p.shape[0], 1)))]
        order = np.argsort(-(p - k), axis=1, kind="stable")
        out = self._lookup[self._code(k, order)]
        bad = np.flatnonzero(out < 0)
        if bad.size:
            d2 = ((xhat[bad, None, :] - self.centroids[None, :, :]) ** 2).sum(axis=2)
            out[bad] = np.argmin(d2, axis=1)
        return out

    def sample(self, sub: npt.NDArray[np.int64], u: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """Reference points in sub-cells ``sub`` (shape=(p,)) from points ``u`` of the reference
        *unit* cell of the sub-cell's shape (the unit simplex for simplices, the unit cube for
        hypercubes), shape=(p, tdim); an affine map, so uniform ``u`` gives uniform points."""
        g = self.granularity
        sub = np.asarray(sub, dtype=np.int64)
        if not self.simplex:
            return (self.corners[sub] + u) / g
        return _from_kuhn((self.corners[sub] + self._offsets(self.orders[sub], u)) / g)
