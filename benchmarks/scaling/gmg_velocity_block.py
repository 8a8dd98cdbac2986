"""Geometric multigrid on the Stokes velocity block: iterations and time against the mesh size.

The operator is the velocity block of this project's Stokes problem, ``2 eta eps(u) : eps(v)``
with P2 vectors on the unit square / cube (u = 0 on the boundary), the viscosity constant or,
with ``--profile smooth``, ``eta = 10^(k z)`` (a contrast of 10^k over the height), with
``--profile jump`` ``eta = 10^k`` above the sloping plane ``z = 0.45 + 0.1 x`` and 1 below (a
sharp contrast that no coarse mesh resolves). The right-hand side is a vertical force
``sin(3 x)``. CG to a relative residual 1e-8 with:

- ``gmg``: PETSc's PCMG on the nested meshes of uniform refinement from a coarse mesh, with
  :func:`fembase.multigrid.prolongation` between the levels, Galerkin coarse operators, two
  Chebyshev/Jacobi smoothing steps per level and a direct solve (redundant LU) on the coarsest;
- ``gmg_rediscretised``: the same, but each coarser level's operator assembled on its own mesh
  with the viscosity evaluated there (at that mesh's quadrature points), as a code that keeps the
  coefficient on every level does, in place of the Galerkin product ``P^T A P``;
- ``hypre``: BoomerAMG with PETSc's defaults (what the velocity block uses today in 3D,
  :mod:`convection.solvers.stokes.solver`);
- ``gamg``: PETSc's smoothed aggregation with defaults (no near-null space).

Usage (under mpirun for several ranks; the machine should be otherwise idle)::

    mpirun -n 2 python -m benchmarks.scaling.gmg_velocity_block --dim 3 --base 2 --levels 1 2 3 4 \\
        --contrast 0 4 6 --methods gmg hypre [--out benchmarks/scaling/gmg_velocity_block.md]

At 32³ run one row per process (``--levels 4 --methods hypre --repeat 1``): a process that
solves that size with BoomerAMG repeatedly grows past 12 GB.

Writes a markdown table (one row per mesh, contrast and method, the fastest of ``--repeat``
solves: unknowns, iterations, setup and solve seconds, the load average before the sitting) and
prints it.
"""

from __future__ import annotations

import gc
import os
import sys
import time
from pathlib import Path

import numpy as np
import ufl
from mpi4py import MPI
from petsc4py import PETSc

import dolfinx.fem
import dolfinx.fem.petsc
import dolfinx.mesh

from benchmarks.harness import Benchmark, Load
from fembase.dolfinx_compat import function_space, petsc_vector, refine_keeping_partition
from fembase.multigrid import prolongation

HERE = Path(__file__).resolve().parent
BENCHMARK = Benchmark(__doc__, out_option=True)

_MG_OPTIONS = {"pc_mg_galerkin": "both", "mg_levels_ksp_type": "chebyshev", "mg_levels_pc_type": "jacobi",
               "mg_levels_ksp_max_it": 2, "mg_coarse_ksp_type": "preonly", "mg_coarse_pc_type": "redundant"}


def _meshes(comm: MPI.Comm, dim: int, base: int, levels: int) -> list[dolfinx.mesh.Mesh]:
    coarse = dolfinx.mesh.create_unit_square(comm, base, base) if dim == 2 else \
        dolfinx.mesh.create_unit_cube(comm, base, base, base)
    meshes = [coarse]
    for _ in range(levels):
        meshes.append(refine_keeping_partition(meshes[-1]))
    return meshes


def _viscosity(x: ufl.SpatialCoordinate, dim: int, contrast: float, profile: str):
    if contrast == 0.0:
        return 1.0
    if profile == "jump":
        return ufl.conditional(ufl.gt(x[dim - 1], 0.45 + 0.1 * x[0]), 10.0**contrast, 1.0)
    return ufl.exp(contrast * np.log(10.0) * x[dim - 1])


def _boundary_condition(V: dolfinx.fem.FunctionSpace):
    """u = 0 on the whole boundary."""
    dim = V.mesh.geometry.dim
    facets = dolfinx.mesh.locate_entities_boundary(V.mesh, dim - 1, lambda X: np.full(X.shape[1], True))
    return dolfinx.fem.dirichletbc(np.zeros(dim), dolfinx.fem.locate_dofs_topological(V, dim - 1, facets), V)


def _interior(V: dolfinx.fem.FunctionSpace) -> PETSc.Vec:
    """1 on the free dofs, 0 on the boundary's (a copy: the caller destroys it)."""
    mask = dolfinx.fem.Function(V)
    mask.x.array[:] = 1.0
    mask.x.array[_boundary_condition(V).dof_indices()[0]] = 0.0
    return petsc_vector(mask).copy()


def _system(V: dolfinx.fem.FunctionSpace, contrast: float, profile: str = "smooth") -> tuple[PETSc.Mat, PETSc.Vec]:
    mesh = V.mesh
    dim = mesh.geometry.dim
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    x = ufl.SpatialCoordinate(mesh)
    eta = _viscosity(x, dim, contrast, profile)
    a = dolfinx.fem.form(2.0 * eta * ufl.inner(ufl.sym(ufl.grad(u)), ufl.sym(ufl.grad(v))) * ufl.dx)
    force = ufl.as_vector([0.0] * (dim - 1) + [ufl.sin(3.0 * x[0])])
    L = dolfinx.fem.form(ufl.inner(force, v) * ufl.dx)
    bc = _boundary_condition(V)
    A = dolfinx.fem.petsc.assemble_matrix(a, bcs=[bc])
    A.assemble()
    b = dolfinx.fem.petsc.assemble_vector(L)
    b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
    dolfinx.fem.petsc.set_bc(b, [bc])
    return A, b


