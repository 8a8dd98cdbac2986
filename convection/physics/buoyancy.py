"""Semi-implicit buoyancy: the body force predicted along the flow, against the "drunken sailor".

With the buoyancy of the start of a step, a dense interface under a large compositional Rayleigh
number overshoots: the velocity answers the density at once, the density follows the velocity for
the whole step, and a step longer than about ``1 / (Rb h)`` makes the interface swing from one
side to the other with growing amplitude (the "drunken sailor" instability of Kaus, Mühlhaus &
May 2010, Phys. Earth Planet. Inter. 181, 12-20). Their remedy, applied here to the whole domain:
predict the density a fraction ``theta`` into the coming step,

    rho(t + theta dt) ~ rho(t) - theta dt  u . grad rho,      rho = Ra T - sum_i Rb_i C_i,

and move the velocity-dependent part to the left of the momentum equation. Of that term,
``theta dt ((u . grad rho) e_up, v)``, only the part that damps is kept:

    theta dt (max(d rho / d up, 0) (u . e_up) (e_up . v))

a restoring stiffness on vertical flow through a stable stratification (dense below: ``rho``
grows upwards; the term opposes flow across it) and nothing elsewhere. An unstable stratification
(hot or light below, van Keken's Rayleigh-Taylor) grows physically and is resolved by the CFL step;
its term is an anti-stiffness of size ``theta dt Ra |d T / d z|`` that can make the operator
indefinite once the step is large against the boundary layers' response. The kept term is
symmetric positive semi-definite for any step and vanishes with ``dt`` (first-order consistent).
(Measured on the 3D thick layer at 8^3, 45-50 CFL steps to t = 0.0015: the full term ran as
stably, vrms within ~15 % of the kept one's, 32-53 FGMRES iterations against 32-46.) It changes
with the fields every step; the iterative solver keeps its preconditioner (built without the
term) while the viscosity is constant.

Material fractions held in discontinuous spaces (the cell averages of particles) have their
gradient on the facets; they enter the term through their lumped L2 projection onto continuous P1,
``c_i = int(phi_i C) / int(phi_i)``, refreshed before every solve, which keeps the matrix's
sparsity that of the cell integrals. The temperature and continuous fractions enter as they are.
``dt`` is the step about to be taken; a run passes the step just taken (the next one is chosen from
the new velocity), and ``dt = 0`` gives the explicit buoyancy.

The velocity so solved is the flow at ``t + theta dt``, and the material carries its density with
it: with ``theta > 0`` the particles and the advected material fields move in this velocity over
the step (:meth:`convection.model.model.Model.step`), not in the velocity extrapolated to the
step's end. For an interface relaxing with time scale ``tau`` (height ``h`` with ``h' = -h / tau``)
the step then multiplies ``h`` by ``(tau - (1 - theta) dt) / (tau + theta dt)``: below 1 in size
for any step when ``theta >= 1/2``, without sign changes for ``theta = 1`` (``theta = 1/2`` is the
midpoint rule, second order). With the extrapolated velocity ``u* = 2 u^n - u^(n-1)`` the
two-step recursion is unstable once ``dt > 2 tau`` for ``theta = 1/2`` and only neutrally stable
for ``theta = 1`` as ``dt / tau`` grows (measured on the 2D thick layer at the CFL step:
vrms jumped by 1.9 from step to step with ``theta = 0.5``, 0.25 now). The temperature keeps its
BDF2 step with the extrapolated velocity.
"""

from __future__ import annotations

from typing import Any

import dolfinx
import dolfinx.fem.petsc
import numpy as np
import ufl
import ufl.algorithms
from petsc4py import PETSc

from convection.physics.approximation import BoussinesqApproximation, fractions
from fembase.dolfinx_compat import create_vector, function_space, is_discontinuous


def _is_discontinuous(expr: Any) -> bool:
    """True when a UFL expression depends on a coefficient of a discontinuous (or "Real") space."""
    if isinstance(expr, (int, float)):
        return False
    return any(is_discontinuous(c.ufl_element()) for c in ufl.algorithms.extract_coefficients(expr))


