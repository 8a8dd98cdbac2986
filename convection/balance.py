"""Load balancing: partition a mesh with cell loads 1 + W n_particles(K) (seed paper section 2.4).

A partition method maps per-cell data to an owner rank per cell. Registry :data:`PARTITIONERS`:

- ``morton``: cells sorted along a Morton (Z-order) curve of their midpoints, cut into contiguous
  blocks of equal load (:func:`block_owners`) — the space-filling-curve partition of p4est-based
  codes such as ASPECT;
- ``rcb``: recursive coordinate bisection; every cut (axis and position) minimises the worst
  imbalance of the cells, the particles and the load 1 + W n_particles on its two sides (a
  multi-constraint geometric partition: for an interface refined along one axis it cuts across the
  interface, so every rank gets its share of fine cells and of coarse, particle-rich cells).

:func:`owner_partitioner` hands fixed owners to ``dolfinx.mesh.create_mesh`` (cells sharing a
facet with another rank's cells are ghosted there, as ``GhostMode.shared_facet`` requires). The
methods need every cell's data: the mesh is gathered whole on rank 0 (:class:`CellLayout`), which
suits the coarse base meshes that adaptive meshes are refined from
(:meth:`convection.adaptivity.MeshHierarchy.repartition`).
"""

from __future__ import annotations

from typing import Any, Callable, NamedTuple, Protocol

import numpy as np
import numpy.typing as npt
from mpi4py import MPI

import dolfinx.cpp.graph
import dolfinx.cpp.mesh
import dolfinx.mesh
import ufl

__all__ = ["CellLayout", "PARTITIONERS", "WeightedMesh", "block_owners", "create_partitioned_mesh",
           "gather_cell_layout", "morton_order", "morton_owners", "owner_partitioner", "partition", "rcb_owners",
           "redistribute", "redistribution"]


def block_owners(weights: npt.NDArray[np.float64], nparts: int, /) -> npt.NDArray[np.int32]:
    """Owner of each item when the sequence is cut into ``nparts`` blocks of equal weight.

    Args:
        weights: Positive weights in curve order, shape=(n,).
        nparts: Number of blocks.

    Returns:
        Block index per item, shape=(n,), int32, non-decreasing.
    """
    w = np.asarray(weights, dtype=np.float64)
    if w.size == 0:
        return np.zeros(0, dtype=np.int32)
    if np.any(w <= 0.0):
        raise ValueError("partition weights must be positive")
    centre = (np.cumsum(w) - 0.5 * w) / w.sum()  # each item goes where its weight's midpoint falls
    return np.minimum((centre * nparts).astype(np.int32), nparts - 1)


def morton_order(points: npt.NDArray[np.float64], /, *, bits: int = 16) -> npt.NDArray[np.int64]:
    """Indices sorting ``points`` (shape=(n, d)) along a Morton (Z-order) curve."""
    p = np.asarray(points, dtype=np.float64)
    if p.shape[0] == 0:
        return np.zeros(0, dtype=np.int64)
    lo, hi = p.min(axis=0), p.max(axis=0)
    q = ((p - lo) / np.where(hi > lo, hi - lo, 1.0) * (2**bits - 1)).astype(np.int64)
    key = np.zeros(p.shape[0], dtype=np.int64)
    for bit in range(bits):
        for axis in range(p.shape[1]):
            key |= ((q[:, axis] >> bit) & 1) << (bit * p.shape[1] + axis)
    return np.argsort(key, kind="stable")


class PartitionMethod(Protocol):
    def __call__(self, points: npt.NDArray[np.float64], cells: npt.NDArray[np.float64],
                 particles: npt.NDArray[np.float64], nparts: int, /, *,
                 particle_weight: float) -> npt.NDArray[np.int32]: ...


def morton_owners(points: npt.NDArray[np.float64], cells: npt.NDArray[np.float64],
                  particles: npt.NDArray[np.float64], nparts: int, /, *, particle_weight: float) -> npt.NDArray[np.int32]:
    """Contiguous blocks of equal load ``cells + W particles`` along a Morton curve.

    Args:
        points: Where each item is (e.g. a base cell's midpoint), shape=(n, d).
        cells: Mesh cells each item carries (>= 1), shape=(n,).
        particles: Particles each item carries, shape=(n,).
        nparts: Number of parts.
        particle_weight: W.

    Returns:
        Owner per item, shape=(n,), int32.
    """
    order = morton_order(points)
    owners = np.empty(points.shape[0], dtype=np.int32)
    owners[order] = block_owners((cells + particle_weight * particles)[order], nparts)
    return owners


