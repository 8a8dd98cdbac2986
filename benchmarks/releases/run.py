"""The same benchmarks on two Debian releases (DOLFINx 0.5.2 on Debian 12, 0.9 on Debian 13): do
they give the same numbers?

``measure`` runs, on the release it is started on, three benchmarks and writes their numbers with
the versions of Python, DOLFINx, PETSc, numpy, numba and gmsh to ``OUT/<codename>.json``:

- Blankenbach et al. (1989) case 1a (benchmarks/blankenbach/run.py, 2 ranks): Nu and vrms at
  steady state, and the number of steps it took;
- the annulus against the analytical solutions of Kramer et al. (2021)
  (benchmarks/shell/analytical.py, levels 0 1 2, each of the four kinds): velocity and pressure
  errors per level, on the same meshes (``OUT/meshes/*.msh``, written by the release measured
  first, read by the other: Debian 12's gmsh 4.8 and Debian 13's 4.13 mesh the annulus differently,
  673 and 675 cells at level 0, which moves the errors by 2e-4 to 8e-3 relative);
- van Keken et al. (1997) case 1a with particles on 2 ranks to t = 300 (the README's default job,
  benchmarks/vanKeken/run.py): the first vrms peak and the whole vrms curve.

``compare A.json B.json`` prints (and with ``--table`` writes) a Markdown table of each number on
both releases, the relative difference and the agreement asked for (1e-8 for Blankenbach and the
analytical errors, 1e-6 for van Keken).

Usage (scripts/compare_releases.sh runs both sides and compares)::

    python -m benchmarks.releases.run measure --out output/releases
    python -m benchmarks.releases.run compare output/releases/bookworm.json output/releases/trixie.json
"""

from __future__ import annotations

import csv
import json
import platform
import subprocess
import sys
from pathlib import Path

import numpy as np

from benchmarks.harness import Benchmark
from benchmarks.vanKeken.run import measure as measure_vankeken

ROOT = Path(__file__).resolve().parents[2]
BENCHMARK = Benchmark(__doc__)

ANALYTICAL_KINDS = ("smooth_free_slip", "smooth_zero_slip", "delta_free_slip", "delta_zero_slip")
TOLERANCES = {"blankenbach": 1e-8, "analytical": 1e-8, "vankeken": 1e-6}
"""Relative agreement asked for between the releases, per benchmark."""


def codename() -> str:
    """The Debian codename of this system (bookworm, trixie, ...), from /etc/os-release."""
    for line in Path("/etc/os-release").read_text().splitlines():
        if line.startswith("VERSION_CODENAME="):
            return line.split("=", 1)[1].strip().strip('"')
    return platform.node()


_VERSIONS = """
import json, platform, dolfinx, gmsh, numba, numpy
from petsc4py import PETSc
print(json.dumps({"python": platform.python_version(), "dolfinx": dolfinx.__version__,
                  "petsc": ".".join(str(v) for v in PETSc.Sys.getVersion()), "numpy": numpy.__version__,
                  "numba": numba.__version__, "gmsh": gmsh.__version__}))
"""


def versions() -> dict[str, str]:
    """Versions of the pieces that can change the numbers. Asked in a child process: importing
    DOLFINx here would make this process an MPI process, and the ``mpirun`` it starts for the
    benchmarks would then fail."""
    return json.loads(_python("-c", _VERSIONS).stdout)


def _python(*args: str) -> subprocess.CompletedProcess:
    """Run a benchmark script with this Python; its stderr is shown if it fails."""
    proc = subprocess.run([sys.executable, *args], cwd=ROOT, capture_output=True, text=True)
    if proc.returncode != 0:
        sys.stderr.write(proc.stdout[-3000:] + proc.stderr[-5000:])
        raise SystemExit(f"{' '.join(args)}: exit code {proc.returncode}")
    return proc


def _statistics(path: Path) -> dict[str, np.ndarray]:
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    return {key: np.array([float(r[key]) if r[key] not in ("", "None") else np.nan for r in rows])
            for key in rows[0]}


