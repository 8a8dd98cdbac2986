"""Whole-run checkpoints: a killed run resumes as if it had never stopped; bad inputs give one line.

The runs are real CLI runs in subprocesses (``mpirun -n 2`` where it says so): a van Keken 1a
setup on a small mesh with particles, adaptivity and (on 2 ranks) repartitioning, and the
iterative Stokes solver, whose results do not change from run to run (parallel MUMPS
factorisations do, in the last bits; see the README).
"""

from __future__ import annotations

import csv
import os
import random
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / "configs" / "vankeken_1a.yaml"
SMALL = ["mesh.cells=[8,8]", "adaptivity.max_level=1", "adaptivity.every=4", "particles.generator.particles_per_cell=10",
         # iterative: MUMPS is not bit-reproducible on > 1 rank; tight tolerance: runs on different
         # rank counts agree to round-off
         "stokes.solver=iterative", "stokes.petsc_options={ksp_rtol: 1.0e-12}", "output.progress=none",
         "output.fields_every=5", "particles.output.every_steps=3",
         "time.max_steps=24"]
PARALLEL = ["balance.strategy=every", "balance.every=5"]
RANK_DEPENDENT = ("wall_time", "cell_imbalance", "particle_imbalance")


def _command(args, ranks=1):
    cmd = [sys.executable, "-m", "convection", *args]
    if ranks > 1:
        cmd = [shutil.which("mpirun"), "-n", str(ranks), "--oversubscribe", *cmd]
    return cmd


def _env():
    return dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")


def _sets(items):
    return [a for item in items for a in ("--set", item)]


def _run(args, ranks=1, timeout=300):
    return subprocess.run(_command(args, ranks), cwd=ROOT, env=_env(), capture_output=True, text=True, timeout=timeout)


def _rows(run_dir):
    with open(Path(run_dir) / "statistics.csv", newline="") as f:
        return list(csv.DictReader(f))


def _same_statistics(a, b):
    """Rows equal to the last bit in every column but the rank-dependent ones."""
    rows_a, rows_b = _rows(a), _rows(b)
    assert len(rows_a) == len(rows_b)
    for x, y in zip(rows_a, rows_b):
        for key in x:
            if key not in RANK_DEPENDENT:
                assert x[key] == y[key], (key, x["step"], x[key], y[key])


def _final_particles(run_dir):
    from convection.checkpoint import latest_checkpoint

    with h5py.File(latest_checkpoint(run_dir) / "particles.h5", "r") as f:
        ids = f["ids"][...]
        order = np.argsort(ids)
        return ids[order], f["x"][...][order], f["properties"][...][order]


def _kill_run(run_dir, ranks, extra, *, when):
    """Start a run and SIGKILL it (the whole process group) when ``when(run_dir)`` is true."""
    proc = subprocess.Popen(_command(["run", str(CONFIG), "--output", str(run_dir), *_sets(extra)], ranks),
                            cwd=ROOT, env=_env(), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True)
    deadline = time.monotonic() + 300
    while proc.poll() is None and time.monotonic() < deadline:
        if when(run_dir):
            os.killpg(proc.pid, signal.SIGKILL)
            break
        time.sleep(0.002)
    proc.wait(timeout=60)
    return proc.returncode


def _rows_written(run_dir, n):
    path = run_dir / "statistics.csv"
    return path.exists() and len(path.read_text().splitlines()) > n


def _writing_checkpoint(run_dir):
    folder = run_dir / "checkpoints"
    return folder.exists() and any(p.name.startswith(".checkpoint_") for p in folder.iterdir())


@pytest.mark.parametrize("moment", ["between steps", "during a checkpoint write"])
def test_killed_run_resumes_bit_for_bit_on_two_ranks(tmp_path, moment):
    extra = [*SMALL, *PARALLEL, "output.checkpoint.every_steps=1" if moment != "between steps" else
             "output.checkpoint.every_steps=3"]
    reference = tmp_path / "reference"
    assert _run(["run", str(CONFIG), "--output", str(reference), *_sets(extra)], ranks=2).returncode == 0
    killed = tmp_path / "killed"
    if moment == "between steps":
        stop_after = random.Random().randint(6, 20)
        code = _kill_run(killed, 2, extra, when=lambda d: _rows_written(d, stop_after))
    else:
        code = _kill_run(killed, 2, extra, when=lambda d: _rows_written(d, 6) and _writing_checkpoint(d))
    assert code != 0  # it was killed before the end
    from convection.checkpoint import latest_checkpoint

    assert latest_checkpoint(killed) is not None
    proc = _run(["resume", str(killed)], ranks=2)
    assert proc.returncode == 0, proc.stderr
    _same_statistics(reference, killed)
    for a, b in zip(_final_particles(reference), _final_particles(killed)):
        assert np.array_equal(a, b)
    assert len(list((killed / "checkpoints").glob(".checkpoint_*"))) == 0  # strays removed


