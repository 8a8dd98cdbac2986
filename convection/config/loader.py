"""Run configuration: the YAML schema of a convection run, loading and ``--set`` overrides.

Every config has at least ``mesh.cells`` (or a shell ``mesh.geometry`` with ``mesh.resolution``),
``time.end`` and ``output.directory``. Sections:

- ``mesh``: the domain (``geometry``: box with cells per direction; annulus or spherical shell
  with radii, cell size and geometry degree);
- ``physics``: Ra, Rb, H and the viscosity law;
- ``boundary``: velocity and temperature conditions per side (box: left/right, bottom/top,
  front/back; annulus and spherical shell: inner/outer);
- ``initial``: initial temperature and composition (closed-form expressions, see
  :mod:`convection.expressions`);
- ``materials``: any number of named materials, each with an initial region, a compositional
  Rayleigh number and a viscosity (instead of ``initial.composition``);
- ``phase_transitions``: named phase transitions (depth, Clapeyron slope, width, density jump,
  latent heat, viscosity jump; :mod:`convection.physics.phases`);
- ``composition``: where the material fractions come from (static, field, particles);
- ``particles``: generator, integrator, interpolator, properties, population bounds, output; or a
  list of named particle systems, each with these keys (:mod:`convection.config.particle_systems`);
- ``stokes``, ``energy``: discretisation and solver choices;
- ``time``: end time, CFL number, step limits, steady-state stop;
- ``adaptivity``: refine/coarsen between levels every N steps;
- ``balance``: repartition across ranks with cell weights 1 + W n_particles (none/every/threshold);
- ``diagnostics``: entrainment;
- ``output``: folder, field output interval, statistics columns, progress display.

Names that choose an implementation (solvers, mixing rules, composition sources, partitioners,
postprocessors, particle generators, properties, ...) are checked against the implementation's
registry, and the error lists the registry's names.
"""

from __future__ import annotations

import copy
import importlib
from pathlib import Path
from collections.abc import Callable, Iterable
from typing import Any

import numpy as np
import yaml

from convection.expressions import Expression, ExpressionError
from convection.config.files import read_document, safe_load
from convection.config.sections import (
    InitialSettings, boundary_settings, mesh_section, temperature_condition, velocity_condition,
)
from convection.config.particle_systems import (
    carries_particles, check_primary, listed_systems, override_target, particle_sections, primary_system,
    resolve_systems,
)
from convection.config.units import apply_scaling, in_written_terms, scaling_of, written_quantities
from convection.geometry.boundary import VELOCITY_BC_KINDS
from convection.geometry.domain import Domain, LevelsByRefinement, safe_product
from convection.geometry.probes import boundary_probes, domain_probes
from convection.geometry.registry import DOMAINS, boundary_descriptions, domain_from_settings, mesh_section_schema
from convection.adapt.adaptivity import AdaptivitySettings
from convection.adapt.rebalance import BALANCE_STRATEGIES, BalanceSettings
from convection.deform.surface import FreeSurfaceSettings, check_free_surface
from convection.model.composition import COMPOSITION_SOURCES, CompositionSettings
from convection.postprocess.postprocessors import DiagnosticsSettings, ModelFeatures, check_statistics
from convection.io.fields import OutputSettings
from convection.run.loop import BlowUp, TimeSettings
from convection.schema import (
    MAX_ENTRIES, ConfigError, Field, Names, check_document_shape, key_text, section_schema,
    settings_from, short_repr, validate,
)
from convection.schema import finite_number as _finite_number
from convection.physics.approximation import HEATING_VISCOSITY, TEMPERATURE_LAWS, PhysicsSettings
from convection.physics.compressible import APPROXIMATIONS, ReferenceProfile
from convection.physics.elastic_outputs import check_elastic_outputs
from convection.physics.elasticity import STRESS_CARRIERS, ElasticitySettings, check_elasticity, check_plasticity
from fembase.dolfinx_compat import repartitioned_manifolds_nest
from convection.physics.materials import MaterialSettings
from convection.physics.phases import PhaseTransitionSettings, check_phase_transitions
from convection.physics.scaling import ScalingSettings
from convection.solvers.steady import check_steady_start
from convection.solvers.stokes.solver import (
    STOKES_SOLVER_CHOICES, STOKES_SOLVERS, StokesSettings, check_viscosity_rules, resolve_solver,
)
from convection.solvers.transport import EnergySettings
from particles.settings import ParticleSettings, particle_settings

__all__ = ["SCHEMA", "ConfigError", "config_gdim", "dump_config", "expression_constants", "load_config",
           "parse_overrides"]

MAX_PARTICLES = 1e8
"""Most particles a config may ask for (about 100 bytes each, with properties several GB)."""
MAX_STEPS = 1e9
"""Most time steps ``time.end / time.dt_max`` may imply (without ``time.max_steps``)."""


def _check_velocity_bc(value: Any) -> str | None:
    try:
        velocity_condition(value)
    except ValueError as err:
        return str(err)
    return None


def _check_temperature_bc(value: Any) -> str | None:
    try:
        temperature_condition(value)
    except ValueError as err:
        return str(err)
    return None


def _names(module: str, name: str) -> Names:
    """The names of the registry ``module.name``, imported when a config is checked."""
    return Names(lambda: getattr(importlib.import_module(module), name))



def _is_list(value: Any) -> str | None:
    return None if isinstance(value, list) else f"expected a list, got {short_repr(value)}"


def _sides(check, default, forms: str) -> dict[str, Field]:
    """A field per boundary name of every geometry (:data:`convection.geometry.registry.DOMAINS`);
    a config keeps its own geometry's (:func:`_resolve_boundaries`)."""
    sides: dict[str, Field] = {}
    for name, where in boundary_descriptions().items():
        sides[name] = Field("any", default=default, nullable=True, check=lambda v: None if v is None else check(v),
                            help=f"{where}: {forms}")
    return sides


