"""The materials and points statistics on models whose answers are known: a square block on a mesh
that resolves it exactly (volume, centroid by symmetry, its deepest cell centre), a linear
temperature read at points, a point outside the domain refused; the same numbers on 1 and 2 ranks."""

from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI

from convection import build_model, load_config
from convection.config.loader import ConfigError
from convection.postprocess import create_postprocessors
from convection.postprocess.base import DiagnosticsSettings


def _block(tmp_path, comm, *extra):
    """A dense, stiff square block [0.375, 0.625] x [0.5, 0.75] in the unit square, 16 x 16 cells
    (the block is 4 x 4 cells), composition held on the mesh (static, P1). The region's bounds lie
    between the vertices: a vertex exactly on a bound may be pushed forward to either side of it in
    the last bit, differently on different partitions."""
    document = {
        "mesh": {"cells": [16, 16]}, "time": {"end": 1.0}, "energy": {"enabled": False},
        "initial": {"temperature": "1 - z"},
        "materials": {"block": {"initial": "0.37 <= x <= 0.63 and 0.49 <= z <= 0.76", "Rb": 100.0,
                                "viscosity": 1000.0}},
        "composition": {"source": "static", "degree": 1},
        # off the cells' faces: a cell field (DG0: viscosity, strain_rate_II) has a value per cell there
        "diagnostics": {"points": {"centre": [0.51, 0.63], "corner": [0.004, 0.003], "low": [0.26, 0.13]}},
        "output": {"directory": str(tmp_path / "out"), "progress": "none"},
    }
    config = load_config(None, document=document, overrides=list(extra))
    model = build_model(config, comm=comm)
    model.start()
    diagnostics = DiagnosticsSettings(points=config["diagnostics"]["points"])
    return model, create_postprocessors(model, ["materials", "points"], diagnostics=diagnostics)


def _row(model, postprocessors):
    row = {}
    for pp in postprocessors:
        row.update(pp(model))
    return row


def test_block_statistics_and_point_values(tmp_path):
    model, pps = _block(tmp_path, MPI.COMM_WORLD)
    row = _row(model, pps)
    # the P1 fraction is exact at the vertices: its integral over the block plus half a cell's ramp
    # on each side is (0.25 + h)^2 - h^2 ... exactly the interpolant's integral; check by symmetry and bounds
    assert 0.25**2 <= row["volume_block"] <= (0.25 + 1 / 16) ** 2
    assert row["x_block"] == pytest.approx(0.5, abs=1e-12)
    assert row["y_block"] == pytest.approx(0.625, abs=1e-12)
    assert row["vup_block"] < 0.0  # dense: it sinks
    assert row["vrms_block"] >= abs(row["vup_block"])
    assert row["vmax_block"] >= 0.9 * row["vrms_block"]
    # the deepest cell at least half filled: below the block's base (depth 0.5) the P1 fraction ramps
    # to 0 over one cell, so a triangle with two vertices on the base has average 2/3 and centroid
    # depth 0.5 + h/3 -- the deepest point is found to within half a cell
    assert row["depth_block"] == pytest.approx(0.5 + 1 / 48, abs=1e-12)
    # the temperature 1 - z is exact in P2; the block's fraction at its centre is 1, at the corner 0
    assert row["T_centre"] == pytest.approx(1 - 0.63, abs=1e-13)
    assert row["T_low"] == pytest.approx(1 - 0.13, abs=1e-13)
    assert row["block_centre"] == pytest.approx(1.0, abs=1e-13) and row["block_corner"] == pytest.approx(0.0, abs=1e-13)
    assert abs(row["vx_corner"]) < 0.01 * abs(row["vy_centre"])  # free slip on both sides: at rest in the corner
    # nearly symmetric (the mesh's diagonals are not)
    assert row["vy_centre"] < 0.0 and abs(row["vx_centre"]) < 0.05 * abs(row["vy_centre"])
    assert row["vy_centre"] == pytest.approx(row["vup_block"], rel=0.1)  # a stiff block sinks as one
    if MPI.COMM_WORLD.size == 1:
        np.save(tmp_path / "row.npy", np.array([row[c] for c in sorted(row)]))


@pytest.mark.mpi
def test_block_statistics_same_on_every_rank_count(tmp_path):
    """Parallel run: the columns equal the serial ones (measured here on COMM_SELF on rank 0)."""
    comm = MPI.COMM_WORLD
    model, pps = _block(tmp_path / str(comm.rank), comm)
    parallel = _row(model, pps)
    if comm.rank == 0:
        serial_model, serial_pps = _block(tmp_path / "serial", MPI.COMM_SELF)
        serial = _row(serial_model, serial_pps)
        for column, value in serial.items():
            assert parallel[column] == pytest.approx(value, rel=1e-9, abs=1e-12), column


