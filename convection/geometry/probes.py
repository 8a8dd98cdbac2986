"""Probe points: where the expressions of a config are evaluated before a run.

An expression is refused (:meth:`convection.expressions.Expression.check`) when it fails or is
not finite at any probe point, so the probes try to include the points where a run will evaluate
it:

- a box: the lattice of ``6 * cells * 2**level`` intervals per direction (``level``: the finest
  adaptivity level), boundary and corners included. Its points contain the vertices and the
  degree-1, 2 and 3 Lagrange nodes of the base mesh and of its uniform refinements (DOLFINx
  interpolates initial conditions at those nodes), so ``1/(x - 0.25)`` and ``log(x)`` are caught
  on a mesh with 4 cells per unit length. The lattice is coarsened by halving (its points stay a
  subset) until it has at most :data:`MAX_PROBES` points;
- an annulus or spherical shell (unstructured gmsh cells): a grid in radius (inner and outer
  surface included) and angles (poles and phi = +-pi included) with a spacing of half the cell
  size, likewise bounded.

A boundary's probes are the points of that boundary (a box side, or the shell's inner or outer
surface): a prescribed velocity only needs to be finite there.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import numpy.typing as npt

__all__ = ["MAX_PROBES", "boundary_probes", "domain_probes"]

MAX_PROBES = 100_000
"""Most probe points of a domain (evaluating an expression there takes milliseconds)."""
_NODES_PER_CELL = 6
"""Lattice intervals per cell and direction: multiples of 1/1, 1/2 and 1/3 of a cell."""
_SHELLS = {"annulus": 2, "spherical_shell": 3}


def _gdim(config: dict[str, Any]) -> int:
    geometry = config["mesh"]["geometry"]
    return _SHELLS[geometry] if geometry in _SHELLS else len(config["mesh"]["cells"])


def _bounded(intervals: list[int]) -> list[int]:
    """Interval counts per direction, halved (the largest first) until the lattice has at most
    :data:`MAX_PROBES` points."""
    counts = [max(int(n), 1) for n in intervals]
    while math.prod(n + 1 for n in counts) > MAX_PROBES:
        i = counts.index(max(counts))
        counts[i] = max(counts[i] // 2, 1)
    return counts


def _axes(config: dict[str, Any]) -> list[npt.NDArray[np.float64]]:
    """The probe coordinates along each axis: box coordinates, or a shell's (r, phi[, theta])."""
    mesh = config["mesh"]
    gdim = _gdim(config)
    if mesh["geometry"] in _SHELLS:
        inner, outer = mesh["radii"]
        h = 0.5 * mesh["resolution"]
        wanted = [min((outer - inner) / h, MAX_PROBES), min(2.0 * math.pi * outer / h, MAX_PROBES)]
        if gdim == 3:
            wanted.append(min(math.pi * outer / h, MAX_PROBES))
        counts = _bounded([max(math.ceil(n), 2) for n in wanted])
        limits = [(inner, outer), (-math.pi, math.pi), (0.0, math.pi)][:gdim]
    else:
        adapt = config["adaptivity"]
        level = min(adapt["max_level"], 30) if adapt["enabled"] else 0
        counts = _bounded([min(_NODES_PER_CELL * n * 2**level, MAX_PROBES) for n in mesh["cells"]])
        limits = list(zip(mesh["lower"] or [0.0] * gdim, mesh["upper"] or [1.0] * gdim))
    return [np.linspace(lo, hi, n + 1) for (lo, hi), n in zip(limits, counts)]


def _cartesian(config: dict[str, Any], grid: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """Points shape=(3, n) from grid coordinates shape=(gdim, n) (a shell's are r, phi[, theta])."""
    gdim = grid.shape[0]
    points = np.zeros((3, grid.shape[1]))
    if config["mesh"]["geometry"] in _SHELLS:
        r, phi = grid[0], grid[1]
        sin_theta = np.sin(grid[2]) if gdim == 3 else 1.0
        points[0], points[1] = r * np.cos(phi) * sin_theta, r * np.sin(phi) * sin_theta
        if gdim == 3:
            points[2] = r * np.cos(grid[2])
    else:
        points[:gdim] = grid
    return points


def _grid(axes: list[npt.NDArray[np.float64]]) -> npt.NDArray[np.float64]:
    return np.stack([a.ravel() for a in np.meshgrid(*axes, indexing="ij")])


def domain_probes(config: dict[str, Any], /) -> npt.NDArray[np.float64]:
    """Probe points of a resolved config's domain, boundary included, shape=(3, n)."""
    return _cartesian(config, _grid(_axes(config)))


def boundary_probes(config: dict[str, Any], name: str, /) -> npt.NDArray[np.float64]:
    """Probe points on the boundary ``name`` (a box side or ``inner``/``outer``), shape=(3, n)."""
    axes = _axes(config)
    if config["mesh"]["geometry"] in _SHELLS:
        axes[0] = axes[0][:1] if name == "inner" else axes[0][-1:]
    else:
        from convection.geometry.boundary import side_axis

        axis, upper = side_axis(name, len(axes))
        axes[axis] = axes[axis][-1:] if upper else axes[axis][:1]
    return _cartesian(config, _grid(axes))
