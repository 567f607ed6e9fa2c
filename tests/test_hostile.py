"""Hostile input (issue 19): budgets, guarded readers and writers, the STEP sandbox, consistent verdicts."""

from __future__ import annotations

import errno
import os
import re
import subprocess
import sys
import time
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from engine import budget
from engine.cli import main
from engine.errors import InputError
from engine.fileio import atomic_write_text, check_output_path, loads_toml, remove_stale_temporaries

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "resources" / "examples"

PIPE = """schema_version = 1
name = "small pipe"
[mandrel]
kind = "pipe"
radius_mm = 40.0
length_mm = 200.0
[band]
width_mm = 10.0
friction = 0.2
[winding]
mode = "geodesic"
points_per_pass = 100
dwell_deg = [180.0, 180.0]
[[winding.angles]]
z_mm = 100.0
angle_deg = 55.0
[payout]
law = "min-range"
grid_points = 200
[machine]
template = "lathe2"
[machine.axes.X]
max = 1800.0
[timelaw]
method = "blocks"
[post]
post = "linuxcnc"
"""


def _job(tmp_path: Path, text: str, name: str = "job.toml") -> Path:
    p = tmp_path / name
    p.write_text(text, encoding="utf-8")
    return p


def _cli(capsys, *argv: str) -> tuple[int, str, str]:
    rc = main(list(argv))
    out, err = capsys.readouterr()
    return rc, out, err


def _line_of(path: Path, key: str) -> int:
    return next(i for i, ln in enumerate(path.read_text().splitlines(), 1) if ln.startswith(key))


# ------------------------------------------------------------------------------------------------
# Budgets before work
# ------------------------------------------------------------------------------------------------
@pytest.mark.parametrize(("edit", "field", "words"), [
    (("width_mm = 10.0", "width_mm = 1e-9"), "band.width_mm", "narrower than a single fibre"),
    (("points_per_pass = 100", "points_per_pass = 100\ncircuits = 1000000000000"), "winding.circuits",
     "closer than a fibre"),
    (("points_per_pass = 100", "points_per_pass = 100\npattern_p = 1000000000"), "winding.pattern_p",
     "closer than a fibre"),
    (("points_per_pass = 100", "points_per_pass = 100\nlayers = 1000000"), "winding.layers", "memory budget"),
    (("dwell_deg = [180.0, 180.0]", "dwell_deg = [1e308, 0.0]"), "winding.dwell_deg.0", "more than 3 turns"),
    (("radius_mm = 40.0", "radius_mm = 1e6"), "mandrel", "beyond any winding machine"),
    (("length_mm = 200.0", "length_mm = 1e308"), "mandrel.length_mm", "beyond any mandrel"),
    (('post = "linuxcnc"', 'post = "linuxcnc"\nmin_block_time_s = 1e308'), "post.min_block_time_s",
     "not a winding program"),
])
def test_absurd_jobs_are_refused_before_work_naming_file_line_field(tmp_path, capsys, edit, field, words) -> None:
    job = _job(tmp_path, PIPE.replace(*edit))
    out = tmp_path / "out.ngc"
    t0 = time.perf_counter()
    rc, _, err = _cli(capsys, "run", str(job), "-o", str(out), "--quiet")
    assert rc == 2 and not out.exists()
    assert time.perf_counter() - t0 < 60  # not a timing test: a hang would have taken hours
    assert str(job) in err and f"field '{field}'" in err and words in err, err
    if field not in ("mandrel",):
        key = field.split(".")[1]
        assert f"line {_line_of(job, key)}" in err, err


def test_memory_budget_names_the_estimate_and_can_be_raised(tmp_path, capsys) -> None:
    # (400 circuits are kept as circuit 0 + rule, engine.budget.BYTES_PER_REPLICATED_POINT: 1 000 points a
    # pass make it ~200 MB)
    job = _job(tmp_path, PIPE.replace("points_per_pass = 100", "points_per_pass = 1000\ncircuits = 400"))
    rc, _, err = _cli(capsys, "trajectory", str(job), "--json", "--max-memory", "64M")
    assert rc == 2 and "field 'winding.circuits'" in err and "64 MB" in err and "--max-memory" in err
    assert re.search(r"about [\d,]+ winding-line points", err)
    rc, out, err = _cli(capsys, "trajectory", str(job), "--json", "--max-memory", "1G")
    assert rc == 0 and '"circuits": 400' in out
    assert budget.max_memory_bytes() == budget.DEFAULT_MAX_MEMORY_BYTES  # the option holds for one command


def test_estimate_bounds_the_real_line(tmp_path) -> None:
    """The estimate is an upper bound of the points the winding stage really makes, and not a loose one."""
    from engine.job import load_job
    from engine.winding import winding_line_for_job

    for extra in ("", "circuits = 12\n", "layers = 3\n", "pattern_p = 7\n", "dwell_deg = [400.0, 30.0]\n"):
        text = PIPE.replace("dwell_deg = [180.0, 180.0]\n", "") if "dwell" in extra else PIPE
        p = _job(tmp_path, text.replace("points_per_pass = 100\n", "points_per_pass = 100\n" + extra))
        job = load_job(p)
        line = winding_line_for_job(job, p)
        est = budget.check_winding_spec(job.winding, 40.0, 10.0)
        assert line.z.size <= est.count <= 3.0 * line.z.size, (extra, line.z.size, est.count)


