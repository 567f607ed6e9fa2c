"""Machine step: the post lists offer only what addresses the template's axes (no blank entry), the
set-up group edits [machine.setup], and the schematic draws the job's part and supports where the
set-up places them (issue 15)."""

from __future__ import annotations

from pathlib import Path

import pytest

from engine.job import load_job
from engine.kinematics import load_machine
from engine.machine_setup import compatible_posts, support_obstacles

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture
def panel(qtbot):
    from winder_gui.panels.machine_panel import MachinePanel

    p = MachinePanel()
    qtbot.addWidget(p)
    p.resize(460, 900)
    job = load_job(ROOT / "resources" / "examples" / "pipe.toml")
    p.set_job(job)
    from engine.job import build_mandrel

    assert p.schematic.schematic.supports == ()          # no mandrel built yet: the nominal one
    p.set_mandrel(build_mandrel(job))                     # as the window does when the build worker is done
    return p


def _items(combo) -> list[str]:
    return [combo.itemText(i) for i in range(combo.count())]


def test_post_lists_follow_the_template(panel, qtbot) -> None:
    from winder_gui.panels.machine_panel import DEFAULT_CONTROLLER

    for name in ("lathe2", "lathe4", "gantry6", "robot_cell"):
        panel.select_template(name)
        want = sorted({p for p, _c in compatible_posts(load_machine(name))})
        assert _items(panel.post_combo) == want and "" not in want
    # the robot: marlin cannot address E1/J1..J6; linuxcnc only with its robot profile
    assert "marlin" not in _items(panel.post_combo)
    panel.post_combo.setCurrentText("linuxcnc")
    panel._on_post()
    assert _items(panel.controller_combo) == [DEFAULT_CONTROLLER, "linuxcnc_robot"]
    with qtbot.waitSignal(panel.job_edited, timeout=2000) as sig:
        panel.select_template("lathe2")
    assert sig.args[0].post.post in _items(panel.post_combo)


def test_setup_fields_edit_the_job_and_survive_a_template_change(panel, qtbot) -> None:
    ed = panel.setup_edits["mandrel_z0_mm"]
    assert ed.text() == "" and ed.placeholderText() == "centred"
    with qtbot.waitSignal(panel.job_edited, timeout=2000) as sig:
        ed.setText("450")
        panel._on_edited()
    job = sig.args[0]
    assert job.machine.setup.mandrel_z0_mm == 450.0
    with qtbot.waitSignal(panel.job_edited, timeout=2000) as sig:
        panel.setup_edits["head_offset_mm.2"].setText("-12.5")
        panel._on_edited()
    assert sig.args[0].machine.setup.head_offset_mm == (0.0, 0.0, -12.5)
    panel.set_job(sig.args[0])
    with qtbot.waitSignal(panel.job_edited, timeout=2000) as sig:
        panel.select_template("lathe3")
    assert sig.args[0].machine.setup.mandrel_z0_mm == 450.0
    panel.setup_edits["shaft_length_mm"].setText("abc")
    panel._on_edited()
    assert "not a number" in panel.errors()


def test_schematic_draws_the_part_and_supports_at_the_placement(panel) -> None:
    job = load_job(ROOT / "resources" / "examples" / "pipe.toml")
    sch = panel.schematic.schematic
    assert sch.mandrel_z == (0.0, 1000.0) and sch.mandrel_radius == pytest.approx(75.0, rel=1e-3)
    from engine.job import build_mandrel

    want = [(o.name, o.z0, o.z1, o.radius) for o in support_obstacles(build_mandrel(job), job.machine.setup)]
    assert [s[0] for s in sch.supports] == [w[0] for w in want]
    assert all(s[1:] == pytest.approx(w[1:]) for s, w in zip(sch.supports, want, strict=True))
    # before a run the mandrel is centred on the travel: the carriage rail's ends are symmetric about it
    x = next(g for g in panel.schematic.axis_glyphs() if g.name == "X")
    zs = sorted(float(e[2]) for e in x.ends3)
    assert 0.5 * (zs[0] + zs[1]) == pytest.approx(500.0, abs=0.1)
    panel.schematic.grab()
