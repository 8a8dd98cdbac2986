"""Physical units: the scaling that maps a dimensional model onto the nondimensional one the
solver runs, and the solver's numbers back onto the units a user reads.

The solver runs the nondimensional Boussinesq equations of :mod:`convection.physics.approximation`.
A model written in physical units names its reference scales in the ``scaling`` config section;
they fix four base scales::

    length       L                            scaling.length
    time         t0 = L^2 / kappa             kappa: scaling.diffusivity
    mass         M0 = eta0 L t0               eta0: scaling.viscosity (so the viscosity scale is eta0)
    temperature  dT                           scaling.temperature_difference

and every quantity ``q`` of dimension ``length^a time^b mass^c temperature^d`` is made
nondimensional by its scale: ``q' = q / (L^a t0^b M0^c dT^d)``. So velocities are measured in
``kappa / L``, stresses and pressures in ``eta0 kappa / L^2``, strain rates in ``kappa / L^2``.
A temperature (a value, not a difference) is measured from the reference temperature
``T0`` (scaling.reference_temperature): ``T' = (T - T0) / dT``.

With the reference density ``rho0`` (scaling.density), gravity ``g`` (scaling.gravity) and
thermal expansivity ``alpha`` (scaling.thermal_expansivity), the body force
``(rho0 alpha (T - T0) - sum_i (rho_i - rho0) C_i) g e_up`` (the density's departure from
``rho0``; the hydrostatic part goes into the pressure) becomes the solver's
``(Ra T' - sum_i Rb_i C_i) e_up`` with::

    Ra   = rho0 alpha dT g L^3 / (eta0 kappa)
    Rb_i = (rho_i - rho0) g L^3 / (eta0 kappa)          (material i of density rho_i)

Internal heating given per mass (W/kg) becomes ``H' = H t0 / (c_p dT)`` (c_p:
scaling.heat_capacity); given as a heating rate (K/s) it is scaled as any quantity.

Units are parsed by pint (the field's units library). The registry is made when a scaling is
first used (about 0.3 s), so nondimensional models never load it.
"""

from __future__ import annotations

import functools
import math
import re
from dataclasses import dataclass, field, fields
from collections.abc import Mapping
from typing import Any

from convection.schema import ConfigError, param, short_repr, subsection

__all__ = ["FIELD_KINDS", "UNIT_KINDS", "ColumnUnits", "OutputUnits", "Quantity", "Scaling", "ScalingSettings",
           "parse_quantity", "registry"]

_NUMBER = re.compile(r"^\s*([-+]?(?:[0-9][0-9_]*(?:\.[0-9_]*)?|\.[0-9][0-9_]*)(?:[eE][-+]?[0-9]+)?)\s*(.*?)\s*$")
"""A number followed by a unit text (``3300 kg/m^3``, ``1e21 Pa s``, ``-5 cm/yr``)."""
_BASE = ("[length]", "[time]", "[mass]", "[temperature]")
Quantity = Any
"""A :class:`pint.Quantity` (pint is imported when first needed)."""


@functools.lru_cache(maxsize=1)
def registry() -> Any:
    """The process's pint unit registry (made once, on first use)."""
    import pint

    return pint.UnitRegistry()


def parse_quantity(text: Any) -> Quantity | None:
    """The quantity of a config value written as ``<number> <unit>`` (``"10 Myr"``), or None when
    ``text`` is not such a text (a plain number, a name, an expression, or a unit pint does not
    know; :func:`unit_problem` says why)."""
    if not isinstance(text, str):
        return None
    match = _NUMBER.match(text)
    if match is None or not match.group(2) or not re.match(r"[A-Za-z°µΩ%(]|1\s*/", match.group(2)):
        return None
    try:
        return registry().Quantity(float(match.group(1).replace("_", "")), match.group(2))
    except Exception:  # noqa: BLE001 - pint raises many kinds for text that is not a unit
        return None


def looks_like_quantity(text: Any) -> bool:
    """Whether ``text`` is written as a number followed by a word (a unit or a misspelt one)."""
    if not isinstance(text, str):
        return False
    match = _NUMBER.match(text)
    return bool(match and match.group(2) and re.fullmatch(r"[A-Za-z°µΩ%][A-Za-z0-9_ */^().°µΩ%-]*", match.group(2)))


