"""From a resolved configuration to a model and a run: one builder per YAML section.

=================== ===========================================================================
section             component
=================== ===========================================================================
``mesh``            the domain (:func:`convection.geometry.registry.domain_from_config`) and its base mesh
``physics``,        :class:`convection.physics.materials.Materials` and the Boussinesq approximation
``materials``
``boundary``        velocity and temperature conditions per side
``stokes``          :class:`convection.solvers.stokes.solver.StokesSolver`
``energy``          :class:`convection.solvers.transport.TransportSolver` for the temperature
``composition``     a :data:`convection.model.composition.COMPOSITION_SOURCES` entry
``particles``       :meth:`particles.manager.ParticleManager.from_config`
``adaptivity``      :class:`convection.adapt.adaptivity.Adaptivity` (and the initial adapted mesh)
``balance``         :class:`convection.adapt.rebalance.Balancer`
``time``,           :class:`convection.run.loop.RunSettings`
``output``
``diagnostics``,    postprocessors (:func:`convection.postprocess.postprocessors.create_postprocessors`)
``output``
=================== ===========================================================================

:func:`run_config` is what ``python -m convection run`` does.
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

from convection.adapt.adaptivity import INDICATOR_FIELDS, Adaptivity, AdaptivitySettings, LevelBounds

from convection.adapt.hierarchy import MeshHierarchy
from convection.adapt.levels import MeshLevels
from convection.geometry.boundary import VELOCITY_BC_KINDS, TemperatureBC, VelocityBC, temperature_dirichlet_bcs
from convection.geometry.domain import Domain
from convection.deform.motion import FreeSurface
from convection.deform.surface import FreeSurfaceSettings, free_surface_boundaries, surface_terms
from convection.io.continuation import initial_temperature
from convection.io.checkpoint import (
    CheckpointError, Checkpointer, SavedRun, fill_functions, restore_mesh, restore_particles, restore_state,
    saved_values,
)
from convection.model.composition import (
    COMPOSITION_SOURCES, CompositionContext, CompositionSettings, StaticComposition, particle_properties,
)
from convection.config.particle_systems import particle_sections, primary_system
from convection.config.units import scaling_of
from convection.io.output_units import output_units
from convection.config.loader import (
    config_gdim, dump_config, expression_constants, material_table, multigrid_levels, point_function,
    viscosity_laws,
)
from convection.geometry.registry import domain_from_config
from convection.expressions import Expression
from convection.physics.materials import Material, Materials
from convection.model.model import Model
from convection.postprocess.postprocessors import DiagnosticsSettings, create_postprocessors
from convection.adapt.rebalance import BALANCE_STRATEGIES, BalanceSettings, Balancer
from convection.run.loop import BlowUp, OutputSettings, Resume, RunSettings, RunSummary, TimeSettings, run
from convection.io.run_folder import RunFolderLock
from convection.solvers.stokes.solver import STOKES_SOLVER_CHOICES, StokesSettings, StokesSolver
from convection.solvers.petsc_options import PetscSolver
from convection.solvers.transport import EnergySettings, TransportSolver, interpolate_initial
from convection.schema import ConfigError, settings_from
from fembase.dolfinx_compat import function_space, petsc_vector
from particles.manager import ParticleManager
from particles.systems import ParticleSystems, file_stem
from particles.properties import PropertyContext

__all__ = ["build_model", "materials_from_config", "run_config", "run_settings", "temperature_bcs_from_config",
           "velocity_bcs_from_config"]


def velocity_bcs_from_config(section: dict, domain: Domain) -> dict[str, VelocityBC]:
    """Velocity conditions per boundary of ``domain`` from the ``boundary.velocity`` section (null:
    traction free)."""
    result = {}
    for side in domain.boundaries:
        value = section[side]
        if value is None:
            continue
        kind = value["kind"] if isinstance(value, dict) else value
        result[side] = VELOCITY_BC_KINDS[kind].from_config(value, domain.gdim)
    return result


def temperature_bcs_from_config(section: dict, domain: Domain) -> dict[str, TemperatureBC]:
    """Temperature conditions per boundary of ``domain`` from the ``boundary.temperature`` section."""
    result = {}
    for side in domain.boundaries:
        value = section[side]
        if value is None or value == "insulating":
            result[side] = TemperatureBC("insulating")
        else:
            result[side] = TemperatureBC("dirichlet", float(value["dirichlet"]))
    return result


def materials_from_config(config: dict[str, Any]) -> Materials:
    """The materials of the ``materials`` section (or of the two-material keys)."""
    gdim = config_gdim(config)
    constants = expression_constants(config)
    table, _ = material_table(config)
    background_law, laws = viscosity_laws(config)
    materials = tuple(Material(m["name"], Expression(m["initial"], constants=constants, gdim=gdim), Rb=m["Rb"],
                               viscosity=law) for m, law in zip(table, laws))
    return Materials(materials, mixing=config["physics"]["viscosity"]["mixing"], background_law=background_law,
                     sharp=tuple(config["physics"]["viscosity"]["sharp"] or ()))


def run_settings(config: dict[str, Any]) -> RunSettings:
    """The ``time`` and ``output`` sections, and the model's units (the ``scaling`` section)."""
    return RunSettings(settings_from(TimeSettings, config["time"]), settings_from(OutputSettings, config["output"]),
                       scaling_of(config))


