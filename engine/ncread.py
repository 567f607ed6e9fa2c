"""NC read-back: parse an NC program, replay it through a machine template, check every limit.

``winder simulate FILE --machine TEMPLATE [--controller C] [--job JOB]`` (engine/cli/simulate.py) uses
:func:`read_nc` and :func:`simulate`.  The reader understands the dialects winder writes (LinuxCNC,
Fanuc, Sinumerik, Marlin/GRBL, the CSV axis table) and foreign G-code of the same families (e.g. a
Marlin program from another winding planner: G90/G91, G92, G20/G21, G93/G94, G0/G1, G4 dwells,
``;`` and ``( )`` comments, N numbers, ``%`` and ``O`` lines, M words); anything else is refused
with the line number (:class:`InputError`, exit code 2) - an unknown word, a number that is not
finite, a word without a number, a program that stops before its end code (truncated).

Timing model (``program_time_s``): G93 (inverse time) - a move takes ``60 / F`` s; G94 - ``60·L / F`` s
with ``L`` the Euclidean length of the move over all axes in controller units (the convention of
winder's Marlin post); G0 - the slowest axis at its ``max_speed`` (reported apart, ``rapid_time_s``).
``time_with_limits_s`` is what a controller keeping the template's limits needs: each move no faster
than any axis' ``max_speed``, and at each corner the part of an axis' speed step above ``max_jump``
bled off at ``max_accel``.  For a program that keeps every limit the two are equal.  The program's
numbers are rounded (positions and F words to the profile's decimals): a speed is checked against its
limit within what those roundings leave open.

With the job's winding line (``line``), the eye positions (forward kinematics) are matched to the
contact points they lay: the eye sits on the free fibre, the tangent of the winding line at the
contact; the laid fibre runs along the line between the first and the last contact
(``fibre_length_mm``) and ``fibre_miss_mm`` says how far the eye ever is from that tangent.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from engine.errors import InputError
from engine.kinematics import MachineTemplate, Violation, forward_kinematics, violations_from_mask

_NUM = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_WORD = re.compile(rf"\s*(?:([A-Za-z][A-Za-z0-9_]*)\s*=\s*({_NUM})|([A-Za-z])\s*({_NUM}))")
_BAD_NUM = re.compile(r"\s*([A-Za-z][A-Za-z0-9_]*)\s*=?\s*([-+]?(?:nan|inf|infinity))\b", re.IGNORECASE)
_G_KNOWN = {0, 1, 4, 17, 20, 21, 40, 49, 61, 64, 80, 90, 91, 92, 93, 94}
_END_CODES = {2, 30}


@dataclass(frozen=True)
class NcProgram:
    """The moves of an NC program in the machine's controller units.

    Attributes
    ----------
    axis_names: machine axis names (column order).
    q: (n+1, n_axes) axis values: the position before the first feed move, then after each move.
    time_s: (n,) move durations from the program's feeds (s).
    line: (n,) 1-based line numbers of the moves.
    rapid_time_s: time of the G0 moves (slowest axis at max_speed).
    dwell_s: G4 dwell time.  feed_mode: ``"inverse_time"``, ``"units_per_min"`` or ``"table"`` (CSV).
    ended: the program reached its end code (M2/M30) or the end of a CSV table.
    file: the source.  machine: see below.
    """

    axis_names: tuple[str, ...]
    q: np.ndarray
    time_s: np.ndarray
    line: np.ndarray
    rapid_time_s: float = 0.0
    dwell_s: float = 0.0
    feed_mode: str = "inverse_time"
    ended: bool = True
    file: str = ""
    machine: Any = None
    """The machine as the program places it (carriage offset from its set-up header line)."""
    resolution: np.ndarray | None = None
    """Per axis: the smallest step the program's numbers resolve (10^-decimals of the profile)."""
    time_resolution: np.ndarray | None = None
    """Per move: the relative uncertainty of its duration from the rounding of its F word (or time column):
    10^-decimals_feed / F (both feed modes: the time is 60 / F or 60·L / F)."""

    @property
    def n(self) -> int:
        return int(self.time_s.size)


