"""Which way is up: the gravity of a domain, and the depth and height it measures.

A domain (:mod:`convection.geometry.domain`) hands its gravity to the physics
(:class:`convection.physics.approximation.BoussinesqApproximation` pushes the buoyancy along
:meth:`Gravity.along_up`; the viscosity laws read :meth:`Gravity.depth`) and to the postprocessors
(:meth:`Gravity.height`). Two kinds exist:

=================== ===================================== =====================================
                    :class:`VerticalGravity` (boxes)      :class:`RadialGravity` (shells,
                                                          sectors)
=================== ===================================== =====================================
``e_up``            ``e_z`` (the last axis)               ``x / |x|``
``depth(x)``        ``z_top - z``                         ``r_outer - |x|``
``height(x)``       ``z``                                 ``|x|``
=================== ===================================== =====================================
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar, Protocol

import numpy as np
import numpy.typing as npt
import ufl

__all__ = ["Gravity", "RadialGravity", "VerticalGravity"]


class Gravity(Protocol):
    """Gravity of a domain: the ``up`` direction (against gravity) and depth and height along it."""

    name: ClassVar[str]

    def up(self, x: Any, /) -> Any:
        """UFL unit vector ``e_up`` at the points ``x`` (``ufl.SpatialCoordinate``)."""

    def along_up(self, magnitude: Any, x: Any, /) -> Any:
        """UFL vector ``magnitude e_up`` of length ``gdim`` (``x``: ``ufl.SpatialCoordinate``)."""

    def depth(self, x: Any, /) -> Any:
        """UFL depth below the top surface at ``x``."""

    def height(self, x: Any, /) -> Any:
        """UFL height at ``x``: the coordinate that grows upwards (``z``, or the radius)."""

    def up_at(self, x: npt.NDArray[np.float64], /) -> npt.NDArray[np.float64]:
        """Unit up vectors at points ``x`` (shape=(n, gdim)), shape=(n, gdim)."""

    def up_axis(self, gdim: int, /) -> int | None:
        """The coordinate axis that ``e_up`` is everywhere, or None (it turns)."""

    def depth_at(self, x: npt.NDArray[np.float64], /) -> npt.NDArray[np.float64]:
        """Depth below the top surface at points ``x`` (shape=(n, gdim)), shape=(n,)."""


@dataclass(frozen=True)
class VerticalGravity:
    """Gravity along ``-e_z`` (the last coordinate axis); the top surface at ``z = top``."""

    top: float = 1.0
    name: ClassVar[str] = "vertical"

    def up(self, x: Any, /) -> Any:
        return ufl.as_vector([0.0] * (x.ufl_shape[0] - 1) + [1.0])

    def along_up(self, magnitude: Any, x: Any, /) -> Any:
        return ufl.as_vector([0.0] * (x.ufl_shape[0] - 1) + [magnitude])

    def depth(self, x: Any, /) -> Any:
        return self.top - x[x.ufl_shape[0] - 1]

    def height(self, x: Any, /) -> Any:
        return x[x.ufl_shape[0] - 1]

    def up_at(self, x: npt.NDArray[np.float64], /) -> npt.NDArray[np.float64]:
        out = np.zeros(x.shape)
        out[:, -1] = 1.0
        return out

    def up_axis(self, gdim: int, /) -> int | None:
        return gdim - 1

    def depth_at(self, x: npt.NDArray[np.float64], /) -> npt.NDArray[np.float64]:
        return self.top - np.asarray(x, dtype=np.float64)[:, -1]


@dataclass(frozen=True)
class RadialGravity:
    """Gravity towards the origin, ``-x/|x|``; the top surface at ``|x| = outer_radius``."""

    outer_radius: float
    name: ClassVar[str] = "radial"

    def up(self, x: Any, /) -> Any:
        return x / ufl.sqrt(ufl.dot(x, x))

    def along_up(self, magnitude: Any, x: Any, /) -> Any:
        return magnitude * self.up(x)

    def depth(self, x: Any, /) -> Any:
        return self.outer_radius - ufl.sqrt(ufl.dot(x, x))

    def height(self, x: Any, /) -> Any:
        return ufl.sqrt(ufl.dot(x, x))

    def up_at(self, x: npt.NDArray[np.float64], /) -> npt.NDArray[np.float64]:
        x = np.asarray(x, dtype=np.float64)
        return x / np.linalg.norm(x, axis=1)[:, None]

    def up_axis(self, gdim: int, /) -> int | None:
        return None

    def depth_at(self, x: npt.NDArray[np.float64], /) -> npt.NDArray[np.float64]:
        return self.outer_radius - np.linalg.norm(np.asarray(x, dtype=np.float64), axis=1)
