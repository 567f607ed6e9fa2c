"""The winding job document: one TOML file holds everything needed to produce an NC program.

Sections: ``[mandrel]`` (generatrix), ``[band]`` (band/material), ``[winding]`` (winding-line
parameters), ``[payout]`` (payout-eye law), ``[machine]`` (machine template and limit overrides),
``[timelaw]`` (time parametrization), ``[post]`` (controller post-processor and NC output), and
(schema version 2) the laminate: an ordered array of tables ``[[layer]]``, each of ``kind`` hoop,
helical, polar or skip.  ``[band]`` and ``[winding]`` are the defaults every layer inherits; a layer
overrides what it names.  A version 1 file (no ``[[layer]]``) loads as one helical layer that
inherits everything, with ``winding.layers`` as its repeat count, and is written back as version 2.

The document is schema-versioned (``schema_version``) and validated with pydantic; every error
names the file, the line and the field (``InputError``).  ``load_job(save_job(job))`` returns an
equal job (floats are written with ``repr`` precision), and saving is atomic.

Example::

    schema_version = 2
    name = "Vessel 200"
    [mandrel]
    kind = "vessel"
    radius_mm = 100.0
    cylinder_length_mm = 300.0
    dome = "isotensoid"
    pole_radius_mm = [25.0, 40.0]
    [band]
    width_mm = 8.0
    [[layer]]
    kind = "hoop"
    [[layer]]
    kind = "helical"
    angles = [{z_mm = 150.0, angle_deg = 30.0}]
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Annotated, Any, Literal

import tomli_w
from pydantic import AfterValidator, BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from engine.errors import InputError
from engine.fileio import MAX_TOML_BYTES, atomic_write_text, loads_toml

SCHEMA_VERSION = 2
SUPPORTED_VERSIONS = (1, 2)

PositiveMM = Annotated[float, Field(gt=0, allow_inf_nan=False)]
NonNegMM = Annotated[float, Field(ge=0, allow_inf_nan=False)]
Finite = Annotated[float, Field(allow_inf_nan=False)]
MAX_DWELL_DEG = 1080.0
"""Largest dwell (deg): 3 turns (= engine.budget.MAX_DWELL_DEG; the schema and the engine agree)."""
MAX_MIN_BLOCK_TIME_S = 10.0
"""Largest ``post.min_block_time_s`` (s) (= engine.budget.MAX_MIN_BLOCK_TIME_S)."""
MAX_TOLERANCE_MM = 10.0
"""Largest ``post.tolerance_mm``: a program may leave the winding line by at most this much (a larger one
replaces the whole line by a few straight moves)."""


def _at_most(limit: float, why: str) -> AfterValidator:
    """A validator refusing values above ``limit`` with ``why`` (``{v}`` = the value, ``{limit}``)."""

    def check(v: float) -> float:
        if not v <= limit:
            raise ValueError(why.format(v=v, limit=limit))
        return v

    return AfterValidator(check)


Dwell = Annotated[float, Field(ge=0, allow_inf_nan=False),
                  _at_most(MAX_DWELL_DEG, "a dwell of {v:g}° is more than 3 turns ({limit:g}°)")]
Friction = Annotated[float, Field(ge=0, allow_inf_nan=False),
                     _at_most(10.0, "a friction coefficient of {v:g} is not physical (at most {limit:g}); check "
                                    "the value")]
MAX_TURN_DEG = 3600.0
"""Largest mandrel rotation of a skip layer or a layer's lead-out (deg): 10 turns; more is a unit mistake
and would be a transition of millions of blocks."""


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, populate_by_name=True)


# ------------------------------------------------------------------------------------------------
# Mandrel
# ------------------------------------------------------------------------------------------------
DomeKind = Literal["hemisphere", "ellipse", "isotensoid"]


class VesselSpec(_Model):
    """Cylinder with two domes; pole openings and dome shapes may differ left/right."""

    kind: Literal["vessel"] = "vessel"
    radius_mm: PositiveMM
    cylinder_length_mm: NonNegMM
    dome: DomeKind | tuple[DomeKind, DomeKind] = "hemisphere"
    dome_ratio: PositiveMM | tuple[PositiveMM, PositiveMM] = 1.0
    pole_radius_mm: NonNegMM | tuple[NonNegMM, NonNegMM] = 0.0


class ConeSpec(_Model):
    """Frustum from r0 at z = 0 to r1 at z = length."""

    kind: Literal["cone"] = "cone"
    r0_mm: PositiveMM
    r1_mm: PositiveMM
    length_mm: PositiveMM


class PipeSpec(_Model):
    """Plain cylinder."""

    kind: Literal["pipe"] = "pipe"
    radius_mm: PositiveMM
    length_mm: PositiveMM


class BottleSpec(_Model):
    """Bottle with an elliptical bottom and a waisted (concave) neck."""

    kind: Literal["bottle"] = "bottle"
    radius_mm: PositiveMM = 60.0
    body_length_mm: PositiveMM = 160.0
    shoulder_length_mm: PositiveMM = 40.0
    waist_radius_mm: PositiveMM = 18.0
    neck_length_mm: PositiveMM = 40.0
    neck_radius_mm: PositiveMM = 24.0
    bottom_pole_radius_mm: PositiveMM = 15.0


class PointsSpec(_Model):
    """A sketched generatrix: C2 spline through points (z increasing)."""

    kind: Literal["points"] = "points"
    z_mm: list[Finite]
    r_mm: list[Finite]

    @model_validator(mode="after")
    def _same_length(self) -> PointsSpec:
        if len(self.z_mm) != len(self.r_mm):
            raise ValueError(f"z_mm has {len(self.z_mm)} values but r_mm has {len(self.r_mm)}")
        return self


class FileSpec(_Model):
    """A generatrix imported from a CSV table, a DXF profile or a STEP solid (path relative to the job)."""

    kind: Literal["file"] = "file"
    path: str
    smoothing_mm: PositiveMM | None = None
    """CSV tables: fit the smoothest spline within this distance of the points (the deviation is reported)."""

    @field_validator("path")
    @classmethod
    def _suffix(cls, v: str) -> str:
        if Path(v).suffix.lower() not in {".csv", ".txt", ".dxf", ".step", ".stp"}:
            raise ValueError(f"'{v}': expected a .csv, .dxf or .step file")
        return v


class SketchSegmentSpec(_Model):
    """One segment of a sketched generatrix (see :mod:`engine.sketch` for the fields each type takes)."""

    type: Literal["line", "arc", "ellipse", "isotensoid", "spline", "smoothstep"]
    to_mm: tuple[Finite, Finite] | None = None
    center_mm: tuple[Finite, Finite] | None = None
    radius_mm: Finite | None = None
    """arc: signed radius (> 0 convex, < 0 concave); isotensoid: the equator radius of a rising dome."""
    semi_axes_mm: tuple[PositiveMM, PositiveMM] | None = None
    pole_radius_mm: NonNegMM | None = None
    points_mm: list[tuple[Finite, Finite]] | None = None
    corner: bool = False
    """The joint at the start of this segment is a corner (not tangent); it must be rounded by fillet_mm."""
    fillet_mm: PositiveMM | None = None


class SegmentsSpec(_Model):
    """A generatrix sketched from exact segments joined tangentially (G1) except at marked corners."""

    kind: Literal["segments"] = "segments"
    start_mm: tuple[Finite, NonNegMM]
    segments: Annotated[list[SketchSegmentSpec], Field(min_length=1)]


MandrelSpec = Annotated[
    VesselSpec | ConeSpec | PipeSpec | BottleSpec | PointsSpec | FileSpec | SegmentsSpec, Field(discriminator="kind")
]


# ------------------------------------------------------------------------------------------------
# Process sections
# ------------------------------------------------------------------------------------------------
class BandSpec(_Model):
    """The band (tow/roving group) laid on the mandrel."""

    width_mm: PositiveMM = 6.0
    thickness_mm: PositiveMM = 0.25
    friction: Friction = 0.2
    """Band-on-mandrel friction coefficient μ (0..10): a line needing |λ| > μ slips."""
    material: str = "carbon/epoxy"


class AngleRequirement(_Model):
    """A winding angle required on the parallel at ``z_mm``."""

    z_mm: Finite
    angle_deg: Annotated[float, Field(gt=0, lt=90)]


class WindingSpec(_Model):
    """Winding-line parameters (see engine.winding)."""

    mode: Literal["auto", "geodesic", "constant-lambda", "piecewise-lambda", "minimax"] = "auto"
    pole_c_mm: tuple[NonNegMM, NonNegMM] | None = None
    """Clairaut constants at the two poles; default: pole radius + band width / 2."""
    angles: list[AngleRequirement] = Field(default_factory=list)
    dwell_deg: tuple[Dwell, Dwell] = (0.0, 0.0)
    """Extra mandrel rotation at the left/right turnaround."""
    points_per_pass: Annotated[int, Field(ge=50, le=200_000)] = 2000
    circuits: Annotated[int, Field(ge=1)] | None = None
    pattern_p: Annotated[int, Field(ge=1)] | None = None
    pattern_q: Annotated[int, Field(ge=1)] | None = None
    layers: Annotated[int, Field(ge=1)] = 1
    lead: Literal["leading", "lagging"] = "leading"
    close_by: Literal["dwell", "angle"] = "dwell"
    """How the pattern is closed (Δv = 2π·q/p): extra dwell at the turnarounds, or (geodesic lines)
    a small change of the winding angle."""


class PayoutSpec(_Model):
    """Payout-eye law (see engine.payout)."""

    law: Literal["parallel", "equidistant", "equal-tangent", "curve", "min-range"] = "min-range"
    impregnation_k: Literal[0, 1] = 1
    clearance_mm: NonNegMM = 20.0
    """Minimum distance of the eye from the mandrel surface."""
    eye_radius_mm: PositiveMM | None = None
    """Eye distance from the axis for the 'parallel' law; default: r_max + clearance."""
    free_length_max_mm: PositiveMM = 400.0
    curve_zr_mm: list[tuple[Finite, Finite]] | None = None
    """Eye path for the 'curve' law: (Z, R) points."""
    grid_points: Annotated[int, Field(ge=50, le=100_000)] = 1000
    u_min: NonNegMM = 0.0
    """Required lower bound of the relative pull speed u = dλ/dx (the min-range law fails below it)."""
    parameter: Literal["s", "v"] = "s"
    """Process parameter x: laid length s (u dimensionless) or mandrel twist v (u in mm/rad)."""
    free_length_mm: PositiveMM | None = None
    """Free length for the 'equal-tangent' law; default: the smallest constant that keeps the clearance."""
    offset_mm: PositiveMM | None = None
    """Eye distance from the mandrel contour for the 'equidistant' law; default: clearance_mm."""
    workspace_z_mm: tuple[Finite, Finite] | None = None
    """Reachable eye Z range (mm, mandrel frame); default: unlimited."""
    workspace_r_mm: tuple[NonNegMM, NonNegMM] | None = None
    """Reachable eye distance from the axis (mm); default: unlimited."""


class AxisOverride(_Model):
    """Limits of one machine axis that replace the template's."""

    min: Finite | None = None
    max: Finite | None = None
    max_speed: PositiveMM | None = None
    max_accel: PositiveMM | None = None
    max_jump: PositiveMM | None = None


