"""The rigid-shear benchmark of Gassmöller, Lokavarapu, Bangerth & Puckett (2019, GJI): L2 errors of
velocity, pressure and density of the particle-in-cell Stokes solution against the analytical one,
over resolutions, particles per cell, interpolators and integrators (problem.py: the equations;
cases.py: one run).

Run (from the project root; the full sweep, then the table and the picture)::

    python -m benchmarks.rigid_shear.rigid_shear
    python -m benchmarks.rigid_shear.rigid_shear --problems time_dependent --ppc 16 --interpolators least_squares
    mpirun -n 2 python -m benchmarks.rigid_shear.rigid_shear --cells 8 16 --results /tmp/r.json
    python -m benchmarks.rigid_shear.rigid_shear --report-only

Every run's result merges into ``--results`` (default results.json here; a run with the same
parameters replaces the old one), one JSON line per run goes to ``--log`` (default
log/sweep_<UTC time>.jsonl), and the table (rigid_shear.md) and the picture (rigid_shear.png) are
made again from the whole results file.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
import time
from pathlib import Path
from typing import Any
from collections.abc import Iterator, Sequence

from mpi4py import MPI

from benchmarks.harness import Benchmark
from benchmarks.rigid_shear.cases import INTERPOLATORS, Case, run_case
from benchmarks.rigid_shear.problem import StokesSolver, unit_square
from benchmarks.rigid_shear.report import write_figure, write_table

HERE = Path(__file__).resolve().parent
BENCHMARK = Benchmark(__doc__)

__all__ = ["main", "parse", "sweep"]

PROBLEMS = ("instantaneous", "time_dependent")
DEFAULT_INTERPOLATORS = ("exact", "cell_average", "least_squares", "least_squares_limited", "quadratic_least_squares",
                         "quadratic_least_squares_limited")


def parse(argv: Sequence[str] | None = None, /) -> argparse.Namespace:
    """The command line."""
    parser = BENCHMARK.parser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--problems", nargs="+", default=list(PROBLEMS), choices=PROBLEMS)
    parser.add_argument("--cells", nargs="+", type=int, default=[8, 16, 32, 64], help="squares per side (h = 1/cells)")
    parser.add_argument("--ppc", nargs="+", type=int, default=[4, 16, 64], help="particles per triangle")
    parser.add_argument("--interpolators", nargs="+", default=list(DEFAULT_INTERPOLATORS), choices=sorted(INTERPOLATORS))
    parser.add_argument("--integrators", nargs="+", default=["rk2", "rk4"], help="for the time-dependent problem")
    parser.add_argument("--end-time", type=float, default=0.1)
    parser.add_argument("--cfl", type=float, default=1.0)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--results", type=Path, default=HERE / "results.json")
    parser.add_argument("--table", type=Path, default=HERE / "rigid_shear.md")
    parser.add_argument("--figure", type=Path, default=HERE / "rigid_shear.png")
    parser.add_argument("--log", type=Path, default=None, help="JSON lines of the runs (default log/sweep_<time>.jsonl)")
    parser.add_argument("--report-only", action="store_true", help="only remake the table and picture")
    return parser.parse_args(argv)


def cases(args: argparse.Namespace, /) -> Iterator[Case]:
    """The runs the command line asks for, coarsest mesh first within each choice."""
    for problem in args.problems:
        for interpolator in args.interpolators:
            exact = interpolator == "exact"
            integrators = ["none"] if exact or problem == "instantaneous" else args.integrators
            if exact and problem == "time_dependent":
                continue  # the exact density does not move: the instantaneous reference
            for ppc in [0] if exact else args.ppc:
                for integrator in integrators:
                    for cells in args.cells:
                        yield Case(problem, cells, ppc, interpolator, integrator, args.end_time, args.cfl, args.seed)


def sweep(args: argparse.Namespace, /, comm: MPI.Comm = MPI.COMM_WORLD) -> list[dict[str, Any]]:
    """Run every case (one Stokes solver, factorised once, per mesh); returns the results and
    writes one JSON line per run to ``args.log`` (rank 0)."""
    solvers: dict[int, StokesSolver] = {}
    results = []
    log = open(args.log, "a") if comm.rank == 0 and args.log is not None else None
    try:
        for case in cases(args):
            if case.cells not in solvers:
                solvers[case.cells] = StokesSolver(unit_square(comm, case.cells))
            result = {**run_case(case, solvers[case.cells]), "ranks": comm.size}
            results.append(result)
            if comm.rank == 0:
                line = json.dumps(result)
                print(line, flush=True)
                if log is not None:
                    log.write(line + "\n")
                    log.flush()
    finally:
        if log is not None:
            log.close()
    return results


def merge(path: Path, new: list[dict[str, Any]], /) -> dict[str, Any]:
    """results.json's content with ``new`` runs replacing those of the same parameters."""
    old = json.loads(path.read_text())["runs"] if path.exists() else []
    key_fields = ("problem", "cells", "ppc", "interpolator", "integrator", "end_time", "cfl", "seed")
    fresh = {tuple(r[k] for k in key_fields) for r in new}
    runs = [r for r in old if tuple(r[k] for k in key_fields) not in fresh] + new
    return {"benchmark": "rigid shear (Gassmöller et al. 2019), P2/P1 triangles", "runs": runs}


def write_results(path: Path, results: dict[str, Any], /) -> None:
    """One run per line (diff-friendly)."""
    lines = ",\n".join(json.dumps(r) for r in results["runs"])
    path.write_text('{"benchmark": ' + json.dumps(results["benchmark"]) + ',\n"runs": [\n' + lines + "\n]}\n")


def report(args: argparse.Namespace, results: dict[str, Any], /) -> None:
    """The table and the picture from ``results``."""
    header = ["# Rigid shear benchmark: results", "",
              "Made by `benchmarks/rigid_shear/rigid_shear.py` from `results.json` (do not edit by hand; "
              "README.md explains the set-up). P2/P1 Taylor-Hood on triangles (h = 1/cells, 2 cells² triangles), "
              "random uniform particles (ppc per triangle); the paper: Q2/Q1 on squares of side h, regular "
              "particles per square."]
    write_table(results, args.table, header=header)
    write_figure(results, args.figure)


def main(argv: Sequence[str] | None = None, /) -> None:
    args = parse(argv)
    logging.getLogger().setLevel(logging.WARNING)  # the form compiler's build lines
    comm = MPI.COMM_WORLD
    if args.report_only:
        if comm.rank == 0:
            report(args, json.loads(args.results.read_text()))
        return
    if args.log is None:
        args.log = HERE / "log" / time.strftime("sweep_%Y%m%dT%H%M%SZ.jsonl", time.gmtime())
    if comm.rank == 0:
        args.log.parent.mkdir(parents=True, exist_ok=True)
        with open(args.log, "a") as f:
            f.write(json.dumps({"argv": sys.argv, "ranks": comm.size, **BENCHMARK.log_load("start").record()}) + "\n")
    t0 = time.perf_counter()
    new = sweep(args, comm)
    if comm.rank == 0:
        results = merge(args.results, new)
        write_results(args.results, results)
        report(args, results)
        print(f"{len(new)} runs in {time.perf_counter() - t0:.1f} s; {args.results}, {args.table}, {args.figure}",
              flush=True)


if __name__ == "__main__":
    main()
