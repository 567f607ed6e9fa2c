"""The ``winder`` command line.

``winder`` with no arguments opens the GUI.  Every module in this package except this one is a
sub-command: it defines ``NAME`` (str), ``HELP`` (one line), ``add_arguments(parser)`` and
``run(args) -> int``.  Sub-commands are discovered, so adding one touches no other file.

Exit codes: 0 success, 1 a computed result violates a limit (reported), 2 bad input
(:class:`engine.errors.InputError`: a one-line message naming the place), 130 interrupted.
"""

from __future__ import annotations

import argparse
import importlib
import json
import pkgutil
import sys
from collections.abc import Sequence
from typing import Any

from engine import __version__
from engine.errors import InputError


def _subcommand_modules() -> list[Any]:
    mods = []
    for info in sorted(pkgutil.iter_modules(__path__), key=lambda m: m.name):
        if info.name.startswith("_"):
            continue
        mods.append(importlib.import_module(f"{__name__}.{info.name}"))
    return mods


def build_parser() -> argparse.ArgumentParser:
    """The full argument parser with every discovered sub-command."""
    parser = argparse.ArgumentParser(
        prog="winder",
        description="Filament-winding CAD/CAM. Without a sub-command, opens the desktop application.",
    )
    parser.add_argument("--version", action="version", version=f"winder {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for mod in _subcommand_modules():
        p = sub.add_parser(mod.NAME, help=mod.HELP, description=mod.HELP)
        mod.add_arguments(p)
        p.add_argument("--max-memory", metavar="SIZE", default=None,
                       help="memory budget of the run, e.g. 8G (default 4G, or $WINDER_MAX_MEMORY); larger jobs "
                            "are refused before they start")
        p.set_defaults(_run=mod.run)
    return parser


_GUI_RAN: list[bool] = []


def entry() -> None:
    """The ``winder`` program (console script, ``python -m engine``, the frozen build): :func:`main`, then
    :func:`exit_now` with its exit code."""
    exit_now(main())


def exit_now(rc: int) -> None:
    """End the process with exit code ``rc`` the quick way once a command is done: the ``atexit`` handlers
    run and the standard streams are flushed, as at a normal exit, but the interpreter is not torn down
    (freeing every module and array costs 0.05-0.09 s, a twelfth of a one-layer run; issue 16).  The
    normal exit (``sys.exit``) instead after the GUI (Qt objects are owed their destructors), where
    another non-daemon thread still runs, or when a stream cannot be flushed (its error is then reported
    as Python reports it)."""
    import atexit
    import os
    import threading

    if "engine.timeparam" in sys.modules:
        sys.modules["engine.timeparam"].shutdown_pool()
    others = [t for t in threading.enumerate() if t is not threading.main_thread() and not t.daemon and t.is_alive()]
    if _GUI_RAN or others:
        sys.exit(rc)
    atexit._run_exitfuncs()
    try:
        sys.stdout.flush()
        sys.stderr.flush()
    except Exception:  # noqa: BLE001 - e.g. a closed pipe: the normal exit reports it and sets the code
        sys.exit(rc)
    os._exit(rc)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``winder``; returns the process exit code."""
    args_list = list(sys.argv[1:] if argv is None else argv)
    if args_list == ["--version"]:  # answered before any sub-command (and numpy) is imported
        print(f"winder {__version__}")
        return 0
    _process_defaults()
    gui_flags = {"--selftest", "--"}
    # the GUI: no arguments, or only GUI flags and at most one job file
    if all(a in gui_flags or a.lower().endswith(".toml") for a in args_list) and (
        sum(a.lower().endswith(".toml") for a in args_list) <= 1
    ):
        from winder_gui.app import main as gui_main  # lazy: the CLI never needs Qt

        _GUI_RAN.append(True)
        return int(gui_main(args_list))
    parser = build_parser()
    args = parser.parse_args(args_list)
    if not getattr(args, "_run", None):
        parser.print_help()
        return 2
    import warnings

    from engine import budget

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            if getattr(args, "max_memory", None) is not None:
                budget.set_max_memory(budget.parse_size(args.max_memory))
            rc = int(args._run(args) or 0)
        except InputError as exc:
            print(f"winder {args.command}: error: {_located(exc, getattr(args, 'job', None))}", file=sys.stderr)
            rc = 2
        except KeyboardInterrupt as exc:
            from engine.errors import Terminated

            terminated = isinstance(exc, Terminated)
            print("winder: terminated" if terminated else "winder: interrupted", file=sys.stderr)
            rc = 143 if terminated else 130
        except BrokenPipeError:
            rc = _broken_pipe()
        except MemoryError:
            print(f"winder {args.command}: error: out of memory; the job is larger than this machine can hold "
                  f"(budget {budget.fmt_bytes(budget.max_memory_bytes())}); lower the number of circuits, layers "
                  "or points", file=sys.stderr)
            rc = 2
        finally:
            budget.set_max_memory(None)
    if rc in (0, 1):  # after an input error the message says it all
        _report_warnings(args.command, caught)
    return rc


def _process_defaults() -> None:
    """Settings of the ``winder`` process itself (the CLI and the GUI it starts), each overridable from the
    environment.  Pydantic plugins are not looked for: pydantic would otherwise scan every installed
    distribution's entry points when the job schema is built (~0.03 s of every start; issue 16), and no
    plugin has any business in a job's validation.  ``PYDANTIC_DISABLE_PLUGINS`` set by the user wins."""
    import os

    os.environ.setdefault("PYDANTIC_DISABLE_PLUGINS", "__all__")


def _located(exc: InputError, job: str | None) -> InputError:
    """``exc`` with its place completed: an error naming a job field but no file is the job file's, and
    a field of a ``.toml`` file gets its line (best effort: the key's line, else its table's header)."""
    loc = exc.location
    if not loc.field or loc.field.startswith("-"):
        return exc
    if loc.file is None and isinstance(job, str) and job.lower().endswith(".toml"):
        exc = exc.at(file=job)
        loc = exc.location
    if loc.line is None and loc.file and loc.file.lower().endswith(".toml"):
        from engine.budget import field_line

        try:
            line = field_line(loc.file, loc.field)
        except Exception:  # noqa: BLE001 - the line is a courtesy; the message stands without it
            line = None
        if line is not None:
            exc = exc.at(line=line)
    return exc


def _broken_pipe() -> int:
    """The reader of stdout went away (``winder ... | head -1``): end quietly, as other tools do."""
    import os

    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())  # the interpreter's final flush must not fail again
    except (OSError, ValueError):
        pass
    return 0


def _report_warnings(command: str, caught: list[Any]) -> None:
    """Warnings are messages: one line each (not Python's file:line form), repeated ones once."""
    seen: set[str] = set()
    for w in caught:
        text = str(w.message).strip().splitlines()[0] if str(w.message).strip() else w.category.__name__
        if text in seen:
            continue
        seen.add(text)
        try:
            print(f"winder {command}: note: numerical warning ({w.category.__name__}): {text}", file=sys.stderr)
        except (OSError, ValueError):
            return


def _json_default(obj: Any) -> Any:
    import numpy as np

    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, set | frozenset | tuple):
        return list(obj)
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")


def dump_json(obj: Any, stream: Any = None) -> None:
    """Print ``obj`` as JSON (numpy arrays and scalars converted) to ``stream`` (stdout)."""
    stream = stream if stream is not None else sys.stdout
    json.dump(obj, stream, indent=2, default=_json_default, allow_nan=False)
    stream.write("\n")


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
