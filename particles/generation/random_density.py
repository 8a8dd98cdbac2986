"""Random particles with a given (non-normalised) density; uniform inside each cell.

Following ASPECT's "random uniform" / "probability density function" generators, cell ``K`` gets
weight ``w_K = int_K rho dx`` (quadrature; the cell volume for a uniform density); the global total
of particles is shared out by :mod:`particles.generation._allocation` (expected count
``N w_K / sum w``, partition independent), and each particle is placed uniformly in its cell
(uniform reference-simplex sample, affine map). Every draw comes from the cell's own random stream,
and ids follow the global order of cell keys, so a fixed seed gives the same (id, position) set on
any number of ranks. Inside a cell the density is treated as constant; use
``metropolis_hastings`` to follow it inside cells (or for non-affine cells).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from fembase.params import param
from fembase.registry import Configured
from fembase.streams import cell_streams, uniforms
from particles.generation._allocation import allocate_counts
from particles.generation.base import Density, DensityGenerator, GenerationResult, first_free_id, insert_in_cells
from particles.generation.maps import CellMaps
from particles.generation.ordering import key_order_offsets
from particles.generation.sampling import cell_weights, uniform_reference_points
from particles.storage.swarm import Swarm

__all__ = ["RandomDensity", "RandomUniform"]

_STREAM = 1


class RandomDensity(DensityGenerator):
    """Random positions with the density of its settings."""

    name: ClassVar[str] = "random_density"
    description: ClassVar[str] = "random positions with probability proportional to a density function"
    affine_cells_only: ClassVar[bool] = True

    @dataclass(frozen=True)
    class Settings:
        """Random positions with density ``rho`` (callable on points shape=(n, gdim) -> (n,), or a text
        that the context makes one of)."""

        num_particles: int = param(help="Global number of particles.")
        seed: int = param(0, help="Random seed.")
        density: Density | str | None = param(None, help="Non-negative, non-normalised density; None means uniform.")
        quadrature_degree: int = param(4, help="Degree of the quadrature rule for the cell integrals of the density.")

    settings: Settings

    def generate(self, swarm: Swarm, /) -> GenerationResult:
        """Insert the particles into ``swarm`` (collective)."""
        s = self.settings
        if s.num_particles < 0:
            raise ValueError("num_particles must be >= 0")
        maps = CellMaps(swarm.mesh)
        if not maps.affine:
            raise ValueError(f"{self.name} needs affine simplex cells; use metropolis_hastings for other cells")
        comm = swarm.comm
        streams = cell_streams(maps.keys, s.seed, _STREAM)
        weights = cell_weights(maps, s.density, s.quadrature_degree)
        counts = allocate_counts(comm, weights, s.num_particles, uniforms(streams, np.zeros(len(streams)), 1)[:, 0])
        offsets = key_order_offsets(comm, maps.keys, counts)
        base = first_free_id(swarm)
        idx = np.repeat(np.arange(counts.shape[0]), counts)
        within = np.arange(idx.shape[0]) - np.repeat(np.cumsum(counts) - counts, counts)
        xhat = uniform_reference_points(maps.basix_cell, uniforms(streams[idx], 1 + within, maps.tdim))
        insert_in_cells(swarm, maps, idx, xhat, base + offsets[idx] + within)
        return GenerationResult(int(idx.shape[0]), s.num_particles, base)


class RandomUniform(Configured):
    """Uniformly distributed random positions (``random_density`` with a constant density)."""

    name: ClassVar[str] = "random_uniform"
    description: ClassVar[str] = "uniformly distributed random positions"
    affine_cells_only: ClassVar[bool] = True

    @dataclass(frozen=True)
    class Settings:
        """Uniformly distributed random positions."""

        num_particles: int = param(help="Global number of particles.")
        seed: int = param(0, help="Random seed.")

    settings: Settings

    def generate(self, swarm: Swarm, /) -> GenerationResult:
        """Insert the particles into ``swarm`` (collective)."""
        s = self.settings
        return RandomDensity(RandomDensity.Settings(s.num_particles, s.seed)).generate(swarm)
