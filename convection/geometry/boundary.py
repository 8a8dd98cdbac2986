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
from convection.geometry.plates import Plate, PlateVelocity, plate_table_problem, plate_width_problem
from convection.schema import finite_number, param, short_repr
from fembase.dolfinx_compat import DirichletBC
from fembase.registry import Registry

__all__ = ["DEFAULT_TEMPERATURE", "DEFAULT_VELOCITY", "TEMPERATURE_BC_KINDS", "VELOCITY_BC_KINDS",
           "BoundarySettings", "ConditionKind", "NitscheTerms", "PlatesSettings", "PrescribedSettings", "TemperatureBC",
           "TemperatureKind", "VelocityBC", "VelocityCondition", "VelocityContext", "VelocityKind",
           "has_rotation_null_space", "nitsche_free_slip", "temperature_dirichlet_bcs", "velocity_dirichlet_bcs",
           "weak_free_slip_boundaries"]

@dataclass(frozen=True)
class VelocityContext:
    """What a velocity condition is made in (:meth:`VelocityKind.build`).

    Attributes:
        gdim: The dimension of the domain.
    """

    gdim: int


@dataclass(frozen=True)
class _NoEntries:
    """The settings of a kind written by its name alone (``top: free_slip``): none."""


def _components_problem(value: Any, /) -> str | None:
    """What is wrong with a prescribed velocity's ``value`` as written (None: missing), or None."""
    if not isinstance(value, (list, tuple)):
        return "a prescribed velocity needs 'value: [vx, vy(, vz)]'"
    for i, component in enumerate(value):
        if isinstance(component, str):
            try:
                Expression(component, gdim=3)
            except ExpressionError as err:
                return f"value[{i}]: {err}"
        elif finite_number(component) is None:
            return f"value[{i}]: {short_repr(component)} must be a finite number or an expression"
    return None


class ConditionKind:
    """What a kind of boundary condition has (the velocity's :class:`VelocityKind`, the
    temperature's :class:`TemperatureKind`): a config name, one line, the entries a config gives it
    (:attr:`Settings`, none by default) and the strong conditions that impose it (none by default).

    Attributes:
        name, description: The config name and one line.
        needs_value: The condition it builds has a value.
    """

    name: ClassVar[str]
    description: ClassVar[str]
    Settings: ClassVar[type] = _NoEntries
    needs_value: ClassVar[bool] = False

    def dirichlet(self, V: dolfinx.fem.FunctionSpace, domain: Domain, name: str, value: Any, /) -> list[DirichletBC]:
        """The strong conditions on the boundary ``name`` (none: a natural or weak condition). Collective."""
        return []


class VelocityKind(ConditionKind):
    """One kind of velocity condition, as ``boundary.velocity.<side>`` names it (an entry of
    :data:`VELOCITY_BC_KINDS`): its entries (:attr:`Settings`), the :class:`VelocityBC` it builds
    and the Dirichlet conditions that impose it. Subclasses override what differs.

    A config writes a kind by its name (``free_slip``) or as ``{kind: <name>, <entry>: ...}``; the
    entries are the fields of its ``Settings`` (made by :func:`fembase.params.param`), whose
    ``check`` says, in the user's terms, what is wrong with an entry as written, and what a
    required entry that is missing lacks (given None).

    Attributes (beyond :class:`ConditionKind`'s):
        form: How a config writes a kind with required entries (for the message when it is
            written by its name alone).
        condition: A :class:`VelocityBC` of this kind exists (False: a config form of another kind).
        rotations_free: Lets the flow slide along the boundary (a shell's rigid rotations cross it nowhere).
        weak_without_axis: Imposed weakly (:func:`nitsche_free_slip`) where the boundary has no normal axis.
        moves: The boundary moves with the flow (:mod:`convection.deform`), a natural condition here.
    """

    form: ClassVar[str] = ""
    condition: ClassVar[bool] = True
    rotations_free: ClassVar[bool] = False
    weak_without_axis: ClassVar[bool] = False
    moves: ClassVar[bool] = False

    @classmethod
    def build(cls, settings: Any, context: VelocityContext, /) -> VelocityBC:
        """The condition of this kind's ``settings`` (a :attr:`Settings`) in ``context``: with the
        settings' ``value`` where the kind :attr:`needs_value`."""
        return VelocityBC(cls.name, settings.value if cls.needs_value else None)

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


