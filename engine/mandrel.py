"""Mandrel generatrix r(z) of a shell of revolution (MATH.md §A1).

A :class:`Mandrel` is a chain of segments on consecutive z intervals.  Each segment evaluates
r, r', r'' in closed form (lines, circle arcs, ellipse arcs), from a Chebyshev representation
(isotensoid domes) or from a C2 cubic spline (user sketches, tables, imported profiles).  All
evaluation is vectorised over z.

Conventions
-----------
* ``z`` along the rotation axis, ``r`` the distance from it; both in mm.
* The mandrel spans the winding zone ``[z_min, z_max]``; ``r(z_min)`` and ``r(z_max)`` are the
  polar-opening radii (``pole_radii``).  Inside the zone r > 0 is required.
* At a joint of two segments r and r' are continuous (checked); r'' may jump where the geometry
  itself does (cylinder to hemisphere); spline mandrels are C2 throughout.  At a joint, evaluation
  takes the segment to the right.

Constructors: :meth:`Mandrel.vessel` (cylinder + hemispherical / elliptical / isotensoid domes,
unequal pole openings), :meth:`Mandrel.cone`, :meth:`Mandrel.pipe`, :meth:`Mandrel.bottle`
(concave waisted neck), :meth:`Mandrel.from_points` (C2 spline through user points).  Importers
for CSV/DXF/STEP are in :mod:`engine.mandrel_io`.
"""

from __future__ import annotations

import math
import numbers
import threading
from collections import OrderedDict
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any, ClassVar

import numpy as np
from numpy.polynomial import chebyshev as C
from numpy.typing import ArrayLike, NDArray

from engine.errors import InputError

FloatArray = NDArray[np.float64]

_GL_X, _GL_W = np.polynomial.legendre.leggauss(64)


def _gauss(a: float, b: float, n_sub: int = 8) -> tuple[FloatArray, FloatArray]:
    """Composite 64-point Gauss-Legendre nodes and weights on [a, b]."""
    edges = np.linspace(a, b, n_sub + 1)
    half = 0.5 * np.diff(edges)
    mid = 0.5 * (edges[:-1] + edges[1:])
    x = (mid[:, None] + half[:, None] * _GL_X[None, :]).ravel()
    w = (half[:, None] * _GL_W[None, :]).ravel()
    return x, w


