"""Job document: round trip, validation messages with file/line/field, atomic save, CLI."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from engine.cli import main
from engine.errors import InputError
from engine.job import Job, VesselSpec, build_mandrel, default_job, load_job, parse_job, save_job

EXAMPLES = Path(__file__).resolve().parents[1] / "resources" / "examples"
VESSEL = (EXAMPLES / "pressure_vessel.toml").read_text()


@pytest.mark.parametrize("name", ["pressure_vessel", "bottle", "pipe"])
def test_examples_round_trip(name: str, tmp_path: Path) -> None:
    job = load_job(EXAMPLES / f"{name}.toml")
    out = save_job(job, tmp_path / "j.toml")
    again = load_job(out)
    assert again == job
    assert again.to_toml() == job.to_toml()
    m = build_mandrel(again, out)
    assert m.z_max > m.z_min


@settings(max_examples=60, deadline=None)
@given(
    radius=st.floats(1.0, 1e4),
    length=st.floats(0.0, 1e4),
    frac=st.floats(0.0, 0.95),
    name=st.text(max_size=30),
)
def test_round_trip_is_lossless(radius: float, length: float, frac: float, name: str) -> None:
    job = Job(name=name, mandrel=VesselSpec(radius_mm=radius, cylinder_length_mm=length,
                                            pole_radius_mm=(frac * radius, 0.5 * frac * radius)))
    assert parse_job(job.to_toml()) == job


def _err(text: str) -> InputError:
    with pytest.raises(InputError) as info:
        parse_job(text, file="job.toml")
    return info.value


def test_mistyped_field_names_file_line_field() -> None:
    e = _err(VESSEL.replace("radius_mm = 100.0", 'radius_mm = "big"'))
    assert e.location.file == "job.toml"
    assert e.location.field == "mandrel.radius_mm"
    assert e.location.line == VESSEL.splitlines().index("radius_mm = 100.0") + 1
    assert "valid number" in e.message and "big" in e.message


def test_missing_field() -> None:
    e = _err(VESSEL.replace("cylinder_length_mm = 300.0\n", ""))
    assert e.location.field == "mandrel.cylinder_length_mm"
    assert "missing" in e.message
    assert e.location.line == VESSEL.splitlines().index("[mandrel]") + 1


def test_unknown_field_is_reported_as_typo() -> None:
    e = _err(VESSEL.replace("width_mm = 8.0", "widht_mm = 8.0"))
    assert e.location.field == "band.widht_mm"
    assert "unknown field" in e.message and "width_mm" in e.message
    assert e.location.line == VESSEL.splitlines().index("widht_mm = 8.0".replace("widht", "width")) + 1


def test_bad_enum_and_kind() -> None:
    e = _err(VESSEL.replace('dome = "isotensoid"', 'dome = "flat"'))
    assert e.location.field.startswith("mandrel.dome")
    e = _err(VESSEL.replace('kind = "vessel"', 'kind = "vase"'))
    assert "vase" in e.message and e.location.field == "mandrel"


def test_negative_and_nan_values() -> None:
    e = _err(VESSEL.replace("width_mm = 8.0", "width_mm = -8.0"))
    assert e.location.field == "band.width_mm" and "greater than 0" in e.message
    e = _err(VESSEL.replace("radius_mm = 100.0", "radius_mm = nan"))
    assert e.location.field == "mandrel.radius_mm"


def test_broken_toml_and_schema_version() -> None:
    e = _err(VESSEL.replace("[band]", "[band"))
    assert "TOML" in e.message and e.location.line is not None
    e = _err(VESSEL.replace("schema_version = 2", "schema_version = 7"))
    assert e.location.field == "schema_version"
    assert e.location.line == VESSEL.splitlines().index("schema_version = 2") + 1
    assert "7" in e.message and "1, 2" in e.message


def test_empty_binary_and_missing_files(tmp_path: Path) -> None:
    (tmp_path / "empty.toml").write_text("")
    (tmp_path / "bin.toml").write_bytes(b"\x00\xff\xfe garbage")
    for name, words in (("empty.toml", "empty"), ("bin.toml", "UTF-8"), ("nope.toml", "not found")):
        with pytest.raises(InputError) as info:
            load_job(tmp_path / name)
        assert words in str(info.value) and name in str(info.value)


def test_geometry_error_points_at_job_field(tmp_path: Path) -> None:
    p = tmp_path / "v.toml"
    p.write_text(VESSEL.replace("radius_mm = 100.0", "radius_mm = 30.0"))
    with pytest.raises(InputError) as info:
        build_mandrel(load_job(p), p)
    e = info.value
    assert e.location.field == "mandrel.pole_radius_mm" and e.location.file == str(p)
    assert e.location.line == VESSEL.splitlines().index("pole_radius_mm = [25.0, 40.0]") + 1


def test_points_axis_crossing_is_rejected() -> None:
    text = 'name = "s"\n[mandrel]\nkind = "points"\nz_mm = [0, 10, 20, 30, 40]\nr_mm = [5, 8, 0, 8, 5]\n'
    with pytest.raises(InputError) as info:
        build_mandrel(parse_job(text), None)
    assert "axis" in info.value.message and info.value.location.field == "mandrel.r_mm"


def test_save_is_atomic_and_keeps_old_file_on_failure(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    p = tmp_path / "job.toml"
    save_job(default_job("first"), p)
    before = p.read_bytes()

    def boom(self: Job) -> str:
        raise RuntimeError("disk full")

    monkeypatch.setattr(Job, "to_toml", boom)
    with pytest.raises(RuntimeError):
        save_job(default_job("second"), p)
    assert p.read_bytes() == before
    assert [f.name for f in tmp_path.iterdir()] == ["job.toml"]  # no temp file left behind


def test_cli_mandrel_json(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["mandrel", str(EXAMPLES / "pressure_vessel.toml"), "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    for key in ("z_min", "z_max", "r_min", "r_max", "pole_radii", "area_mm2", "volume_mm3", "concave_zones"):
        assert key in data
    assert data["pole_radii"] == pytest.approx([25.0, 40.0])
    assert data["r_max"] == pytest.approx(100.0)


def test_cli_mandrel_hemisphere_closed_form(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    p = tmp_path / "h.toml"
    save_job(Job(name="h", mandrel=VesselSpec(radius_mm=50.0, cylinder_length_mm=120.0)), p)
    assert main(["mandrel", str(p), "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    R, L = 50.0, 120.0
    assert data["area_mm2"] == pytest.approx(2 * math.pi * R * L + 4 * math.pi * R * R, rel=1e-6)
    assert data["volume_mm3"] == pytest.approx(math.pi * R * R * L + 4 / 3 * math.pi * R**3, rel=1e-6)


def test_cli_bad_job_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    p = tmp_path / "bad.toml"
    p.write_text(VESSEL.replace("radius_mm = 100.0", 'radius_mm = "x"'))
    assert main(["mandrel", str(p), "--json"]) == 2
    err = capsys.readouterr().err
    assert "bad.toml" in err and "mandrel.radius_mm" in err and "Traceback" not in err


def test_cli_subprocess_version_and_error(tmp_path: Path) -> None:
    exe = [sys.executable, "-m", "engine"]
    env = {**os.environ, "QT_QPA_PLATFORM": "offscreen"}
    out = subprocess.run([*exe, "--version"], capture_output=True, text=True, env=env)
    assert out.returncode == 0 and "winder" in out.stdout
    out = subprocess.run([*exe, "mandrel", str(tmp_path / "missing.toml")], capture_output=True, text=True, env=env)
    assert out.returncode == 2 and "not found" in out.stderr and "Traceback" not in out.stderr
