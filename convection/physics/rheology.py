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

Each law is a plugin of the one shape (``fembase.registry.Plugin``): its parameters are a frozen
``Settings`` dataclass whose fields are made by :func:`convection.schema.param` (default, bounds,
allowed names, help: the config reference and ``check`` read them there), and
``build(settings, context)`` makes the law; it is registered once in :data:`VISCOSITY_LAWS` and
made only through it. A config value becomes a law in two steps: :func:`law_settings` checks it
(a :class:`LawSettings`: the law's name, its ``Settings`` and the bounds; nested laws, tables and
weakenings checked the same way) and :func:`make_law` builds it (``VISCOSITY_LAWS.build``);
:func:`build_law` does both and raises :class:`convection.schema.ConfigError` naming the key, in
one line.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from collections.abc import Callable, Mapping, Sequence
from typing import Any, ClassVar, NamedTuple

import ufl

from convection.schema import (
    REQUIRED, ConfigError, Field, Names, check_value, param, section_schema, settings_from, short_repr, validate,
)
from fembase.registry import Registry

__all__ = ["ElasticTrial", "FlowState", "LawContext", "LawSettings", "STRAIN_RATE_MEASURES", "VISCOSITY_LAWS",
           "ViscosityLawBase", "build_law", "law_settings", "laws_field_names", "make_law", "strain_rate_measure",
           "weakening_factor", "yield_law"]

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
    exact: bool = False
    """Whether the stress where it yields is the yield stress (what visco-elasto-plasticity needs)."""


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
    CombinationRule("minimum", "eta = min(eta_viscous, eta_yield) (ASPECT)", _minimum, exact=True),
    CombinationRule("harmonic", "eta = 1 / (1/eta_viscous + 1/eta_yield)", _scaled_harmonic(1.0)),
))
"""Registry of the visco-plastic combination rules."""

MAXWELL_FLOOR = 1.0e-12
"""Floor of ``1 - eta_y r / G`` in :meth:`ViscoPlastic.maxwell_yield` (where the yield viscosity reaches
``G dt_e`` the stress cannot reach the yield stress in one step: ``eta_p`` is then huge, not infinite)."""

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
    elastic: ElasticTrial | None = None


class ElasticTrial(NamedTuple):
    """What a visco-plastic law needs of Maxwell elasticity to limit the visco-elastic stress
    (:meth:`ViscoPlastic.maxwell_yield`; :mod:`convection.physics.elasticity`), as UFL.

    Attributes:
        modulus: the shear modulus ``G`` (mixed over the materials).
        rate: ``r = 1 / dt_e`` (0: the viscous flow before the first step).
        stress: the old deviatoric stress ``tau^n``, shape (gdim, gdim).
    """

    modulus: Any
    rate: Any
    stress: Any


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


# ---------------------------------------------------------------------- settings and building
class LawContext(NamedTuple):
    """What a law is built in besides its settings: ``key``, the config key it is written at (a
    ``build`` that refuses its settings raises ``ConfigError`` naming it; a nested law is built at
    :meth:`at` its key). A law that needs more to be built adds a field here."""

    key: str

    def at(self, name: str) -> LawContext:
        """The context of the nested law (or value) ``name`` of this one."""
        return self._replace(key=f"{self.key}.{name}")


@dataclass(frozen=True)
class LawSettings:
    """A viscosity law as written: its registered ``name``, its ``settings`` (that law's
    ``Settings``) and the bounds every law may add (the result is clipped to them)."""

    name: str
    settings: Any
    min_viscosity: float | None = param(None, exclusive_minimum=0.0, help="the viscosity is at least this")
    max_viscosity: float | None = param(None, exclusive_minimum=0.0, help="the viscosity is at most this")


_POSITIVE = Field("float", exclusive_minimum=0.0)


