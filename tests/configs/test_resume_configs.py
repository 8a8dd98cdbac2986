"""Every shipped config that adapts or balances: killed (SIGKILL, between steps or in the middle of
a checkpoint write) and resumed on the rank count it ran on, its statistics equal to an
uninterrupted run's in every column but wall_time, to the last digit.

The configs are shrunk to a CI size (a coarser base mesh, fewer particles per cell, adaptation every
few steps, a few dozen steps) and keep everything else as shipped: the partitioner, the Stokes
solver (MUMPS in 2D), the composition source, the particle generator, integrator, interpolator,
population bounds and properties. A slow-marked test does the README's default job at its shipped
size; the two resume paths that are not bit for bit (a checkpoint whose mesh cannot be made again
exactly, and one written by an older version) continue with a one-line note.
"""

from __future__ import annotations

import random
from pathlib import Path

import h5py
import numpy as np
import pytest
import yaml

from _runs import CONFIGS, assert_same_statistics, final_particles, kill_run, rows, rows_written, run_cli, sets, \
    shrink, writing_checkpoint

from convection.io.checkpoint import latest_checkpoint, list_checkpoints

STEPS = 16


def _resumable_configs() -> list[str]:
    """The shipped configs that adapt or balance (read from the files, so a new one is tested too)."""
    names = []
    for path in sorted(CONFIGS.glob("*.yaml")):
        raw = yaml.safe_load(path.read_text())
        if (raw.get("adaptivity") or {}).get("enabled") or (raw.get("balance") or {}).get("strategy", "none") != "none":
            names.append(path.stem)
    return names


CONFIG_NAMES = _resumable_configs()


def _small(name: str) -> list[str]:
    """Overrides that shrink a shipped config to a CI size and keep its features (a box: a third of
    the cells per direction; a shell: 1.8 times coarser, about 6 times fewer cells in 3D)."""
    raw = yaml.safe_load((CONFIGS / f"{name}.yaml").read_text())
    return [*shrink(CONFIGS / f"{name}.yaml", divisor=3, coarsen=1.8, max_particles=3000, max_per_cell=8),
            f"adaptivity.every={min(4, raw['adaptivity'].get('every', 10))}",
            f"time.max_steps={STEPS}", "output.progress=none", "output.fields_every=5"]


def test_every_adapting_config_is_covered():
    assert {"vankeken_1a", "vankeken_1b", "vankeken_1c", "vankeken_1a_particles", "rayleigh_taylor_3",
            "vankeken_case2", "demo"} <= set(CONFIG_NAMES)


@pytest.mark.parametrize("ranks", [1, 2])
@pytest.mark.parametrize("name", CONFIG_NAMES)
def test_killed_config_resumes_bit_for_bit(tmp_path, name, ranks):
    config = CONFIGS / f"{name}.yaml"
    # Between steps on one rank count, in the middle of a checkpoint write on the other, alternating
    # over the configs so that both happen on both rank counts.
    mid_write = (CONFIG_NAMES.index(name) + ranks) % 2 == 0
    extra = [*_small(name), f"output.checkpoint.every_steps={1 if mid_write else 3}"]
    reference = tmp_path / "reference"
    proc = run_cli(["run", str(config), "--output", str(reference), *sets(extra)], ranks)
    assert proc.returncode == 0, proc.stderr
    total = len(rows(reference))
    killed = tmp_path / "killed"
    if mid_write:
        code = kill_run(config, killed, ranks, extra, when=lambda d: rows_written(d, 4) and writing_checkpoint(d))
    else:
        # rows 0..4 written: the checkpoint of step 3 is complete (it is written before step 4)
        stop_after = random.Random().randint(5, total - 2)
        code = kill_run(config, killed, ranks, extra, when=lambda d: rows_written(d, stop_after))
    assert code != 0, "the run ended before it was killed"
    assert latest_checkpoint(killed) is not None
    proc = run_cli(["resume", str(killed)], ranks)
    assert proc.returncode == 0, proc.stderr
    assert "note:" not in proc.stderr, proc.stderr  # the exact path, not the fallback
    assert_same_statistics(reference, killed)
    parts = sorted(p.stem for p in latest_checkpoint(reference).glob("particles*.h5"))  # one per particle system
    assert parts == sorted(p.stem for p in latest_checkpoint(killed).glob("particles*.h5"))
    for part in parts:
        for a, b in zip(final_particles(reference, part), final_particles(killed, part)):
            assert np.array_equal(a, b)


