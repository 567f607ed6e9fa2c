"""Budgets before work: estimate a stage's size from the job, refuse what exceeds the budget.

Every stage that allocates in proportion to a number the user typed (circuits, layers, pattern p,
dwell, band width, points per pass, ...) first calls this module with an estimate of its size.  An
estimate above the budget is an :class:`~engine.errors.InputError` that names the field, the
estimate and the budget, *before* anything is allocated; a physically absurd value (a band narrower
than a fibre, a dwell of many turns) is an input error whatever the budget.

The budget
----------
One number, the memory a run may use (bytes).  Default :data:`DEFAULT_MAX_MEMORY_BYTES` = 4 GiB,
sized for the 2-core, 8–16 GB class of machine the program is tested on (it leaves room for the GUI,
the 3D view and the system).  Raise it with ``winder --max-memory 12G ...`` (any sub-command), the
environment variable ``WINDER_MAX_MEMORY`` or, in the desktop application, Settings → Memory budget
(:func:`set_max_memory`).

Stage estimates (measured, see ``benchmarks/bench_budget.py``): the whole pipeline keeps about
:data:`BYTES_PER_LINE_POINT` bytes per point of the winding line (line, eye path, axes, blocks, time
law and NC text together); the fixed cost of the interpreter and libraries is not counted.  A program
of :data:`REPLICATED_MIN_CIRCUITS` circuits or more keeps its per-point arrays as circuit 0 + rule and
needs :data:`BYTES_PER_REPLICATED_POINT` (``benchmarks/bench_big_variety.py``), unless the process
materialises its results (the desktop application, :func:`set_results_materialised`).

Other stages call :func:`check` with their own :class:`Estimate` (``count`` items × ``bytes_each``),
so new layer kinds use the same mechanism::

    from engine import budget
    budget.check(budget.Estimate("hoop layer points", n, budget.BYTES_PER_LINE_POINT, field="layer[2].turns"),
                 file=job_path)
"""

from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from engine.errors import InputError

DEFAULT_MAX_MEMORY_BYTES = 4 * 2**30
"""Default memory budget of one run (4 GiB)."""

MIN_MAX_MEMORY_BYTES = 64 * 2**20
"""Smallest budget that can be set (64 MiB)."""

BYTES_PER_LINE_POINT = 1000
"""Memory the pipeline keeps per point of the winding line, all stages together (bytes; measured
about 700 on the example vessel with the tube time law, rounded up)."""

BYTES_PER_REPLICATED_POINT = 250
"""The same for a program of at least :data:`engine.periodic.DEFER_MIN_CIRCUITS` circuits, whose line,
eye path and axis path are kept as circuit 0 + rule (issue 16): measured 110–140 bytes per point at the
peak of ``winder run`` on 400 x 8 000 jobs (``benchmarks/bench_big_variety.py``: helical, polar and
non-geodesic layers, the pipe, the bottle, a laminate; the interpreter included), rounded up so that a
laminate's worker and the parent holding its result fit too.  Not used where the results are
materialised (:func:`set_results_materialised`: the desktop application's views read whole arrays)."""

REPLICATED_MIN_CIRCUITS = 8
"""Circuits (of all repeats of a line together) from which the line is kept as circuit 0 + rule
(= :data:`engine.periodic.DEFER_MIN_CIRCUITS`; a test keeps them equal)."""

FIBRE_DIAMETER_MM = 0.005
"""The thinnest reinforcing fibre (carbon, about 5 µm): no band is narrower, no band thinner, and
neighbouring circuits of a pattern are never closer (mm)."""

MAX_DWELL_DEG = 1080.0
"""Largest dwell (extra mandrel rotation) at one turnaround: three turns (deg)."""

MAX_MIN_BLOCK_TIME_S = 10.0
"""Largest minimal block time ``[post].min_block_time_s`` (s): a block lasting longer than this at
its shortest is not a winding program."""

MAX_RADIUS_MM = 1e5
"""Largest mandrel radius (mm): 100 m; anything larger is a unit mistake."""

_ENV = "WINDER_MAX_MEMORY"
_override: int | None = None
_materialised = False


