"""``rank``: the MPI rank owning the particle (for pictures of the partition)."""

from __future__ import annotations

from typing import ClassVar

import numpy as np
import numpy.typing as npt

from particles.properties._base import ParticleProperty, PropertyContext, write_rows
from particles.storage.swarm import Swarm

__all__ = ["Rank"]


class Rank(ParticleProperty):
    """The rank of the swarm's communicator that holds the particle (refreshed at output by default)."""

    name: ClassVar[str] = "rank"
    description: ClassVar[str] = "owning MPI rank (for pictures)"
    default_update: ClassVar[str] = "output_only"
    default_new_particles: ClassVar[str] = "reinitialise"

    def initialise(self, swarm: Swarm, rows: npt.NDArray[np.integer], context: PropertyContext) -> None:
        write_rows(swarm, self.column, rows, float(swarm.comm.rank))
