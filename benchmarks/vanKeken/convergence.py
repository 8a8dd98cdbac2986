"""Convergence of a van Keken Rayleigh-Taylor first vrms peak (case 1a, 1b or 1c) under refinement.

Usage::

    python -m benchmarks.vanKeken.convergence [--case 1a|1b|1c] [--cells 16 24 32] [--ppc 10 20 40]
        [--zip] [--min-ppc M ...] [--max-level L] [--cfl C ...] [--end T] [--fit-half-width W]
        [--ranks 2] [--out DIR] [--no-run | --skip-existing] [--name NAME]
        [--publish [--section TITLE]] [--publish-plot] [--set KEY=VALUE ...]

Runs ``configs/vankeken_<case>.yaml`` (adaptive, levels 0 to ``--max-level`` on the base mesh) for
every combination of base mesh ``N x N`` and particles per initial cell (``--zip``: the i-th mesh
with the i-th particle count, a refinement sequence), to t = ``--end`` (default just past the first
peak: 300 for 1a, peak near t = 209; 120 for 1b, near 73; 80 for 1c, near 51).

Resolution knobs besides the mesh and the particle count: ``--min-ppc`` (population control: cells
with fewer particles get new ones, which copy the composition of the nearest particle of the cell;
one value, or one per run with ``--zip``), ``--max-level`` (adaptive levels) and ``--cfl`` (one
value, or one per run with ``--zip``).

For every run, ``<out>/convergence_<case>.md`` (1a: ``convergence.md``) gets the first peak measured
two ways: the largest sample refined by a parabola through it and its two neighbours (run.py's
:func:`run.peak`, the measure of results_1*.md) and a least-squares cubic through the samples within
``--fit-half-width`` of the peak (:func:`run.fitted_peak`, default 2 time units for 1b/1c, 20 for 1a),
which averages the step-to-step jitter of a noisy curve; its standard error and the samples' scatter
about it; the jitter itself over the 10 time units before the peak (:func:`jitter`, at steps without
and with a mesh adaptation); the errors of both against ``reference.csv``; the change of the fitted peak from the
previous row (successive refinements when the rows are a ``--zip`` sequence); cells, particles,
steps, ranks, wall time and the load average of the machine before and after the run. ``<out>/
convergence_<case>.png`` shows vrms against time around the peak for every run. ``--name`` changes
their basename (several studies in one ``--out``). ``--publish`` copies the table into
benchmarks/vanKeken/, or with ``--section TITLE`` writes it as the section ``## TITLE`` of
benchmarks/vanKeken/convergence_<case>.md (several studies in one file); ``--publish-plot`` copies
the plot. ``--no-run`` only re-measures existing ``<out>/<run>/statistics.csv`` (runs without one
that reaches ``--end`` are left out); ``--skip-existing`` re-measures those and runs the others.
Wall times depend on the load.
"""

from __future__ import annotations

import json
import math
import os
import re
import shutil
import sys
import time as _time
from pathlib import Path
from typing import NamedTuple

import numpy as np

from convection.config.loader import load_config
from convection.io.pictures import read_statistics
from benchmarks.harness import Benchmark
from benchmarks.vanKeken.run import CONFIGS, ROOT, fitted_peak, peak, reference, run_case

HERE = Path(__file__).resolve().parent

CASES = ("1a", "1b", "1c")
BENCHMARK = Benchmark(__doc__, ranks=2, overrides=True, no_run="")
DEFAULT_END = {"1a": 300.0, "1b": 120.0, "1c": 80.0}
DEFAULT_HALF_WIDTH = {"1a": 20.0, "1b": 2.0, "1c": 2.0}


class Resolution(NamedTuple):
    """The resolution knobs of one run (None: the config's value)."""

    cells: int
    ppc: int
    min_ppc: int = 0
    max_level: int | None = None
    cfl: float | None = None

    @property
    def name(self) -> str:
        """The run's folder name, e.g. ``n24_ppc20_min10``."""
        parts = [f"n{self.cells}", f"ppc{self.ppc}"]
        if self.min_ppc:
            parts.append(f"min{self.min_ppc}")
        if self.max_level is not None:
            parts.append(f"L{self.max_level}")
        if self.cfl is not None:
            parts.append(f"cfl{self.cfl:g}")
        return "_".join(parts)

    def overrides(self) -> list[str]:
        """Config overrides (``--set`` items) for these knobs."""
        items = [f"mesh.cells=[{self.cells},{self.cells}]", f"particles.generator.particles_per_cell={self.ppc}"]
        if self.min_ppc:
            items += [f"particles.population.min_per_cell={self.min_ppc}", "particles.population.seed=7"]
        if self.max_level is not None:
            items.append(f"adaptivity.max_level={self.max_level}")
        if self.cfl is not None:
            items.append(f"time.cfl={self.cfl}")
        return items


