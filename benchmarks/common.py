"""Helpers shared by the benchmark scripts: run a config with the CLI (optionally under mpirun, with
a wall-time limit), read a ``reference.csv`` and sample a statistics curve at fixed times.

The benchmark scripts (``benchmarks/<name>/run.py``, run as ``python -m benchmarks.<name>.run``)
import it as ``benchmarks.common``; their declaration, command line and load log are
:mod:`benchmarks.harness`.
"""

from __future__ import annotations

import csv
import subprocess
from dataclasses import dataclass
from pathlib import Path
from collections.abc import Mapping, Sequence

import numpy as np

from convection.launch import cli_command, mpi_environment

ROOT = Path(__file__).resolve().parents[1]

__all__ = ["ROOT", "CliRun", "curves_figure", "iterations_figure", "read_reference", "sample", "start_cli_run"]

# Exit codes of a run stopped by its wall-time limit: coreutils timeout (124) or the CLI's own
# 128 + SIGTERM when the signal reached it first.
_STOPPED_CODES = (124, 143)


@dataclass(frozen=True)
class CliRun:
    """A started ``python -m convection run`` process.

    Attributes:
        process: The process (mpirun, timeout or python).
        output: The run's output directory (statistics.csv, summary.json).
        command: The command line, for logs.
    """

    process: subprocess.Popen
    output: Path
    command: tuple[str, ...]

    def wait(self) -> int:
        """Wait for the end; returns the exit code. A run stopped by its time limit counts as done
        (its statistics.csv holds every finished step); any other failure raises."""
        code = self.process.wait()
        if code != 0 and code not in _STOPPED_CODES:
            raise subprocess.CalledProcessError(code, list(self.command))
        return code


def start_cli_run(config: Path, output: Path, /, *, ranks: int = 1, overrides: Sequence[str] = (),
                  time_limit: float | None = None, nice: int = 10, log: Path | None = None) -> CliRun:
    """Start the CLI on ``config`` in the background.

    Args:
        config: The YAML config.
        output: Output directory (``--output``).
        ranks: MPI ranks; > 1 runs under ``mpirun -n ranks --oversubscribe``.
        overrides: ``key.sub=value`` strings (``--set``), applied after quiet-output defaults.
        time_limit: Wall-time limit in seconds; the run then gets SIGTERM and stops cleanly.
        nice: Niceness of the run (0: none).
        log: File for the run's stdout and stderr (default: inherit).
    """
    env = mpi_environment()
    quiet = ["output.progress=lines", "output.progress_every=200", "output.fields_every=0"]
    cmd = cli_command(config, output, ranks=ranks, overrides=[*quiet, *overrides])
    if time_limit is not None:
        cmd = ["timeout", "-s", "TERM", str(int(time_limit)), *cmd]
    if nice:
        cmd = ["nice", "-n", str(nice), *cmd]
    output.mkdir(parents=True, exist_ok=True)
    print("$", " ".join(cmd), flush=True)
    stream = open(log, "w") if log is not None else None
    try:
        process = subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=stream, stderr=subprocess.STDOUT if stream else None)
    finally:
        if stream is not None:
            stream.close()
    return CliRun(process, output, tuple(cmd))


def read_reference(path: Path, /) -> list[dict[str, str]]:
    """Rows of a ``reference.csv`` (lines starting with ``#`` are comments)."""
    with open(path, newline="") as f:
        return list(csv.DictReader(line for line in f if not line.startswith("#")))


def sample(stats: dict[str, np.ndarray], key: str, times: Sequence[float], /) -> np.ndarray:
    """Column ``key`` linearly interpolated at ``times`` (NaN beyond the last step), shape=(len(times),)."""
    t = stats["time"]
    values = np.interp(np.asarray(times, dtype=np.float64), t, stats[key])
    values[np.asarray(times) > t[-1] * (1 + 1e-12)] = np.nan
    return values


def curves_figure(png: Path, curves: Sequence[tuple[np.ndarray, np.ndarray, str, dict]], /, *, xlabel: str,
                  ylabel: str, title: str = "", size: tuple[float, float] = (7.0, 4.5)) -> Path:
    """Draw ``(x, y, label, style)`` curves (style: matplotlib keyword arguments) into ``png``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=size, constrained_layout=True)
    for x, y, label, style in curves:
        ax.plot(x, y, label=label, **style)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    if title:
        ax.set_title(title)
    ax.legend(fontsize=8)
    fig.savefig(png, dpi=110)
    plt.close(fig)
    return png



def iterations_figure(png: Path, counts: Mapping[str, Sequence[int]], /, *, title: str) -> Path:
    """Nonlinear iterations per time step of the Picard and Newton runs (``counts["picard"]``,
    ``counts["newton"]``), on a log axis, into ``png``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4))
    for method in ("picard", "newton"):
        ax.plot(range(len(counts[method])), counts[method], "o-", ms=3, label=method)
    ax.set_xlabel("time step")
    ax.set_ylabel("nonlinear iterations to |F|/|b| <= 1e-8")
    ax.set_yscale("log")
    ax.legend()
    ax.set_title(title)
    fig.tight_layout()
    fig.savefig(png, dpi=110)
    plt.close(fig)
    return png
