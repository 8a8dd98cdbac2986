"""Particle properties kept as mesh fields (:meth:`particles.manager.ParticleManager.track`).

A tracked property is interpolated from the particles into a Function on the particles' mesh by
the manager's interpolator, again after every advance and on every new mesh (a new Function).
All tracked fields of one mesh share one function space.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import dolfinx.fem
import dolfinx.mesh

from fembase.dolfinx_compat import function_space
from particles.interpolation import Interpolator
from particles.storage.swarm import Swarm

__all__ = ["TrackedFields"]


@dataclass
class _Tracked:
    """A property interpolated into a mesh field: the Function is rebuilt on every mesh."""

    name: str
    component: int | None
    function: dolfinx.fem.Function = field(repr=False)


class TrackedFields:
    """The tracked mesh fields of one particle manager, by label.

    Args:
        interpolator: Particle-to-mesh interpolator.
        degree: Degree of the fields (0: DG0 cell values; >= 1: Lagrange, or DG for interpolators
            that need discontinuous targets).
        timings: Where the interpolation seconds are added (key ``"particle_interpolation"``).
    """

    def __init__(self, interpolator: Interpolator, degree: int, timings: dict[str, float], /) -> None:
        if degree < 0:
            raise ValueError(f"field_degree must be >= 0, got {degree}")
        self.interpolator = interpolator
        self.degree = degree
        self._timings = timings
        self._tracked: dict[str, _Tracked] = {}
        self._space: dolfinx.fem.FunctionSpace | None = None

    def track(self, swarm: Swarm, name: str, component: int | None, label: str | None) -> dolfinx.fem.Function:
        """Interpolate property ``name`` (column ``component`` of it, if given) of ``swarm`` into a
        new field ``label`` (default ``name``, or ``name_<component>``), now and on every
        :meth:`update` (collective). Returns the Function."""
        swarm.layout(name)  # KeyError listing the known names
        label = label or (name if component is None else f"{name}_{component}")
        tracked = _Tracked(name, component, self._new_field(swarm.mesh, label))
        self._tracked[label] = tracked
        self._interpolate(swarm, tracked)
        return tracked.function

    def field(self, label: str, /) -> dolfinx.fem.Function:
        """The current field ``label``."""
        try:
            return self._tracked[label].function
        except KeyError:
            raise KeyError(f"no tracked particle field {label!r}; tracked: {sorted(self._tracked)}") from None

    def update(self, swarm: Swarm, /) -> None:
        """Re-interpolate every field from the particles of ``swarm`` (collective)."""
        for tracked in self._tracked.values():
            self._interpolate(swarm, tracked)

    def rebuild(self, swarm: Swarm, /, *, new_space: bool) -> None:
        """New Functions on the mesh of ``swarm``, interpolated from its particles (collective).
        ``new_space`` makes a new function space even if the mesh is the one of the old fields."""
        if new_space:
            self._space = None
        for tracked in self._tracked.values():
            tracked.function = self._new_field(swarm.mesh, tracked.function.name)
            self._interpolate(swarm, tracked)

    def _new_field(self, mesh: dolfinx.mesh.Mesh, label: str) -> dolfinx.fem.Function:
        """A Function for a tracked field; all tracked fields of one mesh share one space."""
        if self._space is None or self._space.mesh is not mesh:
            discontinuous = self.degree == 0 or self.interpolator.discontinuous
            family = "DG" if discontinuous else "Lagrange"
            self._space = function_space(mesh, family, self.degree)
        return dolfinx.fem.Function(self._space, name=label)

    def _interpolate(self, swarm: Swarm, tracked: _Tracked) -> None:
        t0 = time.perf_counter()
        self.interpolator.interpolate(swarm, tracked.name, tracked.function, component=tracked.component)
        self._timings["particle_interpolation"] += time.perf_counter() - t0