def _letters(machine: MachineTemplate, profile: Any | None) -> dict[str, int]:
    mapping = dict(profile.axis_letters) if profile is not None else {}
    out: dict[str, int] = {}
    for k, a in enumerate(machine.axes):
        out[mapping.get(a.name, a.name).upper()] = k
    return out


_SETUP = re.compile(r"set-up: mandrel z = 0 at (\w+) = ([-+0-9.eE]+)")
_EYE_R = re.compile(r"set-up: eye radius = ([-+0-9.eE]+) mm")


def placed_machine(machine: MachineTemplate, text: str) -> MachineTemplate:
    """``machine`` with the carriage (track) offset and the fixed eye radius a winder program records in
    its header (``set-up: mandrel z = 0 at X = 600``, ``set-up: eye radius = 150 mm``); unchanged when
    the program has no such lines."""
    from dataclasses import replace

    r = _EYE_R.search(text[:4000])
    if r is not None and machine.eye_radius is not None:
        machine = replace(machine, eye_radius=float(r.group(1)))
    m = _SETUP.search(text[:4000])
    if m is None:
        return machine
    axes = tuple(replace(a, offset=float(m.group(2))) if a.name == m.group(1) and a.role in ("carriage", "track")
                 else a for a in machine.axes)
    return replace(machine, axes=axes)


