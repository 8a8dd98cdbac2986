"""Experiment only: Schur-complement variants for the 1e3 viscosity layer (log/NOTES.md,
"Iterations in h with the 1e3 layer"). Runs ``stokes3d.py`` with its arguments after patching the
Stokes solver's preconditioning form; it relies on internals of ``StokesSolver`` and its components
(:mod:`convection.solvers.stokes.forms`, :mod:`convection.solvers.stokes.linear`) of this commit and is not part of
the package.

- ``SCHUR_SCALE=s``: the Schur block ``-s M_p / eta`` instead of ``-M_p / eta``.
- ``SCHUR_W=arith|harm|geo|max|min``: the Schur block ``-M_p w`` with ``w = 1 / eta_node``, eta_node
  the arithmetic / harmonic / geometric mean, the max or the min of the viscosity of the cells
  around each pressure node (P1).
- w-BFBt (PETSc's LSC form) as a Python PC on the pressure block:
  ``--petsc-options '{"fieldsplit_p_pc_type": "python", "fieldsplit_p_pc_python_type":
  "schur_variants.WBFBt"}'`` (W = diag(A)^-1; ``BFBT_W=sqrt_eta``: W = diag(M_u(sqrt(eta)))^-1;
  add ``"fieldsplit_p_bfbt_ksp_type": "cg", "fieldsplit_p_bfbt_ksp_rtol": 1e-10`` for exact inner
  solves; default one BoomerAMG V-cycle). Serial only.

Example: ``SCHUR_W=geo python -m benchmarks.performance.schur_variants --viscosity layer --cells 8
--solver iterative --steps 3``.
"""

from __future__ import annotations

import os
import runpy
import sys

import numpy as np
import ufl
from petsc4py import PETSc

import dolfinx.fem
import dolfinx.fem.petsc

from convection.solvers.stokes import forms as stokes_forms, solver as stokes
from fembase.dolfinx_compat import cell_dofmap, function_space, interpolation_points

sys.modules.setdefault("schur_variants", sys.modules[__name__])  # for pc_python_type
_SOLVERS: list = []  # StokesSolver instances; the last is the one being set up


class WBFBt:
    """y = -(B W B^T)^-1 (B W A W B^T) (B W B^T)^-1 x (petsc4py Python PC context)."""

    def __init__(self) -> None:
        self.ksp = None

    def setUp(self, pc: PETSc.PC) -> None:
        solver = _SOLVERS[-1]
        system = solver.linear_system
        is_u, is_p = system.index_sets()
        self.A00 = system.A.createSubMatrix(is_u, is_u)
        self.B = system.A.createSubMatrix(is_p, is_u)
        self.Bt = system.A.createSubMatrix(is_u, is_p)
        d = self.A00.getDiagonal()
        if os.environ.get("BFBT_W") == "sqrt_eta":
            T, C = solver._forms_key
            eta = solver.approximation.viscosity(T, C)
            u, v = ufl.TrialFunction(solver.V), ufl.TestFunction(solver.V)
            dx = ufl.dx(domain=solver.mesh, metadata={"quadrature_degree": 6})
            M = dolfinx.fem.petsc.assemble_matrix(dolfinx.fem.form(ufl.sqrt(eta) * ufl.inner(u, v) * dx), bcs=system.bcs)
            M.assemble()
            d.array[:] = M.getDiagonal().array  # serial: the velocity block keeps V's numbering
            M.destroy()
        d.reciprocal()
        self.w = d
        scaled = self.Bt.copy()
        scaled.diagonalScale(L=d)
        self.L = self.B.matMult(scaled)
        ones = self.L.createVecLeft()
        ones.set(1.0)
        ones.normalize()
        self.ns = PETSc.NullSpace().create(vectors=[ones], comm=self.L.comm)
        self.L.setNullSpace(self.ns)
        if self.ksp is None:
            self.ksp = PETSc.KSP().create(self.L.comm)
            self.ksp.setOptionsPrefix((pc.getOptionsPrefix() or "") + "bfbt_")
            self.ksp.setType("preonly")
            self.ksp.getPC().setType("hypre")
            self.ksp.setFromOptions()
        self.ksp.setOperators(self.L)
        self.ksp.setUp()
        self.t1, self.t2 = self.L.createVecRight(), self.L.createVecRight()
        self.u1, self.u2 = self.A00.createVecRight(), self.A00.createVecRight()

    def _solve_l(self, b: PETSc.Vec, x: PETSc.Vec) -> None:
        self.ns.remove(b)
        self.ksp.solve(b, x)
        self.ns.remove(x)

    def apply(self, pc: PETSc.PC, x: PETSc.Vec, y: PETSc.Vec) -> None:
        b = x.copy()
        self._solve_l(b, self.t1)
        self.Bt.mult(self.t1, self.u1)
        self.u1.pointwiseMult(self.u1, self.w)
        self.A00.mult(self.u1, self.u2)
        self.u2.pointwiseMult(self.u2, self.w)
        self.B.mult(self.u2, self.t2)
        self._solve_l(self.t2, y)
        y.scale(-1.0)
        b.destroy()


