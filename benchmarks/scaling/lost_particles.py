"""Lost-particle report (seed paper section 3): particles lost per 1000 steps in the adaptive
Rayleigh-Taylor setup (configs/vankeken_1a.yaml) for Euler and RK2 at CFL 1 and 0.5.

Usage::

    python -m benchmarks.scaling.lost_particles [--steps 1000] [--ranks 2] [--out DIR]

Runs the four combinations with the CLI under mpirun, reads ``n_particles`` and ``n_lost`` from
each statistics.csv and writes ``<out>/lost_particles.md``. The seed paper reports < 0.002 % per
1000 steps for RK2 at CFL 1 and 1.5 % for Euler; in a closed domain our goal is zero.
"""

from __future__ import annotations

import sys
from pathlib import Path

from benchmarks.harness import OUTPUT, Benchmark
from convection.launch import run_config
from convection.io.pictures import read_statistics

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
BENCHMARK = Benchmark(__doc__, out=OUTPUT / "lost_particles", ranks=2)


def main(argv: list[str] | None = None) -> int:
    parser = BENCHMARK.parser()
    parser.add_argument("--steps", type=int, default=1000)
    args = parser.parse_args(argv)
    BENCHMARK.log_load("start")
    out = Path(args.out)
    rows = ["| integrator | CFL | steps | end time | particles | lost | lost per 1000 steps |", "|---|---|---|---|---|---|---|"]
    for integrator in ("euler", "rk2"):
        for cfl in (1.0, 0.5):
            run_dir = out / f"{integrator}_cfl{cfl}"
            run_config(ROOT / "configs" / "vankeken_1a.yaml", run_dir, ranks=args.ranks, cwd=ROOT, overrides=[
                f"particles.integrator={integrator}", f"time.cfl={cfl}", f"time.max_steps={args.steps}",
                "output.progress=lines", "output.progress_every=250", "output.fields_every=0"])
            stats = read_statistics(run_dir / "statistics.csv")
            steps = int(stats["step"][-1])
            n0, lost = int(stats["n_particles"][0]), int(stats["n_lost"][-1])
            per_1000 = 100.0 * lost / n0 * 1000.0 / max(steps, 1)
            rows.append(f"| {integrator} | {cfl} | {steps} | {stats['time'][-1]:.1f} | {n0} | {lost} | {per_1000:.4f} % |")
    table = "\n".join(rows) + "\n"
    out.mkdir(parents=True, exist_ok=True)
    (out / "lost_particles.md").write_text(table)
    print(table)
    return 0


if __name__ == "__main__":
    sys.exit(main())
