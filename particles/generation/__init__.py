"""Particle generators (seed paper section 2.2), one module per generator, and their registry.

Every generator is a frozen dataclass of its parameters with a collective
``generate(swarm) -> GenerationResult``. Ids are globally unique and contiguous, and with a fixed
seed the set of (id, position) pairs does not depend on the number of ranks: random draws come
from per-cell streams keyed by the cell's sorted node coordinates, counts per cell follow a
partition-independent rule, and ids follow the global order of cell keys (cell generators) or the
index in the global point list (lattice, shell, file). Each particle lands in an owned cell; a
point on a partition boundary goes to the lowest rank that contains it.
"""

from __future__ import annotations

from typing import Any

from particles.generation.base import Density, GenerationResult, Generator
from particles.generation.box_lattice import BoxLattice
from particles.generation.from_file import FromFile
from particles.generation.metropolis_hastings import MetropolisHastings
from particles.generation.random_density import RandomDensity, RandomUniform
from particles.generation.reference_points import ReferencePoints
from particles.generation.shell import Shell
from fembase.registry import Registry
from particles.storage.swarm import Swarm

__all__ = [
    "GENERATORS",
    "BoxLattice",
    "Density",
    "FromFile",
    "GenerationResult",
    "Generator",
    "MetropolisHastings",
    "RandomDensity",
    "RandomUniform",
    "ReferencePoints",
    "Shell",
    "create_generator",
    "generate",
]

GENERATORS: Registry[type[Generator]] = Registry(
    "particle generator",
    (RandomUniform, RandomDensity, MetropolisHastings, BoxLattice, Shell, FromFile, ReferencePoints),
)
"""Generator classes by their lowercase config name."""

create_generator = GENERATORS.create


def generate(swarm: Swarm, generator: Generator | str, /, **parameters: Any) -> GenerationResult:
    """Insert particles into ``swarm`` (collective).

    Args:
        swarm: Target swarm.
        generator: A generator object, or a registered name built with ``parameters``.
    """
    if isinstance(generator, str):
        generator = create_generator(generator, **parameters)
    elif parameters:
        raise TypeError("parameters are only accepted together with a generator name")
    return generator.generate(swarm)
