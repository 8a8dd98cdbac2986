"""The per-particle buffers behind a :class:`particles.storage.swarm.Swarm`.

Every per-particle array (ids, positions, reference positions, cells, property table, stage table)
is a buffer with spare rows, of which rows ``0:n`` are in use: appending rows costs O(rows) (a full
buffer grows by about an eighth), and a permutation (a sort or a take) writes into the buffers the
previous permutation released, if nothing else refers to them any more (fresh memory costs page
faults that dominate a sort), so arrays handed out before a permutation are never overwritten.
"""

from __future__ import annotations

import sys

import numpy as np
import numpy.typing as npt

from particles.storage.row_kernels import append_packed, gather_particles, scatter_particles

__all__ = ["FIELDS", "RowBuffers", "capacity_for"]

FIELDS = ("ids", "x", "xref", "cells", "props", "stage")
"""Attribute names of the buffers of a :class:`RowBuffers`, in the order the kernels take them."""


def capacity_for(n: int) -> int:
    """Rows to allocate for ``n`` rows in use (room to grow)."""
    return n + n // 8 + 16


class RowBuffers:
    """The buffers of one swarm: ``ids`` (int64), ``x`` (gdim columns), ``xref`` (tdim columns),
    ``cells`` (int32), ``props`` (the property table) and ``stage`` (the stage table), float64
    unless said; rows ``0:n`` are the particles.

    The stage table is carried only while ``stage_width > 0`` (then its first ``stage_width``
    columns are in use); its buffer is kept when it is not, so asking for it again allocates
    nothing.

    Args:
        gdim: Geometric dimension (columns of ``x``).
        tdim: Topological dimension (columns of ``xref``).
    """

    def __init__(self, gdim: int, tdim: int, /) -> None:
        self.gdim = gdim
        self.tdim = tdim
        self.n = 0
        self.ids = np.empty(0, dtype=np.int64)
        self.x = np.empty((0, gdim), dtype=np.float64)
        self.xref = np.empty((0, tdim), dtype=np.float64)
        self.cells = np.empty(0, dtype=np.int32)
        self.props = np.empty((0, 0), dtype=np.float64)
        self.stage = np.empty((0, 0), dtype=np.float64)
        self.stage_width = 0
        self.spare: tuple[npt.NDArray, ...] | None = None
        self._dest = np.empty(0, dtype=np.int64)  # sort destinations, reused

    # ------------------------------------------------------------------ columns
    def column(self, name: str) -> npt.NDArray:
        """The rows in use of buffer ``name`` (a view)."""
        return getattr(self, name)[: self.n]

    def set_column(self, name: str, value: npt.ArrayLike, dtype: type, width: int | None) -> None:
        """Replace buffer ``name`` by ``value``, shape=(n,) (``width`` None) or (n, width)."""
        shape = (self.n,) if width is None else (self.n, width)
        arr = np.ascontiguousarray(value, dtype=dtype)
        if arr.shape != shape:
            raise ValueError(f"expected shape {shape} for {name}, got {arr.shape}")
        setattr(self, name, arr)

    def add_property_columns(self, size: int, value: float) -> None:
        """Append ``size`` columns filled with ``value`` to the property table."""
        start = self.props.shape[1]
        props = np.empty((self.capacity(), start + size), dtype=np.float64)
        props[: self.n, :start] = self.props[: self.n]
        props[: self.n, start:] = value
        self.props = props

    def drop_property_columns(self, columns: slice) -> None:
        """Remove ``columns`` from the property table."""
        keep = np.ones(self.props.shape[1], dtype=bool)
        keep[columns] = False
        props = np.empty((self.capacity(), int(np.count_nonzero(keep))), dtype=np.float64)
        props[: self.n] = self.props[: self.n][:, keep]
        self.props = props

    # ------------------------------------------------------------------ stage table
    def stage_table(self, width: int, /) -> npt.NDArray[np.float64]:
        """Carry a stage table of ``width`` columns (contents unspecified), shape=(n, width)."""
        if width < 0:
            raise ValueError(f"stage table width must be >= 0, got {width}")
        self.stage_width = 0
        capacity = self.capacity()
        if self.stage.shape[1] != width or self.stage.shape[0] < capacity:
            self.stage = np.empty((capacity, width), dtype=np.float64)
        self.stage_width = width
        return self.stage[: self.n]

    def stage_in_use(self) -> npt.NDArray[np.float64]:
        """The stage table, shape=(n, stage_width)."""
        if not self.stage_width:
            return np.empty((self.n, 0), dtype=np.float64)
        return self.stage[: self.n, : self.stage_width]

    # ------------------------------------------------------------------ appending
    def append(
        self,
        ids: npt.NDArray[np.int64],
        x: npt.ArrayLike,
        xref: npt.ArrayLike,
        cells: npt.NDArray[np.int32],
        properties: npt.ArrayLike | None,
        stage: npt.ArrayLike | None,
    ) -> None:
        """Write ``m = len(ids)`` particles after the last row (missing properties and stages: 0)."""
        m = ids.shape[0]
        n = self.n
        self.reserve(n + m)
        end = n + m
        self.ids[n:end] = ids
        self.x[n:end] = np.asarray(x, dtype=np.float64).reshape(m, self.gdim)
        self.xref[n:end] = np.asarray(xref, dtype=np.float64).reshape(m, self.tdim)
        self.cells[n:end] = cells
        if properties is None:
            self.props[n:end] = 0.0
        else:
            self.props[n:end] = np.asarray(properties, dtype=np.float64).reshape(m, self.props.shape[1])
        if self.stage_width:
            if stage is None:
                self.stage[n:end, : self.stage_width] = 0.0
            else:
                self.stage[n:end, : self.stage_width] = np.asarray(stage, dtype=np.float64).reshape(
                    m, self.stage_width)
        self.n = end

    def append_packed(self, table: npt.NDArray[np.float64], cells: npt.NDArray[np.int32],
                      counts: npt.NDArray[np.int64], num_owned_cells: int) -> None:
        """Write the particles of a packed message table after the last row in one compiled pass
        (:func:`particles.storage.row_kernels.append_packed`; ``counts``, shape=(num_owned_cells + 2,) or
        empty, gets the new rows per sort bucket)."""
        m = table.shape[0]
        width = 2 + self.gdim + self.tdim + self.props.shape[1] + self.stage_width
        if table.shape != (m, width) or cells.shape != (m,):
            raise ValueError(f"a packed table of shape (m, {width}) and m cells expected")
        n = self.n
        self.reserve(n + m)
        stage = self.stage[:, : self.stage_width] if self.stage_width else np.empty((self.ids.shape[0], 0))
        append_packed(np.ascontiguousarray(table), np.asarray(cells, dtype=np.int32), n, self.ids.view(np.float64),
                      self.x, self.xref, self.cells, self.props, stage, counts, num_owned_cells)
        self.n = n + m

    # ------------------------------------------------------------------ permutations
    def gather(self, rows: npt.NDArray[np.int64]) -> None:
        """Keep only ``rows`` (int64, contiguous), in that order."""
        n = rows.shape[0]
        buffers = self._spare_buffers(n)
        gather_particles(rows, *self._views(self._buffers(), self.n), *self._views(buffers, n))
        self._install(buffers, n)

    def scatter(self, dest: npt.NDArray[np.int64], n: int) -> None:
        """Move row ``p`` to row ``dest[p]`` (dropped if -1), leaving ``n`` rows."""
        buffers = self._spare_buffers(n)
        scatter_particles(dest, *self._views(self._buffers(), self.n), *self._views(buffers, n))
        self._install(buffers, n)

    def destinations(self) -> npt.NDArray[np.int64]:
        """Scratch for the sort destinations, shape=(n,) (reused from sort to sort)."""
        if self._dest.shape[0] < self.n:
            self._dest = np.empty(capacity_for(self.n), dtype=np.int64)
        return self._dest[: self.n]

    # ------------------------------------------------------------------ buffers
    def _in_use(self) -> tuple[str, ...]:
        return FIELDS if self.stage_width else FIELDS[:5]

    def capacity(self) -> int:
        """Rows that fit in every buffer in use."""
        return min(getattr(self, f).shape[0] for f in self._in_use())

    def reserve(self, n: int) -> None:
        """Grow the buffers in use (copying the rows in use) if fewer than ``n`` rows fit."""
        if n <= self.capacity():
            return
        cap = capacity_for(n)
        for f in self._in_use():
            old = getattr(self, f)
            new = np.empty((cap,) + old.shape[1:], dtype=old.dtype)
            new[: self.n] = old[: self.n]
            setattr(self, f, new)

    def _buffers(self) -> tuple[npt.NDArray, ...]:
        return tuple(getattr(self, f) for f in FIELDS)

    def _views(self, buffers: tuple[npt.NDArray, ...], n: int) -> tuple[npt.NDArray, ...]:
        """The first ``n`` rows of each buffer (the stage table: its columns in use)."""
        ids, x, xref, cells, props, stage = buffers
        w = self.stage_width
        return ids[:n], x[:n], xref[:n], cells[:n], props[:n], stage[:n, :w] if w else np.empty((n, 0))

    def _install(self, buffers: tuple[npt.NDArray, ...], n: int) -> None:
        """Make the output buffers of a permutation current; the old ones become spare."""
        old = self._buffers()
        if self.stage_width:
            current, spare = buffers, old
        else:  # the stage buffer was not permuted: it stays current, the spare keeps its own
            current, spare = buffers[:5] + (old[5],), old[:5] + (buffers[5],)
        for f, b in zip(FIELDS, current):
            setattr(self, f, b)
        self.n = n
        self.spare = spare

    def _spare_buffers(self, n: int) -> tuple[npt.NDArray, ...]:
        """Buffers with at least ``n`` rows for the next permutation: the ones released by the
        previous one if nothing else refers to them any more and they fit, else new ones (with
        room to grow). Arrays handed out before a permutation are therefore never overwritten."""
        spare, self.spare = self.spare, None
        current = self._buffers()
        if spare is not None:
            for k in range(len(current)):
                # references: the tuple ``spare`` and getrefcount's argument; more means a user holds it
                if (spare[k].shape[0] < n or spare[k].shape[1:] != current[k].shape[1:]
                        or sys.getrefcount(spare[k]) > 2):
                    spare = None
                    break
        if spare is None:
            cap = capacity_for(n)
            spare = tuple(np.empty((cap,) + c.shape[1:], dtype=c.dtype) for c in current)
        return spare
