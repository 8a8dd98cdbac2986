"""Explicit Runge-Kutta advection of particles (seed paper section 2.3).

Particles follow ``dx/dt = u_h(x, t)`` over one step ``[t_n, t_n + dt]``. The velocity is known at
the two ends of the step, ``u_old`` at ``t_n`` and ``u_new`` at ``t_n + dt``, and interpolated
linearly in time in between: stage ``i`` of a Butcher tableau ``(a, b, c)`` uses

    k_i = (1 - c_i) u_old(x_i) + c_i u_new(x_i),    x_i = x_0 + dt sum_{j<i} a_ij k_j,
    x_{n+1} = x_0 + dt sum_i b_i k_i.

After every stage position the particle's cell and reference position are updated
(:func:`particles.transport.relocate`) and particles that left this rank's cells are migrated
(:func:`particles.migration.migrate`); the start position ``x_0`` and the slopes ``k_j`` still
needed later travel with the particle as temporary property columns, removed after the step.
The last slope is used at once and never stored, so Euler needs no stage columns at all.

With linear-in-time velocity the scheme keeps order ``min(p, 2)`` for time-dependent fields
(the interpolation error is O(dt^2)); for steady fields, or with an exact time-dependent callable
(:meth:`Advector.step_callable`), the tableau's own order ``p`` is retained.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable

import numpy as np
import numpy.typing as npt

import dolfinx.fem

from particles.evaluation import Evaluator
from particles.swarm import Swarm
from particles.transport import TransportStats, relocate

__all__ = ["AdvectionStats", "Advector", "ButcherTableau", "INTEGRATORS", "get_integrator"]

_STAGE_PROPERTY = "_rk_stage_data"


@dataclass(frozen=True)
class ButcherTableau:
    """An explicit Runge-Kutta method.

    Attributes:
        name: Registry name.
        description: One line.
        order: Convergence order for smooth, exactly known velocity.
        a: Lower-triangular stage matrix, s rows of s entries.
        b: Weights, s entries.
        c: Nodes, s entries (``c_i = sum_j a_ij``).
    """

    name: str
    description: str
    order: int
    a: tuple[tuple[float, ...], ...]
    b: tuple[float, ...]
    c: tuple[float, ...]

    @property
    def stages(self) -> int:
        return len(self.b)


INTEGRATORS: dict[str, ButcherTableau] = {
    t.name: t
    for t in (
        ButcherTableau("euler", "forward Euler, first order", 1, ((0.0,),), (1.0,), (0.0,)),
        ButcherTableau(
            "rk2", "explicit midpoint rule, second order", 2, ((0.0, 0.0), (0.5, 0.0)), (0.0, 1.0), (0.0, 0.5)
        ),
        ButcherTableau(
            "rk4",
            "classical fourth-order Runge-Kutta",
            4,
            ((0.0, 0.0, 0.0, 0.0), (0.5, 0.0, 0.0, 0.0), (0.0, 0.5, 0.0, 0.0), (0.0, 0.0, 1.0, 0.0)),
            (1.0 / 6.0, 1.0 / 3.0, 1.0 / 3.0, 1.0 / 6.0),
            (0.0, 0.5, 0.5, 1.0),
        ),
    )
}


def get_integrator(name: str) -> ButcherTableau:
    """The registered tableau ``name``; ValueError lists the valid names."""
    try:
        return INTEGRATORS[name.lower()]
    except KeyError:
        valid = ", ".join(f"{k} ({v.description})" for k, v in INTEGRATORS.items())
        raise ValueError(f"unknown particle integrator {name!r}; valid: {valid}") from None


@dataclass(frozen=True)
class AdvectionStats:
    """What one advection step did on this rank.

    Attributes:
        transport: Relocation paths summed over the stages (local counts).
        sent: Particles sent to other ranks (summed over stages).
        received: Particles received from other ranks.
        lost: Particles removed because they left the domain (this rank).
        global_lost: Lost particles summed over all ranks (0 if no migration ran).
        evaluation_seconds: Velocity evaluation and position updates.
        relocation_seconds: Transport between cells, including the sort.
        communication_seconds: Migration.
    """

    transport: TransportStats
    sent: int
    received: int
    lost: int
    global_lost: int
    evaluation_seconds: float
    relocation_seconds: float
    communication_seconds: float


class _Timer:
    def __init__(self) -> None:
        self.evaluation = self.relocation = self.communication = 0.0


class Advector:
    """Advance the particles of a swarm with an explicit Runge-Kutta method (collective).

    Args:
        swarm: The particles (sorted, all in owned cells).
        integrator: Registry name: ``"euler"``, ``"rk2"`` or ``"rk4"``.

    Example:
        >>> adv = Advector(swarm, integrator="rk2")
        >>> stats = adv.step(u_old, u_new, dt)
    """

    def __init__(self, swarm: Swarm, /, *, integrator: str = "rk2") -> None:
        self.swarm = swarm
        self.tableau = get_integrator(integrator)
        self._evaluators: dict[int, Evaluator] = {}

    def _evaluator(self, V: dolfinx.fem.FunctionSpace) -> Evaluator:
        ev = self._evaluators.get(id(V))
        if ev is None or ev.V is not V:
            ev = Evaluator(V, geometry=self.swarm.geometry)
            self._evaluators[id(V)] = ev
        return ev

    def step(self, u_old: dolfinx.fem.Function, u_new: dolfinx.fem.Function, dt: float) -> AdvectionStats:
        """Advance all particles by ``dt`` in the velocity linear in time from ``u_old`` to ``u_new``.

        Args:
            u_old: Velocity at the start of the step (vector Function, gdim components).
            u_new: Velocity at the end of the step (may be ``u_old`` for a steady field).
            dt: Time step.
        """
        ev_old = self._evaluator(u_old.function_space)
        ev_new = ev_old if u_new.function_space is u_old.function_space else self._evaluator(u_new.function_space)
        if ev_old.value_size != self.swarm.gdim or ev_new.value_size != self.swarm.gdim:
            raise ValueError("the velocity must have gdim components")

        def slope(c: float) -> npt.NDArray[np.float64]:
            s = self.swarm
            if c == 0.0 or u_new is u_old:
                return ev_old.values(u_old, s.cells, s.xref)
            if c == 1.0:
                return ev_new.values(u_new, s.cells, s.xref)
            return (1.0 - c) * ev_old.values(u_old, s.cells, s.xref) + c * ev_new.values(u_new, s.cells, s.xref)

        return self._advance(slope, dt)

    def step_callable(
        self, velocity: Callable[[npt.NDArray[np.float64], float], npt.ArrayLike], t: float, dt: float
    ) -> AdvectionStats:
        """Advance by ``dt`` from time ``t`` in a prescribed velocity, evaluated exactly at each stage.

        Args:
            velocity: ``velocity(x, t)`` with x shape=(n, gdim), returning shape=(n, gdim).
            t: Time at the start of the step.
            dt: Time step.
        """
        return self._advance(lambda c: np.asarray(velocity(self.swarm.x, t + c * dt), dtype=np.float64), dt)

    def _advance(self, slope: Callable[[float], npt.NDArray[np.float64]], dt: float) -> AdvectionStats:
        swarm, tab = self.swarm, self.tableau
        gdim, s = swarm.gdim, tab.stages
        timer = _Timer()
        transport = TransportStats(0, 0, 0, 0)
        moved = [0, 0, 0, 0]
        if s > 1:
            swarm.add_property(_STAGE_PROPERTY, gdim * s)
            swarm.property(_STAGE_PROPERTY)[:, :gdim] = swarm.x
        try:
            for i in range(s):
                if i > 0:
                    t0 = time.perf_counter()
                    data = swarm.property(_STAGE_PROPERTY)
                    x = data[:, :gdim].copy()
                    for j in range(i):
                        if tab.a[i][j] != 0.0:
                            x += (dt * tab.a[i][j]) * data[:, gdim * (j + 1) : gdim * (j + 2)]
                    swarm.x[:] = x
                    timer.evaluation += time.perf_counter() - t0
                    transport = transport + self._move(timer, moved)
                t0 = time.perf_counter()
                k = slope(tab.c[i])
                if i < s - 1:
                    swarm.property(_STAGE_PROPERTY)[:, gdim * (i + 1) : gdim * (i + 2)] = k
                else:
                    if s == 1:
                        swarm.x += (dt * tab.b[0]) * k
                    else:
                        data = swarm.property(_STAGE_PROPERTY)
                        x = data[:, :gdim] + (dt * tab.b[i]) * k
                        for j in range(i):
                            if tab.b[j] != 0.0:
                                x += (dt * tab.b[j]) * data[:, gdim * (j + 1) : gdim * (j + 2)]
                        swarm.x[:] = x
                timer.evaluation += time.perf_counter() - t0
            transport = transport + self._move(timer, moved)
        finally:
            if swarm.has_property(_STAGE_PROPERTY):
                swarm.remove_property(_STAGE_PROPERTY)
        return AdvectionStats(transport, moved[0], moved[1], moved[2], moved[3],
                              timer.evaluation, timer.relocation, timer.communication)

    def _move(self, timer: _Timer, moved: list[int]) -> TransportStats:
        """Relocate after positions changed, then migrate; accumulates counts into ``moved``."""
        t0 = time.perf_counter()
        stats = relocate(self.swarm)
        t1 = time.perf_counter()
        timer.relocation += t1 - t0
        mig = _migrate(self.swarm)
        timer.communication += time.perf_counter() - t1
        for idx, value in enumerate(mig):
            moved[idx] += value
        return stats


def _migrate(swarm: Swarm) -> tuple[int, int, int, int]:
    """Call particles.migration.migrate if that module is present; else drop unlocated particles
    (serial only). Returns (sent, received, lost, global_lost)."""
    try:
        from particles.migration import migrate
    except ImportError:
        if swarm.comm.size > 1:
            raise RuntimeError("particles.migration is required for advection on more than one rank") from None
        gone = (swarm.cells < 0) | (swarm.cells >= swarm.num_owned_cells)
        lost = swarm.remove(gone)
        return 0, 0, lost, lost
    stats = migrate(swarm)
    return stats.sent, stats.received, stats.lost, stats.global_lost
