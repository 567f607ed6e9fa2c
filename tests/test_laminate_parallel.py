"""A laminate's layer pipelines run side by side in forked processes (``run_laminate(workers=N)``,
``winder run --jobs N``): the program, the report and the errors are those of the run in one process."""

from __future__ import annotations

import os
import signal
import threading
from pathlib import Path

import numpy as np
import pytest

import engine.laminate as lam
from engine.cli import main
from engine.errors import InfeasibleError, InputError
from engine.job import load_job, parse_job

EXAMPLES = Path(__file__).resolve().parents[1] / "resources" / "examples"

LAYUP = """schema_version = 2
name = "parallel layup"
[mandrel]
kind = "vessel"
radius_mm = 80.0
cylinder_length_mm = 200.0
dome = "hemisphere"
pole_radius_mm = 25.0
[band]
width_mm = 6.0
thickness_mm = 0.25
friction = 0.2
[winding]
points_per_pass = 300
[payout]
law = "min-range"
clearance_mm = 15.0
[machine]
template = "lathe4"
[[layer]]
kind = "polar"
[[layer]]
kind = "hoop"
[[layer]]
kind = "skip"
angle_deg = 30.0
[[layer]]
kind = "helical"
angle_deg = 45.0
close_by = "angle"
[[layer]]
kind = "hoop"
terminal = true
"""

pytestmark = pytest.mark.skipif(not lam._can_fork(), reason="needs fork() and a single-threaded process")


_CLOCKS = ("compute_s", "stage_times_s", "wall_time_s", "phase_s")


def _no_clocks(obj: object) -> object:
    """The report without the measured compute times."""
    if isinstance(obj, dict):
        return {k: _no_clocks(v) for k, v in obj.items() if k not in _CLOCKS}
    if isinstance(obj, (list, tuple)):
        return [_no_clocks(v) for v in obj]
    return obj


def _same_result(a: lam.LaminateResult, b: lam.LaminateResult) -> None:
    assert a.nc_text == b.nc_text
    assert [lr.figures for lr in a.layers] == [lr.figures for lr in b.layers]
    assert _no_clocks(a.report()) == _no_clocks(b.report())
    for la, lb in zip(a.layers, b.layers):
        if la.result is None:
            assert lb.result is None
            continue
        assert la.result.line is lb.result.line or np.array_equal(la.result.line.z, lb.result.line.z)
        for f in ("l", "u", "Z", "R", "eye_xyz"):
            np.testing.assert_array_equal(getattr(la.result.eye, f), getattr(lb.result.eye, f))
        np.testing.assert_array_equal(la.result.axes.q, lb.result.axes.q)
        np.testing.assert_array_equal(la.result.blocks.q, lb.result.blocks.q)


@pytest.fixture(scope="module")
def layup() -> tuple:
    job = parse_job(LAYUP)
    return job, lam.run_laminate(job, workers=1)


@pytest.mark.parametrize("workers", [2, 3, 8])
def test_same_program_report_and_arrays_with_any_number_of_processes(layup, workers: int) -> None:
    job, one = layup
    many = lam.run_laminate(job, workers=workers)
    _same_result(one, many)
    # the results that came back from a child are usable: arrays writable, the line is the parent's own
    for lr in many.layers:
        if lr.result is not None:
            lr.result.eye.u[:1] = lr.result.eye.u[:1]
            assert lr.result.mandrel is lr.surface


def test_the_example_vessel_byte_for_byte(monkeypatch: pytest.MonkeyPatch) -> None:
    """The vessel side by side: its program, report (transition clearance and tail depths included) and
    arrays those of one process; the join checked its transitions in a forked process meanwhile."""
    path = EXAMPLES / "pressure_vessel.toml"
    job = load_job(path)
    forks = []
    real = lam._fork_call
    monkeypatch.setattr(lam, "_fork_call", lambda fn: forks.append(fn) or real(fn))
    many = lam.run_laminate(job, path, workers=2)
    assert len(forks) == 1
    one = lam.run_laminate(job, path, workers=1)
    assert len(forks) == 1                       # one process: no fork in the join either
    _same_result(one, many)
    assert many.transition_fibre_over_mm == one.transition_fibre_over_mm and any(many.transition_fibre_over_mm)