@dataclass(frozen=True)
class PrescribedSettings:
    """The entries of a prescribed velocity."""

    value: tuple[float | str, ...] = param(check=_components_problem, help="the velocity: per component a number or "
                                           "an expression in x, y, z, r, ... (as many as the domain's dimension)")

    def __post_init__(self) -> None:
        object.__setattr__(self, "value", tuple(c if isinstance(c, str) else float(c) for c in self.value))


class Prescribed(VelocityKind):
    name = "prescribed"
    description = "velocity equal to `value`: a constant vector, or expressions in x, y, z, r, ... per component"
    form = "{kind: prescribed, value: [vx, vy(, vz)]}"
    Settings: ClassVar[type] = PrescribedSettings
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
    form = ""
    Settings = _NoEntries
    needs_value = False

    def dirichlet(self, V: dolfinx.fem.FunctionSpace, domain: Domain, name: str, value: Any, /) -> list[DirichletBC]:
        return super().dirichlet(V, domain, name, (0.0,) * V.mesh.geometry.dim)

    def homogeneous(self, bc: VelocityBC, /) -> VelocityBC:
        return bc


@dataclass(frozen=True)
class PlatesSettings:
    """The entries of a plates velocity (:mod:`convection.geometry.plates`)."""

    plates: tuple[Plate, ...] = param(check=plate_table_problem, help="the plates: [{centre: [lon, lat], pole: [lon, "
                                      "lat], rate: omega}, ...] (degrees; 2D: centre [lon], no pole)")
    width: float = param(0.1, check=plate_width_problem, help="angular width of the plate boundaries (radians)")


class Plates(VelocityKind):
    name = "plates"
    description = "rigid plates on a spherical shell's outer surface: a prescribed velocity"
    form = "{kind: plates, width: w, plates: [{centre, pole, rate}, ...]}"
    Settings = PlatesSettings
    condition = False

    @classmethod
    def build(cls, settings: Any, context: VelocityContext, /) -> VelocityBC:
        return VelocityBC(Prescribed.name, PlateVelocity(settings.plates, settings.width, context.gdim))


class FreeSurface(VelocityKind):
    name = "free_surface"
    description = "zero traction; the surface moves with the flow and the mesh deforms (the free_surface section)"
    rotations_free = moves = True


VELOCITY_BC_KINDS: Registry[VelocityKind] = Registry("velocity condition", (
    FreeSlip(), NoSlip(), Prescribed(), Plates(), FreeSurface()))
"""Registry of the velocity condition kinds a config names (the order of the config's messages)."""


def _temperature_problem(value: Any, /) -> str | None:
    """What is wrong with a fixed temperature as written (a number, or its text), or None."""
    number = value
    if isinstance(number, str):
        try:
            number = float(number)
        except ValueError:
            pass
    if finite_number(number) is None:
        return f"dirichlet value must be a finite number, got {short_repr(value)}"
    return None


class TemperatureKind(ConditionKind):
    """One kind of temperature condition, as ``boundary.temperature.<side>`` names it (an entry of
    :data:`TEMPERATURE_BC_KINDS`): written by its name, or ``{<name>: <its one entry>}``."""

    @classmethod
    def build(cls, settings: Any, context: Any, /) -> TemperatureBC:
        """The condition of this kind's ``settings`` (``context``: not needed): with the settings'
        ``value`` where the kind :attr:`needs_value`."""
        return TemperatureBC(cls.name, settings.value if cls.needs_value else None)


@dataclass(frozen=True)
class DirichletSettings:
    """The entry of a fixed temperature."""

    value: float = param(check=_temperature_problem, help="the temperature")


class Dirichlet(TemperatureKind):
    name = "dirichlet"
    description = "temperature equal to the constant `value`"
    Settings: ClassVar[type] = DirichletSettings
    needs_value = True

    def dirichlet(self, V: dolfinx.fem.FunctionSpace, domain: Domain, name: str, value: Any, /) -> list[DirichletBC]:
        return [dolfinx.fem.dirichletbc(PETSc.ScalarType(value), domain.locate_dofs(V, name), V)]


class Insulating(TemperatureKind):
    name = "insulating"
    description = "zero heat flux (natural condition)"


TEMPERATURE_BC_KINDS: Registry[TemperatureKind] = Registry("temperature condition", (Dirichlet(), Insulating()))
"""Registry of temperature boundary condition kinds."""


