"""The run loop: time steps of a :class:`~convection.model.model.Model` with statistics, output and stops.

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
from collections.abc import Callable, Mapping, Sequence
from typing import Any, NamedTuple

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from convection.model.model import Model, StepReport
from convection.io.fields import FIELD_WRITERS, FieldWriterContext, OutputSettings
from convection.io.output_units import output_units
from convection.io.profiles import ProfileFile
from convection.postprocess.postprocessors import (
    Nusselt, ParticleStatistics, Postprocessor, TemperatureStatistics, TimeColumns, Velocity,
)
from convection.schema import REQUIRED, param
from convection.run.progress import Progress
from convection.run.steady import SteadyRate, SteadyState
from convection.physics.scaling import ColumnUnits, Scaling
from convection.io.run_folder import RunFolderError
from particles.io.swarm_checkpoint import CheckpointError
from convection.io.statistics import BalanceLog, StatisticsFileError, StatisticsWriter

__all__ = ["BlowUp", "Resume", "RunFailure", "LoopSettings", "TimeSettings", "RunSummary",
           "SteadyRate", "SteadyState", "Watch", "Watched", "run"]


@dataclass(frozen=True)
class TimeSettings:
    """The ``time`` config section: how long a run goes and how long its steps are."""

    end: float = param(REQUIRED, exclusive_minimum=0.0, help="end time (nondimensional)")
    cfl: float = param(1.0, exclusive_minimum=0.0,
                       help="time step = cfl * min over cells of (cell size / (velocity degree * |u|))")
    dt_max: float | None = param(None, exclusive_minimum=0.0, help="longest time step (null: no limit)")
    dt_initial: float | None = param(None, exclusive_minimum=0.0, help="first step when the initial velocity is zero")
    max_increase: float | None = param(None, exclusive_minimum=1.0,
                                       help="a step is at most this many times the previous one (null: no limit); "
                                            "keeps the velocity extrapolation u* = (1 + w) u^n - w u^(n-1), "
                                            "w = dt/dt_previous, tame after a fast initial transient")
    max_steps: int | None = param(None, minimum=0, help="stop after this many steps (null: at time.end)")
    steady_state_tolerance: float | None = param(None, exclusive_minimum=0.0,
                                                 help="stop when Nu and vrms change by less than this (relative) over "
                                                      "the last steady_state_window steps (depends on the step length; "
                                                      "see steady_state_rate)")
    steady_state_window: int = param(20, minimum=1, help="steps over which the steady-state change is measured")
    steady_state_rate: float | None = param(None, exclusive_minimum=0.0,
                                            help="stop when R < this, R = max over Nu and vrms of "
                                                 "max_{t-tau<=s<=t} |q(s) - q(t)| / (|q(t)| tau), the relative change "
                                                 "per unit model time over tau = steady_state_time_window (does not "
                                                 "depend on the step length); the ETA extrapolates log R to it")
    steady_state_time_window: float = param(0.01, exclusive_minimum=0.0,
                                            help="tau: the model time over which steady_state_rate's change is "
                                                 "measured")


@dataclass(frozen=True)
class LoopSettings:
    """How long and how a run goes: the ``time`` and ``output`` sections."""

    time: TimeSettings
    output: OutputSettings
    scaling: Scaling | None = None
    """The model's units (None: a nondimensional model): statistics_physical.csv and progress lines."""


@dataclass(frozen=True)
class RunSummary:
    """What a finished (or stopped) run reached; ``timings`` per phase (see :mod:`fembase.timing`)."""

    steps: int
    time: float
    vrms: float
    nusselt: float
    cells: int
    wall_time: float
    reason: str
    timings: dict[str, dict[str, float]]
    stokes_assemblies: int = 0
    """How many times the Stokes operator was assembled (since the run or resume started)."""

    def as_dict(self) -> dict[str, Any]:
        return dict(self.__dict__)


