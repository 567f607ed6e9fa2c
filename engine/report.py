"""The job report: the sheet that goes to the shop floor with the NC file (PDF or HTML).

:func:`report_sections` gathers the numbers of a pipeline run — exactly the values of
:meth:`engine.pipeline.PipelineResult.report` (program time, fibre length, blocks, axis ranges,
warnings) plus the job, the mandrel, the layer table, the machine's axes and limits — and
:func:`report_figures` draws every plot (mandrel r(z), winding angle/Clairaut/λ, eye path, each
axis's position and speed over the program time, the coverage map) with matplotlib's object API
(no pyplot state, no GUI toolkit).  :func:`write_report` writes a PDF (matplotlib's PDF backend) or an
HTML page with the figures as inline SVG, atomically.  ``winder report JOB.toml -o R.pdf`` runs the
pipeline and writes it; the GUI's File -> Export report does the same for the run on screen.
"""

from __future__ import annotations

import html
import io
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from engine.errors import InputError
from engine.fileio import atomic_write_text, atomic_write_with

REPORT_SUFFIXES = (".pdf", ".html", ".htm")
A4_IN = (8.27, 11.69)


@dataclass
class Section:
    """A titled table (``rows`` of cells, the first row the header) or list of lines."""

    title: str
    rows: list[list[str]] = field(default_factory=list)
    lines: list[str] = field(default_factory=list)


def _fmt(v: Any, digits: int = 6) -> str:
    if isinstance(v, float):
        if not math.isfinite(v):
            return str(v)
        if abs(v) >= 1e11:
            return "unlimited"
        return f"{v:.{digits}g}"
    return str(v)


def is_laminate_result(result: Any) -> bool:
    """True for an :class:`engine.laminate.LaminateResult` (a layered job), False for a single-line result."""
    return hasattr(result, "layers") and hasattr(result, "layup")


def report_sections(result: Any, job_path: str | Path | None = None) -> list[Section]:
    """The report's tables from a pipeline or laminate ``result`` (numbers as in ``result.report()``)."""
    if is_laminate_result(result):
        from engine.report_laminate import laminate_sections

        return laminate_sections(result, job_path)
    rep = result.report()
    job = result.job
    out: list[Section] = []
    summary = [["item", "value"],
               ["job", str(job.name)],
               ["file", str(job_path) if job_path is not None else "(not saved)"],
               ["machine", str(rep.get("machine", ""))],
               ["post-processor", str(rep.get("post", ""))]]
    if "program_time_s" in rep:
        t = float(rep["program_time_s"])
        summary.append(["program time", f"{t:.2f} s ({t / 60.0:.2f} min)"])
    if "blocks" in rep:
        summary.append(["NC blocks", str(rep["blocks"])])
    if "fibre_length_mm" in rep:
        length = float(rep["fibre_length_mm"])
        b = job.band
        vol = length * b.width_mm * b.thickness_mm
        summary.append(["fibre (band) length", f"{length / 1000.0:.3f} m"])
        summary.append(["band volume laid", f"{vol / 1000.0:.1f} cm³ (width {b.width_mm:g} mm × thickness "
                                            f"{b.thickness_mm:g} mm)"])
        density = getattr(b, "density_g_cm3", None)
        summary.append(["fibre mass", f"{vol / 1000.0 * float(density):.1f} g" if density
                        else "not computed: the job gives no material density"])
        summary.append(["material", str(b.material)])
    if "max_error_mm" in rep:
        summary.append(["largest interpolation error", f"{float(rep['max_error_mm']):.3g} mm"])
    out.append(Section("Job", summary))

    m = result.mandrel
    if m is not None:
        out.append(Section("Mandrel", [["kind", "length", "radius", "pole openings"],
                                       [str(job.mandrel.kind), f"{m.length:.2f} mm",
                                        f"{m.r_min:.2f} … {m.r_max:.2f} mm",
                                        f"{m.pole_radii[0]:.2f} / {m.pole_radii[1]:.2f} mm"]]))
    layers = list(getattr(job, "layers", None) or [])
    if layers:
        rows = [["#", "kind", "name", "settings"]]
        for i, lay in enumerate(layers, 1):
            d = lay.model_dump(mode="json", exclude_none=True, exclude_defaults=True)
            kind = str(d.pop("kind", getattr(lay, "kind", "")))
            name = str(d.pop("name", ""))
            rows.append([str(i), kind, name, ", ".join(f"{k} = {v}" for k, v in d.items()) or "defaults"])
        out.append(Section("Layers", rows))
    else:
        w = job.winding
        out.append(Section("Layers", [["#", "kind", "settings"],
                                      ["1", "helical",
                                       f"line {w.mode}, {w.layers} layer(s), dwell {w.dwell_deg} deg"]]))
    line = result.line
    if line is not None:
        out.append(Section("Winding", [["line", "circuits", "pattern", "max |λ|", "μ"],
                                       [str(line.mode), str(line.circuits), f"{line.pattern_p}/{line.pattern_q}",
                                        f"{line.max_abs_lambda:.3g}", f"{line.mu:g}"]]))
    mach = result.machine
    if mach is not None:
        out.append(axes_section(mach, rep))
    out.append(warnings_section(rep))
    return out