@pytest.mark.parametrize(("text", "value"), [("4G", 4 * 2**30), ("512M", 512 * 2**20), ("12GB", 12 * 2**30),
                                             ("1.5g", int(1.5 * 2**30)), ("100000000", 100000000)])
def test_parse_size(text, value) -> None:
    assert budget.parse_size(text) == value


@pytest.mark.parametrize("text", ["", "x", "-1G", "1e400", "0", "10k", "1e30"])
def test_parse_size_refuses(text) -> None:
    with pytest.raises(InputError, match="--max-memory"):
        budget.parse_size(text)


def test_bad_max_memory_option_is_exit_2(tmp_path, capsys) -> None:
    rc, _, err = _cli(capsys, "trajectory", str(_job(tmp_path, PIPE)), "--max-memory", "lots")
    assert rc == 2 and "'lots' is not a size" in err


def test_schema_and_engine_agree_on_levels() -> None:
    from pydantic import ValidationError

    from engine.job import TimeLawSpec
    from engine.timeparam import _MAX_LEVELS

    assert TimeLawSpec(levels=_MAX_LEVELS).levels == _MAX_LEVELS
    with pytest.raises(ValidationError):
        TimeLawSpec(levels=_MAX_LEVELS + 1)


def test_many_speed_levels_are_refused_before_work_by_the_dp_work_model(tmp_path, capsys) -> None:
    """levels = 4096 (the schema's largest) with the tube method on a small pipe: 200 s of CPU before (the
    n × M² model ignored the transition tables leaving the cache and the tube's passes, found by probing
    the schema's extremes); now refused before any DP, naming the field, its line and the largest M."""
    job = _job(tmp_path, PIPE.replace('method = "blocks"', 'method = "tube"\nlevels = 4096'))
    out = tmp_path / "o.ngc"
    rc, _, err = _cli(capsys, "run", str(job), "-o", str(out), "--quiet")
    assert rc == 2 and not out.exists(), err
    assert f"line {_line_of(job, 'levels')}, field 'timelaw.levels'" in err and "too slow" in err, err
    m = int(re.search(r"use at most (\d+) levels", err).group(1))
    n = int(re.search(r"over (\d+) nodes", err).group(1))
    assert budget.dp_work(n, m, budget.TUBE_PASSES) <= budget.MAX_DP_WORK < budget.dp_work(n, m + 1, budget.TUBE_PASSES)


def test_dense_profile_is_decimated_within_the_stated_tolerance(tmp_path) -> None:
    from engine.mandrel_io import MAX_SPLINE_POINTS, load_csv

    z = np.linspace(0.0, 300.0, 60_000)
    r = 50.0 + 5.0 * np.sin(z / 30.0) + 2.0 * np.tanh((z - 150.0) / 5.0)
    p = tmp_path / "scan.csv"
    p.write_text("z,r\n" + "\n".join(f"{a!r},{b!r}" for a, b in zip(z.tolist(), r.tolist())) + "\n", encoding="utf-8")
    m = load_csv(p)
    d = m.meta["decimated"]
    assert d["points_in_file"] == 60_000 and d["points_kept"] <= MAX_SPLINE_POINTS
    # independent check: the mandrel's own curve against every point of the file
    dev = np.abs(m.evaluate(z)[0] - r).max()
    assert dev <= d["tolerance_mm"] * (1 + 1e-9) and d["tolerance_mm"] == pytest.approx(1e-3)
    assert "decimated" in m.meta["note"] and "0.001 mm" in m.meta["note"]


# ------------------------------------------------------------------------------------------------
# Guarded TOML reader
# ------------------------------------------------------------------------------------------------
def test_deeply_nested_toml_is_an_input_error_with_the_line(tmp_path, capsys) -> None:
    job = _job(tmp_path, PIPE + "deep = " + "[" * 5000 + "]" * 5000 + "\n")
    rc, _, err = _cli(capsys, "run", str(job), "-o", str(tmp_path / "o.ngc"))
    assert rc == 2 and "nested 5000 deep" in err and f"line {PIPE.count(chr(10)) + 1}" in err
    assert "Traceback" not in err


def test_toml_parser_failures_are_input_errors() -> None:
    with pytest.raises(InputError, match="not valid TOML.*digits"):
        loads_toml("a = 1" + "0" * 6000, "x.toml")
    # nesting within the pre-check but deep enough to exhaust the recursive parser's stack
    import engine.fileio as fio

    old = fio.MAX_TOML_DEPTH
    try:
        fio.MAX_TOML_DEPTH = 10**6
        with pytest.raises(InputError, match="nested too deeply") as e:
            loads_toml("a = " + "[" * 20000 + "]" * 20000, "x.toml")
        assert e.value.location.line == 1 and e.value.location.file == "x.toml"
    finally:
        fio.MAX_TOML_DEPTH = old
    with pytest.raises(InputError, match="characters long"):
        loads_toml("x" * (fio.MAX_TOML_BYTES + 1))


