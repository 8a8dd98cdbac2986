"""Random particles following a density inside cells too: Metropolis-Hastings per cell.

As in the seed paper, particle counts per cell come from the cell integrals of the density
(:mod:`particles.generation._allocation`), and the positions inside cell ``K`` are samples of a
Metropolis-Hastings chain in the reference cell with target ``g(X) = rho(Phi_K(X)) |det J_K(X)|``,
which is the density pulled back to the reference cell (so curved and non-affine cells are
sampled correctly). Proposals are independent uniform points of the reference cell; a proposal
``X'`` is accepted when ``u g(X) < g(X')``. A chain starts at the first of up to
``_START_TRIES`` uniform points where ``g > 0`` (a cell that the density covers only in part would
otherwise keep states outside the density's support), and never leaves the support afterwards.
After ``burn_in`` steps every ``thinning``-th state is kept. Each cell's chain draws from the
cell's own random stream, so the result does not depend on the number of ranks.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import numpy.typing as npt

from fembase.params import param
from fembase.streams import cell_streams, uniforms
from particles.generation._allocation import allocate_counts
from particles.generation.base import (
    Density, DensityGenerator, GenerationResult, evaluate_density, first_free_id, insert_in_cells)
from particles.generation.maps import CellMaps
from particles.generation.ordering import key_order_offsets
from particles.generation.sampling import cell_weights, uniform_reference_points
from particles.storage.swarm import Swarm

__all__ = ["MetropolisHastings"]

_STREAM = 2
_START_TRIES = 1000
_START_COUNTER = 1 << 40  # stream positions of the start search, far from the chain's own


class MetropolisHastings(DensityGenerator):
    """Metropolis-Hastings sampling of the density of its settings."""

    name: ClassVar[str] = "metropolis_hastings"
    description: ClassVar[str] = "density-following positions by a Metropolis-Hastings chain in each cell"
    affine_cells_only: ClassVar[bool] = False

    @dataclass(frozen=True)
    class Settings:
        """Metropolis-Hastings sampling of ``rho`` (callable on points shape=(n, gdim) -> (n,), or a
        text that the context makes one of)."""

        num_particles: int = param(help="Global number of particles.")
        density: Density | str | None = param(None, help="Non-negative, non-normalised density; None means uniform.")
        seed: int = param(0, help="Random seed.")
        thinning: int = param(10, help="Keep every `thinning`-th chain state (J in the seed paper).")
        burn_in: int = param(20, help="Chain steps discarded before the first kept state.")
        quadrature_degree: int = param(4, help="Degree of the quadrature rule for the cell integrals.")

    settings: Settings

    def _target(self, maps: CellMaps, idx: npt.NDArray[np.int64], xhat: npt.NDArray[np.float64]
                ) -> npt.NDArray[np.float64]:
        g = maps.abs_det(idx, xhat)
        if self.settings.density is not None:
            g = g * evaluate_density(self.settings.density, maps.push(idx, xhat))
        return g

    def generate(self, swarm: Swarm, /) -> GenerationResult:
        """Insert the particles into ``swarm`` (collective)."""
        s = self.settings
        if s.thinning < 1 or s.burn_in < 0 or s.num_particles < 0:
            raise ValueError("need thinning >= 1, burn_in >= 0, num_particles >= 0")
        comm = swarm.comm
        maps = CellMaps(swarm.mesh)
        streams = cell_streams(maps.keys, s.seed, _STREAM)
        weights = cell_weights(maps, s.density, s.quadrature_degree)
        counts = allocate_counts(comm, weights, s.num_particles, uniforms(streams, np.zeros(len(streams)), 1)[:, 0])
        offsets = key_order_offsets(comm, maps.keys, counts)
        base = first_free_id(swarm)
        chains = np.flatnonzero(counts > 0)
        tdim = maps.tdim
        state = uniform_reference_points(maps.basix_cell, uniforms(streams[chains], np.ones(chains.shape[0]), tdim))
        g = self._target(maps, chains, state)
        outside = np.flatnonzero(g <= 0)
        for k in range(_START_TRIES):
            if outside.size == 0:
                break
            u = uniforms(streams[chains[outside]], np.full(outside.shape[0], _START_COUNTER + k), tdim)
            proposal = uniform_reference_points(maps.basix_cell, u)
            g_new = self._target(maps, chains[outside], proposal)
            hit = g_new > 0
            state[outside[hit]] = proposal[hit]
            g[outside[hit]] = g_new[hit]
            outside = outside[~hit]
        steps = s.burn_in + counts[chains] * s.thinning
        samples = np.empty((int(counts.sum()), tdim))
        start = (np.cumsum(counts) - counts)[chains]
        for t in range(1, int(steps.max(initial=0)) + 1):
            active = np.flatnonzero(steps >= t)
            u = uniforms(streams[chains[active]], np.full(active.shape[0], 1 + t), tdim + 1)
            proposal = uniform_reference_points(maps.basix_cell, u[:, :tdim])
            g_new = self._target(maps, chains[active], proposal)
            accept = (u[:, tdim] * g[active] < g_new) | (g[active] <= 0)
            state[active[accept]] = proposal[accept]
            g[active[accept]] = g_new[accept]
            kept = t - s.burn_in
            if kept > 0 and kept % s.thinning == 0:
                samples[start[active] + kept // s.thinning - 1] = state[active]
        idx = np.repeat(np.arange(counts.shape[0]), counts)
        within = np.arange(idx.shape[0]) - np.repeat(np.cumsum(counts) - counts, counts)
        insert_in_cells(swarm, maps, idx, samples, base + offsets[idx] + within)
        return GenerationResult(int(idx.shape[0]), s.num_particles, base)