def _timestep(model: Model, settings: LoopSettings) -> float:
    dt = model.cfl_dt(settings.time.cfl, dt_max=settings.time.dt_max)
    if not np.isfinite(dt) or dt <= 0.0:
        dt = settings.time.dt_initial or settings.time.dt_max or 0.0
        if dt <= 0.0:
            raise RuntimeError("the velocity is zero and neither time.dt_initial nor time.dt_max is set")
    if settings.time.max_increase is not None and model.dt_previous > 0.0:
        dt = min(dt, settings.time.max_increase * model.dt_previous)
    return min(dt, settings.time.end - model.time)


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


class Watched(NamedTuple):
    """What the blow-up and steady-state tests look at after a step (None: not in this model).

    Attributes:
        vrms: Root-mean-square velocity.
        T_min: Smallest nodal temperature.
        T_max: Largest nodal temperature.
        T_mean: Volume-mean temperature.
        n_particles: Global particle count.
        n_lost: Particles lost so far (cumulative).
        nusselt: Nusselt number at the top (only when measured, see :class:`Watch`).
    """

    vrms: float
    T_min: float | None = None
    T_max: float | None = None
    T_mean: float | None = None
    n_particles: int | None = None
    n_lost: int | None = None
    nusselt: float | None = None

    @classmethod
    def of(cls, values: Mapping[str, Any]) -> Watched:
        """The watched quantities among ``values`` (JSON-able: plain floats and ints)."""
        def plain(name: str, kind: type) -> Any:
            value = values.get(name)
            return None if value is None else kind(value)
        return cls(float(values["vrms"]), plain("T_min", float), plain("T_max", float), plain("T_mean", float),
                   plain("n_particles", int), plain("n_lost", int), plain("nusselt", float))


class Watch:
    """Measures :class:`Watched` after every step whatever columns ``statistics.csv`` has (collective).

    The values of the postprocessors the run has anyway (velocity, temperature, particles, Nusselt)
    are taken from their part of the row, at no extra cost; the others are computed here with the
    same postprocessors' code. The Nusselt number is measured only with ``nusselt=True`` (the
    steady-state test).

    Args:
        model: The model.
        postprocessors: The run's postprocessors (the row's producers).
        nusselt: Also measure the Nusselt number when the run's postprocessors do not.
    """

    def __init__(self, model: Model, postprocessors: Sequence[Postprocessor], /, *, nusselt: bool = False) -> None:
        reused = [cls for cls in (Velocity, TemperatureStatistics, Nusselt, ParticleStatistics)
                  if any(isinstance(pp, cls) for pp in postprocessors)]
        self._reused = [c for cls in reused for c in cls.columns]
        wanted = (Velocity, TemperatureStatistics, *((Nusselt,) if nusselt else ()))
        self._own = [cls() for cls in wanted if cls not in reused and cls.applies(model)]
        self._count = model.particles is not None and ParticleStatistics not in reused
        self._nusselt = nusselt

    def __call__(self, model: Model, row: Mapping[str, Any], /) -> Watched:
        """The watched quantities of ``model`` now; ``row`` is this step's row of the run's postprocessors."""
        values = {c: row[c] for c in self._reused}
        for pp in self._own:
            values.update(pp(model))
        if self._count:
            primary = model.particles.primary  # as the particles statistics' columns
            values.update(n_particles=primary.num_particles, n_lost=primary.lost)
        return Watched.of(values)

    def measure(self, model: Model, /) -> Watched:
        """The watched quantities computed afresh, without a row (e.g. right after a restore)."""
        return Watch(model, [], nusselt=self._nusselt)(model, {})


