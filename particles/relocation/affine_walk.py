"""The cell walk of :func:`particles.relocation.between_cells.relocate`, compiled for affine
simplices: one pass over the particles that also counts them per sort bucket.

Each particle's status after the walk is one of :data:`STAYED`, :data:`NEIGHBOUR`,
:data:`UNRESOLVED` (left for the bounding-box fallback) or :data:`SKIPPED`.
"""

from __future__ import annotations

import numba
import numpy as np

from fembase.kernels import pull_back_point
from particles.storage.row_kernels import DEAD

__all__ = ["NEIGHBOUR", "SKIPPED", "STAYED", "UNRESOLVED", "relocate_affine_simplex"]

STAYED = 0
NEIGHBOUR = 1
UNRESOLVED = 2
SKIPPED = 3
"""Relocation status of a discarded row (left untouched)."""


@numba.njit(cache=True)
def _search_vertex_neighbours(
    p, c, x, origin, K, nodes, coords, v2c_off, v2c_cells, centres, nv, tol, xr, cand, score
):  # pragma: no cover
    """Cell among the vertex neighbours of ``c`` containing particle ``p`` (xref into xr), or -1.

    Requires gdim == tdim in {2, 3}.
    """
    gdim = K.shape[2]
    px = x[p, 0]
    py = x[p, 1]
    pz = x[p, 2] if gdim == 3 else 0.0
    best = nodes[c, 0]
    bd = np.inf
    for k in range(nv):
        v = nodes[c, k]
        dx = px - coords[v, 0]
        dy = py - coords[v, 1]
        dz = pz - coords[v, 2] if gdim == 3 else 0.0
        d = dx * dx + dy * dy + dz * dz
        if d < bd:
            bd = d
            best = v
    bx = coords[best, 0]
    by = coords[best, 1]
    bz = coords[best, 2] if gdim == 3 else 0.0
    ax = px - bx
    ay = py - by
    az = pz - bz
    m = 0
    top = 0
    for e in range(v2c_off[best], v2c_off[best + 1]):
        cc = v2c_cells[e]
        if cc == c:
            continue
        sc = ax * (centres[cc, 0] - bx) + ay * (centres[cc, 1] - by)
        if gdim == 3:
            sc += az * (centres[cc, 2] - bz)
        score[m] = sc
        cand[m] = cc
        if sc > score[top]:
            top = m
        m += 1
    # Most particles are found in the best-scoring cell; sort the others only if needed.
    first = -1
    if m > 0:
        first = cand[top]
        ok, X, Y, Z = pull_back_point(first, px, py, pz, origin, K, tol)
        if ok:
            xr[0] = X
            xr[1] = Y
            if gdim == 3:
                xr[2] = Z
            return first
        for i in range(1, m):
            sc = score[i]
            cc = cand[i]
            j = i
            while j > 0 and score[j - 1] < sc:
                score[j] = score[j - 1]
                cand[j] = cand[j - 1]
                j -= 1
            score[j] = sc
            cand[j] = cc
    for i in range(m):
        if cand[i] == first:
            continue
        ok, X, Y, Z = pull_back_point(cand[i], px, py, pz, origin, K, tol)
        if ok:
            xr[0] = X
            xr[1] = Y
            if gdim == 3:
                xr[2] = Z
            return cand[i]
    for k in range(nv):
        v = nodes[c, k]
        if v == best:
            continue
        for e in range(v2c_off[v], v2c_off[v + 1]):
            cc = v2c_cells[e]
            if cc == c:
                continue
            seen = False
            for i in range(m):
                if cand[i] == cc:
                    seen = True
                    break
            if seen:
                continue
            ok, X, Y, Z = pull_back_point(cc, px, py, pz, origin, K, tol)
            if ok:
                xr[0] = X
                xr[1] = Y
                if gdim == 3:
                    xr[2] = Z
                return cc
    return -1


@numba.njit(cache=True)
def _walk_candidate(facet_nbrs, c, L0, L1, L2, L3, tdim):  # pragma: no cover
    """The cell across the facet of ``c`` whose barycentric coordinate is most negative (or -1)."""
    i = 0
    m = L0
    if L1 < m:
        i = 1
        m = L1
    if L2 < m:
        i = 2
        m = L2
    if tdim == 3 and L3 < m:
        i = 3
    return facet_nbrs[c, i]


