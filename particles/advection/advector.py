"""Explicit Runge-Kutta advection of particles (seed paper section 2.3).

Particles follow ``dx/dt = u_h(x, t)`` over one step ``[t_n, t_n + dt]``. The velocity is known at
the two ends of the step, ``u_old`` at ``t_n`` and ``u_new`` at ``t_n + dt``, and interpolated
linearly in time in between: stage ``i`` of a Butcher tableau ``(a, b, c)`` uses

    k_i = (1 - c_i) u_old(x_i) + c_i u_new(x_i),    x_i = x_0 + dt sum_{j<i} a_ij k_j,
    x_{n+1} = x_0 + dt sum_i b_i k_i.

After every stage position the particle's cell and reference position are updated
(:func:`particles.relocation.between_cells.relocate`) and particles that left this rank's cells are migrated
(:func:`particles.parallel.migration.migrate`; the swarm is sorted by cell once, after the last stage);
the start position ``x_0`` and the slopes ``k_j`` still needed later travel with the particle in
the swarm's stage table (:meth:`Swarm.stage_table`, kept allocated from step to step). A slope
needed only for the next stage position is pushed into the position at once and never stored, so
Euler needs no stage columns and the midpoint rule only ``x_0``. A stage at ``0 < c < 1``
evaluates the velocity from time-interpolated coefficients, once (the field is linear in them).

An optional ``confine(x)`` moves stage positions that left the domain back inside before they are
relocated (e.g. onto a curved boundary that a straight Runge-Kutta step crossed; the domain owner
supplies it, see :func:`convection.geometry.mesh.shell_confinement`); without it such particles are lost.

Quantities integrated alongside the positions (deformation gradient, accumulated strain, damage)
are given as :class:`ParticleODE` objects: property ``y`` obeys ``dy/dt = rhs(swarm, c, y, L)``
with ``L = grad u`` at the stage position, interpolated linearly in time like the velocity. The
state ``[x, y_1, y_2, ...]`` is advanced by the same tableau, and the start state and stage slopes
of every ``y`` travel in the same stage table as those of ``x``.

With linear-in-time velocity the scheme keeps order ``min(p, 2)`` for time-dependent fields
(the interpolation error is O(dt^2)); for steady fields, or with an exact time-dependent callable
(:meth:`Advector.step_callable`), the tableau's own order ``p`` is retained.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from collections.abc import Callable, Sequence

import numpy as np
import numpy.typing as npt

import dolfinx.fem

from particles.advection.integrators import ParticleODE, get_integrator
from particles.advection.stages import IntegratedState, StagePlan, stage_combination
from particles.advection.velocity import EvaluatorCache, LinearVelocity
from particles.parallel.migration import migrate
from particles.relocation.moving_mesh import pull_in
from particles.storage.swarm import Swarm
from particles.relocation.between_cells import TransportStats, relocate

__all__ = ["AdvectionStats", "Advector"]


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
        pulled_in: Particles (this rank, summed over stages) a moving boundary had passed, moved
            back in (:func:`particles.relocation.moving_mesh.pull_in`).
    """

    transport: TransportStats
    sent: int
    received: int
    lost: int
    global_lost: int
    evaluation_seconds: float
    relocation_seconds: float
    communication_seconds: float
    pulled_in: int = 0


class _StepRecord:
    """Moves the particles after a stage and keeps what one step did (counts and seconds).

    Args:
        swarm: The particles.
        confine: Moves positions that left the domain back inside (in place), or None.
    """

    def __init__(self, swarm: Swarm, confine: Callable[[npt.NDArray[np.float64]], None] | None, /) -> None:
        self.swarm = swarm
        self.confine = confine
        self.evaluation = self.relocation = self.communication = 0.0
        self.transport = TransportStats(0, 0, 0, 0)
        self.moved = [0, 0, 0, 0]  # sent, received, lost, global lost
        self.pulled_in = 0

    def move(self, *, last: bool) -> None:
        """Confine (if set), relocate after positions changed and migrate.

        Only the move after the last stage sorts: the stages in between need each particle's cell
        and reference position, not the cell order, so particles that arrived stay appended and
        departed ones stay marked (the kernels skip them) until that one sort places and drops
        them all."""
        t0 = time.perf_counter()
        if self.confine is not None:
            self.confine(self.swarm.x)
        old_cells = self.swarm.cells.copy() if self.swarm.inward is not None else None
        stats = relocate(self.swarm, sort=False)
        if old_cells is not None:  # a moving boundary may have passed them
            self.pulled_in += pull_in(self.swarm, old_cells)
        t1 = time.perf_counter()
        mig = _migrate(self.swarm)
        t2 = time.perf_counter()
        if last:
            self.swarm.sort()
        self.relocation += (t1 - t0) + (time.perf_counter() - t2)
        self.communication += t2 - t1
        for idx, value in enumerate(mig):
            self.moved[idx] += value
        self.transport = self.transport + stats

    def stats(self) -> AdvectionStats:
        return AdvectionStats(self.transport, *self.moved, self.evaluation, self.relocation, self.communication,
                              self.pulled_in)


