"""Machine set-up and the NC safety checks (engine.machine_setup, issue 15): placement, head geometry,
back-turn tolerance, clearance against the supports, speed steps, grouping, post x machine."""

from __future__ import annotations

import re
from dataclasses import replace

import numpy as np
import pytest

from engine.blocks import make_blocks, optimise_block_times
from engine.errors import InputError
from engine.job import SetupSpec, default_job, parse_job
from engine.kinematics import AxisPath, Violation, demo_eye_path, forward_kinematics, inverse_kinematics, load_machine
from engine.machine_setup import (
    Locator,
    _segment_min_rho,
    _segment_min_rho_all,
    apply_setup,
    clearance_violations,
    compatible_posts,
    controller_for,
    group_violations,
    hold_back_turns,
    limit_speed_steps,
    mandrel_distance,
    place_on_machine,
    precheck,
    support_obstacles,
)
from engine.mandrel import Mandrel


def _axes(machine_name: str = "lathe2", length: float = 400.0):
    m = load_machine(machine_name)
    p = demo_eye_path("helix", n=1500, circuits=1, length=length, eye_radius=160.0)
    return m, inverse_kinematics(m, p.eye_xyz, p.fibre_dir, p.contact_xyz)


def test_setup_section_round_trips_and_names_typos() -> None:
    job = default_job().replace(machine={"template": "lathe3", "setup": {"mandrel_z0_mm": 250.0,
                                                                      "head_offset_mm": [5.0, 0.0, -10.0]}})
    again = parse_job(job.to_toml())
    assert again == job and again.machine.setup.mandrel_z0_mm == 250.0
    bad = job.to_toml().replace("mandrel_z0_mm", "mandrel_zero_mm")
    with pytest.raises(InputError) as info:
        parse_job(bad, "j.toml")
    assert info.value.location.field == "machine.setup.mandrel_zero_mm" and "mandrel_z0_mm" in info.value.message


def test_centred_placement_by_hand() -> None:
    m, ap = _axes()
    m2, ap2, pl = place_on_machine(m, ap, SetupSpec())
    x = ap2.q[:, 1]
    # centred: the middle of the carriage range is the middle of the travel 0..1200 (offset rounded to 0.1 mm)
    assert 0.5 * (x.min() + x.max()) == pytest.approx(600.0, abs=0.051)
    assert pl.fits and pl.mode == "centre" and pl.z0 == m2.axes[1].offset
    # the physics is unchanged: the same eye positions through forward kinematics
    e1, _ = forward_kinematics(m, ap.q)
    e2, _ = forward_kinematics(m2, ap2.q)
    assert np.allclose(e1, e2, atol=1e-9)
    # every z0 of the fitting interval puts the range inside the travel, its ends touch the limits
    lo_z0, hi_z0 = pl.z0_fit
    span = x.max() - x.min()
    assert hi_z0 - lo_z0 == pytest.approx(1200.0 - span, abs=1e-6)
    for z0 in (lo_z0, hi_z0):
        _m, ap3, pl3 = place_on_machine(apply_setup(m, SetupSpec(mandrel_z0_mm=z0)), ap, SetupSpec(mandrel_z0_mm=z0))
        shift = z0 - m.axes[1].offset
        assert ap3.q[:, 1].min() + shift >= -1e-6 and ap3.q[:, 1].max() + shift <= 1200 + 1e-6


def test_fixed_placement_outside_the_travel_says_what_fits() -> None:
    m, ap = _axes()
    setup = SetupSpec(mandrel_z0_mm=1100.0)
    m1 = apply_setup(m, setup)
    assert m1.axes[1].offset == 1100.0
    ap1 = inverse_kinematics(m1, ap.eye_xyz, ap.fibre_dir, ap.contact_xyz)
    _m, ap2, pl = place_on_machine(m1, ap1, setup)
    assert not pl.fits and pl.mode == "fixed"
    over = [v for v in ap2.violations if v.kind == "position" and v.axis == "X"]
    assert over and max(v.amount for v in over) == pytest.approx(pl.q_max - 1200.0, rel=1e-9)
    msg = pl.message()
    assert "leaves 0..1200" in msg and f"{pl.z0_fit[0]:.1f}" in msg and f"{pl.z0_fit[1]:.1f}" in msg


def test_placement_cannot_fit_a_too_long_path() -> None:
    m, ap = _axes(length=1300.0)
    _m, _ap, pl = place_on_machine(m, ap, SetupSpec())
    assert not pl.fits and pl.z0_fit is None and "no placement fits" in pl.message()


