"""Plate-like prescribed surface velocities (convection/geometry/plates.py) and their config section."""

from pathlib import Path

import numpy as np
import pytest

from convection.config.loader import ConfigError, load_config
from convection.config.loader import config_domain as domain_from_config
from convection.config.settings import run_settings
from convection.geometry.plates import Plate, PlateVelocity, unit_vector

PLATES = (Plate((0.0, 0.0), 2.0, (90.0, 30.0)), Plate((180.0, 0.0), -1.0, (0.0, 90.0)),
          Plate((0.0, 90.0), 0.5, (45.0, 0.0)))


def _sphere_points(n, radius, seed=0):
    x = np.random.default_rng(seed).normal(size=(3, n))
    return radius * x / np.linalg.norm(x, axis=0)


def test_plate_velocity_is_tangent_and_rigid_inside_each_plate():
    field = PlateVelocity(PLATES, width=0.05)
    x = _sphere_points(500, 2.2)
    u = field(x)
    assert u.shape == (3, 500)
    assert np.allclose(np.sum(u * x, axis=0), 0.0, atol=1e-12)
    w = field.weights(x)
    assert np.allclose(w.sum(axis=0), 1.0)
    for k, plate in enumerate(PLATES):  # at a plate's centre the velocity is its rigid rotation
        c = 2.2 * plate.centre_vector[:, None]
        rigid = plate.rate * np.cross(plate.pole_vector, c[:, 0])
        assert np.allclose(field(c)[:, 0], rigid, atol=1e-9 * 2.2 * abs(plate.rate))
        assert field.weights(c)[k, 0] == pytest.approx(1.0, abs=1e-9)


def test_plate_boundary_is_smooth_over_the_width():
    """Halfway between two plate centres both weigh 1/2; 0.02 rad towards one centre the angles
    differ by 0.04 = width / 5, so the weights are 1 / (1 + e^(-+0.2))."""
    field = PlateVelocity(PLATES[:2], width=0.2)
    mid = unit_vector(90.0, 0.0)[:, None]
    assert np.allclose(field.weights(mid)[:, 0], [0.5, 0.5])
    near = unit_vector(90.0 - np.degrees(0.02), 0.0)[:, None]
    expected = 1.0 / (1.0 + np.exp(-0.2))
    assert field.weights(near)[0, 0] == pytest.approx(expected, rel=1e-9)


def test_plates_in_2d_are_arcs_rotating_about_z():
    field = PlateVelocity((Plate((0.0,), 1.0), Plate((180.0,), -3.0)), width=0.05, gdim=2)
    x = np.array([[1.5, -1.5], [0.0, 0.0], [0.0, 0.0]])
    assert np.allclose(field(x), [[0.0, 0.0], [1.5, 4.5]])


def _shell_config(outer, tmp_path):
    document = {"mesh": {"geometry": "spherical_shell", "radii": [1.22, 2.22], "resolution": 0.5},
                "physics": {"Ra": 1e4}, "time": {"end": 0.1}, "output": {"directory": str(tmp_path)},
                "boundary": {"velocity": {"inner": "free_slip", "outer": outer}}}
    return load_config(None, document=document)


def test_plates_config_section_builds_a_prescribed_callable(tmp_path):
    outer = {"kind": "plates", "width": 0.1, "plates": [{"centre": [0, 0], "pole": [90, 30], "rate": 2.0},
                                                      {"centre": [180, 0], "rate": -1}]}
    config = _shell_config(outer, tmp_path)
    bcs = run_settings(config).boundary.velocity_bcs(domain_from_config(config))
    assert bcs["inner"].kind == "free_slip" and bcs["outer"].kind == "prescribed"
    field = bcs["outer"].value
    assert isinstance(field, PlateVelocity) and field.gdim == 3 and field.width == 0.1
    assert field.plates == (Plate((0.0, 0.0), 2.0, (90.0, 30.0)), Plate((180.0, 0.0), -1.0, (0.0, 90.0)))
    for bad, needle in (({"kind": "plates"}, "needs 'plates"),
                        ({"kind": "plates", "plates": [{"centre": [0, 0]}]}, r"plates\[0\]: needs centre and rate"),
                        ({"kind": "plates", "plates": [{"centre": [0, 0], "rate": 1, "speed": 2}]}, "'speed'"),
                        ({"kind": "plates", "width": -1, "plates": [{"centre": [0, 0], "rate": 1}]}, "positive")):
        with pytest.raises(ConfigError, match=f"boundary.velocity.outer.*{needle}"):
            _shell_config(bad, tmp_path)


