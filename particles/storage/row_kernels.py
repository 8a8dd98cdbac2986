"""Numba kernels of the particle hot paths: counting sort by cell, relocation, stage tables, packing.

Each kernel is one compiled loop over particles (no per-particle Python). The kernels only see
flat NumPy arrays; the Python layers (:mod:`particles.storage.swarm`, :mod:`fembase.evaluation`,
:mod:`particles.relocation.between_cells`) prepare them from DOLFINx objects once per mesh or function space. The
general finite-element kernels (evaluation, pull-back, location) are in :mod:`fembase.kernels`.
"""

from __future__ import annotations

import numba
import numpy as np

from fembase.kernels import pull_back_point

__all__ = [
    "DEAD",
    "STAYED",
    "NEIGHBOUR",
    "UNRESOLVED",
    "SKIPPED",
    "count_buckets",
    "gather_particles",
    "relocate_affine_simplex",
    "rows_outside",
    "scatter_particles",
    "sort_destinations",
    "stage_combination",
]

STAYED = 0
NEIGHBOUR = 1
UNRESOLVED = 2
SKIPPED = 3
"""Relocation status of a discarded row (left untouched)."""
DEAD = -2
"""Cell index of a row discarded since the last sort (sent away or lost); the next sort drops it."""


@numba.njit(cache=True)
def _bucket(k, num_owned):  # pragma: no cover - compiled
    """Sort bucket of cell index ``k``: the owned cell itself, ``num_owned`` for a ghost cell or
    an unlocated particle (-1), ``num_owned + 1`` for a discarded row (:data:`DEAD`)."""
    if k >= num_owned or k == -1:
        return num_owned
    if k < 0:
        return num_owned + 1
    return k


@numba.njit(cache=True)
def count_buckets(cells, num_owned, counts):  # pragma: no cover - compiled
    """Add each row's bucket (see :func:`_bucket`) to ``counts`` (shape=(num_owned + 2,), int64).

    Returns True if the buckets are already non-decreasing (and no row is discarded).
    """
    already = True
    prev = -1
    for p in range(cells.shape[0]):
        k = _bucket(cells[p], num_owned)
        counts[k] += 1
        if k < prev:
            already = False
        prev = k
    return already and counts[num_owned + 1] == 0


@numba.njit(cache=True)
def _scatter_1d(dest, a, out):  # pragma: no cover - compiled
    for p in range(dest.shape[0]):
        d = dest[p]
        if d >= 0:
            out[d] = a[p]


@numba.njit(cache=True)
def _scatter_2d(dest, a, out):  # pragma: no cover - compiled
    """out[dest[p]] = a[p] for dest[p] >= 0; the column count is branched on outside the loops
    (a runtime-length inner loop, or a helper call per row, costs about twice the copy)."""
    m = a.shape[1]
    if m == 0:
        return
    if m == 2:
        for p in range(dest.shape[0]):
            d = dest[p]
            if d >= 0:
                out[d, 0] = a[p, 0]
                out[d, 1] = a[p, 1]
    elif m == 3:
        for p in range(dest.shape[0]):
            d = dest[p]
            if d >= 0:
                out[d, 0] = a[p, 0]
                out[d, 1] = a[p, 1]
                out[d, 2] = a[p, 2]
    else:
        for p in range(dest.shape[0]):
            d = dest[p]
            if d >= 0:
                for j in range(m):
                    out[d, j] = a[p, j]


@numba.njit(cache=True)
def _gather_1d(rows, a, out):  # pragma: no cover - compiled
    for d in range(rows.shape[0]):
        out[d] = a[rows[d]]


@numba.njit(cache=True)
def _gather_2d(rows, a, out):  # pragma: no cover - compiled
    m = a.shape[1]
    if m == 0:
        return
    if m == 2:
        for d in range(rows.shape[0]):
            p = rows[d]
            out[d, 0] = a[p, 0]
            out[d, 1] = a[p, 1]
    elif m == 3:
        for d in range(rows.shape[0]):
            p = rows[d]
            out[d, 0] = a[p, 0]
            out[d, 1] = a[p, 1]
            out[d, 2] = a[p, 2]
    else:
        for d in range(rows.shape[0]):
            p = rows[d]
            for j in range(m):
                out[d, j] = a[p, j]


