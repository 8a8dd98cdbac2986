"""``elastic_stress``: the deviatoric stress of a Maxwell visco-elastic material (3 columns in 2D, 6 in 3D).

Columns in Voigt order: ``xx, yy, xy`` in 2D, ``xx, yy, zz, xy, xz, yz`` in 3D. After every flow
solve (:meth:`ElasticStress.refresh`, with the step ``dt`` just taken)::

    tau^{n+1} = 2 eta_ve eps(u^{n+1}) + chi R tau^n R^T,      R = exp(dt W),  W = (grad u - grad u^T) / 2

The particle carries ``tau^n`` along its path (the advective part of the objective rate); ``R tau
R^T`` is the Jaumann rotation ``dtau/dt = W tau - tau W`` integrated exactly over the step for the
spin ``W`` of ``u^{n+1}`` at the particle (Rodrigues' formula): it keeps the stress's invariants,
where the linearised update ``tau + dt (W tau - tau W)`` (ASPECT's) grows them by ``O(dt^2 |W|^2)``
per step. Jaumann's rate because it adds no strain-rate terms of its own (Oldroyd's and Truesdell's
do), so a stress at rest in a rigid rotation only turns, and it is the rate of Moresi et al.
(2003) and ASPECT. ``eta_ve`` and ``chi = eta_ve / (G dt_e)`` are mesh fields the model supplies
(:mod:`convection.physics.elasticity`), sampled at the particle; with a fixed elastic time step the
model supplies the averaged factors ``r eta_ve`` and ``1 - r (1 - chi)``, ``r = dt / dt_e``
(:meth:`~convection.physics.elasticity.Elasticity.averaged`). A step of length 0 (the flow
solved before the first step) changes nothing. New particles take the mean of their neighbours.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import numpy.typing as npt

from fembase.params import param
from particles.properties._base import ParticleProperty, PropertyContext, evaluate_at, gradient_at, write_rows
from particles.properties._tensor import strain_rate
from particles.properties.elastic_kernel import fast_update
from particles.storage.swarm import Swarm

__all__ = ["ElasticStress", "jaumann_rotation", "from_voigt", "to_voigt"]

_VOIGT = {2: ((0, 0), (1, 1), (0, 1)), 3: ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))}


def from_voigt(values: npt.NDArray[np.float64], gdim: int, /) -> npt.NDArray[np.float64]:
    """Symmetric tensors shape=(n, gdim, gdim) from Voigt columns shape=(n, 3 or 6)."""
    out = np.zeros((values.shape[0], gdim, gdim))
    for k, (i, j) in enumerate(_VOIGT[gdim]):
        out[:, i, j] = out[:, j, i] = values[:, k]
    return out


def to_voigt(tensors: npt.NDArray[np.float64], /) -> npt.NDArray[np.float64]:
    """Voigt columns shape=(n, 3 or 6) of the symmetric parts of ``tensors`` shape=(n, gdim, gdim)."""
    sym = 0.5 * (tensors + np.swapaxes(tensors, 1, 2))
    return np.stack([sym[:, i, j] for i, j in _VOIGT[tensors.shape[1]]], axis=1)


def jaumann_rotation(tau: npt.NDArray[np.float64], grad_u: npt.NDArray[np.float64], dt: float, /
                     ) -> npt.NDArray[np.float64]:
    """``R tau R^T`` with ``R = exp(dt W)``, ``W = (L - L^T) / 2``, ``L[p, i, j] = d u_i / d x_j``: the exact
    solution over ``dt`` of ``dtau/dt = W tau - tau W`` (Rodrigues' formula); shapes (n, gdim, gdim)."""
    K = 0.5 * dt * (grad_u - np.swapaxes(grad_u, 1, 2))
    theta = np.sqrt(0.5 * np.einsum("nij,nij->n", K, K))
    a = np.sinc(theta / np.pi)  # sin(theta) / theta
    b = 0.5 * np.sinc(theta / (2.0 * np.pi)) ** 2  # (1 - cos(theta)) / theta^2
    K2 = K @ K
    R = np.eye(tau.shape[1])[None] + a[:, None, None] * K + b[:, None, None] * K2
    return R @ tau @ np.swapaxes(R, 1, 2)


class ElasticStress(ParticleProperty):
    """The deviatoric stress of a Maxwell material (module docstring)."""

    name: ClassVar[str] = "elastic_stress"
    description: ClassVar[str] = "deviatoric stress of a Maxwell visco-elastic material (3 columns in 2D, 6 in 3D)"
    default_update: ClassVar[str] = "every_step"
    default_new_particles: ClassVar[str] = "interpolate"
    mesh_fields: ClassVar[tuple[str, str]] = ("elastic_viscosity", "elastic_memory")
    """The mesh fields :meth:`refresh` reads: ``eta_ve`` and ``chi`` (the model supplies them)."""

    @dataclass(frozen=True, kw_only=True)
    class Settings(ParticleProperty.Settings):
        """The stress at creation."""

        initial: tuple[float, ...] = param((), help="Stress at creation in Voigt order (xx, yy, xy; 3D: xx, yy, "
                                                   "zz, xy, xz, yz); empty: zero.")

    settings: Settings

    def check(self) -> None:
        super().check()
        initial = self.settings.initial
        if len(initial) not in (0, 3, 6) or not np.all(np.isfinite(initial)):
            raise ValueError(f"elastic_stress: initial must be 3 (2D) or 6 (3D) finite numbers, got {initial}")

    @property
    def initial(self) -> tuple[float, ...]:
        """The stress at creation in Voigt order (empty: zero)."""
        return tuple(self.settings.initial)

    def size(self, gdim: int) -> int:
        return len(_VOIGT[gdim])

    def initialise(self, swarm: Swarm, rows: npt.NDArray[np.integer], context: PropertyContext) -> None:
        size = self.size(swarm.gdim)
        if self.initial and len(self.initial) != size:
            raise ValueError(f"elastic_stress: initial needs {size} numbers in {swarm.gdim}D, got {len(self.initial)}")
        write_rows(swarm, self.column, rows, np.asarray(self.initial or (0.0,) * size, dtype=np.float64))

    def refresh(self, swarm: Swarm, context: PropertyContext) -> None:
        """``tau <- 2 eta_ve eps + chi R tau R^T`` at every particle for the step ``context.dt``."""
        if context.dt <= 0.0 or swarm.num_particles == 0:
            return
        missing = [name for name in self.mesh_fields if name not in context.fields]
        if missing:
            raise ValueError(f"particle property {self.name!r} needs the mesh fields {missing} in the PropertyContext")
        u = context.require("velocity", self.name)
        lay = swarm.layout(self.column)
        if fast_update(swarm, (u, *(context.fields[name] for name in self.mesh_fields)), context.evaluators,
                       context.dt, lay.start):  # the compiled loop (2D), the same numbers
            return
        rows = np.arange(swarm.num_particles, dtype=np.int64)
        gdim = swarm.gdim
        grad = gradient_at(swarm, rows, u, context)
        eta_ve, chi = (evaluate_at(swarm, rows, context.fields[name], context).reshape(-1, 1, 1)
                       for name in self.mesh_fields)
        tau = from_voigt(swarm.properties[:, lay.start:lay.start + lay.size], gdim)
        new = 2.0 * eta_ve * strain_rate(grad) + chi * jaumann_rotation(tau, grad, context.dt)
        write_rows(swarm, self.column, rows, to_voigt(new))
