"""``damage``: ``dd/dt = alpha |eps| - beta d`` along the path (growth by deformation, healing)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import numpy.typing as npt

from fembase.params import param
from particles.properties._base import ParticleProperty, PropertyContext, write_rows
from particles.properties._tensor import strain_rate_invariant
from particles.storage.swarm import Swarm

__all__ = ["Damage"]


class Damage(ParticleProperty):
    """Damage ``d`` with ``dd/dt = alpha |eps| - beta d``, ``|eps| = sqrt(eps:eps / 2)`` the second
    invariant of the strain rate; integrated by the Advector with the positions' scheme. For a
    constant strain rate, ``d(t) = (alpha |eps| / beta)(1 - exp(-beta t)) + d(0) exp(-beta t)``.
    """

    name: ClassVar[str] = "damage"
    description: ClassVar[str] = "damage with dd/dt = alpha |eps| - beta d"
    default_new_particles: ClassVar[str] = "interpolate"
    integrated: ClassVar[bool] = True

    @dataclass(frozen=True, kw_only=True)
    class Settings(ParticleProperty.Settings):
        """Growth, healing and the value at creation."""

        alpha: float = param(1.0, help="Growth per unit strain, >= 0.")
        beta: float = param(0.0, help="Healing rate, >= 0.")
        initial: float = param(0.0, help="Damage at creation.")

    settings: Settings

    def check(self) -> None:
        super().check()
        alpha, beta = self.settings.alpha, self.settings.beta
        if alpha < 0 or beta < 0:
            raise ValueError(f"damage: alpha and beta must be >= 0, got {alpha}, {beta}")

    def initialise(self, swarm: Swarm, rows: npt.NDArray[np.integer], context: PropertyContext) -> None:
        write_rows(swarm, self.column, rows, self.settings.initial)

    def rhs(
        self, swarm: Swarm, c: float, y: npt.NDArray[np.float64], grad_u: npt.NDArray[np.float64]
    ) -> npt.NDArray[np.float64]:
        return self.settings.alpha * strain_rate_invariant(grad_u)[:, None] - self.settings.beta * y
