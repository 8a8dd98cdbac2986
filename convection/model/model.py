"""A convection model made of components, advanced one time step at a time.

The model holds the mesh's solvers and the components that act on them, each with one job:

- ``stokes`` (:class:`convection.solvers.stokes.solver.StokesSolver`): velocity and pressure for the current
  temperature and material fractions; its approximation holds the physics;
- ``temperature`` (:class:`convection.solvers.transport.TransportSolver`, or None for a fixed ``T = 0``);
- ``composition`` (a :data:`convection.model.composition.COMPOSITION_SOURCES` entry, or None): the
  material fractions;
- ``particles`` (:class:`particles.systems.ParticleSystems`: one or several particle systems, or None);
- ``adaptivity`` (:class:`convection.adapt.adaptivity.Adaptivity`) and ``balancer``
  (:class:`convection.adapt.rebalance.Balancer`), each with its own schedule;
- ``free_surface`` (:class:`convection.deform.motion.FreeSurface`, or None): the mesh moves with
  the surface;
- ``elastic_stress`` (:class:`convection.model.elastic_stress.FieldStress`, or None): the elastic
  stress history as advected mesh fields (``physics.elasticity.stress: fields``; else the particles
  carry it).

One step of length ``dt`` from ``t^n`` (:meth:`Model.step`):

0. where the flow anticipates the step's end (a free surface's stabilisation, a predicted buoyancy)
   and was solved for less than half of ``dt`` (on the first step: for no step), it is solved again
   for ``dt``, and ``u* = u^n`` in 1. (a flow solved for another step is not of the history ``u*``
   extrapolates); the elastic stress (particles' or fields') takes that flow's strain (the flow moves the step:
   without it, the first step's elastic deformation would carry no stress, issue 48). Up to twice
   the anticipated step the flow is kept: with ``theta = 1`` a relaxing surface is then multiplied
   by ``|A| <= 1`` per step (:mod:`convection.deform.surface`), and solving again at every growing
   CFL step made the flow noisier (vrms jumps 0.215 against 0.093 with the predicted buoyancy,
   tests/convection/physics/test_buoyancy.py);
1. the velocity at the step's end is extrapolated, ``u* = (1 + w) u^n - w u^{n-1}``
   (``w = dt / dt_previous``; ``u* = u^n`` on the first step) — the model is the one owner of the
   previous velocity;
2. the temperature is advanced with ``u*`` (SUPG, BDF2), then the advected material fields and
   stress fields;
3. the particles move in the velocity linear in time from ``u^n`` to ``u*`` (with their ODE
   properties), then the population bounds apply and the material fields are re-averaged. With a
   predicted buoyancy (``stokes.buoyancy_theta > 0``) ``u^n`` is the flow at ``t^n + theta dt`` and
   the material (particles, advected fractions) moves in ``u^n`` over the whole step: the pairing
   that keeps a dense interface stable at any step (:mod:`convection.physics.buoyancy`);
   with a free surface the temperature and the advected fields move with ``u - u_mesh`` (the mesh
   velocity of ``u^n``), then the mesh moves by ``dt u_mesh`` and the particles are found again
   in its cells (:mod:`convection.deform.motion`);
4. ``t += dt``; the mesh is adapted and/or repartitioned if due (every field, the velocity history
   and the particles follow);
5. Stokes is solved for ``u^{n+1}, p^{n+1}``; the stress fields and the particles' properties are
   refreshed from the new solution, the particles written when due.

A run (:func:`convection.run.loop.run`) is a loop around :meth:`Model.step`; a user can write the same
loop in Python (see ``demos/``).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, NamedTuple

import dolfinx.fem
import dolfinx.mesh
import numpy as np

from convection.adapt.adaptivity import Adaptivity
from convection.adapt.hierarchy import MeshHierarchy
from convection.deform.motion import FreeSurface
from convection.geometry.domain import Domain
from convection.model.composition import CompositionSource
from convection.model.elastic_stress import FieldStress
from convection.model.mesh_changes import MeshChanges
from convection.physics.materials import material_index
from convection.model.rheology_fields import Flow, RheologyFields
from convection.adapt.rebalance import Balancer, RankLoads
from convection.solvers.stokes.solver import StokesResult, StokesSolver
from convection.solvers.timestep import cfl_timestep
from convection.solvers.transport import TransportSolver
from fembase.state import State, Stateful
from fembase.timing import Timers
from particles.manager import ParticleManager
from particles.systems import ParticleSystems, file_stem
from particles.properties import PropertyContext

__all__ = ["Model", "StepReport"]


class StepReport(NamedTuple):
    """What happened to the mesh in one step (None: nothing).

    Attributes:
        adapted: Global cell counts (before, after) if the mesh was adapted.
        rebalanced: Loads per rank (before, after) if the mesh was repartitioned.
    """

    adapted: tuple[int, int] | None = None
    rebalanced: tuple[RankLoads, RankLoads] | None = None


class Model(Stateful):
    """Boussinesq convection with optional materials, particles, adaptivity and balancing (all methods collective).

    Args:
        stokes: The flow solver on the model's mesh.
        temperature: The temperature solver (``velocity_extrapolation=False``: the model passes the
            extrapolated velocity), or None for ``T = 0``.
        solve_temperature: False keeps the temperature at its initial value.
        composition: The material fractions, or None.
        particles: The particle systems (or one manager: a system named ``particles``), or None.
        adaptivity: Mesh adaptivity, or None.
        balancer: Load balancing, or None.
        free_surface: The free surface's mesh motion, or None.
        elastic_stress: The elastic stress as mesh fields, or None.
    """

    def __init__(self, stokes: StokesSolver, /, *, temperature: TransportSolver | None = None,
                 solve_temperature: bool = True, composition: CompositionSource | None = None,
                 particles: ParticleSystems | ParticleManager | None = None, adaptivity: Adaptivity | None = None,
                 balancer: Balancer | None = None, free_surface: FreeSurface | None = None,
                 elastic_stress: FieldStress | None = None) -> None:
        if temperature is not None and temperature.velocity_extrapolation:
            raise ValueError("the model extrapolates the velocity itself: build the temperature solver with "
                             "velocity_extrapolation=False")
        self.stokes = stokes
        self.temperature = temperature
        self.solve_temperature = solve_temperature and temperature is not None
        self.composition = composition
        self.particles = ParticleSystems.of(particles) if particles is not None else None
        self.adaptivity, self.balancer = adaptivity, balancer
        self.hierarchy: MeshHierarchy | None = None  # the mesh's, where neither of those holds it (checkpoints)
        self.free_surface = free_surface
        self.elastic_stress = elastic_stress
        self.timers = Timers()
        self.time = 0.0
        self.timestep = 0
        self.dt_previous = 0.0
        self.stokes_assemblies = 0  # how many times the Stokes operator was assembled anew
        self.u_previous: dolfinx.fem.Function | None = None
        self.flow_result: StokesResult | None = None
        self.mesh_version = 0  # increases with every new mesh (caches keyed on the mesh use it)
        self._mesh_changes = MeshChanges(self)
        self.rheology = RheologyFields(stokes, self.particles, elastic_stress)

    # ------------------------------------------------------------------ state
    @property
    def mesh(self) -> dolfinx.mesh.Mesh:
        return self.stokes.mesh

    @property
    def domain(self) -> Domain:
        """The domain (the flow solver's): boundaries, gravity, ... (:mod:`convection.geometry.domain`)."""
        return self.stokes.domain

    @property
    def comm(self):
        """The current mesh's communicator (ask again after a mesh change: the old one is freed with its mesh)."""
        return self.stokes.mesh.comm

    @property
    def num_cells(self) -> int:
        return int(self.mesh.topology.index_map(self.mesh.topology.dim).size_global)

    @property
    def T(self) -> dolfinx.fem.Function | None:
        """The temperature Function (None without a temperature solver)."""
        return self.temperature.T if self.temperature is not None else None

    @property
    def fractions(self) -> tuple[dolfinx.fem.Function, ...]:
        """The material fractions, one Function per material (empty without composition)."""
        return self.composition.fields if self.composition is not None else ()

    def fields(self) -> dict[str, dolfinx.fem.Function]:
        """Every field by name, for output: temperature, velocity, pressure, the material fractions, ``material``
        (two or more; :func:`convection.physics.materials.material_index`), the ``density`` anomaly, the viscosity where
        it varies, ``strain_rate_II``, ``stress_II`` (cell midpoints), ``phase_<name>``, the adiabat (collective)."""
        out = {"velocity": self.stokes.u, "pressure": self.stokes.p}
        if self.temperature is not None:
            out = {"temperature": self.temperature.T, **out}
        for f in self.fractions:
            out[f.name] = f
        if len(self.fractions) >= 2:
            out["material"] = material_index(self.fractions)
        approximation = self.stokes.approximation
        if self.fractions and (approximation.Ra != 0.0 or any(rb != 0.0 for rb in np.atleast_1d(approximation.Rb))):
            out["density"] = self.rheology.density(self.flow())
        if self.stokes.approximation.viscosity_law.numbers is None:
            # The viscosity of the flow (cell midpoints), the particle fields it reads (e.g. plastic
            # strain) and the rates the particles integrate.
            flow = self.flow()
            out["viscosity"] = self.rheology.viscosity(flow)
            out.update(flow.fields)
            out.update(self.particle_fields())
        elif self.stokes.approximation.is_variable_viscosity:
            out["viscosity"] = self.rheology.viscosity(self.flow())
        out.update(self.rheology.outputs(self.flow()))
        return out

    def flow(self) -> Flow:
        """What the rheology reads now: the flow solver, temperature, fractions and the particle
        fields the viscosity laws read (:class:`convection.model.rheology_fields.Flow`)."""
        return Flow(self.stokes, self.T if self.T is not None else 0.0, self.fractions or None,
                    self.rheology.law_fields(self.stokes))

    def particle_fields(self) -> dict[str, dolfinx.fem.Function]:
        """The mesh fields the particles integrate (the rates the rheology declares, e.g.
        ``plastic_strain_rate``), as of the last flow solve (computed here after a restart, which
        restores the flow without solving it; collective then)."""
        if not self.rheology.rates:
            return {}
        return self.rheology.rate_functions(self.flow() if self.flow_result is not None else None)

    def property_context(self, dt: float | None = None) -> PropertyContext:
        """The fields, time and step (default: the last) for particle properties (elasticity's fields: issue 48)."""
        return PropertyContext(time=self.time, dt=dt or self.dt_previous, u_new=self.stokes.u, temperature=self.T,
                               pressure=self.stokes.p, fields=self.rheology.property_fields(self.particle_fields))

    # ------------------------------------------------------------------ checkpoints
    def components(self) -> dict[str, Stateful]:
        """The stateful components by the name a checkpoint keeps them under (:mod:`fembase.state`):
        the model's own time stepping, the flow, the temperature, the material fractions, the particle
        managers (whose swarms are checkpoint parts of their own), the free surface, the stress fields."""
        out: dict[str, Stateful] = {"model": self, "stokes": self.stokes}
        managers = [(file_stem(name), m) for name, m in (self.particles.items() if self.particles is not None else ())]
        for name, component in (("temperature", self.temperature), ("composition", self.composition), *managers,
                                ("free_surface", self.free_surface), ("elastic_stress", self.elastic_stress)):
            if component is not None:
                out[name] = component
        return out

    def state(self) -> State:
        """The time stepping: time, step, last step, the previous velocity (for the extrapolation),
        the last flow solve's outcome and the timers."""
        flow, fields = self.flow_result, ({"u_previous": self.u_previous} if self.u_previous is not None else {})
        return State(fields=fields, scalars={
            "time": self.time, "timestep": self.timestep, "dt_previous": self.dt_previous,
            "has_u_previous": bool(fields),
            "flow": None if flow is None else [int(flow.iterations), float(flow.residual_norm)],
            "timers": {"seconds": self.timers.seconds, "calls": self.timers.calls}})

    def restore(self, scalars: Mapping[str, Any], /) -> dict[str, dolfinx.fem.Function]:
        """Take the time stepping back; returns the previous velocity to fill (if the run had one)."""
        self.time, self.timestep, self.dt_previous = scalars["time"], scalars["timestep"], scalars["dt_previous"]
        flow = scalars["flow"]
        self.flow_result = None if flow is None else StokesResult(int(flow[0]), float(flow[1]))
        self.timers.seconds = dict(scalars["timers"]["seconds"])
        self.timers.calls = dict(scalars["timers"]["calls"])
        if not scalars["has_u_previous"]:
            return {}
        self.u_previous = dolfinx.fem.Function(self.stokes.u.function_space)
        return {"u_previous": self.u_previous}

    # ------------------------------------------------------------------ time stepping
    def solve_flow(self, dt: float | None = None, /) -> StokesResult:
        """Solve Stokes now for the coming step ``dt`` (default: the last); the stress fields take its strain."""
        flow, step = self.flow(), self.dt_previous if dt is None else dt
        result = self.stokes.solve(flow.T, flow.fractions, dt=step, fields=flow.fields or None)
        if self.rheology.rates:
            with self.timers("plastic_strain_rate"):
                self.rheology.update_rates(flow)
        if self.elastic_stress is not None:
            with self.timers("elastic_stress"):
                self.elastic_stress.update(flow, step)
        self.timers.add("stokes_assembly", result.assembly_seconds)
        self.stokes_assemblies += result.assemblies
        self.timers.add("stokes_solve", result.solve_seconds)
        self.flow_result = result
        return result

    def start(self) -> StepReport:
        """Repartition if due at step 0, solve the initial flow, sample it into the particles."""
        report = StepReport(rebalanced=self._rebalance_if_due())
        self.solve_flow()
        if self.particles is not None:
            self.particles.update(self.property_context(), step=self.timestep)
        return report

    def cfl_dt(self, cfl: float, /, *, dt_max: float | None = None) -> float:
        """The largest step with Courant number ``cfl`` for the current velocity (inf if at rest)."""
        return cfl_timestep(self.stokes.u, cfl, dt_max=dt_max)

    def step(self, dt: float, /) -> StepReport:
        """Advance the model by ``dt`` (see the module docstring); starts the model if needed."""
        if self.flow_result is None:
            self.start()
        anticipates = self.stokes.buoyancy_theta > 0.0 or self.stokes.discretisation.anticipates_step
        if anticipates and dt > 2 * self.dt_previous:
            self.solve_flow(dt)  # it anticipated a far shorter step (the first step: none): step 0 above
            self.u_previous = None  # u^n is then not of the history u* extrapolates
            if self.particles is not None:  # the step moves with this flow: its strain joins the elastic stress
                self.particles.refresh("elastic_stress", self.property_context(dt))
        u = self.stokes.u
        u_end = self._velocity_at_step_end(dt)
        u_materials = u if self.stokes.buoyancy_theta > 0.0 else u_end
        frame = self._mesh_changes.moving_frame(u)  # u - u_mesh with a free surface
        if self.solve_temperature and self.temperature is not None:  # solve_temperature: there is one
            with self.timers("temperature"):
                self.temperature.step(frame(u_end), dt)
        for name, advected in (("composition", self.composition), ("elastic_stress", self.elastic_stress)):
            if advected is not None:
                with self.timers(name):
                    advected.advance(frame(u_materials), dt)
        if self.particles is not None:
            self.particles.advance(u, u_materials, dt, step=self.timestep, fields=self.particle_fields())
        if self.free_surface is not None:
            self._mesh_changes.move(dt)
        self.time += dt
        self.timestep += 1
        self.dt_previous = dt
        adapted = self.adapt() if self.adaptivity is not None and self.adaptivity.due(self.timestep) else None
        report = StepReport(adapted, self._rebalance_if_due())
        self.solve_flow()
        if self.particles is not None:
            self.particles.update(self.property_context(), step=self.timestep)
        return report

    def _velocity_at_step_end(self, dt: float) -> dolfinx.fem.Function:
        """u* (module docstring); then remembers u^n as the previous velocity."""
        u = u_end = self.stokes.u
        if self.u_previous is not None and self.dt_previous > 0.0:
            w = dt / self.dt_previous
            u_end = dolfinx.fem.Function(u.function_space)
            u_end.x.array[:] = (1.0 + w) * u.x.array - w * self.u_previous.x.array
        if self.u_previous is None or self.u_previous.function_space is not u.function_space:
            self.u_previous = dolfinx.fem.Function(u.function_space)
        self.u_previous.x.array[:] = u.x.array
        return u_end

    # ------------------------------------------------------------------ mesh changes
    def adapt(self) -> tuple[int, int]:
        """Adapt the mesh once (needs ``adaptivity``) and carry everything to it. Returns the global
        cell counts before and after."""
        return self._mesh_changes.adapt()

    def rebalance(self) -> tuple[RankLoads, RankLoads]:
        """Repartition now (needs ``balancer``); returns the loads per rank before and after."""
        return self._mesh_changes.rebalance()

    def _rebalance_if_due(self) -> tuple[RankLoads, RankLoads] | None:
        swarms = self.particles.swarms if self.particles is not None else []
        if self.balancer is None or not self.balancer.due(self.timestep, self.mesh, swarms):
            return None
        return self.rebalance()

    def destroy(self) -> None:
        """Free the solvers' PETSc objects now, on every rank together."""
        for solver in (self.stokes, self.temperature, self.composition, self.free_surface, self.elastic_stress):
            if solver is not None:
                solver.destroy()