def resolutions(cells: list[int], ppc: list[int], *, zip_lists: bool = False, min_ppc: list[int] | None = None,
                max_level: int | None = None, cfl: list[float] | None = None) -> list[Resolution]:
    """The runs: every (cells, ppc) pair, or with ``zip_lists`` the i-th of each list (the lists then
    have equal lengths; ``min_ppc`` and ``cfl`` have one value or one per run)."""
    min_ppc = min_ppc or [0]
    cfl = cfl or [None]
    if zip_lists:
        if len(cells) != len(ppc):
            raise ValueError(f"--zip needs as many --ppc ({len(ppc)}) as --cells ({len(cells)})")
        for name, values in (("--min-ppc", min_ppc), ("--cfl", cfl)):
            if len(values) not in (1, len(cells)):
                raise ValueError(f"{name} needs 1 or {len(cells)} values, got {len(values)}")
        mins = min_ppc * len(cells) if len(min_ppc) == 1 else min_ppc
        cfls = cfl * len(cells) if len(cfl) == 1 else cfl
        return [Resolution(n, p, m, max_level, c) for n, p, m, c in zip(cells, ppc, mins, cfls)]
    if len(min_ppc) != 1 or len(cfl) != 1:
        raise ValueError("several --min-ppc or --cfl values need --zip")
    return [Resolution(n, p, min_ppc[0], max_level, cfl[0]) for n in cells for p in ppc]


def run_overrides(case: str, res: Resolution, end: float, extra: list[str] = ()) -> list[str]:
    """Every config override of one run (end time, knobs, extra ``--set`` items)."""
    if case not in CASES:
        raise ValueError(f"case must be one of {CASES}, got {case!r}")
    return [f"time.end={end}", *res.overrides(), *extra]


class Row(NamedTuple):
    """One run's measurements."""

    res: Resolution
    stats: dict[str, np.ndarray]
    three_point_vrms: float
    three_point_time: float
    fit_vrms: float
    fit_time: float
    fit_stderr: float
    scatter: float
    load_before: float
    load_after: float
    ranks: int


def measure_run(stats: dict[str, np.ndarray], res: Resolution, half_width: float, end: float,
                load: tuple[float, float] = (math.nan, math.nan), ranks: int = 0) -> Row:
    """Both peak measures of one run's statistics, counted up to ``end``."""
    upto = stats["time"] <= end * (1 + 1e-9)
    stats = {key: column[upto] for key, column in stats.items()}
    t, v = stats["time"], stats["vrms"]
    raw = peak(t, v)
    fit = fitted_peak(t, v, half_width)
    return Row(res, stats, raw.vrms, raw.time, fit.vrms, fit.time, fit.stderr, fit.scatter, *load, ranks)


def jitter(stats: dict[str, np.ndarray], window: tuple[float, float], every: int) -> tuple[float, float]:
    """Step-to-step jitter of vrms in ``window``: root mean square of (v[i+1] - 2 v[i] + v[i-1]) /
    (v[i] sqrt(6)) (the relative standard deviation of independent noise on a locally linear curve),
    over the steps that are not adaptation steps and over the adaptation steps (step divisible by
    ``every``)."""
    t, v, step = stats["time"], stats["vrms"], stats["step"].astype(int)
    d2 = ((v[2:] - 2 * v[1:-1] + v[:-2]) / (v[1:-1] * math.sqrt(6))) ** 2
    inside = (t[1:-1] >= window[0]) & (t[1:-1] <= window[1])
    adapted = step[1:-1] % max(every, 1) == 0
    other, at = inside & ~adapted, inside & adapted
    return (math.sqrt(d2[other].mean()) if other.any() else math.nan, math.sqrt(d2[at].mean()) if at.any() else math.nan)


def _load(before: float, after: float) -> str:
    return f"{before:.1f}/{after:.1f}" if math.isfinite(before) and math.isfinite(after) else "-"