# ------------------------------------------------------------------------------------------------
# Segments
# ------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Segment:
    """One piece of the generatrix on ``[z0, z1]`` (mm)."""

    z0: float
    z1: float
    kind: ClassVar[str] = "segment"

    def eval(self, z: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """r, dr/dz, d2r/dz2 at ``z`` (mm, -, 1/mm)."""
        raise NotImplementedError

    def breakpoints(self) -> FloatArray:
        """Interior z (mm) where r'' has a kink or an extremum: nodes for the line integration and the
        no-bridging check (a knot of a spline, the crest of an arc, a zero of r''').

        Generic: local extrema of r'' on 2049 samples, refined by a parabola through three samples.
        """
        z = np.linspace(self.z0, self.z1, 2049)
        d2 = self.eval(z)[2]
        d = np.diff(d2)
        k = np.flatnonzero(np.sign(d[:-1]) * np.sign(d[1:]) < 0) + 1
        if not k.size:
            return np.zeros(0)
        h = z[1] - z[0]
        den = d2[k - 1] - 2.0 * d2[k] + d2[k + 1]
        off = np.divide(0.5 * (d2[k - 1] - d2[k + 1]), den, out=np.zeros(k.size), where=den != 0)
        out = z[k] + np.clip(off, -1.0, 1.0) * h
        return out[(out > self.z0) & (out < self.z1) & np.isfinite(out)]

    def param_nodes(self) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """Quadrature in a smooth parameter: (r, dz/dp, ds/dp, weights) for area and volume."""
        z, w = _gauss(self.z0, self.z1)
        r, dr, _ = self.eval(z)
        return r, np.ones_like(z), np.sqrt(1.0 + dr * dr), w

    def spec(self) -> dict[str, Any]:
        """A JSON/TOML-able description (for reports)."""
        return {"kind": self.kind, "z0": self.z0, "z1": self.z1}


@dataclass(frozen=True)
class LineSegment(Segment):
    """Straight generatrix from (z0, r0) to (z1, r1): cylinder or cone."""

    r0: float = 0.0
    r1: float = 0.0
    kind: ClassVar[str] = "line"

    def eval(self, z: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        k = (self.r1 - self.r0) / (self.z1 - self.z0)
        return self.r0 + k * (z - self.z0), np.full_like(z, k), np.zeros_like(z)

    def breakpoints(self) -> FloatArray:
        return np.zeros(0)


@dataclass(frozen=True)
class SmoothStepSegment(Segment):
    """r = r0 + (r1 − r0)·P(u), u = (z − z0)/(z1 − z0), P = 10u³ − 15u⁴ + 6u⁵.

    r' and r'' vanish at both ends, so the segment joins lines (and other smooth steps) C2.
    """

    r0: float = 0.0
    r1: float = 0.0
    kind: ClassVar[str] = "smoothstep"

    def eval(self, z: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        h = self.z1 - self.z0
        u = (z - self.z0) / h
        d = self.r1 - self.r0
        p = u**3 * (10.0 - 15.0 * u + 6.0 * u * u)
        dp = 30.0 * u**2 * (1.0 - u) ** 2
        d2p = 60.0 * u * (1.0 - u) * (1.0 - 2.0 * u)
        return self.r0 + d * p, d * dp / h, d * d2p / (h * h)

    def breakpoints(self) -> FloatArray:
        # the zeros of P''' = 60(1 − 6u + 6u²): u = 1/2 ∓ sqrt(3)/6
        u = np.array([0.5 - math.sqrt(3.0) / 6.0, 0.5 + math.sqrt(3.0) / 6.0])
        return self.z0 + u * (self.z1 - self.z0)


@dataclass(frozen=True)
class ArcSegment(Segment):
    """Circle arc r = rc + side·sqrt(a² − (z − zc)²), radius ``a`` (mm), centre (zc, rc).

    ``side`` = +1: the upper half of the circle (convex, r'' < 0, the centre below the arc);
    −1: the lower half (concave, r'' > 0, the centre above the arc).
    """

    zc: float = 0.0
    rc: float = 0.0
    a: float = 1.0
    side: int = 1
    kind: ClassVar[str] = "arc"

    def eval(self, z: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        u = z - self.zc
        q = np.sqrt(np.maximum(self.a * self.a - u * u, 0.0))
        sd = float(self.side)
        with np.errstate(divide="ignore", invalid="ignore"):
            dr = -sd * u / q
            d2r = -sd * (self.a * self.a) / (q * q * q)
        return self.rc + sd * q, dr, d2r

    def breakpoints(self) -> FloatArray:
        return np.array([self.zc]) if self.z0 < self.zc < self.z1 else np.zeros(0)

    def _angles(self) -> tuple[float, float]:
        t0 = math.acos(np.clip((self.z0 - self.zc) / self.a, -1, 1))
        t1 = math.acos(np.clip((self.z1 - self.zc) / self.a, -1, 1))
        return t0, t1

    def param_nodes(self) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        # z = zc + a cos t, r = rc + a sin t, t decreasing from t0 to t1
        t0, t1 = self._angles()
        t, w = _gauss(t1, t0)
        r = self.rc + self.side * self.a * np.sin(t)
        return r, self.a * np.sin(t), np.full_like(t, self.a), w

    def spec(self) -> dict[str, Any]:
        return {**super().spec(), "center": [self.zc, self.rc], "radius": self.a, "side": self.side}


@dataclass(frozen=True)
class EllipseSegment(Segment):
    """Ellipse arc r = rc + b·sqrt(1 − ((z − zc)/a)²): centre (zc, rc), axial semi-axis a, radial
    semi-axis b (mm); the upper half (convex)."""

    zc: float = 0.0
    a: float = 1.0
    b: float = 1.0
    rc: float = 0.0
    kind: ClassVar[str] = "ellipse"

    def eval(self, z: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        u = (z - self.zc) / self.a
        q = np.sqrt(np.maximum(1.0 - u * u, 0.0))
        with np.errstate(divide="ignore", invalid="ignore"):
            dr = -self.b * u / (self.a * q)
            d2r = -self.b / (self.a * self.a * q * q * q)
        return self.rc + self.b * q, dr, d2r

    def breakpoints(self) -> FloatArray:
        return np.array([self.zc]) if self.z0 < self.zc < self.z1 else np.zeros(0)

    def param_nodes(self) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        t0 = math.acos(np.clip((self.z0 - self.zc) / self.a, -1, 1))
        t1 = math.acos(np.clip((self.z1 - self.zc) / self.a, -1, 1))
        t, w = _gauss(t1, t0)
        r = self.rc + self.b * np.sin(t)
        dz = self.a * np.sin(t)
        ds = np.hypot(self.a * np.sin(t), self.b * np.cos(t))
        return r, dz, ds, w

    def spec(self) -> dict[str, Any]:
        return {**super().spec(), "center": [self.zc, self.rc], "semi_axes": [self.a, self.b]}


@dataclass(frozen=True)
class SplineSegment(Segment):
    """C2 cubic spline r(z) through points (SciPy's ``CubicSpline``, via :mod:`engine.knot_spline`).

    ``slopes`` (r' at the first and the last point) clamp the ends where given (a tangent joint of a
    sketch); an end without a slope is not-a-knot.
    """

    z_pts: tuple[float, ...] = ()
    r_pts: tuple[float, ...] = ()
    slopes: tuple[float | None, float | None] = (None, None)
    kind: ClassVar[str] = "spline"

    @cached_property
    def _spline(self) -> Any:
        from engine.knot_spline import CubicSpline  # SciPy's CubicSpline bit for bit, lighter import

        s0, s1 = self.slopes
        n = len(self.z_pts)
        if s0 is None and s1 is None:
            bc: Any = "not-a-knot"
        elif n < 3 and (s0 is None or s1 is None):
            bc = ((1, s0), (2, 0.0)) if s1 is None else ((2, 0.0), (1, s1))
        else:
            bc = ("not-a-knot" if s0 is None else (1, s0), "not-a-knot" if s1 is None else (1, s1))
        return CubicSpline(np.asarray(self.z_pts), np.asarray(self.r_pts), bc_type=bc)

    def breakpoints(self) -> FloatArray:
        """The interior knots (mm): r'' is linear between them, so its kinks and extrema are there."""
        return np.asarray(self.z_pts[1:-1], dtype=float)

    def eval(self, z: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        s = self._spline
        return s(z), s(z, 1), s(z, 2)

    def param_nodes(self) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        x = np.asarray(self.z_pts)
        zs, ws = [], []
        for a, b in zip(x[:-1], x[1:]):  # exact per polynomial piece
            z, w = _gauss(float(a), float(b), 1)
            zs.append(z)
            ws.append(w)
        z = np.concatenate(zs)
        r, dr, _ = self.eval(z)
        return r, np.ones_like(z), np.sqrt(1.0 + dr * dr), np.concatenate(ws)

    def spec(self) -> dict[str, Any]:
        return {**super().spec(), "points": len(self.z_pts)}


@dataclass(frozen=True)
class IsotensoidSegment(Segment):
    """Geodesic-isotensoid dome (netting theory) joined to a cylinder of radius ``R`` at ``zc``.

    With ρ = r/R and ρ0 = C/R the Clairaut constant of the geodesic, the meridian obeys
    dζ/dρ = −ρ³·sqrt(1 − ρ0²) / sqrt(ρ² − ρ0² − ρ⁶(1 − ρ0²)), ζ = (z − zc)/R.  The dome runs from
    the equator (ρ = 1) to the pole ρ_p where the meridian is again parallel to the axis, with
    ρ0² = (ρ_p² − ρ_p⁶)/(1 − ρ_p⁶).  The substitution ρ = 1 − (1 − ρ_p)(1 − cos t)/2 removes both
    square-root singularities, so ζ(t) is analytic and is held as a Chebyshev series.
    ``direction`` is +1 for a dome at the right end (z grows towards the pole), −1 at the left.
    """

    zc: float = 0.0
    R: float = 1.0
    rho_p: float = 0.2
    direction: int = 1
    kind: ClassVar[str] = "isotensoid"

    @staticmethod
    def dome_length(R: float, pole_radius: float) -> float:
        """Axial length (mm) of the isotensoid dome of radius ``R`` ending at ``pole_radius``."""
        return R * IsotensoidSegment._series(pole_radius / R)[2]

    @staticmethod
    def _series(rho_p: float) -> tuple[Any, Any, float]:
        return _isotensoid_series(round(float(rho_p), 15))

    def _t_of_z(self, z: FloatArray) -> FloatArray:
        zeta_c, dzeta_c, length = self._series(self.rho_p)
        zeta = np.clip(self.direction * (z - self.zc) / self.R, 0.0, length)
        t_tab, zeta_tab = _zeta_table(round(float(self.rho_p), 15))
        t = np.interp(zeta, zeta_tab, t_tab)
        for _ in range(6):
            f = _chebval(_to_cheb(t), zeta_c) - zeta
            t = np.clip(t - f / _chebval(_to_cheb(t), dzeta_c), 0.0, math.pi)
        return t

    def eval(self, z: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """r, r', r'' at ``z`` (mm, -, 1/mm).  The dome is evaluated again and again at the same points
        (every layer's surface, distance function and turnaround search samples the bare mandrel's dome on
        the same grids): answers for the last few inputs are kept (:data:`_EVAL_CACHE`, keyed by the
        dome's parameters and the input's bytes) and handed out as copies, the same numbers."""
        za = np.asarray(z, dtype=float)
        if not _EVAL_CACHE_MIN <= za.size <= _EVAL_CACHE_MAX:
            return self._eval(za)
        key = (self.zc, self.R, self.rho_p, self.direction, za.shape, za.tobytes())
        with _EVAL_LOCK:
            hit = _EVAL_CACHE.get(key)
            if hit is not None:
                _EVAL_CACHE.move_to_end(key)
        if hit is None:
            hit = self._eval(za)
            with _EVAL_LOCK:
                _EVAL_CACHE[key] = hit
                while len(_EVAL_CACHE) > _EVAL_CACHE_SIZE:
                    _EVAL_CACHE.popitem(last=False)
        return hit[0].copy(), hit[1].copy(), hit[2].copy()

    def _eval(self, z: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        zeta_c, dzeta_c, _ = self._series(self.rho_p)
        t = self._t_of_z(np.asarray(z, dtype=float))
        h = 0.5 * (1.0 - self.rho_p)
        rho = 1.0 - h * (1.0 - np.cos(t))
        drho = -h * np.sin(t)
        d2rho = -h * np.cos(t)
        zt = _chebval(_to_cheb(t), dzeta_c)
        ztt = _chebval(_to_cheb(t), C.chebder(dzeta_c)) * (2.0 / math.pi)
        slope = drho / zt  # dρ/dζ
        curv = (d2rho * zt - drho * ztt) / zt**3  # d²ρ/dζ²
        d = self.direction
        return self.R * rho, d * slope, curv / self.R

    def param_nodes(self) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        _, dzeta_c, _ = self._series(self.rho_p)
        t, w = _gauss(0.0, math.pi)
        h = 0.5 * (1.0 - self.rho_p)
        r = self.R * (1.0 - h * (1.0 - np.cos(t)))
        dz = self.R * C.chebval(_to_cheb(t), dzeta_c)
        dr = self.R * h * np.sin(t)
        return r, dz, np.hypot(dz, dr), w

    def spec(self) -> dict[str, Any]:
        return {**super().spec(), "R": self.R, "pole_radius": self.R * self.rho_p}


def _to_cheb(t: FloatArray) -> FloatArray:
    return np.asarray(t) * (2.0 / math.pi) - 1.0


_SMALL_CHEBVAL = 24
"""Arrays up to this size are summed with Python floats in :func:`_chebval` (numpy's per-coefficient
array operations cost ~1 µs each whatever the size: a few points of an 81-term series took ~0.3 ms)."""


def _chebval(x: FloatArray, c: FloatArray) -> FloatArray:
    """``numpy.polynomial.chebyshev.chebval(x, c)`` for a 1-D series, bit for bit (the same Clenshaw
    recurrence in the same order; IEEE double arithmetic is the same in Python floats, numpy and compiled
    code): small arrays in Python floats, larger ones by :func:`engine.mandrel_jit.chebval` where it runs."""
    x = np.asarray(x, dtype=float)
    if len(c) >= 3:
        from engine.mandrel_jit import chebval

        got = chebval(x, np.asarray(c))  # compiled (ahead of time), the same recurrence: the same bits
        if got is not None:
            return got
    if x.size > _SMALL_CHEBVAL or len(c) < 3:
        return C.chebval(x, c)
    cs = [float(v) for v in c]
    out = np.empty(x.shape)
    flat = out.reshape(-1)
    for k, xv in enumerate(x.reshape(-1).tolist()):
        x2 = 2 * xv
        c0, c1 = cs[-2], cs[-1]
        for i in range(3, len(cs) + 1):
            tmp = c0
            c0 = cs[-i] - c1
            c1 = tmp + c1 * x2
        flat[k] = c0 + c1 * xv
    return out


_ZETA_TABLES: dict[float, tuple[FloatArray, FloatArray]] = {}

_EVAL_CACHE: OrderedDict[tuple[Any, ...], tuple[FloatArray, FloatArray, FloatArray]] = OrderedDict()
"""The isotensoid dome's last answers (:meth:`IsotensoidSegment.eval`), least recently used first."""
_EVAL_CACHE_SIZE = 64
_EVAL_CACHE_MIN, _EVAL_CACHE_MAX = 1, 65_536
"""Inputs with fewer or more points are evaluated afresh (a big program's whole line is not kept)."""
_EVAL_LOCK = threading.Lock()


def _zeta_table(rho_p: float) -> tuple[FloatArray, FloatArray]:
    """t on 513 points of [0, π] and ζ(t) there: the start of the Newton inversion of ζ(t) (cached)."""
    tab = _ZETA_TABLES.get(rho_p)
    if tab is None:
        t_tab = np.linspace(0.0, math.pi, 513)
        tab = (t_tab, C.chebval(_to_cheb(t_tab), _isotensoid_series(rho_p)[0]))
        _ZETA_TABLES[rho_p] = tab
    return tab


_ISO_CACHE: dict[float, tuple[Any, Any, float]] = {}


def _isotensoid_series(rho_p: float) -> tuple[Any, Any, float]:
    """Chebyshev series (in x = 2t/π − 1) of ζ(t) and dζ/dt, and the dome length ζ(π)."""
    if rho_p in _ISO_CACHE:
        return _ISO_CACHE[rho_p]
    rp2 = rho_p * rho_p
    rho0_sq = (rp2 - rp2**3) / (1.0 - rp2**3)
    # D(ρ) = −(1 − ρ0²)ρ⁶ + ρ² − ρ0² = (ρ − 1)(ρ − ρ_p)·q(ρ)
    D = np.zeros(7)
    D[6], D[2], D[0] = -(1.0 - rho0_sq), 1.0, -rho0_sq  # increasing powers
    q, rem = np.polynomial.polynomial.polydiv(D, np.polynomial.polynomial.polyfromroots([1.0, rho_p]))
    h = 0.5 * (1.0 - rho_p)
    deg = 80
    x = np.cos(np.pi * (np.arange(deg + 1) + 0.5) / (deg + 1))  # Chebyshev nodes in [-1, 1]
    t = (x + 1.0) * (math.pi / 2.0)
    rho = 1.0 - h * (1.0 - np.cos(t))
    qv = np.polynomial.polynomial.polyval(rho, q)
    # dζ/dt = ρ³·sqrt(1−ρ0²)/sqrt(−q(ρ))  (the sqrt((1−ρ)(ρ−ρ_p)) factor cancels with dρ/dt)
    dzdt = rho**3 * math.sqrt(1.0 - rho0_sq) / np.sqrt(-qv)
    dz_c = C.chebfit(x, dzdt, deg)
    z_c = C.chebint(dz_c, lbnd=-1.0) * (math.pi / 2.0)
    length = float(C.chebval(1.0, z_c))
    out = (z_c, dz_c, length)
    _ISO_CACHE[rho_p] = out
    return out


# ------------------------------------------------------------------------------------------------
# Mandrel
# ------------------------------------------------------------------------------------------------
MIN_SKETCH_POINTS = 4
"""Fewest points of a sketched/imported generatrix (a C2 cubic spline needs 4)."""

CONCAVE_GAP_TOL_MM = 0.02
"""Default bridging-gap tolerance of :meth:`Mandrel.concave_zones` (mm).

A concave zone counts only if a straight fibre spanning it would stand off the surface by more than
this.  0.02 mm is below the surface tolerance of a turned mandrel (about ±0.05 mm) and a tenth of one
band thickness (0.2-0.3 mm), and above the wiggle of a C2 spline through sampled points on a straight
cylinder (measured up to 0.016 mm, r'' up to 2e-4 1/mm) and its overshoot at a cylinder-dome joint of
an imported profile (up to 0.001 mm, r'' up to 7e-3 1/mm within 2 mm of the joint).
"""

_D2_FLOOR = 1e-12
"""r'' (1/mm) at or below which a sample does not start a concave run (floating-point noise)."""

_MERGE_GAP_FRACTION = 0.25
"""Two concave runs merge only across a gap at most this fraction of the shorter of them."""


@dataclass(frozen=True)
class Zone:
    """A z interval (mm), e.g. a concave zone.

    ``gap_mm`` is, for a concave zone, the largest distance (mm) between the generatrix and the
    straight chord from (z_from, r(z_from)) to (z_to, r(z_to)): the gap a fibre laid along the
    meridian would bridge there (a fibre at a winding angle bridges less).  0 when not computed.
    """

    z_from: float
    z_to: float
    gap_mm: float = field(default=0.0, compare=False)


@dataclass(frozen=True)
class Mandrel:
    """Generatrix r(z) of the mandrel over the winding zone; see the module docstring."""

    segments: tuple[Segment, ...]
    name: str = "mandrel"
    source: str = ""
    meta: dict[str, Any] = field(default_factory=dict, compare=False)

    def __post_init__(self) -> None:
        if not self.segments:
            raise InputError("the generatrix has no segments")
        for a, b in zip(self.segments[:-1], self.segments[1:]):
            if abs(a.z1 - b.z0) > 1e-9 * max(1.0, abs(a.z1)):
                raise InputError(f"segments do not join: {a.z1} != {b.z0} mm")
        for s in self.segments:
            if not s.z1 > s.z0:
                raise InputError(f"segment {s.kind} has zero or negative length: z {s.z0}..{s.z1} mm")
        self._check_radius()

    # -- evaluation ------------------------------------------------------------------------------
    @cached_property
    def _edges(self) -> FloatArray:
        return np.array([s.z0 for s in self.segments] + [self.segments[-1].z1])

    @property
    def z_min(self) -> float:
        """Start of the winding zone (mm)."""
        return float(self._edges[0])

    @property
    def z_max(self) -> float:
        """End of the winding zone (mm)."""
        return float(self._edges[-1])

    @property
    def length(self) -> float:
        """Axial length of the winding zone (mm)."""
        return self.z_max - self.z_min

    def evaluate(self, z: ArrayLike) -> tuple[FloatArray, FloatArray, FloatArray]:
        """r (mm), r' (-), r'' (1/mm) at ``z`` (mm); z is clipped to [z_min, z_max]."""
        zz = np.clip(np.asarray(z, dtype=float), self.z_min, self.z_max)
        shape = zz.shape
        zz = zz.ravel()
        idx = np.clip(np.searchsorted(self._edges, zz, side="right") - 1, 0, len(self.segments) - 1)
        r = np.empty_like(zz)
        dr = np.empty_like(zz)
        d2r = np.empty_like(zz)
        for i, seg in enumerate(self.segments):
            m = idx == i
            if m.any():
                r[m], dr[m], d2r[m] = seg.eval(zz[m])
        return r.reshape(shape), dr.reshape(shape), d2r.reshape(shape)

    def breakpoints(self) -> FloatArray:
        """Interior z (mm) of knots and r'' extrema of every segment (not the joints), increasing."""
        return self._breakpoints.copy()

    @cached_property
    def _breakpoints(self) -> FloatArray:
        return np.unique(np.concatenate([s.breakpoints() for s in self.segments]))

    def r(self, z: ArrayLike) -> FloatArray:
        """Radius r(z) in mm."""
        return self.evaluate(z)[0]

    def dr(self, z: ArrayLike) -> FloatArray:
        """Slope dr/dz."""
        return self.evaluate(z)[1]

    def d2r(self, z: ArrayLike) -> FloatArray:
        """Second derivative d²r/dz² in 1/mm."""
        return self.evaluate(z)[2]

    def sample(self, n: int = 400) -> tuple[FloatArray, FloatArray]:
        """``n`` points (z, r) spread over every segment (joints included), for plots and export."""
        zs = []
        total = self.length
        for s in self.segments:
            k = max(8, int(math.ceil(n * (s.z1 - s.z0) / total)))
            zs.append(np.linspace(s.z0, s.z1, k, endpoint=False))
        z = np.concatenate([*zs, [self.z_max]])
        return z, self.r(z)

    # -- properties ------------------------------------------------------------------------------
    @property
    def pole_radii(self) -> tuple[float, float]:
        """Polar-opening radii (r at z_min, r at z_max) in mm."""
        r = np.maximum(self.r(np.array([self.z_min, self.z_max])), 0.0)  # closed poles: no -0 roundoff
        return float(r[0]), float(r[1])

    @cached_property
    def r_min(self) -> float:
        """Smallest radius in the winding zone (mm)."""
        z, r = self.sample(4000)
        return float(r.min())

    @cached_property
    def r_max(self) -> float:
        """Largest radius in the winding zone (mm)."""
        z, r = self.sample(4000)
        return float(r.max())

    @cached_property
    def area_mm2(self) -> float:
        """Lateral surface area ∫ 2π r ds (mm²)."""
        total = 0.0
        for s in self.segments:
            r, _, ds, w = s.param_nodes()
            total += float(np.sum(2.0 * math.pi * r * ds * w))
        return total

    @cached_property
    def volume_mm3(self) -> float:
        """Volume enclosed by the surface between the end planes, ∫ π r² dz (mm³)."""
        total = 0.0
        for s in self.segments:
            r, dz, _, w = s.param_nodes()
            total += float(np.sum(math.pi * r * r * dz * w))
        return total

    def concave_zones(self, *, tol_mm: float = CONCAVE_GAP_TOL_MM, n: int = 4000) -> list[Zone]:
        """Concave zones: z intervals where r'' > 0 (concave seen from outside) that a fibre would bridge.

        A fibre laid over a concave zone stands off the surface; the zone matters for the winding
        (non-geodesic / minimax lines, pressure on the band) only if that gap is real.  Zones are found
        in three steps:

        1. maximal runs where r'' > 0, on a grid of about ``n`` samples that contains every segment
           joint (r'' may jump there);
        2. neighbouring runs are merged across a short gap (at most a quarter of the shorter run)
           whose convex bump stays within ``tol_mm`` of its chord: the waist of a bottle where r''
           touches 0, a real zone cut by the noise of measured points.  Longer gaps are not bridged
           (a spline wiggling along a cylinder alternates concave and convex runs of equal length);
        3. a merged zone is kept only if the generatrix lies more than ``tol_mm`` below the chord
           joining its ends (:attr:`Zone.gap_mm`, the bridging gap of a meridional fibre, an upper
           bound for a fibre at any winding angle).

        This drops what a C2 spline through sampled points adds by itself: round-off wiggle along a
        straight cylinder and the overshoot next to a jump of r'' (cylinder-dome joint), while real
        concave zones stay: a waisted neck, the inflection of an isotensoid dome near its pole
        (ρ = sqrt(3/2)·ρ0, ρ0 the Clairaut constant / R), a deliberately concave sketch.
        Zone ends are refined to the zero of r'' (to 1e-8 mm or better) or a segment joint.

        Parameters
        ----------
        tol_mm:
            Bridging-gap tolerance (mm), >= 0; default :data:`CONCAVE_GAP_TOL_MM`.  0 keeps every
            run with r'' > 0 (merged only across short straight stretches).
        n:
            Number of samples of r'' over the winding zone (>= 16).

        Returns
        -------
        list of Zone
            Increasing, disjoint zones, with ``gap_mm`` set (mm).
        """
        if not (isinstance(tol_mm, numbers.Real) and not isinstance(tol_mm, bool) and math.isfinite(tol_mm)
                and tol_mm >= 0):
            raise InputError(f"the concave-zone gap tolerance must be a number of mm >= 0, got {tol_mm!r}",
                             field="tol_mm")
        if isinstance(n, bool) or not isinstance(n, numbers.Integral) or n < 16:
            raise InputError(f"the concave-zone sample count must be an integer >= 16, got {n!r}", field="n")
        z = self._zone_grid(int(n))
        d2 = self.evaluate(z)[2]
        pos = np.where(np.isfinite(d2), d2, 0.0) > _D2_FLOOR
        if not pos.any():
            return []
        edges = np.flatnonzero(np.diff(np.concatenate([[0], pos.astype(np.int8), [0]])))
        first, last = edges[0::2], edges[1::2] - 1  # sample indices of each run
        # run ends halfway to the neighbouring sample outside (refined below for the kept zones)
        lo = np.where(first > 0, 0.5 * (z[np.maximum(first - 1, 0)] + z[first]), z[first])
        hi = np.where(last < len(z) - 1, 0.5 * (z[last] + z[np.minimum(last + 1, len(z) - 1)]), z[last])
        # 2. merge neighbours across a short convex stretch that stays within tol of its chord
        _, bump = self._chord_deviation(hi[:-1], lo[1:])
        groups: list[list[int]] = [[0]]
        for i in range(1, len(first)):
            shorter = min(hi[groups[-1][-1]] - lo[groups[-1][0]], hi[i] - lo[i])
            short = lo[i] - hi[i - 1] <= _MERGE_GAP_FRACTION * shorter
            if short and bump[i - 1] <= tol_mm:
                groups[-1].append(i)
            else:
                groups.append([i])
        # 3. refine the ends, keep the zones that a fibre would bridge by more than tol
        ends = self._refine_ends(z, np.array([first[g[0]] for g in groups] + [last[g[-1]] for g in groups]),
                                 np.repeat([-1, 1], len(groups)))
        a, b = ends[: len(groups)], ends[len(groups):]
        gap, _ = self._chord_deviation(a, b)
        return [Zone(float(za), float(zb), float(g)) for za, zb, g in zip(a, b, gap) if g > tol_mm and zb > za]

    def _zone_grid(self, n: int) -> FloatArray:
        """About ``n`` increasing z samples (mm) over the winding zone, every segment joint included."""
        zs = []
        for s in self.segments:
            k = max(8, int(math.ceil(n * (s.z1 - s.z0) / self.length)))
            zs.append(np.linspace(s.z0, s.z1, k, endpoint=False))
        return np.concatenate([*zs, [self.z_max]])

    def _refine_ends(self, z: FloatArray, inside: NDArray[np.intp], side: NDArray[np.intp], rounds: int = 3,
                     k: int = 256) -> FloatArray:
        """Ends (mm) of runs of r'' > 0 whose outermost samples are ``z[inside]``, towards ``side`` (±1 each).

        The zero of r'' between each such sample and its neighbour outside the run (a jump of r'' at
        a segment joint gives the joint), or the end of the winding zone.  All ends at once: each
        round splits every bracket into ``k`` parts and keeps the one where r'' leaves the run, then
        a linear interpolation; 0.1 mm brackets shrink to 1e-8 mm in 3 rounds (then interpolated).
        """
        inside = np.asarray(inside, dtype=np.intp)
        outside = inside + side
        at_end = (outside < 0) | (outside >= len(z))
        x_in = z[inside].astype(float)
        x_out = z[np.clip(outside, 0, len(z) - 1)].astype(float)
        x_out[at_end] = x_in[at_end]
        f_in = np.ones_like(x_in)
        f_out = -np.ones_like(x_in)
        t = np.linspace(0.0, 1.0, k + 1)
        cols = np.arange(x_in.size)
        for _ in range(rounds):
            xx = x_in[:, None] + (x_out - x_in)[:, None] * t[None, :]
            f = self.evaluate(xx)[2] - _D2_FLOOR
            f = np.where(np.isfinite(f), f, -1.0)
            f[:, -1] = np.minimum(f[:, -1], 0.0)  # outside by construction (guards round-off)
            j = np.maximum(np.argmax(f <= 0, axis=1), 1)  # the first sample that left the run
            x_in, x_out = xx[cols, j - 1], xx[cols, j]
            f_in, f_out = f[cols, j - 1], f[cols, j]
        w = np.divide(f_in, f_in - f_out, out=np.full_like(f_in, 0.5), where=f_in - f_out > 0)
        return np.where(at_end, z[inside], x_in + np.clip(w, 0.0, 1.0) * (x_out - x_in))

    def _chord_deviation(self, a: ArrayLike, b: ArrayLike, k: int = 257) -> tuple[FloatArray, FloatArray]:
        """How far the generatrix strays from its chord on each interval [a_i, b_i] (mm).

        The chord joins (a, r(a)) and (b, r(b)).  Returns the largest distance below it and the
        largest distance above it (both >= 0, mm, normal to the chord, from ``k`` samples).
        """
        a = np.atleast_1d(np.asarray(a, dtype=float))
        b = np.atleast_1d(np.asarray(b, dtype=float))
        t = np.linspace(0.0, 1.0, k)
        zz = a[:, None] + (b - a)[:, None] * t[None, :]
        rr = self.r(zz)
        slope = np.divide(rr[:, -1] - rr[:, 0], b - a, out=np.zeros_like(a), where=b > a)
        below = (rr[:, :1] + (rr[:, -1:] - rr[:, :1]) * t[None, :] - rr) / np.sqrt(1.0 + slope * slope)[:, None]
        below = np.where(np.isfinite(below), below, 0.0)
        return np.maximum(below.max(axis=1), 0.0), np.maximum(-below.min(axis=1), 0.0)

    def summary(self) -> dict[str, Any]:
        """The mandrel summary printed by ``winder mandrel --json``."""
        return {
            "name": self.name,
            "source": self.source,
            "z_min": self.z_min,
            "z_max": self.z_max,
            "length_mm": self.length,
            "r_min": self.r_min,
            "r_max": self.r_max,
            "pole_radii": list(self.pole_radii),
            "area_mm2": self.area_mm2,
            "volume_mm3": self.volume_mm3,
            "concave_zones": [[zn.z_from, zn.z_to] for zn in self.concave_zones()],
            "segments": [s.spec() for s in self.segments],
        }

    def _check_radius(self) -> None:
        z = np.linspace(self.z_min, self.z_max, 2001)
        r, dr, d2r = self.evaluate(z)
        bad = ~np.isfinite(r)
        if bad.any():
            raise InputError(f"the generatrix is not finite at z = {z[bad][0]:.6g} mm")
        inside = r[1:-1]
        if (inside <= 0).any():
            zi = z[1:-1][inside <= 0][0]
            raise InputError(
                f"the generatrix meets the axis inside the winding zone at z = {zi:.6g} mm "
                f"(r = {r[1:-1][inside <= 0][0]:.6g} mm); radii must be > 0 between the poles"
            )
        neg_tol = 1e-12 * max(1.0, float(np.abs(r).max()))  # a spline closed at a pole evaluates to ±roundoff there
        if r[0] < -neg_tol or r[-1] < -neg_tol:
            raise InputError(f"negative pole radius: r(z_min) = {r[0]:.6g}, r(z_max) = {r[-1]:.6g} mm")

    # -- constructors ----------------------------------------------------------------------------
    @classmethod
    def pipe(cls, radius: float, length: float, name: str = "pipe") -> Mandrel:
        """Plain cylinder (mm); the poles are the full radius (winding turns on end pins)."""
        _positive(radius=radius, length=length)
        return cls((LineSegment(0.0, length, radius, radius),), name=name, source="pipe")

    @classmethod
    def cone(cls, r0: float, r1: float, length: float, name: str = "cone") -> Mandrel:
        """Frustum from radius ``r0`` at z = 0 to ``r1`` at z = ``length`` (mm)."""
        _positive(r0=r0, r1=r1, length=length)
        return cls((LineSegment(0.0, length, r0, r1),), name=name, source="cone")

    @classmethod
    def vessel(
        cls,
        radius: float,
        cylinder_length: float,
        dome: str = "hemisphere",
        pole_radii: tuple[float, float] | float = (0.0, 0.0),
        dome_ratio: float | tuple[float, float] = 1.0,
        name: str = "vessel",
    ) -> Mandrel:
        """Cylinder of ``radius`` and ``cylinder_length`` (mm) closed by two domes.

        Parameters
        ----------
        dome:
            ``"hemisphere"``, ``"ellipse"`` (axial/radial semi-axis ratio ``dome_ratio``, any
            positive value) or ``"isotensoid"``; a pair gives the left and right dome.
        pole_radii:
            Polar-opening radii (mm) at the left and right end; 0 closes a hemispherical or
            elliptical dome (not possible for an isotensoid).
        """
        kinds = (dome, dome) if isinstance(dome, str) else tuple(dome)
        poles = (pole_radii, pole_radii) if np.isscalar(pole_radii) else tuple(pole_radii)  # type: ignore[arg-type]
        ratios = (dome_ratio, dome_ratio) if np.isscalar(dome_ratio) else tuple(dome_ratio)  # type: ignore[arg-type]
        _positive(radius=radius)
        if cylinder_length < 0:
            raise InputError(f"cylinder length must be >= 0, got {cylinder_length} mm", field="cylinder_length")
        for side, rp in zip(("left", "right"), poles):
            if not 0.0 <= float(rp) < radius:
                raise InputError(
                    f"{side} pole opening radius must be in [0, {radius}) mm (the cylinder radius), got {rp}",
                    field="pole_radius_mm",
                )
        left = _dome(kinds[0], radius, float(poles[0]), float(ratios[0]), zc=0.0, direction=-1)
        right = _dome(kinds[1], radius, float(poles[1]), float(ratios[1]), zc=cylinder_length, direction=+1)
        segs: list[Segment] = [left]
        if cylinder_length > 0:
            segs.append(LineSegment(0.0, cylinder_length, radius, radius))
        segs.append(right)
        return cls(tuple(segs), name=name, source=f"vessel:{kinds[0]}/{kinds[1]}")

    @classmethod
    def from_points(
        cls, z: ArrayLike, r: ArrayLike, name: str = "spline", source: str = "points", file: str | None = None
    ) -> Mandrel:
        """C2 cubic spline through points (z strictly increasing, r > 0 inside), mm."""
        zz = np.asarray(z, dtype=float)
        rr = np.asarray(r, dtype=float)
        validate_points(zz, rr, file=file)
        seg = SplineSegment(float(zz[0]), float(zz[-1]), tuple(map(float, zz)), tuple(map(float, rr)))
        return cls((seg,), name=name, source=source)

    @classmethod
    def bottle(
        cls,
        radius: float = 60.0,
        body_length: float = 160.0,
        shoulder_length: float = 40.0,
        waist_radius: float = 18.0,
        neck_length: float = 40.0,
        neck_radius: float = 24.0,
        bottom_pole_radius: float = 15.0,
        name: str = "bottle",
    ) -> Mandrel:
        """A bottle: elliptical bottom, cylindrical body, shoulder, a waisted (concave) neck.

        Shoulder (radius -> waist) and neck (waist -> neck radius) are quintic smooth steps, C2
        with the body and with each other, so the waist region is concave (r'' > 0).  mm.
        """
        _positive(radius=radius, body_length=body_length, shoulder_length=shoulder_length,
                  waist_radius=waist_radius, neck_length=neck_length, neck_radius=neck_radius,
                  bottom_pole_radius=bottom_pole_radius)
        if not waist_radius < neck_radius < radius:
            raise InputError(
                f"a bottle needs waist_radius < neck_radius < radius, got {waist_radius}, {neck_radius}, {radius}",
                field="waist_radius")
        if not bottom_pole_radius < radius:
            raise InputError(f"bottom pole radius {bottom_pole_radius} mm must be below the radius {radius} mm",
                             field="bottom_pole_radius")
        bottom = _dome("ellipse", radius, bottom_pole_radius, 0.5, zc=0.0, direction=-1)
        z1 = body_length
        z2 = z1 + shoulder_length
        z3 = z2 + neck_length
        segs = (
            bottom,
            LineSegment(0.0, z1, radius, radius),
            SmoothStepSegment(z1, z2, r0=radius, r1=waist_radius),
            SmoothStepSegment(z2, z3, r0=waist_radius, r1=neck_radius),
        )
        return cls(segs, name=name, source="bottle")


def cylinder_range(mandrel: Mandrel, rel_tol: float = 1e-3) -> tuple[float, float]:
    """z range (mm) of the cylindrical part: the longest run with r >= (1 − rel_tol)·r_max and |r'| <= rel_tol.

    The whole winding zone when there is no such run (a cone, a sketch without a straight part).
    """
    z = np.linspace(mandrel.z_min, mandrel.z_max, 4001)
    r, dr, _ = mandrel.evaluate(z)
    ok = (r >= (1.0 - rel_tol) * float(r.max())) & (np.abs(dr) <= rel_tol)
    if not ok.any():
        return mandrel.z_min, mandrel.z_max
    edges = np.flatnonzero(np.diff(np.concatenate([[0], ok.view(np.int8), [0]])))
    runs = edges.reshape(-1, 2)
    a, b = runs[int(np.argmax(runs[:, 1] - runs[:, 0]))]
    za, zb = float(z[a]), float(z[b - 1])
    # snap to the segment joints inside one grid step (exact cylinder ends on analytic mandrels)
    step = float(z[1] - z[0])
    for s in mandrel.segments:
        for zj in (s.z0, s.z1):
            if abs(zj - za) <= step:
                za = zj
            if abs(zj - zb) <= step:
                zb = zj
    if zb - za <= step:
        return mandrel.z_min, mandrel.z_max
    return za, zb


def _positive(**values: float) -> None:
    for k, v in values.items():
        if not (isinstance(v, int | float) and math.isfinite(v) and v > 0):
            raise InputError(f"{k} must be a positive number of mm, got {v!r}", field=k)


def _dome(kind: str, R: float, rp: float, ratio: float, zc: float, direction: int) -> Segment:
    if kind == "hemisphere":
        h = math.sqrt(R * R - rp * rp)
        z_end = zc + direction * h
        z0, z1 = sorted((zc, z_end))
        return ArcSegment(z0, z1, zc=zc, rc=0.0, a=R)
    if kind == "ellipse":
        if not (math.isfinite(ratio) and ratio > 0):
            raise InputError(f"elliptical dome axis ratio must be > 0, got {ratio}", field="dome_ratio")
        a = ratio * R
        h = a * math.sqrt(1.0 - (rp / R) ** 2)
        z0, z1 = sorted((zc, zc + direction * h))
        return EllipseSegment(z0, z1, zc=zc, a=a, b=R)
    if kind == "isotensoid":
        if not 0.02 <= rp / R <= 0.9:
            raise InputError(
                f"isotensoid dome needs a pole opening between 2 % and 90 % of the radius, got {rp} mm",
                field="pole_radius_mm",
            )
        h = IsotensoidSegment.dome_length(R, rp)
        z0, z1 = sorted((zc, zc + direction * h))
        return IsotensoidSegment(z0, z1, zc=zc, R=R, rho_p=rp / R, direction=direction)
    raise InputError(f"unknown dome '{kind}'; use hemisphere, ellipse or isotensoid", field="dome")


def validate_points(z: FloatArray, r: FloatArray, file: str | None = None, lines: Sequence[int] | None = None) -> None:
    """Check generatrix points: finite, z strictly increasing, r >= 0 at the ends and > 0 inside.

    ``lines`` maps point index to a source line number for the message.
    """

    def where(i: int) -> int | None:
        return None if lines is None else int(lines[i])

    if z.ndim != 1 or z.shape != r.shape:
        raise InputError("z and r must be 1-D arrays of equal length", file=file)
    if len(z) < MIN_SKETCH_POINTS:
        raise InputError(f"need at least {MIN_SKETCH_POINTS} points for a C2 generatrix, got {len(z)}", file=file)
    for name, arr in (("z", z), ("r", r)):
        bad = np.flatnonzero(~np.isfinite(arr))
        if bad.size:
            i = int(bad[0])
            raise InputError(f"{name} is not a finite number ({arr[i]!r}) at point {i + 1}", file=file,
                             line=where(i), field=name)
    dz = np.diff(z)
    bad = np.flatnonzero(dz <= 0)
    if bad.size:
        i = int(bad[0]) + 1
        raise InputError(f"z must increase strictly: z = {z[i]:g} mm after {z[i - 1]:g} mm (point {i + 1})",
                         file=file, line=where(i), field="z")
    bad = np.flatnonzero(r < 0)
    if bad.size:
        i = int(bad[0])
        raise InputError(f"negative radius r = {r[i]:g} mm at point {i + 1}", file=file, line=where(i), field="r")
    inner = np.flatnonzero(r[1:-1] <= 0)
    if inner.size:
        i = int(inner[0]) + 1
        raise InputError(
            f"the generatrix meets the axis inside the winding zone: r = {r[i]:g} mm at z = {z[i]:g} mm "
            f"(point {i + 1}); only the end points may have r = 0",
            file=file, line=where(i), field="r")
