"""Geometry of the machine schematic (no Qt): projection, neutral pose, axis glyphs from the engine's
forward kinematics, and the label placement (:func:`place_labels`).  Drawn by
:class:`winder_gui.views.machine_schematic.MachineSchematic`, whose docstring describes the drawing.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from winder_gui.views.plots import AXIS_COLOURS

VIEW_AZIMUTH_DEG = -40.0  # camera turned from the +x (eye side) towards the tail end (+z)
VIEW_ELEVATION_DEG = 22.0


def _view_matrix(az_deg: float, el_deg: float) -> np.ndarray:
    """Orthographic view: rows are the screen's right and up unit vectors in the machine frame."""
    az, el = math.radians(az_deg), math.radians(el_deg)
    d = np.array([math.cos(el) * math.cos(az), math.sin(el), -math.cos(el) * math.sin(az)])   # to the camera
    right = np.cross([0.0, 1.0, 0.0], d)
    right /= np.linalg.norm(right)
    up = np.cross(d, right)
    return np.stack([right, up])


PROJECTION = _view_matrix(VIEW_AZIMUTH_DEG, VIEW_ELEVATION_DEG)
VIEW_DIR = np.cross(PROJECTION[0], PROJECTION[1])     # towards the camera
UNLIMITED = 1e11          # templates write "no limit" as +-1e12
MANDREL_COLOUR = "#9aa7b4"
STRUCTURE_COLOUR = "#8a8a8a"
EYE_COLOUR = "#d62728"


def project(points: np.ndarray) -> np.ndarray:
    """Machine-frame points (N,3) or (3,), mm -> drawing plane (N,2) or (2,), mm, v up."""
    p = np.asarray(points, dtype=float)
    return p @ PROJECTION.T


def axis_colour(index: int) -> str:
    """Colour of the template's ``index``-th axis (the axes table and the axis plots use the same)."""
    return AXIS_COLOURS[index % len(AXIS_COLOURS)]


# --------------------------------------------------------------------------------------------------
# Geometry (pure numpy + engine; no Qt)
# --------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class AxisGlyph:
    """One axis as drawn.

    Attributes
    ----------
    name, role, type: from the template (``type`` is ``"linear"`` or ``"rotary"``).
    index: the axis's position in the template (colour index, table row).
    label: text drawn next to it (name and travel in controller units).
    origin3: machine frame, mm. Linear: the moved point at the neutral pose; rotary: a point on the
        rotation axis (the arc's centre).
    dir3: unit vector, machine frame: the motion direction for a growing controller value (linear)
        or the rotation axis, right-hand rule for a growing controller value (rotary; the arc's arrow
        head shows that sense).
    ends3: (2,3) linear: the moved point at the axis's min and max (``None`` when unlimited: a nominal
        arrow is drawn); rotary: ``None``.
    radius: rotary arc radius, mm (0 for linear).
    origin, direction: ``origin3`` projected (mm, v up) and ``dir3`` projected and normalised (for a
        rotary axis seen end-on the direction is (0, 0)).
    ends: ``ends3`` projected (2,2), or ``None``.
    """

    name: str
    role: str
    type: str
    index: int
    label: str
    origin3: np.ndarray
    dir3: np.ndarray
    ends3: np.ndarray | None
    radius: float
    origin: np.ndarray
    direction: np.ndarray
    ends: np.ndarray | None


@dataclass(frozen=True)
class Schematic:
    """The whole drawing in the machine frame (mm) and projected.

    ``q``: the neutral pose, controller units.  ``eye3``: eye position (FK of ``q``; the mandrel angle
    is 0, so machine and mandrel frames coincide).  ``eye_axis3``: eye axis.  ``links3``: the
    structure polyline (robot link chain / cartesian slide staircase ending at the eye).
    ``mandrel_radius``, ``mandrel_z``: the nominal mandrel cylinder (radius; z of its two ends).
    """

    machine: Any
    q: np.ndarray
    eye3: np.ndarray
    eye_axis3: np.ndarray
    links3: np.ndarray
    axes: tuple[AxisGlyph, ...]
    mandrel_radius: float
    mandrel_z: tuple[float, float]
    size: float
    supports: tuple[tuple[str, float, float, float], ...] = ()
    """The job's shafts, chuck and tailstock: ``(name, z0, z1, radius)`` in the machine frame (mm)."""

    @property
    def eye(self) -> np.ndarray:
        return project(self.eye3)

    @property
    def links(self) -> np.ndarray:
        return project(self.links3)