class LumpedProjection:
    """Continuous P1 field ``c`` with ``c_i = int(phi_i f) dx / int(phi_i) dx`` of an expression ``f``.

    Args:
        mesh: the mesh.
        expr: scalar UFL expression (e.g. a DG0 Function).

    Attributes:
        function: the projected P1 Function (refreshed by :meth:`update`).
    """

    def __init__(self, mesh: dolfinx.mesh.Mesh, expr: Any) -> None:
        space = function_space(mesh, "Lagrange", 1)
        self.function = dolfinx.fem.Function(space, name="projection")
        phi = ufl.TestFunction(space)
        self._rhs = dolfinx.fem.form(ufl.inner(expr, phi) * ufl.dx)
        mass = dolfinx.fem.petsc.assemble_vector(dolfinx.fem.form(phi * ufl.dx))
        mass.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        self._mass = mass.array.copy()
        mass.destroy()
        self._b = create_vector(self._rhs)

    def update(self) -> None:
        """Project the expression's current values. Collective."""
        with self._b.localForm() as local:
            local.set(0.0)
        dolfinx.fem.petsc.assemble_vector(self._b, self._rhs)
        self._b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        n = self._mass.size
        self.function.x.array[:n] = self._b.array / self._mass
        self.function.x.scatter_forward()

    def destroy(self) -> None:
        self._b.destroy()


class SemiImplicitBuoyancy:
    """The operator term ``theta dt (max(d rho / d up, 0) (u . e_up) (e_up . v))`` (module docstring).

    Args:
        mesh: the mesh.
        approximation: physics (Rayleigh numbers and gravity direction).
        theta: fraction of the step at which the density is predicted, ``0 < theta <= 1``
            (Kaus et al. use 0.5-1).

    Attributes:
        dt: the step in the term (a Constant, set by :meth:`update`).
    """

    def __init__(self, mesh: dolfinx.mesh.Mesh, approximation: BoussinesqApproximation, theta: float) -> None:
        if not 0.0 < theta <= 1.0:
            raise ValueError(f"the semi-implicit buoyancy theta must be in (0, 1], got {theta}")
        self.mesh = mesh
        self.approximation = approximation
        self.theta = float(theta)
        self.dt = dolfinx.fem.Constant(mesh, PETSc.ScalarType(0.0))
        self._projections: list[LumpedProjection] = []
        self._coefficient: Any = None  # theta dt max(d rho / d up, 0) of the last form()

    def form(self, T: Any, C: Any, u: Any, v: Any, dx: Any) -> Any:
        """The bilinear term (UFL) for temperature ``T`` and fractions ``C`` (see
        :meth:`convection.solvers.stokes.solver.StokesSolver.solve`); replaces earlier projections."""
        self.destroy()
        continuous = []
        for c in fractions(C):
            if _is_discontinuous(c):
                projection = LumpedProjection(self.mesh, c)
                self._projections.append(projection)
                continuous.append(projection.function)
            else:
                continuous.append(c)
        if C is None or not continuous:
            C_continuous = None
        else:
            C_continuous = tuple(continuous) if isinstance(C, (tuple, list)) else continuous[0]
        rho = self.approximation.density(T, C_continuous)
        e_up = self.approximation.up(ufl.SpatialCoordinate(self.mesh))
        stable = ufl.max_value(ufl.dot(ufl.grad(rho), e_up), 0.0)
        self._coefficient = self.theta * self.dt * stable
        return self._coefficient * ufl.dot(u, e_up) * ufl.dot(v, e_up) * dx

    @property
    def axis(self) -> int | None:
        """The coordinate axis ``k`` with ``e_up = e_k`` everywhere (boxes: the last), or None
        (shells: ``e_up`` turns)."""
        return self.approximation.gravity.up_axis(self.mesh.geometry.dim)

    def component_form(self, u: Any, v: Any, dx: Any) -> Any:
        """The term on the component ``k = axis`` alone: ``theta dt max(d rho / d up, 0) u_k v_k``
        for scalar trial and test functions ``u``, ``v`` (the coefficient of the last :meth:`form`,
        so the two forms' element matrices agree entry by entry)."""
        if self.axis is None or self._coefficient is None:
            raise ValueError("the semi-implicit term has a single component only on a box, after form()")
        return self._coefficient * u * v * dx

    def coefficients(self) -> list[Any]:
        """The coefficients (Functions: temperature, projected fractions) of the term of the last
        :meth:`form`, in UFL's order; empty before."""
        if self._coefficient is None:
            return []
        return list(ufl.algorithms.extract_coefficients(self._coefficient))

    def update(self, dt: float) -> None:
        """Set the step and refresh the projected fractions. Collective."""
        if not dt >= 0.0 or not np.isfinite(dt):
            raise ValueError(f"the semi-implicit buoyancy needs a finite step >= 0, got {dt}")
        self.dt.value = dt
        for projection in self._projections:
            projection.update()

    def destroy(self) -> None:
        for projection in self._projections:
            projection.destroy()
        self._projections = []
