"""Evaluation of a user-given source (Python callable of x, or a mesh Function) at particles, and the
common base of the properties that store such a source's value under a label."""

from __future__ import annotations

from dataclasses import dataclass
from collections.abc import Callable
from typing import ClassVar

import numpy as np
import numpy.typing as npt

import dolfinx.fem

from fembase.params import param
from particles.properties._base import ParticleProperty, PropertyContext, evaluate_at, write_rows
from particles.storage.swarm import Swarm

__all__ = ["PointFunction", "Source", "SourceValue", "evaluate_source", "source_size"]

PointFunction = Callable[[npt.NDArray[np.float64]], npt.ArrayLike]
"""``f(x)``: points shape=(m, gdim), float64 -> values shape=(m,) or (m, components)."""

Source = PointFunction | dolfinx.fem.Function


def source_size(source: Source, components: int) -> int:
    """Columns produced by ``source``: the Function's value size, else ``components``."""
    if isinstance(source, dolfinx.fem.Function):
        return int(source.function_space.dofmap.index_map_bs)
    return components


def evaluate_source(
    source: Source, swarm: Swarm, rows: npt.NDArray[np.integer], size: int, context: PropertyContext, who: str
) -> npt.NDArray[np.float64]:
    """Values of ``source`` at the particles ``rows``, shape=(m, size)."""
    if isinstance(source, dolfinx.fem.Function):
        return evaluate_at(swarm, rows, source, context)
    m = int(np.asarray(rows).shape[0])
    values = np.asarray(source(np.ascontiguousarray(swarm.x[rows])), dtype=np.float64)
    if values.size != m * size:
        raise ValueError(f"property {who!r}: the callable returned shape {values.shape} for {m} points, "
                         f"expected ({m},) or ({m}, {size})")
    return values.reshape(m, size)


@dataclass(frozen=True, kw_only=True)
class SourceValue(ParticleProperty):
    """Value of a user source at the particle, stored as swarm property ``label``; by default set
    at creation only, and evaluated at the position of a particle added later.

    Class attributes:
        source_field: Name of the subclass's dataclass field that holds the source.
    """

    source_field: ClassVar[str] = "source"
    default_update: ClassVar[str] = "never"
    default_new_particles: ClassVar[str] = "reinitialise"

    label: str = param(help="Swarm property name.")
    components: int = param(1, help="Columns produced by a callable (a Function's value size is used otherwise).")

    @property
    def column(self) -> str:
        return self.label

    def size(self, gdim: int) -> int:
        return source_size(getattr(self, self.source_field), self.components)

    def initialise(self, swarm: Swarm, rows: npt.NDArray[np.integer], context: PropertyContext) -> None:
        values = evaluate_source(getattr(self, self.source_field), swarm, rows, self.size(swarm.gdim), context,
                                 self.label)
        write_rows(swarm, self.column, rows, values)