def axes_section(mach: Any, rep: dict[str, Any]) -> Section:
    """The machine's axes, their limits and the range the program uses (``rep``: the run's report)."""
    ranges = rep.get("axis_ranges", {})
    sp, ac, jp = rep.get("max_speed_ratio"), rep.get("max_accel_ratio"), rep.get("max_jump_ratio")
    head = ["axis", "units", "min", "max", "used from", "used to", "max speed"]
    if sp is not None:
        # accel used: what the speed steps beyond max_jump need of max_accel (0 % when every step is within
        # the jump a block boundary may take at once)
        head += ["speed used", "jump used", "accel used"]
    rows = [head]
    for ax in mach.axes:
        lo, hi = ranges.get(ax.name, (float("nan"), float("nan")))
        row = [ax.name, ax.units, _fmt(float(ax.min)), _fmt(float(ax.max)), _fmt(float(lo)), _fmt(float(hi)),
               _fmt(float(ax.max_speed))]
        if sp is not None:
            row += [f"{100 * float(sp.get(ax.name, float('nan'))):.0f} %",
                    f"{100 * float((jp or {}).get(ax.name, float('nan'))):.0f} %",
                    f"{100 * float((ac or {}).get(ax.name, float('nan'))):.0f} %"]
        rows.append(row)
    return Section(f"Machine {mach.name}: axes and limits", rows)


def _violation_text(v: Any) -> str:
    if not isinstance(v, dict):
        return str(v)
    where = f" at {v['places']} place(s)" if "places" in v else ""
    first = f", first at NC line {v['nc_line']}" if v.get("nc_line") is not None else ""
    return (f"{v.get('axis', '')} {v.get('what', v.get('kind', ''))}: {_fmt(v.get('value'))} against the limit "
            f"{_fmt(v.get('limit'))}{where}{first}").strip()


def warnings_section(rep: dict[str, Any]) -> Section:
    """The run's warnings and grouped limit violations, as the run's report lists them."""
    warns = list(rep.get("warnings", []))
    viol = list(rep.get("violations", []))
    return Section("Warnings and limit violations",
                   lines=[*(f"violation: {_violation_text(v)}" for v in viol), *(f"warning: {w}" for w in warns)]
                   or ["none"])


def report_figures(result: Any) -> list[tuple[str, Any]]:
    """Every plot of the run as (title, matplotlib Figure), drawn from the engine's arrays (a layered job:
    :func:`engine.report_laminate.laminate_figures`)."""
    if is_laminate_result(result):
        from engine.report_laminate import laminate_figures

        return laminate_figures(result)
    figs: list[tuple[str, Any]] = []
    m = result.mandrel
    if m is not None:
        figs.append(("Mandrel drawing", mandrel_figure(m)))
    line = result.line
    if line is not None:
        figs.append(("Winding angle, Clairaut function, slip tendency", winding_figure(line)))
    eye = result.eye_circuit
    if eye is not None and m is not None:
        figs.append(("Eye path", eye_figure(eye, m)))
    if result.blocks is not None and result.machine is not None:
        figs += axes_figures(result.blocks, result.machine)
    if line is not None:
        figs.append(("Coverage map", coverage_figure(line, m)))
    return figs