def table(case: str, rows: list[Row], half_width: float) -> str:
    """Markdown table of the runs (in order; the change is against the previous row)."""
    ref = reference(case)
    rv, rt = ref["first_peak_vrms"].value, ref["first_peak_time"].value
    lines = [
        f"Case {case}, first vrms peak; published {rv:g} at t = {rt:g}. 'fit': least-squares cubic through the "
        f"samples within {half_width:g} of the peak (± its standard error; scatter = the samples' standard "
        "deviation about the fit); '3-point': parabola through the largest sample and its neighbours. "
        "'change' = fitted peak against the previous row. 'jitter': step-to-step noise of vrms over the "
        "10 time units before the fitted peak (rms of the second difference / (vrms √6)), at steps without / "
        "with a mesh adaptation.",
        "",
        "| base mesh | levels | particles/cell (min) | CFL | peak vrms (fit) | rel. error | change | peak time (fit) | "
        "rel. error | change | scatter | jitter (other/adaptation steps) | peak vrms (3-point) | rel. error | peak time (3-point) | cells (max) | "
        "particles (start/end) | steps | ranks | wall time [s] | load before/after |",
        "|---" * 21 + "|",
    ]
    prev: Row | None = None
    for r in rows:
        s = r.stats
        config = load_config(ROOT / "configs" / CONFIGS[case], r.res.overrides())
        level = f"{config['adaptivity']['min_level']}-{config['adaptivity']['max_level']}"
        cfl = f"{config['time']['cfl']:g}"
        every = int(config["adaptivity"]["every"]) if config["adaptivity"]["enabled"] else 0
        j_other, j_adapt = jitter(s, (r.fit_time - 10.0, r.fit_time), every or 10**9)
        minimum = f" ({r.res.min_ppc})" if r.res.min_ppc else ""
        dv = f"{(r.fit_vrms - prev.fit_vrms) / prev.fit_vrms:+.2%}" if prev else "-"
        dt = f"{(r.fit_time - prev.fit_time) / prev.fit_time:+.2%}" if prev else "-"
        lines.append(
            f"| {r.res.cells}x{r.res.cells} | {level} | {r.res.ppc}{minimum} | {cfl} | "
            f"{r.fit_vrms:.5e} ± {r.fit_stderr:.1e} | {(r.fit_vrms - rv) / rv:+.2%} | {dv} | {r.fit_time:.2f} | "
            f"{(r.fit_time - rt) / rt:+.2%} | {dt} | {r.scatter / r.fit_vrms:.1%} | {j_other:.2%}/{j_adapt:.2%} | {r.three_point_vrms:.5e} | "
            f"{(r.three_point_vrms - rv) / rv:+.2%} | {r.three_point_time:.2f} | {int(s['cells'].max())} | "
            f"{int(s['n_particles'][0])}/{int(s['n_particles'][-1])} | {int(s['step'][-1])} | "
            f"{r.ranks or '-'} | {s['wall_time'][-1]:.0f} | {_load(r.load_before, r.load_after)} |")
        prev = r
    return "\n".join(lines) + "\n"


