"""Elastic flexure of a plate under a load, with a free surface, against the thin-plate solution
(Turcotte & Schubert, Geodynamics, ch. 3): the deflection under the load, the first zero and the
forebulge, at two resolutions.

Usage::

    python -m benchmarks.viscoelastic.flexure               # 64 x 64 and 128 x 128 cells, table, picture
    python -m benchmarks.viscoelastic.flexure --quick       # 32 x 32 cells (a smoke run)

The model is ``configs/lithosphere_flexure.yaml`` as shipped (only the cells change): a 5 km
elastic plate (shear modulus ``G = 3e10 Pa``, viscosity ``1e28 Pa s``: Maxwell time 10 Gyr against
a 0.6 Myr run) on a ``1e20 Pa s`` mantle, both ``rho = 3300 kg/m^3``, in a 160 x 80 km box with a
free surface on top, free slip on the sides, no slip at the bottom, ``g = 10 m/s^2``. The plate's
column ``x <= a = 2.5 km`` is ``1000 kg/m^3`` denser: with the left side a symmetry plane, half of
a band load ``V0 = 1000 kg/m^3 g h 2a = 2.5e11 N/m`` per unit length. Steps of 0.1 Myr
(``free_surface.theta = 1``): the mantle relaxes to isostasy within a few (:data:`STEPS`).

**The thin plate** (the incompressible plate in plane strain): ``D w'''' + rho g w = q``, with ``D =
E h^3 / (12 (1 - nu^2))``; incompressible ``nu = 1/2``, ``E = 2 G (1 + nu) = 3 G``, so ``D = G h^3 /
3`` (plane strain is the plate's cylindrical bending: ``E / (1 - nu^2)`` is its modulus). The
restoring force is the mantle's weight at the free surface, ``rho g`` (nothing fills the trough). For
a line load ``V0``: ``alpha = (4 D / (rho g))^(1/4) = 19.73 km``, ``w0 = V0 alpha^3 / (8 D) = 192.0
m``, ``w(x) = w0 exp(-x / alpha) (cos(x / alpha) + sin(x / alpha))``, the first zero at ``x0 = 3 pi
alpha / 4 = 46.5 km`` and the forebulge at ``xb = pi alpha = 62.0 km``, ``w0 exp(-pi) = 8.3 m``
high (``w`` positive down).

**The closed box** keeps its volume: the load's weight is carried by the whole base, and the
surface rises everywhere by ``V0 / (rho g 2 L) = 23.7 m`` (``2 L``: the mirrored box) against the
infinite plate (the thin-plate equation in the box is solved by its cosine series,
:func:`box_thin_plate`: the same shape as Turcotte & Schubert's less this uplift, to 0.1 %). The
measured deflection is the model's less this uplift, ``w = -topography + 23.7 m``:

- **w0**: ``w`` at ``x = 0``, against ``V0 alpha^3 / (8 D)``;
- **x0**: the first zero of ``w`` (linear between the surface nodes), against ``3 pi alpha / 4``;
- **xb**: the forebulge, the lowest ``w`` (a parabola through the lowest node and its neighbours),
  against ``pi alpha``.

The deflection under the load converges as the mantle relaxes: the table gives its change over the
last step. Writes ``flexure.md`` and ``flexure.png`` into ``--results`` (default: this folder) and
prints one JSON line last.
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from mpi4py import MPI

from benchmarks.harness import OUTPUT, ROOT, Benchmark, markdown_table
from benchmarks.viscoelastic.common import resolutions_main
from convection.app.factory import build_model
from convection.config.loader import load_config

HERE = Path(__file__).resolve().parent
CONFIG = ROOT / "configs" / "lithosphere_flexure.yaml"
BENCHMARK = Benchmark(__doc__, out=OUTPUT / "viscoelastic_flexure", results=HERE, results_option=True,
                      quick="32 x 32 cells (2 across the plate: a smoke run)",
                      helps={"out": "run folders", "results": "where the table and the picture go"})

G, H, RHO, GRAVITY, LOAD_RHO, HALF_WIDTH, LENGTH = 3.0e10, 5.0e3, 3300.0, 10.0, 1000.0, 2.5e3, 160.0e3
"""Of the config [SI]: shear modulus, plate thickness, density, gravity, the load's excess density,
its half width, the box's width."""
D = G * H**3 / 3.0
"""Flexural rigidity of the incompressible plate in plane strain, ``E h^3 / (12 (1 - nu^2))`` with ``E = 3 G``."""
ALPHA = (4.0 * D / (RHO * GRAVITY)) ** 0.25
V0 = LOAD_RHO * GRAVITY * H * 2.0 * HALF_WIDTH
"""The whole load per unit length (both halves of the mirrored box)."""
W0 = V0 * ALPHA**3 / (8.0 * D)
X0, XB = 3.0 * math.pi * ALPHA / 4.0, math.pi * ALPHA
UPLIFT = V0 / (RHO * GRAVITY * 2.0 * LENGTH)
"""The closed box's uniform rise against the infinite plate (module docstring)."""
STEPS, DT_MYR = 6, 0.1
"""Steps of the config's ``time.dt_max`` (0.1 Myr)."""
RESOLUTIONS = ((64, 64), (128, 128))
QUICK = ((32, 32),)
LENGTH_UNIT = 80.0e3
"""The config's length unit ``L`` [m] (``scaling.length``)."""


