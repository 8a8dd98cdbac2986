"""The Stokes operator is assembled only when something asked for it (issue 34): once in a run with
a constant viscosity and a fixed mesh, at every solve where the viscosity varies, at every
nonlinear iteration; summary.json and the closing lines say how often."""

from __future__ import annotations

import json
from pathlib import Path

from mpi4py import MPI

from convection import load_config, run_config

ROOT = Path(__file__).resolve().parents[3]


def _run(config: str, out: Path, overrides: list[str]) -> dict:
    document = load_config(ROOT / "configs" / config, [*overrides, "output.progress=none", "output.fields_every=0",
                                                        f"output.directory={out}"])
    run_config(document, comm=MPI.COMM_SELF)
    return json.loads((out / "summary.json").read_text())


def test_constant_viscosity_assembles_once(tmp_path):
    summary = _run("vankeken_1a.yaml", tmp_path / "vk", ["mesh.cells=[16,16]", "time.max_steps=5"])
    assert summary["steps"] == 5 and summary["stokes_assemblies"] == 1  # 6 solves, 1 operator


def test_variable_viscosity_assembles_every_solve(tmp_path):
    summary = _run("sinking_block.yaml", tmp_path / "block", ["mesh.cells=[8,8]", "time.max_steps=3",
                                                               "particles.generator.particles_per_cell=4"])
    assert summary["steps"] == 3 and summary["stokes_assemblies"] == 4  # the initial solve and one per step
