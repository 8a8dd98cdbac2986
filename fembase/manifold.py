"""Where the geometry nodes of refined curved cells go: the manifold of an annulus or spherical shell.

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
place, tests/convection/geometry/test_shell_refinement.py).

The spherical shell (``gdim = 3``) blends by projection instead (Lenoir's / Scott's curved
simplices): for each boundary entity ``E`` of ``K`` on a sphere of radius ``R`` (a boundary face,
else each boundary edge), with ``s = sum_{v in E} lambda_v`` and ``x_E = sum_{v in E} lambda_v v / s``
(the point of ``E`` seen from the opposite vertices),

    Phi(x) = x + sum_E s^2 (R x_E / |x_E| - x_E).

On ``E`` itself ``s = 1`` and ``x_E = x``, so boundary points land on the sphere exactly (no radial
step); restricted to a face of ``K`` the sum depends only on that face's barycentric coordinates
and on whether its edges lie on the boundary (the face formula restricted to a face through one of
its edges is that edge's formula), so two cells sharing a face map it alike. A quadratic face
bubble would leave the face interior ``O(h^3)`` inside the sphere; the projection does not. The
weight ``s^2`` (not ``s``) makes ``Phi`` differentiable at the vertex opposite a curved face.
A base cell with all four vertices on one sphere is refused (:meth:`ShellManifold.fit`).

Interior circles/spheres the mesh conforms to (``interfaces``, e.g. the surface a delta-function
force acts on in benchmarks/shell/analytical.py) are curved the same way: their edges (2D) and
faces (3D) are treated as boundary ones, from both sides.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from mpi4py import MPI

import dolfinx.mesh

from fembase import dolfinx_compat as compat
from fembase.curved_mesh import curve_mesh, straighten_mesh
from fembase.dolfinx_compat import coordinate_map
from fembase.entities import EDGES, boundary_entities

__all__ = ["EDGES", "ShellManifold", "boundary_entities", "boundary_radius_error"]

_ZERO = 1e-13
"""Barycentric coordinates below this count as 0 (points on a base cell's edge or vertex)."""

_SLOTS = 3
"""Curved entities a tetrahedron can have (a face on one sphere and none on the other, or up to
three boundary edges on one sphere without their face, or an edge on each sphere)."""


class ShellManifold:
    """The annulus or spherical shell ``r_inner <= |x| <= r_outer`` as the image of a polygonal /
    polyhedral one (see the module docstring).

    Args:
        r_inner: Inner radius.
        r_outer: Outer radius.
        gdim: 2 (annulus) or 3 (spherical shell).
        interfaces: Radii of interior circles/spheres the mesh conforms to
            (:attr:`convection.geometry.mesh.ShellSpec.interfaces`): their edges (and faces) are curved onto
            them as the boundary's are. An interior edge/face counts as on an interface when all
            its vertices lie on it (as the facets of the forcing are found,
            benchmarks/shell/analytical.py).
    """

    def __init__(self, r_inner: float, r_outer: float, gdim: int, /, *, interfaces: tuple[float, ...] = ()) -> None:
        if gdim not in (2, 3):
            raise ValueError(f"a shell manifold is 2D (annulus) or 3D (spherical shell), got gdim={gdim}")
        if not 0.0 < r_inner < r_outer:
            raise ValueError(f"need 0 < r_inner < r_outer, got {r_inner}, {r_outer}")
        if any(not r_inner < r < r_outer for r in interfaces):
            raise ValueError(f"interface radii must lie strictly between {r_inner} and {r_outer}, got {interfaces}")
        self.r_inner, self.r_outer, self.gdim = float(r_inner), float(r_outer), gdim
        self.interfaces = tuple(float(r) for r in interfaces)
        self._geometry = None
        self._bubbles: npt.NDArray[np.float64] | None = None
        self._radius: npt.NDArray[np.float64] | None = None
        self._masks: npt.NDArray[np.float64] | None = None  # 3D: (cells, _SLOTS, 4) vertices of each entity

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
        boundary = boundary_entities(base, 1)
        c2e = np.asarray(base.topology.connectivity(tdim, 1).array, dtype=np.int32).reshape(-1, len(EDGES[tdim]))[:n]
        # Each cell's vertices in a canonical order (by coordinates), so the barycentric coordinates
        # of a point do not depend on the order a mesh lists them in (ranks may list them otherwise).
        x = geometry.coords[geometry.nodes[:, : tdim + 1]]  # shape=(n, tdim + 1, gdim)
        order = np.lexsort(x.transpose(2, 0, 1)[::-1], axis=-1)
        x = np.take_along_axis(x, order[:, :, None], axis=1)
        c2e = self._sorted_edges(c2e, order, tdim)
        self._origin = np.ascontiguousarray(x[:, 0])
        self._vertices = np.ascontiguousarray(x)
        self._order = order  # sorted vertex j of cell c is the mesh's local vertex order[c, j]
        self._inverse = np.linalg.inv(np.transpose(x[:, 1:] - x[:, :1], (0, 2, 1))) if n else np.zeros((0, gdim, gdim))
        radii = np.linalg.norm(x, axis=2)  # shape=(n, tdim + 1)
        targets = (self.r_inner, self.r_outer, *self.interfaces)
        on_sphere = {t: np.abs(radii - t) < 1e-8 * t for t in targets}
        interface = {t: t in self.interfaces for t in targets}  # interior surfaces: any edge/face on them
        if tdim == 3:
            self._geometry = geometry
            self._fit_faces(base, n, c2e, order, boundary, on_sphere, interface)
            return
        bubbles = np.zeros((n, len(EDGES[tdim]), gdim))
        radius = np.zeros((n, len(EDGES[tdim])))
        for j, (a, b) in enumerate(EDGES[tdim]):
            m = 0.5 * (x[:, a] + x[:, b])
            r = np.linalg.norm(m, axis=1)
            for target in targets:
                on = (interface[target] | boundary[c2e[:, j]]) & on_sphere[target][:, a] & on_sphere[target][:, b]
                bubbles[on, j] = m[on] * (target / r[on] - 1.0)[:, None]
                radius[on, j] = target
        self._geometry, self._bubbles, self._radius = geometry, bubbles, radius

    @staticmethod
    def _sorted_edges(c2e: npt.NDArray[np.int32], order: npt.NDArray[np.int64], tdim: int) -> npt.NDArray[np.int32]:
        """The cell-edge connectivity for the cells' vertices taken in ``order`` (edge j of the
        sorted cell joins sorted vertices EDGES[tdim][j])."""
        index = np.full((tdim + 1, tdim + 1), -1, dtype=np.int64)
        for j, (a, b) in enumerate(EDGES[tdim]):
            index[a, b] = index[b, a] = j
        rows = np.arange(c2e.shape[0])
        out = np.empty_like(c2e)
        for j, (a, b) in enumerate(EDGES[tdim]):
            out[:, j] = c2e[rows, index[order[:, a], order[:, b]]]
        return out

    def _fit_faces(self, base: dolfinx.mesh.Mesh, n: int, c2e: npt.NDArray[np.int32], order: npt.NDArray[np.int64],
                   boundary_edge: npt.NDArray[np.bool_], on_sphere: dict[float, npt.NDArray[np.bool_]],
                   interface: dict[float, bool]) -> None:
        """3D: per cell the curved entities (a boundary or interface face on a sphere, else its
        boundary or interface edges on that sphere) as vertex masks (sorted order) and radii."""
        base.topology.create_connectivity(3, 2)
        c2f = np.asarray(base.topology.connectivity(3, 2).array, dtype=np.int32).reshape(-1, 4)[:n]
        c2f = np.take_along_axis(c2f, order, axis=1)  # face j is opposite vertex j, also after sorting
        boundary_face = boundary_entities(base, 2)
        masks = np.zeros((n, _SLOTS, 4))
        radius = np.zeros((n, _SLOTS))
        used = np.zeros(n, dtype=np.int64)

        def add(cells: npt.NDArray[np.int64], vertices: tuple[int, ...], target: float) -> None:
            slot = used[cells]
            if np.any(slot >= _SLOTS):
                raise ValueError("a base cell touches the shell's boundary in too many entities to be curved")
            masks[cells, slot] = 0.0
            for v in vertices:
                masks[cells, slot, v] = 1.0
            radius[cells, slot] = target
            used[cells] += 1

        for target, on in on_sphere.items():
            if np.any(on.all(axis=1)):
                raise ValueError(f"{int(on.all(axis=1).sum())} base cell(s) have all four vertices on the sphere "
                                 f"r = {target:g}: the manifold cannot curve them (remesh the base)")
            face_on = np.zeros(n, dtype=bool)
            for j in range(4):  # face j: the vertices other than j
                others = [v for v in range(4) if v != j]
                cells = np.flatnonzero((interface[target] | boundary_face[c2f[:, j]]) & on[:, others].all(axis=1))
                face_on[cells] = True
                add(cells, tuple(others), target)
            for j, (a, b) in enumerate(EDGES[3]):
                cells = np.flatnonzero(~face_on & (interface[target] | boundary_edge[c2e[:, j]]) & on[:, a] & on[:, b])
                add(cells, (a, b), target)
        self._masks, self._radius = masks, radius

    def _displacement(self, x: npt.NDArray[np.float64]) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """``Phi(x) - x`` before the radial step, and the radius of the circle each point lies on
        (0: none), for points of the base, x shape=(n, gdim)."""
        if self._geometry is None:
            raise RuntimeError("ShellManifold.fit(base) first")
        found = self._geometry.locate(x)
        if np.any(found.cells < 0):
            raise ValueError(f"{int(np.sum(found.cells < 0))} points lie outside this rank's base cells")
        return self._displacement_in(found.cells, x)

    def _barycentric(self, cells: npt.NDArray[np.int32], x: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """Barycentric coordinates (sorted vertex order) of points x in the straight base cells
        ``cells`` (also of points outside them), shape=(n, tdim + 1)."""
        xref = np.einsum("mtg,mg->mt", self._inverse[cells], x - self._origin[cells])
        return np.concatenate([1.0 - xref.sum(axis=1, keepdims=True), xref], axis=1)

    def _displacement_in(self, cells: npt.NDArray[np.int32], x: npt.NDArray[np.float64]
                         ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """:meth:`_displacement` through the map of the given base cells (shape=(n,)); the formula
        extends smoothly beyond a cell, which the inverse uses."""
        lam = self._barycentric(cells, x)
        lam[np.abs(lam) < _ZERO] = 0.0
        displacement = np.zeros_like(x)
        on_circle = np.zeros(x.shape[0])
        if self.gdim == 3:
            vertices = self._vertices[cells]  # shape=(m, 4, 3), sorted order
            for k in range(_SLOTS):
                radius = self._radius[cells, k]
                on = radius > 0.0
                if not np.any(on):
                    continue
                weights = lam[on] * self._masks[cells[on], k]  # shape=(m_on, 4)
                s = weights.sum(axis=1)
                inside = s > 0.0
                rows = np.flatnonzero(on)[inside]
                xe = np.einsum("mv,mvg->mg", weights[inside], vertices[rows]) / s[inside, None]
                projected = xe * (radius[rows] / np.linalg.norm(xe, axis=1))[:, None]
                displacement[rows] += (s[inside] ** 2)[:, None] * (projected - xe)
            return displacement, on_circle
        for j, (a, b) in enumerate(EDGES[2]):
            displacement += (4.0 * lam[:, a] * lam[:, b])[:, None] * self._bubbles[cells, j]
            radius = self._radius[cells, j]
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
        """``Phi^-1(y)``, y shape=(n, gdim) (not collective).

        Each point starts in the base cell holding it (else the nearest, :meth:`_start_cells`), iterates ``x = y - d_K(x)``
        through that cell's map ``d_K`` (extended beyond the cell: a contraction, ``d_K`` has
        derivative ``O(h_base / r)``) until its step is at round-off, and moves to the cell across
        the facet where the result left its cell (up to 4 times). In 2D the radial step is not
        undone (``O(h_base^4)``)."""
        if self._geometry is None:
            raise RuntimeError("ShellManifold.fit(base) first")
        y = np.ascontiguousarray(np.asarray(y, dtype=np.float64)[:, : self.gdim])
        cells = self._start_cells(y)
        neighbours = self._geometry.facet_neighbours
        x = y.copy()
        todo = np.arange(y.shape[0])
        for _ in range(5):
            if todo.size == 0:
                break
            x[todo] = self._fixed_point(cells[todo], y[todo], x[todo])
            lam = self._barycentric(cells[todo], x[todo])
            worst = np.argmin(lam, axis=1)
            outside = lam[np.arange(todo.size), worst] < -1e-10
            rows, j = todo[outside], worst[outside]
            nxt = neighbours[cells[rows], self._order[cells[rows], j]]  # across the facet opposite vertex j
            moves = nxt >= 0
            cells[rows[moves]] = nxt[moves]
            todo = rows[moves]
        return x

    def _fixed_point(self, cells: npt.NDArray[np.int32], y: npt.NDArray[np.float64], x: npt.NDArray[np.float64]
                     ) -> npt.NDArray[np.float64]:
        """Solve ``x + d_K(x) = y`` in fixed cells by iteration; each point until its own step is at round-off."""
        x = x.copy()
        active = np.arange(y.shape[0])
        for _ in range(60):
            if active.size == 0:
                break
            new = y[active] - self._displacement_in(cells[active], x[active])[0]
            moving = np.abs(new - x[active]).max(axis=1) > 1e-15 * self.r_outer
            x[active] = new
            active = active[moving]
        return x

    def _start_cells(self, y: npt.NDArray[np.float64]) -> npt.NDArray[np.int32]:
        """A local base cell near each point: the one holding it, else the one with the nearest
        centre (a point between a flat boundary face and its sphere, or moved by ``Phi`` across a
        base facet into a cell this rank does not hold), shape=(n,)."""
        cells = self._geometry.locate(y).cells.copy()
        missing = np.flatnonzero(cells < 0)
        centres = self._geometry.centres
        if missing.size and centres.shape[0] == 0:
            raise ValueError(f"{missing.size} points, and no base cell on this rank")
        for chunk in np.array_split(missing, max(1, missing.size // 256)):
            if chunk.size:
                distance = np.linalg.norm(y[chunk, None, :] - centres[None, :, :], axis=2)
                cells[chunk] = np.argmin(distance, axis=1)
        return cells

    def curve(self, straight: dolfinx.mesh.Mesh, /, *, degree: int = 2) -> dolfinx.mesh.Mesh:
        """The curved mesh of a straight-sided (P1) simplex mesh: the same cells on the same ranks,
        geometry of ``degree`` (1 or 2) with every node at ``Phi`` of the straight node (collective;
        :func:`fembase.curved_mesh.curve_mesh`)."""
        return curve_mesh(straight, self.curved_points, degree=degree)

    def straighten(self, curved: dolfinx.mesh.Mesh, /) -> dolfinx.mesh.Mesh:
        """The straight-sided (P1) mesh of a curved one: its vertices mapped back by ``Phi^-1``,
        the same cells on the same ranks (collective)."""
        return straighten_mesh(curved, self.straight_points)


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
