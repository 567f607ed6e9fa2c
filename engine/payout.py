"""Payout-eye trajectory and the minimal-range pull-speed law (MATH.md §A3, equations (7)–(15)).

Every point of the winding line (contact point ``r`` on the mandrel, unit tangent ``τ`` in the
sense of travel) maps to the fibre exit point (the payout eye) at the free-fibre length ``l``::

    R = r + l·τ                                                                  (7)
    τ = dir·(cos β / sqrt(1 + r'²))·(r'·e_ρ + k) + sin β·e_v                     (9)

with ``dir = ±1`` the sense of travel along z (the seed writes the ``dir = +1`` pass).  In the
plane normal to the axis the eye sits at ``d·e_ρ + l·sin β·e_v``, so (10) becomes::

    Z = z + l·b,   d = r + l·a,   R = sqrt(d² + l² sin² β),   V = v + atan2(l sin β, d)
    a = dir·r'·cos β / sqrt(1 + r'²),   b = dir·cos β / sqrt(1 + r'²)

(``atan2`` equals the seed's ``arccos(d/R)`` for sin β > 0 and stays valid at every β).

A *law* fixes ``l(x)`` over the process parameter ``x`` (laid length ``s`` by default, or the
twist ``v``).  Geometric laws (11) solve ``f(Z(l), R(l)) = 0`` point by point (``parallel``,
``equidistant``, ``equal-tangent``, ``curve``).  The technological law ``min-range`` solves (13)–(15)
in sequence on a grid of ``x``: maximise the smallest pull speed ``u = dλ/dx`` with
``λ = s + l − k·R`` (12), then minimise the largest subject to that floor, then minimise the jerk
functional ``∫(u − U)² dx`` inside the band, always subject to cyclicity ``l(x_n) = l(x_k)``, no sag
``d(s + l)/dx >= 0``, no reverse rotation ``dV/dx >= 0`` and the envelope ``l_min(x) <= l <= l_max(x)``
(clearance from the mandrel, reachable workspace, ``free_length_max``).

The pull speed is made exactly linear by optimising over ``μ = l − k·R(l)`` instead of ``l``:
``μ(l)`` is strictly increasing (``dμ/dl = 1 − k·dR/dl >= 1 − |τ_⊥| > 0``) with a closed-form
inverse, so the bounds map exactly and ``u`` is a linear function of ``μ``.  The two constraints
that are then nonlinear (no sag for k = 1, no reverse rotation) are handled by a cutting-plane
loop: rows are added where the exact constraint is violated or nearly active, re-linearised at
each solution, until the exact (nonlinear) check passes.  Default solver (``solver="fast"``): (13)/(14)
by bisection on the u bounds with an exact monotone interval-propagation feasibility test (the no-sag
and rotation bounds enter exactly), (15) by an interior-point QP with O(N) cyclic tridiagonal Newton
systems; the HiGHS formulations are the reference and the fallback.  LPs: ``scipy.optimize.linprog`` (HiGHS);
QP: HiGHS through ``highspy`` or, if that is not installed, the HiGHS build vendored in SciPy
(``scipy.optimize._highspy``); ``trust-constr`` only as a last resort.  See docs/payout.md.

Units: mm, rad.  ``u`` is dimensionless for ``x = s`` and mm/rad for ``x = v``.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from engine.errors import InfeasibleError, InputError
from engine.state import State, SubState, check_cancel

FloatArray = NDArray[np.float64]

GEOMETRIC_LAWS = ("parallel", "equidistant", "equal-tangent", "curve")
LAWS = (*GEOMETRIC_LAWS, "min-range")

_SCAN = 97  # samples of l when bracketing roots / envelope edges
_BISECT = 36  # bisection steps after bracketing (interval / 2**36)
_ENV_CHUNK = 256  # grid points per chunk of the envelope scan (a cancellation poll between chunks)
CHECK_TOL = 1e-6  # tolerance of the exact constraint check (mm, rad, or speed units)
_QP_LOG = False
_LP_METHOD = "highs"
_QP_TIME_LIMIT = 120.0  # s; beyond it the jerk stage keeps the (14) answer and says so


# ------------------------------------------------------------------------------------------------
# Input: the winding line (duck-typed)
# ------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class ContactLine:
    """The minimal winding-line data the payout stage needs (per point, in travel order).

    Attributes
    ----------
    z, r, dr : mm, mm, -
        Axial position, radius and generatrix slope r'(z) at the contact point.
    v : rad
        Twist angle, non-decreasing.
    beta : rad
        Winding angle to the meridian, in [0, π/2].
    direction : -
        Sense of travel along z (+1 or -1) per point.
    s : mm
        Laid length, increasing.
    circuit : -
        Circuit number per point (optional; all zeros if absent).
    """

    z: FloatArray
    r: FloatArray
    dr: FloatArray
    v: FloatArray
    beta: FloatArray
    direction: FloatArray
    s: FloatArray
    circuit: NDArray[np.int64] | None = None

    @classmethod
    def from_line(cls, line: Any) -> ContactLine:
        """Take the fields from any object with ``z, r, dr, v, beta, direction, s`` (e.g. WindingLine)."""
        if isinstance(line, ContactLine):
            line.validate()
            return line
        try:
            z = np.asarray(line.z, dtype=float).ravel()
            arrs = {k: np.asarray(getattr(line, k), dtype=float) for k in ("r", "dr", "v", "beta", "s")}
            direction = np.asarray(line.direction, dtype=float)
        except AttributeError as exc:
            raise InputError(f"the winding line lacks a field the payout stage needs: {exc}") from None
        n = z.size
        out: dict[str, Any] = {"z": z}
        for k, a in arrs.items():
            out[k] = np.broadcast_to(a, (n,)).astype(float).copy()
        out["direction"] = np.broadcast_to(np.sign(direction), (n,)).astype(float).copy()
        circ = getattr(line, "circuit", None)
        out["circuit"] = None if circ is None else np.broadcast_to(np.asarray(circ), (n,)).astype(np.int64).copy()
        cl = cls(**out)
        cl.validate()
        return cl

    def validate(self) -> None:
        """Check shapes and ranges; raise InputError naming the offending point."""
        n = self.z.size
        if n < 3:
            raise InputError(f"the winding line has {n} points; the payout stage needs at least 3")
        for name in ("z", "r", "dr", "v", "beta", "direction", "s"):
            a = getattr(self, name)
            if a.shape != (n,):
                raise InputError(f"winding line field '{name}' has shape {a.shape}, expected ({n},)")
            bad = np.flatnonzero(~np.isfinite(a))
            if bad.size:
                raise InputError(f"winding line field '{name}' is not finite at point {int(bad[0])}")
        if (self.r <= 0).any():
            i = int(np.flatnonzero(self.r <= 0)[0])
            raise InputError(f"contact radius r = {self.r[i]:g} mm <= 0 at point {i} (z = {self.z[i]:g} mm)")
        if (np.diff(self.s) < 0).any():
            i = int(np.flatnonzero(np.diff(self.s) < 0)[0]) + 1
            raise InputError(f"laid length s decreases at point {i} (s = {self.s[i]:g} mm)")
        if (np.diff(self.v) < -1e-12).any():
            i = int(np.flatnonzero(np.diff(self.v) < -1e-12)[0]) + 1
            raise InputError(f"twist angle v decreases at point {i} (v = {self.v[i]:g} rad)")
        if ((self.beta < -1e-12) | (self.beta > math.pi / 2 + 1e-12)).any():
            i = int(np.flatnonzero((self.beta < -1e-12) | (self.beta > math.pi / 2 + 1e-12))[0])
            raise InputError(f"winding angle β = {self.beta[i]:g} rad outside [0, π/2] at point {i}")

    def take(self, idx: ArrayLike) -> ContactLine:
        """The sub-line at point indices ``idx``."""
        i = np.asarray(idx)
        return ContactLine(
            self.z[i], self.r[i], self.dr[i], self.v[i], self.beta[i], self.direction[i], self.s[i],
            None if self.circuit is None else self.circuit[i],
        )

    def first_circuit(self) -> ContactLine:
        """The points of the first circuit (the whole line if there is no ``circuit`` field)."""
        if self.circuit is None:
            return self
        return self.take(np.flatnonzero(self.circuit == self.circuit[0]))


def tangent_components(r: FloatArray, dr: FloatArray, beta: FloatArray, direction: FloatArray
                       ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Components (a, b, c) of τ (9) on (e_ρ, k, e_v): radial, axial, circumferential (-)."""
    cb = np.cos(beta) / np.sqrt(1.0 + dr * dr)
    return direction * dr * cb, direction * cb, np.sin(beta)


@dataclass(frozen=True)
class _Geo:
    """Per-grid-point geometry."""

    line: ContactLine
    x: FloatArray
    a: FloatArray
    b: FloatArray
    c: FloatArray
    index: NDArray[np.int64]

    @property
    def n(self) -> int:
        return self.x.size

    def eye(self, l: FloatArray, rows: slice | NDArray[np.int64] = slice(None)
            ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """Z, R, V, d of the eye at free length l (broadcasts over trailing axes) at grid ``rows``."""
        L = self.line
        sh = (-1,) + (1,) * (np.ndim(l) - 1)
        z, r, v = L.z[rows].reshape(sh), L.r[rows].reshape(sh), L.v[rows].reshape(sh)
        a, b, c = self.a[rows].reshape(sh), self.b[rows].reshape(sh), self.c[rows].reshape(sh)
        d = r + a * l
        q = c * l
        return z + b * l, np.hypot(d, q), v + np.arctan2(q, d), d

    def mu(self, l: FloatArray, k: int) -> FloatArray:
        """μ = l − k·R(l) (mm)."""
        return l - k * self.eye(l)[1] if k else np.asarray(l, dtype=float).copy()

    def l_of_mu(self, mu: FloatArray, k: int) -> FloatArray:
        """Inverse of :meth:`mu` in closed form: b²l² − 2(μ + r·a)l + μ² − r² = 0."""
        if not k:
            return np.asarray(mu, dtype=float).copy()
        r, a, b = self.line.r, self.a, self.b
        B = mu + r * a
        b2 = b * b
        disc = np.sqrt(np.maximum(B * B - b2 * (mu * mu - r * r), 0.0))
        with np.errstate(divide="ignore", invalid="ignore"):  # called outside the _quiet_fp stages too
            neg = (mu * mu - r * r) / (B - disc)
            pos = (B + disc) / b2
        return np.where(B <= 0, neg, pos)

    def dR_dl(self, l: FloatArray) -> FloatArray:
        """dR/dl = (r·a + (1 − b²)·l)/R."""
        _, R, _, _ = self.eye(l)
        return (self.line.r * self.a + (1.0 - self.b**2) * l) / R

    def dV_dl(self, l: FloatArray) -> FloatArray:
        """dV/dl = c·r/R² (rad/mm)."""
        _, R, _, _ = self.eye(l)
        return self.c * self.line.r / (R * R)


def _parameter(line: ContactLine, parameter: str) -> FloatArray:
    if parameter == "s":
        return line.s.copy()
    if parameter == "v":
        return line.v.copy()
    raise InputError(f"process parameter must be 's' or 'v', got {parameter!r}", field="payout.parameter")


def _nearest(m: FloatArray, targets: FloatArray) -> NDArray[np.int64]:
    """Index of the entry of the non-decreasing ``m`` nearest to each target."""
    pos = np.clip(np.searchsorted(m, targets), 0, m.size - 1)
    prev = np.clip(pos - 1, 0, m.size - 1)
    return np.where(np.abs(m[prev] - targets) < np.abs(m[pos] - targets), prev, pos)


def _grid(line: ContactLine, parameter: str, n: int | None, extra: NDArray[np.int64] | None = None) -> _Geo:
    """Grid points: line points spread as evenly in x as the line allows (ends included), plus the line
    points ``extra`` (indices into the line: where the line-resolution check asked for them)."""
    x = _parameter(line, parameter)
    keep = np.concatenate([[True], np.diff(x) > 1e-12 * max(1.0, abs(x[-1] - x[0]))])
    idx = np.flatnonzero(keep)
    if n is not None and n < idx.size:
        xi = x[idx]
        pick = _nearest(xi, np.linspace(xi[0], xi[-1], n))
        if extra is not None and extra.size:
            pick = np.concatenate([pick, np.flatnonzero(np.isin(idx, extra))])
        idx = idx[np.unique(np.concatenate([[0], pick, [idx.size - 1]]))]
    if idx.size < 3:
        raise InputError(f"the process parameter '{parameter}' does not increase along the winding line")
    sub = line.take(idx)
    a, b, c = tangent_components(sub.r, sub.dr, sub.beta, sub.direction)
    return _Geo(sub, x[idx], a, b, c, idx.astype(np.int64))


# ------------------------------------------------------------------------------------------------
# Envelope: clearance from the mandrel and the reachable workspace
# ------------------------------------------------------------------------------------------------
@runtime_checkable
class Workspace(Protocol):
    """Where the eye can go: ``contains(Z, R)`` (mm arrays) -> bool array; ``describe()`` for messages."""

    def contains(self, Z: FloatArray, R: FloatArray) -> NDArray[np.bool_]: ...

    def describe(self) -> str: ...


@dataclass(frozen=True)
class BoxWorkspace:
    """Eye reach as a box in the Z–R plane (mm); ``None`` ends are unlimited."""

    z_range: tuple[float, float] | None = None
    r_range: tuple[float, float] | None = None

    def contains(self, Z: FloatArray, R: FloatArray) -> NDArray[np.bool_]:
        ok = np.ones(np.broadcast(Z, R).shape, dtype=bool)
        if self.z_range is not None:
            ok &= (Z >= self.z_range[0]) & (Z <= self.z_range[1])
        if self.r_range is not None:
            ok &= (R >= self.r_range[0]) & (R <= self.r_range[1])
        return ok

    def describe(self) -> str:
        parts = []
        if self.z_range is not None:
            parts.append(f"Z in [{self.z_range[0]:g}, {self.z_range[1]:g}] mm")
        if self.r_range is not None:
            parts.append(f"R in [{self.r_range[0]:g}, {self.r_range[1]:g}] mm")
        return "workspace " + (", ".join(parts) or "unlimited")


class _Contour:
    """Signed distance (mm) in the meridian plane from (Z, R) to the mandrel body.

    The body is bounded by the generatrix and its two end faces (z = z_min and z = z_max from the
    end radius down to the axis), so an eye beyond an end keeps its clearance from the end face too.
    The boundary is a dense polyline (chord error ~ h²κ/8, about 1e-4 mm here); the nearest vertex
    comes from a KD-tree's search (:class:`engine.nearest_jit.NearestVertex`: the same vertex, compiled) and
    the distance is refined on its two adjacent segments.  Negative inside.
    """

    def __init__(self, mandrel: Any, n: int = 6000) -> None:
        from engine.nearest_jit import NearestVertex

        z, r = mandrel.sample(n)
        self.z, self.r = np.asarray(z, float), np.asarray(r, float)
        self.r = np.maximum(self.r, 0.0)
        h = float(np.median(np.hypot(np.diff(self.z), np.diff(self.r))))
        faces = []
        for rf in (self.r[0], self.r[-1]):
            k = max(2, int(math.ceil(rf / max(h, 1e-9))) + 1) if rf > 0 else 0
            faces.append(np.linspace(0.0, rf, k)[:-1] if k else np.zeros(0))
        left, right = faces
        self.bz = np.concatenate([np.full(left.size, self.z[0]), self.z, np.full(right.size, self.z[-1])])
        self.br = np.concatenate([left, self.r, right[::-1]])
        self.tree = NearestVertex(self.bz, self.br)  # a cKDTree's answers, compiled search (engine.nearest_jit)
        self.z_min, self.z_max = float(self.z[0]), float(self.z[-1])
        self.r_max = float(self.r.max())
        self.edge_max = float(np.hypot(np.diff(self.bz), np.diff(self.br)).max())  # longest boundary segment

    def distance(self, Z: FloatArray, R: FloatArray, far: float | None = None) -> FloatArray:
        """Signed distance (mm); with ``far``, points provably at least ``far`` away (beyond the
        bounding box of the generatrix grown by ``far``) skip the KD-tree, and points outside the body
        provably more than ``far + 1`` away (no boundary vertex within ``far + 1`` + the longest boundary
        segment: every segment is farther than ``far + 1``) end the KD-tree's search early; both get +inf.
        Every value below ``far + 1`` (and every value inside the body) is the one without ``far``, bit for
        bit (the search finds the same nearest vertex)."""
        if far is not None:
            out = np.full(np.shape(Z), np.inf)
            near = (R < self.r_max + far) & (Z > self.z_min - far) & (Z < self.z_max + far)
            if near.any():
                out[near] = self._distance(np.asarray(Z)[near], np.asarray(R)[near],
                                           far + 1.0 + self.edge_max + 1e-6)
            return out
        return self._distance(Z, R, None)

    def _distance(self, Z: FloatArray, R: FloatArray, bound: float | None) -> FloatArray:
        """:meth:`distance` without the box; ``bound``: the nearest vertex is looked for within it only
        (points with none there get +inf outside the body; inside the body they are searched again)."""
        Zf, Rf = np.ravel(Z), np.ravel(R)
        P = np.column_stack([Zf, Rf])
        keep = None
        if bound is None:
            _, j = self.tree.query(P)
        else:
            d0, j = self.tree.query(P, distance_upper_bound=bound)
            none = np.isinf(d0)
            if none.any():
                inner = none & (Zf >= self.z_min) & (Zf <= self.z_max) & (Rf < np.interp(Zf, self.z, self.r))
                if inner.any():
                    j[inner] = self.tree.query(P[inner])[1]
                if not inner.all():
                    keep = ~(none & ~inner)
        if keep is None:
            return self._refine(Zf, Rf, j).reshape(np.shape(Z))
        out = np.full(Zf.shape, np.inf)
        if keep.any():
            out[keep] = self._refine(Zf[keep], Rf[keep], j[keep])
        return out.reshape(np.shape(Z))

    def _refine(self, Zf: FloatArray, Rf: FloatArray, j: NDArray[np.int64]) -> FloatArray:
        """Signed distance of the points (Zf, Rf) from the two boundary segments at their nearest vertices j."""
        best = np.full(Zf.shape, np.inf)
        m = self.bz.size
        for a in (j - 1, j):
            a = np.clip(a, 0, m - 2)
            z0, r0 = self.bz[a], self.br[a]
            ez, er = self.bz[a + 1] - z0, self.br[a + 1] - r0
            t = np.clip(((Zf - z0) * ez + (Rf - r0) * er) / (ez * ez + er * er), 0.0, 1.0)
            best = np.minimum(best, np.hypot(Zf - z0 - t * ez, Rf - r0 - t * er))
        inside = (Zf >= self.z_min) & (Zf <= self.z_max) & (Rf < np.interp(Zf, self.z, self.r))
        return np.where(inside, -best, best)


def _first_true_run(ok: NDArray[np.bool_]) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.bool_]]:
    """Per row: first True column, last column of that run, and whether any True exists."""
    has = ok.any(axis=1)
    first = np.argmax(ok, axis=1)
    m = ok.shape[1]
    after = np.arange(m)[None, :] >= first[:, None]
    stop = after & ~ok
    last = np.where(stop.any(axis=1), np.argmax(stop, axis=1) - 1, m - 1)
    return first, last, has


