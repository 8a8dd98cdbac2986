"""A 2D cylindrical sector (ASPECT's 2D chunk): ``mesh.geometry: sector``.

The region ``r_inner <= r <= r_outer``, ``phi_west <= phi <= phi_east`` (``phi`` counterclockwise
from the +x axis, in degrees in the config, the span below 180 degrees), meshed by gmsh like the
annulus (the annulus intersected with a wedge; curved second-order cells with ``geometry_degree:
2``). Boundaries ``inner``, ``outer`` (arcs) and ``west``, ``east`` (the straight radial sides at
``phi_west`` and ``phi_east``); gravity along ``-x/|x|``. Free slip is weak (Nitsche) on all four:
the sides are oblique to the axes. The conductive reference of the Nusselt number through the arcs
is ``Q = (phi_east - phi_west) delta_T / ln(r_outer / r_inner)``. Rigid rotations are not free
(the radial sides stop them); the pressure is pinned at one dof for a direct solve. Runs on a
sector do not adapt or repartition yet (no manifold places the nodes of refined cells on its arcs
and sides).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import dolfinx
import numpy as np
import numpy.typing as npt
from mpi4py import MPI

from convection.geometry.domain import DomainContext, MeshSection, kept_facets, safe_product
from convection.geometry.mesh import gmsh_mesh, mesh_uniformly
from convection.geometry.radial import RadialDomain, RadialMeshSettings, check_radial_section, shell_radii
from convection.schema import ConfigError, param

__all__ = ["SECTOR_BOUNDARIES", "Sector", "SectorSpec", "create_sector_mesh"]

SECTOR_BOUNDARIES: tuple[str, ...] = ("inner", "outer", "west", "east")


@dataclass(frozen=True)
class SectorMeshSettings(RadialMeshSettings):
    """The ``mesh`` keys of a sector: a radial domain's and its angles."""

    angles: tuple[float, ...] = param((0.0, 90.0), length=(2,),
                                      help="sector: [west, east] angles in degrees, counterclockwise from +x (span "
                                           "below 180)")


@dataclass(frozen=True)
class SectorSpec:
    """A 2D cylindrical sector around the origin.

    Attributes:
        inner_radius, outer_radius: Radii of the arcs ``inner`` and ``outer``.
        angles: ``(phi_west, phi_east)`` in degrees, counterclockwise from +x, ``0 < east - west < 180``.
        resolution: Target cell size (gmsh's mesh size, uniform).
        geometry_degree: 1 (straight-sided cells) or 2 (curved cells, boundary nodes on the arcs).
    """

    inner_radius: float = 1.22
    outer_radius: float = 2.22
    angles: tuple[float, float] = (0.0, 90.0)
    resolution: float = 0.1
    geometry_degree: int = 2

    gdim: ClassVar[int] = 2

    def __post_init__(self) -> None:
        if not 0.0 < self.inner_radius < self.outer_radius:
            raise ValueError(f"need 0 < inner_radius < outer_radius, got {self.inner_radius}, {self.outer_radius}")
        if not 0.0 < self.angles[1] - self.angles[0] < 180.0:
            raise ValueError(f"the sector spans 0 to 180 degrees (east - west), got {self.angles}")
        if not self.resolution > 0.0:
            raise ValueError(f"resolution must be positive, got {self.resolution}")
        if self.geometry_degree not in (1, 2):
            raise ValueError(f"geometry_degree must be 1 or 2, got {self.geometry_degree}")

    @classmethod
    def from_settings(cls, keys: SectorMeshSettings, /) -> SectorSpec:
        """The sector of a checked ``mesh`` section's keys."""
        if keys.resolution is None:
            raise ValueError("a sector needs a resolution (mesh.resolution)")
        inner, outer = (float(r) for r in keys.radii)
        west, east = (float(a) for a in keys.angles)
        return cls(inner, outer, (west, east), float(keys.resolution), int(keys.geometry_degree))

    @property
    def radians(self) -> tuple[float, float]:
        return math.radians(self.angles[0]), math.radians(self.angles[1])

    @property
    def span(self) -> float:
        """The opening angle ``phi_east - phi_west`` in radians."""
        west, east = self.radians
        return east - west

    @property
    def volume(self) -> float:
        """Exact area of the sector."""
        return 0.5 * self.span * (self.outer_radius**2 - self.inner_radius**2)


def _sector_model(gmsh: Any, spec: SectorSpec) -> None:
    """Build and mesh the sector in gmsh's current model (rank 0 only): the annulus cut by a wedge
    (a triangle from the origin whose far side lies outside the outer circle)."""
    occ = gmsh.model.occ
    west, east = spec.radians
    far = 2.0 * spec.outer_radius / math.cos(0.5 * spec.span)
    corners = [occ.addPoint(0.0, 0.0, 0.0), occ.addPoint(far * math.cos(west), far * math.sin(west), 0.0),
               occ.addPoint(far * math.cos(east), far * math.sin(east), 0.0)]
    lines = [occ.addLine(corners[i], corners[(i + 1) % 3]) for i in range(3)]
    wedge = occ.addPlaneSurface([occ.addCurveLoop(lines)])
    ring, _ = occ.cut([(2, occ.addDisk(0.0, 0.0, 0.0, spec.outer_radius, spec.outer_radius))],
                      [(2, occ.addDisk(0.0, 0.0, 0.0, spec.inner_radius, spec.inner_radius))])
    occ.intersect(ring, [(2, wedge)])
    occ.synchronize()
    gmsh.model.addPhysicalGroup(2, [tag for _, tag in gmsh.model.getEntities(2)], 1)
    mesh_uniformly(gmsh, 2, spec.resolution, spec.geometry_degree, untangle=False)