SCHEMA: dict[str, Any] = {
    "name": Field("str", default="run", help="a label for the run"),
    "scaling": section_schema(ScalingSettings),
    "mesh": mesh_section_schema(),
    "physics": section_schema(PhysicsSettings),
    "boundary": {
        "velocity": _sides(_check_velocity_bc, "free_slip",
                           "free_slip, no_slip, {kind: prescribed, value: [vx, vy(, vz)]} (numbers or expressions) "
                           "or, on a spherical shell's outer surface, {kind: plates, width, plates: [{centre, pole, "
                           "rate}, ...]}"),
        "temperature": _sides(_check_temperature_bc, "insulating", "insulating or {dirichlet: <number>}"),
    },
    "initial": section_schema(InitialSettings),
    "materials": Field("mapping", {}, max_items=MAX_ENTRIES, items=section_schema(MaterialSettings),
                       help="named materials {name: {initial, Rb, viscosity}} filling the domain over a background"),
    "phase_transitions": Field("mapping", {}, max_items=MAX_ENTRIES, items=section_schema(PhaseTransitionSettings),
                               help="named phase transitions {name: {depth, width, temperature, clapeyron, Rb or "
                                    "density_jump, entropy_change, viscosity_jump, materials}} "
                                    "(docs/phase_transitions.md)"),
    "stokes": section_schema(StokesSettings),
    "energy": section_schema(EnergySettings),
    "composition": section_schema(CompositionSettings),
    "particles": {
        "enabled": Field("bool", None, nullable=True,
                         help="carry particles (null: when composition.source is particles; true: also as tracers); "
                              "particles may instead be a list of named systems [{name: ..., generator: ..., ...}], "
                              "each with the keys below but this one, and each carried"),
        **section_schema(ParticleSettings),
    },
    "time": section_schema(TimeSettings),
    "adaptivity": section_schema(AdaptivitySettings),
    "balance": section_schema(BalanceSettings),
    "free_surface": section_schema(FreeSurfaceSettings),
    "blowup": section_schema(BlowUp),
    "diagnostics": section_schema(DiagnosticsSettings),
    "output": section_schema(OutputSettings),
}


def domain_class(config: dict[str, Any]) -> type[Domain]:
    """The geometry class of a config (its ``mesh.geometry``)."""
    return DOMAINS.lookup(config["mesh"].get("geometry", "box"))


def config_domain(config: dict[str, Any]) -> Domain:
    """The domain of a checked config (:func:`convection.geometry.registry.domain_from_settings`)."""
    return domain_from_settings(mesh_section(config["mesh"]))


def config_gdim(config: dict[str, Any]) -> int:
    """Geometric dimension of a resolved config's domain."""
    return domain_class(config).config_gdim(mesh_section(config["mesh"]))


def probe_level(config: dict[str, Any]) -> int:
    """The finest refinement level a run of ``config`` reaches (for the probe points)."""
    adapt = config["adaptivity"]
    return min(adapt["max_level"], 30) if adapt["enabled"] else 0


def _resolve_rayleigh(config: dict[str, Any]) -> None:
    """physics.Ra not given: 0 for a model without the energy equation (a mechanical model needs
    none), else a missing required value."""
    if config["physics"]["Ra"] is None:
        if config["energy"]["enabled"]:
            raise ConfigError("config key 'physics.Ra': required value missing (the thermal Rayleigh number; in a "
                              "model with units it follows from scaling.thermal_expansivity; a model without the "
                              "energy equation, energy.enabled: false, needs none)")
        config["physics"]["Ra"] = 0.0


def _resolve_boundaries(config: dict[str, Any], document: dict[str, Any]) -> None:
    """Keep only the boundary names of the config's geometry (box sides, a shell's inner/outer, a
    sector's inner/outer/west/east); names of other geometries given by the user are errors."""
    cls = domain_class(config)
    given = (document.get("boundary") or {}) if isinstance(document.get("boundary"), dict) else {}
    for section in ("velocity", "temperature"):
        user = given.get(section) or {}
        wrong = [n for n in SCHEMA["boundary"][section] if n not in cls.config_boundaries
                 and isinstance(user, dict) and n in user]
        if wrong:
            raise ConfigError(f"config key 'boundary.{section}.{wrong[0]}': not a boundary of mesh.geometry "
                              f"{cls.name}, which has {list(cls.config_boundaries)}")
        values = config["boundary"][section]
        config["boundary"][section] = {n: values[n] for n in cls.config_boundaries}


def _check_mesh(config: dict[str, Any], document: dict[str, Any]) -> None:
    """The keys of the geometry (another geometry's key given a value other than its default is an
    error: it would be ignored), then the geometry's own checks."""
    cls = domain_class(config)
    mesh = document.get("mesh")
    given = mesh if isinstance(mesh, dict) else {}
    for key, field in SCHEMA["mesh"].items():
        if key in given and key not in (*cls.config_keys, "geometry", "max_cells") \
                and config["mesh"][key] != field.default:
            raise ConfigError(f"config key 'mesh.{key}': not a key of mesh.geometry {cls.name}, which reads "
                              f"{list(cls.config_keys)}")
    adapt, balance = config["adaptivity"]["enabled"], BALANCE_STRATEGIES[config["balance"]["strategy"]].repartitions
    cls.check_config(mesh_section(config["mesh"]),
                     changed_by="adaptivity.enabled" if adapt else "balance.strategy" if balance else None)


AUTO_MULTIGRID_LEVELS = 3
"""``stokes.solver: auto`` picks the multigrid in 3D when the mesh nests in at least this many levels
(16^3 and 20^3 cubes do: 16 -> 8 -> 4 -> 2, 20 -> 10 -> 5; a spherical shell of thickness 1 at gmsh
size 0.125 does: 0.5 -> 0.25 -> 0.125)."""


def free_surface_boundaries(config: dict[str, Any], /) -> tuple[str, ...]:
    """The boundaries of a resolved config whose velocity condition is ``free_surface``."""
    return boundary_settings(config["boundary"]).free_surfaces


def multigrid_levels(config: dict[str, Any], domain: Domain | None = None, *, ranks: int = 1) -> int:
    """The number of nested meshes the Stokes solver of a checked config uses, the run's mesh
    included (:func:`nested_levels`); 1: no multigrid."""
    stokes = config["stokes"]
    fixed = (not config["adaptivity"]["enabled"] and not BALANCE_STRATEGIES[config["balance"]["strategy"]].repartitions
             and not free_surface_boundaries(config))
    return nested_levels(stokes["solver"], stokes["multigrid"]["levels"],
                         domain if domain is not None else config_domain(config), fixed=fixed, ranks=ranks)


