"""Regression of a short, coarse thick-layer entrainment run (2D, particle composition, uniform mesh).

configs/thick_layer_2d.yaml on 20 x 20 cells with 5 particles per cell and the benchmark's step cap
(benchmarks/tackley_king/run.py ``overrides``), to t = 0.002. At that time no dense material has
reached the benchmark height z = 0.5 yet, so the quick run measures the dense volume above its
initial top, z = 0.4 (``diagnostics.entrainment_height=0.4``), which rises from the first step.
Stored values (tests/data/thick_layer_2d_quick.csv, per-row rtol) guard against unnoticed changes;
the physics checks hold for any correct discretisation. The slow test runs the benchmark quantity
(height 0.5) to t = 0.02 on the same mesh.
"""

import csv
from pathlib import Path

import dolfinx.fem
import numpy as np
import pytest
import ufl
from mpi4py import MPI

from convection.config.loader import load_config
from convection.io.pictures import read_statistics
from convection.app.factory import build_model, run_config
from convection.model.model import Model
from benchmarks.tackley_king import run as tk

ROOT = Path(__file__).resolve().parents[2]

QUICK_TIMES = (0.0005, 0.001, 0.0015, 0.002)


def _stored():
    with open(ROOT / "tests" / "data" / "thick_layer_2d_quick.csv", newline="") as f:
        rows = csv.DictReader(line for line in f if not line.startswith("#"))
        return {r["quantity"]: (float(r["value"]), float(r["rtol"])) for r in rows}


def _dense_volume(model: Model) -> float:
    (composition,) = model.fractions
    return float(dolfinx.fem.assemble_scalar(dolfinx.fem.form(composition * ufl.dx)))


def _run(out, end, extra=()):
    config = load_config(ROOT / "configs" / "thick_layer_2d.yaml", [
        *tk.overrides("2d", tk.Member(20, 5), end), *extra,
        "output.progress=none", "output.fields_every=0", f"output.directory={out}",
    ])
    sim = build_model(config, comm=MPI.COMM_SELF)
    dense_particles = float(sim.particles.swarm.property("composition").sum())
    volume = _dense_volume(sim)
    run_config(config, comm=MPI.COMM_SELF, model=sim)
    return sim, read_statistics(out / "statistics.csv"), dense_particles, volume


@pytest.fixture(scope="module")
def quick_run(tmp_path_factory):
    return _run(tmp_path_factory.mktemp("thick2d"), QUICK_TIMES[-1], ["diagnostics.entrainment_height=0.4"])


def test_values_match_stored(quick_run):
    _, stats, _, _ = quick_run
    values = {"vrms_initial": stats["vrms"][0]}
    for t in QUICK_TIMES:
        for key in ("vrms", "entrainment"):
            values[f"{key}_t{t:g}"] = float(np.interp(t, stats["time"], stats[key]))
    stored = {k: v for k, v in _stored().items() if not k.startswith("slow_")}
    assert set(stored) == set(values)
    for name, (value, rtol) in stored.items():
        assert values[name] == pytest.approx(value, rel=rtol), name


def test_dense_material_conserved(quick_run):
    sim, stats, dense_particles, volume = quick_run
    assert np.all(stats["n_particles"] == stats["n_particles"][0])  # no particle created or destroyed
    assert np.all(stats["n_lost"] == 0)
    # Every particle keeps its composition: the number of dense particles is exactly constant.
    assert float(sim.particles.swarm.property("composition").sum()) == dense_particles
    # z = 0.4 lies on cell edges of the 20 x 20 mesh: the initial cell averages give exactly 0.4.
    assert volume == pytest.approx(0.4, rel=1e-12)
    # The volume of C changes only through the sampling of mixed cells (0 < C < 1): a cell's
    # average of n particles carries a binomial error of standard deviation sqrt(C (1 - C) / n), so
    # the total has sigma = sqrt(sum |K|^2 C (1 - C) / n). Allow 4 sigma (measured: ~0.3%, ~1 sigma).
    C = sim.fractions[0].x.array
    area = 1.0 / (2 * 20 * 20)
    n = stats["n_particles"][0] / (2 * 20 * 20)
    sigma = np.sqrt(np.sum(area**2 * C * (1.0 - C) / n))
    assert sigma > 0.0
    assert abs(_dense_volume(sim) - volume) <= 4.0 * sigma


def test_physics(quick_run):
    _, stats, _, _ = quick_run
    t, e, v = stats["time"], stats["entrainment"], stats["vrms"]
    assert e[0] == 0.0  # nothing above the initial interface at t = 0
    assert np.all(e >= 0.0)
    early = t <= 4e-5
    assert early.sum() >= 8
    assert np.all(np.diff(e[early]) > 0)  # the initial flow lifts dense material above z = 0.4
    assert np.all(np.diff(v[early]) < 0)  # and decays as the interface deflection resists it
    assert np.all(stats["T_min"] >= -0.05) and np.all(stats["T_max"] <= 1.05)


@pytest.mark.slow
def test_benchmark_entrainment_coarse(tmp_path):
    """The benchmark quantity (dense volume above z = 0.5) to t = 0.02 on 20 x 20, 5 per cell."""
    sim, stats, dense_particles, volume = _run(tmp_path, 0.02)
    t, e = stats["time"], stats["entrainment"]
    assert t[-1] == pytest.approx(0.02)
    assert np.all(e >= 0.0)
    assert e[0] == 0.0
    assert np.all(e[t < 0.0015] == 0.0)  # dense material needs time to rise 0.1 (first > 0 at t = 0.00216)
    assert 0.0 < e[-1] < 0.05  # small but positive entrainment at t = 0.02 (seed, 3D, later: 0.019-0.03)
    assert np.all(stats["n_lost"] == 0)
    assert float(sim.particles.swarm.property("composition").sum()) == dense_particles
    name, (value, rtol) = "slow_entrainment_t0.02", _stored()["slow_entrainment_t0.02"]
    assert e[-1] == pytest.approx(value, rel=rtol), name
