"""Composition sources: where the material fields that buoyancy and viscosity need come from.

One source per model, chosen by name from :data:`COMPOSITION_SOURCES`:

- ``static``: each material's fraction interpolated from its initial region, then kept fixed
  (carried to every new mesh by interpolation);
- ``field``: each fraction is a continuous P(k) field advected with the flow by the SUPG/BDF2
  transport solver with zero diffusivity and no heating (:class:`convection.solvers.transport.TransportSolver`);
- ``particles``: each fraction is a particle property (set from the initial region at creation)
  averaged per cell by the particle manager's interpolator (:class:`particles.manager.ParticleManager`).

A source has ``fields`` (one Function per material, on the current mesh), ``advance(u, dt)`` for
one time step with the advecting velocity ``u`` (already extrapolated to the step's end), and
``to_mesh(mesh, transfer)`` for a change of mesh. All methods are collective.
"""

from __future__ import annotations

from dataclasses import dataclass
from collections.abc import Callable, Mapping
from typing import Any, ClassVar, NamedTuple, Protocol

import numpy as np

import dolfinx.fem
import dolfinx.mesh

from convection.physics.approximation import BoussinesqApproximation
from convection.physics.materials import Materials
from convection.schema import MAX_DEGREE, ConfigError, Names, param
from convection.solvers.transport import TransportSolver
from fembase.dolfinx_compat import function_space
from fembase.registry import Registry
from fembase.state import State, Stateful
from particles.manager import ParticleManager
from particles.properties import InitialComposition

__all__ = ["COMPOSITION_SOURCES", "CompositionContext", "CompositionSettings", "CompositionSource", "FieldComposition",
           "ParticleComposition", "StaticComposition", "Transfer", "TransportedFields", "composition_space",
           "particle_properties"]

Transfer = Callable[[dolfinx.fem.Function, dolfinx.fem.Function], None]
"""``transfer(source_on_old_mesh, target_on_new_mesh)`` fills the target (collective)."""


class CompositionContext(NamedTuple):
    """What a composition source is made from, beside its settings (each takes what it needs).

    Attributes:
        mesh: The model's mesh.
        approximation: The physics (advected fields use its transport).
        materials: The materials whose fractions the source gives.
        particles: The particles (None without).
        stabilisation: The advection's stabilisation (``energy.stabilisation``).
    """

    mesh: dolfinx.mesh.Mesh
    approximation: BoussinesqApproximation
    materials: Materials
    particles: ParticleManager | None
    stabilisation: str


def check_degree(source: str, degree: int, /) -> None:
    """Raise :class:`ConfigError` (naming ``composition.degree``) if the composition source
    ``source`` cannot use fields of ``degree`` (its ``min_degree``: an advected field needs >= 1)."""
    need = COMPOSITION_SOURCES.lookup(source).min_degree
    if degree < need:
        raise ConfigError(f"config key 'composition.degree': the composition source {source!r} needs degree >= {need}, "
                          f"got {degree}")


@dataclass(frozen=True)
class CompositionSettings:
    """The ``composition`` config section: where the material fractions come from."""

    source: str = param("static", choices=Names(lambda: COMPOSITION_SOURCES),
                        help="static: fractions fixed at their initial regions; particles: averaged from advected "
                             "particles; field: advected continuous fields (SUPG, no diffusion)")
    degree: int = param(0, minimum=0, maximum=MAX_DEGREE,
                        help="0: DG0 cell values; >= 1: Lagrange (DG1 for least_squares, DG2 for "
                             "quadratic_least_squares); source field needs >= 1")
    particle_system: str | None = param(None,
                                        help="with several particle systems: the one whose particles carry the "
                                             "material fractions and the fields the viscosity laws read (null: the "
                                             "first)")

    def __post_init__(self) -> None:
        check_degree(self.source, self.degree)


class CompositionSource(Stateful, Protocol):
    """Gives the material fields; see the module docstring."""

    name: ClassVar[str]
    description: ClassVar[str]
    Settings: ClassVar[type]
    min_degree: ClassVar[int]
    needs_materials: ClassVar[bool]
    """A config with this source must name materials (the static source makes none without)."""
    carried_by_particles: ClassVar[bool]
    """The fractions come from particles: the primary particle system carries the materials."""
    materials: Materials

    @property
    def fields(self) -> tuple[dolfinx.fem.Function, ...]: ...

    def advance(self, u: dolfinx.fem.Function, dt: float, /) -> None: ...

    @classmethod
    def build(cls, settings: CompositionSettings, context: CompositionContext, /) -> CompositionSource: ...

    def to_mesh(self, mesh: dolfinx.mesh.Mesh, transfer: Transfer, /) -> None: ...

    def destroy(self) -> None: ...

    def state(self) -> State: ...

    def restore(self, scalars: Mapping[str, Any], /) -> dict[str, dolfinx.fem.Function]: ...