def test_head_geometry() -> None:
    m = load_machine("lathe2")
    assert apply_setup(m, SetupSpec(eye_radius_mm=210.0)).eye_radius == 210.0
    with pytest.raises(InputError, match="fixed eye radius does not apply") as info:
        apply_setup(load_machine("lathe3"), SetupSpec(eye_radius_mm=210.0))
    assert info.value.location.field == "machine.setup.eye_radius_mm"
    # a head offset shifts the controller values by exactly the offset (cross +5 mm -> Y 5 mm less)
    m3 = load_machine("lathe3")
    p = demo_eye_path("dome", n=400, circuits=1)
    a0 = inverse_kinematics(m3, p.eye_xyz, p.fibre_dir, p.contact_xyz)
    a1 = inverse_kinematics(apply_setup(m3, SetupSpec(head_offset_mm=(5.0, 0.0, -10.0))), p.eye_xyz, p.fibre_dir,
                            p.contact_xyz)
    assert np.allclose(a1.q[:, 2], a0.q[:, 2] - 5.0) and np.allclose(a1.q[:, 1], a0.q[:, 1] + 10.0)
    with pytest.raises(InputError, match="robot cell"):
        apply_setup(load_machine("robot_cell"), SetupSpec(head_offset_mm=(1.0, 0.0, 0.0)))


def _reverse_path(m, col):
    n = col.size
    q = np.zeros((n, 2))
    q[:, 0] = col
    q[:, 1] = 600.0
    z = np.zeros((n, 3))
    viol = []
    d = np.diff(col)
    for i in np.flatnonzero(d < 0):
        viol.append(Violation("reverse", "A", float(-d[i]), float(-d[i]), 0.0, index=int(i + 1), message="back"))
    return AxisPath("lathe2", ("A", "X"), q, z, z, z, np.zeros(n), violations=tuple(viol))


def test_back_turn_tolerance() -> None:
    m = load_machine("lathe2")                      # A in degrees
    col = np.linspace(0.0, 100.0, 50)
    col[10] = col[9] - 2e-13                        # noise
    col[30] = col[29] - 1.0                         # a real back-turn of 1 deg
    out = hold_back_turns(m, _reverse_path(m, col), 0.01)
    a = out.q[:, 0]
    assert a[10] == col[9] and a[30] == col[30]     # the noise is held, the real turn kept
    rev = [v for v in out.violations if v.kind == "reverse"]
    assert len(rev) == 1 and rev[0].index == 30
    assert "back_turn_tol_deg = 0.01 deg" in rev[0].message and "min-range" in rev[0].message
    # with a tolerance above 1 deg both are held and the column is monotone
    out2 = hold_back_turns(m, _reverse_path(m, col), 1.5)
    assert not [v for v in out2.violations if v.kind == "reverse"] and np.all(np.diff(out2.q[:, 0]) >= 0)


def test_segment_distance_from_the_axis_against_sampling() -> None:
    rng = np.random.default_rng(3)
    c = rng.uniform(-100, 100, (300, 3))
    e = rng.uniform(-100, 100, (300, 3))
    got = _segment_min_rho(c, e, -20.0, 35.0)
    t = np.linspace(0.0, 1.0, 20001)
    for k in range(300):
        p = c[k] + t[:, None] * (e[k] - c[k])
        inz = (p[:, 2] >= -20.0) & (p[:, 2] <= 35.0)
        want = np.hypot(p[inz, 0], p[inz, 1]).min() if inz.any() else np.inf
        if np.isinf(want):
            assert np.isinf(got[k]) or got[k] >= 0
        else:
            assert got[k] == pytest.approx(want, abs=0.02)


def test_segment_distance_prefilter_is_bit_identical() -> None:
    """Skipping the segments whose z range misses the support changes no value (those are inf)."""
    rng = np.random.default_rng(5)
    c = rng.uniform(-100, 100, (4000, 3))
    e = rng.uniform(-100, 100, (4000, 3))
    e[::7, 2] = c[::7, 2]                                # flat segments, inside and outside the slab
    e[1::9, 2] = -20.0                                    # ending on the slab's face
    for z0, z1 in ((-20.0, 35.0), (90.0, 120.0), (-300.0, -150.0)):
        got, ref = _segment_min_rho(c, e, z0, z1), _segment_min_rho_all(c, e, z0, z1)
        assert np.array_equal(got, ref)


def test_mandrel_distance_of_a_pipe_is_analytic() -> None:
    pipe = Mandrel.pipe(50.0, 300.0)
    z = np.array([10.0, 150.0, 290.0, 150.0, -30.0])
    rho = np.array([55.0, 80.0, 49.0, 20.0, 50.0])
    d = mandrel_distance(pipe, z, rho)
    assert d[:2] == pytest.approx([5.0, 30.0], abs=0.03)
    assert d[2] < 0 and d[3] < 0                    # inside the body
    assert d[4] == pytest.approx(30.0, abs=0.03)    # beyond the end face: to the rim at (0, 50)