def read_nc(text: str, machine: MachineTemplate, profile: Any | None = None, file: str | Path | None = None,
            start: np.ndarray | None = None) -> NcProgram:
    """Parse NC ``text`` for ``machine`` (axis letters from ``profile``, else the axis names).

    ``start``: axis values before the program (default: the machine's internal zero, i.e. the axis
    offsets).  Raises :class:`InputError` with the line number for anything it cannot read.
    """
    src = str(file) if file is not None else None
    head = text.lstrip()[:2000]
    machine = placed_machine(machine, head)
    if re.match(r"^(#[^\n]*\n)*block[,;\t]path_index", head):
        return _read_csv(text, machine, profile, src)
    letters = _letters(machine, profile)
    na = len(machine.axes)
    pos = np.array(machine.offsets if start is None else start, dtype=float)
    origin = np.zeros(na)                       # G92 shift: programmed = machine - origin
    linear = np.array([a.type == "linear" for a in machine.axes])
    vmax = machine.limits("max_speed")
    qs: list[np.ndarray] = []
    ts: list[float] = []
    trs: list[float] = []
    feed_res = 10.0 ** -profile.decimals_feed if profile is not None else 0.0
    lines: list[int] = []
    first_pos: np.ndarray | None = None
    mode_abs, inverse, inch = True, False, False
    motion: int | None = None                   # modal motion G0/G1 (none until set)
    feed: float | None = None
    feed_inch = False                            # F given in inch/min (G20): linear moves scale it
    rapid_t = dwell = 0.0
    ended = False
    end_codes = set(_END_CODES)
    last = (profile.postamble[-1] if profile is not None and profile.postamble else "").strip().upper()
    if re.fullmatch(r"M\d+", last):
        end_codes.add(int(last[1:]))               # e.g. Marlin's M18 (steppers off)
    ours = "filament winding program" in head
    sinumerik = getattr(profile, "dialect", "") == "sinumerik"
    for ln, raw in enumerate(text.replace("\r\n", "\n").replace("\r", "\n").split("\n"), start=1):
        s = re.sub(r"\([^)]*\)", " ", raw)
        if "(" in s:
            raise InputError("unclosed comment '('", file=src, line=ln)
        s = s.split(";", 1)[0].strip()
        if not s or s == "%" or re.fullmatch(r"[Oo]\d+", s):
            continue
        if ended:
            raise InputError(f"'{s}' after the end of the program (M2/M30)", file=src, line=ln)
        words: list[tuple[str, float]] = []
        i = 0
        while i < len(s):
            if s[i].isspace():
                i += 1
                continue
            m = _WORD.match(s, i)
            if m is None:
                bad = _BAD_NUM.match(s, i)
                if bad:
                    raise InputError(f"word {bad.group(1)} has a value that is not a finite number: "
                                     f"{bad.group(2)!r}", file=src, line=ln)
                frag = s[i:].split()[0]
                if re.fullmatch(r"[A-Za-z][A-Za-z0-9_]*=?", frag):
                    raise InputError(f"word {frag!r} has no number (truncated line?)", file=src, line=ln)
                raise InputError(f"cannot read {frag!r}", file=src, line=ln)
            name = (m.group(1) or m.group(3)).upper()
            val = float(m.group(2) or m.group(4))
            if not math.isfinite(val):
                raise InputError(f"word {name} is not a finite number", file=src, line=ln)
            words.append((name, val))
            i = m.end()
        target = pos.copy()
        moved = np.zeros(na, bool)
        g_motion = None
        g4 = g92 = False
        dwell_p = dwell_s = None
        for name, val in words:
            if name == "N":
                continue
            if name == "G":
                g = int(round(val))
                if sinumerik and g in (70, 71):      # Sinumerik: G70 inch, G71 metric
                    inch = g == 70
                    continue
                if abs(val - g) > 1e-9 or g not in _G_KNOWN:
                    known = ", G".join(map(str, sorted(_G_KNOWN)))
                    raise InputError(f"unknown word G{val:g} (this reader knows G{known})", file=src, line=ln)
                if g in (0, 1):
                    g_motion = g
                elif g == 90:
                    mode_abs = True
                elif g == 91:
                    mode_abs = False
                elif g == 93:
                    inverse = True
                elif g == 94:
                    inverse = False
                elif g == 20:
                    inch = True
                elif g == 21:
                    inch = False
                elif g == 4:
                    g4 = True
                elif g == 92:
                    g92 = True
                continue
            if name == "M":
                if int(round(val)) in end_codes:
                    ended = True
                continue
            if name == "F":
                if val <= 0:
                    raise InputError(f"feed F{val:g} must be positive", file=src, line=ln)
                feed = val
                feed_inch = inch
                continue
            if name in ("P", "S", "T") and name not in letters:      # G64 P, G4 P/S, spindle, tool
                if name == "P":
                    dwell_p = val
                elif name == "S":
                    dwell_s = val
                continue
            if name in letters:
                k = letters[name]
                v = val * (25.4 if inch and linear[k] else 1.0)
                if g92:
                    origin[k] = pos[k] - v
                    continue
                target[k] = (v + origin[k]) if mode_abs else target[k] + v
                moved[k] = True
                continue
            known = ", ".join(sorted(letters))
            raise InputError(f"unknown word {name}{val:g}: machine {machine.name} has axes {known}", file=src, line=ln)
        if g4:                                   # Marlin: P ms or S s; RS274: P s
            marlin = (getattr(profile, "dialect", "") or "") == "marlin"
            if dwell_s is not None:
                dwell += dwell_s
            elif dwell_p is not None:
                dwell += dwell_p / 1000.0 if marlin else dwell_p
            continue
        if g_motion is not None:
            motion = g_motion
        if not moved.any():
            continue
        if motion is None:
            raise InputError("an axis move before any G0/G1", file=src, line=ln)
        if motion == 0:
            d = np.abs(target - pos)
            rapid_t += float(np.max(d / vmax))
            pos = target
            continue
        if first_pos is None:
            first_pos = pos.copy()
        d = target - pos
        if inverse:
            if feed is None or "F" not in {w for w, _ in words}:
                raise InputError("a G93 (inverse time) move needs an F word on its line", file=src, line=ln)
            t = 60.0 / feed
        else:
            if feed is None:
                raise InputError("a feed move before any F word", file=src, line=ln)
            f_mm = feed * (25.4 if feed_inch and bool(np.any(linear & (d != 0))) else 1.0)
            t = 60.0 * float(np.linalg.norm(d)) / f_mm
        qs.append(target.copy())
        ts.append(t)
        trs.append(feed_res / feed if feed else 0.0)
        lines.append(ln)
        pos = target
    if not qs:
        raise InputError("the program has no feed moves (G1)", file=src)
    if ours and not ended:
        codes = "/".join(f"M{c}" for c in sorted(end_codes))
        raise InputError(f"the program stops at line {lines[-1]} without its end code {codes} (truncated file?)",
                         file=src, line=lines[-1])
    q = np.vstack([first_pos] + qs)
    return NcProgram(machine.axis_names, q, np.asarray(ts), np.asarray(lines, dtype=np.int64), rapid_t, dwell,
                     "inverse_time" if inverse else "units_per_min", ended, src or "", machine,
                     _resolution(machine, profile), np.asarray(trs))


