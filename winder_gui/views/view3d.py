"""3D view: the revolved mandrel, the winding paths, the eye trajectory and the free fibre, animated.

The pyvista/pyvistaqt backend is heavy (VTK) and is created lazily: only when the view is first
shown, and one event-loop turn later, so the main window paints before VTK loads.  pyvistaqt's
``QtInteractor`` aborts the process under ``QT_QPA_PLATFORM=offscreen`` (pyvistaqt#351); there —
or with ``WINDER_NO_3D=1``, or when VTK cannot start — the view is a placeholder label.  The real
view is tested under ``xvfb-run`` (pytest marker ``gl``).  Rendering happens on the GUI thread only;
the surface arrays come ready-made from a worker (:mod:`winder_gui.views.geometry`).

After a pipeline run, :meth:`MandrelView3D.set_paths` adds the winding line (coloured by circuit,
winding angle, λ or pull speed), the eye trajectory and the free fibre from the eye to the contact
point.  Level of detail: at rest the view draws the winding line with up to
:data:`MAX_DISPLAY_POINTS` points (all of a million-point program); while the camera moves (mouse
interaction, VTK's "desired update rate" is high) and while the animation plays it draws a coarse
copy of at most :data:`~winder_gui.views.geometry.LOD_POINTS` points instead, so rotating stays
smooth with software OpenGL (numbers in ``benchmarks/bench_gui_3d.py``); each frame is rendered once
(:func:`interactor_class`: pyvistaqt's own widget renders every frame twice).  Both copies keep every
turnaround and circuit end (:func:`~winder_gui.views.geometry.decimate_indices`).  The animation
(play / pause / scrub) moves the eye along its trajectory; the frame logic also runs with the
placeholder, so it is tested offscreen.
"""

from __future__ import annotations

import os
import sys
from typing import Any

import numpy as np
from PySide6.QtCore import Qt, QTimer
from PySide6.QtGui import QGuiApplication, QImage
from PySide6.QtWidgets import QComboBox, QHBoxLayout, QLabel, QPushButton, QSlider, QVBoxLayout, QWidget

from winder_gui.views.geometry import MandrelViewData, PathsViewData
from winder_gui.workers import JobRunner

HEADLESS_PLATFORMS = {"offscreen", "minimal", "vnc"}
MAX_DISPLAY_POINTS = 1_000_000
"""Largest number of winding-path points drawn at rest (thinned above it, keeping the turnarounds)."""
PATH_LINE_WIDTH = 1.0
"""Line width of the winding paths in pixels (wide lines cost a geometry shader per frame in llvmpipe)."""
def _env_int(name: str, default: int) -> int:
    """An integer setting from the environment; a malformed value falls back to ``default``."""
    try:
        return max(int(os.environ.get(name, "") or default), 0)
    except ValueError:
        return default


MULTI_SAMPLES = _env_int("WINDER_3D_MULTISAMPLES", 0)
"""MSAA samples of the render window (``WINDER_3D_MULTISAMPLES``; 0: no anti-aliasing).  pyvista's
default of 8, and FXAA too, more than double llvmpipe's time per frame (``benchmarks/bench_gui_3d.py``);
with a GPU, 4 or 8 look smoother at no cost."""
LOD_UPDATE_RATE = 1.0
"""VTK asks for more frames per second than this while the camera moves: then the coarse paths are drawn."""
MAX_FRAMES = 20_000
"""Animation frames over the eye path (thinned by a stride above it)."""
TRAIL_FRAMES = 60
"""The eye's trajectory is drawn over the last this many frames (its whole path would hide the mandrel)."""
COLOUR_BY = ("circuit", "winding angle β [deg]", "λ [–]", "pull speed u")
FRAME_MS = 33
VTK_TITLES = dict(zip(COLOUR_BY, ("circuit", "beta (deg)", "lambda", "pull speed u"), strict=True))
"""Scalar-bar titles in ASCII (VTK's default font has no Greek letters)."""


def gl_available() -> bool:
    """True when a real OpenGL 3D view can be created on this Qt platform."""
    if os.environ.get("WINDER_NO_3D", "") not in ("", "0"):
        return False
    return QGuiApplication.platformName() not in HEADLESS_PLATFORMS


