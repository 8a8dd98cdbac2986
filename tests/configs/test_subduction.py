"""configs/subduction.yaml (docs/own-model.md), written in physical units, at CI size on 2 ranks: it
prints its nondimensional numbers, and its physical statistics give the slab tip's depth in km
against time in Myr (the deepest lithosphere cell starts 200 km below the surface, to within a
cell) while the slab sinks."""

from __future__ import annotations

import csv

import pytest

from _runs import CONFIGS, run_cli, sets

SMALL = ["mesh.cells=[120,30]", "particles.generator.particles_per_cell=8", "time.max_steps=4",
         "output.progress=lines", "output.progress_every=1", "output.fields_every=0"]


def test_subduction_in_units(tmp_path):
    out = tmp_path / "run"
    proc = run_cli(["run", str(CONFIGS / "subduction.yaml"), "--output", str(out), *sets(SMALL)], 2)
    assert proc.returncode == 0, proc.stderr
    L, kappa = 750e3, 1e-6
    rb_air = -3200 * 9.81 * L**3 / (1e21 * kappa)
    rb_lithosphere = 100 * 9.81 * L**3 / (1e21 * kappa)
    assert f"Rb_air = {rb_air:.6g}, Rb_lithosphere = {rb_lithosphere:.6g}" in proc.stdout
    with open(out / "statistics_physical.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    times = [float(r["time [Myr]"]) for r in rows]
    assert times == sorted(times) and times[-1] > 0.0
    tip = [float(r["depth_lithosphere [km]"]) - 50.0 for r in rows]
    assert tip[0] == pytest.approx(200.0, abs=25.0)  # 25 km cells
    assert all(float(r["vup_lithosphere [cm/yr]"]) < 0.0 for r in rows)  # the plate and slab sink on average
    assert float(rows[0]["topography_max [km]"]) == pytest.approx(0.0, abs=1e-6)  # the surface starts flat
