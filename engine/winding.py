"""Winding line on a mandrel of revolution: Clairaut function, twist, circuits, pattern (MATH.md §A2).

Main entry points: :func:`winding_line` (mandrel + band + μ + :class:`engine.job.WindingSpec`) and
:func:`winding_line_for_job`.  The result, :class:`WindingLine`, holds per-point arrays over the
whole pattern (all circuits, in laying order) and the metadata the later stages need.

How C(z) is chosen (``WindingSpec.mode``)
-----------------------------------------
Conditions come from the two ends and from required winding angles:

* an end whose radius grows inwards (a dome pole, the small end of a cone) gets by default
  ``C = r_pole + b/2`` and the line turns around tangentially on the parallel where r = C
  (boundary condition (4)); ``pole_c_mm`` overrides the value.  If a user C is below the end
  radius of an *open* end (pipe, bottle neck) the line leaves that end with C(z_end) = C and turns
  on pins (with the dwell).  An open end without a user value is *free*.
* every ``angles`` entry (z, β) is a point condition C(z) = r(z)·sin β.

``geodesic``: λ = 0, C = const from the first angle (or the larger pole C); turnarounds wherever
r = C.  ``constant-lambda``: exactly two point conditions, the unknown constant λ found by
shooting (Newton on dC/dλ).  ``piecewise-lambda``: one constant λ per interval between
consecutive conditions.  ``minimax``: problem (5)-(6) by the direct search of
:mod:`engine.winding_clairaut`.  ``auto``: minimax where the wound zone has a concave part,
else geodesic / constant / piecewise by the number of conditions.  Free end pieces are geodesic.

Sign of λ: λ = k_g / k_n with k_n = −κ·n (n the outward normal, κ = dτ/ds) and
k_g = κ·(τ × n); with this sign C' = λ·[...] of (3) holds along z on the outgoing pass, and the
return pass (the mirror image run backwards) has the same λ at the same z.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from engine import winding_clairaut as wc
from engine.errors import InfeasibleError, InputError
from engine.state import check_cancel

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

_MIN_STEPS = 1999  # RK4/Simpson steps per pass at least (the output keeps points_per_pass)


# ------------------------------------------------------------------------------------------------
# Result
# ------------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class WindingLine:
    """A winding line over the whole pattern (all circuits concatenated in laying order).

    Per-point arrays (length N): ``z`` (mm), ``r`` (mm), ``dr`` (r'), ``v`` (twist, rad, unwrapped,
    non-decreasing), ``beta`` (winding angle to the meridian, rad, in [0, π/2]), ``direction`` (+1
    while z grows, −1 on the return pass; dwell points keep the sign of the pass they end),
    ``C`` (Clairaut function, mm), ``lam`` (λ = k_g/k_n), ``s`` (laid band length, mm), ``xyz`` (N,3),
    ``tau`` (N,3, unit tangent in the direction of travel), ``normal`` (N,3, outward surface normal),
    ``circuit`` and ``pass_id`` (int), ``dwell`` (bool: point on a dwell arc at a turnaround).

    Circuit k occupies ``circuit_slice(k)``: it starts where circuit k−1 ended (the shared point
    belongs to circuit k), and the slice includes the closing point.  Dwell points (extra mandrel
    rotation at a turnaround, or the turn on pins at an open end) lie on a parallel with β = π/2,
    C = r and τ along the parallel: on the polar boss next to a polar opening (a cylinder, λ = 0),
    else on the turnaround / end parallel of the mandrel, where λ = k_g/k_n = r' (reported as slip
    when |r'| > μ).  The last point of a dwell arc is the first point of the pass that follows and
    carries that pass's labels.

    Metadata: ``lambda_`` (the constant λ, or a list of pieces {z_from, z_to, lambda}; key
    ``lambda`` in :meth:`summary`), ``max_abs_lambda`` and ``z_at_max_lambda`` (of the line between
    the turnarounds; a dwell's λ is in ``turnarounds``), ``mu``, ``slips`` (every z range where
    |λ| > μ, dwell parallels included) and ``bridging`` (z ranges, mm), ``turnarounds`` (how each end
    is realised), pattern ``pattern_p``/``pattern_q``/``lead``,
    ``twist_per_circuit_rad`` (Δv, unwrapped), ``dwell_rad`` (left, right, including the closure),
    ``coverage``, ``circuit_order`` (pattern slot of circuit k), ``z_turn``/``end_kinds``.
    """

    z: FloatArray
    r: FloatArray
    dr: FloatArray
    v: FloatArray
    beta: FloatArray
    direction: IntArray
    C: FloatArray
    lam: FloatArray
    s: FloatArray
    xyz: FloatArray
    tau: FloatArray
    normal: FloatArray
    circuit: IntArray
    pass_id: IntArray
    dwell: NDArray[np.bool_]
    # metadata
    mode: str
    lambda_: float | list[dict[str, float]]
    max_abs_lambda: float
    z_at_max_lambda: float
    mu: float
    slips: list[tuple[float, float]]
    bridging: list[tuple[float, float]]
    circuits: int
    pattern_p: int
    pattern_q: int
    lead: str
    twist_per_circuit_rad: float
    dwell_rad: tuple[float, float]
    coverage: dict[str, float]
    circuit_order: list[int]
    z_turn: tuple[float, float]
    end_kinds: tuple[str, str]
    points_per_circuit: int
    band_width_mm: float
    notes: list[str] = field(default_factory=list)
    turnarounds: list[dict[str, Any]] = field(default_factory=list)
    """How each turnaround (left, right) is realised: kind, z, dwell, where the dwell lies, its λ, stable."""

    @property
    def ok(self) -> bool:
        """True when the band neither slips (|λ| <= μ) nor bridges (6)."""
        return not self.slips and not self.bridging

    def slip_lambda(self, z0_mm: float, z1_mm: float) -> float:
        """The largest |λ| on the slip range [z0, z1] (mm): of the line's points there and of a turnaround
        dwell on a parallel there (k_g/k_n = r' of the dwell, not part of ``max_abs_lambda``)."""
        from engine.periodic import tile_base

        tol = 1e-9 * max(1.0, abs(z0_mm), abs(z1_mm))
        # every circuit repeats circuit 0's z, dwell and λ where they are kept so: its points alone (the same maximum)
        z, dw, lam = (tile_base(self, f) for f in ("z", "dwell", "lam"))
        if z is None or dw is None or lam is None:
            z, dw, lam = self.z, self.dwell, self.lam
        on = (z >= z0_mm - tol) & (z <= z1_mm + tol) & ~dw
        best = float(np.max(np.abs(lam[on]))) if on.any() else 0.0
        for t in self.turnarounds:
            zd, lam = t.get("dwell_z_mm"), t.get("dwell_lambda")
            if t.get("dwell_deg", 0.0) > 0 and zd is not None and lam is not None and \
                    z0_mm - tol <= float(zd) <= z1_mm + tol:
                best = max(best, abs(float(lam)))
        return best

    @property
    def lambda_value(self) -> float | list[dict[str, float]]:
        """λ: a number for a constant-λ line, else the list of pieces {z_from, z_to, lambda}."""
        return self.lambda_

    def circuit_slice(self, k: int) -> slice:
        """Index range of circuit ``k`` (0-based) including its closing point."""
        if not 0 <= k < self.circuits:
            raise IndexError(f"circuit {k} out of range 0..{self.circuits - 1}")
        m = self.points_per_circuit
        return slice(k * m, (k + 1) * m + 1)

    @property
    def one_circuit(self) -> WindingLine:
        """The first circuit alone (a WindingLine with ``circuits = 1``)."""
        return self.take_circuit(0)

    def take_circuit(self, k: int) -> WindingLine:
        """Circuit ``k`` alone as a WindingLine (a per-point array kept as circuit 0 + rule stays so:
        only the circuit's rows are made)."""
        from engine.periodic import field_rows

        sl = self.circuit_slice(k)
        arrays = {name: field_rows(self, name, sl.start, sl.stop) for name in PER_POINT_FIELDS}
        return replace(self, circuits=1, circuit_order=[0], **arrays)

    @property
    def n_points(self) -> int:
        """Number of points N (without materialising an array)."""
        return len(self.__dict__["z"])

    def summary(self) -> dict[str, Any]:
        """JSON-able summary (``winder trajectory --json``)."""
        from engine.periodic import field_rows

        return {
            "mode": self.mode,
            "lambda": self.lambda_,
            "max_abs_lambda": self.max_abs_lambda,
            "z_at_max_lambda": self.z_at_max_lambda,
            "mu": self.mu,
            "ok": self.ok,
            "slips": [list(x) for x in self.slips],
            "bridging": [list(x) for x in self.bridging],
            "circuits": self.circuits,
            "pattern_p": self.pattern_p,
            "pattern_q": self.pattern_q,
            "lead": self.lead,
            "twist_per_circuit_rad": self.twist_per_circuit_rad,
            "dwell_deg": [math.degrees(d) for d in self.dwell_rad],
            "coverage": self.coverage,
            "circuit_order": self.circuit_order,
            "z_turn": list(self.z_turn),
            "end_kinds": list(self.end_kinds),
            "points": self.n_points,
            "points_per_circuit": self.points_per_circuit,
            "band_length_mm": float(field_rows(self, "s", self.n_points - 1, self.n_points)[0]),
            "beta_deg_range": [math.degrees(b) for b in _value_range(self, "beta")],
            "notes": self.notes,
            "turnarounds": self.turnarounds,
        }


PER_POINT_FIELDS: tuple[str, ...] = ("z", "r", "dr", "v", "beta", "direction", "C", "lam", "s", "xyz", "tau",
                                     "normal", "circuit", "pass_id", "dwell")
"""The per-point array fields of :class:`WindingLine`.  A line of at least
:data:`engine.periodic.DEFER_MIN_CIRCUITS` circuits keeps them as circuit 0 + rule
(:class:`engine.periodic.CircuitArray`); each becomes a plain array on its first read."""


def _install_fields() -> None:
    from engine.periodic import install_deferred_fields

    install_deferred_fields(WindingLine, PER_POINT_FIELDS)


_install_fields()


def _value_range(line: WindingLine, name: str) -> tuple[float, float]:
    """(min, max) of a per-point field, without materialising a deferred one."""
    from engine.periodic import deferred

    d = deferred(line, name)
    if d is not None:
        return d.value_range()
    a = getattr(line, name)
    return float(a.min()), float(a.max())


# ------------------------------------------------------------------------------------------------
# One pass
# ------------------------------------------------------------------------------------------------
@dataclass
class PassLine:
    """The outgoing pass z_a -> z_b at the output nodes."""

    z: FloatArray
    r: FloatArray
    dr: FloatArray
    C: FloatArray
    lam: FloatArray
    v: FloatArray
    s: FloatArray
    beta: FloatArray
    left: str
    right: str
    mode: str
    pieces: list[dict[str, float]]
    bridging: list[tuple[float, float]]
    notes: list[str]
    lam_all: FloatArray  # λ at every grid node (for max |λ| and slips)
    z_all: FloatArray


@dataclass
class _Cond:
    z: float
    C: float
    what: str  # "turn", "open", "angle"
    field: str


_SOFT_CAP = 1e-5
"""A minimax line that would ride C = r inside a pass is held at C <= r (1 − this) there (β <= 89.74°)."""
_TOUCH_ATTEMPTS = 4
"""Searches with the soft cap widened to the new touching nodes before a touch is refused."""


def _err(msg: str, fld: str | None, ctx: dict[str, Any], cls: type[InputError] = InputError) -> InputError:
    return cls(msg, file=ctx.get("file"), field=fld if ctx.get("job") else None)


def _end_is_dome(mandrel: Any, side: int) -> bool:
    """True when r grows going inwards from the end (a pole the line can turn around)."""
    L = mandrel.length
    if side == 0:
        z0, z1 = mandrel.z_min, mandrel.z_min + 1e-4 * L
    else:
        z0, z1 = mandrel.z_max, mandrel.z_max - 1e-4 * L
    r0, r1 = mandrel.r(np.array([z0, z1]))
    return bool(r1 > r0 + 1e-9 * max(1.0, r0))


def _crossing(mandrel: Any, C: float, z_start: float, z_stop: float, from_inside: bool = False) -> float | None:
    """First z from ``z_start`` towards ``z_stop`` where r(z) − C changes sign (mm), or None.

    ``from_inside``: the search starts on the line (r >= C there, possibly a turnaround parallel)
    and looks for the first parallel beyond the start where r <= C.
    """
    z = np.linspace(z_start, z_stop, 2001)
    j = [x for x in wc.joints(mandrel) if min(z_start, z_stop) < x < max(z_start, z_stop)]
    if j:
        z = np.sort(np.concatenate([z, j]))
        if z_stop < z_start:
            z = z[::-1]
    f = mandrel.r(z) - C
    if from_inside:
        i0, s0 = 1, 1.0
        idx = np.flatnonzero(f[1:] <= 0.0) + 1
    else:
        # skip samples on the starting parallel itself
        live = np.flatnonzero(np.abs(f) > 1e-12 * max(1.0, abs(C)))
        if not live.size:
            return None
        i0 = int(live[0])
        s0 = f[i0]
        idx = np.flatnonzero(np.sign(f[i0:]) != np.sign(s0)) + i0
    if not idx.size:
        return None
    i = int(idx[0])
    a, b = float(z[i - 1]), float(z[i])
    zz = np.linspace(a, b, 2001)
    ff = mandrel.r(zz) - C
    k = int(np.flatnonzero(np.sign(ff[1:]) != np.sign(s0))[0]) + 1
    if ff[k] == 0.0:
        return float(zz[k])
    # quadratic interpolation through three neighbouring samples (spacing ~1e-5 of a scan step)
    j0 = min(max(k - 1, 0), len(zz) - 3)
    x3, f3 = zz[j0 : j0 + 3], ff[j0 : j0 + 3]
    x = float(zz[k - 1] + (zz[k] - zz[k - 1]) * (-ff[k - 1]) / (ff[k] - ff[k - 1]))
    for _ in range(3):  # Newton on the interpolating parabola
        p = np.polyfit(x3 - x3[1], f3, 2)
        val = np.polyval(p, x - x3[1])
        der = np.polyval(np.polyder(p), x - x3[1])
        if der == 0:
            break
        x -= float(val / der)
    return float(min(max(x, min(a, b)), max(a, b)))


def _end_condition(
    mandrel: Any, side: int, C_end: float | None, fld: str, ctx: dict[str, Any], user: bool = True
) -> tuple[str, float, float | None]:
    """(kind, z, C) of one end: ('turn', z_t, C), ('open', z_end, C) or ('open', z_end, None)."""
    z_end = mandrel.z_min if side == 0 else mandrel.z_max
    z_other = mandrel.z_max if side == 0 else mandrel.z_min
    r_end = float(mandrel.r(np.array([z_end]))[0])
    name = "left" if side == 0 else "right"
    if C_end is None:
        return wc.OPEN, z_end, None
    if C_end >= mandrel.r_max * (1.0 - 1e-12) and (user or _end_is_dome(mandrel, side)):
        raise _err(
            f"{name} pole: Clairaut constant C = {C_end:.6g} mm is not below the largest mandrel radius "
            f"({mandrel.r_max:.6g} mm): the line cannot turn around (pole opening + band/2 >= local radius)",
            fld, ctx)
    if C_end > r_end:
        zt = _crossing(mandrel, C_end, z_end, z_other)
        if zt is None and not user and not _end_is_dome(mandrel, side):
            return wc.OPEN, z_end, None  # an open end (pipe, cone base): the line runs off it, C free
        if zt is None:
            raise _err(
                f"{name} pole: Clairaut constant C = {C_end:.6g} mm is not below the mandrel radius anywhere "
                f"(largest radius {mandrel.r_max:.6g} mm); the pole opening + band/2 must be smaller than the "
                "local radius for the line to turn around",
                fld, ctx)
        return wc.TURN, zt, C_end
    if _end_is_dome(mandrel, side) or r_end <= 0:
        raise _err(
            f"{name} pole: Clairaut constant C = {C_end:.6g} mm is below the pole opening radius {r_end:.6g} mm; "
            "the line would run into the opening", fld, ctx)
    return wc.OPEN, z_end, C_end


def solve_pass(
    mandrel: Any,
    band_width_mm: float,
    spec: Any,
    ctx: dict[str, Any],
    state: Any = None,
    c_override: float | None = None,
    unchecked: dict[str, Any] | None = None,
) -> PassLine:
    """C(z), λ, twist and band length of the outgoing pass (see the module docstring).

    ``unchecked`` (with ``c_override``): the geodesic pass without its bridging check (6) (``bridging``
    left empty), its grid, C and λ put in the dict under ``"grid"`` for :func:`_bridging` later: the
    pattern-closing root search solves many passes and keeps one."""
    b = float(band_width_mm)
    n_out = int(spec.points_per_pass)
    refine = max(1, math.ceil(_MIN_STEPS / (n_out - 1)))
    r_poles = mandrel.pole_radii
    notes: list[str] = []
    if spec.pole_c_mm is not None:
        pole_c: list[float | None] = [float(spec.pole_c_mm[0]), float(spec.pole_c_mm[1])]
        pole_fld = "winding.pole_c_mm"
        for c in pole_c:
            if c is not None and c <= 0:
                raise _err(f"pole Clairaut constant must be > 0, got {c} mm", pole_fld, ctx)
    else:
        pole_c = [r_poles[i] + 0.5 * b for i in (0, 1)]
        pole_fld = "band.width_mm"
    # angle conditions
    angles: list[_Cond] = []
    for i, a in enumerate(spec.angles):
        z = float(a.z_mm)
        if not mandrel.z_min <= z <= mandrel.z_max:
            raise _err(
                f"winding angle {a.angle_deg:g}° is required at z = {z:g} mm, outside the mandrel "
                f"[{mandrel.z_min:.6g}, {mandrel.z_max:.6g}] mm", f"winding.angles[{i}].z_mm", ctx)
        r = float(mandrel.r(np.array([z]))[0])
        angles.append(_Cond(z, r * math.sin(math.radians(a.angle_deg)), "angle", f"winding.angles[{i}].angle_deg"))
    angles.sort(key=lambda c: c.z)

    mode = spec.mode
    user_poles = spec.pole_c_mm is not None
    if c_override is not None or (mode == "geodesic" and angles):
        return _geodesic_pass(mandrel, pole_c, angles, n_out, refine, ctx, notes, pole_fld, c_override,
                              unchecked if c_override is not None else None)
    ends = [_end_condition(mandrel, i, pole_c[i], pole_fld, ctx, user_poles) for i in (0, 1)]
    if mode == "geodesic":  # C from the poles the line can turn at (an open end's default is no condition)
        live = [pole_c[i] if ends[i][2] is not None else None for i in (0, 1)]
        return _geodesic_pass(mandrel, live, angles, n_out, refine, ctx, notes, pole_fld, c_override)
    conds: list[_Cond] = []
    if ends[0][2] is not None:
        conds.append(_Cond(ends[0][1], ends[0][2], ends[0][0], pole_fld))
    za, zb = ends[0][1], ends[1][1]
    for a in angles:
        if not za < a.z < zb:
            raise _err(
                f"winding angle required at z = {a.z:g} mm cannot be reached: the line turns around at "
                f"z = {za:.6g} and {zb:.6g} mm", a.field.replace("angle_deg", "z_mm"), ctx)
        r = float(mandrel.r(np.array([a.z]))[0])
        if a.C >= r:
            raise _err(f"winding angle at z = {a.z:g} mm cannot be reached (C = {a.C:.6g} >= r = {r:.6g} mm)",
                       a.field, ctx)
        conds.append(a)
    if ends[1][2] is not None:
        conds.append(_Cond(ends[1][1], ends[1][2], ends[1][0], pole_fld))
    if not conds:
        raise _err(
            "the line is not determined: both ends are open (no pole to turn around); give a winding angle "
            "([[winding.angles]]) or pole_c_mm", "winding.angles", ctx)
    for c1, c2 in zip(conds[:-1], conds[1:]):
        if c2.z - c1.z < 1e-6:
            raise _err(f"two conditions at the same parallel z = {c1.z:g} mm", c2.field, ctx)
    # free ends: geodesic continuation from the outermost condition
    left_kind, right_kind = ends[0][0], ends[1][0]
    if ends[0][2] is None:
        zt = _crossing(mandrel, conds[0].C, conds[0].z, mandrel.z_min, from_inside=True)
        if zt is not None:
            za, left_kind = zt, wc.TURN
    if ends[1][2] is None:
        zt = _crossing(mandrel, conds[-1].C, conds[-1].z, mandrel.z_max, from_inside=True)
        if zt is not None:
            zb, right_kind = zt, wc.TURN
    # a laminate's grown surface carries the bridging its build-up steps may cause (engine.laminate)
    tol = mandrel.meta.get("concave_tol_mm") if isinstance(getattr(mandrel, "meta", None), dict) else None
    zones = mandrel.concave_zones(tol_mm=tol) if tol is not None else mandrel.concave_zones()
    concave = [zn for zn in zones if zn.z_to > za and zn.z_from < zb]
    same_c = max(c.C for c in conds) - min(c.C for c in conds) <= 1e-12 * max(c.C for c in conds)
    if mode == "auto":
        if concave:
            mode = "minimax"
        elif len(conds) == 1 or same_c:
            mode = "geodesic"
        elif len(conds) == 2:
            mode = "constant-lambda"
        else:
            mode = "piecewise-lambda"
    if mode == "constant-lambda" and len(conds) > 2:
        raise _err(
            f"a constant-λ line meets exactly two conditions, this job has {len(conds)} "
            "(pole turnarounds and required angles); use mode = 'piecewise-lambda' or 'minimax'",
            "winding.mode", ctx)
    check_cancel(state)
    grid = wc.build_grid(mandrel, za, zb, left_kind, right_kind, n_out, refine, [c.z for c in conds])
    idx = [grid.node_index(c.z) for c in conds]
    C = np.empty(grid.n)
    lam = np.zeros(grid.n - 1)
    rn, drn, d2rn = wc.node_geometry(grid)
    cvals = [float(rn[i]) if c.what == wc.TURN else c.C for c, i in zip(conds, idx)]
    # the natural solution: one constant λ per interval between conditions, geodesic free ends
    pieces: list[dict[str, float]] = []
    if same_c and mode != "piecewise-lambda":
        C[:] = conds[0].C
        cvals = [conds[0].C] * len(conds)
        conds = conds[:1]
        idx = idx[:1]
    try:
        for j in range(len(conds) - 1):
            i0, i1 = idx[j], idx[j + 1]
            guess = pieces[-1]["lambda"] if pieces else 0.0
            lj, cs = wc.shoot(grid, i0, i1, cvals[j], cvals[j + 1], guess)
            C[i0 : i1 + 1] = cs
            lam[i0:i1] = lj
            pieces.append({"z_from": float(grid.z[i0]), "z_to": float(grid.z[i1]), "lambda": lj})
            check_cancel(state)
    except ValueError as exc:
        raise _err(f"no line of constant deviation meets the conditions at z = {conds[j].z:.6g} and "
                   f"{conds[j + 1].z:.6g} mm: {exc}", conds[j + 1].field, ctx, InfeasibleError) from None
    C[: idx[0] + 1] = cvals[0]
    C[idx[-1] :] = cvals[-1]
    if idx[0] > 0:
        pieces.insert(0, {"z_from": float(grid.z[0]), "z_to": float(grid.z[idx[0]]), "lambda": 0.0})
    if idx[-1] < grid.n - 1:
        pieces.append({"z_from": float(grid.z[idx[-1]]), "z_to": float(grid.z[-1]), "lambda": 0.0})
    if mode == "geodesic" and len(conds) > 1:
        spread = max(cvals) - min(cvals)
        if spread > 1e-9 * max(cvals):
            raise _err(
                f"a geodesic has one Clairaut constant but the conditions need C from {min(cvals):.6g} to "
                f"{max(cvals):.6g} mm; use mode = 'auto' or 'constant-lambda'", "winding.mode", ctx)
    lo = wc.lower_bound(grid)
    if mode == "minimax":
        # each interval between conditions is its own problem (5)-(6): the natural constant-λ
        # piece where it keeps the band on the surface, else the direct search on that interval
        hi = rn.copy()
        hi[1:-1] *= 1.0 - 1e-9
        points = {i: v for i, v in zip(idx, cvals)}
        if left_kind == wc.TURN:
            points[0] = float(rn[0])
        if right_kind == wc.TURN:
            points[grid.n - 1] = float(rn[-1])
        F = _bracket(grid, C)
        bounds = sorted(set([0, *idx, grid.n - 1]))
        searched: list[float] = []
        for i0, i1 in zip(bounds[:-1], bounds[1:]):
            inner = slice(max(i0, 1), min(i1, grid.n - 2) + 1)
            if (F[i0 : i1 + 1] >= -1e-12).all() and (C[inner] < rn[inner]).all():
                continue
            lam0 = float(np.max(np.abs(lam[i0:i1]))) if i1 > i0 else 0.0
            # The path follows the tube's envelopes, so where the geodesic continuation would cross the
            # local radius it rides the cap C = r (β = 90°: a turnaround, not a pass).  Such nodes get a
            # cap just below r (β <= 89.74°) and the search is repeated: the line then leans away from
            # the parallel in time (usually at the same max |λ|).  Only a line that cannot stay below
            # even that cap is refused.
            hi_k = hi.copy()
            touch = np.zeros(0, dtype=np.int64)
            turn_r = [float(rn[i]) for i, kind in ((0, left_kind), (grid.n - 1, right_kind))
                      if kind == wc.TURN and i0 <= i <= i1]
            for _attempt in range(_TOUCH_ATTEMPTS):
                try:
                    lam_star, tb = wc.minimax_search(grid, lo, hi_k, points, lam0, state=state, i0=i0, i1=i1)
                except ValueError as exc:
                    raise _err(f"minimax winding line: {exc}", "winding.mode", ctx, InfeasibleError) from None
                Cp, lp = wc.tube_path(grid, tb, lam_star)
                # a node held on the upper bound (C = r, β = 90°) inside the pass; nodes next to a turnaround
                # come within 1e-7·r of r by themselves at fine grids (r − C ∝ distance), they are not touches
                touch = np.flatnonzero(Cp[inner] >= hi[inner] * (1.0 - 1e-12)) + inner.start
                if not touch.size:
                    break
                near = np.unique(np.clip(touch[:, None] + np.arange(-2, 3)[None, :], inner.start,
                                         inner.stop - 1))
                cap = rn[near] * (1.0 - _SOFT_CAP)
                # next to a turnaround (C = r_t there) r has grown by less than the soft cap: hold such nodes
                # half-way between r_t and r instead (the geodesic continuation C = r_t stays admitted)
                for r_t in turn_r:
                    gap = rn[near] - r_t
                    cap = np.where(gap > 0.0, np.maximum(cap, r_t + 0.5 * gap), cap)
                hi_k[near] = np.minimum(hi_k[near], cap)
            C[i0 : i1 + 1] = Cp[i0 : i1 + 1]
            lam[i0:i1] = lp[i0:i1]
            if touch.size:
                k = int(touch[0])
                raise _err(
                    f"minimax winding line: the line would have to touch the parallel z = {grid.z[k]:.6g} mm "
                    f"(r = {rn[k]:.6g} mm, winding angle 90°) to stay clear of bridging (6) elsewhere (C >= "
                    f"{float(np.max(lo[i0 : i1 + 1])):.6g} mm needed); no realisable line passes there — move the "
                    "pole condition so the line turns around before it", "winding.pole_c_mm", ctx, InfeasibleError)
            searched.append(lam_star)
            notes.append(f"minimax direct search on z {grid.z[i0]:.6g}..{grid.z[i1]:.6g} mm: max |λ| = "
                         f"{lam_star:.6g} (bisection on the reachable tube)")
        if searched:
            pieces = _pieces_from_steps(grid, lam, max(searched))
    try:
        v, s, _ = wc.twist(grid, C, lam)
    except ValueError as exc:
        raise _err(f"the winding line is not realisable: {exc}", "winding.mode", ctx, InfeasibleError) from None
    bridging = _bridging(grid, C, lam)
    return _finish(grid, C, lam, v, s, mode, pieces, bridging, notes)


def _geodesic_pass(
    mandrel: Any,
    pole_c: list[float | None],
    angles: list[_Cond],
    n_out: int,
    refine: int,
    ctx: dict[str, Any],
    notes: list[str],
    pole_fld: str,
    c_override: float | None,
    unchecked: dict[str, Any] | None = None,
) -> PassLine:
    if c_override is not None:
        C0, z_ref, fld = c_override, (angles[0].z if angles else None), "winding.angles"
    elif angles:
        C0, z_ref, fld = angles[0].C, angles[0].z, angles[0].field
    else:
        given = [c for c in pole_c if c is not None]
        if not given:
            raise _err("a geodesic needs a pole to turn around or a winding angle ([[winding.angles]])",
                       "winding.angles", ctx)
        C0, z_ref, fld = max(given), None, pole_fld
    if z_ref is None:
        zs, rs = mandrel.sample(4000)
        z_ref = float(zs[int(np.argmax(rs))])
    r_ref = float(mandrel.r(np.array([z_ref]))[0])
    if not C0 < r_ref:
        raise _err(f"Clairaut constant C = {C0:.6g} mm is not below the radius {r_ref:.6g} mm anywhere on the line",
                   fld, ctx)
    kinds = []
    zz = []
    for z_end in (mandrel.z_min, mandrel.z_max):
        zt = _crossing(mandrel, C0, z_ref, z_end, from_inside=True)
        if zt is None:
            kinds.append(wc.OPEN)
            zz.append(z_end)
        else:
            kinds.append(wc.TURN)
            zz.append(zt)
    za, zb = zz
    for a in angles[1:]:
        if not za <= a.z <= zb:
            raise _err(f"winding angle required at z = {a.z:g} mm cannot be reached: the geodesic turns around at "
                       f"z = {za:.6g} and {zb:.6g} mm", a.field, ctx)
        if abs(a.C - C0) > 1e-9 * C0:
            raise _err(
                f"winding angle at z = {a.z:g} mm cannot be reached by the geodesic through the first required "
                f"angle (it needs C = {a.C:.6g} mm, the geodesic has C = {C0:.6g} mm); use mode = 'auto'",
                a.field, ctx)
    for i, c in enumerate(pole_c):
        if c is not None and kinds[i] == wc.TURN and abs(c - C0) > 1e-9 * C0:
            notes.append(f"{'left' if i == 0 else 'right'} end: the geodesic turns around at r = {C0:.6g} mm, "
                         f"not at the pole value {c:.6g} mm")
    grid = wc.build_grid(mandrel, za, zb, kinds[0], kinds[1], n_out, refine, [a.z for a in angles])
    C = np.full(grid.n, C0)
    lam = np.zeros(grid.n - 1)
    try:
        v, s, _ = wc.twist(grid, C, lam)
    except ValueError as exc:
        raise _err(f"the geodesic is not realisable: {exc}", fld, ctx, InfeasibleError) from None
    if unchecked is not None:
        unchecked["grid"] = (grid, C, lam)
        bridging: list[tuple[float, float]] = []
    else:
        bridging = _bridging(grid, C, lam)
    pieces = [{"z_from": za, "z_to": zb, "lambda": 0.0}]
    return _finish(grid, C, lam, v, s, "geodesic", pieces, bridging, notes)


BRIDGING_CHECK_POINTS = 25_000
"""Points inside the steps of a pass at which :func:`_bridging` checks (6), at least: 10 per step up to
2 500 steps (the default 2 000 points per pass and its refined grids, up to ~2 400 steps on the shipped
examples: all of them keep 10), fewer per step on a denser pass (at least 3), so that the check of an
8 000-point pass is no coarser in z than the default's and costs about as much (the mandrel's r, r',
r'' at every check point: ~0.5 s a line on the isotensoid vessel at 8 000 points per pass with 10 per
step)."""


def _bridging(grid: wc.PassGrid, C: FloatArray, lam: FloatArray, k: int | None = None) -> list[tuple[float, float]]:
    """Every z range (mm) where the band bridges (constraint (6), the bracket of (3) below 0).

    Checked at the nodes (knots, joints and r'' extrema among them) and at ``k`` points inside every
    step (default: 10, fewer on a pass of more than 2 500 steps, :data:`BRIDGING_CHECK_POINTS`), with C
    between the nodes from the cubic Hermite interpolant of ODE (3) in t.
    """
    if k is None:
        k = max(3, min(10, -(-BRIDGING_CHECK_POINTS // max(grid.n - 1, 1))))
    rn, _, _ = wc.node_geometry(grid)
    F = _bracket(grid, C)
    bad_node = F < -1e-9 * np.maximum(1.0, rn)
    t = grid.t
    h = np.diff(t)
    th = np.arange(1, k + 1) / (k + 1.0)
    tt = t[:-1, None] + h[:, None] * th[None, :]
    z, dzdt, _, _ = wc.t_map(grid.kind, grid.za, grid.L, tt.ravel())
    z = np.clip(z, grid.za, grid.zb)
    r, dr, d2r = wc.eval_on_segments(grid.mandrel, z, np.repeat(grid.seg, k))
    rl, drl, d2l = grid.geo["L"]
    rr, drr, d2rr = grid.geo["R"]
    al, bl = wc.riccati_ab(rl, drl, d2l)
    ar, br = wc.riccati_ab(rr, drr, d2rr)
    cl, cr = C[:-1], C[1:]
    fl = lam * grid.dzdt[:-1] * (al * cl * cl + bl) * h
    fr = lam * grid.dzdt[1:] * (ar * cr * cr + br) * h
    u = th[None, :]
    cs = ((2 * u**3 - 3 * u**2 + 1) * cl[:, None] + (u**3 - 2 * u**2 + u) * fl[:, None]
          + (-2 * u**3 + 3 * u**2) * cr[:, None] + (u**3 - u**2) * fr[:, None]).ravel()
    a, b = wc.riccati_ab(r, dr, d2r)
    with np.errstate(invalid="ignore"):
        bad_in = (a * cs * cs + b) * r * r < -1e-9 * np.maximum(1.0, r)
    n = grid.n
    zz = np.empty(n + (n - 1) * k)
    bad = np.zeros(zz.size, dtype=bool)
    idx = np.arange(n) * (k + 1)
    zz[idx], bad[idx] = grid.z, bad_node
    sub = (idx[:-1, None] + np.arange(1, k + 1)[None, :]).ravel()
    zz[sub], bad[sub] = z, bad_in
    return _ranges(zz, bad)


def _bracket(grid: wc.PassGrid, C: FloatArray) -> FloatArray:
    """The bracket of (3) per node, (aC² + b)·r² (>= 0 means no bridging), min over both sides."""
    out = np.full(grid.n, np.inf)
    for side, sl, cs in (("L", slice(0, -1), C[:-1]), ("R", slice(1, None), C[1:])):
        r, dr, d2r = grid.geo[side]
        a, b = wc.riccati_ab(r, dr, d2r)
        out[sl] = np.minimum(out[sl], (a * cs * cs + b) * r * r)
    return out


def _ranges(z: FloatArray, mask: NDArray[np.bool_]) -> list[tuple[float, float]]:
    if not mask.any():
        return []
    edges = np.flatnonzero(np.diff(np.concatenate([[0], mask.astype(int), [0]])))
    return [(float(z[a]), float(z[b - 1])) for a, b in zip(edges[0::2], edges[1::2])]


def _pieces_from_steps(grid: wc.PassGrid, lam: FloatArray, scale: float) -> list[dict[str, float]]:
    """Runs of (nearly) equal λ per step as pieces {z_from, z_to, lambda}; differences below
    1e-3·``scale`` (single clamped steps at joints) do not start a new piece."""
    tol = 1e-3 * max(scale, 1e-6)
    pieces: list[dict[str, float]] = []
    start = 0
    for k in range(1, len(lam) + 1):
        if k == len(lam) or abs(lam[k] - lam[start]) > tol:
            seg = lam[start:k]
            pieces.append({"z_from": float(grid.z[start]), "z_to": float(grid.z[k]), "lambda": float(np.mean(seg))})
            start = k
    return pieces


def _finish(
    grid: wc.PassGrid,
    C: FloatArray,
    lam: FloatArray,
    v: FloatArray,
    s: FloatArray,
    mode: str,
    pieces: list[dict[str, float]],
    bridging: list[tuple[float, float]],
    notes: list[str],
) -> PassLine:
    rn, drn, _ = wc.node_geometry(grid)
    lam_node = np.append(lam, lam[-1]) if len(lam) else np.zeros(grid.n)
    m = grid.out
    D = np.maximum(rn - C, 0.0)
    beta = np.arctan2(C, np.sqrt(D * (rn + C)))
    if grid.left == wc.TURN:
        beta[0] = 0.5 * math.pi
    if grid.right == wc.TURN:
        beta[-1] = 0.5 * math.pi
    return PassLine(
        z=grid.z[m], r=rn[m], dr=drn[m], C=C[m], lam=lam_node[m], v=v[m], s=s[m], beta=beta[m],
        left=grid.left, right=grid.right, mode=mode, pieces=pieces, bridging=bridging, notes=notes,
        lam_all=lam_node, z_all=grid.z.copy(),
    )


# ------------------------------------------------------------------------------------------------
# Pattern
# ------------------------------------------------------------------------------------------------
@dataclass
class Pattern:
    """Pattern closure: p circuits per layer, Δv = 2π(m + q/p)."""

    p: int
    q: int
    m: int
    lead: str
    total: int
    twist: float
    dwell: tuple[float, float]
    coverage: dict[str, float]
    order: list[int]


def _lead_of(p: int, q: int) -> str:
    if p <= 2:
        return "leading"
    k_plus = pow(q, -1, p)
    return "leading" if k_plus <= p - k_plus else "lagging"


def choose_pattern(
    raw_twist: float, p: int, lead: str, q_user: int | None, ctx: dict[str, Any], allow_below: bool = False
) -> tuple[int, int, float]:
    """(q, m, target twist) closest above ``raw_twist`` (or either side with ``allow_below``)."""
    two_pi = 2.0 * math.pi
    if q_user is not None:
        if p > 1 and (math.gcd(p, q_user) != 1 or q_user % p == 0):
            raise _err(f"pattern_q = {q_user} is not coprime with pattern_p = {p}", "winding.pattern_q", ctx)
        cands = [q_user % p if p > 1 else 0]
    elif p == 1:
        cands = [0]
    else:
        cands = [q for q in range(1, p) if math.gcd(p, q) == 1 and _lead_of(p, q) == lead] or [1]
    best: tuple[float, int, int, float] | None = None
    for q in cands:
        frac = q / p
        m = math.ceil(raw_twist / two_pi - frac - 1e-12)
        opts = [m] + ([m - 1] if allow_below else [])
        for mm in opts:
            target = two_pi * (mm + frac)
            if target <= 0:
                continue
            cost = abs(target - raw_twist)
            if best is None or cost < best[0]:
                best = (cost, q, mm, target)
    assert best is not None
    return best[1], best[2], best[3]


def _coverage(pl: PassLine, b: float, p: int) -> dict[str, float]:
    w = np.sqrt(np.maximum(pl.r**2 - pl.C**2, 0.0))  # r·cos β
    i = int(np.argmax(w))
    band_c = b * pl.r[i] / w[i]  # band width along the parallel, b / cos β
    pitch = 2.0 * math.pi * pl.r[i] / p
    return {
        "fraction": float(band_c / pitch),
        "at_z_mm": float(pl.z[i]),
        "at_r_mm": float(pl.r[i]),
        "beta_deg": float(math.degrees(pl.beta[i])),
        "band_along_parallel_mm": float(band_c),
        "pitch_mm": float(pitch),
        "overlap_mm": float(max(band_c - pitch, 0.0)),
        "gap_mm": float(max(pitch - band_c, 0.0)),
        "circuits_for_full_coverage": int(math.ceil(2.0 * math.pi * w[i] / b - 1e-9)),
    }


# ------------------------------------------------------------------------------------------------
# Main entry
# ------------------------------------------------------------------------------------------------
def winding_line(
    mandrel: Any,
    band_width_mm: float,
    mu: float,
    spec: Any = None,
    state: Any = None,
    *,
    _ctx: dict[str, Any] | None = None,
) -> WindingLine:
    """The winding line of the whole pattern on ``mandrel``.

    Parameters
    ----------
    mandrel:
        :class:`engine.mandrel.Mandrel`.
    band_width_mm:
        Band width b (mm).
    mu:
        Band-on-mandrel friction coefficient μ; points with |λ| > μ are reported in ``slips``.
    spec:
        :class:`engine.job.WindingSpec` (default: all defaults).
    state:
        Progress / cancellation (:mod:`engine.state`).

    Raises
    ------
    InputError
        Bad or contradictory input (names the value, and the job field when called from a job).
    InfeasibleError
        No line meets the conditions (says which and where).
    """
    from engine.job import WindingSpec

    ctx = _ctx or {}
    spec = spec if spec is not None else WindingSpec()
    b = float(band_width_mm)
    mu = float(mu)
    if not (math.isfinite(b) and b > 0):
        raise _err(f"band width must be a positive number of mm, got {band_width_mm!r}", "band.width_mm", ctx)
    if not (math.isfinite(mu) and mu >= 0):
        raise _err(f"friction coefficient μ must be >= 0, got {mu!r}", "band.friction", ctx)
    circ = 2.0 * math.pi * mandrel.r_max
    if b >= circ:
        raise _err(f"band width {b:g} mm is wider than the largest circumference of the mandrel ({circ:.6g} mm)",
                   "band.width_mm", ctx)
    from engine import budget

    budget.check_winding_spec(spec, float(mandrel.r_max), b, ctx=ctx)  # sizes before work
    if state is not None:
        state.progress(0.0, "winding line: Clairaut function")
    pl = solve_pass(mandrel, b, spec, ctx, state)
    check_cancel(state)
    lam_abs = np.abs(pl.lam_all)
    i_max = int(np.argmax(lam_abs))
    max_lam = float(lam_abs[i_max])
    if mu == 0.0 and max_lam > 1e-12:
        raise _err(
            f"friction coefficient μ = 0 but the line needs |λ| up to {max_lam:.4g} (at z = {pl.z_all[i_max]:.6g} mm): "
            "a non-geodesic line cannot be held without friction; set band.friction or use a geodesic",
            "band.friction", ctx)
    slips = _ranges(pl.z_all, lam_abs > mu + 1e-12)
    notes = list(pl.notes)
    if slips:
        notes.append(f"the band slips: |λ| up to {max_lam:.4g} > μ = {mu:g}")
    if pl.bridging:
        notes.append("the band bridges (does not lie on the surface, constraint (6)) in " +
                     ", ".join(f"z {a:.6g}..{c:.6g} mm" for a, c in pl.bridging))
    if state is not None:
        state.progress(0.5, "winding line: pattern")

    # --- pattern -------------------------------------------------------------------------------
    dwell = (math.radians(spec.dwell_deg[0]), math.radians(spec.dwell_deg[1]))
    cov0 = _coverage(pl, b, 1)
    n_min = max(1, cov0["circuits_for_full_coverage"])
    if spec.circuits is not None and spec.pattern_p is not None and spec.circuits % spec.pattern_p:
        raise _err(f"circuits = {spec.circuits} is not a multiple of pattern_p = {spec.pattern_p}",
                   "winding.circuits", ctx)
    p = int(spec.pattern_p or spec.circuits or n_min)
    per_layer = int(spec.circuits or p)
    total = per_layer * int(spec.layers)
    close_by = getattr(spec, "close_by", "dwell")
    raw = 2.0 * pl.v[-1] + dwell[0] + dwell[1]
    if close_by == "angle":
        pl, dwell, q, m, target = _close_by_angle(mandrel, b, spec, ctx, pl, dwell, p, notes)
        places = _turnaround_places(mandrel, pl, b, mu)
    else:
        places = _turnaround_places(mandrel, pl, b, mu)
        q, m, target = choose_pattern(raw, p, spec.lead, spec.pattern_q, ctx)
        extra = target - raw
        stable = (places[0]["stable"], places[1]["stable"])
        share = (0.5, 0.5) if stable[0] == stable[1] else ((1.0, 0.0) if stable[0] else (0.0, 1.0))
        dwell = (dwell[0] + share[0] * extra, dwell[1] + share[1] * extra)
        if extra > 1e-12:
            where = ("half at each end" if share == (0.5, 0.5) else
                     f"all at the {'left' if share[0] else 'right'} end, where a dwell is stable")
            notes.append(f"pattern closed by adding {math.degrees(extra):.4f}° of dwell ({where})")
    turns: list[dict[str, Any]] = []
    for side, (pc, d) in enumerate(zip(places, dwell)):
        name = "left" if side == 0 else "right"
        turns.append({"side": name, "kind": pc["kind"], "z_mm": pc["z_turn"], "r_mm": pc["r_turn"],
                      "dwell_deg": math.degrees(d), "dwell_on": pc["on"] if d > 0 else "none",
                      "dwell_z_mm": pc["z"], "dwell_r_mm": pc["r"], "dwell_lambda": pc["lam"],
                      "stable": bool(pc["stable"] or d <= 0), "how": pc["how"] if d > 0 else pc["how_plain"]})
        if d > 0 and not pc["stable"]:
            slips.append((pc["z"], pc["z"]))
            hint = ("close the pattern by the winding angle (close_by = 'angle') or turn on a polar boss"
                    if pl.mode == "geodesic" else "turn on a polar boss or move the dwell to the other end")
            notes.append(f"{name} turnaround: the dwell of {math.degrees(d):.4g}° lies on the parallel "
                         f"z = {pc['z']:.6g} mm where k_g/k_n = r' = {pc['lam']:.4g}, |λ| > μ = {mu:g}: the band "
                         f"slips there; {hint}")
    slips.sort()
    cov = _coverage(pl, b, p)
    if cov["fraction"] < 1.0 - 1e-9:
        notes.append(f"{p} circuits leave gaps of {cov['gap_mm']:.3g} mm; full coverage needs "
                     f"{cov['circuits_for_full_coverage']}")
    order = [(k * q) % p if p > 1 else 0 for k in range(p)]
    lead = _lead_of(p, q) if p > 1 else "leading"
    if state is not None:
        state.progress(0.7, "winding line: circuits")
    check_cancel(state)
    line = _assemble(pl, dwell, total, target, (places[0], places[1]))
    lam_desc: float | list[dict[str, float]]
    if len({pc["lambda"] for pc in pl.pieces}) == 1:
        lam_desc = float(pl.pieces[0]["lambda"])
    else:
        lam_desc = [{k: float(x) for k, x in pc.items()} for pc in pl.pieces]
    if state is not None:
        state.progress(1.0, "winding line: done")
    return WindingLine(
        **line,
        mode=pl.mode,
        lambda_=lam_desc,
        max_abs_lambda=max_lam,
        z_at_max_lambda=float(pl.z_all[i_max]),
        mu=mu,
        slips=slips,
        bridging=pl.bridging,
        circuits=total,
        pattern_p=p,
        pattern_q=q,
        lead=lead,
        twist_per_circuit_rad=float(target),
        dwell_rad=dwell,
        coverage=cov,
        circuit_order=order,
        z_turn=(float(pl.z[0]), float(pl.z[-1])),
        end_kinds=(pl.left, pl.right),
        band_width_mm=b,
        notes=notes,
        turnarounds=turns,
    )


def _turnaround_places(mandrel: Any, pl: PassLine, b: float, mu: float) -> list[dict[str, Any]]:
    """Where a dwell at each end (left, right) lies and whether it holds without slipping.

    * a tangential turnaround next to a polar opening (the band's edge, b/2 from the turnaround
      parallel, reaches the opening radius): the dwell wraps the polar boss / shaft at the opening
      (a parallel of a cylinder: k_g = 0, stable);
    * any other turnaround: the dwell lies on the turnaround parallel of the mandrel, where
      k_g/k_n = r' (a parallel's geodesic curvature over its normal curvature); it holds only if
      |r'| <= μ, else the band slips there;
    * an open end (pins): the dwell lies on the end parallel, again with λ = r' there.
    """
    out = []
    for side in (0, 1):
        i = 0 if side == 0 else -1
        kind = pl.left if side == 0 else pl.right
        z_t, r_t, dr_t = float(pl.z[i]), float(pl.r[i]), float(pl.dr[i])
        z_end = mandrel.z_min if side == 0 else mandrel.z_max
        r_end = float(mandrel.pole_radii[side])
        base = {"kind": kind, "z_turn": z_t, "r_turn": r_t}
        if (kind == wc.TURN and r_end > 0 and _end_is_dome(mandrel, side)
                and r_t - r_end <= 0.5 * b * (1.0 + 1e-9) + 1e-9):
            out.append({**base, "on": "polar boss", "z": float(z_end), "r": r_end, "dr": 0.0, "lam": 0.0,
                        "stable": True,
                        "how": f"tangential turn on the parallel r = {r_t:.6g} mm; the dwell wraps the polar boss "
                               f"(r = {r_end:.6g} mm at z = {z_end:.6g} mm), where the band's edge rests",
                        "how_plain": f"tangential turn on the parallel r = {r_t:.6g} mm (no dwell)"})
            continue
        stable = abs(dr_t) <= mu + 1e-12
        if kind == wc.TURN:
            how = (f"tangential turn on the parallel r = {r_t:.6g} mm; the dwell lies on that parallel "
                   f"(k_g/k_n = r' = {dr_t:.4g}, {'holds' if stable else 'slips'} with μ = {mu:g})")
            plain = f"tangential turn on the parallel r = {r_t:.6g} mm (no dwell)"
            on = "turnaround parallel"
        else:
            how = (f"the line leaves the open end z = {z_t:.6g} mm; the turn and dwell on the end parallel / pins "
                   f"(k_g/k_n = r' = {dr_t:.4g}, {'holds' if stable else 'slips'} with μ = {mu:g})")
            plain = f"the line leaves the open end z = {z_t:.6g} mm and turns on pins (no dwell)"
            on = "end parallel"
        out.append({**base, "on": on, "z": z_t, "r": r_t, "dr": dr_t, "lam": dr_t, "stable": stable, "how": how,
                    "how_plain": plain})
    return out


def _close_by_angle(
    mandrel: Any, b: float, spec: Any, ctx: dict[str, Any], pl: PassLine, dwell: tuple[float, float], p: int,
    notes: list[str],
) -> tuple[PassLine, tuple[float, float], int, int, float]:
    """Close the pattern by changing the Clairaut constant of a geodesic (the winding angle)."""
    from engine.roots import brentq  # scipy.optimize.brentq bit for bit, without importing scipy.optimize

    if pl.mode != "geodesic":
        raise _err("close_by = 'angle' needs a geodesic line (mode = 'geodesic'); use close_by = 'dwell'",
                   "winding.close_by", ctx)
    raw = 2.0 * pl.v[-1] + dwell[0] + dwell[1]
    q, m, target = choose_pattern(raw, p, spec.lead, spec.pattern_q, ctx, allow_below=True)
    c0 = float(pl.C[len(pl.C) // 2])

    # the root is one of the evaluated constants: its pass is kept, and checked for bridging (6) alone
    passes: dict[float, tuple[PassLine, Any]] = {}

    def f(c: float) -> float:
        raw: dict[str, Any] = {}
        pl_c = solve_pass(mandrel, b, spec, ctx, None, c_override=c, unchecked=raw)
        passes[c] = (pl_c, raw["grid"])
        return 2.0 * pl_c.v[-1] + dwell[0] + dwell[1] - target

    lo_c, hi_c = 0.8 * c0, c0
    r_top = float(np.min(pl.r[1:-1])) if pl.left == wc.OPEN and pl.right == wc.OPEN else float(mandrel.r_max)
    hi_c = min(1.2 * c0, c0 + 0.999 * (r_top - c0))
    try:
        fa, fb = f(lo_c), f(hi_c)
        if fa * fb > 0:
            raise ValueError
        c_new = float(brentq(f, lo_c, hi_c, xtol=1e-13 * c0, rtol=1e-15, fa=fa, fb=fb))  # ends not solved again
    except (ValueError, InputError):
        raise _err(f"the pattern (p = {p}, q = {q}) cannot be closed by a small change of the winding angle; "
                   "use close_by = 'dwell'", "winding.close_by", ctx, InfeasibleError) from None
    if c_new in passes:
        kept, raw_grid = passes[c_new]
        new = replace(kept, bridging=_bridging(*raw_grid))
    else:
        new = solve_pass(mandrel, b, spec, ctx, None, c_override=c_new)
    i = len(new.z) // 2
    notes.append(f"pattern closed by the winding angle: C {c0:.6g} -> {c_new:.6g} mm "
                 f"(β at z = {new.z[i]:.6g} mm: {math.degrees(new.beta[i]):.4f}°)")
    return new, dwell, q, m, target


def _dwell_values(d: float) -> FloatArray:
    if d <= 0.0:
        return np.zeros(0)
    k = max(2, math.ceil(d / math.radians(2.0)))
    return np.linspace(0.0, d, k + 1)[1:]


def _assemble(pl: PassLine, dwell: tuple[float, float], total: int, twist_circ: float,
              places: tuple[dict[str, float], dict[str, float]] | None = None) -> dict[str, Any]:
    """Arrays of all circuits: circuit 0 built from the pass, the others rotated by k·Δv.

    ``places`` says where each dwell lies (left, right): ``z``, ``r``, ``dr`` of its parallel and the
    ``lam`` = k_g/k_n of that parallel (r' on the mandrel's turnaround parallel, 0 on a polar boss);
    default the turnaround parallel.  The last point of each dwell arc is the first point of the
    pass that follows (the return pass, or the next circuit's outgoing pass) and carries that pass's
    labels (β, C, λ, direction, pass) -- with or without a dwell, a pass starts with the line's labels.
    """
    V = float(pl.v[-1])
    S = float(pl.s[-1])
    dl, dr = dwell
    if places is None:
        places = ({"z": float(pl.z[0]), "r": float(pl.r[0]), "dr": float(pl.dr[0]), "lam": float(pl.dr[0])},
                  {"z": float(pl.z[-1]), "r": float(pl.r[-1]), "dr": float(pl.dr[-1]), "lam": float(pl.dr[-1])})
    PL, PR = places
    dR = _dwell_values(dr)
    dL = _dwell_values(dl)
    nR, nL = max(len(dR) - 1, 0), max(len(dL) - 1, 0)  # dwell points proper; the last value starts a pass
    hR, hL = (1 if len(dR) else 0), (1 if len(dL) else 0)
    ret = slice(None, None, -1)
    z_ret = pl.z[ret][1:]
    n_ret = len(z_ret)
    i0 = 0  # pl index of the point that starts the next outgoing pass

    def cat(out_pass: Any, r_dw: Any, r_start: Any, ret_pass: Any, l_dw: Any, l_start: Any, dtype: Any = float
            ) -> NDArray[Any]:
        return np.concatenate([np.asarray(out_pass, dtype=dtype), np.full(nR, r_dw, dtype=dtype),
                               np.full(hR, r_start, dtype=dtype), np.asarray(ret_pass, dtype=dtype),
                               np.full(nL, l_dw, dtype=dtype), np.full(hL, l_start, dtype=dtype)])

    v_ret = V + dr + (V - pl.v[ret][1:])
    s_ret = S + PR["r"] * dr + (S - pl.s[ret][1:])
    S2 = 2.0 * S + PR["r"] * dr
    c0 = {
        "z": cat(pl.z, PR["z"], pl.z[-1], z_ret, PL["z"], pl.z[i0]),
        "r": cat(pl.r, PR["r"], pl.r[-1], pl.r[ret][1:], PL["r"], pl.r[i0]),
        "dr": cat(pl.dr, PR["dr"], pl.dr[-1], pl.dr[ret][1:], PL["dr"], pl.dr[i0]),
        "beta": cat(pl.beta, 0.5 * math.pi, pl.beta[-1], pl.beta[ret][1:], 0.5 * math.pi, pl.beta[i0]),
        "C": cat(pl.C, PR["r"], pl.C[-1], pl.C[ret][1:], PL["r"], pl.C[i0]),
        "lam": cat(pl.lam, PR["lam"], pl.lam[-1], pl.lam[ret][1:], PL["lam"], pl.lam[i0]),
        "direction": cat(np.ones(len(pl.z)), 1, -1, -np.ones(n_ret), -1, 1, dtype=np.int64),
        "pass_id": cat(np.zeros(len(pl.z)), 0, 1, np.ones(n_ret), 1, 2, dtype=np.int64),
        "dwell": cat(np.zeros(len(pl.z)), True, False, np.zeros(n_ret), True, False, dtype=bool),
        "v": np.concatenate([pl.v, V + dR, v_ret, 2.0 * V + dr + dL]),
        "s": np.concatenate([pl.s, S + PR["r"] * dR, s_ret, S2 + PL["r"] * dL]),
    }
    # the closing point: the last one (v = Δv); make it exact
    c0["v"][-1] = 2.0 * V + dr + dl
    m = len(c0["z"]) - 1  # points per circuit without the closing point
    # local frame of circuit 0, then circuit k is circuit 0 turned by k·Δv about the axis
    v0 = c0["v"]
    cv, sv = np.cos(v0), np.sin(v0)
    r0, d0 = c0["r"], c0["dr"]
    g = 1.0 / np.sqrt(1.0 + d0 * d0)
    cb = np.cos(c0["beta"]) * g * c0["direction"]
    sb = np.sin(c0["beta"])
    local = {
        "xyz": (r0 * cv, r0 * sv, c0["z"]),
        "tau": (cb * d0 * cv - sb * sv, cb * d0 * sv + sb * cv, cb),
        "normal": (g * cv, g * sv, -g * d0),
    }
    from engine.periodic import DEFER_MIN_CIRCUITS, CircuitArray

    k = np.arange(total)
    ang = k * twist_circ
    ck, sk = np.cos(ang), np.sin(ang)
    out: dict[str, Any] = {}
    for name in ("z", "r", "dr", "beta", "C", "lam", "direction", "dwell"):
        out[name] = CircuitArray("tile", c0[name], total, m)
    out["v"] = CircuitArray("shift", v0, total, m, twist_circ)
    out["s"] = CircuitArray("shift", c0["s"], total, m, float(c0["s"][-1]))
    out["pass_id"] = CircuitArray("shift", c0["pass_id"], total, m, 2)
    out["circuit"] = CircuitArray("circuit", None, total, m)
    for name, cols in local.items():
        out[name] = CircuitArray("turn", cols, total, m, cos_k=ck, sin_k=sk)
    if total < DEFER_MIN_CIRCUITS:    # small programs: plain arrays (a big one materialises each on first use)
        out = {name: a.materialise() for name, a in out.items()}
    out["points_per_circuit"] = m
    return out


def winding_line_for_job(job: Any, job_path: str | Path | None = None, state: Any = None) -> WindingLine:
    """:func:`winding_line` for a :class:`engine.job.Job`; errors name the job file, line and field."""
    from engine.job import _find_line, build_mandrel

    mandrel = build_mandrel(job, job_path)
    try:
        from engine import budget

        budget.check_winding_spec(job.winding, float(mandrel.r_max), job.band.width_mm, job.band.thickness_mm,
                                  ctx={"file": job_path})
        return winding_line(mandrel, job.band.width_mm, job.band.friction, job.winding, state,
                            _ctx={"file": job_path, "job": True})
    except InputError as exc:
        line = None
        fld = exc.location.field
        if fld and job_path is not None and Path(job_path).is_file():
            loc = tuple(p for p in fld.replace("]", "").replace("[", ".").split(".") if p and not p.isdigit())
            line = _find_line(Path(job_path).read_text(encoding="utf-8", errors="replace"), loc)
        raise type(exc)(exc.message, file=job_path, line=line, field=fld) from None
