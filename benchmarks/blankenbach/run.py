"""Blankenbach et al. (1989) steady convection benchmark: run cases 1a/1b/1c/2a/2b and compare.

Usage::

    python -m benchmarks.blankenbach.run [--case 1a 1b 1c 2a 2b] [--ranks 2] [--quick]
                                         [--cells N] [--set KEY=VALUE ...]
                                         [--adaptive] [--compare-ranks] [--continuation COARSE FINE]
                                         [--out DIR]

Each case runs ``configs/blankenbach_<case>.yaml`` with the CLI under mpirun (to steady state),
then writes ``<out>/results.md`` — a table of the mesh used, Nu and vrms at steady state and their
relative errors against ``reference.csv`` — and ``<out>/results.png``. ``--cells N`` runs every
case with N cells vertically (and as many horizontally as keep the cells square); ``--set``
passes config overrides to every run. ``--adaptive`` adds an adaptive run of case 1b and compares
it with the uniform one; ``--compare-ranks`` runs 1a on 1 and 2 ranks and reports the
differences; ``--continuation COARSE FINE`` runs each case with FINE cells vertically from a cold
start and continued from its run with COARSE cells (``--initial-from``), side by side, and
reports the steps and wall times to the steady state. ``--quick`` uses coarse meshes (for smoke
tests).
"""

from __future__ import annotations

import csv
import json
import sys
from pathlib import Path

from benchmarks.harness import OUTPUT, Benchmark
from convection.launch import run_config
from convection.io.pictures import read_statistics

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
BENCHMARK = Benchmark(__doc__, out=OUTPUT / "blankenbach", ranks=2, quick="coarse meshes, short runs",
                      overrides=True, helps={"set": "a config override for every run (repeatable)"})


def reference() -> dict[str, dict[str, float]]:
    with open(HERE / "reference.csv", newline="") as f:
        rows = [r for r in csv.DictReader(line for line in f if not line.startswith("#"))]
    return {r["case"]: {k: float(v) for k, v in r.items() if k != "case"} for r in rows}


def run_case(config: str, out: Path, ranks: int, overrides: list[str]) -> dict:
    """Run one config with the CLI under mpirun; returns summary.json plus the statistics."""
    progress = ["output.progress=lines", "output.progress_every=100"]
    run_config(ROOT / "configs" / config, out, ranks=ranks, overrides=[*progress, *overrides], cwd=ROOT)
    summary = json.loads((out / "summary.json").read_text())
    summary["statistics"] = read_statistics(out / "statistics.csv")
    return summary


def main(argv: list[str] | None = None) -> int:
    parser = BENCHMARK.parser(cases=CASES, default_cases=["1a", "1b", "1c"])
    parser.add_argument("--cells", type=int, default=None, help="cells vertically (default: the config's)")
    parser.add_argument("--continuation", nargs=2, type=int, default=None, metavar=("COARSE", "FINE"),
                        help="run each case with FINE cells vertically cold and continued from COARSE")
    parser.add_argument("--adaptive", action="store_true", help="also run 1b adaptively and compare")
    parser.add_argument("--compare-ranks", action="store_true", help="run 1a on 1 and 2 ranks")
    args = parser.parse_args(argv)
    BENCHMARK.log_load("start")
    out = args.out
    out.mkdir(parents=True, exist_ok=True)
    ref = reference()
    quick = ["time.steady_state_tolerance=1e-4", "time.steady_state_rate=1e-1"] if args.quick else []

    rows = []
    results = {}
    for case in args.case:
        cells = 12 if args.quick else args.cells
        sized = [*quick, *([cells_override(case, cells)] if cells else []), *args.set]
        summary = run_case(f"blankenbach_{case}.yaml", out / case, args.ranks, sized)
        results[case] = summary
        rows.append((case, f"{mesh_cells(out / case)} P2-P1/P2 uniform", summary, ref[case]))
    if args.adaptive:
        # Base 16x16 refined at most once: the finest cells match the uniform 32x32 run.
        # Mesh changes perturb Nu/vrms slightly (~1e-5), so the steady-state test is looser.
        adaptive = ["adaptivity.enabled=true", "adaptivity.every=20", "adaptivity.min_level=0",
                    "time.steady_state_tolerance=5e-5", "time.steady_state_window=40",
                    "adaptivity.max_level=1", "adaptivity.refine_fraction=0.3", "adaptivity.coarsen_fraction=0.3",
                    "mesh.cells=[16,16]"] + (["mesh.cells=[6,6]", "time.steady_state_tolerance=1e-4"] if args.quick else [])
        summary = run_case("blankenbach_1b.yaml", out / "1b_adaptive", args.ranks, adaptive)
        results["1b_adaptive"] = summary
        rows.append(("1b", "[16, 16] base, levels 0-1, adaptive", summary, ref["1b"]))

    lines = ["| case | mesh | steps | cells | Nu | Nu rel. error | vrms | vrms rel. error | wall time [s] |",
             "|---|---|---|---|---|---|---|---|---|"]
    for case, mesh, s, r in rows:
        nu_err = (s["nusselt"] - r["nusselt"]) / r["nusselt"]
        v_err = (s["vrms"] - r["vrms"]) / r["vrms"]
        lines.append(f"| {case} | {mesh} | {s['steps']} | {s['cells']} | {s['nusselt']:.6f} | {nu_err:+.3%} | "
                     f"{s['vrms']:.5f} | {v_err:+.3%} | {s['wall_time']:.1f} |")
    if "1b_adaptive" in results and "1b" in results:
        a, u = results["1b_adaptive"], results["1b"]
        lines += ["", f"Adaptive 1b vs uniform 1b: Nu {(a['nusselt'] - u['nusselt']) / u['nusselt']:+.3%}, "
                      f"vrms {(a['vrms'] - u['vrms']) / u['vrms']:+.3%}, cells {a['cells']} vs {u['cells']} "
                      f"(see {out / '1b_adaptive' / 'statistics.csv'}, column cells)"]
    if args.compare_ranks:
        one = run_case("blankenbach_1a.yaml", out / "1a_ranks1", 1, quick)
        two = run_case("blankenbach_1a.yaml", out / "1a_ranks2", 2, quick)
        lines += ["", f"1a on 1 vs 2 ranks: Nu {one['nusselt']:.10f} vs {two['nusselt']:.10f} "
                      f"(rel. diff {abs(one['nusselt'] - two['nusselt']) / one['nusselt']:.2e}), vrms {one['vrms']:.10f} vs "
                      f"{two['vrms']:.10f} (rel. diff {abs(one['vrms'] - two['vrms']) / one['vrms']:.2e}), "
                      f"steps {one['steps']} vs {two['steps']}"]
    if args.continuation:
        lines += ["", *continuation(args.case, *args.continuation, out, args.ranks, [*quick, *args.set])]
    table = "\n".join(lines) + "\n"
    BENCHMARK.publish(out / "results.md", table)
    _plot(results, ref, out / "results.png")
    print(f"wrote {out / 'results.png'}")
    return 0