def test_clearance_of_eye_and_fibre_against_the_supports() -> None:
    pipe = Mandrel.pipe(50.0, 300.0)
    setup = SetupSpec(shaft_radius_mm=20.0, shaft_length_mm=100.0, chuck_radius_mm=80.0, chuck_length_mm=100.0,
                      clearance_mm=5.0)
    obs = {o.name: o for o in support_obstacles(pipe, setup)}
    assert obs["chuck"].z0 == -200.0 and obs["chuck"].z1 == -100.0 and obs["tailstock"].radius == 30.0
    # point 0: eye 2 mm above the pipe (too close); point 1: fine; point 2: the fibre from the pipe's end
    # rim out to an eye beyond the chuck face passes through the chuck (radius 80 at z = -100..-200)
    contact = np.array([[52.0, 0.0, 150.0], [50.0, 0.0, 150.0], [50.0, 0.0, 0.0]])
    eye = np.array([[52.0, 0.0, 150.0], [120.0, 0.0, 150.0], [100.0, 0.0, -250.0]])
    contact[0] = [50.0, 0.0, 140.0]
    ap = AxisPath("lathe3", ("A", "X", "Y"), np.zeros((3, 3)), eye, np.zeros((3, 3)), contact, np.zeros(3))
    v = clearance_violations(ap, pipe, setup)
    what = {(x.message.split(":")[1].split(" 0")[0].split(" -")[0].strip(), x.index) for x in v}
    assert any("eye and the mandrel" in w and i == 0 for w, i in what)
    assert any("free fibre and the chuck" in w and i == 2 for w, i in what)
    assert not any(i == 1 for _w, i in what)
    worst = [x for x in v if "eye and the mandrel" in x.message][0]
    assert worst.value == pytest.approx(2.0, abs=0.03) and worst.amount == pytest.approx(-3.0, abs=0.03)
    # by hand: the fibre (50,0,0) -> (100,0,-250) is at rho = 50 + 50·(100/250) = 70 at the chuck face z = -100
    fib = [x for x in v if "free fibre and the chuck" in x.message][0]
    assert fib.value == pytest.approx(70.0 - 80.0, abs=1e-6)


def test_limit_speed_steps_against_the_18_optimum() -> None:
    """Second method: the (18) pairwise/global optimisation of engine.blocks with the given times as
    lower bounds is the least total time keeping max_jump; the ramps keep every step and stay close."""
    m = load_machine("lathe4")
    p = demo_eye_path("dome", n=1200, circuits=1)
    ap = inverse_kinematics(m, p.eye_xyz, p.fibre_dir, p.contact_xyz)
    b = make_blocks(m, ap, 0.05)
    t0 = np.asarray(b.t17) * 0.5                    # too fast everywhere: many steps over
    pj = m.limits("max_jump")
    t = limit_speed_steps(b.delta, t0, pj, b.cyclic)
    v = b.delta / t[:, None]
    steps = np.abs(np.roll(v, -1, axis=0) - v) if b.cyclic else np.abs(np.diff(v, axis=0))
    assert np.all(steps <= pj * (1 + 1e-6)) and np.all(t >= t0 * (1 - 1e-12))
    opt = optimise_block_times(replace(b, t17=t0), m)
    assert opt.total <= t.sum() * (1 + 1e-6)
    assert t.sum() <= 1.5 * opt.total
    print(f"ramps {t.sum():.3f} s, (18) optimum {opt.total:.3f} s")


def test_grouping_collapses_repeats_and_locates_the_first() -> None:
    class _R:                                       # the fields a Locator reads
        blocks = type("B", (), {"index": np.array([0, 10, 20, 30, 40]), "time": np.array([1.0, 2.0, 3.0, 4.0])})()
        nc_text = "(head)\nG0 X0\nG1 X1 F1\nG1 X2 F1\nG1 X3 F1\nG1 X4 F1\nM2\n"
        eye = type("E", (), {"index": np.arange(41)})()
        line = type("L", (), {"points_per_circuit": 20})()

    vs = [Violation("position", "X", 5.0 + k, 1205.0 + k, 1200.0, index=12 + 10 * k, count=2,
                    message=f"axis X: position {1205.0 + k:.6g} mm exceeds the limit 1200 mm by {5.0 + k:g} mm "
                            f"at point {12 + 10 * k} (2 points from point {12 + 10 * k})") for k in range(3)]
    g = group_violations(vs, Locator(_R()))
    assert len(g) == 1
    g = g[0]
    assert g.places == 3 and g.points == 6 and g.worst == 7.0 and g.what == "position"
    # point 12 lies in block 1 (path 10..20): NC line 4, t = 1 s, circuit 1
    assert g.first["nc_line"] == 4 and g.first["time_s"] == 1.0 and g.first["circuit"] == 1
    assert "NC line 4" in g.message and "3 place(s)" in g.message


def test_post_and_machine_resolved_up_front() -> None:
    robot = load_machine("robot_cell")
    assert controller_for("linuxcnc", None, robot).name == "linuxcnc_robot"
    assert controller_for("csv", None, robot).name == "csv"
    with pytest.raises(InputError) as info:
        controller_for("marlin", None, robot)
    msg = info.value.message
    assert "post marlin cannot write machine robot_cell" in msg and "E1" in msg and "linuxcnc_robot" in msg
    with pytest.raises(InputError, match="made for machine"):
        controller_for("linuxcnc", "linuxcnc_robot", load_machine("lathe2"))
    for name in ("lathe2", "lathe3", "lathe4", "gantry6", "robot_cell"):
        pairs = compatible_posts(load_machine(name))
        assert pairs and all(p and c for p, c in pairs)
        assert {p for p, _ in pairs} >= {"csv", "linuxcnc", "sinumerik"}


