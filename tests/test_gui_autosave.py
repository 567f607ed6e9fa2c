"""Autosave with more than one winder running (issue 9): each copy is locked by its instance.

Two windows with different :class:`~winder_gui.main_window.AutosaveOwner` objects stand for two
running instances; a real second process holds a lock for the "live elsewhere" and "killed"
cases.  pytest-qt, offscreen.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest
from PySide6.QtWidgets import QMessageBox

from engine.job import load_job
from winder_gui.main_window import AUTOSAVE_HEADER, AutosaveOwner, MainWindow, autosave_origin

ROOT = Path(__file__).resolve().parents[1]
PIPE = ROOT / "resources" / "examples" / "pipe.toml"


@pytest.fixture
def asked(monkeypatch) -> list[str]:
    """Questions asked by QMessageBox.question (answered Yes)."""
    out: list[str] = []
    monkeypatch.setattr(QMessageBox, "question", lambda *a, **k: out.append(a[2]) or QMessageBox.StandardButton.Yes)
    return out


def _instance(qtbot, path: Path | None = PIPE) -> MainWindow:
    """A window standing for a separate running winder (its own lock owner)."""
    w = MainWindow(path)
    w.autosave_owner = AutosaveOwner()
    w.confirm_discard = False
    qtbot.addWidget(w)
    w.show()
    assert w.wait_idle()
    return w


def _close(*windows: MainWindow) -> None:
    for w in windows:
        w.wait_idle(60000)
        w.set_dirty(False)
        w.close()


def test_a_second_instance_leaves_the_live_autosave_alone(qtbot, tmp_path, asked) -> None:
    w1 = _instance(qtbot)
    w1.payout_panel.set_value("payout.clearance_mm", 31)
    p = w1.autosave_now()
    assert p is not None and p.exists() and AutosaveOwner.lock_path(p).exists()
    text = p.read_text("utf-8")
    w2 = _instance(qtbot, None)
    # not offered, not restorable, not deleted by a save or close of the second instance
    assert w2.pending_autosaves() == []
    w2.offer_autosaves()
    assert asked == [] and w2.job.name == "untitled"
    w2.restore_autosave(p)
    assert w2.wait_idle() and w2.job.name == "untitled" and not w2.dirty
    w2.drop_autosave()
    # locks do not go stale by age while their process runs (Qt's default would after 30 s)
    old = time.time() - 3600
    os.utime(AutosaveOwner.lock_path(p), (old, old))
    assert w2.pending_autosaves() == []
    _close(w2)
    assert p.read_text("utf-8") == text
    # the first instance keeps writing the same copy, and drops it when it saves
    w1.payout_panel.set_value("payout.clearance_mm", 32)
    assert w1.autosave_now() == p and load_job(p).payout.clearance_mm == 32.0
    assert w1.save_job(tmp_path / "saved.toml")
    assert not p.exists() and not AutosaveOwner.lock_path(p).exists()
    _close(w1)


def test_two_instances_on_the_same_job_keep_their_own_copies(qtbot, asked) -> None:
    w1, w2 = _instance(qtbot), _instance(qtbot)
    w1.payout_panel.set_value("payout.clearance_mm", 21)
    w2.payout_panel.set_value("payout.clearance_mm", 22)
    p1, p2 = w1.autosave_now(), w2.autosave_now()
    assert p1 is not None and p2 is not None and p1 != p2 and p1.parent == p2.parent
    assert (p1.name, p2.name) == ("pipe.toml", "pipe-2.toml")
    w1.payout_panel.set_value("payout.clearance_mm", 23)
    assert w1.autosave_now() == p1 and w2.autosave_now() == p2
    assert load_job(p1).payout.clearance_mm == 23.0 and load_job(p2).payout.clearance_mm == 22.0
    assert autosave_origin(p1) == autosave_origin(p2) == PIPE.resolve()
    # a third instance sees neither (both live); closing one instance drops only its own copy
    w3 = _instance(qtbot, None)
    assert w3.pending_autosaves() == []
    _close(w1)
    assert not p1.exists() and p2.exists()
    assert w3.pending_autosaves() == []
    _close(w2, w3)
    assert not p2.exists()


def test_a_leftover_copy_is_not_overwritten_by_a_new_edit(qtbot, asked, tmp_path, monkeypatch) -> None:
    """A leftover nobody restored (answered "Ignore") survives a new session's autosave of the same job."""
    d = tmp_path / "autosave"
    d.mkdir()
    leftover = d / "pipe.toml"
    leftover.write_text(f"{AUTOSAVE_HEADER}{PIPE.resolve()}\n{PIPE.read_text('utf-8')}", "utf-8")
    monkeypatch.setattr(QMessageBox, "question", lambda *a, **k: QMessageBox.StandardButton.Ignore)
    w = _instance(qtbot)
    w.offer_autosaves()
    assert leftover.exists() and not AutosaveOwner.lock_path(leftover).exists()  # lock released after asking
    w.payout_panel.set_value("payout.clearance_mm", 24)
    p = w.autosave_now()
    assert p is not None and p.name == "pipe-2.toml"
    assert load_job(leftover) == load_job(PIPE)
    assert w.pending_autosaves() == [leftover]
    _close(w)
    assert leftover.exists() and not p.exists()


