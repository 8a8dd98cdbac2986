"""Numba kernels of the particle hot paths: cell ordering, P1/P2 simplex evaluation, relocation.

Each kernel is one compiled loop over particles (no per-particle Python). The kernels only see
flat NumPy arrays; the Python layers (:mod:`particles.swarm`, :mod:`particles.evaluation`,
:mod:`particles.transport`) prepare them from DOLFINx objects once per mesh or function space.
"""

from __future__ import annotations

import numba
import numpy as np

__all__ = [
    "STAYED",
    "NEIGHBOUR",
    "UNRESOLVED",
    "cell_order",
    "evaluate_simplex_p12",
    "permute_particles",
    "relocate_affine_simplex",
    "stage_combination",
]

STAYED = 0
NEIGHBOUR = 1
UNRESOLVED = 2


@numba.njit(cache=True)
def cell_order(cells, num_owned):  # pragma: no cover - compiled
    """Counting sort by cell: returns ``(order, offsets, already_sorted)``.

    Cells outside ``[0, num_owned)`` sort last. ``order`` (int64, stable) is empty when the input
    is already sorted. ``offsets`` has shape (num_owned + 1,) and counts only owned cells.
    """
    n = cells.shape[0]
    counts = np.zeros(num_owned + 1, dtype=np.int64)
    already = True
    prev = -1
    for p in range(n):
        k = cells[p]
        if k < 0 or k >= num_owned:
            k = num_owned
        counts[k] += 1
        if k < prev:
            already = False
        prev = k
    offsets = np.zeros(num_owned + 1, dtype=np.int64)
    for k in range(num_owned):
        offsets[k + 1] = offsets[k] + counts[k]
    if already:
        return np.empty(0, dtype=np.int64), offsets, True
    pos = np.empty(num_owned + 1, dtype=np.int64)
    for k in range(num_owned + 1):
        pos[k] = offsets[k] if k < num_owned else offsets[num_owned]
    order = np.empty(n, dtype=np.int64)
    for p in range(n):
        k = cells[p]
        if k < 0 or k >= num_owned:
            k = num_owned
        order[pos[k]] = p
        pos[k] += 1
    return order, offsets, False