def test_precheck_eye_radius_and_travel() -> None:
    job = default_job().replace(mandrel={"kind": "pipe", "radius_mm": 158.0, "length_mm": 500.0})
    m = load_machine("lathe2")
    mandrel = Mandrel.pipe(158.0, 500.0)
    with pytest.raises(InputError, match="needs at least 163 mm") as info:
        precheck(job, m, mandrel, with_post=False)
    assert info.value.location.field == "machine.setup.eye_radius_mm"
    precheck(job, apply_setup(m, SetupSpec(eye_radius_mm=200.0)), mandrel, with_post=False)
    with pytest.raises(InputError, match="travels 1200 mm but the mandrel is 1500 mm long"):
        precheck(job, m, Mandrel.pipe(50.0, 1500.0), with_post=False)


def test_a_new_job_on_lathe2_fits_by_reducing_the_eye_radius() -> None:
    """The default new job (vessel R 100) on lathe2: at the template's eye radius 160 mm the eye, slid along
    the fibre, needs 1215 mm of X; the set-up picks the largest radius that fits the 1200 mm travel."""
    from engine.pipeline import run_pipeline

    job = default_job().replace(machine={"template": "lathe2"})
    res = run_pipeline(job, None, upto="axes")
    pl = res.placement
    assert pl.fits and res.violations == []
    r = res.machine.eye_radius
    assert 105.0 <= r < 160.0 and "eye radius" in pl.note and "1200" in pl.note
    assert pl.q_max - pl.q_min <= 1199.0 + 1e-6
    # by hand: the eye sits on the fibre line at exactly that radius from the axis
    assert np.allclose(np.hypot(res.axes.eye_xyz[:, 0], res.axes.eye_xyz[:, 1]), r, atol=1e-6)
    # an explicit radius is kept as it is: it cannot fit, and the pre-check says so before the payout,
    # with the largest radius that fits - which the full run (payout, inverse kinematics) confirms
    fixed = job.replace(machine={"template": "lathe2", "setup": {"eye_radius_mm": 160.0}})
    with pytest.raises(InputError, match=r"it needs 1215\.4 mm, 15\.4 mm more than the axis has") as info:
        run_pipeline(fixed, None, upto="axes", line=res.line, mandrel=res.mandrel)
    assert info.value.location.field == "machine.setup.eye_radius_mm"
    r_fit = float(re.search(r"eye_radius_mm up to ([0-9.]+) mm fits", info.value.message).group(1))
    assert r_fit == pytest.approx(r, abs=0.1)     # the automatic choice, from the payout's own eye path
    ok = run_pipeline(fixed.replace(machine={"template": "lathe2", "setup": {"eye_radius_mm": r_fit}}), None,
                      upto="axes", previous=res)
    assert ok.placement.fits and ok.violations == [] and ok.machine.eye_radius == r_fit


def test_the_eye_slides_along_its_fibre_instead_of_turning_the_mandrel_back() -> None:
    """Eye-azimuth machine: an eye path whose azimuth goes back by 3 deg; after the slide the azimuth never
    goes back, every moved eye lies on its own fibre line (the laid line is unchanged), ahead of the contact."""
    from engine.machine_setup import monotone_eye_azimuth

    m = load_machine("lathe3")
    n = 200
    a = np.radians(np.concatenate([np.linspace(0, 40, 100), np.linspace(40, 37, 20), np.linspace(37, 80, 80)]))
    c = np.stack([50 * np.cos(a - 0.6), 50 * np.sin(a - 0.6), np.linspace(0, 100, n)], axis=1)
    # fibre from the contact, tangent to the cylinder, leaning forwards (+azimuth) and along z
    tang = np.stack([-np.sin(a - 0.6), np.cos(a - 0.6), np.full(n, 0.3)], axis=1)
    d = tang / np.linalg.norm(tang, axis=1)[:, None]
    eye = c + 60.0 * d
    phi0 = np.unwrap(np.arctan2(eye[:, 1], eye[:, 0]))
    assert np.diff(phi0).min() < -np.radians(0.1)            # the input turns back
    e2, shift = monotone_eye_azimuth(m, eye, d, c, 0.01)
    phi = np.unwrap(np.arctan2(e2[:, 1], e2[:, 0]))
    assert np.diff(phi).min() >= -np.radians(0.011)
    moved = shift != 0
    assert moved.any() and not moved[:100].any()
    rel = e2 - c
    assert np.allclose(np.linalg.norm(np.cross(rel, d), axis=1), 0.0, atol=1e-9)
    assert np.all(np.einsum("ij,ij->i", rel, d) > 0)
    # a fixed-radius machine (its eye slides to the radius in the kinematics) is left alone
    assert not monotone_eye_azimuth(load_machine("lathe2"), eye, d, c, 0.01)[1].any()


@pytest.fixture(scope="module")
def new_job_line():
    """The default new job's winding line and mandrel (cheap: no payout)."""
    from engine.pipeline import run_pipeline

    job = default_job().replace(machine={"template": "lathe2"})
    res = run_pipeline(job, None, upto="winding")
    return job, res


