"""3D Stokes solve cost: iterations, milliseconds per iteration, preconditioner setup, per step.

The unit cube is split into ``n x n x n`` cubes of 6 tetrahedra (P2-P1 Taylor-Hood), free slip on
all six sides, Ra = 1e6, and the thick-layer temperature of ``configs/thick_layer_3d.yaml``::

    T = 1/2 + 1/10 sin(pi z) cos(pi x) cos(pi y)

``--viscosity`` chooses the viscosity:

- ``constant``: eta = 1;
- ``temperature``: Frank-Kamenetskii eta = exp(-ln(1000) T) with T = 1 - z + 1/10 sin(pi z)
  cos(pi x) cos(pi y): a smooth contrast of 1e3 from bottom to top;
- ``layer``: a sharp contrast of 1e3: eta = 1000 in the cells below z = 0.4 + 0.05 cos(pi x)
  cos(pi y) (DG0 composition, geometric mixing), 1 above.

For each ``--cells`` n and ``--solver`` the script prints one JSON line with

- ``cold``: a new solver's first solve, from a zero initial guess (iterations, setup, solve
  seconds; ``ms_per_iteration`` = (solve - preconditioner setup) / iterations), best of
  ``--repeat`` new solvers (after one that JIT-compiles the forms);
- ``steps``: ``--steps`` solves that follow a temperature moving by 0.005 in x per step
  (``cos(pi (x - 0.005 k))``), each warm-started from the previous solution as in a time loop:
  mean iterations, mean setup and solve seconds per step.

Times are wall seconds, the slowest rank's; preconditioner setup is PETSc's ``PCSetUp`` event,
so the script also measures solvers of older commits (``PYTHONPATH=<old checkout>``), whose
``StokesResult`` has no setup field. ``load`` is the 1-minute load average at the start.

Run: ``python benchmarks/performance/stokes3d.py --cells 8 10 12 16 20 --solver iterative direct``
or under ``mpirun -n 2``.
"""

from __future__ import annotations

import argparse
import json
import os
import time

import numpy as np
import ufl
from mpi4py import MPI
from petsc4py import PETSc

import dolfinx.fem
import dolfinx.mesh

from benchmarks.harness import Benchmark
from convection.physics.approximation import BoussinesqApproximation, ViscosityLaw
from convection.geometry.boundary import VelocityBC
from convection.geometry.box import SIDES_3D
from convection.solvers.stokes.solver import StokesSolver
from fembase.dolfinx_compat import function_space

BENCHMARK = Benchmark(__doc__)
SHIFT_PER_STEP = 0.005


def temperature(viscosity: str, shift: float):
    """The temperature as a callable for ``Function.interpolate`` (x has shape (3, num_points))."""
    def T(x: np.ndarray) -> np.ndarray:
        wave = 0.1 * np.sin(np.pi * x[2]) * np.cos(np.pi * (x[0] - shift)) * np.cos(np.pi * x[1])
        return (1.0 - x[2] if viscosity == "temperature" else 0.5) + wave
    return T


def problem(mesh: dolfinx.mesh.Mesh, viscosity: str):
    """Temperature Function (P2), composition (None or DG0 Function) and the approximation."""
    T = dolfinx.fem.Function(function_space(mesh, "Lagrange", 2))
    T.interpolate(temperature(viscosity, 0.0))
    C = None
    if viscosity == "constant":
        law = ViscosityLaw()
    elif viscosity == "temperature":
        law = ViscosityLaw(temperature_law="frank_kamenetskii", gamma=np.log(1000.0))
    elif viscosity == "layer":
        C = dolfinx.fem.Function(function_space(mesh, "DG", 0))
        C.interpolate(lambda x: (x[2] <= 0.4 + 0.05 * np.cos(np.pi * x[0]) * np.cos(np.pi * x[1])).astype(float))
        law = ViscosityLaw((1.0, 1000.0))
    else:
        raise ValueError(viscosity)
    return T, C, BoussinesqApproximation(Ra=1e6, viscosity=law)


