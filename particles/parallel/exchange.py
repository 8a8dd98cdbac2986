"""Point-to-point exchanges of float64 tables, the message patterns of :mod:`particles.parallel.migration`.

Every table has one row per particle (or answer) and the same number of columns on all ranks.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from mpi4py import MPI

__all__ = ["known_exchange", "neighbour_exchange", "sparse_exchange"]


def neighbour_exchange(comm: MPI.Intracomm, neighbours: npt.NDArray[np.int32], table: npt.NDArray[np.float64],
                       offsets: npt.NDArray[np.int64], tag: int) -> dict[int, npt.NDArray[np.float64]]:
    """Send rows ``offsets[s]:offsets[s + 1]`` of ``table`` to ``neighbours[s]`` (one message each,
    empty ones included); return {source: table} of the non-empty ones received from the
    neighbours. The receiver learns a message's size from the message itself (matched probe), so
    one round trip suffices. Every neighbour must call it with this rank among its neighbours."""
    ncols = table.shape[1]
    reqs = [comm.Isend(table[offsets[s]: offsets[s + 1]], dest=int(r), tag=tag) for s, r in enumerate(neighbours)]
    recv: dict[int, npt.NDArray[np.float64]] = {}
    status = MPI.Status()
    for r in neighbours:
        message = comm.Mprobe(source=int(r), tag=tag, status=status)
        buffer = np.empty((status.Get_count(MPI.DOUBLE) // ncols, ncols))
        message.Recv(buffer)
        if buffer.shape[0]:
            recv[int(r)] = buffer
    MPI.Request.Waitall(reqs)
    return recv


def sparse_exchange(comm: MPI.Intracomm, tables: dict[int, npt.NDArray[np.float64]], ncols: int, tag: int
                    ) -> dict[int, npt.NDArray[np.float64]]:
    """Send tables[r] (``ncols`` columns) to any rank r (collective; counts by alltoall). Returns
    {source: table}."""
    send_counts = np.zeros(comm.size, dtype=np.int64)
    for r, t in tables.items():
        send_counts[r] = t.shape[0]
    recv_counts = np.empty(comm.size, dtype=np.int64)
    comm.Alltoall(send_counts, recv_counts)
    recv = {r: np.empty((int(recv_counts[r]), ncols)) for r in range(comm.size) if recv_counts[r] > 0}
    reqs = [comm.Irecv(recv[r], source=r, tag=tag) for r in recv]
    reqs += [comm.Isend(np.ascontiguousarray(tables[r]), dest=r, tag=tag) for r in tables if tables[r].shape[0]]
    MPI.Request.Waitall(reqs)
    return recv


def known_exchange(comm: MPI.Intracomm, tables: dict[int, npt.NDArray[np.float64]], expected: dict[int, int],
                   tag: int) -> dict[int, npt.NDArray[np.float64]]:
    """Send one-column tables[r] to rank r and receive ``expected[r]`` rows from rank r, when both
    sides know the sizes. Returns {source: table} of the non-empty ones."""
    recv = {r: np.empty((n, 1)) for r, n in expected.items() if n > 0}
    reqs = [comm.Irecv(recv[r], source=r, tag=tag) for r in recv]
    reqs += [comm.Isend(np.ascontiguousarray(t), dest=r, tag=tag) for r, t in tables.items() if t.shape[0]]
    MPI.Request.Waitall(reqs)
    return recv
