"""Values for particles added later, from the particles already there ("interpolate" policy)."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from particles.storage.swarm import Swarm

__all__ = ["interpolate_from_neighbours"]


def interpolate_from_neighbours(
    swarm: Swarm, rows: npt.NDArray[np.int64], columns: slice
) -> bool:
    """Set ``columns`` of the particles ``rows`` from the other (older) particles of this rank.

    A new particle takes the mean over the old particles of its cell; in a cell without old
    particles, the value of the nearest old particle. Old particles are all particles not in
    ``rows``.

    Args:
        swarm: The swarm (``cells`` of all particles valid, >= 0).
        rows: The new particles, shape=(m,), int64.
        columns: Column range in ``swarm.properties``.

    Returns:
        False (and nothing set) if this rank has no old particle, else True.
    """
    n = swarm.num_particles
    is_new = np.zeros(n, dtype=bool)
    is_new[rows] = True
    old = np.flatnonzero(~is_new)
    if old.shape[0] == 0:
        return False
    if rows.shape[0] == 0:
        return True
    values = swarm.properties[:, columns]
    ncells = int(max(swarm.cells.max(initial=-1), 0)) + 1
    old_cells = swarm.cells[old].astype(np.int64)
    counts = np.bincount(old_cells, minlength=ncells)
    sums = np.stack([np.bincount(old_cells, weights=values[old, k], minlength=ncells)
                     for k in range(values.shape[1])], axis=1)
    new_cells = swarm.cells[rows].astype(np.int64)
    in_cell = counts[new_cells] > 0
    result = np.empty((rows.shape[0], values.shape[1]))
    result[in_cell] = sums[new_cells[in_cell]] / counts[new_cells[in_cell], None]
    lonely = np.flatnonzero(~in_cell)
    if lonely.shape[0]:
        from scipy.spatial import cKDTree  # here, not at import: scipy.spatial is 23 MB a process
        _, nearest = cKDTree(swarm.x[old]).query(swarm.x[rows[lonely]])
        result[lonely] = values[old[nearest]]
    swarm.properties[rows, columns] = result
    return True
