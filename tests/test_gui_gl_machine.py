"""The machine (carriage, cross-slide / robot links, payout head) in the real 3D view, posed by the
engine's forward kinematics (issue 18) - the head's tip must be the eye FK gives for the axis values of
the frame shown, for every template.  Needs OpenGL: run under xvfb with QT_QPA_PLATFORM=xcb (see
tests/test_gui_gl.py); the numpy part (machine_frames against FK) runs everywhere."""

from __future__ import annotations

from functools import cache
from pathlib import Path

import numpy as np
import pytest

from engine.job import MachineSpec, load_job
from engine.kinematics import forward_kinematics
from engine.pipeline import run_pipeline
from winder_gui.views.geometry import paths_view_data, to_view
from winder_gui.views.machine3d import machine_frames

ROOT = Path(__file__).resolve().parents[1]
TEMPLATES = ("lathe2", "lathe3", "lathe4", "gantry6", "robot_cell")


@cache
def _result(template: str):
    """The pipe example up to the axes on ``template`` (about a second each)."""
    job = load_job(ROOT / "resources/examples/pipe.toml")
    job = job.model_copy(update={"machine": MachineSpec(template=template)})
    res = run_pipeline(job, None, upto="axes")
    return res, paths_view_data(res.line, res.eye, 20_000, 300, axes=res.axes, machine=res.machine)


def _fk_eye_view(res, q: np.ndarray) -> np.ndarray:
    """The engine's eye by forward kinematics, view frame (mm)."""
    return to_view(forward_kinematics(res.machine, np.atleast_2d(q), fibre=False)[0])


@pytest.mark.parametrize("template", TEMPLATES)
def test_machine_frames_end_at_the_fk_eye(template: str) -> None:
    res, paths = _result(template)
    # the frames' axis values are the engine's axis path rows at the frame indices
    np.testing.assert_array_equal(paths.frame_q, np.asarray(res.axes.q)[paths.frame_index])
    fr = machine_frames(res.machine, paths.frame_q, margin_mm=10.0)
    fk = _fk_eye_view(res, paths.frame_q)
    np.testing.assert_allclose(fr.eye, fk, atol=1e-6, rtol=0)
    np.testing.assert_allclose(fr.links[:, -1], fk, atol=1e-6, rtol=0)
    # and the eye the axes realise is the eye path's (what the red eye of the view shows)
    np.testing.assert_allclose(fk, to_view(np.asarray(res.axes.eye_xyz)[paths.frame_index]), atol=1e-6)
    if res.machine.kind == "cartesian":
        # the carriage rides along the mandrel axis with the eye, outside every eye position
        np.testing.assert_allclose(fr.carriage[:, 0], fk[:, 0], atol=1e-9)
        rho_c, rho_e = np.hypot(fr.carriage[:, 1], fr.carriage[:, 2]), np.hypot(fk[:, 1], fk[:, 2])
        assert np.all(rho_c >= rho_e.max() + 10.0 - 1e-9)
    else:
        # the robot's base rides the track (parallel to the mandrel axis) with the track axis
        k = res.machine.axis_index("track")
        track = res.machine.to_internal(paths.frame_q)[:, k]
        np.testing.assert_allclose(fr.carriage[:, 0] - track, fr.carriage[0, 0] - track[0], atol=1e-9)
    # the head's body runs from the eye along its roll axis: unit vectors; on a cartesian machine across the
    # mandrel axis (view x) and away from it; on the robot from the eye towards the flange (the last link)
    u = fr.head_axis
    np.testing.assert_allclose(np.linalg.norm(u, axis=1), 1.0, atol=1e-12)
    if res.machine.kind == "cartesian" and res.machine.axis_index("yaw") is None:
        assert np.abs(u[:, 0]).max() < 1e-12
        assert np.all(u[:, 1] * fk[:, 1] + u[:, 2] * fk[:, 2] > 0.0)
    else:
        back = fr.links[:, -2] - fk
        assert np.all(np.einsum("ij,ij->i", u, back) > 0.0)