def _limited(lo: float, hi: float) -> bool:
    return abs(lo) < UNLIMITED and abs(hi) < UNLIMITED


def _internal_range(ax: Any) -> tuple[float, float] | None:
    """The axis's travel in internal units (rad / mm), sorted, or ``None`` when unlimited."""
    if not _limited(ax.min, ax.max):
        return None
    a, b = (ax.min - ax.offset) / ax.scale, (ax.max - ax.offset) / ax.scale
    return (min(a, b), max(a, b))


def _ends_internal(ax: Any) -> tuple[float, float] | None:
    """Internal values (rad / mm) at the axis's controller min and max (in that order), or ``None``."""
    if not _limited(ax.min, ax.max):
        return None
    return ((ax.min - ax.offset) / ax.scale, (ax.max - ax.offset) / ax.scale)


def neutral_pose(machine: Any) -> np.ndarray:
    """A pose to draw the machine in (internal units: rad, mm).

    Rotary axes at their datum (internal 0) clamped into their travel, robot joints at the template's
    home; linear axes at the middle of their travel (the datum when unlimited).  If the eye would then
    sit closer than 150 mm to the mandrel axis, the first linear axis that moves it radially is set to
    3/4 of its travel (300 mm from the datum when unlimited), on the side away from the axis.
    """
    from engine.kinematics import eye_pose

    q = np.zeros(len(machine.axes))
    for k, ax in enumerate(machine.axes):
        rng = _internal_range(ax)
        if ax.type == "linear":
            q[k] = 0.5 * (rng[0] + rng[1]) if rng else 0.0
        elif rng:
            q[k] = min(max(0.0, rng[0]), rng[1])
    if machine.kind == "robot":
        for j, h in enumerate(machine.home):
            q[machine.axis_index(f"joint{j + 1}")] = h
    p0 = eye_pose(machine, q)[0][0]
    if math.hypot(p0[0], p0[1]) < 150.0:
        for k, ax in enumerate(machine.axes):
            rng = _internal_range(ax)
            if ax.type != "linear":
                continue
            d = _linear_dir(machine, q, k)
            if math.hypot(d[0], d[1]) < 0.5:
                continue
            if rng is None:            # unlimited: 300 mm either side of the datum
                rng = (q[k] - 600.0, q[k] + 600.0)
            hi = q.copy()
            hi[k] = rng[0] + 0.75 * (rng[1] - rng[0])
            lo = q.copy()
            lo[k] = rng[0] + 0.25 * (rng[1] - rng[0])
            ph, pl = eye_pose(machine, hi)[0][0], eye_pose(machine, lo)[0][0]
            q = hi if math.hypot(ph[0], ph[1]) >= math.hypot(pl[0], pl[1]) else lo
            break
    return q


def _frame(machine: Any, q_int: np.ndarray) -> np.ndarray:
    from engine.kinematics import eye_chain

    return eye_chain(machine, q_int[None, :])[0]


def _linear_dir(machine: Any, q_int: np.ndarray, k: int, h: float = 1.0) -> np.ndarray:
    """Unit motion direction of linear axis ``k`` (d eye / d q_k, central difference)."""
    a, b = q_int.copy(), q_int.copy()
    a[k] -= h
    b[k] += h
    d = _frame(machine, b)[:3, 3] - _frame(machine, a)[:3, 3]
    n = np.linalg.norm(d)
    return d / n if n > 1e-12 else np.zeros(3)