@dataclass(frozen=True)
class Envelope:
    """Pointwise admissible free lengths l_min(x) <= l <= l_max(x) (mm) and why."""

    l_min: FloatArray
    l_max: FloatArray
    clearance_mm: float
    free_length_max_mm: float
    workspace: str


def envelope(geo: _Geo, contour: _Contour, clearance: float, l_cap: float,
             workspace: Workspace | None = None, state: State | None = None) -> Envelope:
    """The first admissible interval of l at each grid point (scan + vectorised bisection).

    Admissible: the eye is at least ``clearance`` mm from the mandrel, inside ``workspace`` and
    ``l <= l_cap``.  Raises InfeasibleError naming the first point with no admissible l.  Polls
    ``state`` for cancellation between chunks of the scan and at every bisection step.
    """
    ls = np.linspace(0.0, l_cap, _SCAN)

    Zs = np.empty((geo.n, _SCAN))
    Rs = np.empty((geo.n, _SCAN))
    dist_s = np.empty((geo.n, _SCAN))
    for i0 in range(0, geo.n, _ENV_CHUNK):
        check_cancel(state)
        sl = slice(i0, min(i0 + _ENV_CHUNK, geo.n))
        Zs[sl], Rs[sl], _, _ = geo.eye(np.broadcast_to(ls, (sl.stop - sl.start, _SCAN)), sl)
        dist_s[sl] = contour.distance(Zs[sl], Rs[sl], far=max(clearance, 0.01))
    ok = dist_s >= clearance
    if workspace is not None:
        ok &= workspace.contains(Zs, Rs)
    # the free fibre (contact -> eye) must not pass through the mandrel: cut each row at the first
    # sample inside it; of the admissible runs before the cut take the farthest one (on a concave
    # mandrel a short pocket near the contact would make l jump between neighbouring points)
    inside = dist_s < -0.01
    inside[:, 0] = False
    cut = np.where(inside.any(axis=1), np.argmax(inside, axis=1), _SCAN)
    ok &= np.arange(_SCAN)[None, :] < cut[:, None]
    rev_first, _, has = _first_true_run(ok[:, ::-1])
    last = _SCAN - 1 - rev_first
    before = (np.arange(_SCAN)[None, :] < last[:, None]) & ~ok
    first = np.where(before.any(axis=1), _SCAN - 1 - np.argmax(before[:, ::-1], axis=1) + 1, 0)
    if not has.all():
        i = int(np.flatnonzero(~has)[0])
        Z, R, dist = Zs, Rs, dist_s
        clear_any = (dist[i] >= clearance).any()
        z, x = geo.line.z[i], geo.x[i]
        if not clear_any:
            raise InfeasibleError(
                f"clearance envelope too tight at x = {x:.6g} (z = {z:.6g} mm, grid point {i}): no free length "
                f"up to free_length_max_mm = {l_cap:g} mm keeps the eye {clearance:g} mm from the mandrel "
                f"(largest distance reached {dist[i].max():.4g} mm)", field="payout.clearance_mm")
        desc = workspace.describe() if workspace is not None else "workspace"
        zr = [(float(a), float(b)) for a, b in zip(Z[i][dist[i] >= clearance][:1], R[i][dist[i] >= clearance][:1])]
        raise InfeasibleError(
            f"{desc} too small at x = {x:.6g} (z = {z:.6g} mm, grid point {i}): the eye would need to be at "
            f"(Z, R) = ({zr[0][0]:.5g}, {zr[0][1]:.5g}) mm or farther along the tangent to clear the mandrel by "
            f"{clearance:g} mm", field="payout.workspace")
    lo = ls[first].copy()
    # refine the lower edge: (ls[first-1], ls[first]] where ok flips False -> True
    rows = np.flatnonzero(first > 0)  # only rows whose edge lies inside the scan are refined
    a, b = ls[first[rows] - 1], lo[rows]
    for _ in range(_BISECT):
        check_cancel(state)
        mid = 0.5 * (a + b)
        good = ok_at_rows(geo, contour, clearance, workspace, mid, rows)
        a, b = np.where(good, a, mid), np.where(good, mid, b)
    lo[rows] = b
    hi = ls[last].copy()
    rows = np.flatnonzero(last < _SCAN - 1)
    a, b = hi[rows], ls[last[rows] + 1]
    for _ in range(_BISECT):
        check_cancel(state)
        mid = 0.5 * (a + b)
        good = ok_at_rows(geo, contour, clearance, workspace, mid, rows)
        a, b = np.where(good, mid, a), np.where(good, b, mid)
    hi[rows] = a
    return Envelope(lo, hi, clearance, l_cap, workspace.describe() if workspace is not None else "unlimited")


def ok_at_rows(geo: _Geo, contour: _Contour, clearance: float, workspace: Workspace | None,
               l: FloatArray, rows: slice | NDArray[np.int64] = slice(None)) -> NDArray[np.bool_]:
    """Admissibility of one l per grid point (of the grid points ``rows``)."""
    Z, R, _, _ = geo.eye(l, rows)
    good = contour.distance(Z, R, far=max(clearance, 0.01)) >= clearance
    if workspace is not None:
        good &= workspace.contains(Z, R)
    return good


# ------------------------------------------------------------------------------------------------
# Result
# ------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class EyePath:
    """The payout-eye trajectory over the grid points of the winding line.

    Attributes
    ----------
    x : mm or rad
        Process parameter (``parameter``: laid length s or twist v) at the grid points.
    index : -
        Indices of the grid points in the input line.
    l : mm
        Free-fibre length.
    Z, R, V : mm, mm, rad
        Cylindrical eye coordinates (10).
    eye_xyz, contact_xyz : mm, (N, 3)
        Eye and contact point in the mandrel frame (axis = z).
    fibre_dir : -, (N, 3)
        Unit free-fibre direction contact → eye (= τ, (9)).
    s : mm
        Laid length at the grid points.
    lam_pulled : mm
        Pulled length λ = s + l − k·R (12).
    u : mm/mm or mm/rad, (N − 1,)
        Relative pull speed dλ/dx on each grid interval (at ``x_mid``).
    law, k, parameter :
        Law used, impregnation scheme (12), process parameter.
    l_min, l_max : mm
        Admissible free lengths (clearance / workspace / free_length_max envelope).
    report : dict
        u_min, u_max, u_range, U, jerk, l_min, l_max, feasible, constraints, active, solver.
    """

    x: FloatArray
    index: NDArray[np.int64]
    l: FloatArray
    Z: FloatArray
    R: FloatArray
    V: FloatArray
    eye_xyz: FloatArray
    contact_xyz: FloatArray
    fibre_dir: FloatArray
    s: FloatArray
    lam_pulled: FloatArray
    u: FloatArray
    x_mid: FloatArray
    law: str
    k: int
    parameter: str
    l_min: FloatArray | None = None
    l_max: FloatArray | None = None
    report: dict[str, Any] = field(default_factory=dict, compare=False)

    @property
    def u_min(self) -> float:
        return float(self.u.min())

    @property
    def u_max(self) -> float:
        return float(self.u.max())

    @property
    def u_range(self) -> float:
        return self.u_max - self.u_min

    @property
    def feasible(self) -> bool:
        return bool(self.report.get("feasible", True))

    def summary(self) -> dict[str, Any]:
        """JSON-able summary (no per-point arrays)."""
        return dict(self.report)


EYE_PATH_FIELDS: tuple[str, ...] = ("x", "index", "l", "Z", "R", "V", "eye_xyz", "contact_xyz", "fibre_dir", "s",
                                    "lam_pulled", "u", "x_mid")
"""Per-point fields of :class:`EyePath`; the eye path of a replicated program keeps some of them as
circuit 0 + rule (:class:`engine.periodic.CircuitArray`), materialised on first read."""


def _install_eye_fields() -> None:
    from engine.periodic import install_deferred_fields

    install_deferred_fields(EyePath, EYE_PATH_FIELDS)


_install_eye_fields()


def _build(geo: _Geo, l: FloatArray, k: int, parameter: str, law: str,
           env: Envelope | None = None) -> EyePath:
    L = geo.line
    l = np.asarray(l, dtype=float)
    Z, R, V, _ = geo.eye(l)
    cv, sv = np.cos(L.v), np.sin(L.v)
    a, b, c = geo.a, geo.b, geo.c
    contact = np.empty((cv.size, 3))
    np.multiply(L.r, cv, out=contact[:, 0])
    np.multiply(L.r, sv, out=contact[:, 1])
    contact[:, 2] = L.z
    # τ = a·e_ρ + b·k + c·e_v column by column, with e_ρ = (cos v, sin v, 0), e_v = (−sin v, cos v, 0):
    # the same products and sums in the same order as the (N, 3) broadcast, without its temporaries
    tau = np.empty((cv.size, 3))
    tau[:, 0] = a * cv + b * 0.0 + c * -sv
    tau[:, 1] = a * sv + b * 0.0 + c * cv
    tau[:, 2] = a * 0.0 + b * 1.0 + c * 0.0
    tau /= np.sqrt(tau[:, 0] * tau[:, 0] + tau[:, 1] * tau[:, 1] + tau[:, 2] * tau[:, 2])[:, None]
    eye = contact + l[:, None] * tau
    lam = L.s + l - k * R
    dx = np.diff(geo.x)
    u = np.diff(lam) / dx
    return EyePath(
        x=geo.x, index=geo.index, l=l, Z=Z, R=R, V=V, eye_xyz=eye, contact_xyz=contact, fibre_dir=tau,
        s=L.s, lam_pulled=lam, u=u, x_mid=0.5 * (geo.x[1:] + geo.x[:-1]), law=law, k=int(k), parameter=parameter,
        l_min=None if env is None else env.l_min, l_max=None if env is None else env.l_max,
    )


def eye_path(line: Any, l: ArrayLike, *, k: int = 1, parameter: str = "s", law: str = "given") -> EyePath:
    """The eye path for free lengths ``l`` (mm, one per line point or a scalar) — equations (7)–(10), (12)."""
    cl = ContactLine.from_line(line)
    geo = _grid(cl, parameter, None)
    lv = np.broadcast_to(np.asarray(l, dtype=float), (cl.z.size,))[geo.index]
    if (lv < 0).any():
        raise InputError(f"free length must be >= 0, got {lv.min():g} mm")
    return _build(geo, lv, k, parameter, law)


# ------------------------------------------------------------------------------------------------
# Constraint check and report
# ------------------------------------------------------------------------------------------------
def _runs(mask: NDArray[np.bool_], x: FloatArray, z: FloatArray, limit: int = 12) -> list[dict[str, float]]:
    idx = np.flatnonzero(mask)
    if not idx.size:
        return []
    breaks = np.flatnonzero(np.diff(idx) > 1)
    starts = np.concatenate([[idx[0]], idx[breaks + 1]])
    ends = np.concatenate([idx[breaks], [idx[-1]]])
    out = []
    for a, b in zip(starts[:limit], ends[:limit]):
        out.append({"x_from": float(x[a]), "x_to": float(x[b]), "z_from": float(z[a]), "z_to": float(z[b]),
                    "points": int(b - a + 1)})
    return out


def _report(geo: _Geo, eye: EyePath, env: Envelope | None, u_floor: float, tol: float = CHECK_TOL,
            active_tol: float | None = None, extra: dict[str, Any] | None = None) -> dict[str, Any]:
    """Exact (nonlinear) check of every constraint; where each is violated and where active."""
    L = geo.line
    x, z = geo.x, L.z
    xm = 0.5 * (x[1:] + x[:-1])
    zm = 0.5 * (z[1:] + z[:-1])
    dx = np.diff(x)
    atol = active_tol if active_tol is not None else 1e-6
    checks: dict[str, tuple[FloatArray, FloatArray, FloatArray]] = {}  # name -> (slack, x, z)
    if env is not None:
        checks["clearance"] = (eye.l - env.l_min, x, z)
        checks["workspace"] = (env.l_max - eye.l, x, z)
    sag = np.diff(L.s + eye.l) / dx
    checks["no_sag"] = (sag, xm, zm)
    checks["no_reverse_rotation"] = (np.diff(eye.V) / dx, xm, zm)
    checks["u_floor"] = (eye.u - u_floor, xm, zm)
    cyc = abs(float(eye.l[-1] - eye.l[0]))
    constraints: dict[str, Any] = {}
    feasible = cyc <= tol
    for name, (slack, xs, zs) in checks.items():
        viol = slack < -tol
        feasible &= not viol.any()
        worst = int(np.argmin(slack))
        constraints[name] = {
            "ok": not bool(viol.any()),
            "min_slack": float(slack[worst]),
            "at_x": float(xs[worst]),
            "at_z": float(zs[worst]),
            "violated": _runs(viol, xs, zs),
        }
    constraints["cyclicity"] = {"ok": cyc <= tol, "l_end_minus_l_start": float(eye.l[-1] - eye.l[0])}
    u = eye.u
    U = float((eye.lam_pulled[-1] - eye.lam_pulled[0]) / (x[-1] - x[0]))
    active = {}
    for name, (slack, xs, zs) in checks.items():
        if name == "u_floor":
            continue
        runs = _runs(slack <= atol, xs, zs)
        if runs:
            active[name] = runs
    umin, umax = float(u.min()), float(u.max())
    scale = max(1.0, abs(umax), abs(umin))
    active["u_at_min"] = _runs(u <= umin + 1e-6 * scale, xm, zm)
    active["u_at_max"] = _runs(u >= umax - 1e-6 * scale, xm, zm)
    rep = {
        "law": eye.law,
        "k": eye.k,
        "parameter": eye.parameter,
        "points": int(x.size),
        "u_min": umin,
        "u_max": umax,
        "u_range": umax - umin,
        "U": U,
        "jerk": float(np.sum((u - U) ** 2 * dx)),
        "l_min": float(eye.l.min()),
        "l_max": float(eye.l.max()),
        "R_min": float(eye.R.min()),
        "R_max": float(eye.R.max()),
        "Z_min": float(eye.Z.min()),
        "Z_max": float(eye.Z.max()),
        "feasible": bool(feasible),
        "constraints": constraints,
        "active": active,
    }
    if env is not None:
        rep["envelope"] = {"clearance_mm": env.clearance_mm, "free_length_max_mm": env.free_length_max_mm,
                           "workspace": env.workspace, "l_lower_max": float(env.l_min.max()),
                           "l_upper_min": float(env.l_max.min())}
    if extra:
        rep.update(extra)
    return rep


# ------------------------------------------------------------------------------------------------
# Geometric laws (11)
# ------------------------------------------------------------------------------------------------
def _first_root(geo: _Geo, f: Callable[[FloatArray, FloatArray], FloatArray], l_cap: float, law: str) -> FloatArray:
    """Smallest l in (0, l_cap] with f(Z(l), R(l)) = 0 at every grid point (scan + bisection)."""
    ls = np.linspace(0.0, l_cap, _SCAN)
    L = np.broadcast_to(ls, (geo.n, _SCAN))
    Z, R, _, _ = geo.eye(L)
    F = np.asarray(f(Z, R), dtype=float)
    sign = np.sign(F)
    zero = sign == 0
    zero[:, 0] = False
    change = (sign[:, 1:] * sign[:, :-1] < 0) | zero[:, 1:]
    has = change.any(axis=1)
    if not has.all():
        i = int(np.flatnonzero(~has)[0])
        raise InfeasibleError(
            f"the '{law}' eye path cannot be reached at x = {geo.x[i]:.6g} (z = {geo.line.z[i]:.6g} mm, grid point "
            f"{i}): no free length in (0, {l_cap:g}] mm puts the eye on it (free_length_max_mm)",
            field="payout.law")
    j = np.argmax(change, axis=1)
    a, b = ls[j], ls[j + 1]
    rows = np.arange(geo.n)
    fa = F[rows, j]
    for _ in range(_BISECT):
        mid = 0.5 * (a + b)
        Zm, Rm, _, _ = geo.eye(mid)
        fm = np.asarray(f(Zm, Rm), dtype=float)
        left = np.sign(fm) == np.sign(fa)
        a, b = np.where(left, mid, a), np.where(left, b, mid)
        fa = np.where(left, fm, fa)
    return 0.5 * (a + b)


def parallel_free_length(geo: _Geo, R0: float, law: str = "parallel") -> FloatArray:
    """Closed-form l with R(l) = R0: (1 − b²)l² + 2·r·a·l + r² − R0² = 0 (positive root)."""
    r, a, b = geo.line.r, geo.a, geo.b
    if (r >= R0).any():
        i = int(np.argmax(r >= R0))
        raise InputError(f"eye radius {R0:g} mm is not outside the mandrel (r = {r[i]:g} mm at z = "
                         f"{geo.line.z[i]:g} mm)", field="payout.eye_radius_mm")
    w = 1.0 - b * b
    ra = r * a
    den = ra + np.sqrt(ra * ra + w * (R0 * R0 - r * r))
    bad = den <= 1e-12 * R0
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise InfeasibleError(
            f"the '{law}' eye path R = {R0:g} mm cannot be reached at x = {geo.x[i]:.6g} (z = {geo.line.z[i]:.6g} mm): "
            "the tangent there runs parallel to the axis", field="payout.law")
    return (R0 * R0 - r * r) / den


def _curve_function(points: Sequence[tuple[float, float]]) -> Callable[[FloatArray, FloatArray], FloatArray]:
    pts = np.asarray(points, dtype=float)
    if pts.ndim != 2 or pts.shape[1] != 2 or len(pts) < 2:
        raise InputError("curve_zr_mm needs at least two (Z, R) points", field="payout.curve_zr_mm")
    if not np.isfinite(pts).all():
        raise InputError("curve_zr_mm has a non-finite value", field="payout.curve_zr_mm")
    Zc, Rc = pts[:, 0], pts[:, 1]
    if not (np.diff(Zc) > 0).all():
        i = int(np.flatnonzero(np.diff(Zc) <= 0)[0]) + 1
        raise InputError(f"curve_zr_mm: Z must increase strictly (point {i + 1}: Z = {Zc[i]:g} mm after "
                         f"{Zc[i - 1]:g} mm)", field="payout.curve_zr_mm")
    if len(pts) >= 4:
        from scipy.interpolate import CubicSpline

        spl = CubicSpline(Zc, Rc, bc_type="natural", extrapolate=False)

        def F(Z: FloatArray) -> FloatArray:
            inner = spl(np.clip(Z, Zc[0], Zc[-1]))
            return np.where(Z < Zc[0], Rc[0], np.where(Z > Zc[-1], Rc[-1], inner))
    else:
        def F(Z: FloatArray) -> FloatArray:
            return np.interp(Z, Zc, Rc)

    return lambda Z, R: R - F(Z)


