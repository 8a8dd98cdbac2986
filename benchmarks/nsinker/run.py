"""The nsinker Stokes problem (May et al. 2015; Rudi et al. 2017; ASPECT's benchmarks/nsinker): Stokes
iterations per solve against the viscosity contrast and the mesh, for the 3D Stokes solvers.

The set-up follows ASPECT 2.5's ``benchmarks/nsinker/nsinker_gmg.prm``: the unit cube, no slip on all six
sides (the pressure to zero mean), gravity 1 downward, ``n`` spheres of diameter ``omega = 0.1`` whose
centres are the first ``n`` of the list May et al. made (ASPECT's ``nsinker.cc``, :data:`CENTRES`). The
indicator of the outside, 1 far from every sinker and 0 inside one, is smooth::

    chi(x) = prod_i (1 - exp(-delta max(0, |x - c_i| - omega / 2)^2)),    delta = 200

and with the dynamic viscosity ratio DR the viscosity and density are::

    eta = (sqrt(DR) - 1 / sqrt(DR)) (1 - chi) + 1 / sqrt(DR),    rho = 10 (1 - chi)

(sqrt(DR) in the sinkers, 1 / sqrt(DR) around them). In this project's equations that is one material
of fraction ``C = 1 - chi`` (a UFL expression of the position, evaluated at the quadrature points as
ASPECT evaluates its material model), arithmetic mixing of the viscosities ``1 / sqrt(DR)`` and
``sqrt(DR)``, ``Rb = 10`` and ``T = 0``. One Stokes solve from zero to ``|b - K x| <= 1e-7 |b|`` (the
project's default; ASPECT's prm asks 1e-6) on P2-P1 tetrahedra, ``n`` cubes per side split into six.

Usage (``--quick``: 8^3 only, 4 sinkers)::

    mpirun -n 2 python -m benchmarks.nsinker.run --cells 8 16 --ratios 1e2 1e3 1e4 1e5 1e6 \\
        --solvers multigrid iterative iterative_gamg [--sinkers 4] [--out DIR]

Writes ``<out>/results.json`` (a row per solve), ``<out>/results.md`` and ``<out>/results.png``; the
committed copies are beside this script. Wall times depend on the machine's load (printed first).
"""

from __future__ import annotations

import json
import math
import resource
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import ufl
from mpi4py import MPI

import dolfinx
import dolfinx.fem.petsc

from benchmarks.harness import Benchmark, markdown_table
from convection.geometry.boundary import VelocityBC
from convection.geometry.box import SIDES_3D, BoxDomain, BoxSpec
from convection.physics.approximation import BoussinesqApproximation, ViscosityLaw
from convection.solvers.stokes.multigrid import MultigridSettings
from convection.solvers.stokes.solver import StokesResult, StokesSolver
from fembase.dolfinx_compat import function_space

HERE = Path(__file__).resolve().parent
BENCHMARK = Benchmark(__doc__, out=HERE, ranks=2, quick="8^3, 4 sinkers, the three iterative solvers")

CENTRES: tuple[tuple[float, float, float], ...] = (
    (2.4257829890e-01, 1.3469574514e-02, 3.8313885004e-01),
    (4.1465269048e-01, 6.7768972864e-02, 9.9312692973e-01),
    (4.8430804651e-01, 7.6533776604e-01, 3.1833815403e-02),
    (3.0935481671e-02, 9.3264044027e-01, 8.8787953411e-01),
    (5.9132973039e-01, 4.7877868473e-01, 8.3335433660e-01),
    (1.8633519681e-01, 7.3565270739e-01, 1.1505317181e-01),
    (6.9865863058e-01, 3.5560411138e-01, 6.3830000658e-01),
    (9.0821050755e-01, 2.9400041480e-01, 2.6497158886e-01),
)
"""The first sinker centres of May et al. (2015), as ASPECT's ``benchmarks/nsinker/nsinker.cc`` lists them."""
DELTA = 200.0
"""Sharpness of the indicator's edge."""
OMEGA = 0.1
"""Sinker diameter."""
SINKER_DENSITY = 10.0
RATIOS = (1e2, 1e3, 1e4, 1e5, 1e6)
SOLVERS = ("multigrid", "iterative", "iterative_gamg")


