"""Mandrel importers (CSV, DXF, STEP) and exporters (STEP, STL): round trips, bad input, fuzzing."""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.interpolate import CubicSpline

from engine.errors import InputError
from engine.mandrel import Mandrel
from engine.mandrel_io import export_step, export_stl, load_csv, load_dxf, load_mandrel_file, load_step

# ------------------------------------------------------------------------------------------------
# helpers
# ------------------------------------------------------------------------------------------------
Z_REF = np.array([0.0, 10.0, 20.0, 35.0, 50.0, 70.0, 90.0])
R_REF = np.array([20.0, 28.0, 33.0, 35.0, 34.0, 30.0, 22.0])


def _write(tmp_path: Path, name: str, text: str | bytes) -> Path:
    p = tmp_path / name
    if isinstance(text, bytes):
        p.write_bytes(text)
    else:
        p.write_bytes(text.encode("utf-8"))
    return p


def _rows(sep: str = ",", fmt: str = "{:g}") -> list[str]:
    return [f"{fmt.format(a)}{sep}{fmt.format(b)}" for a, b in zip(Z_REF, R_REF)]


def _check_reference(m: Mandrel) -> None:
    ref = CubicSpline(Z_REF, R_REF)
    z = np.linspace(Z_REF[0], Z_REF[-1], 301)
    np.testing.assert_allclose(m.r(z), ref(z), rtol=0, atol=1e-12)
    assert m.z_min == 0.0 and m.z_max == 90.0


def _err(fn, path: Path) -> InputError:  # noqa: ANN001
    with pytest.raises(InputError) as ei:
        fn(path)
    err = ei.value
    assert err.location.file == str(path), str(err)
    return err


# ================================================================================================
# CSV
# ================================================================================================
@pytest.mark.parametrize(
    "name, text",
    [
        ("plain.csv", "z,r\n" + "\n".join(_rows()) + "\n"),
        ("units.csv", "Z_mm;R_MM\n" + "\n".join(_rows(";")) + "\n"),
        ("brackets.csv", "z [mm]\tr (mm)\n" + "\n".join(_rows("\t")) + "\n"),
        ("blanks.txt", "# a comment\n  z   r  \n" + "\n".join(r.replace(",", "   ") for r in _rows()) + "\n"),
        ("noheader.csv", "\n".join(_rows(", ")) + "\n\n"),
        ("comments.csv", "# profile\n\nz,r # header\n" + "\n".join(f"{r}  # pt" for r in _rows()) + "\n# end\n"),
        ("crlf.csv", "z,r\r\n" + "\r\n".join(_rows()) + "\r\n"),
        ("no_newline.csv", "z,r\n" + "\n".join(_rows())),
        ("swapped.csv", "r_mm,z_mm\n" + "\n".join(f"{b:g},{a:g}" for a, b in zip(Z_REF, R_REF)) + "\n"),
        ("diameter.csv", "z,diameter,t\n" + "\n".join(f"{a:g},{2 * b:g},7" for a, b in zip(Z_REF, R_REF)) + "\n"),
        ("exp.csv", "z,r\n" + "\n".join(_rows(",", "{:.10e}")) + "\n"),
        ("comma_decimal.csv", "z;r\n" + "\n".join(_rows(";", "{:.1f}")).replace(".", ",") + "\n"),
        ("trailing_comma.csv", "z,r,\n" + "\n".join(f"{r}," for r in _rows()) + "\n"),
        ("units_row.csv",
         '"z","r"\n"[mm]","[mm]"\n' + "\n".join(f'"{a:g}","{b:g}"' for a, b in zip(Z_REF, R_REF))),
    ],
)
def test_csv_formats(tmp_path: Path, name: str, text: str) -> None:
    m = load_csv(_write(tmp_path, name, text))
    _check_reference(m)
    assert m.source == "csv"
    assert m.name == Path(name).stem


def test_csv_bom_and_utf16(tmp_path: Path) -> None:
    text = "z,r\n" + "\n".join(_rows()) + "\n"
    _check_reference(load_csv(_write(tmp_path, "bom.csv", b"\xef\xbb\xbf" + text.encode())))
    _check_reference(load_csv(_write(tmp_path, "u16.csv", text.encode("utf-16"))))


def _table(rows: list[str], header: str = "z_mm,r_mm") -> str:
    return header + "\n" + "\n".join(rows) + "\n"


GOOD = _rows()


