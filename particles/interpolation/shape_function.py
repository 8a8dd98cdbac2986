"""Shape-function weighting: the target's own basis functions weigh the particles.

    u_i = sum_p phi_i(x_p) v_p / sum_p phi_i(x_p),

summed over every particle in the support of ``phi_i``. For a DG target the support is one cell;
for a continuous P1/Q1 target it is every cell around the vertex, including cells of other ranks:
each rank adds its owned cells' contributions into the local (owned + ghost) dof vector, a reverse
scatter sums them on the dof's owner, and a forward scatter updates the ghosts. Needs
non-negative basis functions, so degree <= 1. A DG0 target gives the arithmetic cell average.

Exactness: constants are reproduced exactly. A linear field ``f`` gives
``u_i = f(xbar_i)`` at the phi_i-weighted particle centroid ``xbar_i = sum phi_i x_p / sum phi_i``,
so ``u_i = f(x_i)`` exactly where that centroid is the dof point (e.g. interior vertices with a
point-symmetric patch and the same symmetric reference points in every cell), not in general.
Dofs with zero total weight follow the empty-cell rule of :mod:`particles.interpolation.fill`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

import dolfinx.fem

from fembase.registry import Configured
from particles.interpolation._base import InterpolationStats, TargetSpace, property_values, write_with_cell_means
from particles.storage.swarm import Swarm

__all__ = ["ShapeFunction"]


class ShapeFunction(Configured):
    """Weighting by the target's basis functions at the particles (no parameters)."""

    name: ClassVar[str] = "shape_function"
    discontinuous: ClassVar[bool] = False
    target_degree: ClassVar[int | None] = None
    description: ClassVar[str] = ("u_i = sum phi_i(x_p) v_p / sum phi_i(x_p) into P1/Q1 (continuous, across ranks) "
                                  "or DG0/DG1")

    @dataclass(frozen=True)
    class Settings:
        """No parameters."""

    def interpolate(self, swarm: Swarm, property_name: str, target: dolfinx.fem.Function, /, *,
                    component: int | None = None) -> InterpolationStats:
        """Write the shape-function weighted values of ``property_name`` into ``target`` (collective)."""
        space = TargetSpace(target, swarm.num_owned_cells)
        space.require(self.name, max_degree=1)
        v = property_values(swarm, property_name, component)
        n = swarm.num_particles
        if n:
            phi = space.element.tabulate(0, np.ascontiguousarray(swarm.xref))[0, :, :, 0]
        else:
            phi = np.empty((0, space.dofs.shape[1]))
        flat = space.dofs[swarm.cells].reshape(-1)
        num = np.bincount(flat, weights=(phi * v[:, None]).reshape(-1), minlength=space.num_local_dofs)
        den = np.bincount(flat, weights=phi.reshape(-1), minlength=space.num_local_dofs)
        return write_with_cell_means(swarm, space, target, self.name, num=num, den=den, values=v)
