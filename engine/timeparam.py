"""Time parametrization of a path by dynamic programming and a narrowing tube (seed 003, MATH.md §B).

Given a path ``X_c(s)`` (``c = 1..p``) sampled at nodes ``s_0 < ... < s_{N-1}`` together with
``dX_c/ds`` and ``d²X_c/ds²``, find the law ``s(t)`` -- equivalently ``ṡ(s)`` at the nodes -- that
traverses the path as fast as the limits allow:

* axis speeds ``|dX_c/ds|·ṡ <= V_c`` and accelerations ``|d²X_c/ds²·ṡ² + dX_c/ds·s̈| <= A_c``,
* the technological path speed ``ṡ <= ṡ_T`` and acceleration ``|s̈| <= s̈_T``,
* technological points (an ``s`` value or an interval, each with a label) with ``ṡ <= ṡ_TT``.

Public API
----------
``TechPoint``, ``TimeLimits``
    The limits (Tables 2-5 of the paper); ``limits_from_toml`` / ``limits_from_mapping`` read them.
``parametrize(path_s, X, dX, ddX, limits, method="tube", state=None) -> TimeLaw``
    ``method`` is ``"tube"`` (the paper's hybrid algorithm), ``"dp"`` (one classical DP with
    ``limits.levels`` speed levels) or ``"toppra"`` (the time-optimal reference, TOPP-RA).
``TimeLaw``
    Frozen result: ``s``, ``sdot`` (mm/s at the nodes), ``t`` (s at the nodes), ``total_time_s``,
    ``iterations`` (list of :class:`IterationLog`, the paper's Fig. 2), ``max_accel_ratio`` (worst
    ``|axis acceleration| / A_c`` on a fine sub-grid inside every interval), ``max_speed_ratio``,
    ``energy`` (curvature energy of ``ṡ(t)``), ``compute_s``, ``method``.
``block_feeds(law, s_block_ends, decimals=None) -> (durations_s, inverse_time_feed_per_min)``
    Per-NC-block durations and G93 inverse-time feed numbers (1/min); block ends are s values or
    node indices.  ``time_at(law, s)`` is the exact time at any s.
``curvature_energy(t, sdot, speed_unit=1000)``
    ``E = ∫ k² dt`` of the plane curve ``(t, ṡ(t))`` (ṡ in m/s by default; ``energy_mm`` in mm/s).
``prepare(...)``, ``evaluate_limits(prob, sdot)``
    The shared set-up and the limit ratios of any law (e.g. a law from elsewhere).

The state protocol: ``parametrize`` reports ``state.progress``, polls cancellation between tube
iterations (and inside long DP passes), and publishes every finished tube iteration as an
:class:`IterationLog` via ``state.partial`` (tube bounds, ``ṡ`` and the W/O touch masks for plots).

Model between nodes
-------------------
The path between two nodes is the quintic Hermite interpolant of ``X, dX, ddX`` (its "own
interpolation").  On a DP transition from ``ṡ_k`` (node ``i-1``) to ``ṡ_j`` (node ``i``) the path
acceleration ``u = s̈`` is constant, so ``ṡ²`` is linear in ``s`` and ``Δt = Δs / ((ṡ_k + ṡ_j)/2)``
is exact, as in the paper.  The axis acceleration inside the interval,
``a_c(τ) = X_c''(τ)·ṡ²(τ) + X_c'(τ)·u``, is a quartic in ``τ`` whose Bernstein coefficients are linear
in ``(ṡ_k², u)``; requiring every Bernstein coefficient to lie in ``[-A_c, A_c]`` guarantees the limit
on the whole interval, not only at the arrival node (the paper's check, kept as
``accel_check="arrival"`` for comparison).  Axis speeds are bounded the same way (Bernstein bound of
``|X_c'|`` on both intervals adjacent to a node; ``ṡ`` is monotone inside an interval).

Tube levels
-----------
The nominal run spaces its M levels uniformly in ``[0, ṡ_max]``; inside the tube they are clustered
toward the centre (the previous law), ``TimeLimits.tube_cluster`` (0 = uniform).  See
docs/timeparam.md for why and for the measured effect.

Speed of the DP
---------------
All constraints of one interval are half-planes in ``(ṡ_k², u)``; after normalising them to
``n·z <= 1`` only the vertices of the convex hull of the normals matter, found once, vectorised over
intervals.  They bound the feasible polygon in ``(ṡ²_{i-1}, ṡ²_i)``; for a level ``ṡ_j`` the
feasible ``ṡ_k`` form one window ``[k_lo, k_hi]`` read off the polygon's left/right chains (closed
form, one ``np.interp``).  Only those candidates are costed (flat, vectorised, in chunks), and the
sequential pass does one gather + one integer ``minimum.reduceat`` per interval (the window position
rides in the low 12 bits of the float cost, giving min and argmin together).
"""

from __future__ import annotations

import bisect
import functools
import math
import os
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from engine.errors import InfeasibleError, InputError
from engine.resources import read_toml
from engine.state import State, check_cancel
from engine.timeparam_jit import _sweep_back  # (compiled there too; the numpy pass runs it on lists)

__all__ = [
    "IterationLog",
    "TechPoint",
    "TimeLaw",
    "TimeLimits",
    "block_feeds",
    "curvature_energy",
    "evaluate_limits",
    "limits_from_mapping",
    "limits_from_toml",
    "load_path_npz",
    "parametrize",
    "prepare",
    "time_at",
]

METHODS = ("tube", "dp", "toppra")
_N_SUB = 16  # sub-points per interval for the reported limit ratios
_MAX_LEVELS = 4096  # the DP packs the level index into 12 bits
MIN_USER_LEVELS = 5
"""Fewest speed levels a job, a limits file or ``--levels`` may ask for (the job schema's minimum: with fewer
the DP has no speed between rest and the cap and finds no law)."""


# --------------------------------------------------------------------------------------------------
# Inputs and outputs
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class TechPoint:
    """A technological point: ``ṡ <= sdot_max`` (mm/s) at ``s`` or over ``[s_from, s_to]`` (mm)."""

    sdot_max: float
    s: float | None = None
    s_from: float | None = None
    s_to: float | None = None
    label: str = ""

    def describe(self) -> str:
        """``"'feed' at s = 854.27 mm"`` or ``"'x' over s = 10.00..20.00 mm"``."""
        name = f"'{self.label}'" if self.label else "technological point"
        if self.s is not None:
            return f"{name} at s = {self.s:.2f} mm"
        return f"{name} over s = {self.s_from:.2f}..{self.s_to:.2f} mm"


@dataclass(frozen=True)
class TimeLimits:
    """Limits and algorithm parameters (the paper's Tables 2-5).

    Attributes
    ----------
    v_max, a_max:
        Axis speed (unit/s) and acceleration (unit/s²) limits, one per coordinate (rad or mm).
    sdot_max, sddot_max:
        Technological path speed ṡ_T,max (mm/s) and acceleration s̈_T,max (mm/s²); ``inf`` = none.
    levels:
        M, the number of speed levels per node.
    penalty:
        K, the acceleration penalty coefficient (s per (mm/s²)²).
    tube_share, stop_percent:
        Δ_sh (tube half-width as a share of max ṡ of the nominal run) and Δ_p (%).
    sdot_start, sdot_end:
        Path speed at the first and the last node (mm/s).
    points:
        Technological points.
    max_iterations:
        Safety cap on tube iterations.
    accel_check:
        ``"interval"`` (limits hold inside every interval) or ``"arrival"`` (the paper's check at the
        arrival node only).
    tube_cluster:
        Placement of the M levels inside the tube: ``ṡ = lo + (hi - lo)·(1 + (ξ + aξ³)/(1 + a))/2``
        for ξ uniform in [-1, 1]; ``a = 0`` is uniform, the default ``a = 8`` makes the levels near the
        tube's centre (the previous solution) 9x denser (the paper does not fix the placement).
    coarse:
        Tube method: when the nodes are denser than one level step per interval (see
        :func:`_group_length`), solve on groups of consecutive intervals with constant s̈ in each group
        (every node's constraints kept exactly) and interpolate ṡ² to the nodes; ``False`` = always on
        the given nodes (docs/timeparam.md, "Node density").
    sweep:
        Tube method: after the tube, sweep the same constraints once more (:func:`_sweep`: the largest
        admissible speed node by node, as TOPP-RA does) and keep that law where it is faster; ``False`` =
        the tube's law as it is (docs/timeparam.md, "The final sweep").
    """

    v_max: tuple[float, ...]
    a_max: tuple[float, ...]
    sdot_max: float = math.inf
    sddot_max: float = math.inf
    levels: int = 100
    penalty: float = 0.5e-11
    tube_share: float = 0.1
    stop_percent: float = 0.5
    sdot_start: float = 0.0
    sdot_end: float = 0.0
    points: tuple[TechPoint, ...] = ()
    max_iterations: int = 60
    accel_check: str = "interval"
    tube_cluster: float = 8.0
    coarse: bool = True
    sweep: bool = True


@dataclass(frozen=True)
class IterationLog:
    """One DP run of the tube algorithm (a line of the paper's Fig. 2 plus the arrays of Fig. 3).

    ``half_width`` is the tube half-width sh used in this iteration (``None`` for the nominal run);
    ``decrease_percent`` is P = (1 - t_sp(r)/t_sp(r-1))·100 (``None`` for r = 1); ``w_touches`` and
    ``o_touches`` count touching fragments (runs of nodes) off and on a physical/technological limit.
    """

    r: int
    total_time_s: float
    specific_time: float
    half_width: float | None
    w_touches: int
    o_touches: int
    decrease_percent: float | None
    halved: bool
    stop: bool
    s: np.ndarray = field(repr=False)
    sdot: np.ndarray = field(repr=False)
    lower: np.ndarray = field(repr=False)
    upper: np.ndarray = field(repr=False)
    w_mask: np.ndarray = field(repr=False)
    o_mask: np.ndarray = field(repr=False)
    note: str = ""

    def as_dict(self) -> dict[str, Any]:
        """The JSON-able summary (no arrays)."""
        return {
            "r": self.r,
            "total_time_s": self.total_time_s,
            "specific_time": self.specific_time,
            "half_width": self.half_width,
            "w_touches": self.w_touches,
            "o_touches": self.o_touches,
            "decrease_percent": self.decrease_percent,
            "halved": self.halved,
            "stop": self.stop,
            "note": self.note,
        }

    def text(self) -> str:
        """The paper's Fig. 2 wording, in English."""
        lines = [f"Iteration {self.r}. Specific time {self.specific_time:.7f} s/mm "
                 f"(total {self.total_time_s:.4f} s)"]
        if self.half_width is not None:
            lines.append(f"  Tube half-width: {self.half_width:g} mm/s; W touches {self.w_touches}, "
                         f"O touches {self.o_touches}")
            if self.w_touches == 0:
                lines.append("  > no touches")
        if self.decrease_percent is not None:
            lines.append(f"  >> decrease of specific time: {self.decrease_percent:.5f} %")
        if self.note:
            lines.append(f"  {self.note}")
        if self.stop:
            lines.append("  --- >>> done <<< ---")
        return "\n".join(lines)


@dataclass(frozen=True)
class TimeLaw:
    """A time law ``ṡ(s)`` on the path nodes, with its quality figures."""

    method: str
    s: np.ndarray
    sdot: np.ndarray
    t: np.ndarray
    total_time_s: float
    iterations: list[IterationLog]
    max_accel_ratio: float
    max_speed_ratio: float
    max_sddot_ratio: float
    energy: float
    compute_s: float
    levels: int
    energy_mm: float = float("nan")
    node_group: int = 1
    """Consecutive intervals per DP interval (1 = the DP ran on the given nodes; see ``TimeLimits.coarse``)."""
    sweep_gain_s: float = 0.0
    """Time (s) the final sweep saved on the tube's law (0: the tube's law is kept; ``TimeLimits.sweep``)."""

    @property
    def sddot(self) -> np.ndarray:
        """Constant path acceleration (mm/s²) on each of the N-1 intervals."""
        return (self.sdot[1:] ** 2 - self.sdot[:-1] ** 2) / (2.0 * np.diff(self.s))

    def summary(self) -> dict[str, Any]:
        """JSON-able dictionary (the CLI's ``--json`` output)."""
        return {
            "method": self.method,
            "levels": self.levels,
            "total_time_s": self.total_time_s,
            "compute_s": self.compute_s,
            "max_accel_ratio": self.max_accel_ratio,
            "max_speed_ratio": self.max_speed_ratio,
            "max_sddot_ratio": self.max_sddot_ratio,
            "energy": self.energy,
            "energy_mm": self.energy_mm,
            "node_group": self.node_group,
            "sweep_gain_s": self.sweep_gain_s,
            "iterations": [it.as_dict() for it in self.iterations],
            "s": self.s,
            "sdot": self.sdot,
            "t": self.t,
        }


# --------------------------------------------------------------------------------------------------
# Reading limits and paths
# --------------------------------------------------------------------------------------------------


def _num(d: Mapping[str, Any], key: str, default: float | None, file: str | None, *,
         positive: bool = False, nonneg: bool = False) -> float:
    if key not in d:
        if default is None:
            raise InputError("missing", file=file, field=key)
        return float(default)
    v = d[key]
    if isinstance(v, bool) or not isinstance(v, int | float):
        raise InputError(f"must be a number, got {v!r}", file=file, field=key)
    v = float(v)
    if math.isnan(v) or (positive and not v > 0) or (nonneg and v < 0):
        raise InputError(f"must be {'> 0' if positive else '>= 0'}, got {v!r}", file=file, field=key)
    return v


