"""Small cell-geometry helpers for generation and migration (owned cells only).

Vertex coordinates of cells, affine maps of simplices, cell volumes and a point search restricted to
the cells a rank owns. Kept minimal on purpose: the general point search with pull-back for any cell
lives in ``particles.evaluation``.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import numpy.typing as npt

import dolfinx.cpp.mesh
import dolfinx.geometry
import dolfinx.mesh

__all__ = [
    "OwnedLocation",
    "cell_nodes",
    "geometry_dofmap",
    "is_affine_simplex",
    "locate_owned",
    "owned_box",
    "owned_cell_tree",
    "pull_back",
    "push_forward",
]

_SIMPLICES = (dolfinx.mesh.CellType.interval, dolfinx.mesh.CellType.triangle, dolfinx.mesh.CellType.tetrahedron)


class OwnedLocation(NamedTuple):
    """Result of :func:`locate_owned`.

    Attributes:
        cells: Owned local cell containing each point, -1 if none, shape=(m,), int32.
        xref: Reference coordinates in that cell (NaN where not found), shape=(m, tdim), float64.
    """

    cells: npt.NDArray[np.int32]
    xref: npt.NDArray[np.float64]


def is_affine_simplex(mesh: dolfinx.mesh.Mesh) -> bool:
    """True if the cells are simplices with a degree-1 coordinate map."""
    return mesh.topology.cell_type in _SIMPLICES and mesh.geometry.cmap.degree == 1


def geometry_dofmap(mesh: dolfinx.mesh.Mesh) -> npt.NDArray[np.int32]:
    """Geometry node indices of every local cell, shape=(num_local_cells, num_nodes), int32."""
    dofmap = mesh.geometry.dofmap
    return dofmap.array.reshape(-1, mesh.geometry.cmap.create_dof_layout().num_dofs)


def owned_box(mesh: dolfinx.mesh.Mesh) -> npt.NDArray[np.float64]:
    """Bounding box of this rank's owned cells, shape=(2, gdim) (lower > upper if none)."""
    gdim = mesh.geometry.dim
    box = np.empty((2, gdim))
    box[0], box[1] = np.inf, -np.inf
    num_owned = mesh.topology.index_map(mesh.topology.dim).size_local
    if num_owned:
        x = mesh.geometry.x[np.unique(geometry_dofmap(mesh)[:num_owned]), :gdim]
        box[0], box[1] = x.min(axis=0), x.max(axis=0)
        if mesh.geometry.cmap.degree > 1:
            # A curved cell bulges beyond the box of its nodes (an arc between two boundary
            # nodes passes outside their coordinate range): pad by the largest bulge.
            from particles.geometry import CellGeometry

            pad = 1.01 * CellGeometry(mesh).curvature_padding
            box[0] -= pad
            box[1] += pad
    return box


def cell_nodes(mesh: dolfinx.mesh.Mesh, cells: npt.NDArray[np.int32]) -> npt.NDArray[np.float64]:
    """Geometry node coordinates of ``cells`` in DOLFINx order, shape=(m, num_nodes, gdim), float64."""
    gdim = mesh.geometry.dim
    dofmap = geometry_dofmap(mesh)
    return mesh.geometry.x[dofmap[np.asarray(cells, dtype=np.int32)]][:, :, :gdim]


def push_forward(mesh: dolfinx.mesh.Mesh, cells: npt.NDArray[np.int32], xref: npt.NDArray[np.float64]
                 ) -> npt.NDArray[np.float64]:
    """Physical points of reference points ``xref`` (shape=(m, tdim)) in ``cells``; shape=(m, gdim)."""
    nodes = cell_nodes(mesh, cells)
    if is_affine_simplex(mesh):
        jac = nodes[:, 1:, :] - nodes[:, :1, :]
        return nodes[:, 0, :] + np.einsum("mi,mig->mg", xref, jac)
    cmap = mesh.geometry.cmap
    out = np.empty((xref.shape[0], mesh.geometry.dim))
    for i in range(xref.shape[0]):
        out[i] = cmap.push_forward(xref[i : i + 1], nodes[i])[0]
    return out