@pytest.mark.parametrize(
    "text, line, field, words",
    [
        (_table(GOOD[:3] + ["30,35", "25,34"] + GOOD[5:]), 6, "z_mm (column 1)", "z must increase"),
        (_table(GOOD[:3] + ["35,35", "35,34"] + GOOD[5:]), 6, "z_mm (column 1)", "z must increase"),
        (_table(GOOD[:3] + ["35,-1"] + GOOD[4:]), 5, "r_mm (column 2)", "negative radius"),
        (_table(GOOD[:3] + ["35,0"] + GOOD[4:]), 5, "r_mm (column 2)", "meets the axis"),
        (_table(GOOD[:3] + ["35,nan"] + GOOD[4:]), 5, "r_mm (column 2)", "not a finite number"),
        (_table(GOOD[:3] + ["inf,35"] + GOOD[4:]), 5, "z_mm (column 1)", "not a finite number"),
        (_table(GOOD[:3] + ["35,-Infinity"] + GOOD[4:]), 5, "r_mm (column 2)", "not a finite number"),
        (_table(GOOD[:3] + ["35,abc"] + GOOD[4:]), 5, "r_mm (column 2)", "'abc' is not a number"),
        (_table(GOOD[:3] + ["35,3 5"] + GOOD[4:]), 5, "r_mm (column 2)", "is not a number"),
        (_table(GOOD[:3] + ["35,"] + GOOD[4:]), 5, "r_mm (column 2)", "expected 2"),
        (_table(GOOD[:3] + ["35"] + GOOD[4:]), 5, "r_mm (column 2)", "expected 2"),
        (_table(GOOD[:3] + ["35,35,9"] + GOOD[4:]), 5, "column 3", "expected 2"),
        (_table(GOOD[:3] + ["35,,35"] + GOOD[4:]), 5, "column 3", "expected 2"),
        (_table(GOOD[:3]), 4, None, "too few points"),
        ("0,20\n10,x28\n20,33\n35,35\n", 2, "r (column 2)", "'x28' is not a number"),
        ("0,2O\n10,28\n20,33\n35,35\n", 1, "r (column 2)", "'2O' is not a number"),
        (_table(GOOD[:3] + ["35,1e9"] + GOOD[4:]), 5, "r_mm (column 2)", "out of range"),
        (_table(GOOD[:3] + ["20.0000000000001,35"] + GOOD[4:]), 5, "z_mm (column 1)", "too close"),
        (_table(["0,10", "1,10", "2,10", "3,10", "3.1,0.5", "4,10", "5,10"]), 6, "r_mm (column 2)",
         "intersects the axis"),
        ("z_mm,r_mm\n" + "\n".join(GOOD) + "\n90,2", 9, "z_mm (column 1)", "z must increase"),
    ],
)
def test_csv_errors_name_line_and_column(tmp_path: Path, text: str, line: int, field: str | None,
                                         words: str) -> None:
    err = _err(load_csv, _write(tmp_path, "bad.csv", text))
    assert words in err.message, str(err)
    assert err.location.line == line, str(err)
    if field is not None:
        assert err.location.field == field, str(err)


@pytest.mark.parametrize(
    "tail, words",
    [
        ("100,2", "z must increase"),  # would be fine except z; checks the last row is read
        ("100,", "cut off"),  # cut mid-row
        ("100,2.5e", "cut off"),  # cut mid-number
        ("100", "cut off"),
        ("1e", "cut off"),
    ],
)
def test_csv_truncated_last_line(tmp_path: Path, tail: str, words: str) -> None:
    text = "z,r\n" + "\n".join(_rows()) + "\n" + tail.replace("100", "95" if words != "z must increase" else "90")
    err = _err(load_csv, _write(tmp_path, "cut.csv", text))
    assert words in err.message, str(err)
    assert err.location.line == len(GOOD) + 2


