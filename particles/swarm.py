"""Cell-sorted particle storage on a DOLFINx mesh (seed paper section 2.1).

ASPECT keeps particles in a multimap keyed by cell. Here the same invariant is kept with flat
arrays sorted by the owning local cell, plus CSR offsets: the particles of cell ``K`` are the
contiguous rows ``offsets[K]:offsets[K + 1]`` of every per-particle array. The order is restored
by a counting sort (two compiled passes, stable, O(n + cells)); the relocation kernel of
:mod:`particles.transport` counts the particles per cell while it relocates them, so the sort
after a move only has the second pass to do.

Particles live only in cells this rank owns (local indices ``0 <= K < num_owned_cells``). Code that
moves particles may temporarily leave a particle in a ghost cell (``K >= num_owned_cells``) or
unlocated (``K == -1``); :meth:`Swarm.sort` restores the invariant only for owned cells, and the
migration step (``particles.migration``) hands the others to their owners.

The per-particle arrays are views of buffers with spare rows: rows arriving from other ranks are
appended in O(rows) and rows leaving are only marked (:data:`particles.kernels.DEAD`); the next
:meth:`Swarm.sort` places the new rows and drops the marked ones in the same pass, so a migration
costs O(particles sent + received) plus that one sort. The sort writes into the buffers the
previous sort released (fresh memory costs page faults that dominate a sort).
"""

from __future__ import annotations

import sys
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from mpi4py import MPI

import dolfinx.mesh

from fembase.geometry import CellGeometry
from particles.kernels import (
    DEAD, append_packed, count_buckets, gather_particles, rows_outside, scatter_particles, sort_destinations,
)

__all__ = ["PropertyLayout", "Swarm"]

_FIELDS = ("_ids", "_x", "_xref", "_cells", "_props", "_stage")


@dataclass(frozen=True)
class PropertyLayout:
    """Where a named property lives in the property table.

    Attributes:
        name: Property name.
        start: First column in :attr:`Swarm.properties`.
        size: Number of scalar columns (1 for a scalar, gdim for a vector, gdim**2 for a tensor).
    """

    name: str
    start: int
    size: int

    @property
    def columns(self) -> slice:
        return slice(self.start, self.start + self.size)


def _capacity_for(n: int) -> int:
    return n + n // 8 + 16