def test_fork_call_answers_or_says_none() -> None:
    """A forked call's value comes back; where the call raises or the process dies the answer is None (the
    caller computes it itself); with another thread running nothing is forked; close() stops a process
    still running and reaps it."""
    import os
    import signal
    import threading
    import time

    big = np.arange(300_000, dtype=float)        # more than a pipe holds: the answer is read while written
    call = lam._fork_call(lambda: (big * 2.0, "text"))
    got = call.result()
    assert np.array_equal(got[0], big * 2.0) and got[1] == "text"
    assert lam._fork_call(lambda: 1 / 0).result() is None
    assert lam._fork_call(lambda: os.kill(os.getpid(), signal.SIGKILL)).result() is None
    slow = lam._fork_call(lambda: time.sleep(30))
    t0 = time.perf_counter()
    slow.close()
    assert time.perf_counter() - t0 < 5.0
    with pytest.raises(ChildProcessError):
        os.waitpid(slow.pid, os.WNOHANG)
    stop = threading.Event()
    th = threading.Thread(target=stop.wait)
    th.start()
    try:
        assert lam._fork_call(lambda: 1) is None
    finally:
        stop.set()
        th.join()


def _run_here_log(job, workers: int, monkeypatch: pytest.MonkeyPatch) -> tuple:  # noqa: ANN001
    """(result, the layers whose pipeline ran in this process) of a run with ``workers``."""
    here: list[int] = []
    real = lam._Scheduler._here

    def logged(self, p, state):  # noqa: ANN001, ANN202
        here.append(p.i)
        return real(self, p, state)

    monkeypatch.setattr(lam._Scheduler, "_here", logged)
    res = lam.run_laminate(job, workers=workers)
    monkeypatch.setattr(lam._Scheduler, "_here", real)
    return res, sorted(here)


def test_the_childrens_answers_are_used(layup, monkeypatch: pytest.MonkeyPatch) -> None:
    """Only the hoop layers (2 and 5) run here; the polar and helical layers' results come from their
    children (a run that recomputed them here would give the same result)."""
    job, one = layup
    res, here = _run_here_log(job, 2, monkeypatch)
    _same_result(one, res)
    assert here == [1, 4], here


def test_a_child_that_dies_is_replaced_by_this_process(layup, monkeypatch: pytest.MonkeyPatch) -> None:
    job, one = layup
    monkeypatch.setattr(lam, "_pipeline_child", lambda *a, **k: os._exit(3))
    res, here = _run_here_log(job, 2, monkeypatch)
    _same_result(one, res)
    assert here == [0, 1, 3, 4], here


def test_no_room_in_shared_memory_the_answer_comes_another_way(layup, monkeypatch: pytest.MonkeyPatch) -> None:
    """A full /dev/shm (a container's 64 MB): the answer goes through the temporary folder, and with no
    file at all through the pipe; the children's work is used either way (not run again here)."""
    job, one = layup
    real = lam._pack
    for refused in ("/dev/shm", ""):
        def pack(obj, path, refused=refused):  # noqa: ANN001, ANN202
            if path.startswith(refused):
                raise OSError(28, "No space left on device")
            return real(obj, path)

        monkeypatch.setattr(lam, "_pack", pack)
        res, here = _run_here_log(job, 2, monkeypatch)
        _same_result(one, res)
        assert here == [1, 4], (refused, here)


def test_a_refused_fork_runs_the_layer_here(layup, monkeypatch: pytest.MonkeyPatch) -> None:
    """The system refuses to fork (EAGAIN): the layer runs here, nothing leaks, Ctrl-C still works."""
    job, one = layup
    fds = len(os.listdir("/proc/self/fd"))

    def refuse() -> int:
        raise OSError(11, "Resource temporarily unavailable")

    monkeypatch.setattr(os, "fork", refuse)
    res, here = _run_here_log(job, 2, monkeypatch)
    monkeypatch.undo()
    _same_result(one, res)
    assert here == [0, 1, 3, 4]
    assert signal.SIGINT not in signal.pthread_sigmask(signal.SIG_BLOCK, [])
    assert signal.SIGTERM not in signal.pthread_sigmask(signal.SIG_BLOCK, [])
    assert len(os.listdir("/proc/self/fd")) == fds


def test_a_single_layer_to_run_is_not_forked(monkeypatch: pytest.MonkeyPatch) -> None:
    text = LAYUP.split("[[layer]]")[0] + '[[layer]]\nkind = "helical"\nangle_deg = 45.0\nclose_by = "angle"\n'
    job = parse_job(text)
    res, here = _run_here_log(job, 4, monkeypatch)
    assert here == [0]
    assert res.nc_text == lam.run_laminate(job, workers=1).nc_text


