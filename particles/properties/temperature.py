"""``temperature``: the temperature Function at the particle, updated every step."""

from __future__ import annotations

from typing import ClassVar

from particles.properties._field import FieldValue

__all__ = ["Temperature"]


class Temperature(FieldValue):
    """The context's temperature evaluated at the particle (from its cell and reference position)."""

    name: ClassVar[str] = "temperature"
    description: ClassVar[str] = "temperature Function at the particle"
    context_field: ClassVar[str] = "temperature"
