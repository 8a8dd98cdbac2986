"""``function``: any Python callable of the position."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import numpy.typing as npt

from particles.properties._base import ParticleProperty, PropertyContext, write_rows
from particles.properties._callable import PointFunction, evaluate_source
from particles.swarm import Swarm

__all__ = ["FunctionProperty"]


@dataclass(frozen=True, kw_only=True)
class FunctionProperty(ParticleProperty):
    """Values of a callable ``f(x)`` at the particle (at creation; at the current position when
    updated, if the update policy says so).

    Attributes:
        function: ``f(x)``, x shape=(m, gdim) -> shape=(m,) or (m, components).
        label: Swarm property name.
        components: Number of columns.
    """

    name: ClassVar[str] = "function"
    description: ClassVar[str] = "any Python callable of the position"
    default_update: ClassVar[str] = "never"
    default_new_particles: ClassVar[str] = "reinitialise"

    function: PointFunction
    label: str = "function"
    components: int = 1

    @property
    def column(self) -> str:
        return self.label

    def size(self, gdim: int) -> int:
        return self.components

    def initialise(self, swarm: Swarm, rows: npt.NDArray[np.integer], context: PropertyContext) -> None:
        write_rows(swarm, self.column, rows,
                   evaluate_source(self.function, swarm, rows, self.components, context, self.label))
