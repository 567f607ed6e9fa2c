"""The machine schematic (winder_gui/views/machine_schematic.py) and its place in the machine panel.

The drawn geometry is checked against forward kinematics: the engine's (``forward_kinematics``) and,
independently, a closed form written here from the template files themselves (cartesian axes as plain
translations; the robot as a product of standard DH matrices).
"""

from __future__ import annotations

import math
import shutil
import tomllib
from pathlib import Path

import numpy as np
import pytest

from engine.job import load_job
from engine.kinematics import MACHINES_DIR, forward_kinematics, list_machines, load_machine
from winder_gui.views.machine_schematic import PROJECTION, MachineSchematic, axis_colour, project

ROOT = Path(__file__).resolve().parents[1]
TEMPLATES = list_machines()


def _rpy(xyz: list[float], rpy_deg: list[float]) -> np.ndarray:
    r, p, y = np.radians(rpy_deg)
    cz, sz, cy, sy, cx, sx = math.cos(y), math.sin(y), math.cos(p), math.sin(p), math.cos(r), math.sin(r)
    Rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    Ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    Rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    T = np.eye(4)
    T[:3, :3] = Rz @ Ry @ Rx
    T[:3, 3] = xyz
    return T


def _dh(theta: float, d: float, a: float, alpha: float) -> np.ndarray:
    ct, st, ca, sa = math.cos(theta), math.sin(theta), math.cos(alpha), math.sin(alpha)
    return np.array([[ct, -st * ca, st * sa, a * ct], [st, ct * ca, -ct * sa, a * st], [0, sa, ca, d], [0, 0, 0, 1]])


def _internal(ax: dict, value: float) -> float:
    scale = {"deg": 180 / math.pi, "rad": 1.0, "rev": 1 / (2 * math.pi), "mm": 1.0, "inch": 1 / 25.4, "m": 1e-3}
    return (value - ax.get("offset", 0.0)) / (ax.get("sign", 1) * scale[ax["units"]])


def _independent_frames(path: Path, q: np.ndarray) -> tuple[np.ndarray, list[tuple[np.ndarray, np.ndarray]]]:
    """Eye frame (4x4, machine frame) at controller values ``q`` and, for a robot, each joint's (origin, axis).

    Written from the TOML text, not from engine.kinematics.
    """
    data = tomllib.loads(path.read_text())
    axes = data["axes"]
    val = {ax["role"]: _internal(ax, q[i]) for i, ax in enumerate(axes)}
    T = np.eye(4)
    if data["kind"] == "cartesian":
        T[0, 3] = val.get("cross", data.get("eye_radius", 0.0))
        T[1, 3] = val.get("vertical", 0.0)
        T[2, 3] = val["carriage"]
        g, r = val.get("yaw", 0.0), val.get("roll", 0.0)
        T[:3, :3] = _rpy([0, 0, 0], [0, math.degrees(g), 0])[:3, :3] @ _rpy([0, 0, 0], [math.degrees(r), 0, 0])[:3, :3]
        return T, []
    rob = data["robot"]
    T[2, 3] = val["track"]
    T = T @ _rpy(rob["base"]["xyz"], rob["base"]["rpy_deg"])
    joints = []
    for k, row in enumerate(rob["dh"]):
        joints.append((T[:3, 3].copy(), T[:3, 2].copy()))
        T = T @ _dh(val[f"joint{k + 1}"] + math.radians(row.get("theta0_deg", 0.0)), row["d"], row["a"],
                    math.radians(row["alpha_deg"]))
    tool = rob["tool"]
    return T @ _rpy(tool["xyz"], tool["rpy_deg"]), joints


