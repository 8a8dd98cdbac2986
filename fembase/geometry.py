"""Cell geometry helpers: per-cell affine maps, vertex-to-cell adjacency, pull-back, point location.

A :class:`CellGeometry` is built once per mesh and holds everything the particle kernels need
without calling back into DOLFINx:

- the geometry nodes of every local cell (owned and ghost) and their coordinates;
- for affine simplices, the map ``x = origin + J X`` and its inverse ``X = K (x - origin)``
  precomputed per cell;
- the vertex-to-cell adjacency (CSR) and the cell centres, used to order the neighbour search of
  the transport step (seed paper 2.4), and the facet neighbours of simplices for its first guess
  (:class:`fembase.adjacency.CellAdjacency`);
- a lazily built DOLFINx bounding-box tree for the global fallback search.

Non-affine cells (quadrilaterals, hexahedra, degree-2 geometry) are pulled back with a vectorised
Newton iteration on the basix coordinate element.

Points are located without DOLFINx's ``compute_colliding_cells`` (:mod:`fembase.location`): every
candidate cell of the bounding-box tree is tested by pull-back and the reference-cell inside test
(for affine cells a matrix-vector product, 3-4 times cheaper than DOLFINx 0.5's GJK distance; for
curved cells a Newton iteration). For curved (degree-2) cells DOLFINx 0.5 measures the distance to
the cell's vertex simplex only, so it misses points in the part of a cell that bulges beyond its
straight edges (near a convex curved boundary) and accepts points between a straight edge and a
concave curved one (outside the domain); the bounding boxes are therefore padded by the cells'
largest bulge (:attr:`CellGeometry.curvature_padding`).
"""

from __future__ import annotations

from typing import Any, NamedTuple

import basix
import numpy as np
import numpy.typing as npt

import dolfinx.geometry
import dolfinx.mesh

from fembase import location
from fembase.adjacency import CellAdjacency, unique_pairs
from fembase.dolfinx_compat import bounding_box_tree, compute_collisions, coordinate_map, geometry_dofmap
from fembase.location import Candidates, Located

__all__ = ["Candidates", "CellGeometry", "Located", "OwnedLocation", "cell_nodes", "geometry_dofmap",
           "is_affine_simplex", "locate", "locate_owned", "owned_box", "pull_back", "push_forward", "unique_pairs"]

_BASIX_CELL = {
    dolfinx.mesh.CellType.interval: basix.CellType.interval,
    dolfinx.mesh.CellType.triangle: basix.CellType.triangle,
    dolfinx.mesh.CellType.tetrahedron: basix.CellType.tetrahedron,
    dolfinx.mesh.CellType.quadrilateral: basix.CellType.quadrilateral,
    dolfinx.mesh.CellType.hexahedron: basix.CellType.hexahedron,
}
_SIMPLICES = (dolfinx.mesh.CellType.interval, dolfinx.mesh.CellType.triangle, dolfinx.mesh.CellType.tetrahedron)