@dataclass(frozen=True)
class VelocityCondition:
    """One boundary's velocity condition as configured: the name of its kind
    (:data:`VELOCITY_BC_KINDS`) and the kind's settings."""

    kind: str
    settings: Any

    def build(self, context: VelocityContext, /) -> VelocityBC:
        """The :class:`VelocityBC` it gives in ``context`` (through the registry)."""
        return VELOCITY_BC_KINDS.build(self.kind, self.settings, context)


@dataclass(frozen=True)
class BoundarySettings:
    """The ``boundary`` config section of a run, typed: for each boundary of its geometry, the
    velocity condition (None: traction free) and the temperature condition."""

    velocity: Mapping[str, VelocityCondition | None]
    temperature: Mapping[str, TemperatureBC]

    @property
    def free_surfaces(self) -> tuple[str, ...]:
        """The boundaries whose velocity condition moves with the flow (a free surface)."""
        return tuple(name for name, c in self.velocity.items() if c is not None and VELOCITY_BC_KINDS[c.kind].moves)

    def velocity_bcs(self, domain: Domain, /) -> dict[str, VelocityBC]:
        """The velocity conditions on the boundaries of ``domain`` (the traction-free ones left out)."""
        context = VelocityContext(domain.gdim)
        conditions = {side: self.velocity[side] for side in domain.boundaries}
        return {side: c.build(context) for side, c in conditions.items() if c is not None}

    def temperature_bcs(self, domain: Domain, /) -> dict[str, TemperatureBC]:
        """The temperature conditions on the boundaries of ``domain``."""
        return {side: self.temperature[side] for side in domain.boundaries}


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
        if self.spec.needs_value and self.value is None:
            raise ValueError(f"A {self.kind!r} temperature BC needs a value")

    @property
    def spec(self) -> TemperatureKind:
        """The kind's entry of :data:`TEMPERATURE_BC_KINDS`."""
        return TEMPERATURE_BC_KINDS[self.kind]


DEFAULT_VELOCITY = VelocityCondition(FreeSlip.name, FreeSlip.Settings())
"""The velocity condition of a boundary the config does not name."""
DEFAULT_TEMPERATURE = TemperatureBC(Insulating.name)
"""The temperature condition of a boundary the config does not name."""


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
                      eta: Any, /, *, penalty: float, metadata: dict | None = None, density: Any = None
                      ) -> NitscheTerms:
    """Symmetric Nitsche terms imposing free slip on the boundaries ``names`` of ``domain``. Collective.

    With the stress ``sigma(u, p) = 2 eta eps(u) - p I``, outward unit normal ``n`` of the discrete
    boundary (``ufl.FacetNormal``, exact for the curved cells) and ``h`` the cell diameter
    (:func:`convection.geometry.mesh.cell_diameter`), free
    slip ``u . n = 0``, ``(I - n n) sigma n = 0`` adds to the Stokes form, on each boundary::

        - (n . sigma(u, p) n, v . n) - (n . sigma(v, q) n, u . n) + (penalty eta / h) (u . n, v . n).

    The pressure parts (``+ (p, v . n)`` and ``+ (q, u . n)``) keep the constant pressure in the
    discrete null space exactly (divergence theorem), as with strong conditions. With a continuity
    equation ``div(rho_r u) = 0`` (``density``: ``rho_r``, TALA and ALA) the continuity's part is
    ``+ (q, rho_r u . n)``: summed over all ``q`` (``q = 1``) the continuity rows then vanish for
    every ``u``, as ``int div(rho_r u) = int_boundary rho_r u . n``, so the discrete problem stays
    solvable with a pinned pressure dof (with ``(q, u . n)`` the pinned row's mass was lost where
    ``rho_r != 1``: 0.8 % of the heat flow in Davies et al.'s annulus under TALA, Di = 0.5).

    Args:
        mesh: the mesh.
        domain: the domain (its facet tags and measures).
        names: boundary names with free slip imposed weakly (:func:`weak_free_slip_boundaries`).
        u, p, v, q: velocity and pressure trial and test functions.
        eta: viscosity (UFL expression).
        penalty: dimensionless penalty factor (large enough for coercivity, e.g. 10 (k + 1)^2 for
            velocity degree k).
        metadata: form metadata for the boundary integrals (e.g. a quadrature degree).
        density: the continuity equation's reference density ``rho_r`` (UFL), or None for ``div u = 0``.
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
        pu = q * (un if density is None else density * un) * ds
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
        if bc is not None:
            out.extend(bc.spec.dirichlet(V, domain, name, bc.value))
    return out