class SetupSpec(_Model):
    """Machine set-up ``[machine.setup]``: where the mandrel sits on the machine, the payout head's
    geometry, the supports (shafts, chuck, tailstock) and the tolerances of the machine checks
    (see engine.machine_setup and docs/machines.md, "Set-up")."""

    mandrel_z0_mm: Finite | None = None
    """Carriage (or track) position of the mandrel's z = 0, in the axis' controller units; default: the
    mandrel is centred on the machine (the eye path's carriage range centred in the axis travel)."""
    eye_radius_mm: PositiveMM | None = None
    """Eye distance from the mandrel axis on a fixed-radius machine (no cross feed); default: the template's."""
    head_offset_mm: tuple[Finite, Finite, Finite] = (0.0, 0.0, 0.0)
    """Eye position relative to the head's datum that the axes report: radial (cross feed), vertical,
    axial (mm); the cross, vertical and carriage axes are shifted by it."""
    shaft_radius_mm: PositiveMM | None = None
    """Radius of the mandrel shaft beyond both ends; default: 0.6 x the smaller end radius of the mandrel."""
    shaft_length_mm: NonNegMM = 100.0
    """Free shaft between each mandrel end and the chuck (left) or the tailstock (right)."""
    chuck_radius_mm: PositiveMM | None = None
    """Chuck (left, beyond the shaft) radius; default: 2 x the shaft radius."""
    chuck_length_mm: PositiveMM = 120.0
    tailstock_radius_mm: PositiveMM | None = None
    """Tailstock (right, beyond the shaft) radius; default: 1.5 x the shaft radius."""
    tailstock_length_mm: PositiveMM = 150.0
    clearance_mm: NonNegMM = 5.0
    """Smallest gap the eye keeps from the mandrel, the shafts, the chuck and the tailstock, and the free
    fibre from the shafts, the chuck and the tailstock."""
    head_radius_mm: NonNegMM = 0.0
    """Radius of the payout head's body around the eye (a sphere: roller, guide, its bracket): the gaps of
    the eye to the mandrel and the supports are measured from that body (the clearance plus this radius)."""
    head_length_mm: NonNegMM = 0.0
    """Length of the payout head's body along its roll axis, from the eye back into the head (cartesian
    machines: the roll axis, away from the mandrel axis; robot cell: from the eye towards the flange): the body is
    a capsule of ``head_radius_mm`` around that segment; 0 = a sphere around the eye."""
    back_turn_tol_deg: NonNegMM = 0.01
    """Mandrel back-turns up to this angle are numerical noise: the mandrel angle is held instead."""