def measure(comm: MPI.Comm, dim: int, base: int, levels: int, contrast: float, method: str,
            profile: str = "smooth", krylov: str = "cg") -> dict[str, float]:
    """One solve; returns unknowns, iterations and seconds (prolongations, setup, solve; max over
    ranks). The re-discretised coarse operators are assembled in the "prolongations" time."""
    meshes = _meshes(comm, dim, base, levels)
    spaces = [function_space(m, "Lagrange", 2, shape=(dim,)) for m in meshes]
    A, b = _system(spaces[-1], contrast, profile)
    ksp = PETSc.KSP().create(comm)
    ksp.setOperators(A)
    ksp.setType(krylov)
    ksp.setTolerances(rtol=1e-8, max_it=1000)
    prefix = f"gmgbench_{method}_{levels}_{contrast:g}_"
    ksp.setOptionsPrefix(prefix)
    options = PETSc.Options()
    pc = ksp.getPC()
    t0 = time.perf_counter()
    interpolations = []
    if method in ("gmg", "gmg_rediscretised"):
        pc.setType("mg")
        pc.setMGLevels(levels + 1)
        for level in range(1, levels + 1):
            interpolations.append(prolongation(spaces[level - 1], spaces[level]))
            if method == "gmg_rediscretised":
                # Each level's operator has its own boundary rows (unit diagonal): the transfers
                # act between the free dofs only (Galerkin's P^T A P carries the fine rows instead).
                fine, coarse = _interior(spaces[level]), _interior(spaces[level - 1])
                interpolations[-1].diagonalScale(fine, coarse)
                fine.destroy()
                coarse.destroy()
            pc.setMGInterpolation(level, interpolations[-1])
        for key, value in _MG_OPTIONS.items():
            options[prefix + key] = value
        if method == "gmg_rediscretised":
            options[prefix + "pc_mg_galerkin"] = "none"
            for level in range(levels):
                coarse, coarse_b = _system(spaces[level], contrast, profile)
                coarse_b.destroy()
                solver = pc.getMGCoarseSolve() if level == 0 else pc.getMGSmoother(level)
                solver.setOperators(coarse, coarse)
                interpolations.append(coarse)  # destroyed with them
    else:
        pc.setType(method)
    ksp.setFromOptions()
    t1 = time.perf_counter()
    ksp.setUp()
    t2 = time.perf_counter()
    x = A.createVecRight()
    ksp.solve(b, x)
    t3 = time.perf_counter()
    converged = ksp.getConvergedReason() > 0  # a row either way: "no" where CG stopped at 1000 or broke down
    seconds = [comm.allreduce(s, op=MPI.MAX) for s in (t1 - t0, t2 - t1, t3 - t2)]
    row = {"cells": base * 2**levels, "unknowns": A.getSize()[0],
           "iterations": ksp.getIterationNumber() if converged else f"no ({ksp.getConvergedReason()})",
           "prolongation": seconds[0], "setup": seconds[1], "solve": seconds[2]}
    for obj in (ksp, A, b, x, *interpolations):  # now, on every rank together (12 GB piled up otherwise)
        obj.destroy()
    gc.collect()
    return row


def main(argv: list[str] | None = None) -> int:
    parser = BENCHMARK.parser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--dim", type=int, default=3)
    parser.add_argument("--base", type=int, default=2, help="cells per side of the coarsest mesh")
    parser.add_argument("--levels", type=int, nargs="+", default=[1, 2, 3])
    parser.add_argument("--contrast", type=float, nargs="+", default=[0.0, 4.0, 6.0],
                        help="log10 of the viscosity contrast over the height")
    parser.add_argument("--methods", nargs="+", default=["gmg", "hypre"],
                        help="gmg, gmg_rediscretised, hypre, gamg")
    parser.add_argument("--profile", choices=["smooth", "jump"], default="smooth",
                        help="the viscosity: 10^(k z), or a jump of 10^k across a sloping plane")
    parser.add_argument("--krylov", choices=["cg", "fgmres"], default="cg",
                        help="the outer Krylov method (fgmres: as the Stokes solver; no breakdown where the "
                             "V-cycle is not positive definite)")
    parser.add_argument("--repeat", type=int, default=3, help="solves per row; the row shows the fastest")
    args = parser.parse_args(argv)
    comm = MPI.COMM_WORLD
    load = Load.now().averages[0]
    lines = [f"# P2 velocity block, {args.dim}D: {args.krylov.upper()} iterations to 1e-8 and seconds "
             f"(max over {comm.size} ranks)", "",
             f"Generated by `benchmarks/scaling/gmg_velocity_block.py --profile {args.profile} --krylov {args.krylov}` on "
             f"{comm.size} "
             f"rank(s), best of {args.repeat} solves per row; load average before the sitting {load:.2f} on "
             f"{os.cpu_count()} cores.", "",
             "| cells per side | unknowns | viscosity contrast | method | iterations | prolongations [s] | setup [s] | "
             "solve [s] |", "|---|---|---|---|---|---|---|---|"]
    for levels in args.levels:
        for contrast in args.contrast:
            for method in args.methods:
                runs = [measure(comm, args.dim, args.base, levels, contrast, method, args.profile, args.krylov)
                        for _ in range(args.repeat)]
                r = min(runs, key=lambda row: row["setup"] + row["solve"])  # best of --repeat
                lines.append(f"| {r['cells']} | {r['unknowns']} | 1e{contrast:g} | {method} | {r['iterations']} | "
                             f"{r['prolongation']:.2f} | {r['setup']:.2f} | {r['solve']:.2f} |")
                if comm.rank == 0:
                    print(lines[-1], flush=True)
    if comm.rank == 0 and args.out is not None:
        args.out.write_text("\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
