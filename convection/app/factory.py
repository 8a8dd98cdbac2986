"""From a resolved configuration to a model and a run: one builder per YAML section.

=================== ===========================================================================
section             component
=================== ===========================================================================
``mesh``            the domain (:func:`convection.geometry.registry.domain_from_settings`) and its base mesh
``physics``,        :class:`convection.physics.materials.Materials` and the Boussinesq approximation
``materials``
``boundary``        velocity and temperature conditions per side
``stokes``          :class:`convection.solvers.stokes.solver.StokesSolver`
``energy``          :class:`convection.solvers.transport.TransportSolver` for the temperature
``composition``     a :data:`convection.model.composition.COMPOSITION_SOURCES` entry
``particles``       :meth:`particles.manager.ParticleManager.from_config`
``adaptivity``      :class:`convection.adapt.adaptivity.Adaptivity` (and the initial adapted mesh)
``balance``         :class:`convection.adapt.rebalance.Balancer`
``time``,           :class:`convection.run.loop.LoopSettings`
``output``
``diagnostics``,    postprocessors (:func:`convection.postprocess.postprocessors.create_postprocessors`)
``output``
=================== ===========================================================================

:func:`run_config` is what ``python -m convection run`` does. Both take a resolved config and
build its :class:`convection.config.settings.RunSettings` once; every builder here takes those
typed settings.
"""

from __future__ import annotations

import contextlib

import dataclasses
import sys
import time
from pathlib import Path
from collections.abc import Callable
from typing import Any, NamedTuple

import dolfinx.fem
import dolfinx.fem.petsc
import dolfinx.mesh
from mpi4py import MPI

from convection.adapt.adaptivity import INDICATOR_FIELDS, Adaptivity, LevelBounds

from convection.adapt.hierarchy import MeshHierarchy
from convection.adapt.levels import MeshLevels
from convection.geometry.boundary import TemperatureBC, VelocityBC, temperature_dirichlet_bcs
from convection.geometry.domain import Domain, LevelsByRefinement
from convection.deform.motion import FreeSurface
from convection.deform.surface import surface_terms
from convection.io.continuation import initial_temperature
from convection.io.checkpoint import (
    CheckpointError, Checkpointer, SavedRun, fill_functions, restore_mesh, restore_particles, restore_state,
    saved_values,
)
from convection.model.composition import COMPOSITION_SOURCES, CompositionContext, StaticComposition, particle_properties
from convection.io.output_units import output_units
from convection.config.loader import dump_config
from convection.config.settings import RunSettings, run_settings
from convection.geometry.registry import domain_from_settings
from convection.physics.materials import Material, Materials
from convection.physics.compressible import ReferenceState
from convection.model.elastic_fields import ElasticFields
from convection.model.elastic_stress import FieldStress, StressContext
from convection.physics.elasticity import STRESS_CARRIERS, STRESS_PROPERTY, Elasticity, stress_labels
from convection.physics.phases import PhaseTransitions
from convection.model.model import Model
from convection.postprocess.postprocessors import create_postprocessors
from convection.adapt.rebalance import BALANCE_STRATEGIES, Balancer
from convection.run.loop import Resume, RunSummary, run
from convection.io.run_folder import RunFolderLock
from convection.solvers.steady import solve_steady
from convection.solvers.stokes.solver import STOKES_SOLVER_CHOICES, StokesSolver
from convection.solvers.petsc_options import PetscSolver
from convection.solvers.transport import TransportSolver, interpolate_initial
from convection.schema import ConfigError
from fembase.dolfinx_compat import function_space, petsc_vector
from particles.manager import ParticleManager
from particles.systems import ParticleSystems, file_stem
from particles.properties import PropertyContext

__all__ = ["build_model", "build_model_from_settings", "materials_from_settings", "run_config"]


def materials_from_settings(settings: RunSettings, /) -> Materials:
    """The materials of the ``materials`` section (or of the two-material keys)."""
    materials = tuple(Material(m.name, settings.expression(m.initial), Rb=m.Rb, viscosity=m.law)
                      for m in settings.material_table)
    viscosity = settings.physics.viscosity
    return Materials(materials, mixing=viscosity.mixing, background_law=settings.background_law,
                     sharp=tuple(viscosity.sharp or ()))


