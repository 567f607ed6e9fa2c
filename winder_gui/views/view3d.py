"""3D view of the revolved mandrel.

The pyvista/pyvistaqt backend is heavy (VTK) and is created lazily: only when the view is first
shown, and one event-loop turn later, so the main window paints before VTK loads.  pyvistaqt's
``QtInteractor`` aborts the process under ``QT_QPA_PLATFORM=offscreen`` (pyvistaqt#351); there —
or with ``WINDER_NO_3D=1``, or when VTK cannot start — the view is a placeholder label.  The real
view is tested under ``xvfb-run`` (pytest marker ``gl``).  Rendering happens on the GUI thread only;
the surface arrays come ready-made from a worker (:mod:`winder_gui.views.geometry`).
"""

from __future__ import annotations

import os
import sys
from typing import Any

import numpy as np
from PySide6.QtCore import Qt, QTimer
from PySide6.QtGui import QGuiApplication, QImage
from PySide6.QtWidgets import QLabel, QVBoxLayout, QWidget

from winder_gui.views.geometry import MandrelViewData
from winder_gui.workers import JobRunner

HEADLESS_PLATFORMS = {"offscreen", "minimal", "vnc"}


def gl_available() -> bool:
    """True when a real OpenGL 3D view can be created on this Qt platform."""
    if os.environ.get("WINDER_NO_3D", "") not in ("", "0"):
        return False
    return QGuiApplication.platformName() not in HEADLESS_PLATFORMS


def _preload_vtk(*, state: Any) -> bool:
    """Import pyvista/pyvistaqt (seconds of VTK loading) off the GUI thread."""
    import pyvista  # noqa: F401
    import pyvistaqt  # noqa: F401

    return True


class MandrelView3D(QWidget):
    """Container for the 3D view; :attr:`backend` is ``"pending"``, ``"vtk"`` or ``"placeholder"``."""

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.setMinimumSize(200, 150)
        self._layout = QVBoxLayout(self)
        self._layout.setContentsMargins(0, 0, 0, 0)
        self.backend = "pending"
        self.plotter: Any = None
        self.data: MandrelViewData | None = None
        self._scheduled = False
        self._loader: JobRunner | None = None
        self._reset_camera = True
        self._label = QLabel("3D view: loading…")
        self._label.setAlignment(Qt.AlignmentFlag.AlignCenter)
        self._label.setStyleSheet("color: #555; background: #eef0f4;")
        self._layout.addWidget(self._label)

    # -- lifecycle -------------------------------------------------------------------------------
    def showEvent(self, event) -> None:  # noqa: N802 - Qt override
        super().showEvent(event)
        self._maybe_start()

    def _maybe_start(self) -> None:
        """Start loading the backend once the view is visible and has a mandrel to show (plots first)."""
        if self.backend == "pending" and not self._scheduled and self.isVisible() and self.data is not None:
            self._scheduled = True
            if gl_available():
                # import VTK in a worker so the GUI stays live; only the widget is made on the GUI thread
                self._loader = JobRunner(self)
                self._loader.finished.connect(lambda _r: self.ensure_backend())
                self._loader.failed.connect(lambda exc, _tb: self._use_placeholder(f"3D view unavailable: {exc}"))
                self._loader.submit(_preload_vtk)
            else:
                QTimer.singleShot(0, self.ensure_backend)

    def ensure_backend(self) -> str:
        """Create the backend now if not done yet; returns :attr:`backend`."""
        if self.backend not in ("pending",):
            return self.backend
        if not gl_available():
            self._use_placeholder(f"3D view unavailable on the '{QGuiApplication.platformName()}' Qt platform")
            return self.backend
        try:
            import pyvista  # noqa: F401 - heavy, lazy on purpose
            from pyvistaqt import QtInteractor

            plotter = QtInteractor(self, auto_update=False, off_screen=False)  # PYVISTA_OFF_SCREEN must not apply here
            plotter.set_background("#f4f6fa", top="#c9d3e3")
            plotter.add_axes(interactive=False, line_width=2, labels_off=False)
        except Exception as exc:  # noqa: BLE001 - no VTK/GL: degrade to a label, the app stays usable
            print(f"winder: 3D view disabled: {exc}", file=sys.stderr)
            self._use_placeholder(f"3D view unavailable: {exc}")
            return self.backend
        self.plotter = plotter
        self._layout.removeWidget(self._label)
        self._label.hide()
        self._layout.addWidget(plotter.interactor if hasattr(plotter, "interactor") else plotter)
        self.backend = "vtk"
        if self.data is not None:
            self._render()
        return self.backend

    def _use_placeholder(self, why: str) -> None:
        self.backend = "placeholder"
        self._why = why
        self._update_label()

    def close_backend(self) -> None:
        """Release VTK resources (call before the window closes)."""
        if self._loader is not None:
            self._loader.wait(30000)
        if self.plotter is not None:
            try:
                self.plotter.close()
            finally:
                self.plotter = None
                self.backend = "closed"

    # -- data ------------------------------------------------------------------------------------
    def set_data(self, data: MandrelViewData, reset_camera: bool = False) -> None:
        """Show the revolved surface of ``data``."""
        self.data = data
        self._reset_camera = self._reset_camera or reset_camera
        self._maybe_start()
        if self.backend == "vtk":
            self._render()
        elif self.backend == "placeholder":
            self._update_label()

    def _update_label(self) -> None:
        text = getattr(self, "_why", "3D view")
        if self.data is not None:
            d = self.data
            text += (
                f"\n\nmandrel: z {d.z[0]:.1f} … {d.z[-1]:.1f} mm, r max {float(np.max(d.r)):.1f} mm,"
                f" surface grid {d.surface_x.shape[0]} × {d.surface_x.shape[1]}"
            )
        self._label.setText(text)

    def _render(self) -> None:
        import pyvista as pv

        d = self.data
        assert d is not None and self.plotter is not None
        grid = pv.StructuredGrid(d.surface_x, d.surface_y, d.surface_z)
        concave = np.repeat((d.d2r > 1e-9).astype(float)[:, None], d.surface_x.shape[1], axis=1)
        grid.point_data["concave"] = concave.ravel(order="F")
        self.plotter.add_mesh(
            grid,
            name="mandrel",
            scalars="concave",
            cmap=["#9fb3cf", "#e0504a"],
            clim=[0.0, 1.0],
            show_scalar_bar=False,
            smooth_shading=True,
            specular=0.3,
            reset_camera=False,
        )
        if self._reset_camera:
            # the axis runs left to right as in the r(z) plot, seen slightly from above and the front
            self.plotter.view_xz(negative=False)
            self.plotter.camera.elevation = 22.0
            self.plotter.camera.azimuth = -28.0
            self.plotter.reset_camera()
            self.plotter.camera.zoom(1.35)
            self._reset_camera = False
        self.plotter.render()

    def render_image(self) -> QImage | None:
        """The 3D view rendered to an image (VTK draws with GL, which ``QWidget.grab`` may miss)."""
        if self.plotter is None:
            return None
        self.plotter.render()
        arr = np.ascontiguousarray(self.plotter.screenshot(return_img=True, transparent_background=False)[:, :, :3])
        h, w = arr.shape[:2]
        return QImage(arr.data, w, h, 3 * w, QImage.Format.Format_RGB888).copy()

    def mesh_points(self) -> np.ndarray | None:
        """Points of the surface shown by the VTK backend (n, 3), or ``None``."""
        if self.plotter is None:
            return None
        actor = self.plotter.actors.get("mandrel")
        if actor is None:
            return None
        return np.asarray(actor.mapper.dataset.points)
