"""van Keken et al. (1997) benchmarks: Rayleigh-Taylor cases 1a/1b/1c and thermochemical case 2.

Usage::

    python -m benchmarks.vanKeken.run [--case 1a 1b 1c 2] [--ranks 2] [--quick] [--end T] [--out DIR] [--no-run]

Runs ``configs/vankeken_<case>.yaml`` (case 2: ``configs/vankeken_case2.yaml``) with the CLI under
mpirun, then from each statistics.csv:

- cases 1a/1b/1c: the first vrms peak (height and time, refined by a parabola through the three
  samples around the maximum), the growth rate of the early exponential phase (least-squares slope
  of log vrms for t <= 50, at least three samples), vrms(0), and for runs past t = 1500 the second
  peak (the largest vrms for 500 <= t <= 1500); entrainment (light material above z = 0.2) at
  t = 100, 200, 300, 500, 1000, 2000 when reached;
- case 2: vrms(0), the first peak (largest vrms for t <= 0.006), the second peak (largest vrms for
  0.006 <= t <= 0.009), entrainment (dense material above z = 0.2) at t = 0.01 and 0.02, each
  against the published spread of ``reference.csv`` (inside / outside).

Writes ``<out>/results.md`` and ``<out>/vrms.png`` (cases 1x) or ``<out>/results_2.md`` and
``<out>/case2.png`` (case 2). ``--quick`` uses coarse settings (a smoke run). ``--no-run`` only
re-measures existing ``<out>/<case>/statistics.csv`` files. The default end time is 300 for cases
1x (the first peak is near t = 209 in 1a) and 0.02 for case 2.
"""

from __future__ import annotations

import csv
import math
import sys
from pathlib import Path
from typing import NamedTuple

import numpy as np

from benchmarks.harness import OUTPUT, Benchmark, Case, cases
from convection.launch import run_config
from convection.io.pictures import read_statistics

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]

QUICK = ["mesh.cells=[16,16]", "adaptivity.max_level=1", "particles.generator.particles_per_cell=10"]
QUICK_2 = ["mesh.cells=[32,16]", "adaptivity.max_level=1", "particles.generator.particles_per_cell=10"]
CASES = cases(Case("1a", "vankeken_1a.yaml"), Case("1b", "vankeken_1b.yaml"), Case("1c", "vankeken_1c.yaml"),
              Case("2", "vankeken_case2.yaml"))
CONFIGS = {name: case.config for name, case in CASES.items()}
BENCHMARK = Benchmark(__doc__, out=OUTPUT / "vanKeken", ranks=2, quick="", overrides=True,
                      no_run="only measure existing <out>/<case>/statistics.csv")
DEFAULT_END = {"1a": 300.0, "1b": 300.0, "1c": 300.0, "2": 0.02}
ENTRAINMENT_TIMES_1 = (100.0, 200.0, 300.0, 500.0, 1000.0, 2000.0)
SECOND_PEAK_WINDOW_1 = (500.0, 1500.0)
FIRST_PEAK_WINDOW_2 = (0.0, 0.006)
SECOND_PEAK_WINDOW_2 = (0.006, 0.009)
ENTRAINMENT_TIMES_2 = (0.01, 0.02)


class Measures(NamedTuple):
    """What the Rayleigh-Taylor benchmark compares."""

    peak_vrms: float
    peak_time: float
    growth_rate: float
    vrms_initial: float


class Peak(NamedTuple):
    """A vrms maximum: height and time (parabola through the samples around the largest sample)."""

    vrms: float
    time: float


class Case2Measures(NamedTuple):
    """What the thermochemical entrainment benchmark compares (NaN where the run did not reach it)."""

    vrms_initial: float
    first_peak: Peak
    second_peak: Peak
    entrainment: dict[float, float]


def peak(t: np.ndarray, v: np.ndarray, window: tuple[float, float] | None = None) -> Peak:
    """Largest ``v`` for ``t`` in ``window`` (all samples for None), refined by a parabola through
    the sample and its two neighbours when they form a maximum. NaN if no sample lies in the window."""
    inside = np.ones(len(t), dtype=bool) if window is None else (t >= window[0]) & (t <= window[1])
    if not inside.any():
        return Peak(math.nan, math.nan)
    idx = np.flatnonzero(inside)
    i = int(idx[np.argmax(v[idx])])
    peak_t, peak_v = float(t[i]), float(v[i])
    if 0 < i < len(t) - 1:
        a, b, c = np.polyfit(t[i - 1:i + 2], v[i - 1:i + 2], 2)
        if a < 0:
            peak_t = float(-b / (2 * a))
            peak_v = float(c - b * b / (4 * a))
    return Peak(peak_v, peak_t)


