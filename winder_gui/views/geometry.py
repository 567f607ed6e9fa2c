"""Plot and surface data of a mandrel, computed in a worker thread (no Qt here).

The GUI thread only hands these arrays to pyqtgraph / pyvista; everything numeric is done by
:func:`mandrel_view_data`, which the main window runs through a :class:`winder_gui.workers.JobRunner`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    from engine.mandrel import Mandrel

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class MandrelViewData:
    """Everything the views draw for one mandrel (mm, 1/mm).

    Attributes
    ----------
    z, r, d2r:
        The generatrix sampled for the plots: axial position (mm), radius (mm), r'' (1/mm).
    concave:
        Concave zones (r'' > 0) as (z_from, z_to) pairs in mm.
    handle_z, handle_r:
        Editable points shown on the r(z) plot (mm): the sketch points of a ``points`` mandrel, a
        sparse sample of the curve otherwise.
    surface_x, surface_y, surface_z:
        The revolved surface on an (n_z, n_theta) grid (mm); the mandrel axis is the x axis.
    """

    z: FloatArray
    r: FloatArray
    d2r: FloatArray
    concave: tuple[tuple[float, float], ...]
    handle_z: FloatArray
    handle_r: FloatArray
    surface_x: FloatArray
    surface_y: FloatArray
    surface_z: FloatArray


def handle_points(
    mandrel: Mandrel, per_length: int = 24, k_min: int = 4, k_max: int = 10
) -> tuple[FloatArray, FloatArray]:
    """A sparse set of points on the generatrix that a spline through them resembles (mm).

    Each segment gets between ``k_min`` and ``k_max`` points (in proportion to its share of the
    length, ``per_length`` in total); joints between segments are kept once.
    """
    zs: list[float] = []
    total = mandrel.length
    for seg in mandrel.segments:
        k = int(np.clip(round(per_length * (seg.z1 - seg.z0) / total), k_min, k_max))
        pts = np.linspace(seg.z0, seg.z1, k)
        zs.extend(pts[1:] if zs else pts)
    z = np.asarray(zs, dtype=float)
    return z, np.maximum(np.asarray(mandrel.r(z), dtype=float), 0.0)   # a closed pole: -1e-15 -> 0


def sketch_points(mandrel: Mandrel, tol_mm: float = 0.01, max_points: int = 400, state: Any = None,
                  ) -> tuple[FloatArray, FloatArray, float]:
    """Points whose C2 spline (the ``points`` mandrel) stays within ``tol_mm`` of ``mandrel`` in r.

    Starts from :func:`handle_points` and inserts the midpoint of every interval where the spline
    strays by more than ``tol_mm`` (checked at 16 points per interval), until it fits or
    ``max_points`` is reached.  Radii are clamped at 0 (a closed pole evaluates to -1e-15 mm).
    Returns ``(z, r, worst deviation)`` in mm.  ``state``: cancellation between refinements.
    """
    from engine.mandrel import Mandrel as _Mandrel  # (a worker-side import; the module is light)
    from engine.state import check_cancel

    z, r = handle_points(mandrel)
    tau = (np.arange(1, 16) / 16.0)[None, :]
    dev = np.inf
    while True:
        zz = (z[:-1, None] + (z[1:] - z[:-1])[:, None] * tau).ravel()
        spline = _Mandrel.from_points(z, r, name=mandrel.name, source="points")
        err = np.abs(spline.r(zz) - mandrel.r(zz)).reshape(z.size - 1, -1).max(axis=1)
        dev = float(err.max())
        bad = np.flatnonzero(err > tol_mm)
        if bad.size == 0 or z.size >= max_points:
            return z, r, dev
        if state is not None:
            check_cancel(state)
        bad = bad[: max_points - z.size]
        zm = 0.5 * (z[bad] + z[bad + 1])
        z = np.insert(z, bad + 1, zm)
        r = np.insert(r, bad + 1, np.maximum(mandrel.r(zm), 0.0))


def mandrel_view_data(
    mandrel: Mandrel,
    sketch: tuple[list[float], list[float]] | None = None,
    n_z: int = 600,
    n_theta: int = 73,
) -> MandrelViewData:
    """Sample ``mandrel`` for the r(z) / r'' plots and the revolved 3D surface.

    Parameters
    ----------
    mandrel:
        The mandrel to show.
    sketch:
        The (z, r) points of a sketched mandrel (mm), shown as the editable handles; ``None``
        derives handles from the curve (:func:`handle_points`).
    n_z, n_theta:
        Samples along the axis and around it (the last angle repeats the first, closing the surface).
    """
    z, r = mandrel.sample(n_z)
    _, _, d2r = mandrel.evaluate(z)
    if sketch is not None:
        hz, hr = np.asarray(sketch[0], dtype=float), np.asarray(sketch[1], dtype=float)
    else:
        hz, hr = handle_points(mandrel)
    theta = np.linspace(0.0, 2.0 * np.pi, n_theta)
    sx = np.repeat(z[:, None], n_theta, axis=1)
    sy = r[:, None] * np.cos(theta)[None, :]
    sz = r[:, None] * np.sin(theta)[None, :]
    zones = tuple((zn.z_from, zn.z_to) for zn in mandrel.concave_zones())
    return MandrelViewData(z, r, d2r, zones, hz, hr, sx, sy, sz)


def check_points(z: FloatArray, r: FloatArray) -> tuple[int, str] | None:
    """The first problem of an edited sketch, as (point index, message), or ``None`` when it is fine.

    z must increase strictly, r must be > 0 (0 is allowed at the two end points: a closed pole),
    and a C2 spline needs at least 4 points.  Positions in mm; indices 0-based, messages 1-based.
    """
    from engine.mandrel import MIN_SKETCH_POINTS

    n = len(z)
    if n < MIN_SKETCH_POINTS:
        return max(n - 1, 0), f"a sketched generatrix needs at least {MIN_SKETCH_POINTS} points (it would have {n})"
    for i in range(n):
        if not (np.isfinite(z[i]) and np.isfinite(r[i])):
            return i, f"point {i + 1} is not a finite number"
    for i in range(1, n):
        if not z[i] > z[i - 1]:
            return i, (
                f"z must increase along the axis: point {i + 1} at z = {z[i]:.4g} mm "
                f"is not after z = {z[i - 1]:.4g} mm"
            )
    for i in range(n):
        end = i in (0, n - 1)
        if r[i] < 0 or (r[i] <= 0 and not end):
            return i, f"radius must be > 0: point {i + 1} has r = {r[i]:.4g} mm"
    return None


# ------------------------------------------------------------------------------------------------
# Winding paths, eye and fibre (after a pipeline run)
# ------------------------------------------------------------------------------------------------
def to_view(xyz: FloatArray) -> FloatArray:
    """Mandrel-frame points (x, y, z; axis = z) in the view frame (axis = x), shape (n, 3)."""
    xyz = np.asarray(xyz, dtype=float)
    return np.column_stack([xyz[:, 2], xyz[:, 0], xyz[:, 1]])


LOD_POINTS = 40_000
"""Points of the coarse copy of the winding line drawn while the 3D view moves (level of detail)."""


@dataclass(frozen=True)
class PathsViewData:
    """The winding line, eye trajectory and fibre of one pipeline result, thinned for display.

    Attributes
    ----------
    line_index:
        Indices of the shown points into the engine's winding line, increasing: every turnaround
        (local extremum of z: the poles and the ends of a cylinder), both ends of every circuit,
        the points with the smallest and largest x, y, z (so the shown bounds are the line's), and
        points evenly spaced about ``line_stride`` apart between them (:func:`decimate_indices`).
    line_xyz:
        Shown path points in the view frame (mm), lifted off the surface by ``lift`` mm so they are
        not hidden in it.
    scalars:
        Colour arrays per shown point: ``circuit``, ``beta_deg``, ``lam``, ``u`` (pull speed, the
        interval value after each point).
    frame_index:
        Indices of the animation frames into the eye path (= the winding line's points).
    eye_xyz, contact_xyz:
        Eye and contact point at each frame, view frame (mm).
    n_line:
        Points of the engine's winding line.
    lod_index:
        A coarser selection of the same kind (at most ``lod_points``), positions into ``line_index``
        (so ``line_xyz[lod_index]`` are its points); drawn while the view is rotated or animated.
        Equal to ``arange(len(line_index))`` when the line is short enough to move as it is.
    """

    line_index: NDArray[np.int64]
    line_stride: int
    line_xyz: FloatArray
    scalars: dict[str, FloatArray]
    lift: float
    frame_index: NDArray[np.int64]
    eye_xyz: FloatArray
    contact_xyz: FloatArray
    n_line: int
    lod_index: NDArray[np.int64] | None = None
    frame_time_s: FloatArray | None = None
    """Program time (s) of each animation frame (from the NC blocks; ``None`` without blocks)."""
    frame_circuit: NDArray[np.int64] | None = None
    """Circuit of each animation frame."""
    band: Any = None
    """:class:`winder_gui.views.playback.BandStrip`: the band of true width along a thinned line."""
    band_scalars: dict[str, FloatArray] | None = None
    """Colour arrays per band centre point (keys as :attr:`scalars`)."""
    frame_q: FloatArray | None = None
    """Controller axis values at each animation frame (rows of the engine's axis path), or ``None``."""
    machine: Any = None
    """The :class:`engine.kinematics.MachineTemplate` of :attr:`frame_q` (the result's, with its set-up)."""
    head_mm: tuple[float, float] = (0.0, 0.0)
    """The payout head's body from ``[machine.setup]``: radius and length along its roll axis (mm); (0, 0):
    no body given (the view draws a head of its own size)."""


def feature_indices(xyz: FloatArray, circuit: NDArray | None = None, rel_tol: float = 1e-9) -> NDArray[np.int64]:
    """Indices of the points of a polyline that a thinned copy must keep (increasing, unique).

    Kept: the two ends; every turnaround, i.e. each end of a run where the axial coordinate
    (``xyz[:, 2]``, mm) stops rising or falling, plateaus included (steps of less than ``rel_tol``
    times the axial extent count as flat); both points of every change of ``circuit``; and the first
    points with the smallest and largest x, y and z, so the thinned line spans the same box.
    """
    xyz = np.asarray(xyz, dtype=float)
    n = xyz.shape[0]
    if n <= 2:
        return np.arange(n, dtype=np.int64)
    z = xyz[:, 2]
    dz = np.diff(z)
    tol = rel_tol * max(float(np.ptp(z)), 1e-300)
    s = np.where(dz > tol, 1, np.where(dz < -tol, -1, 0))
    turn = np.flatnonzero(s[1:] != s[:-1]) + 1  # the point between two steps of different direction
    parts = [np.array([0, n - 1]), turn, np.argmin(xyz, axis=0), np.argmax(xyz, axis=0)]
    if circuit is not None:
        c = np.asarray(circuit)
        ch = np.flatnonzero(c[1:] != c[:-1])
        parts += [ch, ch + 1]
    return _sorted_unique(np.concatenate(parts).astype(np.int64))


def _sorted_unique(a: NDArray[np.int64]) -> NDArray[np.int64]:
    """``np.unique`` of an integer array by sorting (numpy's sort lets other threads run; its hash-table
    unique holds the GIL: 0.17 s on a 6 M point program's features, a stalled GUI thread)."""
    a = np.sort(a)
    if a.size < 2:
        return a
    keep = np.empty(a.size, dtype=bool)
    keep[0] = True
    np.not_equal(a[1:], a[:-1], out=keep[1:])
    return a[keep]


def decimate_indices(xyz: FloatArray, max_points: int, circuit: NDArray | None = None) -> tuple[NDArray[np.int64], int]:
    """At most ``max_points`` increasing indices of a polyline that keep its shape for display.

    The :func:`feature_indices` (turnarounds, circuit ends, bounding-box points) are always kept
    — uniform sub-sampling would cut the corners at the poles — and the rest of the budget is spread
    evenly along the index.  If the features alone exceed half the budget they are thinned by a stride.

    Returns
    -------
    (indices, stride):
        The kept indices and the (rounded) spacing of the even part (1: every point kept).
    """
    n = int(np.asarray(xyz).shape[0])
    max_points = max(int(max_points), 64)
    if n <= max_points:
        return np.arange(n, dtype=np.int64), 1
    keep = feature_indices(xyz, circuit)
    if keep.size > max_points // 2:
        box = np.concatenate([np.argmin(xyz, axis=0), np.argmax(xyz, axis=0), [0, n - 1]]).astype(np.int64)
        step = int(np.ceil(keep.size / (max_points // 2 - box.size)))
        keep = _sorted_unique(np.concatenate([keep[::step], box]))
    m = max_points - keep.size
    uniform = np.rint(np.linspace(0.0, n - 1.0, m)).astype(np.int64)
    idx = _sorted_unique(np.concatenate([uniform, keep]))
    return idx, max(1, round((n - 1) / max(m - 1, 1)))


def paths_view_data(line: object, eye: object, max_points: int = 200_000, max_frames: int = 1500,
                    lift: float | None = None, lod_points: int = LOD_POINTS, blocks: object = None,
                    band_points: int | None = None, axes: object = None, machine: object = None,
                    head_mm: tuple[float, float] = (0.0, 0.0)) -> PathsViewData:
    """Thin the engine's winding ``line`` and full-line ``eye`` path for the 3D view (no new maths).

    ``max_points`` bounds the line drawn at rest, ``lod_points`` the coarse copy drawn while the view
    moves, ``max_frames`` the animation frames; see :func:`decimate_indices`.  ``axes`` and ``machine``:
    the result's :class:`engine.kinematics.AxisPath` (one row per eye point) and template, so the 3D view
    can draw the machine at each frame (:mod:`winder_gui.views.machine3d`); ``head_mm``: the head body's
    radius and length from the job's ``[machine.setup]``.
    """
    z = np.asarray(line.z)  # type: ignore[attr-defined]
    n = z.size
    xyz_all = np.asarray(line.xyz)  # type: ignore[attr-defined]
    circuit_all = np.asarray(line.circuit)  # type: ignore[attr-defined]
    idx, stride = decimate_indices(xyz_all, max_points, circuit_all)
    r = np.asarray(line.r)[idx]  # type: ignore[attr-defined]
    rmax = float(np.max(np.asarray(line.r)))  # type: ignore[attr-defined]
    lift = 0.004 * rmax if lift is None else lift
    xyz = xyz_all[idx].copy()
    scale = np.where(r > 1e-9, (r + lift) / np.maximum(r, 1e-9), 1.0)
    xyz[:, 0] *= scale
    xyz[:, 1] *= scale
    u_full = np.asarray(getattr(eye, "u", np.zeros(0)), dtype=float) if eye is not None else np.zeros(0)
    u_pt = np.append(u_full, u_full[-1]) if u_full.size == n - 1 else np.zeros(n)
    scalars = {
        "circuit": np.asarray(circuit_all, dtype=float)[idx],
        "beta_deg": np.degrees(np.asarray(line.beta))[idx],  # type: ignore[attr-defined]
        "lam": np.asarray(line.lam, dtype=float)[idx],  # type: ignore[attr-defined]
        "u": u_pt[idx],
    }
    lod, _ = decimate_indices(xyz, lod_points, scalars["circuit"])
    if eye is not None:
        ne = np.asarray(eye.eye_xyz).shape[0]  # type: ignore[attr-defined]
        fstride = max(1, int(np.ceil(ne / max_frames)))
        fidx = np.arange(0, ne, fstride, dtype=np.int64)
        exyz = to_view(np.asarray(eye.eye_xyz)[fidx])  # type: ignore[attr-defined]
        cxyz = to_view(np.asarray(eye.contact_xyz)[fidx])  # type: ignore[attr-defined]
    else:
        fidx = np.zeros(0, dtype=np.int64)
        exyz = cxyz = np.zeros((0, 3))
    from winder_gui.views.playback import BAND_POINTS, band_strip, point_times

    t_pts = (point_times(n, np.asarray(blocks.index), np.asarray(blocks.time),  # type: ignore[attr-defined]
                         getattr(line, "s", None)) if blocks is not None else None)
    frame_time = t_pts[np.minimum(fidx, n - 1)] if t_pts is not None and fidx.size else None
    frame_circuit = circuit_all[np.minimum(fidx, n - 1)].astype(np.int64) if fidx.size else None
    band = band_scalars = None
    normal = getattr(line, "normal", None)
    width = float(getattr(line, "band_width_mm", 0.0) or 0.0)
    if t_pts is not None and normal is not None and width > 0:
        bidx, _ = decimate_indices(xyz_all, band_points or BAND_POINTS, circuit_all)
        band = band_strip(to_view(xyz_all[bidx]), to_view(np.asarray(normal)[bidx]), t_pts[bidx], width, 0.6 * lift)
        u_b = u_pt[bidx]
        band_scalars = {"circuit": np.asarray(circuit_all, dtype=float)[bidx],
                        "beta_deg": np.degrees(np.asarray(line.beta))[bidx],  # type: ignore[attr-defined]
                        "lam": np.asarray(line.lam, dtype=float)[bidx], "u": u_b}  # type: ignore[attr-defined]
    frame_q = None
    if axes is not None and machine is not None and fidx.size:
        q_all = np.asarray(axes.q, dtype=float)  # type: ignore[attr-defined]
        if q_all.ndim == 2 and q_all.shape[0] > int(fidx[-1]):
            frame_q = q_all[fidx]
    return PathsViewData(idx, stride, to_view(xyz), scalars, float(lift), fidx, exyz, cxyz, n, lod,
                         frame_time, frame_circuit, band, band_scalars, frame_q,
                         machine if frame_q is not None else None, (float(head_mm[0]), float(head_mm[1])))
