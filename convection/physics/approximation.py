"""Nondimensional Boussinesq approximation: material parameters and constitutive laws.

Equations (``e_up`` the "up" direction, against gravity: ``e_z``, the last coordinate axis, in a
box; ``x / |x|``, away from the origin, in shells and sectors: the domain's
:mod:`convection.geometry.gravity`)::

    -div(2 eta(T, C) eps(u)) + grad p = (Ra T - sum_i Rb_i C_i) e_up,      div u = 0,
    dT/dt + u . grad T = lap T + H,

with ``eps(u) = (grad u + grad u^T) / 2``, thermal Rayleigh number ``Ra``, compositional (buoyancy)
Rayleigh numbers ``Rb_i`` of the materials with volume fractions ``C_i`` (one material: ``Rb C``),
nondimensional internal heating ``H`` and viscosity ``eta(T, C)`` given by a
:class:`ViscosityLaw`.
"""

from __future__ import annotations

from dataclasses import dataclass
from collections.abc import Callable, Mapping
from typing import Any

import ufl

from fembase.registry import Registry
from convection.geometry.gravity import Gravity, VerticalGravity
from convection.physics.compressible import (
    APPROXIMATIONS, EnergyTerms, Formulation, ReferenceSettings, ReferenceState, shear_heating,
)
from convection.schema import Names, param, subsection
from convection.physics.elasticity import Elasticity, ElasticitySettings
from convection.physics.phases import PhaseTransitions
from convection.physics.rheology import (
    Constant, ElasticTrial, FlowState, ViscosityLawBase, laws_field_names, strain_rate_measure, yield_law,
)


def _geometric(eta0: Any, etas: list[Any], cs: list[Any], background: Any, closed_form: bool) -> Any:
    if closed_form:  # numbers: eta0 exp(sum C ln(eta / eta0))
        return eta0 * ufl.exp(_sum([c * ufl.ln(e / eta0) for c, e in zip(cs, etas)]))
    return ufl.exp(background * ufl.ln(eta0) + _sum([c * ufl.ln(e) for c, e in zip(cs, etas)]))


def _arithmetic(eta0: Any, etas: list[Any], cs: list[Any], background: Any, closed_form: bool) -> Any:
    return background * eta0 + _sum([c * e for c, e in zip(cs, etas)])


def _harmonic(eta0: Any, etas: list[Any], cs: list[Any], background: Any, closed_form: bool) -> Any:
    return 1.0 / (background / eta0 + _sum([c / e for c, e in zip(cs, etas)]))


@dataclass(frozen=True)
class MixingRule:
    """A volume-fraction mixture of viscosities: ``mix(eta0, etas, cs, background, closed_form)``
    of the background's ``eta0``, the materials' ``etas`` with fractions ``cs`` (clipped to [0, 1])
    and the background's fraction ``1 - sum(cs)`` (UFL; ``closed_form``: the viscosities are
    numbers)."""

    name: str
    description: str
    mix: Callable[[Any, list[Any], list[Any], Any, bool], Any]


MIXING_RULES: Registry[MixingRule] = Registry("viscosity mixing rule", (
    MixingRule("geometric", "eta = eta_0^(1-C) * eta_1^C", _geometric),
    MixingRule("arithmetic", "eta = (1-C) eta_0 + C eta_1", _arithmetic),
    MixingRule("harmonic", "1/eta = (1-C)/eta_0 + C/eta_1", _harmonic),
))
"""Registry of composition mixing rules."""

@dataclass(frozen=True)
class TemperatureDependence:
    """A factor ``factor(gamma, T)`` the mixed viscosity is multiplied by (None: no factor)."""

    name: str
    description: str
    factor: Callable[[float, Any], Any] | None


def _frank_kamenetskii(gamma: float, T: Any) -> Any:
    return ufl.exp(-gamma * T)