def outside(x: Any, sinkers: int, /) -> Any:
    """``chi``: the smooth indicator of the outside of the first ``sinkers`` spheres (UFL or numpy, ``x`` of
    shape (3, ...))."""
    if sinkers > len(CENTRES):
        raise ValueError(f"at most {len(CENTRES)} sinkers")
    numpy = isinstance(x, np.ndarray)
    exp, maximum, sqrt = ((np.exp, np.maximum, np.sqrt) if numpy else (ufl.exp, ufl.max_value, ufl.sqrt))
    chi: Any = 1.0
    for centre in CENTRES[:sinkers]:
        distance = sqrt(sum((x[i] - centre[i]) ** 2 for i in range(3)))
        gap = maximum(distance - OMEGA / 2.0, 0.0)
        chi = chi * (1.0 - exp(-DELTA * gap * gap))
    return chi


AVERAGING = ("none", "harmonic")
"""How the material enters (``--averaging``): ``none``, at the quadrature points (the formulas above);
``harmonic``, ASPECT's ``Material averaging = harmonic average`` (its nsinker_gmg.prm, which ASPECT 2.5's GMG
needs): viscosity and density each replaced on every cell by their harmonic mean over the cell,
``|K| / int_K 1 / f`` (DG0 fields; a density of zero at a point makes the cell's zero)."""


def approximation(ratio: float, /) -> BoussinesqApproximation:
    """The material model: viscosities ``1 / sqrt(DR)`` and ``sqrt(DR)`` mixed arithmetically by the fraction
    ``1 - chi``, buoyancy ``-10 (1 - chi) e_z``."""
    root = math.sqrt(ratio)
    return BoussinesqApproximation(Ra=0.0, Rb=SINKER_DENSITY,
                                   viscosity=ViscosityLaw(material_viscosities=(1.0 / root, root), mixing="arithmetic"))


class CellAveraged(BoussinesqApproximation):
    """:func:`approximation` with the viscosity replaced by a DG0 field ``eta`` (the buoyancy is ``-10 C e_z``
    as before; the caller passes the averaged density over 10 as ``C``)."""

    def __init__(self, ratio: float, eta: dolfinx.fem.Function, /) -> None:
        base = approximation(ratio)
        super().__init__(Ra=0.0, Rb=SINKER_DENSITY, viscosity=base.viscosity_law)
        self.eta = eta

    def viscosity(self, T: Any, C: Any, /, **flow: Any) -> Any:
        return self.eta


def harmonic_cell_mean(mesh: dolfinx.mesh.Mesh, f: Any, /) -> dolfinx.fem.Function:
    """``|K| / int_K 1 / f`` on every cell (DG0; quadrature degree 6, the Stokes forms'); ``f`` >= 0, a cell
    where ``f`` vanishes somewhere gets (nearly) zero."""
    Q0 = function_space(mesh, "DG", 0)
    v = ufl.TestFunction(Q0)
    dx = ufl.dx(metadata={"quadrature_degree": 6})
    volumes = dolfinx.fem.petsc.assemble_vector(dolfinx.fem.form(v * dx))
    inverses = dolfinx.fem.petsc.assemble_vector(dolfinx.fem.form(v / ufl.max_value(f, 1e-200) * dx))
    mean = dolfinx.fem.Function(Q0)
    owned = volumes.array.size  # DG0: no ghost contributions to add; the ghosts from their owners
    mean.x.array[:owned] = volumes.array / inverses.array
    mean.x.scatter_forward()
    volumes.destroy()
    inverses.destroy()
    return mean


