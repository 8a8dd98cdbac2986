"""The bending beam and the elastic flexure with the elastic stress on particles and as advected mesh fields.

Usage::

    python -m benchmarks.viscoelastic.carriers                  # 30 x 20 and 45 x 30 cells, 100 kyr: carriers.md
    python -m benchmarks.viscoelastic.carriers --cells 75 50    # other resolutions (repeatable)
    python -m benchmarks.viscoelastic.carriers --quick          # 30 x 20 cells, 6 kyr loaded, 3 unloaded; flexure 32 x 32

The beam of :mod:`benchmarks.viscoelastic.bending_beam` (its material on particles in every run) at
each resolution, with ``physics.elasticity.stress``:

- ``particles``: the particles' ``elastic_stress``, fitted linearly per cell (``least_squares``
  into DG1, limited), the benchmark as published;
- ``fields``: continuous Lagrange fields of degree 2 (``stress_degree``, the default) and 1, advected
  as composition fields and updated by an L2 projection (docs/rheology.md, "The stress as fields").

The beam's table: the tip deflection at the end of the loading and of the run, the share recovered, the
recovery rate, the largest difference from ASPECT 2.5 on the same mesh (its committed curve, where
one exists) and from the particles' curve (relative to the particles' deflection at the end of the
loading), and the CPU time of the process per step (the steps' mean; the machine is shared: its
load at the start and the end is logged and written, the times are indicative only).

Then the elastic flexure of :mod:`benchmarks.viscoelastic.flexure` (``configs/lithosphere_flexure.yaml``,
a free surface: the fields are advected in the velocity relative to the moving mesh) at 64 x 64
cells for 6 steps, with the stress on the particles and as P2 fields: the deflection under the load,
the first zero and the forebulge against the thin plate, and the CPU time per step.

Writes ``carriers.md`` into ``--results`` (default: this folder) and prints one JSON line last.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path

import numpy as np
from mpi4py import MPI

from benchmarks.harness import OUTPUT, Benchmark, markdown_table
from benchmarks.viscoelastic import bending_beam, flexure
from benchmarks.viscoelastic.bending_beam import ASPECT, T_END, T_LOAD, Curve, agreement, aspect_curve

HERE = Path(__file__).resolve().parent
BENCHMARK = Benchmark(__doc__, out=OUTPUT / "viscoelastic_carriers", results=HERE, results_option=True,
                      quick="6 kyr loaded, 3 unloaded",
                      helps={"out": "run folders", "results": "where the table goes"})

CARRIERS: dict[str, dict[str, object] | None] = {
    "particles (least_squares, DG1)": None,
    "fields, P2": {"stress": "fields", "stress_degree": 2},
    "fields, P1": {"stress": "fields", "stress_degree": 1},
}
"""The runs: a label and the ``physics.elasticity`` keys of the carrier (None: the particles)."""
RESOLUTIONS = [(30, 20), (45, 30)]
FLEXURE_CELLS = (64, 64)


def table(curves: dict[str, Curve], aspect: Curve | None, *, t_load: float, t_end: float) -> str:
    """The markdown table of the runs (module docstring)."""
    reference = next(iter(curves.values()))

    def difference(c: Curve, other: Curve, until: float) -> float:
        t = c.t[c.t <= until + 1e-9]
        return float(np.max(np.abs(c.at(t) - other.at(t))) / np.interp(t_load, other.t, other.w))

    rows = []
    for label, c in curves.items():
        final = float(np.interp(t_end, c.t, c.w))
        loaded = float(np.interp(t_load, c.t, c.w))
        rows.append([label, f"{loaded:.1f}", f"{final:.1f}", f"{(1 - final / loaded) * 100:.1f} %",
                     "" if aspect is None else f"{agreement(c, aspect, t_load) * 100:.1f} %",
                     "" if aspect is None else f"{agreement(c, aspect, t_end) * 100:.1f} %",
                     "" if c is reference else f"{difference(c, reference, t_end) * 100:.2f} %",
                     f"{c.cpu_per_step:.2f}"])
    header = ["stress carrier", f"w at {t_load:g} kyr (m)", f"w at {t_end:g} kyr (m)", "recovered",
              "max difference to ASPECT while loading", "over the run", "max difference to the particles' curve",
              "CPU s / step"]
    return "\n".join(markdown_table(header, rows)) + "\n"


def flexure_table(runs: dict[str, flexure.Run]) -> str:
    """The flexure's markdown table: measured against the thin plate, and the cost."""
    rows = []
    for label, r in runs.items():
        (w0, x0, xb), (e0, ex, eb) = r.measured, r.errors
        rows.append([label, f"{w0:.1f} ({e0 * 100:+.1f} %)", f"{x0 / 1e3:.2f} ({ex * 100:+.1f} %)",
                     f"{xb / 1e3:.2f} ({eb * 100:+.1f} %)", f"{r.settled:.1e}", f"{r.cpu_per_step:.2f}"])
    rows.append(["thin plate (Turcotte & Schubert)", f"{flexure.W0:.1f}", f"{flexure.X0 / 1e3:.2f}",
                 f"{flexure.XB / 1e3:.2f}", "", ""])
    header = ["stress carrier", "w0 [m]", "first zero x0 [km]", "forebulge xb [km]", "last step's change of w0",
              "CPU s / step"]
    return "\n".join(markdown_table(header, rows)) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = BENCHMARK.parser()
    parser.add_argument("--cells", type=int, nargs=2, action="append", default=None, metavar=("NX", "NZ"),
                        help="the resolutions to run (repeatable; default: 30 x 20 and 45 x 30)")
    args = parser.parse_args(argv)
    logging.getLogger().addFilter(lambda record: record.levelno >= logging.WARNING)
    comm = MPI.COMM_WORLD
    resolutions = [(30, 20)] if args.quick else [tuple(c) for c in args.cells] if args.cells else RESOLUTIONS
    t_load, t_end = (6.0, 9.0) if args.quick else (T_LOAD, T_END)
    start = BENCHMARK.log_load("start") if comm.rank == 0 else None
    runs = {cells: {label: bending_beam.run_case(cells, out=Path(args.out) / f"{cells[0]}x{cells[1]}_{index}",
                                                 t_load=t_load, t_end=t_end, comm=comm, stress=stress)
                    for index, (label, stress) in enumerate(CARRIERS.items())} for cells in resolutions}
    plate = (32, 32) if args.quick else FLEXURE_CELLS
    plates = {label: flexure.run_case(plate, out=Path(args.out) / f"flexure_{plate[0]}x{plate[1]}_{index}",
                                      steps=2 if args.quick else flexure.STEPS, comm=comm, fields=fields)
              for index, (label, fields) in enumerate((("particles (least_squares, DG1)", False),
                                                       ("fields, P2", True)))}
    if comm.rank == 0:
        end = BENCHMARK.log_load("end")
        heading = (f"{comm.size} rank(s), loading to {t_load:g} kyr, recovering to {t_end:g} kyr, steps of "
                   f"{bending_beam.DT:g} kyr; {start} at the start, {end} at the end (2 cores shared with other "
                   "runs: the CPU times are indicative only)")
        parts = [heading]
        for cells, curves in runs.items():
            path = ASPECT / f"bending_beam_{cells[0]}x{cells[1]}.csv"
            aspect = aspect_curve(path) if path.exists() else None
            parts.append(f"{cells[0]} x {cells[1]} cells:\n\n{table(curves, aspect, t_load=t_load, t_end=t_end)}")
        parts.append(f"Elastic flexure, {plate[0]} x {plate[1]} cells, {2 if args.quick else flexure.STEPS} steps of "
                     f"0.1 Myr:\n\n{flexure_table(plates)}")
        BENCHMARK.publish(args.results / "carriers.md", "\n\n".join(parts))
        print(json.dumps({f"{cells[0]}x{cells[1]}": {label: {
            "loaded": float(np.interp(t_load, c.t, c.w)), "end": float(np.interp(t_end, c.t, c.w)),
            "cpu_per_step": c.cpu_per_step} for label, c in curves.items()} for cells, curves in runs.items()}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