def composition_space(mesh: dolfinx.mesh.Mesh, degree: int, /) -> dolfinx.fem.FunctionSpace:
    """DG0 for degree 0, else continuous Lagrange of that degree."""
    return function_space(mesh, "DG", 0) if degree == 0 else function_space(mesh, "Lagrange", degree)


class StaticComposition(Stateful):
    """Fractions interpolated from the initial regions and kept fixed.

    Args:
        mesh: The mesh.
        materials: The materials.
        degree: 0 (DG0) or a Lagrange degree.
    """

    name: ClassVar[str] = "static"
    Settings: ClassVar[type] = CompositionSettings
    needs_materials: ClassVar[bool] = False
    carried_by_particles: ClassVar[bool] = False
    min_degree: ClassVar[int] = 0
    description: ClassVar[str] = "fractions set from the initial regions and kept fixed"

    @classmethod
    def build(cls, settings: CompositionSettings, context: CompositionContext, /) -> StaticComposition:
        return cls(context.mesh, context.materials, degree=settings.degree)

    def __init__(self, mesh: dolfinx.mesh.Mesh, materials: Materials, /, *, degree: int = 0) -> None:
        self.materials = materials
        self.degree = degree
        self._fields = self._new_fields(mesh)
        for f, material in zip(self._fields, materials.materials):
            f.interpolate(material.initial)
            f.x.scatter_forward()

    def _new_fields(self, mesh: dolfinx.mesh.Mesh) -> tuple[dolfinx.fem.Function, ...]:
        space = composition_space(mesh, self.degree)
        return tuple(dolfinx.fem.Function(space, name=name) for name in self.materials.names)

    @property
    def fields(self) -> tuple[dolfinx.fem.Function, ...]:
        return self._fields

    def advance(self, u: dolfinx.fem.Function, dt: float, /) -> None:
        """Nothing moves."""

    def to_mesh(self, mesh: dolfinx.mesh.Mesh, transfer: Transfer, /) -> None:
        new = self._new_fields(mesh)
        for old, f in zip(self._fields, new):
            transfer(old, f)
        self._fields = new

    def state(self) -> State:
        """The fractions (fixed, but a mesh change moved them with the mesh)."""
        return State(fields={f.name: f for f in self.fields})

    def restore(self, scalars: Mapping[str, Any], /) -> dict[str, dolfinx.fem.Function]:
        return self.state().fields

    def destroy(self) -> None:
        """Nothing to free."""


class TransportedFields(Stateful):
    """Fields advected by their transport solvers (one per field, named as it, no diffusion): what the
    advected fractions and the elastic stress fields (:mod:`convection.model.elastic_stress`) share."""

    solvers: list[TransportSolver]

    def advance(self, u: dolfinx.fem.Function, dt: float, /) -> None:
        """Advect every field over ``dt`` with ``u``."""
        for solver in self.solvers:
            solver.step(u, dt)

    def to_mesh(self, mesh: dolfinx.mesh.Mesh, transfer: Transfer, /) -> None:
        """Carry the fields and their transport history to ``mesh``."""
        old = self.solvers
        self.solvers = [s.on_mesh(mesh) for s in old]
        for new, previous in zip(self.solvers, old):
            new.transfer_from(previous, transfer)
            previous.destroy()

    def state(self) -> State:
        """Every field's transport history (Functions ``<field>/<name>``, scalars by field)."""
        states = [s.state() for s in self.solvers]
        fields = {f"{s.name}/{k}": f for s, state in zip(self.solvers, states) for k, f in state.fields.items()}
        return State(fields=fields, scalars={"solvers": [state.scalars for state in states]})

    def restore(self, scalars: Mapping[str, Any], /) -> dict[str, dolfinx.fem.Function]:
        fields = {}
        for solver, saved in zip(self.solvers, scalars["solvers"]):
            fields.update({f"{solver.name}/{k}": f for k, f in solver.restore(saved).items()})
        return fields

    def destroy(self) -> None:
        for solver in self.solvers:
            solver.destroy()