def limits_from_mapping(d: Mapping[str, Any], file: str | None = None) -> TimeLimits:
    """Build :class:`TimeLimits` from a TOML-like mapping (keys as in the CLI's LIMITS.toml)."""
    known = {"v_max", "a_max", "sdot_max", "sddot_max", "levels", "penalty", "tube_share",
             "stop_percent", "sdot_start", "sdot_end", "points", "max_iterations", "accel_check",
             "tube_cluster", "sweep"}
    for k in d:
        if k not in known:
            raise InputError(f"unknown key (known: {', '.join(sorted(known))})", file=file, field=k)
    vecs = {}
    for key in ("v_max", "a_max"):
        v = d.get(key)
        if not isinstance(v, list) or not v:
            raise InputError(f"must be a non-empty list of numbers, got {v!r}", file=file, field=key)
        arr = []
        for n, x in enumerate(v):
            if isinstance(x, bool) or not isinstance(x, int | float) or not float(x) > 0:
                raise InputError(f"item {n + 1} must be a number > 0, got {x!r}", file=file, field=key)
            arr.append(float(x))
        vecs[key] = tuple(arr)
    if len(vecs["v_max"]) != len(vecs["a_max"]):
        raise InputError(f"v_max has {len(vecs['v_max'])} items but a_max has {len(vecs['a_max'])}",
                         file=file, field="a_max")
    levels = d.get("levels", 100)
    if isinstance(levels, bool) or not isinstance(levels, int) or not MIN_USER_LEVELS <= levels <= _MAX_LEVELS:
        raise InputError(f"must be an integer in {MIN_USER_LEVELS}..{_MAX_LEVELS}, got {levels!r}", file=file,
                         field="levels")
    maxit = d.get("max_iterations", 60)
    if isinstance(maxit, bool) or not isinstance(maxit, int) or maxit < 1:
        raise InputError(f"must be an integer >= 1, got {maxit!r}", file=file, field="max_iterations")
    check = d.get("accel_check", "interval")
    if check not in ("interval", "arrival"):
        raise InputError(f"must be 'interval' or 'arrival', got {check!r}", file=file, field="accel_check")
    sweep = d.get("sweep", True)
    if not isinstance(sweep, bool):
        raise InputError(f"must be true or false, got {sweep!r}", file=file, field="sweep")
    points = []
    raw_points = d.get("points", [])
    if not isinstance(raw_points, list):
        raise InputError("must be an array of tables [[points]]", file=file, field="points")
    for n, pt in enumerate(raw_points):
        fld = f"points[{n + 1}]"
        if not isinstance(pt, Mapping):
            raise InputError(f"must be a table, got {pt!r}", file=file, field=fld)
        label = str(pt.get("label", f"point {n + 1}"))
        extra = set(pt) - {"s", "s_from", "s_to", "sdot_max", "label"}
        if extra:
            raise InputError(f"unknown key(s) {sorted(extra)}", file=file, field=fld)
        vmax = _num(pt, "sdot_max", None, file, nonneg=True) if "sdot_max" in pt else None
        if vmax is None:
            raise InputError(f"'{label}': sdot_max is missing", file=file, field=fld)
        if "s" in pt and ("s_from" in pt or "s_to" in pt):
            raise InputError(f"'{label}': give either s or s_from/s_to, not both", file=file, field=fld)
        if "s" in pt:
            points.append(TechPoint(vmax, s=_num(pt, "s", None, file), label=label))
        elif "s_from" in pt and "s_to" in pt:
            a, b = _num(pt, "s_from", None, file), _num(pt, "s_to", None, file)
            if b < a:
                raise InputError(f"'{label}': s_to = {b} is before s_from = {a}", file=file, field=fld)
            points.append(TechPoint(vmax, s_from=a, s_to=b, label=label))
        else:
            raise InputError(f"'{label}': needs s, or s_from and s_to", file=file, field=fld)
    return TimeLimits(
        v_max=vecs["v_max"], a_max=vecs["a_max"],
        sdot_max=_num(d, "sdot_max", math.inf, file, positive=True),
        sddot_max=_num(d, "sddot_max", math.inf, file, positive=True),
        levels=int(levels),
        penalty=_num(d, "penalty", 0.5e-11, file, nonneg=True),
        tube_share=_num(d, "tube_share", 0.1, file, positive=True),
        stop_percent=_num(d, "stop_percent", 0.5, file, positive=True),
        sdot_start=_num(d, "sdot_start", 0.0, file, nonneg=True),
        sdot_end=_num(d, "sdot_end", 0.0, file, nonneg=True),
        points=tuple(points), max_iterations=int(maxit), accel_check=str(check),
        tube_cluster=_num(d, "tube_cluster", 8.0, file, nonneg=True), sweep=sweep,
    )


def limits_from_toml(path: str | Path) -> TimeLimits:
    """Read a LIMITS.toml file (see :func:`limits_from_mapping`)."""
    path = Path(path)
    return limits_from_mapping(read_toml(path), file=str(path))


def load_path_npz(path: str | Path) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Read ``s`` (N,), ``X``, ``dX``, ``ddX`` (N, p) from an ``.npz`` file."""
    from engine.fileio import load_npz_arrays

    path = Path(path)
    arrs = load_npz_arrays(path, {"s": 1, "X": 2, "dX": 2, "ddX": 2})
    try:
        s, X, dX, ddX = _validate(arrs["s"], arrs["X"], arrs["dX"], arrs["ddX"], None)
    except InputError as exc:
        raise exc.at(file=path) from None
    return s, X, dX, ddX


# --------------------------------------------------------------------------------------------------
# Problem set-up: interpolation, speed caps, constraint rows
# --------------------------------------------------------------------------------------------------

# power basis (degree 4) -> Bernstein basis: b_m = sum_{l<=m} C(m,l)/C(4,l) c_l
_P2B = np.array([[math.comb(m, l) / math.comb(4, l) if l <= m else 0.0 for l in range(5)]
                 for m in range(5)])


@dataclass
class _Problem:
    s: np.ndarray            # (N,)
    h: np.ndarray            # (N-1,)
    p: int
    d1: np.ndarray           # (N-1, p, 5) power coefficients in tau of X'(s)
    d2: np.ndarray           # (N-1, p, 4) power coefficients in tau of X''(s)
    cap_v: np.ndarray        # (N,) physical speed cap from axis speeds
    cap_tech: np.ndarray     # (N,) min(sdot_T, sdot_TT)
    cap: np.ndarray          # (N,) combined
    cap_dp: np.ndarray       # (N,) cap, tightened to the speeds reachable from the start and the end
    xn: np.ndarray           # (N-1,) normaliser of x_j at node i (box half-size)
    rq: np.ndarray           # right chains x_k = R(x_j), abscissa x_j/xn + 3i (flat)
    rk: np.ndarray
    lq: np.ndarray           # left chains x_k = L(x_j)
    lk: np.ndarray
    xjb: np.ndarray          # (N-1,) x_j range of each interval's polygon
    xjt: np.ndarray
    rows: np.ndarray         # (N-1, R, 2) all normalised rows n.(x_k, u) <= 1 (for brute force)
    limits: TimeLimits
    point_nodes: list[tuple[TechPoint, np.ndarray]]
    hull_rows: np.ndarray | None = None   # rows with the provably redundant ones zeroed (for the hull)
    ipos: np.ndarray | None = None        # the ± pairs of rows: rows[:, ineg] == -rows[:, ipos]
    ineg: np.ndarray | None = None
    slopes: tuple | None = None   # the compiled pass's constants: chain slopes, 2h, K/4h², uniform h
    chain_slopes: tuple | None = None     # (rs, ls) from the compiled chains: np.diff(rk)/np.diff(rq), left alike
    work: list = field(default_factory=list, repr=False)   # the compiled pass's (N, M) arrays, kept between passes
    fine_hull: tuple | None = field(default=None, repr=False)   # (allr, order, m) of the intervals' box rows, made
    #                                                              by _coarse_problem, reused by _with_chains


MAX_PATH_VALUE = 1e9
"""Largest |s| (mm) and |X|, |dX|, |ddX| (axis units, per mm, per mm²) of a path: beyond it the numbers are
a unit mistake and their squares would overflow the interval polynomials."""


def _validate(path_s: Any, X: Any, dX: Any, ddX: Any, limits: TimeLimits | None) -> tuple[np.ndarray, ...]:
    s = np.asarray(path_s, dtype=float)
    if s.ndim != 1 or s.size < 2:
        raise InputError(f"s must be a 1-D array of at least 2 values, got shape {s.shape}", field="s")
    n = s.size
    arrs = []
    for name, a in (("X", X), ("dX", dX), ("ddX", ddX)):
        a = np.asarray(a, dtype=float)
        if a.ndim == 1:
            a = a[:, None]
        if a.ndim != 2 or a.shape[0] != n:
            raise InputError(f"{name} must have shape (N={n}, p), got {a.shape}", field=name)
        if not np.all(np.isfinite(a)):
            raise InputError(f"{name} has non-finite values", field=name)
        big = np.array([], int)
        if a.size and not np.abs(a).max() <= MAX_PATH_VALUE:          # (the rows only where one is too big)
            big = np.flatnonzero(np.abs(a).max(axis=1) > MAX_PATH_VALUE)
        if big.size:
            raise InputError(f"{name}[{int(big[0])}] = {np.abs(a[big[0]]).max():g} is beyond {MAX_PATH_VALUE:g} "
                             "(axis units per mm of path): check the units", field=name)
        arrs.append(a)
    p = arrs[0].shape[1]
    if arrs[1].shape[1] != p or arrs[2].shape[1] != p:
        raise InputError(f"X, dX, ddX disagree on p: {arrs[0].shape}, {arrs[1].shape}, {arrs[2].shape}",
                         field="dX")
    if not np.all(np.isfinite(s)) or np.any(np.diff(s) <= 0):
        i = int(np.argmax(~(np.diff(s) > 0)))
        raise InputError(f"s must increase strictly; s[{i}] = {s[i]} >= s[{i + 1}] = {s[i + 1]}", field="s")
    span = float(s[-1] - s[0])
    if not (np.abs(s).max() <= MAX_PATH_VALUE and np.diff(s).min() >= 1e-12 * span):
        i = int(np.argmin(np.diff(s)))
        raise InputError(f"s must lie within ±{MAX_PATH_VALUE:g} mm with steps of at least 1e-12 of its range; "
                         f"s[{i}] = {s[i]:g}, s[{i + 1}] = {s[i + 1]:g}", field="s")
    if limits is None:  # the arrays alone (load_path_npz)
        return s, arrs[0], arrs[1], arrs[2]
    if len(limits.v_max) != p or len(limits.a_max) != p:
        raise InputError(f"the path has p = {p} coordinates but v_max has {len(limits.v_max)} and "
                         f"a_max has {len(limits.a_max)} values", field="v_max")
    if min(limits.v_max) <= 0 or min(limits.a_max) <= 0:
        raise InputError("v_max and a_max must be > 0", field="a_max")
    for name in ("v_max", "a_max"):
        vals = getattr(limits, name)
        if not all(1e-9 <= float(v) <= MAX_PATH_VALUE for v in vals):
            raise InputError(f"{name} = {list(vals)}: every value must be in 1e-9..{MAX_PATH_VALUE:g} (axis units "
                             "per s, per s²): check the units", field=name)
    if not 2 <= limits.levels <= _MAX_LEVELS:
        raise InputError(f"levels must be in 2..{_MAX_LEVELS}, got {limits.levels}", field="levels")
    if limits.accel_check not in ("interval", "arrival"):
        raise InputError(f"accel_check must be 'interval' or 'arrival', got {limits.accel_check!r}",
                         field="accel_check")
    return (s, *arrs)


def _quintic(s: np.ndarray, X: np.ndarray, dX: np.ndarray, ddX: np.ndarray) -> tuple[np.ndarray, ...]:
    """Power coefficients in tau in [0, 1] of X'(s) (degree 4) and X''(s) (degree 3) per interval."""
    h = np.diff(s)[:, None]
    a0, a1, a2 = X[:-1], h * dX[:-1], h * h * ddX[:-1] / 2.0
    r0 = X[1:] - a0 - a1 - a2
    r1 = h * dX[1:] - a1 - 2.0 * a2
    r2 = h * h * ddX[1:] - 2.0 * a2
    a3 = 10.0 * r0 - 4.0 * r1 + 0.5 * r2
    a4 = -15.0 * r0 + 7.0 * r1 - r2
    a5 = 6.0 * r0 - 3.0 * r1 + 0.5 * r2
    # the coefficients written in place (np.stack along the last axis costs ~0.15 ms each at N = 893)
    d1 = np.empty(a1.shape + (5,))
    d2 = np.empty(a1.shape + (4,))
    d1[..., 0] = a1
    for k, (a, f1, f2) in enumerate(((a2, 2.0, 2.0), (a3, 3.0, 6.0), (a4, 4.0, 12.0), (a5, 5.0, 20.0))):
        np.multiply(a, f1, out=d1[..., k + 1])
        np.multiply(a, f2, out=d2[..., k])
    d1 /= h[..., None]
    d2 /= (h * h)[..., None]
    return d1, d2


def _rows(B: int, R: int) -> np.ndarray:
    """Flat offsets of the rows of a C-contiguous (B, R) array, shape (B, 1)."""
    return np.arange(0, B * R, R, dtype=np.intp)[:, None]


def _hull_sym(pts: np.ndarray, ipos: np.ndarray, ineg: np.ndarray, compiled: bool = False, scratch: bool = False
              ) -> tuple[np.ndarray, np.ndarray]:
    """Convex hull vertices of every row of ``pts`` (B, R0, 2), counter-clockwise.

    Every row is centrally symmetric -- ``pts[:, ineg] == -pts[:, ipos]`` (each constraint
    ``|n·z| <= 1`` gives ``n`` and ``-n``) -- and the origin lies strictly inside its hull (the box
    rows).  Then the hull is one chain of vertices with polar angles in ``[0, π)`` followed by their
    mirror images, so only the half set is processed.  Vectorised over the rows:

    1. each pair is oriented into the upper half-plane and sorted by angle (the farther of two
       points on one ray first); zero rows are dropped;
    2. exact pre-filter: points strictly inside the polygon of the extreme points in 2·D directions
       cannot be hull vertices (Akl-Toussaint);
    3. parallel Graham scan: every vertex that does not turn left (against its alive neighbours,
       the mirror images across the ends of the half chain) is removed at once, until none is left
       (a hull vertex always turns left in a star-shaped polygon around an interior point, so
       simultaneous removal is safe).  Collinear and duplicate points are dropped (a vertex that is
       collinear only within round-off waits a round if its predecessor goes too).

    Returns ``(order, m)``: ``order[b, :m[b]]`` are the row indices (into R0) of the hull vertices
    of row b in CCW order; entries past ``m[b]`` are 0.  ``compiled``: steps 1-3 by
    :func:`engine.timeparam_jit.hull_sym_rows` where numba is loaded (the same arithmetic, the same
    vertices bit for bit; the angles stay numpy's), and with ``scratch`` in the thread's work arrays (the
    result is valid until the next such call).
    """
    B = pts.shape[0]
    ipos = np.asarray(ipos, np.intp)
    ineg = np.asarray(ineg, np.intp)
    D = 4
    prep = None
    if compiled and _NUMBA and ipos.size and np.isfinite(pts).all():
        from engine import timeparam_jit

        prep = timeparam_jit.hull_sym_prep(pts, ipos, ineg, work=scratch)
    if prep is not None:                    # the lines below, compiled; then the angles by numpy
        px, py, idx, r2 = prep
        ang = np.arctan2(py, px, out=timeparam_jit.scratch("hs_ang", px.shape) if scratch else None)
        np.copyto(ang, 10.0, where=r2 == 0)
        th = [np.pi * d / D for d in range(D)]
        cd, sd = np.array([math.cos(t) for t in th]), np.array([math.sin(t) for t in th])
        partner = np.zeros(pts.shape[1], np.intp)
        partner[ipos] = ineg
        partner[ineg] = ipos
        out = timeparam_jit.hull_sym_order(px, py, ang, r2, idx, cd, sd, partner, work=scratch)
        if out is not None:                 # with the assembly (_hull_sym_assemble) compiled too
            return out
        res = timeparam_jit.hull_sym_rows(px, py, ang, r2, idx, cd, sd)
        if res is not None:
            return _hull_sym_assemble(pts, ipos, ineg, *res)
    H = pts[:, ipos]
    R = H.shape[1]
    px, py = np.ascontiguousarray(H[..., 0]), np.ascontiguousarray(H[..., 1])
    # hull membership is invariant under a per-row axis scaling: make every cloud round-ish first
    for a in (px, py):
        sc = np.abs(a).max(axis=1, keepdims=True)
        a /= np.where(sc > 0, sc, 1.0)
    flip = (py < 0) | ((py == 0) & (px < 0))
    np.negative(px, out=px, where=flip)
    np.negative(py, out=py, where=flip)
    idx = np.where(flip, ineg[None, :], ipos[None, :])
    ang = np.arctan2(py, px)
    r2 = px * px + py * py
    ang[r2 == 0] = 10.0                                     # zero rows: sorted last, dropped
    order = np.lexsort((-r2, ang), axis=-1)
    order += _rows(B, R)
    X = px.ravel()[order]
    Y = py.ravel()[order]
    A = ang.ravel()[order]
    idx = idx.ravel()[order]
    alive = A < 5.0
    alive[:, 1:] &= A[:, 1:] != A[:, :-1]                  # one point per ray: the farthest
    # 2. pre-filter with the extreme points in D directions of [0, π) and their mirror images
    bi = np.arange(B)
    vx = np.empty((B, 2 * D))
    vy = np.empty((B, 2 * D))
    for d in range(D):
        th = np.pi * d / D
        pr = X * math.cos(th) + Y * math.sin(th)
        r = np.abs(pr).argmax(axis=1)
        sgn = np.sign(pr[bi, r])
        vx[:, d] = sgn * X[bi, r]
        vy[:, d] = sgn * Y[bi, r]
    vx[:, D:] = -vx[:, :D]
    vy[:, D:] = -vy[:, :D]
    inside = np.ones((B, R), bool)
    for d in range(2 * D):
        ax_, ay_ = vx[:, d:d + 1], vy[:, d:d + 1]
        ex = vx[:, (d + 1) % (2 * D), None] - ax_
        ey = vy[:, (d + 1) % (2 * D), None] - ay_
        crs = ex * (Y - ay_) - ey * (X - ax_)
        inside &= (crs > 1e-12 * (np.abs(ex) + np.abs(ey))) | ((ex == 0) & (ey == 0))
    alive &= ~inside
    # 3. parallel Graham scan on the half chain
    ar = np.arange(R)
    act = np.arange(B)
    rounds = 0
    while act.size:
        if rounds % 2 == 0:
            kmax = int(alive.sum(axis=1).max())
            if kmax < 0.75 * R:                             # drop the dead columns
                pos = np.argsort(~alive, axis=1, kind="stable")[:, :kmax]
                X = np.take_along_axis(X, pos, 1)
                Y = np.take_along_axis(Y, pos, 1)
                idx = np.take_along_axis(idx, pos, 1)
                alive = np.take_along_axis(alive, pos, 1)
                R = kmax
                ar = np.arange(R)
        rounds += 1
        al = alive[act]
        Xa, Ya = X[act], Y[act]
        nb = act.size
        pi_ = np.maximum.accumulate(np.where(al, ar, -1), axis=1)
        nx_ = np.minimum.accumulate(np.where(al, ar, R)[:, ::-1], axis=1)[:, ::-1]
        last, first = pi_[:, -1:], nx_[:, :1]
        prv = np.concatenate([np.full((nb, 1), -1), pi_[:, :-1]], axis=1)
        nxt = np.concatenate([nx_[:, 1:], np.full((nb, 1), R)], axis=1)
        o = _rows(nb, R)
        Xf, Yf = Xa.ravel(), Ya.ravel()
        wrap_p, wrap_n = prv < 0, nxt >= R                  # neighbour across an end: a mirror image
        pp = np.clip(np.where(wrap_p, last, prv), 0, R - 1) + o     # (clip: rows without alive points)
        pn = np.clip(np.where(wrap_n, first, nxt), 0, R - 1) + o
        sp = np.where(wrap_p, -1.0, 1.0)
        sn = np.where(wrap_n, -1.0, 1.0)
        e1x = Xa - sp * Xf[pp]
        e1y = Ya - sp * Yf[pp]
        e2x = sn * Xf[pn] - Xa
        e2y = sn * Yf[pn] - Ya
        cr = e1x * e2y - e1y * e2x
        near = al & (cr * cr <= 1e-24 * (e1x * e1x + e1y * e1y) * (e2x * e2x + e2y * e2y))
        strict = al & (cr < 0) & ~near
        # a vertex collinear within round-off is removed only if its predecessor is not marked too
        # (two such neighbours removed at once could empty a degenerate, nearly flat hull)
        bad = strict | (near & ~(strict | near).ravel()[pp])
        changed = bad.any(axis=1)
        if not changed.any():
            break
        alive[act] = al & ~bad
        act = act[changed]
    k = alive.sum(axis=1)
    K = max(int(k.max()), 1)
    up = np.take_along_axis(idx, np.argsort(~alive, axis=1, kind="stable")[:, :K], 1)
    return _hull_sym_assemble(pts, ipos, ineg, up, k)


