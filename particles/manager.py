"""The particle world of one run: one object owning every particle component (ASPECT's Particle::Manager).

A :class:`ParticleManager` owns the swarm and the components that act on it, each chosen by name
from its registry (:mod:`particles.generation`, :mod:`particles.advection`,
:mod:`particles.properties`, :mod:`particles.interpolation`) or given as an object:

- a generator, run once at construction;
- an integrator (Runge-Kutta tableau) advancing positions and the properties that obey an ODE;
- a :class:`~particles.properties.PropertyManager` for the properties every particle carries;
- an interpolator that turns properties into mesh fields (:meth:`ParticleManager.track`);
- optional population bounds (:class:`~particles.population.control.PopulationControl`), applied at
  creation, after every advection step and after every change of mesh;
- an optional :class:`~particles.io.output.ParticleWriter` with an :class:`OutputSchedule`.

A time step from ``t`` to ``t + dt`` takes two collective calls::

    manager.advance(u_old, u_new, dt, step=n)         # advect (+ property ODEs) -> bounds -> mesh fields
    ...                                               # the caller solves for the fields at t + dt
    manager.update(PropertyContext(time=t + dt, dt=dt, u_new=u, temperature=T), step=n + 1)
                                                      # property updates -> output when due

The split lets a coupled code rebuild the mesh fields (e.g. composition) from the advected
particles *before* it solves for the new velocity, and then sample the new solution into the
properties. :meth:`ParticleManager.to_mesh` carries everything to a new mesh (after adaptation or
repartitioning), then applies the population bounds again.

New particles made by population control copy every property from the nearest older particle of
their cell (from neighbouring cells' averages in a cell that had none; both across ranks, so the
result does not depend on the rank count, :func:`particles.population.control.copy_nearest`); properties
whose new-particle policy is ``"reinitialise"`` are then evaluated afresh at the new particles.

The tracked mesh fields live in :class:`particles.interpolation.tracked_fields.TrackedFields`; when output is
next due is kept by this module's ``_OutputClock``.

This module never imports ``convection``; it works on any DOLFINx mesh.
"""

from __future__ import annotations

import dataclasses
import time
from contextlib import contextmanager
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from collections.abc import Callable, Iterator, Mapping, Sequence
from typing import Any

import numpy as np
import numpy.typing as npt
from mpi4py import MPI

import dolfinx.fem
import dolfinx.mesh

from fembase.geometry import Candidates
from fembase.state import State, Stateful
from particles.interpolation.tracked_fields import TrackedFields
from particles.relocation.new_mesh import move_to_mesh
from particles.advection import Advector, get_integrator
from particles.generation import GENERATORS, GenerationResult, Generator, GeneratorContext, MakeFunction, generate
from particles.interpolation import INTERPOLATORS, CellAverage, Interpolator, InterpolatorContext
from particles.parallel.migration import migrate
from particles.relocation.moving_mesh import FollowStats, follow_mesh
from particles.io.output import PARTICLE_WRITERS, OutputRecord, OutputUnits, ParticleWriter, ParticleWriterContext
from particles.population.control import PopulationControl, PopulationStats, copy_nearest
from particles.settings import ParticleSettings, particle_settings
from particles.properties import PROPERTIES, ParticleProperty, PropertyBuildContext, PropertyContext, PropertyManager
from particles.storage.swarm import Swarm
from particles.relocation.between_cells import relocate

__all__ = [
    "AdvanceReport",
    "OutputSchedule",
    "ParticleManager",
    "PointFunction",
    "build_generator",
    "build_interpolator",
    "build_properties",
    "particles_per_cell_summary",
]

PointFunction = Callable[[npt.NDArray[np.float64]], npt.ArrayLike]
"""``f(x)``: points shape=(m, gdim) -> values shape=(m,): a property source or generator density."""

Confine = Callable[[npt.NDArray[np.float64]], None]
"""``confine(x)``: moves positions (shape=(n, gdim), in place) that left the domain back inside."""

TIMING_PHASES: tuple[str, ...] = (
    "particle_advection", "particle_sort", "particle_migration", "particle_mesh_change", "particle_mesh_motion",
    "particle_population",
    "particle_properties", "particle_interpolation", "particle_output",
)
"""Phases of :attr:`ParticleManager.timings` (seconds, summed over calls on this rank)."""


