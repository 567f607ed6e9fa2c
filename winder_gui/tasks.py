"""Worker tasks of the winding workflow (run in :class:`winder_gui.workers.JobRunner` threads).

No widgets and no mathematics here: each task calls engine functions and packs their results for
the views.  Every task takes ``state`` (progress, cancellation, partial results).
"""

from __future__ import annotations

import importlib.util
import os
import threading
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from engine.errors import InputError
from engine.job import FileSpec, Job, PointsSpec, TimeLawSpec, build_mandrel, load_job
from engine.state import SubState, check_cancel
from winder_gui.views.geometry import MandrelViewData, mandrel_view_data, sketch_points
from winder_gui.workers import cad_call

if TYPE_CHECKING:  # engine.mandrel (scipy) is first imported by the build worker, off the start-up path
    from engine.mandrel import Mandrel

COMPARED_LAWS: tuple[str, ...] = ("parallel", "equidistant", "equal-tangent", "min-range")
"""Payout laws shown side by side in the pull-speed plot (``curve`` only when the job gives a curve)."""


@dataclass(frozen=True)
class RunOutput:
    """A pipeline result with its warnings and limit violations (checked in the worker, not the GUI)."""

    result: Any
    warnings: list[str]
    violations: list[Any]
    paths: Any = None
    """:class:`winder_gui.views.geometry.PathsViewData` for the 3D view (thinned in the worker)."""
    coverage: Any = None
    """:class:`engine.coverage.CoverageMap` of a new winding line (``None``: the line did not change)."""


class _MaterialisingState:
    """Forwards a worker's state; a partial pipeline result gets a big program's arrays (kept as circuit 0 +
    rule, :mod:`engine.periodic`) made here in the worker, before the GUI thread draws it."""

    def __init__(self, state: Any) -> None:
        self._state = state

    def progress(self, fraction: float, message: str = "") -> None:
        if self._state is not None:
            self._state.progress(fraction, message)

    def cancelled(self) -> bool:
        return self._state is not None and self._state.cancelled()

    def partial(self, result: Any) -> None:
        from engine.periodic import materialise_all

        for part in ("line", "eye", "axes"):
            materialise_all(getattr(result, part, None))
        if self._state is not None:
            self._state.partial(result)


def pipeline_task(job: Job, job_path: Path | None, previous: Any, upto: str, *, state: Any) -> RunOutput:
    """:func:`engine.pipeline.run_pipeline` up to ``upto``, re-using the unchanged stages of ``previous``."""
    from engine.periodic import materialise_all
    from engine.pipeline import run_pipeline
    from winder_gui.views.geometry import paths_view_data
    from winder_gui.views.view3d import MAX_DISPLAY_POINTS, MAX_FRAMES

    res = run_pipeline(job, job_path, upto=upto, previous=previous, state=_MaterialisingState(state))
    check_cancel(state)
    setup = job.machine.setup
    for part in (res.line, res.eye, res.axes):   # a big program's arrays are made here, not in the GUI thread
        materialise_all(part)
    paths = (paths_view_data(res.line, res.eye, MAX_DISPLAY_POINTS, MAX_FRAMES, blocks=res.blocks,
                             axes=res.axes, machine=res.machine,
                             head_mm=(setup.head_radius_mm, setup.head_length_mm))
             if res.line is not None else None)
    cov = None
    if res.line is not None and (previous is None or getattr(previous, "line", None) is not res.line):
        from engine.coverage import coverage_map

        state.progress(1.0, "coverage map")
        cov = coverage_map(res.line, res.mandrel)
    return RunOutput(res, res.warnings(), list(res.violations), paths, cov)


@dataclass(frozen=True)
class NcReadback:
    """An NC program read back on the job's machine (File > Open NC program)."""

    path: Path
    report: dict[str, Any]
    paths: Any
    """:class:`winder_gui.views.geometry.PathsViewData`: the laid fibre (the winding line between the first
    and the last contact the program reaches) and the eye path of the program (forward kinematics)."""