def nested_levels(solver: str, wanted: int, domain: Domain, /, *, fixed: bool, ranks: int = 1) -> int:
    """The number of nested meshes a Stokes ``solver`` (``stokes.solver``) uses on ``domain``, the
    run's mesh included, for ``wanted`` levels (``stokes.multigrid.levels``); 1: no multigrid.
    ``fixed``: the mesh neither adapts, nor is repartitioned, nor moves.

    ``stokes.solver: multigrid`` uses the domain's levels for ``stokes.multigrid.levels``.
    ``auto`` picks the multigrid on a fixed 3D mesh that nests in at least
    :data:`AUTO_MULTIGRID_LEVELS` levels (a box whose cells halve; a shell whose gmsh size is at
    most an eighth of its thickness) with a coarsest mesh of at least ``ranks`` cells (every rank
    needs one). On the 3D thick layer to t = 0.002 it ran 2.39 (16^3) and 2.03 (32^3) times as fast
    as ASPECT's GMG (benchmarks/scaling/aspect_thick_layer.md, aspect_thick_layer_32.md); on
    configs/shell_plates.yaml at 112k cells (3 levels) 1.30 times as fast per unit of model time
    as BoomerAMG at equal cells, at 0.53 times its memory, while at 14k cells (2 levels) BoomerAMG
    was 1.17 times as fast (benchmarks/shell/log/2026-12-08_uniform_base.md). Elsewhere ``auto`` is
    what :func:`convection.solvers.stokes.solver.resolve_solver` says."""
    refines = isinstance(domain, LevelsByRefinement)
    if STOKES_SOLVER_CHOICES[solver].nested:
        if refines and not fixed:
            if wanted > 1:
                raise ValueError(f"an adaptive or repartitioned {domain.name} takes its refinement rounds as the "
                                 f"levels (leave it 0)")
            return 1
        return domain.mesh_levels(wanted)
    if STOKES_SOLVER_CHOICES[solver].by_mesh and fixed and domain.gdim == 3:
        levels = domain.mesh_levels(wanted)
        coarsest = domain.estimated_cells() / 8 ** (levels - 1)
        return levels if levels >= AUTO_MULTIGRID_LEVELS and coarsest >= ranks else 1
    return 1


def _check_multigrid(config: dict[str, Any]) -> None:
    """``stokes.solver: multigrid`` needs coarser meshes nested in the run's base mesh (a box whose
    cells halve), a fixed shell fine enough for a coarser gmsh mesh refined (``LevelsByRefinement``)
    or an adaptive mesh (the meshes of its refinement rounds, curved on a shell:
    :mod:`convection.adapt.levels`), repartitioned only if adaptive; ``stokes.multigrid.levels``
    only means something with it (or with ``auto`` where that picks it)."""
    stokes = config["stokes"]
    levels = stokes["multigrid"]["levels"]
    if not STOKES_SOLVER_CHOICES[stokes["solver"]].nested:
        if levels != 0:
            try:
                picked = multigrid_levels(config) > 1
            except ValueError as err:
                raise ConfigError(f"config key 'stokes.multigrid.levels': {err}") from None
            if not picked:
                raise ConfigError("config key 'stokes.multigrid.levels': only with stokes.solver: multigrid (or auto "
                                  "on a fixed 3D box whose cells halve twice or a fixed spherical shell of gmsh size "
                                  "at most 1/8 of its thickness)")
        return
    if BALANCE_STRATEGIES[config["balance"]["strategy"]].repartitions and not config["adaptivity"]["enabled"]:
        raise ConfigError("config key 'balance.strategy': stokes.solver multigrid repartitions adaptive meshes only: "
                          "a repartitioned fixed mesh is nested rank by rank in no coarser mesh (use iterative, or "
                          "balance.strategy: none)")
    domain = config_domain(config)
    try:
        count = multigrid_levels(config, domain)
    except ValueError as err:
        raise ConfigError(f"config key 'stokes.multigrid.levels': {err}") from None
    if BALANCE_STRATEGIES[config["balance"]["strategy"]].repartitions and domain.manifold() is not None \
            and not repartitioned_manifolds_nest():
        raise ConfigError("config key 'balance.strategy': stokes.solver multigrid on a repartitioned curved mesh needs "
                          "DOLFINx 0.5 for now (on 0.9 a node of the repartitioned shell lay in no coarser cell of "
                          "its rank); use balance.strategy: none, or stokes.solver: iterative")
    if count < 2 and not config["adaptivity"]["enabled"] and isinstance(domain, LevelsByRefinement):
        why = ("its free surface moves the mesh" if free_surface_boundaries(config) else
               "mesh.resolution is too coarse: the coarsest level, gmsh's at twice the resolution, needs cells no "
               "larger than the shell's thickness / 2" if config["mesh"].get("geometry_degree", 2) == 2 else
               "mesh.geometry_degree 1: the refined levels are curved")
        raise ConfigError(f"config key 'stokes.solver': multigrid on a fixed mesh.geometry {domain.name} refines a "
                          f"coarser gmsh mesh for its levels, and here cannot: {why}")
    if count < 2 and not config["adaptivity"]["enabled"]:  # adaptive: the refinement rounds are levels
        raise ConfigError(f"config key 'stokes.solver': multigrid needs coarser meshes nested in the mesh (a box whose "
                          f"cells per side are even, e.g. 16, 20, 32, of simplices not graded) or an adaptive mesh, "
                          f"not a fixed mesh.geometry {domain.name} with this mesh")


def _check_schur(config: dict[str, Any]) -> None:
    """``stokes.schur`` other than ``mass`` only with an iterative Stokes solver (``auto``: in 3D)."""
    stokes = config["stokes"]
    solver = STOKES_SOLVERS[resolve_solver(stokes["solver"], config_gdim(config))]
    if stokes["schur"] != "mass" and not solver.iterative:
        raise ConfigError(f"config key 'stokes.schur': {stokes['schur']} only with an iterative stokes.solver "
                          f"(iterative, iterative_gamg, multigrid, or auto in 3D), not {stokes['solver']!r} "
                          f"in {config_gdim(config)}D")


