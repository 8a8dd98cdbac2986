"""Convergence of the van Keken 1a first vrms peak over base mesh size and particles per cell.

Usage::

    python benchmarks/vanKeken/convergence.py [--cells 16 24 32] [--ppc 10 20 40] [--end 300] [--ranks 2]
                                              [--out DIR] [--no-run]

Runs ``configs/vankeken_1a.yaml`` (adaptive, levels 0-2 on the base mesh) for every combination of
base mesh ``N x N`` and particles per initial cell, to t = ``--end`` (the first peak is near
t = 209), and writes ``<out>/convergence.md``: peak height and time (parabola through the samples
around the maximum, as in run.py), their errors relative to the published 3.0916e-3 at t = 208.99,
the largest cell count, the particle count, steps and wall time. ``--no-run`` only re-measures the
existing ``<out>/n<N>_ppc<P>/statistics.csv`` (combinations without one are left out). Wall times
depend on the machine's load.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parents[1]))

from convection.plot import read_statistics  # noqa: E402
from run import ROOT, measure, reference, run_case  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--cells", type=int, nargs="+", default=[16, 24, 32])
    parser.add_argument("--ppc", type=int, nargs="+", default=[10, 20, 40])
    parser.add_argument("--end", type=float, default=300.0)
    parser.add_argument("--ranks", type=int, default=2)
    parser.add_argument("--out", default=str(ROOT / "output" / "benchmarks" / "vanKeken" / "convergence"))
    parser.add_argument("--no-run", action="store_true")
    args = parser.parse_args(argv)
    out = Path(args.out)
    ref = reference("1a")
    rv, rt = ref["first_peak_vrms"].value, ref["first_peak_time"].value
    lines = ["| base mesh | particles/cell | peak vrms | rel. error | peak time | rel. error | max cells | particles | steps | wall time [s] |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for n in args.cells:
        for ppc in args.ppc:
            folder = out / f"n{n}_ppc{ppc}"
            if args.no_run:
                if not (folder / "statistics.csv").is_file():
                    continue
                stats = read_statistics(folder / "statistics.csv")
            else:
                stats = run_case("1a", folder, args.ranks, [
                    f"time.end={args.end}", f"mesh.cells=[{n},{n}]", f"particles.generator.particles_per_cell={ppc}"])
            upto = stats["time"] <= args.end * (1 + 1e-9)  # a longer run counts up to --end only
            stats = {key: column[upto] for key, column in stats.items()}
            m = measure(stats)
            lines.append(f"| {n}x{n} | {ppc} | {m.peak_vrms:.5e} | {(m.peak_vrms - rv) / rv:+.2%} | {m.peak_time:.2f} | "
                         f"{(m.peak_time - rt) / rt:+.2%} | {int(stats['cells'].max())} | {int(stats['n_particles'][0])} | "
                         f"{int(stats['step'][-1])} | {stats['wall_time'][-1]:.0f} |")
            print(lines[-1], flush=True)
    table = "\n".join(lines) + "\n"
    out.mkdir(parents=True, exist_ok=True)
    (out / "convergence.md").write_text(table)
    print(table)
    print(f"wrote {out / 'convergence.md'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
