"""Field and particle output in the units a model in physical units chose (``scaling.units``).

The solver's fields are nondimensional (:mod:`convection.physics.scaling`). A run with a
``scaling`` writes its field output (``fields.xdmf``) and its particle output (``particles.xdmf``)
converted, so that ParaView shows kilometres, centimetres per year, pascal seconds and kelvin:

- coordinates and particle positions: ``x = L x'`` in ``units.length``;
- times: ``t = t0 t'`` (``t0 = L^2 / kappa``) in ``units.time``;
- each field by its kind (:data:`convection.physics.scaling.FIELD_KINDS`): the velocity in
  ``units.velocity``, the pressure and ``stress_II`` in ``units.stress``, the viscosity in ``units.viscosity``,
  ``strain_rate_II`` and the rates in ``units.strain_rate``, the temperature as a value ``T0 + dT T'`` in
  ``units.temperature``;
- the density, ``rho = rho0 + rho' eta0 kappa / (g L^3)`` in ``units.density``, where ``rho' =
  sum_i Rb_i C_i - Ra T`` is the field's nondimensional density anomaly (the buoyancy numbers are
  ``Rb = Delta rho g L^3 / (eta0 kappa)``);
- material fractions, the material index, strains: as they are (dimensionless).

``fields_units.json`` (and ``particles_units.json``) beside the output name the units of the
time, the coordinates and every field. A run without a ``scaling`` writes nondimensional output
and no such file.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from collections.abc import Iterable, Mapping

import numpy as np

from convection.physics.scaling import FIELD_KINDS, Scaling
from fembase.files import atomic_write_text

__all__ = ["Conversion", "OutputUnits", "output_units"]

@dataclass(frozen=True)
class Conversion:
    """``value = factor * value' + offset`` in the unit ``label``."""

    factor: float = 1.0
    offset: float = 0.0
    label: str = "1"

    def apply(self, values: np.ndarray, /) -> None:
        """Convert ``values`` in place (any shape)."""
        if self.factor != 1.0:
            values *= self.factor
        if self.offset != 0.0:
            values += self.offset


@dataclass(frozen=True)
class OutputUnits:
    """How one output (fields or particles) is converted.

    Attributes:
        length: Coordinates and positions.
        time: The time values of the series.
        fields: Field (or property) name -> conversion; a name not here is written as it is.
    """

    length: Conversion = Conversion()
    time: Conversion = Conversion()
    fields: Mapping[str, Conversion] = field(default_factory=dict)

    def of(self, name: str, /) -> Conversion | None:
        """The conversion of field ``name``, or None (dimensionless: written as it is)."""
        return self.fields.get(name)

    def write_json(self, path: Path, names: Iterable[str], /) -> None:
        """Write ``{"time": unit, "length": unit, "fields": {name: unit}}`` to ``path`` (one rank)."""
        units = {n: (self.fields[n].label if n in self.fields else "1") for n in names}
        atomic_write_text(path, json.dumps({"time": self.time.label, "length": self.length.label, "fields": units},
                                           indent=1) + "\n")


def output_units(scaling: Scaling, /) -> OutputUnits:
    """The conversions of a scaled model's output (module docstring)."""
    fields: dict[str, Conversion] = {}
    for name, kind in FIELD_KINDS.items():
        if not scaling.converts(kind):
            continue
        if kind in ("temperature", "density_anomaly"):  # affine: value = factor value' + offset
            offset = scaling.dimensional(kind, 0.0)
            fields[name] = Conversion(scaling.dimensional(kind, 1.0) - offset, offset, scaling.unit_label(kind))
        else:
            fields[name] = Conversion(scaling.factor(kind), 0.0, scaling.unit_label(kind))
    return OutputUnits(length=Conversion(scaling.factor("length"), 0.0, scaling.unit_label("length")),
                       time=Conversion(scaling.factor("time"), 0.0, scaling.unit_label("time")), fields=fields)
