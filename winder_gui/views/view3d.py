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
from PySide6.QtCore import Qt, QTimer, Signal
from PySide6.QtGui import QGuiApplication, QImage
from PySide6.QtWidgets import (
    QLabel,
    QVBoxLayout,
    QWidget,
)

from winder_gui.i18n import tr
from winder_gui.views.geometry import MandrelViewData, PathsViewData
from winder_gui.views.playback import Timeline
from winder_gui.views.view3d_machine import MachineMixin
from winder_gui.views.view3d_playback import (
    COLOUR_KEYS,
    FRAME_MS,
    MIN_FRAME_PX,
    SLIDER_STEPS_PER_S,
    PlaybackMixin,
    SceneMixin,
)
from winder_gui.views.view3d_scenes import PATH_ACTORS, SURFACE_ACTORS, SceneCacheMixin
from winder_gui.views.vtk_widget import _preload_vtk, interactor_class
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
MANDREL_LOD_POINTS = 12000
"""Points of the mandrel's coarse copy drawn while playing or moving (rows of the surface grid dropped)."""
"""VTK asks for more frames per second than this while the camera moves: then the coarse paths are drawn."""
MAX_FRAMES = 20_000
"""Animation frames over the eye path (thinned by a stride above it)."""
TRAIL_FRAMES = 60
"""The eye's trajectory is drawn over the last this many frames (its whole path would hide the mandrel)."""
COLOUR_BY = ("circuit", "winding angle β [deg]", "λ [–]", "pull speed u")

VTK_TITLES = dict(zip(COLOUR_BY, ("circuit", "beta (deg)", "lambda", "pull speed u"), strict=True))
"""Scalar-bar titles in ASCII (VTK's default font has no Greek letters)."""


def gl_available() -> bool:
    """True when a real OpenGL 3D view can be created on this Qt platform."""
    if os.environ.get("WINDER_NO_3D", "") not in ("", "0"):
        return False
    return QGuiApplication.platformName() not in HEADLESS_PLATFORMS


