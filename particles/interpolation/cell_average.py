"""Cell averages of the particle values: arithmetic, geometric or harmonic mean (into DG spaces).

ASPECT's "cell average" interpolator. For cell ``K`` with particles ``p = 1..n_K``:

- arithmetic: ``u_K = (1/n_K) sum_p v_p``;
- geometric: ``u_K = exp((1/n_K) sum_p log v_p)`` (values must be > 0);
- harmonic: ``u_K = n_K / sum_p (1 / v_p)`` (values must be > 0), the usual viscosity average.

Every dof of ``K`` gets ``u_K`` (a DG0 target is the intended use). Empty cells follow the
empty-cell rule of :mod:`particles.interpolation.fill` (arithmetic mean of neighbours' averages).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np
from mpi4py import MPI

import dolfinx.fem

from fembase.params import param
from fembase.registry import Configured
from particles.interpolation._base import InterpolationStats, TargetSpace, property_values, write_result
from particles.storage.swarm import Swarm

__all__ = ["CellAverage"]

_MEANS = ("arithmetic", "geometric", "harmonic")


class CellAverage(Configured):
    """The mean of its settings of the particle values in each cell."""

    name: ClassVar[str] = "cell_average"
    discontinuous: ClassVar[bool] = True
    target_degree: ClassVar[int | None] = None
    description: ClassVar[str] = "arithmetic, geometric or harmonic mean of the particles in each cell (DG)"

    @dataclass(frozen=True)
    class Settings:
        """Mean of the particle values in each cell."""

        mean: str = param("arithmetic", help='"arithmetic", "geometric" or "harmonic".')

        def __post_init__(self) -> None:
            if self.mean not in _MEANS:
                raise ValueError(f"unknown mean {self.mean!r}; valid: {list(_MEANS)}")

    settings: Settings

    def interpolate(self, swarm: Swarm, property_name: str, target: dolfinx.fem.Function, /, *,
                    component: int | None = None) -> InterpolationStats:
        """Write the cell means of property ``property_name`` into ``target`` (collective).

        Raises:
            ValueError: On every rank if a geometric/harmonic mean meets a value <= 0 on any rank.
        """
        space = TargetSpace(target, swarm.num_owned_cells)
        space.require(self.name, continuous=False)
        v = property_values(swarm, property_name, component)
        mean = self.settings.mean
        if mean != "arithmetic":
            bad = bool(swarm.comm.allreduce(bool(np.any(~(v > 0))), op=MPI.LOR))
            if bad:
                raise ValueError(f"the {mean} mean needs positive values of {property_name!r}")
        f = v if mean == "arithmetic" else (np.log(v) if mean == "geometric" else 1.0 / v)
        counts = np.diff(swarm.offsets)
        known = counts > 0
        m = np.bincount(swarm.cells, weights=f, minlength=swarm.num_owned_cells) / np.where(known, counts, 1)
        if mean == "geometric":
            m = np.exp(m)
        elif mean == "harmonic":
            m = 1.0 / np.where(known, m, 1.0)
        m = np.where(known, m, 0.0)
        num = np.zeros(space.num_local_dofs)
        den = np.zeros(space.num_local_dofs)
        num[space.dofs] = m[:, None]
        den[space.dofs] = known[:, None]
        return write_result(swarm, space, target, self.name, num=num, den=den, cell_values=m, cell_known=known,
                            ghost_particles=0)
