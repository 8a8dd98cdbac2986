"""Visco-elastic stress build-up and relaxation in a box, against the Maxwell solutions.

Usage::

    python -m benchmarks.viscoelastic.stress                  # dt = 0.2 ... 0.0125, table and picture
    python -m benchmarks.viscoelastic.stress --quick          # dt = 0.2, 0.1, 0.05 on a 2 x 2 mesh
    mpirun -n 2 python -m benchmarks.viscoelastic.stress --ranks 2

A unit box of a Maxwell material (viscosity ``eta = 1``, shear modulus ``G = 1``: Maxwell time
``t_M = eta / G = 1``) is shortened in pure shear, ``u = (eps x, -eps z)`` with ``eps = 0.01``
(free slip on the left and bottom, the velocity prescribed on the right and top), from
``t = 0`` to ``t_load``; then the prescribed velocity is set to zero and the stress relaxes until
``t_end``. The stress, carried by the particles (``elastic_stress``), obeys::

    loading:     tau_xx(t) = 2 eta eps (1 - exp(-G t / eta))          (Gerya and Yuen 2007, section 3.1)
    relaxation:  tau_xx(t) = tau_xx(t_load) exp(-G (t - t_load) / eta)

The errors, over every step, each in the units of its curve's scale:

- ``build-up``: ``max_t |tau_xx - tau_exact| / (2 eta eps)``;
- ``relaxation``: ``max_t |tau_xx / tau_xx(t_load) - exp(-G (t - t_load) / eta)|``.

``tau_xx`` is the particles' mean; ``spread`` the largest difference between two particles (a
uniform stress must stay uniform). The time step is fixed (the elastic time step ``dt_e`` is the
step; ``run_case(..., dt_e=...)`` fixes a longer one, the stress averaged: docs/rheology.md, "A fixed
elastic time step"). The scheme is backward Euler in the stress (docs/rheology.md, "Elasticity"), so both errors
fall as ``dt``: the order is the slope of ``log(error)`` against ``log(dt)`` between successive
``dt``. Writes ``results.md`` and ``stress.png`` into ``--results`` (default: this folder) and
prints one JSON line last.
"""

from __future__ import annotations

import json
import logging
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from mpi4py import MPI

from benchmarks.harness import OUTPUT, Benchmark, markdown_table
from convection.app.factory import build_model
from convection.config.loader import load_config

HERE = Path(__file__).resolve().parent
BENCHMARK = Benchmark(__doc__, out=OUTPUT / "viscoelastic", results=HERE, results_option=True,
                      quick="dt = 0.2, 0.1, 0.05 on a 2 x 2 mesh (the CI size)",
                      helps={"out": "run folders", "results": "where the table and the picture go"})

ETA, G, EPS = 1.0, 1.0, 0.01
"""Viscosity, shear modulus and strain rate of the benchmark (nondimensional; Maxwell time 1)."""
STEPS = (0.2, 0.1, 0.05, 0.025, 0.0125)
QUICK_STEPS = (0.2, 0.1, 0.05)


def document(*, cells: int, dt: float, end: float, out: Path, dt_e: float | None = None,
             stress: str = "particles") -> dict[str, Any]:
    """The config of the box (module docstring) with a fixed step ``dt`` (and a fixed elastic time step
    ``dt_e``: the stress averaged between steps; None: ``dt_e = dt``); ``stress``: what carries the stress
    (``physics.elasticity.stress``: ``fields`` keeps the particles, without the stress, for the same run)."""
    pure_shear = {"kind": "prescribed", "value": [f"{EPS}*x", f"-{EPS}*z"]}
    elasticity = ({"enabled": True, "shear_modulus": G, "stress": stress}
                  | ({} if dt_e is None else {"elastic_time_step": dt_e}))
    return {
        "name": "viscoelastic_stress",
        "mesh": {"cells": [cells, cells]},
        "physics": {"Ra": 0.0, "viscosity": {"law": ETA}, "elasticity": elasticity},
        "boundary": {"velocity": {"left": "free_slip", "bottom": "free_slip", "right": pure_shear, "top": pure_shear},
                     "temperature": {side: "insulating" for side in ("left", "right", "bottom", "top")}},
        "initial": {"temperature": "0"},
        "energy": {"enabled": False},
        "stokes": {"solver": "direct"},
        "particles": {"enabled": True, "generator": {"name": "random_uniform", "particles_per_cell": 9, "seed": 1},
                      "properties": ["elastic_stress"] if stress == "particles" else [],
                      "population": {"min_per_cell": 4, "max_per_cell": 30, "seed": 3}},
        "time": {"end": end, "dt_max": dt, "cfl": 100.0},
        "blowup": {"lost_fraction": 1.0},  # the box's material leaves through the right side
        "output": {"directory": str(out), "progress": "none"},
    }


