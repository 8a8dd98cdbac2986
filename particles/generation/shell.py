"""Points on circles (2D) or spheres (3D) around a centre, several radii.

Shell ``s`` has ``counts[s]`` points of radius ``radii[s]``: in 2D at angles ``2 pi k / n``; in
3D on a Fibonacci (golden-angle) spiral, ``z_k = 1 - (2k + 1) / n``, which spreads points evenly.
Points are listed shell by shell; a point's id is ``first_id + list index``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import numpy.typing as npt

from fembase.params import param
from fembase.geometry import owned_box
from fembase.registry import Configured
from particles.generation._listed import in_box, insert_listed_points
from particles.generation.base import GenerationResult
from particles.storage.swarm import Swarm

__all__ = ["Shell"]


class Shell(Configured):
    """The shells of its settings."""

    name: ClassVar[str] = "shell"
    description: ClassVar[str] = "points on circles or spheres: given radii and points per shell"
    affine_cells_only: ClassVar[bool] = False

    @dataclass(frozen=True)
    class Settings:
        """Shell parameters."""

        center: tuple[float, ...] = param(help="Centre, length gdim (2 or 3).")
        radii: tuple[float, ...] = param(help="Radius of each shell.")
        counts: tuple[int, ...] = param(help="Points on each shell.")

    settings: Settings

    def points(self) -> npt.NDArray[np.float64]:
        """All points of all shells, shape=(sum(counts), gdim)."""
        s = self.settings
        gdim = len(s.center)
        if len(s.radii) != len(s.counts) or gdim not in (2, 3):
            raise ValueError("shell needs a 2D/3D centre and one count per radius")
        blocks = []
        for radius, n in zip(s.radii, s.counts):
            k = np.arange(int(n), dtype=np.float64)
            if gdim == 2:
                phi = 2.0 * np.pi * k / n
                unit = np.stack([np.cos(phi), np.sin(phi)], axis=1)
            else:
                z = 1.0 - (2.0 * k + 1.0) / n
                r = np.sqrt(1.0 - z * z)
                phi = k * np.pi * (3.0 - np.sqrt(5.0))
                unit = np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)
            blocks.append(np.asarray(s.center, dtype=np.float64) + radius * unit)
        return np.concatenate(blocks) if blocks else np.empty((0, gdim))

    def generate(self, swarm: Swarm, /) -> GenerationResult:
        """Insert the shell points inside the mesh into ``swarm`` (collective)."""
        if len(self.settings.center) != swarm.gdim:
            raise ValueError(f"shell centre must have {swarm.gdim} coordinates")
        x = self.points()
        box = owned_box(swarm.mesh)
        index = np.flatnonzero(in_box(x, box)).astype(np.int64)
        return insert_listed_points(swarm, x[index], index, x.shape[0])
