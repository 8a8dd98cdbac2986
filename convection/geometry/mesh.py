"""Meshes for convection runs: a registry of domain geometries, and per-cell size measures.

Geometries (``mesh.geometry`` in a config, :data:`MESH_GEOMETRIES`):

- ``box``: an axis-aligned box ``[lower, upper]`` split into ``cells`` per direction
  (:class:`BoxSpec`, DOLFINx's built-in rectangle/box meshes); sides left/right, bottom/top
  (front/back in 3D); gravity along ``-e_z`` (the last axis).
- ``annulus`` (2D) and ``spherical_shell`` (3D): the region ``r_inner <= |x| <= r_outer`` around
  the origin (:class:`ShellSpec`), meshed by gmsh on rank 0 with a target cell size
  ``resolution`` and read with DOLFINx's gmsh interface (:func:`fembase.dolfinx_compat.gmsh_model_to_mesh`), which
  distributes the cells. With ``geometry_degree: 2`` (the default) the cells are second-order
  (curved) triangles/tetrahedra whose boundary nodes lie on the circles/spheres, so the discrete
  boundary is within ``O(h^3)`` of the true one (a straight-sided mesh is only ``O(h^2)`` close,
  which limits the convergence of free-slip solutions). Boundaries ``inner`` and ``outer``;
  gravity along ``-x/|x|``. Optional ``interfaces`` (radii strictly between the two) are meshed
  conformingly, e.g. for forcing concentrated on a surface ``r = r'``.

DOLFINx 0.5's (Plaza) refinement fails on meshes with second-order geometry ("Data size mismatch
between local and global adjacency lists"), and on straight-sided meshes it puts the new boundary
vertices on the chords, inside the circle. Adaptive (and load-balanced) annulus runs therefore
refine the straight-sided gmsh mesh and curve every mesh they use by the annulus manifold
(:mod:`fembase.manifold`, :class:`convection.adapt.adaptivity.MeshHierarchy` with ``manifold=``; the
domain object of :mod:`convection.geometry.domain` provides it). Spherical shells are not refined yet.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Union

import numpy as np
import numpy.typing as npt
from mpi4py import MPI

import dolfinx.cpp.mesh
import dolfinx.fem
import dolfinx.mesh
import ufl

from fembase.distribute import create_reproducible_mesh
from fembase.dolfinx_compat import (cell_dofmap, coordinate_map, entities_to_geometry, function_space, geometry_dofmap,
                                    gmsh_model_to_mesh)

__all__ = ["BoxSpec", "MESH_GEOMETRIES", "MeshSpec", "ShellSpec", "cell_diameter", "cell_values", "cell_volumes",
           "create_box_mesh",
           "create_mesh", "create_shell_mesh", "mesh_spec_from_config", "shell_confinement"]

MESH_GEOMETRIES: dict[str, str] = {
    "box": "axis-aligned box [lower, upper] with `cells` per direction (2D or 3D)",
    "annulus": "2D annulus r_inner <= |x| <= r_outer around the origin (gmsh, curved cells)",
    "spherical_shell": "3D spherical shell r_inner <= |x| <= r_outer around the origin (gmsh, curved cells)",
}
"""Registry of domain geometries (``mesh.geometry`` name -> one-line description)."""


@dataclass(frozen=True)
class BoxSpec:
    """An axis-aligned box split into ``cells`` per direction.

    Attributes:
        cells: Cells per direction, length 2 or 3.
        lower: Lower corner (same length).
        upper: Upper corner (same length).
        cell_type: "simplex" (triangles/tetrahedra) or "box" (quadrilaterals/hexahedra).
        diagonal: Diagonal direction for 2D simplices.
    """

    cells: tuple[int, ...]
    lower: tuple[float, ...]
    upper: tuple[float, ...]
    cell_type: str = "simplex"
    diagonal: str = "right"

    name = "box"
    gravity = "vertical"

    @classmethod
    def from_config(cls, mesh_config: dict) -> "BoxSpec":
        cells = tuple(int(n) for n in mesh_config["cells"])
        gdim = len(cells)
        lower = tuple(mesh_config["lower"] or [0.0] * gdim)
        upper = tuple(mesh_config["upper"] or [1.0] * gdim)
        return cls(cells, lower, upper, mesh_config["cell_type"], mesh_config["diagonal"])

    @property
    def gdim(self) -> int:
        return len(self.cells)

    @property
    def volume(self) -> float:
        return float(np.prod(np.subtract(self.upper, self.lower)))


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
    """

    gdim: int
    inner_radius: float = 1.22
    outer_radius: float = 2.22
    resolution: float = 0.1
    geometry_degree: int = 2
    interfaces: tuple[float, ...] = ()

    gravity = "radial"

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
    def from_config(cls, mesh_config: dict) -> "ShellSpec":
        gdim = 2 if mesh_config["geometry"] == "annulus" else 3
        inner, outer = (float(r) for r in mesh_config["radii"])
        return cls(gdim, inner, outer, float(mesh_config["resolution"]), int(mesh_config["geometry_degree"]))

    @property
    def name(self) -> str:
        return "annulus" if self.gdim == 2 else "spherical_shell"

    @property
    def volume(self) -> float:
        """Exact area (2D) or volume (3D) of the shell."""
        ri, ro = self.inner_radius, self.outer_radius
        return float(np.pi * (ro**2 - ri**2)) if self.gdim == 2 else float(4.0 / 3.0 * np.pi * (ro**3 - ri**3))