class FieldComposition(TransportedFields):
    """Fractions advected as continuous fields (one transport solver per material, no diffusion).

    Args:
        mesh: The mesh.
        approximation: The physics (the transport solver needs it; no heating is applied).
        materials: The materials.
        degree: Lagrange degree (>= 1).
        stabilisation: ``"supg"`` or ``"none"``.
    """

    name: ClassVar[str] = "field"
    Settings: ClassVar[type] = CompositionSettings
    needs_materials: ClassVar[bool] = True
    carried_by_particles: ClassVar[bool] = False
    min_degree: ClassVar[int] = 1
    description: ClassVar[str] = "fractions advected as continuous fields (SUPG + BDF2, no diffusion)"

    @classmethod
    def build(cls, settings: CompositionSettings, context: CompositionContext, /) -> FieldComposition:
        return cls(context.mesh, context.approximation, context.materials, degree=settings.degree,
                   stabilisation=context.stabilisation)

    def __init__(self, mesh: dolfinx.mesh.Mesh, approximation: BoussinesqApproximation, materials: Materials, /, *,
                 degree: int = 2, stabilisation: str = "supg") -> None:
        check_degree(self.name, degree)
        self.materials = materials
        self.solvers = [
            TransportSolver(mesh, approximation, bcs={}, degree=degree, stabilisation=stabilisation, diffusivity=0.0,
                            heating=False, name=m.name, velocity_extrapolation=False)
            for m in materials.materials
        ]
        for solver, material in zip(self.solvers, materials.materials):
            solver.set_initial(material.initial)

    @property
    def fields(self) -> tuple[dolfinx.fem.Function, ...]:
        return tuple(s.T for s in self.solvers)



def particle_properties(materials: Materials, gdim: int, /) -> list[InitialComposition]:
    """One ``initial_composition`` particle property per material (labelled with its name)."""

    def region(material_initial):
        def at(x: np.ndarray) -> np.ndarray:
            points = np.zeros((3, x.shape[0]))
            points[:gdim] = x.T
            return material_initial(points)
        return at

    return [InitialComposition(InitialComposition.Settings(source=region(m.initial), label=m.name))
            for m in materials.materials]


class ParticleComposition(Stateful):
    """Fractions averaged per cell from particle properties (one per material).

    The particle manager must carry :func:`particle_properties` of the materials; the model
    advances and moves the manager, so this source only names its fields.

    Args:
        manager: The particle manager.
        materials: The materials.
    """

    name: ClassVar[str] = "particles"
    Settings: ClassVar[type] = CompositionSettings
    needs_materials: ClassVar[bool] = True
    carried_by_particles: ClassVar[bool] = True
    min_degree: ClassVar[int] = 0
    description: ClassVar[str] = "fractions averaged per cell from the particles' material properties"

    @classmethod
    def build(cls, settings: CompositionSettings, context: CompositionContext, /) -> ParticleComposition:
        assert context.particles is not None, "the particles composition source needs particles"
        return cls(context.particles, context.materials)

    def __init__(self, manager: ParticleManager, materials: Materials, /) -> None:
        self.materials = materials
        self.manager = manager
        for name in materials.names:
            manager.track(name)

    @property
    def fields(self) -> tuple[dolfinx.fem.Function, ...]:
        return tuple(self.manager.field(name) for name in self.materials.names)

    def advance(self, u: dolfinx.fem.Function, dt: float, /) -> None:
        """The model advances the particles (and with them these fields)."""

    def to_mesh(self, mesh: dolfinx.mesh.Mesh, transfer: Transfer, /) -> None:
        """The model moves the particles (and with them these fields)."""

    def state(self) -> State:
        """Nothing: the particles carry the fractions (the particle manager keeps its own state)."""
        return State()

    def restore(self, scalars: Mapping[str, Any], /) -> dict[str, dolfinx.fem.Function]:
        return {}

    def destroy(self) -> None:
        """Nothing to free."""


COMPOSITION_SOURCES: Registry[type[CompositionSource]] = Registry("composition source",
                                               (StaticComposition, FieldComposition, ParticleComposition))
"""Composition sources by their config name (``composition.source``); each is made by its
``build(settings, context)`` from :class:`CompositionSettings` and a :class:`CompositionContext`."""
