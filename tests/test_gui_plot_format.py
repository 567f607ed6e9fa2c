"""Plot readability helpers (winder_gui.views.plots): tick labels without float noise, a readable band
for flat curves, log axes labelled at 1-2-5 only, the crosshair read-out with units."""

from __future__ import annotations

import math

import numpy as np
import pytest

pytestmark = pytest.mark.usefixtures("qapp")


def test_tick_labels_carry_only_the_decimals_the_spacing_needs() -> None:
    from winder_gui.views.plots import TickAxis

    ax = TickAxis("left")
    assert ax.tickStrings([18.000000000000005, 18.1, 18.2], 1.0, 0.1) == ["18.0", "18.1", "18.2"]
    assert ax.tickStrings([0.0, 500.0, 1000.0], 1.0, 500.0) == ["0", "500", "1000"]
    assert ax.tickStrings([-1e-17, 0.25, 0.5], 1.0, 0.25) == ["0", "0.25", "0.50"]
    assert ax.tickStrings([2e7, 4e7], 1.0, 2e7) == ["2e+07", "4e+07"]


def test_log_axis_labels_one_two_five_of_each_decade() -> None:
    from winder_gui.views.plots import LogTickAxis

    ax = LogTickAxis("bottom")
    ax.setLogMode(True)
    vals = [math.log10(v) for v in (100, 200, 300, 400, 500, 600, 1000, 2000, 3000)]
    assert ax.tickStrings(vals, 1.0, 1.0) == ["100", "200", "", "", "500", "", "1000", "2000", ""]


def test_flat_curve_gets_a_readable_band(qtbot) -> None:
    """A geodesic on a cylinder has a constant Clairaut function: the axis shows a band around it,
    not a range of 1e-15."""
    from winder_gui.views.plots import PlotPage

    page = PlotPage()
    qtbot.addWidget(page)
    page.add_plot("C", 0, 0, "C [mm]", "z [mm]")
    page.set_curve("C", "C", np.linspace(0, 100, 50), np.full(50, 61.43) + 1e-14 * np.arange(50))
    page._done("")
    lo, hi = page.plots["C"].getViewBox().viewRange()[1]
    assert hi - lo >= 1.0 and lo < 61.43 < hi


def test_readout_names_values_with_units() -> None:
    from winder_gui.views.plots import readout_text, split_label

    assert split_label("β [deg]") == ("β", "deg")
    assert split_label("λ [–]") == ("λ", "–")
    assert readout_text("z [mm]", "β [deg]", 12.5, 55.01) == "z = 12.5 mm · β = 55.01 deg"
    assert readout_text("t [s]", "λ [–]", 3.0, -0.1) == "t = 3 s · λ = -0.1"