def law_settings(spec: Any, key: str) -> LawSettings:
    """The checked settings of the config value ``spec`` at config key ``key``: a positive number
    (a constant viscosity) or a mapping ``{name, parameters..., min_viscosity?, max_viscosity?}``.

    Raises:
        ConfigError: anything wrong, in one line naming the key.
    """
    if isinstance(spec, (int, float)) and not isinstance(spec, bool):
        return LawSettings("constant", ConstantSettings(eta0=check_value(_POSITIVE, spec, key)))
    if not isinstance(spec, dict):
        raise ConfigError(f"config key '{key}': expected a viscosity (number) or a law {{name: ..., ...}}, "
                          f"got {short_repr(spec)}")
    if "name" not in spec:
        raise ConfigError(f"config key '{key}.name': a viscosity law needs a name; valid: {sorted(VISCOSITY_LAWS)}")
    name = spec["name"]
    if not isinstance(name, str) or name not in VISCOSITY_LAWS:
        raise ConfigError(f"config key '{key}.name': unknown viscosity law {short_repr(name)}; "
                          f"valid: {sorted(VISCOSITY_LAWS)}")
    bound_keys = ("min_viscosity", "max_viscosity")
    settings_class = VISCOSITY_LAWS[name].Settings
    params = {k: v for k, v in spec.items() if k not in ("name", *bound_keys)}
    settings = _checked(settings_class, params, key, f"a parameter of viscosity law {name!r}",
                        [*sorted(section_schema(settings_class)), *sorted(bound_keys), "name"],
                        f"required by viscosity law {name!r}")
    bounds = validate(section_schema(LawSettings), {k: spec[k] for k in bound_keys if k in spec}, prefix=f"{key}.")
    lo, hi = bounds["min_viscosity"], bounds["max_viscosity"]
    if lo is not None and hi is not None and not lo < hi:
        raise ConfigError(f"config key '{key}.max_viscosity': must exceed min_viscosity, got {hi} <= {lo}")
    return LawSettings(name, settings, lo, hi)


def _checked(cls: type, spec: Mapping[str, Any], key: str, what: str, valid: list[str], required: str) -> Any:
    """The settings dataclass ``cls`` of the mapping ``spec`` at ``key``: its ``param`` fields
    checked as a config section's keys, its nested values (:data:`_NESTED`, by the field's kind)
    checked at their own keys."""
    schema = section_schema(cls)
    unknown = [k for k in spec if k not in schema]
    if unknown:
        raise ConfigError(f"config key '{key}.{unknown[0]}': not {what}; valid: {valid}")
    for name, field in schema.items():
        if name not in spec and field.default is REQUIRED:
            raise ConfigError(f"config key '{key}.{name}': {required} ({field.help})")
    values = validate(schema, spec, prefix=f"{key}.")
    for name, field in schema.items():
        if field.kind in _NESTED and values[name] is not None:
            values[name] = _NESTED[field.kind](values[name], f"{key}.{name}")
    return settings_from(cls, values)


def _laws(value: Any, key: str) -> tuple[LawSettings, ...]:
    if not isinstance(value, list) or len(value) < 1:
        raise ConfigError(f"config key '{key}': expected a list of viscosity laws, got {short_repr(value)}")
    return tuple(law_settings(v, f"{key}[{i}]") for i, v in enumerate(value))


_ROW = Field("list[float]", length=(2,))


def _table(value: Any, key: str) -> tuple[tuple[float, float], ...]:
    if not isinstance(value, list) or len(value) < 2:
        raise ConfigError(f"config key '{key}': expected a list of at least two [depth, factor] rows, "
                          f"got {short_repr(value)}")
    rows = []
    for i, row in enumerate(value):
        if not isinstance(row, list) or len(row) != 2:
            raise ConfigError(f"config key '{key}[{i}]': expected [depth, factor], got {short_repr(row)}")
        depth, factor = check_value(_ROW, row, f"{key}[{i}]")
        rows.append((depth, check_value(_POSITIVE, factor, f"{key}[{i}][1]")))
    depths = [d for d, _ in rows]
    if any(b <= a for a, b in zip(depths, depths[1:])):
        raise ConfigError(f"config key '{key}': the depths must increase, got {depths}")
    return tuple(rows)