def pull_back(mesh: dolfinx.mesh.Mesh, cells: npt.NDArray[np.int32], x: npt.NDArray[np.float64]
              ) -> npt.NDArray[np.float64]:
    """Reference coordinates of physical points ``x`` (shape=(m, gdim)) in ``cells``; shape=(m, tdim)."""
    tdim = mesh.topology.dim
    m = x.shape[0]
    if m == 0:
        return np.empty((0, tdim))
    nodes = cell_nodes(mesh, cells)
    if is_affine_simplex(mesh):
        jac = np.swapaxes(nodes[:, 1:, :] - nodes[:, :1, :], 1, 2)
        rhs = x - nodes[:, 0, :]
        if tdim == mesh.geometry.dim:
            return np.linalg.solve(jac, rhs[:, :, None])[:, :, 0]
        return np.stack([np.linalg.lstsq(jac[i], rhs[i], rcond=None)[0] for i in range(m)])
    cmap = mesh.geometry.cmap
    out = np.empty((m, tdim))
    for i in range(m):
        out[i] = cmap.pull_back(x[i : i + 1], nodes[i])[0]
    return out


def owned_cell_tree(mesh: dolfinx.mesh.Mesh) -> dolfinx.geometry.BoundingBoxTree:
    """Bounding-box tree over this rank's owned cells (not collective)."""
    num_owned = mesh.topology.index_map(mesh.topology.dim).size_local
    return dolfinx.geometry.BoundingBoxTree(mesh, mesh.topology.dim, np.arange(num_owned, dtype=np.int32))


def locate_owned(mesh: dolfinx.mesh.Mesh, x: npt.ArrayLike, /, *,
                 tree: dolfinx.geometry.BoundingBoxTree | None = None, geometry=None) -> OwnedLocation:
    """Find, for each point, an owned cell of this rank that contains it (not collective).

    A point on a face shared by several owned cells gets the lowest local cell index. Curved
    (degree-2) cells are searched by :meth:`particles.geometry.CellGeometry.locate` (pull-back
    into every candidate), as DOLFINx 0.5's collision test only knows their vertex simplex.

    Args:
        mesh: The mesh.
        x: Points, shape=(m, gdim), float64.
        tree: :func:`owned_cell_tree` of ``mesh``, to reuse (built for this call if omitted).
        geometry: The mesh's :class:`particles.geometry.CellGeometry`: when given (always for
            curved cells) its tree and pull-back test are used instead of ``tree``.

    Returns:
        The cells (-1 where no owned cell contains the point) and reference coordinates.
    """
    gdim, tdim = mesh.geometry.dim, mesh.topology.dim
    x = np.asarray(x, dtype=np.float64).reshape(-1, gdim)
    m = x.shape[0]
    cells = np.full(m, -1, dtype=np.int32)
    xref = np.full((m, tdim), np.nan)
    num_owned = mesh.topology.index_map(tdim).size_local
    if m == 0 or num_owned == 0:
        return OwnedLocation(cells, xref)
    if geometry is not None or mesh.geometry.cmap.degree > 1:
        from particles.geometry import CellGeometry

        found = (geometry if geometry is not None else CellGeometry(mesh)).locate(x, owned_only=True)
        hit = found.cells >= 0
        cells[hit] = found.cells[hit]
        xref[hit] = found.xref[hit]
        return OwnedLocation(cells, xref)
    points = np.zeros((m, 3))
    points[:, :gdim] = x
    if tree is None:
        tree = owned_cell_tree(mesh)
    candidates = dolfinx.geometry.compute_collisions(tree, points)
    colliding = dolfinx.geometry.compute_colliding_cells(mesh, candidates, points)
    offsets = np.asarray(colliding.offsets)
    links = np.asarray(colliding.array, dtype=np.int64)
    counts = np.diff(offsets)
    found = np.flatnonzero(counts > 0)
    if found.size:
        segment_min = np.minimum.reduceat(links, offsets[:-1][found]) if links.size else links
        cells[found] = segment_min.astype(np.int32)
        xref[found] = pull_back(mesh, cells[found], x[found])
    return OwnedLocation(cells, xref)
