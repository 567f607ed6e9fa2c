"""Run a reader that may crash (a CAD kernel) in a child process with a time and a memory limit.

The STEP reader (OpenCascade through OCP/cadquery) sees files from anywhere; a malformed one can
end the process with a segmentation fault, loop, or allocate without bound.  :func:`run_isolated`
calls a function in a fresh child process (``multiprocessing`` "spawn", which also works in the
frozen PyInstaller build: ``installer/winder_entry.py`` calls ``freeze_support``), with

* a memory limit: the child's address space may grow by at most the budget
  (``resource.setrlimit(RLIMIT_AS)``, default :func:`engine.budget.max_memory_bytes`),
* a time limit: the parent waits at most ``timeout_s`` and then kills the child,
* no core dump (``RLIMIT_CORE = 0``),

and turns every way it can end into a result or an :class:`~engine.errors.InputError` that names
the file: the function's own ``InputError`` (file, line, field kept), "the STEP reader crashed on
this file (signal SIGSEGV)", "the STEP reader gave up after 120 s", "... needed more than its
memory budget".  The calling process (the CLI, or the GUI with the user's unsaved job) keeps running.

The target is given as ``"module:function"``; its arguments and result must pickle.
"""

from __future__ import annotations

import importlib
import os
import signal
import time
from pathlib import Path
from typing import Any

from engine.errors import InputError

DEFAULT_TIMEOUT_S = 120.0
"""Time limit of one isolated call (s) unless the caller gives one; ``$WINDER_IMPORT_TIMEOUT`` overrides."""

_POLL_S = 0.05


def default_timeout_s() -> float:
    """``$WINDER_IMPORT_TIMEOUT`` (s) if set and valid, else :data:`DEFAULT_TIMEOUT_S`."""
    try:
        v = float(os.environ.get("WINDER_IMPORT_TIMEOUT", ""))
        if 0 < v < 1e6:
            return v
    except ValueError:
        pass
    return DEFAULT_TIMEOUT_S


