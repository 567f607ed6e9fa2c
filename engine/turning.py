"""Turning-mode optimiser: spindle speed and feed for one-pass turning by linear programming.

MATH.md section C (seed ``004``).  Machine time ``t_m = L / (n S)`` is minimised, i.e. ``n S`` is
maximised, subject to the technological constraints (3)-(13) of the paper.  Every constraint has
the monomial form ``n^a * S^b <= c``, so in ``x1 = ln n``, ``x2 = ln S`` the problem is the linear
programme (16)::

    maximise  x1 + x2   subject to   a_i * x1 + b_i * x2 <= ln c_i   (rows b1 .. b11 + user rows)

solved with HiGHS (:func:`scipy.optimize.linprog`).  The rows come either from the physical model
(handbook coefficients in ``resources/cutting/*.toml``, :func:`build_model`) or, in *expert mode*,
directly from the case file (the Mathcad way).

Where a handbook coefficient set changes with the feed (the Taylor constants of K&M table 17 for
S <= 0.4 and S > 0.4, ...), one LP is solved per feed band and the best answer kept; the paper used
the first band for all feeds.

Units here are the cutting handbook's, and every name carries them: n in rpm, S in mm/rev, lengths
in mm, V in m/min, forces in N, power in kW, times in min (``machine_time_s`` is also given).
Tool angles are stored in rad; case files give them in degrees (``*_deg``).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from engine.errors import InfeasibleError, InputError
from engine.resources import read_toml
from engine.state import State, check_cancel

__all__ = [
    "CONSTRAINT_NAMES",
    "CuttingData",
    "Model",
    "Row",
    "TurningCase",
    "TurningResult",
    "build_model",
    "case_from_dict",
    "cutting_dir",
    "evaluate",
    "example_case_path",
    "feasible_polygons",
    "is_feasible",
    "load_case",
    "load_data",
    "minimal_removal_sets",
    "optimise",
    "optimise_with_plot",
    "plot_data",
    "result_to_json",
    "solve_model",
]

#: the paper's rows b1 .. b11, in order
CONSTRAINT_NAMES: tuple[str, ...] = (
    "tool_life", "power", "feed_mechanism", "holder", "insert", "roughness", "accuracy",
    "s_min", "s_max", "n_min", "n_max",
)

LABELS: dict[str, str] = {
    "tool_life": "(3) tool life (Taylor)",
    "power": "(4) drive power",
    "feed_mechanism": "(5) feed-mechanism strength",
    "holder": "(6) tool-holder strength",
    "insert": "(7) insert strength",
    "roughness": "(8) surface roughness",
    "accuracy": "(9) machining accuracy",
    "s_min": "(10) S >= S_min",
    "s_max": "(11) S <= S_max",
    "n_min": "(12) n >= n_min",
    "n_max": "(13) n <= n_max",
}

#: deflection coefficient k in f = P l^3 / (k E J), worst load position (clamped/pinned beams)
FIXTURES: dict[str, float] = {
    "centres": 48.0,  # simply supported, load at mid-span
    "chuck": 3.0,  # cantilever, load at the free end
    "chuck_tailstock": 101.9,  # propped cantilever, load at 0.586 l from the chuck (max of a^3 b^2 (3l+b)/12l^3)
}

_POWER_CONST = 1020.0 * 60.0  # N = P_z V / (1020 * 60) kW  (K&M; P_z in N, V in m/min)
_TOL = 1e-9


def cutting_dir() -> Path:
    """The directory of the shipped cutting data (``resources/cutting``)."""
    return Path(__file__).resolve().parents[1] / "resources" / "cutting"


def example_case_path(name: str) -> Path:
    """Path of a shipped case file ``resources/cutting/cases/<name>.toml`` (``-`` or ``_`` alike)."""
    cases = cutting_dir() / "cases"
    for cand in (name, name.replace("-", "_"), name.replace("_", "-")):
        p = cases / f"{cand}.toml"
        if p.is_file():
            return p
    known = sorted(p.stem for p in cases.glob("*.toml"))
    raise InputError(f"unknown example {name!r}; known examples: {', '.join(known)}", field="--example")


# ================================================================================== data loading
def _read_toml(path: Path) -> dict[str, Any]:
    return read_toml(path)


@dataclass(frozen=True)
class CuttingData:
    """The cutting database: the parsed TOML tables and the files they came from."""

    materials: Mapping[str, Any]
    tools: Mapping[str, Any]
    machines: Mapping[str, Any]
    speed: Mapping[str, Any]
    force: Mapping[str, Any]
    roughness: Mapping[str, Any]
    files: Mapping[str, Path]

    def get(self, table: str, *keys: str, what: str | None = None) -> Any:
        """``self.<table>[k0][k1]...`` or an :class:`InputError` naming the file and the field."""
        node: Any = getattr(self, table)
        path: list[str] = []
        for k in keys:
            path.append(k)
            if not isinstance(node, Mapping) or k not in node:
                desc = what or "coefficient"
                have = sorted(node) if isinstance(node, Mapping) else []
                hint = f" (present: {', '.join(map(str, have))})" if have and len(have) < 30 else ""
                raise InputError(
                    f"missing {desc} '{'.'.join(path)}'{hint}", file=self.files[table], field=".".join(path)
                )
            node = node[k]
        return node


def load_data(root: str | Path | None = None) -> CuttingData:
    """Load the cutting database from ``root`` (default :func:`cutting_dir`)."""
    root = Path(root) if root is not None else cutting_dir()
    names = ("materials", "tools", "machines", "speed", "force", "roughness")
    files = {n: root / f"{n}.toml" for n in names}
    tables = {n: _read_toml(p) for n, p in files.items()}
    return CuttingData(**tables, files=files)


# ================================================================================== the case
@dataclass(frozen=True)
class UserRow:
    """A user constraint ``n^a * S^b <= c`` (``c > 0``)."""

    name: str
    a: float
    b: float
    c: float


@dataclass(frozen=True)
class TurningCase:
    """One turning set-up.  Lengths mm, angles rad, hardness HB, stress MPa, power kW, time min.

    ``mode == "expert"`` means the LP rows are given directly in ``expert_rows``
    (name, a, b, rhs = ln c, enabled) and the physical fields are optional.
    """

    mode: str = "physical"
    title: str = ""
    file: str | None = None
    # machine
    machine: str = "16K20F3"
    n_min_rpm: float | None = None
    n_max_rpm: float | None = None
    s_min_mm_rev: float | None = None
    s_max_mm_rev: float | None = None
    power_kw: float | None = None
    efficiency: float | None = None
    feed_force_max_n: float | None = None
    # workpiece
    material: str = "sch20"
    hb: float | None = None
    sigma_b_mpa: float | None = None
    diameter_mm: float = 80.0
    depth_mm: float = 1.5
    length_mm: float = 430.0
    machined_length_mm: float = 50.0
    approach_mm: float = 0.0
    fixture: str = "centres"
    surface: str = "no_crust"
    tolerance_mm: float = 0.22
    deflection_share: float = 0.25
    # tool
    tool: str = "VK6"
    tool_life_min: float = 60.0
    phi: float = math.radians(45.0)
    phi1: float = math.radians(15.0)
    gamma: float = math.radians(10.0)
    lam: float = 0.0
    nose_radius_mm: float = 1.0
    insert_thickness_mm: float = 6.35
    holder_b_mm: float = 25.0
    holder_h_mm: float = 25.0
    holder_overhang_mm: float = 40.0
    holder_stress_mpa: float = 200.0
    # requirement
    rz_um: float = 80.0
    # options and constraint edits
    roughness_model: str = "geometric"
    speed_bands: str = "auto"
    disabled: tuple[str, ...] = ()
    limit_factor: tuple[tuple[str, float], ...] = ()
    user_rows: tuple[UserRow, ...] = ()
    expert_rows: tuple[tuple[str, float, float, float, bool], ...] = ()

    def with_(self, **changes: Any) -> TurningCase:
        """A copy with fields changed (validated again)."""
        new = replace(self, **changes)
        _validate_case(new)
        return new


_SECTIONS: dict[str, dict[str, tuple[str, str]]] = {
    # section -> toml key -> (case attribute, kind)   kind: pos, nonneg, frac, str, deg, deg_any
    "machine": {
        "id": ("machine", "str"), "n_min_rpm": ("n_min_rpm", "pos"), "n_max_rpm": ("n_max_rpm", "pos"),
        "s_min_mm_rev": ("s_min_mm_rev", "pos"), "s_max_mm_rev": ("s_max_mm_rev", "pos"),
        "power_kw": ("power_kw", "pos"), "efficiency": ("efficiency", "frac"),
        "feed_force_max_n": ("feed_force_max_n", "pos"),
    },
    "workpiece": {
        "material": ("material", "str"), "hb": ("hb", "pos"), "sigma_b_mpa": ("sigma_b_mpa", "pos"),
        "diameter_mm": ("diameter_mm", "pos"), "depth_mm": ("depth_mm", "pos"),
        "length_mm": ("length_mm", "pos"), "machined_length_mm": ("machined_length_mm", "pos"),
        "approach_mm": ("approach_mm", "nonneg"), "fixture": ("fixture", "str"),
        "surface": ("surface", "str"), "tolerance_mm": ("tolerance_mm", "pos"),
        "deflection_share": ("deflection_share", "frac"),
    },
    "tool": {
        "material": ("tool", "str"), "tool_life_min": ("tool_life_min", "pos"),
        "phi_deg": ("phi", "deg"), "phi1_deg": ("phi1", "deg"), "gamma_deg": ("gamma", "deg_any"),
        "lambda_deg": ("lam", "deg_any"), "nose_radius_mm": ("nose_radius_mm", "pos"),
        "insert_thickness_mm": ("insert_thickness_mm", "pos"), "holder_b_mm": ("holder_b_mm", "pos"),
        "holder_h_mm": ("holder_h_mm", "pos"), "holder_overhang_mm": ("holder_overhang_mm", "pos"),
        "holder_stress_mpa": ("holder_stress_mpa", "pos"),
    },
    "requirements": {"rz_um": ("rz_um", "pos")},
    "options": {"roughness_model": ("roughness_model", "str"), "speed_bands": ("speed_bands", "str")},
}

#: case attribute -> (``section.key`` in the case file, kind of value)
CASE_FIELDS: dict[str, tuple[str, str]] = {
    attr: (f"{sec}.{key}", kind) for sec, keys in _SECTIONS.items() for key, (attr, kind) in keys.items()
}


def _coerce(value: Any, kind: str, *, file: str | None, field: str) -> Any:
    if kind == "str":
        if not isinstance(value, str) or not value:
            raise InputError(f"expected a name (text), got {value!r}", file=file, field=field)
        return value
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise InputError(f"expected a number, got {value!r}", file=file, field=field)
    v = float(value)
    if not math.isfinite(v):
        raise InputError(f"expected a finite number, got {value!r}", file=file, field=field)
    if kind == "pos" and v <= 0:
        raise InputError(f"must be positive, got {v:g}", file=file, field=field)
    if kind == "nonneg" and v < 0:
        raise InputError(f"must not be negative, got {v:g}", file=file, field=field)
    if kind == "frac" and not 0 < v <= 1:
        raise InputError(f"must lie in (0, 1], got {v:g}", file=file, field=field)
    if kind == "deg":
        if not 0 < v < 180:
            raise InputError(f"angle must lie in (0, 180) degrees, got {v:g}", file=file, field=field)
        return math.radians(v)
    if kind == "deg_any":
        if not -90 < v < 90:
            raise InputError(f"angle must lie in (-90, 90) degrees, got {v:g}", file=file, field=field)
        return math.radians(v)
    return v


def case_from_dict(doc: Mapping[str, Any], *, file: str | Path | None = None) -> TurningCase:
    """Build a :class:`TurningCase` from a parsed case document (the TOML layout of ``cases/``).

    Raises
    ------
    InputError
        naming the file and the ``section.key`` of the first bad or unknown entry.
    """
    f = str(file) if file is not None else None
    kw: dict[str, Any] = {"file": f}
    mode = doc.get("mode", "physical")
    if mode not in ("physical", "expert"):
        raise InputError(f"mode must be 'physical' or 'expert', got {mode!r}", file=f, field="mode")
    kw["mode"] = mode
    if "title" in doc:
        kw["title"] = str(doc["title"])
    known_top = set(_SECTIONS) | {"mode", "title", "constraints", "rows"}
    for key in doc:
        if key not in known_top:
            raise InputError(f"unknown entry {key!r} (known: {', '.join(sorted(known_top))})", file=f, field=key)
    for sec, keys in _SECTIONS.items():
        tab = doc.get(sec, {})
        if not isinstance(tab, Mapping):
            raise InputError("expected a table", file=f, field=sec)
        for key, value in tab.items():
            if key not in keys:
                raise InputError(
                    f"unknown entry {key!r} (known: {', '.join(sorted(keys))})", file=f, field=f"{sec}.{key}"
                )
            attr, kind = keys[key]
            kw[attr] = _coerce(value, kind, file=f, field=f"{sec}.{key}")
    cons = doc.get("constraints", {})
    if not isinstance(cons, Mapping):
        raise InputError("expected a table", file=f, field="constraints")
    for key in cons:
        if key not in ("disable", "limit_factor", "user"):
            raise InputError(
                f"unknown entry {key!r} (known: disable, limit_factor, user)", file=f, field=f"constraints.{key}"
            )
    disable = cons.get("disable", [])
    if not isinstance(disable, list) or not all(isinstance(x, str) for x in disable):
        raise InputError("expected a list of constraint names", file=f, field="constraints.disable")
    kw["disabled"] = tuple(disable)
    lf = cons.get("limit_factor", {})
    if not isinstance(lf, Mapping):
        raise InputError("expected a table name = factor", file=f, field="constraints.limit_factor")
    kw["limit_factor"] = tuple(
        (k, _coerce(v, "pos", file=f, field=f"constraints.limit_factor.{k}")) for k, v in lf.items()
    )
    users = []
    for i, row in enumerate(cons.get("user", [])):
        fld = f"constraints.user[{i}]"
        if not isinstance(row, Mapping):
            raise InputError("expected a table {name, a, b, c}", file=f, field=fld)
        for k in ("name", "a", "b", "c"):
            if k not in row:
                raise InputError(f"missing '{k}' (a user row is n^a * S^b <= c)", file=f, field=f"{fld}.{k}")
        users.append(
            UserRow(
                _coerce(row["name"], "str", file=f, field=f"{fld}.name"),
                _coerce(row["a"], "any", file=f, field=f"{fld}.a"),
                _coerce(row["b"], "any", file=f, field=f"{fld}.b"),
                _coerce(row["c"], "pos", file=f, field=f"{fld}.c"),
            )
        )
    kw["user_rows"] = tuple(users)
    rows = []
    for i, row in enumerate(doc.get("rows", [])):
        fld = f"rows[{i}]"
        if not isinstance(row, Mapping):
            raise InputError("expected a table {name, a, b, rhs}", file=f, field=fld)
        for k in ("name", "a", "b", "rhs"):
            if k not in row:
                raise InputError(f"missing '{k}' (a row is a*x1 + b*x2 <= rhs)", file=f, field=f"{fld}.{k}")
        enabled = row.get("enabled", True)
        if not isinstance(enabled, bool):
            raise InputError(f"expected true or false, got {enabled!r}", file=f, field=f"{fld}.enabled")
        rows.append(
            (
                _coerce(row["name"], "str", file=f, field=f"{fld}.name"),
                _coerce(row["a"], "any", file=f, field=f"{fld}.a"),
                _coerce(row["b"], "any", file=f, field=f"{fld}.b"),
                _coerce(row["rhs"], "any", file=f, field=f"{fld}.rhs"),
                enabled,
            )
        )
    if mode == "expert" and not rows:
        raise InputError("expert mode needs [[rows]] (a*x1 + b*x2 <= rhs)", file=f, field="rows")
    kw["expert_rows"] = tuple(rows)
    case = TurningCase(**kw)
    _validate_case(case)
    return case


def _validate_case(c: TurningCase) -> None:
    f = c.file
    for attr, (fld, _u) in CASE_FIELDS.items():
        v = getattr(c, attr)
        if isinstance(v, float) and not math.isfinite(v):
            raise InputError(f"must be a finite number, got {v}", file=f, field=fld)
    for attr in ("diameter_mm", "depth_mm", "length_mm", "machined_length_mm", "tool_life_min", "rz_um",
                 "nose_radius_mm", "tolerance_mm", "insert_thickness_mm", "holder_b_mm", "holder_h_mm",
                 "holder_overhang_mm", "holder_stress_mpa"):
        v = getattr(c, attr)
        if v <= 0:
            raise InputError(f"must be positive, got {v:g}", file=f, field=CASE_FIELDS[attr][0])
    if c.depth_mm >= c.diameter_mm / 2:
        raise InputError(
            f"depth of cut {c.depth_mm:g} mm is not less than the radius {c.diameter_mm / 2:g} mm",
            file=f, field="workpiece.depth_mm",
        )
    if c.fixture not in FIXTURES:
        raise InputError(
            f"unknown fixture {c.fixture!r}; one of {', '.join(FIXTURES)}", file=f, field="workpiece.fixture"
        )
    if c.roughness_model not in ("geometric", "empirical"):
        raise InputError(
            f"roughness_model must be 'geometric' or 'empirical', got {c.roughness_model!r}",
            file=f, field="options.roughness_model",
        )
    if c.speed_bands not in ("auto", "first"):
        raise InputError(
            f"speed_bands must be 'auto' or 'first', got {c.speed_bands!r}", file=f, field="options.speed_bands"
        )
    for lo, hi, sec in (("n_min_rpm", "n_max_rpm", "machine"), ("s_min_mm_rev", "s_max_mm_rev", "machine")):
        a, b = getattr(c, lo), getattr(c, hi)
        if a is not None and b is not None and a >= b:
            raise InputError(
                f"range is inverted or empty: {lo} = {a:g} is not below {hi} = {b:g}", file=f, field=f"{sec}.{hi}"
            )
    names = set(CONSTRAINT_NAMES) | {u.name for u in c.user_rows} | {r[0] for r in c.expert_rows}
    for n in c.disabled:
        if n not in names:
            raise InputError(
                f"unknown constraint {n!r}; known: {', '.join(sorted(names))}", file=f, field="constraints.disable"
            )
    for n, _v in c.limit_factor:
        if n not in names:
            raise InputError(
                f"unknown constraint {n!r}; known: {', '.join(sorted(names))}",
                file=f, field=f"constraints.limit_factor.{n}",
            )
    for u in c.user_rows:
        if not (math.isfinite(u.a) and math.isfinite(u.b)) or (u.a == 0 and u.b == 0):
            raise InputError(f"user row {u.name!r}: a and b must not both be zero", file=f, field="constraints.user")
        if u.name in CONSTRAINT_NAMES:
            raise InputError(f"user row name {u.name!r} clashes with a built-in constraint",
                             file=f, field="constraints.user")
    for name, a, b, _rhs, _en in c.expert_rows:
        if a == 0 and b == 0:
            raise InputError(f"row {name!r}: a and b must not both be zero", file=f, field="rows")


def load_case(path: str | Path) -> TurningCase:
    """Read and validate a case file (TOML)."""
    path = Path(path)
    return case_from_dict(_read_toml(path), file=path)


# ================================================================================== the model
@dataclass(frozen=True)
class Row:
    """One LP row ``a * x1 + b * x2 <= rhs`` (``x1 = ln n``, ``x2 = ln S``).

    ``band`` is the feed band the row belongs to (``None``: all bands); ``kind`` is ``"physical"``,
    ``"range"``, ``"user"`` or ``"expert"``.
    """

    name: str
    a: float
    b: float
    rhs: float
    label: str = ""
    enabled: bool = True
    band: int | None = None
    kind: str = "physical"
    paper: str = ""  # the paper's b_i

    def value(self, x1: float, x2: float) -> float:
        """Left-hand side ``a x1 + b x2``."""
        return self.a * x1 + self.b * x2


@dataclass(frozen=True)
class Physics:
    """What is needed to turn (n, S) into V, forces, power, tool life, roughness, deflection."""

    d_mm: float
    t_mm: float
    bands: tuple[tuple[float, float, Mapping[str, float]], ...]  # (s_lo, s_hi, {cv,x,y,m})
    k_v: float
    tool_life_min: float
    forces: Mapping[str, tuple[float, float, float, float, float]]  # comp -> (cp, x, y, n, K_p)
    nose_radius_mm: float
    deflection_k: float  # P = deflection_k * f  [N per mm]
    rz_model: str
    rz_coef: Mapping[str, float] | None
    phi_deg: float
    phi1_deg: float


@dataclass(frozen=True)
class Model:
    """The LP of one case: rows, feed bands, and the physics for the report (``None`` in expert mode)."""

    rows: tuple[Row, ...]
    bands: tuple[tuple[float, float], ...]  # feed bands (s_lo, s_hi) mm/rev, 0 / inf open
    physics: Physics | None
    d_mm: float | None
    path_length_mm: float
    speed_series: tuple[float, ...] = ()
    feed_series: tuple[float, ...] = ()
    notes: tuple[str, ...] = ()
    coefficients: Mapping[str, Any] = field(default_factory=dict)
    file: str | None = None

    def band_rows(self, k: int, enabled_only: bool = True) -> list[Row]:
        """Rows that apply in feed band ``k`` (plus the band's own feed limits)."""
        rows = [r for r in self.rows if (r.band is None or r.band == k) and (r.enabled or not enabled_only)]
        lo, hi = self.bands[k]
        if lo > 0:
            rows.append(Row("band_lo", 0.0, -1.0, -math.log(lo), f"feed band S >= {lo:g}", kind="band"))
        if math.isfinite(hi):
            rows.append(Row("band_hi", 0.0, 1.0, math.log(hi), f"feed band S <= {hi:g}", kind="band"))
        return rows


def _interp(xkey: str, ykey: str, x: float, *, data: CuttingData, src: str,
            path: Sequence[str]) -> float:
    xs = np.asarray(data.get(src, *path, xkey), dtype=float)
    ys = np.asarray(data.get(src, *path, ykey), dtype=float)
    if xs.shape != ys.shape or xs.size < 1 or np.any(np.diff(xs) <= 0):
        raise InputError(f"table '{'.'.join(path)}' needs increasing {xkey} and as many {ykey} values",
                         file=data.files[src], field=".".join([*path, ykey]))
    return float(np.interp(x, xs, ys))  # clamped at the ends


def _mat_factor(rule: Mapping[str, Any], mat: Mapping[str, float], *, data: CuttingData, src: str,
                path: Sequence[str], exponent: float | None = None) -> float:
    prop = data.get(src, *path, "property")
    ref = float(data.get(src, *path, "ref"))
    e = float(exponent if exponent is not None else data.get(src, *path, "exponent"))
    scale = float(rule.get("scale", 1.0))
    if prop not in mat:
        raise InputError(f"the workpiece material has no '{prop}', needed by '{'.'.join(path)}' in {src}.toml",
                         file=data.files["materials"], field=str(prop))
    return scale * (float(mat[prop]) / ref) ** e


def build_model(case: TurningCase, data: CuttingData | None = None) -> Model:
    """Build the LP rows (3)-(13) of ``case`` from the cutting database (or its expert rows).

    Raises
    ------
    InputError
        unknown material/tool/machine, or a coefficient missing for a constraint that is switched on
        (the message names the TOML file and the key).
    """
    f = case.file
    disabled = set(case.disabled)
    factors = dict(case.limit_factor)
    path_len = case.machined_length_mm + case.approach_mm
    if case.mode == "expert":
        rows = []
        for name, a, b, rhs, en in case.expert_rows:
            fac = factors.get(name, 1.0)
            rows.append(Row(name, a, b, rhs + math.log(fac), LABELS.get(name, name), en and name not in disabled,
                            None, "expert", _paper_b(name)))
        rows += _user_rows(case, disabled)
        return Model(tuple(rows), ((0.0, math.inf),), None, case.diameter_mm, path_len,
                     notes=("expert mode: LP rows taken from the case file",), file=f)
    data = data if data is not None else load_data()
    mats = data.materials
    if case.material not in mats:
        raise InputError(f"unknown workpiece material {case.material!r}; known: {', '.join(sorted(mats))}",
                         file=f or data.files["materials"], field="workpiece.material")
    if case.tool not in data.tools:
        raise InputError(f"unknown tool material {case.tool!r}; known: {', '.join(sorted(data.tools))}",
                         file=f or data.files["tools"], field="tool.material")
    if case.machine not in data.machines:
        raise InputError(f"unknown machine {case.machine!r}; known: {', '.join(sorted(data.machines))}",
                         file=f or data.files["machines"], field="machine.id")
    mat = dict(data.get("materials", case.material))
    if case.hb is not None:
        mat["hb"] = case.hb
    if case.sigma_b_mpa is not None:
        mat["sigma_b_mpa"] = case.sigma_b_mpa
    group = data.get("materials", case.material, "group", what="material field")
    mach = data.get("machines", case.machine)

    def machine_value(attr: str, key: str) -> float:
        v = getattr(case, attr)
        if v is None:
            v = float(data.get("machines", case.machine, key, what="machine field"))
        return float(v)

    n_min, n_max = machine_value("n_min_rpm", "n_min_rpm"), machine_value("n_max_rpm", "n_max_rpm")
    s_min, s_max = machine_value("s_min_mm_rev", "s_min_mm_rev"), machine_value("s_max_mm_rev", "s_max_mm_rev")
    for lo, hi, klo, khi in ((n_min, n_max, "n_min_rpm", "n_max_rpm"), (s_min, s_max, "s_min_mm_rev", "s_max_mm_rev")):
        if lo >= hi:
            raise InputError(f"range is inverted or empty: {klo} = {lo:g} is not below {khi} = {hi:g} "
                             f"(machine {case.machine!r} with the case's overrides)",
                             file=f or data.files["machines"], field=f"machine.{khi}")
    D, t = case.diameter_mm, case.depth_mm
    phi_deg, phi1_deg = math.degrees(case.phi), math.degrees(case.phi1)
    coeffs: dict[str, Any] = {"material_group": group}
    notes: list[str] = []

    def on(name: str) -> bool:
        return name not in disabled

    rows: list[Row] = []

    def add(name: str, a: float, b: float, c: float, band: int | None = None) -> None:
        if not c > 0 or not math.isfinite(c):
            raise InputError(f"constraint {name!r}: its limit evaluates to {c:g}, not a positive number",
                             file=f, field=name)
        rows.append(Row(name, a, b, math.log(c * factors.get(name, 1.0)), LABELS[name], on(name), band,
                        "physical", _paper_b(name)))

    # ---- (3) tool life: n S^y <= 318 Cv Kv / (T^m t^x D), per feed band
    bands_raw = data.get("speed", group, "bands", what="speed coefficient table")
    if case.speed_bands == "first":
        bands_raw = bands_raw[:1]
        notes.append("speed_bands = first: the S <= band coefficients are used for every feed (as the paper)")
    rule = data.get("speed", group, "k_mv")
    k_mv = _mat_factor(rule, mat, data=data, src="speed", path=(group, "k_mv"))
    k_uv = float(data.get("speed", group, "k_uv", case.tool, what=f"tool factor K_uv for {case.tool}"))
    k_pv = float(data.get("speed", group, "k_pv", case.surface, what=f"surface factor K_pv for {case.surface!r}"))
    k_phiv = _interp("phi_deg", "k", phi_deg, data=data, src="speed", path=("k_phi_v",))
    k_v = k_mv * k_uv * k_pv * k_phiv
    coeffs["speed"] = {"K_mv": k_mv, "K_uv": k_uv, "K_pv": k_pv, "K_phi_v": k_phiv, "K_v": k_v}
    bands: list[tuple[float, float]] = []
    phys_bands = []
    lo = 0.0
    for i, b in enumerate(bands_raw):
        hi = float(b.get("s_max_mm_rev", math.inf)) if case.speed_bands == "auto" else math.inf
        if i == len(bands_raw) - 1:
            hi = math.inf
        cv: dict[str, float] = {}
        for k in ("cv", "x", "y", "m"):
            if k not in b:
                raise InputError(f"missing coefficient '{k}' in feed band {i + 1}", file=data.files["speed"],
                                 field=f"{group}.bands[{i}].{k}")
            cv[k] = float(b[k])
        bands.append((lo, hi))
        phys_bands.append((lo, hi, cv))
        c = 1000.0 / math.pi * cv["cv"] * k_v / (case.tool_life_min ** cv["m"] * t ** cv["x"] * D)
        add("tool_life", 1.0, cv["y"], c, band=i)
        lo = hi
    coeffs["speed"]["bands"] = [dict(v) | {"s_lo": lo_, "s_hi": hi_} for lo_, hi_, v in phys_bands]

    # ---- forces: P = 10 Cp t^x S^y V^n Kp
    needed = {"pz": ("power", "holder", "insert", "accuracy"), "px": ("feed_mechanism",), "py": ("accuracy",)}
    forces: dict[str, tuple[float, float, float, float, float]] = {}
    missing = [(c, [u for u in us if on(u)]) for c, us in needed.items()
               if not (isinstance(data.force.get(group), Mapping) and c in data.force[group])]
    missing = [(c, us) for c, us in missing if us]
    if missing:
        what = "; ".join(f"'{group}.{c}' (P_{c[1]}) needed by {', '.join(us)}" for c, us in missing)
        raise InputError(f"missing force coefficients {what}; add them or switch those constraints off",
                         file=data.files["force"], field=f"{group}.{missing[0][0]}")
    for comp in needed:
        if not (isinstance(data.force.get(group), Mapping) and comp in data.force[group]):
            continue
        cp = data.get("force", group, comp)
        vals = []
        for k in ("cp", "x", "y", "n"):
            if k not in cp:
                raise InputError(f"missing coefficient '{k}'", file=data.files["force"], field=f"{group}.{comp}.{k}")
            vals.append(float(cp[k]))
        exps = data.get("force", group, "k_mp", "exponent")
        if comp not in exps:
            raise InputError("missing K_mp exponent", file=data.files["force"], field=f"{group}.k_mp.exponent.{comp}")
        k_mp = _mat_factor(data.get("force", group, "k_mp"), mat, data=data, src="force",
                           path=(group, "k_mp"), exponent=float(exps[comp]))
        k_phi = _interp("phi_deg", comp, phi_deg, data=data, src="force", path=("k_phi_p",))
        k_gam = _interp("gamma_deg", comp, math.degrees(case.gamma), data=data, src="force",
                        path=("k_gamma_p",))
        k_lam = _interp("lambda_deg", comp, math.degrees(case.lam), data=data, src="force",
                        path=("k_lambda_p",))
        kp = k_mp * k_phi * k_gam * k_lam
        forces[comp] = (vals[0], vals[1], vals[2], vals[3], kp)
        coeffs[f"force_{comp}"] = {"Cp": vals[0], "x": vals[1], "y": vals[2], "n": vals[3], "K_mp": k_mp,
                                   "K_phi_p": k_phi, "K_gamma_p": k_gam, "K_lambda_p": k_lam, "K_p": kp}

    def force_row(name: str, comp: str, p_max: float, extra: float = 1.0) -> None:
        """P_comp * extra <= p_max  ->  n^n S^y <= p_max 1000^n / (10 Cp t^x (pi D)^n Kp extra)."""
        if comp not in forces:
            rows.append(Row(name, 0.0, 1.0, math.inf, LABELS[name], False, None, "physical", _paper_b(name)))
            return
        cp, x, y, n, kp = forces[comp]
        c = p_max * 1000.0 ** n / (10.0 * cp * t ** x * (math.pi * D) ** n * kp * extra)
        add(name, n, y, c)

    # ---- (4) power: P_z V / 61200 <= N eta
    power, eta = machine_value("power_kw", "power_kw"), machine_value("efficiency", "efficiency")
    if "pz" in forces:
        cp, x, y, n, kp = forces["pz"]
        c = 6120.0 * 1000.0 ** (n + 1) * power * eta / (cp * t ** x * (math.pi * D) ** (n + 1) * kp)
        add("power", n + 1.0, y, c)
    else:
        rows.append(Row("power", 1.0, 0.0, math.inf, LABELS["power"], False, None, "physical", "b2"))
    # ---- (5) feed mechanism: P_x <= P_feed
    force_row("feed_mechanism", "px", machine_value("feed_force_max_n", "feed_force_max_n"))
    # ---- (6) tool holder in bending: P_z <= B H^2 [sigma] / (6 l)
    p_holder = case.holder_b_mm * case.holder_h_mm ** 2 * case.holder_stress_mpa / (6.0 * case.holder_overhang_mm)
    force_row("holder", "pz", p_holder)
    # ---- (7) insert strength: P_z <= 340 c^1.35 t^0.77 (sin 60 / sin phi)^0.8   (reconstructed, see docs)
    p_insert = 340.0 * case.insert_thickness_mm ** 1.35 * t ** 0.77 * (
        math.sin(math.radians(60.0)) / math.sin(case.phi)) ** 0.8
    force_row("insert", "pz", p_insert)
    # ---- (9) accuracy: resultant sqrt(P_y^2 + P_z^2) <= k E J f_allow / L^3 (deflection of the part)
    E = float(mat.get("e_mpa", 0.0))
    if E <= 0 and on("accuracy"):
        raise InputError("material has no Young's modulus 'e_mpa' (needed by constraint 'accuracy')",
                         file=data.files["materials"], field=f"{case.material}.e_mpa")
    d_min = D - 2.0 * t
    J = math.pi * d_min ** 4 / 64.0
    f_allow = case.deflection_share * case.tolerance_mm
    k_fix = FIXTURES[case.fixture]
    stiff = k_fix * E * J / case.length_mm ** 3  # N per mm of deflection
    p_acc = stiff * f_allow
    lam = 0.0
    if "py" in forces and "pz" in forces:
        ref = _force(forces["pz"], t, 1.0, 100.0), _force(forces["py"], t, 1.0, 100.0)
        lam = ref[0] / ref[1]
    force_row("accuracy", "py", p_acc, math.sqrt(1.0 + lam * lam))
    coeffs["accuracy"] = {"fixture_k": k_fix, "E_mpa": E, "J_mm4": J, "f_allow_mm": f_allow,
                          "P_allow_N": p_acc, "lambda_Pz_over_Py": lam}
    coeffs["holder_P_allow_N"] = p_holder
    coeffs["insert_P_allow_N"] = p_insert
    # ---- (8) roughness
    rz_coef = None
    if case.roughness_model == "geometric":
        c = math.sqrt(8.0 * case.nose_radius_mm * case.rz_um / 1000.0)
        add("roughness", 0.0, 1.0, c)
    else:
        e = data.get("roughness", "empirical", group, what="empirical roughness coefficients")
        rz_coef = {}
        for k in ("cs", "y", "u", "x", "z"):
            if k not in e:
                raise InputError("missing coefficient", file=data.files["roughness"],
                                 field=f"empirical.{group}.{k}")
            rz_coef[k] = float(e[k])
        c = (rz_coef["cs"] * case.rz_um ** rz_coef["y"] * case.nose_radius_mm ** rz_coef["u"]
             / (t ** rz_coef["x"] * phi_deg ** rz_coef["z"] * phi1_deg ** rz_coef["z"]))
        add("roughness", 0.0, 1.0, c)
    coeffs["roughness"] = {"model": case.roughness_model, "S_max_mm_rev": c} | (rz_coef or {})
    # ---- (10)-(13) machine ranges
    add("s_min", 0.0, -1.0, 1.0 / s_min)
    add("s_max", 0.0, 1.0, s_max)
    add("n_min", -1.0, 0.0, 1.0 / n_min)
    add("n_max", 1.0, 0.0, n_max)
    rows += _user_rows(case, disabled)
    order = {n: i for i, n in enumerate(CONSTRAINT_NAMES)}
    rows.sort(key=lambda r: (order.get(r.name, len(order)), r.band or 0))
    physics = Physics(D, t, tuple(phys_bands), k_v, case.tool_life_min, forces, case.nose_radius_mm,
                      stiff / math.sqrt(1.0 + lam * lam) if lam else stiff, case.roughness_model, rz_coef,
                      phi_deg, phi1_deg)
    return Model(tuple(rows), tuple(bands), physics, D, path_len,
                 tuple(float(v) for v in mach.get("speed_series_rpm", ())),
                 tuple(float(v) for v in mach.get("feed_series_mm_rev", ())), tuple(notes), coeffs, f)


def _paper_b(name: str) -> str:
    return f"b{CONSTRAINT_NAMES.index(name) + 1}" if name in CONSTRAINT_NAMES else ""


def _user_rows(case: TurningCase, disabled: set[str]) -> list[Row]:
    fac = dict(case.limit_factor)
    return [Row(u.name, u.a, u.b, math.log(u.c * fac.get(u.name, 1.0)), f"user: n^{u.a:g} S^{u.b:g} <= {u.c:g}",
                u.name not in disabled, None, "user") for u in case.user_rows]


def _force(coef: tuple[float, float, float, float, float], t: float, s: float, v: float) -> float:
    cp, x, y, n, kp = coef
    return 10.0 * cp * t ** x * s ** y * v ** n * kp


# ================================================================================== solving
@dataclass(frozen=True)
class LPSolution:
    """Optimum of the LP over all bands: ``x1, x2``, objective and the band used."""

    x1: float
    x2: float
    band: int
    per_band: tuple[tuple[float, float, float] | None, ...]  # (x1, x2, f) per band, None = infeasible


def _matrices(rows: Sequence[Row]) -> tuple[np.ndarray, np.ndarray]:
    rows = [r for r in rows if math.isfinite(r.rhs)]
    A = np.array([[r.a, r.b] for r in rows], dtype=float).reshape(-1, 2)
    b = np.array([r.rhs for r in rows], dtype=float)
    return A, b


def _linprog(rows: Sequence[Row]) -> tuple[str, np.ndarray | None]:
    from scipy.optimize import linprog  # lazy: keeps `import engine.turning` light

    A, b = _matrices(rows)
    if A.shape[0] == 0:
        return "unbounded", None
    res = linprog(c=[-1.0, -1.0], A_ub=A, b_ub=b, bounds=[(None, None), (None, None)], method="highs")
    if res.status == 0:
        return "optimal", np.asarray(res.x, dtype=float)
    if res.status == 2:
        return "infeasible", None
    if res.status == 3:
        return "unbounded", None
    raise InputError(f"the LP solver failed: {res.message}")  # pragma: no cover - numerical trouble


def is_feasible(rows: Sequence[Row], tol: float = 1e-9) -> bool:
    """Exact feasibility of ``{a x1 + b x2 <= rhs}`` by Fourier-Motzkin elimination of ``x1``."""
    A, b = _matrices(rows)
    if A.shape[0] == 0:
        return True
    a1, a2 = A[:, 0], A[:, 1]
    pos, neg, zero = a1 > _TOL, a1 < -_TOL, np.abs(a1) <= _TOL
    c = [a2[zero]]
    d = [b[zero]]
    if pos.any() and neg.any():
        ip, ineg = np.nonzero(pos)[0], np.nonzero(neg)[0]
        P, N = np.meshgrid(ip, ineg, indexing="ij")
        P, N = P.ravel(), N.ravel()
        c.append(-a1[N] * a2[P] + a1[P] * a2[N])
        d.append(-a1[N] * b[P] + a1[P] * b[N])
    cc, dd = np.concatenate(c), np.concatenate(d)
    scale = np.maximum(np.abs(cc), 1.0)
    up, lo, z = cc > _TOL, cc < -_TOL, np.abs(cc) <= _TOL
    if np.any(dd[z] < -tol * scale[z]):
        return False
    hi = np.min(dd[up] / cc[up]) if up.any() else math.inf
    low = np.max(dd[lo] / cc[lo]) if lo.any() else -math.inf
    return bool(low <= hi + tol)


def solve_model(model: Model) -> LPSolution:
    """Maximise ``x1 + x2`` over every feed band (HiGHS); the best band wins.

    Raises
    ------
    InfeasibleError
        no band is feasible (message: the conflicting constraints) or the problem is unbounded
        (message: what limit is missing).
    """
    per: list[tuple[float, float, float] | None] = []
    unbounded = False
    for k in range(len(model.bands)):
        status, x = _linprog(model.band_rows(k))
        if status == "optimal" and x is not None:
            per.append((float(x[0]), float(x[1]), float(x[0] + x[1])))
        else:
            unbounded |= status == "unbounded"
            per.append(None)
    if unbounded:
        raise InfeasibleError(
            "n*S is unbounded: no enabled constraint limits the spindle speed and feed from above "
            "(enable n_max and s_max, or the power / tool-life rows)", file=model.file, field="constraints"
        )
    if all(p is None for p in per):
        raise _infeasible_error(model)
    best = max((i for i, p in enumerate(per) if p is not None), key=lambda i: per[i][2])  # type: ignore[index]
    x1, x2, _f = per[best]  # type: ignore[misc]
    return LPSolution(x1, x2, best, tuple(per))


def _feasible_any(model: Model, removed: Iterable[str] = ()) -> bool:
    removed = set(removed)
    for k in range(len(model.bands)):
        rows = [r for r in model.band_rows(k) if r.name not in removed]
        if is_feasible(rows):
            return True
    return False


def minimal_removal_sets(model: Model, max_size: int = 3) -> list[tuple[str, ...]]:
    """The smallest sets of enabled constraints whose removal makes the model feasible.

    Brute force over subsets of increasing size (at most ``max_size``); band limits are not candidates.
    """
    names = sorted({r.name for r in model.rows if r.enabled and math.isfinite(r.rhs)},
                   key=lambda n: (CONSTRAINT_NAMES.index(n) if n in CONSTRAINT_NAMES else 99, n))
    for size in range(1, max_size + 1):
        found = [s for s in itertools.combinations(names, size) if _feasible_any(model, s)]
        if found:
            return found
    return []


def _conflict_core(model: Model) -> list[str]:
    """A minimal infeasible subset (deletion filter) of the enabled rows, for the band nearest feasibility."""
    names = [n for n in dict.fromkeys(r.name for r in model.rows if r.enabled and math.isfinite(r.rhs))]
    core = list(names)
    for n in names:
        trial = [m for m in core if m != n]
        removed = set(names) - set(trial)
        if not _feasible_any(model, removed):
            core = trial
    return core


def _describe_row(r: Row) -> str:
    c = math.exp(r.rhs) if r.rhs < 700 else math.inf
    if r.a == 0 and r.b != 0:
        v = c ** (1.0 / r.b)
        return f"S {'<=' if r.b > 0 else '>='} {v:.4g} mm/rev"
    if r.b == 0 and r.a != 0:
        v = c ** (1.0 / r.a)
        return f"n {'<=' if r.a > 0 else '>='} {v:.4g} rpm"
    return f"n^{r.a:g} * S^{r.b:g} <= {c:.4g}"


def _infeasible_error(model: Model) -> InfeasibleError:
    core = _conflict_core(model)
    sets = minimal_removal_sets(model)
    by_name = {r.name: r for r in model.rows}
    parts = [f"'{n}' ({by_name[n].label or n}: {_describe_row(by_name[n])})" for n in core if n in by_name]
    msg = "no spindle speed and feed satisfy every constraint: " + " conflicts with ".join(parts) if parts else (
        "no spindle speed and feed satisfy every constraint")
    if sets:
        msg += "; removing " + " or ".join("{" + ", ".join(s) + "}" for s in sets[:6]) + " restores feasibility"
    err = InfeasibleError(msg, file=model.file, field="constraints")
    err.conflict = tuple(core)  # type: ignore[attr-defined]
    err.removal_sets = tuple(sets)  # type: ignore[attr-defined]
    return err


# ================================================================================== evaluation
def evaluate(model: Model, n_rpm: float, s_mm_rev: float) -> dict[str, float | None]:
    """Physical quantities at ``(n, S)``: V, forces, power, tool life, roughness, deflection, time."""
    out: dict[str, float | None] = {
        "n_rpm": n_rpm, "feed_mm_rev": s_mm_rev,
        "feed_mm_min": n_rpm * s_mm_rev,
        "machine_time_min": model.path_length_mm / (n_rpm * s_mm_rev),
    }
    out["machine_time_s"] = 60.0 * out["machine_time_min"]  # type: ignore[operator]
    out["speed_m_min"] = math.pi * model.d_mm * n_rpm / 1000.0 if model.d_mm else None
    ph = model.physics
    keys = ("force_pz_n", "force_py_n", "force_px_n", "power_kw", "tool_life_min", "rz_um", "deflection_mm")
    for k in keys:
        out[k] = None
    if ph is None:
        return out
    v = math.pi * ph.d_mm * n_rpm / 1000.0
    for comp in ("pz", "py", "px"):
        if comp in ph.forces:
            out[f"force_{comp}_n"] = _force(ph.forces[comp], ph.t_mm, s_mm_rev, v)
    if out["force_pz_n"] is not None:
        out["power_kw"] = out["force_pz_n"] * v / _POWER_CONST  # type: ignore[operator]
    for lo, hi, cv in ph.bands:
        if lo <= s_mm_rev <= hi or hi == math.inf:
            vt = cv["cv"] * ph.k_v / (ph.t_mm ** cv["x"] * s_mm_rev ** cv["y"])  # V at T = 1 min
            out["tool_life_min"] = (vt / v) ** (1.0 / cv["m"])
            break
    if ph.rz_model == "geometric":
        out["rz_um"] = 1000.0 * s_mm_rev ** 2 / (8.0 * ph.nose_radius_mm)
    elif ph.rz_coef is not None:
        r = ph.rz_coef
        out["rz_um"] = (s_mm_rev * ph.t_mm ** r["x"] * ph.phi_deg ** r["z"] * ph.phi1_deg ** r["z"]
                        / (r["cs"] * ph.nose_radius_mm ** r["u"])) ** (1.0 / r["y"])
    if "py" in ph.forces and out["force_pz_n"] is not None:
        res = math.hypot(out["force_py_n"], out["force_pz_n"])  # type: ignore[arg-type]
        out["deflection_mm"] = res / ph.deflection_k
    return out


# ================================================================================== result
@dataclass(frozen=True)
class TurningResult:
    """The optimum and its report.  See :func:`result_to_json` for the field list."""

    x1: float
    x2: float
    n_rpm: float
    feed_mm_rev: float
    band: int
    quantities: Mapping[str, float | None]
    active: tuple[str, ...]
    slack: Mapping[str, float]
    utilisation: Mapping[str, float]
    disabled: tuple[str, ...]
    rows: tuple[Row, ...]
    model: Model
    snapped: Mapping[str, Any] | None = None
    notes: tuple[str, ...] = ()


def _row_report(model: Model, band: int, x1: float, x2: float, tol: float = 1e-6
                ) -> tuple[list[str], dict[str, float], dict[str, float], list[Row]]:
    rows = [r for r in model.rows if (r.band is None or r.band == band) and math.isfinite(r.rhs)]
    active, slack, util = [], {}, {}
    for r in rows:
        if not r.enabled:
            continue
        s = r.rhs - r.value(x1, x2)
        slack[r.name] = s
        util[r.name] = math.exp(-s)
        if abs(s) <= tol:
            active.append(r.name)
    return active, slack, util, rows


def snap_to_series(model: Model, x1_opt: float, x2_opt: float) -> dict[str, Any] | None:
    """The best feasible (n, S) pair on the machine's discrete speed/feed series.

    A missing series is continuous.  Returns ``None`` when the machine has neither series, and a dict
    with ``feasible = False`` when no discrete pair satisfies the constraints.
    """
    if not model.speed_series and not model.feed_series:
        return None
    best: tuple[float, float, float] | None = None
    exact: dict[float, float] = {}  # log -> the series value itself (no exp(log()) round-off)
    if model.speed_series:
        x1_cands = [math.log(n) for n in model.speed_series]
        exact.update({math.log(n): n for n in model.speed_series})
    else:
        x1_cands = sorted({x1_opt, *_vertex_x1(model)})
    exact.update({math.log(s): s for s in model.feed_series})
    for k in range(len(model.bands)):
        rows = model.band_rows(k)
        for x1 in x1_cands:
            lo, hi = -math.inf, math.inf
            ok = True
            for r in rows:
                if not math.isfinite(r.rhs):
                    continue
                rest = r.rhs - r.a * x1
                if abs(r.b) <= _TOL:
                    ok &= rest >= -1e-9
                elif r.b > 0:
                    hi = min(hi, rest / r.b)
                else:
                    lo = max(lo, rest / r.b)
            if not ok or lo > hi + 1e-12:
                continue
            if model.feed_series:
                cands = [math.log(s) for s in model.feed_series if lo - 1e-12 <= math.log(s) <= hi + 1e-12]
                if not cands:
                    continue
                x2 = max(cands)
            else:
                if not math.isfinite(hi):
                    continue
                x2 = hi
            if best is None or x1 + x2 > best[2] + 1e-12:
                best = (x1, x2, x1 + x2)
    if best is None:
        return {"feasible": False, "message": "no pair of the machine's discrete speeds and feeds is feasible"}
    x1, x2, _ = best
    n = exact.get(x1, math.exp(x1)) if model.speed_series else math.exp(x1)
    sv = exact.get(x2, math.exp(x2)) if model.feed_series else math.exp(x2)
    q = evaluate(model, n, sv)
    return {"feasible": True, "n_rpm": n, "feed_mm_rev": sv, "x1": x1, "x2": x2,
            "speed_m_min": q["speed_m_min"], "machine_time_min": q["machine_time_min"],
            "power_kw": q["power_kw"], "ratio_to_continuous": math.exp(x1 + x2 - x1_opt - x2_opt)}


def _vertex_x1(model: Model) -> list[float]:
    xs = []
    for k in range(len(model.bands)):
        for v in feasible_polygons(model, k):
            xs.extend(float(p[0]) for p in v)
    return xs


def optimise(case: TurningCase | str | Path, data: CuttingData | None = None, *, snap: bool = False,
             state: State | None = None) -> TurningResult:
    """Optimise the cutting mode of ``case`` (a case object or a case file).

    Parameters
    ----------
    case:
        the set-up; a path is read with :func:`load_case`.
    data:
        the cutting database (default: the shipped one, loaded on demand).
    snap:
        also report the best feasible pair on the machine's discrete speed/feed series.
    state:
        progress/cancellation (:mod:`engine.state`).

    Returns
    -------
    TurningResult
        n (rpm), S (mm/rev), x1 = ln n, x2 = ln S, V (m/min), forces (N), power (kW), machine time
        (min), tool life (min), active constraints and the slack ``rhs - (a x1 + b x2)`` of every row.

    Raises
    ------
    InputError, InfeasibleError
    """
    if state is not None:
        state.progress(0.0, "building the model")
    if not isinstance(case, TurningCase):
        case = load_case(case)
    model = build_model(case, data)
    check_cancel(state)
    if state is not None:
        state.progress(0.3, "solving the LP")
    sol = solve_model(model)
    check_cancel(state)
    n, s = math.exp(sol.x1), math.exp(sol.x2)
    active, slack, util, rows = _row_report(model, sol.band, sol.x1, sol.x2)
    q = evaluate(model, n, s)
    snapped = snap_to_series(model, sol.x1, sol.x2) if snap else None
    notes = list(model.notes)
    if len(model.bands) > 1:
        lo, hi = model.bands[sol.band]
        notes.append(f"optimum in feed band {sol.band + 1} ({lo:g} < S <= {hi:g} mm/rev) of the Taylor table")
    if state is not None:
        state.progress(1.0, "done")
    return TurningResult(sol.x1, sol.x2, n, s, sol.band, q, tuple(active), slack, util,
                         tuple(r.name for r in model.rows if not r.enabled), tuple(rows), model, snapped, tuple(notes))


def result_to_json(res: TurningResult) -> dict[str, Any]:
    """The report as a JSON-ready dict (keys carry units)."""
    q = dict(res.quantities)
    out: dict[str, Any] = {
        "n_rpm": res.n_rpm, "feed_mm_rev": res.feed_mm_rev, "x1": res.x1, "x2": res.x2,
        "speed_m_min": q.get("speed_m_min"), "power_kw": q.get("power_kw"),
        "machine_time_min": q.get("machine_time_min"), "machine_time_s": q.get("machine_time_s"),
        "feed_mm_min": q.get("feed_mm_min"), "tool_life_min": q.get("tool_life_min"),
        "force_pz_n": q.get("force_pz_n"), "force_py_n": q.get("force_py_n"), "force_px_n": q.get("force_px_n"),
        "rz_um": q.get("rz_um"), "deflection_mm": q.get("deflection_mm"),
        "active": list(res.active), "slack": dict(res.slack), "utilisation": dict(res.utilisation),
        "disabled": list(res.disabled), "feed_band": res.band + 1,
        "rows": [{"name": r.name, "paper": r.paper, "label": r.label, "a": r.a, "b": r.b, "rhs": r.rhs,
                  "enabled": r.enabled} for r in res.rows],
        "coefficients": _jsonable(res.model.coefficients),
        "notes": list(res.notes),
    }
    if res.snapped is not None:
        out["snapped"] = dict(res.snapped)
    return out


def _jsonable(obj: Any) -> Any:
    if isinstance(obj, Mapping):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


# ================================================================================== plotting data
def _clip_polygon(poly: list[tuple[float, float]], a: float, b: float, rhs: float) -> list[tuple[float, float]]:
    """Sutherland-Hodgman clip of a convex polygon by ``a x + b y <= rhs``."""
    out: list[tuple[float, float]] = []
    if not poly:
        return out
    for i in range(len(poly)):
        p, q = poly[i], poly[(i + 1) % len(poly)]
        fp, fq = a * p[0] + b * p[1] - rhs, a * q[0] + b * q[1] - rhs
        if fp <= 1e-12:
            out.append(p)
        if (fp < -1e-12 < fq) or (fq < -1e-12 < fp):
            tt = fp / (fp - fq)
            out.append((p[0] + tt * (q[0] - p[0]), p[1] + tt * (q[1] - p[1])))
    return out


def _box(model: Model, around: tuple[float, float] | None = None) -> tuple[float, float, float, float]:
    """Plot window in (x1, x2): the machine range widened by 25 %, else +-1.5 around ``around``."""
    rows = {r.name: r for r in model.rows if math.isfinite(r.rhs)}
    x1lo = -rows["n_min"].rhs if "n_min" in rows else None
    x1hi = rows["n_max"].rhs if "n_max" in rows else None
    x2lo = -rows["s_min"].rhs if "s_min" in rows else None
    x2hi = rows["s_max"].rhs if "s_max" in rows else None
    cx, cy = around if around is not None else (6.0, 0.0)
    x1lo = x1lo if x1lo is not None else cx - 1.5
    x1hi = x1hi if x1hi is not None else cx + 1.5
    x2lo = x2lo if x2lo is not None else cy - 1.5
    x2hi = x2hi if x2hi is not None else cy + 1.5
    m1, m2 = 0.12 * (x1hi - x1lo) + 0.05, 0.12 * (x2hi - x2lo) + 0.05
    return x1lo - m1, x1hi + m1, x2lo - m2, x2hi + m2


def feasible_polygons(model: Model, band: int, box: tuple[float, float, float, float] | None = None
                      ) -> list[list[tuple[float, float]]]:
    """The feasible region of one feed band as a polygon in (x1, x2), clipped to ``box``."""
    x1a, x1b, x2a, x2b = box if box is not None else (-50.0, 50.0, -50.0, 50.0)
    poly = [(x1a, x2a), (x1b, x2a), (x1b, x2b), (x1a, x2b)]
    for r in model.band_rows(band):
        if math.isfinite(r.rhs):
            poly = _clip_polygon(poly, r.a, r.b, r.rhs)
    return [poly] if len(poly) >= 3 else []


def _segment(a: float, b: float, rhs: float, box: tuple[float, float, float, float]
             ) -> tuple[tuple[float, float], tuple[float, float]] | None:
    x1a, x1b, x2a, x2b = box
    pts = []
    if abs(b) > _TOL:
        for x1 in (x1a, x1b):
            x2 = (rhs - a * x1) / b
            if x2a - 1e-12 <= x2 <= x2b + 1e-12:
                pts.append((x1, x2))
    if abs(a) > _TOL:
        for x2 in (x2a, x2b):
            x1 = (rhs - b * x2) / a
            if x1a - 1e-12 <= x1 <= x1b + 1e-12:
                pts.append((x1, x2))
    pts = sorted(set(pts))
    if len(pts) < 2:
        return None
    return pts[0], pts[-1]


def plot_data(res: TurningResult | Model) -> dict[str, Any]:
    """Everything the (n, S) plot draws, in rpm and mm/rev (log axes make every row a straight line).

    ``res`` is a result, or a bare :class:`Model` (e.g. an infeasible one: lines only, no optimum).
    Returns a dict with ``box`` (n_lo, n_hi, S_lo, S_hi), ``lines`` (name, label, enabled, active,
    band, n[2], S[2]), ``offscreen`` (rows whose line misses the window), ``regions`` (band, n[], S[]
    polygons), ``objective`` (n[2], S[2]) or ``None``,
    ``optimum`` (n, S) or ``None`` and, when snapped, ``snapped`` (n, S).
    """
    if isinstance(res, Model):
        model, center, active, band = res, None, (), None
    else:
        model, center, active, band = res.model, (res.x1, res.x2), res.active, res.band
    box = _box(model, center)
    if center is not None:
        box = (min(box[0], center[0] - 0.3), max(box[1], center[0] + 0.3), min(box[2], center[1] - 0.3),
               max(box[3], center[1] + 0.3))
    lines, offscreen = [], []
    for r in model.rows:
        if not math.isfinite(r.rhs):
            continue
        sub = box
        if r.band is not None:
            lo, hi = model.bands[r.band]
            sub = (box[0], box[1], max(box[2], math.log(lo)) if lo > 0 else box[2],
                   min(box[3], math.log(hi)) if math.isfinite(hi) else box[3])
            if sub[2] >= sub[3]:
                continue
        seg = _segment(r.a, r.b, r.rhs, sub)
        if seg is None:
            offscreen.append({"name": r.name, "label": r.label or r.name, "enabled": r.enabled, "band": r.band})
            continue
        (p1, q1), (p2, q2) = seg
        lines.append({"name": r.name, "label": r.label or r.name, "enabled": r.enabled, "band": r.band,
                      "active": r.name in active and (r.band is None or r.band == band),
                      "n": [math.exp(p1), math.exp(p2)], "S": [math.exp(q1), math.exp(q2)]})
    regions = []
    for k in range(len(model.bands)):
        for poly in feasible_polygons(model, k, box):
            regions.append({"band": k, "n": [math.exp(p[0]) for p in poly], "S": [math.exp(p[1]) for p in poly]})
    objective = None
    out: dict[str, Any] = {"box": tuple(math.exp(v) for v in box), "lines": lines, "offscreen": offscreen,
                           "regions": regions, "objective": None, "optimum": None}
    if isinstance(res, TurningResult):
        obj = _segment(1.0, 1.0, res.x1 + res.x2, box)
        if obj is not None:
            objective = {"n": [math.exp(obj[0][0]), math.exp(obj[1][0])],
                         "S": [math.exp(obj[0][1]), math.exp(obj[1][1])]}
        out["objective"] = objective
        out["optimum"] = (res.n_rpm, res.feed_mm_rev)
        if res.snapped and res.snapped.get("feasible"):
            out["snapped"] = (res.snapped["n_rpm"], res.snapped["feed_mm_rev"])
    return out


def optimise_with_plot(case: TurningCase, data: CuttingData | None = None, *, snap: bool = False,
                       state: State | None = None) -> dict[str, Any]:
    """:func:`optimise` plus :func:`plot_data`, for the dialog's worker.

    Returns ``{"result": TurningResult | None, "plot": dict, "error": InfeasibleError | None}``: an
    infeasible set-up still gets its constraint lines (no region, no optimum) and the error.
    Other :class:`InputError` propagate.
    """
    try:
        res = optimise(case, data, snap=snap, state=state)
    except InfeasibleError as exc:
        model = build_model(case, data)
        return {"result": None, "plot": plot_data(model), "error": exc}
    check_cancel(state)
    return {"result": res, "plot": plot_data(res), "error": None}
