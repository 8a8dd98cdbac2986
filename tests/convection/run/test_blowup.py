"""Blow-up detection watches the model itself, whatever statistics columns a run writes.

The CLI cases run a small van Keken 1a in a subprocess (on 1 and, where it says so, 2 ranks);
``time.cfl=200`` makes its first step carry particles out of the box: a blow-up at step 1.
"""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np
import pytest
from mpi4py import MPI

from _runs import error_line as _error_line, run_cli as _run, sets as _sets

from convection.config.loader import load_config
from convection.app.factory import build_model
from convection.io.pictures import read_statistics
from convection.postprocess.postprocessors import ParticleStatistics, TemperatureStatistics, TimeColumns, Velocity
from convection.run.loop import BlowUp, SteadyState, Watch, Watched

ROOT = Path(__file__).resolve().parents[3]
CONFIG = ROOT / "configs" / "vankeken_1a.yaml"
SMALL = ["mesh.cells=[8,8]", "adaptivity.max_level=1", "output.progress=none"]


def _run_state(checkpoint: Path) -> dict:
    with h5py.File(checkpoint / "state.h5", "r") as f:
        return json.loads(f["state"][...].tobytes().decode())["run"]


def test_checks_read_the_watched_quantities():
    blowup = BlowUp()
    first = Watched(1.0e-3, T_min=0.0, T_max=1.0, T_mean=0.5, n_particles=1000, n_lost=0)
    assert blowup.check(first, first, None) is None
    assert blowup.check(first._replace(T_mean=float("nan")), first, first) == "T_mean is nan"
    assert blowup.check(first._replace(n_lost=1), first, first) is None  # 1 <= 1e-3 * 1000
    assert blowup.check(first._replace(n_lost=2), first, first).startswith("2 particles lost")
    assert "grew from 0.001 to 2" in blowup.check(first._replace(vrms=2.0), first, first)
    assert blowup.check(first._replace(vrms=2.0), first, None) is None  # no step before
    assert blowup.check(first._replace(T_max=2.01), first, first).startswith("temperature left [-1, 2]")
    assert BlowUp(max_vrms=1e-4).check(first, first, None).startswith("vrms 0.001 exceeds")
    bare = Watched(1.0e-3)  # no temperature, no particles: those checks have nothing to look at
    assert blowup.check(bare, bare, bare) is None


def test_steady_state_skips_missing_quantities_and_replaces_a_repeated_step():
    steady = SteadyState(1e-3, 2)
    assert not any(steady({"vrms": 1.0, "nusselt": None}, step) for step in range(2))
    assert not steady({"vrms": 1.0, "nusselt": None}, 1)  # step 1 again: replaces, still 2 entries
    assert steady({"vrms": 1.0, "nusselt": None}, 2)
    restored = SteadyState(1e-3, 2)
    restored.restore(json.loads(json.dumps(steady.state())))
    assert restored({"vrms": 1.0}, 2) and restored.state() == steady.state()


def test_watch_measures_what_the_columns_leave_out_and_reuses_the_rest(tmp_path):
    config = load_config(CONFIG, [*SMALL, f"output.directory={tmp_path}"])
    model = build_model(config, comm=MPI.COMM_SELF)
    model.start()
    try:
        alone = Watch(model, [TimeColumns()])(model, {"step": 0, "time": 0.0, "dt": 0.0})
        expected = {**Velocity()(model), **TemperatureStatistics()(model)}
        assert alone == Watched(expected["vrms"], expected["T_min"], expected["T_max"], expected["T_mean"],
                                model.particles.num_particles, 0)
        assert alone.n_particles > 0
        # with the postprocessors present, their values are taken from the row (not measured again)
        everything = [TimeColumns(), Velocity(), TemperatureStatistics(), ParticleStatistics()]
        row = {"vrms": 7.0, "T_min": -1.0, "T_max": 2.0, "T_mean": 0.5, "n_particles": 5, "n_lost": 1}
        row.update({c: 0 for c in ParticleStatistics.columns if c not in row})
        assert Watch(model, everything)(model, row) == Watched(7.0, -1.0, 2.0, 0.5, 5, 1)
    finally:
        model.destroy()