LOCKER = textwrap.dedent("""
    import os, signal, sys
    from PySide6.QtCore import QLockFile
    lock = QLockFile(sys.argv[1])
    lock.setStaleLockTime(0)
    assert lock.tryLock(0)
    print("locked", flush=True)
    sys.stdin.readline()
    os.kill(os.getpid(), signal.SIGKILL)  # dies holding the lock: the file stays with this PID
""")


def test_killed_instance_copy_is_offered_only_after_it_died(qtbot, tmp_path, asked) -> None:
    d = tmp_path / "autosave"
    d.mkdir()
    copy = d / "pipe.toml"
    job = load_job(PIPE)
    edited = job.replace(payout=job.payout.model_copy(update={"clearance_mm": 35.0}))
    copy.write_text(f"{AUTOSAVE_HEADER}{PIPE.resolve()}\n{edited.to_toml()}", "utf-8")
    lock = AutosaveOwner.lock_path(copy)
    with subprocess.Popen([sys.executable, "-c", LOCKER, str(lock)], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                          text=True, env=dict(os.environ, QT_QPA_PLATFORM="offscreen")) as proc:
        try:
            assert proc.stdout.readline().strip() == "locked"
            w = _instance(qtbot, None)
            # another process holds it: its live copy
            assert w.pending_autosaves() == []
            w.offer_autosaves()
            assert asked == []
            proc.stdin.write("\n")
            proc.stdin.flush()
            assert proc.wait(60) == -signal.SIGKILL
        finally:
            if proc.poll() is None:
                proc.kill()
    assert lock.exists() and lock.read_text().split("\n", 1)[0] == str(proc.pid)  # the stale lock is still there
    # the process is gone: its lock is stale, the copy is offered and restored
    assert w.pending_autosaves() == [copy]
    w.offer_autosaves()
    assert w.wait_idle()
    assert len(asked) == 1 and copy.name in asked[0]
    assert w.job == load_job(copy) and w.job.payout.clearance_mm == 35.0 and w.dirty
    assert w.job_path == PIPE.resolve()
    assert lock.read_text().split("\n", 1)[0] == str(os.getpid())  # now this instance's
    # and it keeps autosaving into the restored copy
    w.payout_panel.set_value("payout.clearance_mm", 36)
    assert w.autosave_now() == copy and load_job(copy).payout.clearance_mm == 36.0
    _close(w)
    assert not copy.exists()


def test_failed_autosave_releases_the_lock_it_took(qtbot, monkeypatch) -> None:
    """A write that fails (disk full, permissions) leaves no lock on a name without a copy."""
    import winder_gui.document as mw

    w = _instance(qtbot)
    w.set_dirty(True)

    def fail(*_a, **_k):
        raise OSError(28, "No space left on device")

    write = mw.atomic_write_text
    monkeypatch.setattr(mw, "atomic_write_text", fail)
    p = w.autosave_path()
    assert w.autosave_now() is None
    assert not p.exists() and not w.autosave_owner.holds(p)
    assert "Autosave failed" in w.status_msg.text()
    monkeypatch.setattr(mw, "atomic_write_text", write)
    assert w.autosave_now() == p and p.exists() and w.autosave_owner.holds(p)
    _close(w)
