"""``deformation_gradient``: ``F`` with ``dF/dt = grad(u) F``, ``F(0) = I`` (gdim*gdim columns)."""

from __future__ import annotations

from typing import ClassVar

import numpy as np
import numpy.typing as npt

from particles.properties._base import ParticleProperty, PropertyContext, write_rows
from particles.storage.swarm import Swarm

__all__ = ["DeformationGradient"]


class DeformationGradient(ParticleProperty):
    """The deformation gradient ``F = dx/dX`` of the flow map, integrated along the path with the
    positions' Runge-Kutta scheme; column ``i * gdim + j`` holds ``F_ij``."""

    name: ClassVar[str] = "deformation_gradient"
    description: ClassVar[str] = "deformation gradient, dF/dt = grad(u) F, F(0) = I (gdim*gdim columns)"
    default_new_particles: ClassVar[str] = "interpolate"
    integrated: ClassVar[bool] = True

    def size(self, gdim: int) -> int:
        return gdim * gdim

    def initialise(self, swarm: Swarm, rows: npt.NDArray[np.integer], context: PropertyContext) -> None:
        write_rows(swarm, self.column, rows, np.eye(swarm.gdim).reshape(-1))

    def rhs(
        self, swarm: Swarm, c: float, y: npt.NDArray[np.float64], grad_u: npt.NDArray[np.float64]
    ) -> npt.NDArray[np.float64]:
        g = swarm.gdim
        return np.einsum("nij,njk->nik", grad_u, y.reshape(-1, g, g)).reshape(-1, g * g)
