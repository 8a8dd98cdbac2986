"""Population control: keep the number of particles per cell between two bounds (collective).

Following ASPECT's particle load balancing ("add particles in cells with fewer than min, remove in
cells with more than max"):

- **Removal**: in a cell with ``n > max_per_cell`` particles, each particle gets the random key
  ``hash(stream(seed, step, cell key), id)`` and the ``n - max_per_cell`` particles with the largest
  keys are removed.
- **Addition**: a cell with ``n < min_per_cell`` gets ``min_per_cell - n`` particles at uniformly
  random positions in the cell (the reference-cell sampling of :mod:`particles.generation`).
- **Method** ``density`` (:mod:`particles.population.density`): the same counts are removed and added, but
  the removed particles are the most clustered ones (highest kernel density estimate, greedily)
  and the new ones go where the estimate is lowest (uniformly random within the emptiest of the
  cell's sub-cells), following ASPECT's point-density-function algorithms.
- **Randomness** is counter-based and keyed by ``(seed, step, cell key)`` with the generators'
  partition-independent cell key (the cell's sorted node coordinates), so the same swarm gives the
  same result on any number of ranks.
- **Ids** of new particles are globally unique: ``max global id + 1`` plus an offset from an
  exclusive scan over ranks of the new-particle counts taken in the global order of cell keys
  (:func:`particles.generation.ordering.key_order_offsets`), which makes them rank-count
  independent as well.
- **Properties** of new particles are set by a hook ``initialise(swarm, rows)`` (``rows``: int64
  rows of the new particles in the swarm after insertion). The hook is called on every rank, also
  with no rows, so it may be collective. The default, :func:`copy_nearest`, copies all property
  columns from the nearest pre-existing particle of the same cell (ties: smallest id); in a cell
  that had no particles, every column takes the empty-cell rule of
  :mod:`particles.interpolation.fill` applied to the cell averages (outward averaging of
  neighbouring cells, across ranks).
"""

from __future__ import annotations

from dataclasses import dataclass
from collections.abc import Callable

import numba
import numpy as np
import numpy.typing as npt
from mpi4py import MPI

from fembase.streams import cell_streams, mix, uniforms
from particles.generation.base import first_free_id, insert_in_cells
from particles.generation.maps import CellMaps
from particles.generation.ordering import key_order_offsets
from particles.generation.sampling import uniform_reference_points
from particles.population.density import Neighbourhood, addition_points, removal_mask
from particles.parallel.ghosts import ghost_exchange_for
from particles.interpolation.fill import fill_cells
from particles.storage.swarm import Swarm

__all__ = ["METHODS", "Initialise", "PopulationControl", "PopulationStats", "control_population", "copy_nearest"]

Initialise = Callable[[Swarm, npt.NDArray[np.int64]], None]
"""Hook setting the properties of new particles: ``initialise(swarm, rows)`` (called on all ranks)."""

_STREAM_ADD = 0x5A17
_STREAM_REMOVE = 0x5A18
METHODS = ("count", "density")
"""Population-control methods: random choice (``count``) or by particle density (``density``)."""


@dataclass(frozen=True)
class PopulationStats:
    """What one population-control call did.

    Attributes:
        added, removed: Particles added / removed on this rank.
        global_added, global_removed: Sums over all ranks.
        global_before, global_after: Global particle counts before and after.
    """

    added: int
    removed: int
    global_added: int
    global_removed: int
    global_before: int
    global_after: int


@numba.njit(cache=True)
def _nearest_old(rows, cells, offsets, x, ids, is_new, src):  # pragma: no cover - compiled
    """For each new row, the nearest old row of the same cell (ties: smallest id), -1 if none."""
    gdim = x.shape[1]
    for i in range(rows.shape[0]):
        r = rows[i]
        k = cells[r]
        best = -1
        best_d2 = np.inf
        for p in range(offsets[k], offsets[k + 1]):
            if is_new[p]:
                continue
            d2 = 0.0
            for g in range(gdim):
                t = x[p, g] - x[r, g]
                d2 += t * t
            if d2 < best_d2 or (d2 == best_d2 and ids[p] < ids[best]):
                best_d2 = d2
                best = p
        src[i] = best


def copy_nearest(swarm: Swarm, rows: npt.NDArray[np.int64], /) -> None:
    """Default :data:`Initialise` hook: copy properties from the nearest old particle of the cell.

    New particles in cells without old particles get, per column, the filled cell average (the
    empty-cell rule of :mod:`particles.interpolation.fill`). Collective.
    """
    rows = np.asarray(rows, dtype=np.int64)
    ncols = swarm.num_property_columns
    if ncols == 0:
        return
    is_new = np.zeros(swarm.num_particles, dtype=np.bool_)
    is_new[rows] = True
    src = np.full(rows.shape[0], -1, dtype=np.int64)
    _nearest_old(rows, swarm.cells, swarm.offsets, swarm.x, swarm.ids, is_new, src)
    found = src >= 0
    swarm.properties[rows[found]] = swarm.properties[src[found]]
    orphans = rows[~found]
    if swarm.comm.allreduce(int(orphans.shape[0]), op=MPI.SUM) == 0:
        return
    old = ~is_new
    n_owned = swarm.num_owned_cells
    counts = np.bincount(swarm.cells[old], minlength=n_owned)
    known = counts > 0
    exchange = ghost_exchange_for(swarm.mesh)
    for c in range(ncols):
        sums = np.bincount(swarm.cells[old], weights=swarm.properties[old, c], minlength=n_owned)
        filled, _ = fill_cells(exchange, sums / np.maximum(counts, 1), known)
        swarm.properties[orphans, c] = filled[swarm.cells[orphans]]


