"""Boundary conditions on axis-aligned box domains and helpers to find the box sides.

Side names: in 2D ``x`` is left/right and ``y`` bottom/top; in 3D ``x`` is left/right, ``y``
front/back and ``z`` bottom/top. The sides are found from the global (allreduced) bounding box of
the mesh, so any box ``[x0, x1] x [y0, y1] (x [z0, z1])`` works, in serial and in parallel.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import dolfinx
import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

SIDES_2D: tuple[str, ...] = ("left", "right", "bottom", "top")
SIDES_3D: tuple[str, ...] = ("left", "right", "bottom", "top", "front", "back")

VELOCITY_BC_KINDS: dict[str, str] = {
    "free_slip": "zero normal velocity, zero tangential traction",
    "no_slip": "zero velocity",
    "prescribed": "velocity equal to the constant vector `value`",
}
"""Registry of velocity boundary condition kinds (name -> one-line description)."""

TEMPERATURE_BC_KINDS: dict[str, str] = {
    "dirichlet": "temperature equal to the constant `value`",
    "insulating": "zero heat flux (natural condition)",
}
"""Registry of temperature boundary condition kinds (name -> one-line description)."""


@dataclass(frozen=True)
class VelocityBC:
    """Velocity boundary condition on one side.

    Attributes:
        kind: ``"free_slip"`` | ``"no_slip"`` | ``"prescribed"``.
        value: for ``"prescribed"``, the constant velocity vector (length ``gdim``).
    """

    kind: str
    value: tuple[float, ...] | None = None

    def __post_init__(self) -> None:
        if self.kind not in VELOCITY_BC_KINDS:
            raise ValueError(
                f"Unknown velocity BC kind {self.kind!r}; valid names: {sorted(VELOCITY_BC_KINDS)}"
            )
        if self.kind == "prescribed" and self.value is None:
            raise ValueError("A 'prescribed' velocity BC needs a value")


@dataclass(frozen=True)
class TemperatureBC:
    """Temperature boundary condition on one side.

    Attributes:
        kind: ``"dirichlet"`` | ``"insulating"``.
        value: for ``"dirichlet"``, the constant temperature.
    """

    kind: str
    value: float | None = None

    def __post_init__(self) -> None:
        if self.kind not in TEMPERATURE_BC_KINDS:
            raise ValueError(
                f"Unknown temperature BC kind {self.kind!r}; "
                f"valid names: {sorted(TEMPERATURE_BC_KINDS)}"
            )
        if self.kind == "dirichlet" and self.value is None:
            raise ValueError("A 'dirichlet' temperature BC needs a value")


class BoxBounds(NamedTuple):
    """Global bounding box of a mesh.

    Attributes:
        lower: lower corner, shape=(gdim,), float64.
        upper: upper corner, shape=(gdim,), float64.
    """

    lower: np.ndarray
    upper: np.ndarray


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


def side_marker(mesh: dolfinx.mesh.Mesh, side: str, bounds: BoxBounds | None = None):
    """Marker ``f(x) -> bool array`` for points on ``side`` (x shape=(3, n)). Collective if
    ``bounds`` is not given."""
    gdim = mesh.geometry.dim
    axis, upper = side_axis(side, gdim)
    b = box_bounds(mesh) if bounds is None else bounds
    coordinate = b.upper[axis] if upper else b.lower[axis]
    tol = 1e-10 * float(np.max(b.upper - b.lower))

    def marker(x: np.ndarray) -> np.ndarray:
        return np.abs(x[axis] - coordinate) <= tol

    return marker


def locate_side_facets(
    mesh: dolfinx.mesh.Mesh, side: str, bounds: BoxBounds | None = None
) -> np.ndarray:
    """Local indices (int32) of the boundary facets on ``side``. Collective."""
    fdim = mesh.topology.dim - 1
    mesh.topology.create_connectivity(fdim, mesh.topology.dim)
    facets = dolfinx.mesh.locate_entities_boundary(mesh, fdim, side_marker(mesh, side, bounds))
    return facets.astype(np.int32)


def locate_side_dofs(V: dolfinx.fem.FunctionSpace, side: str, bounds: BoxBounds | None = None):
    """Local dof indices of ``V`` (a space or sub-space) on ``side``. Collective."""
    mesh = V.mesh
    facets = locate_side_facets(mesh, side, bounds)
    return dolfinx.fem.locate_dofs_topological(V, mesh.topology.dim - 1, facets)


def side_facet_tags(mesh: dolfinx.mesh.Mesh) -> dolfinx.mesh.MeshTags:
    """Facet tags marking the box sides: side ``side_names(gdim)[i]`` gets value ``i + 1``.
    Collective."""
    bounds = box_bounds(mesh)
    indices, values = [], []
    for i, side in enumerate(side_names(mesh.geometry.dim)):
        facets = locate_side_facets(mesh, side, bounds)
        indices.append(facets)
        values.append(np.full(facets.shape, i + 1, dtype=np.int32))
    idx = np.concatenate(indices)
    val = np.concatenate(values)
    order = np.argsort(idx, kind="stable")
    idx, val = idx[order], val[order]
    keep = np.ones(idx.shape, dtype=bool)
    keep[1:] = idx[1:] != idx[:-1]
    return dolfinx.mesh.meshtags(mesh, mesh.topology.dim - 1, idx[keep], val[keep])


def side_tag(side: str, gdim: int) -> int:
    """Facet tag value of ``side`` in :func:`side_facet_tags`."""
    names = side_names(gdim)
    if side not in names:
        raise ValueError(f"Unknown side {side!r}; valid names: {list(names)}")
    return names.index(side) + 1


def velocity_dirichlet_bcs(
    V: dolfinx.fem.FunctionSpace, bcs: dict[str, VelocityBC]
) -> list[dolfinx.fem.DirichletBCMetaClass]:
    """DOLFINx Dirichlet conditions on the vector space ``V`` for the given side conditions.

    Free slip fixes the normal component (the sub-space along the side's axis) to zero; no slip
    fixes all components to zero; prescribed fixes all components to ``value``. Sides missing from
    ``bcs`` get no condition (natural, zero traction). Collective.
    """
    mesh = V.mesh
    gdim = mesh.geometry.dim
    bounds = box_bounds(mesh)
    fdim = mesh.topology.dim - 1
    out = []
    for side in side_names(gdim):
        if side not in bcs:
            continue
        bc = bcs[side]
        facets = locate_side_facets(mesh, side, bounds)
        if bc.kind == "free_slip":
            axis, _ = side_axis(side, gdim)
            dofs = dolfinx.fem.locate_dofs_topological(V.sub(axis), fdim, facets)
            out.append(dolfinx.fem.dirichletbc(PETSc.ScalarType(0.0), dofs, V.sub(axis)))
        else:
            value = np.zeros(gdim) if bc.kind == "no_slip" else np.asarray(bc.value, dtype=float)
            if value.shape != (gdim,):
                raise ValueError(f"Prescribed velocity on {side!r} must have {gdim} components")
            dofs = dolfinx.fem.locate_dofs_topological(V, fdim, facets)
            out.append(dolfinx.fem.dirichletbc(value.astype(PETSc.ScalarType), dofs, V))
    _check_sides(bcs, gdim)
    return out


def temperature_dirichlet_bcs(
    V: dolfinx.fem.FunctionSpace, bcs: dict[str, TemperatureBC]
) -> list[dolfinx.fem.DirichletBCMetaClass]:
    """DOLFINx Dirichlet conditions on the scalar space ``V``; insulating sides get none.
    Collective."""
    gdim = V.mesh.geometry.dim
    _check_sides(bcs, gdim)
    bounds = box_bounds(V.mesh)
    out = []
    for side in side_names(gdim):
        bc = bcs.get(side)
        if bc is None or bc.kind == "insulating":
            continue
        dofs = locate_side_dofs(V, side, bounds)
        out.append(dolfinx.fem.dirichletbc(PETSc.ScalarType(bc.value), dofs, V))
    return out


def _check_sides(bcs: dict, gdim: int) -> None:
    names = side_names(gdim)
    unknown = [s for s in bcs if s not in names]
    if unknown:
        raise ValueError(f"Unknown side(s) {unknown}; valid names: {list(names)}")
