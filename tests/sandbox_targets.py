"""Functions that misbehave as a CAD kernel can, for the sandbox tests (run in the child process)."""

from __future__ import annotations

import ctypes
import time
from typing import Any


def crash(*_args: Any) -> None:
    """A segmentation fault (what a malformed STEP file did to OpenCascade)."""
    ctypes.string_at(0)


def hang(*_args: Any) -> None:
    """Never returns."""
    while True:
        time.sleep(0.05)


def hog(*_args: Any) -> bytes:
    """Allocates without bound (64 GB)."""
    return bytes(64 * 2**30)


def echo(*args: Any) -> tuple[Any, ...]:
    """Returns its arguments."""
    return args


def dies_at_start(*_args: Any) -> None:
    """A layer-pool worker that ends before it is ready (a broken install)."""
    import os

    os._exit(3)
