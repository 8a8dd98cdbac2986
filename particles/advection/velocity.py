"""The velocity of one advection step at the particles, linear in time between two Functions.

Stage ``i`` of a Runge-Kutta step at node ``c`` uses ``(1 - c) u_old + c u_new`` at the particles'
current cells and reference positions (:class:`particles.advection.Advector`). When both
Functions share a space, a stage at ``0 < c < 1`` evaluates the field of the time-interpolated
coefficients, once (the field is linear in them), instead of blending two evaluations.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

import dolfinx.fem

from fembase.evaluation import Evaluator
from particles.storage.swarm import Swarm

__all__ = ["EvaluatorCache", "LinearVelocity"]


class EvaluatorCache:
    """Evaluators and scratch Functions by function space, kept from step to step."""

    def __init__(self) -> None:
        self._evaluators: dict[int, Evaluator] = {}
        self._blends: dict[int, dolfinx.fem.Function] = {}

    def evaluator(self, V: dolfinx.fem.FunctionSpace, swarm: Swarm) -> Evaluator:
        """The evaluator of ``V`` (on the cell geometry of ``swarm``)."""
        ev = self._evaluators.get(id(V))
        if ev is None or ev.V is not V:
            ev = Evaluator(V, geometry=swarm.geometry)
            self._evaluators[id(V)] = ev
        return ev

    def blend_function(self, V: dolfinx.fem.FunctionSpace) -> dolfinx.fem.Function:
        """A scratch Function in ``V`` for time-interpolated velocity coefficients."""
        w = self._blends.get(id(V))
        if w is None or w.function_space is not V:
            w = dolfinx.fem.Function(V)
            self._blends[id(V)] = w
        return w


class LinearVelocity:
    """The velocity linear in time from ``u_old`` (node 0) to ``u_new`` (node 1) at the particles.

    Args:
        cache: Where the evaluators and scratch Functions are kept.
        swarm: The particles (evaluated at their current ``cells`` and ``xref``).
        u_old: Velocity at the start of the step (vector Function, gdim components).
        u_new: Velocity at the end of the step (may be ``u_old`` for a steady field).
    """

    def __init__(self, cache: EvaluatorCache, swarm: Swarm, u_old: dolfinx.fem.Function,
                 u_new: dolfinx.fem.Function, /) -> None:
        self.cache = cache
        self.swarm = swarm
        self.u_old, self.u_new = u_old, u_new
        self.ev_old = cache.evaluator(u_old.function_space, swarm)
        self.ev_new = (self.ev_old if u_new.function_space is u_old.function_space
                       else cache.evaluator(u_new.function_space, swarm))
        if self.ev_old.value_size != swarm.gdim or self.ev_new.value_size != swarm.gdim:
            raise ValueError("the velocity must have gdim components")
        self._blended: dict[float, dolfinx.fem.Function] = {}

    def _at(self, c: float) -> tuple[Evaluator, dolfinx.fem.Function] | None:
        """The velocity at stage node c as one Function (None: blend two evaluations)."""
        u_old, u_new = self.u_old, self.u_new
        if c == 0.0 or u_new is u_old:
            return self.ev_old, u_old
        if c == 1.0:
            return self.ev_new, u_new
        if self.ev_new is not self.ev_old:
            return None
        # u is linear in its coefficients: interpolating the coefficients in time gives the
        # same field as blending two evaluations (up to round-off), at the cost of one.
        if c not in self._blended:
            w = self.cache.blend_function(u_old.function_space)
            np.multiply(u_old.x.array, 1.0 - c, out=w.x.array)
            w.x.array[:] += c * u_new.x.array
            self._blended[c] = w
        return self.ev_old, self._blended[c]

    def _blend(self, c: float, kind: str) -> npt.NDArray[np.float64]:
        s = self.swarm
        one = self._at(c)
        if one is not None:
            return getattr(one[0], kind)(one[1], s.cells, s.xref)
        return ((1.0 - c) * getattr(self.ev_old, kind)(self.u_old, s.cells, s.xref)
                + c * getattr(self.ev_new, kind)(self.u_new, s.cells, s.xref))

    def values(self, c: float) -> npt.NDArray[np.float64]:
        """The velocity at node ``c``, shape=(n, gdim)."""
        return self._blend(c, "values")

    def gradients(self, c: float) -> npt.NDArray[np.float64]:
        """The velocity gradient at node ``c``, shape=(n, gdim, gdim)."""
        return self._blend(c, "gradients")

    def push(self, c: float, alpha: float) -> None:
        """x += alpha u(c) at the current cells/xref, fused into the evaluation kernel."""
        s = self.swarm
        one = self._at(c)
        if one is not None:
            one[0].values(one[1], s.cells, s.xref, out=s.x, alpha=alpha, beta=1.0)
        else:
            self.ev_old.values(self.u_old, s.cells, s.xref, out=s.x, alpha=alpha * (1.0 - c), beta=1.0)
            self.ev_new.values(self.u_new, s.cells, s.xref, out=s.x, alpha=alpha * c, beta=1.0)
