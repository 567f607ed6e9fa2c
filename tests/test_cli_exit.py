"""The ``winder`` program ends without tearing the interpreter down once a command is done (issue 16):
the same files, output and exit codes as a normal exit, the exit handlers run, the streams flushed."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONPATH": str(ROOT)}


def _run(code: str, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", code, *args], cwd=ROOT, env=ENV, capture_output=True, text=True,
                          timeout=300)


def test_quick_exit_runs_the_exit_handlers_flushes_and_keeps_the_code(tmp_path: Path) -> None:
    """Buffered output on a pipe, an atexit handler writing a file, exit codes 0 and 3: as a normal exit does."""
    mark = tmp_path / "handler.txt"
    code = ("import atexit, sys\n"
            "from engine.cli import exit_now\n"
            f"atexit.register(lambda: open({str(mark)!r}, 'w').write('ran'))\n"
            "sys.stdout.write('buffered text without a newline')\n"
            "sys.stderr.write('and on stderr')\n"
            "exit_now(int(sys.argv[1]))\n"
            "print('never reached')\n")
    for rc in (0, 3):
        mark.unlink(missing_ok=True)
        r = _run(code, str(rc))
        assert r.returncode == rc
        assert r.stdout == "buffered text without a newline" and r.stderr == "and on stderr"
        assert mark.read_text() == "ran"


def test_quick_exit_waits_for_a_running_thread(tmp_path: Path) -> None:
    """A non-daemon thread still working: the normal exit, which lets it finish (its file is written)."""
    out = tmp_path / "thread.txt"
    code = ("import threading, time\n"
            "from engine.cli import exit_now\n"
            "def work():\n"
            "    time.sleep(0.5)\n"
            f"    open({str(out)!r}, 'w').write('done')\n"
            "threading.Thread(target=work).start()\n"
            "exit_now(5)\n")
    r = _run(code)
    assert r.returncode == 5 and out.read_text() == "done"


def test_quick_exit_stops_the_time_law_thread_pool() -> None:
    """The time law's chunk-building thread (idle, non-daemon) is shut down, not waited on by a normal
    exit: the quick exit still happens (the handlers run once, the code is kept)."""
    code = ("import atexit, threading\n"
            "from engine import timeparam\n"
            "from engine.cli import exit_now\n"
            "timeparam._pool().submit(sum, [1, 2]).result()\n"
            "assert any(t.name.startswith('timeparam') for t in threading.enumerate())\n"
            "atexit.register(lambda: print('handler', len([t for t in threading.enumerate() "
            "if t.name.startswith('timeparam') and t.is_alive()])))\n"
            "exit_now(4)\n")
    r = _run(code)
    assert r.returncode == 4 and r.stdout == "handler 0\n", r.stderr


def test_winder_run_writes_the_same_program_and_reports_errors(tmp_path: Path) -> None:
    """``python -m engine run`` (the quick exit) against the command run in-process (no exit at all): the
    same NC file, the summary on stderr; a bad job: exit code 2 and the message on stderr."""
    from engine.cli import main

    job = ROOT / "resources" / "examples" / "pipe.toml"
    out = tmp_path / "quick.ngc"
    r = subprocess.run([sys.executable, "-m", "engine", "run", str(job), "-o", str(out)], cwd=ROOT, env=ENV,
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert "program time" in r.stderr and str(out) in r.stderr
    ref = tmp_path / "inprocess.ngc"
    assert main(["run", str(job), "-o", str(ref)]) == 0
    assert out.read_bytes() == ref.read_bytes()
    bad = tmp_path / "bad.toml"
    bad.write_text(job.read_text(encoding="utf-8").replace("[winding]", "[winding]\nno_such_field = 1", 1))
    r = subprocess.run([sys.executable, "-m", "engine", "run", str(bad), "-o", str(tmp_path / "x.ngc")], cwd=ROOT,
                       env=ENV, capture_output=True, text=True, timeout=300)
    assert r.returncode == 2 and "no_such_field" in r.stderr and "Traceback" not in r.stderr
    assert not (tmp_path / "x.ngc").exists()