class Advector:
    """Advance the particles of a swarm with an explicit Runge-Kutta method (collective).

    The velocity between two Functions is evaluated by :class:`particles.advection.velocity.LinearVelocity`;
    which slopes are stored, and the integrated state, are :mod:`particles.advection.stages`.

    Args:
        swarm: The particles (sorted, all in owned cells).
        integrator: Registry name: ``"euler"``, ``"rk2"`` or ``"rk4"``.
        odes: Properties integrated alongside the positions with the same tableau.
        confine: ``confine(x)`` moves positions (shape=(n, gdim), in place) that left the domain
            back inside, before every relocation; None: particles outside are lost.

    Example:
        >>> adv = Advector(swarm, integrator="rk2", odes=[ParticleODE("F", rhs)])
        >>> stats = adv.step(u_old, u_new, dt)
    """

    def __init__(self, swarm: Swarm, /, *, integrator: str = "rk2", odes: Sequence[ParticleODE] = (),
                 confine: Callable[[npt.NDArray[np.float64]], None] | None = None) -> None:
        self.swarm = swarm
        self.confine = confine
        self.tableau = get_integrator(integrator)
        self.odes: tuple[ParticleODE, ...] = tuple(odes)
        names = [ode.name for ode in self.odes]
        if len(set(names)) != len(names):
            raise ValueError(f"ODE properties must be distinct, got {names}")
        self._cache = EvaluatorCache()

    def step(self, u_old: dolfinx.fem.Function, u_new: dolfinx.fem.Function, dt: float) -> AdvectionStats:
        """Advance all particles by ``dt`` in the velocity linear in time from ``u_old`` to ``u_new``.

        Args:
            u_old: Velocity at the start of the step (vector Function, gdim components).
            u_new: Velocity at the end of the step (may be ``u_old`` for a steady field).
            dt: Time step.
        """
        velocity = LinearVelocity(self._cache, self.swarm, u_old, u_new)
        return self._advance(velocity.values, velocity.gradients, dt, push=velocity.push)

    def step_callable(
        self,
        velocity: Callable[[npt.NDArray[np.float64], float], npt.ArrayLike],
        t: float,
        dt: float,
        *,
        velocity_gradient: Callable[[npt.NDArray[np.float64], float], npt.ArrayLike] | None = None,
    ) -> AdvectionStats:
        """Advance by ``dt`` from time ``t`` in a prescribed velocity, evaluated exactly at each stage.

        Args:
            velocity: ``velocity(x, t)`` with x shape=(n, gdim), returning shape=(n, gdim).
            t: Time at the start of the step.
            dt: Time step.
            velocity_gradient: ``grad_u(x, t)`` returning shape=(n, gdim, gdim); required when the
                advector integrates ODE properties.
        """
        if self.odes and velocity_gradient is None:
            raise ValueError("step_callable needs velocity_gradient when ODE properties are integrated")
        gdim = self.swarm.gdim

        def gradient(c: float) -> npt.NDArray[np.float64]:
            assert velocity_gradient is not None
            g = np.asarray(velocity_gradient(self.swarm.x, t + c * dt), dtype=np.float64)
            return g.reshape(-1, gdim, gdim)

        return self._advance(lambda c: np.asarray(velocity(self.swarm.x, t + c * dt), dtype=np.float64), gradient, dt)

    def _advance(
        self,
        velocity: Callable[[float], npt.NDArray[np.float64]],
        gradient: Callable[[float], npt.NDArray[np.float64]],
        dt: float,
        *,
        push: Callable[[float, float], None] | None = None,
    ) -> AdvectionStats:
        """Run the stages. ``push(c, alpha)``, if given, does ``x += alpha k(c)`` in place from the
        current cells/xref (fused evaluation); it is used when no ODEs ride along, for the last
        stage and for every stage whose slope is needed only for the next stage position.

        The start state and the stored slopes live in the swarm's stage table (block 0: start
        state, then one block of ``w`` columns per stored slope), which the swarm keeps allocated
        from step to step."""
        swarm, tab = self.swarm, self.tableau
        s = tab.stages
        state = IntegratedState(swarm, self.odes)
        w = state.width
        fused = push is not None and not self.odes
        plan = StagePlan.of(tab, fused)
        record = _StepRecord(swarm, self.confine)
        if s > 1:
            state.save_start(swarm.stage_table(w * (1 + len(plan.stored))))
        try:
            pushed = False  # x already holds the next stage position (set by a fused push)
            for i in range(s):
                if i > 0:
                    if not pushed:
                        t0 = time.perf_counter()
                        state.combine(plan.combination(tab.a[i], dt, upto=i))
                        record.evaluation += time.perf_counter() - t0
                    # (with ODEs or a callable velocity every stage sorts, so user callbacks never
                    # see discarded rows)
                    record.move(last=not fused)
                pushed = False
                t0 = time.perf_counter()
                if fused and (i == s - 1 or i not in plan.block):
                    assert push is not None
                    # x = x0 + dt sum_j coef_j k_j over the stored slopes, then x += dt coef_i k_i
                    # from the current cells/xref (still those of stage i)
                    coef = tab.b if i == s - 1 else tab.a[i + 1]
                    if i > 0:  # (at stage 0, x is the start state already)
                        state.combine(plan.combination(coef, dt, upto=i))
                    push(tab.c[i], dt * coef[i])
                    pushed = i < s - 1
                    record.evaluation += time.perf_counter() - t0
                    continue
                k = state.slope(velocity, gradient, tab.c[i])
                if i < s - 1:
                    swarm.stage[:, w * plan.block[i] : w * (plan.block[i] + 1)] = k
                else:
                    if s == 1:
                        y = state.current() + (dt * tab.b[0]) * k
                    else:
                        y = np.empty((swarm.num_particles, w))
                        stage_combination(swarm.stage, 0, w, plan.coefficients(tab.b, dt, i), y)
                        y += (dt * tab.b[i]) * k
                    state.set(y)
                record.evaluation += time.perf_counter() - t0
            record.move(last=True)
        finally:
            swarm.release_stage_table()
        return record.stats()


def _migrate(swarm: Swarm) -> tuple[int, int, int, int]:
    """Hand particles that left this rank's cells to their owners; returns (sent, received,
    lost, global_lost)."""
    stats = migrate(swarm, sort=False)
    return stats.sent, stats.received, stats.lost, stats.global_lost
