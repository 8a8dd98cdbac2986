"""Three materials from particles and from advected fields: a resolution study of their agreement.

Usage::

    python -m benchmarks.materials.run [--cells 16 24 32] [--end 300] [--ranks 2] [--out DIR] [--no-run]

Runs ``configs/rayleigh_taylor_3.yaml`` (light bottom layer, dense middle layer, stiff lid) with
``composition.source: particles`` (DG0 cell averages of 20 particles per cell) and with
``composition.source: field`` (P2 fields advected with SUPG/BDF2, no diffusion) on base meshes of
``--cells`` (adaptive, levels 0-2, as in the config), to ``--end``. For each resolution it reports
the largest relative difference of vrms between the two methods over the run (relative to the
largest vrms), and for each method the same difference between successive resolutions. The two
methods discretise the same equations differently, so their difference is a discretisation
error: it must shrink as the mesh is refined and be no larger than the change of either method
between the two finest resolutions. Writes ``<out>/results.md`` and ``<out>/vrms.png``.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from benchmarks.common import curves_figure
from benchmarks.harness import OUTPUT, Benchmark
from convection.launch import run_config
from convection.io.pictures import read_statistics

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
BENCHMARK = Benchmark(__doc__, out=OUTPUT / "materials", ranks=2, no_run="only re-measure existing runs")

SOURCES = {"particles": ["composition.source=particles", "composition.degree=0"],
           "field": ["composition.source=field", "composition.degree=2"]}


def max_difference(a: dict, b: dict) -> float:
    """Largest |vrms_a - vrms_b| over the common times (b interpolated to a's times), relative to max vrms_a."""
    t_end = min(a["time"][-1], b["time"][-1])
    t = a["time"][a["time"] <= t_end]
    va = a["vrms"][: t.size]
    vb = np.interp(t, b["time"], b["vrms"])
    return float(np.max(np.abs(va - vb)) / np.max(np.abs(va)))


def main(argv: list[str] | None = None) -> int:
    parser = BENCHMARK.parser()
    parser.add_argument("--cells", type=int, nargs="+", default=[16, 24, 32])
    parser.add_argument("--end", type=float, default=300.0)
    args = parser.parse_args(argv)
    BENCHMARK.log_load("start")
    stats: dict[tuple[str, int], dict] = {}
    for n in args.cells:
        for source, overrides in SOURCES.items():
            out = args.out / f"{source}_{n}"
            if not args.no_run:
                run_config(ROOT / "configs" / "rayleigh_taylor_3.yaml", out, ranks=args.ranks, cwd=ROOT, overrides=[
                    f"mesh.cells=[{n},{n}]", f"time.end={args.end}", "output.fields_every=0", "particles.output=null",
                    "output.progress=lines", "output.progress_every=100", *overrides])
            stats[source, n] = read_statistics(out / "statistics.csv")
    lines = [f"# Three materials: particles vs advected fields (rayleigh_taylor_3, t <= {args.end:g}, {args.ranks} ranks)",
             "", "max |vrms difference| / max vrms over the run", "",
             "| base mesh | particles vs field | particles vs previous mesh | field vs previous mesh | "
             "peak vrms particles | peak vrms field |", "|---|---|---|---|---|---|"]
    previous = None
    for n in args.cells:
        p, f = stats["particles", n], stats["field", n]
        between = max_difference(p, f)
        dp = max_difference(p, stats["particles", previous]) if previous else float("nan")
        df = max_difference(f, stats["field", previous]) if previous else float("nan")
        lines.append(f"| {n}x{n} | {between:.3%} | {dp:.3%} | {df:.3%} | {p['vrms'].max():.5e} | {f['vrms'].max():.5e} |")
        previous = n
    BENCHMARK.publish(args.out / "results.md", "\n".join(lines) + "\n")
    _plot(stats, args.cells, args.out / "vrms.png")
    print(f"wrote {args.out / 'vrms.png'}")
    return 0


def _plot(stats: dict, cells: list[int], png: Path) -> None:
    curves = [(stats[source, n]["time"], stats[source, n]["vrms"], f"{source}, {n}x{n}",
               {"color": f"C{i}", "linestyle": style})
              for i, n in enumerate(cells) for source, style in (("particles", "-"), ("field", "--"))]
    curves_figure(png, curves, xlabel="time", ylabel="vrms",
                  title="three materials: particles (solid) vs advected fields (dashed)")


if __name__ == "__main__":
    sys.exit(main())
