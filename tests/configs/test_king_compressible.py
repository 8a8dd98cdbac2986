"""King et al. (2010) at CI size: configs/king_tala.yaml on 12 x 12 cells to a loose steady state.

The full comparison (32 x 32, Di = 0.25, 0.5, 1) is benchmarks/compressible/run.py. Here: TALA at
Di = 1 against the published codes' mean (1 %) and a stored value; the energy balance Phi = W that
EBA keeps at every step (the momentum equation tested with the velocity: no pressure work, as
div u = 0) and TALA breaks by its pressure work (King et al.'s codes: 4 %); and Phi - W = P, the
compression's work, to round-off at every step under EBA, TALA and ALA.
"""

from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI

from benchmarks.compressible.run import QUICK, final, published, reference
from convection.app.factory import run_config
from convection.config.loader import load_config
from convection.io.pictures import read_statistics

ROOT = Path(__file__).resolve().parents[2]
STORED_NUSSELT = 2.566175949
"""Nu of the TALA Di = 1 run below (12 x 12 cells, steady-state tolerance 1e-4), 2026-12-06."""


def _run(tmp_path_factory, name: str, overrides: list[str]) -> dict:
    out = tmp_path_factory.mktemp(name)
    config = load_config(ROOT / "configs" / "king_tala.yaml", [
        *QUICK, *overrides, "output.progress=none", "output.fields_every=0", f"output.directory={out}"])
    run_config(config, comm=MPI.COMM_SELF)
    return read_statistics(out / "statistics.csv")


@pytest.fixture(scope="module")
def tala(tmp_path_factory):
    return _run(tmp_path_factory, "tala", ["physics.reference.Di=1.0"])


def test_tala_matches_the_published_codes(tala):
    ours = final(tala)
    ref = reference()[("tala", 1e4, 1.0)]
    for quantity in ("nusselt", "vrms", "T_mean", "W", "Phi"):
        assert ours[quantity] == pytest.approx(published(ref, quantity)[2], rel=0.01), quantity
    assert ours["nusselt"] == pytest.approx(STORED_NUSSELT, rel=1e-6)


def test_tala_has_pressure_work(tala):
    """|Phi - W| / W at steady state: 4.4 % for King et al.'s UM code, 4.1 % for ASPECT."""
    assert 0.03 < tala["heating_misfit"][-1] < 0.06


def test_tala_energy_closes_with_its_pressure_work(tala):
    """Phi - W is the compression's work P at every step (the momentum equation tested with the
    velocity): |Phi - W - P| / W at round-off, although P is 4 % of W at steady state."""
    assert np.max(tala["heating_balance"][1:]) < 1e-10
    assert tala["heating_pressure_work"][-1] == pytest.approx(tala["heating_Phi"][-1] - tala["heating_W"][-1],
                                                               rel=1e-8)


def test_ala_energy_closes_with_its_pressure_work(tmp_path_factory):
    """ALA: the pressure's buoyancy takes part of the compression's work back; the balance with what
    is left closes to round-off at every step."""
    statistics = _run(tmp_path_factory, "ala", ["physics.approximation=ala", "physics.reference.Di=1.0",
                                                "time.max_steps=20"])
    assert np.all(statistics["heating_W"][1:] > 0.0)
    assert np.max(statistics["heating_balance"][1:]) < 1e-10
    assert np.max(np.abs(statistics["heating_pressure_work"][1:])) > 1e-4  # not a balance of nothing


def test_eba_balances_dissipation_and_work(tmp_path_factory):
    statistics = _run(tmp_path_factory, "eba", ["physics.approximation=eba", "physics.reference.Di=0.5",
                                                "time.max_steps=60"])
    assert len(statistics["step"]) == 61
    assert np.all(statistics["heating_W"][1:] > 0.0)
    assert np.max(statistics["heating_misfit"]) < 1e-3
    assert np.max(np.abs(statistics["heating_pressure_work"])) < 1e-3 * np.max(statistics["heating_W"])
    assert np.max(statistics["heating_balance"][1:]) < 1e-10