@pytest.mark.parametrize(
    "content, words",
    [
        (b"", "empty file"),
        (b"\n\n   \n", "empty file"),
        (b"# only a comment\n# and another\n", "empty file"),
        (b"z,r\n", "too few points"),
        (b"\x00\x01\x02\x03binary\xff\xfe\x00", "binary"),
        (b"z,r\n0,10\n1,10\n2,1\xe9\n3,10\n", "not UTF-8"),
        (b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR", "binary"),
        (b"alpha,beta\n0,1\n1,2\n2,3\n3,4\n", "cannot read the header"),
        (b"0,1,2\n1,2,3\n", "no header"),
    ],
)
def test_csv_bad_files(tmp_path: Path, content: bytes, words: str) -> None:
    err = _err(load_csv, _write(tmp_path, "x.csv", content))
    assert words in err.message, str(err)


def test_csv_missing_file_and_directory(tmp_path: Path) -> None:
    err = _err(load_csv, tmp_path / "nope.csv")
    assert "not found" in err.message
    d = tmp_path / "dir.csv"
    d.mkdir()
    assert "directory" in _err(load_csv, d).message


def test_csv_sample_bottle(examples_dir: Path) -> None:
    m = load_csv(examples_dir / "bottle_profile.csv")
    ref = Mandrel.bottle()
    assert m.z_min == pytest.approx(ref.z_min, abs=1e-5)
    assert m.z_max == pytest.approx(ref.z_max, abs=1e-5)
    z = np.linspace(m.z_min, m.z_max, 2001)
    assert np.max(np.abs(m.r(z) - ref.r(z))) < 0.05  # 160 points, C1 joints of the source
    assert any(zn.z_from < 200.0 < zn.z_to for zn in m.concave_zones())  # the waist survives


# ------------------------------------------------------------------------------------------------
# fuzzing: only InputError, never a write
# ------------------------------------------------------------------------------------------------
def _listing(d: Path) -> set[str]:
    return set(os.listdir(d))


_cell = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True, width=64).map(repr),
    st.integers(-10**6, 10**6).map(str),
    st.text(alphabet="0123456789.eE+-,;# \tabcnaNIf\"'", max_size=8),
)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.binary(max_size=400))
def test_csv_fuzz_random_bytes(tmp_path: Path, data: bytes) -> None:
    p = _write(tmp_path, "fuzz.csv", data)
    before = _listing(tmp_path)
    try:
        m = load_csv(p)
        assert isinstance(m, Mandrel)
    except InputError as exc:
        assert exc.location.file == str(p)
    assert _listing(tmp_path) == before


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(rows=st.lists(st.lists(_cell, min_size=0, max_size=4), max_size=12),
       sep=st.sampled_from([",", ";", "\t", " "]), header=st.booleans(), newline=st.booleans())
def test_csv_fuzz_random_rows(tmp_path: Path, rows: list[list[str]], sep: str, header: bool, newline: bool) -> None:
    text = ("z,r\n" if header else "") + "\n".join(sep.join(r) for r in rows) + ("\n" if newline else "")
    p = _write(tmp_path, "rows.csv", text)
    before = _listing(tmp_path)
    try:
        m = load_csv(p)
        assert np.isfinite(m.r(np.linspace(m.z_min, m.z_max, 50))).all()
    except InputError as exc:
        assert exc.location.file == str(p)
    assert _listing(tmp_path) == before


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(z=st.one_of(st.lists(st.floats(-1e4, 1e4), max_size=10), st.lists(st.floats(), max_size=8)),
       r=st.one_of(st.lists(st.floats(-10, 1e4), max_size=10), st.lists(st.floats(), max_size=8)))
def test_csv_fuzz_numeric_tables(tmp_path: Path, z: list[float], r: list[float]) -> None:
    text = "z,r\n" + "\n".join(f"{a!r},{b!r}" for a, b in zip(z, r)) + "\n"
    p = _write(tmp_path, "num.csv", text)
    try:
        m = load_csv(p)
    except InputError:
        return
    # accepted: the points are reproduced and the curve stays off the axis
    n = min(len(z), len(r))
    zz, rr = np.array(z[:n]), np.array(r[:n])
    np.testing.assert_allclose(m.r(zz), rr, rtol=1e-9, atol=1e-9)
    assert (m.r(np.linspace(m.z_min, m.z_max, 400))[1:-1] > 0).all()


# ================================================================================================
# DXF
# ================================================================================================
def _new_dxf():  # noqa: ANN202
    import ezdxf

    doc = ezdxf.new("R2010")
    return doc, doc.modelspace()


def _save(doc, tmp_path: Path, name: str = "p.dxf") -> Path:  # noqa: ANN001
    p = tmp_path / name
    doc.saveas(p)
    return p


def test_dxf_sample_vessel(examples_dir: Path) -> None:
    m = load_dxf(examples_dir / "vessel_profile.dxf")
    R, L = 60.0, 120.0
    z_left = -math.sqrt(R * R - 15.0**2)
    assert m.z_min == pytest.approx(z_left, abs=1e-9)
    assert m.pole_radii[0] == pytest.approx(15.0, abs=1e-9)
    assert m.pole_radii[1] == pytest.approx(20.0, abs=1e-9)
    z = np.linspace(z_left + 0.5, -3.0, 400)  # hemisphere, away from the joint
    np.testing.assert_allclose(m.r(z), np.sqrt(R * R - z * z), rtol=1e-7)
    z = np.linspace(3.0, L - 3.0, 200)
    np.testing.assert_allclose(m.r(z), R, rtol=1e-7)
    z = np.linspace(L + 3.0, m.z_max - 0.5, 200)  # the drawn spline approximates an ellipse
    np.testing.assert_allclose(m.r(z), R * np.sqrt(1 - ((z - L) / 40.0) ** 2), rtol=2e-3)


