"""benchmarks/vanKeken/convergence.py: case selection, resolution knobs and the fitted peak (no runs)."""

from pathlib import Path

import numpy as np
import pytest

from convection.config.loader import load_config

from benchmarks.vanKeken.convergence import (
    DEFAULT_END, DEFAULT_HALF_WIDTH, Resolution, jitter, publish_section, resolutions, run_overrides,
)
from benchmarks.vanKeken.run import CONFIGS, fitted_peak, peak, reference

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("case, ratio", [("1b", 0.1), ("1c", 0.01)])
def test_case_selection_gives_the_case_config_with_the_knobs(case, ratio):
    res = Resolution(cells=32, ppc=40, min_ppc=10, max_level=3, cfl=0.5)
    config = load_config(ROOT / "configs" / CONFIGS[case], run_overrides(case, res, DEFAULT_END[case]))
    assert config["physics"]["viscosity"]["material_viscosities"] == [ratio, 1.0]
    assert config["physics"]["viscosity"]["mixing"] == "geometric"
    assert config["mesh"]["cells"] == [32, 32]
    assert config["particles"]["generator"]["particles_per_cell"] == 40
    assert config["particles"]["population"]["min_per_cell"] == 10
    assert config["adaptivity"]["max_level"] == 3
    assert config["time"]["cfl"] == 0.5
    assert config["time"]["end"] == DEFAULT_END[case]
    # the default end time lies past the published first peak and the fit window around it
    assert DEFAULT_END[case] > reference(case)["first_peak_time"].value + DEFAULT_HALF_WIDTH[case]


def test_default_knobs_keep_the_config_values():
    config = load_config(ROOT / "configs" / CONFIGS["1c"], run_overrides("1c", Resolution(24, 20), 80.0))
    assert config["adaptivity"]["max_level"] == 2 and config["time"]["cfl"] == 1.0
    assert config["particles"]["population"]["min_per_cell"] == 10  # the config's own population control
    with pytest.raises(ValueError):
        run_overrides("2", Resolution(24, 20), 80.0)


def test_resolutions_zip_and_product():
    seq = resolutions([16, 24, 32], [10, 20, 40], zip_lists=True, min_ppc=[5])
    assert [(r.cells, r.ppc, r.min_ppc) for r in seq] == [(16, 10, 5), (24, 20, 5), (32, 40, 5)]
    assert len({r.name for r in seq}) == 3
    grid = resolutions([16, 24], [10, 20])
    assert [(r.cells, r.ppc) for r in grid] == [(16, 10), (16, 20), (24, 10), (24, 20)]
    with pytest.raises(ValueError):
        resolutions([16, 24], [10], zip_lists=True)
    with pytest.raises(ValueError):
        resolutions([16, 24], [10, 20], min_ppc=[5, 10])
    steps = resolutions([32, 32], [20, 20], zip_lists=True, min_ppc=[10], cfl=[1.0, 0.5])
    assert [r.cfl for r in steps] == [1.0, 0.5] and steps[0].name != steps[1].name
    with pytest.raises(ValueError):
        resolutions([32, 32], [20, 20], cfl=[1.0, 0.5])


def test_fitted_peak_averages_jitter_that_biases_the_three_point_peak():
    """A cusp-like peak (slow rise, fast fall, as 1c's) sampled with 2 % jitter: the 3-point peak is
    biased upward by the noise, the least-squares cubic recovers the maximum and its time."""
    rng = np.random.default_rng(3)
    t = np.arange(30.0, 70.0, 0.2)
    smooth = 0.0135 * np.exp(-np.where(t < 51.0, ((t - 51.0) / 12.0) ** 2, ((t - 51.0) / 4.0) ** 2))
    errors_fit, errors_raw = [], []
    for _ in range(20):
        v = smooth * (1 + 0.02 * rng.standard_normal(t.size))
        fit = fitted_peak(t, v, 4.0)
        assert abs(fit.time - 51.0) < 1.0
        assert fit.scatter == pytest.approx(0.02 * 0.0135, rel=0.3)
        errors_fit.append(fit.vrms / 0.0135 - 1)
        errors_raw.append(peak(t, v).vrms / 0.0135 - 1)
    assert abs(np.mean(errors_fit)) < 0.01
    assert np.mean(errors_raw) > 0.02  # the largest of ~40 noisy samples near the top
    rms = lambda e: float(np.sqrt(np.mean(np.square(e))))  # noqa: E731
    assert rms(errors_fit) < 0.4 * rms(errors_raw)
    # on a noiseless parabola the fit is exact
    exact = fitted_peak(t, 1.0 - (t - 47.3) ** 2, 3.0)
    assert exact.vrms == pytest.approx(1.0, abs=1e-9) and exact.time == pytest.approx(47.3, abs=1e-2)


def test_publish_section_replaces_only_its_own_section(tmp_path):
    md = tmp_path / "convergence_1c.md"
    publish_section(md, "Mesh", "| a |\n")
    publish_section(md, "Particles", "| b |\n")
    publish_section(md, "Mesh", "| c |\n")  # replaced in place, the other section kept
    text = md.read_text()
    assert text == "## Mesh\n\n| c |\n\n## Particles\n\n| b |\n\n"


def test_jitter_measures_the_noise_and_splits_adaptation_steps():
    """On a linear ramp with 1 % noise, plus 3 % extra noise at every 10th step, the jitter is ~1 % at
    the other steps and larger at the adaptation steps; a noiseless ramp has none."""
    rng = np.random.default_rng(5)
    step = np.arange(2000)
    t = 0.1 * step
    noise = 0.01 * rng.standard_normal(step.size)
    noise[step % 10 == 0] += 0.03 * rng.standard_normal(int(np.count_nonzero(step % 10 == 0)))
    stats = {"time": t, "step": step.astype(float), "vrms": (1.0 + 0.01 * t) * (1 + noise)}
    other, at = jitter(stats, (10.0, 190.0), 10)
    # 2 of the 9 other steps have an adaptation step as a neighbour, whose extra noise enters once
    assert other == pytest.approx(np.sqrt(0.01**2 + 2 / 9 * 0.03**2 / 6), rel=0.1)
    assert at > 1.5 * other
    clean = jitter({**stats, "vrms": 1.0 + 0.01 * t}, (10.0, 190.0), 10)
    assert max(clean) < 1e-12
