"""Worker tasks of the winding workflow (run in :class:`winder_gui.workers.JobRunner` threads).

No widgets and no mathematics here: each task calls engine functions and packs their results for
the views.  Every task takes ``state`` (progress, cancellation, partial results).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from engine.errors import InputError
from engine.job import Job, TimeLawSpec
from engine.state import SubState, check_cancel

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


def pipeline_task(job: Job, job_path: Path | None, previous: Any, upto: str, *, state: Any) -> RunOutput:
    """:func:`engine.pipeline.run_pipeline` up to ``upto``, re-using the unchanged stages of ``previous``."""
    from engine.pipeline import run_pipeline
    from winder_gui.views.geometry import paths_view_data
    from winder_gui.views.view3d import MAX_DISPLAY_POINTS, MAX_FRAMES

    res = run_pipeline(job, job_path, upto=upto, previous=previous, state=state)
    check_cancel(state)
    paths = paths_view_data(res.line, res.eye, MAX_DISPLAY_POINTS, MAX_FRAMES) if res.line is not None else None
    return RunOutput(res, res.warnings(), list(res.violations), paths)


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

    The job's ``[timelaw]`` settings (levels, penalty, tube share, stop percent, speed limits) replace
    the example's.
    """
    from engine.timeparam import parametrize
    from engine.timeparam_example import example_limits, example_path

    s, X, dX, ddX = example_path()
    lim = example_limits()
    changes: dict[str, Any] = {"levels": spec.levels, "penalty": spec.penalty, "tube_share": spec.tube_share,
                               "stop_percent": spec.stop_percent}
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
    state.progress(0.55, "time law: TOPP-RA bound")
    top = parametrize(s, X, dX, ddX, lim, method="toppra", state=SubState(state, 0.55, 1.0))
    state.progress(1.0, "")
    return TimeLawResult("paper example (7 axes, N = 893)", tube, dp, top)


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
