"""Parameters are declared once: each component's settings dataclass is the schema of its config
section, so a component built from an empty config section and one built in Python without
arguments have the same settings."""

from __future__ import annotations

import dataclasses

import dolfinx.mesh
import pytest
from mpi4py import MPI

from convection.adapt.adaptivity import Adaptivity, AdaptivitySettings

from convection.adapt.hierarchy import MeshHierarchy
from convection.adapt.rebalance import BalanceSettings, Balancer
from convection.app.factory import build_model
from convection.config.settings import run_settings
from convection.config.loader import SCHEMA, load_config
from convection.io.checkpoint import CheckpointSettings
from convection.model.composition import CompositionSettings
from convection.physics.approximation import PhysicsSettings, ViscosityLaw, ViscositySettings
from convection.physics.materials import Materials
from convection.postprocess.postprocessors import DiagnosticsSettings
from convection.io.fields import OutputSettings
from convection.run.loop import BlowUp, LoopSettings, TimeSettings
from convection.schema import Field, section_schema, settings_as_section, settings_from
from convection.solvers.stokes.nonlinear import NonlinearSettings
from convection.solvers.stokes.solver import StokesSettings, StokesSolver
from convection.solvers.transport import EnergySettings, TransportSolver

SECTIONS = {"stokes": StokesSettings, "energy": EnergySettings, "composition": CompositionSettings,
            "adaptivity": AdaptivitySettings, "balance": BalanceSettings, "blowup": BlowUp,
            "diagnostics": DiagnosticsSettings, "time": TimeSettings, "output": OutputSettings,
            "physics": PhysicsSettings}
"""Every config section a component's settings dataclass declares."""
REQUIRED = {"time": {"end": 0.1}, "output": {"directory": "unused"}, "physics": {"Ra": 1.0e3}}


def _minimal(**sections) -> dict:
    return load_config(None, document={"mesh": {"cells": [4, 4]}, "physics": {"Ra": 1.0e3}, "time": {"end": 0.1},
                                       "output": {"directory": "unused"}, **sections})


@pytest.mark.parametrize("section", sorted(SECTIONS))
def test_the_schema_of_a_section_is_its_settings_dataclass(section):
    cls = SECTIONS[section]
    assert SCHEMA[section] == section_schema(cls)
    fields = {f.name for f in dataclasses.fields(cls)}
    assert set(SCHEMA[section]) == fields
    leaves = [f for f in SCHEMA[section].values() if isinstance(f, Field)]
    assert leaves and all(f.help for f in leaves)


@pytest.mark.parametrize("section", sorted(SECTIONS))
def test_an_empty_section_gives_the_python_defaults(section):
    cls = SECTIONS[section]
    from_config = settings_from(cls, _minimal()[section])
    assert from_config == cls(**REQUIRED.get(section, {}))
    assert settings_as_section(from_config) == _minimal()[section]


def test_the_drifted_defaults_are_one_value():
    """stokes.nonlinear.switch_tolerance and output.checkpoint.every_wall_seconds had other defaults
    in Python than in YAML; the YAML ones (documented, and what every shipped config ran with) won."""
    assert NonlinearSettings().switch_tolerance == 0.1
    assert CheckpointSettings().every_wall_seconds == 3600.0
    config = _minimal()
    assert config["stokes"]["nonlinear"]["switch_tolerance"] == 0.1
    assert config["output"]["checkpoint"]["every_wall_seconds"] == 3600.0


def test_components_built_from_empty_sections_equal_those_built_without_arguments():
    config = _minimal(adaptivity={"enabled": True}, balance={"strategy": "every"})
    model = build_model(config, comm=MPI.COMM_WORLD)
    stokes, temperature = model.stokes, model.temperature
    mesh = model.mesh
    python_stokes = StokesSolver(mesh, stokes.approximation, bcs=stokes.bcs, domain=model.domain)
    assert python_stokes.settings() == stokes.settings()
    python_temperature = TransportSolver(mesh, stokes.approximation, bcs=temperature.bcs, domain=model.domain,
                                         velocity_extrapolation=False)
    assert python_temperature.settings() == temperature.settings()
    assert model.solve_temperature == EnergySettings().enabled
    hierarchy = MeshHierarchy(dolfinx.mesh.create_unit_square(MPI.COMM_WORLD, 2, 2))
    assert model.adaptivity.params == dataclasses.replace(Adaptivity(hierarchy).params, enabled=True)
    assert model.balancer.settings == dataclasses.replace(Balancer(hierarchy).settings, strategy="every")
    settings = run_settings(config).loop
    assert settings == LoopSettings(TimeSettings(end=0.1), OutputSettings(directory="unused"))
    assert settings.output.checkpoint == CheckpointSettings()
    for solver in (python_stokes, python_temperature, stokes, temperature):
        solver.destroy()


