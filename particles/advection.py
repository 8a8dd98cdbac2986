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

An optional ``confine(x)`` moves stage positions that left the domain back inside before they are
relocated (e.g. onto a curved boundary that a straight Runge-Kutta step crossed; the domain owner
supplies it, see :func:`convection.mesh.shell_confinement`); without it such particles are lost.

Quantities integrated alongside the positions (deformation gradient, accumulated strain, damage)
are given as :class:`ParticleODE` objects: property ``y`` obeys ``dy/dt = rhs(swarm, c, y, L)``
with ``L = grad u`` at the stage position, interpolated linearly in time like the velocity. The
state ``[x, y_1, y_2, ...]`` is advanced by the same tableau, and the start state and stage slopes
of every ``y`` travel in the same temporary property columns as those of ``x``.

With linear-in-time velocity the scheme keeps order ``min(p, 2)`` for time-dependent fields
(the interpolation error is O(dt^2)); for steady fields, or with an exact time-dependent callable
(:meth:`Advector.step_callable`), the tableau's own order ``p`` is retained.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np
import numpy.typing as npt

import dolfinx.fem

from particles.evaluation import Evaluator
from particles.migration import migrate
from particles.kernels import stage_combination
from particles.registry import Registry
from particles.swarm import Swarm
from particles.transport import TransportStats, relocate

__all__ = ["AdvectionStats", "Advector", "ButcherTableau", "INTEGRATORS", "ParticleODE", "get_integrator"]

_STAGE_PROPERTY = "_rk_stage_data"

OdeRhs = Callable[[Swarm, float, npt.NDArray[np.float64], npt.NDArray[np.float64]], npt.ArrayLike]
"""``rhs(swarm, c, y, grad_u) -> dy/dt``: stage node ``c`` in [0, 1], ``y`` shape=(n, size),
``grad_u[p, i, j] = d u_i / d x_j`` shape=(n, gdim, gdim); returns shape=(n, size), float64."""


@dataclass(frozen=True)
class ParticleODE:
    """A particle property integrated together with the position.

    Attributes:
        name: Swarm property holding ``y`` (its columns are the ODE state, updated in place).
        rhs: Right-hand side, see :data:`OdeRhs`. Called at every stage with the swarm positioned
            at the stage (``swarm.x``, ``swarm.cells``, ``swarm.xref`` and ``y`` are stage values).
    """

    name: str
    rhs: OdeRhs


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


INTEGRATORS: Registry[ButcherTableau] = Registry(
    "integrator",
    (
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
    ),
)
"""Butcher tableaus by their lowercase config name."""


