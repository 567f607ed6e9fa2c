"""The job report of a layered job (:class:`engine.laminate.LaminateResult`): the layup table and every layer's
figures beside the joined program's.

Its numbers are those of :meth:`engine.laminate.LaminateResult.report` (program time, blocks, fibre length,
axis ranges, warnings) and of its layup table (:meth:`~engine.laminate.LaminateResult.layup`: each layer's
angle, circuits, coverage, thickness, time, fibre length and mass, and the totals).  The figures: the bare
mandrel, the laminate's cross-section (every layer's outer boundary), winding angle and added thickness of
each layer along z, then for each wound layer its winding line, eye path and coverage map on the surface it
was wound on, then the joined program's axes.  Drawn with matplotlib's object API (no GUI toolkit).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from engine.report import (
    Section,
    axes_figures,
    axes_section,
    coverage_figure,
    eye_figure,
    mandrel_figure,
    warnings_section,
    winding_figure,
)

LAYER_COLOURS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b", "#e377c2", "#17becf",
                 "#bcbd22", "#7f7f7f")


def _layer_label(lr: Any) -> str:
    return f"Layer {lr.index + 1} ({lr.name})"


def laminate_sections(result: Any, job_path: str | Path | None = None) -> list[Section]:
    """The report's tables of a laminate ``result`` (numbers as in ``result.report()`` and its layup)."""
    rep = result.report()
    total = rep["total"]
    job = result.job
    summary = [["item", "value"],
               ["job", str(job.name)],
               ["file", str(job_path) if job_path is not None else "(not saved)"],
               ["machine", str(rep.get("machine", ""))],
               ["post-processor", str(rep.get("post", ""))],
               ["layers wound", str(total["layers"])]]
    if "program_time_s" in rep:
        t = float(rep["program_time_s"])
        summary.append(["program time", f"{t:.2f} s ({t / 60.0:.2f} min)"])
        summary.append(["  of which layers / transitions",
                        f"{total['time_s']:.2f} s / {total['transition_time_s']:.2f} s"])
    if "blocks" in rep:
        summary.append(["NC blocks", str(rep["blocks"])])
    summary.append(["fibre (band) length", f"{rep['fibre_length_mm'] / 1000.0:.3f} m"])
    summary.append(["band volume laid", f"{rep['volume_laid_mm3'] / 1000.0:.1f} cm³"])
    summary.append(["fibre mass / resin mass", f"{total['fibre_mass_kg']:.3f} kg / {total['resin_mass_kg']:.3f} kg"])
    summary.append(["thickness on the cylinder / largest", f"{total['thickness_cyl_mm']:.3f} mm / "
                                                           f"{total['thickness_max_mm']:.3f} mm"])
    summary.append(["polar openings after winding",
                    " / ".join(f"{float(r):.2f} mm" for r in total["final_pole_radii_mm"])])
    summary.append(["volume check (between surfaces / laid − 1)", f"{100 * float(rep['volume_error']):.2f} %"])
    out = [Section("Job", summary)]
    m = result.mandrel
    if m is not None:
        out.append(Section("Mandrel", [["kind", "length", "radius", "pole openings"],
                                       [str(job.mandrel.kind), f"{m.length:.2f} mm",
                                        f"{m.r_min:.2f} … {m.r_max:.2f} mm",
                                        f"{m.pole_radii[0]:.2f} / {m.pole_radii[1]:.2f} mm"]]))
    rows = [["#", "name", "kind", "β cyl [deg]", "circuits", "passes", "coverage", "t cyl [mm]", "t max [mm]",
             "time [s]", "fibre [m]", "fibre [kg]", "resin [kg]", "material"]]
    for r in rep["layers"]:
        ang = r.get("angle_deg_cylinder")
        rows.append([str(r["index"]), str(r["name"]), str(r["kind"]),
                     f"{float(ang):.2f}" if ang is not None else "–", str(r.get("circuits", 0)),
                     str(r.get("passes", 0)), f"{100 * float(r.get('coverage', 0.0)):.0f} %",
                     f"{float(r['thickness_cyl_mm']):.3f}", f"{float(r['thickness_max_mm']):.3f}",
                     f"{float(r['time_s']):.2f}", f"{float(r['fibre_length_m']):.3f}",
                     f"{float(r['fibre_mass_kg']):.4f}", f"{float(r['resin_mass_kg']):.4f}",
                     str(r.get("material", "–"))])
    rows.append(["total", "", "", "", "", "", "", f"{total['thickness_cyl_mm']:.3f}",
                 f"{total['thickness_max_mm']:.3f}", f"{total['time_s']:.2f}",
                 f"{rep['fibre_length_mm'] / 1000.0:.3f}", f"{total['fibre_mass_kg']:.4f}",
                 f"{total['resin_mass_kg']:.4f}", ""])
    out.append(Section("Layup", rows))
    defs = [["#", "kind", "name", "settings"]]
    for i, lay in enumerate(job.layers, 1):
        d = lay.model_dump(mode="json", exclude_none=True, exclude_defaults=True)
        kind = str(d.pop("kind", getattr(lay, "kind", "")))
        name = str(d.pop("name", ""))
        defs.append([str(i), kind, name, ", ".join(f"{k} = {v}" for k, v in d.items()) or "defaults"])
    out.append(Section("Layers (as defined in the job)", defs))
    if result.machine is not None:
        out.append(axes_section(result.machine, rep))
    out.append(warnings_section(rep))
    return out