def test_the_first_failing_layer_is_reported_as_in_one_process(monkeypatch: pytest.MonkeyPatch) -> None:
    """Layers 1 (polar, in a child) and 4 (helical) both fail in their pipelines: both runs name layer 1;
    with only layer 4 failing, both name layer 4."""
    import engine.pipeline as pl

    real = pl.run_pipeline

    def failing(kinds: set[str]):
        def run(job, *a, **k):  # noqa: ANN001, ANN202
            kind = job.layers[0].kind if job.layers else ""
            if kind in kinds:
                raise InfeasibleError(f"payout impossible for the {kind} layer", field="payout.clearance_mm")
            return real(job, *a, **k)
        return run

    job = parse_job(LAYUP)
    for kinds, where in (({"polar", "helical"}, "layer 1 (1 polar)"), ({"helical"}, "layer 4 (4 helical)")):
        monkeypatch.setattr(pl, "run_pipeline", failing(kinds))
        msgs = []
        for workers in (1, 2):
            with pytest.raises(InfeasibleError) as err:
                lam.run_laminate(job, workers=workers)
            msgs.append(str(err.value))
        assert msgs[0] == msgs[1], msgs
        assert where in msgs[0], msgs[0]


def test_a_bug_in_a_later_layer_waits_for_an_earlier_layers_error(monkeypatch: pytest.MonkeyPatch) -> None:
    """Layer 1's pipeline is infeasible and layer 4's hits a bug (IndexError): one process meets layer 1's
    error first and stops there; so must the parallel run (it raised the IndexError)."""
    import engine.pipeline as pl

    real = pl.run_pipeline

    def run(job, *a, **k):  # noqa: ANN001, ANN202
        kind = job.layers[0].kind if job.layers else ""
        if kind == "polar":
            raise InfeasibleError("polar payout impossible", field="payout.clearance_mm")
        if kind == "helical":
            raise IndexError("a bug")
        return real(job, *a, **k)

    monkeypatch.setattr(pl, "run_pipeline", run)
    job = parse_job(LAYUP)
    msgs = []
    for workers in (1, 2):
        with pytest.raises(InfeasibleError) as err:
            lam.run_laminate(job, workers=workers)
        msgs.append(str(err.value))
    assert msgs[0] == msgs[1] and "layer 1 (1 polar)" in msgs[0], msgs
    # and a bug alone is raised as it is, in both modes

    def bug(job, *a, **k):  # noqa: ANN001, ANN202
        if job.layers and job.layers[0].kind == "helical":
            raise IndexError("a bug")
        return real(job, *a, **k)

    monkeypatch.setattr(pl, "run_pipeline", bug)
    for workers in (1, 2):
        with pytest.raises(IndexError, match="a bug"):
            lam.run_laminate(job, workers=workers)


def test_an_input_error_of_a_later_line_waits_for_the_earlier_pipelines(monkeypatch: pytest.MonkeyPatch) -> None:
    """Layer 4's line cannot exist (band wider than the part) and layer 1's pipeline fails: one process
    meets layer 1 first, and so must the parallel run."""
    import engine.pipeline as pl

    real = pl.run_pipeline

    def run(job, *a, **k):  # noqa: ANN001, ANN202
        if job.layers and job.layers[0].kind == "polar":
            raise InfeasibleError("polar payout impossible", field="payout.clearance_mm")
        return real(job, *a, **k)

    text = LAYUP.replace('angle_deg = 45.0', 'angle_deg = 45.0\nband = {width_mm = 1000.0}')
    job = parse_job(text)
    with pytest.raises(InputError) as err:
        lam.run_laminate(job, workers=2)
    assert "layer.4.band.width_mm" in str(err.value)  # without a failing layer 1: layer 4's error
    monkeypatch.setattr(pl, "run_pipeline", run)
    msgs = []
    for workers in (1, 2):
        with pytest.raises(InputError) as err:
            lam.run_laminate(job, workers=workers)
        msgs.append(str(err.value))
    assert msgs[0] == msgs[1] and "polar payout impossible" in msgs[0], msgs