def set_results_materialised(flag: bool) -> None:
    """Say whether this process materialises every per-point array of a result (the desktop application
    does, for its views): a big program then needs :data:`BYTES_PER_LINE_POINT` per point, not
    :data:`BYTES_PER_REPLICATED_POINT`."""
    global _materialised
    _materialised = bool(flag)


def line_point_bytes(circuits: int, per_circuit: int, circuits_known: bool = True) -> float:
    """Memory estimate (bytes) of a line of ``circuits`` circuits (all repeats together) of ``per_circuit``
    points each, through the whole pipeline.  From :data:`REPLICATED_MIN_CIRCUITS` circuits on the
    arrays are kept as circuit 0 + rule (:data:`BYTES_PER_REPLICATED_POINT`), unless this process
    materialises its results.  ``circuits_known`` False: ``circuits`` is only an upper bound (the
    circuits follow from the coverage), so a line of fewer circuits, just below the threshold and
    materialised, is covered too."""
    count = float(circuits) * float(per_circuit)
    if _materialised or circuits < REPLICATED_MIN_CIRCUITS:
        return count * BYTES_PER_LINE_POINT
    rep = count * BYTES_PER_REPLICATED_POINT
    if circuits_known:
        return rep
    below = float(REPLICATED_MIN_CIRCUITS - 1) * float(per_circuit) * BYTES_PER_LINE_POINT
    return max(rep, min(count * BYTES_PER_LINE_POINT, below))


# ------------------------------------------------------------------------------------------------
# The budget
# ------------------------------------------------------------------------------------------------
_SIZE_RE = re.compile(r"^\s*([0-9]*\.?[0-9]+(?:[eE][+-]?[0-9]+)?)\s*([kKmMgGtT]?)(i?[bB])?\s*$")
_UNITS = {"": 1, "k": 2**10, "m": 2**20, "g": 2**30, "t": 2**40}


def parse_size(text: str, field: str = "--max-memory") -> int:
    """Bytes from ``"4G"``, ``"512M"``, ``"12GB"``, ``"1.5g"`` or a plain number of bytes (binary units)."""
    m = _SIZE_RE.match(str(text))
    if not m:
        raise InputError(f"{text!r} is not a size; use e.g. 4G, 512M or 12GB", field=field)
    value = float(m.group(1)) * _UNITS[m.group(2).lower()]
    if not math.isfinite(value) or value < MIN_MAX_MEMORY_BYTES:
        raise InputError(f"{text!r} is below the smallest budget {fmt_bytes(MIN_MAX_MEMORY_BYTES)}", field=field)
    if value > 2**50:
        raise InputError(f"{text!r} is more memory than any machine has", field=field)
    return int(value)


def set_max_memory(n_bytes: int | None) -> None:
    """Set the memory budget of this process (``None``: back to the environment / the default)."""
    global _override
    if n_bytes is not None and n_bytes < MIN_MAX_MEMORY_BYTES:
        raise InputError(f"memory budget {fmt_bytes(n_bytes)} is below {fmt_bytes(MIN_MAX_MEMORY_BYTES)}",
                         field="max_memory")
    _override = None if n_bytes is None else int(n_bytes)


def max_memory_bytes() -> int:
    """The memory budget in force: :func:`set_max_memory`, else ``$WINDER_MAX_MEMORY``, else the default."""
    if _override is not None:
        return _override
    env = os.environ.get(_ENV)
    if env:
        try:
            return parse_size(env, field=_ENV)
        except InputError:
            pass  # a bad environment value must not break every command; the default applies
    return DEFAULT_MAX_MEMORY_BYTES


def fmt_bytes(n: float) -> str:
    """``1.5 GB`` style (binary units)."""
    for unit, f in (("TB", 2**40), ("GB", 2**30), ("MB", 2**20), ("kB", 2**10)):
        if n >= f:
            return f"{n / f:.3g} {unit}"
    return f"{n:.0f} B"


def _fmt_count(n: float) -> str:
    return f"{n:,.0f}" if n < 1e12 else f"{n:.3g}"


