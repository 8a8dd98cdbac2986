"""``displacement``: how far the particle is from where it started, ``|x - x0|``."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import numpy.typing as npt

from fembase.params import param
from particles.properties._base import ParticleProperty, PropertyContext, write_rows
from particles.properties.initial_position import InitialPosition
from particles.storage.swarm import Swarm

__all__ = ["Displacement"]


class Displacement(ParticleProperty):
    """Distance between the particle's position and its ``initial_position`` property (the straight
    line from where the material started, not the length of the path), refreshed after every step.
    Needs the ``initial_position`` property on the same particles (list it too). Particles added
    later get the distance to the initial position they were given (by default the mean of their
    cell's), so they carry the history of the material they stand for.
    """

    name: ClassVar[str] = "displacement"
    description: ClassVar[str] = "distance |x - x0| from the initial_position property (needs initial_position)"
    default_update: ClassVar[str] = "every_step"
    default_new_particles: ClassVar[str] = "reinitialise"

    @dataclass(frozen=True, kw_only=True)
    class Settings(ParticleProperty.Settings):
        """Where the start positions are."""

        reference: str = param(InitialPosition.name, help="Swarm property holding the start positions (gdim "
                                                          "columns).")

    settings: Settings

    def requires(self) -> tuple[str, ...]:
        return (self.settings.reference,)

    def _start(self, swarm: Swarm, rows: npt.NDArray[np.integer]) -> npt.NDArray[np.float64]:
        reference = self.settings.reference
        if not swarm.has_property(reference) or swarm.layout(reference).size != swarm.gdim:
            raise ValueError(f"particle property 'displacement' needs the {swarm.gdim}-column property "
                             f"{reference!r} on the same particles; add it to the properties")
        return swarm.property(reference)[rows]

    def initialise(self, swarm: Swarm, rows: npt.NDArray[np.integer], context: PropertyContext) -> None:
        rows = np.asarray(rows, dtype=np.int64)
        write_rows(swarm, self.column, rows, np.linalg.norm(swarm.x[rows] - self._start(swarm, rows), axis=1))

    def refresh(self, swarm: Swarm, context: PropertyContext) -> None:
        rows = np.arange(swarm.num_particles, dtype=np.int64)
        swarm.properties[:, swarm.layout(self.column).start] = np.linalg.norm(
            swarm.x - self._start(swarm, rows), axis=1)
