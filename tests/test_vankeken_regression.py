"""Regression of a short, coarse van Keken 1a run (particle composition, adaptive mesh).

Stored values (tests/data/vankeken_1a_quick.csv, per-row rtol) guard against unnoticed changes;
the physics checks below hold for any correct discretisation. The full-resolution comparison with
the published values is benchmarks/vanKeken/run.py.
"""

import csv
import sys
from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI

from convection.config import load_config
from convection.plot import read_statistics
from convection.simulation import Simulation

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks" / "vanKeken"))
from run import QUICK, measure  # noqa: E402


def _stored():
    with open(ROOT / "tests" / "data" / "vankeken_1a_quick.csv", newline="") as f:
        rows = csv.DictReader(line for line in f if not line.startswith("#"))
        return {r["quantity"]: (float(r["value"]), float(r["rtol"])) for r in rows}


@pytest.fixture(scope="module")
def quick_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("vk1a")
    config = load_config(ROOT / "configs" / "vankeken_1a.yaml", [
        *QUICK, "time.end=250", "output.progress=none", "output.fields_every=0", f"output.directory={out}",
    ])
    Simulation(config, comm=MPI.COMM_SELF).run()
    return read_statistics(out / "statistics.csv")


def test_values_match_stored(quick_run):
    m = measure(quick_run)
    values = dict(m._asdict())
    for t in (50, 100, 150, 200):
        for key in ("vrms", "entrainment"):
            values[f"{key}_t{t}"] = float(np.interp(t, quick_run["time"], quick_run[key]))
    for name, (stored, rtol) in _stored().items():
        assert values[name] == pytest.approx(stored, rel=rtol), name


def test_physics(quick_run):
    t, v = quick_run["time"], quick_run["vrms"]
    assert np.all(np.diff(v[t < 190]) > 0)  # the instability grows until the first peak
    e = quick_run["entrainment"]
    assert np.all(np.diff(e[t < 200]) > 0)  # light material rises monotonically early
    assert e[0] == pytest.approx(0.02 * 0.9142 / np.pi / (0.2 * 0.9142), rel=0.05)  # the initial bump
    assert np.all(quick_run["n_particles"] == quick_run["n_particles"][0])  # no particle created or destroyed
    assert np.all(quick_run["n_lost"] == 0)
    m = measure(quick_run)
    assert m.peak_time == pytest.approx(208.99, rel=0.05)  # published first peak, coarse tolerance
    assert m.peak_vrms == pytest.approx(3.0916e-3, rel=0.06)
