"""Several particle systems in one run (ASPECT's particle worlds): :class:`ParticleSystems`.

A run may carry more than one swarm, each a :class:`~particles.manager.ParticleManager` with its
own generator, integrator, properties, interpolator, population bounds and output, e.g. a dense
system that carries the composition and a sparse set of passive tracers written every step. The
systems do not see each other: each draws its random numbers from its own seeds, numbers its own
particles and keeps its own counters, so a system's particles are the same whatever other systems
a run has (given the same flow).

:class:`ParticleSystems` holds the systems by name, in the config's order, and calls each in turn
(all calls collective)::

    systems.advance(u_old, u_new, dt, step=n)     # every system
    systems.update(context, step=n + 1)           # every system's properties and output

One system is the *primary*: the one whose tracked fields the model reads (the composition, the
rheology's particle fields). Counts over all systems (:attr:`ParticleSystems.num_particles`,
:attr:`swarms` for a load balancer's weights) and per system (``systems[name]``) are both there.

Each system's files carry its :func:`file_stem`: ``particles`` for a system named ``particles``
(a run with a single ``particles`` section), ``particles_<name>`` for any other name
(``particles_tracers.xdmf``, ``particles_tracers.h5`` in a checkpoint).

This module never imports ``convection``; it works on any DOLFINx mesh.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping

import numpy as np
import numpy.typing as npt

import dolfinx.fem
import dolfinx.mesh

from fembase.geometry import Candidates
from particles.manager import AdvanceReport, ParticleManager
from particles.relocation.moving_mesh import FollowStats
from particles.io.output import OutputRecord
from particles.properties import PropertyContext
from particles.storage.swarm import Swarm

__all__ = ["DEFAULT_SYSTEM", "ParticleSystems", "file_stem"]

DEFAULT_SYSTEM = "particles"
"""The name of the one system of a run with a single ``particles`` section."""


def file_stem(name: str, /) -> str:
    """The file name stem of system ``name``'s output and checkpoint part: ``particles`` for
    :data:`DEFAULT_SYSTEM`, else ``particles_<name>``."""
    return DEFAULT_SYSTEM if name == DEFAULT_SYSTEM else f"{DEFAULT_SYSTEM}_{name}"


class ParticleSystems:
    """Named particle systems of one run, called in their order (see the module docstring).

    Args:
        systems: The managers by name (at least one; the order is the order they are called in).
        primary: The system whose fields the model reads (default: the first).

    Raises:
        ValueError: No system, or ``primary`` is not one of them.
    """

    def __init__(self, systems: Mapping[str, ParticleManager], /, *, primary: str | None = None) -> None:
        if not systems:
            raise ValueError("at least one particle system is needed")
        self._systems = dict(systems)
        self.primary_name = next(iter(self._systems)) if primary is None else primary
        if self.primary_name not in self._systems:
            raise ValueError(f"no particle system {self.primary_name!r}; the systems are {list(self._systems)}")

    @classmethod
    def of(cls, particles: ParticleSystems | ParticleManager, /) -> ParticleSystems:
        """``particles`` itself, or one manager as the one system :data:`DEFAULT_SYSTEM` (a run
        built from components, as a config's single ``particles`` section)."""
        return particles if isinstance(particles, ParticleSystems) else cls({DEFAULT_SYSTEM: particles})

    # ------------------------------------------------------------------ the systems
    def __getitem__(self, name: str, /) -> ParticleManager:
        return self._systems[name]

    def __iter__(self) -> Iterator[ParticleManager]:
        return iter(self._systems.values())

    def __len__(self) -> int:
        return len(self._systems)

    def items(self) -> Iterator[tuple[str, ParticleManager]]:
        """(name, manager) in order."""
        return iter(self._systems.items())

    @property
    def names(self) -> list[str]:
        return list(self._systems)

    @property
    def primary(self) -> ParticleManager:
        """The system whose tracked fields the model reads."""
        return self._systems[self.primary_name]

    @property
    def swarm(self) -> Swarm:
        """The primary system's swarm (a one-system run's particles)."""
        return self.primary.swarm

    @property
    def swarms(self) -> list[Swarm]:
        """Every system's swarm, in order (e.g. a load balancer's particle weights count them all)."""
        return [manager.swarm for manager in self]

    @property
    def rate_fields(self) -> tuple[str, ...]:
        """The mesh fields the systems' accumulating properties integrate (names, each once)."""
        return tuple(dict.fromkeys(name for manager in self for name in manager.properties.rate_fields))

    def field(self, label: str, /) -> dolfinx.fem.Function:
        """The primary system's current tracked field ``label``."""
        return self.primary.field(label)

    # ------------------------------------------------------------------ counts (collective)
    @property
    def num_particles(self) -> int:
        """Particles of all systems (global)."""
        return sum(manager.num_particles for manager in self)

    @property
    def lost(self) -> int:
        """Particles all systems lost so far (global)."""
        return sum(manager.lost for manager in self)

    @property
    def pulled_in(self) -> int:
        """Particles of all systems a sinking free surface passed and that were moved back in."""
        return sum(manager.pulled_in for manager in self)

    @property
    def timings(self) -> dict[str, float]:
        """Seconds per phase, summed over the systems (this rank)."""
        total: dict[str, float] = {}
        for manager in self:
            for phase, seconds in manager.timings.items():
                total[phase] = total.get(phase, 0.0) + seconds
        return total

    @property
    def writes(self) -> bool:
        """Whether any system writes output."""
        return any(manager.writer is not None for manager in self)

    # ------------------------------------------------------------------ time stepping (collective)
    def advance(self, u_old: dolfinx.fem.Function, u_new: dolfinx.fem.Function, dt: float, /, *, step: int = 0,
                fields: Mapping[str, dolfinx.fem.Function] | None = None) -> dict[str, AdvanceReport]:
        """:meth:`ParticleManager.advance` of every system; the reports by name."""
        return {name: manager.advance(u_old, u_new, dt, step=step, fields=fields) for name, manager in self.items()}

    def update(self, context: PropertyContext, /, *, step: int, final: bool = False) -> dict[str, OutputRecord]:
        """:meth:`ParticleManager.update` of every system (with ``final``: of those that write
        output); the output records of the systems that wrote, by name."""
        records = {}
        for name, manager in self.items():
            if final and manager.writer is None:
                continue
            record = manager.update(context, step=step, final=final)
            if record is not None:
                records[name] = record
        return records

    def refresh(self, column: str, context: PropertyContext, /) -> None:
        """Refresh the property ``column`` now, whatever its update policy, in every system that has it
        (the elastic stress for a flow solved again at a step's start: :meth:`convection.model.model.Model.step`)."""
        for manager in self:
            if column in manager.properties.names:
                manager.properties.refresh(column, context)

    def follow_mesh(self) -> dict[str, FollowStats]:
        """:meth:`ParticleManager.follow_mesh` of every system (the mesh's nodes moved)."""
        return {name: manager.follow_mesh() for name, manager in self.items()}

    def set_inward(self, inward: Callable[[npt.NDArray[np.float64]], npt.NDArray[np.float64]] | None, /) -> None:
        """Every swarm moves particles that a moving surface passed back in along ``inward``
        (:mod:`particles.relocation.moving_mesh`)."""
        for swarm in self.swarms:
            swarm.inward = inward

    def to_mesh(self, mesh: dolfinx.mesh.Mesh, /, *, context: PropertyContext | None = None, step: int = 0,
                candidates: Mapping[str, Candidates | None] | None = None, bound: bool = True) -> int:
        """:meth:`ParticleManager.to_mesh` of every system (``candidates``: by system name).
        Returns the particles lost in the move (global, all systems)."""
        candidates = candidates or {}
        return sum(manager.to_mesh(mesh, context=context, step=step, candidates=candidates.get(name), bound=bound)
                   for name, manager in self.items())
