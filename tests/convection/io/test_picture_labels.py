"""Labels and tick numbers of the pictures (convection.io.pictures.labels): plain numbers, the units
of the output, a power of ten in the label where the numbers are very large or small."""

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from convection.io.pictures.labels import Labels, plain_ticks, pyvista_format, tick_scale  # noqa: E402


def test_axis_labels_in_the_output_units():
    assert Labels({"length": "km"}).axis("z") == "z [km]" and Labels().axis("x") == "x"
    assert Labels({"length": "km"}).length == "km" and Labels().length is None


def test_powers_of_ten_in_steps_of_three_outside_the_plain_range():
    assert tick_scale(0.0, 1.0).power == 0 and tick_scale(273.0, 1573.0).power == 0
    assert tick_scale(1e19, 1e23).power == 21 and tick_scale(0.0, 2.5e9).power == 9
    assert tick_scale(0.0, 1.3e-4).power == -6 and tick_scale(-2e6, 1.0).power == 6
    assert tick_scale(0.0, 0.0).power == 0
    assert tick_scale(0.0, 2.5e9).label("pressure [Pa]") == "pressure [Pa] (×$10^{9}$)"


def test_plain_ticks_have_no_offset_and_no_exponent():
    fig, ax = plt.subplots()
    ax.plot([1000.0, 1000.5], [0.0, 2.5e9])
    xlabel = plain_ticks(ax.xaxis, 1000.0, 1000.5, "time")
    ylabel = plain_ticks(ax.yaxis, 0.0, 2.5e9, "pressure [Pa]")
    fig.canvas.draw()
    for axis in (ax.xaxis, ax.yaxis):
        texts = [t.get_text() for t in axis.get_ticklabels() if t.get_text()]
        assert axis.get_offset_text().get_text() == "" and texts and not any("e" in t for t in texts)
    assert "1000.5" in [t.get_text() for t in ax.xaxis.get_ticklabels()]  # not 0.5 with an offset of 1000
    assert xlabel == "time" and ylabel == "pressure [Pa] (×$10^{9}$)"
    assert "2.5" in [t.get_text() for t in ax.yaxis.get_ticklabels()]
    plt.close(fig)


def test_pyvista_formats_print_evenly_spaced_labels_exactly():
    assert pyvista_format(0.0, 1.0, 6) == "%.1f"  # 0.0, 0.2, ..., 1.0
    assert pyvista_format(0.0, 1.0, 5) == "%.2f"  # 0.00, 0.25, ..., 1.00
    assert pyvista_format(273.0, 1573.0, 6) == "%.0f"  # 273, 533, ..., 1573 K
    assert pyvista_format(0.0, 500.0, 6) == "%.0f" and pyvista_format(0.0, 512.0, 6) == "%.0f"  # 102 km apart
    assert pyvista_format(0.0013, 0.987, 6) == "%.3f"
    assert pyvista_format(1e19, 1e23, 5) == "%.3g" and pyvista_format(1.0, 1.0, 5) == "%.0f"


def test_round_ticks_inside_the_range():
    from convection.io.pictures.labels import nice_ticks

    assert nice_ticks(-0.079, 1.0) == [0.0, 0.25, 0.5, 0.75, 1.0]
    assert nice_ticks(273.0, 1573.0) == [300.0, 600.0, 900.0, 1200.0, 1500.0]
