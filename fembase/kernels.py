"""Numba kernels of finite-element hot paths: P1/P2 simplex evaluation at reference points, the
pull-back of a point into an affine simplex, and point location among candidate cells.

Each kernel is one compiled loop over points (no per-point Python) that only sees flat NumPy
arrays; :mod:`fembase.evaluation` and :mod:`fembase.geometry` prepare them from DOLFINx objects
once per mesh or function space.
"""

from __future__ import annotations

import numba

__all__ = ["evaluate_simplex_p12", "locate_among_candidates", "max_among_candidates", "pull_back_point"]


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

    Rows with ``cells < 0`` (discarded, see :data:`DEAD`) are skipped.
    """
    n = cells.shape[0]
    tdim = xref.shape[1]
    if tdim == 2 and degree == 1:
        for p in range(n):
            c = cells[p]
            if c < 0:
                continue
            X = xref[p, 0]
            Y = xref[p, 1]
            L = 1.0 - X - Y
            d0, d1, d2 = dofs[c, 0] * bs, dofs[c, 1] * bs, dofs[c, 2] * bs
            for b in range(bs):
                v = L * coeffs[d0 + b] + X * coeffs[d1 + b] + Y * coeffs[d2 + b]
                out[p, b] = alpha * v + (beta * out[p, b] if beta != 0.0 else 0.0)
    elif tdim == 2 and bs == 2:
        # The velocity case, with both components written out (a runtime-length loop over the
        # components costs about a third more); same arithmetic as the general branch below.
        for p in range(n):
            c = cells[p]
            if c < 0:
                continue
            X = xref[p, 0]
            Y = xref[p, 1]
            L = 1.0 - X - Y
            f0, f1, f2 = L * (2.0 * L - 1.0), X * (2.0 * X - 1.0), Y * (2.0 * Y - 1.0)
            f3, f4, f5 = 4.0 * X * Y, 4.0 * L * Y, 4.0 * L * X
            d0, d1, d2 = dofs[c, 0] * 2, dofs[c, 1] * 2, dofs[c, 2] * 2
            d3, d4, d5 = dofs[c, 3] * 2, dofs[c, 4] * 2, dofs[c, 5] * 2
            v0 = (f0 * coeffs[d0] + f1 * coeffs[d1] + f2 * coeffs[d2]
                  + f3 * coeffs[d3] + f4 * coeffs[d4] + f5 * coeffs[d5])
            v1 = (f0 * coeffs[d0 + 1] + f1 * coeffs[d1 + 1] + f2 * coeffs[d2 + 1]
                  + f3 * coeffs[d3 + 1] + f4 * coeffs[d4 + 1] + f5 * coeffs[d5 + 1])
            if beta != 0.0:
                out[p, 0] = alpha * v0 + beta * out[p, 0]
                out[p, 1] = alpha * v1 + beta * out[p, 1]
            else:
                out[p, 0] = alpha * v0 + 0.0
                out[p, 1] = alpha * v1 + 0.0
    elif tdim == 2:
        for p in range(n):
            c = cells[p]
            if c < 0:
                continue
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
            if c < 0:
                continue
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
            if c < 0:
                continue
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
def pull_back_point(c, px, py, pz, origin, K, tol):  # pragma: no cover
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
def point_at(x, i):  # pragma: no cover
    """Point ``i`` of ``x`` (shape=(m, 2 or 3)) as three coordinates (z = 0 in 2D)."""
    return x[i, 0], x[i, 1], (x[i, 2] if x.shape[1] == 3 else 0.0)


@numba.njit(cache=True)
def locate_among_candidates(groups, offsets, links, x, origin, K, tol, limit, cells, xref):  # pragma: no cover
    """For each point ``x[i]`` (shape=(m, gdim), affine simplices, gdim == tdim in {2, 3}) the lowest
    cell below ``limit`` among its candidates ``links[offsets[g]:offsets[g+1]]``, ``g = groups[i]``
    (points may share a candidate row), that contains it (-1 if none) into ``cells[i]``, its
    reference coordinates into ``xref[i]``."""
    gdim = x.shape[1]
    for i in range(x.shape[0]):
        px, py, pz = point_at(x, i)
        best = -1
        g = groups[i]
        for j in range(offsets[g], offsets[g + 1]):
            c = links[j]
            if c >= limit or (best >= 0 and c > best):
                continue
            inside, X, Y, Z = pull_back_point(c, px, py, pz, origin, K, tol)
            if inside:
                best = c
                xref[i, 0] = X
                xref[i, 1] = Y
                if gdim == 3:
                    xref[i, 2] = Z
        cells[i] = best


@numba.njit(cache=True)
def max_among_candidates(groups, offsets, links, x, origin, K, tol, values, num_owned, best, hit,
                         ghost):  # pragma: no cover
    """For each point ``x[i]`` (affine simplices, gdim == tdim in {2, 3}): the largest ``values[c]``
    over its candidate cells ``links[offsets[g]:offsets[g+1]]``, ``g = groups[i]``, that contain it
    (into ``best[i]``, left as given where none does), whether any does (``hit[i]``) and whether
    any of those is a ghost, ``c >= num_owned`` (``ghost[i]``)."""
    for i in range(x.shape[0]):
        px, py, pz = point_at(x, i)
        g = groups[i]
        for j in range(offsets[g], offsets[g + 1]):
            c = links[j]
            inside, X, Y, Z = pull_back_point(c, px, py, pz, origin, K, tol)
            if inside:
                if not hit[i] or values[c] > best[i]:
                    best[i] = values[c]
                hit[i] = True
                if c >= num_owned:
                    ghost[i] = True