def _nodal_weight(solver, eta, mode: str) -> dolfinx.fem.Function:
    """1 / (the chosen mean of the cell viscosities around each P1 pressure node)."""
    DG0 = function_space(solver.mesh, "DG", 0)
    cell_eta = dolfinx.fem.Function(DG0)
    cell_eta.interpolate(dolfinx.fem.Expression(eta, interpolation_points(DG0)))
    ncell = solver.mesh.topology.index_map(3).size_local
    dofs = cell_dofmap(solver.Q)[:ncell].ravel()
    n = solver.Q.dofmap.index_map.size_local + solver.Q.dofmap.index_map.num_ghosts
    values = np.repeat(cell_eta.x.array[:ncell], 4)
    count = np.bincount(dofs, minlength=n)
    if mode == "arith":
        node = np.bincount(dofs, weights=values, minlength=n) / count
    elif mode == "harm":
        node = count / np.bincount(dofs, weights=1.0 / values, minlength=n)
    elif mode == "geo":
        node = np.exp(np.bincount(dofs, weights=np.log(values), minlength=n) / count)
    elif mode == "max":
        node = np.zeros(n)
        np.maximum.at(node, dofs, values)
    elif mode == "min":
        node = np.full(n, np.inf)
        np.minimum.at(node, dofs, values)
    else:
        raise ValueError(f"SCHUR_W={mode!r}: valid arith, harm, geo, max, min")
    w = dolfinx.fem.Function(solver.Q)
    w.x.array[:] = 1.0 / node
    return w


_prepare = stokes.StokesSolver.prepare
_build_forms = stokes_forms.StokesDiscretisation.forms


def _record(self, T, C=None, /):
    if not _SOLVERS or _SOLVERS[-1] is not self:
        _SOLVERS.append(self)
    return _prepare(self, T, C)


def _forms(self, T, C, /, **kwargs):
    forms = _build_forms(self, T, C, **kwargs)
    scale, mode = os.environ.get("SCHUR_SCALE"), os.environ.get("SCHUR_W")
    if forms.a_pc is None or not (scale or mode):
        return forms
    eta = self.approximation.viscosity(T, C)
    u, v = ufl.TrialFunction(self.V), ufl.TestFunction(self.V)
    p, q = ufl.TrialFunction(self.Q), ufl.TestFunction(self.Q)
    dx = ufl.dx(domain=self.mesh, metadata={"quadrature_degree": 3 * self.degree})
    a00 = 2.0 * eta * ufl.inner(ufl.sym(ufl.grad(u)), ufl.sym(ufl.grad(v))) * dx
    if scale:
        schur = -float(scale) * ufl.inner(p, q) / eta * dx
    else:
        self._schur_weight = _nodal_weight(self, eta, mode)
        schur = -ufl.inner(p, q) * self._schur_weight * dx
    return forms._replace(a_pc=dolfinx.fem.form([[a00, None], [None, schur]]))


stokes.StokesSolver.prepare = _record
stokes_forms.StokesDiscretisation.forms = _forms

if __name__ == "__main__":
    sys.argv = ["stokes3d.py"] + sys.argv[1:]
    runpy.run_module("benchmarks.performance.stokes3d", run_name="__main__")
