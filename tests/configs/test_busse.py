"""The shipped Busse et al. (1994) case 1a config (configs/busse_1a.yaml: a 3D box graded in z,
no slip at top and bottom, free slip on the sides) and its benchmark script at a CI size: the
script's two runs (a uniform coarse mesh cold, then the graded mesh continued from it) write their
table and picture; the flow keeps the initial temperature's symmetry under the inversion through
the box's centre (T -> 1 - T), so the heat flow through the top equals that through the bottom at
every step, and the velocity is finite and the temperature bounded."""

from __future__ import annotations

import pytest

from _runs import rows
from benchmarks.busse import run as busse


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    out = tmp_path_factory.mktemp("busse")
    assert busse.main(["--quick", "--out", str(out), "--coarse", "6x4x6", "--fine", "6x4x6"]) == 0
    return out


def test_the_script_writes_its_table_and_picture(quick):
    table = (quick / "results.md").read_text().splitlines()
    assert table[0].startswith("| run | cells | steps |")
    assert table[2].startswith("| cold, uniform | 6x4x6 | 3 |")
    assert table[3].startswith("| from the coarse run, graded, cfl 16 | 6x4x6 | 3 |")
    assert (quick / "results.png").stat().st_size > 10_000


@pytest.mark.parametrize("run", ["coarse_6x4x6", "fine_6x4x6"])
def test_top_and_bottom_heat_flows_agree_by_symmetry(quick, run):
    for row in rows(quick / run):
        top, bottom = float(row["nusselt"]), float(row["nusselt_bottom"])
        assert abs(top - bottom) <= 1e-6 * top, (row["step"], top, bottom)
        assert 0.0 < float(row["vrms"]) < 1e3
        assert -0.05 <= float(row["T_min"]) and float(row["T_max"]) <= 1.05
