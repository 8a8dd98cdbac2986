"""Tosi et al. (2015) viscoplastic convection benchmark: cases 1-4 and 5a from configs/tosi.yaml.

Usage::

    python -m benchmarks.tosi.run --case N [--cells 48] [--ranks 1] [--method newton] [--out DIR]
    python -m benchmarks.tosi.run --methods [--cells 24] [--steps 40]    # Picard vs Newton per step
    python -m benchmarks.tosi.run --cost [--cells 32]                     # case 2 on 1 and 2 ranks
    python -m benchmarks.tosi.run --table                                 # results.md, results.png

``--case N`` runs case N with the CLI to steady state (case 5a: to ``--end``, default 6, and the
last full period of its oscillation is measured) and prints one JSON line last: the steady-state (5a: last-cycle
mean) values of ``T_mean``, ``nusselt_top``, ``nusselt_bottom``, ``vrms``, ``vrms_surface``,
``vmax_surface``, ``eta_min``, ``eta_max``, ``W``, ``Phi_over_Ra``, ``delta``, the mesh, steps,
wall time and nonlinear iterations; for 5a also ``period`` and ``<name>_min`` / ``<name>_max``
over the last cycle. The JSON goes to ``data/<cells>x<cells>/case<N>.json`` too, with the run's
``statistics.csv`` beside it; ``--table`` writes ``results.md`` (every case at every resolution
in ``data/``, against the published ranges in ``reference.csv``) and ``results.png`` from them.

The cases (Tosi et al. 2015, table 1): eta = 2 / (1/eta_lin + 1/eta_plast) with eta_lin =
exp(-gamma_T T + gamma_z (1 - z)), gamma_T = ln(1e5), eta_plast = 1e-3 + sigma_y / |eps|::

    case 1: Delta eta_z = 1,  no yielding (eta = eta_lin)       case 2: Delta eta_z = 1,  sigma_y = 1
    case 3: Delta eta_z = 10, no yielding                       case 4: Delta eta_z = 10, sigma_y = 1
    case 5a: Delta eta_z = 10, sigma_y = 4 (time-periodic)

"No yielding" is ``eta = eta_lin``, not the limit ``2 eta_lin`` of the harmonic formula: the
published values of cases 1 and 3 are those of ``eta_lin`` (ASPECT's tosi.cc does the same). Case 1
at 32x32 to steady state: ``eta_lin`` gives u_rms 249.61, Nu 3.4215, <T> 0.77578 (published
248.93-252.09, 3.4091-3.4305, 0.7758-0.7768); ``2 eta_lin`` gives 161.24, 2.8930, 0.75520.

``--methods`` runs the first ``--steps`` steps of case 2 with Picard and with Newton (relative
residual 1e-8 each step) and writes ``methods.md`` and ``methods.png`` (iterations per step).

``--cost`` runs case 2 to steady state on 1 and then on 2 ranks, one after the other on the same
machine, and writes ``cost_<cells>x<cells>.md``: wall time to steady state, steps, nonlinear iterations, the time
and share of the nonlinear Stokes solve (every Newton iteration: assembly of the Jacobian and
residual, MUMPS factorisation and solve) and the machine's load before and after. With
``--repeat K`` it also times the first ``--steps`` steps K times on each rank count (best of K);
``--no-steady`` skips the runs to steady state (a larger mesh, where only the timing is wanted).
"""

from __future__ import annotations

import csv
import json
import math
import os
import sys
import time
from pathlib import Path

from benchmarks.common import iterations_figure
from benchmarks.harness import OUTPUT, Benchmark
from convection.launch import run_config
from convection.io.pictures import read_statistics

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
BENCHMARK = Benchmark(__doc__, out=OUTPUT / "tosi", results_option=True, ranks=1, overrides=True,
                      helps={"set": "extra config override key=value", "out": "run folders",
                             "results": "where case<N>.json goes (default: data/<cells>x<cells>; --table: data)"})

GAMMA_T = math.log(1e5)
CASES = {  # case -> (Delta eta_z, sigma_y or None)
    "1": (1.0, None), "2": (1.0, 1.0), "3": (10.0, None), "4": (10.0, 1.0), "5a": (10.0, 4.0),
}
QUANTITIES = ("T_mean", "nusselt_top", "nusselt_bottom", "vrms", "vrms_surface", "vmax_surface", "eta_min",
              "eta_max", "W", "Phi_over_Ra", "delta")
COLUMNS = {"nusselt_top": "nusselt"}  # statistics.csv column of a quantity, where the names differ
STATISTICS = "[time,velocity,nusselt,temperature,mesh,stokes,nonlinear,rheology,energy,surface,wall_time]"