def _check_consistency(config: dict[str, Any], document: dict[str, Any]) -> None:
    _check_mesh(config, document)
    _check_multigrid(config)
    _check_schur(config)
    check_free_surface(settings_from(FreeSurfaceSettings, config["free_surface"]), free_surface_boundaries(config),
                       domain_class(config), multigrid=STOKES_SOLVER_CHOICES[config["stokes"]["solver"]].nested)
    if config["free_surface"]["initial_topography"] is not None:
        _check_initial_topography(config)
    adapt = config["adaptivity"]
    if adapt["min_level"] > adapt["max_level"]:
        raise ConfigError("config key 'adaptivity.min_level': must not exceed adaptivity.max_level")
    cls = domain_class(config)
    if not cls.refinable:
        for key, enabled in (("adaptivity.enabled", adapt["enabled"]),
                             ("balance.strategy", BALANCE_STRATEGIES[config["balance"]["strategy"]].repartitions)):
            if enabled:
                raise ConfigError(f"config key '{key}': runs on mesh.geometry {cls.name} do not adapt or "
                                  "repartition yet")
    check_primary(config)
    _check_materials(config)
    _check_approximation(config)
    cls.check_boundaries(mesh_section(config["mesh"]), boundary_settings(config["boundary"]))
    for name, value in config["initial"]["constants"].items():
        if _finite_number(value) is None:
            raise ConfigError(f"config key 'initial.constants.{key_text(name)}': expected a finite number, "
                              f"got {short_repr(value)}")
    _check_size(config)
    _check_velocity_values(config, config_gdim(config))
    for key in ("temperature", "composition"):
        text = config["initial"][key]
        if text is not None:
            _check_expression(config, f"initial.{key}", text)
    for key in ("min_level_where", "max_level_where"):
        text = adapt[key]
        if text is not None:
            if not adapt["enabled"]:
                raise ConfigError(f"config key 'adaptivity.{key}': only with adaptivity.enabled: true")
            _check_expression(config, f"adaptivity.{key}", text, extra={"t": 0.0})
    carried = _property_names(config) if particles_enabled(config) else ()
    elasticity = settings_from(ElasticitySettings, config["physics"]["elasticity"])
    check_elastic_outputs(elasticity.enabled, carried, config["output"]["extra_fields"],
                          STRESS_CARRIERS[elasticity.stress].on_particles)
    _check_particles(config)
    check_elasticity(elasticity, carried, config["time"]["dt_max"], config["time"]["dt_initial"])  # issue 48
    if laws_given(config):  # visco-elasto-plastic: the yield limits the visco-elastic stress (issue 48)
        check_plasticity(elasticity, _keyed_laws(config))
    if config["initial"]["steady"]:
        _check_steady_start(config)
    _check_statistics(config)
    check_phase_transitions({name: settings_from(PhaseTransitionSettings, spec)
                             for name, spec in config["phase_transitions"].items()},
                            energy=config["energy"]["enabled"], buoyancy_theta=config["stokes"]["buoyancy_theta"],
                            material_names=tuple(m["name"] for m in material_table(config)[0]))


def _check_steady_start(config: dict[str, Any]) -> None:
    """``initial.steady`` only where its equations are the model's
    (:func:`convection.solvers.steady.check_steady_start`)."""
    law0, others = viscosity_laws(config) if laws_given(config) else (None, [])
    depends_on = frozenset().union(*(law.depends_on for law in (law0, *others))) if law0 is not None else (
        frozenset() if TEMPERATURE_LAWS[config["physics"]["viscosity"]["temperature_law"]].factor is None
        else frozenset({"temperature"}))
    check_steady_start(approximation=config["physics"]["approximation"],
                       composition=config["initial"]["composition"] is not None or bool(config["materials"]),
                       particles=particles_enabled(config), energy=config["energy"]["enabled"],
                       free_surface=bool(free_surface_boundaries(config)), box=domain_class(config).axis_aligned,
                       viscosity_depends_on=depends_on, elasticity=config["physics"]["elasticity"]["enabled"],
                       phases=bool(config["phase_transitions"]))


def _check_statistics(config: dict[str, Any]) -> None:
    """Every postprocessor ``output.statistics`` names applies to the model (else it would fail
    at the first step)."""
    table, _ = material_table(config)
    features = ModelFeatures(energy=config["energy"]["enabled"], particles=particles_enabled(config),
                             materials=tuple(m["name"] for m in table),
                             entrainment_material=config["diagnostics"]["entrainment_material"],
                             Ra=config["physics"]["Ra"], points=bool(config["diagnostics"]["points"]),
                             topography_material=config["diagnostics"]["topography_material"],
                             columns=config_domain(config).columns(1, 1) is not None,
                             free_surface=bool(free_surface_boundaries(config)),
                             dissipation=APPROXIMATIONS[config["physics"]["approximation"]].dissipation,
                             elasticity=config["physics"]["elasticity"]["enabled"])
    material = config["diagnostics"]["topography_material"]
    if material is not None and material not in features.materials:
        raise ConfigError(f"config key 'diagnostics.topography_material': {material!r} is not one of the materials "
                          f"{list(features.materials)}")
    gdim = config_gdim(config)
    for name, point in config["diagnostics"]["points"].items():
        if not (isinstance(point, list) and len(point) == gdim and all(_finite_number(c) is not None for c in point)):
            raise ConfigError(f"config key 'diagnostics.points.{key_text(name)}': "
                              f"expected [x, y{', z' if gdim == 3 else ''}] ({gdim} numbers), got {short_repr(point)}")
        if not str(name).isidentifier():
            raise ConfigError(f"config key 'diagnostics.points.{key_text(name)}': a point's name is a column suffix: "
                              "letters, digits and _")
        inside = config_domain(config).contains([[float(c) for c in point]])
        if inside is not None and not inside[0]:
            raise ConfigError(f"config key 'diagnostics.points.{key_text(name)}': {short_repr(point)} is not in the "
                              "domain")
    try:
        check_statistics(config["output"]["statistics"], features)
    except ValueError as err:
        raise ConfigError(f"config key 'output.statistics': {err}") from None


def _check_expression(config: dict[str, Any], key: str, text: str, *, boundary: str | None = None,
                     constants: bool = True, extra: dict[str, float] | None = None) -> Expression:
    """The expression ``text`` of config key ``key``, evaluated at the probe points of the domain
    (or of ``boundary``) of a resolved config (see :mod:`convection.geometry.probes`).

    Raises:
        ConfigError: naming ``key``: the text is not an allowed expression, or it fails or is not
            finite at a probe point.
    """
    try:
        names = {**expression_constants(config), **(extra or {})} if constants else None
        expression = Expression(text, constants=names, gdim=config_gdim(config))
        domain, level = config_domain(config), probe_level(config)
        expression.check(domain_probes(domain, level) if boundary is None else boundary_probes(domain, boundary, level))
    except ExpressionError as err:
        raise ConfigError(f"config key '{key}': {err}") from None
    return expression


