"""Where the geometry nodes of refined curved cells go: the manifold of an annulus.

DOLFINx refines straight-sided (P1) simplex meshes only (0.5's Plaza refinement fails on
second-order geometry), and refining straight-sided cells puts the new boundary vertices on the
chords, inside the circle. A :class:`ShellManifold` keeps the topology straight and *curves* it:

- the straight mesh covers a polygonal annulus whose boundary vertices (those of the coarse base
  mesh) lie on the circles ``r = r_inner`` and ``r = r_outer``;
- a point map ``Phi`` takes that polygonal annulus onto the true one (a *radial* transfinite rule):
  along the ray of angle ``theta`` it maps the segment between the inner and outer polygons,
  radii ``rho_in(theta)`` and ``rho_out(theta)``, linearly onto ``[r_inner, r_outer]``, so a point
  on a boundary chord lands on its circle exactly and a boundary vertex of the base stays where it is;
- :meth:`ShellManifold.curve` places every geometry node of a second-order (P2) mesh at ``Phi``
  of the straight node (the vertices and the edge midpoints of the straight cells) and
  :meth:`ShellManifold.straighten` undoes it (``Phi`` has the explicit inverse
  :meth:`ShellManifold.straight_points`).

``Phi`` depends on a point's coordinates and the base mesh's boundary polygon only, never on a
cell or a rank, so the curved mesh is the same on any number of ranks (bit for bit, given the same
straight mesh). Its derivative differs from the identity by ``O(h_base / r_inner)``, so cells of
any refinement level keep a positive Jacobian.

Only the annulus (``gdim = 2``) is implemented: the spherical shell's polyhedral boundary needs a
search for the boundary triangle below a point (future work).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from mpi4py import MPI

import dolfinx.mesh

from fembase import dolfinx_compat as compat
from fembase.distribute import MeshPiece, create_mesh_from_piece
from fembase.dolfinx_compat import coordinate_element_from, coordinate_map, geometry_dofmap

__all__ = ["EDGES", "ShellManifold", "boundary_radius_error"]

EDGES: dict[int, tuple[tuple[int, int], ...]] = {
    2: ((1, 2), (0, 2), (0, 1)),
    3: ((2, 3), (1, 3), (1, 2), (0, 3), (0, 2), (0, 1)),
}
"""The local vertices of each edge of a triangle / tetrahedron in the reference (basix) order, the
order of the edge nodes of a second-order Lagrange cell."""

_SNAP = 1e-12
"""Relative radial position (0 inner, 1 outer) within which a mapped point is put on its circle."""


class ShellManifold:
    """The annulus ``r_inner <= |x| <= r_outer`` as the image of a polygonal annulus (see the module
    docstring).

    Args:
        r_inner: Inner radius.
        r_outer: Outer radius.
        gdim: 2 (annulus); 3 raises NotImplementedError.
    """

    def __init__(self, r_inner: float, r_outer: float, gdim: int, /) -> None:
        if gdim != 2:
            raise NotImplementedError("curving refined cells is implemented for the annulus (gdim 2) only")
        if not 0.0 < r_inner < r_outer:
            raise ValueError(f"need 0 < r_inner < r_outer, got {r_inner}, {r_outer}")
        self.r_inner, self.r_outer, self.gdim = float(r_inner), float(r_outer), gdim
        self._polygons: tuple[tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]], ...] | None = None

    @property
    def fitted(self) -> bool:
        """Whether :meth:`fit` has given the manifold its boundary polygons."""
        return self._polygons is not None

    def fit(self, base: dolfinx.mesh.Mesh, /) -> None:
        """Take the boundary polygons from the straight base mesh (collective): its boundary vertices,
        gathered on every rank, split by radius and sorted by angle."""
        if coordinate_map(base).degree != 1:
            raise ValueError("the manifold is fitted to a straight-sided (P1) base mesh")
        tdim = base.topology.dim
        base.topology.create_connectivity(tdim - 1, tdim)
        vertices = dolfinx.mesh.locate_entities_boundary(base, 0, lambda x: np.full(x.shape[1], True))
        nodes = compat.entities_to_geometry(base, 0, vertices).reshape(-1)
        local = np.ascontiguousarray(base.geometry.x[nodes, : self.gdim])
        points = np.unique(np.concatenate(base.comm.allgather(local)), axis=0)
        r = np.linalg.norm(points, axis=1)
        inner = np.abs(r - self.r_inner) < np.abs(r - self.r_outer)
        polygons = []
        for chosen, radius in ((inner, self.r_inner), (~inner, self.r_outer)):
            p = points[chosen]
            if p.shape[0] < 3 or np.max(np.abs(np.linalg.norm(p, axis=1) - radius)) > 1e-8 * radius:
                raise ValueError(f"the base mesh's boundary vertices do not lie on the circle r = {radius}")
            angle = np.arctan2(p[:, 1], p[:, 0])
            order = np.argsort(angle, kind="stable")
            polygons.append((angle[order], p[order]))
        self._polygons = tuple(polygons)

    def _radii(self, theta: npt.NDArray[np.float64], direction: npt.NDArray[np.float64]
               ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """Radii of the inner and outer polygons along the rays of angle ``theta`` (unit
        ``direction``, shape=(n, 2))."""
        if self._polygons is None:
            raise RuntimeError("ShellManifold.fit(base) first")
        radii = []
        for angle, p in self._polygons:
            k = (np.searchsorted(angle, theta, side="right") - 1) % angle.size
            a, b = p[k], p[(k + 1) % angle.size]
            normal = np.stack([b[:, 1] - a[:, 1], a[:, 0] - b[:, 0]], axis=1)
            radii.append(np.sum(normal * a, axis=1) / np.sum(normal * direction, axis=1))
        return radii[0], radii[1]

    def curved_points(self, x: npt.NDArray[np.float64], /) -> npt.NDArray[np.float64]:
        """``Phi(x)``: points of the polygonal annulus mapped onto the annulus, x shape=(n, gdim)."""
        x = np.asarray(x, dtype=np.float64)[:, : self.gdim]
        r = np.linalg.norm(x, axis=1)
        theta = np.arctan2(x[:, 1], x[:, 0])
        direction = np.stack([np.cos(theta), np.sin(theta)], axis=1)
        rho_in, rho_out = self._radii(theta, direction)
        s = (r - rho_in) / (rho_out - rho_in)
        s = np.where(np.abs(s) < _SNAP, 0.0, np.where(np.abs(s - 1.0) < _SNAP, 1.0, s))
        return direction * (self.r_inner + s * (self.r_outer - self.r_inner))[:, None]

    def straight_points(self, y: npt.NDArray[np.float64], /) -> npt.NDArray[np.float64]:
        """``Phi^-1(y)``: points of the annulus mapped back to the polygonal one, y shape=(n, gdim)."""
        y = np.asarray(y, dtype=np.float64)[:, : self.gdim]
        r = np.linalg.norm(y, axis=1)
        theta = np.arctan2(y[:, 1], y[:, 0])
        direction = np.stack([np.cos(theta), np.sin(theta)], axis=1)
        rho_in, rho_out = self._radii(theta, direction)
        s = (r - self.r_inner) / (self.r_outer - self.r_inner)
        return direction * (rho_in + s * (rho_out - rho_in))[:, None]

    def curve(self, straight: dolfinx.mesh.Mesh, /, *, degree: int = 2) -> dolfinx.mesh.Mesh:
        """The curved mesh of a straight-sided (P1) simplex mesh: the same cells on the same ranks,
        geometry of ``degree`` (1 or 2) with every node at ``Phi`` of the straight node (collective).

        The new mesh's nodes are numbered rank by rank: each rank's owned straight vertices, then
        its owned edges (a node per edge midpoint), so the result depends on the straight mesh only.
        """
        if coordinate_map(straight).degree != 1:
            raise ValueError("curve() takes a straight-sided (P1) mesh")
        comm = straight.comm
        tdim, gdim = straight.topology.dim, straight.geometry.dim
        num_owned = straight.topology.index_map(tdim).size_local
        dofs = geometry_dofmap(straight)[:num_owned]
        node_map = straight.geometry.index_map()
        x = straight.geometry.x
        vertex_global = np.asarray(node_map.local_to_global(np.ascontiguousarray(dofs.reshape(-1), dtype=np.int32)),
                                   dtype=np.int64).reshape(num_owned, -1)
        owned_nodes = node_map.size_local
        starts = np.concatenate([[0], np.cumsum(comm.allgather(owned_nodes))]).astype(np.int64)
        total_nodes = int(starts[-1])
        own_x = [x[:owned_nodes, :gdim]]
        cells = [vertex_global]
        if degree == 2:
            straight.topology.create_entities(1)
            straight.topology.create_connectivity(tdim, 1)
            c2e = straight.topology.connectivity(tdim, 1)
            edge_map = straight.topology.index_map(1)
            width = len(EDGES[tdim])
            local_edges = np.asarray(c2e.array, dtype=np.int32).reshape(-1, width)[:num_owned]
            # DOLFINx's cell-edge connectivity is in the reference order of the edges (the same as
            # EDGES), which the check below confirms through the vertices.
            edge_global = np.asarray(edge_map.local_to_global(np.ascontiguousarray(local_edges.reshape(-1))),
                                     dtype=np.int64).reshape(num_owned, width) + total_nodes
            cells.append(edge_global)
            owned_edges = edge_map.size_local
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
            own_x.append(midpoint)
            self._check_edges(straight, dofs, local_edges)
        # The global node numbering is vertices block by block, then edges: rank r's piece holds its
        # owned vertices and its owned edges, which is not one contiguous block of that numbering,
        # so the cells are renumbered to the pieces' concatenation order.
        edge_starts = (np.concatenate([[0], np.cumsum(comm.allgather(own_x[1].shape[0]))]).astype(np.int64)
                       if degree == 2 else None)
        piece_starts = starts + (edge_starts if edge_starts is not None else 0)

        def renumber_vertices(g: npt.NDArray[np.int64]) -> npt.NDArray[np.int64]:
            rank = np.searchsorted(starts, g, side="right") - 1
            return g - starts[rank] + piece_starts[rank]

        renumbered = [renumber_vertices(vertex_global)]
        if degree == 2:
            g = edge_global - total_nodes
            rank = np.searchsorted(edge_starts, g, side="right") - 1
            renumbered.append(g - edge_starts[rank] + piece_starts[rank] + (starts[rank + 1] - starts[rank]))
        node_x = np.concatenate(own_x)
        curved_x = self.curved_points(node_x)
        piece = MeshPiece(np.concatenate(renumbered, axis=1), curved_x, np.full(num_owned, comm.rank, dtype=np.int32))
        domain = compat.mesh_domain(coordinate_element_from((straight.topology.cell_name(), degree, gdim)))
        return create_mesh_from_piece(comm, piece, domain).mesh

    @staticmethod
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

    def straighten(self, curved: dolfinx.mesh.Mesh, /) -> dolfinx.mesh.Mesh:
        """The straight-sided (P1) mesh of a curved one: its vertices mapped back by ``Phi^-1``,
        the same cells on the same ranks (collective)."""
        comm = curved.comm
        tdim, gdim = curved.topology.dim, curved.geometry.dim
        num_owned = curved.topology.index_map(tdim).size_local
        dofs = geometry_dofmap(curved)[:num_owned, : tdim + 1]
        node_map = curved.geometry.index_map()
        glob = np.asarray(node_map.local_to_global(np.ascontiguousarray(dofs.reshape(-1), dtype=np.int32)),
                          dtype=np.int64).reshape(num_owned, -1)
        x = self.straight_points(curved.geometry.x[: node_map.size_local, :gdim])
        piece = MeshPiece(glob, x, np.full(num_owned, comm.rank, dtype=np.int32))
        domain = compat.mesh_domain(coordinate_element_from((curved.topology.cell_name(), 1, gdim)))
        return create_mesh_from_piece(comm, piece, domain).mesh


def boundary_radius_error(mesh: dolfinx.mesh.Mesh, r_inner: float, r_outer: float, /) -> float:
    """Largest relative distance of a boundary geometry node from its circle/sphere (collective)."""
    tdim = mesh.topology.dim
    mesh.topology.create_connectivity(tdim - 1, tdim)
    facets = dolfinx.mesh.locate_entities_boundary(mesh, tdim - 1, lambda x: np.full(x.shape[1], True))
    local = 0.0
    if facets.size:
        nodes = compat.entities_to_geometry(mesh, tdim - 1, facets).reshape(-1)
        r = np.linalg.norm(mesh.geometry.x[nodes, : mesh.geometry.dim], axis=1)
        local = float(np.max(np.minimum(np.abs(r - r_inner) / r_inner, np.abs(r - r_outer) / r_outer)))
    return float(mesh.comm.allreduce(local, op=MPI.MAX))
