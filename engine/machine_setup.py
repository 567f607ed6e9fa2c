"""Machine set-up and the checks that make an NC program safe to run (issue 15).

The job's ``[machine.setup]`` (:class:`engine.job.SetupSpec`) says where the mandrel sits on the
machine and how the payout head and the supports are built:

* **placement** - the carriage (or robot track) position of the mandrel's z = 0.  By default the
  mandrel is *centred on the machine*: the carriage range the eye path needs is centred in the axis
  travel (:func:`place_on_machine`), so any job fits a machine whose travel is long enough;
* **head geometry** - the eye radius of a fixed-radius machine and the offsets of the eye from the
  head's datum (:func:`apply_setup`);
* **supports** - the shafts beyond both mandrel ends, the chuck (left, z < z_min) and the tailstock
  (right, z > z_max), modelled as coaxial cylinders (:func:`support_obstacles`).

Checks, all before anything is written (and the cheap ones before any long computation):

* :func:`precheck` - up front: the post-processor can address the machine's axes, a fixed eye radius
  clears the mandrel, the carriage travel is at least the mandrel's length;
* :func:`placement_report` - after the inverse kinematics: which axis leaves its range, by how much, and
  which placement would fit;
* :func:`clearance_violations` - the eye against the mandrel, the shafts, the chuck and the tailstock,
  and the free fibre against the shafts, the chuck and the tailstock, along the whole program;
* :func:`hold_back_turns` - mandrel back-turns below a tolerance (degrees) are numerical noise and are
  removed; larger ones stay violations with a message that says what to change;
* :func:`group_violations` - every violation grouped by kind and axis (worst amount, count, first NC
  line, time, circuit, layer) instead of one line per circuit.

All lengths mm, angles as stated, times s.
"""

from __future__ import annotations

import functools
import math
import re
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from engine.errors import InputError
from engine.kinematics import UNIT_SCALE, AxisPath, MachineTemplate, Violation, unwrap_angles, violations_from_mask

# --------------------------------------------------------------------------------------------------
# Head geometry and placement
# --------------------------------------------------------------------------------------------------
_POSITION_ROLES = ("carriage", "track")


def carriage_index(machine: MachineTemplate) -> int | None:
    """Index of the axis that moves the eye along the mandrel axis (carriage or robot track)."""
    for role in _POSITION_ROLES:
        k = machine.axis_index(role)
        if k is not None:
            return k
    return None


def apply_setup(machine: MachineTemplate, setup: Any) -> MachineTemplate:
    """The template with the set-up's eye radius, head offsets and explicit placement applied.

    ``setup`` is an :class:`engine.job.SetupSpec`.  Controller value of a linear head axis:
    ``scale * (eye coordinate - head offset) + offset``; an explicit ``mandrel_z0_mm`` becomes the
    carriage (track) offset.  Raises :class:`InputError` (field ``machine.setup.*``) for a set-up the
    machine cannot take.
    """
    axes = list(machine.axes)
    kw: dict[str, Any] = {}
    if setup.eye_radius_mm is not None:
        if machine.kind != "cartesian" or machine.axis_index("cross") is not None:
            raise InputError(f"machine {machine.name} moves the eye radially (cross feed or robot): a fixed eye "
                             f"radius does not apply; remove eye_radius_mm", field="machine.setup.eye_radius_mm")
        kw["eye_radius"] = float(setup.eye_radius_mm)
    off = tuple(float(x) for x in setup.head_offset_mm)
    if any(off):
        if machine.kind != "cartesian":
            raise InputError(f"machine {machine.name} is a robot cell: its eye geometry is the [robot].tool "
                             f"transform of the template; remove head_offset_mm", field="machine.setup.head_offset_mm")
        for role, d in zip(("cross", "vertical", "carriage"), off):
            k = machine.axis_index(role)
            if d == 0.0:
                continue
            if k is None:
                if role == "cross":        # fixed radius: the offset moves the eye radius
                    kw["eye_radius"] = float(kw.get("eye_radius", machine.eye_radius)) + d
                    continue
                raise InputError(f"machine {machine.name} has no {role} axis for a head offset of {d:g} mm",
                                 field="machine.setup.head_offset_mm")
            a = axes[k]
            axes[k] = replace(a, offset=a.offset - a.scale * d)
    if setup.mandrel_z0_mm is not None:
        k = carriage_index(machine)
        if k is not None:
            a = axes[k]
            axes[k] = replace(a, offset=float(setup.mandrel_z0_mm) - a.scale * off[2])
    if kw.get("eye_radius") is not None and kw["eye_radius"] <= 0:
        raise InputError(f"the eye radius with the head offset is {kw['eye_radius']:g} mm (must be > 0)",
                         field="machine.setup.head_offset_mm")
    return replace(machine, axes=tuple(axes), **kw)


@dataclass(frozen=True)
class Placement:
    """Where the mandrel sits on the machine and whether the eye path fits the carriage travel.

    Attributes
    ----------
    axis: carriage/track axis name.  mode: ``"centre"`` (automatic) or ``"fixed"`` (mandrel_z0_mm).
    z0: carriage position of the mandrel's z = 0 (controller units).
    q_min, q_max: carriage range of the program.  lo, hi: the axis limits.
    z0_fit: ``(lowest, highest)`` z0 for which the program fits the travel, or ``None`` when it cannot.
    """

    axis: str
    mode: str
    z0: float
    q_min: float
    q_max: float
    lo: float
    hi: float
    z0_fit: tuple[float, float] | None
    note: str = ""
    """What else the set-up chose (e.g. an eye radius reduced to fit the travel)."""

    @property
    def fits(self) -> bool:
        return self.lo - 1e-9 <= self.q_min and self.q_max <= self.hi + 1e-9

    def message(self) -> str:
        """One sentence for the operator."""
        need = self.q_max - self.q_min
        how = "centred on the machine" if self.mode == "centre" else "machine.setup.mandrel_z0_mm"
        where = f"mandrel z = 0 at {self.axis} {self.z0:.1f} ({how})" + (f", {self.note}" if self.note else "")
        if self.fits:
            return f"{where}: {self.axis} runs {self.q_min:.1f}..{self.q_max:.1f} within {self.lo:g}..{self.hi:g}"
        over = max(self.q_max - self.hi, self.lo - self.q_min)
        if self.z0_fit is None:
            return (f"{where}: the program needs {need:.1f} of {self.axis} travel but the axis has "
                    f"{self.hi - self.lo:g} ({self.lo:g}..{self.hi:g}); no placement fits - shorten the eye "
                    f"path (payout law, clearance) or use a machine with a longer {self.axis} axis")
        return (f"{where}: {self.axis} runs {self.q_min:.1f}..{self.q_max:.1f} and leaves {self.lo:g}..{self.hi:g} "
                f"by {over:.1f}; it fits with machine.setup.mandrel_z0_mm between {self.z0_fit[0]:.1f} and "
                f"{self.z0_fit[1]:.1f} (or remove mandrel_z0_mm to centre the mandrel)")


