"""Wall time of two jobs before and after a change, side by side in one sitting.

Usage::

    git worktree add /tmp/before <commit>          # the code before the change
    python -m benchmarks.performance.before_after --before /tmp/before [--repeat 3] [--out FILE]

Runs each job with each checkout's own code (its ``benchmarks/`` script and packages), alternating
before and after, ``--repeat`` times, and reports the best wall time of each (and the ratio after /
before) with the machine's load average before the sitting:

- van Keken 1a to t = 300 on 2 ranks (the README's default job: ``benchmarks/vanKeken/run.py
  --case 1a --ranks 2 --end 300``);
- Tosi et al. case 2 for 150 steps on 1 rank (``benchmarks/tosi/run.py --case 2 --set
  time.max_steps=150``).

It also checks that both checkouts wrote the same statistics (every column but ``wall_time``, to
the last digit) and says so in the table. Writes a Markdown table to ``--out`` (default: stdout).
"""

from __future__ import annotations

import csv
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benchmarks.harness import Benchmark, Load

HERE = Path(__file__).resolve().parents[2]
BENCHMARK = Benchmark(__doc__, out_option=True)
JOBS = {
    "van Keken 1a to t = 300, 2 ranks": (["-m", "benchmarks.vanKeken.run", "--case", "1a", "--ranks", "2", "--end", "300"],
                                        "1a/statistics.csv"),
    "Tosi case 2, 150 steps, 1 rank": (["-m", "benchmarks.tosi.run", "--case", "2", "--set", "time.max_steps=150"],
                                      "case2/statistics.csv"),
}


def _run(tree: Path, args: list[str], out: Path) -> float:
    env = {**os.environ, "PYTHONPATH": str(tree), "PYTHONDONTWRITEBYTECODE": "1", "OMPI_ALLOW_RUN_AS_ROOT": "1",
           "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1"}
    start = time.monotonic()
    proc = subprocess.run([sys.executable, *args, "--out", str(out)], cwd=tree, env=env, capture_output=True,
                          text=True)
    seconds = time.monotonic() - start
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(args)} in {tree}: exit {proc.returncode}\n{proc.stderr[-3000:]}")
    return seconds


def _rows(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as f:
        return [{k: v for k, v in row.items() if k != "wall_time"} for row in csv.DictReader(f)]


def main(argv: list[str] | None = None) -> int:
    parser = BENCHMARK.parser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--before", type=Path, required=True, help="checkout of the code before the change")
    parser.add_argument("--after", type=Path, default=HERE, help="checkout after (default: this one)")
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args(argv)
    load = Load.now().averages
    trees = {"before": args.before.resolve(), "after": args.after.resolve()}
    lines = ["| job | before (s) | after (s) | after / before | statistics |", "|---|---|---|---|---|"]
    with tempfile.TemporaryDirectory() as tmp:
        for job, (command, statistics) in JOBS.items():
            best = {}
            for i in range(args.repeat):
                for name, tree in trees.items():
                    out = Path(tmp) / f"{name}_{i}"
                    seconds = _run(tree, command, out)
                    best[name] = min(best.get(name, float("inf")), seconds)
                    print(f"{job}, {name}, run {i + 1}: {seconds:.1f} s", file=sys.stderr, flush=True)
            same = _rows(Path(tmp) / f"before_{args.repeat - 1}" / statistics) == \
                _rows(Path(tmp) / f"after_{args.repeat - 1}" / statistics)
            lines.append(f"| {job} | {best['before']:.1f} | {best['after']:.1f} | {best['after'] / best['before']:.3f} "
                         f"| {'identical' if same else 'DIFFERENT'} |")
    text = "\n".join([*lines, "", f"Best of {args.repeat}, before and after alternating; load average before the "
                      f"sitting {load[0]:.2f}, {load[1]:.2f}, {load[2]:.2f} (1, 5, 15 min) on {os.cpu_count()} cores."])
    if args.out is None:
        print(text)
    else:
        args.out.write_text(text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