def _resumed_from_first(tmp_path: Path, ranks: int, damage) -> tuple[Path, Path, str]:
    """A reference run and a copy resumed from its first checkpoint after ``damage(state.h5)``."""
    config = CONFIGS / "vankeken_1a.yaml"
    extra = [*_small("vankeken_1a"), "output.checkpoint.every_steps=8", "output.checkpoint.keep=5"]
    reference = tmp_path / "reference"
    assert run_cli(["run", str(config), "--output", str(reference), *sets(extra)], ranks).returncode == 0
    first = list_checkpoints(reference)[0]
    with h5py.File(first / "state.h5", "a") as f:
        damage(f)
    proc = run_cli(["resume", str(reference), "--checkpoint", str(first)], ranks)
    assert proc.returncode == 0, proc.stderr
    return reference, first, proc.stderr


@pytest.mark.parametrize("ranks", [1, 2])
def test_mesh_that_cannot_be_made_again_continues_by_coordinates(tmp_path, ranks):
    """A checkpoint whose saved fingerprint does not match the mesh made again (here: altered)
    continues as on another rank count, with one line that says so."""
    def alter(f):
        fingerprints = f["mesh/fingerprints/mesh"]
        fingerprints[0] = 255 - fingerprints[0]

    config = CONFIGS / "vankeken_1a.yaml"
    reference, first, stderr = _resumed_from_first(tmp_path, ranks, alter)
    notes = [line for line in stderr.splitlines() if line.startswith("note:")]
    assert len(notes) == 1 and "could not be made again" in notes[0] and "round-off" in notes[0], stderr
    straight = tmp_path / "straight"
    extra = [*_small("vankeken_1a"), "output.checkpoint.every_steps=8"]
    assert run_cli(["run", str(config), "--output", str(straight), *sets(extra)], ranks).returncode == 0
    a, b = rows(straight), rows(reference)
    assert [r["step"] for r in a] == [r["step"] for r in b]
    assert [r["n_particles"] for r in a] == [r["n_particles"] for r in b]
    assert float(b[-1]["vrms"]) == pytest.approx(float(a[-1]["vrms"]), rel=1e-9)


def test_checkpoint_of_an_older_version_continues_by_coordinates(tmp_path):
    """Written before fingerprints were saved (format version 2): resumed, with a one-line note."""
    def as_version_2(f):
        del f["mesh/fingerprints"]
        del f["mesh/created_owners"]
        f.attrs["version"] = 2

    _, _, stderr = _resumed_from_first(tmp_path, 2, as_version_2)
    notes = [line for line in stderr.splitlines() if line.startswith("note:")]
    assert len(notes) == 1 and "older version" in notes[0], stderr


@pytest.mark.slow
def test_default_job_killed_and_resumed_at_shipped_size(tmp_path):
    """The README's default job (vK 1a to t = 300 on 2 ranks, checkpoints every 10 steps), SIGKILLed
    after ~150 steps and resumed: statistics equal to an uninterrupted run's to the last digit."""
    config = CONFIGS / "vankeken_1a.yaml"
    extra = ["time.end=300", "output.checkpoint.every_steps=10", "output.checkpoint.keep=100", "output.progress=none",
             "output.fields_every=10", "particles.output.every_time=100", "particles.output.properties=[composition]"]
    reference = tmp_path / "reference"
    assert run_cli(["run", str(config), "--output", str(reference), *sets(extra)], 2, budget=900).returncode == 0
    killed = tmp_path / "killed"
    assert kill_run(config, killed, 2, extra, when=lambda d: rows_written(d, 150), budget=900) != 0
    proc = run_cli(["resume", str(killed)], 2, budget=900)
    assert proc.returncode == 0 and "note:" not in proc.stderr, proc.stderr
    assert_same_statistics(reference, killed)
    for a, b in zip(final_particles(reference), final_particles(killed)):
        assert np.array_equal(a, b)
