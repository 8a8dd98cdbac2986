"""``integrated_strain``: accumulated strain, ``ds/dt = sqrt(eps:eps / 2)`` along the path."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import numpy.typing as npt

from fembase.params import param
from particles.properties._base import ParticleProperty, PropertyContext, write_rows
from particles.properties._tensor import strain_rate_invariant
from particles.storage.swarm import Swarm

__all__ = ["IntegratedStrain"]


class IntegratedStrain(ParticleProperty):
    """Time integral of the second invariant of the strain rate, ``s(0) = initial``; integrated by
    the Advector with the positions' Runge-Kutta scheme.
    """

    name: ClassVar[str] = "integrated_strain"
    description: ClassVar[str] = "accumulated second invariant of the strain rate, ds/dt = sqrt(eps:eps/2)"
    default_new_particles: ClassVar[str] = "interpolate"
    integrated: ClassVar[bool] = True

    @dataclass(frozen=True, kw_only=True)
    class Settings(ParticleProperty.Settings):
        """The value at creation."""

        initial: float = param(0.0, help="Value at creation (and for reinitialised new particles).")

    settings: Settings

    def initialise(self, swarm: Swarm, rows: npt.NDArray[np.integer], context: PropertyContext) -> None:
        write_rows(swarm, self.column, rows, self.settings.initial)

    def rhs(
        self, swarm: Swarm, c: float, y: npt.NDArray[np.float64], grad_u: npt.NDArray[np.float64]
    ) -> npt.NDArray[np.float64]:
        return strain_rate_invariant(grad_u)[:, None]