def _read_csv(text: str, machine: MachineTemplate, profile: Any | None, src: str | None) -> NcProgram:
    rows = text.replace("\r\n", "\n").split("\n")
    letters = _letters(machine, profile)
    hdr_i = next(i for i, r in enumerate(rows) if r.startswith("block"))
    delim = next(d for d in (",", ";", "\t") if d in rows[hdr_i])
    head = rows[hdr_i].split(delim)
    cols: list[int] = []
    for k in range(len(machine.axes)):
        want = next(L for L, kk in letters.items() if kk == k)
        hit = [i for i, h in enumerate(head) if h.split("_")[0].upper() == want]
        if not hit:
            raise InputError(f"no column for axis {machine.axes[k].name} (letter {want})", file=src, line=hdr_i + 1)
        cols.append(hit[0])
    if "time_s" not in head:
        raise InputError("no time_s column", file=src, line=hdr_i + 1)
    ti = head.index("time_s")
    q, t, ln = [], [], []
    for i, r in enumerate(rows[hdr_i + 1:], start=hdr_i + 2):
        if not r.strip():
            continue
        parts = r.split(delim)
        if len(parts) != len(head):
            raise InputError(f"{len(parts)} columns, the header has {len(head)} (truncated row?)", file=src, line=i)
        try:
            vals = [float(parts[c]) for c in cols] + [float(parts[ti])]
        except ValueError:
            raise InputError(f"not a number in row {r!r}", file=src, line=i) from None
        if not all(math.isfinite(v) for v in vals):
            raise InputError("a value that is not a finite number", file=src, line=i)
        q.append(vals[:-1])
        t.append(vals[-1])
        ln.append(i)
    if len(q) < 2:
        raise InputError("the table has no moves", file=src)
    tt = np.asarray(t[1:])
    t_res = (10.0 ** -(profile.decimals_feed + 2) / np.maximum(tt, 1e-12) if profile is not None
             else np.zeros(tt.size))     # the csv post writes time_s with decimals_feed + 2 decimals
    return NcProgram(machine.axis_names, np.asarray(q), tt, np.asarray(ln[1:], dtype=np.int64),
                     feed_mode="table", file=src or "", machine=machine, resolution=_resolution(machine, profile),
                     time_resolution=t_res)


def _resolution(machine: MachineTemplate, profile: Any | None) -> np.ndarray:
    if profile is None:
        return np.zeros(len(machine.axes))
    return np.array([10.0 ** -(profile.decimals_rotary if a.type == "rotary" else profile.decimals_linear)
                     for a in machine.axes])


# --------------------------------------------------------------------------------------------------
# Replay
# --------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Simulation:
    """What the program does on the machine (see :func:`simulate`)."""

    program: NcProgram
    eye_xyz: np.ndarray
    speed: np.ndarray
    violations: list[Violation]
    report: dict[str, Any]
    contact_index: np.ndarray | None = None


