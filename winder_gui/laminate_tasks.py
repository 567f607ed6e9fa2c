"""Worker task of a layered job: :func:`engine.laminate.run_laminate` and the data its views draw.

A job that is not a single line (``not job.is_single_line``: several layers, a hoop, a polar layer, a
skip, overrides) is wound layer by layer on the growing surface by :func:`engine.laminate.run_laminate`.
:func:`laminate_task` runs it in a :class:`~winder_gui.workers.JobRunner` thread with the previous
result (``previous=``), so an edit of layer k re-runs layers k… only, and packs for each wound layer
what the views show: the surface it was wound on (3D), its line thinned for the 3D view, its winding
angle and thickness along z and its outer boundary (the laminate cross-section).  Nothing here is
mathematics: every array is the engine's, only thinned.  The views of a layer whose result was re-used
are re-used too (by the layer's key).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from engine.job import Job
from engine.state import SubState, check_cancel
from winder_gui.tasks import RunOutput

FloatArray = NDArray[np.float64]

PLOT_POINTS = 2000
"""At most this many points per layer curve of the laminate plots (angle, thickness, boundary)."""


@dataclass(frozen=True)
class LayerView:
    """What the views show of one wound layer (job layer ``index``, 0-based).

    ``surface``: :class:`~winder_gui.views.geometry.MandrelViewData` of the surface the layer is wound on;
    ``paths``: its line for the 3D view (``None`` for a skip layer); ``angle_z``/``angle_deg``: winding
    angle β (deg) along z (mm) on the layer's first pass; ``thick_z``/``thick_t``: the thickness the layer
    adds (mm) along z (mm); ``outer_z``/``outer_r``: its outer boundary (mm), i.e. the next layer's surface.
    """

    index: int
    name: str
    kind: str
    key: str
    surface: Any
    paths: Any
    angle_z: FloatArray
    angle_deg: FloatArray
    thick_z: FloatArray
    thick_t: FloatArray
    outer_z: FloatArray
    outer_r: FloatArray
    figures: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class LaminateOutput(RunOutput):
    """A :class:`~engine.laminate.LaminateResult` (``result``) with its layup table and layer views."""

    layup: dict[str, Any] = field(default_factory=dict)
    """:meth:`engine.laminate.LaminateResult.layup` (per-layer figures and totals)."""
    views: tuple[LayerView, ...] = ()
    """One per wound layer (enabled layers, in winding order)."""
    bare_z: FloatArray = field(default_factory=lambda: np.zeros(0))
    bare_r: FloatArray = field(default_factory=lambda: np.zeros(0))
    """The bare mandrel's meridian (mm): the inner boundary of the laminate."""

    def view(self, index: int) -> LayerView | None:
        """The view of job layer ``index`` (0-based), ``None`` when it was not wound (disabled)."""
        for v in self.views:
            if v.index == index:
                return v
        return None

    def figures_by_key(self) -> dict[str, dict[str, Any]]:
        """Each wound layer's figures by its key (:func:`engine.laminate.layer_keys`)."""
        return {v.key: v.figures for v in self.views}


def is_laminate(result: Any) -> bool:
    """True when ``result`` is a :class:`~engine.laminate.LaminateResult` (not a single-line result)."""
    return result is not None and hasattr(result, "layers") and hasattr(result, "layup")


def _thin(x: FloatArray, y: FloatArray, n: int = PLOT_POINTS) -> tuple[FloatArray, FloatArray]:
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    if x.size <= n:
        return x, y
    idx = np.unique(np.linspace(0, x.size - 1, n).round().astype(np.int64))
    return x[idx], y[idx]


def layer_view(lr: Any, surface_data: Any = None) -> LayerView:
    """The :class:`LayerView` of one :class:`engine.laminate.LayerResult` (worker thread)."""
    from winder_gui.views.geometry import mandrel_view_data, paths_view_data
    from winder_gui.views.view3d import MAX_DISPLAY_POINTS, MAX_FRAMES

    surf = surface_data if surface_data is not None else mandrel_view_data(lr.surface)
    paths = None
    az = ad = np.zeros(0)
    res = lr.result
    if res is not None and res.line is not None:
        line = res.line
        setup = res.job.machine.setup
        paths = paths_view_data(line, res.eye, MAX_DISPLAY_POINTS, MAX_FRAMES, blocks=res.blocks,
                                axes=res.axes, machine=res.machine,
                                head_mm=(setup.head_radius_mm, setup.head_length_mm))  # layer time
        sel = (line.pass_id == line.pass_id[0]) & ~line.dwell
        if int(sel.sum()) < 2:
            sel = np.ones(line.z.size, dtype=bool)
        az, ad = _thin(line.z[sel], np.degrees(line.beta[sel]))
    th = lr.thickness
    if th is not None:
        tz, tt = _thin(th.z, th.t)
        oz, orr = _thin(th.z_out, th.r_out)
    else:  # a skip layer: no fibre
        tz = tt = oz = orr = np.zeros(0)
    return LayerView(lr.index, lr.name, lr.kind, lr.key, surf, paths, az, ad, tz, tt, oz, orr, dict(lr.figures))