@dataclass(frozen=True)
class Estimate:
    """Size of one stage's work: ``count`` items of ``bytes_each`` bytes.

    ``what`` names the items (``"winding-line points"``), ``field`` the job field that drives the
    size, ``detail`` how the count follows from the job (shown in the message).
    """

    what: str
    count: float
    bytes_each: float
    field: str | None = None
    detail: str = ""

    @property
    def bytes(self) -> float:
        """Estimated memory (bytes)."""
        return float(self.count) * float(self.bytes_each)


def check(est: Estimate, *, file: str | Path | None = None, line: int | None = None,
          budget_bytes: int | None = None) -> None:
    """Raise :class:`InputError` (naming ``est.field``) when ``est`` exceeds the memory budget."""
    if line is None and file is not None and est.field:
        line = field_line(file, est.field)
    limit = max_memory_bytes() if budget_bytes is None else int(budget_bytes)
    need = est.bytes
    if not (math.isfinite(need) and need <= limit):
        size = fmt_bytes(need) if math.isfinite(need) and need < 2**70 else "more than any machine has"
        detail = f" ({est.detail})" if est.detail else ""
        raise InputError(
            f"too large: about {_fmt_count(est.count)} {est.what}{detail} would need about {size} of memory; "
            f"the memory budget is {fmt_bytes(limit)} (raise it with --max-memory or Settings → Memory budget "
            "if the machine has the memory)", file=file, line=line, field=est.field)


# ------------------------------------------------------------------------------------------------
# The winding line (engine.winding), the size every later stage follows
# ------------------------------------------------------------------------------------------------
def dwell_points(dwell_deg: float) -> int:
    """Points of one dwell arc (engine.winding: one per 2°, at least 2)."""
    return 0 if dwell_deg <= 0 else max(2, math.ceil(dwell_deg / 2.0))


def check_band(width_mm: float, thickness_mm: float | None, *, file: str | Path | None = None,
               prefix: str = "") -> None:
    """A band is at least a fibre wide and thick, and no thicker than it is wide (a thicker 'band' is a unit
    mistake: the laminate would grow by that much per pass).  ``prefix``: the layer's field prefix."""
    b = float(width_mm)
    if not b >= FIBRE_DIAMETER_MM:
        raise InputError(f"band width {b:g} mm is narrower than a single fibre ({FIBRE_DIAMETER_MM:g} mm); "
                         "check the units", file=file, field=f"{prefix}band.width_mm")
    if thickness_mm is None:
        return
    t = float(thickness_mm)
    if not t >= FIBRE_DIAMETER_MM:
        raise InputError(f"band thickness {t:g} mm is thinner than a single fibre "
                         f"({FIBRE_DIAMETER_MM:g} mm); check the units", file=file, field=f"{prefix}band.thickness_mm")
    if not t <= b:
        raise InputError(f"band thickness {t:g} mm is more than its width {b:g} mm; check the units", file=file,
                         field=f"{prefix}band.thickness_mm")


