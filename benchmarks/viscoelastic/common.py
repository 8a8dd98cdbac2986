"""What the visco-elastic benchmarks at two resolutions share: their command line and run loop."""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from mpi4py import MPI

from benchmarks.harness import Benchmark


def resolutions_main(argv: list[str] | None, benchmark: Benchmark, *, run_case: Callable[..., Any],
                     resolutions: Sequence[tuple[int, int]], quick: Sequence[tuple[int, int]], steps: int,
                     steps_help: str, publish: Callable[..., None]) -> int:
    """Parse ``--out``, ``--results``, ``--quick`` and ``--steps``; run ``run_case(cells, out=, steps=,
    comm=)`` per resolution (``quick``'s with ``--quick``) into ``<out>/<nx>x<nz>``; on rank 0
    ``publish(runs, results, steps=, ranks=)``. Logs the load at the start (the end is ``publish``'s)."""
    parser = benchmark.parser()
    parser.add_argument("--steps", type=int, default=steps, help=steps_help)
    args = parser.parse_args(argv)
    logging.getLogger().addFilter(lambda record: record.levelno >= logging.WARNING)
    comm = MPI.COMM_WORLD
    if comm.rank == 0:
        benchmark.log_load("start")
    runs = [run_case(cells, out=Path(args.out) / f"{cells[0]}x{cells[1]}", steps=args.steps, comm=comm)
            for cells in (quick if args.quick else resolutions)]
    if comm.rank == 0:
        publish(runs, args.results, steps=args.steps, ranks=comm.size)
    return 0
