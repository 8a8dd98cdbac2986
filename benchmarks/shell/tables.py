"""Markdown tables of the JSON results of ``analytical.py`` (``measured/*.json``), for the README.

Usage: ``python -m benchmarks.shell.tables [measured/*.json ...]`` (default: every file in measured/).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent


def table(document: dict, reference: dict | None = None) -> str:
    """One result as a markdown table; with ``reference`` (the same case on another rank count),
    a column of the relative differences of the errors."""
    case = document["case"]
    harmonic = f"n = {case['n']}" if case["dim"] == 2 else f"l = {case['n']}, m = {case['m']}"
    forcing = f", k = {case['k']}" if case["kind"].startswith("smooth") else ""
    solver = document.get("solver", "direct")
    solver = "" if solver == "direct" else f", Stokes solver {document.get('solver_resolved', solver)}"
    refinement = {"adaptive": ", adaptive (Kelly indicator of the velocity; a level is a round)",
                  "hierarchy": ", the hierarchy's uniform refinement"}.get(document.get("refinement", "gmsh"), "")
    lines = [f"**{case['kind']}, {case['dim']}D, {harmonic}{forcing}, {document['ranks']} rank(s), "
             f"geometry degree {document['geometry_degree']}{solver}{refinement}**", ""]
    header = "| level | cells | h | dofs | velocity error | pressure error | solve [s] |"
    rule = "|---:|---:|---:|---:|---:|---:|---:|"
    if reference is not None:
        header += " max rel. diff. to 1 rank |"
        rule += "---:|"
    lines += [header, rule]
    for i, row in enumerate(document["levels"]):
        line = (f"| {row['level']} | {row['cells']} | {row['h']:.4f} | {row['dofs']} | {row['velocity_error']:.3e} | "
                f"{row['pressure_error']:.3e} | {row['solve_seconds']:.2f} |")
        if reference is not None:
            ref = reference["levels"][i]
            diff = max(abs(row[k] - ref[k]) / abs(ref[k]) for k in ("velocity_error", "pressure_error"))
            line += f" {diff:.1e} |"
        lines.append(line)
    orders = document["orders"]
    if orders["velocity"] is not None:
        lines += ["", f"Fitted orders: velocity {orders['velocity']:.2f}, pressure {orders['pressure']:.2f}"
                  + (" (against h = (|Omega| / cells)^(1/dim))." if refinement else ".")]
    return "\n".join(lines)


def main(paths: list[str]) -> None:
    files = [Path(p) for p in paths] or sorted((HERE / "measured").glob("*.json"))
    for path in files:
        document = json.loads(path.read_text())
        if "case" not in document:  # e.g. annulus_particles.json
            continue
        reference = None
        if document["ranks"] > 1:
            serial = path.with_name(path.name.replace(f"_np{document['ranks']}", "_np1"))
            if serial.is_file():
                reference = json.loads(serial.read_text())
        print(f"<!-- {path.name} -->\n{table(document, reference)}\n")


if __name__ == "__main__":
    main(sys.argv[1:])
