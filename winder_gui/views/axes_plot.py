"""The Axes tab: every machine axis's position and speed over the program time, one plot per row, with a
chooser of the axes shown and a scroll for many axes (a page of :mod:`winder_gui.views.plots`)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pyqtgraph as pg
from PySide6.QtGui import QAction
from PySide6.QtWidgets import (
    QMenu,
    QToolButton,
    QWidget,
)

from winder_gui.i18n import tr
from winder_gui.views.plots import (
    AXIS_COLOURS,
    PlotPage,
    _pen,
)


class AxesPlot(PlotPage):
    """Axis positions and speeds against the program time (cumulative block times), with their limits."""

    title = "axes"

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.axis_names: list[str] = []
        self.hidden: set[str] = set()
        """Axes the user chose not to show."""
        self.chooser = QToolButton()
        self.chooser.setObjectName("axes.chooser")
        self.chooser.setText(tr("Axes…"))
        self.chooser.setToolTip(tr("Choose the axes to show (one row each: position and speed)"))
        self.chooser.setPopupMode(QToolButton.ToolButtonPopupMode.InstantPopup)
        self.chooser_menu = QMenu(self.chooser)
        self.chooser.setMenu(self.chooser_menu)
        self.top.insertWidget(0, self.chooser)

    def plan(self, machine: Any) -> list[Any]:
        """Steps that lay out one row of plots per axis of ``machine`` (none when laid out already).

        The window runs them one per event-loop turn before :meth:`set_blocks`.
        """
        names = [f"{ax.name}.{w}" for ax in machine.axes for w in ("q", "v")]
        if names == list(self.plots):
            return []

        def start() -> None:
            self.glw.clear()
            self.plots.clear()
            self.curves.clear()
            self._cross.clear()
            self.axis_names = [ax.name for ax in machine.axes]
            self.hidden &= set(self.axis_names)
            self.chooser_menu.clear()
            for name in self.axis_names:
                act = QAction(name, self.chooser_menu)
                act.setCheckable(True)
                act.setChecked(name not in self.hidden)
                act.toggled.connect(lambda on, n=name: self.show_axis(n, on))
                self.chooser_menu.addAction(act)

        def cell(k: int, ax: Any, speed: bool) -> None:
            # one PlotItem per step: building one (menus, axes, view box) costs ~20 ms of GUI-thread CPU
            if speed:
                p = self.add_plot(f"{ax.name}.v", k, 1, f"{ax.name}' [{ax.units}/s]", "")
            else:
                p = self.add_plot(f"{ax.name}.q", k, 0, f"{ax.name} [{ax.units}]", "")
            first = next(iter(self.plots.values()))
            if p is not first:
                p.setXLink(first)

        return [start, *[lambda k=k, ax=ax, v=v: cell(k, ax, v) for k, ax in enumerate(machine.axes)
                         for v in (False, True)], self.relayout]

    def visible_axes(self) -> list[str]:
        """The axes shown, in the machine's order."""
        return [n for n in self.axis_names if n not in self.hidden]

    def show_axis(self, name: str, on: bool = True) -> None:
        """Show or hide the row of axis ``name``."""
        if on:
            self.hidden.discard(name)
        else:
            self.hidden.add(name)
        self.relayout()

    def relayout(self) -> None:
        """Put the rows of the visible axes one under the other; the time axis under the last one."""
        ci = self.glw.ci
        for p in self.plots.values():
            if p in ci.items:
                ci.removeItem(p)
        shown = self.visible_axes()
        for r, name in enumerate(shown):
            for c, kind in enumerate(("q", "v")):
                p = self.plots[f"{name}.{kind}"]
                last = r == len(shown) - 1
                p.setLabel("bottom", "t [s]" if last else "")
                ax = p.getAxis("bottom")
                ax.setStyle(showValues=last)
                ax.setHeight(None if last else 8)
                ci.addItem(p, r, c)
                p.setMinimumHeight(self.plot_min_height(p))
        for p in self.plots.values():
            p.setVisible(p in ci.items)
        self.fit_rows()

    def set_blocks(self, blocks: Any, machine: Any) -> None:
        """Show every axis of ``blocks`` (engine.blocks.Blocks) with the limits of ``machine``."""
        for step in self.updates(blocks, machine):
            step()

    def updates(self, blocks: Any, machine: Any) -> list[Any]:
        """Steps of :meth:`set_blocks` (layout, then one axis each), to run one per event-loop turn."""
        t = np.concatenate([[0.0], np.cumsum(blocks.time)])

        def start() -> None:
            for p in self.plots.values():
                p.clear()
            self.curves.clear()

        def position(k: int, ax: Any) -> None:
            pp = self.plots[f"{ax.name}.q"]
            c = AXIS_COLOURS[k % len(AXIS_COLOURS)]
            self.set_curve(f"{ax.name}.q", f"{ax.name} position", t, blocks.q[:, k], c)
            for lim in (ax.min, ax.max):
                if math.isfinite(lim) and abs(lim) < 1e11:  # templates write "unlimited" as ±1e12
                    pp.addItem(pg.InfiniteLine(lim, angle=0, pen=_pen("#c01010", 1, True)))

        def speed(k: int, ax: Any) -> None:
            pv = self.plots[f"{ax.name}.v"]
            # each block's constant speed drawn over its time span: (t_i, v_i), (t_i+1, v_i)
            v = blocks.delta[:, k] / blocks.time
            self.set_curve(f"{ax.name}.v", f"{ax.name} speed", np.repeat(t, 2)[1:-1], np.repeat(v, 2),
                           AXIS_COLOURS[k % len(AXIS_COLOURS)])
            for lim in (-ax.max_speed, ax.max_speed):
                pv.addItem(pg.InfiniteLine(lim, angle=0, pen=_pen("#c01010", 1, True)))

        # one curve per step (each costs 5-20 ms of GUI-thread CPU on ~30 000 blocks)
        steps = [step for k, ax in enumerate(machine.axes)
                 for step in (lambda k=k, ax=ax: position(k, ax), lambda k=k, ax=ax: speed(k, ax))]
        return [*self.plan(machine), start, *steps,
                lambda: self._done(tr("{n} blocks · program time {total:.2f} s · dashed red: limits")
                                   .format(n=blocks.n, total=blocks.total))]