def _elasticity(settings: RunSettings, /) -> Elasticity | None:
    """The Maxwell visco-elasticity of ``physics.elasticity`` with each material's shear modulus (issue 48)."""
    moduli = [settings.materials[m.name].shear_modulus if m.name in settings.materials else None
              for m in settings.material_table]
    return Elasticity.from_settings(settings.physics.elasticity, moduli)


def _initial_fields(settings: RunSettings, materials: Materials, temperature_bcs: dict[str, TemperatureBC],
                    domain: Domain) -> Callable[[dolfinx.mesh.Mesh], list]:
    """The fields that drive the initial adaptation, set from the initial condition on a mesh."""
    initial_T = settings.expression(settings.initial.temperature)

    def fields_on(mesh: dolfinx.mesh.Mesh) -> list:
        V = function_space(mesh, "Lagrange", settings.energy.degree)
        T = dolfinx.fem.Function(V)
        interpolate_initial(T, initial_T, bounded=settings.initial.temperature_bounded)
        dolfinx.fem.petsc.set_bc(petsc_vector(T), temperature_dirichlet_bcs(V, temperature_bcs, domain))
        T.x.scatter_forward()
        indicator_fields = {
            "temperature": lambda: [T],
            "composition": lambda: list(StaticComposition(mesh, materials, degree=settings.composition.degree)
                                        .fields) if len(materials) else [],
        }
        wanted = settings.adaptivity.fields
        fields = [f for name in INDICATOR_FIELDS if name in wanted for f in indicator_fields[name]()]
        return fields or [T]
    return fields_on


class _Meshes(NamedTuple):
    """The mesh of a run and what changes it: the hierarchy it is refined from (with the domain's
    manifold), adaptivity and balancing; ``exact``: a restored mesh is the saved one; ``coarse``: the
    meshes a mesh of the run is nested in (``stokes.solver: multigrid``), else None."""

    mesh: dolfinx.mesh.Mesh
    hierarchy: MeshHierarchy | None
    manifold: Any
    adaptivity: Adaptivity | None
    balancer: Balancer | None
    exact: bool
    coarse: MeshLevels | None = None


def _meshes(settings: RunSettings, domain: Domain, materials: Materials, temperature_bcs: dict[str, TemperatureBC],
            comm: MPI.Comm, restore: SavedRun | None) -> _Meshes:
    """The run's mesh: the base mesh (adapted to the initial condition), or the checkpoint's."""
    adapt = settings.adaptivity
    exact = True
    levels = settings.multigrid_levels(domain, ranks=comm.size)
    # A fixed shell's multigrid levels: a coarser gmsh shell (the hierarchy's base) refined uniformly.
    refinements = levels - 1 if isinstance(domain, LevelsByRefinement) else 0
    hierarchical = settings.hierarchical or refinements > 0
    # A curved domain's hierarchy refines the straight-sided base and curves what it hands out.
    manifold = domain.manifold() if hierarchical else None
    straight = manifold is not None
    coarse: list[dolfinx.mesh.Mesh] = []  # the boxes below the base, then the base they nest in

    def make_base(owners: Any) -> dolfinx.mesh.Mesh:
        """The base mesh; with multigrid also the meshes nested below it, kept in ``coarse`` (with
        the base: a checkpoint's repartitioned base replaces it, and they do not nest in that)."""
        if refinements:
            return domain.coarsened(refinements).create_mesh(comm, owners=owners, straight=True)
        if levels == 1:
            return domain.create_mesh(comm, owners=owners, straight=straight)
        meshes = domain.create_mesh_levels(comm, levels, owners=owners)
        coarse[:] = meshes
        return meshes[-1]

    if restore is not None:
        restored = restore_mesh(restore, comm, make_base, hierarchical=hierarchical, manifold=manifold)
        mesh, hierarchy, exact = restored.mesh, restored.hierarchy, restored.exact
        if restored.note is not None and comm.rank == 0:
            print(f"note: {restored.note}", file=sys.stderr, flush=True)
    else:
        mesh = make_base(None)
        hierarchy = MeshHierarchy(mesh, manifold=manifold) if hierarchical else None
        if manifold is not None:
            mesh = hierarchy.uniform(refinements)
    adaptivity = None
    if adapt.enabled:
        bounds = None
        if adapt.min_level_where is not None or adapt.max_level_where is not None:
            bounds = LevelBounds(adapt.min_level_where, adapt.max_level_where, constants=dict(settings.constants),
                                 gdim=domain.gdim)
        adaptivity = Adaptivity(hierarchy, adapt, bounds=bounds)
        if restore is None:
            mesh = adaptivity.initial_mesh(_initial_fields(settings, materials, temperature_bcs, domain),
                                           rounds=adapt.initial_steps)
    balancer = Balancer(hierarchy, settings.balance) if BALANCE_STRATEGIES[settings.balance.strategy].repartitions \
        else None
    levels = None
    if coarse:
        levels = MeshLevels(coarse[:-1], coarse[-1], hierarchy)
        if hierarchy is not None:
            hierarchy.keep_levels = True  # a repartition moves the refinement rounds' meshes too
    elif refinements or (adaptivity is not None and STOKES_SOLVER_CHOICES[settings.stokes.solver].nested):
        # No box nests below the base (a shell; a box whose cells do not halve): the levels are
        # the refinement rounds (curved on a shell; a fixed shell's uniform ones, which "auto"
        # makes too where multigrid_levels picks the multigrid).
        assert hierarchy is not None
        levels = MeshLevels((), hierarchy.base, hierarchy)
        hierarchy.keep_levels = True
    return _Meshes(mesh, hierarchy, manifold, adaptivity, balancer, exact, levels)