def test_no_fork_while_another_thread_runs() -> None:
    stop = threading.Event()
    t = threading.Thread(target=stop.wait)
    t.start()
    try:
        assert not lam._can_fork()
    finally:
        stop.set()
        t.join()
    assert lam._can_fork()


def test_pack_unpack_round_trip_without_copies_through_the_pipe(tmp_path: Path) -> None:
    rng = np.random.default_rng(5)
    obj = {1: {"a": np.arange(7.0), "b": np.zeros((3, 2), dtype=np.int64), "s": "x", "odd": np.ones(3, np.int8),
               "t": rng.random(1001)}, 2: InputError("bad", field="f")}
    path = str(tmp_path / "winder-x")
    data, spans = lam._pack(obj, path)
    assert os.path.exists(path) and len(spans) == 4
    assert len(data) < 1000  # the arrays' bytes went to the file
    back = lam._unpack(data, path, spans)
    assert not os.path.exists(path)
    np.testing.assert_array_equal(back[1]["a"], np.arange(7.0))
    np.testing.assert_array_equal(back[1]["b"], np.zeros((3, 2)))
    back[1]["a"][0] = 5.0  # copy-on-write, writable
    # every array as aligned as numpy's own: numpy sums an unaligned float array in another order
    assert all(back[1][k].ctypes.data % 64 == 0 for k in ("a", "b", "odd", "t"))
    assert np.sum(back[1]["t"]) == np.sum(obj[1]["t"])
    assert back[2].location.field == "f" and back[2].message == "bad"
    assert lam._unpack(*_packed({"no arrays": 1}, path)) == {"no arrays": 1}


def _packed(obj: object, path: str) -> tuple:
    data, spans = lam._pack(obj, path)
    return data, path, spans


def test_cli_jobs_option_and_environment(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                         monkeypatch: pytest.MonkeyPatch) -> None:
    job = tmp_path / "j.toml"
    job.write_text(LAYUP)
    outs = []
    for jobs in ("1", "2"):
        out = tmp_path / f"o{jobs}.ngc"
        assert main(["run", str(job), "-o", str(out), "--quiet", "--jobs", jobs]) == 0
        outs.append(out.read_bytes())
    assert outs[0] == outs[1]
    with pytest.raises(SystemExit) as ex:
        main(["run", str(job), "-o", str(tmp_path / "x.ngc"), "--jobs", "0"])
    assert ex.value.code == 2 and "whole number >= 1" in capsys.readouterr().err
    monkeypatch.setenv("WINDER_JOBS", "two")
    assert main(["run", str(job), "-o", str(tmp_path / "y.ngc"), "--quiet"]) == 2
    assert "WINDER_JOBS" in capsys.readouterr().err and not (tmp_path / "y.ngc").exists()
    for bad in ("0", "-3"):  # as --jobs 0: an error, not silently 1
        monkeypatch.setenv("WINDER_JOBS", bad)
        assert main(["run", str(job), "-o", str(tmp_path / "y.ngc"), "--quiet"]) == 2
        assert "WINDER_JOBS" in capsys.readouterr().err
    monkeypatch.setenv("WINDER_JOBS", "1")
    assert lam.default_workers() == 1


def test_default_workers_within_the_cpu_quota_and_not_on_macos(tmp_path: Path,
                                                               monkeypatch: pytest.MonkeyPatch) -> None:
    quota = tmp_path / "cpu.max"
    for text, cpus in (("max 100000\n", 1 << 16), ("200000 100000\n", 2), ("150000 100000\n", 2),
                       ("50000 100000\n", 1), ("garbage\n", 1 << 16)):
        quota.write_text(text)
        assert lam._cgroup_cpus(str(quota)) == cpus, text
    assert lam._cgroup_cpus(str(tmp_path / "none")) == 1 << 16
    monkeypatch.delenv("WINDER_JOBS", raising=False)
    monkeypatch.setattr(lam, "_cgroup_cpus", lambda path="": 1)
    assert lam.default_workers() == 1
    monkeypatch.setattr(lam, "_cgroup_cpus", lambda path="": 1 << 16)
    assert lam.default_workers() == len(os.sched_getaffinity(0))
    monkeypatch.setattr("sys.platform", "darwin")
    assert lam.default_workers() == 1
    monkeypatch.setenv("WINDER_JOBS", "3")
    assert lam.default_workers() == 3


