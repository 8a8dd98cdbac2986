"""The elastic stress as advected mesh fields (``physics.elasticity.stress: fields``,
convection/model/elastic_stress.py): a stress in a rigid rotation only turns (its invariant decays
by chi per step, exactly; the particles' numbers), the config's checks, and whole runs of a
lid-driven Maxwell cavity with adaptivity and repartitioning: 1, 2 and 3 ranks agree to the
solver's tolerance, a run stopped at a checkpoint and resumed gives the uninterrupted one bit for
bit. The build-up under a constant strain rate: tests/benchmarks_viscoelastic/test_stress.py."""

import numpy as np
import pytest
import yaml

from _runs import assert_same_statistics, error_line, rows, run_cli, run_on_ranks, sets
from convection.app.factory import build_model
from convection.config.loader import load_config
from convection.physics.elasticity import stress_labels
from convection.schema import ConfigError
from particles.properties.elastic_stress import from_voigt, jaumann_rotation
from test_elastic_history import CAVITY as HISTORY_CAVITY

PRESTRESS = (0.3, -0.1, 0.2)  # xx, yy, xy
ROTATION = {"kind": "prescribed", "value": ["-(z-0.5)", "x-0.5"]}  # spin 1 about the centre


def rotation_document(out, stress: str) -> dict:
    """A box in rigid rotation (the velocity prescribed on every side), eta = 1e3, G = 1."""
    properties = [{"name": "elastic_stress", "initial": list(PRESTRESS)}] if stress == "particles" else []
    return {"mesh": {"cells": [3, 3]}, "physics": {"Ra": 0.0, "viscosity": {"law": 1.0e3},
                                                   "elasticity": {"enabled": True, "stress": stress}},
            "boundary": {"velocity": {side: ROTATION for side in ("left", "right", "bottom", "top")}},
            "initial": {"temperature": "0"}, "energy": {"enabled": False}, "stokes": {"solver": "direct"},
            "particles": {"enabled": True, "generator": {"name": "random_uniform", "particles_per_cell": 6, "seed": 1},
                          "properties": properties},
            "blowup": {"lost_fraction": 1.0}, "time": {"end": 1.0, "dt_max": 0.1, "cfl": 100.0},
            "output": {"directory": str(out), "progress": "none"}}


def _rotate(stress: str, out, steps: int) -> list[np.ndarray]:
    """The stress (Voigt) after each step: the fields' mean over their nodes, or the particles' mean."""
    model = build_model(load_config(None, document=rotation_document(out, stress)))
    if stress == "fields":
        for solver, value in zip(model.elastic_stress.solvers, PRESTRESS):
            for f in (solver.T, solver.T_old, solver.T_old2):
                f.x.array[:] = value
    model.start()
    out = []
    for _ in range(steps):
        model.step(0.1)
        if stress == "fields":
            fields = model.elastic_stress.fields
            values = np.array([fields[label].x.array for label in stress_labels(2)])
            assert np.ptp(values, axis=1).max() < 1e-12  # a uniform stress stays uniform
            out.append(values.mean(axis=1))
        else:
            out.append(model.particles.primary.properties.values("elastic_stress").mean(axis=0))
    model.destroy()
    return out


def test_a_stress_in_a_rigid_rotation_only_turns(tmp_path):
    """tau_n = chi^n R^n tau_0 R^nT, R the rotation by dt: the invariant decays by chi = eta / (eta + G dt)
    per step and nothing else; the fields give the particles' numbers."""
    steps, chi = 5, 1.0e3 / (1.0e3 + 0.1)
    fields = _rotate("fields", tmp_path / "fields", steps)
    particles = _rotate("particles", tmp_path / "particles", steps)
    spin = np.array([[[0.0, -1.0], [1.0, 0.0]]])
    tau = from_voigt(np.array([PRESTRESS]), 2)
    tau_ii = np.sqrt(0.5 * (PRESTRESS[0] ** 2 + PRESTRESS[1] ** 2) + PRESTRESS[2] ** 2)
    for n, (f, p) in enumerate(zip(fields, particles), start=1):
        tau = chi * jaumann_rotation(tau, spin, 0.1)
        expected = np.array([tau[0, 0, 0], tau[0, 1, 1], tau[0, 0, 1]])
        assert np.allclose(f, expected, rtol=0.0, atol=1e-12), (n, f, expected)
        assert np.allclose(p, expected, rtol=0.0, atol=1e-12), (n, p, expected)
        assert np.sqrt(0.5 * (f[0] ** 2 + f[1] ** 2) + f[2] ** 2) == pytest.approx(chi ** n * tau_ii, rel=1e-11)
    assert abs(fields[-1][2] - PRESTRESS[2]) > 0.05  # it turned


BOX = {"mesh": {"cells": [2, 2]}, "physics": {"Ra": 0.0, "elasticity": {"enabled": True, "stress": "fields"}},
       "initial": {"temperature": "0"}, "energy": {"enabled": False}, "time": {"end": 1.0},
       "output": {"directory": "unused"}}
