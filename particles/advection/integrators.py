"""The explicit Runge-Kutta methods of particle advection, by config name, and the particle
properties integrated alongside the positions (:class:`particles.advection.advector.Advector`).

A method is a Butcher tableau ``(a, b, c)``; :data:`INTEGRATORS` holds them by their lowercase
config name. A :class:`ParticleODE` names a property ``y`` that obeys ``dy/dt = rhs(swarm, c, y,
grad u)``.
"""

from __future__ import annotations

from dataclasses import dataclass
from collections.abc import Callable

import numpy as np
import numpy.typing as npt

from fembase.registry import Registry
from particles.storage.swarm import Swarm

__all__ = ["INTEGRATORS", "ButcherTableau", "OdeRhs", "ParticleODE", "get_integrator"]

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
    "particle integrator",
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