@numba.njit(cache=True)
def evaluate_simplex_p12(cells, xref, dofs, coeffs, bs, degree, alpha, beta, out):  # pragma: no cover
    """Evaluate a P1/P2 Lagrange function on triangles or tetrahedra at reference points.

    Basis in basix order, written with barycentric coordinates ``l``: vertex functions ``l_v``
    (P1) or ``l_v (2 l_v - 1)``, then ``4 l_a l_b`` for the edges (a, b) in basix order
    (triangle: (1,2), (0,2), (0,1); tetrahedron: (2,3), (1,3), (1,2), (0,3), (0,2), (0,1)).
    The sums are written out per case: compiled loops over a runtime number of basis functions
    are several times slower here.

    Args:
        cells: shape=(n,), int32. xref: shape=(n, tdim), tdim 2 or 3. dofs: cell dofs,
        shape=(ncells, ndofs), int32. coeffs: DOF values, shape=(num_dofs * bs,).
        bs: block size (value components). degree: 1 or 2.
        alpha, beta: ``out = beta * out + alpha * u(x)`` (beta == 0 ignores the old ``out``,
        so an explicit Euler push is ``alpha = dt, beta = 1, out = x``).
        out: shape=(n, bs), updated in place.
    """
    n = cells.shape[0]
    tdim = xref.shape[1]
    if tdim == 2 and degree == 1:
        for p in range(n):
            c = cells[p]
            X = xref[p, 0]
            Y = xref[p, 1]
            L = 1.0 - X - Y
            d0, d1, d2 = dofs[c, 0] * bs, dofs[c, 1] * bs, dofs[c, 2] * bs
            for b in range(bs):
                v = L * coeffs[d0 + b] + X * coeffs[d1 + b] + Y * coeffs[d2 + b]
                out[p, b] = alpha * v + (beta * out[p, b] if beta != 0.0 else 0.0)
    elif tdim == 2:
        for p in range(n):
            c = cells[p]
            X = xref[p, 0]
            Y = xref[p, 1]
            L = 1.0 - X - Y
            f0, f1, f2 = L * (2.0 * L - 1.0), X * (2.0 * X - 1.0), Y * (2.0 * Y - 1.0)
            f3, f4, f5 = 4.0 * X * Y, 4.0 * L * Y, 4.0 * L * X
            d0, d1, d2 = dofs[c, 0] * bs, dofs[c, 1] * bs, dofs[c, 2] * bs
            d3, d4, d5 = dofs[c, 3] * bs, dofs[c, 4] * bs, dofs[c, 5] * bs
            for b in range(bs):
                v = (f0 * coeffs[d0 + b] + f1 * coeffs[d1 + b] + f2 * coeffs[d2 + b]
                     + f3 * coeffs[d3 + b] + f4 * coeffs[d4 + b] + f5 * coeffs[d5 + b])
                out[p, b] = alpha * v + (beta * out[p, b] if beta != 0.0 else 0.0)
    elif degree == 1:
        for p in range(n):
            c = cells[p]
            X = xref[p, 0]
            Y = xref[p, 1]
            Z = xref[p, 2]
            L = 1.0 - X - Y - Z
            d0, d1, d2, d3 = dofs[c, 0] * bs, dofs[c, 1] * bs, dofs[c, 2] * bs, dofs[c, 3] * bs
            for b in range(bs):
                v = L * coeffs[d0 + b] + X * coeffs[d1 + b] + Y * coeffs[d2 + b] + Z * coeffs[d3 + b]
                out[p, b] = alpha * v + (beta * out[p, b] if beta != 0.0 else 0.0)
    else:
        for p in range(n):
            c = cells[p]
            X = xref[p, 0]
            Y = xref[p, 1]
            Z = xref[p, 2]
            L = 1.0 - X - Y - Z
            f0, f1 = L * (2.0 * L - 1.0), X * (2.0 * X - 1.0)
            f2, f3 = Y * (2.0 * Y - 1.0), Z * (2.0 * Z - 1.0)
            f4, f5, f6 = 4.0 * Y * Z, 4.0 * X * Z, 4.0 * X * Y
            f7, f8, f9 = 4.0 * L * Z, 4.0 * L * Y, 4.0 * L * X
            for b in range(bs):
                v = (f0 * coeffs[dofs[c, 0] * bs + b] + f1 * coeffs[dofs[c, 1] * bs + b]
                     + f2 * coeffs[dofs[c, 2] * bs + b] + f3 * coeffs[dofs[c, 3] * bs + b]
                     + f4 * coeffs[dofs[c, 4] * bs + b] + f5 * coeffs[dofs[c, 5] * bs + b]
                     + f6 * coeffs[dofs[c, 6] * bs + b] + f7 * coeffs[dofs[c, 7] * bs + b]
                     + f8 * coeffs[dofs[c, 8] * bs + b] + f9 * coeffs[dofs[c, 9] * bs + b])
                out[p, b] = alpha * v + (beta * out[p, b] if beta != 0.0 else 0.0)


@numba.njit(cache=True)
def _pull_back_inside(c, x, p, origin, K, tol, xr):  # pragma: no cover
    """Reference coordinates of particle p in affine simplex c (into xr); True if inside.

    Written out for gdim == tdim in 2D and 3D (the hot cases), generic loops otherwise.
    """
    tdim = K.shape[1]
    gdim = K.shape[2]
    if tdim == 2 and gdim == 2:
        a = x[p, 0] - origin[c, 0]
        b = x[p, 1] - origin[c, 1]
        X = K[c, 0, 0] * a + K[c, 0, 1] * b
        Y = K[c, 1, 0] * a + K[c, 1, 1] * b
        xr[0] = X
        xr[1] = Y
        return X >= -tol and Y >= -tol and X + Y <= 1.0 + tol
    if tdim == 3 and gdim == 3:
        a = x[p, 0] - origin[c, 0]
        b = x[p, 1] - origin[c, 1]
        d = x[p, 2] - origin[c, 2]
        X = K[c, 0, 0] * a + K[c, 0, 1] * b + K[c, 0, 2] * d
        Y = K[c, 1, 0] * a + K[c, 1, 1] * b + K[c, 1, 2] * d
        Z = K[c, 2, 0] * a + K[c, 2, 1] * b + K[c, 2, 2] * d
        xr[0] = X
        xr[1] = Y
        xr[2] = Z
        return X >= -tol and Y >= -tol and Z >= -tol and X + Y + Z <= 1.0 + tol
    s = 0.0
    ok = True
    for i in range(tdim):
        acc = 0.0
        for j in range(gdim):
            acc += K[c, i, j] * (x[p, j] - origin[c, j])
        xr[i] = acc
        s += acc
        if acc < -tol:
            ok = False
    if s > 1.0 + tol:
        ok = False
    return ok