def test_limits_file_reader_is_guarded(tmp_path, capsys) -> None:
    lim = tmp_path / "limits.toml"
    lim.write_text("v_max = " + "[" * 1000 + "]" * 1000, encoding="utf-8")
    rc, _, err = _cli(capsys, "timeparam", "--example", "--limits", str(lim))
    assert rc == 2 and str(lim) in err and "nested" in err


# ------------------------------------------------------------------------------------------------
# Output paths and atomic writes
# ------------------------------------------------------------------------------------------------
def test_output_path_checks(tmp_path, capsys) -> None:
    job = _job(tmp_path, PIPE)
    for target, words in ((tmp_path, "the path is a folder"), (tmp_path / "no" / "x.ngc", "does not exist"),
                          (job / "x.ngc", "is not a folder")):
        rc, _, err = _cli(capsys, "run", str(job), "-o", str(target), "--quiet")
        assert rc == 2 and words in err and str(target) in err, err
    rc, _, err = _cli(capsys, "trajectory", str(job), "--csv", str(tmp_path))
    assert rc == 2 and "cannot write the CSV file: the path is a folder" in err
    rc, _, err = _cli(capsys, "run", str(job), "-o", str(tmp_path / "o.ngc"), "--report", str(tmp_path / "no/r.json"))
    assert rc == 2 and not (tmp_path / "o.ngc").exists()  # refused before any work


@pytest.mark.skipif(os.geteuid() == 0, reason="root may write anywhere")
def test_output_without_permission(tmp_path) -> None:
    d = tmp_path / "ro"
    d.mkdir()
    d.chmod(0o555)
    try:
        with pytest.raises(InputError, match="no permission"):
            check_output_path(d / "x.ngc")
    finally:
        d.chmod(0o755)


def test_an_output_through_a_symlink_keeps_the_link(tmp_path) -> None:
    """Writing to a symlink replaces the file it points to, atomically, and leaves the link a link (a
    dangling link gets its file); the temporary files are made beside the real file."""
    real_dir = tmp_path / "share"
    real_dir.mkdir()
    real = real_dir / "prog.ngc"
    real.write_text("old\n")
    link = tmp_path / "current.ngc"
    link.symlink_to(real)
    assert atomic_write_text(link, "new\n") == link
    assert link.is_symlink() and os.readlink(link) == str(real) and real.read_text() == "new\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["current.ngc", "share"]
    assert sorted(p.name for p in real_dir.iterdir()) == ["prog.ngc"]
    dangling = tmp_path / "next.ngc"
    dangling.symlink_to(real_dir / "later.ngc")
    atomic_write_text(dangling, "later\n")
    assert dangling.is_symlink() and (real_dir / "later.ngc").read_text() == "later\n"


def test_an_output_into_a_pipe_or_device_is_written_into_it(tmp_path) -> None:
    """A FIFO (as ``/dev/stdout`` on a pipe) or a character device behind a symlink is written into, not
    replaced by a regular file: a reader gets the whole content, the FIFO and the link stay what they were;
    ``winder run -o FIFO`` sends the NC program through it."""
    import stat
    import threading

    fifo = tmp_path / "out.fifo"
    os.mkfifo(fifo)
    got: list[bytes] = []

    def read() -> None:
        with open(fifo, "rb") as fh:
            got.append(fh.read())

    t = threading.Thread(target=read, daemon=True)
    t.start()
    atomic_write_text(fifo, "through the pipe\n")
    t.join(30)
    assert got == [b"through the pipe\n"] and stat.S_ISFIFO(os.stat(fifo).st_mode)
    null = tmp_path / "null"
    null.symlink_to("/dev/null")
    atomic_write_text(null, "gone\n")
    assert null.is_symlink() and stat.S_ISCHR(os.stat("/dev/null").st_mode)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["null", "out.fifo"]
    job = tmp_path / "job.toml"
    job.write_text(PIPE, encoding="utf-8")
    got.clear()
    t = threading.Thread(target=read, daemon=True)
    t.start()
    rc = main(["run", str(job), "-o", str(fifo), "--quiet"])
    t.join(120)
    assert rc == 0 and got
    assert main(["run", str(job), "-o", str(tmp_path / "file.ngc"), "--quiet"]) == 0
    assert got[0] == (tmp_path / "file.ngc").read_bytes() and got[0].endswith(b"M2\n")


def test_disk_full_keeps_the_previous_file_and_no_temporary(tmp_path) -> None:
    target = tmp_path / "prog.ngc"
    target.write_text("the previous program\n")

    def full(_tmp: str) -> None:
        raise OSError(errno.ENOSPC, "No space left on device")

    from engine.fileio import atomic_write_with

    with pytest.raises(InputError, match="disk is full") as e:
        atomic_write_with(target, full)
    assert e.value.location.file == str(target)
    assert target.read_text() == "the previous program\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["prog.ngc"]


