"""Carrying a model to a new mesh: adaptation and repartitioning (:class:`MeshChanges`).

After a mesh change every solver is made again on the new mesh with the same settings and its
fields are carried over (:func:`convection.adapt.transfer.transfer_function`), the previous
velocity and the material fractions too; the particles move with the particle manager. When both
meshes are refined from the adaptivity's base mesh (an adaptation), each field node and each
particle is looked for first among the new cells of its old cell's base cell.

With a free surface the mesh's nodes are displaced from where the hierarchy made them. A mesh
change then works in the reference configuration (arbitrary Lagrangian-Eulerian): the old mesh is
put back undeformed, and the hierarchy's levels and base cells, the refinement indicator, the level
bounds (``min_level_where``, ...: positions in the undeformed box) and the fields' transfer all see
the undeformed meshes, where the new mesh nests in the base exactly; the nodes' deformed positions
are carried to the new mesh like a field over the undeformed one, and the new mesh takes them
before the particles are found in it (:meth:`convection.deform.motion.FreeSurface.to_mesh`). Each cell is mapped
affinely in both configurations, so a field's nodal values mean the same in either. Particles keep their
positions; where coarser cells' surface (the chord of the finer one's) passes below a particle, it
is moved down onto it (:func:`particles.relocation.moving_mesh.pull_in`, counted as pulled in).
"""

from __future__ import annotations

import contextlib
from functools import partial
from collections.abc import Callable, Iterator, Mapping
from typing import Protocol

import dolfinx.fem
import dolfinx.mesh
import numpy as np
import numpy.typing as npt

from convection.adapt.adaptivity import INDICATOR_FIELDS, Adaptivity
from convection.adapt.rebalance import Balancer, RankLoads
from convection.adapt.transfer import PointEvaluator, transfer_function
from convection.deform.motion import FreeSurface
from convection.geometry.domain import Domain
from convection.model.composition import CompositionSource, Transfer
from convection.solvers.stokes.solver import StokesSolver
from convection.solvers.transport import TransportSolver
from fembase.geometry import Candidates
from fembase.timing import Timers
from particles.properties import PropertyContext
from particles.storage.swarm import Swarm
from particles.systems import ParticleSystems

__all__ = ["ChangingModel", "MeshChanges"]


class MovingFields(Protocol):
    """Fields a mesh change carries over (the elastic stress fields,
    :class:`convection.model.elastic_stress.FieldStress`)."""

    def to_mesh(self, mesh: dolfinx.mesh.Mesh, transfer: Transfer, /) -> None: ...


class ChangingModel(Protocol):
    """The model as a mesh change sees it: the components it rebuilds on the new mesh (the
    solvers, the free surface, the previous velocity) and those it asks to move (composition,
    particles). :class:`convection.model.model.Model` is one; this protocol keeps the model, which
    owns its :class:`MeshChanges`, out of this module's imports."""

    stokes: StokesSolver
    temperature: TransportSolver | None
    composition: CompositionSource | None
    particles: ParticleSystems | None
    adaptivity: Adaptivity | None
    balancer: Balancer | None
    free_surface: FreeSurface | None
    u_previous: dolfinx.fem.Function | None
    timers: Timers
    time: float
    timestep: int
    mesh_version: int

    @property
    def elastic_stress(self) -> MovingFields | None: ...

    @property
    def mesh(self) -> dolfinx.mesh.Mesh: ...

    @property
    def domain(self) -> Domain: ...

    @property
    def num_cells(self) -> int: ...

    @property
    def T(self) -> dolfinx.fem.Function | None: ...

    @property
    def fractions(self) -> tuple[dolfinx.fem.Function, ...]: ...

    def property_context(self) -> PropertyContext: ...


