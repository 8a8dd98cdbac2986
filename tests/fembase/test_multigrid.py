"""Prolongation between nested Lagrange spaces (fembase/multigrid.py) and the geometric multigrid it
makes: P reproduces the fine interpolant of any coarse function exactly, on every rank count, and
PCMG with it keeps the iteration count of a P2 elasticity-type operator (the Stokes velocity
block) constant under refinement."""

from __future__ import annotations

import numpy as np
import pytest
import ufl
from mpi4py import MPI
from petsc4py import PETSc

import dolfinx.fem
import dolfinx.fem.petsc
import dolfinx.mesh

from fembase.dolfinx_compat import function_space, refine_keeping_partition
from fembase.multigrid import apply, prolongation


def _unit(comm: MPI.Comm, dim: int, n: int) -> dolfinx.mesh.Mesh:
    return dolfinx.mesh.create_unit_square(comm, n, n) if dim == 2 else dolfinx.mesh.create_unit_cube(comm, n, n, n)


def _polynomial(degree: int, components: int | None):
    """A polynomial of full degree ``degree`` (vector: one multiple per component)."""
    def q(x):
        v = 1.0 + x[0] - 2.0 * x[1] + x[-1] / 3.0
        if degree == 2:
            v = v + x[0] * x[1] + 0.5 * x[0] ** 2 - x[-1] ** 2
        return v if components is None else np.stack([(k + 1.0) * v for k in range(components)])
    return q


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("degree, vector", [(1, False), (2, True)])
def test_prolongation_is_exact_on_the_coarse_space(world, dim, degree, vector):
    """Collective: P u_coarse equals the fine interpolant of the same function to rounding (the coarse
    space is a subspace of the fine one), for P1 scalars and P2 vectors, 2D and 3D, any rank count;
    every row sums to one."""
    comm = world
    coarse = _unit(comm, dim, 4 if dim == 2 else 3)
    fine = refine_keeping_partition(coarse)
    shape = (dim,) if vector else None
    Vc = function_space(coarse, "Lagrange", degree, shape=shape)
    Vf = function_space(fine, "Lagrange", degree, shape=shape)
    P = prolongation(Vc, Vf)
    bs = dim if vector else 1
    assert P.getSize() == (Vf.dofmap.index_map.size_global * bs, Vc.dofmap.index_map.size_global * bs)
    q = _polynomial(degree, dim if vector else None)
    uc, uf = dolfinx.fem.Function(Vc), dolfinx.fem.Function(Vf)
    uc.interpolate(q)
    uf.interpolate(q)
    y = apply(P, uc.x.array)
    error = comm.allreduce(float(np.max(np.abs(y - uf.x.array[:y.size]), initial=0.0)), op=MPI.MAX)
    assert error < 1e-12
    # every row is a partition of unity (the constants are in the coarse space)
    y = apply(P, np.ones(uc.x.array.size))
    assert comm.allreduce(float(np.max(np.abs(y - 1.0), initial=0.0)), op=MPI.MAX) < 1e-13
    P.destroy()


def test_prolongation_refuses_different_elements():
    mesh = _unit(MPI.COMM_WORLD, 2, 2)
    with pytest.raises(ValueError, match="different elements"):
        prolongation(function_space(mesh, "Lagrange", 1), function_space(refine_keeping_partition(mesh), "Lagrange", 2))


def _multigrid_iterations(comm: MPI.Comm, levels: int) -> int:
    """CG + PCMG (Galerkin coarse operators, Chebyshev/Jacobi smoothing, coarse LU) on
    2 eps(u):eps(v) with P2 on the unit square refined ``levels`` times from 4 x 4, u = 0 on the
    boundary; rtol 1e-8."""
    meshes = [_unit(comm, 2, 4)]
    for _ in range(levels):
        meshes.append(refine_keeping_partition(meshes[-1]))
    spaces = [function_space(m, "Lagrange", 2, shape=(2,)) for m in meshes]
    V, mesh = spaces[-1], meshes[-1]
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    x = ufl.SpatialCoordinate(mesh)
    a = dolfinx.fem.form(2.0 * ufl.inner(ufl.sym(ufl.grad(u)), ufl.sym(ufl.grad(v))) * ufl.dx)
    L = dolfinx.fem.form(ufl.inner(ufl.as_vector([0.0, ufl.sin(3.0 * x[0])]), v) * ufl.dx)
    facets = dolfinx.mesh.locate_entities_boundary(mesh, 1, lambda X: np.full(X.shape[1], True))
    bc = dolfinx.fem.dirichletbc(np.zeros(2), dolfinx.fem.locate_dofs_topological(V, 1, facets), V)
    A = dolfinx.fem.petsc.assemble_matrix(a, bcs=[bc])
    A.assemble()
    b = dolfinx.fem.petsc.assemble_vector(L)
    b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
    dolfinx.fem.petsc.set_bc(b, [bc])
    ksp = PETSc.KSP().create(comm)
    ksp.setOperators(A)
    ksp.setType("cg")
    ksp.setTolerances(rtol=1e-8, max_it=200)
    pc = ksp.getPC()
    pc.setType("mg")
    pc.setMGLevels(levels + 1)
    interpolations = [prolongation(spaces[level - 1], spaces[level]) for level in range(1, levels + 1)]
    for level, P in enumerate(interpolations, start=1):
        pc.setMGInterpolation(level, P)
    prefix = f"test_mg_{levels}_"
    ksp.setOptionsPrefix(prefix)
    options = PETSc.Options()
    for key, value in {"pc_mg_galerkin": "both", "mg_levels_ksp_type": "chebyshev", "mg_levels_pc_type": "jacobi",
                       "mg_levels_ksp_max_it": 2, "mg_coarse_ksp_type": "preonly",
                       "mg_coarse_pc_type": "redundant"}.items():
        options[prefix + key] = value
    ksp.setFromOptions()
    solution = A.createVecRight()
    ksp.solve(b, solution)
    assert ksp.getConvergedReason() > 0
    its = ksp.getIterationNumber()
    for key in list(options.getAll()):
        if key.startswith(prefix):
            options.delValue(key)
    for obj in (ksp, A, b, solution, *interpolations):  # now, on every rank together (not by the GC)
        obj.destroy()
    return its


def test_multigrid_iterations_do_not_grow_with_the_mesh(world):
    """Collective: 8, 16, 32 and 64 cells per side (1 to 4 levels): the same few iterations (measured
    6, 6, 6, 6 on 1 rank; 7, 7, 6, 6 on 2 and 3 ranks)."""
    its = [_multigrid_iterations(world, levels) for levels in (1, 2, 3, 4)]
    assert max(its) <= 10 and max(its) - min(its) <= 1, its
