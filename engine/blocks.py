"""NC blocks: linear approximation of the axis paths and block times (MATH.md §A5, eqs. (17), (18)).

Linear approximation
--------------------
A block moves every axis linearly from its start to its end position, all axes finishing together.
:func:`make_blocks` chooses block ends among the path points (a vectorised Douglas-Peucker split):
a block is accepted when, at every path point inside it, forward kinematics of the linearly
interpolated axes is within ``tol_mm`` of the eye position the machine realises
(``AxisPath.eye_xyz``, mandrel frame).  A path point inside a block is compared with the block's
interpolated position at the same *time fraction*: the fraction of the block's preliminary time (17)
accumulated up to that point (``sum max_k |dq_k| / f_max_k``), which is how a controller running the
block at constant rate reaches it.

Block times
-----------
Preliminary time (17):  ``t_i = max( max_k |D_i^k| / f_max^k, tau )``.

Pairwise minimisation (18), with ``alpha_i = t_i / t~_i`` (``t~`` the new time, ``0 < alpha <= 1``
keeps every speed within its limit) and ``v_i^k = D_i^k / t_i`` (axis speed at ``alpha = 1``):

    min  T(alpha_i, alpha_j) = t_i / alpha_i + t_j / alpha_j
    s.t. 0 < alpha_i <= 1, 0 < alpha_j <= 1,  |v_i^k alpha_i - v_j^k alpha_j| <= p^k  (every axis k)

for neighbouring blocks ``j = i + 1`` and ``(n, 1)`` (cyclic program).  The paper's text lost its
operators; this reading is the one under which its statements hold: the constraints are linear in
``alpha`` (a convex polygon), the objective is convex and decreasing, so the optimum is a vertex or a
Lagrange point ``alpha ∝ sqrt(t / g)`` on an edge ``g_i alpha_i + g_j alpha_j = h`` with ``g > 0`` - such
edges arise only where an axis reverses between the two blocks; without reversals the feasible set is
closed under component-wise maximum, its greatest element is optimal for every pair at once, and
sweeping the pairs is globally optimal (the paper's "class of programs").

Algorithm: (1) a feasible start - the greatest element of the constraints with each reversal pair
``|v_i| a_i + |v_j| a_j <= p`` replaced by the split ``a <= p / (|v_i| + |v_j|)``, found by a
vectorised fixed-point iteration from ``alpha = 1`` (with a safe fallback); (1b) with
``method="global"`` (default) and axis reversals present: the optimum of the whole program - a
convex problem - by a log-barrier interior-point method whose Newton systems are (cyclic)
tridiagonal, because (18) couples only neighbouring blocks; the pairwise sweeps alone can stop short
of it where an axis reverses (a tight reversal pair cannot trade time without moving a third
block); (2) sweeps of exact
pairwise minimisations (18) (vertex enumeration + Lagrange points, neighbours held fixed, pairs that
share neither a block nor a neighbour solved together, vectorised), only where a neighbour changed,
until no pair improves.
Every pair step keeps the current point as a candidate, so the program time never increases.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from engine.errors import InputError
from engine.kinematics import (
    AxisPath,
    MachineTemplate,
    Violation,
    _reduce_is_left_to_right,  # noqa: F401 - tested from here
    forward_kinematics,
    row_sums,
    violations_from_mask,
)
from engine.state import State, check_cancel


@dataclass(frozen=True)
class Blocks:
    """An NC program as linear blocks.

    Attributes
    ----------
    machine: template name.  axis_names: column order of ``q``/``delta``.
    index: (n+1,) path-point index of every block boundary (block i runs index[i] -> index[i+1]).
    q: (n+1, n_axes) axis positions at the boundaries, controller units.
    delta: (n, n_axes) axis motion of each block, controller units.
    t17: (n,) preliminary block times (17), s.
    time: (n,) block times in use (``t17`` before, ``t17 / alpha`` after (18)), s.
    alpha: (n,) speed factors of (18) (1 before optimisation).
    max_error: (n,) largest eye-position error of the linear interpolation inside each block, mm.
    tol_mm: the tolerance used.  cyclic: whether the last block is followed by the first.
    total_t17: sum of ``t17`` (no speed-jump limits), s.  total_start: time of the feasible start
        of (18), s.  total: sum of ``time``, s.  history: program time after each sweep of (18), s.
    """

    machine: str
    axis_names: tuple[str, ...]
    index: np.ndarray
    q: np.ndarray
    delta: np.ndarray
    t17: np.ndarray
    time: np.ndarray
    alpha: np.ndarray
    max_error: np.ndarray
    tol_mm: float
    cyclic: bool = True
    total_t17: float = 0.0
    total_start: float = 0.0
    history: tuple[float, ...] = ()
    violations: tuple[Violation, ...] = field(default_factory=tuple)
    sections: tuple[tuple[int, str], ...] = ()
    """(block index, text): a comment the posts write before that block (the layers of a laminate)."""

    @property
    def n(self) -> int:
        return int(self.delta.shape[0])

    @property
    def total(self) -> float:
        """Program time, s."""
        return float(self.time.sum())

    @property
    def speed(self) -> np.ndarray:
        """(n, n_axes) axis speeds in every block, controller units/s."""
        return self.delta / self.time[:, None]


def _ro(*arrs: np.ndarray) -> list[np.ndarray]:
    out = []
    for a in arrs:
        a = np.ascontiguousarray(a)
        a.flags.writeable = False
        out.append(a)
    return out


def _seg_max(err: np.ndarray, seg_start: np.ndarray) -> np.ndarray:
    return np.maximum.reduceat(err, seg_start) if err.size else np.zeros(0)


def time_metric(q: np.ndarray, fmax: np.ndarray) -> np.ndarray:
    """The (17) time metric along an axis path: ``w[0] = 0``, ``w[i] = Σ_{j<i} max_k |Δq_jk| / fmax_k``
    (s; ``q`` (N, axes) in controller units, ``fmax`` units/s).

    The same values as ``cumsum(max(|diff(q)| / fmax, axis=1))`` bit for bit (a maximum is exact);
    taken column by column, as numpy's reduction over a short last axis is four times slower, and
    :data:`TIME_METRIC_CHUNK` rows at a time (the work arrays stay in the cache and are not fresh
    pages: on a 6.4 M-point path they were two more 49 MB arrays), the running sum carried from piece
    to piece (``cumsum`` adds left to right: the same sums)."""
    q = np.asarray(q, dtype=float)
    n = q.shape[0]
    w = np.empty(n)
    w[0] = 0.0
    if n < 2:
        return w
    if q.shape[1] == 0:
        raise ValueError("time_metric: the axis path has no axes")
    for s0 in range(0, n - 1, TIME_METRIC_CHUNK):
        s1 = min(s0 + TIME_METRIC_CHUNK, n - 1)
        qc = q[s0:s1 + 1]
        m = None
        for k in range(q.shape[1]):
            c = np.subtract(qc[1:, k], qc[:-1, k])
            np.abs(c, out=c)
            c /= fmax[k]
            m = c if m is None else np.maximum(m, c, out=m)
        seg = w[s0:s1 + 1]          # seg[0] = w[s0], the sum so far
        seg[1:] = m
        np.cumsum(seg, out=seg)
    return w


TIME_METRIC_CHUNK = 1 << 15
"""Path steps per piece of :func:`time_metric`."""


def make_blocks(machine: MachineTemplate, axis_path: AxisPath, tol_mm: float = 0.05, cyclic: bool = True,
                min_block_time: float | None = None, state: State | None = None,
                pieces: list[tuple[int, int]] | None = None) -> Blocks:
    """Linear NC blocks within ``tol_mm`` of the eye path, with preliminary times (17).

    Parameters
    ----------
    machine: the template the axis path was computed for.
    axis_path: output of :func:`engine.kinematics.inverse_kinematics`.
    tol_mm: allowed eye-position error of the linear interpolation, mm (> 0).
    cyclic: the program repeats (last block followed by the first) - used by (18).
    min_block_time: tau of (17), s; default ``machine.min_block_time``.
    state: progress / cancellation.
    pieces: path-index ranges ``(start, end)`` (inclusive, each starting where the previous ends) of
        the circuits, when circuits 2 .. n-1 repeat circuit 1 (the same axis motion up to a constant
        mandrel angle, which the eye-position error does not see): the blocks are then computed for
        the first, the second and the last circuit, each on its own (a block ends at every circuit
        start), and the second circuit's blocks are replicated into the repeated ones (the cost of
        three circuits instead of all).  ``None``: the whole path as one.

    Returns
    -------
    Blocks with ``time = t17`` and ``alpha = 1``.
    """
    if not (tol_mm > 0 and np.isfinite(tol_mm)):
        raise InputError(f"tolerance must be a positive number of mm, got {tol_mm!r}", field="tol_mm")
    if tuple(axis_path.axis_names) != machine.axis_names:
        raise InputError(f"axis path is for axes {axis_path.axis_names}, machine {machine.name} has "
                         f"{machine.axis_names}", field="machine")
    tau = machine.min_block_time if min_block_time is None else float(min_block_time)
    from engine.periodic import field_rows

    q = np.asarray(axis_path.q, dtype=float)
    n = q.shape[0]
    fmax = machine.limits("max_speed")
    # time-like progress along the path (the metric of (17))
    w = time_metric(q, fmax)
    if pieces is not None and len(pieces) >= 4:
        breaks = np.zeros(n, dtype=bool)
        seg_err = np.zeros(n)
        for k, (a, b) in enumerate([pieces[0], pieces[1], pieces[-1]]):
            check_cancel(state)
            eye = np.asarray(field_rows(axis_path, "eye_xyz", a, b + 1), dtype=float)   # (a deferred one: its rows)
            br, se = _douglas_peucker(machine, q[a:b + 1], eye, w[a:b + 1] - w[a], tol_mm, None)
            breaks[a:b + 1] |= br
            seg_err[a:b] = se[:-1]
            if k == 1:                           # the repeated circuits: the second one's blocks
                for a_k, b_k in pieces[2:-1]:
                    breaks[a_k:b_k + 1] |= br
                    seg_err[a_k:b_k] = se[:-1]
            if state is not None:
                state.progress(0.3 * (k + 1), f"linear approximation: circuit pieces {k + 1}/3")
    else:
        breaks, seg_err = _douglas_peucker(machine, q, np.asarray(axis_path.eye_xyz, dtype=float), w, tol_mm, state)
    index = np.flatnonzero(breaks)
    qb = q[index]
    delta = np.diff(qb, axis=0)
    t17 = preliminary_times(delta, fmax, tau)
    max_error = seg_err[index[:-1]]
    index, qb, delta, t17, t2, alpha, max_error = _ro(index, qb, delta, t17, t17.copy(),
                                                      np.ones_like(t17), max_error)
    tot = float(t17.sum())
    if state is not None:
        state.progress(1.0, f"{delta.shape[0]} blocks")
    return Blocks(machine.name, machine.axis_names, index, qb, delta, t17, t2, alpha, max_error,
                  float(tol_mm), cyclic, tot, tot, (tot,))


def _douglas_peucker(machine: MachineTemplate, q: np.ndarray, eye: np.ndarray, w: np.ndarray, tol_mm: float,
                     state: State | None) -> tuple[np.ndarray, np.ndarray]:
    """Block ends (bool per point) and the largest error of the block starting at each end."""
    n = q.shape[0]
    breaks = np.zeros(n, dtype=bool)
    breaks[[0, n - 1]] = True
    seg_err = np.zeros(n)                    # max error of the block starting at each break
    # multilevel Douglas-Peucker: split on a subsample first, then refine on every point
    strides = [s for s in (64, 8) if s < n // 4] + [1]
    for lev, stride in enumerate(strides):
        check_cancel(state)
        sub = np.zeros(n, dtype=bool)
        sub[::stride] = True
        sub |= breaks
        P = np.flatnonzero(sub)
        _split_level(machine, q, eye, w, P, breaks, seg_err, tol_mm, state)
        if state is not None:
            state.progress(0.9 * (lev + 1) / len(strides), f"linear approximation: {int(breaks.sum())} ends")
    return breaks, seg_err


def _split_level(machine: MachineTemplate, q: np.ndarray, eye: np.ndarray, w: np.ndarray, P: np.ndarray,
                 breaks: np.ndarray, seg_err: np.ndarray, tol: float, state: State | None) -> None:
    """Douglas-Peucker on the points ``P`` (sorted, containing every break); updates ``breaks``."""
    isbrk = breaks[P]
    bpos = np.flatnonzero(isbrk)
    active = np.stack([bpos[:-1], bpos[1:]], axis=1)        # positions in P
    while active.size:
        check_cancel(state)
        a, b = active[:, 0], active[:, 1]
        lengths = b - a - 1
        has = lengths > 0
        seg_err[P[a[~has]]] = 0.0
        a, b, lengths = a[has], b[has], lengths[has]
        if a.size == 0:
            break
        seg_id = np.repeat(np.arange(a.size), lengths)
        starts = np.concatenate(([0], np.cumsum(lengths)[:-1]))
        pos = np.arange(lengths.sum()) - np.repeat(starts - a - 1, lengths)
        pts = P[pos]
        # per segment, then repeated for its points: the same operands as point by point
        sa, sb = P[a], P[b]
        wa_s = w[sa]
        span_s = w[sb] - wa_s
        flat_s = ~(span_s > 0)
        u = (w[pts] - np.repeat(wa_s, lengths)) / np.repeat(np.where(flat_s, 1.0, span_s), lengths)
        if flat_s.any():   # no time-like progress over the segment: by point count (rare)
            flat = np.repeat(flat_s, lengths)
            pa, pb = np.repeat(sa, lengths)[flat], np.repeat(sb, lengths)[flat]
            u[flat] = (pts[flat] - pa) / (pb - pa)
        qi = interp_rows(q, sa, sb, u, lengths)
        e_fk, _ = forward_kinematics(machine, qi, fibre=False)
        e_fk -= eye[pts]
        e_fk *= e_fk
        err = np.sqrt(row_sums(e_fk))               # numpy.linalg.norm(·, axis=1), bit for bit
        smax = np.maximum.reduceat(err, starts)
        ok = smax <= tol
        seg_err[P[a[ok]]] = smax[ok]
        bad = np.flatnonzero(~ok)
        if bad.size == 0:
            break
        # first position of the maximum in each bad segment
        cand = np.flatnonzero(err == smax[seg_id])
        sc = seg_id[cand]                        # non-decreasing: the first of each run
        first = np.flatnonzero(np.concatenate(([True], sc[1:] != sc[:-1])))
        split_of = np.full(a.size, -1)
        split_of[sc[first]] = pos[cand[first]]
        split = split_of[bad]
        breaks[P[split]] = True
        active = np.concatenate([np.stack([a[bad], split], axis=1), np.stack([split, b[bad]], axis=1)])


def interp_rows(q: np.ndarray, sa: np.ndarray, sb: np.ndarray, u: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """Rows ``q[a] + u·(q[b] − q[a])`` for segments ``a = sa[s]``, ``b = sb[s]`` repeated ``lengths[s]`` times
    (``u`` one fraction per row): ``(q[sb] − q[sa])`` repeated, times ``u``, plus ``q[sa]`` repeated - the
    same operations as with whole rows, taken column by column (broadcasting ``u`` over a row of a few
    axes is several times slower)."""
    out = np.empty((u.size, q.shape[1]))
    for k in range(q.shape[1]):
        qa = q[sa, k]
        col = np.repeat(q[sb, k] - qa, lengths)
        col *= u
        col += np.repeat(qa, lengths)
        out[:, k] = col
    return out


def preliminary_times(delta: np.ndarray, f_max: np.ndarray, tau: float) -> np.ndarray:
    """Eq. (17): ``t_i = max(max_k |delta_i^k| / f_max^k, tau)``, s."""
    delta = np.atleast_2d(np.asarray(delta, dtype=float))
    m = max_abs_over(delta, np.asarray(f_max, dtype=float))
    return np.maximum(m, float(tau), out=m if m.dtype == float and m.flags.writeable else None)


def max_abs_over(D: np.ndarray, V: np.ndarray) -> np.ndarray:
    """``(np.abs(D) / V).max(axis=1)`` for (N, n) ``D`` and (n,) ``V``, column by column (the same
    divisions, and a maximum is exact: the same values; numpy broadcasting over a few axes is slow)."""
    if D.ndim != 2 or D.shape[1] == 0 or np.shape(V) != (D.shape[1],):
        return (np.abs(D) / V).max(axis=1)
    m = np.abs(D[:, 0])
    m /= V[0]
    for k in range(1, D.shape[1]):
        c = np.abs(D[:, k])
        c /= V[k]
        np.maximum(m, c, out=m)
    return m


# --------------------------------------------------------------------------------------------------
# Pairwise minimisation (18)
# --------------------------------------------------------------------------------------------------
def solve_pairs(ti: np.ndarray, tj: np.ndarray, a: np.ndarray, b: np.ndarray, p: np.ndarray,
                xlo: np.ndarray, xhi: np.ndarray, ylo: np.ndarray, yhi: np.ndarray,
                x0: np.ndarray | None = None, y0: np.ndarray | None = None,
                chunk: int = 1024) -> tuple[np.ndarray, np.ndarray]:
    """Exact minimiser of ``ti/x + tj/y`` over many 2-D polygons at once (eq. (18)).

    Polygon: ``xlo <= x <= xhi``, ``ylo <= y <= yhi``, ``|a_k x - b_k y| <= p_k`` for every k.

    Parameters
    ----------
    ti, tj: (P,) positive preliminary times.  a, b: (P,m) axis speeds at alpha = 1 in blocks i, j.
    p: (m,) or (P,m) allowed speed jumps.  xlo..yhi: (P,) bounds (0 < lo <= hi <= 1).
    x0, y0: (P,) a feasible point kept as a candidate (the answer is never worse than it).

    Returns
    -------
    x, y: (P,) the optimum (vertex of the polygon or Lagrange point on an edge).
    """
    P, m = a.shape
    p = np.broadcast_to(np.asarray(p, dtype=float), (P, m))
    xs, ys = np.empty(P), np.empty(P)
    for s in range(0, P, chunk):
        sl = slice(s, min(P, s + chunk))
        xs[sl], ys[sl] = _solve_chunk(ti[sl], tj[sl], a[sl], b[sl], p[sl], xlo[sl], xhi[sl], ylo[sl],
                                      yhi[sl], None if x0 is None else x0[sl], None if y0 is None else y0[sl])
    return xs, ys


def _solve_chunk(ti, tj, a, b, p, xlo, xhi, ylo, yhi, x0, y0):
    # an axis whose jump cannot reach p_k for any alpha in (0, 1]^2 never binds: drop its lines
    live = np.any(np.abs(a) + np.abs(b) > p, axis=0)
    a, b, p = a[:, live], b[:, live], p[:, live]
    P, m = a.shape
    # lines g1 x + g2 y <= h
    one, zero = np.ones(P), np.zeros(P)
    G1 = np.concatenate([np.stack([one, -one, zero, zero], axis=1), a, -a], axis=1)
    G2 = np.concatenate([np.stack([zero, zero, one, -one], axis=1), -b, b], axis=1)
    H = np.concatenate([np.stack([xhi, -xlo, yhi, -ylo], axis=1), p, p], axis=1)
    L = G1.shape[1]
    iu, ju = np.triu_indices(L, 1)
    det = G1[:, iu] * G2[:, ju] - G1[:, ju] * G2[:, iu]
    scale = np.maximum(np.abs(G1[:, iu] * G2[:, ju]) + np.abs(G1[:, ju] * G2[:, iu]), 1e-300)
    okd = np.abs(det) > 1e-12 * scale
    dets = np.where(okd, det, 1.0)
    cx = np.where(okd, (H[:, iu] * G2[:, ju] - H[:, ju] * G2[:, iu]) / dets, np.nan)
    cy = np.where(okd, (G1[:, iu] * H[:, ju] - G1[:, ju] * H[:, iu]) / dets, np.nan)
    # Lagrange points on lines with g1 > 0, g2 > 0 (negative slope: an axis reverses)
    pos = (G1 > 0) & (G2 > 0)
    g1s, g2s = np.where(pos, G1, 1.0), np.where(pos, G2, 1.0)
    den = np.sqrt(g1s * ti[:, None]) + np.sqrt(g2s * tj[:, None])
    lx = np.where(pos, H * np.sqrt(ti[:, None] / g1s) / den, np.nan)
    ly = np.where(pos, H * np.sqrt(tj[:, None] / g2s) / den, np.nan)
    cands_x = [cx, lx]
    cands_y = [cy, ly]
    if x0 is not None:
        cands_x.append(x0[:, None])
        cands_y.append(y0[:, None])
    CX = np.concatenate(cands_x, axis=1)
    CY = np.concatenate(cands_y, axis=1)
    # feasibility of every candidate against every line
    slack = (G1[:, None, :] * CX[:, :, None] + G2[:, None, :] * CY[:, :, None]) - H[:, None, :]
    tolr = 1e-12 * (np.abs(H) + 1.0)[:, None, :]
    feas = np.all(slack <= tolr, axis=2) & (CX > 0) & (CY > 0)
    obj = np.where(feas, ti[:, None] / np.where(feas, CX, 1.0) + tj[:, None] / np.where(feas, CY, 1.0),
                   np.inf)
    k = np.argmin(obj, axis=1)
    r = np.arange(P)
    x, y = CX[r, k], CY[r, k]
    none = ~np.isfinite(obj[r, k])
    if np.any(none):
        x = np.where(none, np.nan, x)
        y = np.where(none, np.nan, y)
    return x, y


def _pair_indices(nb: int, cyclic: bool) -> tuple[np.ndarray, np.ndarray]:
    i = np.arange(nb - 1)
    if cyclic and nb > 2:
        i = np.arange(nb)
    return i, (i + 1) % nb


def _feasible_start(v: np.ndarray, p: np.ndarray, cyclic: bool, max_iter: int = 10000
                    ) -> tuple[np.ndarray, bool]:
    """Greatest alpha of the 'split' restriction (see module docstring), and whether it was reached.

    The result is always feasible; when the fixed-point iteration did not converge, a safe fallback
    (each block at most ``p / (|v_i| + |v_j|)`` of its pairs) is applied where needed."""
    nb = v.shape[0]
    pi, pj = _pair_indices(nb, cyclic)
    av = np.abs(v)
    vi, vj = v[pi], v[pj]
    rev = (vi * vj) < 0                                      # (pairs, m): axis reverses
    with np.errstate(divide="ignore", invalid="ignore"):
        split = np.where(rev, p / (av[pi] + av[pj]), np.inf).min(axis=1)
    alpha = np.ones(nb)
    np.minimum.at(alpha, pi, split)
    np.minimum.at(alpha, pj, split)
    same = ~rev
    ai, aj = av[pi], av[pj]
    for _ in range(max_iter):
        with np.errstate(divide="ignore", invalid="ignore"):
            bj = np.where(same & (aj > 0), (p + ai * alpha[pi, None]) / aj, np.inf).min(axis=1)
            bi = np.where(same & (ai > 0), (p + aj * alpha[pj, None]) / ai, np.inf).min(axis=1)
        new = alpha.copy()
        np.minimum.at(new, pj, bj)
        np.minimum.at(new, pi, bi)
        if np.all(new >= alpha * (1 - 1e-15)):
            alpha = new
            converged = True
            break
        alpha = new
    else:
        converged = False
    # safety net: the iteration converges geometrically in rare set-ups; enforce feasibility
    local = np.ones(nb)
    with np.errstate(divide="ignore", invalid="ignore"):
        lp = np.where(av[pi] + av[pj] > 0, p / (av[pi] + av[pj]), np.inf).min(axis=1)
    np.minimum.at(local, pi, lp)
    np.minimum.at(local, pj, lp)
    exact = converged
    for _ in range(nb + 1):
        bad = _pair_violation(v, alpha, p, pi, pj) > 0
        if not bad.any():
            break
        exact = False
        alpha[pi[bad]] = np.minimum(alpha[pi[bad]], local[pi[bad]])
        alpha[pj[bad]] = np.minimum(alpha[pj[bad]], local[pj[bad]])
    return alpha, exact


def _pair_violation(v: np.ndarray, alpha: np.ndarray, p: np.ndarray, pi: np.ndarray, pj: np.ndarray,
                    rtol: float = 1e-12) -> np.ndarray:
    """Per pair: worst excess of the speed jump over its limit (<= 0 when feasible)."""
    jump = np.abs(v[pi] * alpha[pi, None] - v[pj] * alpha[pj, None])
    return (jump - p * (1 + rtol)).max(axis=1)


def optimise_block_times(blocks: Blocks, machine: MachineTemplate, max_sweeps: int = 1000,
                         rtol: float = 1e-12, method: str = "global", state: State | None = None) -> Blocks:
    """Minimise the program time pairwise, eq. (18), under the axes' speed-jump limits.

    Parameters
    ----------
    blocks: from :func:`make_blocks` (its ``t17`` are used).
    machine: the template (``max_jump`` per axis, controller units/s).
    max_sweeps: cap on the sweeps of pairwise minimisations.
    rtol: a pair step counts as an improvement when it lowers the pair time by more than this.
    method: ``"pairwise"`` - the paper's procedure: pair sweeps (18) from the feasible start;
        ``"global"`` - first the optimum of the whole program (a convex problem: log-barrier
        interior point, one banded Newton system per step), then the pair sweeps (18) from there.
        Both give the same answer on programs without axis reversals; with reversals the pairwise
        procedure alone can stop short of the optimum (docs/machines.md).

    Returns
    -------
    Blocks with ``time = t17 / alpha``, ``total_start`` the feasible start and ``history`` the
    program time after each sweep (non-increasing).
    """
    nb = blocks.n
    p = machine.limits("max_jump")
    t = np.asarray(blocks.t17, dtype=float)
    if nb == 0:
        return blocks
    v = blocks.delta / t[:, None]
    cyclic = blocks.cyclic and nb > 2
    if method not in ("pairwise", "global"):
        raise InputError(f"method must be 'pairwise' or 'global', got {method!r}", field="method")
    alpha, exact = _feasible_start(v, p, cyclic)
    hist = [float((t / alpha).sum())]
    total_start = hist[0]
    polish_all = False
    pi0, pj0 = _pair_indices(nb, cyclic)
    any_reversal = nb >= 2 and bool(((v[pi0] * v[pj0]) < 0).any())
    # without reversals (and an exact start) the start is the greatest element: already optimal
    if method == "global" and nb >= 2 and (any_reversal or not exact):
        a_ip = _interior_point(v, p, t, cyclic, alpha, state)
        if a_ip is not None and float((t / a_ip).sum()) < hist[-1]:
            alpha = a_ip
            hist.append(float((t / alpha).sum()))
            polish_all = True
    if nb >= 2:
        pi, pj = _pair_indices(nb, cyclic)
        npair = pi.size
        # pairs solved together must not touch each other's blocks or neighbours: pair i and
        # pair i + 3 are independent; the (up to two) wrap-around pairs of a cyclic program get
        # colours of their own
        color = pi % 3
        if cyclic and nb % 3:
            rem = nb % 3
            color[nb - rem:] = 3 + np.arange(rem)
        # neighbours of each pair: left block h of i, right block l of j
        h = (pi - 1) % nb
        l_ = (pj + 1) % nb
        has_h = np.ones(npair, bool) if cyclic else pi > 0
        has_l = np.ones(npair, bool) if cyclic else pj < nb - 1
        if nb <= 3 and cyclic:                      # neighbours coincide with the pair itself
            has_h &= (h != pj)
            has_l &= (l_ != pi)
        # pairs away from any axis reversal already sit at the greatest element of their polygon
        rev = ((v[pi] * v[pj]) < 0).any(axis=1)
        rev_blk = np.zeros(nb, dtype=bool)
        rev_blk[pi[rev]] = True
        rev_blk[pj[rev]] = True
        dirty = rev_blk[pi] | rev_blk[pj] | rev_blk[h] | rev_blk[l_]
        if not exact or polish_all:
            dirty[:] = True
        for _sweep in range(max_sweeps):
            check_cancel(state)
            changed_blocks = np.zeros(nb, dtype=bool)
            for c in range(5):
                sel = np.flatnonzero((color == c) & dirty)
                if sel.size == 0:
                    continue
                x, y = _solve_with_neighbours(sel, pi, pj, h, l_, has_h, has_l, v, alpha, p, t)
                xi, yj = alpha[pi[sel]], alpha[pj[sel]]
                better = (t[pi[sel]] / x + t[pj[sel]] / y) < (t[pi[sel]] / xi + t[pj[sel]] / yj) * (1 - rtol)
                better &= np.isfinite(x) & np.isfinite(y)
                s2 = sel[better]
                alpha[pi[s2]] = x[better]
                alpha[pj[s2]] = y[better]
                changed_blocks[pi[s2]] = True
                changed_blocks[pj[s2]] = True
            hist.append(float((t / alpha).sum()))
            if not changed_blocks.any():
                break
            # a pair needs re-solving when any block in or next to it changed
            touched = changed_blocks[pi] | changed_blocks[pj] | changed_blocks[h] | changed_blocks[l_]
            dirty = touched
            if state is not None:
                state.progress(min(0.99, (_sweep + 1) / 50), f"pairwise minimisation (18): {hist[-1]:.4g} s")
    time = t / alpha
    alpha_ro, time_ro = _ro(alpha, time)
    out = replace(blocks, alpha=alpha_ro, time=time_ro, total_start=total_start, history=tuple(hist))
    return replace(out, violations=tuple(check_blocks(machine, out)))


def _interior_point(v: np.ndarray, p: np.ndarray, t: np.ndarray, cyclic: bool, alpha0: np.ndarray,
                    state: State | None, rgap: float = 1e-11) -> np.ndarray | None:
    """Optimum of ``sum t/alpha`` over the whole program's polygon (18) by a log-barrier method.

    The Hessian couples only neighbouring blocks: a (cyclic) tridiagonal SPD system per Newton step,
    solved by banded Cholesky (Sherman-Morrison for the wrap-around pair).  Starts from half the
    feasible start (strictly inside); every iterate stays strictly feasible.  Returns None if the
    start is not usable.
    """
    from scipy.linalg import solveh_banded

    nb, m = v.shape
    if np.any(alpha0 <= 0):
        return None
    pi, pj = _pair_indices(nb, cyclic)
    live = (np.abs(v[pi]) + np.abs(v[pj])) > p                  # (pairs, m) can bind at all
    kk, ii = np.nonzero(live.T)
    ci, cj = pi[ii], pj[ii]
    GI = np.concatenate([v[ci, kk], -v[ci, kk]])                # constraint g_i a_i + g_j a_j <= h
    GJ = np.concatenate([-v[cj, kk], v[cj, kk]])
    HH = np.concatenate([p[kk], p[kk]])
    CI, CJ = np.concatenate([ci, ci]), np.concatenate([cj, cj])
    # constraint generation: start with the rows that are nearly active at the start, add any row
    # the answer comes close to, re-solve (the start is strictly inside every row)
    sel = (HH - GI * alpha0[CI] - GJ * alpha0[CJ]) <= 0.5 * HH
    for _round in range(6):
        a = _barrier_solve(t, CI[sel], CJ[sel], GI[sel], GJ[sel], HH[sel], nb, cyclic, alpha0, state, rgap,
                           solveh_banded)
        if a is None:
            return None
        slack = HH - GI * a[CI] - GJ * a[CJ]
        near = (~sel) & (slack <= 0.1 * HH)
        if not near.any():
            return a if np.all(slack > 0) else None
        sel |= near
    return None


def _barrier_solve(t, ci, cj, gi, gj, hh, nb, cyclic, alpha0, state, rgap, solveh_banded):
    """Log-barrier interior point on the rows given (see :func:`_interior_point`)."""
    nc = hh.size + 2 * nb
    a = 0.5 * alpha0

    def slacks(x):
        return hh - gi * x[ci] - gj * x[cj], 1.0 - x

    def phi(x, mu):
        sc, su = slacks(x)
        return float(np.sum(t / x) - mu * (np.log(sc).sum() + np.log(su).sum() + np.log(x).sum()))

    f0 = float(np.sum(t / a))
    mu = f0 / nc
    for _outer in range(60):
        check_cancel(state)
        for _newton in range(50):
            sc, su = slacks(a)
            w = mu / sc ** 2
            ms = mu / sc
            grad = (-t / a ** 2 + mu * (1.0 / su - 1.0 / a) + np.bincount(ci, ms * gi, nb)
                    + np.bincount(cj, ms * gj, nb))
            diag = (2 * t / a ** 3 + mu * (1.0 / su ** 2 + 1.0 / a ** 2) + np.bincount(ci, w * gi * gi, nb)
                    + np.bincount(cj, w * gj * gj, nb))
            off = np.bincount(ci, w * gi * gj, nb)                # H[i, i+1 mod nb] at index i
            d = _solve_cyclic_tridiag(diag, off, -grad, cyclic, solveh_banded)
            if d is None:
                return None
            # fraction to the boundary, then backtracking on the barrier function
            sc_d = -(gi * d[ci] + gj * d[cj])
            steps = [1.0]
            for num, den in ((sc, sc_d), (su, -d), (a, d)):
                neg = den < 0
                if neg.any():
                    steps.append(0.99 * float(np.min(-num[neg] / den[neg])))
            tau = min(steps)
            f_old = phi(a, mu)
            dec = float(grad @ d)
            while tau > 1e-16 and phi(a + tau * d, mu) > f_old + 1e-4 * tau * dec:
                tau *= 0.5
            if tau <= 1e-12:                 # no progress possible at this barrier parameter
                break
            a = a + tau * d
            # Newton decrement small against the duality-gap bound of this barrier parameter
            if -dec < 0.1 * mu * nc or -dec < 1e-14 * (1.0 + abs(f_old)):
                break
        if mu * nc < rgap * float(np.sum(t / a)):
            break
        mu *= 0.05
    sc, su = slacks(a)
    if np.any(sc <= 0) or np.any(su < 0) or np.any(a <= 0):
        return None
    return a


def _solve_cyclic_tridiag(diag, off, rhs, cyclic, solveh_banded):
    """Solve H x = rhs, H symmetric with ``diag``, ``off[i] = H[i, i+1]`` and, if cyclic,
    ``off[-1] = H[n-1, 0]``."""
    n = diag.size
    ab = np.zeros((2, n))
    ab[1] = diag
    ab[0, 1:] = off[:-1]
    try:
        if not cyclic or n < 3:
            if n == 2 and cyclic:
                ab[0, 1] = off[0] + off[1]
            return solveh_banded(ab, rhs)
        c = off[-1]
        gamma = -diag[0]
        ab[1, 0] = diag[0] - gamma
        ab[1, -1] = diag[-1] - c * c / gamma
        u = np.zeros(n)
        u[0], u[-1] = gamma, c
        sol = solveh_banded(ab, np.stack([rhs, u], axis=1))
        y, z = sol[:, 0], sol[:, 1]
        vy = y[0] + c / gamma * y[-1]
        vz = z[0] + c / gamma * z[-1]
        return y - vy / (1.0 + vz) * z
    except np.linalg.LinAlgError:
        return None


def _solve_with_neighbours(sel, pi, pj, h, l_, has_h, has_l, v, alpha, p, t):
    i, j = pi[sel], pj[sel]
    vi, vj = v[i], v[j]
    xlo, xhi = _bounds_from_neighbour(vi, v[h[sel]] * alpha[h[sel], None], p, has_h[sel])
    ylo, yhi = _bounds_from_neighbour(vj, v[l_[sel]] * alpha[l_[sel], None], p, has_l[sel])
    x0, y0 = alpha[i], alpha[j]
    xlo, ylo = np.minimum(xlo, x0), np.minimum(ylo, y0)     # guard against rounding
    xhi, yhi = np.maximum(xhi, x0), np.maximum(yhi, y0)
    return solve_pairs(t[i], t[j], vi, vj, p, xlo, xhi, ylo, yhi, x0, y0)


def _bounds_from_neighbour(vx: np.ndarray, c: np.ndarray, p: np.ndarray, has: np.ndarray
                           ) -> tuple[np.ndarray, np.ndarray]:
    """Interval of x with ``|c_k - vx_k x| <= p_k`` for all k, intersected with (0, 1]."""
    with np.errstate(divide="ignore", invalid="ignore"):
        lo1 = np.where(vx > 0, (c - p) / vx, np.where(vx < 0, (c + p) / vx, -np.inf))
        hi1 = np.where(vx > 0, (c + p) / vx, np.where(vx < 0, (c - p) / vx, np.inf))
    lo = np.where(has, np.max(lo1, axis=1), 0.0)
    hi = np.where(has, np.min(hi1, axis=1), 1.0)
    return np.maximum(lo, 0.0), np.minimum(hi, 1.0)


# --------------------------------------------------------------------------------------------------
# Checks
# --------------------------------------------------------------------------------------------------
def check_blocks(machine: MachineTemplate, blocks: Blocks, rtol: float = 1e-9) -> list[Violation]:
    """Position, speed and speed-jump violations of a block program, located by axis and block."""
    out: list[Violation] = []
    spd = blocks.speed
    vmax = machine.limits("max_speed")
    p = machine.limits("max_jump")
    lo, hi = machine.limits("min"), machine.limits("max")
    nb = blocks.n
    for k, ax in enumerate(machine.axes):
        u = f" {ax.units}"
        out += violations_from_mask("position", ax.name, blocks.q[1:, k] > hi[k], blocks.q[1:, k], hi[k], u,
                                    where="block", what="end position")
        out += violations_from_mask("position", ax.name, blocks.q[1:, k] < lo[k], blocks.q[1:, k], lo[k], u,
                                    where="block", what="end position")
        s = np.abs(spd[:, k])
        out += violations_from_mask("speed", ax.name, s > vmax[k] * (1 + rtol), s, vmax[k], f"{u}/s",
                                    where="block", what="speed")
        if nb >= 2:
            nxt = np.roll(spd[:, k], -1) if blocks.cyclic and nb > 2 else np.append(spd[1:, k], spd[-1, k])
            jump = np.abs(nxt - spd[:, k])
            out += violations_from_mask("jump", ax.name, jump > p[k] * (1 + rtol), jump, p[k], f"{u}/s",
                                        where="block", what="speed jump to the next block")
    return out


def check_program(axis_path: AxisPath, blocks: Blocks | None = None, machine: MachineTemplate | None = None
                  ) -> list[Violation]:
    """Every violation of an axis path (and of its blocks, when given); empty means safe to write.

    Callers must not write the NC file when this is non-empty unless the user forces it.
    """
    out = list(axis_path.violations)
    if blocks is not None:
        out += check_blocks(machine, blocks) if machine is not None else list(blocks.violations)
    return out


__all__ = ["Blocks", "check_blocks", "check_program", "make_blocks", "optimise_block_times",
           "preliminary_times", "solve_pairs"]
