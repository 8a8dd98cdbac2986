"""Maxwell visco-elasticity (Moresi et al. 2003, as ASPECT uses it): the effective viscosity and the
old stress's term of the Stokes forms, and the config section ``physics.elasticity``.

A Maxwell material has the deviatoric stress ``tau`` with ``eps = tau / (2 eta) + tau_J' / (2 G)``
(``tau_J'``: an objective rate of ``tau``, here Jaumann's). Backward Euler over the elastic time
step ``dt_e`` gives::

    tau^{n+1} = 2 eta_ve eps(u^{n+1}) + chi tau_J^n
    eta_ve = eta G dt_e / (eta + G dt_e)            chi = eta_ve / (G dt_e) = eta / (eta + G dt_e)

(``tau_J^n``: the old stress carried to the new position and rotated, on the particles). The
Stokes problem keeps its form with ``eta -> eta_ve`` and the old stress as a load::

    (2 eta_ve eps(u), eps(v)) - (p, div v) = (f, v) - (chi tau^n, eps(v))

Both factors are written with ``r = 1 / dt_e`` and the Maxwell time over ``dt_e``,
``De = eta r / G``: ``eta_ve = eta / (1 + De)``, ``chi = De / (1 + De)``, so ``r = 0`` (the flow
solved before the first step, when no time has passed) is the viscous flow, without the stress
term. docs/rheology.md ("Elasticity") has the time discretisation and its error.

The materials' shear moduli mix by volume fraction as compliances (springs in series, Reuss):
``1 / G = C_0 / G_0 + sum_i C_i / G_i``.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import ufl

from convection.physics.rheology import COMBINATIONS, ElasticTrial, ViscoPlastic, ViscosityLawBase, yield_law
from convection.schema import MAX_DEGREE, ConfigError, Names, param
from fembase.registry import Registry

__all__ = ["STRESS_CARRIERS", "STRESS_COMPONENTS", "STRESS_PROPERTY", "Elasticity", "ElasticitySettings",
           "StressCarrier", "check_elasticity", "check_plasticity", "rotated", "stress_labels"]

STRESS_COMPONENTS: dict[int, tuple[tuple[int, int], ...]] = {
    2: ((0, 0), (1, 1), (0, 1)),
    3: ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)),
}
"""The stored components of the symmetric stress tensor by dimension (Voigt order: xx, yy, (zz,) xy, ...)."""

_AXES = "xyz"
STRESS_PROPERTY = "elastic_stress"
"""The particle property that carries the stress (:mod:`particles.properties.elastic_stress`)."""


@functools.cache
def stress_labels(gdim: int, /) -> tuple[str, ...]:
    """The mesh fields of the stress components: ``elastic_stress_xx``, ``elastic_stress_yy``, ``elastic_stress_xy``
    in 2D (and ``_zz``, ``_xz``, ``_yz`` in 3D). Made once: the Stokes solver keeps its forms while
    the fields' names and Functions are the very same objects."""
    return tuple(f"{STRESS_PROPERTY}_{_AXES[i]}{_AXES[j]}" for i, j in STRESS_COMPONENTS[gdim])


@dataclass(frozen=True)
class StressCarrier:
    """What carries the stress history between steps (``physics.elasticity.stress``).

    Attributes:
        name: The config name.
        description: One line for the config reference.
        on_particles: The particles' ``elastic_stress`` carries it (else advected mesh fields,
            :mod:`convection.model.elastic_stress`).
    """

    name: str
    description: str
    on_particles: bool


STRESS_CARRIERS: Registry[StressCarrier] = Registry("elastic stress carrier", (
    StressCarrier("particles", "the particle property elastic_stress, interpolated onto the mesh after each step",
                  on_particles=True),
    StressCarrier("fields", "continuous mesh fields advected as composition fields (SUPG, BDF2, no diffusion)",
                  on_particles=False),
))
"""Registry of the stress history's carriers (docs/rheology.md, "The stress as fields")."""


