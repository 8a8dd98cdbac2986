"""Boundary conditions by boundary name, on boxes and on shells, and helpers to find the boundaries.

Box side names: in 2D ``x`` is left/right and ``y`` bottom/top; in 3D ``x`` is left/right, ``y``
front/back and ``z`` bottom/top. The sides are found from the global (allreduced) bounding box of
the mesh, so any box ``[x0, x1] x [y0, y1] (x [z0, z1])`` works, in serial and in parallel.

Shell boundary names (annulus, spherical shell around the origin): ``inner`` and ``outer``, the
boundary facets whose vertices lie on the smallest / largest radius of the mesh (found from the
allreduced radii, so any partition and any refinement works). Which kind of domain a set of
conditions belongs to follows from its names (:func:`boundary_names`).

On a box, free slip is a zero Dirichlet condition on the velocity component normal to the side.
On a curved boundary the normal varies, so free slip (``u . n = 0``, zero tangential traction) is
imposed weakly by Nitsche's method (:func:`nitsche_free_slip`); no-slip and prescribed velocities
are strong (nodal) conditions there too.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any, NamedTuple

import dolfinx
import numpy as np
import ufl
from mpi4py import MPI
from petsc4py import PETSc

from convection.geometry.mesh import cell_diameter
from fembase.dolfinx_compat import DirichletBC

SIDES_2D: tuple[str, ...] = ("left", "right", "bottom", "top")
SIDES_3D: tuple[str, ...] = ("left", "right", "bottom", "top", "front", "back")
SHELL_BOUNDARIES: tuple[str, ...] = ("inner", "outer")

VELOCITY_BC_KINDS: dict[str, str] = {
    "free_slip": "zero normal velocity, zero tangential traction",
    "no_slip": "zero velocity",
    "prescribed": "velocity equal to `value`: a constant vector, or expressions in x, y, z, r, ... per component",
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
        value: for ``"prescribed"``, the velocity (length ``gdim``): numbers (a constant vector)
            or expression texts (:mod:`convection.expressions`, e.g. ``("-y", "x")``, a rigid
            rotation) per component; or a callable ``f(x)`` from points shape=(3, n) to
            shape=(gdim, n) (e.g. :class:`convection.geometry.plates.PlateVelocity`).
    """

    kind: str
    value: tuple[float | str, ...] | Callable[[np.ndarray], np.ndarray] | None = None

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


def boundary_names(gdim: int, bcs: Iterable[str] = ()) -> tuple[str, ...]:
    """The boundary names of the domain that conditions named ``bcs`` belong to: the shell's
    ``("inner", "outer")`` if one of them is a shell boundary, else the box sides of ``gdim``.

    Raises:
        ValueError: box side and shell boundary names mixed, or unknown names.
    """
    names = list(bcs)
    if any(n in SHELL_BOUNDARIES for n in names):
        unknown = [n for n in names if n not in SHELL_BOUNDARIES]
        if unknown:
            raise ValueError(f"Unknown shell boundary name(s) {unknown}; valid names: {list(SHELL_BOUNDARIES)}")
        return SHELL_BOUNDARIES
    return side_names(gdim)


def is_shell(bcs: Iterable[str]) -> bool:
    """Whether conditions named ``bcs`` are on a shell (they name ``inner`` or ``outer``)."""
    return any(n in SHELL_BOUNDARIES for n in bcs)


def shell_radii(mesh: dolfinx.mesh.Mesh) -> tuple[float, float]:
    """Smallest and largest distance of a geometry node from the origin, over all ranks. Collective."""
    gdim = mesh.geometry.dim
    r = np.linalg.norm(mesh.geometry.x[:, :gdim], axis=1)
    lo = mesh.comm.allreduce(float(r.min()) if r.size else np.inf, op=MPI.MIN)
    hi = mesh.comm.allreduce(float(r.max()) if r.size else -np.inf, op=MPI.MAX)
    return lo, hi


def shell_marker(mesh: dolfinx.mesh.Mesh, name: str, radii: tuple[float, float] | None = None):
    """Marker ``f(x) -> bool array`` for points on shell boundary ``name`` (x shape=(3, n)).
    Collective if ``radii`` is not given."""
    if name not in SHELL_BOUNDARIES:
        raise ValueError(f"Unknown shell boundary {name!r}; valid names: {list(SHELL_BOUNDARIES)}")
    inner, outer = shell_radii(mesh) if radii is None else radii
    radius = inner if name == "inner" else outer
    tol = 1e-8 * outer
    gdim = mesh.geometry.dim

    def marker(x: np.ndarray) -> np.ndarray:
        return np.abs(np.sqrt(np.sum(x[:gdim] ** 2, axis=0)) - radius) <= tol

    return marker


