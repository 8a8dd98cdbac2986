"""Viscosity laws (rheology) as components: linear, Arrhenius, depth-dependent, power-law creep,
composite creep, von Mises and Drucker-Prager yielding, their visco-plastic combinations, bounds
and strain weakening.

A law maps the local state of the flow to a viscosity, as a UFL expression. The state
(:class:`FlowState`) holds the temperature ``T``, the strain-rate tensor ``eps = sym(grad u)``, the
pressure ``p``, the depth ``d`` below the top surface (box: ``z_top - z``; shell: ``r_outer - r``)
and named mesh fields (e.g. a particle property averaged onto the mesh). Strain-rate measures::

    eps_II = sqrt(eps : eps / 2)          second invariant (ASPECT's convention)
    |eps|  = sqrt(eps : eps)              Frobenius norm (Tosi et al. 2015's convention)

(both regularised by a floor, ``sqrt(eps : eps / 2 + floor^2)``, so that a fluid at rest has a
finite viscosity and its derivative exists). The laws (:data:`VISCOSITY_LAWS`)::

    constant:        eta = eta0
    exponential:     eta = eta0 exp(-gamma_T T + gamma_z d)       (Frank-Kamenetskii; Tosi's eta_lin)
    arrhenius:       eta = eta0 exp((E + V d) / (T + T_offset) - (E + V d_ref) / (T_ref + T_offset))
    depth_table:     eta = eta0 f(d), f piecewise linear through a table [[d, f], ...]
    power_law:       eta = eta0 (eps_II / eps_ref)^((1 - n) / n) exp((-gamma_T T + gamma_z d) / n)
    composite:       1 / eta = sum_i 1 / eta_i                    (diffusion + dislocation creep)
    von_mises:       eta_y = eta_star + sigma_y / (2 eps_II)      (or sigma_y / |eps|: measure "norm")
    drucker_prager:  eta_y = eta_star + sigma_y / (2 eps_II),
                     sigma_y = C cos(phi) + p' sin(phi)                          in 2D,
                     sigma_y = 6 (C cos(phi) + p' sin(phi)) / (sqrt(3) (3 + sin(phi)))  in 3D,
                     p' = max(p + lithostatic_gradient d, 0)
    viscoplastic:    tosi:     eta = 2 / (1 / eta_viscous + 1 / eta_y)   (Tosi et al. 2015)
                     minimum:  eta = min(eta_viscous, eta_y)             (ASPECT)
                     harmonic: eta = 1 / (1 / eta_viscous + 1 / eta_y)

Every law in a config is a number (a constant viscosity) or a mapping with ``name`` and the law's
parameters; every mapping may add ``min_viscosity`` and ``max_viscosity`` (the law's result is
clipped to them). The nondimensional Arrhenius inputs: ``E = E* / (R Delta T)`` (activation
energy), ``V = V* rho g h / (R Delta T)`` per unit nondimensional depth (activation volume), ``T_offset
= T_surface / Delta T``; the law is normalised so that ``eta = eta0`` at ``T = T_ref`` and ``d =
d_ref``.

**Strain weakening** (ASPECT's convention, ../shared/reference): a plastic law's ``weakening``
``{field, start, end, factor}`` scales the cohesion or yield stress (and, for Drucker-Prager, the
friction angle, ``weaken: [cohesion, friction_angle]``) by ``w(e)``, linear in the accumulated
strain ``e`` (a named mesh field, e.g. ``plastic_strain`` averaged from the particles) from 1 at
``e <= start`` to ``factor`` at ``e >= end``; a viscous law can be weakened the same way by the
``weakened`` law.

Every parameter is checked when the config is read: :func:`build_law` turns a config value into a
law or raises :class:`convection.schema.ConfigError` naming the key, in one line.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from collections.abc import Callable, Mapping, Sequence
from typing import Any, ClassVar, NamedTuple

import ufl

from convection.schema import ConfigError, short_repr
from fembase.registry import Registry

__all__ = ["FlowState", "STRAIN_RATE_MEASURES", "VISCOSITY_LAWS", "ViscosityLawBase", "build_law", "law_param",
           "laws_field_names", "strain_rate_measure", "weakening_factor", "yield_law"]

@dataclass(frozen=True)
class StrainRateMeasure:
    """A strain-rate measure of the yield laws, ``sqrt(square_scale eps:eps + floor^2)``; the
    yield viscosity is ``sigma_y / (yield_scale measure)``."""

    name: str
    description: str
    square_scale: float
    yield_scale: float


STRAIN_RATE_MEASURES: Registry[StrainRateMeasure] = Registry("strain-rate measure", (
    StrainRateMeasure("second_invariant", "eps_II = sqrt(eps:eps / 2); yield viscosity sigma_y / (2 eps_II) (ASPECT)",
                      0.5, 2.0),
    StrainRateMeasure("norm", "|eps| = sqrt(eps:eps); yield viscosity sigma_y / |eps| (Tosi et al. 2015)", 1.0, 1.0),
))
"""Registry of strain-rate measures of the yield laws."""


@dataclass(frozen=True)
class CombinationRule:
    """How a visco-plastic law combines its viscous viscosity ``eta_v`` with its yield law:
    ``combine(eta_v, plastic, state)`` (UFL)."""

    name: str
    description: str
    combine: Callable[[Any, Any, FlowState], Any]


def _minimum(eta_v: Any, plastic: Any, state: FlowState) -> Any:
    return ufl.min_value(eta_v, plastic(state))


def _scaled_harmonic(scale: float) -> Callable[[Any, Any, FlowState], Any]:
    """``scale / (1/eta_v + 1/eta_y)``, with ``1/eta_y`` written to be 0 at rest for a yield law."""
    def combine(eta_v: Any, plastic: Any, state: FlowState) -> Any:
        inverse_y = plastic.inverse(state) if isinstance(plastic, _Yield) else 1.0 / plastic(state)
        return scale / (1.0 / eta_v + inverse_y)
    return combine


COMBINATIONS: Registry[CombinationRule] = Registry("visco-plastic combination rule", (
    CombinationRule("tosi", "eta = 2 / (1/eta_viscous + 1/eta_yield) (Tosi et al. 2015)", _scaled_harmonic(2.0)),
    CombinationRule("minimum", "eta = min(eta_viscous, eta_yield) (ASPECT)", _minimum),
    CombinationRule("harmonic", "eta = 1 / (1/eta_viscous + 1/eta_yield)", _scaled_harmonic(1.0)),
))
"""Registry of the visco-plastic combination rules."""

DEFAULT_STRAIN_RATE_FLOOR = 1.0e-20
"""Floor of the strain-rate measures (nondimensional): keeps a fluid at rest finite and differentiable."""


class FlowState(NamedTuple):
    """What a viscosity law may depend on, as UFL expressions.

    Attributes:
        T: temperature (scalar).
        strain_rate: strain-rate tensor ``sym(grad u)``, shape (gdim, gdim), or None when the
            velocity is not part of the problem (a law that needs it then fails).
        pressure: pressure (scalar), or None (the same).
        depth: depth below the top surface (scalar).
        fields: named mesh fields (e.g. ``plastic_strain``), scalar each.
        gdim: geometric dimension.
    """

    T: Any
    strain_rate: Any
    pressure: Any
    depth: Any
    fields: Mapping[str, Any]
    gdim: int


def strain_rate_measure(state: FlowState, measure: str, floor: float) -> Any:
    """``eps_II`` (``"second_invariant"``) or ``|eps|`` (``"norm"``) of the state's strain rate,
    regularised by ``floor`` (see the module docstring)."""
    if state.strain_rate is None:
        raise ValueError("this viscosity law depends on the strain rate, which the caller did not provide")
    eps = state.strain_rate
    scale = STRAIN_RATE_MEASURES.lookup(measure).square_scale
    return ufl.sqrt(scale * ufl.inner(eps, eps) + floor * floor)


def weakening_factor(e: Any, start: float, end: float, factor: float) -> Any:
    """``w(e)``: 1 for ``e <= start``, ``factor`` for ``e >= end``, linear between (UFL or float)."""
    if isinstance(e, (int, float)):
        s = min(max((float(e) - start) / (end - start), 0.0), 1.0)
        return 1.0 + (factor - 1.0) * s
    s = ufl.min_value(ufl.max_value((e - start) / (end - start), 0.0), 1.0)
    return 1.0 + (factor - 1.0) * s


# ---------------------------------------------------------------------- parameter parsing
def law_param(kind: str = "float", default: Any = dataclasses.MISSING, **checks: Any) -> Any:
    """A dataclass field of a law: ``kind`` (float | int | str | law | laws | table | list[str]),
    a default and checks (minimum, exclusive_minimum, maximum, exclusive_maximum, choices, help)."""
    metadata = {"kind": kind, **checks}
    if isinstance(default, list):
        return dataclasses.field(default_factory=lambda d=default: list(d), metadata=metadata)
    return dataclasses.field(default=default, metadata=metadata)


def _number(value: Any, key: str, checks: Mapping[str, Any], *, integer: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ConfigError(f"config key '{key}': expected a number, got {short_repr(value)}")
    if integer and int(value) != value:
        raise ConfigError(f"config key '{key}': expected an integer, got {short_repr(value)}")
    number = float(value)
    if not math.isfinite(number):
        raise ConfigError(f"config key '{key}': expected a finite number, got {short_repr(value)}")
    for name, op, text in (("minimum", float.__ge__, ">="), ("exclusive_minimum", float.__gt__, ">"),
                           ("maximum", float.__le__, "<="), ("exclusive_maximum", float.__lt__, "<")):
        bound = checks.get(name)
        if bound is not None and not op(number, float(bound)):
            raise ConfigError(f"config key '{key}': must be {text} {bound}, got {short_repr(value)}")
    return int(number) if integer else number


def _parse_value(kind: str, value: Any, key: str, checks: Mapping[str, Any]) -> Any:
    if kind in ("float", "int"):
        return _number(value, key, checks, integer=kind == "int")
    if kind == "str":
        if not isinstance(value, str):
            raise ConfigError(f"config key '{key}': expected a name, got {short_repr(value)}")
        choices = checks.get("choices")
        if choices is not None and value not in choices:
            raise ConfigError(f"config key '{key}': {value!r} is not one of {sorted(choices)}")
        return value
    if kind == "list[str]":
        if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
            raise ConfigError(f"config key '{key}': expected a list of names, got {short_repr(value)}")
        choices = checks.get("choices")
        for v in value:
            if choices is not None and v not in choices:
                raise ConfigError(f"config key '{key}': {v!r} is not one of {sorted(choices)}")
        return tuple(value)
    if kind == "law":
        return build_law(value, key)
    if kind == "laws":
        if not isinstance(value, list) or len(value) < 1:
            raise ConfigError(f"config key '{key}': expected a list of viscosity laws, got {short_repr(value)}")
        return tuple(build_law(v, f"{key}[{i}]") for i, v in enumerate(value))
    if kind == "table":
        if not isinstance(value, list) or len(value) < 2:
            raise ConfigError(f"config key '{key}': expected a list of at least two [depth, factor] rows, "
                              f"got {short_repr(value)}")
        rows = []
        for i, row in enumerate(value):
            if not isinstance(row, list) or len(row) != 2:
                raise ConfigError(f"config key '{key}[{i}]': expected [depth, factor], got {short_repr(row)}")
            d = _number(row[0], f"{key}[{i}][0]", {})
            f = _number(row[1], f"{key}[{i}][1]", {"exclusive_minimum": 0.0})
            rows.append((d, f))
        depths = [d for d, _ in rows]
        if any(b <= a for a, b in zip(depths, depths[1:])):
            raise ConfigError(f"config key '{key}': the depths must increase, got {depths}")
        return tuple(rows)
    if kind == "weakening":  # null: no weakening (the default)
        return None if value is None else Weakening.from_config(value, key)
    raise AssertionError(kind)


class ViscosityLawBase:
    """Base of every law: parsing from a config mapping, and what the law depends on.

    Subclasses are frozen dataclasses whose fields are made by :func:`law_param`; they set the class
    attributes ``name`` and ``description`` and implement ``__call__(state) -> UFL expression``.
    """

    name: ClassVar[str]
    description: ClassVar[str]
    uses: ClassVar[frozenset[str]] = frozenset()
    """What the law itself reads: a subset of {"temperature", "depth", "strain_rate", "pressure"}."""

    @classmethod
    def from_config(cls, spec: Mapping[str, Any], key: str) -> ViscosityLawBase:
        """The law for the mapping ``spec`` (without ``name``) of config key ``key``.

        Raises:
            ConfigError: an unknown or missing parameter, or a value out of range (one line).
        """
        fields = {f.name: f for f in dataclasses.fields(cls)}
        unknown = [k for k in spec if k not in fields]
        if unknown:
            raise ConfigError(f"config key '{key}.{unknown[0]}': not a parameter of viscosity law {cls.name!r}; "
                              f"valid: {sorted(fields) + ['max_viscosity', 'min_viscosity', 'name']}")
        values = {}
        for name, f in fields.items():
            if name in spec:
                values[name] = _parse_value(f.metadata["kind"], spec[name], f"{key}.{name}", f.metadata)
            elif f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
                raise ConfigError(f"config key '{key}.{name}': required by viscosity law {cls.name!r} "
                                  f"({f.metadata.get('help', name)})")
        law = cls(**values)
        law.check(key)
        return law

    def check(self, key: str) -> None:
        """Checks across parameters (raise ConfigError naming ``key``); none by default."""

    def children(self) -> tuple[ViscosityLawBase, ...]:
        """The laws this one is built from."""
        return ()

    def constant_value(self) -> float | None:
        """The viscosity where it is one known number everywhere (a plain constant), else None."""
        return None

    @property
    def depends_on(self) -> frozenset[str]:
        """Everything the law's value depends on: its own inputs, those of its children and the
        named fields (as ``"field:<name>"``)."""
        out = set(self.uses) | {f"field:{n}" for n in self.field_names()}
        for child in self.children():
            out |= child.depends_on
        return frozenset(out)

    def field_names(self) -> tuple[str, ...]:
        """Named mesh fields this law reads itself."""
        return ()

    @property
    def is_constant(self) -> bool:
        return not self.depends_on

    @property
    def is_nonlinear(self) -> bool:
        """True when the law depends on the flow (strain rate or pressure): the Stokes problem is
        then nonlinear."""
        return bool(self.depends_on & {"strain_rate", "pressure"})

    def __call__(self, state: FlowState) -> Any:  # pragma: no cover - abstract
        raise NotImplementedError


@dataclass(frozen=True)
class Weakening:
    """Linear strain weakening: a factor ``w(e)`` (:func:`weakening_factor`) of a named field ``e``."""

    field: str = "plastic_strain"
    start: float = 0.5
    end: float = 1.5
    factor: float = 0.25

    @classmethod
    def from_config(cls, spec: Any, key: str) -> Weakening:
        if not isinstance(spec, dict):
            raise ConfigError(f"config key '{key}': expected {{field, start, end, factor}}, got {short_repr(spec)}")
        unknown = [k for k in spec if k not in ("field", "start", "end", "factor")]
        if unknown:
            raise ConfigError(f"config key '{key}.{unknown[0]}': not a weakening parameter; valid: "
                              "['end', 'factor', 'field', 'start']")
        field = spec.get("field", cls.field)
        if not isinstance(field, str) or not field.isidentifier():
            raise ConfigError(f"config key '{key}.field': expected a field name, got {short_repr(field)}")
        start = _number(spec.get("start", cls.start), f"{key}.start", {"minimum": 0.0})
        end = _number(spec.get("end", cls.end), f"{key}.end", {"exclusive_minimum": start})
        factor = _number(spec.get("factor", cls.factor), f"{key}.factor", {"exclusive_minimum": 0.0, "maximum": 1.0})
        return cls(field, start, end, factor)

    def __call__(self, state: FlowState) -> Any:
        if self.field not in state.fields:
            raise ValueError(f"strain weakening needs the mesh field {self.field!r}; have {sorted(state.fields)}")
        return weakening_factor(state.fields[self.field], self.start, self.end, self.factor)


# ---------------------------------------------------------------------- viscous laws
@dataclass(frozen=True)
class Constant(ViscosityLawBase):
    name: ClassVar[str] = "constant"
    description: ClassVar[str] = "eta = eta0"
    eta0: float = law_param(default=1.0, exclusive_minimum=0.0, help="viscosity")

    def __call__(self, state: FlowState) -> Any:
        return ufl.as_ufl(self.eta0)

    def constant_value(self) -> float | None:
        return self.eta0


@dataclass(frozen=True)
class Exponential(ViscosityLawBase):
    name: ClassVar[str] = "exponential"
    description: ClassVar[str] = "eta = eta0 exp(-gamma_T T + gamma_z depth) (Frank-Kamenetskii, linear in depth)"
    eta0: float = law_param(default=1.0, exclusive_minimum=0.0, help="viscosity at T = 0, depth 0")
    gamma_T: float = law_param(default=0.0, minimum=0.0, help="ln of the thermal viscosity contrast")
    gamma_z: float = law_param(default=0.0, minimum=0.0, help="ln of the viscosity contrast over unit depth")

    @property
    def uses(self) -> frozenset[str]:  # type: ignore[override]
        return frozenset(({"temperature"} if self.gamma_T else set()) | ({"depth"} if self.gamma_z else set()))

    def __call__(self, state: FlowState) -> Any:
        exponent = 0.0
        if self.gamma_T:
            exponent = -self.gamma_T * state.T
        if self.gamma_z:
            exponent = exponent + self.gamma_z * state.depth
        return self.eta0 * ufl.exp(exponent) if not isinstance(exponent, float) else ufl.as_ufl(self.eta0)


@dataclass(frozen=True)
class Arrhenius(ViscosityLawBase):
    name: ClassVar[str] = "arrhenius"
    description: ClassVar[str] = ("eta = eta0 exp((E + V d)/(T + T_offset) - (E + V d_ref)/(T_ref + T_offset)) "
                                  "(nondimensional activation energy and volume)")
    uses: ClassVar[frozenset[str]] = frozenset({"temperature", "depth"})
    E: float = law_param(minimum=0.0, help="nondimensional activation energy E*/(R Delta T)")
    V: float = law_param(default=0.0, minimum=0.0, help="nondimensional activation volume per unit depth")
    eta0: float = law_param(default=1.0, exclusive_minimum=0.0, help="viscosity at T_ref, d_ref")
    T_offset: float = law_param(default=0.0, minimum=0.0, help="surface temperature / Delta T (keeps T + T_offset > 0)")
    T_ref: float = law_param(default=1.0, help="reference temperature")
    depth_ref: float = law_param(default=0.0, help="reference depth")

    def check(self, key: str) -> None:
        if not self.T_ref + self.T_offset > 0.0:
            raise ConfigError(f"config key '{key}.T_offset': T_ref + T_offset must be > 0, got "
                              f"{self.T_ref + self.T_offset}")

    def __call__(self, state: FlowState) -> Any:
        reference = (self.E + self.V * self.depth_ref) / (self.T_ref + self.T_offset)
        # T below -T_offset (undershoots) would flip the sign: floor the absolute temperature.
        absolute = ufl.max_value(state.T + self.T_offset, 1e-3 * (self.T_ref + self.T_offset))
        return self.eta0 * ufl.exp((self.E + self.V * state.depth) / absolute - reference)


@dataclass(frozen=True)
class DepthTable(ViscosityLawBase):
    name: ClassVar[str] = "depth_table"
    description: ClassVar[str] = "eta = eta0 f(depth), f piecewise linear through [[depth, factor], ...]"
    uses: ClassVar[frozenset[str]] = frozenset({"depth"})
    table: tuple = law_param("table", help="[[depth, factor], ...] with increasing depths")
    eta0: float = law_param(default=1.0, exclusive_minimum=0.0, help="viscosity scale")

    def __call__(self, state: FlowState) -> Any:
        d = state.depth
        f0 = self.table[0][1]
        value: Any = ufl.as_ufl(f0)  # constant above the first row, linear between rows, constant below
        for (da, fa), (db, fb) in zip(self.table, self.table[1:]):
            s = ufl.min_value(ufl.max_value((d - da) / (db - da), 0.0), 1.0)
            value = value + (fb - fa) * s
        return self.eta0 * value


@dataclass(frozen=True)
class PowerLaw(ViscosityLawBase):
    name: ClassVar[str] = "power_law"
    description: ClassVar[str] = ("eta = eta0 (eps_II/eps_ref)^((1-n)/n) exp((-gamma_T T + gamma_z d)/n) "
                                  "(dislocation creep)")
    n: float = law_param(exclusive_minimum=0.0, help="stress exponent (1: linear)")
    eta0: float = law_param(default=1.0, exclusive_minimum=0.0, help="viscosity at the reference strain rate")
    reference_strain_rate: float = law_param(default=1.0, exclusive_minimum=0.0, help="eps_ref")
    gamma_T: float = law_param(default=0.0, minimum=0.0, help="ln of the thermal contrast of the prefactor")
    gamma_z: float = law_param(default=0.0, minimum=0.0, help="ln of the depth contrast of the prefactor")
    strain_rate_floor: float = law_param(default=DEFAULT_STRAIN_RATE_FLOOR, exclusive_minimum=0.0,
                                      help="eps_II is at least this")

    @property
    def uses(self) -> frozenset[str]:  # type: ignore[override]
        out = {"strain_rate"} if self.n != 1.0 else set()
        return frozenset(out | ({"temperature"} if self.gamma_T else set()) | ({"depth"} if self.gamma_z else set()))

    def __call__(self, state: FlowState) -> Any:
        eta: Any = ufl.as_ufl(self.eta0)
        if self.n != 1.0:
            e = strain_rate_measure(state, "second_invariant", self.strain_rate_floor)
            eta = eta * (e / self.reference_strain_rate) ** ((1.0 - self.n) / self.n)
        exponent: Any = 0.0
        if self.gamma_T:
            exponent = -self.gamma_T * state.T
        if self.gamma_z:
            exponent = exponent + self.gamma_z * state.depth
        if not isinstance(exponent, float):
            eta = eta * ufl.exp(exponent / self.n)
        return eta


@dataclass(frozen=True)
class Composite(ViscosityLawBase):
    name: ClassVar[str] = "composite"
    description: ClassVar[str] = "1/eta = sum_i 1/eta_i (e.g. diffusion + dislocation creep)"
    laws: tuple = law_param("laws", help="the creep laws combined")

    def children(self) -> tuple[ViscosityLawBase, ...]:
        return self.laws

    def __call__(self, state: FlowState) -> Any:
        inverse: Any = 0.0
        for law in self.laws:
            inverse = inverse + 1.0 / law(state)
        return 1.0 / inverse


@dataclass(frozen=True)
class Weakened(ViscosityLawBase):
    name: ClassVar[str] = "weakened"
    description: ClassVar[str] = "eta = w(e) eta_law: a viscous law weakened linearly by an accumulated strain e"
    law: Any = law_param("law", help="the law weakened")
    weakening: Any = law_param("weakening", help="{field, start, end, factor}")

    def children(self) -> tuple[ViscosityLawBase, ...]:
        return (self.law,)

    def field_names(self) -> tuple[str, ...]:
        return (self.weakening.field,)

    def __call__(self, state: FlowState) -> Any:
        return self.weakening(state) * self.law(state)


@dataclass(frozen=True)
class Damaged(ViscosityLawBase):
    name: ClassVar[str] = "damaged"
    description: ClassVar[str] = "eta = max(1 - D, residual) eta_law: damage D in [0, 1] (a named field) weakens"
    law: Any = law_param("law", help="the law damaged")
    field: str = law_param("str", default="damage", help="the damage field")
    residual: float = law_param(default=1e-3, exclusive_minimum=0.0, maximum=1.0,
                             help="the factor at full damage")

    def children(self) -> tuple[ViscosityLawBase, ...]:
        return (self.law,)

    def field_names(self) -> tuple[str, ...]:
        return (self.field,)

    def __call__(self, state: FlowState) -> Any:
        if self.field not in state.fields:
            raise ValueError(f"viscosity law 'damaged' needs the mesh field {self.field!r}; "
                             f"have {sorted(state.fields)}")
        return ufl.max_value(1.0 - state.fields[self.field], self.residual) * self.law(state)


# ---------------------------------------------------------------------- yield laws
class _Yield(ViscosityLawBase):
    """A yield viscosity ``eta_star + sigma_y / (2 eps_II)`` (or ``/ |eps|``)."""

    def sigma_y(self, state: FlowState) -> Any:  # pragma: no cover - abstract
        raise NotImplementedError

    def __call__(self, state: FlowState) -> Any:
        e = strain_rate_measure(state, self.strain_rate_measure, self.strain_rate_floor)
        scale = STRAIN_RATE_MEASURES[self.strain_rate_measure].yield_scale
        return self.eta_star + self.sigma_y(state) / (scale * e)

    def inverse(self, state: FlowState) -> Any:
        """``1 / eta_y``, written so that it is 0 (and smooth) at rest."""
        e = strain_rate_measure(state, self.strain_rate_measure, self.strain_rate_floor)
        scale = STRAIN_RATE_MEASURES[self.strain_rate_measure].yield_scale
        return scale * e / (self.eta_star * scale * e + self.sigma_y(state))

    def field_names(self) -> tuple[str, ...]:
        return (self.weakening.field,) if self.weakening is not None else ()


@dataclass(frozen=True)
class VonMises(_Yield):
    name: ClassVar[str] = "von_mises"
    description: ClassVar[str] = "eta_y = eta_star + sigma_y / (2 eps_II) (or / |eps|): a constant yield stress"
    uses: ClassVar[frozenset[str]] = frozenset({"strain_rate"})
    yield_stress: float = law_param(exclusive_minimum=0.0, help="yield stress sigma_y")
    eta_star: float = law_param(default=0.0, minimum=0.0, help="viscosity added to the yield viscosity")
    strain_rate_measure: str = law_param("str", default="second_invariant", choices=tuple(STRAIN_RATE_MEASURES))
    strain_rate_floor: float = law_param(default=DEFAULT_STRAIN_RATE_FLOOR, exclusive_minimum=0.0)
    weakening: Any = law_param("weakening", default=None, help="{field, start, end, factor}: weakens the yield stress")

    def sigma_y(self, state: FlowState) -> Any:
        sigma: Any = ufl.as_ufl(self.yield_stress)
        if self.weakening is not None:
            sigma = self.weakening(state) * sigma
        return sigma


@dataclass(frozen=True)
class DruckerPrager(_Yield):
    name: ClassVar[str] = "drucker_prager"
    description: ClassVar[str] = ("eta_y = eta_star + sigma_y / (2 eps_II), sigma_y = C cos(phi) + max(p, 0) "
                                  "sin(phi) (2D; ASPECT's 3D form)")
    uses: ClassVar[frozenset[str]] = frozenset({"strain_rate", "pressure", "depth"})
    cohesion: float = law_param(minimum=0.0, help="cohesion C")
    friction_angle: float = law_param(minimum=0.0, exclusive_maximum=90.0, help="friction angle phi in degrees")
    lithostatic_gradient: float = law_param(default=0.0, minimum=0.0,
                                         help="p' = p + this x depth: the lithostatic part of the pressure")
    eta_star: float = law_param(default=0.0, minimum=0.0, help="viscosity added to the yield viscosity")
    strain_rate_measure: str = law_param("str", default="second_invariant", choices=tuple(STRAIN_RATE_MEASURES))
    strain_rate_floor: float = law_param(default=DEFAULT_STRAIN_RATE_FLOOR, exclusive_minimum=0.0)
    weakening: Any = law_param("weakening", default=None, help="{field, start, end, factor}")
    weaken: tuple = law_param("list[str]", default=["cohesion", "friction_angle"],
                           choices=("cohesion", "friction_angle"), help="what the weakening scales")

    def check(self, key: str) -> None:
        if self.cohesion == 0.0 and self.friction_angle == 0.0:
            raise ConfigError(f"config key '{key}.cohesion': a zero cohesion needs a friction angle > 0")

    def sigma_y(self, state: FlowState) -> Any:
        if state.pressure is None:
            raise ValueError("viscosity law 'drucker_prager' needs the pressure, which the caller did not provide")
        w = self.weakening(state) if self.weakening is not None else None
        cohesion: Any = ufl.as_ufl(self.cohesion)
        phi: Any = ufl.as_ufl(math.radians(self.friction_angle))
        if w is not None and "cohesion" in self.weaken:
            cohesion = w * cohesion
        if w is not None and "friction_angle" in self.weaken:
            phi = w * phi
        pressure = state.pressure
        if self.lithostatic_gradient:
            pressure = pressure + self.lithostatic_gradient * state.depth
        pressure = ufl.max_value(pressure, 0.0)
        if state.gdim == 3:
            return 6.0 * (cohesion * ufl.cos(phi) + pressure * ufl.sin(phi)) / (math.sqrt(3.0) * (3.0 + ufl.sin(phi)))
        return cohesion * ufl.cos(phi) + pressure * ufl.sin(phi)


@dataclass(frozen=True)
class ViscoPlastic(ViscosityLawBase):
    name: ClassVar[str] = "viscoplastic"
    description: ClassVar[str] = "a viscous law and a yield law combined: tosi (2/(1/a+1/b)), minimum or harmonic"
    viscous: Any = law_param("law", help="the viscous law")
    plastic: Any = law_param("law", help="a yield law: von_mises or drucker_prager")
    combination: str = law_param("str", default="tosi", choices=tuple(COMBINATIONS))

    def check(self, key: str) -> None:
        if not isinstance(self.plastic, (_Yield, Bounded)) or (
                isinstance(self.plastic, Bounded) and not isinstance(self.plastic.law, _Yield)):
            raise ConfigError(f"config key '{key}.plastic': must be a yield law (von_mises or drucker_prager), "
                              f"got {self.plastic.name!r}")

    def children(self) -> tuple[ViscosityLawBase, ...]:
        return (self.viscous, self.plastic)

    def __call__(self, state: FlowState) -> Any:
        return COMBINATIONS[self.combination].combine(self.viscous(state), self.plastic, state)


@dataclass(frozen=True)
class Bounded(ViscosityLawBase):
    """A law clipped to ``[min_viscosity, max_viscosity]`` (either may be None)."""

    name: ClassVar[str] = "bounded"
    description: ClassVar[str] = "a law clipped to [min_viscosity, max_viscosity] (any law's min_/max_viscosity keys)"
    law: Any = law_param("law")
    min_viscosity: Any = law_param(default=None, exclusive_minimum=0.0)
    max_viscosity: Any = law_param(default=None, exclusive_minimum=0.0)

    def children(self) -> tuple[ViscosityLawBase, ...]:
        return (self.law,)

    def __call__(self, state: FlowState) -> Any:
        eta = self.law(state)
        if self.min_viscosity is not None:
            eta = ufl.max_value(eta, self.min_viscosity)
        if self.max_viscosity is not None:
            eta = ufl.min_value(eta, self.max_viscosity)
        return eta

    def inverse(self, state: FlowState) -> Any:
        return 1.0 / self(state)


VISCOSITY_LAWS: Registry[type[ViscosityLawBase]] = Registry("viscosity law", (
    Constant, Exponential, Arrhenius, DepthTable, PowerLaw, Composite, VonMises, DruckerPrager, ViscoPlastic,
    Weakened, Damaged))
"""Registry of viscosity laws (config name -> law class)."""


def build_law(spec: Any, key: str) -> ViscosityLawBase:
    """The law of the config value ``spec`` at config key ``key``: a positive number (constant
    viscosity) or a mapping ``{name, parameters..., min_viscosity?, max_viscosity?}``.

    Raises:
        ConfigError: anything wrong, in one line naming the key.
    """
    if isinstance(spec, (int, float)) and not isinstance(spec, bool):
        return Constant(eta0=_number(spec, key, {"exclusive_minimum": 0.0}))
    if not isinstance(spec, dict):
        raise ConfigError(f"config key '{key}': expected a viscosity (number) or a law {{name: ..., ...}}, "
                          f"got {short_repr(spec)}")
    if "name" not in spec:
        raise ConfigError(f"config key '{key}.name': a viscosity law needs a name; valid: {sorted(VISCOSITY_LAWS)}")
    name = spec["name"]
    if not isinstance(name, str) or name not in VISCOSITY_LAWS:
        raise ConfigError(f"config key '{key}.name': unknown viscosity law {short_repr(name)}; "
                          f"valid: {sorted(VISCOSITY_LAWS)}")
    params = {k: v for k, v in spec.items() if k not in ("name", "min_viscosity", "max_viscosity")}
    law = VISCOSITY_LAWS[name].from_config(params, key)
    bounds = {k: _number(spec[k], f"{key}.{k}", {"exclusive_minimum": 0.0})
              for k in ("min_viscosity", "max_viscosity") if spec.get(k) is not None}
    if bounds:
        lo, hi = bounds.get("min_viscosity"), bounds.get("max_viscosity")
        if lo is not None and hi is not None and not lo < hi:
            raise ConfigError(f"config key '{key}.max_viscosity': must exceed min_viscosity, got {hi} <= {lo}")
        law = Bounded(law=law, min_viscosity=lo, max_viscosity=hi)
    return law


def yield_law(law: ViscosityLawBase) -> ViscoPlastic | None:
    """The visco-plastic law ``law`` is (or clips), or None."""
    while isinstance(law, Bounded):
        law = law.law
    return law if isinstance(law, ViscoPlastic) else None


def laws_field_names(laws: Sequence[ViscosityLawBase]) -> tuple[str, ...]:
    """The named mesh fields the laws read (sorted, each once)."""
    names = set()
    for law in laws:
        names |= {d.split(":", 1)[1] for d in law.depends_on if d.startswith("field:")}
    return tuple(sorted(names))