def _weakening(value: Any, key: str) -> Weakening:
    if not isinstance(value, dict):
        raise ConfigError(f"config key '{key}': expected {{field, start, end, factor}}, got {short_repr(value)}")
    weakening = _checked(Weakening, value, key, "a weakening parameter", sorted(section_schema(Weakening)), "required")
    if not weakening.end > weakening.start:
        raise ConfigError(f"config key '{key}.end': must be > {weakening.start}, got {weakening.end}")
    return weakening


_NESTED: dict[str, Callable[[Any, str], Any]] = {
    "law": law_settings, "laws": _laws, "table": _table, "weakening": _weakening}
"""Parameter kinds whose values are checked by their own function (at their own key), by kind."""


def make_law(settings: LawSettings, context: LawContext) -> ViscosityLawBase:
    """The law of ``settings``, built by its registry entry (clipped when it has bounds).

    Raises:
        ConfigError: settings the law refuses together (one line naming ``context.key``).
    """
    law = VISCOSITY_LAWS.build(settings.name, settings.settings, context)
    if settings.min_viscosity is None and settings.max_viscosity is None:
        return law
    return Bounded(law, settings.min_viscosity, settings.max_viscosity)


def build_law(spec: Any, key: str) -> ViscosityLawBase:
    """The law of the config value ``spec`` at config key ``key`` (:func:`law_settings`, then
    :func:`make_law`).

    Raises:
        ConfigError: anything wrong, in one line naming the key.
    """
    return make_law(law_settings(spec, key), LawContext(key))


class ViscosityLawBase:
    """Base of every law: how it is built and what it depends on.

    A registered law is a frozen dataclass holding its ``settings`` (and the laws it is built from)
    with the class attributes ``name``, ``description`` and ``Settings`` (the frozen dataclass of
    its parameters, fields made by :func:`convection.schema.param`); it implements
    ``__call__(state) -> UFL expression``.
    """

    name: ClassVar[str]
    description: ClassVar[str]
    Settings: ClassVar[type]
    uses: ClassVar[frozenset[str]] = frozenset()
    """What the law itself reads: a subset of {"temperature", "depth", "strain_rate", "pressure"}."""

    def __post_init__(self) -> None:
        settings_class = getattr(type(self), "Settings", None)
        if settings_class is not None and not isinstance(getattr(self, "settings", None), settings_class):
            raise TypeError(f"{type(self).__name__} takes a {settings_class.__name__}, got "
                            f"{type(getattr(self, 'settings', None)).__name__}")

    @classmethod
    def build(cls, settings: Any, context: LawContext, /) -> ViscosityLawBase:
        """The law of ``settings`` (a ``Settings``) at ``context``: by default ``cls(settings)``;
        a law made of other laws builds them (:func:`make_law`), a law with checks across its
        parameters raises ``ConfigError`` naming ``context.key``."""
        return cls(settings)  # type: ignore[call-arg]

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


def _field_name(value: str) -> str | None:
    return None if value.isidentifier() else f"expected a field name, got {short_repr(value)}"


@dataclass(frozen=True)
class Weakening:
    """Linear strain weakening: a factor ``w(e)`` (:func:`weakening_factor`) of a named field ``e``."""

    field: str = param("plastic_strain", check=_field_name, help="the accumulated strain e (a mesh field)")
    start: float = param(0.5, minimum=0.0, help="w = 1 for e <= start")
    end: float = param(1.5, help="w = factor for e >= end (> start)")
    factor: float = param(0.25, exclusive_minimum=0.0, maximum=1.0, help="the factor at e >= end")

    def __call__(self, state: FlowState) -> Any:
        if self.field not in state.fields:
            raise ValueError(f"strain weakening needs the mesh field {self.field!r}; have {sorted(state.fields)}")
        return weakening_factor(state.fields[self.field], self.start, self.end, self.factor)


WEAKENING_HELP = "{field, start, end, factor}: a linear strain weakening (null: none)"


# ---------------------------------------------------------------------- viscous laws
@dataclass(frozen=True)
class ConstantSettings:
    eta0: float = param(1.0, exclusive_minimum=0.0, help="viscosity")


