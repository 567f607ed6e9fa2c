"""3D view interactivity with a million winding-path points (issue 9), software OpenGL (llvmpipe).

Needs a real (virtual) display; run it as::

    QT_QPA_PLATFORM=xcb xvfb-run -a -s "-screen 0 1600x1000x24" .venv/bin/python benchmarks/bench_gui_3d.py

(under ``QT_QPA_PLATFORM=offscreen``, as ``make bench`` runs it, it re-starts itself that way when
``xvfb-run`` is there).  The scene is the real :class:`winder_gui.views.view3d.MandrelView3D` at
1200 × 800 pixels: a cylinder mandrel and a synthetic winding line of ``--points`` points (helical
circuits on the cylinder, each out and back with a dwell at both ends, like
``tests/test_gui_workflow.py::test_decimation_keeps_a_million_points_interactive``).  Printed, for
display caps of 200 000, 500 000 and 1 000 000 points:

* thinning in the worker (:func:`~winder_gui.views.geometry.paths_view_data`), ms;
* building the actors (``set_paths`` including the first render), ms;
* frame time of ``--frames`` camera rotations (``camera.azimuth``, ``plotter.render()`` and Qt's paint
  of the widget), median and 95th percentile, at rest (the full line) and while moving (the coarse
  level-of-detail line), and of ``--frames`` real mouse-drag steps (Qt mouse events -> VTK's interactor
  style renders -> Qt paints), with the VTK renders per frame counted;
* one animation step (``set_frame`` while playing, and the paint), median, ms;
* resident memory (MB);

then a colour-mode switch and the frame time per colour mode, line width 1 vs 2, and one polyline
cell per circuit vs one cell per segment (plain pyvista).  ``--pyvistaqt-paint`` uses pyvistaqt's own
``QtInteractor``, whose paint renders again after every render: two renders per frame (the view's
:func:`~winder_gui.views.view3d.interactor_class` paints by blitting the frame just rendered).
``--multi-samples 8`` / ``--fxaa`` show what anti-aliasing costs.  The machine is shared: the mandrel-only
frame time is printed first as the baseline, with the process CPU time per frame (llvmpipe's threads
included) next to the wall clock.

Measured 2026-11-22 (llvmpipe, 2 CPUs at load 2.5-3, 1200 x 768 px, ``--quick``, two runs each, interleaved),
ms median wall clock, [VTK renders per frame]:

=====================  ==========================  ==========================
1 000 000 points        pyvistaqt's paint (before)  blit-only paint (now)
=====================  ==========================  ==========================
mandrel only            75-77 [2.0]                 45-48 [1.0]
rest (full line)        222-231 [2.0]               124-125 [1.0]
moving (coarse line)    107-108 [2.0]               63-64 [1.0]
real mouse drag         100-101 [2.0]               60 [1.0]
animation step          62-63 [1.0]                 60-63 [1.0]
=====================  ==========================  ==========================

(200 000 points: rest 155-159 -> 84-86, moving 109-110 -> 63-64, drag 106-109 -> 64-66 ms.)  The animation
already rendered once per step (it asks for a paint instead of rendering).
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def _rss_mb() -> float:
    with open("/proc/self/status", encoding="ascii") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    return float("nan")


def synthetic_line(n: int, circuits: int, radius: float = 50.0, length: float = 1000.0) -> SimpleNamespace:
    """A winding-line look-alike: ``circuits`` out-and-back helices on a cylinder (mm, rad)."""
    t = np.linspace(0.0, circuits, n, endpoint=False)
    ph = t % 1.0
    # out (0..0.45), dwell (0.45..0.5), back (0.5..0.95), dwell (0.95..1)
    z = np.interp(ph, [0.0, 0.45, 0.5, 0.95, 1.0], [0.0, length, length, 0.0, 0.0])
    theta = 2.0 * np.pi * (3.3 * t + 0.37 * np.floor(t))
    r = np.full(n, radius)
    xyz = np.column_stack([r * np.cos(theta), r * np.sin(theta), z])
    circuit = np.floor(t).astype(np.int64)
    beta = np.where(np.abs(np.gradient(z)) > 0, 0.6, np.pi / 2)
    lam = np.sin(theta) * 0.1
    line = SimpleNamespace(z=z, r=r, xyz=xyz, beta=beta, lam=lam, circuit=circuit)
    eye = SimpleNamespace(u=1.0 + 0.5 * np.cos(theta[:-1]), eye_xyz=xyz * [1.5, 1.5, 1.0], contact_xyz=xyz)
    return SimpleNamespace(line=line, eye=eye)


def cylinder_data(radius: float = 50.0, length: float = 1000.0):  # noqa: ANN201 - MandrelViewData
    from winder_gui.views.geometry import MandrelViewData

    z = np.linspace(0.0, length, 200)
    r = np.full(z.size, radius)
    th = np.linspace(0.0, 2 * np.pi, 73)
    return MandrelViewData(z, r, np.zeros(z.size), (), z[::50], r[::50], np.repeat(z[:, None], 73, axis=1),
                           r[:, None] * np.cos(th)[None, :], r[:, None] * np.sin(th)[None, :])


def _ms(samples: list[float]) -> tuple[float, float]:
    a = np.asarray(samples) * 1e3
    return float(np.median(a)), float(np.percentile(a, 95))


CPU: list[float] = []
"""Process CPU time (all threads, llvmpipe's included) of each frame timed last, s."""
RENDERS = [0]
"""VTK renders (render-window EndEvents) so far."""
PER_FRAME: list[float] = []
"""VTK renders per frame of the frames timed last."""


def frame(view) -> None:  # noqa: ANN001
    """One frame as the user sees it: VTK renders, then Qt paints (blits VTK's frame into the window;
    pyvistaqt's own paintGL renders again first, see ``--pyvistaqt-paint``)."""
    from PySide6.QtWidgets import QApplication

    view.plotter.render()
    QApplication.processEvents()


def rotations(view, count: int, moving: bool) -> tuple[float, float]:  # noqa: ANN001
    """Median and 95th percentile of ``count`` rotate-and-paint frames (wall clock, ms)."""
    pl = view.plotter
    rw = pl.render_window
    rw.SetDesiredUpdateRate(30.0 if moving else 0.0001)  # what the interactor style sets while dragging
    frame(view)
    out = []
    CPU.clear()
    r0 = RENDERS[0]
    for _ in range(count):
        pl.camera.azimuth += 360.0 / count
        t0, c0 = time.perf_counter(), time.process_time()
        frame(view)
        out.append(time.perf_counter() - t0)
        CPU.append(time.process_time() - c0)
    PER_FRAME[:] = [(RENDERS[0] - r0) / count]
    rw.SetDesiredUpdateRate(0.0001)
    return _ms(out)


def drag(view, count: int) -> tuple[float, float]:  # noqa: ANN001
    """Median and 95th percentile of ``count`` steps of a real left-button mouse drag (ms): Qt's mouse-move
    event, VTK's trackball style rotating and rendering (the coarse line), Qt's paint."""
    from PySide6.QtCore import QPoint, Qt
    from PySide6.QtTest import QTest
    from PySide6.QtWidgets import QApplication

    g = view.gl_widget
    at = QPoint(g.width() // 2, g.height() // 2)
    nb = Qt.KeyboardModifier.NoModifier
    QTest.mousePress(g, Qt.MouseButton.LeftButton, nb, at)
    QApplication.processEvents()
    out = []
    CPU.clear()
    r0 = RENDERS[0]
    for k in range(1, count + 1):
        t0, c0 = time.perf_counter(), time.process_time()
        QTest.mouseMove(g, at + QPoint(3 * k, k))
        QApplication.processEvents()
        out.append(time.perf_counter() - t0)
        CPU.append(time.process_time() - c0)
    PER_FRAME[:] = [(RENDERS[0] - r0) / count]
    QTest.mouseRelease(g, Qt.MouseButton.LeftButton, nb, at + QPoint(3 * count, count))
    QApplication.processEvents()
    return _ms(out)


def per_frame() -> float:
    """VTK renders per frame of the frames timed last."""
    return PER_FRAME[0] if PER_FRAME else float("nan")


def cpu_ms() -> float:
    """Median CPU time of the frames timed last (ms)."""
    return float(np.median(CPU) * 1e3)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--points", type=int, default=1_000_000)
    ap.add_argument("--circuits", type=int, default=120)
    ap.add_argument("--frames", type=int, default=30)
    ap.add_argument("--caps", default="200000,500000,1000000")
    ap.add_argument("--multi-samples", type=int, default=None,
                    help="MSAA samples of the render window (default: the view's MULTI_SAMPLES)")
    ap.add_argument("--fxaa", action="store_true", help="add FXAA anti-aliasing")
    ap.add_argument("--lod", type=int, default=None, help="points of the coarse copy (default: LOD_POINTS)")
    ap.add_argument("--quick", action="store_true", help="skip the colour, line-width and polyline comparisons")
    ap.add_argument("--pyvistaqt-paint", action="store_true",
                    help="pyvistaqt's own QtInteractor (its paint renders again after each render: the old way)")
    args = ap.parse_args(argv)

    if os.environ.get("QT_QPA_PLATFORM", "") in ("offscreen", "minimal") or not os.environ.get("DISPLAY"):
        xvfb = shutil.which("xvfb-run")
        if xvfb is None or os.environ.get("_WINDER_BENCH_XVFB"):
            print("bench_gui_3d: needs a display (xvfb-run); skipped")
            return 0
        env = dict(os.environ, QT_QPA_PLATFORM="xcb", _WINDER_BENCH_XVFB="1")
        cmd = [xvfb, "-a", "-s", "-screen 0 1600x1000x24", sys.executable, __file__, *(argv or sys.argv[1:])]
        return subprocess.call(cmd, env=env)

    from PySide6.QtWidgets import QApplication

    app = QApplication.instance() or QApplication([])
    from winder_gui.views import view3d as v3
    from winder_gui.views.geometry import LOD_POINTS, paths_view_data

    if args.multi_samples is not None:
        v3.MULTI_SAMPLES = args.multi_samples
    if args.pyvistaqt_paint:
        from pyvistaqt import QtInteractor

        v3._INTERACTOR_CLASS = QtInteractor
    view = v3.MandrelView3D()
    view.resize(1200, 800)
    view.show()
    app.processEvents()
    view.set_data(cylinder_data(), reset_camera=True)
    if view.ensure_backend() != "vtk":
        print("bench_gui_3d: no VTK view on this platform; skipped")
        return 0
    if args.fxaa:
        view.plotter.enable_anti_aliasing("fxaa")
    view.plotter.render_window.AddObserver("EndEvent", lambda *_: RENDERS.__setitem__(0, RENDERS[0] + 1))
    app.processEvents()
    gl = view.plotter.render_window.ReportCapabilities().splitlines()
    renderer = next((s.split(":", 1)[1].strip() for s in gl if "OpenGL renderer string" in s), "?")
    print(f"OpenGL renderer: {renderer}; view {view.gl_widget.width()} x {view.gl_widget.height()} px, "
          f"MSAA {v3.MULTI_SAMPLES}{' + FXAA' if args.fxaa else ''}; widget {type(view.plotter).__name__}; "
          f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs")
    rotations(view, 10, moving=False)  # warm-up: shaders, first expose
    med, p95 = rotations(view, args.frames, moving=False)
    print(f"mandrel only: frame median {med:.1f} ms, p95 {p95:.1f} ms, CPU {cpu_ms():.1f} ms, "
          f"{per_frame():.1f} renders per frame (baseline of this machine right now)")

    src = synthetic_line(args.points, args.circuits)
    print(f"source: {args.points} path points, {args.circuits} circuits; coarse copy while moving: "
          f"<= {args.lod or LOD_POINTS} points; RSS {_rss_mb():.0f} MB")
    print("frame times in ms: wall-clock median / 95th percentile (CPU-time median of the process) "
          "[VTK renders per frame]; rest = full line, moving = coarse line, drag = real mouse drag (coarse)")
    hdr = (f"{'cap':>9} {'shown':>9} {'thin ms':>8} {'build ms':>9} {'rest':>26} "
           f"{'moving':>26} {'drag':>26} {'anim step':>9} {'RSS MB':>7}")
    print(hdr)
    for cap in [int(c) for c in args.caps.split(",")]:
        t0 = time.perf_counter()
        paths = paths_view_data(src.line, src.eye, cap, v3.MAX_FRAMES, lod_points=args.lod or LOD_POINTS)
        thin = time.perf_counter() - t0
        view.set_paths(None)
        t0 = time.perf_counter()
        view.set_paths(paths)
        app.processEvents()
        build = time.perf_counter() - t0
        rest = rotations(view, args.frames, moving=False)
        rest_cpu, rest_n = cpu_ms(), per_frame()
        moving = rotations(view, args.frames, moving=True)
        moving_cpu, moving_n = cpu_ms(), per_frame()
        dragged = drag(view, args.frames)
        drag_cpu, drag_n = cpu_ms(), per_frame()
        view.play()  # the timer is started but never fires here: set_frame is timed alone
        steps = []
        for k in range(20):
            t0 = time.perf_counter()
            view.set_frame(view.frame + 7 * k + 1)
            app.processEvents()
            steps.append(time.perf_counter() - t0)
        view.pause()
        print(f"{cap:>9} {paths.line_xyz.shape[0]:>9} {thin * 1e3:>8.0f} {build * 1e3:>9.0f} "
              f"{rest[0]:>7.1f} / {rest[1]:<6.1f} ({rest_cpu:5.0f}) [{rest_n:.1f}] "
              f"{moving[0]:>6.1f} / {moving[1]:<6.1f} ({moving_cpu:5.0f}) [{moving_n:.1f}] "
              f"{dragged[0]:>6.1f} / {dragged[1]:<6.1f} ({drag_cpu:5.0f}) [{drag_n:.1f}] "
              f"{_ms(steps)[0]:>9.1f} "
              f"{_rss_mb():>7.0f}")
    if args.quick:
        view.close_backend()
        return 0

    print("colour modes (last cap): switch ms, rest frame median ms (CPU)")
    for name in v3.COLOUR_BY:
        t0 = time.perf_counter()
        view.set_colour_by(name)
        sw = time.perf_counter() - t0
        fr = rotations(view, max(5, args.frames // 3), moving=False)[0]
        print(f"  {name:24s} {sw * 1e3:7.0f} {fr:8.1f} ({cpu_ms():.0f})")
    view.set_colour_by(v3.COLOUR_BY[0])

    print("line width (last cap): build ms, rest frame median ms (CPU)")
    for lw in (1.0, 2.0):
        v3.PATH_LINE_WIDTH = lw
        t0 = time.perf_counter()
        view.set_paths(view.paths)
        b = time.perf_counter() - t0
        fr = rotations(view, max(5, args.frames // 3), moving=False)[0]
        print(f"  width {lw:.0f}: {b * 1e3:7.0f} {fr:8.1f} ({cpu_ms():.0f})")
    v3.PATH_LINE_WIDTH = 1.0

    import pyvista as pv

    p = view.paths
    view.set_paths(None)
    print("cells (last cap, plain pyvista, solid colour): build ms, rest frame median ms (CPU)")
    c = p.scalars["circuit"]
    starts = np.flatnonzero(np.r_[True, c[1:] != c[:-1]])
    ends = np.r_[starts[1:], c.size]
    polys = pv.PolyData(p.line_xyz)
    polys.lines = np.concatenate([np.r_[min(b + 1, c.size) - a, np.arange(a, min(b + 1, c.size))]
                                  for a, b in zip(starts, ends, strict=True)])
    for label, mesh in (("one cell per segment", pv.lines_from_points(p.line_xyz)),
                        (f"one polyline per circuit ({starts.size})", polys)):
        t0 = time.perf_counter()
        view.plotter.add_mesh(mesh, name="cmp", color="#203040", line_width=1, reset_camera=False)
        frame(view)
        b = time.perf_counter() - t0
        fr = rotations(view, max(5, args.frames // 3), moving=False)[0]
        print(f"  {label:34s} {b * 1e3:7.0f} {fr:8.1f} ({cpu_ms():.0f})")
        view.plotter.remove_actor("cmp")
    view.close_backend()
    return 0


if __name__ == "__main__":
    sys.exit(main())
