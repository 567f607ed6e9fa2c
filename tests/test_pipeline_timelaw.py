"""The time law drives the NC output (job.timelaw.method = "tube" | "dp" | "toppra")."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from engine.blocks import Blocks
from engine.job import load_job
from engine.pipeline import STAGES, run_pipeline, timelaw_block_check, write_program
from engine.post import load_controller

EXAMPLES = Path(__file__).resolve().parents[1] / "resources" / "examples"
RS274 = shutil.which("rs274") or ("/usr/bin/rs274" if Path("/usr/bin/rs274").exists() else None)


def _with_method(job, method: str):
    return job.replace(timelaw={**job.timelaw.model_dump(), "method": method})


@pytest.fixture(scope="module", params=["pipe", "pressure_vessel"])
def runs(request: pytest.FixtureRequest):
    path = EXAMPLES / f"{request.param}.toml"
    job = load_job(path)
    base = run_pipeline(job, path, upto="axes")
    blocks18 = run_pipeline(_with_method(job, "blocks"), path, previous=base)
    tube = run_pipeline(_with_method(job, "tube"), path, previous=base)
    return request.param, blocks18, tube


def _inverse_time_program_time(nc_text: str) -> float:
    """Sum of 60/F over the G1 blocks of a G93 program (F = 1 / block time in minutes)."""
    feeds = [float(m.group(1)) for m in re.finditer(r"^G1 .*F([0-9.]+)\s*$", nc_text, re.MULTILINE)]
    assert feeds, "no G1 ... F blocks"
    return float(np.sum(60.0 / np.array(feeds)))


def test_program_time_equals_the_law(runs) -> None:
    name, _b18, res = runs
    rep = res.report()
    tl = rep["timelaw"]
    for key in ("method", "total_time_s", "compute_s", "iterations", "max_accel_ratio", "energy"):
        assert key in tl
    assert tl["method"] == "tube" and tl["iterations"] >= 2
    assert tl["max_accel_ratio"] <= 1.0 + 1e-6
    # the program takes the law's time plus the ramps that keep max_jump where a block cannot be split
    assert rep["program_time_s"] == pytest.approx(tl["total_time_s"] + tl["time_added_s"], rel=1e-5)
    assert rep["program_time_s"] >= tl["total_time_s"] * (1 - 1e-9)
    assert res.blocks.time.size == res.blocks.n
    assert np.all(res.blocks.alpha <= 1.0) and np.all(res.blocks.alpha > 0)
    # every block at least its (17) time: the law includes the axis speed limits
    assert np.all(res.blocks.time >= res.blocks.t17 * (1 - 1e-12))
    assert max(rep["max_speed_ratio"].values()) <= 1.0 + 1e-9
    json.dumps(rep)


def test_nc_feeds_reproduce_the_law_time(runs) -> None:
    name, _b18, res = runs
    assert res.post_name == "linuxcnc"
    assert "G93" in res.nc_text
    prog = _inverse_time_program_time(res.nc_text)
    assert prog == pytest.approx(res.blocks.total, rel=0.01)
    prof = load_controller("linuxcnc")
    assert prof.feed_mode == "inverse_time"


def test_law_respects_accelerations_that_18_ignores(runs, monkeypatch: pytest.MonkeyPatch) -> None:
    import engine.pipeline as pl

    name, b18, res = runs
    r18, rtl = b18.report(), res.report()
    assert "timelaw" not in r18
    def raw_accel(blocks, machine) -> float:  # noqa: ANN001
        """Largest speed change over the mean duration of two blocks / max_accel (computed here from the
        block speeds and times; the report's max_accel_ratio counts only the part beyond max_jump)."""
        v, t = np.asarray(blocks.speed), np.asarray(blocks.time)
        if blocks.cyclic:
            dv, tm = np.abs(np.roll(v, -1, axis=0) - v), 0.5 * (t + np.roll(t, -1))
        else:
            dv, tm = np.abs(np.diff(v, axis=0)), 0.5 * (t[1:] + t[:-1])
        return float(np.max(dv / tm[:, None] / machine.limits("max_accel")))

    # (18) bounds block speed jumps only: its block-to-block accelerations exceed max_accel - shown on the
    # whole-path blocks (the pipe's blocks made per circuit, one ending at every circuit start, happen to
    # keep (18) below max_accel: 0.57)
    monkeypatch.setattr(pl, "_BLOCKS_REPLICATE_MIN", 10**9)
    path = EXAMPLES / f"{name}.toml"
    whole18 = run_pipeline(_with_method(load_job(path), "blocks"), path, previous=res)
    assert raw_accel(whole18.blocks, whole18.machine) > 1.5
    # the law: speed change over the mean duration of two blocks stays within max_accel
    assert raw_accel(res.blocks, res.machine) <= 1.0 + 1e-6
    assert max(rtl["max_accel_ratio"].values()) <= 1.0 + 1e-6
    assert max(r18["max_jump_ratio"].values()) <= 1.0 + 1e-6 and max(rtl["max_jump_ratio"].values()) <= 1.0 + 1e-6
    # both keep the axis speeds; both are above the pure speed bound (17) of their own blocks
    assert rtl["program_time_s"] >= rtl["program_time_t17_s"]
    assert r18["program_time_s"] >= r18["program_time_t17_s"]
    print(f"{name}: (18) {r18['program_time_s']:.1f} s, time law {rtl['program_time_s']:.1f} s")


def test_no_violations_and_every_speed_step_within_max_jump(runs) -> None:
    """No class of limit is a mere warning: the law's blocks keep max_jump everywhere (checked here
    directly on the block speeds, independent of the pipeline's own check)."""
    name, _b18, res = runs
    assert res.violations == []
    assert not [w for w in res.warnings() if "max_jump" in w]
    v = np.asarray(res.blocks.speed)
    p = res.machine.limits("max_jump")
    assert np.all(np.abs(np.diff(v, axis=0)) <= p * (1 + 1e-6))
    assert res.timelaw["time_added_s"] >= 0.0


def test_stage_reuse_with_time_law(runs) -> None:
    name, _b18, res = runs
    path = EXAMPLES / f"{name}.toml"
    other = res.job.replace(post={**res.job.post.model_dump(), "post": "fanuc"})
    res2 = run_pipeline(other, path, previous=res)
    assert res2.reused == STAGES[:5]
    assert res2.timelaw is res.timelaw and res2.blocks is res.blocks
    back = run_pipeline(_with_method(res.job, "blocks"), path, previous=res)
    assert "blocks" not in back.reused and back.timelaw is None


def test_toppra_is_the_lower_bound_of_the_tube() -> None:
    """Second method on the same limits: the time-optimal TOPP-RA law bounds the tube law from below."""
    path = EXAMPLES / "pipe.toml"
    job = load_job(path)
    base = run_pipeline(job, path, upto="axes")
    tube = run_pipeline(_with_method(job, "tube"), path, previous=base, upto="blocks")
    topp = run_pipeline(_with_method(job, "toppra"), path, previous=base, upto="blocks")
    t_tube, t_topp = tube.timelaw["total_time_s"], topp.timelaw["total_time_s"]
    assert t_topp <= t_tube * (1 + 1e-3)
    assert t_tube <= t_topp * 1.08
    assert topp.blocks.total == pytest.approx(t_topp + topp.timelaw["time_added_s"], rel=0.01)


def _blocks(speeds: np.ndarray, times: np.ndarray) -> Blocks:
    delta = speeds * times[:, None]
    q = np.vstack([np.zeros((1, speeds.shape[1])), np.cumsum(delta, axis=0)])
    n = times.size
    return Blocks("m", ("A", "X"), np.arange(n + 1), q, delta, times.copy(), times.copy(), np.ones(n),
                  np.zeros(n), 0.05, cyclic=False)


def test_jump_check_is_hard_and_the_blocks_ramp() -> None:
    """A speed jump above max_jump is a violation whatever the acceleration over the blocks, and
    limit_speed_steps removes it by the least slow-down of the blocks around it (checked by hand)."""
    from engine.kinematics import load_machine
    from engine.machine_setup import limit_speed_steps

    m = load_machine("lathe2")          # X: max_jump 60 mm/s, max_accel 2000 mm/s²
    pos = 0.5 * (m.axes[1].min + m.axes[1].max) - m.axes[1].offset
    # jump of 100 mm/s over blocks of 0.1 s (1000 mm/s² <= 2000): still a violation
    v = np.array([[10.0, 0.0], [10.0, 100.0], [10.0, 100.0]])
    b = _blocks(v, np.full(3, 0.1))
    b = Blocks(b.machine, b.axis_names, b.index, b.q + [0.0, pos + m.axes[1].offset], b.delta, b.t17,
               b.time, b.alpha, b.max_error, b.tol_mm, cyclic=False)
    hard, soft = timelaw_block_check(m, b)
    assert [h.kind for h in hard] == ["jump"] and hard[0].axis == "X" and soft == []
    t = limit_speed_steps(b.delta, b.time, m.limits("max_jump"), cyclic=False)
    # by hand: block 1 comes down to 0 + 60 mm/s (t = 10 mm / 60 mm/s), then block 2 to 60 + 60 = 120
    # (it was 100: unchanged); block 0 never moves X
    assert t == pytest.approx([0.1, 10.0 / 60.0, 0.1], rel=1e-6)
    vx = b.delta[:, 1] / t
    assert np.all(np.abs(np.diff(vx)) <= 60.0 * (1 + 1e-6))


def test_repeated_circuit_laws_match_the_whole_program_law(monkeypatch: pytest.MonkeyPatch) -> None:
    """Second method: one law over the whole program (rest to rest, every node) against the laws of
    one circuit repeated (first / middle x n-2 / last, boundary speed v_b between circuits)."""
    import engine.pipeline as pl

    path = EXAMPLES / "pipe.toml"
    job = _with_method(load_job(path), "tube")
    base = run_pipeline(job, path, upto="axes")
    rep = run_pipeline(job, path, previous=base, upto="blocks")
    assert rep.timelaw["pieces"] == base.line.circuits and rep.timelaw["laws_computed"] == 3
    monkeypatch.setattr(pl, "_circuit_plan", lambda res, s, X: [(0, s.size - 1)])
    monkeypatch.setattr(pl, "_periodic_pieces", lambda res: None)   # (a replicated axis path's circuits)
    whole = run_pipeline(job, path, previous=base, upto="blocks")
    assert whole.timelaw["pieces"] == 1 and whole.timelaw["boundary_speed_mm_s"] == 0.0
    t_rep, t_whole = rep.timelaw["total_time_s"], whole.timelaw["total_time_s"]
    # the repeated laws pass the circuit junctions no faster than the whole-program law
    assert t_whole * 0.99 <= t_rep <= t_whole * 1.06
    assert whole.blocks.total == pytest.approx(t_whole + whole.timelaw["time_added_s"], rel=0.01)
    assert whole.violations == []


def test_progress_partials_and_cancel_inside_the_time_law() -> None:
    from engine.errors import Cancelled
    from engine.pipeline import PipelineResult
    from engine.state import RecordingState

    path = EXAMPLES / "pipe.toml"
    job = _with_method(load_job(path), "tube")
    base = run_pipeline(job, path, upto="axes")
    st = RecordingState()
    run_pipeline(job, path, previous=base, upto="blocks", state=st)
    assert st.partials and all(isinstance(p, PipelineResult) for p in st.partials)   # no tube iterations
    assert all(0.0 <= f <= 1.0 for f in st.fractions)
    assert st.polls > 10
    with pytest.raises(Cancelled):
        run_pipeline(job, path, previous=base, upto="blocks", state=RecordingState(cancel_after=st.polls // 2))


@pytest.mark.rs274
@pytest.mark.skipif(RS274 is None, reason="LinuxCNC's rs274 interpreter is not installed")
def test_linuxcnc_reads_the_time_law_program(runs, tmp_path: Path) -> None:
    """LinuxCNC's own interpreter: the durations of its moves sum to the law's time.

    In G93 the interpreter turns ``F`` (1/min) into a units/min rate for the canonical move:
    ``SET_FEED_RATE = F·L``, L = the XYZ length of the move, or its ABC length when no linear axis
    moves; the move's duration is ``60·L / rate`` s.
    """
    name, _b18, res = runs
    ngc = write_program(res, tmp_path / f"{name}.ngc")          # no violations: written without force
    proc = subprocess.run([RS274, "-g", str(ngc)], stdin=subprocess.DEVNULL, capture_output=True, text=True,
                          timeout=300)
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0 and not re.search(r"(?i)\berror\b", out), out[-2000:]
    rate, pos, total, moves = None, None, 0.0, 0
    for m in re.finditer(r"SET_FEED_RATE\(([0-9.]+)\)|STRAIGHT_(FEED|TRAVERSE)\(([^)]*)\)", out):
        if m.group(1) is not None:
            rate = float(m.group(1))
            continue
        new = np.array([float(x) for x in m.group(3).split(",")][:6])
        if m.group(2) == "FEED":
            d = new - pos
            L = float(np.linalg.norm(d[:3])) or float(np.linalg.norm(d[3:]))
            total += 60.0 * L / rate if L > 0 else 0.0
            moves += 1
        pos = new
    assert moves == res.blocks.n
    print(f"{name}: rs274 program time {total:.3f} s, law {res.timelaw['total_time_s']:.3f} s")
    assert total == pytest.approx(res.blocks.total, rel=0.01)


def test_technological_path_speed_limit_from_the_job() -> None:
    """[timelaw].sdot_max caps the laying speed: the laid length of every block over its duration."""
    path = EXAMPLES / "pipe.toml"
    job = _with_method(load_job(path), "dp")
    base = run_pipeline(job, path, upto="axes")
    free = run_pipeline(job, path, previous=base, upto="blocks")
    cap = 40.0
    slow_job = job.replace(timelaw={**job.timelaw.model_dump(), "sdot_max": cap})
    slow = run_pipeline(slow_job, path, previous=base, upto="blocks")
    s = base.eye.s
    b = slow.blocks
    laid_speed = np.diff(s[b.index]) / b.time
    assert laid_speed.max() <= cap * (1 + 1e-9)
    assert np.diff(s[free.blocks.index]).sum() == pytest.approx(s[-1] - s[0])
    assert (np.diff(s[free.blocks.index]) / free.blocks.time).max() > cap
    assert slow.blocks.total > free.blocks.total
    # a program at most at cap needs at least the laid length / cap
    assert slow.blocks.total >= (s[-1] - s[0]) / cap


def test_cli_run_with_the_time_law(tmp_path: Path) -> None:
    from engine.cli import main

    job = tmp_path / "pipe_tube.toml"
    job.write_text((EXAMPLES / "pipe.toml").read_text() + '\n[timelaw]\nmethod = "tube"\n')
    out, rep = tmp_path / "p.ngc", tmp_path / "r.json"
    assert main(["run", str(job), "-o", str(out), "--report", str(rep), "--quiet"]) == 0
    data = json.loads(rep.read_text())
    assert data["written"] is True and data["timelaw"]["method"] == "tube"
    assert data["program_time_s"] == pytest.approx(data["timelaw"]["total_time_s"] + data["timelaw"]["time_added_s"],
                                                   rel=1e-6)
    assert _inverse_time_program_time(out.read_text()) == pytest.approx(data["program_time_s"], rel=0.01)


def test_winder_run_subprocess_prints_stage_times(tmp_path: Path) -> None:
    import sys

    winder = Path(sys.executable).parent / "winder"
    if not winder.exists():
        pytest.skip("winder entry point not installed")
    job = tmp_path / "pipe_tube.toml"
    job.write_text((EXAMPLES / "pipe.toml").read_text() + '\n[timelaw]\nmethod = "tube"\n')
    proc = subprocess.run([str(winder), "run", str(job), "-o", str(tmp_path / "p.ngc")], capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "stages: mandrel" in proc.stderr and "blocks " in proc.stderr
    assert (tmp_path / "p.ngc").read_text().count("G1 ") > 100


def test_result_keeps_the_time_laws_and_reuse_keeps_the_objects(runs) -> None:
    """PipelineResult.timelaw_laws: the TimeLaw objects of the blocks stage, with labels and problems; the
    summary agrees with them, stage re-use keeps the very objects, method "blocks" keeps none."""
    from engine.pipeline import compare_time_laws, timelaw_path
    from engine.timeparam import TimeLaw

    name, b18, res = runs
    assert b18.timelaw_laws == () and b18.timelaw_main == -1
    laws = res.timelaw_laws
    assert laws and all(isinstance(lw, TimeLaw) for lw in laws)
    assert len(laws) == len(res.timelaw_labels) == len(res.timelaw_paths) == res.timelaw["laws_computed"]
    assert res.timelaw["iterations"] == sum(len(lw.iterations) for lw in laws)
    if res.timelaw["pieces"] == 1:
        assert res.timelaw_labels == ("whole program",)
        assert laws[0].total_time_s == pytest.approx(res.timelaw["total_time_s"], rel=1e-12)
    else:
        assert res.timelaw_labels == ("first circuit ramp", "circuit (repeated)", "last circuit ramp")
        n = res.timelaw["pieces"]
        total = laws[0].total_time_s + (n - 2) * laws[1].total_time_s + laws[2].total_time_s
        assert total == pytest.approx(res.timelaw["total_time_s"], rel=1e-12)
    main = res.timelaw_main
    s, X, dX, ddX, lim = timelaw_path(res)
    assert s[-1] == pytest.approx(laws[main].s[-1]) and X.shape == dX.shape == ddX.shape == (s.size, X.shape[1])
    # the iteration logs lie on the law's path; the last one is the law there (ramps: spliced on the s offset)
    for lw, p in zip(laws, res.timelaw_paths, strict=True):
        for g in lw.iterations:
            assert g.s[0] + p.iteration_s_offset >= -1e-9 and g.s[-1] + p.iteration_s_offset <= lw.s[-1] + 1e-9
        g = lw.iterations[-1]
        if lw.sweep_gain_s == 0:                    # else the final sweep's law, faster (TimeLimits.sweep)
            np.testing.assert_allclose(np.interp(g.s + p.iteration_s_offset, lw.s, lw.sdot), g.sdot, atol=1e-9)
    # re-running the law's own method on the kept problem reproduces it (the path and limits are complete)
    again = compare_time_laws(res, main, ("toppra", "tube"))
    assert again["tube"] is laws[main]
    assert again["toppra"].total_time_s <= laws[main].total_time_s * 1.005
    other = res.job.replace(post={**res.job.post.model_dump(), "post": "fanuc"})
    res2 = run_pipeline(other, EXAMPLES / f"{name}.toml", previous=res)
    assert "blocks" in res2.reused
    assert res2.timelaw_laws is res.timelaw_laws and res2.timelaw_paths is res.timelaw_paths
    assert all(a is b for a, b in zip(res2.timelaw_laws, laws, strict=True))
    assert res2.timelaw_labels == res.timelaw_labels


def test_timelaw_path_without_a_law_is_an_input_error(runs) -> None:
    from engine.errors import InputError
    from engine.pipeline import timelaw_path

    _name, b18, res = runs
    with pytest.raises(InputError, match="no time law"):
        timelaw_path(b18)
    with pytest.raises(InputError, match="out of range"):
        timelaw_path(res, len(res.timelaw_laws))


def test_final_sweep_switch_of_the_job() -> None:
    """``[timelaw] sweep``: on (the default) the bottle's program is shorter than with the tube's own laws
    (``sweep = false``, whose laws report no sweep gain), both programs hold every limit, and the block times
    follow each law."""
    path = EXAMPLES / "bottle.toml"
    job = load_job(path)
    assert job.timelaw.sweep is True
    base = run_pipeline(job, path, upto="axes")
    on = run_pipeline(job, path, previous=base)
    off = run_pipeline(job.replace(timelaw={**job.timelaw.model_dump(), "sweep": False}), path, previous=base)
    assert "blocks" not in off.reused
    assert all(lw.sweep_gain_s == 0.0 for lw in off.timelaw_laws)
    assert any(lw.sweep_gain_s > 0.0 for lw in on.timelaw_laws)
    t_on, t_off = on.report()["program_time_s"], off.report()["program_time_s"]
    assert t_on < 0.99 * t_off                          # 545.9 against 571.3 s when this was written
    for res in (on, off):
        rep = res.report()
        assert rep["timelaw"]["max_accel_ratio"] <= 1.0 + 1e-9
        assert max(rep["max_speed_ratio"].values()) <= 1.0 + 1e-9
        assert rep["program_time_s"] == pytest.approx(float(np.sum(res.blocks.time)), rel=1e-9)
