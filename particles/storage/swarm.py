"""Cell-sorted particle storage on a DOLFINx mesh (seed paper section 2.1).

ASPECT keeps particles in a multimap keyed by cell. Here the same invariant is kept with flat
arrays sorted by the owning local cell, plus CSR offsets: the particles of cell ``K`` are the
contiguous rows ``offsets[K]:offsets[K + 1]`` of every per-particle array. The order is restored
by a counting sort (two compiled passes, stable, O(n + cells)); the relocation kernel of
:mod:`particles.relocation.between_cells` counts the particles per cell while it relocates them, so the sort
after a move only has the second pass to do.

Particles live only in cells this rank owns (local indices ``0 <= K < num_owned_cells``). Code that
moves particles may temporarily leave a particle in a ghost cell (``K >= num_owned_cells``) or
unlocated (``K == -1``); :meth:`Swarm.sort` restores the invariant only for owned cells, and the
migration step (``particles.parallel.migration``) hands the others to their owners.

The per-particle arrays are views of buffers with spare rows: rows arriving from other ranks are
appended in O(rows) and rows leaving are only marked (:data:`particles.storage.row_kernels.DEAD`); the next
:meth:`Swarm.sort` places the new rows and drops the marked ones in the same pass, so a migration
costs O(particles sent + received) plus that one sort. The sort writes into the buffers the
previous sort released (fresh memory costs page faults that dominate a sort).

A :class:`Swarm` delegates to three parts: the buffers (:mod:`particles.storage.rows`), the order
by cell (:mod:`particles.storage.cell_order`: the sort and the rows per cell a relocation hands it) and
the named column ranges of the property table (:mod:`particles.storage.property_layout`).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import numpy.typing as npt
from mpi4py import MPI

import dolfinx.mesh

from fembase.geometry import CellGeometry
from particles.storage.cell_order import CellOrder
from particles.storage.property_layout import PropertyLayout, PropertyLayouts
from particles.storage.rows import RowBuffers
from particles.storage.row_kernels import DEAD, rows_outside

__all__ = ["PropertyLayout", "Swarm"]


def _column(name: str, dtype: type, width: str | None, doc: str) -> property:
    """A per-particle array of the swarm: the rows in use of buffer ``name`` (a view); assigning an
    array of shape (n,) (``width`` None) or (n, the swarm's attribute ``width``) replaces it."""

    def get(swarm: Swarm) -> npt.NDArray:
        return swarm._rows.column(name)

    def set_(swarm: Swarm, value: npt.ArrayLike) -> None:
        swarm._rows.set_column(name, value, dtype, None if width is None else getattr(swarm, width))
        swarm._order.clear()

    return property(get, set_, doc=doc)


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

    Attributes:
        inward: ``inward(x)``, unit directions into the domain at points shape=(n, gdim) ->
            shape=(n, gdim), where a moving boundary (a free surface) may pass particles: a
            particle found in no cell after a relocation is moved back in along it
            (:func:`particles.relocation.moving_mesh.pull_in`); None (the default): such particles are lost.
    """

    def __init__(self, mesh: dolfinx.mesh.Mesh, /) -> None:
        self.mesh = mesh
        self.comm: MPI.Intracomm = mesh.comm
        self.gdim: int = mesh.geometry.dim
        self.tdim: int = mesh.topology.dim
        cell_map = mesh.topology.index_map(self.tdim)
        self.num_owned_cells: int = cell_map.size_local
        self.num_local_cells: int = cell_map.size_local + cell_map.num_ghosts
        self.offsets = np.zeros(self.num_owned_cells + 1, dtype=np.int64)
        self._rows = RowBuffers(self.gdim, self.tdim)
        self._order = CellOrder(self.num_owned_cells)
        self._layout = PropertyLayouts()
        self._geometry: CellGeometry | None = None
        self.inward: Callable[[npt.NDArray[np.float64]], npt.NDArray[np.float64]] | None = None

    @property
    def geometry(self) -> CellGeometry:
        """Per-cell geometry data of the mesh (affine maps, vertex-to-cell adjacency, BB tree),
        built on first use and shared by evaluation, transport and generators."""
        if self._geometry is None:
            self._geometry = CellGeometry(self.mesh)
        return self._geometry

    def mesh_moved(self) -> None:
        """The mesh's nodes moved: take their new positions into the cell geometry (cell maps,
        bounding boxes). ``cells`` and ``xref`` are those of the old positions until
        :func:`particles.relocation.moving_mesh.follow_mesh` finds the particles again. Local."""
        if self._geometry is not None:
            self._geometry.moved()

    # ------------------------------------------------------------------ per-particle arrays
    ids = _column("ids", np.int64, None, "Global ids, shape=(n,), int64.")
    x = _column("x", np.float64, "gdim", "Physical positions, shape=(n, gdim), float64.")
    xref = _column("xref", np.float64, "tdim", "Reference positions in ``cells``, shape=(n, tdim), float64.")
    cells = _column("cells", np.int32, None, "Local cell indices, shape=(n,), int32.")
    properties = _column("props", np.float64, "num_property_columns",
                         "Property table, shape=(n, num_property_columns), float64.")

    # ------------------------------------------------------------------ integrator stage table
    @property
    def stage_width(self) -> int:
        """Number of columns of the stage table (0 when not in use)."""
        return self._rows.stage_width

    def stage_table(self, width: int, /) -> npt.NDArray[np.float64]:
        """Scratch columns that travel with the particles, shape=(n, width), float64 (contents
        unspecified until written).

        For integrator stage data (start state, stage slopes): like a property it is moved by
        :meth:`sort`, :meth:`take` and migration, so a particle that changes cell or rank mid-step
        keeps its stages; unlike a property it has no name, is not written to output or
        checkpoints, and its buffer is kept by :meth:`release_stage_table`, so asking for it again
        every time step allocates nothing. Ask again after a sort or migration: they move it.
        """
        return self._rows.stage_table(width)

    @property
    def stage(self) -> npt.NDArray[np.float64]:
        """The current stage table, shape=(n, stage_width) (see :meth:`stage_table`)."""
        return self._rows.stage_in_use()

    def release_stage_table(self) -> None:
        """Stop carrying the stage table (its buffer is kept for the next :meth:`stage_table`)."""
        self._rows.stage_width = 0

    # ------------------------------------------------------------------ properties
    @property
    def num_particles(self) -> int:
        """Number of particles on this rank."""
        return self._rows.n

    def global_num_particles(self) -> int:
        """Total number of particles over all ranks (collective)."""
        return int(self.comm.allreduce(self.num_particles, op=MPI.SUM))

    @property
    def property_names(self) -> list[str]:
        return self._layout.names

    @property
    def num_property_columns(self) -> int:
        return int(self._rows.props.shape[1])

    def layout(self, name: str) -> PropertyLayout:
        """Column range of property ``name``; KeyError lists the known names."""
        return self._layout[name]

    def add_property(self, name: str, size: int = 1, value: float = 0.0) -> PropertyLayout:
        """Append ``size`` scalar columns named ``name`` filled with ``value``. Returns the layout."""
        lay = self._layout.add(name, self.num_property_columns, size)
        self._rows.add_property_columns(size, value)
        return lay

    def remove_property(self, name: str) -> None:
        """Drop the columns of property ``name``."""
        self._rows.drop_property_columns(self._layout.remove(name).columns)

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
        cells = np.asarray(cells, dtype=np.int32).reshape(ids.shape[0])
        self._rows.append(ids, x, xref, cells, properties, stage)
        self._order.appended(cells)

    def append_packed(self, table: npt.NDArray[np.float64], cells: npt.NDArray[np.int32], /) -> None:
        """Append the particles of a message table (the rows :func:`particles.storage.row_kernels.pack_by_slot`
        makes: [id bits, hint, x, xref, properties, stage], shape=(m, 2 + gdim + tdim + columns +
        stage_width)) in the given cells (shape=(m,)), unsorted, in one compiled pass; as
        :meth:`append_rows`."""
        self._order.append_packed(self._rows, table, cells)

    def outside_rows(self) -> npt.NDArray[np.int64]:
        """Rows whose particle is in a ghost cell or unlocated (cells >= num_owned_cells or -1),
        in row order, shape=(m,), int64. O(m) when the last relocation handed over its counts and
        rows (:meth:`set_pending_counts`), else one scan; so ``cells`` must not be changed between
        a relocation with ``sort=False`` and the migration that follows it."""
        rows = self._order.outside_rows(self._rows.cells)
        return rows if rows is not None else rows_outside(self.cells, self.num_owned_cells)

    def discard_rows(self, rows: npt.NDArray[np.integer]) -> None:
        """Mark ``rows`` (currently in ghost cells or unlocated) as removed, in O(len(rows)); the
        next :meth:`sort` drops them. Until then ``num_particles`` still counts them."""
        rows = np.asarray(rows, dtype=np.int64)
        if rows.size == 0:
            return
        if self._order.counts is not None:
            self._order.discarded(self._rows.cells[rows])
        self._rows.cells[rows] = DEAD

    def remove(self, mask: npt.NDArray[np.bool_]) -> int:
        """Remove the particles where ``mask`` is True (shape=(n,)); keeps the order. Returns count."""
        keep = ~np.asarray(mask, dtype=bool)
        removed = int(keep.shape[0] - np.count_nonzero(keep))
        if removed:
            self.take(np.flatnonzero(keep))
        return removed

    def take(self, rows: npt.NDArray[np.integer]) -> None:
        """Keep only ``rows`` (in that order) of every per-particle array; offsets are rebuilt."""
        self.offsets = self._order.take(self._rows, np.ascontiguousarray(rows, dtype=np.int64))

    def sort(self) -> None:
        """Restore the order by cell after ``cells`` changed (stable: ties keep their order).

        A counting sort by cell, O(n + num_owned_cells), compiled with numba; nothing is moved if
        the particles are already in order. Particles with ``cells`` outside the owned range
        (ghost or -1) are placed last; the offsets only describe owned cells. Rows marked by
        :meth:`discard_rows` are dropped.
        """
        self.offsets = self._order.sort(self._rows)

    def set_pending_counts(self, counts: npt.NDArray[np.int64], in_order: bool,
                           outside: npt.NDArray[np.int64] | None = None, /) -> None:
        """Hand the next :meth:`sort` the rows per bucket, shape=(num_owned_cells + 2,) (owned
        cells, ghost/unlocated, discarded), counted while the cells were computed, and whether
        the rows are in bucket order, so the sort skips its counting pass. Row appends and
        discards keep them up to date; counts that no longer match the cells are detected by the
        sort, which then counts afresh. ``outside`` (shape=(m,), increasing) lists every row then
        in a ghost cell or unlocated, so :meth:`outside_rows` need not scan all rows."""
        self._order.set(counts, in_order, outside)

    def check_invariants(self) -> None:
        """Raise AssertionError if the store is inconsistent (for tests and debugging)."""
        _check_invariants(self)


def _check_invariants(swarm: Swarm) -> None:
    """Raise AssertionError if ``swarm`` is inconsistent (see :meth:`Swarm.check_invariants`)."""
    n = swarm.num_particles
    assert swarm.x.shape == (n, swarm.gdim) and swarm.xref.shape == (n, swarm.tdim)
    assert swarm.cells.shape == (n,) and swarm.properties.shape[0] == n
    assert np.all(np.diff(swarm.cells) >= 0), "particles are not sorted by cell"
    assert np.all((swarm.cells >= 0) & (swarm.cells < swarm.num_owned_cells)), "particle outside owned cells"
    assert swarm.offsets[-1] == n
    assert np.array_equal(swarm.offsets, np.concatenate([[0], np.cumsum(np.bincount(
        swarm.cells, minlength=swarm.num_owned_cells))])), "offsets do not match the cells"
    assert np.unique(swarm.ids).shape[0] == n, "duplicate ids on this rank"