def geometric_law(line: Any, mandrel: Any, law: str, spec: Any = None, *, k: int | None = None,
                  parameter: str | None = None, grid_points: int | None = None, workspace: Workspace | None = None,
                  curve: Callable[[FloatArray, FloatArray], FloatArray] | None = None,
                  state: State | None = None, refine: bool = True) -> EyePath:
    """Eye path of a geometric law (11): solve (10) + (11) for l(x) at each grid point.

    The program uses l interpolated linearly between grid points at every line point; where that
    breaks a constraint the law is also solved at those line points (:func:`_refined`), and the
    report's ``line`` section checks the eye path at every line point.

    Parameters
    ----------
    line : ContactLine or WindingLine-like
    mandrel : engine.mandrel.Mandrel
    law : 'parallel' (R = eye_radius_mm), 'equidistant' (distance offset_mm from the contour),
        'equal-tangent' (l = free_length_mm) or 'curve' (R = F(Z) through curve_zr_mm, or ``curve(Z, R) = 0``).
    spec : engine.job.PayoutSpec (defaults used if None).

    The result's ``report`` says which constraints the law violates (geometric laws ignore them).
    """
    from engine.job import PayoutSpec

    spec = spec if spec is not None else PayoutSpec()
    if law not in GEOMETRIC_LAWS:
        raise InputError(f"unknown geometric law {law!r}; use one of {', '.join(GEOMETRIC_LAWS)}", field="payout.law")
    k = spec.impregnation_k if k is None else k
    parameter = spec.parameter if parameter is None else parameter
    return _refined(line, mandrel, spec, workspace, state, refine, lambda extra, st, con, cache: _geometric_grid(
        line, mandrel, law, spec, k, parameter, grid_points, workspace, curve, st, extra, con, cache))


def _geometric_grid(line: Any, mandrel: Any, law: str, spec: Any, k: int, parameter: str, grid_points: int | None,
                    workspace: Workspace | None, curve: Callable[[FloatArray, FloatArray], FloatArray] | None,
                    state: State | None, extra: NDArray[np.int64] | None, contour: _Contour,
                    cache: _EnvCache | None = None) -> EyePath:
    """:func:`geometric_law` on the grid (plus the line points ``extra``)."""
    geo, env, contour = _prepare(line, mandrel, spec, parameter, grid_points, workspace, state, extra, contour,
                                 cache)
    l_cap = spec.free_length_max_mm
    if law == "parallel":
        R0 = spec.eye_radius_mm if spec.eye_radius_mm is not None else mandrel.r_max + spec.clearance_mm
        l = parallel_free_length(geo, float(R0))
    elif law == "equal-tangent":
        l0 = spec.free_length_mm if spec.free_length_mm is not None else float(env.l_min.max())
        l = np.full(geo.n, float(l0))
    elif law == "equidistant":
        h = spec.offset_mm if spec.offset_mm is not None else spec.clearance_mm
        l = _first_root(geo, lambda Z, R: contour.distance(Z, R) - h, l_cap, law)
    else:
        if curve is None:
            if not spec.curve_zr_mm:
                raise InputError("the 'curve' law needs curve_zr_mm (a table of eye (Z, R) points)",
                                 field="payout.curve_zr_mm")
            curve = _curve_function(spec.curve_zr_mm)
        l = _first_root(geo, curve, l_cap, law)
    eye = _build(geo, l, k, parameter, law, env)
    rep = _report(geo, eye, env, spec.u_min)
    if state is not None:
        state.progress(1.0, f"{law} law done")
    return _with_report(eye, rep)


def _with_report(eye: EyePath, rep: dict[str, Any]) -> EyePath:
    from engine.periodic import replace_raw

    return replace_raw(eye, report=rep)       # a deferred per-point array stays deferred


LINE_TOL_MM = 1e-3
"""Clearance, fibre and workspace tolerance of the check at every line point (mm): a micrometre."""
_REFINE_ROUNDS = 6
"""Rounds of adding the line points where the interpolated eye path breaks a constraint to the grid."""
_REFINE_NEAR = 4
"""Line points on each side of a failing one that join the grid with it."""
_REFINE_BAND = 1e-2
"""u between grid points may leave the grid's band by this share of its width before points are added
(the line's own band is reported either way)."""


def _line_check(cl: ContactLine, contour: _Contour, spec: Any, eye: EyePath, workspace: Workspace | None,
                tol: float = CHECK_TOL) -> tuple[dict[str, Any], NDArray[np.int64]]:
    """Check the eye path as the program uses it: l interpolated linearly in x at every line point.

    Checks the clearance (distance of the eye to the mandrel body), the free fibre staying out of the
    body, the workspace and free_length_max (to :data:`LINE_TOL_MM`), no sag, no reverse rotation and
    u >= u_min (with the tolerance of the grid's exact check).  Returns the summary (``feasible``, u
    figures at line resolution, ``constraints`` shaped as the grid report's) and the line indices to add
    to the grid where a check fails or u leaves the grid's band (each with its neighbours).
    """
    geo = _grid(cl, eye.parameter, None)
    l = np.interp(geo.x, eye.x, eye.l)
    Z, R, V, _ = geo.eye(l)
    L = geo.line
    x, z = geo.x, L.z
    xm, zm = 0.5 * (x[1:] + x[:-1]), 0.5 * (z[1:] + z[:-1])
    dx = np.diff(x)
    h = float(spec.clearance_mm)
    far = max(h, 0.01)
    dist = np.minimum(contour.distance(Z, R, far=far), far + 1.0)  # "far" is all the check needs to know
    fibre = np.full(geo.n, far + 1.0)
    for t in (0.125, 0.25, 0.375, 0.5, 0.625, 0.75, 0.875):  # the free fibre from the contact to the eye
        Zt, Rt, _, _ = geo.eye(l * t)
        fibre = np.minimum(fibre, contour.distance(Zt, Rt, far=far))
    if workspace is None and (spec.workspace_z_mm is not None or spec.workspace_r_mm is not None):
        workspace = BoxWorkspace(spec.workspace_z_mm, spec.workspace_r_mm)
    reach = float(spec.free_length_max_mm) - l
    if workspace is not None:
        reach = np.where(workspace.contains(Z, R), reach, np.minimum(reach, -1.0))
    lam = L.s + l - eye.k * R
    u = np.diff(lam) / dx
    point = {"clearance": dist - h, "fibre_outside_mandrel": fibre + 0.01, "workspace": reach}
    mid = {"no_sag": np.diff(L.s + l) / dx, "no_reverse_rotation": np.diff(V) / dx, "u_floor": u - float(spec.u_min)}
    bad = np.zeros(geo.n, dtype=bool)
    constraints: dict[str, Any] = {}
    for name, slack in point.items():
        viol = slack < -max(tol, LINE_TOL_MM)
        bad |= viol
        w = int(np.argmin(slack))
        constraints[name] = {"ok": not bool(viol.any()), "min_slack": float(slack[w]), "at_x": float(x[w]),
                             "at_z": float(z[w]), "violated": _runs(viol, x, z)}
    for name, slack in mid.items():
        viol = slack < -tol
        bad[:-1] |= viol
        bad[1:] |= viol
        w = int(np.argmin(slack))
        constraints[name] = {"ok": not bool(viol.any()), "min_slack": float(slack[w]), "at_x": float(xm[w]),
                             "at_z": float(zm[w]), "violated": _runs(viol, xm, zm)}
    # the band itself: u between grid points outside the grid's [u_min, u_max] widens the program's band
    ug = eye.u
    give = _REFINE_BAND * max(float(ug.max() - ug.min()), tol)
    wide = (u < float(ug.min()) - give) | (u > float(ug.max()) + give)
    grow = bad.copy()
    grow[:-1] |= wide
    grow[1:] |= wide
    i = geo.index[np.flatnonzero(grow)]
    near = np.arange(-_REFINE_NEAR, _REFINE_NEAR + 1)
    add = np.unique(np.clip((i[:, None] + near[None, :]).ravel(), 0, cl.z.size - 1)) if i.size else i
    umin, umax = float(u.min()), float(u.max())
    summary = {"points": int(geo.n), "feasible": not bool(bad.any()), "u_min": umin, "u_max": umax,
               "u_range": umax - umin, "clearance_min_mm": float(dist.min()), "constraints": constraints}
    return summary, add.astype(np.int64)


def _refined(line: Any, mandrel: Any, spec: Any, workspace: Workspace | None, state: State | None, refine: bool,
             solve: Callable[[NDArray[np.int64] | None, State | None, _Contour, _EnvCache | None], EyePath]
             ) -> EyePath:
    """Solve on the grid, check at every line point (:func:`_line_check`), add the line points where the
    interpolated path breaks a constraint or leaves the grid's pull-speed band to the grid and solve
    again (at most :data:`_REFINE_ROUNDS` times).  Without ``refine``: the grid's answer alone (solver
    comparisons on one grid).  The report gets the line check as ``line``; its ``feasible`` needs both
    checks, and a constraint broken only between grid points is listed as ``<name> (between grid
    points)``."""
    contour = _Contour(mandrel)
    if not refine:
        return solve(None, state, contour, None)
    cl = ContactLine.from_line(line)
    cache = _EnvCache()  # the envelope of the grid points already solved: a refined grid adds only its new points
    extra: NDArray[np.int64] | None = None
    added = 0
    for rnd in range(_REFINE_ROUNDS + 1):
        # progress: the first solve to 0.75, each refinement half of what is left
        a, b = (0.0, 0.75) if rnd == 0 else (1.0 - 0.25 * 0.5 ** (rnd - 1), 1.0 - 0.25 * 0.5 ** rnd)
        eye = solve(extra, None if state is None else SubState(state, a, b), contour, cache)
        check_cancel(state)
        chk, add = _line_check(cl, contour, spec, eye, workspace)
        # a law already infeasible on the grid stays so: refining would only re-solve it at more points
        if not add.size or not eye.report.get("feasible", True) or rnd == _REFINE_ROUNDS:
            break
        new = add if extra is None else np.union1d(extra, add)
        if extra is not None and new.size == extra.size:
            break  # nothing new to add: the grid already holds these points
        added, extra = new.size, new
    rep = dict(eye.report)
    chk["refinements"] = rnd
    chk["grid_points_added"] = added
    rep["line"] = chk
    cons = dict(rep.get("constraints") or {})
    for name, c in chk["constraints"].items():
        if not c["ok"] and cons.get(name, {}).get("ok", True):
            cons[f"{name} (between grid points)"] = c
    rep["constraints"] = cons
    rep["feasible"] = bool(rep.get("feasible", True)) and chk["feasible"]
    if state is not None:
        state.progress(1.0, f"{eye.law} law checked at {chk['points']} line points")
    return _with_report(eye, rep)


class _EnvCache:
    """The envelope at the line points of the grids solved so far in one :func:`_refined` call (same line,
    mandrel, spec and workspace): each grid point's envelope depends on that point alone, so a refined
    grid computes it only at its new points (bit for bit the same numbers).  It also carries the last
    narrowest-band LP's basis to the refined grid's first LP (:func:`_solve_range_stage`)."""

    def __init__(self) -> None:
        self.index: NDArray[np.int64] | None = None  # sorted line indices
        self.l_min: FloatArray | None = None
        self.l_max: FloatArray | None = None
        self.range_basis: _Basis | None = None  # the last narrowest-band LP's basis (_solve_range_stage)

    def envelope(self, geo: _Geo, contour: _Contour, clearance: float, l_cap: float,
                 workspace: Workspace | None, state: State | None) -> Envelope:
        """:func:`envelope` of ``geo``, computed at the grid points not seen before."""
        if self.index is None or self.l_min is None or self.l_max is None:
            env = envelope(geo, contour, clearance, l_cap, workspace, state)
        else:
            pos = np.clip(np.searchsorted(self.index, geo.index), 0, self.index.size - 1)
            have = self.index[pos] == geo.index
            lo, hi = np.empty(geo.n), np.empty(geo.n)
            lo[have], hi[have] = self.l_min[pos[have]], self.l_max[pos[have]]
            new = np.flatnonzero(~have)
            if new.size:
                sub = _Geo(geo.line.take(new), geo.x[new], geo.a[new], geo.b[new], geo.c[new], geo.index[new])
                try:
                    part = envelope(sub, contour, clearance, l_cap, workspace, state)
                except InfeasibleError:  # the whole grid again: the message names the grid point
                    return envelope(geo, contour, clearance, l_cap, workspace, state)
                lo[new], hi[new] = part.l_min, part.l_max
            env = Envelope(lo, hi, clearance, l_cap, workspace.describe() if workspace is not None else "unlimited")
        self.index, self.l_min, self.l_max = geo.index, env.l_min, env.l_max
        return env


def _prepare(line: Any, mandrel: Any, spec: Any, parameter: str, grid_points: int | None,
             workspace: Workspace | None, state: State | None, extra: NDArray[np.int64] | None = None,
             contour: _Contour | None = None, cache: _EnvCache | None = None) -> tuple[_Geo, Envelope, _Contour]:
    cl = ContactLine.from_line(line)
    n = spec.grid_points if grid_points is None else grid_points
    geo = _grid(cl, parameter, n, extra)
    if workspace is None and (spec.workspace_z_mm is not None or spec.workspace_r_mm is not None):
        workspace = BoxWorkspace(spec.workspace_z_mm, spec.workspace_r_mm)
    check_cancel(state)
    contour = _Contour(mandrel) if contour is None else contour
    if cache is not None:
        env = cache.envelope(geo, contour, spec.clearance_mm, spec.free_length_max_mm, workspace, state)
    else:
        env = envelope(geo, contour, spec.clearance_mm, spec.free_length_max_mm, workspace, state)
    if state is not None:
        state.progress(0.2, "clearance envelope")
    check_cancel(state)
    return geo, env, contour


# ------------------------------------------------------------------------------------------------
# Technological law: (13)–(15)
# ------------------------------------------------------------------------------------------------
class _Problem:
    """The discretised problem in the variables μ_i = l_i − k·R_i(l_i)."""

    def __init__(self, geo: _Geo, env: Envelope, k: int) -> None:
        import scipy.sparse as sp

        self.geo, self.env, self.k = geo, env, k
        n = geo.n
        self.n = n
        self.dx = np.diff(geo.x)
        self.ds = np.diff(geo.line.s)
        self.D = sp.diags([-np.ones(n - 1), np.ones(n - 1)], [0, 1], shape=(n - 1, n), format="csr")
        self.mu_lo = geo.mu(env.l_min, k)
        self.mu_hi = geo.mu(env.l_max, k)
        L = geo.line
        ends_equal = all(
            abs(float(arr[0] - arr[-1])) <= 1e-9 * max(1.0, float(np.abs(arr).max()))
            for arr in (L.r, geo.a, geo.b, geo.c)
        )
        self.exact_cyclic = ends_equal or k == 0
        self.U = float((L.s[-1] - L.s[0]) / (geo.x[-1] - geo.x[0]))
        # nonlinear rows (family -> set of interval indices) kept in the model
        self.rows: dict[str, set[int]] = {"no_sag": set(), "no_reverse_rotation": set()}
        if k == 0:
            self.rows["no_sag"] = set(range(n - 1))  # exactly linear in μ = l

    def l_of(self, mu: FloatArray) -> FloatArray:
        return self.geo.l_of_mu(mu, self.k)

    def u(self, mu: FloatArray) -> FloatArray:
        return (self.ds + np.diff(mu)) / self.dx

    def nonlinear_values(self, mu: FloatArray) -> dict[str, FloatArray]:
        l = self.l_of(mu)
        _, _, V, _ = self.geo.eye(l)
        return {"no_sag": np.diff(self.geo.line.s + l) / self.dx, "no_reverse_rotation": np.diff(V) / self.dx}

    def cut_rows(self, mu: FloatArray, slack: float = 0.0) -> tuple[Any, FloatArray]:
        """Linearised rows G·μ >= h of the kept nonlinear constraints, at μ; ``slack`` admits the exact
        violation :meth:`nonlinear_values` may show (per unit x, as the exact check counts it)."""
        import scipy.sparse as sp

        l = self.l_of(mu)
        dl_dmu = 1.0 / (1.0 - self.k * self.geo.dR_dl(l)) if self.k else np.ones_like(l)
        _, _, V, _ = self.geo.eye(l)
        blocks, rhs = [], []
        vals = {"no_sag": self.geo.line.s + l, "no_reverse_rotation": V}
        grads = {"no_sag": dl_dmu, "no_reverse_rotation": self.geo.dV_dl(l) * dl_dmu}
        for name, rows in self.rows.items():
            if not rows:
                continue
            i = np.array(sorted(rows))
            g, f = grads[name], vals[name]
            m = i.size
            data = np.concatenate([-g[i], g[i + 1]])
            cols = np.concatenate([i, i + 1])
            rr = np.concatenate([np.arange(m), np.arange(m)])
            G = sp.csr_matrix((data, (rr, cols)), shape=(m, self.n))
            # f(i+1) − f(i) + g(i+1)(μ' − μ(i+1)) − g(i)(μ' − μ(i)) >= 0
            h = -(f[i + 1] - f[i]) + g[i + 1] * mu[i + 1] - g[i] * mu[i] - slack * self.dx[i]
            blocks.append(G)
            rhs.append(h)
        if not blocks:
            return sp.csr_matrix((0, self.n)), np.zeros(0)
        return sp.vstack(blocks, format="csr"), np.concatenate(rhs)

    def range_keys(self) -> tuple[tuple[Any, ...], tuple[Any, ...]]:
        """Names of the columns and rows of the range LP in :func:`_solve_range_stage`'s order, by line point
        (the same names on a refined grid for what it keeps): μ at each grid point, t, T; the band rows of
        each interval (up: u <= T, down: u >= t), the cut rows of :meth:`cut_rows` (family, interval), the
        cyclic row."""
        idx = self.geo.index.tolist()
        cols = tuple(("mu", i) for i in idx) + ("t", "T")
        first = idx[:-1]
        cut = tuple((name, idx[i]) for name, rows in self.rows.items() for i in sorted(rows))
        return cols, tuple(("up", i) for i in first) + tuple(("down", i) for i in first) + cut + ("cyclic",)

    def cyclic_row(self, mu: FloatArray) -> tuple[FloatArray, float]:
        """Row c·μ = e for l_0 = l_{N-1} (exact when both ends have the same geometry)."""
        c = np.zeros(self.n)
        if self.exact_cyclic:
            c[0], c[-1] = 1.0, -1.0
            return c, 0.0
        l = self.l_of(mu)
        g = 1.0 / (1.0 - self.k * self.geo.dR_dl(l))
        c[0], c[-1] = g[0], -g[-1]
        return c, float(-(l[0] - l[-1]) + g[0] * mu[0] - g[-1] * mu[-1])

    def update_rows(self, mu: FloatArray, margin: float) -> float:
        """Add nonlinear rows that are violated or within ``margin``; return the worst exact violation."""
        worst = 0.0
        for name, val in self.nonlinear_values(mu).items():
            # rows within a few percent of their typical size join early: fewer re-solves
            near = np.flatnonzero(val < max(margin, 0.03 * float(np.median(np.abs(val)))))
            self.rows[name].update(int(i) for i in near)
            worst = max(worst, float(-val.min()))
        if not self.exact_cyclic:
            l = self.l_of(mu)
            worst = max(worst, abs(float(l[0] - l[-1])))
        return worst


