"""Convergence orders, the markdown table and the log-log picture of the rigid-shear results, with
the Q2/Q1 numbers of Gassmöller et al. (2019) from ASPECT's result files (aspect_q2q1.json) beside
ours (P2/P1 on triangles)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any
from collections.abc import Iterable, Sequence

import numpy as np
import numpy.typing as npt

__all__ = ["convergence", "paper_rows", "series", "write_figure", "write_table"]

HERE = Path(__file__).resolve().parent
QUANTITIES = ("u", "p", "rho")
LABELS = {"u": "velocity", "p": "pressure", "rho": "density"}
PAPER_PPC = (16, 25, 36, 49, 100, 225, 400)
"""Particles per square in the paper's runs (ASPECT's result files)."""


def convergence(h: Sequence[float], e: Sequence[float], /) -> tuple[npt.NDArray[np.float64], float]:
    """(orders between consecutive resolutions shape=(n-1,), least-squares slope of log e over
    log h over all of them) for cell sizes ``h`` and errors ``e`` (shape=(n,), n >= 2)."""
    lh, le = np.log(np.asarray(h, dtype=float)), np.log(np.asarray(e, dtype=float))
    return np.diff(le) / np.diff(lh), float(np.polyfit(lh, le, 1)[0])


def series(runs: Iterable[dict[str, Any]], /) -> dict[tuple[str, str, int, str], list[dict[str, Any]]]:
    """Runs grouped by (problem, interpolator, ppc, integrator), each group sorted by cell size
    (coarsest first)."""
    groups: dict[tuple[str, str, int, str], list[dict[str, Any]]] = {}
    for run in runs:
        groups.setdefault((run["problem"], run["interpolator"], run["ppc"], run["integrator"]), []).append(run)
    return {k: sorted(v, key=lambda r: r["cells"]) for k, v in sorted(groups.items())}


def paper_rows() -> list[dict[str, Any]]:
    """The rows of aspect_q2q1.json (problem, interpolator, integrator, ppc_per_quad, h, u, p, rho)."""
    return json.loads((HERE / "aspect_q2q1.json").read_text())["rows"]


def paper_match(ppc: int, /) -> int:
    """The paper's particles per square closest (in log) to ours per triangle: 2 ppc per h^2."""
    return min(PAPER_PPC, key=lambda q: abs(np.log(q / (2.0 * ppc))))


def _paper_series(problem: str, interpolator: str, integrator: str, ppc_quad: int) -> list[dict[str, Any]]:
    rows = [r for r in paper_rows() if (r["problem"], r["interpolator"], r["integrator"], r["ppc_per_quad"])
            == (problem, interpolator, integrator, ppc_quad)]
    return sorted(rows, key=lambda r: -r["h"])


def _order_cell(h: Sequence[float], e: Sequence[float]) -> str:
    if len(h) < 2 or min(e) <= 0.0:
        return "–"
    pairs, fit = convergence(h, e)
    return f"{fit:.2f} ({pairs[-1]:.2f})"


def _choice(interpolator: str, ppc: int, integrator: str) -> str:
    text = f"`{interpolator}`" + (f", {ppc} ppc" if ppc else "")
    return text + (f", {integrator}" if integrator != "none" else "")


def _orders_table(groups: dict[tuple[str, str, int, str], list[dict[str, Any]]], problem: str) -> list[str]:
    lines = ["| choice | h | u order | p order | ρ order | paper Q2/Q1 (ppc/square) | paper u order | paper p order "
             "| paper ρ order |", "|---|---|---|---|---|---|---|---|---|"]
    for (prob, interp, ppc, integ), runs in groups.items():
        if prob != problem:
            continue
        h = [1.0 / r["cells"] for r in runs]
        ours = [_order_cell(h, [r[q] for r in runs]) for q in QUANTITIES]
        paper = ["", "", "", ""]
        paper_problem, paper_interp = ("instantaneous", "exact") if interp == "exact" else (problem, interp)
        ref = _paper_series(paper_problem, paper_interp, integ, 0 if interp == "exact" else paper_match(ppc))
        ref = [r for r in ref if 1.0 / r["h"] in {round(1.0 / x) for x in h}] or ref
        if ref:
            hp = [r["h"] for r in ref]
            paper = [f"{ref[0]['ppc_per_quad'] or 'exact ρ'}"] + [_order_cell(hp, [r[q] for r in ref]) for q in QUANTITIES]
        span = f"1/{runs[0]['cells']}–1/{runs[-1]['cells']}"
        lines.append(f"| {_choice(interp, ppc, integ)} | {span} | " + " | ".join(ours + paper) + " |")
    return lines