@dataclass(frozen=True)
class OutputSchedule:
    """When particles are written.

    Attributes:
        every_steps: Write every this many steps (None: not by steps).
        every_time: Write at the first step at or after every multiple of this time (None: not by
            time). With both, either condition writes.
    """

    every_steps: int | None = None
    every_time: float | None = None

    def __post_init__(self) -> None:
        if self.every_steps is not None and self.every_steps < 1:
            raise ValueError(f"every_steps must be >= 1, got {self.every_steps}")
        if self.every_time is not None and not self.every_time > 0.0:
            raise ValueError(f"every_time must be > 0, got {self.every_time}")

    @property
    def enabled(self) -> bool:
        return self.every_steps is not None or self.every_time is not None

    def next_time(self, t: float, /) -> float:
        """The first output time strictly after ``t`` (inf without a time interval)."""
        if self.every_time is None:
            return float("inf")
        return (np.floor(t / self.every_time * (1.0 + 1e-12)) + 1.0) * self.every_time


@dataclass(frozen=True)
class AdvanceReport:
    """What one :meth:`ParticleManager.advance` did (global counts).

    Attributes:
        lost: Particles that left the domain in this step.
        sent: Particles that changed rank (sum over ranks and stages).
        population: Population-control counts, or None without bounds.
    """

    lost: int
    sent: int
    population: PopulationStats | None


def _choice(spec: Mapping[str, Any], /) -> tuple[Any, dict[str, Any]]:
    """(name, parameters) of a ``{name: ..., **parameters}`` mapping."""
    parameters = dict(spec)
    return parameters.pop("name", None), parameters


def build_properties(specs: Sequence[str | Mapping[str, Any] | ParticleProperty], /, *,
                     make_function: MakeFunction | None = None) -> list[ParticleProperty]:
    """Property objects from registry names, ``{name: ..., **parameters}`` mappings or objects: each
    the :data:`~particles.properties.PROPERTIES` entry's ``build`` of the ``Settings`` made of the
    parameters (text sources made functions by ``make_function``).

    Raises:
        ValueError: ``"item N: ..."`` naming the first bad entry (unknown name, with the valid
            names from :data:`particles.properties.PROPERTIES`, or bad parameters).
    """
    built: list[ParticleProperty] = []
    for i, spec in enumerate(specs):
        try:
            if isinstance(spec, ParticleProperty):
                built.append(spec)
                continue
            if isinstance(spec, str):
                spec = {"name": spec}
            if not isinstance(spec, Mapping) or "name" not in spec:
                raise ValueError(f"expected a property name or {{name: ..., parameters}}, got {spec!r}")
            name, parameters = _choice(spec)
            settings = PROPERTIES.settings(name, **parameters)
            built.append(PROPERTIES.build(name, settings, PropertyBuildContext(make_function)))
        except (TypeError, ValueError) as err:
            raise ValueError(f"item {i}: {err}") from None
    return built


def build_generator(spec: Mapping[str, Any] | Generator, /, *, num_cells: int,
                    make_function: MakeFunction | None = None, gdim: int | None = None) -> Generator:
    """A generator from ``{name: ..., **parameters}``: the :data:`~particles.generation.GENERATORS`
    entry's ``build`` of the ``Settings`` made of the parameters, in a
    :class:`~particles.generation.GeneratorContext` of ``gdim`` and ``make_function``;
    ``particles_per_cell`` (> 0) may replace ``num_particles`` (times ``num_cells``, the global
    cell count).

    Raises:
        ValueError: Unknown name (listing :data:`particles.generation.GENERATORS`), bad
            parameters, or a ``from_file`` path that is not a file (or, given ``gdim``, has the
            wrong number of columns).
    """
    if not isinstance(spec, Mapping):
        return spec
    name, params = _choice(spec)
    counted = "num_particles" in {f.name for f in dataclasses.fields(GENERATORS.lookup(name).Settings)}
    per_cell = params.pop("particles_per_cell", None) if counted else None  # else named as a parameter it lacks
    if isinstance(per_cell, str):  # YAML reads 1e6 as text
        try:
            per_cell = float(per_cell)
        except ValueError:
            pass
    if per_cell is not None:
        if "num_particles" in params:
            raise ValueError("give either particles_per_cell or num_particles, not both")
        if isinstance(per_cell, bool) or not isinstance(per_cell, (int, float)) or not per_cell > 0:
            raise ValueError(f"particles_per_cell must be a number > 0, got {per_cell!r}")
        params["num_particles"] = int(round(per_cell * num_cells))
    return GENERATORS.build(name, GENERATORS.settings(name, **params), GeneratorContext(gdim, make_function))


