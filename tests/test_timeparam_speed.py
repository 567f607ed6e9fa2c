"""The compiled DP pass (engine.timeparam_jit, numba) against the numpy reference pass (issue 16).

Both passes must give the same bits of every finite J and its argmin, hence the same laws bit for bit: on the paper's
example (uniform node spacing, every tube iteration) and on a non-uniform path without the penalty
term.  Without compiled kernels the numpy pass runs and gives the same answer.  (In this process the compiled
kernels are the ahead-of-time ones where they are built: tests/test_timeparam_aot.py compares those with
numba's just-in-time kernels.)
"""

from __future__ import annotations

import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import engine.timeparam as tp
from engine.timeparam_example import example_limits, example_path

ROOT = Path(__file__).resolve().parents[1]
numba = pytest.importorskip("numba")


def _law(flag: bool, *args, **kw):
    old = tp._NUMBA
    tp._NUMBA = flag
    try:
        return tp.parametrize(*args, **kw)
    finally:
        tp._NUMBA = old


def test_compiled_pass_is_used_and_bit_identical_on_the_example() -> None:
    from engine import timeparam_jit

    s, X, dX, ddX = example_path()
    lim = replace(example_limits(), levels=80)
    ref = _law(False, s, X, dX, ddX, lim)
    new = _law(True, s, X, dX, ddX, lim)
    assert timeparam_jit.kernel(0) is not None          # numba is loaded: the kernel ran
    assert np.array_equal(ref.sdot, new.sdot) and ref.total_time_s == new.total_time_s
    assert [it.total_time_s for it in ref.iterations] == [it.total_time_s for it in new.iterations]
    assert [(it.w_touches, it.o_touches) for it in ref.iterations] == \
        [(it.w_touches, it.o_touches) for it in new.iterations]


def test_compiled_pass_bit_identical_non_uniform_spacing_no_penalty() -> None:
    s, X, dX, ddX = example_path(n=300)
    rng = np.random.default_rng(3)
    keep = np.sort(np.r_[0, rng.choice(np.arange(1, 299), 180, replace=False), 299])
    s, X, dX, ddX = s[keep], X[keep], dX[keep], ddX[keep]
    lim = replace(example_limits(), levels=60, penalty=0.0)
    for method in ("tube", "dp"):
        ref = _law(False, s, X, dX, ddX, lim, method=method)
        new = _law(True, s, X, dX, ddX, lim, method=method)
        assert np.array_equal(ref.sdot, new.sdot), method


def test_without_numba_the_numpy_pass_gives_the_same_law() -> None:
    """No numba and no ahead-of-time kernels (engine.aot; tests/test_timeparam_aot.py has the frozen
    build's case, numba absent and those kernels there): the numpy pass."""
    import os

    code = (
        "import sys; sys.modules['numba'] = None\n"         # import numba fails, as in the frozen build
        "from dataclasses import replace\n"
        "from engine import timeparam_jit\n"
        "from engine.timeparam import parametrize\n"
        "from engine.timeparam_example import example_limits, example_path\n"
        "law = parametrize(*example_path(), replace(example_limits(), levels=74))\n"
        "assert timeparam_jit.kernel(10**12) is None\n"
        "print(repr(law.total_time_s))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT,
                         env={**os.environ, "WINDER_AOT": "0"})
    assert out.returncode == 0, out.stderr
    s, X, dX, ddX = example_path()
    law = _law(True, s, X, dX, ddX, replace(example_limits(), levels=74))
    assert float(out.stdout.strip()) == law.total_time_s


@pytest.mark.parametrize("n", [3000, 10000])
def test_dense_nodes_converge_like_the_paper_spacing(n: int) -> None:
    """Node density (issue 16): the paper's path resampled to n nodes.  On the given nodes the tube
    used to stall (N = 3000: 15 iterations, 0.67 % above TOPP-RA; N = 10 000 at the 60-iteration cap);
    on node groups one level step long it stops in a few iterations within 0.5 % of TOPP-RA on the
    same nodes, at least as fast as the ungrouped law, with every limit held inside every interval
    of the given nodes."""
    s, X, dX, ddX = example_path(n)
    lim = example_limits()
    ref = tp.parametrize(s, X, dX, ddX, lim, method="toppra")
    law = tp.parametrize(s, X, dX, ddX, lim)
    assert law.node_group > 1 and law.s.size == n
    assert len(law.iterations) < 10 and law.iterations[-1].stop
    assert law.total_time_s <= 1.005 * ref.total_time_s
    assert law.max_accel_ratio <= 1 + 1e-9 and law.max_speed_ratio <= 1 + 1e-9 and law.max_sddot_ratio <= 1 + 1e-9
    if n == 3000:
        old = tp.parametrize(s, X, dX, ddX, replace(lim, coarse=False))
        assert old.node_group == 1 and law.total_time_s <= old.total_time_s
        ref_np = _law(False, s, X, dX, ddX, lim)            # numpy hulls and passes (no numba)
        assert ref_np.node_group == law.node_group and ref_np.max_accel_ratio <= 1 + 1e-9
        assert ref_np.total_time_s == pytest.approx(law.total_time_s, rel=1e-6)