@dataclass(frozen=True)
class OutputUnits:
    """The ``scaling.units`` config section: the units statistics, progress lines and summaries
    are written in (any unit of the right dimension pint knows)."""

    length: str = param("km", help="lengths and coordinates")
    time: str = param("Myr", help="times")
    velocity: str = param("cm/yr", help="velocities")
    temperature: str = param("K", help="temperatures")
    viscosity: str = param("Pa*s", help="viscosities")
    stress: str = param("MPa", help="stresses and pressures")
    density: str = param("kg/m^3", help="densities")
    area: str = param("km^2", help="areas (a material's volume in 2D)")
    volume: str = param("km^3", help="volumes")
    strain_rate: str = param("1/s", help="strain rates")


UNIT_KINDS: dict[str, str] = {"length": "[length]", "time": "[time]", "velocity": "[length] / [time]",
                              "temperature": "[temperature]", "viscosity": "[mass] / [length] / [time]",
                              "stress": "[mass] / [length] / [time] ** 2", "density": "[mass] / [length] ** 3",
                              "strain_rate": "1 / [time]", "area": "[length] ** 2", "volume": "[length] ** 3"}
"""The kinds of :class:`OutputUnits` and their dimensions."""

FIELD_KINDS: dict[str, str] = {
    "temperature": "temperature", "velocity": "velocity", "pressure": "stress", "stress_II": "stress",
    "viscosity": "viscosity", "strain_rate_II": "strain_rate", "plastic_strain_rate": "strain_rate",
    "strain_rate": "strain_rate", "density": "density_anomaly", "initial_position": "length",
    "displacement": "length", "time_since_creation": "time",
    # elasticity (issue 48): the stress history, its fields in the forms, and the outputs
    "elastic_stress": "stress", "elastic_stress_invariant": "stress", "elastic_strain_rate": "strain_rate",
    "viscous_strain_rate": "strain_rate", "elastic_viscosity": "viscosity",
    **{f"elastic_stress_{c}": "stress" for c in ("xx", "yy", "zz", "xy", "xz", "yz")},
    # the reference state of the compressible approximations (issue 49)
    "adiabatic_temperature": "temperature", "nonadiabatic_temperature": "temperature_difference",
}
"""The unit kind of each output field or particle property by name (a name not here is
dimensionless): a kind of :data:`UNIT_KINDS`, or ``density_anomaly`` for the ``density`` field
(``rho' = sum_i Rb_i C_i - Ra T``, written as ``rho0 + rho' eta0 kappa / (g L^3)`` in the density
unit; :meth:`Scaling.dimensional`), or ``temperature_difference`` for a temperature less another (in the
temperature unit, without its offset)."""


@dataclass(frozen=True)
class ScalingSettings:
    """The ``scaling`` config section: the reference scales and physical constants of a model
    written in physical units (values with units, e.g. ``660 km``; see :mod:`convection.physics.scaling`)."""

    length: str | None = param(None, help="reference length L (e.g. the depth of the box: 660 km); a "
                                                  "nondimensional length 1")
    viscosity: str | None = param(None, help="reference viscosity eta0 (e.g. 1e21 Pa s)")
    diffusivity: str = param("1e-6 m^2/s", help="thermal diffusivity kappa: the time unit is L^2 / kappa")
    density: str | None = param(None, help="reference density rho0 (e.g. 3300 kg/m^3): the "
                                                          "background material's; materials' densities count from it")
    gravity: str | None = param(None, help="gravitational acceleration g (e.g. 9.81 m/s^2)")
    thermal_expansivity: str | None = param(None, help="thermal expansivity alpha (e.g. 3e-5 1/K)")
    temperature_difference: str | None = param(None, help="temperature scale dT (e.g. the "
                                                                         "temperature drop across the model, 1300 K)")
    reference_temperature: str = param("0 K", help="temperature T0 of the nondimensional T = 0 (e.g. the "
                                                   "surface's, 273 K)")
    heat_capacity: str | None = param(None, help="specific heat c_p (e.g. 1250 J/kg/K), for "
                                                                "internal heating given in W/kg")
    units: OutputUnits = subsection(OutputUnits)


def _quantity(text: Any, key: str, dimension: str) -> Quantity:
    """The quantity of ``text`` at config key ``key``, of ``dimension`` (a pint dimensionality text).

    Raises:
        ConfigError: not a number with a unit, or of another dimension.
    """
    quantity = parse_quantity(text)
    if quantity is None:
        raise ConfigError(f"config key '{key}': expected a value with a unit of {dimension} (e.g. "
                          f"{_EXAMPLES.get(dimension, '1 m')}), got {short_repr(text)}")
    if quantity.dimensionality != registry().get_dimensionality(dimension):
        raise ConfigError(f"config key '{key}': {short_repr(text)} is not of {dimension} "
                          f"(its dimension: {quantity.dimensionality})")
    return quantity


