"""``winder payout JOB.toml [--law LAW] [--json] [--csv OUT.csv]``: the payout-eye path and pull speed."""

from __future__ import annotations

import argparse
import io
from pathlib import Path
from typing import Any

from engine.errors import InputError

NAME = "payout"
HELP = "Payout-eye path of one circuit by a geometric or the min-range law; pull-speed range, jerk, constraints."

_LAWS = ("parallel", "equidistant", "equal-tangent", "curve", "min-range")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("job", help="job file (.toml)")
    parser.add_argument("--law", choices=_LAWS, default=None, help="eye law (default: the job's payout.law)")
    parser.add_argument("--k", type=int, choices=(0, 1), default=None,
                        help="impregnation scheme of (12) (default: the job's payout.impregnation_k)")
    parser.add_argument("--points", type=int, default=None, metavar="N", help="grid points (default: the job's)")
    parser.add_argument("--json", action="store_true", help="print the report as JSON")
    parser.add_argument("--csv", metavar="OUT.csv", help="write x, z, l, Z, R, V, eye xyz, u per grid point")


def _csv_text(eye: Any) -> str:
    import numpy as np

    u = np.append(eye.u, np.nan)  # u on [x_i, x_i+1]; the last point has none
    buf = io.StringIO()
    buf.write("x,s_mm,z_mm,l_mm,Z_mm,R_mm,V_rad,eye_x_mm,eye_y_mm,eye_z_mm,lambda_mm,u\n")
    cols = np.column_stack([eye.x, eye.s, eye.contact_xyz[:, 2], eye.l, eye.Z, eye.R, eye.V, eye.eye_xyz,
                            eye.lam_pulled]).tolist()
    for row, ui in zip(cols, u.tolist()):
        buf.write(",".join(repr(float(v)) for v in row) + "," + ("" if ui != ui else repr(ui)) + "\n")
    return buf.getvalue()


def run(args: argparse.Namespace) -> int:
    from engine.cli import dump_json
    from engine.fileio import atomic_write_text
    from engine.job import build_mandrel, load_job
    from engine.payout import payout_for_job
    from engine.state import CliState
    from engine.winding import winding_line_for_job

    path = Path(args.job)
    if args.csv:
        from engine.fileio import check_output_path

        check_output_path(args.csv, "CSV")
    job = load_job(path)
    upd: dict[str, Any] = {}
    if args.k is not None:
        upd["impregnation_k"] = args.k
    if args.points is not None:
        if not 50 <= args.points <= 100_000:
            raise InputError(f"must be in [50, 100000], got {args.points}", field="--points")
        upd["grid_points"] = args.points
    if upd:
        job = job.replace(payout=job.payout.model_copy(update=upd))
    state = CliState(quiet=args.json)
    mandrel = build_mandrel(job, path)
    line = winding_line_for_job(job, path, state=None)
    try:
        eye = payout_for_job(job, line, mandrel, state=state, law=args.law)
    except InputError as exc:
        raise exc.at(file=path) from None
    rep = eye.report
    if args.csv:
        atomic_write_text(args.csv, _csv_text(eye))
    if args.json:
        dump_json(rep)
    else:
        print(f"{job.name}: law {rep['law']}, k = {rep['k']}, x = {rep['parameter']}, {rep['points']} grid points")
        print(f"  pull speed u: {rep['u_min']:.6g} .. {rep['u_max']:.6g} (range {rep['u_range']:.6g}), "
              f"mean U = {rep['U']:.6g}, jerk {rep['jerk']:.6g}")
        print(f"  free length l: {rep['l_min']:.4g} .. {rep['l_max']:.4g} mm; eye R {rep['R_min']:.4g} .. "
              f"{rep['R_max']:.4g} mm, Z {rep['Z_min']:.4g} .. {rep['Z_max']:.4g} mm")
        for name, c in rep["constraints"].items():
            if not c["ok"]:
                where = c.get("violated") or [{}]
                w = where[0]
                at = f" at x {w['x_from']:.5g}..{w['x_to']:.5g} (z {w['z_from']:.5g}..{w['z_to']:.5g} mm)" if w else ""
                print(f"  VIOLATED {name}{at}")
        print("  feasible" if rep["feasible"] else "  NOT feasible")
    return 0 if rep["feasible"] else 1
