"""Small tensor helpers shared by the strain-type properties."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

__all__ = ["strain_rate", "strain_rate_invariant"]


def strain_rate(grad_u: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """Symmetric gradient ``eps = (L + L^T) / 2`` of ``L = grad u``, shape=(n, gdim, gdim)."""
    return 0.5 * (grad_u + np.swapaxes(grad_u, 1, 2))


def strain_rate_invariant(grad_u: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """Second invariant ``sqrt(eps:eps / 2)`` of the strain rate of ``L = grad u``, shape=(n,)."""
    eps = strain_rate(grad_u)
    return np.sqrt(0.5 * np.einsum("nij,nij->n", eps, eps))
