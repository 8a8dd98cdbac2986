"""Linear least squares per cell into DG1, with an optional bound-preserving limiter.

For each owned cell ``K`` the linear function ``f(x) = a + c . (x - x_K) / h_K`` (``x_K`` the
vertex centre, ``h_K`` the diameter; scaled for conditioning) minimising ``sum_p (f(x_p) - v_p)^2``
over the particles of ``K`` is found from the normal equations and evaluated at the DG1 dof points.
A linear field is reproduced exactly (to round-off) in every cell with at least ``gdim + 1``
particles in general position.

Fallbacks, in order, for a cell whose own particles do not determine a linear fit (fewer than
``gdim + 1`` or a normal matrix with reciprocal condition number below ``rcond``):

1. ``use_neighbours=True``: the fit over the particles of the cell *and* its vertex-neighbour
   cells, including other ranks' cells through the ghost layer of :mod:`particles.parallel.ghosts`;
2. the constant average of the cell's own particles, or, if it has none, of the particles of its
   neighbourhood (``use_neighbours=True``);
3. nothing in reach: the empty-cell rule of :mod:`particles.interpolation.fill`.

Limiter (``limit=True``): the fitted values are kept within ``[min, max]`` of the particle values
used in the fit by clipping the value at ``x_K`` into that range and scaling the slope by the
largest ``alpha`` in [0, 1] that keeps every dof value in range (Barth-Jespersen style).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import numpy.typing as npt

import dolfinx.fem

from fembase.params import param
from fembase.registry import Configured
from particles.interpolation._base import (
    InterpolationStats,
    Samples,
    TargetSpace,
    gather_samples,
    write_with_cell_means,
)
from particles.interpolation._cell_kernels import least_squares_moments
from particles.interpolation.distance_weighted import cell_diameters
from particles.storage.swarm import Swarm

__all__ = ["LeastSquares", "fit_target"]


class _Fit:
    """Moments and solution of the normal equations for a set of cells."""

    def __init__(self, samples: Samples, cells: npt.NDArray[np.int32], use_nb: bool, centres: npt.NDArray[np.float64],
                 h: npt.NDArray[np.float64], rcond: float) -> None:
        m, d1 = cells.shape[0], samples.x.shape[1] + 1
        self.A = np.zeros((m, d1, d1))
        self.b = np.zeros((m, d1))
        self.count = np.zeros(m, dtype=np.int64)
        self.vmin = np.full(m, np.inf)
        self.vmax = np.full(m, -np.inf)
        self.vsum = np.zeros(m)
        ex = samples.exchange
        nb_off = ex.neighbour_offsets if ex is not None else np.zeros(samples.num_owned_cells + 1, dtype=np.int64)
        nb_cells = ex.neighbour_cells if ex is not None else np.zeros(0, dtype=np.int32)
        least_squares_moments(cells, samples.offsets, np.ascontiguousarray(samples.x), samples.values, nb_off,
                              nb_cells, use_nb, centres, h, self.A, self.b, self.count, self.vmin, self.vmax, self.vsum)
        self.ok = self.count >= d1
        if np.any(self.ok):
            eig = np.linalg.eigvalsh(self.A[self.ok])
            self.ok[self.ok] = eig[:, 0] > rcond * eig[:, -1]
        self.coef = np.zeros((m, d1))
        if np.any(self.ok):
            self.coef[self.ok] = np.linalg.solve(self.A[self.ok], self.b[self.ok][:, :, None])[:, :, 0]


class LeastSquares(Configured):
    """Linear least-squares fit per cell into a DG1 target, as its settings say."""

    name: ClassVar[str] = "least_squares"
    discontinuous: ClassVar[bool] = True
    description: ClassVar[str] = "linear least-squares fit per cell into DG1, optional bound-preserving limiter"
    target_degree: ClassVar[int | None] = 1

    @dataclass(frozen=True)
    class Settings:
        """Linear least-squares fit per cell into a DG1 target."""

        limit: bool = param(False, help="Keep the values within the range of the particle values used (slope "
                                        "limiter).")
        use_neighbours: bool = param(True, help="Use vertex-neighbour cells' particles for cells that cannot be "
                                                "fitted alone (collective ghost exchange).")
        rcond: float = param(1e-10, help="Smallest accepted reciprocal condition number of the (scaled) normal "
                                         "matrix.")

    settings: Settings

    def interpolate(self, swarm: Swarm, property_name: str, target: dolfinx.fem.Function, /, *,
                    component: int | None = None) -> InterpolationStats:
        """Write the per-cell linear fits of ``property_name`` into ``target`` (collective)."""
        s = self.settings
        space = fit_target(self.name, swarm, target, 1)
        n_owned = swarm.num_owned_cells
        samples = gather_samples(swarm, property_name, component, ghosts=s.use_neighbours)
        geo = swarm.geometry
        centres = np.ascontiguousarray(geo.centres[:n_owned])
        h = cell_diameters(swarm)
        cells = np.arange(n_owned, dtype=np.int32)
        own = _Fit(samples, cells, False, centres, h, s.rcond)
        coef, lo, hi = own.coef, own.vmin, own.vmax
        fitted = own.ok.copy()
        constant = np.where(own.count > 0, own.vsum / np.maximum(own.count, 1), 0.0)
        has = own.count > 0
        if s.use_neighbours:
            need = np.flatnonzero(~own.ok).astype(np.int32)
            nb = _Fit(samples, need, True, centres, h, s.rcond)
            coef[need[nb.ok]] = nb.coef[nb.ok]
            lo[need[nb.ok]], hi[need[nb.ok]] = nb.vmin[nb.ok], nb.vmax[nb.ok]
            fitted[need[nb.ok]] = True
            alone = need[(nb.count > 0) & (own.count[need] == 0)]
            sel = (nb.count > 0) & (own.count[need] == 0)
            constant[alone] = nb.vsum[sel] / nb.count[sel]
            has[alone] = True
        dof_x = space.dof_points()[space.dofs]
        xi = (dof_x - centres[:, None, :]) / h[:, None, None]
        values = coef[:, :1] + np.einsum("kjg,kg->kj", xi, coef[:, 1:])
        if s.limit:
            values = _limit(values, coef[:, 0], lo, hi, fitted)
        values = np.where(fitted[:, None], values, constant[:, None])
        num = np.zeros(space.num_local_dofs)
        den = np.zeros(space.num_local_dofs)
        num[space.dofs] = values
        den[space.dofs] = has[:, None]
        return write_with_cell_means(swarm, space, target, self.name, num=num, den=den,
                                     values=samples.values[: swarm.num_particles], ghost_particles=samples.num_ghosts)


def fit_target(method: str, swarm: Swarm, target: dolfinx.fem.Function, degree: int, /) -> TargetSpace:
    """The target space of a per-cell fit: DG of ``degree``, on a mesh with gdim == tdim (raises
    ValueError naming ``method`` otherwise)."""
    space = TargetSpace(target, swarm.num_owned_cells)
    space.require(method, continuous=False, degree=degree)
    if swarm.gdim != swarm.tdim:
        raise ValueError(f"{method} needs gdim == tdim")
    return space


def _limit(values: npt.NDArray[np.float64], centre: npt.NDArray[np.float64], lo: npt.NDArray[np.float64],
           hi: npt.NDArray[np.float64], fitted: npt.NDArray[np.bool_]) -> npt.NDArray[np.float64]:
    """Clip the centre value into [lo, hi] and scale the slope so every dof value is in range."""
    lo_ = np.where(fitted, lo, 0.0)[:, None]
    hi_ = np.where(fitted, hi, 0.0)[:, None]
    c = np.clip(np.where(fitted, centre, 0.0)[:, None], lo_, hi_)
    dev = values - c
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(dev > 0, (hi_ - c) / dev, np.where(dev < 0, (lo_ - c) / dev, 1.0))
    alpha = np.clip(ratio.min(axis=1, initial=1.0), 0.0, 1.0)[:, None]
    return np.clip(c + alpha * dev, lo_, hi_)