def readback_task(path: Path, job: Job, job_path: Path | None, result: Any, *, state: Any) -> NcReadback:
    """Read ``path`` back on the job's machine (the run's, when there is one) and match it to the job's
    winding line (:func:`engine.ncread.read_back`); the 3D view's data are thinned here, in the worker."""
    from types import SimpleNamespace

    import numpy as np

    from engine.ncread import read_back
    from engine.pipeline import run_pipeline, setup_machine_for_job
    from winder_gui.views.geometry import paths_view_data
    from winder_gui.views.view3d import MAX_DISPLAY_POINTS, MAX_FRAMES

    if job.is_single_line:
        line = getattr(result, "line", None)
        if line is None:
            line = run_pipeline(job, job_path, upto="winding", state=_MaterialisingState(state)).line
    else:   # a laminate: every layer's line as the joined program lays it
        from engine.laminate import laid_line, run_laminate

        lam = result if getattr(result, "layers", None) is not None else run_laminate(job, job_path, state=state)
        line = laid_line(lam)
    check_cancel(state)
    machine = setup_machine_for_job(job, job_path)
    sim, profile = read_back(path, machine, job.post.controller, line,
                             back_turn_tol_deg=float(job.machine.setup.back_turn_tol_deg))
    check_cancel(state)
    a, b = int(sim.contact_index[0]), int(sim.contact_index[-1]) + 1
    xyz = np.asarray(line.xyz)[a:b]
    zeros = np.zeros(b - a)
    laid = SimpleNamespace(
        z=np.asarray(line.z)[a:b], xyz=xyz, r=np.hypot(xyz[:, 0], xyz[:, 1]),
        circuit=np.asarray(getattr(line, "circuit", getattr(line, "layer", zeros)))[a:b],
        beta=np.asarray(getattr(line, "beta", zeros))[a:b] if hasattr(line, "beta") else zeros,
        lam=np.asarray(getattr(line, "lam", zeros))[a:b] if hasattr(line, "lam") else zeros)
    eye = SimpleNamespace(eye_xyz=sim.eye_xyz, contact_xyz=np.asarray(line.xyz)[sim.contact_index],
                          u=np.zeros(0))
    paths = paths_view_data(laid, eye, MAX_DISPLAY_POINTS, MAX_FRAMES)
    return NcReadback(Path(path), {**sim.report, "controller": profile}, paths)


@dataclass(frozen=True)
class BuildResult:
    """A job whose mandrel was built, with the data the views show."""

    job: Job
    path: Path | None
    mandrel: Mandrel
    data: MandrelViewData


@dataclass(frozen=True)
class JobTimeLawResult:
    """One of the job's own time laws (``PipelineResult.timelaw_laws[index]``) with the classical DP
    and TOPP-RA laws on the same path and limits."""

    source: str
    index: int
    law: Any
    dp: Any
    toppra: Any
    s_offset: float
    key: str


def job_timelaw_task(result: Any, index: int, *, state: Any) -> JobTimeLawResult:
    """:func:`engine.pipeline.compare_time_laws` of the job's law ``index`` (DP and TOPP-RA)."""
    from engine.pipeline import compare_time_laws

    state.progress(0.0, "time law: DP and TOPP-RA on the job's path")
    cmp = compare_time_laws(result, index, ("dp", "toppra"), state=state)
    state.progress(1.0, "")
    law = result.timelaw_laws[index]
    n = int(result.timelaw_paths[index].s.size)
    return JobTimeLawResult(f"job: {result.timelaw_labels[index]} ({law.method}, N = {n})", index, law,
                            cmp["dp"], cmp["toppra"], float(result.timelaw_paths[index].iteration_s_offset),
                            str(result.keys.get("blocks", "")))


def mandrel_io_available() -> bool:
    """True when :mod:`engine.mandrel_io` (CSV/DXF/STEP import, STEP/STL export) is installed."""
    return importlib.util.find_spec("engine.mandrel_io") is not None


def build_task(job: Job, path: Path | None, *, state: Any) -> BuildResult:
    """Build ``job``'s mandrel and sample it for the views (worker thread)."""
    state.progress(0.0, "building the mandrel")
    spec = job.mandrel
    if isinstance(spec, FileSpec):
        if not mandrel_io_available():
            raise InputError(
                "reading profile files needs engine.mandrel_io, which this build does not have yet",
                file=path,
                field="mandrel.path",
            )
        step = Path(spec.path).suffix.lower() in (".step", ".stp")
        mandrel = (cad_call(build_mandrel) if step else build_mandrel)(job, path)
    else:
        mandrel = build_mandrel(job, path)
    check_cancel(state)
    sketch = (list(spec.z_mm), list(spec.r_mm)) if isinstance(spec, PointsSpec) else None
    data = mandrel_view_data(mandrel, sketch)
    state.progress(1.0, "")
    return BuildResult(job, path, mandrel, data)