def place_on_machine(machine: MachineTemplate, axes: AxisPath, setup: Any) -> tuple[MachineTemplate, AxisPath,
                                                                                      Placement | None]:
    """Centre the mandrel on the machine (unless ``setup.mandrel_z0_mm`` fixes it).

    Shifts the carriage (track) column of ``axes`` and the axis offset so that the program's carriage
    range is centred in the axis travel (offset rounded to 0.1 mm), re-checks that axis' position
    limits, and returns ``(machine, axes, placement)``.  Physics is unchanged: only the datum moves.
    """
    k = carriage_index(machine)
    if k is None or axes.q.shape[0] == 0:
        return machine, axes, None
    ax = machine.axes[k]
    col = np.asarray(axes.q[:, k], dtype=float)
    q_min, q_max = float(col.min()), float(col.max())
    lo, hi = float(ax.min), float(ax.max)
    finite = math.isfinite(lo) and math.isfinite(hi) and hi - lo < 1e11
    mode = "fixed" if setup.mandrel_z0_mm is not None else "centre"
    shift = 0.0
    if mode == "centre" and finite:
        new_off = round(ax.offset + 0.5 * (lo + hi) - 0.5 * (q_min + q_max), 1)
        shift = new_off - ax.offset
    new_ax = replace(ax, offset=ax.offset + shift)
    q = np.array(axes.q, dtype=float)
    q[:, k] += shift
    q_min, q_max = q_min + shift, q_max + shift
    fit = None
    if finite and q_max - q_min <= hi - lo + 1e-9:
        fit = (new_ax.offset + lo - q_min, new_ax.offset + hi - q_max)
    placement = Placement(ax.name, mode, new_ax.offset, q_min, q_max, lo, hi, fit)
    if shift == 0.0:
        return machine, axes, placement
    machine = replace(machine, axes=tuple(new_ax if i == k else a for i, a in enumerate(machine.axes)))
    viol = [v for v in axes.violations if not (v.kind == "position" and v.axis == ax.name)]
    u = " " + ax.units
    viol += violations_from_mask("position", ax.name, q[:, k] > hi, q[:, k], hi, u, what="position")
    viol += violations_from_mask("position", ax.name, q[:, k] < lo, q[:, k], lo, u, what="position")
    q.flags.writeable = False
    return machine, replace(axes, q=q, violations=tuple(viol)), placement


def fit_eye_radius(machine: MachineTemplate, eye: Any, mandrel: Any, setup: Any) -> tuple[MachineTemplate, str]:
    """A fixed-radius machine (no cross feed) whose eye, slid along the fibre to the template's radius,
    would need more carriage travel than the axis has: the largest eye radius (0.1 mm steps, at least
    the mandrel's largest radius + ``setup.clearance_mm``) whose eye path fits with 1 mm to spare.  Only when
    ``setup.eye_radius_mm`` is not given; returns ``(machine, note)`` (note '' when unchanged).
    ``eye``: the payout stage's path (``eye_xyz``, ``fibre_dir``, ``contact_xyz``, mandrel frame)."""
    from engine.kinematics import _slide_to_radius

    k = carriage_index(machine)
    if (machine.kind != "cartesian" or machine.axis_index("cross") is not None or setup.eye_radius_mm is not None
            or machine.eye_radius is None or k is None):
        return machine, ""
    ax = machine.axes[k]
    if abs(ax.min) >= 1e11 or abs(ax.max) >= 1e11:
        return machine, ""
    travel = (ax.max - ax.min) / abs(ax.scale)
    e, d, c = (np.asarray(getattr(eye, n), dtype=float) for n in ("eye_xyz", "fibre_dir", "contact_xyz"))

    def span(radius: float) -> float:
        pts, _shift, viol = _slide_to_radius(e, d, c, radius)
        return float(np.ptp(pts[:, 2])) if not viol else np.inf

    r0 = float(machine.eye_radius)
    need = span(r0)
    if need <= travel:
        return machine, ""
    room = travel - 1.0                      # 1 mm to spare for the 0.1 mm rounding of the placement
    lo, hi = float(mandrel.r_max) + float(setup.clearance_mm), r0
    if lo >= hi or span(lo) > room:
        return machine, ""
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if span(mid) <= room else (lo, mid)
    r = math.floor(lo * 10.0) / 10.0
    note = (f"eye radius {r:g} mm (the template's {r0:g} mm would need {need:.1f} mm of {ax.name} travel, the axis "
            f"has {travel:g}; set machine.setup.eye_radius_mm to choose it)")
    return replace(machine, eye_radius=r), note


def placement_report(machine: MachineTemplate, axes: AxisPath, placement: Placement | None) -> list[str]:
    """Which axes leave their range, by how much, and (carriage) which placement would fit."""
    out: list[str] = []
    if placement is not None and not placement.fits:
        out.append(placement.message())
    q = np.asarray(axes.q, dtype=float)
    for k, ax in enumerate(machine.axes):
        if placement is not None and ax.name == placement.axis:
            continue
        lo, hi = q[:, k].min(), q[:, k].max()
        if lo < ax.min - 1e-9 or hi > ax.max + 1e-9:
            over = max(hi - ax.max, ax.min - lo)
            out.append(f"axis {ax.name} ({ax.role}) runs {lo:.4g}..{hi:.4g} {ax.units} and leaves its range "
                       f"{ax.min:g}..{ax.max:g} by {over:.4g} {ax.units}")
    return out


# --------------------------------------------------------------------------------------------------
# Mandrel back-turns
# --------------------------------------------------------------------------------------------------
def hold_back_turns(machine: MachineTemplate, axes: AxisPath, tol_deg: float) -> AxisPath:
    """Remove mandrel back-turns of at most ``tol_deg`` degrees (the angle is held instead) and give the
    remaining ones a message that names the amount, the tolerance and the cure."""
    k = machine.axis_index("mandrel")
    if k is None or not any(v.kind == "reverse" for v in axes.violations):
        return axes
    ax = machine.axes[k]
    tol = math.radians(tol_deg) * abs(ax.scale)
    q = np.array(axes.q, dtype=float)
    col = q[:, k]
    major = 1.0 if col[-1] >= col[0] else -1.0
    mono = major * np.maximum.accumulate(major * col)
    diff = np.abs(mono - col)
    keep: list[Violation] = []
    from engine.kinematics import _runs  # the same run grouping the checks use

    for a, b in _runs(diff > 0):
        if float(diff[a:b].max()) <= tol:
            col[a:b] = mono[a:b]
    q[:, k] = col
    deg = 180.0 / math.pi / UNIT_SCALE[ax.units]
    for v in axes.violations:
        if v.kind != "reverse":
            keep.append(v)
            continue
        if v.amount * deg <= tol_deg:
            continue
        keep.append(replace(v, message=(
            f"axis {ax.name}: the mandrel turns back by {v.amount:.4g} {ax.units} (tolerance "
            f"machine.setup.back_turn_tol_deg = {tol_deg:g} deg) at point {v.index}: the eye path overtakes the "
            f"fibre at a turnaround; use the min-range payout law, a larger clearance or a longer dwell")))
    q.flags.writeable = False
    return replace(axes, q=q, violations=tuple(keep))


