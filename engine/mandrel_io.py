"""Mandrel importers and exporters: CSV generatrix tables, DXF profiles, STEP solids, STL meshes.

Every importer returns a :class:`engine.mandrel.Mandrel` (a C2 spline through the profile points)
or raises :class:`engine.errors.InputError` naming the file and, where it makes sense, the line,
column, DXF entity or geometric place that is wrong.  Nothing else escapes for bad input.

* :func:`load_csv` -- a table ``z, r`` (mm), header optional, ``,`` ``;`` tab or blanks between
  cells, ``#`` comments.
* :func:`load_dxf` -- a profile drawn in model space with LINE / ARC / LWPOLYLINE (bulges) /
  POLYLINE / SPLINE / ELLIPSE, x = axial z, y = radius.
* :func:`load_step` -- a solid of revolution; the axis is detected, the body is cut by a plane
  through the axis and probed in six more half-planes; the outer profile is the generatrix.
* :func:`export_step`, :func:`export_stl` -- the solid obtained by revolving the closed profile
  (generatrix, end faces, axis) 360° about the Z axis (:func:`mandrel_solid`).
* :func:`load_mandrel_file` -- dispatch by suffix.

CAD kernels are imported lazily, inside the functions (the GUI must start fast).  cadquery/OCP is
not thread-safe: every OCP call happens inside :func:`load_step`, :func:`export_step`,
:func:`export_stl` and :func:`mandrel_solid`, so callers can serialise them with one lock;
:func:`load_csv` and :func:`load_dxf` never touch OCP.
"""

from __future__ import annotations

import io
import math
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from engine.errors import InputError
from engine.fileio import atomic_write_with
from engine.mandrel import (
    ArcSegment,
    EllipseSegment,
    LineSegment,
    Mandrel,
    Segment,
    SplineSegment,
    validate_points,
)

FloatArray = NDArray[np.float64]

MAX_INPUT_BYTES = 64 * 1024 * 1024
"""Importers refuse larger files (a generatrix never needs that much)."""

MAX_COORD_MM = 1e7
"""Largest |z| or |r| accepted (10 km): anything larger is a unit mistake, and would overflow the spline."""

MIN_LENGTH_MM = 1e-3
"""Shortest winding zone accepted (1 µm)."""

MAX_SPLINE_POINTS = 4000
"""A profile with more points than this (a scanned or densely exported curve) is decimated before the
spline is built: the spline through the kept points passes within :func:`decimation_tolerance_mm`
of every point of the file (all later stages cost in proportion to the spline's points)."""

# Profile points handed to the spline by the DXF/STEP importers: about this many along the zone.
_PROFILE_POINTS = 1200
# Spline segments up to this many points are exported exactly; denser ones are re-fitted.
_EXACT_SPLINE_POINTS = 400


# ================================================================================================
# Common helpers
# ================================================================================================
def _read_bytes(path: str | Path, what: str) -> bytes:
    p = Path(path)
    try:
        size = p.stat().st_size
    except FileNotFoundError:
        raise InputError(f"{what} file not found", file=p) from None
    except OSError as exc:
        raise InputError(f"cannot read the {what} file: {exc.strerror or exc}", file=p) from None
    if p.is_dir():
        raise InputError(f"expected a {what} file, got a directory", file=p)
    if size > MAX_INPUT_BYTES:
        raise InputError(f"{what} file too large: {size} bytes (limit {MAX_INPUT_BYTES})", file=p)
    try:
        return p.read_bytes()
    except OSError as exc:
        raise InputError(f"cannot read the {what} file: {exc.strerror or exc}", file=p) from None


def _mandrel_from_profile(
    z: FloatArray, r: FloatArray, *, path: Path, source: str, lines: Sequence[int] | None = None,
    meta: dict[str, Any] | None = None,
) -> Mandrel:
    """Validate points, check the spline stays off the axis between them, build the mandrel."""
    file = str(path)
    for name, arr in (("z", z), ("r", r)):
        with np.errstate(invalid="ignore"):
            big = np.flatnonzero(np.isfinite(arr) & (np.abs(arr) > MAX_COORD_MM))
        if big.size:
            i = int(big[0])
            raise InputError(f"{name} = {arr[i]:g} mm is out of range (|{name}| <= {MAX_COORD_MM:g} mm); check the "
                             "units", file=file, line=None if lines is None else int(lines[i]), field=name)
    validate_points(z, r, file=file, lines=lines)
    dz = np.diff(z)
    i = int(np.argmin(dz))
    if dz[i] < 1e-9 * (z[-1] - z[0]) or z[-1] - z[0] < MIN_LENGTH_MM:
        if z[-1] - z[0] < MIN_LENGTH_MM:
            msg = f"the profile is only {z[-1] - z[0]:.3g} mm long (at least {MIN_LENGTH_MM:g} mm); check the units"
            raise InputError(msg, file=file, field="z")
        raise InputError(f"points {i + 1} and {i + 2} are too close: z = {z[i]:.17g} and {z[i + 1]:.17g} mm",
                         file=file, line=None if lines is None else int(lines[i + 1]), field="z")
    if r.max() < MIN_LENGTH_MM:
        raise InputError(f"the largest radius is {r.max():.3g} mm (at least {MIN_LENGTH_MM:g} mm); check the units",
                         file=file, field="r")
    decimated: dict[str, Any] | None = None
    if len(z) > MAX_SPLINE_POINTS:
        keep, err, tol = decimate_profile(z, r)
        decimated = {"points_in_file": int(len(z)), "points_kept": int(keep.size), "tolerance_mm": tol,
                     "max_deviation_mm": err}
        z, r = z[keep], r[keep]
        lines = [lines[i] for i in keep] if lines is not None else None
    _check_spline_off_axis(z, r, file=file, lines=lines)
    try:
        m = Mandrel.from_points(z, r, name=path.stem, source=source, file=file)
    except InputError as exc:
        raise exc.at(file=file) from None
    if meta:
        m.meta.update(meta)
    m.meta.setdefault("file", file)
    m.meta.setdefault("points", int(len(z)))
    if decimated is not None:
        m.meta["decimated"] = decimated
        dev = decimated["max_deviation_mm"]
        m.meta["note"] = (f"the profile's {decimated['points_in_file']} points were decimated to "
                          f"{decimated['points_kept']}: the spline passes within {dev:.3g} mm of every point "
                          f"(tolerance {decimated['tolerance_mm']:g} mm)")
    return m


def decimation_tolerance_mm(z: FloatArray, r: FloatArray) -> float:
    """Largest deviation allowed by :func:`decimate_profile`: 0.001 mm, or 1e-6 of the profile's size."""
    return max(1e-3, 1e-6 * float(max(np.ptp(z), np.max(np.abs(r)))))


