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
from fembase.shell_map import ShellMap

__all__ = ["EDGES", "ShellManifold", "boundary_entities", "boundary_radius_error"]


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
        self._map: ShellMap | None = None

    @property
    def fitted(self) -> bool:
        """Whether :meth:`fit` has given the manifold its base mesh."""
        return self._map is not None

    def fit(self, base: dolfinx.mesh.Mesh, /) -> None:
        """Take the straight base mesh the points lie in (collective; again after the base is
        repartitioned): per local base cell its vertices in a canonical order, the inverse of its
        affine map and its curved entities (:meth:`fembase.shell_map.ShellMap.fit`)."""
        if coordinate_map(base).degree != 1:
            raise ValueError("the manifold is fitted to a straight-sided (P1) base mesh")
        self._map = ShellMap.fit(base, self.r_inner, self.r_outer, self.interfaces)

    def _fitted_map(self) -> ShellMap:
        """The map :meth:`fit` made."""
        if self._map is None:
            raise RuntimeError("ShellManifold.fit(base) first")
        return self._map

    def curved_points(self, x: npt.NDArray[np.float64], /) -> npt.NDArray[np.float64]:
        """``Phi(x)``: points of this rank's base cells mapped onto the annulus, x shape=(n, gdim)."""
        x = np.ascontiguousarray(np.asarray(x, dtype=np.float64)[:, : self.gdim])
        return self._fitted_map().curved_points(x)

    def straight_points(self, y: npt.NDArray[np.float64], /) -> npt.NDArray[np.float64]:
        """``Phi^-1(y)``, y shape=(n, gdim) (not collective).

        Each point starts in the base cell holding it (else the one with the nearest centre),
        iterates ``x = y - d_K(x)`` through that cell's map ``d_K`` (extended beyond the cell: a
        contraction, ``d_K`` has derivative ``O(h_base / r)``) until its step is at round-off, and
        moves to the cell across the facet where the result left its cell (up to 4 times). In 2D the
        radial step is not undone (``O(h_base^4)``)."""
        phi = self._fitted_map()
        return phi.straight_points(np.ascontiguousarray(np.asarray(y, dtype=np.float64)[:, : self.gdim]))

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