def _free_surface(settings: RunSettings, domain: Domain, mesh: dolfinx.mesh.Mesh, bcs: dict[str, VelocityBC],
                  restore: SavedRun | None, *, exact: bool) -> FreeSurface | None:
    """The free surfaces (None without): made on the undeformed mesh, then the mesh takes the
    initial topography, or a checkpoint's coordinates, before anything else is built on it."""
    names = tuple(name for name, bc in bcs.items() if bc.spec.moves)
    if not names:
        return None
    surface = FreeSurface(mesh, domain, surface_terms(names, settings.free_surface))
    if restore is not None and exact:
        fill_functions(restore, {f"free_surface/{name}": f
                                 for name, f in surface.restore(restore.components["free_surface"]).items()},
                       exact=True)
        surface.restored()
    elif restore is not None:  # another partition: each node goes where the saved node of its undeformed place went
        try:
            surface.move_nodes_as_saved(saved_values(restore, "free_surface/reference"),
                                        saved_values(restore, "free_surface/coordinates"))
        except ValueError as err:
            raise CheckpointError(f"checkpoint {restore.path}: the free surface's nodes: {err}") from None
    elif settings.free_surface.initial_topography is not None:
        surface.raise_surface(settings.expression(settings.free_surface.initial_topography))
        if surface.quality_min <= 0.0:  # the same on every rank
            raise ConfigError(f"config key 'free_surface.initial_topography': it folds the mesh (a cell turned inside "
                              f"out, quality {surface.quality_min:.3g}): the surface must stay above the box's bottom")
    return surface


