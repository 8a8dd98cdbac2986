"""A visco-elasto-plastic shear band in compression, after Kaus (2010): the band's angle against
the Coulomb and Roscoe angles, and the stress-strain curve reaching the yield plateau.

Usage::

    python -m benchmarks.viscoelastic.shear_band                # 16 x 8 and 32 x 16 cells, table, picture
    python -m benchmarks.viscoelastic.shear_band --quick        # 16 x 8 cells

A box ``[0, 2] x [0, 1]`` of a visco-elasto-plastic material (viscosity ``eta = 1e4``, shear modulus
``G = 100``: Maxwell time 100, far beyond the run, so elastic before it yields; Drucker-Prager
yield stress ``sigma_y = C cos(phi) + p sin(phi)``, cohesion ``C = 1``, friction angle ``phi =
30``, no dilatancy ``psi = 0`` as the flow is incompressible, ``eta_star = 0.01``: a viscoplastic
regularisation, ``tau_II = sigma_y + 2 eta_star eps_pl``) is shortened in pure shear, ``u =
(-eps x, eps z)`` prescribed on the right side, free slip on the left side (a symmetry plane) and
the base, the top traction free, ``eps = 1``. A weak viscous seed (viscosity 0.01, radius 0.2, no
plasticity) sits in the corner at the origin. Gravity is off (``Ra = 0``): the pressure is the
stress's own. The stress is carried by the particles (``elastic_stress``). The box is at rest
before the first step (:func:`_start_at_rest`); the steps are ``t_yield / 10``.

Far from the seed the box deforms uniformly until it yields: ``tau_xx = -tau_II`` with
``tau_II = 2 eta_ve eps`` growing by backward Euler's Maxwell law, and the traction-free top
gives ``p = tau_zz = tau_II``, so the uniform box would yield at::

    tau_y = C cos(phi) / (1 - sin(phi)) = sqrt(3) C          (phi = 30 degrees)

at ``t_yield = tau_y / (2 G eps)``. From the seed a band grows to the surface. A Mohr-Coulomb
material makes its bands at the **Coulomb** angle ``45 - phi / 2 = 30`` degrees to the largest
compression (here horizontal); a plastic flow rule with dilatancy ``psi`` gives the **Roscoe**
angle ``45 - psi / 2 = 45`` degrees; Kaus (2010) found numerical bands between the two, near
Arthur's ``45 - (phi + psi) / 4 = 37.5`` degrees, depending on the resolution.

Measured:

- **the band angle**, from the strain rate's second invariant at the cell midpoints (DG0) at the
  end time (:func:`band_angle`): in each row of cell midpoints with ``0.3 <= z <= 0.8`` (away
  from the seed and the top) the band's position is the strain-rate-weighted mean ``x`` of the
  cells within ``2 h`` of the row's largest strain rate; a least-squares line ``x(z)`` through
  these positions gives the angle ``atan(|dz/dx|)`` to the horizontal;
- **the stress-strain curve**: the particles' mean ``tau_II`` (of the carried stress) against the
  shortening ``eps t``, in units of ``tau_y``, and, over the particles where the flow yields,
  ``sum tau_II / sum sigma_y`` (``p`` at the particle); the **plateau** is the latter's mean over
  the last quarter of the run and its error ``|plateau - 1|``;
- **the nonlinear solve**: the iterations of every step (Newton with the line search ``bt``,
  after Picard to ``1e-3``) and the residual per iteration of the last step (the relative
  residual ``|F| / |b|``, to ``rtol = 1e-6``).

Writes ``shear_band.md`` and ``shear_band.png`` into ``--results`` (default: this folder) and
prints one JSON line last.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from mpi4py import MPI

from benchmarks.harness import OUTPUT, Benchmark, markdown_table
from benchmarks.viscoelastic.common import resolutions_main
from convection.app.factory import build_model
from convection.config.loader import load_config

HERE = Path(__file__).resolve().parent
BENCHMARK = Benchmark(__doc__, out=OUTPUT / "viscoelastic_shear_band", results=HERE, results_option=True,
                      quick="24 x 6 cells (the CI size)",
                      helps={"out": "run folders", "results": "where the table and the picture go"})

ETA, G, COHESION, PHI, EPS = 1.0e4, 100.0, 1.0, 30.0, 1.0
"""Viscosity, shear modulus, cohesion, friction angle (degrees) and shortening rate (nondimensional)."""
SEED_ETA, SEED_RADIUS = 0.01, 0.2
ETA_STAR = 1.0e-2
"""The yield law's added viscosity (viscoplastic regularisation): without it the solve stalls."""
LENGTH = 2.0
TAU_Y = COHESION * math.cos(math.radians(PHI)) / (1.0 - math.sin(math.radians(PHI)))
"""The homogeneous yield stress of the box (module docstring)."""
COULOMB, ROSCOE, ARTHUR = 45.0 - PHI / 2.0, 45.0, 45.0 - PHI / 4.0
T_YIELD = TAU_Y / (2.0 * G * EPS)
"""When the homogeneous box would reach the yield stress (elastically)."""
RESOLUTIONS = ((16, 8), (32, 16))
QUICK = ((16, 8),)
STEPS = 16
"""Steps per run, of ``t_yield / 10`` each: the end time is ``1.6 t_yield``."""


