"""A visco-elastic beam in a weak viscous medium, bent by gravity and recovering when it is switched
off (Keller, May and Kaus 2013, Geophys. J. Int. 195, appendix B.2.3; ASPECT's
``benchmarks/viscoelastic_bending_beam``), against ASPECT 2.5 on the same setup.

Usage::

    python -m benchmarks.viscoelastic.bending_beam                 # 30 x 20, 45 x 30 and 75 x 50 cells, table, picture
    python -m benchmarks.viscoelastic.bending_beam --quick         # 30 x 20 cells
    python -m benchmarks.viscoelastic.bending_beam --aspect-csv DIR   # ASPECT's run folder -> its tip curve

The setup (ASPECT's prm): a box of 7.5 km x 5 km holds a beam ``0 <= x <= 4.5 km``, ``2.5 km <= z
<= 3 km`` (density 3300 kg/m^3, viscosity 1e24 Pa s, shear modulus 1e10 Pa: Maxwell time 3.2 Myr,
elastic over the run) clamped in the left wall, in a medium of density 2800 kg/m^3, viscosity
1e18 Pa s and shear modulus 1e11 Pa (Maxwell time 0.3 yr: viscous). No slip on the left side, free
slip on the others, gravity 10 m/s^2. Gravity bends the beam for 50 kyr; then it is switched off
and the beam's elastic stress unbends it against the medium's viscous drag. The steps are 1 kyr
(the elastic time step is the step, as ASPECT's ``Use fixed elastic time step = false``); the flow
before the first step is the viscous one (ASPECT's time step 0).

Nondimensional here, with the units ``L = 1 km``, ``t0 = 1 kyr`` (ASPECT's year, 365.2425 days),
``eta0 = 1e18 Pa s`` and the stress ``eta0 / t0``: the medium has ``eta = 1``, ``G = 1e11 Pa /
(eta0 / t0)``; the beam is a material (carried by the particles, cell averages) with ``eta =
1e6``, ``G = 1e10 Pa / (eta0 / t0)`` and the buoyancy ``Rb = (3300 - 2800) g L / (eta0 / t0)``
(only the density difference drives a flow in a closed box). Its viscosity, shear modulus and
buoyancy mix with the medium's by volume fraction (viscosity: geometric; shear modulus: as
compliances); ASPECT takes the largest fraction's (``maximum composition``).

Measured: the **tip deflection**, ``z0 - z`` of a passive tracer particle (a second particle
system) started at the end of the beam's mid-line ``(4.5 km, 2.75 km)``, after every step: its
largest value (at the end of the loading) and the **elastic recovery** ``1 - w(t_end) / w_max``.
ASPECT's curve comes from the same tracer in its run (``benchmarks/viscoelastic/aspect/``: the
ASPECT 2.5 parameter files and the curves read from its output with ``--aspect-csv``). Agreement:
the largest difference of the two curves while loading and over the run, relative to ASPECT's
deflection at the end of the loading.

Writes ``bending_beam.md`` and ``bending_beam.png`` into ``--results`` (default: this folder) and
prints one JSON line last.
"""

from __future__ import annotations

import json
import logging
import re
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from mpi4py import MPI

from benchmarks.harness import OUTPUT, Benchmark, markdown_table
from convection.app.factory import build_model
from convection.config.loader import load_config

HERE = Path(__file__).resolve().parent
ASPECT = HERE / "aspect"
"""ASPECT 2.5's parameter files of the comparison and its tip curves (``bending_beam_<nx>x<nz>.csv``)."""
BENCHMARK = Benchmark(__doc__, out=OUTPUT / "viscoelastic_bending_beam", results=HERE, results_option=True,
                      quick="30 x 20 cells", no_run="read the curves of earlier runs (tip.csv in the run folders)",
                      helps={"out": "run folders", "results": "where the table and the picture go"})

YEAR = 365.2425 * 24 * 3600.0
"""ASPECT's year in seconds."""
T0, ETA0, LENGTH = 1.0e3 * YEAR, 1.0e18, 1.0e3
"""The units: time (1 kyr), viscosity (Pa s), length (m)."""
STRESS = ETA0 / T0
"""The stress unit (Pa)."""
GRAVITY, RHO_BEAM, RHO_MEDIUM = 10.0, 3300.0, 2800.0
ETA_BEAM, G_BEAM, G_MEDIUM = 1.0e24 / ETA0, 1.0e10 / STRESS, 1.0e11 / STRESS
RB_BEAM = (RHO_BEAM - RHO_MEDIUM) * GRAVITY * LENGTH / STRESS
WIDTH, HEIGHT = 7.5, 5.0
BEAM = "x <= 4.5 and z >= 2.5 and z <= 3.0"
TIP = np.array([[4.5, 2.75], [4.5, 3.0], [4.5, 2.5]])
"""Tracers: the end of the beam's mid-line (the measured one), its top and its bottom corner (km)."""
T_LOAD, T_END, DT = 50.0, 100.0, 1.0
"""End of the loading, of the run, and the step (kyr)."""
RECOVERY_WINDOW = (52.0, 59.0)
"""Where the recovery rate is measured (kyr): the first 7 kyr from the second step after the switch (the
first moves in the loaded flow in both codes)."""
RESOLUTIONS = ((30, 20), (45, 30), (75, 50))
QUICK = ((30, 20),)