def solve(comm: MPI.Comm, cells: int, ratio: float, solver: str, /, *, sinkers: int = 4, smoother: str = "jacobi",
          schur: str = "mass", averaging: str = "none", petsc_options: dict[str, Any] | None = None,
          label: str | None = None, keep: bool = False) -> dict[str, Any]:
    """One Stokes solve from zero (collective): iterations, the true residual against ``|b|``, vrms, the
    L2 norm of div u, seconds and the peak resident size. ``smoother``: ``stokes.multigrid.smoother``;
    ``schur``: ``stokes.schur``; ``averaging``: one of :data:`AVERAGING`; ``label``: the row's solver name
    (default: from the four). ``keep``: also the solver under ``"stokes"`` (the caller destroys it)."""
    domain = BoxDomain.from_spec(BoxSpec((cells,) * 3, (0.0,) * 3, (1.0,) * 3))
    levels = domain.mesh_levels() if solver == "multigrid" else 1
    meshes = domain.create_mesh_levels(comm, levels)
    mesh = meshes[-1]
    if averaging not in AVERAGING:
        raise ValueError(f"averaging {averaging!r}: one of {', '.join(AVERAGING)}")
    C: Any = 1.0 - outside(ufl.SpatialCoordinate(mesh), sinkers)
    material = approximation(ratio)
    if averaging == "harmonic":
        material = CellAveraged(ratio, harmonic_cell_mean(mesh, material.viscosity(0.0, C)))
        C = harmonic_cell_mean(mesh, C)  # the density over SINKER_DENSITY
    stokes = StokesSolver(mesh, material, bcs={side: VelocityBC("no_slip") for side in SIDES_3D},
                          solver=solver, coarse_meshes=meshes[:-1], petsc_options=petsc_options or None,
                          multigrid=MultigridSettings(smoother=smoother), schur=schur)
    start = time.perf_counter()
    try:
        result = stokes.solve(0.0, C)
        converged = True
    except RuntimeError:  # the KSP stopped at its maximum iterations: record it as such
        system = stokes.linear_system
        result = StokesResult(stokes.ksp.getIterationNumber(), system.residual_norm())
        converged = False
    seconds = comm.allreduce(time.perf_counter() - start, op=MPI.MAX)
    system = stokes.linear_system
    b_norm = float(system.b.norm())
    u = stokes.u
    vrms = math.sqrt(_integral(comm, ufl.inner(u, u) * ufl.dx))
    extras = [x for x, default in ((smoother if solver == "multigrid" else "jacobi", "jacobi"), (schur, "mass"),
                                   (averaging, "none")) if x != default]
    name = label or (f"{solver} ({', '.join(extras)})" if extras else solver)
    row = {"cells": cells, "ratio": ratio, "solver": name, "sinkers": sinkers, "levels": levels,
           "unknowns": (stokes.V.dofmap.index_map.size_global * stokes.V.dofmap.index_map_bs
                        + stokes.Q.dofmap.index_map.size_global),
           "iterations": result.iterations, "converged": converged, "relative_residual": result.residual_norm / b_norm if b_norm else 0.0,
           "vrms": vrms, "div_l2": math.sqrt(_integral(comm, ufl.div(u) ** 2 * ufl.dx)),
           "seconds": seconds, "setup_seconds": comm.allreduce(result.setup_seconds, op=MPI.MAX),
           "peak_rss_mb": comm.allreduce(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0, op=MPI.MAX)}
    if keep:
        row["stokes"] = stokes
    else:
        stokes.destroy()
    return row


def _key(row: dict[str, Any]) -> tuple[Any, ...]:
    return row["cells"], row["ratio"], row["solver"], row["sinkers"]


def _integral(comm: MPI.Comm, integrand: Any, /) -> float:
    return comm.allreduce(dolfinx.fem.assemble_scalar(dolfinx.fem.form(integrand)), op=MPI.SUM)


def growth(rows: Sequence[dict[str, Any]], solver: str, cells: int, /) -> str:
    """Iterations at the largest ratio over those at the smallest (one solver, one mesh), ``"> x"`` where
    the largest ratio's solve stopped unconverged."""
    mine = sorted((r["ratio"], r["iterations"], r.get("converged", True)) for r in rows
                  if r["solver"] == solver and r["cells"] == cells)
    if len(mine) < 2:
        return ""
    return ("" if mine[-1][2] else "> ") + f"{mine[-1][1] / mine[0][1]:.2f}"


def _iterations(row: dict[str, Any]) -> str:
    return str(row["iterations"]) if row.get("converged", True) else f"> {row['iterations']}"