def _particles(settings: RunSettings, meshes: _Meshes, domain: Domain, materials: Materials, stokes: StokesSolver,
               temperature: TransportSolver, restore: SavedRun | None, surface: FreeSurface | None
               ) -> ParticleSystems | None:
    """The run's particle systems (None without), generated or the checkpoint's swarms."""
    # The confinement margin follows the curvature of the coarsest cells a hierarchy hands out (its
    # base, curved): it covers every mesh of the run, and a resumed run gets the same margin as the
    # run it continues (the mesh it starts from is refined differently from the first one). A free
    # surface's mesh: its undeformed cells (the deformed ones differ between a run and its resume).
    systems = settings.particle_systems
    if not systems:
        return None
    manifold = meshes.manifold
    confinement_mesh = manifold.curve(meshes.hierarchy.base) if manifold is not None else meshes.mesh
    with surface.undeformed() if surface is not None and confinement_mesh is meshes.mesh else contextlib.nullcontext():
        confine = domain.confinement(confinement_mesh, free=settings.boundary.free_surfaces)
    composition = settings.composition
    primary = settings.primary_system
    context = PropertyContext(u_new=stokes.u, temperature=temperature.T, pressure=stokes.p)
    units = settings.units
    managers = {}
    for name, section in systems.items():  # each system draws from its own seeds: they do not interact
        feeds = COMPOSITION_SOURCES[composition.source].carried_by_particles and name == primary
        extra = particle_properties(materials, domain.gdim) if feeds else []
        managers[name] = ParticleManager.from_config(
            section, meshes.mesh, directory=settings.output.directory, extra_properties=extra,
            make_function=settings.point_function(), field_degree=composition.degree, context=context,
            generate_particles=restore is None, confine=confine, name=file_stem(name),
            output_units=output_units(units) if units is not None else None)
        if restore is not None:
            saved = restore.components["model"]
            restore_particles(restore, managers[name], dataclasses.replace(context, time=saved["time"],
                                                                           dt=saved["dt_previous"]),
                              part=file_stem(name))
    return ParticleSystems(managers, primary=primary)


def _composition(settings: RunSettings, mesh: dolfinx.mesh.Mesh, approximation: Any, materials: Materials,
                 particles: ParticleSystems | None, stabilisation: str) -> Any:
    """Where the material fractions come from (None without materials)."""
    if not len(materials):
        return None
    composition = settings.composition
    context = CompositionContext(mesh, approximation, materials, particles.primary if particles is not None else None,
                                 stabilisation)
    return COMPOSITION_SOURCES.build(composition.source, composition, context)


def build_model(config: dict[str, Any], /, *, comm: MPI.Comm = MPI.COMM_WORLD,
                restore: SavedRun | None = None) -> Model:
    """The model of a resolved configuration (collective): :func:`build_model_from_settings` of
    its :func:`convection.config.settings.run_settings`."""
    return build_model_from_settings(run_settings(config), comm=comm, restore=restore)


