"""Numba kernels of the rows of a swarm: counting sort by cell, gather and scatter, the rows
outside the owned cells, and the message rows of a migration (packed by destination, appended).

Each kernel is one compiled loop over particles (no per-particle Python). The kernels only see
flat NumPy arrays; the Python layers (:mod:`particles.storage.swarm`, :mod:`particles.storage.rows`,
:mod:`particles.parallel.migration`) prepare them. The relocation walk is in
:mod:`particles.relocation.affine_walk`, the Runge-Kutta stage sum in :mod:`particles.advection.stages`,
the general finite-element kernels (evaluation, pull-back, location) in :mod:`fembase.kernels`."""

from __future__ import annotations

import numba
import numpy as np

__all__ = [
    "DEAD",
    "count_buckets",
    "gather_particles",
    "rows_outside",
    "scatter_particles",
    "sort_destinations",
]

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

