"""Machine kinematics: templates, inverse and forward kinematics (MATH.md §A4, eq. (16)).

Frames (all lengths mm, angles rad inside the engine)
-----------------------------------------------------
*Mandrel frame* M: fixed to the mandrel, its z axis is the mandrel's rotation axis.  The payout stage
gives the eye path, the contact point and the free-fibre direction in this frame.

*Machine frame* W: fixed to the machine bed.  Its z axis coincides with the mandrel axis, x is
horizontal (towards the eye side, the cross-feed direction), y is vertical (up).

The two sides of eq. (16) are products of 4x4 homogeneous transforms:

* mandrel chain:  ``p_W = Rz(theta) p_M`` (theta = mandrel angle, internal units rad);
* eye chain:      ``T_W,eye = E_1(q_1) E_2(q_2) ... E_n(q_n)`` - translations along / rotations about
  fixed unit vectors (cartesian winders) or a linear track, a base transform and Denavit-Hartenberg
  joints (robot cells), followed by a fixed tool transform.

The *eye frame*'s z axis is the **eye axis**; when the machine can orient the eye, it is aligned with
the fibre direction (from the contact point to the eye).  The robot's eye-frame x axis is the band's
width direction ``w = normalise(fibre x n)`` with ``n`` the radial direction at the contact point
(the band normal of a cylinder; an approximation on doubly curved parts).

What forward kinematics reproduces (``MachineTemplate.fibre_mode``)
-------------------------------------------------------------------
* ``"line"`` (2- and 3-axis winders, no eye rotation): the eye is a ring; the fibre direction is the
  direction from the contact point on the rotated mandrel to the eye,
  ``normalise(FK_eye(q) - contact)``; :func:`forward_kinematics` returns it when ``contact_xyz`` is
  given.
* ``"projected"`` (4-axis, eye roll about the cross-feed axis): the eye axis equals the fibre
  direction projected onto the plane normal to the roll axis, normalised.
* ``"full"`` (6-axis gantry, robot cell): the eye axis equals the fibre direction.

A machine whose eye cannot leave a fixed radius (2-axis lathe winder) reproduces the *fibre line*:
the eye is slid along the free fibre to the machine's eye radius (``AxisPath.eye_shift``, mm); the
laid line is unchanged, and ``AxisPath.eye_xyz`` is the eye position the machine actually realises.

Controller values
-----------------
``q_controller = sign * scale(units) * q_internal + offset`` with internal units rad / mm, e.g. a
mandrel axis in degrees with ``sign = -1`` counts up while the mandrel winds (the mandrel angle is
``theta = psi_eye - V``, decreasing as the twist angle V grows).
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from engine.errors import InfeasibleError, InputError
from engine.resources import file_stamp, find_named, list_named, read_toml
from engine.state import State, check_cancel

MACHINES_DIR = Path(__file__).resolve().parents[1] / "resources" / "machines"

ROLES_CARTESIAN = ("mandrel", "carriage", "cross", "vertical", "yaw", "roll")
ROLES_ROBOT = ("mandrel", "track", "joint1", "joint2", "joint3", "joint4", "joint5", "joint6")
UNIT_SCALE = {"deg": 180.0 / math.pi, "rad": 1.0, "rev": 1.0 / (2.0 * math.pi), "mm": 1.0,
              "inch": 1.0 / 25.4, "m": 1e-3}
ROTARY_UNITS = ("deg", "rad", "rev")
LINEAR_UNITS = ("mm", "inch", "m")


# --------------------------------------------------------------------------------------------------
# Violations
# --------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Violation:
    """One limit violation, located.

    Attributes
    ----------
    kind:
        ``"position"``, ``"speed"``, ``"jump"``, ``"workspace"``, ``"singular"``, ``"reverse"`` or
        ``"ik"`` (numerical inverse kinematics did not converge).
    axis:
        Controller axis name, or ``None`` for whole-machine problems.
    index:
        First path point of the run of offending points (``None`` when the violation is per block).
    block:
        First offending block (``None`` when per path point).
    count:
        Number of consecutive offending points/blocks in this run.
    amount:
        Worst excess over the limit in the run, controller units (``value - limit``, signed).
    value, limit:
        The worst value and the limit it exceeds.
    """

    kind: str
    axis: str | None
    amount: float
    value: float
    limit: float
    index: int | None = None
    block: int | None = None
    count: int = 1
    message: str = ""

    def __str__(self) -> str:
        return self.message or f"{self.kind} violation on {self.axis}: {self.amount:g}"


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """Contiguous runs of True in a 1-D mask as (start, stop) pairs."""
    m = np.asarray(mask, dtype=bool)
    if not m.any():
        return []
    d = np.diff(np.concatenate(([0], m.view(np.int8), [0])))
    starts = np.flatnonzero(d == 1)
    stops = np.flatnonzero(d == -1)
    return list(zip(starts.tolist(), stops.tolist()))


def violations_from_mask(kind: str, axis: str | None, mask: np.ndarray, value: np.ndarray,
                         limit: np.ndarray | float, unit: str = "", where: str = "point",
                         what: str = "") -> list[Violation]:
    """Group a per-point (or per-block) violation mask into located :class:`Violation` runs."""
    out: list[Violation] = []
    value = np.asarray(value, dtype=float)
    lim = np.broadcast_to(np.asarray(limit, dtype=float), value.shape)
    for a, b in _runs(mask):
        seg = value[a:b] - lim[a:b]
        k = a + int(np.argmax(np.abs(seg)))
        amount = float(value[k] - lim[k])
        label = f"axis {axis}" if axis else "machine"
        desc = what or kind
        msg = (f"{label}: {desc} {value[k]:.6g}{unit} exceeds the limit {lim[k]:.6g}{unit} by "
               f"{abs(amount):.6g}{unit} at {where} {k} ({b - a} {where}s from {where} {a})")
        kw: dict[str, Any] = {"index": a} if where == "point" else {"block": a}
        out.append(Violation(kind, axis, amount, float(value[k]), float(lim[k]), count=b - a,
                             message=msg, **kw))
    return out


# --------------------------------------------------------------------------------------------------
# Machine templates
# --------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Axis:
    """One controlled coordinate of a machine, bound to an element of the kinematic scheme.

    Attributes
    ----------
    name: controller's axis name (letter), e.g. ``"A"``.
    role: element of the scheme (``mandrel``, ``carriage``, ``cross``, ``vertical``, ``yaw``,
        ``roll``, ``track``, ``joint1`` .. ``joint6``).
    type: ``"rotary"`` or ``"linear"``.
    sign: +1 or -1.
    units: ``deg``/``rad``/``rev`` (rotary) or ``mm``/``inch``/``m`` (linear).
    offset: controller value at the internal zero (datum), controller units.
    min, max: position limits, controller units.
    max_speed: controller units/s.  max_accel: units/s^2.  max_jump: allowed speed jump between
        neighbouring NC blocks, units/s.
    """

    name: str
    role: str
    type: str
    sign: float
    units: str
    offset: float
    min: float
    max: float
    max_speed: float
    max_accel: float
    max_jump: float

    @property
    def scale(self) -> float:
        """Controller units per internal unit (rad or mm), including the sign."""
        return self.sign * UNIT_SCALE[self.units]


@dataclass(frozen=True)
class DH:
    """Standard Denavit-Hartenberg row: ``Rz(theta + theta0) Tz(d) Tx(a) Rx(alpha)`` (mm, rad)."""

    a: float
    alpha: float
    d: float
    theta0: float


@dataclass(frozen=True)
class MachineTemplate:
    """A real machine bound to the generalised kinematic scheme (16).

    Attributes
    ----------
    name, title: identifier (file stem) and a human title.
    kind: ``"cartesian"`` (lathe-type winders) or ``"robot"`` (6R arm on a linear track).
    axes: the controlled coordinates in program order.
    fibre_mode: ``"line"``, ``"projected"`` or ``"full"`` (see module docstring).
    mandrel_phase: ``"eye"`` - the eye stays at machine azimuth ``phase`` (rad);
        ``"contact"`` - the contact point stays at machine azimuth ``phase``.
    eye_radius: fixed eye distance from the mandrel axis when there is no cross-feed axis, mm.
    min_block_time: tau of eq. (17), s.
    base: robot base transform (4x4, machine frame, at track position 0).
    dh: robot DH rows.  tool: fixed flange-to-eye transform (4x4).  home: robot joint seed, rad.
    band_symmetric: the eye slot is symmetric, so the eye x axis may be +w or -w (the solver takes
        the face whose first pose is nearer ``home`` and keeps it continuous along the path).
    source: file the template was read from.
    """

    name: str
    title: str
    kind: str
    axes: tuple[Axis, ...]
    fibre_mode: str
    mandrel_phase: str = "eye"
    phase: float = 0.0
    eye_radius: float | None = None
    min_block_time: float = 0.002
    base: np.ndarray | None = None
    dh: tuple[DH, ...] = ()
    tool: np.ndarray | None = None
    home: tuple[float, ...] = ()
    band_symmetric: bool = True
    source: str = ""

    @property
    def axis_names(self) -> tuple[str, ...]:
        return tuple(a.name for a in self.axes)

    @property
    def roles(self) -> tuple[str, ...]:
        return tuple(a.role for a in self.axes)

    def axis_index(self, role: str) -> int | None:
        """Index of the axis bound to ``role``, or ``None``."""
        for i, a in enumerate(self.axes):
            if a.role == role:
                return i
        return None

    def limits(self, what: str) -> np.ndarray:
        """Per-axis array of ``min``/``max``/``max_speed``/``max_accel``/``max_jump``."""
        return np.array([getattr(a, what) for a in self.axes], dtype=float)

    @property
    def scales(self) -> np.ndarray:
        return np.array([a.scale for a in self.axes], dtype=float)

    @property
    def offsets(self) -> np.ndarray:
        return np.array([a.offset for a in self.axes], dtype=float)

    def to_internal(self, q: np.ndarray) -> np.ndarray:
        """Controller values -> internal values (rad, mm)."""
        q = np.asarray(q, dtype=float)
        if q.ndim == 2 and q.shape[0] > _BY_COLUMN:
            return _by_column(q, self.offsets, self.scales, internal=True)
        return (q - self.offsets) / self.scales

    def to_controller(self, q_int: np.ndarray) -> np.ndarray:
        """Internal values (rad, mm) -> controller values."""
        q_int = np.asarray(q_int, dtype=float)
        if q_int.ndim == 2 and q_int.shape[0] > _BY_COLUMN:
            return _by_column(q_int, self.offsets, self.scales, internal=False)
        return q_int * self.scales + self.offsets


_BY_COLUMN = 64
"""Rows from which :meth:`MachineTemplate.to_internal` / ``to_controller`` work column by column: numpy
broadcasting a row of a few axes over many rows runs its inner loop a few elements at a time (about
five times slower); the same elementwise operations, so the same bits."""


def _by_column(q: np.ndarray, offsets: np.ndarray, scales: np.ndarray, internal: bool) -> np.ndarray:
    """``(q - offsets) / scales`` (``internal``) or ``q * scales + offsets``, one column at a time."""
    if q.shape[1] != offsets.size:            # let numpy raise its broadcasting error
        return (q - offsets) / scales if internal else q * scales + offsets
    out = np.empty(q.shape)
    for k in range(q.shape[1]):
        col = out[:, k]
        if internal:
            np.subtract(q[:, k], offsets[k], out=col)
            col /= scales[k]
        else:
            np.multiply(q[:, k], scales[k], out=col)
            col += offsets[k]
    return out


def list_machines(directory: str | Path | None = None) -> list[str]:
    """Names of the shipped (or ``directory``'s) machine templates, sorted."""
    return list_named(Path(directory) if directory is not None else MACHINES_DIR)


def _need(data: dict, key: str, typ: type | tuple[type, ...], file: str, prefix: str = "") -> Any:
    if key not in data:
        raise InputError(f"missing required field '{prefix}{key}'", file=file, field=prefix + key)
    val = data[key]
    if isinstance(val, bool) or not isinstance(val, typ):
        tn = typ.__name__ if isinstance(typ, type) else "/".join(t.__name__ for t in typ)
        raise InputError(f"'{prefix}{key}' must be {tn}, got {val!r}", file=file, field=prefix + key)
    return val


def _num(data: dict, key: str, file: str, prefix: str = "", default: float | None = None,
         positive: bool = False) -> float:
    if key not in data and default is not None:
        return float(default)
    v = float(_need(data, key, (int, float), file, prefix))
    if not math.isfinite(v):
        raise InputError(f"'{prefix}{key}' must be finite, got {v!r}", file=file, field=prefix + key)
    if positive and v <= 0:
        raise InputError(f"'{prefix}{key}' must be > 0, got {v!r}", file=file, field=prefix + key)
    return v


def _mat(val: Any, file: str, fld: str) -> np.ndarray:
    """A 4x4 transform from ``{xyz=[..], rpy_deg=[..]}`` (rotation Rz(yaw) Ry(pitch) Rx(roll))."""
    if not isinstance(val, dict):
        raise InputError(f"'{fld}' must be a table with xyz and rpy_deg", file=file, field=fld)
    xyz = val.get("xyz", [0.0, 0.0, 0.0])
    rpy = val.get("rpy_deg", [0.0, 0.0, 0.0])
    for nm, v in (("xyz", xyz), ("rpy_deg", rpy)):
        if (not isinstance(v, list) or len(v) != 3
                or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v)):
            raise InputError(f"'{fld}.{nm}' must be a list of 3 numbers, got {v!r}", file=file,
                             field=f"{fld}.{nm}")
    r, p, y = np.radians(np.asarray(rpy, dtype=float))
    T = np.eye(4)
    T[:3, :3] = _rot("z", y) @ _rot("y", p) @ _rot("x", r)
    T[:3, 3] = xyz
    return T


