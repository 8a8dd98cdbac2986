"""What every domain between two radii around the origin shares (:class:`RadialDomain`): the
annulus, the spherical shell (:mod:`convection.geometry.shell`) and the sector
(:mod:`convection.geometry.sector`).

Their ``inner`` and ``outer`` boundaries are found as the boundary facets whose vertices lie on the
smallest / largest radius of the mesh (allreduced, so any partition and any refinement works);
gravity points to the origin; the cells are curved (``geometry_degree: 2``) or straight; the probe
points of their configs are a polar grid; particles are kept inside radially
(:func:`shell_confinement`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

import dolfinx
import numpy as np
import numpy.typing as npt
from mpi4py import MPI

from convection.geometry.domain import Domain, MeshSection, kept_facets
from convection.geometry.gravity import RadialGravity
from convection.geometry.probes import MAX_PROBES, bounded
from convection.schema import ConfigError, param
from fembase.dolfinx_compat import coordinate_map, entities_to_geometry

__all__ = ["RadialDomain", "check_radial_section", "polar_points", "radius_marker", "shell_confinement",
           "shell_radii"]


@dataclass(frozen=True)
class RadialMeshSettings:
    """The ``mesh`` keys of a domain between two radii around the origin (gmsh-meshed)."""

    radii: tuple[float, ...] = param((1.22, 2.22), length=(2,), exclusive_minimum=0.0,
                                     help="[inner, outer] radius of an annulus/spherical shell/sector around the "
                                          "origin")
    resolution: float | None = param(None, exclusive_minimum=0.0,
                                     help="target cell size of an annulus/spherical shell (gmsh)")
    geometry_degree: int = param(2, minimum=1,
                                 help="1: straight-sided cells; 2: curved cells on the circles/spheres (shells)")


def shell_radii(mesh: dolfinx.mesh.Mesh) -> tuple[float, float]:
    """Smallest and largest distance of a geometry node from the origin, over all ranks. Collective."""
    gdim = mesh.geometry.dim
    r = np.linalg.norm(mesh.geometry.x[:, :gdim], axis=1)
    lo = mesh.comm.allreduce(float(r.min()) if r.size else np.inf, op=MPI.MIN)
    hi = mesh.comm.allreduce(float(r.max()) if r.size else -np.inf, op=MPI.MAX)
    return lo, hi


def radius_marker(gdim: int, radius: float, tol: float) -> Callable[[np.ndarray], np.ndarray]:
    """Marker ``f(x) -> bool array`` for points (x shape=(3, n)) within ``tol`` of the circle or
    sphere of ``radius`` around the origin."""
    def marker(x: np.ndarray) -> np.ndarray:
        return np.abs(np.sqrt(np.sum(x[:gdim] ** 2, axis=0)) - radius) <= tol
    return marker


def polar_points(grid: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """Points shape=(3, n) from polar grid coordinates shape=(gdim, n): ``(r, phi)`` in 2D,
    ``(r, phi, theta)`` (theta from the +z axis) in 3D."""
    gdim = grid.shape[0]
    points = np.zeros((3, grid.shape[1]))
    r, phi = grid[0], grid[1]
    sin_theta = np.sin(grid[2]) if gdim == 3 else 1.0
    points[0], points[1] = r * np.cos(phi) * sin_theta, r * np.sin(phi) * sin_theta
    if gdim == 3:
        points[2] = r * np.cos(grid[2])
    return points


def check_radial_section(mesh: MeshSection, /) -> None:
    """The checks every geometry between two radii makes: a resolution, ordered radii, a geometry
    degree of 1 or 2."""
    keys = mesh.keys
    if keys.resolution is None:
        raise ConfigError(f"config key 'mesh.resolution': required for mesh.geometry {mesh.geometry} "
                          "(target cell size)")
    inner, outer = keys.radii
    if not inner < outer:
        raise ConfigError(f"config key 'mesh.radii': the inner radius must be below the outer one, got "
                          f"{list(keys.radii)}")
    if keys.geometry_degree not in (1, 2):
        raise ConfigError(f"config key 'mesh.geometry_degree': must be 1 or 2, got {keys.geometry_degree}")


def shell_confinement(mesh: dolfinx.mesh.Mesh, spec: Any, /, *, outer: bool = True
                      ) -> Callable[[npt.NDArray[np.float64]], None]:
    """``confine(x)``: move points (shape=(n, gdim), in place) that lie outside the radii of ``spec``
    (its ``inner_radius`` and ``outer_radius``: a shell's or a sector's), or within
    ``margin`` of its surfaces, radially to ``r_inner + margin`` / ``r_outer - margin``
    (``outer=False``: the inner surface only; a free outer surface moves).

    For particles (:class:`particles.manager.ParticleManager`): a straight Runge-Kutta step along a
    curved free-slip surface ends slightly outside it. The curved cells' boundary is within
    ``margin = 2 s^2 / r_inner`` of the true circle/sphere (``s``: the cells' largest node deviation
    from the straight-sided cell, :attr:`fembase.geometry.CellGeometry.curvature_padding`;
    parabola versus circle), so a confined point lies in a cell. Straight-sided cells (vertices on
    the circles/spheres) need no margin at the inner surface (the hole they leave is a polygon or
    polyhedron inscribed in the inner circle/sphere, so ``|x| >= r_inner`` is inside the mesh); at
    the outer surface the bound is the smallest distance from the origin to an outer boundary
    facet's line/plane. Collective (the bounds are allreduced).
    """
    if coordinate_map(mesh).degree == 1:
        lower = spec.inner_radius * (1.0 + 1e-12)
        upper = _outer_facet_distance(mesh, spec) * (1.0 - 1e-12)
    else:
        from fembase.geometry import CellGeometry

        padding = mesh.comm.allreduce(CellGeometry(mesh).curvature_padding, op=MPI.MAX)
        margin = 2.0 * padding**2 / spec.inner_radius + 1e-12 * spec.outer_radius
        lower, upper = spec.inner_radius + margin, spec.outer_radius - margin
    if not outer:
        upper = np.inf

    def confine(x: npt.NDArray[np.float64]) -> None:
        if x.shape[0] == 0:
            return
        r = np.sqrt(np.sum(x * x, axis=1))
        outside = (r < lower) | (r > upper)
        if np.any(outside):
            target = np.clip(r[outside], lower, upper)
            x[outside] *= (target / np.where(r[outside] > 0.0, r[outside], 1.0))[:, None]

    return confine


def _outer_facet_distance(mesh: dolfinx.mesh.Mesh, spec: Any, /) -> float:
    """Smallest distance from the origin to the line (2D) or plane (3D) of a straight-sided boundary
    facet on the outer circle/sphere, over all ranks (collective)."""
    tdim, gdim = mesh.topology.dim, mesh.geometry.dim
    mesh.topology.create_connectivity(tdim - 1, tdim)
    tol = 1e-8 * spec.outer_radius

    def on_outer(x: npt.NDArray[np.float64]) -> npt.NDArray[np.bool_]:
        return np.abs(np.linalg.norm(x[:gdim], axis=0) - spec.outer_radius) <= tol

    facets = dolfinx.mesh.locate_entities_boundary(mesh, tdim - 1, on_outer)
    local = spec.outer_radius
    if facets.size:
        nodes = entities_to_geometry(mesh, tdim - 1, facets)
        x = mesh.geometry.x[nodes][:, :, :gdim]
        if gdim == 2:
            normal = np.stack([x[:, 1, 1] - x[:, 0, 1], x[:, 0, 0] - x[:, 1, 0]], axis=1)
        else:
            normal = np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0])
        normal /= np.linalg.norm(normal, axis=1)[:, None]
        local = float(np.min(np.abs(np.sum(normal * x[:, 0], axis=1))))
    return float(mesh.comm.allreduce(local, op=MPI.MIN))


class RadialDomain(Domain):
    """A domain between the radii ``spec.inner_radius`` and ``spec.outer_radius`` around the origin,
    meshed by gmsh at ``spec.resolution`` (see the module docstring).

    Subclasses give :meth:`angle_limits` (the angular extent of the probe grid), :meth:`_mesh` and
    the boundaries other than ``inner`` and ``outer``.
    """

    top = "outer"
    bottom = "inner"

    def __init__(self, spec: Any, /) -> None:
        self.spec = spec
        self.gdim = spec.gdim

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.spec})"

    def expression_constants(self) -> dict[str, float]:
        return {"r_inner": self.spec.inner_radius, "r_outer": self.spec.outer_radius}

    def contains(self, points: npt.ArrayLike, /) -> npt.NDArray[np.bool_]:
        inner, outer = self.spec.inner_radius, self.spec.outer_radius
        r = np.linalg.norm(np.asarray(points, dtype=float).reshape(-1, self.gdim), axis=1)
        return (r >= inner * (1.0 - 1e-12)) & (r <= outer * (1.0 + 1e-12))

    @property
    def curved(self) -> bool:
        return self.spec.geometry_degree >= 2

    def angle_limits(self) -> list[tuple[float, float]]:
        """The range of each angle of the probe grid (radians)."""
        raise NotImplementedError

    def probe_axes(self, level: int, /) -> tuple[list[npt.NDArray[np.float64]], Callable]:
        """A grid in radius and angles with a spacing of half the cell size (at the outer radius),
        ends included (:mod:`convection.geometry.probes`)."""
        inner, outer = self.spec.inner_radius, self.spec.outer_radius
        h = 0.5 * self.spec.resolution
        angles = self.angle_limits()
        wanted = [min((outer - inner) / h, MAX_PROBES), *(min((hi - lo) * outer / h, MAX_PROBES) for lo, hi in angles)]
        counts = bounded([max(math.ceil(n), 2) for n in wanted])
        limits = [(inner, outer), *angles]
        return [np.linspace(lo, hi, n + 1) for (lo, hi), n in zip(limits, counts)], polar_points

    @property
    def gravity(self) -> RadialGravity:
        return RadialGravity(self.spec.outer_radius)

    def create_mesh(self, comm: MPI.Comm, /, *, owners: npt.NDArray[np.int32] | None = None,
                    straight: bool = False) -> dolfinx.mesh.Mesh:
        return self._mesh(comm, replace(self.spec, geometry_degree=1) if straight else self.spec, owners)

    def _mesh(self, comm: MPI.Comm, spec: Any, owners: npt.NDArray[np.int32] | None, /) -> dolfinx.mesh.Mesh:
        raise NotImplementedError

    def estimated_cells(self) -> float:
        """The volume over the volume of an equilateral simplex of edge ``resolution``."""
        h = self.spec.resolution
        cell = math.sqrt(3.0) / 4.0 * h * h if self.gdim == 2 else h**3 / (6.0 * math.sqrt(2.0))
        return self.spec.volume / cell

    def confinement(self, mesh: dolfinx.mesh.Mesh, /, *, free: tuple[str, ...] = ()
                    ) -> Callable[[npt.NDArray[np.float64]], None]:
        """Moves particles outside the radii back in (:func:`shell_confinement`; collective); not
        at a free outer surface."""
        return shell_confinement(mesh, self.spec, outer=self.top not in free)

    def inward(self, x: npt.NDArray[np.float64], /) -> npt.NDArray[np.float64]:
        """Radially in from the outer half, out from the inner half (into the domain from the
        nearer surface)."""
        x = np.asarray(x, dtype=np.float64)[:, : self.gdim]
        r = np.linalg.norm(x, axis=1)
        middle = 0.5 * (self.spec.inner_radius + self.spec.outer_radius)
        return np.where((r > middle)[:, None], -1.0, 1.0) * self.up(x)

    def locate_facets(self, mesh: dolfinx.mesh.Mesh, name: str, /, *,
                      radii: tuple[float, float] | None = None) -> npt.NDArray[np.int32]:
        """The facets of ``inner`` or ``outer`` (``radii``: the mesh's, if known)."""
        if (kept := kept_facets(mesh, name)) is not None:
            return kept
        self.check_boundary_names([name])
        inner, outer = shell_radii(mesh) if radii is None else radii
        return self._facets(mesh, radius_marker(mesh.geometry.dim, inner if name == "inner" else outer,
                                                1e-8 * outer))

    @staticmethod
    def _facets(mesh: dolfinx.mesh.Mesh, marker: Callable[[np.ndarray], np.ndarray]) -> npt.NDArray[np.int32]:
        fdim = mesh.topology.dim - 1
        mesh.topology.create_connectivity(fdim, mesh.topology.dim)
        return dolfinx.mesh.locate_entities_boundary(mesh, fdim, marker).astype(np.int32)
