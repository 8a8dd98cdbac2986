"""Boundary conditions by boundary name, on any domain.

The names are the domain's (:attr:`convection.geometry.domain.Domain.boundaries`: box sides, the
shell's ``inner`` and ``outer``, a sector's arcs and sides); the domain finds their facets. Where a
boundary is a plane normal to a coordinate axis (:meth:`convection.geometry.domain.Domain.normal_axis`:
a box side), free slip is a zero Dirichlet condition on the velocity component along that axis.
Elsewhere (curved or oblique boundaries) the normal varies, so free slip (``u . n = 0``, zero
tangential traction) is imposed weakly by Nitsche's method (:func:`nitsche_free_slip`); no-slip and
prescribed velocities are strong (nodal) conditions everywhere.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from typing import Any, ClassVar, NamedTuple

import dolfinx
import numpy as np
import ufl
from petsc4py import PETSc

from convection.geometry.domain import Domain
from convection.expressions import Expression, ExpressionError
from convection.geometry.mesh import cell_diameter
from convection.geometry.plates import PlateVelocity
from convection.schema import finite_number, short_repr
from fembase.dolfinx_compat import DirichletBC
from fembase.registry import Registry

__all__ = ["TEMPERATURE_BC_KINDS", "VELOCITY_BC_KINDS", "BoundarySettings", "NitscheTerms", "TemperatureBC",
           "VelocityBC", "VelocityKind", "has_rotation_null_space", "nitsche_free_slip", "temperature_dirichlet_bcs",
           "velocity_dirichlet_bcs", "weak_free_slip_boundaries"]

class VelocityKind:
    """One kind of velocity condition, as ``boundary.velocity.<side>`` names it (an entry of
    :data:`VELOCITY_BC_KINDS`): how a config gives it, the :class:`VelocityBC` it makes and the
    Dirichlet conditions that impose it. Subclasses override what differs.

    Attributes:
        name, description: The config name and one line.
        condition: A :class:`VelocityBC` of this kind exists (False: a config form of another kind).
        needs_value: The config gives ``{kind: <name>, value: [...]}`` and :class:`VelocityBC` a value.
        rotations_free: Lets the flow slide along the boundary (a shell's rigid rotations cross it nowhere).
        weak_without_axis: Imposed weakly (:func:`nitsche_free_slip`) where the boundary has no normal axis.
        moves: The boundary moves with the flow (:mod:`convection.deform`), a natural condition here.
    """

    name: ClassVar[str]
    description: ClassVar[str]
    condition: ClassVar[bool] = True
    needs_value: ClassVar[bool] = False
    rotations_free: ClassVar[bool] = False
    weak_without_axis: ClassVar[bool] = False
    moves: ClassVar[bool] = False

    def check_config(self, value: Any, /) -> str | None:
        """What is wrong with the config's ``value`` of this kind (a name or a mapping), or None."""
        if not isinstance(value, dict):
            return (f"a {self.name} velocity needs the form {{kind: {self.name}, value: [vx, vy(, vz)]}}"
                    if self.needs_value else None)
        extra = [name for name in value if name not in ("kind", "value")]
        if extra:
            return f"unknown entry {short_repr(extra[0])}; allowed: ['kind', 'value']"
        if self.needs_value and not isinstance(value.get("value"), list):
            return f"a {self.name} velocity needs 'value: [vx, vy(, vz)]'"
        for i, component in enumerate(value.get("value") or ()):
            if isinstance(component, str):
                try:
                    Expression(component, gdim=3)
                except ExpressionError as err:
                    return f"value[{i}]: {err}"
            elif finite_number(component) is None:
                return f"value[{i}]: {short_repr(component)} must be a finite number or an expression"
        return None

    def from_config(self, value: Any, gdim: int, /) -> VelocityBC:
        """The condition the config's checked ``value`` of this kind gives in ``gdim`` dimensions."""
        if not isinstance(value, dict):
            return VelocityBC(self.name)
        components = tuple(v if isinstance(v, str) else float(v) for v in value.get("value") or ())
        return VelocityBC(self.name, components or None)

    def dirichlet(self, V: dolfinx.fem.FunctionSpace, domain: Domain, name: str, value: Any, /) -> list[DirichletBC]:
        """The strong conditions on the boundary ``name`` (none: a natural or weak condition). Collective."""
        return []

    def homogeneous(self, bc: VelocityBC, /) -> VelocityBC:
        """``bc`` with zero values on the same dofs."""
        return bc


class FreeSlip(VelocityKind):
    name = "free_slip"
    description = "zero normal velocity, zero tangential traction"
    rotations_free = weak_without_axis = True

    def dirichlet(self, V: dolfinx.fem.FunctionSpace, domain: Domain, name: str, value: Any, /) -> list[DirichletBC]:
        """Zero velocity component along the boundary's normal axis; none without one (Nitsche)."""
        axis = domain.normal_axis(name)
        if axis is None:
            return []
        facets = domain.locate_facets(V.mesh, name)
        dofs = dolfinx.fem.locate_dofs_topological(V.sub(axis), V.mesh.topology.dim - 1, facets)
        return [dolfinx.fem.dirichletbc(PETSc.ScalarType(0.0), dofs, V.sub(axis))]


class Prescribed(VelocityKind):
    name = "prescribed"
    description = "velocity equal to `value`: a constant vector, or expressions in x, y, z, r, ... per component"
    needs_value = True

    def dirichlet(self, V: dolfinx.fem.FunctionSpace, domain: Domain, name: str, value: Any, /) -> list[DirichletBC]:
        """Every component fixed: a constant vector, or the interpolated expressions or callable."""
        facets = domain.locate_facets(V.mesh, name)
        fdim = V.mesh.topology.dim - 1
        if callable(value) or any(isinstance(c, str) for c in value or ()):
            dofs = dolfinx.fem.locate_dofs_topological(V, fdim, facets)
            return [dolfinx.fem.dirichletbc(_velocity_function(V, value), dofs)]
        constant = np.asarray(value, dtype=float)
        if constant.shape != (V.mesh.geometry.dim,):
            raise ValueError(f"Prescribed velocity on {name!r} must have {V.mesh.geometry.dim} components")
        dofs = dolfinx.fem.locate_dofs_topological(V, fdim, facets)
        return [dolfinx.fem.dirichletbc(constant.astype(PETSc.ScalarType), dofs, V)]

    def homogeneous(self, bc: VelocityBC, /) -> VelocityBC:
        return VelocityBC("no_slip")


class NoSlip(Prescribed):
    name = "no_slip"
    description = "zero velocity"
    needs_value = False

    def dirichlet(self, V: dolfinx.fem.FunctionSpace, domain: Domain, name: str, value: Any, /) -> list[DirichletBC]:
        return super().dirichlet(V, domain, name, (0.0,) * V.mesh.geometry.dim)

    def homogeneous(self, bc: VelocityBC, /) -> VelocityBC:
        return bc


class Plates(VelocityKind):
    name = "plates"
    description = "rigid plates on a spherical shell's outer surface: a prescribed velocity"
    condition = False

    def check_config(self, value: Any, /) -> str | None:
        if not isinstance(value, dict):
            return "a plates velocity needs the form {kind: plates, width: w, plates: [{centre, pole, rate}, ...]}"
        try:
            PlateVelocity.from_config(value, 3)
        except (TypeError, ValueError, OverflowError) as err:  # TypeError: e.g. keys of mixed types
            return str(err)
        return None

    def from_config(self, value: Any, gdim: int, /) -> VelocityBC:
        return VelocityBC(Prescribed.name, PlateVelocity.from_config(value, gdim))


class FreeSurface(VelocityKind):
    name = "free_surface"
    description = "zero traction; the surface moves with the flow and the mesh deforms (the free_surface section)"
    rotations_free = moves = True


VELOCITY_BC_KINDS: Registry[VelocityKind] = Registry("velocity condition", (
    FreeSlip(), NoSlip(), Prescribed(), Plates(), FreeSurface()))
"""Registry of the velocity condition kinds a config names (the order of the config's messages)."""

TEMPERATURE_BC_KINDS: dict[str, str] = {
    "dirichlet": "temperature equal to the constant `value`",
    "insulating": "zero heat flux (natural condition)",
}
"""Registry of temperature boundary condition kinds (name -> one-line description)."""


@dataclass(frozen=True)
class BoundarySettings:
    """The ``boundary`` config section of a run: for each boundary of its geometry, the velocity and
    the temperature condition as written (a kind name, ``{kind: ..., ...}`` or ``{dirichlet: T}``;
    null: traction free / insulating)."""

    velocity: Mapping[str, Any]
    temperature: Mapping[str, Any]

    @property
    def free_surfaces(self) -> tuple[str, ...]:
        """The boundaries whose velocity condition moves with the flow (a free surface)."""
        kinds = {name: value.get("kind") if isinstance(value, dict) else value for name, value in self.velocity.items()}
        return tuple(name for name, kind in kinds.items()
                     if isinstance(kind, str) and kind in VELOCITY_BC_KINDS and VELOCITY_BC_KINDS[kind].moves)


@dataclass(frozen=True)
class VelocityBC:
    """Velocity boundary condition on one side.

    Attributes:
        kind: ``"free_slip"`` | ``"no_slip"`` | ``"prescribed"`` | ``"free_surface"`` (a natural
            condition here; :mod:`convection.deform` moves the mesh).
        value: for ``"prescribed"``, the velocity (length ``gdim``): numbers (a constant vector)
            or expression texts (:mod:`convection.expressions`, e.g. ``("-y", "x")``, a rigid
            rotation) per component; or a callable ``f(x)`` from points shape=(3, n) to
            shape=(gdim, n) (e.g. :class:`convection.geometry.plates.PlateVelocity`).
    """

    kind: str
    value: tuple[float | str, ...] | Callable[[np.ndarray], np.ndarray] | None = None

    def __post_init__(self) -> None:
        if self.kind not in VELOCITY_BC_KINDS or not VELOCITY_BC_KINDS[self.kind].condition:
            raise ValueError(f"Unknown velocity BC kind {self.kind!r}; valid names: "
                             f"{sorted(n for n, kind in VELOCITY_BC_KINDS.items() if kind.condition)}")
        if self.spec.needs_value and self.value is None:
            raise ValueError(f"A {self.kind!r} velocity BC needs a value")

    @property
    def spec(self) -> VelocityKind:
        """The kind's entry of :data:`VELOCITY_BC_KINDS`."""
        return VELOCITY_BC_KINDS[self.kind]


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


def velocity_dirichlet_bcs(V: dolfinx.fem.FunctionSpace, bcs: dict[str, VelocityBC], domain: Domain, /
                           ) -> list[DirichletBC]:
    """DOLFINx Dirichlet conditions on the vector space ``V`` for the given boundary conditions.

    Free slip fixes the normal component (the sub-space along the boundary's axis) to zero where
    the domain has a normal axis, and gives no Dirichlet condition elsewhere (weak, see
    :func:`nitsche_free_slip`). No slip fixes all components to zero; prescribed fixes all
    components to ``value`` (a constant, or the interpolated expressions or callable). Boundaries
    missing from ``bcs`` get no condition (natural, zero traction). Collective.
    """
    domain.check_boundary_names(bcs)
    out = []
    for name in domain.boundaries:
        bc = bcs.get(name)
        if bc is not None:
            out.extend(bc.spec.dirichlet(V, domain, name, bc.value))
    return out


def _velocity_function(V: dolfinx.fem.FunctionSpace, value: Any) -> dolfinx.fem.Function:
    """The velocity ``value`` (numbers or expression texts per component, or a callable on points)
    interpolated into ``V``."""
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


def weak_free_slip_boundaries(bcs: dict[str, VelocityBC], domain: Domain, /) -> tuple[str, ...]:
    """The boundaries with free slip that have no normal axis, where :func:`nitsche_free_slip` applies."""
    return tuple(n for n in domain.boundaries if n in bcs and bcs[n].spec.weak_without_axis
                 and domain.normal_axis(n) is None)


def has_rotation_null_space(bcs: dict[str, VelocityBC], domain: Domain, /) -> bool:
    """Whether the velocity is only defined up to rigid rotations about the centre (a shell free
    slip or a free surface on every boundary: one rotation in 2D, three in 3D; a rotation moves no
    surface of the undeformed shell)."""
    return domain.has_rotations({n for n, bc in bcs.items() if bc.spec.rotations_free})


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


def nitsche_free_slip(mesh: dolfinx.mesh.Mesh, domain: Domain, names: Iterable[str], u: Any, p: Any, v: Any, q: Any,
                      eta: Any, /, *, penalty: float, metadata: dict | None = None) -> NitscheTerms:
    """Symmetric Nitsche terms imposing free slip on the boundaries ``names`` of ``domain``. Collective.

    With the stress ``sigma(u, p) = 2 eta eps(u) - p I``, outward unit normal ``n`` of the discrete
    boundary (``ufl.FacetNormal``, exact for the curved cells) and ``h`` the cell diameter
    (:func:`convection.geometry.mesh.cell_diameter`), free
    slip ``u . n = 0``, ``(I - n n) sigma n = 0`` adds to the Stokes form, on each boundary::

        - (n . sigma(u, p) n, v . n) - (n . sigma(v, q) n, u . n) + (penalty eta / h) (u . n, v . n).

    The pressure parts (``+ (p, v . n)`` and ``+ (q, u . n)``) keep the constant pressure in the
    discrete null space exactly (divergence theorem), as with strong conditions.

    Args:
        mesh: the mesh.
        domain: the domain (its facet tags and measures).
        names: boundary names with free slip imposed weakly (:func:`weak_free_slip_boundaries`).
        u, p, v, q: velocity and pressure trial and test functions.
        eta: viscosity (UFL expression).
        penalty: dimensionless penalty factor (large enough for coercivity, e.g. 10 (k + 1)^2 for
            velocity degree k).
        metadata: form metadata for the boundary integrals (e.g. a quadrature degree).
    """
    n = ufl.FacetNormal(mesh)
    h = cell_diameter(mesh)
    a_uu = a_up = a_pu = None
    tags = domain.facet_tags(mesh)
    for name in names:
        ds = domain.measure(mesh, name, tags=tags, metadata=metadata)
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


def temperature_dirichlet_bcs(V: dolfinx.fem.FunctionSpace, bcs: dict[str, TemperatureBC], domain: Domain | None,
                              /) -> list[DirichletBC]:
    """DOLFINx Dirichlet conditions on the scalar space ``V``; insulating boundaries get none
    (``domain`` may be None when ``bcs`` is empty). Collective."""
    if not bcs:
        return []
    assert domain is not None, "boundary conditions need the domain"
    domain.check_boundary_names(bcs)
    out = []
    for name in domain.boundaries:
        bc = bcs.get(name)
        if bc is not None and bc.kind == "dirichlet":
            out.append(dolfinx.fem.dirichletbc(PETSc.ScalarType(bc.value), domain.locate_dofs(V, name), V))
    return out