class MandrelView3D(PlaybackMixin, SceneMixin, SceneCacheMixin, MachineMixin, QWidget):
    """Container for the 3D view; :attr:`backend` is ``"pending"``, ``"vtk"`` or ``"placeholder"``.

    Signals: ``layer_requested(int)`` — show job layer ``index`` of the laminate (the layer chooser, or the
    playback reaching the end of the shown layer)."""

    layer_requested = Signal(int)

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
        self._frame_pending = False
        """A framing asked for before the GL widget had its size (done at its first real size)."""
        self.paths: PathsViewData | None = None
        self.supports: list[tuple[str, float, float, float]] = []
        """The job's shafts, chuck and tailstock as drawn (:meth:`set_supports`)."""
        self.gl_widget: QWidget | None = None
        """The VTK render widget (below the animation controls), once created."""
        self.colour_by = COLOUR_BY[0]
        self.frame = 0
        self.lod_active = False
        """True while the coarse copy of the paths is drawn (camera moving, animation playing or the
        engine busy -- a full-detail frame of a million points takes ~0.25 s on software GL, longer
        than the GUI thread may be held while the engine works)."""
        self._eye_meshes: dict[str, Any] = {}
        self._band: Any = None
        self.band_quads = 0
        """Quads of the band drawn (laid by the current time)."""
        self._path_meshes: dict[str, Any] = {}
        self._was_busy = False
        self._anim = QTimer(self)
        self._anim.setInterval(FRAME_MS)
        self._anim.timeout.connect(self._tick)
        self._machine_init()
        self._scenes_init()
        self._build_controls()
        self._label = QLabel(tr("3D view: loading…"))
        self._label.setAlignment(Qt.AlignmentFlag.AlignCenter)
        self._label.setStyleSheet("color: #555; background: #eef0f4;")
        self._layout.addWidget(self._label, 1)

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
            # translucent supports blended in one pass: order-independent translucency costs llvmpipe ~4 ms a frame
            plotter.renderer.SetUseOIT(False)
        except Exception as exc:  # noqa: BLE001 - no VTK/GL: degrade to a label, the app stays usable
            print(f"winder: 3D view disabled: {exc}", file=sys.stderr)
            self._use_placeholder(f"3D view unavailable: {exc}")
            return self.backend
        self.plotter = plotter
        plotter.resized_callback = self._gl_resized
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

    def _gl_resized(self, w: int, h: int) -> None:
        """The GL widget got a size: a framing that had to wait for one is done now (after the resize)."""
        if self._frame_pending and min(w, h) >= MIN_FRAME_PX:
            self._frame_pending = False
            QTimer.singleShot(0, self.frame_all)

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
        """Show the winding paths, eye trajectory, band and fibre of a pipeline result (``None``: remove
        them).  The animation is in machine time; a new program starts at its end (all the band laid)."""
        self.paths = paths
        n = 0 if paths is None else paths.frame_index.size
        self._set_controls_enabled(n > 0)
        if paths is not None and paths.frame_time_s is not None and n:
            times = np.asarray(paths.frame_time_s, dtype=float)
        else:
            times = np.arange(n, dtype=float) * FRAME_MS / 1000.0   # no blocks: one frame per tick at ×1
        circuits = (np.asarray(paths.frame_circuit, dtype=np.int64) if paths is not None
                    and paths.frame_circuit is not None else np.zeros(n, dtype=np.int64))
        self.timeline = Timeline(times, circuits) if n else None
        self.slider.blockSignals(True)
        self.slider.setRange(0, int(round(self.timeline.total_s * SLIDER_STEPS_PER_S)) if n else 0)
        self.slider.blockSignals(False)
        if n:
            self.circuit_spin.setRange(int(circuits.min()), int(circuits.max()))
        if n == 0:
            self.pause()
        self.frame = max(n - 1, 0)
        self.time_s = self.timeline.total_s if n else 0.0
        self._sync_slider()
        if self.backend == "vtk":
            self._render_paths()
            if paths is not None and not self.is_playing():
                self.frame_all()   # the mandrel, the whole eye path and the head in view after a run
        elif self.backend == "placeholder":
            self._update_label()
        self.frame_label.setText(self._frame_text(short=True))

    def colour_scalars(self) -> np.ndarray | None:
        """The colour values of the shown path points for the current :attr:`colour_by`."""
        if self.paths is None:
            return None
        return self.paths.scalars[COLOUR_KEYS[self.colour_by]]

    def set_colour_by(self, name: str) -> None:
        """Colour the paths by ``name`` (one of :data:`COLOUR_BY`)."""
        if name not in COLOUR_BY:
            raise ValueError(f"colour by one of {COLOUR_BY}, not {name!r}")
        self.colour_by = name
        if self.colour_combo.currentText() != name:
            self.colour_combo.setCurrentText(name)
        if self.backend == "vtk":
            self.forget_scenes("paths")   # every layer's paths and band in the other colours (made again on demand)
            self._prepared["paths"] = {(k[0], k[1], name) for k in self._prepared["paths"]}
            if self.paths is not None:
                self._render_paths()
        elif self.backend == "placeholder":
            self._update_label()

    def eye_at_frame(self) -> tuple[np.ndarray, np.ndarray] | None:
        """(eye, contact) positions of the current frame in the view frame (mm)."""
        if self.paths is None or self.paths.frame_index.size == 0:
            return None
        return self.paths.eye_xyz[self.frame], self.paths.contact_xyz[self.frame]

    def _render_paths(self) -> None:
        """Show :attr:`paths`: its kept scene (a visibility swap) or a new one; the eye, fibre and machine."""
        assert self.plotter is not None
        for name in ("eye_path", "eye", "fibre"):
            self.plotter.remove_actor(name, render=False)
        self._remove_machine()
        self._eye_meshes.clear()
        self._park_scene("paths")
        self._band = None
        self._path_meshes = {}
        for title in list(self.plotter.scalar_bars.keys()):
            self.plotter.remove_scalar_bar(title, render=False)
        p = self.paths
        if p is None or p.line_xyz.shape[0] < 2:
            self.plotter.render()
            return
        # pyvista renders inside add_mesh/add_scalar_bar even with render=False (twice here, ~40 ms
        # each at 1e5 points on software GL, on the GUI thread): build everything, then render once
        self.plotter.suppress_rendering = True
        try:
            scene = self._show_scene("paths", self._paths_key(p))
            if scene is None:
                self._drop_unprepared("paths")   # an earlier run's paths: not shown again
                scene = self._build_paths_scene(p)
            self._band = scene["band"]
            if self._band is not None:
                self._band["last"] = None
            self._path_meshes = scene["meshes"]
            if scene["bar"] is not None:
                self.plotter.add_scalar_bar(mapper=scene["actors"]["paths"].mapper, **scene["bar"])
            self._update_eye()
        finally:
            self.plotter.suppress_rendering = False
        self._redraw()

    def _redraw(self) -> None:
        """Render now, or while the animation plays in its next frame's paint (no extra frame per layer)."""
        if self._anim.isActive() and self.gl_widget is not None:
            self.gl_widget.update()
        else:
            self.plotter.render()

    def _paths_key(self, p: PathsViewData) -> tuple:
        return ("paths", id(p), self.colour_by)

    def _build_paths_scene(self, p: PathsViewData) -> dict[str, Any]:
        """Make the actors of ``p`` (line, coarse line, eye path, band) as the shown paths scene."""
        c = np.asarray(p.scalars[COLOUR_KEYS[self.colour_by]], dtype=float)
        cmap = "tab20" if self.colour_by == "circuit" else "viridis"
        finite = c[np.isfinite(c)]
        clim = (float(finite.min()), float(finite.max())) if finite.size else (0.0, 1.0)
        if clim[1] <= clim[0]:
            clim = (clim[0] - 0.5, clim[0] + 0.5)
        lod = p.lod_index
        coarse = lod is not None and 2 <= lod.size < p.line_xyz.shape[0]
        self._path_meshes = {}
        bar = self._add_path_actors(p, c, cmap, clim, lod if coarse else None)
        band = self._add_band_actor(p, cmap, clim)
        return self._keep_scene("paths", self._paths_key(p), PATH_ACTORS, band=band, bar=bar, paths=p,
                                meshes=dict(self._path_meshes))

    def _add_path_actors(self, p: PathsViewData, c: np.ndarray, cmap: str, clim: tuple[float, float],
                         lod: np.ndarray | None) -> dict[str, Any] | None:
        """The line and its coarse copy; returns the scalar bar's arguments (None: one value, no bar)."""
        import pyvista as pv

        finite = c[np.isfinite(c)]
        one_value = finite.size == 0 or float(finite.min()) == float(finite.max())
        bar = {"title": VTK_TITLES[self.colour_by], "vertical": True}
        if self.colour_by == "circuit":  # whole circuit numbers on the bar
            bar.update(fmt="%.0f", n_labels=int(min(5, round(clim[1] - clim[0]) + 1)))
        for name, idx in (("paths", None), ("paths_lod", lod)):
            if name == "paths_lod" and lod is None:
                continue
            line = pv.lines_from_points(p.line_xyz if idx is None else p.line_xyz[idx])
            line.point_data["c"] = c if idx is None else c[idx]
            self._path_meshes[name] = line
            actor = self.plotter.add_mesh(
                line, name=name, scalars="c", cmap=cmap, clim=clim, line_width=PATH_LINE_WIDTH,
                show_scalar_bar=False, reset_camera=False, render=False)
            if name == "paths_lod":
                actor.SetVisibility(False)
        return None if one_value else bar  # one value (a hoop layer's one circuit): one colour, no bar

    def set_busy(self, busy: bool) -> None:
        """Whether the engine is computing: the coarse paths are drawn meanwhile, the full ones after."""
        busy = bool(busy)
        if busy == self._was_busy:
            return
        self._was_busy = busy
        if self.plotter is not None and self.plotter.actors.get("paths_lod") is not None:
            self.plotter.render()                   # _choose_detail runs at the start of the render

    def _choose_detail(self, *_args: Any) -> None:
        """Renderer start: draw the coarse paths (and mandrel) while the camera moves or the animation plays."""
        if self.plotter is None:
            return
        actors = self.plotter.actors
        full, lod = actors.get("paths"), actors.get("paths_lod")
        moving = self.plotter.render_window.GetDesiredUpdateRate() > LOD_UPDATE_RATE
        playing = moving or self._anim.isActive()
        m_full, m_lod = actors.get("mandrel"), actors.get("mandrel_lod")
        if m_full is not None and m_lod is not None:
            m_lod.SetVisibility(playing)
            m_full.SetVisibility(not playing)
        self.lod_active = lod is not None and (playing or self._was_busy)
        if lod is not None:
            lod.SetVisibility(self.lod_active)
        if full is not None:
            full.SetVisibility(not self.lod_active)
        e_full, e_lod = actors.get("eye_path_all"), actors.get("eye_path_lod")
        if e_full is not None and e_lod is not None:   # the whole eye path, thinned while playing or moving
            e_lod.SetVisibility(playing)
            e_full.SetVisibility(not playing)

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
        self._update_band()
        self._update_machine()
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
        """Show :attr:`data`: its kept surface scene (a visibility swap) or a new one."""
        d = self.data
        assert d is not None and self.plotter is not None
        self._park_scene("surface")
        self.plotter.suppress_rendering = True     # one render at the end, not one inside add_mesh
        try:
            if self._show_scene("surface", ("surface", id(d))) is None:
                self._drop_unprepared("surface")
                self._build_surface_scene(d)
            if self._reset_camera:
                # the axis runs left to right as in the r(z) plot, seen slightly from above and the front
                self.plotter.view_xz(negative=False)
                self.plotter.camera.elevation = 22.0
                self.plotter.camera.azimuth = -28.0
                self.frame_all(render=False)   # the whole mandrel (and eye path) in view, also after a STEP import
                self._reset_camera = False
        finally:
            self.plotter.suppress_rendering = False
        self._redraw()

    def _build_surface_scene(self, d: MandrelViewData) -> dict[str, Any]:
        """The revolved surface (concave zones shaded) and its coarse copy, as the shown surface scene."""
        import pyvista as pv

        grid = pv.StructuredGrid(d.surface_x, d.surface_y, d.surface_z)
        # the engine's concave zones (those a fibre would bridge), not every sign change of r''
        zin = np.zeros(d.z.size, bool)
        for z0, z1 in d.concave:
            zin |= (d.z >= z0) & (d.z <= z1)
        concave = np.repeat(zin.astype(float)[:, None], d.surface_x.shape[1], axis=1)
        grid.point_data["concave"] = concave.ravel(order="F")
        style = {"scalars": "concave", "cmap": ["#9fb3cf", "#e0504a"], "clim": [0.0, 1.0], "show_scalar_bar": False,
                 "smooth_shading": True, "specular": 0.3, "reset_camera": False, "render": False}
        self.plotter.add_mesh(grid, name="mandrel", **style)
        # a coarse copy drawn while the animation plays or the camera moves (the full surface is a
        # third of a software-GL frame)
        step = max(1, int(np.ceil(d.surface_x.size / MANDREL_LOD_POINTS)))
        coarse = pv.StructuredGrid(d.surface_x[::step], d.surface_y[::step], d.surface_z[::step])
        coarse.point_data["concave"] = concave[::step].ravel(order="F")
        self.plotter.add_mesh(coarse, name="mandrel_lod", **style)
        self.plotter.actors["mandrel_lod"].SetVisibility(False)
        return self._keep_scene("surface", ("surface", id(d)), SURFACE_ACTORS, data=d)

    def set_supports(self, supports: list[tuple[str, float, float, float]]) -> None:
        """Draw the job's shafts, chuck and tailstock: ``(name, z0, z1, radius)`` (mm, mandrel frame, the
        axis is the view's x axis); an empty list removes them."""
        self.supports = list(supports)
        if self.plotter is None:
            return
        import pyvista as pv

        for name in [n for n in self.plotter.actors if str(n).startswith("support:")]:
            self.plotter.remove_actor(name, render=False)
        for name, z0, z1, r in self.supports:
            if not (z1 > z0 and r > 0):
                continue
            cyl = pv.Cylinder(center=(0.5 * (z0 + z1), 0.0, 0.0), direction=(1.0, 0.0, 0.0), radius=r,
                              height=z1 - z0, resolution=48)
            self.plotter.add_mesh(cyl, name=f"support:{name}", color="#b5b5b5", opacity=0.55,
                                  smooth_shading=True, reset_camera=False, render=False)
        if self.paths is not None and not self.is_playing():
            self.frame_all(render=False)   # they come after the run's paths: framed with them
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
