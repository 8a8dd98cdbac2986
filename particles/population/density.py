"""Kernel density estimates of the particles around each cell, and the density-based choice of the
particles to remove and of the places to add new ones (``population.method: density``).

Following ASPECT's "point density function" removal and addition algorithms (PRs #6333, #6443):

- **Estimate.** For a point ``y`` in owned cell ``c`` the (unnormalised) kernel density estimate is

  .. math::  \\rho(y) = \\sum_{q \\in P(c)} K\\big(|y - x_q| / h_c\\big), \\qquad K(r) = \\max(0, 1 - r^2),

  the Epanechnikov kernel, where ``P(c)`` are the particles of ``c`` and of every cell sharing a
  vertex with it (other ranks' cells through the ghost exchange of :mod:`particles.parallel.ghosts`, so
  particles near a cell's edge are not under-counted), and ``h_c = bandwidth * diam(c) /
  sqrt(tdim)`` (``diam``: the largest distance between two nodes of the cell; bandwidth 0.3 as
  ASPECT's default). A particle's own term ``K(0) = 1`` is included.
- **Removal.** In a cell with ``n > max`` particles, ``n - max`` particles are removed one at a
  time: each time the one with the highest ``rho`` (ties: the largest id), after which its kernel
  is subtracted from the estimates of the cell's remaining particles. The neighbours' particles
  are those before this call's removals (every cell decides from the same snapshot).
- **Addition.** A cell with ``n < min`` particles gets ``min - n`` particles one at a time: ``rho``
  is evaluated at the centroids of the cell's ``g**tdim`` equal-volume sub-cells
  (:class:`particles.population.subcells.SubCells`, ``g = 4``); the new particle goes to a uniformly random
  point of the sub-cell with the lowest estimate (ties: the lowest sub-cell index, random numbers
  as in the count method), then its kernel is added to the estimates at the centroids.

Every sum runs over ``P(c)`` in the order of particle ids, and sub-cells and maps are taken in the
partition-independent frame of :class:`particles.generation.maps.CellMaps`, so the choices are the
same on any number of ranks. Nothing is kept between calls.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
import numpy.typing as npt

from fembase.geometry import cell_nodes
from particles.generation.maps import CellMaps
from particles.generation.sampling import uniform_reference_points
from particles.parallel.ghosts import ghost_exchange_for
from particles.population.subcells import SubCells
from particles.storage.swarm import Swarm

__all__ = ["ADD_GRANULARITY", "Neighbourhood", "addition_points", "density_at", "particle_density",
           "removal_mask"]

ADD_GRANULARITY = 4
"""Sub-cells per direction whose centroids are the candidate places of new particles."""


@dataclass(frozen=True)
class Neighbourhood:
    """The particles around every owned cell: the owned particles followed by the ghost copies.

    Attributes:
        x: Positions, shape=(m, gdim), float64 (rows ``< swarm.num_particles`` are the swarm's rows).
        ids: Global ids, shape=(m,), int64.
        offsets: Rows of each cell in the owned + halo cell index space, shape=(num_owned + num_halo + 1,).
        neighbour_offsets, neighbour_cells: CSR of the vertex-neighbour cells of each owned cell.
        radius: Kernel radius ``h_c`` of each owned cell, shape=(num_owned,), float64.
    """

    x: npt.NDArray[np.float64]
    ids: npt.NDArray[np.int64]
    offsets: npt.NDArray[np.int64]
    neighbour_offsets: npt.NDArray[np.int64]
    neighbour_cells: npt.NDArray[np.int32]
    radius: npt.NDArray[np.float64]

    @classmethod
    def of(cls, swarm: Swarm, bandwidth: float, /) -> Neighbourhood:
        """The particles of ``swarm`` around its owned cells (collective: one ghost exchange)."""
        exchange = ghost_exchange_for(swarm.mesh)
        ghosts = exchange.exchange(swarm)
        n_owned, n_halo = swarm.num_owned_cells, exchange.num_halo_cells
        ghost_counts = np.bincount(ghosts.cells.astype(np.int64) - n_owned, minlength=n_halo)
        offsets = np.concatenate([swarm.offsets, swarm.offsets[-1] + np.cumsum(ghost_counts)]).astype(np.int64)
        return cls(np.ascontiguousarray(np.concatenate([swarm.x, ghosts.x])),
                   np.concatenate([swarm.ids, ghosts.ids]).astype(np.int64), offsets,
                   exchange.neighbour_offsets.astype(np.int64), exchange.neighbour_cells.astype(np.int32),
                   bandwidth * _diameters(swarm) / np.sqrt(swarm.tdim))


def _diameters(swarm: Swarm) -> npt.NDArray[np.float64]:
    """Largest distance between two nodes of each owned cell, shape=(num_owned,) (order-free)."""
    nodes = cell_nodes(swarm.mesh, np.arange(swarm.num_owned_cells, dtype=np.int32))
    diam = np.zeros(nodes.shape[0])
    for a in range(nodes.shape[1]):
        for b in range(a + 1, nodes.shape[1]):
            d = nodes[:, a, :] - nodes[:, b, :]
            diam = np.maximum(diam, np.sqrt((d * d).sum(axis=1)))
    return diam


@numba.njit(cache=True)
def _kernel(a, b, h2):  # pragma: no cover - compiled
    """``max(0, 1 - |a - b|^2 / h^2)`` (fixed operation order)."""
    d2 = 0.0
    for g in range(a.shape[0]):
        t = a[g] - b[g]
        d2 += t * t
    return 1.0 - d2 / h2 if d2 < h2 else 0.0


@numba.njit(cache=True)
def _members(c, offsets, nb_off, nb_cells, ids):  # pragma: no cover - compiled
    """Rows of the particles of cell ``c`` and its vertex neighbours, sorted by id."""
    total = offsets[c + 1] - offsets[c]
    for k in range(nb_off[c], nb_off[c + 1]):
        n = nb_cells[k]
        total += offsets[n + 1] - offsets[n]
    rows = np.empty(total, dtype=np.int64)
    pos = 0
    for r in range(offsets[c], offsets[c + 1]):
        rows[pos] = r
        pos += 1
    for k in range(nb_off[c], nb_off[c + 1]):
        n = nb_cells[k]
        for r in range(offsets[n], offsets[n + 1]):
            rows[pos] = r
            pos += 1
    return rows[np.argsort(ids[rows])]


@numba.njit(cache=True)
def _density_kernel(cells, points, offsets, nb_off, nb_cells, x, ids, radius, out):  # pragma: no cover
    """``out[i] = rho(points[i])`` in owned cell ``cells[i]`` (points grouped by cell for reuse)."""
    last = -1
    members = np.empty(0, dtype=np.int64)
    for i in range(cells.shape[0]):
        c = cells[i]
        if c != last:
            members = _members(c, offsets, nb_off, nb_cells, ids)
            last = c
        h2 = radius[c] * radius[c]
        s = 0.0
        for q in members:
            s += _kernel(points[i], x[q], h2)
        out[i] = s


@numba.njit(cache=True)
def _removal_kernel(cells, excess, offsets, nb_off, nb_cells, x, ids, radius, remove):  # pragma: no cover
    """Greedy removal of ``excess[t]`` particles of the highest density in each cell ``cells[t]``."""
    for t in range(cells.shape[0]):
        c = cells[t]
        members = _members(c, offsets, nb_off, nb_cells, ids)
        h2 = radius[c] * radius[c]
        r0 = offsets[c]
        n = offsets[c + 1] - r0
        rho = np.zeros(n)
        for i in range(n):
            s = 0.0
            for q in members:
                s += _kernel(x[r0 + i], x[q], h2)
            rho[i] = s
        alive = np.ones(n, dtype=np.bool_)
        for _ in range(excess[t]):
            best = -1
            for i in range(n):
                if not alive[i]:
                    continue
                if best < 0 or rho[i] > rho[best] or (rho[i] == rho[best] and ids[r0 + i] > ids[r0 + best]):
                    best = i
            alive[best] = False
            remove[r0 + best] = True
            for i in range(n):
                if alive[i]:
                    rho[i] -= _kernel(x[r0 + i], x[r0 + best], h2)


def density_at(hood: Neighbourhood, cells: npt.NDArray[np.int64], points: npt.NDArray[np.float64]
               ) -> npt.NDArray[np.float64]:
    """``rho`` at physical points (shape=(p, gdim)) in owned cells ``cells`` (shape=(p,)); shape=(p,)."""
    cells = np.asarray(cells, dtype=np.int64)
    order = np.argsort(cells, kind="stable")
    out = np.empty(cells.shape[0])
    _density_kernel(cells[order], np.ascontiguousarray(points[order], dtype=np.float64), hood.offsets,
                    hood.neighbour_offsets, hood.neighbour_cells, hood.x, hood.ids, hood.radius, out)
    result = np.empty_like(out)
    result[order] = out
    return result


def particle_density(swarm: Swarm, bandwidth: float = 0.3, /) -> npt.NDArray[np.float64]:
    """``rho`` at every particle of ``swarm``, shape=(num_particles,), float64 (collective)."""
    hood = Neighbourhood.of(swarm, bandwidth)
    return density_at(hood, swarm.cells.astype(np.int64), swarm.x)


def removal_mask(swarm: Swarm, hood: Neighbourhood, max_per_cell: int, /) -> npt.NDArray[np.bool_]:
    """The particles to remove so that no cell keeps more than ``max_per_cell``: in each cell the
    most clustered first (see the module docstring); shape=(num_particles,), bool."""
    counts = swarm.particles_per_cell()
    cells = np.flatnonzero(counts > max_per_cell).astype(np.int64)
    remove = np.zeros(swarm.num_particles, dtype=np.bool_)
    _removal_kernel(cells, (counts[cells] - max_per_cell).astype(np.int64), hood.offsets, hood.neighbour_offsets,
                    hood.neighbour_cells, hood.x, hood.ids, hood.radius, remove)
    return remove


def addition_points(hood: Neighbourhood, maps: CellMaps, need: npt.NDArray[np.int64], u: npt.NDArray[np.float64],
                    granularity: int = ADD_GRANULARITY) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.float64]]:
    """Where the new particles go: ``need[c]`` in owned cell ``c``, each in the sub-cell of lowest ``rho``.

    Args:
        hood: The particles around the cells.
        maps: The owned cells' maps (their frame defines the sub-cells).
        need: New particles per owned cell, shape=(num_owned,), int64.
        u: Uniform random numbers of every new particle, shape=(need.sum(), tdim), ordered by cell
            and, within a cell, by the new particle's number ``0 .. need[c] - 1``.

    Returns:
        ``(idx, xhat)``: the owned cell of each new particle, shape=(need.sum(),), and its reference
        point in the frame of ``maps``, shape=(need.sum(), tdim), in the order of ``u``.
    """
    sub = SubCells(maps.basix_cell, granularity)
    cells = np.flatnonzero(need > 0).astype(np.int64)
    nsub = sub.num
    cand_idx = np.repeat(cells, nsub)
    cand_ref = np.tile(sub.centroids, (cells.shape[0], 1))
    cand_x = maps.push(cand_idx, cand_ref).reshape(cells.shape[0], nsub, -1)
    rho = density_at(hood, cand_idx, cand_x.reshape(cand_idx.shape[0], -1)).reshape(cells.shape[0], nsub)
    h2 = (hood.radius[cells] ** 2)[:, None]
    first = np.cumsum(need) - need
    xhat = np.empty((int(need.sum()), maps.tdim))
    unit = uniform_reference_points(maps.basix_cell, np.asarray(u, dtype=np.float64))
    for r in range(int(need.max(initial=0))):
        active = np.flatnonzero(need[cells] > r)
        rows = first[cells[active]] + r
        best = np.argmin(rho[active], axis=1)
        xhat[rows] = sub.sample(best, unit[rows])
        x_new = maps.push(cells[active], xhat[rows])
        d2 = ((cand_x[active] - x_new[:, None, :]) ** 2).sum(axis=2)
        rho[active] += np.where(d2 < h2[active], 1.0 - d2 / h2[active], 0.0)
    return np.repeat(np.arange(need.shape[0], dtype=np.int64), need), xhat

