"""Particle properties (seed paper section 2.6): registry, one module per property, and a manager.

All particles of a swarm carry the same named properties, stored as scalar columns of the swarm's
property table (a vector takes gdim columns, a tensor gdim*gdim, row-major). Every property has the
one plugin shape: a ``Settings`` dataclass of its parameters, made by
``PROPERTIES.build(name, settings, PropertyBuildContext(...))`` (the module of ``damage`` shows one
with parameters, that of ``rank`` one without). It declares its size, its
initialiser, the policy for particles added later (``"reinitialise"``: the initialiser at the new
position; ``"interpolate"``: from the older particles nearby) and when it updates (``"never"``,
``"every_step"``, ``"output_only"``). Properties obeying an ODE along the path (deformation
gradient, integrated strain, damage) are advanced by the Advector together with the positions:

    >>> manager = PropertyManager(swarm, ["initial_position", Damage(Damage.Settings(alpha=2.0)), "integrated_strain"])
    >>> manager.initialise(PropertyContext(u_new=u))
    >>> advector = Advector(swarm, integrator="rk2", odes=manager.odes())
    >>> advector.step(u_old, u_new, dt)
    >>> manager.update(PropertyContext(time=t + dt, dt=dt, u_old=u_old, u_new=u_new))
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence

import dolfinx.fem

import numpy as np
import numpy.typing as npt

from particles.advection.integrators import ParticleODE
from particles.properties._base import (
    NEW_PARTICLE_POLICIES,
    UPDATE_POLICIES,
    EvaluatorCache,
    ParticleProperty,
    PropertyBuildContext,
    PropertyContext,
    evaluate_at,
)
from particles.properties._interpolate import interpolate_from_neighbours
from particles.properties.damage import Damage
from particles.properties.deformation_gradient import DeformationGradient
from particles.properties.displacement import Displacement
from particles.properties.elastic_outputs import (ElasticShare, ElasticStrainRate, ElasticStressInvariant,
                                                  ViscousStrainRate)
from particles.properties.elastic_stress import ElasticStress
from particles.properties.function import FunctionProperty
from particles.properties.initial_composition import InitialComposition
from particles.properties.initial_position import InitialPosition
from particles.properties.integrated_strain import IntegratedStrain
from particles.properties.plastic_strain import PlasticStrain
from particles.properties.pressure import Pressure
from particles.properties.rank import Rank
from particles.properties.strain_rate import StrainRate
from particles.properties.temperature import Temperature
from particles.properties.time_since_creation import TimeSinceCreation
from particles.properties.velocity import Velocity
from particles.storage.swarm import PropertyLayout, Swarm
from fembase.registry import Registry

__all__ = [
    "NEW_PARTICLE_POLICIES",
    "PROPERTIES",
    "UPDATE_POLICIES",
    "Damage",
    "DeformationGradient",
    "Displacement",
    "ElasticShare",
    "ElasticStrainRate",
    "ElasticStress",
    "ElasticStressInvariant",
    "FunctionProperty",
    "InitialComposition",
    "InitialPosition",
    "IntegratedStrain",
    "ParticleProperty",
    "PlasticStrain",
    "Pressure",
    "PropertyBuildContext",
    "PropertyContext",
    "PropertyManager",
    "Rank",
    "StrainRate",
    "Temperature",
    "TimeSinceCreation",
    "Velocity",
    "ViscousStrainRate",
    "dependency_order",
]

PROPERTIES: Registry[type[ParticleProperty]] = Registry(
    "particle property",
    (
        InitialPosition, InitialComposition, FunctionProperty, Velocity, Temperature, Pressure, StrainRate,
        IntegratedStrain, DeformationGradient, Damage, TimeSinceCreation, Rank, Displacement, PlasticStrain,
        ElasticStress, ElasticStressInvariant, ElasticStrainRate, ViscousStrainRate, ElasticShare,  # elasticity
    ),
)
"""Property classes by their lowercase config name."""

PropertySpec = ParticleProperty | str


def dependency_order(properties: Sequence[ParticleProperty], /) -> list[ParticleProperty]:
    """``properties`` with every property after the ones it requires (stable otherwise).

    Raises:
        ValueError: A required property is missing (or the requirements form a cycle).
    """
    columns = {p.column for p in properties}
    for prop in properties:
        missing = [c for c in prop.requires() if c not in columns]
        if missing:
            raise ValueError(f"particle property {prop.column!r} needs the propert{'ies' if len(missing) > 1 else 'y'} "
                             f"{', '.join(repr(c) for c in missing)}; add {'them' if len(missing) > 1 else 'it'} "
                             "to the properties")
    ordered: list[ParticleProperty] = []
    pending = list(properties)
    while pending:
        placed = {p.column for p in ordered}
        ready = next((p for p in pending if set(p.requires()) <= placed), None)
        if ready is None:
            raise ValueError(f"particle properties require each other in a cycle: {[p.column for p in pending]}")
        ordered.append(ready)
        pending.remove(ready)
    return ordered


class PropertyManager:
    """The properties carried by every particle of one swarm.

    Adds each property's columns to the swarm at construction (zero-filled). The manager remembers
    the last context it was given, so :meth:`initialise_new` (the ``initialise(swarm, rows)`` hook
    of population control) can re-evaluate fields at new particles.

    Properties that read other properties (:meth:`ParticleProperty.requires`, e.g. ``displacement``
    reads ``initial_position``) are placed after them, otherwise the given order is kept.

    Args:
        swarm: The swarm.
        properties: Property objects or registered names (built with their default settings).

    Raises:
        ValueError: Two properties with the same column name, an unknown name, or a property whose
            required property is missing.
    """

    def __init__(self, swarm: Swarm, properties: Sequence[PropertySpec], /) -> None:
        self.swarm = swarm
        built = [PROPERTIES.build(p, PROPERTIES.settings(p), PropertyBuildContext()) if isinstance(p, str) else p
                 for p in properties]
        columns = [p.column for p in built]
        duplicates = sorted({c for c in columns if columns.count(c) > 1})
        if duplicates:
            raise ValueError(f"particle properties share column names {duplicates}; give them distinct labels")
        self.properties: tuple[ParticleProperty, ...] = tuple(dependency_order(built))
        self._evaluators = EvaluatorCache()
        self._context = PropertyContext(evaluators=self._evaluators)
        for prop in self.properties:
            swarm.add_property(prop.column, prop.size(swarm.gdim))

    @property
    def context(self) -> PropertyContext:
        """The last context given (fields and time that new particles are initialised from)."""
        return self._context

    def set_context(self, context: PropertyContext, /) -> None:
        """Remember ``context`` for later :meth:`initialise_new` calls."""
        self._bind(context)

    def attach(self, swarm: Swarm, /) -> None:
        """Manage ``swarm`` instead (the same particles on a new mesh, e.g. after
        :func:`particles.relocation.new_mesh.move_to_mesh`). Evaluators are rebuilt for the new mesh and the
        remembered context keeps its time but drops its fields (they live on the old mesh).

        Raises:
            ValueError: ``swarm`` lacks a managed property's columns.
        """
        for prop in self.properties:
            if not swarm.has_property(prop.column) or swarm.layout(prop.column).size != prop.size(swarm.gdim):
                raise ValueError(f"the swarm lacks the columns of particle property {prop.column!r}")
        self.swarm = swarm
        self._evaluators = EvaluatorCache()
        self._context = PropertyContext(time=self._context.time, dt=self._context.dt, evaluators=self._evaluators)

    @property
    def names(self) -> list[str]:
        """Column names of the managed properties, in order."""
        return [p.column for p in self.properties]

    def __getitem__(self, column: str) -> ParticleProperty:
        for prop in self.properties:
            if prop.column == column:
                return prop
        raise KeyError(f"no managed particle property {column!r}; known: {self.names}")

    def layout(self, column: str) -> PropertyLayout:
        """Column range of property ``column`` in the swarm's property table."""
        return self.swarm.layout(self[column].column)

    def values(self, column: str) -> npt.NDArray[np.float64]:
        """View of property ``column``, shape=(n, size)."""
        return self.swarm.property(self[column].column)

    def _bind(self, context: PropertyContext) -> PropertyContext:
        if context.evaluators is not self._evaluators:
            context = dataclasses.replace(context, evaluators=self._evaluators)
        self._context = context
        return context

    def initialise(self, context: PropertyContext | None = None, /) -> None:
        """Initialise every property at every particle (start of a run)."""
        ctx = self._bind(context if context is not None else self._context)
        rows = np.arange(self.swarm.num_particles, dtype=np.int64)
        for prop in self.properties:
            prop.initialise(self.swarm, rows, ctx)

    def initialise_new(self, swarm: Swarm, rows: npt.ArrayLike, /) -> None:
        """Give the particles ``rows`` (added after the start) their values, per property policy.

        ``"reinitialise"`` calls the property's initialiser at the particle's position with the last
        context; ``"interpolate"`` takes the mean of the other particles in the same cell (the
        nearest other particle if the cell has none; the initialiser if this rank has no other
        particle). Not collective.

        Args:
            swarm: The managed swarm (the argument makes this a population-control hook).
            rows: Rows of the new particles, shape=(m,), integer.
        """
        if swarm is not self.swarm:
            raise ValueError("initialise_new called with a swarm this manager does not manage")
        rows = np.asarray(rows, dtype=np.int64).reshape(-1)
        for prop in self.properties:
            if prop.new_particles_policy == "interpolate":
                lay = swarm.layout(prop.column)
                if interpolate_from_neighbours(swarm, rows, lay.columns):
                    continue
            prop.initialise(swarm, rows, self._context)

    def update(self, context: PropertyContext, /, *, at_output: bool = False) -> None:
        """Refresh the properties whose policy says so; call once per time step, after advection.

        ``"every_step"`` properties are refreshed on every call, ``"output_only"`` ones only with
        ``at_output=True``. Integrated properties are skipped: the Advector advances them (pass
        :meth:`odes` to it).
        """
        ctx = self._bind(context)
        for prop in self.properties:
            if prop.integrated:
                continue
            policy = prop.update_policy
            if policy == "every_step" or (policy == "output_only" and at_output):
                prop.refresh(self.swarm, ctx)

    def refresh(self, column: str, context: PropertyContext, /) -> None:
        """Refresh the property ``column`` now, whatever its update policy."""
        self[column].refresh(self.swarm, self._bind(context))

    @property
    def rate_fields(self) -> tuple[str, ...]:
        """The mesh fields the accumulating properties integrate, and those the others read when they
        refresh (``elastic_stress``: ``mesh_fields``), names each once."""
        read = (name for p in self.properties for name in getattr(p, "mesh_fields", ()))  # elasticity (issue 48)
        return tuple(dict.fromkeys([*(p.rate_field for p in self.properties if p.accumulating), *read]))

    def accumulate(self, fields: Mapping[str, dolfinx.fem.Function], dt: float, /) -> None:
        """Advance the accumulating properties by one step: ``v += dt f(x_p)`` with ``f`` the
        property's rate field (from ``fields``) at the particles' current positions (call before
        the particles move: explicit Euler). Not collective.

        Raises:
            ValueError: a rate field is missing from ``fields``.
        """
        rows = np.arange(self.swarm.num_particles, dtype=np.int64)
        for prop in self.properties:
            if not prop.accumulating:
                continue
            if prop.rate_field not in fields:
                raise ValueError(f"particle property {prop.column!r} integrates the mesh field {prop.rate_field!r}, "
                                 f"which was not given (have {sorted(fields)})")
            if rows.shape[0] == 0 or dt == 0.0:
                continue
            rate = evaluate_at(self.swarm, rows, fields[prop.rate_field], self._context)
            lay = self.swarm.layout(prop.column)
            self.swarm.properties[:, lay.start:lay.start + lay.size] += dt * rate.reshape(rows.shape[0], lay.size)

    def odes(self) -> list[ParticleODE]:
        """The integrated properties as Advector ODEs (``Advector(swarm, odes=manager.odes())``)."""
        return [ParticleODE(p.column, p.rhs) for p in self.properties if p.integrated]
