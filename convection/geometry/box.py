"""An axis-aligned box: ``mesh.geometry: box``.

``[lower, upper]`` split into ``cells`` per direction (DOLFINx's rectangle and box meshes, triangles
or quadrilaterals, tetrahedra or hexahedra). Sides: in 2D ``x`` is left/right and ``y``
bottom/top; in 3D ``x`` is left/right, ``y`` front/back and ``z`` bottom/top. Gravity along
``-e_z`` (the last axis). The sides are found from the global (allreduced) bounding box of the
mesh, so any box works, in serial and in parallel. Free slip on a side is a zero Dirichlet
condition on the velocity component normal to it; the pressure is pinned at the lower corner.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar, NamedTuple

import dolfinx
import numpy as np
import numpy.typing as npt
from mpi4py import MPI
from petsc4py import PETSc

from convection.geometry.boundary import DEFAULT_TEMPERATURE, DEFAULT_VELOCITY
from convection.geometry.domain import Columns, Domain, DomainContext, MeshSection, kept_facets, safe_product
from convection.geometry.gravity import VerticalGravity
from convection.geometry.probes import MAX_PROBES, NODES_PER_CELL, bounded
from convection.schema import ConfigError, param
from fembase.distribute import create_nested_meshes, create_reproducible_mesh
from fembase.dolfinx_compat import DirichletBC

__all__ = ["SIDES_2D", "SIDES_3D", "BoxBounds", "BoxDomain", "BoxSpec", "box_bounds", "create_box_mesh",
           "side_names"]

SIDES_2D: tuple[str, ...] = ("left", "right", "bottom", "top")
SIDES_3D: tuple[str, ...] = ("left", "right", "bottom", "top", "front", "back")
SIMPLICES_PER_BOX = {2: 2, 3: 6}


def side_names(gdim: int) -> tuple[str, ...]:
    """Valid side names for a ``gdim``-dimensional box."""
    if gdim == 2:
        return SIDES_2D
    if gdim == 3:
        return SIDES_3D
    raise ValueError(f"Only 2D and 3D boxes are supported, got gdim={gdim}")


def side_axis(side: str, gdim: int) -> tuple[int, bool]:
    """Coordinate axis normal to ``side`` and whether the side is at the upper end of that axis."""
    names = side_names(gdim)
    if side not in names:
        raise ValueError(f"Unknown side {side!r}; valid names: {list(names)}")
    axis = {"left": 0, "right": 0, "front": 1, "back": 1, "bottom": gdim - 1, "top": gdim - 1}
    return axis[side], side in ("right", "back", "top")


class BoxBounds(NamedTuple):
    """Global bounding box of a mesh.

    Attributes:
        lower: lower corner, shape=(gdim,), float64.
        upper: upper corner, shape=(gdim,), float64.
    """

    lower: np.ndarray
    upper: np.ndarray


def box_bounds(mesh: dolfinx.mesh.Mesh) -> BoxBounds:
    """Global bounding box of the mesh geometry. Collective."""
    gdim = mesh.geometry.dim
    x = mesh.geometry.x[:, :gdim]
    lo = x.min(axis=0) if x.shape[0] else np.full(gdim, np.inf)
    hi = x.max(axis=0) if x.shape[0] else np.full(gdim, -np.inf)
    comm = mesh.comm
    lower = np.empty(gdim)
    upper = np.empty(gdim)
    comm.Allreduce(np.ascontiguousarray(lo, dtype=np.float64), lower, op=MPI.MIN)
    comm.Allreduce(np.ascontiguousarray(hi, dtype=np.float64), upper, op=MPI.MAX)
    return BoxBounds(lower, upper)


def _side_marker(mesh: dolfinx.mesh.Mesh, side: str, bounds: BoxBounds) -> Callable:
    """Marker ``f(x) -> bool array`` for points on ``side`` (x shape=(3, n))."""
    axis, upper = side_axis(side, mesh.geometry.dim)
    coordinate = bounds.upper[axis] if upper else bounds.lower[axis]
    tol = 1e-10 * float(np.max(bounds.upper - bounds.lower))

    def marker(x: np.ndarray) -> np.ndarray:
        return np.abs(x[axis] - coordinate) <= tol

    return marker


@dataclass(frozen=True)
class BoxSpec:
    """An axis-aligned box split into ``cells`` per direction.

    Attributes:
        cells: Cells per direction, length 2 or 3.
        lower: Lower corner (same length).
        upper: Upper corner (same length).
        cell_type: "simplex" (triangles/tetrahedra) or "box" (quadrilaterals/hexahedra).
        diagonal: Diagonal direction for 2D simplices.
        grading: Per direction, how much the cells bunch towards both ends of that axis
            (:func:`graded`); None or zeros: uniform cells.
    """

    cells: tuple[int, ...]
    lower: tuple[float, ...]
    upper: tuple[float, ...]
    cell_type: str = "simplex"
    diagonal: str = "right"
    grading: tuple[float, ...] | None = None

    @classmethod
    def from_settings(cls, keys: BoxMeshSettings, /) -> BoxSpec:
        """The box of a checked ``mesh`` section's keys."""
        cells = tuple(int(n) for n in keys.cells or ())
        gdim = len(cells)
        lower = tuple(keys.lower or [0.0] * gdim)
        upper = tuple(keys.upper or [1.0] * gdim)
        grading = keys.grading
        return cls(cells, lower, upper, keys.cell_type, keys.diagonal,
                   tuple(float(g) for g in grading) if grading is not None and any(grading) else None)

    @property
    def gdim(self) -> int:
        return len(self.cells)

    @property
    def volume(self) -> float:
        return float(np.prod(np.subtract(self.upper, self.lower)))


