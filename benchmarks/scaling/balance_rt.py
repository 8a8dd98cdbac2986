"""Particle-weighted load balancing in the adaptive Rayleigh-Taylor setup (seed paper section 3.2).

Usage::

    python -m benchmarks.scaling.balance_rt [--ranks 2 3] [--steps 60] [--ppc 200] [--out DIR]

Runs ``configs/vankeken_1a.yaml`` (0.9142 x 1, fine cells only near the interface, particles
uniform in space) for ``--steps`` steps under three partitionings, each on every rank count:

- ``default``: no repartitioning (DOLFINx's partition of the base mesh, refined in place);
- ``morton W=0``: space-filling-curve blocks of equal cell count every 10 steps (what a mesh code
  without particle weights does, e.g. p4est's default in ASPECT);
- ``morton W=0.01``: the same curve with cell loads 1 + W n_particles;
- ``rcb W=0.01``: recursive coordinate bisection with loads 1 + W n_particles, each cut along the
  axis that splits both cells and particles most evenly (our default ``balance.method``).

Writes ``<out>/balance_rt.md`` (imbalance max/mean over ranks of cells and of particles at the
first step, mean and worst over the run, wall time) and ``<out>/balance_rt.png``. Rank counts
above the number of cores run oversubscribed (the table says so).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import numpy as np

from benchmarks.harness import OUTPUT, Benchmark
from convection.launch import run_config
from convection.io.pictures import read_statistics

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
BENCHMARK = Benchmark(__doc__, out=OUTPUT / "balance_rt", ranks=(2, 3))

STRATEGIES = {
    "default": [],
    "morton W=0": ["balance.strategy=every", "balance.every=10", "balance.method=morton", "balance.particle_weight=0"],
    "morton W=0.01": ["balance.strategy=every", "balance.every=10", "balance.method=morton",
                      "balance.particle_weight=0.01"],
    "rcb W=0.01": ["balance.strategy=every", "balance.every=10", "balance.method=rcb", "balance.particle_weight=0.01"],
}


def run_all(out: Path, ranks: list[int], steps: int, ppc: int,
            strategies: list[str]) -> dict[tuple[int, str], dict[str, np.ndarray]]:
    results = {}
    for n in ranks:
        for name in strategies:
            extra = STRATEGIES[name]
            run_dir = out / f"{name.replace(' ', '_').replace('=', '')}_{n}"
            run_config(ROOT / "configs" / "vankeken_1a.yaml", run_dir, ranks=n, cwd=ROOT, overrides=[
                f"time.max_steps={steps}", f"particles.generator.particles_per_cell={ppc}",
                "output.fields_every=0", "output.progress=lines", "output.progress_every=20", *extra])
            results[(n, name)] = read_statistics(run_dir / "statistics.csv")
    return results


def table(results: dict[tuple[int, str], dict[str, np.ndarray]], ppc: int) -> str:
    cores = os.cpu_count() or 1
    lines = [
        f"Adaptive RT (configs/vankeken_1a.yaml, {ppc} particles per initial cell), imbalance = max/mean over ranks.",
        "",
        "| ranks | partition | cells (end) | particles | cell imb. step 0 | particle imb. step 0 "
        "| cell imb. mean / worst | particle imb. mean / worst | wall time [s] |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for (n, name), s in results.items():
        ranks = f"{n} (oversubscribed)" if n > cores else str(n)
        c, p = s["cell_imbalance"], s["particle_imbalance"]
        lines.append(
            f"| {ranks} | {name} | {int(s['cells'][-1])} | {int(s['n_particles'][0])} | {c[0]:.3f} | {p[0]:.3f} "
            f"| {c.mean():.3f} / {c.max():.3f} | {p.mean():.3f} / {p.max():.3f} | {s['wall_time'][-1]:.1f} |"
        )
    return "\n".join(lines) + "\n"


def plot(results: dict[tuple[int, str], dict[str, np.ndarray]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ranks = sorted({n for n, _ in results})
    fig, axes = plt.subplots(len(ranks), 2, figsize=(10, 3.2 * len(ranks)), squeeze=False, sharex=True)
    for row, n in enumerate(ranks):
        for col, (key, label) in enumerate((("particle_imbalance", "particles"), ("cell_imbalance", "cells"))):
            ax = axes[row, col]
            for (m, name), s in results.items():
                if m == n:
                    ax.plot(s["step"], s[key], label=name)
            ax.axhline(1.2 if key == "particle_imbalance" else 1.5, color="grey", ls=":", lw=1)
            ax.set_ylabel(f"{label}: max/mean")
            ax.set_title(f"{n} ranks: {label} per rank")
            ax.legend(fontsize=8)
        axes[-1, 0].set_xlabel("step")
        axes[-1, 1].set_xlabel("step")
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def main(argv: list[str] | None = None) -> int:
    parser = BENCHMARK.parser()
    parser.add_argument("--steps", type=int, default=60)
    parser.add_argument("--ppc", type=int, default=200, help="particles per cell of the initial mesh")
    parser.add_argument("--strategies", nargs="+", default=list(STRATEGIES), choices=list(STRATEGIES))
    args = parser.parse_args(argv)
    BENCHMARK.log_load("start")
    out = Path(args.out)
    results = run_all(out, args.ranks, args.steps, args.ppc, args.strategies)
    text = table(results, args.ppc)
    out.mkdir(parents=True, exist_ok=True)
    (out / "balance_rt.md").write_text(text)
    plot(results, out / "balance_rt.png")
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