@dataclass(frozen=True)
class ElasticitySettings:
    """The ``physics.elasticity`` config section (off by default)."""

    enabled: bool = param(False, help="Maxwell visco-elasticity (Moresi et al. 2003): the stress history is carried "
                                      "by particles carrying elastic_stress or by mesh fields (stress)")
    shear_modulus: float = param(1.0, exclusive_minimum=0.0, help="shear modulus G of the background material (a "
                                                                  "stress: e.g. 1e10 Pa with the scaling section)")
    elastic_time_step: float | None = param(None, exclusive_minimum=0.0,
                                            help="a fixed elastic time step dt_e >= time.dt_max, the stress averaged "
                                                 "between steps (a time: e.g. 10 kyr with the scaling section); null: "
                                                 "dt_e = dt")
    stress: str = param("particles", choices=Names(STRESS_CARRIERS),
                        help="what carries the stress history: particles (the property elastic_stress) or fields "
                             "(advected continuous mesh fields, one per stress component)")
    stress_degree: int = param(2, minimum=1, maximum=MAX_DEGREE,
                               help="with stress: fields, the Lagrange degree of the stress fields")


@dataclass(frozen=True)
class Elasticity:
    """The elastic part of the rheology (module docstring).

    Attributes:
        shear_modulus: ``G`` of the background material.
        material_moduli: ``G`` of each material (None: the background's), in the materials' order.
        time_step: a fixed elastic time step ``dt_e`` (None: ``dt_e = dt``, the step), with the stress
            averaged between steps (:meth:`averaged`).
    """

    shear_modulus: float
    material_moduli: tuple[float | None, ...] = ()
    time_step: float | None = None

    def __post_init__(self) -> None:
        if not all(g is None or g > 0.0 for g in (self.shear_modulus, *self.material_moduli)):
            raise ValueError(f"shear moduli must be > 0, got {self.shear_modulus}, {self.material_moduli}")
        if self.time_step is not None and not self.time_step > 0.0:
            raise ValueError(f"the elastic time step must be > 0, got {self.time_step}")

    @property
    def is_variable(self) -> bool:
        """Whether ``G`` differs between the materials (then it moves with them)."""
        return any(g is not None and g != self.shear_modulus for g in self.material_moduli)

    @classmethod
    def from_settings(cls, settings: ElasticitySettings, material_moduli: Sequence[float | None] = (), /
                      ) -> Elasticity | None:
        """The elasticity of a run (None when not enabled)."""
        return (cls(settings.shear_modulus, tuple(material_moduli), settings.elastic_time_step) if settings.enabled
                else None)

    def modulus(self, C: Any, /) -> Any:
        """``G`` at the material fractions ``C`` (a number where every material has the background's)."""
        if not self.is_variable:
            return self.shear_modulus
        moduli = [self.shear_modulus if g is None else g for g in self.material_moduli]
        parts = C if isinstance(C, (list, tuple)) else (C,)
        clipped = [ufl.min_value(ufl.max_value(c, 0.0), 1.0) for c in parts]
        compliance = (1.0 - sum(clipped)) / self.shear_modulus + sum(c / g for c, g in zip(clipped, moduli))
        return 1.0 / compliance

    def deborah(self, eta: Any, C: Any, rate: Any, /) -> Any:
        """``De = eta r / G``: the Maxwell time over ``dt_e`` (``rate``: ``r = 1 / dt_e``, a Constant)."""
        return eta * rate / self.modulus(C)

    def viscosity(self, eta: Any, C: Any, rate: Any, /) -> Any:
        """``eta_ve = eta / (1 + De) = eta G dt_e / (eta + G dt_e)``."""
        return eta / (1.0 + self.deborah(eta, C, rate))

    def memory(self, eta: Any, C: Any, rate: Any, /) -> Any:
        """``chi = De / (1 + De) = eta_ve / (G dt_e)``: the share of the old stress the new one keeps."""
        de = self.deborah(eta, C, rate)
        return de / (1.0 + de)

    def steps(self, dt: float, /) -> tuple[float, float]:
        """``1 / dt_e`` and the averaging's share ``r = dt / dt_e`` for a step ``dt``: ``dt_e = dt``, ``r = 1``
        without a fixed elastic time step; ``dt = 0`` (no step yet): ``1 / dt_e = 0``, the viscous flow."""
        dt_e = dt if self.time_step is None else self.time_step
        return (1.0 / dt_e if dt > 0.0 else 0.0), (1.0 if self.time_step is None else dt / self.time_step)

    def update_factors(self, eta: Any, C: Any, rate: Any, share: Any, /) -> tuple[Any, Any]:
        """The factors of the particles' stress update ``tau <- 2 eta_ve eps + chi R tau R^T``: ``eta_ve`` and
        ``chi`` at ``dt_e``, averaged over the step (:meth:`averaged`, ``share``: ``dt / dt_e``) with a fixed
        ``dt_e``."""
        factors = self.viscosity(eta, C, rate), self.memory(eta, C, rate)
        return factors if self.time_step is None else self.averaged(*factors, share)

    @staticmethod
    def averaged(eta_ve: Any, chi: Any, share: Any, /) -> tuple[Any, Any]:
        """The factors of the particles' update ``tau <- 2 eta_ve' eps + chi' R tau R^T`` with the stress
        averaged over a step ``dt`` shorter than a fixed ``dt_e`` (``share``: ``r = dt / dt_e``)::

            tau <- (1 - r) R tau R^T + r (2 eta_ve eps + chi R tau R^T)
            eta_ve' = r eta_ve,   chi' = 1 - r (1 - chi)

        (docs/rheology.md, "A fixed elastic time step")."""
        return share * eta_ve, 1.0 - share * (1.0 - chi)

    @staticmethod
    def stress(fields: Mapping[str, Any], gdim: int, /) -> Any:
        """The old deviatoric stress as a UFL tensor from its component fields (:func:`stress_labels`)."""
        labels = stress_labels(gdim)
        missing = [name for name in labels if name not in fields]
        if missing:
            raise ValueError(f"the elastic stress needs the mesh fields {missing} (the particles' elastic_stress)")
        entries: list[list[Any]] = [[0.0] * gdim for _ in range(gdim)]
        for (i, j), name in zip(STRESS_COMPONENTS[gdim], labels):
            entries[i][j] = entries[j][i] = fields[name]
        return ufl.as_matrix(entries)

    def trial(self, C: Any, rate: Any, fields: Mapping[str, Any], gdim: int, /) -> ElasticTrial:
        """What the visco-plastic laws need to limit the visco-elastic stress to the yield stress
        (:meth:`convection.physics.rheology.ViscoPlastic.maxwell_yield`): ``G``, ``r`` and ``tau^n``."""
        return ElasticTrial(self.modulus(C), rate, self.stress(fields, gdim))

    def load(self, eta: Any, C: Any, rate: Any, fields: Mapping[str, Any], v: Any, dx: Any, /) -> Any:
        """The old stress's term of the momentum equation's right-hand side, ``-(chi tau^n, eps(v))``."""
        tau = self.stress(fields, v.ufl_shape[0])
        return -self.memory(eta, C, rate) * ufl.inner(tau, ufl.sym(ufl.grad(v))) * dx