def _initial_fields(config: dict[str, Any], materials: Materials, temperature_bcs: dict[str, TemperatureBC],
                    domain: Domain) -> Callable[[dolfinx.mesh.Mesh], list]:
    """The fields that drive the initial adaptation, set from the initial condition on a mesh."""
    acfg = config["adaptivity"]
    gdim = config_gdim(config)
    initial_T = Expression(config["initial"]["temperature"], constants=expression_constants(config), gdim=gdim)

    def fields_on(mesh: dolfinx.mesh.Mesh) -> list:
        V = function_space(mesh, "Lagrange", config["energy"]["degree"])
        T = dolfinx.fem.Function(V)
        interpolate_initial(T, initial_T, bounded=config["initial"]["temperature_bounded"])
        dolfinx.fem.petsc.set_bc(petsc_vector(T), temperature_dirichlet_bcs(V, temperature_bcs, domain))
        T.x.scatter_forward()
        indicator_fields = {
            "temperature": lambda: [T],
            "composition": lambda: list(StaticComposition(mesh, materials, degree=config["composition"]["degree"])
                                        .fields) if len(materials) else [],
        }
        fields = [f for name in INDICATOR_FIELDS if name in acfg["fields"] for f in indicator_fields[name]()]
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


def _meshes(config: dict[str, Any], domain: Domain, materials: Materials, temperature_bcs: dict[str, TemperatureBC],
            comm: MPI.Comm, restore: SavedRun | None) -> _Meshes:
    """The run's mesh: the base mesh (adapted to the initial condition), or the checkpoint's."""
    acfg, bcfg = config["adaptivity"], config["balance"]
    hierarchical = acfg["enabled"] or BALANCE_STRATEGIES[bcfg["strategy"]].repartitions
    # A curved domain's hierarchy refines the straight-sided base and curves what it hands out.
    manifold = domain.manifold() if hierarchical else None
    straight = manifold is not None
    exact = True
    levels = multigrid_levels(config, domain, ranks=comm.size)
    coarse: list[dolfinx.mesh.Mesh] = []  # the boxes below the base, then the base they nest in

    def make_base(owners: Any) -> dolfinx.mesh.Mesh:
        """The base mesh; with multigrid also the meshes nested below it, kept in ``coarse`` (with
        the base: a checkpoint's repartitioned base replaces it, and they do not nest in that)."""
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
            mesh = hierarchy.uniform(0)
    adaptivity = None
    if acfg["enabled"]:
        bounds = None
        if acfg["min_level_where"] is not None or acfg["max_level_where"] is not None:
            bounds = LevelBounds(acfg["min_level_where"], acfg["max_level_where"],
                                 constants=expression_constants(config), gdim=domain.gdim)
        adaptivity = Adaptivity(hierarchy, settings_from(AdaptivitySettings, acfg), bounds=bounds)
        if restore is None:
            mesh = adaptivity.initial_mesh(_initial_fields(config, materials, temperature_bcs, domain),
                                           rounds=acfg["initial_steps"])
    repartitions = BALANCE_STRATEGIES[bcfg["strategy"]].repartitions
    balancer = Balancer(hierarchy, settings_from(BalanceSettings, bcfg)) if repartitions else None
    levels = None
    if coarse:
        levels = MeshLevels(coarse[:-1], coarse[-1], hierarchy)
        if hierarchy is not None:
            hierarchy.keep_levels = True  # a repartition moves the refinement rounds' meshes too
    elif adaptivity is not None and STOKES_SOLVER_CHOICES[config["stokes"]["solver"]].nested:
        # No box nests below the base (a shell; a box whose cells do not halve): the levels are
        # the refinement rounds (curved on a shell).
        levels = MeshLevels((), hierarchy.base, hierarchy)
        hierarchy.keep_levels = True
    return _Meshes(mesh, hierarchy, manifold, adaptivity, balancer, exact, levels)


