"""Playback of a whole program in the 3D view: wall time at each speed and frames per second.

Run under a virtual screen (software OpenGL):

    xvfb-run -a -s "-screen 0 1600x1000x24" env QT_QPA_PLATFORM=xcb .venv/bin/python benchmarks/bench_gui_playback.py

Prints, for the pressure-vessel example (a laminate of 4 layers) at 1280x800: the program time, the frame
rate over 10 s at x1, the wall time to play the whole program (every layer, from the first layer's start)
at x1000 (and x100), the
renders per second (and per second of the process's CPU time: the machine may be shared), the time
of one render with the band half laid, and a render and a frame update with the machine (carriage, links,
head) shown and hidden.
"""

from __future__ import annotations

import os
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main() -> int:
    tmp = tempfile.mkdtemp(prefix="winder-bench-")
    os.environ["WINDER_SETTINGS"] = str(Path(tmp) / "s.ini")
    os.environ["WINDER_AUTOSAVE_DIR"] = str(Path(tmp) / "autosave")
    from PySide6.QtWidgets import QApplication

    app = QApplication.instance() or QApplication([])
    from winder_gui.main_window import MainWindow

    job = Path(sys.argv[1]) if len(sys.argv) > 1 else ROOT / "resources/examples/pressure_vessel.toml"
    w = MainWindow(job)
    w.confirm_discard = False
    w.auto_run = False
    w.resize(1280, 800)
    w.show()
    w.wait_idle()
    t0 = time.monotonic()
    while w.view3d.backend == "pending" and time.monotonic() - t0 < 60:
        app.processEvents()
        time.sleep(0.01)
    v = w.view3d
    if v.backend != "vtk":
        print(f"no 3D view ({v.backend}): run under xvfb-run with QT_QPA_PLATFORM=xcb")
        return 1
    w.run_pipeline_now()
    w.wait_idle(600000)
    renders = [0]
    v.plotter.render_window.AddObserver("EndEvent", lambda *_a: renders.__setitem__(0, renders[0] + 1))
    v.set_time(0.5 * v.timeline.total_s)
    one = []
    for _ in range(5):
        t = time.perf_counter()
        v.plotter.render()
        one.append(time.perf_counter() - t)
    print(f"{job.name}: program {v.timeline.total_s:.1f} s, {v.paths.frame_index.size} frames, "
          f"band {v.paths.band.m if v.paths.band is not None else 0} points; "
          f"one render (band half laid) {1000 * min(one):.0f} ms (median {1000 * sorted(one)[2]:.0f} ms)")
    # the machine (carriage, links, head) drawn or not: renders and frame updates interleaved (a shared machine)
    cost: dict[bool, dict[str, list[float]]] = {True: {"render": [], "frame": []}, False: {"render": [], "frame": []}}
    half = 0.5 * v.timeline.total_s
    for k in range(14):
        shown = k % 2 == 0
        v.set_machine_visible(shown)
        t = time.perf_counter()
        v.plotter.render()
        cost[shown]["render"].append(time.perf_counter() - t)
        t = time.perf_counter()
        v.set_time(half + (k + 1) * 1e-3 * v.timeline.total_s)   # the eye, band and machine moved, one render
        cost[shown]["frame"].append(time.perf_counter() - t)
    v.set_machine_visible(True)
    med = {s: {key: 1000 * sorted(x)[len(x) // 2] for key, x in c.items()} for s, c in cost.items()}
    print(f"machine shown / hidden: one render {med[True]['render']:.1f} / {med[False]['render']:.1f} ms, "
          f"one frame (set_time: eye, band, machine, render) {med[True]['frame']:.1f} / {med[False]['frame']:.1f} ms "
          "(medians of 7)")
    total = v.program_total_s if v.program_total_s is not None else v.timeline.total_s
    print(f"whole program {total:.1f} s; layers shown in turn: {[label for _i, label, _t in v.layers] or 'one line'}")
    # x1: the whole program would take 24 minutes; the frame rate over 10 s of it, from the first layer's start
    v.set_speed(1)
    if v.layers:
        v.jump_to_layer(v.layers[0][0])
    v.set_time(0.0)
    renders[0] = 0
    t = time.monotonic()
    cpu = time.process_time()
    v.play()
    while v.is_playing() and time.monotonic() - t < 10.0:
        app.processEvents()
        time.sleep(0.001)
    v.pause()
    dt, dcpu = time.monotonic() - t, time.process_time() - cpu
    print(f"x1: 10 s of the program: {renders[0]} renders, {renders[0] / dt:.1f} frames/s; process CPU {dcpu:.2f} s "
          f"({renders[0] / max(dcpu, 1e-9):.1f} frames per CPU second)")
    for speed in (1000, 100):
        v.set_speed(speed)
        if v.layers:
            v.jump_to_layer(v.layers[0][0])
        v.set_time(0.0)
        renders[0] = 0
        seen = {v.layer_index}
        v.layer_requested.connect(seen.add)
        t = time.monotonic()
        cpu = time.process_time()
        v.play()
        while v.is_playing() and time.monotonic() - t < 600:
            app.processEvents()
            time.sleep(0.001)
        dt = time.monotonic() - t
        dcpu = time.process_time() - cpu
        v.layer_requested.disconnect(seen.add)
        print(f"x{speed}: played in {dt:.2f} s wall, {renders[0]} renders, {renders[0] / dt:.1f} frames/s, "
              f"layers {len(seen)}, ends at t {v.program_time_s():.1f} s; process CPU {dcpu:.2f} s "
              f"({renders[0] / max(dcpu, 1e-9):.1f} frames per CPU second: the rate on a core of its own)")
    w.close()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