def rotated(tau: Any, grad_u: Any, dt: Any, /) -> Any:
    """``R tau R^T`` with ``R = exp(dt W)``, ``W = (grad u - grad u^T) / 2`` (UFL; Rodrigues' formula as
    :func:`particles.properties.elastic_stress.jaumann_rotation`): the Jaumann rotation of the stress
    over a step, which keeps its invariants."""
    K = 0.5 * dt * (grad_u - grad_u.T)
    theta = ufl.max_value(ufl.sqrt(0.5 * ufl.inner(K, K)), 1.0e-20)  # sin(t) / t = 1 below 1e-20 in doubles
    half = theta / 2.0
    R = ufl.Identity(grad_u.ufl_shape[0]) + ufl.sin(theta) / theta * K + 0.5 * (ufl.sin(half) / half) ** 2 * K * K
    return R * tau * R.T


def check_elasticity(settings: ElasticitySettings, carried: Sequence[str], dt_max: float | None = None,
                     dt_initial: float | None = None, /) -> None:
    """The cross-key checks of ``physics.elasticity`` (``carried``: the property names of the primary
    particle system, empty without particles; ``dt_max``, ``dt_initial``: the ``time`` keys).

    Raises:
        ConfigError: elasticity whose stress is carried by particles without the particles'
            ``elastic_stress``, that property with the stress carried by fields or without
            elasticity; a fixed elastic time step without ``time.dt_max`` or below it (the averaging
            would extrapolate the stress).
    """
    dt_e = settings.elastic_time_step
    if settings.enabled and dt_e is not None and (dt_max is None or dt_max > dt_e):
        raise ConfigError("config key 'physics.elasticity.elastic_time_step': a fixed elastic time step must be at "
                          "least the longest step; set time.dt_max, at most elastic_time_step")
    if settings.enabled and dt_e is not None and dt_initial is not None and dt_initial > dt_e:
        raise ConfigError("config key 'time.dt_initial': a step longer than "
                          "physics.elasticity.elastic_time_step; set it at most that")
    on_particles = STRESS_CARRIERS[settings.stress].on_particles
    if settings.enabled and on_particles and STRESS_PROPERTY not in carried:
        raise ConfigError("config key 'physics.elasticity.enabled': the stress history is carried by particles; set "
                          f"particles.enabled: true and carry {STRESS_PROPERTY!r} in particles.properties (or "
                          "physics.elasticity.stress: fields)")
    if settings.enabled and not on_particles and STRESS_PROPERTY in carried:
        raise ConfigError(f"config key 'particles.properties': {STRESS_PROPERTY!r} is the stress history of "
                          f"physics.elasticity.stress: particles, not of stress: {settings.stress!r}; remove it")
    if not settings.enabled and STRESS_PROPERTY in carried:
        raise ConfigError(f"config key 'particles.properties': {STRESS_PROPERTY!r} needs physics.elasticity.enabled: "
                          "true")


