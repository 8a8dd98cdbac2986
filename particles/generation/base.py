"""Shared pieces of the generators: result type, generator protocol, id base, insertion."""

from __future__ import annotations

from dataclasses import dataclass
from collections.abc import Callable
from typing import ClassVar, Protocol

import numpy as np
import numpy.typing as npt
from mpi4py import MPI

from particles.generation.maps import CellMaps
from particles.storage.swarm import Swarm

__all__ = ["Density", "GenerationResult", "Generator", "evaluate_density", "first_free_id", "insert_in_cells"]

Density = Callable[[npt.NDArray[np.float64]], npt.ArrayLike]
"""A non-normalised density: points shape=(n, gdim), float64 -> values shape=(n,), >= 0."""


@dataclass(frozen=True)
class GenerationResult:
    """What one generator call inserted.

    Attributes:
        num_local: Particles inserted on this rank.
        num_global: Particles inserted on all ranks.
        first_id: Global id of the first inserted particle; ids are first_id .. first_id+num_global-1
            (for the point-list generators: first_id + index in the list, minus points outside).
        num_outside: Points of a point list that no cell of the mesh contains (global; 0 for
            cell-based generators).
    """

    num_local: int
    num_global: int
    first_id: int
    num_outside: int = 0


class Generator(Protocol):
    """A particle generator: a frozen dataclass of parameters with a collective ``generate``."""

    name: ClassVar[str]
    description: ClassVar[str]
    affine_cells_only: ClassVar[bool]
    """True for a generator that needs straight-sided (affine) simplex cells (optional; default False)."""

    def generate(self, swarm: Swarm, /) -> GenerationResult: ...


def evaluate_density(density: Density, x: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """Evaluate ``density`` on points shape=(n, gdim); checks shape and sign; returns shape=(n,)."""
    values = np.asarray(density(np.ascontiguousarray(x)), dtype=np.float64).reshape(-1)
    if values.shape[0] != x.shape[0]:
        raise ValueError(f"density returned {values.shape[0]} values for {x.shape[0]} points")
    if np.any(values < 0) or not np.all(np.isfinite(values)):
        raise ValueError("density must be finite and non-negative")
    return values


def first_free_id(swarm: Swarm) -> int:
    """0 for an empty swarm, else one past the largest id on any rank (collective)."""
    local = int(swarm.ids.max()) if swarm.num_particles else -1
    return int(swarm.comm.allreduce(local, op=MPI.MAX)) + 1


def insert_in_cells(swarm: Swarm, maps: CellMaps, idx: npt.NDArray[np.int64], xhat: npt.NDArray[np.float64],
                    ids: npt.NDArray[np.int64]) -> npt.NDArray[np.float64]:
    """Insert particles at reference points ``xhat`` (p, tdim) of cells ``maps.cells[idx]``; returns x."""
    x = maps.push(idx, xhat)
    xref = maps.to_dolfinx_reference(idx, xhat, x)
    swarm.add(ids, x, xref, maps.cells[idx])
    return x