def _bulge(angle: float) -> float:
    return math.tan(angle / 4.0)


def test_dxf_lwpolyline_with_bulges_matches_vessel(tmp_path: Path) -> None:
    """A closed section (axis, end faces, hemispherical domes as bulge arcs) drawn right to left."""
    R, L, rp = 50.0, 80.0, 12.0
    h = math.sqrt(R * R - rp * rp)
    phi = math.asin(rp / R)
    sweep = 0.5 * math.pi - phi  # each dome arc
    doc, msp = _new_dxf()
    # counter-clockwise: axis left->right, right end face up, right dome, cylinder (right->left), left dome, face
    pts = [
        (-h, 0.0, 0.0),
        (L + h, 0.0, 0.0),
        (L + h, rp, _bulge(sweep)),
        (L, R, 0.0),
        (0.0, R, _bulge(sweep)),
        (-h, rp, 0.0),
    ]
    msp.add_lwpolyline(pts, format="xyb", close=True, dxfattribs={"layer": "SKETCH"})
    msp.add_text("label", dxfattribs={"layer": "NOTES"})
    m = load_dxf(_save(doc, tmp_path))
    ref = Mandrel.vessel(R, L, "hemisphere", pole_radii=rp)
    assert m.z_min == pytest.approx(ref.z_min, abs=1e-9) and m.z_max == pytest.approx(ref.z_max, abs=1e-9)
    for a, b in ((ref.z_min + 0.3, -2.0), (2.0, L - 2.0), (L + 2.0, ref.z_max - 0.3)):
        z = np.linspace(a, b, 300)
        np.testing.assert_allclose(m.r(z), ref.r(z), rtol=1e-7)
    assert m.area_mm2 == pytest.approx(ref.area_mm2, rel=1e-6)
    assert m.volume_mm3 == pytest.approx(ref.volume_mm3, rel=1e-6)


def test_dxf_polyline_spline_line_arc_chain_and_units(tmp_path: Path) -> None:
    """POLYLINE (cone) + SPLINE + LINE + ARC on a PROFILE layer, distractors elsewhere, drawn in cm."""
    doc, msp = _new_dxf()
    doc.header["$INSUNITS"] = 5  # cm
    doc.layers.add("PROFILE")
    msp.add_polyline2d([(0.0, 2.0), (3.0, 3.0)], dxfattribs={"layer": "PROFILE"})  # cone r 20 -> 30 mm
    # cubic Bezier-like spline from (3, 3) to (5, 3.5), tangent-continuous with the cone (slope 1/3)
    msp.add_spline(fit_points=[(3.0, 3.0), (3.6, 3.2), (4.2, 3.38), (5.0, 3.5)],
                   dxfattribs={"layer": "PROFILE"}).dxf.start_tangent = (3.0, 1.0, 0.0)
    msp.add_line((5.0, 3.5), (7.0, 3.5), dxfattribs={"layer": "PROFILE"})
    msp.add_arc((7.0, 0.0), 3.5, 60.0, 90.0, dxfattribs={"layer": "PROFILE"})  # quarter-sphere-like end
    msp.add_line((-5.0, -5.0), (20.0, 20.0), dxfattribs={"layer": "CONSTRUCTION"})  # ignored: other layer
    m = load_dxf(_save(doc, tmp_path))
    assert m.z_min == pytest.approx(0.0, abs=1e-9)
    assert m.z_max == pytest.approx(70.0 + 35.0 * math.cos(math.radians(60.0)), abs=1e-6)
    z = np.linspace(1.0, 27.0, 50)
    np.testing.assert_allclose(m.r(z), 20.0 + z / 3.0, rtol=1e-4)  # C1 joint ringing stays small
    z = np.linspace(52.0, 68.0, 50)
    np.testing.assert_allclose(m.r(z), 35.0, rtol=1e-4)
    z = np.linspace(72.0, m.z_max - 0.5, 50)
    np.testing.assert_allclose(m.r(z), np.sqrt(35.0**2 - (z - 70.0) ** 2), rtol=1e-6)


