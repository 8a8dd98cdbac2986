"""Shared pieces of the particle properties: contexts, policies, the property base class.

A property has the one plugin shape (:class:`fembase.registry.Plugin`): a ``Settings`` dataclass
of its parameters (the base's ``update`` and ``new_particles`` first), made by
``PROPERTIES.build(name, settings, PropertyBuildContext(...))``. It owns ``size`` scalar columns
of the swarm's property table (named by :attr:`ParticleProperty.column`). It says how its columns
are filled when particles are created (:meth:`ParticleProperty.initialise`), what happens for
particles added later (policy ``"reinitialise"`` or ``"interpolate"``), and when the values change
afterwards (``"never"``, ``"every_step"``, ``"output_only"``). Properties that obey an ODE along the particle path
(``integrated = True``) are advanced by :class:`particles.advection.Advector` with the same
Runge-Kutta scheme as the positions, through :meth:`ParticleProperty.rhs`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from collections.abc import Mapping
from typing import Any, ClassVar, NamedTuple

import numpy as np
import numpy.typing as npt

import dolfinx.fem

from fembase.params import param
from fembase.evaluation import Evaluator
from fembase.registry import Configured
from particles.generation.base import MakeFunction
from particles.storage.swarm import Swarm

__all__ = [
    "NEW_PARTICLE_POLICIES",
    "UPDATE_POLICIES",
    "EvaluatorCache",
    "ParticleProperty",
    "PropertyBuildContext",
    "PropertyContext",
    "evaluate_at",
    "gradient_at",
    "write_rows",
]

UPDATE_POLICIES: tuple[str, ...] = ("never", "every_step", "output_only")
"""When a property's values change after initialisation."""

NEW_PARTICLE_POLICIES: tuple[str, ...] = ("reinitialise", "interpolate")
"""How particles added after the start get their values."""


class PropertyBuildContext(NamedTuple):
    """What a property is made from, beside its settings (the fields it reads at run time come in
    a :class:`PropertyContext`).

    Attributes:
        make_function: Turns a text source (a config expression of the position) into a function
            (None: a text is refused).
    """

    make_function: MakeFunction | None = None


class EvaluatorCache:
    """One :class:`Evaluator` per function space, built on first use (keyed by the space's id)."""

    def __init__(self) -> None:
        self._evaluators: dict[int, Evaluator] = {}

    def get(self, swarm: Swarm, V: dolfinx.fem.FunctionSpace) -> Evaluator:
        """The evaluator of ``V`` using the swarm's cell geometry; ``V`` must live on the swarm's mesh."""
        if V.mesh is not swarm.mesh:
            raise ValueError("the Function must live on the swarm's mesh")
        ev = self._evaluators.get(id(V))
        if ev is None or ev.V is not V:
            ev = Evaluator(V, geometry=swarm.geometry)
            self._evaluators[id(V)] = ev
        return ev


@dataclass(frozen=True)
class PropertyContext:
    """The fields and times properties are initialised or updated from.

    Attributes:
        time: Current time (end of the last step when updating after advection).
        dt: Length of the last time step.
        u_old: Velocity at the start of the last step (vector Function), if known.
        u_new: Velocity at ``time`` (vector Function), if known.
        temperature: Temperature at ``time`` (scalar Function), if known.
        pressure: Pressure at ``time`` (scalar Function), if known.
        fields: Other named mesh fields (e.g. a plastic strain rate for ``plastic_strain``).
        evaluators: Evaluator cache (the property manager passes its own, so evaluators are built
            once per function space).
    """

    time: float = 0.0
    dt: float = 0.0
    u_old: dolfinx.fem.Function | None = None
    u_new: dolfinx.fem.Function | None = None
    temperature: dolfinx.fem.Function | None = None
    pressure: dolfinx.fem.Function | None = None
    fields: Mapping[str, dolfinx.fem.Function] = field(default_factory=dict, compare=False)
    evaluators: EvaluatorCache = field(default_factory=EvaluatorCache, compare=False, repr=False)

    @property
    def velocity(self) -> dolfinx.fem.Function | None:
        """The current velocity: ``u_new`` if given, else ``u_old``."""
        return self.u_new if self.u_new is not None else self.u_old

    def require(self, name: str, who: str) -> dolfinx.fem.Function:
        """Field ``name`` (``"velocity"``, ``"temperature"``, ``"pressure"``); ValueError if absent."""
        value = self.velocity if name == "velocity" else getattr(self, name)
        if value is None:
            raise ValueError(f"particle property {who!r} needs the {name} in the PropertyContext")
        return value


def evaluate_at(
    swarm: Swarm, rows: npt.NDArray[np.integer], u: dolfinx.fem.Function, context: PropertyContext
) -> npt.NDArray[np.float64]:
    """Values of ``u`` at the particles ``rows`` from their stored cell and xref; (m, value_size)."""
    ev = context.evaluators.get(swarm, u.function_space)
    return ev.values(u, swarm.cells[rows], swarm.xref[rows])


def gradient_at(
    swarm: Swarm, rows: npt.NDArray[np.integer], u: dolfinx.fem.Function, context: PropertyContext
) -> npt.NDArray[np.float64]:
    """Gradients of ``u`` at the particles ``rows``; (m, value_size, gdim)."""
    ev = context.evaluators.get(swarm, u.function_space)
    return ev.gradients(u, swarm.cells[rows], swarm.xref[rows])