def law_overrides(case: str) -> list[str]:
    """``--set`` overrides of configs/tosi.yaml (case 2) for ``case``."""
    contrast_z, sigma = CASES[case]
    viscous = f"{{name: exponential, gamma_T: {GAMMA_T!r}, gamma_z: {math.log(contrast_z)!r}}}"
    if sigma is None:  # no yielding: eta = eta_lin (module docstring)
        law = f"{{name: exponential, eta0: 1.0, gamma_T: {GAMMA_T!r}, gamma_z: {math.log(contrast_z)!r}}}"
        return [f"physics.viscosity.law={law}"]
    plastic = f"{{name: von_mises, yield_stress: {sigma!r}, eta_star: 1.0e-3, strain_rate_measure: norm}}"
    return [f"physics.viscosity.law={{name: viscoplastic, combination: tosi, viscous: {viscous}, plastic: {plastic}}}"]


def reference() -> dict[str, dict[str, tuple[float, float]]]:
    """Published ranges by case and quantity (reference.csv)."""
    out: dict[str, dict[str, tuple[float, float]]] = {}
    with open(HERE / "reference.csv", newline="") as f:
        for row in csv.DictReader(line for line in f if not line.startswith("#")):
            out.setdefault(row["case"], {})[row["quantity"]] = (float(row["low"]), float(row["high"]))
    return out


def run_case(case: str, out: Path, *, cells: int, ranks: int, method: str, end: float, cfl: float,
             extra: list[str]) -> dict:
    """Run one case with the CLI; returns its statistics (columns -> lists), the wall time and the
    run's time per phase (summary.json)."""
    overrides = [*law_overrides(case), f"mesh.cells=[{cells},{cells}]", f"stokes.nonlinear.method={method}",
                 f"time.end={end}", f"time.cfl={cfl}", f"output.statistics={STATISTICS}", f"name=tosi_case{case}",
                 "output.progress=lines", "output.progress_every=200", *extra]
    start = time.perf_counter()
    run_config(ROOT / "configs" / "tosi.yaml", out, ranks=ranks, overrides=overrides, cwd=ROOT)
    wall = time.perf_counter() - start
    timings = json.loads((out / "summary.json").read_text())["timings"] if (out / "summary.json").exists() else {}
    return {"statistics": read_statistics(out / "statistics.csv"), "wall": wall, "timings": timings}


def _value(stats: dict, name: str, index: int) -> float:
    return float(stats[COLUMNS.get(name, name)][index])


def oscillation(series: list[float], times: list[float]) -> tuple[float, int, int] | None:
    """Period of the last full cycles of a periodic series (mean spacing of the last maxima) and the
    index range of the last cycle, or None when fewer than three maxima were seen."""
    peaks = [i for i in range(1, len(series) - 1) if series[i - 1] < series[i] >= series[i + 1]]
    if len(peaks) < 3:
        return None
    last = peaks[-4:] if len(peaks) >= 4 else peaks
    period = (times[last[-1]] - times[last[0]]) / (len(last) - 1)
    return period, peaks[-2], peaks[-1]


def summarise(case: str, result: dict, cells: int, ranks: int, method: str) -> dict:
    stats = result["statistics"]
    n = len(stats["step"])
    summary = {"case": case, "cells": f"{cells}x{cells}", "ranks": ranks, "method": method,
               "steps": int(stats["step"][-1]), "time": float(stats["time"][-1]), "wall_seconds": result["wall"],
               "nonlinear_iterations": int(sum(stats["nonlinear_iterations"])),
               "nonlinear_per_step": float(sum(stats["nonlinear_iterations"][1:]) / max(n - 1, 1))}
    if case == "5a":
        cycle = oscillation(stats["vrms"], stats["time"])
        if cycle is None:
            summary["period"] = None
            summary.update({q: _value(stats, q, -1) for q in QUANTITIES})
            return summary
        period, a, b = cycle
        summary["period"] = period
        for q in QUANTITIES:
            values = [_value(stats, q, i) for i in range(a, b + 1)]
            summary[q] = sum(values) / len(values)
            summary[f"{q}_min"], summary[f"{q}_max"] = min(values), max(values)
        return summary
    summary.update({q: _value(stats, q, -1) for q in QUANTITIES})
    return summary


def resolutions(data: Path) -> list[Path]:
    """The ``<n>x<n>`` folders of ``data``, coarsest first."""
    folders = [d for d in data.glob("*x*") if d.is_dir() and d.name.split("x")[0].isdigit()]
    return sorted(folders, key=lambda d: int(d.name.split("x")[0]))


