"""The job report (engine.report, ``winder report``): PDF and HTML with every figure for every example;
its numbers are the run's report."""

from __future__ import annotations

import html
import re
from pathlib import Path

import pytest

from engine.cli import main as cli_main
from engine.job import load_job
from engine.pipeline import run_pipeline
from engine.report import report_figures, report_sections, write_report

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ("pipe", "bottle", "pressure_vessel")


@pytest.fixture(scope="module", params=EXAMPLES)
def run(request):
    path = ROOT / "resources/examples" / f"{request.param}.toml"
    return path, run_pipeline(load_job(path), path)


def test_report_has_every_figure_and_the_runs_numbers(run, tmp_path) -> None:
    path, res = run
    rep = res.report()
    figs = report_figures(res)
    titles = [t for t, _f in figs]
    n_axis_pages = -(-len(res.machine.axes) // 4)
    assert titles[:3] == ["Mandrel drawing", "Winding angle, Clairaut function, slip tendency", "Eye path"]
    assert sum(t.startswith("Axes ") for t in titles) == n_axis_pages and titles[-1] == "Coverage map"
    # every axis is drawn once, with its limits
    drawn = [a for t in titles if t.startswith("Axes ") for a in t.removeprefix("Axes ").split(", ")]
    assert drawn == [a.name for a in res.machine.axes]
    html_path = write_report(res, tmp_path / "r.html", path)
    text = html_path.read_text("utf-8")
    assert text.count("<svg") == len(figs)
    # the numbers are those of the run's report (the same formatting as the sections)
    assert f"{rep['program_time_s']:.2f} s" in text
    assert f"{rep['fibre_length_mm'] / 1000.0:.3f} m" in text
    assert f"<td>{rep['blocks']}</td>" in text
    for ax in res.machine.axes:
        lo, hi = rep["axis_ranges"][ax.name]
        assert f"<td>{lo:.6g}</td><td>{hi:.6g}</td>" in text
    for w in rep["warnings"]:
        assert html.escape(w) in text
    pdf = write_report(res, tmp_path / "r.pdf", path)
    data = pdf.read_bytes()
    assert data[:5] == b"%PDF-" and data.rstrip().endswith(b"%%EOF")
    assert len(re.findall(rb"/Type\s*/Page\b", data)) >= len(figs) + 1  # the tables, then one page per figure
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.html", "r.pdf"]  # nothing half written
    sections = {s.title for s in report_sections(res, path)}
    assert {"Job", "Mandrel", "Layers", "Winding", "Warnings and limit violations"} <= sections


def test_cli_report_writes_pdf_and_refuses_other_suffixes(tmp_path, capsys) -> None:
    job = ROOT / "resources/examples/pipe.toml"
    out = tmp_path / "pipe.pdf"
    assert cli_main(["report", str(job), "-o", str(out), "--quiet"]) == 0
    assert out.read_bytes()[:5] == b"%PDF-"
    bad = tmp_path / "pipe.doc"
    assert cli_main(["report", str(job), "-o", str(bad), "--quiet"]) == 2
    assert not bad.exists()
    assert ".pdf or .html" in capsys.readouterr().err