def laminate_figure(result: Any) -> Any:
    """Build-up (every layer's outer boundary as its height above the bare mandrel at the same z), each
    layer's winding angle on its first pass and the thickness it adds, along z (mm)."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(7.5, 7.0), layout="constrained")
    axs = fig.subplots(3, 1, sharex=True)
    m = result.mandrel
    z = np.linspace(m.z_min, m.z_max, 800)
    bare = m.r(z)
    inner = np.zeros_like(z)  # heights above the mandrel: the layers are thin beside the radius
    axs[0].plot(z, inner, color="#333", lw=1.2, label="mandrel")
    for k, lr in enumerate(result.layers):
        th = lr.thickness
        colour = LAYER_COLOURS[k % len(LAYER_COLOURS)]
        label = f"{lr.index + 1} {lr.name}"
        if th is None:
            continue
        order = np.argsort(th.z_out)
        outer = np.interp(z, th.z_out[order], th.r_out[order]) - bare
        axs[0].fill_between(z, inner, np.maximum(outer, inner), color=colour, alpha=0.35, lw=0)
        axs[0].plot(z, outer, color=colour, lw=0.9, label=label)
        inner = np.maximum(outer, inner)
        axs[2].plot(th.z, th.t, color=colour, lw=1.0, label=label)
        res = lr.result
        if res is not None and res.line is not None:
            line = res.line
            sel = (line.pass_id == line.pass_id[0]) & ~line.dwell
            if int(sel.sum()) >= 2:
                axs[1].plot(line.z[sel], np.degrees(line.beta[sel]), color=colour, lw=1.0, label=label)
    axs[0].set_ylabel("r − r mandrel [mm]")
    axs[0].set_title("Build-up: each layer's outer boundary above the mandrel")
    handles, labels = axs[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside upper center", fontsize=7, ncol=min(len(labels), 6))
    axs[1].set_ylabel("β [deg]")
    axs[1].set_title("Winding angle (first pass)")
    axs[2].set_ylabel("t [mm]")
    axs[2].set_title("Thickness added by each layer")
    axs[2].set_xlabel("z [mm]")
    for a in axs:
        a.grid(alpha=0.3)
        a.ticklabel_format(useOffset=False)
    return fig


def laminate_figures(result: Any) -> list[tuple[str, Any]]:
    """Every plot of a laminate run as (title, matplotlib Figure)."""
    figs: list[tuple[str, Any]] = []
    if result.mandrel is not None:
        figs.append(("Mandrel drawing", mandrel_figure(result.mandrel)))
        if result.layers:
            figs.append(("Laminate: layer boundaries, winding angle, thickness", laminate_figure(result)))
    for lr in result.layers:
        res = lr.result
        if res is None or res.line is None:
            continue  # a skip layer: no fibre
        lab = _layer_label(lr)
        figs.append((f"{lab}: winding line",
                     winding_figure(res.line, f"{lab}: winding line (first circuit); dashed: ±μ")))
        if res.eye_circuit is not None:
            figs.append((f"{lab}: eye path", eye_figure(res.eye_circuit, lr.surface,
                                                        f"{lab}: payout eye path (one circuit)")))
        figs.append((f"{lab}: coverage map", coverage_figure(res.line, lr.surface, f"{lab}: coverage")))
    if result.blocks is not None and result.machine is not None:
        figs += axes_figures(result.blocks, result.machine)
    return figs