def _scene_stamp(render_window: Any) -> tuple[int, ...]:
    """What the picture of ``render_window`` depends on: its size and the modification times of its renderers,
    cameras and props (``GetRedrawMTime`` includes the mapper and its input data).  Unchanged stamp: a new
    render would draw the same picture."""
    stamp = [*render_window.GetSize(), render_window.GetMTime()]
    renderers = render_window.GetRenderers()
    renderers.InitTraversal()
    for _ in range(renderers.GetNumberOfItems()):
        ren = renderers.GetNextItem()
        stamp += [ren.GetMTime(), ren.GetActiveCamera().GetMTime()]
        props = ren.GetViewProps()
        props.InitTraversal()
        for _ in range(props.GetNumberOfItems()):
            prop = props.GetNextProp()
            stamp += [prop.GetMTime(), prop.GetRedrawMTime(), prop.GetVisibility()]
    return tuple(stamp)


_INTERACTOR_CLASS: Any = None


def interactor_class() -> Any:
    """pyvistaqt's ``QtInteractor`` that renders once per frame instead of twice (imports pyvistaqt).

    pyvistaqt's widget renders in VTK first (``plotter.render()``, or the interactor style on every mouse
    move), which schedules a Qt paint, and its ``paintGL`` then always renders again before it blits VTK's
    frame into the widget: every frame cost two renders (``benchmarks/bench_gui_3d.py``).  Here the paint
    only blits when the frame VTK finished last is still current: rendered since the last paint, the
    widget not resized or its GL context re-made since, and :func:`_scene_stamp` unchanged (pyvista may
    move the camera or change an actor without rendering: then the paint renders, as before).  A paint
    that is not preceded by a render (exposure, ``update()``, the animation) renders as before.  A mouse-drag
    frame of a million-point program: ~100 -> ~60 ms, a full-detail frame ~225 -> ~125 ms on llvmpipe.
    """
    global _INTERACTOR_CLASS
    if _INTERACTOR_CLASS is not None:
        return _INTERACTOR_CLASS
    from pyvistaqt import QtInteractor

    class SingleRenderInteractor(QtInteractor):
        def __init__(self, *args: Any, **kwargs: Any) -> None:
            self._fresh_stamp: tuple[int, ...] | None = None
            self.paint_renders = 0
            """Renders done by Qt paints (the others were done before the paint, which only blitted)."""
            self.blit_only_paints = 0
            """Paints that only copied VTK's last frame to the widget."""
            super().__init__(*args, **kwargs)
            rw = self.GetRenderWindow()
            tag = rw.AddObserver("EndEvent", self._on_render_end)
            if isinstance(getattr(self, "_vtk_observers", None), list):
                self._vtk_observers.append((rw, tag))  # pyvistaqt removes its observers on close

        def _on_render_end(self, *_args: Any) -> None:
            # a render outside paintGL: VTK's display framebuffer holds this picture
            in_paint = getattr(self, "_in_paint", False)
            self._fresh_stamp = None if in_paint else _scene_stamp(self.GetRenderWindow())

        def initializeGL(self) -> None:  # noqa: N802 - Qt override
            self._fresh_stamp = None
            super().initializeGL()

        def resizeGL(self, w: int, h: int) -> None:  # noqa: N802 - Qt override
            self._fresh_stamp = None
            super().resizeGL(w, h)

        def paintGL(self) -> None:  # noqa: N802 - Qt override
            rw = self.GetRenderWindow()
            fresh = (self._fresh_stamp is not None and rw is not None and "_in_paint" in self.__dict__
                     and not self._in_paint and self._fresh_stamp == _scene_stamp(rw))
            self._fresh_stamp = None
            if not fresh:
                self.paint_renders += 1
                super().paintGL()
                return
            self.blit_only_paints += 1
            self._in_paint = True  # pyvistaqt's paintGL then blits VTK's last frame without rendering
            try:
                super().paintGL()
            finally:
                self._in_paint = False

    _INTERACTOR_CLASS = SingleRenderInteractor
    return _INTERACTOR_CLASS


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
        self.paths: PathsViewData | None = None
        self.gl_widget: QWidget | None = None
        """The VTK render widget (below the animation controls), once created."""
        self.colour_by = COLOUR_BY[0]
        self.frame = 0
        self.lod_active = False
        """True while the coarse copy of the paths is drawn (camera moving, animation playing or the
        engine busy -- a full-detail frame of a million points takes ~0.25 s on software GL, longer
        than the GUI thread may be held while the engine works)."""
        self._eye_meshes: dict[str, Any] = {}
        self._path_meshes: dict[str, Any] = {}
        self._was_busy = False
        self._anim = QTimer(self)
        self._anim.setInterval(FRAME_MS)
        self._anim.timeout.connect(self._tick)
        self._build_controls()
        self._label = QLabel("3D view: loading…")
        self._label.setAlignment(Qt.AlignmentFlag.AlignCenter)
        self._label.setStyleSheet("color: #555; background: #eef0f4;")
        self._layout.addWidget(self._label, 1)

    def _build_controls(self) -> None:
        bar = QWidget()
        h = QHBoxLayout(bar)
        h.setContentsMargins(4, 2, 4, 2)
        self.play_button = QPushButton("▶ Play")
        self.play_button.setObjectName("view3d.play")
        self.play_button.setCheckable(True)
        self.play_button.setToolTip("Animate the winding: the eye moves along its path (Space)")
        self.play_button.toggled.connect(self._on_play)
        self.slider = QSlider(Qt.Orientation.Horizontal)
        self.slider.setObjectName("view3d.scrub")
        self.slider.setToolTip("Scrub through the winding")
        self.slider.valueChanged.connect(self.set_frame)
        self.colour_combo = QComboBox()
        self.colour_combo.setObjectName("view3d.colour")
        self.colour_combo.addItems(list(COLOUR_BY))
        self.colour_combo.setToolTip("Colour the winding paths by")
        self.colour_combo.currentTextChanged.connect(self.set_colour_by)
        self.frame_label = QLabel("")
        self.frame_label.setMinimumWidth(120)
        h.addWidget(self.play_button)
        h.addWidget(self.slider, 1)
        h.addWidget(self.frame_label)
        h.addWidget(QLabel("colour:"))
        h.addWidget(self.colour_combo)
        self.controls = bar
        self._layout.addWidget(bar)
        self._set_controls_enabled(False)

    def _set_controls_enabled(self, on: bool) -> None:
        for w in (self.play_button, self.slider, self.colour_combo):
            w.setEnabled(on)

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
            # off_screen=False: PYVISTA_OFF_SCREEN must not apply here
            plotter = interactor_class()(self, auto_update=False, off_screen=False, multi_samples=MULTI_SAMPLES)
            plotter.set_background("#f4f6fa", top="#c9d3e3")
            plotter.add_axes(interactive=False, line_width=2, labels_off=False)
            plotter.renderer.AddObserver("StartEvent", self._choose_detail)
        except Exception as exc:  # noqa: BLE001 - no VTK/GL: degrade to a label, the app stays usable
            print(f"winder: 3D view disabled: {exc}", file=sys.stderr)
            self._use_placeholder(f"3D view unavailable: {exc}")
            return self.backend
        self.plotter = plotter
        self._layout.removeWidget(self._label)
        self._label.hide()
        self.gl_widget = plotter.interactor if hasattr(plotter, "interactor") else plotter
        self._layout.addWidget(self.gl_widget, 1)
        self.backend = "vtk"
        if self.data is not None:
            self._render()
        if self.paths is not None:
            self._render_paths()
            self.frame_all()
        return self.backend

    def _use_placeholder(self, why: str) -> None:
        self.backend = "placeholder"
        self._why = why
        self._update_label()

    def close_backend(self) -> None:
        """Release VTK resources (call before the window closes)."""
        self._anim.stop()
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
        if self.paths is not None:
            p = self.paths
            text += (f"\nwinding paths: {p.n_line} points ({p.line_xyz.shape[0]} shown), coloured by {self.colour_by}"
                     f"\n{self._frame_text()}")
        self._label.setText(text)

    # -- winding paths and animation -------------------------------------------------------------
    def set_paths(self, paths: PathsViewData | None) -> None:
        """Show the winding paths, eye trajectory and fibre of a pipeline result (``None``: remove them)."""
        self.paths = paths
        n = 0 if paths is None else paths.frame_index.size
        self._set_controls_enabled(n > 0)
        self.slider.blockSignals(True)
        self.slider.setRange(0, max(n - 1, 0))
        self.slider.setValue(min(self.frame, max(n - 1, 0)))
        self.slider.blockSignals(False)
        self.frame = self.slider.value()
        if n == 0:
            self.pause()
        if self.backend == "vtk":
            self._render_paths()
            if paths is not None:
                self.frame_all()   # the mandrel, the whole eye path and the head in view after a run
        elif self.backend == "placeholder":
            self._update_label()
        self.frame_label.setText(self._frame_text(short=True))

    def colour_scalars(self) -> np.ndarray | None:
        """The colour values of the shown path points for the current :attr:`colour_by`."""
        if self.paths is None:
            return None
        key = {"circuit": "circuit", "winding angle β [deg]": "beta_deg", "λ [–]": "lam", "pull speed u": "u"}
        return self.paths.scalars[key[self.colour_by]]

    def set_colour_by(self, name: str) -> None:
        """Colour the paths by ``name`` (one of :data:`COLOUR_BY`)."""
        if name not in COLOUR_BY:
            raise ValueError(f"colour by one of {COLOUR_BY}, not {name!r}")
        self.colour_by = name
        if self.colour_combo.currentText() != name:
            self.colour_combo.setCurrentText(name)
        if self.backend == "vtk" and self.paths is not None:
            self._render_paths()
        elif self.backend == "placeholder":
            self._update_label()

    def eye_at_frame(self) -> tuple[np.ndarray, np.ndarray] | None:
        """(eye, contact) positions of the current frame in the view frame (mm)."""
        if self.paths is None or self.paths.frame_index.size == 0:
            return None
        return self.paths.eye_xyz[self.frame], self.paths.contact_xyz[self.frame]

    def set_frame(self, i: int) -> None:
        """Move the animation to frame ``i`` (the eye and the free fibre follow)."""
        if self.paths is None or self.paths.frame_index.size == 0:
            return
        i = int(np.clip(i, 0, self.paths.frame_index.size - 1))
        self.frame = i
        if self.slider.value() != i:
            self.slider.blockSignals(True)
            self.slider.setValue(i)
            self.slider.blockSignals(False)
        self.frame_label.setText(self._frame_text(short=True))
        if self.backend == "vtk":
            self._update_eye()

    def play(self) -> None:
        """Start the animation."""
        if self.paths is not None and self.paths.frame_index.size:
            self.play_button.setChecked(True)

    def pause(self) -> None:
        """Stop the animation (at the current frame)."""
        self.play_button.setChecked(False)

    def is_playing(self) -> bool:
        return self._anim.isActive()

    def _on_play(self, on: bool) -> None:
        self.play_button.setText("⏸ Pause" if on else "▶ Play")
        if on:
            self._anim.start()
        else:
            self._anim.stop()
            if self.plotter is not None and self.lod_active:
                self.plotter.render()  # back to the full line

    def _tick(self) -> None:
        if self.paths is None or self.paths.frame_index.size == 0:
            self.pause()
            return
        n = self.paths.frame_index.size
        self.set_frame((self.frame + max(1, n // 3000)) % n)  # a whole program plays in about 100 s

    def _frame_text(self, short: bool = False) -> str:
        if self.paths is None or self.paths.frame_index.size == 0:
            return ""
        n = self.paths.frame_index.size
        point = int(self.paths.frame_index[self.frame])
        return f"frame {self.frame + 1}/{n}" + ("" if short else f" (path point {point})")

    def _render_paths(self) -> None:

        assert self.plotter is not None
        for name in ("paths", "paths_lod", "eye_path", "eye", "fibre"):
            self.plotter.remove_actor(name, render=False)
        self._eye_meshes.clear()
        self._path_meshes.clear()
        p = self.paths
        if p is None or p.line_xyz.shape[0] < 2:
            self.plotter.render()
            return
        c = np.asarray(self.colour_scalars(), dtype=float)
        cmap = "tab20" if self.colour_by == "circuit" else "viridis"
        finite = c[np.isfinite(c)]
        clim = (float(finite.min()), float(finite.max())) if finite.size else (0.0, 1.0)
        if clim[1] <= clim[0]:
            clim = (clim[0] - 0.5, clim[0] + 0.5)
        lod = p.lod_index
        coarse = lod is not None and 2 <= lod.size < p.line_xyz.shape[0]
        # pyvista renders inside add_mesh/add_scalar_bar even with render=False (twice here, ~40 ms
        # each at 1e5 points on software GL, on the GUI thread): build everything, then render once
        self.plotter.suppress_rendering = True
        try:
            self._add_path_actors(p, c, cmap, clim, lod if coarse else None)
            self._update_eye()
        finally:
            self.plotter.suppress_rendering = False
        self.plotter.render()

    def _add_path_actors(self, p: PathsViewData, c: np.ndarray, cmap: str, clim: tuple[float, float],
                         lod: np.ndarray | None) -> None:
        import pyvista as pv

        for name, idx in (("paths", None), ("paths_lod", lod)):
            if name == "paths_lod" and lod is None:
                continue
            line = pv.lines_from_points(p.line_xyz if idx is None else p.line_xyz[idx])
            line.point_data["c"] = c if idx is None else c[idx]
            self._path_meshes[name] = line
            actor = self.plotter.add_mesh(
                line, name=name, scalars="c", cmap=cmap, clim=clim, line_width=PATH_LINE_WIDTH,
                show_scalar_bar=name == "paths", reset_camera=False, render=False,
                scalar_bar_args={"title": VTK_TITLES[self.colour_by], "vertical": True})
            if name == "paths_lod":
                actor.SetVisibility(False)

    def set_busy(self, busy: bool) -> None:
        """Whether the engine is computing: the coarse paths are drawn meanwhile, the full ones after."""
        busy = bool(busy)
        if busy == self._was_busy:
            return
        self._was_busy = busy
        if self.plotter is not None and self.plotter.actors.get("paths_lod") is not None:
            self.plotter.render()                   # _choose_detail runs at the start of the render

    def _choose_detail(self, *_args: Any) -> None:
        """Renderer start: draw the coarse paths while the camera moves or the animation plays."""
        if self.plotter is None:
            return
        full, lod = self.plotter.actors.get("paths"), self.plotter.actors.get("paths_lod")
        moving = self.plotter.render_window.GetDesiredUpdateRate() > LOD_UPDATE_RATE
        self.lod_active = lod is not None and (moving or self._anim.isActive() or self._was_busy)
        if lod is not None:
            lod.SetVisibility(self.lod_active)
        if full is not None:
            full.SetVisibility(not self.lod_active)

    def shown_path_points(self) -> np.ndarray | None:
        """Points of the winding line as drawn by the last render (the coarse copy while moving)."""
        return self.actor_points("paths_lod" if self.lod_active else "paths")

    def _update_eye(self) -> None:
        """Move the eye, the fibre and the eye's trail to the current frame and render once.

        The three small meshes are made once per path set and then updated in place (a new actor
        per frame would cost a render each in pyvista's ``add_mesh``).
        """
        import pyvista as pv

        at = self.eye_at_frame()
        if at is None or self.plotter is None:
            return
        eye, contact = at
        actors = self.plotter.actors
        meshes = self._eye_meshes
        if "eye" not in actors or "eye" not in meshes:
            size = 0.03 * float(np.max(np.abs(self.paths.line_xyz[:, 1:]))) if self.paths is not None else 3.0
            meshes["eye"] = pv.Sphere(radius=size, center=(0.0, 0.0, 0.0))
            meshes["eye0"] = np.array(meshes["eye"].points)
            self.plotter.add_mesh(meshes["eye"], name="eye", color="#e0201a", reset_camera=False, render=False)
        meshes["eye"].points = meshes["eye0"] + eye
        if "fibre" not in actors or "fibre" not in meshes:
            meshes["fibre"] = pv.Line(contact, eye)
            self.plotter.add_mesh(meshes["fibre"], name="fibre", color="#202020", line_width=3, reset_camera=False,
                                  render=False)
        else:
            meshes["fibre"].points = np.array([contact, eye], dtype=float)
        trail = self.trail()
        if trail is not None and trail.shape[0] >= 2:
            if "eye_path" not in actors or "eye_path" not in meshes:
                meshes["eye_path"] = pv.lines_from_points(trail)
                self.plotter.add_mesh(meshes["eye_path"], name="eye_path", color="#e07b00", line_width=2.5,
                                      reset_camera=False, render=False)
            else:
                meshes["eye_path"].copy_from(pv.lines_from_points(trail))
        elif "eye_path" in actors:
            self.plotter.remove_actor("eye_path", render=False)
            meshes.pop("eye_path", None)
        if self._anim.isActive() and self.gl_widget is not None:
            self.gl_widget.update()  # playing: render in the next paint (frames the GUI cannot keep up with merge)
        else:
            self.plotter.render()

    def trail(self) -> np.ndarray | None:
        """The eye's trajectory over the last :data:`TRAIL_FRAMES` frames up to the current one (view frame)."""
        if self.paths is None or self.paths.frame_index.size == 0:
            return None
        return self.paths.eye_xyz[max(0, self.frame - TRAIL_FRAMES): self.frame + 1]

    def path_mesh(self, name: str = "paths") -> Any:
        """The pyvista mesh of the winding line drawn at rest (``paths``) or while moving (``paths_lod``).

        Kept here: pyvista's ``actor.mapper.dataset`` of an actor that was hidden at the last render
        can be an empty pipeline output.
        """
        return self._path_meshes.get(name)

    def actor_points(self, name: str) -> np.ndarray | None:
        """Points of a VTK actor (``paths``, ``paths_lod``, ``eye_path``, ``eye``, ``fibre``), or ``None``."""
        if self.plotter is None:
            return None
        if name in self._path_meshes and name in self.plotter.actors:
            return np.asarray(self._path_meshes[name].points)
        actor = self.plotter.actors.get(name)
        if actor is None:
            return None
        return np.asarray(actor.mapper.dataset.points)

    def _render(self) -> None:
        import pyvista as pv

        d = self.data
        assert d is not None and self.plotter is not None
        grid = pv.StructuredGrid(d.surface_x, d.surface_y, d.surface_z)
        # the engine's concave zones (those a fibre would bridge), not every sign change of r''
        zin = np.zeros(d.z.size, bool)
        for z0, z1 in d.concave:
            zin |= (d.z >= z0) & (d.z <= z1)
        concave = np.repeat(zin.astype(float)[:, None], d.surface_x.shape[1], axis=1)
        grid.point_data["concave"] = concave.ravel(order="F")
        self.plotter.suppress_rendering = True     # one render at the end, not one inside add_mesh
        try:
            self._add_mandrel_actor(grid)
        finally:
            self.plotter.suppress_rendering = False
        self.plotter.render()

    def _add_mandrel_actor(self, grid: Any) -> None:
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
            self.frame_all(render=False)   # the whole mandrel (and eye path) in view, also after a STEP import
            self._reset_camera = False

    def scene_points(self) -> np.ndarray:
        """Points that must be in view (view frame, mm): the mandrel's surface, the eye trajectory and
        the winding paths' extremes."""
        pts = []
        if self.data is not None:
            d = self.data
            pts.append(np.column_stack([d.surface_x.ravel(), d.surface_y.ravel(), d.surface_z.ravel()])[::7])
        if self.paths is not None and self.paths.eye_xyz.size:
            pts.append(self.paths.eye_xyz)
        return np.vstack(pts) if pts else np.zeros((0, 3))

    def frame_all(self, render: bool = True) -> None:
        """Frame the mandrel, the whole eye trajectory and the head (auto-framing after a run; View ->
        Frame all)."""
        pts = self.scene_points()
        if self.plotter is None or pts.shape[0] == 0:
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
        ren = self.plotter.renderer
        w, h = self.plotter.render_window.GetSize()
        out = np.zeros(len(pts), dtype=bool)
        for i, p in enumerate(np.asarray(pts, dtype=float)):
            ren.SetWorldPoint(float(p[0]), float(p[1]), float(p[2]), 1.0)
            ren.WorldToDisplay()
            x, y, _z = ren.GetDisplayPoint()
            out[i] = margin * w <= x <= (1 - margin) * w and margin * h <= y <= (1 - margin) * h
        return out

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
