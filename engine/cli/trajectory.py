"""``winder trajectory JOB.toml``: the winding line of a job (MATH.md §A2).

Prints a summary (``--json`` for the full JSON report) and optionally writes the per-point table
(``--csv OUT.csv``: z, r, v, beta, C, lambda, x, y, zz; mm and rad).  Exit code 1 when the band
slips (|λ| > μ) or bridges somewhere; the report says where.
"""

from __future__ import annotations

import argparse
import io
import math
from typing import Any

import numpy as np

NAME = "trajectory"
HELP = "compute the winding line (Clairaut function, twist, circuits, pattern) of a job"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("job", help="job file (.toml)")
    parser.add_argument("--json", action="store_true", help="print the report as JSON")
    parser.add_argument("--csv", metavar="OUT.csv", help="write the points: z, r, v, beta, C, lambda, x, y, zz")
    parser.add_argument("--one-circuit", action="store_true", help="write only the first circuit to the CSV")


def csv_text(line: Any) -> str:
    """The per-point table as CSV text (header + one row a point)."""
    cols = np.column_stack([line.z, line.r, line.v, line.beta, line.C, line.lam,
                            line.xyz[:, 0], line.xyz[:, 1], line.xyz[:, 2]])
    buf = io.StringIO()
    buf.write("z,r,v,beta,C,lambda,x,y,zz\n")
    np.savetxt(buf, cols, delimiter=",", fmt="%.12g")
    return buf.getvalue()


def run(args: argparse.Namespace) -> int:
    from engine.cli import dump_json
    from engine.fileio import atomic_write_text
    from engine.job import load_job
    from engine.state import CliState
    from engine.winding import winding_line_for_job

    if args.csv:
        from engine.fileio import check_output_path

        check_output_path(args.csv, "CSV")
    job = load_job(args.job)
    line = winding_line_for_job(job, args.job, state=CliState(quiet=args.json))
    if args.csv:
        atomic_write_text(args.csv, csv_text(line.one_circuit if args.one_circuit else line))
    report = line.summary()
    if args.csv:
        report["csv"] = str(args.csv)
    if args.json:
        dump_json(report)
    else:
        lam = report["lambda"]
        lam_txt = f"{lam:.6g}" if isinstance(lam, float) else f"{len(lam)} pieces"
        print(f"mode {report['mode']}: λ {lam_txt}, max |λ| {report['max_abs_lambda']:.4g} "
              f"at z = {report['z_at_max_lambda']:.6g} mm, μ = {report['mu']:g}")
        print(f"turnarounds z = {report['z_turn'][0]:.6g} / {report['z_turn'][1]:.6g} mm ({', '.join(line.end_kinds)})")
        print(f"pattern p = {line.pattern_p}, q = {line.pattern_q} ({line.lead}), {line.circuits} circuits, "
              f"Δv = {math.degrees(line.twist_per_circuit_rad):.4f}°, coverage {line.coverage['fraction']:.4f}")
        for t in line.turnarounds:
            print(f"{t['side']} turnaround: {t['how']}")
        for a, b in line.slips:
            print(f"SLIPS (|λ| > μ) in z {a:.6g} .. {b:.6g} mm")
        for a, b in line.bridging:
            print(f"BRIDGES (constraint (6)) in z {a:.6g} .. {b:.6g} mm")
        for n in line.notes:
            print(f"note: {n}")
    return 0 if line.ok else 1