class MachineSpec(_Model):
    """Machine template (a file name in resources/machines, or a path), limit overrides and set-up."""

    template: str = "lathe2"
    axes: dict[str, AxisOverride] = Field(default_factory=dict)
    setup: SetupSpec = Field(default_factory=SetupSpec)


class TimeLawSpec(_Model):
    """Time parametrization (see engine.timeparam).

    ``method``: ``"tube"`` (default: DP + tube time law, keeps every axis acceleration limit, sets the
    block times), ``"dp"`` (single DP), ``"toppra"`` (time-optimal reference; may exceed accelerations
    between nodes), ``"blocks"`` (the block times of (17)/(18): speed and speed-jump limits only).
    """

    method: Literal["blocks", "tube", "dp", "toppra"] = "tube"
    levels: Annotated[int, Field(ge=5, le=4096)] = 100
    """M, speed levels per node (the engine packs the level index into 12 bits: at most 4096)."""
    penalty: Annotated[float, Field(ge=0, le=1.0)] = 0.5e-11
    """K, the acceleration penalty of the DP (s per (mm/s²)²; default 5e-12; above 1 every transition costs
    more than any time saved)."""
    tube_share: Annotated[float, Field(gt=0, lt=1)] = 0.1
    stop_percent: Annotated[float, Field(gt=0, le=100)] = 0.5
    sweep: bool = True
    """After the tube, sweep the same limits once more and keep that law where it is faster (the time-optimal
    law for the nodes: up to a few % shorter programs, every limit held; ``false``: the tube's own law, which
    the DP's penalty keeps smoother).  See docs/timeparam.md, "The final sweep"."""
    sdot_max: Annotated[float, Field(ge=1e-3, le=1e9)] | None = None
    """Technological path speed limit (mm/s)."""
    sddot_max: Annotated[float, Field(ge=1e-3, le=1e12)] | None = None
    """Technological path acceleration limit (mm/s²)."""


