"""The whole winding pipeline: job → mandrel → line → eye → axes → blocks → NC text.

Each stage is a pure engine function; :func:`run_pipeline` chains them, times them, collects the
warnings every stage reports, and re-uses the results of a previous run for every stage whose inputs
(the job sections it reads) did not change — the GUI calls it after each edit, so an edit of the
post-processor re-renders the NC text only, an edit of the payout law starts at the eye path.

Stages and the job sections they read (cumulative):

    mandrel  [mandrel]
    winding  + [band], [winding]
    payout   + [payout]
    axes     + [machine]
    blocks   + [post].tolerance_mm, [post].min_block_time_s, [timelaw]
    nc       + [post].post, [post].controller
"""

from __future__ import annotations

import hashlib
import json
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from engine.errors import InputError
from engine.job import Job, build_mandrel
from engine.state import State, SubState, check_cancel

STAGES: tuple[str, ...] = ("mandrel", "winding", "payout", "axes", "blocks", "nc")

_STAGE_SECTIONS: dict[str, tuple[str, ...]] = {
    "mandrel": ("mandrel",),
    "winding": ("band", "winding"),
    "payout": ("payout",),
    "axes": ("machine",),
    "blocks": ("post.tolerance_mm", "post.min_block_time_s", "timelaw"),
    "nc": ("post.post", "post.controller"),
}

# share of the progress bar per stage (measured proportions on the example vessel)
_WEIGHTS = {"mandrel": 0.02, "winding": 0.10, "payout": 0.30, "axes": 0.25, "blocks": 0.28, "nc": 0.05}


@dataclass(frozen=True)
class PipelineResult:
    """Everything one run produced; stages not run are ``None``."""

    job: Job
    job_path: str | None
    keys: dict[str, str]
    mandrel: Any = None
    line: Any = None
    eye_circuit: Any = None
    eye: Any = None
    machine: Any = None
    axes: Any = None
    blocks: Any = None
    nc_text: str | None = None
    post_name: str | None = None
    extension: str = ".nc"
    stage_times: dict[str, float] = field(default_factory=dict)
    reused: tuple[str, ...] = ()

    @property
    def violations(self) -> list[Any]:
        """Located limit violations of the axis path and the blocks (empty = safe to write)."""
        if self.axes is None:
            return []
        from engine.blocks import check_program

        return check_program(self.axes, self.blocks, self.machine)

    def warnings(self) -> list[str]:
        """Human-readable warnings from every stage that ran."""
        out: list[str] = []
        if self.line is not None:
            for z0, z1 in getattr(self.line, "slips", ()) or ():
                out.append(
                    f"winding line slips (|λ| > μ = {self.line.mu:g}) for z in [{z0:.2f}, {z1:.2f}] mm; "
                    f"max |λ| = {self.line.max_abs_lambda:.4g}"
                )
        if self.eye_circuit is not None and not self.eye_circuit.feasible:
            bad = self.eye_circuit.report.get("violations") or self.eye_circuit.report.get("constraints")
            out.append(f"payout: the eye path violates a constraint: {bad}")
        for v in self.violations:
            out.append(getattr(v, "message", str(v)))
        return out

    def report(self) -> dict[str, Any]:
        """The run report (``winder run --report``)."""
        rep: dict[str, Any] = {"job": self.job.name, "stage_times_s": dict(self.stage_times)}
        if self.machine is not None:
            rep["machine"] = self.machine.name
            rep["axes"] = list(self.machine.axis_names)
        if self.line is not None:
            rep["winding"] = {
                k: v for k, v in self.line.summary().items() if not isinstance(v, list | np.ndarray) or k == "slips"
            }
        if self.eye_circuit is not None:
            rep["payout"] = {
                k: self.eye_circuit.report.get(k)
                for k in ("law", "k", "u_min", "u_max", "u_range", "jerk", "feasible")
                if k in self.eye_circuit.report
            }
        if self.blocks is not None:
            b = self.blocks
            rep["blocks"] = int(b.n)
            rep["program_time_s"] = float(b.total)
            rep["program_time_t17_s"] = float(b.total_t17)
            rep["program_time_start_s"] = float(b.total_start)
            rep["max_speed_ratio"] = _speed_ratios(b, self.machine)
            rep["max_accel_ratio"] = _accel_ratios(b, self.machine)
            rep["max_error_mm"] = float(np.max(b.max_error)) if b.n else 0.0
        if self.post_name:
            rep["post"] = self.post_name
        rep["warnings"] = self.warnings()
        rep["reused_stages"] = list(self.reused)
        return rep