def _rotary_axis(machine: Any, q_int: np.ndarray, k: int, h: float = 1e-6) -> tuple[np.ndarray, np.ndarray]:
    """Rotation axis (unit) of rotary axis ``k`` and the point on it nearest the eye.

    From ``dR/dq R^T = [w]x`` and ``dp/dq = w x (p - c)``: ``c_perp = p + w x dp/dq`` (|w| = 1).
    """
    a, b = q_int.copy(), q_int.copy()
    a[k] -= h
    b[k] += h
    Ta, Tb, T0 = _frame(machine, a), _frame(machine, b), _frame(machine, q_int)
    W = (Tb[:3, :3] - Ta[:3, :3]) / (2 * h) @ T0[:3, :3].T
    w = np.array([W[2, 1] - W[1, 2], W[0, 2] - W[2, 0], W[1, 0] - W[0, 1]]) * 0.5
    n = np.linalg.norm(w)
    if n < 1e-9:
        return np.zeros(3), T0[:3, 3].copy()
    w /= n
    v = (Tb[:3, 3] - Ta[:3, 3]) / (2 * h) / n
    return w, T0[:3, 3] + np.cross(w, v)


def _screen_distance(p3: np.ndarray) -> float:
    """Distance of a point's projection from the projected mandrel axis, mm."""
    a = PROJECTION[:, 2] / np.linalg.norm(PROJECTION[:, 2])
    v = project(p3)
    return float(abs(v[0] * a[1] - v[1] * a[0]))


def _robot_links(machine: Any, q_int: np.ndarray) -> tuple[list[np.ndarray], list[np.ndarray], list[np.ndarray]]:
    """Robot link polyline and, per joint, its axis and origin: frames of the truncated chain.

    ``eye_chain`` of the template with the DH rows cut after joint k and no tool is the frame after
    joint k (standard DH: joint k+1 turns about that frame's z axis through its origin).
    """
    pts: list[np.ndarray] = []
    zs: list[np.ndarray] = []
    os_: list[np.ndarray] = []
    for k in range(len(machine.dh) + 1):
        F = _frame(replace(machine, dh=machine.dh[:k], tool=np.eye(4)), q_int)
        if k < len(machine.dh):
            zs.append(F[:3, 2].copy())
            os_.append(F[:3, 3].copy())
            pts.append(F[:3, 3].copy())
            d = machine.dh[k].d
            if d and machine.dh[k].a:          # the offset along z first, then the common normal
                pts.append(F[:3, 3] + d * F[:3, 2])
        else:
            pts.append(F[:3, 3].copy())        # the flange
    pts.append(_frame(machine, q_int)[:3, 3].copy())   # the eye
    return pts, zs, os_


def _range_text(ax: Any) -> str:
    if not _limited(ax.min, ax.max):
        return ax.name
    return f"{ax.name} {ax.min:g}…{ax.max:g} {ax.units}"