def table(data: Path) -> str:
    """Every case at every resolution found in ``data`` against the published ranges (markdown)."""
    ref = reference()
    lines = ["| case | mesh | quantity | this code | published range | inside |", "|---|---|---|---|---|---|"]
    for case in CASES:
        for folder in resolutions(data):
            path = folder / f"case{case}.json"
            if not path.exists():
                continue
            r = json.loads(path.read_text())
            for q in QUANTITIES:
                low_high = ref.get(case, {}).get(q)
                value = r[q]
                text = f"{value:.6g}"
                if case == "5a" and f"{q}_min" in r:
                    text += f" ({r[f'{q}_min']:.5g} to {r[f'{q}_max']:.5g})"
                inside = "" if low_high is None else ("yes" if low_high[0] <= value <= low_high[1] else "**no**")
                published = "" if low_high is None else f"{low_high[0]:g} to {low_high[1]:g}"
                lines.append(f"| {case} | {r['cells']} P2-P1/P2 | {q} | {text} | {published} | {inside} |")
            solve = (f"{r['nonlinear_per_step']:.2f} nonlinear iterations per step ({r['method']})"
                     if r['nonlinear_per_step'] > 0 else "linear Stokes (no yielding: one solve per step)")
            extra = f"steps {r['steps']}, t = {r['time']:.4g}, {r['wall_seconds']:.0f} s on {r['ranks']} rank(s), {solve}"
            if case == "5a":
                extra += f", period {r['period']:.5g}" if r.get("period") else ", no period detected"
            lines.append(f"| {case} | {r['cells']} | run | {extra} | | |")
    return "\n".join(lines) + "\n"