def rcb_owners(points: npt.NDArray[np.float64], cells: npt.NDArray[np.float64],
               particles: npt.NDArray[np.float64], nparts: int, /, *, particle_weight: float) -> npt.NDArray[np.int32]:
    """Recursive coordinate bisection balancing cells, particles and the load ``cells + W particles``.

    Each part is split into ``k // 2`` and ``k - k // 2`` parts; of all cut positions along all axes
    the one with the smallest worst ratio (share / target share) of cells, particles and load is
    taken (first axis on ties). Arguments and result as :func:`morton_owners`.
    """
    load = cells + particle_weight * particles
    if np.any(load <= 0.0):
        raise ValueError("partition loads must be positive")
    owners = np.zeros(points.shape[0], dtype=np.int32)
    stack = [(np.arange(points.shape[0]), nparts, 0)]
    while stack:
        items, k, first = stack.pop()
        if k == 1 or items.size == 0:
            owners[items] = first
            continue
        k_left = k // 2
        fraction = k_left / k
        best: tuple[float, np.ndarray, np.ndarray] | None = None
        for axis in range(points.shape[1]):
            order = items[np.argsort(points[items, axis], kind="stable")]
            # Worst ratio (share / target share) of cells, particles and load for every cut position.
            score = np.zeros(order.size + 1)
            for quantity in (cells, particles, load):
                q = quantity[order]
                total = q.sum()
                if total <= 0:
                    continue
                left = np.concatenate(([0.0], np.cumsum(q))) / total
                score = np.maximum(score, np.maximum(left / fraction, (1.0 - left) / (1.0 - fraction)))
            cut = int(np.argmin(score[1:-1])) + 1 if order.size > 1 else order.size
            if best is None or score[cut] < best[0] - 1e-12:
                best = (float(score[cut]), order[:cut], order[cut:])
        assert best is not None
        stack.append((best[1], k_left, first))
        stack.append((best[2], k - k_left, first + k_left))
    return owners


PARTITIONERS: dict[str, PartitionMethod] = {"morton": morton_owners, "rcb": rcb_owners}
"""Partition methods by config name (``balance.method``)."""


def partition(method: str, points: npt.NDArray[np.float64], cells: npt.NDArray[np.float64],
              particles: npt.NDArray[np.float64], nparts: int, /, *, particle_weight: float) -> npt.NDArray[np.int32]:
    """Owner per item by the named method (see :data:`PARTITIONERS`)."""
    if method not in PARTITIONERS:
        raise ValueError(f"unknown partition method {method!r}; valid names: {sorted(PARTITIONERS)}")
    return PARTITIONERS[method](points, cells, particles, nparts, particle_weight=particle_weight)


def owner_partitioner(owners: npt.NDArray[np.int32], /) -> Callable[..., Any]:
    """A cell partitioner for ``dolfinx.mesh.create_mesh(..., partitioner=...)`` with fixed owners.

    Args:
        owners: Owner rank of each cell this rank passes to ``create_mesh``, in the same order,
            shape=(num_cells_passed,) (all cells on one rank, none elsewhere).
    """
    owners = np.asarray(owners, dtype=np.int32)

    def graph_partitioner(comm: Any, nparts: int, graph: Any, ghosting: bool) -> Any:
        n = graph.num_nodes
        if n != owners.shape[0]:
            raise ValueError(f"owner partitioner: {owners.shape[0]} owners for {n} cells on this rank")
        if n and (owners.min() < 0 or owners.max() >= nparts):
            raise ValueError(f"owner partitioner: owners must lie in [0, {nparts})")
        destinations: list[int] = []
        offsets = [0]
        for i in range(n):
            destinations.append(int(owners[i]))
            if ghosting:
                others = {int(owners[j]) for j in graph.links(i) if 0 <= j < n} - {int(owners[i])}
                destinations.extend(sorted(others))
            offsets.append(len(destinations))
        return dolfinx.cpp.graph.AdjacencyList_int32(
            np.asarray(destinations, dtype=np.int32), np.asarray(offsets, dtype=np.int32)
        )

    return dolfinx.cpp.mesh.create_cell_partitioner(graph_partitioner)


class CellLayout(NamedTuple):
    """A simplex mesh held whole on rank 0 (empty arrays elsewhere), cells in canonical order.

    Attributes:
        points: Vertex coordinates, shape=(num_points, gdim) (rank 0).
        cells: Vertex indices of each cell, shape=(num_cells, num_vertices), int64 (rank 0).
        midpoints: Cell midpoints, shape=(num_cells, gdim) (rank 0).
        num_cells: Global number of cells (every rank).
    """

    points: npt.NDArray[np.float64]
    cells: npt.NDArray[np.int64]
    midpoints: npt.NDArray[np.float64]
    num_cells: int


