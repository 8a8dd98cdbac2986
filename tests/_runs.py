"""Runs of the command line in subprocesses, for tests (``from _runs import ...``): start, kill
(SIGKILL of the whole process group), resume, and read back what a run wrote.

A subprocess that hangs must not hang the test suite, and a machine that is merely busy must not
fail a test. So no run here has a wall-clock deadline: each has a budget counted in an idle
machine's seconds (:class:`Watchdog`), and a second of wall time counts only as much as the share
of the machine's cores the load left free in it."""

from __future__ import annotations

import csv
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from collections.abc import Callable, Iterator

import h5py
import numpy as np
import yaml

from convection.config.particle_systems import document_generators
from convection.launch import mpi_environment, mpirun

ROOT = Path(__file__).resolve().parents[1]
CONFIGS = ROOT / "configs"


def command(args: list[str], ranks: int = 1) -> list[str]:
    """``python -m convection ARGS``, under MPI's launcher with RANKS ranks when ranks > 1."""
    cmd = [sys.executable, "-m", "convection", *args]
    if ranks > 1:
        cmd = [*mpirun(ranks), *cmd]
    return cmd


def env() -> dict[str, str]:
    """The environment of a run under mpirun (:func:`convection.launch.mpi_environment`)."""
    return mpi_environment()


def shrink(config: Path, *, divisor: int, coarsen: float, max_particles: int, max_per_cell: int) -> list[str]:
    """Overrides that make a shipped config smaller and keep its features: a box gets its cells
    per direction divided by ``divisor`` (at least 4), a shell a cell size ``coarsen`` times
    larger; particle counts are capped at ``max_particles`` or ``max_per_cell`` per cell."""
    raw = yaml.safe_load(Path(config).read_text())
    mesh = raw["mesh"]
    if "cells" in mesh:
        extra = [f"mesh.cells=[{','.join(str(max(4, c // divisor)) for c in mesh['cells'])}]"]
    else:  # a shell meshed by gmsh to a resolution
        extra = [f"mesh.resolution={mesh['resolution'] * coarsen:.3g}"]
    for prefix, generator in document_generators(raw).items():
        if "particles_per_cell" in generator:
            extra.append(f"{prefix}.generator.particles_per_cell={min(max_per_cell, generator['particles_per_cell'])}")
        if "num_particles" in generator:
            extra.append(f"{prefix}.generator.num_particles={min(max_particles, generator['num_particles'])}")
    return extra


def sets(items: list[str]) -> list[str]:
    """``--set`` arguments for config overrides ``key=value``."""
    return [a for item in items for a in ("--set", item)]


class Watchdog:
    """A time budget in idle-machine seconds: each wall-clock second counts ``cores / load``
    (at most 1), the share of the machine a run gets at the 1-minute load average. At a load of
    30 on 2 cores a budget of 300 s lasts 75 minutes of wall time; on an idle machine, 5."""

    def __init__(self, budget: float) -> None:
        self.budget = budget
        self.spent = 0.0
        self._last = time.monotonic()

    def expired(self) -> bool:
        """Count the time since the last call; whether the budget is spent."""
        now = time.monotonic()
        cores = len(os.sched_getaffinity(0))
        self.spent += (now - self._last) * min(1.0, cores / max(os.getloadavg()[0], 1e-9))
        self._last = now
        return self.spent > self.budget


def guarded_run(argv: list[str], *, budget: float = 300, **kwargs) -> subprocess.CompletedProcess:
    """``subprocess.run(argv, capture_output=True, text=True, **kwargs)`` that kills the process and
    everything it started (its session) and raises ``subprocess.TimeoutExpired`` only once
    ``budget`` idle-machine seconds are spent (:class:`Watchdog`)."""
    watchdog = Watchdog(budget)
    with subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
                          **kwargs) as proc:
        while True:
            try:
                out, err = proc.communicate(timeout=2)
                break
            except subprocess.TimeoutExpired:
                if watchdog.expired():
                    kill_session(proc.pid)
                    out, err = proc.communicate()
                    raise subprocess.TimeoutExpired(argv, budget, out, err) from None
    return subprocess.CompletedProcess(argv, proc.returncode, out, err)


def run_cli(args: list[str], ranks: int = 1, budget: float = 300) -> subprocess.CompletedProcess:
    """Run the command line to the end; returns the finished process (text output captured).
    ``budget``: idle-machine seconds before a hung run is killed (:func:`guarded_run`)."""
    return guarded_run(command(args, ranks), budget=budget, cwd=ROOT, env=env())


def run_on_ranks(config: Path, folders: dict[int, Path], extra: list[str] = ()) -> dict[int, Path]:
    """Run ``config`` with the overrides ``extra`` into ``folders[ranks]`` on each rank count
    (asserting that each run ends well); returns ``folders``."""
    for ranks, folder in folders.items():
        proc = run_cli(["run", str(config), "--output", str(folder), *sets(list(extra))], ranks)
        assert proc.returncode == 0, proc.stderr
    return folders


def rows(run_dir: Path) -> list[dict[str, str]]:
    """The rows of a run's statistics.csv, as written (strings)."""
    with open(Path(run_dir) / "statistics.csv", newline="") as f:
        return list(csv.DictReader(f))


