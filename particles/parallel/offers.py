"""Who keeps an unlocated particle: the offer rounds of :mod:`particles.parallel.migration`.

A rank offers a particle no local cell contains to every other rank whose owned bounding box
contains it, with the number of such candidates. A sole candidate decides alone: it keeps the
particle if one of its owned cells contains it, else counts it lost. For particles with several
candidates, the candidates answer found/not found and the offering rank tells each candidate
whether it is the lowest finder (or counts the particle lost if none found it).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from mpi4py import MPI

import dolfinx.mesh

from fembase.geometry import OwnedLocation, locate_owned
from particles.parallel.exchange import known_exchange
from particles.storage.swarm import Swarm

__all__ = ["Kept", "append_kept", "offers_by_rank", "settle_offers"]

Kept = list[tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.int32]]]
"""Offered particles a rank keeps, per batch: rows of a packed table
(:func:`particles.storage.row_kernels.pack_by_slot`), their reference positions shape=(m, tdim) and
the owned cells shape=(m,) found here."""


def offers_by_rank(inside: npt.NDArray[np.bool_]) -> dict[int, npt.NDArray[np.int64]]:
    """{rank: the particles offered to it} from ``inside`` (shape=(m, size), bool)."""
    return {int(r): np.flatnonzero(inside[:, r]) for r in np.flatnonzero(inside.any(axis=0))}


def settle_offers(
    comm: MPI.Intracomm,
    mesh: dolfinx.mesh.Mesh,
    swarm: Swarm,
    inside: npt.NDArray[np.bool_],
    received: dict[int, tuple[npt.NDArray[np.float64], npt.NDArray[np.int64]]],
    tags: tuple[int, int],
) -> tuple[Kept, int]:
    """Settle offered particles point-to-point between the pairs of an offer round (see the module).

    Args:
        comm: The communicator of the offer round.
        mesh: The mesh whose owned cells are searched.
        swarm: The particles of this rank (for the dimensions and the cell geometry).
        inside: To which ranks this rank offered each of its ``m`` particles (in row order per
            rank), shape=(m, size).
        received: Per source, the offered rows (packed) and their number of candidates.
        tags: Message tags of the answers and of the verdicts.

    Returns:
        The kept rows per batch and the particles lost here.
    """
    num_candidates = inside.sum(axis=1)
    lost = 0
    kept: Kept = []
    shared: dict[int, tuple[npt.NDArray[np.int64], OwnedLocation]] = {}
    answers: dict[int, npt.NDArray[np.float64]] = {}
    for src in sorted(received):
        t, candidates = received[src]
        loc = locate_owned(mesh, t[:, 2: 2 + swarm.gdim], geometry=swarm.geometry)
        sole = candidates == 1
        found = sole & (loc.cells >= 0)
        kept.append((t[found], loc.xref[found], loc.cells[found]))
        lost += int(np.count_nonzero(sole & (loc.cells < 0)))
        if (~sole).any():
            shared[src] = (np.flatnonzero(~sole), loc)
            answers[src] = (loc.cells[~sole] >= 0).astype(np.float64)[:, None]
    multi = {r: idx[num_candidates[idx] > 1] for r, idx in offers_by_rank(inside).items()}
    multi = {r: idx for r, idx in multi.items() if idx.size}
    replies = known_exchange(comm, answers, {r: idx.shape[0] for r, idx in multi.items()}, tags[0])
    keeper = np.full(inside.shape[0], comm.size, dtype=np.int64)
    for r in sorted(replies, reverse=True):
        keeper[multi[r][replies[r][:, 0] > 0]] = r
    lost += int(np.count_nonzero((keeper == comm.size) & (num_candidates > 1)))
    decisions = {r: (keeper[idx] == r).astype(np.float64)[:, None] for r, idx in multi.items()}
    verdicts = known_exchange(comm, decisions, {r: a.shape[0] for r, a in answers.items()}, tags[1])
    for src in sorted(verdicts):
        rows_shared, loc = shared[src]
        sel = rows_shared[verdicts[src][:, 0] > 0]
        kept.append((received[src][0][sel], loc.xref[sel], loc.cells[sel]))
    return kept, lost


def append_kept(swarm: Swarm, kept: Kept) -> int:
    """Append the kept rows of packed tables with the reference positions and owned cells found
    here (the offering rank did not know them). Returns how many."""
    n_in = 0
    for t, xref, cells in kept:
        if t.shape[0]:
            t = t.copy()
            t[:, 2 + swarm.gdim: 2 + swarm.gdim + swarm.tdim] = xref
            swarm.append_packed(t, np.asarray(cells, dtype=np.int32))
            n_in += t.shape[0]
    return n_in
