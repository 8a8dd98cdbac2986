"""Quadratic least squares per cell into DG2 (ASPECT's "quadratic least squares").

For each owned cell ``K`` the quadratic ``f(x) = sum_j c_j m_j(xi)``, ``xi = (x - x_K) / h_K``
(``x_K`` the vertex centre, ``h_K`` the diameter; scaled for conditioning) over the monomials
``m_j`` of degree <= 2 (``1, xi, eta, xi^2, xi eta, eta^2`` in 2D: 6; 10 in 3D) minimising
``sum_p (f(x_p) - v_p)^2`` over the particles of ``K`` is found from the normal equations and
evaluated at the DG2 dof points. A quadratic field is reproduced exactly (to round-off) in every
cell with at least as many particles as monomials in general position, so the interpolation
error is third order in the cell size where the particles are dense enough.

A cell whose own particles do not determine a quadratic (fewer than the monomials, or a normal
matrix with reciprocal condition number below ``rcond``) takes the linear least-squares fit
(:class:`particles.interpolation.least_squares.LeastSquares`, with its fallbacks: the
neighbours' particles, the constant average, the empty-cell rule), evaluated at the DG2 points.

Limiter (``limit=True``): every dof value of a quadratic fit is clipped into ``[min, max]`` of the
cell's particle values (the linear fallback uses its own limiter), so no new extrema appear.
"""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import numpy as np
import numpy.typing as npt

import dolfinx.fem

from fembase.dolfinx_compat import function_space
from particles.interpolation._base import InterpolationStats, property_values
from particles.interpolation.distance_weighted import cell_diameters
from particles.interpolation.least_squares import LeastSquares, fit_target
from particles.storage.swarm import Swarm

__all__ = ["QuadraticLeastSquares", "monomials"]


def monomials(xi: npt.NDArray[np.float64], /) -> npt.NDArray[np.float64]:
    """The monomials of degree <= 2 at points ``xi`` (shape=(..., gdim)), shape=(..., n):
    ``1``, the coordinates, then their products ``xi_i xi_j`` for ``i <= j``."""
    gdim = xi.shape[-1]
    columns = [np.ones(xi.shape[:-1]), *(xi[..., i] for i in range(gdim)),
               *(xi[..., i] * xi[..., j] for i in range(gdim) for j in range(i, gdim))]
    return np.stack(columns, axis=-1)


class QuadraticLeastSquares(LeastSquares):
    """Quadratic least-squares fit per cell into a DG2 target (see the module docstring); the
    parameters are :class:`LeastSquares`'s (``limit``: clip to the particles' range;
    ``use_neighbours``: for the linear fallback; ``rcond``: for both fits)."""

    name: ClassVar[str] = "quadratic_least_squares"
    discontinuous: ClassVar[bool] = True
    description: ClassVar[str] = ("quadratic least-squares fit per cell into DG2 (linear least squares where a cell "
                                  "has too few particles), optional limiter")
    target_degree: ClassVar[int | None] = 2

    def interpolate(self, swarm: Swarm, property_name: str, target: dolfinx.fem.Function, /, *,
                    component: int | None = None) -> InterpolationStats:
        """Write the per-cell quadratic fits of ``property_name`` into ``target`` (collective)."""
        s = self.settings
        space = fit_target(self.name, swarm, target, 2)
        # Everywhere first the linear fit with its fallbacks (the statistics are its: which cells
        # had particles in reach), then the quadratic where a cell's own particles determine one.
        linear = dolfinx.fem.Function(function_space(swarm.mesh, "DG", 1))
        stats = LeastSquares(s).interpolate(
            swarm, property_name, linear, component=component)
        target.interpolate(linear)
        n = swarm.num_owned_cells
        cells = np.asarray(swarm.cells, dtype=np.int64)
        values = np.asarray(property_values(swarm, property_name, component), dtype=np.float64)
        centres = np.ascontiguousarray(swarm.geometry.centres[:n])
        h = cell_diameters(swarm)
        phi = monomials((swarm.x - centres[cells]) / h[cells, None])
        nb = phi.shape[1]
        # Fit the departure from the cell's mean (a constant is then reproduced to the last bit).
        counts = np.bincount(cells, minlength=n)
        mean = np.bincount(cells, weights=values, minlength=n) / np.maximum(counts, 1)
        A = np.empty((n, nb, nb))
        for i in range(nb):  # per-cell sums in particle order (np.bincount: np.add.at's sums, faster)
            for j in range(i, nb):
                A[:, i, j] = A[:, j, i] = np.bincount(cells, weights=phi[:, i] * phi[:, j], minlength=n)
        departure = values - mean[cells]
        b = np.stack([np.bincount(cells, weights=phi[:, i] * departure, minlength=n) for i in range(nb)], axis=1)
        ok = counts >= nb
        if np.any(ok):
            eig = np.linalg.eigvalsh(A[ok])
            ok[ok] = eig[:, 0] > s.rcond * eig[:, -1]
        if np.any(ok):
            coef = np.linalg.solve(A[ok], b[ok][:, :, None])[:, :, 0]
            xi = (space.dof_points()[space.dofs[ok]] - centres[ok][:, None, :]) / h[ok][:, None, None]
            fitted = mean[ok][:, None] + np.einsum("kjm,km->kj", monomials(xi), coef)
            if s.limit:
                lo = np.full(n, np.inf)
                hi = np.full(n, -np.inf)
                np.minimum.at(lo, cells, values)
                np.maximum.at(hi, cells, values)
                fitted = np.clip(fitted, lo[ok][:, None], hi[ok][:, None])
            target.x.array[space.dofs[ok]] = fitted
        target.x.scatter_forward()
        return dataclasses.replace(stats, method=self.name)