class FittedPeak(NamedTuple):
    """A vrms maximum from a least-squares polynomial over a time window around it.

    Attributes:
        vrms, time: Maximum of the fitted polynomial and where it is.
        stderr: Standard error of the fitted value at ``time`` (from the fit's covariance, i.e. from
            the residual scatter, assuming independent samples; NaN with too few samples).
        scatter: Standard deviation of the samples about the fit (the step-to-step noise).
        samples: Number of samples in the final window.
    """

    vrms: float
    time: float
    stderr: float
    scatter: float
    samples: int


def fitted_peak(t: np.ndarray, v: np.ndarray, half_width: float, *, degree: int = 3,
                window: tuple[float, float] | None = None, iterations: int = 20) -> FittedPeak:
    """Maximum of a least-squares polynomial of ``degree`` through the samples with
    ``|t - t*| <= half_width``, where ``t*`` starts at the largest sample (in ``window``, all samples
    for None) and is moved to the fitted maximum until it settles.

    A noisy series (step-to-step jitter of the samples) makes the largest sample, and a parabola
    through it and its two neighbours (:func:`peak`), an upward-biased estimate of the maximum;
    the least-squares fit averages the jitter over the window.
    """
    inside = np.ones(len(t), dtype=bool) if window is None else (t >= window[0]) & (t <= window[1])
    idx = np.flatnonzero(inside)
    if len(idx) == 0:
        return FittedPeak(math.nan, math.nan, math.nan, math.nan, 0)
    centre = float(t[idx[np.argmax(v[idx])]])
    for _ in range(iterations):
        sel = np.flatnonzero(np.abs(t - centre) <= half_width)
        if len(sel) < degree + 2:
            raise ValueError(f"only {len(sel)} samples within {half_width} of t = {centre:.4g} "
                             f"for a degree-{degree} fit")
        coeffs = np.polyfit(t[sel] - centre, v[sel], degree)
        grid = np.linspace(-half_width, half_width, 4001)
        j = int(np.argmax(np.polyval(coeffs, grid)))
        new = centre + float(grid[j])
        if abs(new - centre) <= 1e-6 * max(1.0, abs(centre)):
            break
        centre = new
    sel = np.flatnonzero(np.abs(t - centre) <= half_width)
    x = t[sel] - centre
    coeffs = np.polyfit(x, v[sel], degree)
    grid = np.linspace(float(x.min()), float(x.max()), 4001)
    fit = np.polyval(coeffs, grid)
    j = int(np.argmax(fit))
    scatter = float(np.std(v[sel] - np.polyval(coeffs, x), ddof=degree + 1))
    stderr = math.nan
    if len(sel) > degree + 2:
        _, cov = np.polyfit(x, v[sel], degree, cov=True)
        basis = grid[j] ** np.arange(degree, -1, -1)
        stderr = float(math.sqrt(max(basis @ cov @ basis, 0.0)))
    return FittedPeak(float(fit[j]), centre + float(grid[j]), stderr, scatter, len(sel))


def value_at(stats: dict[str, np.ndarray], key: str, time: float) -> float:
    """Column ``key`` interpolated linearly to ``time`` (NaN if the run did not get there)."""
    t = stats["time"]
    if time > t[-1] * (1 + 1e-9):
        return math.nan
    return float(np.interp(time, t, stats[key]))


def measure(stats: dict[str, np.ndarray], *, early_until: float = 50.0) -> Measures:
    """First vrms peak = the maximum (parabola through the samples around it), early growth rate, vrms(0).

    The growth rate is the least-squares slope of log vrms over the early exponential phase,
    t <= ``early_until`` (at least the first three samples). In case 1a the first peak is the
    largest (the second is ~4x lower).
    """
    t, v = stats["time"], stats["vrms"]
    first = peak(t, v)
    early = t <= early_until
    early[:3] = True
    rate = float(np.polyfit(t[early], np.log(v[early]), 1)[0])
    return Measures(first.vrms, first.time, rate, float(v[0]))


def measure_case2(stats: dict[str, np.ndarray]) -> Case2Measures:
    """vrms(0), first and second vrms peaks, entrainment at t = 0.01 and 0.02 of a case-2 run."""
    t, v = stats["time"], stats["vrms"]
    return Case2Measures(
        float(v[0]), peak(t, v, FIRST_PEAK_WINDOW_2), peak(t, v, SECOND_PEAK_WINDOW_2),
        {time: value_at(stats, "entrainment", time) for time in ENTRAINMENT_TIMES_2},
    )


class Reference(NamedTuple):
    """A published value: a point value, or a range [low, high] across published methods."""

    value: float
    low: float
    high: float
    source: str


