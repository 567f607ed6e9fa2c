"""The machine drawn in the 3D view from the engine's forward kinematics (no Qt, no VTK).

For every animation frame the controller axis values of the engine's :class:`engine.kinematics.AxisPath`
give, through the engine's forward kinematics (:func:`engine.kinematics.eye_pose`; the robot's joint
origins from the same DH chain), the eye and a link chain from the carriage (robot: the base on its
track) to the eye, in the machine frame; turned by the mandrel angle (``p_M = Rz(-theta) p_W``, as
:func:`engine.kinematics.forward_kinematics`) into the mandrel frame and then into the view frame
(:func:`winder_gui.views.geometry.to_view`).  Computed once per path set, vectorised over the frames,
so a frame only moves three actors.

Cartesian (lathe-type) machines: the carriage rides a rail at a fixed distance from the mandrel axis
(beyond the eye's farthest radial position), the cross-slide runs from it to the head, whose tip is
the eye.  Robot: base, the six joint origins, the eye.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np


@dataclass(frozen=True)
class MachineFrames:
    """The machine's pose at each animation frame, view frame (mm).

    Attributes
    ----------
    links: (N, K, 3) link chain from the carriage / robot base to the eye (``links[:, -1]`` is the eye).
    eye: (N, 3) the eye by forward kinematics (= ``links[:, -1]``).
    carriage: (N, 3) where the carriage (robot: its base on the track) is drawn; it moves along the
        mandrel axis (the robot's track is parallel to it).
    """

    links: np.ndarray
    eye: np.ndarray
    carriage: np.ndarray
    head_axis: np.ndarray | None = None
    """(N, 3) unit vectors, view frame: from the eye along the payout head's body (its roll axis,
    :func:`engine.machine_setup.head_axis_q`)."""


def _to_mandrel(v: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """Machine-frame points (N, K, 3) at mandrel angles ``theta`` (N,) -> mandrel frame: ``Rz(-theta) v``."""
    c, s = np.cos(theta)[:, None], np.sin(theta)[:, None]
    out = np.empty_like(v)
    out[..., 0] = c * v[..., 0] + s * v[..., 1]
    out[..., 1] = c * v[..., 1] - s * v[..., 0]
    out[..., 2] = v[..., 2]
    return out


def _view(v: np.ndarray) -> np.ndarray:
    """Mandrel frame (axis z) -> view frame (axis x), any leading shape (as ``geometry.to_view``)."""
    return v[..., [2, 0, 1]]


def machine_frames(machine: Any, q: np.ndarray, margin_mm: float = 0.0) -> MachineFrames:
    """The machine's link chain at each row of controller values ``q`` (N, n_axes).

    ``machine``: the :class:`engine.kinematics.MachineTemplate` the axis path was made for (the
    result's, so with its set-up and placement).  ``margin_mm``: how far beyond the eye's farthest
    radial position a lathe's carriage rail is drawn.
    """
    from engine.kinematics import _robot_chain, eye_pose

    q = np.atleast_2d(np.asarray(q, dtype=float))
    n = q.shape[0]
    q_int = machine.to_internal(q)
    theta = q_int[:, machine.axis_index("mandrel")]
    eye_w, _ = eye_pose(machine, q_int, axis=False)
    if machine.kind == "robot":
        track = q_int[:, machine.axis_index("track")]
        joints = q_int[:, [machine.axis_index(f"joint{k + 1}") for k in range(len(machine.dh))]]
        _R, pe, _zs, os_ = _robot_chain(machine, track, joints, want_axes=True)
        links_w = np.concatenate([os_, pe[:, None, :]], axis=1)
        carriage_w = os_[:, 0]
    else:
        rho = np.hypot(eye_w[:, 0], eye_w[:, 1])
        rail = float(rho.max()) + margin_mm if n else margin_mm
        # the rail on the side the eye works on (machine +x unless the eye sits at negative x)
        side = 1.0 if float(np.median(eye_w[:, 0])) >= 0.0 else -1.0
        carriage_w = np.column_stack([np.full(n, side * rail), np.zeros(n), eye_w[:, 2]])
        elbow = np.column_stack([np.full(n, side * rail), eye_w[:, 1], eye_w[:, 2]])
        links_w = np.stack([carriage_w, elbow, eye_w], axis=1)
    links = _view(_to_mandrel(links_w, theta))
    carriage = _view(_to_mandrel(carriage_w[:, None, :], theta)[:, 0])
    from engine.machine_setup import head_axis_q

    return MachineFrames(links, links[:, -1].copy(), carriage, _view(head_axis_q(machine, q)))