class PostSpec(_Model):
    """NC output."""

    post: str = "linuxcnc"
    controller: str | None = None
    tolerance_mm: Annotated[PositiveMM, _at_most(MAX_TOLERANCE_MM, "a program {v:g} mm off the winding line does "
                                                 "not lay it (at most {limit:g} mm)")] = 0.05
    min_block_time_s: Annotated[PositiveMM, _at_most(MAX_MIN_BLOCK_TIME_S, "a block of at least {v:g} s is not a "
                                                     "winding program (at most {limit:g} s)")] = 0.004
    output: str | None = None


# ------------------------------------------------------------------------------------------------
# Laminate: layers (schema version 2)
# ------------------------------------------------------------------------------------------------
class LayerBand(_Model):
    """Band values of one layer that override ``[band]`` (unset = inherited)."""

    width_mm: PositiveMM | None = None
    thickness_mm: PositiveMM | None = None
    friction: Friction | None = None
    tows: Annotated[int, Field(ge=1, le=1000)] | None = None
    """Number of tows (rovings) side by side in the band; used for the fibre mass."""
    material: str | None = None


class _LayerBase(_Model):
    name: str = ""
    """Shown in the layer table, the NC comments and the report; default: kind and index."""
    enabled: bool = True
    """A disabled layer stays in the document but is neither wound nor counted."""
    band: LayerBand = Field(default_factory=LayerBand)
    lead_in_mm: Annotated[float, Field(ge=0.0, le=1e5)] = 0.0
    """Carriage move (mm, at most 100 m) from the transition position to the layer's first point, before the
    fibre is laid."""
    lead_out_deg: Annotated[float, Field(ge=0.0, le=MAX_TURN_DEG)] = 0.0
    """Extra mandrel rotation (deg, at most 10 turns) after the layer's last point (the band is tied off on
    the shaft)."""


class HoopLayer(_LayerBase):
    """Near-90° turns along a z range: pitch = band width × (1 − overlap) per mandrel turn."""

    kind: Literal["hoop"] = "hoop"
    z_range_mm: tuple[Finite, Finite] | None = None
    """z range wound (mm); default: the cylindrical part of the surface (r within 0.1 % of r_max)."""
    overlap: Annotated[float, Field(ge=0.0, lt=1.0)] = 0.0
    """Share of the band width laid over the previous turn (0 = butt joints)."""
    passes: Annotated[int, Field(ge=1, le=1000)] = 1
    """Passes over the z range (alternating direction unless ``terminal``); each pass adds one band thickness."""
    terminal: bool = False
    """Wind in one direction only (the carriage returns without laying between passes)."""
    repeat: Annotated[int, Field(ge=1, le=1000)] = 1
    points_per_turn: Annotated[int, Field(ge=8, le=2000)] = 72


class HelicalLayer(_LayerBase):
    """A winding line (geodesic, non-geodesic or minimax): the fields of ``[winding]``, per layer."""

    kind: Literal["helical"] = "helical"
    mode: Literal["auto", "geodesic", "constant-lambda", "piecewise-lambda", "minimax"] | None = None
    pole_c_mm: tuple[NonNegMM, NonNegMM] | None = None
    angles: list[AngleRequirement] | None = None
    angle_deg: Annotated[float, Field(gt=0, lt=90)] | None = None
    """Shortcut: the winding angle on the middle parallel of the cylindrical part (or of the surface); the
    layer is then the geodesic through it (turning where r = C) unless ``mode`` says otherwise."""
    dwell_deg: tuple[Dwell, Dwell] | None = None
    points_per_pass: Annotated[int, Field(ge=50, le=200_000)] | None = None
    circuits: Annotated[int, Field(ge=1)] | None = None
    pattern_p: Annotated[int, Field(ge=1)] | None = None
    pattern_q: Annotated[int, Field(ge=1)] | None = None
    lead: Literal["leading", "lagging"] | None = None
    close_by: Literal["dwell", "angle"] | None = None
    repeat: Annotated[int, Field(ge=1, le=1000)] | None = None
    """Times the pattern is wound (default: ``winding.layers``)."""