def build_interpolator(spec: Mapping[str, Any] | Interpolator, /) -> Interpolator:
    """An interpolator from ``{name: ..., **parameters}``: the
    :data:`~particles.interpolation.INTERPOLATORS` entry's ``build`` of the ``Settings`` made of
    the parameters.

    Raises:
        ValueError: Unknown name (listing the valid ones), an unknown or missing parameter, or a bad value.
    """
    if not isinstance(spec, Mapping):
        return spec
    name, params = _choice(spec)
    return INTERPOLATORS.build(name, INTERPOLATORS.settings(name, **params), InterpolatorContext())


def particles_per_cell_summary(swarm: Swarm, /) -> tuple[int, float, int]:
    """Global (min, mean, max) of the particles per cell over all owned cells (collective)."""
    counts = swarm.particles_per_cell()
    comm = swarm.comm
    lo = comm.allreduce(int(counts.min()) if counts.size else np.iinfo(np.int64).max, op=MPI.MIN)
    hi = comm.allreduce(int(counts.max()) if counts.size else 0, op=MPI.MAX)
    total, cells = comm.allreduce(np.array([counts.sum(), counts.size], dtype=np.int64), op=MPI.SUM)
    return int(lo), float(total) / max(int(cells), 1), int(hi)


def _config_arguments(section: Mapping[str, Any] | ParticleSettings, mesh: dolfinx.mesh.Mesh,
                      directory: str | Path | None, extra_properties: Sequence[ParticleProperty],
                      make_function: MakeFunction | None, output_units: OutputUnits | None = None,
                      name: str = "particles") -> dict[str, Any]:
    """The :class:`ParticleManager` keyword arguments a config section gives (see
    :meth:`ParticleManager.from_config`): generator, integrator, properties, interpolator,
    population, writer and output."""
    settings = particle_settings(section)
    num_cells = mesh.topology.index_map(mesh.topology.dim).size_global
    generator = build_generator(settings.generator, num_cells=num_cells, make_function=make_function)
    properties = [*extra_properties, *build_properties(settings.properties, make_function=make_function)]
    interpolator = build_interpolator(settings.interpolator)
    pop = settings.population
    population = PopulationControl(pop.min_per_cell, pop.max_per_cell, pop.seed, pop.method,
                                   pop.bandwidth) if pop.enabled else None
    out = settings.output
    schedule = OutputSchedule(out.every_steps, out.every_time)
    writer = None
    if schedule.enabled:
        if directory is None:
            raise ValueError("particle output needs an output directory")
        writer = PARTICLE_WRITERS.build(out.format, out, ParticleWriterContext(directory, name, output_units))
    return {"generator": generator, "integrator": settings.integrator, "properties": properties,
            "interpolator": interpolator, "population": population, "writer": writer, "output": schedule}


def _confine_generated(swarm: Swarm, confine: Confine) -> int:
    """Apply ``confine`` to freshly generated positions (collective). Returns the particles lost.

    A generator samples the mesh's cells, and the cells may reach outside the region ``confine``
    keeps particles in (straight-sided shell cells cover part of the inscribed hole, r < r_inner);
    without this the first step would move such particles there, a jump their displacement
    would record. Moved particles are relocated (and migrated, should one change rank); a
    confined point lies in a cell, so none is lost."""
    x = swarm.x
    before = x.copy()
    confine(x)
    moved = swarm.comm.allreduce(int(np.count_nonzero(np.any(x != before, axis=1))), op=MPI.SUM)
    if not moved:
        return 0
    relocate(swarm, sort=False)
    return migrate(swarm, sort=True).global_lost


@contextmanager
def _timed(timings: dict[str, float], phase: str) -> Iterator[None]:
    """Add the wall seconds of the ``with`` block to ``timings[phase]`` (not if it raises)."""
    t0 = time.perf_counter()
    yield
    timings[phase] += time.perf_counter() - t0


def _initialise_new(properties: PropertyManager, swarm: Swarm, rows: npt.NDArray[np.int64]) -> None:
    """Population hook: copy the nearest older particle, then re-evaluate "reinitialise" properties."""
    copy_nearest(swarm, rows)
    for prop in properties.properties:
        if prop.new_particles_policy == "reinitialise":
            prop.initialise(swarm, rows, properties.context)


