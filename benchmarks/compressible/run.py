"""King et al. (2010) compressible convection: TALA and ALA at Ra = 1e4 and 1e5, Di = 0.25, 0.5, 1, against
the published codes.

Usage::

    python -m benchmarks.compressible.run [--case tala_0.25 ... ala_1e5_1] [--cells 32] [--ranks 2]
                                          [--set KEY=VALUE ...] [--quick] [--out DIR]

Each case runs ``configs/king_tala.yaml`` (unit square, free slip, T = 1 bottom, 0 top, gamma = 1 and
T0 = 0.091) with its approximation (``tala``, the truncated anelastic liquid, or ``ala``, the anelastic
liquid approximation), Rayleigh number (``_1e5``; else 1e4) and dissipation number, with the CLI
under mpirun to its steady state, and reads the last row of its statistics: Nu (top), vrms, <T> and the
energy statistics W (work against gravity) and Phi (shear heating). Writes ``<out>/results.md`` (each
value beside the range of the codes King et al. compare, UM, VT and CU, and its deviation from their
mean; ``reference.csv``) and ``<out>/results.png`` (Nu, vrms and Phi, W over the published mean against
Di, the published codes as markers). ``--quick`` runs 12 x 12 cells to a loose steady state (a smoke run);
``--no-run`` tabulates the run folders already in ``--out`` (e.g. a run continued from a coarser one with
``--set initial.from_run=DIR``).
"""

from __future__ import annotations

import csv
import json
import sys
from pathlib import Path

from benchmarks.harness import OUTPUT, Benchmark, Case, cases, markdown_table
from convection.io.pictures import read_statistics
from convection.launch import run_config

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
BENCHMARK = Benchmark(__doc__, out=OUTPUT / "compressible", ranks=2, quick="12 x 12 cells, loose steady state",
                      overrides=True, no_run="tabulate the runs already in --out",
                      helps={"set": "a config override for every run (repeatable)"})
CASES = cases(*(Case(f"{form}{'' if ra == '1e4' else '_' + ra}_{di}", "king_tala.yaml",
                     (f"physics.reference.Di={di}", f"physics.approximation={form}", f"physics.Ra={ra}"))
                for form in ("tala", "ala") for ra in ("1e4", "1e5") for di in ("0.25", "0.5", "1")))
PUBLISHED_CODES = ("UM", "VT", "CU")
"""The codes of King et al. (2010) in ``reference.csv`` (ASPECT's values are listed beside them)."""
QUANTITIES = {"nusselt": "nusselt", "vrms": "vrms", "T_mean": "T_mean", "W": "heating_W", "Phi": "heating_Phi"}
"""reference.csv column -> statistics.csv column."""
QUICK = ["mesh.cells=[12,12]", "time.steady_state_tolerance=1e-4"]


def reference() -> dict[tuple[str, float, float], dict[str, dict[str, float]]]:
    """``{(formulation, Ra, Di): {code: {quantity: value}}}`` of ``reference.csv``."""
    out: dict[tuple[str, float, float], dict[str, dict[str, float]]] = {}
    with open(HERE / "reference.csv", newline="") as f:
        for row in csv.DictReader(line for line in f if not line.startswith("#")):
            values = {k: float(row[k]) for k in QUANTITIES}
            out.setdefault((row["formulation"], float(row["Ra"]), float(row["Di"])), {})[row["code"]] = values
    return out


def published(ref: dict[str, dict[str, float]], quantity: str) -> tuple[float, float, float]:
    """``(min, max, mean)`` of ``quantity`` over the codes King et al. compare."""
    values = [ref[code][quantity] for code in PUBLISHED_CODES]
    return min(values), max(values), sum(values) / len(values)


def final(statistics: dict) -> dict[str, float]:
    """The last row's values of :data:`QUANTITIES`, and the steps."""
    values = {q: float(statistics[column][-1]) for q, column in QUANTITIES.items()}
    values["steps"] = int(statistics["step"][-1])
    return values


def case_key(case: Case) -> tuple[str, float, float]:
    """``(formulation, Ra, Di)`` of a case, its key in :func:`reference`."""
    values = dict(item.split("=", 1) for item in case.overrides)
    return values["physics.approximation"], float(values["physics.Ra"]), float(values["physics.reference.Di"])