_LP_OPTIONS = {"presolve": True, "primal_feasibility_tolerance": 1e-9, "dual_feasibility_tolerance": 1e-9}
_HIGHS_CORE_NAME = "scipy.optimize._highspy._core"
_highs_core_cache: list[Any] = []


def _highs_core() -> Any | None:
    """SciPy's build of HiGHS (``scipy.optimize._highspy._core``, SciPy >= 1.15) for
    :func:`_linprog_highs_direct`, loaded by :func:`engine._lightimport.extension_module` (without
    importing all of ``scipy.optimize`` when nothing else has); None where that layout is absent (other
    SciPy versions): :func:`_linprog` then calls ``linprog``."""
    if _highs_core_cache:
        return _highs_core_cache[0]
    from engine._lightimport import extension_module

    mod: Any = extension_module(_HIGHS_CORE_NAME)
    needed = ("HighsLp", "_Highs", "HighsOptions", "MatrixFormat", "HighsModelStatus", "HighsDebugLevel",
              "HighsStatus", "simplex_constants", "kHighsInf")
    if mod is not None and not all(hasattr(mod, a) for a in needed):
        mod = None
    _highs_core_cache.append(mod)
    return mod


@dataclass
class _LPResult:
    status: int  # scipy.optimize.linprog's codes: 0 optimal, 2 infeasible, 4 numerical trouble, ...
    x: FloatArray | None
    message: str
    basis: _Basis | None = None  # the optimal simplex basis (direct HiGHS only)
    iterations: int = 0  # HiGHS's simplex iterations (direct HiGHS only)


@dataclass
class _Basis:
    """A simplex basis of an LP: HiGHS's status codes (0 at lower, 1 basic, 2 at upper, 3 zero, 4 nonbasic)
    of every column and row, with a key naming each column and row (:meth:`_Problem.range_keys`), so that
    the next LP can start from it (:meth:`warm_for`): the next round of a cutting-plane loop (the same
    columns, the rows re-linearised, rows added) or the first round on a refined grid (columns and rows
    added between the old ones)."""

    cols: NDArray[np.int8]
    rows: NDArray[np.int8]
    keys: tuple[Any, ...] = ()
    col_keys: tuple[Any, ...] = ()

    def warm_for(self, col_keys: tuple[Any, ...], keys: tuple[Any, ...]
                 ) -> tuple[NDArray[np.int8], NDArray[np.int8], bool] | None:
        """The statuses ``(cols, rows, alien)`` for an LP with columns ``col_keys`` and rows ``keys``: a kept
        column or row keeps its status, a new one is basic (a new row's slack).  With the same columns the
        result must have exactly one basic variable per row (else None: the LP is solved from scratch);
        with other columns (a refined grid) it is an *alien* basis, which HiGHS completes to a valid one."""
        same_cols = col_keys == self.col_keys
        if same_cols and keys == self.keys:
            return self.cols, self.rows, False
        rows = self._map(self.keys, self.rows, keys)
        if same_cols:
            if int((self.cols == 1).sum()) + int((rows == 1).sum()) != len(keys):
                return None
            return self.cols, rows, False
        return self._map(self.col_keys, self.cols, col_keys), rows, True

    @staticmethod
    def _map(old_keys: tuple[Any, ...], old: NDArray[np.int8], keys: tuple[Any, ...]) -> NDArray[np.int8]:
        where = {k: i for i, k in enumerate(old_keys)}
        out = np.ones(len(keys), dtype=np.int8)
        for j, k in enumerate(keys):
            i = where.get(k)
            if i is not None:
                out[j] = old[i]
        return out


def _linprog(c: FloatArray, A_ub: Any, b_ub: FloatArray, A_eq: Any, b_eq: FloatArray,
             bounds: FloatArray, warm: tuple[NDArray[np.int8], NDArray[np.int8], bool] | None = None) -> Any:
    """``scipy.optimize.linprog(c, A_ub, b_ub, A_eq, b_eq, bounds, method='highs')`` with
    :data:`_LP_OPTIONS`: the same HiGHS model, options and status checks, so the same answer bit for bit
    (tests/test_payout_speed.py), called directly where :func:`_highs_core` has HiGHS at hand.

    ``warm`` (column and row statuses and whether the basis is alien, :meth:`_Basis.warm_for`) starts HiGHS's
    simplex from that basis instead of from scratch; the result then carries its own basis (``basis``,
    without keys)."""
    core = _highs_core()
    if core is None:
        from scipy.optimize import linprog

        return linprog(c, A_ub=A_ub, b_ub=b_ub, A_eq=A_eq, b_eq=b_eq, bounds=bounds, method=_LP_METHOD,
                       options=dict(_LP_OPTIONS))
    return _linprog_highs_direct(core, c, A_ub, b_ub, A_eq, b_eq, bounds, warm)


def _linprog_highs_direct(h: Any, c: FloatArray, A_ub: Any, b_ub: FloatArray, A_eq: Any, b_eq: FloatArray,
                          bounds: FloatArray, warm: tuple[NDArray[np.int8], NDArray[np.int8], bool] | None = None
                          ) -> _LPResult:
    """What ``linprog(method='highs')`` does for sparse A_ub/A_eq and an (n, 2) ``bounds`` (SciPy 1.15+:
    ``_clean_inputs``, ``_linprog_highs``, ``_highs_wrapper``, ``_check_result``), step for step; with
    ``warm``, from that basis (HiGHS then skips presolve and starts its dual simplex there)."""
    import scipy.sparse as sp

    c = np.array(c, dtype=np.float64, copy=True).reshape(-1)
    A = sp.csc_array(sp.vstack((sp.coo_array(A_ub, dtype=float, copy=True),
                                sp.coo_array(A_eq, dtype=float, copy=True))))
    b_ub = np.array(b_ub, dtype=float, copy=True).reshape(-1)
    b_eq = np.array(b_eq, dtype=float, copy=True).reshape(-1)
    bounds = np.atleast_2d(np.array(bounds, dtype=float))
    bounds[np.isnan(bounds[:, 0]), 0] = -np.inf
    bounds[np.isnan(bounds[:, 1]), 1] = np.inf
    lb, ub = bounds.T.copy()
    lhs = np.concatenate((-np.ones_like(b_ub) * np.inf, b_eq))
    rhs = np.concatenate((b_ub, b_eq))
    for arr in (rhs, lhs, lb, ub):
        infs = np.isinf(arr)
        arr[infs] = np.sign(arr[infs]) * h.kHighsInf
    lp = h.HighsLp()
    lp.num_col_ = c.size
    lp.num_row_ = rhs.size
    lp.a_matrix_.num_col_ = c.size
    lp.a_matrix_.num_row_ = rhs.size
    lp.a_matrix_.format_ = h.MatrixFormat.kColwise
    lp.col_cost_ = c
    lp.col_lower_ = lb
    lp.col_upper_ = ub
    lp.row_lower_ = lhs
    lp.row_upper_ = rhs
    lp.a_matrix_.start_ = A.indptr
    lp.a_matrix_.index_ = A.indices
    lp.a_matrix_.value_ = A.data
    highs = h._Highs()
    opts = h.HighsOptions()
    opts.presolve = "on" if _LP_OPTIONS["presolve"] else "off"
    opts.highs_debug_level = h.HighsDebugLevel.kHighsDebugLevelNone
    opts.dual_feasibility_tolerance = float(_LP_OPTIONS["dual_feasibility_tolerance"])
    opts.primal_feasibility_tolerance = float(_LP_OPTIONS["primal_feasibility_tolerance"])
    opts.log_to_console = False
    opts.output_flag = False
    opts.simplex_strategy = h.simplex_constants.SimplexStrategy.kSimplexStrategyDual
    M = h.HighsModelStatus
    fail = h.HighsStatus.kError
    codes = {M.kModelError: 2, M.kOptimal: 0, M.kTimeLimit: 1, M.kIterationLimit: 1, M.kInfeasible: 2,
             M.kUnbounded: 3}
    if highs.passOptions(opts) == fail:
        status = highs.getModelStatus()
        return _LPResult(codes.get(status, 4), None, f"HiGHS refused the options ({highs.modelStatusToString(status)})")
    if highs.passModel(lp) == fail:
        return _LPResult(2, None, "HiGHS could not load the model (HiGHS Status kModelError)")
    if warm is not None and warm[0].size == c.size and warm[1].size == rhs.size:
        B = h.HighsBasisStatus
        codes_in = (B.kLower, B.kBasic, B.kUpper, B.kZero, B.kNonbasic)
        basis = h.HighsBasis()
        basis.col_status = [codes_in[i] for i in warm[0].tolist()]
        basis.row_status = [codes_in[i] for i in warm[1].tolist()]
        basis.valid = True
        basis.alien = bool(warm[2])
        highs.setBasis(basis)  # refused (kError) if HiGHS finds it singular: it then starts from scratch
    if highs.run() == fail:
        status = highs.getModelStatus()
        return _LPResult(codes.get(status, 4), None, f"HiGHS failed ({highs.modelStatusToString(status)})")
    status = highs.getModelStatus()
    code = codes.get(status, 4)
    msg = f"{highs.modelStatusToString(status)} (HiGHS Status {int(status)})"
    if status != M.kOptimal:
        return _LPResult(code, None, msg)
    sol = highs.getSolution()
    x = np.array(sol.col_value)
    slack = rhs - np.asarray(sol.row_value)
    tol = np.sqrt(1e-9) * 10  # linprog's _check_result
    con = slack[b_ub.size:]
    ok = not (np.isnan(x).any() or np.isnan(slack).any())
    ok = ok and bool(np.all((x >= bounds[:, 0] - tol) & (x <= bounds[:, 1] + tol)))
    ok = ok and not (slack[:b_ub.size] < -tol).any() and not (np.abs(con) > tol).any()
    if not ok:
        return _LPResult(4, x, "the solution HiGHS returned violates the constraints (numerical difficulties)")
    out = highs.getBasis()
    basis_out = None
    if out.valid:
        basis_out = _Basis(np.array([int(v) for v in out.col_status], dtype=np.int8),
                           np.array([int(v) for v in out.row_status], dtype=np.int8), ())
    return _LPResult(0, x, msg, basis_out, int(highs.getInfo().simplex_iteration_count))


def _qp_highs(Q: Any, c: FloatArray, A: Any, row_lo: FloatArray, row_hi: FloatArray,
              col_lo: FloatArray, col_hi: FloatArray) -> tuple[FloatArray | None, str, str]:
    """min ½xᵀQx + cᵀx s.t. row_lo <= A x <= row_hi, col_lo <= x <= col_hi with HiGHS' QP solver.

    Returns (x or None, model status text, backend name).
    """
    import scipy.sparse as sp

    try:
        import highspy as hs  # type: ignore[import-not-found]

        core: Any = hs
        highs = hs.Highs()
        backend = "highspy"
    except ImportError:
        try:
            from scipy.optimize._highspy import _core as core  # HiGHS vendored in SciPy

            highs = core._Highs()
            backend = "scipy-vendored HiGHS"
        except ImportError:  # pragma: no cover - depends on the SciPy build
            return None, "unavailable", "none"
    inf = core.kHighsInf
    n = Q.shape[0]
    lp = core.HighsLp()
    lp.num_col_ = n
    lp.num_row_ = A.shape[0]
    lp.col_cost_ = np.asarray(c, dtype=float)
    lp.col_lower_ = np.where(np.isfinite(col_lo), col_lo, -inf)
    lp.col_upper_ = np.where(np.isfinite(col_hi), col_hi, inf)
    lp.row_lower_ = np.where(np.isfinite(row_lo), row_lo, -inf)
    lp.row_upper_ = np.where(np.isfinite(row_hi), row_hi, inf)
    Ac = sp.csc_matrix(A)
    lp.a_matrix_.format_ = core.MatrixFormat.kColwise
    lp.a_matrix_.start_ = Ac.indptr.astype(np.int32)
    lp.a_matrix_.index_ = Ac.indices.astype(np.int32)
    lp.a_matrix_.value_ = Ac.data.astype(float)
    lp.a_matrix_.num_col_ = n
    lp.a_matrix_.num_row_ = A.shape[0]
    model = core.HighsModel()
    model.lp_ = lp
    Ht = sp.tril(sp.csc_matrix(Q)).tocsc()
    hess = core.HighsHessian()
    hess.dim_ = n
    hess.format_ = core.HessianFormat.kTriangular
    hess.start_ = Ht.indptr.astype(np.int32)
    hess.index_ = Ht.indices.astype(np.int32)
    hess.value_ = Ht.data.astype(float)
    model.hessian_ = hess
    highs.setOptionValue("output_flag", _QP_LOG)
    highs.setOptionValue("time_limit", float(_QP_TIME_LIMIT))
    highs.passModel(model)
    highs.run()
    status = highs.getModelStatus()
    text = highs.modelStatusToString(status)
    if status != core.HighsModelStatus.kOptimal:
        return None, text, backend
    return np.array(highs.getSolution().col_value, dtype=float), text, backend


def _qp_trust_constr(Q: Any, c: FloatArray, A: Any, row_lo: FloatArray, row_hi: FloatArray,
                     col_lo: FloatArray, col_hi: FloatArray, x0: FloatArray) -> FloatArray:
    from scipy.optimize import Bounds, LinearConstraint, minimize

    res = minimize(lambda x: 0.5 * x @ (Q @ x) + c @ x, x0, jac=lambda x: Q @ x + c, hess=lambda x: Q,
                   method="trust-constr", constraints=[LinearConstraint(A, row_lo, row_hi)],
                   bounds=Bounds(col_lo, col_hi), options={"gtol": 1e-10, "xtol": 1e-12, "maxiter": 5000})
    return np.asarray(res.x, dtype=float)


@dataclass
class _Stage:
    name: str
    mu: FloatArray
    value: float
    iterations: int
    seconds: float


def _diagnose_infeasible(prob: _Problem) -> InfeasibleError:
    """Say which constraint family makes the pointwise-admissible set empty, and where."""
    geo, env = prob.geo, prob.env
    lo, hi = env.l_min, env.l_max
    x, z = geo.x, geo.line.z
    if max(lo[0], lo[-1]) > min(hi[0], hi[-1]) + 1e-9:
        return InfeasibleError(
            f"cyclicity l(x_n) = l(x_k) cannot hold: admissible free length is [{lo[0]:.4g}, {hi[0]:.4g}] mm at the "
            f"start (z = {z[0]:.5g} mm) but [{lo[-1]:.4g}, {hi[-1]:.4g}] mm at the end (z = {z[-1]:.5g} mm)",
            field="payout")
    # no sag: l_{i+1} >= l_i − Δs_i: propagate the smallest admissible sequence forward (twice, cyclic)
    ds = np.diff(geo.line.s)
    low = lo.copy()
    for _ in range(2):
        for i in range(len(low) - 1):
            low[i + 1] = max(low[i + 1], low[i] - ds[i])
        low[0] = max(low[0], low[-1])
    bad = np.flatnonzero(low > hi + 1e-9)
    if bad.size:
        i = int(bad[0])
        return InfeasibleError(
            f"no sag (d(s + l)/dx >= 0) cannot hold with the envelope at x = {x[i]:.6g} (z = {z[i]:.5g} mm, grid "
            f"point {i}): the free length would have to stay above {low[i]:.4g} mm but at most {hi[i]:.4g} mm is "
            f"admissible there ({env.workspace}, free_length_max_mm = {env.free_length_max_mm:g})", field="payout")
    return InfeasibleError(
        "no free-length law keeps the mandrel from rotating backwards (dV/dx >= 0) inside the clearance/workspace "
        f"envelope (clearance_mm = {env.clearance_mm:g}, {env.workspace}, free_length_max_mm = "
        f"{env.free_length_max_mm:g}); relax the envelope", field="payout")


def _solve_lp_stage(prob: _Problem, kind: str, u_lo: float | None, mu0: FloatArray, state: State | None,
                    tol: float, max_iter: int = 40) -> _Stage:
    """(13) kind='maxmin' or (14) kind='minmax' with the cutting-plane loop for the nonlinear rows."""
    import scipy.sparse as sp

    n = prob.n
    t0 = time.perf_counter()
    mu = mu0
    dxcol = sp.csr_matrix(prob.dx[:, None])
    for it in range(1, max_iter + 1):
        check_cancel(state)
        G, h = prob.cut_rows(mu)
        cyc, e = prob.cyclic_row(mu)
        Gx = sp.hstack([G, sp.csr_matrix((G.shape[0], 1))], format="csr")
        if kind == "maxmin":
            # max t: t·Δx − Dμ <= Δs
            A = sp.vstack([sp.hstack([-prob.D, dxcol]), -Gx], format="csr")
            b = np.concatenate([prob.ds, -h])
            cost = np.zeros(n + 1)
            cost[-1] = -1.0
        else:
            # min T: Dμ − T·Δx <= −Δs ; −Dμ <= Δs − u_lo·Δx
            assert u_lo is not None
            A = sp.vstack([sp.hstack([prob.D, -dxcol]), sp.hstack([-prob.D, sp.csr_matrix((n - 1, 1))]), -Gx],
                          format="csr")
            b = np.concatenate([-prob.ds, prob.ds - u_lo * prob.dx, -h])
            cost = np.zeros(n + 1)
            cost[-1] = 1.0
        A_eq = sp.csr_matrix(np.append(cyc, 0.0)[None, :])
        bounds = np.column_stack([np.append(prob.mu_lo, -np.inf), np.append(prob.mu_hi, np.inf)])
        res = _linprog(cost, A, b, A_eq, np.array([e]), bounds)
        check_cancel(state)  # a HiGHS solve cannot be interrupted: stop right after it
        if res.status == 2:
            raise _diagnose_infeasible(prob)
        if res.status != 0:
            raise InfeasibleError(f"the pull-speed {'(13)' if kind == 'maxmin' else '(14)'} problem could not be "
                                  f"solved ({res.message.strip().rstrip('.')}); try fewer grid_points", field="payout")
        mu = res.x[:n]
        if prob.update_rows(mu, margin=10 * tol) <= tol:
            return _Stage(kind, mu, float(res.x[-1]), it, time.perf_counter() - t0)
    return _Stage(kind, mu, float(res.x[-1]), max_iter, time.perf_counter() - t0)