def _is_offset(quantity: Quantity) -> bool:
    """Whether ``quantity``'s unit has an offset (degC, degF): a temperature value, not a difference.
    Public pint only: 0 of a unit without an offset is 0 K."""
    if quantity.dimensionality != registry().get_dimensionality("[temperature]"):
        return False
    return registry().Quantity(0.0, quantity.units).to("K").magnitude != 0.0


_EXAMPLES = {"[length]": "660 km", "[mass] / [length] / [time]": "1e21 Pa s", "[length] ** 2 / [time]": "1e-6 m^2/s",
             "[mass] / [length] ** 3": "3300 kg/m^3", "[length] / [time] ** 2": "9.81 m/s^2",
             "1 / [temperature]": "3e-5 1/K", "[temperature]": "1300 K",
             "[length] ** 2 / [time] ** 2 / [temperature]": "1250 J/kg/K"}


@dataclass(frozen=True)
class Scaling:
    """Reference scales of a dimensional model (module docstring); every value in SI base units.

    Attributes:
        length: L [m].
        viscosity: eta0 [Pa s].
        diffusivity: kappa [m^2/s].
        density: rho0 [kg/m^3] (None: not given).
        gravity: g [m/s^2] (None: not given).
        thermal_expansivity: alpha [1/K] (None: not given).
        temperature_difference: dT [K] (None: not given).
        reference_temperature: T0 [K].
        heat_capacity: c_p [J/(kg K)] (None: not given).
        units: The output units by kind (:class:`OutputUnits`).
    """

    length: float
    viscosity: float
    diffusivity: float = 1e-6
    density: float | None = None
    gravity: float | None = None
    thermal_expansivity: float | None = None
    temperature_difference: float | None = None
    reference_temperature: float = 0.0
    heat_capacity: float | None = None
    units: Mapping[str, str] = field(default_factory=lambda: {f.name: f.default for f in fields(OutputUnits)})

    def __post_init__(self) -> None:
        for name in ("length", "viscosity", "diffusivity", "density", "gravity", "temperature_difference",
                     "heat_capacity", "thermal_expansivity", "reference_temperature"):
            value = getattr(self, name)
            positive = name != "reference_temperature"
            if value is not None and not (math.isfinite(value) and (value > 0.0 if positive else value >= 0.0)):
                raise ConfigError(f"config key 'scaling.{name}': must be {'positive' if positive else '>= 0 K'} and "
                                  f"finite, got {value:g} (SI)")
        scales = (self.time, self.mass, self.length**3 / (self.viscosity * self.diffusivity))
        if not all(math.isfinite(v) and v > 0.0 for v in scales):
            raise ConfigError("config key 'scaling': the scales overflow a double (L^2/kappa, eta0 L t0 or L^3/(eta0 "
                              "kappa)); choose scales nearer to the model's")

    @classmethod
    def from_section(cls, section: Mapping[str, Any]) -> Scaling:
        """The scaling of a checked ``scaling`` config section (values with units).

        Raises:
            ConfigError: a value is missing, not a quantity or of the wrong dimension.
        """
        for key in ("length", "viscosity"):
            if section.get(key) is None:
                raise ConfigError(f"config key 'scaling.{key}': required in a model with units (e.g. "
                                  f"{'660 km' if key == 'length' else '1e21 Pa s'})")
        dims = {"length": "[length]", "viscosity": "[mass] / [length] / [time]",
                "diffusivity": "[length] ** 2 / [time]",
                "density": "[mass] / [length] ** 3", "gravity": "[length] / [time] ** 2",
                "thermal_expansivity": "1 / [temperature]", "temperature_difference": "[temperature]",
                "reference_temperature": "[temperature]",
                "heat_capacity": "[length] ** 2 / [time] ** 2 / [temperature]"}
        values: dict[str, Any] = {}
        for key, dimension in dims.items():
            text = section.get(key)
            if text is None:
                continue
            quantity = _quantity(text, f"scaling.{key}", dimension)
            if key == "temperature_difference" and _is_offset(quantity):
                raise ConfigError(f"config key 'scaling.temperature_difference': a difference, in K (e.g. 1300 K), "
                                  f"not {short_repr(text)}")
            values[key] = float(quantity.to("K" if dimension == "[temperature]" else quantity.to_base_units().units)
                                .magnitude)
        units = dict(section.get("units") or {})
        for kind, text in units.items():
            try:
                unit = registry().Unit(str(text))
            except Exception:  # noqa: BLE001 - pint's many parse errors
                raise ConfigError(f"config key 'scaling.units.{kind}': {short_repr(text)} is not a unit pint knows") \
                    from None
            if unit.dimensionality != registry().get_dimensionality(UNIT_KINDS[kind]):
                raise ConfigError(f"config key 'scaling.units.{kind}': {short_repr(text)} is not of {UNIT_KINDS[kind]}")
        defaults = {f.name: f.default for f in fields(OutputUnits)}
        return cls(**values, units={**defaults, **units})

    # --- the base scales ---
    @property
    def time(self) -> float:
        """t0 = L^2 / kappa [s]."""
        return self.length**2 / self.diffusivity

    @property
    def mass(self) -> float:
        """M0 = eta0 L t0 [kg]."""
        return self.viscosity * self.length * self.time

    def scale(self, dimensionality: Mapping[str, float]) -> float:
        """The SI magnitude of the nondimensional 1 of a dimension (``{"[length]": 1, "[time]": -1}``).

        Raises:
            ConfigError: the dimension has a base other than length, time, mass, temperature, or a
                temperature without ``scaling.temperature_difference``.
        """
        other = [name for name, power in dimensionality.items() if power and name not in _BASE]
        if other:
            raise ConfigError(f"a quantity of dimension {other[0]} cannot be made nondimensional (the scaling knows "
                              "length, time, mass and temperature)")
        if dimensionality.get("[temperature]", 0) and self.temperature_difference is None:
            raise ConfigError("config key 'scaling.temperature_difference': needed for a quantity with a "
                              "temperature in it")
        length, time, mass = (dimensionality.get(base, 0) for base in _BASE[:3])
        # M0^c = (eta0 L t0)^c: powers of eta0, L and t0, so that a viscosity's scale is eta0 exactly
        value = self.viscosity**mass * self.length ** (length + mass) * self.time ** (time + mass)
        return value * (self.temperature_difference or 1.0) ** dimensionality.get("[temperature]", 0)

    def nondimensional(self, quantity: Quantity, *, absolute: bool = False) -> float:
        """The solver's number for ``quantity``; ``absolute``: a temperature value, counted from
        ``T0`` (``(T - T0) / dT``), else a difference or any other quantity (``q / scale``)."""
        if absolute and quantity.dimensionality == registry().get_dimensionality("[temperature]"):
            kelvin = float(quantity.to("K").magnitude)
            return (kelvin - self.reference_temperature) / self.scale({"[temperature]": 1})
        if _is_offset(quantity):
            raise ConfigError(f"{quantity:~} is a temperature on a scale with an offset; here a difference is meant: "
                              "write it in K")
        base = quantity.to_base_units()
        return float(base.magnitude) / self.scale(dict(base.dimensionality))

    # --- the nondimensional numbers ---
    def buoyancy_number(self, density_difference: float) -> float:
        """``Delta rho g L^3 / (eta0 kappa)`` of a density difference [kg/m^3] (Rb of a material)."""
        return density_difference * self.needed("gravity") * self.length**3 / (self.viscosity * self.diffusivity)

    def rayleigh(self) -> float:
        """Ra = rho0 alpha dT g L^3 / (eta0 kappa)."""
        rho0, alpha = self.needed("density"), self.needed("thermal_expansivity")
        dT = self.needed("temperature_difference")
        return self.buoyancy_number(rho0 * alpha * dT)

    def dissipation_number(self) -> float:
        """Di = alpha g L / c_p (King et al. 2010)."""
        return self.needed("thermal_expansivity") * self.needed("gravity") * self.length / self.needed("heat_capacity")

    def needed(self, name: str) -> float:
        """The value of ``scaling.<name>``.

        Raises:
            ConfigError: it was not given.
        """
        value = getattr(self, name)
        if value is None:
            raise ConfigError(f"config key 'scaling.{name}': needed by this model ({_WHY[name]})")
        return float(value)

    # --- back to the user's units ---
    def factor(self, kind: str) -> float:
        """Multiply a nondimensional value of ``kind`` (:data:`UNIT_KINDS`, a difference for
        temperatures) by this to get it in the output unit of that kind."""
        if kind == "temperature_difference":  # of the values: also right for a unit with an offset (degC)
            return self.dimensional("temperature", 1.0) - self.dimensional("temperature", 0.0)
        unit = registry().Unit(self.units[kind])
        one = registry().Quantity(1.0, unit).to_base_units()
        return self.scale(dict(one.dimensionality)) / float(one.magnitude)

    def dimensional(self, kind: str, value: float) -> float:
        """A nondimensional value of ``kind`` in its output unit (a temperature as a value: ``T0 + dT T'``;
        a ``density_anomaly`` as the density ``rho0 + rho' eta0 kappa / (g L^3)``)."""
        if kind == "density_anomaly":
            kg = self.needed("density") + value / self.buoyancy_number(1.0)
            return float(registry().Quantity(kg, "kg/m^3").to(self.units["density"]).magnitude)
        if kind == "temperature":
            kelvin = self.reference_temperature + value * self.scale({"[temperature]": 1})
            return float(registry().Quantity(kelvin, "K").to(self.units["temperature"]).magnitude)
        return value * self.factor(kind)

    def unit_label(self, kind: str) -> str:
        """The short text of the output unit of ``kind`` (as the user wrote it)."""
        return self.units[{"density_anomaly": "density", "temperature_difference": "temperature"}.get(kind, kind)]

    def converts(self, kind: str) -> bool:
        """Whether values of ``kind`` can be written in units (a temperature needs
        ``temperature_difference``; a density anomaly ``density`` and ``gravity``)."""
        if kind in ("temperature", "temperature_difference"):
            return self.temperature_difference is not None
        if kind == "density_anomaly":
            return self.density is not None and self.gravity is not None
        return kind in UNIT_KINDS

    def expression_constants(self) -> dict[str, float]:
        """Unit constants for config expressions: the nondimensional value of one of each unit
        (``"z > 1 - 100*km"``; a temperature constant ``K`` is a difference of one kelvin)."""
        constants = {"m": 1.0 / self.length, "km": 1e3 / self.length, "s": 1.0 / self.time,
                     "yr": 365.25 * 86400.0 / self.time}
        constants |= {"kyr": 1e3 * constants["yr"], "Myr": 1e6 * constants["yr"]}
        if self.temperature_difference is not None:
            constants["K"] = 1.0 / self.temperature_difference
        return constants

    def describe(self) -> str:
        """The scales in the output units, one line (a run prints it at its start)."""
        u = registry()

        def shown(value: float, si: str, kind: str) -> str:
            return f"{u.Quantity(value, si).to(self.units[kind]).magnitude:.6g} {self.units[kind]}"
        return (f"scaling: length unit L = {shown(self.length, 'm', 'length')}, time unit L^2/kappa = "
                f"{shown(self.time, 's', 'time')}, velocity unit kappa/L = "
                f"{shown(self.diffusivity / self.length, 'm/s', 'velocity')}, stress unit eta0 kappa/L^2 = "
                f"{shown(self.viscosity * self.diffusivity / self.length**2, 'Pa', 'stress')}")