@numba.njit(cache=True)
def _pull_back_tuple(c, px, py, pz, origin, K, tol):  # pragma: no cover
    """(inside, X, Y, Z) of point (px, py, pz) in affine simplex c, gdim == tdim in {2, 3}."""
    if K.shape[1] == 2:
        a = px - origin[c, 0]
        b = py - origin[c, 1]
        X = K[c, 0, 0] * a + K[c, 0, 1] * b
        Y = K[c, 1, 0] * a + K[c, 1, 1] * b
        return (X >= -tol and Y >= -tol and X + Y <= 1.0 + tol), X, Y, 0.0
    a = px - origin[c, 0]
    b = py - origin[c, 1]
    d = pz - origin[c, 2]
    X = K[c, 0, 0] * a + K[c, 0, 1] * b + K[c, 0, 2] * d
    Y = K[c, 1, 0] * a + K[c, 1, 1] * b + K[c, 1, 2] * d
    Z = K[c, 2, 0] * a + K[c, 2, 1] * b + K[c, 2, 2] * d
    return (X >= -tol and Y >= -tol and Z >= -tol and X + Y + Z <= 1.0 + tol), X, Y, Z


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
        ok, X, Y, Z = _pull_back_tuple(first, px, py, pz, origin, K, tol)
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
        ok, X, Y, Z = _pull_back_tuple(cand[i], px, py, pz, origin, K, tol)
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
            ok, X, Y, Z = _pull_back_tuple(cc, px, py, pz, origin, K, tol)
            if ok:
                xr[0] = X
                xr[1] = Y
                if gdim == 3:
                    xr[2] = Z
                return cc
    return -1


@numba.njit(cache=True)
def _stay_pass(x, cells, xref, origin, K, tol, status):  # pragma: no cover
    """First pass: particles still inside their cell get their new xref and STAYED; returns their count."""
    n = x.shape[0]
    tdim = K.shape[1]
    gdim = K.shape[2]
    stayed = 0
    if tdim == 2 and gdim == 2:
        for p in range(n):
            c = cells[p]
            if c < 0:
                status[p] = UNRESOLVED
                continue
            a = x[p, 0] - origin[c, 0]
            b = x[p, 1] - origin[c, 1]
            X = K[c, 0, 0] * a + K[c, 0, 1] * b
            Y = K[c, 1, 0] * a + K[c, 1, 1] * b
            if X >= -tol and Y >= -tol and X + Y <= 1.0 + tol:
                xref[p, 0] = X
                xref[p, 1] = Y
                status[p] = STAYED
                stayed += 1
            else:
                status[p] = UNRESOLVED
    elif tdim == 3 and gdim == 3:
        for p in range(n):
            c = cells[p]
            if c < 0:
                status[p] = UNRESOLVED
                continue
            a = x[p, 0] - origin[c, 0]
            b = x[p, 1] - origin[c, 1]
            d = x[p, 2] - origin[c, 2]
            X = K[c, 0, 0] * a + K[c, 0, 1] * b + K[c, 0, 2] * d
            Y = K[c, 1, 0] * a + K[c, 1, 1] * b + K[c, 1, 2] * d
            Z = K[c, 2, 0] * a + K[c, 2, 1] * b + K[c, 2, 2] * d
            if X >= -tol and Y >= -tol and Z >= -tol and X + Y + Z <= 1.0 + tol:
                xref[p, 0] = X
                xref[p, 1] = Y
                xref[p, 2] = Z
                status[p] = STAYED
                stayed += 1
            else:
                status[p] = UNRESOLVED
    else:
        xr = np.empty(tdim)
        for p in range(n):
            c = cells[p]
            if c >= 0 and _pull_back_inside(c, x, p, origin, K, tol, xr):
                for i in range(tdim):
                    xref[p, i] = xr[i]
                status[p] = STAYED
                stayed += 1
            else:
                status[p] = UNRESOLVED
    return stayed


