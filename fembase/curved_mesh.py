"""Meshes whose geometry nodes are moved by a point map: the second-order (P2) mesh of a straight-sided
one with every node at the map's image of the straight node, and back (the straight mesh of a curved
one through the inverse map). :class:`fembase.manifold.ShellManifold` curves refined shells this way.

Both keep the cells and their owners; the new mesh's nodes are numbered rank by rank, so the result
depends on the given mesh and the map only.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import numpy.typing as npt

import dolfinx.mesh

from fembase import dolfinx_compat as compat
from fembase.distribute import MeshPiece, create_mesh_from_piece
from fembase.dolfinx_compat import coordinate_element_from, coordinate_map, geometry_dofmap
from fembase.entities import EDGES

__all__ = ["PointMap", "curve_mesh", "straighten_mesh"]

PointMap = Callable[[npt.NDArray[np.float64]], npt.NDArray[np.float64]]
"""Where points go, shape=(n, gdim) to shape=(n, gdim) (not collective)."""


def curve_mesh(straight: dolfinx.mesh.Mesh, place: PointMap, /, *, degree: int = 2) -> dolfinx.mesh.Mesh:
    """The curved mesh of a straight-sided (P1) simplex mesh: the same cells on the same ranks,
    geometry of ``degree`` (1 or 2) with every node at ``place`` of the straight node (collective).

    The new mesh's nodes are numbered rank by rank: each rank's owned straight vertices, then its
    owned edges (a node per edge midpoint), so the result depends on the straight mesh only.
    """
    if coordinate_map(straight).degree != 1:
        raise ValueError("curve() takes a straight-sided (P1) mesh")
    comm = straight.comm
    tdim, gdim = straight.topology.dim, straight.geometry.dim
    num_owned = straight.topology.index_map(tdim).size_local
    dofs = geometry_dofmap(straight)[:num_owned]
    node_map = straight.geometry.index_map()
    vertex_global = np.asarray(node_map.local_to_global(np.ascontiguousarray(dofs.reshape(-1), dtype=np.int32)),
                               dtype=np.int64).reshape(num_owned, -1)
    starts = np.concatenate([[0], np.cumsum(comm.allgather(node_map.size_local))]).astype(np.int64)
    own_x = [straight.geometry.x[: node_map.size_local, :gdim]]
    if degree == 2:
        local_edges, midpoints = _owned_edges(straight, dofs)
        edge_map = straight.topology.index_map(1)
        edge_global = np.asarray(edge_map.local_to_global(np.ascontiguousarray(local_edges.reshape(-1))),
                                 dtype=np.int64).reshape(num_owned, len(EDGES[tdim]))
        own_x.append(midpoints)
    # The global node numbering is vertices block by block, then edges: rank r's piece holds its
    # owned vertices and its owned edges, which is not one contiguous block of that numbering,
    # so the cells are renumbered to the pieces' concatenation order.
    edge_starts = (np.concatenate([[0], np.cumsum(comm.allgather(own_x[1].shape[0]))]).astype(np.int64)
                   if degree == 2 else None)
    piece_starts = starts + (edge_starts if edge_starts is not None else 0)
    rank = np.searchsorted(starts, vertex_global, side="right") - 1
    renumbered = [vertex_global - starts[rank] + piece_starts[rank]]
    if edge_starts is not None:  # degree 2
        rank = np.searchsorted(edge_starts, edge_global, side="right") - 1
        renumbered.append(edge_global - edge_starts[rank] + piece_starts[rank] + (starts[rank + 1] - starts[rank]))
    curved_x = place(np.concatenate(own_x))
    piece = MeshPiece(np.concatenate(renumbered, axis=1), curved_x, np.full(num_owned, comm.rank, dtype=np.int32))
    domain = compat.mesh_domain(coordinate_element_from((straight.topology.cell_name(), degree, gdim)))
    return create_mesh_from_piece(comm, piece, domain).mesh


def _owned_edges(straight: dolfinx.mesh.Mesh, dofs: npt.NDArray[np.int32]
                 ) -> tuple[npt.NDArray[np.int32], npt.NDArray[np.float64]]:
    """The local edges of each owned cell in the reference order of :data:`EDGES`,
    shape=(num_owned_cells, num_edges), and the straight midpoint of each owned edge,
    shape=(num_owned_edges, gdim) (not collective once the edges exist)."""
    tdim, gdim = straight.topology.dim, straight.geometry.dim
    x = straight.geometry.x
    straight.topology.create_entities(1)
    straight.topology.create_connectivity(tdim, 1)
    c2e = straight.topology.connectivity(tdim, 1)
    # DOLFINx's cell-edge connectivity is in the reference order of the edges (the same as EDGES),
    # which _check_edges confirms through the vertices.
    local_edges = np.asarray(c2e.array, dtype=np.int32).reshape(-1, len(EDGES[tdim]))[: dofs.shape[0]]
    owned_edges = straight.topology.index_map(1).size_local
    # The straight midpoint of each owned edge, from the cell that lists it first.
    midpoint = np.full((owned_edges, gdim), np.nan)
    for j, (a, b) in enumerate(EDGES[tdim]):
        e = local_edges[:, j]
        mine = e < owned_edges
        midpoint[e[mine]] = 0.5 * (x[dofs[mine, a], :gdim] + x[dofs[mine, b], :gdim])
    # Owned edges of no owned cell (their owner holds only ghost cells around them): their
    # midpoints from the edge-vertex connectivity.
    missing = np.flatnonzero(np.isnan(midpoint[:, 0]))
    if missing.size:
        straight.topology.create_connectivity(1, 0)
        e2v = straight.topology.connectivity(1, 0)
        verts = np.asarray(e2v.array, dtype=np.int32).reshape(-1, 2)[missing]
        geo = compat.entities_to_geometry(straight, 0, verts.reshape(-1)).reshape(-1, 2)
        midpoint[missing] = 0.5 * (x[geo[:, 0], :gdim] + x[geo[:, 1], :gdim])
    _check_edges(straight, dofs, local_edges)
    return local_edges, midpoint


def _check_edges(mesh: dolfinx.mesh.Mesh, dofs: npt.NDArray[np.int32], local_edges: npt.NDArray[np.int32]) -> None:
    """Raise if DOLFINx's cell-edge connectivity is not in the reference order of :data:`EDGES`."""
    tdim = mesh.topology.dim
    mesh.topology.create_connectivity(1, 0)
    e2v = np.asarray(mesh.topology.connectivity(1, 0).array, dtype=np.int32).reshape(-1, 2)
    mesh.topology.create_connectivity(tdim, 0)
    c2v = np.asarray(mesh.topology.connectivity(tdim, 0).array, dtype=np.int32).reshape(-1, tdim + 1)
    for j, (a, b) in enumerate(EDGES[tdim]):
        expected = np.sort(c2v[: dofs.shape[0]][:, [a, b]], axis=1)
        if not np.array_equal(np.sort(e2v[local_edges[:, j]], axis=1), expected):
            raise RuntimeError("the cell-edge connectivity is not in the reference edge order")


def straighten_mesh(curved: dolfinx.mesh.Mesh, place: PointMap, /) -> dolfinx.mesh.Mesh:
    """The straight-sided (P1) mesh of a curved one: its vertices moved by ``place`` (the inverse
    of the map it was curved by), the same cells on the same ranks (collective)."""
    comm = curved.comm
    tdim, gdim = curved.topology.dim, curved.geometry.dim
    num_owned = curved.topology.index_map(tdim).size_local
    dofs = geometry_dofmap(curved)[:num_owned, : tdim + 1]
    node_map = curved.geometry.index_map()
    glob = np.asarray(node_map.local_to_global(np.ascontiguousarray(dofs.reshape(-1), dtype=np.int32)),
                      dtype=np.int64).reshape(num_owned, -1)
    x = place(curved.geometry.x[: node_map.size_local, :gdim])
    piece = MeshPiece(glob, x, np.full(num_owned, comm.rank, dtype=np.int32))
    domain = compat.mesh_domain(coordinate_element_from((curved.topology.cell_name(), 1, gdim)))
    return create_mesh_from_piece(comm, piece, domain).mesh
