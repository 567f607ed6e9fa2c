"""The GUI survives hostile files with the user's job intact (issue 19): open and import actions."""

from __future__ import annotations

from pathlib import Path

import pytest
from gui_helpers import close_window, shown_window

from engine import budget

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "resources" / "examples"


@pytest.fixture
def window(qtbot):
    w = shown_window(qtbot, EXAMPLES / "bottle.toml")
    yield w
    close_window(w)
    budget.set_max_memory(None)


def _edited(w):
    """Change the job without saving it (the user's unsaved work)."""
    w.mandrel_panel.set_value("radius_mm", 61)
    assert w.wait_idle()
    return w.job


def _assert_kept(w, job, shown: str, *words: str) -> None:
    assert w.job == job and w.dirty
    assert "Traceback" not in shown and "Internal error" not in shown
    for word in words:
        assert word in shown, shown
    assert w.isVisible()


def test_open_deeply_nested_job_keeps_the_job(window, tmp_path) -> None:
    w = window
    job = _edited(w)
    bad = tmp_path / "deep.toml"
    bad.write_text("schema_version = 1\nx = " + "[" * 100000 + "]" * 100000 + "\n")
    w.open_job(bad)
    assert w.wait_idle()
    _assert_kept(w, job, w.error_box.text(), "deep.toml", "nested 100000 deep")


def test_import_of_a_step_file_that_crashes_the_reader_keeps_the_job(window, tmp_path, monkeypatch) -> None:
    import engine.mandrel_io as mio

    w = window
    job = _edited(w)
    monkeypatch.setattr(mio, "STEP_READER", "sandbox_targets:crash")  # a segfault inside the CAD kernel
    f = tmp_path / "evil.step"
    f.write_bytes((EXAMPLES / "vessel.step").read_bytes())
    w.import_generatrix(f)
    assert w.wait_idle(120000)
    _assert_kept(w, job, w.error_box.text(), "evil.step", "the STEP reader crashed on this file")
    w.error_box.close()
    # the application still works: a good import afterwards
    monkeypatch.setattr(mio, "STEP_READER", "engine.mandrel_io:_step_profile_of_file")
    w.import_generatrix(f)
    assert w.wait_idle(120000) and w.last_error.count("crashed") <= 1
    assert w.job.mandrel.kind == "file"


def test_import_of_a_step_file_that_hangs_the_reader(window, tmp_path, monkeypatch) -> None:
    import engine.mandrel_io as mio

    w = window
    job = _edited(w)
    monkeypatch.setattr(mio, "STEP_READER", "sandbox_targets:hang")
    monkeypatch.setenv("WINDER_IMPORT_TIMEOUT", "2")
    f = tmp_path / "slow.step"
    f.write_bytes((EXAMPLES / "vessel.step").read_bytes())
    w.import_generatrix(f)
    assert w.wait_idle(120000)
    _assert_kept(w, job, w.error_box.text(), "slow.step", "gave up after 2 s")


def test_absurd_job_is_refused_by_the_budget_and_the_setting_raises_it(window, tmp_path) -> None:
    from winder_gui.settings import apply_memory_budget, set_memory_budget

    w = window
    text = (EXAMPLES / "bottle.toml").read_text()
    p = tmp_path / "big.toml"
    p.write_text(text.replace("[winding]", "[winding]\ncircuits = 300"))
    set_memory_budget("64M")
    w.open_job(p)
    assert w.wait_idle()
    w.run_pipeline_now()
    assert w.wait_idle(120000)
    assert "winding.circuits" in w.last_error and "64 MB" in w.last_error and "Memory budget" in w.last_error
    assert w.job.winding.circuits == 300  # the job stays, the user can fix it
    set_memory_budget("")
    assert apply_memory_budget() == budget.DEFAULT_MAX_MEMORY_BYTES