PARTICLES = {"enabled": True, "generator": {"name": "random_uniform", "particles_per_cell": 4}}


def test_config_is_checked_when_read():
    config = load_config(None, document=BOX)  # no particles needed
    assert config["physics"]["elasticity"]["stress"] == "fields"
    assert config["physics"]["elasticity"]["stress_degree"] == 2
    assert load_config(None, document=BOX | {"particles": PARTICLES | {"properties": ["plastic_strain"]}})
    cases = [(BOX | {"particles": PARTICLES | {"properties": ["elastic_stress"]}},
              "particles.properties.*'elastic_stress' is the stress history of physics.elasticity.stress: particles"),
             (BOX | {"particles": PARTICLES | {"properties": ["elastic_share"]}},
              "particles.properties.*'elastic_share' needs the particles' stress"),
             (BOX | {"physics": {"Ra": 0.0, "elasticity": {"enabled": True, "stress": "nodes"}}},
              "physics.elasticity.stress"),
             (BOX | {"physics": {"Ra": 0.0, "elasticity": {"enabled": True, "stress": "fields", "stress_degree": 0}}},
              "physics.elasticity.stress_degree"),
             (BOX | {"physics": {"Ra": 0.0, "elasticity": {"enabled": True, "stress": "particles"}}},
              "or physics.elasticity.stress: fields")]
    for document, needle in cases:
        with pytest.raises(ConfigError, match=needle):
            load_config(None, document=document)
    fields_out = BOX | {"output": {"directory": "unused", "extra_fields": ["elastic_stress", "elastic_share"]}}
    assert load_config(None, document=fields_out)["output"]["extra_fields"] == ["elastic_stress", "elastic_share"]


def test_check_refuses_in_one_line(tmp_path):
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(BOX | {"particles": PARTICLES | {"properties": ["elastic_stress"]}}))
    error_line(run_cli(["check", str(path)]), 2, "particles.properties")


def cavity_document() -> dict:
    """test_elastic_history's Maxwell cavity with the stress as fields (no particles), adapted every 3 steps
    (a refined band that moves with the time), repartitioned every 2, the elastic outputs written."""
    document = yaml.safe_load(HISTORY_CAVITY)
    del document["particles"]
    document["name"] = "elastic_cavity_fields"
    document["physics"]["elasticity"]["stress"] = "fields"
    document["adaptivity"] = {"enabled": True, "every": 3, "max_level": 1, "fields": ["temperature"],
                              "min_level_where": "x < 0.2 + t"}
    document["balance"]["every"] = 2
    document["output"] |= {"fields_every": 8, "extra_fields": ["elastic_stress", "elastic_share"],
                           "statistics": ["time", "velocity", "mesh", "elasticity"]}
    return document


COMPARED = ("vrms", "elastic_stress_invariant_max", "elastic_stress_invariant_mean", "elastic_strain_rate_mean",
            "viscous_strain_rate_mean", "elastic_share")


@pytest.fixture(scope="module")
def cavity(tmp_path_factory):
    folder = tmp_path_factory.mktemp("cavity_fields")
    config = folder / "cavity.yaml"
    config.write_text(yaml.safe_dump(cavity_document()))
    out = run_on_ranks(config, {ranks: folder / f"ranks{ranks}" for ranks in (1, 2, 3)})
    out["stopped"] = folder / "stopped"
    proc = run_cli(["run", str(config), "--output", str(out["stopped"]), *sets(["time.max_steps=4"])], 2)
    assert proc.returncode == 0, proc.stderr
    proc = run_cli(["resume", str(out["stopped"]), *sets(["time.max_steps=8"])], 2)
    assert proc.returncode == 0, proc.stderr
    return out


def test_cavity_ranks_agree(cavity):
    """The stress shapes the flow (the elastic share grows), the mesh adapted; 2 and 3 ranks give the
    1-rank statistics to the solvers' tolerance."""
    tables = {ranks: rows(cavity[ranks]) for ranks in (1, 2, 3)}
    assert len(tables[1]) == 9 and float(tables[1][-1]["elastic_share"]) > 0.1
    assert float(tables[1][-1]["elastic_stress_invariant_max"]) > 0.05
    assert len({r["cells"] for r in tables[1]}) > 1
    for ranks in (2, 3):
        for a, b in zip(tables[1], tables[ranks]):
            assert a["cells"] == b["cells"], (ranks, a["step"])
            for key in COMPARED:
                assert float(b[key]) == pytest.approx(float(a[key]), rel=1e-8, abs=1e-14), (ranks, key, a["step"])


def test_resumed_cavity_is_bit_for_bit(cavity):
    assert_same_statistics(cavity[2], cavity["stopped"])


def test_cavity_writes_the_elastic_fields(cavity):
    """The field outputs read the forms' stress, the stress fields' here."""
    texts = [p.read_text() for p in cavity[1].glob("*.xdmf")]
    assert any("elastic_share" in text and "elastic_stress" in text for text in texts), sorted(cavity[1].iterdir())