class CellGeometry:
    """Geometry data of all local cells (owned + ghost) of a mesh, built once.

    The cells' adjacency is a :class:`fembase.adjacency.CellAdjacency` (:attr:`adjacency`, its
    arrays repeated here); the point searches are those of :mod:`fembase.location`, among the
    candidates of this geometry's bounding-box tree.

    Args:
        mesh: A DOLFINx mesh with degree-1 or degree-2 Lagrange geometry.
        tol: Relative tolerance of the inside-cell test, in reference coordinates.

    Attributes:
        nodes: Geometry nodes of each cell, shape=(num_local_cells, num_nodes), int32.
        coords: Node coordinates, shape=(num_geometry_nodes, gdim), float64.
        affine: True for degree-1 simplices, where ``origin``, ``J`` and ``K`` are valid.
        origin: First vertex of each cell, shape=(num_local_cells, gdim).
        J: Jacobian of each cell map, shape=(num_local_cells, gdim, tdim).
        K: (Pseudo-)inverse Jacobian, shape=(num_local_cells, tdim, gdim).
        centres: Vertex average of each cell, shape=(num_local_cells, gdim).
        adjacency: The cells' adjacency through their vertices.
        v2c_offsets, v2c_cells: CSR vertex-to-cell adjacency over geometry nodes (int64 / int32).
    """

    def __init__(self, mesh: dolfinx.mesh.Mesh, /, *, tol: float = 1e-12) -> None:
        self.mesh = mesh
        self.tol = float(tol)
        self.tdim: int = mesh.topology.dim
        self.gdim: int = mesh.geometry.dim
        self.cell_type = mesh.topology.cell_type
        if self.cell_type not in _BASIX_CELL:
            raise NotImplementedError(f"cell type {self.cell_type} is not supported")
        self.basix_cell = _BASIX_CELL[self.cell_type]
        self.simplex = self.cell_type in _SIMPLICES
        cell_map = mesh.topology.index_map(self.tdim)
        self.num_owned_cells: int = cell_map.size_local
        self.num_local_cells: int = cell_map.size_local + cell_map.num_ghosts
        self.degree: int = coordinate_map(mesh).degree
        if self.degree > 2:
            raise NotImplementedError("geometry of degree > 2 is not supported")
        self.nodes = np.ascontiguousarray(geometry_dofmap(mesh)[: self.num_local_cells], dtype=np.int32)
        self.num_vertices: int = basix.geometry(self.basix_cell).shape[0]
        self.coordinate_element = basix.create_element(
            basix.ElementFamily.P, self.basix_cell, self.degree, basix.LagrangeVariant.gll_warped
        )
        self.affine = self.simplex and self.degree == 1
        self._set_coordinates()
        self.adjacency = CellAdjacency(self.nodes[:, : self.num_vertices], self.coords.shape[0])
        self.v2c_offsets, self.v2c_cells = self.adjacency.v2c_offsets, self.adjacency.v2c_cells
        self.max_valence = self.adjacency.max_valence

    def moved(self) -> None:
        """Take the mesh's node coordinates again after they moved (a deforming mesh: the same
        cells and nodes, other positions): the cell maps, centres and bounding-box tree are made
        anew, the adjacency is kept. Local (not collective)."""
        self._set_coordinates()

    def _set_coordinates(self) -> None:
        """Everything that depends on the node positions."""
        self.coords = np.ascontiguousarray(self.mesh.geometry.x[:, : self.gdim], dtype=np.float64)
        vertices = self.coords[self.nodes[:, : self.num_vertices]]
        self.centres = vertices.mean(axis=1)
        self.origin = np.ascontiguousarray(vertices[:, 0, :])
        if self.affine:
            self.J = np.ascontiguousarray(np.transpose(vertices[:, 1:, :] - vertices[:, :1, :], (0, 2, 1)))
        else:
            self.J = self.jacobians(np.arange(self.num_local_cells, dtype=np.int32),
                                    np.tile(basix.geometry(self.basix_cell).mean(axis=0), (self.num_local_cells, 1)))
        # Square Jacobians: LU inverse (the SVD-based pseudo-inverse costs ~5x more).
        self.K = np.ascontiguousarray(np.linalg.inv(self.J) if self.gdim == self.tdim and self.num_local_cells
                                      else np.linalg.pinv(self.J))
        self.curvature_padding: float = self._curvature_padding()
        self._tree: Any | None = None

    def _curvature_padding(self) -> float:
        """Largest distance of a geometry node from its position in the straight-sided (degree-1)
        cell: bounds how far a curved cell reaches beyond the box of its vertices (0 when
        ``degree == 1``; exact for quadratic edges, whose bulge peaks at the midpoint node)."""
        if self.degree == 1 or self.num_local_cells == 0:
            return 0.0
        linear = basix.create_element(basix.ElementFamily.P, self.basix_cell, 1, basix.LagrangeVariant.equispaced)
        phi = linear.tabulate(0, self.coordinate_element.points)[0, :, :, 0]
        vertices = self.coords[self.nodes[:, : self.num_vertices]]
        straight = np.einsum("nv,cvg->cng", phi, vertices)
        return float(np.linalg.norm(self.coords[self.nodes] - straight, axis=2).max())

    @property
    def vertex_neighbours(self) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int32]]:
        """:attr:`fembase.adjacency.CellAdjacency.vertex_neighbours` of the local cells."""
        return self.adjacency.vertex_neighbours

    @property
    def facet_neighbours(self) -> npt.NDArray[np.int32]:
        """:attr:`fembase.adjacency.CellAdjacency.facet_neighbours` of the local cells."""
        return self.adjacency.facet_neighbours

    # ------------------------------------------------------------------ maps
    def jacobians(self, cells: npt.NDArray[np.int32], xref: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """Jacobian dx/dX at reference points, shape=(m, gdim, tdim)."""
        if self.affine:
            return self.J[cells]
        tab = self.coordinate_element.tabulate(1, np.ascontiguousarray(xref))[1:, :, :, 0]
        xc = self.coords[self.nodes[cells]]
        return np.einsum("tmn,mng->mgt", tab, xc)

    def push_forward(self, cells: npt.NDArray[np.int32], xref: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """Physical coordinates of reference points ``xref`` in ``cells``, shape=(m, gdim)."""
        if self.affine:
            return self.origin[cells] + np.einsum("mgt,mt->mg", self.J[cells], xref)
        phi = self.coordinate_element.tabulate(0, np.ascontiguousarray(xref))[0, :, :, 0]
        return np.einsum("mn,mng->mg", phi, self.coords[self.nodes[cells]])

    def pull_back(
        self, cells: npt.NDArray[np.int32], x: npt.NDArray[np.float64], *, max_iterations: int = 30
    ) -> npt.NDArray[np.float64]:
        """Reference coordinates of physical points ``x`` (shape=(m, gdim)) in ``cells`` (shape=(m,)).

        Affine cells use the stored inverse map; others use a vectorised Newton iteration.
        """
        cells = np.asarray(cells, dtype=np.int32)
        x = np.asarray(x, dtype=np.float64).reshape(-1, self.gdim)
        if self.affine:
            return np.einsum("mtg,mg->mt", self.K[cells], x - self.origin[cells])
        xref = np.einsum("mtg,mg->mt", self.K[cells], x - self.centres[cells])
        xref += basix.geometry(self.basix_cell).mean(axis=0)
        active = np.arange(cells.shape[0])
        square = self.gdim == self.tdim
        for _ in range(max_iterations):
            if active.size == 0:
                break
            c, X = cells[active], xref[active]
            r = x[active] - self.push_forward(c, X)
            J = self.jacobians(c, X)
            # Square Jacobians: a batched LU solve (an SVD-based pseudo-inverse is ~10x slower).
            dX = np.linalg.solve(J, r[:, :, None])[:, :, 0] if square else np.einsum("mtg,mg->mt", np.linalg.pinv(J), r)
            xref[active] = X + dX
            step = np.linalg.norm(dX, axis=1)
            # Converged (Newton is quadratic: after a step below 1e-12 the error is at round-off,
            # where smaller steps are not reached), or far outside the reference cell.
            active = active[(step > 1e-12) & (np.abs(xref[active]).max(axis=1) < 1e3)]
        return xref

    def inside(self, xref: npt.NDArray[np.float64]) -> npt.NDArray[np.bool_]:
        """Whether reference points lie in the reference cell (tolerance ``tol``), shape=(m,)."""
        t = self.tol
        if self.simplex:
            return np.all(xref >= -t, axis=1) & (xref.sum(axis=1) <= 1.0 + t)
        return np.all((xref >= -t) & (xref <= 1.0 + t), axis=1)

    # ------------------------------------------------------------------ search
    @property
    def tree(self) -> Any:
        """Bounding-box tree over all local (owned + ghost) cells, built on first use."""
        if self._tree is None:
            cells = np.arange(self.num_local_cells, dtype=np.int32)
            # Padded by the cells' bulge (curved cells) and by round-off, so that points on the
            # boundary (or a facet) within round-off of a cell are tested by pull-back.
            padding = 1.01 * self.curvature_padding + 1e-12 * float(np.abs(self.coords).max(initial=1.0))
            self._tree = bounding_box_tree(self.mesh, self.tdim, cells, padding=padding)
        return self._tree

    def locate(self, points: npt.ArrayLike, *, owned_only: bool = False,
               candidates: Candidates | None = None) -> Located:
        """Find a local cell containing each point with the bounding-box tree, and pull back.

        Among several containing cells (point on a shared facet) the lowest local index is taken,
        which prefers owned cells over ghosts. A candidate cell of the tree contains a point when
        the point's pull-back lies in the reference cell (tolerance ``tol``): exact for affine
        cells (no distance computation), Newton for curved ones (module docstring).

        Args:
            points: Physical points, shape=(m, gdim).
            owned_only: Search the owned cells only (ghosts count as not found).
            candidates: Cells to test first (affine simplices; ignored otherwise): a point found
                in one of its candidates takes the lowest such cell, the others are searched with
                the tree. With every containing cell among the candidates the result is that of
                the tree alone; a point on a facet between candidates and other cells may take
                another (equally containing) cell.

        Returns:
            :class:`Located` with cells (-1 where no local cell contains the point) and xref.
        """
        return location.locate_points(self, points, self._tree_candidates, owned_only=owned_only,
                                      candidates=candidates)

    def _tree_candidates(self, pts: npt.NDArray[np.float64]) -> Candidates:
        """The bounding-box tree's candidate cells of each point (one group per point)."""
        p3 = np.zeros((pts.shape[0], 3), dtype=np.float64)
        p3[:, : self.gdim] = pts
        found = compute_collisions(self.tree, p3)
        return Candidates(np.arange(pts.shape[0], dtype=np.int64), np.asarray(found.offsets, dtype=np.int64),
                          np.asarray(found.array, dtype=np.int32))

    def max_over_containing(self, points: npt.ArrayLike, values: npt.NDArray[np.int32], /, *, default: int = -1,
                            candidates: Candidates | None = None
                            ) -> tuple[npt.NDArray[np.int32], npt.NDArray[np.bool_], npt.NDArray[np.bool_]]:
        """The largest ``values[c]`` over the local cells ``c`` containing each point.

        Args:
            points: Physical points, shape=(m, gdim).
            values: One integer per local cell (owned and ghost), shape=(num_local_cells,).
            default: Result for points in no local cell.
            candidates: Cells to test first (affine simplices; ignored otherwise). A point contained
                in one of its candidates is answered from them alone, so they must hold every
                cell containing it; the other points are searched with the tree.

        Returns:
            ``(largest, hit, touches_ghost)``, each shape=(m,): the largest value (``default``
            where no local cell contains the point), whether one does, whether a ghost cell does.
        """
        return location.max_over_containing(self, points, values, self._tree_candidates, default=default,
                                            candidates=candidates)

    def colliding(self, points: npt.ArrayLike, *, owned_only: bool = False
                  ) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int32], npt.NDArray[np.float64]]:
        """Every local cell containing each point (see :meth:`locate` for the test).

        Args:
            points: Physical points, shape=(m, gdim).
            owned_only: Test the owned cells only.

        Returns:
            CSR ``(offsets, cells, xref)``: the cells containing point ``i`` are
            ``cells[offsets[i]:offsets[i+1]]`` (in the tree's order), with the point's reference
            coordinates in each (``xref`` shape=(offsets[-1], tdim)).
        """
        return location.containing_cells(self, points, owned_only=owned_only)


