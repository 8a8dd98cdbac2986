"""Load balancing of a particle swarm: repartition its mesh with cell loads 1 + W n_particles and move
the particles along (seed paper section 2.4).

:func:`rebalance` counts the particles per cell, lets a partition method of :mod:`fembase.partition`
choose a new owner for every cell (:func:`fembase.distribute.cell_owners`), creates the mesh anew on
that partition (:func:`fembase.distribute.redistribute`) and moves the particles to it
(:func:`particles.relocation.new_mesh.move_to_mesh`). Functions on the old mesh are the caller's to carry
over (or to rebuild on ``swarm.mesh``).
"""

from __future__ import annotations

from typing import Any

from fembase.distribute import cell_owners, redistribute
from particles.relocation.new_mesh import move_to_mesh
from particles.storage.swarm import Swarm

__all__ = ["rebalance"]


def rebalance(swarm: Swarm, /, *, particle_weight: float = 1.0, method: str = "rcb", ghost_layer: str = "vertex",
              **options: Any) -> Swarm:
    """The particles of ``swarm`` on their mesh repartitioned for cell loads ``1 + W n_particles``
    (collective).

    The mesh is created anew on the partition :func:`cell_owners` chooses (same cells and
    vertices; by default with the vertex ghost layer, see :func:`owner_partitioner`), and every
    particle (id, position, properties) is moved to the rank owning its cell there. With ``rcb`` every cut balances the
    load ``1 + W n`` alone (``balance=("load",)`` unless given), so ranks get equal work rather than equal cells and
    equal particles at once (what the convection runs ask of it). Functions on the old mesh are not carried over: build
    them again on ``result.mesh`` (or interpolate them across). On one rank the swarm itself is
    returned.

    Args:
        swarm: The particles (sorted, in owned cells) on a P1 simplex mesh.
        particle_weight: W, the cost of a particle relative to a cell.
        method: Partition method name (:data:`fembase.partition.PARTITIONERS`).
        ghost_layer: ``"vertex"`` (every cell touching an owned cell is local, as in deal.II: a
            particle crossing a partition corner lands in a ghost cell) or ``"facet"``.
        options: Method options, e.g. ``balance=("load",)`` or ``axes=(1,)`` for ``rcb``
            (:func:`fembase.partition.rcb_owners`).

    Returns:
        A new swarm on the repartitioned mesh, with the same particles and property layout.

    Example:
        >>> swarm = rebalance(swarm, particle_weight=1.0)
        >>> V = dolfinx.fem.VectorFunctionSpace(swarm.mesh, ("Lagrange", 2))
    """
    if method == "rcb":
        options.setdefault("balance", ("load",))
    owners = cell_owners(swarm.mesh, swarm.particles_per_cell(), particle_weight=particle_weight, method=method,
                         **options)
    if swarm.comm.size == 1:
        return swarm
    mesh = redistribute(swarm.mesh, owners, ghost_layer=ghost_layer)
    moved, stats = move_to_mesh(swarm, mesh)
    if stats.lost:
        raise RuntimeError(f"rebalance lost {stats.lost} particles (the new mesh must cover the old one)")
    return moved
