"""Numba kernels of the interpolators: one compiled loop over owned cells each.

Particles are given as CSR over the owned + halo cell index space (``offsets``), cell
neighbourhoods as CSR over owned cells (``nb_offsets``, ``nb_cells``) into the same index space.
"""

from __future__ import annotations

import numba
import numpy as np

__all__ = ["idw_accumulate", "least_squares_moments", "nearest_values"]


@numba.njit(cache=True)
def nearest_values(dof_points, dofs, offsets, x, values, ids, out, has):  # pragma: no cover - compiled
    """Value of the particle nearest to each dof point of each owned cell (ties: smallest id).

    Writes ``out[dofs[K, j]]`` and sets ``has[dofs[K, j]] = 1`` where cell ``K`` has particles.
    """
    ncells, ndpc = dofs.shape
    gdim = x.shape[1]
    for k in range(ncells):
        start, end = offsets[k], offsets[k + 1]
        if end == start:
            continue
        for j in range(ndpc):
            d = dofs[k, j]
            best = -1
            best_d2 = np.inf
            for p in range(start, end):
                d2 = 0.0
                for g in range(gdim):
                    t = x[p, g] - dof_points[d, g]
                    d2 += t * t
                if d2 < best_d2 or (d2 == best_d2 and ids[p] < ids[best]):
                    best_d2 = d2
                    best = p
            out[d] = values[best]
            has[d] = 1.0


@numba.njit(cache=True)
def idw_accumulate(dof_points, dofs, offsets, x, values, nb_offsets, nb_cells, use_nb, power, floor,
                   num, den):  # pragma: no cover - compiled
    """Add inverse-distance weights ``w = max(|y_d - x_p|, floor_K)**-power`` of the particles in reach.

    The reach of owned cell ``K`` is its own particles, plus those of its neighbour cells if
    ``use_nb``. ``num[d] += sum w v``, ``den[d] += sum w`` for every dof ``d`` of ``K``.
    """
    ncells, ndpc = dofs.shape
    gdim = x.shape[1]
    for k in range(ncells):
        n_extra = nb_offsets[k + 1] - nb_offsets[k] if use_nb else 0
        for j in range(ndpc):
            d = dofs[k, j]
            for c_i in range(n_extra + 1):
                c = k if c_i == 0 else nb_cells[nb_offsets[k] + c_i - 1]
                for p in range(offsets[c], offsets[c + 1]):
                    d2 = 0.0
                    for g in range(gdim):
                        t = x[p, g] - dof_points[d, g]
                        d2 += t * t
                    r = max(np.sqrt(d2), floor[k])
                    w = r ** (-power)
                    num[d] += w * values[p]
                    den[d] += w


@numba.njit(cache=True)
def least_squares_moments(cells, offsets, x, values, nb_offsets, nb_cells, use_nb, centres, h,
                          A, b, count, vmin, vmax, vsum):  # pragma: no cover - compiled
    """Normal equations of the fit ``v = a + c . (x - centre_K) / h_K`` over the reach of each cell.

    For each ``i``, cell ``K = cells[i]``: ``A[i] = sum q q^T``, ``b[i] = sum q v`` with
    ``q = (1, (x_p - centre_K) / h_K)``, plus the count, min, max and sum of the values.
    """
    gdim = x.shape[1]
    for i in range(cells.shape[0]):
        k = cells[i]
        n_extra = nb_offsets[k + 1] - nb_offsets[k] if use_nb else 0
        q = np.empty(gdim + 1)
        q[0] = 1.0
        lo = np.inf
        hi = -np.inf
        for c_i in range(n_extra + 1):
            c = k if c_i == 0 else nb_cells[nb_offsets[k] + c_i - 1]
            for p in range(offsets[c], offsets[c + 1]):
                for g in range(gdim):
                    q[g + 1] = (x[p, g] - centres[k, g]) / h[k]
                v = values[p]
                for a in range(gdim + 1):
                    b[i, a] += q[a] * v
                    for e in range(gdim + 1):
                        A[i, a, e] += q[a] * q[e]
                count[i] += 1
                vsum[i] += v
                lo = min(lo, v)
                hi = max(hi, v)
        vmin[i] = lo
        vmax[i] = hi