@dataclass(frozen=True)
class Constant(ViscosityLawBase):
    name: ClassVar[str] = "constant"
    description: ClassVar[str] = "eta = eta0"
    Settings: ClassVar[type] = ConstantSettings
    settings: ConstantSettings

    @classmethod
    def of(cls, eta0: float) -> Constant:
        """The constant viscosity ``eta0``."""
        return cls(ConstantSettings(float(eta0)))

    def __call__(self, state: FlowState) -> Any:
        return ufl.as_ufl(self.settings.eta0)

    def constant_value(self) -> float | None:
        return self.settings.eta0


@dataclass(frozen=True)
class ExponentialSettings:
    eta0: float = param(1.0, exclusive_minimum=0.0, help="viscosity at T = 0, depth 0")
    gamma_T: float = param(0.0, minimum=0.0, help="ln of the thermal viscosity contrast")
    gamma_z: float = param(0.0, minimum=0.0, help="ln of the viscosity contrast over unit depth")


@dataclass(frozen=True)
class Exponential(ViscosityLawBase):
    name: ClassVar[str] = "exponential"
    description: ClassVar[str] = "eta = eta0 exp(-gamma_T T + gamma_z depth) (Frank-Kamenetskii, linear in depth)"
    Settings: ClassVar[type] = ExponentialSettings
    settings: ExponentialSettings

    @property
    def uses(self) -> frozenset[str]:  # type: ignore[override]
        s = self.settings
        return frozenset(({"temperature"} if s.gamma_T else set()) | ({"depth"} if s.gamma_z else set()))

    def __call__(self, state: FlowState) -> Any:
        s = self.settings
        exponent = 0.0
        if s.gamma_T:
            exponent = -s.gamma_T * state.T
        if s.gamma_z:
            exponent = exponent + s.gamma_z * state.depth
        return s.eta0 * ufl.exp(exponent) if not isinstance(exponent, float) else ufl.as_ufl(s.eta0)


@dataclass(frozen=True)
class ArrheniusSettings:
    E: float = param(minimum=0.0, help="nondimensional activation energy E*/(R Delta T)")
    V: float = param(0.0, minimum=0.0, help="nondimensional activation volume per unit depth")
    eta0: float = param(1.0, exclusive_minimum=0.0, help="viscosity at T_ref, d_ref")
    T_offset: float = param(0.0, minimum=0.0, help="surface temperature / Delta T (keeps T + T_offset > 0)")
    T_ref: float = param(1.0, help="reference temperature")
    depth_ref: float = param(0.0, help="reference depth")


@dataclass(frozen=True)
class Arrhenius(ViscosityLawBase):
    name: ClassVar[str] = "arrhenius"
    description: ClassVar[str] = ("eta = eta0 exp((E + V d)/(T + T_offset) - (E + V d_ref)/(T_ref + T_offset)) "
                                  "(nondimensional activation energy and volume)")
    Settings: ClassVar[type] = ArrheniusSettings
    uses: ClassVar[frozenset[str]] = frozenset({"temperature", "depth"})
    settings: ArrheniusSettings

    @classmethod
    def build(cls, settings: ArrheniusSettings, context: LawContext, /) -> Arrhenius:
        if not settings.T_ref + settings.T_offset > 0.0:
            raise ConfigError(f"config key '{context.key}.T_offset': T_ref + T_offset must be > 0, got "
                              f"{settings.T_ref + settings.T_offset}")
        return cls(settings)

    def __call__(self, state: FlowState) -> Any:
        s = self.settings
        reference = (s.E + s.V * s.depth_ref) / (s.T_ref + s.T_offset)
        # T below -T_offset (undershoots) would flip the sign: floor the absolute temperature.
        absolute = ufl.max_value(state.T + s.T_offset, 1e-3 * (s.T_ref + s.T_offset))
        return s.eta0 * ufl.exp((s.E + s.V * state.depth) / absolute - reference)


@dataclass(frozen=True)
class DepthTableSettings:
    table: tuple[tuple[float, float], ...] = param(kind="table", help="[[depth, factor], ...] with increasing depths")
    eta0: float = param(1.0, exclusive_minimum=0.0, help="viscosity scale")