def _events(job, one, workers: int, monkeypatch: pytest.MonkeyPatch) -> list[str]:  # noqa: ANN001
    """The order of layer preparations and forks of a run with ``workers`` (whose result must not change)."""
    log: list[str] = []
    prep, fork = lam._prepare_layer, lam._fork_pipeline

    def logged_prep(*a, **k):  # noqa: ANN002, ANN003, ANN202
        p = prep(*a, **k)
        log.append(f"prep {a[2]}")
        return p

    def logged_fork(jp, p, upto, register):  # noqa: ANN001, ANN202
        log.append(f"fork {p.i}")
        return fork(jp, p, upto, register)

    monkeypatch.setattr(lam, "_prepare_layer", logged_prep)
    monkeypatch.setattr(lam, "_fork_pipeline", logged_fork)
    _same_result(one, lam.run_laminate(job, workers=workers))
    monkeypatch.undo()
    return log


def test_a_layer_pipeline_starts_while_the_next_layers_are_prepared(layup, monkeypatch: pytest.MonkeyPatch) -> None:
    """With 2 workers: layer 0 (polar) goes to a child as soon as it is prepared, the helical layer to the
    second slot once all are prepared, the hoops run here; with 3, the helical layer gets a slot as soon
    as it is prepared, and the hoop before it is not forked for (a heavier layer is still to come: this
    process winds it while the others run).  The result is unchanged."""
    job, one = layup
    log = _events(job, one, 2, monkeypatch)
    assert log[:2] == ["prep 0", "fork 0"], log
    # the polar and helical layers in children; the hoops, each far cheaper, here (no fork for them)
    assert sorted(e for e in log if e.startswith("fork")) == ["fork 0", "fork 3"], log
    log = _events(job, one, 3, monkeypatch)
    assert log[:6] == ["prep 0", "fork 0", "prep 1", "prep 2", "prep 3", "fork 3"], log
    assert sorted(e for e in log if e.startswith("fork")) == ["fork 0", "fork 3"], log


def test_hoops_around_a_helical_layer_are_wound_here_while_it_runs(monkeypatch: pytest.MonkeyPatch) -> None:
    """The pipe example (hoop, helical, hoop) with 2 workers: only the helical layer is forked for, as soon
    as it is prepared; both hoops are wound in this process meanwhile (forking for the first hoop would put
    three processes on two cores while the helical layer runs).  The result is the one-process result."""
    from engine.job import load_job

    path = Path(__file__).resolve().parents[1] / "resources" / "examples" / "pipe.toml"
    job = load_job(path)
    one = lam.run_laminate(job, str(path), workers=1)
    log: list[str] = []
    fork, here = lam._fork_pipeline, lam._Scheduler._here

    def logged_fork(jp, p, upto, register):  # noqa: ANN001, ANN202
        log.append(f"fork {p.i}")
        return fork(jp, p, upto, register)

    def logged_here(self, p, state):  # noqa: ANN001, ANN202
        log.append(f"here {p.i}")
        return here(self, p, state)

    monkeypatch.setattr(lam, "_fork_pipeline", logged_fork)
    monkeypatch.setattr(lam._Scheduler, "_here", logged_here)
    _same_result(one, lam.run_laminate(job, str(path), workers=2))
    assert log[0] == "fork 1" and sorted(log[1:]) == ["here 0", "here 2"], log


def _interrupted_run(tmp_path: Path, sig: int) -> tuple[int, str, int, Path]:
    """``winder run`` of the layup with 2 processes, sent ``sig`` once a child exists (SIGINT to the whole
    process group, as a terminal's Ctrl-C; another signal to the parent only): (exit code, stderr,
    process group, NC path)."""
    import subprocess
    import sys
    import time

    job = tmp_path / "j.toml"
    job.write_text(LAYUP)
    out = tmp_path / "o.ngc"
    env = {**os.environ, "WINDER_JOBS": "2", "PYTHONPATH": str(Path(__file__).resolve().parents[1])}
    proc = subprocess.Popen([sys.executable, "-m", "engine", "run", str(job), "-o", str(out), "--quiet"],
                            env=env, stderr=subprocess.PIPE, start_new_session=True)
    try:
        deadline = time.monotonic() + 60.0
        while time.monotonic() < deadline and proc.poll() is None:  # until the pipelines have started
            kids = Path(f"/proc/{proc.pid}/task/{proc.pid}/children")
            if kids.exists() and kids.read_text().split():
                break
            time.sleep(0.02)
        assert proc.poll() is None, "finished before any child started"
        if sig == signal.SIGINT:
            os.killpg(proc.pid, sig)
        else:
            os.kill(proc.pid, sig)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    return proc.returncode, err.decode(), proc.pid, out


