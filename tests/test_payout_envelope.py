"""One envelope (issue 17 point 4): min-range is the minimum over the very set the feasibility report checks."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, Phase, example, given, settings
from hypothesis import strategies as st

from engine.errors import InfeasibleError
from engine.job import PayoutSpec, WindingSpec, build_mandrel, load_job
from engine.mandrel import Mandrel
from engine.payout import ContactLine, _Contour, geometric_law, min_range_law, payout_law
from engine.winding import winding_line, winding_line_for_job

ROOT = Path(__file__).resolve().parents[1]
GEOMETRIC = ("parallel", "equidistant", "equal-tangent")


def _compare(line: ContactLine, mandrel: Mandrel, spec: PayoutSpec) -> list[tuple[str, float, float]]:
    try:
        mr = min_range_law(line, mandrel, spec)
    except InfeasibleError:  # then no geometric law may pass the same checks either
        for law in GEOMETRIC:
            try:
                assert not geometric_law(line, mandrel, law, spec).feasible, law
            except InfeasibleError:
                pass
        return []
    assert mr.feasible, mr.report["constraints"]
    out = []
    for law in GEOMETRIC:
        try:
            g = geometric_law(line, mandrel, law, spec)
        except InfeasibleError:
            continue
        if g.feasible:  # judged by the same report (same envelope, same checks)
            assert mr.report["u_range"] <= g.report["u_range"] + 1e-6 * max(1.0, g.report["u_range"]), law
            out.append((law, mr.report["u_range"], g.report["u_range"]))
    return out


@pytest.mark.parametrize("name", ["pipe", "pressure_vessel", "bottle"])
def test_min_range_never_wider_than_a_feasible_geometric_law_on_the_examples(name: str) -> None:
    path = ROOT / "resources" / "examples" / f"{name}.toml"
    job = load_job(path)
    job = job.replace(winding=job.winding.model_copy(update={"points_per_pass": 600}),
                      payout=job.payout.model_copy(update={"grid_points": 300}))
    mandrel = build_mandrel(job, path)
    line = ContactLine.from_line(winding_line_for_job(job, path).one_circuit)
    pairs = _compare(line, mandrel, job.payout)
    if name == "pipe":  # the issue's case: equidistant is feasible (3.578 at full density), min-range was 3.650
        assert any(law == "equidistant" for law, _, _ in pairs)
        assert all(mr < g for _, mr, g in pairs)


def test_pipe_issue_numbers_at_the_default_grid() -> None:
    """The issue's 3.578 (equidistant) was measured on the 1 000-point grid: interpolated between grid
    points that law cut 12 mm into the clearance at the pins.  Every law is now checked at every line
    point, refined where it fails, and equals the law solved at every line point."""
    path = ROOT / "resources" / "examples" / "pipe.toml"
    job = load_job(path)
    mandrel = build_mandrel(job, path)
    line = ContactLine.from_line(winding_line_for_job(job, path).one_circuit)
    eq = payout_law(line, mandrel, job.payout, law="equidistant")
    mr = payout_law(line, mandrel, job.payout, law="min-range")
    eq_all = payout_law(line, mandrel, job.payout, law="equidistant", grid_points=100_000)
    mr_all = payout_law(line, mandrel, job.payout, law="min-range", grid_points=100_000)
    assert eq_all.report["points"] == mr_all.report["points"] == eq.report["line"]["points"] > 4000
    assert eq.feasible and eq_all.feasible
    assert eq.report["line"]["u_range"] == pytest.approx(eq_all.report["u_range"], abs=1e-6)
    assert mr.feasible and mr.report["line"]["u_range"] == pytest.approx(mr_all.report["u_range"], abs=1e-3)
    assert mr.report["line"]["u_range"] < eq.report["line"]["u_range"]
    assert mr.report["points"] < 0.3 * mr_all.report["points"]  # refined only where needed
    sol = mr.report["solver"]
    assert mr.report["u_range"] <= sol["range_lp"]["u_range"] + 1e-6


def test_interpolated_eye_path_is_checked_at_every_line_point() -> None:
    """Without refinement (one round) the pipe's min-range path, interpolated at the line points the program
    uses, breaks the clearance and pulls negatively at the pins: the report says so, located."""
    import engine.payout as payout

    path = ROOT / "resources" / "examples" / "pipe.toml"
    job = load_job(path)
    mandrel = build_mandrel(job, path)
    line = ContactLine.from_line(winding_line_for_job(job, path).one_circuit)
    rounds = payout._REFINE_ROUNDS
    payout._REFINE_ROUNDS = 0
    try:
        mr = payout_law(line, mandrel, job.payout, law="min-range")
    finally:
        payout._REFINE_ROUNDS = rounds
    assert not mr.feasible
    cons = mr.report["constraints"]
    assert cons["clearance"]["ok"]  # on the grid
    bad = cons["clearance (between grid points)"]
    assert bad["min_slack"] < -1.0 and bad["violated"]
    assert not mr.report["line"]["constraints"]["u_floor"]["ok"]
    # the check is independent of the grid: the eye's distance to the body at every line point
    geo = payout._grid(line, "s", None)
    lf = np.interp(geo.x, mr.x, mr.l)
    Z, R, _, _ = geo.eye(lf)
    d = payout._Contour(mandrel).distance(Z, R)
    assert float(d.min()) - job.payout.clearance_mm == pytest.approx(bad["min_slack"], abs=1e-9)


@settings(max_examples=5, deadline=None, suppress_health_check=[HealthCheck.too_slow],
          phases=[Phase.explicit, Phase.reuse, Phase.generate])
@given(radius=st.floats(40.0, 120.0), length=st.floats(200.0, 800.0), angle=st.floats(25.0, 70.0),
       clearance=st.floats(5.0, 40.0), k=st.sampled_from([0, 1]))
# found by the explore profile: the (15) QP's cuts, exact at the band's answer, left no interior where that
# answer is 1e-7 inside the exact check; min-range was refused although equidistant passes the checks
@example(radius=106.98552246066244, length=422.3473174833926, angle=43.46558812556574, clearance=6.0, k=1)
def test_random_pipes(radius: float, length: float, angle: float, clearance: float, k: int) -> None:
    m = Mandrel.pipe(radius, length)
    wl = winding_line(m, 8.0, 0.2, WindingSpec(mode="geodesic", angles=[{"z_mm": length / 2, "angle_deg": angle}],
                                              dwell_deg=(180.0, 180.0), points_per_pass=300))
    spec = PayoutSpec(grid_points=200, clearance_mm=clearance, impregnation_k=k, free_length_max_mm=600.0)
    _compare(ContactLine.from_line(wl.one_circuit), m, spec)


@settings(max_examples=4, deadline=None, suppress_health_check=[HealthCheck.too_slow],
          phases=[Phase.explicit, Phase.reuse, Phase.generate])
@given(radius=st.floats(60.0, 120.0), cyl=st.floats(100.0, 400.0), pole=st.floats(0.2, 0.4),
       dome=st.sampled_from(["hemisphere", "ellipse", "isotensoid"]))
def test_random_vessels(radius: float, cyl: float, pole: float, dome: str) -> None:
    m = Mandrel.vessel(radius, cyl, dome, pole * radius)
    wl = winding_line(m, 8.0, 0.3, WindingSpec(points_per_pass=300))
    _compare(ContactLine.from_line(wl.one_circuit), m, PayoutSpec(grid_points=200))


def test_clearance_counts_the_end_faces() -> None:
    """Beyond an end the body is its end face: the distance is to the face, not to the last profile point."""
    c = _Contour(Mandrel.pipe(75.0, 1000.0))
    d = c.distance(np.array([-5.0, -5.0, 500.0, 1010.0, 500.0, -20.0]), np.array([30.0, 80.0, 100.0, 70.0, 50.0, 0.0]))
    assert d == pytest.approx([5.0, np.hypot(5.0, 5.0), 25.0, 10.0, -25.0, 20.0], abs=1e-9)


@pytest.mark.parametrize("name", ["pipe", "pressure_vessel", "bottle"])
def test_far_distances_are_the_full_search_below_far_plus_one(name: str) -> None:
    """distance(far=f) ends the k-d tree's search at f + 1 + the longest boundary segment: every value
    below f + 1, and every value inside the body, is the full search's bit for bit; the others are +inf
    where the full search gives at least f + 1 (what the envelope and the line check read is unchanged)."""
    path = ROOT / "resources" / "examples" / f"{name}.toml"
    c = _Contour(build_mandrel(load_job(path), path))
    rng = np.random.default_rng(3)
    n = 200_000
    Z = rng.uniform(c.z_min - 40.0, c.z_max + 40.0, n)
    R = rng.uniform(0.0, c.r_max + 40.0, n)
    # and points just around the boundary and its face vertices (near-ties of the nearest vertex)
    k = rng.integers(0, c.bz.size, 20_000)
    Z = np.concatenate([Z, c.bz[k] + rng.normal(0, 0.5, k.size), np.repeat(c.bz[:50], 3)])
    R = np.concatenate([R, c.br[k] + rng.normal(0, 0.5, k.size), np.repeat(c.br[:50], 3) + 0.25])
    full = c.distance(Z, R)
    cuts = 0
    for f in (0.01, 5.0, 20.0):
        box = (R < c.r_max + f) & (Z > c.z_min - f) & (Z < c.z_max + f)
        ref = np.where(box, full, np.inf)        # the box alone (the search to the end inside it)
        got = c.distance(Z, R, far=f)
        keep = (ref < f + 1.0) | (ref < 0)
        assert np.array_equal(got[keep], ref[keep])            # bit for bit
        cut = ~keep & np.isfinite(ref) & np.isinf(got)
        assert (ref[cut] >= f + 1.0).all()
        cuts += int(cut.sum())
        assert np.array_equal(got[~keep & ~cut], ref[~keep & ~cut])
        assert np.array_equal(np.minimum(got, f + 1.0), np.minimum(ref, f + 1.0))   # what the checks read
    assert cuts > 100   # (the search was ended early: near the ends of a pipe, over the domes of a vessel)
