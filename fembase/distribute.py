"""Mesh redistribution: one rank's share of a mesh (:class:`MeshPiece`), meshes created from the
pieces on owners of our choosing, reproducible new meshes, and the partition decision for cell
loads (seed paper section 2.4).

A mesh is created anew *distributed*: every rank hands ``dolfinx.mesh.create_mesh`` only its own
cells (:class:`MeshPiece`: their vertices as global geometry node indices of the current mesh, its
own block of node coordinates, the owner chosen for each cell), and :func:`owner_partitioner`
sends each cell to its owner and, as ghost, to the ranks owning a cell that shares a facet with it
(DOLFINx's ``shared_facet``) or, on request, a vertex (deal.II's ghost layer: a particle that
crosses a partition corner then lands in a ghost cell). Memory per rank stays O(cells per rank); the
rank-independent (canonical) index of each cell travels along (:func:`create_mesh_from_piece`).

What still goes through rank 0 is the partition *decision* (:func:`cell_owners`: one midpoint and
one load per cell are gathered there and a method of :mod:`fembase.partition` runs serially),
O(global cells) small data on rank 0. :func:`gather_cell_layout` and :func:`create_partitioned_mesh`
(the whole mesh gathered on rank 0, the path used before) are kept only for the cost-model
measurement of that path (``benchmarks/scaling/measure_constants.py serialmesh``).

The same tools make a new mesh reproducible (:func:`create_reproducible_mesh`): DOLFINx's graph
partitioner (SCOTCH) gives another partition in every run, so a mesh is built on rank 0 alone, its
cells get owners from a partition method (or the owners a checkpoint saved,
:func:`cell_owners_by_input`) and are handed to ``create_mesh`` through :func:`owner_partitioner`;
:func:`mesh_fingerprint` proves two meshes have the same numbering.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable, Sequence
from typing import Any, NamedTuple

import numpy as np
import numpy.typing as npt
from mpi4py import MPI

import dolfinx.cpp.graph
import dolfinx.cpp.mesh
import dolfinx.mesh
import ufl

from fembase import dolfinx_compat as compat
from fembase.dolfinx_compat import adjacency_list, cell_partitioner, geometry_dofmap
from fembase.geometry import locate
from fembase.partition import PARTITIONERS, partition

__all__ = ["GHOST_LAYERS", "CellLayout", "MeshPiece", "WeightedMesh", "cell_owners", "cell_owners_by_input",
           "create_mesh_from_piece", "create_nested_meshes", "create_partitioned_mesh", "create_reproducible_mesh",
           "duplicate_cells", "gather_cell_layout", "mesh_fingerprint", "mesh_piece", "owner_partitioner", "pull",
           "redistribute", "redistribution", "refine_on_ranks"]


def _starts(comm: MPI.Comm, n: int) -> npt.NDArray[np.int64]:
    """First global index of every rank's block of ``n`` rows and the total, shape=(size + 1,)
    (an allgather of one integer per rank)."""
    return np.concatenate([[0], np.cumsum(comm.allgather(int(n)))]).astype(np.int64)


def pull(comm: MPI.Comm, wanted: npt.ArrayLike, values: npt.NDArray, starts: npt.NDArray[np.int64], /) -> npt.NDArray:
    """Values of rows held on other ranks, by global row index (collective).

    Rank r holds ``values`` for the global rows ``starts[r] <= i < starts[r + 1]``. Each rank sends
    its requests to the ranks holding them and gets the values back: an ``Alltoall`` of the request
    counts (O(ranks) integers per rank) and two ``Alltoallv`` of the requests and answers.

    Args:
        comm: The communicator.
        wanted: Global row indices, shape=(m,).
        values: This rank's rows, shape=(starts[rank + 1] - starts[rank], ...).
        starts: Row offsets of all ranks, shape=(size + 1,) (see ``_starts``).

    Returns:
        ``values`` of the wanted rows, shape=(m, ...), in the order of ``wanted``.
    """
    wanted = np.asarray(wanted, dtype=np.int64).reshape(-1)
    values = np.ascontiguousarray(values)
    size = comm.size
    holder = np.searchsorted(starts, wanted, side="right") - 1
    if wanted.size and (holder.min() < 0 or holder.max() >= size):
        raise ValueError("pull: a wanted row lies outside every rank's range")
    order = np.argsort(holder, kind="stable")
    send_counts = np.bincount(holder, minlength=size).astype(np.int32)
    recv_counts = np.empty(size, dtype=np.int32)
    comm.Alltoall(send_counts, recv_counts)
    requests = np.empty(int(recv_counts.sum()), dtype=np.int64)
    comm.Alltoallv([wanted[order], send_counts], [requests, recv_counts])
    trailing = values.shape[1:]
    width = int(np.prod(trailing, dtype=np.int64))
    reply = np.ascontiguousarray(values[requests - starts[comm.rank]]).reshape(-1)
    answers = np.empty(wanted.size * width, dtype=values.dtype)
    comm.Alltoallv([reply, recv_counts * width], [answers, send_counts * width])
    out = np.empty((wanted.size, *trailing), dtype=values.dtype)
    out[order] = answers.reshape((wanted.size, *trailing))
    return out


GHOST_LAYERS = ("facet", "vertex")


def owner_partitioner(owners: npt.NDArray[np.int32], /, *, vertices: npt.NDArray[np.int64] | None = None
                      ) -> Callable[..., Any]:
    """A cell partitioner for ``dolfinx.mesh.create_mesh(..., partitioner=...)`` with fixed owners.

    Every rank may pass cells (each its own share; the dual graph DOLFINx builds links them by
    global input index, rank r's cells numbered from the sum of the counts of ranks < r). When
    ghosting, a cell also goes to the ranks that own a cell sharing a facet with it (``vertices``
    None: the owners of its dual-graph neighbours, those passed by another rank asked for with
    :func:`pull`) or sharing a vertex with it (``vertices`` given: :func:`_vertex_sharing_owners`).
    The vertex layer is the one deal.II (and so ASPECT) keeps: every cell that touches an owned
    cell is local, so a particle that crosses a partition boundary at a corner lands in a ghost
    cell and is handed on by its neighbour message instead of a search on the receiving rank.

    Args:
        owners: Owner rank of each cell this rank passes to ``create_mesh``, in the same order,
            shape=(num_cells_passed,).
        vertices: Global vertex indices of those cells (the first ``tdim + 1`` geometry nodes of
            a simplex), shape=(num_cells_passed, tdim + 1), int64; None for the facet layer.
    """
    owners = np.asarray(owners, dtype=np.int32)
    if vertices is not None:
        vertices = np.asarray(vertices, dtype=np.int64).reshape(owners.shape[0], -1)

    def graph_partitioner(comm: Any, nparts: int, graph: Any, ghosting: bool) -> Any:
        n = graph.num_nodes
        if n != owners.shape[0]:
            raise ValueError(f"owner partitioner: {owners.shape[0]} owners for {n} cells on this rank")
        if n and (owners.min() < 0 or owners.max() >= nparts):
            raise ValueError(f"owner partitioner: owners must lie in [0, {nparts})")
        if not ghosting:
            return adjacency_list(owners)
        if vertices is not None:
            source, neighbour = _vertex_sharing_owners(comm, vertices, owners)
        else:
            starts = _starts(comm, n)
            first = starts[comm.rank]
            links = np.asarray(graph.array, dtype=np.int64)
            source = np.repeat(np.arange(n, dtype=np.int64), np.diff(np.asarray(graph.offsets, dtype=np.int64)))
            mine = (links >= first) & (links < first + n)
            neighbour = np.empty(links.size, dtype=np.int32)
            neighbour[mine] = owners[links[mine] - first]
            neighbour[~mine] = pull(comm, links[~mine], owners, starts)  # collective: every rank calls it
        # Per cell: its owner, then the other owners among its neighbours in increasing order.
        keys = np.unique(source * nparts + neighbour)
        cell, rank = keys // nparts, (keys % nparts).astype(np.int32)
        other = rank != owners[cell]
        cell, rank = cell[other], rank[other]
        offsets = np.zeros(n + 1, dtype=np.int32)
        offsets[1:] = np.cumsum(1 + np.bincount(cell, minlength=n))
        destinations = np.empty(int(offsets[-1]), dtype=np.int32)
        destinations[offsets[:-1]] = owners
        within = np.arange(cell.size) - np.searchsorted(cell, cell)
        destinations[offsets[cell] + 1 + within] = rank
        return adjacency_list(destinations, offsets)

    return cell_partitioner(graph_partitioner)


def _expand(keys: npt.NDArray[np.int64], table: npt.NDArray[np.int64]) -> tuple[npt.NDArray[np.int64],
                                                                               npt.NDArray[np.int64]]:
    """For each entry of ``keys``, the positions of its equal entries in the sorted ``table``:
    returns (index into keys, index into table), one pair per match."""
    first = np.searchsorted(table, keys, side="left")
    count = np.searchsorted(table, keys, side="right") - first
    which = np.repeat(np.arange(keys.size, dtype=np.int64), count)
    ends = np.cumsum(count)
    position = np.repeat(first, count) + np.arange(which.size, dtype=np.int64) - np.repeat(ends - count, count)
    return which, position


def _exchange_rows(comm: MPI.Comm, rows: npt.NDArray[np.int64], dest: npt.NDArray[np.int64]
                   ) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """Send each int64 row (shape=(m, w)) to rank ``dest``; returns the rows received and the rank
    each came from (collective: an Alltoall of counts and one Alltoallv)."""
    size, width = comm.size, rows.shape[1]
    order = np.argsort(dest, kind="stable")
    send_counts = np.bincount(dest, minlength=size).astype(np.int32)
    recv_counts = np.empty(size, dtype=np.int32)
    comm.Alltoall(send_counts, recv_counts)
    received = np.empty((int(recv_counts.sum()), width), dtype=np.int64)
    comm.Alltoallv([np.ascontiguousarray(rows[order]).reshape(-1), send_counts * width],
                   [received.reshape(-1), recv_counts * width])
    return received, np.repeat(np.arange(size, dtype=np.int64), recv_counts)


def _vertex_sharing_owners(comm: MPI.Comm, vertices: npt.NDArray[np.int64], owners: npt.NDArray[np.int32]
                           ) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int32]]:
    """For each cell passed on this rank, the owners of all cells sharing a vertex with it
    (collective; memory O(cells passed here + their vertices)).

    Each vertex has a home rank (index mod size) that learns the owners of the cells around it
    and tells them back to every rank that passed one of those cells: two rounds of an Alltoall
    of counts and an Alltoallv.

    Returns (cell, owner) pairs, cell as an index into ``vertices``' rows, int64 and int32.
    """
    n, per_cell = vertices.shape
    v = vertices.reshape(-1)
    o = np.repeat(owners.astype(np.int64), per_cell)
    pairs = np.unique(np.stack([v, o], axis=1), axis=0)  # (vertex, owner)
    received, source = _exchange_rows(comm, pairs, pairs[:, 0] % comm.size)
    known = np.unique(received, axis=0)  # sorted by vertex, then owner
    asking = np.unique(np.stack([received[:, 0], source], axis=1), axis=0)  # (vertex, rank that asked)
    which, position = _expand(asking[:, 0], known[:, 0])
    answers, _ = _exchange_rows(comm, known[position], asking[which, 1])
    answers = answers[np.lexsort((answers[:, 1], answers[:, 0]))]
    which, position = _expand(v, answers[:, 0])
    return which // per_cell, answers[position, 1].astype(np.int32)


class CellLayout(NamedTuple):
    """A simplex mesh held whole on rank 0 (empty arrays elsewhere), cells in canonical order
    (the gathered path, kept for ``benchmarks/scaling/measure_constants.py serialmesh`` only).

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
    """Gather a P1 simplex mesh on rank 0 (collective; memory O(global cells) on rank 0, which
    repartitioning no longer does: see :func:`mesh_piece`).

    Args:
        mesh: The distributed mesh.
        canonical: Rank-independent index of each owned cell, shape=(num_owned_cells,), int64,
            a permutation of 0..num_cells-1 over all ranks (e.g. ``topology.original_cell_index``).
    """
    comm = mesh.comm
    tdim, gdim = mesh.topology.dim, mesh.geometry.dim
    num_owned = mesh.topology.index_map(tdim).size_local
    dofs = geometry_dofmap(mesh)[:num_owned]
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
    """Distribute ``layout`` with the given owner of each canonical cell (collective; every cell
    passes through rank 0, see :func:`create_mesh_from_piece` for the distributed path).

    Args:
        comm: Communicator of the new mesh.
        layout: The gathered mesh (:func:`gather_cell_layout`).
        owners: Owner rank per canonical cell, shape=(num_cells,) (read on rank 0 only).
        domain: The coordinate element (``ufl.Mesh``) of the mesh.
    """
    owners = np.asarray(owners if comm.rank == 0 else np.zeros(0), dtype=np.int32)
    mesh = compat.create_mesh(comm, layout.cells, layout.points, domain, owner_partitioner(owners))
    return WeightedMesh(mesh, np.asarray(mesh.topology.original_cell_index, dtype=np.int64))


class MeshPiece(NamedTuple):
    """One rank's share of a mesh to create (:func:`create_mesh_from_piece`): its own cells only.

    Attributes:
        cells: Geometry nodes of each cell as global node indices, shape=(num_cells, nodes_per_cell),
            int64.
        x: This rank's block of node coordinates, shape=(num_nodes, gdim): global nodes
            ``offset .. offset + num_nodes - 1``, ``offset`` the sum of the blocks of lower ranks.
        owners: Owner rank chosen for each cell, shape=(num_cells,), int32.
        canonical: Rank-independent index of each cell, shape=(num_cells,), int64, or None (then
            the index of a cell is its position in the concatenation of the pieces in rank order).
    """

    cells: npt.NDArray[np.int64]
    x: npt.NDArray[np.float64]
    owners: npt.NDArray[np.int32]
    canonical: npt.NDArray[np.int64] | None = None


def mesh_piece(mesh: dolfinx.mesh.Mesh, owners: npt.NDArray[np.int32], canonical: npt.NDArray[np.int64] | None = None,
               /) -> MeshPiece:
    """This rank's owned cells of ``mesh`` and owned geometry nodes, numbered by the geometry's
    global node indices, with the new owner of each cell (not collective).

    Args:
        mesh: A mesh with an affine (P1) coordinate element.
        owners: New owner rank of each owned cell, shape=(num_owned_cells,).
        canonical: Rank-independent index of each owned cell, shape=(num_owned_cells,), or None.
    """
    tdim, gdim = mesh.topology.dim, mesh.geometry.dim
    num_owned = mesh.topology.index_map(tdim).size_local
    nodes = mesh.geometry.index_map()
    dofs = geometry_dofmap(mesh)[:num_owned]
    cells = np.asarray(nodes.local_to_global(np.ascontiguousarray(dofs, dtype=np.int32).reshape(-1)),
                       dtype=np.int64).reshape(num_owned, -1)
    x = np.array(mesh.geometry.x[: nodes.size_local, :gdim])
    owners = np.asarray(owners, dtype=np.int32)[:num_owned].copy()
    if owners.shape[0] != num_owned:
        raise ValueError(f"{owners.shape[0]} owners for {num_owned} owned cells")
    if canonical is not None:
        canonical = np.asarray(canonical, dtype=np.int64)[:num_owned].copy()
    return MeshPiece(cells, x, owners, canonical)


def create_mesh_from_piece(comm: MPI.Comm, piece: MeshPiece, domain: ufl.Mesh, /, *,
                           ghost_layer: str = "facet") -> WeightedMesh:
    """The mesh made of every rank's piece, each cell on the owner its piece names (collective).

    The same pieces on the same ranks give the same mesh, numbering and all (DOLFINx builds
    meshes deterministically from the same input).

    Args:
        comm: Communicator of the new mesh.
        piece: This rank's cells (:func:`mesh_piece`).
        domain: The coordinate element (``ufl.Mesh``) of the mesh.
        ghost_layer: Which cells of other ranks each rank also holds (:data:`GHOST_LAYERS`):
            ``"facet"``, those sharing a facet with an owned cell (DOLFINx's ``shared_facet``);
            ``"vertex"``, those sharing a vertex (deal.II's ghost layer, see
            :func:`owner_partitioner`).

    Returns:
        The mesh and the canonical index of each of its local cells (owned and ghost), fetched from
        the rank that passed the cell.
    """
    if ghost_layer not in GHOST_LAYERS:
        raise ValueError(f"unknown ghost layer {ghost_layer!r}; valid names: {list(GHOST_LAYERS)}")
    vertices = piece.cells[:, : compat.topological_dimension(domain) + 1] if ghost_layer == "vertex" else None
    mesh = compat.create_mesh(comm, piece.cells, piece.x, domain, owner_partitioner(piece.owners, vertices=vertices))
    original = np.asarray(mesh.topology.original_cell_index, dtype=np.int64)
    if piece.canonical is None:
        return WeightedMesh(mesh, original)
    starts = _starts(comm, piece.cells.shape[0])
    return WeightedMesh(mesh, pull(comm, original, piece.canonical, starts))


def create_reproducible_mesh(comm: MPI.Comm, build: Callable[[MPI.Comm], dolfinx.mesh.Mesh], /, *,
                             owners: npt.NDArray[np.int32] | None = None, method: str = "rcb") -> dolfinx.mesh.Mesh:
    """The mesh ``build`` makes, distributed over ``comm`` on a partition that is the same in every
    run (collective).

    DOLFINx's default graph partitioner (SCOTCH) does not give the same partition twice, not even
    on one process, so the same config on the same ranks would get another mesh numbering each
    run, and a checkpoint could not be replayed. Here rank 0 builds the mesh alone
    (``build(MPI.COMM_SELF)``: a box, a gmsh model on rank 0, ...), chooses the owners of its cells
    by ``method`` (:data:`fembase.partition.PARTITIONERS`, on the cell midpoints) unless they are
    given, and hands every cell to :func:`create_mesh_from_piece` in the order of ``build``'s
    input, so ``original_cell_index`` means what it means for a mesh ``build`` distributes itself.
    On one rank it is ``build(comm)``.

    Args:
        comm: Communicator of the mesh.
        build: Makes the mesh on the communicator it is given (called on rank 0 only, with
            ``MPI.COMM_SELF``, when ``comm`` has several ranks).
        owners: Owner rank of every cell by its input index, shape=(num_cells,) on rank 0 (other
            ranks: ignored), e.g. a saved partition to impose again; None: chosen by ``method``.
        method: Partition method when ``owners`` is None.

    Returns:
        The distributed mesh (facet ghost layer).
    """
    return create_nested_meshes(comm, [build], owners=owners, method=method)[0]


def create_nested_meshes(comm: MPI.Comm, builds: Sequence[Callable[[MPI.Comm], dolfinx.mesh.Mesh]], /, *,
                         owners: npt.NDArray[np.int32] | None = None, method: str = "rcb"
                         ) -> list[dolfinx.mesh.Mesh]:
    """Meshes from coarse to fine, each cell of a finer mesh inside one cell of the mesh before it
    (nested, e.g. boxes of n, 2n, 4n cells per side), distributed so that every cell sits on the rank
    of the coarser cell it lies in, on a partition that is the same in every run (collective).

    That is what geometric multigrid needs (:func:`fembase.multigrid.prolongation` finds the nodes of
    a rank's fine dofs among its own coarse cells). Rank 0 builds every mesh alone, as
    :func:`create_reproducible_mesh` does; the coarsest mesh is partitioned by ``method`` and each
    finer cell goes to the owner of the coarser cell that contains its midpoint. With ``owners`` of
    the finest mesh (a checkpoint's) each coarser cell first goes to the owner of the finer cell
    that contains its midpoint, and the finer cells then follow their coarser ones: a partition that
    keeps nested cells together comes back as given, another one is changed so that it does (or,
    where that would leave a rank without a coarsest cell, partitioned afresh).

    Args:
        comm: Communicator of the meshes.
        builds: Make the meshes, coarse to fine, on the communicator they are given.
        owners: Owner rank of every cell of the finest mesh by its input index (rank 0), or None.
        method: Partition method of the coarsest mesh when ``owners`` is None.

    Returns:
        The distributed meshes (facet ghost layer), coarse to fine.

    Raises:
        RuntimeError: A build failed on rank 0, or the meshes are not nested (on every rank).
    """
    if comm.size == 1:
        meshes = [build(comm) for build in builds]
        if owners is not None:
            _check_owners(owners, meshes[-1].topology.index_map(meshes[-1].topology.dim).size_local, 1)
        return meshes
    pieces: list[MeshPiece] = []
    element, failure, shape = None, None, None
    if comm.rank == 0:
        try:
            serial = [build(MPI.COMM_SELF) for build in builds]
            element = compat.coordinate_element_description(serial[-1])
            orders = [np.argsort(np.asarray(m.topology.original_cell_index, dtype=np.int64), kind="stable")
                      for m in serial]
            for mesh, order, level_owners in zip(serial, orders, _nested_owners(serial, orders, owners, comm.size,
                                                                               method)):
                whole = mesh_piece(mesh, np.zeros(order.size, dtype=np.int32))
                pieces.append(MeshPiece(whole.cells[order], whole.x, level_owners))
            shape = (pieces[-1].cells.shape[1], pieces[-1].x.shape[1])
        except Exception as err:  # noqa: BLE001 - told to every rank below, raised on every rank
            failure = f"{type(err).__name__}: {err}"
    failure, element, shape = comm.bcast((failure, element, shape), root=0)
    if failure is not None:
        raise RuntimeError(f"creating the mesh on rank 0 failed: {failure}")
    if comm.rank != 0:
        pieces = [MeshPiece(np.zeros((0, shape[0]), dtype=np.int64), np.zeros((0, shape[1])),
                            np.zeros(0, dtype=np.int32)) for _ in builds]
    domain = ufl.Mesh(compat.coordinate_element_from(element))
    return [create_mesh_from_piece(comm, piece, domain).mesh for piece in pieces]


def _input_midpoints(mesh: dolfinx.mesh.Mesh, order: npt.NDArray[np.int64]) -> npt.NDArray[np.float64]:
    """Midpoints of a serial mesh's cells in input order, shape=(num_cells, gdim)."""
    tdim = mesh.topology.dim
    return dolfinx.mesh.compute_midpoints(mesh, tdim, order.astype(np.int32))[:, :mesh.geometry.dim]


def _owners_through(points_of: dolfinx.mesh.Mesh, order: npt.NDArray[np.int64], other: dolfinx.mesh.Mesh,
                    other_owners: npt.NDArray[np.int32]) -> npt.NDArray[np.int32]:
    """Owner of every cell of the serial mesh ``points_of`` (input order): the owner (by input
    index, ``other_owners``) of the cell of the serial mesh ``other`` that holds its midpoint."""
    cells = locate(other, _input_midpoints(points_of, order)).cells
    if np.any(cells < 0):
        raise ValueError(f"{int(np.count_nonzero(cells < 0))} cell midpoints lie in no cell of the other mesh: "
                         "the meshes are not nested")
    return other_owners[np.asarray(other.topology.original_cell_index, dtype=np.int64)[cells]]


def _nested_owners(serial: list[dolfinx.mesh.Mesh], orders: list[npt.NDArray[np.int64]],
                   owners: npt.NDArray[np.int32] | None, size: int, method: str) -> list[npt.NDArray[np.int32]]:
    """Owners by input index of every level of :func:`create_nested_meshes` (rank 0 only)."""
    counts = [order.size for order in orders]
    levels: list[npt.NDArray[np.int32]] = [np.empty(0, dtype=np.int32)] * len(serial)
    if owners is not None:
        # Up from the saved partition of the finest mesh, then down again: a partition that keeps
        # nested cells together (one written by a run with these levels) comes back unchanged;
        # another one is made to, or, if that would leave a rank without cells, replaced by a fresh
        # one (either way the mesh differs from the saved one, which a checkpoint's fingerprint
        # check notices).
        levels[-1] = _check_owners(owners, counts[-1], size)
        for k in range(len(serial) - 2, -1, -1):
            levels[k] = _owners_through(serial[k], orders[k], serial[k + 1], levels[k + 1])
        if np.unique(levels[0]).size < size:
            owners = None
    if owners is None:
        levels[0] = _check_owners(partition(method, _input_midpoints(serial[0], orders[0]), np.ones(counts[0]),
                                            np.zeros(counts[0]), size, particle_weight=0.0), counts[0], size)
    for k in range(1, len(serial)):
        levels[k] = _owners_through(serial[k], orders[k], serial[k - 1], levels[k - 1])
    empty = size - np.unique(levels[0]).size
    if empty:
        raise ValueError(f"the coarsest mesh ({counts[0]} cells) leaves {empty} of {size} ranks without a cell: "
                         "use fewer levels or ranks")
    return levels


def _check_owners(owners: npt.ArrayLike, num_cells: int, size: int) -> npt.NDArray[np.int32]:
    """``owners`` as int32 if it names a rank in [0, size) for each of ``num_cells`` cells."""
    owners = np.asarray(owners, dtype=np.int32).reshape(-1)
    if owners.shape[0] != num_cells or owners.min(initial=0) < 0 or owners.max(initial=0) >= size:
        raise ValueError(f"{owners.shape[0]} owners in [0, {size}) given for {num_cells} cells")
    return owners


def cell_owners_by_input(mesh: dolfinx.mesh.Mesh, /) -> npt.NDArray[np.int32] | None:
    """The owner rank of every cell by its input index (``original_cell_index``) on rank 0, None
    elsewhere (collective): the partition :func:`create_reproducible_mesh` can impose again."""
    comm = mesh.comm
    num_owned = mesh.topology.index_map(mesh.topology.dim).size_local
    mine = np.asarray(mesh.topology.original_cell_index, dtype=np.int64)[:num_owned]
    gathered = comm.gather(mine, root=0)
    if comm.rank != 0:
        return None
    owners = np.full(sum(g.size for g in gathered), -1, dtype=np.int32)
    for rank, index in enumerate(gathered):
        owners[index] = rank
    return owners


def mesh_fingerprint(mesh: dolfinx.mesh.Mesh, /) -> bytes:
    """A digest of this rank's part of ``mesh`` (not collective): node coordinates, geometry dofmap,
    cell-vertex connectivity, global vertex numbers, input cell indices and the owned/ghost cell
    counts. Two meshes with the same digest on every rank have the same numbering, so function
    spaces on them number their dofs alike (the dofmaps are built from these)."""
    tdim = mesh.topology.dim
    mesh.topology.create_connectivity(tdim, 0)
    cells, vertices = mesh.topology.index_map(tdim), mesh.topology.index_map(0)
    num_vertices = vertices.size_local + vertices.num_ghosts
    digest = hashlib.sha256()
    for part in (np.asarray([cells.size_local, cells.num_ghosts, vertices.size_local, num_vertices], dtype=np.int64),
                 mesh.geometry.x, geometry_dofmap(mesh).reshape(-1), mesh.topology.connectivity(tdim, 0).array,
                 np.asarray(vertices.local_to_global(np.arange(num_vertices, dtype=np.int32)), dtype=np.int64),
                 np.asarray(mesh.topology.original_cell_index, dtype=np.int64)):
        digest.update(np.ascontiguousarray(part).tobytes())
    return digest.digest()


def duplicate_cells(mesh: dolfinx.mesh.Mesh, /) -> int:
    """How many of this rank's local cells (owned and ghost) repeat another local cell's vertices
    (not collective; 0 for a sound mesh)."""
    tdim = mesh.topology.dim
    mesh.topology.create_connectivity(tdim, 0)
    c2v = mesh.topology.connectivity(tdim, 0)
    width = int(c2v.offsets[1] - c2v.offsets[0]) if c2v.num_nodes else 1
    vertices = np.asarray(mesh.topology.index_map(0).local_to_global(c2v.array), dtype=np.int64)
    rows = np.sort(vertices.reshape(-1, width), axis=1)
    return int(rows.shape[0] - np.unique(rows, axis=0).shape[0])


def refine_on_ranks(mesh: dolfinx.mesh.Mesh, cells: npt.NDArray[np.int32] | None = None, /) -> dolfinx.mesh.Mesh:
    """``mesh`` refined at the local cells ``cells`` (None: every cell), each new cell on the rank of
    its parent, with the facet ghost layer (collective).

    DOLFINx 0.9 refines without ghost cells when the partition is kept; DOLFINx 0.5 keeps them but
    can give a rank the same ghost cell twice (seen on 3 ranks: 2-20
    duplicates per 8 x 8 mesh; on 2 ranks too, after repeated local refinement: 11 in an adapted
    28 x 7 box), and a facet then has three cells and is no interior facet any more (jump terms such
    as the refinement indicator miss it, so the adapted mesh depended on the partition). In both
    cases the refined mesh is made again from its owned cells on the same partition
    (:func:`redistribute` with every cell kept on its rank), which builds a clean ghost layer."""
    edges = None
    if cells is not None:
        mesh.topology.create_entities(1)
        edges = compat.incident_entities(mesh, cells, mesh.topology.dim, 1)
    refined = compat.refine_keeping_partition(mesh, edges)
    comm = refined.comm
    if comm.size == 1:
        return refined
    if compat.REFINE_KEEPS_GHOSTS and not comm.allreduce(duplicate_cells(refined), op=MPI.SUM):
        return refined
    num_owned = refined.topology.index_map(refined.topology.dim).size_local
    return redistribute(refined, np.full(num_owned, comm.rank, dtype=np.int32))


def redistribute(mesh: dolfinx.mesh.Mesh, owners: npt.NDArray[np.int32], /, *,
                 ghost_layer: str = "facet") -> dolfinx.mesh.Mesh:
    """The same cells, distributed so each owned cell of ``mesh`` goes to ``owners`` (collective).

    Every rank hands its own cells to ``create_mesh`` (:func:`redistribution`); DOLFINx 0.5 has no
    in-place redistribution, and creating the mesh anew gives it a fresh, consistent parallel
    topology.

    Args:
        mesh: A P1 simplex mesh.
        owners: New owner rank of each owned cell, shape=(num_owned_cells,).
        ghost_layer: ``"facet"`` or ``"vertex"`` (:func:`create_mesh_from_piece`).
    """
    domain = ufl.Mesh(mesh.ufl_domain().ufl_coordinate_element())
    return create_mesh_from_piece(mesh.comm, redistribution(mesh, owners), domain, ghost_layer=ghost_layer).mesh


def redistribution(mesh: dolfinx.mesh.Mesh, owners: npt.NDArray[np.int32], /) -> MeshPiece:
    """What :func:`redistribute` hands to :func:`create_mesh_from_piece` on this rank: its owned
    cells and nodes (:func:`mesh_piece`) with their new owners. Not collective."""
    return mesh_piece(mesh, owners)


def cell_owners(mesh: dolfinx.mesh.Mesh, particles_per_cell: npt.ArrayLike, /, *, particle_weight: float = 1.0,
                method: str = "rcb", **options: Any) -> npt.NDArray[np.int32]:
    """New owner rank of every owned cell, balancing cells and particles (collective).

    The cell midpoints and particle counts are gathered on rank 0, partitioned there by ``method``
    (:data:`fembase.partition.PARTITIONERS`) with the load ``1 + W n_particles`` per cell, and
    the owners scattered back: the partition decision is serial, on O(global cells) small data
    (gdim + 1 numbers per cell); the mesh itself is never gathered (:func:`redistribute`).

    Args:
        mesh: The mesh.
        particles_per_cell: Particles in each owned cell, shape=(num_owned_cells,).
        particle_weight: W, the cost of a particle relative to a cell.
        method: Partition method name.
        options: Method options (e.g. ``balance``, ``axes`` of :func:`fembase.partition.rcb_owners`).

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
