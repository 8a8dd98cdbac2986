"""Thick-layer entrainment benchmark (seed paper section 4.1, after Tackley & King 2003), 2D and 3D.

Usage::

    python -m benchmarks.tackley_king.run --case 2d 3d [--quick] [--ranks 1] [--jobs 2] [--end 0.02]
        [--series 40x10 80x10] [--time-limit 3900] [--reuse] [--out DIR] [--results DIR]

Runs ``configs/thick_layer_<case>.yaml`` with the CLI: in 2D a series of uniform meshes
(N x N cells) and particles per cell (``--series NxP ...``), in 3D one run (``--series`` picks N
and P there too). A config with an explicit buoyancy (2D: ``stokes.buoyancy_theta: 0``) gets
``time.dt_max = DT_FACTOR / (Rb h)`` (h = 1/N) for every run: a larger step makes the dense
interface oscillate from step to step ("drunken sailor"; at 10^3 the CFL step alone blows up).
The 3D config predicts the buoyancy (``buoyancy_theta: 1``, :mod:`convection.physics.buoyancy`) and takes
the CFL step. ``--time-limit`` stops a run cleanly after that many seconds (its statistics keep
every finished step).

From each ``statistics.csv`` the script samples e(t) and vrms(t) at :data:`SAMPLE_TIMES` and
writes ``<results>/results_<case>.md`` (e at fixed times, its time average over MEAN_WINDOW
(less sensitive to single plume events), final time and e, particles, lost,
steps, wall time; in 3D also the relative difference to the seed's 64^3 value from
``reference.csv``), ``entrainment_<case>.png`` (e(t) of the whole series) and ``vrms_<case>.png``.
``--quick`` is a smoke run (20 x 20, 5 and 10 particles per cell, t = 0.003; 3D 6^3, t = 0.0003) whose
results go to ``--out``, not to the benchmark folder.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import NamedTuple
from collections.abc import Sequence

import numpy as np

from benchmarks.common import ROOT, read_reference, sample, start_cli_run
from benchmarks.harness import OUTPUT, Benchmark
from convection.io.pictures import read_statistics

HERE = Path(__file__).resolve().parent

RB = 1.0e6
DT_FACTOR = 0.25
SAMPLE_TIMES = (0.005, 0.01, 0.015, 0.02)
MEAN_WINDOW = (0.01, 0.02)
DEFAULT_SERIES = {
    "2d": ("20x5", "20x10", "20x40", "20x100", "40x5", "40x10", "40x40", "40x100", "80x10", "80x40"),
    "3d": ("20x10",),
}
QUICK_SERIES = {"2d": ("20x5", "20x10"), "3d": ("6x5",)}
BENCHMARK = Benchmark(__doc__, out=OUTPUT / "tackley_king", results_option=True, ranks=1, quick="",
                      helps={"ranks": "MPI ranks per run",
                             "results": "folder of the tables and plots (default: this folder; --out with --quick)"})
QUICK_END = {"2d": 0.003, "3d": 0.0003}


class Member(NamedTuple):
    """One run of a series: N cells per direction and particles per cell."""

    cells: int
    ppc: int

    @classmethod
    def parse(cls, text: str) -> Member:
        n, p = text.lower().split("x")
        return cls(int(n), int(p))

    @property
    def label(self) -> str:
        return f"n{self.cells}_ppc{self.ppc}"


def overrides(case: str, member: Member, end: float) -> list[str]:
    """``--set`` items of one run: mesh, particles per cell, end time and, for an explicit buoyancy
    (the config's ``stokes.buoyancy_theta`` is 0), the step cap."""
    dim = 2 if case == "2d" else 3
    cells = "[" + ",".join([str(member.cells)] * dim) + "]"
    items = [f"mesh.cells={cells}", f"particles.generator.particles_per_cell={member.ppc}", f"time.end={end}"]
    if not semi_implicit(case):
        items.append(f"time.dt_max={dt_cap(member.cells):.6g}")
    return items


def semi_implicit(case: str) -> bool:
    """Whether ``configs/thick_layer_<case>.yaml`` predicts the buoyancy (``stokes.buoyancy_theta > 0``)."""
    from convection.config.loader import load_config

    return load_config(ROOT / "configs" / f"thick_layer_{case}.yaml")["stokes"]["buoyancy_theta"] > 0.0


def dt_cap(cells: int) -> float:
    """Largest step DT_FACTOR / (Rb h) for a mesh of ``cells`` per direction (h = 1 / cells)."""
    return DT_FACTOR * cells / RB


def run_series(case: str, members: Sequence[Member], out: Path, *, ranks: int, jobs: int, end: float,
               time_limit: float | None, reuse: bool) -> dict[Member, dict[str, np.ndarray]]:
    """Run (or, with ``reuse``, read finished) members, ``jobs`` at a time; returns their statistics."""
    config = ROOT / "configs" / f"thick_layer_{case}.yaml"
    todo = [m for m in members if not (reuse and (out / m.label / "summary.json").is_file())]
    running = []
    for m in todo:
        if len(running) >= jobs:
            running.pop(0).wait()
        running.append(start_cli_run(config, out / m.label, ranks=ranks, overrides=overrides(case, m, end),
                                     time_limit=time_limit, log=out / m.label / "run.log"))
    for run in running:
        run.wait()
    return {m: read_statistics(out / m.label / "statistics.csv") for m in members}


def seed_reference() -> dict[str, float]:
    """The seed paper's 3D entrainment values (reference.csv rows with dim 3)."""
    return {r["label"]: float(r["entrainment"]) for r in read_reference(HERE / "reference.csv") if r["dim"] == "3"}


def table(case: str, results: dict[Member, dict[str, np.ndarray]], out: Path) -> str:
    """Markdown table of e at SAMPLE_TIMES, the final e and run facts (plus the seed comparison in 3D)."""
    head = "| mesh | particles/cell | " + " | ".join(f"e(t={t:g})" for t in SAMPLE_TIMES) + \
        f" | mean e, t in [{MEAN_WINDOW[0]:g}, {MEAN_WINDOW[1]:g}] | t reached | final e | final vrms | particles | lost | steps | wall time [s] |"
    lines = [head, "|" + "---|" * (head.count("|") - 1)]
    for m, s in results.items():
        e = sample(s, "entrainment", SAMPLE_TIMES)
        mesh = "x".join([str(m.cells)] * (2 if case == "2d" else 3))
        cells = " | ".join("-" if np.isnan(x) else f"{x:.5f}" for x in e)
        mean = window_mean(s, "entrainment", MEAN_WINDOW)
        cells += " | -" if np.isnan(mean) else f" | {mean:.5f}"
        lines.append(f"| {mesh} | {m.ppc} | {cells} | {s['time'][-1]:.5f} | {s['entrainment'][-1]:.5f} | "
                     f"{s['vrms'][-1]:.1f} | {int(s['n_particles'][0])} | {int(s['n_lost'][-1])} | "
                     f"{int(s['step'][-1])} | {_wall(out / m.label, s):.0f} |")
    text = "\n".join(lines) + "\n"
    if case == "3d":
        ref = seed_reference()
        rows = ["", "| this run | reference | reference e | final e here | relative difference |", "|---|---|---|---|---|"]
        for m, s in results.items():
            for label, value in ref.items():
                final = s["entrainment"][-1]
                rows.append(f"| {m.cells}^3, {m.ppc}/cell, t = {s['time'][-1]:.5f} | {label} | {value:.5f} | "
                            f"{final:.5f} | {(final - value) / value:+.1%} |")
        text += "\n".join(rows) + "\n"
    return text


def window_mean(stats: dict[str, np.ndarray], key: str, window: tuple[float, float]) -> float:
    """Time average of column ``key`` over ``window`` (trapezoid rule; NaN if the run ends before it)."""
    t, y = stats["time"], stats[key]
    if t[-1] < window[1] * (1 - 1e-9):
        return float("nan")
    inside = (t > window[0]) & (t < window[1])
    tt = np.concatenate([[window[0]], t[inside], [window[1]]])
    yy = np.interp(tt, t, y)
    return float(np.sum(0.5 * (yy[1:] + yy[:-1]) * np.diff(tt)) / (window[1] - window[0]))


def _wall(run_dir: Path, stats: dict[str, np.ndarray]) -> float:
    summary = run_dir / "summary.json"
    if summary.is_file():
        return float(json.loads(summary.read_text())["wall_time"])
    return float(stats["wall_time"][-1])


def plot(case: str, results: dict[Member, dict[str, np.ndarray]], key: str, ylabel: str, png: Path) -> None:
    """One curve per member of ``key`` over time (colour: mesh, line style: particles per cell)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 5), constrained_layout=True)
    styles = {5: ":", 10: "-", 40: "--", 100: "-."}
    meshes = sorted({m.cells for m in results})
    colors = {n: f"C{i}" for i, n in enumerate(meshes)}
    for m, s in results.items():
        ax.plot(s["time"], s[key], styles.get(m.ppc, "-"), color=colors[m.cells], linewidth=0.9, label=f"{m.cells}{'²' if case == '2d' else '³'}, {m.ppc}/cell")
    if key == "entrainment" and case == "3d":
        for label, value in seed_reference().items():
            ax.axhline(value, color="gray", linewidth=0.8, linestyle="--")
            ax.annotate(label, (ax.get_xlim()[0], value), fontsize=7, color="gray", va="bottom")
    ax.set_xlabel("time")
    ax.set_ylabel(ylabel)
    ax.set_title(f"Thick-layer entrainment, {case.upper()} (Ra = Rb = 1e6, dense layer z <= 0.4)")
    ax.legend(fontsize=8, ncol=2)
    fig.savefig(png, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    parser = BENCHMARK.parser(cases=DEFAULT_SERIES, default_cases=["2d"])
    parser.add_argument("--series", nargs="+", default=None, help="members NxP (N cells per side, P particles per cell)")
    parser.add_argument("--jobs", type=int, default=1, help="runs at the same time")
    parser.add_argument("--end", type=float, default=None, help="end time (default: the config's, 0.02)")
    parser.add_argument("--time-limit", type=float, default=None, help="wall seconds per run (stops cleanly)")
    parser.add_argument("--reuse", action="store_true", help="read runs that already finished instead of rerunning")
    args = parser.parse_args(argv)
    BENCHMARK.log_load("start")
    out = args.out
    results_dir = args.results or (out if args.quick else HERE)
    results_dir.mkdir(parents=True, exist_ok=True)
    for case in args.case:
        names = args.series or (QUICK_SERIES if args.quick else DEFAULT_SERIES)[case]
        end = args.end if args.end is not None else (QUICK_END[case] if args.quick else 0.02)
        results = run_series(case, [Member.parse(n) for n in names], out / case, ranks=args.ranks, jobs=args.jobs,
                             end=end, time_limit=args.time_limit, reuse=args.reuse)
        text = table(case, results, out / case)
        BENCHMARK.publish(results_dir / f"results_{case}.md", text)
        plot(case, results, "entrainment", "e = dense volume above z = 0.5 / initial dense volume",
             results_dir / f"entrainment_{case}.png")
        plot(case, results, "vrms", "vrms", results_dir / f"vrms_{case}.png")
        print(f"wrote {results_dir}/entrainment_{case}.png, vrms_{case}.png")
    BENCHMARK.log_load("end")
    return 0


if __name__ == "__main__":
    sys.exit(main())
