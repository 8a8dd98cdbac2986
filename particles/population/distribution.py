"""How evenly the particles spread inside their cells: the particle distribution score of ASPECT's
``particle distribution score`` postprocessor (benchmarks/particle_distribution).

Each owned cell is split into ``B = g**tdim`` equal-volume sub-cells (buckets,
:class:`particles.population.subcells.SubCells`, granularity ``g``, default 2). With ``n`` particles in the
cell, ``c_b`` of them in bucket ``b`` and the ideal count ``m = n / B``:

.. math::

    E = \\sum_{b=1}^{B} (c_b - m)^2, \\qquad
    W = (n - m)^2 + (B - 1)\\,m^2 = n^2 \\frac{B - 1}{B}, \\qquad
    S_{cell} = E / W,

the squared distance of the bucket counts from the even spread, divided by that of the worst
spread (every particle in one bucket): ``S = 0`` for an even spread, ``S = 1`` for all particles
in one bucket, and ``S = 1`` for a cell without particles. The statistics over all cells of the
mesh are the minimum, the mean ``<S>``, the maximum and the standard deviation
``sqrt(sum (S - <S>)^2 / (N - 1))`` (``N`` cells; deal.II's ``mean_and_standard_deviation``).

Buckets are found in a partition-independent reference frame (for affine simplices the one of
:class:`particles.generation.maps.CellMaps`, on sorted vertices), and the global mean and standard
deviation are exactly rounded sums (``math.fsum``) of the gathered cell scores, so the statistics
are the same bits on any number of ranks.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from particles.generation.maps import CellMaps
from particles.population.subcells import SubCells
from particles.storage.swarm import Swarm

__all__ = ["DistributionScore", "cell_scores", "canonical_reference", "distribution_score", "scores_of_counts"]


@dataclass(frozen=True)
class DistributionScore:
    """Distribution score statistics over all cells of a mesh (see the module docstring)."""

    min: float
    mean: float
    max: float
    std: float


def canonical_reference(swarm: Swarm, maps: CellMaps | None = None, /) -> npt.NDArray[np.float64]:
    """Reference coordinates of the particles in a partition-independent frame, shape=(n, tdim).

    Affine simplices: the frame of :class:`CellMaps` (vertices sorted by coordinates); other
    cells: the swarm's own reference coordinates (their frame follows the input mesh).
    """
    maps = maps if maps is not None else CellMaps(swarm.mesh)
    if not maps.affine:
        return np.asarray(swarm.xref, dtype=np.float64).copy()
    return maps.pull(swarm.cells.astype(np.int64), swarm.x)


def scores_of_counts(bucket: npt.NDArray[np.int64], cells: npt.NDArray[np.int64], num_cells: int,
                     num_buckets: int) -> npt.NDArray[np.float64]:
    """Score ``E / W`` of every cell from the bucket of each particle.

    Args:
        bucket: Bucket of every particle, shape=(n,), in ``[0, num_buckets)``.
        cells: Cell of every particle, shape=(n,), in ``[0, num_cells)``.
        num_cells, num_buckets: Cells and buckets per cell.

    Returns:
        shape=(num_cells,), float64 in [0, 1]; 1 for a cell without particles.
    """
    counts = np.bincount(cells * num_buckets + bucket, minlength=num_cells * num_buckets).reshape(num_cells,
                                                                                                  num_buckets)
    n = counts.sum(axis=1).astype(np.float64)
    ideal = n / num_buckets
    error = ((counts - ideal[:, None]) ** 2).sum(axis=1)
    worst = (n - ideal) ** 2 + ideal * ideal * (num_buckets - 1)
    out = np.ones(num_cells)
    has = n > 0
    out[has] = error[has] / worst[has] if num_buckets > 1 else 0.0
    return out


def cell_scores(swarm: Swarm, granularity: int = 2, /) -> npt.NDArray[np.float64]:
    """Distribution score of every owned cell, shape=(num_owned_cells,), float64 (not collective)."""
    maps = CellMaps(swarm.mesh)
    sub = SubCells(maps.basix_cell, granularity)
    bucket = sub.index(canonical_reference(swarm, maps))
    return scores_of_counts(bucket, swarm.cells.astype(np.int64), swarm.num_owned_cells, sub.num)


def distribution_score(swarm: Swarm, granularity: int = 2, /) -> DistributionScore:
    """Minimum, mean, maximum and standard deviation of the cell scores over all cells (collective).

    The cell scores are gathered on rank 0 (8 bytes per cell) and summed exactly there, so the
    result does not depend on the rank count; every rank gets it.
    """
    local = cell_scores(swarm, granularity)
    comm = swarm.comm
    parts = comm.gather(local, root=0)
    stats = None
    if comm.rank == 0:
        scores = np.concatenate(parts)
        count = scores.shape[0]
        mean = math.fsum(scores) / count
        var = math.fsum((scores - mean) ** 2) / (count - 1) if count > 1 else 0.0
        stats = DistributionScore(float(scores.min()), mean, float(scores.max()), math.sqrt(var))
    return comm.bcast(stats, root=0)
