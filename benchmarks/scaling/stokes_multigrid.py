"""The whole Stokes solve with ``stokes.solver: multigrid`` against the mesh: iterations, seconds and
memory per unknown, against the AMG solver (``iterative``), with a constant viscosity and with a
contrast.

The problem is this project's Stokes solver (:class:`convection.solvers.stokes.solver.StokesSolver`)
on the unit square or cube of ``n`` cells per side, free slip on every side, Ra = 1e6 and the
thick layer's temperature ``T = 1 - z + 0.1 sin(pi z) cos(pi x) cos(pi y)`` (in 2D without the
y factor); the viscosity is constant or ``exp(-ln(contrast) T)`` (Frank-Kamenetskii: the contrast
across the layer). One solve from zero to ``|b - K x| <= 1e-7 |b|`` (the default stopping rule);
the meshes of the multigrid are the boxes of n/2, n/4, ... cells (``stokes.multigrid.levels: 0``).

Memory: the growth of the process's peak resident size (``ru_maxrss``, max over ranks) while the
solver is made and solves, per Stokes unknown; one row per process (``--sizes`` one value) measures
it cleanly, as the peak only grows.

Usage (the machine otherwise idle)::

    mpirun -n 2 python -m benchmarks.scaling.stokes_multigrid --dim 3 --sizes 8 16 24 32 \\
        --contrast 1 1e4 --solvers multigrid iterative --header

Prints one markdown row per size, contrast and solver (``--header`` first prints the header).
"""

from __future__ import annotations

import gc
import os
import resource
import sys
from pathlib import Path

import numpy as np
from mpi4py import MPI

import dolfinx

from benchmarks.harness import Benchmark
from convection.geometry.boundary import VelocityBC
from convection.geometry.box import SIDES_2D, SIDES_3D, BoxDomain, BoxSpec
from convection.physics.approximation import BoussinesqApproximation, ViscosityLaw
from convection.solvers.stokes.solver import StokesSolver
from fembase.dolfinx_compat import function_space

HERE = Path(__file__).resolve().parent
BENCHMARK = Benchmark(__doc__)

HEADER = ("| dim | cells per side | Stokes unknowns | viscosity contrast | solver | levels | iterations | "
          "setup + solve [s] | assembly [s] | memory [bytes / unknown] |\n|---|---|---|---|---|---|---|---|---|---|")


def _peak_bytes(comm: MPI.Comm) -> float:
    return comm.allreduce(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024.0, op=MPI.MAX)


def measure(comm: MPI.Comm, dim: int, n: int, contrast: float, solver: str,
            petsc_options: dict[str, str] | None = None) -> dict[str, float]:
    """One cold solve; seconds are the slowest rank's. ``petsc_options`` go on top of the solver's."""
    before = _peak_bytes(comm)
    domain = BoxDomain.from_spec(BoxSpec((n,) * dim, (0.0,) * dim, (1.0,) * dim))
    levels = domain.mesh_levels() if solver == "multigrid" else 1
    meshes = domain.create_mesh_levels(comm, levels)
    mesh = meshes[-1]
    T = dolfinx.fem.Function(function_space(mesh, "Lagrange", 2))
    if dim == 3:
        T.interpolate(lambda x: 1.0 - x[2] + 0.1 * np.sin(np.pi * x[2]) * np.cos(np.pi * x[0]) * np.cos(np.pi * x[1]))
    else:
        T.interpolate(lambda x: 1.0 - x[1] + 0.1 * np.sin(np.pi * x[1]) * np.cos(np.pi * x[0]))
    law = ViscosityLaw(temperature_law="frank_kamenetskii", gamma=np.log(contrast)) if contrast != 1.0 else ViscosityLaw()
    sides = SIDES_3D if dim == 3 else SIDES_2D
    stokes = StokesSolver(mesh, BoussinesqApproximation(Ra=1e6, viscosity=law),
                          bcs={side: VelocityBC("free_slip") for side in sides}, solver=solver,
                          coarse_meshes=meshes[:-1], petsc_options=petsc_options or None)
    comm.barrier()
    result = stokes.solve(T)
    unknowns = (stokes.V.dofmap.index_map.size_global * stokes.V.dofmap.index_map_bs
                + stokes.Q.dofmap.index_map.size_global)
    after = _peak_bytes(comm)
    row = {"unknowns": unknowns, "levels": levels, "iterations": result.iterations,
           "solve": comm.allreduce(result.solve_seconds, op=MPI.MAX),
           "assembly": comm.allreduce(result.assembly_seconds, op=MPI.MAX),
           "memory": (after - before) * comm.size / unknowns}
    stokes.destroy()
    del stokes, meshes, mesh, T
    gc.collect()
    return row


def main(argv: list[str] | None = None) -> int:
    parser = BENCHMARK.parser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--dim", type=int, default=3)
    parser.add_argument("--sizes", type=int, nargs="+", default=[8, 16])
    parser.add_argument("--contrast", type=float, nargs="+", default=[1.0, 1e4])
    parser.add_argument("--solvers", nargs="+", default=["multigrid", "iterative"])
    parser.add_argument("--header", action="store_true", help="print the table header first")
    parser.add_argument("--petsc", nargs="*", default=[], metavar="KEY=VALUE",
                        help="PETSc options on top of the solver's (e.g. fieldsplit_u_mg_levels_ksp_max_it=3)")
    args = parser.parse_args(argv)
    petsc_options = dict(item.split("=", 1) for item in args.petsc)
    comm = MPI.COMM_WORLD
    if comm.rank == 0 and args.header:
        print(f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores, {comm.size} ranks\n\n{HEADER}", flush=True)
    for n in args.sizes:
        for contrast in args.contrast:
            for solver in args.solvers:
                r = measure(comm, args.dim, n, contrast, solver, petsc_options)
                if comm.rank == 0:
                    print(f"| {args.dim} | {n} | {r['unknowns']} | {contrast:g} | {solver} | {r['levels']} | "
                          f"{r['iterations']} | {r['solve']:.2f} | {r['assembly']:.2f} | {r['memory']:.0f} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
