"""configs/sinking_block.yaml, a model written in physical units, at CI size: the scaling's numbers
are printed, statistics_physical.csv holds the nondimensional statistics in Myr and cm/yr (checked
against the scales computed by hand), 1 and 2 ranks agree, and a resumed run continues both files."""

from __future__ import annotations

import csv

import pytest

from _runs import CONFIGS, rows, run_cli, sets

CONFIG = CONFIGS / "sinking_block.yaml"
SMALL = ["mesh.cells=[16,16]", "time.end=200 Myr", "particles.generator.particles_per_cell=8", "time.max_steps=6",
         "output.progress=lines", "output.progress_every=1", "output.fields_every=0"]
YEAR = 365.25 * 86400.0
L, KAPPA = 512e3, 1e-6


def _physical(run_dir):
    with open(run_dir / "statistics_physical.csv", newline="") as f:
        return list(csv.DictReader(f))


@pytest.mark.parametrize("ranks", [1, 2])
def test_sinking_block_in_units(tmp_path, ranks):
    out = tmp_path / "run"
    proc = run_cli(["run", str(CONFIG), "--output", str(out), *sets(SMALL)], ranks)
    assert proc.returncode == 0, proc.stderr
    rb = 8 * 10.0 * L**3 / (1e21 * KAPPA)
    assert f"Ra = 0, Rb_block = {rb:.6g}" in proc.stdout
    assert "time unit L^2/kappa = 8306.84 Myr" in proc.stdout
    assert " Myr  dt=" in proc.stdout and " cm/yr  ETA" in proc.stdout
    plain, physical = rows(out), _physical(out)
    assert list(physical[0])[:4] == ["step", "time [Myr]", "dt [Myr]", "vrms [cm/yr]"]
    assert "T_mean" not in plain[0]  # no energy equation: no temperature columns
    for a, b in zip(plain, physical, strict=True):
        assert a["step"] == b["step"] and a["cells"] == b["cells"]
        assert float(b["time [Myr]"]) == pytest.approx(float(a["time"]) * L**2 / KAPPA / (1e6 * YEAR), rel=1e-12)
        assert float(b["vrms [cm/yr]"]) == pytest.approx(float(a["vrms"]) * KAPPA / L * 100 * YEAR, rel=1e-12)
    assert 0.01 < float(physical[-1]["vrms [cm/yr]"]) < 1.0  # the block sinks at a fraction of a cm/yr
    first, last = physical[0], physical[-1]
    assert float(last["vup_block [cm/yr]"]) < 0.0  # it sinks ...
    # its base: 192 km (32 km cells)
    assert float(last["depth_block [km]"]) > float(first["depth_block [km]"]) > 192.0 - 32.0
    assert float(first["volume_block [km^2]"]) == pytest.approx(128.0**2, rel=0.05)
    assert float(first["x_block [km]"]) == pytest.approx(256.0, rel=0.01)
    assert float(first["vy_centre [cm/yr]"]) == pytest.approx(float(first["vup_block [cm/yr]"]), rel=0.2)
    assert int(plain[-1]["n_lost"]) == 0


def test_one_and_two_ranks_agree_and_resume_continues(tmp_path):
    one, two = tmp_path / "one", tmp_path / "two"
    for out, ranks in ((one, 1), (two, 2)):
        proc = run_cli(["run", str(CONFIG), "--output", str(out), *sets(SMALL)], ranks)
        assert proc.returncode == 0, proc.stderr
    for a, b in zip(_physical(one), _physical(two), strict=True):
        assert float(a["vrms [cm/yr]"]) == pytest.approx(float(b["vrms [cm/yr]"]), rel=1e-8)
        assert float(a["time [Myr]"]) == pytest.approx(float(b["time [Myr]"]), rel=1e-8)
    proc = run_cli(["resume", str(two), "--set", "time.max_steps=9"], 2)
    assert proc.returncode == 0, proc.stderr
    assert [r["step"] for r in _physical(two)] == [str(i) for i in range(10)]
    assert [r["step"] for r in rows(two)] == [str(i) for i in range(10)]