def locate(mesh: dolfinx.mesh.Mesh, points: npt.ArrayLike, /, *, geometry: CellGeometry | None = None) -> Located:
    """Locate ``points`` (shape=(m, gdim)) in the local cells of ``mesh`` by bounding-box search.

    Args:
        mesh: The mesh.
        points: Physical points, shape=(m, gdim).
        geometry: Reuse an existing :class:`CellGeometry` of ``mesh`` (and its tree).

    Returns:
        :class:`Located`: ``cells`` int32 (-1 if not on this rank) and ``xref`` (m, tdim).
    """
    geom = geometry if geometry is not None else CellGeometry(mesh)
    return geom.locate(points)


# ---------------------------------------------------------------------- owned cells
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
    return mesh.topology.cell_type in _SIMPLICES and coordinate_map(mesh).degree == 1


def owned_box(mesh: dolfinx.mesh.Mesh) -> npt.NDArray[np.float64]:
    """Bounding box of this rank's owned cells, shape=(2, gdim) (lower > upper if none)."""
    gdim = mesh.geometry.dim
    box = np.empty((2, gdim))
    box[0], box[1] = np.inf, -np.inf
    num_owned = mesh.topology.index_map(mesh.topology.dim).size_local
    if num_owned:
        x = mesh.geometry.x[np.unique(geometry_dofmap(mesh)[:num_owned]), :gdim]
        box[0], box[1] = x.min(axis=0), x.max(axis=0)
        if coordinate_map(mesh).degree > 1:
            # A curved cell bulges beyond the box of its nodes (an arc between two boundary
            # nodes passes outside their coordinate range): pad by the largest bulge.
            pad = 1.01 * CellGeometry(mesh).curvature_padding
            box[0] -= pad
            box[1] += pad
    return box


