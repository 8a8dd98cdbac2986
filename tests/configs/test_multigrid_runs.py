"""Shipped configs with ``stokes.solver: multigrid`` at a CI size.

- The 3D thick layer (configs/thick_layer_3d.yaml; 8^3 cubes over 4^3 and 2^3, 2 particles per
  cell, 6 steps): the same run as with the AMG solver to the solver tolerance on 1 and 2 ranks
  (3: tests/convection/solvers/test_stokes_multigrid.py) (the same mesh: the multigrid levels only
  change its partition), and killed and resumed on 2 ranks, bit for bit (also with a preconditioner
  kept over the checkpoint's step).
- The same adapted every 3 steps (levels from the refinement rounds): the AMG run's to the solver
  tolerance on 1, 2 and 3 ranks, and killed and resumed on 2 ranks, bit for bit; also repartitioned
  every 2 steps on 3 ranks.
- van Keken 1a with particles, adapted and repartitioned: resumed on 2 ranks from a checkpoint
  that holds moved refinement rounds, bit for bit.
- The adaptive, repartitioned 3D shell (configs/shell_adaptive.yaml, curved levels): the AMG run's
  to the solver tolerance on 2 ranks, and resumed bit for bit.
- The fixed 3D shell with the multigrid (configs/shell_plates.yaml, levels by refinement): resumed
  on 2 ranks bit for bit.
- The viscoplastic Tosi et al. (2015) case (configs/tosi.yaml, 16x16 over 8x8, 4x4, 2x2), Newton
  and Picard: the same run as with the direct solver to the nonlinear tolerance."""

from __future__ import annotations

import shutil

import h5py
import pytest

from _runs import CONFIGS, assert_same_statistics, kill_run, rows, rows_written, run_cli, sets

from convection.io.checkpoint import latest_checkpoint
from convection.solvers.petsc_options import HAS_HYPRE
from fembase.dolfinx_compat import repartitioned_manifolds_nest

CONFIG = CONFIGS / "thick_layer_3d.yaml"
SMALL = ["mesh.cells=[8,8,8]", "particles.generator.particles_per_cell=2", "time.max_steps=6",
         "output.progress=none", "output.fields_every=0"]
AMG = "iterative" if HAS_HYPRE else "iterative_gamg"


def _run(tmp_path, name: str, solver: str, ranks: int, extra: list[str] = ()) -> list[dict[str, str]]:
    out = tmp_path / name
    proc = run_cli(["run", str(CONFIG), "--output", str(out), *sets([*SMALL, f"stokes.solver={solver}", *extra])],
                   ranks)
    assert proc.returncode == 0, proc.stderr
    return rows(out)


@pytest.mark.parametrize("ranks", [1, 2])
def test_multigrid_run_equals_the_amg_run(tmp_path, ranks):
    """vrms, Nusselt number and entrainment of every step agree to 1e-5 (both solvers stop at
    |b - K x| <= 1e-7 |b|); particles and cells are the same."""
    multigrid = _run(tmp_path, "multigrid", "multigrid", ranks)
    amg = _run(tmp_path, "amg", AMG, ranks)
    assert len(multigrid) == len(amg) == 7
    for a, b in zip(multigrid, amg):
        for key in ("cells", "n_particles", "n_lost"):
            assert a[key] == b[key], key
        for key in ("time", "vrms", "nusselt", "entrainment"):
            assert float(a[key]) == pytest.approx(float(b[key]), rel=1e-5, abs=1e-9), (key, a["step"])
        # Both grow over these steps with the step size: the AMG's preconditioner leaves the
        # semi-implicit buoyancy term out, the multigrid's has it (measured on 1 rank: 13 ... 17
        # and 27 ... 44; 20 ... 47 and 37 ... 53 while the block preconditioner lacked B^T).
        assert 0 < int(a["stokes_iterations"]) <= int(b["stokes_iterations"])


# The default lag of the preconditioner (its step grows 1.5x a step here: set up every solve), and
# one kept for 4 solves whatever the step (the checkpoints of steps 2 and 4 then hold a kept
# preconditioner, which the resumed run sets up from the saved fields: convection/solvers/stokes/lagged.py).
LAGS = {"default": [], "kept": ["stokes.multigrid.rebuild_steps=4", "stokes.multigrid.rebuild_dt_change=100"]}


@pytest.mark.parametrize("lag", sorted(LAGS))
def test_killed_multigrid_run_resumes_bit_for_bit(tmp_path, lag):
    _kill_and_resume(tmp_path, [*SMALL, "stokes.solver=multigrid", "output.checkpoint.every_steps=2", *LAGS[lag]], 4)