class PolarLayer(HelicalLayer):
    """Polar winding: the near-geodesic line tangent to both polar openings (C = opening + band/2 at
    each end unless ``pole_c_mm`` is given); only on a surface closed by two domes."""

    kind: Literal["polar"] = "polar"  # type: ignore[assignment]


class SkipLayer(_LayerBase):
    """A pure mandrel reposition between layers (no fibre laid)."""

    kind: Literal["skip"] = "skip"
    angle_deg: Annotated[float, Field(ge=-MAX_TURN_DEG, le=MAX_TURN_DEG)] = 0.0
    """Mandrel rotation (deg, at most 10 turns either way)."""


LayerSpec = Annotated[HoopLayer | HelicalLayer | PolarLayer | SkipLayer, Field(discriminator="kind")]
LAYER_KINDS: tuple[str, ...] = ("hoop", "helical", "polar", "skip")
_WINDING_OVERRIDES = ("mode", "pole_c_mm", "angles", "dwell_deg", "points_per_pass", "circuits", "pattern_p",
                      "pattern_q", "lead", "close_by")


def layer_name(layer: Any, index: int) -> str:
    """The layer's display name: its own, else ``"<index+1> <kind>"``."""
    return layer.name or f"{index + 1} {layer.kind}"


def effective_band(job: Job, layer: Any) -> BandSpec:
    """``[band]`` with the layer's overrides applied."""
    over = {k: v for k, v in layer.band.model_dump().items() if v is not None and k != "tows"}
    return job.band.model_copy(update=over) if over else job.band


def effective_winding(job: Job, layer: Any, mandrel: Any = None) -> WindingSpec:
    """``[winding]`` with a helical/polar layer's overrides; ``angle_deg`` becomes an angle condition on the
    middle of the cylindrical part of ``mandrel`` (or of the surface)."""
    data = job.winding.model_dump()
    for k in _WINDING_OVERRIDES:
        v = getattr(layer, k, None)
        if v is not None:
            data[k] = v
    rep = getattr(layer, "repeat", None)
    if rep is not None:
        data["layers"] = rep
    ang = getattr(layer, "angle_deg", None)
    if ang is not None and getattr(layer, "angles", None) is None and mandrel is not None:
        from engine.mandrel import cylinder_range

        z0, z1 = cylinder_range(mandrel)
        data["angles"] = [{"z_mm": 0.5 * (z0 + z1), "angle_deg": ang}]
        if getattr(layer, "mode", None) is None:
            # the shortcut means "a helical layer at this angle": the geodesic through it (turning where
            # r = C), not a non-geodesic line also pinned to the default pole values
            data["mode"] = "geodesic"
    return WindingSpec.model_validate(data)


class Job(_Model):
    """A complete winding job."""

    schema_version: Literal[2] = SCHEMA_VERSION
    name: str = "untitled"
    description: str = ""
    mandrel: MandrelSpec
    band: BandSpec = Field(default_factory=BandSpec)
    winding: WindingSpec = Field(default_factory=WindingSpec)
    payout: PayoutSpec = Field(default_factory=PayoutSpec)
    machine: MachineSpec = Field(default_factory=MachineSpec)
    timelaw: TimeLawSpec = Field(default_factory=TimeLawSpec)
    post: PostSpec = Field(default_factory=PostSpec)
    layers: list[LayerSpec] = Field(default_factory=lambda: [HelicalLayer()], alias="layer", min_length=1,
                                    max_length=200)
    """The laminate, wound in this order (TOML: ``[[layer]]``)."""

    @model_validator(mode="before")
    @classmethod
    def _migrate(cls, data: Any) -> Any:
        # version 1: no [[layer]]: one helical layer inheriting everything (winding.layers stays its repeat
        # count, so every message still names the field the user wrote)
        if isinstance(data, dict) and data.get("schema_version", SCHEMA_VERSION) == 1:
            data = dict(data)
            data["schema_version"] = SCHEMA_VERSION
            if "layer" not in data and "layers" not in data:
                data["layer"] = [{"kind": "helical"}]
        return data

    @property
    def active_layers(self) -> list[tuple[int, Any]]:
        """(index, layer) of the enabled layers, in winding order."""
        return [(i, lay) for i, lay in enumerate(self.layers) if lay.enabled]

    @property
    def is_single_line(self) -> bool:
        """True for a job that is one helical layer inheriting every winding value (a version-1 job)."""
        if len(self.layers) != 1 or not isinstance(self.layers[0], HelicalLayer) or self.layers[0].kind != "helical":
            return False
        lay = self.layers[0]
        return all(getattr(lay, k) is None for k in (*_WINDING_OVERRIDES, "angle_deg", "repeat")) and \
            lay.band == LayerBand() and lay.lead_in_mm == 0 and lay.lead_out_deg == 0 and lay.enabled

    def to_toml(self) -> str:
        """The document as TOML text."""
        data = self.model_dump(mode="json", exclude_none=True, by_alias=True)
        layers = data.pop("layer", [])
        text = tomli_w.dumps(_order(data))
        for lay in layers:  # one readable [[layer]] table each (tomli_w would write an inline array)
            head = {k: v for k, v in lay.items() if not isinstance(v, dict)}
            head = {"kind": head.pop("kind"), **head}
            text += "\n[[layer]]\n" + tomli_w.dumps(head)
            for k, v in lay.items():
                if isinstance(v, dict) and v:
                    text += f"\n[layer.{k}]\n" + tomli_w.dumps(v)
        return text

    def replace(self, **changes: Any) -> Job:
        """A copy with top-level sections replaced (validated)."""
        data = self.model_dump(mode="python")
        data.update(changes)
        return Job.model_validate(data)