def check_plasticity(settings: ElasticitySettings, laws: Mapping[str, ViscosityLawBase], /) -> None:
    """With elasticity, the visco-plastic laws (``laws``: each material's law by its config key) must
    limit the visco-elastic stress to the yield stress: ``combination: minimum``, at the top of the
    material's law (or under its bounds), where the yield acts on the whole visco-elastic stress.

    Raises:
        ConfigError: another combination, or a visco-plastic law inside another law.
    """
    if not settings.enabled:
        return
    for key, law in laws.items():
        top = yield_law(law)
        if top is not None and not COMBINATIONS[top.settings.combination].exact:
            exact = [name for name, rule in COMBINATIONS.items() if rule.exact]
            raise ConfigError(f"config key '{key}.combination': with physics.elasticity the stress is limited to the "
                              f"yield stress (combination: {' or '.join(exact)}), not {top.settings.combination!r}")
        nested = [child for child in _descendants(law) if isinstance(child, ViscoPlastic) and child is not top]
        if nested:
            raise ConfigError(f"config key '{key}': with physics.elasticity a viscoplastic law must be the material's "
                              f"law itself (the yield limits the visco-elastic stress), not inside a {law.name!r} law")


def _descendants(law: ViscosityLawBase, /) -> list[ViscosityLawBase]:
    out = [law]
    for child in law.children():
        out.extend(_descendants(child))
    return out