def _kill_and_resume(tmp_path, extra: list[str], rows: int) -> None:
    """The run with ``extra`` on 2 ranks, and the same killed after ``rows`` statistics rows and
    resumed from its last checkpoint: the same statistics."""
    reference = tmp_path / "reference"
    proc = run_cli(["run", str(CONFIG), "--output", str(reference), *sets(extra)], 2)
    assert proc.returncode == 0, proc.stderr
    killed = tmp_path / "killed"
    code = kill_run(CONFIG, killed, 2, extra, when=lambda d: rows_written(d, rows))
    assert code != 0, "the run ended before it was killed"
    assert latest_checkpoint(killed) is not None
    proc = run_cli(["resume", str(killed)], 2)
    assert proc.returncode == 0, proc.stderr
    assert "note:" not in proc.stderr, proc.stderr  # the mesh and its levels made again exactly
    assert_same_statistics(reference, killed)


ADAPTIVE = ["adaptivity.enabled=true", "adaptivity.every=3", "adaptivity.max_level=1",
            "adaptivity.fields=[composition]"]


@pytest.mark.parametrize("ranks", [1, 2, 3])
def test_adaptive_multigrid_run_equals_the_amg_run(tmp_path, ranks):
    """The thick layer adapted every 3 steps (the 8^3 base, the dense interface refined once): the
    multigrid takes the boxes below the base, the base and the refinement rounds as its levels
    (convection/adapt/levels.py), made again at every adaptation. The same cells as the AMG run,
    vrms and Nusselt number to 1e-5, fewer iterations (measured on 2 ranks: 12-13 against 31-38)."""
    multigrid = _run(tmp_path, "multigrid", "multigrid", ranks, ADAPTIVE)
    amg = _run(tmp_path, "amg", AMG, ranks, ADAPTIVE)
    assert len(multigrid) == len(amg) == 7
    assert int(multigrid[-1]["cells"]) > int(multigrid[0]["cells"]) > 6 * 8 ** 3  # adapted at the start and later
    for a, b in zip(multigrid, amg):
        assert a["cells"] == b["cells"] and a["n_lost"] == b["n_lost"] == "0"
        for key in ("vrms", "nusselt"):
            assert float(a[key]) == pytest.approx(float(b[key]), rel=1e-5), (key, a["step"])
        assert int(a["stokes_iterations"]) < int(b["stokes_iterations"])


def test_killed_adaptive_multigrid_run_resumes_bit_for_bit(tmp_path):
    """Killed after step 4 (adapted at step 3; 9 steps, so that it is killed before its end) and
    resumed from the checkpoint of step 4: the replayed mesh brings its refinement rounds back,
    the multigrid its levels."""
    _kill_and_resume(tmp_path, [*SMALL, "time.max_steps=9", "stokes.solver=multigrid",
                                "output.checkpoint.every_steps=2", *ADAPTIVE], 5)


def test_adaptive_multigrid_run_resumes_on_another_rank_count(tmp_path):
    """A 2-rank checkpoint of the adaptive run (step 4, after the adaptation of step 3) resumed on
    1 rank: the mesh is made again from the saved cells, not by the refinement rounds, so the base
    is its next level until the adaptation of step 6; the same cells, vrms to 1e-5."""
    extra = [*SMALL, "stokes.solver=multigrid", "output.checkpoint.every_steps=2", "output.checkpoint.keep=5",
             *ADAPTIVE]
    reference = tmp_path / "reference"
    proc = run_cli(["run", str(CONFIG), "--output", str(reference), *sets(extra)], 2)
    assert proc.returncode == 0, proc.stderr
    resumed = tmp_path / "resumed"
    shutil.copytree(reference, resumed)
    proc = run_cli(["resume", str(resumed), "--checkpoint", str(resumed / "checkpoints" / "checkpoint_000004")], 1)
    assert proc.returncode == 0, proc.stderr
    notes = [line for line in proc.stderr.splitlines() if line.startswith("note:")]
    assert len(notes) == 1 and "written on 2 ranks, resumed on 1" in notes[0], proc.stderr
    a, b = rows(reference), rows(resumed)
    assert len(a) == len(b) == 7
    for x, y in zip(a, b):
        assert x["cells"] == y["cells"], x["step"]
        assert float(x["vrms"]) == pytest.approx(float(y["vrms"]), rel=1e-5), x["step"]


BALANCED = [*ADAPTIVE, "balance.strategy=every", "balance.every=2"]