def _speed_ratios(blocks: Any, machine: Any) -> dict[str, float]:
    v = np.abs(blocks.speed)
    lim = np.array([a.max_speed for a in machine.axes])
    return {name: float(v[:, k].max() / lim[k]) if blocks.n else 0.0 for k, name in enumerate(machine.axis_names)}


def _accel_ratios(blocks: Any, machine: Any) -> dict[str, float]:
    """Speed change between neighbouring blocks over their mean duration, per axis, / max_accel."""
    if blocks.n < 2:
        return {name: 0.0 for name in machine.axis_names}
    v = blocks.speed
    t = blocks.time
    if blocks.cyclic:
        dv = np.abs(np.roll(v, -1, axis=0) - v)
        tm = 0.5 * (t + np.roll(t, -1))
    else:
        dv = np.abs(np.diff(v, axis=0))
        tm = 0.5 * (t[1:] + t[:-1])
    a = dv / tm[:, None]
    lim = np.array([ax.max_accel for ax in machine.axes])
    return {name: float(a[:, k].max() / lim[k]) for k, name in enumerate(machine.axis_names)}


def stage_keys(job: Job) -> dict[str, str]:
    """A hash per stage of every job field it (and the stages before it) reads."""
    data = job.model_dump(mode="json")
    keys: dict[str, str] = {}
    h = hashlib.sha256()
    for stage in STAGES:
        for sec in _STAGE_SECTIONS[stage]:
            part: Any = data
            for p in sec.split("."):
                part = part.get(p) if isinstance(part, dict) else None
            h.update(sec.encode())
            h.update(json.dumps(part, sort_keys=True).encode())
        keys[stage] = h.copy().hexdigest()[:16]
    return keys


def load_machine_for_job(job: Job, job_path: str | Path | None = None) -> Any:
    """The job's machine template with the job's axis-limit overrides applied."""
    from engine.kinematics import load_machine

    name = job.machine.template
    if job_path is not None and (name.endswith(".toml") or "/" in name):
        cand = Path(job_path).parent / name
        if cand.exists():
            name = str(cand)
    try:
        machine = load_machine(name)
    except InputError as exc:
        raise InputError(exc.message, file=exc.location.file or job_path, field="machine.template") from None
    if not job.machine.axes:
        return machine
    by_name = {a.name: a for a in machine.axes}
    new_axes = []
    for ax_name in job.machine.axes:
        if ax_name not in by_name:
            raise InputError(
                f"machine {machine.name} has no axis {ax_name!r}; its axes are {', '.join(machine.axis_names)}",
                file=job_path,
                field=f"machine.axes.{ax_name}",
            )
    for ax in machine.axes:
        ov = job.machine.axes.get(ax.name)
        if ov is not None:
            changes = {k: v for k, v in ov.model_dump().items() if v is not None}
            ax = replace(ax, **changes)
            if ax.min > ax.max:
                raise InputError(
                    f"axis {ax.name}: min {ax.min} > max {ax.max}", file=job_path, field=f"machine.axes.{ax.name}"
                )
        new_axes.append(ax)
    return replace(machine, axes=tuple(new_axes))


