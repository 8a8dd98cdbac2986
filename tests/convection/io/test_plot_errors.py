"""``python -m convection.plot`` on missing or damaged run files: one line ``error: ...`` naming
what is wrong, exit code 1, nothing from VTK, libxml2 or HDF5 on the way; partial runs are drawn.

One small van Keken 1a run (CLI subprocess, two meshes, fields and particles every 2 steps) is
copied for every case and damaged there.
"""

from __future__ import annotations

import os
import shutil
import sys
from pathlib import Path

import pytest

from convection.io.pictures import main

from _runs import guarded_run

ROOT = Path(__file__).resolve().parents[3]
CONFIG = ROOT / "configs" / "vankeken_1a.yaml"
NOISE = ("Traceback", "HDF5-DIAG", "parser error", "ERR|", "XDMF Error")


@pytest.fixture(scope="module")
def good_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    run_dir = tmp_path_factory.mktemp("plot") / "run"
    sets = ["mesh.cells=[8,8]", "adaptivity.max_level=1", "adaptivity.every=2", "output.progress=none",
            "time.max_steps=4", "output.fields_every=2", "particles.output.every_steps=2"]
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    proc = guarded_run([sys.executable, "-m", "convection", "run", str(CONFIG), "--output", str(run_dir),
                        *[a for s in sets for a in ("--set", s)]], cwd=ROOT, env=env, budget=300)
    assert proc.returncode == 0, proc.stderr
    assert (run_dir / "fields_001.h5").is_file() and (run_dir / "particles_000004.h5").is_file()
    return run_dir


def _truncate(path: Path, keep: float = 0.5) -> None:
    data = path.read_bytes()
    path.write_bytes(data[: int(len(data) * keep)])


def _nul_rows(path: Path) -> None:
    lines = path.read_bytes().splitlines(keepends=True)
    path.write_bytes(b"".join(lines[:2]) + b"\0" * 40 + b"".join(lines[3:]))


# case -> (how the copy is damaged, the needle of the error line, relative to the copy)
CASES = {
    "missing folder": (lambda d: shutil.rmtree(d), "run folder '{d}' not found"),
    "empty folder": (lambda d: [shutil.rmtree(d), d.mkdir()], "run folder '{d}' is empty"),
    "a file": (lambda d: [shutil.rmtree(d), d.write_text("x")], "'{d}' is not a run folder"),
    "no statistics.csv": (lambda d: (d / "statistics.csv").unlink(), "run folder '{d}' has no statistics.csv"),
    "damaged statistics.csv": (lambda d: _nul_rows(d / "statistics.csv"),
                               "{d}/statistics.csv: line 3 is damaged (NUL bytes"),
    "damaged fields.xdmf": (lambda d: _truncate(d / "fields.xdmf"), "{d}/fields.xdmf: damaged XDMF"),
    "missing fields.xdmf": (lambda d: (d / "fields.xdmf").unlink(), "{d}/fields.xdmf is missing"),
    "missing fields_001.h5": (lambda d: (d / "fields_001.h5").unlink(),
                              "{d}/fields_001.h5 is missing (fields.xdmf refers to it)"),
    "damaged fields_001.h5": (lambda d: _truncate(d / "fields_001.h5"), "{d}/fields_001.h5: damaged HDF5 file"),
    "damaged particles.xdmf": (lambda d: _truncate(d / "particles.xdmf"), "{d}/particles.xdmf: damaged XDMF"),
    "missing particles_000004.h5": (lambda d: (d / "particles_000004.h5").unlink(),
                                    "{d}/particles_000004.h5 is missing (particles.xdmf refers to it)"),
}


@pytest.mark.parametrize("case", list(CASES))
def test_a_bad_run_folder_is_one_error_line(good_run, tmp_path, capfd, case):
    damage, needle = CASES[case]
    copy = tmp_path / "run"
    shutil.copytree(good_run, copy)
    damage(copy)
    assert main([str(copy)]) == 1
    err = capfd.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.startswith("error")]
    assert len(lines) == 1 and needle.format(d=copy) in lines[0], err
    assert not any(word in err for word in NOISE), err


def test_a_run_without_fields_draws_its_curves(good_run, tmp_path, capfd):
    copy = tmp_path / "run"
    shutil.copytree(good_run, copy)
    for path in [*copy.glob("fields*"), *copy.glob("particles*")]:
        path.unlink()
    assert main([str(copy)]) == 0
    out, err = capfd.readouterr()
    assert out.splitlines() == [str(copy / "summary.png"), f"{copy}: no field output (fields.xdmf, fields_NNN.h5): "
                                                           "summary without the temperature, no snapshots"]
    assert (copy / "summary.png").stat().st_size > 10_000 and "error" not in err


def test_a_cut_off_last_statistics_line_is_left_out(good_run, tmp_path, capfd):
    copy = tmp_path / "run"
    shutil.copytree(good_run, copy)
    with open(copy / "statistics.csv", "a") as f:
        f.write("5,21")
    assert main([str(copy), "--times", "0"]) == 0
    out, err = capfd.readouterr()
    assert f"{copy}/statistics.csv: its last line was cut off (the run was stopped while writing it); left out" in out
    assert (copy / "summary.png").is_file() and "error" not in err