@pytest.mark.parametrize("template", ["lathe2", "lathe3", "lathe4", "gantry6"])
def test_carriage_need_from_the_line_against_the_inverse_kinematics(new_job_line, template) -> None:
    """The pre-check's carriage range (from the winding line alone) against the carriage column of the full
    run (payout law, inverse kinematics): equal on the fixed-radius lathe2, a lower bound on the others."""
    from engine.machine_setup import carriage_need
    from engine.pipeline import run_pipeline

    job, wres = new_job_line
    job = job.replace(machine={"template": template, "axes": {"X": {"min": -1e4, "max": 1e4}}})
    res = run_pipeline(job, None, upto="axes", line=wres.line, mandrel=wres.mandrel)
    k = res.machine.axis_index("carriage")
    ax = res.machine.axes[k]
    z = (np.asarray(res.axes.q[:, k]) - ax.offset) / ax.scale     # the eye's z along the mandrel, mm
    z_lo, z_hi, how = carriage_need(res.machine, wres.line)
    if template == "lathe2":
        assert how.startswith("the eye at radius 160")
        assert z_lo == pytest.approx(z.min(), abs=1e-6) and z_hi == pytest.approx(z.max(), abs=1e-6)
    else:
        assert z.min() <= z_lo + 1e-9 and z.max() >= z_hi - 1e-9
    assert carriage_need(load_machine("robot_cell"), wres.line) is None


def test_fixed_placement_is_refused_before_the_payout_and_the_range_it_names_fits(new_job_line, monkeypatch) -> None:
    import engine.payout
    from engine.pipeline import run_pipeline

    job, wres = new_job_line
    job = job.replace(machine={"template": "lathe2", "setup": {"eye_radius_mm": 120.0, "mandrel_z0_mm": 900.0}})
    with monkeypatch.context() as mp:
        mp.setattr(engine.payout, "payout_for_job", lambda *a, **k: pytest.fail("the payout ran"))
        with pytest.raises(InputError) as info:
            run_pipeline(job, None, upto="axes", line=wres.line, mandrel=wres.mandrel)
    msg = info.value.message
    assert info.value.location.field == "machine.setup.mandrel_z0_mm"
    m = re.search(r"would run ([0-9.-]+)\.\.([0-9.-]+) mm .*?, ([0-9.]+) mm above its maximum 1200; it fits with "
                  r"mandrel_z0_mm between ([0-9.-]+) and ([0-9.-]+)", msg)
    assert m, msg
    a, b, over, f0, f1 = (float(x) for x in m.groups())
    assert over == pytest.approx(b - 1200.0, abs=0.11)
    # the full run at both ends of the named range fits (within the 0.1 mm of the printed numbers)
    for z0 in (f0 + 0.1, f1 - 0.1, 0.5 * (f0 + f1)):
        j2 = job.replace(machine={"template": "lathe2", "setup": {"eye_radius_mm": 120.0, "mandrel_z0_mm": z0}})
        res = run_pipeline(j2, None, upto="axes", line=wres.line, mandrel=wres.mandrel)
        assert res.placement.mode == "fixed" and res.placement.fits and res.violations == [], z0
    # just outside it does not
    j3 = job.replace(machine={"template": "lathe2", "setup": {"eye_radius_mm": 120.0, "mandrel_z0_mm": f1 + 0.2}})
    with pytest.raises(InputError, match="above its maximum"):
        run_pipeline(j3, None, upto="axes", line=wres.line, mandrel=wres.mandrel)


def test_a_path_longer_than_any_eye_radius_allows_is_refused_up_front(new_job_line) -> None:
    from engine.pipeline import run_pipeline

    job, wres = new_job_line
    job = job.replace(machine={"template": "lathe2", "axes": {"X": {"max": 560.0}}})   # line spans ~ 535 mm
    with pytest.raises(InputError, match=r"axis X of machine lathe2 travels 560 mm .* even the smallest eye radius "
                                         r"105 mm .* no placement fits") as info:
        run_pipeline(job, None, upto="axes", line=wres.line, mandrel=wres.mandrel)
    assert info.value.location.field == "machine.template"


def test_laminate_post_mismatch_is_refused_before_any_layer(monkeypatch) -> None:
    """A post that cannot address the template's axes: refused before any layer is wound, naming what
    works; the post the robot cell can use (LinuxCNC with its linuxcnc_robot profile) is found without a
    controller (the joined program is rendered through the same choice as a single line)."""
    import engine.laminate as lam
    from engine.laminate import run_laminate

    text = """schema_version = 2
[mandrel]
kind = "pipe"
radius_mm = 50.0
length_mm = 200.0
[winding]
points_per_pass = 200
[machine]
template = "robot_cell"
[post]
post = "marlin"
[[layer]]
kind = "hoop"
"""
    monkeypatch.setattr(lam, "_wind_layer", lambda *a, **k: pytest.fail("a layer was wound"))
    with pytest.raises(InputError) as info:
        run_laminate(parse_job(text))
    assert "post marlin cannot write machine robot_cell" in info.value.message
    assert 'post linuxcnc with [post] controller = "linuxcnc_robot"' in info.value.message
    assert info.value.location.field == "post.post"