def _solve_range_stage(prob: _Problem, u_floor: float, mu0: FloatArray, state: State | None, tol: float,
                       max_iter: int = 40, carry: Any = None) -> tuple[_Stage, float, float]:
    """min (T − t) with t <= u <= T on every interval and t >= ``u_floor``: the narrowest pull-speed band.

    The same constraints as (13)/(14) (envelope, cyclicity, no sag, no reverse rotation with the
    cutting-plane loop), so every law the report finds feasible lies in its feasible set and its
    band is never wider.  Returns the stage (value = T − t) and (t, T).

    Every round starts HiGHS from the last optimal basis: the previous round's, or for the first round
    the one ``carry.range_basis`` holds (the coarser grid's last round, :class:`_EnvCache`); the final
    basis is left there for the next grid.
    """
    import scipy.sparse as sp

    n = prob.n
    t0 = time.perf_counter()
    mu = mu0
    dxcol = sp.csr_matrix(prob.dx[:, None])
    zero = sp.csr_matrix((n - 1, 1))
    x = np.zeros(n + 2)
    it = 0
    basis: _Basis | None = getattr(carry, "range_basis", None)
    while it < max_iter:
        it += 1
        check_cancel(state)
        G, h = prob.cut_rows(mu)
        cyc, e = prob.cyclic_row(mu)
        Gx = sp.hstack([G, sp.csr_matrix((G.shape[0], 2))], format="csr")
        # u_i = (Δs_i + (Dμ)_i)/Δx_i:  Dμ − T·Δx <= −Δs ;  −Dμ + t·Δx <= Δs
        A = sp.vstack([sp.hstack([prob.D, zero, -dxcol]), sp.hstack([-prob.D, dxcol, zero]), -Gx], format="csr")
        b = np.concatenate([-prob.ds, prob.ds, -h])
        cost = np.zeros(n + 2)
        cost[-1], cost[-2] = 1.0, -1.0
        A_eq = sp.csr_matrix(np.append(cyc, [0.0, 0.0])[None, :])
        bounds = np.column_stack([np.append(prob.mu_lo, [u_floor, -np.inf]),
                                  np.append(prob.mu_hi, [np.inf, np.inf])])
        # the rounds differ only in re-linearised and added cut rows: each starts from the last one's
        # optimal basis (a handful of dual simplex steps instead of hundreds from scratch)
        col_keys, keys = prob.range_keys()
        res = _linprog(cost, A, b, A_eq, np.array([e]), bounds,
                       basis.warm_for(col_keys, keys) if basis is not None else None)
        basis = res.basis if isinstance(res, _LPResult) else None
        if basis is not None:
            basis.keys, basis.col_keys = keys, col_keys
        if carry is not None:
            carry.range_basis = basis
        check_cancel(state)
        if res.status == 2:
            raise _diagnose_infeasible(prob)
        if res.status != 0:
            msg = res.message.strip().rstrip(".")
            raise InfeasibleError(f"the narrowest pull-speed band could not be found ({msg}); try fewer "
                                  "grid_points", field="payout")
        x = res.x
        mu = x[:n]
        if prob.update_rows(mu, margin=10 * tol) <= tol:
            break
    return _Stage("range", mu, float(x[-1] - x[-2]), it, time.perf_counter() - t0), float(x[-2]), float(x[-1])


def _polish_cuts(prob: _Problem, mu: FloatArray, val: float,
                 run: Callable[[FloatArray], tuple[FloatArray, int, bool]],
                 objective: Callable[[FloatArray], float], tol: float) -> tuple[FloatArray, float, int]:
    """Second pass of a (15) cutting-plane loop that converged at ``mu`` with jerk ``val``.

    Rows that joined early (near-active at an intermediate point) are linearised where the nonconvex
    no-sag / no-reverse-rotation set is narrower than at the optimum and can cut off a sliver of it (a
    jerk ~1e-4 relative too high, and a different sliver for each solver).  Only the rows active at the
    solution are kept and the loop re-run from it (``run``); its answer is taken when it is exactly
    feasible and lower.  Returns (μ, jerk, extra iterations)."""
    kept = {name: set(rows) for name, rows in prob.rows.items()}
    for name, v in prob.nonlinear_values(mu).items():
        if name == "no_sag" and prob.k == 0:
            continue  # exactly linear in μ: no sliver to recover
        prob.rows[name] = {int(i) for i in np.flatnonzero(v <= 10 * tol)}
    if prob.rows == kept:
        return mu, val, 0
    try:
        mu2, it2, ok = run(mu)
    except (_FastFail, InfeasibleError):
        ok = False
    if ok and (v2 := objective(mu2)) < val:
        return mu2, v2, it2
    prob.rows = kept
    return mu, val, 0


def _solve_qp_stage(prob: _Problem, u_lo: float, u_hi: float, mu0: FloatArray, state: State | None,
                    tol: float, max_iter: int = 40) -> tuple[_Stage, str]:
    """(15): min Σ (u_i − U)²·Δx_i, u_lo <= u <= u_hi, with the same cutting-plane loop."""
    import scipy.sparse as sp

    t0 = time.perf_counter()
    W = sp.diags(1.0 / prob.dx)
    D = prob.D
    Q = (2.0 * (D.T @ W @ D)).tocsc()
    rhs = prob.ds - prob.U * prob.dx
    c = 2.0 * (D.T @ (rhs / prob.dx))
    const = float(np.sum(rhs * rhs / prob.dx))
    mu = mu0
    backend = ""
    it = 0
    if u_hi - u_lo <= 1e-6 * max(1.0, abs(u_hi)):  # the band pins u: the (14) answer is the jerk optimum
        val = float(0.5 * mu @ (Q @ mu) + c @ mu) + const
        return _Stage("jerk", mu, val, 0, time.perf_counter() - t0), "none (band of zero width)"
    def objective(m: FloatArray) -> float:
        return float(0.5 * m @ (Q @ m) + c @ m) + const

    def cutting_planes(mu: FloatArray, slack: float = 0.0) -> tuple[FloatArray, int, bool, str]:
        backend, it, worst = "", 0, np.inf
        for it in range(1, max_iter + 1):  # noqa: B007 - returned below
            check_cancel(state)
            G, h = prob.cut_rows(mu, slack)
            cyc, e = prob.cyclic_row(mu)
            A = sp.vstack([D, G, sp.csr_matrix(cyc[None, :])], format="csc")
            row_lo = np.concatenate([u_lo * prob.dx - prob.ds, h, [e]])
            row_hi = np.concatenate([u_hi * prob.dx - prob.ds, np.full(h.size, np.inf), [e]])
            sol, status, backend = _qp_highs(Q, c, A, row_lo, row_hi, prob.mu_lo, prob.mu_hi)
            check_cancel(state)
            if sol is None:
                if status == "unavailable":
                    sol = _qp_trust_constr(Q, c, A, row_lo, row_hi, prob.mu_lo, prob.mu_hi, mu)
                    backend = "trust-constr"
                elif "nfeasible" in status:
                    # the band stage's answer sits on the boundary of the rows it made tight, inside the exact
                    # check's tolerance: the cuts are then re-tried with that tolerance as slack
                    if slack == 0.0 and _fast_check(prob, mu0, u_lo, u_hi, tol):
                        return cutting_planes(mu0, slack=tol)
                    raise _diagnose_infeasible(prob)
                else:  # time limit / numerical trouble: keep the (14) answer (it satisfies every constraint)
                    return mu, it, False, backend + f" ({status}: jerk not minimised, (14) answer kept)"
            if not np.isfinite(sol).all() or (sol < prob.mu_lo - 1e-6).any() or (sol > prob.mu_hi + 1e-6).any():
                return mu, it, False, backend + " (returned an invalid point: jerk not minimised, (14) answer kept)"
            worst = prob.update_rows(sol, margin=10 * tol)
            if _QP_LOG:
                print(f"QP round {it}: worst exact violation {worst:.3g}")
            mu = sol
            if worst <= tol:
                break
        return mu, it, worst <= tol, backend

    mu, it, ok, backend = cutting_planes(mu)
    val = objective(mu)
    if ok:
        mu, val, it2 = _polish_cuts(prob, mu, val, lambda m: cutting_planes(m)[:3], objective, tol)
        it += it2
    return _Stage("jerk", mu, val, it, time.perf_counter() - t0), backend


# ------------------------------------------------------------------------------------------------
# Fast path: (13)/(14) by interval propagation along the cycle, (15) by an interior-point QP whose
# Newton systems are cyclic tridiagonal.  Every answer is checked with the exact formulas; any
# case the fast path cannot settle goes to the HiGHS formulations above (the reference).
# ------------------------------------------------------------------------------------------------
class _FastFail(Exception):
    """The fast path cannot settle this case exactly: use the HiGHS formulations."""


def _f8_vector(v: Any, n: int | None = None) -> bool:
    """Whether ``v`` is a C-contiguous 1-D float64 array (of ``n`` entries): what the compiled steps of
    :class:`_Tube` read as raw memory."""
    return (type(v) is np.ndarray and v.dtype == np.float64 and v.ndim == 1 and v.flags.c_contiguous
            and (n is None or v.shape[0] == n))


