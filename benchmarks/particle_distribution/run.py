"""Population control by count against by density over a long run: configs/vankeken_1a_particles.yaml
(van Keken et al. 1997 case 1a, adaptive mesh, 10 to 40 particles per cell) to ``--end`` (2000).

Usage::

    python -m benchmarks.particle_distribution.run                  # both methods to t = 2000, 1 rank
    python -m benchmarks.particle_distribution.run --end 300 --ranks 2
    python -m benchmarks.particle_distribution.run --report-only    # table and picture from log/

Each method (``particles.population.method: count`` and ``density``) runs once, one after the
other, with the statistics ``time, mesh, particles, particle_distribution, wall_time``: the
distribution score of ASPECT's benchmark (per cell ``S = sum_b (c_b - n/B)^2 / (n^2 (B-1)/B)`` over
``B = 4`` equal sub-cells, 0 even .. 1 all in one; :mod:`particles.population.distribution`) and the
particles per cell min/mean/max. The runs' statistics.csv and output are kept in ``log/``
(``log/<method>.csv``, ``log/<method>.log``); ``results.md`` gets the table (every 250 time units
and the averages over the run) and ``distribution.png`` the curves. The last line printed is JSON.
"""

from __future__ import annotations

import json
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks.common import start_cli_run
from benchmarks.harness import Benchmark
from convection.io.pictures import read_statistics

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
BENCHMARK = Benchmark(__doc__, results=HERE, results_option=True, ranks=1,
                      helps={"ranks": "MPI ranks of each run (default 1)",
                             "results": "folder of results.md, distribution.png, log/"})

CONFIG = ROOT / "configs" / "vankeken_1a_particles.yaml"
METHODS = ("count", "density")
STATISTICS = "[time,mesh,particles,particle_distribution,wall_time]"


def run_method(method: str, *, end: float, ranks: int, log: Path) -> float:
    """Run the config with ``method`` to ``end``; keep statistics and output in ``log``; wall time."""
    with tempfile.TemporaryDirectory(prefix=f"pd_{method}_") as work:
        out = Path(work) / "run"
        overrides = [f"time.end={end}", f"particles.population.method={method}", f"output.statistics={STATISTICS}",
                     "particles.output.every_time=null"]
        start = time.monotonic()
        start_cli_run(CONFIG, out, ranks=ranks, overrides=overrides, log=log / f"{method}.log").wait()
        wall = time.monotonic() - start
        shutil.copy(out / "statistics.csv", log / f"{method}.csv")
    return wall


def _at(stats: dict[str, np.ndarray], key: str, t: float) -> float:
    """The value of ``key`` at the first step at or after time ``t`` (NaN past the end)."""
    i = int(np.searchsorted(stats["time"], t - 1e-9))
    return float(stats[key][i]) if i < stats["time"].shape[0] else float("nan")


def _mean_in_time(stats: dict[str, np.ndarray], key: str) -> float:
    """Time average of ``key`` over the run (each step's value over its step length)."""
    dt = np.diff(stats["time"])
    return float((stats[key][1:] * dt).sum() / dt.sum()) if dt.sum() > 0 else float(stats[key][-1])


def table(stats: dict[str, dict[str, np.ndarray]], end: float) -> str:
    """Markdown table: score and particles per cell of both methods, every 250 time units."""
    lines = ["| t | score count | score density | max score count | max score density | ppc count min/mean/max "
             "| ppc density min/mean/max |", "|---|---|---|---|---|---|---|"]
    times = [t for t in np.arange(0.0, end + 1e-9, 250.0)] + ([end] if end % 250 else [])
    for t in times:
        cells = [f"{t:g}"]
        cells += [f"{_at(stats[m], 'distribution_score', t):.4f}" for m in METHODS]
        cells += [f"{_at(stats[m], 'distribution_score_max', t):.3f}" for m in METHODS]
        cells += [f"{_at(stats[m], 'ppc_min', t):.0f} / {_at(stats[m], 'ppc_mean', t):.2f} / "
                  f"{_at(stats[m], 'ppc_max', t):.0f}" for m in METHODS]
        lines.append("| " + " | ".join(cells) + " |")
    avg = ["time average"] + [f"{_mean_in_time(stats[m], 'distribution_score'):.4f}" for m in METHODS]
    avg += [f"{_mean_in_time(stats[m], 'distribution_score_max'):.3f}" for m in METHODS]
    avg += [f"{stats[m]['ppc_min'].min():.0f} / {_mean_in_time(stats[m], 'ppc_mean'):.2f} / "
            f"{stats[m]['ppc_max'].max():.0f}" for m in METHODS]
    lines.append("| " + " | ".join(avg) + " |")
    return "\n".join(lines) + "\n"