def locate_boundary_facets(mesh: dolfinx.mesh.Mesh, name: str) -> np.ndarray:
    """Local indices (int32) of the boundary facets on box side or shell boundary ``name``. Collective."""
    if name not in SHELL_BOUNDARIES:
        return locate_side_facets(mesh, name)
    fdim = mesh.topology.dim - 1
    mesh.topology.create_connectivity(fdim, mesh.topology.dim)
    return dolfinx.mesh.locate_entities_boundary(mesh, fdim, shell_marker(mesh, name)).astype(np.int32)


def shell_facet_tags(mesh: dolfinx.mesh.Mesh) -> dolfinx.mesh.MeshTags:
    """Facet tags of the shell boundaries: ``SHELL_BOUNDARIES[i]`` gets value ``i + 1`` (inner 1,
    outer 2). Collective."""
    radii = shell_radii(mesh)
    fdim = mesh.topology.dim - 1
    mesh.topology.create_connectivity(fdim, mesh.topology.dim)
    indices, values = [], []
    for i, name in enumerate(SHELL_BOUNDARIES):
        facets = dolfinx.mesh.locate_entities_boundary(mesh, fdim, shell_marker(mesh, name, radii))
        indices.append(facets.astype(np.int32))
        values.append(np.full(facets.shape, i + 1, dtype=np.int32))
    idx, val = np.concatenate(indices), np.concatenate(values)
    order = np.argsort(idx, kind="stable")
    return dolfinx.mesh.meshtags(mesh, fdim, idx[order], val[order])


def boundary_measure(mesh: dolfinx.mesh.Mesh, name: str, /, *, tags: dolfinx.mesh.MeshTags | None = None,
                     metadata: dict | None = None) -> ufl.Measure:
    """``ds`` restricted to box side or shell boundary ``name``. Collective.

    Args:
        tags: the facet tags to use (:func:`shell_facet_tags` or :func:`side_facet_tags`), so several
            measures can share them in one form; built if omitted.
        metadata: form metadata (e.g. a quadrature degree).
    """
    if name in SHELL_BOUNDARIES:
        tags = shell_facet_tags(mesh) if tags is None else tags
        tag = SHELL_BOUNDARIES.index(name) + 1
    else:
        tags = side_facet_tags(mesh) if tags is None else tags
        tag = side_tag(name, mesh.geometry.dim)
    return ufl.Measure("ds", domain=mesh, subdomain_data=tags, metadata=metadata or {})(tag)


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
    """Local dof indices of ``V`` (a space or sub-space) on box side or shell boundary ``side``.
    Collective."""
    mesh = V.mesh
    if side in SHELL_BOUNDARIES:
        facets = locate_boundary_facets(mesh, side)
    else:
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
) -> list[DirichletBC]:
    """DOLFINx Dirichlet conditions on the vector space ``V`` for the given side conditions.

    On a box, free slip fixes the normal component (the sub-space along the side's axis) to zero;
    on a shell boundary free slip is weak (:func:`nitsche_free_slip`) and gives no Dirichlet
    condition. No slip fixes all components to zero; prescribed fixes all components to ``value``
    (a constant, or the interpolated expressions). Sides missing from ``bcs`` get no condition
    (natural, zero traction). Collective.
    """
    mesh = V.mesh
    gdim = mesh.geometry.dim
    if is_shell(bcs):
        return _shell_velocity_bcs(V, bcs)
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
        elif bc.kind == "prescribed" and (callable(bc.value) or any(isinstance(c, str) for c in bc.value)):
            dofs = dolfinx.fem.locate_dofs_topological(V, fdim, facets)
            out.append(dolfinx.fem.dirichletbc(_velocity_function(V, bc.value), dofs))
        else:
            value = np.zeros(gdim) if bc.kind == "no_slip" else np.asarray(bc.value, dtype=float)
            if value.shape != (gdim,):
                raise ValueError(f"Prescribed velocity on {side!r} must have {gdim} components")
            dofs = dolfinx.fem.locate_dofs_topological(V, fdim, facets)
            out.append(dolfinx.fem.dirichletbc(value.astype(PETSc.ScalarType), dofs, V))
    _check_sides(bcs, gdim)
    return out


def _velocity_function(V: dolfinx.fem.FunctionSpace, value: Any) -> dolfinx.fem.Function:
    """The velocity ``value`` (numbers or expression texts per component, or a callable on points)
    interpolated into ``V``."""
    from convection.expressions import Expression

    gdim = V.mesh.geometry.dim
    if callable(value):
        f = dolfinx.fem.Function(V)
        f.interpolate(value)
        f.x.scatter_forward()
        return f
    if len(value) != gdim:
        raise ValueError(f"A prescribed velocity needs {gdim} components, got {len(value)}")
    components = [Expression(str(c), gdim=gdim) for c in value]
    f = dolfinx.fem.Function(V)
    f.interpolate(lambda x: np.stack([c(x) for c in components]))
    f.x.scatter_forward()
    return f


