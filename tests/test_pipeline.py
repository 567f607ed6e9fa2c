"""The whole pipeline: every example job to NC, read back by LinuxCNC's own interpreter."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from engine.cli import main
from engine.errors import Cancelled, InputError
from engine.job import load_job, parse_job
from engine.pipeline import STAGES, load_machine_for_job, run_pipeline, stage_keys, write_program
from engine.post import load_controller
from engine.state import RecordingState

EXAMPLES = Path(__file__).resolve().parents[1] / "resources" / "examples"
JOBS = sorted(p for p in EXAMPLES.glob("*.toml") if "[mandrel]" in p.read_text())
RS274 = shutil.which("rs274") or ("/usr/bin/rs274" if Path("/usr/bin/rs274").exists() else None)


@pytest.fixture(scope="module", params=[p.stem for p in JOBS])
def example(request: pytest.FixtureRequest):
    path = EXAMPLES / f"{request.param}.toml"
    job = load_job(path)
    return path, job, run_pipeline(job, path)


def test_every_stage_ran(example) -> None:
    path, job, res = example
    assert res.nc_text and res.nc_text.startswith("(") or res.nc_text.startswith("%")
    assert set(res.stage_times) == set(STAGES)
    rep = res.report()
    for key in ("machine", "axes", "blocks", "program_time_s", "max_speed_ratio", "max_accel_ratio", "warnings"):
        assert key in rep
    assert rep["axes"] == list(res.machine.axis_names)
    assert rep["blocks"] == res.blocks.n > 0
    # (18) never makes the program slower than its feasible start, and speeds stay within limits
    assert rep["program_time_s"] <= res.blocks.total_start * (1 + 1e-12)
    assert max(rep["max_speed_ratio"].values()) <= 1 + 1e-9
    # every speed step within the jump a block boundary may take at once: no acceleration beyond it
    assert max(rep["max_jump_ratio"].values()) <= 1 + 1e-9 and max(rep["max_accel_ratio"].values()) == 0.0
    json.dumps(rep)  # JSON-able


@pytest.mark.rs274
@pytest.mark.skipif(RS274 is None, reason="LinuxCNC's rs274 interpreter is not installed")
def test_linuxcnc_reads_example_program(example, tmp_path: Path) -> None:
    path, job, res = example
    ngc = write_program(res, tmp_path / f"{path.stem}.ngc", force=True)
    proc = subprocess.run([RS274, "-g", str(ngc)], stdin=subprocess.DEVNULL, capture_output=True, text=True,
                          timeout=300)
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0, out[-2000:]
    assert not re.search(r"(?i)\berror\b|bad character|unknown word", out), out[-2000:]
    pos = np.array([[float(x) for x in m.group(2).split(",")]
                    for m in re.finditer(r"STRAIGHT_(FEED|TRAVERSE)\(([^)]*)\)", out)])
    b, machine = res.blocks, res.machine
    assert pos.shape[0] == b.n + 1
    prof = load_controller(job.post.controller or "linuxcnc")
    for k, name in enumerate(machine.axis_names):
        col = "XYZABC".index(prof.axis_letters.get(name, name))
        dec = prof.decimals_rotary if machine.axes[k].type == "rotary" else prof.decimals_linear
        assert np.abs(pos[:, col] - b.q[:, k]).max() <= 0.5 * 10.0**-dec + 1e-9, name


def test_changing_the_post_reuses_every_upstream_stage(example) -> None:
    path, job, res = example
    other = job.replace(post={**job.post.model_dump(), "post": "fanuc"})
    res2 = run_pipeline(other, path, previous=res)
    assert res2.reused == ("mandrel", "winding", "payout", "axes", "blocks")
    assert res2.blocks is res.blocks and res2.nc_text != res.nc_text
    assert res2.post_name == "fanuc"


def test_stage_keys_follow_the_sections() -> None:
    job = load_job(EXAMPLES / "pressure_vessel.toml")
    k0 = stage_keys(job)
    k1 = stage_keys(job.replace(payout={**job.payout.model_dump(), "clearance_mm": 33.0}))
    assert [k0[s] == k1[s] for s in STAGES] == [True, True, False, False, False, False]
    k2 = stage_keys(job.replace(post={**job.post.model_dump(), "post": "csv"}))
    assert [k0[s] == k2[s] for s in STAGES] == [True] * 5 + [False]


def test_cancel_stops_the_run() -> None:
    job = load_job(EXAMPLES / "pressure_vessel.toml")
    st = RecordingState(cancel_after=2)
    with pytest.raises(Cancelled):
        run_pipeline(job, EXAMPLES / "pressure_vessel.toml", state=st)
    assert st.fractions == sorted(st.fractions)


def test_machine_overrides_and_bad_axis() -> None:
    text = (EXAMPLES / "pressure_vessel.toml").read_text() + "\n[machine.axes.X]\nmax_speed = 123.0\n"
    m = load_machine_for_job(parse_job(text))
    assert m.axes[m.axis_names.index("X")].max_speed == 123.0
    bad = (EXAMPLES / "pressure_vessel.toml").read_text() + "\n[machine.axes.Q]\nmax_speed = 1.0\n"
    with pytest.raises(InputError) as info:
        load_machine_for_job(parse_job(bad), "v.toml")
    assert info.value.location.field == "machine.axes.Q" and "has no axis 'Q'" in info.value.message


def test_cli_run_refuses_to_write_a_violating_program(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    job = tmp_path / "tight.toml"
    # lathe4 (cross feed): 1010 mm of travel holds the 1000 mm pipe and its winding line (the up-front
    # checks pass) but not the eye's 1084 mm (the payout law decides how far the eye leads)
    text = (EXAMPLES / "pipe.toml").read_text()
    text = text[: text.index("# The laminate")]  # the pipe's single line (the laminate: test_laminate.py)
    job.write_text(text.replace("max = 1800.0", "max = 1010.0").replace('template = "lathe2"', 'template = "lathe4"'))
    out = tmp_path / "p.ngc"
    rep = tmp_path / "r.json"
    assert main(["run", str(job), "-o", str(out), "--report", str(rep), "--quiet"]) == 1
    assert not out.exists()
    err = capsys.readouterr().err
    assert "not written" in err and "axis X" in err and "NC line" in err
    assert "of X travel but the axis has 1010 (0..1010); no placement fits" in err   # what the placement says
    data = json.loads(rep.read_text())
    assert data["written"] is False and any("axis X" in w for w in data["warnings"])
    # grouped: one entry per kind and axis, located by NC line and time
    groups = [g for g in data["violations"] if g["axis"] == "X" and g["kind"] == "position"]
    assert len(groups) == 2 and all(g["places"] >= 1 and g["nc_line"] > 0 for g in groups)
    assert not data["placement"]["fits"] and data["placement"]["z0_fit"] is None
    assert main(["run", str(job), "-o", str(out), "--force", "--quiet"]) == 0
    assert out.read_text().count("G1 ") > 10


def test_cli_run_fixed_eye_radius_too_long_for_the_travel_is_refused_before_the_payout(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """lathe2's eye at its fixed 160 mm needs 1198 mm of X for the pipe: with 1100 mm the pre-check (the eye on
    each fibre tangent at that radius, from the winding line alone) refuses it before the payout, naming
    the excess and the largest eye radius that fits."""
    job = tmp_path / "tight.toml"
    text = (EXAMPLES / "pipe.toml").read_text()
    text = text[: text.index("# The laminate")]
    job.write_text(text.replace("max = 1800.0", "max = 1100.0") + "\n[machine.setup]\neye_radius_mm = 160.0\n")
    out = tmp_path / "p.ngc"
    assert main(["run", str(job), "-o", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "axis X of machine lathe2 travels 1100 mm" in err and "it needs 1197.9 mm, 97.9 mm more" in err
    assert "machine.setup.eye_radius_mm up to" in err and "line " in err and not out.exists()


def test_cli_run_too_short_travel_is_refused_before_computing(tmp_path: Path,
                                                               capsys: pytest.CaptureFixture[str]) -> None:
    job = tmp_path / "short.toml"
    job.write_text((EXAMPLES / "pipe.toml").read_text().replace("max = 1800.0", "max = 700.0"))
    assert main(["run", str(job), "-o", str(tmp_path / "p.ngc"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "axis X travels 700 mm but the mandrel is 1000 mm long" in err


def test_cli_run_writes_program_and_report(tmp_path: Path) -> None:
    out = tmp_path / "pipe.ngc"
    rep = tmp_path / "r.json"
    assert main(["run", str(EXAMPLES / "pipe.toml"), "-o", str(out), "--report", str(rep), "--quiet"]) == 0
    data = json.loads(rep.read_text())
    assert data["written"] is True and data["machine"] == "lathe2" and data["axes"] == ["A", "X"]
    assert out.read_text().endswith("M2\n")


def test_cli_run_bad_job_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    job = tmp_path / "bad.toml"
    job.write_text((EXAMPLES / "pipe.toml").read_text().replace('template = "lathe2"', 'template = "nosuch"'))
    assert main(["run", str(job), "-o", str(tmp_path / "x.ngc"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "machine.template" in err and "nosuch" in err
    assert not (tmp_path / "x.ngc").exists()


def test_payout_warnings_name_the_constraint_and_place(tmp_path) -> None:
    path = tmp_path / "pipe_parallel.toml"  # the parallel law sags at the pins of the pipe example
    path.write_text((EXAMPLES / "pipe.toml").read_text().replace('law = "min-range"', 'law = "parallel"'))
    res = run_pipeline(load_job(path), path, upto="payout")
    eye = res.eye_circuit
    broken = [k for k, c in eye.report["constraints"].items() if isinstance(c, dict) and not c.get("ok", True)]
    warns = [w for w in res.warnings() if w.startswith("payout")]
    assert (not eye.feasible) == bool(warns)
    for name in broken:
        assert any(f"'{name}'" in w or "cyclic" in w for w in warns), (name, warns)
    for w in warns:
        assert "{" not in w and "(parallel law)" in w
