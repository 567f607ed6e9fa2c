"""The laminate: a stack of layers wound one after the other on the surface the previous ones built.

A job (schema version 2) holds an ordered list of layers (:mod:`engine.job`): ``hoop``, ``helical``,
``polar`` and ``skip``.  :func:`run_laminate` winds them in order:

1. layer k is wound on the surface ``S_k`` (``S_0`` the bare mandrel): a hoop layer by
   :func:`hoop_line`, a helical or polar layer by :func:`engine.winding.winding_line`; each line then
   runs through the single-line pipeline (payout -> axes -> time law -> blocks,
   :func:`engine.pipeline.run_pipeline`);
2. the layer's thickness t(s) along the meridian of ``S_k`` follows from fibre-count conservation
   (:func:`layer_thickness`, docs/laminate.md), and ``S_{k+1}`` is ``S_k`` offset along its normal by
   t(s), trimmed where the offset folds over at a polar opening (the opening grows) and re-fitted as a C2
   spline (:func:`grow_surface`);
3. the layers' blocks, joined by transition moves inside the machine limits (:func:`transition_blocks`),
   make one NC program with a comment per layer.

Results are cached per layer: a layer whose own definition and every layer before it are unchanged is
taken from the previous result (``previous=``), so an edit of layer k re-runs layers k... only.
"""

from __future__ import annotations

import hashlib
import json
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from engine.errors import InputError
from engine.job import (
    HelicalLayer,
    HoopLayer,
    Job,
    PolarLayer,
    SkipLayer,
    build_mandrel,
    effective_band,
    effective_winding,
    layer_name,
)
from engine.state import State, SubState, check_cancel

FloatArray = NDArray[np.float64]

THICKNESS_GRID = 1201
"""Points of the meridian grid on which each layer's thickness is computed."""
GROWN_POINTS = 401
"""Spline points of a grown surface (spread by arc length)."""
_MAX_END_SLOPE = 5.0
"""A grown surface's ends are cut where |dr/dz| exceeds this (a C2 spline r(z) needs a finite slope)."""


# --------------------------------------------------------------------------------------------------
# Material data
# --------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Material:
    """Fibre and resin data of a band material (resources/materials/fibres.toml)."""

    name: str
    title: str
    fibre_density_g_cm3: float
    resin_density_g_cm3: float
    fibre_volume_fraction: float
    tex_g_km: float
    """Linear density of one tow (g/km)."""
    source: str = ""

    def masses_kg(self, volume_mm3: float) -> tuple[float, float]:
        """(fibre, resin) mass in kg of a wound volume (mm³) at the material's fibre volume fraction."""
        v_cm3 = volume_mm3 * 1e-3
        vf = self.fibre_volume_fraction
        return v_cm3 * vf * self.fibre_density_g_cm3 * 1e-3, v_cm3 * (1.0 - vf) * self.resin_density_g_cm3 * 1e-3

    def masses_from_tows_kg(self, length_mm: float, tows: int) -> tuple[float, float]:
        """(fibre, resin) mass in kg of a band of ``tows`` tows laid over ``length_mm`` (mm): the fibre from
        the tows' linear density (tex, g/km), the resin from the fibre volume fraction."""
        fibre = tows * self.tex_g_km * length_mm * 1e-9  # g/km * km -> g -> kg
        vf = self.fibre_volume_fraction
        resin = fibre / self.fibre_density_g_cm3 * (1.0 - vf) / vf * self.resin_density_g_cm3
        return fibre, resin


MATERIALS_FILE = Path(__file__).resolve().parents[1] / "resources" / "materials" / "fibres.toml"


_MATERIALS: dict[str, tuple[tuple[int, int], dict[str, Material]]] = {}
"""Materials files read in this process, by resolved path, with the file's modification time and size (a
changed file is read again; engine.resources.file_stamp): every layer's figures look their material up (a
copy of the dict is handed out; a Material is frozen)."""


def load_materials(path: str | Path | None = None) -> dict[str, Material]:
    """Every material of the materials file, by name (read again when the file changes)."""
    from engine.resources import file_stamp

    p = Path(path) if path is not None else MATERIALS_FILE
    fs = file_stamp(p)  # None (missing): read_toml says so
    hit = _MATERIALS.get(fs[0]) if fs is not None else None
    if hit is not None and fs is not None and hit[0] == fs[1]:
        return dict(hit[1])
    out = _read_materials(p)
    if fs is not None:
        _MATERIALS[fs[0]] = (fs[1], out)
    return dict(out)


def _read_materials(p: Path) -> dict[str, Material]:
    from engine.resources import read_toml

    data = read_toml(p, "materials file")
    out: dict[str, Material] = {}
    for name, d in data.get("material", {}).items():
        try:
            out[name] = Material(
                name=name, title=str(d.get("title", name)), fibre_density_g_cm3=float(d["fibre_density_g_cm3"]),
                resin_density_g_cm3=float(d["resin_density_g_cm3"]),
                fibre_volume_fraction=float(d["fibre_volume_fraction"]), tex_g_km=float(d["tex_g_km"]),
                source=str(d.get("source", "")))
        except (KeyError, TypeError, ValueError) as exc:
            raise InputError(f"material {name!r}: bad or missing value ({exc})", file=p,
                             field=f"material.{name}") from None
    return out


def find_material(text: str, materials: dict[str, Material] | None = None) -> Material:
    """The material named by a band's ``material`` text: an exact key, else the first key contained in the
    text (``"carbon T700 / epoxy"`` -> ``t700``), else the generic carbon/epoxy entry."""
    mats = materials if materials is not None else load_materials()
    key = text.strip().lower()
    if key in mats:
        return mats[key]
    for name, m in mats.items():
        if name in key.replace(" ", "").replace("-", "") or name in key:
            return m
    if "glass" in key:
        return mats.get("e-glass", next(iter(mats.values())))
    return mats.get("carbon", next(iter(mats.values())))


# --------------------------------------------------------------------------------------------------
# Hoop line
# --------------------------------------------------------------------------------------------------
def hoop_range(mandrel: Any, layer: HoopLayer, band_width: float, index: int, bare: Any = None
               ) -> tuple[float, float]:
    """The z range (mm) a hoop layer covers: its own, else the cylindrical part of the bare mandrel ``bare``
    (the cylinder keeps its z range as the laminate grows), else of ``mandrel``."""
    from engine.mandrel import cylinder_range

    fld = f"layer.{index + 1}.z_range_mm"
    if layer.z_range_mm is None:
        z0, z1 = cylinder_range(bare if bare is not None else mandrel)
        z0, z1 = max(z0, mandrel.z_min), min(z1, mandrel.z_max)
    else:
        z0, z1 = (float(x) for x in layer.z_range_mm)
        tol = 1e-9 * max(1.0, abs(mandrel.z_max))
        if not (mandrel.z_min - tol <= z0 < z1 <= mandrel.z_max + tol):
            raise InputError(
                f"layer {index + 1} (hoop): z range {z0:g}..{z1:g} mm is outside the surface it is wound on "
                f"(z {mandrel.z_min:.6g}..{mandrel.z_max:.6g} mm)", field=fld)
    if z1 - z0 < band_width:
        raise InputError(f"layer {index + 1} (hoop): z range {z0:g}..{z1:g} mm is narrower than the band "
                         f"({band_width:g} mm)", field=fld)
    return z0, z1