def test_gui_survives_fuzzed_jobs_and_profiles(window, tmp_path) -> None:
    """Seeded mutations of jobs and profiles through File -> Open and Import: each either loads or shows
    a message (never a traceback) and leaves the job as it was."""
    import random

    from fuzz_cases import SMALL_PIPE, SMALL_VESSEL, mutate_job, mutate_profile

    rng = random.Random(19)
    w = window
    outcomes = {"loaded": 0, "refused": 0}
    for i in range(16):
        before = w.job
        w.last_error = ""
        if i % 2 == 0:
            f = tmp_path / f"job{i}.toml"
            f.write_bytes(mutate_job(rng.choice([SMALL_PIPE, SMALL_VESSEL]), rng).encode("utf-8", "replace"))
            w.open_job(f)
        else:
            src = rng.choice([EXAMPLES / "bottle_profile.csv", EXAMPLES / "vessel_profile.dxf"])
            f = tmp_path / f"profile{i}{src.suffix}"
            f.write_bytes(mutate_profile(src.read_bytes(), rng))
            w.import_generatrix(f)
        assert w.wait_idle(120000)
        assert w.isVisible()
        if w.last_error:
            outcomes["refused"] += 1
            assert "Traceback" not in w.last_error and "Internal error" not in w.last_error, w.last_error
            assert f.name in w.last_error, w.last_error
            assert w.job == before
            w.error_box.close()
        else:
            outcomes["loaded"] += 1
            assert w.job != before or w.job_path == f
    print(outcomes)
    assert outcomes["refused"] >= 4 and outcomes["loaded"] >= 1, outcomes


def test_gui_survives_hostile_layered_jobs(window, tmp_path) -> None:
    """Layered jobs with hostile layers (huge passes/repeat, absurd bands, 1e308° skips, hoop ranges off the
    mandrel, thousands of layers) through File -> Open: each is refused with its file and field, or loads
    and then its run is refused before any work (budget, layer checks) - the window keeps working and the
    job shown is the one opened."""
    import random

    from fuzz_cases import SMALL_LAYERED, SMALL_LAYERED_VESSEL, mutate_layers

    rng = random.Random(1919)
    w = window
    edited = _edited(w)
    attacks = [("passes = 1", "passes = 1000\nrepeat = 1000"), ("angle_deg = 30.0", "angle_deg = 1e308"),
               ('name = "outer hoop"', 'name = "outer hoop"\nz_range_mm = [-1e6, 1e6]'),
               ('name = "outer hoop"', 'name = "outer hoop"\nband = { width_mm = 1e-9 }'),
               ("repeat = 1", "repeat = 1000\ncircuits = 1000000000")]
    expected = ["layer.1.repeat", "", "layer.4.z_range_mm", "layer.4.band.width_mm", "layer.2.circuits"]
    texts = [SMALL_LAYERED.replace(a, b) for a, b in attacks]
    texts.append(SMALL_LAYERED + '[[layer]]\nkind = "skip"\nangle_deg = 1.0\n' * 5000)
    texts += [mutate_layers(rng.choice([SMALL_LAYERED, SMALL_LAYERED_VESSEL]), rng) for _ in range(4)]
    outcomes = {"refused on open": 0, "run refused": 0, "ran": 0}
    for i, text in enumerate(texts):
        f = tmp_path / f"layered{i}.toml"
        f.write_text(text, encoding="utf-8")
        before = w.job
        w.last_error = ""
        w.open_job(f)
        assert w.wait_idle(120000) and w.isVisible()
        if w.last_error:
            outcomes["refused on open"] += 1
            assert i >= len(expected) or not expected[i], w.last_error  # the schema takes the size attacks
            assert f.name in w.last_error and "Traceback" not in w.last_error, w.last_error
            assert w.job == before  # the user's job (edited, unsaved) is kept
            assert w.job == edited or i > 0
            w.error_box.close()
            continue
        assert w.job_path == f
        opened = w.job
        w.run_pipeline_now()
        assert w.wait_idle(180000) and w.isVisible()
        assert w.job == opened
        if w.last_error:
            outcomes["run refused"] += 1
            assert "Traceback" not in w.last_error and "Internal error" not in w.last_error, w.last_error
            if i < len(expected):
                assert expected[i] in w.last_error, w.last_error
            w.error_box.close()
        else:
            outcomes["ran"] += 1
        assert w.job_path == f  # the job stays the one opened
    print(outcomes)
    assert outcomes["refused on open"] >= 3 and outcomes["run refused"] >= 2, outcomes
