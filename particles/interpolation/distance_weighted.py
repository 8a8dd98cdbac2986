"""Inverse-distance weighting of the particles in reach of each dof point.

    u_d = sum_p w_p v_p / sum_p w_p,   w_p = max(|y_d - x_p|, eps h_K)^(-power),

with ``y_d`` the dof point (a DG0 target: the cell midpoint). The floor ``eps h_K`` (``h_K`` the
cell diameter) keeps the weight finite when a particle sits on the dof point; such a particle then
dominates and ``u_d`` is its value to round-off. The reach is:

- discontinuous targets: the particles of the dof's cell, plus (``use_neighbours=True``) those of
  all cells sharing a vertex with it, including other ranks' cells through the ghost layer of
  :mod:`particles.parallel.ghosts` (complete for any DOLFINx ghost mode);
- continuous targets (P1, any Lagrange degree): the particles of every cell containing the dof,
  summed over ranks by a reverse scatter (``use_neighbours`` is not accepted).

Dofs with nothing in reach follow the empty-cell rule of :mod:`particles.interpolation.fill`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

import dolfinx.fem

from fembase.params import param
from fembase.registry import Configured
from particles.interpolation._base import InterpolationStats, TargetSpace, gather_samples, write_with_cell_means
from particles.interpolation._cell_kernels import idw_accumulate
from particles.storage.swarm import Swarm

__all__ = ["DistanceWeighted", "cell_diameters"]


def cell_diameters(swarm: Swarm) -> np.ndarray:
    """Twice the largest centre-to-vertex distance of each owned cell, shape=(num_owned_cells,)."""
    geo = swarm.geometry
    n = swarm.num_owned_cells
    v = geo.coords[geo.nodes[:n, : geo.num_vertices]]
    return 2.0 * np.sqrt(((v - geo.centres[:n, None, :]) ** 2).sum(axis=2).max(axis=1)) if n else np.empty(0)


class DistanceWeighted(Configured):
    """Inverse-distance weighted average at the dof points, with the weights of its settings."""

    name: ClassVar[str] = "distance_weighted"
    discontinuous: ClassVar[bool] = False
    target_degree: ClassVar[int | None] = None
    description: ClassVar[str] = ("inverse-distance weighted average of the particles in the cell (and neighbours) at "
                                  "the dof points")

    @dataclass(frozen=True)
    class Settings:
        """Inverse-distance weighted average at the dof points."""

        power: float = param(2.0, help="Exponent of the inverse distance (> 0).")
        use_neighbours: bool = param(False, help="Also use the particles of vertex-neighbour cells (DG targets; "
                                                 "collective ghost exchange).")
        eps: float = param(1e-9, help="Distance floor relative to the cell diameter.")

        def __post_init__(self) -> None:
            if not self.power > 0 or not self.eps > 0:
                raise ValueError("power and eps must be > 0")

    settings: Settings

    def interpolate(self, swarm: Swarm, property_name: str, target: dolfinx.fem.Function, /, *,
                    component: int | None = None) -> InterpolationStats:
        """Write the weighted averages of ``property_name`` into ``target`` (collective)."""
        s = self.settings
        space = TargetSpace(target, swarm.num_owned_cells)
        if s.use_neighbours:
            space.require(f"{self.name} with use_neighbours", continuous=False)
        samples = gather_samples(swarm, property_name, component, ghosts=s.use_neighbours)
        ex = samples.exchange
        nb_off = ex.neighbour_offsets if ex is not None else np.zeros(swarm.num_owned_cells + 1, dtype=np.int64)
        nb_cells = ex.neighbour_cells if ex is not None else np.zeros(0, dtype=np.int32)
        num = np.zeros(space.num_local_dofs)
        den = np.zeros(space.num_local_dofs)
        floor = s.eps * cell_diameters(swarm)
        idw_accumulate(space.dof_points(), space.dofs, samples.offsets, np.ascontiguousarray(samples.x),
                       samples.values, nb_off, nb_cells, s.use_neighbours, float(s.power), floor, num, den)
        return write_with_cell_means(swarm, space, target, self.name, num=num, den=den,
                                     values=samples.values[: swarm.num_particles], ghost_particles=samples.num_ghosts)
