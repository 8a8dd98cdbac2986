"""Nondimensional Boussinesq approximation: material parameters and constitutive laws.

Equations (``e_z`` is the last coordinate axis, pointing "up")::

    -div(2 eta(T, C) eps(u)) + grad p = (Ra T - Rb C) e_z,      div u = 0,
    dT/dt + u . grad T = lap T + H,

with ``eps(u) = (grad u + grad u^T) / 2``, thermal Rayleigh number ``Ra``, compositional (buoyancy)
Rayleigh number ``Rb``, nondimensional internal heating ``H`` and viscosity ``eta(T, C)`` given by a
:class:`ViscosityLaw`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import ufl

MIXING_RULES: dict[str, str] = {
    "geometric": "eta = eta_0^(1-C) * eta_1^C",
    "arithmetic": "eta = (1-C) eta_0 + C eta_1",
    "harmonic": "1/eta = (1-C)/eta_0 + C/eta_1",
}
"""Registry of composition mixing rules (lowercase name -> one-line description)."""

TEMPERATURE_LAWS: dict[str, str] = {
    "none": "no temperature dependence",
    "frank_kamenetskii": "eta *= exp(-gamma T)",
}
"""Registry of temperature dependences (lowercase name -> one-line description)."""


def _check_name(name: str, registry: dict[str, str], what: str) -> None:
    if name not in registry:
        raise ValueError(f"Unknown {what} {name!r}; valid names: {sorted(registry)}")


def _as_ufl(value: Any) -> Any:
    """Return ``value`` as something UFL algebra accepts (``None`` -> 0)."""
    if value is None:
        return ufl.as_ufl(0.0)
    if isinstance(value, (int, float)):
        return ufl.as_ufl(float(value))
    return value


@dataclass(frozen=True)
class ViscosityLaw:
    """Viscosity law ``eta(T, C)``.

    Attributes:
        material_viscosities: ``(eta_0, eta_1)``: the ``C = 0`` material has viscosity ``eta_0``,
            the ``C = 1`` material ``eta_1``; they are mixed by ``mixing`` with ``C`` clipped to
            ``[0, 1]``. ``None`` means reference viscosity 1 regardless of ``C``.
        mixing: name in :data:`MIXING_RULES` (``"geometric"`` | ``"arithmetic"`` | ``"harmonic"``).
        temperature_law: name in :data:`TEMPERATURE_LAWS` (``"none"`` | ``"frank_kamenetskii"``,
            which multiplies the viscosity by ``exp(-gamma T)``).
        gamma: Frank-Kamenetskii parameter (``ln`` of the thermal viscosity contrast).
    """

    material_viscosities: tuple[float, float] | None = None
    mixing: str = "geometric"
    temperature_law: str = "none"
    gamma: float = 0.0

    def __post_init__(self) -> None:
        _check_name(self.mixing, MIXING_RULES, "viscosity mixing rule")
        _check_name(self.temperature_law, TEMPERATURE_LAWS, "viscosity temperature law")
        if self.material_viscosities is not None:
            if len(self.material_viscosities) != 2 or min(self.material_viscosities) <= 0.0:
                raise ValueError("material_viscosities must be two positive numbers (eta_0, eta_1)")

    @property
    def is_constant(self) -> bool:
        """True when ``eta`` depends on neither ``T`` nor ``C``."""
        composition_free = (
            self.material_viscosities is None
            or self.material_viscosities[0] == self.material_viscosities[1]
        )
        temperature_free = self.temperature_law == "none" or self.gamma == 0.0
        return composition_free and temperature_free

    def __call__(self, T: Any, C: Any) -> Any:
        """UFL expression of the viscosity for temperature ``T`` and composition ``C``."""
        if self.material_viscosities is None:
            eta = ufl.as_ufl(1.0)
        else:
            eta0, eta1 = (float(v) for v in self.material_viscosities)
            if eta0 == eta1:
                eta = ufl.as_ufl(eta0)
            else:
                c = _as_ufl(C)
                c = ufl.min_value(ufl.max_value(c, 0.0), 1.0)
                if self.mixing == "geometric":
                    eta = eta0 * ufl.exp(c * ufl.ln(eta1 / eta0))
                elif self.mixing == "arithmetic":
                    eta = (1.0 - c) * eta0 + c * eta1
                else:
                    eta = 1.0 / ((1.0 - c) / eta0 + c / eta1)
        if self.temperature_law == "frank_kamenetskii" and self.gamma != 0.0:
            eta = eta * ufl.exp(-self.gamma * _as_ufl(T))
        return eta


class BoussinesqApproximation:
    """Boussinesq approximation parameters (see the module docstring for the equations).

    Args:
        Ra: thermal Rayleigh number.
        Rb: compositional Rayleigh number (buoyancy ``-Rb C e_z``).
        H: nondimensional internal heating rate.
        viscosity: viscosity law ``eta(T, C)``.
    """

    def __init__(
        self,
        /,
        *,
        Ra: float,
        Rb: float = 0.0,
        H: float = 0.0,
        viscosity: ViscosityLaw = ViscosityLaw(),
    ) -> None:
        self.Ra = float(Ra)
        self.Rb = float(Rb)
        self.H = float(H)
        self.viscosity_law = viscosity

    @property
    def is_variable_viscosity(self) -> bool:
        """True when the viscosity depends on ``T`` or ``C``."""
        return not self.viscosity_law.is_constant

    def viscosity(self, T: Any, C: Any) -> Any:
        """UFL expression of ``eta(T, C)`` (``T``, ``C``: Functions, UFL expressions or numbers)."""
        return self.viscosity_law(T, C)

    def buoyancy(self, T: Any, C: Any, gdim: int) -> Any:
        """UFL vector expression ``(Ra T - Rb C) e_z`` of length ``gdim`` (``C = None`` -> 0)."""
        magnitude = self.Ra * _as_ufl(T)
        if self.Rb != 0.0 and C is not None:
            magnitude = magnitude - self.Rb * _as_ufl(C)
        return ufl.as_vector([0.0] * (gdim - 1) + [magnitude])

    def __repr__(self) -> str:
        return (
            f"BoussinesqApproximation(Ra={self.Ra}, Rb={self.Rb}, H={self.H}, "
            f"viscosity={self.viscosity_law})"
        )
