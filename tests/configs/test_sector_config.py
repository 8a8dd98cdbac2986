"""configs/sector.yaml at its shipped size: a quarter of the Davies et al. annulus (case 2.1) whose
steady state is the annulus's, within 0.2 % of ASPECT's values (about 15 s on one rank)."""

from __future__ import annotations

from pathlib import Path

import pytest

from _runs import CONFIGS, rows, run_cli, sets

ASPECT = {"vrms": 46.244, "nusselt": 4.700, "nusselt_bottom": 4.706, "T_mean": 0.382}
"""Davies et al. case 2.1 as run by ASPECT (configs/annulus_davies.yaml)."""


def test_sector_reaches_the_annulus_steady_state(tmp_path: Path):
    pytest.importorskip("gmsh")
    proc = run_cli(["run", str(CONFIGS / "sector.yaml"), "--output", str(tmp_path / "run"),
                    *sets(["output.progress=none", "output.fields_every=0", "output.checkpoint.at_end=false"])])
    assert proc.returncode == 0, proc.stderr
    last = rows(tmp_path / "run")[-1]
    assert float(last["time"]) < 3.0  # stopped by the steady-state test, not at time.end
    for column, reference in ASPECT.items():
        assert float(last[column]) == pytest.approx(reference, rel=2e-3), column