def test_grouping_keeps_the_paper_spacing_and_the_vessel_on_their_nodes() -> None:
    s, X, dX, ddX = example_path()
    for M in (74, 100):
        prob = tp._prepare(s, X, dX, ddX, replace(example_limits(), levels=M), chains=False)
        assert tp._group_length(prob) is None


def test_compiled_hull_matches_qhull() -> None:
    from scipy.spatial import ConvexHull

    from engine import timeparam_jit

    rng = np.random.default_rng(11)
    B, R = 200, 40
    pts = rng.normal(size=(B, R, 2)) * rng.uniform(1e-6, 1e3, size=(B, 1, 2))
    pts[:, 5] = pts[:, 4]                                    # duplicates
    pts[:, 7] = pts[:, 6] * (1 + 1e-15)                      # near-duplicates
    pts[:, 9] = 0.0                                          # zero rows
    pts[:, 11] = 0.5 * pts[:, 10]                            # on a ray (inside)
    order, m = timeparam_jit.hulls(pts)
    for b in range(B):
        nz = np.flatnonzero(np.abs(pts[b]).sum(1) > 0)
        q = ConvexHull(pts[b, nz])
        ours = pts[b, order[b, :m[b]]]
        # same polygon: the same vertex points (a near-twin may stand for its twin), CCW order
        assert m[b] == len(q.vertices)
        ref = pts[b, nz[q.vertices]]
        d = np.abs(ours[:, None, :] - ref[None, :, :]).max(-1)
        assert np.all(d.min(1) <= 1e-12 * np.abs(ref).max())
        area = 0.5 * np.sum(ours[:, 0] * np.roll(ours[:, 1], -1) - np.roll(ours[:, 0], -1) * ours[:, 1])
        assert area > 0


def test_compiled_hull_on_the_symmetric_half_equals_the_full_chain() -> None:
    """The compiled hull given the ± pairs of the rows runs the monotone chain on half the points and
    mirrors it: the same vertex rows in the same order as on every point -- on the example's
    intervals, on node groups, and on random symmetric sets with exact and near duplicates, mirror
    duplicates (the full chain then runs), collinear points, zero rows and nearly flat sets."""
    from engine import timeparam_jit

    sets = []
    for n in (None, 3000):
        s, X, dX, ddX = example_path(n) if n else example_path()
        prob = tp._prepare(s, X, dX, ddX, replace(example_limits(), levels=100), chains=False)
        xn = (1.5 * np.minimum(prob.cap, 1e9)) ** 2 + 1.0
        sets.append(tp._box_rows(prob.hull_rows, prob.h, xn[:-1], xn[1:], prob.ipos, prob.ineg))
    rng = np.random.default_rng(5)
    B, H = 600, 20
    P = rng.normal(size=(B, H, 2)) * rng.uniform(1e-6, 1e3, size=(B, 1, 2))
    P[:100, 5] = P[:100, 3]                                  # duplicates
    P[100:200, 6] = -P[100:200, 2]                           # a mirror duplicate
    P[200:300, 7] = 2.0 * P[200:300, 1]                      # on a ray
    P[300:400, 8] = P[300:400, 4] * (1 + 1e-15)              # near-duplicates
    P[400:450, :, 1] = 1e-17 * P[400:450, :, 0]              # nearly flat
    P[450:500, 3:] = 0.0                                     # zero rows
    P[500:] = np.round(P[500:] * 2) / 2                      # a lattice: collinear and duplicate points
    sets.append((np.concatenate([P, -P], axis=1), np.arange(H), np.arange(H, 2 * H)))
    for pts, ipos, ineg in sets:
        full = timeparam_jit.hulls(pts)
        half = timeparam_jit.hulls(pts, (ipos, ineg))
        assert np.array_equal(full[1], half[1])
        for b in range(pts.shape[0]):
            assert np.array_equal(full[0][b, :full[1][b]], half[0][b, :half[1][b]]), b