def test_stale_temporaries_of_killed_writes_are_removed(tmp_path) -> None:
    # a dead process (no such PID) and an old file: removed; a live one (ours): kept
    dead = tmp_path / ".prog.ngc.winder-999999999-abcd.ngc"
    live = tmp_path / f".prog.ngc.winder-{os.getpid()}-efgh.ngc"
    fresh = tmp_path / ".prog.ngc.winder-999999998-ijkl.ngc"
    for p in (dead, live, fresh):
        p.write_text("partial")
    old = time.time() - 3600
    os.utime(dead, (old, old))
    os.utime(live, (old, old))
    assert remove_stale_temporaries(tmp_path) == 1
    assert not dead.exists() and live.exists() and fresh.exists()
    # the next write into the folder cleans up; a killed write's temporary is named with its PID
    os.utime(fresh, (old, old))
    atomic_write_text(tmp_path / "prog.ngc", "G0\n")
    assert not fresh.exists() and (tmp_path / "prog.ngc").read_text() == "G0\n"


def test_killed_write_leaves_a_named_temporary_that_the_next_run_removes(tmp_path) -> None:
    """A real kill: a child process is killed inside the writer; the next write removes its temporary."""
    code = ("import os, signal, sys; from engine.fileio import atomic_write_with; "
            "atomic_write_with(sys.argv[1], lambda tmp: os.kill(os.getpid(), signal.SIGKILL))")
    target = tmp_path / "prog.ngc"
    target.write_text("old\n")
    proc = subprocess.run([sys.executable, "-c", code, str(target)], env={**os.environ, "PYTHONPATH": str(ROOT)},
                          timeout=120)
    assert proc.returncode == -9
    left = [p for p in tmp_path.iterdir() if p.name != "prog.ngc"]
    assert len(left) == 1 and ".winder-" in left[0].name and target.read_text() == "old\n"
    old = time.time() - 3600
    os.utime(left[0], (old, old))
    atomic_write_text(target, "new\n")
    assert [p.name for p in tmp_path.iterdir()] == ["prog.ngc"] and target.read_text() == "new\n"


# ------------------------------------------------------------------------------------------------
# .npz and limits readers
# ------------------------------------------------------------------------------------------------
def _npz(path: Path, **arrays) -> Path:
    np.savez(path, **arrays)
    return path


def _path_arrays(n: int = 40) -> dict[str, np.ndarray]:
    s = np.linspace(0.0, 100.0, n)
    return {"s": s, "X": np.column_stack([s, s]), "dX": np.ones((n, 2)), "ddX": np.zeros((n, 2))}


@pytest.mark.parametrize(("change", "words"), [
    ({"X": np.full((40, 2), np.nan)}, "non-finite"),
    ({"s": np.zeros((40, 2))}, "2 dimensions"),
    ({"dX": np.array(["a", "b"])}, "dtype"),
    ({"ddX": np.zeros((40, 2, 2))}, "3 dimensions"),
    ({"s": np.linspace(100.0, 0.0, 40)}, "increase strictly"),
    ({"X": np.zeros((7, 2))}, "shape"),
    ({"dX": np.full((40, 2), 1e308)}, "beyond 1e+09"),  # found by the fuzzer: dp overflowed, NaN in the JSON
    ({"s": np.linspace(0.0, 1e300, 40)}, "within ±1e+09 mm"),
])
def test_bad_npz_paths_are_input_errors(tmp_path, capsys, change, words) -> None:
    lim = tmp_path / "limits.toml"
    lim.write_text("v_max = [1.0, 1.0]\na_max = [1.0, 1.0]\n")
    p = _npz(tmp_path / "path.npz", **{**_path_arrays(), **change})
    rc, _, err = _cli(capsys, "timeparam", str(p), "--limits", str(lim))
    assert rc == 2 and str(p) in err and words in err, err


def test_npz_bomb_and_garbage(tmp_path, capsys) -> None:
    sys.path.insert(0, str(Path(__file__).parent))
    from fuzz_cases import npz_bomb

    lim = tmp_path / "limits.toml"
    lim.write_text("v_max = [1.0]\na_max = [1.0]\n")
    for name, data, words in (("bomb.npz", npz_bomb(), "8 TB"), ("text.npz", b"not a zip", "not a readable .npz"),
                              ("empty.npz", b"", "not a readable .npz")):
        p = tmp_path / name
        p.write_bytes(data)
        rc, _, err = _cli(capsys, "timeparam", str(p), "--limits", str(lim))
        assert rc == 2 and str(p) in err and words in err, err


# ------------------------------------------------------------------------------------------------
# Consistent verdicts
# ------------------------------------------------------------------------------------------------
def test_run_refuses_what_trajectory_reports_as_slipping(tmp_path, capsys) -> None:
    text = (EXAMPLES / "pressure_vessel.toml").read_text().replace("friction = 0.2", "friction = 1e-9")
    text = text.replace("points_per_pass = 2000", "points_per_pass = 200") + '[timelaw]\nmethod = "blocks"\n'
    job = _job(tmp_path, text)
    rc_t, _, _ = _cli(capsys, "trajectory", str(job))
    out = tmp_path / "o.ngc"
    rc, _, err = _cli(capsys, "run", str(job), "-o", str(out), "--quiet")
    assert rc_t == 1 and rc == 1 and not out.exists() and "slips" in err and "--force" in err
    rc, _, _ = _cli(capsys, "run", str(job), "-o", str(out), "--quiet", "--force")
    assert rc == 0 and out.exists()


