"""Point location among the local cells of a :class:`fembase.geometry.CellGeometry`: the searches
behind :meth:`~fembase.geometry.CellGeometry.locate`,
:meth:`~fembase.geometry.CellGeometry.max_over_containing` and
:meth:`~fembase.geometry.CellGeometry.colliding`, and what they return.

A candidate cell contains a point when the point's pull-back lies in the reference cell. Affine
simplices in 2D and 3D are tested by one compiled pass over the candidates (:mod:`fembase.kernels`):
first the candidates the caller gives, then, for the points still missed, the cells whose bounding
boxes hold them (``tree``: the geometry's bounding-box search). Other cells pull back every candidate
of the bounding-box tree (Newton for curved cells).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, NamedTuple, Protocol

import numpy as np
import numpy.typing as npt

from fembase import kernels
from fembase.dolfinx_compat import compute_collisions

__all__ = ["Candidates", "Located", "SearchedCells", "TreeSearch", "containing_cells", "locate_points",
           "max_over_containing"]


class SearchedCells(Protocol):
    """What the searches read of the cells they search: :class:`fembase.geometry.CellGeometry` has
    it (this protocol keeps :mod:`fembase.geometry`, which calls the searches, out of this
    module's imports).

    Attributes:
        gdim, tdim: Geometric and topological dimensions.
        affine: True for degree-1 simplices, where ``origin`` and ``K`` are valid.
        origin: First vertex of each cell, shape=(num_local_cells, gdim).
        K: (Pseudo-)inverse Jacobian of each cell map, shape=(num_local_cells, tdim, gdim).
        tol: Relative tolerance of the inside-cell test, in reference coordinates.
        num_owned_cells, num_local_cells: Owned cells, and owned plus ghost cells.
        tree: The bounding-box tree over all local cells.
    """

    gdim: int
    tdim: int
    affine: bool
    origin: npt.NDArray[np.float64]
    K: npt.NDArray[np.float64]
    tol: float
    num_owned_cells: int
    num_local_cells: int

    @property
    def tree(self) -> Any: ...

    def pull_back(self, cells: npt.NDArray[np.int32], x: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """Reference coordinates of points ``x`` (shape=(m, gdim)) in ``cells`` (shape=(m,))."""
        ...

    def inside(self, xref: npt.NDArray[np.float64]) -> npt.NDArray[np.bool_]:
        """Whether reference points lie in the reference cell, shape=(m,)."""
        ...


class Located(NamedTuple):
    """Result of a point search.

    Attributes:
        cells: Local cell containing each point (-1 if none on this rank), shape=(m,), int32.
        xref: Reference coordinates in that cell (undefined where cells == -1), shape=(m, tdim).
    """

    cells: npt.NDArray[np.int32]
    xref: npt.NDArray[np.float64]


class Candidates(NamedTuple):
    """Cells to search first, shared by groups of points (e.g. the cells of a new mesh refined from
    the base cell each point's old cell descends from).

    Attributes:
        groups: The candidate group of each point, shape=(m,), int64 in [0, G).
        offsets: Group ``g``'s cells are ``cells[offsets[g]:offsets[g + 1]]``, shape=(G + 1,), int64.
        cells: Local cell indices, shape=(offsets[-1],), int32.
    """

    groups: npt.NDArray[np.int64]
    offsets: npt.NDArray[np.int64]
    cells: npt.NDArray[np.int32]


TreeSearch = Callable[[npt.NDArray[np.float64]], Candidates]
"""The cells whose bounding boxes hold each point (points shape=(m, gdim), one group per point)."""

def _compiled(geometry: SearchedCells) -> bool:
    """Whether the compiled kernels search the geometry's cells (affine simplices, gdim == tdim in {2, 3})."""
    return geometry.affine and geometry.gdim == geometry.tdim and geometry.gdim in (2, 3)


def locate_points(geometry: SearchedCells, points: npt.ArrayLike, tree: TreeSearch, *, owned_only: bool = False,
                  candidates: Candidates | None = None) -> Located:
    """:meth:`fembase.geometry.CellGeometry.locate`, whose bounding-box search is ``tree``."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, geometry.gdim)
    m = pts.shape[0]
    cells = np.full(m, -1, dtype=np.int32)
    xref = np.zeros((m, geometry.tdim), dtype=np.float64)
    if _compiled(geometry) and m > 0:
        # One compiled pass over the candidates (the vectorised path below costs ~5 numpy
        # temporaries per candidate).
        pts = np.ascontiguousarray(pts)
        limit = geometry.num_owned_cells if owned_only else geometry.num_local_cells

        def search(rows: slice | npt.NDArray[np.int64], among: Candidates) -> None:
            found, found_xref = cells[rows], xref[rows]
            kernels.locate_among_candidates(*among, pts[rows], geometry.origin, geometry.K, geometry.tol, limit,
                                            found, found_xref)
            cells[rows], xref[rows] = found, found_xref

        _first_then_tree(pts, candidates, tree, search, lambda: cells < 0)
        return Located(cells, xref)
    offsets, links, X = containing_cells(geometry, pts, owned_only=owned_only)
    hit = offsets[1:] > offsets[:-1]
    if np.any(hit):
        lowest = np.minimum.reduceat(links, offsets[:-1][hit])
        # the row of each point's lowest cell: the first row whose cell is its point's lowest
        rows = np.flatnonzero(links == np.repeat(lowest, np.diff(offsets)[hit]))
        point_of = np.repeat(np.flatnonzero(hit), np.diff(offsets)[hit])[rows]
        first = rows[np.r_[True, point_of[1:] != point_of[:-1]]]
        cells[hit] = lowest
        xref[hit] = X[first]
    return Located(cells, xref)


def max_over_containing(geometry: SearchedCells, points: npt.ArrayLike, values: npt.NDArray[np.int32],
                        tree: TreeSearch, *, default: int = -1, candidates: Candidates | None = None
                        ) -> tuple[npt.NDArray[np.int32], npt.NDArray[np.bool_], npt.NDArray[np.bool_]]:
    """:meth:`fembase.geometry.CellGeometry.max_over_containing`, whose bounding-box search is ``tree``."""
    pts = np.ascontiguousarray(np.asarray(points, dtype=np.float64).reshape(-1, geometry.gdim))
    m = pts.shape[0]
    values = np.ascontiguousarray(values, dtype=np.int32)
    largest = np.full(m, default, dtype=np.int32)
    hit = np.zeros(m, dtype=np.bool_)
    ghost = np.zeros(m, dtype=np.bool_)
    if m == 0:
        return largest, hit, ghost
    if _compiled(geometry):
        def search(rows: slice | npt.NDArray[np.int64], among: Candidates) -> None:
            out = largest[rows], hit[rows], ghost[rows]
            kernels.max_among_candidates(*among, pts[rows], geometry.origin, geometry.K, geometry.tol, values,
                                         geometry.num_owned_cells, *out)
            largest[rows], hit[rows], ghost[rows] = out

        _first_then_tree(pts, candidates, tree, search, lambda: ~hit)
        return largest, hit, ghost
    offsets, cells, _ = containing_cells(geometry, pts)
    hit = offsets[1:] > offsets[:-1]
    if np.any(hit):
        largest[hit] = np.maximum.reduceat(values[cells], offsets[:-1][hit])
        is_ghost = (cells >= geometry.num_owned_cells).astype(np.int64)
        ghost[hit] = np.add.reduceat(is_ghost, offsets[:-1][hit]) > 0
    return largest, hit, ghost


def containing_cells(geometry: SearchedCells, points: npt.ArrayLike, *, owned_only: bool = False
                     ) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int32], npt.NDArray[np.float64]]:
    """:meth:`fembase.geometry.CellGeometry.colliding`: every candidate of the geometry's
    bounding-box tree pulled back and tested."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, geometry.gdim)
    m = pts.shape[0]
    if m == 0:
        return np.zeros(1, dtype=np.int64), np.zeros(0, dtype=np.int32), np.zeros((0, geometry.tdim))
    p3 = np.zeros((m, 3), dtype=np.float64)
    p3[:, : geometry.gdim] = pts
    candidates = compute_collisions(geometry.tree, p3)
    offsets = np.asarray(candidates.offsets, dtype=np.int64)
    links = np.asarray(candidates.array, dtype=np.int32)
    if owned_only:
        offsets, links = _restrict(offsets, links, links < geometry.num_owned_cells)
    point_of = np.repeat(np.arange(m), np.diff(offsets))
    X = geometry.pull_back(links, pts[point_of])
    ok = geometry.inside(X)
    new_offsets = np.zeros(m + 1, dtype=np.int64)
    np.cumsum(np.bincount(point_of[ok], minlength=m), out=new_offsets[1:])
    return new_offsets, links[ok], X[ok]


def _first_then_tree(pts: npt.NDArray[np.float64], candidates: Candidates | None, tree: TreeSearch,
                     search: Callable[[slice | npt.NDArray[np.int64], Candidates], None],
                     missed: Callable[[], npt.NDArray[np.bool_]]) -> None:
    """Run ``search(rows, candidates)`` on every point with the given candidates, then on the
    points ``missed()`` still flags with the tree's candidates (on all points without any)."""
    rows: slice | npt.NDArray[np.int64] = slice(None)
    if candidates is not None:
        search(rows, Candidates(*(np.ascontiguousarray(a, dtype=t) for a, t in
                                  zip(candidates, (np.int64, np.int64, np.int32)))))
        rows = np.flatnonzero(missed())
        if rows.size == 0:
            return
    search(rows, tree(np.ascontiguousarray(pts[rows])))


def _restrict(offsets: npt.NDArray[np.int64], links: npt.NDArray[np.int32], keep: npt.NDArray[np.bool_]
              ) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int32]]:
    """The CSR adjacency ``(offsets, links)`` with only the links where ``keep`` is true."""
    segment = np.repeat(np.arange(offsets.size - 1), np.diff(offsets))
    counts = np.bincount(segment[keep], minlength=offsets.size - 1)
    new_offsets = np.zeros_like(offsets)
    np.cumsum(counts, out=new_offsets[1:])
    return new_offsets, links[keep]