_REFERENCE_COORDINATES = "_fembase_reference_coordinates"


def set_reference_coordinates(mesh: dolfinx.mesh.Mesh, x: npt.NDArray[np.float64], /) -> None:
    """Register the undeformed node positions ``x`` (shape=(num_nodes, 3), the layout of
    ``mesh.geometry.x``) of a mesh whose nodes move (a free surface): what must not depend on the
    motion's history (the particles' cell keys, a curved mesh's cell sizes in forms) is taken from
    them. The moved positions differ in round-off between partitions and between a run and its
    resume."""
    setattr(mesh, _REFERENCE_COORDINATES, x)


def reference_coordinates(mesh: dolfinx.mesh.Mesh, /) -> npt.NDArray[np.float64]:
    """The registered undeformed node positions (:func:`set_reference_coordinates`), or the
    mesh's own."""
    return getattr(mesh, _REFERENCE_COORDINATES, mesh.geometry.x)


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
    cmap = coordinate_map(mesh)
    out = np.empty((xref.shape[0], mesh.geometry.dim))
    for i in range(xref.shape[0]):
        out[i] = cmap.push_forward(xref[i : i + 1], nodes[i])[0]
    return out


def pull_back(mesh: dolfinx.mesh.Mesh, cells: npt.NDArray[np.int32], x: npt.NDArray[np.float64], /, *,
              geometry: CellGeometry | None = None) -> npt.NDArray[np.float64]:
    """Reference coordinates of physical points ``x`` (shape=(m, gdim)) in ``cells``; shape=(m, tdim).

    Affine simplices invert the map of each given cell (no data of the other cells needed);
    other cells go through :meth:`CellGeometry.pull_back` (of ``geometry``, built if omitted)."""
    tdim = mesh.topology.dim
    m = x.shape[0]
    if m == 0:
        return np.empty((0, tdim))
    if not is_affine_simplex(mesh):
        return (geometry if geometry is not None else CellGeometry(mesh)).pull_back(cells, x)
    nodes = cell_nodes(mesh, cells)
    jac = np.swapaxes(nodes[:, 1:, :] - nodes[:, :1, :], 1, 2)
    rhs = x - nodes[:, 0, :]
    if tdim == mesh.geometry.dim:
        return np.linalg.solve(jac, rhs[:, :, None])[:, :, 0]
    return np.stack([np.linalg.lstsq(jac[i], rhs[i], rcond=None)[0] for i in range(m)])


