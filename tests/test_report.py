"""The job report (engine.report, ``winder report``): PDF and HTML with every figure for every example (a
layered example: its layup table and every layer's figures); its numbers are the run's report."""

from __future__ import annotations

import html
import re
import shutil
from pathlib import Path

import pytest

from engine.cli import main as cli_main
from engine.job import load_job
from engine.laminate import run_laminate
from engine.pipeline import run_pipeline
from engine.report import report_figures, report_sections, write_report

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ("pipe", "bottle", "pressure_vessel")


def _run(path: Path):
    job = load_job(path)
    return run_pipeline(job, path) if job.is_single_line else run_laminate(job, path)


@pytest.fixture(scope="module", params=EXAMPLES)
def run(request):
    path = ROOT / "resources/examples" / f"{request.param}.toml"
    return path, _run(path)


def _pdf_pages(data: bytes) -> int:
    assert data[:5] == b"%PDF-" and data.rstrip().endswith(b"%%EOF")
    return len(re.findall(rb"/Type\s*/Page\b", data))


def test_laminate_report_has_the_layup_every_layers_figures_and_the_runs_numbers(run, tmp_path) -> None:
    path, res = run
    assert not res.job.is_single_line  # every example is a laminate
    rep = res.report()
    figs = report_figures(res)
    titles = [t for t, _f in figs]
    assert titles[:2] == ["Mandrel drawing", "Laminate: layer boundaries, winding angle, thickness"]
    wound = [lr for lr in res.layers if lr.result is not None and lr.result.line is not None]
    assert wound
    for lr in wound:  # each wound layer: its line, eye path (when it has one) and coverage map
        lab = f"Layer {lr.index + 1} ({lr.name})"
        assert f"{lab}: winding line" in titles and f"{lab}: coverage map" in titles
        assert (f"{lab}: eye path" in titles) == (lr.result.eye_circuit is not None)
    n_axis_pages = -(-len(res.machine.axes) // 4)
    assert sum(t.startswith("Axes ") for t in titles) == n_axis_pages and titles[-1].startswith("Axes ")
    drawn = [a for t in titles if t.startswith("Axes ") for a in t.removeprefix("Axes ").split(", ")]
    assert drawn == [a.name for a in res.machine.axes]
    for _t, f in figs:  # every figure has drawn something
        assert f.axes and any(a.lines or a.collections or a.images for a in f.axes)
    text = write_report(res, tmp_path / "r.html", path).read_text("utf-8")
    assert text.count("<svg") == len(figs)
    # the numbers of the run's report and of its layup table
    assert f"{rep['program_time_s']:.2f} s" in text
    assert f"{rep['fibre_length_mm'] / 1000.0:.3f} m" in text
    assert f"<td>{rep['blocks']}</td>" in text
    for row in rep["layers"]:
        assert f"<td>{row['name']}</td>" in text
        assert f"<td>{float(row['time_s']):.2f}</td>" in text
        assert f"<td>{float(row['fibre_length_m']):.3f}</td>" in text
        assert f"<td>{float(row['fibre_mass_kg']):.4f}</td>" in text
    assert f"<td>{rep['total']['time_s']:.2f}</td>" in text
    assert f"{rep['total']['fibre_mass_kg']:.3f} kg" in text
    for name, (lo, hi) in rep["axis_ranges"].items():
        assert f"<td>{name}</td>" in text and f"<td>{lo:.6g}</td><td>{hi:.6g}</td>" in text
    for w in rep["warnings"]:
        assert html.escape(w) in text
    data = write_report(res, tmp_path / "r.pdf", path).read_bytes()
    assert _pdf_pages(data) >= len(figs) + 1  # the tables, then one page per figure
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.html", "r.pdf"]  # nothing half written
    sections = {s.title for s in report_sections(res, path)}
    assert {"Job", "Mandrel", "Layup", "Layers (as defined in the job)", "Warnings and limit violations"} <= sections


def test_single_line_report_has_every_figure_and_the_runs_numbers(tmp_path) -> None:
    from engine.job import build_mandrel, effective_band, effective_winding, save_job

    src = ROOT / "resources/examples/pipe.toml"
    job = load_job(src)  # its helical layer as the job's single line
    lay = next(x for _, x in job.active_layers if x.kind == "helical")
    job = job.replace(winding=effective_winding(job, lay, build_mandrel(job, src)).model_dump(),
                      band=effective_band(job, lay).model_dump(), layers=[{"kind": "helical"}])
    path = tmp_path / "job" / "pipe.toml"
    path.parent.mkdir()
    save_job(job, path)
    res = _run(path)
    assert res.job.is_single_line
    rep = res.report()
    figs = report_figures(res)
    titles = [t for t, _f in figs]
    assert titles[:3] == ["Mandrel drawing", "Winding angle, Clairaut function, slip tendency", "Eye path"]
    assert titles[-1] == "Coverage map"
    drawn = [a for t in titles if t.startswith("Axes ") for a in t.removeprefix("Axes ").split(", ")]
    assert drawn == [a.name for a in res.machine.axes]
    text = write_report(res, tmp_path / "r.html", path).read_text("utf-8")
    assert text.count("<svg") == len(figs)
    assert f"{rep['program_time_s']:.2f} s" in text
    assert f"{rep['fibre_length_mm'] / 1000.0:.3f} m" in text
    assert f"<td>{rep['blocks']}</td>" in text
    for ax in res.machine.axes:
        lo, hi = rep["axis_ranges"][ax.name]
        assert f"<td>{lo:.6g}</td><td>{hi:.6g}</td>" in text
    for w in rep["warnings"]:
        assert html.escape(w) in text
    assert "{'kind'" not in text  # violations are sentences, not dicts
    assert _pdf_pages(write_report(res, tmp_path / "r.pdf", path).read_bytes()) >= len(figs) + 1


def test_cli_report_writes_the_laminates_pdf_and_refuses_other_suffixes(tmp_path, capsys) -> None:
    job = tmp_path / "pipe.toml"
    shutil.copy(ROOT / "resources/examples/pipe.toml", job)
    out = tmp_path / "pipe.html"
    assert cli_main(["report", str(job), "-o", str(out), "--quiet"]) == 0
    text = out.read_text("utf-8")
    assert "<h2>Layup</h2>" in text and "Layer 2 (helical 55): coverage map" in text
    assert cli_main(["report", str(job), "-o", str(tmp_path / "pipe.pdf"), "--quiet"]) == 0
    assert (tmp_path / "pipe.pdf").read_bytes()[:5] == b"%PDF-"
    bad = tmp_path / "pipe.doc"
    assert cli_main(["report", str(job), "-o", str(bad), "--quiet"]) == 2
    assert not bad.exists()
    assert ".pdf or .html" in capsys.readouterr().err
