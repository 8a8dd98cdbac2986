"""Evaluation of a user-given source (Python callable of x, or a mesh Function) at particles."""

from __future__ import annotations

from typing import Callable, Union

import numpy as np
import numpy.typing as npt

import dolfinx.fem

from particles.properties._base import PropertyContext, evaluate_at
from particles.swarm import Swarm

__all__ = ["PointFunction", "Source", "evaluate_source", "source_size"]

PointFunction = Callable[[npt.NDArray[np.float64]], npt.ArrayLike]
"""``f(x)``: points shape=(m, gdim), float64 -> values shape=(m,) or (m, components)."""

Source = Union[PointFunction, dolfinx.fem.Function]


def source_size(source: Source, components: int) -> int:
    """Columns produced by ``source``: the Function's value size, else ``components``."""
    if isinstance(source, dolfinx.fem.Function):
        return int(source.function_space.dofmap.index_map_bs)
    return components


def evaluate_source(
    source: Source, swarm: Swarm, rows: npt.NDArray[np.integer], size: int, context: PropertyContext, who: str
) -> npt.NDArray[np.float64]:
    """Values of ``source`` at the particles ``rows``, shape=(m, size)."""
    if isinstance(source, dolfinx.fem.Function):
        return evaluate_at(swarm, rows, source, context)
    m = int(np.asarray(rows).shape[0])
    values = np.asarray(source(np.ascontiguousarray(swarm.x[rows])), dtype=np.float64)
    if values.size != m * size:
        raise ValueError(f"property {who!r}: the callable returned shape {values.shape} for {m} points, "
                         f"expected ({m},) or ({m}, {size})")
    return values.reshape(m, size)
