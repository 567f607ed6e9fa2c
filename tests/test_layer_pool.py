"""engine.layer_pool: a laminate's layers side by side in spawned worker processes, for a process with
threads (the GUI): the same program as one process, a cancel stops the workers at once, a dead worker's
layer is wound here, and nothing is left behind."""

from __future__ import annotations

import os
import threading
import time
from pathlib import Path

import pytest

import engine.laminate as lam
from engine.errors import Cancelled
from engine.job import parse_job
from engine.layer_pool import LayerPool
from tests.test_laminate_parallel import LAYUP, _same_result


@pytest.fixture(scope="module")
def layup() -> tuple:
    job = parse_job(LAYUP)
    return job, lam.run_laminate(job, workers=1)


@pytest.fixture(scope="module")
def pool():
    p = LayerPool(2)
    p.warm()
    yield p
    p.close()


def _in_thread(fn):  # noqa: ANN001, ANN202
    """``fn()`` in another thread while this one also runs (as the GUI's worker threads do)."""
    out: dict = {}

    def go() -> None:
        try:
            out["r"] = fn()
        except BaseException as exc:  # noqa: BLE001
            out["e"] = exc

    t = threading.Thread(target=go)
    t.start()
    t.join(300)
    assert not t.is_alive()
    if "e" in out:
        raise out["e"]
    return out["r"]


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    # a zombie is dead too
    try:
        return Path(f"/proc/{pid}/stat").read_text().split()[2] != "Z"
    except OSError:
        return False


