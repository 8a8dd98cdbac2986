"""The elastic outputs (convection/physics/elastic_outputs.py; issue 48, item 4) in the stress build-up
box of benchmarks/viscoelastic (eta = G = 1, pure shear eps = 0.01): as statistics, fields and
particle output, the stress invariant is backward Euler's ``2 eta eps (1 - (1 + G dt / eta)^-n)``
(within the benchmark's 0.5 % of the Maxwell curve at dt = t_M / 40), the elastic share
``(1 + G dt / eta)^-n`` (``exp(-G t / eta)``: eps_v = tau / (2 eta)), and the elastic and viscous
strain rates add up to the strain rate; in a model with units the columns and files are in MPa
and 1/s; every output is refused at check without elasticity."""

from __future__ import annotations

import csv
import json

import h5py
import numpy as np
import pytest
import yaml

from benchmarks.viscoelastic.stress import EPS, ETA, G, document
from convection.config.loader import load_config
from convection.io.pictures import import_pyvista
from convection.schema import ConfigError

OUTPUTS = ["elastic_stress_invariant", "elastic_strain_rate", "viscous_strain_rate", "elastic_share"]
DT = 0.025


def _box(out, *, dt: float = DT, end: float = 1.0) -> dict:
    doc = document(cells=2, dt=dt, end=end, out=out)
    doc["particles"]["properties"] = ["elastic_stress", *OUTPUTS]
    doc["particles"]["output"] = {"every_steps": 1}
    return doc


def _build_up(n: np.ndarray, dt: float) -> np.ndarray:
    """Backward Euler's stress after ``n`` steps (docs/rheology.md, "Elasticity")."""
    return 2 * ETA * EPS * (1 - (1 + G * dt / ETA) ** -n)


def test_statistics_fields_and_particles_follow_the_build_up(world, tmp_path):
    from convection.app.factory import build_model
    from convection.postprocess.postprocessors import create_postprocessors

    out = tmp_path if world.rank == 0 else None
    out = world.bcast(out)
    steps = 40 if world.size == 1 else 8  # collective runs are slow on a shared machine
    model = build_model(load_config(None, document=_box(out)), comm=world)
    model.start()
    [stats] = create_postprocessors(model, ["elasticity"])
    first = stats(model)
    assert first["elastic_share"] == 0.0 and first["elastic_strain_rate_mean"] == 0.0  # before any step: viscous
    for n in range(1, steps + 1):
        model.step(DT)
        row = stats(model)
        sigma = _build_up(np.array(n), DT)
        for key in ("elastic_stress_invariant_max", "elastic_stress_invariant_mean"):
            assert row[key] == pytest.approx(sigma, rel=1e-9), (n, key)
            assert abs(row[key] - 2 * ETA * EPS * (1 - np.exp(-G * n * DT / ETA))) < 5e-3 * 2 * ETA * EPS
        assert row["elastic_share"] == pytest.approx((1 + G * DT / ETA) ** -n, rel=1e-9)
        assert row["elastic_strain_rate_mean"] + row["viscous_strain_rate_mean"] == pytest.approx(EPS, rel=1e-12)
    sigma = _build_up(np.array(steps), DT)
    fields = model.fields()
    owned = model.mesh.topology.index_map(2).size_local
    tau = fields["elastic_stress"].x.array.reshape(-1, 2, 2)[:owned]
    assert np.allclose(tau, np.array([[sigma, 0.0], [0.0, -sigma]]), rtol=0.0, atol=1e-12)
    assert np.allclose(fields["elastic_stress_invariant"].x.array, sigma, rtol=1e-10, atol=0.0)
    total = fields["elastic_strain_rate"].x.array + fields["viscous_strain_rate"].x.array
    assert np.allclose(total.reshape(-1, 2, 2), np.diag([EPS, -EPS]), rtol=0.0, atol=1e-14)
    model.destroy()
    world.barrier()
    with h5py.File(out / f"particles_{steps:06d}.h5", "r") as f:
        particles = {name: f[f"properties/{name}"][...] for name in ["elastic_stress", *OUTPUTS]}
    assert np.allclose(particles["elastic_stress"], [sigma, -sigma, 0.0], rtol=0.0, atol=1e-12)
    assert np.allclose(particles["elastic_stress_invariant"], sigma, rtol=1e-10, atol=0.0)
    total = particles["elastic_strain_rate"] + particles["viscous_strain_rate"]
    assert np.allclose(total, [EPS, -EPS, 0.0], rtol=0.0, atol=1e-14)
    assert np.allclose(particles["elastic_share"], (1 + G * DT / ETA) ** -steps, rtol=1e-9, atol=0.0)