_WHY = {"gravity": "densities give buoyancy", "density": "the thermal buoyancy rho0 alpha dT",
        "thermal_expansivity": "the thermal buoyancy: Ra = rho0 alpha dT g L^3 / (eta0 kappa)",
        "temperature_difference": "temperatures are measured in it", "heat_capacity": "internal heating in W/kg"}


_AFFINE = ("temperature", "density_anomaly")
"""Kinds converted with an offset (:meth:`Scaling.dimensional`), not by a factor alone."""


class ColumnUnits:
    """Statistics columns in the output units: the header (``vrms [cm/yr]``) and each row
    converted; a column without a kind (counts, Nusselt numbers, ratios) is kept as it is.

    Args:
        scaling: The model's scaling.
        columns: The columns, in order.
        kinds: Column -> kind of :data:`UNIT_KINDS` (temperatures as values: ``T0 + dT T'``).
    """

    def __init__(self, scaling: Scaling, columns: list[str], kinds: Mapping[str, str]) -> None:
        self.scaling = scaling
        self.columns = list(columns)
        self.kinds = {c: kinds[c] for c in columns if c in kinds and scaling.converts(kinds[c])}
        self.header = [f"{c} [{scaling.unit_label(self.kinds[c])}]" if c in self.kinds else c for c in columns]
        self._factors = {c: scaling.factor(k) for c, k in self.kinds.items() if k not in _AFFINE}

    def convert(self, row: Mapping[str, Any]) -> dict[str, Any]:
        """The row keyed by :attr:`header`, values in the output units."""
        out = {}
        for column, name in zip(self.columns, self.header):
            value = row[column]
            kind = self.kinds.get(column)
            if kind in _AFFINE:
                value = self.scaling.dimensional(kind, float(value))
            elif kind is not None:
                value = float(value) * self._factors[column]
            out[name] = value
        return out
