"""Where the time goes: wall seconds per phase of a run, summed on each rank.

Phases are named by the code that times them (``stokes_assembly``, ``stokes_solve``,
``temperature``, ``composition``, ``particle_advection``, ``particle_sort``, ``particle_migration``,
``particle_interpolation``, ``adaptation``, ``balancing``, ``output``, ...). :meth:`Timers.summary`
reduces over ranks (max and mean) for the table printed at the end of a run and stored in
``summary.json``.
"""

from __future__ import annotations

import time
from contextlib import contextmanager
from collections.abc import Iterator, Mapping

import numpy as np
from mpi4py import MPI

__all__ = ["Timers"]


class Timers:
    """Seconds and call counts per named phase (this rank)."""

    def __init__(self) -> None:
        self.seconds: dict[str, float] = {}
        self.calls: dict[str, int] = {}

    def add(self, phase: str, seconds: float, /, calls: int = 1) -> None:
        """Add ``seconds`` to ``phase``."""
        self.seconds[phase] = self.seconds.get(phase, 0.0) + float(seconds)
        self.calls[phase] = self.calls.get(phase, 0) + calls

    @contextmanager
    def __call__(self, phase: str, /) -> Iterator[None]:
        """Time the ``with`` block as ``phase``."""
        t0 = time.perf_counter()
        try:
            yield
        finally:
            self.add(phase, time.perf_counter() - t0)

    def summary(self, comm: MPI.Comm, /, *, extra: Mapping[str, float] | None = None,
                total: float | None = None) -> dict[str, dict[str, float]]:
        """Per phase: max and mean over ranks of the seconds, and the share of ``total`` (collective).

        Args:
            comm: The run's communicator.
            extra: More phases measured elsewhere (e.g. the particle manager's timings).
            total: The run's wall time (for the ``share`` of each phase); rank 0's value is used.
        """
        local = dict(self.seconds)
        for phase, seconds in (extra or {}).items():
            local[phase] = local.get(phase, 0.0) + float(seconds)
        phases = sorted(set().union(*comm.allgather(set(local))))
        values = np.array([local.get(p, 0.0) for p in phases])
        maxima = np.empty_like(values)
        sums = np.empty_like(values)
        comm.Allreduce(values, maxima, op=MPI.MAX)
        comm.Allreduce(values, sums, op=MPI.SUM)
        total = comm.bcast(total, root=0)
        out = {}
        for p, hi, s in zip(phases, maxima, sums):
            row = {"max_seconds": float(hi), "mean_seconds": float(s) / comm.size}
            if total:
                row["share"] = float(hi) / total
            out[p] = row
        return dict(sorted(out.items(), key=lambda item: -item[1]["max_seconds"]))

    @staticmethod
    def table(summary: Mapping[str, Mapping[str, float]], /) -> str:
        """The summary as a text table, slowest phase first."""
        lines = [f"{'phase':<24} {'max s':>9} {'mean s':>9} {'share':>7}"]
        for phase, row in summary.items():
            share = f"{100.0 * row['share']:6.1f}%" if "share" in row else ""
            lines.append(f"{phase:<24} {row['max_seconds']:9.3f} {row['mean_seconds']:9.3f} {share:>7}")
        return "\n".join(lines)
