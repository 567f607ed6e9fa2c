from __future__ import annotations

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
