"""``function``: any Python callable of the position."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from fembase.params import param
from particles.properties._callable import PointFunction, SourceValue

__all__ = ["FunctionProperty"]


class FunctionProperty(SourceValue):
    """Values of a callable ``f(x)`` at the particle (at creation; at the current position when
    updated, if the update policy says so)."""

    name: ClassVar[str] = "function"
    description: ClassVar[str] = "any Python callable of the position"
    source_field: ClassVar[str] = "function"

    @dataclass(frozen=True, kw_only=True)
    class Settings(SourceValue.Settings):
        """A callable of the position."""

        function: PointFunction | str = param(help="`f(x)`, x shape=(m, gdim) -> shape=(m,) or (m, components).")
        label: str = param("function", help="Swarm property name.")
        components: int = param(1, help="Number of columns.")
