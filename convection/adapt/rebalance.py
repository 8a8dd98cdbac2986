"""The load-balancing component of a model: when to repartition and the loads per rank.

The work of a cell is about ``1 + W n_particles(K)``. :class:`Balancer` repartitions the mesh
(:meth:`convection.adapt.hierarchy.MeshHierarchy.repartition`: the base mesh and the current mesh move
together, with a partition method of :data:`fembase.partition.PARTITIONERS`) with strategy

- ``every``: every ``every`` steps;
- ``threshold``: every ``every`` steps, if max/mean over ranks of the load exceeds ``threshold``;
- ``none``: never.

Nothing is repartitioned on one rank. Fields and particles move with the mesh (the model carries
them); results do not change, only where they are computed.
"""

from __future__ import annotations

from dataclasses import dataclass
from collections.abc import Callable, Sequence

import numpy as np

import dolfinx.mesh

from convection.adapt.hierarchy import MeshHierarchy
from convection.schema import Names, param
from fembase.registry import Registry
from fembase.partition import PARTITIONERS
from particles.storage.swarm import Swarm

__all__ = ["BALANCE_STRATEGIES", "BalanceSettings", "Balancer", "RankLoads"]

@dataclass(frozen=True)
class BalancingStrategy:
    """A balancing strategy: on a step that is due, ``wants(balancer, mesh, swarms)`` decides whether
    to repartition (collective where it measures the loads)."""

    name: str
    description: str
    wants: Callable[[Balancer, dolfinx.mesh.Mesh, Sequence[Swarm]], bool]
    repartitions: bool = True
    """False: never repartitions (no balancer is made; the mesh keeps its first partition)."""


def _over_threshold(balancer: Balancer, mesh: dolfinx.mesh.Mesh, swarms: Sequence[Swarm], /) -> bool:
    return balancer.loads(mesh, swarms).load_imbalance > balancer.threshold


BALANCE_STRATEGIES: Registry[BalancingStrategy] = Registry("balancing strategy", (
    BalancingStrategy("none", "never repartition", lambda balancer, mesh, swarms: False, repartitions=False),
    BalancingStrategy("every", "repartition every N steps", lambda balancer, mesh, swarms: True),
    BalancingStrategy("threshold", "repartition when max/mean of the load over ranks exceeds a threshold (checked "
                      "every N steps)", _over_threshold),
))
"""Balancing strategies by name: each decides, on a step that is due, whether to repartition
(``wants(balancer, mesh, swarms)``)."""


@dataclass(frozen=True)
class RankLoads:
    """Per-rank counts, each shape=(num_ranks,): owned cells, particles, load = cells + W particles."""

    cells: np.ndarray
    particles: np.ndarray
    load: np.ndarray

    @staticmethod
    def _ratio(values: np.ndarray) -> float:
        mean = float(np.mean(values))
        return float(np.max(values)) / mean if mean > 0 else 1.0

    @property
    def cell_imbalance(self) -> float:
        return self._ratio(self.cells)

    @property
    def particle_imbalance(self) -> float:
        return self._ratio(self.particles)

    @property
    def load_imbalance(self) -> float:
        return self._ratio(self.load)

    @classmethod
    def measure(cls, mesh: dolfinx.mesh.Mesh, swarms: Sequence[Swarm], /, *, particle_weight: float) -> RankLoads:
        """The loads of ``mesh`` and the particles of ``swarms`` (every particle system's; collective)."""
        owned = mesh.topology.index_map(mesh.topology.dim).size_local
        particles = sum(swarm.num_particles for swarm in swarms)
        gathered = mesh.comm.allgather((owned, particles, owned + particle_weight * particles))
        return cls(*(np.array(column) for column in zip(*gathered)))


@dataclass(frozen=True)
class BalanceSettings:
    """The ``balance`` config section: when and how :class:`Balancer` repartitions."""

    strategy: str = param("none", choices=Names(BALANCE_STRATEGIES),
                          help="repartition the mesh: never, every N steps, or when the load imbalance exceeds a "
                               "threshold")
    every: int = param(10, minimum=1, help="steps between repartitions (every) or checks (threshold)")
    threshold: float = param(1.2, minimum=1.0,
                             help="repartition when max/mean over ranks of the load (cells + W particles) exceeds "
                                  "this")
    particle_weight: float = param(0.01, minimum=0.0, help="W in the cell weight 1 + W n_particles(K)")
    method: str = param("rcb", choices=Names(PARTITIONERS),
                        help="rcb: recursive bisection balancing cells and particles; morton: space-filling-curve "
                             "blocks")

    def __post_init__(self) -> None:
        if self.strategy not in BALANCE_STRATEGIES:
            raise ValueError(f"unknown balancing strategy {self.strategy!r}; valid: {sorted(BALANCE_STRATEGIES)}")
        if self.method not in PARTITIONERS:
            raise ValueError(f"unknown partition method {self.method!r}; valid: {sorted(PARTITIONERS)}")
        if self.every < 1:
            raise ValueError(f"every must be >= 1, got {self.every}")


class Balancer:
    """When and how to repartition (see the module docstring).

    Args:
        hierarchy: The base mesh and its refinements (shared with adaptivity).
        settings: Strategy (a name in :data:`BALANCE_STRATEGIES`), interval, threshold, the particle
            weight W of the cell load ``1 + W n_particles`` and the partition method (a name in
            :data:`fembase.partition.PARTITIONERS`).
    """

    def __init__(self, hierarchy: MeshHierarchy, settings: BalanceSettings = BalanceSettings(), /) -> None:
        self.hierarchy = hierarchy
        self.settings = settings
        self.strategy = settings.strategy
        self.every = settings.every
        self.threshold = settings.threshold
        self.particle_weight = settings.particle_weight
        self.method = settings.method

    def loads(self, mesh: dolfinx.mesh.Mesh, swarms: Sequence[Swarm], /) -> RankLoads:
        """Cells, particles (of every swarm in ``swarms``) and load per rank (collective)."""
        return RankLoads.measure(mesh, swarms, particle_weight=self.particle_weight)

    def due(self, timestep: int, mesh: dolfinx.mesh.Mesh, swarms: Sequence[Swarm], /) -> bool:
        """Whether to repartition after step ``timestep`` (collective for ``threshold``)."""
        if mesh.comm.size == 1 or timestep % self.every != 0:
            return False
        return BALANCE_STRATEGIES[self.strategy].wants(self, mesh, swarms)

    def new_mesh(self, mesh: dolfinx.mesh.Mesh, swarms: Sequence[Swarm], /) -> dolfinx.mesh.Mesh:
        """The same cells on a partition with equal loads, a cell weighing 1 + W (its particles of
        every swarm in ``swarms``) (collective)."""
        num_owned = mesh.topology.index_map(mesh.topology.dim).size_local
        counts = np.zeros(num_owned)
        for swarm in swarms:
            counts += swarm.particles_per_cell()
        return self.hierarchy.repartition(mesh, counts, particle_weight=self.particle_weight, method=self.method)

