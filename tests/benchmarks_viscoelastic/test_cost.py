"""benchmarks/viscoelastic/cost.py at CI size: the compiled stress update gives the vectorised
path's stresses to round-off, in less CPU time (no absolute time is asserted)."""

from benchmarks.viscoelastic import cost


def test_compiled_update_is_the_vectorised_one_for_less(tmp_path):
    result = cost.measure(8, tmp_path, repeats=3, steps=2)
    assert result["particles"] > 1000
    assert result["difference"] < 1e-13
    assert result["compiled"] < result["vectorised"]
    assert "| compiled |" in cost.table(result)


def test_step_measurement_splits_the_step(tmp_path):
    """The viscous and the visco-elastic step of the same cavity are measured with their parts (no
    time is asserted, only that the parts lie within the step and the table holds both)."""
    blocks = {elastic: cost.measure_step(4, tmp_path, elastic=elastic, steps=2, repeats=2) for elastic in (False, True)}
    for block in blocks.values():
        assert block["step"] > 0.0 and block["flow"] > 0.0 and block["particles"] > 0.0
        assert block["flow"] + block["particles"] <= block["step"] * (1 + 1e-9)
    text = cost.step_table(blocks[False], blocks[True])
    assert "| viscous | 1.000 |" in text and "| visco-elastic |" in text and "| ratio |" in text
