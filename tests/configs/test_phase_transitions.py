"""The phase-transition benchmarks at CI size (benchmarks/phase_transitions has the full ones).

The latent heat: configs/phase_latent_heat.yaml on 50 cells in depth to 30 Myr (in this process, one
rank): mantle at 1600 K flowing down through an exothermic transition leaves it at
1600 K exp(Delta S / c_p); the temperature jump within 1 % of the closed form's.
"""

from pathlib import Path

import pytest
from mpi4py import MPI

from benchmarks.phase_transitions.run import T_LH, latent_heat_prediction
from convection.app.factory import run_config
from convection.config.loader import load_config
from convection.io.pictures import read_statistics

ROOT = Path(__file__).resolve().parents[2]
STORED_BELOW = 1679.5219
"""T_below [K] of the run below, 2026-12-07 (2 ranks; the closed form: 1679.487 K)."""


def test_latent_heat_temperature_jump(tmp_path):
    if MPI.COMM_WORLD.size > 1:
        pytest.skip("one rank: a run in this process")
    config = load_config(ROOT / "configs" / "phase_latent_heat.yaml", [
        "mesh.cells=[2,50]", "time.end=30 Myr", "time.cfl=4", "output.progress=none", "output.fields_every=0",
        f"output.directory={tmp_path}"])
    run_config(config, comm=MPI.COMM_SELF)
    statistics = read_statistics(tmp_path / "statistics_physical.csv")
    below, above = statistics["T_below [K]"][-1], statistics["T_above [K]"][-1]
    exact = latent_heat_prediction()["exact"]
    assert above == pytest.approx(T_LH, abs=1e-6)
    assert abs(below - exact) < 0.01 * (exact - T_LH)
    assert below == pytest.approx(STORED_BELOW, abs=1e-3)
    assert statistics["phase_p500_below"][-1] > 1.0 - 1e-9 and statistics["phase_p500_above"][-1] < 1e-9
