"""van Keken et al. (1997) Rayleigh-Taylor benchmark, cases 1a/1b/1c: run, measure, compare, plot.

Usage::

    python benchmarks/vanKeken/run.py [--case 1a 1b 1c] [--ranks 2] [--quick] [--end 300] [--out DIR]

Runs ``configs/vankeken_<case>.yaml`` with the CLI under mpirun, then from each statistics.csv:
the first vrms peak (height and time, refined by a parabola through the three samples around the
maximum), the growth rate of the early exponential phase (least-squares slope of log vrms for
t <= 50, at least three samples) and vrms(0). Writes ``<out>/results.md`` (our numbers vs ``reference.csv`` with relative
errors, case 1a) and ``<out>/vrms.png`` (our curves with the published peak). ``--quick`` uses a
coarse mesh and 10 particles per cell (a smoke run of about a minute).
"""

from __future__ import annotations

import argparse
import csv
import os
import shutil
import subprocess
import sys
from pathlib import Path
from typing import NamedTuple

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
sys.path.insert(0, str(ROOT))

from convection.plot import read_statistics  # noqa: E402

QUICK = ["mesh.cells=[16,16]", "adaptivity.max_level=1", "particles.generator.particles_per_cell=10"]


class Measures(NamedTuple):
    """What the benchmark compares."""

    peak_vrms: float
    peak_time: float
    growth_rate: float
    vrms_initial: float


def measure(stats: dict[str, np.ndarray], *, early_until: float = 50.0) -> Measures:
    """First vrms peak = the maximum (parabola through the samples around it), early growth rate, vrms(0).

    The growth rate is the least-squares slope of log vrms over the early exponential phase,
    t <= ``early_until`` (at least the first three samples).
    """
    t, v = stats["time"], stats["vrms"]
    i = int(np.argmax(v))  # in case 1a the first peak is the largest (the second is ~4x lower)
    peak_t, peak_v = t[i], v[i]
    if 0 < i < len(t) - 1:
        a, b, c = np.polyfit(t[i - 1:i + 2], v[i - 1:i + 2], 2)
        if a < 0:
            peak_t = -b / (2 * a)
            peak_v = c - b * b / (4 * a)
    early = t <= early_until
    early[:3] = True
    rate = float(np.polyfit(t[early], np.log(v[early]), 1)[0])
    return Measures(float(peak_v), float(peak_t), rate, float(v[0]))


def reference() -> dict[str, float]:
    with open(HERE / "reference.csv", newline="") as f:
        rows = list(csv.DictReader(line for line in f if not line.startswith("#")))
    return {r["quantity"]: float(r["value"]) for r in rows if r["case"] == "1a"}


def run_case(case: str, out: Path, ranks: int, overrides: list[str]) -> dict[str, np.ndarray]:
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    cmd = [sys.executable, "-m", "convection", "run", str(ROOT / "configs" / f"vankeken_{case}.yaml"),
           "--output", str(out), "--set", "output.progress=lines", "--set", "output.progress_every=100",
           "--set", "output.fields_every=0"]
    for item in overrides:
        cmd += ["--set", item]
    if ranks > 1:
        cmd = [shutil.which("mpirun"), "-n", str(ranks), "--oversubscribe", *cmd]
    print("$", " ".join(cmd), flush=True)
    subprocess.run(cmd, cwd=ROOT, env=env, check=True)
    return read_statistics(out / "statistics.csv")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--case", nargs="+", default=["1a"], choices=["1a", "1b", "1c"])
    parser.add_argument("--ranks", type=int, default=2)
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--end", type=float, default=300.0, help="end time (the first peak is near t = 209 in 1a)")
    parser.add_argument("--out", default=str(ROOT / "output" / "benchmarks" / "vanKeken"))
    args = parser.parse_args(argv)
    out = Path(args.out)
    overrides = [f"time.end={args.end}"] + (QUICK if args.quick else [])
    ref = reference()
    lines = ["| case | peak vrms | rel. error | peak time | rel. error | growth rate | rel. error | vrms(0) | particles | lost | steps |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    curves = {}
    for case in args.case:
        stats = run_case(case, out / case, args.ranks, overrides)
        curves[case] = stats
        m = measure(stats)
        if case == "1a":
            errs = [(m.peak_vrms - ref["first_peak_vrms"]) / ref["first_peak_vrms"],
                    (m.peak_time - ref["first_peak_time"]) / ref["first_peak_time"],
                    (m.growth_rate - ref["growth_rate"]) / ref["growth_rate"]]
            e = [f"{x:+.2%}" for x in errs]
        else:
            e = ["(no published value here)"] * 3
        lines.append(f"| {case} | {m.peak_vrms:.5e} | {e[0]} | {m.peak_time:.2f} | {e[1]} | {m.growth_rate:.5f} | {e[2]} | "
                     f"{m.vrms_initial:.4e} | {int(stats['n_particles'][0])} | {int(stats['n_lost'][-1])} | {int(stats['step'][-1])} |")
    table = "\n".join(lines) + "\n"
    out.mkdir(parents=True, exist_ok=True)
    (out / "results.md").write_text(table)
    print(table)
    _plot(curves, ref, out / "vrms.png")
    print(f"wrote {out / 'results.md'} and {out / 'vrms.png'}")
    return 0


def _plot(curves: dict[str, dict[str, np.ndarray]], ref: dict[str, float], png: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(12, 4.5), constrained_layout=True)
    for case, stats in curves.items():
        ax.plot(stats["time"], stats["vrms"], label=f"case {case} (this code)")
        ax2.plot(stats["time"], stats["entrainment"], label=f"case {case} (this code)")
    ax.plot([ref["first_peak_time"]], [ref["first_peak_vrms"]], "k*", markersize=12, label="1a published first peak")
    ax.set_xlabel("time")
    ax.set_ylabel("vrms")
    ax.set_title("van Keken et al. (1997) Rayleigh-Taylor")
    ax.legend()
    ax2.set_xlabel("time")
    ax2.set_ylabel("light material above z = 0.2 (fraction)")
    ax2.legend()
    fig.savefig(png, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    sys.exit(main())