def check_winding_spec(spec: Any, r_max_mm: float, band_width_mm: float, thickness_mm: float | None = None,
                       ctx: dict[str, Any] | None = None) -> Estimate:
    """Physical sanity and size of the winding line of ``spec`` (:class:`engine.job.WindingSpec`).

    Raises :class:`InputError` (with ``ctx['file']`` and the field) for a band narrower or thinner
    than a fibre, a dwell beyond :data:`MAX_DWELL_DEG`, a pattern whose neighbouring circuits would be
    closer than a fibre, a radius beyond :data:`MAX_RADIUS_MM`, or a line whose estimated memory
    exceeds the budget.  Returns the estimate.
    """
    file = (ctx or {}).get("file")
    b = float(band_width_mm)
    if not b >= FIBRE_DIAMETER_MM:
        raise InputError(f"band width {b:g} mm is narrower than a single fibre ({FIBRE_DIAMETER_MM:g} mm); "
                         "check the units", file=file, field="band.width_mm")
    check_band(b, thickness_mm, file=file)
    if not r_max_mm <= MAX_RADIUS_MM:
        raise InputError(f"the mandrel's largest radius {r_max_mm:g} mm is beyond any winding machine "
                         f"({MAX_RADIUS_MM:g} mm); check the units", file=file, field="mandrel")
    for side, d in zip(("left", "right"), spec.dwell_deg, strict=True):
        if not float(d) <= MAX_DWELL_DEG:
            raise InputError(f"the {side} dwell {float(d):g}° is more than {MAX_DWELL_DEG / 360:g} turns "
                             f"({MAX_DWELL_DEG:g}°)", file=file, field="winding.dwell_deg")
    circ = 2.0 * math.pi * r_max_mm
    p_max = max(1, int(circ / FIBRE_DIAMETER_MM))
    p_eff, p_field = (spec.pattern_p, "winding.pattern_p") if spec.pattern_p is not None else \
        (spec.circuits, "winding.circuits")
    if p_eff is not None and p_eff > p_max:
        raise InputError(f"{p_field.split('.')[1]} = {p_eff}: the circuits of the pattern would lie {circ / p_eff:.3g} "
                         f"mm apart on the largest circumference ({circ:.6g} mm), closer than a fibre "
                         f"({FIBRE_DIAMETER_MM:g} mm); at most {p_max}", file=file, field=p_field)
    n_full = max(1, math.ceil(circ / b - 1e-9))  # circuits for full coverage at most (cos β <= 1)
    if spec.circuits is not None:
        per_layer, fld, why = int(spec.circuits), "winding.circuits", f"circuits = {spec.circuits}"
    elif spec.pattern_p is not None:
        per_layer, fld, why = int(spec.pattern_p), "winding.pattern_p", f"pattern_p = {spec.pattern_p}"
    else:
        per_layer, fld = n_full, "band.width_mm"
        why = f"up to {n_full} circuits to cover radius {r_max_mm:.6g} mm with a {b:g} mm band"
    layers = int(spec.layers)
    if layers > 1 and layers >= per_layer:
        fld = "winding.layers"
    per_circuit = 2 * int(spec.points_per_pass) + sum(dwell_points(float(d) + 180.0) for d in spec.dwell_deg)
    count = float(per_layer) * float(layers) * float(per_circuit)
    known = spec.circuits is not None or spec.pattern_p is not None
    each = line_point_bytes(per_layer * layers, per_circuit, known) / max(count, 1.0)
    est = Estimate("winding-line points", count, each, field=fld,
                   detail=f"{why} × {layers} layer{'s' * (layers != 1)} × about {per_circuit} points a circuit")
    check(est, file=file)
    return est


DP_BYTES_PER_CELL = 64
"""Memory of the time-law DP per node and speed level (bytes; an upper estimate)."""

MAX_DP_WORK = 3e9
"""Largest work of one time-law DP, nodes × levels² (about half a minute on the 2-core machine: the
tube method's passes took 8 s for 893 nodes × 1000² levels)."""


DP_CACHE_LEVELS = 1024
"""Above this many speed levels an interval's M × M transition table (8 MB at 1024) no longer fits the
processor's cache: each cell costs about M / 1024 times more (measured: 4096 levels on a 90-node path took
200 s in the tube method, the plain n × M² model said 15 s)."""

TUBE_PASSES = 3
"""DP passes of the tube method counted before work (the examples stop after 3; the first passes are the
full ones)."""


def dp_work(n_nodes: int, levels: int, passes: int = 1) -> float:
    """Work units of a time-law DP: nodes × levels² × max(1, levels / 1024) × passes (about 1e8 a second)."""
    m = float(levels)
    return float(n_nodes) * m * m * max(1.0, m / DP_CACHE_LEVELS) * passes