@numba.njit(cache=True)
def relocate_affine_simplex(
    x, cells, xref, origin, K, nodes, coords, v2c_off, v2c_cells, centres, nv, max_valence, tol, status
):  # pragma: no cover
    """Update ``cells``/``xref`` of particles at new positions ``x`` (affine simplices).

    Per particle: test the current cell; if the point left it, test the cells around the cell
    vertex closest to the point, ordered by descending ``(x - v) . (centre(K') - v)``
    (seed paper section 2.4), then the remaining vertex neighbours of the old cell. ``status``
    gets STAYED, NEIGHBOUR or UNRESOLVED (cell == -1 on input, or not found: left for the
    bounding-box fallback; ``cells`` is then unchanged). Returns the counts per status, shape=(3,).
    Two passes: a tight loop for the
    particles that stayed (most of them), then the search for the others.
    """
    counts = np.zeros(3, dtype=np.int64)
    counts[STAYED] = _stay_pass(x, cells, xref, origin, K, tol, status)
    counts[UNRESOLVED] = x.shape[0] - counts[STAYED]
    tdim = K.shape[1]
    xr = np.empty(tdim)
    cand = np.empty(max_valence, dtype=np.int32)
    score = np.empty(max_valence)
    for p in range(x.shape[0]):
        c = cells[p]
        if status[p] != UNRESOLVED or c < 0:
            continue
        found = _search_vertex_neighbours(
            p, c, x, origin, K, nodes, coords, v2c_off, v2c_cells, centres, nv, tol, xr, cand, score
        )
        if found >= 0:
            cells[p] = found
            status[p] = NEIGHBOUR
            counts[NEIGHBOUR] += 1
            counts[UNRESOLVED] -= 1
            for i in range(tdim):
                xref[p, i] = xr[i]
    return counts



@numba.njit(cache=True)
def stage_combination(table, start, width, coefs, out):  # pragma: no cover
    """Runge-Kutta stage sum from stage columns of the property table, in one pass.

    ``out[p, i] = table[p, start + i] + sum_j coefs[j] * table[p, start + width * (j + 1) + i]``
    for ``i < width``: the start state plus the weighted stage slopes stored after it.
    (Several times faster than the same NumPy expression on strided column views.)
    """
    for p in range(table.shape[0]):
        for i in range(width):
            acc = table[p, start + i]
            for j in range(coefs.shape[0]):
                acc += coefs[j] * table[p, start + width * (j + 1) + i]
            out[p, i] = acc


@numba.njit(cache=True)
def _permute_rows(order, a, out):  # pragma: no cover
    """out[i] = a[order[i]] for a 2-D array; 1-3 columns written out (runtime-length inner loops
    are much slower here)."""
    m = a.shape[1]
    if m == 2:
        for i in range(order.shape[0]):
            r = order[i]
            out[i, 0] = a[r, 0]
            out[i, 1] = a[r, 1]
    elif m == 3:
        for i in range(order.shape[0]):
            r = order[i]
            out[i, 0] = a[r, 0]
            out[i, 1] = a[r, 1]
            out[i, 2] = a[r, 2]
    else:
        for i in range(order.shape[0]):
            r = order[i]
            for j in range(m):
                out[i, j] = a[r, j]


@numba.njit(cache=True)
def permute_particles(order, ids, x, xref, cells, ids_out, x_out, xref_out, cells_out):  # pragma: no cover
    """Write row ``order[i]`` of ids, x, xref, cells into row i of the preallocated outputs."""
    for i in range(order.shape[0]):
        r = order[i]
        ids_out[i] = ids[r]
        cells_out[i] = cells[r]
    _permute_rows(order, x, x_out)
    _permute_rows(order, xref, xref_out)
