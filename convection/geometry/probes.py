"""Probe points: where the expressions of a config are evaluated before a run.

An expression is refused (:meth:`convection.expressions.Expression.check`) when it fails or is
not finite at any probe point, so the probes try to include the points where a run will evaluate
it. Each domain gives a grid (:meth:`convection.geometry.domain.Domain.probe_axes`):

- a box: the lattice of ``6 * cells * 2**level`` intervals per direction (``level``: the finest
  adaptivity level), boundary and corners included. Its points contain the vertices and the
  degree-1, 2 and 3 Lagrange nodes of the base mesh and of its uniform refinements (DOLFINx
  interpolates initial conditions at those nodes), so ``1/(x - 0.25)`` and ``log(x)`` are caught
  on a mesh with 4 cells per unit length;
- an annulus, spherical shell or sector (unstructured gmsh cells): a grid in radius (inner and
  outer surface included) and angles (poles and the ends of the angle range included) with a
  spacing of half the cell size.

A grid is coarsened by halving (its points stay a subset) until it has at most
:data:`MAX_PROBES` points. A boundary's probes are the points of that boundary (one end of a grid
axis): a prescribed velocity only needs to be finite there.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

if TYPE_CHECKING:
    from convection.geometry.domain import Domain

__all__ = ["MAX_PROBES", "NODES_PER_CELL", "boundary_probes", "bounded", "domain_probes"]

MAX_PROBES = 100_000
"""Most probe points of a domain (evaluating an expression there takes milliseconds)."""
NODES_PER_CELL = 6
"""Lattice intervals per cell and direction: multiples of 1/1, 1/2 and 1/3 of a cell."""


def bounded(intervals: list[int]) -> list[int]:
    """Interval counts per direction, halved (the largest first) until the lattice has at most
    :data:`MAX_PROBES` points."""
    counts = [max(int(n), 1) for n in intervals]
    while math.prod(n + 1 for n in counts) > MAX_PROBES:
        i = counts.index(max(counts))
        counts[i] = max(counts[i] // 2, 1)
    return counts


def _grid(axes: list[npt.NDArray[np.float64]]) -> npt.NDArray[np.float64]:
    return np.stack([a.ravel() for a in np.meshgrid(*axes, indexing="ij")])


def domain_probes(domain: Domain, /, level: int = 0) -> npt.NDArray[np.float64]:
    """Probe points of ``domain``, boundary included, shape=(3, n); ``level``: the finest
    refinement level a run reaches."""
    axes, cartesian = domain.probe_axes(level)
    return cartesian(_grid(axes))


def boundary_probes(domain: Domain, name: str, /, level: int = 0) -> npt.NDArray[np.float64]:
    """Probe points on the boundary ``name`` of ``domain``, shape=(3, n)."""
    axes, cartesian = domain.probe_axes(level)
    axis, upper = domain.boundary_axis(name)
    axes[axis] = axes[axis][-1:] if upper else axes[axis][:1]
    return cartesian(_grid(axes))
