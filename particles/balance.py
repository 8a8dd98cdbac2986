"""Load balancing: repartition a mesh with cell loads 1 + W n_particles and move the particles along
(seed paper section 2.4).

:func:`rebalance` is the call for particle users: it counts the particles per cell, lets a
partition method of :mod:`particles.partition` choose a new owner for every cell, creates the
mesh anew on that partition and moves the particles to it (:func:`particles.adaptivity.move_to_mesh`).
Functions on the old mesh are the caller's to carry over (or to rebuild on ``swarm.mesh``).

The building blocks are shared with the convection code's adaptive meshes
(``convection.adaptivity.MeshHierarchy.repartition``): :func:`owner_partitioner` hands fixed
owners to ``dolfinx.mesh.create_mesh`` (cells sharing a facet with another rank's cells are ghosted
there, as ``GhostMode.shared_facet`` requires). The methods need every cell's data: the mesh is
gathered whole on rank 0 (:class:`CellLayout`), which suits meshes of up to a few million cells;
memory on rank 0 is O(global cells).
"""

from __future__ import annotations

from typing import Any, Callable, NamedTuple

import numpy as np
import numpy.typing as npt
from mpi4py import MPI

import dolfinx.cpp.graph
import dolfinx.cpp.mesh
import dolfinx.mesh
import ufl

from particles.adaptivity import move_to_mesh
from particles.partition import PARTITIONERS, partition
from particles.swarm import Swarm

__all__ = ["CellLayout", "WeightedMesh", "cell_owners", "create_partitioned_mesh", "gather_cell_layout",
           "owner_partitioner", "rebalance", "redistribute", "redistribution"]


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


def cell_owners(mesh: dolfinx.mesh.Mesh, particles_per_cell: npt.ArrayLike, /, *, particle_weight: float = 1.0,
                method: str = "rcb", **options: Any) -> npt.NDArray[np.int32]:
    """New owner rank of every owned cell, balancing cells and particles (collective).

    The cell midpoints and particle counts are gathered on rank 0, partitioned there by ``method``
    (:data:`particles.partition.PARTITIONERS`) with the load ``1 + W n_particles`` per cell, and
    the owners scattered back.

    Args:
        mesh: The mesh.
        particles_per_cell: Particles in each owned cell, shape=(num_owned_cells,).
        particle_weight: W, the cost of a particle relative to a cell.
        method: Partition method name.
        options: Method options (e.g. ``balance``, ``axes`` of :func:`particles.partition.rcb_owners`).

    Returns:
        Owner rank per owned cell, shape=(num_owned_cells,), int32.
    """
    if method not in PARTITIONERS:
        raise ValueError(f"unknown partition method {method!r}; valid names: {sorted(PARTITIONERS)}")
    comm = mesh.comm
    tdim, gdim = mesh.topology.dim, mesh.geometry.dim
    num_owned = mesh.topology.index_map(tdim).size_local
    counts = np.asarray(particles_per_cell, dtype=np.float64).reshape(-1)
    if counts.shape[0] != num_owned:
        raise ValueError(f"particles_per_cell has {counts.shape[0]} entries for {num_owned} owned cells")
    midpoints = dolfinx.mesh.compute_midpoints(mesh, tdim, np.arange(num_owned, dtype=np.int32))[:, :gdim]
    gathered = comm.gather((midpoints, counts), root=0)
    pieces = None
    if comm.rank == 0:
        points = np.concatenate([g[0] for g in gathered])
        particles = np.concatenate([g[1] for g in gathered])
        owners = partition(method, points, np.ones(points.shape[0]), particles, comm.size,
                           particle_weight=particle_weight, **options)
        pieces = np.split(owners, np.cumsum([g[0].shape[0] for g in gathered])[:-1])
    return np.asarray(comm.scatter(pieces, root=0), dtype=np.int32)


def rebalance(swarm: Swarm, /, *, particle_weight: float = 1.0, method: str = "rcb", **options: Any) -> Swarm:
    """The particles of ``swarm`` on their mesh repartitioned for cell loads ``1 + W n_particles``
    (collective).

    The mesh is created anew on the partition :func:`cell_owners` chooses (same cells and
    vertices, ghost mode ``shared_facet``), and every particle (id, position, properties) is moved
    to the rank owning its cell there. With ``rcb`` every cut balances the load ``1 + W n`` alone
    (``balance=("load",)`` unless given), so ranks get equal work rather than equal cells and equal
    particles at once (what the convection runs ask of it). Functions on the old mesh are not carried over: build them
    again on ``result.mesh`` (or interpolate them across). On one rank the swarm itself is
    returned.

    Args:
        swarm: The particles (sorted, in owned cells) on a P1 simplex mesh.
        particle_weight: W, the cost of a particle relative to a cell.
        method: Partition method name (:data:`particles.partition.PARTITIONERS`).
        options: Method options, e.g. ``balance=("load",)`` or ``axes=(1,)`` for ``rcb``
            (:func:`particles.partition.rcb_owners`).

    Returns:
        A new swarm on the repartitioned mesh, with the same particles and property layout.

    Example:
        >>> swarm = rebalance(swarm, particle_weight=1.0)
        >>> V = dolfinx.fem.VectorFunctionSpace(swarm.mesh, ("Lagrange", 2))
    """
    if method == "rcb":
        options.setdefault("balance", ("load",))
    owners = cell_owners(swarm.mesh, swarm.particles_per_cell(), particle_weight=particle_weight, method=method,
                         **options)
    if swarm.comm.size == 1:
        return swarm
    mesh = redistribute(swarm.mesh, owners)
    moved, stats = move_to_mesh(swarm, mesh)
    if stats.lost:
        raise RuntimeError(f"rebalance lost {stats.lost} particles (the new mesh must cover the old one)")
    return moved
