"""The same reference points in every cell: a quadrature rule or a regular interior sub-lattice.

Points are placed through the canonical cell map (simplices: vertices sorted by coordinates), so
the positions do not depend on the partition; ids number the cells in the global order of their
keys (partition independent), then the points inside each cell.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import basix
import numpy as np
import numpy.typing as npt

from fembase.params import param
from fembase.registry import Configured
from particles.generation.base import GenerationResult, first_free_id, insert_in_cells
from particles.generation.maps import CellMaps
from particles.generation.ordering import key_order_offsets
from particles.storage.swarm import Swarm

__all__ = ["ReferencePoints"]

_KINDS = ("quadrature", "lattice")


class ReferencePoints(Configured):
    """The reference points of its settings in every owned cell."""

    name: ClassVar[str] = "reference_points"
    description: ClassVar[str] = "the same reference points (quadrature points or a sub-lattice) in every cell"
    affine_cells_only: ClassVar[bool] = False

    @dataclass(frozen=True)
    class Settings:
        """Per-cell reference points."""

        kind: str = param("quadrature", help="\"quadrature\" (the points of basix's default rule of `degree`) or "
                                             "\"lattice\" (the interior points of basix's equispaced lattice with "
                                             "`degree` intervals per edge).")
        degree: int = param(2, help="Quadrature degree, or number of lattice intervals per reference edge.")

    settings: Settings

    def reference_points(self, cell: basix.CellType) -> npt.NDArray[np.float64]:
        """The points in the reference cell, shape=(q, tdim)."""
        kind, degree = self.settings.kind, self.settings.degree
        if kind == "quadrature":
            return np.asarray(basix.make_quadrature(cell, degree)[0], dtype=np.float64)
        if kind == "lattice":
            return np.asarray(basix.create_lattice(cell, degree, basix.LatticeType.equispaced, False))
        raise ValueError(f"unknown reference point kind {kind!r}; valid: {list(_KINDS)}")

    def generate(self, swarm: Swarm, /) -> GenerationResult:
        """Insert the particles into ``swarm`` (collective)."""
        maps = CellMaps(swarm.mesh)
        points = self.reference_points(maps.basix_cell)
        q, m = points.shape[0], maps.cells.shape[0]
        offsets = key_order_offsets(swarm.comm, maps.keys, np.full(m, q, dtype=np.int64))
        base = first_free_id(swarm)
        idx = np.repeat(np.arange(m), q)
        within = np.tile(np.arange(q), m)
        insert_in_cells(swarm, maps, idx, points[within], base + offsets[idx] + within)
        num_global = int(swarm.comm.allreduce(m * q))
        return GenerationResult(m * q, num_global, base)