def _free_surface(config: dict[str, Any], domain: Domain, mesh: dolfinx.mesh.Mesh, bcs: dict[str, VelocityBC],
                  restore: SavedRun | None, *, exact: bool) -> FreeSurface | None:
    """The free surfaces (None without): made on the undeformed mesh, then the mesh takes the
    initial topography, or a checkpoint's coordinates, before anything else is built on it."""
    names = tuple(name for name, bc in bcs.items() if bc.spec.moves)
    if not names:
        return None
    settings = settings_from(FreeSurfaceSettings, config["free_surface"])
    surface = FreeSurface(mesh, domain, surface_terms(names, settings))
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
    elif settings.initial_topography is not None:
        surface.raise_surface(Expression(settings.initial_topography, constants=expression_constants(config),
                                         gdim=domain.gdim))
        if surface.quality_min <= 0.0:  # the same on every rank
            raise ConfigError(f"config key 'free_surface.initial_topography': it folds the mesh (a cell turned inside "
                              f"out, quality {surface.quality_min:.3g}): the surface must stay above the box's bottom")
    return surface


def _particles(config: dict[str, Any], meshes: _Meshes, domain: Domain, materials: Materials, stokes: StokesSolver,
               temperature: TransportSolver, restore: SavedRun | None, surface: FreeSurface | None
               ) -> ParticleSystems | None:
    """The run's particle systems (None without), generated or the checkpoint's swarms."""
    # The confinement margin follows the curvature of the coarsest cells a hierarchy hands out (its
    # base, curved): it covers every mesh of the run, and a resumed run gets the same margin as the
    # run it continues (the mesh it starts from is refined differently from the first one). A free
    # surface's mesh: its undeformed cells (the deformed ones differ between a run and its resume).
    sections = particle_sections(config)
    if not sections:
        return None
    manifold = meshes.manifold
    confinement_mesh = manifold.curve(meshes.hierarchy.base) if manifold is not None else meshes.mesh
    with surface.undeformed() if surface is not None and confinement_mesh is meshes.mesh else contextlib.nullcontext():
        confine = domain.confinement(confinement_mesh, free=free_surface_boundaries(config))
    ccfg = config["composition"]
    primary = primary_system(config)
    context = PropertyContext(u_new=stokes.u, temperature=temperature.T, pressure=stokes.p)
    scaling = scaling_of(config)
    systems = {}
    for name, section in sections.items():  # each system draws from its own seeds: they do not interact
        feeds = COMPOSITION_SOURCES[ccfg["source"]].carried_by_particles and name == primary
        extra = particle_properties(materials, domain.gdim) if feeds else []
        systems[name] = ParticleManager.from_config(
            section, meshes.mesh, directory=config["output"]["directory"], extra_properties=extra,
            make_function=point_function(config), field_degree=ccfg["degree"], context=context,
            generate_particles=restore is None, confine=confine, name=file_stem(name),
            output_units=output_units(scaling) if scaling is not None else None)
        if restore is not None:
            saved = restore.components["model"]
            restore_particles(restore, systems[name], dataclasses.replace(context, time=saved["time"],
                                                                          dt=saved["dt_previous"]),
                              part=file_stem(name))
    return ParticleSystems(systems, primary=primary)


def _composition(config: dict[str, Any], mesh: dolfinx.mesh.Mesh, approximation: Any, materials: Materials,
                 particles: ParticleSystems | None, stabilisation: str) -> Any:
    """Where the material fractions come from (None without materials)."""
    if not len(materials):
        return None
    composition = settings_from(CompositionSettings, config["composition"])
    context = CompositionContext(mesh, approximation, materials, particles.primary if particles is not None else None,
                                 stabilisation)
    return COMPOSITION_SOURCES.build(composition.source, composition, context)