def test_dxf_block_reference(tmp_path: Path) -> None:
    doc, msp = _new_dxf()
    blk = doc.blocks.new("PROF")
    blk.add_lwpolyline([(0, 10), (10, 12), (20, 15), (30, 19), (40, 24)])
    msp.add_blockref("PROF", (5.0, 0.0))
    m = load_dxf(_save(doc, tmp_path))
    assert m.z_min == pytest.approx(5.0) and m.z_max == pytest.approx(45.0)
    assert m.r(np.array([15.0]))[0] == pytest.approx(12.0, abs=1e-9)


def _dxf_case(kind: str, tmp_path: Path) -> Path:
    doc, msp = _new_dxf()
    if kind == "empty_modelspace":
        pass
    elif kind == "text_only":
        msp.add_text("profile goes here", dxfattribs={"layer": "NOTES"})
        msp.add_circle((0, 0), 5.0)
    elif kind == "vertical_only":
        msp.add_line((10.0, 0.0), (10.0, 50.0))
        msp.add_line((30.0, 0.0), (30.0, 50.0))
    elif kind == "axis_only":
        msp.add_line((0.0, 0.0), (100.0, 0.0))
    elif kind == "below_axis":
        msp.add_lwpolyline([(0, -10), (10, -12), (20, -15), (30, -19)])
    elif kind == "overhang":
        msp.add_lwpolyline([(0, 10), (20, 20), (30, 30), (25, 40), (40, 45)], dxfattribs={"layer": "L1"})
    elif kind == "overlap":
        msp.add_line((0, 10), (50, 10))
        msp.add_line((30, 20), (80, 20))
    elif kind == "gap":
        msp.add_line((0, 10), (50, 10))
        msp.add_line((60, 10), (80, 10))
    elif kind == "step":
        msp.add_lwpolyline([(0, 10), (50, 10), (50, 20), (80, 20)])
    elif kind == "too_short":
        msp.add_line((0, 10), (0.0, 10.0))
    else:  # pragma: no cover
        raise AssertionError(kind)
    return _save(doc, tmp_path, f"{kind}.dxf")


@pytest.mark.parametrize(
    "kind, words",
    [
        ("empty_modelspace", ["no profile", "model space is empty"]),
        ("text_only", ["no profile", "TEXT", "CIRCLE", "layer 'NOTES'"]),
        ("vertical_only", ["no profile above the axis", "2 are perpendicular to the axis", "LINE #"]),
        ("axis_only", ["no profile above the axis", "1 lie on the axis"]),
        ("below_axis", ["no profile above the axis", "3 below it", "LWPOLYLINE"]),
        ("overhang", ["not a function of z", "LWPOLYLINE #", "layer 'L1'", "z = 30"]),
        ("overlap", ["not a function of z", "LINE #"]),
        ("gap", ["gap", "z = 50", "z = 60"]),
        ("step", ["steps", "z = 50"]),
        ("too_short", ["no profile"]),
    ],
)
def test_dxf_without_usable_profile(tmp_path: Path, kind: str, words: list[str]) -> None:
    err = _err(load_dxf, _dxf_case(kind, tmp_path))
    for w in words:
        assert w in err.message, str(err)


@pytest.mark.parametrize(
    "content, words",
    [
        (b"", "empty file"),
        (b"this is not a drawing\n", "not a readable DXF"),
        (b"0\nSECTION\n2\nENTITIES\n0\nLINE\n10\nabc\n", "no profile"),
        (b"\x00\x01\x02garbage\xff\xfe", "binary"),
        (b"0\nSECTION\n2\nHEADER\n9\n$ACADVER\n1\nAC1015\n0\nENDSEC\n0\nEOF\n", "no profile"),
    ],
)
def test_dxf_unreadable(tmp_path: Path, content: bytes, words: str) -> None:
    err = _err(load_dxf, _write(tmp_path, "bad.dxf", content))
    assert words in err.message, str(err)


def test_dxf_truncated_file(tmp_path: Path, examples_dir: Path) -> None:
    data = (examples_dir / "vessel_profile.dxf").read_bytes()
    for frac in (0.1, 0.5, 0.9):
        p = _write(tmp_path, f"cut{frac}.dxf", data[: int(len(data) * frac)])
        try:
            load_dxf(p)
        except InputError as exc:
            assert exc.location.file == str(p)


@settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.one_of(
    st.binary(max_size=300),
    st.lists(st.tuples(st.integers(-5, 1100), st.text(alphabet="ABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789.$-_ ",
                                                      max_size=10)), max_size=30).map(
        lambda tags: ("0\nSECTION\n2\nENTITIES\n" + "".join(f"{c}\n{v}\n" for c, v in tags)
                      + "0\nENDSEC\n0\nEOF\n").encode()),
))
def test_dxf_fuzz_random_bytes_and_tags(tmp_path: Path, data: bytes) -> None:
    p = _write(tmp_path, "fuzz.dxf", data)
    before = _listing(tmp_path)
    try:
        assert isinstance(load_dxf(p), Mandrel)
    except InputError as exc:
        assert exc.location.file == str(p)
    assert _listing(tmp_path) == before


