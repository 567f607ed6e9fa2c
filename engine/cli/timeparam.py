"""``winder timeparam``: the time law ṡ(s) of a path (DP + tube of seed 003, classical DP, TOPP-RA).

Examples::

    winder timeparam --example                      # the paper's setting on the project's 7-axis path
    winder timeparam PATH.npz --limits LIMITS.toml --method tube --json
    winder timeparam --example --method dp --levels 1100 --npz-out law.npz

``PATH.npz`` holds ``s`` (N,), ``X``, ``dX``, ``ddX`` (N, p).  ``LIMITS.toml`` keys: ``v_max``,
``a_max`` (lists of p), ``sdot_max``, ``sddot_max``, ``levels``, ``penalty``, ``tube_share``,
``stop_percent``, ``sdot_start``, ``sdot_end`` and ``[[points]]`` tables (``s`` or ``s_from``/``s_to``,
``sdot_max``, ``label``).  Exit code 1 if the computed law breaks a limit (never expected for the
DP methods; TOPP-RA's interpolation scheme may overshoot slightly inside intervals and is reported).
"""

from __future__ import annotations

import argparse
import io
from dataclasses import replace
from pathlib import Path

import numpy as np

from engine.cli import dump_json
from engine.errors import InputError
from engine.fileio import atomic_write_bytes, check_output_path
from engine.state import CliState
from engine.timeparam import METHODS, limits_from_toml, load_path_npz, parametrize

NAME = "timeparam"
HELP = "Time law of a path under axis/technological limits: DP + tube (seed 003), DP or TOPP-RA"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("path", nargs="?", help="PATH.npz with arrays s, X, dX, ddX")
    parser.add_argument("--limits", help="LIMITS.toml (with --example: defaults to the paper's limits)")
    parser.add_argument("--method", choices=METHODS, default="tube", help="tube (default), dp or toppra")
    parser.add_argument("--levels", type=int, help="override M, the number of speed levels")
    parser.add_argument("--no-sweep", action="store_true",
                        help="tube: keep the tube's own law (no final sweep; same as sweep = false in LIMITS.toml)")
    parser.add_argument("--example", action="store_true",
                        help="the paper's setting (p = 7, N = 893, s_N = 2846.9 mm) on the project's path")
    parser.add_argument("--json", action="store_true", help="print the result as JSON")
    parser.add_argument("--npz-out", help="save s, sdot, t (and the iteration log) to this .npz file")


def run(args: argparse.Namespace) -> int:
    if args.npz_out:
        check_output_path(args.npz_out, ".npz")
    if args.example:
        from engine.timeparam_example import EXAMPLE_LIMITS, example_path

        s, X, dX, ddX = example_path()
        limits = limits_from_toml(args.limits or EXAMPLE_LIMITS)
    else:
        if not args.path:
            raise InputError("give PATH.npz (or --example)", field="path")
        if not args.limits:
            raise InputError("--limits LIMITS.toml is required with PATH.npz", field="limits")
        s, X, dX, ddX = load_path_npz(args.path)
        limits = limits_from_toml(args.limits)
    if args.levels is not None:
        from engine.timeparam import _MAX_LEVELS, MIN_USER_LEVELS

        if not MIN_USER_LEVELS <= args.levels <= _MAX_LEVELS:
            raise InputError(f"must be in {MIN_USER_LEVELS}..{_MAX_LEVELS}, got {args.levels}", field="--levels")
        limits = replace(limits, levels=args.levels)
    if args.no_sweep:
        limits = replace(limits, sweep=False)
    from engine import budget

    if args.method != "toppra":
        budget.check_dp(s.size, limits.levels, field="--levels" if args.levels is not None else "levels",
                        file=None if args.levels is not None or args.example and not args.limits else args.limits,
                        method=args.method)
    try:
        law = parametrize(s, X, dX, ddX, limits, method=args.method, state=CliState(quiet=args.json))
    except InputError as exc:
        if args.example or exc.location.file:
            raise
        where = args.path if exc.location.field in ("s", "X", "dX", "ddX") else args.limits
        raise exc.at(file=where) from None
    if args.npz_out:
        buf = io.BytesIO()
        its = law.iterations
        # the iterations' own nodes: the law's, or the node groups' ends on dense paths (node_group > 1)
        it_s = its[0].s if its else law.s
        np.savez(buf, s=law.s, sdot=law.sdot, t=law.t, iter_s=it_s,
                 iter_r=np.array([it.r for it in its], int),
                 iter_total_time_s=np.array([it.total_time_s for it in its]),
                 iter_sdot=np.array([it.sdot for it in its]).reshape(len(its), it_s.size),
                 iter_lower=np.array([it.lower for it in its]).reshape(len(its), it_s.size),
                 iter_upper=np.array([it.upper for it in its]).reshape(len(its), it_s.size))
        atomic_write_bytes(Path(args.npz_out), buf.getvalue())
    violated = args.method != "toppra" and max(law.max_accel_ratio, law.max_speed_ratio,
                                               law.max_sddot_ratio) > 1.0 + 1e-9
    if args.json:
        dump_json(law.summary())
    else:
        for it in law.iterations:
            print(it.text())
        if law.sweep_gain_s > 0:
            print(f"final sweep: {law.sweep_gain_s:.4f} s faster than the tube's law (its limits held)")
        print(f"method {law.method}  M = {law.levels}  total time {law.total_time_s:.4f} s  "
              f"computed in {law.compute_s:.3f} s")
        print(f"worst ratios inside intervals: axis acceleration {law.max_accel_ratio:.5f}, "
              f"axis speed {law.max_speed_ratio:.5f}, path acceleration {law.max_sddot_ratio:.5f}")
        print(f"curvature energy of sdot(t): {law.energy:.6g}")
        if args.npz_out:
            print(f"saved {args.npz_out}")
    if violated:
        print("winder timeparam: the computed law breaks a limit (see the ratios above)")
        return 1
    return 0