def _vm_size_bytes() -> int:
    try:
        with open("/proc/self/status", encoding="ascii") as fh:
            for ln in fh:
                if ln.startswith("VmSize:"):
                    return int(ln.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return 0


def _child(conn: Any, target: str, args: tuple[Any, ...], memory_bytes: int, cpu_s: float) -> None:
    """Body of the child process: limits, then the call; the outcome goes back through ``conn``."""
    try:
        import resource

        devnull = os.open(os.devnull, os.O_WRONLY)  # the kernel's own chatter (OCP prints parse errors)
        os.dup2(devnull, 1)
        os.dup2(devnull, 2)
        resource.setrlimit(resource.RLIMIT_CORE, (0, 0))
        # import the target's module first (OCP maps about 1 GB of libraries): the budget is for data
        mod_name, func_name = target.split(":")
        func = getattr(importlib.import_module(mod_name), func_name)
        if memory_bytes > 0:
            limit = _vm_size_bytes() + int(memory_bytes)
            _soft, hard = resource.getrlimit(resource.RLIMIT_AS)
            if hard != resource.RLIM_INFINITY:
                limit = min(limit, hard)
            resource.setrlimit(resource.RLIMIT_AS, (limit, hard))
        if cpu_s > 0:
            c = int(cpu_s) + 1
            _soft, hard = resource.getrlimit(resource.RLIMIT_CPU)
            resource.setrlimit(resource.RLIMIT_CPU, (c, hard if hard == resource.RLIM_INFINITY else max(c, hard)))
    except Exception as exc:  # noqa: BLE001 - report any set-up failure to the parent
        conn.send(("error", f"{type(exc).__name__}: {exc}"))
        return
    try:
        result = func(*args)
    except InputError as exc:
        conn.send(("input", exc.message, exc.location.file, exc.location.line, exc.location.field,
                   type(exc).__name__))
        return
    except MemoryError:
        conn.send(("memory",))
        return
    except RecursionError:
        conn.send(("error", "the model is nested too deeply (recursion limit)"))
        return
    except Exception as exc:  # noqa: BLE001 - the reader sees arbitrary files; the parent names the file
        conn.send(("error", f"{type(exc).__name__}: {exc}"))
        return
    conn.send(("ok", result))


def _signal_name(code: int) -> str:
    try:
        return signal.Signals(code).name
    except ValueError:
        return f"signal {code}"


def run_isolated(target: str, *args: Any, what: str, file: str | Path | None = None,
                 timeout_s: float | None = None, memory_bytes: int | None = None, state: Any = None) -> Any:
    """Call ``target`` (``"module:function"``) with ``args`` in a child process; return its result.

    Parameters
    ----------
    what:
        Who does the work, for the messages (``"the STEP reader"``).
    file:
        The file being read; every error names it.
    timeout_s:
        Wall-clock limit (s); default :func:`default_timeout_s`.  The child also gets a CPU-time
        limit of the same length.
    memory_bytes:
        How much the child's address space may grow after importing the target's module (bytes);
        default the memory budget (:func:`engine.budget.max_memory_bytes`).  0 = no limit.
    state:
        :mod:`engine.state` object: cancelling it kills the child (:class:`engine.errors.Cancelled`).

    Raises
    ------
    InputError
        The function's own :class:`InputError` (its place kept, the file filled in), or how the child
        ended: crashed (a signal), gave up (time limit), ran out of its memory budget, failed.
    """
    import multiprocessing as mp

    from engine import budget
    from engine.state import check_cancel

    timeout = default_timeout_s() if timeout_s is None else float(timeout_s)
    mem = budget.max_memory_bytes() if memory_bytes is None else int(memory_bytes)
    ctx = mp.get_context("spawn")
    recv, send = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_child, args=(send, target, tuple(args), mem, timeout), daemon=True,
                       name=f"winder-sandbox-{target}")
    proc.start()
    send.close()
    t0 = time.monotonic()
    msg: Any = None
    try:
        while True:
            if recv.poll(_POLL_S):
                try:
                    msg = recv.recv()
                except (EOFError, OSError):
                    msg = None  # the child died without answering
                break
            if not proc.is_alive() and not recv.poll(0):
                break
            if time.monotonic() - t0 > timeout:
                proc.kill()
                proc.join(5.0)
                raise InputError(f"{what} gave up after {timeout:g} s on this file (time limit)", file=file)
            check_cancel(state)
    except BaseException:
        if proc.is_alive():
            proc.kill()
        proc.join(5.0)
        recv.close()
        raise
    proc.join(10.0)
    if proc.is_alive():  # answered but does not end: make sure it does
        proc.kill()
        proc.join(5.0)
    recv.close()
    if msg is None:
        code = proc.exitcode
        if code is not None and code < 0:
            how = _signal_name(-code)
            if -code == signal.SIGXCPU:
                raise InputError(f"{what} gave up after {timeout:g} s of computing on this file (time limit)",
                                 file=file)
            if -code == signal.SIGKILL:
                raise InputError(f"{what} was killed while reading this file (out of memory?)", file=file)
            raise InputError(f"{what} crashed on this file ({how}); the file is probably malformed, or uses "
                             "features the reader cannot handle", file=file)
        raise InputError(f"{what} ended unexpectedly on this file (exit code {code})", file=file)
    kind = msg[0]
    if kind == "ok":
        return msg[1]
    if kind == "input":
        _, message, f, line, field, cls_name = msg
        from engine.errors import InfeasibleError

        cls = InfeasibleError if cls_name == "InfeasibleError" else InputError
        return_exc = cls(message, file=f or file, line=line, field=field)
        raise return_exc
    if kind == "memory":
        raise InputError(f"{what} needed more than its memory budget ({budget.fmt_bytes(mem)}) on this file; "
                         "raise it with --max-memory if the model is really that large", file=file)
    raise InputError(f"{what} failed on this file ({msg[1]})", file=file)