def build_model(config: dict[str, Any], /, *, comm: MPI.Comm = MPI.COMM_WORLD,
                restore: SavedRun | None = None) -> Model:
    """The model of a resolved configuration (collective).

    The mesh is adapted to the initial condition first (``adaptivity.initial_steps`` rounds); the
    composition source and the particles are then created on that mesh. With ``restore`` (a
    checkpoint of a run of this config) the mesh, fields, particles and time stepping state are
    the checkpoint's instead.
    """
    PetscSolver.prepare_process()  # before any vector of the run is made
    domain = domain_from_config(config)
    physics = config["physics"]
    materials = materials_from_config(config)
    visc = physics["viscosity"]
    approximation = materials.approximation(Ra=physics["Ra"], H=physics["H"], temperature_law=visc["temperature_law"],
                                            gamma=visc["gamma"], gravity=domain.gravity)
    velocity_bcs = velocity_bcs_from_config(config["boundary"]["velocity"], domain)
    temperature_bcs = temperature_bcs_from_config(config["boundary"]["temperature"], domain)
    meshes = _meshes(config, domain, materials, temperature_bcs, comm, restore)
    mesh = meshes.mesh
    free_surface = _free_surface(config, domain, mesh, velocity_bcs, restore, exact=meshes.exact)
    stokes_settings = settings_from(StokesSettings, config["stokes"])
    if meshes.coarse is not None:  # "auto" on a box whose cells halve picks the multigrid (multigrid_levels)
        stokes_settings = dataclasses.replace(stokes_settings, solver="multigrid")
    stokes = StokesSolver(mesh, approximation,
                          bcs={n: bc for n, bc in velocity_bcs.items() if not bc.spec.moves}, domain=domain,
                          coarse_meshes=meshes.coarse or (),
                          surface=free_surface.terms if free_surface is not None else None, **vars(stokes_settings))
    energy = settings_from(EnergySettings, config["energy"])
    temperature = TransportSolver(mesh, approximation, bcs=temperature_bcs, domain=domain, degree=energy.degree,
                                  stabilisation=energy.stabilisation, velocity_extrapolation=False)
    temperature.set_initial(Expression(config["initial"]["temperature"], constants=expression_constants(config),
                                       gdim=domain.gdim), bounded=config["initial"]["temperature_bounded"])
    if restore is None and config["initial"]["from_run"] is not None:
        continued = dolfinx.fem.Function(temperature.T.function_space)
        initial_temperature(config["initial"]["from_run"], continued)
        temperature.set_initial(continued)
    particles = _particles(config, meshes, domain, materials, stokes, temperature, restore, free_surface)
    composition = _composition(config, mesh, approximation, materials, particles, energy.stabilisation)
    if particles is not None:
        # Particle properties the viscosity laws read (e.g. plastic_strain), averaged onto the mesh
        # with the particles' interpolator after every step.
        for name in approximation.viscosity_law.field_names:
            particles.primary.track(name)
    model = Model(stokes, temperature=temperature, solve_temperature=energy.enabled, composition=composition,
                  particles=particles, adaptivity=meshes.adaptivity, balancer=meshes.balancer,
                  free_surface=free_surface)
    if restore is not None:
        restore_state(model, restore, exact=meshes.exact)
    return model


def run_config(config: dict[str, Any], /, *, comm: MPI.Comm = MPI.COMM_WORLD,
               should_stop: Callable[[], bool] = lambda: False, model: Model | None = None,
               resume: SavedRun | None = None) -> RunSummary:
    """Build (unless ``model`` is given, built from this config) and run a resolved configuration
    (collective). The run folder is created and locked for the whole run
    (:class:`convection.io.run_folder.RunFolderLock`) before anything is written into it, then
    ``config.yaml`` is written. With ``resume`` (a checkpoint of this run) the run continues from
    it: statistics, fields and particle series go on after its step.

    Raises:
        RunFolderError: The folder is in use by another run, cannot be created, or a file to
            continue is damaged (on every rank).
        RunFailure: The run blew up or a solver failed (on every rank).
    """
    start = time.monotonic()
    directory = Path(config["output"]["directory"])
    with RunFolderLock(directory, comm):
        if comm.rank == 0:
            (directory / "config.yaml").write_text(dump_config(config))
        comm.barrier()
        if model is None:
            model = build_model(config, comm=comm, restore=resume)
        settings = run_settings(config)
        postprocessors = create_postprocessors(model, settings.output.statistics, start=start,
                                               diagnostics=settings_from(DiagnosticsSettings, config["diagnostics"]))
        checkpoints = Checkpointer(settings.output.checkpoint, directory, config,
                                   resumed_at=model.timestep if resume is not None else None)
        resumed = Resume.from_state(resume.state["run"]) if resume is not None else None
        return run(model, settings, postprocessors, should_stop=should_stop, start=start,
                   checkpoints=checkpoints, blowup=settings_from(BlowUp, config["blowup"]), resume=resumed)
