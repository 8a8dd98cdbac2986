"""benchmarks/viscoelastic/shear_band.py at CI size (16 x 8 cells, 12 steps of t_yield / 10): the band
between the Coulomb and Roscoe angles, the stress of the yielding particles at the Drucker-Prager
yield stress within 2 %, the elastic build-up before, and the nonlinear solve converging; the
angle measurement recovers a known band."""

import math

import numpy as np
import pytest

from benchmarks.viscoelastic import shear_band

STEPS = 12


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    from mpi4py import MPI

    return shear_band.run_case((16, 8), out=tmp_path_factory.mktemp("shear_band"), steps=STEPS, comm=MPI.COMM_WORLD)


def test_band_angle_is_between_coulomb_and_roscoe(run):
    assert shear_band.COULOMB < run.angle < shear_band.ROSCOE


def test_stress_builds_up_elastically_then_holds_at_the_yield_stress(run):
    n = np.arange(STEPS + 1)
    x = shear_band.G * shear_band.T_YIELD / 10 / shear_band.ETA  # G dt / eta
    maxwell = 2 * shear_band.ETA * shear_band.EPS * (1 - (1 + x) ** -n.astype(float)) / shear_band.TAU_Y
    elastic = run.at_yield == 0.0  # no particle yields yet
    assert elastic[:4].all() and not elastic[-1]
    # the seed is 1.6 % of the box
    np.testing.assert_allclose(run.stress[elastic], maxwell[elastic], rtol=0.03, atol=1e-12)
    assert run.plateau_error < 0.02
    assert np.all(np.abs(run.at_yield[-3:] - 1.0) < 0.02)
    assert run.yielding[-1] > 0.3 and run.stress[-1] < 0.98  # the band yields, the blocks beside it do not
    assert "| 16 x 8 |" in shear_band.table([run])


def test_nonlinear_solve_converges(run):
    assert np.all(run.iterations[:4] == 1)  # elastic: one linear solve
    assert np.all(run.iterations[5:] > 1)  # yielding: nonlinear
    history = run.history  # the last step's residual per iteration
    assert history[-1] <= 1e-6 < history[0]
    assert history[-1] < 1e-2 * history[-2]  # Newton's last step: faster than linear


def test_band_angle_measures_a_known_band():
    """A Gaussian band x = z / tan(37 deg) on a grid of midpoints: the measured angle is 37 degrees."""
    h = 1.0 / 16
    xs, zs = np.meshgrid(np.arange(h / 2, 2.0, h / 2), np.arange(h / 3, 1.0, h / 3))
    x, z = xs.ravel(), zs.ravel()
    rate = 1e-2 + np.exp(-((x - z / math.tan(math.radians(37.0))) / (1.5 * h)) ** 2)
    assert shear_band.band_angle(x, z, rate, h) == pytest.approx(37.0, abs=0.3)