MeshSpec = Union[BoxSpec, ShellSpec]


def mesh_spec_from_config(mesh_config: dict) -> MeshSpec:
    """The spec of the ``mesh`` config section (its ``geometry`` names a :data:`MESH_GEOMETRIES` entry)."""
    geometry = mesh_config.get("geometry", "box")
    if geometry not in MESH_GEOMETRIES:
        raise ValueError(f"Unknown mesh geometry {geometry!r}; valid names: {sorted(MESH_GEOMETRIES)}")
    return BoxSpec.from_config(mesh_config) if geometry == "box" else ShellSpec.from_config(mesh_config)


def create_mesh(comm: MPI.Comm, spec: MeshSpec, /, *, owners: npt.NDArray[np.int32] | None = None
                ) -> dolfinx.mesh.Mesh:
    """Create the (coarse, base) mesh described by ``spec`` (collective) on a reproducible
    partition (:func:`fembase.distribute.create_reproducible_mesh`: the same mesh, numbering and
    all, in every run on the same ranks); ``owners``: a partition to impose (owner rank per cell
    by input index, on rank 0), e.g. the one a checkpoint saved."""
    if isinstance(spec, ShellSpec):
        return create_shell_mesh(comm, spec, owners=owners)
    return create_box_mesh(comm, spec, owners=owners)


def create_box_mesh(comm: MPI.Comm, spec: BoxSpec, /, *, owners: npt.NDArray[np.int32] | None = None
                    ) -> dolfinx.mesh.Mesh:
    """Create the (coarse, base) mesh described by ``spec`` (collective; partition as in :func:`create_mesh`)."""
    return create_reproducible_mesh(comm, lambda c: _box(c, spec), owners=owners)


def _box(comm: MPI.Comm, spec: BoxSpec) -> dolfinx.mesh.Mesh:
    """DOLFINx's rectangle or box mesh of ``spec`` on ``comm``."""
    ghost_mode = dolfinx.mesh.GhostMode.shared_facet
    if spec.gdim == 2:
        cell_type = dolfinx.mesh.CellType.triangle if spec.cell_type == "simplex" else dolfinx.mesh.CellType.quadrilateral
        diagonal = getattr(dolfinx.mesh.DiagonalType, spec.diagonal.replace("/", "_"))
        return dolfinx.mesh.create_rectangle(
            comm, [np.array(spec.lower), np.array(spec.upper)], list(spec.cells), cell_type,
            ghost_mode=ghost_mode, diagonal=diagonal,
        )
    cell_type = dolfinx.mesh.CellType.tetrahedron if spec.cell_type == "simplex" else dolfinx.mesh.CellType.hexahedron
    return dolfinx.mesh.create_box(
        comm, [np.array(spec.lower), np.array(spec.upper)], list(spec.cells), cell_type, ghost_mode=ghost_mode
    )


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
    gmsh.option.setNumber("Mesh.CharacteristicLengthMin", spec.resolution)
    gmsh.option.setNumber("Mesh.CharacteristicLengthMax", spec.resolution)
    gmsh.option.setNumber("Mesh.CharacteristicLengthFromCurvature", 0)
    gmsh.option.setNumber("Mesh.CharacteristicLengthExtendFromBoundary", 0)
    gmsh.model.mesh.generate(dim)
    if spec.geometry_degree > 1:
        gmsh.model.mesh.setOrder(spec.geometry_degree)
        # Curving the boundary faces of coarse tetrahedra can invert them (negative Jacobian where a
        # concave face bends into a thin cell); gmsh's high-order optimiser untangles such cells
        # (only cells below its quality threshold move; boundary nodes stay on the surfaces).
        gmsh.model.mesh.optimize("HighOrder")


