"""A checked run configuration as one frozen, typed tree: :class:`RunSettings`.

:func:`run_settings` turns a resolved config (what :func:`convection.config.loader.load_config`
returns) into a :class:`RunSettings` with one field per section, each the section's declared
settings dataclass (the one that declares its keys for the schema), plus the few values resolved
from several sections at once (the dimension, the expressions' constants, the units, the
materials with their viscosity laws, the carried particle systems). Below ``config/``, code
receives these typed settings and never indexes a config mapping by its keys
(``tests/test_settings_tree.py`` checks it).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

import numpy as np

from convection.adapt.adaptivity import AdaptivitySettings
from convection.adapt.rebalance import BALANCE_STRATEGIES, BalanceSettings
from convection.config.loader import (
    config_gdim, expression_constants, material_table, nested_levels, viscosity_laws,
)
from convection.config.particle_systems import particle_sections, primary_system
from convection.config.sections import InitialSettings, boundary_settings, mesh_section
from convection.config.units import scaling_of
from convection.deform.surface import FreeSurfaceSettings
from convection.expressions import Expression
from convection.geometry.boundary import BoundarySettings
from convection.geometry.domain import Domain, MeshSection
from convection.model.composition import CompositionSettings
from convection.physics.approximation import PhysicsSettings
from convection.physics.materials import MaterialSettings
from convection.physics.phases import PhaseTransitionSettings
from convection.physics.scaling import Scaling, ScalingSettings
from convection.postprocess.base import DiagnosticsSettings
from convection.io.fields import OutputSettings
from convection.run.loop import BlowUp, LoopSettings, TimeSettings
from convection.schema import settings_from
from convection.solvers.stokes.solver import StokesSettings
from convection.solvers.transport import EnergySettings
from particles.settings import ParticleSettings, particle_settings

__all__ = ["MaterialEntry", "RunSettings", "run_settings"]


@dataclass(frozen=True)
class MaterialEntry:
    """One material of a run: its name, initial region (an expression text), compositional
    Rayleigh number and viscosity law (:mod:`convection.physics.rheology`)."""

    name: str
    initial: str
    Rb: float
    law: Any


@dataclass(frozen=True)
class RunSettings:
    """A checked run configuration: one field per config section, each its declared settings, and
    the values resolved from several sections (after the sections, in the order of the schema).

    Attributes:
        gdim: The geometric dimension of the domain.
        constants: The names an expression of the config may use (Ra, Rb, H, the domain's, the
            units', ``initial.constants``; :func:`convection.config.loader.expression_constants`).
        units: The model's units (None: a nondimensional model).
        material_table: The materials (the ``materials`` section, or the classic two-material
            keys as one material named ``composition``), each with its viscosity law.
        background_law: The viscosity law of the background material.
        particle_systems: The particle systems the run carries, by name, in order (empty: none).
        primary_system: The system whose fields the model reads (None without particles).
    """

    name: str
    scaling: ScalingSettings
    mesh: MeshSection
    physics: PhysicsSettings
    boundary: BoundarySettings
    initial: InitialSettings
    materials: Mapping[str, MaterialSettings]
    phase_transitions: Mapping[str, PhaseTransitionSettings]
    stokes: StokesSettings
    energy: EnergySettings
    composition: CompositionSettings
    time: TimeSettings
    adaptivity: AdaptivitySettings
    balance: BalanceSettings
    free_surface: FreeSurfaceSettings
    blowup: BlowUp
    diagnostics: DiagnosticsSettings
    output: OutputSettings
    gdim: int
    constants: Mapping[str, float]
    units: Scaling | None
    material_table: tuple[MaterialEntry, ...]
    background_law: Any
    particle_systems: Mapping[str, ParticleSettings]
    primary_system: str | None

    @property
    def loop(self) -> LoopSettings:
        """The settings of the run loop (:func:`convection.run.loop.run`)."""
        return LoopSettings(self.time, self.output, self.units)

    @property
    def hierarchical(self) -> bool:
        """Whether the mesh changes during the run (adapted or repartitioned), so that it is
        refined from a hierarchy."""
        return self.adaptivity.enabled or BALANCE_STRATEGIES[self.balance.strategy].repartitions

    def multigrid_levels(self, domain: Domain, /, *, ranks: int) -> int:
        """The number of nested meshes the Stokes solver uses on ``ranks`` ranks
        (:func:`convection.config.loader.nested_levels`); 1: no multigrid."""
        fixed = not self.hierarchical and not self.boundary.free_surfaces
        return nested_levels(self.stokes.solver, self.stokes.multigrid.levels, domain, fixed=fixed, ranks=ranks)

    def expression(self, text: str, /) -> Expression:
        """The expression ``text`` of this config (its constants, its dimension)."""
        return Expression(text, constants=dict(self.constants), gdim=self.gdim)

    def point_function(self) -> Callable[[str], Callable]:
        """Text -> function of points shape=(m, gdim) (particle properties and densities)."""
        gdim = self.gdim

        def make(text: str) -> Callable:
            expression = self.expression(text)

            def at(x: Any) -> Any:
                points = np.zeros((3, x.shape[0]))
                points[:gdim] = np.asarray(x).T
                return expression(points)
            return at
        return make


def run_settings(config: dict[str, Any], /) -> RunSettings:
    """The :class:`RunSettings` of a resolved configuration (built once, after loading)."""
    table, _ = material_table(config)
    background_law, laws = viscosity_laws(config)
    systems = particle_sections(config)
    sections = {
        "name": config["name"],
        "mesh": mesh_section(config["mesh"]),
        "boundary": boundary_settings(config["boundary"]),
        "materials": MappingProxyType({name: settings_from(MaterialSettings, spec)
                                       for name, spec in config["materials"].items()}),
        "phase_transitions": MappingProxyType({name: settings_from(PhaseTransitionSettings, spec)
                                               for name, spec in config["phase_transitions"].items()}),
        **{key: settings_from(cls, config[key]) for key, cls in _SECTIONS.items()},
    }
    return RunSettings(
        **sections, gdim=config_gdim(config), constants=MappingProxyType(expression_constants(config)),
        units=scaling_of(config), material_table=tuple(
            MaterialEntry(m["name"], m["initial"], m["Rb"], law) for m, law in zip(table, laws)),
        background_law=background_law,
        particle_systems=MappingProxyType({name: particle_settings(section) for name, section in systems.items()}),
        primary_system=primary_system(config))


_SECTIONS: dict[str, type] = {
    "scaling": ScalingSettings, "physics": PhysicsSettings, "initial": InitialSettings, "stokes": StokesSettings,
    "energy": EnergySettings, "composition": CompositionSettings, "time": TimeSettings,
    "adaptivity": AdaptivitySettings, "balance": BalanceSettings, "free_surface": FreeSurfaceSettings,
    "blowup": BlowUp, "diagnostics": DiagnosticsSettings, "output": OutputSettings,
}
"""The sections that are one settings dataclass each (the others need their own building)."""
