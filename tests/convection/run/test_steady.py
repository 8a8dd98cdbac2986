"""The steady-state rate test stops at a model time, not a step count, and estimates the time left.

Synthetic histories q(t) = q_inf (1 + A exp(-lambda t)) (and a decaying oscillation) sampled with
different step lengths stand in for Nu and vrms.
"""

from __future__ import annotations

import io
import json

import numpy as np
import pytest

from convection.run.progress import Progress
from convection.run.steady import SteadyRate, SteadyState, decay_estimate

LAMBDA = 30.0


def _q(t: float) -> dict[str, float]:
    return {"vrms": 480.0 * (1.0 + 0.5 * np.exp(-LAMBDA * t)),
            "nusselt": 10.0 * (1.0 - 0.3 * np.exp(-LAMBDA * t) * np.cos(200.0 * t))}


def _stop_time(test, dt: float, end: float = 2.0) -> float:
    for step, t in enumerate(np.arange(0.0, end, dt)):
        if test(_q(t), step, t):
            return float(t)
    return float("inf")


def test_rate_stops_at_the_same_model_time_for_any_step_length():
    stops = [_stop_time(SteadyRate(1e-3, 0.01), dt) for dt in (4e-4, 2e-4, 1e-4, 5e-5)]
    assert np.all(np.isfinite(stops))
    # the same time to within the longest step
    assert max(stops) - min(stops) <= 4e-4, stops
    # the step-count test (20 steps) stops much sooner with half the step: its window spans half the time
    steps = [_stop_time(SteadyState(1e-5, 20), dt) for dt in (4e-4, 2e-4)]
    assert steps[0] - steps[1] > 10 * 4e-4, steps


def test_rate_is_the_relative_change_per_unit_time_over_the_window():
    tau = 0.01
    test = SteadyRate(None, tau, columns=("vrms",))
    for t in np.arange(0.0, 0.2 + 1e-12, 1e-3):
        test({"vrms": 2.0 + t}, None, float(t))  # linear: |q(t - tau) - q(t)| = tau
    assert test.change_rate() == pytest.approx(1.0 / 2.2, rel=1e-12)
    # a window start between two steps: q(t - tau) interpolated linearly
    odd = SteadyRate(None, 0.0105, columns=("vrms",))
    for t in np.arange(0.0, 0.2 + 1e-12, 1e-3):
        odd({"vrms": 2.0 + t}, None, float(t))
    assert odd.change_rate() == pytest.approx(1.0 / 2.2, rel=1e-12)


def test_decay_estimate_of_an_exponential_change_rate():
    t = np.linspace(0.1, 0.3, 41)
    rates = 5.0 * np.exp(-LAMBDA * t)
    fit = decay_estimate(t, rates, 1e-4)
    assert fit.rate == pytest.approx(LAMBDA, rel=1e-10)
    assert fit.remaining == pytest.approx(np.log(rates[-1] / 1e-4) / LAMBDA, rel=1e-10)
    assert decay_estimate(t, np.exp(t), 1e-4).remaining is None  # growing: no estimate
    assert decay_estimate(t, rates, 10.0).remaining == 0.0  # already below
    assert decay_estimate(t[:2], rates[:2], 1e-4) is None


def test_remaining_time_predicts_when_the_rate_test_stops():
    """For an exponentially decaying change the estimate made early in the decay is the stop time."""
    test = SteadyRate(1e-4, 0.01, columns=("vrms",))
    dt, estimates = 1e-4, {}
    for step, t in enumerate(np.arange(0.0, 2.0, dt)):
        if test({"vrms": 480.0 * (1.0 + 0.01 * np.exp(-LAMBDA * t))}, step, float(t)):
            stop = float(t)
            break
        remaining = test.remaining()
        if remaining is not None:
            estimates[round(float(t), 6)] = float(t) + remaining
    early = [estimates[t] for t in (0.05, 0.1, 0.2)]
    # R ~ A lambda exp(-lambda t) (tau lambda = 0.3: times (exp(0.3) - 1) / 0.3)
    expected = np.log(0.01 * (np.exp(LAMBDA * 0.01) - 1.0) / 0.01 / 1e-4) / LAMBDA
    assert stop == pytest.approx(expected, abs=2 * dt)
    assert early == pytest.approx([stop] * 3, abs=1e-3)  # 0.4 % of the time left at t = 0.05


def test_state_round_trip_and_a_repeated_time_replaces():
    test = SteadyRate(1e-3, 0.01)
    for step, t in enumerate(np.arange(0.0, 0.05, 1e-3)):
        test(_q(t), step, float(t))
    test(_q(0.0495), 50, 0.049)  # the same time again: replaces the last entry
    again = SteadyRate(1e-3, 0.01)
    again.restore(json.loads(json.dumps(test.state())))
    assert again.state() == test.state() and again.change_rate() == test.change_rate()
    assert test.remaining() == again.remaining()
    with pytest.raises(ValueError, match="model time"):
        test(_q(0.1), 51)


def test_progress_eta_to_the_steady_state():
    stream = io.StringIO()
    progress = Progress(1.0, mode="lines", every=1, stream=stream)
    progress._start -= 10.0  # 10 s of wall time for t = 0.1: 100 s per unit time
    progress.update(5, 0.1, 0.01, 1.0, remaining=0.2)
    progress.update(6, 0.1, 0.01, 1.0)
    progress.update(7, 0.1, 0.01, 1.0, remaining=5.0)  # later than the end: the end counts
    lines = stream.getvalue().splitlines()
    assert "ETA 20s (steady)" in lines[0]
    assert "ETA 90s" in lines[1] and "steady" not in lines[1]
    assert "ETA 90s" in lines[2] and "steady" not in lines[2]


def test_a_resumed_run_stops_where_the_uninterrupted_one_does(tmp_path):
    """The rate test's history is in the checkpoint: stopped at step 40 and resumed, a small 1a run
    stops at the same step, with the same numbers."""
    from _runs import CONFIGS, run_cli, sets

    small = ["mesh.cells=[8,8]", "time.steady_state_tolerance=null", "time.steady_state_rate=1e-2",
             "time.steady_state_time_window=0.02", "output.progress=none", "output.fields_every=0"]
    config = str(CONFIGS / "blankenbach_1a.yaml")
    whole = run_cli(["run", config, "--output", str(tmp_path / "whole"), *sets(small)])
    assert whole.returncode == 0, whole.stderr
    part = run_cli(["run", config, "--output", str(tmp_path / "part"), *sets([*small, "time.max_steps=40"])])
    assert part.returncode == 0, part.stderr
    resumed = run_cli(["resume", str(tmp_path / "part"), *sets(["time.max_steps=null"])])
    assert resumed.returncode == 0, resumed.stderr
    first, second = (json.loads((tmp_path / name / "summary.json").read_text()) for name in ("whole", "part"))
    assert first["reason"] == second["reason"] == "steady state"
    assert first["steps"] == second["steps"] > 40
    assert (first["time"], first["nusselt"], first["vrms"]) == (second["time"], second["nusselt"], second["vrms"])
