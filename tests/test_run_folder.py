"""Run folders against hostile use: one run at a time, only the checkpoints the writer made, a
checkpoint's parts proven to belong together, statistics.csv with complete rows only.

CLI cases run a small van Keken 1a in subprocesses (``mpirun -n 2`` where it says so), killed with
SIGKILL of the process group as in tests/test_resume.py.
"""

from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from mpi4py import MPI

from convection.checkpoint import latest_checkpoint, list_checkpoints
from convection.plot import read_statistics
from convection.statistics import StatisticsFileError, StatisticsWriter, read_table

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / "configs" / "vankeken_1a.yaml"
SMALL = ["mesh.cells=[8,8]", "adaptivity.max_level=1", "output.progress=none"]
ENDLESS = ["time.end=1e9", "time.dt_max=1", "time.max_steps=1000000", "output.checkpoint.every_steps=3"]


def _command(args: list[str], ranks: int = 1) -> list[str]:
    cmd = [sys.executable, "-m", "convection", *args]
    if ranks > 1:
        cmd = [shutil.which("mpirun"), "-n", str(ranks), "--oversubscribe", *cmd]
    return cmd


def _env() -> dict[str, str]:
    return dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")


def _run(args: list[str], ranks: int = 1) -> subprocess.CompletedProcess:
    return subprocess.run(_command(args, ranks), cwd=ROOT, env=_env(), capture_output=True, text=True, timeout=300)


def _sets(items: list[str]) -> list[str]:
    return [a for item in items for a in ("--set", item)]


def _new_run(run_dir: Path, *extra: str) -> None:
    proc = _run(["run", str(CONFIG), "--output", str(run_dir), *_sets([*SMALL, *extra])])
    assert proc.returncode == 0, proc.stderr


def _error_line(proc: subprocess.CompletedProcess, code: int) -> str:
    lines = [ln for ln in proc.stderr.splitlines() if ln.startswith("error")]
    assert proc.returncode == code, proc.stderr
    assert len(lines) == 1 and "Traceback" not in proc.stderr and "MPI_ABORT" not in proc.stderr, proc.stderr
    return lines[0]


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
