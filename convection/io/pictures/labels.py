"""Titles, axis labels and tick numbers of the pictures, in the output's units
(:func:`convection.io.pictures.run_files.field_units`; a nondimensional run: the solver's numbers).

Ticks are plain numbers (``1573``, ``0.25``), never an offset (``+1.5e3``) or a power of ten
printed apart from the axis: where the numbers are very large or very small, the power goes into
the label instead (``pressure [MPa] (×10^3)``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, NamedTuple
from collections.abc import Mapping

if TYPE_CHECKING:
    from matplotlib.axis import Axis
    from matplotlib.ticker import Formatter

__all__ = ["Labels", "TickScale", "nice_ticks", "plain_ticks", "pyvista_format", "round_bar_labels", "tick_scale",
           "time_label"]

_PLAIN = (1e-3, 1e5)
"""Numbers whose largest magnitude lies in this range are printed as they are."""


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

    @property
    def length(self) -> str | None:
        """The unit of the coordinates (e.g. ``km``), None for nondimensional output."""
        unit = self.units.get("length")
        return str(unit) if unit else None

    def axis(self, name: str) -> str:
        """The label of coordinate ``name`` (``x``, ``y``, ``z``; a 2D model's vertical coordinate is
        ``z``, as in its config): ``x [km]``, or ``x``."""
        return f"{name} [{self.length}]" if self.length else name


class TickScale(NamedTuple):
    """Ticks shown as ``value / 10**power``, the label saying so (``power`` 0: as they are)."""

    power: int

    def label(self, label: str) -> str:
        return label if self.power == 0 else f"{label} (×$10^{{{self.power}}}$)"


def tick_scale(lo: float, hi: float) -> TickScale:
    """The scale of ticks between ``lo`` and ``hi``: a power of ten in steps of three when the
    largest magnitude is outside [1e-3, 1e5) (``2.5e9`` is ticked ``2.5`` with ×10^9 in the label)."""
    top = max(abs(lo), abs(hi))
    if top == 0.0 or not math.isfinite(top) or _PLAIN[0] <= top < _PLAIN[1]:
        return TickScale(0)
    return TickScale(3 * math.floor(math.log10(top) / 3))


def _formatter(scale: TickScale) -> Formatter:
    from matplotlib.ticker import FuncFormatter, ScalarFormatter

    if scale.power == 0:
        formatter = ScalarFormatter(useOffset=False)
        formatter.set_scientific(False)
        return formatter
    factor = 10.0 ** scale.power
    return FuncFormatter(lambda value, _: f"{value / factor:.6g}")


def plain_ticks(axis: Axis, lo: float, hi: float, label: str) -> str:
    """Give the matplotlib ``axis`` plain tick numbers for values from ``lo`` to ``hi``; returns
    ``label`` with the power of ten the ticks leave out, if any."""
    scale = tick_scale(lo, hi)
    axis.set_major_formatter(_formatter(scale))
    return scale.label(label)


def pyvista_format(lo: float, hi: float, labels: int) -> str:
    """A printf format of plain numbers for ``labels`` evenly spaced labels from ``lo`` to ``hi``
    (pyvista's scalar bars and axes): as few decimals as print them exactly (``%.0f`` for 273..1573
    K in 6 labels, ``%.1f`` for 0..1 in 6), at most those of three significant digits of their
    spacing; ``%.3g`` where the numbers are very large or very small."""
    if tick_scale(lo, hi).power != 0:
        return "%.3g"
    step = abs(hi - lo) / max(labels - 1, 1)
    if step == 0.0:
        return "%.0f"
    most = max(0, 2 - math.floor(math.log10(step)))
    exact = [d for d in range(most + 1) if max(abs(round(lo, d) - lo), abs(round(step, d) - step)) <= 1e-9 * step]
    return f"%.{exact[0] if exact else most}f"


def nice_ticks(lo: float, hi: float, most: int = 6) -> list[float]:
    """At most ``most`` round tick values between ``lo`` and ``hi`` (both included where round):
    ``0, 0.2, ..., 1`` for -0.079..1 (matplotlib's MaxNLocator)."""
    from matplotlib.ticker import MaxNLocator

    span = abs(hi - lo)
    values = MaxNLocator(most - 1).tick_values(lo, hi)
    return [float(v) for v in values if lo - 1e-9 * span <= v <= hi + 1e-9 * span]


def round_bar_labels(bar: Any, limits: tuple[float, float]) -> None:
    """Label the VTK scalar bar ``bar`` (a pyvista plotter's ``scalar_bars[title]``) at round values
    of its range ``limits`` (0, 0.25, ..., 1 for -0.079..1), printed plainly."""
    from vtkmodules.vtkCommonCore import vtkDoubleArray

    ticks = nice_ticks(*limits)
    values = vtkDoubleArray()
    for value in ticks:
        values.InsertNextValue(value)
    bar.SetUseCustomLabels(True)
    bar.SetCustomLabels(values)
    bar.SetLabelFormat(pyvista_format(ticks[0], ticks[-1], len(ticks)) if len(ticks) > 1 else "%.3g")