def measure(out: Path) -> Path:
    """Run the three benchmarks on this release; returns the JSON file written."""
    name = codename()
    work = out / name
    work.mkdir(parents=True, exist_ok=True)
    result: dict = {"release": name, "versions": versions()}

    _python("-m", "benchmarks.blankenbach.run", "--case", "1a", "--out", str(work / "blankenbach"))
    summary = json.loads((work / "blankenbach" / "1a" / "summary.json").read_text())
    result["blankenbach"] = {"nusselt": summary["nusselt"], "vrms": summary["vrms"], "steps": summary["steps"]}

    result["analytical"] = {}
    for kind in ANALYTICAL_KINDS:
        document = json.loads(_python("-m", "benchmarks.shell.analytical", "--kind", kind, "--levels", "0", "1", "2",
                                      "--mesh-dir", str(out / "meshes")).stdout)
        result["analytical"][kind] = [{"level": lv["level"], "cells": lv["cells"], "velocity_error": lv["velocity_error"],
                                       "pressure_error": lv["pressure_error"]} for lv in document["levels"]]

    _python("-m", "benchmarks.vanKeken.run", "--case", "1a", "--ranks", "2", "--end", "300", "--out", str(work / "vankeken"))
    stats = _statistics(work / "vankeken" / "1a" / "statistics.csv")
    first = measure_vankeken(stats)
    result["vankeken"] = {"peak_vrms": first.peak_vrms, "peak_time": first.peak_time,
                          "time": stats["time"].tolist(), "vrms": stats["vrms"].tolist()}

    path = out / f"{name}.json"
    path.write_text(json.dumps(result, indent=1) + "\n")
    return path


def _row(name: str, a: float, b: float, tolerance: float) -> tuple[str, bool]:
    rel = abs(a - b) / max(abs(a), abs(b), 1e-300)
    ok = rel <= tolerance
    return f"| {name} | {a:.12g} | {b:.12g} | {rel:.2e} | {tolerance:.0e} | {'yes' if ok else 'no'} |", ok


def compare(a: dict, b: dict) -> tuple[str, bool]:
    """Markdown table of every number of ``a`` and ``b``; True if all agree to their tolerance."""
    lines = [f"Releases: {a['release']} ({_versions(a)}) and {b['release']} ({_versions(b)}).", "",
             f"| quantity | {a['release']} | {b['release']} | rel. difference | asked | agrees |",
             "|---|---|---|---|---|---|"]
    oks = []

    def add(name: str, x: float, y: float, tolerance: float) -> None:
        line, ok = _row(name, x, y, tolerance)
        lines.append(line)
        oks.append(ok)

    tol = TOLERANCES["blankenbach"]
    for key in ("nusselt", "vrms", "steps"):
        add(f"Blankenbach 1a {key}", a["blankenbach"][key], b["blankenbach"][key], tol)
    tol = TOLERANCES["analytical"]
    for kind in ANALYTICAL_KINDS:
        for la, lb in zip(a["analytical"][kind], b["analytical"][kind]):
            if la["cells"] != lb["cells"]:
                lines.append(f"| annulus {kind} level {la['level']} cells | {la['cells']} | {lb['cells']} | "
                             "different meshes | equal | no |")
                oks.append(False)
            for key in ("velocity_error", "pressure_error"):
                add(f"annulus {kind} level {la['level']} {key.replace('_', ' ')}", la[key], lb[key], tol)
    tol = TOLERANCES["vankeken"]
    va, vb = a["vankeken"], b["vankeken"]
    add("van Keken 1a (particles, 2 ranks) first peak vrms", va["peak_vrms"], vb["peak_vrms"], tol)
    add("van Keken 1a first peak time", va["peak_time"], vb["peak_time"], tol)
    n = min(len(va["vrms"]), len(vb["vrms"]))
    curve = np.abs(np.array(va["vrms"][:n]) - np.array(vb["vrms"][:n])) / np.abs(np.array(va["vrms"][:n]))
    lines.append(f"| van Keken 1a vrms curve, largest rel. difference over {n} steps (steps: {len(va['vrms'])} vs "
                 f"{len(vb['vrms'])}) | | | {curve.max():.2e} | {tol:.0e} | {'yes' if curve.max() <= tol else 'no'} |")
    oks.append(bool(curve.max() <= tol) and len(va["vrms"]) == len(vb["vrms"]))
    return "\n".join(lines) + "\n", all(oks)


def _versions(r: dict) -> str:
    v = r["versions"]
    return (f"Python {v['python']}, DOLFINx {v['dolfinx']}, PETSc {v['petsc']}, numpy {v['numpy']}, "
            f"numba {v['numba']}, gmsh {v['gmsh']}")


def main(argv: list[str] | None = None) -> int:
    parser = BENCHMARK.parser()
    sub = parser.add_subparsers(dest="command", required=True)
    m = sub.add_parser("measure", help="run the benchmarks on this release")
    m.add_argument("--out", type=Path, default=ROOT / "output" / "releases")
    c = sub.add_parser("compare", help="compare two releases' numbers")
    c.add_argument("a", type=Path)
    c.add_argument("b", type=Path)
    c.add_argument("--table", type=Path, default=None, help="also write the table here")
    args = parser.parse_args(argv)
    if args.command == "measure":
        print(measure(args.out))
        return 0
    table, ok = compare(json.loads(args.a.read_text()), json.loads(args.b.read_text()))
    print(table)
    if args.table is not None:
        args.table.write_text(table)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