def test_resume_on_another_rank_count(tmp_path):
    """Written on 2 ranks, resumed on 1 (and written on 3, resumed on 2): the same run to round-off."""
    extra = [*SMALL, *PARALLEL, "time.max_steps=10", "output.checkpoint.every_steps=10"]
    longer = ["time.max_steps=30"]
    reference = tmp_path / "reference"
    assert _run(["run", str(CONFIG), "--output", str(reference), *_sets(extra), *_sets(longer)], ranks=2).returncode == 0
    for written, resumed in ((2, 1), (3, 2)):
        run_dir = tmp_path / f"from{written}"
        assert _run(["run", str(CONFIG), "--output", str(run_dir), *_sets(extra)], ranks=written).returncode == 0
        proc = _run(["resume", str(run_dir), *_sets(longer)], ranks=resumed)
        assert proc.returncode == 0, proc.stderr
        a, b = _rows(reference), _rows(run_dir)
        assert [r["step"] for r in a] == [r["step"] for r in b]
        assert float(b[-1]["vrms"]) == pytest.approx(float(a[-1]["vrms"]), rel=1e-10)
        assert [r["n_particles"] for r in a] == [r["n_particles"] for r in b]
        assert np.array_equal(_final_particles(reference)[0], _final_particles(run_dir)[0])


def _one_line(proc, code, needle):
    lines = [ln for ln in proc.stderr.splitlines() if ln.startswith("error")]
    assert proc.returncode == code, proc.stderr
    assert len(lines) == 1 and needle in lines[0], proc.stderr
    assert "Traceback" not in proc.stderr
    return lines[0]


def test_bad_resume_inputs(tmp_path):
    run_dir = tmp_path / "run"
    assert _run(["run", str(CONFIG), "--output", str(run_dir), *_sets([*SMALL, "time.max_steps=4"])]).returncode == 0
    checkpoint = run_dir / "checkpoints" / "checkpoint_000004"
    _one_line(_run(["resume", str(tmp_path / "nowhere")]), 1, "not found")
    _one_line(_run(["resume", str(run_dir), "--set", "mesh.cells=[4,4]"]), 2, "mesh.cells")
    copy = tmp_path / "damaged"
    shutil.copytree(run_dir, copy)
    state = copy / "checkpoints" / "checkpoint_000004" / "state.h5"
    state.write_bytes(state.read_bytes()[:2000])
    _one_line(_run(["resume", str(copy)], ranks=2), 1, "damaged")
    with h5py.File(checkpoint / "state.h5", "a") as f:
        f.attrs["config_version"] = 99
    _one_line(_run(["resume", str(run_dir)]), 1, "config version 99")
    empty = tmp_path / "empty"
    empty.mkdir()
    _one_line(_run(["resume", str(empty)]), 1, "no complete checkpoint")


def test_blow_up_stops_with_one_line_and_keeps_the_checkpoint(tmp_path):
    """An absurd time step (CFL 200) makes particles leave the box: the run stops, names the step."""
    run_dir = tmp_path / "run"
    extra = [*SMALL, "output.checkpoint.every_steps=2", "time.max_steps=40"]
    assert _run(["run", str(CONFIG), "--output", str(run_dir), *_sets(extra), "--set", "time.max_steps=4"]).returncode == 0
    proc = _run(["resume", str(run_dir), "--set", "time.cfl=200", "--set", "time.max_steps=40"])
    line = _one_line(proc, 3, "failed at step")
    assert "particles lost" in line or "vrms" in line
    import json

    assert json.loads((run_dir / "summary.json").read_text())["reason"].startswith("failed at step")
    from convection.checkpoint import latest_checkpoint

    newest = latest_checkpoint(run_dir)
    assert newest is not None
    proc = _run(["resume", str(run_dir), "--set", "time.max_steps=6"])  # the last good checkpoint loads
    assert proc.returncode == 0, proc.stderr
