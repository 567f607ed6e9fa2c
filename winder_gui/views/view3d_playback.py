"""Playback, band and camera of the 3D view (mixins of :class:`winder_gui.views.view3d.MandrelView3D`).

The program plays in machine time (:class:`winder_gui.views.playback.Timeline`): a slider in tenths
of a second, speeds ×1…×1000, a jump to a circuit and, for a laminate, to a layer (playing goes on
from one layer to the next, the read-out in the whole program's time); the band of true width is laid as the time
advances (one mesh of every quad, whose cell list is cut at the quads laid by then);
camera presets and framing of the mandrel with the whole eye path.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from PySide6.QtCore import QElapsedTimer, Qt
from PySide6.QtWidgets import (
    QCheckBox,
    QComboBox,
    QHBoxLayout,
    QLabel,
    QPushButton,
    QSlider,
    QSpinBox,
    QStyle,
    QToolButton,
    QWidget,
)

from winder_gui.i18n import tr
from winder_gui.views.geometry import PathsViewData
from winder_gui.views.playback import SPEEDS, Timeline

FRAME_MS = 40
"""Animation timer interval (25 frames/s); the program time advances by the wall time times the speed."""
SLIDER_STEPS_PER_S = 10
"""The time slider moves in tenths of a machine second."""
CAMERA_PRESETS = ("iso", "side", "axis")
EYE_PATH_LOD_POINTS = 3000
MIN_FRAME_PX = 16
"""A viewport smaller than this (px, either side) is not laid out yet: framing waits for its real size."""
"""Points of the thinned eye path drawn while playing or moving (the whole path: up to 20 000 frames)."""
COLOUR_KEYS = {"circuit": "circuit", "winding angle β [deg]": "beta_deg", "λ [–]": "lam", "pull speed u": "u"}


class PlaybackMixin:
    """Controls and machine-time animation (needs ``paths``, ``plotter``, ``backend``, ``_anim``,
    ``_layout``, ``_update_eye`` of the view)."""

    paths: PathsViewData | None
    timeline: Timeline | None

    def _build_controls(self) -> None:
        bar = QWidget()
        h = QHBoxLayout(bar)
        h.setContentsMargins(4, 2, 4, 2)
        self.play_button = QPushButton(tr("Play"))
        self.play_button.setObjectName("view3d.play")
        self.play_button.setCheckable(True)
        self.play_button.setIcon(self.style().standardIcon(QStyle.StandardPixmap.SP_MediaPlay))
        self.play_button.setToolTip(tr("Play the program in machine time: the eye moves, the band is laid (Space)"))
        self.play_button.toggled.connect(self._on_play)
        self.slider = QSlider(Qt.Orientation.Horizontal)
        self.slider.setObjectName("view3d.scrub")
        self.slider.setToolTip(tr("Program time: scrub to see the band laid up to that time"))
        self.slider.valueChanged.connect(self._on_slider)
        self.speed_combo = QComboBox()
        self.speed_combo.setObjectName("view3d.speed")
        for sp in SPEEDS:
            self.speed_combo.addItem(f"×{sp}", sp)
        self.speed_combo.setCurrentIndex(SPEEDS.index(100))
        self.speed_combo.setToolTip(tr("Playback speed: machine seconds per second"))
        self.circuit_spin = QSpinBox()
        self.circuit_spin.setObjectName("view3d.circuit")
        self.circuit_spin.setPrefix(tr("circuit "))
        self.circuit_spin.setToolTip(tr("Jump to the start of a circuit"))
        self.circuit_spin.editingFinished.connect(lambda: self.jump_to_circuit(self.circuit_spin.value()))
        self.layer_combo = QComboBox()
        self.layer_combo.setObjectName("view3d.layer")
        self.layer_combo.setToolTip(tr("Jump to the start of a layer of the laminate; playing goes on through the "
                                    "layers in winding order"))
        self.layer_combo.activated.connect(lambda i: self.jump_to_layer(int(self.layer_combo.itemData(i))))
        self.layer_combo.setVisible(False)
        self.frame_label = QLabel("")
        self.frame_label.setObjectName("view3d.time")
        self.frame_label.setMinimumWidth(150)
        for w in (self.play_button, self.slider, self.frame_label, self.speed_combo, self.layer_combo,
                  self.circuit_spin):
            h.addWidget(w, 1 if w is self.slider else 0)
        bar2 = QWidget()
        h2 = QHBoxLayout(bar2)
        h2.setContentsMargins(4, 0, 4, 2)
        self.colour_combo = QComboBox()
        self.colour_combo.setObjectName("view3d.colour")
        self.colour_combo.addItems(list(COLOUR_KEYS))
        self.colour_combo.setToolTip(tr("Colour the winding paths and the band by"))
        self.colour_combo.currentTextChanged.connect(self.set_colour_by)
        h2.addWidget(QLabel(tr("colour:")))
        h2.addWidget(self.colour_combo)
        h2.addStretch(1)
        self.machine_check = QCheckBox(tr("machine"))
        self.machine_check.setObjectName("view3d.machine")
        self.machine_check.setChecked(True)
        self.machine_check.setToolTip(tr("Show the carriage, cross-slide / robot links and payout head, posed by the "
                                      "machine's forward kinematics at the current time"))
        self.machine_check.toggled.connect(self.set_machine_visible)
        h2.addWidget(self.machine_check)
        h2.addWidget(QLabel(tr("view:")))
        self.camera_buttons: dict[str, QToolButton] = {}
        for key, text, tip in (("iso", tr("Iso"), tr("Isometric view")), ("side", tr("Side"),
                                                                          tr("Side view (the axis across)")),
                               ("axis", tr("Axis"), tr("Along the mandrel axis")),
                               ("fit", tr("Fit"), tr("Frame the mandrel, the eye path and the head"))):
            b = QToolButton()
            b.setObjectName(f"view3d.camera.{key}")
            b.setText(text)
            b.setToolTip(tip)
            b.clicked.connect(lambda _c=False, k=key: self.frame_all() if k == "fit" else self.set_camera(k))
            self.camera_buttons[key] = b
            h2.addWidget(b)
        self.controls = bar
        self._layout.addWidget(bar)
        self._layout.addWidget(bar2)
        self.timeline: Timeline | None = None
        self.time_s = 0.0
        self.layers: list[tuple[int, str, float]] = []
        """The laminate's wound layers (job index, label, program time s at which it starts) in winding order;
        empty for a single line."""
        self.program_total_s: float | None = None
        """The whole (joined) program's time when a laminate is shown, else ``None``."""
        self.layer_index = -1
        """The job layer whose paths are shown (-1: a single line)."""
        self._clock = QElapsedTimer()
        self._set_controls_enabled(False)

    def _set_controls_enabled(self, on: bool) -> None:
        for w in (self.play_button, self.slider, self.colour_combo, self.speed_combo, self.circuit_spin):
            w.setEnabled(on)

    def set_frame(self, i: int) -> None:
        """Move the animation to frame ``i`` (its machine time; the eye, fibre and band follow)."""
        if self.paths is None or self.paths.frame_index.size == 0 or self.timeline is None:
            return
        i = int(np.clip(i, 0, self.paths.frame_index.size - 1))
        self._show(i, float(self.timeline.times[i]))

    def set_time(self, t: float) -> None:
        """Move the animation to machine time ``t`` (s): the eye at its place then, the band laid up to it."""
        if self.timeline is None:
            return
        t = float(np.clip(t, 0.0, self.timeline.total_s))
        self._show(self.timeline.frame_at(t), t)

    def jump_to_circuit(self, circuit: int) -> None:
        """Move to the first frame of ``circuit``."""
        if self.timeline is not None:
            self.set_frame(self.timeline.circuit_start(int(circuit)))

    def set_layers(self, layers: list[tuple[int, str, float]], program_total_s: float | None) -> None:
        """The laminate's wound layers (job index, label, start time in the program, s) and the program's
        total time (s): the layer chooser, program times in the read-out and play on through the layers.
        An empty list: a single line."""
        self.layers = list(layers)
        self.program_total_s = program_total_s if self.layers else None
        self.layer_combo.blockSignals(True)
        self.layer_combo.clear()
        for index, label, _t0 in self.layers:
            self.layer_combo.addItem(label, index)
        self.layer_combo.blockSignals(False)
        self.layer_combo.setVisible(bool(self.layers))
        self._sync_layer_combo()

    def set_layer_shown(self, index: int) -> None:
        """The paths shown are job layer ``index``'s (the laminate presenter calls this with set_paths)."""
        self.layer_index = int(index)
        self._sync_layer_combo()
        self.frame_label.setText(self._frame_text(short=True))

    def _sync_layer_combo(self) -> None:
        i = self.layer_combo.findData(self.layer_index)
        if i >= 0 and i != self.layer_combo.currentIndex():
            self.layer_combo.blockSignals(True)
            self.layer_combo.setCurrentIndex(i)
            self.layer_combo.blockSignals(False)

    def layer_start_s(self) -> float:
        """Program time (s) at which the shown layer starts (0 for a single line)."""
        for index, _label, t0 in self.layers:
            if index == self.layer_index:
                return float(t0)
        return 0.0

    def program_time_s(self) -> float:
        """The time shown in the whole program (s): the layer's start plus the time within the layer."""
        return self.layer_start_s() + self.time_s

    def jump_to_layer(self, index: int) -> None:
        """Show job layer ``index`` (``layer_requested``: the laminate presenter swaps the paths) from its start."""
        if index != self.layer_index:
            self.layer_requested.emit(int(index))
        self.set_time(0.0)

    def _next_layer(self) -> int | None:
        ids = [i for i, _l, _t in self.layers]
        if self.layer_index in ids:
            k = ids.index(self.layer_index)
            if k + 1 < len(ids):
                return ids[k + 1]
        return None

    def _show(self, frame: int, t: float) -> None:
        self.frame = frame
        self.time_s = t
        self._sync_slider()
        self.frame_label.setText(self._frame_text(short=True))
        if self.backend == "vtk":
            self._update_eye()

    def _sync_slider(self) -> None:
        v = int(round(self.time_s * SLIDER_STEPS_PER_S))
        if self.slider.value() != v:
            self.slider.blockSignals(True)
            self.slider.setValue(v)
            self.slider.blockSignals(False)
        if self.timeline is not None and self.timeline.circuits.size:
            self.circuit_spin.blockSignals(True)
            self.circuit_spin.setValue(int(self.timeline.circuits[self.frame]))
            self.circuit_spin.blockSignals(False)

    def _on_slider(self, value: int) -> None:
        self.set_time(value / SLIDER_STEPS_PER_S)

    def speed(self) -> float:
        """Playback speed (machine seconds per wall-clock second)."""
        return float(self.speed_combo.currentData() or 1)

    def set_speed(self, speed: int) -> None:
        self.speed_combo.setCurrentIndex(max(self.speed_combo.findData(int(speed)), 0))

    def play(self) -> None:
        """Start the animation (from the start when at the end)."""
        if self.paths is not None and self.paths.frame_index.size:
            if self.timeline is not None and self.time_s >= self.timeline.total_s:
                self.set_time(0.0)
            self.play_button.setChecked(True)

    def pause(self) -> None:
        """Stop the animation (at the current time)."""
        self.play_button.setChecked(False)

    def is_playing(self) -> bool:
        return self._anim.isActive()

    def _on_play(self, on: bool) -> None:
        self.play_button.setText(tr("Pause") if on else tr("Play"))
        self.play_button.setIcon(self.style().standardIcon(
            QStyle.StandardPixmap.SP_MediaPause if on else QStyle.StandardPixmap.SP_MediaPlay))
        if on:
            self._clock.start()
            self._anim.start()
        else:
            self._anim.stop()
            if self.plotter is not None and self.lod_active:
                self.plotter.render()  # back to the full line

    def _tick(self) -> None:
        if self.paths is None or self.paths.frame_index.size == 0 or self.timeline is None:
            self.pause()
            return
        dt = self._clock.restart() / 1000.0
        t = self.time_s + self.speed() * dt
        if t >= self.timeline.total_s:
            nxt = self._next_layer()
            if nxt is None:
                self.set_time(self.timeline.total_s)
                self.pause()
                return
            carry = t - self.timeline.total_s  # a laminate: on into the next layer (its paths, its surface)
            self.layer_requested.emit(nxt)
            if self.layer_index != nxt or self.timeline is None:
                self.pause()
                return
            self.set_time(min(carry, self.timeline.total_s))
            return
        self.set_time(t)

    def _frame_text(self, short: bool = False) -> str:
        if self.paths is None or self.paths.frame_index.size == 0 or self.timeline is None:
            return ""
        tl = self.timeline
        circ = f" · circuit {int(tl.circuits[self.frame])}" if tl.circuits.size else ""
        if self.program_total_s is not None and self.layer_index >= 0:
            text = f"t {self.program_time_s():.1f} / {self.program_total_s:.1f} s"
        else:
            text = f"t {self.time_s:.1f} / {tl.total_s:.1f} s"
        return text if short else f"{text}{circ} (frame {self.frame + 1}/{tl.times.size})"