def _order(data: dict[str, Any]) -> dict[str, Any]:
    head = {k: v for k, v in data.items() if not isinstance(v, dict | list)}
    tail = {k: v for k, v in data.items() if isinstance(v, dict | list)}
    return {**head, **tail}


# ------------------------------------------------------------------------------------------------
# Load / save
# ------------------------------------------------------------------------------------------------
def parse_job(text: str, file: str | Path | None = None) -> Job:
    """Parse and validate TOML text; errors name ``file``, the line and the field."""
    data = loads_toml(text, file)  # size, nesting and every parser failure -> InputError with the line
    if "schema_version" in data and (isinstance(data["schema_version"], bool)
                                     or data["schema_version"] not in SUPPORTED_VERSIONS):
        raise InputError(
            f"schema_version {data['schema_version']!r} is not supported (this program reads versions "
            f"{', '.join(map(str, SUPPORTED_VERSIONS))})",
            file=file,
            line=_find_line(text, ("schema_version",)),
            field="schema_version",
        )
    try:
        return Job.model_validate(data)
    except ValidationError as exc:
        raise _validation_error(exc, text, file) from None


def load_job(path: str | Path) -> Job:
    """Read a job file (.toml)."""
    p = Path(path)
    try:
        if p.stat().st_size > MAX_TOML_BYTES:
            raise InputError(f"the job file is {p.stat().st_size} bytes (at most {MAX_TOML_BYTES})", file=p)
        raw = p.read_bytes()
    except FileNotFoundError:
        raise InputError("file not found", file=p) from None
    except OSError as exc:
        raise InputError(f"cannot read: {exc.strerror}", file=p) from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = raw[: exc.start].count(b"\n") + 1
        raise InputError("not a UTF-8 text file (is this a job .toml?)", file=p, line=line) from None
    if not text.strip():
        raise InputError("the job file is empty", file=p)
    return parse_job(text, file=p)


def save_job(job: Job, path: str | Path) -> Path:
    """Write ``job`` to ``path`` atomically (temporary file + rename)."""
    return atomic_write_text(path, job.to_toml())


def _validation_error(exc: ValidationError, text: str, file: str | Path | None) -> InputError:
    errs = sorted(exc.errors(), key=lambda e: e["type"] != "extra_forbidden")  # a typo explains 'missing'
    first = errs[0]
    loc = _clean_loc(first["loc"])
    field = ".".join(str(p) for p in loc)
    msg = first["msg"]
    if first["type"] == "missing":
        msg = "required field is missing"
    elif first["type"] == "extra_forbidden":
        msg = f"unknown field (typo?); allowed: {_allowed(tuple(first['loc']))}"
    elif first["type"] == "union_tag_invalid":
        msg = f"unknown kind {first.get('ctx', {}).get('tag')!r}; expected {first.get('ctx', {}).get('expected_tags')}"
    elif first["type"] == "literal_error":
        msg = f"{msg} (got {first.get('input')!r})"
    elif first["type"] == "value_error":
        msg = msg.removeprefix("Value error, ")
    elif "input" in first and not isinstance(first["input"], dict | list):
        msg = f"{msg} (got {first['input']!r})"
    if len(errs) > 1:
        msg += f" (and {len(errs) - 1} more problem{'s' if len(errs) > 2 else ''})"
    line = _find_line(text, loc)
    if len(loc) >= 3 and loc[:2] == ("mandrel", "segments") and isinstance(loc[2], int):
        line = _segment_line(text, loc[2], next((p for p in loc[3:] if isinstance(p, str)), None)) or line
        field = f"mandrel.segments[{loc[2]}]" + "".join(f".{p}" for p in loc[3:] if isinstance(p, str))
    if len(loc) >= 2 and loc[0] in ("layer", "layers") and isinstance(loc[1], int):
        # layers are numbered from 1 for people: 'layer.3.overlap' is the third [[layer]]
        field = ".".join(["layer", str(loc[1] + 1), *(str(p) for p in loc[2:])])
        msg = f"layer {loc[1] + 1}: {msg}"
    return InputError(msg, file=file, line=line, field=field)


