"""The point map ``Phi`` of a :class:`fembase.manifold.ShellManifold` on its fitted straight base mesh,
and its inverse (the formulas are in :mod:`fembase.manifold`'s docstring).

A :class:`ShellMap` holds, per local base cell, its vertices in a canonical order and the inverse of
its affine map (barycentric coordinates), and the cell's curved entities: in 2D an
:class:`EdgeBubbles` (Gordon-Hall blending with quadratic edge bubbles), in 3D a
:class:`ProjectedEntities` (projection blending onto the spheres).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

import dolfinx.mesh

from fembase.entities import EDGES, boundary_entities

if TYPE_CHECKING:
    from fembase.geometry import CellGeometry

__all__ = ["EdgeBubbles", "ProjectedEntities", "ShellMap"]

_ZERO = 1e-13
"""Barycentric coordinates below this count as 0 (points on a base cell's edge or vertex)."""

_SLOTS = 3
"""Curved entities a tetrahedron can have (a face on one sphere and none on the other, or up to
three boundary edges on one sphere without their face, or an edge on each sphere)."""


class EdgeBubbles:
    """2D: per base cell and edge (sorted vertex order) the bubble ``d_e`` from the chord's midpoint
    to its circle (0 for an edge on none) and that circle's radius (0: none).

    Args:
        bubbles: shape=(num_cells, 3, 2).
        radius: shape=(num_cells, 3).
    """

    def __init__(self, bubbles: npt.NDArray[np.float64], radius: npt.NDArray[np.float64], /) -> None:
        self.bubbles, self.radius = bubbles, radius

    @classmethod
    def fit(cls, x: npt.NDArray[np.float64], c2e: npt.NDArray[np.int32], boundary_edge: npt.NDArray[np.bool_],
            radii: tuple[float, ...], on_sphere: dict[float, npt.NDArray[np.bool_]], interface: dict[float, bool]
            ) -> EdgeBubbles:
        """The bubbles of the boundary and interface edges of cells with vertices ``x`` (sorted
        order, shape=(n, 3, 2)) and edges ``c2e`` (sorted order), onto the circles of ``radii``
        (``on_sphere``: which vertices lie on each)."""
        n, gdim = x.shape[0], x.shape[2]
        bubbles = np.zeros((n, len(EDGES[2]), gdim))
        radius = np.zeros((n, len(EDGES[2])))
        for j, (a, b) in enumerate(EDGES[2]):
            m = 0.5 * (x[:, a] + x[:, b])
            r = np.linalg.norm(m, axis=1)
            for target in radii:
                on = (interface[target] | boundary_edge[c2e[:, j]]) & on_sphere[target][:, a] & on_sphere[target][:, b]
                bubbles[on, j] = m[on] * (target / r[on] - 1.0)[:, None]
                radius[on, j] = target
        return cls(bubbles, radius)

    def displacement(self, cells: npt.NDArray[np.int32], lam: npt.NDArray[np.float64]
                     ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """``Phi(x) - x`` before the radial step and the radius of the circle each point lies on (0:
        none), for points with barycentric coordinates ``lam`` (shape=(m, 3)) in ``cells``."""
        displacement = np.zeros((lam.shape[0], self.bubbles.shape[2]))
        on_circle = np.zeros(lam.shape[0])
        for j, (a, b) in enumerate(EDGES[2]):
            displacement += (4.0 * lam[:, a] * lam[:, b])[:, None] * self.bubbles[cells, j]
            radius = self.radius[cells, j]
            on = (radius > 0.0) & (lam[:, j] == 0.0)  # edge j is opposite vertex j
            on_circle[on] = radius[on]
        return displacement, on_circle


class ProjectedEntities:
    """3D: per base cell its curved entities (a boundary or interface face on a sphere, else its
    boundary or interface edges on that sphere) as vertex masks (sorted order) and radii.

    Args:
        vertices: Each cell's vertices in sorted order, shape=(num_cells, 4, 3).
        masks: The vertices of each entity, shape=(num_cells, 3, 4) (1.0: in it).
        radius: The radius of each entity's sphere (0: no entity), shape=(num_cells, 3).
    """

    def __init__(self, vertices: npt.NDArray[np.float64], masks: npt.NDArray[np.float64],
                 radius: npt.NDArray[np.float64], /) -> None:
        self.vertices, self.masks, self.radius = vertices, masks, radius

    @classmethod
    def fit(cls, base: dolfinx.mesh.Mesh, x: npt.NDArray[np.float64], c2e: npt.NDArray[np.int32],
            order: npt.NDArray[np.int64], boundary_edge: npt.NDArray[np.bool_],
            on_sphere: dict[float, npt.NDArray[np.bool_]], interface: dict[float, bool]) -> ProjectedEntities:
        """The curved entities of the cells with vertices ``x`` (sorted order, shape=(n, 4, 3)):
        ``order`` sorts the mesh's vertices of each cell, ``c2e`` its edges in sorted order
        (collective: the boundary faces)."""
        n = x.shape[0]
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
        return cls(x, masks, radius)

    def displacement(self, cells: npt.NDArray[np.int32], lam: npt.NDArray[np.float64]
                     ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """``Phi(x) - x`` for points with barycentric coordinates ``lam`` (shape=(m, 4)) in
        ``cells``, and zeros (the projection puts boundary points on their spheres: no radial step)."""
        displacement = np.zeros((lam.shape[0], 3))
        on_circle = np.zeros(lam.shape[0])
        vertices = self.vertices[cells]  # shape=(m, 4, 3), sorted order
        for k in range(_SLOTS):
            radius = self.radius[cells, k]
            on = radius > 0.0
            if not np.any(on):
                continue
            weights = lam[on] * self.masks[cells[on], k]  # shape=(m_on, 4)
            s = weights.sum(axis=1)
            inside = s > 0.0
            rows = np.flatnonzero(on)[inside]
            xe = np.einsum("mv,mvg->mg", weights[inside], vertices[rows]) / s[inside, None]
            projected = xe * (radius[rows] / np.linalg.norm(xe, axis=1))[:, None]
            displacement[rows] += (s[inside] ** 2)[:, None] * (projected - xe)
        return displacement, on_circle


_LOST = 1e-8
"""A point of :meth:`ShellMap.straight_points` whose result lies outside its last cell by more than this
(barycentric) was lost by its walk."""

_SEARCHED = 64
"""How many local cells, nearest first, :meth:`ShellMap._search` tries for a point its walk lost."""


class ShellMap:
    """``Phi`` and its inverse on a fitted straight base mesh (made by :meth:`fit`).

    Args:
        geometry: The base mesh's cell geometry (which base cell holds a point).
        vertices: Each local base cell's vertices in a canonical order (by coordinates),
            shape=(num_cells, tdim + 1, gdim).
        order: Sorted vertex ``j`` of cell ``c`` is the mesh's local vertex ``order[c, j]``.
        entities: The cells' curved entities.
        r_outer: The outer radius (the scale of the inverse's round-off).
    """

    def __init__(self, geometry: CellGeometry, vertices: npt.NDArray[np.float64], order: npt.NDArray[np.int64],
                 entities: EdgeBubbles | ProjectedEntities, r_outer: float, /) -> None:
        n, gdim = vertices.shape[0], geometry.gdim
        self.geometry, self.order, self.entities, self.r_outer = geometry, order, entities, r_outer
        self.origin = np.ascontiguousarray(vertices[:, 0])
        self.vertices = np.ascontiguousarray(vertices)
        self.inverse = (np.linalg.inv(np.transpose(vertices[:, 1:] - vertices[:, :1], (0, 2, 1))) if n
                        else np.zeros((0, gdim, gdim)))

    @classmethod
    def fit(cls, base: dolfinx.mesh.Mesh, r_inner: float, r_outer: float, interfaces: tuple[float, ...], /
            ) -> ShellMap:
        """The map of a straight-sided (P1) base mesh of the shell ``r_inner <= |x| <= r_outer``
        conforming to the interior circles/spheres of radii ``interfaces`` (collective)."""
        from fembase.geometry import CellGeometry

        tdim = base.topology.dim
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
        c2e = _sorted_edges(c2e, order, tdim)
        distance = np.linalg.norm(x, axis=2)  # shape=(n, tdim + 1)
        radii = (r_inner, r_outer, *interfaces)
        on_sphere = {t: np.abs(distance - t) < 1e-8 * t for t in radii}
        interface = {t: t in interfaces for t in radii}  # interior surfaces: any edge/face on them
        entities = (ProjectedEntities.fit(base, x, c2e, order, boundary, on_sphere, interface) if tdim == 3
                    else EdgeBubbles.fit(x, c2e, boundary, radii, on_sphere, interface))
        return cls(geometry, x, order, entities, r_outer)

    def barycentric(self, cells: npt.NDArray[np.int32], x: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """Barycentric coordinates (sorted vertex order) of points x in the straight base cells
        ``cells`` (also of points outside them), shape=(n, tdim + 1)."""
        xref = np.einsum("mtg,mg->mt", self.inverse[cells], x - self.origin[cells])
        return np.concatenate([1.0 - xref.sum(axis=1, keepdims=True), xref], axis=1)

    def displacement_in(self, cells: npt.NDArray[np.int32], x: npt.NDArray[np.float64]
                        ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """``Phi(x) - x`` before the radial step, and the radius of the circle each point lies on
        (0: none), through the map of the given base cells (shape=(n,)); the formula extends
        smoothly beyond a cell, which the inverse uses."""
        lam = self.barycentric(cells, x)
        lam[np.abs(lam) < _ZERO] = 0.0
        return self.entities.displacement(cells, lam)

    def curved_points(self, x: npt.NDArray[np.float64], /) -> npt.NDArray[np.float64]:
        """``Phi(x)`` of points of this rank's base cells, x shape=(n, gdim), contiguous."""
        found = self.geometry.locate(x)
        if np.any(found.cells < 0):
            raise ValueError(f"{int(np.sum(found.cells < 0))} points lie outside this rank's base cells")
        displacement, on_circle = self.displacement_in(found.cells, x)
        y = x + displacement
        on = on_circle > 0.0
        y[on] *= (on_circle[on] / np.linalg.norm(y[on], axis=1))[:, None]
        return y

    def straight_points(self, y: npt.NDArray[np.float64], /) -> npt.NDArray[np.float64]:
        """``Phi^-1(y)``, y shape=(n, gdim), contiguous (not collective): see
        :meth:`fembase.manifold.ShellManifold.straight_points`.

        A walk that ends outside its cell (it met the shell's boundary, or cycled, before the cell
        of the answer: the nearest centre of a point between a flat boundary face and its sphere can
        lie cells away on a coarse base, and the map extended far beyond a cell leads astray) is
        replaced by a search of the nearest cells (:meth:`_search`)."""
        x, lost = self._walk(y, self._start_cells(y))
        if lost.size:
            x[lost] = self._search(y[lost], x[lost])
        return x

    def _walk(self, y: npt.NDArray[np.float64], cells: npt.NDArray[np.int32], /
              ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.int64]]:
        """``Phi^-1(y)`` by the fixed point in ``cells`` (changed in place), moving across the facet
        where the result left its cell (up to 4 times); and the points whose result lies outside its
        last cell by more than :data:`_LOST` (barycentric)."""
        neighbours = self.geometry.facet_neighbours
        x = y.copy()
        todo = np.arange(y.shape[0])
        for _ in range(5):
            if todo.size == 0:
                break
            x[todo] = self._fixed_point(cells[todo], y[todo], x[todo])
            lam = self.barycentric(cells[todo], x[todo])
            worst = np.argmin(lam, axis=1)
            outside = lam[np.arange(todo.size), worst] < -1e-10
            rows, j = todo[outside], worst[outside]
            nxt = neighbours[cells[rows], self.order[cells[rows], j]]  # across the facet opposite vertex j
            moves = nxt >= 0
            cells[rows[moves]] = nxt[moves]
            todo = rows[moves]
        lost = np.flatnonzero(self.barycentric(cells, x).min(axis=1, initial=0.0) < -_LOST) if y.shape[0] else \
            np.zeros(0, dtype=np.int64)
        return x, lost

    def _search(self, y: npt.NDArray[np.float64], x: npt.NDArray[np.float64], /) -> npt.NDArray[np.float64]:
        """``Phi^-1`` of points a walk lost: the fixed point in each of the :data:`_SEARCHED` local
        cells whose centres are nearest, the first (nearest) whose result lies in it; a point none
        takes keeps ``x``."""
        centres = self.geometry.centres
        count = min(_SEARCHED, centres.shape[0])
        x = x.copy()
        for i in range(y.shape[0]):
            cells = np.argsort(np.linalg.norm(centres - y[i], axis=1), kind="stable")[:count].astype(np.int32)
            ys = np.repeat(y[i : i + 1], count, axis=0)
            with np.errstate(over="ignore", invalid="ignore"):  # the map extended far beyond a cell diverges
                candidates = self._fixed_point(cells, ys, ys)
                inside = np.flatnonzero(self.barycentric(cells, candidates).min(axis=1) >= -_LOST)
            if inside.size:
                x[i] = candidates[inside[0]]
        return x

    def _fixed_point(self, cells: npt.NDArray[np.int32], y: npt.NDArray[np.float64], x: npt.NDArray[np.float64]
                     ) -> npt.NDArray[np.float64]:
        """Solve ``x + d_K(x) = y`` in fixed cells by iteration; each point until its own step is at round-off."""
        x = x.copy()
        active = np.arange(y.shape[0])
        for _ in range(60):
            if active.size == 0:
                break
            new = y[active] - self.displacement_in(cells[active], x[active])[0]
            moving = np.abs(new - x[active]).max(axis=1) > 1e-15 * self.r_outer
            x[active] = new
            active = active[moving]
        return x

    def _start_cells(self, y: npt.NDArray[np.float64]) -> npt.NDArray[np.int32]:
        """A local base cell near each point: the one holding it, else the one with the nearest
        centre (a point between a flat boundary face and its sphere, or moved by ``Phi`` across a
        base facet into a cell this rank does not hold), shape=(n,)."""
        cells = self.geometry.locate(y).cells.copy()
        missing = np.flatnonzero(cells < 0)
        centres = self.geometry.centres
        if missing.size and centres.shape[0] == 0:
            raise ValueError(f"{missing.size} points, and no base cell on this rank")
        for chunk in np.array_split(missing, max(1, missing.size // 256)):
            if chunk.size:
                distance = np.linalg.norm(y[chunk, None, :] - centres[None, :, :], axis=2)
                cells[chunk] = np.argmin(distance, axis=1)
        return cells


def _sorted_edges(c2e: npt.NDArray[np.int32], order: npt.NDArray[np.int64], tdim: int) -> npt.NDArray[np.int32]:
    """The cell-edge connectivity for the cells' vertices taken in ``order`` (edge j of the sorted
    cell joins sorted vertices EDGES[tdim][j])."""
    index = np.full((tdim + 1, tdim + 1), -1, dtype=np.int64)
    for j, (a, b) in enumerate(EDGES[tdim]):
        index[a, b] = index[b, a] = j
    rows = np.arange(c2e.shape[0])
    out = np.empty_like(c2e)
    for j, (a, b) in enumerate(EDGES[tdim]):
        out[:, j] = c2e[rows, index[order[:, a], order[:, b]]]
    return out
