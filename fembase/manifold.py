"""Where the geometry nodes of refined curved cells go: the manifold of an annulus.

DOLFINx refines straight-sided (P1) simplex meshes only (0.5's Plaza refinement fails on
second-order geometry), and refining straight-sided cells puts the new boundary vertices on the
chords, inside the circle. A :class:`ShellManifold` keeps the topology straight and *curves* it:

- the straight base mesh covers a polygonal annulus whose boundary vertices lie on the circles
  ``r = r_inner`` and ``r = r_outer``;
- a point map ``Phi`` takes a point ``x`` of the straight base cell ``K`` holding it through ``K``'s
  curved (second-order) map: ``Phi(x) = x + sum_e 4 lambda_a lambda_b d_e`` over the boundary
  edges ``e = (a, b)`` of ``K`` (``lambda``: barycentric coordinates of ``x`` in ``K``; ``d_e``: from
  the chord's midpoint to the circle), the blend of the parent cell's curved map (Gordon-Hall with
  quadratic edge bubbles). A point on a boundary edge is then put on its circle radially;
- :meth:`ShellManifold.curve` places every geometry node of a second-order (P2) mesh at ``Phi``
  of the straight node (the vertices and the edge midpoints of the straight cells) and
  :meth:`ShellManifold.straighten` undoes it (:meth:`ShellManifold.straight_points`, a fixed-point
  iteration, exact up to the radial step: ``O(h_base^4)``).

``Phi`` is smooth inside each base cell, and refined cells never straddle two base cells, so every
refined cell's map is smooth and its Jacobian differs from the straight one by ``O(h_base / r)``.
On the base cells' interior edges and vertices ``Phi`` is the identity (barycentric coordinates
below 1e-13 count as 0), so it depends on a point's coordinates and the base mesh only, never on
the rank: the curved mesh is the same on any number of ranks (measured: to one unit in the last
place, tests/test_shell_refinement.py).

Only the annulus (``gdim = 2``) is implemented (the tetrahedra of a spherical shell need face
bubbles as well: future work).
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

_ZERO = 1e-13
"""Barycentric coordinates below this count as 0 (points on a base cell's edge or vertex)."""


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
        self._geometry = None
        self._bubbles: npt.NDArray[np.float64] | None = None
        self._radius: npt.NDArray[np.float64] | None = None

    @property
    def fitted(self) -> bool:
        """Whether :meth:`fit` has given the manifold its base mesh."""
        return self._geometry is not None

    def fit(self, base: dolfinx.mesh.Mesh, /) -> None:
        """Take the straight base mesh the points lie in (not collective; again after the base is
        repartitioned): per local base cell and edge, the bubble ``d_e`` of a boundary edge (0 for
        interior edges) and the radius of its circle."""
        from fembase.geometry import CellGeometry

        if coordinate_map(base).degree != 1:
            raise ValueError("the manifold is fitted to a straight-sided (P1) base mesh")
        tdim, gdim = base.topology.dim, self.gdim
        base.topology.create_entities(1)
        base.topology.create_connectivity(tdim - 1, tdim)
        base.topology.create_connectivity(tdim, 1)
        geometry = CellGeometry(base)
        n = geometry.num_local_cells
        boundary = np.zeros(base.topology.index_map(1).size_local + base.topology.index_map(1).num_ghosts, dtype=bool)
        boundary[dolfinx.mesh.locate_entities_boundary(base, 1, lambda x: np.full(x.shape[1], True))] = True
        c2e = np.asarray(base.topology.connectivity(tdim, 1).array, dtype=np.int32).reshape(-1, len(EDGES[tdim]))[:n]
        # Each cell's vertices in a canonical order (by coordinates), so the barycentric coordinates
        # of a point do not depend on the order a mesh lists them in (ranks may list them otherwise).
        x = geometry.coords[geometry.nodes[:, : tdim + 1]]  # shape=(n, 3, gdim)
        order = np.lexsort(x.transpose(2, 0, 1)[::-1], axis=-1)
        x = np.take_along_axis(x, order[:, :, None], axis=1)
        c2e_sorted = np.empty_like(c2e)
        for j, (a, b) in enumerate(EDGES[tdim]):  # edge j of the sorted cell: opposite sorted vertex j
            c2e_sorted[:, j] = c2e[np.arange(n), order[:, j]]
        c2e = c2e_sorted
        self._origin = np.ascontiguousarray(x[:, 0])
        self._inverse = np.linalg.inv(np.transpose(x[:, 1:] - x[:, :1], (0, 2, 1))) if n else np.zeros((0, gdim, gdim))
        bubbles = np.zeros((n, len(EDGES[tdim]), gdim))
        radius = np.zeros((n, len(EDGES[tdim])))
        for j, (a, b) in enumerate(EDGES[tdim]):
            m = 0.5 * (x[:, a] + x[:, b])
            r = np.linalg.norm(m, axis=1)
            ra, rb = np.linalg.norm(x[:, a], axis=1), np.linalg.norm(x[:, b], axis=1)
            for target in (self.r_inner, self.r_outer):
                on = (boundary[c2e[:, j]] & (np.abs(ra - target) < 1e-8 * target)
                      & (np.abs(rb - target) < 1e-8 * target))
                bubbles[on, j] = m[on] * (target / r[on] - 1.0)[:, None]
                radius[on, j] = target
        self._geometry, self._bubbles, self._radius = geometry, bubbles, radius

    def _displacement(self, x: npt.NDArray[np.float64]) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """``Phi(x) - x`` before the radial step, and the radius of the circle each point lies on
        (0: none), for points of the base, x shape=(n, gdim)."""
        if self._geometry is None:
            raise RuntimeError("ShellManifold.fit(base) first")
        found = self._geometry.locate(x)
        if np.any(found.cells < 0):
            raise ValueError(f"{int(np.sum(found.cells < 0))} points lie outside this rank's base cells")
        xref = np.einsum("mtg,mg->mt", self._inverse[found.cells], x - self._origin[found.cells])
        lam = np.concatenate([1.0 - xref.sum(axis=1, keepdims=True), xref], axis=1)
        lam[np.abs(lam) < _ZERO] = 0.0
        displacement = np.zeros_like(x)
        on_circle = np.zeros(x.shape[0])
        for j, (a, b) in enumerate(EDGES[2]):
            displacement += (4.0 * lam[:, a] * lam[:, b])[:, None] * self._bubbles[found.cells, j]
            radius = self._radius[found.cells, j]
            on = (radius > 0.0) & (lam[:, j] == 0.0)  # edge j is opposite vertex j
            on_circle[on] = radius[on]
        return displacement, on_circle

    def curved_points(self, x: npt.NDArray[np.float64], /) -> npt.NDArray[np.float64]:
        """``Phi(x)``: points of this rank's base cells mapped onto the annulus, x shape=(n, gdim)."""
        x = np.ascontiguousarray(np.asarray(x, dtype=np.float64)[:, : self.gdim])
        displacement, on_circle = self._displacement(x)
        y = x + displacement
        on = on_circle > 0.0
        y[on] *= (on_circle[on] / np.linalg.norm(y[on], axis=1))[:, None]
        return y

    def straight_points(self, y: npt.NDArray[np.float64], /) -> npt.NDArray[np.float64]:
        """``Phi^-1(y)`` by fixed-point iteration ``x = y - (Phi(x) - x)`` (a contraction: ``Phi``
        is the identity up to ``O(h_base / r)`` in its derivative), y shape=(n, gdim); the radial
        step is not undone (``O(h_base^4)``)."""
        y = np.ascontiguousarray(np.asarray(y, dtype=np.float64)[:, : self.gdim])
        x = y.copy()
        for _ in range(60):
            r = np.linalg.norm(x, axis=1)
            inside = np.clip(r, self.r_inner * (1 + 1e-15), self.r_outer)  # keep the iterate in the base
            x_in = x * (inside / np.where(r > 0, r, 1.0))[:, None]
            new = y - self._displacement_clamped(x_in)
            if np.abs(new - x).max(initial=0.0) <= 1e-15 * self.r_outer:
                return new
            x = new
        return x

    def _displacement_clamped(self, x: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """``Phi(x) - x`` before the radial step for points that may lie just outside the base (the
        nearest base point along the ray is taken: outside points are moved in by halving steps)."""
        found = self._geometry.locate(x)
        missing = found.cells < 0
        if np.any(missing):
            x = x.copy()
            # A point between the chord and the circle: slide it towards the annulus' mid radius.
            mid = 0.5 * (self.r_inner + self.r_outer)
            for _ in range(60):
                r = np.linalg.norm(x[missing], axis=1)
                x[missing] *= ((r + 0.05 * (mid - r)) / r)[:, None]
                still = self._geometry.locate(x[missing]).cells < 0
                if not np.any(still):
                    break
                rows = np.flatnonzero(missing)
                missing = np.zeros_like(missing)
                missing[rows[still]] = True
        return self._displacement(x)[0]

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
