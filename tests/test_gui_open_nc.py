"""File > Open NC program (issue 15, point 6): a program is read back on the job's machine in the worker,
its eye path and laid fibre are drawn in 3D and the status bar gives time, fibre and violations; a
corrupted file is refused with its line number."""

from __future__ import annotations

import numpy as np
import pytest
from gui_helpers import close_window, shown_window

from engine.job import default_job
from engine.pipeline import run_pipeline, write_program

pytestmark = pytest.mark.usefixtures("qapp")


@pytest.fixture
def job_and_program(tmp_path):
    job = default_job("open-nc").replace(
        mandrel={"kind": "vessel", "radius_mm": 60.0, "cylinder_length_mm": 120.0, "pole_radius_mm": 20.0},
        winding={"points_per_pass": 300}, machine={"template": "lathe4"})
    path = tmp_path / "job.toml"
    path.write_text(job.to_toml())
    res = run_pipeline(job, path)
    prog = write_program(res, tmp_path / "prog.ngc")
    return path, prog, res


def test_open_nc_draws_the_program_and_reports(qtbot, job_and_program) -> None:
    path, prog, res = job_and_program
    w = shown_window(qtbot, path)
    try:
        assert "open_nc" in w.actions and w.actions["open_nc"].shortcut().toString() == "Ctrl+Shift+O"
        with qtbot.waitSignal(w.nc_read, timeout=120000) as sig:
            w.open_nc(prog)
        out = sig.args[0]
        r = out.report
        assert r["ok"] and r["program_time_s"] == pytest.approx(res.blocks.total, rel=1e-3)
        assert r["fibre_length_mm"] == pytest.approx(res.report()["fibre_length_mm"], rel=1e-3)
        assert w.view3d.paths is out.paths
        # the drawn eye frames are the program's eye positions (forward kinematics), in the view frame
        assert out.paths.eye_xyz.shape[0] >= 2 and np.all(np.isfinite(out.paths.eye_xyz))
        assert "within every limit" in w.status_msg.text() and "prog.ngc" in w.status_msg.text()
        # a corrupted program: refused with the line number, nothing drawn over the last one
        lines = prog.read_text().split("\n")
        k = next(i for i, s in enumerate(lines) if s.startswith("G1 ")) + 3
        lines[k] = lines[k].replace("G1 ", "G1 Q7 ")
        bad = prog.with_name("bad.ngc")
        bad.write_text("\n".join(lines))
        w.open_nc(bad)
        assert w.wait_idle(60000)
        assert f"Line: {k + 1}" in w.last_error and "unknown word Q7" in w.last_error
        assert w.view3d.paths is out.paths
    finally:
        close_window(w)