def thin_plate(x: np.ndarray) -> np.ndarray:
    """Turcotte & Schubert's line load on an infinite plate: ``w(x)`` [m], positive down."""
    s = np.asarray(x) / ALPHA
    return W0 * np.exp(-s) * (np.cos(s) + np.sin(s))


def box_thin_plate(x: np.ndarray, *, shear: bool = False, terms: int = 20000) -> np.ndarray:
    """The thin-plate equation in the closed, mirrored box with the band load, plus the uniform
    uplift (so comparable with :func:`thin_plate`): ``w = UPLIFT + sum_n q_n cos(k_n x) / (D_n k_n^4
    + rho g)``, ``k_n = n pi / L``, ``q_n = 2 q sin(k_n a) / (n pi)``. ``shear``: Timoshenko's
    shear compliance, ``D_n = D / (1 + D k_n^2 / (kappa G h))`` with ``kappa = 5/6`` (an estimate of
    the plate's thickness error, not a reference)."""
    k = np.arange(1, terms + 1) * math.pi / LENGTH
    q = 2.0 * LOAD_RHO * GRAVITY * H * np.sin(k * HALF_WIDTH) / (np.arange(1, terms + 1) * math.pi)
    stiffness = D * k**4 / (1.0 + D * k**2 / (5.0 / 6.0 * G * H)) if shear else D * k**4
    weights = q / (stiffness + RHO * GRAVITY)
    x = np.asarray(x, dtype=np.float64)
    # in blocks of points: the whole cos(x k) of 16001 points and 20000 terms would take 2.6 GB twice
    return UPLIFT + np.concatenate([np.cos(np.outer(part, k)) @ weights
                                    for part in np.array_split(x, max(1, x.size // 256))])


def measures(x: np.ndarray, w: np.ndarray) -> tuple[float, float, float]:
    """``(w0, x0, xb)`` of a profile ``w(x)`` sorted by ``x`` (module docstring)."""
    below = np.nonzero(w <= 0.0)[0][0]
    x0 = x[below - 1] + (x[below] - x[below - 1]) * w[below - 1] / (w[below - 1] - w[below])
    i = int(np.clip(np.argmin(w), 1, len(w) - 2))
    a, b, _ = np.polyfit(x[i - 1:i + 2], w[i - 1:i + 2], 2)
    return float(w[0]), float(x0), float(-b / (2.0 * a))


@dataclass(frozen=True)
class Run:
    """One resolution's run.

    Attributes:
        cells: Cells along x and z.
        x: The surface nodes' positions [m], sorted.
        w: The deflection at the end, less the box's uplift [m], positive down.
        history: ``w(0)`` after every step [m].
        mean: The surface's mean height at the end [m] (the box's volume: 0).
    """

    cells: tuple[int, int]
    x: np.ndarray
    w: np.ndarray
    history: tuple[float, ...]
    mean: float
    cpu_per_step: float = float("nan")
    """CPU seconds of the process per step (the steps' mean)."""

    @property
    def measured(self) -> tuple[float, float, float]:
        return measures(self.x, self.w)

    @property
    def errors(self) -> tuple[float, float, float]:
        """Relative errors of ``(w0, x0, xb)`` against Turcotte & Schubert's."""
        return tuple(m / r - 1.0 for m, r in zip(self.measured, (W0, X0, XB)))  # type: ignore[return-value]

    @property
    def settled(self) -> float:
        """The change of ``w(0)`` over the last step, relative."""
        return abs(self.history[-1] - self.history[-2]) / abs(self.history[-1])


def surface(model, comm: MPI.Comm) -> tuple[np.ndarray, np.ndarray]:
    """The surface nodes' ``x`` [m] and heights [m], sorted, on every rank (collective)."""
    x, h = model.free_surface.heights()
    parts = comm.allgather((x[:, 0], h))
    x, h = (np.concatenate([p[k] for p in parts]) * LENGTH_UNIT for k in (0, 1))
    x, keep = np.unique(x, return_index=True)
    return x, h[keep]


def run_case(cells: tuple[int, int], *, out: Path, steps: int = STEPS, comm: MPI.Comm = MPI.COMM_WORLD,
             fields: bool = False) -> Run:
    """The config at ``cells`` for ``steps`` steps of 0.1 Myr (collective); ``fields``: the stress as mesh
    fields (``physics.elasticity.stress: fields``, the particles carrying only the materials)."""
    sets = [f"mesh.cells=[{cells[0]},{cells[1]}]", f"output.directory={out}", "output.progress=none",
            "output.fields_every=0", *(["physics.elasticity.stress=fields", "particles.properties=[]"] if fields else [])]
    document = load_config(CONFIG, sets)
    model = build_model(document, comm=comm)
    model.start()
    history = []
    cpu = 0.0
    for _ in range(steps):
        start = time.process_time()
        model.step(document["time"]["dt_max"])  # DT_MYR
        cpu += time.process_time() - start
        x, h = surface(model, comm)
        history.append(UPLIFT - h[0])
    x, h = surface(model, comm)
    mean = float(np.trapz(h, x) / (x[-1] - x[0]))
    model.destroy()
    return Run(cells, x, UPLIFT - h, tuple(history), mean, cpu / max(steps, 1))


def table(runs: list[Run]) -> str:
    """The markdown table: measured against Turcotte & Schubert per resolution, then the thin plate
    in the box and Timoshenko's estimate of the thickness error."""
    rows = []
    for r in runs:
        (w0, x0, xb), (e0, ex, eb) = r.measured, r.errors
        rows.append([f"{r.cells[0]} x {r.cells[1]}", f"{w0:.1f} ({e0 * 100:+.1f} %)", f"{x0 / 1e3:.2f} ({ex * 100:+.1f} %)",
                     f"{xb / 1e3:.2f} ({eb * 100:+.1f} %)", f"{r.settled:.1e}", f"{r.mean:.2f}"])
    rows.append(["thin plate (Turcotte & Schubert)", f"{W0:.1f}", f"{X0 / 1e3:.2f}", f"{XB / 1e3:.2f}", "", ""])
    x = np.linspace(0.0, LENGTH / 2.0, 16001)
    for label, shear in (("thin plate in the box, band load", False), ("the same with Timoshenko's shear", True)):
        w0, x0, xb = measures(x, box_thin_plate(x, shear=shear))
        rows.append([label, f"{w0:.1f}", f"{x0 / 1e3:.2f}", f"{xb / 1e3:.2f}", "", ""])
    header = ["cells", "w0 [m]", "first zero x0 [km]", "forebulge xb [km]", "last step's change of w0",
              "mean height [m]"]
    return "\n".join(markdown_table(header, rows)) + "\n"


def picture(runs: list[Run], path: Path) -> None:
    """The deflection profiles against the thin-plate solutions; ``w0`` against time."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (profile, relax) = plt.subplots(1, 2, figsize=(12, 4), gridspec_kw={"width_ratios": [2, 1]})
    x = np.linspace(0.0, LENGTH, 1601)
    profile.plot(x / 1e3, -thin_plate(x), "k-", lw=1.5, label="Turcotte & Schubert (line load)")
    profile.plot(x / 1e3, -box_thin_plate(x, shear=True), "k:", lw=1, label="thin plate in the box + Timoshenko shear")
    for r, style in zip(runs, ("o", ".")):
        profile.plot(r.x / 1e3, -r.w, style, ms=3, label=f"{r.cells[0]} x {r.cells[1]} cells")
    for at, label in ((X0, "x0"), (XB, "xb")):
        profile.axvline(at / 1e3, color="0.7", lw=0.8)
        profile.annotate(label, (at / 1e3, -W0 * 0.9), fontsize=8)
    profile.axhline(0.0, color="0.7", lw=0.8)
    profile.set(xlabel="x [km]", ylabel="-w [m] (the box's uplift removed)", xlim=(0.0, LENGTH / 1e3),
                title=f"5 km plate, alpha = {ALPHA / 1e3:.2f} km")
    profile.legend(fontsize=8)
    for r in runs:
        relax.plot(DT_MYR * np.arange(1, len(r.history) + 1), r.history, "o-", ms=3,
                   label=f"{r.cells[0]} x {r.cells[1]}")
    relax.axhline(W0, color="k", lw=1, label="thin plate")
    relax.set(xlabel="t [Myr]", ylabel="w0 [m]", title="deflection under the load")
    relax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)


def _publish(runs: list[Run], results: Path, *, steps: int, ranks: int) -> None:
    """The table and the picture into ``results``; the load; the JSON line."""
    heading = (f"{ranks} rank(s), {steps} steps of {DT_MYR} Myr; alpha = {ALPHA / 1e3:.3f} km, "
               f"h / alpha = {H / ALPHA:.3f}, box uplift {UPLIFT:.2f} m removed\n\n")
    BENCHMARK.publish(results / "flexure.md", heading + table(runs))
    picture(runs, results / "flexure.png")
    BENCHMARK.log_load("end")
    print(json.dumps({"cells": [list(r.cells) for r in runs], "measured": [r.measured for r in runs],
                      "errors": [r.errors for r in runs], "history": [r.history for r in runs]}))


def main(argv: list[str] | None = None) -> int:
    return resolutions_main(argv, BENCHMARK, run_case=run_case, resolutions=RESOLUTIONS, quick=QUICK, steps=STEPS,
                            steps_help="steps of 0.1 Myr", publish=_publish)


if __name__ == "__main__":
    raise SystemExit(main())