def convert_task(job: Job, mandrel: Mandrel, path: Path | None, *, state: Any) -> BuildResult:
    """``job`` with its mandrel replaced by a sketch whose spline is within 0.01 mm of ``mandrel``
    (:func:`winder_gui.views.geometry.sketch_points`), built (worker thread)."""
    state.progress(0.0, "converting the generatrix to sketch points")
    z, r, _dev = sketch_points(mandrel, state=state)
    spec = PointsSpec(z_mm=[float(v) for v in z], r_mm=[float(v) for v in r])
    return build_task(job.replace(mandrel=spec), path, state=state)


def sketch_task(job: Job, mandrel: Mandrel, path: Path | None, *, state: Any) -> BuildResult:
    """``job`` with its mandrel replaced by the sketch of its exact segments (engine.sketch), built (worker)."""
    from engine.job import SegmentsSpec
    from engine.sketch import sketch_from_mandrel

    state.progress(0.0, "converting the generatrix to a sketch of exact segments")
    spec = SegmentsSpec.model_validate(sketch_from_mandrel(mandrel))
    return build_task(job.replace(mandrel=spec), path, state=state)


def open_task(path: Path, *, state: Any) -> BuildResult:
    """Read a job file and build its mandrel (worker thread)."""
    return build_task(load_job(path), path, state=state)


def export_task(mandrel: Mandrel, path: Path, *, state: Any) -> Path:
    """Write the mandrel solid as STEP or mesh as STL, by suffix (worker thread, CAD lock)."""
    from engine import mandrel_io

    state.progress(0.0, f"exporting {path.name}")
    fn = mandrel_io.export_stl if path.suffix.lower() == ".stl" else mandrel_io.export_step
    cad_call(fn)(mandrel, path)
    return path


def profile_ref(profile: Path, job_path: Path | None) -> str:
    """How a job refers to a profile file: relative to the job's folder if saved, else absolute."""
    profile = profile.resolve()
    if job_path is None:
        return profile.as_posix()
    try:
        return Path(os.path.relpath(profile, job_path.resolve().parent)).as_posix()
    except ValueError:  # another drive (Windows)
        return profile.as_posix()


def laws_task(result: Any, *, state: Any) -> dict[str, Any]:
    """The eye path of each payout law on the job's first circuit (law -> EyePath or an error message).

    The job's own law is taken from ``result``; the others are computed with the job's payout
    settings.  A law that cannot be applied gives its message instead of a path.
    """
    from engine.payout import ContactLine, payout_law

    job: Job = result.job
    laws = list(COMPARED_LAWS)
    if job.payout.curve_zr_mm:
        laws.insert(3, "curve")
    own = result.eye_circuit
    out: dict[str, Any] = {}
    cl = None
    for i, law in enumerate(laws):
        check_cancel(state)
        state.progress(i / len(laws), f"payout law {law}")
        if own is not None and law == own.law:
            out[law] = own
            continue
        if cl is None:
            cl = ContactLine.from_line(result.line).first_circuit()
        try:
            out[law] = payout_law(cl, result.mandrel, job.payout, law=law,
                                  state=SubState(state, i / len(laws), (i + 1) / len(laws)))
        except InputError as exc:
            out[law] = exc.message
    state.progress(1.0, "")
    return out


@dataclass(frozen=True)
class TimeLawResult:
    """The three time laws of one path: the tube algorithm (with its iterations), one DP, TOPP-RA."""

    source: str
    tube: Any
    dp: Any
    toppra: Any