def decimate_profile(z: FloatArray, r: FloatArray, tol_mm: float | None = None,
                     max_points: int = 20 * MAX_SPLINE_POINTS) -> tuple[NDArray[np.int64], float, float]:
    """Indices of a subset of the points whose cubic spline passes within ``tol_mm`` of all of them.

    Greedy refinement: start from :data:`MAX_SPLINE_POINTS` / 4 points evenly spread, then add, in
    every interval that deviates by more than ``tol_mm``, its worst point, until none does or
    ``max_points`` are kept (noisy data).  Returns ``(indices, max deviation mm, tol_mm)``; the
    end points are always kept.
    """
    from scipy.interpolate import CubicSpline

    n = len(z)
    tol = decimation_tolerance_mm(z, r) if tol_mm is None else float(tol_mm)
    keep = np.unique(np.linspace(0, n - 1, min(n, MAX_SPLINE_POINTS // 4)).round().astype(np.int64))
    err_max = math.inf
    for _ in range(64):
        spl = CubicSpline(z[keep], r[keep], bc_type="not-a-knot")
        err = np.abs(spl(z) - r)
        err_max = float(err.max())
        if err_max <= tol or keep.size >= max_points:
            break
        seg = np.searchsorted(keep, np.arange(n), side="right") - 1
        bad = err > tol
        if not bad.any():
            break
        idx = np.flatnonzero(bad)
        order = np.lexsort((-err[idx], seg[idx]))
        first = np.ones(order.size, dtype=bool)
        first[1:] = seg[idx][order][1:] != seg[idx][order][:-1]
        add = idx[order][first]
        keep = np.union1d(keep, add[: max(0, max_points - keep.size)])
    return keep, err_max, tol


def _check_spline_off_axis(z: FloatArray, r: FloatArray, *, file: str, lines: Sequence[int] | None) -> None:
    """The cubic spline through positive points can still dip to the axis between them: refuse that."""
    from scipy.interpolate import CubicSpline

    s = CubicSpline(z, r, bc_type="not-a-knot")
    k = 16
    t = np.linspace(0.0, 1.0, k + 1)[1:-1]
    zz = (z[:-1, None] + np.diff(z)[:, None] * t[None, :]).ravel()
    rr = s(zz)
    bad = np.flatnonzero(~(rr > 0))
    if bad.size:
        i = int(bad[0]) // (k - 1)
        where = f" between lines {lines[i]} and {lines[i + 1]}" if lines is not None else ""
        raise InputError(
            f"the generatrix intersects the axis inside the winding zone: the smooth curve through the points "
            f"reaches r = {rr[bad[0]]:.4g} mm at z = {zz[bad[0]]:.6g} mm{where}, between z = {z[i]:g} and "
            f"{z[i + 1]:g} mm; add points or move the profile away from the axis",
            file=file, line=None if lines is None else int(lines[i]), field="r")


# ================================================================================================
# CSV
# ================================================================================================
_NUM_RE = re.compile(r"[+-]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][+-]?\d+)?")
_NONFINITE_RE = re.compile(r"[+-]?(?:nan|inf|infinity)", re.IGNORECASE)
_Z_NAMES = {"z", "x", "axial", "axis", "position", "pos", "s"}
_R_NAMES = {"r", "y", "radius", "rad", "radial"}
_D_NAMES = {"d", "dia", "diameter", "diam"}
_UNIT_RE = re.compile(r"[\s_]*[\[(]?\s*mm\s*[\])]?$", re.IGNORECASE)
_UNITS_ROW_RE = re.compile(r"[\[(]?\s*mm\s*[\])]?|", re.IGNORECASE)


def _decode_text(data: bytes, file: str) -> str:
    if data.startswith((b"\xff\xfe", b"\xfe\xff")):
        try:
            return data.decode("utf-16")
        except UnicodeDecodeError:
            raise InputError("the file starts with a UTF-16 mark but is not valid UTF-16 text", file=file) from None
    if b"\x00" in data:
        off = data.index(b"\x00")
        line = data.count(b"\n", 0, off) + 1
        raise InputError(f"binary data (a NUL byte at offset {off}); expected a text table of z, r values",
                         file=file, line=line)
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        raise InputError(
            f"not UTF-8 text: byte 0x{data[exc.start]:02x} at offset {exc.start}; save the table as UTF-8 (or plain "
            "ASCII) text", file=file, line=line) from None


def _split_cells(text: str) -> tuple[list[str], str]:
    for sep, name in ((";", "semicolon"), ("\t", "tab"), (",", "comma")):
        if sep in text:
            return [c.strip() for c in text.split(sep)], name
    return text.split(), "blank"


def _column_role(name: str) -> str | None:
    n = _UNIT_RE.sub("", name.strip().strip("\"'").lower()).strip()
    if n in _Z_NAMES:
        return "z"
    if n in _R_NAMES:
        return "r"
    if n in _D_NAMES:
        return "d"
    return None


def _parse_number(cell: str, separator: str) -> float | None:
    c = cell.strip().strip("\"'")
    if _NUM_RE.fullmatch(c):
        return float(c)
    # a decimal comma is unambiguous when the cells are separated by something else
    if separator in ("semicolon", "tab", "blank") and re.fullmatch(r"[+-]?\d+,\d*(?:[eE][+-]?\d+)?", c):
        return float(c.replace(",", "."))
    return None


_FAST_CSV_BYTES = 1_000_000
_PLAIN_NUMBERS = re.compile(r"[0-9eE+\-.,;\t \r\n]*")


def _fast_csv_table(text: str) -> tuple[FloatArray, FloatArray, list[int]] | None:
    """(z, r, line numbers) of a large table that is a header ``z,r``-like line (optional) and rows of
    exactly two plain numbers, or None (then the general reader runs and names any bad cell)."""
    first, sep, body = text.partition("\n")
    head = 0
    if not _PLAIN_NUMBERS.fullmatch(first):
        cells = [c.strip().strip("\"'") for c in re.split(r"[,;\t ]+", first.strip())]
        roles = [_column_role(c) for c in cells]
        if roles != ["z", "r"]:
            return None
        head = 1
    else:
        body = text
    if not _PLAIN_NUMBERS.fullmatch(body):
        return None
    if ("," in body) and (";" in body or "\t" in body):
        return None  # a decimal comma is possible: the general reader decides
    rows = body.count("\n") + (0 if body.endswith("\n") else 1)
    if "\n\n" in body or body.startswith("\n") or "\r\n\r\n" in body:
        return None
    vals = np.fromstring(body.replace(",", " ").replace(";", " ").replace("\t", " "), sep=" ")  # C parser
    if vals.size != 2 * rows or rows < 4:
        return None
    tab = vals.reshape(rows, 2)
    return tab[:, 0].copy(), tab[:, 1].copy(), list(range(head + 1, head + rows + 1))


def load_csv(path: str | Path, smoothing_mm: float | None = None) -> Mandrel:
    """Read a generatrix table (z and r in mm) and return a C2 spline mandrel.

    Format: one point per line; cells separated by ``,``, ``;``, tab or blanks; decimal point (a
    decimal comma is accepted with ``;``/tab/blank separators); ``#`` starts a comment.  An
    optional header names the columns (``z``/``z_mm``/``x`` and ``r``/``r_mm``/``radius``, or
    ``d``/``diameter`` for a diameter column, any case, an optional ``(mm)``/``[mm]``).  Without a
    header the table has exactly two columns, z then r.

    Raises
    ------
    InputError
        Naming file, line and column: unreadable or binary file, empty table, a text or non-finite
        cell, a row with a missing or extra cell (e.g. a truncated last line), z not increasing,
        r <= 0 inside the zone (only the end points may sit on the axis), fewer than 4 points, or a
        smooth curve through the points that reaches the axis between them.
    """
    p = Path(path)
    file = str(p)
    text = _decode_text(_read_bytes(p, "CSV"), file)
    if len(text) > _FAST_CSV_BYTES:
        fast = _fast_csv_table(text)
        if fast is not None:  # a plain numeric table (a scan): parsed in C, same checks after
            z, r, line_nos = fast
            m = _mandrel_from_profile(z, r, path=p, source="csv", lines=line_nos)
            return smooth_profile(m, z, r, smoothing_mm, file=file) if smoothing_mm is not None else m
    ends_with_newline = text.endswith(("\n", "\r"))
    raw_lines = text.splitlines()
    if not any(ln.split("#", 1)[0].strip() for ln in raw_lines):
        raise InputError("empty file: no z, r rows found (expected lines like '0.0, 50.0')", file=file)

    names: list[str] | None = None
    iz = ir = -1
    diameter = False
    ncol = 0
    zs: list[float] = []
    rs: list[float] = []
    line_nos: list[int] = []
    last_data_line = max(i for i, ln in enumerate(raw_lines, 1) if ln.split("#", 1)[0].strip())
    for lineno, raw in enumerate(raw_lines, 1):
        body = raw.split("#", 1)[0].strip()
        if not body:
            continue
        cells, sep = _split_cells(body)
        if sep == "comma" and cells and cells[-1] == "" and len(cells) > 1:
            cells = cells[:-1]  # tolerate one trailing comma
        values = [_parse_number(c, sep) for c in cells]
        truncated = lineno == last_data_line and not ends_with_newline
        if (names is not None and not zs and "mm" in body.lower()
                and all(_UNITS_ROW_RE.fullmatch(c.strip().strip("\"'")) for c in cells)):
            continue  # a row of units under the header, e.g. "mm, mm"
        if names is None and not zs:
            # first row: a header if no cell is a number (a row mixing numbers and text is bad data)
            if all(v is None for v in values) and not any(_NONFINITE_RE.fullmatch(c.strip()) for c in cells):
                roles = [_column_role(c) for c in cells]
                if roles.count("z") != 1 or (roles.count("r") + roles.count("d")) != 1:
                    raise InputError(
                        f"cannot read the header {body!r}: it must name one axial column (z, z_mm, x) and one "
                        "radius column (r, r_mm, radius, or d/diameter)", file=file, line=lineno)
                names = [c.strip().strip("\"'") for c in cells]
                iz = roles.index("z")
                if "r" in roles:
                    ir = roles.index("r")
                else:
                    ir, diameter = roles.index("d"), True
                ncol = len(cells)
                continue
            if len(cells) != 2:
                if len(cells) < 2:
                    msg = (f"the row has only 1 cell ({body!r}); expected 2 (z, r)"
                           + (" - the file seems cut off" if truncated else ""))
                    raise InputError(msg, file=file, line=lineno, field="r")
                raise InputError(
                    f"the row has {len(cells)} cells but the table has no header; give a header naming the z and r "
                    "columns, or keep two columns (z, r)", file=file, line=lineno)
            names = ["z", "r"]
            iz, ir, ncol = 0, 1, 2
        if len(cells) != ncol:
            missing = len(cells) < ncol
            msg = (f"the row has {len(cells)} cell{'s' if len(cells) != 1 else ''}, expected {ncol} "
                   f"({', '.join(names)})")
            if missing and truncated:
                msg += " - the last line is incomplete, the file seems cut off"
            col = len(cells) + 1 if missing else ncol + 1
            raise InputError(msg, file=file, line=lineno,
                             field=f"{names[col - 1]} (column {col})" if missing else f"column {col}")
        for j in (iz, ir):
            if values[j] is None:
                cell = cells[j]
                col = f"{names[j]} (column {j + 1})"
                if _NONFINITE_RE.fullmatch(cell.strip().strip("\"'")):
                    raise InputError(f"{cell!r} is not a finite number", file=file, line=lineno, field=col)
                hint = ""
                if truncated:
                    hint = " - the last line is incomplete, the file seems cut off"
                elif "," in cell:
                    hint = " (use a decimal point)"
                elif cell == "":
                    hint = " (empty cell)"
                raise InputError(f"{cell!r} is not a number{hint}", file=file, line=lineno, field=col)
        zs.append(float(values[iz]))  # type: ignore[arg-type]
        rv = float(values[ir])  # type: ignore[arg-type]
        rs.append(0.5 * rv if diameter else rv)
        line_nos.append(lineno)

    if names is None:  # pragma: no cover - a non-empty file always sets it
        raise InputError("no z, r rows found", file=file)
    z = np.asarray(zs, dtype=float)
    r = np.asarray(rs, dtype=float)
    if len(z) < 4:
        raise InputError(f"too few points: {len(z)} row{'s' if len(z) != 1 else ''}; a C2 generatrix needs at "
                         "least 4", file=file, line=line_nos[-1] if line_nos else None)
    # errors from validation should name the CSV column
    try:
        m = _mandrel_from_profile(z, r, path=p, source="csv", lines=line_nos)
        if smoothing_mm is not None:
            m = smooth_profile(m, z, r, smoothing_mm, file=file)
        return m
    except InputError as exc:
        f = exc.location.field
        if f in ("z", "r"):
            j = iz if f == "z" else ir
            exc = InputError(exc.message, file=exc.location.file, line=exc.location.line,
                             field=f"{names[j]} (column {j + 1})")
        raise exc from None


# ================================================================================================
# DXF
# ================================================================================================
_DXF_CURVES = ("LINE", "ARC", "LWPOLYLINE", "POLYLINE", "SPLINE", "ELLIPSE")


@dataclass
class _Piece:
    """A polyline in the (z, r) plane from one drawing entity (or a part of it)."""

    pts: FloatArray  # (n, 2): z, r
    label: str  # e.g. "LINE #2F on layer 'PROFILE'"


def _entity_label(e: Any) -> str:
    try:
        return f"{e.dxftype()} #{e.dxf.handle} on layer '{e.dxf.layer}'"
    except Exception:  # noqa: BLE001 - only for a message
        return "an entity"


def _describe_entities(entities: Iterable[Any], limit: int = 8) -> str:
    from collections import Counter

    cnt: Counter[str] = Counter()
    examples: dict[str, str] = {}
    for e in entities:
        try:
            t = e.dxftype()
        except Exception:  # noqa: BLE001
            t = "?"
        cnt[t] += 1
        examples.setdefault(t, _entity_label(e))
    if not cnt:
        return "model space is empty"
    parts = [f"{n} {t}" for t, n in cnt.most_common(limit)]
    ex = "; e.g. " + ", ".join(examples[t] for t, _ in cnt.most_common(3))
    return "model space holds " + ", ".join(parts) + ex


MAX_DXF_TAGS = 250_000
"""Most DXF tags (group code + value, two lines) read: the example profile drawing has 1 800; the DXF
reader is pure Python (ezdxf) and needs seconds per 100 000 tags."""


def load_dxf(path: str | Path) -> Mandrel:
    """Read a generatrix drawn in a DXF file and return a C2 spline mandrel.

    The profile is taken from model space: LINE, ARC, LWPOLYLINE (with bulges), POLYLINE,
    SPLINE and ELLIPSE entities (also inside block references), x = axial z, y = radius, in mm
    (``$INSUNITS`` inch, foot, cm and dm are converted; unitless, mm and metre are read as mm,
    because metre is the default many writers put in every drawing).  If a layer named
    ``PROFILE``, ``GENERATRIX`` or ``MANDREL`` exists, only its entities are used.  Curves are
    flattened finely (exact points on arcs, ellipses and splines); parts on the axis (y ≈ 0) or
    below it and segments perpendicular to the axis (end faces) are dropped; what remains must be
    one chain that is a function of z (no overhang, no step, no gap).

    Raises
    ------
    InputError
        Naming the file and what was found (entity types, handles, layers) when there is no usable
        profile, or where the profile goes backwards, steps or has a gap.
    """
    p = Path(path)
    file = str(p)
    data = _read_bytes(p, "DXF")
    if not data.strip():
        raise InputError("empty file: not a DXF drawing", file=file)
    tags = (data.count(b"\n") + 1) // 2  # a DXF tag is two lines (cheap, in C)
    if tags > MAX_DXF_TAGS:
        raise InputError(f"the drawing has {tags} tags, more than {MAX_DXF_TAGS} (reading it would take minutes); "
                         "draw the profile alone as one polyline or spline, or export it as a CSV table", file=file)
    doc = _read_dxf_doc(p, data)
    try:
        msp = doc.modelspace()
        entities = list(msp)
    except Exception as exc:  # noqa: BLE001 - anything the parser chokes on is bad input
        raise InputError(f"cannot read the model space of the DXF drawing ({type(exc).__name__}: {exc})",
                         file=file) from None
    scale = _dxf_scale(doc)
    try:
        pieces, ignored, curves = _dxf_pieces(entities, scale)
    except InputError as exc:
        raise exc.at(file=file) from None
    except Exception as exc:  # noqa: BLE001
        raise InputError(f"cannot interpret the DXF geometry ({type(exc).__name__}: {exc})", file=file) from None
    if not curves:
        raise InputError(
            "no profile found: expected LINE/ARC/LWPOLYLINE/POLYLINE/SPLINE entities in model space (x = axial z, "
            f"y = radius); {_describe_entities(entities)}", file=file)
    meta = {"dxf_entities": [_entity_label(e) for e in curves][:50], "dxf_scale_to_mm": scale}
    exact, why = _dxf_exact_segments(curves, scale)
    if exact is not None:
        try:
            m = Mandrel(tuple(exact), name=p.stem, source="dxf")
        except InputError:
            m = None
            why = "the exact segments do not form a valid generatrix"
        if m is not None:
            m.meta.update(meta)
            m.meta.update({"file": file, "dxf_exact": True, "segments": len(exact)})
            return m
    try:
        z, r = _profile_from_pieces(pieces, curves)
    except InputError as exc:
        raise exc.at(file=file) from None
    meta["dxf_exact"] = False
    meta["dxf_spline_reason"] = why
    return _mandrel_from_profile(z, r, path=p, source="dxf", meta=meta)


DXF_TANGENCY_TOL_RAD = 1e-6
"""Largest angle between drawn segments at a joint that still counts as tangent (exact DXF import)."""


MIN_BULGE = 1e-9
"""Polyline bulges smaller than this (tan of a quarter of the arc angle) are straight segments: an arc of
radius ~ chord / (4 bulge) beyond 1e9 chords is a line drawn with noise (ezdxf turned a bulge of 1e-110
into an arc of no length, or overflowed)."""


def _dxf_parts(e: Any) -> list[Any]:
    """The LINE/ARC parts of a LINE, ARC, LWPOLYLINE or POLYLINE entity; negligible bulges straightened."""
    t = e.dxftype()
    if t == "LWPOLYLINE":
        with e.points("xyseb") as pts:
            for i, p in enumerate(pts):
                if abs(p[4]) < MIN_BULGE:
                    pts[i] = (p[0], p[1], p[2], p[3], 0.0)
    elif t == "POLYLINE":
        for v in e.vertices:
            if abs(float(v.dxf.get("bulge", 0.0))) < MIN_BULGE:
                v.dxf.bulge = 0.0
    else:
        return [e]
    return list(e.virtual_entities())


def _dxf_exact_segments(curves: list[Any], scale: float) -> tuple[list[Segment] | None, str]:
    """The profile as exact line and arc segments, if it is drawn only with LINE, ARC and (bulged)
    polylines, joined end to end and tangentially; else (None, why) and the caller fits a spline."""
    raw: list[tuple[str, FloatArray, FloatArray, Any]] = []  # kind, start, end (z increasing), extra
    for e in curves:
        parts = _dxf_parts(e)
        for part in parts:
            pt = part.dxftype()
            if pt == "LINE":
                a = np.array([part.dxf.start.x, part.dxf.start.y]) * scale
                b = np.array([part.dxf.end.x, part.dxf.end.y]) * scale
                raw.append(("line", a, b, None))
            elif pt == "ARC":
                c = np.array([part.dxf.center.x, part.dxf.center.y]) * scale
                rad = float(part.dxf.radius) * scale
                t0, t1 = math.radians(part.dxf.start_angle), math.radians(part.dxf.end_angle)
                sweep = (t1 - t0) % (2.0 * math.pi)
                a = c + rad * np.array([math.cos(t0), math.sin(t0)])
                b = c + rad * np.array([math.cos(t0 + sweep), math.sin(t0 + sweep)])
                mid = t0 + 0.5 * sweep
                raw.append(("arc", a, b, (c, rad, t0, sweep, 1 if math.sin(mid) > 0 else -1)))
            else:
                return None, f"{_entity_label(part)} is not a line or an arc"
    if not raw:
        return None, "no lines or arcs"
    allp = np.concatenate([[a, b] for _, a, b, _ in raw])
    extent = max(float(np.ptp(allp[:, 0])), float(np.ptp(allp[:, 1])), 1e-9)
    tol = 1e-6 * extent
    segs: list[tuple[float, float, Segment]] = []
    for kind, a, b, extra in raw:
        if abs(a[0] - b[0]) <= tol and kind == "line":
            continue  # an end face
        if a[1] <= tol and b[1] <= tol and kind == "line":
            continue  # the axis
        if min(a[1], b[1]) < -tol:
            return None, "geometry below the axis"
        if a[0] > b[0]:
            a, b = b, a
        if kind == "line":
            segs.append((a[0], b[0], LineSegment(float(a[0]), float(b[0]), float(a[1]), float(b[1]))))
            continue
        c, rad, t0, sweep, side = extra
        # the arc must not pass a vertical tangent (angle 0 or π) inside: it would turn back along z
        for v in (0.0, math.pi):
            inner = ((v - t0) % (2.0 * math.pi))
            if 1e-9 < inner < sweep - 1e-9:
                return None, "an arc passes a vertical tangent"
        if (side > 0 and min(a[1], b[1]) < c[1] - tol) or (side < 0 and max(a[1], b[1]) > c[1] + tol):
            return None, "an arc is not a function of z"
        segs.append((a[0], b[0], ArcSegment(float(a[0]), float(b[0]), zc=float(c[0]), rc=float(c[1]), a=rad,
                                            side=int(side))))
    if not segs:
        return None, "only end faces and the axis"
    segs.sort(key=lambda s: s[0])
    out: list[Segment] = []
    for k, (z0, _z1, seg) in enumerate(segs):
        if k:
            prev = out[-1]
            if abs(z0 - prev.z1) > tol:
                return None, f"a gap or overlap at z = {z0:.6g} mm"
            r_prev = float(prev.eval(np.array([prev.z1]))[0][0])
            r_here = float(seg.eval(np.array([z0]))[0][0])
            if abs(r_prev - r_here) > tol:
                return None, f"a step at z = {z0:.6g} mm"
            s_prev = float(prev.eval(np.array([prev.z1]))[1][0])
            s_here = float(seg.eval(np.array([z0]))[1][0])
            if abs(math.atan(s_prev) - math.atan(s_here)) > DXF_TANGENCY_TOL_RAD:
                return None, (f"a corner at z = {z0:.6g} mm (slopes {s_prev:.6g} and {s_here:.6g}); a spline fit "
                              "rounds it")
            z0 = prev.z1  # snap the joint
            if isinstance(seg, LineSegment):
                seg = LineSegment(z0, seg.z1, r_prev, seg.r1)
            else:
                assert isinstance(seg, ArcSegment)
                seg = ArcSegment(z0, seg.z1, zc=seg.zc, rc=seg.rc, a=seg.a, side=seg.side)
        if not seg.z1 > seg.z0:
            return None, "a zero-length segment"
        out.append(seg)
    return out, ""


def export_dxf(mandrel: Mandrel, path: str | Path) -> Path:
    """Write the generatrix as a DXF profile (x = axial z, y = radius, mm) on layer PROFILE.

    Lines and circle arcs are written exactly (LINE, ARC), so :func:`load_dxf` reads them back as the
    same segments; other segments as fit-point SPLINEs through 64 points each.
    """
    import ezdxf

    doc = ezdxf.new("R2010")
    doc.header["$INSUNITS"] = 4  # mm
    doc.layers.add("PROFILE")
    msp = doc.modelspace()
    att = {"layer": "PROFILE"}
    for s in mandrel.segments:
        if isinstance(s, LineSegment):
            msp.add_line((s.z0, s.r0), (s.z1, s.r1), dxfattribs=att)
        elif isinstance(s, ArcSegment):
            r0 = float(s.eval(np.array([s.z0]))[0][0])
            r1 = float(s.eval(np.array([s.z1]))[0][0])
            a0 = math.degrees(math.atan2(r0 - s.rc, s.z0 - s.zc))
            a1 = math.degrees(math.atan2(r1 - s.rc, s.z1 - s.zc))
            start, end = (a1, a0) if s.side > 0 else (a0, a1)  # DXF arcs run counter-clockwise
            msp.add_arc((s.zc, s.rc), s.a, start, end, dxfattribs=att)
        else:
            z = np.linspace(s.z0, s.z1, 64)
            r = s.eval(z)[0]
            msp.add_spline(fit_points=[(float(a), float(b), 0.0) for a, b in zip(z, r)], dxfattribs=att)
    out = Path(path)

    def write(tmp: str) -> None:
        doc.saveas(tmp)

    return atomic_write_with(out, write)


def _read_dxf_doc(p: Path, data: bytes) -> Any:
    import logging

    import ezdxf
    from ezdxf import recover

    file = str(p)
    head = data[:4096]
    if b"\x00" in head and not head.startswith(b"AutoCAD Binary DXF"):
        raise InputError("binary data that is not a DXF drawing (export the profile as an ASCII DXF)", file=file)
    logger = logging.getLogger("ezdxf")
    old = logger.level
    logger.setLevel(logging.CRITICAL)  # recovery chatter is not for the user
    try:
        try:
            doc, auditor = recover.read(io.BytesIO(data))
        except ezdxf.DXFStructureError as exc:
            raise InputError(f"not a readable DXF drawing: {exc}", file=file) from None
        except (UnicodeError, ValueError, TypeError, IndexError, KeyError, AttributeError, EOFError, OSError,
                AssertionError, RecursionError) as exc:
            raise InputError(f"not a readable DXF drawing ({type(exc).__name__}: {exc})", file=file) from None
    except InputError:
        raise
    except Exception as exc:  # noqa: BLE001 - the parser sees arbitrary bytes
        raise InputError(f"not a readable DXF drawing ({type(exc).__name__}: {exc})", file=file) from None
    finally:
        logger.setLevel(old)
    if auditor.has_errors:
        msgs = "; ".join(str(e.message) for e in auditor.errors[:3])
        raise InputError(f"the DXF drawing is damaged: {msgs}", file=file)
    return doc


# $INSUNITS honoured: inch, foot, cm, dm.  Unitless, mm and metre are read as mm: metre is the default
# that ezdxf and several other writers put in every new drawing, whatever the user drew in.
_DXF_UNITS_MM = {1: 25.4, 2: 304.8, 5: 10.0, 14: 100.0}


def _dxf_scale(doc: Any) -> float:
    """Factor from drawing units to mm (see ``_DXF_UNITS_MM``)."""
    try:
        return _DXF_UNITS_MM.get(int(doc.header.get("$INSUNITS", 0)), 1.0)
    except Exception:  # noqa: BLE001 - an unreadable unit code: assume mm
        return 1.0


def _dxf_pieces(entities: list[Any], scale: float) -> tuple[list[_Piece], list[Any], list[Any]]:
    """Flatten the usable entities into polylines in (z, r); return (pieces, ignored, used entities)."""
    from ezdxf import path as dxfpath

    flat: list[Any] = []
    for e in entities:
        t = e.dxftype()
        if t == "INSERT":
            try:
                flat.extend(v for v in e.virtual_entities() if v.dxftype() in _DXF_CURVES)
            except Exception:  # noqa: BLE001 - a broken block reference is skipped
                continue
        else:
            flat.append(e)
    curves = [e for e in flat if e.dxftype() in _DXF_CURVES]
    ignored = [e for e in flat if e.dxftype() not in _DXF_CURVES]
    layers = {}
    for e in curves:
        layers.setdefault(str(e.dxf.layer).upper(), []).append(e)
    for name in ("PROFILE", "GENERATRIX", "MANDREL"):
        if name in layers:
            curves = layers[name]
            break
    # extent, for the flattening tolerance
    boxes = []
    for e in curves:
        try:
            bb = dxfpath.bbox([dxfpath.make_path(e)], fast=True)
        except Exception as exc:  # noqa: BLE001
            raise InputError(f"cannot read {_entity_label(e)} ({type(exc).__name__}: {exc})") from None
        if bb.has_data:
            boxes.append((bb.extmin, bb.extmax))
    if not boxes:
        return [], ignored, curves
    lo = np.min([[b[0].x, b[0].y] for b in boxes], axis=0)
    hi = np.max([[b[1].x, b[1].y] for b in boxes], axis=0)
    extent = float(np.max(hi - lo))
    if not math.isfinite(extent) or extent * scale > MAX_COORD_MM:
        raise InputError(f"the drawing is {extent * scale:.3g} mm across, more than {MAX_COORD_MM:g} mm; check the "
                         "units and stray entities far from the profile")
    extent = max(extent, 1e-9)
    distance = 1e-9 * extent  # chords this close to the curve may later be subdivided linearly
    pieces = []
    for e in curves:
        label = _entity_label(e)
        try:
            parts = _dxf_parts(e)
            for part in parts:
                pt = part.dxftype()
                if pt == "LINE":
                    verts = [part.dxf.start, part.dxf.end]
                elif pt == "ARC":  # exact points on the circle (ezdxf paths would use Bezier arcs)
                    verts = list(part.flattening(sagitta=distance))
                elif pt == "SPLINE":  # flattened in the drawing plane (z dropped, as for every other point)
                    verts = _bounded(_planar_bspline(part).flattening(distance, segments=16), label)
                elif pt == "ELLIPSE":
                    verts = _bounded(part.flattening(distance, segments=16), label)
                else:
                    continue
                v = np.array([(q.x, q.y) for q in verts], dtype=float)
                if len(v) >= 2 and np.isfinite(v).all():
                    pieces.append(_Piece(v * scale, label))
        except InputError:
            raise
        except Exception as exc:  # noqa: BLE001
            raise InputError(f"cannot flatten {label} ({type(exc).__name__}: {exc})") from None
    return pieces, ignored, curves


MAX_FLATTEN_POINTS = 200_000
"""Most points one DXF curve may flatten into (an adaptive subdivision that does not converge, e.g. on
a spline with a control point far off the drawing plane, is refused instead of running for hours)."""


def _planar_bspline(spline: Any) -> Any:
    """The B-spline of a DXF SPLINE with its control points projected on the drawing plane (z = 0): the
    profile uses x and y only, and a control point far out of the plane would make the adaptive
    flattening subdivide without end (its distances are measured in 3D)."""
    from ezdxf.math import BSpline

    tool = spline.construction_tool()
    knots = np.asarray(list(spline.knots), dtype=float)  # as written in the file
    if knots.size and not (np.isfinite(knots).all() and (np.diff(knots) >= 0).all() and knots[-1] > knots[0]):
        i = int(np.flatnonzero(~np.isfinite(knots) | np.r_[False, np.diff(knots) < 0])[0]) if not (
            np.isfinite(knots).all() and (np.diff(knots) >= 0).all()) else knots.size - 1
        raise InputError(f"{_entity_label(spline)}: its knot vector is not finite and increasing (knot {i + 1} of "
                         f"{knots.size} is {knots[i]:g})")
    return BSpline([(p.x, p.y, 0.0) for p in tool.control_points], order=tool.order, knots=tool.knots(),
                   weights=tool.weights() or None)


def _bounded(points: Any, label: str) -> list[Any]:
    """At most :data:`MAX_FLATTEN_POINTS` points of a flattening generator, else an InputError."""
    import itertools

    out = list(itertools.islice(points, MAX_FLATTEN_POINTS + 1))
    if len(out) > MAX_FLATTEN_POINTS:
        raise InputError(f"{label} flattens into more than {MAX_FLATTEN_POINTS} points within the drawing's "
                         "tolerance (a degenerate curve); redraw or simplify it")
    return out


def _profile_from_pieces(pieces: list[_Piece], curves: list[Any]) -> tuple[FloatArray, FloatArray]:
    """Turn flattened pieces into one z-monotone chain of points (z increasing)."""
    if not pieces:
        raise InputError(f"no profile geometry: the curves have no length ({_describe_entities(curves)})")
    allp = np.concatenate([pc.pts for pc in pieces])
    extent = max(float(np.ptp(allp[:, 0])), float(np.ptp(allp[:, 1])), 1e-9)
    tol = 1e-6 * extent  # geometric tolerance (joins, axis, perpendicular faces)
    # split into edges, keep those off the axis and not perpendicular to it
    chains: list[tuple[FloatArray, str]] = []
    dropped_vertical: list[tuple[float, float, float, str]] = []
    n_axis = n_below = 0
    for pc in pieces:
        q = pc.pts
        keep_edge = np.ones(len(q) - 1, dtype=bool)
        dz = np.diff(q[:, 0])
        seglen = np.hypot(dz, np.diff(q[:, 1]))
        on_axis = (np.abs(q[:-1, 1]) <= tol) & (np.abs(q[1:, 1]) <= tol)
        below = (q[:-1, 1] < -tol) | (q[1:, 1] < -tol)
        vertical = np.abs(dz) <= max(tol, 1e-9 * extent) + 1e-12 * seglen
        zero = seglen <= 1e-12 * extent
        keep_edge &= ~(on_axis | below | vertical | zero)
        n_axis += int(np.count_nonzero(on_axis & ~zero))
        n_below += int(np.count_nonzero(below & ~on_axis & ~zero))
        for k in np.flatnonzero(vertical & ~on_axis & ~below & ~zero):
            dropped_vertical.append((float(q[k, 0]), float(min(q[k, 1], q[k + 1, 1])),
                                     float(max(q[k, 1], q[k + 1, 1])), pc.label))
        # runs of kept edges become chains
        idx = np.flatnonzero(keep_edge)
        if idx.size == 0:
            continue
        breaks = np.flatnonzero(np.diff(idx) > 1)
        for run in np.split(idx, breaks + 1):
            pts = q[run[0]: run[-1] + 2]
            d = np.diff(pts[:, 0])
            if (d > 0).all():
                chains.append((pts, pc.label))
            elif (d < 0).all():
                chains.append((pts[::-1], pc.label))
            else:
                k = int(np.flatnonzero(np.sign(d) != np.sign(d[0]))[0])
                zt = pts[k, 0]
                raise InputError(
                    f"the profile is not a function of z: {pc.label} turns back along the axis at z = {zt:.6g} "
                    f"mm, r = {pts[k, 1]:.6g} mm (an overhang); the generatrix must run monotonically along x")
    if not chains:
        found = _describe_entities(curves)
        raise InputError(
            f"no profile above the axis: of the drawn segments {len(dropped_vertical)} are perpendicular to the axis "
            f"(end faces), {n_axis} lie on the axis (y = 0) and {n_below} below it (y < 0), none is left for the "
            f"generatrix (x = axial z, y = radius > 0); {found}")
    chains.sort(key=lambda c: c[0][0, 0])
    zs = [chains[0][0]]
    for (prev, plab), (cur, clab) in zip(chains[:-1], chains[1:]):
        zp, rp = prev[-1]
        zc, rc = cur[0]
        if zc < zp - tol:
            raise InputError(
                f"the profile is not a function of z: {clab} starts at z = {zc:.6g} mm inside the z range of "
                f"{plab} (which ends at z = {zp:.6g} mm); two curves cover the same z (overhang or duplicate)")
        if zc > zp + tol:
            raise InputError(
                f"the profile has a gap between z = {zp:.6g} mm ({plab}) and z = {zc:.6g} mm ({clab}); the "
                "curves must join end to end")
        if abs(rc - rp) > tol:
            raise InputError(
                f"the profile steps from r = {rp:.6g} to {rc:.6g} mm at z = {zc:.6g} mm (a face perpendicular to "
                f"the axis inside the winding zone, between {plab} and {clab}); the generatrix must be smooth")
        zs.append(cur[1:])
    pts = np.concatenate(zs)
    return _resample_chain(pts[:, 0], pts[:, 1])


def _resample_chain(z: FloatArray, r: FloatArray, n: int = _PROFILE_POINTS) -> tuple[FloatArray, FloatArray]:
    """Make the point spacing usable for a C2 spline.

    Long straight chords (lines, polyline segments) are subdivided so that no z gap exceeds
    ``length / n`` (points on a straight chord lie on the drawn line).  Very dense runs of points
    are thinned to an arc-length spacing of ``length / (2 n)``, except where the curve turns by more
    than 0.01 rad between kept points (tight bends keep their points).  Both ends are kept.
    """
    length = float(z[-1] - z[0])
    h = length / n
    out_z = [z[:1]]
    out_r = [r[:1]]
    for i in range(len(z) - 1):
        k = max(1, int(math.ceil((z[i + 1] - z[i]) / h - 1e-9)))
        t = np.arange(1, k + 1) / k
        out_z.append(z[i] + (z[i + 1] - z[i]) * t)
        out_r.append(r[i] + (r[i + 1] - r[i]) * t)
    zz = np.concatenate(out_z)
    rr = np.concatenate(out_r)
    if len(zz) < 3:
        return zz, rr
    s = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(zz), np.diff(rr)))])
    ang = np.arctan2(np.diff(rr), np.diff(zz))  # direction of each chord
    turn = np.concatenate([[0.0, 0.0], np.cumsum(np.abs(np.angle(np.exp(1j * np.diff(ang)))))])
    # keep the first point of every arc-length bucket of h/8 and of every 0.01 rad of turning
    bucket_s = np.floor(s / (h / 2.0))
    bucket_t = np.floor(turn / 0.01)
    keep = np.flatnonzero(np.diff(bucket_s) != 0) + 1
    keep = np.union1d(keep, np.flatnonzero(np.diff(bucket_t) != 0) + 1)
    keep = keep[(keep > 0) & (keep < len(zz) - 1) & (s[-1] - s[keep] >= 1e-3 * h)]
    keep = np.concatenate([[0], keep, [len(zz) - 1]])
    return zz[keep], rr[keep]


