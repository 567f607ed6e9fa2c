"""The machine in the 3D view: carriage, cross-slide / robot links and payout head at the current frame
(a mixin of :class:`winder_gui.views.view3d.MandrelView3D`).

The pose of each frame comes from the engine's forward kinematics of the result's axis path
(:func:`winder_gui.views.machine3d.machine_frames`, computed once per path set).  Three actors are made
once per path set and then only moved: the carriage (a box, by its user matrix), the link chain (a
thick polyline whose points are replaced) and the head (a cylinder whose tip, its local origin, is
placed at the eye by its user matrix).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from winder_gui.views.machine3d import MachineFrames, machine_frames

MACHINE_ACTORS = ("machine_links", "machine_carriage", "machine_head")
MACHINE_COLOUR = "#5a6b7d"
HEAD_COLOUR = "#e3a21a"


def _frame_matrix(x: np.ndarray, hint: np.ndarray, origin: np.ndarray) -> np.ndarray:
    """4x4 placing a local frame: local x along ``x``, local y along ``hint`` made orthogonal to it,
    local z = x × y, local origin at ``origin``."""
    x = x / max(float(np.linalg.norm(x)), 1e-12)
    y = hint - float(np.dot(hint, x)) * x
    ny = float(np.linalg.norm(y))
    if ny < 1e-9:   # hint along x: any perpendicular
        y = np.cross(x, [0.0, 0.0, 1.0] if abs(x[2]) < 0.9 else [0.0, 1.0, 0.0])
        ny = float(np.linalg.norm(y))
    y = y / ny
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = x, y, np.cross(x, y), origin
    return m


class MachineMixin:
    """Draws and moves the machine (needs ``plotter``, ``paths``, ``frame`` of the view)."""

    paths: Any
    plotter: Any
    frame: int

    def _machine_init(self) -> None:
        self.machine_visible = True
        """Whether the carriage, links and head are drawn (View -> Show the machine)."""
        self._machine: dict[str, Any] = {}
        self._machine_frames_cache: dict[int, tuple[Any, MachineFrames]] = {}
        """The machine's frames per path set (a laminate's layers: playing on swaps, computes none)."""

    def machine_pose(self) -> MachineFrames | None:
        """The machine's pose at every frame of the shown paths (view frame, mm), or ``None`` when the
        paths carry no axis path."""
        p = self.paths
        if p is None or p.frame_q is None or p.machine is None:
            return None
        if self._machine.get("paths") is not p:
            size = self._machine_size()
            frames = self._machine_frames_cache.get(id(p))
            if frames is None or frames[0] is not p:   # forward kinematics of every frame, once per path set
                frames = (p, machine_frames(p.machine, p.frame_q, margin_mm=6.0 * size))
                self._machine_frames_cache[id(p)] = frames
                while len(self._machine_frames_cache) > 12:
                    self._machine_frames_cache.pop(next(iter(self._machine_frames_cache)))
            self._machine = {"paths": p, "size": size, "frames": frames[1]}
        return self._machine["frames"]

    def _machine_size(self) -> float:
        p = self.paths
        return 0.03 * float(np.max(np.abs(p.line_xyz[:, 1:]))) if p is not None and p.line_xyz.size else 3.0

    def _remove_machine(self) -> None:
        if self.plotter is not None:
            for name in MACHINE_ACTORS:
                self.plotter.remove_actor(name, render=False)
        self._machine = {}

    def set_machine_visible(self, on: bool) -> None:
        """Show or hide the carriage, cross-slide / links and head."""
        self.machine_visible = bool(on)
        box = getattr(self, "machine_check", None)
        if box is not None and box.isChecked() != self.machine_visible:
            box.blockSignals(True)
            box.setChecked(self.machine_visible)
            box.blockSignals(False)
        if self.plotter is None:
            return
        for name in MACHINE_ACTORS:
            actor = self.plotter.actors.get(name)
            if actor is not None:
                actor.SetVisibility(self.machine_visible)
        if self.machine_visible:
            self._update_machine()
        self.plotter.render()

    def _update_machine(self) -> None:
        """Move the machine's actors to the current frame (made on the first call per path set)."""
        import pyvista as pv

        fr = self.machine_pose() if self.machine_visible else None
        if fr is None or self.plotter is None or fr.eye.shape[0] == 0:
            return
        i = int(np.clip(self.frame, 0, fr.eye.shape[0] - 1))
        st = self._machine
        h = st["size"]
        actors = self.plotter.actors
        links = fr.links[i]
        if "links" not in st or "machine_links" not in actors:
            st["links"] = pv.lines_from_points(links)
            self.plotter.add_mesh(st["links"], name="machine_links", color=MACHINE_COLOUR, line_width=7,
                                  reset_camera=False, render=False)
            box = pv.Box(bounds=(-6.0 * h, 6.0 * h, -2.0 * h, 2.0 * h, -4.0 * h, 4.0 * h))
            st["machine_carriage"] = self.plotter.add_mesh(box, name="machine_carriage", color=MACHINE_COLOUR,
                                                           reset_camera=False, render=False)
            # the head: a cylinder behind its tip, the local origin, which is placed at the eye; the set-up's
            # body (a capsule of head_radius_mm about head_length_mm of the roll axis) where one is given
            rad, length = self.paths.head_mm if self.paths is not None else (0.0, 0.0)
            if length > 0.0 or rad > 0.0:
                rad = rad if rad > 0.0 else 1.5 * h
                length = max(length, 1e-3 * h)
                head = pv.Cylinder(center=(-0.5 * length, 0.0, 0.0), direction=(1.0, 0.0, 0.0), radius=rad,
                                   height=length, resolution=24)
                head = head.merge(pv.Sphere(radius=rad, center=(0.0, 0.0, 0.0))).merge(
                    pv.Sphere(radius=rad, center=(-length, 0.0, 0.0)))
            else:
                head = pv.Cylinder(center=(-5.0 * h, 0.0, 0.0), direction=(1.0, 0.0, 0.0), radius=1.5 * h,
                                   height=10.0 * h, resolution=24)
            st["machine_head"] = self.plotter.add_mesh(head, name="machine_head", color=HEAD_COLOUR,
                                                       reset_camera=False, render=False)
        else:
            st["links"].points = links
        from vtkmodules.vtkCommonMath import vtkMatrix4x4

        def place(name: str, m: np.ndarray) -> None:
            vm = vtkMatrix4x4()
            vm.DeepCopy(m.ravel())
            st[name].SetUserMatrix(vm)

        c = fr.carriage[i]
        place("machine_carriage", _frame_matrix(np.array([1.0, 0.0, 0.0]), np.array([0.0, c[1], c[2]]), c))
        eye = fr.eye[i]
        # from the head's body into its tip: against the head's roll axis (the last link where none is known)
        into = -fr.head_axis[i] if fr.head_axis is not None else eye - links[-2]
        place("machine_head", _frame_matrix(into, np.array([1.0, 0.0, 0.0]), eye))

    def machine_head_eye(self) -> np.ndarray | None:
        """The drawn head's eye (its tip) in the view frame (mm): the head actor's transform applied to
        its local origin; ``None`` when no head is drawn."""
        if self.plotter is None:
            return None
        actor = self.plotter.actors.get("machine_head")
        if actor is None:
            return None
        m = actor.GetMatrix()
        return np.array([m.GetElement(r, 3) / m.GetElement(3, 3) for r in range(3)])