def document(*, cells: tuple[int, int], dt: float, end: float, out: Path, tracers: Path,
             stress: dict[str, Any] | None = None) -> dict[str, Any]:
    """The config of the beam (module docstring), nondimensional, with a fixed step ``dt``; ``stress``:
    ``physics.elasticity`` keys of the stress's carrier (e.g. ``{"stress": "fields"}``; None: the particles)."""
    on_particles = (stress or {}).get("stress", "particles") == "particles"
    return {
        "name": "viscoelastic_bending_beam",
        "mesh": {"cells": list(cells), "upper": [WIDTH, HEIGHT]},
        "physics": {"Ra": 0.0, "viscosity": {"law": 1.0, "mixing": "geometric", "sharp": ["beam"]},
                    "elasticity": {"enabled": True, "shear_modulus": G_MEDIUM, **(stress or {})}},
        "materials": {"beam": {"initial": BEAM, "Rb": RB_BEAM, "viscosity": ETA_BEAM, "shear_modulus": G_BEAM}},
        "boundary": {"velocity": {"left": "no_slip", "right": "free_slip", "bottom": "free_slip", "top": "free_slip"},
                     "temperature": {side: "insulating" for side in ("left", "right", "bottom", "top")}},
        "initial": {"temperature": "0"},
        "energy": {"enabled": False},
        "composition": {"source": "particles", "degree": 1},
        "stokes": {"solver": "direct"},
        "particles": [
            {"name": "material", "generator": {"name": "random_uniform", "particles_per_cell": 16, "seed": 1},
             "integrator": "rk2", "interpolator": {"name": "least_squares", "limit": True},
             "properties": ["elastic_stress"] if on_particles else [], "population": {"min_per_cell": 6, "max_per_cell": 48, "seed": 3}},
            {"name": "tip", "generator": {"name": "from_file", "path": str(tracers)}, "integrator": "rk2"},
        ],
        "time": {"end": end, "dt_max": dt, "cfl": 100.0},
        "output": {"directory": str(out), "progress": "none"},
    }


@dataclass(frozen=True)
class Curve:
    """The tip deflection of one run (kyr, m).

    Attributes:
        label: Who ran it and at which resolution.
        t: Times after every step, shape=(n,), from 0.
        w: Deflection ``z0 - z`` of the mid-line tracer, shape=(n,).
    """

    label: str
    t: np.ndarray
    w: np.ndarray
    cpu_per_step: float = float("nan")
    """CPU seconds of the process per step (the steps' mean; nan: not measured)."""

    @property
    def loaded(self) -> float:
        """The deflection at the end of the loading (m)."""
        return float(np.interp(T_LOAD, self.t, self.w))

    @property
    def final(self) -> float:
        """The deflection at ``T_END`` (m; nan if the curve ends before)."""
        return float(np.interp(T_END, self.t, self.w)) if self.t[-1] >= T_END - 1e-9 else float("nan")

    @property
    def recovery(self) -> float:
        """``1 - w(T_END) / w(T_LOAD)``: the share of the deflection recovered."""
        return 1.0 - self.final / self.loaded

    @property
    def recovery_rate(self) -> float:
        """``-(w(b) - w(a)) / (b - a)`` over :data:`RECOVERY_WINDOW` (m/kyr; nan if the curve ends before)."""
        a, b = RECOVERY_WINDOW
        if self.t[-1] < b - 1e-9:
            return float("nan")
        return float(-(np.interp(b, self.t, self.w) - np.interp(a, self.t, self.w)) / (b - a))

    def at(self, t: np.ndarray) -> np.ndarray:
        return np.interp(t, self.t, self.w)