def record_sent(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """The indices of the layers :func:`engine.laminate._pool_pipeline` hands to a pool worker, in order
    (filled while the patched function runs)."""
    sent: list[int] = []
    orig = lam._pool_pipeline

    def logged(pool_, jp, p, upto, register):  # noqa: ANN001, ANN202
        ok = orig(pool_, jp, p, upto, register)
        if ok:
            sent.append(p.i)
        return ok

    monkeypatch.setattr(lam, "_pool_pipeline", logged)
    return sent


def test_same_program_from_the_pool_while_threads_run(layup, pool, monkeypatch: pytest.MonkeyPatch) -> None:
    job, one = layup
    sent = record_sent(monkeypatch)
    assert threading.active_count() >= 1
    many = _in_thread(lambda: lam.run_laminate(job, pool=pool))
    _same_result(one, many)
    assert 0 in sent and 3 in sent, sent   # the polar and the helical layer went to the workers
    again = _in_thread(lambda: lam.run_laminate(job, pool=pool))   # the same workers, kept between runs
    _same_result(one, again)
    assert len(pool.pids()) == 2


def test_cancel_kills_the_busy_workers_and_the_pool_refills(layup, pool) -> None:
    job, _one = layup

    class Cancel:
        def __init__(self) -> None:
            self.t0 = None

        def progress(self, fraction: float, message: str = "") -> None:
            pass

        def cancelled(self) -> bool:
            return bool(lam_children())

        def partial(self, result: object) -> None:
            pass

    busy: list[int] = []
    orig = lam._Scheduler._spawn

    def spawn(self, p, sub, here=True):  # noqa: ANN001, ANN202
        ok = orig(self, p, sub, here)
        busy.extend(c.pid for c in self.children.values())
        return ok

    def lam_children() -> list[int]:
        return busy

    lam._Scheduler._spawn = spawn
    try:
        with pytest.raises(Cancelled):
            _in_thread(lambda: lam.run_laminate(job, pool=pool, state=Cancel()))
    finally:
        lam._Scheduler._spawn = orig
    assert busy
    deadline = time.monotonic() + 10
    while any(_alive(pid) for pid in busy) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not any(_alive(pid) for pid in busy)      # killed, not left computing
    deadline = time.monotonic() + 60
    while len(pool.pids()) < 2 and time.monotonic() < deadline:
        time.sleep(0.1)
    assert len(pool.pids()) == 2                      # fresh workers behind them
    assert not [f for f in os.listdir("/dev/shm") if f.startswith(f"winder-{os.getpid()}-")]


def test_a_dead_worker_layer_is_wound_here(layup, pool, monkeypatch: pytest.MonkeyPatch) -> None:
    job, one = layup
    orig = lam._pool_pipeline

    def kill_after_send(pool_, jp, p, upto, register):  # noqa: ANN001, ANN202
        def reg(child):  # noqa: ANN001, ANN202
            os.kill(child.pid, 9)
            register(child)
        return orig(pool_, jp, p, upto, reg)

    monkeypatch.setattr(lam, "_pool_pipeline", kill_after_send)
    _same_result(one, _in_thread(lambda: lam.run_laminate(job, pool=pool)))


def test_closed_pool_leaves_no_process_and_runs_here(layup) -> None:
    job, one = layup
    p = LayerPool(2)
    p.warm()
    pids = p.pids()
    p.close()
    assert pids and not any(_alive(pid) for pid in pids)
    _same_result(one, _in_thread(lambda: lam.run_laminate(job, pool=p)))   # nothing to send to: here
    assert p.pids() == []


def test_a_pool_whose_workers_cannot_start_gives_up_and_runs_here(layup, monkeypatch: pytest.MonkeyPatch) -> None:
    import engine.layer_pool as lp
    from tests.sandbox_targets import dies_at_start

    monkeypatch.setattr(lp, "_pool_main", dies_at_start)
    job, one = layup
    p = LayerPool(2)
    try:
        for _ in range(3):
            _same_result(one, _in_thread(lambda: lam.run_laminate(job, pool=p)))
        assert p._closed and p.pids() == []       # it stopped trying after a few failed starts
    finally:
        p.close()


def test_a_layer_the_pool_cannot_take_is_wound_with_progress_and_cancel(layup, monkeypatch: pytest.MonkeyPatch) -> None:
    """A busy, closed or failing pool: the layer is wound in the calling thread later, with its share of the
    progress and the cancel checks (not with no state at all), and the program is the same."""
    from engine.state import RecordingState

    class Refusing:
        workers = 2

        def acquire(self):  # noqa: ANN202
            return None

    job, one = layup
    states: list[bool] = []
    here = lam._Scheduler._here

    def logged(self, p, state):  # noqa: ANN001, ANN202
        states.append(state is not None)
        return here(self, p, state)

    monkeypatch.setattr(lam._Scheduler, "_here", logged)
    _same_result(one, _in_thread(lambda: lam.run_laminate(job, pool=Refusing(), state=RecordingState())))
    assert states and all(states), states


def test_pool_size_check_does_not_materialise_the_line(layup, pool, monkeypatch: pytest.MonkeyPatch) -> None:
    """The pool's size limit counts the line's points from its stored field (a big line kept as circuit 0 +
    rule is not made whole to be measured)."""
    import engine.periodic as per

    job, one = layup
    seen: list[int] = []
    orig = per.raw_field

    def counted(obj, name):  # noqa: ANN001, ANN202
        seen.append(1)
        return orig(obj, name)

    monkeypatch.setattr(per, "raw_field", counted)
    _same_result(one, _in_thread(lambda: lam.run_laminate(job, pool=pool)))
    assert seen


def test_a_layer_that_will_not_pickle_keeps_the_worker(layup, monkeypatch: pytest.MonkeyPatch) -> None:
    """Pickling the request fails (here: the budget state made unpicklable): the layer is wound in the caller,
    the worker is not killed or replaced (the same processes afterwards), the program is the same."""
    job, one = layup
    p = LayerPool(2)
    try:
        p.warm()
        deadline = time.monotonic() + 60
        while len(p.pids()) < 2 and time.monotonic() < deadline:
            time.sleep(0.05)
        before = sorted(p.pids())
        assert len(before) == 2
        monkeypatch.setattr(lam, "_budget_state", lambda: (None, lambda: None))   # a lambda does not pickle
        _same_result(one, _in_thread(lambda: lam.run_laminate(job, pool=p)))
        time.sleep(0.2)
        assert sorted(p.pids()) == before
    finally:
        p.close()


def test_closing_the_pool_under_a_waiting_run(layup, monkeypatch: pytest.MonkeyPatch) -> None:
    """Another thread closes the pool while a run waits for a worker's answer: the run gets end-of-file, winds
    that layer itself (the same program), and its own thread closes the worker's connection afterwards;
    no worker is left."""
    job, one = layup
    p = LayerPool(2)
    sent = threading.Event()
    go = threading.Event()
    children: list = []
    orig = lam._pool_pipeline

    def hooked(pool_, jp, prep, upto, register):  # noqa: ANN001, ANN202
        def reg(child):  # noqa: ANN001, ANN202
            register(child)
            children.append(child)
            if not sent.is_set():
                sent.set()
                go.wait(30)
        return orig(pool_, jp, prep, upto, reg)

    monkeypatch.setattr(lam, "_pool_pipeline", hooked)
    out: dict = {}
    t = threading.Thread(target=lambda: out.setdefault("r", lam.run_laminate(job, pool=p)))
    t.start()
    try:
        assert sent.wait(120)
        pids = p.pids()
        p.close()                                    # from this thread, while the run's thread waits
        go.set()
        t.join(300)
        assert not t.is_alive() and "r" in out
        _same_result(one, out["r"])
        assert children and all(c.worker.conn.closed for c in children)
        assert not any(_alive(pid) for pid in pids)
    finally:
        go.set()
        p.close()
