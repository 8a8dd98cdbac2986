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
    "relocate_affine_simplex",
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
def evaluate_simplex_p12(cells, xref, dofs, coeffs, bs, degree, edges, out):  # pragma: no cover
    """Evaluate a P1/P2 Lagrange function on simplices at reference points.

    Basis in basix order: vertex functions, then one function per edge ``edges[e] = (a, b)``,
    written with barycentric coordinates ``l``: ``l_v`` (P1), ``l_v (2 l_v - 1)`` and
    ``4 l_a l_b`` (P2).

    Args:
        cells: shape=(n,), int32. xref: shape=(n, tdim). dofs: cell dofs, shape=(ncells, ndofs).
        coeffs: DOF values, shape=(num_dofs * bs,). bs: block size (value components).
        degree: 1 or 2. edges: reference edges, shape=(num_edges, 2), int64.
        out: Values, shape=(n, bs), written in place.
    """
    n = cells.shape[0]
    tdim = xref.shape[1]
    nv = tdim + 1
    nd = dofs.shape[1]
    lam = np.empty(nv)
    phi = np.empty(nd)
    for p in range(n):
        c = cells[p]
        s = 0.0
        for i in range(tdim):
            lam[i + 1] = xref[p, i]
            s += xref[p, i]
        lam[0] = 1.0 - s
        if degree == 1:
            for v in range(nv):
                phi[v] = lam[v]
        else:
            for v in range(nv):
                phi[v] = lam[v] * (2.0 * lam[v] - 1.0)
            for e in range(edges.shape[0]):
                phi[nv + e] = 4.0 * lam[edges[e, 0]] * lam[edges[e, 1]]
        for b in range(bs):
            acc = 0.0
            for i in range(nd):
                acc += phi[i] * coeffs[dofs[c, i] * bs + b]
            out[p, b] = acc


@numba.njit(cache=True, inline="always")
def _pull_back_inside(c, x, p, origin, K, tol, xr):  # pragma: no cover
    tdim = K.shape[1]
    gdim = K.shape[2]
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
def relocate_affine_simplex(
    x, cells, xref, origin, K, nodes, coords, v2c_off, v2c_cells, v2c_dirs, nv, max_valence, tol, status
):  # pragma: no cover
    """Update ``cells``/``xref`` of particles at new positions ``x`` (affine simplices).

    Per particle: test the current cell; if the point left it, test the cells around the cell
    vertex closest to the point, ordered by descending ``(x - v) . (centre(K') - v)/|...|``
    (seed paper section 2.4), then the remaining vertex neighbours of the old cell. ``status``
    gets STAYED, NEIGHBOUR or UNRESOLVED (cell == -1 on input, or not found: left for the
    bounding-box fallback; ``cells`` is then unchanged).
    """
    n = x.shape[0]
    tdim = K.shape[1]
    gdim = K.shape[2]
    xr = np.empty(tdim)
    cand = np.empty(max_valence, dtype=np.int32)
    score = np.empty(max_valence)
    for p in range(n):
        c = cells[p]
        if c < 0:
            status[p] = UNRESOLVED
            continue
        if _pull_back_inside(c, x, p, origin, K, tol, xr):
            for i in range(tdim):
                xref[p, i] = xr[i]
            status[p] = STAYED
            continue
        best = nodes[c, 0]
        bd = np.inf
        for k in range(nv):
            v = nodes[c, k]
            d = 0.0
            for j in range(gdim):
                t = x[p, j] - coords[v, j]
                d += t * t
            if d < bd:
                bd = d
                best = v
        m = 0
        for e in range(v2c_off[best], v2c_off[best + 1]):
            cc = v2c_cells[e]
            if cc == c:
                continue
            sc = 0.0
            for j in range(gdim):
                sc += (x[p, j] - coords[best, j]) * v2c_dirs[e, j]
            i = m
            while i > 0 and score[i - 1] < sc:
                score[i] = score[i - 1]
                cand[i] = cand[i - 1]
                i -= 1
            score[i] = sc
            cand[i] = cc
            m += 1
        found = -1
        for i in range(m):
            if _pull_back_inside(cand[i], x, p, origin, K, tol, xr):
                found = cand[i]
                break
        if found < 0:
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
                    if _pull_back_inside(cc, x, p, origin, K, tol, xr):
                        found = cc
                        break
                if found >= 0:
                    break
        if found >= 0:
            cells[p] = found
            for i in range(tdim):
                xref[p, i] = xr[i]
            status[p] = NEIGHBOUR
        else:
            status[p] = UNRESOLVED