def _nothing_left(pgid: int, files: bool = True) -> None:
    """No process of the group and no answer file of that run are left (children die with the parent)."""
    import subprocess
    import time

    deadline = time.monotonic() + 10.0
    while True:
        left = subprocess.run(["pgrep", "-g", str(pgid)], capture_output=True, text=True).stdout.split()
        if not left or time.monotonic() > deadline:
            break
        time.sleep(0.05)
    assert not left, left
    shm = Path("/dev/shm")
    if files and shm.is_dir():
        assert not list(shm.glob(f"winder-{pgid}-*"))


@pytest.mark.parametrize(("sig", "code", "line"), [(signal.SIGINT, 130, "winder: interrupted"),
                                                   (signal.SIGTERM, 143, "winder: terminated")])
def test_ctrl_c_or_kill_stops_every_process_and_leaves_no_file(tmp_path: Path, sig: int, code: int,
                                                               line: str) -> None:
    """Ctrl-C (or ``kill``) while the layers run side by side: exit 130 (143) with one line (no
    "Process ForkProcess-1:", no traceback), no process and no shared-memory file left, no NC file."""
    rc, err, pgid, out = _interrupted_run(tmp_path, sig)
    assert rc == code, err
    assert err.strip() == line, err
    assert not out.exists()
    _nothing_left(pgid)


def test_a_killed_parent_takes_its_children_with_it(tmp_path: Path) -> None:
    """SIGKILL cannot be caught: the children get SIGKILL when the parent dies (PR_SET_PDEATHSIG), and a
    later parallel run removes answer files a dead run left."""
    rc, _err, pgid, out = _interrupted_run(tmp_path, signal.SIGKILL)
    assert rc == -signal.SIGKILL and not out.exists()
    _nothing_left(pgid, files=False)  # a child may have written its answer before the parent died
    stale = Path("/dev/shm") / f"winder-{pgid}-7-0123456789ab"
    if stale.parent.is_dir():
        stale.write_bytes(b"x")
        lam._remove_stale_files()
        assert not stale.exists()


def test_an_answered_child_is_not_waited_for_until_the_run_ends(layup, monkeypatch: pytest.MonkeyPatch) -> None:
    """Receiving a child's answer does not wait for its exit (freeing its memory): a child that has answered
    but still runs is left to finish and reaped after the join; a run leaves no child behind."""
    import time

    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:  # a child that answers at once and exits only later
        try:
            os.close(r)
            os.write(w, b"")
            os.close(w)
            time.sleep(1.0)
        finally:
            os._exit(0)
    os.close(w)
    child = lam._Child(pid, r, None, [])  # type: ignore[arg-type]
    assert child.receive() is None         # an empty answer: the layer would be wound here
    assert pid in lam._EXITING              # not waited for: it was still running
    os.kill(pid, 0)                         # (alive, not a zombie reaped yet)
    lam._reap_exited()
    assert lam._EXITING == []
    with pytest.raises(ChildProcessError):
        os.waitpid(pid, os.WNOHANG)
    os.close(r)
    job, _one = layup
    forked: list[int] = []
    orig = lam._fork_pipeline

    def logged(jp, p, upto, register):  # noqa: ANN001, ANN202
        c = orig(jp, p, upto, register)
        forked.append(c.pid)
        return c

    monkeypatch.setattr(lam, "_fork_pipeline", logged)
    lam.run_laminate(job, workers=2)
    assert forked and lam._EXITING == []
    for p in forked:                        # every child reaped: not even a zombie is left
        with pytest.raises(ChildProcessError):
            os.waitpid(p, os.WNOHANG)