def row(name: str, mesh: str, ours: dict[str, float], ref: dict[str, dict[str, float]], wall: float) -> list[str]:
    cells = [name, mesh, str(ours["steps"])]
    for quantity in QUANTITIES:
        lo, hi, mean = published(ref, quantity)
        inside = "in" if lo <= ours[quantity] <= hi else "out"
        cells.append(f"{ours[quantity]:.5g} ({lo:.5g}-{hi:.5g}, {inside}; {(ours[quantity] - mean) / mean:+.2%})")
    cells.append(f"{abs(ours['Phi'] - ours['W']) / ours['W']:.2%}")
    cells.append(f"{wall:.0f}")
    return cells


def main(argv: list[str] | None = None) -> int:
    parser = BENCHMARK.parser(cases=CASES, default_cases=list(CASES))
    parser.add_argument("--cells", type=int, default=32, help="cells per side of the unit square")
    args = parser.parse_args(argv)
    BENCHMARK.log_load("start")
    ref = reference()
    sized = QUICK if args.quick else [f"mesh.cells=[{args.cells},{args.cells}]"]
    rows, curves = [], {}
    for name in args.case:
        case = CASES[name]
        out = args.out / name
        if not args.no_run:
            run_config(case.path, out, ranks=args.ranks, cwd=ROOT, overrides=[
                "output.progress=lines", "output.progress_every=200", *case.overrides, *sized, *args.set])
        summary = json.loads((out / "summary.json").read_text())
        statistics = read_statistics(out / "statistics.csv")
        key = case_key(case)
        ours = final(statistics)
        curves[key] = ours
        mesh = f"{summary['cells']} cells ({_config_value(out, 'cells')}), from {_start(out)}"
        rows.append(row(name, mesh, ours, ref[key], summary["wall_time"]))
    header = ["case", "mesh", "steps", *(f"{q} (published range; vs mean)" for q in QUANTITIES), "abs(Phi-W)/W",
              "wall time [s]"]
    BENCHMARK.log_load("end")
    BENCHMARK.publish(args.out / "results.md", "\n".join(markdown_table(header, rows)) + "\n")
    _plot(curves, ref, args.out / "results.png")
    print(f"wrote {args.out / 'results.png'}")
    return 0


def _config_value(run: Path, key: str) -> str:
    """A key's value as the run folder's config.yaml writes it (the first line ``key: ...``)."""
    lines = (run / "config.yaml").read_text().splitlines()
    return next(line.split(":", 1)[1].strip() for line in lines if line.strip().startswith(f"{key}:"))


def _start(run: Path) -> str:
    """Where the run started: the config's initial temperature, or the run it continued."""
    source = _config_value(run, "from_run")
    return "the initial temperature" if source in ("null", "") else f"the steady state of {Path(source).name} ({source})"


def _plot(curves: dict[tuple[str, float, float], dict[str, float]], ref: dict, png: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(QUANTITIES), figsize=(15, 3.8), constrained_layout=True)
    series = sorted({key[:2] for key in curves})
    for ax, quantity in zip(axes, QUANTITIES):
        for k, (form, ra) in enumerate(series):
            keys = sorted(key for key in curves if key[:2] == (form, ra))
            dis = [key[2] + 0.02 * (k - len(series) / 2) for key in keys]  # side by side
            spread = [published(ref[key], quantity) for key in keys]
            ax.errorbar(dis, [1.0] * len(keys), yerr=[[1 - lo / mean for lo, _, mean in spread],
                                                       [hi / mean - 1 for _, hi, mean in spread]],
                        fmt="none", ecolor="0.6", capsize=2)
            ax.plot(dis, [ref[key]["ASPECT"][quantity] / published(ref[key], quantity)[2] for key in keys], "x",
                    color=f"C{k}", alpha=0.6)
            ax.plot(dis, [curves[key][quantity] / published(ref[key], quantity)[2] for key in keys], "o",
                    color=f"C{k}", label=f"{form.upper()} Ra {ra:.0e}")
        ax.axhline(1.0, color="k", lw=0.6)
        ax.ticklabel_format(axis="y", useOffset=False)
        ax.set_xlabel("Di")
        ax.set_title(f"{quantity} / published mean")
    axes[0].legend(fontsize=7)
    fig.suptitle("King et al. (2010): this code (o), ASPECT (x), the range of the paper's codes (bars)")
    fig.savefig(png, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    sys.exit(main())