def _segment_line(text: str, index: int, key: str | None) -> int | None:
    """Line (1-based) of ``key`` in the ``index``-th (0-based) ``[[mandrel.segments]]`` table, or of its header."""
    seen = -1
    header: int | None = None
    for i, line in enumerate(text.splitlines(), start=1):
        h = _HEADER.match(line)
        if h:
            if header is not None:
                break
            if line.strip().startswith("[[") and h.group(1).strip() == "mandrel.segments":
                seen += 1
                if seen == index:
                    header = i
            continue
        k = _KEY.match(line)
        if header is not None and key and k and k.group(1).strip("\"'") == key:
            return i
    return header


def _clean_loc(loc: tuple[Any, ...]) -> tuple[Any, ...]:
    # drop discriminator tags (e.g. ('mandrel', 'vessel', 'radius_mm')) and tuple/union members
    out: list[Any] = []
    for i, part in enumerate(loc):
        if i > 0 and loc[0] == "mandrel" and i == 1 and part in {"vessel", "cone", "pipe", "bottle", "points", "file",
                                                                 "segments"}:
            continue
        if i == 2 and loc[0] in ("layer", "layers") and part in LAYER_KINDS:
            continue
        if isinstance(part, str) and ("[" in part or part in {"tuple", "float", "function-after"}
                                      or part.startswith("constrained-")):  # union members: float | tuple
            continue
        out.append(part)
    return tuple(out)


def _allowed(loc: tuple[Any, ...]) -> str:
    models: dict[str, type[BaseModel]] = {
        "band": BandSpec,
        "winding": WindingSpec,
        "payout": PayoutSpec,
        "machine": MachineSpec,
        "timelaw": TimeLawSpec,
        "post": PostSpec,
    }
    kinds: dict[str, type[BaseModel]] = {
        "vessel": VesselSpec,
        "cone": ConeSpec,
        "pipe": PipeSpec,
        "bottle": BottleSpec,
        "points": PointsSpec,
        "file": FileSpec,
        "segments": SegmentsSpec,
    }
    if len(loc) >= 5 and loc[0] == "mandrel" and loc[1] == "segments" and loc[2] == "segments":
        return ", ".join(SketchSegmentSpec.model_fields)
    if len(loc) >= 3 and loc[0] == "mandrel" and loc[1] in kinds:
        return ", ".join(kinds[loc[1]].model_fields)
    if len(loc) >= 3 and loc[:2] == ("machine", "setup"):
        return ", ".join(SetupSpec.model_fields)
    layer_kinds: dict[str, type[BaseModel]] = {"hoop": HoopLayer, "helical": HelicalLayer, "polar": PolarLayer,
                                               "skip": SkipLayer}
    if len(loc) >= 4 and loc[0] == "layer" and loc[2] in layer_kinds:
        if loc[3] == "band" and len(loc) >= 5:
            return ", ".join(LayerBand.model_fields)
        return ", ".join(layer_kinds[loc[2]].model_fields)
    if len(loc) >= 2 and loc[0] in models:
        return ", ".join(models[loc[0]].model_fields)
    if len(loc) == 1:
        return ", ".join(Job.model_fields)
    return "see the documentation"


_HEADER = re.compile(r"^\s*\[\[?\s*([^\]]+?)\s*\]\]?\s*(#.*)?$")
_KEY = re.compile(r"^\s*([A-Za-z0-9_\-\"']+)\s*=")


def _find_line(text: str, loc: tuple[Any, ...]) -> int | None:
    """Best-effort line number (1-based) of the TOML key at ``loc``; the section header if absent."""
    if len(loc) >= 2 and isinstance(loc[0], str) and isinstance(loc[1], int):
        return _find_line_in_array(text, loc[0], loc[1], [p for p in loc[2:] if isinstance(p, str)])
    keys = [p for p in loc if isinstance(p, str)]
    if not keys:
        return None
    section, key = keys[:-1], keys[-1]
    sec_name = ".".join(section)
    current = ""
    header_line: int | None = None
    for i, line in enumerate(text.splitlines(), start=1):
        h = _HEADER.match(line)
        if h:
            current = h.group(1).strip()
            if current == sec_name and header_line is None:
                header_line = i
            if current == ".".join(keys):
                return i
            continue
        k = _KEY.match(line)
        if k and current == sec_name and k.group(1).strip("\"'") == key:
            return i
        if k and not section and current == "" and k.group(1) == key:
            return i
    # dotted/inline: 'mandrel.radius_mm = ...' or key in a table of the same name
    return header_line


