"""Taylor-Hood discretisation of the Boussinesq Stokes problem: spaces, strong conditions, forms.

Weak form (find ``u in V_D``, ``p in Q`` such that for all ``v in V_0``, ``q in Q``)::

    (2 eta eps(u), eps(v)) - (p, div v) = ((Ra T - Rb C) e_z, v)
                            -(q, div u) = 0

(the truncated anelastic liquid approximation, :mod:`convection.physics.compressible`: ``-(q, div(rho_r u))``
and ``rho_r`` in the body force; the anelastic liquid approximation also ``+(c p e_up, v)`` in the
momentum equation's pressure block, the pressure's buoyancy, ``c = (Di / gamma) (cp / cv) rho_r``,
and the compressible stress's ``-(2/3) (eta div u, div v)``)

on a vector P(k) / scalar P(k-1) pair (k = 2: Taylor-Hood P2-P1), ``eta = eta(T, C)`` and the
body force from :class:`~convection.physics.approximation.BoussinesqApproximation`. With a variable
viscosity the cell integrals use a quadrature of degree ``3 k`` (UFL's estimate for ``exp`` or
quotients would be far higher). Strong conditions (:func:`convection.geometry.boundary.velocity_dirichlet_bcs`)
fix the velocity on the box sides and the no-slip or prescribed shell boundaries; free slip on a
curved shell boundary adds the symmetric Nitsche terms of
:func:`convection.geometry.boundary.nitsche_free_slip` (penalty ``nitsche_penalty eta / h``) to the three
blocks.

Besides the operator ``K = [[A, B^T], [B, 0]]`` and the right-hand side, :meth:`StokesDiscretisation.forms`
builds what a linear solver asks for:

- a zero pressure-pressure block (``pressure_block=True``), to hold the diagonal of a pinned
  pressure dof;
- the preconditioning matrix ``[[A, B^T], [B, -M_p / eta]]`` (``preconditioner=True``): the
  viscosity-scaled pressure mass matrix approximates the Schur complement ``S = -B A^-1 B^T``
  (PETSc's sign); PETSc's fieldsplit takes the factorisation's ``B`` and ``B^T`` from this
  matrix, so it holds the operator's (without them the block-triangular preconditioner is
  block diagonal: 20 instead of 13 multigrid iterations at 16^3, 54 instead of 40 with AMG);
- with a free surface (:mod:`convection.deform.surface`), its load ``-(B h n, v)`` on the right-hand
  side and its stabilisation ``theta dt B (u . n, v . e_up)`` in ``A``;
- with elasticity (:mod:`convection.physics.elasticity`), the visco-elastic viscosity ``eta_ve`` in
  place of ``eta`` and the old stress's load ``-(chi tau^n, eps(v))`` on the right-hand side;
- with a semi-implicit buoyancy (:class:`convection.physics.buoyancy.SemiImplicitBuoyancy`), its
  velocity-velocity term on its own (added to ``A`` every solve) and the whole operator
  ``K + term`` that lifts the boundary values into the right-hand side.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import dolfinx
import numpy as np
import ufl
from petsc4py import PETSc

from convection.physics.approximation import BoussinesqApproximation
from convection.geometry.boundary import (
    NitscheTerms, VelocityBC, nitsche_free_slip, velocity_dirichlet_bcs, weak_free_slip_boundaries,
)
from convection.geometry.domain import Domain
from convection.physics.buoyancy import SemiImplicitBuoyancy
from convection.physics.elasticity import Elasticity
from convection.deform.surface import SurfaceTerms
from fembase.dolfinx_compat import function_space

__all__ = ["StokesDiscretisation", "StokesForms"]



class StokesForms(NamedTuple):
    """Compiled forms of one Stokes problem (fields ``T``, ``C`` fixed as coefficients).

    Attributes:
        a: the operator ``K``, a 2 x 2 block form (velocity, pressure).
        L: the right-hand side, a block form (momentum, continuity).
        a_lift: the operator that lifts the boundary values into ``L``: ``a``, or ``K + term`` with
            a semi-implicit buoyancy.
        a_pc: the preconditioning matrix ``[[A, B^T], [B, -M_p / eta]]``, or None.
        a_si: the semi-implicit buoyancy term (a velocity-velocity form), or None.
        a_weights: ``sqrt(eta)`` times the scalar mass form on the velocity's component space, whose
            diagonal weighs the w-BFBt Schur approximation (:mod:`convection.solvers.stokes.bfbt`), or None.
        a_si_component: where the term has one velocity component only (a box: ``e_up = e_k``),
            ``(k, W, W_to_V, form)``: the component's space ``V.sub(k).collapse()``, its map into
            ``V``'s unrolled dofs and the term as a scalar form on it
            (:class:`convection.solvers.stokes.axis_block.AxisBlock`); None otherwise.
    """

    a: Any
    L: Any
    a_lift: Any
    a_pc: Any = None
    a_si: Any = None
    a_si_component: Any = None
    a_weights: Any = None


def weights_form(W: dolfinx.fem.FunctionSpace, eta: Any, dx: Any, /) -> Any:
    """The compiled ``(sqrt(eta) w, s)`` on the scalar space ``W`` (the w-BFBt weights: its diagonal)."""
    w, s = ufl.TrialFunction(W), ufl.TestFunction(W)
    return dolfinx.fem.form(ufl.sqrt(eta) * w * s * dx)


class StokesDiscretisation:
    """Taylor-Hood spaces, the strong velocity conditions and the forms (see the module docstring).

    Args:
        mesh: the mesh (box or shell, 2D or 3D).
        approximation: physics parameters, viscosity law and body force.
        domain: the domain (its boundaries; :mod:`convection.geometry.domain`).
        bcs: velocity condition per boundary name (:mod:`convection.geometry.boundary`).
        degree: velocity degree ``k >= 2``; the pressure has degree ``k - 1``.
        nitsche_penalty: penalty factor of the weak free-slip condition on curved or oblique boundaries.

    Attributes:
        V: the vector P(degree) velocity space.
        Q: the P(degree - 1) pressure space.
        dirichlet: the strong velocity conditions (DirichletBC list, on ``V`` or its sub-spaces).
    """

    def __init__(self, mesh: dolfinx.mesh.Mesh, approximation: BoussinesqApproximation, /, *,
                 domain: Domain, bcs: dict[str, VelocityBC], degree: int, nitsche_penalty: float,
                 surface: SurfaceTerms | None = None) -> None:
        if degree < 2:
            raise ValueError("Taylor-Hood needs velocity degree >= 2")
        self.mesh = mesh
        self.approximation = approximation
        self.domain = domain
        self.bcs = bcs
        self.degree = degree
        self.nitsche_penalty = nitsche_penalty
        self.V = function_space(mesh, "Lagrange", degree, shape=(mesh.geometry.dim,))
        self.Q = function_space(mesh, "Lagrange", degree - 1)
        self.dirichlet = velocity_dirichlet_bcs(self.V, bcs, domain)
        self.surface = surface
        self.surface_dt = SurfaceTerms.step_constant(mesh) if surface is not None else None
        # Elasticity (issue 48): eta -> eta_ve, the old stress's load; 1 / dt_e (0: the viscous flow), r = dt / dt_e.
        self.elasticity: Elasticity | None = getattr(approximation, "elasticity", None)
        self.elastic_rate, self.elastic_share = (dolfinx.fem.Constant(mesh, PETSc.ScalarType(x)) for x in (0.0, 1.0))

    @property
    def anticipates_step(self) -> bool:
        """Whether the forms depend on the coming step ``dt`` (a free surface with ``theta > 0``)."""
        return self.surface is not None and self.surface.theta > 0.0

    def set_surface_step(self, dt: float, /) -> bool:
        """Set the step the free surface's stabilisation anticipates; whether the operator changed."""
        if self.surface_dt is None or self.surface_dt.value == dt:
            return False
        self.surface_dt.value = dt
        return True

    def set_steps(self, dt: float, /) -> bool:
        """Set the step of the free surface's stabilisation and the elastic time step; whether the operator changed."""
        surface = self.set_surface_step(dt)
        return self.set_elastic_step(dt) or surface

    def set_elastic_step(self, dt: float, /) -> bool:
        """Set ``1 / dt_e`` and ``r = dt / dt_e`` for the step ``dt`` (:mod:`convection.physics.elasticity`,
        ``Elasticity.steps``); whether the operator changed (always where ``G`` moves with the materials)."""
        if self.elasticity is None:
            return False
        rate, self.elastic_share.value = self.elasticity.steps(dt)
        changed = self.elastic_rate.value != rate
        self.elastic_rate.value = rate
        return changed or self.elasticity.is_variable

    def viscosity(self, T: Any, C: Any, flow: dict[str, Any] | None = None, /) -> Any:
        """The viscosity (UFL) for ``T``, ``C`` and, for :mod:`convection.physics.rheology` laws, the flow:
        ``flow = {"u": ..., "p": ..., "fields": {...}}`` (the current iterate's Functions); with
        elasticity the visco-elastic ``eta_ve`` (visco-elasto-plastic where a yield law limits it)."""
        eta = self.maxwell_viscosity(T, C, flow)
        return eta if self.elasticity is None else self.elasticity.viscosity(eta, C, self.elastic_rate)

    def maxwell_viscosity(self, T: Any, C: Any, flow: dict[str, Any] | None = None, /) -> Any:
        """The laws' viscosity ``eta`` that :meth:`viscosity` makes visco-elastic; with elasticity and a
        law that yields, its yield laws see the elastic trial state (:meth:`elastic_trial`), so that the
        visco-elastic stress is limited to the yield stress (docs/rheology.md, "Visco-elasto-plasticity")."""
        flow = flow or {}
        trial = self.elastic_trial(C, flow.get("fields") or {})
        extra = {} if trial is None else {"elastic": trial}
        return self.approximation.viscosity(T, C, x=ufl.SpatialCoordinate(self.mesh), **flow, **extra)

    def elastic_trial(self, C: Any, fields: dict[str, Any], /) -> Any:
        """``G``, ``1 / dt_e`` and the old stress for the yield laws, with elasticity and a law that
        yields (:meth:`convection.physics.elasticity.Elasticity.trial`); else None."""
        if self.elasticity is None or not self.approximation.viscosity_law.yields:
            return None
        return self.elasticity.trial(C, self.elastic_rate, fields, self.mesh.geometry.dim)

    def elastic_load(self, T: Any, C: Any, flow: dict[str, Any] | None, v: Any, dx: Any, /) -> Any:
        """The old stress's load ``-(chi tau^n, eps(v))`` (:mod:`convection.physics.elasticity`), or None."""
        if self.elasticity is None:
            return None
        flow = flow or {}
        eta = self.maxwell_viscosity(T, C, flow)
        return self.elasticity.load(eta, C, self.elastic_rate, flow.get("fields") or {}, v, dx)

    def _dx(self) -> Any:
        # A variable viscosity (exp, quotients) would inflate UFL's quadrature degree estimate.
        metadata = {"quadrature_degree": 3 * self.degree} if self.approximation.is_variable_viscosity else {}
        return ufl.dx(domain=self.mesh, metadata=metadata), metadata

    def _mass_flux(self, u: Any, /) -> Any:
        """The continuity equation's ``div u``, or ``div(rho_r u)`` when the approximation weighs it by
        a reference density (:meth:`~convection.physics.approximation.BoussinesqApproximation.continuity_density`)."""
        rho = self.approximation.continuity_density(ufl.SpatialCoordinate(self.mesh))
        return ufl.div(u) if rho is None else ufl.div(rho * u)

    def _weak_free_slip(self, u: Any, p: Any, v: Any, q: Any, eta: Any, metadata: dict, /) -> NitscheTerms | None:
        """The Nitsche terms of free slip on the curved boundaries (continuity: ``(q, rho_r u . n)``), or None."""
        curved = weak_free_slip_boundaries(self.bcs, self.domain)
        return nitsche_free_slip(self.mesh, self.domain, curved, u, p, v, q, eta, penalty=self.nitsche_penalty,
                                 metadata=metadata, density=self.approximation.continuity_density(
                                     ufl.SpatialCoordinate(self.mesh))) if curved else None

    def _viscous(self, eta: Any, u: Any, v: Any, dx: Any, /) -> Any:
        """``(2 eta eps(u), eps(v))``; with the ALA's pressure buoyancy the compressible stress's
        ``-(2/3) eta div u I`` too, ``-(2/3) (eta div u, div v)`` (else the pressure would hold it and
        weigh it in the buoyancy)."""
        term = 2.0 * eta * ufl.inner(ufl.sym(ufl.grad(u)), ufl.sym(ufl.grad(v))) * dx
        if not self.approximation.formulation.pressure_buoyancy:
            return term
        return term - 2.0 / 3.0 * eta * ufl.div(u) * ufl.div(v) * dx

    def _pressure_block(self, p: Any, v: Any, dx: Any, /) -> Any:
        """The momentum equation's pressure term ``-(p, div v)``, with the ALA's pressure buoyancy
        ``+(c p e_up, v)`` (:meth:`~convection.physics.approximation.BoussinesqApproximation.pressure_buoyancy`)."""
        x = ufl.SpatialCoordinate(self.mesh)
        c = self.approximation.pressure_buoyancy(x)
        term = -ufl.inner(p, ufl.div(v)) * dx
        if c is None:
            return term
        return term + ufl.inner(self.approximation.gravity.along_up(c * p, x), v) * dx

    def pressure_column(self, p: Any, /) -> Any:
        """The compiled linear form ``v -> `` the momentum equation's pressure term of the pressure ``p``
        (:class:`convection.solvers.stokes.nullspace.PressureMode`). Collective."""
        v, (dx, metadata) = ufl.TestFunction(self.V), self._dx()
        column = self._pressure_block(p, v, dx)
        nitsche = self._weak_free_slip(ufl.TrialFunction(self.V), p, v, ufl.TestFunction(self.Q), 1.0, metadata)
        if nitsche is not None:  # the weak free slip's (p, v . n), as in the operator
            column = column + nitsche.a_up
        return dolfinx.fem.form(column)

    def component_space(self, axis: int, /) -> tuple[dolfinx.fem.FunctionSpace, np.ndarray]:
        """``V.sub(axis).collapse()`` (made once): the scalar space and its map into ``V``'s
        unrolled local dofs, shape=(owned + ghosts,). Collective."""
        cache = self.__dict__.setdefault("_component_spaces", {})
        if axis not in cache:
            W, W_to_V = self.V.sub(axis).collapse()
            cache[axis] = (W, np.asarray(W_to_V, dtype=np.int64))
        return cache[axis]

    def nonlinear_forms(self, T: Any, C: Any, u: dolfinx.fem.Function, p: dolfinx.fem.Function, /, *,
                        fields: dict[str, Any] | None, pressure_block: bool) -> tuple[Any, Any]:
        """The residual ``F(u, p)`` (a block linear form in ``(v, q)``) and its Jacobian (UFL's
        derivative with respect to ``u`` and ``p``, a 2 x 2 block form) for Newton's method, with
        the viscosity evaluated at the Functions ``u``, ``p`` (the iterate). Collective (compiles).

        ``F = a(eta(u, p); (u, p), (v, q)) - L(v, q)``: the Picard operator of :meth:`forms`
        applied to the iterate, so both methods solve the same equations."""
        v, q = ufl.TestFunction(self.V), ufl.TestFunction(self.Q)
        du, dp = ufl.TrialFunction(self.V), ufl.TrialFunction(self.Q)
        eta = self.viscosity(T, C, {"u": u, "p": p, "fields": fields or {}})
        f = self.approximation.buoyancy(T, C, self.mesh.geometry.dim, x=ufl.SpatialCoordinate(self.mesh))
        dx, metadata = self._dx()
        F_u = self._viscous(eta, u, v, dx) + self._pressure_block(p, v, dx) - ufl.inner(f, v) * dx
        F_p = -ufl.inner(self._mass_flux(u), q) * dx
        elastic = self.elastic_load(T, C, {"u": u, "p": p, "fields": fields or {}}, v, dx)
        if elastic is not None:
            F_u = F_u - elastic
        nitsche = self._weak_free_slip(u, p, v, q, eta, metadata)
        if nitsche is not None:
            F_u = F_u + nitsche.a_uu + nitsche.a_up
            F_p = F_p + nitsche.a_pu
        if self.surface is not None:
            F_u = F_u - self.surface.rhs(self.mesh, self.domain, v, metadata=metadata)
            stabilisation = self.surface.lhs(self.mesh, self.domain, u, v, self.surface_dt, metadata=metadata)
            if stabilisation is not None:
                F_u = F_u + stabilisation
        J = [[ufl.derivative(F_u, u, du), ufl.derivative(F_u, p, dp)],
             [ufl.derivative(F_p, u, du), None]]
        if pressure_block:
            zero = dolfinx.fem.Constant(self.mesh, PETSc.ScalarType(0.0))
            J[1][1] = zero * ufl.inner(dp, q) * dx
        return dolfinx.fem.form([F_u, F_p]), dolfinx.fem.form(J)

    def forms(self, T: Any, C: Any, /, *, pressure_block: bool, preconditioner: bool, weights: bool = False,
              semi_implicit: SemiImplicitBuoyancy | None = None, flow: dict[str, Any] | None = None) -> StokesForms:
        """The forms for temperature ``T`` and composition ``C`` (see
        :meth:`convection.solvers.stokes.solver.StokesSolver.solve`); a semi-implicit buoyancy's term replaces its
        earlier one. Collective (compiles forms).

        Args:
            pressure_block: add a zero pressure-pressure block (for a pinned pressure dof).
            preconditioner: also build the preconditioning matrix's form ``a_pc`` (and ``weights``: ``a_weights``).
            semi_implicit: the buoyancy predictor whose operator term to build, or None.
            flow: the iterate ``{"u", "p", "fields"}`` the viscosity laws read (Picard: the
                operator of the viscosity at the iterate), or None.
        """
        u, v = ufl.TrialFunction(self.V), ufl.TestFunction(self.V)
        p, q = ufl.TrialFunction(self.Q), ufl.TestFunction(self.Q)
        eta = self.viscosity(T, C, flow)
        f = self.approximation.buoyancy(T, C, self.mesh.geometry.dim, x=ufl.SpatialCoordinate(self.mesh))
        zero = dolfinx.fem.Constant(self.mesh, PETSc.ScalarType(0.0))
        dx, metadata = self._dx()
        a = [
            [self._viscous(eta, u, v, dx), self._pressure_block(p, v, dx)],
            [-ufl.inner(self._mass_flux(u), q) * dx, None],
        ]
        nitsche = self._weak_free_slip(u, p, v, q, eta, metadata)
        if nitsche is not None:
            a[0][0] += nitsche.a_uu
            a[0][1] += nitsche.a_up
            a[1][0] += nitsche.a_pu
        if self.surface is not None:
            stabilisation = self.surface.lhs(self.mesh, self.domain, u, v, self.surface_dt, metadata=metadata)
            if stabilisation is not None:
                a[0][0] += stabilisation
        if pressure_block:
            a[1][1] = zero * ufl.inner(p, q) * dx  # a zero block to hold the pinned dof's diagonal
        a_form = dolfinx.fem.form(a)
        a_lift = a_form
        a_si = None
        a_si_component = None
        if semi_implicit is not None:
            # Assembled on its own into a copy of the fixed operator every solve; the lifting of
            # the boundary values uses the whole operator.
            term = semi_implicit.form(T, C, u, v, dx)
            a_si = dolfinx.fem.form(term)
            axis = semi_implicit.axis
            if axis is not None:
                W, W_to_V = self.component_space(axis)
                scalar = semi_implicit.component_form(ufl.TrialFunction(W), ufl.TestFunction(W), dx)
                a_si_component = (axis, W, W_to_V, dolfinx.fem.form(scalar))
            a_lift = dolfinx.fem.form([[a[0][0] + term, a[0][1]], [a[1][0], a[1][1]]])
        # The zero-Constant term keeps the form non-empty when the buoyancy simplifies to 0.
        zero_vec = dolfinx.fem.Constant(self.mesh, np.zeros(self.mesh.geometry.dim))
        L_u = ufl.inner(f, v) * dx + ufl.inner(zero_vec, v) * dx
        if self.surface is not None:
            L_u = L_u + self.surface.rhs(self.mesh, self.domain, v, metadata=metadata)
        elastic = self.elastic_load(T, C, flow, v, dx)
        if elastic is not None:
            L_u = L_u + elastic
        L = dolfinx.fem.form([L_u, ufl.inner(zero, q) * dx])
        a_pc = None
        if preconditioner:
            # -M_p / eta approximates the Schur complement S = -B A^-1 B^T (PETSc's sign).
            a_pc = dolfinx.fem.form([[a[0][0], a[0][1]], [a[1][0], -ufl.inner(p, q) / eta * dx]])
        a_weights = weights_form(self.component_space(0)[0], eta, dx) if preconditioner and weights else None
        return StokesForms(a_form, L, a_lift, a_pc, a_si, a_si_component, a_weights)