def write_rows(swarm: Swarm, column: str, rows: npt.NDArray[np.integer], values: npt.ArrayLike) -> None:
    """Store ``values`` into property ``column`` at ``rows`` (shape=(m,)).

    ``values`` is a scalar or shape=(size,) (the same for every row), or shape=(m, size) / (m,)
    when size is 1.
    """
    lay = swarm.layout(column)
    rows = np.asarray(rows, dtype=np.int64)
    data = np.asarray(values, dtype=np.float64)
    m = rows.shape[0]
    if data.ndim == 0 or data.shape == (lay.size,):
        data = np.broadcast_to(data, (m, lay.size))  # one value for every row
    else:
        data = data.reshape(m, lay.size)
    swarm.properties[rows, lay.start : lay.start + lay.size] = data


class ParticleProperty(Configured):
    """Base of all particle properties: made from its ``Settings`` (checked when made).

    Class attributes (declared by each property):
        name: Registry name (lowercase).
        description: One line.
        default_update: Default update policy, one of :data:`UPDATE_POLICIES`.
        default_new_particles: Default policy for particles added later, one of
            :data:`NEW_PARTICLE_POLICIES`.
        integrated: True if the property obeys an ODE advanced by the Advector (then its update
            policy is fixed to ``"every_step"`` and :meth:`rhs` is defined).
        accumulating: True if the property is the time integral of a mesh field sampled at the
            particle (``dv/dt = f(x_p)``, :attr:`rate_field`), advanced once per step by
            :meth:`particles.properties.PropertyManager.accumulate` (explicit Euler, the field of
            the step's start).
    """

    name: ClassVar[str] = ""
    description: ClassVar[str] = ""
    default_update: ClassVar[str] = "never"
    default_new_particles: ClassVar[str] = "reinitialise"
    integrated: ClassVar[bool] = False
    accumulating: ClassVar[bool] = False

    @dataclass(frozen=True, kw_only=True)
    class Settings:
        """The parameters every property has (a property's ``Settings`` derive from these)."""

        update: str | None = param(None, help="Override of `default_update` (None keeps the default).")
        new_particles: str | None = param(None, help="Override of `default_new_particles` (None keeps the default).")

    settings: Settings

    def __init__(self, settings: Any = None, /) -> None:
        super().__init__(settings)
        self.check()

    def check(self) -> None:
        """Raise ValueError for settings this property refuses (a property with more to check
        extends this)."""
        update, new_particles = self.settings.update, self.settings.new_particles
        if update is not None and update not in UPDATE_POLICIES:
            raise ValueError(
                f"property {self.name!r}: unknown update policy {update!r}; valid: {list(UPDATE_POLICIES)}"
            )
        if new_particles is not None and new_particles not in NEW_PARTICLE_POLICIES:
            raise ValueError(
                f"property {self.name!r}: unknown new-particle policy {new_particles!r}; "
                f"valid: {list(NEW_PARTICLE_POLICIES)}"
            )
        if self.integrated and update not in (None, "every_step"):
            raise ValueError(f"property {self.name!r} is integrated along the path; its update policy is every_step")

    @property
    def update_policy(self) -> str:
        """When the values change: ``"never"``, ``"every_step"`` or ``"output_only"``."""
        if self.integrated:
            return "every_step"
        update = self.settings.update
        return update if update is not None else self.default_update

    @property
    def new_particles_policy(self) -> str:
        """``"reinitialise"`` or ``"interpolate"``."""
        new_particles = self.settings.new_particles
        return new_particles if new_particles is not None else self.default_new_particles

    @property
    def column(self) -> str:
        """Name of the swarm property holding this property's columns."""
        return self.name

    def size(self, gdim: int) -> int:
        """Number of scalar columns on a mesh of geometric dimension ``gdim``."""
        return 1

    def requires(self) -> tuple[str, ...]:
        """Columns of other properties this one reads (the property manager fills them first)."""
        return ()

    def initialise(self, swarm: Swarm, rows: npt.NDArray[np.integer], context: PropertyContext) -> None:
        """Fill the columns of the particles ``rows`` (int array, shape=(m,)) at their positions."""
        raise NotImplementedError

    def refresh(self, swarm: Swarm, context: PropertyContext) -> None:
        """Update all particles (called according to the update policy). Default: re-initialise."""
        self.initialise(swarm, np.arange(swarm.num_particles, dtype=np.int64), context)

    def rhs(
        self, swarm: Swarm, c: float, y: npt.NDArray[np.float64], grad_u: npt.NDArray[np.float64]
    ) -> npt.NDArray[np.float64]:
        """dy/dt at a Runge-Kutta stage (integrated properties only).

        Args:
            swarm: The swarm at the stage positions.
            c: Stage node in [0, 1].
            y: Current stage values, shape=(n, size).
            grad_u: ``grad_u[p, i, j] = d u_i / d x_j`` at the stage, shape=(n, gdim, gdim).

        Returns:
            shape=(n, size), float64.
        """
        raise NotImplementedError(f"property {self.name!r} is not integrated along the path")