@dataclass(frozen=True)
class Curve:
    """One run: the times, the particles' mean ``tau_xx`` and its spread after every step.

    Attributes:
        dt: The step.
        t_load: When the loading stopped.
        t: Times, shape=(n,), from 0.
        tau: Mean ``tau_xx`` over the particles, shape=(n,).
        spread: Largest difference of ``tau_xx`` between two particles, shape=(n,).
    """

    dt: float
    t_load: float
    t: np.ndarray
    tau: np.ndarray
    spread: np.ndarray

    @property
    def loading(self) -> np.ndarray:
        return self.t <= self.t_load * (1 + 1e-12)

    def build_up_error(self) -> float:
        """``max |tau_xx - 2 eta eps (1 - exp(-G t / eta))| / (2 eta eps)`` while loading."""
        exact = 2 * ETA * EPS * (1 - np.exp(-G * self.t / ETA))
        return float(np.max(np.abs(self.tau - exact)[self.loading]) / (2 * ETA * EPS))

    def relaxation_error(self) -> float:
        """``max |tau_xx / tau_xx(t_load) - exp(-G (t - t_load) / eta)|`` after the loading."""
        k = int(np.flatnonzero(self.loading)[-1])
        s = self.t[k:] - self.t_load
        return float(np.max(np.abs(self.tau[k:] / self.tau[k] - np.exp(-G * s / ETA))))


def _stop_loading(model: Any) -> None:
    """Set the prescribed velocity to zero (the strong conditions' values are Functions)."""
    for bc in model.stokes.discretisation.dirichlet:
        g = bc.g
        if hasattr(g, "x"):
            g.x.array[:] = 0.0


def _stress_xx(model: Any, comm: MPI.Comm) -> tuple[float, float]:
    """The particles' (or the stress field's nodes') mean ``tau_xx`` and its spread (global)."""
    if model.elastic_stress is not None:
        field = model.elastic_stress.fields["elastic_stress_xx"]
        tau = field.x.array[:field.function_space.dofmap.index_map.size_local]
    else:
        tau = model.particles.primary.properties.values("elastic_stress")[:, 0]
    total = comm.allreduce(float(tau.sum()), op=MPI.SUM)
    count = comm.allreduce(int(tau.size), op=MPI.SUM)
    high = comm.allreduce(float(tau.max(initial=-np.inf)), op=MPI.MAX)
    low = comm.allreduce(float(tau.min(initial=np.inf)), op=MPI.MIN)
    return total / count, high - low


def run_case(dt: float, *, t_load: float, t_end: float, cells: int, out: Path,
             comm: MPI.Comm = MPI.COMM_WORLD, dt_e: float | None = None, stress: str = "particles") -> Curve:
    """Load to ``t_load``, relax to ``t_end`` with the step ``dt`` (and the elastic time step ``dt_e``;
    None: ``dt``; ``stress``: its carrier, ``physics.elasticity.stress``) (collective)."""
    config = load_config(None, document=document(cells=cells, dt=dt, end=t_end, out=out, dt_e=dt_e, stress=stress))
    model = build_model(config, comm=comm)
    model.start()
    times, taus, spreads = [0.0], *([value] for value in _stress_xx(model, comm))
    n_load, n_end = round(t_load / dt), round(t_end / dt)
    for n in range(1, n_end + 1):
        if n == n_load + 1:
            _stop_loading(model)
        model.step(dt)
        tau, spread = _stress_xx(model, comm)
        times.append(n * dt)
        taus.append(tau)
        spreads.append(spread)
    model.destroy()
    return Curve(dt, n_load * dt, np.array(times), np.array(taus), np.array(spreads))