class _OutputClock:
    """When the particles were last written (step, time) and when they are next due by time."""

    def __init__(self) -> None:
        self.last: tuple[int, float] | None = None
        self.next_time = float("inf")

    def due(self, schedule: OutputSchedule, step: int, t: float, final: bool) -> bool:
        """Whether ``schedule`` asks for output at ``step`` (time ``t``; ``final``: at the end of a
        run, unless this step was written), given a writer."""
        if self.last is not None and self.last[0] == step:
            return False
        if final or self.last is None:
            return final or schedule.enabled
        every = schedule.every_steps
        return bool((every is not None and step % every == 0) or t >= self.next_time * (1.0 - 1e-12))

    def written(self, schedule: OutputSchedule, step: int, t: float) -> None:
        self.last = (step, t)
        self.next_time = schedule.next_time(t)

    def state(self) -> dict[str, Any]:
        return {"last_output": list(self.last) if self.last else None, "next_output_time": self.next_time}

    def restore(self, scalars: Mapping[str, Any]) -> None:
        last = scalars["last_output"]
        self.last = (int(last[0]), float(last[1])) if last else None
        self.next_time = float(scalars["next_output_time"])


class ParticleManager(Stateful):
    """The particles of one run and every component acting on them (see the module docstring).

    Construction is collective: it generates the particles, initialises their properties from
    ``context`` and applies the population bounds.

    Args:
        mesh: The mesh.
        generator: A generator object (see :func:`build_generator` for config mappings).
        integrator: Registered Runge-Kutta integrator name (:data:`particles.advection.INTEGRATORS`).
        properties: Properties every particle carries (objects or registered names).
        interpolator: Particle-to-mesh interpolator for :meth:`track` (default arithmetic cell average).
        field_degree: Degree of the tracked mesh fields (0: DG0 cell values; >= 1: Lagrange, or DG
            for interpolators that need discontinuous targets).
        population: Bounds on the particles per cell, or None.
        writer: Particle output, or None.
        output: When :meth:`update` writes (requires ``writer``).
        context: Fields for the properties' initial values (e.g. the initial temperature).
        confine: ``confine(x)`` moves positions that left the domain back inside (in place,
            shape=(n, gdim)) before they are relocated, e.g. onto a curved boundary a Runge-Kutta
            step crossed; None: such particles are lost (see :class:`particles.advection.Advector`).
        generate_particles: False starts with no particles (e.g. to :meth:`adopt` restored ones).
    """

    def __init__(self, mesh: dolfinx.mesh.Mesh, /, *, generator: Generator, integrator: str = "rk2",
                 properties: Sequence[ParticleProperty | str] = (), interpolator: Interpolator | None = None,
                 field_degree: int = 0, population: PopulationControl | None = None,
                 writer: ParticleWriter | None = None, output: OutputSchedule = OutputSchedule(),
                 context: PropertyContext | None = None, confine: Confine | None = None,
                 generate_particles: bool = True) -> None:
        get_integrator(integrator)  # ValueError listing the valid names
        self.confine = confine
        if output.enabled and writer is None:
            raise ValueError("an output schedule needs a ParticleWriter")
        self.integrator = integrator
        self.population = population
        self.writer = writer
        self.output = output
        self.timings: dict[str, float] = dict.fromkeys(TIMING_PHASES, 0.0)
        self.lost = self.added = self.removed = self.pulled_in = 0
        self._fields = TrackedFields(interpolator or CellAverage(), field_degree, self.timings)
        self._clock = _OutputClock()
        self.swarm = Swarm(mesh)
        self.properties = PropertyManager(self.swarm, properties)
        self._advector = self._new_advector()
        self.generation = GenerationResult(0, 0, 0)
        if generate_particles:
            self.generation = generate(self.swarm, generator)
            if confine is not None:
                self.lost += _confine_generated(self.swarm, confine)
            self.properties.initialise(context if context is not None else PropertyContext())
            self._bound(step=0, salt=0)

    # ------------------------------------------------------------------ construction from a config
    @classmethod
    def from_config(cls, section: Mapping[str, Any] | ParticleSettings, mesh: dolfinx.mesh.Mesh, /, *,
                    directory: str | Path | None = None, extra_properties: Sequence[ParticleProperty] = (),
                    make_function: MakeFunction | None = None, context: PropertyContext | None = None,
                    confine: Confine | None = None, generate_particles: bool = True, field_degree: int = 0,
                    output_units: OutputUnits | None = None, name: str = "particles") -> ParticleManager:
        """One manager from one config section (collective).

        ``section`` is a :class:`~particles.settings.ParticleSettings` or its config section (its
        keys: generator, integrator, interpolator, properties, population, output; missing keys
        take the settings' defaults). Text values of callable parameters (``function``,
        ``source``, ``density``) are turned into functions by ``make_function``.

        ``directory``: where the particle output goes (needed for output); ``extra_properties``:
        properties the caller needs besides the section's (e.g. one composition per material),
        carried first; ``output_units``: the output's conversion to physical units (None: as they
        are); ``name``: the output files' stem; the others as for the class."""
        arguments = _config_arguments(section, mesh, directory, extra_properties, make_function, output_units, name)
        return cls(mesh, **arguments, field_degree=field_degree, context=context,
                   generate_particles=generate_particles, confine=confine)

    # ------------------------------------------------------------------ queries
    @property
    def mesh(self) -> dolfinx.mesh.Mesh:
        return self.swarm.mesh

    @property
    def num_particles(self) -> int:
        """Global particle count (collective)."""
        return self.swarm.global_num_particles()

    def particles_per_cell(self) -> tuple[int, float, int]:
        """Global (min, mean, max) particles per cell (collective)."""
        return particles_per_cell_summary(self.swarm)

    @property
    def columns(self) -> list[str]:
        """Names of the carried properties."""
        return self.properties.names

    @property
    def interpolator(self) -> Interpolator:
        """The particle-to-mesh interpolator of the tracked fields."""
        return self._fields.interpolator

    @property
    def field_degree(self) -> int:
        """Degree of the tracked fields."""
        return self._fields.degree

    # ------------------------------------------------------------------ mesh fields
    def track(self, name: str, /, *, component: int | None = None, label: str | None = None) -> dolfinx.fem.Function:
        """Interpolate property ``name`` into a mesh field, now and after every advance and mesh
        change (collective). Returns the Function (a new one after each :meth:`to_mesh`; ask
        :meth:`field` for the current one).

        Args:
            name: A carried property.
            component: Column of a multi-column property.
            label: Field name (default ``name``, or ``name_<component>``).
        """
        return self._fields.track(self.swarm, name, component, label)

    def field(self, label: str, /) -> dolfinx.fem.Function:
        """The current mesh field ``label`` (see :meth:`track`)."""
        return self._fields.field(label)

    def update_fields(self) -> None:
        """Re-interpolate every tracked field from the particles (collective)."""
        self._fields.update(self.swarm)

    # ------------------------------------------------------------------ time stepping
    def advance(self, u_old: dolfinx.fem.Function, u_new: dolfinx.fem.Function, dt: float, /, *,
                step: int = 0, fields: Mapping[str, dolfinx.fem.Function] | None = None) -> AdvanceReport:
        """Advance the accumulating properties (``plastic_strain``: ``v += dt f(x_p)``, the fields
        at the step's start), advect over one step (positions and ODE properties), apply the
        population bounds and re-interpolate the tracked fields (collective).

        Args:
            u_old: Velocity at the start of the step.
            u_new: Velocity at the end of the step (linear in time in between).
            dt: Step length.
            step: Number of the step being taken (keys the population's random draws).
            fields: The mesh fields the accumulating properties integrate (by name).
        """
        if self.properties.rate_fields:
            self.properties.accumulate(fields or {}, dt)
        stats = self._advector.step(u_old, u_new, dt)
        self.timings["particle_advection"] += stats.evaluation_seconds
        self.timings["particle_sort"] += stats.relocation_seconds
        self.timings["particle_migration"] += stats.communication_seconds
        self.lost += stats.global_lost
        sent, pulled = self.swarm.comm.allreduce(np.array([stats.sent, stats.pulled_in], dtype=np.int64), op=MPI.SUM)
        self.pulled_in += int(pulled)
        population = self._bound(step=step, salt=0)
        self.update_fields()
        return AdvanceReport(int(stats.global_lost), int(sent), population)

    def follow_mesh(self) -> FollowStats:
        """Find every particle again after the mesh's nodes moved
        (:func:`particles.relocation.moving_mesh.follow_mesh`), then re-interpolate the tracked fields (collective)."""
        stats = follow_mesh(self.swarm)
        self.timings["particle_mesh_motion"] += stats.seconds
        self.lost += stats.lost
        self.pulled_in += stats.pulled_in
        self.update_fields()
        return stats

    def update(self, context: PropertyContext, /, *, step: int, final: bool = False) -> OutputRecord | None:
        """Refresh the properties whose policy says so and write the particles when due, or with
        ``final`` unless this step was written (collective). ``context``: fields and time at the end
        of the step just taken; ``step``: the step reached. Returns the output record if written."""
        due = self.writer is not None and self._clock.due(self.output, step, context.time, final)
        with _timed(self.timings, "particle_properties"):
            self.properties.update(context, at_output=due)
        return self.write(context.time, step) if due else None

    def write(self, t: float, step: int, /) -> OutputRecord:
        """Write the particles now (collective; needs a writer)."""
        if self.writer is None:
            raise ValueError("this ParticleManager has no writer")
        with _timed(self.timings, "particle_output"):
            record = self.writer.write(self.swarm, t, step)
            self._clock.written(self.output, step, t)
        return record

    # ------------------------------------------------------------------ checkpoints
    def state(self) -> State:
        """What a checkpoint needs besides the swarm (:mod:`fembase.state`; JSON-able scalars):
        counters, output schedule, timings. The swarm is a checkpoint part of its own
        (:mod:`particles.io.swarm_checkpoint`), given back by :meth:`adopt`."""
        return State(scalars={"lost": self.lost, "added": self.added, "removed": self.removed,
                              "pulled_in": self.pulled_in, **self._clock.state(), "timings": dict(self.timings)})

    def restore(self, scalars: Mapping[str, Any], /) -> dict[str, Any]:
        """Take the saved :meth:`state` scalars back (after :meth:`adopt`); no fields to fill."""
        self.lost, self.added, self.removed = int(scalars["lost"]), int(scalars["added"]), int(scalars["removed"])
        self.pulled_in = int(scalars.get("pulled_in", 0))
        self._clock.restore(scalars)
        self.timings.update(scalars["timings"])
        return {}

    def adopt(self, swarm: Swarm, /, *, context: PropertyContext) -> None:
        """Continue with ``swarm`` (e.g. restored from a checkpoint, with this manager's property
        columns); rebuilds the tracked fields (collective)."""
        self._attach(swarm, context=context)
        self._fields.rebuild(self.swarm, new_space=True)

    # ------------------------------------------------------------------ mesh changes
    def to_mesh(self, mesh: dolfinx.mesh.Mesh, /, *, context: PropertyContext | None = None, step: int = 0,
                candidates: Candidates | None = None, bound: bool = True) -> int:
        """Carry the particles to ``mesh`` (after adaptation or repartitioning), apply the population
        bounds there (``bound``: new cells; a repartition, the same cells, passes False, so it
        changes where particles are, not which) and rebuild the tracked fields (collective).

        Args:
            mesh: The new mesh, covering the same domain.
            context: Fields on the new mesh for properties that new particles evaluate afresh.
            step: The current step number (keys the population's random draws).
            candidates: Cells of ``mesh`` to search first for each particle, in the order of
                ``self.swarm`` (:func:`particles.relocation.new_mesh.move_to_mesh`).

        Returns:
            Particles lost in the move (global; 0 unless the meshes cover different domains).
        """
        with _timed(self.timings, "particle_mesh_change"):
            swarm, stats = move_to_mesh(self.swarm, mesh, candidates=candidates)
        self.lost += stats.lost
        self.pulled_in += stats.pulled_in
        self._attach(swarm, context=context)
        if bound:
            self._bound(step=step, salt=1)
        self._fields.rebuild(self.swarm, new_space=False)
        return int(stats.lost)

    def _attach(self, swarm: Swarm, /, *, context: PropertyContext | None) -> None:
        """Continue with ``swarm``: the properties (with ``context``, if given) and the advector act on it."""
        self.swarm = swarm
        self.properties.attach(swarm)
        if context is not None:
            self.properties.set_context(context)
        self._advector = self._new_advector()

    def _new_advector(self) -> Advector:
        return Advector(self.swarm, integrator=self.integrator, odes=self.properties.odes(), confine=self.confine)

    def _bound(self, *, step: int, salt: int) -> PopulationStats | None:
        """Population bounds; ``salt`` separates the random draws of the calls within one step."""
        if self.population is None:
            return None
        with _timed(self.timings, "particle_population"):
            stats = self.population.apply(self.swarm, step=2 * step + salt,
                                          initialise=partial(_initialise_new, self.properties))
            self.added += stats.global_added
            self.removed += stats.global_removed
        return stats
