"""Common base of the properties that sample a field of the context (velocity, temperature, ...)."""

from __future__ import annotations

from typing import ClassVar

import numpy as np
import numpy.typing as npt

from particles.properties._base import ParticleProperty, PropertyContext, evaluate_at, write_rows
from particles.storage.swarm import Swarm

__all__ = ["FieldValue"]


class FieldValue(ParticleProperty):
    """Value of the context field ``context_field`` at the particle, from its stored cell and xref."""

    context_field: ClassVar[str] = ""
    default_update: ClassVar[str] = "every_step"
    default_new_particles: ClassVar[str] = "reinitialise"

    def size(self, gdim: int) -> int:
        return gdim if self.context_field == "velocity" else 1

    def initialise(self, swarm: Swarm, rows: npt.NDArray[np.integer], context: PropertyContext) -> None:
        u = context.require(self.context_field, self.name)
        values = evaluate_at(swarm, rows, u, context)
        if values.shape[1] != self.size(swarm.gdim):
            raise ValueError(f"property {self.name!r}: the {self.context_field} has {values.shape[1]} components, "
                             f"expected {self.size(swarm.gdim)}")
        write_rows(swarm, self.column, rows, values)