def test_the_particles_section_is_declared_once_in_particles():
    """The particles section's keys (all but the front end's ``enabled``) are
    :class:`particles.settings.ParticleSettings`; an empty section gives its Python defaults."""
    from particles.settings import ParticleSettings, particle_settings

    schema = dict(SCHEMA["particles"])
    assert schema.pop("enabled").default is None
    assert schema == section_schema(ParticleSettings)
    section = _minimal()["particles"]
    assert particle_settings(section) == ParticleSettings()
    assert settings_as_section(ParticleSettings()) == {k: v for k, v in section.items() if k != "enabled"}
    assert particle_settings({"population": None, "output": None}) == ParticleSettings()


def test_a_manager_from_an_empty_section_is_the_one_the_config_defaults_give():
    """ParticleManager.from_config({}) used a generator without the YAML's seed 1 (another drift):
    now both place the same particles."""
    from particles.manager import ParticleManager

    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_WORLD, 3, 3)
    empty = ParticleManager.from_config({}, mesh)
    config = ParticleManager.from_config(_minimal()["particles"], mesh)
    assert empty.num_particles == config.num_particles == 20 * 18
    assert (empty.swarm.x == config.swarm.x).all()


def test_the_degree_a_composition_source_needs_is_one_check():
    """composition.source field with degree 0 is refused by the config and by the component, with
    one message (the check lives beside the composition sources)."""
    from convection.config.loader import ConfigError
    from convection.model.composition import COMPOSITION_SOURCES

    with pytest.raises(ConfigError) as from_config:
        _minimal(composition={"source": "field", "degree": 0}, initial={"composition": "y < 0.2"})
    with pytest.raises(ConfigError) as from_python:
        CompositionSettings(source="field", degree=0)
    assert str(from_config.value) == str(from_python.value)
    assert "'composition.degree'" in str(from_python.value)
    assert COMPOSITION_SOURCES["field"].min_degree == 1 and CompositionSettings(source="field", degree=1).degree == 1


def test_the_mesh_section_is_declared_by_the_geometries():
    """``mesh`` is ``geometry``, each geometry's own keys (its ``Settings``), ``max_cells``;
    a geometry's config_keys are its declared keys."""
    from convection.geometry.registry import DOMAINS, MeshSettings, mesh_section_schema

    assert SCHEMA["mesh"] == mesh_section_schema()
    declared = {"geometry", "max_cells"}
    for cls in DOMAINS.values():
        keys = tuple(section_schema(cls.Settings))
        assert cls.config_keys == keys and keys
        assert all(SCHEMA["mesh"][k] == f for k, f in section_schema(cls.Settings).items())
        declared |= set(keys)
    assert set(SCHEMA["mesh"]) == declared
    assert _minimal()["mesh"]["geometry"] == MeshSettings().geometry


def test_the_viscosity_defaults_are_one_declaration():
    """ViscosityLaw and Materials take their defaults from the physics.viscosity section."""
    settings = ViscositySettings()
    law, materials = ViscosityLaw(), Materials()
    assert (law.mixing, law.temperature_law, law.gamma) == (settings.mixing, settings.temperature_law, settings.gamma)
    assert (materials.mixing, materials.background_viscosity) == (settings.mixing, settings.background)


def test_a_material_entry_is_declared_once():
    """``materials.<name>`` is :class:`MaterialSettings`; :class:`Material`'s defaults are its."""
    from convection.physics.materials import Material, MaterialSettings

    assert SCHEMA["materials"].items == section_schema(MaterialSettings)
    material = Material("crust", lambda x: x[0])
    default = MaterialSettings(initial="0")
    assert (material.Rb, material.viscosity) == (default.Rb, default.viscosity)
    config = _minimal(materials={"crust": {"initial": "z > 0.9"}})
    assert config["materials"]["crust"] == settings_as_section(MaterialSettings(initial="z > 0.9"))