def _user_templates(tmp_path: Path) -> list[Path]:
    """Two user-added templates: a cartesian one with its own axis names/order, a robot with other DH."""
    cart = tmp_path / "my_winder.toml"
    cart.write_text("""
schema = 1
title = "user winder: vertical before cross, inch carriage"
kind = "cartesian"
mandrel_phase = "contact"
phase_deg = -90.0
[[axes]]
name = "U"
role = "carriage"
type = "linear"
units = "inch"
sign = -1
offset = 10.0
min = -10.0
max = 30.0
max_speed = 10.0
max_accel = 40.0
max_jump = 2.0
[[axes]]
name = "S"
role = "mandrel"
type = "rotary"
units = "rev"
max_speed = 2.0
max_accel = 4.0
max_jump = 0.5
[[axes]]
name = "V"
role = "vertical"
type = "linear"
units = "mm"
min = -300.0
max = 100.0
max_speed = 300.0
max_accel = 1500.0
max_jump = 40.0
[[axes]]
name = "W"
role = "cross"
type = "linear"
units = "mm"
min = 50.0
max = 450.0
max_speed = 300.0
max_accel = 1500.0
max_jump = 40.0
[[axes]]
name = "R"
role = "roll"
type = "rotary"
units = "deg"
min = -90.0
max = 90.0
max_speed = 360.0
max_accel = 1440.0
max_jump = 60.0
""")
    robot = tmp_path / "my_robot.toml"
    text = (MACHINES_DIR / "robot_cell.toml").read_text()
    text = text.replace('{ a = 700.0, alpha_deg = 0.0, d = 0.0, theta0_deg = -90.0 }',
                        '{ a = 560.0, alpha_deg = 0.0, d = 0.0, theta0_deg = -90.0 }')
    text = text.replace('home_deg = [0.0, -20.0, 30.0, 0.0, 80.0, 0.0]',
                        'home_deg = [30.0, -10.0, 20.0, 10.0, 60.0, 0.0]')
    text = text.replace('name = "E1"', 'name = "T"')
    robot.write_text(text)
    return [cart, robot]


@pytest.fixture
def widget(qtbot) -> MachineSchematic:
    w = MachineSchematic()
    qtbot.addWidget(w)
    w.resize(520, 340)
    return w


def _paths(tmp_path: Path) -> list[Path]:
    return [MACHINES_DIR / f"{n}.toml" for n in TEMPLATES] + _user_templates(tmp_path)


def test_every_template_is_drawn_from_forward_kinematics(widget, tmp_path, qtbot) -> None:
    assert set(TEMPLATES) >= {"lathe2", "lathe3", "lathe4", "gantry6", "robot_cell"}
    for path in _paths(tmp_path):
        m = load_machine(path)
        widget.set_template(path)
        assert widget.message == "", (path.name, widget.message)
        sch = widget.schematic
        # labels: the template's axis names, in order, each with its travel when limited
        assert widget.labels() == list(m.axis_names)
        for g, ax in zip(widget.axis_glyphs(), m.axes, strict=True):
            assert g.label.startswith(ax.name)
            if abs(ax.min) < 1e11:
                assert f"{ax.min:g}" in g.label and f"{ax.max:g}" in g.label and ax.units in g.label
        # the eye drawn = the forward kinematics of the neutral pose, projected the same way
        q = sch.q
        assert q[m.axis_index("mandrel")] == pytest.approx(m.axes[m.axis_index("mandrel")].offset)
        eye_engine = forward_kinematics(m, q[None, :])[0][0]
        T_ind, joints = _independent_frames(path, q)
        np.testing.assert_allclose(eye_engine, T_ind[:3, 3], atol=1e-6)
        np.testing.assert_allclose(widget.eye_point(), project(T_ind[:3, 3]), atol=1e-6)
        np.testing.assert_allclose(sch.eye_axis3, T_ind[:3, 2], atol=1e-9)
        # the neutral pose respects every limit
        assert np.all(q >= m.limits("min") - 1e-9) and np.all(q <= m.limits("max") + 1e-9)
        eye_r = math.hypot(*T_ind[:2, 3])
        assert eye_r > sch.mandrel_radius, path.name
        for g in widget.axis_glyphs():
            ax = m.axes[g.index]
            if g.type == "linear":
                # travel ends: the eye moved by that axis alone from its min to its max
                qa, qb = q.copy(), q.copy()
                qa[g.index], qb[g.index] = ax.min, ax.max
                d_ind = _independent_frames(path, qb)[0][:3, 3] - _independent_frames(path, qa)[0][:3, 3]
                np.testing.assert_allclose(g.ends3[1] - g.ends3[0], d_ind, atol=1e-6)
                np.testing.assert_allclose(g.dir3, d_ind / np.linalg.norm(d_ind), atol=1e-9)
                np.testing.assert_allclose(g.ends, project(g.ends3), atol=1e-9)
                d2 = project(d_ind)
                np.testing.assert_allclose(g.direction, d2 / np.linalg.norm(d2), atol=1e-9)
            elif ax.role == "mandrel":
                np.testing.assert_allclose(g.dir3, [0, 0, ax.sign], atol=1e-12)
                np.testing.assert_allclose(g.origin3[:2], 0.0, atol=1e-12)
            else:
                # rotation axis: dir3 through origin3; the eye moves as dir3 x (eye - origin3) per
                # unit of growing controller value
                h = 1e-4
                qa, qb = q.copy(), q.copy()
                qa[g.index] -= h
                qb[g.index] += h
                v = (_independent_frames(path, qb)[0][:3, 3] - _independent_frames(path, qa)[0][:3, 3]) / (2 * h)
                Ra, Rb = _independent_frames(path, qa)[0][:3, :3], _independent_frames(path, qb)[0][:3, :3]
                W = (Rb - Ra) / (2 * h) @ T_ind[:3, :3].T
                w = np.array([W[2, 1], W[0, 2], W[1, 0]])
                np.testing.assert_allclose(g.dir3, w / np.linalg.norm(w), atol=1e-6)
                np.testing.assert_allclose(v, np.cross(w, T_ind[:3, 3] - g.origin3), atol=1e-4 * (1 + np.abs(v).max()))
                if ax.role.startswith("joint"):      # a robot joint sits on its own DH axis
                    o, z = joints[int(ax.role[-1]) - 1]
                    np.testing.assert_allclose(np.cross(g.origin3 - o, z), 0.0, atol=1e-6)
                    np.testing.assert_allclose(abs(g.dir3 @ z), 1.0, atol=1e-9)
        if m.kind == "robot":   # the link chain ends at the flange and the eye (DH + tool)
            np.testing.assert_allclose(sch.links3[-1], T_ind[:3, 3], atol=1e-6)
            np.testing.assert_allclose(sch.links3[0], joints[0][0], atol=1e-6)
        widget.grab()   # paints without error