class _Tube:
    """Step bounds of μ along the cycle (exact cyclic case only).

    μ_{i+1} − μ_i ∈ [t·Δx_i − Δs_i, T·Δx_i − Δs_i] (u bounds) and μ_{i+1} >= g_i(μ_i), where g_i
    (no sag, no reverse rotation) is nondecreasing in μ_i and evaluated exactly (closed forms).
    The forward reachable set of μ_i from a start interval is an interval; its upper end is a
    running minimum, its lower end a running maximum with the g_i terms found by a short
    fixed-point iteration on the (slowly varying) increments g_i(μ) − μ.
    """

    def __init__(self, prob: _Problem) -> None:
        geo, k = prob.geo, prob.k
        self.prob, self.k = prob, k
        self.state: State | None = None  # polled for cancellation once per round of :meth:`solve`
        L = geo.line
        self.dx, self.ds = prob.dx, prob.ds
        self.lo = prob.mu_lo.copy()
        self.hi = prob.mu_hi.copy()
        self.scale = max(1.0, float(np.abs(self.hi).max()), float(np.abs(self.lo).max()))
        # geometry of the interval's first (f) and second (t) point
        self.rf, self.af, self.bf, self.cf, self.vf = L.r[:-1], geo.a[:-1], geo.b[:-1], geo.c[:-1], L.v[:-1]
        self.rt, self.at, self.bt, self.ct, self.vt = L.r[1:], geo.a[1:], geo.b[1:], geo.c[1:], L.v[1:]
        self.sf, self.st = L.s[:-1], L.s[1:]
        self.theta_t = np.arctan2(self.ct, self.at)  # sup of V − v over l >= 0 at the second point
        self._last: tuple[FloatArray, FloatArray, FloatArray] | None = None  # (y, A, μ_hi) of the last solution
        self._cap: FloatArray | None = None
        # products of :meth:`_l_of_mu` that do not depend on μ, for :meth:`g` (the same products: the same bits)
        self._ra, self._b2, self._r2 = self.rf * self.af, self.bf * self.bf, self.rf * self.rf
        # the compiled steps (engine.payout_jit: the same bits), with the geometry as one table of rows
        from engine.payout_jit import kernels

        self._kern = kernels()
        self._n1 = int(self.rf.shape[0])
        self._noidx = np.zeros(0, dtype=np.int64)
        self.geometry_changed()

    def geometry_changed(self) -> None:
        """Take the per-interval geometry attributes again into the compiled steps' table (after code that
        changes them, e.g. a test's made-up azimuths; the numpy code reads the attributes themselves)."""
        from engine.payout_jit import G_ROWS

        self._G: FloatArray | None = None
        if self._kern is not None:
            rows = {"ra": self._ra, "b2": self._b2, "r2": self._r2, "ds": self.ds, "af": self.af, "rf": self.rf,
                    "cf": self.cf, "vf": self.vf, "vt": self.vt, "rt": self.rt, "at": self.at, "ct": self.ct,
                    "theta_t": self.theta_t}
            G = np.ascontiguousarray(np.stack([np.asarray(rows[r], dtype=np.float64) for r in G_ROWS]))
            self._G = G if G.shape == (len(G_ROWS), self._n1) else None

    # exact per-point maps --------------------------------------------------------------------
    def _l_of_mu(self, mu: FloatArray, r: FloatArray, a: FloatArray, b: FloatArray) -> FloatArray:
        if not self.k:
            return mu
        B = mu + r * a
        b2 = b * b
        disc = np.sqrt(np.maximum(B * B - b2 * (mu * mu - r * r), 0.0))
        neg = (mu * mu - r * r) / (B - disc)  # 0/0, x/0 possible: run under _quiet_fp (no warning)
        pos = (B + disc) / b2
        return np.where(B <= 0, neg, pos)

    def _mu_of_l(self, l: FloatArray, r: FloatArray, a: FloatArray, c: FloatArray) -> FloatArray:
        if not self.k:
            return l
        return np.where(np.isinf(l), np.inf, l - np.hypot(r + a * l, c * l))  # inf - inf: under _quiet_fp

    def g(self, mu: FloatArray, idx: NDArray[np.int64] | slice = slice(None)) -> FloatArray:
        """Smallest μ_{i+1} allowed by no sag and no reverse rotation given μ_i (nondecreasing in μ_i).

        The arithmetic of :meth:`g_reference` operation for operation (so bit for bit), with the μ-free
        products made once, temporaries reused, and the branches of ``np.where`` that no entry takes not
        computed (the forward propagation calls this ~3 000 times per example law; ~10 % less time).
        Where the compiled steps run (:mod:`engine.payout_jit`), by them around numpy's ``arctan2``: the
        same bits again."""
        if self._G is not None:
            out = self._g_compiled(mu, idx)
            if out is not None:
                return out
        rf, af, cf, rt, at, ct = self.rf[idx], self.af[idx], self.cf[idx], self.rt[idx], self.at[idx], self.ct[idx]
        if self.k:  # l(μ), as _l_of_mu
            b2, r2 = self._b2[idx], self._r2[idx]
            B = mu + self._ra[idx]
            m2 = mu * mu
            m2 -= r2
            disc = B * B
            disc -= b2 * m2
            np.maximum(disc, 0.0, out=disc)
            np.sqrt(disc, out=disc)
            neg = B <= 0
            l = B + disc
            l /= b2
            if neg.any():
                l = np.where(neg, m2 / (B - disc), l)
        else:
            l = mu
        l_sag = l - self.ds[idx]
        x = af * l
        x += rf
        phi = self.vf[idx] + np.arctan2(cf * l, x)
        phi -= self.vt[idx]
        sp, cp = np.sin(phi), np.cos(phi)
        den = ct * cp
        den -= at * sp
        ok = phi < self.theta_t[idx]
        ok &= den > 0
        if ok.all():
            l_rot = rt * sp
            l_rot /= den
        else:
            l_rot = np.where(ok, rt * sp / np.where(ok, den, 1.0), np.inf)
        back = phi <= 0
        if back.any():
            l_rot = np.where(back, 0.0, l_rot)
        need = np.maximum(l_sag, l_rot)
        np.maximum(need, 0.0, out=need)
        if not self.k:
            return need
        h = at * need  # μ(need), as _mu_of_l
        h += rt
        out = need - np.hypot(h, ct * need)
        inf = np.isinf(need)
        return np.where(inf, np.inf, out) if inf.any() else out

    def _g_compiled(self, mu: FloatArray, idx: NDArray[np.int64] | slice) -> FloatArray | None:
        """:meth:`g` by the compiled kernels; None where the arguments are not theirs (the numpy code runs)."""
        if not _f8_vector(mu):
            return None
        n = mu.shape[0]
        if isinstance(idx, slice):
            if idx != slice(None) or n != self._n1:
                return None
            full, ix = True, self._noidx
        else:
            if (type(idx) is not np.ndarray or idx.dtype != np.int64 or idx.ndim != 1 or not idx.flags.c_contiguous
                    or idx.shape[0] != n or (n and (int(idx.min()) < 0 or int(idx.max()) >= self._n1))):
                return None
            full, ix = False, idx
        pre, post = self._kern[0], self._kern[1]
        k = bool(self.k)
        l, num, den = np.empty(n), np.empty(n), np.empty(n)
        pre(self._G, mu, ix, full, k, l, num, den)
        ang = np.arctan2(num, den)   # numpy's own (its bits differ from a compiled loop's on some CPUs)
        out = np.empty(n)
        post(self._G, l, ang, ix, full, k, out)
        return out

    def g_reference(self, mu: FloatArray, idx: NDArray[np.int64] | slice = slice(None)) -> FloatArray:
        """:meth:`g` written plainly (the tested reference)."""
        rf, af, cf, rt, at, ct = self.rf[idx], self.af[idx], self.cf[idx], self.rt[idx], self.at[idx], self.ct[idx]
        l = self._l_of_mu(mu, rf, af, self.bf[idx])
        l_sag = l - self.ds[idx]
        phi = self.vf[idx] + np.arctan2(cf * l, rf + af * l) - self.vt[idx]
        sp, cp = np.sin(phi), np.cos(phi)
        den = ct * cp - at * sp
        ok = (phi < self.theta_t[idx]) & (den > 0)
        l_rot = np.where(phi <= 0, 0.0, np.where(ok, rt * sp / np.where(ok, den, 1.0), np.inf))
        need = np.maximum(np.maximum(l_sag, l_rot), 0.0)
        return self._mu_of_l(need, rt, at, ct)

    def rotation_cap(self) -> FloatArray:
        """μ_i above which g_i is infinite (no μ_{i+1} keeps the eye from turning back): the eye's azimuth
        lead over the contact point, φ(l) = v_i + atan2(c·l, r + a·l) − v_{i+1}, reaches the second point's
        θ at l = r·sin ψ/(c·cos ψ − a·sin ψ), ψ = θ + v_{i+1} − v_i (no cap where that has no solution)."""
        if self._cap is None:
            psi = self.theta_t + self.vt - self.vf
            den = self.cf * np.cos(psi) - self.af * np.sin(psi)
            ok = (psi > 0.0) & (psi < np.pi) & (den > 0.0)
            l = np.where(ok, self.rf * np.sin(psi) / np.where(ok, den, 1.0), np.inf)
            self._cap = self._mu_of_l(l, self.rf, self.af, self.cf)
        return self._cap

    def implied_hi(self, B: FloatArray) -> FloatArray | None:
        """μ_hi tightened by the implied bound g_i(μ_i) <= μ_{i+1} <= μ_i + B_i (None: empty somewhere).

        Where g_i(μ) − μ − B_i changes sign inside the band (found by bisection on those few points)
        the larger μ_i cannot be continued; without this bound the fixed-point iteration would only
        creep towards the contradiction.
        """
        hi = self.hi.copy()
        tol = 1e-12 * self.scale
        fh = self.g(hi[:-1]) - hi[:-1] - B
        idx = np.flatnonzero(fh > tol)
        if idx.size:
            lo_i = self.lo[idx]
            if (self.g(lo_i, idx) - lo_i - B[idx] > tol).any():
                return None
            hi[idx] = self._edge(idx, lo_i.copy(), hi[idx].copy(), B[idx], tol)
        hi[0] = hi[-1] = min(hi[0], hi[-1])
        return hi

    def _edge(self, idx: NDArray[np.int64], a: FloatArray, b: FloatArray, B: FloatArray, tol: float) -> FloatArray:
        """Largest μ in [a, b] with φ(μ) = g_i(μ) − μ − B_i <= 0 (φ(a) <= 0 < φ(b)), to ``tol``.

        Illinois (regula falsi with the stale end's value halved; superlinear, ~10 steps instead of
        bisection's ~45), every third step a bisection step so the bracket shrinks at least geometrically;
        non-finite values (no reverse rotation impossible) fall back to bisection.
        """
        fa = self.g(a, idx) - a - B
        fb = self.g(b, idx) - b - B
        last = np.zeros(a.size)  # +1: b moved last step, −1: a moved
        if self._G is not None and all(_f8_vector(v, a.size) for v in (a, b, fa, fb, B)):
            return self._edge_compiled(idx, a.copy(), b.copy(), fa, fb, B, tol, last)
        for it in range(200):
            w = b - a
            if w.max() <= tol:
                break
            m = a - fa * w / (fb - fa)
            ok = np.isfinite(m) & (it % 3 != 2)
            m = np.where(ok, np.clip(m, a + 0.25 * tol, b - 0.25 * tol), 0.5 * (a + b))
            fm = self.g(m, idx) - m - B
            bad = fm > 0
            fa = np.where(bad & (last > 0), 0.5 * fa, np.where(bad, fa, fm))
            fb = np.where(~bad & (last < 0), 0.5 * fb, np.where(bad, fm, fb))
            a, b = np.where(bad, a, m), np.where(bad, m, b)
            last = np.where(bad, 1.0, -1.0)
        return a

    def _edge_compiled(self, idx: NDArray[np.int64], a: FloatArray, b: FloatArray, fa: FloatArray, fb: FloatArray,
                       B: FloatArray, tol: float, last: FloatArray) -> FloatArray:
        """:meth:`_edge`'s steps by the compiled kernels (engine.payout_jit), g by :meth:`g`: the same bits."""
        mid, upd = self._kern[4], self._kern[5]
        for it in range(200):
            m = np.empty(a.size)
            if mid(a, b, fa, fb, it, float(tol), m):
                break
            gm = self.g(m, idx)
            upd(a, b, fa, fb, last, m, np.ascontiguousarray(gm, dtype=np.float64), B)
        return a

    # propagation ------------------------------------------------------------------------------
    @staticmethod
    def _sweep(x: FloatArray, A: FloatArray, cap: FloatArray, C: FloatArray) -> FloatArray:
        """y_0 = x_0, y_{i+1} = max(x_{i+1}, y_i + A_i) by running maxima (vectorised), capped at ``cap``.

        ``C`` is scratch of x's size with C_0 = 0 (the cumulative sums of A go to C_1..); the forward
        pass makes up to a few hundred sweeps per solve, so the scratch and the caller's fixed ``cap``
        save allocations, not arithmetic: the operations (and so the bits) are those of
        ``C = [0, cumsum(A)]; C + maximum.accumulate([x_0, x_1..] − C)``."""
        np.cumsum(A, out=C[1:])
        w = x - C
        return np.minimum(C + np.maximum.accumulate(w), cap)

    @staticmethod
    def _run_min(start: float, E: FloatArray, B: FloatArray) -> FloatArray:
        C = np.concatenate([[0.0], np.cumsum(B)])
        w = np.concatenate([[start], E[1:]]) - C
        return C + np.minimum.accumulate(w)

    def forward(self, x: FloatArray, A: FloatArray, h: FloatArray) -> FloatArray | None:
        """Forward closure y_0 = x_0, y_{i+1} = max(x_{i+1}, y_i + A_i, g_i(y_i)); None if y > μ_hi somewhere.

        The recursion has one solution; it is found by running maxima with the increments
        g_i(y) − y frozen at the previous iterate.  After each sweep the leading entries that satisfy
        the recursion exactly are final (at least one more per sweep, usually all at once).
        """
        tol = 1e-12 * self.scale
        cap = h + 1.0
        C = np.zeros(x.size)
        y = self._sweep(x, A, cap, C)
        if self._G is not None and self._fits(x, A, h):
            return self._forward_compiled(x, A, h, y, cap, C, tol)
        prev = np.inf
        newton = True
        for _ in range(80):
            gv = self.g(y[:-1])
            res = np.maximum(np.maximum(x[1:], y[:-1] + A), gv) - y[1:]
            bad = np.flatnonzero(np.abs(res) > tol)
            exact = y.size if not bad.size else int(bad[0]) + 1
            if (y[:exact] > h[:exact] + tol).any():
                return None
            if not bad.size:
                return y
            if y[exact] + res[exact - 1] > h[exact] + tol:  # the next entry, exactly
                return None
            worst = float(np.abs(res).max())
            newton = newton and worst < prev  # Newton steps only while they pay
            prev = worst
            gfin = np.isfinite(gv)
            Ahat = np.maximum(A, np.where(gfin, gv, y[:-1] + 1e3 * self.scale) - y[:-1])
            y_new = self._sweep(x, Ahat, cap, C)
            if newton:
                y_new = self._newton(x, y, y_new, A, cap, gv, gfin, C)
            y = y_new
        raise _FastFail("forward propagation did not settle")

    def _fits(self, x: FloatArray, A: FloatArray, h: FloatArray) -> bool:
        """Whether the compiled forward closure takes these arrays (C-contiguous float64 of the grid's sizes)."""
        n = self._n1 + 1
        return _f8_vector(x, n) and _f8_vector(A, n - 1) and _f8_vector(h, n)

    def _forward_compiled(self, x: FloatArray, A: FloatArray, h: FloatArray, y: FloatArray, cap: FloatArray,
                          C: FloatArray, tol: float) -> FloatArray | None:
        """:meth:`forward` after its first sweep ``y``, each round's checks, frozen-increment sweep and
        Newton sweeps (:meth:`_newton`) by the compiled kernels; g by :meth:`g`.  The same operations, the same
        bits."""
        step, newton_k = self._kern[2], self._kern[3]
        n = x.shape[0]
        big = 1e3 * self.scale
        inc, yd, dy, info = np.empty(n - 1), np.empty(n - 1), np.empty(n - 1), np.empty(1)
        prev = np.inf
        newton = True
        for _ in range(80):
            gv = self.g(y[:-1])
            y_new = np.empty(n)
            status = step(x, A, y, gv, h, cap, C, tol, big, inc, y_new, yd, dy, info)
            if status == 0:
                return None
            if status == 1:
                return y
            worst = float(info[0])
            newton = newton and worst < prev  # Newton steps only while they pay
            prev = worst
            if newton:
                g2 = self.g(yd)
                z = np.empty(n)
                newton_k(x, y, y_new, A, cap, C, gv, g2, dy, 1e-13 * self.scale, big, inc, z)
                y_new = z
            y = y_new
        raise _FastFail("forward propagation did not settle")

    def _newton(self, x: FloatArray, y: FloatArray, z: FloatArray, A: FloatArray, cap: FloatArray,
                gv: FloatArray, gfin: NDArray[np.bool_], C: FloatArray) -> FloatArray:
        """One Newton step for the forward recursion: the recursion with g_i linearised at y_i,
        z_{i+1} = max(x_{i+1}, z_i + A_i, g_i(y_i) + g_i'(y_i)·(z_i − y_i)), solved by cheap running-maximum
        sweeps (no g evaluations) started from the frozen-increment sweep ``z``.  Along a long chain of
        active no-sag bounds this converges quadratically where frozen increments converge geometrically
        (up to ~20 sweeps on the domes).  Only a better iterate: the caller checks the exact recursion.
        ``cap`` (μ_hi + 1) and ``C`` as in :meth:`_sweep`."""
        yi = y[:-1]
        dy = 1e-7 * np.maximum(1.0, np.abs(yi))
        g2 = self.g(yi + dy)
        slope = (g2 - gv) / dy
        lin = gfin & np.isfinite(slope)
        slope = np.where(lin, slope, 1.0)
        base = np.where(gfin, gv, yi + 1e3 * self.scale) - yi  # increment at z_i = y_i
        tol = 1e-13 * self.scale
        s1 = slope - 1.0
        for _ in range(60):
            inc = np.maximum(A, base + s1 * (z[:-1] - yi))
            z_new = self._sweep(x, inc, cap, C)
            if not np.isfinite(z_new).all():
                return z
            done = float(np.abs(z_new - z).max()) <= tol
            z = z_new
            if done:
                break
        return z

    def solve(self, t: float | None, T: float | None, max_rounds: int = 200,
              below: FloatArray | None = None) -> FloatArray | None:
        """The lowest cyclic μ with t <= u <= T (None: that side unbounded), or None if there is none.

        Every constraint is a lower bound x_j >= φ(x_k) with φ nondecreasing (μ_{i+1} >= μ_i + A_i,
        μ_{i+1} >= g_i(μ_i), μ_i >= μ_{i+1} − B_i, μ_0 = μ_{N−1}, μ >= μ_lo) except μ <= μ_hi, so the
        set is non-empty iff the least fixed point (Kleene iteration from μ_lo: forward sweeps,
        backward running maxima, closing the cycle) stays below μ_hi — and that point is feasible.
        ``below``: a known lower bound of that point (the solution for looser bounds) to start from.
        """
        A, B = self._steps(t, T)
        tol = 1e-10 * self.scale
        hi = self.hi if B is None else self.implied_hi(B)
        if hi is None:
            return None
        x = self.lo.copy() if below is None else np.maximum(self.lo, below)
        x[0] = x[-1] = max(x[0], x[-1])
        for _ in range(max_rounds):
            check_cancel(self.state)
            y = self.forward(x, A, hi)
            if y is None:
                return None
            if B is not None:
                C = np.concatenate([[0.0], np.cumsum(B)])
                y = C + np.maximum.accumulate((y - C)[::-1])[::-1]
            c = max(y[0], y[-1])
            y[0] = y[-1] = c
            if (y > hi + tol).any():
                return None
            if np.abs(y - x).max() <= 1e-13 * self.scale:
                out = self._polish(y, A, B, hi)
                if out is not None:
                    self._last = (out, A, hi)
                return out
            x = y
        raise _FastFail("cyclic closure did not settle")

    def margin(self) -> float:
        """How far the last solution :meth:`solve` returned is from infeasible (mm), continuous in the
        bounds: the smallest of its distance to μ_hi, to the rotation cap (:meth:`rotation_cap`) and the
        slack of the cycle, −Σ max(A_i, g_i(y_i) − y_i) (the forced increments around the closed cycle must
        not add up to more than 0; (13) is often limited there, with y far below μ_hi)."""
        if self._last is None:
            return math.nan
        y, A, hi = self._last
        cycle = -float(np.sum(np.maximum(A, self.g(y[:-1]) - y[:-1])))
        return float(min(np.min(hi - y), np.min(self.rotation_cap() - y[:-1]), cycle))

    def _steps(self, t: float | None, T: float | None) -> tuple[FloatArray, FloatArray | None]:
        A = (t * self.dx - self.ds) if t is not None else np.full(self.dx.size, -1e3 * self.scale)
        return A, ((T * self.dx - self.ds) if T is not None else None)

    def _polish(self, y: FloatArray, A: FloatArray, B: FloatArray | None, hi: FloatArray,
                passes: int = 4) -> FloatArray | None:
        """Push every entry up to its own lower bounds (exact, elementwise): removes the rounding of the
        running sums and the recursion tolerance, which matter where dl/dμ is large (turnarounds)."""
        for _ in range(passes):
            old = y.copy()
            y[1:] = np.maximum(y[1:], np.maximum(y[:-1] + A, self.g(y[:-1])))
            if B is not None:
                y[:-1] = np.maximum(y[:-1], y[1:] - B)
            y[0] = y[-1] = max(y[0], y[-1])
            if np.array_equal(old, y):
                break
        if (y > hi + 1e-10 * self.scale).any():
            return None
        return y


def _fast_check(prob: _Problem, mu: FloatArray, t: float | None, T: float | None, tol: float) -> bool:
    """Exact check of a fast-path point: band, u bounds, no sag, no reverse rotation, cyclicity."""
    u = prob.u(mu)
    ok = bool((mu >= prob.mu_lo - 1e-9 * max(1.0, float(np.abs(prob.mu_lo).max()))).all()
              and (mu <= prob.mu_hi + 1e-9 * max(1.0, float(np.abs(prob.mu_hi).max()))).all())
    scale = max(1.0, float(np.abs(u).max()))
    if t is not None:
        ok &= bool(u.min() >= t - 1e-9 * scale)
    if T is not None:
        ok &= bool(u.max() <= T + 1e-9 * scale)
    ok &= all(float(v.min()) >= -tol for v in prob.nonlinear_values(mu).values())
    l = prob.l_of(mu)
    return ok and abs(float(l[0] - l[-1])) <= tol


def _bisect(feasible: Callable[[float], FloatArray | None], good: float, bad: float, rel: float = 1e-12,
            margin: Callable[[], float] | None = None, peek: Callable[[float], bool | None] | None = None
            ) -> tuple[float, FloatArray]:
    """Largest (or smallest, if bad < good) feasible parameter between good and bad; good must be feasible.

    Bisection to ``|bad − good| <= rel·scale``.  With ``margin`` (how far the last feasible answer is from
    infeasible, continuous and about 0 where the test flips) and ``peek`` (the feasibility test without
    its side effects: the warm start of later probes is not moved), midpoints that are certainly
    infeasible are not solved: the secant root ``e`` of the margin through the last two feasible points
    estimates the flip, one peek at ``e + 2·guard`` (guard = 1e-9·scale, ~100× the flip's dependence on
    the warm start) that fails marks every later midpoint at least ``guard`` beyond it infeasible at
    once.  Before there are two feasible points with different margins the peeks step from ``good``,
    growing 16-fold, until one finds the margin unchanged (it is bound elsewhere there); at most 6
    peeks per bisection.  The probes that are solved, their order and their warm starts are those of plain bisection,
    so the answer is bit for bit the same; only the certainly-infeasible solves are saved.
    """
    mu = feasible(good)
    if mu is None:
        raise _FastFail("bracket start is not feasible")
    scale = max(1.0, abs(good), abs(bad))
    tol = rel * scale
    guard = 1e-9 * scale
    pts: list[tuple[float, float]] = [(good, margin())] if margin is not None and peek is not None else []
    certain: float | None = None  # a parameter known infeasible (from a peek)
    peeks = 0
    step = 1e-6 * scale
    flat = False  # a step peek found the margin unchanged: no more step peeks
    while abs(bad - good) > tol:
        mid = 0.5 * (good + bad)
        d = 1.0 if bad > good else -1.0
        if certain is not None and d * (mid - certain) >= guard:
            bad = mid
            continue
        if pts and peeks < 6 and peek is not None:
            p: float | None = None
            (t1, m1), (t2, m2) = pts[-2] if len(pts) > 1 else (math.nan, math.nan), pts[-1]
            if len(pts) > 1 and m1 != m2 and math.isfinite(m1) and math.isfinite(m2):
                p = t2 + m2 * (t2 - t1) / (m1 - m2) + 2.0 * guard * d
            elif certain is None and not flat:  # no estimate yet: steps from good growing 16-fold
                p = good + step * d
                step *= 16.0
            if (p is not None and d * (p - good) > 0.0 and d * (mid - p) >= guard
                    and (certain is None or d * (certain - p) > 0.0)):
                peeks += 1
                ok = peek(p)
                if ok is False:
                    certain = p
                    bad = mid
                    continue
                if ok:
                    mp = margin()  # type: ignore[misc]
                    flat = flat or mp == pts[-1][1]  # the margin is bound elsewhere here: steps tell nothing
                    pts.append((p, mp))
        m = feasible(mid)
        if m is None:
            bad = mid
        else:
            good, mu = mid, m
            if pts:
                pts.append((good, margin()))  # type: ignore[misc]
    return good, mu


class _WarmProbe:
    """Feasibility probe of one pull-speed bound for the bisections of (13) and (14).

    ``bounds(x) -> (u_lo, u_hi)`` places the probed value; each call polls cancellation, counts, and
    warm-starts the propagation from the last feasible least solution (valid because the bisection
    only moves towards the optimum, where the least solution grows).
    """

    def __init__(self, tube: Any, state: State | None,
                 bounds: Callable[[float], tuple[float | None, float | None]]) -> None:
        self.tube, self.state, self.bounds = tube, state, bounds
        self.calls = 0
        self.warm: FloatArray | None = None

    def __call__(self, x: float) -> FloatArray | None:
        self.calls += 1
        check_cancel(self.state)
        lo, hi = self.bounds(x)
        mu = self.tube.solve(lo, hi, below=self.warm)
        if mu is not None:
            self.warm = mu
        return mu

    def margin(self) -> float:
        """How far the last feasible answer is from infeasible (mm): :meth:`_Tube.margin`."""
        return float(self.tube.margin())

    def peek(self, x: float) -> bool | None:
        """Feasibility at ``x`` without moving the warm start (None: the test could not settle)."""
        self.calls += 1
        check_cancel(self.state)
        lo, hi = self.bounds(x)
        try:
            return self.tube.solve(lo, hi, below=self.warm) is not None
        except _FastFail:
            return None


def _quiet_fp(fn: Callable[..., Any]) -> Callable[..., Any]:
    """``fn`` under ``np.errstate(divide="ignore", invalid="ignore")``: the interval propagation
    (:class:`_Tube`, used only inside the decorated stages) divides by zero and subtracts infinities on
    purpose (unbounded steps, no rotation cap) and handles the results itself.  One context for the whole
    stage instead of one per call (~8 000 calls of :meth:`_Tube.g` per example law, ~3 µs each); the
    numbers are the same."""
    import functools

    @functools.wraps(fn)
    def wrapped(*args: Any, **kwargs: Any) -> Any:
        with np.errstate(divide="ignore", invalid="ignore"):
            return fn(*args, **kwargs)

    return wrapped


@_quiet_fp
def _fast_lp13(prob: _Problem, state: State | None, tol: float) -> _Stage:
    """(13) by bisection on the lower u bound with the interval-propagation feasibility test."""
    if not prob.exact_cyclic:
        raise _FastFail("ends of the line differ (linearised cyclicity)")
    tube = _Tube(prob)
    tube.state = state
    U = prob.U
    t0 = time.perf_counter()
    # the least solution grows with t: the last feasible one (smaller t) is a valid start
    f13 = _WarmProbe(tube, state, lambda t: (t, None))

    if tube.solve(None, None) is None:
        raise _diagnose_infeasible(prob)
    # bracket: max min u <= mean u = U; go down until feasible
    if f13(U) is not None:
        t_star, mu13 = U, tube.solve(U, None)
    else:
        gap = 1.0
        while f13(U - gap) is None:
            gap *= 4.0
            if gap > 1e7:
                raise _FastFail("no finite lower pull-speed bound found")
        t_star, mu13 = _bisect(f13, U - gap, U if gap == 1.0 else U - gap / 4.0, margin=f13.margin, peek=f13.peek)
    assert mu13 is not None
    if not _fast_check(prob, mu13, t_star - 1e-9, None, tol):
        # the warm-started fixed point can keep a recursion residual that the turnarounds' large
        # dl/dμ magnify: solve once more from μ_lo
        mu13 = tube.solve(t_star - 1e-9 * max(1.0, abs(t_star)), None)
        if mu13 is None or not _fast_check(prob, mu13, t_star - 1e-9, None, CHECK_TOL):  # as in (14)
            raise _FastFail("(13) point failed the exact check")
    s13 = _Stage("maxmin", mu13, t_star, f13.calls, time.perf_counter() - t0)
    prob.update_rows(mu13, margin=10 * tol)
    return s13


