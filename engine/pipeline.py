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

Block times: ``[timelaw].method = "blocks"`` (default) uses (17)/(18) (engine.blocks);
``"tube"``, ``"dp"``, ``"toppra"`` time the blocks by a time law s(t) of the whole program
(engine.timeparam): laws of the first, the repeated and the last circuit (or of the whole program when
the circuits differ), block durations from the law, blocks split where their speed jumps exceed
``max_jump``; ``PipelineResult.timelaw`` / the report's ``"timelaw"`` hold its figures.  See
docs/timeparam.md, "The time law drives the NC output".
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
    placement: Any = None
    """:class:`engine.machine_setup.Placement` of the axes stage (where the mandrel sits on the machine)."""
    blocks: Any = None
    timelaw: dict[str, Any] | None = None
    timelaw_laws: tuple[Any, ...] = ()
    """The :class:`engine.timeparam.TimeLaw` objects of the blocks stage (method tube/dp/toppra), empty
    with method "blocks"; :attr:`timelaw_labels` names them, :func:`timelaw_path` gives each one's problem."""
    timelaw_labels: tuple[str, ...] = ()
    timelaw_paths: tuple[Any, ...] = ()
    """One :class:`TimeLawPath` per law of :attr:`timelaw_laws`."""
    nc_text: str | None = None
    post_name: str | None = None
    extension: str = ".nc"
    stage_times: dict[str, float] = field(default_factory=dict)
    reused: tuple[str, ...] = ()

    @property
    def timelaw_main(self) -> int:
        """Index of the job's main law in :attr:`timelaw_laws` (the repeated circuit, else the only law);
        -1 when the blocks stage ran without a time law."""
        if not self.timelaw_laws:
            return -1
        return self.timelaw_labels.index(LAW_REPEATED) if LAW_REPEATED in self.timelaw_labels else 0

    @property
    def violations(self) -> list[Any]:
        """Located limit violations of the axis path and the blocks (empty = safe to write)."""
        if self.axes is None:
            return []
        from engine.blocks import check_program

        if self.timelaw is not None and self.blocks is not None and self.machine is not None:
            return list(self.axes.violations) + timelaw_block_check(self.machine, self.blocks)[0]
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
            out += _payout_warnings(self.eye_circuit)
        if self.placement is not None and not self.placement.fits:
            out.append(self.placement.message())   # which placement would fit (or that none does)
        out += [g.message for g in self.violation_groups()]
        if self.timelaw is not None and self.blocks is not None and self.machine is not None:
            r = float(self.timelaw.get("max_accel_ratio", 0.0))
            if r > 1.0 + 1e-6:
                out.append(f"time law ({self.timelaw.get('method')}): axis accelerations inside the node intervals "
                           f"reach {r:.3f} x the law's limit (TOPP-RA checks its grid points only); "
                           f"the tube and dp methods keep them")
        return out

    def violation_groups(self) -> list[Any]:
        """:attr:`violations` grouped by kind and axis, located by NC line, time, circuit and layer."""
        from engine.machine_setup import Locator, group_violations

        v = self.violations
        return group_violations(v, Locator(self)) if v else []

    def report(self) -> dict[str, Any]:
        """The run report (``winder run --report``)."""
        rep: dict[str, Any] = {"job": self.job.name, "stage_times_s": dict(self.stage_times)}
        if self.machine is not None:
            rep["machine"] = self.machine.name
            rep["axes"] = list(self.machine.axis_names)
        if self.placement is not None:
            p = self.placement
            rep["placement"] = {"axis": p.axis, "mode": p.mode, "mandrel_z0": p.z0, "range": [p.q_min, p.q_max],
                                "travel": [p.lo, p.hi], "fits": p.fits,
                                "z0_fit": list(p.z0_fit) if p.z0_fit else None, "message": p.message()}
        if self.eye is not None:
            s_eye = np.asarray(self.eye.s, dtype=float)
            rep["fibre_length_mm"] = float(s_eye[-1] - s_eye[0]) if s_eye.size else 0.0
        if self.blocks is not None and self.machine is not None:
            qb = np.asarray(self.blocks.q, dtype=float)
            rep["axis_ranges"] = {n: [float(qb[:, k].min()), float(qb[:, k].max())]
                                  for k, n in enumerate(self.machine.axis_names)}
        if self.axes is not None:
            rep["violations"] = [{"kind": g.kind, "axis": g.axis, "what": g.what, "worst": g.worst, "value": g.value,
                                  "limit": g.limit, "places": g.places, "count": g.points, **g.first}
                                 for g in self.violation_groups()]
        if self.line is not None:
            keep = ("slips", "bridging", "turnarounds")
            rep["winding"] = {
                k: v for k, v in self.line.summary().items() if not isinstance(v, list | np.ndarray) or k in keep
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
            rep["max_jump_ratio"] = _jump_ratios(b, self.machine)
            rep["block_accel_ratio"] = _block_accel_ratios(b, self.machine)
            rep["max_error_mm"] = float(np.max(b.max_error)) if b.n else 0.0
        if self.timelaw is not None:
            rep["timelaw"] = dict(self.timelaw)
        if self.post_name:
            rep["post"] = self.post_name
        rep["warnings"] = self.warnings()
        rep["reused_stages"] = list(self.reused)
        return rep


def process_refusals(result: Any) -> list[str]:
    """Why the process itself fails, as ``winder trajectory`` (slip, bridging) and ``winder payout``
    (an infeasible eye path) report it with exit code 1; empty when it does not.  ``winder run``
    refuses to write a program for any of these (unless ``--force``)."""
    out: list[str] = []
    line = result.line
    if line is not None:
        for z0, z1 in getattr(line, "slips", ()) or ():
            out.append(f"the band slips (|λ| up to {_slip_lambda(line, z0, z1):.4g} > μ = {line.mu:g}) for z in "
                       f"[{z0:.2f}, {z1:.2f}] mm")
        for z0, z1 in getattr(line, "bridging", ()) or ():
            out.append(f"the band bridges (does not lie on the mandrel) for z in [{z0:.2f}, {z1:.2f}] mm")
    eye = result.eye_circuit
    if eye is not None and not eye.feasible:
        out += _payout_warnings(eye)
    return out


def _payout_warnings(eye: Any) -> list[str]:
    """One line per payout constraint the eye path breaks: where and by how much."""
    law = eye.report.get("law", "?")
    cons = eye.report.get("constraints") or {}
    out: list[str] = []
    for name, c in cons.items():
        if not isinstance(c, dict) or c.get("ok", True):
            continue
        if "l_end_minus_l_start" in c:
            out.append(f"payout ({law} law): not cyclic, the free length differs by "
                       f"{c['l_end_minus_l_start']:.3f} mm between the start and the end of a circuit")
            continue
        runs = c.get("violated") or []
        where = "; ".join(f"z {r['z_from']:.2f}..{r['z_to']:.2f} mm ({r['points']} point{'s' * (r['points'] > 1)})"
                          for r in runs[:3])
        more = f" and {len(runs) - 3} more places" if len(runs) > 3 else ""
        out.append(f"payout ({law} law): constraint '{name}' violated by up to {-float(c.get('min_slack', 0.0)):.4g} "
                   f"at {where}{more}")
    return out or [f"payout ({law} law): the eye path is not feasible"]


def _speed_ratios(blocks: Any, machine: Any) -> dict[str, float]:
    v = np.abs(blocks.speed)
    lim = np.array([a.max_speed for a in machine.axes])
    return {name: float(v[:, k].max() / lim[k]) if blocks.n else 0.0 for k, name in enumerate(machine.axis_names)}


def _corner_steps(blocks: Any) -> tuple[np.ndarray, np.ndarray]:
    """Speed steps at the block boundaries (units/s) and the mean duration of the two blocks (s)."""
    v = blocks.speed
    t = blocks.time
    if blocks.cyclic:
        return np.abs(np.roll(v, -1, axis=0) - v), 0.5 * (t + np.roll(t, -1))
    return np.abs(np.diff(v, axis=0)), 0.5 * (t[1:] + t[:-1])


def _accel_ratios(blocks: Any, machine: Any) -> dict[str, float]:
    """Acceleration the program needs, per axis, / max_accel.

    Each block runs at a constant speed; at a block boundary the machine takes a speed step of up to
    ``max_jump`` at once (the template's allowed jump, (18) of the seeds) and only the part of a step
    beyond it must be bled at ``max_accel``, within the two blocks around the boundary.  So this is
    ``max((|Δv| − max_jump)⁺ / t_mean) / max_accel`` - 0 when every step is within the jump."""
    if blocks.n < 2:
        return {name: 0.0 for name in machine.axis_names}
    dv, tm = _corner_steps(blocks)
    p = machine.limits("max_jump")
    a = np.maximum(dv - p, 0.0) / tm[:, None]
    lim = machine.limits("max_accel")
    return {name: float(a[:, k].max() / lim[k]) for k, name in enumerate(machine.axis_names)}


def _block_accel_ratios(blocks: Any, machine: Any) -> dict[str, float]:
    """Speed step at a block boundary spread over the mean duration of its two blocks, per axis, /
    max_accel (a smoothness figure of the block program: how hard a controller that blends the corners
    over the blocks would accelerate; docs/timeparam.md's "block accelerations")."""
    if blocks.n < 2:
        return {name: 0.0 for name in machine.axis_names}
    dv, tm = _corner_steps(blocks)
    a = dv / tm[:, None]
    lim = machine.limits("max_accel")
    return {name: float(a[:, k].max() / lim[k]) for k, name in enumerate(machine.axis_names)}


def _jump_ratios(blocks: Any, machine: Any) -> dict[str, float]:
    """Largest speed step at a block boundary, per axis, / max_jump."""
    if blocks.n < 2:
        return {name: 0.0 for name in machine.axis_names}
    dv, _tm = _corner_steps(blocks)
    p = machine.limits("max_jump")
    return {name: float(dv[:, k].max() / p[k]) for k, name in enumerate(machine.axis_names)}


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


def setup_machine_for_job(job: Job, job_path: str | Path | None = None) -> Any:
    """:func:`load_machine_for_job` with the job's ``[machine.setup]`` applied (eye radius, head offsets,
    a fixed placement); see :mod:`engine.machine_setup`."""
    from engine.machine_setup import apply_setup

    try:
        return apply_setup(load_machine_for_job(job, job_path), job.machine.setup)
    except InputError as exc:
        raise exc.at(file=job_path) from None


def run_pipeline(
    job: Job,
    job_path: str | Path | None = None,
    *,
    upto: str = "nc",
    previous: PipelineResult | None = None,
    post_name: str | None = None,
    state: State | None = None,
    mandrel: Any = None,
    line: Any = None,
) -> PipelineResult:
    """Run the stages of ``job`` up to ``upto`` (inclusive), re-using ``previous`` where valid.

    This is the single-line pipeline (one winding line).  A layered job (``not job.is_single_line``) is
    wound by :func:`engine.laminate.run_laminate`, which calls this once per layer with the surface the
    layer is wound on (``mandrel``) and its line (``line``) given; those replace the mandrel and winding
    stages (no re-use across calls then).

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
    if mandrel is not None or line is not None:
        previous = None
    jp = str(job_path) if job_path is not None else None
    if STAGES.index(upto) >= STAGES.index("blocks"):
        from engine.budget import check_post

        check_post(job.post.min_block_time_s, file=jp)  # before the minutes of the stages ahead of it
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
        elif stage == "mandrel" and mandrel is not None:
            res = replace(res, mandrel=mandrel)
            times[stage] = 0.0
        elif stage == "winding" and line is not None:
            res = replace(res, line=line)
            times[stage] = 0.0
        else:
            t0 = time.perf_counter()
            try:
                res = _run_stage(res, stage, sub)
            except InputError as exc:  # every message names the job file (and the field's line)
                raise _locate(exc, jp, stage) from None
            times[stage] = time.perf_counter() - t0
        if stage == "winding" and last >= STAGES.index("axes"):
            # cheap checks before the long stages (payout, time law): post x machine, eye radius, carriage
            # travel (after the winding stage, whose budget checks come first)
            from engine.machine_setup import precheck

            try:
                precheck(job, setup_machine_for_job(job, jp), res.mandrel, with_post=upto == "nc", line=res.line)
            except InputError as exc:
                raise _locate(exc, jp, "nc") from None
        res = replace(res, keys={**res.keys, stage: keys[stage]})
        done += w
        if state is not None:
            state.progress(min(done, 1.0), f"{stage} done")
            state.partial(res)
        del i
    return replace(res, stage_times=times, reused=tuple(reused))


# fields the stages' engine functions name without their job section
_STAGE_FIELD_NAMES = {"nc": {"post": "post.post", "controller": "post.controller"}}


def _locate(exc: InputError, job_path: str | None, stage: str | None = None) -> InputError:
    """``exc`` with the job file and the line of its field filled in (a profile file's own place wins)."""
    if job_path is None or exc.location.file not in (None, job_path):
        return exc
    fld = exc.location.field
    if fld and stage in _STAGE_FIELD_NAMES and fld in _STAGE_FIELD_NAMES[stage]:
        exc = InputError(exc.message, file=exc.location.file, line=exc.location.line,
                         field=_STAGE_FIELD_NAMES[stage][fld]) if type(exc) is InputError else exc
        fld = exc.location.field
    line = exc.location.line
    if line is None and fld:
        from engine.budget import field_line

        line = field_line(job_path, fld)
    return exc.at(file=job_path, line=line)


_STAGE_FIELDS = {
    "mandrel": ("mandrel",),
    "winding": ("line",),
    "payout": ("eye_circuit", "eye"),
    "axes": ("machine", "axes", "placement"),
    "blocks": ("blocks", "timelaw", "timelaw_laws", "timelaw_labels", "timelaw_paths"),
    "nc": ("nc_text", "post_name", "extension"),
}


# None / empty when the stage ran without a time law (method "blocks")
_OPTIONAL_FIELDS = ("timelaw", "timelaw_laws", "timelaw_labels", "timelaw_paths", "placement")


def _has(res: PipelineResult, stage: str) -> bool:
    return all(getattr(res, f) is not None for f in _STAGE_FIELDS[stage] if f not in _OPTIONAL_FIELDS)


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
        from engine.periodic import replicate_axes

        def run_axes(eye: Any) -> tuple[Any, Any, Any]:
            return _axes_stage(job, jp, res.mandrel, eye, state)

        out = replicate_axes(res.line, res.eye, run_axes) or run_axes(res.eye)
        return replace(res, machine=out[0], axes=out[1], placement=out[2])
    if stage == "blocks":
        from engine.blocks import make_blocks, optimise_block_times
        from engine.budget import check_post

        check_post(job.post.min_block_time_s, file=jp)

        # internal axis positions, once for the circuit plan and the time law (an (N, axes) array); a
        # replicated axis path (engine.periodic) needs them on three circuits only
        X = (res.machine.to_internal(np.asarray(res.axes.q, dtype=float))
             if job.timelaw.method != "blocks" and _periodic_pieces(res) is None else None)
        blocks = make_blocks(
            res.machine, res.axes, tol_mm=job.post.tolerance_mm, min_block_time=job.post.min_block_time_s,
            state=SubState(state, 0.0, 0.5) if state is not None else None, pieces=_block_pieces(res, X),
        )
        if job.timelaw.method == "blocks":
            blocks = optimise_block_times(blocks, res.machine, state=SubState(state, 0.5, 1.0) if state else None)
            return replace(res, blocks=blocks, timelaw=None, timelaw_laws=(), timelaw_labels=(), timelaw_paths=())
        kept: list[tuple[str, Any, TimeLawPath]] = []
        blocks, info = _time_law_blocks(res, blocks, SubState(state, 0.5, 1.0) if state is not None else None,
                                        keep=kept, X=X)
        return replace(res, blocks=blocks, timelaw=info, timelaw_laws=tuple(k[1] for k in kept),
                       timelaw_labels=tuple(k[0] for k in kept), timelaw_paths=tuple(k[2] for k in kept))
    if stage == "nc":
        from engine.machine_setup import controller_for
        from engine.post import get_post

        post = get_post(job.post.post)
        profile = controller_for(post.name, job.post.controller, res.machine)
        text = post.render(res.blocks, res.machine, profile)
        return replace(res, nc_text=text, post_name=post.name, extension=post.extension)
    raise AssertionError(stage)  # pragma: no cover


def _axes_stage(job: Job, jp: str | None, mandrel: Any, eye: Any, state: State | None) -> tuple[Any, Any, Any]:
    """The axes stage on the eye path ``eye``: ``(machine, AxisPath, placement)`` (every point computed)."""
    from engine.kinematics import inverse_kinematics
    from engine.machine_setup import (
        clearance_violations,
        fit_eye_radius,
        hold_back_turns,
        monotone_eye_azimuth,
        place_on_machine,
    )

    setup = job.machine.setup
    machine, note = fit_eye_radius(setup_machine_for_job(job, jp), eye, mandrel, setup)
    # an eye-azimuth machine: where the eye path would turn the mandrel back, the eye slides along its fibre
    e_xyz, slid = monotone_eye_azimuth(machine, eye.eye_xyz, eye.fibre_dir, eye.contact_xyz,
                                       float(setup.back_turn_tol_deg))
    axes = inverse_kinematics(machine, e_xyz, eye.fibre_dir, eye.contact_xyz, state=state, x=eye.x)
    if slid.any():
        sh = np.ascontiguousarray(np.asarray(axes.eye_shift) + slid)
        sh.flags.writeable = False
        axes = replace(axes, eye_shift=sh)
    axes = hold_back_turns(machine, axes, float(setup.back_turn_tol_deg))
    machine, axes, placement = place_on_machine(machine, axes, setup)
    if placement is not None and note:
        placement = replace(placement, note=note)
    clear = clearance_violations(axes, mandrel, setup, machine=machine)
    if clear:
        axes = replace(axes, violations=tuple(axes.violations) + tuple(clear))
    return machine, axes, placement


# --------------------------------------------------------------------------------------------------
# The time law drives the blocks (job.timelaw.method = "tube" | "dp" | "toppra"); docs/timeparam.md
# --------------------------------------------------------------------------------------------------
_TL_TOL_SPEED = 0.02    # node refinement: |X'_nodes - X'_path| / V at the axis-speed cap, per axis
_TL_TOL_ACCEL = 0.10    # node refinement: |X''_nodes - X''_path| / A at the axis-speed cap squared
_TL_STRIDE = 16         # initial node spacing (path points) before the refinement
_TL_SPLIT_ROUNDS = 24   # block-splitting rounds for the speed-jump limits
_TL_VB_SHARE = 0.5      # share of the local speed cap used as the circuit boundary speed (halved if infeasible)


LAW_WHOLE = "whole program"
LAW_REPEATED = "circuit (repeated)"
LAW_FIRST = "first circuit ramp"
LAW_LAST = "last circuit ramp"


@dataclass(frozen=True)
class TimeLawPath:
    """The problem one time law of the blocks stage solved: its nodes and limits.

    Attributes
    ----------
    s, X, dX, ddX:
        Nodes: path length (mm, from 0), internal axis positions, dX/ds and d²X/ds² (per mm).
    limits:
        :class:`engine.timeparam.TimeLimits` (boundary speeds included).
    iteration_s_offset:
        Path length (mm) to add to the ``s`` of the law's iteration log to place it on ``s`` (non-zero
        for the last circuit's ramp, whose iterations run on the ramp only).
    """

    s: np.ndarray
    X: np.ndarray
    dX: np.ndarray
    ddX: np.ndarray
    limits: Any
    iteration_s_offset: float = 0.0


def timelaw_path(result: PipelineResult, index: int | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray,
                                                                            np.ndarray, Any]:
    """``(s, X, dX, ddX, limits)`` of the time law ``index`` of ``result`` (default: the main law), to
    re-run :func:`engine.timeparam.parametrize` with another method on the same path and limits.

    Raises
    ------
    InputError
        When the blocks stage ran without a time law or ``index`` is out of range.
    """
    if not result.timelaw_paths:
        raise InputError("the pipeline kept no time law (run the blocks stage with [timelaw].method tube, dp "
                         "or toppra)", field="timelaw.method")
    i = result.timelaw_main if index is None else int(index)
    if not 0 <= i < len(result.timelaw_paths):
        raise InputError(f"time law index {i} out of range 0..{len(result.timelaw_paths) - 1}", field="index")
    p = result.timelaw_paths[i]
    return p.s, p.X, p.dX, p.ddX, p.limits


def compare_time_laws(result: PipelineResult, index: int | None = None, methods: tuple[str, ...] = ("dp", "toppra"),
                      state: State | None = None) -> dict[str, Any]:
    """The time law ``index`` of ``result`` re-computed by each of ``methods`` on the same path and limits.

    The law itself is re-used for its own method.  Returns ``{method: TimeLaw}``.
    """
    i = result.timelaw_main if index is None else int(index)
    nodes = timelaw_path(result, i)
    own = result.timelaw_laws[i]
    out: dict[str, Any] = {}
    for k, m in enumerate(methods):
        check_cancel(state)
        if m == own.method and result.timelaw_labels[i] not in (LAW_FIRST, LAW_LAST):
            out[m] = own
            continue
        sub = SubState(state, k / len(methods), (k + 1) / len(methods)) if state is not None else None
        out[m] = _parametrize(m, nodes[:4], nodes[4], sub)
    return out


class _NoPartial:
    """Forwards progress and cancellation but not the tube iterations (the pipeline's partials are
    PipelineResults)."""

    def __init__(self, parent: State | None) -> None:
        self._p = parent

    def progress(self, fraction: float, message: str = "") -> None:
        if self._p is not None:
            self._p.progress(fraction, message)

    def cancelled(self) -> bool:
        return self._p is not None and self._p.cancelled()

    def partial(self, result: Any) -> None:
        pass


def _hermite_derivs(X0, X1, D0, D1, E0, E1, h, tau):  # noqa: ANN001, ANN202
    """dX/ds and d²X/ds² of the quintic Hermite interpolant (the time law's path model) at ``tau``."""
    a1, a2 = h * D0, h * h * E0 / 2.0
    r0, r1, r2 = X1 - X0 - a1 - a2, h * D1 - a1 - 2.0 * a2, h * h * E1 - 2.0 * a2
    a3, a4, a5 = 10.0 * r0 - 4.0 * r1 + 0.5 * r2, -15.0 * r0 + 7.0 * r1 - r2, 6.0 * r0 - 3.0 * r1 + 0.5 * r2
    d1 = (a1 + tau * (2.0 * a2 + tau * (3.0 * a3 + tau * (4.0 * a4 + tau * 5.0 * a5)))) / h
    d2 = (2.0 * a2 + tau * (6.0 * a3 + tau * (12.0 * a4 + tau * 20.0 * a5))) / (h * h)
    return d1, d2


def _law_nodes(s: np.ndarray, X: np.ndarray, D1: np.ndarray, D2: np.ndarray, V: np.ndarray, A: np.ndarray
               ) -> np.ndarray:
    """Path points used as time-law nodes: every ``_TL_STRIDE``-th point, refined (worst point first)
    until the quintic Hermite interpolant of the nodes reproduces the path's X' and X'' at every path
    point: speed error <= 2 % of V and acceleration error <= 10 % of A at the local speed cap."""
    n = s.size
    isn = np.zeros(n, bool)
    isn[::_TL_STRIDE] = True
    isn[-1] = True
    from engine.blocks import max_abs_over

    w = max_abs_over(D1, V)
    sref = 1.0 / np.maximum(w, 1e-300)
    sref = np.minimum(sref, 1e12)
    active = np.ones(n, bool)                      # points whose segment may still be bad
    for _ in range(200):
        nd = np.flatnonzero(isn)
        pts = np.flatnonzero(~isn & active)
        if pts.size == 0:
            break
        seg = np.searchsorted(nd, pts, side="right") - 1
        a, b = nd[seg], nd[seg + 1]
        h = s[b] - s[a]
        tau = (s[pts] - s[a]) / h
        e1 = e2 = None               # max over the axes of |X'_nodes - X'| / V and |X''_nodes - X''| / A
        for k in range(X.shape[1]):  # column by column: the same elementwise operations, a maximum is exact
            d1, d2 = _hermite_derivs(X[a, k], X[b, k], D1[a, k], D1[b, k], D2[a, k], D2[b, k], h, tau)
            d1 -= D1[pts, k]
            c1 = np.abs(d1, out=d1)
            c1 /= V[k]
            d2 -= D2[pts, k]
            c2 = np.abs(d2, out=d2)
            c2 /= A[k]
            e1 = c1 if e1 is None else np.maximum(e1, c1, out=e1)
            e2 = c2 if e2 is None else np.maximum(e2, c2, out=e2)
        e1 *= sref[pts]
        e2 *= sref[pts] ** 2
        err = np.maximum(e1 / _TL_TOL_SPEED, e2 / _TL_TOL_ACCEL)
        bad = err > 1.0
        if not bad.any():
            break
        o = np.lexsort((-err, seg))
        first = np.concatenate([[True], seg[o][1:] != seg[o][:-1]])
        worst = o[first]
        worst = worst[bad[worst]]
        isn[pts[worst]] = True
        # only the points of segments that were bad need another look
        bad_seg = np.zeros(nd.size, bool)
        bad_seg[seg[worst]] = True
        active[:] = False
        active[pts[bad_seg[seg]]] = True
    return np.flatnonzero(isn)


def _abs_max(X: np.ndarray) -> np.ndarray:
    """``np.abs(X).max(axis=0)`` without the (N, axes) temporary (the same values: max |x| = max(max x, −min x)),
    column by column (numpy reduces over the rows of a few columns about ten times slower)."""
    if X.ndim != 2 or X.shape[0] == 0:
        return np.maximum(X.max(axis=0), -X.min(axis=0))
    return np.array([np.maximum(X[:, k].max(), -X[:, k].min()) for k in range(X.shape[1])], dtype=float)


def _zero_round_off(D: np.ndarray) -> np.ndarray:
    """``np.where(np.abs(D) < 1e-12 · (np.abs(D).max(axis=0) + 1e-300), 0.0, D)`` column by column (the same
    values): derivatives at round-off level are exact zeros (an axis at rest), not noise."""
    if D.ndim != 2 or D.shape[0] == 0:
        scale = np.abs(D).max(axis=0) + 1e-300
        return np.where(np.abs(D) < 1e-12 * scale, 0.0, D)
    out = np.empty(D.shape)
    for k in range(D.shape[1]):
        c = D[:, k]
        a = np.abs(c)
        out[:, k] = np.where(a < 1e-12 * (a.max() + 1e-300), 0.0, c)
    return out


def _periodic_pieces(res: PipelineResult) -> list[tuple[int, int]] | None:
    """The circuits of an axis path replicated by :func:`engine.periodic.replicate_axes` (circuits 1 ..
    n-1 are circuit 1 with the mandrel advanced by a constant: nothing to check point by point), when the
    eye path maps line points to path points one to one; else None."""
    from engine.periodic import circuit_pieces, field_rows, raw_field_or

    if res.axes is None or res.eye is None or getattr(res.axes, "circuits", None) is None:
        return None
    idx = raw_field_or(res.eye, "index")
    n = np.shape(res.axes.q)[0]
    if (idx is None or len(idx) != n or int(field_rows(res.eye, "index", 0, 1)[0]) != 0
            or int(field_rows(res.eye, "index", n - 1, n)[0]) != n - 1):
        return None
    return circuit_pieces(res.axes, res.eye.s)


def _circuit_plan(res: PipelineResult, s: np.ndarray, X: np.ndarray) -> list[tuple[int, int]]:
    """Path-index ranges ``(start, end)`` (inclusive) of the pieces that get a law each: the circuits
    when the middle ones repeat the same motion (up to constant axis offsets, e.g. the mandrel angle),
    else the whole program as one piece.  Circuit k starts at line point ``k·points_per_circuit``;
    ``EyePath.index`` maps line points to path points (the payout may drop zero-length steps)."""
    n = s.size
    whole = [(0, n - 1)]
    line = res.line
    nc = int(getattr(line, "circuits", 1) or 1)
    m = int(getattr(line, "points_per_circuit", 0) or 0)
    idx = getattr(res.eye, "index", None)
    if nc < 3 or m < 2 or idx is None or len(idx) != n:
        return whole
    idx = np.asarray(idx, dtype=np.int64)
    starts = np.arange(nc + 1) * m
    bk = np.searchsorted(idx, starts)
    if np.any(bk >= n) or np.any(idx[np.minimum(bk, n - 1)] != starts) or bk[-1] != n - 1:
        return whole
    pieces = [(int(bk[k]), int(bk[k + 1])) for k in range(nc)]
    a1, b1 = pieces[1]
    dq_ref = X[a1:b1 + 1] - X[a1]
    ds_ref = s[a1:b1 + 1] - s[a1]
    tol_q = 1e-7 * (1.0 + _abs_max(X))
    tol_s = 1e-7 * (1.0 + abs(float(s[-1])))
    mids = pieces[2:-1]
    if any(b - a != b1 - a1 for a, b in mids):
        return whole
    if mids:
        # every middle circuit against circuit 1, all at once and column by column: the same elementwise
        # |X[a + j] - X[a] - dq_ref[j]| > tol_q as circuit by circuit
        first = np.array([a for a, _ in mids], dtype=np.int64)
        rows = first[:, None] + np.arange(b1 - a1 + 1)
        for k in range(X.shape[1]):
            col = X[:, k]
            dev = col[rows]
            dev -= col[first][:, None]
            dev -= dq_ref[:, k]
            if np.any(np.abs(dev, out=dev) > tol_q[k]):
                return whole
        dev = s[rows]
        dev -= s[first][:, None]
        dev -= ds_ref
        if np.any(np.abs(dev, out=dev) > tol_s):
            return whole
    return pieces


_BLOCKS_REPLICATE_MIN = 8   # circuits from which the blocks of the repeated circuit are computed once
# (100 until 2026-11-29, which kept the shipped examples, 28-74 circuits, approximated as a whole)


def _block_pieces(res: PipelineResult, X: np.ndarray | None = None) -> list[tuple[int, int]] | None:
    """The circuits for :func:`engine.blocks.make_blocks`'s replication, when the program has at
    least ``_BLOCKS_REPLICATE_MIN`` circuits and circuits 2 .. n-1 repeat circuit 1 up to a constant
    mandrel angle only (to 1e-9 relative).  Smaller programs are approximated as a whole."""
    if int(getattr(res.line, "circuits", 1) or 1) < _BLOCKS_REPLICATE_MIN or res.eye is None:
        return None
    periodic = _periodic_pieces(res)
    if periodic is not None:
        return periodic
    machine = res.machine
    if X is None:
        X = machine.to_internal(np.asarray(res.axes.q, dtype=float))
    pieces = _circuit_plan(res, np.asarray(res.eye.s, dtype=float), X)
    if len(pieces) < 4:
        return None
    a1, b1 = pieces[1]
    ref = X[a1:b1 + 1] - X[a1]
    tol = 1e-9 * (1.0 + _abs_max(X))
    mandrel = machine.axis_index("mandrel")
    if mandrel is None:
        return None
    for a, b in pieces[2:-1]:
        off = X[a] - X[a1]
        off[mandrel] = 0.0
        if np.any(np.abs(off) > tol) or np.any(np.abs(X[a:b + 1] - X[a] - ref) > tol):
            return None
    return pieces


def _piece_arrays(s: np.ndarray, X: np.ndarray, a: int, b: int, V: np.ndarray, A: np.ndarray
                  ) -> tuple[np.ndarray, ...]:
    """Nodes of the piece of the path a..b: local s (from 0), X, X', X'' (cubic spline of the whole
    piece at full resolution, evaluated at the refined nodes; :func:`engine.knot_spline.knot_derivatives`
    gives SciPy's ``CubicSpline`` derivatives bit for bit without importing ``scipy.interpolate``)."""
    from engine.knot_spline import knot_derivatives

    sp, Xp = s[a:b + 1] - s[a], X[a:b + 1]
    keep = np.concatenate([[True], np.diff(sp) > 0])         # s must increase strictly
    sp, Xp = sp[keep], Xp[keep]
    D1, D2 = knot_derivatives(sp, Xp)
    # derivatives at round-off level are exact zeros (an axis at rest), not noise
    D1, D2 = _zero_round_off(D1), _zero_round_off(D2)
    nodes = _law_nodes(sp, Xp, D1, D2, V, A)
    return sp[nodes], Xp[nodes], D1[nodes], D2[nodes]


def _parametrize(method: str, nodes: tuple[np.ndarray, ...], limits: Any, state: State | None) -> Any:
    from engine.budget import check_dp
    from engine.timeparam import parametrize

    if method != "toppra":
        check_dp(nodes[0].size, limits.levels, method=method)
    with np.errstate(divide="ignore", invalid="ignore"):
        return parametrize(*nodes, limits, method=method, state=_NoPartial(state))


def _junction_cap(pieces: tuple[tuple[np.ndarray, ...], ...], V: np.ndarray, A: np.ndarray) -> float:
    """A path speed the law can hold where circuits meet: the axis-speed cap ``min V/|X'|`` and the
    curvature cap ``min sqrt(A/|X''|)`` on both sides of every junction (the law's limits would
    otherwise make it slow down there anyway)."""
    caps = [np.inf]
    for nodes in pieces:
        for k in (0, -1):
            d1, d2 = np.abs(nodes[2][k]), np.abs(nodes[3][k])
            with np.errstate(divide="ignore"):
                caps.append(float(np.min(np.where(d1 > 0, V / np.where(d1 > 0, d1, 1.0), np.inf))))
                caps.append(float(np.min(np.where(d2 > 0, np.sqrt(A / np.where(d2 > 0, d2, 1.0)), np.inf))))
    return float(min(caps))


def _same_nodes(a: tuple[np.ndarray, ...], b: tuple[np.ndarray, ...]) -> bool:
    """Same nodes and derivatives (the positions may differ by a constant offset, e.g. the mandrel angle)."""
    if a[0].shape != b[0].shape:
        return False
    return all(np.allclose(x, y, rtol=1e-9, atol=1e-9 * (1.0 + float(np.abs(y).max())))
               for x, y in ((a[0], b[0]), (a[2], b[2]), (a[3], b[3])))


def _end_law(method: str, nodes: tuple[np.ndarray, ...], mid: tuple[np.ndarray, ...], law_mid: Any,
             limits: Any, at_start: bool, state: State | None) -> Any:
    """The law of the first (``at_start``) or the last circuit.

    When that circuit is the repeated one (same nodes), only its start (end) needs a law of its own:
    from rest to the middle law's speed at node k (from that speed at node N-1-k to rest), spliced with
    the middle law (constraints act per interval, so the splice is admissible); k = N/8, doubled while
    no admissible ramp exists within k nodes.  Otherwise, or when no k works, the whole circuit.
    """
    from dataclasses import replace as dc_replace

    from engine.errors import InfeasibleError
    from engine.timeparam import curvature_energy

    n = nodes[0].size
    if _same_nodes(nodes, mid):
        k = max(n // 8, 8)
        while k < n - 1:
            check_cancel(state)
            try:
                if at_start:
                    part = _parametrize(method, tuple(x[:k + 1] for x in nodes),
                                        dc_replace(limits, sdot_end=float(law_mid.sdot[k])), state)
                    s = np.concatenate([part.s, law_mid.s[k + 1:]])
                    sdot = np.concatenate([part.sdot, law_mid.sdot[k + 1:]])
                    t = np.concatenate([part.t, part.t[-1] + law_mid.t[k + 1:] - law_mid.t[k]])
                else:
                    j = n - 1 - k
                    part = _parametrize(method, tuple(x[j:] - (x[j] if i == 0 else 0.0) for i, x in enumerate(nodes)),
                                        dc_replace(limits, sdot_start=float(law_mid.sdot[j])), state)
                    s = np.concatenate([law_mid.s[:j], part.s + law_mid.s[j]])
                    sdot = np.concatenate([law_mid.sdot[:j], part.sdot])
                    t = np.concatenate([law_mid.t[:j], law_mid.t[j] + part.t])
                return dc_replace(part, s=s, sdot=sdot, t=t, total_time_s=float(t[-1]),
                                  max_accel_ratio=max(part.max_accel_ratio, law_mid.max_accel_ratio),
                                  max_speed_ratio=max(part.max_speed_ratio, law_mid.max_speed_ratio),
                                  max_sddot_ratio=max(part.max_sddot_ratio, law_mid.max_sddot_ratio),
                                  energy=curvature_energy(t, sdot),
                                  energy_mm=curvature_energy(t, sdot, speed_unit=1.0))
            except InfeasibleError:
                k *= 2
    return _parametrize(method, nodes, limits, state)


def _time_law_blocks(res: PipelineResult, blocks: Any, state: State | None,
                     keep: list[tuple[str, Any, TimeLawPath]] | None = None, X: np.ndarray | None = None
                     ) -> tuple[Any, dict[str, Any]]:
    """Block times from a time law s(t) of the whole program (see docs/timeparam.md, "NC output").

    ``keep`` (optional) receives ``(label, TimeLaw, TimeLawPath)`` of every law computed."""
    from dataclasses import replace as dc_replace

    from engine.errors import InfeasibleError
    from engine.timeparam import TimeLimits, time_at

    job, machine, axes = res.job, res.machine, res.axes
    spec = job.timelaw
    t_start = time.perf_counter()
    s = np.asarray(res.eye.s, dtype=float)
    q = np.asarray(axes.q, dtype=float)
    if s.shape[0] != q.shape[0]:
        raise InputError(f"the eye path has {s.shape[0]} points but the axis path {q.shape[0]}", field="timelaw")
    pieces = _periodic_pieces(res)
    if X is None and pieces is None:
        X = machine.to_internal(q)
    scales = np.abs(machine.scales)
    V = machine.limits("max_speed") / scales
    A = machine.limits("max_accel") / scales
    # the law sees the path through its nodes (quintic Hermite), which reproduce the path's X' within
    # _TL_TOL_SPEED·V and X'' within _TL_TOL_ACCEL·A at the speed cap: the law gets limits reduced by
    # those shares, so the real path (and every block's chord speed) keeps the machine's limits
    limits = TimeLimits(
        v_max=tuple(V * (1.0 - _TL_TOL_SPEED)), a_max=tuple(A * (1.0 - _TL_TOL_ACCEL)),
        sdot_max=float(spec.sdot_max) if spec.sdot_max is not None else float("inf"),
        sddot_max=float(spec.sddot_max) if spec.sddot_max is not None else float("inf"),
        levels=int(spec.levels), penalty=float(spec.penalty), tube_share=float(spec.tube_share),
        stop_percent=float(spec.stop_percent), sdot_start=0.0, sdot_end=0.0, sweep=bool(spec.sweep))
    if pieces is None:
        pieces = _circuit_plan(res, s, X)
    check_cancel(state)

    def piece(a: int, b: int) -> tuple[np.ndarray, ...]:
        if X is not None:
            return _piece_arrays(s, X, a, b, V, A)
        return _piece_arrays(s[a:b + 1], machine.to_internal(q[a:b + 1]), 0, b - a, V, A)

    t_nodes = 0.0
    laws: list[Any] = []
    v_b = 0.0
    if len(pieces) == 1:
        nodes = piece(*pieces[0])
        t_nodes = time.perf_counter() - t_start
        laws = [_parametrize(spec.method, nodes, limits, state)]
        n_nodes = nodes[0].size
        piece_law = [0]
        if keep is not None:
            keep.append((LAW_WHOLE, laws[0], TimeLawPath(*nodes, limits)))
    else:
        first, mid, last = piece(*pieces[0]), piece(*pieces[1]), piece(*pieces[-1])
        n_nodes = first[0].size + mid[0].size + last[0].size
        t_nodes = time.perf_counter() - t_start
        v_b = _TL_VB_SHARE * _junction_cap((first, mid, last), np.asarray(limits.v_max), np.asarray(limits.a_max))
        if spec.sdot_max is not None:
            v_b = min(v_b, _TL_VB_SHARE * float(spec.sdot_max))
        # the circuits need not join smoothly (X' may change at the junction): the boundary speed
        # keeps the speed step of every axis there within its max_jump
        P = machine.limits("max_jump") / scales
        for d_in, d_out in ((first[2][-1], mid[2][0]), (mid[2][-1], mid[2][0]), (mid[2][-1], last[2][0])):
            dd = np.abs(d_out - d_in)
            with np.errstate(divide="ignore"):
                v_b = min(v_b, float(np.min(np.where(dd > 0, P / np.where(dd > 0, dd, 1.0), np.inf))))
        while True:
            check_cancel(state)
            try:
                law_mid = _parametrize(spec.method, mid, dc_replace(limits, sdot_start=v_b, sdot_end=v_b),
                                       SubState(state, 0.0, 0.6) if state is not None else None)
                laws = [
                    _end_law(spec.method, first, mid, law_mid, dc_replace(limits, sdot_end=v_b), True,
                             SubState(state, 0.6, 0.8) if state is not None else None),
                    law_mid,
                    _end_law(spec.method, last, mid, law_mid, dc_replace(limits, sdot_start=v_b), False,
                             SubState(state, 0.8, 1.0) if state is not None else None),
                ]
                break
            except InfeasibleError:
                if v_b <= 0.0:
                    raise
                v_b = 0.0 if v_b < 1e-3 else 0.5 * v_b     # a lower boundary speed, at last rest
        piece_law = [0] + [1] * (len(pieces) - 2) + [2]
        if keep is not None:
            its = laws[2].iterations
            # the last circuit's ramp law logs its iterations on the ramp's own s (from 0)
            off = float(laws[2].s[-1] - its[-1].s[-1]) if its else 0.0
            keep += [(LAW_FIRST, laws[0], TimeLawPath(*first, dc_replace(limits, sdot_end=v_b))),
                     (LAW_REPEATED, laws[1], TimeLawPath(*mid, dc_replace(limits, sdot_start=v_b, sdot_end=v_b))),
                     (LAW_LAST, laws[2], TimeLawPath(*last, dc_replace(limits, sdot_start=v_b), off))]
    # time at every path point: law of its piece, shifted by the time of the pieces before
    n = s.size
    T = np.empty(n)
    t0 = 0.0
    for (a, b), li in zip(pieces, piece_law, strict=True):
        T[a:b + 1] = t0 + time_at(laws[li], s[a:b + 1] - s[a])
        t0 += laws[li].total_time_s
    law_total = t0
    t_laws = time.perf_counter() - t_start - t_nodes
    check_cancel(state)
    out, split_info = _split_for_jumps(machine, axes, blocks, T, float(job.post.min_block_time_s))
    info = {
        "method": spec.method,
        "total_time_s": float(law_total),
        "compute_s": time.perf_counter() - t_start,
        "iterations": int(sum(len(lw.iterations) for lw in laws)),
        "max_accel_ratio": float(max(lw.max_accel_ratio for lw in laws)),
        "max_speed_ratio": float(max(lw.max_speed_ratio for lw in laws)),
        "energy": float(sum(laws[li].energy for li in piece_law)),
        "pieces": len(pieces),
        "laws_computed": len(laws),
        "nodes": int(n_nodes),
        "boundary_speed_mm_s": float(v_b),
        **split_info,
    }
    info["phase_s"] = {"nodes": t_nodes, "laws": t_laws,
                       "blocks": info["compute_s"] - t_nodes - t_laws}
    return out, info


def _jump_pairs(v: np.ndarray, p: np.ndarray, cyclic: bool) -> tuple[np.ndarray, np.ndarray]:
    """Neighbouring blocks ``(i, j = i + 1)`` (and the last with the first when ``cyclic``) whose speeds
    ``v`` (blocks, axes) step by more than ``p`` on some axis; column by column (the same comparisons)."""
    nb = v.shape[0]
    i = np.arange(nb) if cyclic and nb > 2 else np.arange(nb - 1)
    j = (i + 1) % nb
    if i.size == 0:
        return i, j
    pk = p * (1 + 1e-9)
    bad = np.zeros(i.size, bool)
    for k in range(v.shape[1]):
        c = v[:, k]
        d = np.subtract(c[1:], c[:-1]) if i.size == nb - 1 else np.append(c[1:] - c[:-1], c[0] - c[-1])
        np.abs(d, out=d)
        bad |= d > pk[k]
    return i[bad], j[bad]


def _split_for_jumps(machine: Any, axes: Any, blocks: Any, T: np.ndarray, tau: float
                     ) -> tuple[Any, dict[str, Any]]:
    """Blocks timed by the law (``T`` = law time at every path point), split where neighbouring
    block speeds jump by more than ``max_jump`` (the blocks are shorter where the law accelerates;
    the program time stays the law's)."""
    from engine.blocks import preliminary_times
    from engine.kinematics import _rows_divided

    q = np.asarray(axes.q, dtype=float)
    fmax = machine.limits("max_speed")
    p = machine.limits("max_jump")
    idx = np.asarray(blocks.index, dtype=np.int64)
    split = 0
    for _round in range(_TL_SPLIT_ROUNDS):
        dur = np.diff(T[idx])
        v = _rows_divided(np.diff(q[idx], axis=0), dur)
        bi, bj = _jump_pairs(v, p, blocks.cyclic)
        if bi.size == 0:
            break
        cand = np.unique(np.concatenate([bi, bj]))
        cand = cand[idx[cand + 1] - idx[cand] >= 2]
        mids = (idx[cand] + idx[cand + 1]) // 2
        # never below the minimal block time tau of (17)
        ok = (T[mids] - T[idx[cand]] >= tau) & (T[idx[cand + 1]] - T[mids] >= tau)
        cand, mids = cand[ok], mids[ok]
        if cand.size == 0:
            break
        idx = np.sort(np.concatenate([idx, mids]))
        split += int(cand.size)
    qb = q[idx]
    delta = np.diff(qb, axis=0)
    t17 = preliminary_times(delta, fmax, tau)
    dur = np.diff(T[idx])
    clamped = dur < t17
    time_b = np.maximum(dur, t17)
    alpha = np.minimum(t17 / time_b, 1.0)
    err = np.asarray(blocks.max_error, dtype=float)
    if split:
        old = np.asarray(blocks.index, dtype=np.int64)
        k = np.clip(np.searchsorted(old, idx[:-1]), 0, old.size - 2)
        same = (old[k] == idx[:-1]) & (old[k + 1] == idx[1:])
        new_err = np.where(same, err[k], 0.0)
        new_err[~same] = _block_errors(machine, axes, idx, ~same)[~same]
        err = new_err
    arrs = []
    for a in (idx, qb, delta, t17, time_b, alpha, err):
        a = np.ascontiguousarray(a)
        a.flags.writeable = False
        arrs.append(a)
    total = float(time_b.sum())
    out = replace(blocks, index=arrs[0], q=arrs[1], delta=arrs[2], t17=arrs[3], time=arrs[4], alpha=arrs[5],
                  max_error=arrs[6], total_t17=float(t17.sum()), total_start=total, history=(total,))
    if _jump_pairs(np.asarray(out.speed), p, blocks.cyclic)[0].size:
        # where a block cannot be split the speed step to its neighbour may still exceed max_jump: slow
        # the blocks of those steps (a ramp with steps within max_jump and max_accel), never below the law's times
        from engine.machine_setup import limit_speed_steps

        time_b = limit_speed_steps(delta, time_b, p, blocks.cyclic, machine.limits("max_accel"))
        a = np.ascontiguousarray(np.minimum(t17 / time_b, 1.0))
        tb = np.ascontiguousarray(time_b)
        a.flags.writeable = tb.flags.writeable = False
        out = replace(out, time=tb, alpha=a, total_start=float(time_b.sum()), history=(float(time_b.sum()),))
    hard, _ = timelaw_block_check(machine, out)
    out = replace(out, violations=tuple(hard))
    return out, {"blocks_split": split, "blocks_at_min_time": int(clamped.sum()),
                 "time_added_s": float((time_b - dur).sum())}


def timelaw_block_check(machine: Any, blocks: Any) -> tuple[list[Any], list[str]]:
    """Limit check of a block program timed by a time law: ``(violations, warnings)``.

    Position, speed and speed-jump limits are all hard (violations; the warnings list stays empty):
    :func:`_split_for_jumps` splits blocks and slows the pairs it cannot split
    (:func:`engine.machine_setup.stretch_for_jumps`) so that a program it times keeps every one.
    """
    from engine.blocks import check_blocks

    return check_blocks(machine, blocks), []


def _block_errors(machine: Any, axes: Any, idx: np.ndarray, sel: np.ndarray | None = None) -> np.ndarray:
    """Largest eye-position error of the linear interpolation inside every block (as make_blocks
    measures it: a path point is compared at its (17) time fraction of the block), mm; with ``sel``
    (a mask over the blocks) only those blocks are measured (the others get 0).

    On an axis path replicated circuit by circuit (``axes.circuits``, :mod:`engine.periodic`) a block
    of a middle circuit (2 .. n-2) that spans the same points of its circuit as a measured block of
    circuit 1 gets that block's error (the error does not see the mandrel angle, the only axis that
    differs); the (17) metric is then summed within each measured block."""
    q = np.asarray(axes.q, dtype=float)
    nb = idx.size - 1
    chosen = np.arange(nb) if sel is None else np.flatnonzero(sel)
    per = getattr(axes, "circuits", None)
    if per is None or per[0] < 4 or q.shape[0] != per[0] * per[1] + 1:
        return _block_errors_of(machine, axes, idx, chosen, local_metric=False)
    nc, m = per
    c = idx[chosen] // m
    key = (idx[chosen] - c * m) * (m + 1) + (idx[chosen + 1] - c * m)
    mid = (c >= 2) & (c <= nc - 2)
    ref_blocks, ref_key = chosen[c == 1], key[c == 1]
    order = np.argsort(ref_key, kind="stable")
    sk = ref_key[order]
    pos = np.clip(np.searchsorted(sk, key[mid]), 0, max(sk.size - 1, 0))
    found = np.zeros(int(mid.sum()), bool) if sk.size == 0 else sk[pos] == key[mid]
    copy_to = chosen[mid][found]
    compute = np.setdiff1d(chosen, copy_to, assume_unique=True)
    out = _block_errors_of(machine, axes, idx, compute, local_metric=True)
    if copy_to.size:
        out[copy_to] = out[ref_blocks[order][pos[found]]]
    return out


def _block_errors_of(machine: Any, axes: Any, idx: np.ndarray, chosen: np.ndarray, local_metric: bool
                     ) -> np.ndarray:
    """:func:`_block_errors` of the blocks ``chosen`` (sorted); the (17) metric of the whole path
    (``local_metric`` False) or summed within each chosen block (the same up to rounding)."""
    from engine.blocks import interp_rows, row_sums, time_metric
    from engine.kinematics import forward_kinematics
    from engine.periodic import field_take

    q = np.asarray(axes.q, dtype=float)
    fmax = machine.limits("max_speed")
    nb = idx.size - 1
    # inner points of each chosen block; the last block also counts the program's end point (as the
    # make_blocks measure does: its FK residual)
    lengths = idx[chosen + 1] - idx[chosen] - 1 + (chosen == nb - 1)
    chosen, lengths = chosen[lengths > 0], lengths[lengths > 0]
    out = np.zeros(nb)
    if chosen.size == 0:
        return out
    blk = np.repeat(chosen, lengths)
    first = np.concatenate([[0], np.cumsum(lengths)[:-1]])
    pts = np.arange(int(lengths.sum())) - np.repeat(first - idx[chosen] - 1, lengths)
    a, b = idx[blk], idx[blk + 1]
    if local_metric:
        # the metric from each block's start: the steps a..b-1 of every chosen block, summed per block
        steps = idx[chosen + 1] - idx[chosen]
        s0 = np.concatenate([[0], np.cumsum(steps)[:-1]])
        j = np.arange(int(steps.sum())) - np.repeat(s0 - idx[chosen], steps)      # step j: point j -> j+1
        cs = np.concatenate([[0.0], np.cumsum(_step_metric(q, j, fmax))])
        base = np.repeat(cs[s0], lengths)                      # metric at each block's start
        off = np.repeat(s0 - idx[chosen], lengths)             # point p of a block sits at cs[p + off]
        wp = cs[pts + off] - base
        span = cs[np.repeat(s0 + steps, lengths)] - base
        u = np.where(span > 0, wp / np.where(span > 0, span, 1.0), (pts - a) / (b - a))
    else:
        # the (17) time metric w at the points used (a cumulative sum over the path)
        w = time_metric(q, fmax)
        span = w[b] - w[a]
        u = np.where(span > 0, (w[pts] - w[a]) / np.where(span > 0, span, 1.0), (pts - a) / (b - a))
    # q[a] + u·(q[b] − q[a]) with the block ends gathered once per block (the same operands, bit for bit)
    qi = interp_rows(q, idx[chosen], idx[chosen + 1], u, lengths)
    e_fk, _ = forward_kinematics(machine, qi, fibre=False)
    e_fk -= field_take(axes, "eye_xyz", pts)                 # (a deferred eye path: only these rows are made)
    e_fk *= e_fk
    err = np.sqrt(row_sums(e_fk))                            # numpy.linalg.norm(·, axis=1), bit for bit
    out[chosen] = np.maximum.reduceat(err, first)            # blk is sorted: one reduceat per block
    return out


def _step_metric(q: np.ndarray, j: np.ndarray, fmax: np.ndarray) -> np.ndarray:
    """The (17) metric of the steps ``j -> j+1``: ``max_k |q[j+1,k] - q[j,k]| / fmax_k`` (s)."""
    m = None
    for k in range(q.shape[1]):
        c = np.abs(q[j + 1, k] - q[j, k]) / fmax[k]
        m = c if m is None else np.maximum(m, c, out=m)
    return m if m is not None else np.zeros(j.size)


def write_program(result: PipelineResult, path: str | Path, force: bool = False) -> Path:
    """Write the NC text atomically; refuses (InfeasibleError) when there are violations unless forced.
    The refusal lists the violations grouped (kind, axis, worst amount, count, first NC line and time)."""
    from engine.post import write_nc

    if result.nc_text is None:
        raise InputError("no NC program was produced (the pipeline stopped before the NC stage)")
    b = result.blocks
    if b is not None and b.n:
        t = np.asarray(b.time, dtype=float)
        bad = np.flatnonzero(~(np.isfinite(t) & (t > 0)))
        if bad.size or not np.all(np.isfinite(np.asarray(b.q, dtype=float))):
            i = int(bad[0]) if bad.size else 0
            raise InputError(f"not written: {bad.size} block(s) have a non-finite or zero duration (block {i}: "
                             f"{t[i]!r} s), which would be an infinite or zero feed", file=path,
                             field="post.min_block_time_s")
    problems: list[Any] = list(result.violation_groups())
    if problems and result.placement is not None and not result.placement.fits:
        problems.insert(0, _Msg(result.placement.message()))
    return write_nc(path, result.nc_text, problems, force=force)


@dataclass(frozen=True)
class _Msg:
    message: str


def _slip_lambda(line: Any, z0: float, z1: float) -> float:
    """|λ| of a slip range: the line's own figure there (a dwell's k_g/k_n included), else its max |λ|."""
    f = getattr(line, "slip_lambda", None)
    return float(f(z0, z1)) if callable(f) else float(line.max_abs_lambda)