@dataclass(frozen=True)
class PopulationControl:
    """Bounds on the particles per cell.

    Attributes:
        min_per_cell: Cells with fewer particles get new ones (0: never add).
        max_per_cell: Cells with more particles lose some (None: never remove).
        seed: Random seed (combined with the step and the cell key).
        method: ``count`` (random particles removed, new ones uniformly random in the cell) or
            ``density`` (most clustered removed, new ones where the density is lowest).
        bandwidth: Kernel radius of the ``density`` method in cell diameters / sqrt(tdim).
    """

    min_per_cell: int = 0
    max_per_cell: int | None = None
    seed: int = 0
    method: str = "count"
    bandwidth: float = 0.3

    def __post_init__(self) -> None:
        if self.min_per_cell < 0:
            raise ValueError("min_per_cell must be >= 0")
        if self.max_per_cell is not None and self.max_per_cell < max(self.min_per_cell, 1):
            raise ValueError("max_per_cell must be >= max(min_per_cell, 1)")
        if self.method not in METHODS:
            raise ValueError(f"method must be one of {list(METHODS)}, not {self.method!r}")
        if not self.bandwidth > 0:
            raise ValueError("bandwidth must be > 0")

    def apply(self, swarm: Swarm, /, *, step: int = 0, initialise: Initialise | None = None) -> PopulationStats:
        """Remove particles above ``max_per_cell`` and add particles below ``min_per_cell`` (collective).

        Args:
            swarm: The particles (sorted, in owned cells).
            step: Time-step number; part of the random key, so every step draws afresh.
            initialise: Property hook for the new particles; default :func:`copy_nearest`.
        """
        comm = swarm.comm
        before = swarm.global_num_particles()
        base = first_free_id(swarm)
        maps = CellMaps(swarm.mesh)
        removed = self._remove(swarm, maps, step)
        added = self._add(swarm, maps, step, base, initialise or copy_nearest)
        totals = comm.allreduce(np.array([added, removed], dtype=np.int64), op=MPI.SUM)
        after = swarm.global_num_particles()
        return PopulationStats(added, removed, int(totals[0]), int(totals[1]), before, after)

    def _streams(self, maps: CellMaps, kind: int, step: int) -> npt.NDArray[np.uint64]:
        stream = int(mix(np.uint64(kind), np.uint64(step & 0xFFFFFFFFFFFFFFFF)))
        return cell_streams(maps.keys, self.seed, stream)

    def _remove(self, swarm: Swarm, maps: CellMaps, step: int) -> int:
        if self.max_per_cell is None:
            return 0
        counts = swarm.particles_per_cell()
        if self.method == "density":
            if not swarm.comm.allreduce(bool(np.any(counts > self.max_per_cell)), op=MPI.LOR):
                return 0
            return swarm.remove(removal_mask(swarm, Neighbourhood.of(swarm, self.bandwidth), self.max_per_cell))
        if not np.any(counts > self.max_per_cell):
            return 0
        streams = self._streams(maps, _STREAM_REMOVE, step)
        keys = mix(streams[swarm.cells], swarm.ids)
        order = np.lexsort((swarm.ids, keys, swarm.cells))
        rank_in_cell = np.empty(swarm.num_particles, dtype=np.int64)
        rank_in_cell[order] = np.arange(swarm.num_particles) - np.repeat(swarm.offsets[:-1], counts)
        return swarm.remove(rank_in_cell >= self.max_per_cell)

    def _add(self, swarm: Swarm, maps: CellMaps, step: int, base: int, initialise: Initialise) -> int:
        counts = swarm.particles_per_cell()
        need = np.maximum(self.min_per_cell - counts, 0).astype(np.int64)
        total = int(need.sum())
        if swarm.comm.allreduce(total, op=MPI.SUM) == 0:
            return 0
        offsets = key_order_offsets(swarm.comm, maps.keys, need)
        idx = np.repeat(np.arange(need.shape[0]), need)
        within = np.arange(total) - np.repeat(np.cumsum(need) - need, need)
        streams = self._streams(maps, _STREAM_ADD, step)
        u = uniforms(streams[idx], within, maps.tdim)
        if self.method == "density":
            idx, xhat = addition_points(Neighbourhood.of(swarm, self.bandwidth), maps, need, u)
        else:
            xhat = uniform_reference_points(maps.basix_cell, u)
        new_ids = base + offsets[idx] + within
        insert_in_cells(swarm, maps, idx, xhat, new_ids)
        rows = np.flatnonzero(swarm.ids >= base).astype(np.int64)
        initialise(swarm, rows)
        return total


def control_population(swarm: Swarm, /, *, min_per_cell: int = 0, max_per_cell: int | None = None, seed: int = 0,
                       step: int = 0, initialise: Initialise | None = None, method: str = "count",
                       bandwidth: float = 0.3) -> PopulationStats:
    """Keep every cell's particle count in ``[min_per_cell, max_per_cell]`` (collective).

    See :class:`PopulationControl`.
    """
    control = PopulationControl(min_per_cell, max_per_cell, seed, method, bandwidth)
    return control.apply(swarm, step=step, initialise=initialise)