def _rot(ax: str, a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    if ax == "x":
        return np.array([[1, 0, 0], [0, c, -s], [0, s, c]], dtype=float)
    if ax == "y":
        return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]], dtype=float)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]], dtype=float)


def parse_machine(data: dict, file: str = "<machine>", name: str | None = None) -> MachineTemplate:
    """Validate a machine template table (as read from TOML); raise :class:`InputError` naming the field."""
    kind = _need(data, "kind", str, file)
    if kind not in ("cartesian", "robot"):
        raise InputError(f"'kind' must be 'cartesian' or 'robot', got {kind!r}", file=file, field="kind")
    title = str(data.get("title", name or Path(file).stem))
    raw_axes = _need(data, "axes", list, file)
    if not raw_axes:
        raise InputError("'axes' must list at least the mandrel axis", file=file, field="axes")
    allowed = ROLES_CARTESIAN if kind == "cartesian" else ROLES_ROBOT
    axes: list[Axis] = []
    for i, ax in enumerate(raw_axes):
        pre = f"axes[{i}]."
        if not isinstance(ax, dict):
            raise InputError(f"'axes[{i}]' must be a table", file=file, field=f"axes[{i}]")
        nm = _need(ax, "name", str, file, pre)
        if not nm or not nm.replace("_", "").isalnum():
            raise InputError(f"axis name must be letters/digits, got {nm!r}", file=file, field=pre + "name")
        role = _need(ax, "role", str, file, pre)
        if role not in allowed:
            raise InputError(f"role {role!r} is not one of {', '.join(allowed)} for a {kind} machine",
                             file=file, field=pre + "role")
        typ = _need(ax, "type", str, file, pre)
        want = "linear" if role in ("carriage", "cross", "vertical", "track") else "rotary"
        if typ != want:
            raise InputError(f"role {role!r} needs type '{want}', got {typ!r}", file=file, field=pre + "type")
        units = _need(ax, "units", str, file, pre)
        ok_units = ROTARY_UNITS if typ == "rotary" else LINEAR_UNITS
        if units not in ok_units:
            raise InputError(f"units {units!r} not allowed for a {typ} axis (use {', '.join(ok_units)})",
                             file=file, field=pre + "units")
        sign = _num(ax, "sign", file, pre, default=1.0)
        if sign not in (1.0, -1.0):
            raise InputError(f"'sign' must be 1 or -1, got {sign!r}", file=file, field=pre + "sign")
        lo = _num(ax, "min", file, pre, default=-1e12)
        hi = _num(ax, "max", file, pre, default=1e12)
        if lo >= hi:
            raise InputError(f"'min' ({lo}) must be below 'max' ({hi})", file=file, field=pre + "min")
        axes.append(Axis(
            name=nm, role=role, type=typ, sign=sign, units=units,
            offset=_num(ax, "offset", file, pre, default=0.0), min=lo, max=hi,
            max_speed=_num(ax, "max_speed", file, pre, positive=True),
            max_accel=_num(ax, "max_accel", file, pre, positive=True),
            max_jump=_num(ax, "max_jump", file, pre, positive=True)))
    names = [a.name for a in axes]
    roles = [a.role for a in axes]
    for lst, what in ((names, "name"), (roles, "role")):
        dup = sorted({x for x in lst if lst.count(x) > 1})
        if dup:
            raise InputError(f"duplicate axis {what} {dup[0]!r}", file=file, field="axes")
    if "mandrel" not in roles:
        raise InputError("no axis has role 'mandrel'", file=file, field="axes")
    phase_mode = data.get("mandrel_phase", "eye")
    if phase_mode not in ("eye", "contact"):
        raise InputError(f"'mandrel_phase' must be 'eye' or 'contact', got {phase_mode!r}", file=file,
                         field="mandrel_phase")
    phase = math.radians(_num(data, "phase_deg", file, default=0.0))
    tau = _num(data, "min_block_time", file, default=0.002, positive=True)
    kw: dict[str, Any] = {}
    if kind == "cartesian":
        if "carriage" not in roles:
            raise InputError("a cartesian winder needs an axis with role 'carriage'", file=file, field="axes")
        if "vertical" not in roles and (phase_mode != "eye" or phase != 0.0):
            raise InputError("without a 'vertical' axis the eye stays in the y = 0 plane: use "
                             "mandrel_phase = 'eye' and phase_deg = 0", file=file, field="mandrel_phase")
        if "cross" not in roles:
            kw["eye_radius"] = _num(data, "eye_radius", file, positive=True)
        if "yaw" in roles and "roll" not in roles:
            raise InputError("an eye 'yaw' axis needs a 'roll' axis too", file=file, field="axes")
        fibre_mode = "full" if "yaw" in roles else ("projected" if "roll" in roles else "line")
        if "yaw" in roles and "vertical" not in roles:
            raise InputError("an eye 'yaw' axis needs a 'vertical' axis (6-axis layout)", file=file,
                             field="axes")
    else:
        missing = [r for r in ROLES_ROBOT if r not in roles]
        if missing:
            raise InputError(f"a robot cell needs axes with roles {', '.join(missing)}", file=file,
                             field="axes")
        robot = _need(data, "robot", dict, file)
        dh_rows = _need(robot, "dh", list, file, "robot.")
        if len(dh_rows) != 6:
            raise InputError(f"'robot.dh' must have 6 rows, got {len(dh_rows)}", file=file, field="robot.dh")
        dh = []
        for i, row in enumerate(dh_rows):
            pre = f"robot.dh[{i}]."
            if not isinstance(row, dict):
                raise InputError(f"'robot.dh[{i}]' must be a table", file=file, field=f"robot.dh[{i}]")
            dh.append(DH(a=_num(row, "a", file, pre), alpha=math.radians(_num(row, "alpha_deg", file, pre)),
                         d=_num(row, "d", file, pre),
                         theta0=math.radians(_num(row, "theta0_deg", file, pre, default=0.0))))
        home = _need(robot, "home_deg", list, file, "robot.")
        if len(home) != 6 or not all(isinstance(h, (int, float)) for h in home):
            raise InputError(f"'robot.home_deg' must be 6 numbers, got {home!r}", file=file,
                             field="robot.home_deg")
        sym = robot.get("band_symmetric", True)
        if not isinstance(sym, bool):
            raise InputError(f"'robot.band_symmetric' must be true or false, got {sym!r}", file=file,
                             field="robot.band_symmetric")
        kw.update(band_symmetric=sym,
                  base=_mat(_need(robot, "base", dict, file, "robot."), file, "robot.base"),
                  tool=_mat(_need(robot, "tool", dict, file, "robot."), file, "robot.tool"),
                  dh=tuple(dh), home=tuple(math.radians(h) for h in home))
        fibre_mode = "full"
    return MachineTemplate(name=name or Path(file).stem, title=title, kind=kind, axes=tuple(axes),
                           fibre_mode=fibre_mode, mandrel_phase=phase_mode, phase=phase,
                           min_block_time=tau, source=str(file), **kw)