def mandrel_figure(m: Any, title: str = "") -> Any:
    """The mandrel's drawing: its section through the axis (mm)."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(7.5, 2.6), layout="constrained")
    ax = fig.add_subplot()
    z = np.linspace(m.z_min, m.z_max, 600)
    r = m.r(z)
    ax.fill_between(z, -r, r, color="#c9d3e3")
    ax.plot(z, r, color="#333")
    ax.plot(z, -r, color="#333")
    ax.axhline(0.0, color="#888", lw=0.8, ls="-.")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("z [mm]")
    ax.set_ylabel("r [mm]")
    ax.set_title(title or f"Mandrel: L {m.length:.1f} mm, r {m.r_min:.1f}…{m.r_max:.1f} mm")
    return fig


def winding_figure(line: Any, title: str = "Winding line (first circuit); dashed: ±μ") -> Any:
    """Winding angle β, Clairaut function C and slip tendency λ along z on the first circuit."""
    from matplotlib.figure import Figure

    sl = line.circuit_slice(0)
    fig = Figure(figsize=(7.5, 6.0), layout="constrained")
    axs = fig.subplots(3, 1, sharex=True)
    zz = line.z[sl]
    axs[0].plot(zz, np.degrees(line.beta[sl]), color="#1f77b4")
    axs[0].set_ylabel("β [deg]")
    axs[1].plot(zz, line.C[sl], color="#2ca02c")
    axs[1].set_ylabel("C = r·sin β [mm]")
    axs[2].plot(zz, line.lam[sl], color="#d62728")
    for s in (1.0, -1.0):
        axs[2].axhline(s * line.mu, color="#888", ls="--", lw=0.8)
    axs[2].set_ylabel("λ [–]")
    axs[2].set_xlabel("z [mm]")
    for a in axs:
        a.grid(alpha=0.3)
        a.ticklabel_format(useOffset=False)
    fig.suptitle(title)
    return fig


def eye_figure(eye: Any, m: Any, title: str = "Payout eye path (one circuit)") -> Any:
    """The payout eye's path Z-R over one circuit beside the surface r(z)."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(7.5, 3.2), layout="constrained")
    ax = fig.add_subplot()
    z = np.linspace(m.z_min, m.z_max, 400)
    ax.plot(z, m.r(z), color="#555", lw=2, label="mandrel r(z)")
    ax.plot(eye.Z, eye.R, color="#d62728", lw=1.5, label=f"eye ({eye.law})")
    ax.set_xlabel("Z, z [mm]")
    ax.set_ylabel("R, r [mm]")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    ax.set_title(title)
    return fig


def axes_figures(blocks: Any, mach: Any, per_page: int = 4) -> list[tuple[str, Any]]:
    """Each axis's position and speed over the program time (``per_page`` axes a figure), limits dashed."""
    from matplotlib.figure import Figure

    figs: list[tuple[str, Any]] = []
    t = np.concatenate([[0.0], np.cumsum(blocks.time)])
    n = len(mach.axes)
    for start in range(0, n, per_page):
        axes = mach.axes[start:start + per_page]
        fig = Figure(figsize=(7.5, 2.3 * len(axes) + 0.6), layout="constrained")
        grid = fig.subplots(len(axes), 2, squeeze=False, sharex=True)
        for row, axspec in enumerate(axes):
            k = start + row
            q = blocks.q[:, k]
            v = blocks.delta[:, k] / blocks.time
            grid[row, 0].plot(t, q, lw=0.8)
            grid[row, 0].set_ylabel(f"{axspec.name} [{axspec.units}]")
            grid[row, 1].step(t[:-1], v, where="post", lw=0.6)
            grid[row, 1].set_ylabel(f"{axspec.name}' [{axspec.units}/s]")
            for lim in (axspec.min, axspec.max):
                if math.isfinite(lim) and abs(lim) < 1e11:
                    grid[row, 0].axhline(lim, color="#c01010", ls="--", lw=0.8)
            for lim in (-axspec.max_speed, axspec.max_speed):
                grid[row, 1].axhline(lim, color="#c01010", ls="--", lw=0.8)
            for a in grid[row]:
                a.grid(alpha=0.3)
                a.ticklabel_format(useOffset=False, axis="y")
        for a in grid[-1]:
            a.set_xlabel("t [s]")
        fig.suptitle(f"Axes: position and speed over the program ({blocks.total:.1f} s); dashed red: limits")
        figs.append((f"Axes {', '.join(a.name for a in axes)}", fig))
    return figs


def coverage_figure(line: Any, m: Any, title: str = "Coverage") -> Any:
    """The unwrapped coverage map (bands per point: gaps red) with its covered and overlapped shares."""
    from matplotlib.colors import ListedColormap
    from matplotlib.figure import Figure

    from engine.coverage import coverage_map

    cov = coverage_map(line, m)
    fig = Figure(figsize=(7.5, 3.4), layout="constrained")
    ax = fig.add_subplot()
    cmap = ListedColormap(["#d62728", "#9ecae1", "#74c476", "#238b45", "#005a32"])
    im = ax.imshow(np.minimum(cov.count, 4).T, origin="lower", aspect="auto", cmap=cmap, vmin=-0.5, vmax=4.5,
                   extent=(cov.z_edges[0], cov.z_edges[-1], 0.0, 360.0), interpolation="nearest")
    bar = fig.colorbar(im, ax=ax, ticks=[0, 1, 2, 3, 4])
    bar.ax.set_yticklabels(["gap", "1", "2", "3", "4+"])
    bar.set_label("bands over a point")
    ax.set_xlabel("meridian length m [mm]" if cov.meridian else "z [mm]")
    ax.set_ylabel("v [deg]")
    ax.set_title(f"{title}: {100 * cov.covered_fraction:.1f} % covered, {100 * cov.overlap_fraction:.1f} % "
                 f"overlapped (band {cov.band_width_mm:g} mm)")
    return fig