def test_run_of_a_laminate_refuses_what_payout_and_layup_report_infeasible(tmp_path, capsys) -> None:
    """A layered job whose helical layer's eye path sags at the pins (parallel law): ``payout`` and
    ``layup`` exit 1, and ``run`` writes nothing (exit 1, naming the layer) unless --force."""
    text = PIPE.replace("schema_version = 1", "schema_version = 2").replace('law = "min-range"', 'law = "parallel"')
    job = _job(tmp_path, text + '[[layer]]\nkind = "hoop"\n[[layer]]\nkind = "helical"\nname = "h55"\n')
    rc_p, _, _ = _cli(capsys, "payout", str(job))
    rc_l, _, _ = _cli(capsys, "layup", str(job), "--quiet")
    out = tmp_path / "o.ngc"
    rc, _, err = _cli(capsys, "run", str(job), "-o", str(out), "--quiet")
    assert (rc_p, rc_l, rc) == (1, 1, 1) and not out.exists(), err
    assert "layer 2 (h55): payout (parallel law)" in err and "--force" in err, err
    rc, _, _ = _cli(capsys, "run", str(job), "-o", str(out), "--quiet", "--force")
    assert rc == 0 and out.exists()


def test_no_program_with_a_non_finite_or_zero_feed(tmp_path) -> None:
    from engine.job import load_job
    from engine.pipeline import run_pipeline, write_program

    p = _job(tmp_path, PIPE)
    res = run_pipeline(load_job(p), p)
    out = tmp_path / "o.ngc"
    for bad in (np.inf, 0.0, np.nan):
        t = np.array(res.blocks.time, dtype=float)
        t[3] = bad
        broken = replace(res, blocks=replace(res.blocks, time=t))
        with pytest.raises(InputError, match="non-finite or zero duration"):
            write_program(broken, out, force=True)
        assert not out.exists()
    write_program(res, out)
    assert out.stat().st_size > 0


def test_post_list_has_no_empty_name() -> None:
    from engine.post import get_post, list_posts

    assert all(list_posts()) and "linuxcnc" in list_posts()
    with pytest.raises(InputError, match="known: csv"):
        get_post("")


