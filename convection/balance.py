"""Load balancing of convection runs: partition a mesh with cell loads 1 + W n_particles.

The partition methods (:data:`PARTITIONERS`: ``morton``, ``rcb``) live in
:mod:`particles.partition` and the mesh redistribution helpers in :mod:`particles.balance`, shared
with particle users (:func:`particles.balance.rebalance`); this module re-exports them under the
names the convection code and its config (``balance.method``) use.
:meth:`convection.adaptivity.MeshHierarchy.repartition` applies them to the coarse base mesh of an
adaptive run.
"""

from __future__ import annotations

from particles.balance import (
    CellLayout, MeshPiece, WeightedMesh, create_mesh_from_piece, create_partitioned_mesh, gather_cell_layout,
    mesh_piece, owner_partitioner, pull, redistribute, redistribution,
)
from particles.partition import (
    PARTITIONERS, PartitionMethod, block_owners, morton_order, morton_owners, partition, rcb_owners,
)

__all__ = ["CellLayout", "MeshPiece", "PARTITIONERS", "PartitionMethod", "WeightedMesh", "block_owners",
           "create_mesh_from_piece", "create_partitioned_mesh", "gather_cell_layout", "mesh_piece", "morton_order",
           "morton_owners", "owner_partitioner", "partition", "pull", "rcb_owners", "redistribute", "redistribution"]
