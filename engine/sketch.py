"""A generatrix sketched from exact segments (MATH.md §A1, issue 17).

A sketch starts at a point (z, r) and chains segments, each starting where the previous one
ended:

* ``line``       -- to ``to_mm`` (z, r).
* ``arc``        -- to ``to_mm``, around ``center_mm`` (zc, rc), or with a signed ``radius_mm``
  (> 0 convex: centre below the arc; < 0 concave: centre above it), or, with neither, the arc
  *tangent* to its neighbour (to the previous segment; the first segment of a sketch is tangent
  to the next one, which must then be a line).
* ``ellipse``    -- to ``to_mm`` around ``center_mm`` with ``semi_axes_mm`` (axial a, radial b);
  the upper (convex) half.
* ``isotensoid`` -- a geodesic-isotensoid dome (netting theory): ``pole_radius_mm`` runs *down*
  from the current point (the equator, r = R) to that pole; ``radius_mm`` R runs *up* from the
  current point (the pole) to the equator of radius R.  The end point follows from the shape.
* ``spline``     -- a C2 cubic spline through ``points_mm`` [[z, r], ...] (after the current point);
  its ends are clamped to the neighbours' slopes where they are tangent joints (the previous
  segment; the next one if it is a line), else not-a-knot.
* ``smoothstep`` -- to ``to_mm`` by the quintic step (r' = r'' = 0 at both ends).

Joints are G1 (tangent) by default: the builder checks that the slopes agree to
:data:`TANGENCY_TOL_RAD`.  A joint may be a corner only where the user marks it (``corner = true``
on the segment that starts there) and then it must be rounded by ``fillet_mm`` (a tangent circle
arc of that radius; both neighbours must be lines or arcs).  Every error names the segment
(``segments[i].field``, 0-based, and "segment i+1" in words).

:func:`sketch_from_mandrel` converts any :class:`~engine.mandrel.Mandrel` (templates, imports) to
the sketch of its exact segments; building that sketch gives back the same generatrix.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from engine.errors import InputError
from engine.mandrel import (
    ArcSegment,
    EllipseSegment,
    IsotensoidSegment,
    LineSegment,
    Mandrel,
    Segment,
    SmoothStepSegment,
    SplineSegment,
)

TANGENCY_TOL_RAD = 1e-6
"""Largest angle (rad) between the tangents of two segments at a joint that counts as tangent (G1)."""

ON_CURVE_TOL = 1e-6
"""Relative tolerance (of the segment's size) for a given point lying on an arc or ellipse."""

SEGMENT_TYPES = ("line", "arc", "ellipse", "isotensoid", "spline", "smoothstep")

_FIELDS = {
    "line": {"to_mm"},
    "arc": {"to_mm", "center_mm", "radius_mm"},
    "ellipse": {"to_mm", "center_mm", "semi_axes_mm"},
    "isotensoid": {"pole_radius_mm", "radius_mm"},
    "spline": {"points_mm"},
    "smoothstep": {"to_mm"},
}
_COMMON = {"type", "corner", "fillet_mm"}


def _err(i: int, item: Mapping[str, Any], fld: str, msg: str) -> InputError:
    return InputError(f"segment {i + 1} ({item.get('type', '?')}): {msg}", field=f"segments[{i}].{fld}")


def _pt(i: int, item: Mapping[str, Any], fld: str) -> tuple[float, float]:
    v = item.get(fld)
    if v is None:
        raise _err(i, item, fld, f"{fld} = [z, r] is required")
    try:
        z, r = (float(x) for x in v)
    except (TypeError, ValueError):
        raise _err(i, item, fld, f"{fld} must be two numbers [z, r] (mm), got {v!r}") from None
    if not (math.isfinite(z) and math.isfinite(r)):
        raise _err(i, item, fld, f"{fld} must be finite, got {v!r}")
    return z, r


def _slope_at(seg: Segment, z: float) -> float:
    return float(seg.eval(np.array([z], dtype=float))[1][0])


def _r_at(seg: Segment, z: float) -> float:
    return float(seg.eval(np.array([z], dtype=float))[0][0])


def _tangent_arc(p0: tuple[float, float], slope: float, p1: tuple[float, float], backwards: bool = False
                 ) -> tuple[float, float, float, int] | None:
    """Circle through p0 and p1 tangent at p0 to the direction (1, slope): (zc, rc, a, side)."""
    d = np.array([1.0, slope]) / math.hypot(1.0, slope)
    if backwards:
        d = -d
    n = np.array([-d[1], d[0]])
    chord = np.array([p1[0] - p0[0], p1[1] - p0[1]])
    den = 2.0 * float(chord @ n)
    if abs(den) <= 1e-12 * float(chord @ chord):
        return None
    rho = float(chord @ chord) / den
    c = np.array(p0) + rho * n
    side = 1 if c[1] < 0.5 * (p0[1] + p1[1]) else -1
    return float(c[0]), float(c[1]), abs(rho), side


def _arc_from_circle(i: int, item: Mapping[str, Any], p0: tuple[float, float], z1: float, zc: float, rc: float,
                     a: float, side: int, r1_given: float | None) -> ArcSegment:
    if not a > 0:
        raise _err(i, item, "center_mm", "the arc has zero radius")
    tol = ON_CURVE_TOL * max(1.0, a)
    for z in (p0[0], z1):
        if abs(z - zc) > a + tol:
            raise _err(i, item, "to_mm", f"z = {z:.6g} mm is not on the circle of radius {a:.6g} mm around "
                       f"({zc:.6g}, {rc:.6g})")
    q0 = math.sqrt(max(a * a - (p0[0] - zc) ** 2, 0.0))
    if abs(rc + side * q0 - p0[1]) > tol:
        raise _err(i, item, "center_mm", f"the arc around ({zc:.6g}, {rc:.6g}) mm with radius {a:.6g} mm does not "
                   f"pass through its start point ({p0[0]:.6g}, {p0[1]:.6g}) mm on the "
                   f"{'upper' if side > 0 else 'lower'} half "
                   "(an arc past a vertical tangent turns back along the axis: split it there)")
    seg = ArcSegment(p0[0], z1, zc=zc, rc=rc, a=a, side=side)
    if r1_given is not None and abs(_r_at(seg, z1) - r1_given) > tol:
        raise _err(i, item, "to_mm", f"the end point ({z1:.6g}, {r1_given:.6g}) mm is not on the arc (which passes "
                   f"r = {_r_at(seg, z1):.9g} mm there; centre ({zc:.6g}, {rc:.6g}) mm, radius {a:.6g} mm, "
                   f"{'upper (convex)' if side > 0 else 'lower (concave)'} half)")
    return seg


def _build_one(i: int, item: Mapping[str, Any], p0: tuple[float, float], prev: Segment | None,
               items: Sequence[Mapping[str, Any]]) -> Segment:
    kind = item.get("type")
    tangent_prev = prev is not None and not item.get("corner", False)
    if kind in ("line", "smoothstep", "arc", "ellipse"):
        z1, r1 = _pt(i, item, "to_mm")
        if not z1 > p0[0]:
            raise _err(i, item, "to_mm", f"z must increase along the generatrix: to z = {z1:.6g} mm after "
                       f"z = {p0[0]:.6g} mm")
        if kind == "line":
            return LineSegment(p0[0], z1, p0[1], r1)
        if kind == "smoothstep":
            return SmoothStepSegment(p0[0], z1, r0=p0[1], r1=r1)
        if kind == "ellipse":
            zc, rc = _pt(i, item, "center_mm")
            ax = item.get("semi_axes_mm")
            if ax is None:
                raise _err(i, item, "semi_axes_mm", "semi_axes_mm = [a, b] (axial, radial) is required")
            a, b = (float(x) for x in ax)
            if not (a > 0 and b > 0):
                raise _err(i, item, "semi_axes_mm", f"semi-axes must be > 0, got {ax!r}")
            seg = EllipseSegment(p0[0], z1, zc=zc, a=a, b=b, rc=rc)
            tol = ON_CURVE_TOL * max(1.0, a, b)
            for z, r, fld in ((p0[0], p0[1], "center_mm"), (z1, r1, "to_mm")):
                u = (z - zc) / a
                if abs(u) > 1.0 + tol or abs(_r_at(seg, z) - r) > tol:
                    raise _err(i, item, fld, f"the point ({z:.6g}, {r:.6g}) mm is not on the upper half of the ellipse "
                               f"centre ({zc:.6g}, {rc:.6g}) mm, semi-axes ({a:.6g}, {b:.6g}) mm")
            return seg
        # arc
        if item.get("center_mm") is not None:
            zc, rc = _pt(i, item, "center_mm")
            a = math.hypot(p0[0] - zc, p0[1] - rc)
            side = 1 if p0[1] > rc + 1e-12 * max(1.0, a) else (-1 if p0[1] < rc - 1e-12 * max(1.0, a)
                                                                 else (1 if r1 >= rc else -1))
            return _arc_from_circle(i, item, p0, z1, zc, rc, a, side, r1)
        if item.get("radius_mm") is not None:
            rad = float(item["radius_mm"])
            a = abs(rad)
            half = 0.5 * math.hypot(z1 - p0[0], r1 - p0[1])
            if not (math.isfinite(rad) and a >= half * (1.0 - 1e-12)):
                raise _err(i, item, "radius_mm", f"radius {rad:g} mm is smaller than half the chord ({half:.6g} mm)")
            mid = np.array([0.5 * (p0[0] + z1), 0.5 * (p0[1] + r1)])
            u = np.array([z1 - p0[0], r1 - p0[1]]) / (2.0 * half)
            n = np.array([-u[1], u[0]])  # left of the chord: n_r > 0 (z increases)
            off = math.sqrt(max(a * a - half * half, 0.0))
            side = 1 if rad > 0 else -1
            c = mid - side * off * n  # convex: the centre below the chord
            return _arc_from_circle(i, item, p0, z1, float(c[0]), float(c[1]), a, side, r1)
        # tangent arc
        if tangent_prev:
            assert prev is not None
            t = _tangent_arc(p0, _slope_at(prev, prev.z1), (z1, r1))
            if t is None:
                raise _err(i, item, "to_mm", "the tangent arc is straight (the end point lies on the tangent): "
                           "use a line")
            return _arc_from_circle(i, item, p0, z1, *t, r1)
        nxt = items[i + 1] if i + 1 < len(items) else None
        if prev is None and nxt is not None and nxt.get("type") == "line" and not nxt.get("corner", False):
            z2, r2 = _pt(i + 1, nxt, "to_mm")
            if not z2 > z1:
                raise _err(i + 1, nxt, "to_mm", f"z must increase along the generatrix: to z = {z2:.6g} mm after "
                           f"z = {z1:.6g} mm")
            t = _tangent_arc((z1, r1), (r2 - r1) / (z2 - z1), p0, backwards=True)
            if t is None:
                raise _err(i, item, "to_mm", "the tangent arc is straight (the start lies on the next line): "
                           "use a line")
            return _arc_from_circle(i, item, p0, z1, *t, r1)
        raise _err(i, item, "center_mm", "an arc needs center_mm or radius_mm, or a tangent neighbour (a previous "
                   "segment joined without a corner, or, for the first segment, a following line)")
    if kind == "isotensoid":
        pole = item.get("pole_radius_mm")
        R = item.get("radius_mm")
        if (pole is None) == (R is None):
            raise _err(i, item, "pole_radius_mm", "give pole_radius_mm (a dome down from the current point, the "
                       "equator) or radius_mm (a dome up from the current point, the pole to the equator radius R)")
        if pole is not None:
            R_ = p0[1]
            rp = float(pole)
            fld = "pole_radius_mm"
            if not 0.02 * R_ <= rp <= 0.9 * R_:
                raise _err(i, item, fld, f"the pole radius must be between 2 % and 90 % of the equator radius "
                           f"{R_:.6g} mm (the current point), got {rp:g} mm")
            L = IsotensoidSegment.dome_length(R_, rp)
            return IsotensoidSegment(p0[0], p0[0] + L, zc=p0[0], R=R_, rho_p=rp / R_, direction=1)
        R_ = float(R)  # type: ignore[arg-type]
        rp = p0[1]
        fld = "radius_mm"
        if not (R_ > 0 and 0.02 * R_ <= rp <= 0.9 * R_):
            raise _err(i, item, fld, f"the current point (the pole, r = {rp:.6g} mm) must be between 2 % and 90 % of "
                       f"the equator radius, got radius_mm = {R_:g}")
        L = IsotensoidSegment.dome_length(R_, rp)
        return IsotensoidSegment(p0[0], p0[0] + L, zc=p0[0] + L, R=R_, rho_p=rp / R_, direction=-1)
    if kind == "spline":
        pts = item.get("points_mm")
        if not pts:
            raise _err(i, item, "points_mm", "points_mm = [[z, r], ...] is required (at least one point)")
        try:
            arr = np.array([[float(a), float(b)] for a, b in pts])
        except (TypeError, ValueError):
            raise _err(i, item, "points_mm", "points_mm must be a list of [z, r] pairs (mm)") from None
        z = np.concatenate([[p0[0]], arr[:, 0]])
        r = np.concatenate([[p0[1]], arr[:, 1]])
        if not np.isfinite(arr).all():
            raise _err(i, item, "points_mm", "points must be finite")
        bad = np.flatnonzero(np.diff(z) <= 0)
        if bad.size:
            k = int(bad[0])
            raise _err(i, item, "points_mm", f"z must increase: point {k + 1} has z = {z[k + 1]:.6g} mm after "
                       f"z = {z[k]:.6g} mm")
        s0 = _slope_at(prev, prev.z1) if tangent_prev and prev is not None else None
        s1 = None
        nxt = items[i + 1] if i + 1 < len(items) else None
        if nxt is not None and nxt.get("type") == "line" and not nxt.get("corner", False):
            z2, r2 = _pt(i + 1, nxt, "to_mm")
            if z2 > z[-1]:
                s1 = (r2 - r[-1]) / (z2 - z[-1])
        if len(z) < 4 and (s0 is None or s1 is None):
            if len(z) == 2 and s0 is None and s1 is None:
                raise _err(i, item, "points_mm", "a spline through two points is a line: use type = 'line'")
        return SplineSegment(float(z[0]), float(z[-1]), tuple(map(float, z)), tuple(map(float, r)), slopes=(s0, s1))
    raise _err(i, item, "type", f"unknown segment type {kind!r}; use one of {', '.join(SEGMENT_TYPES)}")


# ------------------------------------------------------------------------------------------------
# Fillets
# ------------------------------------------------------------------------------------------------
def _prim(seg: Segment) -> tuple[str, np.ndarray, Any]:
    if isinstance(seg, LineSegment):
        p = np.array([seg.z0, seg.r0])
        d = np.array([seg.z1 - seg.z0, seg.r1 - seg.r0])
        return "line", p, d / np.hypot(*d)
    if isinstance(seg, ArcSegment):
        return "circle", np.array([seg.zc, seg.rc]), float(seg.a)
    raise TypeError


def _offsets(prim: tuple[str, np.ndarray, Any], rho: float) -> list[tuple[str, np.ndarray, Any]]:
    kind, p, x = prim
    if kind == "line":
        n = np.array([-x[1], x[0]])
        return [("line", p + rho * n, x), ("line", p - rho * n, x)]
    out = [("circle", p, x + rho)]
    if x - rho > 0:
        out.append(("circle", p, x - rho))
    return out


def _intersect(a: tuple[str, np.ndarray, Any], b: tuple[str, np.ndarray, Any]) -> list[np.ndarray]:
    if a[0] == "circle" and b[0] == "line":
        a, b = b, a
    if a[0] == "line" and b[0] == "line":
        p, d = a[1], a[2]
        q, e = b[1], b[2]
        den = d[0] * e[1] - d[1] * e[0]
        if abs(den) < 1e-14:
            return []
        t = ((q[0] - p[0]) * e[1] - (q[1] - p[1]) * e[0]) / den
        return [p + t * d]
    if a[0] == "line":
        p, d = a[1], a[2]
        c, R = b[1], b[2]
        f = p - c
        bb = float(f @ d)
        cc = float(f @ f) - R * R
        disc = bb * bb - cc
        if disc < 0:
            return []
        s = math.sqrt(disc)
        return [p + (-bb - s) * d, p + (-bb + s) * d]
    c1, r1 = a[1], a[2]
    c2, r2 = b[1], b[2]
    dvec = c2 - c1
    dist = float(np.hypot(*dvec))
    if dist < 1e-14 or dist > r1 + r2 or dist < abs(r1 - r2):
        return []
    x = (dist * dist + r1 * r1 - r2 * r2) / (2 * dist)
    h = math.sqrt(max(r1 * r1 - x * x, 0.0))
    u = dvec / dist
    n = np.array([-u[1], u[0]])
    return [c1 + x * u + h * n, c1 + x * u - h * n]


def _project(prim: tuple[str, np.ndarray, Any], x: np.ndarray) -> np.ndarray:
    if prim[0] == "line":
        p, d = prim[1], prim[2]
        return p + float((x - p) @ d) * d
    c, R = prim[1], prim[2]
    v = x - c
    return c + R * v / np.hypot(*v)


def _fillet(i: int, item: Mapping[str, Any], A: Segment, B: Segment, rho: float) -> tuple[Segment, Segment, Segment]:
    try:
        pa, pb = _prim(A), _prim(B)
    except TypeError:
        raise _err(i, item, "fillet_mm", f"a fillet joins lines and arcs only (here {A.kind} and {B.kind})") from None
    P = np.array([B.z0, _r_at(B, B.z0)])
    best: tuple[float, Segment, Segment, Segment] | None = None
    tol = 1e-9 * max(1.0, rho)
    for oa in _offsets(pa, rho):
        for ob in _offsets(pb, rho):
            for X in _intersect(oa, ob):
                TA, TB = _project(pa, X), _project(pb, X)
                if not (A.z0 + tol < TA[0] <= A.z1 + tol and B.z0 - tol <= TB[0] < B.z1 - tol and TA[0] < TB[0] - tol):
                    continue
                side = 1 if X[1] < min(TA[1], TB[1]) + tol else (-1 if X[1] > max(TA[1], TB[1]) - tol else 0)
                if side == 0:
                    continue
                za, zb = float(min(TA[0], A.z1)), float(max(TB[0], B.z0))
                arc = ArcSegment(za, zb, zc=float(X[0]), rc=float(X[1]), a=rho, side=side)
                try:
                    ok = (abs(math.atan(_slope_at(arc, za)) - math.atan(_slope_at(A, za))) < 1e-6
                          and abs(math.atan(_slope_at(arc, zb)) - math.atan(_slope_at(B, zb))) < 1e-6)
                except (FloatingPointError, ValueError):
                    ok = False
                if not ok or abs(_r_at(arc, za) - _r_at(A, za)) > 1e-7 * max(1.0, rho):
                    continue
                cost = float(np.hypot(*(TA - P)) + np.hypot(*(TB - P)))
                if best is None or cost < best[0]:
                    best = (cost, _trim(A, A.z0, za), arc, _trim(B, zb, B.z1))
    if best is None:
        raise _err(i, item, "fillet_mm", f"no fillet of radius {rho:g} mm fits the corner at z = {B.z0:.6g} mm "
                   "(too large for the neighbouring segments?)")
    return best[1], best[2], best[3]


def _trim(seg: Segment, z0: float, z1: float) -> Segment:
    if isinstance(seg, LineSegment):
        return LineSegment(z0, z1, _r_at(seg, z0), _r_at(seg, z1))
    assert isinstance(seg, ArcSegment)
    return ArcSegment(z0, z1, zc=seg.zc, rc=seg.rc, a=seg.a, side=seg.side)


# ------------------------------------------------------------------------------------------------
# Build
# ------------------------------------------------------------------------------------------------
def build_sketch(start_mm: Sequence[float], segments: Sequence[Mapping[str, Any]], name: str = "sketch") -> Mandrel:
    """The mandrel of a sketch (see the module docstring); errors name ``segments[i].field``.

    Parameters
    ----------
    start_mm:
        (z, r) of the first point, mm.
    segments:
        Mappings with ``type`` and the fields of that type (``to_mm``, ``center_mm``, ``radius_mm``,
        ``semi_axes_mm``, ``pole_radius_mm``, ``points_mm``, ``corner``, ``fillet_mm``; mm).
    """
    try:
        p0 = (float(start_mm[0]), float(start_mm[1]))
    except (TypeError, ValueError, IndexError):
        raise InputError(f"start_mm must be [z, r] (mm), got {start_mm!r}", field="start_mm") from None
    if not (math.isfinite(p0[0]) and math.isfinite(p0[1]) and p0[1] >= 0):
        raise InputError(f"start_mm must be finite with r >= 0, got {start_mm!r}", field="start_mm")
    if not segments:
        raise InputError("a sketch needs at least one segment", field="segments")
    items = [dict(s) for s in segments]
    for i, item in enumerate(items):
        kind = item.get("type")
        if kind not in _FIELDS:
            raise _err(i, item, "type", f"unknown segment type {kind!r}; use one of {', '.join(SEGMENT_TYPES)}")
        extra = sorted(k for k, v in item.items() if v is not None and k not in _FIELDS[kind] | _COMMON)
        if extra:
            raise _err(i, item, extra[0], f"{extra[0]} does not apply to a {kind} segment (it takes "
                       f"{', '.join(sorted(_FIELDS[kind]))})")
        if item.get("corner") and i == 0:
            raise _err(i, item, "corner", "the first segment has no joint before it to be a corner")
        if item.get("fillet_mm") is not None and not item.get("corner"):
            raise _err(i, item, "fillet_mm", "fillet_mm rounds a corner: set corner = true on this segment")
        if item.get("corner") and not (item.get("fillet_mm") or 0) > 0:
            raise _err(i, item, "fillet_mm", "a corner must be rounded: give fillet_mm > 0 (the winding needs a "
                       "continuous slope r')")
    segs: list[Segment] = []
    owner: list[int] = []
    pos = p0
    for i, item in enumerate(items):
        seg = _build_one(i, item, pos, segs[-1] if segs else None, items)
        segs.append(seg)
        owner.append(i)
        pos = (seg.z1, _r_at(seg, seg.z1))
        if not math.isfinite(pos[1]):
            raise _err(i, item, "type", f"the segment ends at a non-finite radius (z = {seg.z1:.6g} mm)")
    # fillets at the marked corners
    k = 0
    while k < len(segs):
        i = owner[k]
        item = items[i]
        if item.get("corner") and k > 0 and owner[k - 1] != i:
            a, arc, b = _fillet(i, item, segs[k - 1], segs[k], float(item["fillet_mm"]))
            segs[k - 1 : k + 1] = [a, arc, b]
            owner[k - 1 : k + 1] = [owner[k - 1], i, i]
            k += 2  # the trimmed segment; the next joint to look at follows it
            continue
        k += 1
    # G1 everywhere else
    for k in range(1, len(segs)):
        A, B = segs[k - 1], segs[k]
        i = owner[k]
        ra, rb = _r_at(A, A.z1), _r_at(B, B.z0)
        if abs(ra - rb) > ON_CURVE_TOL * max(1.0, abs(ra)):
            raise _err(i, items[i], "type", f"does not start where segment {owner[k - 1] + 1} ends: r = {rb:.9g} vs "
                       f"{ra:.9g} mm at z = {B.z0:.6g} mm")
        sa, sb = _slope_at(A, A.z1), _slope_at(B, B.z0)
        ang = abs(math.atan(sa) - math.atan(sb))
        if ang > TANGENCY_TOL_RAD:
            raise _err(i, items[i], "corner", f"does not join segment {owner[k - 1] + 1} tangentially at z = "
                       f"{B.z0:.6g} mm (slopes {sa:.6g} and {sb:.6g}, {math.degrees(ang):.4g}° apart): make them "
                       "tangent, or mark the corner (corner = true) and round it (fillet_mm)")
    m = Mandrel(tuple(segs), name=name, source="sketch")
    m.meta["sketch_segments"] = len(items)
    return m


def sketch_from_mandrel(mandrel: Mandrel) -> dict[str, Any]:
    """The sketch (a ``[mandrel]`` table: kind = "segments") of ``mandrel``'s exact segments.

    Lines, arcs, ellipse arcs, isotensoid domes, splines and smooth steps map one to one, so
    :func:`build_sketch` of the result gives back the same generatrix (to round-off).
    """
    segs = mandrel.segments
    z0 = segs[0].z0
    start = [float(z0), float(max(_r_at(segs[0], z0), 0.0))]
    out: list[dict[str, Any]] = []
    for s in segs:
        end = [float(s.z1), float(max(_r_at(s, s.z1), 0.0))]
        if isinstance(s, LineSegment):
            out.append({"type": "line", "to_mm": [float(s.z1), float(s.r1)]})
        elif isinstance(s, ArcSegment):
            out.append({"type": "arc", "to_mm": end, "center_mm": [float(s.zc), float(s.rc)]})
        elif isinstance(s, EllipseSegment):
            out.append({"type": "ellipse", "to_mm": end, "center_mm": [float(s.zc), float(s.rc)],
                        "semi_axes_mm": [float(s.a), float(s.b)]})
        elif isinstance(s, IsotensoidSegment):
            if s.direction > 0:
                out.append({"type": "isotensoid", "pole_radius_mm": float(s.R * s.rho_p)})
            else:
                out.append({"type": "isotensoid", "radius_mm": float(s.R)})
        elif isinstance(s, SplineSegment):
            pts = [[float(a), float(b)] for a, b in zip(s.z_pts[1:], s.r_pts[1:])]
            out.append({"type": "spline", "points_mm": pts})
        elif isinstance(s, SmoothStepSegment):
            out.append({"type": "smoothstep", "to_mm": [float(s.z1), float(s.r1)]})
        else:
            raise InputError(f"segment kind {s.kind!r} has no sketch form")
    return {"kind": "segments", "start_mm": start, "segments": out}