@numba.njit(cache=True)
def sort_destinations(num_owned, counts, cells, dest):  # pragma: no cover - compiled
    """Counting sort by cell, second half: the row each particle goes to, into ``dest`` (shape=(n,),
    int64).

    ``counts`` holds the rows per bucket (:func:`count_buckets`, or counted on the fly by the
    relocation kernel). Rows keep their relative order within a bucket (stable); rows of owned
    cells come first, by cell, then ghost/unlocated rows; discarded rows get -1. Returns False if
    ``counts`` do not match ``cells`` (then recount), else True.
    """
    nb = num_owned + 1
    n = cells.shape[0]
    pos = np.empty(nb, dtype=np.int64)
    end = np.empty(nb, dtype=np.int64)
    s = 0
    for k in range(nb):
        pos[k] = s
        s += counts[k]
        end[k] = s
    if s + counts[nb] != n:
        return False
    for p in range(n):
        k = cells[p]
        if k >= num_owned or k == -1:
            k = num_owned
        elif k < 0:
            dest[p] = -1
            continue
        d = pos[k]
        if d >= end[k]:
            return False
        pos[k] = d + 1
        dest[p] = d
    for k in range(nb):
        if pos[k] != end[k]:
            return False
    return True


@numba.njit(cache=True)
def scatter_particles(
    dest, ids, x, xref, cells, props, stage, ids_out, x_out, xref_out, cells_out, props_out, stage_out
):  # pragma: no cover - compiled
    """Row ``p`` of every per-particle array into row ``dest[p]`` of the outputs (skipped if -1)."""
    _scatter_1d(dest, ids, ids_out)
    _scatter_1d(dest, cells, cells_out)
    _scatter_2d(dest, x, x_out)
    _scatter_2d(dest, xref, xref_out)
    _scatter_2d(dest, props, props_out)
    _scatter_2d(dest, stage, stage_out)


@numba.njit(cache=True)
def gather_particles(
    rows, ids, x, xref, cells, props, stage, ids_out, x_out, xref_out, cells_out, props_out, stage_out
):  # pragma: no cover - compiled
    """Row ``rows[i]`` of every per-particle array into row ``i`` of the preallocated outputs."""
    _gather_1d(rows, ids, ids_out)
    _gather_1d(rows, cells, cells_out)
    _gather_2d(rows, x, x_out)
    _gather_2d(rows, xref, xref_out)
    _gather_2d(rows, props, props_out)
    _gather_2d(rows, stage, stage_out)