def load_machine(name_or_path: str | Path) -> MachineTemplate:
    """Load a machine template by shipped name (``"lathe2"``) or by path to a ``.toml`` file.

    Raises
    ------
    InputError
        Unknown name, unreadable file, bad TOML or an invalid field (the message names file and field).
    """
    p = find_named(MACHINES_DIR, name_or_path, "machine", "machine")
    fs = file_stamp(p)  # None: read_toml says what is wrong with it
    key, stamp = fs if fs is not None else ("", None)
    with _MACHINE_LOCK:
        hit = _MACHINES.get(key) if stamp is not None else None
    if hit is not None and hit[0] == stamp:
        return hit[1]
    data = read_toml(p, "machine template file")
    machine = parse_machine(data, file=str(p), name=p.stem)
    for arr in (machine.base, machine.tool):
        if arr is not None:
            arr.flags.writeable = False
    if stamp is not None:
        with _MACHINE_LOCK:
            _MACHINES[key] = (stamp, machine)
    return machine


_MACHINES: dict[str, tuple[tuple[int, int], MachineTemplate]] = {}
"""Templates read so far by file (with the file's modification time and size: a changed file is read
again).  A template is immutable (frozen, its arrays read-only), so every caller gets the same object: a
run loads its machine ~9 times (stages, checks, the laminate's layers), ~4 ms each."""
_MACHINE_LOCK = threading.Lock()


# --------------------------------------------------------------------------------------------------
# Homogeneous transforms (vectorised)
# --------------------------------------------------------------------------------------------------
def _rot_batch(axis: str, ang: np.ndarray) -> np.ndarray:
    """(N,4,4) rotations about a coordinate axis."""
    n = ang.shape[0]
    T = np.zeros((n, 4, 4))
    c, s = np.cos(ang), np.sin(ang)
    i, j = {"x": (1, 2), "y": (2, 0), "z": (0, 1)}[axis]
    k = 3 - i - j
    T[:, k, k] = 1.0
    T[:, i, i] = c
    T[:, j, j] = c
    T[:, i, j] = -s
    T[:, j, i] = s
    T[:, 3, 3] = 1.0
    return T


def _trans_batch(axis: str, d: np.ndarray) -> np.ndarray:
    n = d.shape[0]
    T = np.broadcast_to(np.eye(4), (n, 4, 4)).copy()
    T[:, "xyz".index(axis), 3] = d
    return T


def _dh_fixed(row: DH) -> np.ndarray:
    """The fixed part ``Tz(d) Tx(a) Rx(alpha)`` of a DH row."""
    T = np.eye(4)
    T[:3, :3] = _rot("x", row.alpha)
    T[0, 3] = row.a
    T[2, 3] = row.d
    return T


def eye_chain(machine: MachineTemplate, q_int: np.ndarray) -> np.ndarray:
    """Eye frame in the machine frame, ``(N,4,4)``: right-hand side of eq. (16).

    ``q_int``: (N, n_axes) internal values (rad, mm).  The mandrel column is ignored.
    """
    q_int = np.atleast_2d(np.asarray(q_int, dtype=float))
    n = q_int.shape[0]
    T = np.broadcast_to(np.eye(4), (n, 4, 4)).copy()
    if machine.kind == "cartesian":
        col = {r: machine.axis_index(r) for r in ROLES_CARTESIAN}
        x = q_int[:, col["cross"]] if col["cross"] is not None else np.full(n, machine.eye_radius)
        y = q_int[:, col["vertical"]] if col["vertical"] is not None else np.zeros(n)
        T[:, 0, 3], T[:, 1, 3], T[:, 2, 3] = x, y, q_int[:, col["carriage"]]
        if col["yaw"] is not None:
            T = T @ _rot_batch("y", q_int[:, col["yaw"]])
        if col["roll"] is not None:
            T = T @ _rot_batch("x", q_int[:, col["roll"]])
        return T
    T = _trans_batch("z", q_int[:, machine.axis_index("track")]) @ machine.base
    for k, row in enumerate(machine.dh):
        T = T @ _rot_batch("z", q_int[:, machine.axis_index(f"joint{k + 1}")] + row.theta0) @ _dh_fixed(row)
    return T @ machine.tool