def _errors_table(groups: dict[tuple[str, str, int, str], list[dict[str, Any]]], problem: str) -> list[str]:
    cells = sorted({r["cells"] for runs in groups.values() for r in runs if r["problem"] == problem})
    lines = ["| quantity | choice | " + " | ".join(f"h = 1/{n}" for n in cells) + " |",
             "|---|---|" + "---|" * len(cells)]
    for q in QUANTITIES:
        for (prob, interp, ppc, integ), runs in groups.items():
            if prob != problem or (q == "rho" and interp == "exact"):
                continue
            by_cells = {r["cells"]: r[q] for r in runs}
            values = [f"{by_cells[n]:.3e}" if n in by_cells else "" for n in cells]
            lines.append(f"| {LABELS[q]} | {_choice(interp, ppc, integ)} | " + " | ".join(values) + " |")
    return lines


def write_table(results: dict[str, Any], path: Path, /, *, header: Sequence[str]) -> Path:
    """The markdown report of ``results`` (results.json's content) with ``header`` lines first."""
    groups = series(results["runs"])
    lines = list(header)
    for problem in ("instantaneous", "time_dependent"):
        if not any(k[0] == problem for k in groups):
            continue
        title = problem.replace("_", "-")
        lines += ["", f"## {title}: convergence orders", "",
                  "Order: least-squares slope over all resolutions (in brackets: between the two finest). "
                  "Paper: the Q2/Q1 runs at the closest particle density (our ppc per triangle x 2 = particles "
                  "per h²), same interpolator and integrator, over the same h.", ""]
        lines += _orders_table(groups, problem)
        lines += ["", f"## {title}: L2 errors", ""] + _errors_table(groups, problem)
    path.write_text("\n".join(lines) + "\n")
    return path


def _reference_slopes(ax: Any, h: npt.NDArray[np.float64], anchor: float) -> None:
    for k, style in ((1, ":"), (2, "--"), (3, "-.")):
        ax.loglog(h, anchor * (h / h[0]) ** k, color="grey", ls=style, lw=0.8, label=f"h^{k}")


def write_figure(results: dict[str, Any], path: Path, /, *, ppc: int | None = None) -> Path:
    """Errors against h: rows instantaneous / time-dependent (rk2), columns u, p, rho; every
    interpolator at ``ppc`` (default: the largest run), the exact density, and the paper's Q2/Q1
    cell average and linear least squares at the closest particle density (grey markers)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    groups = series(results["runs"])
    ppc = ppc or max(k[2] for k in groups)
    problems = [(p, i) for p, i in (("instantaneous", "none"), ("time_dependent", "rk2")) if any(k[0] == p for k in groups)]
    fig, axes = plt.subplots(len(problems), 3, figsize=(13, 4.2 * len(problems)), squeeze=False, constrained_layout=True)
    for row, (problem, integ) in enumerate(problems):
        for col, q in enumerate(QUANTITIES):
            ax = axes[row, col]
            _plot_ours(ax, groups, problem, integ, ppc, q)
            _plot_paper(ax, problem, integ, ppc, q)
            ax.set_title(f"{problem.replace('_', '-')}: {LABELS[q]}" + (f" ({integ})" if integ != "none" else ""))
            ax.set_xlabel("h")
            ax.set_ylabel(f"L2 error of {q}")
            ax.legend(fontsize=7)
    fig.suptitle(f"Rigid shear, P2/P1 triangles, {ppc} particles per triangle (random uniform); "
                 "grey: Gassmöller et al. 2019 Q2/Q1", fontsize=10)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def _plot_ours(ax: Any, groups: dict, problem: str, integ: str, ppc: int, q: str) -> None:
    anchor = None
    for (prob, interp, n, it), runs in groups.items():
        exact = interp == "exact"  # the finite-element limit (run as the instantaneous problem)
        if exact and q != "rho" and prob == "instantaneous":
            pass
        elif prob != problem or exact or n != ppc or it != integ:
            continue
        h = np.array([1.0 / r["cells"] for r in runs])
        e = np.array([r[q] for r in runs])
        _, fit = convergence(h, e) if len(h) > 1 else (None, float("nan"))
        ax.loglog(h, e, "o-" if not exact else "k*-", label=f"{interp} ({fit:.2f})")
        anchor = e[0] if anchor is None else max(anchor, e[0])
    if anchor is not None:
        _reference_slopes(ax, h, anchor * 1.5)


def _plot_paper(ax: Any, problem: str, integ: str, ppc: int, q: str) -> None:
    if problem != "time_dependent":
        ref = _paper_series("instantaneous", "exact", "none", 0)
        if q != "rho":
            ax.loglog([r["h"] for r in ref if r["h"] >= 1 / 64], [r[q] for r in ref if r["h"] >= 1 / 64], "x",
                      color="grey", label="paper: exact ρ")
        return
    for interp, marker in (("cell_average", "s"), ("least_squares", "^")):
        ref = _paper_series(problem, interp, integ, paper_match(ppc))
        ax.loglog([r["h"] for r in ref], [r[q] for r in ref], marker, color="grey", mfc="none",
                  label=f"paper: {interp} {paper_match(ppc)}/sq")