@_quiet_fp
def _fast_lp14(prob: _Problem, u_lo: float, mu13: FloatArray, state: State | None, tol: float) -> _Stage:
    tube = _Tube(prob)
    tube.state = state
    t0 = time.perf_counter()
    # the least solution grows as T falls: the last feasible one (larger T) is a valid start
    f14 = _WarmProbe(tube, state, lambda T: (u_lo, T))

    hi = float(prob.u(mu13).max())
    hi = max(hi, prob.U) + 1e-9 * max(1.0, abs(hi))
    if f14(prob.U) is not None:
        T_star, mu = prob.U, tube.solve(u_lo, prob.U)
    else:
        T_star, mu = _bisect(f14, hi, prob.U, margin=f14.margin, peek=f14.peek)
    assert mu is not None
    if not _fast_check(prob, mu, u_lo, T_star + 1e-9, tol):
        mu = tube.solve(u_lo, T_star)  # as in (13): once more from μ_lo
        # the closed-form l(μ) round trip can leave ~1e-7 where dl/dμ is large; the report's own check
        # (CHECK_TOL) is what the answer must pass, and HiGHS would cost seconds on a refined grid
        if mu is None or not _fast_check(prob, mu, u_lo, T_star + 1e-9, CHECK_TOL):
            raise _FastFail("(14) point failed the exact check")
    prob.update_rows(mu, margin=10 * tol)
    return _Stage("minmax", mu, T_star, f14.calls, time.perf_counter() - t0)


class _CyclicKKT:
    """Newton matrices Q + Aᵀ·diag(d)·A of the cyclic (15) problem: symmetric cyclic tridiagonal.

    Every row of A has at most two entries, on neighbouring variables (i, i + 1 mod m); the matrix is
    assembled from them with ``np.bincount`` and solved by a banded Cholesky (LAPACK pbtrf/pbtrs) plus a
    Sherman–Morrison correction for the corner entry — O(m) per Newton step.
    """

    def __init__(self, Q: Any, A: Any) -> None:
        import scipy.sparse as sp

        m = Q.shape[0]
        self.m = m
        A = sp.csr_matrix(A)
        A.sort_indices()
        cnt = np.diff(A.indptr)
        if m < 4 or cnt.max() > 2:
            raise _FastFail("constraint rows are not pairs of neighbours")
        rows = A.shape[0]
        j1 = np.zeros(rows, dtype=np.int64)
        j2 = np.zeros(rows, dtype=np.int64)
        w1 = np.zeros(rows)
        w2 = np.zeros(rows)
        first = A.indptr[:-1]
        has = cnt >= 1
        j1[has] = A.indices[first[has]]
        w1[has] = A.data[first[has]]
        two = cnt == 2
        j2[two] = A.indices[first[two] + 1]
        w2[two] = A.data[first[two] + 1]
        # a pair (0, m-1) is the wrap-around interval m-1: order it as (m-1, 0)
        wrap = two & (j1 == 0) & (j2 == m - 1)
        j1[wrap], j2[wrap] = m - 1, 0
        w1[wrap], w2[wrap] = w2[wrap].copy(), w1[wrap].copy()
        if not ((~two) | wrap | (j2 == j1 + 1)).all():
            raise _FastFail("constraint rows are not pairs of neighbours")
        self.j1, self.j2, self.w1, self.w2 = j1, j2, w1, w2
        self.iv = np.where(two, j1, 0)
        self.pair = two
        Qc = sp.csr_matrix(Q)
        self.qd = Qc.diagonal().copy()
        idx = np.arange(m)
        self.qo = np.asarray(Qc[idx, (idx + 1) % m]).ravel()

    def factor(self, d: FloatArray) -> Callable[[FloatArray], FloatArray]:
        """The solve of the Newton system Q + Aᵀ·diag(d)·A (its diagonal and off-diagonal by ``np.bincount``)."""
        m = self.m
        dg = self.qd + np.bincount(self.j1, d * self.w1 * self.w1, m) + np.bincount(self.j2, d * self.w2 * self.w2, m)
        off = self.qo + np.bincount(self.iv, np.where(self.pair, d * self.w1 * self.w2, 0.0), m)
        cb, zu, g, c, denom = self.factor_parts(dg, off)
        dpbtrs = self._lapack()[1]

        def solve(rhs: FloatArray) -> FloatArray:
            x = dpbtrs(cb, rhs, lower=1)[0]
            return x - zu * ((g * x[0] + c * x[-1]) / g / denom)

        return solve

    @staticmethod
    def _lapack() -> tuple[Any, Any]:
        from engine._lightimport import flapack

        # what cholesky_banded / cho_solve_banded call, without their per-call argument checks (~0.15 ms
        # each, 3–4 calls per Newton step) and without importing scipy.linalg
        lp = flapack()
        return lp.dpbtrf, lp.dpbtrs

    def factor_parts(self, dg: FloatArray, off: FloatArray) -> tuple[Any, FloatArray, Any, Any, Any]:
        """The banded Cholesky factor of the matrix with diagonal ``dg`` and off-diagonal ``off`` (``off[-1]``
        the corner entry) less its corner, and the Sherman–Morrison terms ``(cb, zu, g, c, denom)``: a solve is
        ``x = pbtrs(cb, rhs); x − zu·((g·x₀ + c·x₋₁)/g/denom)``.  Raises LinAlgError where it is not positive
        definite."""
        dpbtrf, dpbtrs = self._lapack()
        m = self.m
        c = off[-1]  # M[m-1, 0]
        g = -dg[0]
        ab = np.zeros((2, m))
        ab[0] = dg
        ab[0, 0] -= g
        ab[0, -1] -= c * c / g
        ab[1, :-1] = off[:-1]
        cb, info = dpbtrf(ab, lower=1)
        if info != 0:
            raise np.linalg.LinAlgError(f"Newton matrix not positive definite (pbtrf info {info})")
        u = np.zeros(m)
        u[0], u[-1] = g, c
        zu = dpbtrs(cb, u, lower=1)[0]
        denom = 1.0 + (g * zu[0] + c * zu[-1]) / g
        return cb, zu, g, c, denom


def _vdot(a: FloatArray, b: FloatArray) -> float:
    """Dot product without BLAS: OpenBLAS threads its ddot above 10⁴ entries, and those threads
    spin-wait — on a busy 2-core machine one (15) QP at 4000 points went from 0.06 s to 0.6 s."""
    return float(np.add.reduce(a * b))


def _ipm_qp(Q: Any, c: FloatArray, A: Any, b: FloatArray, x0: FloatArray, max_iter: int = 100,
            kkt: _CyclicKKT | None = None, state: State | None = None) -> FloatArray | None:
    """min ½xᵀQx + cᵀx s.t. A x >= b by a Mehrotra predictor–corrector interior-point method.

    Q and AᵀA are cyclic tridiagonal here, so each Newton system is a sparse LU of that pattern.
    Returns None when it does not converge (the caller then uses HiGHS).
    """
    import scipy.sparse as sp

    m = A.shape[0]
    At = A.T.tocsr()
    x = np.asarray(x0, dtype=float).copy()
    r0 = A @ x - b
    s = np.maximum(r0, 1e-2)
    z = np.ones(m)
    bscale = 1.0 + float(np.abs(b).max())
    cscale = 1.0 + float(np.abs(c).max())
    if kkt is not None:
        from engine.payout_jit import ipm_kernels

        kern = ipm_kernels()
        if kern is not None and _ipm_fits(Q, c, A, At, b, x, kkt):
            return _ipm_compiled(kern, Q, np.ascontiguousarray(c, dtype=np.float64), A, At,
                                 np.ascontiguousarray(b, dtype=np.float64), x, s, z, bscale, cscale, max_iter,
                                 kkt, state)
    for _ in range(max_iter):
        check_cancel(state)
        Qx, Atz = Q @ x, At @ z
        rd = Qx + c - Atz
        rp = A @ x - s - b
        gap = _vdot(s, z)
        obj = abs(0.5 * _vdot(x, Qx) + _vdot(c, x))
        dscale = cscale + float(np.abs(Qx).max()) + float(np.abs(Atz).max())
        if (np.abs(rp).max() <= 1e-9 * bscale and np.abs(rd).max() <= 1e-7 * dscale
                and gap <= 1e-9 * max(1.0, obj)):
            return x
        d = z / s
        try:
            if kkt is not None:
                solve = kkt.factor(d)
            else:
                import scipy.sparse.linalg as spla  # here only: its import costs ~0.05 s, the cyclic path needs none

                solve = spla.splu((Q + At @ sp.diags(d) @ A).tocsc()).solve
        except (RuntimeError, np.linalg.LinAlgError, ValueError):
            return None
        rc = -s * z
        dx = solve(-rd + At @ ((rc - z * rp) / s))
        dsl = A @ dx + rp
        dz = (rc - z * dsl) / s

        def step(v: FloatArray, dv: FloatArray) -> float:
            with np.errstate(divide="ignore", invalid="ignore"):
                r = np.where(dv < 0, -v / dv, np.inf)
            return min(1.0, float(r.min()))

        a_aff = min(step(s, dsl), step(z, dz))
        mu_aff = _vdot(s + a_aff * dsl, z + a_aff * dz) / m
        sigma = (mu_aff / (gap / m)) ** 3 if gap > 0 else 0.0
        rc = -s * z - dsl * dz + sigma * gap / m
        dx = solve(-rd + At @ ((rc - z * rp) / s))
        dsl = A @ dx + rp
        dz = (rc - z * dsl) / s
        a = min(1.0, 0.995 * min(step(s, dsl), step(z, dz)))
        x += a * dx
        s += a * dsl
        z += a * dz
        if not (np.isfinite(x).all() and np.isfinite(z).all()):
            return None
    return None


def _csr_parts(M: Any) -> tuple[NDArray[np.int64], NDArray[np.int64], FloatArray]:
    """A compressed sparse matrix's index pointers, indices (int64) and data (float64), C-contiguous."""
    return (np.ascontiguousarray(M.indptr, dtype=np.int64), np.ascontiguousarray(M.indices, dtype=np.int64),
            np.ascontiguousarray(M.data, dtype=np.float64))


def _ipm_fits(Q: Any, c: Any, A: Any, At: Any, b: Any, x: FloatArray, kkt: _CyclicKKT) -> bool:
    """Whether :func:`_ipm_compiled` takes these: Q in CSC or CSR, A and Aᵀ in CSR, float64 data, sizes that match."""
    n, m = x.shape[0], A.shape[0]
    return (getattr(Q, "format", None) in ("csc", "csr") and getattr(A, "format", None) == "csr"
            and getattr(At, "format", None) == "csr" and Q.shape == (n, n) and A.shape == (m, n)
            and kkt.m == n and kkt.j1.shape[0] == m and np.shape(c) == (n,) and np.shape(b) == (m,)
            and all(M.dtype == np.float64 for M in (Q, A, At)) and n >= 1 and m >= 1)


def _ipm_compiled(kern: tuple[Any, ...], Q: Any, c: FloatArray, A: Any, At: Any, b: FloatArray, x: FloatArray,
                  s: FloatArray, z: FloatArray, bscale: float, cscale: float, max_iter: int, kkt: _CyclicKKT,
                  state: State | None) -> FloatArray | None:
    """:func:`_ipm_qp`'s iterations on the cyclic problem by the compiled kernels (engine.payout_jit), the
    banded Cholesky by LAPACK as before: the same operations in the same order, the same bits."""
    res_k, fac_k, rhs_k, aff_k, fin_k = kern
    dpbtrs = kkt._lapack()[1]
    n, m = x.shape[0], s.shape[0]
    Qp, Qi, Qd = _csr_parts(Q)
    qcsc = Q.format == "csc"
    Ap, Ai, Ad = _csr_parts(A)
    Tp, Ti, Td = _csr_parts(At)
    pair = np.ascontiguousarray(kkt.pair, dtype=np.bool_)
    j1, j2, iv = (np.ascontiguousarray(a, dtype=np.int64) for a in (kkt.j1, kkt.j2, kkt.iv))
    w1, w2, qd, qo = (np.ascontiguousarray(a, dtype=np.float64) for a in (kkt.w1, kkt.w2, kkt.qd, kkt.qo))
    Qx, Atz, rd, rhs, dx = (np.empty(n) for _ in range(5))
    rp, rc, t, dsl, dz = (np.empty(m) for _ in range(5))
    w = np.empty(max(n, m))
    dg, off = np.empty(kkt.m), np.empty(kkt.m)
    info = np.empty(8)
    for _ in range(max_iter):
        check_cancel(state)
        res_k(Qp, Qi, Qd, qcsc, Ap, Ai, Ad, Tp, Ti, Td, x, s, z, c, b, Qx, Atz, rd, rp, w, info)
        gap = float(info[0])
        obj = abs(0.5 * float(info[1]) + float(info[2]))
        dscale = cscale + float(info[3]) + float(info[4])
        if info[5] <= 1e-9 * bscale and info[6] <= 1e-7 * dscale and gap <= 1e-9 * max(1.0, obj):
            return x
        fac_k(s, z, j1, j2, iv, pair, w1, w2, qd, qo, dg, off)
        try:
            cb, zu, g, cc, denom = kkt.factor_parts(dg, off)
        except (RuntimeError, np.linalg.LinAlgError, ValueError):
            return None
        zu = np.ascontiguousarray(zu, dtype=np.float64)
        g, cc, denom = float(g), float(cc), float(denom)
        rhs_k(Tp, Ti, Td, s, z, rp, rd, dsl, dz, False, 0.0, rc, t, rhs)
        x1 = np.ascontiguousarray(dpbtrs(cb, rhs, lower=1)[0], dtype=np.float64)
        aff_k(x1, zu, g, cc, denom, Ap, Ai, Ad, rp, rc, s, z, dx, dsl, dz, w, info)
        mu_aff = float(info[1]) / m
        sigma = (mu_aff / (gap / m)) ** 3 if gap > 0 else 0.0
        rhs_k(Tp, Ti, Td, s, z, rp, rd, dsl, dz, True, sigma * gap / m, rc, t, rhs)
        x1 = np.ascontiguousarray(dpbtrs(cb, rhs, lower=1)[0], dtype=np.float64)
        if not fin_k(x1, zu, g, cc, denom, Ap, Ai, Ad, rp, rc, s, z, dx, dsl, dz, x):
            return None
    return None


def _fast_qp_stage(prob: _Problem, u_lo: float, u_hi: float, mu0: FloatArray, state: State | None,
                   tol: float, max_iter: int = 40) -> tuple[_Stage, str]:
    """(15) with the same cutting-plane loop as the HiGHS path, each QP by :func:`_ipm_qp` over μ_0..μ_{N−2}."""
    import scipy.sparse as sp

    t0 = time.perf_counter()
    n = prob.n
    W = sp.diags(1.0 / prob.dx)
    D = prob.D
    Qf = (2.0 * (D.T @ W @ D)).tocsc()
    rhs = prob.ds - prob.U * prob.dx
    cf = 2.0 * (D.T @ (rhs / prob.dx))
    const = float(np.sum(rhs * rhs / prob.dx))
    mu = mu0
    if u_hi - u_lo <= 1e-6 * max(1.0, abs(u_hi)):
        val = float(0.5 * mu @ (Qf @ mu) + cf @ mu) + const
        return _Stage("jerk", mu, val, 0, time.perf_counter() - t0), "none (band of zero width)"
    # cyclic: μ_{N−1} = μ_0, variables y = μ_0..μ_{N−2}
    P = sp.vstack([sp.identity(n - 1, format="csr"), sp.csr_matrix(([1.0], ([0], [0])), shape=(1, n - 1))],
                  format="csr")
    Q = (P.T @ Qf @ P).tocsc()
    c = P.T @ cf
    lo = prob.mu_lo[:-1].copy()
    hi = prob.mu_hi[:-1].copy()
    lo[0], hi[0] = max(lo[0], prob.mu_lo[-1]), min(hi[0], prob.mu_hi[-1])
    I = sp.identity(n - 1, format="csr")
    DP = (D @ P).tocsr()

    def objective(m: FloatArray) -> float:
        return float(0.5 * m @ (Qf @ m) + cf @ m) + const

    def cutting_planes(mu: FloatArray, iters: int, slack: float = 0.0) -> tuple[FloatArray, int, bool]:
        it, worst = 0, np.inf
        for it in range(1, iters + 1):  # noqa: B007 - returned below
            check_cancel(state)
            G, h = prob.cut_rows(mu, slack)
            A = sp.vstack([I, -I, DP, -DP, (G @ P).tocsr()], format="csr")
            b = np.concatenate([lo, -hi, u_lo * prob.dx - prob.ds, prob.ds - u_hi * prob.dx, h])
            try:
                kkt: _CyclicKKT | None = _CyclicKKT(Q, A)
            except _FastFail:
                kkt = None
            y = _ipm_qp(Q, c, A, b, mu[:-1], kkt=kkt, state=state)
            if y is None:
                raise _FastFail("interior-point QP did not converge")
            mu = P @ np.clip(y, lo, hi)
            worst = prob.update_rows(mu, margin=10 * tol)
            if worst <= tol:
                break
        return mu, it, worst <= tol

    try:
        mu, it, ok = cutting_planes(mu, max_iter)
    except _FastFail:
        # the band stage's answer sits on the boundary of the rows it made tight, inside the exact check's
        # tolerance: with the u band as tight, the cuts (exact at μ) can leave no interior; re-try with
        # that tolerance as slack
        if not _fast_check(prob, mu0, u_lo, u_hi, tol):
            raise
        mu, it, ok = cutting_planes(mu0, max_iter, slack=tol)
    val = objective(mu)
    if ok:
        mu, val, it2 = _polish_cuts(prob, mu, val, lambda m: cutting_planes(m, max_iter), objective, tol)
        it += it2
    return _Stage("jerk", mu, val, it, time.perf_counter() - t0), "interior point (cyclic tridiagonal KKT)"