@pytest.mark.parametrize("ranks", [1, 2])
def test_blow_up_is_caught_with_only_the_time_columns(tmp_path, ranks):
    run_dir = tmp_path / "run"
    proc = _run(["run", str(CONFIG), "--output", str(run_dir),
                 *_sets([*SMALL, "output.statistics=[time]", "time.cfl=200", "time.max_steps=10"])], ranks)
    line = _error_line(proc, 3)
    assert line.startswith("error: run failed at step 1, t=2000: ") and "particles lost" in line, line
    assert list(read_statistics(run_dir / "statistics.csv")) == ["step", "time", "dt"]
    assert json.loads((run_dir / "summary.json").read_text())["reason"].startswith("failed at step 1")


def test_resume_keeps_the_blow_up_references(tmp_path):
    """The first step's quantities and the checkpoint step's (the 'previous' of the growth test)
    come back from the checkpoint, not from statistics.csv (which here has no such columns)."""
    run_dir = tmp_path / "run"
    extra = [*SMALL, "output.statistics=[time]", "output.checkpoint.every_steps=2", "time.max_steps=4"]
    assert _run(["run", str(CONFIG), "--output", str(run_dir), *_sets(extra)]).returncode == 0
    checkpoints = run_dir / "checkpoints"
    first = _run_state(checkpoints / "checkpoint_000002")["watched"]["first"]
    assert first["n_particles"] == 20 * 222 and first["n_lost"] == 0 and first["T_max"] == 0.0
    last = _run_state(checkpoints / "checkpoint_000004")["watched"]
    assert last["first"] == first
    # vrms grows by a factor ~1.2 per step here: the first step after the resume must see it
    line = _error_line(_run(["resume", str(run_dir), *_sets(["time.max_steps=8", "blowup.vrms_growth=1.0001"])]), 3)
    assert line.startswith("error: run failed at step 5, t=") and \
        f"vrms grew from {last['last']['vrms']:.6g} to " in line, line
    assert _run(["resume", str(run_dir), "--set", "time.max_steps=6"]).returncode == 0
    assert _run_state(checkpoints / "checkpoint_000006")["watched"]["first"] == first


def test_statistics_without_the_time_columns_still_resume(tmp_path):
    """step, time and dt are always written: a resume needs the step of every row."""
    run_dir = tmp_path / "run"
    extra = [*SMALL, "output.statistics=[velocity]", "output.checkpoint.every_steps=2", "time.max_steps=3"]
    assert _run(["run", str(CONFIG), "--output", str(run_dir), *_sets(extra)]).returncode == 0
    proc = _run(["resume", str(run_dir), "--checkpoint", str(run_dir / "checkpoints" / "checkpoint_000002"),
                 "--set", "time.max_steps=4"])
    assert proc.returncode == 0, proc.stderr
    stats = read_statistics(run_dir / "statistics.csv")
    assert list(stats) == ["step", "time", "dt", "vrms"]
    assert stats["step"].tolist() == [0, 1, 2, 3, 4]


def test_a_checkpoint_without_the_references_resumes(tmp_path):
    """Checkpoints written before the references were kept: they are measured on resuming."""
    run_dir = tmp_path / "run"
    extra = [*SMALL, "output.checkpoint.every_steps=2", "time.max_steps=2"]
    assert _run(["run", str(CONFIG), "--output", str(run_dir), *_sets(extra)]).returncode == 0
    checkpoint = run_dir / "checkpoints" / "checkpoint_000002"
    with h5py.File(checkpoint / "state.h5", "a") as f:
        state = json.loads(f["state"][...].tobytes().decode())
        kept = state["run"].pop("watched")
        del state["run"]["steady"], f["state"]
        f["state"] = np.frombuffer(json.dumps(state).encode(), dtype=np.uint8)
    proc = _run(["resume", str(run_dir), "--set", "time.max_steps=3"])
    assert proc.returncode == 0, proc.stderr
    measured = _run_state(run_dir / "checkpoints" / "checkpoint_000003")["watched"]["first"]
    assert measured == kept["last"]  # the checkpoint step's values, measured again