def figure(stats: dict[str, dict[str, np.ndarray]], png: Path) -> None:
    """Score (mean and max over cells) and particles per cell (min/mean/max) over time, both methods."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(8, 7), sharex=True, constrained_layout=True)
    colours = {"count": "tab:red", "density": "tab:blue"}
    for m in METHODS:
        s, c = stats[m], colours[m]
        ax1.plot(s["time"], s["distribution_score"], color=c, label=f"{m}: mean over cells")
        ax1.plot(s["time"], s["distribution_score_max"], color=c, ls=":", lw=0.8, label=f"{m}: max over cells")
        ax2.plot(s["time"], s["ppc_mean"], color=c, label=f"{m}: mean")
        ax2.plot(s["time"], s["ppc_min"], color=c, ls="--", lw=0.8, label=f"{m}: min / max")
        ax2.plot(s["time"], s["ppc_max"], color=c, ls="--", lw=0.8)
    ax1.set_yscale("log")
    ax1.set_ylabel("distribution score (0 even, 1 clustered)")
    ax1.legend(fontsize=8, ncol=2)
    ax2.set_ylabel("particles per cell")
    ax2.set_xlabel("time")
    ax2.legend(fontsize=8, ncol=2)
    fig.suptitle("vankeken_1a_particles: population control by count vs by density")
    fig.savefig(png, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    parser = BENCHMARK.parser()
    parser.add_argument("--end", type=float, default=2000.0, help="end time (default 2000)")
    parser.add_argument("--report-only", action="store_true", help="no runs: table and picture from log/")
    args = parser.parse_args(argv)
    BENCHMARK.log_load("start")
    log = args.results / "log"
    log.mkdir(parents=True, exist_ok=True)
    walls = {}
    if not args.report_only:
        for method in METHODS:
            walls[method] = run_method(method, end=args.end, ranks=args.ranks, log=log)
            print(f"{method}: {walls[method]:.0f} s", flush=True)
    stats = {m: read_statistics(log / f"{m}.csv") for m in METHODS}
    end = float(min(stats[m]["time"][-1] for m in METHODS))
    (args.results / "results.md").write_text(
        f"# Particle distribution: population control by count vs by density\n\n"
        f"configs/vankeken_1a_particles.yaml to t = {end:g} ({args.ranks} rank(s)); "
        f"score: mean and max over cells of ASPECT's distribution score (granularity 2); "
        f"ppc: particles per cell.\n\n" + table(stats, end) + "\n" + "; ".join(
            f"{m}: {int(stats[m]['step'][-1])} steps, {stats[m]['n_particles'][-1]:.0f} particles and "
            f"{stats[m]['cells'][-1]:.0f} cells at the end, wall time {stats[m]['wall_time'][-1]:.0f} s"
            for m in METHODS) + "\n")
    figure(stats, args.results / "distribution.png")
    summary = {m: {"score_time_average": _mean_in_time(stats[m], "distribution_score"),
                   "score_end": float(stats[m]["distribution_score"][-1]), "steps": int(stats[m]["step"][-1]),
                   "wall_s": walls.get(m)} for m in METHODS}
    print(json.dumps(summary))
    return 0


if __name__ == "__main__":
    sys.exit(main())