def document(*, cells: tuple[int, int], dt: float, end: float, out: Path) -> dict[str, Any]:
    """The config of the box (module docstring) with a fixed step ``dt``."""
    shortening = {"kind": "prescribed", "value": [f"-{EPS}*x", f"{EPS}*z"]}
    plastic = {"name": "drucker_prager", "cohesion": COHESION, "friction_angle": PHI, "eta_star": ETA_STAR}
    return {
        "name": "viscoelastic_shear_band",
        "mesh": {"cells": list(cells), "upper": [LENGTH, 1.0], "diagonal": "crossed"},
        "physics": {"Ra": 0.0,
                    "viscosity": {"mixing": "geometric",
                                  "law": {"name": "viscoplastic", "combination": "minimum", "viscous": ETA,
                                          "plastic": plastic}},
                    "elasticity": {"enabled": True, "shear_modulus": G}},
        "materials": {"seed": {"initial": f"x**2 + z**2 < {SEED_RADIUS}**2", "Rb": 0.0,
                               "viscosity": SEED_ETA}},
        "boundary": {"velocity": {"left": "free_slip", "right": shortening, "bottom": "free_slip", "top": None},
                     "temperature": {side: "insulating" for side in ("left", "right", "bottom", "top")}},
        "initial": {"temperature": "0"},
        "energy": {"enabled": False},
        "composition": {"source": "particles", "degree": 0},
        "stokes": {"solver": "direct", "nonlinear": {"method": "newton", "rtol": 1.0e-6, "max_iterations": 400,
                                                     "switch_tolerance": 1.0e-3, "line_search": "bt"}},
        "particles": {"enabled": True, "generator": {"name": "random_uniform", "particles_per_cell": 6, "seed": 1},
                      "interpolator": {"name": "cell_average", "mean": "arithmetic"},
                      "properties": ["elastic_stress", "plastic_strain"],
                      "population": {"min_per_cell": 3, "max_per_cell": 24, "seed": 3}},
        "time": {"end": end, "dt_max": dt, "cfl": 100.0},
        "blowup": {"lost_fraction": 1.0},  # the material leaves through the top
        "output": {"directory": str(out), "progress": "none"},
    }