def assert_same_statistics(a: Path, b: Path, *, ignore: tuple[str, ...] = ("wall_time",)) -> None:
    """The statistics of two runs equal to the last digit in every column but ``ignore``."""
    rows_a, rows_b = rows(a), rows(b)
    assert [r["step"] for r in rows_a] == [r["step"] for r in rows_b]
    assert list(rows_a[0]) == list(rows_b[0])
    for x, y in zip(rows_a, rows_b):
        for key in x:
            if key not in ignore:
                assert x[key] == y[key], (key, x["step"], x[key], y[key])


def final_particles(run_dir: Path, part: str = "particles") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Ids, positions and properties of the particles in the newest checkpoint (its ``part``: a
    particle system's file stem), sorted by id."""
    from convection.io.checkpoint import latest_checkpoint

    with h5py.File(latest_checkpoint(run_dir) / f"{part}.h5", "r") as f:
        ids = f["ids"][...]
        order = np.argsort(ids)
        return ids[order], f["x"][...][order], f["properties"][...][order]


def final_property(run_dir: Path, name: str) -> np.ndarray:
    """The values of the particle property ``name`` in the newest checkpoint, sorted by id
    (shape=(n,) for a scalar, (n, size) otherwise)."""
    from convection.io.checkpoint import latest_checkpoint

    with h5py.File(latest_checkpoint(run_dir) / "particles.h5", "r") as f:
        names = [n.decode() if isinstance(n, bytes) else str(n) for n in f["layout/names"][...]]
        k = names.index(name)
        start, size = int(f["layout/starts"][k]), int(f["layout/sizes"][k])
        order = np.argsort(f["ids"][...])
        values = f["properties"][...][order, start:start + size]
    return values[:, 0] if size == 1 else values


def _processes() -> Iterator[tuple[int, list[str]]]:
    """Every process's pid and the fields of its /proc stat after "pid (comm)": state ppid pgrp
    session ..."""
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        yield int(stat.parent.name), fields


def children(parent: int) -> list[int]:
    """The processes ``parent`` started (under mpirun: its ranks, with Open MPI 4 and 5 alike)."""
    return [pid for pid, fields in _processes() if int(fields[1]) == parent]


def kill_session(leader: int) -> None:
    """SIGKILL every process of the session ``leader`` leads (a process started with
    ``start_new_session=True``): mpirun and all its ranks. Open MPI 4 keeps the ranks in mpirun's
    process group; Open MPI 5 (prterun) gives each rank a group of its own, in the same session."""
    for pid, fields in _processes():
        if int(fields[3]) == leader:
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass


def kill_run(config: Path, run_dir: Path, ranks: int, extra: list[str], *, when: Callable[[Path], bool],
             budget: float = 300) -> int:
    """Start ``run CONFIG`` and SIGKILL it and all its ranks as soon as ``when(run_dir)`` (or once
    ``budget`` idle-machine seconds are spent, :class:`Watchdog`); returns the exit code
    (negative: killed)."""
    proc = subprocess.Popen(command(["run", str(config), "--output", str(run_dir), *sets(extra)], ranks),
                            cwd=ROOT, env=env(), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True)
    watchdog = Watchdog(budget)
    while proc.poll() is None and not watchdog.expired():
        if when(run_dir):
            kill_session(proc.pid)
            break
        time.sleep(0.002)
    proc.wait(timeout=60)
    return proc.returncode


def kill_and_resume(config: Path, run_dir: Path, ranks: int, extra: list[str], *, after_rows: int) -> None:
    """Run ``config`` into ``run_dir``, SIGKILL it once its statistics have more than ``after_rows``
    lines and resume it from its newest checkpoint on as many ranks, asserting each stage (it was
    killed, had a checkpoint, and the resumed run ended well without a note)."""
    from convection.io.checkpoint import latest_checkpoint

    code = kill_run(config, run_dir, ranks, extra, when=lambda d: rows_written(d, after_rows))
    assert code != 0, "the run ended before it was killed"
    assert latest_checkpoint(run_dir) is not None
    proc = run_cli(["resume", str(run_dir)], ranks)
    assert proc.returncode == 0, proc.stderr
    assert "note:" not in proc.stderr, proc.stderr


def rows_written(run_dir: Path, n: int) -> bool:
    """Whether statistics.csv has more than ``n`` lines."""
    path = run_dir / "statistics.csv"
    return path.exists() and len(path.read_text().splitlines()) > n


def writing_checkpoint(run_dir: Path) -> bool:
    """Whether a checkpoint is being written (its hidden temporary folder exists)."""
    folder = run_dir / "checkpoints"
    return folder.exists() and any(p.name.startswith(".checkpoint_") for p in folder.iterdir())


def error_line(proc: subprocess.CompletedProcess, code: int, needle: str = "") -> str:
    """The one ``error...`` line a refused command printed (asserting exit code ``code``, exactly one
    such line containing ``needle``, no traceback and no MPI abort block)."""
    lines = [ln for ln in proc.stderr.splitlines() if ln.startswith("error")]
    assert proc.returncode == code, proc.stderr
    assert len(lines) == 1 and needle in lines[0], proc.stderr
    assert "Traceback" not in proc.stderr and "MPI_ABORT" not in proc.stderr, proc.stderr
    return lines[0]
