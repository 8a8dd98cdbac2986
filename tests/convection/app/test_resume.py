"""Whole-run checkpoints: a killed run resumes as if it had never stopped; bad inputs give one line.

The runs are real CLI runs in subprocesses (``mpirun -n 2`` where it says so): a van Keken 1a
setup on a small mesh with particles, adaptivity and (on 2 ranks) repartitioning, with the shipped
solver (MUMPS; reproducible on several ranks, see :func:`convection.solvers.petsc_options.reproducible_lu`).
Every shipped config that adapts or balances is killed and resumed in tests/configs/test_resume_configs.py.
"""

from __future__ import annotations

import random
import shutil

import h5py
import numpy as np
import pytest

from _runs import CONFIGS, assert_same_statistics, error_line, final_particles, kill_run, rows, rows_written, run_cli, \
    sets, writing_checkpoint

CONFIG = CONFIGS / "vankeken_1a.yaml"
SMALL = ["mesh.cells=[8,8]", "adaptivity.max_level=1", "adaptivity.every=4",
         "particles.generator.particles_per_cell=10", "output.progress=none", "output.fields_every=5",
         "particles.output.every_steps=3", "time.max_steps=24"]
PARALLEL = ["balance.strategy=every", "balance.every=5"]


def _run(args, ranks=1, budget=300):
    return run_cli(args, ranks, budget)


@pytest.mark.parametrize("moment", ["between steps", "during a checkpoint write"])
def test_killed_run_resumes_bit_for_bit_on_two_ranks(tmp_path, moment):
    extra = [*SMALL, *PARALLEL, "output.checkpoint.every_steps=1" if moment != "between steps" else
             "output.checkpoint.every_steps=3"]
    reference = tmp_path / "reference"
    assert _run(["run", str(CONFIG), "--output", str(reference), *sets(extra)], ranks=2).returncode == 0
    killed = tmp_path / "killed"
    if moment == "between steps":
        stop_after = random.Random().randint(6, 20)
        code = kill_run(CONFIG, killed, 2, extra, when=lambda d: rows_written(d, stop_after))
    else:
        code = kill_run(CONFIG, killed, 2, extra, when=lambda d: rows_written(d, 6) and writing_checkpoint(d))
    assert code != 0  # it was killed before the end
    from convection.io.checkpoint import latest_checkpoint

    assert latest_checkpoint(killed) is not None
    proc = _run(["resume", str(killed)], ranks=2)
    assert proc.returncode == 0, proc.stderr
    assert_same_statistics(reference, killed)
    for a, b in zip(final_particles(reference), final_particles(killed)):
        assert np.array_equal(a, b)
    assert len(list((killed / "checkpoints").glob(".checkpoint_*"))) == 0  # strays removed


def test_resume_on_another_rank_count(tmp_path):
    """Written on 2 ranks, resumed on 1 (and written on 3, resumed on 2): the same run to round-off."""
    extra = [*SMALL, *PARALLEL, "time.max_steps=10", "output.checkpoint.every_steps=10"]
    longer = ["time.max_steps=30"]
    reference = tmp_path / "reference"
    assert _run(["run", str(CONFIG), "--output", str(reference), *sets(extra), *sets(longer)], ranks=2).returncode == 0
    for written, resumed in ((2, 1), (3, 2)):
        run_dir = tmp_path / f"from{written}"
        assert _run(["run", str(CONFIG), "--output", str(run_dir), *sets(extra)], ranks=written).returncode == 0
        proc = _run(["resume", str(run_dir), *sets(longer)], ranks=resumed)
        assert proc.returncode == 0, proc.stderr
        a, b = rows(reference), rows(run_dir)
        assert [r["step"] for r in a] == [r["step"] for r in b]
        assert float(b[-1]["vrms"]) == pytest.approx(float(a[-1]["vrms"]), rel=1e-10)
        assert [r["n_particles"] for r in a] == [r["n_particles"] for r in b]
        assert np.array_equal(final_particles(reference)[0], final_particles(run_dir)[0])


def test_bad_resume_inputs(tmp_path):
    run_dir = tmp_path / "run"
    assert _run(["run", str(CONFIG), "--output", str(run_dir), *sets([*SMALL, "time.max_steps=4"])]).returncode == 0
    checkpoint = run_dir / "checkpoints" / "checkpoint_000004"
    error_line(_run(["resume", str(tmp_path / "nowhere")]), 1, "not found")
    error_line(_run(["resume", str(run_dir), "--set", "mesh.cells=[4,4]"]), 2, "mesh.cells")
    copy = tmp_path / "damaged"
    shutil.copytree(run_dir, copy)
    state = copy / "checkpoints" / "checkpoint_000004" / "state.h5"
    state.write_bytes(state.read_bytes()[:2000])
    error_line(_run(["resume", str(copy)], ranks=2), 1, "damaged")
    with h5py.File(checkpoint / "state.h5", "a") as f:
        f.attrs["config_version"] = 99
    error_line(_run(["resume", str(run_dir)]), 1, "config version 99")
    empty = tmp_path / "empty"
    empty.mkdir()
    error_line(_run(["resume", str(empty)]), 1, "no complete checkpoint")


def test_blow_up_stops_with_one_line_and_keeps_the_checkpoint(tmp_path):
    """An absurd time step (CFL 200) makes particles leave the box: the run stops, names the step."""
    run_dir = tmp_path / "run"
    extra = [*SMALL, "output.checkpoint.every_steps=2", "time.max_steps=40"]
    first = _run(["run", str(CONFIG), "--output", str(run_dir), *sets(extra), "--set", "time.max_steps=4"])
    assert first.returncode == 0
    proc = _run(["resume", str(run_dir), "--set", "time.cfl=200", "--set", "time.max_steps=40"])
    line = error_line(proc, 3, "failed at step")
    assert "particles lost" in line or "vrms" in line
    import json

    assert json.loads((run_dir / "summary.json").read_text())["reason"].startswith("failed at step")
    from convection.io.checkpoint import latest_checkpoint

    newest = latest_checkpoint(run_dir)
    assert newest is not None
    proc = _run(["resume", str(run_dir), "--set", "time.max_steps=6"])  # the last good checkpoint loads
    assert proc.returncode == 0, proc.stderr
