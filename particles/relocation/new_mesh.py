"""Particles through mesh refinement, coarsening and repartitioning (seed paper section 2.5).

When the mesh changes, every particle must end up in its new cell with a correct reference
position, without losing any. DOLFINx 0.5 exposes the parent-cell map only for uniform refinement,
and meshes rebuilt from a base mesh (for coarsening) have no parent relation to the previous mesh
at all, so the new cells are found by a *rank-local* bounding-box search on the new mesh: meshes
refined without redistribution keep every region on the rank that owned it, so almost every
particle is found among this rank's new cells without communication. Particles that land in a
ghost cell or outside this rank's new cells (after a repartition) are handed on by the migration
step (:func:`particles.parallel.migration.migrate`), which also counts any particle found nowhere.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import numpy.typing as npt
from mpi4py import MPI

import dolfinx.mesh

from fembase.geometry import Candidates
from particles.parallel.migration import migrate
from particles.relocation.moving_mesh import pull_in
from particles.storage.swarm import Swarm

__all__ = ["MeshChangeStats", "move_to_mesh"]


class MeshChangeStats(NamedTuple):
    """Counts of one move to a new mesh (global sums over ranks).

    Attributes:
        found_locally: Particles located in an owned cell of the new mesh on their rank.
        migrated: Particles that had to change rank.
        lost: Particles found on no rank (must be 0 when both meshes cover the same domain).
        pulled_in: Particles outside the new mesh moved inside along the swarm's ``inward``
            (a free surface: coarsened cells' surface is the chord of the finer one's).
    """

    found_locally: int
    migrated: int
    lost: int
    pulled_in: int = 0


def move_to_mesh(swarm: Swarm, mesh: dolfinx.mesh.Mesh, /, *,
                 candidates: Candidates | None = None) -> tuple[Swarm, MeshChangeStats]:
    """A swarm on ``mesh`` holding all particles of ``swarm`` (ids, positions, properties). Collective.

    Args:
        swarm: Particles on the old mesh (all in owned cells).
        mesh: The new mesh, covering the same domain.
        candidates: Cells of ``mesh`` to search first for each particle (see
            :meth:`fembase.geometry.CellGeometry.locate`); the others are found with the
            bounding-box tree.

    Returns:
        The new swarm (same property layout) and the move's statistics.
    """
    new = Swarm(mesh)
    for name in swarm.property_names:
        lay = swarm.layout(name)
        new.add_property(name, lay.size)
    located = new.geometry.locate(swarm.x, candidates=candidates)
    cells = located.cells
    local = (cells >= 0) & (cells < new.num_owned_cells)
    new.add(swarm.ids, swarm.x, located.xref, cells, swarm.properties)
    pulled = 0
    if swarm.inward is not None:  # the same on every rank
        new.inward = swarm.inward
        pulled = pull_in(new, _nearest_owned_cells(new))
    stats = migrate(new)
    found, pulled = mesh.comm.allreduce(np.array([np.count_nonzero(local), pulled], dtype=np.int64), op=MPI.SUM)
    return new, MeshChangeStats(int(found), int(stats.global_sent + stats.global_fallback_sent), int(stats.global_lost),
                                int(pulled))


def _nearest_owned_cells(swarm: Swarm, /) -> npt.NDArray[np.int32]:
    """Per particle, its cell, or for one in no local cell the owned cell with the nearest centre
    (where :func:`particles.relocation.moving_mesh.pull_in` starts looking along ``inward``), shape=(n,)."""
    cells = swarm.cells.copy()
    missing = np.flatnonzero(cells < 0)
    if missing.size and swarm.num_owned_cells:
        owned = swarm.geometry.centres[: swarm.num_owned_cells]
        from scipy.spatial import cKDTree  # here, not at import: scipy.spatial is 23 MB a process
        cells[missing] = cKDTree(owned).query(swarm.x[missing])[1]
    return cells
