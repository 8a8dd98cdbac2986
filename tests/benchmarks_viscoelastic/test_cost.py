"""benchmarks/viscoelastic/cost.py at CI size: the compiled stress update gives the vectorised
path's stresses to round-off, in less CPU time (no absolute time is asserted)."""

from benchmarks.viscoelastic import cost


def test_compiled_update_is_the_vectorised_one_for_less(tmp_path):
    result = cost.measure(8, tmp_path, repeats=3, steps=2)
    assert result["particles"] > 1000
    assert result["difference"] < 1e-13
    assert result["compiled"] < result["vectorised"]
    assert "| compiled |" in cost.table(result)
