"""``initial_composition``: a named composition (material fraction, ...) set once at creation."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import numpy.typing as npt

from particles.properties._base import ParticleProperty, PropertyContext, write_rows
from particles.properties._callable import Source, evaluate_source, source_size
from particles.swarm import Swarm

__all__ = ["InitialComposition"]


@dataclass(frozen=True, kw_only=True)
class InitialComposition(ParticleProperty):
    """Initial value of a composition field, from a callable of x or a mesh Function.

    Attributes:
        label: Swarm property name (one per material, e.g. ``"basalt"``).
        source: ``f(x)`` (x shape=(m, gdim) -> shape=(m,) or (m, components)) or a Function on the
            swarm's mesh (evaluated from the particle's cell and reference position).
        components: Columns produced by a callable (a Function's value size is used otherwise).
    """

    name: ClassVar[str] = "initial_composition"
    description: ClassVar[str] = "named composition from a callable of x or a mesh Function, set at creation"
    default_update: ClassVar[str] = "never"
    default_new_particles: ClassVar[str] = "interpolate"

    source: Source
    label: str = "composition"
    components: int = 1

    @property
    def column(self) -> str:
        return self.label

    def size(self, gdim: int) -> int:
        return source_size(self.source, self.components)

    def initialise(self, swarm: Swarm, rows: npt.NDArray[np.integer], context: PropertyContext) -> None:
        size = self.size(swarm.gdim)
        write_rows(swarm, self.column, rows, evaluate_source(self.source, swarm, rows, size, context, self.label))
