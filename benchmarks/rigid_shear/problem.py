"""The rigid-shear problem of Gassmöller, Lokavarapu, Bangerth & Puckett (2019, GJI): the analytical
solution, a P2/P1 Taylor-Hood Stokes solve on triangles with the particle density as buoyancy, and
the L2 errors.

On the unit square, viscosity 1, free slip (``u . n = 0``, no tangential stress) on all four sides:

    u   = ( sin(pi x) cos(pi y), -cos(pi x) sin(pi y) )
    p   = 2 pi cos(pi x) cos(pi y)                      (zero mean)
    rho = sin(pi x) sin(pi y) + 2

solve ``-div(2 eps(u)) + grad p = rho g``, ``div u = 0`` with the gravity
``g = (0, f / rho)``, ``f = -4 pi^2 cos(pi x) sin(pi y)``: with the exact density the right-hand
side is ``(0, f)`` and (u, p) above is the solution. The density is steady along the flow
(``u . grad rho = 0``), so the same u, p, rho solve the time-dependent problem in which the density
is carried by the particles and the flow moves them.

The discrete problem replaces ``rho`` by the field ``rho_h`` interpolated from the particles
(DG0, DG1 or DG2), keeps ``g`` analytical (as ASPECT's gravity plugin does) and pins the pressure
at the origin, then shifts it to zero mean. The matrix does not depend on the density, so it is
factorised once per mesh (MUMPS LU) and every further solve costs one right-hand side.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import ufl
from mpi4py import MPI
from petsc4py import PETSc

import dolfinx.fem
import dolfinx.fem.petsc
import dolfinx.mesh

from dolfinx.fem import form

from fembase.dolfinx_compat import (assemble_block_matrix, assemble_block_vector, create_block_matrix,
                                    create_block_vector, element_degree, function_space)

__all__ = ["Errors", "StokesSolver", "exact_density", "unit_square"]

QUADRATURE_DEGREE = 8
"""Quadrature degree of the right-hand side and of the error integrals (ASPECT: Gauss with
velocity degree + 2 points per direction, exact to degree 7 on quads)."""


def exact_density(x: npt.NDArray[np.float64], /) -> npt.NDArray[np.float64]:
    """``rho`` at points shape=(m, gdim) -> shape=(m,)."""
    return np.sin(np.pi * x[:, 0]) * np.sin(np.pi * x[:, 1]) + 2.0


def _exact_ufl(mesh: dolfinx.mesh.Mesh) -> tuple[ufl.core.expr.Expr, ufl.core.expr.Expr, ufl.core.expr.Expr,
                                                 ufl.core.expr.Expr]:
    """(u, p, rho, f) of the analytical solution as UFL expressions of the position."""
    x = ufl.SpatialCoordinate(mesh)
    sx, cx = ufl.sin(ufl.pi * x[0]), ufl.cos(ufl.pi * x[0])
    sy, cy = ufl.sin(ufl.pi * x[1]), ufl.cos(ufl.pi * x[1])
    u = ufl.as_vector((sx * cy, -cx * sy))
    p = 2.0 * ufl.pi * cx * cy
    rho = sx * sy + 2.0
    f = -4.0 * ufl.pi ** 2 * cx * sy
    return u, p, rho, f


def unit_square(comm: MPI.Comm, n: int, /) -> dolfinx.mesh.Mesh:
    """``n x n`` squares, each cut into two triangles (cell size h = 1/n)."""
    return dolfinx.mesh.create_unit_square(comm, n, n, dolfinx.mesh.CellType.triangle)


@dataclass(frozen=True)
class Errors:
    """L2 errors against the analytical solution.

    Attributes:
        u: ``||u - u_h||``.
        p: ``||p - p_h||`` (``p_h`` shifted to zero mean).
        rho: ``||rho - rho_h||`` (0 for the exact density).
    """

    u: float
    p: float
    rho: float


def _free_slip(V: dolfinx.fem.FunctionSpace) -> list[dolfinx.fem.DirichletBC]:
    """``u_x = 0`` on x = 0, 1 and ``u_y = 0`` on y = 0, 1."""
    mesh = V.mesh
    fdim = mesh.topology.dim - 1
    bcs = []
    for axis in (0, 1):
        facets = dolfinx.mesh.locate_entities_boundary(
            mesh, fdim, lambda x, a=axis: np.isclose(x[a], 0.0) | np.isclose(x[a], 1.0))
        dofs = dolfinx.fem.locate_dofs_topological(V.sub(axis), fdim, facets)
        bcs.append(dolfinx.fem.dirichletbc(PETSc.ScalarType(0.0), dofs, V.sub(axis)))
    return bcs


def _pin_origin(Q: dolfinx.fem.FunctionSpace) -> dolfinx.fem.DirichletBC:
    """``p = 0`` at the vertex (0, 0) (fixes the constant; the result is shifted to zero mean)."""
    dofs = dolfinx.fem.locate_dofs_geometrical(Q, lambda x: np.isclose(x[0], 0.0) & np.isclose(x[1], 0.0))
    return dolfinx.fem.dirichletbc(PETSc.ScalarType(0.0), dofs, Q)


class StokesSolver:
    """P2/P1 Stokes solve of the rigid-shear problem on one mesh, for densities in DG0..DG2.

    Attributes:
        mesh: The mesh.
        u: Velocity of the last solve (P2 vector).
        p: Pressure of the last solve (P1, zero mean).
    """

    def __init__(self, mesh: dolfinx.mesh.Mesh, /) -> None:
        self.mesh = mesh
        self.V = function_space(mesh, "Lagrange", 2, shape=(mesh.geometry.dim,))
        self.Q = function_space(mesh, "Lagrange", 1)
        self.u = dolfinx.fem.Function(self.V)
        self.p = dolfinx.fem.Function(self.Q)
        self._exact = _exact_ufl(mesh)
        u, v = ufl.TrialFunction(self.V), ufl.TestFunction(self.V)
        p, q = ufl.TrialFunction(self.Q), ufl.TestFunction(self.Q)
        zero = dolfinx.fem.Constant(mesh, PETSc.ScalarType(0.0))
        self._a = form([[2.0 * ufl.inner(ufl.sym(ufl.grad(u)), ufl.sym(ufl.grad(v))) * ufl.dx,
                         -p * ufl.div(v) * ufl.dx],
                        [-q * ufl.div(u) * ufl.dx, zero * p * q * ufl.dx]])
        self._L1 = form(zero * q * ufl.dx)
        self._bcs = [*_free_slip(self.V), _pin_origin(self.Q)]
        A = create_block_matrix(self._a)
        assemble_block_matrix(A, self._a, bcs=self._bcs)
        A.assemble()
        self._ksp = PETSc.KSP().create(mesh.comm)
        self._ksp.setOperators(A)
        self._ksp.setType("preonly")
        pc = self._ksp.getPC()
        pc.setType("lu")
        pc.setFactorSolverType("mumps")
        self._A = A
        self._b = create_block_vector([form(ufl.inner(zero, v[0]) * ufl.dx), self._L1])
        self._x = self._A.createVecRight()
        self._rhs: dict[int, tuple[dolfinx.fem.Function | None, dolfinx.fem.Form]] = {}
        self._p_integral = form(self.p * ufl.dx)
        self._error_forms: dict[int | None, tuple[dolfinx.fem.Form, ...]] = {}
        self._area = self._integral(form(dolfinx.fem.Constant(mesh, PETSc.ScalarType(1.0)) * ufl.dx))

    def _rhs_form(self, degree: int | None) -> tuple[dolfinx.fem.Function | None, dolfinx.fem.Form]:
        """(density Function in DG ``degree`` or None for the exact density, compiled ``rho g . v``)."""
        if degree not in self._rhs:
            _, _, rho_exact, f = self._exact
            v = ufl.TestFunction(self.V)
            rho = None if degree is None else dolfinx.fem.Function(function_space(self.mesh, "DG", degree))
            buoyancy = f if rho is None else rho * f / rho_exact
            dx = ufl.dx(metadata={"quadrature_degree": QUADRATURE_DEGREE})
            self._rhs[degree] = (rho, form(buoyancy * v[1] * dx))
        return self._rhs[degree]

    def solve(self, density: dolfinx.fem.Function | None, /) -> None:
        """Solve with the buoyancy ``density * g`` (a scalar DG Function on this mesh; None: the
        exact density); fills :attr:`u` and :attr:`p` (collective)."""
        degree = None if density is None else element_degree(density.function_space)
        rho, L0 = self._rhs_form(degree)
        if rho is not None:
            rho.interpolate(density)
        with self._b.localForm() as local:
            local.set(0.0)
        assemble_block_vector(self._b, [L0, self._L1], self._a, bcs=self._bcs)
        self._ksp.solve(self._b, self._x)
        if self._ksp.getConvergedReason() < 0:
            raise RuntimeError(f"Stokes solve failed: reason {self._ksp.getConvergedReason()}")
        self._split()

    def _split(self) -> None:
        """Copy the block solution into :attr:`u` and :attr:`p` and shift p to zero mean."""
        offset = self.V.dofmap.index_map.size_local * self.V.dofmap.index_map_bs
        n_p = self.Q.dofmap.index_map.size_local
        x = self._x.getArray(readonly=True)
        self.u.x.array[:offset] = x[:offset]
        self.p.x.array[:n_p] = x[offset:offset + n_p]
        self.u.x.scatter_forward()
        self.p.x.scatter_forward()
        mean = self._integral(self._p_integral) / self._area
        self.p.x.array[:] -= mean

    def _integral(self, compiled: dolfinx.fem.Form) -> float:
        """The integral of a compiled scalar form over the whole mesh (collective)."""
        return float(self.mesh.comm.allreduce(dolfinx.fem.assemble_scalar(compiled), op=MPI.SUM))

    def errors(self, density: dolfinx.fem.Function | None, /) -> Errors:
        """L2 errors of the last solve and of ``density`` (None: the exact density, error 0)
        (collective)."""
        degree = None if density is None else element_degree(density.function_space)
        rho, _ = self._rhs_form(degree)
        if degree not in self._error_forms:
            u_ex, p_ex, rho_ex, _ = self._exact
            dx = ufl.dx(metadata={"quadrature_degree": QUADRATURE_DEGREE})
            self._error_forms[degree] = (form(ufl.inner(self.u - u_ex, self.u - u_ex) * dx),
                                         form((self.p - p_ex) ** 2 * dx),
                                         None if rho is None else form((rho - rho_ex) ** 2 * dx))
        if rho is not None:
            rho.interpolate(density)
        squares = [0.0 if f is None else self._integral(f) for f in self._error_forms[degree]]
        return Errors(*(float(np.sqrt(s)) for s in squares))