def _shell_velocity_bcs(V: dolfinx.fem.FunctionSpace, bcs: dict[str, VelocityBC]) -> list:
    """Strong conditions on the shell boundaries (no slip, prescribed); free slip is weak."""
    boundary_names(V.mesh.geometry.dim, bcs)  # checks the names
    fdim = V.mesh.topology.dim - 1
    out = []
    for name in SHELL_BOUNDARIES:
        bc = bcs.get(name)
        if bc is None or bc.kind == "free_slip":
            continue
        value = (0.0,) * V.mesh.geometry.dim if bc.kind == "no_slip" else bc.value
        dofs = dolfinx.fem.locate_dofs_topological(V, fdim, locate_boundary_facets(V.mesh, name))
        out.append(dolfinx.fem.dirichletbc(_velocity_function(V, value), dofs))
    return out


def free_slip_boundaries(bcs: dict[str, VelocityBC]) -> tuple[str, ...]:
    """The curved (shell) boundaries with free slip, where :func:`nitsche_free_slip` applies."""
    return tuple(n for n in SHELL_BOUNDARIES if n in bcs and bcs[n].kind == "free_slip")


def has_rotation_null_space(bcs: dict[str, VelocityBC]) -> bool:
    """Whether every boundary of a shell is free slip: the velocity is then only defined up to rigid
    rotations about the centre (one in 2D, three in 3D)."""
    return is_shell(bcs) and len(free_slip_boundaries(bcs)) == len(SHELL_BOUNDARIES)


class NitscheTerms(NamedTuple):
    """Symmetric Nitsche terms of free slip, to add to the Stokes blocks (UFL forms or None).

    Attributes:
        a_uu: velocity-velocity block.
        a_up: pressure trial, velocity test.
        a_pu: velocity trial, pressure test.
    """

    a_uu: Any
    a_up: Any
    a_pu: Any


def nitsche_free_slip(mesh: dolfinx.mesh.Mesh, names: Iterable[str], u: Any, p: Any, v: Any, q: Any, eta: Any,
                      /, *, penalty: float, metadata: dict | None = None) -> NitscheTerms:
    """Symmetric Nitsche terms imposing free slip on the curved boundaries ``names``. Collective.

    With the stress ``sigma(u, p) = 2 eta eps(u) - p I``, outward unit normal ``n`` of the discrete
    boundary (``ufl.FacetNormal``, exact for the curved cells) and ``h`` the cell diameter
    (:func:`convection.geometry.mesh.cell_diameter`), free
    slip ``u . n = 0``, ``(I - n n) sigma n = 0`` adds to the Stokes form, on each boundary::

        - (n . sigma(u, p) n, v . n) - (n . sigma(v, q) n, u . n) + (penalty eta / h) (u . n, v . n).

    The pressure parts (``+ (p, v . n)`` and ``+ (q, u . n)``) keep the constant pressure in the
    discrete null space exactly (divergence theorem), as with strong conditions.

    Args:
        mesh: the mesh.
        names: shell boundary names with free slip.
        u, p, v, q: velocity and pressure trial and test functions.
        eta: viscosity (UFL expression).
        penalty: dimensionless penalty factor (large enough for coercivity, e.g. 10 (k + 1)^2 for
            velocity degree k).
        metadata: form metadata for the boundary integrals (e.g. a quadrature degree).
    """
    n = ufl.FacetNormal(mesh)
    h = cell_diameter(mesh)
    a_uu = a_up = a_pu = None
    tags = shell_facet_tags(mesh)
    for name in names:
        ds = boundary_measure(mesh, name, tags=tags, metadata=metadata)
        un, vn = ufl.dot(u, n), ufl.dot(v, n)
        uu = (-2.0 * eta * ufl.dot(n, ufl.dot(ufl.sym(ufl.grad(u)), n)) * vn
              - 2.0 * eta * ufl.dot(n, ufl.dot(ufl.sym(ufl.grad(v)), n)) * un
              + penalty * eta / h * un * vn) * ds
        up = p * vn * ds
        pu = q * un * ds
        a_uu = uu if a_uu is None else a_uu + uu
        a_up = up if a_up is None else a_up + up
        a_pu = pu if a_pu is None else a_pu + pu
    return NitscheTerms(a_uu, a_up, a_pu)


def temperature_dirichlet_bcs(
    V: dolfinx.fem.FunctionSpace, bcs: dict[str, TemperatureBC]
) -> list[DirichletBC]:
    """DOLFINx Dirichlet conditions on the scalar space ``V``; insulating sides get none.
    Collective."""
    gdim = V.mesh.geometry.dim
    if is_shell(bcs):
        out = []
        for name in boundary_names(gdim, bcs):
            bc = bcs.get(name)
            if bc is not None and bc.kind == "dirichlet":
                out.append(dolfinx.fem.dirichletbc(PETSc.ScalarType(bc.value), locate_side_dofs(V, name), V))
        return out
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
