"""Programs whose circuits repeat: compute a few circuits, keep and replicate the rest (issue 16,
docs/speed.md).

The winding line of a program is circuit 0 turned by k·Δv about the mandrel axis
(:func:`engine.winding._assemble`) and the payout stage turns circuit 0's eye path the same way
(:func:`engine.payout.extend_to_line`, from :data:`engine.payout.REPLICATE_MIN_CIRCUITS` circuits on).

* :class:`CircuitArray` keeps a per-point array as circuit 0 + the rule that makes circuit k;
  :class:`DeferredField` makes a dataclass field hold one and materialise it on first read (the line,
  the eye path and the axis path of a program of :data:`DEFER_MIN_CIRCUITS` circuits or more);
  :func:`field_rows`, :func:`field_take`, :func:`raw_field` and :func:`replace_raw` read such fields
  without materialising them.
* The machine sees the same motion every circuit: every axis repeats, the mandrel axis advanced by a
  constant angle per circuit.  :func:`replicate_axes` runs the axes stage on the first three circuits
  only, checks that circuits 1 and 2 repeat (every axis equal, the mandrel advanced by one constant)
  and builds the whole axis path from them; whenever the check fails (or the short path reports any
  violation, ...) it returns None and the caller computes every point.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from typing import Any

import numpy as np

#: circuits from which the winding line keeps its per-point arrays as circuit 0 + rule (:class:`CircuitArray`),
#: materialised on first use (as :data:`engine.payout.REPLICATE_MIN_CIRCUITS`; the axes stage replicates from
#: ``_SHORT_CIRCUITS + 2`` = 5 circuits on)
DEFER_MIN_CIRCUITS = 8

#: relative tolerance of the periodicity check of the axis path (of 1 + the axis' largest |value|)
PERIODIC_RTOL = 1e-9

#: rows per piece where a whole per-point field is reduced piece by piece (:func:`row_chunks`)
CHUNK_ROWS = 1 << 19

#: the short path: this many circuits (circuit 0 may differ from the others by its start; 1 and 2 are compared)
_SHORT_CIRCUITS = 3


def replicated_circuits(line: Any, eye: Any) -> tuple[int, int] | None:
    """``(circuits, points_per_circuit)`` when ``eye`` is the payout stage's replicated eye path of
    ``line`` (circuit 0 turned by k·Δv, one path point per line point), else None."""
    if eye is None or line is None:
        return None
    report = getattr(eye, "report", None) or {}
    nc = int(getattr(line, "circuits", 1) or 1)
    m = int(getattr(line, "points_per_circuit", 0) or 0)
    if report.get("replicated_circuits") != nc or nc < _SHORT_CIRCUITS + 2 or m < 2:
        return None
    n = nc * m + 1
    if tuple(np.shape(raw_field(eye, "s"))) != (n,) or tuple(raw_field(eye, "eye_xyz").shape) != (n, 3):
        return None
    return nc, m


def eye_head(eye: Any, npts: int) -> Any:
    """The first ``npts`` points of an :class:`engine.payout.EyePath` (views where possible)."""
    per_point = ("x", "index", "l", "Z", "R", "V", "eye_xyz", "contact_xyz", "fibre_dir", "s", "lam_pulled")
    per_step = ("u", "x_mid")
    kw: dict[str, Any] = {f: field_rows(eye, f, 0, npts) for f in per_point}
    kw.update({f: field_rows(eye, f, 0, npts - 1) for f in per_step})
    for f in ("l_min", "l_max"):
        a = getattr(eye, f, None)
        if a is not None and np.shape(a)[:1] == np.shape(eye.s):
            kw[f] = a[:npts]
    return replace(eye, **kw)


def tile_circuits(head: np.ndarray, nc: int, m: int, step: np.ndarray | float | None = None) -> np.ndarray:
    """The whole path of ``nc`` circuits of ``m`` points (+ the closing point) from the first three
    circuits ``head`` (``3m + 1`` rows): circuit 0 as it is, circuit k >= 1 = circuit 1 + (k-1)·``step``
    (per column; None = no step), the closing point = ``head[m] + (nc-1)·step``."""
    head = np.asarray(head)
    out = np.empty((nc * m + 1,) + head.shape[1:], dtype=head.dtype)
    out[:m] = head[:m]
    body = out[m:nc * m].reshape((nc - 1, m) + head.shape[1:])
    body[:] = head[m:2 * m]
    if step is not None:
        k = np.arange(nc - 1, dtype=float)
        st = np.asarray(step, dtype=float)
        if st.ndim == 0:
            body += k[:, None] * st
        else:
            nz = np.flatnonzero(st)                      # add only to the columns that advance
            for j in nz.tolist():
                body[..., j] += k[:, None] * st[j]
        out[-1] = head[m] + (nc - 1) * st
    else:
        out[-1] = head[m]
    return out


def repeats(head: np.ndarray, m: int, rtol: float = PERIODIC_RTOL) -> np.ndarray | None:
    """The per-circuit step of every column of ``head`` (3m + 1 rows) when circuit 2 is circuit 1 plus
    a constant per column (to ``rtol`` of 1 + the column's largest |value|), else None."""
    a = np.asarray(head, dtype=float)
    if a.shape[0] != _SHORT_CIRCUITS * m + 1:
        return None
    c1, c2 = a[m:2 * m + 1], a[2 * m:3 * m + 1]
    step = c2[0] - c1[0]
    scale = 1.0 + np.abs(a).max(axis=0)
    if np.any(np.abs(c2 - c1 - step) > rtol * scale):
        return None
    return step


def replicate_axes(line: Any, eye: Any, run_axes: Callable[[Any], tuple[Any, Any, Any]]
                   ) -> tuple[Any, Any, Any] | None:
    """The axes stage of a program whose circuits repeat, from its first three circuits.

    ``run_axes(eye_path)`` is the axes stage (``-> (machine, AxisPath, placement)``).  It is run on the
    first three circuits of ``eye``; the result is used when that short path has no violation, the
    placement fits and circuit 2 repeats circuit 1 (to :data:`PERIODIC_RTOL`) with only the mandrel axis
    advanced by a constant (:func:`repeats`) and the eye slid along its fibre by the same amounts
    (``eye_shift``).  The whole axis path is then circuit 0 and circuit 1 advanced by k times that
    constant (:func:`tile_circuits`); ``fibre_dir`` and ``contact_xyz`` are the eye path's own arrays
    (no copy), ``eye_xyz`` too where the eye was not slid.  Returns None (compute every point) otherwise.
    """
    rc = replicated_circuits(line, eye)
    if rc is None:
        return None
    nc, m = rc
    machine, axes, placement = run_axes(eye_head(eye, _SHORT_CIRCUITS * m + 1))
    if axes.violations:
        return None
    if placement is not None and not placement.fits:
        return None
    step = repeats(axes.q, m)
    k_mandrel = machine.axis_index("mandrel")
    if step is None or k_mandrel is None:
        return None
    others = np.delete(step, k_mandrel)
    q_scale = 1.0 + np.abs(np.asarray(axes.q)).max(axis=0)
    if np.any(np.abs(others) > PERIODIC_RTOL * np.delete(q_scale, k_mandrel)):
        return None
    step = np.where(np.arange(step.size) == k_mandrel, step, 0.0)
    q = tile_circuits(axes.q, nc, m, step)
    # the eye slid along its fibre (engine.machine_setup.monotone_eye_azimuth) by the same amount every circuit
    sh = np.asarray(axes.eye_shift, dtype=float)
    sh_step = repeats(sh[:, None], m)
    if sh_step is None or abs(float(sh_step[0])) > PERIODIC_RTOL * (1.0 + float(np.abs(sh).max())):
        return None
    # the eye path's arrays as stored: a CircuitArray (engine.payout's replicated eye path) stays one
    vec: list[Any] = [raw_field(eye, f) for f in ("eye_xyz", "fibre_dir", "contact_xyz")]
    shift: Any
    if isinstance(vec[0], CircuitArray) and vec[0].kind == "turn" and vec[0].patch_rows is None:
        # kept as circuit 0 + rule too: circuit k slides as circuit 1 does (in circuit 0's frame, turned
        # by k·Δv); circuit 0's rows that differ from circuit 1's (the program's start) given as they are
        c1 = sh[m:2 * m + 1]
        own = np.flatnonzero(sh[:m] != c1[:m])
        shift = CircuitArray("tile", c1.copy(), nc, m, patch_rows=own, patch_values=sh[own])
        if np.any(c1 != 0.0) or own.size:
            e0 = field_rows(eye, "eye_xyz", 0, m + 1) + c1[:, None] * field_rows(eye, "fibre_dir", 0, m + 1)
            vec[0] = CircuitArray("turn", tuple(np.ascontiguousarray(e0[:, i]) for i in range(3)), nc, m,
                                  cos_k=vec[0].cos_k, sin_k=vec[0].sin_k, patch_rows=own,
                                  patch_values=np.asarray(axes.eye_xyz, dtype=float)[own])
    else:
        shift = tile_circuits(sh, nc, m)
        rows = np.flatnonzero(shift)
        if rows.size:       # the eye moved along its (unit) fibre direction: the same arithmetic as the slide
            e = vec[0].materialise() if isinstance(vec[0], CircuitArray) else np.array(vec[0], dtype=float)
            e[rows] += shift[rows, None] * field_take(eye, "fibre_dir", rows)
            vec[0] = e
            e.flags.writeable = False
        shift.flags.writeable = False
    q.flags.writeable = False
    x = None if axes.x is None else np.asarray(eye.x, dtype=float)
    full = replace(axes, q=q, eye_xyz=vec[0], fibre_dir=vec[1], contact_xyz=vec[2], eye_shift=shift, x=x,
                   circuits=(nc, m))
    # the placement (carriage range) is the short path's: the carriage axis repeats circuit by circuit
    return machine, full, placement


def circuit_pieces(axes: Any, s: Any, rtol: float = 1e-7) -> list[tuple[int, int]] | None:
    """Path-index ranges ``(start, end)`` (inclusive) of the circuits of an axis path built by
    :func:`replicate_axes` (``axes.circuits`` set), when the path length ``s`` (mm, one value per path
    point) also repeats circuit 1 from circuit 1 on (to ``rtol`` of the program's length); else None."""
    per = getattr(axes, "circuits", None)
    if per is None:
        return None
    nc, m = per
    n = nc * m + 1
    s = np.asarray(s, dtype=float)
    if s.shape != (n,) or np.shape(axes.q)[0] != n:
        return None
    ref = s[m:2 * m + 1] - s[m]
    tol = rtol * (1.0 + abs(float(s[-1])))
    for k in range(2, nc):
        a = k * m
        if np.any(np.abs(s[a:a + m + 1] - s[a] - ref) > tol):
            return None
    return [(k * m, (k + 1) * m) for k in range(nc)]


# --------------------------------------------------------------------------------------------------
# Per-point arrays kept as circuit 0 + how circuit k is made (materialised on first use)
# --------------------------------------------------------------------------------------------------
class CircuitArray:
    """A per-point array of ``circuits`` circuits of ``m`` points plus the closing point, kept as
    circuit 0 (``m + 1`` rows) and the rule that makes circuit k from it (issue 16: the line of a
    400 x 8 000 program is 1 GB materialised).

    ``kind``:

    * ``"tile"``: every circuit is circuit 0 (rows ``base[:m]``), the closing point ``base[m]``;
    * ``"shift"``: circuit k is ``base[:m] + k·step``, the closing point ``base[m] + (circuits-1)·step``;
    * ``"circuit"``: the circuit number k (the closing point circuits - 1);
    * ``"turn"``: (N, 3) points of circuit 0 given by their columns ``base = (x0, y0, z0)``, turned by
      the angle whose cosine / sine are ``cos_k[k]`` / ``sin_k[k]`` about z.

    :meth:`materialise` and :meth:`rows` use the arithmetic of :func:`engine.winding._assemble`
    (bit for bit the arrays it made)."""

    __slots__ = ("base", "circuits", "m", "kind", "step", "cos_k", "sin_k", "dtype", "_full", "patch_rows",
                 "patch_values")

    def __init__(self, kind: str, base: Any, circuits: int, m: int, step: Any = 0,
                 cos_k: np.ndarray | None = None, sin_k: np.ndarray | None = None,
                 patch_rows: np.ndarray | None = None, patch_values: np.ndarray | None = None) -> None:
        if kind not in ("tile", "shift", "circuit", "turn"):
            raise ValueError(f"CircuitArray: unknown kind {kind!r}")
        self.kind, self.base, self.circuits, self.m, self.step = kind, base, int(circuits), int(m), step
        self.cos_k, self.sin_k = cos_k, sin_k
        self._full: np.ndarray | None = None
        # a few rows given explicitly (e.g. circuit 0's start, where the program begins from rest)
        self.patch_rows = self.patch_values = None
        if patch_rows is not None:
            rows = np.asarray(patch_rows, dtype=np.int64)
            order = np.argsort(rows, kind="stable")
            self.patch_rows, self.patch_values = rows[order], np.asarray(patch_values)[order]
        self.dtype = np.dtype(np.int64) if kind == "circuit" else (
            np.dtype(float) if kind == "turn" else np.asarray(base).dtype)

    @property
    def n(self) -> int:
        """Points of the whole path."""
        return self.circuits * self.m + 1

    @property
    def shape(self) -> tuple[int, ...]:
        return (self.n, 3) if self.kind == "turn" else (self.n,)

    def __len__(self) -> int:
        return self.n

    @property
    def nbytes_materialised(self) -> int:
        """Bytes the whole array takes once materialised."""
        return int(np.prod(self.shape)) * self.dtype.itemsize

    def array(self) -> np.ndarray:
        """The whole array, made once and shared by every holder of this CircuitArray."""
        if self._full is None:
            self._full = self.materialise()
        return self._full

    def materialise(self) -> np.ndarray:
        """The whole array (a new ndarray, not kept)."""
        out = self._materialise_rule()
        if self.patch_rows is not None and self.patch_rows.size:
            out[self.patch_rows] = self.patch_values
        return out

    def _materialise_rule(self) -> np.ndarray:
        total, m, n = self.circuits, self.m, self.n
        k = np.arange(total)
        if self.kind == "tile":
            a = self.base
            res = np.empty(n, dtype=a.dtype)
            res[:-1].reshape(total, m)[:] = a[:m]
            res[-1] = a[m]
            return res
        if self.kind == "shift":
            a, step = self.base, self.step
            res = np.empty(n, dtype=a.dtype)
            res[:-1].reshape(total, m)[:] = a[:m][None, :] + (k * step)[:, None]
            res[-1] = a[m] + (total - 1) * step
            return res
        if self.kind == "circuit":
            res = np.empty(n, dtype=np.int64)
            res[:-1].reshape(total, m)[:] = k[:, None]
            res[-1] = total - 1
            return res
        x0, y0, z0 = self.base
        ck, sk = self.cos_k[:, None], self.sin_k[:, None]
        arr = np.empty((n, 3))
        body = arr[:-1].reshape(total, m, 3)
        # x0·cos − y0·sin and x0·sin + y0·cos written in place (the same arithmetic, one temporary)
        np.multiply(x0[:m], ck, out=body[:, :, 0])
        body[:, :, 0] -= y0[:m] * sk
        np.multiply(x0[:m], sk, out=body[:, :, 1])
        body[:, :, 1] += y0[:m] * ck
        body[:, :, 2] = z0[:m]
        cl, sl = float(ck[-1, 0]), float(sk[-1, 0])
        arr[-1] = (x0[m] * cl - y0[m] * sl, x0[m] * sl + y0[m] * cl, z0[m])
        return arr

    def rows(self, start: int, stop: int) -> np.ndarray:
        """Rows ``start .. stop-1`` of the whole array (the same values as ``materialise()[start:stop]``).
        A range of more than two circuits is made circuit by circuit from slices of circuit 0 (the
        arithmetic of :meth:`take`, without its per-row index arithmetic)."""
        start, stop, _ = slice(start, stop).indices(self.n)
        stop = max(stop, start)
        m, n = self.m, self.n
        if stop - start < 2 * m:
            return self.take(np.arange(start, stop))
        out = np.empty((stop - start,) + self.shape[1:], dtype=self.dtype)
        body_stop = min(stop, n - 1)                       # the closing row is made by take
        for k in range(start // m, (body_stop - 1) // m + 1 if body_stop > start else start // m):
            a, b = max(start, k * m), min(body_stop, (k + 1) * m)
            if b > a:
                out[a - start:b - start] = self._circuit_rows(k, a - k * m, b - k * m)
        if stop == n:
            out[-1] = self._take_rule(np.array([n - 1], dtype=np.int64))[0]
        if self.patch_rows is not None and self.patch_rows.size:
            lo, hi = np.searchsorted(self.patch_rows, [start, stop])
            if hi > lo:
                out[self.patch_rows[lo:hi] - start] = self.patch_values[lo:hi]
        return out

    def _circuit_rows(self, k: int, j0: int, j1: int) -> np.ndarray:
        """Rows ``j0 .. j1-1`` of circuit ``k`` (``j1 <= m``), with :meth:`_take_rule`'s arithmetic."""
        if self.kind == "tile":
            return self.base[j0:j1]
        if self.kind == "shift":
            return self.base[j0:j1] + np.int64(k) * self.step
        if self.kind == "circuit":
            return np.full(j1 - j0, k, dtype=np.int64)
        x0, y0, z0 = self.base
        c, s = self.cos_k[k], self.sin_k[k]
        out = np.empty((j1 - j0, 3))
        np.multiply(x0[j0:j1], c, out=out[:, 0])
        out[:, 0] -= y0[j0:j1] * s
        np.multiply(x0[j0:j1], s, out=out[:, 1])
        out[:, 1] += y0[j0:j1] * c
        out[:, 2] = z0[j0:j1]
        return out

    def take(self, i: np.ndarray) -> np.ndarray:
        """Rows ``i`` (non-negative indices) of the whole array (the same values as ``materialise()[i]``)."""
        i = np.asarray(i, dtype=np.int64)
        out = self._take_rule(i)
        if self.patch_rows is not None and self.patch_rows.size and i.size:
            pos = np.searchsorted(self.patch_rows, i)
            hit = (pos < self.patch_rows.size) & (self.patch_rows[np.minimum(pos, self.patch_rows.size - 1)] == i)
            if hit.any():
                out = np.array(out)
                out[hit] = self.patch_values[pos[hit]]
        return out

    def _take_rule(self, i: np.ndarray) -> np.ndarray:
        n, m, total = self.n, self.m, self.circuits
        i = np.asarray(i, dtype=np.int64)
        if i.size and (i.min() < 0 or i.max() >= n):
            raise IndexError(f"CircuitArray: index out of range 0..{n - 1}")
        kk, j = np.divmod(i, m)
        last = i == n - 1
        j = np.where(last, m, j)
        kk = np.where(last, total - 1, kk)
        if self.kind == "tile":
            return self.base[j]
        if self.kind == "shift":
            out = self.base[j] + kk * self.step
            if last.any():
                out[last] = self.base[m] + (total - 1) * self.step
            return out
        if self.kind == "circuit":
            return kk.astype(np.int64)
        x0, y0, z0 = self.base
        ck, sk = self.cos_k[kk], self.sin_k[kk]
        out = np.empty((i.size, 3))
        np.multiply(x0[j], ck, out=out[:, 0])
        out[:, 0] -= y0[j] * sk
        np.multiply(x0[j], sk, out=out[:, 1])
        out[:, 1] += y0[j] * ck
        out[:, 2] = z0[j]
        if last.any():
            cl, sl = float(self.cos_k[-1]), float(self.sin_k[-1])
            out[last] = (x0[m] * cl - y0[m] * sl, x0[m] * sl + y0[m] * cl, z0[m])
        return out

    def value_range(self) -> tuple[float, float]:
        """(min, max) of a ``"tile"`` array without materialising it (its values are circuit 0's)."""
        if self.kind != "tile":
            a = self.materialise()
            return float(a.min()), float(a.max())
        return float(np.min(self.base)), float(np.max(self.base))


def _rows_of(a: Any, start: int, stop: int) -> np.ndarray:
    return a.rows(start, stop) if isinstance(a, CircuitArray) else np.asarray(a)[start:stop]


def _take_of(a: Any, i: np.ndarray) -> np.ndarray:
    return a.take(i) if isinstance(a, CircuitArray) else np.asarray(a)[i]


class DerivedArray(CircuitArray):
    """A per-point (or per-step) array defined elementwise from other arrays (plain or
    :class:`CircuitArray`), made on first read like a CircuitArray: its rows with the arithmetic of the
    whole-array expression, bit for bit (each element depends on the operands' elements at its own row,
    or at its row and the next).  ``op``:

    * ``"add"``: ``a + b``;
    * ``"pulled"``: ``(s + l) - k·R`` (``args = (s, l, R, k)``: the payout's λ, engine.payout);
    * ``"slope"``: ``np.diff(a) / np.diff(b)`` (``n`` = the operands' rows − 1);
    * ``"mid"``: ``0.5 * (a[1:] + a[:-1])`` (``n`` = the operand's rows − 1).

    The eye path of a replicated program keeps its V, λ, u and x_mid so (4 x 49 MB on a 400 x 8 000
    program, which no stage of ``winder run`` reads whole)."""

    __slots__ = ("op", "args", "_n")

    def __init__(self, op: str, args: tuple[Any, ...], n: int) -> None:  # noqa: D107
        if op not in ("add", "pulled", "slope", "mid"):
            raise ValueError(f"DerivedArray: unknown op {op!r}")
        self.op, self.args, self._n = op, tuple(args), int(n)
        self.kind, self.base, self.circuits, self.m, self.step = "derived", None, 0, 0, 0
        self.cos_k = self.sin_k = None
        self._full = None
        self.patch_rows = self.patch_values = None
        self.dtype = np.dtype(float)

    @property
    def n(self) -> int:
        return self._n

    @property
    def shape(self) -> tuple[int, ...]:
        return (self._n,)

    def materialise(self) -> np.ndarray:
        return self.rows(0, self._n)

    def rows(self, start: int, stop: int) -> np.ndarray:
        start, stop, _ = slice(start, stop).indices(self._n)
        stop = max(stop, start)
        a = self.args
        if self.op == "add":
            return _rows_of(a[0], start, stop) + _rows_of(a[1], start, stop)
        if self.op == "pulled":
            return _rows_of(a[0], start, stop) + _rows_of(a[1], start, stop) - a[3] * _rows_of(a[2], start, stop)
        if self.op == "slope":
            return np.diff(_rows_of(a[0], start, stop + 1)) / np.diff(_rows_of(a[1], start, stop + 1))
        x = _rows_of(a[0], start, stop + 1)
        return 0.5 * (x[1:] + x[:-1])

    def take(self, i: np.ndarray) -> np.ndarray:
        i = np.asarray(i, dtype=np.int64)
        if i.size and (i.min() < 0 or i.max() >= self._n):
            raise IndexError(f"DerivedArray: index out of range 0..{self._n - 1}")
        a = self.args
        if self.op == "add":
            return _take_of(a[0], i) + _take_of(a[1], i)
        if self.op == "pulled":
            return _take_of(a[0], i) + _take_of(a[1], i) - a[3] * _take_of(a[2], i)
        if self.op == "slope":
            return (_take_of(a[0], i + 1) - _take_of(a[0], i)) / (_take_of(a[1], i + 1) - _take_of(a[1], i))
        return 0.5 * (_take_of(a[0], i + 1) + _take_of(a[0], i))

    def value_range(self) -> tuple[float, float]:
        a = self.materialise()
        return float(a.min()), float(a.max())


class DeferredField:
    """A data descriptor for a per-point field of a frozen dataclass that may hold a
    :class:`CircuitArray`: the first read materialises it (and keeps the array), so every reader sees a
    plain ndarray; :func:`deferred` gives the CircuitArray itself while it is not materialised."""

    def __init__(self, name: str) -> None:
        self.name = name

    def __get__(self, obj: Any, owner: Any = None) -> Any:
        if obj is None:
            return self
        v = obj.__dict__[self.name]
        if isinstance(v, CircuitArray):
            v = v.array()             # one array for every object that holds this CircuitArray
            obj.__dict__[self.name] = v
        return v

    def __set__(self, obj: Any, value: Any) -> None:
        obj.__dict__[self.name] = value


def install_deferred_fields(cls: type, names: tuple[str, ...]) -> None:
    """Make the dataclass fields ``names`` of ``cls`` :class:`DeferredField` s (after the dataclass is made)."""
    for name in names:
        setattr(cls, name, DeferredField(name))


def deferred(obj: Any, name: str) -> CircuitArray | None:
    """The :class:`CircuitArray` of field ``name`` of ``obj`` while it is not materialised, else None."""
    v = getattr(obj, "__dict__", {}).get(name)
    return v if isinstance(v, CircuitArray) else None


def raw_field(obj: Any, name: str) -> Any:
    """Field ``name`` of ``obj`` as stored: a :class:`CircuitArray` while not materialised, else the array."""
    v = getattr(obj, "__dict__", {}).get(name)
    return v if isinstance(v, CircuitArray) else getattr(obj, name)


def raw_field_or(obj: Any, name: str, default: Any = None) -> Any:
    """:func:`raw_field`, or ``default`` when ``obj`` has no field ``name`` (``hasattr`` would materialise a
    deferred field to answer)."""
    v = getattr(obj, "__dict__", {}).get(name)
    return v if isinstance(v, CircuitArray) else getattr(obj, name, default)


def field_take(obj: Any, name: str, idx: np.ndarray) -> np.ndarray:
    """Rows ``idx`` of the per-point field ``name`` of ``obj``, without materialising it."""
    d = deferred(obj, name)
    return np.asarray(getattr(obj, name))[idx] if d is None else d.take(idx)


def replace_raw(obj: Any, **changes: Any) -> Any:
    """``dataclasses.replace`` that passes the fields on as stored (a deferred one stays deferred)."""
    from dataclasses import fields

    kw = {f.name: obj.__dict__[f.name] for f in fields(obj) if f.init and f.name not in changes}
    return type(obj)(**kw, **changes)


def field_rows(obj: Any, name: str, start: int, stop: int) -> np.ndarray:
    """Rows ``start .. stop-1`` of the per-point field ``name`` of ``obj``, without materialising it."""
    d = deferred(obj, name)
    return getattr(obj, name)[start:stop] if d is None else d.rows(start, stop)


def row_chunks(n: int, chunk: int = CHUNK_ROWS) -> list[tuple[int, int]]:
    """Row ranges ``[a, b)`` covering rows ``0 .. n-1`` in pieces of at most ``chunk`` rows, each piece
    starting at the last row of the one before (so the differences of consecutive rows, ``np.diff``, are
    taken exactly once, piece by piece)."""
    chunk = max(int(chunk), 2)
    out = []
    a = 0
    while True:
        b = min(a + chunk, n)
        out.append((a, b))
        if b >= n:
            return out
        a = b - 1


def tile_base(obj: Any, name: str) -> np.ndarray | None:
    """Circuit 0's rows (``m + 1``, the closing point last) of field ``name`` of ``obj`` when it is kept
    as a ``"tile"`` :class:`CircuitArray` without patched rows (every circuit repeats circuit 0), else None."""
    d = deferred(obj, name)
    if d is None or d.kind != "tile" or d.patch_rows is not None:
        return None
    return np.asarray(d.base)[:d.m + 1]


def tile_rows(base: np.ndarray, m: int, n: int, start: int, stop: int) -> np.ndarray:
    """Rows ``start .. stop-1`` of the ``n``-row tiled array whose circuit 0 is ``base`` (``m + 1`` rows): row
    i is ``base[i mod m]``, the last row ``base[m]`` (:meth:`CircuitArray.rows` of a ``"tile"`` array)."""
    i = np.arange(start, stop)
    j = i % m
    j[i == n - 1] = m
    return base[j]


def materialise_all(obj: Any) -> Any:
    """Materialise every deferred per-point field of ``obj`` (in place; returns ``obj``): a worker thread
    calls it before a GUI thread reads the fields (``winder_gui.tasks``)."""
    if obj is not None:
        for name, v in list(getattr(obj, "__dict__", {}).items()):
            if isinstance(v, CircuitArray):
                getattr(obj, name)
    return obj
