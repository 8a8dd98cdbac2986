"""Insert a global list of points: bounding-box prefilter, owned-cell search, one owner per point.

A point on the boundary between partitions may be found by several ranks; the lowest rank that
finds it keeps it (every finder tells the higher-ranked finders whose owned-cell boxes contain the
point). Points no rank finds are outside the mesh and are counted.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from fembase.geometry import locate_owned, owned_box
from particles.generation.base import GenerationResult, first_free_id
from particles.storage.swarm import Swarm

__all__ = ["in_box", "insert_listed_points"]


def in_box(x: npt.NDArray[np.float64], box: npt.NDArray[np.float64], tol: float = 1e-10) -> npt.NDArray[np.bool_]:
    """Which points (n, gdim) lie in the box (2, gdim), with an absolute tolerance."""
    return np.all((x >= box[0] - tol) & (x <= box[1] + tol), axis=1)


def insert_listed_points(swarm: Swarm, x: npt.NDArray[np.float64], index: npt.NDArray[np.int64],
                         num_listed: int) -> GenerationResult:
    """Insert the points of a global list that lie in this rank's owned cells (collective).

    Args:
        swarm: Target swarm.
        x: Candidate points of this rank (already prefiltered by its box), shape=(n, gdim).
        index: Their indices in the global list, shape=(n,), int64 (distinct).
        num_listed: Length of the global list.

    Returns:
        Counts; the ids are ``first_id + index``.
    """
    comm = swarm.comm
    base = first_free_id(swarm)
    loc = locate_owned(swarm.mesh, x, geometry=swarm.geometry)
    found = loc.cells >= 0
    if comm.size > 1:
        boxes = comm.allgather(owned_box(swarm.mesh))
        outgoing = [index[found & in_box(x, boxes[r])] if r > comm.rank else index[:0] for r in range(comm.size)]
        claimed = np.concatenate(comm.alltoall(outgoing))
        found &= ~np.isin(index, claimed)
    swarm.add(base + index[found], x[found], loc.xref[found], loc.cells[found])
    num_local = int(np.count_nonzero(found))
    num_global = int(comm.allreduce(num_local))
    return GenerationResult(num_local, num_global, base, num_listed - num_global)
