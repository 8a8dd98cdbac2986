"""Composition carried by particles: the mesh field C is a per-cell average of a particle property.

Each particle carries ``composition`` (set from ``initial.composition`` at its initial position).
Per time step the particles are advected with the velocity interpolated linearly in time between
the start and the end of the step, and C is rebuilt on the mesh from them with a particle-to-mesh
interpolator (default: arithmetic cell average into DG0, as in the seed paper). When the mesh
changes, the particles move to the new mesh (:func:`particles.adaptivity.move_to_mesh`).
"""

from __future__ import annotations

from typing import Any, Callable

import numpy as np
import numpy.typing as npt

import dolfinx.fem
import dolfinx.mesh

from particles import Swarm
from particles.adaptivity import move_to_mesh
from particles.advection import AdvectionStats, Advector
from particles.generation import create_generator, generate
from particles.interpolation import InterpolationStats, interpolate_to_mesh

__all__ = ["ParticleComposition"]

PROPERTY = "composition"


class ParticleComposition:
    """Particles with a composition property and the mesh field averaged from them (collective).

    Args:
        mesh: The current mesh.
        initial: Initial composition as a function of points, x shape=(3, n) -> shape=(n,).
        generator: Generator name and parameters (``{"name": ..., **params}``); ``num_particles``
            may be replaced by ``particles_per_cell`` (times the global cell count).
        integrator: Runge-Kutta integrator name.
        interpolator: Particle-to-mesh interpolator name and its parameters.
        degree: Degree of C (0: DG0 cell values; 1: DG1 or P1 depending on the interpolator).
    """

    def __init__(
        self,
        mesh: dolfinx.mesh.Mesh,
        initial: Callable[[npt.NDArray[np.float64]], npt.NDArray[np.float64]],
        /,
        *,
        generator: dict[str, Any],
        integrator: str = "rk2",
        interpolator: dict[str, Any] | None = None,
        degree: int = 0,
    ) -> None:
        params = dict(generator)
        name = params.pop("name")
        per_cell = params.pop("particles_per_cell", None)
        if per_cell is not None:
            cells = mesh.topology.index_map(mesh.topology.dim).size_global
            params["num_particles"] = int(round(per_cell * cells))
        self.interpolator = dict(interpolator or {"name": "cell_average"})
        self.degree = degree
        self.integrator = integrator
        self.swarm = Swarm(mesh)
        self.swarm.add_property(PROPERTY)
        generate(self.swarm, create_generator(name, **params))
        x3 = np.zeros((3, self.swarm.num_particles))
        x3[: self.swarm.gdim] = self.swarm.x.T
        self.swarm.property(PROPERTY)[:, 0] = initial(x3)
        self.lost = 0
        self._setup(mesh)

    def _setup(self, mesh: dolfinx.mesh.Mesh) -> None:
        self.advector = Advector(self.swarm, integrator=self.integrator)
        family = "DG" if self.degree == 0 or self.interpolator["name"] == "least_squares" else "Lagrange"
        self.field = dolfinx.fem.Function(dolfinx.fem.FunctionSpace(mesh, (family, self.degree)), name="composition")
        self.update_field()

    @property
    def num_particles(self) -> int:
        """Global particle count (collective)."""
        return self.swarm.global_num_particles()

    def update_field(self) -> InterpolationStats:
        """Rebuild C from the particles (collective)."""
        params = dict(self.interpolator)
        method = params.pop("name")
        return interpolate_to_mesh(self.swarm, PROPERTY, self.field, method=method, **params)

    def advect(self, u_old: dolfinx.fem.Function, u_new: dolfinx.fem.Function, dt: float) -> AdvectionStats:
        """Move the particles over one step and rebuild C (collective)."""
        stats = self.advector.step(u_old, u_new, dt)
        self.lost += stats.global_lost
        self.update_field()
        return stats

    def move_to_mesh(self, mesh: dolfinx.mesh.Mesh) -> None:
        """Carry the particles to a new mesh and rebuild C there (collective)."""
        self.swarm, stats = move_to_mesh(self.swarm, mesh)
        self.lost += stats.lost
        self._setup(mesh)