SCALING = {"length": "100 km", "viscosity": "1e21 Pa s", "density": "3300 kg/m^3", "gravity": "10 m/s^2"}
"""Stresses in units of eta0 kappa / L^2 = 1e5 Pa = 0.1 MPa, strain rates in kappa / L^2 = 1e-16 1/s."""


def _table(path) -> list[dict[str, float]]:
    with open(path, newline="") as f:
        return [{k: float(v) for k, v in row.items()} for row in csv.DictReader(f)]


def test_statistics_and_files_have_the_model_units(tmp_path):
    from _runs import run_cli

    doc = _box(str(tmp_path / "run"), dt=0.1, end=0.3) | {"scaling": SCALING}
    doc["physics"]["elasticity"]["shear_modulus"] = "0.1 MPa"  # G = 1 in the model's units
    doc["output"]["fields_every"] = 3
    path = tmp_path / "box.yaml"
    path.write_text(yaml.safe_dump(doc))
    proc = run_cli(["run", str(path)])
    assert proc.returncode == 0, proc.stderr
    plain, physical = _table(tmp_path / "run" / "statistics.csv"), _table(tmp_path / "run" / "statistics_physical.csv")
    assert len(plain) == len(physical) == 4
    for a, b in zip(plain, physical):
        for key, factor in (("elastic_stress_invariant_max [MPa]", 0.1), ("elastic_stress_invariant_mean [MPa]", 0.1),
                            ("elastic_strain_rate_mean [1/s]", 1e-16), ("viscous_strain_rate_mean [1/s]", 1e-16),
                            ("elastic_share", 1.0)):
            assert b[key] == pytest.approx(factor * a[key.split(" ")[0]], rel=1e-12), key
    assert plain[-1]["elastic_stress_invariant_max"] == pytest.approx(float(_build_up(np.array(3), 0.1)), rel=1e-9)
    fields = json.loads((tmp_path / "run" / "fields_units.json").read_text())["fields"]
    particles = json.loads((tmp_path / "run" / "particles_units.json").read_text())["fields"]
    for units in (fields, particles):
        assert (units["elastic_stress"], units["elastic_stress_invariant"]) == ("MPa", "MPa")
        rates = (units["elastic_strain_rate"], units["viscous_strain_rate"], units["elastic_share"])
        assert rates == ("1/s", "1/s", "1")
    with h5py.File(tmp_path / "run" / "particles_000003.h5", "r") as f:
        invariant = f["properties/elastic_stress_invariant"][...]
    assert np.allclose(invariant, 0.1 * plain[-1]["elastic_stress_invariant_max"], rtol=1e-9, atol=0.0)
    pv = import_pyvista()  # not `import pyvista` after DOLFINx: see import_pyvista
    reader = pv.get_reader(str(tmp_path / "run" / "fields.xdmf"))  # VTK's XdmfReader, as ParaView reads it
    reader.set_active_time_value(reader.time_values[-1])
    cells = reader.read().cell_data
    sigma = 0.1 * plain[-1]["elastic_stress_invariant_max"]
    assert np.allclose(cells["elastic_stress"][:, [0, 4, 1]], [sigma, -sigma, 0.0], rtol=1e-9, atol=1e-12 * sigma)
    assert np.allclose(cells["elastic_stress_invariant"], sigma, rtol=1e-9, atol=0.0)
    assert np.allclose(cells["elastic_strain_rate"] + cells["viscous_strain_rate"],
                       [1e-18, 0, 0, 0, -1e-18, 0, 0, 0, 0], rtol=0.0, atol=1e-30)


def test_every_output_is_refused_without_elasticity(tmp_path):
    from _runs import error_line, run_cli

    def viscous(**changes):
        doc = _box("unused")
        doc["physics"].pop("elasticity")
        doc["particles"]["properties"] = ["initial_position"]
        for key, value in changes.items():
            section, name = key.split("__")
            doc[section][name] = value
        return doc

    cases = [(viscous(output__statistics=["time", "elasticity"]), "'output.statistics': 'elasticity' needs elasticity"),
             (viscous(output__extra_fields=["elastic_stress"]), "'output.extra_fields': 'elastic_stress'"),
             *((viscous(particles__properties=["initial_position", name]), f"'particles.properties': {name!r}")
               for name in OUTPUTS)]
    for doc, needle in cases:
        with pytest.raises(ConfigError, match=needle):
            load_config(None, document=doc)
    load_config(None, document=viscous())
    path = tmp_path / "viscous.yaml"
    path.write_text(yaml.safe_dump(viscous(output__extra_fields=["elastic_share"])))
    line = error_line(run_cli(["check", str(path)]), 2, "output.extra_fields")
    assert "physics.elasticity.enabled: true" in line
