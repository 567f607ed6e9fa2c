"""The job ``state`` protocol that every long-running engine function takes.

An engine stage is ``stage(inputs, params, state) -> Result``.  It reports progress through
``state.progress(fraction, message)``, polls ``state.cancelled()`` at safe points (raising
:class:`engine.errors.Cancelled` via :func:`check_cancel`), and may publish intermediate results
through ``state.partial(obj)``.  The GUI implements the protocol in a Qt worker, the CLI with a text
progress bar (:class:`CliState`), and tests with :class:`RecordingState`.
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass, field
from typing import Any, Protocol, TextIO, runtime_checkable

from engine.errors import Cancelled


@runtime_checkable
class State(Protocol):
    """What an engine job may tell its caller, and ask it."""

    def progress(self, fraction: float, message: str = "") -> None:
        """Report progress; ``fraction`` in [0, 1]."""

    def cancelled(self) -> bool:
        """True when the caller wants the job to stop as soon as it safely can."""

    def partial(self, result: Any) -> None:
        """Publish an intermediate result (e.g. one iteration of the DP tube)."""


class NullState:
    """A state that ignores everything and never cancels (the default)."""

    def progress(self, fraction: float, message: str = "") -> None:
        pass

    def cancelled(self) -> bool:
        return False

    def partial(self, result: Any) -> None:
        pass


NULL_STATE = NullState()


def check_cancel(state: State | None) -> None:
    """Raise :class:`Cancelled` if ``state`` asks to stop."""
    if state is not None and state.cancelled():
        raise Cancelled()


class SubState:
    """Maps progress of a sub-stage onto ``[start, stop]`` of a parent state."""

    def __init__(self, parent: State, start: float, stop: float) -> None:
        self._parent, self._a, self._b = parent, float(start), float(stop)

    def progress(self, fraction: float, message: str = "") -> None:
        f = min(max(float(fraction), 0.0), 1.0)
        self._parent.progress(self._a + (self._b - self._a) * f, message)

    def cancelled(self) -> bool:
        return self._parent.cancelled()

    def partial(self, result: Any) -> None:
        self._parent.partial(result)


class CliState:
    """A text progress bar on a terminal (stderr); silent when ``quiet`` or not a TTY."""

    def __init__(self, stream: TextIO | None = None, quiet: bool = False, width: int = 30) -> None:
        self._stream = stream if stream is not None else sys.stderr
        self._quiet = quiet or not getattr(self._stream, "isatty", lambda: False)()
        self._width = width
        self._last = 0.0

    def progress(self, fraction: float, message: str = "") -> None:
        if self._quiet:
            return
        now = time.monotonic()
        if fraction < 1.0 and now - self._last < 0.1:
            return
        self._last = now
        f = min(max(float(fraction), 0.0), 1.0)
        n = int(round(f * self._width))
        bar = "#" * n + "-" * (self._width - n)
        end = "\n" if f >= 1.0 else ""
        self._stream.write(f"\r[{bar}] {f * 100:5.1f}% {message[:40]:<40}{end}")
        self._stream.flush()

    def cancelled(self) -> bool:
        return False

    def partial(self, result: Any) -> None:
        pass


@dataclass
class RecordingState:
    """Test stub: records every call; cancels after ``cancel_after`` ``cancelled()`` polls."""

    cancel_after: int | None = None
    progress_calls: list[tuple[float, str]] = field(default_factory=list)
    partials: list[Any] = field(default_factory=list)
    polls: int = 0

    def progress(self, fraction: float, message: str = "") -> None:
        self.progress_calls.append((float(fraction), message))

    def cancelled(self) -> bool:
        self.polls += 1
        return self.cancel_after is not None and self.polls > self.cancel_after

    def partial(self, result: Any) -> None:
        self.partials.append(result)

    @property
    def fractions(self) -> list[float]:
        """The progress fractions reported, in order."""
        return [f for f, _ in self.progress_calls]


__all__ = [
    "Cancelled",
    "CliState",
    "NULL_STATE",
    "NullState",
    "RecordingState",
    "State",
    "SubState",
    "check_cancel",
]