def hoop_line(mandrel: Any, band_width: float, mu: float, layer: HoopLayer, index: int = 0, bare: Any = None
              ) -> Any:
    """A hoop layer as a :class:`engine.winding.WindingLine` (one "circuit" holding every pass).

    The band centre runs from ``z0 + b/2`` to ``z1 − b/2`` (band edges on the range ends) on a helix of
    pitch ``p = b·(1 − overlap)`` per mandrel turn; passes alternate direction (a terminal layer has
    one pass).  On a surface that is not a cylinder the near-parallel line needs λ = k_g/k_n ≈ r'·sin²β
    (a parallel of slope r'), reported as slip where it exceeds μ.
    """
    from engine.winding import WindingLine

    b = float(band_width)
    z0, z1 = hoop_range(mandrel, layer, b, index, bare)
    pitch = b * (1.0 - layer.overlap)
    za, zb = z0 + 0.5 * b, z1 - 0.5 * b
    turns = max((zb - za) / pitch, 1e-9)
    passes = 1 if layer.terminal else layer.passes
    n_pass = max(2, int(math.ceil(turns * layer.points_per_turn)) + 1)
    u = np.linspace(0.0, 1.0, n_pass)
    zs, vs, dirs, pids = [], [], [], []
    for k in range(passes):
        fwd = k % 2 == 0
        z = za + (zb - za) * (u if fwd else 1.0 - u)
        v = 2.0 * math.pi * turns * (k + u)
        sl = slice(0 if k == 0 else 1, None)  # the passes share their turning point
        zs.append(z[sl])
        vs.append(v[sl])
        dirs.append(np.full(z[sl].size, 1 if fwd else -1, dtype=np.int64))
        pids.append(np.full(z[sl].size, k, dtype=np.int64))
    z = np.concatenate(zs)
    v = np.concatenate(vs)
    direction = np.concatenate(dirs)
    pass_id = np.concatenate(pids)
    r, dr, _ = mandrel.evaluate(z)
    g = 1.0 / np.sqrt(1.0 + dr * dr)
    # tangent: d/dv of (r cos v, r sin v, z) with dz/dv = ±p/2π
    dzdv = direction * pitch / (2.0 * math.pi)
    t_vec = np.stack([dr * dzdv * np.cos(v) - r * np.sin(v), dr * dzdv * np.sin(v) + r * np.cos(v),
                      dzdv * np.ones_like(v)], axis=1)
    ds = np.linalg.norm(t_vec, axis=1)
    tau = t_vec / ds[:, None]
    beta = np.arctan2(r, np.abs(dzdv) / g)  # tan β = r dv / dm, dm = dz·sqrt(1 + r'²)
    dv = np.diff(v)
    s = np.concatenate([[0.0], np.cumsum(0.5 * (ds[1:] + ds[:-1]) * dv)])
    xyz = np.stack([r * np.cos(v), r * np.sin(v), z], axis=1)
    normal = np.stack([g * np.cos(v), g * np.sin(v), -g * dr], axis=1)
    lam = dr * np.sin(beta) ** 2 * direction  # geodesic curvature of a near-parallel over its normal one
    lam_abs = np.abs(lam)
    slips: list[tuple[float, float]] = []
    if (lam_abs > mu + 1e-12).any():
        zz = z[lam_abs > mu + 1e-12]
        slips = [(float(zz.min()), float(zz.max()))]
    i_max = int(np.argmax(lam_abs))
    n = z.size
    notes = [f"hoop: {passes} pass(es) over z {z0:.6g}..{z1:.6g} mm, pitch {pitch:.6g} mm per turn, "
             f"{turns:.4g} turns per pass"]
    return WindingLine(
        z=z, r=r, dr=dr, v=v, beta=beta, direction=direction, C=r * np.sin(beta), lam=lam, s=s, xyz=xyz,
        tau=tau, normal=normal, circuit=np.zeros(n, dtype=np.int64), pass_id=pass_id,
        dwell=np.zeros(n, dtype=bool), mode="hoop", lambda_=float(lam[i_max]), max_abs_lambda=float(lam_abs[i_max]),
        z_at_max_lambda=float(z[i_max]), mu=float(mu), slips=slips, bridging=[], circuits=1, pattern_p=1,
        pattern_q=0, lead="leading", twist_per_circuit_rad=float(v[-1]), dwell_rad=(0.0, 0.0),
        coverage={"fraction": 1.0 / (1.0 - layer.overlap), "pitch_mm": pitch, "band_along_parallel_mm": b,
                  "overlap_mm": b - pitch, "gap_mm": 0.0, "at_z_mm": 0.5 * (z0 + z1),
                  "at_r_mm": float(mandrel.r(0.5 * (z0 + z1))), "beta_deg": float(math.degrees(beta[n // 2])),
                  "circuits_for_full_coverage": 1},
        circuit_order=[0], z_turn=(z0, z1), end_kinds=("hoop", "hoop"), points_per_circuit=n - 1,
        band_width_mm=b, notes=notes)


# --------------------------------------------------------------------------------------------------
# Thickness and growth
# --------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Thickness:
    """A layer's thickness along the meridian of the surface it was wound on.

    Arrays on the meridian grid (length M): ``m`` arc length (mm), ``z``, ``r`` of the surface (mm),
    ``nz``, ``nr`` its outward unit normal, ``t`` thickness (mm, along the normal), ``z_out``, ``r_out``
    the outer boundary (surface + t·n, mm).  ``volume_mm3`` is the volume between the two boundaries.
    """

    m: FloatArray
    z: FloatArray
    r: FloatArray
    nz: FloatArray
    nr: FloatArray
    t: FloatArray
    z_out: FloatArray
    r_out: FloatArray
    volume_mm3: float

    def at(self, z: ArrayLikeF) -> FloatArray:
        """Thickness (mm) at axial positions ``z`` (mm) of the wound surface."""
        return np.interp(np.asarray(z, dtype=float), self.z, self.t)


ArrayLikeF = Any


def meridian_grid(mandrel: Any, n: int = THICKNESS_GRID) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """(m, z, r, dr): ``n`` points equally spaced in meridian arc length m (mm) over the winding zone."""
    zf = np.linspace(mandrel.z_min, mandrel.z_max, 8 * n)
    rf, drf, _ = mandrel.evaluate(zf)
    dm = np.hypot(np.diff(zf), np.diff(rf))
    mf = np.concatenate([[0.0], np.cumsum(dm)])
    m = np.linspace(0.0, mf[-1], n)
    z = np.interp(m, mf, zf)
    r, dr, _ = mandrel.evaluate(z)
    return m, z, r, dr


def ring_volume(z_in: FloatArray, r_in: FloatArray, z_out: FloatArray, r_out: FloatArray) -> float:
    """Volume (mm³) of the solid of revolution of the region between two meridian polylines of equal length
    (outer point i is inner point i moved along the normal)."""
    # one quadrilateral per grid step (inner i, i+1, outer i+1, i), each by Pappus, ∬ r dA exact for a
    # polygon: a fold of the outer boundary near a polar opening cannot cancel area as one big polygon would
    zq = np.stack([z_in[:-1], z_in[1:], z_out[1:], z_out[:-1]], axis=1)
    rq = np.stack([r_in[:-1], r_in[1:], r_out[1:], r_out[:-1]], axis=1)
    z2, r2 = np.roll(zq, -1, axis=1), np.roll(rq, -1, axis=1)
    moment = np.sum((zq * r2 - z2 * rq) * (rq + r2), axis=1) / 6.0
    return float(2.0 * math.pi * np.abs(moment).sum())


def _smooth(m: FloatArray, y: FloatArray, width: float) -> FloatArray:
    """Moving average of y over ``width`` (mm of arc length) on the uniform grid ``m``, mirrored at the ends:
    what would spill over an end is folded back, so ∫ y dm is kept exactly and a plateau keeps its value."""
    h = float(m[1] - m[0])
    k = int(round(width / h))
    if k < 2 or k >= y.size:
        return y
    k += 1 - k % 2
    half = k // 2
    padded = np.pad(y, half, mode="symmetric")
    c = np.concatenate([[0.0], np.cumsum(padded)])
    return (c[k:] - c[:-k]) / k


def dwell_length(line: Any, side: int) -> float:
    """Laid length (mm) of the dwell arcs at the left (0) or right (1) end of ``line`` over all circuits."""
    zt = line.z_turn[side]
    tol = 1e-6 * max(1.0, abs(zt))
    if _kept_as_rule(line):  # a big program: piece by piece, the same numbers summed in the same order
        from engine.periodic import field_rows, field_take, row_chunks, tile_base

        n, m = line.n_points, int(line.points_per_circuit)
        dw0, z0 = tile_base(line, "dwell"), tile_base(line, "z")
        if dw0 is not None and z0 is not None and dw0.shape[0] == z0.shape[0] == m + 1:
            # every circuit's dwell rows are circuit 0's: the steps ending on them, circuit after circuit
            j = np.flatnonzero(dw0 & (np.abs(z0 - zt) <= tol))
            body = j[j < m]
            ends = (np.arange(line.circuits, dtype=np.int64)[:, None] * m + body[None, :]).ravel()
            if j.size and j[-1] == m:
                ends = np.append(ends, n - 1)
            ends = ends[ends >= 1]
            if not ends.size:
                return 0.0
            ds = field_take(line, "s", ends) - field_take(line, "s", ends - 1)
            return float(ds.sum())
        parts = []
        for a, b in row_chunks(line.n_points):
            ds = np.diff(field_rows(line, "s", a, b))
            at = np.abs(field_rows(line, "z", a, b)[1:] - zt) <= tol
            parts.append(ds[field_rows(line, "dwell", a, b)[1:] & at])
        return float(np.concatenate(parts).sum())
    if not line.dwell.any():
        return 0.0
    ds = np.diff(line.s)
    on = line.dwell[1:]
    at = np.abs(line.z[1:] - zt) <= tol
    return float(ds[on & at].sum())


def _kept_as_rule(line: Any) -> bool:
    """True for a line whose per-point arrays are kept as circuit 0 + rule (a program of at least
    :data:`engine.periodic.DEFER_MIN_CIRCUITS` circuits): read it piece by piece, do not materialise it."""
    from engine.periodic import CircuitArray

    return hasattr(line, "n_points") and any(isinstance(v, CircuitArray) for v in vars(line).values())


def _pass_fields(line: Any, pass_no: int, names: tuple[str, ...]) -> tuple[Any, ...]:
    """``pass_id`` and the fields ``names`` of ``line``, only circuit 0's rows (and the closing one) when
    every point of pass ``pass_no`` lies there (a line kept as circuit 0 + rule, passes numbered on
    circuit by circuit), else the whole arrays.  Selecting pass ``pass_no`` gives the same points either way."""
    from engine.periodic import deferred, field_rows

    d = deferred(line, "pass_id")
    if d is not None and d.kind == "shift" and d.patch_rows is None and float(d.step) > 0 and \
            pass_no < int(np.min(d.base)) + float(d.step):  # circuit k >= 1 holds passes >= min + k·step
        m = int(d.m)
        return tuple(field_rows(line, f, 0, m + 1) for f in ("pass_id", *names))
    return tuple(getattr(line, f) for f in ("pass_id", *names))


def off_part_length(line: Any) -> float:
    """Length (mm) of the line laid off the part: dwell arcs at open ends (turns on pins)."""
    return sum(dwell_length(line, side) for side in (0, 1) if line.end_kinds[side] == "open")


def layer_thickness(surface: Any, line: Any, band_width: float, band_thickness: float, kind: str,
                    n: int = THICKNESS_GRID) -> Thickness:
    """Thickness a layer leaves on ``surface`` (mm), from fibre-count conservation.

    Through a parallel of radius r the band crosses ``N`` times (2 per circuit for a helical line, once
    per turn and pass for a hoop); a band of width b and thickness t_b crossing at angle β to the meridian
    lays ``b·t_b / cos β`` of volume per unit meridian length.  Away from the turnaround this is
    ``t(r) = N·b·t_b / (2π r cos β)`` (thin shell).  Two refinements:

    * *band-width averaging at the turnaround*: the band's fibres have Clairaut constants spread over
      ``C ± κ b/2``, κ = |dr/dm| at the turnaround parallel (each fibre turns on its own parallel), and
      ``b / cos β`` is replaced by its average over them,
      ``r·[asin(min(1, C_hi/r)) − asin(min(1, C_lo/r))] / κ`` — finite everywhere, zero below C_lo;
    * *mid-thickness radius*: the fibre count holds on the parallel at the layer's mid-thickness, so the
      annulus area solves ``2π t (r + t n_r/2) = A (1 + t sin²β/(2r))`` (A the volume per unit meridian
      length on the surface); then the volume between the surfaces equals the volume laid, and a hoop pass
      is exactly one band thickness / (1 − overlap).

    The field is finally averaged over one band width along the meridian (the band smears any step).
    """
    m, z, r, dr = meridian_grid(surface, n)
    g = 1.0 / np.sqrt(1.0 + dr * dr)
    nz, nr = -dr * g, g
    b, tb = float(band_width), float(band_thickness)
    A = np.zeros_like(z)
    sin2b = np.ones_like(z)
    if kind == "hoop":
        # one crossing per turn of every pass: per unit z, turns / pitch; meridian length dm = dz / g
        # covered multiplicity: w/p inside, ramping over one band width at each end (the helix's first and
        # last turn leave a triangle of half a turn uncovered): cover = clip(min(z - z0, z1 - z, b), 0) / p
        z0, z1 = line.z_turn
        pitch = float(line.coverage["pitch_mm"])
        passes = int(line.pass_id.max()) + 1
        cover = np.clip(np.minimum(np.minimum(z - z0, z1 - z), b), 0.0, None) / pitch
        A = passes * 2.0 * math.pi * r * tb * cover * g
    else:
        # centre line's Clairaut function C(z) on its outgoing pass (circuit 0, pass 0, no dwell)
        pid, dw, zl, Cl = _pass_fields(line, 0, ("dwell", "z", "C"))
        sel = (pid == 0) & ~dw
        zc, Cc = zl[sel], Cl[sel]
        order = np.argsort(zc)
        zc, Cc = zc[order], Cc[order]
        # fibres of the band with C below the centre's turn beyond the centre's turning parallel (toward the
        # pole), so a turning end does not limit the wound zone: r > C_lo does
        wound = np.ones_like(z, dtype=bool)
        if line.end_kinds[0] == "open":
            wound &= z >= zc[0] - 1e-9
        if line.end_kinds[1] == "open":
            wound &= z <= zc[-1] + 1e-9
        C = np.interp(z, zc, Cc)
        N = 2.0 * line.circuits
        # κ at each turnaround (|dr/dm| where the line turns), else 0 (the line leaves the surface there)
        kap = np.zeros_like(z)
        zmid = 0.5 * (zc[0] + zc[-1])
        for side, zt in ((0, zc[0]), (1, zc[-1])):
            kind_end = line.end_kinds[side]
            k = 0.0
            if kind_end not in ("open", "pins", "free") and "pin" not in kind_end:
                _, d1, _ = surface.evaluate(np.array([zt]))
                k = float(min(1.0, abs(d1[0]) / math.sqrt(1.0 + d1[0] ** 2)))
            kap[(z < zmid) if side == 0 else (z >= zmid)] = k
        half = 0.5 * kap * b
        c_lo, c_hi = C - half, C + half
        with np.errstate(divide="ignore", invalid="ignore"):
            narrow = half < 1e-9 * np.maximum(r, 1.0)
            avg_inv_cos = np.where(
                narrow,
                r / np.sqrt(np.maximum(r * r - C * C, 1e-300)),
                r * (np.arcsin(np.clip(c_hi / r, -1, 1)) - np.arcsin(np.clip(c_lo / r, -1, 1)))
                / np.maximum(2.0 * half, 1e-300),
            )
        reach = r > c_lo + 1e-12
        avg_inv_cos = np.where(reach & wound & np.isfinite(avg_inv_cos), avg_inv_cos, 0.0)
        A = N * b * tb * avg_inv_cos
        # dwell arcs laid on the surface at a turnaround (not on pins beyond an open end): a ring of the
        # dwell length × t_b spread over one band width of meridian around the turn parallel
        for side, zt in ((0, zc[0]), (1, zc[-1])):
            if line.end_kinds[side] == "open":
                continue
            L_d = dwell_length(line, side)
            if L_d > 0:
                i = int(np.argmin(np.abs(z - zt)))
                win = np.abs(m - m[i]) <= 0.5 * b
                A[win] += L_d * b * tb / max(float(np.ptp(m[win])) if win.sum() > 1 else b, 1e-9)
        sin2b = np.clip((C / np.maximum(r, 1e-300)) ** 2, 0.0, 1.0)
    # mid-thickness annulus: π n_r t² + (2π r − A sin²β/(2r)) t − A = 0, the positive root
    a2 = math.pi * nr
    a1 = 2.0 * math.pi * r - A * sin2b / (2.0 * np.maximum(r, 1e-300))
    with np.errstate(invalid="ignore"):
        disc = np.maximum(a1 * a1 + 4.0 * a2 * A, 0.0)
        t = np.where(A > 0, 2.0 * A / (a1 + np.sqrt(disc)), 0.0)
    # meridional curvature κ_m: the shell element between the offsets is 2π ∫0^t (r + h n_r)(1 + h κ_m) dh;
    # a few Newton steps on  2π [r t + t²/2 (n_r + r κ_m) + t³/3 n_r κ_m] = A (1 + t sin²β/(2r))
    _, _, d2 = surface.evaluate(z)
    km = -d2 * g**3
    for _ in range(4):
        f = 2.0 * math.pi * (r * t + 0.5 * t * t * (nr + r * km) + t**3 / 3.0 * nr * km) \
            - A * (1.0 + t * sin2b / (2.0 * np.maximum(r, 1e-300)))
        df = 2.0 * math.pi * (r + t * (nr + r * km) + t * t * nr * km) - A * sin2b / (2.0 * np.maximum(r, 1e-300))
        t = np.where(A > 0, np.maximum(t - f / np.where(np.abs(df) > 1e-300, df, 1e-300), 0.0), 0.0)
    # the band smears any step over its width; a hoop layer's ends are tapered over three band widths
    # (staggered turnarounds), so the next layers do not have to follow a sharp step
    t = _smooth(m, t, 3.0 * b if kind == "hoop" else b)
    z_out = z + t * nz
    r_out = r + t * nr
    vol = ring_volume(z, r, z_out, r_out)
    return Thickness(m=m, z=z, r=r, nz=nz, nr=nr, t=t, z_out=z_out, r_out=r_out, volume_mm3=vol)


def grow_surface(surface: Any, th: Thickness, name: str = "grown", n: int = GROWN_POINTS) -> Any:
    """The surface after a layer: the outer boundary, made a graph r(z) again and re-fitted as a C2 spline.

    Where a thick turnaround band folds the offset back in z near a polar opening (the laminate's edge
    faces the opening), the boundary is cut at its axial crest: the polar opening grows to the crest's
    radius.  Points steeper than |dr/dz| = _MAX_END_SLOPE at the ends are dropped (a C2 spline needs a finite slope).
    """
    from engine.mandrel import CONCAVE_GAP_TOL_MM, Mandrel

    if float(th.t.max()) <= 0.0:
        return surface
    z, r = th.z_out.copy(), th.r_out.copy()
    n0 = z.size
    half = n0 // 2
    built = th.t > 1e-9 * max(1.0, float(th.t.max()))
    # an end with no build-up keeps its shape (no crest cut, no slope trim)
    k_end = max(2, int(round(0.02 * n0)))
    left_built, right_built = bool(built[:k_end].any()), bool(built[-k_end:].any())
    # axial crests at the ends (fold-over at an opening): keep the part between them
    lo = int(np.argmin(z[:half])) if left_built else 0
    hi = half + int(np.argmax(z[half:])) if right_built else n0 - 1
    z, r = z[lo:hi + 1], r[lo:hi + 1]
    # strictly increasing z (drop folded points inside, if any)
    keep = np.concatenate([[True], np.diff(np.maximum.accumulate(z)) > 1e-9])
    keep &= z >= np.maximum.accumulate(z)
    z, r = z[keep], r[keep]
    # finite end slopes
    slope = np.abs(np.diff(r) / np.maximum(np.diff(z), 1e-300))
    a, bidx = 0, z.size - 1
    while left_built and a < bidx - 8 and slope[a] > _MAX_END_SLOPE:
        a += 1
    while right_built and bidx > a + 8 and slope[bidx - 1] > _MAX_END_SLOPE:
        bidx -= 1
    z, r = z[a:bidx + 1], r[a:bidx + 1]
    # spline points spread by arc length
    dm = np.hypot(np.diff(z), np.diff(r))
    mm = np.concatenate([[0.0], np.cumsum(dm)])
    pick = np.unique(np.searchsorted(mm, np.linspace(0.0, mm[-1], n)).clip(0, z.size - 1))
    zs, rs = z[pick], np.maximum(r[pick], 0.0)
    grown = Mandrel.from_points(zs, rs, name=name, source="grown")
    # concave zones shallower than the thickest build-up step are bridged by design (resin-filled):
    # a line on the grown surface keeps the mode the bare mandrel asks for
    prev = surface.meta.get("concave_tol_mm", CONCAVE_GAP_TOL_MM) if isinstance(surface.meta, dict) else \
        CONCAVE_GAP_TOL_MM
    tol = max(float(prev), float(th.t.max()))
    # the shafts, the chuck and the tailstock stay where the bare mandrel put them (the laminate grows over
    # its ends): every grown surface carries the bare mandrel's support frame (machine_setup.support_obstacles)
    frame = surface.meta.get("support_frame") if isinstance(surface.meta, dict) else None
    if frame is None:
        from engine.machine_setup import default_shaft_radius

        frame = (float(surface.z_min), float(surface.z_max), float(default_shaft_radius(surface)))
    return replace(grown, meta={**grown.meta, "concave_tol_mm": tol, "support_frame": tuple(frame)})


# --------------------------------------------------------------------------------------------------
# Transitions
# --------------------------------------------------------------------------------------------------
def trapezoid_move(machine: Any, q0: FloatArray, q1: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Blocks of a straight axis-space move from rest at ``q0`` to rest at ``q1`` (controller units).

    The move follows a trapezoidal (or triangular) speed profile in the path parameter whose peak speed
    and acceleration keep every axis's ``max_speed`` and ``max_accel``; blocks last at most
    ``min(max_jump / max_accel)`` so the speed step between neighbouring blocks stays within every
    ``max_jump`` and the first and last block (from and to rest) run below half a ``max_jump``.
    Returns (q (n+1, n_axes), time (n,)).
    """
    q0 = np.asarray(q0, dtype=float)
    q1 = np.asarray(q1, dtype=float)
    D = np.abs(q1 - q0)
    if not (D > 1e-12).any():
        return np.stack([q0, q1]), np.array([machine.min_block_time])
    V = machine.limits("max_speed")
    A = machine.limits("max_accel")
    J = machine.limits("max_jump")
    mv = D > 1e-12
    vmax = float(np.min(V[mv] / D[mv]))  # path speed (1/s)
    amax = float(np.min(A[mv] / D[mv]))
    # trapezoid in s ∈ [0, 1]
    t_acc = vmax / amax
    if amax * t_acc * t_acc >= 1.0:  # triangular
        t_acc = math.sqrt(1.0 / amax)
        vmax = amax * t_acc
        t_flat = 0.0
    else:
        t_flat = (1.0 - amax * t_acc * t_acc) / vmax
    T = 2.0 * t_acc + t_flat
    dt_max = 0.9 * float(np.min(np.where(mv, J / np.maximum(A, 1e-300), np.inf)))
    dt_max = max(min(dt_max, 0.05), 2.0 * machine.min_block_time)
    nb = max(2, int(math.ceil(T / dt_max)))
    tk = np.linspace(0.0, T, nb + 1)

    def s_of(t: FloatArray) -> FloatArray:
        out = np.empty_like(t)
        a = t <= t_acc
        out[a] = 0.5 * amax * t[a] ** 2
        c = (t > t_acc) & (t <= t_acc + t_flat)
        out[c] = 0.5 * amax * t_acc**2 + vmax * (t[c] - t_acc)
        d = t > t_acc + t_flat
        td = T - t[d]
        out[d] = 1.0 - 0.5 * amax * td**2
        return out

    s = np.clip(s_of(tk), 0.0, 1.0)
    s[-1] = 1.0
    q = q0[None, :] + s[:, None] * (q1 - q0)[None, :]
    return q, np.diff(tk)


def transition_blocks(machine: Any, q_end: FloatArray, q_start: FloatArray, clearance_mm: float,
                      lead_in: FloatArray | None = None) -> tuple[FloatArray, FloatArray]:
    """The move between two layers: retract the cross axis (eye away from the mandrel) by the clearance,
    move the carriage and the mandrel to the next layer's start, and feed the cross axis in again.

    ``q_start`` is the next layer's first position; the mandrel axis of the next layer is shifted before
    this call so that no mandrel turn back is needed (:func:`run_laminate`).  ``lead_in``: a position the
    carriage passes through just before the start (the layer's lead-in).  Returns (q, time) with the first
    row ``q_end`` and the last row ``q_start``; every piece starts and ends at rest.
    """
    ci = machine.axis_index("cross")
    pts = [np.asarray(q_end, dtype=float)]
    if ci is not None:
        ax = machine.axes[ci]
        up = max(q_end[ci], q_start[ci]) + abs(ax.scale) * clearance_mm
        up = min(up, ax.max)
        a = pts[-1].copy()
        a[ci] = up
        pts.append(a)
        b = np.asarray(q_start if lead_in is None else lead_in, dtype=float).copy()
        b[ci] = up
        pts.append(b)
    if lead_in is not None:
        pts.append(np.asarray(lead_in, dtype=float))
    pts.append(np.asarray(q_start, dtype=float))
    qs, ts = [pts[0][None, :]], []
    for p0, p1 in zip(pts[:-1], pts[1:]):
        if np.allclose(p0, p1, atol=1e-12, rtol=0):
            continue
        q, t = trapezoid_move(machine, p0, p1)
        qs.append(q[1:])
        ts.append(t)
    if not ts:
        return np.stack([pts[0], pts[-1]]), np.array([machine.min_block_time])
    return np.concatenate(qs), np.concatenate(ts)


# --------------------------------------------------------------------------------------------------
# Results
# --------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class LayerResult:
    """One wound layer: the surface it was wound on, its single-line pipeline result, its thickness, the
    surface it leaves, and its production figures (``figures``)."""

    index: int
    name: str
    kind: str
    key: str
    surface: Any
    grown: Any
    result: Any = None
    """:class:`engine.pipeline.PipelineResult` of the layer (None for a skip layer)."""
    thickness: Thickness | None = None
    figures: dict[str, Any] = field(default_factory=dict)
    mandrel_shift: float = 0.0
    """Added to the layer's mandrel axis (controller units) so it continues from the previous layer."""
    block0: int = 0
    """Index of the layer's first block in the joined program."""
    t0: float = 0.0
    """Program time (s) at which the layer starts."""


@dataclass(frozen=True)
class LaminateResult:
    """The whole stack: one :class:`LayerResult` per enabled layer, the joined program and its report."""

    job: Job
    job_path: str | None
    mandrel: Any
    layers: tuple[LayerResult, ...]
    machine: Any = None
    blocks: Any = None
    nc_text: str | None = None
    post_name: str | None = None
    extension: str = ".nc"
    transitions: tuple[tuple[int, int, float], ...] = ()
    """(first block, block count, time s) of each transition move in :attr:`blocks`."""
    transition_fibre_over_mm: tuple[float, ...] = ()
    """Per transition: how deep the straight line from the last laid point to the eye passes inside the
    laminate (mm; 0: the fibre stays free) - there the fibre is drawn over the surface
    (:func:`transition_clearance`)."""
    sections: tuple[tuple[int, str], ...] = ()
    stage_times: dict[str, float] = field(default_factory=dict)
    reused: tuple[int, ...] = ()

    @property
    def final_surface(self) -> Any:
        return self.layers[-1].grown if self.layers else self.mandrel

    def layer(self, index: int) -> LayerResult:
        """The result of job layer ``index`` (0-based)."""
        for lr in self.layers:
            if lr.index == index:
                return lr
        raise KeyError(index)

    @property
    def volume_laid_mm3(self) -> float:
        return float(sum(lr.figures.get("volume_laid_mm3", 0.0) for lr in self.layers))

    @property
    def volume_between_surfaces_mm3(self) -> float:
        return float(sum(lr.thickness.volume_mm3 for lr in self.layers if lr.thickness is not None))

    placement: Any = None
    """The one mandrel placement shared by every layer (:class:`engine.machine_setup.Placement`)."""
    program_problems: tuple[str, ...] = ()
    """Limits the joined program breaks beyond the layers' own checks (positions after the common placement)."""

    @property
    def violations(self) -> list[Any]:
        out: list[Any] = []
        for lr in self.layers:
            if lr.result is not None:
                out += list(lr.result.violations)
        return out

    def violation_groups(self) -> list[Any]:
        """Every layer's violations grouped (kind, axis, worst, count), located by NC line and time in the joined
        program, circuit and layer."""
        from engine.machine_setup import Locator, group_violations, nc_move_lines

        out: list[Any] = []
        lines: np.ndarray | None = None
        for lr in self.layers:
            if lr.result is None or not lr.result.violations:
                continue
            if lines is None:
                lines = nc_move_lines(self.nc_text) if self.nc_text else np.zeros(0, dtype=np.int64)
            loc = Locator(lr.result, layer=lr.index + 1)
            if self.nc_text is not None and loc.block_start is not None:
                nb = int(lr.result.blocks.n)
                loc.lines = lines[lr.block0: lr.block0 + nb + 1]
                loc.block_start = loc.block_start + lr.t0
            out += group_violations(list(lr.result.violations), loc)
        return out

    def warnings(self) -> list[str]:
        out: list[str] = []
        groups = {id(g): g for g in self.violation_groups()}
        grouped_msgs = {g.message for g in groups.values()}
        for lr in self.layers:
            if lr.result is not None:
                own = {g.message for g in lr.result.violation_groups()} if lr.result.violations else set()
                ws = [w for w in lr.result.warnings() if w not in own]
                if lr.kind == "hoop":  # a hoop layer is no repeated circuit: its ends need not meet
                    ws = [w for w in ws if "not cyclic" not in w]
                out += [f"layer {lr.index + 1} ({lr.name}): {w}" for w in ws]
        out += sorted(grouped_msgs) + list(self.program_problems)
        return out

    def layup(self) -> dict[str, Any]:
        """The layup table (``winder layup --json``): per-layer figures, totals and the volume check."""
        rows = [dict(lr.figures) for lr in self.layers]
        keys = ("time_s", "fibre_length_m", "fibre_mass_kg", "resin_mass_kg", "volume_laid_mm3")
        total: dict[str, Any] = {k: float(sum(r.get(k, 0.0) for r in rows)) for k in keys}
        total["transition_time_s"] = float(sum(t for *_, t in self.transitions))
        total["program_time_s"] = total["time_s"] + total["transition_time_s"]
        total["thickness_cyl_mm"] = float(sum(r.get("thickness_cyl_mm", 0.0) for r in rows))
        fs = self.final_surface
        total["thickness_max_mm"] = float(_total_thickness(self).max()) if self.layers else 0.0
        total["layers"] = len(rows)
        total["final_pole_radii_mm"] = list(fs.pole_radii)
        for r in rows:
            r.pop("volume_laid_mm3", None)
        return {
            "job": self.job.name,
            "layers": rows,
            "total": total,
            "volume_laid_mm3": self.volume_laid_mm3,
            "volume_between_surfaces_mm3": self.volume_between_surfaces_mm3,
            "volume_error": (self.volume_between_surfaces_mm3 / self.volume_laid_mm3 - 1.0)
            if self.volume_laid_mm3 > 0 else 0.0,
        }

    def report(self) -> dict[str, Any]:
        """The run report of a layered job (``winder run --report``)."""
        rep = self.layup()
        rep["stage_times_s"] = dict(self.stage_times)
        laws = [lr.result.timelaw for lr in self.layers if lr.result is not None and lr.result.timelaw]
        if laws:
            law_total = float(sum(float(x.get("total_time_s", 0.0)) for x in laws))
            program = float(self.blocks.total) if self.blocks is not None else law_total
            rep["timelaw"] = {
                "method": self.job.timelaw.method,
                "total_time_s": law_total,
                "time_added_s": program - law_total,
                "layers": laws,
            }
        if self.machine is not None:
            rep["machine"] = self.machine.name
            rep["axes"] = list(self.machine.axis_names)
        if self.blocks is not None:
            rep["blocks"] = int(self.blocks.n)
            rep["program_time_s"] = float(self.blocks.total)
            rep["program_time_t17_s"] = float(self.blocks.total_t17)
        if self.placement is not None:
            p = self.placement
            rep["placement"] = {"axis": p.axis, "mode": p.mode, "mandrel_z0": p.z0, "range": [p.q_min, p.q_max],
                                "travel": [p.lo, p.hi], "fits": p.fits,
                                "z0_fit": list(p.z0_fit) if p.z0_fit else None, "message": p.message()}
        if self.blocks is not None and self.machine is not None:
            from engine.pipeline import _accel_ratios, _jump_ratios, _speed_ratios

            rep["max_speed_ratio"] = _speed_ratios(self.blocks, self.machine)
            rep["max_accel_ratio"] = _accel_ratios(self.blocks, self.machine)
            rep["max_jump_ratio"] = _jump_ratios(self.blocks, self.machine)
            qb = np.asarray(self.blocks.q, dtype=float)
            rep["axis_ranges"] = {n: [float(qb[:, k].min()), float(qb[:, k].max())]
                                  for k, n in enumerate(self.machine.axis_names)}
        rep["fibre_length_mm"] = 1e3 * float(sum(lr.figures.get("fibre_length_m", 0.0) for lr in self.layers))
        if self.transition_fibre_over_mm:
            # where the straight fibre of a transition would pass inside the laminate it is drawn over the surface
            rep["transition_fibre_over_laminate_mm"] = [float(x) for x in self.transition_fibre_over_mm]
        rep["violations"] = [{"kind": g.kind, "axis": g.axis, "what": g.what, "worst": g.worst, "value": g.value,
                              "limit": g.limit, "places": g.places, "count": g.points, **g.first}
                             for g in self.violation_groups()]
        if self.post_name:
            rep["post"] = self.post_name
        rep["warnings"] = self.warnings()
        rep["reused_layers"] = [i + 1 for i in self.reused]
        return rep


def _total_thickness(res: LaminateResult) -> FloatArray:
    """Total laminate thickness (mm) along the bare mandrel's grid: distance between bare and final surface
    measured along the bare surface's normal (sum of the layers' thicknesses, each at the same z)."""
    m, z, r, dr = meridian_grid(res.mandrel, 601)
    tot = np.zeros_like(z)
    for lr in res.layers:
        if lr.thickness is not None:
            tot += np.interp(z, lr.thickness.z, lr.thickness.t, left=0.0, right=0.0)
    return tot


# --------------------------------------------------------------------------------------------------
# The stack
# --------------------------------------------------------------------------------------------------
def _layer_job(job: Job, layer: Any, surface: Any) -> Job:
    """The single-line job of one layer: its band and winding values, the job's other sections."""
    band = effective_band(job, layer)
    if isinstance(layer, HelicalLayer):
        win = effective_winding(job, layer, surface)
        if isinstance(layer, PolarLayer) and layer.pole_c_mm is None:
            rp = surface.pole_radii
            win = win.model_copy(update={"pole_c_mm": (rp[0] + 0.5 * band.width_mm, rp[1] + 0.5 * band.width_mm)})
    else:
        win = job.winding
    payout = job.payout
    if isinstance(layer, HoopLayer) and payout.law != "parallel":
        # a hoop's free fibre leaves the mandrel along the parallel: the eye rides on a cylinder above the
        # contact (the 'parallel' law), the other laws' envelopes are built for turnarounds
        payout = payout.model_copy(update={"law": "parallel"})
    return job.model_copy(update={"band": band, "winding": win, "payout": payout, "layers": [layer]})


def _hash(*parts: Any) -> str:
    h = hashlib.sha256()
    for p in parts:
        h.update(json.dumps(p, sort_keys=True, default=str).encode())
    return h.hexdigest()[:16]


def layer_keys(job: Job) -> list[str]:
    """A key per layer of every input it depends on: the job's sections and all layers up to it."""
    data = job.model_dump(mode="json")
    layers = data.pop("layers")
    for k in ("post", "controller", "output"):   # the dialect is rendered by the join only: the layers stay
        data.get("post", {}).pop(k, None)
    base = _hash(data)
    return [_hash(base, layers[: k + 1]) for k in range(len(layers))]


def _check_polar(surface: Any, index: int) -> None:
    rp = surface.pole_radii
    rmax = surface.r_max
    if max(rp) >= 0.999 * rmax:
        raise InputError(
            f"layer {index + 1} (polar): a polar layer needs two polar openings (domes at both ends); this "
            f"surface ends with radii {rp[0]:.6g} and {rp[1]:.6g} mm against r_max {rmax:.6g} mm",
            field=f"layer.{index + 1}.kind")


def _located(exc: InputError, job_path: str | None, index: int, layer: Any) -> InputError:
    fld = exc.location.field or ""
    if fld.startswith(("winding.", "band.")):
        fld = f"layer.{index + 1}.{fld.split('.', 1)[1]}" if fld.startswith("winding.") else \
            f"layer.{index + 1}.band.{fld.split('.', 1)[1]}"
    msg = exc.message if exc.message.startswith("layer ") else \
        f"layer {index + 1} ({layer_name(layer, index)}): {exc.message}"
    return type(exc)(msg, file=exc.location.file or job_path, line=exc.location.line, field=fld or None)


def run_laminate(
    job: Job,
    job_path: str | Path | None = None,
    *,
    previous: LaminateResult | None = None,
    post_name: str | None = None,
    state: State | None = None,
    upto: str = "nc",
    workers: int = 1,
    pool: Any = None,
) -> LaminateResult:
    """Wind every enabled layer of ``job`` in order and join them into one program.

    Parameters
    ----------
    job, job_path:
        The job (schema 2) and its file (relative paths, error locations).
    previous:
        An earlier result of the same job: layers whose key (:func:`layer_keys`) is unchanged are re-used.
    post_name:
        Post-processor overriding ``job.post.post``.
    state:
        Progress / cancellation.
    upto:
        Last single-line stage run for each layer (``"nc"`` also joins and renders the program).
    workers:
        Worker processes for the layers' pipelines (payout -> axes -> blocks).  With more than one, the
        layers' lines, thicknesses and grown surfaces are computed here, in order (each layer needs the
        surface the previous ones left), and their pipelines run side by side in up to ``workers``
        forked children (POSIX; :class:`_Scheduler`; this process also runs a layer far cheaper than
        those running).  The result is the same as with ``workers=1``, which runs everything in this
        process, layer after layer.  Ignored (one process) while other threads run (a GUI): a fork
        copies only the calling thread.
    pool:
        An :class:`engine.layer_pool.LayerPool`: the layers' pipelines run side by side in its spawned
        worker processes instead (a process with threads, e.g. the GUI; ``workers`` is then the pool's).
        The same result again.
    """
    from engine.pipeline import load_machine_for_job, run_pipeline

    if post_name is not None:
        job = job.replace(post={**job.post.model_dump(), "post": post_name})
    jp = str(job_path) if job_path is not None else None
    t0 = time.perf_counter()
    bare = build_mandrel(job, jp)
    from engine.budget import check_laminate

    check_laminate(job, bare, file=jp)  # every layer's size and physics, and the sum, before any work
    if upto == "nc":
        # the post x machine mismatch is refused before any layer is wound (issue 15): the layers' own
        # runs stop at the blocks and never reach the post's check
        from engine.machine_setup import controller_for
        from engine.pipeline import _locate, setup_machine_for_job

        try:
            controller_for(job.post.post, job.post.controller, setup_machine_for_job(job, jp))
        except InputError as exc:
            raise _locate(exc, jp, "nc") from None
    keys = layer_keys(job)
    prev_by_key = {lr.key: lr for lr in previous.layers} if previous is not None else {}
    active = job.active_layers
    if not active:
        raise InputError("every layer is disabled: nothing to wind", file=jp, field="layer")
    surface = bare
    results: list[LayerResult] = []
    reused: list[int] = []
    layer_upto = "blocks" if upto == "nc" else upto
    n = len(active)
    if pool is not None:
        workers = max(2, pool.workers)  # a layer the pool cannot take runs in this process
    parallel = workers > 1 and (pool is not None or _can_fork())
    slots: list[LayerResult | _Prepared] = []  # parallel: in order, a layer's result or its preparation
    sched = _Scheduler(jp, layer_upto, workers, pool, join=upto == "nc") if parallel else None
    if parallel:
        _preload()
        _remove_stale_files()
    term = _TerminateAsInterrupt().__enter__() if parallel else None
    _reap_exited()  # children of an earlier run that failed after they answered
    try:
        first_error: InputError | None = None
        for j, (i, layer) in enumerate(active):
            check_cancel(state)
            sub = SubState(state, j / n, (j + 1) / n) if state is not None else None
            key = keys[i]
            old = prev_by_key.get(key)
            if old is not None and old.surface is not None and _same_surface(old.surface, surface):
                results.append(old)
                slots.append(old)
                reused.append(i)
                surface = old.grown
                continue
            name = layer_name(layer, i)
            try:
                if parallel:  # the pipelines run after the loop, side by side
                    p = _prepare_layer(job, jp, i, layer, name, key, surface, sub, bare=bare)
                    slots.append(p)
                    surface = p.grown
                    if isinstance(p, _Prepared):
                        sched.add(p, more=j < n - 1,  # type: ignore[union-attr]
                                  heavier_later=any(isinstance(lay, (HelicalLayer, PolarLayer))
                                                    for _k, lay in active[j + 1:]))
                    continue
                lr = _wind_layer(job, jp, i, layer, name, key, surface, layer_upto, sub, run_pipeline, bare=bare)
            except InputError as exc:  # InfeasibleError included
                if not parallel:
                    raise _located(exc, jp, i, layer) from None
                first_error = _located(exc, jp, i, layer)  # raised after the pipelines of the layers before it
                break
            results.append(lr)
            surface = lr.grown
        if parallel:
            results = sched.finish(job, slots, state, n, active)  # type: ignore[union-attr]
            if first_error is not None:
                raise first_error
    finally:
        if sched is not None:  # an error or a cancel while layers were still being prepared
            sched.close()
        if term is not None:
            term.__exit__()
    res = LaminateResult(job=job, job_path=jp, mandrel=bare, layers=tuple(results), reused=tuple(reused))
    times: dict[str, float] = {}
    for lr in results:
        if lr.result is not None and lr.index not in reused:
            for k, v in lr.result.stage_times.items():
                times[k] = times.get(k, 0.0) + float(v)
    if upto == "nc":
        t1 = time.perf_counter()
        laid = [lr for lr in results if lr.result is not None and lr.result.machine is not None]
        machine = laid[0].result.machine if laid else load_machine_for_job(job, jp)
        res = _join(res, machine, sched.prebuilt if sched is not None else None, side=parallel and pool is None)
        times["nc"] = times.get("nc", 0.0) + time.perf_counter() - t1
    _reap_exited()
    times["total"] = time.perf_counter() - t0
    return replace(res, stage_times=times)


_EXITING: list[int] = []
"""Forked children that have answered and were still exiting then: reaped by :func:`_reap_exited` (their
exit, freeing a few hundred MB, takes ~8 ms that the join need not wait for)."""


def _reap_exited() -> None:
    """Reap the children of :data:`_EXITING` (they have answered: each is gone or about to be)."""
    import os

    while _EXITING:
        pid = _EXITING.pop()
        try:
            os.waitpid(pid, 0)
        except ChildProcessError:  # reaped already
            pass


def default_workers() -> int:
    """Worker processes :func:`run_laminate` may use from a command line: the CPUs this process may run
    on, within the cgroup's CPU quota (a container's limit); ``WINDER_JOBS`` overrides.  1 on macOS (its
    system libraries are not safe in a forked child: Python itself spawns there) unless ``WINDER_JOBS``
    says otherwise, and where processes cannot be forked."""
    import os
    import sys

    env = os.environ.get("WINDER_JOBS", "").strip()
    if env:
        try:
            n = int(env)
        except ValueError:
            n = 0
        if n < 1:
            raise InputError(f"WINDER_JOBS must be a whole number of processes >= 1, not {env!r}",
                             field="WINDER_JOBS")
        return n
    if sys.platform == "darwin" or not _can_fork():
        return 1
    return available_cpus()


def available_cpus() -> int:
    """The CPUs this process may run on (its affinity), within the cgroup's CPU quota (a container's limit)."""
    import os

    try:
        n = len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        n = os.cpu_count() or 1
    return max(1, min(n, _cgroup_cpus()))


def _cgroup_cpus(path: str = "/sys/fs/cgroup/cpu.max") -> int:
    """The CPUs a cgroup-v2 CPU quota allows (``cpu.max``: "quota period", or "max"), rounded up; a large
    number where there is no quota or no such file."""
    import math

    try:
        with open(path) as f:
            quota, period = f.read().split()[:2]
        if quota == "max":
            return 1 << 16
        return max(1, math.ceil(int(quota) / int(period)))
    except (OSError, ValueError):
        return 1 << 16


def _can_fork() -> bool:
    """Whether forking is available and safe here: POSIX, and no other Python thread running (a fork
    copies only the calling thread; a lock another thread holds would stay locked in the child)."""
    import multiprocessing
    import threading

    return "fork" in multiprocessing.get_all_start_methods() and threading.active_count() == 1


def _pipeline_cost(p: _Prepared) -> float:
    """A layer's pipeline cost in arbitrary units: its line points, a hoop's much cheaper per point."""
    from engine.periodic import raw_field

    w = 0.1 if isinstance(p.layer, HoopLayer) else 1.0
    return w * float(len(raw_field(p.line, "z")))  # (a big line's z is not materialised to count it)


_PIPELINE_MODULES = ("engine.payout", "engine.kinematics", "engine.blocks", "engine.timeparam",
                     "scipy.sparse")
"""What the layers' pipelines import: imported once here before the forks instead of once per child.
(SciPy's HiGHS, k-d tree and LAPACK extensions: :func:`_preload` loads them alone, engine._lightimport.)"""


def _preload() -> None:
    import importlib

    for name in _PIPELINE_MODULES:
        importlib.import_module(name)
    from engine.payout import _highs_core

    _highs_core()  # the narrowest-band LP's HiGHS, once for every child
    from engine._lightimport import ckdtree, flapack

    ckdtree()      # and the clearance distances' k-d tree
    flapack()      # and the banded solves' LAPACK


class _Failed:
    """A layer's pipeline failed other than on its input (a bug): raised again in layer order."""

    def __init__(self, exc: Exception) -> None:
        self.exc = exc


def _read_to_end(fd: int) -> bytes:
    """Everything a child writes to the pipe ``fd`` until it closes its end (exits or dies)."""
    import os

    chunks = []
    while True:
        got = os.read(fd, 1 << 20)
        if not got:
            return b"".join(chunks)
        chunks.append(got)


def _kill_and_reap(pid: int, kill: bool = True) -> None:
    """Stop the child ``pid`` (``kill``: SIGKILL first, else wait for its own end) and reap it."""
    import os
    import signal

    if kill:
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    try:
        os.waitpid(pid, 0)
    except ChildProcessError:  # reaped already (an interrupt came between the wait and the flag)
        pass


class _Child:
    """A forked process running one layer's pipeline (:func:`_fork_pipeline`)."""

    def __init__(self, pid: int, fd: int, layer: _Prepared, paths: list[str]) -> None:
        self.pid, self.fd, self.layer, self.paths = pid, fd, layer, paths
        self.reaped = self.closed = False

    def ready(self) -> bool:
        """Whether it has written its answer (or died): reading will not wait for its work."""
        import select

        return bool(select.select([self.fd], [], [], 0.0)[0])

    def receive(self) -> Any:
        """Its answer: the layer's pipeline result (without line and surface), the InputError it raised, or
        None when it died or failed otherwise (the layer is then run here)."""
        import pickle

        got = _read_to_end(self.fd)
        self.let_exit()
        try:
            if not got:
                return None
            data, path, spans = pickle.loads(got)
            return _unpack(data, path, spans)
        except Exception:  # noqa: BLE001 - a truncated answer: run the layer here
            return None
        finally:
            self.remove_files()

    def let_exit(self) -> None:
        """It has answered (or died): reap it if it is gone, else leave it to finish its exit and be reaped
        after the join (:func:`_reap_exited`) instead of waiting for it here."""
        import os

        if self.reaped:
            return
        try:
            done, _ = os.waitpid(self.pid, os.WNOHANG)
        except ChildProcessError:  # reaped already
            done = self.pid
        if not done:
            _EXITING.append(self.pid)
        self.reaped = True

    def reap(self, kill: bool = True) -> None:
        if self.reaped:
            return
        _kill_and_reap(self.pid, kill)
        self.reaped = True

    def remove_files(self) -> None:
        _remove_files(self.paths)

    def close(self) -> None:
        """Stop it if it still runs, reap it, close its pipe and remove its files."""
        import os

        self.reap(kill=True)
        if not self.closed:
            self.closed = True
            os.close(self.fd)
        self.remove_files()


class _Scheduler:
    """Runs the prepared layers' pipelines side by side in forked worker processes, one layer each.

    A layer goes to a child as soon as it is prepared if a later layer is still to be prepared and fewer
    than ``workers - 1`` children run (this process prepares the next layers meanwhile), except a hoop
    layer with a helical or polar layer still to come (this process winds it later).  Once every layer
    is prepared, up to ``workers`` children run the rest, the longest first, each slot taking the next
    layer as it frees up; this process runs a layer itself only when it is far cheaper than those running
    (a hoop layer costs less than its fork) or when it is the last one and no child runs.  The answers are
    taken in layer order, so the first failing layer's error is the one raised, as in one process."""

    def __init__(self, jp: str | None, upto: str, workers: int, pool: Any = None, join: bool = False) -> None:
        self.jp, self.upto, self.workers, self.slots_free = jp, upto, workers, max(0, workers - 1)
        self.join = join  # the layers will be joined into one program (run_laminate(upto="nc"))
        self.prebuilt: dict[int, tuple[Any, Any]] = {}  # distance functions for the join, built while waiting
        self.laid: dict[int, LayerResult] = {}  # layers wound here, with their figures (made while waiting)
        self.figs: dict[int, dict[str, Any]] = {}  # the children's layers' figures but the time (made while waiting)
        self.pool = pool  # an engine.layer_pool.LayerPool: its workers instead of forked children
        self.queue: list[_Prepared] = []
        self.children: dict[int, _Child] = {}  # by layer index
        self.out: dict[int, Any] = {}

    def _running(self) -> int:
        return sum(1 for i in self.children if i not in self.out)

    def _poll(self) -> None:
        """Collect the answers of children that have written them (frees their slots)."""
        for i, c in self.children.items():
            if i not in self.out and c.ready():
                self.out[i] = c.receive()

    def _small(self, p: _Prepared) -> bool:
        """A layer much cheaper than the ones running (run here rather than forked for)."""
        running = [_pipeline_cost(c.layer) for i, c in self.children.items() if i not in self.out]
        return bool(running) and _pipeline_cost(p) <= 0.25 * max(running)

    def _wait(self, state: State | None) -> None:
        """Until a running child answers (polling ``state`` for a cancel every 0.1 s)."""
        import select

        fds = [c.fd for i, c in self.children.items() if i not in self.out]
        while fds and not select.select(fds, [], [], 0.1)[0]:
            check_cancel(state)
        check_cancel(state)

    def _spawn(self, p: _Prepared, sub: State | None, here: bool = True) -> bool:
        """``p`` to a new child (True); where forking is not possible any more (a thread started, the
        system refused the fork) or the pool cannot take it: run here (``here``) or leave it to the
        caller (False)."""
        import threading

        if self.pool is not None:
            if _pool_pipeline(self.pool, self.jp, p, self.upto, lambda c: self.children.__setitem__(p.i, c)):
                return True
        elif threading.active_count() == 1:
            try:
                _fork_pipeline(self.jp, p, self.upto, lambda c: self.children.__setitem__(p.i, c))
                return True
            except OSError:
                pass
        if here:
            self.out[p.i] = self._here(p, sub)
        return False

    def close(self) -> None:
        """Stop and reap every child, close its pipe, remove its files (idempotent)."""
        for c in self.children.values():
            c.close()

    def add(self, p: _Prepared, more: bool, heavier_later: bool = False) -> None:
        """A layer is prepared (``more``: others are still to be prepared): to a free child, else queued.
        A hoop layer with a helical or polar layer still to come is queued: it will be far cheaper than
        that one, and this process winds it while that one runs (its fork would cost about as much)."""
        self._poll()
        if not (more and self._running() < self.slots_free and not (isinstance(p.layer, HoopLayer) and heavier_later)
                and self._spawn(p, None, here=False)):
            self.queue.append(p)  # wound later, with its progress and cancel (finish)

    def _here(self, p: _Prepared, state: State | None) -> Any:
        from engine.errors import Cancelled
        from engine.pipeline import run_pipeline

        try:
            return run_pipeline(p.ljob, self.jp, upto=self.upto, mandrel=p.surface, line=p.line, state=state)
        except InputError as exc:  # InfeasibleError included
            return exc
        except Cancelled:
            raise
        except Exception as exc:  # noqa: BLE001 - raised again in layer order
            return _Failed(exc)

    def _lay(self, job: Job, p: _Prepared) -> None:
        """The result of layer ``p``, wound in this process, with its figures (:func:`_laid`)."""
        self.laid[p.i] = _laid(job, p, self.out[p.i])

    def _prefigure(self, job: Job, p: _Prepared) -> None:
        """The figures of layer ``p``, whose pipeline runs in a child, but for its time (they come from its
        preparation): made while this process waits, not after the child's answer."""
        self.figs[p.i] = _figures(job, p.i, p.name, p.layer, p.ljob, p.surface, p.line, p.thickness, None)

    def _prefigures(self, job: Job, done: set[int]) -> list[Callable[[], None]]:
        """:meth:`_prefigure` steps for the children's layers not yet in ``done`` (added to it)."""
        import functools

        new = [c.layer for i, c in self.children.items() if i not in done]
        done.update(p.i for p in new)
        return [functools.partial(self._prefigure, job, p) for p in new]

    def finish(self, job: Job, slots: list[Any], state: State | None, n: int,
               active: list[Any]) -> list[LayerResult]:
        """Every prepared layer's result, in order; the first failing layer's error (in layer order) is
        raised, as in one process."""
        order = {i: j for j, (i, _layer) in enumerate(active)}

        def sub(p: _Prepared) -> State | None:
            j = order[p.i]
            return SubState(state, j / n, (j + 1) / n) if state is not None else None

        import functools

        # what the join will need and the layers' answers do not change: built while this process waits
        idle = _join_prework(slots, self.prebuilt) if self.join else []
        figured: set[int] = set()   # the children's figures go first (needed right at their answers)
        try:
            self.queue.sort(key=_pipeline_cost, reverse=True)
            while self.queue or self._running():
                self._poll()
                idle[:0] = self._prefigures(job, figured)   # (of the children forked since)
                while len(self.queue) > 1 and self._running() < self.workers and not self._small(self.queue[0]):
                    p = self.queue.pop(0)
                    self._spawn(p, sub(p))
                if self.queue and (self._running() >= self.workers or self._small(self.queue[-1]) or
                                   len(self.queue) == 1 and not self._running()):
                    p = self.queue.pop()
                    self.out[p.i] = self._here(p, sub(p))
                    got = self.out[p.i]
                    if got is not None and not isinstance(got, (BaseException, _Failed)):
                        idle.insert(0, functools.partial(self._lay, job, p))  # its figures, while children run
                    continue
                if self.queue:
                    p = self.queue.pop(0)
                    self._spawn(p, sub(p))
                    continue
                if idle and not any(c.ready() for i, c in self.children.items() if i not in self.out):
                    check_cancel(state)
                    idle.pop(0)()
                    continue
                self._wait(state)
            for i, c in self.children.items():
                if i not in self.out:
                    self.out[i] = c.receive()
        finally:
            self.close()
        filled: list[LayerResult] = []
        for p in slots:  # in layer order: a re-run, an error, as one process would meet them
            if isinstance(p, LayerResult):
                filled.append(p)
                continue
            if p.i in self.laid:  # wound here, its figures made while waiting
                filled.append(self.laid[p.i])
                continue
            got = self.out[p.i]
            if got is None:  # its child died, or failed other than on its input: run it here
                got = self._here(p, sub(p))
            elif p.i in self.children and not isinstance(got, (BaseException, _Failed)):
                got = replace(got, line=p.line, mandrel=p.surface)  # not sent back: this process's own
            if isinstance(got, _Failed):
                raise got.exc
            if isinstance(got, InputError):
                raise _located(got, self.jp, p.i, p.layer) from None
            filled.append(_laid(job, p, got, self.figs.get(p.i) if p.i in self.children else None))
        return filled


def _join_prework(slots: list[Any], fns: dict[int, tuple[Any, Any]]) -> list[Callable[[], None]]:
    """The distance functions of the surfaces the layers that lay fibre are wound on (the join's
    transition checks measure against them, :func:`transition_clearance`), as steps that add them to ``fns``;
    none when fewer than two layers lay fibre (no transition)."""
    import functools

    surfaces = [s.surface for s in slots if isinstance(s, _Prepared)
                or (isinstance(s, LayerResult) and s.result is not None)]
    if len(surfaces) < 2:
        return []
    return [functools.partial(prebuild_distance, surface, fns) for surface in surfaces]


def _fork_pipeline(jp: str | None, p: _Prepared, upto: str, register: Callable[[_Child], None]) -> _Child:
    """Fork a process that runs the pipeline of ``p`` and answers through a pipe: its result (line and
    surface left out: this process has them) or the InputError it raised, pickled with the arrays' data
    in a file whose name this process chose (so it removes it whatever happens; shared memory first).
    ``register`` gets the child before Ctrl-C can interrupt this process again (so it is always stopped).
    Raises OSError where the system refuses the fork (nothing is left then)."""
    import os
    import secrets

    tag = f"winder-{os.getpid()}-{p.i}-{secrets.token_hex(6)}"
    paths = [os.path.join(folder, tag) for folder in _answer_folders()]

    def adopt(pid: int, r: int) -> _Child:
        child = _Child(pid, r, p, paths)
        register(child)
        return child

    return _fork_with(lambda w: _pipeline_child(w, jp, p, upto, paths), adopt)


def _fork_with(body: Callable[[int], None], adopt: Callable[[int, int], Any]) -> Any:
    """Fork a process that runs ``body(w)`` (``w``: the write end of a pipe to this process) and exits; here
    ``adopt(pid, r)`` (``r``: the pipe's read end) is called and its value returned.  Ctrl-C and kill stay
    pending across the fork: the child ignores them (and dies with this process) before they can arrive,
    this process takes them after ``adopt`` (so whatever it registers can always be stopped).  Raises
    OSError where the system refuses the fork (nothing is left then)."""
    import os
    import signal

    r, w = os.pipe()
    parent = os.getpid()
    old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT, signal.SIGTERM})
    try:
        try:
            pid = os.fork()
        except OSError:
            os.close(r)
            os.close(w)
            raise
        if pid == 0:  # the child: never returns into the caller's code
            code = 1
            try:
                signal.signal(signal.SIGINT, signal.SIG_IGN)
                signal.signal(signal.SIGTERM, signal.SIG_DFL)
                _die_with_parent()
                if os.getppid() == parent:  # else the parent died before that took effect
                    signal.pthread_sigmask(signal.SIG_SETMASK, old)
                    os.close(r)
                    body(w)
                    code = 0
            finally:
                os._exit(code)
        os.close(w)
        return adopt(pid, r)
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


def _budget_state() -> tuple[int | None, bool]:
    """This process's memory budget settings (engine.budget), for a pool worker to apply (a spawned process
    does not inherit them as a forked child does)."""
    from engine import budget

    return budget._override, budget._materialised


_POOL_MAX_POINTS = 2_000_000
"""A layer whose line has more points is wound in the calling process rather than sent to a pool worker:
pickling its line (~160 bytes a point) would hold the interpreter lock long enough to stall the GUI."""


def _pool_pipeline(pool: Any, jp: str | None, p: _Prepared, upto: str, register: Callable[[Any], None]) -> bool:
    """Send ``p`` to a worker of ``pool`` (:class:`engine.layer_pool.LayerPool`); False when none is free
    or it could not take the layer (the caller runs it itself)."""
    import os
    import secrets

    from engine.layer_pool import PoolChild
    from engine.periodic import raw_field

    if len(raw_field(p.line, "z")) > _POOL_MAX_POINTS:  # counted without materialising the line
        return False
    w = pool.acquire()
    if w is None:
        return False
    tag = f"winder-{os.getpid()}-{p.i}-{secrets.token_hex(6)}"
    paths = [os.path.join(folder, tag) for folder in _answer_folders()]
    try:
        message = PoolChild.message(jp, p, upto, paths, _budget_state())
    except Exception:  # noqa: BLE001 - the layer would not pickle: run it here; the worker stays as it is
        pool.release(w)
        return False
    try:
        child = PoolChild(pool, w, p, paths, message)
    except Exception:  # noqa: BLE001 - the worker died: run it here, a fresh one replaces it
        pool.discard(w)
        return False
    register(child)
    return True


def _remove_files(paths: list[str]) -> None:
    """Remove a child's answer files (those that exist; a cleanup never raises)."""
    import os

    for path in paths:
        try:
            os.unlink(path)
        except OSError:
            pass


def _answer_folders() -> list[str]:
    """Where children write their answers: shared memory first, then the temporary folder (a container's
    /dev/shm is often 64 MB)."""
    import os
    import tempfile

    out = ["/dev/shm"] if os.path.isdir("/dev/shm") else []
    tmp = tempfile.gettempdir()
    return out + ([tmp] if tmp not in out else [])


class _ForkedCall:
    """A function running in a forked process (:func:`_fork_call`); :meth:`result` waits for its answer."""

    def __init__(self, pid: int, fd: int) -> None:
        self.pid, self.fd = pid, fd
        self.done = False

    def result(self) -> Any:
        """The function's value, or None where it raised or the process died (the caller computes it itself)."""
        import pickle

        try:
            got = _read_to_end(self.fd)
        finally:
            self.close()
        try:
            kind, value = pickle.loads(got)
        except Exception:  # noqa: BLE001 - nothing or a partial answer: it died
            return None
        return value if kind == "ok" else None

    def close(self) -> None:
        """Stop the process if it still runs, reap it and close the pipe (idempotent)."""
        import os

        if self.done:
            return
        self.done = True
        _kill_and_reap(self.pid)
        try:
            os.close(self.fd)
        except OSError:
            pass


def _fork_call(fn: Callable[[], Any]) -> _ForkedCall | None:
    """Run ``fn()`` in a forked process that sends its value back pickled through a pipe; None where forking
    is not possible here (another thread runs, no fork) or the system refuses it.  The process ignores
    Ctrl-C and dies with this one (:func:`_fork_with`); an exception in it is not sent (the caller then runs
    ``fn`` itself and meets it there, as without the fork)."""
    import os
    import pickle

    def body(w: int) -> None:
        try:
            data = pickle.dumps(("ok", fn()), protocol=pickle.HIGHEST_PROTOCOL)
        except BaseException:  # noqa: BLE001 - the caller runs fn itself and meets it
            data = pickle.dumps(("failed", None))
        view = memoryview(data)
        while view:
            view = view[os.write(w, view):]

    if not _can_fork():
        return None
    try:
        return _fork_with(body, _ForkedCall)
    except OSError:
        return None


def _die_with_parent() -> None:
    """Linux: this (child) process gets SIGKILL when its parent dies, whatever kills the parent (best
    effort: elsewhere the parent's cleanup and :func:`_remove_stale_files` must do)."""
    try:
        import ctypes
        import signal

        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, int(signal.SIGKILL), 0, 0, 0)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass


def _remove_stale_files() -> None:
    """Remove answer files of earlier runs whose process is gone (killed before it could clean up)."""
    import os
    import re

    for folder in _answer_folders():
        try:
            names = os.listdir(folder)
        except OSError:
            continue
        for name in names:
            m = re.fullmatch(r"winder-(\d+)-\d+-[0-9a-f]{12}", name)
            if m is None or int(m.group(1)) == os.getpid():
                continue
            try:
                os.kill(int(m.group(1)), 0)
            except ProcessLookupError:
                try:
                    os.unlink(os.path.join(folder, name))
                except OSError:
                    pass
            except OSError:
                pass


class _TerminateAsInterrupt:
    """While layers run in children: SIGTERM (``kill``, a job scheduler's time limit) raises
    :class:`engine.errors.Terminated` (a KeyboardInterrupt) in this (main) thread, so the children are
    stopped and their files removed as on Ctrl-C; the previous handler is restored on exit."""

    def __enter__(self) -> _TerminateAsInterrupt:
        import signal

        from engine.errors import Terminated

        def stop(signum: int, frame: Any) -> None:
            raise Terminated

        self.installed = False
        try:
            self.old = signal.signal(signal.SIGTERM, stop)
            self.installed = True
        except ValueError:  # not the main thread
            pass
        return self

    def __exit__(self, *exc: object) -> None:
        import signal

        if self.installed:
            signal.signal(signal.SIGTERM, self.old if self.old is not None else signal.SIG_DFL)


def _pipeline_child(fd: int, jp: str | None, p: _Prepared, upto: str, paths: list[str]) -> None:
    """A forked child's work: :func:`_pipeline_answer` written to the pipe ``fd``."""
    import os

    view = memoryview(_pipeline_answer(jp, p, upto, paths))
    while view:
        view = view[os.write(fd, view):]
    os.close(fd)


def _pipeline_answer(jp: str | None, p: _Prepared, upto: str, paths: list[str]) -> bytes:
    """Run the pipeline of ``p``; the answer to send back: its result (line and surface left out: the
    caller has them), the InputError it raised, or None after another error (the caller runs the layer
    again and meets it itself), pickled with the arrays' data in the first of ``paths`` that takes them
    (:func:`_pack`; else everything in the pickle)."""
    import os
    import pickle

    from engine.pipeline import run_pipeline

    try:
        r = run_pipeline(p.ljob, jp, upto=upto, mandrel=p.surface, line=p.line, state=None)
        out: Any = replace(r, line=None, mandrel=None)
    except InputError as exc:
        out = exc
    except Exception:  # noqa: BLE001 - the parent runs this layer again and meets the error itself
        out = None
    msg = None
    for path in paths:  # shared memory, then the temporary folder
        try:
            data, spans = _pack(out, path)
            msg = (data, path, spans)
            break
        except OSError:  # full (a container's 64 MB /dev/shm), not writable
            try:
                os.unlink(path)
            except OSError:
                pass
    if msg is None:  # no file at all: everything through the pipe
        msg = (pickle.dumps(out, protocol=5), None, [])
    return pickle.dumps(msg, protocol=5)


def _pack(obj: Any, path: str) -> tuple[bytes, list[tuple[int, int]]]:
    """Pickle ``obj`` with its arrays' data out of band, written to the file ``path`` (shared memory,
    ``/dev/shm``, where there is room): the parent maps that file instead of copying tens of MB through
    the pipe.  Returns the pickle and the (offset, size) of every buffer in the file."""
    import os
    import pickle

    bufs: list[pickle.PickleBuffer] = []
    data = pickle.dumps(obj, protocol=5, buffer_callback=bufs.append)
    spans = []
    with open(path, "wb", opener=lambda f, fl: os.open(f, fl, 0o600)) as f:
        off = 0
        for b in bufs:
            raw = b.raw()
            pad = -off % 64  # aligned as numpy aligns its own: an unaligned array sums in another order
            f.write(b"\0" * pad)
            off += pad
            spans.append((off, raw.nbytes))
            f.write(raw)
            off += raw.nbytes
    return data, spans


def _unpack(data: bytes, path: str | None, spans: list[tuple[int, int]]) -> Any:
    """The object :func:`_pack` wrote (``path`` None: pickled whole); its arrays are copy-on-write views
    of the mapped file, which is removed."""
    import mmap
    import os
    import pickle

    if path is None:
        return pickle.loads(data)
    try:
        with open(path, "rb") as f:
            size = os.fstat(f.fileno()).st_size
            mm = mmap.mmap(f.fileno(), size, access=mmap.ACCESS_COPY) if size else None
    finally:
        os.unlink(path)
    view = memoryview(mm) if mm is not None else memoryview(b"")
    return pickle.loads(data, buffers=[view[a:a + n] for a, n in spans])


def _same_surface(a: Any, b: Any) -> bool:
    if a is b:
        return True
    za, ra = a.sample(200)
    zb, rb = b.sample(200)
    return za.shape == zb.shape and bool(np.allclose(za, zb, atol=1e-9) and np.allclose(ra, rb, atol=1e-9))


@dataclass(frozen=True)
class _Prepared:
    """A layer up to its pipeline: its job, line, thickness and the surface it leaves (all that the next
    layer needs), computed in layer order; the pipeline itself may then run in another process."""

    i: int
    layer: Any
    name: str
    key: str
    surface: Any
    ljob: Job
    line: Any
    thickness: Thickness
    grown: Any


def _prepare_layer(job: Job, jp: str | None, i: int, layer: Any, name: str, key: str, surface: Any,
                   state: State | None, bare: Any = None) -> _Prepared | LayerResult:
    """The layer's line on ``surface``, its thickness and the grown surface (a skip layer: its result)."""
    if isinstance(layer, SkipLayer):
        return LayerResult(index=i, name=name, kind="skip", key=key, surface=surface, grown=surface,
                           figures=_figures_skip(i, name, layer))
    ljob = _layer_job(job, layer, surface)
    band = ljob.band
    if isinstance(layer, HoopLayer):
        line = hoop_line(surface, band.width_mm, band.friction, layer, i, bare=bare)
    else:
        if isinstance(layer, PolarLayer):
            _check_polar(surface, i)
        from engine.winding import winding_line

        line = winding_line(surface, band.width_mm, band.friction, ljob.winding, state,
                            _ctx={"file": jp, "job": True})
        if isinstance(layer, PolarLayer) and layer.pole_c_mm is None and line.slips:
            # unequal openings: no line tangent to both is held by friction; the geodesic tangent to the
            # larger opening passes the smaller one at a distance (the usual polar layup of such a vessel)
            c = max(ljob.winding.pole_c_mm or (0.0, 0.0))
            win = ljob.winding.model_copy(update={"pole_c_mm": (c, c), "mode": "geodesic"})
            ljob = ljob.model_copy(update={"winding": win})
            line = winding_line(surface, band.width_mm, band.friction, win, state, _ctx={"file": jp, "job": True})
            line = replace(line, notes=[*line.notes, f"polar layer: the line tangent to both openings slips; "
                                                     f"wound as the geodesic tangent to the larger one (C {c:.6g} mm)"])
    if not isinstance(layer, HoopLayer):
        _check_band_on_surface(surface, line, band.width_mm, i, layer)
    th = layer_thickness(surface, line, band.width_mm, band.thickness_mm, layer.kind)
    grown = grow_surface(surface, th, name=f"after layer {i + 1}")
    return _Prepared(i=i, layer=layer, name=name, key=key, surface=surface, ljob=ljob, line=line, thickness=th,
                     grown=grown)


def _laid(job: Job, p: _Prepared, res: Any, figs: dict[str, Any] | None = None) -> LayerResult:
    """The layer's result from its preparation and its pipeline result (``figs``: its figures made from the
    preparation before the pipeline ended, :func:`_figures` with ``res`` None; their time is added here)."""
    if figs is None:
        figs = _figures(job, p.i, p.name, p.layer, p.ljob, p.surface, p.line, p.thickness, res)
    else:
        figs = {**figs, "time_s": _figures_time(res)}
    return LayerResult(index=p.i, name=p.name, kind=p.layer.kind, key=p.key, surface=p.surface, grown=p.grown,
                       result=res, thickness=p.thickness, figures=figs)


def _wind_layer(job: Job, jp: str | None, i: int, layer: Any, name: str, key: str, surface: Any, upto: str,
                state: State | None, run_pipeline: Any, bare: Any = None) -> LayerResult:
    p = _prepare_layer(job, jp, i, layer, name, key, surface, state, bare=bare)
    if isinstance(p, LayerResult):
        return p
    res = run_pipeline(p.ljob, jp, upto=upto, mandrel=surface, line=p.line, state=state)
    return _laid(job, p, res)


def _check_band_on_surface(surface: Any, line: Any, b: float, i: int, layer: Any) -> None:
    """A line turning on a dome must keep its whole band on the surface: C − κ·b/2 >= the opening radius."""
    rp = surface.pole_radii
    for side in (0, 1):
        if line.end_kinds[side] == "open":
            continue
        zt = line.z_turn[side]
        r_t, d1, _ = surface.evaluate(np.array([zt]))
        kap = min(1.0, abs(float(d1[0])) / math.sqrt(1.0 + float(d1[0]) ** 2))
        c_lo = float(r_t[0]) - 0.5 * kap * b
        if c_lo < rp[side] - 1e-6 * max(1.0, rp[side]):
            end = ("left", "right")[side]
            raise InputError(
                f"layer {i + 1} ({layer_name(layer, i)}): the line turns at r = {float(r_t[0]):.4g} mm on the {end} "
                f"dome, closer than half the band ({b:g} mm) to the polar opening (r = {rp[side]:.4g} mm): the band "
                f"would hang over its edge; choose a smaller angle or a pole C >= {rp[side] + 0.5 * b:.4g} mm",
                field=f"layer.{i + 1}.angle_deg" if getattr(layer, "angle_deg", None) is not None
                else f"layer.{i + 1}.pole_c_mm")


def _figures_skip(i: int, name: str, layer: SkipLayer) -> dict[str, Any]:
    return {"index": i + 1, "name": name, "kind": "skip", "angle_deg_cylinder": None, "circuits": 0, "passes": 0,
            "band_width_mm": 0.0, "band_thickness_mm": 0.0, "overlap": 0.0, "radius_cyl_mm": None,
            "coverage": 0.0, "thickness_cyl_mm": 0.0, "thickness_max_mm": 0.0, "time_s": 0.0,
            "fibre_length_m": 0.0, "fibre_mass_kg": 0.0, "resin_mass_kg": 0.0, "volume_laid_mm3": 0.0,
            "skip_deg": float(layer.angle_deg)}


def _figures(job: Job, i: int, name: str, layer: Any, ljob: Job, surface: Any, line: Any, th: Thickness,
             res: Any) -> dict[str, Any]:
    from engine.mandrel import cylinder_range

    band = ljob.band
    b, tb = band.width_mm, band.thickness_mm
    za, zb = cylinder_range(surface)
    zc = 0.5 * (za + zb)
    rc = float(surface.r(zc))
    # angle on the cylinder middle: from the outgoing pass
    from engine.periodic import field_rows

    p0 = int(field_rows(line, "pass_id", 0, 1)[0])
    pid, dw, zl, bl = _pass_fields(line, p0, ("dwell", "z", "beta"))
    sel = (pid == p0) & ~dw
    beta_c = float(np.interp(zc, *_sorted(zl[sel], bl[sel])))
    length_mid = _length_mid(line, th, layer.kind)
    vol = length_mid * b * tb
    mat = find_material(band.material)
    tows = layer.band.tows if layer.band.tows is not None else getattr(job.band, "tows", None)
    if tows:  # the band's linear density: tows x tex x length
        mass_f, mass_r = mat.masses_from_tows_kg(length_mid, int(tows))
    else:  # the laid volume at the material's fibre volume fraction
        mass_f, mass_r = mat.masses_kg(vol)
    cov = line.coverage
    if layer.kind == "hoop":
        coverage = float(cov["fraction"])
        circuits = 0
        passes = 1 if layer.terminal else layer.passes
        overlap = float(layer.overlap)
    else:
        coverage = float(cov.get("fraction", 0.0))
        circuits = int(line.circuits)
        passes = 2 * circuits
        overlap = float(max(cov.get("overlap_mm", 0.0), 0.0) / b)
    time_s = _figures_time(res)
    return {
        "index": i + 1, "name": name, "kind": layer.kind,
        "angle_deg_cylinder": math.degrees(beta_c),
        "circuits": circuits, "passes": passes,
        "band_width_mm": b, "band_thickness_mm": tb, "overlap": overlap,
        "radius_cyl_mm": rc, "coverage": coverage,
        "thickness_cyl_mm": float(th.at(zc)), "thickness_max_mm": float(th.t.max()),
        "thickness_pole_mm": _pole_thickness(th, b),
        "time_s": time_s, "fibre_length_m": float(field_rows(line, "s", line.n_points - 1, line.n_points)[0]) * 1e-3,
        "fibre_mass_kg": mass_f, "resin_mass_kg": mass_r, "material": mat.name,
        "volume_laid_mm3": vol, "volume_between_mm3": th.volume_mm3,
        "pole_radii_after_mm": None,
    }


def _figures_time(res: Any) -> float:
    """A layer's figure ``time_s``: its blocks' total time (s), 0 without blocks (or without a result yet)."""
    return float(res.blocks.total) if getattr(res, "blocks", None) is not None else 0.0


def _length_mid(line: Any, th: Thickness, kind: str) -> float:
    """Laid band length at mid-thickness (mm): the line's length with each step stretched circumferentially
    by (r + t n_r/2)/r (t, n_r of the layer's thickness ``th`` where the step lies), dwell arcs on pins
    beyond an open end (off the part) left out.  A line kept as circuit 0 + rule (a big program) is
    read piece by piece (:func:`engine.periodic.row_chunks`; the stretch of a repeating circuit made
    once): the same numbers, summed in the same order."""

    def stretch_of(z: FloatArray, beta: FloatArray, r: FloatArray) -> FloatArray:
        t_line = np.interp(z, th.z, th.t)
        nr_line = np.interp(z, th.z, th.nr)
        return 1.0 + 0.5 * t_line * nr_line * np.sin(beta) ** 2 / np.maximum(r, 1e-300)

    open_ends = [line.z_turn[side] for side in (0, 1) if kind != "hoop" and line.end_kinds[side] == "open"]

    def steps(s: FloatArray, stretch: FloatArray, dwell: Any, z: Any) -> FloatArray:
        ds = np.diff(s)
        on_part = np.ones(ds.size, dtype=bool)
        for zt in open_ends:
            on_part &= ~(dwell()[1:] & (np.abs(z()[1:] - zt) <= 1e-6 * max(1.0, abs(zt))))
        return (ds * 0.5 * (stretch[1:] + stretch[:-1]))[on_part]

    if not _kept_as_rule(line):
        return float(np.sum(steps(line.s, stretch_of(line.z, line.beta, line.r), lambda: line.dwell,
                                  lambda: line.z)))
    from engine.periodic import field_rows, row_chunks, tile_base, tile_rows

    n = line.n_points
    bases = [tile_base(line, f) for f in ("z", "beta", "r")]
    m = int(line.points_per_circuit)
    st0 = stretch_of(*bases) if all(b_ is not None and b_.shape[0] == m + 1 for b_ in bases) else None
    parts = []
    for a, b in row_chunks(n):
        if st0 is not None:
            st = tile_rows(st0, m, n, a, b)
        else:
            st = stretch_of(field_rows(line, "z", a, b), field_rows(line, "beta", a, b), field_rows(line, "r", a, b))
        parts.append(steps(field_rows(line, "s", a, b), st, lambda a=a, b=b: field_rows(line, "dwell", a, b),
                           lambda a=a, b=b: field_rows(line, "z", a, b)))
    return float(np.sum(np.concatenate(parts)))


def _pole_thickness(th: Thickness, b: float) -> list[float]:
    """Largest thickness (mm) within two band widths of meridian from each end of the surface (the build-up at
    a polar opening; on an open end the thickness at the end)."""
    m = th.m
    near_l = m <= m[0] + 2.0 * b
    near_r = m >= m[-1] - 2.0 * b
    return [float(th.t[near_l].max()), float(th.t[near_r].max())]


def _sorted(x: FloatArray, y: FloatArray) -> tuple[FloatArray, FloatArray]:
    o = np.argsort(x)
    return x[o], y[o]


def _join(res: LaminateResult, machine: Any, fns: dict[int, tuple[Any, Any]] | None = None,
          side: bool = False) -> LaminateResult:
    """Join the layers' blocks with transition moves into one program and render it (``fns``: the laminate
    surfaces' distance functions already built, see :func:`transition_clearance`).  ``side``: the
    transitions' clearance may be checked in a forked process while this one renders the NC text (a
    command line's run whose layers ran side by side; the same answer, see :func:`_fork_call`)."""
    from engine.blocks import Blocks
    from engine.machine_setup import controller_for
    from engine.post import get_post

    job = res.job
    machine, shifts, placement = _common_placement(res, machine)
    mi = machine.axis_index("mandrel")
    qs: list[FloatArray] = []
    times: list[FloatArray] = []
    t17: list[FloatArray] = []
    errs: list[FloatArray] = []
    sections: list[tuple[int, str]] = []
    transitions: list[tuple[int, int, float]] = []
    nb = 0
    last_q: FloatArray | None = None
    pending_skip = 0.0
    new_layers: list[LayerResult] = []
    prev_index: int | None = None
    for lr in res.layers:
        if lr.result is None:  # skip layer: a mandrel reposition folded into the next transition
            pending_skip += float(lr.figures.get("skip_deg", 0.0))
            new_layers.append(lr)
            continue
        b = lr.result.blocks
        q = np.array(b.q, dtype=float)
        if lr.index in shifts:
            q[:, shifts[lr.index][0]] += shifts[lr.index][1]
        shift = 0.0
        if mi is not None and last_q is not None:
            ax = machine.axes[mi]
            fwd = 1.0 if (q[-1, mi] - q[0, mi]) >= 0 else -1.0
            lead_out = float(job.layers[prev_index].lead_out_deg) if prev_index is not None else 0.0
            target = last_q[mi] + fwd * _deg_to_units(ax, pending_skip + lead_out)
            shift = target - q[0, mi]
            q[:, mi] += shift
        if last_q is not None:
            tq, tt = transition_blocks(machine, last_q, q[0], job.payout.clearance_mm,
                                       lead_in=_lead_in(machine, q, float(job.layers[lr.index].lead_in_mm)))
            sections.append((nb, f"transition to layer {lr.index + 1}: {tt.sum():.3f} s"))
            transitions.append((nb, int(tt.size), float(tt.sum())))
            qs.append(tq[1:])
            times.append(tt)
            t17.append(tt)
            errs.append(np.zeros(tt.size))
            nb += tt.size
        f = lr.figures
        block0, t_start = nb, float(sum(float(np.sum(x)) for x in times))
        qr, tr, added = _ramp_layer(machine, q, np.asarray(b.time, dtype=float))
        tr = limit_from_rest(machine, qr, tr)
        sections.append((nb, f"layer {lr.index + 1} {lr.name} ({lr.kind}): {float(tr.sum()):.3f} s, "
                             f"fibre {f['fibre_length_m']:.3f} m"))
        qs.append(qr if last_q is None else qr[1:])
        times.append(tr)
        t17_l = np.concatenate([np.full(added, np.nan), np.asarray(b.t17, dtype=float),
                                np.full(tr.size - b.n - added, np.nan)])
        t17.append(np.where(np.isnan(t17_l), tr, t17_l))  # the ramp pieces: their own times
        err = np.asarray(b.max_error, dtype=float)
        errs.append(np.concatenate([np.full(added, err[0]), err, np.full(tr.size - b.n - added, err[-1])]))
        block0 += added
        nb += tr.size
        q = qr
        last_q = q[-1]
        prev_index = lr.index
        pending_skip = 0.0
        figs = {**lr.figures, "time_s": float(tr.sum()), "ramps_s": float(tr.sum() - float(np.sum(b.time)))}
        new_layers.append(replace(lr, mandrel_shift=shift, block0=block0, t0=t_start, figures=figs))
    if not qs:
        raise InputError("the laminate has no layer that lays fibre (only skip layers)", file=res.job_path,
                         field="layer")
    q_all = np.concatenate(qs)
    time_all = np.concatenate(times)
    blocks = Blocks(
        machine=machine.name, axis_names=machine.axis_names, index=np.arange(q_all.shape[0]), q=q_all,
        delta=np.diff(q_all, axis=0), t17=np.concatenate(t17), time=time_all, alpha=np.ones(time_all.size),
        max_error=np.concatenate(errs), tol_mm=job.post.tolerance_mm, cyclic=False,
        total_t17=float(np.concatenate(t17).sum()), total_start=float(time_all.sum()),
        sections=tuple(sections))
    post = get_post(job.post.post)
    # the profile that addresses the machine's axes (e.g. linuxcnc_robot for the robot cell's E1, J1..J6),
    # as the single-line NC stage chooses it
    profile = controller_for(post.name, job.post.controller, machine)
    setup = job.machine.setup
    helper = None
    import functools

    first = set(range((len(transitions) + 1) // 2))
    if side and setup is not None and any(n >= 1 for _b, n, _t in transitions):
        # the transitions' clearance (its branch and bound over the free fibre's tail is most of the join):
        # the first half of them in a forked process while this one renders the text, then the rest
        helper = _fork_call(functools.partial(_transition_raw, machine, blocks, new_layers, transitions,
                                              res.mandrel, setup, True, fns, first))
    clearance = None
    try:
        text = post.render(blocks, machine, profile)
        if helper is not None:
            rest = _transition_raw(machine, blocks, new_layers, transitions, res.mandrel, setup, True, fns,
                                   set(range(len(transitions))) - first)
            part = helper.result()
            if part is not None:
                clearance = part.merged(rest)
    finally:
        if helper is not None:
            helper.close()
    over: list[float] = []
    problems = _joined_problems(machine, blocks, text, new_layers, transitions, placement, res.mandrel,
                                setup, depths=over, fns=fns, clearance=clearance)
    return replace(res, layers=tuple(new_layers), machine=machine, blocks=blocks, nc_text=text,
                   post_name=post.name, extension=post.extension, transitions=tuple(transitions),
                   transition_fibre_over_mm=tuple(over),
                   sections=tuple(sections), placement=placement, program_problems=tuple(problems))


class _JoinedLocator:
    """Block of the joined program -> NC line, time and the layer (or transition) it belongs to."""

    def __init__(self, blocks: Any, text: str, layers: list[LayerResult], transitions: list[tuple[int, int, float]]
                 ) -> None:
        self._text = text
        self._lines: np.ndarray | None = None
        self.start = np.concatenate(([0.0], np.cumsum(np.asarray(blocks.time, dtype=float))))
        # (first block, label) of every section in program order: layer, transition, layer, ...
        laid = [lr for lr in layers if lr.result is not None]
        spans: list[tuple[int, str]] = [(0, str(laid[0].index + 1))] if laid else []
        for j, (b0, n, _t) in enumerate(transitions):
            nxt = str(laid[j + 1].index + 1) if j + 1 < len(laid) else "?"
            spans += [(b0, f"transition to layer {nxt}"), (b0 + n, nxt)]
        self.spans = sorted(spans)

    @property
    def lines(self) -> np.ndarray:
        """1-based NC line of every block of the joined program (read on first use)."""
        if self._lines is None:
            from engine.machine_setup import nc_move_lines

            self._lines = nc_move_lines(self._text)
        return self._lines

    def locate(self, point: int | None = None, block: int | None = None) -> dict[str, Any]:
        out: dict[str, Any] = {"layer": None, "circuit": None, "time_s": None, "nc_line": None, "block": block,
                               "point": point}
        if block is None:
            return out
        out["time_s"] = float(self.start[min(block, self.start.size - 1)])
        if block < self.lines.size:
            out["nc_line"] = int(self.lines[block])
        label = None
        for b0, name in self.spans:
            if b0 <= block:
                label = name
        out["layer"] = label
        return out


TRANSITION_SUBSTEPS = 16
"""Eye positions checked inside each transition block (the controller interpolates the axes linearly)."""


def _last_laid_point(machine: Any, q_end: FloatArray, layer: LayerResult) -> FloatArray | None:
    """The last laid point of ``layer`` (its contact at its last block) in the joined program's mandrel frame.

    The joined program may shift the layer's mandrel axis (and its placement): the layer's own eye at that
    point is turned about the axis (and moved along it) onto the eye that forward kinematics gives for the
    joined program's row ``q_end``; the contact is moved the same way."""
    from engine.kinematics import forward_kinematics

    r = layer.result
    if r is None or r.axes is None or r.blocks is None:
        return None
    from engine.periodic import field_take

    i = np.asarray(r.blocks.index)[-1:].astype(np.int64)   # one row (a big path's points stay rules)
    e_own = np.asarray(field_take(r.axes, "eye_xyz", i), dtype=float)[0]
    c_own = np.asarray(field_take(r.axes, "contact_xyz", i), dtype=float)[0]
    e_join = forward_kinematics(machine, np.asarray(q_end, dtype=float)[None, :], fibre=False)[0][0]
    turn = math.atan2(e_join[1], e_join[0]) - math.atan2(e_own[1], e_own[0])
    ct, st = math.cos(turn), math.sin(turn)
    return np.array([ct * c_own[0] - st * c_own[1], st * c_own[0] + ct * c_own[1],
                     c_own[2] + (e_join[2] - e_own[2])])


def transition_clearance(machine: Any, blocks: Any, layers: list[LayerResult],
                         transitions: list[tuple[int, int, float]], bare: Any, setup: Any,
                         depths: list[float] | None = None, fns: dict[int, tuple[Any, Any]] | None = None,
                         measured: _TransitionRaw | None = None) -> list[Any]:
    """The eye along every transition move against the laminate laid so far (the surface the next layer is
    wound on), the shafts, the chuck and the tailstock (of the bare mandrel), and the free fibre - from the
    last laid point of the layer before, which stays where it was laid, to the eye - against the shafts,
    the chuck and the tailstock (``setup.clearance_mm``; the fibre would catch on them): violations of kind
    ``clearance`` located by block of the joined program.  The eye is sampled at
    :data:`TRANSITION_SUBSTEPS` points of each block (axes interpolated linearly, as the controller moves
    them); the first and the last point of a transition are the layers' own end points, which the layers'
    own checks cover.

    Where the straight line from the last laid point to the eye would pass inside the laminate, the taut
    fibre is drawn over its surface instead (a helical layer ending at the pole and a hoop layer starting
    on the cylinder: the tail crosses the dome) - not a collision, but fibre laid outside the pattern: with
    ``depths`` a list, the deepest such pass of each transition (mm, 0 when the fibre stays free; by branch
    and bound along the line, :func:`engine.machine_setup.capsule_min_distance`, within 0.05 mm) is
    appended to it.

    ``fns`` (optional): the surfaces' distance functions, ``{id(surface): (surface, mandrel_distance_fn(surface))}``,
    as :func:`prebuild_distance` makes them (the laminate run builds them while it waits for its layers);
    the missing ones are built here and added to it.  ``measured``: these measures already made
    (:func:`_transition_raw` of every transition, the depths included where ``depths`` is given)."""
    raw = measured if measured is not None else _transition_raw(machine, blocks, layers, transitions, bare, setup,
                                                                depths is not None, fns)
    if depths is not None:
        depths.extend(float(d) for d in raw.depths)
    return raw.violations()


@dataclass
class _TransitionRaw:
    """What :func:`transition_clearance` measured, before it is told as violations: the smallest gaps per block
    of the joined program (inf where not measured), the tail depth of each transition (None: not measured)."""

    d_surf: FloatArray
    d_sup: dict[str, FloatArray]
    f_sup: dict[str, FloatArray]
    depths: list[float | None]
    gap: float
    f_gap: float

    def merged(self, other: _TransitionRaw) -> _TransitionRaw:
        """The measures of two disjoint sets of transitions together (each block is one transition's: the
        smaller of the two values is the one measured)."""
        return _TransitionRaw(np.minimum(self.d_surf, other.d_surf),
                              {k: np.minimum(v, other.d_sup[k]) for k, v in self.d_sup.items()},
                              {k: np.minimum(v, other.f_sup[k]) for k, v in self.f_sup.items()},
                              [a if a is not None else b for a, b in zip(self.depths, other.depths)],
                              self.gap, self.f_gap)

    def violations(self) -> list[Any]:
        from engine.kinematics import violations_from_mask

        gap, f_gap = self.gap, self.f_gap
        out = violations_from_mask("clearance", None, self.d_surf < gap - 1e-6, self.d_surf, gap, " mm",
                                   where="block", what="gap between the eye and the laminate on a transition")
        for name, d in self.d_sup.items():
            out += violations_from_mask("clearance", None, d < gap - 1e-6, d, gap, " mm", where="block",
                                        what=f"gap between the eye and the {name} on a transition")
        for name, d in self.f_sup.items():
            out += violations_from_mask("clearance", None, d < f_gap - 1e-6, d, f_gap, " mm", where="block",
                                        what=f"gap between the free fibre and the {name} on a transition")
        return out


def _transition_raw(machine: Any, blocks: Any, layers: list[LayerResult], transitions: list[tuple[int, int, float]],
                    bare: Any, setup: Any, with_depths: bool, fns: dict[int, tuple[Any, Any]] | None = None,
                    which: set[int] | None = None) -> _TransitionRaw:
    """:func:`transition_clearance`'s measures of the transitions ``which`` (all: None); the tail depths with
    ``with_depths``."""
    from engine.kinematics import forward_kinematics
    from engine.machine_setup import (
        _rect_distance,
        _segment_min_rho,
        capsule_min_distance,
        radial_prune,
        support_obstacles,
    )

    laid = [lr for lr in layers if lr.result is not None]
    gap = float(setup.clearance_mm) + float(getattr(setup, "head_radius_mm", 0.0))   # from the head's body
    q = np.asarray(blocks.q, dtype=float)
    nb = q.shape[0] - 1
    d_surf = np.full(nb, np.inf)
    d_sup = {ob.name: np.full(nb, np.inf) for ob in support_obstacles(bare, setup)}
    f_gap = float(setup.clearance_mm)
    f_sup = {name: np.full(nb, np.inf) for name in d_sup}
    u = (np.arange(TRANSITION_SUBSTEPS) + 1.0) / TRANSITION_SUBSTEPS     # inside and at the end of each block
    built = fns if fns is not None else {}

    def distance_to(surface: Any) -> Any:
        """The sampled distance function of a laminate surface, built once (a surface is the next layer's
        in one transition and the last laid layer's in the next); called with its bound each time."""
        prebuild_distance(surface, built)
        return built[id(surface)][1]
    depths: list[float | None] = []
    for j, (b0, n, _t) in enumerate(transitions):
        if which is not None and j not in which:
            depths.append(None)
            continue
        if j + 1 >= len(laid) or n < 1:
            depths.append(0.0)
            continue
        qq = q[b0: b0 + n + 1]
        dense = (qq[:-1, None, :] + u[None, :, None] * np.diff(qq, axis=0)[:, None, :]).reshape(-1, q.shape[1])
        blk = np.repeat(np.arange(b0, b0 + n), u.size)
        dense, blk = dense[:-1], blk[:-1]                # the next layer's first point is its own
        if dense.shape[0] == 0:
            depths.append(0.0)
            continue
        eye, _ = forward_kinematics(machine, dense, fibre=False)
        z, rho = eye[:, 2], np.hypot(eye[:, 0], eye[:, 1])
        dm = distance_to(laid[j + 1].surface)(z, rho, 2.0 * gap + 1.0)
        np.minimum.at(d_surf, blk, dm)
        for ob in support_obstacles(bare, setup):
            np.minimum.at(d_sup[ob.name], blk, _rect_distance(z, rho, ob))
        anchor = _last_laid_point(machine, q[b0], laid[j])
        if anchor is None:
            depths.append(0.0)
            continue
        if not with_depths:
            depths.append(0.0)
        else:
            v = anchor[None, :] - eye
            length = np.linalg.norm(v, axis=1)
            along = v / np.maximum(length, 1e-12)[:, None]
            # against the surface the last laid point lies on; dips within 0.1 mm of it are the sampled
            # surface's own roughness at the point
            fn = distance_to(laid[j].surface)
            dmin = capsule_min_distance(fn, eye, along, length, -0.1, prune=radial_prune(fn, eye, along, -0.1))
            depths.append(float(max(0.0, -float(dmin.min()))) if float(dmin.min()) < -0.1 else 0.0)
        a_rep = np.broadcast_to(anchor, eye.shape)
        for ob in support_obstacles(bare, setup):
            np.minimum.at(f_sup[ob.name], blk, _segment_min_rho(a_rep, eye, ob.z0, ob.z1) - ob.radius)
    return _TransitionRaw(d_surf, d_sup, f_sup, depths, gap, f_gap)


def prebuild_distance(surface: Any, fns: dict[int, tuple[Any, Any]]) -> None:
    """Add ``surface``'s sampled distance function (:func:`engine.machine_setup.mandrel_distance_fn`) to
    ``fns`` under ``id(surface)``, with the surface itself (so the id stays its own), unless it is there."""
    from engine.machine_setup import mandrel_distance_fn

    got = fns.get(id(surface))
    if got is None or got[0] is not surface:
        fns[id(surface)] = (surface, mandrel_distance_fn(surface))


def _joined_problems(machine: Any, blocks: Any, text: str, layers: list[LayerResult],
                     transitions: list[tuple[int, int, float]], placement: Any, bare: Any = None,
                     setup: Any = None, depths: list[float] | None = None,
                     fns: dict[int, tuple[Any, Any]] | None = None,
                     clearance: _TransitionRaw | None = None) -> list[str]:
    """What the joined program breaks beyond the layers' own checks: every block of it (the layers' speed
    ramps, the transitions, the common placement) against every position, speed and speed-jump limit,
    the eye's clearance along the transitions (with ``bare`` and ``setup``), grouped and located by NC line,
    time and layer or transition; a placement that does not fit says which would.  ``clearance``: the
    transitions' clearance already measured (:func:`_transition_raw` of all of them, with their depths)."""
    from engine.blocks import check_blocks
    from engine.machine_setup import group_violations

    own = {(v.kind, v.axis) for lr in layers if lr.result is not None for v in lr.result.violations
           if v.kind != "position"}
    viol = [v for v in check_blocks(machine, blocks) if v.kind == "position" or (v.kind, v.axis) not in own]
    if bare is not None and setup is not None:
        viol += transition_clearance(machine, blocks, layers, transitions, bare, setup, depths=depths, fns=fns,
                                     measured=clearance)
    out: list[str] = []
    if placement is not None and not placement.fits:
        out.append(placement.message())
    loc = _JoinedLocator(blocks, text, layers, transitions)
    out += [f"joined program, {g.message}" for g in group_violations(viol, loc)]
    return out


def _common_placement(res: LaminateResult, machine: Any) -> tuple[Any, dict[int, tuple[int, float]], Any]:
    """One mandrel placement for every layer: each layer was placed on its own (its carriage range centred
    in the travel); the joined program centres the union of the ranges instead and shifts each layer's
    carriage column by the difference of datums.  Returns (machine with the common datum,
    {layer index: (axis column, shift)}, Placement)."""
    from engine.machine_setup import Placement, carriage_index

    k = carriage_index(machine)
    laid = [lr for lr in res.layers if lr.result is not None and lr.result.placement is not None]
    if k is None or not laid:
        return machine, {}, None
    ps = [lr.result.placement for lr in laid]
    ax = machine.axes[k]
    lo, hi = float(ax.min), float(ax.max)
    rel_lo = min(p.q_min - p.z0 for p in ps)
    rel_hi = max(p.q_max - p.z0 for p in ps)
    finite = math.isfinite(lo) and math.isfinite(hi) and hi - lo < 1e11
    if any(p.mode == "fixed" for p in ps) or not finite:
        z0 = ps[0].z0
    else:
        z0 = round(0.5 * (lo + hi) - 0.5 * (rel_lo + rel_hi), 1)
    shifts = {lr.index: (k, z0 - lr.result.placement.z0) for lr in laid}
    q_min, q_max = z0 + rel_lo, z0 + rel_hi
    fit = (lo - rel_lo, hi - rel_hi) if finite and rel_hi - rel_lo <= hi - lo + 1e-9 else None
    placement = Placement(ax.name, ps[0].mode, z0, q_min, q_max, lo, hi, fit)
    axes = list(machine.axes)
    axes[k] = replace(ax, offset=z0)
    return replace(machine, axes=tuple(axes)), shifts, placement


@dataclass(frozen=True)
class LaidLine:
    """Every layer's winding line in the joined program's mandrel frame, one after the other (for the NC
    read-back): ``xyz``, ``tau`` (N,3), ``s`` (N,) laid length continued from layer to layer (mm), ``layer`` (N,)
    the job's layer index, ``z``."""

    xyz: FloatArray
    tau: FloatArray
    s: FloatArray
    z: FloatArray
    layer: NDArray[np.int64]


def laid_line(result: LaminateResult) -> LaidLine:
    """The layers' lines as the joined program lays them: each turned about the axis by the mandrel shift that
    made it continue from the layer before (``p_M = Rz(−θ) p_W``, so a shift Δθ turns the line by −Δθ)."""
    xyz, tau, s, z, lay = [], [], [], [], []
    s0 = 0.0
    mi = result.machine.axis_index("mandrel") if result.machine is not None else None
    for lr in result.layers:
        if lr.result is None:
            continue
        line = lr.result.line
        ang = 0.0
        if mi is not None and lr.mandrel_shift:
            ang = -lr.mandrel_shift / result.machine.axes[mi].scale
        c, sn = math.cos(ang), math.sin(ang)
        rot = np.array([[c, -sn, 0.0], [sn, c, 0.0], [0.0, 0.0, 1.0]])
        xyz.append(np.asarray(line.xyz) @ rot.T)
        tau.append(np.asarray(line.tau) @ rot.T)
        s.append(np.asarray(line.s) - float(line.s[0]) + s0)
        s0 = float(s[-1][-1])
        z.append(np.asarray(line.z))
        lay.append(np.full(len(line.z), lr.index, dtype=np.int64))
    return LaidLine(np.concatenate(xyz), np.concatenate(tau), np.concatenate(s), np.concatenate(z),
                    np.concatenate(lay))


def ramp_from_rest(machine: Any, q0: FloatArray, q1: FloatArray, t: float) -> tuple[FloatArray, FloatArray]:
    """Split the straight block q0 -> q1 (duration ``t`` s) so that it starts from rest: sub-blocks whose speed
    rises in steps that keep every axis's ``max_jump`` (the first step from rest included) and ``max_accel``,
    then the rest of the block at its own speed.  Same path (points on the segment), a little more time.

    Returns (q (k+1, n_axes) with q[0] = q0 and q[-1] = q1, times (k,)).
    """
    q0 = np.asarray(q0, dtype=float)
    q1 = np.asarray(q1, dtype=float)
    d = np.abs(q1 - q0)
    v = d / t
    J = machine.limits("max_jump")
    A = machine.limits("max_accel")
    mv = v > 0
    if not mv.any() or np.all(v[mv] <= 0.5 * J[mv] * (1 - 1e-9)):
        return np.stack([q0, q1]), np.array([t])
    # speed step as a fraction of the block speed: at most half a max_jump, so that a neighbour block running
    # the other way (a transition coming to rest) stays within max_jump of it
    dfrac = 0.45 * float(np.min(J[mv] / v[mv]))
    tau = float(np.max(dfrac * v[mv] / A[mv]))           # sub-block time that keeps max_accel for that step
    tau = max(tau, machine.min_block_time)
    fr, ts, frac = [], [], 0.0
    sp = dfrac
    while sp < 1.0 - 1e-12:
        step = sp * tau / t                               # share of the block covered at speed sp·v in tau
        if frac + step >= 1.0:
            break
        fr.append(frac + step)
        ts.append(tau)
        frac += step
        sp += dfrac
    rest = 1.0 - frac
    fracs = np.array([*fr, 1.0])
    times = np.array([*ts, rest * t / min(sp, 1.0)])
    q = q0[None, :] + np.concatenate([[0.0], fracs])[:, None] * (q1 - q0)[None, :]
    return q, times


def _scale_pass(v: FloatArray, t: FloatArray, J: FloatArray, A: FloatArray) -> FloatArray:
    """Speed factors α_i <= 1, block by block from rest, so that every axis's speed step between neighbouring
    blocks stays within min(max_jump, max_accel × mean block time); stops once the blocks keep their speed."""
    n = v.shape[0]
    alpha = np.ones(n)
    prev = np.zeros(v.shape[1])
    t_prev = 0.0
    for i in range(n):
        # from rest: half a max_jump (the block before may run the other way at up to half of it)
        lim = np.minimum(J, A * 0.5 * (t[i] + t_prev)) if t_prev > 0 else np.minimum(0.5 * J, A * t[i])
        hi = 1.0
        vi = v[i]
        for k in np.flatnonzero(np.abs(vi) > 1e-12):
            a = (prev[k] - lim[k]) / vi[k]
            b = (prev[k] + lim[k]) / vi[k]
            hi = min(hi, max(a, b))
        hi = max(hi, 1e-6)
        if hi >= 1.0 and np.all(np.abs(vi - prev) <= lim * (1 + 1e-9)):
            if i > 0 and alpha[i - 1] >= 1.0:
                break
        alpha[i] = min(1.0, hi)
        prev = alpha[i] * vi
        t_prev = t[i] / alpha[i]
    return alpha


def limit_from_rest(machine: Any, q: FloatArray, t: FloatArray) -> FloatArray:
    """Block times (s) of the program ``q`` (n+1 positions) slowed where needed so that it starts and ends at
    rest within every axis's ``max_jump`` and ``max_accel`` (a forward pass from the start and a backward pass
    from the end; the blocks between keep their times)."""
    t = np.asarray(t, dtype=float).copy()
    v = np.diff(np.asarray(q, dtype=float), axis=0) / t[:, None]
    J, A = machine.limits("max_jump"), machine.limits("max_accel")
    a_f = _scale_pass(v, t, J, A)
    t = t / a_f
    v = np.diff(np.asarray(q, dtype=float), axis=0) / t[:, None]
    a_b = _scale_pass(v[::-1], t[::-1], J, A)[::-1]
    return t / a_b


def _ramp_layer(machine: Any, q: FloatArray, t: FloatArray) -> tuple[FloatArray, FloatArray, int]:
    """A layer's blocks made to start and end at rest (its own law may start and end at cruise speed: a
    single-line program repeats its circuits).  Returns (q, time, blocks added before the first original)."""
    q = np.asarray(q, dtype=float)
    t = np.asarray(t, dtype=float)
    head_q, head_t = ramp_from_rest(machine, q[0], q[1], float(t[0]))
    if q.shape[0] == 2:  # one block: ramp up, then ramp down its last part
        tail_q, tail_t = ramp_from_rest(machine, head_q[-1], head_q[-2], float(head_t[-1]))
        qq = np.concatenate([head_q[:-1], tail_q[::-1][1:]])
        tt = np.concatenate([head_t[:-1], tail_t[::-1]])
        return qq, tt, head_t.size - 1
    tail_q, tail_t = ramp_from_rest(machine, q[-1], q[-2], float(t[-1]))
    qq = np.concatenate([head_q, q[2:-1], tail_q[::-1][1:]])
    tt = np.concatenate([head_t, t[1:-1], tail_t[::-1]])
    return qq, tt, head_t.size - 1


def _lead_in(machine: Any, q: FloatArray, lead_in_mm: float) -> FloatArray | None:
    """The position ``lead_in_mm`` back along the carriage from the layer's first point (None when 0)."""
    ci = machine.axis_index("carriage")
    if ci is None or lead_in_mm <= 0:
        return None
    ax = machine.axes[ci]
    k = min(len(q) - 1, 50)
    d = float(np.sign(q[k, ci] - q[0, ci])) or 1.0
    p = np.array(q[0], dtype=float)
    p[ci] = float(np.clip(p[ci] - d * abs(ax.scale) * lead_in_mm, ax.min, ax.max))
    return p


def _deg_to_units(ax: Any, deg: float) -> float:
    """A mandrel rotation of ``deg`` degrees in the axis's controller units (magnitude)."""
    return abs(ax.scale) * math.radians(deg)


def laminate_refusals(result: LaminateResult) -> list[str]:
    """Why the joined program must not be written (each naming its layer): machine-limit violations, and
    per layer what ``winder trajectory`` / ``winder payout`` / ``winder layup`` report as failing (the band
    slips or bridges, the eye path is infeasible, as :func:`engine.pipeline.process_refusals`); empty when it
    may be written."""
    from engine.pipeline import _slip_lambda

    out: list[str] = [g.message for g in result.violation_groups()] + list(result.program_problems)
    for lr in result.layers:
        if lr.result is None:
            continue
        line = lr.result.line
        for z0, z1 in getattr(line, "slips", ()) or ():
            out.append(f"layer {lr.index + 1} ({lr.name}): the band slips "
                       f"(|λ| up to {_slip_lambda(line, z0, z1):.4g} > "
                       f"μ = {line.mu:g}) for z in [{z0:.2f}, {z1:.2f}] mm")
        # as a single line's run refuses them (winder run): a bridging band, an infeasible eye path
        for z0, z1 in getattr(line, "bridging", ()) or ():
            out.append(f"layer {lr.index + 1} ({lr.name}): the band bridges (does not lie on the surface) for z in "
                       f"[{z0:.2f}, {z1:.2f}] mm")
        eye = lr.result.eye_circuit
        if eye is not None and not eye.feasible:
            from engine.pipeline import _payout_warnings

            out += [f"layer {lr.index + 1} ({lr.name}): {w}" for w in _payout_warnings(eye)
                    if not (lr.kind == "hoop" and "not cyclic" in w)]  # a hoop layer is no repeated circuit
    return out


def write_laminate(result: LaminateResult, path: str | Path, force: bool = False) -> Path:
    """Write the joined program atomically (:func:`engine.post.write_nc`): refused (InfeasibleError) when a
    layer violates a machine limit or its line slips (:func:`laminate_refusals`), unless ``force``."""
    from engine.post import write_nc

    if result.nc_text is None:
        raise InputError("no NC program was produced (the laminate stopped before the NC stage)")
    b = result.blocks
    t = np.asarray(b.time, dtype=float)
    bad = np.flatnonzero(~(np.isfinite(t) & (t > 0)))
    if bad.size or not np.all(np.isfinite(np.asarray(b.q, dtype=float))):
        i = int(bad[0]) if bad.size else 0
        raise InputError(f"not written: {bad.size} block(s) have a non-finite or zero duration (block {i}: "
                         f"{t[i]!r} s), which would be an infinite or zero feed", file=path,
                         field="post.min_block_time_s")
    return write_nc(path, result.nc_text, [_Msg(m) for m in laminate_refusals(result)], force=force)


@dataclass(frozen=True)
class _Msg:
    message: str


def thickness_table(result: LaminateResult) -> tuple[list[str], list[list[float]]]:
    """Rows (z, r) of every layer boundary for ``--thickness CSV``: columns ``z_bare, r_bare, z_1, r_1, ...``
    on the bare mandrel's meridian grid (each boundary along its own surface's grid)."""
    cols = ["z_0_mm", "r_0_mm"]
    data: list[FloatArray] = []
    m, z, r, _ = meridian_grid(result.mandrel, THICKNESS_GRID)
    data += [z, r]
    for lr in result.layers:
        if lr.thickness is None:
            continue
        cols += [f"z_{lr.index + 1}_mm", f"r_{lr.index + 1}_mm"]
        data += [lr.thickness.z_out, lr.thickness.r_out]
    n = max(len(d) for d in data)
    rows = []
    for k in range(n):
        rows.append([float(d[k]) if k < len(d) else float("nan") for d in data])
    return cols, rows