def forward_kinematics(machine: MachineTemplate, q: np.ndarray, contact_xyz: np.ndarray | None = None,
                       fibre: bool = True) -> tuple[np.ndarray, np.ndarray | None]:
    """Eye position and fibre direction in the mandrel frame from controller axis values.

    Parameters
    ----------
    machine: the template.
    q: (N, n_axes) controller values.
    contact_xyz: (N,3) contact points in the mandrel frame, mm; needed for ``fibre_mode == "line"``.

    Returns
    -------
    eye_xyz: (N,3) mm, mandrel frame.
    fibre_dir: (N,3) unit vectors, mandrel frame: the eye axis (``"projected"``/``"full"``) or
        ``normalise(eye - contact)`` (``"line"``; NaN when ``contact_xyz`` is None); ``None`` when
        ``fibre`` is False (the eye position only: what the block tolerance checks need, cheaper).
    """
    q_int = machine.to_internal(np.atleast_2d(q))
    pw, zw = eye_pose(machine, q_int, axis=fibre)
    theta = q_int[:, machine.axis_index("mandrel")]
    c, s = np.cos(theta), np.sin(theta)

    def to_m(v: np.ndarray) -> np.ndarray:   # p_M = Rz(-theta) p_W
        out = np.empty(v.shape)
        np.multiply(c, v[:, 0], out=out[:, 0])
        out[:, 0] += s * v[:, 1]
        np.multiply(c, v[:, 1], out=out[:, 1])
        out[:, 1] -= s * v[:, 0]
        out[:, 2] = v[:, 2]
        return out

    eye = to_m(pw)
    if not fibre:
        return eye, None
    if machine.fibre_mode == "line":
        if contact_xyz is None:
            return eye, np.full_like(eye, np.nan)
        d = eye - np.asarray(contact_xyz, dtype=float)
        return eye, d / np.linalg.norm(d, axis=1, keepdims=True)
    return eye, to_m(zw)