def create_shell_mesh(comm: MPI.Comm, spec: ShellSpec, /, *, owners: npt.NDArray[np.int32] | None = None,
                      msh_file: str | Path | None = None) -> dolfinx.mesh.Mesh:
    """Mesh the annulus/spherical shell of ``spec`` with gmsh on rank 0 and distribute it (collective;
    partition as in :func:`create_mesh`).

    Needs the ``gmsh`` Python module (Debian: ``python3-gmsh``) on rank 0.

    Args:
        msh_file: A gmsh ``.msh`` file of this shell: read if it exists (instead of meshing),
            written after meshing if not. Different gmsh versions mesh the same shell differently
            (Debian 12's 4.8 and Debian 13's 4.13 give 673 and 675 cells for the annulus at cell size
            0.2), so comparing two installations on the same mesh needs the file of one of them
            (benchmarks/releases). None: mesh, write nothing.
    """
    started = False
    if comm.rank == 0:
        import gmsh

        # gmsh < 4.9 (Debian 12 ships 4.8) cannot tell whether it is initialised: start our own session.
        is_initialized = getattr(gmsh, "isInitialized", lambda: False)
        started = not is_initialized()
        if started:
            gmsh.initialize(readConfigFiles=False)
        gmsh.option.setNumber("General.Terminal", 0)
        if msh_file is not None and Path(msh_file).exists():
            gmsh.open(str(msh_file))
        else:
            gmsh.model.add(f"{spec.name}_{id(spec)}")
            _shell_model(gmsh, spec)
            if msh_file is not None:
                gmsh.write(str(msh_file))
    try:
        return create_reproducible_mesh(comm, lambda c: gmsh_model_to_mesh(gmsh.model, c, 0, gdim=spec.gdim),
                                        owners=owners)
    finally:
        if comm.rank == 0:
            gmsh.model.remove()
            if started:
                gmsh.finalize()


def cell_values(mesh: dolfinx.mesh.Mesh, integrand: ufl.core.expr.Expr, /) -> npt.NDArray[np.float64]:
    """Integral of ``integrand`` over every local cell (owned and ghost), shape=(num_local_cells,)."""
    V0 = function_space(mesh, "DG", 0)
    w = ufl.TestFunction(V0)
    vec = dolfinx.fem.assemble_vector(dolfinx.fem.form(integrand * w * ufl.dx))
    vec.scatter_forward()
    return vec.array[cell_dofmap(V0).reshape(-1)].copy()


def cell_volumes(mesh: dolfinx.mesh.Mesh, /) -> npt.NDArray[np.float64]:
    """Volume (area in 2D) of every local cell (owned and ghost), shape=(num_local_cells,)."""
    return cell_values(mesh, ufl.as_ufl(1.0))


def cell_diameter(mesh: dolfinx.mesh.Mesh, /) -> ufl.core.expr.Expr:
    """Cell diameter for forms: ``ufl.CellDiameter`` on straight-sided cells; on curved cells (which
    FFCx 0.5 cannot generate ``CellDiameter`` for) a DG0 Function of the largest vertex distance.
    Not collective (ghost cells are computed directly)."""
    if coordinate_map(mesh).degree == 1:
        return ufl.CellDiameter(mesh)
    V0 = function_space(mesh, "DG", 0)
    tdim = mesh.topology.dim
    num_cells = mesh.topology.index_map(tdim).size_local + mesh.topology.index_map(tdim).num_ghosts
    num_vertices = dolfinx.cpp.mesh.cell_num_vertices(mesh.topology.cell_type)
    nodes = geometry_dofmap(mesh)[:num_cells, :num_vertices]
    x = mesh.geometry.x[nodes]
    h = np.zeros(num_cells)
    for i in range(num_vertices):
        for j in range(i + 1, num_vertices):
            h = np.maximum(h, np.linalg.norm(x[:, i] - x[:, j], axis=1))
    f = dolfinx.fem.Function(V0, name="cell_diameter")
    f.x.array[cell_dofmap(V0).reshape(-1)[:num_cells]] = h
    return f


def shell_confinement(mesh: dolfinx.mesh.Mesh, spec: ShellSpec, /) -> Callable[[npt.NDArray[np.float64]], None]:
    """``confine(x)``: move points (shape=(n, gdim), in place) that lie outside the shell, or within
    ``margin`` of its surfaces, radially to ``r_inner + margin`` / ``r_outer - margin``.

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

    def confine(x: npt.NDArray[np.float64]) -> None:
        if x.shape[0] == 0:
            return
        r = np.sqrt(np.sum(x * x, axis=1))
        outside = (r < lower) | (r > upper)
        if np.any(outside):
            target = np.clip(r[outside], lower, upper)
            x[outside] *= (target / np.where(r[outside] > 0.0, r[outside], 1.0))[:, None]

    return confine


def _outer_facet_distance(mesh: dolfinx.mesh.Mesh, spec: ShellSpec, /) -> float:
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