def write(out: Path, rows: list[dict[str, Any]], *, load: str) -> None:
    """``results.json``, ``results.md`` and ``results.png`` under ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    (out / "results.json").write_text(json.dumps(rows, indent=1) + "\n")
    cells = sorted({r["cells"] for r in rows})
    solvers = [s for s in dict.fromkeys(r["solver"] for r in rows)]
    ratios = sorted({r["ratio"] for r in rows})
    sinkers = sorted({r["sinkers"] for r in rows})
    lines = ["# nsinker: Stokes iterations against the viscosity contrast", "",
             f"Generated by `python -m benchmarks.nsinker.run` ({', '.join(map(str, sinkers))} sinkers, P2-P1 "
             "tetrahedra, one solve from zero to |b - K x| <= 1e-7 |b|; " + load + "). Cells: Stokes iterations; "
             "the last column: iterations at the largest contrast over those at the smallest; > N: stopped "
             "unconverged at N (PETSc's ksp_max_it 1000).", ""]
    for n in cells:
        at = [r for r in rows if r["cells"] == n]
        lines += [f"## {n}^3 cubes ({at[0]['unknowns']} unknowns)", ""]
        table = []
        for solver in solvers:
            by_ratio = {r["ratio"]: r for r in at if r["solver"] == solver}
            if by_ratio:
                table.append([solver, *(_iterations(by_ratio[q]) if q in by_ratio else "" for q in ratios),
                              growth(at, solver, n)])
        lines += markdown_table(["solver", *(f"DR {q:.0e}" for q in ratios), "growth"], table) + [""]
    (out / "results.md").write_text("\n".join(lines))
    _picture(out / "results.png", rows, solvers, cells)


def _picture(path: Path, rows: list[dict[str, Any]], solvers: list[str], cells: list[int]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(9, 4.8))
    styles = ["-", "--", ":"]
    for k, n in enumerate(cells):
        for solver in solvers:
            pts = sorted((r["ratio"], r["iterations"]) for r in rows if r["cells"] == n and r["solver"] == solver)
            if pts:
                ax.loglog(*zip(*pts), styles[k % 3], marker="o", markersize=4, label=f"{solver}, {n}$^3$")
    ax.set_xlabel("viscosity ratio DR")
    ax.set_ylabel("Stokes iterations (from zero, rtol 1e-7)")
    ax.set_title("nsinker: iterations against the viscosity contrast")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)
    fig.tight_layout()
    fig.savefig(path, dpi=130)


def main(argv: list[str] | None = None) -> int:
    parser = BENCHMARK.parser()
    parser.add_argument("--cells", type=int, nargs="+", default=[8, 16])
    parser.add_argument("--ratios", type=float, nargs="+", default=list(RATIOS))
    parser.add_argument("--solvers", nargs="+", default=list(SOLVERS))
    parser.add_argument("--sinkers", type=int, default=4)
    parser.add_argument("--merge", action="store_true", help="add to (or replace rows of) <out>/results.json")
    parser.add_argument("--smoother", default="jacobi", help="stokes.multigrid.smoother of the multigrid")
    parser.add_argument("--schur", default="mass", help="stokes.schur of the iterative solvers (mass, wbfbt)")
    parser.add_argument("--averaging", default="none", choices=AVERAGING,
                        help="the material at the quadrature points (none) or cell-averaged, harmonic (ASPECT's)")
    parser.add_argument("--label", default=None, help="the rows' solver name (e.g. for an exact velocity solve)")
    parser.add_argument("--petsc", nargs="*", default=[], metavar="KEY=VALUE",
                        help="PETSc options on top of the solver's (e.g. fieldsplit_u_mg_levels_ksp_max_it=3)")
    args = parser.parse_args(argv)
    if args.quick:
        args.cells = [8]
    comm = MPI.COMM_WORLD
    load = BENCHMARK.log_load("start") if comm.rank == 0 else None
    petsc = dict(item.split("=", 1) for item in args.petsc)
    out = Path(args.out)
    rows = json.loads((out / "results.json").read_text()) if args.merge and (out / "results.json").exists() else []
    for n in args.cells:
        for solver in args.solvers:
            for ratio in args.ratios:
                row = solve(comm, n, ratio, solver, sinkers=args.sinkers, smoother=args.smoother,
                            schur=args.schur, averaging=args.averaging, petsc_options=petsc, label=args.label)
                rows = [r for r in rows if _key(r) != _key(row)] + [row]
                if comm.rank == 0:  # every row as it comes: a long sweep can be stopped and merged
                    out.mkdir(parents=True, exist_ok=True)
                    (out / "results.json").write_text(json.dumps(rows, indent=1) + "\n")
                if comm.rank == 0:
                    print(f"{n}^3 {solver} DR={ratio:.0e}: {row['iterations']} iterations, residual "
                          f"{row['relative_residual']:.1e}, vrms {row['vrms']:.6e}, {row['seconds']:.3f} s, "
                          f"peak {row['peak_rss_mb']:.0f} MB", flush=True)
    if comm.rank == 0:
        write(out, rows, load=f"{comm.size} ranks, {load}")
        print(f"wrote {args.out}/results.md")
    return 0


if __name__ == "__main__":
    sys.exit(main())