def test_balanced_adaptive_multigrid_run_equals_the_amg_run(tmp_path):
    """The adaptive thick layer repartitioned every 2 steps: the repartition moves the refinement
    rounds' meshes with the base (convection/adapt/hierarchy.py), the levels are the base and the
    rounds after it. The same cells and loads as the AMG run, vrms and Nusselt number to 1e-5,
    fewer iterations (measured on 2 ranks: 12-15 against 31-39). On 3 ranks (2 ranks: the
    balanced runs below)."""
    multigrid = _run(tmp_path, "multigrid", "multigrid", 3, BALANCED)
    amg = _run(tmp_path, "amg", AMG, 3, BALANCED)
    assert len(multigrid) == len(amg) == 7
    assert len({a["cell_imbalance"] for a in multigrid}) > 2  # repartitioned (and adapted)
    for a, b in zip(multigrid, amg):
        for key in ("cells", "n_lost", "cell_imbalance"):
            assert a[key] == b[key], (key, a["step"])
        for key in ("vrms", "nusselt"):
            assert float(a[key]) == pytest.approx(float(b[key]), rel=1e-5), (key, a["step"])
        assert int(a["stokes_iterations"]) < int(b["stokes_iterations"])


VK_PARTICLES = CONFIGS / "vankeken_1a_particles.yaml"


def test_balanced_multigrid_run_resumes_bit_for_bit(tmp_path):
    """van Keken 1a with particles on the adaptive mesh (24^2 base, two refinement rounds),
    adapted and repartitioned every 5 steps, with the multigrid, 30 steps: resumed from the
    checkpoint of step 6, which holds the rounds' meshes the repartition of step 5 moved
    (recipe/level_i; the boxes below the config's base do not nest in the saved base), the
    statistics are those of the uninterrupted run to the last digit. (A copy resumed from a
    middle checkpoint, not a killed run: the same restore, and a 2D run this short ends before a
    kill under load.) Before the fix the resume failed: the boxes were taken as levels of the
    repartitioned base."""
    extra = ["time.max_steps=30", "output.progress=none", "output.fields_every=0", "particles.output.every_time=1e9",
             "adaptivity.every=5", "balance.strategy=every", "balance.every=5", "output.checkpoint.every_steps=2",
             "output.checkpoint.keep=20", "stokes.solver=multigrid"]
    reference = tmp_path / "reference"
    proc = run_cli(["run", str(VK_PARTICLES), "--output", str(reference), *sets(extra)], 2)
    assert proc.returncode == 0, proc.stderr
    resumed = tmp_path / "resumed"
    shutil.copytree(reference, resumed)
    checkpoint = resumed / "checkpoints" / "checkpoint_000006"
    with h5py.File(checkpoint / "state.h5", "r") as f:
        assert "recipe/level_0" in f and "recipe/mesh" in f
    proc = run_cli(["resume", str(resumed), "--checkpoint", str(checkpoint)], 2)
    assert proc.returncode == 0, proc.stderr
    assert "note:" not in proc.stderr, proc.stderr
    assert_same_statistics(reference, resumed)
    assert len(rows(resumed)) == 31


SHELL = CONFIGS / "shell_adaptive.yaml"
SHELL_SMALL = ["mesh.resolution=0.8", "time.max_steps=6", "time.end=1e9", "output.fields_every=0",
               "output.progress=none", "particles.generator.num_particles=4000", "particles.output.every_steps=1000",
               "adaptivity.every=2", "adaptivity.initial_steps=1", "balance.every=2"]
if not repartitioned_manifolds_nest():  # the config check refuses the multigrid on a repartitioned shell
    SHELL_SMALL.append("balance.strategy=none")


def test_adaptive_shell_multigrid_run_equals_the_amg_run(tmp_path):
    """The adaptive, repartitioned 3D shell (configs/shell_adaptive.yaml at gmsh size 0.8, 2
    ranks): the levels are the curved meshes of the straight refinement rounds (or the curved
    base), nested through their straight cells (convection/adapt/levels.py). The same cells as
    the BoomerAMG run, vrms to 1e-5, fewer iterations (measured: 17-22 against 35-45); resumed
    from a checkpoint, bit for bit."""
    runs = {}
    for name, solver in (("multigrid", "multigrid"), ("amg", AMG)):
        out = tmp_path / name
        extra = [*SHELL_SMALL, f"stokes.solver={solver}", "output.checkpoint.every_steps=1",
                 "output.checkpoint.keep=10"]
        proc = run_cli(["run", str(SHELL), "--output", str(out), *sets(extra)], 2)
        assert proc.returncode == 0, proc.stderr
        runs[name] = rows(out)
    multigrid, amg = runs["multigrid"], runs["amg"]
    assert len(multigrid) == len(amg) == 7
    assert len({a["cells"] for a in multigrid}) > 1  # adapted
    for a, b in zip(multigrid, amg):
        assert a["cells"] == b["cells"] and a["n_lost"] == b["n_lost"] == "0"
        assert float(a["vrms"]) == pytest.approx(float(b["vrms"]), rel=1e-5), a["step"]
        assert int(a["stokes_iterations"]) < int(b["stokes_iterations"])
    # Resumed from step 3 (after the adaptation and repartition of step 2): bit for bit.
    resumed = tmp_path / "resumed"
    shutil.copytree(tmp_path / "multigrid", resumed)
    proc = run_cli(["resume", str(resumed), "--checkpoint", str(resumed / "checkpoints" / "checkpoint_000003")], 2)
    assert proc.returncode == 0, proc.stderr
    assert "note:" not in proc.stderr, proc.stderr
    assert_same_statistics(tmp_path / "multigrid", resumed)