def gather_cell_layout(mesh: dolfinx.mesh.Mesh, canonical: npt.NDArray[np.int64], /) -> CellLayout:
    """Gather a P1 simplex mesh on rank 0 (collective).

    Args:
        mesh: The distributed mesh.
        canonical: Rank-independent index of each owned cell, shape=(num_owned_cells,), int64,
            a permutation of 0..num_cells-1 over all ranks (e.g. ``topology.original_cell_index``).
    """
    comm = mesh.comm
    tdim, gdim = mesh.topology.dim, mesh.geometry.dim
    num_owned = mesh.topology.index_map(tdim).size_local
    dofs = mesh.geometry.dofmap.array.reshape(-1, tdim + 1)[:num_owned]
    corners = mesh.geometry.x[dofs][:, :, :gdim].reshape(num_owned, -1)
    gathered = comm.gather((np.asarray(canonical[:num_owned], dtype=np.int64), corners), root=0)
    num_cells = int(mesh.topology.index_map(tdim).size_global)
    if comm.rank != 0:
        return CellLayout(np.zeros((0, gdim)), np.zeros((0, tdim + 1), dtype=np.int64), np.zeros((0, gdim)), num_cells)
    index = np.concatenate([g[0] for g in gathered])
    coords = np.concatenate([g[1] for g in gathered]).reshape(-1, tdim + 1, gdim)
    if not np.array_equal(np.sort(index), np.arange(num_cells)):
        raise ValueError("canonical cell indices are not a permutation of the global cells")
    coords = coords[np.argsort(index)]
    # Coordinates of a shared vertex are bit-identical on every rank (one source), so exact
    # matching joins the cells again.
    points, inverse = np.unique(coords.reshape(-1, gdim), axis=0, return_inverse=True)
    cells = inverse.reshape(num_cells, tdim + 1).astype(np.int64)
    return CellLayout(points, cells, coords.mean(axis=1), num_cells)


class WeightedMesh(NamedTuple):
    """A mesh created by :func:`create_partitioned_mesh` and the canonical index of its local cells."""

    mesh: dolfinx.mesh.Mesh
    canonical: npt.NDArray[np.int64]  # shape=(num_owned + num_ghost cells,)


def create_partitioned_mesh(comm: MPI.Comm, layout: CellLayout, owners: npt.NDArray[np.int32] | None,
                            domain: ufl.Mesh, /) -> WeightedMesh:
    """Distribute ``layout`` with the given owner of each canonical cell (collective).

    Args:
        comm: Communicator of the new mesh.
        layout: The gathered mesh (:func:`gather_cell_layout`).
        owners: Owner rank per canonical cell, shape=(num_cells,) (read on rank 0 only).
        domain: The coordinate element (``ufl.Mesh``) of the mesh.
    """
    owners = np.asarray(owners if comm.rank == 0 else np.zeros(0), dtype=np.int32)
    mesh = dolfinx.mesh.create_mesh(comm, layout.cells, layout.points, domain,
                                    ghost_mode=dolfinx.mesh.GhostMode.shared_facet,
                                    partitioner=owner_partitioner(owners))
    return WeightedMesh(mesh, np.asarray(mesh.topology.original_cell_index, dtype=np.int64))


def redistribute(mesh: dolfinx.mesh.Mesh, owners: npt.NDArray[np.int32], /) -> dolfinx.mesh.Mesh:
    """The same cells, distributed so each owned cell of ``mesh`` goes to ``owners`` (collective).

    The cells are gathered on rank 0 and the mesh is created anew (DOLFINx 0.5 has no in-place
    redistribution), which gives it a fresh, consistent parallel topology.

    Args:
        mesh: A P1 simplex mesh.
        owners: New owner rank of each owned cell, shape=(num_owned_cells,).
    """
    layout, all_owners = redistribution(mesh, owners)
    domain = ufl.Mesh(mesh.ufl_domain().ufl_coordinate_element())
    return create_partitioned_mesh(mesh.comm, layout, all_owners, domain).mesh


def redistribution(mesh: dolfinx.mesh.Mesh, owners: npt.NDArray[np.int32], /) -> tuple[CellLayout, Any]:
    """What :func:`redistribute` hands to :func:`create_partitioned_mesh`: the cells gathered on
    rank 0 (in rank order) and their new owners (rank 0; None elsewhere). Collective."""
    comm = mesh.comm
    tdim = mesh.topology.dim
    num_owned = mesh.topology.index_map(tdim).size_local
    offset = comm.exscan(num_owned) or 0
    layout = gather_cell_layout(mesh, np.arange(offset, offset + num_owned, dtype=np.int64))
    gathered = comm.gather(np.asarray(owners, dtype=np.int32)[:num_owned], root=0)
    return layout, (np.concatenate(gathered) if comm.rank == 0 else None)
