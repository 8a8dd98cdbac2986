"""The run loop: time steps of a :class:`~convection.model.Model` with statistics, output and stops.

Per step: statistics row (from the postprocessors), progress, field output when due; then the stop
conditions (end time, ``max_steps``, steady state, a stop request); then the CFL step length and
:meth:`Model.step`. At the end the fields (and the particles, if they are written) are written
once more, the time per phase is printed and ``summary.json`` written.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np
from mpi4py import MPI

from convection.model import Model, StepReport
from convection.output import FieldOutput
from convection.postprocess import Postprocessor
from convection.progress import Progress
from convection.statistics import BalanceLog, StatisticsWriter

__all__ = ["RunSettings", "RunSummary", "SteadyState", "run"]


@dataclass(frozen=True)
class RunSettings:
    """How long and how a run goes (the ``time`` and ``output`` sections).

    Attributes:
        end: End time.
        cfl: Courant number of the step.
        dt_max: Largest step, or None.
        dt_initial: Step used while the velocity is zero, or None.
        max_steps: Stop after this many steps, or None.
        steady_tolerance: Stop when vrms and Nu change by less than this (relative) over
            ``steady_window`` steps, or None.
        steady_window: Steps of the steady-state test.
        directory: Output folder.
        fields_every: Field output every this many steps (0: only at the end).
        progress: ``auto``, ``bar``, ``lines`` or ``none``.
        progress_every: Steps between progress lines.
    """

    end: float
    directory: Path
    cfl: float = 1.0
    dt_max: float | None = None
    dt_initial: float | None = None
    max_steps: int | None = None
    steady_tolerance: float | None = None
    steady_window: int = 20
    fields_every: int = 10
    progress: str = "auto"
    progress_every: int = 10


@dataclass(frozen=True)
class RunSummary:
    """What a finished (or stopped) run reached; ``timings`` per phase (see :mod:`convection.timing`)."""

    steps: int
    time: float
    vrms: float
    nusselt: float
    cells: int
    wall_time: float
    reason: str
    timings: dict[str, dict[str, float]]

    def as_dict(self) -> dict[str, Any]:
        return dict(self.__dict__)


class SteadyState:
    """Stop when every watched column changed by less than ``tolerance`` (relative) over ``window`` steps."""

    def __init__(self, tolerance: float | None, window: int, columns: Sequence[str] = ("vrms", "nusselt")) -> None:
        self.tolerance = tolerance
        self.window = window
        self.columns = tuple(columns)
        self._history: list[list[float]] = []

    def __call__(self, row: dict[str, float]) -> bool:
        self._history.append([float(row.get(c, np.nan)) for c in self.columns])
        if self.tolerance is None or len(self._history) <= self.window:
            return False
        recent = np.array(self._history[-self.window - 1:])
        scale = np.maximum(np.abs(recent[-1]), 1e-300)
        change = np.max(np.abs(recent - recent[-1]), axis=0) / scale
        return bool(np.all(change < self.tolerance))


def _timestep(model: Model, settings: RunSettings) -> float:
    dt = model.cfl_dt(settings.cfl, dt_max=settings.dt_max)
    if not np.isfinite(dt) or dt <= 0.0:
        dt = settings.dt_initial or settings.dt_max or 0.0
        if dt <= 0.0:
            raise RuntimeError("the velocity is zero and neither time.dt_initial nor time.dt_max is set")
    return min(dt, settings.end - model.time)


def _report(report: StepReport, step: int, balance_log: BalanceLog, progress: Progress) -> None:
    if report.adapted is not None:
        before, after = report.adapted
        progress.message(f"adapted mesh at step {step}: {before} -> {after} cells")
    if report.rebalanced is not None:
        before, after = report.rebalanced
        balance_log.write(step, before, after)
        progress.message(
            f"rebalanced at step {step}: cells per rank {before.cells.tolist()} -> {after.cells.tolist()}, "
            f"particles per rank {before.particles.tolist()} -> {after.particles.tolist()} "
            f"(imbalance cells {before.cell_imbalance:.3f} -> {after.cell_imbalance:.3f}, "
            f"particles {before.particle_imbalance:.3f} -> {after.particle_imbalance:.3f})"
        )


def run(model: Model, settings: RunSettings, postprocessors: Sequence[Postprocessor], /, *,
        should_stop: Callable[[], bool] = lambda: False, start: float | None = None) -> RunSummary:
    """Run ``model`` to ``settings.end`` (or max_steps, steady state, or a stop request). Collective.

    Args:
        model: The model (started here if it was not).
        settings: Time and output settings.
        postprocessors: The statistics columns (:func:`convection.postprocess.create_postprocessors`).
        should_stop: Polled every step on every rank (e.g. a signal flag); the run stops when it
            is True on any rank, with everything written.
        start: ``time.monotonic()`` at the start of the run (default: now).
    """
    rank0 = model.comm.rank == 0
    start = time.monotonic() if start is None else start
    directory = Path(settings.directory)
    columns = [c for pp in postprocessors for c in pp.columns]
    writer = StatisticsWriter(directory / "statistics.csv", columns, comm=model.comm)
    fields = FieldOutput(directory)
    progress = Progress(settings.end, mode=settings.progress, every=settings.progress_every, enabled=rank0)
    balance_log = BalanceLog(directory / "balance.csv", comm=model.comm)
    steady = SteadyState(settings.steady_tolerance, settings.steady_window)
    reason = "end time"
    row: dict[str, Any] = {}
    written = -1
    try:
        if model.flow_result is None:
            _report(model.start(), model.timestep, balance_log, progress)
        while True:
            with model.timers("postprocess"):
                row = {k: v for pp in postprocessors for k, v in pp(model).items()}
            writer.write(row)
            extra = f"Nu={row['nusselt']:.5g}" if "nusselt" in row else ""
            progress.update(model.timestep, model.time, model.dt_previous, row.get("vrms", np.nan), extra=extra)
            if settings.fields_every and model.timestep % settings.fields_every == 0:
                with model.timers("output"):
                    fields.write(model.fields(), model.time)
                written = model.timestep
            if model.time >= settings.end * (1.0 - 1e-12):
                break
            if settings.max_steps is not None and model.timestep >= settings.max_steps:
                reason = "max steps"
                break
            if steady(row):
                reason = "steady state"
                break
            if model.comm.allreduce(bool(should_stop()), op=MPI.LOR):
                reason = "stopped by signal"
                break
            _report(model.step(_timestep(model, settings)), model.timestep, balance_log, progress)
        with model.timers("output"):
            if written != model.timestep:
                fields.write(model.fields(), model.time)
            if model.particles is not None and model.particles.writer is not None:
                model.particles.update(model.property_context(), step=model.timestep, final=True)
    finally:
        writer.close()
        balance_log.close()
        progress.close()
        fields.close()
        # The solvers are done; free them now, on every rank together, not in the garbage collector.
        model.destroy()
    wall = time.monotonic() - start
    timings = model.timers.summary(model.comm, extra=model.particles.timings if model.particles else None, total=wall)
    summary = RunSummary(model.timestep, model.time, float(row.get("vrms", np.nan)), float(row.get("nusselt", np.nan)),
                         model.num_cells, wall, reason, timings)
    if rank0:
        (directory / "summary.json").write_text(json.dumps(summary.as_dict(), indent=2) + "\n")
        progress.message(f"finished ({reason}): step {summary.steps}, t={summary.time:.6g}, "
                         f"vrms={summary.vrms:.6g}, Nu={summary.nusselt:.6g}, {summary.cells} cells, "
                         f"{summary.wall_time:.1f} s")
        progress.message("time per phase (max over ranks):\n" + model.timers.table(timings))
    return summary
