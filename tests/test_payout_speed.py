"""Issue 16: the payout's refinement rounds reuse work without changing a number."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from engine import payout
from engine.job import build_mandrel, load_job
from engine.payout import ContactLine
from engine.winding import winding_line_for_job

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("name", ["pressure_vessel", "pipe"])
def test_envelope_cache_equals_the_whole_envelope(name: str) -> None:
    """A refined grid's envelope, taken from the earlier grid plus the new points, is bit for bit the
    envelope computed on the whole refined grid (each point's envelope depends on that point alone)."""
    path = ROOT / "resources" / "examples" / f"{name}.toml"
    job = load_job(path)
    job = job.replace(winding=job.winding.model_copy(update={"points_per_pass": 600}))
    spec = job.payout
    line = ContactLine.from_line(winding_line_for_job(job, path).one_circuit)
    contour = payout._Contour(build_mandrel(job, path))
    cache = payout._EnvCache()
    geo1 = payout._grid(line, spec.parameter, 200)
    env1 = cache.envelope(geo1, contour, spec.clearance_mm, spec.free_length_max_mm, None, None)
    full1 = payout.envelope(geo1, contour, spec.clearance_mm, spec.free_length_max_mm)
    assert np.array_equal(env1.l_min, full1.l_min) and np.array_equal(env1.l_max, full1.l_max)
    # two refinement rounds: line points not on the first grid join it (as _refined adds them)
    rng = np.random.default_rng(7)
    extra = np.unique(rng.choice(line.z.size, 60, replace=False))
    for more in (extra[:30], extra):
        geo = payout._grid(line, spec.parameter, 200, more)
        assert geo.n > geo1.n
        env = cache.envelope(geo, contour, spec.clearance_mm, spec.free_length_max_mm, None, None)
        full = payout.envelope(geo, contour, spec.clearance_mm, spec.free_length_max_mm)
        assert np.array_equal(env.l_min, full.l_min)
        assert np.array_equal(env.l_max, full.l_max)
        assert env.workspace == full.workspace


def _coarse_example(name: str) -> tuple:
    """An example at 600 points per pass and a 300-point payout grid: (job, mandrel, one circuit's line)."""
    path = ROOT / "resources" / "examples" / f"{name}.toml"
    job = load_job(path)
    job = job.replace(winding=job.winding.model_copy(update={"points_per_pass": 600}),
                      payout=job.payout.model_copy(update={"grid_points": 300}))
    return job, build_mandrel(job, path), ContactLine.from_line(winding_line_for_job(job, path).one_circuit)


def test_refined_min_range_law_unchanged_by_the_cache(monkeypatch: pytest.MonkeyPatch) -> None:
    """The whole refined min-range law with and without the envelope cache: the same law bit for bit."""
    job, mandrel, line = _coarse_example("pipe")
    a = payout.min_range_law(line, mandrel, job.payout)
    assert a.report["line"]["refinements"] >= 1  # the cache was used

    def uncached(self, geo, contour, clearance, l_cap, workspace, state):  # noqa: ANN001, ANN202
        return payout.envelope(geo, contour, clearance, l_cap, workspace, state)

    monkeypatch.setattr(payout._EnvCache, "envelope", uncached)
    b = payout.min_range_law(line, mandrel, job.payout)
    assert np.array_equal(a.l, b.l) and np.array_equal(a.x, b.x)
    assert a.report["line"]["u_range"] == b.report["line"]["u_range"]


@pytest.mark.parametrize("name", ["pipe", "pressure_vessel"])
def test_bisection_skipping_certain_failures_is_bit_for_bit_bisection(name: str, monkeypatch: pytest.MonkeyPatch
                                                                       ) -> None:
    """(13) and (14) with the peeks (midpoints certainly infeasible are not solved) against plain bisection
    (every midpoint solved): the same bounds and the same law bit for bit, with fewer solves."""
    job, mandrel, line = _coarse_example(name)
    a = payout.min_range_law(line, mandrel, job.payout, refine=False)
    monkeypatch.setattr(payout._WarmProbe, "peek", lambda self, x: None)  # nothing is ever certain
    b = payout.min_range_law(line, mandrel, job.payout, refine=False)
    sa, sb = a.report["solver"], b.report["solver"]
    assert sa["fallback"] == sb["fallback"] == []
    assert sa["u_min_13"] == sb["u_min_13"] and sa["u_max_14"] == sb["u_max_14"]
    assert np.array_equal(a.l, b.l)
    # the iterations count every solve, peeks included: at most 6 peeks per bisection are wasted
    na, nb = sa["iterations"]["13"] + sa["iterations"]["14"], sb["iterations"]["13"] + sb["iterations"]["14"]
    assert na <= nb + 12
    if name == "pipe":
        assert na < nb - 10, (na, nb)


def test_tube_margin_closes_at_the_optimum() -> None:
    """The margin the peeks extrapolate is positive on feasible bounds and about 0 at the (13) optimum."""
    job, mandrel, line = _coarse_example("pipe")
    eye = payout.min_range_law(line, mandrel, job.payout, refine=False)
    t13 = eye.report["solver"]["u_min_13"]
    geo, env, _ = payout._prepare(line, mandrel, job.payout, job.payout.parameter, 300, None, None)
    tube = payout._Tube(payout._Problem(geo, env, job.payout.impregnation_k))
    margins = []
    with np.errstate(divide="ignore", invalid="ignore"):  # as the stages run it (payout._quiet_fp)
        for t in (t13 - 1e-2, t13 - 1e-4, t13 - 1e-6, t13):
            assert tube.solve(t, None) is not None
            margins.append(tube.margin())
        assert tube.solve(t13 + 1e-6, None) is None
    assert all(m1 > m2 for m1, m2 in zip(margins, margins[1:], strict=False))
    assert margins[-1] < 1e-6 * margins[0]


def test_build_equals_the_broadcast_formula() -> None:
    """The eye path's contact points, fibre directions and eye points, computed column by column, equal the
    (N, 3) broadcast formula a·e_ρ + b·k + c·e_v (normalised) bit for bit."""
    rng = np.random.default_rng(3)
    line = payout.reference_vessel_circuit(n=800)
    geo = payout._grid(ContactLine.from_line(line), "s", None)
    l = rng.uniform(0.0, 60.0, geo.n)
    eye = payout._build(geo, l, 1, "s", "given")
    L = geo.line
    cv, sv = np.cos(L.v), np.sin(L.v)
    contact = np.column_stack([L.r * cv, L.r * sv, L.z])
    e_rho = np.column_stack([cv, sv, np.zeros_like(cv)])
    e_v = np.column_stack([-sv, cv, np.zeros_like(cv)])
    kk = np.array([0.0, 0.0, 1.0])
    tau = geo.a[:, None] * e_rho + geo.b[:, None] * kk[None, :] + geo.c[:, None] * e_v
    tau /= np.linalg.norm(tau, axis=1)[:, None]
    assert np.array_equal(eye.contact_xyz, contact)
    assert np.array_equal(eye.fibre_dir, tau)
    assert np.array_equal(eye.eye_xyz, contact + l[:, None] * tau)
    # and an independent check: τ is the unit tangent, the eye is l along it from the contact point
    assert np.allclose(np.linalg.norm(eye.fibre_dir, axis=1), 1.0, atol=1e-14)
    assert np.allclose(np.linalg.norm(eye.eye_xyz - eye.contact_xyz, axis=1), l, atol=1e-9)


def _linprog_reference(c, A_ub, b_ub, A_eq, b_eq, bounds):  # noqa: ANN001, ANN202
    from scipy.optimize import linprog

    return linprog(c, A_ub=A_ub, b_ub=b_ub, A_eq=A_eq, b_eq=b_eq, bounds=bounds, method="highs",
                   options=dict(payout._LP_OPTIONS))


def _same_lp_answer(ref, got) -> bool:  # noqa: ANN001
    if ref.status != got.status:
        return False
    if ref.x is None or got.x is None:
        return ref.x is None and got.x is None
    return bool(np.array_equal(ref.x, got.x))


def test_direct_highs_lp_is_linprog_bit_for_bit(monkeypatch: pytest.MonkeyPatch) -> None:
    """The narrowest-band LP through SciPy's HiGHS called directly (no ``scipy.optimize`` import) against
    ``scipy.optimize.linprog`` on the same input: the same status and the same x bit for bit - on the
    example's own LPs (every cutting-plane round) and on random sparse LPs, infeasible and unbounded ones
    included."""
    import scipy.sparse as sp

    core = payout._highs_core()
    if core is None:
        pytest.skip("this SciPy has no scipy.optimize._highspy._core (linprog is used as before)")
    lps: list[tuple] = []
    direct = payout._linprog

    def record(*args):  # noqa: ANN002, ANN202
        lps.append(args)
        return direct(*args)

    monkeypatch.setattr(payout, "_linprog", record)
    job, mandrel, line = _coarse_example("pipe")
    payout.min_range_law(line, mandrel, job.payout)
    assert len(lps) >= 2
    for args in lps:   # every round from scratch (the cutting-plane loop's later rounds start warm)
        assert _same_lp_answer(_linprog_reference(*args[:6]), payout._linprog_highs_direct(core, *args[:6]))
    rng = np.random.default_rng(5)
    statuses = set()
    for k in range(120):
        n, m = int(rng.integers(2, 25)), int(rng.integers(1, 30))
        A = sp.random(m, n, density=0.4, random_state=k, format="csr")
        A_eq = sp.csr_matrix(rng.normal(size=(1, n)))
        b = rng.normal(size=m) * (3.0 if k % 3 else 0.1)
        free_lo, free_hi = rng.random(n) < 0.3, rng.random(n) < 0.3
        bounds = np.column_stack([np.where(free_lo, -np.inf, -5 * rng.random(n)),
                                  np.where(free_hi, np.inf, 5 * rng.random(n))])
        args = (rng.normal(size=n), A, b, A_eq, rng.normal(size=1), bounds)
        ref = _linprog_reference(*args)
        statuses.add(ref.status)
        assert _same_lp_answer(ref, payout._linprog_highs_direct(core, *args)), k
    assert {0, 2, 3} <= statuses  # optimal, infeasible and unbounded problems were compared


def test_highs_core_while_another_thread_imports_scipy() -> None:
    """The direct HiGHS (loaded from its file under its own module lock, engine._lightimport) and a thread
    importing scipy.optimize at the same time, at several offsets: neither hangs (the extension loaded
    under the interpreter-wide import lock did, in 5 of 6 runs), the extension is loaded once, and
    scipy.optimize works with it."""
    code = (
        "import threading, time, sys\n"
        "import numpy as np\n"
        "import engine.payout as payout\n"
        "t = threading.Thread(target=__import__, args=('scipy.optimize',))\n"
        "t.start(); time.sleep(float(sys.argv[1]))\n"
        "core = payout._highs_core()\n"
        "t.join(30)\n"
        "assert not t.is_alive(), 'hung'\n"
        "assert core is None or core is sys.modules['scipy.optimize._highspy._core']\n"
        "from scipy.optimize import linprog\n"
        "r = linprog([1.0, 1.0], A_ub=[[-1.0, -2.0]], b_ub=[-2.0], bounds=[(0, None)] * 2, method='highs')\n"
        "assert r.status == 0 and abs(r.fun - 1.0) < 1e-9, r\n"
        "print('ok')\n"
    )
    import subprocess
    import sys

    root = Path(__file__).resolve().parents[1]
    for delay in ("0", "0.001", "0.003", "0.01", "0.03", "0.08"):
        out = subprocess.run([sys.executable, "-c", code, delay], capture_output=True, text=True, timeout=60,
                             cwd=root, env={**os.environ, "PYTHONPATH": str(root)})
        assert out.returncode == 0 and out.stdout.strip() == "ok", (delay, out.stderr)



def test_closed_form_inverse_outside_the_quiet_stages_warns_nothing() -> None:
    """_Geo.l_of_mu is called outside the (13)/(14) stages too (the LP/QP stages, the final law): its
    0/0 and x/0 branches (b = 0) are discarded without a floating-point warning."""
    import warnings

    job, mandrel, line = _coarse_example("pipe")
    geo, _env, _ = payout._prepare(line, mandrel, job.payout, job.payout.parameter, 300, None, None)
    flat = payout._Geo(geo.line, geo.x, geo.a, np.zeros_like(geo.b), geo.c, geo.index)
    mu = np.abs(geo.line.r) + 50.0
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        l = flat.l_of_mu(mu, 1)
    assert l.shape == mu.shape


@pytest.mark.parametrize("name", ["pipe", "pressure_vessel"])
@pytest.mark.parametrize("k", [0, 1])
def test_tube_g_is_its_reference_bit_for_bit(name: str, k: int) -> None:
    """_Tube.g (μ-free products made once, unused np.where branches skipped) against its plain reference
    g_reference, bit for bit, with every branch taken: μ on and between the envelopes, far below (l(μ) with
    B <= 0), eye azimuths behind the next point (φ <= 0) and beyond its θ (no l keeps the eye from turning
    back: inf) on random points; on index subsets; with and without impregnation (k = 0: μ = l)."""
    job, mandrel, line = _coarse_example(name)
    geo, env, _ = payout._prepare(line, mandrel, job.payout, job.payout.parameter, 300, None, None)
    tube = payout._Tube(payout._Problem(geo, env, k))
    lo, hi = tube.lo[:-1], tube.hi[:-1]
    rng = np.random.default_rng(11)
    span = np.where(np.isfinite(hi - lo), hi - lo, 100.0)
    cases = [lo, np.where(np.isfinite(hi), hi, lo + 50.0), lo + rng.uniform(0, 1, lo.size) * span,
             lo - rng.uniform(0, 5e3, lo.size)]
    some = rng.uniform(size=lo.size) < 0.2
    theta, vt = tube.theta_t.copy(), tube.vt.copy()
    hit = {"neg_B": False, "back": False, "inf": False}
    with np.errstate(divide="ignore", invalid="ignore"):  # as the stages run it (payout._quiet_fp)
        for variant in ("as is", "theta", "behind"):
            tube.theta_t = np.where(some, -1.0, theta) if variant == "theta" else theta
            tube.vt = np.where(some, vt + 3.0, vt) if variant == "behind" else vt
            tube.geometry_changed()  # into the compiled steps' table (engine.payout_jit), where they run
            for mu in cases:
                for idx in (slice(None), np.flatnonzero(rng.uniform(size=lo.size) < 0.3)):
                    m = mu if isinstance(idx, slice) else mu[idx]
                    got, ref = tube.g(m, idx), tube.g_reference(m, idx)
                    assert got.dtype == ref.dtype and np.array_equal(got, ref, equal_nan=True)
                if tube.k:
                    hit["neg_B"] |= bool((mu + tube.rf * tube.af <= 0).any())
                g = tube.g(mu)
                hit["inf"] |= bool(np.isinf(g).any())
                hit["back"] |= variant == "behind" and bool((g[some] == tube.g_reference(mu)[some]).all())
    assert hit["inf"] and hit["back"], hit
    assert hit["neg_B"] or not tube.k, hit


def test_basis_for_the_next_round_keeps_rows_by_name() -> None:
    """A cutting-plane round's basis for the next one: kept rows keep their status by name, added rows are
    basic (their slack), and a basis that would not have one basic variable per row is not offered; on a
    refined grid (other columns) kept columns and rows keep theirs, new ones are basic, as an alien basis."""
    ck = (("mu", 0), "t", "T")
    b = payout._Basis(np.array([1, 0, 2], dtype=np.int8), np.array([1, 0, 1, 1], dtype=np.int8),
                      (("up", 0), ("down", 0), ("no_sag", 4), "cyclic"), ck)
    cols, rows, alien = b.warm_for(ck, (("up", 0), ("down", 0), ("no_sag", 4), "cyclic"))
    assert rows.tolist() == [1, 0, 1, 1] and cols.tolist() == [1, 0, 2] and not alien
    got = b.warm_for(ck, (("up", 0), ("down", 0), ("no_sag", 2), ("no_sag", 4), ("no_reverse_rotation", 0),
                          "cyclic"))
    assert got is not None and got[1].tolist() == [1, 0, 1, 1, 1, 1] and not got[2]
    assert b.warm_for(ck, (("up", 0), ("no_sag", 4), "cyclic")) is None     # a nonbasic row dropped: one too many
    got = b.warm_for(ck, (("down", 0), ("no_sag", 4), "cyclic"))            # a basic row dropped: one per row
    assert got is not None and got[1].tolist() == [0, 1, 1]
    fine = (("mu", 0), ("mu", 3), "t", "T")
    cols, rows, alien = b.warm_for(fine, (("up", 0), ("up", 3), ("down", 0), ("down", 3), "cyclic"))
    assert alien and cols.tolist() == [1, 1, 0, 2] and rows.tolist() == [1, 1, 0, 1, 1]


@pytest.mark.parametrize("name", ["pipe", "pressure_vessel", "bottle"])
def test_warm_started_narrowest_band_is_as_good_as_from_scratch(name: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """The narrowest-band LP's cutting-plane rounds start from the last round's basis (a refined grid's first
    round from the coarser grid's last).  The LP's optimum is degenerate (many μ give the narrowest band), so
    the vertex may differ in the last bits from the rounds solved from scratch; the answer is as good: the
    same band width (1e-9 relative, or narrower), the (15) jerk in it no larger, every exact constraint held
    (the report's check), and far fewer simplex iterations."""
    core = payout._highs_core()
    if core is None:
        pytest.skip("this SciPy has no scipy.optimize._highspy._core (linprog is used, from scratch)")
    job, mandrel, line = _coarse_example(name)
    iters: dict[str, list[tuple[bool, int]]] = {"warm": [], "cold": []}
    direct = payout._linprog_highs_direct
    mode = ["warm"]

    def count(h, *args):  # noqa: ANN001, ANN002, ANN202
        res = direct(h, *args)
        iters[mode[0]].append((len(args) > 6 and args[6] is not None, res.iterations))
        return res

    monkeypatch.setattr(payout, "_linprog_highs_direct", count)
    warm = payout.min_range_law(line, mandrel, job.payout)
    mode[0] = "cold"
    monkeypatch.setattr(payout._Basis, "warm_for", lambda self, col_keys, keys: None)
    cold = payout.min_range_law(line, mandrel, job.payout)
    assert any(w for w, _ in iters["warm"]) and not any(w for w, _ in iters["cold"])
    assert len(iters["warm"]) >= 2
    sw, sc = warm.report["solver"], cold.report["solver"]
    width_w, width_c = sw["range_lp"]["u_range"], sc["range_lp"]["u_range"]
    assert width_w <= width_c + 1e-9 * max(1.0, abs(width_c))
    assert sw["jerk_15"] <= sc["jerk_15"] * (1 + 1e-9) + 1e-12
    for eye in (warm, cold):
        assert eye.feasible and all(c["ok"] for c in eye.report["constraints"].values())
    assert warm.report["u_range"] <= cold.report["u_range"] + 1e-7 * max(1.0, cold.report["u_range"])
    total_w, total_c = (sum(i for _, i in iters[m]) for m in ("warm", "cold"))
    assert total_w < 0.6 * total_c, (iters["warm"], iters["cold"])
