"""The shipped Tosi et al. (2015) config (configs/tosi.yaml, case 2: viscoplastic, Newton) at a CI
size: the nonlinear solve converges every step, the energy identity holds, 1 and 2 ranks agree, a
killed run resumes bit for bit, non-convergence is a one-line run failure, and the benchmark script
prints its JSON line."""

from __future__ import annotations

import json
import sys

import pytest

from _runs import CONFIGS, ROOT, assert_same_statistics, env, guarded_run, kill_run, rows, rows_written, run_cli, sets

CONFIG = CONFIGS / "tosi.yaml"
SMALL = ["mesh.cells=[10,10]", "time.max_steps=8", "output.progress=none", "output.fields_every=0"]


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    out = {}
    for ranks in (1, 2):
        folder = tmp_path_factory.mktemp(f"tosi{ranks}")
        proc = run_cli(["run", str(CONFIG), "--output", str(folder), *sets(SMALL)], ranks)
        assert proc.returncode == 0, proc.stderr
        out[ranks] = rows(folder)
    return out


def test_every_step_converges_and_balances_energy(runs):
    for row in runs[1]:
        assert float(row["nonlinear_residual"]) <= 1e-8
        assert int(row["nonlinear_iterations"]) >= 1
        # Galerkin orthogonality: int 2 eta eps:eps = Ra int T u_z for the converged solution
        assert float(row["delta"]) < 1e-9
    last = runs[1][-1]
    assert float(last["eta_min"]) >= 1e-5 * 2 / (1 + 2e-5) * 0.99 and float(last["eta_max"]) <= 2.0
    assert 0 < float(last["vrms_surface"]) <= float(last["vmax_surface"])


def test_one_and_two_ranks_agree(runs):
    a, b = runs[1], runs[2]
    assert [r["step"] for r in a] == [r["step"] for r in b]
    for x, y in zip(a, b):
        assert x["nonlinear_iterations"] == y["nonlinear_iterations"], x["step"]
        for key in ("vrms", "nusselt", "T_mean", "W", "eta_min", "eta_max", "vrms_surface"):
            assert float(x[key]) == pytest.approx(float(y[key]), rel=1e-7), (key, x["step"])


def test_golden_numbers(runs):
    """Regression at 10 x 10 after 8 steps (Newton to 1e-8, MUMPS): any change of the physics or
    of the solution shows here."""
    last = runs[1][-1]
    assert int(last["step"]) == 8
    assert float(last["vrms"]) == pytest.approx(GOLDEN["vrms"], rel=1e-6)
    assert float(last["nusselt"]) == pytest.approx(GOLDEN["nusselt"], rel=1e-6)
    assert float(last["T_mean"]) == pytest.approx(GOLDEN["T_mean"], rel=1e-8)


GOLDEN = {"vrms": 136.32297197991932, "nusselt": 1.0041311653544172, "T_mean": 0.5046464149510529}


def test_killed_run_resumes_bit_for_bit(tmp_path):
    extra = [*SMALL, "output.checkpoint.every_steps=2"]
    reference = tmp_path / "reference"
    proc = run_cli(["run", str(CONFIG), "--output", str(reference), *sets(extra)])
    assert proc.returncode == 0, proc.stderr
    killed = tmp_path / "killed"
    code = kill_run(CONFIG, killed, 1, extra, when=lambda d: rows_written(d, 6))
    assert code != 0
    proc = run_cli(["resume", str(killed)])
    assert proc.returncode == 0, proc.stderr
    assert_same_statistics(reference, killed)


def test_not_converging_is_a_one_line_run_failure(tmp_path):
    proc = run_cli(["run", str(CONFIG), "--output", str(tmp_path / "run"),
                    *sets([*SMALL, "stokes.nonlinear.max_iterations=2", "stokes.nonlinear.rtol=1e-12"])])
    assert proc.returncode == 3, proc.stderr
    lines = [line for line in proc.stderr.splitlines() if line.strip() and not line.startswith("INFO")]
    assert len(lines) == 1 and "did not reach the relative residual" in lines[0], proc.stderr


def test_benchmark_script_prints_its_json_line(tmp_path):
    proc = guarded_run([sys.executable, "-m", "benchmarks.tosi.run", "--case", "2", "--cells", "6",
                        "--end", "0.02", "--out", str(tmp_path / "runs"), "--results", str(tmp_path / "results")],
                       cwd=ROOT, env=env(), budget=300)
    assert proc.returncode == 0, proc.stderr
    summary = json.loads(proc.stdout.strip().splitlines()[-1])
    for key in ("T_mean", "nusselt_top", "nusselt_bottom", "vrms", "vrms_surface", "vmax_surface", "eta_min",
                "eta_max", "W", "Phi_over_Ra", "delta"):
        assert isinstance(summary[key], float), key
    assert (tmp_path / "results" / "case2.json").exists()
