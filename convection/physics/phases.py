"""Phase transitions: a phase function per transition, its density jump, latent heat and viscosity jump.

Nondimensional (``docs/phase_transitions.md`` has the physical forms and the derivation). A
transition sits at the depth ``d0`` at the temperature ``T0``; a Clapeyron slope ``gamma`` moves it
by ``gamma (T - T0)``, and it has the width ``w``. The fraction of the deep phase is::

    Gamma(T, d) = (1 + tanh(pi / w)) / 2,        pi = d - d0 - gamma (T - T0)

(``d`` the depth below the top; ``pi`` the "excess depth", C&Y's excess pressure over ``rho g``).
The deep phase is denser by ``Rb`` (a buoyancy number as a material's): the body force gains
``-sum_k Rb_k Gamma_k e_up``. The transition releases the latent heat ``T dS = T (Delta S / c_p)
dGamma`` per unit heat capacity, ``L = Delta S / c_p`` its entropy change (Clausius-Clapeyron:
``Delta S = gamma_phys Delta rho / rho^2``). With ``DGamma/Dt = Gamma' (-w_up - gamma DT/Dt)``
(``Gamma' = dGamma/dpi``, ``w_up = u . e_up``) the energy equation's heat capacity and heating gain::

    c += rho_r L gamma Gamma' (T + T_s),        q += -rho_r L Gamma' (T + T_s) w_up

(``T + T_s`` the absolute temperature, ``T_s = physics.reference.surface_temperature``; ``rho_r`` the
reference density of the approximation, 1 without one). Since ``L gamma >= 0`` (both have the
slope's sign), ``c >= 1``. Across the transition, in a steady downflow without conduction,
``d ln(T + T_s) = L dGamma``: the absolute temperature grows by the factor ``exp(L)``
(:meth:`PhaseTransition.temperature_below`). A viscosity jump ``f`` multiplies the viscosity by
``f ** Gamma``.

Per material: a transition may apply to some materials only (``materials``: indices, 0 the
background, ``i`` material ``i`` of the fractions ``C_1 .. C_n``). Its density jump and viscosity
jump are then weighted by those materials' volume fraction ``phi = sum_{i in materials} C_i`` (``C_0 = 1
- sum_i C_i``): the body force gains ``-Rb phi Gamma e_up`` and the viscosity the factor ``f ** (phi
Gamma)`` (the geometric mixture's exactly; any mixture's where a cell holds one material). Different
materials get different jumps (or depths, slopes) through different transitions.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import ufl

from convection.schema import REQUIRED, param

__all__ = ["PhaseTransition", "PhaseTransitionSettings", "PhaseTransitions"]


@dataclass(frozen=True)
class PhaseTransitionSettings:
    """One entry of the ``phase_transitions`` config section (``phase_transitions.<name>``)."""

    depth: float = param(REQUIRED, minimum=0.0, help="depth d0 of the transition at its temperature (e.g. 660 km)")
    width: float = param(REQUIRED, exclusive_minimum=0.0, help="width w of the phase function "
                                                                "(1 + tanh((d - d_ref(T)) / w)) / 2 (e.g. 20 km)")
    temperature: float = param(0.0, help="temperature T0 at which the transition lies at its depth (a value: "
                                         "e.g. 1900 K)")
    clapeyron: float = param(0.0, help="Clapeyron slope: d_ref(T) = d0 + clapeyron (T - T0); with units a "
                                       "pressure per temperature (e.g. -2.5 MPa/K), made clapeyron dT / (rho0 g L)")
    Rb: float = param(0.0, help="buoyancy number of the deep phase's density excess: body force -Rb Gamma e_up "
                                "(> 0: denser below)")
    density_jump: float | None = param(None, help="the deep phase's density excess as a fraction of "
                                                  "scaling.density (e.g. 0.08; needs the scaling section): "
                                                  "gives Rb")
    entropy_change: float = param(0.0, help="latent heat: entropy change over heat capacity, Delta S / c_p; with "
                                            "units J/kg/K (over scaling.heat_capacity) or clausius_clapeyron "
                                            "(Delta S = clapeyron density_jump / scaling.density)")
    viscosity_jump: float = param(1.0, exclusive_minimum=0.0, help="the deep phase's viscosity over the shallow "
                                                                   "one's: eta *= viscosity_jump ** Gamma")
    materials: tuple[str, ...] | None = param(None, help="the materials the transition applies to (names of the "
                                                         "materials section, background: the background; its "
                                                         "density and viscosity jumps weighted by their volume "
                                                         "fraction); null: every material")


@dataclass(frozen=True)
class PhaseTransition:
    """One phase transition (module docstring), nondimensional.

    Attributes:
        name: Its name (the config's key).
        depth: ``d0``. width: ``w``. temperature: ``T0``. clapeyron: ``gamma``.
        Rb: Buoyancy number of the deep phase's excess density.
        entropy_change: ``L = Delta S / c_p``.
        viscosity_jump: ``f``, the deep phase's viscosity over the shallow one's.
        materials: The materials it applies to (0 the background, ``i`` the fraction ``C_i``), or
            None: every material.
    """

    name: str
    depth: float
    width: float
    temperature: float = 0.0
    clapeyron: float = 0.0
    Rb: float = 0.0
    entropy_change: float = 0.0
    viscosity_jump: float = 1.0
    materials: tuple[int, ...] | None = None

    def __post_init__(self) -> None:
        if self.materials is not None and (not self.materials or min(self.materials) < 0
                                           or len(set(self.materials)) != len(self.materials)):
            raise ValueError(f"phase transition {self.name!r}: materials must be distinct indices >= 0 (0 the "
                             f"background), got {self.materials}")
        if not self.width > 0.0:
            raise ValueError(f"phase transition {self.name!r}: the width must be positive, got {self.width}")
        if not self.viscosity_jump > 0.0:
            raise ValueError(f"phase transition {self.name!r}: the viscosity jump must be positive, "
                             f"got {self.viscosity_jump}")

    def boundary_depth(self, T: Any, /) -> Any:
        """``d_ref(T) = d0 + gamma (T - T0)`` (numbers, arrays or UFL)."""
        return self.depth + self.clapeyron * (T - self.temperature)

    def phase(self, T: Any, depth: Any, /) -> Any:
        """``Gamma(T, d)`` (UFL)."""
        return 0.5 * (1.0 + ufl.tanh((depth - self.boundary_depth(T)) / self.width))

    def phase_derivative(self, T: Any, depth: Any, /) -> Any:
        """``Gamma' = dGamma / dpi = (1 - tanh^2(pi / w)) / (2 w)`` (UFL)."""
        tanh = ufl.tanh((depth - self.boundary_depth(T)) / self.width)
        return 0.5 * (1.0 - tanh * tanh) / self.width

    def phase_at(self, T: Any, depth: Any, /) -> Any:
        """``Gamma`` of numbers or arrays (numpy)."""
        return 0.5 * (1.0 + np.tanh((np.asarray(depth) - self.boundary_depth(np.asarray(T))) / self.width))

    def temperature_below(self, T_above: float, surface_temperature: float, /) -> float:
        """The temperature below the transition of material that crossed it downwards at steady state
        without conduction from ``T_above``: ``(T_above + T_s) exp(L) - T_s`` (module docstring)."""
        return (T_above + surface_temperature) * math.exp(self.entropy_change) - surface_temperature

    def fraction(self, C: Any, /) -> Any | None:
        """``phi``, the volume fraction of the materials it applies to (UFL; the fractions ``C``: None, one
        or a sequence, as :func:`~convection.physics.approximation.fractions`), or None for every material."""
        if self.materials is None:
            return None
        cs = tuple(C) if isinstance(C, (list, tuple)) else (() if C is None else (C,))
        if max(self.materials) > len(cs):
            raise ValueError(f"phase transition {self.name!r} applies to material {max(self.materials)}, "
                             f"the model has {len(cs)}")
        clamped = [ufl.min_value(ufl.max_value(ufl.as_ufl(c), 0.0), 1.0) for c in cs]
        terms = [clamped[i - 1] for i in self.materials if i > 0]
        if 0 in self.materials:
            terms.append(1.0 - sum(clamped[1:], clamped[0]) if clamped else ufl.as_ufl(1.0))
        return sum(terms[1:], terms[0])

    def weighted_phase(self, T: Any, depth: Any, C: Any = None, /) -> Any:
        """``phi Gamma`` (UFL): the phase weighted by the fraction of its materials (``Gamma`` for all)."""
        phi = self.fraction(C)
        return self.phase(T, depth) if phi is None else phi * self.phase(T, depth)


@dataclass(frozen=True)
class PhaseTransitions:
    """The phase transitions of a model and the absolute temperature's offset.

    Attributes:
        transitions: The transitions (empty: none; the terms below are then absent).
        surface_temperature: ``T_s``: the absolute temperature is ``T + T_s`` (the latent heat).
    """

    transitions: tuple[PhaseTransition, ...] = ()
    surface_temperature: float = 0.0

    @classmethod
    def from_settings(cls, settings: Mapping[str, PhaseTransitionSettings], /, *, surface_temperature: float = 0.0,
                      material_names: tuple[str, ...] = ()) -> PhaseTransitions:
        """The transitions of the ``phase_transitions`` section (checked, nondimensional);
        ``material_names`` the materials in the order of the fractions (a transition's ``materials``)."""
        return cls(tuple(PhaseTransition(name, s.depth, s.width, s.temperature, s.clapeyron, s.Rb, s.entropy_change,
                                         s.viscosity_jump, material_indices(s.materials, material_names))
                         for name, s in settings.items()), surface_temperature)

    def __len__(self) -> int:
        return len(self.transitions)

    @property
    def buoyant(self) -> bool:
        """Whether some transition has a density jump."""
        return any(t.Rb != 0.0 for t in self.transitions)

    @property
    def latent(self) -> bool:
        """Whether some transition releases latent heat."""
        return any(t.entropy_change != 0.0 for t in self.transitions)

    @property
    def changes_viscosity(self) -> bool:
        """Whether some transition changes the viscosity."""
        return any(t.viscosity_jump != 1.0 for t in self.transitions)

    def density(self, T: Any, depth: Any, C: Any = None, /) -> Any:
        """``sum_k Rb_k phi_k Gamma_k`` (UFL): the deep phases' excess density, a buoyancy magnitude
        (``phi_k`` the fraction of the materials of transition ``k`` in ``C``; 1 for every material)."""
        terms = [t.Rb * t.weighted_phase(T, depth, C) for t in self.transitions if t.Rb != 0.0]
        return sum(terms[1:], terms[0]) if terms else ufl.as_ufl(0.0)

    def viscosity_factor(self, T: Any, depth: Any, C: Any = None, /) -> Any:
        """``prod_k f_k ** (phi_k Gamma_k) = exp(sum_k phi_k Gamma_k ln f_k)`` (UFL)."""
        terms = [math.log(t.viscosity_jump) * t.weighted_phase(T, depth, C) for t in self.transitions
                 if t.viscosity_jump != 1.0]
        return ufl.exp(sum(terms[1:], terms[0])) if terms else ufl.as_ufl(1.0)

    def latent_heat(self, T_new: Any, T: Any, w_up: Any, depth: Any, density: Any, /) -> tuple[Any, Any]:
        """``(c, q)`` the latent heat adds to the energy equation's heat capacity and heating (module
        docstring; UFL): ``Gamma'`` and the capacity's temperature at the last temperature ``T``,
        the heating linear in the unknown ``T_new``; ``density`` the reference density (1: none)."""
        capacity: Any = ufl.as_ufl(0.0)
        heating: Any = ufl.as_ufl(0.0)
        ts = self.surface_temperature
        for t in self.transitions:
            if t.entropy_change == 0.0:
                continue
            rate = density * t.entropy_change * t.phase_derivative(T, depth)
            capacity = capacity + rate * t.clapeyron * (T + ts)
            heating = heating - rate * (T_new + ts) * w_up
        return capacity, heating


BACKGROUND = "background"
"""The name of the background material in a transition's ``materials``."""


def material_indices(names: tuple[str, ...] | None, material_names: tuple[str, ...], /) -> tuple[int, ...] | None:
    """The indices of the materials ``names`` (0 the background, ``i`` the ``i``-th of ``material_names``),
    or None for None (every material).

    Raises:
        ValueError: a name that is neither ``background`` nor one of ``material_names``.
    """
    if names is None:
        return None
    known = (BACKGROUND, *material_names)
    unknown = [n for n in names if n not in known]
    if unknown:
        raise ValueError(f"unknown material {unknown[0]!r}; valid: {list(known)}")
    return tuple(known.index(n) for n in names)


def check_phase_transitions(settings: Mapping[str, PhaseTransitionSettings], /, *, energy: bool,
                            buoyancy_theta: float, material_names: tuple[str, ...] = ()) -> None:
    """The cross-key checks of the ``phase_transitions`` section (nondimensional: after the units pass).

    Raises:
        ConfigError: a density jump left as a fraction (no scaling section gave it its Rb), latent heat
            without the energy equation, a transition with the semi-implicit buoyancy.
    """
    from convection.schema import ConfigError, key_text

    for name, s in settings.items():
        key = f"phase_transitions.{key_text(name)}"
        if s.density_jump is not None:
            raise ConfigError(f"config key '{key}.density_jump': needs the scaling section (scaling.density, "
                              "gravity, length, viscosity give its Rb); a nondimensional model gives Rb")
        if s.entropy_change != 0.0 and not energy:
            raise ConfigError(f"config key '{key}.entropy_change': latent heat needs the energy equation "
                              "(energy.enabled: true)")
        _check_materials(key, s, material_names)
        if buoyancy_theta != 0.0:
            raise ConfigError(f"config key '{key}': not with stokes.buoyancy_theta (the semi-implicit buoyancy has no "
                              "phase transitions yet)")


def _check_materials(key: str, s: PhaseTransitionSettings, material_names: tuple[str, ...], /) -> None:
    """A transition's ``materials``: known, distinct names, none with latent heat (:func:`check_phase_transitions`)."""
    from convection.schema import ConfigError

    if s.materials is None:
        return
    if not s.materials or len(set(s.materials)) != len(s.materials):
        raise ConfigError(f"config key '{key}.materials': expected distinct material names, got {list(s.materials)}")
    if BACKGROUND in material_names:
        raise ConfigError(f"config key '{key}.materials': a material named {BACKGROUND!r} is ambiguous here; rename it")
    try:
        material_indices(s.materials, material_names)
    except ValueError as err:
        raise ConfigError(f"config key '{key}.materials': {err}") from None
    if s.entropy_change != 0.0:
        raise ConfigError(f"config key '{key}.materials': latent heat applies to every material (not yet per "
                          "material); give the latent heat in a transition without materials")
