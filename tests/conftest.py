"""Shared test configuration.

Qt runs offscreen unless the caller chose a platform (the ``gl`` tests run under ``xvfb-run`` with
``QT_QPA_PLATFORM=xcb``, see the Makefile).
"""

from __future__ import annotations

import os
from pathlib import Path

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
os.environ.setdefault("PYVISTA_OFF_SCREEN", "true")

import pytest  # noqa: E402

from engine.state import RecordingState  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
RESOURCES = ROOT / "resources"
EXAMPLES = RESOURCES / "examples"


@pytest.fixture
def state() -> RecordingState:
    """A recording stand-in for the GUI/CLI job state."""
    return RecordingState()


@pytest.fixture
def examples_dir() -> Path:
    return EXAMPLES