@dataclass(frozen=True)
class DepthTable(ViscosityLawBase):
    name: ClassVar[str] = "depth_table"
    description: ClassVar[str] = "eta = eta0 f(depth), f piecewise linear through [[depth, factor], ...]"
    Settings: ClassVar[type] = DepthTableSettings
    uses: ClassVar[frozenset[str]] = frozenset({"depth"})
    settings: DepthTableSettings

    def __call__(self, state: FlowState) -> Any:
        d, table = state.depth, self.settings.table
        f0 = table[0][1]
        value: Any = ufl.as_ufl(f0)  # constant above the first row, linear between rows, constant below
        for (da, fa), (db, fb) in zip(table, table[1:]):
            s = ufl.min_value(ufl.max_value((d - da) / (db - da), 0.0), 1.0)
            value = value + (fb - fa) * s
        return self.settings.eta0 * value


@dataclass(frozen=True)
class PowerLawSettings:
    n: float = param(exclusive_minimum=0.0, help="stress exponent (1: linear)")
    eta0: float = param(1.0, exclusive_minimum=0.0, help="viscosity at the reference strain rate")
    reference_strain_rate: float = param(1.0, exclusive_minimum=0.0, help="eps_ref")
    gamma_T: float = param(0.0, minimum=0.0, help="ln of the thermal contrast of the prefactor")
    gamma_z: float = param(0.0, minimum=0.0, help="ln of the depth contrast of the prefactor")
    strain_rate_floor: float = param(DEFAULT_STRAIN_RATE_FLOOR, exclusive_minimum=0.0, help="eps_II is at least this")


@dataclass(frozen=True)
class PowerLaw(ViscosityLawBase):
    name: ClassVar[str] = "power_law"
    description: ClassVar[str] = ("eta = eta0 (eps_II/eps_ref)^((1-n)/n) exp((-gamma_T T + gamma_z d)/n) "
                                  "(dislocation creep)")
    Settings: ClassVar[type] = PowerLawSettings
    settings: PowerLawSettings

    @property
    def uses(self) -> frozenset[str]:  # type: ignore[override]
        s = self.settings
        out = {"strain_rate"} if s.n != 1.0 else set()
        return frozenset(out | ({"temperature"} if s.gamma_T else set()) | ({"depth"} if s.gamma_z else set()))

    def __call__(self, state: FlowState) -> Any:
        s = self.settings
        eta: Any = ufl.as_ufl(s.eta0)
        if s.n != 1.0:
            e = strain_rate_measure(state, "second_invariant", s.strain_rate_floor)
            eta = eta * (e / s.reference_strain_rate) ** ((1.0 - s.n) / s.n)
        exponent: Any = 0.0
        if s.gamma_T:
            exponent = -s.gamma_T * state.T
        if s.gamma_z:
            exponent = exponent + s.gamma_z * state.depth
        if not isinstance(exponent, float):
            eta = eta * ufl.exp(exponent / s.n)
        return eta


@dataclass(frozen=True)
class CompositeSettings:
    laws: tuple[LawSettings, ...] = param(kind="laws", help="the creep laws combined")


@dataclass(frozen=True)
class Composite(ViscosityLawBase):
    name: ClassVar[str] = "composite"
    description: ClassVar[str] = "1/eta = sum_i 1/eta_i (e.g. diffusion + dislocation creep)"
    Settings: ClassVar[type] = CompositeSettings
    settings: CompositeSettings
    laws: tuple[ViscosityLawBase, ...]

    @classmethod
    def build(cls, settings: CompositeSettings, context: LawContext, /) -> Composite:
        return cls(settings, tuple(make_law(law, context.at(f"laws[{i}]")) for i, law in enumerate(settings.laws)))

    def children(self) -> tuple[ViscosityLawBase, ...]:
        return self.laws

    def __call__(self, state: FlowState) -> Any:
        inverse: Any = 0.0
        for law in self.laws:
            inverse = inverse + 1.0 / law(state)
        return 1.0 / inverse