def test_benchmark_at_ci_size():
    """benchmarks/sinking_block/run.py's measurement at 32 x 32 cells: the scaled velocity
    |v| eta1 / delta_rho is the same for every delta_rho (a linear problem), grows as the block
    weakens, and no longer depends on eta2 for a stiff block (< 1 % from eta2/eta1 = 1e3 to 1e6)."""
    from benchmarks.sinking_block import run as bench

    scaled = {(ratio, rho): bench.scaled(bench.block_velocity(32, rho, ratio), rho)
              for ratio in (1e-2, 1.0, 1e3, 1e6) for rho in (8.0, 128.0)}
    for ratio in (1e-2, 1.0, 1e3, 1e6):
        assert scaled[ratio, 8.0] == pytest.approx(scaled[ratio, 128.0], rel=1e-9)
    assert scaled[1e-2, 8.0] > scaled[1.0, 8.0] > scaled[1e3, 8.0]
    assert abs(scaled[1e3, 8.0] - scaled[1e6, 8.0]) < 0.01 * scaled[1e6, 8.0]
    # an isoviscous block (eta* = 1) at 32^2 against the table's 128^2 value, to the discretisation error
    assert scaled[1.0, 8.0] == pytest.approx(1.24e10, rel=0.02)


def test_summary_picture_fits_the_model(tmp_path):
    """No energy equation: the summary shows the block, not a constant temperature, and plots vrms in
    cm/yr against Myr, without a Nusselt panel."""
    from convection.io.pictures import plot_run, read_statistics
    from convection.io.pictures.summary import curve_panels, summary_field

    out = tmp_path / "run"
    proc = run_cli(["run", str(CONFIG), "--output", str(out), *sets([*SMALL, "output.fields_every=2"])], 1)
    assert proc.returncode == 0, proc.stderr
    name, _ = summary_field(out)
    assert name == "block"
    time, time_label, panels = curve_panels(out, read_statistics(out / "statistics.csv"), None)
    assert time_label == "time [Myr]"
    assert [label for _, label in panels] == ["vrms [cm/yr]", "cells"]
    assert plot_run(out).stat().st_size > 10_000


def test_fields_in_units(tmp_path):
    """The field output of a model in physical units: km, Myr, cm/yr, Pa s and the density in kg/m^3
    (the mantle's 3200, the block's 3208 in the cells the block fills), named in fields_units.json."""
    import json

    import h5py

    out = tmp_path / "run"
    small = [s for s in SMALL if not s.startswith("output.fields_every")]
    proc = run_cli(["run", str(CONFIG), "--output", str(out), *sets([*small, "output.fields_every=3"])], 1)
    assert proc.returncode == 0, proc.stderr
    units = json.loads((out / "fields_units.json").read_text())
    assert units["time"] == "Myr" and units["length"] == "km"
    assert {k: units["fields"][k] for k in ("velocity", "pressure", "viscosity", "density", "block")} == {
        "velocity": "cm/yr", "pressure": "MPa", "viscosity": "Pa*s", "density": "kg/m^3", "block": "1"}
    times = {r["step"]: float(r["time [Myr]"]) for r in _physical(out)}
    first = _physical(out)[0]  # the points statistic in the same units: the block's centre is 3208 kg/m^3
    assert float(first["density_centre [kg/m^3]"]) == pytest.approx(3208.0, rel=1e-12)
    assert float(first["viscosity_centre [Pa*s]"]) == pytest.approx(1e23, rel=1e-9)
    assert "stress_II_centre [MPa]" in first and "strain_rate_II_centre [1/s]" in first
    with h5py.File(out / "fields_000.h5", "r") as h5:
        x = h5["Mesh/mesh/geometry"][...]
        assert x.min() == pytest.approx(0.0, abs=1e-9) and x.max() == pytest.approx(512.0, rel=1e-12)
        keys = sorted(h5["Function/density"], key=lambda k: float(k.replace("_", ".")))
        assert [float(k.replace("_", ".")) for k in keys] == pytest.approx([times["0"], times["3"], times["6"]],
                                                                           rel=1e-12, abs=1e-12)
        density = h5[f"Function/density/{keys[0]}"][...]
        block = h5[f"Function/block/{keys[0]}"][...]
        viscosity = h5[f"Function/viscosity/{keys[0]}"][...]
    assert density == pytest.approx(3200.0 + 8.0 * block, rel=1e-12)
    assert density.min() == pytest.approx(3200.0, rel=1e-12) and density.max() == pytest.approx(3208.0, rel=1e-12)
    assert viscosity.min() == pytest.approx(1e21, rel=1e-9) and viscosity.max() > 1e21
