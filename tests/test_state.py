from __future__ import annotations

import io

import pytest

from engine.errors import Cancelled, InputError
from engine.state import CliState, RecordingState, SubState, check_cancel


def test_recording_state_cancels_after_polls() -> None:
    st = RecordingState(cancel_after=2)
    check_cancel(st)
    check_cancel(st)
    with pytest.raises(Cancelled):
        check_cancel(st)
    assert st.polls == 3


def test_substate_maps_progress() -> None:
    parent = RecordingState()
    sub = SubState(parent, 0.5, 1.0)
    sub.progress(0.0, "a")
    sub.progress(0.5, "b")
    sub.progress(2.0, "c")
    assert parent.fractions == [0.5, 0.75, 1.0]


def test_cli_state_silent_when_not_tty() -> None:
    buf = io.StringIO()
    CliState(stream=buf).progress(0.5, "x")
    assert buf.getvalue() == ""


def test_input_error_names_place() -> None:
    err = InputError("radius must be > 0, got -1", file="a.csv", line=3, field="r")
    assert str(err) == "a.csv, line 3, field 'r': radius must be > 0, got -1"
    err2 = InputError("bad").at(file="job.toml", field="mandrel.radius")
    assert str(err2) == "job.toml, field 'mandrel.radius': bad"


def test_read_toml_names_file_and_line(tmp_path) -> None:
    from engine.resources import find_named, read_toml, resource_path

    bad = tmp_path / "bad.toml"
    bad.write_text("a = 1\nb = = 2\nc = 3\n")
    with pytest.raises(InputError) as info:
        read_toml(bad)
    assert info.value.location.file == str(bad) and info.value.location.line == 2
    with pytest.raises(InputError) as info:
        read_toml(tmp_path / "none.toml", "machine template file")
    assert "machine template file not found" in str(info.value)
    with pytest.raises(InputError) as info:
        find_named(resource_path("machines"), "no_such_machine", "machine", "machine")
    assert "lathe2" in info.value.message and info.value.location.field == "machine"