CASES = ["1a", "1b", "1c", "2a", "2b"]
WIDTH = {"2b": 2.5}
"""The boxes' widths (height 1)."""


def cells_override(case: str, cells: int) -> str:
    """``mesh.cells`` for ``cells`` square cells vertically in the case's box."""
    return f"mesh.cells=[{round(WIDTH.get(case, 1.0) * cells)},{cells}]"


def mesh_cells(run_dir: Path) -> str:
    """The ``mesh.cells`` a run folder's config.yaml holds, as written there."""
    config = (run_dir / "config.yaml").read_text()
    return next(line.split(":", 1)[1].strip() for line in config.splitlines() if line.strip().startswith("cells:"))


def continuation(cases: list[str], coarse: int, fine: int, out: Path, ranks: int, overrides: list[str]) -> list[str]:
    """Each case on ``fine`` cells from a cold start and continued from its run on ``coarse`` cells
    (``initial.from_run``, run first), one after the other; the table's lines."""
    lines = ["| case | mesh | start | steps | model time | wall time [s] | Nu | vrms |", "|---|---|---|---|---|---|---|---|"]
    savings = [""]
    for case in cases:
        source = out / f"{case}_{coarse}"
        config = f"blankenbach_{case}.yaml"
        first = run_case(config, source, ranks, [cells_override(case, coarse), *overrides])
        cold = run_case(config, out / f"{case}_{fine}_cold", ranks, [cells_override(case, fine), *overrides])
        warm_dir = out / f"{case}_{fine}_from_{coarse}"
        warm = run_case(config, warm_dir, ranks, [cells_override(case, fine), f"initial.from_run={source}", *overrides])
        for label, s, folder in (("cold", first, source), ("cold", cold, out / f"{case}_{fine}_cold"),
                                 (f"from {mesh_cells(source)}", warm, warm_dir)):
            lines.append(f"| {case} | {mesh_cells(folder)} | {label} | {s['steps']} | {s['time']:.4f} | "
                         f"{s['wall_time']:.1f} | {s['nusselt']:.6f} | {s['vrms']:.5f} |")
        savings.append(f"{case}: continued from {coarse} cells, the {fine}-cell run took {warm['wall_time']:.1f} s "
                       f"against {cold['wall_time']:.1f} s cold (ratio {warm['wall_time'] / cold['wall_time']:.2f}), "
                       f"{warm['steps']} steps against {cold['steps']}")
    return lines + savings


def _plot(results: dict, ref: dict, png: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4), constrained_layout=True)
    for name, s in results.items():
        st = s["statistics"]
        case = name[:2]
        axes[0].plot(st["time"], st["nusselt"] / ref[case]["nusselt"], label=name)
        axes[1].plot(st["time"], st["vrms"] / ref[case]["vrms"], label=name)
    for ax, label in zip(axes, ("Nu / Nu_ref", "vrms / vrms_ref")):
        ax.axhline(1.0, color="k", lw=0.8)
        ax.set_ylim(0.9, 1.1)
        ax.set_xscale("log")
        ax.set_xlabel("time")
        ax.set_ylabel(label)
        ax.legend()
    fig.savefig(png, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    sys.exit(main())