def eye_pose(machine: MachineTemplate, q_int: np.ndarray, axis: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Fast form of :func:`eye_chain`: eye position (N,3) and eye axis (N,3), machine frame.

    Same products as the 4x4 chain, written out column by column (tests compare the two).  With
    ``axis=False`` a Cartesian machine's eye axis is not computed (returned as zeros).
    """
    q_int = np.atleast_2d(np.asarray(q_int, dtype=float))
    n = q_int.shape[0]
    if machine.kind == "cartesian":
        col = {r: machine.axis_index(r) for r in ROLES_CARTESIAN}
        p = np.empty((n, 3))
        p[:, 0] = q_int[:, col["cross"]] if col["cross"] is not None else machine.eye_radius
        p[:, 1] = q_int[:, col["vertical"]] if col["vertical"] is not None else 0.0
        p[:, 2] = q_int[:, col["carriage"]]
        z = np.zeros((n, 3))
        if not axis:
            return p, z
        z[:, 2] = 1.0
        if col["roll"] is not None:
            r = q_int[:, col["roll"]]
            z[:, 1], z[:, 2] = -np.sin(r), np.cos(r)
        if col["yaw"] is not None:
            g = q_int[:, col["yaw"]]
            cg, sg = np.cos(g), np.sin(g)
            z[:, 0], z[:, 2] = sg * z[:, 2], cg * z[:, 2]
        return p, z
    track = q_int[:, machine.axis_index("track")]
    joints = q_int[:, [machine.axis_index(f"joint{k + 1}") for k in range(6)]]
    p, z = np.empty((n, 3)), np.empty((n, 3))
    for c0 in range(0, n, _CHUNK):            # chunks keep the temporaries in cache
        sl = slice(c0, min(n, c0 + _CHUNK))
        R, p[sl], _, _ = _robot_chain(machine, track[sl], joints[sl])
        z[sl] = R[:, :, 2]
    return p, z


def _robot_chain(machine: MachineTemplate, track: np.ndarray, j: np.ndarray, want_axes: bool = False
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray | None]:
    """Eye rotation (N,3,3), eye position (N,3) and optionally joint axes/origins (N,6,3), machine frame.

    DH step ``R <- R Rz(theta) Rx(alpha)``, ``p <- p + R Rz(theta) (a, 0, d)`` written on columns
    (component-major arrays of shape (3, N) for speed).
    """
    n = j.shape[0]
    Rb, pb = machine.base[:3, :3], machine.base[:3, 3]
    r0 = np.repeat(Rb[:, 0:1], n, axis=1)
    r1 = np.repeat(Rb[:, 1:2], n, axis=1)
    r2 = np.repeat(Rb[:, 2:3], n, axis=1)
    p = np.repeat(pb[:, None], n, axis=1)
    p[2] += track
    zs = np.empty((n, 6, 3)) if want_axes else None
    os_ = np.empty((n, 6, 3)) if want_axes else None
    jt = np.ascontiguousarray(j.T)
    for k, row in enumerate(machine.dh):
        if want_axes:
            zs[:, k] = r2.T
            os_[:, k] = p.T
        th = jt[k] + row.theta0
        ct, st = np.cos(th), np.sin(th)
        ca, sa = math.cos(row.alpha), math.sin(row.alpha)
        n0 = ct * r0 + st * r1
        m1 = ct * r1 - st * r0
        p = p + row.a * n0 + row.d * r2 if row.a or row.d else p
        r0, r1, r2 = n0, ca * m1 + sa * r2, ca * r2 - sa * m1
    Rt, pt = machine.tool[:3, :3], machine.tool[:3, 3]
    cols = [Rt[0, c] * r0 + Rt[1, c] * r1 + Rt[2, c] * r2 for c in range(3)]
    pe = p + pt[0] * r0 + pt[1] * r1 + pt[2] * r2
    R = np.stack([c.T for c in cols], axis=2)
    return R, np.ascontiguousarray(pe.T), zs, os_


# --------------------------------------------------------------------------------------------------
# Inverse kinematics
# --------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class AxisPath:
    """Machine axis positions along the path.

    Attributes
    ----------
    machine: template name.
    axis_names: controller axis names, column order of ``q``.
    q: (N, n_axes) controller units.
    eye_xyz: (N,3) the eye positions the machine realises, mandrel frame, mm (the input eye path, or
        it slid along the fibre line for a fixed-radius eye).
    fibre_dir, contact_xyz: (N,3) the inputs (mandrel frame).
    eye_shift: (N,) how far the eye was slid along the fibre, mm (0 when the machine reaches it).
    violations: located limit/workspace violations (empty when the path is feasible).
    x: (N,) the payout stage's process parameter, passed through (None when not given).
    circuits: ``(circuits, points_per_circuit)`` when the path is circuit 0, then circuit 1 repeated
        with only the mandrel axis advanced by a constant per circuit (built so by
        :func:`engine.periodic.replicate_axes`; the later stages use it); None otherwise.
    """

    machine: str
    axis_names: tuple[str, ...]
    q: np.ndarray
    eye_xyz: np.ndarray
    fibre_dir: np.ndarray
    contact_xyz: np.ndarray
    eye_shift: np.ndarray
    violations: tuple[Violation, ...] = field(default_factory=tuple)
    x: np.ndarray | None = None
    circuits: tuple[int, int] | None = None

    @property
    def ok(self) -> bool:
        return not self.violations

    def message(self) -> str:
        """All violations, one per line (empty when none)."""
        return "\n".join(v.message for v in self.violations)


AXIS_PATH_FIELDS: tuple[str, ...] = ("q", "eye_xyz", "fibre_dir", "contact_xyz", "eye_shift", "x")
"""Per-point fields of :class:`AxisPath`; a replicated program's path may keep its eye path's arrays as
circuit 0 + rule (:class:`engine.periodic.CircuitArray`), materialised on first read."""


def _install_axis_fields() -> None:
    from engine.periodic import install_deferred_fields

    install_deferred_fields(AxisPath, AXIS_PATH_FIELDS)


_install_axis_fields()


def _as_path(a: np.ndarray, name: str) -> np.ndarray:
    arr = np.asarray(a, dtype=float)
    if arr.ndim != 2 or arr.shape[1] != 3 or arr.shape[0] < 2:
        raise InputError(f"{name} must be an (N,3) array with N >= 2, got shape {arr.shape}", field=name)
    if not np.isfinite(arr).all():
        i = int(np.flatnonzero(~np.isfinite(arr).all(axis=1))[0])
        raise InputError(f"{name} has a non-finite value at point {i}", field=name)
    return arr


def unwrap_angles(p: np.ndarray) -> np.ndarray:
    """``numpy.unwrap(p)`` of a 1-D float array (rad), bit for bit, in fewer passes over the data.

    ``numpy.unwrap`` computes the correction ``mod(dd + π, 2π) - π - dd`` of every step ``dd`` and
    zeroes it where ``|dd| < π``; here it is computed at the steps ``|dd| >= π`` only (the same
    arithmetic), and the running sum of those few corrections (sequential, as ``cumsum``) is added to
    the points after each one.  Anything but a 1-D float64 array goes to ``numpy.unwrap``.
    """
    p = np.asarray(p)
    if p.ndim != 1 or p.dtype != np.float64 or p.size < 2:
        return np.unwrap(p)
    dd = np.diff(p)
    big = np.flatnonzero(~(np.abs(dd) < np.pi))
    up = p.copy()
    if big.size == 0:
        return up
    d = dd[big]
    ddmod = np.mod(d + np.pi, 2.0 * np.pi) - np.pi
    np.copyto(ddmod, np.pi, where=(ddmod == -np.pi) & (d > 0))
    corr = np.cumsum(ddmod - d)
    if big.size <= 20_000:
        # the points after the k-th wrap get corr[k] added, slice by slice (numpy's repeat would hold
        # the GIL for the whole array: 0.1 s on a 6 M point program, a stalled GUI thread)
        ends = np.append(big[1:], dd.size) + 1
        for a, b, c in zip((big + 1).tolist(), ends.tolist(), corr.tolist(), strict=True):
            up[a:b] += c
        return up
    lengths = np.diff(np.concatenate(([0], big, [dd.size])))
    up[1:] += np.repeat(np.concatenate(([0.0], corr)), lengths)
    return up


def _unwrap_near(a: np.ndarray, ref: float = 0.0) -> np.ndarray:
    """Unwrap angles and shift by a multiple of 2 pi so the first one is nearest ``ref``."""
    u = unwrap_angles(a)
    return u - 2 * np.pi * np.round((u[0] - ref) / (2 * np.pi))


def inverse_kinematics(machine: MachineTemplate, eye_xyz: np.ndarray, fibre_dir: np.ndarray,
                       contact_xyz: np.ndarray, state: State | None = None,
                       x: np.ndarray | None = None) -> AxisPath:
    """Axis positions that put the eye on the path with the eye axis along the fibre.

    Closed form for cartesian winders; warm-started, vectorised Newton for robot cells.  Angles are
    unwrapped and follow one continuous branch.  Position limits, workspace, singular points and
    reverse mandrel rotation are reported as :class:`Violation` objects (never raised).

    Parameters
    ----------
    machine: the template.
    eye_xyz, fibre_dir, contact_xyz: (N,3) in the mandrel frame (mm; unit vectors from the contact
        point to the eye).
    state: progress / cancellation.
    x: (N,) process parameter of the payout stage, kept in the result for plots (optional).

    Returns
    -------
    AxisPath
    """
    eye = _as_path(eye_xyz, "eye_xyz")
    d = _as_path(fibre_dir, "fibre_dir")
    c = _as_path(contact_xyz, "contact_xyz")
    if not (eye.shape == d.shape == c.shape):
        raise InputError(f"eye_xyz, fibre_dir, contact_xyz differ in shape: {eye.shape}, {d.shape}, "
                         f"{c.shape}", field="eye_xyz")
    nrm = np.sqrt(row_sums(d * d))                # numpy.linalg.norm(d, axis=1), bit for bit
    if np.any(np.abs(nrm - 1.0) > 1e-6):
        i = int(np.argmax(np.abs(nrm - 1.0)))
        raise InputError(f"fibre_dir must be unit vectors; |fibre_dir| = {nrm[i]:.9g} at point {i}",
                         field="fibre_dir")
    d = _rows_divided(d, nrm)
    n = eye.shape[0]
    viol: list[Violation] = []
    shift = np.zeros(n)
    if state is not None:
        state.progress(0.0, "inverse kinematics")
    if machine.kind == "cartesian" and machine.axis_index("cross") is None:
        eye, shift, v = _slide_to_radius(eye, d, c, float(machine.eye_radius))
        viol += v
    # mandrel angle from the phase rule: p_W = Rz(theta) p_M
    ref = eye if machine.mandrel_phase == "eye" else c
    theta = _unwrap_near(machine.phase - np.arctan2(ref[:, 1], ref[:, 0]))
    dth = np.diff(theta)
    if np.any(dth > 0) and np.any(dth < 0):
        major = np.sign(theta[-1] - theta[0]) or 1.0
        ax = machine.axes[machine.axis_index("mandrel")]
        for a, b in _runs(np.concatenate(([False], np.sign(dth) == -major))):
            back = float(abs(theta[b - 1] - theta[a - 1]) * abs(ax.scale))     # controller units
            viol.append(Violation(
                "reverse", ax.name, back, back, 0.0, index=a, count=b - a,
                message=f"axis {ax.name}: the mandrel turns back by {back:.4g} {ax.units} between points "
                        f"{a - 1} and {b - 1} (winding needs one direction of rotation)"))
    ct, st = np.cos(theta), np.sin(theta)
    pw, dw = _turn_about_z(ct, st, eye), _turn_about_z(ct, st, d)
    q_int = np.zeros((n, len(machine.axes)))
    q_int[:, machine.axis_index("mandrel")] = theta
    check_cancel(state)
    if machine.kind == "cartesian":
        viol += _ik_cartesian(machine, pw, dw, q_int)
    else:
        cw = _turn_about_z(ct, st, c)
        viol += _ik_robot(machine, pw, dw, cw, q_int, state)
        del cw
    del pw, dw, ct, st, theta, dth                # the peak of a big program: drop them before the next copy
    q = q_int                                     # machine.to_controller, in place (the same arithmetic)
    sc, of = machine.scales, machine.offsets
    for k in range(q.shape[1]):                   # column by column (broadcasting a short row is slow)
        q[:, k] *= sc[k]
        q[:, k] += of[k]
    lo, hi = machine.limits("min"), machine.limits("max")
    for k, ax in enumerate(machine.axes):
        u = " " + ax.units
        viol += violations_from_mask("position", ax.name, q[:, k] > hi[k], q[:, k], hi[k], u,
                                     what="position")
        viol += violations_from_mask("position", ax.name, q[:, k] < lo[k], q[:, k], lo[k], u,
                                     what="position")
    if state is not None:
        state.progress(1.0, "inverse kinematics done")
    xs = None
    if x is not None:
        xs = np.asarray(x, dtype=float)
        if xs.shape != (n,):
            raise InputError(f"x must have shape ({n},), got {xs.shape}", field="x")
    arrs = [np.ascontiguousarray(a) for a in (q, eye, d, c, shift)]
    for a in arrs:
        a.flags.writeable = False
    return AxisPath(machine.name, machine.axis_names, *arrs, violations=tuple(viol), x=xs)


def _reduce_is_left_to_right() -> bool:
    """Whether ``np.add.reduce(a, axis=1)`` of a C-contiguous (N, 2..5) float array adds its columns left
    to right from +0 (``((0 + a0) + a1) + ...``) in this numpy, checked once on values where the order shows."""
    if not _LEFT_TO_RIGHT:
        rng = np.random.default_rng(1)
        a = rng.random((301, 5)) * np.array([1e-9, 1.0, 3e8, 1e-3, 7e5])
        a *= rng.choice([-1.0, 1.0], size=a.shape)
        a[:7] = -0.0
        left = ((((a[:, 0] + 0.0) + a[:, 1]) + a[:, 2]) + a[:, 3]) + a[:, 4]
        other = a[:, 0] + (a[:, 1] + (a[:, 2] + (a[:, 3] + a[:, 4])))
        def same(x: np.ndarray, y: np.ndarray) -> bool:     # bit for bit (-0 is not +0)
            return x.tobytes() == y.tobytes()

        _LEFT_TO_RIGHT.append(same(np.add.reduce(a, axis=1), left) and not same(left, other)
                              and same(np.add.reduce(a[:, :3], axis=1), ((a[:, 0] + 0.0) + a[:, 1]) + a[:, 2]))
    return _LEFT_TO_RIGHT[0]


_LEFT_TO_RIGHT: list[bool] = []


def row_sums(a: np.ndarray) -> np.ndarray:
    """``np.add.reduce(a, axis=1)`` of an (N, m) float array, bit for bit: column by column, left to right, where
    numpy's own reduction adds in that order (checked once, :func:`_reduce_is_left_to_right`; reducing a
    short row is ~15x slower than adding columns), else numpy's reduction."""
    if (a.ndim != 2 or a.dtype != np.float64 or not 2 <= a.shape[1] <= 5 or not a.flags.c_contiguous
            or not _reduce_is_left_to_right()):
        return np.add.reduce(a, axis=1)
    out = a[:, 0] + 0.0                       # numpy's reduction starts from +0 (a row of -0 sums to +0)
    for k in range(1, a.shape[1]):
        out += a[:, k]
    return out