ROOT = Path(__file__).resolve().parents[3]


@pytest.mark.parametrize("name", ["shell_plates", "annulus_davies"])
def test_shell_configs_pass_the_config_check(name, capsys):
    """``python -m convection check`` accepts both shell configs, and the fully resolved config it
    prints loads again to the same config."""
    import yaml

    from convection.app.cli import main

    path = ROOT / "configs" / f"{name}.yaml"
    assert main(["check", str(path)]) == 0
    printed = capsys.readouterr().out
    config = load_config(path)
    assert load_config(None, document=yaml.safe_load(printed)) == config
    assert config["mesh"]["geometry"] == ("spherical_shell" if name == "shell_plates" else "annulus")
    if name == "shell_plates":
        outer = config["boundary"]["velocity"]["outer"]
        assert outer["kind"] == "plates" and len(outer["plates"]) == 4
        assert config["particles"]["properties"] == ["initial_position", "displacement"]


def test_short_plates_run_keeps_particles_and_writes_displacement(world, tmp_path):
    """configs/shell_plates.yaml on a coarse straight-sided shell for two steps (the iterative Stokes
    solver, the 3D default): the surface moves with the plates, no particle is lost, every written
    particle lies in the shell at every step, and the particle output carries
    displacement = |x - initial_position| (0 at the start)."""
    pytest.importorskip("gmsh")
    import h5py

    from convection.app.factory import run_config
    from convection.io.pictures import read_statistics

    out = Path(world.bcast(str(tmp_path) if world.rank == 0 else None))
    n = 600
    overrides = ["mesh.resolution=0.6", "mesh.geometry_degree=1", "time.max_steps=2", "time.end=1",
                 f"particles.generator.num_particles={n}", "particles.output.every_steps=1",
                 "output.fields_every=0", "output.progress=none", "output.checkpoint.at_end=false",
                 f"output.directory={out}"]
    config = load_config(ROOT / "configs" / "shell_plates.yaml", overrides)
    run_config(config)
    if world.rank != 0:
        return
    stats = read_statistics(out / "statistics.csv")
    assert list(stats["step"]) == [0, 1, 2]
    assert list(stats["n_lost"]) == [0, 0, 0] and list(stats["n_particles"]) == [n, n, n]
    assert np.all((stats["stokes_iterations"] > 1) & (stats["stokes_iterations"] < 200))  # FGMRES converged
    assert stats["vrms"][-1] > 5.0
    for step in range(3):
        with h5py.File(out / f"particles_{step:06d}.h5", "r") as f:
            assert int(f.attrs["num_ranks"]) == world.size
            ids = np.asarray(f["ids"]).reshape(-1)
            x = np.asarray(f["positions"])
            x0 = np.asarray(f["properties/initial_position"])
            d = np.asarray(f["properties/displacement"]).reshape(-1)
        assert np.array_equal(np.sort(ids), np.arange(n))
        assert np.allclose(d, np.linalg.norm(x - x0, axis=1), rtol=0.0, atol=1e-12)
        assert (d.max() == 0.0) if step == 0 else (d.max() > 0.0)
        r = np.linalg.norm(x, axis=1)
        assert r.min() >= 1.22 * (1 - 1e-9) and r.max() <= 2.22
        assert np.all(np.linalg.norm(x0, axis=1) <= 1.22 + 0.15 + 1e-9)  # seeded in the layer above the core
