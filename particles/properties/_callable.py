"""Evaluation of a user-given source (Python callable of x, or a mesh Function) at particles, and the
common base of the properties that store such a source's value under a label."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from collections.abc import Callable
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt

import dolfinx.fem

from fembase.params import param
from particles.generation.base import text_function
from particles.properties._base import ParticleProperty, PropertyBuildContext, PropertyContext, evaluate_at, write_rows
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


class SourceValue(ParticleProperty):
    """Value of a user source at the particle, stored as swarm property ``label``; by default set
    at creation only, and evaluated at the position of a particle added later. A text source (a
    config expression) is made a function by the build context.

    Class attributes:
        source_field: Name of the field of the subclass's ``Settings`` that holds the source.
    """

    source_field: ClassVar[str] = "source"
    default_update: ClassVar[str] = "never"
    default_new_particles: ClassVar[str] = "reinitialise"

    @dataclass(frozen=True, kw_only=True)
    class Settings(ParticleProperty.Settings):
        """A source's value stored under a label."""

        label: str = param(help="Swarm property name.")
        components: int = param(1, help="Columns produced by a callable (a Function's value size is used "
                                        "otherwise).")

    settings: Any

    @classmethod
    def build(cls, settings: Any, context: PropertyBuildContext, /) -> SourceValue:
        """The property of ``settings``, a text source made a function by the context."""
        source = text_function(getattr(settings, cls.source_field), context.make_function, cls.name, cls.source_field)
        return cls(dataclasses.replace(settings, **{cls.source_field: source}))

    @property
    def source(self) -> Source:
        """The source (the ``Settings`` field named by :attr:`source_field`)."""
        return getattr(self.settings, self.source_field)

    @property
    def column(self) -> str:
        return self.settings.label

    def size(self, gdim: int) -> int:
        return source_size(self.source, self.settings.components)

    def initialise(self, swarm: Swarm, rows: npt.NDArray[np.integer], context: PropertyContext) -> None:
        values = evaluate_source(self.source, swarm, rows, self.size(swarm.gdim), context, self.settings.label)
        write_rows(swarm, self.column, rows, values)