def reference(case: str = "1a") -> dict[str, Reference]:
    """Rows of ``reference.csv`` for one case."""
    with open(HERE / "reference.csv", newline="") as f:
        rows = list(csv.DictReader(line for line in f if not line.startswith("#")))

    def number(text: str | None) -> float:
        return float(text) if text not in (None, "") else math.nan

    return {r["quantity"]: Reference(number(r["value"]), number(r["low"]), number(r["high"]), r["source"])
            for r in rows if r["case"] == case}


def run_case(case: str, out: Path, ranks: int, overrides: list[str]) -> dict[str, np.ndarray]:
    """Run one case with the CLI (under mpirun for ``ranks`` > 1); returns its statistics."""
    quiet = ["output.progress=lines", "output.progress_every=100", "output.fields_every=0"]
    run_config(ROOT / "configs" / CONFIGS[case], out, ranks=ranks, overrides=[*quiet, *overrides], cwd=ROOT)
    return read_statistics(out / "statistics.csv")


def _rel(value: float, ref: float) -> str:
    return f"{(value - ref) / ref:+.2%}" if math.isfinite(value) and math.isfinite(ref) else "-"


def table_case1(curves: dict[str, dict[str, np.ndarray]]) -> str:
    """Markdown tables of the Rayleigh-Taylor cases: first peak, growth rate, second peak, entrainment."""
    lines = ["| case | peak vrms | published | rel. error | peak time | published | rel. error | growth rate | "
             "vrms(0) | particles | lost | steps | wall time [s] |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for case, stats in curves.items():
        m = measure(stats)
        ref = reference(case)
        rv = ref.get("first_peak_vrms", Reference(math.nan, math.nan, math.nan, ""))
        rt = ref.get("first_peak_time", Reference(math.nan, math.nan, math.nan, ""))
        lines.append(f"| {case} | {m.peak_vrms:.5e} | {rv.value:.5g} | {_rel(m.peak_vrms, rv.value)} | {m.peak_time:.2f} | "
                     f"{rt.value:.5g} | {_rel(m.peak_time, rt.value)} | {m.growth_rate:.5f} | {m.vrms_initial:.4e} | "
                     f"{int(stats['n_particles'][0])} | {int(stats['n_lost'][-1])} | {int(stats['step'][-1])} | "
                     f"{stats['wall_time'][-1]:.0f} |")
    lines += ["", "| case | second peak vrms (500 <= t <= 1500) | published | rel. error | time | published | "
              + " | ".join(f"entrainment t={t:g}" for t in ENTRAINMENT_TIMES_1) + " |",
              "|---|---|---|---|---|---|" + "---|" * len(ENTRAINMENT_TIMES_1)]
    for case, stats in curves.items():
        t, v = stats["time"], stats["vrms"]
        second = peak(t, v, SECOND_PEAK_WINDOW_1) if t[-1] >= SECOND_PEAK_WINDOW_1[1] else Peak(math.nan, math.nan)
        ref = reference(case)
        rv = ref.get("second_peak_vrms", Reference(math.nan, math.nan, math.nan, ""))
        rt = ref.get("second_peak_time", Reference(math.nan, math.nan, math.nan, ""))
        ent = [value_at(stats, "entrainment", time) for time in ENTRAINMENT_TIMES_1]
        lines.append(f"| {case} | {second.vrms:.4e} | {rv.value:.4g} | {_rel(second.vrms, rv.value)} | {second.time:.1f} | "
                     f"{rt.value:.4g} | " + " | ".join(f"{e:.4f}" for e in ent) + " |")
    return "\n".join(lines).replace("nan", "-") + "\n"


def _verdict(value: float, ref: Reference) -> str:
    if not math.isfinite(value):
        return "not reached"
    return "inside" if ref.low <= value <= ref.high else "outside"


def table_case2(stats: dict[str, np.ndarray]) -> str:
    """Markdown table of case 2 against the published spread."""
    m = measure_case2(stats)
    ref = reference("2")
    rows = [
        ("vrms(0)", m.vrms_initial, ref["vrms_initial"]),
        ("first peak vrms (t <= 0.006)", m.first_peak.vrms, ref["first_peak_vrms"]),
        ("first peak time", m.first_peak.time, ref["first_peak_time"]),
        ("second peak vrms (0.006 <= t <= 0.009)", m.second_peak.vrms, ref["second_peak_vrms"]),
        ("second peak time", m.second_peak.time, ref["second_peak_time"]),
        *((f"entrainment at t = {time:g}", m.entrainment[time], ref[f"entrainment_t{time:g}"]) for time in ENTRAINMENT_TIMES_2),
    ]
    lines = ["| quantity | this code | published | verdict |", "|---|---|---|---|"]
    for name, value, r in rows:
        published = f"{r.low:.4g} - {r.high:.4g}" if math.isfinite(r.low) else f"~{r.value:.4g}"
        verdict = _verdict(value, r) if math.isfinite(r.low) else (_rel(value, r.value) if math.isfinite(value) else "not reached")
        lines.append(f"| {name} | {value:.5g} | {published} | {verdict} |")
    lines.append(f"\nparticles {int(stats['n_particles'][0])}, lost {int(stats['n_lost'][-1])}, steps {int(stats['step'][-1])}, "
                 f"cells {int(stats['cells'].min())}-{int(stats['cells'].max())}, t_end {stats['time'][-1]:.4g}, "
                 f"wall time {stats['wall_time'][-1]:.0f} s")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = BENCHMARK.parser(cases=CASES, default_cases=["1a"])
    parser.add_argument("--end", type=float, default=None, help="end time (default: 300 for 1x, 0.02 for 2)")
    args = parser.parse_args(argv)
    out = args.out
    out.mkdir(parents=True, exist_ok=True)
    BENCHMARK.log_load("start")
    curves = {}
    for case in args.case:
        if args.no_run:
            curves[case] = read_statistics(out / case / "statistics.csv")
            continue
        end = args.end if args.end is not None else DEFAULT_END[case]
        quick = (QUICK_2 if case == "2" else QUICK) if args.quick else []
        curves[case] = run_case(case, out / case, args.ranks, [f"time.end={end}", *quick, *args.set])
    rt_cases = {c: s for c, s in curves.items() if c != "2"}
    if rt_cases:
        table = table_case1(rt_cases)
        BENCHMARK.publish(out / "results.md", table)
        _plot_case1(rt_cases, out / "vrms.png")
        print(f"wrote {out / 'vrms.png'}")
    if "2" in curves:
        table = table_case2(curves["2"])
        BENCHMARK.publish(out / "results_2.md", table)
        _plot_case2(curves["2"], out / "case2.png")
        print(f"wrote {out / 'case2.png'}")
    BENCHMARK.log_load("end")
    return 0


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _plot_case1(curves: dict[str, dict[str, np.ndarray]], png: Path) -> None:
    plt = _pyplot()
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(12, 4.5), constrained_layout=True)
    for case, stats in curves.items():
        line, = ax.plot(stats["time"], stats["vrms"], label=f"case {case} (this code)")
        ax2.plot(stats["time"], stats["entrainment"], color=line.get_color(), label=f"case {case} (this code)")
        ref = reference(case)
        for key, marker in (("first_peak", "*"), ("second_peak", "^")):
            if f"{key}_vrms" in ref:
                ax.plot([ref[f"{key}_time"].value], [ref[f"{key}_vrms"].value], marker, color=line.get_color(),
                        markeredgecolor="k", markersize=11, label=f"{case} published {key.replace('_', ' ')}")
    ax.set_xlabel("time")
    ax.set_ylabel("vrms")
    ax.set_title("van Keken et al. (1997) Rayleigh-Taylor")
    ax.legend(fontsize=8)
    ax2.set_xlabel("time")
    ax2.set_ylabel("light material above z = 0.2 (fraction)")
    ax2.legend(fontsize=8)
    fig.savefig(png, dpi=110)
    plt.close(fig)