_coord = st.floats(-200, 200, allow_nan=False)


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(polys=st.lists(st.lists(st.tuples(_coord, _coord, st.floats(-2, 2)), min_size=1, max_size=8), min_size=1,
                      max_size=3),
       lines=st.lists(st.tuples(_coord, _coord, _coord, _coord), max_size=3))
def test_dxf_fuzz_random_entities(tmp_path: Path, polys: list, lines: list) -> None:  # noqa: ANN001
    doc, msp = _new_dxf()
    for pl in polys:
        msp.add_lwpolyline(pl, format="xyb")
    for x0, y0, x1, y1 in lines:
        msp.add_line((x0, y0), (x1, y1))
    p = _save(doc, tmp_path, "ents.dxf")
    before = _listing(tmp_path)
    try:
        m = load_dxf(p)
        assert (m.r(np.linspace(m.z_min, m.z_max, 200))[1:-1] > 0).all()
    except InputError as exc:
        assert exc.location.file == str(p)
    assert _listing(tmp_path) == before


# ================================================================================================
# STEP / STL
# ================================================================================================
def _roundtrip(m: Mandrel, tmp_path: Path) -> Mandrel:
    p = tmp_path / f"{m.name}.step"
    export_step(m, p)
    assert p.stat().st_size < 1_000_000
    back = load_step(p)
    assert back.source == "step"
    return back


@pytest.mark.parametrize(
    "mandrel",
    [
        Mandrel.vessel(100.0, 200.0, "hemisphere", pole_radii=(30.0, 20.0), name="hemi"),
        Mandrel.vessel(80.0, 150.0, "ellipse", pole_radii=(10.0, 25.0), dome_ratio=(0.6, 1.7), name="ellipse"),
        pytest.param(Mandrel.vessel(100.0, 200.0, "isotensoid", pole_radii=(30.0, 20.0), name="iso"),
                     marks=pytest.mark.slow),
        pytest.param(Mandrel.bottle(), marks=pytest.mark.slow),
    ],
    ids=["hemisphere", "ellipse", "isotensoid", "bottle"],
)
def test_step_roundtrip(tmp_path: Path, mandrel: Mandrel) -> None:
    back = _roundtrip(mandrel, tmp_path)
    scale = mandrel.length
    assert back.z_min == pytest.approx(mandrel.z_min, abs=1e-7 * scale)
    assert back.z_max == pytest.approx(mandrel.z_max, abs=1e-7 * scale)
    z = np.linspace(mandrel.z_min, mandrel.z_max, 20001)
    rel = np.abs(back.r(z) - mandrel.r(z)) / mandrel.r(z)
    assert rel.max() < 1e-5, (rel.max(), z[rel.argmax()])
    assert back.volume_mm3 == pytest.approx(mandrel.volume_mm3, rel=1e-6)
    assert back.meta["axis_direction"] == [0.0, 0.0, 1.0]


def test_step_closed_hemisphere_and_sample(tmp_path: Path, examples_dir: Path) -> None:
    m = Mandrel.vessel(40.0, 60.0, "hemisphere", pole_radii=0.0, name="closed")
    back = _roundtrip(m, tmp_path)
    assert back.pole_radii == pytest.approx((0.0, 0.0), abs=1e-6)
    z = np.linspace(m.z_min + 2.0, m.z_max - 2.0, 2001)  # r(z) is singular at a closed pole
    np.testing.assert_allclose(back.r(z), m.r(z), rtol=1e-5)
    sample = load_mandrel_file(examples_dir / "vessel.step")
    ref = Mandrel.vessel(60.0, 120.0, dome="ellipse", dome_ratio=0.7, pole_radii=15.0)
    z = np.linspace(ref.z_min, ref.z_max, 4001)
    np.testing.assert_allclose(sample.r(z), ref.r(z), rtol=1e-5)


def test_step_roundtrip_closed_spline_and_cone(tmp_path: Path) -> None:
    for m in (Mandrel.from_points([0, 10, 20, 30, 40], [0.0, 12.0, 15.0, 14.0, 0.0], name="closed_spline"),
              Mandrel.cone(30.0, 10.0, 100.0)):
        back = _roundtrip(m, tmp_path)
        z = np.linspace(m.z_min + 1.0, m.z_max - 1.0, 500)
        np.testing.assert_allclose(back.r(z), m.r(z), rtol=1e-6)
        assert back.pole_radii == pytest.approx(m.pole_radii, abs=1e-6)