class _OfOneLaw(ViscosityLawBase):
    """A law that changes another one: its settings' ``law``, built as its ``law``."""

    law: ViscosityLawBase

    @classmethod
    def build(cls, settings: Any, context: LawContext, /) -> ViscosityLawBase:
        return cls(settings=settings, law=make_law(settings.law, context.at("law")))  # type: ignore[call-arg]

    def children(self) -> tuple[ViscosityLawBase, ...]:
        return (self.law,)


@dataclass(frozen=True)
class WeakenedSettings:
    law: LawSettings = param(kind="law", help="the law weakened")
    weakening: Weakening = param(kind="weakening", help="{field, start, end, factor}")


@dataclass(frozen=True)
class Weakened(_OfOneLaw):
    name: ClassVar[str] = "weakened"
    description: ClassVar[str] = "eta = w(e) eta_law: a viscous law weakened linearly by an accumulated strain e"
    Settings: ClassVar[type] = WeakenedSettings
    settings: WeakenedSettings
    law: ViscosityLawBase

    def field_names(self) -> tuple[str, ...]:
        return (self.settings.weakening.field,)

    def __call__(self, state: FlowState) -> Any:
        return self.settings.weakening(state) * self.law(state)


@dataclass(frozen=True)
class DamagedSettings:
    law: LawSettings = param(kind="law", help="the law damaged")
    field: str = param("damage", help="the damage field")
    residual: float = param(1e-3, exclusive_minimum=0.0, maximum=1.0, help="the factor at full damage")


@dataclass(frozen=True)
class Damaged(_OfOneLaw):
    name: ClassVar[str] = "damaged"
    description: ClassVar[str] = "eta = max(1 - D, residual) eta_law: damage D in [0, 1] (a named field) weakens"
    Settings: ClassVar[type] = DamagedSettings
    settings: DamagedSettings
    law: ViscosityLawBase

    def field_names(self) -> tuple[str, ...]:
        return (self.settings.field,)

    def __call__(self, state: FlowState) -> Any:
        field = self.settings.field
        if field not in state.fields:
            raise ValueError(f"viscosity law 'damaged' needs the mesh field {field!r}; have {sorted(state.fields)}")
        return ufl.max_value(1.0 - state.fields[field], self.settings.residual) * self.law(state)


# ---------------------------------------------------------------------- yield laws
class _Yield(ViscosityLawBase):
    """A yield viscosity ``eta_star + sigma_y / (2 eps_II)`` (or ``/ |eps|``); its settings have
    ``eta_star``, ``strain_rate_measure``, ``strain_rate_floor`` and ``weakening``."""

    settings: Any

    def sigma_y(self, state: FlowState) -> Any:  # pragma: no cover - abstract
        raise NotImplementedError

    def __call__(self, state: FlowState) -> Any:
        s = self.settings
        e = strain_rate_measure(state, s.strain_rate_measure, s.strain_rate_floor)
        scale = STRAIN_RATE_MEASURES[s.strain_rate_measure].yield_scale
        return s.eta_star + self.sigma_y(state) / (scale * e)

    def inverse(self, state: FlowState) -> Any:
        """``1 / eta_y``, written so that it is 0 (and smooth) at rest."""
        s = self.settings
        e = strain_rate_measure(state, s.strain_rate_measure, s.strain_rate_floor)
        scale = STRAIN_RATE_MEASURES[s.strain_rate_measure].yield_scale
        return scale * e / (s.eta_star * scale * e + self.sigma_y(state))

    def field_names(self) -> tuple[str, ...]:
        return (self.settings.weakening.field,) if self.settings.weakening is not None else ()


_MEASURES = Names(STRAIN_RATE_MEASURES)
_ETA_STAR = "viscosity added to the yield viscosity"
_FLOOR = "the strain-rate measure is at least this"


@dataclass(frozen=True)
class VonMisesSettings:
    yield_stress: float = param(exclusive_minimum=0.0, help="yield stress sigma_y")
    eta_star: float = param(0.0, minimum=0.0, help=_ETA_STAR)
    strain_rate_measure: str = param("second_invariant", choices=_MEASURES, help="eps_II or |eps|")
    strain_rate_floor: float = param(DEFAULT_STRAIN_RATE_FLOOR, exclusive_minimum=0.0, help=_FLOOR)
    weakening: Weakening | None = param(None, kind="weakening", help=WEAKENING_HELP + "; weakens the yield stress")


