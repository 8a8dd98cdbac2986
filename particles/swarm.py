"""Cell-sorted particle storage on a DOLFINx mesh (seed paper section 2.1).

ASPECT keeps particles in a multimap keyed by cell. Here the same invariant is kept with flat
arrays sorted by the owning local cell, plus CSR offsets: the particles of cell ``K`` are the
contiguous rows ``offsets[K]:offsets[K + 1]`` of every per-particle array. Bulk insertion merges a
sorted batch into the sorted store (numpy's stable sort is a timsort, which merges two sorted runs
in linear time); bulk removal compacts with a mask and keeps the order.

Particles live only in cells this rank owns (local indices ``0 <= K < num_owned_cells``). Code that
moves particles may temporarily leave a particle in a ghost cell (``K >= num_owned_cells``) or
unlocated (``K == -1``); :meth:`Swarm.sort` restores the invariant only for owned cells, and the
migration step (``particles.migration``) hands the others to their owners.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from mpi4py import MPI

import dolfinx.mesh

from particles.geometry import CellGeometry
from particles.kernels import cell_order, permute_particles

__all__ = ["PropertyLayout", "Swarm"]


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


class Swarm:
    """Particles on a DOLFINx mesh, kept sorted by the local cell that contains them.

    Per particle (``n`` local particles):

    - ``ids``: global id, shape=(n,), int64, unique across ranks;
    - ``x``: physical position, shape=(n, gdim), float64;
    - ``xref``: position in the reference cell of ``cells``, shape=(n, tdim), float64;
    - ``cells``: local cell index, shape=(n,), int32, non-decreasing;
    - ``properties``: named scalar columns, shape=(n, num_columns), float64.

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
        self.ids = np.empty(0, dtype=np.int64)
        self.x = np.empty((0, self.gdim), dtype=np.float64)
        self.xref = np.empty((0, self.tdim), dtype=np.float64)
        self.cells = np.empty(0, dtype=np.int32)
        self.properties = np.empty((0, 0), dtype=np.float64)
        self._layout: dict[str, PropertyLayout] = {}
        self.offsets = np.zeros(self.num_owned_cells + 1, dtype=np.int64)
        self._geometry: CellGeometry | None = None
        self._spare: tuple[npt.NDArray, ...] | None = None

    @property
    def geometry(self) -> CellGeometry:
        """Per-cell geometry data of the mesh (affine maps, vertex-to-cell adjacency, BB tree),
        built on first use and shared by evaluation, transport and generators."""
        if self._geometry is None:
            self._geometry = CellGeometry(self.mesh)
        return self._geometry

    # ------------------------------------------------------------------ properties
    @property
    def num_particles(self) -> int:
        """Number of particles on this rank."""
        return int(self.ids.shape[0])

    def global_num_particles(self) -> int:
        """Total number of particles over all ranks (collective)."""
        return int(self.comm.allreduce(self.num_particles, op=MPI.SUM))

    @property
    def property_names(self) -> list[str]:
        return list(self._layout)

    @property
    def num_property_columns(self) -> int:
        return int(self.properties.shape[1])

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
        new = np.full((self.num_particles, size), value, dtype=np.float64)
        self.properties = np.concatenate([self.properties, new], axis=1)
        self._layout[name] = PropertyLayout(name, start, size)
        return self._layout[name]

    def remove_property(self, name: str) -> None:
        """Drop the columns of property ``name`` (e.g. integrator stage data after a step)."""
        lay = self.layout(name)
        keep = np.ones(self.num_property_columns, dtype=bool)
        keep[lay.columns] = False
        self.properties = np.ascontiguousarray(self.properties[:, keep])
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
    ) -> None:
        """Insert a batch of particles (any order) and restore the cell order.

        Args:
            ids: Global ids, shape=(m,), int64.
            x: Positions, shape=(m, gdim).
            xref: Reference positions in ``cells``, shape=(m, tdim).
            cells: Local cell indices, shape=(m,), int32.
            properties: Property table, shape=(m, num_property_columns); zeros if omitted.
        """
        ids = np.asarray(ids, dtype=np.int64).reshape(-1)
        m = ids.shape[0]
        x = np.asarray(x, dtype=np.float64).reshape(m, self.gdim)
        xref = np.asarray(xref, dtype=np.float64).reshape(m, self.tdim)
        cells = np.asarray(cells, dtype=np.int32).reshape(m)
        if properties is None:
            props = np.zeros((m, self.num_property_columns), dtype=np.float64)
        else:
            props = np.asarray(properties, dtype=np.float64).reshape(m, self.num_property_columns)
        self.ids = np.concatenate([self.ids, ids])
        self.x = np.concatenate([self.x, x])
        self.xref = np.concatenate([self.xref, xref])
        self.cells = np.concatenate([self.cells, cells])
        self.properties = np.concatenate([self.properties, props])
        self.sort()

    def remove(self, mask: npt.NDArray[np.bool_]) -> int:
        """Remove the particles where ``mask`` is True (shape=(n,)); keeps the order. Returns count."""
        keep = ~np.asarray(mask, dtype=bool)
        removed = int(keep.shape[0] - np.count_nonzero(keep))
        if removed:
            self.take(np.flatnonzero(keep))
        return removed

    def take(self, rows: npt.NDArray[np.integer]) -> None:
        """Keep only ``rows`` (in that order) of every per-particle array; offsets are rebuilt."""
        self.ids = self.ids[rows]
        self.x = self.x[rows]
        self.xref = self.xref[rows]
        self.cells = self.cells[rows]
        self.properties = self.properties[rows]
        self._rebuild_offsets()

    def sort(self) -> None:
        """Restore the order by cell after ``cells`` changed (stable: ties keep their order).

        A counting sort by cell, O(n + num_owned_cells), compiled with numba; nothing is moved if
        the particles are already in order. Particles with ``cells`` outside the owned range
        (ghost or -1) are placed last; the offsets only describe owned cells.
        """
        order, offsets, already = cell_order(self.cells, self.num_owned_cells)
        if not already:
            old = (self.ids, self.x, self.xref, self.cells)
            new = self._spare_buffers()
            permute_particles(order, *old, *new)
            self.ids, self.x, self.xref, self.cells = new
            self._spare = old
            if self.properties.shape[1]:
                self.properties = np.take(self.properties, order, axis=0)
            else:
                self.properties = np.empty((self.num_particles, 0), dtype=np.float64)
        self.offsets = offsets

    def _spare_buffers(self) -> tuple[npt.NDArray, ...]:
        """Arrays for the next permutation: the ones replaced by the previous sort if nothing else
        refers to them any more (writing into fresh memory costs page faults that dominate the
        sort), else new ones. Arrays handed out before a sort are therefore never overwritten."""
        current = (self.ids, self.x, self.xref, self.cells)
        spare, self._spare = self._spare, None
        if spare is None:
            return tuple(np.empty_like(c) for c in current)
        for k in range(len(current)):
            # references: the tuple ``spare`` and getrefcount's argument; more means a user holds it
            if spare[k].shape != current[k].shape or sys.getrefcount(spare[k]) > 2:
                return tuple(np.empty_like(c) for c in current)
        return spare

    def _rebuild_offsets(self) -> None:
        owned = self.cells[(self.cells >= 0) & (self.cells < self.num_owned_cells)]
        counts = np.bincount(owned, minlength=self.num_owned_cells)
        self.offsets = np.zeros(self.num_owned_cells + 1, dtype=np.int64)
        np.cumsum(counts, out=self.offsets[1:])

    def check_invariants(self) -> None:
        """Raise AssertionError if the store is inconsistent (for tests and debugging)."""
        n = self.num_particles
        assert self.x.shape == (n, self.gdim) and self.xref.shape == (n, self.tdim)
        assert self.cells.shape == (n,) and self.properties.shape[0] == n
        assert np.all(np.diff(self.cells) >= 0), "particles are not sorted by cell"
        assert np.all((self.cells >= 0) & (self.cells < self.num_owned_cells)), "particle outside owned cells"
        assert self.offsets[-1] == n
        assert np.unique(self.ids).shape[0] == n, "duplicate ids on this rank"
