"""Transport of particles between cells after their positions changed (seed paper section 2.4).

For every particle the reference position in its old cell is recomputed; if it is still inside,
nothing else happens. Otherwise the cell across the facet the particle crossed (the most negative
barycentric coordinate) is tried first, then the cells around the old cell's vertex closest to the
particle in order of descending ``a . b_K'`` (``a`` = particle - vertex, ``b_K'`` = centre of
candidate ``K'`` - vertex), then the other vertex neighbours of the old
cell; only particles still not found use a bounding-box search over this rank's owned and ghost
cells. Particles found nowhere get ``cells = -1``; particles found in ghost cells keep the ghost
index. Migration (:mod:`particles.parallel.migration`) then hands both kinds on. The relocation kernel
counts the particles per cell as it goes, so the re-sort by cell that follows (counting sort) is a
single pass.

Affine simplices use a compiled kernel (:func:`particles.relocation.affine_walk.relocate_affine_simplex`); other
cells a vectorised search over the vertex neighbours with Newton pull-backs.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from fembase.geometry import CellGeometry
from particles.relocation.affine_walk import NEIGHBOUR, SKIPPED, STAYED, UNRESOLVED, relocate_affine_simplex
from particles.storage.row_kernels import DEAD
from particles.storage.swarm import Swarm

__all__ = ["TransportStats", "relocate"]


class TransportStats(NamedTuple):
    """How each particle of this rank was relocated (local counts; they add up to the particles).

    Attributes:
        stayed: Still inside the old cell.
        neighbour: Found among the vertex neighbours of the old cell.
        fallback: Found by the bounding-box search.
        not_found: In no local cell (``cells = -1``).
    """

    stayed: int
    neighbour: int
    fallback: int
    not_found: int

    def __add__(self, other: object) -> TransportStats:  # type: ignore[override]
        if not isinstance(other, TransportStats):
            return NotImplemented
        return TransportStats(*(a + b for a, b in zip(self, other)))


def _relocate_general(geom: CellGeometry, x, cells, xref, status) -> None:
    """Vectorised relocation for non-affine cells (same contract as the compiled kernel)."""
    status[:] = UNRESOLVED
    status[cells == DEAD] = SKIPPED
    valid = np.flatnonzero(cells >= 0)
    X = geom.pull_back(cells[valid], x[valid])
    ok = geom.inside(X)
    xref[valid[ok]] = X[ok]
    status[valid[ok]] = STAYED
    todo = valid[~ok]
    if todo.size == 0:
        return
    offsets, nbrs = geom.vertex_neighbours
    old = cells[todo]
    r = 0
    while todo.size:
        has = offsets[old] + r < offsets[old + 1]
        todo, old = todo[has], old[has]
        if todo.size == 0:
            break
        cand = nbrs[offsets[old] + r]
        X = geom.pull_back(cand, x[todo])
        ok = geom.inside(X)
        hit = todo[ok]
        cells[hit], xref[hit], status[hit] = cand[ok], X[ok], NEIGHBOUR
        todo, old = todo[~ok], old[~ok]
        r += 1


def relocate(swarm: Swarm, /, *, sort: bool = True) -> TransportStats:
    """Update ``cells`` and ``xref`` of all particles after ``swarm.x`` changed (local, not collective).

    Rows discarded since the last sort (:meth:`Swarm.discard_rows`) are left alone.

    Args:
        swarm: The particles; ``cells`` holds the cell before the move (or -1).
        sort: Re-sort the swarm by cell afterwards. With False the particles per cell counted
            during the relocation are handed to the swarm (:meth:`Swarm.set_pending_counts`), so
            a later :meth:`Swarm.sort` (e.g. the one at the end of a migration) needs one pass only;
            the swarm must be sorted before its ``offsets`` are used again.

    Returns:
        Local counts of the path each particle took.
    """
    geom = swarm.geometry
    n = swarm.num_particles
    status = np.empty(n, dtype=np.int8)
    num_owned = swarm.num_owned_cells
    buckets: np.ndarray | None = None
    outside: np.ndarray | None = None
    if geom.affine and geom.gdim == geom.tdim and geom.tdim in (2, 3):
        buckets = np.zeros(num_owned + 2, dtype=np.int64)
        outside = np.empty(n, dtype=np.int64)
        counts, in_order = relocate_affine_simplex(
            swarm.x, swarm.cells, swarm.xref, geom.origin, geom.K, geom.nodes, geom.coords,
            geom.v2c_offsets, geom.v2c_cells, geom.centres, geom.facet_neighbours, geom.num_vertices,
            max(geom.max_valence, 1), geom.tol, num_owned, status, buckets, outside,
        )
        outside = outside[: counts[3]]
    else:
        _relocate_general(geom, swarm.x, swarm.cells, swarm.xref, status)
        counts, in_order = np.bincount(status, minlength=4), False
    rows = np.flatnonzero(status == UNRESOLVED) if counts[UNRESOLVED] else np.empty(0, dtype=np.int64)
    found = 0
    if rows.size:
        loc = geom.locate(swarm.x[rows])
        swarm.cells[rows] = loc.cells
        hit = loc.cells >= 0
        swarm.xref[rows[hit]] = loc.xref[hit]
        found = int(np.count_nonzero(hit))
        if buckets is not None:
            buckets += np.bincount(np.where((loc.cells >= 0) & (loc.cells < num_owned), loc.cells, num_owned),
                                   minlength=num_owned + 2)
            in_order = False
        if outside is not None:
            outside = np.union1d(outside, rows[(loc.cells < 0) | (loc.cells >= num_owned)])
    if buckets is not None:
        swarm.set_pending_counts(buckets, bool(in_order), outside)
    if sort:
        swarm.sort()
    return TransportStats(int(counts[STAYED]), int(counts[NEIGHBOUR]), found, int(rows.size) - found)
