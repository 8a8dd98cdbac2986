"""Starting a run from another run's temperature (``initial.from_run``, ``run --initial-from``):
copied on the same mesh, interpolated onto another mesh, the same on 1 and 2 ranks, and refused by
``check`` (exit 2, one line naming the key) when the source is missing or another domain.

The source is a small Blankenbach 1a run (8 x 8, a few steps) on one rank; the continuations stop
at step 0 (their checkpoint holds the initial temperature) or after two steps.
"""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest
from mpi4py import MPI

from _runs import CONFIGS, rows, run_cli, sets

import dolfinx.fem
import dolfinx.geometry
import dolfinx.mesh

from convection.io.checkpoint import latest_checkpoint
from fembase.dolfinx_compat import bounding_box_tree, compute_collisions, function_space

CONFIG = CONFIGS / "blankenbach_1a.yaml"
QUIET = ["output.progress=none", "output.fields_every=0", "time.steady_state_tolerance=null"]


def _temperature(run_dir: Path) -> tuple[np.ndarray, np.ndarray]:
    """The temperature of a run's newest checkpoint: dof coordinates and values, sorted by coordinates."""
    with h5py.File(latest_checkpoint(run_dir) / "state.h5", "r") as f:
        coords, values = f["functions/temperature/T/coords"][...], f["functions/temperature/T/values"][...].reshape(-1)
    order = np.lexsort(np.round(coords[:, ::-1], 12).T)
    return coords[order], values[order]


def _continue(source: Path, out: Path, cells: int, ranks: int = 1, steps: int = 0):
    proc = run_cli(["run", str(CONFIG), "--output", str(out), "--initial-from", str(source),
                    *sets([*QUIET, f"mesh.cells=[{cells},{cells}]", f"time.max_steps={steps}"])], ranks)
    assert proc.returncode == 0, proc.stderr
    return proc


@pytest.fixture(scope="module")
def source(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("source")
    proc = run_cli(["run", str(CONFIG), "--output", str(out), *sets([*QUIET, "mesh.cells=[8,8]", "time.max_steps=5"])])
    assert proc.returncode == 0, proc.stderr
    return out


def test_same_mesh_copies_the_temperature_exactly(source, tmp_path):
    _continue(source, tmp_path / "same", 8)
    coords, values = _temperature(source)
    again, continued = _temperature(tmp_path / "same")
    assert np.array_equal(coords, again)
    assert np.array_equal(values, continued)
    assert rows(tmp_path / "same")[0]["time"] == "0.0"


def test_finer_mesh_gets_the_interpolant(source, tmp_path):
    _continue(source, tmp_path / "fine", 12)
    coords, continued = _temperature(tmp_path / "fine")
    # the source's P2 temperature rebuilt here, evaluated at the new nodes with DOLFINx's own search
    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_SELF, 8, 8)
    T = dolfinx.fem.Function(function_space(mesh, "Lagrange", 2))
    saved_coords, saved = _temperature(source)
    local = T.function_space.tabulate_dof_coordinates()
    index = np.argmin(np.linalg.norm(local[:, None, :] - saved_coords[None, :, :], axis=2), axis=1)
    T.x.array[:] = saved[index]
    points = np.zeros((coords.shape[0], 3))
    points[:, : coords.shape[1]] = coords
    candidates = compute_collisions(bounding_box_tree(mesh, 2), points)
    cells = dolfinx.geometry.compute_colliding_cells(mesh, candidates, points)
    first = np.array([cells.links(i)[0] for i in range(points.shape[0])], dtype=np.int32)
    expected = T.eval(points, first).reshape(-1)
    assert np.max(np.abs(continued - expected)) < 1e-12
    assert not np.array_equal(coords.shape, saved_coords.shape)  # another mesh indeed


def test_two_ranks_continue_as_one(source, tmp_path):
    _continue(source, tmp_path / "one", 12, ranks=1, steps=2)
    _continue(source, tmp_path / "two", 12, ranks=2, steps=2)
    one, two = rows(tmp_path / "one"), rows(tmp_path / "two")
    assert len(one) == len(two) == 3
    # the initial temperature: the same interpolant on both (its mean to round-off)
    assert float(one[0]["T_mean"]) == pytest.approx(float(two[0]["T_mean"]), rel=1e-13)
    # after two steps: the solvers' round-off on 1 and 2 ranks (1a on 1 and 2 ranks: 4e-10 in Nu)
    for a, b in zip(one, two):
        for key in ("time", "vrms", "nusselt", "T_mean"):
            assert float(a[key]) == pytest.approx(float(b[key]), rel=1e-9, abs=1e-14), key
    _, first = _temperature(tmp_path / "one")
    _, second = _temperature(tmp_path / "two")
    assert np.max(np.abs(first - second)) < 1e-9


def test_check_refuses_a_missing_or_other_source(source, tmp_path):
    missing = run_cli(["check", str(CONFIG), "--initial-from", str(tmp_path / "nothing")])
    assert missing.returncode == 2
    assert missing.stderr.strip().count("\n") == 0 and "'initial.from_run'" in missing.stderr
    other = run_cli(["check", str(CONFIGS / "blankenbach_2b.yaml"), "--initial-from", str(source)])
    assert other.returncode == 2 and "'initial.from_run'" in other.stderr and "mesh.upper" in other.stderr
    fine = run_cli(["check", str(CONFIGS / "blankenbach_2a.yaml"), *sets([f"initial.from_run={source}"])])
    assert fine.returncode == 0, fine.stderr