def _check_initial_topography(config: dict[str, Any]) -> None:
    """free_surface.initial_topography: finite in the domain, and the surface above the bottom at
    the top's probe points (lower, the mesh would fold: the run refuses it too)."""
    key, text = "free_surface.initial_topography", config["free_surface"]["initial_topography"]
    expression = _check_expression(config, key, text)
    domain, level = config_domain(config), probe_level(config)
    points = boundary_probes(domain, domain.top, level)
    bottom = np.asarray(boundary_probes(domain, domain.bottom, level), dtype=np.float64)
    depth = float(np.max(domain.gravity.depth_at(bottom.T[:, : domain.gdim])))
    lowest = float(np.min(expression(points)))
    if lowest <= -depth:
        raise ConfigError(f"config key '{key}': {text!r} is {lowest:.6g} on the top: the surface must stay above the "
                          f"bottom ({depth:.6g} below the top)")


def _check_velocity_values(config: dict[str, Any], gdim: int) -> None:
    """Prescribed velocities: gdim components, each expression finite on its boundary."""
    for side, bc in config["boundary"]["velocity"].items():
        if not (isinstance(bc, dict) and VELOCITY_BC_KINDS[bc["kind"]].needs_value):
            continue
        if len(bc["value"]) != gdim:
            raise ConfigError(f"config key 'boundary.velocity.{side}.value': needs {gdim} components")
        for i, component in enumerate(bc["value"]):
            if isinstance(component, str):
                # boundary.py builds these without the config's constants
                _check_expression(config, f"boundary.velocity.{side}.value[{i}]", component, boundary=side,
                                 constants=False)


def _check_size(config: dict[str, Any]) -> None:
    """Refuse meshes (and particle counts) that would exhaust the machine, naming the estimate."""
    mesh, adapt = config["mesh"], config["adaptivity"]
    cls = domain_class(config)
    gdim = cls.config_gdim(mesh_section(mesh))
    base = cls.base_cells_bound(mesh_section(mesh))
    level = adapt["max_level"] if adapt["enabled"] else 0
    most = safe_product(base, *[2.0] * min(gdim * level, 2048))
    if most > mesh["max_cells"]:
        key = "adaptivity.max_level" if level else f"mesh.{cls.size_key}"
        raise ConfigError(f"config key '{key}': the mesh can reach {most:.3g} cells ({base:.3g} base cells, refined "
                          f"{level} times), more than mesh.max_cells = {mesh['max_cells']}; raise mesh.max_cells "
                          "if the machine can take it")
    if particles_enabled(config):
        _check_particle_count(config, most)
    end, dt_max = config["time"]["end"], config["time"]["dt_max"]
    if dt_max is not None and config["time"]["max_steps"] is None and end / dt_max > MAX_STEPS:
        raise ConfigError(f"config key 'time.dt_max': time.end / time.dt_max = {end / dt_max:.3g} steps at least "
                          f"(more than {MAX_STEPS:.0e}); raise dt_max or set time.max_steps")


def _check_particle_count(config: dict[str, Any], cells: float) -> None:
    """Refuse generators and population bounds that ask for more than :data:`MAX_PARTICLES` (each,
    and the generators of all systems together)."""
    asked, total = [], 0.0
    for where, section in _system_keys(config).items():
        generator = section["generator"]
        for key in ("particles_per_cell", "num_particles"):
            try:
                number = float(generator.get(key) or 0.0)
            except (TypeError, ValueError, OverflowError):
                continue  # reported by the particle checks
            asked.append((f"{where}.generator.{key}",
                          safe_product(number, cells) if key == "particles_per_cell" else number))
            total += asked[-1][1]
        asked.append((f"{where}.population.min_per_cell", safe_product(section["population"]["min_per_cell"], cells)))
    asked.append(("particles", total))
    for key, count in asked:
        if count > MAX_PARTICLES:
            raise ConfigError(f"config key '{key}': up to {count:.3g} particles on the finest mesh (more than "
                              f"{MAX_PARTICLES:.0e}, several GB)")


def _system_keys(config: dict[str, Any]) -> dict[str, dict[str, Any]]:
    """The particle sections of a resolved config by their config key (``particles``, or
    ``particles.<name>`` for listed systems); the one mapping also when the run carries none."""
    listed = listed_systems(config)
    return {f"particles.{name}" if listed else "particles": section
            for name, section in particle_sections(config, carried=False).items()}


def expression_constants(config: dict[str, Any]) -> dict[str, float]:
    """Constants available in initial-condition expressions: Ra, Rb, H, the domain's, the unit
    constants of a scaled model (:meth:`convection.physics.scaling.Scaling.expression_constants`) and
    initial.constants."""
    physics = config["physics"]
    scaling = scaling_of(config)
    units = scaling.expression_constants() if scaling is not None else {}
    return {"Ra": physics["Ra"], "Rb": physics["Rb"], "H": physics["H"], **config_domain(config).expression_constants(),
            **units, **config["initial"]["constants"]}


RESERVED_FIELD_NAMES = ("temperature", "velocity", "pressure", "material")


def material_table(config: dict[str, Any]) -> tuple[list[dict[str, Any]], float]:
    """The materials of a resolved config and the background viscosity.

    Each material is ``{name, initial, Rb, viscosity}`` (``initial`` an expression text). The
    classic two-material keys (``initial.composition``, ``physics.Rb``,
    ``physics.viscosity.material_viscosities``) give one material named ``composition``.
    """
    physics = config["physics"]
    viscosity = physics["viscosity"]
    if config["materials"]:
        table = [{"name": name, **spec} for name, spec in config["materials"].items()]
        return table, viscosity["background"]
    text = config["initial"]["composition"]
    if text is None:
        return [], viscosity["background"]
    etas = viscosity["material_viscosities"]
    return ([{"name": "composition", "initial": text, "Rb": physics["Rb"], "viscosity": etas[1] if etas else None}],
            etas[0] if etas else viscosity["background"])


def laws_given(config: dict[str, Any]) -> bool:
    """Whether a resolved config gives a viscosity law (``physics.viscosity.law`` or a material's
    ``{name: ...}``) rather than numbers only."""
    table, _ = material_table(config)
    return config["physics"]["viscosity"]["law"] is not None or any(isinstance(m["viscosity"], dict) for m in table)