def build_schematic(machine: Any, part: tuple[float, float, float, tuple] | None = None) -> Schematic:
    """The schematic of ``machine`` (an :class:`engine.kinematics.MachineTemplate`).

    ``part``: ``(z_min, z_max, r_max, supports)`` of the job's mandrel (mm, mandrel frame = machine
    frame at mandrel angle 0) and its supports ``(name, z0, z1, radius)``: drawn instead of the nominal
    mandrel, where the set-up places them relative to the carriage travel."""
    q_int = neutral_pose(machine)
    T = _frame(machine, q_int)
    eye, eye_axis = T[:3, 3].copy(), T[:3, 2].copy()
    mi = machine.axis_index("mandrel")
    lin = [k for k, ax in enumerate(machine.axes) if ax.type == "linear"]
    origins: dict[int, np.ndarray] = {}
    ends: dict[int, np.ndarray | None] = {}
    dirs: dict[int, np.ndarray] = {}
    rot_centres: dict[int, tuple[np.ndarray, np.ndarray]] = {}
    links: list[np.ndarray]
    if machine.kind == "robot":
        links, zs, os_ = _robot_links(machine, q_int)
        base_track = links[0]
        for k in lin:      # the track carries the base: its locus is the base origin's
            dirs[k] = _linear_dir(machine, q_int, k)
            origins[k] = base_track
            rng = _ends_internal(machine.axes[k])
            ends[k] = (np.array([base_track + (r - q_int[k]) * dirs[k] for r in rng]) if rng else None)
        for j in range(len(machine.dh)):
            rot_centres[machine.axis_index(f"joint{j + 1}")] = (zs[j], os_[j])
    else:
        # staircase of slides in chain order: slide j is drawn with the later slides at the end of their
        # travel drawn farther from the mandrel axis (so the slides do not cross the mandrel)
        far = q_int.copy()
        for k in lin[1:]:
            rng = _internal_range(machine.axes[k])
            if rng is None:
                continue
            cand = []
            for r in (rng[1], rng[0]):
                qq = q_int.copy()
                qq[k] = r
                cand.append((_screen_distance(_frame(machine, qq)[:3, 3]), r))
            far[k] = max(cand, key=lambda c: c[0] + 1e-9 * (c[1] == rng[1]))[1]
        links = []
        for j, k in enumerate(lin):
            qq = q_int.copy()
            for kk in lin[j + 1:]:
                qq[kk] = far[kk]
            p = _frame(machine, qq)[:3, 3].copy()
            dirs[k] = _linear_dir(machine, qq, k)
            origins[k] = p
            rng = _ends_internal(machine.axes[k])
            ends[k] = np.array([p + (r - q_int[k]) * dirs[k] for r in rng]) if rng else None
            links.append(p)
        links.append(eye)
    # nominal mandrel: radius from the eye's distance to the axis, length from the travel along it
    r_eye = math.hypot(eye[0], eye[1])
    radius = float(np.clip(0.4 * r_eye, 40.0, 250.0))
    along = [k for k in lin if abs(dirs[k][2]) > 0.9 and ends[k] is not None]
    if along:
        span = float(np.ptp(ends[along[0]][:, 2]))
        half = 0.5 * min(max(0.55 * span, 4 * radius), 2000.0)
    else:
        half = 3.0 * radius
    zc = float(eye[2]) if machine.kind == "robot" else 0.0
    mandrel_z = (zc - half, zc + half)
    supports: tuple[tuple[str, float, float, float], ...] = ()
    if part is not None:
        mandrel_z, radius, supports = (float(part[0]), float(part[1])), float(part[2]), tuple(part[3])
    pts = [eye, *links, np.array([radius, radius, mandrel_z[0]]), np.array([-radius, -radius, mandrel_z[1]])]
    for e in ends.values():
        if e is not None:
            pts.extend(e)
    for _n, z0s, z1s, rs in supports:
        pts += [np.array([rs, rs, z0s]), np.array([-rs, -rs, z1s])]
    size = float(np.ptp(project(np.array(pts)), axis=0).max()) or 500.0
    # rotary axes: mandrel at the headstock; eye rotations through the eye; robot joints at their origins
    glyphs: list[AxisGlyph] = []
    used: list[np.ndarray] = []
    arm = float(np.ptp(project(np.array([*links, eye])), axis=0).max())
    r_small = min(0.045 * size, 0.07 * arm) if machine.kind == "robot" and arm > 0 else 0.045 * size
    for k, ax in enumerate(machine.axes):
        label = _range_text(ax)
        if ax.type == "linear":
            d = ax.sign * dirs[k]
            if ends[k] is None:
                e3 = None
                nominal = 0.15 * size
                o3 = origins[k]
                ends3 = np.array([o3 - nominal * d, o3 + nominal * d])
            else:
                e3 = ends3 = ends[k]
            o3 = origins[k]
            g2 = project(ends3[1]) - project(ends3[0])
            glyphs.append(AxisGlyph(ax.name, ax.role, ax.type, k, label, o3, d, e3, 0.0, project(o3),
                                    _unit2(g2), project(e3) if e3 is not None else None))
            continue
        if k == mi:
            w = np.array([0.0, 0.0, 1.0])             # p_W = Rz(theta) p_M: the spindle is the z axis
            c = np.array([0.0, 0.0, mandrel_z[0] - 0.12 * size])
            r = 1.25 * radius
        elif k in rot_centres:
            w, c = rot_centres[k]
            r = r_small
        else:
            w, c = _rotary_axis(machine, q_int, k)
            r = r_small
        c = c.copy()
        for u in used:                               # two axes through one point: shift along the axis
            if np.linalg.norm(u - c) < 1.1 * r_small:
                c = c + 2.1 * r_small * w
        if k != mi and np.linalg.norm(c - eye) < 1.1 * r_small:
            c = c + 2.1 * r_small * w
        used.append(c)
        w = ax.sign * w
        glyphs.append(AxisGlyph(ax.name, ax.role, ax.type, k, label, c, w, None, r, project(c),
                                _unit2(project(w)), None))
    return Schematic(machine, machine.to_controller(q_int), eye, eye_axis, np.array(links), tuple(glyphs),
                     radius, mandrel_z, size, supports)