def run_pipeline(
    job: Job,
    job_path: str | Path | None = None,
    *,
    upto: str = "nc",
    previous: PipelineResult | None = None,
    post_name: str | None = None,
    state: State | None = None,
) -> PipelineResult:
    """Run the stages of ``job`` up to ``upto`` (inclusive), re-using ``previous`` where valid.

    Parameters
    ----------
    job, job_path:
        The job document and its file (for relative paths and error locations).
    upto:
        Last stage to run: one of :data:`STAGES`.
    previous:
        An earlier result; each stage whose key is unchanged is taken from it.
    post_name:
        Post-processor overriding ``job.post.post``.
    state:
        Progress / cancellation (:mod:`engine.state`).
    """
    if upto not in STAGES:
        raise InputError(f"unknown stage {upto!r}; stages: {', '.join(STAGES)}", field="upto")
    if post_name is not None:
        job = job.replace(post={**job.post.model_dump(), "post": post_name})
    keys = stage_keys(job)
    jp = str(job_path) if job_path is not None else None
    res = PipelineResult(job=job, job_path=jp, keys={})
    times: dict[str, float] = {}
    reused: list[str] = []
    last = STAGES.index(upto)
    done = 0.0
    for i, stage in enumerate(STAGES[: last + 1]):
        check_cancel(state)
        w = _WEIGHTS[stage]
        sub = SubState(state, done, done + w) if state is not None else None
        if previous is not None and previous.keys.get(stage) == keys[stage] and _has(previous, stage):
            res = _copy_stage(res, previous, stage)
            reused.append(stage)
            times[stage] = 0.0
        else:
            t0 = time.perf_counter()
            res = _run_stage(res, stage, sub)
            times[stage] = time.perf_counter() - t0
        res = replace(res, keys={**res.keys, stage: keys[stage]})
        done += w
        if state is not None:
            state.progress(min(done, 1.0), f"{stage} done")
            state.partial(res)
        del i
    return replace(res, stage_times=times, reused=tuple(reused))


_STAGE_FIELDS = {
    "mandrel": ("mandrel",),
    "winding": ("line",),
    "payout": ("eye_circuit", "eye"),
    "axes": ("machine", "axes"),
    "blocks": ("blocks",),
    "nc": ("nc_text", "post_name", "extension"),
}


def _has(res: PipelineResult, stage: str) -> bool:
    return all(getattr(res, f) is not None for f in _STAGE_FIELDS[stage])


def _copy_stage(res: PipelineResult, prev: PipelineResult, stage: str) -> PipelineResult:
    return replace(res, **{f: getattr(prev, f) for f in _STAGE_FIELDS[stage]})


def _run_stage(res: PipelineResult, stage: str, state: State | None) -> PipelineResult:
    job, jp = res.job, res.job_path
    if stage == "mandrel":
        return replace(res, mandrel=build_mandrel(job, jp))
    if stage == "winding":
        from engine.winding import winding_line_for_job

        return replace(res, line=winding_line_for_job(job, jp, state=state))
    if stage == "payout":
        from engine.payout import extend_to_line, payout_for_job

        eye1 = payout_for_job(job, res.line, res.mandrel, state=state)
        check_cancel(state)
        return replace(res, eye_circuit=eye1, eye=extend_to_line(eye1, res.line))
    if stage == "axes":
        from engine.kinematics import inverse_kinematics

        machine = load_machine_for_job(job, jp)
        eye = res.eye
        axes = inverse_kinematics(machine, eye.eye_xyz, eye.fibre_dir, eye.contact_xyz, state=state, x=eye.x)
        return replace(res, machine=machine, axes=axes)
    if stage == "blocks":
        from engine.blocks import make_blocks, optimise_block_times

        blocks = make_blocks(
            res.machine, res.axes, tol_mm=job.post.tolerance_mm, min_block_time=job.post.min_block_time_s,
            state=SubState(state, 0.0, 0.5) if state is not None else None,
        )
        blocks = optimise_block_times(blocks, res.machine, state=SubState(state, 0.5, 1.0) if state else None)
        return replace(res, blocks=blocks)
    if stage == "nc":
        from engine.post import get_post, load_controller

        post = get_post(job.post.post)
        profile = load_controller(job.post.controller or post.name)
        text = post.render(res.blocks, res.machine, profile)
        return replace(res, nc_text=text, post_name=post.name, extension=post.extension)
    raise AssertionError(stage)  # pragma: no cover


def write_program(result: PipelineResult, path: str | Path, force: bool = False) -> Path:
    """Write the NC text atomically; refuses (InfeasibleError) when there are violations unless forced."""
    from engine.post import write_nc

    if result.nc_text is None:
        raise InputError("no NC program was produced (the pipeline stopped before the NC stage)")
    return write_nc(path, result.nc_text, result.violations, force=force)