def min_range_law(line: Any, mandrel: Any, spec: Any = None, workspace: Workspace | None = None,
                  state: State | None = None, *, k: int | None = None, parameter: str | None = None,
                  grid_points: int | None = None, solver: str = "fast", refine: bool = True) -> EyePath:
    """The technological law (13)–(15): the free length with the narrowest, smoothest pull speed.

    Solves, on ``spec.grid_points`` points of x: (13) max min u → u_min*; (14) min max u with
    u >= u_min* → u_max*; (15) min ∫(u − U)² dx with u_min* <= u <= u_max*.  All subject to
    cyclicity, no sag, no reverse rotation and the clearance/workspace envelope.  The final answer is
    checked with the exact nonlinear formulas (``report['constraints']``), and again at every line point
    with l interpolated as the program uses it; where that fails (or u leaves the band) those line
    points join the grid and the law is solved again (``refine``; ``report['line']``).

    Raises
    ------
    InfeasibleError
        The envelope is empty somewhere, the constraints contradict each other, or the best
        achievable lower pull speed is below ``spec.u_min``; the message says which and where.
    """
    from engine.job import PayoutSpec

    spec = spec if spec is not None else PayoutSpec()
    k = spec.impregnation_k if k is None else int(k)
    parameter = spec.parameter if parameter is None else parameter
    if solver not in ("fast", "highs"):
        raise InputError(f"solver must be 'fast' or 'highs', got {solver!r}")
    return _refined(line, mandrel, spec, workspace, state, refine, lambda extra, st, con, cache: _min_range_grid(
        line, mandrel, spec, workspace, st, k, parameter, grid_points, solver, extra, con, cache))


def _min_range_grid(line: Any, mandrel: Any, spec: Any, workspace: Workspace | None, state: State | None, k: int,
                    parameter: str, grid_points: int | None, solver: str, extra: NDArray[np.int64] | None,
                    contour: _Contour, cache: _EnvCache | None = None) -> EyePath:
    """:func:`min_range_law` on the grid (plus the line points ``extra``)."""
    geo, env, _ = _prepare(line, mandrel, spec, parameter, grid_points, workspace, state, extra, contour, cache)
    prob = _Problem(geo, env, k)
    tol = 0.1 * CHECK_TOL  # exact violation accepted by the cutting-plane loops (speed or rad/mm units)
    # start: the lower envelope (admissible), made cyclic by the larger end value
    mu0 = prob.mu_lo.copy()
    t_start = time.perf_counter()
    fallback: list[str] = []
    s13: _Stage | None = None
    if solver == "fast":
        try:
            s13 = _fast_lp13(prob, state, tol)
        except _FastFail as exc:
            fallback.append(f"(13): {exc}")
    if s13 is None:
        s13 = _solve_lp_stage(prob, "maxmin", None, mu0, state, tol)
    u13 = s13.value
    if state is not None:
        state.progress(0.45, "(13) max min u")
    u_floor = float(spec.u_min)
    if u13 < u_floor - 1e-9:
        u = prob.u(s13.mu)
        i = int(np.argmin(u))
        raise InfeasibleError(
            f"the pull speed cannot be kept at u >= u_min = {u_floor:g}: the best lower bound is {u13:.6g}, "
            f"limited at x = {0.5 * (geo.x[i] + geo.x[i + 1]):.6g} (z = {geo.line.z[i]:.5g} mm)",
            field="payout.u_min")
    u_lo = u13 - 1e-7 * max(1.0, abs(u13))
    s14: _Stage | None = None
    if solver == "fast" and not fallback:
        try:
            s14 = _fast_lp14(prob, u_lo, s13.mu, state, tol)
        except _FastFail as exc:
            fallback.append(f"(14): {exc}")
    if s14 is None:
        s14 = _solve_lp_stage(prob, "minmax", u_lo, s13.mu, state, tol)
    if state is not None:
        state.progress(0.7, "(14) min max u")
    u_hi = s14.value + 1e-7 * max(1.0, abs(s14.value))
    # the narrowest band itself: (13) then (14) fixes the lower bound first, and a law with a lower
    # u_min may have a narrower band (pipe.toml: equidistant 3.578 < 3.650); take the narrower one
    mu_band = s14.mu
    band_from = "(13) max min u, then (14) min max u"
    s_rng, t_rng, T_rng = _solve_range_stage(prob, u_floor, s14.mu, state, tol, carry=cache)
    scale = max(1.0, abs(s14.value), abs(u13))
    if s_rng.value < (s14.value - u13) - 1e-7 * scale:
        u_lo = t_rng - 1e-7 * max(1.0, abs(t_rng))
        u_hi = T_rng + 1e-7 * max(1.0, abs(T_rng))
        mu_band = s_rng.mu
        band_from = "min (u_max − u_min) (narrower than (13) then (14))"
    if state is not None:
        state.progress(0.8, "narrowest band")
    s15: _Stage | None = None
    if solver == "fast" and prob.exact_cyclic:
        try:
            s15, backend = _fast_qp_stage(prob, u_lo, u_hi, mu_band, state, tol)
        except _FastFail as exc:
            fallback.append(f"(15): {exc}")
    if s15 is None:
        s15, backend = _solve_qp_stage(prob, u_lo, u_hi, mu_band, state, tol)
    solve_s = time.perf_counter() - t_start
    if state is not None:
        state.progress(0.95, "(15) jerk")
    l = prob.l_of(s15.mu)
    eye = _build(geo, l, k, parameter, "min-range", env)
    rep = _report(geo, eye, env, u_floor, extra={
        "solver": {
            "lp": ("interval propagation + bisection (exact nonlinear no-sag/rotation bounds)"
                   if solver == "fast" and not any(f.startswith(("(13)", "(14)")) for f in fallback)
                   else "scipy.optimize.linprog (HiGHS)"),
            "fallback": fallback,
            "qp": backend,
            "variables": "mu = l - k*R(l) (exact), nonlinear rows by cutting planes",
            "iterations": {"13": s13.iterations, "14": s14.iterations, "15": s15.iterations},
            "seconds": {"13": s13.seconds, "14": s14.seconds, "15": s15.seconds, "total": solve_s},
            "nonlinear_rows": {kk: len(v) for kk, v in prob.rows.items()},
            "u_min_13": u13,
            "u_max_14": s14.value,
            "range_lp": {"u_min": t_rng, "u_max": T_rng, "u_range": s_rng.value, "iterations": s_rng.iterations,
                         "seconds": s_rng.seconds},
            "band_15": [u_lo, u_hi],
            "band_from": band_from,
            "jerk_15": s15.value,
        }
    })
    if state is not None:
        state.progress(1.0, "min-range law done")
    return _with_report(eye, rep)


# ------------------------------------------------------------------------------------------------
# A reference line (closed form) for tests and benchmarks
# ------------------------------------------------------------------------------------------------
def reference_vessel_circuit(radius: float = 100.0, cylinder_length: float = 300.0, C: float = 40.0,
                             n: int = 2000) -> ContactLine:
    """One closed geodesic circuit on a cylinder with hemispherical domes, in closed form (mm, rad).

    Helix (β0 = asin(C/radius)) along the cylinder, a great-circle half on the right dome (turning at
    r = C), the helix back and a great-circle half on the left dome; it starts and ends at z = 0
    going +z.  On ``Mandrel.vessel(radius, cylinder_length, "hemisphere", pole_radii=p)`` with p < C.
    """
    a = float(radius)
    if not 0 < C < a:
        raise InputError(f"Clairaut constant must be in (0, {a:g}) mm, got {C!r}")
    b0 = math.asin(C / a)
    sa, ca = math.cos(b0), C / a  # sin α, cos α of the great-circle plane
    lh = cylinder_length / math.cos(b0)
    ld = math.pi * a
    total = 2 * lh + 2 * ld
    parts: list[dict[str, FloatArray]] = []
    v0, s0 = 0.0, 0.0
    for seg in range(4):
        if seg % 2 == 0:  # helix
            m = max(8, int(n * lh / total))
            t = np.linspace(0.0, lh, m, endpoint=False)
            sign = 1.0 if seg == 0 else -1.0
            z = (0.0 if seg == 0 else cylinder_length) + sign * t * math.cos(b0)
            part = {"z": z, "r": np.full(m, a), "dr": np.zeros(m), "v": v0 + t * math.sin(b0) / a,
                    "beta": np.full(m, b0), "direction": np.full(m, sign), "s": s0 + t}
            v0, s0 = v0 + lh * math.sin(b0) / a, s0 + lh
        else:  # dome: p(φ) = a(cos φ, sin φ cos α, sin φ sin α) about the dome centre
            m = max(8, int(n * ld / total))
            phi = np.linspace(0.0, math.pi, m, endpoint=False)
            sign = 1.0 if seg == 1 else -1.0
            zc = cylinder_length if seg == 1 else 0.0
            dz = sign * a * np.sin(phi) * sa
            r = a * np.sqrt(np.cos(phi) ** 2 + (np.sin(phi) * ca) ** 2)
            vloc = np.unwrap(np.arctan2(np.sin(phi) * ca, np.cos(phi)))
            direction = sign * np.where(np.cos(phi) >= 0, 1.0, -1.0)
            part = {"z": zc + dz, "r": r, "dr": -dz / r, "v": v0 + vloc,
                    "beta": np.arcsin(np.clip(C / r, 0.0, 1.0)), "direction": direction, "s": s0 + a * phi}
            v0, s0 = v0 + math.pi, s0 + ld
        parts.append(part)
    end = {"z": np.array([0.0]), "r": np.array([a]), "dr": np.array([0.0]), "v": np.array([v0]),
           "beta": np.array([b0]), "direction": np.array([1.0]), "s": np.array([s0])}
    parts.append(end)
    cat = {k: np.concatenate([p[k] for p in parts]) for k in end}
    return ContactLine(**cat)


# ------------------------------------------------------------------------------------------------
# Job level
# ------------------------------------------------------------------------------------------------
def payout_law(line: Any, mandrel: Any, spec: Any = None, law: str | None = None,
               workspace: Workspace | None = None, state: State | None = None, **kw: Any) -> EyePath:
    """Dispatch to :func:`geometric_law` or :func:`min_range_law` by ``law`` (default ``spec.law``)."""
    from engine.job import PayoutSpec

    spec = spec if spec is not None else PayoutSpec()
    law = spec.law if law is None else law
    if law == "min-range":
        return min_range_law(line, mandrel, spec, workspace=workspace, state=state, **kw)
    return geometric_law(line, mandrel, law, spec, workspace=workspace, state=state, **kw)


def payout_for_job(job: Any, line: Any, mandrel: Any, state: State | None = None, law: str | None = None,
                   workspace: Workspace | None = None) -> EyePath:
    """The eye path of the job's first circuit (the pattern repeats it), by ``job.payout``.

    ``line`` is the job's WindingLine (or any ContactLine-like object with an optional ``circuit``).
    Use :func:`extend_to_line` to evaluate the law at every point of the full line.
    """
    one = getattr(line, "one_circuit", None)  # WindingLine: first circuit including its closing point
    if one is not None and not isinstance(line, ContactLine):
        cl = ContactLine.from_line(one() if callable(one) else one)
    else:
        cl = ContactLine.from_line(line).first_circuit()
    return payout_law(cl, mandrel, job.payout, law=law, workspace=workspace, state=state)


REPLICATE_MIN_CIRCUITS = 8
"""From this many circuits on, :func:`extend_to_line` evaluates the eye path on the first circuit and
turns it by k·Δv for circuit k (the winding line is circuit 0 turned, :func:`engine.winding._assemble`);
smaller programs are evaluated point by point.  (It was 100 until 2026-11-29, which kept the shipped
examples, 28-74 circuits, on the point-by-point path and their NC files bit for bit as before; turning
circuit 0 gives the same eye path to ~1e-12 relative, and the examples' programs the same axis words and
program times to the millisecond, 7-12 % faster - docs/speed.md.)"""


def extend_to_line(eye: EyePath, line: Any) -> EyePath:
    """Evaluate ``eye``'s law l(x) at every point of ``line`` (all circuits: l repeats each circuit).

    l is interpolated linearly in the within-circuit parameter; grid points of the first circuit
    keep their exact value.  A WindingLine of at least :data:`REPLICATE_MIN_CIRCUITS` circuits that
    repeat circuit 0 turned about the axis gets circuit 0's eye path turned the same way (equal to the
    point-by-point evaluation to rounding, about 1e-12 relative; tests/test_payout_cli.py).
    """
    rep = _extend_replicated(eye, line)
    if rep is not None:
        return rep
    return _extend_pointwise(eye, line)


def _extend_replicated(eye: EyePath, line: Any) -> EyePath | None:
    """:func:`extend_to_line` by turning circuit 0's eye path; None when ``line`` is not such a line."""
    nc = int(getattr(line, "circuits", 1) or 1)
    m = int(getattr(line, "points_per_circuit", 0) or 0)
    take = getattr(line, "take_circuit", None)
    twist = getattr(line, "twist_per_circuit_rad", None)
    if nc < REPLICATE_MIN_CIRCUITS or m < 2 or take is None or twist is None or eye.parameter not in ("s", "v"):
        return None
    from engine.periodic import deferred

    n = nc * m + 1
    dz = deferred(line, "z")
    if (len(dz) if dz is not None else np.shape(line.z)[0]) != n:
        return None
    # the line must repeat circuit 0: exactly in z, r, r', β and the direction, v shifted by Δv per circuit
    # (a field kept as circuit 0 + rule, engine.periodic.CircuitArray "tile", does by construction)
    for name in ("z", "r", "dr", "beta", "direction"):
        d = deferred(line, name)
        if d is not None and d.kind == "tile" and (d.circuits, d.m) == (nc, m):
            continue
        a = np.asarray(getattr(line, name))
        if a.shape != (n,):
            return None
        if not np.array_equal(a[:-1].reshape(nc, m), np.broadcast_to(a[:m], (nc, m))) or a[-1] != a[m]:
            return None
    dv = deferred(line, "v")
    kk = np.arange(nc)
    if dv is not None:   # a rule: the circuits' first rows and the last one only (v made below if x is v)
        v: FloatArray | None = None
        v_start, v_last = dv.take(kk * m), float(dv.rows(n - 1, n)[0])
    else:
        v = np.asarray(line.v, dtype=float)
        v_start, v_last = v[kk * m], float(v[-1])
    if np.any(np.abs(v_start - v_start[0] - kk * float(twist)) > 1e-9 * (1.0 + abs(v_last))):
        return None
    one_line = take(0)
    one = _extend_pointwise(eye, one_line)
    if one.index.size != m + 1:      # zero-length steps dropped: evaluate point by point
        return None

    from engine.periodic import CircuitArray, DerivedArray, field_rows, raw_field_or

    # the eye path's per-point arrays are kept as circuit 0 + rule (engine.periodic.CircuitArray, the
    # arithmetic of the arrays made before: bit for bit) and materialised on first read
    ang = kk * float(twist)
    cos_k, sin_k = np.cos(ang), np.sin(ang)

    def tile(a: FloatArray) -> CircuitArray:
        return CircuitArray("tile", np.ascontiguousarray(a), nc, m)

    def turned(a: FloatArray) -> CircuitArray:
        cols = tuple(np.ascontiguousarray(a[:, i]) for i in range(3))
        return CircuitArray("turn", cols, nc, m, cos_k=cos_k, sin_k=sin_k)

    # the line's own points are circuit 0's turned by the same k·Δv with the same arithmetic
    # (engine.winding._assemble): where they match bit for bit the eye path shares the line's array
    xyz = raw_field_or(line, "xyz")   # (hasattr would materialise it)
    contact: Any = None
    if xyz is not None:
        c0 = one.contact_xyz
        ref = turned(c0)

        if (tuple(xyz.shape) == (n, 3) and xyz.dtype == np.float64
                and np.array_equal(field_rows(line, "xyz", 0, m + 1), c0)
                and all(np.array_equal(field_rows(line, "xyz", k * m, (k + 1) * m), ref.rows(k * m, (k + 1) * m))
                        for k in (1, nc // 2))
                and np.array_equal(field_rows(line, "xyz", n - 1, n), ref.rows(n - 1, n))):
            contact = xyz
    if contact is None:
        contact = turned(one.contact_xyz)
    s_all = np.asarray(line.s, dtype=float)
    l, R = tile(one.l), tile(one.R)
    # V, λ, u and x_mid: made on first read from their operands, with the whole-array arithmetic
    # (engine.periodic.DerivedArray; no stage of a CLI run reads them whole)
    v_rule = dv if dv is not None else v
    if eye.parameter == "s":
        x = s_all
    else:
        x = v if v is not None else dv.materialise()   # type: ignore[union-attr]
    V = DerivedArray("add", (v_rule, tile(one.V - np.asarray(one_line.v, dtype=float))), n)
    lam = DerivedArray("pulled", (s_all, l, R, one.k), n)
    out = EyePath(
        x=x, index=CircuitArray("shift", np.arange(m + 1, dtype=np.int64), nc, m, m), l=l, Z=tile(one.Z), R=R,
        V=V, eye_xyz=turned(one.eye_xyz), contact_xyz=contact, fibre_dir=turned(one.fibre_dir),
        s=s_all, lam_pulled=lam, u=DerivedArray("slope", (lam, x), n - 1), x_mid=DerivedArray("mid", (x,), n - 1),
        law=eye.law, k=one.k, parameter=eye.parameter,
    )
    return _with_report(out, {"law": eye.law, "extended_from_points": int(eye.x.size), "points": n,
                              "replicated_circuits": nc})


def _extend_pointwise(eye: EyePath, line: Any) -> EyePath:
    """:func:`extend_to_line` evaluated at every point."""
    cl = ContactLine.from_line(line)
    x_all = _parameter(cl, eye.parameter)
    circ = cl.circuit if cl.circuit is not None else np.zeros(cl.z.size, dtype=np.int64)
    # x of each point's circuit start: circuits are runs of equal numbers (slices, no per-circuit
    # masks); a circuit number that comes back after another one falls back to its first occurrence.
    run_start = np.flatnonzero(np.concatenate([[True], circ[1:] != circ[:-1]]))
    if np.unique(circ[run_start]).size == run_start.size:
        first = np.repeat(run_start, np.diff(np.append(run_start, circ.size)))
    else:
        _, first_idx, inverse = np.unique(circ, return_index=True, return_inverse=True)
        first = first_idx[inverse]
    xc = x_all - x_all[first] + eye.x[0]
    period = float(eye.x[-1] - eye.x[0])
    if period > 0:
        xc = eye.x[0] + np.mod(xc - eye.x[0], period * (1 + 1e-12))
    l = np.interp(xc, eye.x, eye.l)
    del xc, first
    idx = np.arange(cl.z.size)
    a, b, c3 = tangent_components(cl.r, cl.dr, cl.beta, cl.direction)
    geo = _Geo(cl, x_all, a, b, c3, idx.astype(np.int64))
    keep = np.concatenate([[True], np.diff(x_all) > 0])
    if not keep.all():  # u undefined on zero-length steps: evaluate on the strictly increasing subset
        geo = _Geo(cl.take(idx[keep]), x_all[keep], a[keep], b[keep], c3[keep], idx[keep].astype(np.int64))
        l = l[keep]
    out = _build(geo, l, eye.k, eye.parameter, eye.law)
    return _with_report(out, {"law": eye.law, "extended_from_points": int(eye.x.size), "points": int(l.size)})


__all__ = [
    "BoxWorkspace",
    "ContactLine",
    "Envelope",
    "EyePath",
    "GEOMETRIC_LAWS",
    "LAWS",
    "Workspace",
    "envelope",
    "extend_to_line",
    "eye_path",
    "geometric_law",
    "min_range_law",
    "parallel_free_length",
    "payout_for_job",
    "payout_law",
    "reference_vessel_circuit",
    "tangent_components",
]
