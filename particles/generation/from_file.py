"""Particles at coordinates read from a text file (ASPECT's "ascii file").

The file holds one point per row, ``gdim`` columns (a third all-zero column is accepted in 2D),
whitespace-separated, ``#`` comments. Every rank reads the file, keeps the rows inside the bounding
box of its owned cells, and searches its owned cells; a row's id is ``first_id + row index``.
Rows outside the mesh are counted in ``GenerationResult.num_outside``, not silently dropped.
:meth:`FromFile.build` refuses a path that is not a file, or (given the context's ``gdim``) a file
with the wrong number of columns.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import numpy as np
import numpy.typing as npt

from fembase.params import param
from fembase.geometry import owned_box
from fembase.registry import Configured
from particles.generation._listed import in_box, insert_listed_points
from particles.generation.base import GenerationResult, GeneratorContext
from particles.storage.swarm import Swarm

__all__ = ["FromFile", "check_point_file"]


def check_point_file(path: Path, gdim: int | None) -> None:
    """A point list must exist and have gdim (or 3, padded with zeros) columns (ValueError if not)."""
    if not path.is_file():
        raise ValueError(f"particle file {str(path)!r} not found")
    if gdim is None:
        return
    try:
        data = np.loadtxt(path, comments="#", ndmin=2)
    except ValueError as err:
        raise ValueError(f"particle file {str(path)!r}: {err}") from None
    if data.size and data.shape[1] not in (gdim, 3):
        raise ValueError(f"particle file {str(path)!r}: expected {gdim} columns, found {data.shape[1]}")


class FromFile(Configured):
    """The points of the file of its settings."""

    name: ClassVar[str] = "from_file"
    description: ClassVar[str] = "positions read from a text file, one point per row"
    affine_cells_only: ClassVar[bool] = False

    @dataclass(frozen=True)
    class Settings:
        """File parameters."""

        path: str | Path = param(help="Text file with one point per row.")

    settings: Settings

    @classmethod
    def build(cls, settings: Settings, context: GeneratorContext, /) -> FromFile:
        """The generator of ``settings``, whose file is checked (its columns given ``context.gdim``)."""
        check_point_file(Path(str(settings.path)), context.gdim)
        return cls(settings)

    def read(self, gdim: int) -> npt.NDArray[np.float64]:
        """All points of the file, shape=(n, gdim), float64."""
        path = self.settings.path
        data = np.loadtxt(path, dtype=np.float64, comments="#", ndmin=2)
        if data.shape[0] == 0:
            return np.empty((0, gdim))
        if data.shape[1] == gdim:
            return data
        if data.shape[1] == 3 and gdim < 3 and np.all(data[:, gdim:] == 0):
            return np.ascontiguousarray(data[:, :gdim])
        raise ValueError(f"{path}: expected {gdim} columns, found {data.shape[1]}")

    def generate(self, swarm: Swarm, /) -> GenerationResult:
        """Insert the file's points inside the mesh into ``swarm`` (collective)."""
        x = self.read(swarm.gdim)
        box = owned_box(swarm.mesh)
        index = np.flatnonzero(in_box(x, box)).astype(np.int64)
        return insert_listed_points(swarm, x[index], index, x.shape[0])