def simulate(prog: NcProgram, machine: MachineTemplate, line: Any | None = None,
             back_turn_tol_deg: float = 0.01) -> Simulation:
    """Replay ``prog`` through ``machine``'s forward kinematics and check every limit.

    ``line``: the job's winding line (``xyz``, ``tau``, ``s``) for the laid fibre (optional).
    Violations (kinds ``position``, ``speed``, ``jump``, ``reverse``) are located by move (``block``);
    the report holds the program time, the time with the limits, the axis ranges, the fibre length
    and every violation with its NC line.
    """
    machine = prog.machine if prog.machine is not None else machine
    q = prog.q
    t = np.maximum(prog.time_s, 1e-12)
    d = np.diff(q, axis=0)
    v = d / t[:, None]
    lo, hi = machine.limits("min"), machine.limits("max")
    vmax, p, amax = machine.limits("max_speed"), machine.limits("max_jump"), machine.limits("max_accel")
    viol: list[Violation] = []
    # the numbers of the program are rounded: a speed is known within (position step) / (move time)
    # plus |speed| x (relative time step of the rounded F word)
    res = prog.resolution if prog.resolution is not None else np.zeros(len(machine.axes))
    dv = res[None, :] / t[:, None]
    if prog.time_resolution is not None and prog.time_resolution.shape == t.shape:
        dv = dv + np.abs(v) * prog.time_resolution[:, None]
    for k, ax in enumerate(machine.axes):
        u = " " + ax.units
        col = q[1:, k]
        viol += violations_from_mask("position", ax.name, col > hi[k] + 1e-9, col, hi[k], u, where="block",
                                     what="end position")
        viol += violations_from_mask("position", ax.name, col < lo[k] - 1e-9, col, lo[k], u, where="block",
                                     what="end position")
        s = np.abs(v[:, k])
        viol += violations_from_mask("speed", ax.name, s > vmax[k] * (1 + 1e-6) + dv[:, k], s, vmax[k], u + "/s",
                                     where="block", what="speed")
        if v.shape[0] >= 2:
            jump = np.abs(np.diff(v[:, k]))
            ok = p[k] * (1 + 1e-6) + dv[1:, k] + dv[:-1, k]
            viol += violations_from_mask("jump", ax.name, jump > ok, jump, p[k], u + "/s",
                                         where="block", what="speed jump to the next block")
    km = machine.axis_index("mandrel")
    if km is not None and d.shape[0] >= 2:
        ax = machine.axes[km]
        col = q[:, km]
        major = 1.0 if col[-1] >= col[0] else -1.0
        back = major * np.maximum.accumulate(major * col) - col
        tol = math.radians(back_turn_tol_deg) * abs(ax.scale)
        viol += violations_from_mask("reverse", ax.name, np.abs(back[1:]) > tol, np.abs(back[1:]), tol,
                                     " " + ax.units, where="block", what="mandrel back-turn")
    # time with the limits: no move faster than an axis allows, speed steps above max_jump bled at max_accel
    t_lim = np.maximum(t, (np.abs(d) / vmax).max(axis=1))
    vl = d / t_lim[:, None]
    extra = 0.0
    if vl.shape[0] >= 2:
        step = np.abs(np.diff(vl, axis=0))
        extra = float((np.maximum(step - p, 0.0) / amax).max(axis=1).sum())
    eye, _ = forward_kinematics(machine, q)
    ranges = {n: [float(q[:, k].min()), float(q[:, k].max())] for k, n in enumerate(machine.axis_names)}
    acc, jmp = {}, {}
    if v.shape[0] >= 2:
        # constant speed in each move; a step up to max_jump at once, the rest bled at max_accel within the
        # two moves around the corner (the model of time_with_limits_s and of the pipeline's report)
        tm = 0.5 * (t[1:] + t[:-1])
        dv = np.abs(np.diff(v, axis=0))
        a = np.maximum(dv - p, 0.0) / tm[:, None]
        acc = {n: float(a[:, k].max() / amax[k]) for k, n in enumerate(machine.axis_names)}
        jmp = {n: float(dv[:, k].max() / p[k]) for k, n in enumerate(machine.axis_names)}
    rep: dict[str, Any] = {
        "file": prog.file, "machine": machine.name, "moves": prog.n, "feed_mode": prog.feed_mode,
        "program_time_s": float(t.sum()), "time_with_limits_s": float(t_lim.sum()) + extra,
        "rapid_time_s": prog.rapid_time_s, "dwell_s": prog.dwell_s,
        "axis_ranges": ranges,
        "max_speed_ratio": {n: float(np.abs(v[:, k]).max() / vmax[k]) for k, n in enumerate(machine.axis_names)},
        "max_accel_ratio": acc,
        "max_jump_ratio": jmp,
        "eye_path_length_mm": float(np.linalg.norm(np.diff(eye, axis=0), axis=1).sum()),
    }
    contact = None
    if line is not None:
        contact, miss = match_contacts(eye, np.asarray(line.xyz, float), np.asarray(line.tau, float))
        s_line = np.asarray(line.s, float)
        rep["fibre_length_mm"] = float(s_line[contact[-1]] - s_line[contact[0]])
        fin = np.isfinite(miss)  # a move away from the mandrel (a laminate's transition) has no contact ray
        rep["fibre_miss_mm"] = float(np.max(miss[fin])) if fin.any() else None
    from engine.machine_setup import group_violations

    groups = group_violations(viol)
    rep["violations"] = []
    for g in groups:
        b = g.first.get("block")
        rep["violations"].append({"kind": g.kind, "axis": g.axis, "what": g.what, "worst": g.worst, "value": g.value,
                                  "limit": g.limit, "places": g.places, "count": g.points,
                                  "nc_line": int(prog.line[b]) if b is not None and b < prog.n else None,
                                  "time_s": float(t[:b].sum()) if b is not None else None,
                                  "message": _with_line(g.message, prog, b, t)})
    rep["ok"] = not viol
    return Simulation(prog, eye, v, viol, rep, contact)


