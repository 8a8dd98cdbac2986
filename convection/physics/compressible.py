"""Approximations beyond Boussinesq: the extended Boussinesq (EBA), the truncated anelastic liquid
(TALA) and the anelastic liquid (ALA) approximations, on the nondimensional reference state of King
et al. (2010).

Reference state (``d`` the depth below the top, ``Di = alpha0 g0 h / cp0`` the dissipation number,
``gamma`` the Grueneisen parameter, ``T0 = T_surface / Delta T`` the surface temperature)::

    alpha_r = cp_r = g_r = 1,      rho_r(d) = exp(Di d / gamma),      T_ad(d) = T0 (exp(Di d) - 1)

(``T_ad`` the adiabat's rise above the surface temperature). The equations each approximation
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

import ufl

from convection.schema import param
from fembase.registry import Registry

__all__ = ["APPROXIMATIONS", "EnergyTerms", "Formulation", "ReferenceSettings", "ReferenceState", "shear_heating"]


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


@dataclass(frozen=True)
class ReferenceState:
    """The nondimensional reference state (module docstring): ``alpha_r = cp_r = g_r = 1``.

    Attributes:
        Di: Dissipation number.
        gruneisen: Grueneisen parameter ``gamma`` of the reference density ``exp(Di d / gamma)``.
        surface_temperature: ``T0``, the surface temperature over the temperature scale.
        heat_capacity_ratio: ``cp / cv`` in the ALA's pressure buoyancy (0 leaves it out: TALA).
    """

    Di: float = 0.0
    gruneisen: float = 1.0
    surface_temperature: float = 0.0
    heat_capacity_ratio: float = 1.0

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
        """``rho_r = exp(Di depth / gamma)`` (UFL or numbers)."""
        return ufl.exp(self.Di * depth / self.gruneisen)

    def adiabat(self, depth: Any, /) -> Any:
        """``T_ad = T0 (exp(Di depth) - 1)``: the adiabat's rise above the surface (UFL)."""
        return self.surface_temperature * (ufl.exp(self.Di * depth) - 1.0)

    def compressibility(self, depth: Any, /) -> Any:
        """``(Di / gamma) (cp / cv) rho_r``: the ALA's buoyancy loses this times the dynamic pressure (UFL)."""
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