def _hull_sym_assemble(pts: np.ndarray, ipos: np.ndarray, ineg: np.ndarray, up: np.ndarray, k: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray]:
    """The half chain's row ids ``up[b, :k[b]]`` followed by their mirror partners: ``(order, m)``."""
    K = max(int(k.max()), 1) if k.size else 1
    up = up[:, :K]
    partner = np.zeros(pts.shape[1], np.intp)
    partner[ipos] = ineg
    partner[ineg] = ipos
    m = 2 * k
    tt = np.arange(2 * K)[None, :]
    lower = tt < k[:, None]
    v = np.take_along_axis(up, np.clip(np.where(lower, tt, tt - k[:, None]), 0, K - 1), 1)
    v = np.where(lower, v, partner[v])
    return np.where(tt < m[:, None], v, 0), m


def _drop_parallel(allr: np.ndarray, order: np.ndarray, m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Remove hull vertices (constraint normals) parallel to their CCW successor.

    Two consecutive hull normals that are parallel (an axis at rest or moving linearly gives rows
    ``(g, c)`` with ``g`` at round-off level; the collinearity tolerance of the hull then keeps
    both) have no intersection: the polygon vertex would be 0/0.  Of two parallel normals pointing
    the same way the longer one is the tighter constraint; the shorter one is dropped.  Repeats
    until no neighbours are parallel (the polygon is unchanged up to round-off).
    """
    B = order.shape[0]
    br = np.arange(B)[:, None]
    for _ in range(order.shape[1]):
        V = order.shape[1]
        tt = np.arange(V)[None, :]
        valid = tt < m[:, None]
        nxt = np.where(valid, (tt + 1) % np.maximum(m, 1)[:, None], 0)
        na = allr[br, order]
        nb = allr[br, order[br, nxt]]
        la = np.hypot(na[..., 0], na[..., 1])
        lb = np.hypot(nb[..., 0], nb[..., 1])
        det = na[..., 0] * nb[..., 1] - na[..., 1] * nb[..., 0]
        dot = na[..., 0] * nb[..., 0] + na[..., 1] * nb[..., 1]
        par = valid & (m[:, None] > 3) & ~(det > 0) & (dot > 0)
        if not par.any():
            break
        # drop the shorter of each parallel pair (the successor on a tie); one drop per row and pass
        t_star = np.argmax(par, axis=1)
        rows_ = np.flatnonzero(par.any(axis=1))
        t0 = t_star[rows_]
        t1 = nxt[rows_, t0]
        gone = np.where(la[rows_, t0] < lb[rows_, t0], t0, t1)
        keep = valid.copy()
        keep[rows_, gone] = False
        pos = np.argsort(~keep, axis=1, kind="stable")
        order = np.take_along_axis(order, pos, 1)
        m = keep.sum(axis=1)
    return order, m


def _box_rows(rows: np.ndarray, h: np.ndarray, xn_prev: np.ndarray, xn_cur: np.ndarray, ipos: np.ndarray,
              ineg: np.ndarray, out: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``rows`` with the box rows ``|x_k| <= xn_prev``, ``|x_j| <= xn_cur`` appended, and the ± pairs
    (written into ``out`` of shape (B, R + 4, 2) when given)."""
    B = rows.shape[0]
    box = np.zeros((B, 4, 2))
    box[:, 0, 0] = 1.0 / xn_prev
    box[:, 1, 0] = -1.0 / xn_prev
    box[:, 2, 0] = 1.0 / xn_cur
    box[:, 2, 1] = 2.0 * h / xn_cur
    box[:, 3] = -box[:, 2]
    R = rows.shape[1]
    return np.concatenate([rows, box], axis=1, out=out), np.r_[ipos, R, R + 2], np.r_[ineg, R + 1, R + 3]


def _compiled_hull_for(nodes: int) -> bool:
    """Whether a problem of ``nodes`` nodes takes the compiled monotone-chain hull.

    The monotone chain and :func:`_hull_sym` give the same polygons up to round-off but may keep a
    different one of two nearly coincident vertices, which can move a law's last bits (the pipe
    example's NC differed in one F word).  So the choice depends on the problem alone, never on
    whether numba happens to be loaded in this process: problems from
    :data:`engine.timeparam_jit.IMPORT_THRESHOLD` nodes on (which import numba anyway) take the
    monotone chain, smaller ones :func:`_hull_sym` (compiled too where numba is loaded, bit for bit
    its numpy code): a one-shot ``winder run`` and a GUI with numba warmed write the same program.
    Without numba at all (e.g. the frozen build) big problems take :func:`_hull_sym` too.  The DP
    passes and the chains are bit for bit the same either way."""
    from engine.timeparam_jit import IMPORT_THRESHOLD

    return nodes >= IMPORT_THRESHOLD


def _hulls(allr: np.ndarray, ipos: np.ndarray, ineg: np.ndarray, compiled: bool, scratch: bool = False,
           chain: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Hull vertex rows of every row set: with ``compiled`` and ``chain`` the compiled monotone chain
    where available, else :func:`_hull_sym` (compiled where numba is loaded: the same bits).
    ``chain``: see :func:`_compiled_hull_for`.  ``scratch``: the compiled chain's ``order`` may be
    the thread's work array (used at once)."""
    if compiled and chain and _NUMBA:
        from engine import timeparam_jit

        out = timeparam_jit.hulls(allr, (ipos, ineg), scratch_out=scratch)
        if out is not None:
            return out
    return _hull_sym(allr, ipos, ineg, compiled=compiled, scratch=scratch)


def _chains(rows: np.ndarray, h: np.ndarray, xn_prev: np.ndarray, xn_cur: np.ndarray,
            ipos: np.ndarray, ineg: np.ndarray, compiled: bool = False, hull_compiled: bool | None = None,
            work: bool = False, hull: tuple | None = None) -> dict[str, np.ndarray]:
    """The feasible polygon of every interval in the ``(x_k, x_j) = (ṡ²_{i-1}, ṡ²_i)`` plane.

    ``rows`` (B, R, 2) are normalised constraints ``n·(x_k, u) <= 1`` with ``u = (x_j - x_k)/(2h)``,
    in pairs ``rows[:, ineg] == -rows[:, ipos]``;
    box rows ``|x_k| <= xn_prev``, ``|x_j| <= xn_cur`` are added (relaxations of the node caps) so
    that the polygon is bounded.  Returns the right chain ``x_k = R(x_j)`` and the left chain
    ``x_k = L(x_j)`` of each polygon, flattened for one global ``np.interp`` (abscissa
    ``x_j / xn_cur + 3·i``), and the x_j range of each polygon; from the compiled code also the chains'
    segment slopes ``rs``, ``ls``.  ``work``: the chains may be the thread's work arrays (valid until
    the next such call; for parametrize's problems, used within the call only).  ``hull``: ``(allr, order,
    m)``, the box rows of these very rows and boxes and their hull (:func:`_coarse_problem` makes them), used
    instead of making them again.
    """
    B = rows.shape[0]
    if hull is not None:
        allr, order, m = hull
    else:
        wrows = None
        if compiled and _NUMBA:             # the rows and the hull in the thread's work arrays (used here only)
            from engine import timeparam_jit

            if timeparam_jit.kernel(0) is not None:
                wrows = timeparam_jit.scratch("box_rows", (B, rows.shape[1] + 4, 2))
        allr, ip2, in2 = _box_rows(rows, h, xn_prev, xn_cur, ipos, ineg, out=wrows)
        chain = True if hull_compiled is None else hull_compiled
        order, m = _hulls(allr, ip2, in2, compiled, scratch=wrows is not None, chain=chain)
    if compiled and _NUMBA:
        from engine import timeparam_jit

        out = timeparam_jit.chains(allr, order, m, h, xn_cur, work)     # the same bits, one compiled loop
        if out is not None:
            return out
    V = int(m.max())
    order = order[:, :V]
    br = np.arange(B)[:, None]
    tt = np.arange(V)[None, :]
    valid = tt < m[:, None]
    na = allr[br, order]                                           # (B, V, 2)
    nb = allr[br, order[br, np.where(valid, (tt + 1) % m[:, None], 0)]]
    det = na[..., 0] * nb[..., 1] - na[..., 1] * nb[..., 0]
    det = np.where(valid, det, 1.0)
    if np.any(valid & ~(det > 0)):
        order, m = _drop_parallel(allr, order, m)
        V = int(m.max())
        order = order[:, :V]
        tt = np.arange(V)[None, :]
        valid = tt < m[:, None]
        na = allr[br, order]
        nb = allr[br, order[br, np.where(valid, (tt + 1) % m[:, None], 0)]]
        det = na[..., 0] * nb[..., 1] - na[..., 1] * nb[..., 0]
        det = np.where(valid & (det > 0), det, 1.0)
    zx = (nb[..., 1] - na[..., 1]) / det                           # x_k of the polygon vertex
    zu = (na[..., 0] - nb[..., 0]) / det                           # u
    xk = zx
    xj = zx + 2.0 * h[:, None] * zu
    xj_v = np.where(valid, xj, np.inf)
    bot = np.argmin(xj_v, axis=1)
    top = np.argmax(np.where(valid, xj, -np.inf), axis=1)
    c = (top - bot) % m + 1                                        # points on the right chain
    L = V + 1
    ll = np.arange(L)[None, :]
    # right chain: bottom -> top (CCW); pad with the top
    ridx = (bot[:, None] + np.minimum(ll, c[:, None] - 1)) % m[:, None]
    # left chain: top -> bottom (CCW), reversed to run bottom -> top; pad with the top
    nl = m - c + 2                                                 # points on the left chain
    lpos = np.minimum(ll, nl[:, None] - 1)                         # 0 .. nl-1 along bottom -> top
    lidx = (bot[:, None] - lpos) % m[:, None]
    scale = xn_cur[:, None]
    off = 3.0 * np.arange(B)[:, None]
    return {
        "rq": (xj[br, ridx] / scale + off).ravel(), "rk": xk[br, ridx].ravel(),
        "lq": (xj[br, lidx] / scale + off).ravel(), "lk": xk[br, lidx].ravel(),
        "xjb": xj[np.arange(B), bot], "xjt": xj[np.arange(B), top],
        "uhi": np.max(np.where(valid, zu, -np.inf), axis=1), "ulo": np.min(np.where(valid, zu, np.inf), axis=1),
        "xkt": np.max(np.where(valid, xk, -np.inf), axis=1),
    }


def _reachable(cap: np.ndarray, h: np.ndarray, ch: dict[str, np.ndarray], limits: TimeLimits) -> np.ndarray:
    """``cap`` tightened to what any admissible law can reach (a valid bound, no law is excluded).

    ``ṡ²`` grows by at most ``2h·max s̈`` over an interval (the largest ``s̈`` of its feasible polygon)
    from the start speed, and falls by at most ``2h·max(-s̈)`` towards the end speed; the polygon
    also bounds ``ṡ²`` at both of its nodes.  Without this, a node without a speed limit (no
    ``sdot_max``, straight motion) would spread the nominal run's levels over unreachable speeds.
    """
    c = cap.astype(float) ** 2
    c[:-1] = np.minimum(c[:-1], np.maximum(ch["xkt"], 0.0))
    c[1:] = np.minimum(c[1:], np.maximum(ch["xjt"], 0.0))
    c[0] = min(c[0], limits.sdot_start ** 2)
    c[-1] = min(c[-1], limits.sdot_end ** 2)
    up = 2.0 * h * np.maximum(ch["uhi"], 0.0)
    D = np.concatenate([[0.0], np.cumsum(up)])
    fwd = D + np.minimum.accumulate(c - D)
    dn = 2.0 * h * np.maximum(-ch["ulo"], 0.0)
    E = np.concatenate([[0.0], np.cumsum(dn[::-1])])            # from the end backwards
    bwd = (E + np.minimum.accumulate(c[::-1] - E))[::-1]
    out = np.sqrt(np.maximum(np.minimum(np.minimum(c, fwd), bwd), 0.0))
    return np.minimum(out, cap)


def _interval_caps(d1: np.ndarray, adX: np.ndarray, V: np.ndarray, arrival: bool,
                   wk: Callable[[str, tuple[int, ...]], np.ndarray]) -> tuple[np.ndarray, np.ndarray | None]:
    """Node caps of the path speed (mm/s) from the axis speeds, and the caps of the intervals behind them.

    ``arrival``: ``min_k V_k/|X'_k|`` at the node (the paper's check at the arrival node; no interval caps).
    Else ``|X'_k|`` is bounded over each interval by its Bernstein coefficients: the interval's cap is
    ``min_k V_k/bound_k`` (as ``x = ṡ²``: the second array, one per interval), and a node's is the smaller
    of its two intervals' (and its own): it holds the axis speeds inside the intervals whatever a law does
    between the nodes, up to the change of |X'| over an interval below the node's own cap
    (:func:`_chord_caps` recovers that)."""
    def caps(b: np.ndarray) -> np.ndarray:  # min_k V_k/b_k (inf where no axis moves)
        with np.errstate(divide="ignore"):
            return np.min(np.where(b > 0, V / np.where(b > 0, b, 1.0), np.inf), axis=1)

    cap = caps(adX)
    if arrival:
        return cap, None
    bb = np.matmul(d1, _P2B.T, out=wk("prepare_bb", d1.shape))
    np.abs(bb, out=bb)
    b1 = np.maximum(bb[..., 0], bb[..., 1])                   # (N-1, p); max over the 5 (exact in any order)
    for k in range(2, 5):
        np.maximum(b1, bb[..., k], out=b1)
    # V/max(b) = min(V/b) exactly (division is monotone and rounded once): a node's cap is the smaller of its
    # own and its two intervals'
    ib = caps(b1)
    np.minimum(cap[:-1], ib, out=cap[:-1])
    np.minimum(cap[1:], ib, out=cap[1:])
    return cap, ib ** 2


_P2B8 = np.array([[math.comb(m, l) / math.comb(8, l) if l <= m else 0.0 for l in range(9)] for m in range(9)])
"""Power to Bernstein coefficients, degree 8 (|X'|² of the quintic Hermite interpolant)."""
_CHORD_SWEEPS = 12
_CHORD_HUGE = 1e30   # a node where no axis moves: no cap of its own (the chords of its intervals set one)


def _chord_caps(d1: np.ndarray, adX: np.ndarray, V: np.ndarray, cap_old: np.ndarray, xb: np.ndarray,
                levels: int) -> np.ndarray:
    """Node caps of the path speed (mm/s) that hold every axis speed inside every interval for any law
    with ṡ² linear in s between nodes at or below them, at least ``cap_old`` (:func:`_interval_caps`).

    *The bound.*  Inside interval ``i`` (τ in [0, 1]) a law with ``x = ṡ²`` at most ``c_i``, ``c_{i+1}`` at
    its ends has ``x(τ) <= (1 - τ)c_i + τc_{i+1}``, and axis ``k`` moves at ``|X'_k(τ)|·√x(τ)``.  So the
    speeds hold if ``((1 - τ)c_i + τc_{i+1})·X'_k(τ)² <= V_k²`` for all τ: a polynomial of degree 9 in τ,
    linear in ``(c_i, c_{i+1})``, at most the largest of its Bernstein coefficients ``α_kj·c_i + β_kj·c_{i+1}``
    (``α_kj = (9 - j)/9·q_kj``, ``β_kj = j/9·q_k,j-1``, q the Bernstein coefficients of ``X'_k²``): the
    *chord* test.  Both ends at most the interval's cap ``xb`` (:func:`_interval_caps`) is the other proof.

    *The caps.*  From the caps at the nodes themselves (``x <= V_k²/X'_k²`` there, as TOPP-RA's), every
    interval whose chord breaks the test has both end caps scaled down until it holds, a node taking the
    smaller scale of its two intervals; one sweep usually settles them, a second confirms (not settled
    within :data:`_CHORD_SWEEPS`: the old caps).

    *Where the old caps stay.*  A node whose new cap is not at least one level step (``1/levels``) above
    the old keeps the old one exactly: the DP's levels would move by less than a step there, and the law
    could come out a little better or worse by their placement alone (the paper's path keeps its law bit
    for bit).  Each interval is then certified by one of the two tests; where one that mixes old and new
    caps is not, its ends take their old caps (both old: the interval cap certifies it), until all are.
    So no cap is below the old one, and every interval is proven.

    The old caps alone bound a node by the worst speed of both adjacent intervals: where an axis speed
    changes by ~10 % from node to node the law then stays ~10 % below the node's own cap, 1-2 % of the
    traversal time on such paths (benchmarks/bench_timelaw_variety.py).
    """
    n1, p, _ = d1.shape
    xo = np.minimum(cap_old * cap_old, _CHORD_HUGE)          # the old caps as x = ṡ²
    with np.errstate(divide="ignore"):
        node = np.min(np.where(adX > 0, (V * V)[None, :] / np.where(adX > 0, adX * adX, 1.0), np.inf), axis=1)
    step = (1.0 + 1.0 / max(levels, 1)) ** 2
    if not (np.minimum(node, _CHORD_HUGE) > xo * step).any():
        return cap_old                                        # no cap can gain a level step (caps only fall)
    q = np.zeros((n1, p, 9))                                  # X'² in powers of τ
    for i in range(5):
        q[..., 2 * i] += d1[..., i] * d1[..., i]
        for j in range(i + 1, 5):
            q[..., i + j] += 2.0 * (d1[..., i] * d1[..., j])
    qb = np.matmul(q, _P2B8.T)
    inv = 1.0 / (V * V)
    w = np.arange(10) / 9.0
    alpha = np.zeros((n1, p, 10))
    beta = np.zeros((n1, p, 10))
    np.multiply(qb, (1.0 - w[:9]) * inv[:, None], out=alpha[..., :9])
    np.multiply(qb, w[1:] * inv[:, None], out=beta[..., 1:])
    alpha = alpha.reshape(n1, p * 10)
    beta = beta.reshape(n1, p * 10)
    xbh = np.minimum(xb, _CHORD_HUGE)

    def chord(c: np.ndarray) -> np.ndarray:
        """Per interval, the largest Bernstein coefficient of the chord test for end caps ``c`` (<= 1: proven)."""
        f = alpha * c[:-1, None]
        f += beta * c[1:, None]
        return f.max(axis=1)

    def uncertified(c: np.ndarray) -> np.ndarray:
        """The intervals that neither the chord test nor the interval cap certifies for end caps ``c``."""
        return ~((chord(c) <= 1.0 - 1e-12) | ((c[:-1] <= xbh) & (c[1:] <= xbh)))

    c = np.minimum(node, _CHORD_HUGE)
    for _ in range(_CHORD_SWEEPS):
        fm = chord(c)
        bad = fm > 1.0 - 1e-12
        if not bad.any():
            break
        scale = np.where(bad, (1.0 - 1e-9) / np.where(bad, fm, 1.0), 1.0)
        ns = np.ones(c.size)
        ns[:-1] = scale
        np.minimum(ns[1:], scale, out=ns[1:])
        c *= ns
    else:
        return cap_old
    gain = c > xo * step
    c = np.where(gain, c, xo)
    for _ in range(n1 + 1):                                     # mixed intervals: ends back to their old caps
        bad = uncertified(c)
        if not bad.any():
            break
        back = np.zeros(c.size, dtype=bool)
        back[:-1] |= bad
        back[1:] |= bad
        gain &= ~back
        c = np.where(gain, c, xo)
    return np.where(gain, np.where(c >= _CHORD_HUGE, np.inf, np.sqrt(c)), cap_old)


def _prepare(path_s: Any, X: Any, dX: Any, ddX: Any, limits: TimeLimits, chains: bool = True, work: bool = False
             ) -> _Problem:
    s, X, dX, ddX = _validate(path_s, X, dX, ddX, limits)
    n, p = X.shape
    h = np.diff(s)
    A = np.asarray(limits.a_max, float)
    V = np.asarray(limits.v_max, float)
    d1, d2 = _quintic(s, X, dX, ddX)
    if work:                       # the thread's work arrays for what is used here only (no fresh pages)
        from engine.timeparam_jit import scratch as _wk
    else:
        def _wk(name: str, shape: tuple[int, ...]) -> np.ndarray:
            return np.empty(shape)

    # axis speed caps: at the nodes (the paper's check at the arrival node), or caps whose chords keep the
    # axis speeds inside every interval (_chord_caps; where that does not settle, the Bernstein bound of |X'|
    # over both adjacent intervals, _interval_caps)
    cap_v, xb = _interval_caps(d1, np.abs(dX), V, limits.accel_check == "arrival", _wk)
    if xb is not None:
        cap_v = _chord_caps(d1, np.abs(dX), V, cap_v, xb, int(limits.levels))

    cap_tech = np.full(n, float(limits.sdot_max))
    point_nodes: list[tuple[TechPoint, np.ndarray]] = []
    tol = 1e-9 * max(1.0, abs(s[-1]), abs(s[0]))
    for pt in limits.points:
        lo_s = pt.s if pt.s is not None else pt.s_from
        hi_s = pt.s if pt.s is not None else pt.s_to
        if lo_s is None or hi_s is None:
            raise InputError(f"{pt.describe()}: needs s or s_from/s_to", field="points")
        if lo_s < s[0] - tol or hi_s > s[-1] + tol:
            raise InputError(f"{pt.describe()} lies outside the path s = {s[0]:.2f}..{s[-1]:.2f} mm",
                             field="points")
        if pt.sdot_max < 0:
            raise InputError(f"{pt.describe()}: sdot_max must be >= 0, got {pt.sdot_max}", field="points")
        i0 = int(np.searchsorted(s, lo_s - tol, side="left"))          # first node >= lo
        i1 = int(np.searchsorted(s, hi_s + tol, side="right")) - 1     # last node <= hi
        if abs(s[min(i0, n - 1)] - lo_s) > tol:
            i0 = max(i0 - 1, 0)                                          # bracketing node before
        if abs(s[max(i1, 0)] - hi_s) > tol:
            i1 = min(i1 + 1, n - 1)                                      # bracketing node after
        nodes = np.arange(i0, i1 + 1)
        cap_tech[nodes] = np.minimum(cap_tech[nodes], pt.sdot_max)
        point_nodes.append((pt, nodes))
    cap = np.minimum(cap_v, cap_tech)

    # constraint rows n.(x_k, u) <= 1 per interval
    if limits.accel_check == "arrival":
        P = ddX[1:, :, None]                                            # (N-1, p, 1)
        Q = (2 * h[:, None] * ddX[1:] + dX[1:])[:, :, None]
    else:
        Pp = _wk("prepare_Pp", d1.shape)                                   # degree 3 -> 4 slots
        Pp[..., :4] = d2
        Pp[..., 4] = 0.0
        Qp = _wk("prepare_Qp", d1.shape)
        np.copyto(Qp, d1)
        Qp[..., 1:] += np.multiply(2.0 * h[:, None, None], d2, out=_wk("prepare_h2", d2.shape))
        P = np.matmul(Pp, _P2B.T, out=_wk("prepare_P", d1.shape))
        Q = np.matmul(Qp, _P2B.T, out=_wk("prepare_Q", d1.shape))
    G = P.shape[1] * P.shape[2]
    extra = math.isfinite(limits.sddot_max)
    R = 2 * G + 2 * extra
    ipos, ineg = np.arange(G), np.arange(G, 2 * G)   # the ± pairs
    if extra:
        ipos, ineg = np.r_[ipos, 2 * G], np.r_[ineg, 2 * G + 1]
    # rows (g, c), then (-g, -c), then the s̈_T pair, and the pre-pruned hull rows (_rows_numpy).  ``work``: in
    # the thread's work arrays (no fresh pages every solve; parametrize's problem is used only within the call)
    prune = P.shape[-1] == 5
    if work:
        from engine.timeparam_jit import scratch

        rows = scratch("prepare_rows", (n - 1, R, 2))
        hull_rows = scratch("prepare_hull_rows", (n - 1, R, 2)) if prune else rows
    else:
        rows = np.empty((n - 1, R, 2))
        hull_rows = np.empty((n - 1, R, 2)) if prune else rows
    done = False
    if _NUMBA:
        from engine import timeparam_jit

        done = timeparam_jit.constraint_rows(P, Q, A, 1.0 / limits.sddot_max if extra else None, rows, hull_rows)
    if not done:
        _rows_numpy(P, Q, A, limits, rows, hull_rows)
    xn, cap_dp, ch = _polygons(cap, h, hull_rows, ipos, ineg, limits, chains)
    return _Problem(s=s, h=h, p=p, d1=d1, d2=d2, cap_v=cap_v, cap_tech=cap_tech, cap=cap, cap_dp=cap_dp, xn=xn[1:],
                    rows=rows, limits=limits, point_nodes=point_nodes, hull_rows=hull_rows, ipos=ipos, ineg=ineg,
                    **ch)


def _rows_numpy(P: np.ndarray, Q: np.ndarray, A: np.ndarray, limits: TimeLimits, rows: np.ndarray,
                hull_rows: np.ndarray) -> None:
    """The constraint rows ``n·(x_k, u) <= 1`` of every interval into ``rows`` (N-1, R, 2): ``(g, c) =
    (P, Q)/A`` for every axis and Bernstein coefficient, then ``(-g, -c)``, then ``(0, ±1/s̈_T)``; and
    ``hull_rows`` (the same array when there is nothing to prune): exact pre-pruning, an inner
    Bernstein point inside the triangle (origin, first, last) of its own axis is implied by those two
    (the origin lies inside the hull), so the hull skips it (its row times 0.0, the others times 1.0).
    :func:`engine.timeparam_jit.constraint_rows` is this code compiled (the same bits)."""
    n1, p = P.shape[:2]
    g5, c5 = P / A[None, :, None], Q / A[None, :, None]
    G = g5[0].size
    rows[:, :G, 0] = g5.reshape(n1, G)
    rows[:, :G, 1] = c5.reshape(n1, G)
    np.negative(rows[:, :G], out=rows[:, G:2 * G])
    if rows.shape[1] > 2 * G:
        rows[:, 2 * G:, 0] = 0.0
        rows[:, 2 * G, 1] = 1.0 / limits.sddot_max
        rows[:, 2 * G + 1, 1] = -1.0 / limits.sddot_max
    if P.shape[-1] == 5:
        gt, ct = np.moveaxis(g5, -1, 0).copy(), np.moveaxis(c5, -1, 0).copy()    # (5, N-1, p), contiguous
        det = gt[0] * ct[4] - ct[0] * gt[4]
        sd = np.where(np.abs(det) > 0, det, 1.0)
        al = (gt[1:4] * ct[4] - ct[1:4] * gt[4]) / sd
        be = (gt[0] * ct[1:4] - ct[0] * gt[1:4]) / sd
        inner = (np.abs(det) > 0) & (al >= 0) & (be >= 0) & (al + be <= 1.0 - 1e-12)    # (3, N-1, p)
        keep = np.ones((n1, rows.shape[1]))
        kp = np.ones((n1, p, 5))
        kp[..., 1:4] = np.moveaxis(~inner, 0, -1)
        keep[:, :G] = kp.reshape(n1, G)
        keep[:, G:2 * G] = keep[:, :G]
        np.multiply(rows[..., 0], keep, out=hull_rows[..., 0])   # rows · keep: the dropped rows times 0.0
        np.multiply(rows[..., 1], keep, out=hull_rows[..., 1])


def _polygons(cap: np.ndarray, h: np.ndarray, hull_rows: np.ndarray, ipos: np.ndarray, ineg: np.ndarray,
              limits: TimeLimits, chains: bool, compiled: bool = False, hull_compiled: bool | None = None,
              work: bool = False, hull: tuple | None = None) -> tuple[np.ndarray, np.ndarray, dict[str, Any]]:
    """Box sizes ``xn``, the reachable caps ``cap_dp`` and the polygon chains of every interval
    (``hull_compiled``: see :func:`_compiled_hull_for`; ``work``: see :func:`_chains`), with the chains'
    segment slopes as ``chain_slopes`` where the compiled code made them."""
    cap_box = np.minimum(cap, 1e9)
    xn = (1.5 * cap_box) ** 2 + 1.0
    if chains:
        ch = _chains(hull_rows, h, xn[:-1], xn[1:], ipos, ineg, compiled, hull_compiled, work, hull)
        cap_dp = _reachable(cap_box, h, ch, limits)
        # The box is a relaxation of the node caps.  Where no axis limits the speed (axes at rest or
        # moving linearly, large V, no sdot_max) it is orders of magnitude larger than the speeds any
        # law reaches, and the flattened chains (abscissa x_j/xn + 3i) lose the polygon to round-off:
        # rebuild them with the box of the reachable speeds (also a valid relaxation).
        xn_r = (1.5 * cap_dp) ** 2 + 1.0
        loose = (xn > 1e12) & (xn > 1e6 * xn_r)                 # ṡ > 670 m/s: no physical limit
        if loose.any():
            xn = np.where(loose, xn_r, xn)
            ch = _chains(hull_rows, h, xn[:-1], xn[1:], ipos, ineg, compiled, hull_compiled, work)
            cap_dp = np.minimum(cap_dp, _reachable(cap_box, h, ch, limits))
    else:
        e = np.zeros(0)
        ch = {"rq": e, "rk": e, "lq": e, "lk": e, "xjb": e, "xjt": e}
        cap_dp = cap
    slopes = (ch["rs"], ch["ls"]) if "rs" in ch else None
    ch = {k: v for k, v in ch.items() if k not in ("uhi", "ulo", "xkt", "rs", "ls")}
    ch["chain_slopes"] = slopes
    return xn, cap_dp, ch


_GROUP_SHARE = 1.0   # h* = share·ṡ_ref²/(M·a_ref): one level step per interval (docs/timeparam.md)
_GROUP_WHEN = 5.0    # group only when the median interval is shorter than a fifth of a level step


def _group_length(prob: _Problem) -> np.ndarray | None:
    """Per interval, the path length (mm) one level step needs, or ``None`` to solve on the given nodes.

    A DP transition changes ṡ by a whole level step or more, unless it stays on its level.  The
    nominal run's step at a node is ``ṡ_i/M`` (its levels span ``[0, ṡ_i]``, ``ṡ_i`` the speed cap);
    one step there is ``Δ(ṡ²) ≈ 2·ṡ_i²/M``, and at the largest path acceleration at rest,
    ``a_i = min_c A_c/|X_c'|`` (and ``s̈_T``), it takes ``ℓ_i = ṡ_i²/(M·a_i)`` of path.  On intervals
    much shorter than ``ℓ_i`` the levels cannot follow the acceleration limit and the tube stalls
    (issue 16: at the iteration cap, 1.7 % slow on the paper's path at N = 30 000).  When the median
    of ``h_i/ℓ_i`` is below 1/5 the tube runs on groups of consecutive intervals about ``ℓ`` long
    (:func:`_coarse_problem`); otherwise on the given nodes.  Measured medians: the paper's example
    0.40 / 0.53 (M = 74 / 100, given nodes: the pinned answers), resampled to N = 3 000 0.12 / 0.16
    (grouped), the pressure vessel's law 0.23 / 0.31 (given nodes).
    """
    if not prob.limits.coarse or prob.s.size < 8:
        return None
    c = prob.rows[..., 1]                                  # u coefficients of the rows n.(x, u) <= 1
    cmax = c.max(axis=1)
    a0 = np.where(cmax > 0, 1.0 / np.where(cmax > 0, cmax, 1.0), np.inf)
    cap = np.minimum(prob.cap, 1e9)
    if not 0 < float(cap.max()) < 1e8:
        return None
    # the speed cap, at most the highest speed reachable anywhere at the acceleration at rest (an
    # estimate for the group size only, not a constraint: it matters where no axis limits the speed)
    x_cap = np.minimum(cap[:-1], cap[1:]) ** 2
    ah = prob.h * np.where(np.isfinite(a0), a0, 0.0)
    fwd = 2.0 * np.cumsum(ah) + prob.limits.sdot_start ** 2
    bwd = 2.0 * np.cumsum(ah[::-1])[::-1] + prob.limits.sdot_end ** 2
    x_i = np.minimum(x_cap, float(np.max(np.minimum(fwd, bwd))))
    with np.errstate(divide="ignore", invalid="ignore"):
        ell = _GROUP_SHARE * x_i / (prob.limits.levels * a0)
    ell = np.where(np.isfinite(ell) & (ell > 0), ell, np.inf)    # no motion limit: no level step
    ell = np.minimum(ell, (prob.s[-1] - prob.s[0]) / 16.0)       # at least 16 groups
    ratio = prob.h / ell
    return ell if float(np.median(ratio)) * _GROUP_WHEN < 1.0 else None


def _coarse_problem(prob: _Problem, ell: np.ndarray, work: bool = False) -> tuple[_Problem, np.ndarray]:
    """The problem on groups of consecutive intervals about one level step ``ell`` long, constant s̈
    in each.

    Coarse nodes: the first node past every whole step of ``σ(s) = ∫ ds/ℓ`` (so a group spans about
    one local ``ℓ``, and intervals longer than ``ℓ`` stay alone), the ends,
    the first and last node of every technological point and every node with a zero speed cap.  On
    a group ``[a, b]`` the law's ``x = ṡ²`` is linear in s, so at a node ``i`` of the group
    ``x_i = x_a + 2u·(s_i - s_a)``: each row ``g·x_i + c·u <= 1`` of each interval of the group becomes
    ``g·x_a + (c + 2g·(s_i - s_a))·u <= 1``, and each inner node's cap ``x_i <= cap_i²`` a row too.  The
    group's polygon is exactly the set of (x_a, x_b) whose linear ṡ² keeps every constraint of every
    interval in it.  Returns the coarse problem and the indices of its nodes among the given ones.
    ``work``: work arrays of the thread for the hulls and the chains (see :func:`_chains`).
    """
    n = prob.s.size
    sigma = np.concatenate([[0.0], np.cumsum(np.minimum(prob.h / ell, 1e6))])
    bins = np.floor(sigma)
    need = [np.array([0, n - 1]), np.flatnonzero(np.diff(bins) > 0) + 1]
    for _, nodes in prob.point_nodes:
        if nodes.size:
            need.append(np.array([nodes[0], nodes[-1]]))
    need.append(np.flatnonzero(prob.cap <= 0))
    idx = np.unique(np.concatenate(need))
    B = idx.size - 1
    sizes = np.diff(idx)
    mx = int(sizes.max())
    # fine interval of every slot (B, mx); slots past a group's end repeat its last interval with
    # zero rows
    slot = np.arange(mx)[None, :]
    valid = slot < sizes[:, None]
    fi = np.minimum(idx[:-1, None] + slot, idx[1:, None] - 1)
    off = prob.s[fi] - prob.s[idx[:-1], None]                         # s_i - s_a (mm)
    # each interval's rows reduced to the vertices of their hull (with the box rows: valid, as the
    # node caps imply them); the others are implied, also after the linear change to (x_a, u)
    hr = prob.hull_rows if prob.hull_rows is not None else prob.rows
    xn_f = (1.5 * np.minimum(prob.cap, 1e9)) ** 2 + 1.0
    allr, ip_f, in_f = _box_rows(hr, prob.h, xn_f[:-1], xn_f[1:], prob.ipos, prob.ineg)
    order, mv = _hulls(allr, ip_f, in_f, True, scratch=work, chain=_compiled_hull_for(n))
    # the same box rows and hull as _with_chains(prob) would make (the final sweep's chains): kept for it
    if prob.limits.sweep:
        prob.fine_hull = (allr, order.copy() if work else order, mv.copy() if work else mv)
    R = max(int(mv.max()), 1)
    order = order[:, :R]
    keep = np.arange(R)[None, :] < mv[:, None]
    # which rows they are: the box rows (implied by the node caps, kept as rows of their own) go; the
    # row of a Bernstein coefficient at τ = 0 (the start node) repeats the previous interval's row at
    # τ = 1 up to round-off, and such near-twins make ill-conditioned polygon vertices: it goes too,
    # except in the first interval of a group
    n_rows = hr.shape[1]
    inner_rows = order < n_rows
    pos_of = np.zeros(n_rows, np.int64)
    pos_of[prob.ipos] = np.arange(prob.ipos.size)
    pos_of[prob.ineg] = np.arange(prob.ineg.size)
    n_bern = prob.d1.shape[-1] if prob.limits.accel_check != "arrival" else 1
    n_acc = 2 * prob.p * n_bern                                      # acceleration rows (± pairs)
    at_start = inner_rows & (order < n_acc) & (pos_of[np.minimum(order, n_rows - 1)] % n_bern == 0) & (n_bern > 1)
    keep &= inner_rows
    # caps of the inner nodes (slot >= 1): x_a + 2u·off <= cap², as a ± pair (the minus side only cuts
    # x < 0, outside every level range)
    capf = prob.cap[fi]
    inner = valid & (slot >= 1) & (capf < 1e9)
    icap = np.where(inner, 1.0 / np.where(inner, capf * capf, 1.0), 0.0)
    icap = np.where(inner & (capf <= 0), 0.0, icap)                    # zero caps are coarse nodes
    crow = np.stack([icap, 2.0 * off * icap], axis=-1)                 # (B, mx, 2)
    rows = None
    if _NUMBA:                         # the lines below in one compiled loop (the same bits; no temporaries)
        from engine import timeparam_jit

        rows = timeparam_jit.group_rows(allr, order, keep, at_start, fi, off, valid, crow)
    if rows is None:
        vert = allr[np.arange(allr.shape[0])[:, None], order] * keep[..., None]   # (N-1, R, 2)
        vert_later = vert * ~at_start[..., None]
        rr = np.where((slot >= 1)[..., None, None], vert_later[fi], vert[fi])   # (B, mx, R, 2)
        g = rr[..., 0]
        cc = rr[..., 1] + 2.0 * off[..., None] * g
        rows = np.stack([g, cc], axis=-1) * valid[..., None, None]
        rows = rows.reshape(B, mx * R, 2)
        # both signs of every vertex row: the set stays centrally symmetric for _hull_sym (the compiled
        # hull does not need it; a mirror that is not a vertex is dropped by it)
        rows = np.concatenate([rows, -rows], axis=1)
        rows = np.concatenate([rows, crow, -crow], axis=1)
    ipos = np.arange(mx * R)
    ineg = mx * R + ipos
    base = 2 * mx * R
    ipos = np.r_[ipos, base + np.arange(mx)]
    ineg = np.r_[ineg, base + mx + np.arange(mx)]
    s = prob.s[idx]
    h = np.diff(s)
    cap = prob.cap[idx]
    xn, cap_dp, ch = _polygons(cap, h, rows, ipos, ineg, prob.limits, True, compiled=True,
                               hull_compiled=_compiled_hull_for(n), work=work)
    pos = {int(v): k for k, v in enumerate(idx)}
    pnodes = []
    for pt, nodes in prob.point_nodes:
        cn = np.array(sorted({pos[int(v)] for v in nodes if int(v) in pos}), dtype=np.int64)
        pnodes.append((pt, cn))
    e = np.zeros((B, 0, 0))
    coarse = _Problem(s=s, h=h, p=prob.p, d1=e, d2=e, cap_v=prob.cap_v[idx], cap_tech=prob.cap_tech[idx], cap=cap,
                      cap_dp=cap_dp, xn=xn[1:], rows=rows, limits=prob.limits, point_nodes=pnodes,
                      hull_rows=rows, ipos=ipos, ineg=ineg, **ch)
    return coarse, idx


def _with_chains(prob: _Problem, work: bool = False) -> _Problem:
    """``prob`` (prepared without chains) with its polygons and reachable caps (``work``: see
    :func:`_chains`)."""
    from dataclasses import replace as dc_replace

    xn, cap_dp, ch = _polygons(prob.cap, prob.h, prob.hull_rows, prob.ipos, prob.ineg, prob.limits, True,
                               compiled=True, hull_compiled=_compiled_hull_for(prob.s.size), work=work,
                               hull=prob.fine_hull)
    return dc_replace(prob, xn=xn[1:], cap_dp=cap_dp, slopes=None, work=[], fine_hull=None, **ch)


_SWEEP_MARGIN = 1e-9
"""The final sweep keeps every constraint row at ``<= 1 - _SWEEP_MARGIN`` (a 5e-10 share of the time)."""


def _sweep_fwd(rows: np.ndarray, two_h: np.ndarray, capx: np.ndarray, chi: np.ndarray, x0: float, xend: float,
               one: float, x: np.ndarray) -> int:
    """The forward pass of :func:`_sweep` (the rows' bounds made by numpy, then Python floats per node;
    compiled by numba element by element: the same bits).

    From ``x0``, ``x_{i+1}`` is the largest value every row ``g·x_i + c·(x_{i+1} - x_i)/(2h) <= one`` of
    interval i allows, ``min`` over the rows with ``c > 0`` of ``a·x_i + b`` (``q = 2h/c``, ``a = 1 - q·g``,
    ``b = q·one``), at most ``chi_{i+1}`` and ``capx_{i+1}``, at least ``max(0, max`` over the rows with
    ``c < 0)``; rows with ``c = 0`` need ``g·x_i <= one``.  Writes ``x``; returns -1, or the interval
    where no speed is left.  (The compiled pass also checks every row ``<= 1`` at the chosen speeds and
    returns the interval where one is not; here :func:`_sweep` checks them all at once.)"""
    n = capx.size
    g = rows[..., 0]
    c = rows[..., 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        q = two_h[:, None] / c
        a = 1.0 - q * g
        b = q * one
    pos, neg = c > 0, c < 0
    au, bu = np.where(pos, a, 0.0), np.where(pos, b, np.inf)
    al, bl = np.where(neg, a, 0.0), np.where(neg, b, -np.inf)
    g0 = np.max(np.where(c == 0, g, 0.0), axis=1).tolist()
    # Python floats per node (the same IEEE products and sums as numpy's, a few times faster on ~20 rows)
    AU, BU, AL, BL = au.tolist(), bu.tolist(), al.tolist(), bl.tolist()
    ch, cx = chi.tolist(), capx.tolist()
    xs = [0.0] * n
    xs[0] = x0
    fail = -1
    for i in range(n - 1):
        xk = xs[i]
        if g0[i] * xk > one:
            fail = i
            break
        up = min([a * xk + b for a, b in zip(AU[i], BU[i])])
        lo = max(0.0, max([a * xk + b for a, b in zip(AL[i], BL[i])]))
        if i + 1 == n - 1:
            xj = xend
        else:
            xj = min(up, ch[i + 1], cx[i + 1])
            if xj < lo:
                xj = lo
        if xj > up or xj < lo:
            fail = i
            break
        xs[i + 1] = xj
    x[:] = xs
    return fail


def _sweep(prob: _Problem) -> np.ndarray | None:
    """ṡ at every node of the greatest admissible law the sweep finds on ``prob``'s polygons and rows
    (``prob`` with chains), or ``None`` where it does not settle.

    TOPP-RA's scheme (backward: the speeds from which the end stays reachable,
    :func:`engine.timeparam_jit._sweep_back`; forward: from the start, the largest next speed that stays in
    them, :func:`_sweep_fwd`) on the same constraints as the DP: the rows of every interval (limits inside
    the interval, Bernstein certificates) and the node caps.  The forward pass takes its bounds from the rows
    with a margin of :data:`_SWEEP_MARGIN` (the round-off of the limits' evaluation on sub-grids stays well
    inside it), and the law is checked on the rows themselves (``<= 1``), so a returned law keeps every
    limit the DP's laws keep.
    Where the chains' round-off leaves an interval without a next speed, the sweep is repeated on chains
    built with the box of the reachable speeds, then given up (``None``).
    """
    n = prob.s.size
    if n < 3 or prob.rq.size == 0:
        return None
    rows = np.ascontiguousarray(prob.rows, float)
    two_h = 2.0 * prob.h
    one = 1.0 - _SWEEP_MARGIN
    capx = prob.cap_dp * prob.cap_dp
    x0, xend = prob.limits.sdot_start ** 2, prob.limits.sdot_end ** 2
    chains = (prob.rq, prob.rk, prob.lq, prob.lk, prob.xn, prob.xjb, prob.xjt)
    jit = None
    if _NUMBA:
        from engine import timeparam_jit

        jit = timeparam_jit.sweep_kernels()
    for attempt in range(2):
        if attempt:
            xn = (1.5 * prob.cap_dp) ** 2 + 1.0
            if np.all(xn[1:] >= prob.xn):
                return None             # the same box: the same chains
            ch = _chains(prob.hull_rows, prob.h, xn[:-1], xn[1:], prob.ipos, prob.ineg, True,
                         _compiled_hull_for(n))
            chains = (ch["rq"], ch["rk"], ch["lq"], ch["lk"], xn[1:], ch["xjb"], ch["xjt"])
        L = chains[0].size // (n - 1)
        x = np.empty(n)
        if jit is not None:
            clo, chi = np.empty(n), np.empty(n)
            f = np.ascontiguousarray
            fail = jit[0](*(f(v, float) for v in chains[:4]), L, *(f(v, float) for v in chains[4:]), f(capx, float),
                          xend, clo, chi)
            if fail < 0:
                fail = jit[1](rows, two_h, capx, chi, x0, xend, one, x)     # (the rows <= 1 checked there)
        else:
            cl, ch_ = [0.0] * n, [0.0] * n
            fail = _sweep_back(*(v.tolist() for v in chains[:4]), L, *(v.tolist() for v in chains[4:]),
                               capx.tolist(), xend, cl, ch_)
            if fail < 0:
                fail = _sweep_fwd(rows, two_h, capx, np.asarray(ch_), x0, xend, one, x)
            if fail < 0:                                        # every row <= 1 (as the compiled pass)
                u = (x[1:] - x[:-1]) / two_h
                bad = ~np.all(rows[..., 0] * x[:-1, None] + rows[..., 1] * u[:, None] <= 1.0, axis=1)
                fail = int(np.argmax(bad)) if bad.any() else -1
        if fail < 0:
            return np.minimum(np.sqrt(x), prob.cap_dp)   # (a rounded square root above a cap: 1 ulp)
    return None


def _keep_faster(prob: _Problem, sdot: np.ndarray) -> tuple[np.ndarray, float, dict[str, float] | None]:
    """The faster of the tube's law ``sdot`` and the sweep's (:func:`_sweep`) on ``prob`` (with chains): the
    law, the time (s) the sweep saved (0.0 when the tube's law is kept) and the sweep's limit ratios
    (:func:`evaluate_limits`; ``None`` when the tube's law is kept).

    The sweep's law is kept only when it is faster and its limits hold on the evaluation sub-grid of every
    interval (ratios <= 1)."""
    alt = _sweep(prob)
    if alt is None:
        return sdot, 0.0, None
    t_old = float(_times(prob.s, sdot)[-1])
    t_new = float(_times(prob.s, alt)[-1])
    if not t_new < t_old:
        return sdot, 0.0, None
    ratios = evaluate_limits(prob, alt)
    if max(ratios["accel"], ratios["speed"], ratios["sddot"], ratios["sdot"], ratios["points"]) > 1.0:
        return sdot, 0.0, None
    return alt, t_old - t_new, ratios


def _refine_to_nodes(s: np.ndarray, idx: np.ndarray, sdot_c: np.ndarray) -> np.ndarray:
    """ṡ at every node from the coarse law: ṡ² linear in s inside each group (constant s̈)."""
    x = np.interp(s, s[idx], sdot_c * sdot_c)
    out = np.sqrt(np.maximum(x, 0.0))
    out[idx] = sdot_c
    return out


# --------------------------------------------------------------------------------------------------
# The DP procedure (init, forward pass, backward pass)
# --------------------------------------------------------------------------------------------------


def _infeasible(prob: _Problem, i: int, why: str) -> InfeasibleError:
    s_i = prob.s[i]
    near = [pt for pt, nodes in prob.point_nodes if nodes.size and nodes[0] - 2 <= i <= nodes[-1] + 2]
    if near:
        pt = near[0]
        return InfeasibleError(f"{pt.describe()}: ṡ <= {pt.sdot_max:g} mm/s cannot be met -- no admissible "
                               f"speed law reaches s = {s_i:.2f} mm ({why})", field="points")
    return InfeasibleError(f"no admissible speed law reaches s = {s_i:.2f} mm (node {i}) within the axis "
                           f"and technological limits ({why})", field="limits")


_CHUNK = 1 << 16   # candidates costed at once (whole intervals)
_DENSE_SHARE = 0.95  # intervals with at least this share of the M² level pairs as candidates: as a matrix
_DENSE_BATCH = 32   # dense intervals costed at once (at most; fewer when M² is large: <= 2^19 pairs)
_DENSE_WORK = threading.local()


def _dense_work(size: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Three float work arrays of at least ``size`` elements for the dense intervals' costs, kept per thread
    between passes (a fresh array costs its first touch page by page: ~2 ms for a batch, every pass)."""
    bufs = getattr(_DENSE_WORK, "bufs", None)
    if bufs is None or bufs[0].size < size:
        bufs = _DENSE_WORK.bufs = tuple(np.empty(size) for _ in range(3))
    return bufs
# Build the next chunk in a worker thread: True, False, None = when a core is idle.  Off by default:
# measured on the 2-core machine (quiet, 2026-11-22) the GIL hand-offs between the worker's numpy calls
# and the sequential pass's many small ones cost more than the overlap gains (M = 100: 0.142 s on,
# 0.123 s off; M = 80: 0.154 vs 0.137 s).
_THREADS: bool | None = False
_POOL: list[ThreadPoolExecutor] = []
_STATS: dict[str, int] = {}  # size of the last DP pass (for the benchmark)
_LOBITS = 12
_LOMASK = np.int64((1 << _LOBITS) - 1)
_HIMASK = np.int64(~((1 << _LOBITS) - 1))


def _threads_wanted() -> bool:
    """Overlap chunk building with the sequential pass only when a second core is idle."""
    if _THREADS is not None:
        return bool(_THREADS)
    try:
        return (os.cpu_count() or 1) >= 2 and os.getloadavg()[0] < (os.cpu_count() or 1) - 0.75
    except OSError:  # pragma: no cover - no load average on this platform
        return False


def _pool() -> ThreadPoolExecutor:
    if not _POOL:
        _POOL.append(ThreadPoolExecutor(max_workers=1, thread_name_prefix="timeparam"))
    return _POOL[0]


def shutdown_pool() -> None:
    """Stop the chunk-building thread (finishing what it was given; a later time law starts a new one)."""
    while _POOL:
        _POOL.pop().shutdown(wait=True)


def _forward_compiled(chunks: list[tuple[int, int]], uniform_h: bool, two_h: np.ndarray, kq_h: np.ndarray,
                      levf: np.ndarray, klo: np.ndarray, cnt: np.ndarray, bad: np.ndarray, use_k: bool, M: int,
                      Jraw: np.ndarray) -> bool:
    """The forward pass by the compiled kernel (engine.timeparam_jit), bit for bit the numpy pass's
    result; False when it is not available (then the numpy pass runs)."""
    if not _NUMBA:
        return False
    from engine import timeparam_jit

    if uniform_h:  # the numpy pass costs a chunk with the 2h and K/4h² of its first interval
        first = np.repeat([a for a, _ in chunks], [b - a for a, b in chunks])
        th, kq = two_h[first], kq_h[first]
    else:
        th, kq = two_h, kq_h
    return timeparam_jit.forward_pass(levf, klo, cnt, bad, np.ascontiguousarray(th, float),
                                      np.ascontiguousarray(kq, float), use_k, M, int(_LOMASK), int(_HIMASK),
                                      Jraw.reshape(-1))


_NUMBA = True  # False: always the numpy pass (the tested reference; tests switch it)


@functools.lru_cache(maxsize=32)
def _level_tables(M: int, cluster: float) -> tuple[np.ndarray, int, np.ndarray, np.ndarray]:
    """The levels' fractions of the span (clustered towards the middle by ``cluster``) and the lookup
    tables of :func:`_dp`: the index of the first level >= / last level <= a fraction of the span, in
    bins that hold at most one level each (the estimate is then exact or one off; :func:`_dp` corrects
    it).  Cached (read-only arrays): every pass of a tube uses the same ones."""
    xi = np.linspace(-1.0, 1.0, M)
    a = float(cluster)
    frac = (1.0 + (xi + a * xi**3) / (1.0 + a)) / 2.0 if a > 0 else (xi + 1.0) / 2.0
    frac[0], frac[-1] = 0.0, 1.0
    nb = int(2.0 / max(float(np.min(np.diff(frac))), 1e-9)) + 2
    edges = np.arange(nb + 1) / nb
    t_lo = np.searchsorted(frac, edges[:-1], side="left")
    t_hi = np.searchsorted(frac, edges[1:], side="right") - 1
    for arr in (frac, t_lo, t_hi):
        arr.flags.writeable = False
    return frac, nb, t_lo, t_hi


def _dp(prob: _Problem, lo: np.ndarray, hi: np.ndarray, M: int, state: State | None = None,
        square: bool = False, cluster: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """One DP pass on the grid ``s_i × {M levels in [lo_i, hi_i]}``.

    The levels are uniform in ṡ (``square=False``, the paper's tube) or in ṡ² (``square=True``).
    Returns ``(sdot, jidx)``: the optimal speed at every node and its level index.  Minimises
    ``Σ Δt + K·(p·s̈)²`` subject to every interval's constraint rows.
    """
    n = prob.s.size
    K = prob.limits.penalty * prob.p ** 2
    plo, phi = (lo * lo, hi * hi) if square else (lo, hi)
    span = phi - plo
    degenerate = span <= 0
    span = np.where(degenerate, 0.0, span)
    frac, nb, t_lo, t_hi = _level_tables(M, float(cluster))
    sp_p = np.where(degenerate[:-1], 1.0, span[:-1])
    if not square and _NUMBA:
        from engine import timeparam_jit

        L = prob.rq.size // max(n - 1, 1)
        if prob.slopes is None:     # once per problem: the chains' segment slopes, 2h, K/4h², uniform h
            h = prob.h
            if prob.chain_slopes is not None:
                rs_ls = prob.chain_slopes
            else:
                with np.errstate(divide="ignore", invalid="ignore"):
                    rs_ls = (np.diff(prob.rk) / np.diff(prob.rq), np.diff(prob.lk) / np.diff(prob.lq))
            prob.slopes = (*rs_ls, 2.0 * h, (K / 4.0) / (h * h), bool(np.ptp(h) <= 1e-12 * h.max()))
        rs, ls, two_h, kq_h, uniform_h = prob.slopes
        fused = timeparam_jit.dp_pass((plo, span, phi, frac), prob.xn, (prob.rq, prob.rk, prob.lq, prob.lk, rs, ls), L,
                                      prob.xjb,
                                      prob.xjt, degenerate, plo, sp_p, t_lo, t_hi, nb, two_h, kq_h, uniform_h,
                                      _CHUNK, K > 0, int(_LOMASK), int(_HIMASK), work=prob.work)
        if fused is not None:                # windows, forward and backward pass in one call: the same bits
            _STATS["candidates"], bad_node, final_ok, jidx, sdot = fused
            if bad_node >= 0:
                raise _infeasible(prob, bad_node, "every transition into this node breaks a limit")
            if not final_ok:
                raise _infeasible(prob, n - 1, "the final speed cannot be reached")
            return sdot, jidx
    lev = np.minimum(plo[:, None] + span[:, None] * frac, phi[:, None])   # (N, M) in phi
    if square:
        xall = lev
        lev = np.sqrt(lev)
    else:
        xall = lev * lev
    win = None
    if not square and _NUMBA:
        from engine import timeparam_jit

        L = prob.rq.size // max(n - 1, 1)
        win = timeparam_jit.windows(lev, xall, prob.xn, (prob.rq, prob.rk, prob.lq, prob.lk), L, prob.xjb,
                                    prob.xjt, degenerate, plo, sp_p, t_lo, t_hi, nb)
    if win is not None:                      # the compiled windows: the same integers
        klo, cnt_eff, bad = win
    else:
        # --- windows (closed form): the feasible x_k of level j at node i form [L(x_j), R(x_j)] ------
        xj = xall[1:]
        q = xj / prob.xn[:, None]
        q += 3.0 * np.arange(n - 1)[:, None]
        q = q.ravel()
        ub = np.interp(q, prob.rq, prob.rk).reshape(n - 1, M)
        lb = np.interp(q, prob.lq, prob.lk).reshape(n - 1, M)
        ok = xj >= prob.xjb[:, None]
        ok &= xj <= prob.xjt[:, None]
        ok &= ub >= lb
        ok &= ub >= 0
        ok[degenerate[1:], 1:] = False
        if square:
            pk_lo = np.maximum(lb, 0.0)
            pk_hi = ub
        else:
            pk_lo = np.sqrt(np.maximum(lb, 0.0, out=lb), out=lb)
            pk_hi = np.sqrt(np.maximum(ub, 0.0, out=ub), out=ub)
        lo_p = plo[:-1, None]
        sp_p = np.where(degenerate[:-1], 1.0, span[:-1])[:, None]
        y = pk_lo - lo_p
        y /= sp_p                                                 # fraction of the span
        y *= nb
        klo = t_lo[np.clip(y.astype(np.int64), 0, nb - 1)]
        np.subtract(pk_hi, lo_p, out=y)
        y /= sp_p
        y *= nb
        khi = t_hi[np.clip(y.astype(np.int64), 0, nb - 1)]
        # exact correction against the actual level values (the index maps are only rounded)
        rowp = np.arange(0, (n - 1) * M, M, dtype=np.int64)[:, None]
        levp = lev.ravel() if not square else xall.ravel()
        kix = np.minimum(klo, M - 1)
        kix += rowp
        klo += (klo <= M - 1) & (levp[kix] < pk_lo)
        np.maximum(khi, 0, out=kix)
        kix += rowp
        khi -= (khi >= 0) & (levp[kix] > pk_hi)
        degp = degenerate[:-1]
        if degp.any():
            inside = (lo_p[degp] >= pk_lo[degp]) & (lo_p[degp] <= pk_hi[degp])
            klo[degp] = 0
            khi[degp] = np.where(inside, 0, -1)
        cnt_eff = khi - klo
        cnt_eff += 1
        cnt_eff[~ok] = 0
        bad = cnt_eff <= 0
        cnt_eff[bad] = 1                                                     # (N-1, M)
        klo[bad] = 0
    klo_i = klo
    # --- forward pass, in chunks of whole intervals of <= _CHUNK candidates ----------------------
    # Each candidate's cost has its position w in the window written into the low 12 bits of its
    # float64 pattern (costs are >= 0, so the integer order is the float order): one integer
    # minimum.reduceat then gives min and argmin together (J perturbed by <= 2^-40 relative).
    h = prob.h
    Kq = K / 4.0
    per_int = cnt_eff.sum(axis=1)
    _STATS["candidates"] = int(per_int.sum())
    bounds = [0]
    acc = 0
    for i, c in enumerate(per_int.tolist()):
        if acc and acc + c > _CHUNK:
            bounds.append(i)
            acc = 0
        acc += c
    bounds.append(n - 1)
    levf = lev.ravel()
    Jf = np.full(n * M, np.inf)
    Jf[0] = 0.0
    Jraw = Jf.view(np.int64).reshape(n, M)
    two_h = 2.0 * h
    uniform_h = bool(np.ptp(h) <= 1e-12 * h.max())
    kq_h = Kq / (h * h)
    ar_all = np.arange(_CHUNK + int(per_int.max()), dtype=np.int64)
    # work buffers, one set per chunk parity (the next chunk may be built while this one is used)
    t_max = min(int(per_int.sum()), _CHUNK + int(per_int.max()))
    bufs: list[tuple[np.ndarray, ...] | None] = [None, None]
    # intervals whose windows hold most of the (k, j) pairs: costed and minimised as an (M, M) matrix, without
    # the candidates' index arrays; the pairs outside the windows cost inf, so every finite J and its argmin
    # are the candidate list's (a state no law reaches stays not finite, maybe with other bits).  Their costs
    # are made in batches of _DENSE_BATCH intervals, with the 2h and K/4h² the list would use (of the chunk's
    # first interval when h is uniform).
    dense = per_int >= _DENSE_SHARE * M * M
    dense_at = np.flatnonzero(dense)
    dense_row = np.cumsum(dense) - 1                   # interval -> its row among the dense ones
    dense_set = set(dense_at.tolist())
    glow_row = np.arange(M, dtype=np.int64)
    dstate: dict[str, Any] = {"batch": -1}
    nbat = max(1, min(_DENSE_BATCH, (1 << 19) // (M * M)))

    def dense_costs(batch: int) -> np.ndarray:
        at = dense_at[batch * nbat:(batch + 1) * nbat]
        nf = at.size
        if "bufs" not in dstate:
            dstate["bufs"] = _dense_work(min(nbat, dense_at.size) * M * M)
        db = tuple(b[:nf * M * M].reshape(nf, M, M) for b in dstate["bufs"])
        first = chunk_first[at] if uniform_h else at
        vk_d = lev[at][:, None, :]                      # departure level k along the columns
        vj_d = lev[at + 1][:, :, None]                  # arrival level j along the rows
        ssum_d = np.add(vk_d, vj_d, out=db[0][:nf])
        diff_d = np.subtract(vj_d, vk_d, out=db[1][:nf])
        with np.errstate(divide="ignore"):
            cost_d = np.divide(two_h[first][:, None, None], ssum_d, out=db[2][:nf])
        if K > 0:
            diff_d *= ssum_d
            diff_d *= diff_d
            diff_d *= kq_h[first][:, None, None]
            cost_d += diff_d
        # the pairs outside the windows cost inf: the rows (arrivals j) whose window is not all levels
        r, j = np.nonzero((klo_i[at] > 0) | (cnt_eff[at] < M) | bad[at])
        if r.size:
            k0 = klo_i[at[r], j][:, None]
            out = glow_row < k0
            out |= glow_row >= k0 + cnt_eff[at[r], j][:, None]
            out |= bad[at[r], j][:, None]
            rows = cost_d[r, j]
            np.copyto(rows, np.inf, where=out)
            cost_d[r, j] = rows
        return cost_d

    def build(i0: int, i1: int, par: int = 0) -> tuple:
        if bufs[par] is None:
            bufs[par] = (np.empty(t_max), np.empty(t_max), np.empty(t_max), np.empty(t_max, np.int64))
        b_vk, b_ssum, b_cost, b_glow = bufs[par]
        ni = i1 - i0
        fl = dense[i0:i1]
        ce2 = cnt_eff[i0:i1]
        if fl.any():
            ce2 = np.where(fl[:, None], 0, ce2)         # the dense intervals: no list of candidates
        ce = ce2.ravel()
        st = np.zeros(ce.size + 1, np.int64)
        np.cumsum(ce, out=st[1:])
        T = int(st[-1])
        # global index G = node*M + k of the departure level of every candidate
        base = (np.arange(i0, i1, dtype=np.int64) * M)[:, None] + klo_i[i0:i1]
        G = np.repeat(base.ravel() - st[:-1], ce)
        G += ar_all[:T]
        glow = np.bitwise_and(G, _LOMASK, out=b_glow[:T])
        vk = np.take(levf, G, out=b_vk[:T], mode="clip")       # G is in range; "clip" is unbuffered
        vj = np.repeat(levf[(i0 + 1) * M:(i1 + 1) * M], ce)
        ssum = np.add(vk, vj, out=b_ssum[:T])
        vj -= vk
        diff = vj
        if uniform_h:
            with np.errstate(divide="ignore"):
                cost = np.divide(two_h[i0], ssum, out=b_cost[:T])
            if K > 0:
                diff *= ssum
                diff *= diff
                diff *= kq_h[i0]
                cost += diff
        else:
            per = ce.reshape(ni, M).sum(axis=1)
            with np.errstate(divide="ignore"):
                cost = np.divide(np.repeat(two_h[i0:i1], per), ssum, out=b_cost[:T])
            if K > 0:
                diff *= ssum
                diff *= diff
                diff *= np.repeat(kq_h[i0:i1], per)
                cost += diff
        cost[st[:-1][(bad[i0:i1] & ~fl[:, None] if fl.any() else bad[i0:i1]).ravel()]] = np.inf
        seg = st[:-1].reshape(ni, M)
        segl = seg - seg[:, :1]
        ends = np.append(seg[1:, 0], T).tolist()
        starts0 = seg[:, 0].tolist()
        return G, glow, cost, segl, starts0, ends

    chunks = list(zip(bounds[:-1], bounds[1:]))
    chunk_first = np.repeat(bounds[:-1], np.diff(bounds))
    if _forward_compiled(chunks, uniform_h, two_h, kq_h, levf, klo_i, cnt_eff, bad, K > 0, M, Jraw):
        chunks = []                                 # done by the compiled pass (same bits)
    listed = [not dense[i0:i1].all() for i0, i1 in chunks] if dense_set else [True] * len(chunks)
    fbuf = np.empty(max(int(per_int.max()), M * M))   # the sequential pass's scratch and its integer view
    ibuf = fbuf.view(np.int64)
    dbuf = fbuf[:M * M].reshape(M, M)
    dibuf = dbuf.view(np.int64)
    todo = [c for c in range(len(chunks)) if listed[c]]
    pool = _pool() if len(todo) > 1 and _threads_wanted() else None
    fut = pool.submit(build, *chunks[todo[0]], 0) if pool is not None else None
    nxt = 1
    for c, (i0, i1) in enumerate(chunks):
        if not listed[c]:
            pass
        elif pool is not None:
            G, glow, cost, segl, starts0, ends = fut.result()
            if nxt < len(todo):
                fut = pool.submit(build, *chunks[todo[nxt]], nxt % 2)   # build the next chunk meanwhile
                nxt += 1
        else:
            G, glow, cost, segl, starts0, ends = build(i0, i1)
        with np.errstate(invalid="ignore"):
            for i in range(i0, i1):
                if i in dense_set:          # every (k, j): J_k + cost, the same integer minimum over k
                    r = int(dense_row[i])
                    if r // nbat != dstate["batch"]:
                        dstate["batch"] = r // nbat
                        dstate["costs"] = dense_costs(dstate["batch"])
                    np.add(Jf[i * M:(i + 1) * M], dstate["costs"][r % nbat], out=dbuf)
                    dibuf &= _HIMASK
                    dibuf |= (glow_row + i * M) & _LOMASK
                    np.minimum.reduce(dibuf, axis=1, out=Jraw[i + 1])
                    continue
                ii = i - i0
                a, b = starts0[ii], ends[ii]
                cand = fbuf[:b - a]
                Jf.take(G[a:b], out=cand, mode="clip")      # G is in range; "clip" is unbuffered
                cand += cost[a:b]
                ci = ibuf[:b - a]
                ci &= _HIMASK
                ci |= glow[a:b]
                # min and argmin at once; the low bits stay in J (<= 2^-40 relative; infeasible -> NaN)
                np.minimum.reduceat(ci, segl[ii], out=Jraw[i + 1])
        if state is not None:
            check_cancel(state)
    # low bits hold (node*M + k) mod 2^12: recover k
    kstar = Jraw[1:] & _LOMASK
    kstar -= (np.arange(n - 1, dtype=np.int64) * M)[:, None]
    kstar &= _LOMASK
    Jraw &= _HIMASK
    Jm = Jf.reshape(n, M)
    reach = np.isfinite(Jm).any(axis=1)
    if not reach.all():
        i = int(np.argmin(reach))
        raise _infeasible(prob, i, "every transition into this node breaks a limit")
    if not np.isfinite(Jm[-1, 0]):
        raise _infeasible(prob, n - 1, "the final speed cannot be reached")
    # --- backward pass ---------------------------------------------------------------------------
    jidx = np.zeros(n, np.int64)
    j = 0
    for i in range(n - 2, -1, -1):
        j = int(kstar[i, j])
        jidx[i] = j
    sdot = lev[np.arange(n), jidx]
    return sdot, jidx


def _times(s: np.ndarray, sdot: np.ndarray) -> np.ndarray:
    h = np.diff(s)
    with np.errstate(divide="ignore"):
        dt = 2.0 * h / (sdot[:-1] + sdot[1:])
    return np.concatenate([[0.0], np.cumsum(dt)])


def _runs(mask: np.ndarray) -> int:
    m = mask.astype(np.int8)
    return int(np.sum(np.diff(np.concatenate([[0], m])) == 1))


# --------------------------------------------------------------------------------------------------
# Quality figures
# --------------------------------------------------------------------------------------------------


def curvature_energy(t: np.ndarray, sdot: np.ndarray, speed_unit: float = 1000.0) -> float:
    """Curvature energy ``E = ∫ k² dt`` of the plane curve ``(t, ṡ(t))`` (the paper's smoothness figure).

    ``k = |ṡ''| / (1 + ṡ'²)^(3/2)`` with three-point finite differences on the (non-uniform) node
    times; the integral is the trapezoid sum over the interior nodes.  ``ṡ`` is taken in mm/s divided
    by ``speed_unit`` -- by default m/s (SI), so that the figure is dominated by the real changes of
    acceleration; with ``speed_unit=1`` (mm/s) every ṡ' is large except at flat extrema, and a single
    one-level zigzag of the DP grid at a speed peak dominates the sum.
    """
    t = np.asarray(t, float)
    v = np.asarray(sdot, float) / speed_unit
    if t.size < 3:
        return 0.0
    dt = np.diff(t)
    h0, h1 = dt[:-1], dt[1:]
    ok = (h0 > 0) & (h1 > 0) & np.isfinite(h0) & np.isfinite(h1)
    h0, h1 = np.where(ok, h0, 1.0), np.where(ok, h1, 1.0)
    g0 = (v[1:-1] - v[:-2]) / h0
    g1 = (v[2:] - v[1:-1]) / h1
    d1 = (g0 * h1 + g1 * h0) / (h0 + h1)
    d2 = 2.0 * (g1 - g0) / (h0 + h1)
    k = np.abs(d2) / (1.0 + d1 * d1) ** 1.5
    return float(np.sum(np.where(ok, k * k * (h0 + h1) / 2.0, 0.0)))


def _limit_ratios(prob: _Problem, x0: np.ndarray, u: np.ndarray, tau: np.ndarray, A: np.ndarray, V: np.ndarray
                  ) -> tuple[float, float]:
    """``max |X''·x + X'·u|/A`` and ``max |X'|·√x/V`` over the intervals' sub-points ``tau`` (x = ṡ² =
    ``x0 + 2u·h·τ``, clipped at 0; X', X'' by Horner from the power coefficients): by the compiled loop
    where numba is loaded (:func:`engine.timeparam_jit.limit_ratios`, the same operations: the same
    bits), else in numpy in the layout (sub-point, interval, axis), every operation elementwise on
    contiguous slabs (the values of the former (interval, axis, sub-point) arrays, bit for bit)."""
    if _NUMBA:
        from engine import timeparam_jit

        res = timeparam_jit.limit_ratios(prob.d1, prob.d2, prob.h, x0, u, tau, A, V)
        if res is not None:
            return res
    T = tau.size
    n1, p = prob.d1.shape[:2]
    x = (2.0 * u * prob.h)[None, :] * tau[:, None]                              # (T, N-1)
    x += x0[None, :]
    np.maximum(x, 0.0, out=x)
    tc = tau[:, None, None]
    q = []
    for coef in (prob.d1, prob.d2):                  # Horner from 0: out = out·τ + c_n, n = deg .. 0
        c = np.moveaxis(coef, -1, 0).copy()                                        # (deg+1, N-1, p)
        out = np.zeros((T, n1, p))
        for n in range(c.shape[0] - 1, -1, -1):
            out *= tc
            out += c[n]
        q.append(out)
    q1, q2 = q
    acc = q2
    acc *= x[:, :, None]
    acc += q1 * u[None, :, None]
    np.abs(acc, out=acc)
    acc /= A
    np.abs(q1, out=q1)
    q1 *= np.sqrt(x)[:, :, None]
    q1 /= V
    return float(acc.max()), float(q1.max())


def evaluate_limits(prob: _Problem, sdot: np.ndarray, n_sub: int = _N_SUB) -> dict[str, float]:
    """Worst limit ratios of a speed law on a fine sub-grid inside every interval.

    ``prob`` comes from :func:`prepare`.  The path is the quintic Hermite interpolant of the nodes;
    ṡ² is linear in s inside an interval.  Returns ``accel`` (max |a_c|/A_c), ``speed``
    (max |v_c|/V_c), ``sddot`` (max |s̈|/s̈_T), ``sdot`` (max ṡ/ṡ_T,max) and ``points``
    (max ṡ/ṡ_TT at the technological points).
    """
    lim = prob.limits
    v = np.asarray(sdot, float)
    tau = np.linspace(0.0, 1.0, n_sub + 1)
    x0 = v[:-1] ** 2
    u = (v[1:] ** 2 - x0) / (2.0 * prob.h)
    accel, speed = _limit_ratios(prob, x0, u, tau, np.asarray(lim.a_max, float), np.asarray(lim.v_max, float))
    out = {
        "accel": accel,
        "speed": speed,
        "sddot": float(np.abs(u).max() / lim.sddot_max) if math.isfinite(lim.sddot_max) else 0.0,
        "sdot": float(v.max() / lim.sdot_max) if math.isfinite(lim.sdot_max) else 0.0,
        "points": 0.0,
    }
    worst = 0.0
    for pt, _nodes in prob.point_nodes:
        a = pt.s if pt.s is not None else pt.s_from
        b = pt.s if pt.s is not None else pt.s_to
        i0 = max(int(np.searchsorted(prob.s, a, side="right")) - 1, 0)
        i1 = min(int(np.searchsorted(prob.s, b, side="left")), prob.s.size - 1)
        vmax = float(v[i0:i1 + 1].max())   # ṡ is monotone inside intervals: ends bound it
        worst = max(worst, vmax / pt.sdot_max if pt.sdot_max > 0 else (np.inf if vmax > 0 else 0.0))
    out["points"] = float(worst)
    return out


# --------------------------------------------------------------------------------------------------
# The methods
# --------------------------------------------------------------------------------------------------


def _bounds_check(prob: _Problem) -> tuple[np.ndarray, np.ndarray]:
    lim = prob.limits
    n = prob.s.size
    if lim.sdot_start > prob.cap[0] * (1 + 1e-12):
        raise InfeasibleError(f"the start speed {lim.sdot_start:g} mm/s exceeds the speed limit "
                              f"{prob.cap[0]:g} mm/s at s = {prob.s[0]:.2f} mm", field="sdot_start")
    if lim.sdot_end > prob.cap[-1] * (1 + 1e-12):
        raise InfeasibleError(f"the end speed {lim.sdot_end:g} mm/s exceeds the speed limit "
                              f"{prob.cap[-1]:g} mm/s at s = {prob.s[-1]:.2f} mm", field="sdot_end")
    bad = ~(prob.cap_dp < 1e8)
    if bad.any():
        i = int(np.argmax(bad))
        raise InputError(f"the path speed is unbounded at s = {prob.s[i]:.2f} mm (no axis moves there and "
                         f"no technological limit): give sdot_max", field="sdot_max")
    lo = np.zeros(n)
    hi = prob.cap_dp.copy()
    lo[0] = hi[0] = lim.sdot_start
    lo[-1] = hi[-1] = lim.sdot_end
    # an interval with zero speed at both ends is never traversed
    zz = np.flatnonzero((hi[:-1] <= 0) & (hi[1:] <= 0))
    if zz.size:
        i = int(zz[0])
        for pt, nodes in prob.point_nodes:
            if pt.sdot_max <= 0 and nodes[0] <= i + 1 and i <= nodes[-1]:
                raise InfeasibleError(
                    f"{pt.describe()}: ṡ <= 0 between nodes s = {prob.s[i]:.2f} and {prob.s[i + 1]:.2f} mm "
                    f"-- the path cannot stop there (a stop is possible only at a node; put the point "
                    f"exactly on a node or give it a speed > 0)", field="points")
        if n == 2:
            raise InfeasibleError("a path of one interval cannot start and end at rest; give more nodes or "
                                  "a non-zero start/end speed", field="s")
        raise InfeasibleError(f"the speed limit is zero on both ends of the interval s = {prob.s[i]:.2f}.."
                              f"{prob.s[i + 1]:.2f} mm; the path cannot be traversed", field="limits")
    return lo, hi


def _touches(jidx: np.ndarray, lo: np.ndarray, hi: np.ndarray, prob: _Problem, M: int
             ) -> tuple[np.ndarray, np.ndarray]:
    n = jidx.size
    inner = np.zeros(n, bool)
    inner[1:-1] = hi[1:-1] > lo[1:-1]
    at_hi = inner & (jidx == M - 1)
    at_lo = inner & (jidx == 0)
    hi_on_limit = hi >= prob.cap * (1 - 1e-12)
    lo_on_limit = lo <= 0.0
    w = (at_hi & ~hi_on_limit) | (at_lo & ~lo_on_limit)
    o = (at_hi & hi_on_limit) | (at_lo & lo_on_limit)
    return w, o


def _tube(prob: _Problem, state: State | None) -> tuple[np.ndarray, list[IterationLog]]:
    lim = prob.limits
    M = lim.levels
    s = prob.s
    sN = s[-1] - s[0]
    lo, hi = _bounds_check(prob)
    logs: list[IterationLog] = []
    if state is not None:
        state.progress(0.0, "nominal DP")
    sdot, jidx = _dp(prob, lo, hi, M, state)
    t_total = float(_times(s, sdot)[-1])
    tsp_prev = t_total / sN
    no_mask = np.zeros(s.size, bool)
    log = IterationLog(1, t_total, tsp_prev, None, 0, 0, None, False, False, s, sdot, lo, hi, no_mask, no_mask)
    logs.append(log)
    if state is not None:
        state.partial(log)
    sh = lim.tube_share * float(sdot.max())
    prev_touch_free = False
    r = 1
    while r < lim.max_iterations:
        check_cancel(state)
        r += 1
        lo = np.maximum(sdot - sh, 0.0)
        hi = np.minimum(sdot + sh, prob.cap)
        lo[0] = hi[0] = lim.sdot_start
        lo[-1] = hi[-1] = lim.sdot_end
        lo = np.minimum(lo, hi)
        sh_used = sh
        try:
            sdot_r, jidx = _dp(prob, lo, hi, M, state, cluster=lim.tube_cluster)
        except InfeasibleError as exc:
            # the previous law is feasible but not on this tube's grid: keep it and stop
            log = IterationLog(r, logs[-1].total_time_s, tsp_prev, sh, 0, 0, 0.0, False, True, s, sdot,
                               lo, hi, np.zeros(s.size, bool), np.zeros(s.size, bool),
                               note=f"no admissible law on this tube's grid ({exc.message}); "
                                    f"the previous iteration's law is kept")
            logs.append(log)
            if state is not None:
                state.partial(log)
            break
        t_total = float(_times(s, sdot_r)[-1])
        tsp = t_total / sN
        w, o = _touches(jidx, lo, hi, prob, M)
        touch_free = not w.any()
        halved = False
        if touch_free:
            sh /= 2.0
            halved = True
        P = (1.0 - tsp / tsp_prev) * 100.0
        stop = touch_free and prev_touch_free and P < lim.stop_percent
        log = IterationLog(r, t_total, tsp, sh_used, _runs(w), _runs(o), P, halved, stop, s, sdot_r,
                           lo, hi, w, o)
        logs.append(log)
        if state is not None:
            state.partial(log)
            state.progress(min(0.95, 0.1 + 0.85 * (1 - 0.5 ** (r / 3))), f"tube iteration {r}")
        sdot, tsp_prev, prev_touch_free = sdot_r, tsp, touch_free
        if stop:
            break
    return sdot, logs


class _ToppraPath:
    """The quintic Hermite path in toppra's interface, parameter σ = s / 1000 (m) and an extra
    coordinate equal to σ carrying the technological limits on ṡ and s̈."""

    def __init__(self, prob: _Problem, X0: np.ndarray) -> None:
        self.prob = prob
        self.X0 = X0

    @property
    def dof(self) -> int:
        return self.prob.p + 1

    @property
    def path_interval(self) -> np.ndarray:
        return np.array([self.prob.s[0], self.prob.s[-1]]) / 1000.0

    @property
    def waypoints(self) -> None:
        return None

    def __call__(self, path_positions: Any, order: int = 0) -> np.ndarray:
        sig = np.atleast_1d(np.asarray(path_positions, float))
        ss = np.clip(sig * 1000.0, self.prob.s[0], self.prob.s[-1])
        i = np.clip(np.searchsorted(self.prob.s, ss, side="right") - 1, 0, self.prob.s.size - 2)
        tau = (ss - self.prob.s[i]) / self.prob.h[i]
        out = np.zeros((sig.size, self.dof))
        if order == 0:
            # positions are not used by the constraints; return a first-order estimate
            out[:, :-1] = self.X0[i]
            out[:, -1] = sig
        elif order == 1:
            c = self.prob.d1[i]                                          # (n, p, 5)
            out[:, :-1] = np.einsum("npk,nk->np", c, tau[:, None] ** np.arange(5)) * 1000.0
            out[:, -1] = 1.0
        elif order == 2:
            c = self.prob.d2[i]
            out[:, :-1] = np.einsum("npk,nk->np", c, tau[:, None] ** np.arange(4)) * 1.0e6
        else:
            raise ValueError(order)
        return out if np.ndim(path_positions) else out[0]

    eval = __call__  # noqa: A003

    def evald(self, ss: Any) -> np.ndarray:
        return self(ss, 1)

    def evaldd(self, ss: Any) -> np.ndarray:
        return self(ss, 2)


def _toppra(prob: _Problem, X: np.ndarray) -> np.ndarray:
    import logging

    import toppra
    import toppra.algorithm as algo
    import toppra.constraint as constraint
    from toppra.interpolator import AbstractGeometricPath

    logging.getLogger("toppra").setLevel(logging.ERROR)
    lim = prob.limits
    path = type("TPath", (_ToppraPath, AbstractGeometricPath), {})(prob, X)
    grid = prob.s / 1000.0
    vnode = np.minimum(prob.cap_tech, 1e12) / 1000.0      # m/s
    V = np.asarray(lim.v_max, float)

    table = np.empty((grid.size, prob.p + 1, 2))
    table[:, :-1, 0], table[:, :-1, 1] = -V, V
    table[:, -1, 0], table[:, -1, 1] = -vnode - 1e-12, vnode + 1e-12
    glist = grid.tolist()

    def vlim(sig: float) -> np.ndarray:
        i = min(max(bisect.bisect_left(glist, float(sig) - 1e-12), 0), len(glist) - 1)
        return table[i]

    sdd = lim.sddot_max / 1000.0 if math.isfinite(lim.sddot_max) else 1e9
    alim = np.concatenate([np.asarray(lim.a_max, float), [sdd]])
    cons = [constraint.JointVelocityConstraintVarying(vlim),
            constraint.JointAccelerationConstraint(np.stack([-alim, alim], 1),
                                                   discretization_scheme=constraint.DiscretizationType.Interpolation)]
    inst = algo.TOPPRA(cons, path, gridpoints=grid, solver_wrapper="seidel")
    sdd_vec, sd_vec, _, _ = inst.compute_parameterization(lim.sdot_start / 1000.0, lim.sdot_end / 1000.0,
                                                          return_data=True)
    del toppra
    if sd_vec is None:
        raise InfeasibleError("TOPP-RA finds no admissible speed law under these limits", field="limits")
    return np.maximum(np.asarray(sd_vec, float), 0.0) * 1000.0


def parametrize(path_s: Any, X: Any, dX: Any, ddX: Any, limits: TimeLimits, method: str = "tube",
                state: State | None = None) -> TimeLaw:
    """Find the time law ``ṡ(s)`` of a path under axis and technological limits.

    Parameters
    ----------
    path_s:
        Node values s_i (mm), strictly increasing, shape (N,).
    X, dX, ddX:
        Coordinates (rad or mm) and their first/second derivatives in s at the nodes, shape (N, p).
    limits:
        :class:`TimeLimits`.
    method:
        ``"tube"`` (DP + narrowing tube, the paper's algorithm), ``"dp"`` (a single DP with
        ``limits.levels`` levels) or ``"toppra"`` (time-optimal reference).
    state:
        Optional job state (progress, cancellation, partial results = tube iterations).

    Returns
    -------
    TimeLaw

    Raises
    ------
    InputError
        Malformed input.
    InfeasibleError
        No speed law satisfies the limits (names the technological point or the s where it fails).
    """
    if method not in METHODS:
        raise InputError(f"unknown method {method!r}; use one of {', '.join(METHODS)}", field="method")
    t0 = time.perf_counter()
    if _NUMBA and method != "toppra" and np.size(path_s) >= 2:
        from engine import timeparam_jit

        timeparam_jit.kernel(int(np.size(path_s)))        # loads numba for big problems (see there)
    prob = _prepare(path_s, X, dX, ddX, limits, chains=method == "dp", work=True)
    iterations: list[IterationLog] = []
    group = 1
    gain = 0.0
    ratios = None
    if method == "tube":
        ell = _group_length(prob)
        if ell is not None:
            coarse, idx = _coarse_problem(prob, ell, work=True)
            sdot_c, iterations = _tube(coarse, state)
            sdot = _refine_to_nodes(prob.s, idx, sdot_c)
            group = max(1, round((prob.s.size - 1) / max(idx.size - 1, 1)))
            if limits.sweep:
                prob = _with_chains(prob, work=True)
        else:
            prob = _with_chains(prob, work=True)
            sdot, iterations = _tube(prob, state)
        if limits.sweep:
            check_cancel(state)
            sdot, gain, ratios = _keep_faster(prob, sdot)
    elif method == "dp":
        lo, hi = _bounds_check(prob)
        if state is not None:
            state.progress(0.0, f"DP with M = {limits.levels}")
        sdot, _ = _dp(prob, lo, hi, limits.levels, state)
    else:
        _bounds_check(prob)
        if state is not None:
            state.progress(0.0, "TOPP-RA")
        sdot = _toppra(prob, np.asarray(X, float).reshape(prob.s.size, -1))
    compute = time.perf_counter() - t0
    t = _times(prob.s, sdot)
    if ratios is None:
        ratios = evaluate_limits(prob, sdot)
    if state is not None:
        state.progress(1.0, "done")
    return TimeLaw(method=method, s=prob.s, sdot=sdot, t=t, total_time_s=float(t[-1]), iterations=iterations,
                   max_accel_ratio=ratios["accel"], max_speed_ratio=ratios["speed"],
                   max_sddot_ratio=ratios["sddot"], energy=curvature_energy(t, sdot), compute_s=compute,
                   levels=limits.levels if method != "toppra" else 0,
                   energy_mm=curvature_energy(t, sdot, speed_unit=1.0), node_group=group, sweep_gain_s=gain)


def prepare(path_s: Any, X: Any, dX: Any, ddX: Any, limits: TimeLimits) -> _Problem:
    """The set-up shared by all methods (interpolant, speed caps, constraint rows); for tests/tools."""
    return _prepare(path_s, X, dX, ddX, limits)


# --------------------------------------------------------------------------------------------------
# NC output
# --------------------------------------------------------------------------------------------------


def time_at(law: TimeLaw, s_query: Any) -> np.ndarray:
    """Exact time (s) at arbitrary ``s`` values under the law (constant s̈ inside each interval)."""
    s = law.s
    sq = np.asarray(s_query, float)
    i = np.clip(np.searchsorted(s, sq, side="right") - 1, 0, s.size - 2)
    sig = sq - s[i]
    v0 = law.sdot[i]
    v1 = law.sdot[i + 1]
    h = s[i + 1] - s[i]
    u = (v1 ** 2 - v0 ** 2) / (2.0 * h)
    vs = np.sqrt(np.maximum(v0 ** 2 + 2.0 * u * sig, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        # t = 2σ/(v0 + v(σ)) is exact for constant acceleration and stable for u -> 0
        dt = np.where(sig > 0, 2.0 * sig / (v0 + vs), 0.0)
    return law.t[i] + dt


def block_feeds(law: TimeLaw, s_block_ends: Sequence[float] | np.ndarray, decimals: int | None = None
                ) -> tuple[np.ndarray, np.ndarray]:
    """Per-block durations and G93 inverse-time feed numbers for NC blocks along the path.

    Parameters
    ----------
    law:
        The time law.
    s_block_ends:
        End points of the NC blocks, in order: s values (mm, float array) or node indices (integer
        array).  The first block starts at ``law.s[0]``; the last end should be the path end.
    decimals:
        Round the feed numbers to this many decimals as the controller would (rounded down, so no
        block becomes faster than the law allows); ``None`` keeps them exact.

    Returns
    -------
    durations_s, inverse_time_feed_per_min:
        Block durations (s) and ``F = 1 / duration`` in 1/min (``G93 ... F``).
    """
    ends = np.asarray(s_block_ends)
    if ends.ndim != 1 or ends.size == 0:
        raise InputError(f"block ends must be a non-empty 1-D array, got shape {ends.shape}", field="blocks")
    if np.issubdtype(ends.dtype, np.integer):
        if ends.min() < 1 or ends.max() >= law.s.size:
            raise InputError(f"block end indices must be in 1..{law.s.size - 1}, got {ends.min()}..{ends.max()}",
                             field="blocks")
        ends = law.s[ends]
    ends = ends.astype(float)
    tol = 1e-9 * max(1.0, abs(law.s[-1]))
    if ends.min() < law.s[0] - tol or ends.max() > law.s[-1] + tol:
        raise InputError(f"block ends must lie in s = {law.s[0]:.3f}..{law.s[-1]:.3f} mm", field="blocks")
    allpts = np.concatenate([[law.s[0]], np.clip(ends, law.s[0], law.s[-1])])
    if np.any(np.diff(allpts) <= 0):
        i = int(np.argmax(np.diff(allpts) <= 0))
        raise InputError(f"block ends must increase strictly; block {i + 1} ends at s = {allpts[i + 1]:.4f} mm",
                         field="blocks")
    tb = time_at(law, allpts)
    dur = np.diff(tb)
    if not np.all(np.isfinite(dur)):
        raise InputError("a block has no finite duration (the law stops inside it)", field="blocks")
    feed = 60.0 / dur
    if decimals is not None:
        q = 10.0 ** decimals
        feed = np.floor(feed * q) / q
        feed = np.maximum(feed, 1.0 / q)
        dur = 60.0 / feed
    return dur, feed