def _plot_case2(stats: dict[str, np.ndarray], png: Path) -> None:
    plt = _pyplot()
    ref = reference("2")
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(12, 4.5), constrained_layout=True)
    ax.plot(stats["time"], stats["vrms"], label="this code")
    for key in ("first_peak", "second_peak"):
        v, t = ref[f"{key}_vrms"], ref[f"{key}_time"]
        ax.errorbar([t.value], [0.5 * (v.low + v.high)], yerr=[[0.5 * (v.high - v.low)]], fmt="k*", markersize=10,
                    capsize=4, label=f"published {key.replace('_', ' ')} (spread)")
    ax.plot([0.0], [ref["vrms_initial"].value], "ks", label="published vrms(0)")
    ax.set_xlabel("time")
    ax.set_ylabel("vrms")
    ax.set_title("van Keken et al. (1997) case 2 (Ra = 3e5, B = 1.5)")
    ax.legend(fontsize=8)
    ax2.plot(stats["time"], stats["entrainment"], label="this code")
    for time in ENTRAINMENT_TIMES_2:
        r = ref[f"entrainment_t{time:g}"]
        ax2.errorbar([time], [0.5 * (r.low + r.high)], yerr=[[0.5 * (r.high - r.low)]], fmt="k_", capsize=5,
                     label="published spread" if time == ENTRAINMENT_TIMES_2[0] else None)
    ax2.set_xlabel("time")
    ax2.set_ylabel("dense material above z = 0.2 (fraction)")
    ax2.legend(fontsize=8)
    fig.savefig(png, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    sys.exit(main())