def write_report(result: Any, path: str | Path, job_path: str | Path | None = None) -> Path:
    """Write the report of ``result`` to ``path`` (.pdf or .html), atomically; returns the path."""
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix not in REPORT_SUFFIXES:
        raise InputError(f"a report is written as .pdf or .html, not {suffix or 'a file without suffix'!r}",
                         file=p)
    sections = report_sections(result, job_path)
    figures = report_figures(result)
    if suffix == ".pdf":
        return atomic_write_with(p, lambda tmp: _write_pdf(tmp, sections, figures, result), suffix=".pdf")
    return atomic_write_text(p, report_html(sections, figures, result))


def _write_pdf(path: str, sections: list[Section], figures: list[tuple[str, Any]], result: Any) -> None:
    from matplotlib.backends.backend_pdf import PdfPages
    from matplotlib.figure import Figure

    with PdfPages(path, metadata={"Title": f"winder job report: {result.job.name}", "Creator": "winder"}) as pdf:
        # the tables, as monospaced text, as many A4 pages as they need
        lines: list[tuple[str, bool]] = [(f"Job report: {result.job.name}", True), ("", False)]
        for sec in sections:
            lines.append((sec.title, True))
            if sec.rows:
                widths = [max(len(r[j]) if j < len(r) else 0 for r in sec.rows) for j in range(len(sec.rows[0]))]
                for r in sec.rows:
                    cells = [c.ljust(widths[j]) for j, c in enumerate(r[: len(widths)])]
                    text = "  ".join(cells)
                    lines += [(text[i:i + 110], False) for i in range(0, max(len(text), 1), 110)]
            for ln in sec.lines:
                lines += [(ln[i:i + 110], False) for i in range(0, max(len(ln), 1), 110)]
            lines.append(("", False))
        per_page = 70
        for start in range(0, len(lines), per_page):
            fig = Figure(figsize=A4_IN)
            y = 0.97
            for text, bold in lines[start:start + per_page]:
                fig.text(0.05, y, text, family="monospace", fontsize=7.2, weight="bold" if bold else "normal",
                         va="top")
                y -= 0.0135
            pdf.savefig(fig)
        for _title, fig in figures:
            pdf.savefig(fig)


def report_html(sections: list[Section], figures: list[tuple[str, Any]], result: Any) -> str:
    """The report as one self-contained HTML page (figures inline as SVG)."""
    e = html.escape
    parts = ["<!DOCTYPE html><html><head><meta charset='utf-8'>",
             f"<title>winder job report: {e(str(result.job.name))}</title>",
             "<style>body{font-family:sans-serif;max-width:60em;margin:2em auto}"
             "table{border-collapse:collapse;margin:.5em 0}td,th{border:1px solid #bbb;padding:2px 8px;"
             "text-align:left;font-size:90%}th{background:#eef}figure{margin:1em 0}</style></head><body>",
             f"<h1>Job report: {e(str(result.job.name))}</h1>"]
    for sec in sections:
        parts.append(f"<h2>{e(sec.title)}</h2>")
        if sec.rows:
            parts.append("<table>")
            parts.append("<tr>" + "".join(f"<th>{e(c)}</th>" for c in sec.rows[0]) + "</tr>")
            for r in sec.rows[1:]:
                parts.append("<tr>" + "".join(f"<td>{e(c)}</td>" for c in r) + "</tr>")
            parts.append("</table>")
        if sec.lines:
            parts.append("<ul>" + "".join(f"<li>{e(x)}</li>" for x in sec.lines) + "</ul>")
    for title, fig in figures:
        buf = io.StringIO()
        fig.savefig(buf, format="svg")
        svg = buf.getvalue()
        svg = svg[svg.find("<svg"):]
        parts.append(f"<figure><figcaption><b>{e(title)}</b></figcaption>{svg}</figure>")
    parts.append("</body></html>")
    return "\n".join(parts)