def _rows_divided(d: np.ndarray, nrm: np.ndarray) -> np.ndarray:
    """``d / nrm[:, None]`` (a new array) column by column: the same divisions."""
    if d.ndim != 2 or d.shape[0] != nrm.shape[0]:
        return d / nrm[:, None]
    out = np.empty(d.shape)
    for k in range(d.shape[1]):
        np.divide(d[:, k], nrm, out=out[:, k])
    return out


def _turn_about_z(ct: np.ndarray, st: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Points (N,3) turned about z by the angles whose cosines / sines are ``ct``, ``st`` (written in place
    of a stack of the three columns: the same values, one (N,3) array fewer)."""
    out = np.empty_like(p)
    np.multiply(ct, p[:, 0], out=out[:, 0])
    out[:, 0] -= st * p[:, 1]
    np.multiply(st, p[:, 0], out=out[:, 1])
    out[:, 1] += ct * p[:, 1]
    out[:, 2] = p[:, 2]
    return out


def _slide_to_radius(eye: np.ndarray, d: np.ndarray, c: np.ndarray, r0: float
                     ) -> tuple[np.ndarray, np.ndarray, list[Violation]]:
    """Slide the eye along the fibre line to distance ``r0`` from the mandrel axis (nearest root)."""
    a = d[:, 0] ** 2 + d[:, 1] ** 2
    b = 2 * (eye[:, 0] * d[:, 0] + eye[:, 1] * d[:, 1])
    cc = eye[:, 0] ** 2 + eye[:, 1] ** 2 - r0 * r0
    disc = b * b - 4 * a * cc
    bad = (disc < 0) | (a < 1e-18)
    sq = np.sqrt(np.where(bad, 0.0, disc))
    aa = np.where(bad, 1.0, a)
    # numerically stable roots; choose the one nearest zero
    qq = -0.5 * (b + np.copysign(sq, b))
    r1 = np.where(qq != 0, cc / np.where(qq == 0, 1.0, qq), 0.0)
    r2 = qq / aa
    l_free = np.einsum("ij,ij->i", eye - c, d)
    # the root on the eye side of the contact point (free length > 0); nearest one if both are
    front1, front2 = l_free + r1 > 0, l_free + r2 > 0
    nearer1 = np.abs(r1) < np.abs(r2)
    s = np.where(front1 & (~front2 | nearer1), r1, np.where(front2, r2, np.where(nearer1, r1, r2)))
    s = np.where(bad, 0.0, s)
    viol = violations_from_mask("workspace", None, bad, np.sqrt(cc + r0 * r0), r0, " mm",
                                what="the fibre line never reaches the eye radius; eye radius")
    behind = (~bad) & (l_free + s <= 0)
    viol += violations_from_mask("workspace", None, behind, l_free + s, 0.0, " mm",
                                 what="eye would sit behind the contact point; free length")
    return eye + s[:, None] * d, s, viol


def _ik_cartesian(machine: MachineTemplate, pw: np.ndarray, dw: np.ndarray, q_int: np.ndarray
                  ) -> list[Violation]:
    viol: list[Violation] = []
    col = {r: machine.axis_index(r) for r in ROLES_CARTESIAN}
    q_int[:, col["carriage"]] = pw[:, 2]
    if col["cross"] is not None:
        q_int[:, col["cross"]] = pw[:, 0]
    if col["vertical"] is not None:
        q_int[:, col["vertical"]] = pw[:, 1]
    if col["yaw"] is not None:
        # eye axis Ry(g) Rx(p) e_z = (sin g cos p, -sin p, cos g cos p) = d
        dy = np.clip(dw[:, 1], -1.0, 1.0)
        h = np.hypot(dw[:, 0], dw[:, 2])
        name = machine.axes[col["yaw"]].name
        viol += violations_from_mask("singular", name, h < 1e-9, h, 1e-9,
                                     what="fibre nearly along the yaw axis; horizontal component")
        q_int[:, col["yaw"]] = _unwrap_near(np.arctan2(dw[:, 0], dw[:, 2]))
        q_int[:, col["roll"]] = -np.arcsin(dy)
    elif col["roll"] is not None:
        # eye axis Rx(p) e_z = (0, -sin p, cos p) along the projection of d onto the y-z plane
        h = np.hypot(dw[:, 1], dw[:, 2])
        name = machine.axes[col["roll"]].name
        viol += violations_from_mask("singular", name, h < 1e-9, h, 1e-9,
                                     what="fibre along the roll axis; projected length")
        q_int[:, col["roll"]] = _unwrap_near(np.arctan2(-dw[:, 1], dw[:, 2]))
    return viol


# --------------------------------------------------------------------------------------------------
# Robot: vectorised Newton with multilevel warm start
# --------------------------------------------------------------------------------------------------
def _robot_frames(machine: MachineTemplate, track: np.ndarray, j: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Eye frame (N,4,4), joint axes z_i (N,6,3) and origins o_i (N,6,3), machine frame."""
    R, p, zs, os_ = _robot_chain(machine, track, j, want_axes=True)
    T = np.zeros((j.shape[0], 4, 4))
    T[:, :3, :3] = R
    T[:, :3, 3] = p
    T[:, 3, 3] = 1.0
    return T, zs, os_


def _robot_target(dw: np.ndarray, cw: np.ndarray) -> np.ndarray:
    """Target eye rotation (N,3,3): z = fibre direction, x = band width direction."""
    nr = cw.copy()
    nr[:, 2] = 0.0
    nr /= np.maximum(np.linalg.norm(nr, axis=1, keepdims=True), 1e-300)
    x = np.cross(dw, nr)
    x /= np.maximum(np.linalg.norm(x, axis=1, keepdims=True), 1e-300)
    y = np.cross(dw, x)
    return np.stack([x, y, dw], axis=2)


def _pose_error(T: np.ndarray, p: np.ndarray, R: np.ndarray) -> np.ndarray:
    """(N,6): position error (mm) and orientation error (rad, small-angle rotation vector).

    ``0.5 * sum_k c_k x t_k = 0.5 * vee(R_t R_c^T - R_c R_t^T)`` for current/target frame columns.
    """
    e = np.empty((T.shape[0], 6))
    e[:, :3] = p - T[:, :3, 3]
    M = R @ T[:, :3, :3].transpose(0, 2, 1)
    e[:, 3] = 0.5 * (M[:, 2, 1] - M[:, 1, 2])
    e[:, 4] = 0.5 * (M[:, 0, 2] - M[:, 2, 0])
    e[:, 5] = 0.5 * (M[:, 1, 0] - M[:, 0, 1])
    return e


_W = np.array([1.0, 1.0, 1.0, 1000.0, 1000.0, 1000.0])   # error weights: 1 rad ~ 1000 mm


def _err_norm(e: np.ndarray) -> np.ndarray:
    return np.maximum(np.abs(e[:, :3]).max(axis=1), 1000.0 * np.abs(e[:, 3:]).max(axis=1))


def _jacobian(T: np.ndarray, zs: np.ndarray, os_: np.ndarray) -> np.ndarray:
    """Geometric Jacobian (N,6,6) of the eye point and frame (rows weighted by ``_W``)."""
    J = np.empty((T.shape[0], 6, 6))
    J[:, :3, :] = np.cross(zs, T[:, None, :3, 3] - os_).transpose(0, 2, 1)
    J[:, 3:, :] = zs.transpose(0, 2, 1)
    return J * _W[None, :, None]


def _newton(machine: MachineTemplate, track: np.ndarray, p: np.ndarray, R: np.ndarray,
            j0: np.ndarray, iters: int = 40, damping: float = 0.0, want_jinv: bool = False
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Batched Newton / damped least squares on the 6 joints.

    Returns the joints, the final error norms (mm, rad x 1000) and, when asked, the inverse weighted
    Jacobians at the solution (for chord iterations on a finer level).
    """
    j = j0.copy()
    active = np.arange(j.shape[0])
    err = np.full(j.shape[0], np.inf)
    for _ in range(iters):
        if active.size == 0:
            break
        T, zs, os_ = _robot_frames(machine, track[active], j[active])
        e = _pose_error(T, p[active], R[active])
        en = _err_norm(e)
        err[active] = en
        keep = en >= 1e-10
        active, e, T, zs, os_ = active[keep], e[keep], T[keep], zs[keep], os_[keep]
        if active.size == 0:
            break
        Jw = _jacobian(T, zs, os_)
        ew = e * _W[None, :]
        A = Jw.transpose(0, 2, 1) @ Jw + max(damping, 1e-9) ** 2 * np.eye(6)
        dj = np.linalg.solve(A, (Jw.transpose(0, 2, 1) @ ew[:, :, None]))[:, :, 0]
        step = np.abs(dj).max(axis=1, keepdims=True)
        dj *= np.minimum(1.0, 0.3 / np.maximum(step, 1e-300))   # trust region 0.3 rad per step
        j[active] += dj
    if active.size:
        T, _, _ = _robot_frames(machine, track[active], j[active])
        err[active] = _err_norm(_pose_error(T, p[active], R[active]))
    jinv = None
    if want_jinv:
        T, zs, os_ = _robot_frames(machine, track, j)
        Jw = _jacobian(T, zs, os_)
        A = Jw.transpose(0, 2, 1) @ Jw + 1e-18 * np.eye(6)
        jinv = np.linalg.solve(A, Jw.transpose(0, 2, 1))
    return j, err, jinv


def _chord(machine: MachineTemplate, track: np.ndarray, p: np.ndarray, R: np.ndarray, j0: np.ndarray,
           jinv: np.ndarray, lo: np.ndarray, f: np.ndarray, iters: int = 12) -> tuple[np.ndarray, np.ndarray]:
    """Chord iterations ``j += J^-1 e`` with inverse Jacobians interpolated from the coarser level.

    ``jinv`` (M,6,6) at the coarse points; fine point k lies at fraction ``f[k]`` between coarse
    points ``lo[k]`` and ``lo[k] + 1``.  Only points not yet converged are touched.
    """
    j = j0.copy()
    active = np.arange(j.shape[0])
    err = np.full(j.shape[0], np.inf)
    ji = None
    for _ in range(iters + 1):
        R_, pe, _, _ = _robot_chain(machine, track[active], j[active])
        T = np.empty((active.size, 4, 4))
        T[:, :3, :3] = R_
        T[:, :3, 3] = pe
        e = _pose_error(T, p[active], R[active])
        en = _err_norm(e)
        err[active] = en
        keep = en >= 1e-10
        active, e = active[keep], e[keep]
        if active.size == 0:
            break
        if ji is None:
            fk = f[active, None, None]
            ji = jinv[lo[active]] * (1 - fk) + jinv[lo[active] + 1] * fk
        else:
            ji = ji[keep]
        j[active] += np.einsum("nij,nj->ni", ji, e * _W[None, :])
    return j, err


_CHUNK = 8192


def _levels(n: int, n0: int = 64, factor: int = 16) -> list[np.ndarray]:
    """Nested index sets 0 .. n-1 from ``n0`` points up to all points."""
    out = []
    m = min(n, n0)
    while True:
        out.append(np.linspace(0, n - 1, m).round().astype(np.int64))
        if m >= n:
            return out
        m = min(n, m * factor)


def _ik_robot(machine: MachineTemplate, pw: np.ndarray, dw: np.ndarray, cw: np.ndarray, q_int: np.ndarray,
              state: State | None) -> list[Violation]:
    n = pw.shape[0]
    track = pw[:, 2].copy()          # the track follows the eye along the mandrel axis
    q_int[:, machine.axis_index("track")] = track
    R = _robot_target(dw, cw)
    jcols = [machine.axis_index(f"joint{k + 1}") for k in range(6)]
    home = np.asarray(machine.home, dtype=float)
    levels = _levels(n)
    # level 0: sequential continuation on a coarse subset (keeps one continuous branch)
    idx = levels[0]
    i0 = idx[:1]
    # symmetric slot: the band-width axis is kept continuous along the path (+w or -w, no half turns
    # of the wrist where w itself reverses) and the face whose first pose lies nearer home is used
    sign = np.ones(n)
    faces: tuple[float, ...] = (1.0,)
    if machine.band_symmetric:
        flips = np.concatenate(([False], np.einsum("ij,ij->i", R[1:, :, 0], R[:-1, :, 0]) < 0))
        sign = np.where(np.cumsum(flips) % 2 == 1, -1.0, 1.0)
        faces = (1.0, -1.0)
    best = None
    for face in faces:
        Rf = R[i0].copy()
        Rf[:, :, :2] *= face * sign[0]
        j0, _, _ = _newton(machine, track[i0], pw[i0], Rf, home[None, :], iters=40, damping=50.0)
        j0, e0, _ = _newton(machine, track[i0], pw[i0], Rf, j0, iters=50)
        dist = float(np.abs(j0[0] - home).sum()) + (1e9 if e0[0] > 1e-6 else 0.0)
        if best is None or dist < best[0]:
            best = (dist, face, j0, e0)
    _, face, j0, e0 = best
    R[:, :, :2] *= (face * sign)[:, None, None]
    if e0[0] > 1e-6:
        raise InfeasibleError(f"robot cell {machine.name}: no joint solution for the first eye pose "
                              f"(pose error {e0[0]:.3g} mm) starting from home joints {machine.home}",
                              field="robot.home_deg", file=machine.source)
    sol = np.empty((idx.size, 6))
    sol[0] = j0[0]
    for m in range(1, idx.size):
        im = idx[m:m + 1]
        jm, _, _ = _newton(machine, track[im], pw[im], R[im], sol[m - 1:m], iters=60)
        sol[m] = jm[0]
    # finer levels: interpolated warm start, batched Newton; the last level uses chord iterations
    # with the inverse Jacobians interpolated from the level before
    jinv = None
    err = np.zeros(idx.size)
    for lev, new_idx in enumerate(levels[1:], start=1):
        check_cancel(state)
        pos = np.interp(new_idx, idx, np.arange(idx.size))
        lo = np.minimum(np.floor(pos).astype(np.int64), idx.size - 2)
        f = (pos - lo)[:, None]
        # cubic (Catmull-Rom) warm start: near-solution guesses, fewer Newton/chord steps
        p0, p3 = sol[np.maximum(lo - 1, 0)], sol[np.minimum(lo + 2, idx.size - 1)]
        p1, p2 = sol[lo], sol[lo + 1]
        guess = p1 + 0.5 * f * ((p2 - p0) + f * ((2 * p0 - 5 * p1 + 4 * p2 - p3) + f * (3 * (p1 - p2) + p3 - p0)))
        last = lev == len(levels) - 1
        if last and jinv is not None:
            # chunks of a few thousand points keep the temporaries in cache (3-10x faster here)
            sol, err = np.empty_like(guess), np.empty(new_idx.size)
            for c0 in range(0, new_idx.size, _CHUNK):
                sl = slice(c0, min(new_idx.size, c0 + _CHUNK))
                ni = new_idx[sl]
                sol[sl], err[sl] = _chord(machine, track[ni], pw[ni], R[ni], guess[sl], jinv, lo[sl], f[sl, 0])
                check_cancel(state)
            bad = err >= 1e-10
            if bad.any():
                b = np.flatnonzero(bad)
                sb, eb, _ = _newton(machine, track[new_idx[b]], pw[new_idx[b]], R[new_idx[b]], sol[b])
                sol[b], err[b] = sb, eb
        else:
            sol, err, jinv = _newton(machine, track[new_idx], pw[new_idx], R[new_idx], guess,
                                     want_jinv=lev == len(levels) - 2)
        idx = new_idx
        if state is not None:
            state.progress(min(0.95, idx.size / n), "robot inverse kinematics")
    for k, c in enumerate(jcols):
        q_int[:, c] = sol[:, k]
    viol = violations_from_mask("ik", None, err > 1e-7, err, 1e-7, " mm",
                                what="no joint solution (pose error)")
    jump = np.abs(np.diff(sol, axis=0)).max(axis=1)
    big = np.flatnonzero(jump > _BRANCH_STEP_RAD)
    if big.size:
        # a big joint step is a branch switch only when continuation through the in-between poses
        # (eye point on the chord, eye frame turned about one axis) reaches a different solution
        end, worst = _continue_steps(machine, track, pw, R, sol, big)
        same = (np.abs(end - sol[big + 1]).max(axis=1) < 1e-6) & (worst <= _BRANCH_STEP_RAD)
        jump[big[same]] = 0.0
    viol += violations_from_mask("ik", None, np.concatenate(([False], jump > _BRANCH_STEP_RAD)),
                                 np.concatenate(([0.0], jump)), _BRANCH_STEP_RAD, " rad",
                                 what="joint branch switch; joint step")
    return viol


_BRANCH_STEP_RAD = 0.5      # a joint step above this between two path points is checked by continuation
_CONTINUE_STEP_RAD = 0.05   # joint change per in-between pose of the continuation (about)


def _slerp_frames(Ra: np.ndarray, Rb: np.ndarray, t: float) -> np.ndarray:
    """Frames (N,3,3) a fraction ``t`` of the way from ``Ra`` to ``Rb`` (rotation about one fixed axis)."""
    from scipy.spatial.transform import Rotation

    rel = Rotation.from_matrix(Ra.transpose(0, 2, 1) @ Rb).as_rotvec()
    return Ra @ Rotation.from_rotvec(t * rel).as_matrix()


def _continue_steps(machine: MachineTemplate, track: np.ndarray, pw: np.ndarray, R: np.ndarray,
                    sol: np.ndarray, ks: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Joints reached at point ``k + 1`` by Newton continuation from ``sol[k]`` (every ``k`` in ``ks``).

    The eye pose moves from point k to k + 1 through in-between poses: the eye point along the chord,
    the eye frame turned about one axis (slerp), the track along its chord; each pose's Newton starts from
    the previous pose's joints, in steps of about :data:`_CONTINUE_STEP_RAD` of the largest joint.

    Returns the joints at ``k + 1`` (len(ks), 6) and the largest joint change between in-between poses
    (rad) - above :data:`_BRANCH_STEP_RAD` the continuation itself jumped branch.
    """
    step = np.abs(sol[ks + 1] - sol[ks]).max(axis=1)
    m = int(min(400, max(2, np.ceil(step.max() / _CONTINUE_STEP_RAD))))
    j = sol[ks].copy()
    worst = np.zeros(ks.size)
    for i in range(1, m + 1):
        t = i / m
        p = (1 - t) * pw[ks] + t * pw[ks + 1]
        tr = (1 - t) * track[ks] + t * track[ks + 1]
        jn, _, _ = _newton(machine, tr, p, _slerp_frames(R[ks], R[ks + 1], t), j, iters=60)
        worst = np.maximum(worst, np.abs(jn - j).max(axis=1))
        j = jn
    return j, worst


# --------------------------------------------------------------------------------------------------
# Synthetic eye paths for tests and benchmarks
# --------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class DemoEyePath:
    """A synthetic payout-stage output: arrays in the mandrel frame (mm)."""

    x: np.ndarray
    eye_xyz: np.ndarray
    contact_xyz: np.ndarray
    fibre_dir: np.ndarray
    free_length: np.ndarray


def demo_eye_path(kind: str = "helix", n: int = 4000, circuits: int = 2, radius: float = 100.0,
                  length: float = 400.0, beta_deg: float = 30.0, eye_radius: float = 160.0,
                  free_length: float = 120.0) -> DemoEyePath:
    """Closed circuits of a winding line on a cylinder and an eye path above it.

    The winding angle beta goes smoothly from ``beta_deg`` through 90 deg to ``180 - beta_deg`` at each
    end (turnarounds), so the line is a helix with smooth hoop-like turnarounds.

    Parameters
    ----------
    kind:
        ``"helix"``: eye on a parallel path at fixed distance ``eye_radius`` from the axis;
        ``"dome"``: constant free length ``free_length`` - the eye radius and height vary (dome-like).
    n: number of points.  circuits: number of circuits.  radius, length: cylinder, mm.
    """
    if kind not in ("helix", "dome"):
        raise InputError(f"demo path kind must be 'helix' or 'dome', got {kind!r}", field="kind")
    b0 = math.radians(beta_deg)
    # one circuit in arc length: pass, turn, pass, turn; beta(s) smooth
    pass_len = length / math.cos(b0)
    turn_len = 0.6 * math.pi * radius
    seg = np.array([pass_len, turn_len, pass_len, turn_len])
    total = circuits * seg.sum()
    s = np.linspace(0.0, total, n)
    sc = np.mod(s, seg.sum())
    edges = np.concatenate(([0.0], np.cumsum(seg)))
    beta = np.full(n, b0)
    for k in range(4):
        m = (sc >= edges[k]) & (sc < edges[k + 1] + 1e-12)
        u = (sc[m] - edges[k]) / seg[k]
        if k == 0:
            beta[m] = b0
        elif k == 2:
            beta[m] = math.pi - b0
        elif k == 1:
            beta[m] = b0 + (math.pi - 2 * b0) * 0.5 * (1 - np.cos(np.pi * u))
        else:
            beta[m] = (math.pi - b0) - (math.pi - 2 * b0) * 0.5 * (1 - np.cos(np.pi * u))
    # integrate dz = cos(beta) ds, dv = sin(beta)/R ds (trapezoid on the fine grid)
    ds = np.diff(s)
    z = np.concatenate(([0.0], np.cumsum(0.5 * (np.cos(beta[1:]) + np.cos(beta[:-1])) * ds)))
    v = np.concatenate(([0.0], np.cumsum(0.5 * (np.sin(beta[1:]) + np.sin(beta[:-1])) * ds))) / radius
    z -= 0.5 * (z.max() + z.min())
    er = np.stack([np.cos(v), np.sin(v), np.zeros(n)], axis=1)
    ev = np.stack([-np.sin(v), np.cos(v), np.zeros(n)], axis=1)
    contact = radius * er + z[:, None] * np.array([0.0, 0.0, 1.0])
    tau = np.cos(beta)[:, None] * np.array([0.0, 0.0, 1.0]) + np.sin(beta)[:, None] * ev
    if kind == "helix":
        if eye_radius <= radius:
            raise InputError(f"eye_radius {eye_radius} must exceed the mandrel radius {radius}",
                             field="eye_radius")
        lf = math.sqrt(eye_radius ** 2 - radius ** 2) / np.sin(beta)
    else:
        lf = np.full(n, float(free_length))
    eye = contact + lf[:, None] * tau
    return DemoEyePath(x=s, eye_xyz=eye, contact_xyz=contact, fibre_dir=tau, free_length=lf)


def reproduced_fibre_dir(machine: MachineTemplate, axis_path: AxisPath) -> np.ndarray:
    """The fibre direction the machine is expected to reproduce (mandrel frame), per ``fibre_mode``.

    ``"line"`` and ``"full"``: the fibre direction itself; ``"projected"``: its projection onto the
    plane normal to the eye roll axis (the machine's x axis, rotated into the mandrel frame), normalised.
    """
    d = np.asarray(axis_path.fibre_dir, dtype=float)
    if machine.fibre_mode != "projected":
        return d.copy()
    theta = machine.to_internal(axis_path.q)[:, machine.axis_index("mandrel")]
    ax = np.stack([np.cos(theta), -np.sin(theta), np.zeros_like(theta)], axis=1)  # Rz(-theta) e_x
    p = d - np.einsum("ij,ij->i", d, ax)[:, None] * ax
    return p / np.linalg.norm(p, axis=1, keepdims=True)


def angle_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle between unit vectors, rad, accurate for tiny angles (atan2 of |a x b| and a.b)."""
    return np.arctan2(np.linalg.norm(np.cross(a, b), axis=1), np.einsum("ij,ij->i", a, b))


__all__ = [
    "AxisPath", "Axis", "DH", "DemoEyePath", "MachineTemplate", "Violation", "angle_between",
    "demo_eye_path", "eye_chain", "forward_kinematics", "inverse_kinematics", "list_machines",
    "load_machine", "parse_machine", "reproduced_fibre_dir", "violations_from_mask",
]
