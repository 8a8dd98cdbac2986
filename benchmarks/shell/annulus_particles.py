"""Annulus with particle composition on 1 and 2 ranks: identical statistics, no particle lost,
every particle inside the shell (issue 13's must-show).

Runs ``configs/annulus_layer.yaml`` (a dense layer on the inner surface, carried by particles;
thermal convection between a hot inner and a cold outer surface, free slip on both, curved cells)
for ``--steps`` steps on each rank count, writing the particles every ``--every`` steps, then:

- compares every statistics column (except wall time and load imbalance) between the runs, relative
  to the column's largest magnitude;
- checks ``n_lost == 0`` at every step;
- reads every particle output file and checks ``r_inner <= |x| <= r_outer`` for every particle,
  and that the same particle ids are present on both rank counts.

Prints a JSON summary and writes ``results_annulus_particles.md``.

Usage: ``python -m benchmarks.shell.annulus_particles --steps 100 --every 20 --ranks 1 2``
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from benchmarks.common import start_cli_run
from benchmarks.harness import Benchmark
from convection.io.pictures import read_statistics

HERE = Path(__file__).resolve().parent
BENCHMARK = Benchmark(__doc__, ranks=(1, 2), overrides=True)

RANK_DEPENDENT = ("wall_time", "cell_imbalance", "particle_imbalance")
CONFIG = HERE.parents[1] / "configs" / "annulus_layer.yaml"


def particle_radii(directory: Path) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """Sorted ids and radii of the particles of every output step in ``directory``."""
    import h5py

    out = {}
    for path in sorted(directory.glob("particles*.h5")):
        with h5py.File(path, "r") as f:
            ids = np.asarray(f["ids"])
            r = np.linalg.norm(np.asarray(f["positions"]), axis=1)
            step = int(f.attrs["step"])
        order = np.argsort(ids)
        out[step] = (ids[order], r[order])
    return out


def main(argv: list[str] | None = None) -> dict:
    parser = BENCHMARK.parser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=100)
    parser.add_argument("--every", type=int, default=20)
    parser.add_argument("--output", type=Path, default=Path("output/shell_annulus_particles"))
    args = parser.parse_args(argv)
    BENCHMARK.log_load("start")
    radii = (1.22, 2.22)
    overrides = [f"time.max_steps={args.steps}", "time.end=1e9", f"particles.output.every_steps={args.every}",
                 "particles.output.properties=[composition]", *args.set]
    runs = {}
    for ranks in args.ranks:
        out = args.output / f"np{ranks}"
        start_cli_run(CONFIG, out, ranks=ranks, overrides=overrides, log=args.output / f"np{ranks}.log").wait()
        runs[ranks] = (read_statistics(out / "statistics.csv"), particle_radii(out))
    base_stats, base_particles = runs[args.ranks[0]]
    summary = {"steps": args.steps, "ranks": args.ranks, "columns_compared": [], "max_relative_difference": {},
               "lost": {}, "outside": {}, "r_min": {}, "r_max": {}, "particles": {}, "same_ids": {}}
    for ranks, (stats, particles) in runs.items():
        summary["lost"][ranks] = int(stats["n_lost"][-1])
        summary["particles"][ranks] = int(stats["n_particles"][-1])
        r_all = np.concatenate([r for _, r in particles.values()])
        summary["r_min"][ranks] = float(r_all.min())
        summary["r_max"][ranks] = float(r_all.max())
        summary["outside"][ranks] = int(np.count_nonzero((r_all < radii[0]) | (r_all > radii[1])))
        summary["same_ids"][ranks] = all(np.array_equal(particles[s][0], base_particles[s][0]) for s in base_particles)
        if ranks == args.ranks[0]:
            continue
        for key in stats:
            if key in RANK_DEPENDENT:
                continue
            scale = max(float(np.abs(base_stats[key]).max()), 1e-300)
            diff = float(np.abs(stats[key] - base_stats[key]).max()) / scale
            summary["max_relative_difference"][key] = diff
    summary["columns_compared"] = sorted(summary["max_relative_difference"])
    print(json.dumps(summary, indent=1))
    return summary


if __name__ == "__main__":
    main()