class LayerProgress:
    """The state :func:`engine.laminate.run_laminate` reports to: each message is prefixed with the layer it
    concerns (``layer 2/4 helical 40: …``).  run_laminate gives layer j of n the share [j/n, (j+1)/n) of the
    progress, so the layer follows from the fraction; partial results of single layers are not passed on
    (they are not the job's result)."""

    def __init__(self, parent: Any, names: list[str]) -> None:
        self._parent = parent
        self._names = names

    def progress(self, fraction: float, message: str = "") -> None:
        n = len(self._names)
        if message and n:
            j = min(max(int(fraction * n + 1e-9), 0), n - 1)
            message = f"layer {j + 1}/{n} {self._names[j]}: {message}"
        self._parent.progress(fraction, message)

    def cancelled(self) -> bool:
        return bool(self._parent.cancelled())

    def partial(self, result: Any) -> None:
        return None


def laminate_task(job: Job, job_path: Path | None, previous: Any, upto: str = "nc", *, state: Any,
                  previous_views: LaminateOutput | None = None) -> LaminateOutput:
    """:func:`engine.laminate.run_laminate` of ``job`` (re-using the unchanged layers of ``previous``, a
    :class:`~engine.laminate.LaminateResult` or anything else, then ignored) and the views of its layers.

    ``previous_views``: the output of the previous run, whose layer views are re-used by key.
    """
    from engine.job import layer_name
    from engine.laminate import laminate_refusals, meridian_grid, run_laminate
    from winder_gui.views.geometry import mandrel_view_data

    prev = previous if is_laminate(previous) else None
    names = [layer_name(lay, i) for i, lay in job.active_layers]
    from winder_gui.tasks import gui_layer_pool

    res = run_laminate(job, job_path, previous=prev, state=LayerProgress(SubState(state, 0.0, 0.9), names),
                       upto=upto, pool=gui_layer_pool())
    check_cancel(state)
    from engine.periodic import materialise_all

    for lr in res.layers:      # a big program's arrays are made here, not on a first read in the GUI thread
        for part in ("line", "eye", "axes"):
            materialise_all(getattr(getattr(lr, "result", None), part, None))
    state.progress(0.9, "laminate: views of the layers")
    old = {v.key: v for v in previous_views.views} if previous_views is not None else {}
    views: list[LayerView] = []
    surfaces: dict[int, Any] = {}
    for lr in res.layers:
        check_cancel(state)
        if lr.key in old:
            views.append(old[lr.key])
            continue
        sid = id(lr.surface)  # a skip layer shares its surface with the next layer
        if sid not in surfaces:
            surfaces[sid] = mandrel_view_data(lr.surface)
        views.append(layer_view(lr, surfaces[sid]))
    _m, bz, br, _dr = meridian_grid(res.mandrel, 1201)
    bz, br = _thin(bz, br)
    state.progress(1.0, "")
    # the violations the window asks about before writing: what write_laminate refuses (limits, slips; per layer)
    refusals = laminate_refusals(res) if res.nc_text is not None else []
    return LaminateOutput(result=res, warnings=res.warnings(), violations=refusals, layup=res.layup(),
                          views=tuple(views), bare_z=bz, bare_r=br)


def coverage_task(key: str, line: Any, surface: Any, *, state: Any) -> tuple[str, Any]:
    """(``key``, :func:`engine.coverage.coverage_map` of a layer's ``line`` on its ``surface``): computed when
    the layer is first shown (a few seconds on a vessel's helical layer, so not part of every run)."""
    from engine.coverage import coverage_map

    state.progress(0.0, "coverage map of the layer")
    return key, coverage_map(line, surface)


def run_task(job: Job, job_path: Path | None, previous: Any, upto: str = "nc", *, state: Any,
             previous_views: Any = None) -> RunOutput:
    """The run of the workflow: the single-line pipeline for a single-line job, the laminate otherwise."""
    if job.is_single_line:
        from winder_gui.tasks import pipeline_task

        prev = None if is_laminate(previous) else previous
        return pipeline_task(job, job_path, prev, upto, state=state)
    pv = previous_views if isinstance(previous_views, LaminateOutput) else None
    return laminate_task(job, job_path, previous, upto, state=state, previous_views=pv)


def write_laminate_task(result: Any, path: Path, force: bool, *, state: Any) -> Path:
    """:func:`engine.laminate.write_laminate`: the joined program, atomically (refused when a layer
    violates a limit or slips, unless ``force``)."""
    from engine.laminate import write_laminate

    state.progress(0.0, f"writing {path.name}")
    return write_laminate(result, path, force=force)