# ================================================================================================
# STEP / STL export
# ================================================================================================
def _bspline_graph_edge(seg: Segment, tol: float, tol_dense: float) -> Any:
    """A cubic B-spline edge x = r(z), z = z in the XZ plane for any segment.

    Exact for spline segments of up to ``_EXACT_SPLINE_POINTS`` points; within ``tol_dense`` (mm)
    for denser splines (imported profiles: fewer knots keep the STEP small and fast to mesh); within
    ``tol`` (mm) for other segments.  x(u) = u exactly: the z coordinates of the poles are the
    Greville abscissae of the knots.
    """
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeEdge
    from OCP.Geom import Geom_BSplineCurve
    from OCP.gp import gp_Pnt
    from OCP.TColgp import TColgp_Array1OfPnt
    from OCP.TColStd import TColStd_Array1OfInteger, TColStd_Array1OfReal
    from scipy.interpolate import make_interp_spline

    if isinstance(seg, SplineSegment) and len(seg.z_pts) <= _EXACT_SPLINE_POINTS:
        # the same not-a-knot cubic as the segment: exact
        pts = np.asarray(seg.z_pts, dtype=float)
        bs = make_interp_spline(pts, np.asarray(seg.r_pts, dtype=float), k=3)
    else:
        if isinstance(seg, SplineSegment):  # a dense imported profile: fewer knots, within tol_dense
            pts = np.asarray(seg.z_pts, dtype=float)
            nodes = np.unique(np.concatenate([pts[:: max(1, len(pts) // 128)], pts[-1:]]))
            tt = np.linspace(0.0, 1.0, 4)[:-1]
            zc = (pts[:-1, None] + np.diff(pts)[:, None] * tt[None, :]).ravel()
            tol = max(tol, tol_dense)
        else:
            nodes = _initial_nodes(seg)
            zc = None
        r_check = None
        for _ in range(24):
            bs = make_interp_spline(nodes, seg.eval(nodes)[0], k=3)
            tt = np.linspace(0.0, 1.0, 5)[1:-1]
            zm = (nodes[:-1, None] + np.diff(nodes)[:, None] * tt[None, :]).ravel()
            if zc is not None:
                zm = np.concatenate([zm, zc])
            if r_check is None or len(r_check) != len(zm):
                r_check = seg.eval(zm)[0]
            err = np.abs(bs(zm) - r_check)
            idx = np.clip(np.searchsorted(nodes, zm, side="right") - 1, 0, len(nodes) - 2)
            bad = np.unique(idx[err > tol])
            if bad.size == 0:
                break
            nodes = np.sort(np.concatenate([nodes, 0.5 * (nodes[bad] + nodes[bad + 1])]))
    t, c = np.asarray(bs.t, dtype=float), np.asarray(bs.c, dtype=float)
    deg = 3
    greville = np.array([t[i + 1: i + deg + 1].mean() for i in range(len(c))])
    poles = TColgp_Array1OfPnt(1, len(c))
    for i, (zc, rc) in enumerate(zip(greville, c), 1):
        poles.SetValue(i, gp_Pnt(float(rc), 0.0, float(zc)))
    uk, mult = np.unique(t, return_counts=True)
    knots = TColStd_Array1OfReal(1, len(uk))
    mults = TColStd_Array1OfInteger(1, len(uk))
    for i, (u, m) in enumerate(zip(uk, mult), 1):
        knots.SetValue(i, float(u))
        mults.SetValue(i, int(m))
    curve = Geom_BSplineCurve(poles, knots, mults, deg)
    return BRepBuilderAPI_MakeEdge(curve).Edge()


def _initial_nodes(seg: Segment) -> FloatArray:
    from engine.mandrel import IsotensoidSegment

    if isinstance(seg, IsotensoidSegment):
        # uniform in the smooth parameter t (clusters nodes where the meridian bends most)
        t = np.linspace(0.0, math.pi, 97)
        zeta = np.polynomial.chebyshev.chebval(t * (2.0 / math.pi) - 1.0, seg._series(seg.rho_p)[0])
        z = seg.zc + seg.direction * seg.R * zeta
        z = np.sort(z)
        z[0], z[-1] = seg.z0, seg.z1
        return np.unique(z)
    return np.linspace(seg.z0, seg.z1, 33)


def _segment_edge(seg: Segment, tol: float, tol_dense: float) -> Any:
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeEdge
    from OCP.GC import GC_MakeArcOfCircle, GC_MakeArcOfEllipse, GC_MakeSegment
    from OCP.gp import gp_Ax2, gp_Dir, gp_Elips, gp_Pnt

    def pnt(z: float) -> Any:
        r = float(seg.eval(np.array([z]))[0][0])
        return gp_Pnt(max(r, 0.0), 0.0, float(z))

    if isinstance(seg, LineSegment):
        return BRepBuilderAPI_MakeEdge(GC_MakeSegment(pnt(seg.z0), pnt(seg.z1)).Value()).Edge()
    if isinstance(seg, ArcSegment):
        zm = 0.5 * (seg.z0 + seg.z1)
        arc = GC_MakeArcOfCircle(pnt(seg.z0), pnt(zm), pnt(seg.z1)).Value()
        return BRepBuilderAPI_MakeEdge(arc).Edge()
    if isinstance(seg, EllipseSegment):
        if seg.a >= seg.b:
            ax = gp_Ax2(gp_Pnt(0, 0, seg.zc), gp_Dir(0, 1, 0), gp_Dir(0, 0, 1))
            el = gp_Elips(ax, seg.a, seg.b)
        else:
            ax = gp_Ax2(gp_Pnt(0, 0, seg.zc), gp_Dir(0, 1, 0), gp_Dir(1, 0, 0))
            el = gp_Elips(ax, seg.b, seg.a)
        for pa, pb in ((pnt(seg.z0), pnt(seg.z1)), (pnt(seg.z1), pnt(seg.z0))):
            arc = GC_MakeArcOfEllipse(el, pa, pb, True).Value()
            mid = arc.Value(0.5 * (arc.FirstParameter() + arc.LastParameter()))
            if mid.X() > 0:
                return BRepBuilderAPI_MakeEdge(arc).Edge()
        raise RuntimeError("could not orient the ellipse arc")  # pragma: no cover
    return _bspline_graph_edge(seg, tol, tol_dense)


def mandrel_solid(mandrel: Mandrel) -> Any:
    """The mandrel as an OCP ``TopoDS_Solid``: the closed profile revolved 360° about the Z axis.

    The generatrix uses exact lines, circle and ellipse arcs where the segments are analytic, and
    cubic B-splines x = r(z) elsewhere: exact for spline segments of up to 400 points, within 1e-7
    of the size for denser (imported) splines, within 1e-9 of the size for isotensoid and
    smooth-step segments.  Coordinates in mm; the solid axis is Z.
    """
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeEdge, BRepBuilderAPI_MakeFace, BRepBuilderAPI_MakeWire
    from OCP.BRepCheck import BRepCheck_Analyzer
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeRevol
    from OCP.GC import GC_MakeSegment
    from OCP.gp import gp_Ax1, gp_Dir, gp_Pnt
    from OCP.TopAbs import TopAbs_SOLID
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS

    scale = max(mandrel.r_max, mandrel.length)
    tol = 1e-9 * scale
    wire = BRepBuilderAPI_MakeWire()
    for seg in mandrel.segments:
        wire.Add(_segment_edge(seg, tol, 1e-7 * scale))
    r0, r1 = mandrel.pole_radii
    z0, z1 = mandrel.z_min, mandrel.z_max
    close_tol = 1e-9 * scale

    def line(a: tuple[float, float], b: tuple[float, float]) -> None:
        seg = GC_MakeSegment(gp_Pnt(a[0], 0.0, a[1]), gp_Pnt(b[0], 0.0, b[1])).Value()
        wire.Add(BRepBuilderAPI_MakeEdge(seg).Edge())

    if r1 > close_tol:
        line((r1, z1), (0.0, z1))
    line((0.0, z1), (0.0, z0))
    if r0 > close_tol:
        line((0.0, z0), (r0, z0))
    if not wire.IsDone():
        raise RuntimeError("could not close the mandrel profile into a wire")
    face = BRepBuilderAPI_MakeFace(wire.Wire(), True).Face()
    revol = BRepPrimAPI_MakeRevol(face, gp_Ax1(gp_Pnt(0, 0, 0), gp_Dir(0, 0, 1)), 2.0 * math.pi)
    revol.Build()
    shape = revol.Shape()
    exp = TopExp_Explorer(shape, TopAbs_SOLID)
    if not exp.More():
        raise RuntimeError("revolving the mandrel profile did not give a solid")
    solid = TopoDS.Solid_s(exp.Current())
    if not BRepCheck_Analyzer(solid).IsValid():
        raise RuntimeError("the revolved mandrel solid is not valid")
    return solid


def export_step(mandrel: Mandrel, path: str | Path) -> Path:
    """Write the mandrel solid (axis = Z, mm) as a STEP AP214 file, atomically; return the path."""
    import cadquery as cq
    from OCP.IFSelect import IFSelect_ReturnStatus

    shape = cq.Shape.cast(mandrel_solid(mandrel))

    def write(tmp: str) -> None:
        status = shape.exportStep(tmp)
        if status != IFSelect_ReturnStatus.IFSelect_RetDone:
            raise OSError(f"the STEP writer failed ({status})")

    return atomic_write_with(path, write, suffix=".step")


def export_stl(mandrel: Mandrel, path: str | Path, tolerance_mm: float = 0.01, angular_tolerance_rad: float = 0.1,
               ascii: bool = False) -> Path:
    """Write the mandrel as a closed triangle mesh (STL, mm, axis = Z), atomically; return the path.

    The closed profile (generatrix, end faces, axis) is revolved about Z and tessellated directly:
    the generatrix edges (the same exact curves as :func:`export_step`) are discretised with a
    chordal deviation of ``tolerance_mm / 2`` and a turning angle of at most
    ``angular_tolerance_rad``, and each profile point becomes a ring of ``n`` vertices, ``n`` chosen
    so that the polygon deviates at most ``tolerance_mm / 2`` at the largest radius.  End faces
    become triangle fans; a closed pole is one vertex.  The mesh is watertight and its facets face
    outwards.  (cadquery's general mesher is 10-100x slower on B-spline surfaces of revolution.)

    Parameters
    ----------
    tolerance_mm:
        Largest distance between the mesh and the surface (chordal deviation), mm.
    angular_tolerance_rad:
        Largest angle between neighbouring facets along the profile and around the axis, rad.
    ascii:
        Write ASCII STL instead of binary.
    """
    if not (math.isfinite(tolerance_mm) and 1e-4 <= tolerance_mm <= 0.1 * mandrel.r_max):
        raise InputError(f"STL tolerance must be in 0.0001 .. {0.1 * mandrel.r_max:.4g} mm (a tenth of the largest "
                         f"radius), got {tolerance_mm}", field="tolerance_mm")
    if not (math.isfinite(angular_tolerance_rad) and 0 < angular_tolerance_rad <= 1.0):
        raise InputError(f"STL angular tolerance must be in (0, 1] rad, got {angular_tolerance_rad}",
                         field="angular_tolerance_rad")
    z, r = _profile_polyline(mandrel, 0.5 * tolerance_mm, angular_tolerance_rad)
    r_max = float(r.max())
    half = min(0.5 * tolerance_mm / r_max, 1.0)
    n = max(8, int(math.ceil(math.pi / math.acos(1.0 - half))), int(math.ceil(2 * math.pi / angular_tolerance_rad)))
    if len(z) * n > 20_000_000:
        raise InputError(f"STL tolerance {tolerance_mm} mm is too fine for this mandrel: it would need "
                         f"{2 * len(z) * n} triangles", field="tolerance_mm")
    tri = _revolve_mesh(z, r, n, closed_tol=1e-9 * max(r_max, float(z[-1] - z[0])))
    data = _stl_bytes(tri, ascii=ascii, name=mandrel.name)
    return atomic_write_with(path, lambda tmp: Path(tmp).write_bytes(data), suffix=".stl")


def _profile_polyline(mandrel: Mandrel, deflection: float, angle: float) -> tuple[FloatArray, FloatArray]:
    """Points (z, r) along the generatrix with chordal deviation <= ``deflection`` (mm), z increasing."""
    from OCP.BRepAdaptor import BRepAdaptor_Curve
    from OCP.GCPnts import GCPnts_TangentialDeflection

    scale = max(mandrel.r_max, mandrel.length)
    zs: list[FloatArray] = []
    rs: list[FloatArray] = []
    for seg in mandrel.segments:
        c = BRepAdaptor_Curve(_segment_edge(seg, 1e-9 * scale, 1e-7 * scale))
        td = GCPnts_TangentialDeflection(c, angle, deflection, 2)
        pts = np.array([[p.X(), p.Z()] for p in (td.Value(i) for i in range(1, td.NbPoints() + 1))])
        if pts[0, 1] > pts[-1, 1]:
            pts = pts[::-1]
        # exact end points (shared with the neighbours)
        pts[0] = (max(float(seg.eval(np.array([seg.z0]))[0][0]), 0.0), seg.z0)
        pts[-1] = (max(float(seg.eval(np.array([seg.z1]))[0][0]), 0.0), seg.z1)
        zs.append(pts[:-1, 1])
        rs.append(pts[:-1, 0])
    zs.append(np.array([mandrel.z_max]))
    rs.append(np.array([max(mandrel.pole_radii[1], 0.0)]))
    return np.concatenate(zs), np.concatenate(rs)


def _revolve_mesh(z: FloatArray, r: FloatArray, n: int, closed_tol: float) -> FloatArray:
    """Triangles (m, 3, 3) of the closed solid bounded by the profile revolved about Z, outward facing."""
    th = 2.0 * math.pi * np.arange(n) / n
    c, s = np.cos(th), np.sin(th)
    point = r <= closed_tol  # rings that collapse onto the axis (closed poles)
    tris: list[FloatArray] = []
    j0 = np.arange(n)
    j1 = (j0 + 1) % n

    def ring(i: int) -> FloatArray:
        if point[i]:
            return np.tile([0.0, 0.0, z[i]], (n, 1))
        return np.column_stack([r[i] * c, r[i] * s, np.full(n, z[i])])

    prev = ring(0)
    for i in range(len(z) - 1):
        cur = ring(i + 1)
        a, b, cc, d = prev[j0], prev[j1], cur[j1], cur[j0]
        if not point[i]:
            tris.append(np.stack([a, b, cc], axis=1))
        if not point[i + 1]:
            tris.append(np.stack([a, cc, d], axis=1))
        prev = cur
    for i, sign in ((0, -1.0), (len(z) - 1, 1.0)):  # end faces: fans around the axis
        if point[i]:
            continue
        rg = ring(i)
        o = np.tile([0.0, 0.0, z[i]], (n, 1))
        tris.append(np.stack([o, rg[j1], rg[j0]] if sign < 0 else [o, rg[j0], rg[j1]], axis=1))
    return np.concatenate(tris)


def _stl_bytes(tri: FloatArray, ascii: bool, name: str) -> bytes:
    """Binary (or ASCII) STL of triangles (m, 3, 3) with their unit normals."""
    nrm = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    ln = np.linalg.norm(nrm, axis=1, keepdims=True)
    nrm = np.divide(nrm, ln, out=np.zeros_like(nrm), where=ln > 0)
    if ascii:
        safe = re.sub(r"\s+", "_", name) or "mandrel"
        facet = ("  facet normal %.7e %.7e %.7e\n    outer loop\n" + "      vertex %.9e %.9e %.9e\n" * 3
                 + "    endloop\n  endfacet\n")
        values = np.hstack([nrm, tri.reshape(-1, 9)]).astype(np.float32).astype(float)
        body = (facet * len(tri)) % tuple(values.ravel().tolist())
        return f"solid {safe}\n{body}endsolid {safe}\n".encode("ascii")
    rec = np.zeros(len(tri), dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("attr", "<u2")])
    rec["n"] = nrm
    rec["v"] = tri
    header = f"winder mandrel {name}"[:80].encode("ascii", "replace").ljust(80, b" ")
    return header + np.uint32(len(tri)).tobytes() + rec.tobytes()


# ================================================================================================
# STEP import
# ================================================================================================
# Half-planes probed besides the 0°/180° section.  37° is no divisor of 360° / n for small n, so prisms with
# n-fold symmetry are caught.
_PROBE_ANGLES_DEG = (37.0, 90.0, 127.0, 217.0, 270.0, 307.0)
_PROBE_Z = 48  # heights probed per half-plane


STEP_READER = "engine.mandrel_io:_step_profile_of_file"
"""The function :func:`load_step` runs in the sandboxed child process (``module:function``)."""


def load_step(path: str | Path, *, isolated: bool = True, timeout_s: float | None = None) -> Mandrel:
    """Read a solid of revolution from a STEP file and return a C2 spline mandrel of its outer profile.

    The axis is taken from the faces of revolution (cylinders, cones, tori, surfaces of revolution,
    sphere centres), else from the principal axes of inertia, else Z through the centroid.  The
    solid is cut by the plane through the axis at 0°/180°: section edges on the axis and
    perpendicular to it (end faces) are dropped, the outer envelope of the rest is the profile of
    each half-plane, and the two must agree within 1e-4 of the model size.  Six more half-planes
    (37°, 90°, 127°, 217°, 270°, 307°) are probed with rays from the axis at 48 heights (the
    farthest hit is the outer radius there; rays are exact and much cheaper than more sections of
    B-spline faces), and the body must not reach beyond the revolved 0° profile.
    z is measured along the axis from the foot of the global origin, so a solid revolved about Z
    keeps its z coordinates.

    The CAD kernel runs in a child process (``isolated``, :func:`engine.sandbox.run_isolated`) with
    the memory budget and a time limit (``timeout_s``, default 120 s): a file that crashes it, loops
    or allocates without bound is an :class:`InputError` naming the file, and the caller keeps running.

    Raises
    ------
    InputError
        Unreadable file, no solid or several solids, not a solid of revolution (which profiles
        differ, by how much, where), a step in the profile; the reader crashed, gave up after the
        time limit or exceeded the memory budget on this file.
    """
    p = Path(path)
    file = str(p)
    data = _read_bytes(p, "STEP")
    if not data.strip():
        raise InputError("empty file: not a STEP model", file=file)
    if not data.lstrip()[:64].upper().startswith(b"ISO-10303-21"):
        raise InputError("not a STEP file: it does not start with 'ISO-10303-21;' (export the mandrel as STEP "
                         "AP203/AP214)", file=file)
    try:
        if isolated:
            from engine.sandbox import run_isolated

            z, r, meta = run_isolated(STEP_READER, file, what="the STEP reader", file=file, timeout_s=timeout_s)
        else:
            z, r, meta = _step_profile_of_file(file)
    except InputError as exc:
        raise exc.at(file=file) from None
    return _mandrel_from_profile(np.asarray(z, dtype=float), np.asarray(r, dtype=float), path=p, source="step",
                                 meta=meta)


def _step_profile_of_file(file: str) -> tuple[FloatArray, FloatArray, dict[str, Any]]:
    """(z, r, meta) of the STEP solid in ``file``: every OCP call of :func:`load_step` (the sandboxed part)."""
    solid = _read_step_solid(file)
    axis_o, axis_d, how = _revolution_axis(solid)
    z, r = _step_profile(solid, axis_o, axis_d, how)
    return z, r, {"axis_origin": axis_o.tolist(), "axis_direction": axis_d.tolist(), "axis_from": how}


def _read_step_solid(file: str) -> Any:
    import cadquery as cq
    from OCP.TopAbs import TopAbs_SOLID
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS

    try:
        wp = cq.importers.importStep(file)
    except Exception as exc:  # noqa: BLE001 - the reader sees arbitrary files
        raise InputError(f"cannot read the STEP model ({type(exc).__name__}: {exc})") from None
    solids = []
    for obj in wp.vals():
        if not isinstance(obj, cq.Shape):
            continue
        exp = TopExp_Explorer(obj.wrapped, TopAbs_SOLID)
        while exp.More():
            solids.append(TopoDS.Solid_s(exp.Current()))
            exp.Next()
    if not solids:
        kinds = sorted({type(o).__name__ for o in wp.vals()})
        raise InputError(f"the STEP model holds no solid (found: {', '.join(kinds) or 'nothing'}); export the "
                         "mandrel as a solid body")
    if len(solids) > 1:
        raise InputError(f"the STEP model holds {len(solids)} solids; export only the mandrel body")
    return solids[0]


def _revolution_axis(solid: Any) -> tuple[FloatArray, FloatArray, str]:
    """(origin, unit direction, how found) of the presumed axis of revolution."""
    from OCP.BRepAdaptor import BRepAdaptor_Surface
    from OCP.BRepGProp import BRepGProp
    from OCP.GeomAbs import (
        GeomAbs_Cone,
        GeomAbs_Cylinder,
        GeomAbs_Sphere,
        GeomAbs_SurfaceOfRevolution,
        GeomAbs_Torus,
    )
    from OCP.GProp import GProp_GProps
    from OCP.TopAbs import TopAbs_FACE
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS

    def vec(p: Any) -> FloatArray:
        return np.array([p.X(), p.Y(), p.Z()], dtype=float)

    g = GProp_GProps()
    BRepGProp.VolumeProperties_s(solid, g)
    centroid = vec(g.CentreOfMass())
    bb = _bbox(solid)
    size = float(np.max(bb[1] - bb[0]))
    tol = 1e-5 * max(size, 1.0)  # axes of faces from other CAD systems agree to about this
    axes: list[tuple[float, FloatArray, FloatArray, str]] = []
    centres: list[FloatArray] = []
    exp = TopExp_Explorer(solid, TopAbs_FACE)
    kinds = {GeomAbs_Cylinder: "cylinder", GeomAbs_Cone: "cone", GeomAbs_Torus: "torus",
             GeomAbs_SurfaceOfRevolution: "surface of revolution"}
    while exp.More():
        face = TopoDS.Face_s(exp.Current())
        exp.Next()
        ad = BRepAdaptor_Surface(face)
        t = ad.GetType()
        if t == GeomAbs_Sphere:
            centres.append(vec(ad.Sphere().Location()))
            continue
        if t not in kinds:
            continue
        if t == GeomAbs_Cylinder:
            ax = ad.Cylinder().Axis()
        elif t == GeomAbs_Cone:
            ax = ad.Cone().Axis()
        elif t == GeomAbs_Torus:
            ax = ad.Torus().Axis()
        else:
            ax = ad.AxeOfRevolution()
        fg = GProp_GProps()
        BRepGProp.SurfaceProperties_s(face, fg)
        d = ax.Direction()
        axes.append((fg.Mass(), vec(ax.Location()), np.array([d.X(), d.Y(), d.Z()]), kinds[t]))
    if axes:
        axes.sort(key=lambda a: -a[0])
        _, o, d, kind = axes[0]
        for _, o2, d2, k2 in axes[1:]:
            off = _dist_to_line(o2, o, d)
            if np.linalg.norm(np.cross(d, d2)) > 1e-5 or off > tol:
                raise InputError(
                    f"not a solid of revolution: its {k2} face turns about an axis through "
                    f"{_fmt_pt(o2)} along {_fmt_pt(d2)}, but the main {kind} face about {_fmt_pt(o)} along "
                    f"{_fmt_pt(d)} ({off:.4g} mm apart)")
        for c in centres:
            off = _dist_to_line(c, o, d)
            if off > tol:
                raise InputError(f"not a solid of revolution: a spherical face is centred at {_fmt_pt(c)}, "
                                 f"{off:.4g} mm off the axis of the {kind} faces")
        how = f"{kind} faces"
    else:
        # principal axes of inertia: the axis of a body of revolution has the odd moment
        mat = g.MatrixOfInertia()
        inertia = np.array([[mat.Value(i, j) for j in (1, 2, 3)] for i in (1, 2, 3)])
        w, v = np.linalg.eigh(inertia)
        scale = max(abs(w).max(), 1e-300)
        same01 = abs(w[0] - w[1]) <= 1e-6 * scale
        same12 = abs(w[1] - w[2]) <= 1e-6 * scale
        o = centres[0] if centres else centroid
        if same01 and not same12:
            d, how = v[:, 2], "principal axes of inertia"
        elif same12 and not same01:
            d, how = v[:, 0], "principal axes of inertia"
        else:
            d, how = np.array([0.0, 0.0, 1.0]), "assumed Z axis"
    d = np.asarray(d, dtype=float) / np.linalg.norm(d)
    if d[int(np.argmax(np.abs(d)))] < 0:
        d = -d
    o = np.asarray(o, dtype=float)
    o = o - np.dot(o, d) * d  # foot of the global origin on the axis
    d[np.abs(d) < 1e-15] = 0.0
    return o, d, how


def _fmt_pt(p: FloatArray) -> str:
    return "(" + ", ".join(f"{x + 0.0:.6g}" for x in np.asarray(p, dtype=float)) + ")"


def _dist_to_line(p: FloatArray, o: FloatArray, d: FloatArray) -> float:
    return float(np.linalg.norm(np.cross(p - o, d)))


def _bbox(shape: Any) -> tuple[FloatArray, FloatArray]:
    from OCP.Bnd import Bnd_Box
    from OCP.BRepBndLib import BRepBndLib

    box = Bnd_Box()
    BRepBndLib.Add_s(shape, box)
    x0, y0, z0, x1, y1, z1 = box.Get()
    return np.array([x0, y0, z0]), np.array([x1, y1, z1])


_Perp = tuple[float, float, float]  # an edge perpendicular to the axis: z, r from, r to (mm)


def _section_halves(solid: Any, o: FloatArray, d: FloatArray, u: FloatArray, h: float,
                    tol: float) -> tuple[list[FloatArray], list[FloatArray], list[_Perp], list[_Perp]]:
    """Cut with the plane through the axis spanned by d and u.

    Returns the polylines (z, r) of the +u and the −u half, and for each half the edges
    perpendicular to the axis (z, r_lo, r_hi); edges on the axis are dropped.
    """
    from OCP.BRepAdaptor import BRepAdaptor_Curve
    from OCP.BRepAlgoAPI import BRepAlgoAPI_Section
    from OCP.GCPnts import GCPnts_AbscissaPoint, GCPnts_TangentialDeflection, GCPnts_UniformAbscissa
    from OCP.gp import gp_Dir, gp_Pln, gp_Pnt
    from OCP.TopAbs import TopAbs_EDGE
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS

    n = np.cross(d, u)
    sec = BRepAlgoAPI_Section(solid, gp_Pln(gp_Pnt(*map(float, o)), gp_Dir(*map(float, n))), False)
    sec.Approximation(True)
    sec.Build()
    if not sec.IsDone():
        raise InputError("cannot cut the solid with a plane through its axis")
    plus: list[FloatArray] = []
    minus: list[FloatArray] = []
    perp_plus: list[_Perp] = []
    perp_minus: list[_Perp] = []
    exp = TopExp_Explorer(sec.Shape(), TopAbs_EDGE)
    while exp.More():
        edge = TopoDS.Edge_s(exp.Current())
        exp.Next()
        c = BRepAdaptor_Curve(edge)
        f, l_ = c.FirstParameter(), c.LastParameter()
        length = GCPnts_AbscissaPoint.Length_s(c)
        if not length > tol:
            continue
        params = [f, l_]
        ua = GCPnts_UniformAbscissa(c, max(8, int(math.ceil(length / h)) + 1), -1.0)
        if ua.IsDone():
            params += [ua.Parameter(i) for i in range(1, ua.NbPoints() + 1)]
        td = GCPnts_TangentialDeflection(c, 0.01, 1e-4 * h)
        params += [td.Parameter(i) for i in range(1, td.NbPoints() + 1)]
        prm = np.unique(np.asarray(params, dtype=float))
        pts = np.array([[q.X(), q.Y(), q.Z()] for q in (c.Value(float(t)) for t in prm)])
        rel = pts - o
        zz = rel @ d
        ss = rel @ u
        if np.abs(ss).max() <= tol:
            continue  # on the axis
        if np.ptp(zz) <= tol:  # perpendicular to the axis (an end face, or a step)
            ze = float(np.mean(zz))
            if ss.max() > tol:
                perp_plus.append((ze, max(float(ss.min()), 0.0), float(ss.max())))
            if ss.min() < -tol:
                perp_minus.append((ze, max(float(-ss.max()), 0.0), float(-ss.min())))
            continue
        if ss.max() > tol:
            m = ss >= -tol
            plus.append(np.column_stack([zz[m], np.maximum(ss[m], 0.0)]))
        if ss.min() < -tol:
            m = ss <= tol
            minus.append(np.column_stack([zz[m], np.maximum(-ss[m], 0.0)]))
    return plus, minus, perp_plus, perp_minus


def _monotone_runs(pl: FloatArray, ztol: float) -> list[FloatArray]:
    """Split a polyline into runs of strictly increasing z (reversed where decreasing); drop constant-z runs."""
    runs: list[FloatArray] = []
    d = np.diff(pl[:, 0])
    sgn = np.where(d > 0, 1, np.where(d < 0, -1, 0))
    start = 0
    for i in range(1, len(sgn) + 1):
        if i == len(sgn) or sgn[i] != sgn[start]:
            run = pl[start: i + 1]
            if sgn[start] == -1:
                run = run[::-1]
            if sgn[start] != 0 and np.ptp(run[:, 0]) > ztol:
                runs.append(run)
            start = i
    return runs


def _outer_envelope(polylines: list[FloatArray], tol: float, perps: Sequence[_Perp] = ()) -> FloatArray:
    """Points (z, r) of the outer envelope r(z) of the section polylines, z increasing.

    ``tol`` is the geometric tolerance (mm); points closer than ``1e-3 tol`` in z are merged, and
    a jump in r between such points, or an edge perpendicular to the axis that reaches the envelope
    between its ends (``perps``), is a step in the profile.
    """
    ztol = 1e-3 * tol
    runs = [r for pl in polylines for r in _monotone_runs(pl, ztol)]
    if not runs:
        raise InputError("the section through the axis has no profile edge off the axis")
    kept = []
    for i, run in enumerate(runs):
        best = np.full(len(run), -np.inf)
        for j, other in enumerate(runs):
            if i == j:
                continue
            inside = (run[:, 0] >= other[0, 0] - ztol) & (run[:, 0] <= other[-1, 0] + ztol)
            if inside.any():
                best[inside] = np.maximum(best[inside], np.interp(run[inside, 0], other[:, 0], other[:, 1]))
        m = run[:, 1] >= best - tol
        if m.any():
            kept.append(run[m])
    pts = np.concatenate(kept)
    pts = pts[np.lexsort((pts[:, 1], pts[:, 0]))]
    out = [pts[0]]
    for q in pts[1:]:
        if q[0] - out[-1][0] <= ztol:
            if abs(q[1] - out[-1][1]) > 10 * tol:
                raise InputError(
                    f"the profile steps from r = {out[-1][1]:.6g} to {q[1]:.6g} mm at z = {q[0]:.6g} mm (a face "
                    "perpendicular to the axis inside the winding zone); the generatrix must be smooth")
            continue
        out.append(q)
    env = np.array(out)
    for ze, lo, hi in perps:
        if env[0, 0] + 10 * tol < ze < env[-1, 0] - 10 * tol and hi - lo > 10 * tol:
            r_env = float(np.interp(ze, env[:, 0], env[:, 1]))
            if hi >= r_env - 10 * tol:
                raise InputError(
                    f"the profile steps between r = {lo:.6g} and {hi:.6g} mm at z = {ze:.6g} mm (a face perpendicular "
                    "to the axis inside the winding zone); the generatrix must be smooth")
    return env


def _step_profile(solid: Any, o: FloatArray, d: FloatArray, how: str) -> tuple[FloatArray, FloatArray]:
    lo, hi = _bbox(solid)
    size = float(np.max(hi - lo))
    if not size < MAX_COORD_MM:
        raise InputError(f"the model is {size:.3g} mm across, more than {MAX_COORD_MM:g} mm; check the units")
    tol = 1e-6 * max(size, 1.0)
    # the axial extent sets the sampling step
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    zext = float(np.ptp((corners - o) @ d))
    h = max(zext, tol) / _PROFILE_POINTS
    e1 = np.cross(d, [1.0, 0.0, 0.0] if abs(d[0]) < 0.9 else [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(d, e1)
    if abs(d[2]) > 1 - 1e-12:  # axis along Z: 0° is +X, as a user expects
        e1, e2 = np.array([1.0, 0.0, 0.0]), np.array([0.0, float(np.sign(d[2])), 0.0])
    where = f"axis through {_fmt_pt(o)} along {_fmt_pt(d)}, from the {how}"
    rev_tol = max(1e-4 * size, 1e-3)

    def differ(a: float, dr: float, z: float) -> InputError:
        return InputError(f"not a solid of revolution: profiles at 0° and {a:g}° differ by {dr:.4g} mm at z = "
                          f"{z:.6g} mm ({where}; tolerance {rev_tol:.3g} mm)")

    # 1) the plane at 0°/180°: the profile, and a first comparison of two half-planes
    plus, minus, perp_plus, perp_minus = _section_halves(solid, o, d, e1, h, tol)
    profiles: dict[float, FloatArray] = {}
    for a, pls, perps in ((0.0, plus, perp_plus), (180.0, minus, perp_minus)):
        if not pls:
            raise InputError(f"not a solid of revolution: the half-section at {a:g}° is empty ({where})")
        profiles[a] = _outer_envelope(pls, tol, perps)
    ref, q = profiles[0.0], profiles[180.0]
    for end, zr, zq in (("start", ref[0, 0], q[0, 0]), ("end", ref[-1, 0], q[-1, 0])):
        if abs(zr - zq) > rev_tol:
            raise InputError(f"not a solid of revolution: the profile at 180° {end}s at z = {zq:.6g} mm, the one at "
                             f"0° at z = {zr:.6g} mm ({where})")
    m = (q[:, 0] >= ref[0, 0]) & (q[:, 0] <= ref[-1, 0])
    diff = np.abs(q[m, 1] - np.interp(q[m, 0], ref[:, 0], ref[:, 1]))
    if diff.size and diff.max() > rev_tol:
        k = int(np.argmax(diff))
        raise differ(180.0, float(diff[k]), float(q[m][k, 0]))
    # 2) other half-planes, probed by rays from the axis: the farthest hit is the outer radius there
    zs = ref[0, 0] + (ref[-1, 0] - ref[0, 0]) * (np.arange(_PROBE_Z) + 0.5) / _PROBE_Z
    r_ref = np.interp(zs, ref[:, 0], ref[:, 1])
    for a in _PROBE_ANGLES_DEG:
        u = math.cos(math.radians(a)) * e1 + math.sin(math.radians(a)) * e2
        r_a = _probe_radii(solid, o, d, u, zs, tol)
        diff = np.abs(np.where(np.isnan(r_a), 0.0, r_a) - r_ref)
        k = int(np.argmax(diff))
        if diff[k] > rev_tol:
            raise differ(a, float(diff[k]), float(zs[k]))
    # 3) nothing may stick out of the body of revolution of the 0° profile (axial and radial extent)
    zlo, zhi, rho = _extent_in_axis_frame(solid, o, d, e1)
    rmax = float(ref[:, 1].max())
    if zlo < ref[0, 0] - rev_tol or zhi > ref[-1, 0] + rev_tol or rho > rmax + rev_tol:
        raise InputError(
            f"not a solid of revolution: the body spans z = {zlo:.6g}..{zhi:.6g} mm and reaches {rho:.6g} mm from the "
            f"axis, the profile at 0° spans z = {ref[0, 0]:.6g}..{ref[-1, 0]:.6g} mm with r <= {rmax:.6g} mm ({where})")
    return _resample_chain(ref[:, 0], ref[:, 1])


def _probe_radii(solid: Any, o: FloatArray, d: FloatArray, u: FloatArray, zs: FloatArray, tol: float) -> FloatArray:
    """Farthest intersection of the rays o + z·d + t·u (t >= 0) with the solid, NaN where none (mm)."""
    from OCP.gp import gp_Dir, gp_Lin, gp_Pnt
    from OCP.IntCurvesFace import IntCurvesFace_ShapeIntersector

    si = IntCurvesFace_ShapeIntersector()
    si.Load(solid, tol)
    out = np.full(len(zs), np.nan)
    direction = gp_Dir(*map(float, u))
    for i, z in enumerate(zs):
        p = o + z * d
        si.Perform(gp_Lin(gp_Pnt(*map(float, p)), direction), 0.0, 1e12)
        if si.IsDone() and si.NbPnt() > 0:
            out[i] = max(si.WParameter(j) for j in range(1, si.NbPnt() + 1))
    return out


def _extent_in_axis_frame(solid: Any, o: FloatArray, d: FloatArray, e1: FloatArray) -> tuple[float, float, float]:
    """(z min, z max, largest distance from the axis bound) of the solid in the frame of the axis (mm)."""
    from OCP.Bnd import Bnd_Box
    from OCP.BRepBndLib import BRepBndLib
    from OCP.BRepBuilderAPI import BRepBuilderAPI_Transform
    from OCP.gp import gp_Ax3, gp_Dir, gp_Pnt, gp_Trsf

    trsf = gp_Trsf()
    trsf.SetTransformation(gp_Ax3(gp_Pnt(*map(float, o)), gp_Dir(*map(float, d)), gp_Dir(*map(float, e1))))
    local = BRepBuilderAPI_Transform(solid, trsf, True).Shape()
    box = Bnd_Box()
    BRepBndLib.AddOptimal_s(local, box, False, False)
    x0, y0, z0, x1, y1, z1 = box.Get()
    return z0, z1, max(abs(x0), abs(x1), abs(y0), abs(y1))


# ================================================================================================
# Dispatch
# ================================================================================================
_LOADERS = {".csv": load_csv, ".txt": load_csv, ".dat": load_csv, ".dxf": load_dxf, ".step": load_step,
            ".stp": load_step}


def smooth_profile(mandrel: Mandrel, z: FloatArray, r: FloatArray, tolerance_mm: float,
                   file: str | None = None) -> Mandrel:
    """The smoothest spline that stays within ``tolerance_mm`` of measured points (z, r), mm.

    A penalised cubic smoothing spline (scipy ``make_smoothing_spline``) with the largest penalty whose
    final C2 spline (through its values at the points, pole radii kept) deviates from every point by at
    most the tolerance (bisection on the penalty in log scale).  ``meta['smoothing']`` states the
    tolerance and the deviation reached (max and where, rms); when even a tiny penalty exceeds the
    tolerance the points are interpolated as they are and the note says so.
    """
    from scipy.interpolate import make_smoothing_spline

    tol = float(tolerance_mm)
    if not (math.isfinite(tol) and tol > 0):
        raise InputError(f"the smoothing tolerance must be a positive number of mm, got {tolerance_mm!r}", file=file,
                         field="smoothing_mm")
    zz = np.asarray(z, dtype=float)
    rr = np.asarray(r, dtype=float)
    if len(zz) < 5:
        raise InputError("smoothing needs at least 5 points", file=file, field="smoothing_mm")

    def fit(log_lam: float) -> tuple[Mandrel | None, float]:
        try:
            spl = make_smoothing_spline(zz, rr, lam=10.0**log_lam)
            rs = np.asarray(spl(zz), dtype=float)
            rs[0], rs[-1] = rr[0], rr[-1]  # keep the pole radii as measured
            m = Mandrel.from_points(zz, rs, name=mandrel.name, source="csv", file=file)
        except (InputError, ValueError, np.linalg.LinAlgError):
            return None, math.inf
        return m, float(np.abs(m.r(zz) - rr).max())

    span = float(zz[-1] - zz[0])
    lo, hi = math.log10(1e-12 * span**3), math.log10(1e3 * span**3)
    best, dev = fit(lo)
    if best is None or dev > tol:
        mandrel.meta["smoothing"] = {"tolerance_mm": tol, "max_deviation_mm": 0.0, "rms_deviation_mm": 0.0,
                                     "applied": False,
                                     "note": "no smoothing meets the tolerance; the points are interpolated"}
        return mandrel
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        m, d = fit(mid)
        if m is not None and d <= tol:
            best, dev, lo = m, d, mid
        else:
            hi = mid
        if hi - lo < 0.01:
            break
    res = best.r(zz) - rr
    i = int(np.argmax(np.abs(res)))
    best.meta.update(mandrel.meta)
    best.meta["smoothing"] = {"tolerance_mm": tol, "max_deviation_mm": float(abs(res[i])), "at_z_mm": float(zz[i]),
                              "rms_deviation_mm": float(np.sqrt(np.mean(res * res))), "applied": True,
                              "penalty": 10.0**lo}
    return best


def load_mandrel_file(path: str | Path, smoothing_mm: float | None = None) -> Mandrel:
    """Load a mandrel from a CSV/TXT table, a DXF profile or a STEP solid, chosen by the file suffix.

    ``smoothing_mm``: for a CSV/TXT table, the smoothest spline within this distance (mm) of the points
    instead of the interpolating one (:func:`smooth_profile`); refused for other files.
    """
    p = Path(path)
    loader = _LOADERS.get(p.suffix.lower())
    if loader is None:
        raise InputError(
            f"unknown mandrel file type '{p.suffix or '(no suffix)'}'; use .csv/.txt (z, r table), .dxf (profile "
            "drawing) or .step/.stp (solid of revolution)", file=p)
    if smoothing_mm is not None:
        if loader is not load_csv:
            raise InputError("smoothing applies to measured point tables (.csv/.txt/.dat) only", file=p,
                             field="smoothing_mm")
        return load_csv(p, smoothing_mm=smoothing_mm)
    return loader(p)