def test_projection_is_the_documented_view() -> None:
    # orthographic: rows are orthonormal; the mandrel axis (z) runs across the picture, y is drawn up
    np.testing.assert_allclose(PROJECTION @ PROJECTION.T, np.eye(2), atol=1e-12)
    assert abs(PROJECTION[0, 2]) > 0.6 and PROJECTION[1, 1] > 0.9 and PROJECTION[0, 1] == 0.0
    np.testing.assert_allclose(project(np.array([[1.0, 2.0, 3.0]])), (PROJECTION @ [1.0, 2.0, 3.0])[None], atol=0)


def test_drawing_fits_the_widget_at_any_size(widget, qtbot) -> None:
    widget.set_template("gantry6")
    for size in ((260, 180), (700, 420)):
        widget.resize(*size)
        widget.grab()
        sch = widget.schematic
        pts = [sch.eye, *sch.links] + [e for g in widget.axis_glyphs() if g.ends is not None for e in g.ends]
        for p2 in pts:
            px = widget.to_pixels(p2)
            assert 0 <= px.x() <= size[0] and 0 <= px.y() <= size[1]


def test_panel_shows_schematic_and_highlights_selected_row(qtbot) -> None:
    from winder_gui.panels.machine_panel import MachinePanel

    panel = MachinePanel()
    qtbot.addWidget(panel)
    panel.resize(460, 760)
    panel.set_job(load_job(ROOT / "resources" / "examples" / "pipe.toml"))
    sch = panel.schematic
    assert sch.minimumWidth() >= 260 and sch.minimumHeight() >= 180
    for name in TEMPLATES:
        panel.select_template(name)
        m = load_machine(name)
        assert sch.labels() == list(m.axis_names)
        assert sch.highlighted is None
        base = sch.grab().toImage()
        for i, ax in enumerate(m.axes):
            panel.table.selectRow(i)
            assert sch.highlighted == ax.name
            # the table row's swatch has the axis's colour in the drawing
            icon = panel.table.item(i, 0).icon().pixmap(10, 10).toImage()
            assert icon.pixelColor(5, 5).name() == axis_colour(i)
        assert sch.grab().toImage() != base
    # clicking an axis in the drawing selects its row
    panel.select_template("lathe3")
    g = next(g for g in sch.axis_glyphs() if g.name == "Y")
    sch.grab()
    sch.axis_clicked.emit("Y")
    assert sch.highlighted == "Y" and panel.table.currentRow() == g.index
    # a limit typed in the table redraws that axis's travel
    panel.set_cell("X", "max", "1000")
    x = next(g for g in sch.axis_glyphs() if g.name == "X")
    assert "0…1000 mm" in x.label
    assert np.linalg.norm(x.ends3[1] - x.ends3[0]) == pytest.approx(1000.0)


