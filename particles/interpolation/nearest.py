"""Nearest particle: each dof takes the value of the particle of its cell nearest to the dof point.

For a DG0 target the dof point is the cell midpoint; for DG_k the Lagrange points of the cell.
Ties (equal distances) go to the smallest particle id, so the result does not depend on the
storage order. Only discontinuous targets (a continuous dof has no single cell). Empty cells follow
the empty-cell rule of :mod:`particles.interpolation.fill`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

import dolfinx.fem

from fembase.registry import Configured
from particles.interpolation._base import InterpolationStats, TargetSpace, property_values, write_with_cell_means
from particles.interpolation._cell_kernels import nearest_values
from particles.storage.swarm import Swarm

__all__ = ["Nearest"]


class Nearest(Configured):
    """Value of the nearest particle of the cell at each dof point (no parameters)."""

    name: ClassVar[str] = "nearest"
    discontinuous: ClassVar[bool] = False
    target_degree: ClassVar[int | None] = None
    description: ClassVar[str] = "value of the particle of the cell nearest to each dof point (DG)"

    @dataclass(frozen=True)
    class Settings:
        """No parameters."""

    def interpolate(self, swarm: Swarm, property_name: str, target: dolfinx.fem.Function, /, *,
                    component: int | None = None) -> InterpolationStats:
        """Write nearest-particle values of ``property_name`` into ``target`` (collective)."""
        space = TargetSpace(target, swarm.num_owned_cells)
        space.require(self.name, continuous=False)
        v = property_values(swarm, property_name, component)
        num = np.zeros(space.num_local_dofs)
        den = np.zeros(space.num_local_dofs)
        nearest_values(space.dof_points(), space.dofs, swarm.offsets, swarm.x, v, swarm.ids, num, den)
        return write_with_cell_means(swarm, space, target, self.name, num=num, den=den, values=v)
