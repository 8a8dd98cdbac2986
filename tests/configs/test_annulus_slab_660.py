"""A slab at the 660 at CI size (benchmarks/phase_transitions/slab.py; configs/annulus_slab_660.yaml on a
200 km mesh to 40 Myr, in this process): the two runs differ only in the 660's Clapeyron slope. At
-6 MPa/K the slab's tip stays above 760 km and none of its cold core lies below 760 km; at -1 MPa/K
the tip is hundreds of km deeper and a sizeable share of the core has sunk through. Both
measures are global (the deepest node over the ranks, an integral): the same on any number of ranks."""

import pytest
from mpi4py import MPI

from benchmarks.phase_transitions.slab import QUICK, SLOPES, slab_run

CI = QUICK


@pytest.fixture(scope="module")
def runs():
    return {name: slab_run(slope, CI, every=20.0, comm=MPI.COMM_WORLD) for name, slope in SLOPES.items()}


def test_slab_stagnates_at_a_strongly_negative_slope_and_sinks_through_a_weak_one(runs):
    stagnating, penetrating = (runs[name]["rows"] for name in ("stagnating", "penetrating"))
    assert [r[0] for r in stagnating] == pytest.approx([0.0, 20.0, 40.0])
    assert stagnating[0][1:] == pytest.approx(penetrating[0][1:], rel=1e-12)  # the same start
    assert 300.0 < stagnating[0][1] < 560.0 and stagnating[0][2] < 1e-6  # the slab hangs 450 km deep
    _, tip_stagnating, _ = stagnating[-1]
    _, tip_penetrating, _ = penetrating[-1]
    assert max(r[1] for r in stagnating) < 760.0  # held on the 660 (the tip's node on the deflected 660)
    assert tip_penetrating > tip_stagnating + 400.0  # through it and hundreds of km below
    # the slab's cold core below 760 km: none at -6 MPa/K, a fifth of the slab at -1 MPa/K (20 Myr)
    assert max(r[2] for r in stagnating) < 0.01 and max(r[2] for r in penetrating) > 0.1
