"""One layer of ghost particles along rank boundaries (support for seed paper section 2.7).

Interpolators that look beyond a cell (vertex-neighbour cells, empty-cell filling across ranks)
need the particles of the cells around an owned cell, some of which other ranks own. The *vertex
halo* of a rank is the set of cells of other ranks that share at least a vertex with its owned
cells. A :class:`GhostExchange` sends copies of the particles of every owned cell to each rank
whose owned cells touch it: point-to-point messages to neighbour ranks only, first one count per
neighbour, then one float64 table per neighbour with rows ``[id, global cell, x, selected property
columns]`` (id and cell bit-cast). The receiver stores them apart from its swarm in a
:class:`GhostParticles`, indexed by halo cell, with the local (ghost) cell index where it has one.

Ghost mode: DOLFINx 0.5 refuses ``GhostMode.shared_vertex`` ("Ghost mode via vertex currently
disabled"), and with ``GhostMode.shared_facet`` a cell of another rank that touches an owned cell
in a single vertex (or an edge in 3D) is *not* a ghost cell here. The halo is therefore built from
vertex sharing itself (vertex index map + global vertex numbers), not from the mesh's ghost cells:
it is complete for any ghost mode (``none``, ``shared_facet``). Halo cells that are not local
cells carry ``local_cells == -1``; they have no geometry on this rank, only their particles, their
global vertex numbers (for adjacency) and per-cell values (:meth:`GhostExchange.exchange_cell_values`).
:func:`vertex_complete` tells whether the mesh's own ghost cells would have been enough.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from collections.abc import Sequence

import numpy as np
import numpy.typing as npt
from mpi4py import MPI

import dolfinx.la
import dolfinx.mesh

from fembase.dolfinx_compat import SCATTER_ADD
from fembase.geometry import unique_pairs
from particles.storage.swarm import PropertyLayout, Swarm

__all__ = ["GhostExchange", "GhostParticles", "exchange_ghosts", "ghost_exchange_for", "vertex_complete"]

_TAG_SETUP = 7410
_TAG_COUNT = 7401
_TAG_DATA = 7402
_TAG_VALUES = 7403
_CACHE_ATTR = "_particles_ghost_exchange"


@dataclass(frozen=True)
class GhostParticles:
    """Copies of other ranks' particles in this rank's halo cells, sorted by (cell, id).

    Attributes:
        ids: Global ids, shape=(m,), int64.
        x: Positions, shape=(m, gdim), float64.
        cells: Halo index of the cell (``num_owned_cells + j``), shape=(m,), int32, non-decreasing.
        local_cells: Local ghost cell index of that cell, -1 where it is not a local cell,
            shape=(m,), int32.
        owners: Rank that owns each particle, shape=(m,), int32.
        values: The requested property columns, shape=(m, k), float64.
        layout: Where each requested property lives in ``values``.
    """

    ids: npt.NDArray[np.int64]
    x: npt.NDArray[np.float64]
    cells: npt.NDArray[np.int32]
    local_cells: npt.NDArray[np.int32]
    owners: npt.NDArray[np.int32]
    values: npt.NDArray[np.float64]
    layout: dict[str, PropertyLayout] = field(default_factory=dict)

    @property
    def num_particles(self) -> int:
        return int(self.ids.shape[0])

    def property(self, name: str) -> npt.NDArray[np.float64]:
        """Columns of property ``name``, shape=(m, size); KeyError lists the exchanged names."""
        try:
            return self.values[:, self.layout[name].columns]
        except KeyError:
            raise KeyError(f"property {name!r} was not exchanged; exchanged: {sorted(self.layout)}") from None


class GhostExchange:
    """The vertex halo of one mesh and its communication pattern (collective constructor).

    The halo of a rank is the set of cells owned by other ranks that share a vertex with one of
    its owned cells; they get *halo indices* ``num_owned_cells + j`` (``j`` indexing
    :attr:`halo_globals`), so owned cells and halo cells form one compact index space.

    Setup (once per mesh): each rank tells the owner of every ghost vertex of its owned cells that
    it touches it; owners answer with the full list of ranks touching each such vertex (messages
    along a distributed graph built from the vertex index map); then every rank sends each
    touching rank the global index and global vertex numbers of the owned cells it touches.

    Attributes:
        neighbours: Ranks sharing at least one vertex with this rank's owned cells, sorted, int32.
        send_cells: For each neighbour rank, the owned local cells touching it (sorted, int32).
        halo_globals: Global index of each halo cell, shape=(h,), int64 (grouped by owner rank).
        halo_owners: Owner rank of each halo cell, shape=(h,), int32.
        halo_local: Local (ghost) cell index of each halo cell, -1 if the cell is not local here
            (e.g. a cell touching only in a vertex with ``GhostMode.shared_facet``), shape=(h,), int32.
        neighbour_offsets, neighbour_cells: CSR over owned cells of their vertex-neighbour cells in
            the owned + halo index space (the cell itself excluded); int64 / int32.
    """

    def __init__(self, mesh: dolfinx.mesh.Mesh, /) -> None:
        self.mesh = mesh
        self.comm: MPI.Intracomm = mesh.comm.Dup()
        tdim = mesh.topology.dim
        cmap = mesh.topology.index_map(tdim)
        self.num_owned_cells: int = cmap.size_local
        self.cell_start = int(cmap.local_range[0])
        mesh.topology.create_connectivity(tdim, 0)
        c2v = mesh.topology.connectivity(tdim, 0)
        self.num_cell_vertices = int(c2v.offsets[1] - c2v.offsets[0]) if len(c2v.offsets) > 1 else tdim + 1
        nv = self.num_cell_vertices
        local_vertices = np.asarray(c2v.array, dtype=np.int32)[: self.num_owned_cells * nv].reshape(-1, nv)
        vmap = mesh.topology.index_map(0)
        self.owned_vertex_globals = np.asarray(vmap.local_to_global(local_vertices.reshape(-1)),
                                               dtype=np.int64).reshape(-1, nv)
        touching = self._touching_ranks(vmap, local_vertices)
        self._build_halo(local_vertices, touching, cmap)

    # ------------------------------------------------------------------ point-to-point helpers
    def _exchange(self, tables: dict[int, npt.NDArray], ncols: int, dtype: type, tags: tuple[int, int],
                  sources: Sequence[int] | None = None) -> dict[int, npt.NDArray]:
        """Counts first, then data: send ``tables[r]`` to each r, receive from ``sources``."""
        comm = self.comm
        dests = sorted(tables)
        srcs = [int(r) for r in (self.neighbours if sources is None else sources)]
        send_counts = {r: np.array([tables[r].shape[0]], dtype=np.int64) for r in dests}
        recv_counts = {r: np.zeros(1, dtype=np.int64) for r in srcs}
        reqs = [comm.Irecv(recv_counts[r], source=r, tag=tags[0]) for r in srcs]
        reqs += [comm.Isend(send_counts[r], dest=r, tag=tags[0]) for r in dests]
        MPI.Request.Waitall(reqs)
        recv = {r: np.empty((int(recv_counts[r][0]), ncols), dtype=dtype) for r in srcs if recv_counts[r][0] > 0}
        reqs = [comm.Irecv(recv[r], source=r, tag=tags[1]) for r in recv]
        reqs += [comm.Isend(np.ascontiguousarray(tables[r], dtype=dtype), dest=r, tag=tags[1])
                 for r in dests if send_counts[r][0] > 0]
        MPI.Request.Waitall(reqs)
        return recv

    def _touching_ranks(self, vmap, local_vertices: npt.NDArray[np.int32]) -> npt.NDArray[np.int64]:
        """Pairs (local vertex, rank) for every rank whose owned cells contain a vertex of my owned cells."""
        rank = self.comm.rank
        mine = np.unique(local_vertices)
        num_owned_v = vmap.size_local
        ghost_owners = np.asarray(vmap.owners, dtype=np.int32)
        ghost_v = mine[mine >= num_owned_v]
        owners = ghost_owners[ghost_v - num_owned_v]
        g_of = np.asarray(vmap.local_to_global(ghost_v), dtype=np.int64)
        dests = [int(r) for r in np.unique(owners)]
        graph = self.comm.Create_dist_graph([rank], [len(dests)], dests, reorder=False)
        sources = sorted(int(s) for s in graph.Get_dist_neighbors()[0])
        graph.Free()
        claims = self._exchange({r: g_of[owners == r][:, None] for r in dests}, 1, np.int64,
                                (_TAG_SETUP, _TAG_SETUP + 1), sources)
        # The owner's view: (owned vertex, rank) for itself and every claimant.
        v_start = int(vmap.local_range[0])
        own_pairs = [np.stack([mine[mine < num_owned_v], np.full(np.count_nonzero(mine < num_owned_v), rank)], axis=1)]
        for r, t in claims.items():
            own_pairs.append(np.stack([t[:, 0] - v_start, np.full(t.shape[0], r)], axis=1))
        pairs = unique_pairs(np.concatenate(own_pairs))
        # Answer each claimant with all (global vertex, rank) pairs of the vertices it claimed.
        replies = {}
        for r, t in claims.items():
            sel = np.isin(pairs[:, 0], t[:, 0] - v_start)
            replies[r] = np.stack([pairs[sel, 0] + v_start, pairs[sel, 1]], axis=1)
        answers = self._exchange(replies, 2, np.int64, (_TAG_SETUP + 2, _TAG_SETUP + 3), dests)
        result = [pairs[np.isin(pairs[:, 0], mine)]]
        if answers:
            got = np.concatenate(list(answers.values()))
            order = np.argsort(g_of)
            pos = order[np.searchsorted(g_of, got[:, 0], sorter=order)]
            result.append(np.stack([ghost_v[pos].astype(np.int64), got[:, 1]], axis=1))
        return unique_pairs(np.concatenate(result))

    def _build_halo(self, local_vertices: npt.NDArray[np.int32], touching: npt.NDArray[np.int64], cmap) -> None:
        rank, nv, n_owned = self.comm.rank, self.num_cell_vertices, self.num_owned_cells
        touching = touching[touching[:, 1] != rank]
        # (owned cell, rank) pairs: join the cell-vertex incidence with the touching table.
        cell_of = np.repeat(np.arange(n_owned, dtype=np.int64), nv)
        vert = local_vertices.reshape(-1).astype(np.int64)
        order = np.argsort(touching[:, 0], kind="stable")
        tv, tr = touching[order, 0], touching[order, 1]
        lo, hi = np.searchsorted(tv, vert, "left"), np.searchsorted(tv, vert, "right")
        lengths = hi - lo
        idx = np.repeat(lo - (np.cumsum(lengths) - lengths), lengths) + np.arange(int(lengths.sum()))
        pairs = unique_pairs(np.stack([np.repeat(cell_of, lengths), tr[idx]], axis=1))
        self.neighbours = np.unique(pairs[:, 1]).astype(np.int32)
        self.send_cells = {int(r): pairs[pairs[:, 1] == r, 0].astype(np.int32) for r in self.neighbours}
        tables = {r: np.concatenate([(c.astype(np.int64) + self.cell_start)[:, None], self.owned_vertex_globals[c]],
                                    axis=1) for r, c in self.send_cells.items()}
        received = self._exchange(tables, 1 + nv, np.int64, (_TAG_SETUP + 4, _TAG_SETUP + 5))
        parts = [received[r] for r in sorted(received)]
        halo = np.concatenate(parts) if parts else np.empty((0, 1 + nv), dtype=np.int64)
        self.halo_globals = np.ascontiguousarray(halo[:, 0])
        self.halo_owners = np.concatenate([np.full(received[r].shape[0], r, dtype=np.int32)
                                           for r in sorted(received)]) \
            if parts else np.empty(0, dtype=np.int32)
        self._recv_slices, start = {}, 0
        for r in sorted(received):
            self._recv_slices[r] = slice(start, start + received[r].shape[0])
            start += received[r].shape[0]
        self._halo_sorter = np.argsort(self.halo_globals, kind="stable")
        ghosts = np.asarray(cmap.ghosts, dtype=np.int64)
        gsort = np.argsort(ghosts)
        pos = np.minimum(np.searchsorted(ghosts, self.halo_globals, sorter=gsort), max(ghosts.size - 1, 0))
        hit = (ghosts[gsort[pos]] == self.halo_globals) if ghosts.size else np.zeros(self.halo_globals.shape, bool)
        self.halo_local = np.where(hit, n_owned + (gsort[pos] if ghosts.size else 0), -1).astype(np.int32)
        # Vertex-neighbour CSR of owned cells in the owned + halo index space, by global vertex.
        all_vertices = np.concatenate([self.owned_vertex_globals, halo[:, 1:]])
        cells = np.repeat(np.arange(all_vertices.shape[0], dtype=np.int64), nv)
        _, vid = np.unique(all_vertices.reshape(-1), return_inverse=True)
        order = np.argsort(vid, kind="stable")
        v_sorted, c_sorted = vid[order], cells[order]
        counts = np.bincount(vid)
        v_off = np.concatenate([[0], np.cumsum(counts)])
        own_vid = vid[: n_owned * nv]
        starts, lengths = v_off[own_vid], counts[own_vid]
        idx = np.repeat(starts - (np.cumsum(lengths) - lengths), lengths) + np.arange(int(lengths.sum()))
        owner_cell = np.repeat(np.repeat(np.arange(n_owned, dtype=np.int64), nv), lengths)
        nb = unique_pairs(np.stack([owner_cell, c_sorted[idx]], axis=1))
        nb = nb[nb[:, 0] != nb[:, 1]]
        del v_sorted
        self.neighbour_offsets = np.zeros(n_owned + 1, dtype=np.int64)
        np.cumsum(np.bincount(nb[:, 0], minlength=n_owned), out=self.neighbour_offsets[1:])
        self.neighbour_cells = nb[:, 1].astype(np.int32)

    @property
    def num_halo_cells(self) -> int:
        return int(self.halo_globals.shape[0])

    def halo_index(self, global_cells: npt.NDArray[np.int64]) -> npt.NDArray[np.int32]:
        """Halo index (``num_owned_cells + j``) of halo cells given by global index; (m,) int32."""
        if global_cells.size == 0:
            return np.empty(0, dtype=np.int32)
        pos = np.searchsorted(self.halo_globals, global_cells, sorter=self._halo_sorter)
        idx = self._halo_sorter[np.minimum(pos, self.halo_globals.shape[0] - 1)]
        if not np.array_equal(self.halo_globals[idx], global_cells):
            raise RuntimeError("received a ghost particle for a cell outside the halo")
        return (self.num_owned_cells + idx).astype(np.int32)

    # ------------------------------------------------------------------ exchanges
    def exchange_cell_values(self, values: npt.ArrayLike, /) -> npt.NDArray[np.float64]:
        """Values of the halo cells from per-owned-cell values (collective).

        Args:
            values: shape=(num_owned_cells, k) (or (num_owned_cells,)), float64.

        Returns:
            shape=(num_halo_cells, k) (or (num_halo_cells,)), in halo order.
        """
        arr = np.asarray(values, dtype=np.float64)
        flat = arr.reshape(arr.shape[0], -1)
        k = flat.shape[1]
        out = np.empty((self.num_halo_cells, k))
        if self.comm.size > 1:
            recv = {r: np.empty((s.stop - s.start, k)) for r, s in self._recv_slices.items()}
            reqs = [self.comm.Irecv(recv[r], source=r, tag=_TAG_VALUES) for r in recv]
            reqs += [self.comm.Isend(np.ascontiguousarray(flat[c]), dest=r, tag=_TAG_VALUES)
                     for r, c in self.send_cells.items() if c.size]
            MPI.Request.Waitall(reqs)
            for r, s in self._recv_slices.items():
                out[s] = recv[r]
        return out.reshape((self.num_halo_cells,) + arr.shape[1:])

    def exchange(self, swarm: Swarm, names: Sequence[str] = (), /) -> GhostParticles:
        """Send copies of the particles of owned cells to every rank touching them (collective).

        Args:
            swarm: Particles on ``self.mesh`` (sorted, in owned cells).
            names: Properties whose columns travel with the copies.

        Returns:
            The particles of this rank's halo cells.
        """
        if swarm.mesh is not self.mesh:
            raise ValueError("the swarm lives on a different mesh than this GhostExchange")
        layouts = [swarm.layout(n) for n in names]
        columns = np.concatenate([np.arange(lay.start, lay.start + lay.size) for lay in layouts]).astype(np.int64) \
            if layouts else np.empty(0, dtype=np.int64)
        layout, start = {}, 0
        for lay in layouts:
            layout[lay.name] = PropertyLayout(lay.name, start, lay.size)
            start += lay.size
        gdim = swarm.gdim
        ncols = 2 + gdim + columns.shape[0]
        tables = {}
        for r, cells in self.send_cells.items():
            starts, ends = swarm.offsets[cells], swarm.offsets[cells + 1]
            lengths = ends - starts
            rows = np.repeat(starts - (np.cumsum(lengths) - lengths), lengths) + np.arange(int(lengths.sum()))
            table = np.empty((rows.shape[0], ncols))
            table[:, 0] = swarm.ids[rows].view(np.float64)
            table[:, 1] = (swarm.cells[rows].astype(np.int64) + self.cell_start).view(np.float64)
            table[:, 2 : 2 + gdim] = swarm.x[rows]
            table[:, 2 + gdim :] = swarm.properties[rows][:, columns]
            tables[r] = table
        received = self._exchange(tables, ncols, np.float64, (_TAG_COUNT, _TAG_DATA)) if self.comm.size > 1 else {}
        parts = [received[r] for r in sorted(received)]
        table = np.concatenate(parts) if parts else np.empty((0, ncols))
        owners = np.concatenate([np.full(received[r].shape[0], r, dtype=np.int32) for r in sorted(received)]) \
            if parts else np.empty(0, dtype=np.int32)
        cells = self.halo_index(np.ascontiguousarray(table[:, 1]).view(np.int64))
        ids = np.ascontiguousarray(table[:, 0]).view(np.int64)
        order = np.lexsort((ids, cells))
        cells = cells[order]
        return GhostParticles(
            ids=ids[order],
            x=np.ascontiguousarray(table[order, 2 : 2 + gdim]),
            cells=cells,
            local_cells=self.halo_local[cells - self.num_owned_cells],
            owners=owners[order],
            values=np.ascontiguousarray(table[order, 2 + gdim :]),
            layout=layout,
        )


def vertex_complete(mesh: dolfinx.mesh.Mesh, /) -> bool:
    """Whether every cell sharing a vertex with an owned cell is a local (owned or ghost) cell, on every rank.

    Counts, for each vertex, the cells containing it over all ranks (a reverse then forward
    scatter over the vertex index map of per-rank owned-cell counts) and compares with the local
    (owned + ghost) count at the vertices of owned cells. True in serial; usually False in
    parallel with ``GhostMode.shared_facet`` (the reason :class:`GhostExchange` builds its own
    vertex halo). Collective.
    """
    tdim = mesh.topology.dim
    if mesh.comm.size == 1:
        return True
    mesh.topology.create_connectivity(tdim, 0)
    c2v = mesh.topology.connectivity(tdim, 0)
    cmap = mesh.topology.index_map(tdim)
    offsets = np.asarray(c2v.offsets)
    links = np.asarray(c2v.array, dtype=np.int32)
    owned_links = links[: offsets[cmap.size_local]]
    local_links = links[: offsets[cmap.size_local + cmap.num_ghosts]]
    vmap = mesh.topology.index_map(0)
    nv = vmap.size_local + vmap.num_ghosts
    counts = dolfinx.la.vector(vmap)
    counts.array[:] = np.bincount(owned_links, minlength=nv)
    counts.scatter_reverse(SCATTER_ADD)
    counts.scatter_forward()
    touched = np.unique(owned_links)
    local = np.bincount(local_links, minlength=nv)
    ok = bool(np.all(local[touched] == np.rint(counts.array[touched]).astype(np.int64)))
    return bool(mesh.comm.allreduce(ok, op=MPI.LAND))


def ghost_exchange_for(mesh: dolfinx.mesh.Mesh, /) -> GhostExchange:
    """The :class:`GhostExchange` of ``mesh``, built on first use and cached on the mesh (collective)."""
    exchange = getattr(mesh, _CACHE_ATTR, None)
    if exchange is None:
        exchange = GhostExchange(mesh)
        setattr(mesh, _CACHE_ATTR, exchange)
    return exchange


def exchange_ghosts(swarm: Swarm, names: Sequence[str] = (), /) -> GhostParticles:
    """Ghost particles of ``swarm`` with the columns of properties ``names`` (collective).

    See :meth:`GhostExchange.exchange`; the pattern is cached on the mesh.
    """
    return ghost_exchange_for(swarm.mesh).exchange(swarm, names)
