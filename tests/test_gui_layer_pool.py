"""The GUI winds a laminate's layers side by side in its LayerPool's worker processes (engine.layer_pool):
the program it shows and exports is the one process's (the CLI's with one process), and a cancel leaves
no worker computing."""

from __future__ import annotations

import os
import time
from pathlib import Path

import pytest
from gui_helpers import close_window, shown_window

import engine.laminate as lam
from engine.job import load_job
from tests.test_layer_pool import record_sent

EXAMPLES = Path(__file__).resolve().parents[1] / "resources" / "examples"


@pytest.fixture
def pooled(monkeypatch: pytest.MonkeyPatch):
    """The GUI's pool turned on (the suite turns it off, tests/conftest.py), with two workers."""
    from winder_gui import tasks

    monkeypatch.setenv("WINDER_GUI_POOL", "1")
    monkeypatch.setenv("WINDER_JOBS", "2")
    monkeypatch.setattr(tasks, "_POOL", [])
    pool = tasks.gui_layer_pool()
    assert pool is not None and pool.workers == 2
    pool.warm()
    yield pool
    pool.close()


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
        return Path(f"/proc/{pid}/stat").read_text().split()[2] != "Z"
    except (ProcessLookupError, OSError):
        return False


def test_gui_run_uses_the_pool_and_exports_the_one_process_program(qtbot, tmp_path, pooled,
                                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    path = EXAMPLES / "pressure_vessel.toml"
    one = lam.run_laminate(load_job(path), str(path), workers=1)
    sent = record_sent(monkeypatch)
    w = shown_window(qtbot, path)
    try:
        w.auto_run = False
        assert w.run_pipeline_now()
        assert w.wait_idle(180000) and w.last_error == "", w.last_error
        assert sorted(sent) == [0, 2], sent          # the polar and the helical layer, in the workers
        out = tmp_path / "v.ngc"
        assert w.export_nc(out) and w.wait_idle()
        assert out.read_text() == one.nc_text          # what is exported is the one-process program
    finally:
        close_window(w)


def test_gui_cancel_stops_the_pool_workers(qtbot, tmp_path, pooled, monkeypatch: pytest.MonkeyPatch) -> None:
    # the example vessel at 4x its points per pass and payout grid points: its layers take seconds in a
    # worker, so the cancel below always meets them computing (at the example's own size a loaded machine
    # could let the first layer finish - and its worker rightly stay, idle - before the cancel arrives;
    # the points per pass alone no longer do it since a layer computes one circuit and turns it)
    text = (EXAMPLES / "pressure_vessel.toml").read_text()
    assert "points_per_pass = 2000" in text and "\n[payout]\n" in text and "grid_points" not in text
    path = tmp_path / "vessel_heavy.toml"
    path.write_text(text.replace("points_per_pass = 2000", "points_per_pass = 8000")
                    .replace("\n[payout]\n", "\n[payout]\ngrid_points = 4000\n"))
    busy: list[int] = []
    orig = lam._pool_pipeline

    def logged(pool, jp, p, upto, register):  # noqa: ANN001, ANN202
        return orig(pool, jp, p, upto, lambda c: (busy.append(c.pid), register(c)))

    monkeypatch.setattr(lam, "_pool_pipeline", logged)
    w = shown_window(qtbot, path)
    try:
        w.auto_run = False
        assert w.run_pipeline_now()
        qtbot.waitUntil(lambda: bool(busy), timeout=60000)
        w.cancel_run()
        assert w.wait_idle(180000)
        assert w.result is None
        deadline = time.monotonic() + 10
        while any(_alive(pid) for pid in busy) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert not any(_alive(pid) for pid in busy)   # the workers computing were stopped at once
    finally:
        close_window(w)


@pytest.mark.parametrize(("env", "want"), [({"WINDER_GUI_POOL": "0"}, None), ({"WINDER_JOBS": "1"}, None),
                                            ({"WINDER_JOBS": "3"}, 3)])
def test_gui_pool_size_follows_the_settings(monkeypatch: pytest.MonkeyPatch, env: dict, want: int | None) -> None:
    """One worker per CPU available (not 1 because the GUI's threads forbid forking); WINDER_JOBS overrides,
    WINDER_JOBS=1 and WINDER_GUI_POOL=0 turn the pool off."""
    from winder_gui import tasks

    monkeypatch.setenv("WINDER_GUI_POOL", "1")
    monkeypatch.delenv("WINDER_JOBS", raising=False)
    for k, v in env.items():
        monkeypatch.setenv(k, v)
    monkeypatch.setattr(tasks, "_POOL", [])
    pool = tasks.gui_layer_pool()
    try:
        assert (pool.workers if pool is not None else None) == want
        assert tasks.gui_layer_pool() is pool            # one pool for the process
    finally:
        if pool is not None:
            pool.close()


def test_gui_pool_default_is_the_cpus_available_up_to_eight(monkeypatch: pytest.MonkeyPatch) -> None:
    from engine.laminate import available_cpus
    from winder_gui import tasks

    monkeypatch.setenv("WINDER_GUI_POOL", "1")
    monkeypatch.delenv("WINDER_JOBS", raising=False)
    monkeypatch.setattr(tasks, "_POOL", [])
    pool = tasks.gui_layer_pool()
    try:
        assert (pool.workers if pool is not None else 1) == min(available_cpus(), tasks._POOL_MAX_WORKERS)
    finally:
        if pool is not None:
            pool.close()
