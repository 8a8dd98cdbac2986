"""Run folders against hostile use: one run at a time, only the checkpoints the writer made, a
checkpoint's parts proven to belong together, statistics.csv with complete rows only.

CLI cases run a small van Keken 1a in subprocesses (``mpirun -n 2`` where it says so), killed with
SIGKILL of the process group as in tests/convection/app/test_resume.py.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import time
from pathlib import Path

import h5py
import pytest
from mpi4py import MPI

from _runs import command as _command
from _runs import env as _env
from _runs import error_line as _error_line
from _runs import kill_session
from _runs import run_cli as _run
from _runs import sets as _sets

from convection.io.checkpoint import CheckpointError, latest_checkpoint, list_checkpoints, read_checkpoint
from convection.io.pictures import read_statistics
from convection.io.run_folder import LOCK_NAME, RunFolderError, RunFolderLock
from convection.io.statistics import StatisticsFileError, StatisticsWriter, read_table

ROOT = Path(__file__).resolve().parents[3]
CONFIG = ROOT / "configs" / "vankeken_1a.yaml"
SMALL = ["mesh.cells=[8,8]", "adaptivity.max_level=1", "output.progress=none"]
ENDLESS = ["time.end=1e9", "time.dt_max=1", "time.max_steps=1000000", "output.checkpoint.every_steps=3"]


def _new_run(run_dir: Path, *extra: str) -> None:
    proc = _run(["run", str(CONFIG), "--output", str(run_dir), *_sets([*SMALL, *extra])])
    assert proc.returncode == 0, proc.stderr


# ---------------------------------------------------------------------- statistics rows
def _writer_file(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def test_resume_drops_later_rows_and_a_cut_off_line(tmp_path):
    path = _writer_file(tmp_path / "statistics.csv", "step,time\r\n0,0.0\r\n1,0.5\r\n2,1.0\r\n1")
    writer = StatisticsWriter(path, ["step", "time"], comm=MPI.COMM_SELF, resume_after_step=1)
    assert writer.dropped_incomplete
    writer.write({"step": 2, "time": 0.75})
    writer.close()
    assert path.read_bytes() == b"step,time\r\n0,0.0\r\n1,0.5\r\n2,0.75\r\n"
    assert read_table(path).incomplete is False


@pytest.mark.parametrize("text, needle", [
    ("step,time\n0,0.0\n\0\0\0,1\n", "line 3 is damaged (NUL bytes"),
    ("step,time\n0,0.0\n1,0.5,7\n", "line 3 is damaged (3 fields, the header has 2)"),
    ("step,time\n0,zero\n", "line 2 is damaged ('zero' is not a number)"),
    ("", "no header line"),
    ("step,vrms\n0,0.0\n", "its columns differ"),
])
def test_damaged_statistics_are_one_line(tmp_path, text, needle):
    path = _writer_file(tmp_path / "statistics.csv", text)
    with pytest.raises(StatisticsFileError) as err:
        StatisticsWriter(path, ["step", "time"], comm=MPI.COMM_SELF, resume_after_step=5)
    assert needle in str(err.value) and str(path) in str(err.value) and "\n" not in str(err.value)
    assert path.read_text() == text  # left as it was


@pytest.mark.mpi
def test_damaged_statistics_raise_on_every_rank(tmp_path):
    comm = MPI.COMM_WORLD
    path = Path(comm.bcast(str(tmp_path / "statistics.csv"), root=0))
    if comm.rank == 0:
        path.write_text("step,time\n0,0.0\n\0\0,1\n")
    try:
        StatisticsWriter(path, ["step", "time"], comm=comm, resume_after_step=5)
        raised = False
    except StatisticsFileError:
        raised = True
    assert comm.allreduce(int(raised)) == comm.size


# ---------------------------------------------------------------------- the lock
def test_lock_refuses_a_second_holder_and_is_free_after_release(tmp_path):
    folder = tmp_path / "a" / "run"
    with RunFolderLock(folder, MPI.COMM_SELF) as lock:
        assert lock.held and folder.is_dir()
        assert (folder / LOCK_NAME).read_text() == f"pid {os.getpid()} on {os.uname().nodename}\n"
        message = f"run folder '{folder}' is in use by another run (pid {os.getpid()} "
        with pytest.raises(RunFolderError, match=re.escape(message)):
            RunFolderLock(folder, MPI.COMM_SELF).__enter__()
    with RunFolderLock(folder, MPI.COMM_SELF):  # released: free again
        pass
    (tmp_path / "file").write_text("")
    with pytest.raises(RunFolderError, match="cannot be created"):
        RunFolderLock(tmp_path / "file", MPI.COMM_SELF).__enter__()


@pytest.mark.mpi
def test_lock_decision_is_the_same_on_every_rank(tmp_path):
    comm = MPI.COMM_WORLD
    folder = Path(comm.bcast(str(tmp_path / "run"), root=0))
    with RunFolderLock(folder, comm) as lock:
        assert comm.allreduce(int(lock.held)) == 1  # rank 0 only
        try:
            RunFolderLock(folder, comm).__enter__()
            refused = False
        except RunFolderError as err:
            refused = f"'{folder}' is in use" in str(err)
        assert comm.allreduce(int(refused)) == comm.size


def _start(run_dir: Path, ranks: int, extra: list[str]) -> subprocess.Popen:
    return subprocess.Popen(_command(["run", str(CONFIG), "--output", str(run_dir), *_sets([*SMALL, *extra])], ranks),
                            cwd=ROOT, env=_env(), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True)


def _wait_for(proc: subprocess.Popen, ready, timeout: float = 120.0) -> None:
    deadline = time.monotonic() + timeout
    while not ready():
        assert proc.poll() is None, "the run ended early"
        assert time.monotonic() < deadline, "the run did not get going"
        time.sleep(0.05)


def test_a_second_run_or_resume_of_a_busy_folder_is_refused(tmp_path):
    """While a run goes on, another run and a 2-rank resume of its folder get one line naming the
    folder and the holder (exit 1) and write nothing; killed with SIGKILL, the run resumes."""
    run_dir = tmp_path / "run"
    proc = _start(run_dir, 1, ENDLESS)
    try:
        _wait_for(proc, lambda: latest_checkpoint(run_dir) is not None)
        before = (run_dir / "config.yaml").read_text()
        line = _error_line(_run(["run", str(CONFIG), "--output", str(run_dir),
                                 *_sets([*SMALL, "time.max_steps=2"])]), 1)
        assert line == f"error: run folder '{run_dir}' is in use by another run (pid {proc.pid} on " \
                       f"{os.uname().nodename}); wait for it to end or use another folder"
        line = _error_line(_run(["resume", str(run_dir)], ranks=2), 1)
        assert f"'{run_dir}' is in use by another run (pid {proc.pid} " in line
        assert (run_dir / "config.yaml").read_text() == before
    finally:
        kill_session(proc.pid)
        proc.wait(timeout=60)
    table = read_table(run_dir / "statistics.csv")  # not damaged by the refused ones
    step = int(latest_checkpoint(run_dir).name.split("_")[1])
    proc = _run(["resume", str(run_dir), "--set", f"time.max_steps={step + 2}"])
    assert proc.returncode == 0, proc.stderr
    steps = read_statistics(run_dir / "statistics.csv")["step"].tolist()
    assert steps == list(range(step + 3)) and len(table.rows) >= step + 1


# ---------------------------------------------------------------------- a run killed mid-row
def test_a_run_killed_mid_row_resumes_with_complete_rows(tmp_path):
    """A last row cut off inside its step number ('1' of '13,...') would pass for step 1."""
    run_dir = tmp_path / "run"
    _new_run(run_dir, "time.max_steps=4", "output.checkpoint.every_steps=2", "output.checkpoint.keep=2")
    shutil.rmtree(run_dir / "checkpoints" / "checkpoint_000004")  # as if killed before it
    with open(run_dir / "statistics.csv", "a") as f:
        f.write("1")
    assert read_table(run_dir / "statistics.csv").incomplete
    proc = _run(["resume", str(run_dir), "--set", "time.max_steps=5", "--set", "output.progress=lines"], ranks=2)
    assert proc.returncode == 0, proc.stderr
    assert "statistics.csv: its last line was cut off when the run stopped; dropped" in proc.stdout
    table = read_table(run_dir / "statistics.csv")
    assert not table.incomplete and [int(r[0]) for r in table.rows] == [0, 1, 2, 3, 4, 5]
    assert all(len(r) == len(table.columns) for r in table.rows)


# ---------------------------------------------------------------------- checkpoint names
def test_listing_takes_only_the_writers_names(tmp_path):
    folder = tmp_path / "checkpoints"
    for name in ("checkpoint_000002", "checkpoint_000010", "checkpoint_000010.bak", "checkpoint_000011 copy",
                 "checkpoint_x", "checkpoint_000012", ".checkpoint_000013.abcd.tmp"):
        (folder / name).mkdir(parents=True)
        (folder / name / "state.h5").write_bytes(b"")
    (folder / "checkpoint_000012" / "state.h5").unlink()  # incomplete: no state.h5
    (folder / "checkpoint_000020").write_text("a file")
    assert [p.name for p in list_checkpoints(tmp_path)] == ["checkpoint_000002", "checkpoint_000010"]
    assert latest_checkpoint(tmp_path).name == "checkpoint_000010"
    assert list_checkpoints(tmp_path / "nowhere") == []


def test_resume_ignores_a_backup_copy_and_the_writer_keeps_it(tmp_path):
    run_dir = tmp_path / "run"
    _new_run(run_dir, "time.max_steps=2", "output.checkpoint.every_steps=1", "output.checkpoint.keep=1")
    backup = run_dir / "checkpoints" / "checkpoint_000001.bak"
    shutil.copytree(run_dir / "checkpoints" / "checkpoint_000002", backup)
    proc = _run(["resume", str(run_dir), "--set", "time.max_steps=4"])
    assert proc.returncode == 0, proc.stderr
    assert sorted(p.name for p in (run_dir / "checkpoints").iterdir()) == ["checkpoint_000001.bak", "checkpoint_000004"]


# ---------------------------------------------------------------------- a checkpoint's parts
def test_a_part_from_another_run_or_checkpoint_is_refused(tmp_path):
    run_dir, other = tmp_path / "run", tmp_path / "other"
    _new_run(run_dir, "time.max_steps=2", "output.checkpoint.every_steps=1")
    _new_run(other, "time.max_steps=2", "particles.generator.particles_per_cell=5")
    newest = run_dir / "checkpoints" / "checkpoint_000002"
    original = (newest / "particles.h5").read_bytes()
    shutil.copy(newest / "state.h5", tmp_path / "state.h5")
    for source, ranks in ((other / "checkpoints" / "checkpoint_000002", (1, 2)),
                          (run_dir / "checkpoints" / "checkpoint_000001", (1,))):
        shutil.copy(source / "particles.h5", newest / "particles.h5")
        for n in ranks:
            line = _error_line(_run(["resume", str(run_dir)], ranks=n), 1)
            assert line == f"error: checkpoint {newest}: particles.h5 does not belong to this checkpoint (its token " \
                           "differs from state.h5's: copied from another run or checkpoint?)"
    # a checkpoint written before the token: the steps of the parts must agree
    for path in (newest / "state.h5", newest / "particles.h5"):
        with h5py.File(path, "a") as f:
            del f.attrs["token"]
    with pytest.raises(CheckpointError, match="particles.h5 is of step 1, state.h5 of step 2"):
        read_checkpoint(newest, MPI.COMM_SELF)
    (newest / "particles.h5").write_bytes(original)
    with h5py.File(newest / "particles.h5", "a") as f:
        del f.attrs["token"]
    assert read_checkpoint(newest, MPI.COMM_SELF).path == newest
    (newest / "particles.h5").write_bytes(original)
    shutil.copy(tmp_path / "state.h5", newest / "state.h5")
    proc = _run(["resume", str(run_dir), "--set", "time.max_steps=3"])
    assert proc.returncode == 0, proc.stderr