@dataclass(frozen=True)
class Run:
    """One resolution's run.

    Attributes:
        cells: Cells along x and z.
        strain: The shortening ``eps t`` after every step, shape=(STEPS + 1,), from 0.
        stress: The particles' mean ``tau_II / tau_y`` after every step, shape=(STEPS + 1,).
        at_yield: Over the yielding particles, ``sum tau_II / sum sigma_y`` after every step (0: none yields).
        yielding: The fraction of the particles that yield after every step.
        iterations: Nonlinear iterations of every step's solve, shape=(STEPS,).
        history: The relative residual per iteration of the last step's solve.
        angle: The band's angle (degrees to the horizontal).
        field: The cell midpoints' ``x``, ``z`` and strain rate ``eps_II`` at the end (rank 0; empty elsewhere).
    """

    cells: tuple[int, int]
    strain: np.ndarray
    stress: np.ndarray
    at_yield: np.ndarray
    yielding: np.ndarray
    iterations: np.ndarray
    history: tuple[float, ...]
    angle: float
    field: tuple[np.ndarray, np.ndarray, np.ndarray]

    @property
    def plateau(self) -> float:
        """The yielding particles' ``sum tau_II / sum sigma_y`` averaged over the last quarter of the run."""
        return float(np.mean(self.at_yield[-(len(self.at_yield) // 4):]))

    @property
    def plateau_error(self) -> float:
        """``|plateau - 1|``: the plateau's distance from the yield stress, relative."""
        return abs(self.plateau - 1.0)


def stress_measures(model: Any, comm: MPI.Comm) -> tuple[float, float, float]:
    """Of the particles (global): the mean ``tau_II = sqrt(((tau_xx - tau_zz) / 2)^2 + tau_xz^2)`` over
    ``tau_y``; over the particles where the flow yields (the ``plastic_strain_rate`` field positive
    at the particle) the sum of ``tau_II`` over the sum of ``sigma_y = C cos(phi) + max(p, 0) sin(phi)``
    (``p`` at the particle; 0 before any yields); and the fraction of the particles that yield."""
    from particles.properties._base import evaluate_at

    swarm = model.particles.primary.swarm
    tau = model.particles.primary.properties.values("elastic_stress")
    tau_ii = np.sqrt(0.25 * (tau[:, 0] - tau[:, 1]) ** 2 + tau[:, 2] ** 2)
    context = model.property_context()
    rows = np.arange(swarm.num_particles, dtype=np.int64)
    rate = model.rheology.rates["plastic_strain_rate"].function
    yielding = (evaluate_at(swarm, rows, rate, context)[:, 0] > 0.0) if rate is not None else np.zeros(len(rows), bool)
    p = evaluate_at(swarm, rows, model.stokes.p, context)[:, 0]
    phi = math.radians(PHI)
    sigma_y = COHESION * math.cos(phi) + np.maximum(p, 0.0) * math.sin(phi)
    sums = comm.allreduce(np.array([tau_ii.sum(), tau_ii.size, tau_ii[yielding].sum(), sigma_y[yielding].sum(),
                                    np.count_nonzero(yielding)], dtype=float), op=MPI.SUM)
    ratio = sums[2] / sums[3] if sums[4] > 0 else 0.0
    return float(sums[0] / sums[1] / TAU_Y), float(ratio), float(sums[4] / sums[1])


def strain_rate_cells(model: Any, comm: MPI.Comm) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The cell midpoints' ``x``, ``z`` and ``eps_II = sqrt(eps : eps / 2)`` of the current flow,
    gathered on rank 0 (empty arrays elsewhere). Collective."""
    import dolfinx.fem
    import dolfinx.mesh
    import ufl

    from fembase.dolfinx_compat import cell_dofmap, function_space, interpolation_points

    mesh = model.stokes.mesh
    space = function_space(mesh, "DG", 0)
    eps = ufl.sym(ufl.grad(model.stokes.u))
    rate = dolfinx.fem.Function(space)
    rate.interpolate(dolfinx.fem.Expression(ufl.sqrt(ufl.inner(eps, eps) / 2.0), interpolation_points(space)))
    tdim = mesh.topology.dim
    cells = np.arange(mesh.topology.index_map(tdim).size_local, dtype=np.int32)
    midpoints = dolfinx.mesh.compute_midpoints(mesh, tdim, cells)
    values = rate.x.array[cell_dofmap(space)[cells, 0]]
    parts = comm.gather((midpoints[:, 0], midpoints[:, 1], values), root=0)
    if comm.rank != 0:
        return np.empty(0), np.empty(0), np.empty(0)
    return tuple(np.concatenate([part[k] for part in parts]) for k in range(3))  # type: ignore[return-value]


def band_angle(x: np.ndarray, z: np.ndarray, rate: np.ndarray, h: float, *,
               rows: tuple[float, float] = (0.3, 0.8)) -> float:
    """The band's angle (degrees to the horizontal; module docstring): per row of midpoints in
    ``rows``, the strain-rate-weighted mean ``x`` within ``2 h`` of the row's largest strain rate; a
    least-squares line ``x(z)`` through them."""
    positions, levels = [], []
    for level in np.unique(np.round(z[(z >= rows[0]) & (z <= rows[1])], 9)):
        row = np.abs(z - level) < 1e-9
        peak = x[row][np.argmax(rate[row])]
        near = row & (np.abs(x - peak) <= 2.0 * h)
        positions.append(float(np.sum(rate[near] * x[near]) / np.sum(rate[near])))
        levels.append(float(level))
    slope = np.polyfit(levels, positions, 1)[0]  # dx / dz
    return math.degrees(math.atan(1.0 / abs(slope)))


def _start_at_rest(model: Any) -> None:
    """Solve the flow before the first step with the prescribed velocities zero, then restore them:
    the box is at rest at ``t = 0`` and the loading starts with the first step. (That flow is the
    viscous one, no time having passed: ``2 eta eps = 2e4`` would yield the whole box.)"""
    saved = [(bc.g, bc.g.x.array.copy()) for bc in model.stokes.discretisation.dirichlet if hasattr(bc.g, "x")]
    for g, _ in saved:
        g.x.array[:] = 0.0
    model.start()
    for g, values in saved:
        g.x.array[:] = values


def run_case(cells: tuple[int, int], *, out: Path, steps: int = STEPS, comm: MPI.Comm = MPI.COMM_WORLD) -> Run:
    """Shorten the box for ``steps`` steps of ``t_yield / 10`` (collective)."""
    dt = T_YIELD / 10.0
    model = build_model(load_config(None, document=document(cells=cells, dt=dt, end=steps * dt, out=out)), comm=comm)
    _start_at_rest(model)
    measures, iterations, history = [stress_measures(model, comm)], [], ()
    for _ in range(steps):
        model.step(dt)
        measures.append(stress_measures(model, comm))
        result = model.flow_result.nonlinear
        iterations.append(result.iterations)
        history = result.history
    field = strain_rate_cells(model, comm)
    model.destroy()
    angle = band_angle(*field, 1.0 / cells[1]) if comm.rank == 0 else math.nan
    stress, at_yield, yielding = (np.array(column) for column in zip(*measures))
    return Run(cells, EPS * dt * np.arange(steps + 1), stress, at_yield, yielding, np.array(iterations),
               tuple(history), comm.bcast(angle, root=0), field)


def table(runs: list[Run]) -> str:
    """The markdown table: the band angle against the Coulomb and Roscoe angles, the plateau and
    the nonlinear iterations, per resolution."""
    rows = [[f"{r.cells[0]} x {r.cells[1]}", f"{r.angle:.1f}", f"{COULOMB:g} / {ARTHUR:g} / {ROSCOE:g}",
             "yes" if COULOMB <= r.angle <= ROSCOE else "no", f"{r.plateau:.4f}", f"{r.plateau_error * 100:.2f} %",
             f"{r.stress[-1]:.3f}", f"{r.yielding[-1]:.2f}", f"{np.mean(r.iterations):.1f} / {np.max(r.iterations)}",
             f"{r.history[-1]:.1e}"] for r in runs]
    header = ["cells", "band angle", "Coulomb / Arthur / Roscoe", "between", "tau_II / sigma_y (yielding)",
              "plateau error", "mean tau_II / tau_y", "yielding", "iterations mean / max", "last residual"]
    return "\n".join(markdown_table(header, rows)) + "\n"


def picture(runs: list[Run], path: Path) -> None:
    """The finest run's strain rate with the measured band and the Coulomb and Roscoe lines; the
    stress-strain curves; the residual per iteration of the last step."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (field, curve, residual) = plt.subplots(1, 3, figsize=(16, 4.2), gridspec_kw={"width_ratios": [1.6, 1, 1]})
    fine = runs[-1]
    x, z, rate = fine.field
    shown = field.tricontourf(x, z, np.log10(np.maximum(rate, 1e-3)), levels=30, cmap="viridis")
    fig.colorbar(shown, ax=field, label="log10 eps_II")
    s = np.linspace(0.0, 1.0, 2)
    for angle, style, label in ((COULOMB, "w--", "Coulomb"), (ROSCOE, "w:", "Roscoe"), (fine.angle, "r-", "measured")):
        field.plot(s / math.tan(math.radians(angle)), s, style, lw=1.5, label=f"{label} {angle:.1f}")
    field.set_xlim(0.0, LENGTH)
    field.set_ylim(0.0, 1.0)
    field.set_aspect("equal")
    field.legend(fontsize=7, loc="upper right")
    field.set_title(f"{fine.cells[0]} x {fine.cells[1]}: strain rate at eps t = {fine.strain[-1]:.4f}")
    for r in runs:
        curve.plot(r.strain, r.stress, ".-", ms=3, label=f"{r.cells[0]} x {r.cells[1]}: mean tau_II / tau_y")
        yielded = r.at_yield > 0
        curve.plot(r.strain[yielded], r.at_yield[yielded], "s--", ms=3, label=f"{r.cells[0]} x {r.cells[1]}: "
                   "yielding tau_II / sigma_y")
    curve.axhspan(0.98, 1.02, color="0.85", label="yield stress +- 2 %")
    curve.set(xlabel="shortening eps t", ylabel="stress / yield stress")
    curve.legend(fontsize=7)
    for r in runs:
        residual.semilogy(range(len(r.history)), r.history, "o-", ms=3, label=f"{r.cells[0]} x {r.cells[1]}")
    residual.axhline(1e-6, color="k", lw=0.8, ls=":", label="rtol")
    residual.set(xlabel="nonlinear iteration (last step)", ylabel="|F| / |b|")
    residual.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=100)


def _publish(runs: list[Run], results: Path, *, steps: int, ranks: int) -> None:
    """Write the table and the picture into ``results``, log the load, print the JSON line."""
    summary = f"{ranks} rank(s), {steps} steps of t_yield / 10; tau_y = {TAU_Y:.4f}\n\n{table(runs)}"
    BENCHMARK.publish(results / "shear_band.md", summary)
    picture(runs, results / "shear_band.png")
    BENCHMARK.log_load("end")
    print(json.dumps({"cells": [list(r.cells) for r in runs], "angle": [r.angle for r in runs],
                      "plateau_error": [r.plateau_error for r in runs],
                      "iterations": [r.iterations.tolist() for r in runs], "history": [list(r.history) for r in runs]}))


def main(argv: list[str] | None = None) -> int:
    return resolutions_main(argv, BENCHMARK, run_case=run_case, resolutions=RESOLUTIONS, quick=QUICK, steps=STEPS,
                            steps_help="steps of t_yield / 10", publish=_publish)


if __name__ == "__main__":
    raise SystemExit(main())
