"""``pressure``: the pressure Function at the particle, updated every step."""

from __future__ import annotations

from typing import ClassVar

from particles.properties._field import FieldValue

__all__ = ["Pressure"]


class Pressure(FieldValue):
    """The context's pressure evaluated at the particle (from its cell and reference position)."""

    name: ClassVar[str] = "pressure"
    description: ClassVar[str] = "pressure Function at the particle"
    context_field: ClassVar[str] = "pressure"