@dataclass(frozen=True)
class BlowUp:
    """When a run counts as failed: the ``blowup`` config section.

    The tests read :class:`Watched` quantities, measured whatever statistics columns the run writes.

    Attributes:
        vrms_growth: vrms growing by more than this factor in one step.
        max_vrms: vrms above this (None: no bound).
        temperature_margin: T leaving [T_min0 - m dT0, T_max0 + m dT0] (initial range dT0, at least 1).
        lost_fraction: More than this fraction of the initial particle count lost.
    """

    vrms_growth: float | None = param(1.0e3, exclusive_minimum=1.0,
                                      help="fail when vrms grows by more than this factor in one step")
    max_vrms: float | None = param(None, exclusive_minimum=0.0, help="fail when vrms exceeds this")
    temperature_margin: float | None = param(1.0, minimum=0.0,
                                             help="fail when T leaves the initial range widened by this many times its "
                                                  "width")
    lost_fraction: float | None = param(1.0e-3, minimum=0.0, maximum=1.0,
                                        help="fail when more than this fraction of the particles is lost")

    def check(self, now: Watched, first: Watched, previous: Watched | None) -> str | None:
        """What failed at this step (None: nothing); ``first`` is the run's first step (step 0, kept
        across resumes), ``previous`` the step before (None at the first)."""
        for key in ("vrms", "T_min", "T_max", "T_mean"):
            value = getattr(now, key)
            if value is not None and not np.isfinite(value):
                return f"{key} is {value}"
        vrms = now.vrms
        if self.max_vrms is not None and vrms > self.max_vrms:
            return f"vrms {vrms:.6g} exceeds blowup.max_vrms = {self.max_vrms:g}"
        if previous is not None and self.vrms_growth is not None and previous.vrms > 0 \
                and vrms > self.vrms_growth * previous.vrms:
            return f"vrms grew from {previous.vrms:.6g} to {vrms:.6g} in one step (more than blowup.vrms_growth)"
        if self.temperature_margin is not None and None not in (now.T_min, now.T_max, first.T_min, first.T_max):
            span = max(first.T_max - first.T_min, 1.0) * self.temperature_margin
            if now.T_min < first.T_min - span or now.T_max > first.T_max + span:
                return f"temperature left [{first.T_min - span:.6g}, {first.T_max + span:.6g}]: " \
                       f"min {now.T_min:.6g}, max {now.T_max:.6g}"
        if self.lost_fraction is not None and now.n_lost is not None \
                and now.n_lost > self.lost_fraction * max(first.n_particles or 0, 1):
            return f"{now.n_lost} particles lost (more than blowup.lost_fraction = {self.lost_fraction:g})"
        return None


@dataclass
class Resume:
    """What a resumed run continues from (see :mod:`convection.io.checkpoint`).

    Attributes:
        wall_seconds: Wall time of the run up to the checkpoint.
        postprocessors: Saved postprocessor states by name.
        first: The watched quantities of the run's first step (the blow-up reference), or None
            (a checkpoint written before they were kept: measured again on resuming).
        last: Those of the checkpoint's step (the blow-up test's previous step), or None.
        steady: The steady-state test's recent history (:meth:`SteadyState.state`), or None.
        steady_rate: The steady-state rate test's history (:meth:`SteadyRate.state`), or None.
    """

    wall_seconds: float
    postprocessors: dict[str, Any]
    first: Watched | None = None
    last: Watched | None = None
    steady: list[list[Any]] | None = None
    steady_rate: dict[str, Any] | None = None

    @classmethod
    def from_state(cls, state: Mapping[str, Any], /) -> Resume:
        """From the run loop's part of a checkpoint (what :func:`run` saved)."""
        watched = state.get("watched") or {}
        first, last = watched.get("first"), watched.get("last")
        return cls(float(state["wall_seconds"]), dict(state["postprocessors"]),
                   Watched.of(first) if first else None, Watched.of(last) if last else None, state.get("steady"),
                   state.get("steady_rate"))


