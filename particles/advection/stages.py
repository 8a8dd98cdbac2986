"""The Runge-Kutta stages of one advection step (:class:`particles.advection.Advector`).

The integrated state of a particle is ``[x, y_1, y_2, ...]``: its position and the properties
that obey an ODE. During a step the swarm's stage table holds the start state (block 0) and the
stage slopes still needed later (one block of ``width`` columns each).
"""

from __future__ import annotations

from dataclasses import dataclass
from collections.abc import Callable, Iterator, Sequence

import numba
import numpy as np
import numpy.typing as npt

from particles.advection.integrators import ButcherTableau, ParticleODE
from particles.storage.swarm import Swarm

__all__ = ["IntegratedState", "StagePlan", "stage_combination"]


@dataclass(frozen=True)
class StagePlan:
    """Which stage slopes of a tableau are kept in the stage table.

    Attributes:
        stored: Stages ``j < s - 1`` whose slope is stored, increasing.
        block: Block of the stage table holding the slope of each stored stage (block 0 is the
            start state).
    """

    stored: tuple[int, ...]
    block: dict[int, int]

    @classmethod
    def of(cls, tab: ButcherTableau, fused: bool) -> StagePlan:
        """Every slope but the last's, or, with the fused push (the slope of stage ``i`` added to
        the position at once), only those needed after the next stage position."""
        s = tab.stages
        if not fused:
            stored = tuple(range(s - 1))
        else:
            stored = tuple(j for j in range(s - 1)
                           if tab.b[j] != 0.0 or any(tab.a[m][j] != 0.0 for m in range(j + 2, s)))
        return cls(stored, {j: 1 + q for q, j in enumerate(stored)})

    def coefficients(self, row: Sequence[float], dt: float, upto: int) -> npt.NDArray[np.float64]:
        """``dt * row[j]`` for the stored slopes ``j < upto``, in stage-table order."""
        return np.array([dt * row[j] for j in self.stored if j < upto], dtype=np.float64)

    def combination(self, row: Sequence[float], dt: float, upto: int) -> npt.NDArray[np.float64]:
        """:meth:`coefficients`, checking that every slope ``j < upto`` with ``row[j] != 0`` is stored."""
        coefs = self.coefficients(row, dt, upto)
        if any(row[j] != 0.0 for j in range(upto) if j not in self.block):
            raise AssertionError("a stage combination needs a slope that was not stored")
        return coefs


class IntegratedState:
    """The state ``[x, y_1, y_2, ...]`` of the particles of a swarm, shape=(n, width).

    Args:
        swarm: The particles.
        odes: The properties integrated alongside the positions.
    """

    def __init__(self, swarm: Swarm, odes: Sequence[ParticleODE], /) -> None:
        self.swarm = swarm
        self.odes = tuple(odes)
        self.width = swarm.gdim + sum(swarm.layout(ode.name).size for ode in self.odes)

    def current(self) -> npt.NDArray[np.float64]:
        """A copy of the state, shape=(n, width)."""
        swarm = self.swarm
        if not self.odes:
            return swarm.x.copy()
        return np.concatenate([swarm.x] + [swarm.property(ode.name) for ode in self.odes], axis=1)

    def set(self, state: npt.NDArray[np.float64]) -> None:
        """Write ``state`` (shape=(n, width)) into the positions and ODE properties."""
        swarm = self.swarm
        swarm.x[:] = state[:, : swarm.gdim]
        for columns, properties in self._blocks():
            swarm.properties[:, properties] = state[:, columns]

    def save_start(self, table: npt.NDArray[np.float64]) -> None:
        """Copy the state into the first ``width`` columns of ``table`` (the stage table)."""
        swarm = self.swarm
        table[:, : swarm.gdim] = swarm.x
        for columns, properties in self._blocks():
            table[:, columns] = swarm.properties[:, properties]

    def _blocks(self) -> Iterator[tuple[slice, slice]]:
        """(its columns in the state, its columns in the property table) of every ODE property."""
        col = self.swarm.gdim
        for ode in self.odes:
            lay = self.swarm.layout(ode.name)
            yield slice(col, col + lay.size), lay.columns
            col += lay.size

    def combine(self, coefs: npt.NDArray[np.float64]) -> None:
        """Set the state to the start state plus the stored slopes weighted by ``coefs``."""
        swarm = self.swarm
        out = swarm.x if not self.odes else np.empty((swarm.num_particles, self.width))
        stage_combination(swarm.stage, 0, self.width, coefs, out)
        if self.odes:
            self.set(out)

    def slope(
        self,
        velocity: Callable[[float], npt.NDArray[np.float64]],
        gradient: Callable[[float], npt.NDArray[np.float64]],
        c: float,
    ) -> npt.NDArray[np.float64]:
        """d/dt of the state at the current (stage) positions, at stage node ``c``, shape=(n, width)."""
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


@numba.njit(cache=True)
def stage_combination(table, start, width, coefs, out):  # pragma: no cover
    """Runge-Kutta stage sum from stage columns of a table, in one pass.

    ``out[p, i] = table[p, start + i] + sum_j coefs[j] * table[p, start + width * (j + 1) + i]``
    for ``i < width``: the start state plus the weighted stage slopes stored after it.
    (Several times faster than the same NumPy expression on strided column views; widths 2 and
    3, the positions, are written out.)
    """
    nc = coefs.shape[0]
    if width == 2:
        for p in range(table.shape[0]):
            a0 = table[p, start]
            a1 = table[p, start + 1]
            for j in range(nc):
                a0 += coefs[j] * table[p, start + 2 * (j + 1)]
                a1 += coefs[j] * table[p, start + 2 * (j + 1) + 1]
            out[p, 0] = a0
            out[p, 1] = a1
    elif width == 3:
        for p in range(table.shape[0]):
            a0 = table[p, start]
            a1 = table[p, start + 1]
            a2 = table[p, start + 2]
            for j in range(nc):
                a0 += coefs[j] * table[p, start + 3 * (j + 1)]
                a1 += coefs[j] * table[p, start + 3 * (j + 1) + 1]
                a2 += coefs[j] * table[p, start + 3 * (j + 1) + 2]
            out[p, 0] = a0
            out[p, 1] = a1
            out[p, 2] = a2
    else:
        for p in range(table.shape[0]):
            for i in range(width):
                acc = table[p, start + i]
                for j in range(nc):
                    acc += coefs[j] * table[p, start + width * (j + 1) + i]
                out[p, i] = acc