def viscosity_laws(config: dict[str, Any]) -> tuple[Any, list[Any]]:
    """The rheology laws of a resolved config: ``(background law, [law per material])``. Numbers
    (the classic keys ``physics.viscosity.background``, ``material_viscosities``, a material's
    number) become :class:`convection.physics.rheology.Constant` laws; a material without a
    viscosity takes the background's law.

    Raises:
        ConfigError: a law is wrong (one line naming the key).
    """
    from convection.physics.rheology import build_law

    visc = config["physics"]["viscosity"]
    table, background = material_table(config)
    law0 = build_law(visc["law"] if visc["law"] is not None else background, "physics.viscosity.law")
    keyed = config["materials"] and True
    laws = []
    for m in table:
        key = f"materials.{m['name']}.viscosity" if keyed else "physics.viscosity.material_viscosities"
        laws.append(law0 if m["viscosity"] is None else build_law(m["viscosity"], key))
    return law0, laws


def _keyed_laws(config: dict[str, Any]) -> dict[str, Any]:
    """The background's law and each material's own law by their config keys."""
    law0, laws = viscosity_laws(config)
    table, _ = material_table(config)
    return {"physics.viscosity.law": law0, **{f"materials.{m['name']}.viscosity": law
                                              for m, law in zip(table, laws) if m["viscosity"] is not None}}


def _check_rheology(config: dict[str, Any]) -> None:
    visc = config["physics"]["viscosity"]
    for name, spec in config["materials"].items():
        value = spec["viscosity"]
        if value is not None and not isinstance(value, dict) and (
                isinstance(value, bool) or not isinstance(value, (int, float)) or not value > 0):
            raise ConfigError(f"config key 'materials.{name}.viscosity': expected a positive number or a law "
                              f"{{name: ..., ...}}, got {short_repr(value)}")
    if not laws_given(config):
        return
    laws = viscosity_laws(config)
    if visc["law"] is not None and visc["background"] != 1.0:
        raise ConfigError("config key 'physics.viscosity.background': not with physics.viscosity.law (the law is the "
                          "background's)")
    if TEMPERATURE_LAWS[visc["temperature_law"]].factor is not None:
        raise ConfigError("config key 'physics.viscosity.temperature_law': not with viscosity laws (give the "
                          "temperature dependence in the law, e.g. {name: exponential, gamma_T: ...})")
    law0, others = laws
    stokes = config["stokes"]
    check_viscosity_rules(frozenset().union(*(law.depends_on for law in (law0, *others))),
                          buoyancy_theta=stokes["buoyancy_theta"], method=stokes["nonlinear"]["method"],
                          pressure_level_free=all(v is not None for v in config["boundary"]["velocity"].values()))
    fields = sorted({d.split(":", 1)[1] for law in (law0, *others) for d in law.depends_on if d.startswith("field:")})
    if fields:
        if not particles_enabled(config):
            raise ConfigError(f"config key 'particles.enabled': the viscosity laws read the field {fields[0]!r}, "
                              "a particle property averaged onto the mesh; set particles.enabled: true and carry "
                              f"{fields[0]!r} in particles.properties")
        carried = _property_names(config)
        missing = [name for name in fields if name not in carried]
        if missing:
            raise ConfigError(f"config key 'particles.properties': the viscosity laws read the field {missing[0]!r}, "
                              "which comes from a particle property of that name (e.g. plastic_strain); carry it "
                              f"(particles carry {carried})")


def _check_approximation(config: dict[str, Any]) -> None:
    """``physics.approximation`` and ``physics.reference`` agree, and the model has what the
    approximation needs (:mod:`convection.physics.compressible`)."""
    physics = config["physics"]
    name, Di = physics["approximation"], physics["reference"]["Di"]
    formulation = APPROXIMATIONS[name]
    _check_pressure_buoyancy(config, formulation)
    dissipating = [n for n, f in APPROXIMATIONS.items() if f.dissipation]
    _check_reference_profile(physics["reference"], name if not formulation.dissipation else None, dissipating)
    if not formulation.dissipation:
        if Di != 0.0:
            raise ConfigError(f"config key 'physics.reference.Di': only with physics.approximation "
                              f"{' or '.join(dissipating)} (the {name} approximation has no dissipation number)")
        return
    if Di == 0.0:
        raise ConfigError(f"config key 'physics.reference.Di': physics.approximation {name} needs a dissipation "
                          "number Di > 0")
    if not config["energy"]["enabled"]:
        raise ConfigError(f"config key 'energy.enabled': physics.approximation {name} heats by adiabatic compression "
                          "and shear, so it needs the energy equation")
    if not physics["Ra"] > 0.0:
        raise ConfigError(f"config key 'physics.Ra': physics.approximation {name} needs Ra > 0 (its shear heating "
                          "is Di / Ra Phi)")
    table, _ = material_table(config)
    law0 = viscosity_laws(config)[0] if laws_given(config) else None
    if table or (law0 is not None and not law0.depends_on <= HEATING_VISCOSITY):
        raise ConfigError(f"config key 'physics.approximation': {name}'s shear heating takes a viscosity of "
                          "temperature and depth only for now (no materials, no strain-rate, pressure or field laws)")
    if formulation.reference_density and config["stokes"]["buoyancy_theta"] != 0.0:
        raise ConfigError(f"config key 'stokes.buoyancy_theta': not with physics.approximation {name} (the "
                          "semi-implicit buoyancy has no reference density yet)")


def _check_reference_profile(reference: dict[str, Any], without: str | None, dissipating: list[str]) -> None:
    """``physics.reference.profile`` is a table :class:`ReferenceProfile` takes, and it and the
    potential temperature come with a compressible approximation (``without``: the approximation's
    name when it has no reference state)."""
    profile = reference["profile"]
    try:
        ReferenceProfile(**{k: tuple(v) for k, v in profile.items()})
    except ValueError as err:
        raise ConfigError(f"config key 'physics.reference.profile': {err}") from None
    for key, unset in (("profile", not any(profile.values())), ("potential_temperature",
                                                                reference["potential_temperature"] == 0.0)):
        if without is not None and not unset:
            raise ConfigError(f"config key 'physics.reference.{key}': only with physics.approximation "
                              f"{' or '.join(dissipating)} (the {without} approximation has no adiabat)")


