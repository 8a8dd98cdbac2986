"""configs/vankeken_1a_tracers.yaml (two particle systems: a dense one carrying the composition,
500 passive tracers written every step with their initial position) at CI size (12 x 12 cells,
one adaptation, 13 steps):

- the composition's run is configs/vankeken_1a.yaml's to the last digit (statistics, the dense
  system's particles);
- with a flow that does not depend on the particles (the composition as an advected field) the
  tracers are those of a run that carries only them, bit for bit;
- killed on 2 ranks and resumed, bit for bit (both systems; the tracers' per-step output);
- 1, 2 and 3 ranks agree.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest
import yaml

from convection.io.checkpoint import latest_checkpoint
from _runs import CONFIGS, assert_same_statistics, final_particles, kill_run, rows, rows_written, run_cli, run_on_ranks

CONFIG = CONFIGS / "vankeken_1a_tracers.yaml"
COMMON = ["mesh.cells=[12,12]", "time.max_steps=13", "output.progress=none", "output.fields_every=100",
          "output.checkpoint.every_steps=4"]
SMALL = [*COMMON, "particles.dense.generator.particles_per_cell=8"]
TRACER_COLUMNS = ("n_particles", "n_lost", "n_added", "n_removed", "ppc_min", "ppc_mean", "ppc_max")


def _tracer_output(run_dir: Path) -> dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """The tracers written at every step: step -> (ids, positions, initial positions), sorted by id."""
    out = {}
    for path in sorted(run_dir.glob("particles_tracers_*.h5")):
        with h5py.File(path, "r") as f:
            order = np.argsort(f["ids"][...])
            out[int(f.attrs["step"])] = (f["ids"][...][order], f["positions"][...][order],
                                         f["properties/initial_position"][...][order])
    return out


def _assert_same_tracers(a: Path, b: Path) -> None:
    ta, tb = _tracer_output(a), _tracer_output(b)
    assert sorted(ta) == sorted(tb) == list(range(len(ta))) and len(ta) > 10  # every step written
    for step in ta:
        for x, y in zip(ta[step], tb[step]):
            np.testing.assert_array_equal(x, y, err_msg=f"step {step}")
    assert len(ta[0][0]) == 500


def test_the_composition_is_the_one_system_runs(tmp_path):
    """The two-system run's statistics, but for the tracers' columns and the load (which counts all
    particles), and its dense particles are vankeken_1a.yaml's to the last digit (2 ranks)."""
    one = run_on_ranks(CONFIGS / "vankeken_1a.yaml", {2: tmp_path / "one"},
                       [*COMMON, "particles.generator.particles_per_cell=8"])[2]
    two = run_on_ranks(CONFIG, {2: tmp_path / "two"}, SMALL)[2]
    a, b = rows(one), rows(two)
    assert len(a) == len(b) == 14
    assert list(b[0]) == [*a[0]][:16] + [f"{c}_tracers" for c in TRACER_COLUMNS] + [*a[0]][16:]
    for x, y in zip(a, b):  # the load's particle imbalance counts every system's particles
        assert all(x[key] == y[key] for key in x if key not in ("wall_time", "particle_imbalance")), x["step"]
    assert int(a[-1]["cells"]) != int(a[0]["cells"])  # it adapted
    assert all(int(r["n_particles_tracers"]) == 500 and int(r["n_lost_tracers"]) == 0 for r in b)
    for x, y in zip(final_particles(one), final_particles(two, "particles_dense")):
        np.testing.assert_array_equal(x, y)
    assert not (two / "particles.xdmf").exists() and (two / "particles_tracers.xdmf").exists()


def _config_with(tmp_path: Path, name: str, systems: list[str]) -> Path:
    """The config with the composition as an advected field and only the named particle systems."""
    document = yaml.safe_load(CONFIG.read_text())
    document["composition"] = {"source": "field", "degree": 1}
    document["particles"] = [s for s in document["particles"] if s["name"] in systems]
    path = tmp_path / f"{name}.yaml"
    path.write_text(yaml.safe_dump(document))
    return path


def test_the_tracers_are_a_tracer_only_runs(tmp_path):
    """With a flow independent of the particles, the tracers beside the dense system are those of a
    run that carries only them, at every step, bit for bit (2 ranks)."""
    alone = run_on_ranks(_config_with(tmp_path, "alone", ["tracers"]), {2: tmp_path / "alone"}, COMMON)[2]
    beside = run_on_ranks(_config_with(tmp_path, "beside", ["dense", "tracers"]), {2: tmp_path / "beside"},
                          SMALL)[2]
    _assert_same_tracers(alone, beside)
    a, b = rows(alone), rows(beside)
    assert [r["vrms"] for r in a] == [r["vrms"] for r in b]
    assert [r[c] for r in a for c in TRACER_COLUMNS] == [r[f"{c}_tracers"] for r in b for c in TRACER_COLUMNS]


def test_killed_and_resumed_bit_for_bit(tmp_path):
    """On 2 ranks, SIGKILLed after 10 statistics rows (checkpoints every 4 steps), resumed: the
    statistics, both systems' final particles and the tracers written at every step are the
    uninterrupted run's (the dense system writes no output and still restarts)."""
    reference = run_on_ranks(CONFIG, {2: tmp_path / "reference"}, SMALL)[2]
    killed = tmp_path / "killed"
    code = kill_run(CONFIG, killed, 2, SMALL, when=lambda d: rows_written(d, 10))
    assert code != 0, "the run ended before it was killed"
    assert latest_checkpoint(killed) is not None and len(rows(killed)) < 14
    proc = run_cli(["resume", str(killed)], 2)
    assert proc.returncode == 0, proc.stderr
    assert_same_statistics(reference, killed)
    for part in ("particles_dense", "particles_tracers"):
        for x, y in zip(final_particles(reference, part), final_particles(killed, part)):
            np.testing.assert_array_equal(x, y)
    _assert_same_tracers(reference, killed)


def test_one_two_three_ranks_agree(tmp_path):
    """The same cells and particle counts every step on 1, 2 and 3 ranks, vrms to 1e-8, the tracers
    (positions at every step) to 1e-9."""
    folders = run_on_ranks(CONFIG, {r: tmp_path / f"ranks{r}" for r in (1, 2, 3)}, SMALL)
    table = {r: rows(folder) for r, folder in folders.items()}
    counts = ("cells", "n_particles", "n_particles_tracers", "n_lost", "n_lost_tracers", "ppc_max_tracers")
    for r in (2, 3):
        assert [[x[c] for c in counts] for x in table[r]] == [[x[c] for c in counts] for x in table[1]]
        assert [float(x["vrms"]) for x in table[r]] == pytest.approx([float(x["vrms"]) for x in table[1]], rel=1e-8)
        serial, parallel = _tracer_output(folders[1]), _tracer_output(folders[r])
        assert sorted(serial) == sorted(parallel)
        for step in serial:
            np.testing.assert_array_equal(serial[step][0], parallel[step][0])
            np.testing.assert_allclose(parallel[step][1], serial[step][1], rtol=0, atol=1e-9)
            np.testing.assert_array_equal(serial[step][2], parallel[step][2])  # where they started: exact
    shutil.rmtree(tmp_path)
