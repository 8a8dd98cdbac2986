"""A regular lattice of points in a box (ASPECT's "uniform box").

Along direction ``d`` there are ``counts[d]`` points from ``lower[d]`` to ``upper[d]`` inclusive
(one point: the middle). The point with lattice index ``(i_0, ..., i_{d-1})`` has list index
``ravel_multi_index`` (C order) and id ``first_id + list index``. Each rank only builds the part of
the lattice inside the bounding box of its owned cells, so no rank holds the whole lattice.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import numpy.typing as npt

from fembase.params import param
from fembase.geometry import owned_box
from fembase.registry import Configured
from particles.generation._listed import insert_listed_points
from particles.generation.base import GenerationResult
from particles.storage.swarm import Swarm

__all__ = ["BoxLattice"]


class BoxLattice(Configured):
    """The lattice of its settings."""

    name: ClassVar[str] = "box_lattice"
    description: ClassVar[str] = "regular lattice of points in a box with a given count per direction"
    affine_cells_only: ClassVar[bool] = False

    @dataclass(frozen=True)
    class Settings:
        """Lattice parameters (each a tuple of length gdim)."""

        lower: tuple[float, ...] = param(help="Lower corner of the box.")
        upper: tuple[float, ...] = param(help="Upper corner of the box.")
        counts: tuple[int, ...] = param(help="Points per direction (>= 1).")

    settings: Settings

    def axis(self, d: int) -> npt.NDArray[np.float64]:
        """Coordinates of the lattice planes along direction ``d``, shape=(counts[d],)."""
        s = self.settings
        n, lo, hi = int(s.counts[d]), float(s.lower[d]), float(s.upper[d])
        if n == 1:
            return np.array([0.5 * (lo + hi)])
        return lo + np.arange(n) * ((hi - lo) / (n - 1))

    def generate(self, swarm: Swarm, /) -> GenerationResult:
        """Insert the lattice points inside the mesh into ``swarm`` (collective)."""
        gdim, s = swarm.gdim, self.settings
        if not (len(s.lower) == len(s.upper) == len(s.counts) == gdim) or min(s.counts) < 1:
            raise ValueError(f"box_lattice needs lower, upper, counts of length {gdim} and counts >= 1")
        box = owned_box(swarm.mesh)
        tol = 1e-10 * max(1.0, float(np.max(np.abs(np.concatenate([s.lower, s.upper])))))
        selected = []
        for d in range(gdim):
            c = self.axis(d)
            selected.append(np.flatnonzero((c >= box[0, d] - tol) & (c <= box[1, d] + tol)))
        grids = np.meshgrid(*selected, indexing="ij")
        multi = tuple(g.reshape(-1) for g in grids)
        index = np.ravel_multi_index(multi, tuple(int(n) for n in s.counts)).astype(np.int64)
        x = np.stack([self.axis(d)[multi[d]] for d in range(gdim)], axis=1).reshape(-1, gdim)
        return insert_listed_points(swarm, x, index, int(np.prod(s.counts)))
