"""Particle generators (seed paper section 2.2), one module per generator, and their registry.

Every generator has the one plugin shape (:class:`fembase.registry.Plugin`): a ``Settings``
dataclass of its parameters, made by ``GENERATORS.build(name, settings, GeneratorContext(...))``
(the context turns a text density into a function and gives the dimension a point file is checked
against), with a collective ``generate(swarm) -> GenerationResult``. Ids are globally unique and
contiguous, and with a fixed seed the set of (id, position) pairs does not depend on the number of
ranks: random draws come from per-cell streams keyed by the cell's sorted node coordinates, counts
per cell follow a partition-independent rule, and ids follow the global order of cell keys (cell generators) or the
index in the global point list (lattice, shell, file). Each particle lands in an owned cell; a
point on a partition boundary goes to the lowest rank that contains it.
"""

from __future__ import annotations

from typing import Any

from particles.generation.base import Density, GenerationResult, Generator, GeneratorContext, MakeFunction
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
    "GeneratorContext",
    "MakeFunction",
    "MetropolisHastings",
    "RandomDensity",
    "RandomUniform",
    "ReferencePoints",
    "Shell",
    "generate",
]

GENERATORS: Registry[type[Generator]] = Registry(
    "particle generator",
    (RandomUniform, RandomDensity, MetropolisHastings, BoxLattice, Shell, FromFile, ReferencePoints),
)
"""Generator classes by their lowercase config name."""


def generate(swarm: Swarm, generator: Generator | str, /, **parameters: Any) -> GenerationResult:
    """Insert particles into ``swarm`` (collective).

    Args:
        swarm: Target swarm.
        generator: A generator object, or a registered name whose ``Settings`` are made of ``parameters``.
    """
    if isinstance(generator, str):
        settings = GENERATORS.settings(generator, **parameters)
        generator = GENERATORS.build(generator, settings, GeneratorContext(gdim=swarm.gdim))
    elif parameters:
        raise TypeError("parameters are only accepted together with a generator name")
    return generator.generate(swarm)