def test_compiled_pass_reports_infeasibility_as_the_numpy_pass() -> None:
    """The fused compiled pass finds the same unreachable node (its reach checks and backward pass
    are compiled too): the same error text with and without numba."""
    from engine.errors import InfeasibleError
    from engine.timeparam import TechPoint, TimeLimits

    s = np.linspace(0, 10, 11)
    X = s[:, None] * 1.0
    one = np.ones_like(X)
    lim = TimeLimits(v_max=(1e6,), a_max=(100.0,), sdot_start=300.0, sdot_end=0.0,
                     points=(TechPoint(10.0, s=3.0, label="feed"),))
    msgs = []
    for flag in (False, True):
        with pytest.raises(InfeasibleError) as err:
            _law(flag, s, X, one, 0 * one, lim, method="dp")
        msgs.append(str(err.value))
    assert msgs[0] == msgs[1] and "'feed'" in msgs[0]


def test_compiled_pass_bit_identical_on_the_long_path() -> None:
    """The paper's spacing on a path three times as long (the benchmark's long case, shorter): every
    tube iteration the same bits with the compiled pass (pruned windows) and the numpy pass."""
    from engine.timeparam_example import N_PAPER, S_N_PAPER

    s, X, dX, ddX = example_path((N_PAPER - 1) * 3 + 1, 3 * S_N_PAPER, S_N_PAPER)
    lim = replace(example_limits(), levels=100)
    ref = _law(False, s, X, dX, ddX, lim)
    new = _law(True, s, X, dX, ddX, lim)
    assert np.array_equal(ref.sdot, new.sdot)
    assert [it.total_time_s for it in ref.iterations] == [it.total_time_s for it in new.iterations]


@pytest.mark.parametrize("n", [300, 3000])
def test_compiled_chains_bit_identical(n: int, monkeypatch: pytest.MonkeyPatch) -> None:
    """The compiled polygon chains (engine.timeparam_jit.chains) are the numpy code's bit for bit, on
    the given nodes (n = 300) and on node groups (n = 3000: many rows per interval)."""
    from engine import timeparam_jit

    s, X, dX, ddX = example_path(n)
    lim = replace(example_limits(), levels=100)
    prob = tp._prepare(s, X, dX, ddX, lim, chains=False)
    ell = tp._group_length(prob)
    assert (ell is None) == (n == 300)
    new = tp._with_chains(prob) if ell is None else tp._coarse_problem(prob, ell)[0]
    assert timeparam_jit.chains(np.zeros((1, 3, 2)), np.zeros((1, 3), np.int64), np.array([3]), np.ones(1),
                                np.ones(1)) is None                       # det 0: the numpy branch
    monkeypatch.setattr(timeparam_jit, "chains", lambda *a: None)
    ref = tp._with_chains(prob) if ell is None else tp._coarse_problem(prob, ell)[0]
    for k in ("rq", "rk", "lq", "lk", "xjb", "xjt", "cap_dp", "xn"):
        assert np.array_equal(getattr(ref, k), getattr(new, k)), k


def test_work_arrays_per_thread_give_the_same_laws_concurrently() -> None:
    """The compiled pass and hull keep their work arrays per thread (engine.timeparam_jit.scratch):
    laws solved in two threads at once, on problems of different sizes, are those solved alone."""
    from concurrent.futures import ThreadPoolExecutor

    cases = [(example_path(300), 60), (example_path(), 80), (example_path(500), 100)]
    alone = [tp.parametrize(*p, replace(example_limits(), levels=M)) for p, M in cases]
    with ThreadPoolExecutor(max_workers=2) as ex:
        futs = [ex.submit(tp.parametrize, *p, replace(example_limits(), levels=M)) for p, M in cases * 2]
        together = [f.result() for f in futs]
    for a, b in zip(alone * 2, together):
        assert np.array_equal(a.sdot, b.sdot) and a.total_time_s == b.total_time_s


def test_compiled_hull_used_once_numba_is_loaded_after_a_numpy_solve() -> None:
    """A solve before numba is loaded runs the numpy code; once numba is loaded the compiled hull
    must be used (it used to remember 'not available' for good: later solves took the slower numpy
    hull, whose answers may differ at round-off)."""
    code = (
        "import sys\n"
        "from engine.timeparam import parametrize\n"
        "from engine.timeparam_example import example_limits, example_path\n"
        "from engine import timeparam_jit\n"
        "parametrize(*example_path(200), example_limits())\n"
        "assert 'numba' not in sys.modules\n"
        "import numba\n"
        "import numpy as np\n"
        "assert timeparam_jit.hulls(np.array([[[1.0, 0.0], [0.0, 1.0], [-1.0, 0.0], [0.0, -1.0]]])) is not None\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT)
    assert out.returncode == 0, out.stderr