TEMPERATURE_LAWS: Registry[TemperatureDependence] = Registry("viscosity temperature law", (
    TemperatureDependence("none", "no temperature dependence", None),
    TemperatureDependence("frank_kamenetskii", "eta *= exp(-gamma T)", _frank_kamenetskii),
))
"""Registry of temperature dependences of the classic viscosity keys."""


def _check_name(name: str, registry: Mapping[str, Any], what: str) -> None:
    if name not in registry:
        raise ValueError(f"Unknown {what} {name!r}; valid names: {sorted(registry)}")


def _as_ufl(value: Any) -> Any:
    """Return ``value`` as something UFL algebra accepts (``None`` -> 0)."""
    if value is None:
        return ufl.as_ufl(0.0)
    if isinstance(value, (int, float)):
        return ufl.as_ufl(float(value))
    return value


def fractions(C: Any) -> tuple[Any, ...]:
    """The material fractions ``(C_1, ..., C_n)`` of a composition argument.

    ``C`` is ``None`` (no material: ``()``), one field/expression/number (one material, the
    two-material case ``C`` / ``1 - C``) or a sequence of them (one per material).
    """
    if C is None:
        return ()
    if isinstance(C, (list, tuple)):
        return tuple(C)
    return (C,)


@dataclass(frozen=True)
class ViscositySettings:
    """The ``physics.viscosity`` config section: the classic keys (numbers per material, their
    mixing and temperature dependence) or a law. The defaults of :class:`ViscosityLaw` and
    :class:`~convection.physics.materials.Materials` come from here."""

    material_viscosities: tuple[float, ...] | None = param(
        None, length=(2,), exclusive_minimum=0.0,
        help="[eta of C=0 material, eta of C=1 material] (with initial.composition)")
    background: float = param(1.0, exclusive_minimum=0.0,
                              help="viscosity of the background material (with the materials section)")
    mixing: str = param("geometric", choices=Names(MIXING_RULES),
                        help="volume-fraction weighted mixing of the material viscosities")
    sharp: tuple[str, ...] = param((), help="materials (by name) that enter the viscosity by threshold, not by "
                                           "mixing: a cell (point) at least half of them takes their viscosity, any "
                                           "other the mixture of the rest, renormalised (e.g. [air]: sticky air's "
                                           "thin film on a plate then does not weaken the plate's whole top cell)")
    temperature_law: str = param("none", choices=Names(TEMPERATURE_LAWS),
                                 help="temperature dependence of the material viscosities (older than law)")
    gamma: float = param(0.0, minimum=0.0, help="eta *= exp(-gamma T) for frank_kamenetskii")
    law: Any | None = param(None, help="the background material's viscosity law: a number or {name: <law>, ...} "
                                       "(convection.physics.rheology: constant, exponential, arrhenius, depth_table, "
                                       "power_law, composite, von_mises, drucker_prager, viscoplastic, weakened, "
                                       "damaged; any law may add min_viscosity, max_viscosity)")


@dataclass(frozen=True)
class PhysicsSettings:
    """The ``physics`` config section: the nondimensional numbers and the viscosity."""

    Ra: float | None = param(None, minimum=0.0, help="thermal Rayleigh number (required with the energy equation; "
                                                     "with units: from scaling.thermal_expansivity)")
    Rb: float = param(0.0, help="compositional Rayleigh number (body force (Ra T - Rb C) e_up)")
    H: float = param(0.0, help="internal heating")
    viscosity: ViscositySettings = subsection(ViscositySettings)
    approximation: str = param("boussinesq", choices=Names(APPROXIMATIONS),
                               help="the equations: boussinesq, eba (adiabatic and shear heating), tala (also a "
                                    "reference density) or ala (also the pressure's buoyancy; docs/compressible.md)")
    reference: ReferenceSettings = subsection(ReferenceSettings)
    elasticity: ElasticitySettings = subsection(ElasticitySettings)  # issue 48


VISCOSITY_DEFAULTS = ViscositySettings()