def check_dp(n_nodes: int, levels: int, *, field: str = "timelaw.levels", file: str | Path | None = None,
             method: str = "dp") -> None:
    """Refuse a time-law DP (engine.timeparam, methods tube and dp) too slow or too large for the budget."""
    passes = TUBE_PASSES if method == "tube" else 1
    work = dp_work(n_nodes, levels, passes)
    if work > MAX_DP_WORK:
        n = max(n_nodes, 1)
        m_max = int(math.sqrt(MAX_DP_WORK / (n * passes)))
        if m_max > DP_CACHE_LEVELS:
            m_max = int((MAX_DP_WORK * DP_CACHE_LEVELS / (n * passes)) ** (1.0 / 3.0))
        raise InputError(f"too slow: the time law's {method} over {n_nodes} nodes × {levels} speed levels"
                         f"{f' × {passes} passes' if passes > 1 else ''} would take about "
                         f"{work / MAX_DP_WORK * 30:.0f} s (the work budget is about 30 s); use at most "
                         f"{max(m_max, 2)} levels", file=file,
                         line=field_line(file, field) if file is not None else None, field=field)
    check(Estimate("DP cells", float(n_nodes) * float(levels), DP_BYTES_PER_CELL, field=field,
                   detail=f"{n_nodes} nodes × {levels} speed levels"), file=file)


MAX_SKETCH_POINTS = 20_000
"""Most points of a sketched generatrix (``[mandrel] kind = "points"``): a sketch is drawn, not scanned;
a scanned table belongs in a CSV profile, which is decimated (engine.mandrel_io)."""


def check_sketch_points(n: int) -> None:
    """Refuse a sketch of more than :data:`MAX_SKETCH_POINTS` points (field ``z_mm``)."""
    if n > MAX_SKETCH_POINTS:
        raise InputError(f"the sketch has {n} points, at most {MAX_SKETCH_POINTS}: import a scanned profile as a "
                         "CSV table (kind = \"file\"), which is decimated to what the spline needs", field="z")


def field_line(file: str | Path, field: str) -> int | None:
    """Line of ``field`` (dotted, e.g. ``"winding.circuits"``) in the job file ``file``, if it is one."""
    p = Path(file)
    if p.suffix.lower() != ".toml":
        return None
    from engine.job import _find_line

    try:
        text = p.read_text(encoding="utf-8", errors="replace")
    except OSError:
        return None
    parts = [x for x in field.replace("]", "").replace("[", ".").split(".") if x]
    if len(parts) >= 2 and parts[0] == "layer" and parts[1].isdigit():  # 'layer.3.band.width_mm': 3rd [[layer]]
        from engine.job import _find_line_in_array

        line = _find_line_in_array(text, "layer", int(parts[1]) - 1, [x for x in parts[2:] if not x.isdigit()])
        if line is not None:
            return line
    if len(parts) >= 3 and parts[:2] == ["mandrel", "segments"] and parts[2].isdigit():
        from engine.job import _segment_line

        line = _segment_line(text, int(parts[2]), parts[3] if len(parts) > 3 else None)
        if line is not None:
            return line
    keys = tuple(x for x in parts if not x.isdigit())
    while keys:  # the key's line, else the nearest enclosing table's header that the file has
        line = _find_line(text, keys)
        if line is not None:
            return line
        keys = keys[:-1]
    return None