def _check_pressure_buoyancy(config: dict[str, Any], formulation: Any) -> None:
    """``physics.reference.heat_capacity_ratio`` only with the ALA, and the ALA with the direct Stokes
    solver (:class:`convection.solvers.stokes.nullspace.PressureMode`)."""
    ratio = config["physics"]["reference"]["heat_capacity_ratio"]
    if not formulation.pressure_buoyancy:
        if ratio != 1.0:
            raise ConfigError("config key 'physics.reference.heat_capacity_ratio': only with physics.approximation "
                              f"ala (the {formulation.name} approximation has no pressure buoyancy)")
        return
    solver = config["stokes"]["solver"]
    if STOKES_SOLVERS[resolve_solver(solver, config_gdim(config))].iterative:
        raise ConfigError(f"config key 'stokes.solver': physics.approximation {formulation.name} needs the direct "
                          f"solver for now (its pressure's buoyancy changes the pressure null space), got {solver!r}")


def _property_names(config: dict[str, Any]) -> list[str]:
    """Names of the particle properties of a resolved config's primary system (as given: names or
    {name: ...})."""
    names: list[str] = []
    primary = primary_system(config)
    if primary is None:
        return names
    for item in particle_sections(config).get(primary, {}).get("properties", []):
        if isinstance(item, str):
            names.append(item)
        elif isinstance(item, dict) and isinstance(item.get("name"), str):
            names.append(item["name"])
    return names


def _check_materials(config: dict[str, Any]) -> None:
    _check_rheology(config)
    if config["materials"]:
        legacy = (("initial.composition", config["initial"]["composition"] is not None),
                  ("physics.Rb", config["physics"]["Rb"] != 0.0),
                  ("physics.viscosity.material_viscosities",
                   config["physics"]["viscosity"]["material_viscosities"] is not None))
        for key, given in legacy:
            if given:
                raise ConfigError(f"config key '{key}': not with the materials section (give each material its "
                                  "initial region, Rb and viscosity there)")
        for name, spec in config["materials"].items():
            if name in RESERVED_FIELD_NAMES:
                raise ConfigError(f"config key 'materials.{name}': the name is taken by a field; "
                                  f"reserved: {list(RESERVED_FIELD_NAMES)}")
            _check_expression(config, f"materials.{name}.initial", spec["initial"])
    table, _ = material_table(config)
    names = [m["name"] for m in table]
    source = config["composition"]["source"]
    if COMPOSITION_SOURCES[source].needs_materials and not table:
        raise ConfigError(f"config key 'composition.source': {source} needs materials (the materials section or "
                          "initial.composition)")
    settings_from(CompositionSettings, config["composition"])  # its checks (the degree a source needs)
    material = config["diagnostics"]["entrainment_material"]
    if material is not None:
        valid = ["all", *names] + (["dense", "light"] if len(names) == 1 else [])
        if material not in valid:
            raise ConfigError(f"config key 'diagnostics.entrainment_material': {material!r} is not one of {valid}")


def particles_enabled(config: dict[str, Any]) -> bool:
    """Whether a run of ``config`` carries particles (:func:`convection.config.particle_systems.carries_particles`)."""
    return carries_particles(config)


def point_function(config: dict[str, Any], *, probe: bool = False) -> Callable[[str], Callable]:
    """Text -> function of points shape=(m, gdim) (particle properties and densities of a config).

    With ``probe``, each expression is first evaluated at the domain's probe points
    (:mod:`convection.geometry.probes`), and one that fails or is not finite there raises ExpressionError
    (a ValueError, which the particle builders report under the entry's key).
    """
    gdim = config_gdim(config)
    constants = expression_constants(config)

    def make(text: str) -> Callable:
        expression = Expression(text, constants=constants, gdim=gdim)
        if probe:
            expression.check(domain_probes(config_domain(config), probe_level(config)))

        def at(x):
            import numpy as np

            points = np.zeros((3, x.shape[0]))
            points[:gdim] = np.asarray(x).T
            return expression(points)
        return at
    return make


def _check_particles(config: dict[str, Any]) -> None:
    """Every particle system's settings (the one mapping's also when the run carries no particles):
    its plugins made through their registries from their typed ``Settings``, as a run makes them."""
    section = config["particles"]
    carried = COMPOSITION_SOURCES[config["composition"]["source"]].carried_by_particles
    if isinstance(section, dict) and section["enabled"] is False and carried:
        raise ConfigError("config key 'particles.enabled': composition.source: particles needs particles")
    primary = primary_system(config)
    make = point_function(config, probe=True)
    for (name, section), where in zip(particle_sections(config, carried=False).items(), _system_keys(config)):
        feeds = name == primary  # the system whose fields the model reads
        settings = particle_settings(section)
        _check_system_components(config, settings, where, make, feeds=feeds)
        _check_system_properties(config, settings, where, make, feeds=feeds)


def _check_system_components(config: dict[str, Any], settings: ParticleSettings, where: str, make: Callable, *,
                             feeds: bool) -> None:
    """A system's generator and interpolator (``where``: its config key; ``feeds``: the model reads
    its fields, whose degree the interpolator decides)."""
    from particles.interpolation import INTERPOLATORS
    from particles.manager import build_generator, build_interpolator

    try:
        generator = build_generator(settings.generator, num_cells=1, make_function=make, gdim=config_gdim(config))
    except (TypeError, ValueError) as err:
        raise ConfigError(f"config key '{where}.generator': {err}") from None
    density = getattr(generator.settings, "density", None)
    if density is not None:
        _check_generator_density(config, f"{where}.generator.density", settings.generator.get("density"), density)
    if config_domain(config).curved and particles_enabled(config) and generator.affine_cells_only:
        raise ConfigError(f"config key '{where}.generator.name': {generator.name} needs straight-sided cells; the "
                          f"{config['mesh']['geometry']} has curved ones (mesh.geometry_degree 2): use "
                          "metropolis_hastings (with a density, e.g. \"r < r_inner + 0.15\", or none for uniform)")
    name = settings.interpolator.get("name")
    if not isinstance(name, str) or name not in INTERPOLATORS:
        raise ConfigError(f"config key '{where}.interpolator.name': {short_repr(name)} is not one of "
                          f"{sorted(INTERPOLATORS)}")
    try:
        interpolator = build_interpolator(settings.interpolator)
    except (TypeError, ValueError) as err:
        raise ConfigError(f"config key '{where}.interpolator': {err}") from None
    wanted = interpolator.target_degree  # the fields it writes: DG of this degree
    if wanted is not None and feeds and particles_enabled(config) and config["composition"]["degree"] != wanted:
        raise ConfigError(f"config key 'composition.degree': {name} writes DG{wanted} fields; set composition.degree: "
                          f"{wanted} (is {config['composition']['degree']})")