class _Outputs:
    """The files a run writes as it goes: statistics, balance log, fields, progress (collective).

    Raises:
        RunFolderError: On every rank: a file to continue (resume) is missing or damaged, or a
            file cannot be written.
    """

    def __init__(self, model: Model, settings: LoopSettings, columns: list[str], resume: bool,
                 kinds: Mapping[str, str] | None = None, profiles: Sequence[Any] = ()) -> None:
        output = settings.output
        directory = Path(output.directory)
        # the profiles written with the fields (topography): postprocessors with a ``profile``
        self.profiles = [(pp, ProfileFile(directory / f"{pp.name}_profile.csv", model.comm,
                                          getattr(pp, "profile_quantities", {}), scaling=settings.scaling,
                                          resume_after=model.time if resume else None)) for pp in profiles]
        after = model.timestep if resume else None
        scaling = settings.scaling
        self.units = ColumnUnits(scaling, columns, kinds or {}) if scaling is not None else None
        try:
            self.statistics = StatisticsWriter(directory / "statistics.csv", columns, comm=model.comm,
                                               resume_after_step=after)
            self.physical = StatisticsWriter(directory / "statistics_physical.csv", self.units.header, comm=model.comm,
                                             resume_after_step=after) if self.units is not None else None
            self.balance = BalanceLog(directory / "balance.csv", comm=model.comm, resume_after_step=after)
        except StatisticsFileError as err:
            raise RunFolderError(str(err)) from None
        self.fields = FIELD_WRITERS.build(output.fields_format, output, FieldWriterContext(
            resume_after=model.time if resume else None, units=output_units(scaling) if scaling is not None else None))
        units = None if scaling is None else (scaling.factor("time"), scaling.unit_label("time"),
                                              scaling.factor("velocity"), scaling.unit_label("velocity"))
        self.progress = Progress(settings.time.end, mode=output.progress, every=output.progress_every,
                                 enabled=model.comm.rank == 0, units=units)
        if scaling is not None and not resume:
            approximation = model.stokes.approximation
            numbers = [f"Ra = {approximation.Ra:.6g}"] + [
                f"Rb_{f.name} = {rb:.6g}" for f, rb in zip(model.fractions, np.atleast_1d(approximation.Rb))]
            self.progress.message(f"{scaling.describe()}; {', '.join(numbers)}")
        if self.statistics.dropped_incomplete:
            self.progress.message("statistics.csv: its last line was cut off when the run stopped; dropped")
        self.fields_every = output.fields_every
        self.written = model.timestep if resume and output.fields_every and model.timestep % output.fields_every == 0 \
            else -1

    def row(self, model: Model, row: dict[str, Any], now: Watched, remaining: float | None = None) -> None:
        """Write a step's statistics row (and fields when due); ``remaining``: the model time
        estimated to a steady state, for the ETA (None: to the end time)."""
        self.statistics.write(row)
        if self.physical is not None and self.units is not None:
            self.physical.write(self.units.convert(row))
        extra = f"Nu={now.nusselt:.5g}" if now.nusselt is not None else ""
        self.progress.update(model.timestep, model.time, model.dt_previous, now.vrms, extra=extra, remaining=remaining)
        if self.fields_every and model.timestep % self.fields_every == 0:
            self.write_fields(model)

    def write_fields(self, model: Model) -> None:
        with model.timers("output"):
            self.fields.write(model.fields(), model.time)
            for pp, file in self.profiles:
                file.write(model.time, pp.profile(model))
        self.written = model.timestep

    def close(self) -> None:
        self.statistics.close()
        if self.physical is not None:
            self.physical.close()
        self.balance.close()
        self.progress.close()
        self.fields.close()


def _close(out: _Outputs, model: Model) -> None:
    """Close the run's files and free the solvers, on every rank together (collective)."""
    out.close()
    model.destroy()  # now, together, not in the garbage collector


def _with_time_columns(postprocessors: Sequence[Postprocessor]) -> list[Postprocessor]:
    """The postprocessors with the step, time and dt columns first (resume and pictures need them)."""
    if any(isinstance(pp, TimeColumns) for pp in postprocessors):
        return list(postprocessors)
    return [TimeColumns(), *postprocessors]


def run(model: Model, settings: LoopSettings, postprocessors: Sequence[Postprocessor], /, *,
        should_stop: Callable[[], bool] = lambda: False, start: float | None = None,
        checkpoints: Any = None, blowup: BlowUp = BlowUp(), resume: Resume | None = None) -> RunSummary:
    """Run ``model`` to ``settings.time.end`` (or max_steps, steady state, or a stop request). Collective.

    The blow-up and steady-state tests watch the model itself (:class:`Watch`), whatever
    statistics columns the postprocessors write; the columns step, time and dt are always written.

    Args:
        model: The model (started here if it was not).
        settings: Time and output settings.
        postprocessors: The statistics columns (:func:`convection.postprocess.postprocessors.create_postprocessors`).
        should_stop: Polled every step on every rank (e.g. a signal flag); the run stops when it
            is True on any rank, with everything written.
        start: ``time.monotonic()`` at the start of the run (default: now).
        checkpoints: A :class:`convection.io.checkpoint.Checkpointer`, or None.
        blowup: When the run counts as failed.
        resume: Continue a run restored from a checkpoint: its statistics, field and particle
            series are continued after the checkpoint's step, the blow-up and steady-state tests
            with the checkpoint's references.

    Raises:
        RunFailure: The run blew up or a solver failed (summary.json says so; on every rank).
        RunFolderError: A file to continue is missing or damaged (on every rank, before any step).
    """
    loop = _RunLoop(model, settings, postprocessors, start=start, checkpoints=checkpoints, blowup=blowup)
    if resume is not None:
        loop.resume(resume)
    return loop.run(should_stop)


