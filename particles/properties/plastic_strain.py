"""``plastic_strain``: accumulated plastic strain, ``de/dt = eps_II`` where (and while) the material yields."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import numpy.typing as npt

from fembase.params import param
from particles.properties._base import ParticleProperty, PropertyContext, write_rows
from particles.storage.swarm import Swarm

__all__ = ["PlasticStrain"]


class PlasticStrain(ParticleProperty):
    """Accumulated plastic strain ``e``: the time integral of a mesh field ``rate_field`` sampled
    at the particle, ``de/dt = f(x_p)``. The model supplies ``f = eps_II`` where the material
    yields and 0 elsewhere (ASPECT's convention; ``integrated_strain`` is the total-strain
    variant). Advanced once per step before the particles move, with the field of the step's start
    (explicit Euler): a particle in a steady yielding shear of rate ``eps_II`` has ``e = e0 + eps_II t``.
    """

    name: ClassVar[str] = "plastic_strain"
    description: ClassVar[str] = "accumulated plastic strain, de/dt = eps_II where the material yields"
    default_new_particles: ClassVar[str] = "interpolate"
    accumulating: ClassVar[bool] = True

    @dataclass(frozen=True, kw_only=True)
    class Settings(ParticleProperty.Settings):
        """The value at creation and the field integrated."""

        initial: float = param(0.0, help="Value at creation (new particles later take the mean of their "
                                         "neighbours).")
        rate_field: str = param("plastic_strain_rate", help="Name of the mesh field integrated.")

    settings: Settings

    def check(self) -> None:
        super().check()
        initial, rate_field = self.settings.initial, self.settings.rate_field
        if not np.isfinite(initial) or initial < 0:
            raise ValueError(f"plastic_strain: initial must be a finite number >= 0, got {initial}")
        if not isinstance(rate_field, str) or not rate_field.isidentifier():
            raise ValueError(f"plastic_strain: rate_field must be a field name, got {rate_field!r}")

    @property
    def rate_field(self) -> str:
        """The mesh field integrated."""
        return self.settings.rate_field

    def initialise(self, swarm: Swarm, rows: npt.NDArray[np.integer], context: PropertyContext) -> None:
        write_rows(swarm, self.column, rows, self.settings.initial)
