"""configs/crameri_case1.yaml (sticky air, physical units) at CI size through benchmarks/crameri/run.py:
the surface's cosine amplitude starts at the 7 km it is given and relaxes at about Crameri et al.'s
rate (the full-size runs and their errors: benchmarks/crameri/README.md)."""

from __future__ import annotations

import numpy as np
import pytest



@pytest.fixture
def bench():
    """The benchmark's module; the postprocessor it registers is removed afterwards, so that the
    registry (and the config reference made from it) is the package's again."""
    from convection.postprocess import POSTPROCESSORS

    from benchmarks.crameri import run

    yield run
    POSTPROCESSORS.pop("cosine_topography", None)


def test_relaxation_at_ci_size(tmp_path, bench):
    result = bench.run((112, 32), 1e18, 0.5, 10.0, tmp_path / "run")
    assert result["A"][0] == pytest.approx(bench.AMPLITUDE, rel=0.1)
    assert np.all(np.diff(result["A"]) < 0.0)  # it relaxes, step after step
    rate = bench.fitted_rate(result["t"], result["A"], 10.0)
    assert rate == pytest.approx(bench.RATE, rel=0.1)  # 25 km cells: +2.9 % measured
