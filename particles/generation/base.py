"""Shared pieces of the generators: result type, generator protocol and context, id base, insertion."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from collections.abc import Callable
from typing import Any, ClassVar, NamedTuple, Protocol

import numpy as np
import numpy.typing as npt
from mpi4py import MPI

from fembase.registry import Configured
from particles.generation.maps import CellMaps
from particles.storage.swarm import Swarm

__all__ = ["Density", "DensityGenerator", "GenerationResult", "Generator", "GeneratorContext", "MakeFunction",
           "evaluate_density", "first_free_id", "insert_in_cells", "text_function"]

Density = Callable[[npt.NDArray[np.float64]], npt.ArrayLike]
"""A non-normalised density: points shape=(n, gdim), float64 -> values shape=(n,), >= 0."""

MakeFunction = Callable[[str], Callable[[npt.NDArray[np.float64]], npt.ArrayLike]]
"""Turns a text (e.g. a config expression such as ``"z > 0.5"``) into a function of points shape=(m, gdim)."""


def text_function(value: Any, make_function: MakeFunction | None, who: str, key: str, /) -> Any:
    """``value``, or the function ``make_function`` makes of it if it is a text (a config expression).

    Raises:
        ValueError: A text without ``make_function``.
    """
    if not isinstance(value, str):
        return value
    if make_function is None:
        raise ValueError(f"{who}: {key!r} is text but no expression parser was given")
    return make_function(value)


class GeneratorContext(NamedTuple):
    """What a generator is made from, beside its settings (each takes what it needs).

    Attributes:
        gdim: The mesh's geometric dimension (a point file's columns are checked against it; None:
            not checked).
        make_function: Turns a text ``density`` into a function (None: a text is refused).
    """

    gdim: int | None = None
    make_function: MakeFunction | None = None


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
    """A particle generator (:class:`fembase.registry.Plugin`): made by ``build(settings, context)``
    from its ``Settings`` and a :class:`GeneratorContext`, with a collective ``generate``."""

    name: ClassVar[str]
    description: ClassVar[str]
    Settings: ClassVar[type]
    affine_cells_only: ClassVar[bool]
    """True for a generator that needs straight-sided (affine) simplex cells."""
    settings: Any

    @classmethod
    def build(cls, settings: Any, context: GeneratorContext, /) -> Generator: ...

    def generate(self, swarm: Swarm, /) -> GenerationResult: ...


class DensityGenerator(Configured):
    """Base of a generator whose settings have a ``density``: :meth:`build` makes a text density
    (a config expression) a function with the context's ``make_function``."""

    @classmethod
    def build(cls, settings: Any, context: GeneratorContext, /) -> Any:
        density = text_function(settings.density, context.make_function, cls.name, "density")
        return cls(dataclasses.replace(settings, density=density))


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