@dataclass(frozen=True)
class ViscosityLaw:
    """Viscosity law ``eta(T, C_1, ..., C_n)``: one :mod:`convection.physics.rheology` law per
    material, mixed.

    The domain holds a background material and ``n`` materials with volume fractions ``C_i``
    (clipped to ``[0, 1]``; the background has ``C_0 = 1 - sum_i C_i``). Their viscosities are
    mixed, weighted by volume fraction, by ``mixing``::

        arithmetic:  eta = C_0 eta_0 + sum_i C_i eta_i
        geometric:   eta = exp(C_0 ln eta_0 + sum_i C_i ln eta_i)
        harmonic:    1 / eta = C_0 / eta_0 + sum_i C_i / eta_i

    With one material this is the classic two-material rule in ``C`` and ``1 - C``. Where every
    law is a plain number (:class:`~convection.physics.rheology.Constant`), the mixture is the
    closed form of those numbers (equal numbers: that number; geometric:
    ``eta_0 exp(sum_i C_i ln(eta_i / eta_0))``), which needs neither the flow nor the position.

    Attributes:
        material_viscosities: ``(eta_0, eta_1, ..., eta_n)``, numbers in place of ``laws``: each
            becomes a :class:`~convection.physics.rheology.Constant` law. With neither, the
            viscosity is 1.
        mixing: name in :data:`MIXING_RULES` (``"geometric"`` | ``"arithmetic"`` | ``"harmonic"``).
        temperature_law: name in :data:`TEMPERATURE_LAWS` (``"none"`` | ``"frank_kamenetskii"``,
            which multiplies the mixed viscosity by ``exp(-gamma T)``).
        gamma: Frank-Kamenetskii parameter (``ln`` of the thermal viscosity contrast).
        laws: ``(law_0, law_1, ..., law_n)``: a law per material (background first), in the
            order of the fractions passed to :meth:`__call__`; made from ``material_viscosities``
            when not given.
        gravity: along which the laws' depth is measured (:mod:`convection.geometry.gravity`:
            ``z_top - z`` in a box, ``r_outer - |x|`` in a shell).
        sharp: indices ``i >= 1`` of the materials (in the order of ``laws``; 0, the background,
            cannot be one) that enter by threshold instead of by mixing. With ``S = sum_{i in sharp}
            C_i``: where ``S >= 1/2`` the viscosity is the mixture of the sharp materials alone
            (fractions ``C_i / S``), elsewhere the mixture of the others (fractions ``C_j / (1 - S)``,
            background ``C_0 / (1 - S)``). The volume fractions themselves (and so the buoyancy) are
            unchanged. Meant for sticky air: a surface lowered by a few km into a 25 km cell makes
            it ~10 % air, and the geometric mean then weakens the whole cell by ``10^(0.1 * 4)``.
    """

    material_viscosities: tuple[float, ...] | None = None
    mixing: str = VISCOSITY_DEFAULTS.mixing
    temperature_law: str = VISCOSITY_DEFAULTS.temperature_law
    gamma: float = VISCOSITY_DEFAULTS.gamma
    laws: tuple[ViscosityLawBase, ...] | None = None
    gravity: Gravity = VerticalGravity()
    sharp: tuple[int, ...] = ()

    def __post_init__(self) -> None:
        _check_name(self.mixing, MIXING_RULES, "viscosity mixing rule")
        _check_name(self.temperature_law, TEMPERATURE_LAWS, "viscosity temperature law")
        if self.material_viscosities is not None:
            if len(self.material_viscosities) < 2 or min(self.material_viscosities) <= 0.0:
                raise ValueError("material_viscosities must be at least two positive numbers (eta_0, eta_1, ...)")
            if self.laws is not None:
                raise ValueError("give either material_viscosities or laws, not both")
            object.__setattr__(self, "laws", tuple(Constant.of(v) for v in self.material_viscosities))
        elif self.laws is None:
            object.__setattr__(self, "laws", (Constant.of(1.0),))
        if not self.laws:
            raise ValueError("laws needs at least the background material's law")
        if any(not 1 <= i < len(self.laws) for i in self.sharp) or len(set(self.sharp)) != len(self.sharp):
            raise ValueError(f"sharp must name distinct materials 1..{len(self.laws) - 1} (not the background), "
                             f"got {self.sharp}")

    @property
    def is_nonlinear(self) -> bool:
        """True when the viscosity depends on the flow (strain rate or pressure)."""
        return any(law.is_nonlinear for law in self.laws)

    @property
    def depends_on(self) -> frozenset[str]:
        """What the laws read (``"temperature"``, ``"strain_rate"``, ``"pressure"``, ``"depth"``,
        ``"field:<name>"``): the union over the background and the materials."""
        return frozenset().union(*(law.depends_on for law in self.laws))

    @property
    def field_names(self) -> tuple[str, ...]:
        """Named mesh fields the laws read (e.g. ``plastic_strain``)."""
        return laws_field_names(self.laws)

    def depth(self, x: Any, /) -> Any:
        """UFL depth below the top surface at the points ``x`` (``ufl.SpatialCoordinate``)."""
        return self.gravity.depth(x)

    @property
    def numbers(self) -> tuple[float, ...] | None:
        """The viscosities when every law is a plain number (:class:`Constant`), else None."""
        if all(type(law) is Constant for law in self.laws):
            return tuple(law.settings.eta0 for law in self.laws)
        return None

    @property
    def is_constant(self) -> bool:
        """True when ``eta`` depends on neither ``T`` nor ``C`` (nor on the flow or a field)."""
        temperature_free = TEMPERATURE_LAWS[self.temperature_law].factor is None or self.gamma == 0.0
        # Only plain constants are known to be equal (a clipped constant counts as variable).
        values = {law.constant_value() for law in self.laws}
        return None not in values and len(values) == 1 and temperature_free

    def __call__(self, T: Any, C: Any, /, *, u: Any = None, p: Any = None,
                 fields: Mapping[str, Any] | None = None, x: Any = None, elastic: ElasticTrial | None = None) -> Any:
        """UFL expression of the viscosity for temperature ``T`` and composition ``C``
        (see :func:`fractions`; one fraction per material after the background), and of the
        velocity ``u`` (its strain rate), the pressure ``p``, the named ``fields`` and the position
        ``x`` (``ufl.SpatialCoordinate``, for the depth) for the laws that read them (a law that
        needs one fails without it). ``elastic``: with Maxwell elasticity, what the visco-plastic
        laws need to limit the visco-elastic stress (:meth:`ViscoPlastic.maxwell_yield`), or None."""
        numbers = self.numbers
        if numbers is not None:
            eta = self._mixed_numbers(numbers, C)
        else:
            eta = self._mixed_laws(T, C, u=u, p=p, fields=fields or {}, x=x, elastic=elastic)
        factor = TEMPERATURE_LAWS[self.temperature_law].factor
        if factor is not None and self.gamma != 0.0:
            eta = eta * factor(self.gamma, _as_ufl(T))
        return eta

    def _mixed_numbers(self, numbers: tuple[float, ...], C: Any) -> Any:
        eta0, *etas = numbers
        if all(e == eta0 for e in etas):
            return ufl.as_ufl(eta0)
        return self._mix(eta0, etas, C, closed_form=True)

    @property
    def yields(self) -> bool:
        """True when some material has a visco-plastic law (it can yield)."""
        return self.laws is not None and any(yield_law(law) is not None for law in self.laws)

    def rate_fields(self) -> dict[str, Any]:
        """The rates this rheology provides for particles to integrate, by name: ``f(T, C, *, u, p,
        fields, x) -> UFL`` (``plastic_strain_rate``: :meth:`plastic_strain_rate`, of a rheology
        that can yield; it refuses one that cannot when evaluated)."""
        return {"plastic_strain_rate": self._yielding_rate}

    def _yielding_rate(self, T: Any, C: Any, /, *, u: Any, p: Any, fields: Mapping[str, Any], x: Any,
                       elastic: ElasticTrial | None = None) -> Any:
        if not self.yields:
            raise ValueError("particle property plastic_strain needs a material with a viscoplastic law "
                             "(it accumulates strain where the material yields)")
        return self.plastic_strain_rate(T, C, u=u, p=p, fields=fields, x=x, elastic=elastic)

    def plastic_strain_rate(self, T: Any, C: Any, /, *, u: Any, p: Any, fields: Mapping[str, Any], x: Any,
                            elastic: ElasticTrial | None = None) -> Any:
        """UFL ``eps_II sum_l C_l [eta_yield,l < eta_viscous,l]``: the strain rate where the
        visco-plastic laws yield (their yield viscosity below the viscous one), weighted by the
        volume fractions ``C_l`` (background ``C_0 = 1 - sum_i C_i``); what ``plastic_strain``
        particles integrate (with ``elastic``, where the visco-elastic stress yields)."""
        state = self._state(T, u, p, fields, x, elastic)
        cs = [ufl.min_value(ufl.max_value(_as_ufl(c), 0.0), 1.0) for c in fractions(C)]
        weights = [1.0 - _sum(cs) if cs else ufl.as_ufl(1.0), *cs]
        if len(weights) != len(self.laws):
            raise ValueError(f"the viscosity law has {len(self.laws) - 1} material(s), got {len(cs)} fraction(s)")
        rate: Any = ufl.as_ufl(0.0)
        for weight, law in zip(weights, self.laws):
            vp = yield_law(law)
            if vp is not None:
                rate = rate + weight * ufl.conditional(vp.yielding(state), 1.0, 0.0)
        return rate * strain_rate_measure(state, "second_invariant", 0.0)

    def _state(self, T: Any, u: Any, p: Any, fields: Mapping[str, Any], x: Any,
               elastic: ElasticTrial | None = None) -> FlowState:
        if x is None:
            raise ValueError("viscosity laws need the spatial coordinate x (for the depth)")
        return FlowState(T=_as_ufl(T), strain_rate=ufl.sym(ufl.grad(u)) if u is not None else None,
                         pressure=p, depth=self.depth(x), fields=fields, gdim=x.ufl_shape[0], elastic=elastic)

    def _mixed_laws(self, T: Any, C: Any, *, u: Any, p: Any, fields: Mapping[str, Any], x: Any,
                    elastic: ElasticTrial | None) -> Any:
        state = self._state(T, u, p, fields, x, elastic)
        law0, *others = self.laws
        eta0 = law0(state)
        if not others:
            return eta0
        return self._mix(eta0, [law(state) for law in others], C, closed_form=False)

    def _mix(self, eta0: Any, etas: list[Any], C: Any, *, closed_form: bool) -> Any:
        """The volume-fraction mixture of the background's ``eta0`` and the materials' ``etas``
        (``closed_form``: numbers, the geometric mean as ``eta0 exp(sum C ln(eta / eta0))``)."""
        cs = fractions(C)
        if len(cs) != len(etas):
            raise ValueError(f"the viscosity law has {len(etas)} material(s), got {len(cs)} fraction(s)")
        cs = [ufl.min_value(ufl.max_value(_as_ufl(c), 0.0), 1.0) for c in cs]
        background = 1.0 - _sum(cs)
        mix = MIXING_RULES[self.mixing].mix
        if not self.sharp:
            return mix(eta0, etas, cs, background, closed_form)
        # Threshold on the sharp materials' total S; each side mixes its own materials, renormalised.
        sharp = set(self.sharp)
        total = _sum([c for i, c in enumerate(cs, start=1) if i in sharp])
        inside = ufl.max_value(total, 1e-12)
        outside = ufl.max_value(1.0 - total, 1e-12)
        zero = ufl.as_ufl(0.0)
        eta_in = mix(eta0, etas, [c / inside if i in sharp else zero for i, c in enumerate(cs, start=1)], zero,
                     closed_form)
        eta_out = mix(eta0, etas, [zero if i in sharp else c / outside for i, c in enumerate(cs, start=1)],
                      background / outside, closed_form)
        return ufl.conditional(ufl.ge(total, 0.5), eta_in, eta_out)


