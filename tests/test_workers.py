from __future__ import annotations

import threading
import time

from engine.errors import InputError
from engine.state import check_cancel
from winder_gui.workers import JobRunner


def _slow(n: int, *, state) -> int:
    total = 0
    for i in range(n):
        check_cancel(state)
        state.progress(i / n, "working")
        time.sleep(0.01)
        total += i
    return total


def _bad(*, state) -> None:
    raise InputError("bad radius", field="r")


def test_runner_delivers_result(qtbot) -> None:
    runner = JobRunner()
    with qtbot.waitSignal(runner.finished, timeout=5000) as blocker:
        runner.submit(_slow, 5)
    assert blocker.args == [sum(range(5))]
    runner.wait()


def test_runner_reports_error(qtbot) -> None:
    runner = JobRunner()
    with qtbot.waitSignal(runner.failed, timeout=5000) as blocker:
        runner.submit(_bad)
    assert isinstance(blocker.args[0], InputError)
    runner.wait()


def test_new_job_supersedes_old(qtbot) -> None:
    runner = JobRunner()
    results: list[int] = []
    runner.finished.connect(results.append)
    runner.submit(_slow, 1000)
    t0 = time.monotonic()
    with qtbot.waitSignal(runner.finished, timeout=5000):
        runner.submit(_slow, 3)
    assert results == [3]
    assert runner.wait(2000)
    assert time.monotonic() - t0 < 2.0  # the superseded job stopped at its next poll


def test_warm_engine_imports_loads_the_stage_modules() -> None:
    import subprocess
    import sys

    code = ("import sys; from winder_gui.tasks import ENGINE_MODULES, warm_engine_imports; "
            "warm_engine_imports(); print(all(m in sys.modules for m in ENGINE_MODULES))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "True"


def test_cyclic_garbage_is_collected_on_the_gui_thread(qtbot) -> None:
    """A worker that allocates a lot never runs the cyclic collector: Qt wrappers in garbage cycles
    (closed windows, dialogs) are destroyed on the GUI thread only (a worker destroying them can
    deadlock against the GUI thread on Qt's object mutexes and the GIL)."""
    import gc
    import weakref

    from PySide6.QtCore import QObject

    runner = JobRunner()
    assert not gc.isenabled()
    died_on: list[str] = []

    class Cycle(QObject):
        def __del__(self) -> None:
            died_on.append(threading.current_thread().name)

    obj = Cycle()
    obj.me = obj                      # a reference cycle: only the cyclic collector frees it
    ref = weakref.ref(obj)
    del obj

    def churn(*, state) -> int:
        junk = []
        for i in range(300_000):      # far past every automatic-collection threshold
            d = {"i": i}
            d["self"] = d
            junk.append(d)
        return len(junk)

    with qtbot.waitSignal(runner.finished, timeout=30_000):
        runner.submit(churn)
    # collected by the GUI thread's timer (maybe already while the worker ran), never by the worker
    qtbot.waitUntil(lambda: ref() is None, timeout=5_000)
    assert died_on == [threading.main_thread().name]