def timelaw_task(spec: TimeLawSpec, *, state: Any) -> TimeLawResult:
    """Run :func:`engine.timeparam.parametrize` (tube, dp, toppra) on the paper's 7-axis example.

    The job's ``[timelaw]`` settings (levels, penalty, tube share, stop percent, final sweep, speed limits) replace
    the example's.
    """
    from engine.timeparam import parametrize
    from engine.timeparam_example import example_limits, example_path

    s, X, dX, ddX = example_path()
    lim = example_limits()
    changes: dict[str, Any] = {"levels": spec.levels, "penalty": spec.penalty, "tube_share": spec.tube_share,
                               "stop_percent": spec.stop_percent, "sweep": spec.sweep}
    if spec.sdot_max is not None:
        changes["sdot_max"] = spec.sdot_max
    if spec.sddot_max is not None:
        changes["sddot_max"] = spec.sddot_max
    lim = replace(lim, **changes)
    state.progress(0.0, "time law: tube iterations")
    tube = parametrize(s, X, dX, ddX, lim, method="tube", state=SubState(state, 0.0, 0.4))
    check_cancel(state)
    state.progress(0.4, "time law: single DP")
    dp = parametrize(s, X, dX, ddX, lim, method="dp", state=SubState(state, 0.4, 0.55))
    check_cancel(state)
    state.progress(0.55, "time law: TOPP-RA reference")
    top = parametrize(s, X, dX, ddX, lim, method="toppra", state=SubState(state, 0.55, 1.0))
    state.progress(1.0, "")
    return TimeLawResult("paper example (7 axes, N = 893)", tube, dp, top)


def report_task(result: Any, path: Path, job_path: Path | None, *, state: Any) -> Path:
    """:func:`engine.report.write_report` (PDF or HTML by suffix, atomic) of ``result``."""
    from engine.report import write_report

    state.progress(0.0, f"writing the report {path.name}")
    return write_report(result, path, job_path)


def write_task(result: Any, path: Path, force: bool, *, state: Any) -> Path:
    """:func:`engine.pipeline.write_program` (atomic; refuses a violating program unless ``force``)."""
    from engine.pipeline import write_program

    state.progress(0.0, f"writing {path.name}")
    return write_program(result, path, force=force)


ENGINE_MODULES: tuple[str, ...] = (
    "scipy.interpolate", "scipy.optimize", "scipy.spatial", "scipy.linalg",
    "engine.pipeline", "engine.winding", "engine.payout", "engine.kinematics", "engine.blocks",
    "engine.timeparam", "engine.post",
)


_POOL: list[Any] = []   # the process's LayerPool (or None), made once
_POOL_MAX_WORKERS = 8
_POOL_LOCK = threading.Lock()


def gui_layer_pool() -> Any:
    """The GUI process's :class:`engine.layer_pool.LayerPool` for a laminate's layers (their pipelines run
    side by side in its worker processes: this process has threads and must not fork), with one worker
    per CPU available (``WINDER_JOBS`` overrides), or None: one CPU, ``WINDER_JOBS=1``,
    ``WINDER_GUI_POOL=0``, or no process could be made.  Made on first use, kept for the session,
    stopped at exit."""

    with _POOL_LOCK:
        if not _POOL:
            pool = None
            # POSIX: the scheduler selects on the workers' pipes and removes answer files it has mapped
            if os.environ.get("WINDER_GUI_POOL", "1").strip() != "0" and os.name == "posix":
                try:
                    from engine.laminate import available_cpus
                    from engine.layer_pool import LayerPool

                    env = os.environ.get("WINDER_JOBS", "").strip()
                    # more workers than heavy layers are rare; each costs ~0.4 s of CPU to start and ~35 MB
                    n = int(env) if env.isdigit() else min(available_cpus(), _POOL_MAX_WORKERS)
                    pool = LayerPool(n) if n > 1 else None
                except Exception:  # noqa: BLE001 - no pool: the layers run one after the other here
                    pool = None
            _POOL.append(pool)
        return _POOL[0]


def warm_engine_imports() -> None:
    """Import the engine's heavy modules ahead of the first run (call from a background thread).

    An import cannot be cancelled: done lazily inside the first pipeline run, scipy.spatial alone
    would hold a Cancel for 0.5–1 s.  Errors are left for the real run to report.
    """
    import importlib

    for name in ENGINE_MODULES:
        try:
            importlib.import_module(name)
        except Exception:  # noqa: BLE001 - the run that needs the module reports the problem
            pass
    try:  # numba and the time law's compiled kernels (big programs use them; ~0.5 s, GIL held)
        from engine import timeparam_jit

        timeparam_jit.warm()
    except Exception:  # noqa: BLE001 - without numba the numpy passes run
        pass
    pool = gui_layer_pool()
    if pool is not None:  # its workers start (and import the engine) before the first run needs them
        pool.warm()