@pytest.mark.gl
def test_drawn_head_sits_at_the_fk_eye_for_every_template(qtbot) -> None:
    from PySide6.QtGui import QGuiApplication

    if QGuiApplication.platformName() in ("offscreen", "minimal"):
        pytest.skip("needs a real display (xvfb-run with QT_QPA_PLATFORM=xcb)")
    from winder_gui.views.view3d import MandrelView3D

    v = MandrelView3D()
    qtbot.addWidget(v)
    v.resize(640, 480)
    v.show()
    assert v.ensure_backend() == "vtk"
    for template in TEMPLATES:
        res, paths = _result(template)
        v.set_paths(paths)
        n = paths.frame_index.size
        for i in (0, n // 7, n // 3, n // 2, n - 1):
            v.set_frame(i)
            fk = _fk_eye_view(res, paths.frame_q[i])[0]
            np.testing.assert_allclose(v.machine_head_eye(), fk, atol=1e-6, rtol=0, err_msg=f"{template} frame {i}")
            links = v.actor_points("machine_links")
            np.testing.assert_allclose(links[-1], fk, atol=1e-6, rtol=0)
            assert v.plotter.actors["machine_head"].GetVisibility()
        # scrubbing by time poses the machine at that time's frame
        t = 0.4 * v.timeline.total_s
        v.set_time(t)
        fk = _fk_eye_view(res, paths.frame_q[v.timeline.frame_at(t)])[0]
        np.testing.assert_allclose(v.machine_head_eye(), fk, atol=1e-6, rtol=0)
        # the machine's actors are made once per path set and moved, not re-added per frame
        head = v.plotter.actors["machine_head"]
        v.set_frame(1)
        assert v.plotter.actors["machine_head"] is head
    # hidden and shown again (View -> Show the machine / the 3D view's box)
    v.machine_check.setChecked(False)
    assert not any(v.plotter.actors[a].GetVisibility() for a in ("machine_head", "machine_links", "machine_carriage"))
    v.set_frame(3)
    v.machine_check.setChecked(True)
    assert v.plotter.actors["machine_head"].GetVisibility()
    np.testing.assert_allclose(v.machine_head_eye(), _fk_eye_view(res, paths.frame_q[3])[0], atol=1e-6)


@pytest.mark.gl
def test_drawn_head_body_is_the_set_up_capsule(qtbot) -> None:
    """With [machine.setup] head_radius_mm / head_length_mm the drawn head is that body: its tip at the
    eye, its far end head_length_mm along the engine's roll axis, its radius the set-up's."""
    from PySide6.QtGui import QGuiApplication

    if QGuiApplication.platformName() in ("offscreen", "minimal"):
        pytest.skip("needs a real display (xvfb-run with QT_QPA_PLATFORM=xcb)")
    from engine.machine_setup import head_axis_q
    from winder_gui.views.view3d import MandrelView3D

    res, _ = _result("lathe3")
    paths = paths_view_data(res.line, res.eye, 20_000, 300, axes=res.axes, machine=res.machine,
                            head_mm=(8.0, 120.0))
    v = MandrelView3D()
    qtbot.addWidget(v)
    v.resize(640, 480)
    v.show()
    assert v.ensure_backend() == "vtk"
    v.set_paths(paths)
    for i in (0, paths.frame_index.size // 3):
        v.set_frame(i)
        fk = _fk_eye_view(res, paths.frame_q[i])[0]
        np.testing.assert_allclose(v.machine_head_eye(), fk, atol=1e-6, rtol=0)
        m = v.plotter.actors["machine_head"].GetMatrix()
        M = np.array([[m.GetElement(r, c) for c in range(4)] for r in range(4)])
        far = (M @ np.array([-120.0, 0.0, 0.0, 1.0]))[:3]
        u = to_view(head_axis_q(res.machine, paths.frame_q[i]))[0]
        np.testing.assert_allclose(far, fk + 120.0 * u, atol=1e-6)
    pts = v.actor_points("machine_head")     # its own frame: the axis on x from -120 to 0, radius 8, round ends
    assert pts[:, 0].min() == pytest.approx(-128.0, abs=0.05) and pts[:, 0].max() == pytest.approx(8.0, abs=0.05)
    assert np.hypot(pts[:, 1], pts[:, 2]).max() == pytest.approx(8.0, abs=0.05)   # (tessellated spheres)


@pytest.mark.gl
def test_fit_frames_the_machine_and_the_supports(qtbot) -> None:
    """Fit (and the framing after a run) keeps the machine in view when it is shown -- its links, carriage
    and head over the whole program, so playing never runs it out of the picture -- and the shafts, chuck
    and tailstock; hidden, the machine does not widen the view.  The bottle on its own machine in a wide,
    low view (the main window's): framed on the eye path only, some of the machine fell outside (in the
    main window, with the mandrel, an eighth of its points).  The vectorised projection used for it agrees
    with VTK's WorldToDisplay."""
    from PySide6.QtGui import QGuiApplication

    if QGuiApplication.platformName() in ("offscreen", "minimal"):
        pytest.skip("needs a real display (xvfb-run with QT_QPA_PLATFORM=xcb)")
    from winder_gui.views.view3d import MandrelView3D

    job = load_job(ROOT / "resources/examples/bottle.toml")
    res = run_pipeline(job, None, upto="axes")
    paths = paths_view_data(res.line, res.eye, 20_000, 300, axes=res.axes, machine=res.machine)
    v = MandrelView3D()
    qtbot.addWidget(v)
    v.resize(792, 400)
    v.show()
    assert v.ensure_backend() == "vtk"
    v.set_paths(paths)
    qtbot.waitUntil(lambda: v.plotter.render_window.GetSize()[0] > 0, timeout=10000)
    qtbot.wait(50)
    w, h = v.plotter.render_window.GetSize()
    assert w > 2 * h   # wide and low, as in the main window
    v.set_supports([("left shaft", -400.0, -150.0, 20.0), ("chuck", -150.0, -100.0, 60.0)])
    v.set_camera("iso")
    machine = v.machine_points()
    assert machine.shape[0] > 100
    assert v.points_in_view(machine).all()
    assert v.points_in_view(v.scene_points()).all()
    ren = v.plotter.renderer
    x, y = v.project_points(machine[::37])
    for p, xi, yi in zip(machine[::37], x, y, strict=True):
        ren.SetWorldPoint(*p, 1.0)
        ren.WorldToDisplay()
        dx, dy, _ = ren.GetDisplayPoint()
        assert abs(dx - xi) < 1e-6 and abs(dy - yi) < 1e-6
    with_machine = v.plotter.camera.distance
    v.set_machine_visible(False)
    v.frame_all()
    assert v.points_in_view(v.scene_points()).all()
    assert not v.points_in_view(machine).all()   # framing without the machine cuts some of it off
    assert v.plotter.camera.distance <= with_machine + 1e-9
    v.set_machine_visible(True)
    v.frame_all()
    assert v.points_in_view(machine).all()
