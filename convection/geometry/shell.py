"""An annulus (2D) or spherical shell (3D) around the origin: ``mesh.geometry: annulus`` or
``spherical_shell``.

The region ``r_inner <= |x| <= r_outer`` (:class:`ShellSpec`), meshed by gmsh on rank 0 with a
target cell size ``resolution`` and distributed (:func:`convection.geometry.mesh.gmsh_mesh`). With
``geometry_degree: 2`` (the default) the cells are second-order (curved) triangles/tetrahedra whose
boundary nodes lie on the circles/spheres, so the discrete boundary is within ``O(h^3)`` of the
true one (a straight-sided mesh is only ``O(h^2)`` close, which limits the convergence of
free-slip solutions). Boundaries ``inner`` and ``outer``, found as the boundary facets whose
vertices lie on the smallest / largest radius of the mesh (allreduced, so any partition and any
refinement works); gravity along ``-x/|x|``. Free slip is imposed weakly (Nitsche); with free slip
on both surfaces rigid rotations about the origin solve the homogeneous problem. Optional
``interfaces`` (radii strictly between the two) are meshed conformingly, e.g. for forcing
concentrated on a surface ``r = r'``. Refined meshes are curved by :class:`fembase.manifold.ShellManifold`.

A fixed shell with ``stokes.solver: multigrid`` gets its levels by refinement
(:meth:`ShellDomain.mesh_levels`): with ``L`` levels the run's mesh is gmsh's straight shell at
``resolution * 2^(L-1)``, refined uniformly ``L - 1`` times and curved by the manifold, so the
cells are about ``resolution`` in size and every coarser level is one of the refinement's meshes
(curved the same way; :mod:`convection.adapt.levels`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, ClassVar

import dolfinx
import numpy as np
import numpy.typing as npt
from mpi4py import MPI

from convection.geometry.domain import DomainContext, MeshSection, safe_product
from convection.geometry.mesh import gmsh_mesh, mesh_uniformly
from convection.geometry.radial import (
    RadialDomain, RadialMeshSettings, check_radial_section, shell_confinement, shell_radii,
)
from convection.schema import ConfigError
from fembase.manifold import ShellManifold

__all__ = ["SHELL_BOUNDARIES", "Annulus", "ShellDomain", "ShellSpec", "SphericalShell", "conductive_heat_flow",
           "create_shell_mesh", "shell_confinement", "shell_domain", "shell_radii"]

SHELL_BOUNDARIES: tuple[str, ...] = ("inner", "outer")
_DIMENSIONS = {"annulus": 2, "spherical_shell": 3}

CURVABLE_SHRINK = 0.97
CURVABLE_TRIES = 8
"""A straight base the manifold curves is meshed again at this fraction of the last cell size, up to
this many times, while a tetrahedron has all four vertices on a sphere (:func:`_shell_model`). gmsh's
Delaunay mesher leaves one or two such cells at some sizes (radii 1.22 and 2.22, 13 sizes from 0.2
to 1.0: at 0.2, 0.4 and 0.5; at 0.4 and 0.7 with :data:`UNIFORM_BASE_QUALITY`); its HXT mesher left
none but gave another mesh at every call (1620, 1645, 1620, 1658 cells at 0.5)."""

UNIFORM_BASE_QUALITY = 0.95
"""gmsh's tetrahedron optimiser improves every cell below this quality (its own threshold: 0.3) in
the base of a fixed shell's levels, which is refined uniformly. That refinement cuts a tetrahedron's
inner octahedron along the diagonal between the midpoints of its longest edge and the opposite
edge; in a flat (sliver) cell these two edges cross and their midpoints nearly meet, so the refined
mesh gets an edge far shorter than half the base's, and the CFL step with it. Radii 1.22 and 2.22,
shortest edge of the base refined once: 0.113 at size 0.5 (0.083 at gmsh's threshold, size 0.485);
refined twice: 0.056 (0.042); gmsh's own mesh of as many cells as the first: 0.142. Adaptive
shells keep gmsh's threshold: on configs/shell_adaptive.yaml at CI size (1.8x coarser, 2 ranks)
it gave a first step 0.59x as long (0.00229 against 0.00390) and 0.94x the model time in 10 steps."""

COARSEST_LAYERS = 2
"""The coarsest multigrid level of a fixed shell has cells no larger than the shell's thickness over
this (:meth:`ShellDomain.mesh_levels`): two cells across, so the coarse problem still resolves
the radial flow."""


@dataclass(frozen=True)
class ShellSpec:
    """An annulus (``gdim = 2``) or spherical shell (``gdim = 3``) centred at the origin.

    Attributes:
        gdim: 2 (annulus) or 3 (spherical shell).
        inner_radius: Radius of the inner boundary ``inner``.
        outer_radius: Radius of the outer boundary ``outer``.
        resolution: Target cell size (gmsh's mesh size, uniform).
        geometry_degree: 1 (straight-sided cells) or 2 (curved cells, boundary nodes on the
            circles/spheres).
        interfaces: Radii of interior circles/spheres the mesh conforms to (facets on them).
        curvable: The straight base of meshes the manifold curves (a hierarchy's): in 3D, no
            tetrahedron may have all four vertices on one sphere (:func:`_shell_model`).
        refined_uniformly: The base of a fixed shell's levels (:meth:`ShellDomain.coarsened`),
            refined uniformly: in 3D, gmsh optimises its cells up to :data:`UNIFORM_BASE_QUALITY`.
    """

    gdim: int
    inner_radius: float = 1.22
    outer_radius: float = 2.22
    resolution: float = 0.1
    geometry_degree: int = 2
    interfaces: tuple[float, ...] = ()
    curvable: bool = False
    refined_uniformly: bool = False


    def __post_init__(self) -> None:
        if self.gdim not in (2, 3):
            raise ValueError(f"a shell is 2D (annulus) or 3D (spherical_shell), got gdim={self.gdim}")
        if not 0.0 < self.inner_radius < self.outer_radius:
            raise ValueError(f"need 0 < inner_radius < outer_radius, got {self.inner_radius}, {self.outer_radius}")
        if not self.resolution > 0.0:
            raise ValueError(f"resolution must be positive, got {self.resolution}")
        if self.geometry_degree not in (1, 2):
            raise ValueError(f"geometry_degree must be 1 or 2, got {self.geometry_degree}")
        for r in self.interfaces:
            if not self.inner_radius < r < self.outer_radius:
                raise ValueError(f"interface radius {r} is not between the inner and outer radii")

    @classmethod
    def from_settings(cls, keys: RadialMeshSettings, gdim: int, /) -> ShellSpec:
        """The shell of dimension ``gdim`` of a checked ``mesh`` section's keys."""
        if keys.resolution is None:
            raise ValueError("a shell needs a resolution (mesh.resolution)")
        inner, outer = (float(r) for r in keys.radii)
        return cls(gdim, inner, outer, float(keys.resolution), int(keys.geometry_degree))

    @property
    def name(self) -> str:
        return "annulus" if self.gdim == 2 else "spherical_shell"

    @property
    def volume(self) -> float:
        """Exact area (2D) or volume (3D) of the shell."""
        ri, ro = self.inner_radius, self.outer_radius
        return float(np.pi * (ro**2 - ri**2)) if self.gdim == 2 else float(4.0 / 3.0 * np.pi * (ro**3 - ri**3))


def _shell_model(gmsh, spec: ShellSpec) -> None:
    """Build and mesh the shell in gmsh's current model (rank 0 only)."""
    occ = gmsh.model.occ
    dim = spec.gdim
    radii = sorted({spec.inner_radius, *spec.interfaces, spec.outer_radius})

    def ball(r: float) -> int:
        return occ.addDisk(0.0, 0.0, 0.0, r, r) if dim == 2 else occ.addSphere(0.0, 0.0, 0.0, r)

    pieces = []
    for r_in, r_out in zip(radii[:-1], radii[1:]):
        out, _ = occ.cut([(dim, ball(r_out))], [(dim, ball(r_in))])
        pieces.extend(out)
    if len(pieces) > 1:
        pieces, _ = occ.fragment(pieces[:1], pieces[1:])
    occ.synchronize()
    gmsh.model.addPhysicalGroup(dim, [tag for _, tag in gmsh.model.getEntities(dim)], 1)
    size = spec.resolution
    for _ in range(CURVABLE_TRIES):
        mesh_uniformly(gmsh, dim, size, spec.geometry_degree, untangle=True,
                       optimize_below=UNIFORM_BASE_QUALITY if spec.refined_uniformly and dim == 3 else None)
        if not spec.curvable or dim == 2 or not _caps(gmsh, (spec.inner_radius, spec.outer_radius)):
            return
        gmsh.model.mesh.clear()
        size *= CURVABLE_SHRINK
    raise ValueError(f"gmsh's shell of size {spec.resolution:g} to {size / CURVABLE_SHRINK:.4g} kept a "
                     f"tetrahedron with all four vertices on a sphere, which the manifold cannot curve: try another "
                     f"mesh.resolution")


def _caps(gmsh: Any, radii: tuple[float, ...], /) -> int:
    """Tetrahedra of gmsh's current mesh with all four vertices on one of the spheres ``radii``."""
    _, _, nodes = gmsh.model.mesh.getElements(3)
    tags, x, _ = gmsh.model.mesh.getNodes()
    index = np.zeros(int(tags.max()) + 1, dtype=np.int64)
    index[tags.astype(np.int64)] = np.arange(len(tags))
    r = np.linalg.norm(x.reshape(-1, 3), axis=1)[index[np.concatenate(nodes).astype(np.int64)]].reshape(-1, 4)
    return int(sum(np.all(np.abs(r - radius) <= 1e-9 * radius, axis=1).sum() for radius in radii))


def create_shell_mesh(comm: MPI.Comm, spec: ShellSpec, /, *, owners: npt.NDArray[np.int32] | None = None,
                      msh_file: str | Path | None = None) -> dolfinx.mesh.Mesh:
    """Mesh the annulus/spherical shell of ``spec`` with gmsh on rank 0 and distribute it
    (collective; :func:`convection.geometry.mesh.gmsh_mesh`, whose ``owners`` and ``msh_file`` these are)."""
    return gmsh_mesh(comm, lambda gmsh: _shell_model(gmsh, spec), gdim=spec.gdim, name=f"{spec.name}_{id(spec)}",
                     owners=owners, msh_file=msh_file)


def conductive_heat_flow(inner_radius: float, outer_radius: float, delta_T: float, gdim: int) -> float:
    """Heat flow ``Q`` through an annulus (per unit length, ``gdim = 2``) or spherical shell by pure
    conduction with temperature difference ``delta_T`` (inner minus outer)::

        2D:  Q = 2 pi delta_T / ln(r_o / r_i),      3D:  Q = 4 pi r_i r_o delta_T / (r_o - r_i).
    """
    ri, ro = inner_radius, outer_radius
    if gdim == 2:
        return float(2.0 * np.pi * delta_T / np.log(ro / ri))
    return float(4.0 * np.pi * ri * ro * delta_T / (ro - ri))


class ShellDomain(RadialDomain):
    """An annulus or spherical shell (:class:`ShellSpec`; see the module docstring)."""

    name: ClassVar[str] = "shell"
    description: ClassVar[str] = "annulus or spherical shell r_inner <= |x| <= r_outer around the origin (gmsh)"
    Settings: ClassVar[type] = RadialMeshSettings
    config_boundaries: ClassVar[tuple[str, ...]] = SHELL_BOUNDARIES
    boundary_descriptions: ClassVar[dict[str, str]] = {"inner": "the inner surface r = r_inner",
                                                         "outer": "the outer surface r = r_outer"}
    boundaries: tuple[str, ...] = SHELL_BOUNDARIES

    # ------------------------------------------------------------------ config
    @classmethod
    def build(cls, settings: RadialMeshSettings, context: DomainContext, /) -> ShellDomain:
        return cls(ShellSpec.from_settings(settings, _DIMENSIONS[cls.name]))

    @classmethod
    def config_gdim(cls, mesh: MeshSection, /) -> int:
        return _DIMENSIONS[mesh.geometry]

    @classmethod
    def check_config(cls, mesh: MeshSection, /, *, changed_by: str | None) -> None:
        check_radial_section(mesh)
        if changed_by is not None and mesh.keys.geometry_degree != 2:
            surfaces = "circles" if mesh.geometry == "annulus" else "spheres"
            raise ConfigError(f"config key '{changed_by}': on mesh.geometry {mesh.geometry} needs "
                              f"mesh.geometry_degree 2 (the refined cells are curved onto the {surfaces})")

    @classmethod
    def base_cells_bound(cls, mesh: MeshSection, /) -> float:
        """Shell volume over the volume of an equilateral cell of edge ``resolution``."""
        inner, outer = mesh.keys.radii
        # products, not powers: a float power raises OverflowError where a product gives inf
        volume, cell = ((math.pi * (outer - inner) * (outer + inner), 0.4330127) if cls.config_gdim(mesh) == 2
                        else (4.18879020 * (outer - inner) * (outer * outer + outer * inner + inner * inner),
                              0.11785113))
        return safe_product(volume / cell, *[1.0 / mesh.keys.resolution] * cls.config_gdim(mesh)) + 1.0

    def mesh_levels(self, wanted: int = 0, /) -> int:
        """A gmsh shell nests in no coarser gmsh shell: ``L`` levels are gmsh's shell at
        ``resolution * 2^(L-1)`` refined uniformly ``L - 1`` times (module docstring). The coarsest
        cells must be no larger than the shell's thickness over :data:`COARSEST_LAYERS`. With
        ``wanted`` 0, as many levels as that allows (1: none)."""
        spec = self.spec
        thickness = spec.outer_radius - spec.inner_radius
        most = 1
        while spec.resolution * 2 ** most <= thickness / COARSEST_LAYERS:
            most += 1
        if wanted == 0:
            return most if spec.geometry_degree == 2 else 1
        if wanted > 1 and spec.geometry_degree != 2:
            raise ValueError("levels by refinement need mesh.geometry_degree 2 (the refined cells are curved onto "
                             "the spheres)")
        if wanted > most:
            raise ValueError(f"{wanted} levels need a coarsest mesh of cell size resolution * 2^{wanted - 1} = "
                             f"{spec.resolution * 2 ** (wanted - 1):.4g}, more than the shell's thickness "
                             f"{thickness:.4g} / {COARSEST_LAYERS}: at most {most} with mesh.resolution "
                             f"{spec.resolution:.4g}")
        return wanted

    def coarsened(self, refinements: int, /) -> ShellDomain:
        """The shell of gmsh cells ``2^refinements`` times larger (:meth:`mesh_levels`;
        :class:`convection.geometry.domain.LevelsByRefinement`)."""
        return shell_domain(replace(self.spec, resolution=self.spec.resolution * 2 ** refinements,
                                    refined_uniformly=True))

    def angle_limits(self) -> list[tuple[float, float]]:
        """Longitude (poles included: -pi and pi) and, in 3D, colatitude."""
        return [(-math.pi, math.pi), (0.0, math.pi)][: self.gdim - 1]

    def boundary_axis(self, name: str, /) -> tuple[int, bool]:
        self.check_boundary_names([name])
        return 0, name == "outer"

    # ------------------------------------------------------------------ mesh and boundaries
    def create_mesh(self, comm: MPI.Comm, /, *, owners: npt.NDArray[np.int32] | None = None,
                    straight: bool = False) -> dolfinx.mesh.Mesh:
        spec = replace(self.spec, geometry_degree=1, curvable=True) if straight else self.spec
        return create_shell_mesh(comm, spec, owners=owners)

    def manifold(self) -> ShellManifold:
        """Where refined cells' geometry nodes go: a new (unfitted) :class:`ShellManifold`."""
        return ShellManifold(self.spec.inner_radius, self.spec.outer_radius, self.gdim)

    def _boundary_facets(self, mesh: dolfinx.mesh.Mesh, /) -> list[npt.NDArray[np.int32]]:
        radii = shell_radii(mesh)
        return [self.locate_facets(mesh, name, radii=radii) for name in self.boundaries]

    def has_rotations(self, free_slip: set[str], /) -> bool:
        """Free slip on both surfaces: rigid rotations (one in 2D, three in 3D) are free."""
        return set(self.boundaries) <= free_slip

    def nusselt(self, mesh: dolfinx.mesh.Mesh, name: str, heat_flow: float, delta_T: float, area: float, /) -> float:
        """``Q / Q_conductive(delta_T)`` (:func:`conductive_heat_flow` between the mesh's radii)."""
        inner, outer = shell_radii(mesh)
        return float(heat_flow / conductive_heat_flow(inner, outer, delta_T, mesh.geometry.dim))


class Annulus(ShellDomain):
    """The 2D shell: ``mesh.geometry: annulus``."""

    name: ClassVar[str] = "annulus"
    free_surfaces: ClassVar[tuple[str, ...]] = ("outer",)
    description: ClassVar[str] = "2D annulus r_inner <= |x| <= r_outer around the origin (gmsh, curved cells)"


class SphericalShell(ShellDomain):
    """The 3D shell: ``mesh.geometry: spherical_shell``."""

    name: ClassVar[str] = "spherical_shell"
    description: ClassVar[str] = ("3D spherical shell r_inner <= |x| <= r_outer around the origin (gmsh, curved "
                                  "cells)")


def shell_domain(spec: ShellSpec, /) -> ShellDomain:
    """The :class:`Annulus` or :class:`SphericalShell` of ``spec``."""
    return Annulus(spec) if spec.gdim == 2 else SphericalShell(spec)