def place_labels(anchors: list[tuple[float, float]], sizes: list[tuple[float, float]],
                 obstacles: list[tuple[float, float, float, float]], bounds: tuple[float, float],
                 gap: float = 2.0) -> list[tuple[float, float, float, float]]:
    """Rectangles ``(x, y, w, h)`` for labels of ``sizes`` near their ``anchors`` (px) that overlap
    neither each other nor ``obstacles`` and stay inside ``bounds`` (width, height).

    Each label tries the eight places around its anchor, then rings farther out (a leader line joins
    it to its anchor); the first place free of every rectangle placed so far wins.  Labels are placed
    in the given order, so the earlier ones stay closest to their points.  Only when no place in
    the widget is free (too many labels for the room) may a label overlap.
    """
    W, H = bounds
    placed: list[tuple[float, float, float, float]] = []
    fixed = [tuple(o) for o in obstacles]

    def free(r: tuple[float, float, float, float]) -> bool:
        x, y, w, h = r
        for ox, oy, ow, oh in (*fixed, *placed):
            if x < ox + ow + gap and ox < x + w + gap and y < oy + oh + gap and oy < y + h + gap:
                return False
        return True

    def clamp(x: float, y: float, w: float, h: float) -> tuple[float, float, float, float]:
        return (min(max(x, 1.0), max(W - w - 1.0, 1.0)), min(max(y, 1.0), max(H - h - 1.0, 1.0)), w, h)

    for (ax, ay), (w, h) in zip(anchors, sizes, strict=True):
        best = None
        for ring in range(0, 14):
            d = 4.0 + ring * 0.6 * h
            cands = [(ax + d, ay - h / 2), (ax - w - d, ay - h / 2), (ax - w / 2, ay - h - d), (ax - w / 2, ay + d),
                     (ax + d, ay - h - d / 2), (ax + d, ay + d / 2), (ax - w - d, ay - h - d / 2),
                     (ax - w - d, ay + d / 2)]
            for x, y in cands:
                r = clamp(x, y, w, h)
                if free(r):
                    best = r
                    break
            if best is not None:
                break
        if best is None:  # scan the widget for any free place, nearest first
            spots = [clamp(x, y, w, h) for y in np.arange(1.0, max(H - h, 2.0), h / 2)
                     for x in np.arange(1.0, max(W - w, 2.0), 8.0)]
            spots.sort(key=lambda r: (r[0] + r[2] / 2 - ax) ** 2 + (r[1] + r[3] / 2 - ay) ** 2)
            best = next((r for r in spots if free(r)), clamp(ax + 4.0, ay - h / 2, w, h))
        placed.append(best)
    return placed


def _unit2(v: np.ndarray) -> np.ndarray:
    n = float(np.linalg.norm(v))
    return v / n if n > 1e-9 else np.zeros(2)


def _hull(points: np.ndarray) -> np.ndarray:
    """Convex hull (monotone chain) of 2-D points, counter-clockwise."""
    pts = sorted(map(tuple, np.round(points, 9)))
    if len(pts) < 3:
        return np.array(pts)

    def cross(o: tuple, a: tuple, b: tuple) -> float:
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    lower: list[tuple] = []
    for p in pts:
        while len(lower) >= 2 and cross(lower[-2], lower[-1], p) <= 0:
            lower.pop()
        lower.append(p)
    upper: list[tuple] = []
    for p in reversed(pts):
        while len(upper) >= 2 and cross(upper[-2], upper[-1], p) <= 0:
            upper.pop()
        upper.append(p)
    return np.array(lower[:-1] + upper[:-1])


def _circle3(c: np.ndarray, w: np.ndarray, r: float, a0: float, a1: float, n: int = 48) -> np.ndarray:
    """Points of an arc of radius ``r`` about axis ``w`` through ``c`` from angle a0 to a1 (rad)."""
    ref = np.array([0.0, 1.0, 0.0]) if abs(w[1]) < 0.9 else np.array([0.0, 0.0, 1.0])
    e1 = np.cross(w, ref)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(w, e1)
    t = np.linspace(a0, a1, n)
    return c + r * (np.cos(t)[:, None] * e1 + np.sin(t)[:, None] * e2)
