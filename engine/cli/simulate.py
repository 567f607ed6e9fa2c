"""``winder simulate FILE --machine TEMPLATE [--controller C] [--job JOB] [--json]``: NC read-back."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

NAME = "simulate"
HELP = ("Read an NC program back (ours or foreign G-code), replay it on a machine template and report time, "
        "fibre length, axis ranges and every limit violation.")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("file", help="NC program (.ngc, .nc, .mpf, .gcode, .csv)")
    parser.add_argument("--machine", metavar="TEMPLATE",
                        help="machine template (name or .toml); default: the job's, else lathe2")
    parser.add_argument("--controller", metavar="C",
                        help="controller profile for the axis letters (default: the profile that matches "
                             "the file's dialect and the machine)")
    parser.add_argument("--job", metavar="JOB.toml",
                        help="the winding job: its machine set-up, and its winding line for the laid fibre")
    parser.add_argument("--json", action="store_true", help="print the report as JSON")


def run(args: argparse.Namespace) -> int:
    from engine.cli import dump_json
    from engine.ncread import read_back

    path = Path(args.file)
    job = line = None
    tol = 0.01
    if args.job:
        from engine.job import load_job

        job = load_job(args.job)
        tol = float(job.machine.setup.back_turn_tol_deg)
    machine = _machine(args, job)
    if job is not None and job.is_single_line:
        from engine.pipeline import run_pipeline

        line = run_pipeline(job, args.job, upto="winding").line
    elif job is not None:  # a laminate: every layer's line as the joined program lays it
        from engine.laminate import laid_line, run_laminate

        line = laid_line(run_laminate(job, args.job))
    sim, profile_name = read_back(path, machine, args.controller, line, back_turn_tol_deg=tol)
    prog = sim.program
    rep = {**sim.report, "controller": profile_name}
    if args.json:
        dump_json(rep, sys.stdout)
    else:
        print(f"{path}: {prog.n} moves on {machine.name}, program time {rep['program_time_s']:.2f} s "
              f"(with the limits {rep['time_with_limits_s']:.2f} s)")
        for n, (a, b) in rep["axis_ranges"].items():
            print(f"  {n}: {a:.4g} .. {b:.4g}")
        if "fibre_length_mm" in rep:
            print(f"  laid fibre {rep['fibre_length_mm']:.1f} mm (eye within {rep['fibre_miss_mm']:.3g} mm of the "
                  f"fibre tangent)")
        for v in rep["violations"]:
            print(f"violation: {v['message']}", file=sys.stderr)
    return 0 if sim.report["ok"] else 1


def _machine(args: argparse.Namespace, job: object | None) -> object:
    if job is not None:
        from engine.pipeline import setup_machine_for_job

        if args.machine:
            job = job.replace(machine={**job.machine.model_dump(), "template": args.machine})  # type: ignore[attr-defined]
        return setup_machine_for_job(job, args.job)  # type: ignore[arg-type]
    from engine.kinematics import load_machine

    return load_machine(args.machine or "lathe2")