def orders(dts: list[float], errors: list[float]) -> list[float]:
    """Observed orders ``log(e_i / e_{i+1}) / log(dt_i / dt_{i+1})`` (nan first)."""
    return [math.nan] + [math.log(errors[i - 1] / errors[i]) / math.log(dts[i - 1] / dts[i])
                         for i in range(1, len(dts))]


def table(curves: list[Curve]) -> str:
    """The markdown table of the errors and their orders."""
    dts = [c.dt for c in curves]
    build = [c.build_up_error() for c in curves]
    relax = [c.relaxation_error() for c in curves]
    rows = [[f"{c.dt:g}", f"{b * 100:.3f} %", "" if math.isnan(ob) else f"{ob:.2f}", f"{r * 100:.3f} %",
             "" if math.isnan(orr) else f"{orr:.2f}", f"{float(np.max(c.spread)):.1e}"]
            for c, b, ob, r, orr in zip(curves, build, orders(dts, build), relax, orders(dts, relax))]
    header = ["dt", "build-up error", "order", "relaxation error", "order", "spread"]
    return "\n".join(markdown_table(header, rows)) + "\n"


def picture(curves: list[Curve], path: Path) -> None:
    """The stress against time for every dt, with the exact curves, and the errors against dt."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4))
    fine = curves[-1]
    t = np.linspace(0.0, fine.t[-1], 400)
    exact = np.where(t <= fine.t_load, 1 - np.exp(-G * t / ETA),
                     (1 - np.exp(-G * fine.t_load / ETA)) * np.exp(-G * (t - fine.t_load) / ETA))
    left.plot(t, exact, "k-", lw=2.5, alpha=0.4, label="Maxwell (exact)")
    for c in curves:
        left.plot(c.t, c.tau / (2 * ETA * EPS), ".-", ms=3, lw=0.8, label=f"dt = {c.dt:g}")
    left.set_xlabel("t / t_M")
    left.set_ylabel("tau_xx / (2 eta eps)")
    left.legend(fontsize=8)
    dts = np.array([c.dt for c in curves])
    right.loglog(dts, [c.build_up_error() for c in curves], "o-", ms=11, mfc="none", label="build-up")
    right.loglog(dts, [c.relaxation_error() for c in curves], "s--", ms=4, label="relaxation (the same numbers)")
    right.loglog(dts, 0.2 * dts, "k--", lw=0.8, label="slope 1")
    right.axhline(5e-3, color="r", lw=0.8, ls=":", label="0.5 %")
    right.set_xlabel("dt / t_M")
    right.set_ylabel("max error (relative to the curve's scale)")
    right.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)


def main(argv: list[str] | None = None) -> int:
    parser = BENCHMARK.parser()
    parser.add_argument("--cells", type=int, default=4, help="cells per side")
    parser.add_argument("--load", type=float, default=3.0, help="end of the loading (Maxwell times)")
    parser.add_argument("--end", type=float, default=6.0, help="end time (Maxwell times)")
    args = parser.parse_args(argv)
    logging.getLogger().addFilter(lambda record: record.levelno >= logging.WARNING)
    comm = MPI.COMM_WORLD
    steps, cells = (QUICK_STEPS, 2) if args.quick else (STEPS, args.cells)
    if comm.rank == 0:
        BENCHMARK.log_load("start")
    curves = [run_case(dt, t_load=args.load, t_end=args.end, cells=cells, out=args.out / f"dt_{dt:g}", comm=comm)
              for dt in steps]
    if comm.rank == 0:
        text = table(curves)
        BENCHMARK.publish(args.results / "results.md", f"{cells} x {cells} cells, {comm.size} rank(s), loading to "
                          f"t = {args.load:g}, relaxing to t = {args.end:g} (Maxwell times)\n\n{text}")
        picture(curves, args.results / "stress.png")
        BENCHMARK.log_load("end")
        print(json.dumps({"dt": list(steps), "build_up": [c.build_up_error() for c in curves],
                          "relaxation": [c.relaxation_error() for c in curves]}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