@dataclass(frozen=True)
class BoxMeshSettings:
    """The ``mesh`` keys of a box."""

    cells: tuple[int, ...] | None = param(None, length=(2, 3), minimum=1, help="cells per direction, e.g. [32, 32]")
    lower: tuple[float, ...] | None = param(None, length=(2, 3), help="lower box corner (default 0)")
    upper: tuple[float, ...] | None = param(None, length=(2, 3), help="upper box corner (default 1)")
    cell_type: str = param("simplex", choices=("simplex", "box"), help="triangles/tets or quads/hexes")
    diagonal: str = param("right", choices=("right", "left", "crossed", "left/right", "right/left"),
                          help="how a 2D simplex box mesh splits its squares into triangles (DOLFINx's diagonal)")
    grading: tuple[float, ...] | None = param(
        None, length=(2, 3), minimum=0.0, maximum=0.9,
        help="per direction g: cells bunched towards both ends of that axis, the end cells (1 - g) and the middle "
             "ones (1 + g) times the uniform size (x -> x - g L sin(2 pi x / L) / (2 pi)); e.g. [0, 0.5] for thermal "
             "boundary layers at top and bottom; null: uniform")


def graded(s: npt.NDArray[np.float64], g: float) -> npt.NDArray[np.float64]:
    """The graded coordinate of ``s`` in [0, 1]: ``s - g sin(2 pi s) / (2 pi)``, monotone for g < 1,
    fixing 0, 1/2 and 1, with the slope ``1 - g`` at both ends and ``1 + g`` in the middle (so a
    uniform cell there becomes ``1 - g`` resp. ``1 + g`` times as long)."""
    return s - g * np.sin(2.0 * np.pi * s) / (2.0 * np.pi)


def _box(comm: MPI.Comm, spec: BoxSpec) -> dolfinx.mesh.Mesh:
    """DOLFINx's rectangle or box mesh of ``spec`` on ``comm``, its nodes moved by ``spec.grading``."""
    ghost_mode = dolfinx.mesh.GhostMode.shared_facet
    if spec.gdim == 2:
        cell_type = (dolfinx.mesh.CellType.triangle if spec.cell_type == "simplex"
                     else dolfinx.mesh.CellType.quadrilateral)
        diagonal = getattr(dolfinx.mesh.DiagonalType, spec.diagonal.replace("/", "_"))
        mesh = dolfinx.mesh.create_rectangle(
            comm, [np.array(spec.lower), np.array(spec.upper)], list(spec.cells), cell_type,
            ghost_mode=ghost_mode, diagonal=diagonal,
        )
    else:
        cell_type = (dolfinx.mesh.CellType.tetrahedron if spec.cell_type == "simplex"
                     else dolfinx.mesh.CellType.hexahedron)
        mesh = dolfinx.mesh.create_box(
            comm, [np.array(spec.lower), np.array(spec.upper)], list(spec.cells), cell_type, ghost_mode=ghost_mode
        )
    x = mesh.geometry.x
    for axis, g in enumerate(spec.grading or ()):
        if g:
            lo, length = spec.lower[axis], spec.upper[axis] - spec.lower[axis]
            x[:, axis] = lo + length * graded((x[:, axis] - lo) / length, g)
    return mesh