def test_point_outside_the_domain_is_named(tmp_path):
    model, _ = _block(tmp_path, MPI.COMM_WORLD)
    with pytest.raises(ConfigError, match=r"'diagnostics.points.away': \[2.0, 0.5\] is not in the domain"):
        pps = create_postprocessors(model, ["points"], diagnostics=DiagnosticsSettings(points={"away": [2.0, 0.5]}))
        _row(model, pps)


@pytest.mark.parametrize("mesh, inside, outside", [
    ({"cells": [4, 4]}, [1.0, 0.0], [0.5, 1.01]),
    ({"geometry": "annulus", "radii": [1.0, 2.0], "resolution": 0.5}, [0.0, -2.0], [0.5, 0.5]),
    ({"geometry": "sector", "radii": [1.0, 2.0], "angles": [60.0, 120.0], "resolution": 0.5}, [0.0, 1.5],
     [1.5, 0.0]),
])
def test_point_outside_the_domain_is_refused_by_check(mesh, inside, outside):
    """A point outside the domain is a config error at check time (box, annulus, sector), one on
    its boundary is not."""
    def document(point):
        return {"mesh": mesh, "physics": {"Ra": 1.0}, "time": {"end": 1.0}, "diagnostics": {"points": {"p": point}},
                "output": {"directory": "o", "statistics": ["time", "points"]}}
    load_config(None, document=document(inside))
    with pytest.raises(ConfigError, match=r"'diagnostics.points.p': \[.*\] is not in the domain"):
        load_config(None, document=document(outside))


def test_points_need_points_and_materials_need_materials(tmp_path):
    with pytest.raises(ConfigError, match="'points' needs diagnostics.points"):
        load_config(None, document={"mesh": {"cells": [4, 4]}, "physics": {"Ra": 1.0}, "time": {"end": 1.0},
                                    "output": {"directory": "o", "statistics": ["points"]}})
    with pytest.raises(ConfigError, match="'materials' needs materials"):
        load_config(None, document={"mesh": {"cells": [4, 4]}, "physics": {"Ra": 1.0}, "time": {"end": 1.0},
                                    "output": {"directory": "o", "statistics": ["materials"]}})
    with pytest.raises(ConfigError, match=r"'diagnostics.points.p': expected \[x, y\]"):
        load_config(None, document={"mesh": {"cells": [4, 4]}, "physics": {"Ra": 1.0}, "time": {"end": 1.0},
                                    "diagnostics": {"points": {"p": [0.5]}}, "output": {"directory": "o"}})


def _air(tmp_path, comm, cells):
    """Sticky air over a cosine surface h = 0.8 + 0.1 cos(pi x) in the unit square."""
    document = {
        "mesh": {"cells": [cells, cells]}, "time": {"end": 1.0}, "energy": {"enabled": False},
        "initial": {"temperature": "0"},
        "materials": {"air": {"initial": "z > 0.8 + 0.1*cos(pi*x)", "Rb": -1.0, "viscosity": 0.01}},
        "composition": {"source": "static", "degree": 1},
        "diagnostics": {"topography_material": "air"},
        "output": {"directory": str(tmp_path / "out"), "progress": "none", "statistics": ["time", "topography"]},
    }
    config = load_config(None, document=document)
    model = build_model(config, comm=comm)
    model.start()
    diagnostics = DiagnosticsSettings(topography_material="air")
    return _row(model, create_postprocessors(model, ["topography"], diagnostics=diagnostics))


@pytest.mark.parametrize("cells", [16, 32, 64])
def test_topography_of_a_cosine_surface(tmp_path, cells):
    """max, min and rms of h - mean(h) against 0.1, -0.1 and 0.1/sqrt(2), within half a cell."""
    row = _air(tmp_path, MPI.COMM_WORLD, cells)
    h = 1.0 / cells
    assert row["topography_max"] == pytest.approx(0.1, abs=h / 2)
    assert row["topography_min"] == pytest.approx(-0.1, abs=h / 2)
    assert row["topography_rms"] == pytest.approx(0.1 / np.sqrt(2), abs=h / 2)


@pytest.mark.mpi
def test_topography_same_on_every_rank_count(tmp_path):
    comm = MPI.COMM_WORLD
    parallel = _air(tmp_path / str(comm.rank), comm, 32)
    if comm.rank == 0:
        serial = _air(tmp_path / "serial", MPI.COMM_SELF, 32)
        for column, value in serial.items():
            assert parallel[column] == pytest.approx(value, rel=1e-12, abs=1e-14), column


def test_topography_needs_a_material_above(tmp_path):
    base = {"mesh": {"cells": [4, 4]}, "physics": {"Ra": 1.0}, "time": {"end": 1.0},
            "materials": {"air": {"initial": "z > 0.9"}}, "output": {"directory": "o", "statistics": ["topography"]}}
    with pytest.raises(ConfigError, match="'topography' needs a free surface, or diagnostics.topography_material"):
        load_config(None, document=base)
    with pytest.raises(ConfigError, match="'diagnostics.topography_material': 'rock' is not one of the materials"):
        load_config(None, document={**base, "diagnostics": {"topography_material": "rock"}})
