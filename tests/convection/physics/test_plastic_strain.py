"""Particle history into the physics: the ``plastic_strain`` property in simple shear.

A box sheared by its boundaries, ``u = (z, 0)``, has the uniform strain rate ``eps_xz = 1/2``,
``eps_II = 1/2``. A von Mises material of viscosity 10 and yield stress ``sigma_y = 1`` yields
everywhere (``sigma_y / (2 eps_II) = 1 < 10``), so every particle accumulates plastic strain at
the rate ``eps_II``: ``e(t) = t / 2``. The yield stress is weakened linearly in ``e`` (ASPECT's
convention), ``w(e) = 1 - (1 - 0.5) clip((e - 0.05) / 0.1, 0, 1)``, so the viscosity of the
(uniform) flow is ``eta(t) = w(t / 2)``, read from the ``eta_min`` / ``eta_max`` columns. With a
yield stress of 100 the material never yields and the plastic strain stays 0.
"""

import textwrap

import h5py
import numpy as np
import pytest

from _runs import final_particles, rows, run_cli, sets
from convection.physics.rheology import weakening_factor

SHEAR = textwrap.dedent("""\
    name: simple_shear
    mesh: {cells: [8, 8]}
    physics:
      Ra: 0.0
      viscosity:
        law:
          name: viscoplastic
          combination: minimum
          viscous: {name: constant, eta0: 10.0}
          plastic:
            name: von_mises
            yield_stress: 1.0
            weakening: {field: plastic_strain, start: 0.05, end: 0.15, factor: 0.5}
    boundary:
      velocity:
        bottom: {kind: prescribed, value: [0, 0]}
        top: {kind: prescribed, value: [1, 0]}
        left: {kind: prescribed, value: ["z", 0]}
        right: {kind: prescribed, value: ["z", 0]}
      temperature: {left: insulating, right: insulating, bottom: insulating, top: insulating}
    initial: {temperature: "0"}
    energy: {enabled: false}
    stokes:
      solver: direct
      nonlinear: {method: picard, rtol: 1.0e-10, max_iterations: 20}
    particles:
      enabled: true
      generator: {name: random_uniform, particles_per_cell: 10, seed: 1}
      interpolator: {name: cell_average, mean: arithmetic}
      properties: [plastic_strain]
      output: {every_steps: 4}
    time: {end: 0.4, cfl: 100.0, dt_max: 0.05}
    blowup: {lost_fraction: 1.0}  # the flow leaves through the right side
    output: {fields_every: 0, progress: none}
    """)


@pytest.fixture(scope="module")
def config(tmp_path_factory):
    path = tmp_path_factory.mktemp("shear") / "shear.yaml"
    path.write_text(SHEAR)
    return path


@pytest.fixture(scope="module")
def sheared(config, tmp_path_factory):
    runs = {}
    for ranks in (1, 2):
        folder = tmp_path_factory.mktemp(f"shear{ranks}")
        proc = run_cli(["run", str(config), "--output", str(folder)], ranks)
        assert proc.returncode == 0, proc.stderr
        runs[ranks] = folder
    return runs


def test_plastic_strain_grows_at_the_analytic_rate_and_weakens_the_yield_stress(sheared):
    table = rows(sheared[1])
    assert len(table) == 9
    for row in table:
        t = float(row["time"])
        assert int(row["nonlinear_iterations"]) >= 1 and float(row["nonlinear_residual"]) < 1e-10
        assert float(row["vrms"]) == pytest.approx(3 ** -0.5, rel=1e-12)  # u = (z, 0)
        # The viscosity at the end of the step: the yield viscosity sigma_y w(e) / (2 eps_II).
        eta = weakening_factor(0.5 * t, 0.05, 0.15, 0.5)
        assert float(row["eta_min"]) == pytest.approx(eta, rel=1e-11)
        assert float(row["eta_max"]) == pytest.approx(eta, rel=1e-11)
    ids, x, props = final_particles(sheared[1])
    assert props.shape == (ids.shape[0], 1) and ids.shape[0] > 500
    assert np.allclose(props[:, 0], 0.5 * 0.4, rtol=1e-12, atol=0)
    assert int(table[-1]["n_particles"]) + int(table[-1]["n_lost"]) == 640 * 2


def test_no_yield_no_plastic_strain(config, tmp_path):
    proc = run_cli(["run", str(config), "--output", str(tmp_path),
                    *sets(["physics.viscosity.law.plastic.yield_stress=100.0", "time.end=0.1"])])
    assert proc.returncode == 0, proc.stderr
    assert all(float(r["eta_max"]) == pytest.approx(10.0, rel=1e-12) for r in rows(tmp_path))
    _, _, props = final_particles(tmp_path)
    assert np.all(props[:, 0] == 0.0)


def test_two_ranks_give_the_same_history(sheared):
    """Counts equal; values to the direct solver's round-off (MUMPS sums in another order on 2 ranks)."""
    a, b = rows(sheared[1]), rows(sheared[2])
    assert [r["step"] for r in a] == [r["step"] for r in b]
    for ra, rb in zip(a, b):
        for key in ("n_particles", "n_lost", "nonlinear_iterations", "cells"):
            assert ra[key] == rb[key], key
        for key in ("time", "vrms", "eta_min", "eta_max", "vrms_surface"):
            assert float(ra[key]) == pytest.approx(float(rb[key]), rel=1e-11), key
    ids1, x1, p1 = final_particles(sheared[1])
    ids2, x2, p2 = final_particles(sheared[2])
    assert np.array_equal(ids1, ids2)
    assert np.allclose(x1, x2, rtol=0, atol=1e-13) and np.allclose(p1, p2, rtol=1e-13, atol=0)


def test_plastic_strain_is_written_with_the_particles(sheared):
    with h5py.File(sheared[2] / "particles_000008.h5", "r") as f:
        e = f["properties/plastic_strain"][...]
    assert e.shape[0] > 500 and np.allclose(e, 0.2, rtol=1e-12, atol=0)


def test_damage_on_particles_lowers_the_viscosity(config, tmp_path):
    """``damaged`` law over the ``damage`` property (alpha = 1, no healing): in the same shear,
    d = eps_II t = t / 2 on every particle and eta = 10 (1 - d)."""
    law = "{name: damaged, law: {name: constant, eta0: 10.0}}"
    proc = run_cli(["run", str(config), "--output", str(tmp_path),
                    *sets([f"physics.viscosity.law={law}", "particles.properties=[{name: damage, alpha: 1.0}]",
                           "output.statistics=[time,velocity,rheology]"])])
    assert proc.returncode == 0, proc.stderr
    table = rows(tmp_path)
    assert len(table) == 9
    for row in table:
        eta = 10.0 * (1.0 - 0.5 * float(row["time"]))
        assert float(row["eta_min"]) == pytest.approx(eta, rel=1e-10)
        assert float(row["eta_max"]) == pytest.approx(eta, rel=1e-10)
    _, _, props = final_particles(tmp_path)
    assert np.allclose(props[:, 0], 0.2, rtol=1e-12, atol=0)
