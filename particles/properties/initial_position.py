"""``initial_position``: where the particle was created (gdim columns, never updated)."""

from __future__ import annotations

from typing import ClassVar

import numpy as np
import numpy.typing as npt

from particles.properties._base import ParticleProperty, PropertyContext, write_rows
from particles.storage.swarm import Swarm

__all__ = ["InitialPosition"]


class InitialPosition(ParticleProperty):
    """The particle's position at creation. Particles added later take the mean initial position
    of the other particles in their cell by default (the material they stand for came from there)."""

    name: ClassVar[str] = "initial_position"
    description: ClassVar[str] = "position at creation (gdim columns)"
    default_update: ClassVar[str] = "never"
    default_new_particles: ClassVar[str] = "interpolate"

    def size(self, gdim: int) -> int:
        return gdim

    def initialise(self, swarm: Swarm, rows: npt.NDArray[np.integer], context: PropertyContext) -> None:
        write_rows(swarm, self.column, rows, swarm.x[rows])
