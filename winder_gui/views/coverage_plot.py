"""The Coverage tab: the unwrapped coverage map of the bands of true width, gaps and overlaps shaded, with
the covered and overlapped shares (a page of :mod:`winder_gui.views.plots`)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pyqtgraph as pg
from PySide6.QtWidgets import QWidget

from winder_gui.i18n import tr
from winder_gui.views.plots import PlotPage


class CoveragePlot(PlotPage):
    """The unwrapped coverage map: the bands with their true width over (meridian length m or z, v).

    Cells are coloured by how many bands cover them (:func:`engine.coverage.coverage_map`): gaps red,
    one direction's ply light blue, both directions (a closed helical layer) green, more (overlaps)
    darker; the message gives the coverage and overlap percentages.  The band centre lines are drawn
    thin on top (thinned by a stride to at most :attr:`MAX_POINTS` points).
    """

    title = "coverage"
    MAX_POINTS = 300_000
    COLOURS = ((214, 39, 40), (158, 202, 225), (116, 196, 118), (35, 139, 69), (0, 90, 50))
    """Colours of 0 (gap), 1, 2, 3 and 4+ bands over a cell."""

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        p = self.add_plot("map", 0, 0, tr("v mod 360 [deg]"), tr("z [mm]"))
        p.setYRange(0, 360)
        self.stride = 1
        self.image = pg.ImageItem()
        self.image.setZValue(-10)
        p.addItem(self.image)
        self.coverage: Any = None

    def clear_data(self, message: str = "") -> None:
        super().clear_data(message)
        self.image = pg.ImageItem()
        self.image.setZValue(-10)
        self.plots["map"].addItem(self.image)
        self.coverage = None

    def set_line(self, line: Any) -> None:
        """Show every circuit of ``line`` as (z, v mod 360°) centre lines."""
        self.clear_data()
        step = max(1, math.ceil(line.z.size / self.MAX_POINTS))
        z = np.asarray(line.z[::step], dtype=float)
        v = np.mod(np.degrees(line.v[::step]), 360.0)
        wrap = np.flatnonzero(np.abs(np.diff(v)) > 180.0) + 1
        zs = np.insert(z, wrap, np.nan)
        vs = np.insert(v, wrap, np.nan)
        self.stride = step
        self.set_curve("map", "coverage", zs, vs, "#30303080", 0.6, connect="finite")
        self._z_lines = None
        self._line_note = (f"{line.circuits} circuits · {line.z.size} points"
                           + (f" (every {step}th centre line point shown)" if step > 1 else ""))
        self._done(self._line_note)

    def set_coverage(self, cov: Any) -> None:
        """Show the coverage map ``cov`` (:class:`engine.coverage.CoverageMap`) under the centre lines."""
        self.coverage = cov
        count = np.minimum(np.asarray(cov.count), len(self.COLOURS) - 1)
        lut = np.array(self.COLOURS, dtype=np.ubyte)
        self.image.setImage(count.astype(np.int32), levels=(0, len(self.COLOURS) - 1), lut=lut, autoLevels=False)
        from PySide6.QtCore import QRectF

        z0, z1 = float(cov.z_edges[0]), float(cov.z_edges[-1])
        self.image.setRect(QRectF(z0, 0.0, z1 - z0, 360.0))
        self.plots["map"].setLabel("bottom", tr("meridian length m [mm]") if cov.meridian else tr("z [mm]"))
        c = self.curves.get("coverage")
        if c is not None and cov.meridian:  # the centre lines on the map's axis (m, not z)
            self._z_lines = getattr(self, "_z_lines", None) or (np.asarray(c.xData), np.asarray(c.yData))
            c.setData(cov.to_map(self._z_lines[0]), self._z_lines[1], connect="finite")
        f, b = cov.direction_fraction
        note = getattr(self, "_line_note", "")
        self._done(
                   tr("covered {v0:.1f} % (gaps red {v1:.1f} %) · each direction {v2:.1f} % / "
                      "{v3:.1f} % · overlaps {v4:.1f} % · band {band_width_mm:g} mm")
                   .format(v0=100 * cov.covered_fraction, v1=100 * cov.gap_fraction, v2=100 * f, v3=100 * b,
                           v4=100 * cov.overlap_fraction, band_width_mm=cov.band_width_mm)
                   + (f" · {note}" if note else ""))
