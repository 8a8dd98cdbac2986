"""summary.png (convection.io.pictures.summary): one panel per series and none empty, axes in the
run's units, plain tick numbers."""

from __future__ import annotations

import json

import matplotlib.pyplot as plt
import numpy as np
import pytest

from _picture_runs import run_directory
from convection.io.pictures import plot_run
from convection.io.pictures.summary import flat_mesh, summary_figure


def _curves_and_field(fig):
    """(the curve axes, the field axes or None, the colour bar axes) of a summary figure."""
    bars = [ax for ax in fig.axes if ax.get_label() == "<colorbar>"]
    plots = [ax for ax in fig.axes if ax not in bars]
    field = [ax for ax in plots if ax.collections]
    return [ax for ax in plots if ax.lines and not ax.collections], (field[0] if field else None), bars


def _tick_texts(fig, axis):
    fig.canvas.draw()
    return [t.get_text() for t in axis.get_ticklabels() if t.get_text()], axis.get_offset_text().get_text()


@pytest.mark.parametrize("dim", [2, 3])
def test_one_panel_per_series_none_empty(tmp_path, dim):
    """vrms, Nusselt and cells: three curves and the field (a 3D box: its side y = 0), every axes drawn
    on, axes x and z without units in a nondimensional run."""
    directory = run_directory(tmp_path, dim=dim, particles=False)
    fig = summary_figure(directory)
    curves, field, bars = _curves_and_field(fig)
    assert [ax.get_ylabel() for ax in curves] == ["vrms", "Nusselt (top)", "cells"]
    assert field is not None and len(bars) == 1
    assert len(fig.axes) == len(curves) + 2  # nothing else: no empty panel
    assert (field.get_xlabel(), field.get_ylabel()) == ("x", "z")
    assert field.get_title().endswith("side y = 0" if dim == 3 else "t = 2")
    assert curves[-1].get_xlabel() == "time"
    plt.close(fig)
    assert plot_run(directory).stat().st_size > 10_000


def test_axes_in_the_runs_units_with_plain_ticks(tmp_path):
    """A run in physical units (fields_units.json, statistics_physical.csv): x [km], z [km], vrms in
    cm/yr against Myr; a temperature in K is ticked 1000, not 1e+03, without an offset."""
    directory = run_directory(tmp_path, particles=False)
    (directory / "fields_units.json").write_text(json.dumps({"time": "Myr", "length": "km",
                                                             "fields": {"temperature": "K"}}))
    (directory / "statistics_physical.csv").write_text("step,time [Myr],vrms [cm/yr],cells\n0,0,1.5,100\n1,3,2.5,100\n")
    fig = summary_figure(directory)
    curves, field, bars = _curves_and_field(fig)
    assert (field.get_xlabel(), field.get_ylabel()) == ("x [km]", "z [km]")
    assert [ax.get_ylabel() for ax in curves] == ["vrms [cm/yr]", "cells"]
    assert curves[-1].get_xlabel() == "time [Myr]" and bars[0].get_ylabel() == "temperature [K]"
    ticks, offset = _tick_texts(fig, curves[-1].yaxis)  # cells = 100: no "+1e2" offset
    assert offset == "" and all("e" not in t for t in ticks)
    plt.close(fig)


def test_large_values_put_their_power_of_ten_in_the_label(tmp_path):
    """A temperature of 1e21 (say) is ticked 0.5, 1, ... with the power in the colour bar's label."""
    directory = run_directory(tmp_path, particles=False)
    (directory / "fields_units.json").write_text(json.dumps({"time": "Myr", "length": "km",
                                                             "fields": {"temperature": "K"}}))
    import h5py

    with h5py.File(directory / "fields_001.h5", "r+") as h5:
        for step in h5["Function/temperature"].values():
            step[...] = 1e21 * (1.0 + step[...])
    fig = summary_figure(directory)
    _, _, bars = _curves_and_field(fig)
    ticks, offset = _tick_texts(fig, bars[0].yaxis)
    assert bars[0].get_ylabel() == "temperature [K] (×$10^{21}$)"
    assert offset == "" and ticks and all("e" not in t for t in ticks)
    assert 1.0 <= float(ticks[0].replace("−", "-")) < float(ticks[-1].replace("−", "-")) <= 2.0
    plt.close(fig)


def test_no_fields_only_the_curves(tmp_path):
    directory = run_directory(tmp_path, particles=False)
    for path in directory.glob("fields*"):
        path.unlink()
    fig = summary_figure(directory)
    curves, field, bars = _curves_and_field(fig)
    assert len(curves) == len(fig.axes) == 3 and field is None and not bars
    assert fig._suptitle.get_text() == "no field output"
    plt.close(fig)


def test_flat_mesh_of_tetrahedra_is_the_side_nearest_minus_y():
    """Two tetrahedra of the unit cube: only faces with all vertices on y = 0 are kept, in (x, z)."""
    points = np.array([[0, 0, 0], [1, 0, 0], [0, 0, 1], [0, 1, 0], [1, 0, 1]], dtype=np.float64)
    cells = np.array([[0, 1, 2, 3], [1, 2, 4, 3]])
    mesh = flat_mesh(points, cells)
    assert mesh.axes == (0, 2) and mesh.where == "side y = 0"
    assert sorted(map(sorted, mesh.triangles.tolist())) == [[0, 1, 2], [1, 2, 4]]
    assert mesh.cell_of.tolist() == [0, 1] and np.array_equal(mesh.points, points[:, [0, 2]])
    assert flat_mesh(points[:, :2], np.array([[0, 1, 2]])).axes == (0, 1)


def test_quadrilaterals_are_cut_in_two():
    """XDMF lists a quadrilateral's vertices in cyclic order: the halves (0, 1, 2), (0, 2, 3) cover it."""
    points = np.array([[0, 0], [0, 1], [1, 1], [1, 0], [2, 1], [2, 0]], dtype=np.float64)
    mesh = flat_mesh(points, np.array([[0, 1, 2, 3], [3, 2, 4, 5]]))
    assert mesh.triangles.tolist() == [[0, 1, 2], [3, 2, 4], [0, 2, 3], [3, 4, 5]]
    assert mesh.cell_of.tolist() == [0, 1, 0, 1] and mesh.outlines.tolist() == [[0, 1, 2, 3], [3, 2, 4, 5]]
    a, b, c = (points[mesh.triangles[:, i]] for i in range(3))
    areas = 0.5 * np.abs(np.cross(b - a, c - a))
    assert np.allclose(areas, 0.5) and areas.sum() == pytest.approx(2.0)
