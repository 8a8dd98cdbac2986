"""Global order of cells by a geometric key, independent of the partition (collective).

Generators number particles by the position of their cell in the global order of cell keys. The
order is computed without gathering the mesh: cells are bucketed by the first key column into one
bucket per rank (the bucket map is monotone, so buckets are ordered), each bucket is sorted
lexicographically, an exclusive scan over ranks gives bucket bases, and the offsets go back.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from mpi4py import MPI

__all__ = ["key_order_offsets"]


def _lex_order(keys: npt.NDArray[np.float64]) -> npt.NDArray[np.int64]:
    return np.lexsort(keys.T[::-1]) if keys.shape[0] else np.empty(0, dtype=np.int64)


def key_order_offsets(comm: MPI.Intracomm, keys: npt.NDArray[np.float64], counts: npt.NDArray[np.int64]
                      ) -> npt.NDArray[np.int64]:
    """Exclusive prefix sum of ``counts`` taken in the global lexicographic order of ``keys``.

    Args:
        comm: Communicator (collective).
        keys: Distinct key rows, shape=(m, k), float64; equal on every partition for the same cell.
        counts: Items per row, shape=(m,), int64.

    Returns:
        offsets, shape=(m,), int64: the number of items in all rows (on all ranks) with smaller keys.
    """
    keys = np.ascontiguousarray(keys, dtype=np.float64)
    counts = np.asarray(counts, dtype=np.int64)
    if comm.size == 1:
        order = _lex_order(keys)
        offsets = np.empty_like(counts)
        offsets[order] = np.cumsum(counts[order]) - counts[order]
        return offsets
    first = keys[:, 0] if keys.shape[0] else np.empty(0)
    lo = comm.allreduce(float(first.min(initial=np.inf)), op=MPI.MIN)
    hi = comm.allreduce(float(first.max(initial=-np.inf)), op=MPI.MAX)
    span = hi - lo if hi > lo else 1.0
    bucket = np.clip(np.floor((first - lo) / span * comm.size), 0, comm.size - 1).astype(np.int64)
    local_index = np.arange(keys.shape[0], dtype=np.int64)
    outgoing = [(keys[bucket == r], counts[bucket == r], local_index[bucket == r]) for r in range(comm.size)]
    incoming = comm.alltoall(outgoing)
    all_keys = np.concatenate([k for k, _, _ in incoming]).reshape(-1, keys.shape[1])
    all_counts = np.concatenate([c for _, c, _ in incoming])
    order = _lex_order(all_keys)
    bucket_offsets = np.empty_like(all_counts)
    bucket_offsets[order] = np.cumsum(all_counts[order]) - all_counts[order]
    base = comm.exscan(int(all_counts.sum()), op=MPI.SUM)
    bucket_offsets += 0 if base is None or comm.rank == 0 else base
    replies, start = [], 0
    for _, c, idx in incoming:
        replies.append((idx, bucket_offsets[start : start + c.shape[0]]))
        start += c.shape[0]
    offsets = np.empty_like(counts)
    for idx, off in comm.alltoall(replies):
        offsets[idx] = off
    return offsets