class Swarm:
    """Particles on a DOLFINx mesh, kept sorted by the local cell that contains them.

    Per particle (``n`` local particles):

    - ``ids``: global id, shape=(n,), int64, unique across ranks;
    - ``x``: physical position, shape=(n, gdim), float64;
    - ``xref``: position in the reference cell of ``cells``, shape=(n, tdim), float64;
    - ``cells``: local cell index, shape=(n,), int32, non-decreasing;
    - ``properties``: named scalar columns, shape=(n, num_columns), float64.

    These are views of the swarm's buffers: writing into them changes the particles; assigning a
    new array of the same length replaces the column. A sort moves the particles into other
    buffers, so a view taken before a sort keeps the old order (it is never overwritten).

    Args:
        mesh: The DOLFINx mesh (any cell type DOLFINx supports with an affine or non-affine map).
    """

    def __init__(self, mesh: dolfinx.mesh.Mesh, /) -> None:
        self.mesh = mesh
        self.comm: MPI.Intracomm = mesh.comm
        self.gdim: int = mesh.geometry.dim
        self.tdim: int = mesh.topology.dim
        cell_map = mesh.topology.index_map(self.tdim)
        self.num_owned_cells: int = cell_map.size_local
        self.num_local_cells: int = cell_map.size_local + cell_map.num_ghosts
        self._n = 0
        self._ids = np.empty(0, dtype=np.int64)
        self._x = np.empty((0, self.gdim), dtype=np.float64)
        self._xref = np.empty((0, self.tdim), dtype=np.float64)
        self._cells = np.empty(0, dtype=np.int32)
        self._props = np.empty((0, 0), dtype=np.float64)
        self._stage = np.empty((0, 0), dtype=np.float64)
        self._stage_width = 0
        self._layout: dict[str, PropertyLayout] = {}
        self.offsets = np.zeros(self.num_owned_cells + 1, dtype=np.int64)
        self._geometry: CellGeometry | None = None
        self._spare: tuple[npt.NDArray, ...] | None = None
        # Rows per sort bucket (owned cells, then ghost/unlocated, then discarded) and whether the
        # rows are in bucket order, when known from the last relocation; None: count in sort().
        self._pending: tuple[npt.NDArray[np.int64], bool] | None = None
        # The rows in a ghost cell or unlocated (a superset: discarded ones are filtered out), when
        # known from the last relocation; None: scan in outside_rows(). Valid while _pending is.
        self._outside: npt.NDArray[np.int64] | None = None
        self._dest = np.empty(0, dtype=np.int64)  # sort destinations, reused

    @property
    def geometry(self) -> CellGeometry:
        """Per-cell geometry data of the mesh (affine maps, vertex-to-cell adjacency, BB tree),
        built on first use and shared by evaluation, transport and generators."""
        if self._geometry is None:
            self._geometry = CellGeometry(self.mesh)
        return self._geometry

    # ------------------------------------------------------------------ per-particle arrays
    def _column(self, name: str) -> npt.NDArray:
        return getattr(self, name)[: self._n]

    def _set_column(self, name: str, value: npt.ArrayLike, dtype: type, width: int | None) -> None:
        shape = (self._n,) if width is None else (self._n, width)
        arr = np.ascontiguousarray(value, dtype=dtype)
        if arr.shape != shape:
            raise ValueError(f"expected shape {shape} for {name[1:]}, got {arr.shape}")
        self._pending = None
        setattr(self, name, arr)

    @property
    def ids(self) -> npt.NDArray[np.int64]:
        return self._column("_ids")

    @ids.setter
    def ids(self, value: npt.ArrayLike) -> None:
        self._set_column("_ids", value, np.int64, None)

    @property
    def x(self) -> npt.NDArray[np.float64]:
        return self._column("_x")

    @x.setter
    def x(self, value: npt.ArrayLike) -> None:
        self._set_column("_x", value, np.float64, self.gdim)

    @property
    def xref(self) -> npt.NDArray[np.float64]:
        return self._column("_xref")

    @xref.setter
    def xref(self, value: npt.ArrayLike) -> None:
        self._set_column("_xref", value, np.float64, self.tdim)

    @property
    def cells(self) -> npt.NDArray[np.int32]:
        return self._column("_cells")

    @cells.setter
    def cells(self, value: npt.ArrayLike) -> None:
        self._set_column("_cells", value, np.int32, None)

    @property
    def properties(self) -> npt.NDArray[np.float64]:
        return self._column("_props")

    @properties.setter
    def properties(self, value: npt.ArrayLike) -> None:
        self._set_column("_props", value, np.float64, self.num_property_columns)

    # ------------------------------------------------------------------ integrator stage table
    @property
    def stage_width(self) -> int:
        """Number of columns of the stage table (0 when not in use)."""
        return self._stage_width

    def stage_table(self, width: int, /) -> npt.NDArray[np.float64]:
        """Scratch columns that travel with the particles, shape=(n, width), float64 (contents
        unspecified until written).

        For integrator stage data (start state, stage slopes): like a property it is moved by
        :meth:`sort`, :meth:`take` and migration, so a particle that changes cell or rank mid-step
        keeps its stages; unlike a property it has no name, is not written to output or
        checkpoints, and its buffer is kept by :meth:`release_stage_table`, so asking for it again
        every time step allocates nothing. Ask again after a sort or migration: they move it.
        """
        if width < 0:
            raise ValueError(f"stage table width must be >= 0, got {width}")
        self._stage_width = 0
        capacity = self._capacity()
        if self._stage.shape[1] != width or self._stage.shape[0] < capacity:
            self._stage = np.empty((capacity, width), dtype=np.float64)
        self._stage_width = width
        return self._stage[: self._n]

    @property
    def stage(self) -> npt.NDArray[np.float64]:
        """The current stage table, shape=(n, stage_width) (see :meth:`stage_table`)."""
        if not self._stage_width:
            return np.empty((self._n, 0), dtype=np.float64)
        return self._stage[: self._n, : self._stage_width]

    def release_stage_table(self) -> None:
        """Stop carrying the stage table (its buffer is kept for the next :meth:`stage_table`)."""
        self._stage_width = 0

    # ------------------------------------------------------------------ properties
    @property
    def num_particles(self) -> int:
        """Number of particles on this rank."""
        return self._n

    def global_num_particles(self) -> int:
        """Total number of particles over all ranks (collective)."""
        return int(self.comm.allreduce(self.num_particles, op=MPI.SUM))

    @property
    def property_names(self) -> list[str]:
        return list(self._layout)

    @property
    def num_property_columns(self) -> int:
        return int(self._props.shape[1])

    def layout(self, name: str) -> PropertyLayout:
        """Column range of property ``name``; KeyError lists the known names."""
        try:
            return self._layout[name]
        except KeyError:
            raise KeyError(f"unknown particle property {name!r}; known: {sorted(self._layout)}") from None

    def add_property(self, name: str, size: int = 1, value: float = 0.0) -> PropertyLayout:
        """Append ``size`` scalar columns named ``name`` filled with ``value``. Returns the layout."""
        if name in self._layout:
            raise ValueError(f"particle property {name!r} exists already")
        if size < 1:
            raise ValueError(f"property size must be >= 1, got {size}")
        start = self.num_property_columns
        props = np.empty((self._capacity(), start + size), dtype=np.float64)
        props[: self._n, :start] = self.properties
        props[: self._n, start:] = value
        self._props = props
        self._layout[name] = PropertyLayout(name, start, size)
        return self._layout[name]

    def remove_property(self, name: str) -> None:
        """Drop the columns of property ``name``."""
        lay = self.layout(name)
        keep = np.ones(self.num_property_columns, dtype=bool)
        keep[lay.columns] = False
        props = np.empty((self._capacity(), int(np.count_nonzero(keep))), dtype=np.float64)
        props[: self._n] = self.properties[:, keep]
        self._props = props
        del self._layout[name]
        for key, other in list(self._layout.items()):
            if other.start > lay.start:
                self._layout[key] = PropertyLayout(key, other.start - lay.size, other.size)

    def has_property(self, name: str) -> bool:
        return name in self._layout

    def property(self, name: str) -> npt.NDArray[np.float64]:
        """View of property ``name``, shape=(n, size) (writes go into the swarm)."""
        return self.properties[:, self.layout(name).columns]

    # ------------------------------------------------------------------ cell access
    def cell_slice(self, cell: int) -> slice:
        """Rows of the particles in owned local cell ``cell`` (O(1))."""
        return slice(int(self.offsets[cell]), int(self.offsets[cell + 1]))

    def particles_per_cell(self) -> npt.NDArray[np.int64]:
        """Particle count of each owned cell, shape=(num_owned_cells,)."""
        return np.diff(self.offsets)

    # ------------------------------------------------------------------ bulk updates
    def add(
        self,
        ids: npt.ArrayLike,
        x: npt.ArrayLike,
        xref: npt.ArrayLike,
        cells: npt.ArrayLike,
        properties: npt.ArrayLike | None = None,
        *,
        sort: bool = True,
    ) -> None:
        """Insert a batch of particles (any order) and restore the cell order.

        Args:
            ids: Global ids, shape=(m,), int64.
            x: Positions, shape=(m, gdim).
            xref: Reference positions in ``cells``, shape=(m, tdim).
            cells: Local cell indices, shape=(m,), int32.
            properties: Property table, shape=(m, num_property_columns); zeros if omitted.
            sort: False appends the rows in O(m) and leaves them for the next :meth:`sort`
                (until then ``offsets`` do not cover them).
        """
        self.append_rows(ids, x, xref, cells, properties)
        if sort:
            self.sort()

    def append_rows(
        self,
        ids: npt.ArrayLike,
        x: npt.ArrayLike,
        xref: npt.ArrayLike,
        cells: npt.ArrayLike,
        properties: npt.ArrayLike | None = None,
        stage: npt.ArrayLike | None = None,
    ) -> None:
        """Append a batch of particles after the last row, unsorted (O(m) amortised).

        Arguments as :meth:`add`; ``stage`` fills the rows of the stage table when it is in use
        (shape=(m, stage_width)). Call :meth:`sort` before using ``offsets``.
        """
        ids = np.asarray(ids, dtype=np.int64).reshape(-1)
        m = ids.shape[0]
        cells = np.asarray(cells, dtype=np.int32).reshape(m)
        n = self._n
        self._reserve(n + m)
        end = n + m
        self._ids[n:end] = ids
        self._x[n:end] = np.asarray(x, dtype=np.float64).reshape(m, self.gdim)
        self._xref[n:end] = np.asarray(xref, dtype=np.float64).reshape(m, self.tdim)
        self._cells[n:end] = cells
        ncols = self.num_property_columns
        if properties is None:
            self._props[n:end] = 0.0
        else:
            self._props[n:end] = np.asarray(properties, dtype=np.float64).reshape(m, ncols)
        if self._stage_width:
            if stage is None:
                self._stage[n:end, : self._stage_width] = 0.0
            else:
                self._stage[n:end, : self._stage_width] = np.asarray(stage, dtype=np.float64).reshape(
                    m, self._stage_width)
        self._n = end
        if self._pending is not None and m:
            counts, _ = self._pending
            owned = (cells >= 0) & (cells < self.num_owned_cells)
            counts[: self.num_owned_cells] += np.bincount(cells[owned], minlength=self.num_owned_cells)
            outside = int(np.count_nonzero((cells >= self.num_owned_cells) | (cells == -1)))
            counts[self.num_owned_cells] += outside
            counts[self.num_owned_cells + 1] += int(np.count_nonzero(cells < -1))
            self._pending = (counts, False)
            if outside:
                self._outside = None

    def append_packed(self, table: npt.NDArray[np.float64], cells: npt.NDArray[np.int32], /) -> None:
        """Append the particles of a message table (the rows :func:`particles.kernels.pack_by_slot`
        makes: [id bits, hint, x, xref, properties, stage], shape=(m, 2 + gdim + tdim + columns +
        stage_width)) in the given cells (shape=(m,)), unsorted, in one compiled pass; as
        :meth:`append_rows`."""
        m = table.shape[0]
        width = 2 + self.gdim + self.tdim + self.num_property_columns + self._stage_width
        if table.shape != (m, width) or cells.shape != (m,):
            raise ValueError(f"a packed table of shape (m, {width}) and m cells expected")
        n = self._n
        self._reserve(n + m)
        counts = self._pending[0] if self._pending is not None else np.empty(0, dtype=np.int64)
        outside_before = int(counts[self.num_owned_cells]) if counts.size else 0
        stage = self._stage[:, : self._stage_width] if self._stage_width else np.empty((self._ids.shape[0], 0))
        append_packed(np.ascontiguousarray(table), np.asarray(cells, dtype=np.int32), n, self._ids.view(np.float64),
                      self._x, self._xref, self._cells, self._props, stage, counts, self.num_owned_cells)
        self._n = n + m
        if self._pending is not None and m:
            self._pending = (counts, False)
            if counts[self.num_owned_cells] != outside_before:
                self._outside = None

    def outside_rows(self) -> npt.NDArray[np.int64]:
        """Rows whose particle is in a ghost cell or unlocated (cells >= num_owned_cells or -1),
        in row order, shape=(m,), int64. O(m) when the last relocation handed over its counts and
        rows (:meth:`set_pending_counts`), else one scan; so ``cells`` must not be changed between
        a relocation with ``sort=False`` and the migration that follows it."""
        if self._pending is not None:
            if self._pending[0][self.num_owned_cells] == 0:
                return np.empty(0, dtype=np.int64)
            if self._outside is not None:
                cells = self._cells[self._outside]
                return self._outside[(cells >= self.num_owned_cells) | (cells == -1)]
        return rows_outside(self.cells, self.num_owned_cells)

    def discard_rows(self, rows: npt.NDArray[np.integer]) -> None:
        """Mark ``rows`` (currently in ghost cells or unlocated) as removed, in O(len(rows)); the
        next :meth:`sort` drops them. Until then ``num_particles`` still counts them."""
        rows = np.asarray(rows, dtype=np.int64)
        if rows.size == 0:
            return
        if self._pending is not None:
            counts, _ = self._pending
            cells = self._cells[rows]
            outside = (cells >= self.num_owned_cells) | (cells == -1)
            if not np.all(outside):
                self._pending = None
            else:
                counts[self.num_owned_cells] -= rows.size
                counts[self.num_owned_cells + 1] += rows.size
                self._pending = (counts, False)
        self._cells[rows] = DEAD

    def remove(self, mask: npt.NDArray[np.bool_]) -> int:
        """Remove the particles where ``mask`` is True (shape=(n,)); keeps the order. Returns count."""
        keep = ~np.asarray(mask, dtype=bool)
        removed = int(keep.shape[0] - np.count_nonzero(keep))
        if removed:
            self.take(np.flatnonzero(keep))
        return removed

    def take(self, rows: npt.NDArray[np.integer]) -> None:
        """Keep only ``rows`` (in that order) of every per-particle array; offsets are rebuilt."""
        rows = np.ascontiguousarray(rows, dtype=np.int64)
        n = rows.shape[0]
        buffers = self._spare_buffers(n)
        gather_particles(rows, *self._views(self._buffers(), self._n), *self._views(buffers, n))
        self._install(buffers, n)
        counts = np.zeros(self.num_owned_cells + 2, dtype=np.int64)
        count_buckets(self.cells, self.num_owned_cells, counts)
        self._set_offsets(counts)

    def sort(self) -> None:
        """Restore the order by cell after ``cells`` changed (stable: ties keep their order).

        A counting sort by cell, O(n + num_owned_cells), compiled with numba; nothing is moved if
        the particles are already in order. Particles with ``cells`` outside the owned range
        (ghost or -1) are placed last; the offsets only describe owned cells. Rows marked by
        :meth:`discard_rows` are dropped.
        """
        pending, self._pending = self._pending, None
        if pending is not None and not pending[1]:
            counts, already = pending[0], False
        else:
            counts = np.zeros(self.num_owned_cells + 2, dtype=np.int64)
            already = count_buckets(self.cells, self.num_owned_cells, counts)
        if not already:
            if self._dest.shape[0] < self._n:
                self._dest = np.empty(_capacity_for(self._n), dtype=np.int64)
            dest = self._dest[: self._n]
            if not sort_destinations(self.num_owned_cells, counts, self.cells, dest):
                # counts from a relocation no longer match (cells changed since): count afresh
                counts = np.zeros(self.num_owned_cells + 2, dtype=np.int64)
                count_buckets(self.cells, self.num_owned_cells, counts)
                ok = sort_destinations(self.num_owned_cells, counts, self.cells, dest)
                assert ok
            n_out = self._n - int(counts[-1])
            buffers = self._spare_buffers(n_out)
            scatter_particles(dest, *self._views(self._buffers(), self._n), *self._views(buffers, n_out))
            self._install(buffers, n_out)
        self._set_offsets(counts)

    def set_pending_counts(self, counts: npt.NDArray[np.int64], in_order: bool,
                           outside: npt.NDArray[np.int64] | None = None, /) -> None:
        """Hand the next :meth:`sort` the rows per bucket, shape=(num_owned_cells + 2,) (owned
        cells, ghost/unlocated, discarded), counted while the cells were computed, and whether
        the rows are in bucket order, so the sort skips its counting pass. Row appends and
        discards keep them up to date; counts that no longer match the cells are detected by the
        sort, which then counts afresh. ``outside`` (shape=(m,), increasing) lists every row then
        in a ghost cell or unlocated, so :meth:`outside_rows` need not scan all rows."""
        counts = np.asarray(counts, dtype=np.int64)
        if counts.shape != (self.num_owned_cells + 2,):
            raise ValueError(f"counts must have shape {(self.num_owned_cells + 2,)}")
        self._pending = (counts, bool(in_order))
        self._outside = None if outside is None else np.asarray(outside, dtype=np.int64)

    # ------------------------------------------------------------------ buffers
    def _in_use(self) -> tuple[str, ...]:
        return _FIELDS if self._stage_width else _FIELDS[:5]

    def _capacity(self) -> int:
        return min(getattr(self, f).shape[0] for f in self._in_use())

    def _buffers(self) -> tuple[npt.NDArray, ...]:
        return tuple(getattr(self, f) for f in _FIELDS)

    def _views(self, buffers: tuple[npt.NDArray, ...], n: int) -> tuple[npt.NDArray, ...]:
        """The first ``n`` rows of each buffer (the stage table: its columns in use)."""
        ids, x, xref, cells, props, stage = buffers
        w = self._stage_width
        return ids[:n], x[:n], xref[:n], cells[:n], props[:n], stage[:n, :w] if w else np.empty((n, 0))

    def _install(self, buffers: tuple[npt.NDArray, ...], n: int) -> None:
        """Make the output buffers of a permutation current; the old ones become spare. Counts and
        rows handed over by a relocation describe the old rows, so they are dropped."""
        self._pending = None
        self._outside = None
        old = self._buffers()
        if self._stage_width:
            current, spare = buffers, old
        else:  # the stage buffer was not permuted: it stays current, the spare keeps its own
            current, spare = buffers[:5] + (old[5],), old[:5] + (buffers[5],)
        for f, b in zip(_FIELDS, current):
            setattr(self, f, b)
        self._n = n
        self._spare = spare

    def _spare_buffers(self, n: int) -> tuple[npt.NDArray, ...]:
        """Buffers with at least ``n`` rows for the next permutation: the ones released by the
        previous sort if nothing else refers to them any more and they fit, else new ones (with
        room to grow). Arrays handed out before a sort are therefore never overwritten."""
        spare, self._spare = self._spare, None
        current = self._buffers()
        if spare is not None:
            for k in range(len(current)):
                # references: the tuple ``spare`` and getrefcount's argument; more means a user holds it
                if (spare[k].shape[0] < n or spare[k].shape[1:] != current[k].shape[1:]
                        or sys.getrefcount(spare[k]) > 2):
                    spare = None
                    break
        if spare is None:
            cap = _capacity_for(n)
            spare = tuple(np.empty((cap,) + c.shape[1:], dtype=c.dtype) for c in current)
        return spare

    def _reserve(self, n: int) -> None:
        """Grow the buffers in use (copying the rows in use) if fewer than ``n`` rows fit."""
        if n <= self._capacity():
            return
        cap = _capacity_for(n)
        for f in self._in_use():
            old = getattr(self, f)
            new = np.empty((cap,) + old.shape[1:], dtype=old.dtype)
            new[: self._n] = old[: self._n]
            setattr(self, f, new)

    def _set_offsets(self, counts: npt.NDArray[np.int64]) -> None:
        offsets = np.empty(self.num_owned_cells + 1, dtype=np.int64)
        offsets[0] = 0
        np.cumsum(counts[: self.num_owned_cells], out=offsets[1:])
        self.offsets = offsets

    def check_invariants(self) -> None:
        """Raise AssertionError if the store is inconsistent (for tests and debugging)."""
        n = self.num_particles
        assert self.x.shape == (n, self.gdim) and self.xref.shape == (n, self.tdim)
        assert self.cells.shape == (n,) and self.properties.shape[0] == n
        assert np.all(np.diff(self.cells) >= 0), "particles are not sorted by cell"
        assert np.all((self.cells >= 0) & (self.cells < self.num_owned_cells)), "particle outside owned cells"
        assert self.offsets[-1] == n
        assert np.array_equal(self.offsets, np.concatenate([[0], np.cumsum(np.bincount(
            self.cells, minlength=self.num_owned_cells))])), "offsets do not match the cells"
        assert np.unique(self.ids).shape[0] == n, "duplicate ids on this rank"