def test_broken_pipe_ends_quietly(tmp_path) -> None:
    cmd = (f"{sys.executable} -m engine trajectory {EXAMPLES / 'pressure_vessel.toml'} --json | head -1; "
           "exit ${PIPESTATUS[0]}")
    proc = subprocess.run(["bash", "-c", cmd], capture_output=True, text=True, timeout=300,
                          env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert proc.stdout == "{\n" and proc.stderr == "" and proc.returncode == 0


def test_warnings_are_messages_not_python_warnings(tmp_path, capsys, monkeypatch) -> None:
    import engine.cli.mandrel as cm

    real = cm.load_any_mandrel

    def noisy(path):
        np.log(np.zeros(2))  # RuntimeWarning: divide by zero
        warnings.warn("something odd", RuntimeWarning, stacklevel=1)
        return real(path)

    monkeypatch.setattr(cm, "load_any_mandrel", noisy)
    rc, _, err = _cli(capsys, "mandrel", str(EXAMPLES / "pipe.toml"))
    assert rc == 0
    assert "note: numerical warning (RuntimeWarning): divide by zero" in err and "something odd" in err
    assert not re.search(r"^\S+:\d+: RuntimeWarning", err, re.M)
    # after an input error the message says it all
    monkeypatch.setattr(cm, "load_any_mandrel", lambda p: (np.log(np.zeros(1)), real(p))[1])
    rc, _, err = _cli(capsys, "mandrel", str(tmp_path / "nope.csv"))
    assert rc == 2 and "numerical warning" not in err and "RuntimeWarning" not in err


# ------------------------------------------------------------------------------------------------
# The sandbox (STEP reader)
# ------------------------------------------------------------------------------------------------
def test_sandbox_turns_a_crash_a_hang_and_a_hog_into_messages(tmp_path) -> None:
    from engine.sandbox import run_isolated

    assert run_isolated("sandbox_targets:echo", 1, "a", what="x") == (1, "a")
    with pytest.raises(InputError, match=r"the STEP reader crashed on this file \(SIGSEGV\)") as e:
        run_isolated("sandbox_targets:crash", what="the STEP reader", file="m.step")
    assert e.value.location.file == "m.step"
    t0 = time.monotonic()
    with pytest.raises(InputError, match="gave up after 1 s"):
        run_isolated("sandbox_targets:hang", what="the STEP reader", file="m.step", timeout_s=1.0)
    assert time.monotonic() - t0 < 60
    with pytest.raises(InputError, match=r"needed more than its memory budget \(256 MB\)"):
        run_isolated("sandbox_targets:hog", what="the STEP reader", file="m.step", memory_bytes=256 * 2**20)


def test_step_reader_errors_keep_their_place_through_the_sandbox(tmp_path, capsys) -> None:
    data = (EXAMPLES / "vessel.step").read_bytes()
    p = tmp_path / "cut.step"
    p.write_bytes(data[: len(data) // 3])
    rc, out, err = _cli(capsys, "mandrel", str(p), "--json")
    assert rc == 2 and str(p) in err and "cannot read the STEP model" in err
    assert "ERR" not in out + err  # the kernel's own chatter stays in the child


def test_crashing_step_reader_in_a_job_is_exit_2(tmp_path, capsys, monkeypatch) -> None:
    import engine.mandrel_io as mio

    monkeypatch.setattr(mio, "STEP_READER", "sandbox_targets:crash")
    (tmp_path / "m.step").write_bytes((EXAMPLES / "vessel.step").read_bytes())
    job = _job(tmp_path, 'schema_version = 1\n[mandrel]\nkind = "file"\npath = "m.step"\n')
    rc, _, err = _cli(capsys, "trajectory", str(job))
    assert rc == 2 and "the STEP reader crashed on this file" in err and str(tmp_path / "m.step") in err


@pytest.mark.parametrize("tol", ["1e308", "1e-9", "nan", "-1"])
def test_stl_tolerance_outside_its_range_is_refused(tmp_path, capsys, tol) -> None:
    out = tmp_path / "m.stl"
    rc, _, err = _cli(capsys, "mandrel", str(EXAMPLES / "pipe.toml"), "--stl", str(out), "--stl-tolerance", tol)
    assert rc == 2 and "STL tolerance must be in 0.0001" in err and not out.exists()


def test_output_name_too_long(tmp_path, capsys) -> None:
    out = tmp_path / ("n" * 300 + ".ngc")
    rc, _, err = _cli(capsys, "run", str(_job(tmp_path, PIPE)), "-o", str(out), "--quiet")
    assert rc == 2 and "the file name is too long" in err


@pytest.mark.parametrize(("edit", "field"), [('post = "nosuch"', "post.post"),
                                             ('controller = "nosuch"', "post.controller"),
                                             ('template = "nosuch"', "machine.template")])
def test_run_errors_name_the_job_field_and_line(tmp_path, capsys, edit, field) -> None:
    key = edit.split(" ")[0]
    text = PIPE.replace('post = "linuxcnc"', 'post = "linuxcnc"\ncontroller = "linuxcnc"')
    text = "\n".join(edit if ln.startswith(key + " ") else ln for ln in text.splitlines()) + "\n"
    job = _job(tmp_path, text)
    rc, _, err = _cli(capsys, "run", str(job), "-o", str(tmp_path / "o.ngc"), "--quiet")
    assert rc == 2 and f"{job}, line {_line_of(job, key + ' ')}, field '{field}'" in err, err


def test_large_csv_fast_path_agrees_with_the_general_reader(tmp_path, monkeypatch) -> None:
    import engine.mandrel_io as mio

    z = np.linspace(0.0, 300.0, 40_000)
    r = 50.0 + 5.0 * np.sin(z / 30.0)
    rows = [f"{a!r};{b!r}" for a, b in zip(z.tolist(), r.tolist())]
    p = tmp_path / "scan.csv"
    p.write_text("z_mm;r_mm\n" + "\n".join(rows) + "\n", encoding="utf-8")
    fast = mio.load_csv(p)
    monkeypatch.setattr(mio, "_FAST_CSV_BYTES", 10**12)  # the general reader only
    slow = mio.load_csv(p)
    assert fast.meta["decimated"] == slow.meta["decimated"]
    np.testing.assert_array_equal(fast.evaluate(z)[0], slow.evaluate(z)[0])
    # a bad cell in a large file: the general reader names its line and column
    monkeypatch.setattr(mio, "_FAST_CSV_BYTES", 1_000_000)
    rows[12345] = "12.5;abc"
    p.write_text("z_mm;r_mm\n" + "\n".join(rows) + "\n", encoding="utf-8")
    with pytest.raises(InputError) as e:
        mio.load_csv(p)
    assert e.value.location.line == 12347 and "r_mm (column 2)" in str(e.value)
    rows[12345] = f"{z[12344]!r};50.0"  # z not increasing
    p.write_text("z_mm;r_mm\n" + "\n".join(rows) + "\n", encoding="utf-8")
    with pytest.raises(InputError) as e:
        mio.load_csv(p)
    assert e.value.location.line == 12347, e.value


def test_sketch_with_too_many_points_is_refused(tmp_path, capsys) -> None:
    z = np.linspace(0.0, 100.0, budget.MAX_SKETCH_POINTS + 1)
    r = 50.0 + np.sin(z / 10.0)
    job = _job(tmp_path, 'schema_version = 1\n[mandrel]\nkind = "points"\nz_mm = [' + ", ".join(map(repr, z.tolist()))
               + "]\nr_mm = [" + ", ".join(map(repr, r.tolist())) + "]\n")
    rc, _, err = _cli(capsys, "mandrel", str(job))
    assert rc == 2 and "line 4, field 'mandrel.z_mm'" in err and "at most 20000" in err


def test_dxf_spline_with_a_broken_knot_vector_is_refused_quickly(tmp_path, capsys) -> None:
    """Found by the fuzzer: a SPLINE whose last knot was 0 made ezdxf's adaptive flattening subdivide for
    hours (trajectory hung); a control point far off the drawing plane did the same."""
    import ezdxf

    doc = ezdxf.readfile(EXAMPLES / "vessel_profile.dxf")
    spline = next(e for e in doc.modelspace() if e.dxftype() == "SPLINE")
    knots = list(spline.knots)
    spline.knots = knots[:-1] + [0.0]
    p = tmp_path / "knots.dxf"
    doc.saveas(p)
    rc, _, err = _cli(capsys, "mandrel", str(p))
    assert rc == 2 and str(p) in err and "knot vector is not finite and increasing" in err, err
    spline.knots = knots
    cps = [tuple(c) for c in spline.control_points]
    cps[15] = (cps[15][0], cps[15][1], 1.23456789e7)
    spline.control_points = cps
    doc.saveas(p)
    rc, _, err = _cli(capsys, "mandrel", str(p))
    assert rc == 0, err  # the profile is the drawing's x, y: the spline is flattened in its plane


def test_huge_dxf_is_refused_before_parsing(tmp_path, capsys) -> None:
    from engine.mandrel_io import MAX_DXF_TAGS

    p = tmp_path / "many.dxf"
    p.write_bytes(b"  0\nSECTION\n  2\nENTITIES\n" + b"  0\nLINE\n 10\n1.0\n 20\n50.0\n" * (MAX_DXF_TAGS // 2))
    rc, _, err = _cli(capsys, "mandrel", str(p))
    assert rc == 2 and str(p) in err and f"more than {MAX_DXF_TAGS}" in err


@pytest.mark.parametrize(("extra", "field", "words"), [
    ("overlap = 0.9999999", "layer.2.overlap", "hoop-layer points"),
    ("band = { width_mm = 1e-9 }", "layer.2.band.width_mm", "narrower than a single fibre"),
])
def test_laminate_layers_are_budgeted(tmp_path, capsys, extra, field, words) -> None:
    text = (EXAMPLES / "bottle.toml").read_text().replace("terminal = true", "terminal = true\n" + extra)
    job = _job(tmp_path, text)
    rc, _, err = _cli(capsys, "run", str(job), "-o", str(tmp_path / "o.ngc"), "--quiet")
    assert rc == 2 and f"field '{field}'" in err and words in err and str(job) in err, err


LAYERED = PIPE.replace("schema_version = 1", "schema_version = 2") + """[[layer]]
kind = "hoop"
name = "inner"
[[layer]]
kind = "helical"
[[layer]]
kind = "hoop"
name = "outer"
"""


@pytest.mark.parametrize(("edit", "field", "words"), [
    ("passes = 1000\nrepeat = 1000", "layer.3.repeat", "hoop-layer points"),
    ("points_per_turn = 2000\npasses = 1000", "layer.3.passes", "hoop-layer points"),
    ("z_range_mm = [-1e6, 1e6]", "layer.3.z_range_mm", "hoop-layer points"),
    ("z_range_mm = [500.0, 900.0]", "layer.3.z_range_mm", "outside the surface"),
    ("band = { width_mm = 1e-9 }", "layer.3.band.width_mm", "narrower than a single fibre"),
])
def test_hostile_layer_fields_name_their_layer_line_and_field(tmp_path, capsys, edit, field, words) -> None:
    """A size attack on one layer is refused before any work, naming that layer's field and its line in
    the file (the third [[layer]], not the first one that has the key)."""
    job = _job(tmp_path, LAYERED.replace('name = "outer"', 'name = "outer"\n' + edit))
    key = field.split(".")[2] + " ="
    line = max(i for i, ln in enumerate(job.read_text().splitlines(), 1) if ln.startswith(key))
    out = tmp_path / "o.ngc"
    rc, _, err = _cli(capsys, "run", str(job), "-o", str(out), "--quiet")
    assert rc == 2 and not out.exists(), err
    assert f"{job}, line {line}, field '{field}'" in err and words in err, err


@pytest.mark.parametrize(("edit", "field"), [
    ("lead_out_deg = 1e9", "layer.3.lead_out_deg"),  # found by the fuzzer: a 9.5 GB transition, MemoryError
    ("lead_in_mm = 1e308", "layer.3.lead_in_mm"),
])
def test_schema_refuses_turns_and_leads_the_engine_cannot_move(tmp_path, capsys, edit, field) -> None:
    job = _job(tmp_path, LAYERED.replace('name = "outer"', 'name = "outer"\n' + edit))
    rc, _, err = _cli(capsys, "layup", str(job), "--quiet")
    line = _line_of(job, edit.split(" =")[0])
    assert rc == 2 and f"line {line}, field '{field}'" in err and "less than or equal" in err, err
    skip = _job(tmp_path, LAYERED + '[[layer]]\nkind = "skip"\nangle_deg = 1e308\n', "skip.toml")
    rc, _, err = _cli(capsys, "layup", str(skip), "--quiet")
    last = len(skip.read_text().splitlines())  # angle_deg = 1e308 is the file's last line
    assert rc == 2 and f"line {last}, field 'layer.4.angle_deg'" in err, err


@pytest.mark.parametrize(("edit", "field", "words"), [
    (('post = "linuxcnc"', 'post = "linuxcnc"\ntolerance_mm = 1e308'), "post.tolerance_mm", "does not lay it"),
    (('post = "linuxcnc"', 'post = "linuxcnc"\nmin_block_time_s = 11'), "post.min_block_time_s", "at most 10 s"),
    (('method = "blocks"', 'method = "tube"\nsdot_max = 1e-300'), "timelaw.sdot_max", "greater than or equal"),
    (('method = "blocks"', 'method = "tube"\npenalty = 1e308'), "timelaw.penalty", "less than or equal"),
    (("friction = 0.2", "friction = 1e308"), "band.friction", "not physical"),  # a report's ±μ plot overflowed
    (("friction = 0.2", "friction = 0.2\nthickness_mm = 1e308"), "band.thickness_mm", "more than its width"),
    (("dwell_deg = [180.0, 180.0]", "dwell_deg = [180.0, 1081.0]"), "winding.dwell_deg.1", "more than 3 turns"),
])
def test_the_schema_refuses_what_the_engine_would(tmp_path, capsys, edit, field, words) -> None:
    """Values the engine cannot use are refused when the job is read (the GUI's fields validate with the
    same schema), with the file, the line and the field; the limits are the engine's own."""
    from engine import job as J

    assert (J.MAX_DWELL_DEG, J.MAX_MIN_BLOCK_TIME_S) == (budget.MAX_DWELL_DEG, budget.MAX_MIN_BLOCK_TIME_S)
    job = _job(tmp_path, PIPE.replace(*edit))
    out = tmp_path / "o.ngc"
    rc, _, err = _cli(capsys, "run", str(job), "-o", str(out), "--quiet")
    key = field.split(".")[1]
    line = max(i for i, ln in enumerate(job.read_text().splitlines(), 1) if ln.startswith(key))
    assert rc == 2 and not out.exists() and f"{job}, line {line}, field '{field}'" in err and words in err, err


def test_mandrel_beyond_the_machines_swing_is_refused_before_work(tmp_path, capsys) -> None:
    """A 3 m radius on lathe2 (eye at 160 mm): refused by the machine pre-check, naming the set-up field and,
    as the job has no [machine.setup], the line of its [machine] table."""
    text = PIPE.replace("radius_mm = 40.0", "radius_mm = 3000.0").replace("points_per_pass = 100",
                                                                          "points_per_pass = 100\ncircuits = 7")
    job = _job(tmp_path, text)
    out = tmp_path / "o.ngc"
    rc, _, err = _cli(capsys, "run", str(job), "-o", str(out), "--quiet")
    assert rc == 2 and not out.exists(), err
    assert f"line {_line_of(job, '[machine]')}, field 'machine.setup.eye_radius_mm'" in err and "3000 mm" in err, err


def test_union_field_error_names_the_field_and_its_line(tmp_path, capsys) -> None:
    """pole_radius_mm is a number or a pair: an error inside the union names the field, not pydantic's member
    ('mandrel.pole_radius_mm.constrained-float', found by the fuzzer), and its line."""
    text = (EXAMPLES / "pressure_vessel.toml").read_text()
    job = _job(tmp_path, re.sub(r"(?m)^pole_radius_mm = .*$", "pole_radius_mm = nan", text))
    rc, _, err = _cli(capsys, "run", str(job), "-o", str(tmp_path / "o.ngc"), "--quiet")
    assert rc == 2 and f"line {_line_of(job, 'pole_radius_mm')}, field 'mandrel.pole_radius_mm':" in err, err


@pytest.mark.parametrize("edit", ["tolerance_mm = 10", "min_block_time_s = 10", "friction = 10"])
def test_the_largest_values_the_schema_accepts_run(tmp_path, capsys, edit) -> None:
    sec = "[band]" if "friction" in edit else "[post]"
    job = _job(tmp_path, PIPE.replace("friction = 0.2\n", "").replace(sec, f"{sec}\n{edit}"))
    out = tmp_path / "o.ngc"
    rc, _, err = _cli(capsys, "run", str(job), "-o", str(out), "--quiet")
    assert rc in (0, 1) and "Traceback" not in err, err
    assert out.exists() == (rc == 0)


@pytest.mark.parametrize(("argv", "field"), [
    (["turning", "--example", "paper", "--set", "material.k=nan"], "--set material.k"),
    (["turning", "--example", "paper", "--set", "x=y"], "--set x"),
    (["payout", str(EXAMPLES / "pipe.toml"), "--points", "0"], "--points"),
])
def test_option_errors_name_the_option(capsys, argv, field) -> None:
    rc, _, err = _cli(capsys, *argv)
    assert rc == 2 and f"field '{field}'" in err and ".toml" not in err, err


def test_laminate_sum_of_layers_is_budgeted(tmp_path) -> None:
    """Each layer fits the budget, all of them together do not (their results are kept together)."""
    from engine.job import build_mandrel, load_job
    from engine.laminate import run_laminate

    text = (EXAMPLES / "bottle.toml").read_text() + "".join('\n[[layer]]\nkind = "helical"\n' for _ in range(5))
    job_path = _job(tmp_path, text)
    job = load_job(job_path)
    one = budget.check_winding_spec(job.winding, build_mandrel(job).r_max, job.band.width_mm)
    budget.set_max_memory(int(one.bytes * 3))
    try:
        with pytest.raises(InputError, match="points in all layers") as e:
            run_laminate(job, job_path, upto="winding")
        assert str(job_path) in str(e.value)
    finally:
        budget.set_max_memory(None)
