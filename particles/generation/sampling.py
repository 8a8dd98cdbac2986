"""Uniform reference-cell sampling and cell weights (integrals of a density) of owned cells."""

from __future__ import annotations

import basix
import numpy as np
import numpy.typing as npt

from particles.generation.base import Density, evaluate_density
from particles.generation.maps import CellMaps

__all__ = ["cell_weights", "uniform_reference_points"]

_SIMPLEX = (basix.CellType.interval, basix.CellType.triangle, basix.CellType.tetrahedron)


def uniform_reference_points(cell: basix.CellType, u: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """Map uniforms ``u`` in [0, 1)^tdim (shape=(p, tdim)) to uniform points of the reference cell.

    Simplices use the spacings of the sorted uniforms (uniform barycentric coordinates);
    hypercubes use ``u`` itself.
    """
    if cell not in _SIMPLEX:
        return u.copy()
    s = np.sort(u, axis=1)
    bary = np.diff(np.concatenate([np.zeros((u.shape[0], 1)), s], axis=1), axis=1)
    return bary


def cell_weights(maps: CellMaps, density: Density | None, degree: int) -> npt.NDArray[np.float64]:
    """Integral of ``density`` (1 if None) over each owned cell by quadrature, shape=(m,), float64."""
    m = maps.cells.shape[0]
    idx = np.arange(m)
    if density is None and maps.affine:
        return maps.abs_det(idx, np.zeros((m, maps.tdim))) * maps.reference_volume
    points, weights = basix.make_quadrature(maps.basix_cell, degree)
    total = np.zeros(m)
    for q in range(weights.shape[0]):
        xhat = np.repeat(points[q : q + 1], m, axis=0)
        value = weights[q] * maps.abs_det(idx, xhat)
        if density is not None:
            value = value * evaluate_density(density, maps.push(idx, xhat))
        total += value
    return total