def test_head_body_radius_widens_the_eye_gaps() -> None:
    """The payout head's body (a sphere of head_radius_mm about the eye): its gap to the mandrel and the
    supports is the eye's minus that radius (closed form on a pipe: rho - R - h)."""
    pipe = Mandrel.pipe(50.0, 300.0)
    contact = np.array([[50.0, 0.0, 140.0], [50.0, 0.0, 150.0], [50.0, 0.0, 150.0]])
    eye = np.array([[58.0, 0.0, 150.0], [70.0, 0.0, 150.0], [120.0, 0.0, 150.0]])     # 8, 20, 70 mm off
    ap = AxisPath("lathe3", ("A", "X", "Y"), np.zeros((3, 3)), eye, np.zeros((3, 3)), contact, np.zeros(3))
    base = SetupSpec(clearance_mm=5.0)
    assert clearance_violations(ap, pipe, base) == []
    v = clearance_violations(ap, pipe, base.model_copy(update={"head_radius_mm": 10.0}))    # needs 15 mm
    assert [(x.index, x.count) for x in v] == [(0, 1)]
    assert v[0].value == pytest.approx(8.0, abs=0.03) and v[0].limit == 15.0
    v = clearance_violations(ap, pipe, base.model_copy(update={"head_radius_mm": 16.0}))    # needs 21 mm
    assert [(x.index, x.count) for x in v] == [(0, 2)]
    # and the supports: an eye 12 mm beyond the tailstock face (z = 300 + 100 + 150 + 12)
    far = np.array([[10.0, 0.0, 562.0]])
    ap2 = AxisPath("lathe3", ("A", "X", "Y"), np.zeros((1, 3)), far, np.zeros((1, 3)), far, np.zeros(1))
    assert not [x for x in clearance_violations(ap2, pipe, base) if "tailstock" in x.message]
    vt = [x for x in clearance_violations(ap2, pipe, base.model_copy(update={"head_radius_mm": 10.0}))
          if "eye and the tailstock" in x.message]
    assert vt and vt[0].value == pytest.approx(12.0) and vt[0].limit == 15.0


def _dense_capsule_min(mandrel_fn, a, u, length, step=0.02):
    """The independent reference: the distance at points every ``step`` mm along each segment."""
    t = np.linspace(0.0, length, int(length / step) + 1)
    out = np.empty(a.shape[0])
    for i in range(a.shape[0]):
        p = a[i] + t[:, None] * u[i]
        out[i] = mandrel_fn(p[:, 2], np.hypot(p[:, 0], p[:, 1])).min()
    return out