def monotone_eye_azimuth(machine: MachineTemplate, eye_xyz: np.ndarray, fibre_dir: np.ndarray,
                         contact_xyz: np.ndarray, tol_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """Slide the eye along its free fibre where the mandrel would otherwise turn back.

    On a machine that keeps the eye at one azimuth (``mandrel_phase = "eye"``) the mandrel angle follows
    the eye's azimuth in the mandrel frame; where the payout's eye path turns that azimuth back by more
    than ``tol_deg`` (e.g. at a dwell), the eye is moved along its own fibre line - the laid line does
    not change - to the point whose azimuth is the largest reached so far, so the mandrel holds instead
    of turning back.  Where no point of the free fibre has that azimuth the eye is left (the back-turn
    is then reported).  Returns ``(eye_xyz, shift_mm)`` (shift along the fibre, 0 where unchanged).
    """
    e = np.asarray(eye_xyz, dtype=float)            # copied only where the eye is moved
    n = e.shape[0]
    shift = np.zeros(n)
    if machine.mandrel_phase != "eye" or (machine.kind == "cartesian" and machine.axis_index("cross") is None):
        return e, shift
    d = np.asarray(fibre_dir, dtype=float)
    c = np.asarray(contact_xyz, dtype=float)
    phi = unwrap_angles(np.arctan2(e[:, 1], e[:, 0]))
    major = 1.0 if phi[-1] >= phi[0] else -1.0
    target = major * np.maximum.accumulate(major * phi)
    back = np.abs(target - phi) > math.radians(tol_deg)
    if not back.any():
        return e, shift
    i = np.flatnonzero(back)
    st, ct = np.sin(target[i]), np.cos(target[i])
    den = d[i, 0] * st - d[i, 1] * ct
    with np.errstate(divide="ignore", invalid="ignore"):
        t = -(e[i, 0] * st - e[i, 1] * ct) / den
    p = e[i] + t[:, None] * d[i]
    free = np.einsum("ij,ij->i", p - c[i], d[i])
    ok = np.isfinite(t) & (np.abs(den) > 1e-12) & (p[:, 0] * ct + p[:, 1] * st > 0) & (free > 0)
    if not ok.any():
        return e, shift
    e = e.copy()
    e[i[ok]] = p[ok]
    shift[i[ok]] = t[ok]
    return e, shift


# --------------------------------------------------------------------------------------------------
# Supports and clearance
# --------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Obstacle:
    """A coaxial cylinder ``z0 <= z <= z1``, ``rho <= radius`` (mandrel frame, mm)."""

    name: str
    z0: float
    z1: float
    radius: float


def default_shaft_radius(mandrel: Any) -> float:
    """0.6 x the smaller end radius of the mandrel (at least 1 mm), mm."""
    r0, r1 = (float(x) for x in mandrel.r(np.array([mandrel.z_min, mandrel.z_max])))
    return max(0.6 * min(r0, r1), 1.0)


def support_obstacles(mandrel: Any, setup: Any) -> list[Obstacle]:
    """Shafts, chuck (left) and tailstock (right) as coaxial cylinders in the mandrel frame (defaults:
    shaft 0.6 x the smaller end radius, chuck 2 x and tailstock 1.5 x the shaft radius).  A laminate's
    grown surface (``meta["support_frame"]``: the bare mandrel's ends and default shaft radius) keeps the
    bare mandrel's supports."""
    meta = getattr(mandrel, "meta", None)
    frame = meta.get("support_frame") if isinstance(meta, dict) else None
    if frame is not None:   # a laminate's grown surface: the supports of the bare mandrel under it
        z0, z1, r_def = (float(x) for x in frame)
    else:
        z0, z1 = float(mandrel.z_min), float(mandrel.z_max)
        r_def = default_shaft_radius(mandrel) if setup.shaft_radius_mm is None else 0.0
    rs = float(setup.shaft_radius_mm) if setup.shaft_radius_mm is not None else r_def
    gap = float(setup.shaft_length_mm)
    out = []
    if gap > 0:
        out += [Obstacle("left shaft", z0 - gap, z0, rs), Obstacle("right shaft", z1, z1 + gap, rs)]
    rc = float(setup.chuck_radius_mm) if setup.chuck_radius_mm is not None else 2.0 * rs
    rt = float(setup.tailstock_radius_mm) if setup.tailstock_radius_mm is not None else 1.5 * rs
    out += [Obstacle("chuck", z0 - gap - float(setup.chuck_length_mm), z0 - gap, rc),
            Obstacle("tailstock", z1 + gap, z1 + gap + float(setup.tailstock_length_mm), rt)]
    return out


def _rect_distance(z: np.ndarray, rho: np.ndarray, ob: Obstacle) -> np.ndarray:
    """Distance of points (z, rho) from the cylinder's half-plane section (0 inside)."""
    dz = np.maximum(np.maximum(ob.z0 - z, z - ob.z1), 0.0)
    dr = np.maximum(rho - ob.radius, 0.0)
    return np.hypot(dz, dr)


def mandrel_distance(mandrel: Any, z: np.ndarray, rho: np.ndarray, step_mm: float = 0.05,
                     upto_mm: float = np.inf) -> np.ndarray:
    """Distance (mm) of points (z, rho) from the mandrel's generatrix (negative inside the mandrel).

    The generatrix is sampled every ``step_mm`` of arc length (a k-d tree's search finds the nearest sample:
    :class:`engine.nearest_jit.NearestVertex`), so the distance is exact within ``step_mm / 2``; points
    farther than ``upto_mm`` get ``inf``.
    """
    return mandrel_distance_fn(mandrel, step_mm, upto_mm)(z, rho)


def mandrel_distance_fn(mandrel: Any, step_mm: float = 0.05, upto_mm: float = np.inf) -> Any:
    """:func:`mandrel_distance` as a function ``(z, rho, upto=upto_mm) -> distance`` (the sampled generatrix
    built once; a smaller ``upto`` makes the k-d tree queries cheaper)."""
    from engine.nearest_jit import NearestVertex

    zs = np.linspace(mandrel.z_min, mandrel.z_max, 2001)
    rs = np.asarray(mandrel.r(zs), dtype=float)
    arc = np.concatenate(([0.0], np.cumsum(np.hypot(np.diff(zs), np.diff(rs)))))
    sa = np.linspace(0.0, arc[-1], max(int(arc[-1] / step_mm) + 2, 2))
    zd = np.interp(sa, arc, zs)
    prof = np.stack([zd, np.asarray(mandrel.r(zd), dtype=float)], axis=1)
    # the end faces (from the end radius down to the axis) are part of the body
    ends = [np.stack([np.full(m, zz), np.linspace(0.0, rr, m)], axis=1)
            for zz, rr in ((prof[0, 0], prof[0, 1]), (prof[-1, 0], prof[-1, 1]))
            for m in (max(int(rr / step_mm) + 2, 2),)]
    pts = np.vstack([prof, *ends])
    tree = NearestVertex(pts[:, 0], pts[:, 1])  # a cKDTree's answers, compiled search (engine.nearest_jit)
    zlo, zhi = float(mandrel.z_min), float(mandrel.z_max)
    bins: dict[float, np.ndarray] = {}

    def far_mask(z: np.ndarray, rho: np.ndarray, ub: float) -> np.ndarray:
        """Points certainly farther than ``ub`` from every sample (the k-d tree would answer inf): beyond
        the samples' z range grown by ``ub``, or above the largest sample radius of the three bins of
        width ``ub`` around them (those hold every sample within ``ub`` in z)."""
        w = max(ub, 4.0 * step_mm)
        rmax = bins.get(w)
        if rmax is None:
            nb = int((pts[:, 0].max() - zlo) // w) + 3
            k = np.clip(((pts[:, 0] - zlo) // w).astype(np.int64) + 1, 0, nb - 1)
            per = np.full(nb, -np.inf)
            np.maximum.at(per, k, pts[:, 1])
            rmax = np.maximum(np.maximum(per, np.concatenate([[-np.inf], per[:-1]])),
                              np.concatenate([per[1:], [-np.inf]]))
            bins[w] = rmax
        margin = ub * (1.0 + 1e-9) + 1e-9
        kq = np.floor((z - zlo) / w) + 1.0
        outside = (kq < 0) | (kq > rmax.size - 1) | ~np.isfinite(kq)
        kq = np.clip(np.where(np.isfinite(kq), kq, 0.0), 0, rmax.size - 1).astype(np.int64)
        far = (outside & ((z < zlo - margin) | (z > zhi + margin))) | (rho - rmax[kq] > margin)
        return far & np.isfinite(z) & np.isfinite(rho)

    def dist(z: np.ndarray, rho: np.ndarray, upto: float | None = None) -> np.ndarray:
        ub = upto_mm if upto is None else upto
        z, rho = np.asarray(z, dtype=float), np.asarray(rho, dtype=float)
        if np.isfinite(ub) and ub > 0 and z.size > 64:
            far = far_mask(z, rho, float(ub))
            if far.any():        # the same answer without the k-d tree for the points it would not find
                out = np.full(z.shape, np.inf)
                near = ~far
                out[near] = dist_all(z[near], rho[near], ub)
                return out
        return dist_all(z, rho, ub)

    def dist_all(z: np.ndarray, rho: np.ndarray, ub: float) -> np.ndarray:
        d, _ = tree.query(np.stack([z, rho], axis=1), distance_upper_bound=ub)
        inside = (z >= zlo) & (z <= zhi)
        rin = np.interp(z, zd, prof[:, 1])
        body = inside & (rho < rin)
        return np.where(body, -np.where(np.isinf(d), rin - rho, d), d)

    rmax: list[_RangeMax] = []

    def radius_max(z0: np.ndarray, z1: np.ndarray) -> np.ndarray:
        """Largest radius of the body's sampled generatrix (the one :func:`dist` tells inside from outside
        by) over ``z0 <= z <= z1`` (mm; -inf where that range misses the body), end faces included."""
        if not rmax:
            rmax.append(_RangeMax(zd, prof[:, 1]))
        return rmax[0](np.maximum(z0, zlo), np.minimum(z1, zhi))

    dist.radius_max = radius_max  # type: ignore[attr-defined]
    # the sampled generatrix is a polyline of these vertices: a point inside the body by a radial gap g is
    # within g + half the longest edge of a sample
    dist.sample_gap = float(np.hypot(np.diff(zd), np.diff(prof[:, 1])).max()) if zd.size > 1 else 0.0  # type: ignore[attr-defined]
    return dist


class _RangeMax:
    """Maximum over ``lo <= x <= hi`` of the piecewise-linear function through ``(x_j, y_j)`` (x
    nondecreasing), vectorised: the two ends interpolated and the vertices between them by a sparse table
    (O(n log n) once, O(1) a query)."""

    def __init__(self, x: np.ndarray, y: np.ndarray) -> None:
        self.x, self.y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
        levels = [self.y]
        k = 1
        while 2 * k <= self.y.size:
            prev = levels[-1]
            levels.append(np.maximum(prev[:-k], prev[k:]))
            k *= 2
        self.levels = levels

    def __call__(self, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        lo, hi = np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)
        out = np.maximum(np.interp(lo, self.x, self.y), np.interp(hi, self.x, self.y))
        j0 = np.searchsorted(self.x, lo, "right")
        j1 = np.searchsorted(self.x, hi, "left") - 1
        span = j1 - j0 + 1
        has = np.flatnonzero(span > 0)
        if has.size:
            k = np.floor(np.log2(span[has])).astype(np.int64)
            k = np.where((1 << (k + 1)) <= span[has], k + 1, k)          # log2's rounding at powers of 2
            k = np.where((1 << k) > span[has], k - 1, k)
            for lev in np.unique(k):
                sel = has[k == lev]
                row = self.levels[int(lev)]
                w = 1 << int(lev)
                out[sel] = np.maximum(out[sel], np.maximum(row[j0[sel]], row[j1[sel] - w + 1]))
        return np.where(lo <= hi, out, -np.inf)


def radial_prune(dist: Any, a: np.ndarray, u: np.ndarray, need_mm: np.ndarray | float) -> Any:
    """A ``prune`` for :func:`capsule_min_distance` with ``dist`` from :func:`mandrel_distance_fn`: the pieces
    ``a + t u``, ``t0 <= t <= t1`` of the segments that cannot come below ``need_mm`` anywhere, told by
    the piece's closest approach to the axis against the body's largest radius over its z range:

    - ``need >= 0``: the piece stays at least ``need`` above every radius of the body within ``need`` of
      its z range (every sample is then at least ``need`` away);
    - ``need < 0``: no point of the piece is inside the body by more than ``−need`` less half the longest
      edge of the sampled generatrix (a point inside by a radial gap ``g`` has ``dist >= −(g + edge/2)``),
      with 1e-6 mm to spare.

    Both only ever drop pieces whose every value is at least ``need``: the search's values below ``need``
    are the same numbers with and without it."""
    a = np.asarray(a, dtype=float)
    u = np.asarray(u, dtype=float)
    need = np.broadcast_to(np.asarray(need_mm, dtype=float), (a.shape[0],))
    radius_max = getattr(dist, "radius_max", None)
    edge = float(getattr(dist, "sample_gap", np.inf))
    if radius_max is None or not np.isfinite(edge):
        return None
    uu = np.einsum("ij,ij->i", u[:, :2], u[:, :2])
    au = np.einsum("ij,ij->i", a[:, :2], u[:, :2])

    def prune(i: np.ndarray, t0: np.ndarray, t1: np.ndarray) -> np.ndarray:
        with np.errstate(divide="ignore", invalid="ignore"):
            ts = np.where(uu[i] > 0.0, -au[i] / uu[i], t0)
        ts = np.clip(ts, t0, t1)
        p = a[i, :2] + ts[:, None] * u[i, :2]
        rho = np.hypot(p[:, 0], p[:, 1])
        rho = rho - 1e-9 * np.maximum(1.0, rho)                         # its rounding, to the safe side
        za, zb = a[i, 2] + t0 * u[i, 2], a[i, 2] + t1 * u[i, 2]
        z0, z1 = np.minimum(za, zb), np.maximum(za, zb)
        n = need[i]
        pos = n >= 0.0
        grow = np.where(pos, n, 0.0) + 1e-9 * np.maximum(1.0, np.abs(z1))
        r = radius_max(z0 - grow, z1 + grow)
        return np.where(pos, rho - r >= n, r - rho < -n - 0.5 * edge - 1e-6)

    return prune


def head_axis(machine: MachineTemplate, axes: AxisPath) -> np.ndarray:
    """Unit vectors (N,3), mandrel frame: from the eye along the payout head's body.

    Cartesian machines: the roll axis (machine x, turned by the yaw axis where there is one), pointing
    away from the mandrel axis; robot cell: from the eye towards the flange (the tool's body)."""
    return head_axis_q(machine, np.asarray(axes.q, dtype=float))


def head_axis_q(machine: MachineTemplate, q: np.ndarray) -> np.ndarray:
    """:func:`head_axis` for controller axis values ``q`` (N, n_axes)."""
    from engine.kinematics import _robot_chain, eye_pose

    qi = machine.to_internal(np.atleast_2d(np.asarray(q, dtype=float)))
    n = qi.shape[0]
    if machine.kind == "cartesian":
        u = np.zeros((n, 3))
        u[:, 0] = 1.0
        k = machine.axis_index("yaw")
        if k is not None:
            u[:, 0], u[:, 2] = np.cos(qi[:, k]), -np.sin(qi[:, k])
        p_w, _ = eye_pose(machine, qi, axis=False)
        side = np.where(u[:, 0] * p_w[:, 0] + u[:, 1] * p_w[:, 1] < 0.0, -1.0, 1.0)
        u *= side[:, None]
    else:
        track = qi[:, machine.axis_index("track")]
        joints = qi[:, [machine.axis_index(f"joint{k + 1}") for k in range(6)]]
        R, p_w, _, _ = _robot_chain(machine, track, joints)
        flange = p_w - np.einsum("nij,j->ni", R @ machine.tool[:3, :3].T, machine.tool[:3, 3])
        u = flange - p_w
        u /= np.maximum(np.linalg.norm(u, axis=1, keepdims=True), 1e-300)
    th = qi[:, machine.axis_index("mandrel")]
    c, s = np.cos(th), np.sin(th)             # p_M = Rz(-theta) p_W
    return np.stack([c * u[:, 0] + s * u[:, 1], -s * u[:, 0] + c * u[:, 1], u[:, 2]], axis=1)


def capsule_min_distance(dist: Any, a: np.ndarray, u: np.ndarray, length_mm: np.ndarray | float,
                         need_mm: np.ndarray | float, tol_mm: float = 0.05, prune: Any = None) -> np.ndarray:
    """Smallest ``dist(z, rho)`` over the segments ``a + t u``, ``0 <= t <= length_mm`` (N,), mm (``length_mm``
    one for all or one per segment).

    ``dist(z, rho, upto)`` is a distance in the (z, rho) half-plane of an axisymmetric body (1-Lipschitz in
    space, as :func:`mandrel_distance_fn`; values beyond ``upto`` may be returned as ``inf``; negative
    inside the body).  Branch and bound on ``t``: an interval of half width h whose centre is at
    distance d cannot come nearer than d - h; intervals that could still come below ``need_mm`` (or below
    the best value found) are halved until h <= ``tol_mm``.  The answer is a distance the segment reaches;
    where it is below ``need_mm`` it is the minimum within ``tol_mm``, elsewhere the minimum is at least
    ``need_mm - tol_mm``.

    ``prune(i, t0, t1)``, optional (e.g. :func:`radial_prune`): True for the pieces ``t0 <= t <= t1`` of the
    segments ``i`` that are certainly at least ``need_mm`` away everywhere; they are not searched.  A
    piece it drops holds no value below ``need_mm``, so every answer below ``need_mm`` is the same number
    with it; the others are still distances the segments reach, at least ``need_mm``.  After a level where
    it drops less than a tenth of the pieces (those left dip into the body) it is not asked again."""
    a = np.asarray(a, dtype=float)
    n = a.shape[0]
    need = np.broadcast_to(np.asarray(need_mm, dtype=float), (n,))

    top = float(np.max(need)) if n else 0.0
    top = top if np.isfinite(top) else np.inf

    def at(i: np.ndarray, t: np.ndarray, upto: float) -> np.ndarray:
        p = a[i] + t[:, None] * u[i]
        return dist(p[:, 2], np.hypot(p[:, 0], p[:, 1]), upto)

    length = np.broadcast_to(np.asarray(length_mm, dtype=float), (n,))
    every = np.arange(n)
    best = np.minimum(at(every, np.zeros(n), top + 1.0), at(every, length.copy(), top + 1.0))
    idx = every[length > 0.0]
    half = 0.5 * length[idx]             # one interval per segment to start: most are cut at once
    tc = half.copy()
    while idx.size:
        if prune is not None:
            keep = ~prune(idx, tc - half, tc + half)
            if keep.sum() > 0.9 * keep.size:
                prune = None     # it no longer pays here (the pieces left dip into the body): not asked again
            idx, tc, half = idx[keep], tc[keep], half[keep]
            if not idx.size:
                break
        d = at(idx, tc, top + float(half.max()) + 1.0)    # farther centres are cut whatever their distance
        np.minimum.at(best, idx, d)
        keep = (d - half < np.minimum(best[idx], need[idx])) & (half > tol_mm)
        idx, tc, half = idx[keep], tc[keep], 0.5 * half[keep]
        idx, half = np.repeat(idx, 2), np.repeat(half, 2)
        tc = np.stack([tc - half[::2], tc + half[::2]], axis=1).ravel()
    return best


def _segment_min_rho(c: np.ndarray, e: np.ndarray, z0: float, z1: float,
                     z_range: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """Smallest distance from the axis of the segments c->e (N,3) within z0 <= z <= z1 (inf: none there).

    Only the segments whose z range meets [z0, z1] are evaluated (the others are ``inf``; the values of
    the rest are those of :func:`_segment_min_rho_all`, bit for bit).  ``z_range``: the segments'
    ``(min z, max z)`` when the caller has them already."""
    if z_range is None:
        cz, ez = c[:, 2], e[:, 2]
        z_range = (np.minimum(cz, ez), np.maximum(cz, ez))
    near = np.flatnonzero((z_range[1] >= z0 - 1e-9) & (z_range[0] <= z1 + 1e-9))
    out = np.full(c.shape[0], np.inf)
    if near.size:
        out[near] = _segment_min_rho_all(c[near], e[near], z0, z1)
    return out


def _segment_min_rho_all(c: np.ndarray, e: np.ndarray, z0: float, z1: float) -> np.ndarray:
    """:func:`_segment_min_rho` evaluated on every segment (the reference)."""
    d = e - c
    dz = d[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        ta = np.where(np.abs(dz) > 1e-12, (z0 - c[:, 2]) / dz, -np.inf)
        tb = np.where(np.abs(dz) > 1e-12, (z1 - c[:, 2]) / dz, np.inf)
    t_lo = np.clip(np.minimum(ta, tb), 0.0, 1.0)
    t_hi = np.clip(np.maximum(ta, tb), 0.0, 1.0)
    flat = np.abs(dz) <= 1e-12
    inside_flat = (c[:, 2] >= z0) & (c[:, 2] <= z1)
    t_lo = np.where(flat, 0.0, t_lo)
    t_hi = np.where(flat, 1.0, t_hi)
    empty = np.where(flat, ~inside_flat, t_hi <= t_lo)
    dxy = d[:, :2]
    a = np.einsum("ij,ij->i", dxy, dxy)
    with np.errstate(divide="ignore", invalid="ignore"):
        ts = np.where(a > 0, -np.einsum("ij,ij->i", c[:, :2], dxy) / a, 0.0)
    ts = np.clip(ts, t_lo, t_hi)
    p = c[:, :2] + ts[:, None] * dxy
    return np.where(empty, np.inf, np.hypot(p[:, 0], p[:, 1]))


def clearance_violations(axes: AxisPath, mandrel: Any, setup: Any, eye_clearance_mm: float | None = None,
                         machine: MachineTemplate | None = None) -> list[Violation]:
    """The eye (the head) against the mandrel and the supports, the free fibre against the supports, at
    every point.

    ``eye_clearance_mm`` (default ``setup.clearance_mm``) is the smallest gap between the eye and the
    mandrel; the supports keep ``setup.clearance_mm`` from the eye and from the free fibre.  The eye's gaps
    are measured from the head's body around it: ``setup.head_radius_mm`` is added to them.  With
    ``setup.head_length_mm`` > 0 and the ``machine`` given, the body is a capsule of that radius around the
    segment of that length from the eye along :func:`head_axis` (:func:`capsule_min_distance`).
    Violations have kind ``"clearance"``, ``axis`` None, ``amount`` = the missing gap (mm).
    """
    gap = float(setup.clearance_mm)
    head = float(getattr(setup, "head_radius_mm", 0.0))
    length = float(getattr(setup, "head_length_mm", 0.0) or 0.0)
    eye_gap = (gap if eye_clearance_mm is None else float(eye_clearance_mm)) + head
    eye = np.asarray(axes.eye_xyz, dtype=float)
    con = np.asarray(axes.contact_xyz, dtype=float)
    z, rho = eye[:, 2], np.hypot(eye[:, 0], eye[:, 1])
    capsule = length > 0.0 and machine is not None
    u = head_axis(machine, axes) if capsule else None
    body = "head" if capsule else "eye"
    out: list[Violation] = []
    if capsule:
        fn = mandrel_distance_fn(mandrel, upto_mm=2.0 * eye_gap + 1.0)
        dm = fn(z, rho, eye_gap + length + 1.0)
        near = np.flatnonzero(dm - length < eye_gap)          # the capsule's axis stays within ``length``
        if near.size:
            dm[near] = capsule_min_distance(fn, eye[near], u[near], length, eye_gap)
    else:
        dm = mandrel_distance(mandrel, z, rho, upto_mm=2.0 * eye_gap + 1.0)
    out += violations_from_mask("clearance", None, dm < eye_gap - 1e-6, dm, eye_gap, " mm",
                                what=f"gap between the {body} and the mandrel")
    z_range = (np.minimum(con[:, 2], z), np.maximum(con[:, 2], z))    # of every free fibre
    for ob in support_obstacles(mandrel, setup):
        # only points within ``gap`` of the support's box can violate (elsewhere de >= gap; the values
        # of :func:`violations_from_mask` are read inside the violating runs only)
        g_eye = gap + head
        reach = g_eye + length
        near = np.flatnonzero((z > ob.z0 - reach) & (z < ob.z1 + reach) & (rho < ob.radius + reach))
        de = np.full(z.size, np.inf)
        if capsule and near.size:
            de[near] = capsule_min_distance(lambda zz, rr, _up, ob=ob: _rect_distance(zz, rr, ob), eye[near], u[near],
                                            length, g_eye)
        else:
            de[near] = _rect_distance(z[near], rho[near], ob)
        out += violations_from_mask("clearance", None, de < g_eye - 1e-6, de, g_eye, " mm",
                                    what=f"gap between the {body} and the {ob.name}")
        rf = _segment_min_rho(con, eye, ob.z0, ob.z1, z_range) - ob.radius
        out += violations_from_mask("clearance", None, rf < gap - 1e-6, rf, gap, " mm",
                                    what=f"gap between the free fibre and the {ob.name}")
    return out


# --------------------------------------------------------------------------------------------------
# Speed steps between blocks
# --------------------------------------------------------------------------------------------------
def limit_speed_steps(delta: np.ndarray, time_s: np.ndarray, max_jump: np.ndarray, cyclic: bool,
                      max_accel: np.ndarray | None = None, max_rounds: int = 10_000) -> np.ndarray:
    """Block times (s), each >= ``time_s``, for which every axis' speed step between neighbouring blocks
    is within ``max_jump`` (controller units/s) - the (18) condition - and, with ``max_accel`` (units/s²),
    also within ``max_accel`` x the pair's mean block time (the acceleration measure of the report).

    Only blocks that take part in a step above the limit are slowed, each by the smallest factor its
    worst pair needs: where both blocks run the same way on the axis, the faster one comes down to the
    slower one's speed + max_jump; on a reversal both come down so that the step is max_jump.  Repeated
    (Jacobi rounds) until no step is over: the slowed block may now step against its other neighbour,
    so a speed ramp with steps of max_jump grows outwards, as a controller's look-ahead would plan it.
    Speeds only fall, so the rounds end.
    """
    t = np.array(time_s, dtype=float)
    nb = t.size
    if nb < 2:
        return t
    d = np.asarray(delta, dtype=float)
    p = np.asarray(max_jump, dtype=float)
    i_all = np.arange(nb) if cyclic and nb > 2 else np.arange(nb - 1)
    act = i_all
    for _ in range(max_rounds):
        i = act
        j = (i + 1) % nb
        vi, vj = d[i] / t[i, None], d[j] / t[j, None]
        pe = p if max_accel is None else np.minimum(p, np.asarray(max_accel) * 0.5 * (t[i] + t[j])[:, None])
        over = np.abs(vj - vi) > pe * (1.0 + 1e-9)
        rows = over.any(axis=1)
        if not rows.any():
            if act.size == i_all.size:
                return t
            act = i_all                          # confirm on every pair
            continue
        i, j, vi, vj, over, pe = i[rows], j[rows], vi[rows], vj[rows], over[rows], np.broadcast_to(pe, vi.shape)[rows]
        ai, aj = np.abs(vi), np.abs(vj)
        same = vi * vj >= 0
        with np.errstate(divide="ignore", invalid="ignore"):
            fi = np.where(same, np.where(ai > aj, ai / (aj + pe), 1.0), (ai + aj) / pe)
            fj = np.where(same, np.where(aj > ai, aj / (ai + pe), 1.0), (ai + aj) / pe)
        fi = np.where(over, fi, 1.0).max(axis=1) * (1.0 + 1e-9)
        fj = np.where(over, fj, 1.0).max(axis=1) * (1.0 + 1e-9)
        g = np.ones(nb)
        np.maximum.at(g, i, fi)
        np.maximum.at(g, j, fj)
        t *= g
        moved = np.flatnonzero(g > 1.0)
        act = np.unique(np.concatenate([(moved - 1) % nb, moved]))
        if not (cyclic and nb > 2):
            act = act[(act >= 0) & (act < nb - 1)]
    return t


# --------------------------------------------------------------------------------------------------
# Locating and grouping violations
# --------------------------------------------------------------------------------------------------
_MOVE = re.compile(r"^\s*(?:N\d+\s+)?G0?1(?![0-9])", re.IGNORECASE)


def nc_move_lines(nc_text: str | None) -> np.ndarray:
    """1-based line numbers of the feed moves (G1/G01 lines, or the rows of a CSV table after block 0).

    Read-only; the last few texts' answers are kept (a run's report, warnings and violation groups all
    locate blocks in the same program: one scan of a 56 000-block program is about 25 ms)."""
    if not nc_text:
        return np.zeros(0, dtype=np.int64)
    return _nc_move_lines_cached(nc_text)


@functools.lru_cache(maxsize=4)
def _nc_move_lines_cached(nc_text: str) -> np.ndarray:
    out = _nc_move_lines(nc_text)
    out.setflags(write=False)
    return out


def _nc_move_lines(nc_text: str) -> np.ndarray:
    lines = nc_text.replace("\r\n", "\n").split("\n")
    rows = [i + 1 for i, s in enumerate(lines) if _MOVE.match(s)]
    if rows:
        return np.asarray(rows, dtype=np.int64)
    # CSV: a header row starting with "block", then block 0 (the start) and one row per block
    for i, s in enumerate(lines):
        if s.startswith("block"):
            n = sum(1 for x in lines[i + 2:] if x and x[0].isdigit())
            return np.arange(i + 3, i + 3 + n, dtype=np.int64)
    return np.zeros(0, dtype=np.int64)


class Locator:
    """Maps a path point or a block of a pipeline result to (layer, circuit, time, NC line)."""

    def __init__(self, result: Any, layer: int = 1) -> None:
        self.layer = layer
        blocks = result.blocks
        self.block_index = np.asarray(blocks.index, dtype=np.int64) if blocks is not None else None
        self.block_start = (np.concatenate(([0.0], np.cumsum(np.asarray(blocks.time, dtype=float))))
                            if blocks is not None else None)
        self._nc_text = result.nc_text
        self._lines: np.ndarray | None = None
        eye_index = getattr(result.eye, "index", None)
        self.line_index = np.asarray(eye_index, dtype=np.int64) if eye_index is not None else None
        self.ppc = int(getattr(result.line, "points_per_circuit", 0) or 0)

    @property
    def lines(self) -> np.ndarray:
        """1-based NC line of every block (read on first use: most runs locate nothing)."""
        if self._lines is None:
            self._lines = nc_move_lines(self._nc_text)
        return self._lines

    @lines.setter
    def lines(self, value: np.ndarray) -> None:
        self._lines = value

    def block_of_point(self, i: int) -> int | None:
        if self.block_index is None or self.block_index.size < 2:
            return None
        return int(np.clip(np.searchsorted(self.block_index, i, side="right") - 1, 0, self.block_index.size - 2))

    def locate(self, point: int | None = None, block: int | None = None) -> dict[str, Any]:
        """``{"layer", "circuit", "time_s", "nc_line", "block", "point"}`` (None where unknown)."""
        if point is None and block is not None and self.block_index is not None:
            point = int(self.block_index[min(block, self.block_index.size - 1)])
        if block is None and point is not None:
            block = self.block_of_point(point)
        out: dict[str, Any] = {"layer": self.layer, "circuit": None, "time_s": None, "nc_line": None,
                               "block": block, "point": point}
        if point is not None and self.line_index is not None and self.ppc > 0 and point < self.line_index.size:
            out["circuit"] = int(self.line_index[point] // self.ppc) + 1
        if block is not None and self.block_start is not None:
            out["time_s"] = float(self.block_start[block])
        if block is not None and block < self.lines.size:
            out["nc_line"] = int(self.lines[block])
        return out


@dataclass(frozen=True)
class ViolationGroup:
    """All violations of one kind on one axis (or one clearance pair)."""

    kind: str
    axis: str | None
    what: str
    worst: float
    value: float
    limit: float
    places: int
    points: int
    first: dict[str, Any]
    message: str


_UNIT = re.compile(r"exceeds the limit -?[0-9.eE+-]+( [^ ]+)? by")
_WHAT = re.compile(r"^(?:axis \S+|machine): (.*?) -?[0-9.eE+-]+(?: ?\S+)? exceeds")


def _where(loc: dict[str, Any]) -> str:
    parts = []
    if loc.get("nc_line") is not None:
        parts.append(f"NC line {loc['nc_line']}")
    if loc.get("time_s") is not None:
        parts.append(f"t = {loc['time_s']:.2f} s")
    if loc.get("circuit") is not None:
        parts.append(f"circuit {loc['circuit']}")
    lay = loc.get("layer")
    if lay is not None:   # a layer's number, or a named part of a joined program ("transition to layer 2")
        parts.append(lay if isinstance(lay, str) and not lay.isdigit() else f"layer {lay}")
    if not parts and loc.get("point") is not None:
        parts.append(f"path point {loc['point']}")
    return ", ".join(parts)


def group_violations(violations: list[Violation], locator: Locator | None = None) -> list[ViolationGroup]:
    """One group per (kind, axis, what, above/below the limit): worst amount, number of places, first
    place located (NC line, time, circuit, layer)."""
    groups: dict[tuple[Any, ...], list[Violation]] = {}
    for v in violations:
        m = _WHAT.match(v.message or "")
        what = m.group(1) if m else v.kind
        what = what.removeprefix("end ")           # a block's end position is a path position too
        if v.kind == "reverse":
            what = "mandrel back-turn"
        groups.setdefault((v.kind, v.axis, what, v.value < v.limit), []).append(v)
    out: list[ViolationGroup] = []
    for (kind, axis, what, _below), vs in groups.items():
        w = max(vs, key=lambda v: abs(v.amount))
        first = min(vs, key=lambda v: (v.index if v.index is not None else 1 << 62,
                                       v.block if v.block is not None else 1 << 62))
        loc = (locator.locate(point=first.index, block=first.block) if locator is not None
               else {"point": first.index, "block": first.block})
        label = f"axis {axis}" if axis else "machine"
        pts = sum(v.count for v in vs)
        if kind == "reverse":
            text = (f"{label}: the mandrel turns back by up to {abs(w.amount):.4g} at {len(vs)} place(s)"
                    f"; {w.message.split(': ', 1)[1] if ': ' in w.message else ''}")
        else:
            rel = "below" if w.value < w.limit else "above"
            m_u = _UNIT.search(w.message or "")
            u = m_u.group(1) if m_u else ""
            text = (f"{label}: {what} {w.value:.6g}{u} is {rel} the limit {w.limit:.6g}{u} by {abs(w.amount):.4g}{u} "
                    f"(worst) at {len(vs)} place(s), {pts} {'block' if first.block is not None else 'point'}(s)")
        where = _where(loc)
        msg = f"{text}; first at {where}" if where else text
        out.append(ViolationGroup(kind, axis, what, float(abs(w.amount)), float(w.value), float(w.limit), len(vs),
                                  pts, loc, msg))
    return out


# --------------------------------------------------------------------------------------------------
# Post-processor x machine
# --------------------------------------------------------------------------------------------------
def post_mismatch(post_name: str, profile: Any, machine: MachineTemplate) -> str | None:
    """Why ``post_name`` with ``profile`` cannot write programs for ``machine`` (None: it can)."""
    from engine.post import get_post

    post = get_post(post_name)
    if profile.dialect != post.name:
        return f"controller profile {profile.name} is for the {profile.dialect} dialect, not {post.name}"
    only = profile.extra.get("machines")
    if only and machine.name not in only:
        return f"controller profile {profile.name} is made for machine(s) {', '.join(only)}"
    try:
        post.letters(machine, profile)
        post.check_units(machine, profile)
    except InputError as exc:
        return exc.message
    return None


def controller_for(post_name: str, controller: str | None, machine: MachineTemplate) -> Any:
    """The controller profile that writes ``machine``'s axes in dialect ``post_name``.

    With ``controller`` given, that profile (refused with the reason when it cannot address the axes);
    else the dialect's own profile, or the first shipped profile of that dialect that addresses them.
    Raises :class:`InputError` (field ``post.post``/``post.controller``) naming the mismatch and the
    posts/controllers that do work for the machine.
    """
    from engine.post import get_post, list_controllers, load_controller

    if not post_name:
        raise InputError("no post-processor chosen", field="post.post")
    post = get_post(post_name)
    if controller:
        prof = load_controller(controller)
        why = post_mismatch(post.name, prof, machine)
        if why is None:
            return prof
        raise InputError(f"post {post.name} with controller {prof.name} cannot write machine {machine.name}: {why}"
                         f"; {_suggest(machine)}", field="post.controller")
    names = [post.name] + [c for c in list_controllers() if c != post.name]
    first_why = None
    for name in names:
        prof = load_controller(name)
        if prof.dialect != post.name:
            continue
        why = post_mismatch(post.name, prof, machine)
        if why is None:
            return prof
        first_why = first_why or why
    raise InputError(f"post {post.name} cannot write machine {machine.name} ({first_why}); {_suggest(machine)}",
                     field="post.post")


def compatible_posts(machine: MachineTemplate) -> list[tuple[str, str]]:
    """``(post, controller)`` pairs (shipped profiles) that can address ``machine``'s axes."""
    from engine.post import list_controllers, list_posts, load_controller

    out = []
    posts = set(list_posts())
    for c in list_controllers():
        prof = load_controller(c)
        if prof.dialect in posts and post_mismatch(prof.dialect, prof, machine) is None:
            out.append((prof.dialect, c))
    return out


def _suggest(machine: MachineTemplate) -> str:
    ok = compatible_posts(machine)
    if not ok:
        return "no shipped controller profile addresses its axes"
    return "these work: " + ", ".join(f"post {p}" + (f" with [post] controller = \"{c}\"" if c != p else "")
                                      for p, c in ok)


# --------------------------------------------------------------------------------------------------
# Up-front checks
# --------------------------------------------------------------------------------------------------
def precheck(job: Any, machine: MachineTemplate, mandrel: Any | None = None, with_post: bool = True,
             line: Any | None = None) -> None:
    """Checks that need no long computation; raises :class:`InputError` naming the field.

    * the post (and controller) can address the machine's axes (``with_post``);
    * a fixed eye radius clears the mandrel's largest radius by ``setup.clearance_mm``;
    * the carriage (track) travel is at least the mandrel's length;
    * with the winding ``line`` (before the payout and the time law): the carriage range the eye path
      needs at least (:func:`carriage_need`) fits the travel - and, with a fixed placement
      (``mandrel_z0_mm``), lies inside it; the message names the axis, by how much it leaves its range
      and which placement (or eye radius) would fit.
    """
    if with_post:
        controller_for(job.post.post, job.post.controller, machine)
    if mandrel is None:
        return
    setup = job.machine.setup
    if machine.kind == "cartesian" and machine.axis_index("cross") is None and machine.eye_radius is not None:
        need = float(mandrel.r_max) + float(setup.clearance_mm)
        if machine.eye_radius < need:
            raise InputError(f"the eye of machine {machine.name} runs at radius {machine.eye_radius:g} mm but the "
                             f"mandrel's largest radius is {mandrel.r_max:g} mm: it needs at least {need:g} mm "
                             f"(machine.setup.eye_radius_mm)", field="machine.setup.eye_radius_mm")
    k = carriage_index(machine)
    if k is not None:
        ax = machine.axes[k]
        travel = (ax.max - ax.min) / abs(ax.scale)
        if travel < mandrel.length:
            raise InputError(f"axis {ax.name} travels {travel:g} mm but the mandrel is {mandrel.length:g} mm long: "
                             f"no placement fits it on machine {machine.name}", field="machine.template")
    if line is not None and k is not None:
        _precheck_carriage(job, machine, mandrel, line)


def _fixed_radius(machine: MachineTemplate) -> bool:
    return machine.kind == "cartesian" and machine.axis_index("cross") is None and machine.eye_radius is not None


def carriage_need(machine: MachineTemplate, line: Any, eye_radius_mm: float | None = None,
                  law_radius_mm: float | None = None) -> tuple[float, float, str] | None:
    """The mandrel-frame z range (mm) the eye must cover, from the winding line alone: ``(z_lo, z_hi, how)``.

    The eye always sits on the free fibre, the tangent ray of the line at its contact point, ahead of
    the contact.  On a fixed-radius machine (no cross feed) the eye is that ray's point at the eye radius
    (``eye_radius_mm``, default the machine's): the range is exact, whatever the payout law.  On the other
    cartesian machines it is a lower bound: where the contact is at its largest (smallest) z the ray runs
    along the parallel or away from the mandrel, so the eye is at least as far out - unless the payout
    law puts the eye at a known radius (the 'parallel' law: ``law_radius_mm``), where it is that ray's
    point at that radius as on a fixed-radius machine (the payout interpolates its law between grid points:
    the eye path's own range is within about a millimetre of it, mostly inside).  ``None`` for a robot
    (its arm reaches along the mandrel axis beyond the track)."""
    if machine.kind != "cartesian":
        return None
    from engine.periodic import deferred

    if deferred(line, "xyz") is not None or deferred(line, "tau") is not None:
        line = line.one_circuit          # circuits are circuit 0 turned about the axis: the same z range
    c = np.asarray(line.xyz, dtype=float)
    if c.shape[0] == 0:
        return None
    fixed = _fixed_radius(machine)
    if fixed or law_radius_mm is not None:
        from engine.kinematics import _slide_to_radius

        r = float(eye_radius_mm if eye_radius_mm is not None else machine.eye_radius) if fixed else float(
            law_radius_mm)
        pts, _s, viol = _slide_to_radius(c, np.asarray(line.tau, dtype=float), c, r)
        if not viol:
            how = f"the eye at radius {r:g} mm" if fixed else f"the eye on the parallel law's radius {r:g} mm"
            return float(pts[:, 2].min()), float(pts[:, 2].max()), how
    return float(c[:, 2].min()), float(c[:, 2].max()), "the winding line (turnarounds included)"


def _precheck_carriage(job: Any, machine: MachineTemplate, mandrel: Any, line: Any) -> None:
    setup = job.machine.setup
    k = carriage_index(machine)
    ax = machine.axes[k]
    lo, hi = float(ax.min), float(ax.max)
    if not (math.isfinite(lo) and math.isfinite(hi)) or hi - lo >= 1e11:
        return
    law_r = None
    if not _fixed_radius(machine) and job.payout.law == "parallel":
        law_r = (float(job.payout.eye_radius_mm) if job.payout.eye_radius_mm is not None
                 else float(mandrel.r_max) + float(job.payout.clearance_mm))
    need = carriage_need(machine, line, law_radius_mm=law_r)
    if need is None:
        return
    z_lo, z_hi, how = need
    s = float(ax.scale)
    travel = (hi - lo) / abs(s)
    span = z_hi - z_lo
    slack = 1e-6 * max(1.0, travel) + 1e-3            # numerical noise: only a sure misfit is refused here
    exact = how.startswith("the eye at radius")
    if how.startswith("the eye on the parallel law"):
        # the law is interpolated between its grid points: the eye path's range falls short of the ray's by
        # up to about a millimetre at the default grid (1000 points a circuit); only what is sure is kept -
        # the ray's range less a margin that grows with a coarser grid, and never less than the line's own
        margin = max(5.0, 0.02 * span * max(1.0, 1000.0 / float(job.payout.grid_points)))
        c_lo, c_hi, _how = carriage_need(machine, line)
        z_lo, z_hi = min(z_lo + 0.5 * margin, c_lo), max(z_hi - 0.5 * margin, c_hi)
        span = z_hi - z_lo
        how += f" (less {margin:.1f} mm for the payout grid's interpolation)"
    if span > travel + slack:
        extra, fld = "", "machine.template"
        tail = (f"; no placement fits - use a machine with a longer {ax.name} axis or shorten the turnarounds "
                f"(dwell, pins)")
        if exact:
            r_min = float(mandrel.r_max) + float(setup.clearance_mm)
            room = travel - 1.0                        # as fit_eye_radius: 1 mm to spare for the rounding

            def span_at(r: float) -> float:
                got = carriage_need(machine, line, r)
                return got[1] - got[0] if got is not None else math.inf

            if span_at(r_min) <= room:
                if setup.eye_radius_mm is None:
                    return                             # the set-up reduces the eye radius (fit_eye_radius)
                a_r, b_r = r_min, float(machine.eye_radius)
                for _ in range(40):
                    mid = 0.5 * (a_r + b_r)
                    a_r, b_r = (mid, b_r) if span_at(mid) <= room else (a_r, mid)
                extra = (f"; machine.setup.eye_radius_mm up to {math.floor(a_r * 10.0) / 10.0:g} mm fits (or remove "
                         f"it to let the set-up choose)")
                tail, fld = "", "machine.setup.eye_radius_mm"
            else:
                extra = (f"; even the smallest eye radius {r_min:g} mm (largest mandrel radius + clearance) needs "
                         f"{span_at(r_min):.1f} mm")
        raise InputError(
            f"axis {ax.name} of machine {machine.name} travels {travel:g} mm ({lo:g}..{hi:g} {ax.units}) but "
            f"{how} runs z = {z_lo:.1f}..{z_hi:.1f} mm: it needs {'' if exact else 'at least '}{span:.1f} mm, "
            f"{span - travel:.1f} mm more than the axis has{extra}{tail}", field=fld)
    if setup.mandrel_z0_mm is None:
        return
    z0 = float(ax.offset)                             # the fixed placement (apply_setup) with the head offset
    a, b = sorted((z0 + s * z_lo, z0 + s * z_hi))
    if a >= lo - slack and b <= hi + slack:
        return
    over, side = (b - hi, f"above its maximum {hi:g}") if b - hi >= lo - a else (lo - a, f"below its minimum {lo:g}")
    fit_lo, fit_hi = float(setup.mandrel_z0_mm) + lo - a, float(setup.mandrel_z0_mm) + hi - b
    raise InputError(
        f"with the mandrel's z = 0 at {ax.name} = {float(setup.mandrel_z0_mm):g} (machine.setup.mandrel_z0_mm) "
        f"axis {ax.name} would run {'' if exact else 'at least '}{a:.1f}..{b:.1f} {ax.units} ({how} runs "
        f"z = {z_lo:.1f}..{z_hi:.1f} mm), {over:.1f} {ax.units} {side}; it "
        f"{'fits' if exact else 'can only fit'} with mandrel_z0_mm between {fit_lo:.1f} and {fit_hi:.1f} "
        f"(or remove mandrel_z0_mm to centre the mandrel on the machine)", field="machine.setup.mandrel_z0_mm")


__all__ = ["Locator", "Obstacle", "Placement", "ViolationGroup", "apply_setup", "capsule_min_distance",
           "carriage_index", "carriage_need", "clearance_violations", "compatible_posts", "controller_for",
           "fit_eye_radius", "group_violations", "head_axis", "head_axis_q", "hold_back_turns", "limit_speed_steps",
           "mandrel_distance_fn", "monotone_eye_azimuth", "nc_move_lines", "place_on_machine", "radial_prune",
           "placement_report", "post_mismatch", "precheck", "support_obstacles"]