def _find_line_in_array(text: str, table: str, index: int, keys: list[str]) -> int | None:
    """Line (1-based) of ``keys`` inside the ``index``-th ``[[table]]`` (its header when absent)."""
    count = -1
    header: int | None = None
    inline: int | None = None
    sub = ""
    for i, line in enumerate(text.splitlines(), start=1):
        h = _HEADER.match(line)
        if h:
            name = h.group(1).strip()
            if line.lstrip().startswith("[[") and name == table:
                count += 1
                sub = ""
                if count == index:
                    header = i
                elif count > index:
                    break
                continue
            if count == index and name.startswith(table + "."):
                sub = name[len(table) + 1:]
                if keys and sub == ".".join(keys):
                    return i
                continue
            if count == index:
                break
            continue
        if count != index or not keys:
            continue
        k = _KEY.match(line)
        if k and sub == ".".join(keys[:-1]) and k.group(1).strip("\"'") == keys[-1]:
            return i
        if k and not sub and len(keys) > 1 and k.group(1).strip("\"'") == keys[0] and inline is None:
            inline = i  # an inline table: 'band = { width_mm = ... }'
    return inline or header


def build_mandrel(job: Job, job_path: str | Path | None = None) -> Any:
    """The :class:`engine.mandrel.Mandrel` described by ``job.mandrel``.

    Errors carry the job file and the ``mandrel.*`` field they come from.
    """
    from engine.mandrel import Mandrel

    spec = job.mandrel
    try:
        from engine.budget import check_mandrel_spec

        check_mandrel_spec(spec)
        if isinstance(spec, VesselSpec):
            return Mandrel.vessel(
                spec.radius_mm,
                spec.cylinder_length_mm,
                dome=spec.dome,  # type: ignore[arg-type]
                pole_radii=spec.pole_radius_mm,  # type: ignore[arg-type]
                dome_ratio=spec.dome_ratio,  # type: ignore[arg-type]
                name=job.name,
            )
        if isinstance(spec, ConeSpec):
            return Mandrel.cone(spec.r0_mm, spec.r1_mm, spec.length_mm, name=job.name)
        if isinstance(spec, PipeSpec):
            return Mandrel.pipe(spec.radius_mm, spec.length_mm, name=job.name)
        if isinstance(spec, BottleSpec):
            return Mandrel.bottle(
                radius=spec.radius_mm,
                body_length=spec.body_length_mm,
                shoulder_length=spec.shoulder_length_mm,
                waist_radius=spec.waist_radius_mm,
                neck_length=spec.neck_length_mm,
                neck_radius=spec.neck_radius_mm,
                bottom_pole_radius=spec.bottom_pole_radius_mm,
                name=job.name,
            )
        if isinstance(spec, PointsSpec):
            from engine.budget import check_sketch_points

            check_sketch_points(len(spec.z_mm))
            return Mandrel.from_points(spec.z_mm, spec.r_mm, name=job.name, source="points")
        if isinstance(spec, SegmentsSpec):
            from engine.sketch import build_sketch

            return build_sketch(spec.start_mm, [sg.model_dump(exclude_none=True) for sg in spec.segments],
                                name=job.name)
        if isinstance(spec, FileSpec):
            from engine.mandrel_io import load_mandrel_file

            base = Path(job_path).parent if job_path else Path(".")
            return load_mandrel_file(base / spec.path, smoothing_mm=spec.smoothing_mm)
    except InputError as exc:
        if exc.location.file:  # a problem inside an imported profile file: keep its own location
            raise
        f = exc.location.field
        loc = ("mandrel", _spec_field(f)) if f else ("mandrel",)
        line = None
        if job_path is not None and Path(job_path).is_file():
            text = Path(job_path).read_text(encoding="utf-8", errors="replace")
            m = re.match(r"segments\[(\d+)\]\.(\w+)$", f or "")
            line = _segment_line(text, int(m.group(1)), m.group(2)) if m else _find_line(text, loc)
        raise InputError(exc.message, file=job_path, line=line, field=".".join(loc)) from None
    raise InputError(f"unknown mandrel kind {spec!r}", file=job_path, field="mandrel.kind")


def _spec_field(engine_name: str) -> str:
    mapping = {
        "radius": "radius_mm",
        "length": "length_mm",
        "cylinder_length": "cylinder_length_mm",
        "pole_radius_mm": "pole_radius_mm",
        "dome_ratio": "dome_ratio",
        "r0": "r0_mm",
        "r1": "r1_mm",
        "z": "z_mm",
        "r": "r_mm",
    }
    return mapping.get(engine_name, engine_name)


def default_job(name: str = "untitled") -> Job:
    """A new job: a small vessel with hemispherical domes."""
    return Job(name=name, mandrel=VesselSpec(radius_mm=100.0, cylinder_length_mm=300.0, pole_radius_mm=30.0))