@dataclass(frozen=True)
class VonMises(_Yield):
    name: ClassVar[str] = "von_mises"
    description: ClassVar[str] = "eta_y = eta_star + sigma_y / (2 eps_II) (or / |eps|): a constant yield stress"
    Settings: ClassVar[type] = VonMisesSettings
    uses: ClassVar[frozenset[str]] = frozenset({"strain_rate"})
    settings: VonMisesSettings

    def sigma_y(self, state: FlowState) -> Any:
        sigma: Any = ufl.as_ufl(self.settings.yield_stress)
        if self.settings.weakening is not None:
            sigma = self.settings.weakening(state) * sigma
        return sigma


@dataclass(frozen=True)
class DruckerPragerSettings:
    cohesion: float = param(minimum=0.0, help="cohesion C")
    friction_angle: float = param(minimum=0.0, exclusive_maximum=90.0, help="friction angle phi in degrees")
    lithostatic_gradient: float = param(0.0, minimum=0.0,
                                        help="p' = p + this x depth: the lithostatic part of the pressure")
    eta_star: float = param(0.0, minimum=0.0, help=_ETA_STAR)
    strain_rate_measure: str = param("second_invariant", choices=_MEASURES, help="eps_II or |eps|")
    strain_rate_floor: float = param(DEFAULT_STRAIN_RATE_FLOOR, exclusive_minimum=0.0, help=_FLOOR)
    weakening: Weakening | None = param(None, kind="weakening", help=WEAKENING_HELP)
    weaken: tuple[str, ...] = param(("cohesion", "friction_angle"), choices=("cohesion", "friction_angle"),
                                    help="what the weakening scales")


@dataclass(frozen=True)
class DruckerPrager(_Yield):
    name: ClassVar[str] = "drucker_prager"
    description: ClassVar[str] = ("eta_y = eta_star + sigma_y / (2 eps_II), sigma_y = C cos(phi) + max(p, 0) "
                                  "sin(phi) (2D; ASPECT's 3D form)")
    Settings: ClassVar[type] = DruckerPragerSettings
    uses: ClassVar[frozenset[str]] = frozenset({"strain_rate", "pressure", "depth"})
    settings: DruckerPragerSettings

    @classmethod
    def build(cls, settings: DruckerPragerSettings, context: LawContext, /) -> DruckerPrager:
        if settings.cohesion == 0.0 and settings.friction_angle == 0.0:
            raise ConfigError(f"config key '{context.key}.cohesion': a zero cohesion needs a friction angle > 0")
        return cls(settings)

    def sigma_y(self, state: FlowState) -> Any:
        if state.pressure is None:
            raise ValueError("viscosity law 'drucker_prager' needs the pressure, which the caller did not provide")
        s = self.settings
        w = s.weakening(state) if s.weakening is not None else None
        cohesion: Any = ufl.as_ufl(s.cohesion)
        phi: Any = ufl.as_ufl(math.radians(s.friction_angle))
        if w is not None and "cohesion" in s.weaken:
            cohesion = w * cohesion
        if w is not None and "friction_angle" in s.weaken:
            phi = w * phi
        pressure = state.pressure
        if s.lithostatic_gradient:
            pressure = pressure + s.lithostatic_gradient * state.depth
        pressure = ufl.max_value(pressure, 0.0)
        if state.gdim == 3:
            return 6.0 * (cohesion * ufl.cos(phi) + pressure * ufl.sin(phi)) / (math.sqrt(3.0) * (3.0 + ufl.sin(phi)))
        return cohesion * ufl.cos(phi) + pressure * ufl.sin(phi)


@dataclass(frozen=True)
class ViscoPlasticSettings:
    viscous: LawSettings = param(kind="law", help="the viscous law")
    plastic: LawSettings = param(kind="law", help="a yield law: von_mises or drucker_prager")
    combination: str = param("tosi", choices=Names(COMBINATIONS), help="how the two are combined")


