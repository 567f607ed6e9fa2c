"""Sketched generatrix of exact segments (engine.sketch, issue 17 point 1)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from engine.errors import InputError
from engine.job import build_mandrel, load_job, parse_job, save_job
from engine.mandrel import ArcSegment, LineSegment, Mandrel
from engine.sketch import build_sketch, sketch_from_mandrel
from engine.winding import winding_line

EXAMPLES = Path(__file__).resolve().parents[1] / "resources" / "examples"

R = 60.0
CYL = [{"type": "arc", "center_mm": [0.0, 0.0], "to_mm": [0.0, R]},
       {"type": "line", "to_mm": [300.0, R]},
       {"type": "arc", "to_mm": [300.0 + math.sqrt(R * R - 400.0), 20.0]}]
START = [-math.sqrt(R * R - 400.0), 20.0]


def test_cylinder_with_arc_ends_is_exactly_straight() -> None:
    m = build_sketch(START, CYL)
    z = np.linspace(0.0, 300.0, 200_001)
    r, dr, d2r = m.evaluate(z)
    assert np.abs(r - R).max() <= 1e-9
    assert np.abs(dr).max() <= 1e-12 and np.abs(d2r[:-1]).max() == 0.0  # z = 300: the arc's r''
    assert m.concave_zones(tol_mm=0.0) == []
    # the domes are the circle of radius R around the cylinder's end centres (the second one tangent)
    zz = np.linspace(m.z_min, 0.0, 1001)
    assert np.abs(np.hypot(zz, m.r(zz)) - R).max() < 1e-9
    zz = np.linspace(300.0, m.z_max, 1001)
    assert np.abs(np.hypot(zz - 300.0, m.r(zz)) - R).max() < 1e-9
    assert m.pole_radii == pytest.approx((20.0, 20.0), abs=1e-9)


def test_first_arc_tangent_to_the_following_line() -> None:
    m = build_sketch([0.0, 20.0], [{"type": "arc", "to_mm": [40.0, 60.0]}, {"type": "line", "to_mm": [200.0, 60.0]}])
    arc = m.segments[0]
    assert isinstance(arc, ArcSegment)
    # tangent to r = 60 at z = 40: centre (40, 60 - a), through (0, 20): a = 40
    assert (arc.zc, arc.rc, arc.a, arc.side) == pytest.approx((40.0, 20.0, 40.0, 1))


@pytest.mark.parametrize("rho", [5.0, 20.0, 50.0])
def test_fillet_between_lines_is_tangent_with_the_given_radius(rho: float) -> None:
    # a cone 60 -> 30 over 100 mm after a cylinder: a convex corner at z = 300, a concave one at z = 400
    m = build_sketch([0.0, 60.0], [
        {"type": "line", "to_mm": [300.0, 60.0]},
        {"type": "line", "to_mm": [400.0, 30.0], "corner": True, "fillet_mm": rho},
        {"type": "line", "to_mm": [500.0, 30.0], "corner": True, "fillet_mm": rho},
    ])
    kinds = [s.kind for s in m.segments]
    assert kinds == ["line", "arc", "line", "arc", "line"]
    theta = math.atan(0.3)  # deflection of each corner
    tangent_len = rho * math.tan(0.5 * theta)  # analytic: corner to tangent point
    a1, a2 = m.segments[1], m.segments[3]
    assert isinstance(a1, ArcSegment) and isinstance(a2, ArcSegment)
    assert a1.a == rho and a2.a == rho and a1.side == 1 and a2.side == -1
    assert a1.z0 == pytest.approx(300.0 - tangent_len, abs=1e-9)
    assert a2.z1 == pytest.approx(400.0 + tangent_len, abs=1e-9)
    for j in (1, 2, 3, 4):
        z = m.segments[j].z0
        left, right = m.segments[j - 1].eval(np.array([z])), m.segments[j].eval(np.array([z]))
        assert abs(left[0][0] - right[0][0]) < 1e-9 and abs(left[1][0] - right[1][0]) < 1e-9
    assert len(m.concave_zones(tol_mm=0.0)) == 1  # the concave fillet only
    assert all(s.kind == "line" for s in m.segments[::2])


@pytest.mark.parametrize("template", [
    Mandrel.vessel(100.0, 300.0, "isotensoid", (25.0, 40.0)),
    Mandrel.vessel(100.0, 300.0, "ellipse", 30.0, 0.6),
    Mandrel.vessel(100.0, 300.0, "hemisphere", (30.0, 0.0)),
    Mandrel.bottle(),
    Mandrel.cone(50.0, 80.0, 200.0),
    Mandrel.pipe(75.0, 1000.0),
    Mandrel.from_points([0, 10, 20, 30, 40], [20, 24, 23, 26, 21]),
], ids=["isotensoid", "ellipse", "hemisphere-closed", "bottle", "cone", "pipe", "spline"])
def test_templates_convert_to_the_same_exact_segments(template: Mandrel) -> None:
    sk = sketch_from_mandrel(template)
    assert sk["kind"] == "segments"
    again = build_sketch(sk["start_mm"], sk["segments"])
    assert [type(s) for s in again.segments] == [type(s) for s in template.segments]
    z = np.linspace(template.z_min, template.z_max, 50_001)
    assert abs(again.z_min - template.z_min) < 1e-9 and abs(again.z_max - template.z_max) < 1e-9
    assert np.abs(again.r(z) - template.r(z)).max() < 1e-9
    # and through the job document
    job = parse_job('schema_version = 1\n[mandrel]\nkind = "pipe"\nradius_mm = 1\nlength_mm = 1\n')
    job = job.replace(mandrel=sk)
    text = job.to_toml()
    assert "[[mandrel.segments]]" in text
    m = build_mandrel(parse_job(text))
    assert np.abs(m.r(z) - template.r(z)).max() < 1e-9


@pytest.mark.parametrize("name", ["pressure_vessel", "bottle", "pipe"])
def test_examples_lines_unchanged_by_convert_to_sketch(name: str) -> None:
    job = load_job(EXAMPLES / f"{name}.toml")
    m0 = build_mandrel(job)
    m1 = build_mandrel(job.replace(mandrel=sketch_from_mandrel(m0)))
    w = job.winding.model_copy(update={"points_per_pass": 400})
    a = winding_line(m0, job.band.width_mm, job.band.friction, w)
    b = winding_line(m1, job.band.width_mm, job.band.friction, w)
    for f in ("z", "r", "v", "C", "lam", "beta", "s"):
        assert np.abs(getattr(a, f) - getattr(b, f)).max() <= 1e-9, f


def _bad(start: list[float], segs: list[dict]) -> InputError:
    with pytest.raises(InputError) as info:
        build_sketch(start, segs)
    return info.value


def test_errors_name_the_segment_and_field() -> None:
    e = _bad([0.0, 60.0], [{"type": "line", "to_mm": [100.0, 60.0]}, {"type": "line", "to_mm": [200.0, 40.0]}])
    assert e.location.field == "segments[1].corner" and "segment 2" in e.message and "tangent" in e.message
    e = _bad([0.0, 60.0], [{"type": "line", "to_mm": [100.0, 60.0]},
                           {"type": "line", "to_mm": [200.0, 40.0], "corner": True}])
    assert e.location.field == "segments[1].fillet_mm"
    e = _bad([0.0, 60.0], [{"type": "line", "to_mm": [100.0, 60.0]},
                           {"type": "arc", "center_mm": [100.0, 0.0], "to_mm": [150.0, 10.0]}])
    assert e.location.field == "segments[1].to_mm" and "not on the arc" in e.message
    e = _bad([0.0, 60.0], [{"type": "line", "to_mm": [-10.0, 60.0]}])
    assert e.location.field == "segments[0].to_mm" and "increase" in e.message
    e = _bad([0.0, 60.0], [{"type": "line", "to_mm": [10.0, 60.0], "points_mm": [[1, 2]]}])
    assert e.location.field == "segments[0].points_mm"
    e = _bad([0.0, 20.0], [{"type": "arc", "to_mm": [40.0, 60.0]}])
    assert e.location.field == "segments[0].center_mm"
    e = _bad([0.0, 60.0], [{"type": "line", "to_mm": [100.0, 60.0]},
                           {"type": "line", "to_mm": [110.0, 0.0], "corner": True, "fillet_mm": 500.0}])
    assert e.location.field == "segments[1].fillet_mm" and "no fillet" in e.message


def test_job_file_errors_name_file_line_and_segment(tmp_path: Path) -> None:
    text = (
        'schema_version = 1\n[mandrel]\nkind = "segments"\nstart_mm = [0.0, 60.0]\n'
        '[[mandrel.segments]]\ntype = "line"\nto_mm = [100.0, 60.0]\n'
        '[[mandrel.segments]]\ntype = "arc"\ncenter_mm = [100.0, 0.0]\nto_mm = [150.0, 10.0]\n'
    )
    p = tmp_path / "s.toml"
    p.write_text(text)
    with pytest.raises(InputError) as info:
        build_mandrel(load_job(p), p)
    e = info.value
    assert e.location.field == "mandrel.segments[1].to_mm"
    assert e.location.line == text.splitlines().index("to_mm = [150.0, 10.0]") + 1
    bad = text.replace('type = "arc"', 'type = "circle"')
    with pytest.raises(InputError) as info:
        parse_job(bad, file="s.toml")
    assert info.value.location.field == "mandrel.segments[1].type"
    assert info.value.location.line == bad.splitlines().index('type = "circle"') + 1
    ok = text.replace("to_mm = [150.0, 10.0]", "to_mm = [160.0, 0.0]").replace('center_mm = [100.0, 0.0]',
                                                                                 "center_mm = [100.0, 0.0]")
    job = parse_job(ok.replace('center_mm = [100.0, 0.0]\n', ''))
    m = build_mandrel(job)
    assert isinstance(m.segments[1], ArcSegment) and m.pole_radii[1] == pytest.approx(0.0, abs=1e-9)
    out = save_job(job, tmp_path / "again.toml")
    assert load_job(out) == job


def test_spline_segment_is_clamped_tangent_to_its_neighbours() -> None:
    m = build_sketch([0.0, 60.0], [
        {"type": "line", "to_mm": [100.0, 60.0]},
        {"type": "spline", "points_mm": [[120.0, 55.0], [140.0, 45.0], [160.0, 40.0]]},
        {"type": "line", "to_mm": [200.0, 30.0]},
    ])
    assert isinstance(m.segments[0], LineSegment)
    for j in (1, 2):
        z = m.segments[j].z0
        assert abs(m.segments[j - 1].eval(np.array([z]))[1][0] - m.segments[j].eval(np.array([z]))[1][0]) < 1e-12


# ------------------------------------------------------------------------------------------------
# DXF: lines and arcs stay exact segments
# ------------------------------------------------------------------------------------------------
def _filleted() -> Mandrel:
    return build_sketch(START, [
        *CYL[:2],
        {"type": "line", "to_mm": [360.0, 40.0], "corner": True, "fillet_mm": 30.0},
        {"type": "line", "to_mm": [420.0, 40.0], "corner": True, "fillet_mm": 15.0},  # a concave fillet
        {"type": "arc", "to_mm": [440.0, 20.0]},
    ])


@pytest.mark.parametrize("make", [lambda: build_sketch(START, CYL), _filleted], ids=["cylinder-arcs", "fillets"])
def test_dxf_of_lines_and_arcs_round_trips_exactly(make, tmp_path: Path) -> None:  # noqa: ANN001
    from engine.mandrel_io import export_dxf, load_dxf

    m = make()
    p = export_dxf(m, tmp_path / "profile.dxf")
    back = load_dxf(p)
    assert back.meta["dxf_exact"] is True
    assert [type(s) for s in back.segments] == [type(s) for s in m.segments]
    for a, b in zip(m.segments, back.segments):
        assert abs(a.z0 - b.z0) < 1e-9 and abs(a.z1 - b.z1) < 1e-9
        if isinstance(a, ArcSegment):
            assert isinstance(b, ArcSegment)
            assert (abs(a.zc - b.zc), abs(a.rc - b.rc), abs(a.a - b.a), a.side) < (1e-9, 1e-9, 1e-9, b.side + 1)
            assert a.side == b.side
    z = np.linspace(m.z_min, m.z_max, 100_001)
    assert np.abs(back.r(z) - m.r(z)).max() < 1e-9
    z = np.linspace(1.0, m.segments[1].z1 - 1.0, 1001)  # the straight part stays exactly straight
    assert np.abs(back.r(z) - R).max() <= 1e-9
    # and again: a second round trip changes nothing
    again = load_dxf(export_dxf(back, tmp_path / "again.dxf"))
    assert np.abs(again.r(z) - back.r(z)).max() < 1e-12


def test_dxf_with_a_corner_is_fitted_by_a_spline_and_says_why(tmp_path: Path) -> None:
    import ezdxf

    from engine.mandrel_io import load_dxf

    doc = ezdxf.new("R2010")
    msp = doc.modelspace()
    msp.add_line((0.0, 30.0), (100.0, 30.0))
    msp.add_line((100.0, 30.0), (150.0, 20.0))
    doc.saveas(tmp_path / "corner.dxf")
    m = load_dxf(tmp_path / "corner.dxf")
    assert m.meta["dxf_exact"] is False and "corner at z = 100" in m.meta["dxf_spline_reason"]
    assert m.segments[0].kind == "spline"


def test_cli_exports_dxf_and_sketch(tmp_path: Path) -> None:
    import tomllib

    from engine.cli import main

    job = EXAMPLES / "pressure_vessel.toml"
    assert main(["mandrel", str(job), "--dxf", str(tmp_path / "v.dxf"), "--sketch", str(tmp_path / "v.toml")]) == 0
    sk = tomllib.loads((tmp_path / "v.toml").read_text())["mandrel"]
    assert [s["type"] for s in sk["segments"]] == ["isotensoid", "line", "isotensoid"]
    m0 = build_mandrel(load_job(job))
    m1 = build_sketch(sk["start_mm"], sk["segments"])
    z = np.linspace(m0.z_min, m0.z_max, 10_001)
    assert np.abs(m1.r(z) - m0.r(z)).max() < 1e-9
    assert (tmp_path / "v.dxf").stat().st_size > 0
    assert main(["mandrel", str(job), "--dxf", str(tmp_path / "v.txt")]) == 2


# ------------------------------------------------------------------------------------------------
# CSV: smoothing fit with a stated tolerance
# ------------------------------------------------------------------------------------------------
def _noisy_csv(tmp_path: Path, sigma: float = 0.01) -> tuple[Path, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(3)
    z = np.concatenate([np.linspace(-56.0, 0.0, 15, endpoint=False), np.linspace(0.0, 300.0, 30, endpoint=False),
                        np.linspace(300.0, 356.0, 15)])
    r_true = np.where(z < 0, np.sqrt(np.maximum(R * R - z * z, 0)),
                      np.where(z <= 300, R, np.sqrt(np.maximum(R * R - (z - 300) ** 2, 0))))
    r = r_true + rng.normal(0.0, sigma, z.size)
    p = tmp_path / "noisy.csv"
    p.write_text("z,r\n" + "\n".join(f"{float(a)!r},{float(b)!r}" for a, b in zip(z, r)))
    return p, z, r


@pytest.mark.parametrize("tol", [0.01, 0.03, 0.1])
def test_csv_smoothing_stays_within_the_stated_tolerance(tol: float, tmp_path: Path) -> None:
    from engine.mandrel_io import load_csv

    p, z, r = _noisy_csv(tmp_path)
    raw = load_csv(p)
    sm = load_csv(p, smoothing_mm=tol)
    info = sm.meta["smoothing"]
    assert info["applied"] and info["tolerance_mm"] == tol
    dev = np.abs(sm.r(z) - r)
    assert dev.max() <= tol + 1e-12 and info["max_deviation_mm"] == pytest.approx(dev.max())
    assert info["rms_deviation_mm"] == pytest.approx(float(np.sqrt(np.mean(dev**2))))
    # smoother than the interpolating spline on the straight part: less curvature wiggle
    zz = np.linspace(40.0, 260.0, 2001)
    assert np.abs(sm.d2r(zz)).max() < np.abs(raw.d2r(zz)).max()
    assert sm.pole_radii == pytest.approx(raw.pole_radii)


def test_csv_smoothing_in_a_job_and_refused_for_dxf(tmp_path: Path) -> None:
    p, _, _ = _noisy_csv(tmp_path)
    job = parse_job(f'schema_version = 1\n[mandrel]\nkind = "file"\npath = "{p.name}"\nsmoothing_mm = 0.05\n')
    m = build_mandrel(job, tmp_path / "job.toml")
    assert m.meta["smoothing"]["max_deviation_mm"] <= 0.05
    from engine.mandrel_io import export_dxf, load_mandrel_file

    d = export_dxf(build_sketch(START, CYL), tmp_path / "p.dxf")
    with pytest.raises(InputError, match="point tables"):
        load_mandrel_file(d, smoothing_mm=0.05)