@numba.njit(cache=True)
def relocate_affine_simplex(
    x, cells, xref, origin, K, nodes, coords, v2c_off, v2c_cells, centres, facet_nbrs, nv, max_valence, tol,
    num_owned, status, counts, outside
):  # pragma: no cover
    """Update ``cells``/``xref`` of particles at new positions ``x`` (affine simplices, gdim == tdim
    in {2, 3}) and count the particles per sort bucket, in one pass.

    Per particle: test the current cell; if the point left it, test the cell across the facet with
    the most negative barycentric coordinate (``facet_nbrs``, the usual case for a move shorter than
    a cell); then the cells around the cell vertex closest to the point, ordered by descending
    ``(x - v) . (centre(K') - v)`` (seed paper section 2.4), then the remaining vertex neighbours of
    the old cell. ``status`` gets STAYED, NEIGHBOUR or UNRESOLVED (cell == -1 on input, or not found:
    left for the bounding-box fallback; ``cells`` is then unchanged), or SKIPPED for a discarded row
    (:data:`DEAD`). Every resolved or discarded particle adds 1 to ``counts[bucket]``
    (shape=(num_owned + 2,), see :func:`particles.storage.row_kernels.count_buckets`); unresolved ones
    are not counted. The rows of the resolved particles now in a ghost cell are written, in row order,
    to the start of ``outside`` (shape=(n,), int64). Returns ``(counts per status and then the number of those
    rows, shape=(4,), whether the counted rows are in bucket order)``.
    """
    res = np.zeros(4, dtype=np.int64)
    tdim = K.shape[1]
    xr = np.empty(tdim)
    cand = np.empty(max(max_valence, 1), dtype=np.int32)
    score = np.empty(max(max_valence, 1))
    already = True
    prev = -1
    for p in range(x.shape[0]):
        c = cells[p]
        if c < 0:
            if c == DEAD:  # discarded since the last sort: leave it for the sort to drop
                status[p] = SKIPPED
                counts[num_owned + 1] += 1
            else:
                status[p] = UNRESOLVED
                res[UNRESOLVED] += 1
            already = False
            continue
        px = x[p, 0]
        py = x[p, 1]
        a = px - origin[c, 0]
        b = py - origin[c, 1]
        if tdim == 2:
            X = K[c, 0, 0] * a + K[c, 0, 1] * b
            Y = K[c, 1, 0] * a + K[c, 1, 1] * b
            Z = 0.0
            inside = X >= -tol and Y >= -tol and X + Y <= 1.0 + tol
        else:
            pz = x[p, 2]
            e = pz - origin[c, 2]
            X = K[c, 0, 0] * a + K[c, 0, 1] * b + K[c, 0, 2] * e
            Y = K[c, 1, 0] * a + K[c, 1, 1] * b + K[c, 1, 2] * e
            Z = K[c, 2, 0] * a + K[c, 2, 1] * b + K[c, 2, 2] * e
            inside = X >= -tol and Y >= -tol and Z >= -tol and X + Y + Z <= 1.0 + tol
        found = -1
        if inside:
            found = c
            status[p] = STAYED
            res[STAYED] += 1
        else:
            f = _walk_candidate(facet_nbrs, c, 1.0 - X - Y - Z, X, Y, Z, tdim)
            if f >= 0:
                inside, X, Y, Z = pull_back_point(f, px, py, x[p, 2] if tdim == 3 else 0.0, origin, K, tol)
                if inside:
                    found = f
            if found < 0:
                found = _search_vertex_neighbours(
                    p, c, x, origin, K, nodes, coords, v2c_off, v2c_cells, centres, nv, tol, xr, cand, score
                )
                if found >= 0:
                    X = xr[0]
                    Y = xr[1]
                    if tdim == 3:
                        Z = xr[2]
            if found >= 0:
                cells[p] = found
                status[p] = NEIGHBOUR
                res[NEIGHBOUR] += 1
            else:
                status[p] = UNRESOLVED
                res[UNRESOLVED] += 1
                already = False
                continue
        xref[p, 0] = X
        xref[p, 1] = Y
        if tdim == 3:
            xref[p, 2] = Z
        k = found if found < num_owned else num_owned
        counts[k] += 1
        if k == num_owned:
            outside[res[3]] = p
            res[3] += 1
        if k < prev:
            already = False
        prev = k
    return res, already
