"""Clairaut function C(z) and twist v(z) of one pass of a winding line (MATH.md §A2).

This is the numerical core of :mod:`engine.winding`; it knows nothing about jobs, patterns or
circuits.  One *pass* runs over ``[z_a, z_b]``; each end is either a **turnaround** (the line
touches the parallel there, C = r, boundary condition (4)) or an **open end** (the line leaves
the mandrel end with C < r; the turnaround happens off the surface, on pins, with a dwell).

Parametrisation
---------------
The twist integral (1) has a 1/sqrt singularity at every turnaround, where r² − C² vanishes
linearly in z.  We integrate in a parameter t with ``z − z_a ∝ sin²(t/2)`` at a turnaround end
(``z_b − z ∝ cos²(t/2)`` at the other), so that with ``w(z)`` the product of the distances to the
turnaround ends, ``dz/dt / sqrt(w)`` is smooth and

    dv/dt = C·sqrt(1 + r'²) / ( r·sqrt((r + C)·q) ) · (dz/dt)/sqrt(w),     q = (r − C)/w

is smooth and bounded.  At a turnaround q is replaced by its analytic limit
``q = (r' − C')/w'`` (``C' = λ`` there because the bracket of (3) equals 1 at C = r): no
blow-up and no loss of accuracy near C = r.

ODE (3) is ``C' = λ·(a·C² + b)`` with ``a = 1/r² + r''/(r(1 + r'²))``, ``b = −r·r''/(1 + r'²)``
(a Riccati equation); it is integrated in t with classical RK4 on a grid that has every segment
joint of the mandrel (where r'' may jump) and every constraint point as a node, so each step
sees a smooth right-hand side.  The twist and the band length are integrated
on the same steps with 3-point Gauss-Legendre (C between nodes from the cubic Hermite interpolant).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

TURN = "turn"
OPEN = "open"
_GL_A = 0.5 - math.sqrt(15.0) / 10.0  # 3-point Gauss-Legendre nodes on [0, 1]
_GL_B = 0.5 + math.sqrt(15.0) / 10.0


def eval_on_segments(mandrel: Any, z: FloatArray, seg: NDArray[np.int64]) -> tuple[FloatArray, ...]:
    """r, r', r'' of ``mandrel`` at ``z`` (mm) evaluated with the given segment index per point."""
    r = np.empty_like(z)
    dr = np.empty_like(z)
    d2r = np.empty_like(z)
    for i, s in enumerate(mandrel.segments):
        m = seg == i
        if m.any():
            zz = np.clip(z[m], s.z0, s.z1)
            r[m], dr[m], d2r[m] = s.eval(zz)
    return r, dr, d2r


def segment_index(mandrel: Any, z: FloatArray) -> NDArray[np.int64]:
    """Index of the segment containing each z (the right one at a joint)."""
    edges = np.array([s.z0 for s in mandrel.segments] + [mandrel.segments[-1].z1])
    return np.clip(np.searchsorted(edges, z, side="right") - 1, 0, len(mandrel.segments) - 1)


def joints(mandrel: Any) -> list[float]:
    """Interior segment joints (mm)."""
    return [float(s.z0) for s in mandrel.segments[1:]]