@dataclass(frozen=True)
class ViscoPlastic(ViscosityLawBase):
    name: ClassVar[str] = "viscoplastic"
    description: ClassVar[str] = "a viscous law and a yield law combined: tosi (2/(1/a+1/b)), minimum or harmonic"
    Settings: ClassVar[type] = ViscoPlasticSettings
    settings: ViscoPlasticSettings
    viscous: ViscosityLawBase
    plastic: ViscosityLawBase

    @classmethod
    def build(cls, settings: ViscoPlasticSettings, context: LawContext, /) -> ViscoPlastic:
        viscous = make_law(settings.viscous, context.at("viscous"))
        plastic = make_law(settings.plastic, context.at("plastic"))
        if not isinstance(plastic.law if isinstance(plastic, Bounded) else plastic, _Yield):
            raise ConfigError(f"config key '{context.key}.plastic': must be a yield law (von_mises or "
                              f"drucker_prager), got {plastic.name!r}")
        return cls(settings, viscous, plastic)

    def children(self) -> tuple[ViscosityLawBase, ...]:
        return (self.viscous, self.plastic)

    def __call__(self, state: FlowState) -> Any:
        if state.elastic is not None:  # visco-elasto-plastic (only the minimum combination is accepted then)
            eta_v = self.viscous(state)
            return ufl.min_value(eta_v, self.maxwell_yield(state, eta_v))
        return COMBINATIONS[self.settings.combination].combine(self.viscous(state), self.plastic, state)

    def maxwell_yield(self, state: FlowState, eta_v: Any, /) -> Any:
        """With elasticity (``state.elastic``): the viscosity ``eta_p`` whose visco-elastic viscosity
        ``eta_p / (1 + eta_p r / G)`` gives the yield stress at the effective strain rate ``eps_eff =
        eps + r tau^n / (2 G)``: ``eta_vep = sigma_y / (2 eps_eff)``, or with ``eta_star > 0`` (a
        viscoplastic regularisation of the plastic strain rate, ``tau_II = sigma_y + 2 eta_star
        eps_pl``) ``eta_vep = eta_ve eta_y / (eta_ve + eta_star)`` with ``eta_y = eta_star + sigma_y /
        (2 eps_eff)``; then ``eta_p = eta_vep / (1 - eta_vep r / G)`` (the denominator floored;
        docs/rheology.md, "Visco-elasto-plasticity")."""
        trial = state.elastic
        if trial is None:
            raise ValueError("maxwell_yield needs the elastic trial state")
        effective = state._replace(strain_rate=state.strain_rate + (trial.rate / (2.0 * trial.modulus)) * trial.stress)
        eta_vep = self.plastic(effective)
        plastic = self.plastic.law if isinstance(self.plastic, Bounded) else self.plastic
        star = getattr(plastic.settings, "eta_star", 0.0)
        if star:
            eta_ve = eta_v / (1.0 + eta_v * trial.rate / trial.modulus)
            eta_vep = eta_ve * eta_vep / (eta_ve + star)
        return eta_vep / ufl.max_value(1.0 - eta_vep * trial.rate / trial.modulus, MAXWELL_FLOOR)

    def yielding(self, state: FlowState) -> Any:
        """UFL condition: the yield law limits the stress here (with elasticity: the visco-elastic one)."""
        if state.elastic is not None:
            eta_v = self.viscous(state)
            return ufl.lt(self.maxwell_yield(state, eta_v), eta_v)
        return ufl.lt(self.plastic(state), self.viscous(state))


@dataclass(frozen=True)
class Bounded(ViscosityLawBase):
    """A law clipped to ``[min_viscosity, max_viscosity]`` (either may be None): what
    :func:`make_law` makes of a law with bounds (:class:`LawSettings`)."""

    name: ClassVar[str] = "bounded"
    description: ClassVar[str] = "a law clipped to [min_viscosity, max_viscosity] (any law's min_/max_viscosity keys)"
    law: ViscosityLawBase
    min_viscosity: float | None = None
    max_viscosity: float | None = None

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
"""Registry of viscosity laws (config name -> law class): ``VISCOSITY_LAWS.build(name, settings, context)``."""


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