def plot(data: Path, out: Path) -> None:
    """u_rms and Nu_top against time of every case (finest resolution in ``data``)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for case in CASES:
        found = [f / f"case{case}" / "statistics.csv" for f in resolutions(data)]
        found = [f for f in found if f.exists()]
        if not found:
            continue
        stats = read_statistics(found[-1])
        label = f"case {case} ({found[-1].parent.parent.name})"
        axes[0].plot(stats["time"], stats["vrms"], label=label)
        axes[1].plot(stats["time"], stats["nusselt"], label=label)
    axes[0].set_ylabel("u_rms")
    axes[1].set_ylabel("Nu (top)")
    for ax in axes:
        ax.set_xlabel("time")
        ax.legend()
    fig.suptitle("Tosi et al. (2015) cases: this code")
    fig.tight_layout()
    fig.savefig(out, dpi=110)


def _load() -> str:
    return f"{os.getloadavg()[0]:.2f}"


def cost(out: Path, *, cells: int, repeat: int, steps: int, steady: bool = True) -> None:
    """Case 2 to steady state on 1 and 2 ranks one after the other (unless not ``steady``), then
    (``repeat`` > 0) the first ``steps`` steps ``repeat`` times each; writes cost_<cells>x<cells>.md."""
    rows, loads = [], [_load()]
    for ranks in (1, 2) if steady else ():
        r = run_case("2", out / f"cost_{ranks}", cells=cells, ranks=ranks, method="newton", end=4.0, cfl=4.0, extra=[])
        stats = r["statistics"]
        solve = r["timings"].get("stokes_solve", {}).get("max_seconds", float("nan"))
        rows.append({"ranks": ranks, "steps": int(stats["step"][-1]), "wall": r["wall"],
                     "iterations": int(sum(stats["nonlinear_iterations"])), "solve": solve,
                     "vrms": float(stats["vrms"][-1]), "nusselt": float(stats["nusselt"][-1])})
        loads.append(_load())
    short = {}
    for ranks in (1, 2) if repeat else ():
        walls = []
        for _ in range(repeat):
            r = run_case("2", out / f"cost_short_{ranks}", cells=cells, ranks=ranks, method="newton", end=4.0,
                         cfl=4.0, extra=[f"time.max_steps={steps}"])
            walls.append(r["wall"])
        short[ranks] = walls
        loads.append(_load())
    lines = [f"Tosi case 2, {cells}x{cells} P2-P1/P2, Newton to 1e-8 (MUMPS), cfl 4, from the initial condition"
             + (" to the steady state (relative change < 1e-6 over 40 steps)" if steady else "")
             + f"; 1 and 2 ranks run one after the other on this {os.cpu_count()}-core machine, nothing else "
             f"running. Load average (1 min) before, between and after: {', '.join(loads)}.", ""]
    if rows:
        lines += ["| ranks | steps | wall to steady state [s] | speed-up | nonlinear iterations | Stokes solve [s] "
                  "| share of the wall | s per iteration | u_rms | Nu_top |", "|---|---|---|---|---|---|---|---|---|---|"]
    for row in rows:
        lines.append(f"| {row['ranks']} | {row['steps']} | {row['wall']:.0f} | {rows[0]['wall'] / row['wall']:.2f} | "
                     f"{row['iterations']} | {row['solve']:.0f} | {100 * row['solve'] / row['wall']:.1f} % | "
                     f"{row['solve'] / max(row['iterations'], 1):.4f} | {row['vrms']:.5g} | {row['nusselt']:.6g} |")
    if short:
        best = {k: min(v) for k, v in short.items()}
        lines += ["", f"First {steps} steps, best of {repeat}: 1 rank {best[1]:.1f} s "
                  f"({', '.join(f'{w:.1f}' for w in short[1])}), 2 ranks {best[2]:.1f} s "
                  f"({', '.join(f'{w:.1f}' for w in short[2])}); ratio {best[1] / best[2]:.2f}."]
    lines += ["", "The Stokes solve is the whole nonlinear iteration (Jacobian and residual assembly, factorisation, "
              "solve, viscosity update); the rest is the temperature step, postprocessing and output."]
    (HERE / f"cost_{cells}x{cells}.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


def methods(out: Path, *, cells: int, steps: int, ranks: int) -> None:
    """Picard against Newton, iterations per step to the relative residual 1e-8 (case 2)."""
    counts = {}
    for method in ("picard", "newton"):
        result = run_case("2", out / f"methods_{method}", cells=cells, ranks=ranks, method=method, end=4.0, cfl=16.0,
                          extra=[f"time.max_steps={steps}", "stokes.nonlinear.rtol=1e-8",
                                 "stokes.nonlinear.max_iterations=500"])
        counts[method] = [int(c) for c in result["statistics"]["nonlinear_iterations"]]
        counts[method + "_wall"] = result["wall"]
    lines = [f"Tosi case 2, {cells}x{cells} P2-P1/P2, first {steps} steps from the initial condition, relative "
             "residual 1e-8 every step (MUMPS).", "",
             "| method | iterations, total | per step (mean) | max | wall [s] |", "|---|---|---|---|---|"]
    for method in ("picard", "newton"):
        c = counts[method]
        lines.append(f"| {method} | {sum(c)} | {sum(c) / len(c):.2f} | {max(c)} | {counts[method + '_wall']:.0f} |")
    lines += ["", f"Load average at the end: {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores; the wall times are what "
              "these runs took, not a timing measurement."]
    (HERE / "methods.md").write_text("\n".join(lines) + "\n")
    iterations_figure(HERE / "methods.png", counts, title=f"Tosi case 2, {cells}x{cells}")
    print(json.dumps({m: sum(counts[m]) for m in ("picard", "newton")}))


def main(argv: list[str] | None = None) -> int:
    parser = BENCHMARK.parser()
    parser.add_argument("--case", choices=list(CASES))
    parser.add_argument("--cells", type=int, default=48)
    parser.add_argument("--method", default="newton", choices=["newton", "picard"])
    parser.add_argument("--end", type=float, default=None, help="end time (default: 4; 5a: 6)")
    parser.add_argument("--cfl", type=float, default=16.0)
    parser.add_argument("--methods", action="store_true", help="Picard vs Newton iterations per step (case 2)")
    parser.add_argument("--cost", action="store_true", help="case 2 to steady state on 1 and 2 ranks (cost.md)")
    parser.add_argument("--repeat", type=int, default=0, help="--cost: time the first --steps steps this often")
    parser.add_argument("--no-steady", action="store_true", help="--cost: only the --repeat timings")
    parser.add_argument("--steps", type=int, default=40)
    parser.add_argument("--table", action="store_true", help="write results.md and results.png")
    args = parser.parse_args(argv)
    BENCHMARK.log_load("start")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    if args.methods:
        methods(out, cells=args.cells, steps=args.steps, ranks=args.ranks)
        return 0
    if args.cost:
        cost(out, cells=args.cells, repeat=args.repeat, steps=args.steps, steady=not args.no_steady)
        return 0
    if args.table:
        data = Path(args.results) if args.results else HERE / "data"
        (HERE / "results.md").write_text(table(data))
        plot(data, HERE / "results.png")
        print((HERE / "results.md").read_text())
        return 0
    if args.case is None:
        parser.error("give --case N, --methods, --cost or --table")
    end = args.end if args.end is not None else (6.0 if args.case == "5a" else 4.0)
    extra = list(args.set)
    if args.case == "5a":
        extra.append("time.steady_state_tolerance=null")  # periodic: run to the end time
    result = run_case(args.case, out / f"case{args.case}", cells=args.cells, ranks=args.ranks, method=args.method,
                      end=end, cfl=args.cfl, extra=extra)
    summary = summarise(args.case, result, args.cells, args.ranks, args.method)
    results_dir = Path(args.results) if args.results else HERE / "data" / f"{args.cells}x{args.cells}"
    results_dir.mkdir(parents=True, exist_ok=True)
    (results_dir / f"case{args.case}.json").write_text(json.dumps(summary, indent=1) + "\n")
    case_dir = results_dir / f"case{args.case}"
    case_dir.mkdir(exist_ok=True)
    (case_dir / "statistics.csv").write_text((out / f"case{args.case}" / "statistics.csv").read_text())
    print(json.dumps(summary))
    return 0


if __name__ == "__main__":
    sys.exit(main())