def test_malformed_template_shows_a_message(widget, tmp_path, qtbot) -> None:
    bad = tmp_path / "broken.toml"
    bad.write_text((MACHINES_DIR / "lathe3.toml").read_text().replace('role = "cross"', 'role = "sideways"'))
    widget.set_template(bad)
    assert widget.schematic is None and "sideways" in widget.message and widget.labels() == []
    assert widget.axis_glyphs() == [] and widget.eye_point() is None
    widget.grab()
    widget.set_template(tmp_path / "nowhere.toml")
    assert widget.schematic is None and widget.message
    # not TOML at all
    junk = tmp_path / "junk.toml"
    junk.write_text("this is [not toml")
    widget.set_template(junk)
    assert widget.schematic is None and widget.message
    widget.set_template("lathe2")
    assert widget.message == "" and widget.labels() == ["A", "X"]


def test_panel_with_malformed_template_file(qtbot, tmp_path) -> None:
    from winder_gui.panels.machine_panel import MachinePanel

    bad = tmp_path / "broken.toml"
    shutil.copy(MACHINES_DIR / "lathe4.toml", bad)
    bad.write_text(bad.read_text().replace('type = "linear"', 'type = "linear', 1))
    panel = MachinePanel()
    qtbot.addWidget(panel)
    panel.set_job(load_job(ROOT / "resources" / "examples" / "pipe.toml"))
    panel.template_combo.addItem(str(bad))
    panel.select_template(str(bad))
    assert panel.schematic.schematic is None and panel.schematic.message
    assert panel.table.rowCount() == 0
    panel.grab()
    panel.select_template("lathe4")
    assert panel.schematic.labels() == ["A", "X", "Y", "B"]


def test_unlimited_axis_gets_a_nominal_arrow(widget, tmp_path) -> None:
    text = (MACHINES_DIR / "lathe3.toml").read_text().replace("min = 20.0\n", "").replace("max = 600.0\n", "")
    path = tmp_path / "free_cross.toml"
    path.write_text(text)
    m = load_machine(path)
    widget.set_template(path)
    y = next(g for g in widget.axis_glyphs() if g.name == "Y")
    assert y.label == "Y" and y.ends3 is None and y.ends is None
    np.testing.assert_allclose(y.dir3, [1.0, 0.0, 0.0], atol=1e-9)
    sch = widget.schematic
    # the cross feed is set 300 mm off the datum so the eye is drawn clear of the mandrel
    assert sch.q[m.axis_index("cross")] == pytest.approx(300.0)
    np.testing.assert_allclose(sch.eye3, forward_kinematics(m, sch.q[None, :])[0][0], atol=1e-9)
    assert math.hypot(*sch.eye3[:2]) > sch.mandrel_radius
    widget.grab()


def test_head_body_drawn_from_the_eye_along_the_roll_axis(widget, qtbot) -> None:
    """The set-up's head body (radius, length along the roll axis) is drawn from the eye: on a lathe the roll
    axis is machine x away from the mandrel, so its far end is the projection of eye + length x e_x; its
    width is the diameter at the drawing's scale; none without a body."""
    widget.set_template("lathe3")
    widget.grab()
    assert widget.head_pixels is None
    widget.set_head(12.0, 150.0)
    widget.grab()
    a, b, width = widget.head_pixels
    sch = widget.schematic
    e = widget.to_pixels(project(sch.eye3))
    far = widget.to_pixels(project(sch.eye3 + np.array([150.0, 0.0, 0.0]) * np.sign(sch.eye3[0] or 1.0)))
    assert (a.x(), a.y()) == pytest.approx((e.x(), e.y()), abs=1e-9)
    assert (b.x(), b.y()) == pytest.approx((far.x(), far.y()), abs=1e-6)
    assert width == pytest.approx(max(24.0 * widget._map[0], 2.0))
    widget.set_head(0.0, 0.0)
    widget.grab()
    assert widget.head_pixels is None
