"""Hand particles to the rank that owns their cell (seed paper section 2.4, between subdomains).

After particles moved, each one sits in an owned cell (nothing to do), in a ghost cell (its owner
is known from the cell index map: send it there), or in no local cell at all (``cells == -1``).
Ghost-cell particles travel by non-blocking point-to-point messages to neighbour ranks only: one
float64 buffer per neighbour (empty ones too; the receiver reads the size from the matched probe),
packed by a compiled kernel, whose rows hold the particle id, the *global* cell index as a hint,
the position, the reference position, every property column and the swarm's stage table (ids and
cell indices are carried bit-for-bit as int64 reinterpreted as float64). The receiver turns the
global cell index into its local owned index and appends the batch in one compiled pass; the
sender only marks the departed rows. One sort at the end places the new rows and drops
the departed ones, so apart from that sort a migration costs O(particles sent + received).

Unlocated particles take a global fallback: every rank publishes the bounding box of its owned
cells once; a particle goes to all other ranks whose box contains it (the only collective step,
an Alltoall of counts); a sole candidate keeps it if one of its owned cells contains it; with
several candidates, they answer found/not found and the lowest rank that found it keeps it.
Particles nobody found are removed and counted as lost.

Integrator stage data travels in the stage table, so a particle that changes rank in the middle
of a Runge-Kutta step carries its stages with it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from mpi4py import MPI

import dolfinx.mesh

from fembase.geometry import owned_box
from particles.parallel.exchange import neighbour_exchange, sparse_exchange
from particles.parallel.offers import Kept, append_kept, offers_by_rank, settle_offers
from particles.storage.row_kernels import pack_by_slot
from particles.storage.swarm import Swarm

__all__ = ["MigrationStats", "Migrator", "migrate", "migrator_for"]

_TAG_DATA = 7302
_TAG_REPLY = 7303
_TAG_NB_REPLY = 7304
_TAG_NB_VERDICT = 7305
_CACHE_ATTR = "_particles_migrator"


@dataclass(frozen=True)
class MigrationStats:
    """Counts of one :func:`migrate` call (local to this rank, and global totals).

    Attributes:
        sent: Particles this rank sent to neighbours (ghost-cell particles).
        received: Particles this rank received (from neighbours and through the fallback).
        fallback_sent: Unlocated particles this rank offered to candidate ranks (each counted once).
        lost: Particles this rank declared lost because no rank contains them (the offering rank,
            or the sole candidate rank of the fallback that did not find it).
        global_sent, global_received, global_fallback_sent, global_lost: Sums over all ranks.
    """

    sent: int
    received: int
    fallback_sent: int
    lost: int
    global_sent: int
    global_received: int
    global_fallback_sent: int
    global_lost: int


def _pack(swarm: Swarm, rows: npt.NDArray[np.int64], slots: npt.NDArray[np.int64], nslots: int,
          hints: npt.NDArray[np.float64]) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.int64]]:
    """Rows of particles as one float64 table [id, hint, x, xref, properties, stage] grouped by
    destination slot (:func:`particles.storage.row_kernels.pack_by_slot`), with the first row of every slot."""
    stage = swarm.stage if swarm.stage_width else np.empty((swarm.num_particles, 0))
    return pack_by_slot(np.ascontiguousarray(rows, dtype=np.int64), np.ascontiguousarray(slots, dtype=np.int64),
                        nslots, swarm.ids.view(np.float64), np.ascontiguousarray(hints, dtype=np.float64),
                        swarm.x, swarm.xref, swarm.properties, stage)


@dataclass(frozen=True)
class _Offer:
    """Unlocated particles offered to neighbours: their rows, shape=(m,), and to which ranks each
    goes, shape=(m, size), bool."""

    rows: npt.NDArray[np.int64]
    inside: npt.NDArray[np.bool_]


def _neighbour_ranks(comm: MPI.Intracomm, ghost_owners: npt.NDArray[np.int32]) -> npt.NDArray[np.int32]:
    """Ranks that own one of my ghost cells or ghost one of my cells, sorted (collective)."""
    rank = comm.rank
    out_ranks = np.unique(ghost_owners)
    out_ranks = out_ranks[out_ranks != rank]
    # The ranks that ghost my cells: let MPI invert the "I ghost a cell of" graph.
    graph = comm.Create_dist_graph([rank], [len(out_ranks)], [int(r) for r in out_ranks], reorder=False)
    sources, _ = graph.Get_dist_neighbors()[:2]
    graph.Free()
    return np.union1d(out_ranks, np.asarray(sources, dtype=np.int32)).astype(np.int32)


class Migrator:
    """Communication pattern of one mesh, computed once (collective constructor).

    The messages go point-to-point (:mod:`particles.parallel.exchange`); who keeps an unlocated particle
    is settled by offer rounds (:mod:`particles.parallel.offers`).

    Attributes:
        neighbours: Ranks that own one of my ghost cells or ghost one of my cells, sorted, int32.
        owned_boxes: Bounding box of the owned cells of every rank, shape=(size, 2, gdim); empty
            ranks have lower > upper.
    """

    def __init__(self, mesh: dolfinx.mesh.Mesh, /) -> None:
        self.mesh = mesh
        self.comm: MPI.Intracomm = mesh.comm.Dup()  # private tag space for the messages below
        cmap = mesh.topology.index_map(mesh.topology.dim)
        self.num_owned_cells = cmap.size_local
        self.cell_range = tuple(int(r) for r in cmap.local_range)
        self.ghost_owners = np.asarray(cmap.owners, dtype=np.int32)
        self.ghost_globals = np.asarray(cmap.ghosts, dtype=np.int64)
        self.neighbours = _neighbour_ranks(self.comm, self.ghost_owners)
        self.owned_boxes = self._gather_boxes(mesh.geometry.dim)
        self._is_neighbour = np.zeros(self.comm.size, dtype=bool)
        self._is_neighbour[self.neighbours] = True
        # Per ghost cell: the position of its owner among the neighbours, and its global index as
        # the float64 bits the messages carry.
        self._slot_of_rank = np.full(self.comm.size, -1, dtype=np.int64)
        self._slot_of_rank[self.neighbours] = np.arange(self.neighbours.shape[0])
        self._ghost_slots = self._slot_of_rank[self.ghost_owners]
        self._ghost_hints = np.ascontiguousarray(self.ghost_globals, dtype=np.int64).view(np.float64)

    def moved(self) -> None:
        """Gather the ranks' bounding boxes again after the mesh's nodes moved (collective)."""
        self.owned_boxes = self._gather_boxes(self.mesh.geometry.dim)

    def _gather_boxes(self, gdim: int) -> npt.NDArray[np.float64]:
        box = owned_box(self.mesh)
        boxes = np.empty((self.comm.size, 2, gdim))
        self.comm.Allgather(box, boxes)
        return boxes

    def _neighbour_exchange(self, table: npt.NDArray[np.float64], offsets: npt.NDArray[np.int64]
                            ) -> dict[int, npt.NDArray[np.float64]]:
        """Send rows ``offsets[s]:offsets[s + 1]`` of ``table`` to neighbour ``s``; return {source:
        table} of the non-empty ones received (:func:`particles.parallel.exchange.neighbour_exchange`)."""
        return neighbour_exchange(self.comm, self.neighbours, table, offsets, _TAG_DATA)

    # ------------------------------------------------------------------ migration
    def migrate(self, swarm: Swarm, /, *, sort: bool = True) -> MigrationStats:
        """Move ghost-cell particles to their owners and resolve unlocated ones (collective).

        Leaving particles are only marked (:meth:`Swarm.discard_rows`) and arriving ones appended
        (:meth:`Swarm.append_rows`); one sort at the end places the new rows and drops the marked
        ones, so the work besides that sort is O(particles sent + received). An unlocated particle
        whose candidate ranks (owned bounding box contains it) are all neighbours is offered to
        them in the same messages as the ghost-cell particles and decided point-to-point. The only
        collective in the common case is one allreduce of five counts; the global fallback (an
        Alltoall and a second allreduce) runs only when some particle has a candidate rank that is
        not a neighbour.

        Args:
            swarm: Particles on ``self.mesh``; ``cells`` may hold owned, ghost or -1 entries.
            sort: Sort the swarm at the end. False leaves the arrived rows unsorted and the
                departed ones marked, for a caller that sorts next anyway.

        Returns:
            Local and global counts of sent, received, fallback and lost particles.
        """
        if swarm.mesh is not self.mesh:
            raise ValueError("the swarm lives on a different mesh than this Migrator")
        ncols = 2 + swarm.gdim + swarm.tdim + swarm.num_property_columns + swarm.stage_width
        outside = swarm.outside_rows()
        cells = swarm.cells[outside]
        ghost_rows = outside[cells >= self.num_owned_cells]
        unlocated_rows = outside[cells < 0]
        sent = int(ghost_rows.shape[0])
        if self.comm.size == 1:
            swarm.discard_rows(unlocated_rows)
            lost = int(unlocated_rows.shape[0])
            if sort:
                swarm.sort()
            return MigrationStats(sent, 0, 0, lost, sent, 0, 0, lost)

        offer, global_rows, lost = self._split_unlocated(swarm, unlocated_rows)
        incoming = self._neighbour_exchange(*self._outgoing(swarm, ghost_rows, offer))
        swarm.discard_rows(ghost_rows)
        swarm.discard_rows(offer.rows)
        received, offers_in = self._receive(swarm, incoming)
        nb_lost = 0
        if offer.rows.size or offers_in:
            kept, nb_lost = self._decide(swarm, offer.inside, offers_in, (_TAG_NB_REPLY, _TAG_NB_VERDICT))
            received += append_kept(swarm, kept)
        lost += nb_lost
        fallback_sent = int(offer.rows.shape[0])

        first = _sum_over_ranks(self.comm, [sent, received, fallback_sent, lost, global_rows.shape[0]])
        if first[4] > 0:
            fb_sent, fb_received, fb_lost = self._fallback(swarm, global_rows, ncols)
            fallback_sent += fb_sent
            received += fb_received
            lost += fb_lost
            totals = _sum_over_ranks(self.comm, [sent, received, fallback_sent, lost])
        else:
            totals = first[:4]
        if sort:
            swarm.sort()
        return MigrationStats(sent, received, fallback_sent, lost, *(int(t) for t in totals))

    def _split_unlocated(self, swarm: Swarm, rows: npt.NDArray[np.int64]
                         ) -> tuple[_Offer, npt.NDArray[np.int64], int]:
        """Sort the unlocated ``rows``: those whose candidate ranks are all neighbours are offered to
        them with the neighbour messages, those with another candidate go to the global fallback,
        those without a candidate are discarded as lost. Returns the offer, the fallback rows
        and the number lost."""
        if not rows.size:
            return _Offer(rows, np.zeros((0, self.comm.size), dtype=bool)), rows, 0
        inside = self._box_candidates(swarm.x[rows])
        num_candidates = inside.sum(axis=1)
        local = np.all(~inside | self._is_neighbour[None, :], axis=1) & (num_candidates > 0)
        swarm.discard_rows(rows[num_candidates == 0])
        return (_Offer(rows[local], inside[local]), rows[~local & (num_candidates > 0)],
                int(np.count_nonzero(num_candidates == 0)))

    def _outgoing(self, swarm: Swarm, ghost_rows: npt.NDArray[np.int64], offer: _Offer
                  ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.int64]]:
        """One table grouped by neighbour, with the first row of each: the ghost-cell particles
        (global cell as the hint), then one copy of each offered particle per candidate (-(number
        of candidates) as the hint)."""
        g = swarm.cells[ghost_rows] - self.num_owned_cells
        rows, slots, hints = ghost_rows, self._ghost_slots[g], self._ghost_hints[g]
        if offer.rows.size:
            which, ranks = np.nonzero(offer.inside)
            minus = -offer.inside.sum(axis=1).astype(np.int64)
            rows = np.concatenate([rows, offer.rows[which]])
            slots = np.concatenate([slots, self._slot_of_rank[ranks]])
            hints = np.concatenate([hints, minus[which].view(np.float64)])
        return _pack(swarm, rows, slots, self.neighbours.shape[0], hints)

    def _receive(self, swarm: Swarm, incoming: dict[int, npt.NDArray[np.float64]]
                 ) -> tuple[int, dict[int, tuple[npt.NDArray[np.float64], npt.NDArray[np.int64]]]]:
        """Append the particles handed to this rank's cells; return how many, and per source the
        offered rows with their number of candidates."""
        offers_in: dict[int, tuple[npt.NDArray[np.float64], npt.NDArray[np.int64]]] = {}
        handed = []
        for src in sorted(incoming):
            t = incoming[src]
            hint = np.ascontiguousarray(t[:, 1]).view(np.int64)
            offered = hint < 0
            if not offered.any():
                handed.append(t)
                continue
            handed.append(t[~offered])
            offers_in[src] = (t[offered], -hint[offered])
        if not handed:
            return 0, offers_in
        table = np.concatenate(handed) if len(handed) > 1 else handed[0]
        local_cells = np.ascontiguousarray(table[:, 1]).view(np.int64) - self.cell_range[0]
        if np.any((local_cells < 0) | (local_cells >= self.num_owned_cells)):
            raise RuntimeError("migration received a particle for a cell this rank does not own")
        swarm.append_packed(table, local_cells.astype(np.int32))
        return table.shape[0], offers_in

    def _box_candidates(self, x: npt.NDArray[np.float64]) -> npt.NDArray[np.bool_]:
        """Other ranks whose owned bounding box contains each point, shape=(m, size), bool."""
        lower, upper = self.owned_boxes[:, 0, :], self.owned_boxes[:, 1, :]
        finite = self.owned_boxes[np.isfinite(self.owned_boxes)]
        tol = 1e-12 * max(1.0, float(np.abs(finite).max(initial=1.0)))
        inside = np.all((x[:, None, :] >= lower[None] - tol) & (x[:, None, :] <= upper[None] + tol), axis=2)
        inside[:, self.comm.rank] = False
        return inside

    def _fallback(self, swarm: Swarm, rows: npt.NDArray[np.int64], ncols: int) -> tuple[int, int, int]:
        """Global search for the unlocated particles in ``rows`` (collective). Returns (offered,
        received, lost).

        Round 1 (the only collective one) offers each particle to every other rank whose owned box
        contains it, together with the number of candidates; :meth:`_decide` settles the rest
        point-to-point.
        """
        inside = self._box_candidates(swarm.x[rows])
        num_candidates = inside.sum(axis=1)
        table, _ = _pack(swarm, rows, np.zeros(rows.shape[0], dtype=np.int64), 1,
                         num_candidates.astype(np.int64).view(np.float64))
        swarm.discard_rows(rows)
        offers = offers_by_rank(inside)
        received = sparse_exchange(self.comm, {r: table[idx] for r, idx in offers.items()}, ncols, _TAG_DATA)
        decided = {src: (t, np.ascontiguousarray(t[:, 1]).view(np.int64)) for src, t in received.items()}
        kept, lost = self._decide(swarm, inside, decided, (_TAG_REPLY, _TAG_REPLY))
        lost += int(np.count_nonzero(num_candidates == 0))
        offered = int(np.count_nonzero(num_candidates > 0))
        return offered, append_kept(swarm, kept), lost

    def _decide(
        self,
        swarm: Swarm,
        inside: npt.NDArray[np.bool_],
        received: dict[int, tuple[npt.NDArray[np.float64], npt.NDArray[np.int64]]],
        tags: tuple[int, int],
    ) -> tuple[Kept, int]:
        """Settle offered particles point-to-point between the pairs of an offer round
        (:func:`particles.parallel.offers.settle_offers`). Returns the kept rows (table, xref, owned cell)
        per batch and the particles lost here."""
        return settle_offers(self.comm, self.mesh, swarm, inside, received, tags)


def _sum_over_ranks(comm: MPI.Comm, counts: list[int]) -> npt.NDArray[np.int64]:
    """Element-wise sum of ``counts`` over all ranks (collective; one buffer Allreduce, no pickling)."""
    local = np.array(counts, dtype=np.int64)
    total = np.empty_like(local)
    comm.Allreduce(local, total, op=MPI.SUM)
    return total


def migrator_for(mesh: dolfinx.mesh.Mesh, /) -> Migrator:
    """The :class:`Migrator` of ``mesh``, built on first use and cached on the mesh (collective)."""
    migrator = getattr(mesh, _CACHE_ATTR, None)
    if migrator is None:
        migrator = Migrator(mesh)
        setattr(mesh, _CACHE_ATTR, migrator)
    return migrator


def migrate(swarm: Swarm, /, *, migrator: Migrator | None = None, sort: bool = True) -> MigrationStats:
    """Send every particle to the rank owning its cell; drop particles outside the domain (collective).

    Particles in ghost cells go to the ghost's owner (neighbour messages); particles with
    ``cells == -1`` go through the bounding-box fallback; the rest stay. In serial, particles with
    ``cells == -1`` are removed as lost. Afterwards every particle is in an owned cell of its rank.

    Args:
        swarm: The particles.
        migrator: The mesh's communication pattern; by default :func:`migrator_for` (cached).
        sort: Sort the swarm at the end (see :meth:`Migrator.migrate`).

    Returns:
        Local and global counts.
    """
    return (migrator or migrator_for(swarm.mesh)).migrate(swarm, sort=sort)