@numba.njit(cache=True)
def rows_outside(cells, num_owned):  # pragma: no cover - compiled
    """Rows whose cell is a ghost cell or -1 (not owned, not discarded), int64, in row order."""
    m = 0
    for p in range(cells.shape[0]):
        k = cells[p]
        if k >= num_owned or k == -1:
            m += 1
    rows = np.empty(m, dtype=np.int64)
    m = 0
    for p in range(cells.shape[0]):
        k = cells[p]
        if k >= num_owned or k == -1:
            rows[m] = p
            m += 1
    return rows


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
    (shape=(num_owned + 2,), see :func:`count_buckets`); unresolved ones are not counted. The rows
    of the resolved particles now in a ghost cell are written, in row order, to the start of
    ``outside`` (shape=(n,), int64). Returns ``(counts per status and then the number of those
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


@numba.njit(cache=True)
def stage_combination(table, start, width, coefs, out):  # pragma: no cover
    """Runge-Kutta stage sum from stage columns of a table, in one pass.

    ``out[p, i] = table[p, start + i] + sum_j coefs[j] * table[p, start + width * (j + 1) + i]``
    for ``i < width``: the start state plus the weighted stage slopes stored after it.
    (Several times faster than the same NumPy expression on strided column views; widths 2 and
    3, the positions, are written out.)
    """
    nc = coefs.shape[0]
    if width == 2:
        for p in range(table.shape[0]):
            a0 = table[p, start]
            a1 = table[p, start + 1]
            for j in range(nc):
                a0 += coefs[j] * table[p, start + 2 * (j + 1)]
                a1 += coefs[j] * table[p, start + 2 * (j + 1) + 1]
            out[p, 0] = a0
            out[p, 1] = a1
    elif width == 3:
        for p in range(table.shape[0]):
            a0 = table[p, start]
            a1 = table[p, start + 1]
            a2 = table[p, start + 2]
            for j in range(nc):
                a0 += coefs[j] * table[p, start + 3 * (j + 1)]
                a1 += coefs[j] * table[p, start + 3 * (j + 1) + 1]
                a2 += coefs[j] * table[p, start + 3 * (j + 1) + 2]
            out[p, 0] = a0
            out[p, 1] = a1
            out[p, 2] = a2
    else:
        for p in range(table.shape[0]):
            for i in range(width):
                acc = table[p, start + i]
                for j in range(nc):
                    acc += coefs[j] * table[p, start + width * (j + 1) + i]
                out[p, i] = acc


@numba.njit(cache=True)
def pack_by_slot(rows, slots, nslots, ids_bits, hints, x, xref, props, stage):  # pragma: no cover - compiled
    """Rows of particles as one float64 table grouped by destination slot (stable within a slot).

    ``rows`` (shape=(m,)) are the particles to pack, ``slots`` (shape=(m,), 0 <= slot < nslots)
    their destinations, ``ids_bits`` the swarm's ids viewed as float64 (shape=(n,)), ``hints``
    (shape=(m,), float64 bits) the second column. Columns: [id, hint, x, xref, properties, stage].
    Returns the table, shape=(m, 2 + gdim + tdim + ncols + stage_width), and the first row of
    every slot, shape=(nslots + 1,).
    """
    m = rows.shape[0]
    gdim, tdim, ncols, nstage = x.shape[1], xref.shape[1], props.shape[1], stage.shape[1]
    offsets = np.zeros(nslots + 1, dtype=np.int64)
    for i in range(m):
        offsets[slots[i] + 1] += 1
    for s in range(nslots):
        offsets[s + 1] += offsets[s]
    fill = offsets[:-1].copy()
    table = np.empty((m, 2 + gdim + tdim + ncols + nstage))
    for i in range(m):
        r, row = rows[i], fill[slots[i]]
        fill[slots[i]] += 1
        table[row, 0] = ids_bits[r]
        table[row, 1] = hints[i]
        c = 2
        for d in range(gdim):
            table[row, c + d] = x[r, d]
        c += gdim
        for d in range(tdim):
            table[row, c + d] = xref[r, d]
        c += tdim
        for d in range(ncols):
            table[row, c + d] = props[r, d]
        c += ncols
        for d in range(nstage):
            table[row, c + d] = stage[r, d]
    return table, offsets


@numba.njit(cache=True)
def append_packed(table, cells, start, ids_bits, x, xref, cells_out, props, stage, counts,
                  num_owned):  # pragma: no cover - compiled
    """Write the rows of a :func:`pack_by_slot` table (shape=(m, ncols)) into the swarm's buffers
    from row ``start`` on, with the given cells (shape=(m,), int32); ``counts`` (shape=(num_owned
    + 2,), or empty) gets one more particle per owned cell, or in the ghost/unlocated bucket."""
    gdim, tdim, ncols, nstage = x.shape[1], xref.shape[1], props.shape[1], stage.shape[1]
    track = counts.shape[0] > 0
    for i in range(table.shape[0]):
        r = start + i
        ids_bits[r] = table[i, 0]
        c = 2
        for d in range(gdim):
            x[r, d] = table[i, c + d]
        c += gdim
        for d in range(tdim):
            xref[r, d] = table[i, c + d]
        c += tdim
        for d in range(ncols):
            props[r, d] = table[i, c + d]
        c += ncols
        for d in range(nstage):
            stage[r, d] = table[i, c + d]
        k = cells[i]
        cells_out[r] = k
        if track:
            if 0 <= k < num_owned:
                counts[k] += 1
            elif k >= num_owned or k == -1:
                counts[num_owned] += 1
            else:
                counts[num_owned + 1] += 1