PLATES = CONFIGS / "shell_plates.yaml"


def test_fixed_shell_multigrid_run_resumes_bit_for_bit(tmp_path):
    """The fixed 3D shell with the multigrid (configs/shell_plates.yaml at gmsh size 0.25: gmsh's shell
    at 0.485 refined once, 2 levels; 4 steps, 2000 particles, 2 ranks): resumed from the checkpoint
    of step 2, the refinement is made again from the saved recipe (no note) and the statistics are
    the uninterrupted run's to the last digit."""
    extra = ["mesh.resolution=0.25", "stokes.solver=multigrid", "time.max_steps=4", "time.end=1e9",
             "output.fields_every=0", "output.progress=none", "particles.generator.num_particles=2000",
             "particles.output.every_steps=1000", "output.checkpoint.every_steps=1", "output.checkpoint.keep=10"]
    reference = tmp_path / "reference"
    proc = run_cli(["run", str(PLATES), "--output", str(reference), *sets(extra)], 2)
    assert proc.returncode == 0, proc.stderr
    statistics = rows(reference)
    assert len(statistics) == 5 and all(int(row["stokes_iterations"]) > 0 for row in statistics)
    resumed = tmp_path / "resumed"
    shutil.copytree(reference, resumed)
    proc = run_cli(["resume", str(resumed), "--checkpoint", str(resumed / "checkpoints" / "checkpoint_000002")], 2)
    assert proc.returncode == 0, proc.stderr
    assert "note:" not in proc.stderr, proc.stderr
    assert_same_statistics(reference, resumed)


TOSI = CONFIGS / "tosi.yaml"
TOSI_SMALL = ["mesh.cells=[16,16]", "output.progress=none", "output.fields_every=0"]
NONLINEAR = {
    # Newton on the viscoplastic case: PCMG once went on with the first step's velocity block after
    # fieldsplit made the block anew at the first Newton step (its iterations then grew to
    # thousands and the run failed at step 10); 20 steps reach the yielding lid.
    "newton": ["time.max_steps=20"],
    # Picard to 1e-6 (it converges linearly: 6 to 41 iterations a step over these steps)
    "picard": ["time.max_steps=8", "stokes.nonlinear.method=picard", "stokes.nonlinear.rtol=1e-6"],
}
NONLINEAR_RTOL = {"newton": 1e-8, "picard": 1e-6}


@pytest.mark.parametrize("method, ranks", [("newton", 1), ("newton", 2), ("picard", 2)])
def test_viscoplastic_multigrid_run_equals_the_direct_run(tmp_path, method, ranks):
    """configs/tosi.yaml (1e5 temperature contrast, von Mises yielding) with the multigrid on
    16x16 -> 8x8 -> 4x4 -> 2x2: every step's nonlinear solve converges with the same iterations as
    the direct solver's, and vrms and Nusselt agree to the nonlinear tolerance."""
    out = {}
    for solver in ("direct", "multigrid"):
        folder = tmp_path / solver
        proc = run_cli(["run", str(TOSI), "--output", str(folder),
                        *sets([*TOSI_SMALL, *NONLINEAR[method], f"stokes.solver={solver}"])], ranks)
        assert proc.returncode == 0, proc.stderr
        out[solver] = rows(folder)
    rtol = 1e-8 if method == "newton" else 1e-5
    assert len(out["multigrid"]) == len(out["direct"]) > 8
    for a, b in zip(out["multigrid"], out["direct"]):
        assert a["nonlinear_iterations"] == b["nonlinear_iterations"], a["step"]
        assert float(a["nonlinear_residual"]) <= float(NONLINEAR_RTOL[method])
        for key in ("time", "vrms", "nusselt"):
            assert float(a[key]) == pytest.approx(float(b[key]), rel=rtol, abs=1e-12), (key, a["step"])
        # the whole step's Krylov iterations (every nonlinear iteration's), a few hundred at most
        assert int(a["stokes_iterations"]) <= 120 * int(a["nonlinear_iterations"])