def riccati_ab(r: FloatArray, dr: FloatArray, d2r: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Coefficients of C' = λ(a C² + b), ODE (3)."""
    g = 1.0 + dr * dr
    return 1.0 / (r * r) + d2r / (r * g), -r * d2r / g


# ------------------------------------------------------------------------------------------------
# The t map
# ------------------------------------------------------------------------------------------------
def _kind(left: str, right: str) -> str:
    if left == TURN and right == TURN:
        return "both"
    if left == TURN:
        return "left"
    if right == TURN:
        return "right"
    return "none"


def t_range(kind: str) -> tuple[float, float]:
    return {"both": (0.0, math.pi), "left": (0.0, math.pi / 2), "right": (math.pi / 2, math.pi), "none": (0.0, 1.0)}[
        kind
    ]


def t_map(kind: str, za: float, L: float, t: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """z(t), dz/dt, w(t) and (dz/dt)/sqrt(w) for the pass [za, za + L]."""
    t = np.asarray(t, dtype=float)
    if kind == "both":
        s2 = np.sin(0.5 * t) ** 2
        z = za + L * s2
        dzdt = 0.5 * L * np.sin(t)
        w = (0.5 * L * np.sin(t)) ** 2
        ratio = np.ones_like(t)
    elif kind == "left":
        s2 = np.sin(0.5 * t) ** 2
        z = za + 2.0 * L * s2
        dzdt = L * np.sin(t)
        w = 2.0 * L * s2
        ratio = math.sqrt(2.0 * L) * np.cos(0.5 * t)
    elif kind == "right":
        c2 = np.cos(0.5 * t) ** 2
        z = za + L - 2.0 * L * c2
        dzdt = L * np.sin(t)
        w = 2.0 * L * c2
        ratio = math.sqrt(2.0 * L) * np.sin(0.5 * t)
    else:
        z = za + L * t
        dzdt = np.full_like(t, L)
        w = np.ones_like(t)
        ratio = np.full_like(t, L)
    return z, dzdt, w, ratio


def t_of_z(kind: str, za: float, L: float, z: FloatArray) -> FloatArray:
    """Inverse of :func:`t_map`."""
    u = np.clip((np.asarray(z, dtype=float) - za) / L, 0.0, 1.0)
    if kind == "both":
        return 2.0 * np.arcsin(np.sqrt(u))
    if kind == "left":
        return 2.0 * np.arcsin(np.sqrt(0.5 * u))
    if kind == "right":
        return 2.0 * np.arccos(np.sqrt(0.5 * (1.0 - u)))
    return u


# ------------------------------------------------------------------------------------------------
# Grid
# ------------------------------------------------------------------------------------------------
@dataclass
class PassGrid:
    """Nodes of one pass in t (every segment joint and constraint point is a node)."""

    mandrel: Any
    za: float
    zb: float
    left: str
    right: str
    t: FloatArray
    z: FloatArray
    dzdt: FloatArray
    w: FloatArray
    ratio: FloatArray
    out: NDArray[np.bool_]
    seg: NDArray[np.int64]  # per step
    # per step, at left node / midpoint / right node
    zs: tuple[FloatArray, FloatArray, FloatArray] = field(default=None)  # type: ignore[assignment]
    geo: dict[str, tuple[FloatArray, FloatArray, FloatArray]] = field(default_factory=dict)
    A: tuple[list[float], list[float], list[float]] = field(default=None)  # type: ignore[assignment]
    B: tuple[list[float], list[float], list[float]] = field(default=None)  # type: ignore[assignment]
    h: list[float] = field(default_factory=list)

    @property
    def kind(self) -> str:
        return _kind(self.left, self.right)

    @property
    def L(self) -> float:
        return self.zb - self.za

    @property
    def n(self) -> int:
        return len(self.t)

    def node_index(self, z: float) -> int:
        return int(np.argmin(np.abs(self.z - z)))


def _far_from_nodes(tu: FloatArray, tb: FloatArray, tol: float) -> NDArray[np.bool_]:
    """For each of ``tb``: whether every node of the sorted ``tu`` is more than ``tol`` from it, i.e.
    ``min |tu − x| > tol`` (:func:`_far_from_nodes_reference`, the same comparisons): the smallest distance
    is at one of x's two neighbours in ``tu`` (rounding is monotone, so that holds for the float values too)."""
    if tu.size < 2:
        return _far_from_nodes_reference(tu, tb, tol)
    k = np.clip(np.searchsorted(tu, tb), 1, tu.size - 1)
    return np.minimum(np.abs(tu[k - 1] - tb), np.abs(tu[k] - tb)) > tol


def _far_from_nodes_reference(tu: FloatArray, tb: FloatArray, tol: float) -> NDArray[np.bool_]:
    """:func:`_far_from_nodes` by a scan of every node per point (the tested reference)."""
    return np.array([np.min(np.abs(tu - x)) > tol for x in tb], dtype=bool)


def build_grid(
    mandrel: Any, za: float, zb: float, left: str, right: str, n_out: int, refine: int, extra_z: list[float]
) -> PassGrid:
    """Grid of ``(n_out − 1)·refine`` uniform t steps plus breakpoints (joints, ``extra_z``)."""
    kind = _kind(left, right)
    L = zb - za
    t0, t1 = t_range(kind)
    n_uni = (n_out - 1) * refine + 1
    tu = np.linspace(t0, t1, n_uni)
    is_out = np.zeros(n_uni, dtype=bool)
    is_out[::refine] = True
    inside = 1e-9 * max(1.0, L)
    bz = [z for z in joints(mandrel) + list(extra_z) if za + inside < z < zb - inside]
    # knots and r'' extrema: integration nodes too (not output points), so that neither the RK4 steps
    # nor the no-bridging bound straddle a kink or a peak of r''
    bp = getattr(mandrel, "breakpoints", None)
    inner = [float(z) for z in (bp() if bp is not None else ()) if za + inside < z < zb - inside
             and all(abs(z - x) > inside for x in bz)]
    exact_u = np.full(n_uni, np.nan)
    if bz or inner:
        bza = np.array(bz + inner)
        b_out = np.array([True] * len(bz) + [False] * len(inner))
        tb = t_of_z(kind, za, L, bza)
        tol = 1e-9 * (t1 - t0)
        keep = _far_from_nodes(tu, tb, tol)
        # snap uniform nodes that coincide with a breakpoint onto it
        for x, zx in zip(tb[~keep], bza[~keep]):
            j = int(np.argmin(np.abs(tu - x)))
            tu[j] = x
            exact_u[j] = zx
        t = np.concatenate([tu, tb[keep]])
        out = np.concatenate([is_out, b_out[keep]])
        exact = np.concatenate([exact_u, bza[keep]])
        order = np.argsort(t, kind="stable")
        t, out, exact = t[order], out[order], exact[order]
    else:
        t, out, exact = tu, is_out, exact_u
    z, dzdt, w, ratio = t_map(kind, za, L, t)
    fixed = ~np.isnan(exact)
    z[fixed] = exact[fixed]  # joints and condition points exactly
    z[0], z[-1] = za, zb
    grid = PassGrid(mandrel, za, zb, left, right, t, z, dzdt, w, ratio, out, np.zeros(len(t) - 1, dtype=np.int64))
    tm = 0.5 * (t[:-1] + t[1:])
    zm, dzm, wm, ratm = t_map(kind, za, L, tm)
    seg = segment_index(mandrel, zm)
    grid.seg = seg
    zl, zr = z[:-1], z[1:]
    grid.zs = (zl, zm, zr)
    ns = len(seg)
    h = np.diff(t)
    tg1, tg2 = t[:-1] + _GL_A * h, t[:-1] + _GL_B * h
    z1, dz1, w1, rat1 = t_map(kind, za, L, tg1)
    z2, dz2, w2, rat2 = t_map(kind, za, L, tg2)
    r5, dr5, d2r5 = eval_on_segments(mandrel, np.concatenate([zl, zm, zr, z1, z2]), np.tile(seg, 5))
    geo = {}
    for i, name in enumerate(("L", "M", "R", "G1", "G2")):
        sl = slice(i * ns, (i + 1) * ns)
        geo[name] = (r5[sl], dr5[sl], d2r5[sl])
    geo["G1_map"] = (dz1, w1, rat1)
    geo["G2_map"] = (dz2, w2, rat2)
    grid.geo = geo
    grid.h = np.diff(t).tolist()
    grid.geo["mid_map"] = (dzm, wm, ratm)
    a_l, b_l = riccati_ab(*geo["L"])
    a_m, b_m = riccati_ab(*geo["M"])
    a_r, b_r = riccati_ab(*geo["R"])
    grid.A = ((a_l * dzdt[:-1]).tolist(), (a_m * dzm).tolist(), (a_r * dzdt[1:]).tolist())
    grid.B = ((b_l * dzdt[:-1]).tolist(), (b_m * dzm).tolist(), (b_r * dzdt[1:]).tolist())
    return grid


def node_geometry(grid: PassGrid) -> tuple[FloatArray, FloatArray, FloatArray]:
    """r, r', r'' at the nodes (left-node values of each step; the last node from the last step)."""
    rl, drl, d2l = grid.geo["L"]
    rr, drr, d2rr = grid.geo["R"]
    return (np.append(rl, rr[-1]), np.append(drl, drr[-1]), np.append(d2l, d2rr[-1]))


def lower_bound(grid: PassGrid, margin: float = 1e-5) -> FloatArray:
    """Smallest admissible C at each node: the no-bridging bound of (6) where r'' > 0, else 0.

    Each node takes the largest bound over its own parallel and the Gauss and mid points of the
    two steps next to it (so the line also clears the bound between nodes), raised by the
    relative ``margin``.
    """
    out = np.zeros(grid.n)
    for side in ("L", "R", "M", "G1", "G2"):
        r, dr, d2r = grid.geo[side]
        with np.errstate(invalid="ignore", divide="ignore"):
            cb2 = np.where(d2r > 0, r**3 * d2r / (1.0 + dr * dr + r * d2r), 0.0)
        cb = np.sqrt(np.maximum(cb2, 0.0))
        if side != "R":
            out[:-1] = np.maximum(out[:-1], cb)
        if side != "L":
            out[1:] = np.maximum(out[1:], cb)
    return out * (1.0 + margin)


# ------------------------------------------------------------------------------------------------
# RK4 on ODE (3) in t
# ------------------------------------------------------------------------------------------------
def integrate(
    grid: PassGrid,
    i0: int,
    i1: int,
    c0: float,
    lam: float,
    sens: bool = False,
    lo: FloatArray | None = None,
    hi: FloatArray | None = None,
) -> tuple[list[float], list[float] | None]:
    """Integrate C from node i0 (value ``c0``) to node i1 (either direction) with constant ``lam``.

    Returns the C values at nodes i0..i1 (in travel order) and, with ``sens``, dC/dλ.  With
    ``lo``/``hi`` the values are clipped to [lo, hi] after every step (reachable-set envelopes).
    """
    from engine.winding_jit import rk4

    got = rk4(grid, i0, i1, c0, lam, sens, lo, hi)   # the same loop compiled (the same numbers), where built
    if got is not None:
        return got
    hs = grid.h
    AL, AM, AR = grid.A
    BL, BM, BR = grid.B
    lo_l = lo.tolist() if lo is not None else None
    hi_l = hi.tolist() if hi is not None else None
    lam = float(lam)
    step = 1 if i1 >= i0 else -1
    c = float(c0)
    s = 0.0
    cs = [c]
    ss: list[float] | None = [s] if sens else None
    j = i0
    while j != i1:
        if step > 0:
            k = j
            h = hs[k]
            a1, b1, a2, b2, a3, b3 = AL[k], BL[k], AM[k], BM[k], AR[k], BR[k]
        else:
            k = j - 1
            h = -hs[k]
            a1, b1, a2, b2, a3, b3 = AR[k], BR[k], AM[k], BM[k], AL[k], BL[k]
        hh = 0.5 * h
        g1 = a1 * c * c + b1
        k1 = lam * g1
        c2 = c + hh * k1
        g2 = a2 * c2 * c2 + b2
        k2 = lam * g2
        c3 = c + hh * k2
        g3 = a2 * c3 * c3 + b2
        k3 = lam * g3
        c4 = c + h * k3
        g4 = a3 * c4 * c4 + b3
        k4 = lam * g4
        if sens:
            m1 = g1 + 2.0 * lam * a1 * c * s
            s2 = s + hh * m1
            m2 = g2 + 2.0 * lam * a2 * c2 * s2
            s3 = s + hh * m2
            m3 = g3 + 2.0 * lam * a2 * c3 * s3
            s4 = s + h * m3
            m4 = g4 + 2.0 * lam * a3 * c4 * s4
            s = s + h * (m1 + 2.0 * m2 + 2.0 * m3 + m4) / 6.0
            ss.append(s)  # type: ignore[union-attr]
        c = c + h * (k1 + 2.0 * k2 + 2.0 * k3 + k4) / 6.0
        j += step
        if lo_l is not None and c < lo_l[j]:
            c = lo_l[j]
        if hi_l is not None and c > hi_l[j]:
            c = hi_l[j]
        if not math.isfinite(c) or abs(c) > 1e12:
            c = math.copysign(1e12, c) if math.isfinite(c) else 1e12
        cs.append(c)
    return cs, ss


def step_value(grid: PassGrid, k: int, c: float, lam: float, forward: bool) -> float:
    """One RK4 step across step ``k`` from its left (``forward``) or right node."""
    AL, AM, AR = grid.A
    BL, BM, BR = grid.B
    if forward:
        h = grid.h[k]
        a1, b1, a2, b2, a3, b3 = AL[k], BL[k], AM[k], BM[k], AR[k], BR[k]
    else:
        h = -grid.h[k]
        a1, b1, a2, b2, a3, b3 = AR[k], BR[k], AM[k], BM[k], AL[k], BL[k]
    hh = 0.5 * h
    k1 = lam * (a1 * c * c + b1)
    c2 = c + hh * k1
    k2 = lam * (a2 * c2 * c2 + b2)
    c3 = c + hh * k2
    k3 = lam * (a2 * c3 * c3 + b2)
    c4 = c + h * k3
    k4 = lam * (a3 * c4 * c4 + b3)
    return c + h * (k1 + 2.0 * k2 + 2.0 * k3 + k4) / 6.0


def step_lambda(grid: PassGrid, k: int, c: float, target: float, forward: bool, lam_guess: float) -> float:
    """The λ for which one RK4 step across step ``k`` from ``c`` lands on ``target`` (secant)."""
    l0, l1 = 0.0, lam_guess if lam_guess != 0.0 else 1e-3
    f0 = step_value(grid, k, c, l0, forward) - target
    f1 = step_value(grid, k, c, l1, forward) - target
    for _ in range(30):
        if f1 == f0:
            break
        l2 = l1 - f1 * (l1 - l0) / (f1 - f0)
        l0, f0 = l1, f1
        l1 = l2
        f1 = step_value(grid, k, c, l1, forward) - target
        if abs(f1) < 1e-13 * max(1.0, abs(target)):
            break
    return l1


def shoot(grid: PassGrid, i0: int, i1: int, c0: float, c1: float, lam0: float = 0.0) -> tuple[float, list[float]]:
    """Constant λ carrying C from ``c0`` at node i0 to ``c1`` at node i1.

    Newton on dC/dλ (the variational equation is integrated alongside); if Newton does not
    converge, a scan for a sign change of the residual and Brent's method.  Raises ``ValueError``
    when no λ is found.
    """
    tol = 1e-12 * max(1.0, abs(c1))
    for start in dict.fromkeys((lam0, 0.0)):
        lam = start
        cs, ss = integrate(grid, i0, i1, c0, lam, sens=True)
        res = cs[-1] - c1
        if not (math.isfinite(res) and abs(res) < 1e11):
            continue
        for _ in range(60):
            if abs(res) < tol:
                return lam, cs
            d = ss[-1] if ss else 0.0  # type: ignore[index]
            if d == 0.0 or not math.isfinite(d):
                break
            dl = -res / d
            for _half in range(40):
                cand = lam + dl
                cs2, ss2 = integrate(grid, i0, i1, c0, cand, sens=True)
                res2 = cs2[-1] - c1
                if math.isfinite(res2) and abs(res2) < abs(res):
                    lam, cs, ss, res = cand, cs2, ss2, res2
                    break
                dl *= 0.5
            else:
                break
        if abs(res) < 1e-9:
            return lam, cs
    return _shoot_bracket(grid, i0, i1, c0, c1)


def _shoot_bracket(grid: PassGrid, i0: int, i1: int, c0: float, c1: float) -> tuple[float, list[float]]:
    from scipy.optimize import brentq

    def res(lam: float) -> float:
        v = integrate(grid, i0, i1, c0, lam)[0][-1] - c1
        return v if math.isfinite(v) else math.copysign(1e12, lam)

    r0 = res(0.0)
    if r0 == 0.0:
        return 0.0, integrate(grid, i0, i1, c0, 0.0)[0]
    for sign in (1.0, -1.0):
        a, fa = 0.0, r0
        mag = 1e-3
        while mag <= 16.0:
            b = sign * mag
            fb = res(b)
            if abs(fb) < 1e11 and fa * fb < 0:
                lam = float(brentq(res, min(a, b), max(a, b), xtol=1e-15, rtol=1e-15, maxiter=200))
                cs = integrate(grid, i0, i1, c0, lam)[0]
                if abs(cs[-1] - c1) < 1e-9:
                    return lam, cs
                break
            if abs(fb) >= 1e11:
                break
            a, fa = b, fb
            mag *= 1.5
    raise ValueError(f"no constant λ with |λ| <= 16 carries C from {c0:.6g} to {c1:.6g} mm")


# ------------------------------------------------------------------------------------------------
# Twist and band length
# ------------------------------------------------------------------------------------------------
@dataclass
class PassProfile:
    """C, λ per node (λ per step) of one pass, and the derived twist v and band length s."""

    C: FloatArray
    lam_step: FloatArray
    v: FloatArray = field(default=None)  # type: ignore[assignment]
    s: FloatArray = field(default=None)  # type: ignore[assignment]
    q_ends: tuple[float, float] = (math.nan, math.nan)


def twist(grid: PassGrid, C: FloatArray, lam_step: FloatArray) -> tuple[FloatArray, FloatArray, tuple[float, float]]:
    """Twist v (rad) and laid band length s (mm) at the nodes (3-point Gauss-Legendre per step).

    Raises ``ValueError`` if the line reaches C = r inside the pass or cannot turn around
    tangentially (``r' − C'`` of the wrong sign at a turnaround).
    """
    t = grid.t
    h = np.diff(t)
    rl, drl, d2l = grid.geo["L"]
    rm, drm, d2m = grid.geo["M"]
    rr, drr, d2rr = grid.geo["R"]
    dzm, wm, ratm = grid.geo["mid_map"]
    al, bl = riccati_ab(rl, drl, d2l)
    ar, br = riccati_ab(rr, drr, d2rr)
    cl, cr = C[:-1], C[1:]
    fl = lam_step * grid.dzdt[:-1] * (al * cl * cl + bl)
    fr = lam_step * grid.dzdt[1:] * (ar * cr * cr + br)
    cm = 0.5 * (cl + cr) + h * (fl - fr) / 8.0

    def dvdt(r: FloatArray, dr: FloatArray, c: FloatArray, q: FloatArray, ratio: FloatArray) -> FloatArray:
        return c * np.sqrt(1.0 + dr * dr) / (r * np.sqrt((r + c) * q)) * ratio

    def hermite(th: float) -> FloatArray:
        return ((2 * th**3 - 3 * th**2 + 1) * cl + (th**3 - 2 * th**2 + th) * h * fl
                + (-2 * th**3 + 3 * th**2) * cr + (th**3 - th**2) * h * fr)

    with np.errstate(divide="ignore", invalid="ignore"):
        ql = (rl - cl) / grid.w[:-1]
        qr = (rr - cr) / grid.w[1:]
        qm = (rm - cm) / wm
    q_a = q_b = math.nan
    L = grid.L
    if grid.left == TURN:
        wp = L if grid.kind == "both" else 1.0
        q_a = (drl[0] - lam_step[0]) / wp
        ql[0] = q_a
    if grid.right == TURN:
        wp = L if grid.kind == "both" else 1.0
        q_b = (lam_step[-1] - drr[-1]) / wp
        qr[-1] = q_b
    for name, q in (("start", ql), ("mid", qm), ("end", qr)):
        bad = ~(q > 0)
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            zz = grid.zs[{"start": 0, "mid": 1, "end": 2}[name]][k]
            raise ValueError(f"C reaches the local radius at z = {zz:.6g} mm before the intended turnaround")
    # 3-point Gauss-Legendre per step (6th order; the turnaround ends are never evaluated)
    dv = np.zeros(len(h))
    ds = np.zeros(len(h))
    for name, th, wgt in (("G1", _GL_A, 5.0 / 18.0), ("M", 0.5, 8.0 / 18.0), ("G2", _GL_B, 5.0 / 18.0)):
        r, dr, _ = grid.geo[name]
        dz, w, rat = grid.geo["mid_map"] if name == "M" else grid.geo[name + "_map"]
        c = hermite(th)
        with np.errstate(divide="ignore", invalid="ignore"):
            q = (r - c) / w
        if not (q > 0).all():
            k = int(np.flatnonzero(~(q > 0))[0])
            raise ValueError(f"C reaches the local radius near z = {grid.zs[1][k]:.6g} mm before the turnaround")
        ph = dvdt(r, dr, c, q, rat)
        dv += wgt * ph
        ds += wgt * np.sqrt((1.0 + dr * dr) * dz**2 + (r * ph) ** 2)
    dv *= h
    ds *= h
    v = np.concatenate([[0.0], np.cumsum(dv)])
    s = np.concatenate([[0.0], np.cumsum(ds)])
    return v, s, (q_a, q_b)


# ------------------------------------------------------------------------------------------------
# Minimax (5)-(6): reachable tubes and the direct search
# ------------------------------------------------------------------------------------------------
@dataclass
class Tube:
    """Forward-reachable [lo_f, up_f] and backward-viable [lo_b, up_b] envelopes for one Λ."""

    ok: bool
    lo_f: FloatArray
    up_f: FloatArray
    lo_b: FloatArray
    up_b: FloatArray
    fail_z: float = math.nan
    reason: str = ""
    i0: int = 0
    i1: int = -1


def _sweep(
    grid: PassGrid, lam_max: float, lo: FloatArray, hi: FloatArray, points: dict[int, float], forward: bool,
    i0: int, i1: int,
) -> tuple[bool, FloatArray, FloatArray, int]:
    n = grid.n
    idx = range(i0, i1 + 1) if forward else range(i1, i0 - 1, -1)
    up = np.full(n, np.nan)
    dn = np.full(n, np.nan)
    first = True
    u = d = 0.0
    prev = 0
    tol = 1e-9
    for i in idx:
        if first:
            if i in points:
                u = d = points[i]
            else:
                u, d = float(hi[i]), float(lo[i])
            first = False
        else:
            k = prev if forward else i
            # upper envelope: +Λ going forward, −Λ going backward (both raise C in travel order)
            u = step_value(grid, k, u, lam_max if forward else -lam_max, forward)
            d = step_value(grid, k, d, -lam_max if forward else lam_max, forward)
            if u > hi[i]:
                u = float(hi[i])
            if d < lo[i]:
                d = float(lo[i])
            if i in points:
                c = points[i]
                if d - tol <= c <= u + tol:
                    u = d = c
                else:
                    up[i], dn[i] = u, d
                    return False, up, dn, i
            if d > u + tol:
                up[i], dn[i] = u, d
                return False, up, dn, i
        up[i], dn[i] = u, d
        prev = i
    return True, up, dn, -1


def tube(
    grid: PassGrid, lam_max: float, lo: FloatArray, hi: FloatArray, points: dict[int, float],
    i0: int = 0, i1: int | None = None,
) -> Tube:
    """Envelopes of all lines with |λ| <= ``lam_max`` inside [lo, hi] through the point constraints,
    on the nodes ``i0..i1`` (default: the whole pass)."""
    i1 = grid.n - 1 if i1 is None else i1
    ok_f, up_f, lo_f, kf = _sweep(grid, lam_max, lo, hi, points, True, i0, i1)
    if not ok_f:
        return Tube(False, lo_f, up_f, lo_f, up_f, float(grid.z[kf]), "forward envelope empty")
    ok_b, up_b, lo_b, kb = _sweep(grid, lam_max, lo, hi, points, False, i0, i1)
    if not ok_b:
        return Tube(False, lo_f, up_f, lo_b, up_b, float(grid.z[kb]), "backward envelope empty")
    sl = slice(i0, i1 + 1)
    width = np.minimum(up_f[sl], up_b[sl]) - np.maximum(lo_f[sl], lo_b[sl])
    if (width < -1e-9).any():
        k = int(np.argmin(width)) + i0
        return Tube(False, lo_f, up_f, lo_b, up_b, float(grid.z[k]), "envelopes do not overlap")
    return Tube(True, lo_f, up_f, lo_b, up_b, i0=i0, i1=i1)


def tube_path(grid: PassGrid, tb: Tube, lam_max: float) -> tuple[FloatArray, FloatArray]:
    """A line inside the tube: geodesic where it can be, on an envelope (λ = ±Λ) where it must.

    Starts at the pinch of the tube (its narrowest interior node) and runs both ways.  Returns C
    at the nodes and λ per step, filled on the tube's node range only.
    """
    n = grid.n
    i0, i1 = tb.i0, (tb.i1 if tb.i1 >= 0 else n - 1)
    upper = np.minimum(tb.up_f, tb.up_b)
    lower = np.maximum(tb.lo_f, tb.lo_b)
    width = upper - lower
    if i1 - i0 >= 2:
        k0 = int(np.argmin(width[i0 + 1 : i1])) + i0 + 1
    else:
        k0 = i0
    C = np.full(n, np.nan)
    lam = np.zeros(n - 1)
    C[k0] = 0.5 * (upper[k0] + lower[k0])
    # forward from the pinch: stay inside the backward-viable envelope
    c = C[k0]
    for k in range(k0, i1):
        nxt = step_value(grid, k, c, 0.0, True)
        target = min(max(nxt, tb.lo_b[k + 1]), tb.up_b[k + 1])
        if target != nxt:
            guess = lam_max if target > nxt else -lam_max
            lam[k] = step_lambda(grid, k, c, target, True, guess)
        c = target
        C[k + 1] = c
    c = C[k0]
    for k in range(k0 - 1, i0 - 1, -1):
        nxt = step_value(grid, k, c, 0.0, False)
        target = min(max(nxt, tb.lo_f[k]), tb.up_f[k])
        if target != nxt:
            guess = -lam_max if target > nxt else lam_max
            lam[k] = step_lambda(grid, k, c, target, False, guess)
        c = target
        C[k] = c
    return C, lam


def minimax_search(
    grid: PassGrid,
    lo: FloatArray,
    hi: FloatArray,
    points: dict[int, float],
    lam_start: float,
    lam_cap: float = 4.0,
    rel_tol: float = 1e-7,
    state: Any = None,
    i0: int = 0,
    i1: int | None = None,
) -> tuple[float, Tube]:
    """Smallest Λ for which a line with |λ| <= Λ satisfies (6) and the point constraints (bisection).

    Raises ``ValueError`` (message says where) when even ``lam_cap`` does not suffice.
    """
    from engine.state import check_cancel

    hi_l = max(lam_start, 1e-3)
    tb = tube(grid, hi_l, lo, hi, points, i0, i1)
    while not tb.ok:
        check_cancel(state)
        if hi_l >= lam_cap:
            raise ValueError(
                f"no line with |λ| <= {lam_cap:g} keeps the band on the surface; it fails at z = {tb.fail_z:.6g} mm "
                f"({tb.reason})"
            )
        hi_l = min(2.0 * hi_l, lam_cap)
        tb = tube(grid, hi_l, lo, hi, points, i0, i1)
    lo_l = lam_start if lam_start < hi_l else 0.0
    best = tb
    while hi_l - lo_l > rel_tol * max(hi_l, 1e-6):
        check_cancel(state)
        mid = 0.5 * (lo_l + hi_l)
        tm = tube(grid, mid, lo, hi, points, i0, i1)
        if tm.ok:
            hi_l, best = mid, tm
        else:
            lo_l = mid
    return hi_l, best