def _check_generator_density(config: dict[str, Any], key: str, text: Any, density: Callable, /) -> None:
    """A generator's density: >= 0 at every probe point of the domain and > 0 at one (the
    generator refuses a negative value, and can place nothing where the density is 0 everywhere)."""
    gdim = config_gdim(config)
    points = np.asarray(domain_probes(config_domain(config), probe_level(config)), dtype=np.float64)[:gdim].T
    values = np.asarray(density(points), dtype=np.float64).reshape(-1)
    worst = int(np.argmin(values))
    if values[worst] < 0.0:
        scaling = scaling_of(config)
        where = points[worst] * (scaling.factor("length") if scaling is not None else 1.0)
        unit = f" {scaling.unit_label('length')}" if scaling is not None else ""
        names = ("x", "z") if gdim == 2 else ("x", "y", "z")
        at = ", ".join(f"{name} = {value + 0.0:.6g}{unit}" for name, value in zip(names, where))
        raise ConfigError(f"config key '{key}': {short_repr(text)} is {values[worst]:.6g} at {at}: a density must "
                          "be >= 0 everywhere")
    if not np.any(values > 0.0):
        raise ConfigError(f"config key '{key}': {short_repr(text)} is 0 everywhere in the domain: no particle could "
                          "be placed")


def _check_system_properties(config: dict[str, Any], settings: ParticleSettings, where: str, make: Callable, *,
                             feeds: bool) -> None:
    """A system's properties (the materials' fractions besides, for the system that carries them),
    population bounds and output properties."""
    from particles.manager import build_properties
    from particles.population.control import PopulationControl

    materials = feeds and COMPOSITION_SOURCES[config["composition"]["source"]].carried_by_particles
    columns = [m["name"] for m in material_table(config)[0]] if materials else []
    built = []
    for i, spec in enumerate(settings.properties):
        try:
            built.append(build_properties([spec], make_function=make)[0])
        except (TypeError, ValueError) as err:
            raise ConfigError(f"config key '{where}.properties[{i}]': {str(err).removeprefix('item 0: ')}") from None
        columns.append(built[-1].column)
    for i, prop in enumerate(built):
        missing = [c for c in prop.requires() if c not in columns]
        if missing:
            raise ConfigError(f"config key '{where}.properties[{i}]': {prop.column!r} needs the particle property "
                              f"{missing[0]!r}; add it to {where}.properties")
    repeated = sorted({c for c in columns if columns.count(c) > 1})
    if repeated:
        raise ConfigError(f"config key '{where}.properties': more than one property (or material) named "
                          f"{repeated[0]!r}; give properties distinct labels")
    pop = settings.population
    try:
        PopulationControl(pop.min_per_cell, pop.max_per_cell, pop.seed, pop.method, pop.bandwidth)
    except ValueError as err:
        raise ConfigError(f"config key '{where}.population': {err}") from None
    for name in settings.output.properties or ():
        if name not in columns:
            raise ConfigError(f"config key '{where}.output.properties': {name!r} is not carried; carried: {columns}")


def parse_overrides(items: Iterable[str]) -> list[tuple[list[str], Any]]:
    """Parse ``--set key.sub=value`` strings into (path, value) with YAML-typed values."""
    parsed = []
    for item in items:
        if "=" not in item:
            raise ConfigError(f"--set {short_repr(item)}: expected key.sub=value")
        key, text = item.split("=", 1)
        path = [p for p in key.strip().split(".") if p]
        if not path:
            raise ConfigError(f"--set {short_repr(item)}: empty key")
        try:
            value = safe_load(text, f"--set {key_text(key.strip())}")
        except yaml.YAMLError:
            value = text
        parsed.append((path, value))
    return parsed


def _apply_override(document: dict[str, Any], path: list[str], value: Any) -> None:
    node, i = document, 0
    while i < len(path) - 1:
        child = node.get(path[i])
        if child is None:
            child = node[path[i]] = {}
        if isinstance(child, list) and i + 2 < len(path):  # listed particle systems: particles.<name or index>.<key>
            child = override_target(child, path[i + 1], path)
            i += 1
        if not isinstance(child, dict):
            raise ConfigError(f"--set {'.'.join(path)}: '{'.'.join(path[:i + 1])}' is not a section")
        node, i = child, i + 1
    node[path[-1]] = value


def load_config(path: str | Path | None, overrides: Iterable[str] = (), *, document: dict | None = None
                ) -> dict[str, Any]:
    """Read, override and validate a run configuration.

    Args:
        path: YAML file (or None when ``document`` is given).
        overrides: ``key.sub=value`` strings applied on top of the file.
        document: An already parsed document to use instead of the file.

    Returns:
        The fully resolved configuration (every key present, defaults filled in).

    Raises:
        ConfigError: with a one-line message naming the key.
    """
    try:
        return _load(path, overrides, document)
    except RecursionError:  # the sizes are bounded; this is the last guard
        raise ConfigError("config: nested too deeply to check") from None
    except MemoryError:
        raise ConfigError("config: too large to check") from None


def _load(path: str | Path | None, overrides: Iterable[str], document: dict | None) -> dict[str, Any]:
    if document is None:
        if path is None:
            raise ConfigError("no configuration file given")
        p = Path(path)
        document = read_document(p)
        document = {} if document is None else document
        if not isinstance(document, dict):
            raise ConfigError(f"config file '{p}': expected a mapping at the top level")
    check_document_shape(document)
    document = copy.deepcopy(document)
    for key_path, value in parse_overrides(overrides):
        _apply_override(document, key_path, value)
    check_document_shape(document)
    written = written_quantities(document)
    document = apply_scaling(document)
    try:
        systems = resolve_systems(document)
        config = validate(SCHEMA, document)
        if systems is not None:
            config["particles"] = systems
        _resolve_rayleigh(config)
        _resolve_boundaries(config, document)
        _check_consistency(config, document)
    except ConfigError as err:  # report a value with a unit as written, not as the solver's number
        raise in_written_terms(err, written, document) from None
    return config


def dump_config(config: dict[str, Any]) -> str:
    """The resolved config as YAML text (written to the output folder as config.yaml)."""
    return yaml.safe_dump(config, sort_keys=False, default_flow_style=None)
