"""Particle counts per cell from cell weights, independent of the partition (collective).

Cell ``K`` with weight ``w_K`` (e.g. the integral of the density over ``K``) of total ``W`` expects
``c_K = N w_K / W`` particles. It gets ``floor(c_K)`` particles, and the ``R = N - sum floor(c_K)``
remaining particles go to ``R`` distinct cells drawn with probabilities proportional to the
fractional parts (weighted sampling without replacement by exponential races: cell priority
``-log(u_K) / frac_K`` with ``u_K`` from the cell's random stream; the ``R`` smallest win). So the
expected count of every cell is exactly ``c_K`` and the count never deviates from it by 1 or more.
Unlike a per-rank cumulative-weight search (ASPECT), nothing depends on the partition: ``W`` is the
correctly rounded exact sum of all weights, and the ``R`` smallest priorities are found by a global
bisection over their bit patterns.
"""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import numpy.typing as npt
from mpi4py import MPI

__all__ = ["allocate_counts", "exact_global_sum"]


def _exact_local_sum(values: npt.NDArray[np.float64]) -> Fraction:
    """Exact sum of finite float64 values as a Fraction (vectorised by binary exponent)."""
    mant, expo = np.frexp(values)
    ints = (mant * 2.0**53).astype(np.int64)
    total = Fraction(0)
    for e in np.unique(expo):
        sel = ints[expo == e]
        hi, lo = sel >> 26, sel & ((1 << 26) - 1)
        total += Fraction((int(hi.sum()) << 26) + int(lo.sum())) * Fraction(2) ** (int(e) - 53)
    return total


def exact_global_sum(comm: MPI.Intracomm, values: npt.NDArray[np.float64]) -> float:
    """Correctly rounded sum of ``values`` over all ranks: the same float on any partition."""
    parts = comm.allgather(_exact_local_sum(np.asarray(values, dtype=np.float64)))
    return float(sum(parts, Fraction(0)))


def _count_not_above(comm: MPI.Intracomm, bits: npt.NDArray[np.int64], threshold: int) -> int:
    return int(comm.allreduce(int(np.count_nonzero(bits <= threshold)), op=MPI.SUM))


def allocate_counts(comm: MPI.Intracomm, weights: npt.NDArray[np.float64], total: int,
                    uniform: npt.NDArray[np.float64]) -> npt.NDArray[np.int64]:
    """Particles per cell (collective).

    Args:
        comm: Communicator.
        weights: Non-negative cell weights of this rank's owned cells, shape=(m,), float64.
        total: Global number of particles N.
        uniform: One number in (0, 1) per cell from the cell's random stream, shape=(m,).

    Returns:
        counts, shape=(m,), int64, summing to ``total`` over all ranks.
    """
    weights = np.asarray(weights, dtype=np.float64)
    if np.any(~np.isfinite(weights)) or np.any(weights < 0):
        raise ValueError("cell weights must be finite and non-negative (is the density negative?)")
    wsum = exact_global_sum(comm, weights)
    if total > 0 and wsum <= 0:
        raise ValueError("the density integrates to zero over the domain")
    expected = total * weights / wsum if total > 0 else np.zeros_like(weights)
    counts = np.floor(expected).astype(np.int64)
    remainder = total - int(comm.allreduce(int(counts.sum()), op=MPI.SUM))
    if remainder < 0:
        raise RuntimeError("round-off made the floor counts exceed the total")
    if remainder == 0:
        return counts
    frac = expected - counts
    with np.errstate(divide="ignore"):
        priority = np.where(frac > 0, -np.log(np.maximum(uniform, 2.0**-60)) / frac, np.inf)
    bits = priority.view(np.int64)  # non-negative floats order like their bit patterns
    lo, hi = -1, int(np.float64(np.inf).view(np.int64))
    if _count_not_above(comm, bits, hi - 1) < remainder:
        raise RuntimeError("fewer cells with a fractional expected count than remaining particles")
    while hi - lo > 1:  # smallest threshold t with count(bits <= t) >= remainder
        mid = (lo + hi) // 2
        if _count_not_above(comm, bits, mid) >= remainder:
            hi = mid
        else:
            lo = mid
    if _count_not_above(comm, bits, hi) != remainder:
        raise RuntimeError("tie between cell priorities; change the seed")
    counts += (bits <= hi).astype(np.int64)
    return counts
