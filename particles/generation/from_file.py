"""Particles at coordinates read from a text file (ASPECT's "ascii file").

The file holds one point per row, ``gdim`` columns (a third all-zero column is accepted in 2D),
whitespace-separated, ``#`` comments. Every rank reads the file, keeps the rows inside the bounding
box of its owned cells, and searches its owned cells; a row's id is ``first_id + row index``.
Rows outside the mesh are counted in ``GenerationResult.num_outside``, not silently dropped.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import numpy as np
import numpy.typing as npt

from fembase.params import param
from fembase.geometry import owned_box
from particles.generation._listed import in_box, insert_listed_points
from particles.generation.base import GenerationResult
from particles.storage.swarm import Swarm

__all__ = ["FromFile"]


@dataclass(frozen=True)
class FromFile:
    """File parameters."""

    name: ClassVar[str] = "from_file"
    description: ClassVar[str] = "positions read from a text file, one point per row"

    path: str | Path = param(help="Text file with one point per row.")

    def read(self, gdim: int) -> npt.NDArray[np.float64]:
        """All points of the file, shape=(n, gdim), float64."""
        data = np.loadtxt(self.path, dtype=np.float64, comments="#", ndmin=2)
        if data.shape[0] == 0:
            return np.empty((0, gdim))
        if data.shape[1] == gdim:
            return data
        if data.shape[1] == 3 and gdim < 3 and np.all(data[:, gdim:] == 0):
            return np.ascontiguousarray(data[:, :gdim])
        raise ValueError(f"{self.path}: expected {gdim} columns, found {data.shape[1]}")

    def generate(self, swarm: Swarm, /) -> GenerationResult:
        """Insert the file's points inside the mesh into ``swarm`` (collective)."""
        x = self.read(swarm.gdim)
        box = owned_box(swarm.mesh)
        index = np.flatnonzero(in_box(x, box)).astype(np.int64)
        return insert_listed_points(swarm, x[index], index, x.shape[0])