def test_step_axis_detected_off_origin(tmp_path: Path) -> None:
    """A plain cylinder along a tilted axis away from the origin is a solid of revolution about that axis."""
    import cadquery as cq

    body = cq.Workplane("XY").circle(25.0).extrude(100.0).val()
    body = body.rotate(cq.Vector(0, 0, 0), cq.Vector(1, 0, 0), 30.0).translate(cq.Vector(40.0, -20.0, 5.0))
    p = tmp_path / "tilted.step"
    cq.exporters.export(body, str(p))
    m = load_step(p)
    assert m.length == pytest.approx(100.0, rel=1e-9)
    np.testing.assert_allclose(m.r(np.linspace(m.z_min, m.z_max, 101)), 25.0, rtol=1e-9)
    d = np.array(m.meta["axis_direction"])
    assert abs(d @ np.array([0.0, -math.sin(math.radians(30)), math.cos(math.radians(30))])) == pytest.approx(1.0)


def _export_cq(shape, tmp_path: Path, name: str) -> Path:  # noqa: ANN001
    import cadquery as cq

    p = tmp_path / name
    cq.exporters.export(shape, str(p))
    return p


@pytest.mark.parametrize("kind", ["box", "square_prism", "eccentric_boss", "cross_hole", "tab_on_top"])
def test_step_not_a_solid_of_revolution(tmp_path: Path, kind: str) -> None:
    import cadquery as cq

    if kind == "box":
        shape = cq.Workplane("XY").box(40.0, 60.0, 100.0)
    elif kind == "square_prism":  # 4-fold symmetric about Z: caught by the 37° half-plane
        shape = cq.Workplane("XY").rect(50.0, 50.0).extrude(100.0)
    elif kind == "eccentric_boss":  # a cylinder with an off-axis cylinder on top
        shape = (cq.Workplane("XY").circle(30.0).extrude(80.0)
                 .faces(">Z").workplane().center(12.0, 0.0).circle(8.0).extrude(20.0))
    elif kind == "cross_hole":  # a cylinder with a transverse hole
        shape = (cq.Workplane("XY").circle(30.0).extrude(80.0)
                 .cut(cq.Workplane("YZ").workplane(offset=-50).center(0, 40).circle(5.0).extrude(100.0)))
    else:  # a small block on the top face, off the 0° half-plane: caught by the extent check
        shape = (cq.Workplane("XY").circle(30.0).extrude(80.0)
                 .union(cq.Workplane("XY").workplane(offset=80).center(0, 10).rect(4, 4).extrude(5)))
    err = _err(load_step, _export_cq(shape, tmp_path, f"{kind}.step"))
    assert "not a solid of revolution" in err.message, str(err)


def test_step_hollow_body_gives_outer_profile_and_steps_are_refused(tmp_path: Path) -> None:
    import cadquery as cq

    tube = (cq.Workplane("XY").circle(30.0).extrude(80.0).cut(cq.Workplane("XY").circle(10.0).extrude(40.0))
            .cut(cq.Workplane("XY").circle(5.0).extrude(80.0)))  # stepped through-bore
    m = load_step(_export_cq(tube, tmp_path, "tube.step"))
    assert (m.z_min, m.z_max) == pytest.approx((0.0, 80.0), abs=1e-9)
    np.testing.assert_allclose(m.r(np.linspace(0.0, 80.0, 81)), 30.0, rtol=1e-9)
    shoulder = cq.Workplane("XY").circle(30.0).extrude(50.0).faces(">Z").workplane().circle(20.0).extrude(30.0)
    err = _err(load_step, _export_cq(shoulder, tmp_path, "shoulder.step"))
    assert "steps between r = 20 and 30 mm at z = 50 mm" in err.message


def test_step_bad_files(tmp_path: Path) -> None:
    import cadquery as cq

    assert "empty file" in _err(load_step, _write(tmp_path, "e.step", b"")).message
    assert "not a STEP file" in _err(load_step, _write(tmp_path, "t.step", b"solid x\nendsolid\n")).message
    assert "not a STEP file" in _err(load_step, _write(tmp_path, "b.stp", bytes(range(256)))).message
    broken = _write(tmp_path, "broken.step", b"ISO-10303-21;\nHEADER;\nENDSEC;\nDATA;\n#1=FOO(;\n")
    assert _err(load_step, broken).message
    two = cq.Workplane("XY").circle(10).extrude(10).union(
        cq.Workplane("XY").workplane(offset=50).circle(10).extrude(10))
    assert "2 solids" in _err(load_step, _export_cq(two, tmp_path, "two.step")).message