class MeshChanges:
    """Adapts and repartitions a model's mesh and carries the model to it (see the module
    docstring). All methods are collective.

    Args:
        model: The model whose mesh changes (its solvers, history, fractions and particles).
    """

    def __init__(self, model: ChangingModel, /) -> None:
        self.model = model
        self._point_evaluator: PointEvaluator | None = None

    def _swarm(self) -> Swarm | None:
        """The primary particle system's swarm (None without particles)."""
        particles = self.model.particles
        return particles.primary.swarm if particles is not None else None

    def _swarms(self) -> list[Swarm]:
        """Every particle system's swarm."""
        particles = self.model.particles
        return particles.swarms if particles is not None else []

    def locator(self) -> PointEvaluator:
        """Point location and evaluation on the current mesh (built once per mesh; shares the
        particles' cell geometry when they live on it)."""
        mesh = self.model.mesh
        if self._point_evaluator is None or self._point_evaluator.mesh is not mesh:
            swarm = self._swarm()
            geometry = swarm.geometry if swarm is not None and swarm.mesh is mesh else None
            self._point_evaluator = PointEvaluator(mesh, geometry=geometry)
        return self._point_evaluator

    def moving_frame(self, u: dolfinx.fem.Function, /) -> Callable[[dolfinx.fem.Function], dolfinx.fem.Function]:
        """What a velocity becomes in the mesh's frame for this step: with a free surface, the
        velocity minus the mesh velocity of the flow ``u`` (made here); otherwise itself."""
        model = self.model
        surface = model.free_surface
        if surface is None:
            return lambda v: v
        if model.particles is not None:  # particles the moving surface passes are moved back in
            model.particles.set_inward(model.domain.inward)
        with model.timers("mesh_motion"):
            surface.velocity(u)
        return surface.relative

    def move(self, dt: float, /) -> None:
        """Move the mesh's nodes by ``dt`` times the free surface's mesh velocity and find the
        particles again in the moved cells (those the sinking surface left outside are moved
        down inside: :mod:`particles.relocation.moving_mesh`)."""
        model = self.model
        assert model.free_surface is not None, "only a free surface moves the mesh's nodes"
        with model.timers("mesh_motion"):
            model.free_surface.move(dt)
        model.stokes.mesh_moved()
        model.mesh_version += 1
        self._point_evaluator = None
        if model.particles is not None:
            model.particles.follow_mesh()

    def adapt(self) -> tuple[int, int]:
        """Adapt the mesh once (needs the model's ``adaptivity``) and carry the model to it.
        Returns the global cell counts before and after."""
        model = self.model
        adaptivity = model.adaptivity
        assert adaptivity is not None
        before = model.num_cells
        with model.timers("adaptation"), self._reference_frame() as locator:
            indicator_fields = {"temperature": lambda: [model.T] if model.T is not None else [],
                                "composition": lambda: list(model.fractions)}
            fields = [f for name in INDICATOR_FIELDS if name in adaptivity.fields for f in indicator_fields[name]()]
            fallback = model.T if model.T is not None else model.stokes.u
            mesh = adaptivity.new_mesh(model.mesh, fields or [fallback], locator=locator, time=model.time)
            # Both meshes are refined from one base: each particle is looked for first among the
            # new cells of its old cell's base cell, not with a bounding-box search of the new mesh.
            candidates = {name: adaptivity.hierarchy.candidates(mesh, model.mesh, manager.swarm.cells)
                          for name, manager in (model.particles.items() if model.particles is not None else ())}
        self.move_to(mesh, candidates=candidates, nested=True)
        return before, model.num_cells

    def rebalance(self) -> tuple[RankLoads, RankLoads]:
        """Repartition now (needs the model's ``balancer``); returns the loads per rank before and
        after."""
        model = self.model
        balancer = model.balancer
        assert balancer is not None
        surface = model.free_surface  # the undeformed cells, as _reference_frame, without its locator
        with model.timers("balancing"), surface.undeformed() if surface is not None else contextlib.nullcontext():
            before = balancer.loads(model.mesh, self._swarms())
            mesh = balancer.new_mesh(model.mesh, self._swarms())
        self.move_to(mesh)
        return before, balancer.loads(model.mesh, self._swarms())

    def move_to(self, mesh: dolfinx.mesh.Mesh, /, *, candidates: Mapping[str, Candidates | None] | None = None,
                nested: bool = False) -> None:
        """Rebuild the solvers on ``mesh`` and carry every field, the history and the particles
        (``candidates``: where to look for each particle first, by particle system, see
        ``ParticleManager.to_mesh``;
        ``nested``: both meshes are refined from the adaptivity's base mesh, so the fields' nodes are
        looked for among the old cells of their base cell first)."""
        model = self.model
        nodes_in = None
        if nested and model.adaptivity is not None:
            hierarchy, old_mesh = model.adaptivity.hierarchy, model.mesh

            def nodes_in(cells: npt.NDArray[np.int32]) -> Candidates | None:
                return hierarchy.candidates(old_mesh, mesh, cells)

        surface = model.free_surface
        positions = surface.positions() if surface is not None else None
        with model.timers("field_transfer"), self._reference_frame() as locator:
            if surface is not None:  # first: it keeps the new mesh's boundary facets for the solvers
                model.free_surface = surface.to_mesh(mesh, positions, partial(
                    transfer_function, evaluator=locator, candidates=nodes_in))
            old = self._transfer_fields(mesh, nodes_in, locator)
        if surface is not None:
            surface.release()  # the old mesh may be the hierarchy's base
            assert model.free_surface is not None  # the new mesh's, made above
            model.free_surface.displace()
            old.append(surface)
        if model.particles is not None:  # the manager times its own move
            # A repartition (not nested) keeps the cells: no population bounds (after a free
            # surface's move the counts are out of them until the next step; on one rank, which
            # never repartitions, they would stay so).
            model.particles.to_mesh(mesh, context=model.property_context(), step=model.timestep,
                                    candidates=candidates, bound=nested)
        for solver in old:
            if solver is not None:
                solver.destroy()
        self._point_evaluator = None  # it holds the old mesh
        model.mesh_version += 1

    @contextlib.contextmanager
    def _reference_frame(self) -> Iterator[PointEvaluator]:
        """The mesh in the configuration a mesh change works in, with a point locator of it there:
        with a free surface the undeformed one (the hierarchy's levels and base cells, the
        indicator, the level bounds and the field transfer all work on the undeformed meshes; the
        nodes' deformed positions are carried as a field), otherwise the mesh as it is."""
        surface = self.model.free_surface
        if surface is None:
            yield self.locator()
            return
        with surface.undeformed():
            # Not the particles' cell geometry (the deformed one). Snapped: the new mesh's nodes are
            # old nodes or old edges' midpoints, and their positions must not depend on the partition.
            yield PointEvaluator(self.model.mesh, snap=True)

    def _transfer_fields(self, mesh: dolfinx.mesh.Mesh,
                         candidates: Callable[[npt.NDArray[np.int32]], Candidates | None] | None,
                         evaluator: PointEvaluator, /) -> list:
        """New solvers on ``mesh`` with the fields carried over by ``evaluator`` (of the current
        mesh); returns the old solvers (``candidates``: see
        :func:`convection.adapt.transfer.transfer_function`)."""
        model = self.model

        def transfer(src: dolfinx.fem.Function, dst: dolfinx.fem.Function) -> None:
            transfer_function(src, dst, evaluator=evaluator, candidates=candidates)

        old_stokes, old_temperature = model.stokes, model.temperature
        model.stokes = old_stokes.on_mesh(mesh)
        model.stokes.transfer_from(old_stokes, transfer)
        if old_temperature is not None:
            model.temperature = old_temperature.on_mesh(mesh)
            model.temperature.transfer_from(old_temperature, transfer)
        if model.u_previous is not None:
            u_previous = dolfinx.fem.Function(model.stokes.u.function_space)
            transfer(model.u_previous, u_previous)
            model.u_previous = u_previous
        if model.composition is not None:
            model.composition.to_mesh(mesh, transfer)
        if model.elastic_stress is not None:
            model.elastic_stress.to_mesh(mesh, transfer)
        return [old_stokes, old_temperature]