def create_sector_mesh(comm: MPI.Comm, spec: SectorSpec, /, *, owners: npt.NDArray[np.int32] | None = None,
                       msh_file: str | Path | None = None) -> dolfinx.mesh.Mesh:
    """Mesh the sector of ``spec`` with gmsh on rank 0 and distribute it (collective;
    :func:`convection.geometry.mesh.gmsh_mesh`)."""
    return gmsh_mesh(comm, lambda gmsh: _sector_model(gmsh, spec), gdim=2, name=f"sector_{id(spec)}", owners=owners,
                     msh_file=msh_file)


def _line_marker(angle: float, tol: float) -> Callable[[np.ndarray], np.ndarray]:
    """Marker for points (x shape=(3, n)) within ``tol`` of the ray from the origin at ``angle``."""
    c, s = math.cos(angle), math.sin(angle)

    def marker(x: np.ndarray) -> np.ndarray:
        return (np.abs(c * x[1] - s * x[0]) <= tol) & (c * x[0] + s * x[1] > 0.0)
    return marker


class Sector(RadialDomain):
    """A 2D cylindrical sector (:class:`SectorSpec`; see the module docstring)."""

    name: ClassVar[str] = "sector"
    description: ClassVar[str] = ("2D cylindrical sector (ASPECT's 2D chunk) between two radii and two angles "
                                  "(gmsh, curved cells)")
    Settings: ClassVar[type] = SectorMeshSettings
    config_boundaries: ClassVar[tuple[str, ...]] = SECTOR_BOUNDARIES
    boundary_descriptions: ClassVar[dict[str, str]] = {
        "inner": "the inner surface r = r_inner", "outer": "the outer surface r = r_outer",
        "west": "the radial side at the west angle", "east": "the radial side at the east angle"}
    refinable: ClassVar[bool] = False
    boundaries: tuple[str, ...] = SECTOR_BOUNDARIES

    # ------------------------------------------------------------------ config
    @classmethod
    def build(cls, settings: SectorMeshSettings, context: DomainContext, /) -> Sector:
        return cls(SectorSpec.from_settings(settings))

    @classmethod
    def config_gdim(cls, mesh: MeshSection, /) -> int:
        return 2

    @classmethod
    def check_config(cls, mesh: MeshSection, /, *, changed_by: str | None) -> None:
        check_radial_section(mesh)
        west, east = mesh.keys.angles
        if not 0.0 < east - west < 180.0:
            raise ConfigError(f"config key 'mesh.angles': [west, east] in degrees with 0 < east - west < 180, got "
                              f"{list(mesh.keys.angles)}")

    @classmethod
    def base_cells_bound(cls, mesh: MeshSection, /) -> float:
        keys = mesh.keys
        inner, outer = keys.radii
        west, east = keys.angles
        area = 0.5 * math.radians(east - west) * (outer - inner) * (outer + inner)
        return safe_product(area / 0.4330127, 1.0 / keys.resolution, 1.0 / keys.resolution) + 1.0

    def angle_limits(self) -> list[tuple[float, float]]:
        return [self.spec.radians]

    def boundary_axis(self, name: str, /) -> tuple[int, bool]:
        self.check_boundary_names([name])
        return {"inner": (0, False), "outer": (0, True), "west": (1, False), "east": (1, True)}[name]

    # ------------------------------------------------------------------ mesh and boundaries
    def _mesh(self, comm: MPI.Comm, spec: SectorSpec, owners: npt.NDArray[np.int32] | None, /) -> dolfinx.mesh.Mesh:
        return create_sector_mesh(comm, spec, owners=owners)

    def locate_facets(self, mesh: dolfinx.mesh.Mesh, name: str, /, *,
                      radii: tuple[float, float] | None = None) -> npt.NDArray[np.int32]:
        if (kept := kept_facets(mesh, name)) is not None:
            return kept
        if name not in ("west", "east"):
            return super().locate_facets(mesh, name, radii=radii)
        west, east = self.spec.radians
        return self._facets(mesh, _line_marker(west if name == "west" else east, 1e-8 * self.spec.outer_radius))

    def opposite(self, name: str, /) -> tuple[str, str]:
        if name in ("inner", "outer"):
            return "inner", "outer"
        raise ValueError(f"no Nusselt number through {name!r} of the sector; through 'inner' or 'outer'")

    def contains(self, points: npt.ArrayLike, /) -> npt.NDArray[np.bool_]:
        x = np.asarray(points, dtype=float).reshape(-1, 2)
        west, east = self.spec.radians
        # the angle from the sector's middle, in (-pi, pi]: no wrap-around at +-pi
        middle = 0.5 * (west + east)
        offset = np.angle(np.exp(1j * (np.arctan2(x[:, 1], x[:, 0]) - middle)))
        return super().contains(x) & (np.abs(offset) <= 0.5 * (east - west) + 1e-12)

    def nusselt(self, mesh: dolfinx.mesh.Mesh, name: str, heat_flow: float, delta_T: float, area: float, /) -> float:
        """``Q / Q_conductive``, ``Q_conductive = (phi_east - phi_west) delta_T / ln(r_o / r_i)``."""
        inner, outer = shell_radii(mesh)
        return float(heat_flow / (self.spec.span * delta_T / math.log(outer / inner)))