def test_the_joins_distances_are_built_while_the_layers_run(layup, monkeypatch: pytest.MonkeyPatch) -> None:
    """While this process only waits for its children, it builds the sampled distance functions of the
    surfaces the join's transition checks measure against (they depend on the prepared layers alone): the
    join gets one for every surface a layer that lays fibre is wound on and builds none itself, and the
    program and report are those of one process."""
    import engine.machine_setup as ms

    job, one = layup
    during_join: list[int] = []
    given: list[dict] = []
    joining: list[bool] = []
    orig_fn, orig_join = ms.mandrel_distance_fn, lam._join

    def counting(surface, *a, **k):  # noqa: ANN001, ANN002, ANN003, ANN202
        if joining:
            during_join.append(id(surface))
        return orig_fn(surface, *a, **k)

    def join(res, machine, fns=None, side=False):  # noqa: ANN001, ANN202
        given.append(dict(fns or {}))
        joining.append(True)
        return orig_join(res, machine, fns, side=side)

    monkeypatch.setattr(ms, "mandrel_distance_fn", counting)
    monkeypatch.setattr(lam, "_join", join)
    res = lam.run_laminate(job, workers=2)
    _same_result(one, res)
    laid = [lr for lr in res.layers if lr.result is not None]
    assert set(given[0]) == {id(lr.surface) for lr in laid}
    assert all(given[0][id(lr.surface)][0] is lr.surface for lr in laid)
    assert during_join == [], "the join built a distance function itself"


def test_join_prework_only_where_a_transition_is_checked() -> None:
    """No prework without a transition (one layer that lays fibre); skip layers are not measured against."""
    job = parse_job(LAYUP)
    surface = object()
    laid = lam.LayerResult(index=0, name="a", kind="hoop", key="k", surface=surface, grown=surface,
                           result=object())
    skip = lam.LayerResult(index=1, name="s", kind="skip", key="k2", surface=object(), grown=surface)
    assert lam._join_prework([laid, skip], {}) == []
    fns: dict[int, tuple] = {}
    steps = lam._join_prework([laid, skip, laid], fns)
    assert len(steps) == 2 and job is not None


def test_figures_of_layers_wound_here_are_made_while_the_children_run(layup, monkeypatch: pytest.MonkeyPatch
                                                                     ) -> None:
    """The hoop layers this process winds get their figures (_laid) while it waits for the children, not
    after the last answer; the result and report are those of one process."""
    job, one = layup
    when: dict[int, bool] = {}  # layer -> whether a child was still running then
    running: list[lam._Scheduler] = []
    orig_laid, orig_init = lam._laid, lam._Scheduler.__init__

    def init(self, *a, **k):  # noqa: ANN001, ANN002, ANN003, ANN202
        orig_init(self, *a, **k)
        running.append(self)

    def laid(job_, p, res, *figs):  # noqa: ANN001, ANN002, ANN202
        when.setdefault(p.i, running[-1]._running() > 0)
        return orig_laid(job_, p, res, *figs)

    monkeypatch.setattr(lam._Scheduler, "__init__", init)
    monkeypatch.setattr(lam, "_laid", laid)
    res = lam.run_laminate(job, workers=2)
    _same_result(one, res)
    assert when[1] and when[4], when      # the hoops (wound here) while the polar or helical child ran


def test_figures_of_the_childrens_layers_are_made_while_they_run(layup, monkeypatch: pytest.MonkeyPatch) -> None:
    """The layers wound in children get their figures from their preparation while this process waits
    (all but their time, which comes with the answer), not after the answer: the same figures as in one
    process."""
    job, one = layup
    before: dict[int, bool] = {}  # layer -> figures made (without a result) while its child still ran
    running: list[lam._Scheduler] = []
    orig_figs, orig_init = lam._figures, lam._Scheduler.__init__

    def init(self, *a, **k):  # noqa: ANN001, ANN002, ANN003, ANN202
        orig_init(self, *a, **k)
        running.append(self)

    def figures(job_, i, *a):  # noqa: ANN001, ANN002, ANN202
        if a[-1] is None:
            before[i] = i in running[-1].children and i not in running[-1].out
        return orig_figs(job_, i, *a)

    def slow_child(*a):  # noqa: ANN002, ANN202 - (in the forked child) long enough for this process to wait
        import time

        time.sleep(0.5)
        return real_child(*a)

    real_child = lam._pipeline_child
    monkeypatch.setattr(lam._Scheduler, "__init__", init)
    monkeypatch.setattr(lam, "_figures", figures)
    monkeypatch.setattr(lam, "_pipeline_child", slow_child)
    res = lam.run_laminate(job, workers=2)
    _same_result(one, res)
    assert before.get(0) and before.get(3), before   # the polar and the helical layer
    assert [lr.figures["time_s"] for lr in res.layers] == [lr.figures["time_s"] for lr in one.layers]