def _with_line(msg: str, prog: NcProgram, b: int | None, t: np.ndarray) -> str:
    if b is None or b >= prog.n:
        return msg
    return f"{msg.split('; first at')[0]}; first at NC line {int(prog.line[b])}, t = {float(t[:b].sum()):.2f} s"


def match_contacts(eye: np.ndarray, c: np.ndarray, tau: np.ndarray, window: int = 256, near_mm: float = 0.5
                   ) -> tuple[np.ndarray, np.ndarray]:
    """For every eye position the winding-line point whose tangent ray passes nearest to it.

    The contact advances along the line: each search starts at the previous contact and looks
    ``window`` points ahead (the window doubles, up to 64 times, while the best point sits at its far
    edge or its ray misses the eye by more than ``near_mm``).
    Returns ``(index, miss_mm)``: the contact point of each eye position and the distance of the eye
    from that point's tangent ray.
    """
    n, m = eye.shape[0], c.shape[0]
    idx = np.zeros(n, dtype=np.int64)
    miss = np.zeros(n)
    j0 = 0
    for k in range(n):
        w = window
        while True:
            j1 = min(m, j0 + w)
            rel = eye[k] - c[j0:j1]
            along = np.einsum("ij,ij->i", rel, tau[j0:j1])
            perp = np.linalg.norm(rel - along[:, None] * tau[j0:j1], axis=1)
            perp = np.where(along > 0, perp, np.inf)
            b = int(np.argmin(perp))
            if (b < j1 - j0 - 1 and perp[b] <= near_mm) or j1 == m or w >= 64 * window:
                break
            w *= 2
        idx[k] = j0 + b
        miss[k] = perp[b]
        j0 = idx[k]
    return idx, miss


def guess_dialect(path: str | Path, text: str) -> str:
    """The post-processor dialect a program is most likely written in (file suffix, framing, comments)."""
    ext = Path(path).suffix.lower()
    head = text[:4000]
    if ext == ".csv" or ("path_index" in head and head.lstrip().startswith(("# ", "block"))):
        return "csv"
    if ext == ".mpf":
        return "sinumerik"
    if ext == ".gcode" or (";" in head and "(" not in head[:200]):
        return "marlin"
    if text.lstrip().startswith("%"):
        return "fanuc"
    return "linuxcnc"


def read_back(path: str | Path, machine: MachineTemplate, controller: str | None = None, line: Any | None = None,
              back_turn_tol_deg: float = 0.01) -> tuple[Simulation, str]:
    """Read the NC file ``path`` and replay it on ``machine``: ``(simulation, controller profile name)``.

    The profile is ``controller`` or the one of the file's dialect that addresses the machine's axes.
    """
    from engine.machine_setup import controller_for

    p = Path(path)
    try:
        raw = p.read_bytes()
    except OSError as exc:
        raise InputError(f"cannot read: {exc.strerror}", file=p) from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise InputError("not a text file", file=p, line=raw[: exc.start].count(b"\n") + 1) from None
    if controller:
        from engine.post import load_controller

        profile = load_controller(controller)
    else:
        profile = controller_for(guess_dialect(p, text), None, machine)
    prog = read_nc(text, machine, profile, file=p)
    return simulate(prog, machine, line, back_turn_tol_deg=back_turn_tol_deg), profile.name


__all__ = ["NcProgram", "Simulation", "guess_dialect", "match_contacts", "read_back", "read_nc", "simulate"]
