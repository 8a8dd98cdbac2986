"""Titles and labels of the pictures in the output's units (:func:`convection.io.pictures.run_files.field_units`)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Mapping

__all__ = ["Labels", "time_label"]


def time_label(t: float) -> str:
    return f"{t:.6g}"


@dataclass(frozen=True)
class Labels:
    """Titles in the output's units (:func:`field_units`; none: the solver's numbers)."""

    units: Mapping[str, Any] = field(default_factory=dict)

    def time(self, t: float) -> str:
        unit = self.units.get("time")
        return f"{t:.6g} {unit}" if unit else f"{t:.6g}"

    def of(self, name: str) -> str:
        unit = (self.units.get("fields") or {}).get(name)
        return f"{name} [{unit}]" if unit and unit != "1" else name