def create_box_mesh(comm: MPI.Comm, spec: BoxSpec, /, *, owners: npt.NDArray[np.int32] | None = None
                    ) -> dolfinx.mesh.Mesh:
    """The mesh of ``spec`` (collective) on a reproducible partition
    (:func:`fembase.distribute.create_reproducible_mesh`: the same mesh, numbering and all, in every
    run on the same ranks); ``owners``: a partition to impose (owner rank per cell by input index,
    on rank 0), e.g. the one a checkpoint saved."""
    return create_reproducible_mesh(comm, lambda c: _box(c, spec), owners=owners)


class BoxDomain(Domain):
    """An axis-aligned box ``[lower, upper]`` (see the module docstring).

    Args:
        lower, upper: The corners, length ``gdim``.
        spec: How the box is meshed (:class:`BoxSpec`); None for a box around a given mesh
            (:meth:`around`), which cannot make meshes.
    """

    name: ClassVar[str] = "box"
    description: ClassVar[str] = "axis-aligned box [lower, upper] with `cells` per direction (2D or 3D)"
    Settings: ClassVar[type] = BoxMeshSettings
    config_boundaries: ClassVar[tuple[str, ...]] = SIDES_3D
    size_key: ClassVar[str] = "cells"
    boundary_descriptions: ClassVar[dict[str, str]] = {
        "left": "x = lower", "right": "x = upper", "bottom": "lowest y (2D) or z (3D)",
        "top": "highest y (2D) or z (3D)", "front": "y = lower (3D)", "back": "y = upper (3D)"}
    top: ClassVar[str] = "top"
    free_surfaces: ClassVar[tuple[str, ...]] = ("top",)
    bottom: ClassVar[str] = "bottom"
    axis_aligned: ClassVar[bool] = True

    def __init__(self, lower: Sequence[float] | npt.NDArray[np.float64],
                 upper: Sequence[float] | npt.NDArray[np.float64], /, *, spec: BoxSpec | None = None) -> None:
        self.lower = tuple(float(v) for v in lower)
        self.upper = tuple(float(v) for v in upper)
        self.gdim = len(self.lower)
        self.boundaries = side_names(self.gdim)
        self.spec = spec

    @classmethod
    def from_spec(cls, spec: BoxSpec, /) -> BoxDomain:
        return cls(spec.lower, spec.upper, spec=spec)

    @classmethod
    def around(cls, mesh: dolfinx.mesh.Mesh, /) -> BoxDomain:
        """The box a mesh fills (its global bounding box; collective). For solvers built on a box
        mesh without a domain."""
        bounds = box_bounds(mesh)
        return cls(bounds.lower, bounds.upper)

    def __repr__(self) -> str:
        return f"BoxDomain(lower={self.lower}, upper={self.upper})"

    # ------------------------------------------------------------------ config
    @classmethod
    def build(cls, settings: BoxMeshSettings, context: DomainContext, /) -> BoxDomain:
        return cls.from_spec(BoxSpec.from_settings(settings))

    @classmethod
    def config_gdim(cls, mesh: MeshSection, /) -> int:
        return len(mesh.keys.cells)

    @classmethod
    def check_config(cls, mesh: MeshSection, /, *, changed_by: str | None) -> None:
        keys = mesh.keys
        if keys.cells is None:
            raise ConfigError("config key 'mesh.cells': required value missing (cells per direction, e.g. [32, 32])")
        gdim = len(keys.cells)
        for key in ("lower", "upper", "grading"):
            corner = getattr(keys, key)
            if corner is not None and len(corner) != gdim:
                raise ConfigError(f"config key 'mesh.{key}': needs {gdim} entries like mesh.cells")
        lower = list(keys.lower or [0.0] * gdim)
        upper = list(keys.upper or [1.0] * gdim)
        if any(u <= lo for lo, u in zip(lower, upper)):
            raise ConfigError(f"config key 'mesh.upper': must exceed mesh.lower in every direction, got {upper} vs "
                              f"{lower}")
        if not all(math.isfinite(u - lo) for lo, u in zip(lower, upper)):
            raise ConfigError(f"config key 'mesh.upper': the box size upper - lower must be a finite number, got "
                              f"{upper} vs {lower}")
        if changed_by is not None and keys.cell_type != "simplex":
            raise ConfigError(f"config key '{changed_by}': needs mesh.cell_type: simplex (triangles/tetrahedra)")

    @classmethod
    def check_boundaries(cls, mesh: MeshSection, boundary: Any, /) -> None:
        """A 2D box has no front and back: conditions there must be the defaults."""
        if len(mesh.keys.cells) != 2:
            return
        for section, conditions, defaults in (("velocity", boundary.velocity, (None, DEFAULT_VELOCITY)),
                                              ("temperature", boundary.temperature, (DEFAULT_TEMPERATURE,))):
            for side in ("front", "back"):
                if conditions[side] not in defaults:
                    raise ConfigError(f"config key 'boundary.{section}.{side}': only exists in 3D")

    @classmethod
    def base_cells_bound(cls, mesh: MeshSection, /) -> float:
        cells = mesh.keys.cells
        return safe_product(*cells, SIMPLICES_PER_BOX[len(cells)] if mesh.keys.cell_type == "simplex" else 1)

    def probe_axes(self, level: int, /) -> tuple[list[npt.NDArray[np.float64]], Callable]:
        """A lattice of ``6 cells 2**level`` intervals per direction, boundary and corners included
        (see :mod:`convection.geometry.probes`)."""
        counts = bounded([min(NODES_PER_CELL * n * 2**level, MAX_PROBES) for n in self._spec().cells])
        axes = [np.linspace(lo, hi, n + 1) for lo, hi, n in zip(self.lower, self.upper, counts)]

        def cartesian(grid: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
            points = np.zeros((3, grid.shape[1]))
            points[: grid.shape[0]] = grid
            return points
        return axes, cartesian

    def contains(self, points: npt.ArrayLike, /) -> npt.NDArray[np.bool_]:
        lower, upper = np.asarray(self.lower, dtype=float), np.asarray(self.upper, dtype=float)
        slack = 1e-12 * np.max(upper - lower)
        x = np.asarray(points, dtype=float).reshape(-1, self.gdim)
        return np.all((x >= lower - slack) & (x <= upper + slack), axis=1)

    def columns(self, across: int, along: int, /) -> Columns:
        """Vertical lines at the midpoints of ``across`` equal intervals of each horizontal axis
        (``across`` lines in 2D, ``across^2`` in 3D), ``along`` midpoint samples from bottom to top."""
        gdim = self.gdim
        axes = [self.lower[i] + (np.arange(across) + 0.5) * (self.upper[i] - self.lower[i]) / across
                for i in range(gdim - 1)]
        positions = np.stack([a.ravel() for a in np.meshgrid(*axes, indexing="ij")], axis=1)
        height = self.upper[-1] - self.lower[-1]
        z = self.lower[-1] + (np.arange(along) + 0.5) * height / along
        points = np.zeros((len(positions), along, 3))
        points[:, :, : gdim - 1] = positions[:, None, :]
        points[:, :, gdim - 1] = z[None, :]
        return Columns(positions, points, height, self.upper[-1])

    def boundary_axis(self, name: str, /) -> tuple[int, bool]:
        return side_axis(name, self.gdim)

    # ------------------------------------------------------------------ shape and mesh
    @property
    def gravity(self) -> VerticalGravity:
        return VerticalGravity(top=self.upper[-1])

    def _spec(self) -> BoxSpec:
        if self.spec is None:
            raise ValueError("this box was made around a mesh (BoxDomain.around) and has no mesh spec")
        return self.spec

    def create_mesh(self, comm: MPI.Comm, /, *, owners: npt.NDArray[np.int32] | None = None,
                    straight: bool = False) -> dolfinx.mesh.Mesh:
        return create_box_mesh(comm, self._spec(), owners=owners)

    def mesh_levels(self, wanted: int = 0, /) -> int:
        """Boxes of ``cells / 2^k`` cells per side nest in the box of ``cells`` (a cell of the finer
        box lies in one cell of the coarser: DOLFINx splits every cube into the same six
        tetrahedra around its main diagonal and every square along the same diagonal, patterns that
        halving the cell size refines). With ``wanted`` 0, halve while every count is even and
        stays at least 2. 2D simplices split ``left/right`` or ``right/left`` alternate, and do not nest."""
        spec = self._spec()
        if spec.grading is not None and spec.cell_type == "simplex":
            if wanted > 1:
                raise ValueError("a graded simplex box (mesh.grading) is nested in no coarser box: the diagonals of "
                                 "its graded squares do not line up (use mesh.cell_type: box, or no grading)")
            return 1
        if spec.gdim == 2 and spec.cell_type == "simplex" and "/" in spec.diagonal:
            if wanted > 1:
                raise ValueError(f"mesh.diagonal {spec.diagonal} alternates from square to square: the boxes of "
                                 "half as many cells are not nested in it (use right, left or crossed)")
            return 1
        if wanted == 0:
            halvings = 0
            while all(n % 2 ** (halvings + 1) == 0 and n // 2 ** (halvings + 1) >= 2 for n in spec.cells):
                halvings += 1
            return halvings + 1
        if any(n % 2 ** (wanted - 1) for n in spec.cells):
            raise ValueError(f"{wanted} mesh levels need mesh.cells divisible by 2^{wanted - 1} = {2 ** (wanted - 1)} "
                             f"(got {list(spec.cells)}): each coarser box has half the cells per side")
        return wanted

    def create_mesh_levels(self, comm: MPI.Comm, levels: int, /, *, owners: npt.NDArray[np.int32] | None = None
                           ) -> list[dolfinx.mesh.Mesh]:
        spec = self._spec()
        self.mesh_levels(levels)
        specs = [dataclasses.replace(spec, cells=tuple(n // 2 ** k for n in spec.cells))
                 for k in range(levels - 1, -1, -1)]
        return create_nested_meshes(comm, [functools.partial(_box, spec=s) for s in specs], owners=owners)

    def estimated_cells(self) -> float:
        """Cells of the base mesh."""
        spec = self._spec()
        return float(math.prod(spec.cells)) * (math.factorial(self.gdim) if spec.cell_type == "simplex" else 1)

    # ------------------------------------------------------------------ boundaries
    def locate_facets(self, mesh: dolfinx.mesh.Mesh, name: str, /, *,
                      bounds: BoxBounds | None = None) -> npt.NDArray[np.int32]:
        if (kept := kept_facets(mesh, name)) is not None:
            return kept
        fdim = mesh.topology.dim - 1
        mesh.topology.create_connectivity(fdim, mesh.topology.dim)
        marker = _side_marker(mesh, name, box_bounds(mesh) if bounds is None else bounds)
        return dolfinx.mesh.locate_entities_boundary(mesh, fdim, marker).astype(np.int32)

    def _boundary_facets(self, mesh: dolfinx.mesh.Mesh, /) -> list[npt.NDArray[np.int32]]:
        bounds = box_bounds(mesh)
        return [self.locate_facets(mesh, side, bounds=bounds) for side in self.boundaries]

    def normal_axis(self, name: str, /) -> int:
        return side_axis(name, self.gdim)[0]

    def pressure_pin(self, Q: dolfinx.fem.FunctionSpace, /) -> DirichletBC:
        """Zero Dirichlet condition on the pressure dof(s) at the lower corner. Collective."""
        bounds = box_bounds(Q.mesh)
        lower = bounds.lower
        tol = 1e-10 * float(np.max(bounds.upper - lower))
        gdim = Q.mesh.geometry.dim

        def corner(x: np.ndarray) -> np.ndarray:
            return np.all(np.abs(x[:gdim] - lower[:, None]) <= tol, axis=0)

        dofs = dolfinx.fem.locate_dofs_geometrical(Q, corner)
        return dolfinx.fem.dirichletbc(PETSc.ScalarType(0.0), dofs, Q)

    def opposite(self, name: str, /) -> tuple[str, str]:
        axis = side_axis(name, self.gdim)[0]
        lower, upper = [s for s in self.boundaries if side_axis(s, self.gdim)[0] == axis]
        return (upper, lower) if side_axis(lower, self.gdim)[1] else (lower, upper)

    def nusselt(self, mesh: dolfinx.mesh.Mesh, name: str, heat_flow: float, delta_T: float, area: float, /) -> float:
        """``(Q / A) / (delta_T / L)``, ``L`` the box extent along the axis normal to ``name``."""
        axis = side_axis(name, self.gdim)[0]
        x = mesh.geometry.x[:, axis]
        lo = mesh.comm.allreduce(float(x.min()) if x.size else np.inf, op=MPI.MIN)
        hi = mesh.comm.allreduce(float(x.max()) if x.size else -np.inf, op=MPI.MAX)
        return float((heat_flow / area) * (hi - lo) / delta_T)