def locate_owned(mesh: dolfinx.mesh.Mesh, x: npt.ArrayLike, /, *, geometry: CellGeometry | None = None
                 ) -> OwnedLocation:
    """Find, for each point, an owned cell of this rank that contains it (not collective):
    :meth:`CellGeometry.locate` restricted to the owned cells. A point on a face shared by several
    owned cells gets the lowest local cell index.

    Args:
        mesh: The mesh.
        x: Points, shape=(m, gdim), float64.
        geometry: The mesh's :class:`CellGeometry`, to reuse (built for this call if omitted).

    Returns:
        The cells (-1 where no owned cell contains the point) and reference coordinates (NaN there).
    """
    gdim, tdim = mesh.geometry.dim, mesh.topology.dim
    x = np.asarray(x, dtype=np.float64).reshape(-1, gdim)
    m = x.shape[0]
    cells = np.full(m, -1, dtype=np.int32)
    xref = np.full((m, tdim), np.nan)
    if m == 0 or mesh.topology.index_map(tdim).size_local == 0:
        return OwnedLocation(cells, xref)
    found = (geometry if geometry is not None else CellGeometry(mesh)).locate(x, owned_only=True)
    hit = found.cells >= 0
    cells[hit] = found.cells[hit]
    xref[hit] = found.xref[hit]
    return OwnedLocation(cells, xref)