def plot(case: str, rows: list[Row], half_width: float, png: Path) -> None:
    """vrms against time around the first peak for every run, with the fitted cubics."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ref = reference(case)
    rv, rt = ref["first_peak_vrms"].value, ref["first_peak_time"].value
    fig, ax = plt.subplots(figsize=(9, 5.5), constrained_layout=True)
    lo, hi = rt - 8 * half_width, rt + 6 * half_width
    for r in rows:
        t, v = r.stats["time"], r.stats["vrms"]
        keep = (t >= lo) & (t <= hi)
        line, = ax.plot(t[keep], v[keep], lw=0.9, label=f"{r.res.name}: fit {r.fit_vrms:.4e} at {r.fit_time:.1f}")
        sel = np.abs(t - r.fit_time) <= half_width
        coeffs = np.polyfit(t[sel] - r.fit_time, v[sel], 3)
        x = np.linspace(t[sel].min(), t[sel].max(), 200)
        ax.plot(x, np.polyval(coeffs, x - r.fit_time), color=line.get_color(), lw=2.2, alpha=0.6)
        ax.plot([r.fit_time], [r.fit_vrms], "o", color=line.get_color(), markeredgecolor="k")
    ax.plot([rt], [rv], "k*", markersize=14, label=f"published {rv:g} at t = {rt:g}")
    ax.axhspan(rv * 0.99, rv * 1.01, color="0.85", zorder=0, label="published ± 1 %")
    ax.set_xlabel("time")
    ax.set_ylabel("vrms")
    ax.set_title(f"van Keken et al. (1997) case {case}: first vrms peak under refinement\n"
                 f"(thin: samples, thick: cubic fit over ±{half_width:g})")
    ax.legend(fontsize=8)
    fig.savefig(png, dpi=110)
    plt.close(fig)


def publish_section(path: Path, title: str, text: str) -> None:
    """Write ``text`` under the heading ``## title`` of the markdown file ``path``: replaces the
    section of that title (up to the next ``## `` heading) or appends it; other sections are kept."""
    block = f"## {title}\n\n{text.rstrip()}\n\n"
    old = path.read_text() if path.is_file() else ""
    parts = [part for part in re.split(r"(?m)^(?=## )", old) if part]
    heading = f"## {title}\n"
    if any(part.startswith(heading) for part in parts):
        parts = [block if part.startswith(heading) else part for part in parts]
    else:
        parts.append(block)
    path.write_text("".join(parts))


def _finished(folder: Path, end: float) -> bool:
    """Whether ``folder`` holds a statistics.csv that reaches ``end``."""
    path = folder / "statistics.csv"
    if not path.is_file():
        return False
    stats = read_statistics(path)
    return bool(stats) and stats["time"][-1] >= end * (1 - 1e-9)


def main(argv: list[str] | None = None) -> int:
    parser = BENCHMARK.parser()
    parser.add_argument("--case", default="1a", choices=CASES)
    parser.add_argument("--cells", type=int, nargs="+", default=[16, 24, 32])
    parser.add_argument("--ppc", type=int, nargs="+", default=[10, 20, 40])
    parser.add_argument("--zip", action="store_true", help="pair the i-th --cells with the i-th --ppc")
    parser.add_argument("--min-ppc", type=int, nargs="+", default=None,
                        help="population control: min particles per cell")
    parser.add_argument("--max-level", type=int, default=None, help="adaptive levels (default: the config's)")
    parser.add_argument("--cfl", type=float, nargs="+", default=None,
                        help="CFL number (default: the config's; one per run with --zip)")
    parser.add_argument("--end", type=float, default=None, help="end time (default: just past the first peak)")
    parser.add_argument("--fit-half-width", type=float, default=None, help="time window of the peak fit (each side)")
    parser.add_argument("--out", default=None, help="default: output/benchmarks/vanKeken/convergence[_<case>]")
    parser.add_argument("--skip-existing", action="store_true",
                        help="re-measure runs whose statistics.csv already reaches --end instead of running them")
    parser.add_argument("--name", default=None, help="basename of the table and plot (default: convergence[_<case>])")
    parser.add_argument("--publish", action="store_true", help="copy the table into benchmarks/vanKeken/")
    parser.add_argument("--section", default=None,
                        help="with --publish: write the table as the section '## SECTION' of "
                             "benchmarks/vanKeken/convergence[_<case>].md (replacing a section of that title)")
    parser.add_argument("--publish-plot", action="store_true", help="copy the plot into benchmarks/vanKeken/")
    args = parser.parse_args(argv)
    BENCHMARK.log_load("start")
    case = args.case
    suffix = "" if case == "1a" else f"_{case}"
    out = Path(args.out or ROOT / "output" / "benchmarks" / "vanKeken" / f"convergence{suffix}")
    end = args.end if args.end is not None else DEFAULT_END[case]
    half_width = args.fit_half_width if args.fit_half_width is not None else DEFAULT_HALF_WIDTH[case]
    runs = resolutions(args.cells, args.ppc, zip_lists=args.zip, min_ppc=args.min_ppc,
                       max_level=args.max_level, cfl=args.cfl)
    rows: list[Row] = []
    for res in runs:
        folder = out / res.name
        info = folder / "load.json"
        done = _finished(folder, end)
        if args.no_run or (args.skip_existing and done):
            if not done:
                print(f"left out {folder}: no statistics.csv reaching t = {end:g}", flush=True)
                continue
            stats = read_statistics(folder / "statistics.csv")
            meta = json.loads(info.read_text()) if info.is_file() else {}
        else:
            before = os.getloadavg()[0]
            start = _time.time()
            stats = run_case(case, folder, args.ranks, run_overrides(case, res, end, args.set))
            meta = {"load": [before, os.getloadavg()[0]], "seconds": _time.time() - start, "ranks": args.ranks}
            info.write_text(json.dumps(meta))
        rows.append(measure_run(stats, res, half_width, end, tuple(meta.get("load", (math.nan, math.nan))),
                                meta.get("ranks", 0)))
        print(table(case, rows[-1:], half_width).splitlines()[-1], flush=True)
    text = table(case, rows, half_width)
    out.mkdir(parents=True, exist_ok=True)
    name = args.name or f"convergence{suffix}"
    md, png = out / f"{name}.md", out / f"{name}.png"
    md.write_text(text)
    plot(case, rows, half_width, png)
    print(text)
    print(f"wrote {md} and {png}")
    if args.publish:
        if args.section:
            target = HERE / f"convergence{suffix}.md"
            publish_section(target, args.section, text)
            print(f"wrote section '{args.section}' of {target}")
        else:
            shutil.copy(md, HERE / md.name)
            print(f"copied {md.name} into {HERE}")
    if args.publish_plot:
        shutil.copy(png, HERE / png.name)
        print(f"copied {png.name} into {HERE}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
