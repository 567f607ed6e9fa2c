"""The paper's worked example of time parametrization (seed 003, MATH.md §B), on a path we generate.

The paper's 7-coordinate path of a robot cell (6 revolute joints + a linear track) is not published;
:func:`example_path` builds a deterministic, smooth stand-in of the same size (N = 893 nodes,
s_N = 2846.9 mm): each joint is a sum of a few slow harmonics of ``u = s / s_N`` (rad), the track a
ramp plus a harmonic (mm), with exact first and second derivatives.  With the limits of Tables 4-5
the time-optimal law is bound by the accelerations of axes 1, 4, 5 and 6, by s̈_T and by the two
technological points (axis 1 reaches 90 % of its speed limit; ṡ peaks at ~670 of the 750 mm/s).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from engine.timeparam import TimeLimits, limits_from_toml

__all__ = ["EXAMPLE_LIMITS", "example_limits", "example_path"]

EXAMPLE_LIMITS = Path(__file__).resolve().parents[1] / "resources" / "examples" / "timeparam_paper_limits.toml"

N_PAPER = 893
S_N_PAPER = 2846.9  # mm

# per coordinate: list of (amplitude, harmonic number, phase); joints in rad, track in mm
_HARMONICS: tuple[tuple[tuple[float, float, float], ...], ...] = (
    ((2.00, 0.5, 0.0), (0.03, 2.0, 0.4)),             # J1 base swing (its speed limit binds)
    ((0.09, 1.0, 1.1), (0.018, 3.0, 0.2)),            # J2 shoulder
    ((0.084, 1.0, 2.3), (0.015, 4.0, 1.0)),           # J3 elbow
    ((0.105, 1.5, 0.7), (0.024, 3.0, 2.0)),           # J4 wrist roll
    ((0.075, 2.0, 1.9), (0.015, 5.0, 0.3)),           # J5 wrist pitch
    ((0.18, 1.0, 0.5), (0.03, 4.0, 1.4)),             # J6 wrist yaw / eye roll
    ((78.0, 1.0, 0.0), (18.0, 3.0, 0.9)),             # track (mm)
)
_TRACK_RAMP = 1200.0  # mm over the path


def example_path(n: int = N_PAPER, s_end: float = S_N_PAPER, s_unit: float | None = None
                 ) -> tuple[np.ndarray, ...]:
    """The example path: ``(s, X, dX, ddX)``, shapes (n,), (n, 7), (n, 7), (n, 7); mm and rad.

    Parameters
    ----------
    n:
        Number of nodes (893 in the paper).
    s_end:
        Path length s_N (mm); the nodes are uniform on ``[0, s_end]``.
    s_unit:
        Path length (mm) over which the harmonics have their listed numbers (default ``s_end``: the
        path is stretched to ``s_end``).  ``example_path(30 * 892 + 1, 30 * S_N_PAPER, S_N_PAPER)`` is
        the paper's path continued 30 times as long at the paper's node spacing.
    """
    s = np.linspace(0.0, float(s_end), int(n))
    s_end = float(s_unit) if s_unit is not None else float(s_end)
    u = s / s_end
    p = len(_HARMONICS)
    X = np.zeros((s.size, p))
    dX = np.zeros_like(X)
    ddX = np.zeros_like(X)
    for c, terms in enumerate(_HARMONICS):
        for amp, k, ph in terms:
            w = 2.0 * np.pi * k / s_end                  # rad per mm of s
            arg = 2.0 * np.pi * k * u + ph
            X[:, c] += amp * (np.sin(arg) - np.sin(ph))
            dX[:, c] += amp * w * np.cos(arg)
            ddX[:, c] += -amp * w * w * np.sin(arg)
    X[:, -1] += _TRACK_RAMP * u
    dX[:, -1] += _TRACK_RAMP / s_end
    return s, X, dX, ddX


def example_limits() -> TimeLimits:
    """The limits of Tables 4-5 (``resources/examples/timeparam_paper_limits.toml``)."""
    return limits_from_toml(EXAMPLE_LIMITS)