class SceneMixin:
    """The band laid so far, camera presets and framing (needs ``plotter``, ``paths``, ``data``)."""

    def _add_band_actor(self, p: PathsViewData, cmap: str, clim: tuple[float, float]) -> dict[str, Any] | None:
        """The whole eye trajectory (thin; a thinned copy drawn while playing) and the band of true width.

        The band is one mesh of every quad (points and colours uploaded once); the band laid by a time is
        its first ``k`` quads (:meth:`_update_band` replaces only the cell list).  Returns the band's state,
        or ``None`` without a band."""
        import pyvista as pv

        if p.eye_xyz.shape[0] >= 2:
            self.plotter.add_mesh(pv.lines_from_points(p.eye_xyz), name="eye_path_all", color="#ecd2a8",
                                  line_width=1.0, reset_camera=False, render=False)
            stride = max(1, -(-p.eye_xyz.shape[0] // EYE_PATH_LOD_POINTS))
            coarse = np.vstack([p.eye_xyz[::stride], p.eye_xyz[-1:]])
            lod = self.plotter.add_mesh(pv.lines_from_points(coarse), name="eye_path_lod", color="#ecd2a8",
                                        line_width=1.0, reset_camera=False, render=False)
            lod.SetVisibility(False)
        band = p.band
        if band is None or band.m < 2 or p.band_scalars is None:
            return None
        from vtkmodules.vtkCommonDataModel import vtkCellArray

        sc = np.asarray(p.band_scalars[COLOUR_KEYS[self.colour_by]], dtype=float)
        m = band.m
        i = np.arange(m - 1, dtype=np.int64)
        conn = np.column_stack([i, i + 1, m + i + 1, m + i]).ravel()   # quad i: centre points i, i + 1
        mesh = pv.PolyData()   # (not PolyData(points): that makes a vertex cell per point)
        mesh.points = np.asarray(band.points, dtype=float)
        mesh.SetPolys(vtkCellArray())
        mesh.point_data["c"] = np.concatenate([sc, sc])
        actor = self.plotter.add_mesh(mesh, name="band", scalars="c", cmap=cmap, clim=clim, show_scalar_bar=False,
                                      reset_camera=False, render=False)
        actor.SetVisibility(False)   # its quads are given when the band is shown (_update_band)
        return {"band": band, "mesh": mesh, "conn": conn, "actor": actor, "last": None}

    def _update_band(self) -> None:
        """Show the band laid by :attr:`time_s`: its first quads (the cell list replaced, points kept)."""
        if self._band is None:
            return
        bd = self._band
        k = bd["band"].quads_until(self.time_s)
        self.band_quads = k
        if bd["last"] == k:
            return
        bd["last"] = k
        from vtkmodules.util.numpy_support import numpy_to_vtkIdTypeArray
        from vtkmodules.vtkCommonDataModel import vtkCellArray

        cells = vtkCellArray()
        cells.SetData(numpy_to_vtkIdTypeArray(np.arange(0, 4 * k + 1, 4, dtype=np.int64), deep=True),
                      numpy_to_vtkIdTypeArray(bd["conn"][:4 * k], deep=True))
        bd["mesh"].SetPolys(cells)
        bd["actor"].SetVisibility(k > 0)

    def band_cells(self) -> int:
        """Quads of the band drawn now (the band actor's cells; 0 when it is hidden)."""
        bd = self._band
        if bd is None or not bd["actor"].GetVisibility():
            return 0
        return int(bd["mesh"].GetNumberOfCells())

    def set_camera(self, preset: str) -> None:
        """Camera preset: ``iso`` (from above and the front), ``side`` (the axis across the view) or
        ``axis`` (along the mandrel axis); then frame the scene."""
        if preset not in CAMERA_PRESETS:
            raise ValueError(f"camera preset one of {CAMERA_PRESETS}, not {preset!r}")
        if self.plotter is None:
            return
        if preset == "side":
            self.plotter.view_xz(negative=False)
        elif preset == "axis":
            self.plotter.view_yz(negative=False)
        else:
            self.plotter.view_xz(negative=False)
            self.plotter.camera.elevation = 22.0
            self.plotter.camera.azimuth = -28.0
        self.frame_all()

    def scene_points(self) -> np.ndarray:
        """Points that must be in view (view frame, mm): the mandrel's surface, the eye trajectory, the
        shafts, chuck and tailstock, and -- when the machine is shown -- the machine over the whole program
        (:meth:`machine_points`: playing, it stays in view)."""
        pts = []
        if self.data is not None:
            d = self.data
            pts.append(np.column_stack([d.surface_x.ravel(), d.surface_y.ravel(), d.surface_z.ravel()])[::7])
        if self.paths is not None and self.paths.eye_xyz.size:
            pts.append(self.paths.eye_xyz)
        for _name, z0, z1, r in self.supports:
            if z1 > z0 and r > 0:   # the cylinder's extreme points (the axis is the view's x)
                ring = np.array([[0.0, r, 0.0], [0.0, -r, 0.0], [0.0, 0.0, r], [0.0, 0.0, -r]])
                pts += [ring + [z0, 0.0, 0.0], ring + [z1, 0.0, 0.0]]
        if self.machine_visible:
            pts.append(self.machine_points())
        return np.vstack(pts) if pts else np.zeros((0, 3))

    def machine_points(self, max_frames: int = 240) -> np.ndarray:
        """The machine drawn over the program (view frame, mm): the link chain, the carriage box's reach
        and the head's far end at up to ``max_frames`` frames spread over it; empty without a machine."""
        fr = self.machine_pose()
        if fr is None or fr.links.shape[0] == 0:
            return np.zeros((0, 3))
        n = fr.links.shape[0]
        idx = np.unique(np.linspace(0, n - 1, min(n, max_frames)).round().astype(np.int64))
        h = float(self._machine.get("size", 0.0))
        box = 6.0 * h * np.vstack([np.eye(3), -np.eye(3)])   # the carriage box: at most 6 h from its centre
        out = [fr.links[idx].reshape(-1, 3), (fr.carriage[idx][:, None, :] + box[None]).reshape(-1, 3)]
        if fr.head_axis is not None:   # the head's body behind the eye, along its roll axis
            length = float(self.paths.head_mm[1]) if self.paths is not None and self.paths.head_mm[1] > 0 else 10.0 * h
            out.append(fr.eye[idx] + length * fr.head_axis[idx])
        return np.vstack(out)

    def frame_all(self, render: bool = True) -> None:
        """Frame the mandrel, the whole eye trajectory and the head (auto-framing after a run; View ->
        Frame all)."""
        pts = self.scene_points()
        if self.plotter is None or pts.shape[0] == 0:
            return
        if min(self.plotter.render_window.GetSize()) < MIN_FRAME_PX:
            # not laid out yet (0 x 0 at the first render): the zoom below would fit a viewport that is
            # not the one shown; frame once the widget has its size (View3D._gl_resized)
            self._frame_pending = True
            return
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        pad = 0.04 * float(np.max(hi - lo))
        bounds = (lo[0] - pad, hi[0] + pad, lo[1] - pad, hi[1] + pad, lo[2] - pad, hi[2] + pad)
        self.plotter.reset_camera(render=False, bounds=bounds)
        # VTK fits a sphere round the bounds: a long mandrel then fills a third of the view; zoom in
        # while every point (a sample of them) stays inside the viewport
        sample = pts[:: max(1, pts.shape[0] // 300)]
        cam = self.plotter.camera
        for _ in range(12):
            cam.zoom(1.12)
            if not self.points_in_view(sample, margin=0.03).all():
                cam.zoom(1.0 / 1.12)
                break
        if render:
            self.plotter.render()

    def points_in_view(self, pts: np.ndarray, margin: float = 0.0) -> np.ndarray:
        """For each point (view frame, mm): True when it projects inside the 3D viewport (less a
        ``margin``, a fraction of its size, on every side)."""
        if self.plotter is None:
            return np.zeros(len(pts), dtype=bool)
        x, y = self.project_points(pts)
        w, h = self.plotter.render_window.GetSize()
        return (margin * w <= x) & (x <= (1 - margin) * w) & (margin * h <= y) & (y <= (1 - margin) * h)

    def project_points(self, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Display coordinates (px) of points (view frame, mm) by the camera's projection, all at once
        (what ``vtkRenderer.WorldToDisplay`` gives one point at a time)."""
        ren = self.plotter.renderer
        m = ren.GetActiveCamera().GetCompositeProjectionTransformMatrix(ren.GetTiledAspectRatio(), -1.0, 1.0)
        mat = np.array([[m.GetElement(i, j) for j in range(4)] for i in range(4)])
        p = np.asarray(pts, dtype=float).reshape(-1, 3)
        hom = np.column_stack([p, np.ones(len(p))]) @ mat.T
        ndc = hom[:, :2] / hom[:, 3:4]
        vx0, vy0, vx1, vy1 = ren.GetViewport()
        w, h = self.plotter.render_window.GetSize()
        x = (vx0 + (ndc[:, 0] + 1.0) * 0.5 * (vx1 - vx0)) * w
        y = (vy0 + (ndc[:, 1] + 1.0) * 0.5 * (vy1 - vy0)) * h
        return x, y