def _sum(terms: list[Any]) -> Any:
    """``terms[0] + terms[1] + ...`` (left to right, so one term is returned as it is)."""
    total = terms[0]
    for term in terms[1:]:
        total = total + term
    return total


class BoussinesqApproximation:
    """Boussinesq approximation parameters (see the module docstring for the equations).

    Args:
        Ra: thermal Rayleigh number.
        Rb: compositional Rayleigh number (buoyancy ``-Rb C e_z``), or one per material
            (buoyancy ``-sum_i Rb_i C_i e_z``) in the order of the fractions (:func:`fractions`).
        H: nondimensional internal heating rate.
        viscosity: viscosity law ``eta(T, C)``.
        gravity: which way is up (:mod:`convection.geometry.gravity`; the domain's
            :attr:`~convection.geometry.domain.Domain.gravity`).
        formulation: a name in :data:`~convection.physics.compressible.APPROXIMATIONS`
            (``"boussinesq"``, ``"eba"``, ``"tala"``, ``"ala"``): the terms the solvers ask for
            (:meth:`continuity_density`, :meth:`buoyancy`, :meth:`pressure_buoyancy`, :meth:`energy_terms`).
        reference: the reference state of ``eba``, ``tala`` and ``ala`` (``Di > 0``; ``Di = 0`` for ``boussinesq``).
        elasticity: Maxwell visco-elasticity (:mod:`convection.physics.elasticity`, issue 48), or None.
        phases: the phase transitions (:mod:`convection.physics.phases`: buoyancy, latent heat, viscosity).
    """

    def __init__(
        self,
        /,
        *,
        Ra: float,
        Rb: float | tuple[float, ...] = 0.0,
        H: float = 0.0,
        viscosity: ViscosityLaw = ViscosityLaw(),
        gravity: Gravity = VerticalGravity(),
        formulation: str = "boussinesq",
        reference: ReferenceState = ReferenceState(),
        elasticity: Elasticity | None = None,
        phases: PhaseTransitions = PhaseTransitions(),
    ) -> None:
        self.gravity = gravity
        self.phases = phases
        self.elasticity = elasticity
        self.Ra = float(Ra)
        self.Rb: float | tuple[float, ...] = tuple(float(r) for r in Rb) if isinstance(Rb, (list, tuple)) else float(Rb)
        self.H = float(H)
        self.viscosity_law = viscosity
        self.formulation: Formulation = APPROXIMATIONS.lookup(formulation)
        self.reference = reference
        _check_formulation(self)

    @property
    def is_variable_viscosity(self) -> bool:
        """True when the viscosity depends on ``T`` or ``C``."""
        return not self.viscosity_law.is_constant or self.phases.changes_viscosity

    @property
    def is_nonlinear(self) -> bool:
        """True when the viscosity depends on the flow: the Stokes problem is nonlinear."""
        return self.viscosity_law.is_nonlinear

    def viscosity(self, T: Any, C: Any, /, **flow: Any) -> Any:
        """UFL expression of ``eta(T, C)`` (``T``, ``C``: Functions, UFL expressions or numbers);
        ``flow``: ``u``, ``p``, ``fields``, ``x`` for :mod:`convection.physics.rheology` laws (see
        :meth:`ViscosityLaw.__call__`)."""
        eta = self.viscosity_law(T, C, **flow)
        if self.phases.changes_viscosity:
            eta = eta * self.phases.viscosity_factor(_as_ufl(T), self.gravity.depth(flow["x"]), C)
        return eta

    def up(self, x: Any, /) -> Any:
        """UFL unit vector ``e_up`` against gravity at the points ``x`` (``ufl.SpatialCoordinate``)."""
        return self.gravity.up(x)

    def density(self, T: Any, C: Any) -> Any:
        """UFL scalar ``Ra T - sum_i Rb_i C_i``, the buoyancy's magnitude along ``e_up`` (``C = None`` -> 0)."""
        magnitude = self.Ra * _as_ufl(T)
        cs = fractions(C)
        rbs = self.Rb if isinstance(self.Rb, tuple) else (self.Rb,) * len(cs)
        if cs and len(rbs) != len(cs):
            raise ValueError(f"{len(rbs)} compositional Rayleigh number(s) for {len(cs)} material fraction(s)")
        for rb, c in zip(rbs, cs):
            if rb != 0.0:
                magnitude = magnitude - rb * _as_ufl(c)
        return magnitude

    def buoyancy(self, T: Any, C: Any, gdim: int, /, *, x: Any = None) -> Any:
        """UFL vector expression ``(Ra T - sum_i Rb_i C_i) e_up`` of length ``gdim`` (``C = None`` -> 0).

        ``x``: ``ufl.SpatialCoordinate`` of the mesh."""
        if x is None:
            raise ValueError("the buoyancy needs the spatial coordinate x")
        if x.ufl_shape[0] != gdim:
            raise ValueError(f"x has {x.ufl_shape[0]} components, the buoyancy {gdim}")
        alpha = self.reference.expansivity(self.gravity.depth(x)) if self.formulation.dissipation else None
        magnitude = self.density(T if alpha is None else alpha * _as_ufl(T), C)  # Ra alpha_r T - sum_i Rb_i C_i
        if self.formulation.reference_density:
            magnitude = self.reference.density(self.gravity.depth(x)) * magnitude
        if self.phases.buoyant:
            magnitude = magnitude - self.phases.density(_as_ufl(T), self.gravity.depth(x), C)
        return self.gravity.along_up(magnitude, x)

    @property
    def dissipates(self) -> bool:
        """Whether the energy equation has adiabatic and shear heating (EBA, TALA, ALA)."""
        return self.formulation.dissipation

    def continuity_density(self, x: Any, /) -> Any | None:
        """UFL ``rho_r`` of the continuity equation ``div(rho_r u) = 0`` at the points ``x``, or None
        for ``div u = 0``."""
        return self.reference.density(self.gravity.depth(x)) if self.formulation.reference_density else None

    def pressure_buoyancy(self, x: Any, /) -> Any | None:
        """UFL ``c`` of the ALA's pressure buoyancy ``-c p e_up``, ``c = (Di / gamma) (cp / cv) rho_r``
        at the points ``x``, or None without it."""
        return self.reference.compressibility(self.gravity.depth(x)) if self.formulation.pressure_buoyancy else None

    def energy_terms(self, T_new: Any, T: Any, u: Any, x: Any, /) -> EnergyTerms | None:
        """The energy equation's heat capacity and heating (:class:`~convection.physics.compressible.EnergyTerms`)
        for the unknown temperature ``T_new``, the last temperature ``T`` (the shear heating's viscosity)
        and the velocity ``u``, or None for the Boussinesq ``dT/dt + u . grad T - lap T = H`` (without latent heat)."""
        if not self.formulation.dissipation:
            return self._latent_heat(EnergyTerms(1.0, self.H), T_new, T, u, x) if self.phases.latent else None
        density = self.reference.density(self.gravity.depth(x)) if self.formulation.reference_density else 1.0
        adiabatic, shear = self.heating_rates(T_new, T, u, x)
        heating = shear - adiabatic
        if self.H != 0.0:
            heating = heating + density * self.H
        cp = self.reference.heat_capacity(self.gravity.depth(x))  # None: cp_r = 1
        capacity = density if cp is None else density * cp
        return self._latent_heat(EnergyTerms(capacity, heating), T_new, T, u, x)

    def _latent_heat(self, terms: EnergyTerms, T_new: Any, T: Any, u: Any, x: Any, /) -> EnergyTerms:
        """``terms`` with the phase transitions' latent heat (:mod:`convection.physics.phases`), the
        reference density's weight when the approximation has one."""
        if not self.phases.latent:
            return terms
        rho = self.reference.density(self.gravity.depth(x)) if self.formulation.reference_density else 1.0
        capacity, heating = self.phases.latent_heat(T_new, T, ufl.dot(u, self.up(x)), self.gravity.depth(x), rho)
        return EnergyTerms(terms.capacity + capacity, terms.heating + heating)

    def heating_rates(self, T: Any, T_eta: Any, u: Any, x: Any, /) -> tuple[Any, Any]:
        """UFL ``(Di alpha_r rho_r w (T + T0), (Di / Ra) Phi)``: the adiabatic cooling (the work against
        gravity ``W`` per volume) and the shear heating, ``Phi`` with the viscosity at ``T_eta``."""
        reference = self.reference
        rho = reference.density(self.gravity.depth(x)) if self.formulation.reference_density else 1.0
        w = ufl.dot(u, self.up(x))
        adiabatic = reference.Di * rho * w * (T + reference.surface_temperature)
        alpha = reference.expansivity(self.gravity.depth(x))  # None: alpha_r = 1
        if alpha is not None:
            adiabatic = alpha * adiabatic
        shear = reference.Di / self.Ra * shear_heating(self.viscosity(T_eta, None, x=x), u)
        return adiabatic, shear

    def pressure_work(self, T_eta: Any, u: Any, p: Any, x: Any, /) -> Any:
        """UFL ``P``, what the compression adds to the energy balance: ``Phi - W = <P>``.

        Testing the momentum equation with the velocity gives, with ``Phi`` the shear heating
        ``2 eta (eps : eps - (div u)^2 / 3)`` and ``<alpha_r rho_r w> = 0`` (mass):

        - EBA, TALA (viscous term ``2 eta eps : eps``): ``P = (Di / Ra) (p div u - (2/3) eta (div u)^2)``,
          zero under EBA (``div u = 0``);
        - ALA (the compressible stress, and the pressure buoyancy ``-c p e_up``):
          ``P = (Di / Ra) (p div u - c p w)``.

        ``eta`` at ``T_eta``."""
        div_u = ufl.div(u)
        c = self.pressure_buoyancy(x)
        if c is None:
            work = p * div_u - 2.0 / 3.0 * self.viscosity(T_eta, None, x=x) * div_u * div_u
        else:
            work = p * div_u - c * p * ufl.dot(u, self.up(x))
        return self.reference.Di / self.Ra * work

    def __repr__(self) -> str:
        return (
            f"BoussinesqApproximation(Ra={self.Ra}, Rb={self.Rb}, H={self.H}, "
            f"viscosity={self.viscosity_law}, gravity={self.gravity!r}"
            + (f", formulation={self.formulation.name!r}, reference={self.reference})" if self.dissipates else ")")
        )


HEATING_VISCOSITY = frozenset({"temperature", "depth"})
"""What the viscosity may depend on in the shear heating of this version (no materials, no flow)."""


def _check_formulation(approximation: BoussinesqApproximation) -> None:
    """Refuse an approximation whose reference state or viscosity does not fit its formulation."""
    formulation, Di = approximation.formulation, approximation.reference.Di
    if not formulation.dissipation:
        if Di != 0.0:
            raise ValueError(f"the {formulation.name} approximation has no dissipation number (Di = {Di}); "
                             "use eba, tala or ala")
        return
    if Di == 0.0:
        raise ValueError(f"the {formulation.name} approximation needs a dissipation number Di > 0")
    if approximation.Ra <= 0.0:
        raise ValueError(f"the {formulation.name} approximation needs Ra > 0 (its shear heating is Di / Ra Phi)")
    law = approximation.viscosity_law
    if len(law.laws or ()) > 1 or not law.depends_on <= HEATING_VISCOSITY:
        raise ValueError(f"the {formulation.name} approximation's shear heating needs a viscosity of temperature "
                         "and depth only (no materials, no strain-rate, pressure or field dependence)")