def check_laminate(job: Any, mandrel: Any, *, file: str | Path | None = None) -> Estimate:
    """Physical sanity and size of every enabled layer of a schema-2 job, and of all of them together.

    Helical and polar layers: :func:`check_winding_spec` of the layer's effective winding and band;
    hoop layers: ``passes × turns × points_per_turn`` points, ``turns = length / (band width × (1 −
    overlap))``.  The fields named are the layer's own (``layer.N.circuits``) where it overrides the
    default, else the default's (``winding.circuits``).  The layers' results are kept together, so the
    sum must fit the budget too.  Returns the total estimate.
    """
    from engine.job import HoopLayer, SkipLayer, effective_band, effective_winding

    r_max = float(mandrel.r_max)
    length = float(mandrel.z_max - mandrel.z_min)
    total = 0.0
    total_bytes = 0.0
    worst: tuple[float, str | None] = (-1.0, None)
    for i, layer in job.active_layers:
        if isinstance(layer, SkipLayer):
            continue
        pre = f"layer.{i + 1}"
        band = effective_band(job, layer)
        own_band = {k for k, v in layer.band.model_dump().items() if v is not None}
        b = float(band.width_mm)

        def where(fld: str, pre: str = pre, own_band: set[str] = own_band, layer: Any = layer) -> str:
            sec, _, key = fld.partition(".")
            if sec == "band" and key in own_band:
                return f"{pre}.band.{key}"
            if sec == "winding" and (getattr(layer, key, None) is not None or key == "layers"
                                     and getattr(layer, "repeat", None) is not None):
                return f"{pre}.{'repeat' if key == 'layers' else key}"
            return fld

        if isinstance(layer, HoopLayer):
            try:
                check_band(b, float(band.thickness_mm), file=file)
            except InputError as exc:
                raise InputError(f"layer {i + 1}: {exc.message}", file=file,
                                 field=where(exc.location.field or "band")) from None
            span = (float(layer.z_range_mm[1]) - float(layer.z_range_mm[0]) if layer.z_range_mm is not None
                    else length)
            pitch = b * (1.0 - float(layer.overlap))
            passes = 1 if layer.terminal else int(layer.passes)
            turns = abs(span) / pitch + 1.0
            count = passes * turns * int(layer.points_per_turn) * int(layer.repeat)
            # the field named is the factor furthest above its default (a size attack names the one it set)
            factors = {f"{pre}.repeat": float(layer.repeat), f"{pre}.passes": float(passes),
                       f"{pre}.points_per_turn": layer.points_per_turn / 72.0,
                       f"{pre}.overlap": 1.0 / (1.0 - float(layer.overlap)),
                       where("band.width_mm"): 10.0 / b, f"{pre}.z_range_mm": abs(span) / max(length, 1e-9)}
            worst_factor = max(factors, key=factors.__getitem__)
            est = Estimate("hoop-layer points", count, BYTES_PER_LINE_POINT, field=worst_factor,
                           detail=f"layer {i + 1}: {passes} pass(es) × {turns - 1.0:.4g} turns × "
                                  f"{layer.points_per_turn} points a turn × repeat {layer.repeat}")
            check(est, file=file)
        else:
            spec = effective_winding(job, layer, mandrel)
            try:
                est = check_winding_spec(spec, r_max, b, float(band.thickness_mm), ctx={"file": file})
            except InputError as exc:
                f = exc.location.field
                raise InputError(f"layer {i + 1}: {exc.message}", file=file,
                                 field=where(f) if f else None) from None
            est = Estimate(est.what, est.count, est.bytes_each, field=where(est.field or ""), detail=est.detail)
        total += est.count
        total_bytes += est.bytes
        if est.count > worst[0]:
            worst = (est.count, est.field)
    est = Estimate("points in all layers", total, total_bytes / total if total > 0 else BYTES_PER_LINE_POINT,
                   field=worst[1] or "layer", detail="the layers' results are kept together")
    check(est, file=file)
    return est


MAX_LENGTH_MM = 1e7
"""Largest length or coordinate of a mandrel (mm): 10 km; anything larger is a unit mistake (the same
limit as the profile importers', engine.mandrel_io.MAX_COORD_MM)."""


def check_mandrel_spec(spec: Any) -> None:
    """Refuse a template mandrel (``[mandrel]``) with a length, radius or coordinate beyond
    :data:`MAX_LENGTH_MM` (field: the spec's key), before the spline is built."""
    for key, value in spec.model_dump().items():
        vals = value if isinstance(value, list | tuple) else [value]
        for v in vals:
            if isinstance(v, float | int) and not isinstance(v, bool) and not abs(v) <= MAX_LENGTH_MM:
                raise InputError(f"{key} = {v:g} is beyond any mandrel (at most {MAX_LENGTH_MM:g} mm); check the "
                                 "units", field=key)


def check_post(min_block_time_s: float, *, file: str | Path | None = None) -> None:
    """A minimal block time beyond :data:`MAX_MIN_BLOCK_TIME_S` is an input error."""
    if not float(min_block_time_s) <= MAX_MIN_BLOCK_TIME_S:
        raise InputError(f"min_block_time_s = {min_block_time_s:g} s: a block of at least that long is not a "
                         f"winding program (at most {MAX_MIN_BLOCK_TIME_S:g} s)", file=file,
                         line=field_line(file, "post.min_block_time_s") if file is not None else None,
                         field="post.min_block_time_s")