def _tip_z(model: Any, comm: MPI.Comm) -> np.ndarray:
    """The tracers' heights by id, shape=(3,) (global; a tracer that left the mesh is nan)."""
    swarm = model.particles["tip"].swarm
    z = np.full(len(TIP), -np.inf)
    ids = np.asarray(swarm.ids, dtype=np.int64) - comm.allreduce(int(np.min(swarm.ids, initial=2**62)), op=MPI.MIN)
    z[ids] = swarm.x[:, -1]
    found = np.empty_like(z)
    comm.Allreduce(z, found, op=MPI.MAX)
    return np.where(np.isfinite(found), found, np.nan)


def _unload(model: Any) -> None:
    """Switch gravity off: the beam's buoyancy to zero, and the Stokes forms built again."""
    approximation = model.stokes.approximation
    approximation.Rb = tuple(0.0 for _ in approximation.Rb) if isinstance(approximation.Rb, tuple) else 0.0
    model.stokes._forms_key = None  # the forms hold Rb as a number: prepare() builds them again


def run_case(cells: tuple[int, int], *, out: Path, t_load: float = T_LOAD, t_end: float = T_END, dt: float = DT,
             comm: MPI.Comm = MPI.COMM_WORLD, stress: dict[str, Any] | None = None) -> Curve:
    """Load to ``t_load``, recover to ``t_end`` (kyr) with the step ``dt`` (collective; ``stress``: see
    :func:`document`)."""
    out.mkdir(parents=True, exist_ok=True)
    tracers = out / "tip.txt"
    if comm.rank == 0:
        np.savetxt(tracers, TIP, header="x z (km): the beam's tip, mid-line, top, bottom")
    comm.barrier()
    config = load_config(None, document=document(cells=cells, dt=dt, end=t_end, out=out, tracers=tracers,
                                                 stress=stress))
    model = build_model(config, comm=comm)
    model.start()
    z0 = _tip_z(model, comm)[0]
    times, w = [0.0], [0.0]
    n_load, n_end = round(t_load / dt), round(t_end / dt)
    cpu = 0.0
    for n in range(1, n_end + 1):
        if n == n_load + 1:
            _unload(model)
        start = time.process_time()
        model.step(dt)
        cpu += time.process_time() - start
        times.append(n * dt)
        w.append((z0 - _tip_z(model, comm)[0]) * LENGTH)
    model.destroy()
    curve = Curve(f"this code, {cells[0]} x {cells[1]}", np.array(times), np.array(w), cpu / max(n_end, 1))
    if comm.rank == 0:
        np.savetxt(out / "tip.csv", np.column_stack([curve.t, curve.w]), delimiter=",", header="t_kyr,w_m", comments="")
    return curve


def saved_curve(cells: tuple[int, int], out: Path) -> Curve:
    """The curve that :func:`run_case` saved in ``out``."""
    data = np.loadtxt(out / "tip.csv", delimiter=",", skiprows=1, ndmin=2)
    return Curve(f"this code, {cells[0]} x {cells[1]}", data[:, 0], data[:, 1])


def aspect_curve(csv: Path) -> Curve:
    """ASPECT's tip curve of ``bending_beam_<nx>x<nz>.csv`` (columns ``t`` in kyr, ``w`` in m)."""
    data = np.loadtxt(csv, delimiter=",", skiprows=1, ndmin=2)
    nx, nz = re.findall(r"(\d+)x(\d+)", csv.stem)[-1]
    return Curve(f"ASPECT 2.5, {nx} x {nz}", data[:, 0], data[:, 1])


def read_aspect_run(folder: Path) -> np.ndarray:
    """The mid-line tracer's deflection (rows ``t`` kyr, ``w`` m) of an ASPECT run folder: the times
    of its ``log.txt`` (``*** Timestep N:  t=T years``, the last of each N: a resumed run repeats
    none) and the tracer with id 0 of ``particles/particles-N.0000.gnuplot``."""
    times = {int(n): float(t) / 1e3 for n, t in re.findall(r"\*\*\* Timestep (\d+):\s+t=([0-9.eE+-]+) years",
                                                           (folder / "log.txt").read_text())}
    rows = []
    for n, t in sorted(times.items()):
        path = folder / "particles" / f"particles-{n:05d}.0000.gnuplot"
        if not path.exists():
            continue
        data = np.loadtxt(path, comments="#", ndmin=2)
        z = float(data[data[:, 2] == 0][0, 1])
        rows.append((t, z))
    table = np.array(rows)
    return np.column_stack([table[:, 0], table[0, 1] - table[:, 1]])


def agreement(ours: Curve, theirs: Curve, until: float = T_END) -> float:
    """``max_t |w - w_aspect| / w_aspect(T_LOAD)`` over ASPECT's times up to ``until`` within both runs."""
    t = theirs.t[theirs.t <= min(ours.t[-1], theirs.t[-1], until) + 1e-9]
    return float(np.max(np.abs(ours.at(t) - theirs.at(t))) / theirs.loaded)


