"""What a visco-elastic run reports (issue 48): the deviatoric stress, its second invariant, the
elastic and viscous strain rates and the elastic share of the deformation, as UFL of the flow.

The split follows the time discretisation (:mod:`convection.physics.elasticity`, docs/rheology.md
"Elasticity"). With ``tau^{n+1} = 2 eta_ve eps + chi tau_J^n`` the Maxwell law
``eps = tau / (2 eta) + (tau - tau_J^n) / (2 G dt_e)`` holds exactly, so::

    eps_v  = tau^{n+1} / (2 eta)                     the viscous strain rate
    eps_el = (tau^{n+1} - tau_J^n) / (2 G dt_e)      the elastic one
           = eps - eps_v = chi (eps - tau_J^n / (2 eta))
    share  = eps_el_II / eps_II                      (0 where eps_II = 0)

with ``X_II = sqrt(X : X / 2)``. ``eps_el + eps_v = eps`` holds to round-off, and the flow solved
before the first step (``dt_e`` undefined, ``chi = 0``) is all viscous. On the mesh ``tau_J^n`` is
the old stress of the forms (the particles' stress interpolated after they moved); the particles
(:mod:`particles.properties.elastic_outputs`) use their own, rotated one.

Every output is asked for by the same name as a field (``output.extra_fields``), a particle
property (``particles.properties``) and, through the ``elasticity`` statistics, as columns; each is
refused when the config is checked unless ``physics.elasticity.enabled``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, NamedTuple

import ufl

from convection.physics.elasticity import Elasticity
from convection.schema import ConfigError

__all__ = ["ELASTIC_OUTPUTS", "ElasticSplit", "check_elastic_outputs", "elastic_split", "second_invariant"]

ELASTIC_OUTPUTS: tuple[str, ...] = ("elastic_stress", "elastic_stress_invariant", "elastic_strain_rate",
                                    "viscous_strain_rate", "elastic_share")
"""The outputs by name: the fields of ``output.extra_fields`` (the particle properties bear the same
names; ``elastic_stress`` is the stress history itself there)."""


class ElasticSplit(NamedTuple):
    """The stress and the strain rates of a visco-elastic flow (UFL tensors, module docstring)."""

    stress: Any
    elastic: Any
    viscous: Any
    total: Any

    def outputs(self) -> dict[str, Any]:
        """UFL by the names of :data:`ELASTIC_OUTPUTS`."""
        total_ii = second_invariant(self.total)
        share = ufl.conditional(ufl.gt(total_ii, 0.0), second_invariant(self.elastic) / total_ii, 0.0)
        return {"elastic_stress": self.stress, "elastic_stress_invariant": second_invariant(self.stress),
                "elastic_strain_rate": self.elastic, "viscous_strain_rate": self.viscous, "elastic_share": share}


def second_invariant(tensor: Any, /) -> Any:
    """``sqrt(t : t / 2)`` (ASPECT's convention, as ``strain_rate_II``)."""
    return ufl.sqrt(ufl.inner(tensor, tensor) / 2.0)


def elastic_split(elasticity: Elasticity, eta: Any, C: Any, rate: Any, fields: Mapping[str, Any], u: Any, /
                  ) -> ElasticSplit:
    """The split of the flow ``u`` (module docstring): ``eta`` the viscosity of the laws, ``C`` the
    material fractions, ``rate`` ``1 / dt_e`` and ``fields`` the old stress's components."""
    eps = ufl.sym(ufl.grad(u))
    old = elasticity.stress(fields, u.ufl_shape[0])
    chi = elasticity.memory(eta, C, rate)
    stress = 2.0 * elasticity.viscosity(eta, C, rate) * eps + chi * old
    elastic = chi * (eps - old / (2.0 * eta))
    return ElasticSplit(stress, elastic, eps - elastic, eps)


def check_elastic_outputs(enabled: bool, carried: Sequence[str], extra_fields: Sequence[str] | None,
                          on_particles: bool = True, /) -> None:
    """Refuse an elastic output without elasticity (``carried``: the primary particle system's
    property names; ``extra_fields``: ``output.extra_fields``), and an elastic particle property when
    the stress is not carried by the particles (``on_particles`` False: ``physics.elasticity.stress:
    fields``; the particle outputs need each particle's own stress; the fields work with either).

    Raises:
        ConfigError: naming the key and the output.
    """
    history = [name for name in carried if name != "elastic_stress"]  # the history: checked with elasticity
    if enabled and not on_particles:
        asked = [name for name in history if name in ELASTIC_OUTPUTS]
        if asked:
            raise ConfigError(f"config key 'particles.properties': {asked[0]!r} needs the particles' stress "
                              "(physics.elasticity.stress: particles); with stress: fields ask for it in "
                              "output.extra_fields")
    if enabled:
        return
    for key, names in (("particles.properties", history), ("output.extra_fields", extra_fields or ())):
        asked = [name for name in names if name in ELASTIC_OUTPUTS]
        if asked:
            raise ConfigError(f"config key '{key}': {asked[0]!r} is an output of elasticity; set "
                              "physics.elasticity.enabled: true")