class _RunLoop:
    """The state of one :func:`run`: its outputs, the watched quantities and the stop tests."""

    def __init__(self, model: Model, settings: LoopSettings, postprocessors: Sequence[Postprocessor], /, *,
                 start: float | None, checkpoints: Any, blowup: BlowUp) -> None:
        self.model = model
        self.settings = settings
        self.start = time.monotonic() if start is None else start
        self.postprocessors = _with_time_columns(postprocessors)
        self.checkpoints = checkpoints
        self.blowup = blowup
        self.out: _Outputs | None = None
        time_settings = settings.time
        self.steady = SteadyState(time_settings.steady_state_tolerance, time_settings.steady_state_window)
        self.steady_rate = SteadyRate(time_settings.steady_state_rate, time_settings.steady_state_time_window)
        steady = time_settings.steady_state_tolerance is not None or time_settings.steady_state_rate is not None
        self.watch = Watch(model, self.postprocessors, nusselt=steady)
        self.first: Watched | None = None
        self.now: Watched | None = None
        self.report = True
        self.resumed = False

    def resume(self, resume: Resume, /) -> None:
        """Continue a run restored from a checkpoint (its references and postprocessor states)."""
        self.start -= resume.wall_seconds
        for pp in self.postprocessors:
            pp.restore(resume.postprocessors.get(pp.name) or {})
            if pp.name == "wall_time":
                pp.start = self.start
        # A checkpoint written before the references were kept: they are measured now.
        self.now = resume.last or self.watch.measure(self.model)
        self.first = resume.first or self.now
        self.steady.restore(resume.steady or [])
        self.steady_rate.restore(resume.steady_rate)
        self.report = False
        self.resumed = True

    def run(self, should_stop: Callable[[], bool], /) -> RunSummary:
        """Step to the end (see :func:`run`). Collective."""
        model = self.model
        columns = [c for pp in self.postprocessors for c in pp.columns]
        kinds = {c: k for pp in self.postprocessors for c, k in getattr(pp, "quantities", {}).items()}
        profiles = [pp for pp in self.postprocessors if callable(getattr(pp, "profile", None))]
        self.out = out = _Outputs(model, self.settings, columns, self.resumed, kinds, profiles)
        reason, failure = "end time", None
        try:
            reason, failure = self._steps(should_stop)
            if failure is None:
                self._finish()
        except BaseException as err:
            # Closing the files and freeing the solvers are collective: only when every rank is here.
            # An error met on one rank alone (a bug, a failed write) may leave the others inside a
            # collective call, where cleaning up would wait forever; the command line stops them all.
            if model.comm.size == 1 or isinstance(err, CheckpointError):  # CheckpointErrors: raised on every rank
                _close(out, model)
            raise
        _close(out, model)
        if failure is not None:  # the time in the model's units, as the progress shows it
            reason = f"failed at step {model.timestep}, t={out.progress.time_text(model.time)}: {failure}"
        summary = self._summary(reason)
        if failure is not None:
            raise RunFailure(reason)
        return summary

    def _steps(self, should_stop: Callable[[], bool]) -> tuple[str, str | None]:
        """The steps: (why they stopped, what failed or None)."""
        model, out = self.model, self.out
        if model.flow_result is None:
            try:
                _report(model.start(), model.timestep, out.balance, out.progress)
            except SOLVER_ERRORS as err:
                return "end time", " ".join(str(err).split())
        while True:
            if self.report:
                failure = self._row()
                if failure:
                    return "end time", failure
            self.report = True
            reason = self._stop(should_stop)
            if reason is not None:
                return reason, None
            try:
                _report(model.step(_timestep(model, self.settings)), model.timestep, out.balance, out.progress)
            except SOLVER_ERRORS as err:
                return "end time", " ".join(str(err).split())

    def _row(self) -> str | None:
        """This step's statistics row, outputs and checkpoint; what blew up, or None."""
        model = self.model
        previous = self.now
        with model.timers("postprocess"):
            row = {k: v for pp in self.postprocessors for k, v in pp(model).items()}
            self.now = self.watch(model, row)
        self.first = self.first or self.now
        self.out.row(model, row, self.now, self.steady_rate.remaining())
        failure = self.blowup.check(self.now, self.first, previous)
        if failure:
            return failure
        if self.checkpoints is not None and self.checkpoints.due(model):
            self.checkpoints.write(model, self._state())
        return None

    def _stop(self, should_stop: Callable[[], bool]) -> str | None:
        """Why the run stops after this step, or None."""
        model, time_settings = self.model, self.settings.time
        if model.time >= time_settings.end * (1.0 - 1e-12):
            return "end time"
        if time_settings.max_steps is not None and model.timestep >= time_settings.max_steps:
            return "max steps"
        watched = self.now._asdict()
        if self.steady(watched, model.timestep):
            return "steady state"
        if self.steady_rate(watched, model.timestep, model.time):
            return "steady state"
        if model.comm.allreduce(bool(should_stop()), op=MPI.LOR):
            return "stopped by signal"
        return None

    def _state(self) -> dict[str, Any]:
        return _state(self.postprocessors, self.start, self.first, self.now, self.steady, self.steady_rate)

    def _finish(self) -> None:
        """The last fields, particles and checkpoint of a run that did not fail."""
        model, out = self.model, self.out
        if out.written != model.timestep:
            out.write_fields(model)
        with model.timers("output"):
            if model.particles is not None and model.particles.writes:
                model.particles.update(model.property_context(), step=model.timestep, final=True)
        if self.checkpoints is not None and self.checkpoints.settings.at_end:
            self.checkpoints.write(model, self._state(), only_if_new=True)

    def _summary(self, reason: str) -> RunSummary:
        """The summary (written to summary.json and shown by rank 0)."""
        model, now = self.model, self.now
        wall = time.monotonic() - self.start
        timings = model.timers.summary(model.comm, extra=model.particles.timings if model.particles else None,
                                       total=wall)
        vrms = now.vrms if now is not None else np.nan
        nusselt = now.nusselt if now is not None and now.nusselt is not None else np.nan
        summary = RunSummary(model.timestep, model.time, float(vrms), float(nusselt), model.num_cells, wall, reason,
                             timings, model.stokes_assemblies)
        if model.comm.rank == 0:
            (Path(self.settings.output.directory) / "summary.json").write_text(
                json.dumps(summary.as_dict(), indent=2) + "\n")
            progress = self.out.progress
            nusselt = f"Nu={summary.nusselt:.6g}, " if np.isfinite(summary.nusselt) else ""
            progress.message(f"finished ({reason}): step {summary.steps}, t={progress.time_text(summary.time)}, "
                             f"vrms={progress.velocity_text(summary.vrms)}, {nusselt}{summary.cells} cells, "
                             f"{summary.wall_time:.1f} s")
            times = "time" if summary.stokes_assemblies == 1 else "times"
            self.out.progress.message(f"Stokes solver {model.stokes.description}, operator assembled "
                                      f"{summary.stokes_assemblies} {times}; time per phase "
                                      "(max over ranks):\n" + model.timers.table(timings))
        return summary


def _state(postprocessors: Sequence[Postprocessor], start: float, first: Watched | None, last: Watched | None,
           steady: SteadyState, steady_rate: SteadyRate) -> dict[str, Any]:
    """The run loop's part of a checkpoint (JSON-able): what :meth:`Resume.from_state` reads."""
    return {"wall_seconds": time.monotonic() - start,
            "postprocessors": {pp.name: pp.state().scalars for pp in postprocessors},
            "watched": {"first": first._asdict() if first else None, "last": last._asdict() if last else None},
            "steady": steady.state(), "steady_rate": steady_rate.state()}
