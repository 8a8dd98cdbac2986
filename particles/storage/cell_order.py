"""The order of a :class:`particles.storage.swarm.Swarm`'s rows by cell: the counting sort, and what a
relocation tells it.

A sort places each row in a bucket: its owned cell (``0:num_owned_cells``), then one bucket for
the rows in a ghost cell or unlocated, then one for the discarded rows (shape=(num_owned_cells +
2,)). Counting the rows per bucket is the sort's first pass; the relocation kernel counts them
while it computes the cells and hands them over (:meth:`CellOrder.set`), so the sort after a move
only has the second pass to do. Row appends and discards keep the counts up to date until then.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from particles.storage.rows import RowBuffers
from particles.storage.row_kernels import count_buckets, sort_destinations

__all__ = ["CellOrder"]


class CellOrder:
    """Sorts rows by cell, using the rows per bucket when known from the last relocation.

    Attributes:
        num_owned_cells: Owned cells of the swarm's mesh.
        counts: Rows per bucket, shape=(num_owned_cells + 2,), int64, or None: unknown (the sort
            counts afresh).
        in_order: Whether the rows are in bucket order.
        outside: The rows in a ghost cell or unlocated (a superset: discarded ones are filtered
            out), shape=(m,), increasing; None: unknown (scan the cells). Valid while ``counts`` is.

    Args:
        num_owned_cells: Owned cells of the swarm's mesh.
    """

    def __init__(self, num_owned_cells: int, /) -> None:
        self.num_owned_cells = num_owned_cells
        self.counts: npt.NDArray[np.int64] | None = None
        self.in_order = False
        self.outside: npt.NDArray[np.int64] | None = None

    # ------------------------------------------------------------------ sorting
    def sort(self, rows: RowBuffers, /) -> npt.NDArray[np.int64]:
        """Sort ``rows`` by cell (stable; rows outside the owned cells last, discarded rows
        dropped; nothing moves if they are in order already). Returns the offsets of the owned
        cells, shape=(num_owned_cells + 1,)."""
        counts = self.counts if not self.in_order else None
        self.clear()
        already = False
        if counts is None:
            counts, already = self._count(rows)
        if not already:
            dest = rows.destinations()
            if not sort_destinations(self.num_owned_cells, counts, rows.column("cells"), dest):
                # counts from a relocation no longer match (cells changed since): count afresh
                counts = self._count(rows)[0]
                ok = sort_destinations(self.num_owned_cells, counts, rows.column("cells"), dest)
                assert ok
            rows.scatter(dest, rows.n - int(counts[-1]))
        return self._offsets(counts)

    def take(self, rows: RowBuffers, keep: npt.NDArray[np.int64], /) -> npt.NDArray[np.int64]:
        """Keep only the rows ``keep`` (int64, contiguous), in that order. Returns the offsets (of
        the rows in owned cells, when the kept rows are in cell order)."""
        rows.gather(keep)
        self.clear()
        return self._offsets(self._count(rows)[0])

    def _count(self, rows: RowBuffers) -> tuple[npt.NDArray[np.int64], bool]:
        """Rows per bucket, and whether they are in bucket order."""
        counts = np.zeros(self.num_owned_cells + 2, dtype=np.int64)
        already = count_buckets(rows.column("cells"), self.num_owned_cells, counts)
        return counts, already

    def _offsets(self, counts: npt.NDArray[np.int64]) -> npt.NDArray[np.int64]:
        offsets = np.empty(self.num_owned_cells + 1, dtype=np.int64)
        offsets[0] = 0
        np.cumsum(counts[: self.num_owned_cells], out=offsets[1:])
        return offsets

    # ------------------------------------------------------------------ counts from a relocation
    def set(self, counts: npt.NDArray[np.int64], in_order: bool, outside: npt.NDArray[np.int64] | None) -> None:
        """Take the counts (and the outside rows, if listed) of a relocation."""
        counts = np.asarray(counts, dtype=np.int64)
        if counts.shape != (self.num_owned_cells + 2,):
            raise ValueError(f"counts must have shape {(self.num_owned_cells + 2,)}")
        self.counts, self.in_order = counts, bool(in_order)
        self.outside = None if outside is None else np.asarray(outside, dtype=np.int64)

    def clear(self) -> None:
        """Forget the counts (the rows changed in a way they do not follow)."""
        self.counts = None
        self.outside = None

    def appended(self, cells: npt.NDArray[np.int32]) -> None:
        """Count appended rows in ``cells`` (shape=(m,))."""
        if self.counts is None or not cells.shape[0]:
            return
        k = self.num_owned_cells
        owned = (cells >= 0) & (cells < k)
        self.counts[:k] += np.bincount(cells[owned], minlength=k)
        outside = int(np.count_nonzero((cells >= k) | (cells == -1)))
        self.counts[k] += outside
        self.counts[k + 1] += int(np.count_nonzero(cells < -1))
        self.in_order = False
        if outside:
            self.outside = None

    def append_packed(self, rows: RowBuffers, table: npt.NDArray[np.float64], cells: npt.NDArray[np.int32]) -> None:
        """Append a packed message table to ``rows`` in ``cells``, counting the new rows."""
        k = self.num_owned_cells
        counts = self.counts if self.counts is not None else np.empty(0, dtype=np.int64)
        outside_before = int(counts[k]) if counts.size else 0
        rows.append_packed(table, cells, counts, k)
        if self.counts is not None and table.shape[0]:
            self.in_order = False
            if counts[k] != outside_before:
                self.outside = None

    def discarded(self, cells: npt.NDArray[np.int32]) -> None:
        """Move rows now in ``cells`` (shape=(m,)) to the discarded bucket; forget the counts if
        one of them was not outside (the counts cannot say which bucket it left)."""
        if self.counts is None:
            return
        k = self.num_owned_cells
        if not np.all((cells >= k) | (cells == -1)):
            self.clear()
            return
        self.counts[k] -= cells.shape[0]
        self.counts[k + 1] += cells.shape[0]
        self.in_order = False

    def outside_rows(self, cells: npt.NDArray[np.int32]) -> npt.NDArray[np.int64] | None:
        """The rows in a ghost cell or unlocated, in row order, if known without a scan of
        ``cells`` (the cell of every row); else None."""
        if self.counts is None:
            return None
        if self.counts[self.num_owned_cells] == 0:
            return np.empty(0, dtype=np.int64)
        if self.outside is None:
            return None
        here = cells[self.outside]
        return self.outside[(here >= self.num_owned_cells) | (here == -1)]
