"""``initial_composition``: a named composition (material fraction, ...) set once at creation."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from fembase.params import param
from particles.properties._callable import Source, SourceValue

__all__ = ["InitialComposition"]


class InitialComposition(SourceValue):
    """Initial value of a composition field, from a callable of x or a mesh Function."""

    name: ClassVar[str] = "initial_composition"
    description: ClassVar[str] = "named composition from a callable of x or a mesh Function, set at creation"
    default_new_particles: ClassVar[str] = "interpolate"

    @dataclass(frozen=True, kw_only=True)
    class Settings(SourceValue.Settings):
        """A composition's source and label."""

        source: Source | str = param(help="`f(x)` (x shape=(m, gdim) -> shape=(m,) or (m, components)) or a "
                                          "Function on the swarm's mesh (evaluated from the particle's cell and "
                                          "reference position).")
        label: str = param("composition", help='Swarm property name (one per material, e.g. `"basalt"`).')
