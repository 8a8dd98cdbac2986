"""Particle-to-mesh interpolation (seed paper section 2.7), one module per interpolator.

Every interpolator has the one plugin shape (:class:`fembase.registry.Plugin`): a ``Settings``
dataclass of its parameters, made by ``INTERPOLATORS.build(name, settings, InterpolatorContext())``,
with a collective ``interpolate(swarm, property_name, target, /, *, component=None)`` that writes
a scalar DOLFINx Function and returns :class:`InterpolationStats`. A property of size 1 is
interpolated directly; for a multi-column property pass the column as ``component``.

Empty cells never give NaN: see :mod:`particles.interpolation.fill` (outward averaging over
vertex-neighbour cells, across ranks through the vertex ghost layer of :mod:`particles.parallel.ghosts`,
which is built from vertex sharing and so works with DOLFINx 0.5's ``GhostMode.shared_facet`` and
``none``; 0.5 refuses ``shared_vertex``). All interpolators give the same field on any number of
ranks.
"""

from __future__ import annotations

from typing import Any

import dolfinx.fem

from particles.interpolation._base import InterpolationStats, Interpolator, InterpolatorContext
from particles.interpolation.cell_average import CellAverage
from particles.interpolation.distance_weighted import DistanceWeighted
from particles.interpolation.least_squares import LeastSquares
from particles.interpolation.nearest import Nearest
from particles.interpolation.quadratic_least_squares import QuadraticLeastSquares
from particles.interpolation.shape_function import ShapeFunction
from fembase.registry import Registry
from particles.storage.swarm import Swarm

__all__ = [
    "INTERPOLATORS",
    "CellAverage",
    "DistanceWeighted",
    "InterpolationStats",
    "Interpolator",
    "InterpolatorContext",
    "LeastSquares",
    "Nearest",
    "QuadraticLeastSquares",
    "ShapeFunction",
    "describe_interpolators",
    "interpolate_to_mesh",
]

INTERPOLATORS: Registry[type[Interpolator]] = Registry(
    "particle interpolator",
    (Nearest, CellAverage, DistanceWeighted, ShapeFunction, LeastSquares, QuadraticLeastSquares)
)
"""Interpolator classes by their lowercase config name."""

describe_interpolators = INTERPOLATORS.describe


def interpolate_to_mesh(swarm: Swarm, property_name: str, target: dolfinx.fem.Function, /, *,
                        method: str = "cell_average", component: int | None = None,
                        **parameters: Any) -> InterpolationStats:
    """Interpolate particle property ``property_name`` into ``target`` (collective).

    Args:
        swarm: The particles.
        property_name: A swarm property (size 1, or pick a column with ``component``).
        target: Scalar Lagrange / DG Function on ``swarm.mesh``; overwritten (ghosts updated).
        method: Registered interpolator name (see :func:`describe_interpolators`).
        component: Column of a multi-column property.
        parameters: Parameters of the interpolator (its ``Settings``).
    """
    if target.function_space.mesh is not swarm.mesh:
        raise ValueError("the target Function lives on a different mesh than the swarm")
    interpolator = INTERPOLATORS.build(method, INTERPOLATORS.settings(method, **parameters), InterpolatorContext())
    return interpolator.interpolate(swarm, property_name, target, component=component)
