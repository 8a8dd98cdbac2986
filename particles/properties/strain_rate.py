"""``strain_rate``: symmetric velocity gradient at the particle (gdim*gdim columns, row-major)."""

from __future__ import annotations

from typing import ClassVar

import numpy as np
import numpy.typing as npt

from particles.properties._base import ParticleProperty, PropertyContext, gradient_at, write_rows
from particles.properties._tensor import strain_rate
from particles.storage.swarm import Swarm

__all__ = ["StrainRate"]


class StrainRate(ParticleProperty):
    """``eps = (grad u + grad u^T) / 2`` of the current velocity at the particle; column
    ``i * gdim + j`` holds ``eps_ij``."""

    name: ClassVar[str] = "strain_rate"
    description: ClassVar[str] = "symmetric gradient of the velocity (gdim*gdim columns, row-major)"
    default_update: ClassVar[str] = "every_step"
    default_new_particles: ClassVar[str] = "reinitialise"

    def size(self, gdim: int) -> int:
        return gdim * gdim

    def initialise(self, swarm: Swarm, rows: npt.NDArray[np.integer], context: PropertyContext) -> None:
        u = context.require("velocity", self.name)
        grad = gradient_at(swarm, rows, u, context)
        if grad.shape[1] != swarm.gdim:
            raise ValueError(f"property {self.name!r}: the velocity must have gdim components")
        write_rows(swarm, self.column, rows, strain_rate(grad).reshape(-1, swarm.gdim * swarm.gdim))
