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
from petsc4py import PETSc

from convection.model import Model, StepReport
from convection.output import FieldOutput
from convection.postprocess import Postprocessor
from convection.progress import Progress
from convection.statistics import BalanceLog, StatisticsWriter

__all__ = ["BlowUp", "Resume", "RunFailure", "RunSettings", "RunSummary", "SteadyState", "run"]


@dataclass(frozen=True)
class RunSettings:
    """How long and how a run goes (the ``time`` and ``output`` sections).

    Attributes:
        end: End time.
        cfl: Courant number of the step.
        dt_max: Largest step, or None.
        dt_initial: Step used while the velocity is zero, or None.
        max_increase: A step is at most this factor times the previous one, or None.
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
    max_increase: float | None = None
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
    if settings.max_increase is not None and model.dt_previous > 0.0:
        dt = min(dt, settings.max_increase * model.dt_previous)
    return min(dt, settings.end - model.time)


def _report(report: StepReport, step: int, balance_log: BalanceLog, progress: Progress) -> None:
    """Log what happened to the mesh in a step."""
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


SOLVER_ERRORS = (RuntimeError, FloatingPointError, PETSc.Error)
"""What a failing solve raises (on every rank: convergence is decided globally)."""


class RunFailure(RuntimeError):
    """The run cannot go on (blow-up, solver failure, lost particles); one line naming the step."""


@dataclass(frozen=True)
class BlowUp:
    """When a run counts as failed (the ``blowup`` section).

    Attributes:
        vrms_growth: vrms growing by more than this factor in one step.
        max_vrms: vrms above this (None: no bound).
        temperature_margin: T leaving [T_min0 - m dT0, T_max0 + m dT0] (initial range dT0, at least 1).
        lost_fraction: More than this fraction of the particles lost.
    """

    vrms_growth: float | None = 1.0e3
    max_vrms: float | None = None
    temperature_margin: float | None = 1.0
    lost_fraction: float | None = 1.0e-3

    def check(self, row: dict[str, float], first: dict[str, float], previous: dict[str, float] | None) -> str | None:
        """What failed in ``row`` (None: nothing); ``first`` is the first row of the run."""
        for key in ("vrms", "T_min", "T_max", "T_mean"):
            if key in row and not np.isfinite(row[key]):
                return f"{key} is {row[key]}"
        vrms = row.get("vrms")
        if vrms is not None and self.max_vrms is not None and vrms > self.max_vrms:
            return f"vrms {vrms:.6g} exceeds blowup.max_vrms = {self.max_vrms:g}"
        if vrms is not None and previous and self.vrms_growth is not None and previous["vrms"] > 0 \
                and vrms > self.vrms_growth * previous["vrms"]:
            return f"vrms grew from {previous['vrms']:.6g} to {vrms:.6g} in one step (more than blowup.vrms_growth)"
        if self.temperature_margin is not None and "T_min" in row:
            span = max(first["T_max"] - first["T_min"], 1.0) * self.temperature_margin
            if row["T_min"] < first["T_min"] - span or row["T_max"] > first["T_max"] + span:
                return f"temperature left [{first['T_min'] - span:.6g}, {first['T_max'] + span:.6g}]: " \
                       f"min {row['T_min']:.6g}, max {row['T_max']:.6g}"
        if self.lost_fraction is not None and row.get("n_lost", 0) > self.lost_fraction * max(first.get("n_particles", 0), 1):
            return f"{int(row['n_lost'])} particles lost (more than blowup.lost_fraction = {self.lost_fraction:g})"
        return None


@dataclass
class Resume:
    """What a resumed run continues from (see :mod:`convection.checkpoint`).

    Attributes:
        wall_seconds: Wall time of the run up to the checkpoint.
        postprocessors: Saved postprocessor states by name.
    """

    wall_seconds: float
    postprocessors: dict[str, Any]


class _Outputs:
    """The files a run writes as it goes: statistics, balance log, fields, progress (collective)."""

    def __init__(self, model: Model, settings: RunSettings, columns: list[str], resume: bool) -> None:
        directory = Path(settings.directory)
        after = model.timestep if resume else None
        self.statistics = StatisticsWriter(directory / "statistics.csv", columns, comm=model.comm, resume_after_step=after)
        self.balance = BalanceLog(directory / "balance.csv", comm=model.comm, resume_after_step=after)
        self.fields = FieldOutput(directory, resume_after=model.time if resume else None)
        self.progress = Progress(settings.end, mode=settings.progress, every=settings.progress_every,
                                 enabled=model.comm.rank == 0)
        self.fields_every = settings.fields_every
        self.written = model.timestep if resume and settings.fields_every and model.timestep % settings.fields_every == 0 \
            else -1

    def row(self, model: Model, row: dict[str, Any]) -> None:
        self.statistics.write(row)
        extra = f"Nu={row['nusselt']:.5g}" if "nusselt" in row else ""
        self.progress.update(model.timestep, model.time, model.dt_previous, row.get("vrms", np.nan), extra=extra)
        if self.fields_every and model.timestep % self.fields_every == 0:
            self.write_fields(model)

    def write_fields(self, model: Model) -> None:
        with model.timers("output"):
            self.fields.write(model.fields(), model.time)
        self.written = model.timestep

    def close(self) -> None:
        self.statistics.close()
        self.balance.close()
        self.progress.close()
        self.fields.close()


def _history(directory: Path, comm: Any) -> list[dict[str, float]]:
    """The rows of an existing statistics.csv (rank 0 reads, every rank gets them)."""
    rows = None
    if comm.rank == 0:
        import csv

        with open(directory / "statistics.csv", newline="") as f:
            rows = [{k: float(v) for k, v in r.items()} for r in csv.DictReader(f)]
    return comm.bcast(rows, root=0)


def run(model: Model, settings: RunSettings, postprocessors: Sequence[Postprocessor], /, *,
        should_stop: Callable[[], bool] = lambda: False, start: float | None = None,
        checkpoints: Any = None, blowup: BlowUp = BlowUp(), resume: Resume | None = None) -> RunSummary:
    """Run ``model`` to ``settings.end`` (or max_steps, steady state, or a stop request). Collective.

    Args:
        model: The model (started here if it was not).
        settings: Time and output settings.
        postprocessors: The statistics columns (:func:`convection.postprocess.create_postprocessors`).
        should_stop: Polled every step on every rank (e.g. a signal flag); the run stops when it
            is True on any rank, with everything written.
        start: ``time.monotonic()`` at the start of the run (default: now).
        checkpoints: A :class:`convection.checkpoint.Checkpointer`, or None.
        blowup: When the run counts as failed.
        resume: Continue a run restored from a checkpoint: its statistics, field and particle
            series are continued after the checkpoint's step.

    Raises:
        RunFailure: The run blew up or a solver failed (summary.json says so; on every rank).
    """
    rank0 = model.comm.rank == 0
    start = time.monotonic() if start is None else start
    directory = Path(settings.directory)
    columns = [c for pp in postprocessors for c in pp.columns]
    out = _Outputs(model, settings, columns, resume is not None)
    steady = SteadyState(settings.steady_tolerance, settings.steady_window)
    reason, failure = "end time", None
    row: dict[str, Any] = {}
    first: dict[str, Any] | None = None
    report = True
    if resume is not None:
        start -= resume.wall_seconds
        history = [r for r in _history(directory, model.comm) if r["step"] <= model.timestep]
        first, row = history[0], history[-1]
        for old in history:
            steady(old)
        for pp in postprocessors:
            if hasattr(pp, "restore") and pp.name in resume.postprocessors:
                pp.restore(resume.postprocessors[pp.name])
            if pp.name == "wall_time":
                pp.start = start
        report = False
    try:
        if model.flow_result is None:
            try:
                _report(model.start(), model.timestep, out.balance, out.progress)
            except SOLVER_ERRORS as err:
                failure = " ".join(str(err).split())
        while failure is None:
            if report:
                previous = row
                with model.timers("postprocess"):
                    row = {k: v for pp in postprocessors for k, v in pp(model).items()}
                first = first or row
                out.row(model, row)
                failure = blowup.check(row, first, previous if previous is not row else None)
                if failure:
                    break
                if checkpoints is not None and checkpoints.due(model):
                    checkpoints.write(model, _state(postprocessors, start))
            report = True
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
            try:
                _report(model.step(_timestep(model, settings)), model.timestep, out.balance, out.progress)
            except SOLVER_ERRORS as err:
                failure = " ".join(str(err).split())
                break
        if failure is None:
            if out.written != model.timestep:
                out.write_fields(model)
            with model.timers("output"):
                if model.particles is not None and model.particles.writer is not None:
                    model.particles.update(model.property_context(), step=model.timestep, final=True)
            if checkpoints is not None and checkpoints.settings.at_end:
                checkpoints.write(model, _state(postprocessors, start), only_if_new=True)
    finally:
        out.close()
        # The solvers are done; free them now, on every rank together, not in the garbage collector.
        model.destroy()
    if failure is not None:
        reason = f"failed at step {model.timestep}, t={model.time:.6g}: {failure}"
    wall = time.monotonic() - start
    timings = model.timers.summary(model.comm, extra=model.particles.timings if model.particles else None, total=wall)
    summary = RunSummary(model.timestep, model.time, float(row.get("vrms", np.nan)), float(row.get("nusselt", np.nan)),
                         model.num_cells, wall, reason, timings)
    if rank0:
        (directory / "summary.json").write_text(json.dumps(summary.as_dict(), indent=2) + "\n")
        out.progress.message(f"finished ({reason}): step {summary.steps}, t={summary.time:.6g}, "
                             f"vrms={summary.vrms:.6g}, Nu={summary.nusselt:.6g}, {summary.cells} cells, "
                             f"{summary.wall_time:.1f} s")
        out.progress.message("time per phase (max over ranks):\n" + model.timers.table(timings))
    if failure is not None:
        raise RunFailure(reason)
    return summary


def _state(postprocessors: Sequence[Postprocessor], start: float) -> dict[str, Any]:
    """The run loop's part of a checkpoint (JSON-able)."""
    return {"wall_seconds": time.monotonic() - start,
            "postprocessors": {pp.name: pp.state() for pp in postprocessors if hasattr(pp, "state")}}