def table(curves: list[Curve], aspect: dict[str, Curve]) -> str:
    """The markdown table: deflection at the end of the loading, at the end, recovery, agreement."""
    rows = []
    for c in [*aspect.values(), *curves]:
        cells = c.label.split(", ")[-1]
        other = aspect.get(cells) if not c.label.startswith("ASPECT") else None
        end = f"{c.final:.1f}" if np.isfinite(c.final) else f"(ends at {c.t[-1]:g} kyr: {c.w[-1]:.1f})"
        rows.append([c.label, f"{c.loaded:.1f}", end, f"{c.recovery * 100:.1f} %" if np.isfinite(c.final) else "",
                     f"{c.recovery_rate:.2f}",
                     *(["", ""] if other is None else [f"{agreement(c, other, T_LOAD) * 100:.1f} %",
                                                      f"{agreement(c, other) * 100:.1f} %"])])
    header = ["run", f"w at {T_LOAD:g} kyr (m)", f"w at {T_END:g} kyr (m)", "recovered",
              f"recovery rate {RECOVERY_WINDOW[0]:g}-{RECOVERY_WINDOW[1]:g} kyr (m/kyr)",
              "max difference to ASPECT while loading", "over the run (of ASPECT's w at the load's end)"]
    return "\n".join(markdown_table(header, rows)) + "\n"


def picture(curves: list[Curve], aspect: dict[str, Curve], path: Path) -> None:
    """The tip deflection against time, this code's and ASPECT's."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4))
    colours: dict[str, str] = {}
    for c in [*aspect.values(), *curves]:  # one colour per mesh: ASPECT's thick, this code's dashed
        colour = colours.setdefault(c.label.split(", ")[-1], f"C{len(colours)}")
        aspects = c.label.startswith("ASPECT")
        ax.plot(c.t, c.w, "-" if aspects else "--", color=colour, lw=3 if aspects else 1.2,
                alpha=0.4 if aspects else 1.0, label=c.label)
    ax.axvline(T_LOAD, color="k", lw=0.6, ls=":")
    ax.set_xlim(0.0, T_END)
    ax.set_xlabel("time (kyr)")
    ax.set_ylabel("tip deflection (m)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)


def main(argv: list[str] | None = None) -> int:
    parser = BENCHMARK.parser()
    parser.add_argument("--cells", type=int, nargs=2, action="append", default=None, metavar=("NX", "NZ"),
                        help="the resolutions to run (repeatable; default: 30 x 20, 45 x 30, 75 x 50)")
    parser.add_argument("--aspect-csv", type=Path, default=None,
                        help="an ASPECT run folder: write its tip curve into aspect/ and stop")
    args = parser.parse_args(argv)
    if args.aspect_csv is not None:
        name = re.sub(r"\D*(\d+)$", r"\1", args.aspect_csv.name)
        rows = read_aspect_run(args.aspect_csv)
        target = ASPECT / f"bending_beam_{name}x{round(int(name) * HEIGHT / WIDTH)}.csv"
        np.savetxt(target, rows, delimiter=",", header="t_kyr,w_m", comments="", fmt="%.6g")
        print(f"wrote {target}")
        return 0
    logging.getLogger().addFilter(lambda record: record.levelno >= logging.WARNING)
    comm = MPI.COMM_WORLD
    resolutions = QUICK if args.quick else tuple(map(tuple, args.cells)) if args.cells else RESOLUTIONS
    if comm.rank == 0:
        BENCHMARK.log_load("start")
    runs = {cells: args.out / f"{cells[0]}x{cells[1]}" for cells in resolutions}
    curves = [saved_curve(cells, out) if args.no_run else run_case(cells, out=out, comm=comm) for cells, out in runs.items()]
    if comm.rank == 0:
        aspect = {f"{c.label.split(', ')[-1]}": c for c in map(aspect_curve, sorted(ASPECT.glob("bending_beam_*.csv")))}
        text = table(curves, aspect)
        BENCHMARK.publish(args.results / "bending_beam.md", f"{comm.size} rank(s), loading to {T_LOAD:g} kyr, "
                          f"recovering to {T_END:g} kyr, steps of {DT:g} kyr\n\n{text}")
        picture(curves, aspect, args.results / "bending_beam.png")
        BENCHMARK.log_load("end")
        print(json.dumps({c.label: {"loaded": c.loaded, "end": c.final, "recovery": c.recovery}
                          for c in curves}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