def test_stl_closed_mesh_and_volume(tmp_path: Path) -> None:
    import pyvista as pv

    for m, tol, ascii in ((Mandrel.vessel(50.0, 80.0, "ellipse", pole_radii=(10.0, 15.0), dome_ratio=0.7), 0.01, False),
                          (Mandrel.vessel(40.0, 60.0, "hemisphere", pole_radii=(0.0, 12.0)), 0.005, True),
                          (Mandrel.vessel(40.0, 0.0, "isotensoid", pole_radii=(8.0, 20.0)), 0.01, False),
                          (Mandrel.bottle(), 0.02, False),
                          (Mandrel.from_points([0, 10, 20, 30, 40], [0.0, 12.0, 15.0, 14.0, 0.0]), 0.01, True)):
        p = tmp_path / "m.stl"
        export_stl(m, p, tolerance_mm=tol, ascii=ascii)
        assert p.read_bytes()[:5] == b"solid" if ascii else p.read_bytes()[:6] == b"winder"
        mesh = pv.read(str(p)).clean()
        assert mesh.n_cells > 100
        assert mesh.n_open_edges == 0
        assert mesh.is_manifold
        # chordal deviation <= tol everywhere: the volume differs by at most area * tol
        assert abs(mesh.volume - m.volume_mm3) <= m.area_mm2 * tol
        assert abs(mesh.volume - m.volume_mm3) >= 1e-3 * m.area_mm2 * tol  # not absurdly fine either
        # facets face outwards: the signed volume is positive
        tri = mesh.extract_surface(algorithm="dataset_surface").triangulate()
        f = tri.faces.reshape(-1, 4)[:, 1:]
        v = tri.points[f]
        assert np.einsum("ij,ij->i", v[:, 0], np.cross(v[:, 1], v[:, 2])).sum() / 6.0 > 0
        assert mesh.bounds[4] == pytest.approx(m.z_min, abs=tol) and mesh.bounds[5] == pytest.approx(m.z_max, abs=tol)


def test_exports_are_atomic_and_replace(tmp_path: Path) -> None:
    m = Mandrel.pipe(20.0, 50.0)
    p = tmp_path / "out.step"
    p.write_text("old")
    export_step(m, p)
    assert p.read_bytes().startswith(b"ISO-10303-21")
    export_stl(m, tmp_path / "out.stl", tolerance_mm=0.05)
    assert sorted(os.listdir(tmp_path)) == ["out.step", "out.stl"]
    with pytest.raises(InputError):
        export_stl(m, tmp_path / "bad.stl", tolerance_mm=0.0)
    assert sorted(os.listdir(tmp_path)) == ["out.step", "out.stl"]


# ================================================================================================
# dispatch
# ================================================================================================
def test_load_mandrel_file_dispatch(tmp_path: Path, examples_dir: Path) -> None:
    assert load_mandrel_file(examples_dir / "bottle_profile.csv").source == "csv"
    assert load_mandrel_file(examples_dir / "vessel_profile.dxf").source == "dxf"
    t = _write(tmp_path, "p.TXT", "z r\n" + "\n".join(r.replace(",", " ") for r in _rows()))
    _check_reference(load_mandrel_file(t))
    for name in ("job.toml", "mesh.stl", "noext"):
        err = _err(load_mandrel_file, _write(tmp_path, name, "x"))
        assert "unknown mandrel file type" in err.message


def test_samples_are_small(examples_dir: Path) -> None:
    for name in ("bottle_profile.csv", "vessel_profile.dxf", "vessel.step"):
        assert (examples_dir / name).stat().st_size < 1_000_000


def test_dxf_negligible_bulge_is_a_straight_segment(tmp_path: Path) -> None:
    """A bulge of 1e-110 (hypothesis found it: an overflow warning inside the arc conversion, or an arc of no
    length) is a straight segment: the profile comes in exact, r on the line equals the drawn line."""
    doc, msp = _new_dxf()
    msp.add_lwpolyline([(0.0, 10.0, -1.1e-110), (100.0, 30.0, 0.0)], format="xyb")
    m = load_dxf(_save(doc, tmp_path, "bulge.dxf"))
    assert m.meta["dxf_exact"] is True
    z = np.linspace(0.0, 100.0, 11)
    np.testing.assert_allclose(m.r(z), 10.0 + 0.2 * z, rtol=0, atol=1e-9)
