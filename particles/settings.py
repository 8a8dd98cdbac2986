"""The parameters of a particle system, declared once: :class:`ParticleSettings`.

The dataclasses are the one declaration of a ``particles`` config section: their defaults are the
defaults of :meth:`particles.manager.ParticleManager.from_config`, and ``convection``'s config
loader turns them into the schema of its ``particles`` section (and its config reference), so
the two cannot drift apart. Names are checked against the registries
(:data:`particles.advection.INTEGRATORS`, :data:`particles.io.output.PARTICLE_WRITERS`), read when a
config is checked. The ``output`` subsection is the particle writers' settings, declared with them
(:class:`particles.io.output.ParticleOutputSettings`).
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from collections.abc import Mapping
from typing import Any

from fembase.params import MAX_ENTRIES, Names, param, settings_from, short_repr, subsection
from particles.io.output import ParticleOutputSettings

__all__ = ["ParticleOutputSettings", "ParticleSettings", "PopulationSettings", "particle_settings"]


def _names(module: str, name: str) -> Names:
    """The names of the registry ``module.name``, imported when a config is checked."""
    return Names(lambda: getattr(importlib.import_module(module), name))


def _is_list(value: Any) -> str | None:
    return None if isinstance(value, list) else f"expected a list, got {short_repr(value)}"


@dataclass(frozen=True)
class PopulationSettings:
    """Particles per cell kept within bounds (:class:`particles.population.control.PopulationControl`)."""

    min_per_cell: int = param(0, minimum=0, help="cells with fewer particles get new ones")
    max_per_cell: int | None = param(None, minimum=1, help="cells with more particles lose some (null: never)")
    seed: int = param(0, help="random seed of the population control")
    method: str = param("count", choices=("count", "density"),
                        help="count: random particles removed, new ones uniformly random in the cell; density: "
                             "the most clustered removed, new ones where the kernel density estimate is lowest")
    bandwidth: float = param(0.3, exclusive_minimum=0.0,
                             help="kernel radius of the density method, in cell diameters / sqrt(dim)")

    @property
    def enabled(self) -> bool:
        """Whether the bounds ask for anything (a minimum above 0 or a maximum)."""
        return bool(self.min_per_cell) or self.max_per_cell is not None


@dataclass(frozen=True)
class ParticleSettings:
    """One particle system: how particles are made, moved, carried, averaged, kept and written."""

    generator: Mapping[str, Any] = param({"name": "random_uniform", "particles_per_cell": 20, "seed": 1},
                                         help="generator name and parameters; particles_per_cell may replace "
                                              "num_particles")
    integrator: str = param("rk2", choices=_names("particles.advection", "INTEGRATORS"),
                            help="time integrator of the particle positions (and integrated properties)")
    interpolator: Mapping[str, Any] = param({"name": "cell_average", "mean": "arithmetic"},
                                            help="particle-to-mesh interpolator name and parameters")
    properties: list[Any] = param([], kind="any", check=_is_list, max_items=MAX_ENTRIES,
                                  help="properties every particle carries: names or {name: ..., parameters}")
    population: PopulationSettings = subsection(PopulationSettings)
    output: ParticleOutputSettings = subsection(ParticleOutputSettings)


def particle_settings(section: Mapping[str, Any] | ParticleSettings, /) -> ParticleSettings:
    """:class:`ParticleSettings` from a (possibly partial) config section: missing keys, and a
    ``null`` population or output, take the defaults; keys that are not settings (a front end's
    ``enabled``) are ignored. Values are not checked here (a config loader checks them)."""
    if isinstance(section, ParticleSettings):
        return section
    return settings_from(ParticleSettings, {k: v for k, v in section.items() if v is not None})
