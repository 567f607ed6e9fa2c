"""Shared test configuration.

Qt runs offscreen unless the caller chose a platform (the ``gl`` tests run under ``xvfb-run`` with
``QT_QPA_PLATFORM=xcb``, see the Makefile).
"""

from __future__ import annotations

import gc
import itertools
import os
from pathlib import Path

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
os.environ.setdefault("PYVISTA_OFF_SCREEN", "true")
# the GUI's layers run one after the other in the test process (tests patch engine functions and count on
# them); tests/test_gui_layer_pool.py turns the GUI's worker processes on
os.environ.setdefault("WINDER_GUI_POOL", "0")

import pytest  # noqa: E402
from hypothesis import settings  # noqa: E402

from engine.state import RecordingState  # noqa: E402

# Property tests: CI (the default profile) draws the same examples on every run, so main's verdict does
# not depend on the draw; `HYPOTHESIS_PROFILE=explore` draws new ones (run it when changing the numerics:
# cases it finds become @example regressions).
settings.register_profile("ci", derandomize=True, print_blob=True)
settings.register_profile("explore", derandomize=False, print_blob=True)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))

ROOT = Path(__file__).resolve().parents[1]
RESOURCES = ROOT / "resources"
EXAMPLES = RESOURCES / "examples"


@pytest.fixture(autouse=True)
def _isolated(tmp_path, monkeypatch):
    """Settings and autosave copies in the test's own folder, never the user's (every test)."""
    monkeypatch.setenv("WINDER_SETTINGS", str(tmp_path / "settings.ini"))
    monkeypatch.setenv("WINDER_AUTOSAVE_DIR", str(tmp_path / "autosave"))


@pytest.fixture
def state() -> RecordingState:
    """A recording stand-in for the GUI/CLI job state."""
    return RecordingState()


@pytest.fixture
def examples_dir() -> Path:
    return EXAMPLES


_TESTS_RUN = itertools.count(1)


def pytest_runtest_teardown(item, nextitem) -> None:  # noqa: ARG001 - pytest hook signature
    """Once a GUI test made a JobRunner, Python's automatic cyclic GC is off for the session
    (winder_gui.workers: collection belongs on the GUI thread, where a QTimer does it while a Qt
    loop runs).  Tests without a Qt loop would then never collect: do it here, on the main thread."""
    if not gc.isenabled():
        gc.collect(2 if next(_TESTS_RUN) % 50 == 0 else 1)