def test_capsule_distance_against_dense_sampling_of_its_axis() -> None:
    """Branch and bound on the head's axis segment (capsule_min_distance) against the distance sampled
    every 0.02 mm along it: equal within the 0.05 mm tolerance, for segments tilted every way around a
    cone (some ending inside it, some passing its end faces)."""
    from engine.machine_setup import capsule_min_distance, mandrel_distance_fn

    ves = Mandrel.cone(60.0, 90.0, 300.0)
    fn = mandrel_distance_fn(ves)
    rng = np.random.default_rng(7)
    n = 60
    phi = rng.uniform(0, 2 * np.pi, n)
    rr = rng.uniform(70.0, 160.0, n)
    a = np.stack([rr * np.cos(phi), rr * np.sin(phi), rng.uniform(-60.0, 360.0, n)], axis=1)
    u = rng.normal(size=(n, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    got = capsule_min_distance(fn, a, u, 120.0, np.inf)
    ref = _dense_capsule_min(fn, a, u, 120.0)
    assert np.abs(got - ref).max() <= 0.05 + 1e-9
    assert (got < fn(a[:, 2], np.hypot(a[:, 0], a[:, 1])) - 1.0).sum() >= 10     # the axis matters
    # with a needed gap, values below it are exact within the tolerance outside the body (inside it, deeper
    # than the k-d tree's bound, a depth below the surface), the rest stay above it
    need = 15.0
    g2 = capsule_min_distance(fn, a, u, 120.0, need)
    low = (ref < need - 0.05) & (ref > 0.0)
    assert low.sum() >= 5 and np.abs(g2[low] - ref[low]).max() <= 0.05 + 1e-9
    assert np.all(g2[ref <= 0.0] < 0.0) and np.all(g2[ref > need + 0.05] >= need - 0.05)


def test_range_max_of_a_polyline_against_brute_force() -> None:
    """The sparse-table range maximum of a piecewise-linear function (machine_setup._RangeMax) against the
    maximum of the function sampled at its vertices in range and at both ends: equal bit for bit, for
    ranges of every length (powers of two among them), ranges ending on vertices, outside the data and
    empty (lo > hi: -inf)."""
    from engine.machine_setup import _RangeMax

    rng = np.random.default_rng(11)
    x = np.cumsum(rng.uniform(0.0, 1.0, 257))
    x[40:44] = x[40]                                  # a repeated abscissa (a vertical step)
    y = rng.normal(size=x.size)
    rm = _RangeMax(x, y)
    lo = np.concatenate([rng.uniform(x[0] - 5.0, x[-1] + 5.0, 3000), x[:64], x[[0, 0, 5, 40]]])
    span = np.concatenate([rng.uniform(-1.0, 80.0, 3000), np.zeros(64), x[[0, 1, 45, 44]] - x[0]])
    hi = lo + span
    hi[3000:3064] = x[np.minimum(np.arange(64) + 2 ** (np.arange(64) % 8), x.size - 1)]   # spans of 2^k vertices
    got = rm(lo, hi)
    for k in range(lo.size):
        if lo[k] > hi[k]:
            assert got[k] == -np.inf
            continue
        inner = y[(x > lo[k]) & (x < hi[k])]
        ref = max(np.interp(lo[k], x, y), np.interp(hi[k], x, y), inner.max() if inner.size else -np.inf)
        assert got[k] == ref, (k, lo[k], hi[k])


def _random_segments(rng, n, r_lo, r_hi, z_lo, z_hi):
    phi = rng.uniform(0, 2 * np.pi, n)
    rr = rng.uniform(r_lo, r_hi, n)
    a = np.stack([rr * np.cos(phi), rr * np.sin(phi), rng.uniform(z_lo, z_hi, n)], axis=1)
    u = rng.normal(size=(n, 3))
    return a, u / np.linalg.norm(u, axis=1, keepdims=True)


@pytest.mark.parametrize("need", [-0.1, -2.0, 0.0, 4.0])
def test_radial_prune_drops_only_pieces_that_stay_above_the_need(need) -> None:
    """radial_prune (the piece's closest approach to the axis against the body's largest radius over its
    z range) is sound: every piece it drops, sampled every 0.01 mm, has every sampled distance >= need -
    on a vessel with domes and a cone, for segments from inside, through and around the bodies; and it
    does drop pieces (most of those that stay clear)."""
    from engine.machine_setup import mandrel_distance_fn, radial_prune

    rng = np.random.default_rng(5)
    for body in (Mandrel.vessel(80.0, 200.0, "hemisphere", pole_radii=20.0), Mandrel.cone(60.0, 90.0, 300.0)):
        fn = mandrel_distance_fn(body)
        a, u = _random_segments(rng, 400, 20.0, 150.0, body.z_min - 60.0, body.z_max + 60.0)
        prune = radial_prune(fn, a, u, need)
        i = np.repeat(np.arange(a.shape[0]), 4)
        t0 = rng.uniform(0.0, 150.0, i.size)
        t1 = t0 + rng.choice([0.05, 0.8, 6.0, 60.0], i.size)
        drop = prune(i, t0, t1)
        assert 0.2 * i.size < drop.sum() < i.size
        for k in np.flatnonzero(drop):
            t = np.linspace(t0[k], t1[k], max(int((t1[k] - t0[k]) / 0.01), 2) + 1)
            p = a[i[k]] + t[:, None] * u[i[k]]
            d = fn(p[:, 2], np.hypot(p[:, 0], p[:, 1]), abs(need) + 5.0)
            assert d.min() >= need, (k, d.min())


def test_capsule_search_with_radial_prune_keeps_every_value_below_the_need() -> None:
    """capsule_min_distance with radial_prune: every answer below ``need`` is the same number as without
    it (the same answers below need, for segments ending deep inside a vessel, passing through it and
    staying clear), with far fewer distance evaluations when the segments stay clear of the body."""
    from engine.machine_setup import capsule_min_distance, mandrel_distance_fn, radial_prune

    ves = Mandrel.vessel(80.0, 200.0, "hemisphere", pole_radii=20.0)
    fn = mandrel_distance_fn(ves)
    rng = np.random.default_rng(3)
    a, u = _random_segments(rng, 300, 40.0, 160.0, -80.0, 280.0)
    calls: list[int] = []

    def counted(z, rho, upto=None):  # noqa: ANN001, ANN202
        calls.append(np.size(z))
        return fn(z, rho, upto)

    for need in (-0.1, -3.0, 2.0):
        calls.clear()
        ref = capsule_min_distance(counted, a, u, 120.0, need)
        n_ref = sum(calls)
        calls.clear()
        got = capsule_min_distance(counted, a, u, 120.0, need, prune=radial_prune(fn, a, u, need))
        below = ref < need
        assert 20 <= below.sum() < a.shape[0]
        assert np.array_equal(got < need, below) and np.array_equal(got[below], ref[below])
        assert np.all(got[~below] >= need)
        assert sum(calls) < n_ref
    # fibres tangent to a cylinder's surface from outside (the pipe's transitions): all pruned at once
    pipe = Mandrel.pipe(50.0, 300.0)
    fp = mandrel_distance_fn(pipe)
    phi = np.linspace(0.0, 2 * np.pi, 50, endpoint=False)
    anchor = np.stack([50.0 * np.cos(phi), 50.0 * np.sin(phi), np.linspace(20.0, 280.0, 50)], axis=1)
    tang = np.stack([-np.sin(phi), np.cos(phi), 0.3 * np.ones_like(phi)], axis=1)
    tang /= np.linalg.norm(tang, axis=1, keepdims=True)
    eye = anchor + 80.0 * tang
    along = -tang

    def counted_pipe(z, rho, upto=None):  # noqa: ANN001, ANN202
        calls.append(np.size(z))
        return fp(z, rho, upto)

    calls.clear()
    ref = capsule_min_distance(counted_pipe, eye, along, 80.0, -0.1)
    n_ref = sum(calls)
    calls.clear()
    got = capsule_min_distance(counted_pipe, eye, along, 80.0, -0.1, prune=radial_prune(fp, eye, along, -0.1))
    assert ref.min() >= -0.1 and got.min() >= -0.1
    assert sum(calls) == 2 * eye.shape[0] and n_ref > 20 * eye.shape[0]


def test_head_axis_of_a_lathe_is_radial_and_the_capsule_is_checked(monkeypatch) -> None:
    """On a fixed-radius lathe the head's roll axis is machine x, away from the mandrel: in the mandrel
    frame the eye's radial unit vector (closed form).  With head_length_mm the head is a capsule: a head
    whose axis leans over the mandrel violates where the sphere about the eye does not, by the amount
    dense sampling of its axis gives."""
    import engine.machine_setup as ms

    m = load_machine("lathe3")
    p = demo_eye_path("helix", n=400, circuits=1)
    ap = inverse_kinematics(m, p.eye_xyz, p.fibre_dir, p.contact_xyz)
    u = ms.head_axis(m, ap)
    radial = ap.eye_xyz * np.array([1.0, 1.0, 0.0])
    radial /= np.linalg.norm(radial, axis=1, keepdims=True)
    assert np.abs(u - radial).max() < 1e-12
    pipe = Mandrel.pipe(50.0, 300.0)
    eye = np.array([[75.0, 0.0, 150.0], [0.0, 90.0, 20.0]])
    ap2 = AxisPath("lathe3", ("A", "X", "Y"), np.zeros((2, 3)), eye, np.zeros((2, 3)), eye.copy(), np.zeros(2))
    setup = SetupSpec(clearance_mm=5.0, head_radius_mm=4.0, shaft_length_mm=0.0)
    assert clearance_violations(ap2, pipe, setup, machine=m) == []        # sphere: 25 and 40 mm > 9 mm
    lean = np.array([[-0.6, 0.0, 0.8], [0.0, 0.6, 0.8]])                    # over the pipe, away from it
    monkeypatch.setattr(ms, "head_axis", lambda machine, axes: lean)
    v = clearance_violations(ap2, pipe, setup.model_copy(update={"head_length_mm": 60.0}), machine=m)
    hit = [x for x in v if "head and the mandrel" in x.message]
    ref = _dense_capsule_min(ms.mandrel_distance_fn(pipe), eye, lean, 60.0)
    assert ref[0] < 9.0 < ref[1] and [(x.index, x.count) for x in hit] == [(0, 1)]
    assert hit[0].value == pytest.approx(ref[0], abs=0.05) and hit[0].limit == 9.0


def test_parallel_law_on_a_cross_feed_machine_is_prechecked_by_its_radius(new_job_line, monkeypatch) -> None:
    """With the 'parallel' payout law the eye sits on the tangent ray at the law's radius on a cross-feed
    machine too: the pre-check's carriage range is that ray's (less a margin for the payout grid's
    interpolation), not the winding line's (about half of it here). Against the full run (payout, inverse
    kinematics) on a long axis: the ray's range equals the eye's within 0.1 mm; a travel between the
    line's range and the run's is refused before the payout with the sure lower bound; a travel that holds
    the run's range runs and fits."""
    import engine.payout
    from engine.machine_setup import carriage_need
    from engine.pipeline import run_pipeline

    job, wres = new_job_line
    job = job.replace(payout={**job.payout.model_dump(), "law": "parallel"})
    long = job.replace(machine={"template": "lathe3", "axes": {"X": {"min": -1e4, "max": 1e4}}})
    res = run_pipeline(long, None, upto="axes", line=wres.line, mandrel=wres.mandrel)
    k = res.machine.axis_index("carriage")
    ax = res.machine.axes[k]
    z = (np.asarray(res.axes.q[:, k]) - ax.offset) / ax.scale
    r0 = float(wres.mandrel.r_max) + float(job.payout.clearance_mm)
    lo, hi, how = carriage_need(res.machine, wres.line, law_radius_mm=r0)
    assert "parallel law's radius" in how
    assert lo == pytest.approx(z.min(), abs=0.1) and hi == pytest.approx(z.max(), abs=0.1)
    c_lo, c_hi, _ = carriage_need(res.machine, wres.line)
    span = float(z.max() - z.min())
    assert c_hi - c_lo < 0.6 * span                              # the old bound: the line's range
    short = job.replace(machine={"template": "lathe3", "axes": {"X": {"min": 0.0, "max": span - 30.0}}})
    with monkeypatch.context() as mp:
        mp.setattr(engine.payout, "payout_for_job", lambda *a, **k: pytest.fail("the payout ran"))
        with pytest.raises(InputError) as info:
            run_pipeline(short, None, upto="axes", line=wres.line, mandrel=wres.mandrel)
    msg = info.value.message
    need = float(re.search(r"it needs at least ([0-9.]+) mm", msg).group(1))
    assert span - 0.02 * span - 0.1 <= need <= span and "parallel law's radius" in msg
    fits = job.replace(machine={"template": "lathe3", "axes": {"X": {"min": 0.0, "max": span + 2.0}}})
    ok = run_pipeline(fits, None, upto="axes", line=wres.line, mandrel=wres.mandrel)
    assert ok.placement.fits and not [v for v in ok.violations if v.kind == "position"]
