"""configs/subduction.yaml (docs/own-model.md), written in physical units, at CI size on 2 ranks: it
prints its nondimensional numbers, and its physical statistics give the slab tip's depth in km
against time in Myr (the deepest lithosphere cell starts 200 km below the surface, to within a
cell) while the slab sinks."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from _runs import CONFIGS, run_cli, sets

from benchmarks.schmeling import run as bench

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
    # The slab's end (200 km) lies on a cell row's edge at 25 km cells: the deepest cell the
    # lithosphere fills at least half is a triangle whose centroid is a third of a cell higher.
    assert tip[0] == pytest.approx(200.0 - 25.0 / 3.0, abs=1e-6)
    # Every cell is one material at the start (the edges lie on the mesh's lines): the linear fits
    # are the constants 0 and 1, and the volumes are the polygons' areas.
    assert float(rows[0]["volume_lithosphere [km^2]"]) == pytest.approx(2000 * 100 + 100 * 100, rel=1e-9)
    assert float(rows[0]["volume_air [km^2]"]) == pytest.approx(3000 * 50, rel=1e-9)
    assert all(float(r["vup_lithosphere [cm/yr]"]) < 0.0 for r in rows)  # the plate and slab sink on average
    assert float(rows[0]["topography_max [km]"]) == pytest.approx(0.0, abs=1e-6)  # the surface starts flat
    # the benchmark's table and picture from this run (benchmarks/schmeling/run.py --collect)
    text = bench.write(tmp_path / "bench", [out])
    ours = next(line for line in text.splitlines() if line.startswith("| this project 120x30 |"))
    assert ours.split("|")[2].strip() == "-"  # 4 steps do not reach 10 Myr
    assert (tmp_path / "bench" / "results.png").stat().st_size > 10_000


def test_published_curves():
    """reference.csv holds the paper's five geometric-mixing curves: each starts at the initial 200 km
    and they reach 400 km between 35 and 42 Myr (Schmeling et al. 2008, Fig. 5)."""
    curves = {name: c for name, c in bench.reference().items() if name.endswith("geom")}
    assert len(curves) == 5
    for name, curve in curves.items():
        assert bench.at(curve, 0.0) == pytest.approx(200.0, abs=3.0), name
    passing = [bench.passing(c, 400.0) for c in curves.values()]
    assert sorted(p for p in passing if p == p) == pytest.approx([35.5, 36.4, 37.5, 41.1], abs=0.1)
    t = np.array([0.0, 1.0, 2.0])
    assert bench.passing((t, t * 300.0 + 200.0), 350.0) == pytest.approx(0.5)


def test_topography_profile_with_the_fields(tmp_path):
    """The topography profile is written whenever the fields are (km against Myr), its extremes are
    the statistics' topography_max/min of those steps, and a resumed run continues the file."""
    out = tmp_path / "run"
    small = ["mesh.cells=[60,15]", "particles.generator.particles_per_cell=8", "time.max_steps=4",
             "output.progress=none", "output.fields_every=2"]
    proc = run_cli(["run", str(CONFIGS / "subduction.yaml"), "--output", str(out), *sets(small)], 1)
    assert proc.returncode == 0, proc.stderr
    proc = run_cli(["resume", str(out), "--set", "time.max_steps=6"], 1)
    assert proc.returncode == 0, proc.stderr
    with open(out / "statistics_physical.csv", newline="") as f:
        stats = {float(r["time [Myr]"]): r for r in csv.DictReader(f) if int(r["step"]) % 2 == 0}
    with open(out / "topography_profile.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert list(rows[0]) == ["time [Myr]", "x [km]", "topography [km]"]
    times = sorted({float(r["time [Myr]"]) for r in rows})
    assert times == pytest.approx(sorted(stats), rel=1e-12) and len(times) == 4  # steps 0, 2, 4, 6
    for t in times:
        profile = [r for r in rows if float(r["time [Myr]"]) == t]
        x = [float(r["x [km]"]) for r in profile]
        h = [float(r["topography [km]"]) for r in profile]
        assert len(profile) == 60 and x == sorted(x) and x[0] == pytest.approx(25.0) and x[-1] == pytest.approx(2975.0)
        row = stats[min(stats, key=lambda s: abs(s - t))]
        assert max(h) == pytest.approx(float(row["topography_max [km]"]), rel=1e-9, abs=1e-9)
        assert min(h) == pytest.approx(float(row["topography_min [km]"]), rel=1e-9, abs=1e-9)


def test_the_page_shows_the_shipped_config():
    """docs/own-model.md builds configs/subduction.yaml: its full listing is the shipped file."""
    import yaml

    page = (CONFIGS.parent / "docs" / "own-model.md").read_text()
    blocks = [b.split("```", 1)[0] for b in page.split("```yaml\n")[1:]]
    (listing,) = [b for b in blocks if b.startswith("name: subduction")]
    assert yaml.safe_load(listing) == yaml.safe_load((CONFIGS / "subduction.yaml").read_text())
