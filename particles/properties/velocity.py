"""``velocity``: the velocity Function at the particle, updated every step."""

from __future__ import annotations

from typing import ClassVar

from particles.properties._field import FieldValue

__all__ = ["Velocity"]


class Velocity(FieldValue):
    """The context's velocity evaluated at the particle (from its cell and reference position)."""

    name: ClassVar[str] = "velocity"
    description: ClassVar[str] = "velocity Function at the particle (gdim columns)"
    context_field: ClassVar[str] = "velocity"
