"""The steady start (``initial.steady``, :mod:`convection.solvers.steady`): Newton's method on the
steady equations finds the published steady flows of Blankenbach et al. (1989), case 1a
(isoviscous) and case 2b (a viscosity contrast of 16384 in temperature and 64 in depth, which no
start from the sinusoid reaches by time steps), the time steps stay on it, the result is the same
on 1 and 2 ranks, and ``check`` refuses it where its equations are not the model's.
"""

from __future__ import annotations

import pytest

from _runs import CONFIGS, error_line, rows, run_cli, sets

QUIET = ["output.progress=none", "output.fields_every=0", "initial.steady=true"]
# Blankenbach et al. (1989), Table 9 (benchmarks/blankenbach/reference.csv)
NU_1A, VRMS_1A = 4.884409, 42.864947
NU_2B, VRMS_2B = 6.9299, 171.755


def _run(tmp_path, config: str, extra: list[str], ranks: int = 1) -> list[dict[str, str]]:
    out = tmp_path / f"{config}_{ranks}"
    proc = run_cli(["run", str(CONFIGS / f"{config}.yaml"), "--output", str(out), *sets([*QUIET, *extra])], ranks)
    assert proc.returncode == 0, proc.stderr
    assert "steady start:" in proc.stderr
    return rows(out)


def _value(row: dict[str, str], key: str) -> float:
    return float(row[key])


def test_isoviscous_steady_start_is_blankenbach_1a(tmp_path):
    first = _run(tmp_path, "blankenbach_1a", ["mesh.cells=[16,16]", "time.max_steps=0"])[0]
    assert _value(first, "time") == 0.0
    assert _value(first, "vrms") == pytest.approx(VRMS_1A, rel=5e-3)
    assert _value(first, "nusselt") == pytest.approx(NU_1A, rel=1e-2)
    # a steady state: as much heat leaves at the top as enters at the bottom
    assert _value(first, "nusselt") == pytest.approx(_value(first, "nusselt_bottom"), rel=5e-3)


def test_steady_start_finds_blankenbach_2b_and_the_time_steps_stay_there(tmp_path):
    table = _run(tmp_path, "blankenbach_2b", ["mesh.cells=[40,16]", "mesh.grading=[0,0.5]", "time.max_steps=20"])
    first, last = table[0], table[-1]
    for row in (first, last):
        assert _value(row, "vrms") == pytest.approx(VRMS_2B, rel=1e-2)
        assert _value(row, "nusselt") == pytest.approx(NU_2B, rel=1e-2)
        assert _value(row, "nusselt") == pytest.approx(_value(row, "nusselt_bottom"), rel=1e-2)
    # 20 steps of the time stepper (SUPG, BDF2) keep the flow: a cold start swings by 50 % and more
    assert _value(last, "vrms") == pytest.approx(_value(first, "vrms"), rel=2e-3)


def test_steady_start_is_the_same_on_one_and_two_ranks(tmp_path):
    extra = ["mesh.cells=[12,12]", "time.max_steps=0"]
    one, two = (_run(tmp_path, "blankenbach_1a", extra, ranks)[0] for ranks in (1, 2))
    for key in ("vrms", "nusselt", "nusselt_bottom", "T_mean"):
        assert _value(two, key) == pytest.approx(_value(one, key), rel=1e-9), key


@pytest.mark.parametrize("extra, needle", [
    (["initial.composition=z < 0.2"], "composition"),
    (["physics.approximation=eba", "physics.reference.Di=0.5"], "approximation"),
    (["energy.enabled=false"], "energy.enabled"),
])
def test_refused_at_check_where_its_equations_are_not_the_model(extra, needle):
    proc = run_cli(["check", str(CONFIGS / "blankenbach_1a.yaml"), *sets(["initial.steady=true", *extra])])
    line = error_line(proc, 2, "initial.steady")
    assert needle in line


def test_steady_start_gives_the_same_bits_twice_on_two_ranks(tmp_path):
    """The Newton solves are gathered on rank 0 (reproducible_lu): a parallel MUMPS factorisation
    gave a different last digit in each of 8 runs of this start."""
    extra = ["mesh.cells=[26,10]", "time.max_steps=0"]
    first, second = (_run(tmp_path / name, "blankenbach_2b", extra, 2)[0] for name in ("a", "b"))
    assert first == {**second, "wall_time": first["wall_time"]}