def build_model_from_settings(settings: RunSettings, /, *, comm: MPI.Comm = MPI.COMM_WORLD,
                              restore: SavedRun | None = None) -> Model:
    """The model of a run's settings (collective).

    The mesh is adapted to the initial condition first (``adaptivity.initial_steps`` rounds); the
    composition source and the particles are then created on that mesh. With ``restore`` (a
    checkpoint of a run of this config) the mesh, fields, particles and time stepping state are
    the checkpoint's instead.
    """
    PetscSolver.prepare_process()  # before any vector of the run is made
    domain = domain_from_settings(settings.mesh)
    physics = settings.physics
    materials = materials_from_settings(settings)
    visc = physics.viscosity
    reference = ReferenceState.from_settings(physics.reference)
    approximation = materials.approximation(Ra=physics.Ra, H=physics.H, temperature_law=visc.temperature_law,
                                            gamma=visc.gamma, gravity=domain.gravity,
                                            formulation=physics.approximation, reference=reference,
                                            elasticity=_elasticity(settings),
                                            phases=PhaseTransitions.from_settings(
                                                settings.phase_transitions,
                                                surface_temperature=physics.reference.surface_temperature,
                                                material_names=tuple(materials.names)))
    velocity_bcs = settings.boundary.velocity_bcs(domain)
    temperature_bcs = settings.boundary.temperature_bcs(domain)
    meshes = _meshes(settings, domain, materials, temperature_bcs, comm, restore)
    mesh = meshes.mesh
    free_surface = _free_surface(settings, domain, mesh, velocity_bcs, restore, exact=meshes.exact)
    stokes_settings = settings.stokes
    if meshes.coarse is not None:  # "auto" on a box whose cells halve or a fine fixed shell picks the multigrid
        stokes_settings = dataclasses.replace(stokes_settings, solver="multigrid")
    stokes = StokesSolver(mesh, approximation,
                          bcs={n: bc for n, bc in velocity_bcs.items() if not bc.spec.moves}, domain=domain,
                          coarse_meshes=meshes.coarse or (),
                          surface=free_surface.terms if free_surface is not None else None, **vars(stokes_settings))
    energy = settings.energy
    temperature = TransportSolver(mesh, approximation, bcs=temperature_bcs, domain=domain, degree=energy.degree,
                                  stabilisation=energy.stabilisation, velocity_extrapolation=False)
    initial = settings.initial
    temperature.set_initial(settings.expression(initial.temperature), bounded=initial.temperature_bounded)
    if restore is None and initial.from_run is not None:
        continued = dolfinx.fem.Function(temperature.T.function_space)
        initial_temperature(initial.from_run, continued)
        temperature.set_initial(continued)
    if restore is None and initial.steady:
        steady = solve_steady(stokes, temperature)
        if comm.rank == 0:
            print(f"steady start: {steady.pseudo_steps} pseudo-time steps, {steady.contrast_steps} contrast steps, "
                  f"{steady.newton_iterations} Newton iterations", file=sys.stderr, flush=True)
    particles = _particles(settings, meshes, domain, materials, stokes, temperature, restore, free_surface)
    composition = _composition(settings, mesh, approximation, materials, particles, energy.stabilisation)
    on_particles = STRESS_CARRIERS[physics.elasticity.stress].on_particles
    if particles is not None:
        # Particle properties the viscosity laws read (e.g. plastic_strain), averaged onto the mesh
        # with the particles' interpolator after every step.
        for name in approximation.viscosity_law.field_names:
            particles.primary.track(name)
        if stokes.discretisation.elasticity is not None and on_particles:  # the old stress of the forms (issue 48)
            for component, label in enumerate(stress_labels(mesh.geometry.dim)):
                particles.primary.track(STRESS_PROPERTY, component=component, label=label)
    stress = None if stokes.discretisation.elasticity is None or on_particles else FieldStress.build(
        physics.elasticity, StressContext(mesh, approximation, energy.stabilisation))
    model = Model(stokes, temperature=temperature, solve_temperature=energy.enabled, composition=composition,
                  particles=particles, adaptivity=meshes.adaptivity, balancer=meshes.balancer,
                  free_surface=free_surface, elastic_stress=stress)
    model.hierarchy = meshes.hierarchy  # a fixed shell's multigrid levels: neither adaptivity nor balancing has it
    if stokes.discretisation.elasticity is not None:  # the elastic outputs of the field output (issue 48)
        model.rheology.elastic = ElasticFields(settings.output.extra_fields).update
    if restore is not None:
        restore_state(model, restore, exact=meshes.exact)
    return model


def run_config(config: dict[str, Any], /, *, comm: MPI.Comm = MPI.COMM_WORLD,
               should_stop: Callable[[], bool] = lambda: False, model: Model | None = None,
               resume: SavedRun | None = None) -> RunSummary:
    """Build (unless ``model`` is given, built from this config) and run a resolved configuration
    (collective). The run folder is created and locked for the whole run
    (:class:`convection.io.run_folder.RunFolderLock`) before anything is written into it, then
    ``config.yaml`` is written (and each checkpoint keeps the config). With ``resume`` (a
    checkpoint of this run) the run continues from it: statistics, fields and particle series go
    on after its step.

    Raises:
        RunFolderError: The folder is in use by another run, cannot be created, or a file to
            continue is damaged (on every rank).
        RunFailure: The run blew up or a solver failed (on every rank).
    """
    start = time.monotonic()
    settings = run_settings(config)
    directory = Path(settings.output.directory)
    with RunFolderLock(directory, comm):
        if comm.rank == 0:
            (directory / "config.yaml").write_text(dump_config(config))
        comm.barrier()
        if model is None:
            model = build_model_from_settings(settings, comm=comm, restore=resume)
        postprocessors = create_postprocessors(model, settings.output.statistics, start=start,
                                               diagnostics=settings.diagnostics)
        checkpoints = Checkpointer(settings.output.checkpoint, directory, config,
                                   resumed_at=model.timestep if resume is not None else None)
        resumed = Resume.from_state(resume.state["run"]) if resume is not None else None
        return run(model, settings.loop, postprocessors, should_stop=should_stop, start=start,
                   checkpoints=checkpoints, blowup=settings.blowup, resume=resumed)