def get_integrator(name: str) -> ButcherTableau:
    """The registered tableau ``name`` (case-insensitive); ValueError lists the valid names."""
    return INTEGRATORS.lookup(name.lower())


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
        if _STAGE_PROPERTY in names:
            raise ValueError(f"{_STAGE_PROPERTY!r} is reserved for stage data")
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

        def blend(c: float, kind: str) -> npt.NDArray[np.float64]:
            s = self.swarm
            f_old, f_new = getattr(ev_old, kind), getattr(ev_new, kind)
            if c == 0.0 or u_new is u_old:
                return f_old(u_old, s.cells, s.xref)
            if c == 1.0:
                return f_new(u_new, s.cells, s.xref)
            return (1.0 - c) * f_old(u_old, s.cells, s.xref) + c * f_new(u_new, s.cells, s.xref)

        def push(c: float, alpha: float) -> None:
            """x += alpha u(c) at the current cells/xref, fused into the evaluation kernel."""
            s = self.swarm
            if c == 0.0 or u_new is u_old:
                ev_old.values(u_old, s.cells, s.xref, out=s.x, alpha=alpha, beta=1.0)
            elif c == 1.0:
                ev_new.values(u_new, s.cells, s.xref, out=s.x, alpha=alpha, beta=1.0)
            else:
                ev_old.values(u_old, s.cells, s.xref, out=s.x, alpha=alpha * (1.0 - c), beta=1.0)
                ev_new.values(u_new, s.cells, s.xref, out=s.x, alpha=alpha * c, beta=1.0)

        return self._advance(lambda c: blend(c, "values"), lambda c: blend(c, "gradients"), dt, push=push)

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

    def _state(self) -> npt.NDArray[np.float64]:
        """The integrated state [x, y_1, y_2, ...], shape=(n, gdim + sum of ODE sizes)."""
        swarm = self.swarm
        if not self.odes:
            return swarm.x.copy()
        return np.concatenate([swarm.x] + [swarm.property(ode.name) for ode in self.odes], axis=1)

    def _set_state(self, state: npt.NDArray[np.float64]) -> None:
        swarm = self.swarm
        gdim = swarm.gdim
        swarm.x[:] = state[:, :gdim]
        col = gdim
        for ode in self.odes:
            lay = swarm.layout(ode.name)
            swarm.properties[:, lay.columns] = state[:, col : col + lay.size]
            col += lay.size

    def _slope(
        self,
        velocity: Callable[[float], npt.NDArray[np.float64]],
        gradient: Callable[[float], npt.NDArray[np.float64]],
        c: float,
    ) -> npt.NDArray[np.float64]:
        """d/dt of the state at the current (stage) positions, shape=(n, width)."""
        k = velocity(c)
        if not self.odes:
            return k
        swarm = self.swarm
        grad_u = gradient(c)
        parts = [k]
        for ode in self.odes:
            y = swarm.property(ode.name)
            dy = np.asarray(ode.rhs(swarm, c, y.copy(), grad_u), dtype=np.float64)
            parts.append(dy.reshape(y.shape))
        return np.concatenate(parts, axis=1)

    def _advance(
        self,
        velocity: Callable[[float], npt.NDArray[np.float64]],
        gradient: Callable[[float], npt.NDArray[np.float64]],
        dt: float,
        *,
        push: Callable[[float, float], None] | None = None,
    ) -> AdvectionStats:
        """Run the stages. ``push(c, alpha)``, if given, does ``x += alpha k(c)`` in place from the
        current cells/xref (fused evaluation); it is used for the last stage when no ODEs ride along."""
        swarm, tab = self.swarm, self.tableau
        s = tab.stages
        w = swarm.gdim + sum(swarm.layout(ode.name).size for ode in self.odes)
        fused = push is not None and not self.odes
        timer = _Timer()
        transport = TransportStats(0, 0, 0, 0)
        moved = [0, 0, 0, 0]
        if s > 1:
            swarm.add_property(_STAGE_PROPERTY, w * s)
            swarm.property(_STAGE_PROPERTY)[:, :w] = self._state()
        try:
            for i in range(s):
                if i > 0:
                    t0 = time.perf_counter()
                    self._combine([dt * tab.a[i][j] for j in range(i)], w)
                    timer.evaluation += time.perf_counter() - t0
                    transport = transport + self._move(timer, moved)
                t0 = time.perf_counter()
                if i == s - 1 and fused:
                    assert push is not None
                    if s > 1:  # x = x0 + dt sum_{j<i} b_j k_j; cells/xref still hold the stage point
                        self._combine([dt * tab.b[j] for j in range(i)], w)
                    push(tab.c[i], dt * tab.b[i])
                    timer.evaluation += time.perf_counter() - t0
                    continue
                k = self._slope(velocity, gradient, tab.c[i])
                if i < s - 1:
                    swarm.property(_STAGE_PROPERTY)[:, w * (i + 1) : w * (i + 2)] = k
                else:
                    if s == 1:
                        y = self._state() + (dt * tab.b[0]) * k
                    else:
                        y = np.empty((swarm.num_particles, w))
                        stage_combination(swarm.properties, swarm.layout(_STAGE_PROPERTY).start, w,
                                          np.array([dt * tab.b[j] for j in range(i)]), y)
                        y += (dt * tab.b[i]) * k
                    self._set_state(y)
                timer.evaluation += time.perf_counter() - t0
            transport = transport + self._move(timer, moved)
        finally:
            if swarm.has_property(_STAGE_PROPERTY):
                swarm.remove_property(_STAGE_PROPERTY)
        return AdvectionStats(transport, moved[0], moved[1], moved[2], moved[3],
                              timer.evaluation, timer.relocation, timer.communication)

    def _combine(self, coefs: list[float], w: int) -> None:
        """Set the state to the start state plus ``sum_j coefs[j] k_j`` from the stage columns."""
        swarm = self.swarm
        start = swarm.layout(_STAGE_PROPERTY).start
        out = swarm.x if not self.odes else np.empty((swarm.num_particles, w))
        stage_combination(swarm.properties, start, w, np.asarray(coefs, dtype=np.float64), out)
        if self.odes:
            self._set_state(out)

    def _move(self, timer: _Timer, moved: list[int]) -> TransportStats:
        """Confine (if set), relocate after positions changed, then migrate; accumulates counts into ``moved``."""
        t0 = time.perf_counter()
        if self.confine is not None:
            self.confine(self.swarm.x)
        stats = relocate(self.swarm)
        t1 = time.perf_counter()
        timer.relocation += t1 - t0
        mig = _migrate(self.swarm)
        timer.communication += time.perf_counter() - t1
        for idx, value in enumerate(mig):
            moved[idx] += value
        return stats


def _migrate(swarm: Swarm) -> tuple[int, int, int, int]:
    """Hand particles that left this rank's cells to their owners; returns (sent, received,
    lost, global_lost)."""
    stats = migrate(swarm)
    return stats.sent, stats.received, stats.lost, stats.global_lost
