"""Approximations beyond Boussinesq: the extended Boussinesq (EBA), the truncated anelastic liquid
(TALA) and the anelastic liquid (ALA) approximations, on the nondimensional reference state of King
et al. (2010).

Reference state (``d`` the depth below the top, ``Di = alpha0 g0 h / cp0`` the dissipation number,
``gamma`` the Grueneisen parameter, ``T0 = T_surface / Delta T`` the surface temperature)::

    alpha_r = cp_r = g_r = 1,      rho_r(d) = exp(Di d / gamma),      T_ad(d) = T0 (exp(Di d) - 1)

(``T_ad`` the adiabat's rise above the surface temperature). With a depth-dependent thermal
expansivity and heat capacity (:class:`ReferenceProfile`, relative to their surface values,
``alpha_r(d)``, ``cp_r(d)``; e.g. from physical values in a ``scaling`` set-up) the reference state
is the adiabat (Adams-Williamson with ``K_S = gamma rho cp / alpha``)::

    I(d) = int_0^d alpha_r / cp_r,    rho_r(d) = exp(Di I(d) / gamma),    T_ad(d) = (T_p + T0) exp(Di I(d)) - T0

(``T_p`` the potential temperature, the adiabat's at the surface, 0 by default), and the
equations below take ``alpha_r`` where they have ``alpha`` (buoyancy, adiabatic heating) and
``cp_r`` where they have ``cp`` (the heat capacity). The equations each approximation
solves, ``w = u . e_up`` the velocity against gravity (:mod:`convection.physics.approximation` has
the Boussinesq ones; ``eta`` the viscosity, ``H`` the internal heating)::

    EBA:   div u = 0,                        -div(2 eta eps(u)) + grad p = Ra T e_up,
           DT/Dt + Di w (T + T0) = lap T + (Di / Ra) Phi + H
    TALA:  div(rho_r u) = 0,                 -div(2 eta eps(u)) + grad p = Ra rho_r T e_up,
           rho_r DT/Dt + Di rho_r w (T + T0) = lap T + (Di / Ra) Phi + rho_r H
    ALA:   as TALA, with the dynamic pressure's effect on the density in the buoyancy:
           -div(2 eta eps(u)) + grad p = (Ra rho_r T - (Di / gamma) (cp / cv) rho_r p) e_up

with the shear heating ``Phi = 2 eta (eps(u) : eps(u) - (div u)^2 / 3)`` (the deviatoric stress
times the strain rate). The momentum equation keeps ``2 eta eps(u)``: the compressible stress's
``-(2/3) eta div u I`` is a gradient when ``eta`` is constant and goes into the pressure; with a
variable viscosity leaving it out is an error of order ``Di``. Each approximation is an entry of
:data:`APPROXIMATIONS` that the solvers ask (:class:`Formulation`); ``docs/compressible.md`` has
the derivation.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
import ufl

from convection.schema import param, subsection
from fembase.registry import Registry

__all__ = ["APPROXIMATIONS", "EnergyTerms", "Formulation", "ReferenceProfile", "ReferenceProfileSettings",
           "ReferenceSettings", "ReferenceState", "shear_heating"]


@dataclass(frozen=True)
class ReferenceProfileSettings:
    """The ``physics.reference.profile`` config section: the thermal expansivity and heat capacity
    with depth, piecewise linear through rows (a table, e.g. made with BurnMan; docs/compressible.md)."""

    depth: tuple[float, ...] = param((), help="depths of the rows, increasing (with units: lengths, e.g. "
                                              "[0 km, 660 km, 2890 km]); empty: alpha and cp constant")
    thermal_expansivity: tuple[float, ...] = param((), exclusive_minimum=0.0,
                                                   help="alpha at each depth over the surface's (with units: "
                                                        "1/K, over scaling.thermal_expansivity); empty: 1")
    heat_capacity: tuple[float, ...] = param((), exclusive_minimum=0.0,
                                             help="cp at each depth over the surface's (with units: J/kg/K, "
                                                  "over scaling.heat_capacity); empty: 1")


@dataclass(frozen=True)
class ReferenceSettings:
    """The ``physics.reference`` config section: the nondimensional reference state of the
    compressible approximations (King et al. 2010)."""

    Di: float = param(0.0, minimum=0.0, help="dissipation number alpha g h / cp (with physics.approximation eba, "
                                             "tala or ala; 0 for boussinesq)")
    gruneisen: float = param(1.0, exclusive_minimum=0.0, help="Grueneisen parameter gamma: reference density "
                                                              "exp(Di depth / gamma) (tala, ala)")
    surface_temperature: float = param(0.0, minimum=0.0, help="T0 = T_surface / Delta T: the adiabatic heating "
                                                              "is Di rho w (T + T0) (King et al. 2010: 0.091)")
    heat_capacity_ratio: float = param(1.0, minimum=1.0, help="cp / cv of the pressure's buoyancy "
                                                              "-(Di / gamma) (cp / cv) rho p (ala only; King et al. "
                                                              "2010: 1)")
    potential_temperature: float = param(0.0, help="the adiabat's temperature at the surface, T_p (the "
                                                   "adiabatic_temperature output; with units a temperature, e.g. "
                                                   "1600 K; 0: the surface temperature)")
    profile: ReferenceProfileSettings = subsection(ReferenceProfileSettings)


class _Ops(NamedTuple):
    """min, max and log of UFL or of numpy (:meth:`ReferenceProfile.integral` serves both)."""

    min: Any
    max: Any
    log: Any


UFL_OPS = _Ops(ufl.min_value, ufl.max_value, ufl.ln)
NUMPY_OPS = _Ops(np.minimum, np.maximum, np.log)


@dataclass(frozen=True)
class ReferenceProfile:
    """``alpha_r(d)`` and ``cp_r(d)``, the thermal expansivity and heat capacity over their surface
    values, piecewise linear through the rows ``depth`` (constant above the first and below the last
    row); an empty column is 1, no rows: both 1 (King et al.'s reference state).

    Attributes:
        depth: The rows' depths, increasing.
        thermal_expansivity: ``alpha_r`` at each row (empty: 1).
        heat_capacity: ``cp_r`` at each row (empty: 1).
    """

    depth: tuple[float, ...] = ()
    thermal_expansivity: tuple[float, ...] = ()
    heat_capacity: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        n = len(self.depth)
        for name in ("thermal_expansivity", "heat_capacity"):
            column = getattr(self, name)
            if column and len(column) != n:
                raise ValueError(f"the reference profile has {n} depth(s) but {len(column)} {name.replace('_', ' ')} "
                                 "value(s); give one per depth")
            if any(not v > 0.0 for v in column):
                raise ValueError(f"the reference profile's {name.replace('_', ' ')} must be positive")
        if n and not (self.thermal_expansivity or self.heat_capacity):
            raise ValueError("the reference profile has depths but neither thermal expansivity nor heat capacity")
        if n and not self.depth[0] >= 0.0:
            raise ValueError("the reference profile's first depth must not be above the surface (< 0)")
        if any(not b > a for a, b in zip(self.depth, self.depth[1:])):
            raise ValueError("the reference profile's depths must increase")

    @property
    def varies(self) -> bool:
        """Whether ``alpha_r`` or ``cp_r`` is not 1 somewhere (the equations then take them)."""
        return bool(self.depth)

    def _column(self, name: str) -> tuple[float, ...]:
        return getattr(self, name) or (1.0,) * len(self.depth)

    def value(self, name: str, depth: Any, /, ops: _Ops = UFL_OPS) -> Any:
        """``thermal_expansivity`` or ``heat_capacity`` at ``depth`` (UFL, or numpy with :data:`NUMPY_OPS`)."""
        column = self._column(name)
        value: Any = column[0] + 0.0 * depth
        for (da, fa), (db, fb) in zip(zip(self.depth, column), zip(self.depth[1:], column[1:])):
            value = value + (fb - fa) * ops.min(ops.max((depth - da) / (db - da), 0.0), 1.0)
        return value

    def integral(self, depth: Any, /, ops: _Ops = UFL_OPS) -> Any:
        """``I(d) = int_0^d alpha_r / cp_r``, exact for the piecewise linear columns (UFL, or numpy
        with :data:`NUMPY_OPS`): per row interval, with ``x = cp_r' s / cp_r(start)``,
        ``int_0^s alpha_r / cp_r = (s / c) (a L(x) + alpha_r' s (1 - L(x)) / x)`` (``a``, ``c`` the values at the
        interval's start, ``x = cp_r' s / c``, ``L(x) = ln(1 + x) / x``; as series for ``|x| < 1e-3``)."""
        alpha, cp, d = self._column("thermal_expansivity"), self._column("heat_capacity"), self.depth
        total: Any = alpha[0] / cp[0] * ops.min(depth, d[0]) + alpha[-1] / cp[-1] * ops.max(depth - d[-1], 0.0)
        for i in range(len(d) - 1):
            h = d[i + 1] - d[i]
            s = ops.min(ops.max(depth - d[i], 0.0), h)
            slope_a, slope_c = (alpha[i + 1] - alpha[i]) / h, (cp[i + 1] - cp[i]) / h
            x = slope_c * s / cp[i]
            if abs(slope_c * h / cp[i]) < 1e-3:  # L = ln(1 + x) / x and M = (1 - L) / x as series
                L = 1.0 - x / 2.0 + x * x / 3.0 - x ** 3 / 4.0 + x ** 4 / 5.0
                M = 0.5 - x / 3.0 + x * x / 4.0 - x ** 3 / 5.0
                total = total + s / cp[i] * (alpha[i] * L + slope_a * s * M)
            else:
                total = total + slope_a / slope_c * s + (alpha[i] - slope_a * cp[i] / slope_c) / slope_c \
                    * ops.log(1.0 + x)
        return total


@dataclass(frozen=True)
class ReferenceState:
    """The nondimensional reference state (module docstring): ``alpha_r = cp_r = g_r = 1``, or the
    ``alpha_r(d)``, ``cp_r(d)`` of a :class:`ReferenceProfile` and ``g_r = 1``.

    Attributes:
        Di: Dissipation number.
        gruneisen: Grueneisen parameter ``gamma`` of the reference density ``exp(Di d / gamma)``.
        surface_temperature: ``T0``, the surface temperature over the temperature scale.
        heat_capacity_ratio: ``cp / cv`` in the ALA's pressure buoyancy (0 leaves it out: TALA).
        potential_temperature: ``T_p``, the adiabat's temperature at the surface (:meth:`adiabat`).
        profile: ``alpha_r(d)``, ``cp_r(d)`` (:class:`ReferenceProfile`; none: both 1).
    """

    Di: float = 0.0
    gruneisen: float = 1.0
    surface_temperature: float = 0.0
    heat_capacity_ratio: float = 1.0
    potential_temperature: float = 0.0
    profile: ReferenceProfile = ReferenceProfile()

    @classmethod
    def from_settings(cls, settings: ReferenceSettings, /) -> ReferenceState:
        """The reference state of the ``physics.reference`` section (nondimensional, checked)."""
        return cls(**{**vars(settings), "profile": ReferenceProfile(**vars(settings.profile))})

    def __post_init__(self) -> None:
        if not self.Di >= 0.0:
            raise ValueError(f"the dissipation number Di must not be negative, got {self.Di}")
        if not self.gruneisen > 0.0:
            raise ValueError(f"the Grueneisen parameter must be positive, got {self.gruneisen}")
        if not self.surface_temperature >= 0.0:
            raise ValueError(f"the surface temperature must not be negative, got {self.surface_temperature}")
        if not self.heat_capacity_ratio >= 0.0:
            raise ValueError(f"the heat capacity ratio cp / cv must not be negative, got {self.heat_capacity_ratio}")

    def density(self, depth: Any, /) -> Any:
        """``rho_r = exp(Di depth / gamma)``, with a profile ``exp(Di I(depth) / gamma)`` (UFL or numbers)."""
        if self.profile.varies:
            return ufl.exp(self.Di * self.profile.integral(depth) / self.gruneisen)
        return ufl.exp(self.Di * depth / self.gruneisen)

    def adiabat(self, depth: Any, /) -> Any:
        """``T_ad = T0 (exp(Di depth) - 1)``: the adiabat's rise above the surface (UFL); with a
        potential temperature or a profile ``(T_p + T0) exp(Di I(depth)) - T0``."""
        if self.profile.varies or self.potential_temperature != 0.0:
            T0 = self.surface_temperature
            integral = self.profile.integral(depth) if self.profile.varies else depth
            return (self.potential_temperature + T0) * ufl.exp(self.Di * integral) - T0
        return self.surface_temperature * (ufl.exp(self.Di * depth) - 1.0)

    def adiabat_at(self, depth: Any, /) -> Any:
        """:meth:`adiabat` of numbers or arrays (numpy)."""
        integral = self.profile.integral(np.asarray(depth, dtype=float), NUMPY_OPS) if self.profile.varies else depth
        T0 = self.surface_temperature
        return (self.potential_temperature + T0) * np.exp(self.Di * np.asarray(integral)) - T0

    def expansivity(self, depth: Any, /) -> Any | None:
        """``alpha_r(depth)`` (UFL), or None where it is 1 (no profile: the equations stay King et al.'s)."""
        return self.profile.value("thermal_expansivity", depth) if self.profile.varies else None

    def heat_capacity(self, depth: Any, /) -> Any | None:
        """``cp_r(depth)`` (UFL), or None where it is 1."""
        return self.profile.value("heat_capacity", depth) if self.profile.varies else None

    def compressibility(self, depth: Any, /) -> Any:
        """``(Di / gamma) (cp / cv) rho_r``: the ALA's buoyancy loses this times the dynamic pressure (UFL);
        with a profile times ``alpha_r / cp_r`` (``rho0 chi_S g h = alpha g h / (gamma cp)``)."""
        if self.profile.varies:
            return self.Di / self.gruneisen * self.heat_capacity_ratio * self.density(depth) \
                * self.expansivity(depth) / self.heat_capacity(depth)
        return self.Di / self.gruneisen * self.heat_capacity_ratio * self.density(depth)


@dataclass(frozen=True)
class Formulation:
    """One approximation of the equations, as the solvers ask it.

    Attributes:
        name: Its config name (``physics.approximation``).
        description: One line.
        dissipation: Adiabatic and shear heating enter the energy equation (needs ``Di > 0``).
        reference_density: The reference density weighs the continuity equation (``div(rho_r u)``),
            the buoyancy and the energy equation's heat capacity and internal heating.
        pressure_buoyancy: The dynamic pressure compresses: the buoyancy has the ALA's
            ``-(Di / gamma) (cp / cv) rho_r p e_up`` (:meth:`ReferenceState.compressibility`).
    """

    name: str
    description: str
    dissipation: bool
    reference_density: bool
    pressure_buoyancy: bool = False


APPROXIMATIONS: Registry[Formulation] = Registry("approximation", (
    Formulation("boussinesq", "Boussinesq: div u = 0, no adiabatic or shear heating", False, False),
    Formulation("eba", "extended Boussinesq: div u = 0, with adiabatic and shear heating", True, False),
    Formulation("tala", "truncated anelastic liquid: div(rho_r u) = 0, rho_r in the buoyancy and the energy "
                        "equation, with adiabatic and shear heating", True, True),
    Formulation("ala", "anelastic liquid: tala, and the dynamic pressure's effect on the density in the buoyancy",
                True, True, True),
))
"""The approximations by config name."""


class EnergyTerms(NamedTuple):
    """What an approximation adds to the energy equation ``c (dT/dt + u . grad T) - lap T = q``.

    Attributes:
        capacity: ``c``, the heat capacity per volume (UFL; 1 without a reference density).
        heating: ``q`` (UFL, may hold the unknown temperature linearly): internal, adiabatic and
            shear heating.
    """

    capacity: Any
    heating: Any


def shear_heating(eta: Any, u: Any, /) -> Any:
    """``Phi = 2 eta (eps(u) : eps(u) - (div u)^2 / 3)`` (UFL): the deviatoric stress times the
    strain rate (``1/3`` in 2D too, a plane strain of the 3D stress)."""
    eps = ufl.sym(ufl.grad(u))
    return 2.0 * eta * (ufl.inner(eps, eps) - ufl.div(u) ** 2 / 3.0)
