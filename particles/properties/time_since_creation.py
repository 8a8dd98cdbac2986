"""``time_since_creation``: the particle's age."""

from __future__ import annotations

from typing import ClassVar

import numpy as np
import numpy.typing as npt

from particles.properties._base import ParticleProperty, PropertyContext, write_rows
from particles.storage.swarm import Swarm

__all__ = ["TimeSinceCreation"]


class TimeSinceCreation(ParticleProperty):
    """Age: 0 at creation, increased by ``context.dt`` at each update (call the manager's update
    once per time step)."""

    name: ClassVar[str] = "time_since_creation"
    description: ClassVar[str] = "age of the particle (0 at creation, + dt per step)"
    default_update: ClassVar[str] = "every_step"
    default_new_particles: ClassVar[str] = "reinitialise"

    def initialise(self, swarm: Swarm, rows: npt.NDArray[np.integer], context: PropertyContext) -> None:
        write_rows(swarm, self.column, rows, 0.0)

    def refresh(self, swarm: Swarm, context: PropertyContext) -> None:
        swarm.properties[:, swarm.layout(self.column).start] += context.dt