class EventClock:
    """Seconds spent in the PETSc event ``name`` since the last call (slowest rank)."""

    def __init__(self, name: str, comm: MPI.Comm) -> None:
        self.event, self.comm = PETSc.Log.Event(name), comm
        self.last = self.event.getPerfInfo()["time"]

    def lap(self) -> float:
        now = self.event.getPerfInfo()["time"]
        elapsed, self.last = now - self.last, now
        return self.comm.allreduce(elapsed, op=MPI.MAX)


def timed_solve(stokes: StokesSolver, T, C, setup_clock: EventClock) -> dict:
    comm = stokes.mesh.comm
    comm.Barrier()
    t0 = time.perf_counter()
    result = stokes.solve(T, C)
    seconds = comm.allreduce(time.perf_counter() - t0, op=MPI.MAX)
    setup = setup_clock.lap()
    solve = comm.allreduce(result.solve_seconds, op=MPI.MAX)
    iterations = result.iterations
    return {"iterations": iterations, "setup_seconds": setup, "solve_seconds": solve,
            "assembly_seconds": comm.allreduce(result.assembly_seconds, op=MPI.MAX), "total_seconds": seconds,
            "ms_per_iteration": 1e3 * (solve - setup) / max(iterations, 1), "residual_norm": result.residual_norm}


def run(n: int, solver: str, args: argparse.Namespace) -> dict:
    comm = MPI.COMM_WORLD
    load = os.getloadavg()[0]
    mesh = dolfinx.mesh.create_unit_cube(comm, n, n, n)
    T, C, approximation = problem(mesh, args.viscosity)
    options = json.loads(args.petsc_options)

    def build() -> StokesSolver:
        return StokesSolver(mesh, approximation, bcs={side: VelocityBC("free_slip") for side in SIDES_3D},
                            solver=solver, **({"petsc_options": options} if options else {}))

    setup_clock = EventClock("PCSetUp", comm)
    build().solve(T, C)  # JIT compilation of the forms
    setup_clock.lap()
    cold = None
    for _ in range(args.repeat):  # a new solver: zero initial guess, preconditioner set up afresh
        stokes = build()
        trial = timed_solve(stokes, T, C, setup_clock)
        if cold is None or trial["total_seconds"] < cold["total_seconds"]:
            cold = trial
    steps = []
    for k in range(1, args.steps + 1):
        T.interpolate(temperature(args.viscosity, SHIFT_PER_STEP * k))
        steps.append(timed_solve(stokes, T, C, setup_clock))
    dofs = stokes.V.dofmap.index_map.size_global * stokes.V.dofmap.index_map_bs + stokes.Q.dofmap.index_map.size_global
    vrms = np.sqrt(comm.allreduce(dolfinx.fem.assemble_scalar(dolfinx.fem.form(ufl.inner(stokes.u, stokes.u) * ufl.dx)),
                                  op=MPI.SUM))
    stokes.destroy()
    mean = {key: float(np.mean([s[key] for s in steps])) for key in ("iterations", "setup_seconds", "solve_seconds",
                                                                       "ms_per_iteration")} if steps else {}
    if steps:
        mean["iterations_list"] = [s["iterations"] for s in steps]
    return {"cells": n, "tets": 6 * n**3, "dofs": int(dofs), "ranks": comm.size, "solver": solver,
            "viscosity": args.viscosity, "petsc_options": options, "load": round(load, 2), "cold": cold,
            "steps": mean, "vrms": float(vrms)}


def main() -> None:
    parser = BENCHMARK.parser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cells", type=int, nargs="+", default=[8, 10, 12, 16, 20])
    parser.add_argument("--solver", nargs="+", default=["iterative"])
    parser.add_argument("--viscosity", choices=("constant", "temperature", "layer"), default="constant")
    parser.add_argument("--petsc-options", default="{}", help="JSON dict of extra PETSc options")
    parser.add_argument("--repeat", type=int, default=1, help="cold solves from zero, best kept")
    parser.add_argument("--steps", type=int, default=5, help="warm-started solves following a moving T")
    args = parser.parse_args()
    PETSc.Log.begin()
    for n in args.cells:
        for solver in args.solver:
            result = run(n, solver, args)
            if MPI.COMM_WORLD.rank == 0:
                print(json.dumps(result), flush=True)


if __name__ == "__main__":
    main()
