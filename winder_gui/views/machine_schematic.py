"""Kinematic schematic of a machine template, drawn from the engine's own machine model.

The drawing is computed, never hand-made: every point comes from the engine's forward kinematics
(:func:`engine.kinematics.eye_chain`, the right-hand side of eq. (16)) at a *neutral pose*
(:func:`neutral_pose`), and every axis direction from the chain's derivative with respect to that
axis (a central difference of the same forward kinematics).  So a user-added template is drawn by the
same code as the shipped ones; there is no per-template code, only the engine's two machine kinds:

* ``cartesian`` winders: the linear slides are drawn as a staircase in chain (program) order - each
  slide carries the next one, drawn from the end of its travel drawn farther from the mandrel axis (so a
  carriage rail runs beside the mandrel and a cross slide reaches towards it); the eye rotations
  (yaw, roll) are circular arrows about their axes through the eye;
* ``robot`` cells: the track is an arrow at the robot base, the arm is its Denavit-Hartenberg link
  chain (frames of the chain truncated after each joint), each joint a circular arrow about its axis.

The mandrel is a schematic cylinder on the spindle axis (the machine frame's z axis); its size is
nominal (the template does not know the part).  The payout eye is a dot at the end of the chain.

Projection
----------
Orthographic axonometric view of the machine frame (mm) from the eye side (+x), turned 40 deg towards
the tail end (+z) and raised 22 deg: the mandrel axis runs across the picture (headstock on the
right, at the far end), the vertical y is drawn up, x comes towards the viewer.  :data:`PROJECTION`
is that 2x3 matrix (rows: the screen's right and up unit vectors); :meth:`MachineSchematic.axis_glyphs`
returns every axis's projected anchor, direction and label (tests check them against the forward
kinematics).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
from PySide6.QtCore import QPointF, QRectF, QSize, Qt, Signal
from PySide6.QtGui import QBrush, QColor, QFont, QFontMetricsF, QPainter, QPainterPath, QPen, QPolygonF
from PySide6.QtWidgets import QSizePolicy, QWidget

from winder_gui.i18n import tr
from winder_gui.views.schematic_model import (  # noqa: F401 - PROJECTION, place_labels: this module's API too
    EYE_COLOUR,
    MANDREL_COLOUR,
    PROJECTION,
    STRUCTURE_COLOUR,
    VIEW_DIR,
    AxisGlyph,
    Schematic,
    _circle3,
    _hull,
    axis_colour,
    build_schematic,
    neutral_pose,
    place_labels,
    project,
)


def _alpha(colour: str, a: int) -> QColor:
    c = QColor(colour)
    c.setAlpha(a)
    return c


# --------------------------------------------------------------------------------------------------
# Widget
# --------------------------------------------------------------------------------------------------
class MachineSchematic(QWidget):
    """The selected template's kinematic scheme (QPainter, axonometric projection; works offscreen).

    ``set_machine(template)`` or ``set_template(name_or_path)`` shows a template; a template that
    fails to load shows its message instead.  ``set_highlight(axis_name)`` draws that axis bold.
    ``axis_clicked(name)`` is emitted when the user clicks near an axis.
    """

    axis_clicked = Signal(str)

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.setObjectName("machine.schematic")
        self.setMinimumSize(260, 180)
        self.setSizePolicy(QSizePolicy.Policy.Expanding, QSizePolicy.Policy.Expanding)
        self.schematic: Schematic | None = None
        self.message = ""
        self.highlighted: str | None = None
        self._queued: list[Any] = []
        self.label_rects: dict[str, QRectF] = {}
        """Where each label was drawn last (widget pixels), for tests: none overlaps another."""
        self._map: tuple[float, float, float] = (1.0, 0.0, 0.0)    # scale, x0, y0
        self.head_mm: tuple[float, float] = (0.0, 0.0)
        """The payout head's body from the job's set-up: radius and length along its roll axis (mm)."""
        self.head_pixels: tuple[QPointF, QPointF, float] | None = None
        """Where the head's body was drawn last: eye end, far end (widget pixels) and its width, for tests."""
        self.setToolTip(tr("Kinematic scheme of the template drawn from its forward kinematics (mandrel "
                        "schematic, nominal size); each axis with its travel in controller units. "
                        "Click an axis to select its row."))

    def sizeHint(self) -> QSize:
        return QSize(360, 240)

    # -- API ---------------------------------------------------------------------------------------
    def set_machine(self, machine: Any | None, message: str = "") -> None:
        """Show ``machine`` (a MachineTemplate); ``None`` shows ``message`` instead."""
        self.schematic = None
        self.message = message
        if machine is not None:
            try:
                self.schematic = build_schematic(machine, getattr(self, "part", None))
            except Exception as exc:     # noqa: BLE001 - a drawing must never take the panel down
                self.message = f"cannot draw the scheme of {getattr(machine, 'name', 'the machine')}: {exc}"
        if self.schematic is not None and self.highlighted not in self.labels():
            self.highlighted = None
        self.update()

    def set_part(self, part: tuple[float, float, float, tuple] | None) -> None:
        """Draw the job's mandrel ``(z_min, z_max, r_max, supports)`` instead of the nominal one (None:
        nominal); takes effect with the next :meth:`set_machine`."""
        self.part = part

    def set_head(self, radius_mm: float, length_mm: float) -> None:
        """The payout head's body (``[machine.setup]`` head_radius_mm, head_length_mm): drawn from the eye
        along its roll axis (engine.machine_setup.head_axis_q) when either is set."""
        self.head_mm = (float(radius_mm), float(length_mm))
        self.update()

    def set_template(self, name_or_path: str | Path) -> None:
        """Load a template by name or path and show it (or the loader's message)."""
        from engine.errors import InputError
        from engine.kinematics import load_machine

        try:
            self.set_machine(load_machine(name_or_path))
        except InputError as exc:
            self.set_machine(None, str(exc))

    def set_highlight(self, name: str | None) -> None:
        self.highlighted = name
        self.update()

    def labels(self) -> list[str]:
        """Axis names drawn, in template order."""
        return [g.name for g in self.schematic.axes] if self.schematic else []

    def axis_glyphs(self) -> list[AxisGlyph]:
        """Per-axis drawing data (3-D and projected anchors, directions, ends, labels)."""
        return list(self.schematic.axes) if self.schematic else []

    def eye_point(self) -> np.ndarray | None:
        """The eye as drawn, projected (mm, v up)."""
        return self.schematic.eye if self.schematic else None

    def to_pixels(self, p2: np.ndarray) -> QPointF:
        """Drawing-plane point (mm, v up) -> widget pixels, for the current size."""
        s, x0, y0 = self._map
        return QPointF(x0 + s * float(p2[0]), y0 - s * float(p2[1]))

    # -- painting ----------------------------------------------------------------------------------
    def _fit(self, sch: Schematic) -> None:
        pts = [sch.links, sch.eye[None, :], project(self._mandrel_points(sch))]
        for _n, z0, z1, r in sch.supports:
            pts.append(project(self._cylinder_points(z0, z1, r, 8)))
        for g in sch.axes:
            if g.type == "linear":
                pts.append(project(self._linear_ends(g, sch)))
            else:
                pts.append(project(_circle3(g.origin3, g.dir3, g.radius, 0, 2 * math.pi, 16)))
        allp = np.vstack(pts)
        lo, hi = allp.min(axis=0), allp.max(axis=0)
        span = np.maximum(hi - lo, 1.0)
        mx, my = 46.0, 22.0   # room for the labels
        w, h = max(self.width() - 2 * mx, 10.0), max(self.height() - 2 * my, 10.0)
        s = min(w / span[0], h / span[1])
        x0 = mx + 0.5 * (w - s * span[0]) - s * lo[0]
        y0 = my + 0.5 * (h - s * span[1]) + s * hi[1]
        self._map = (s, x0, y0)

    @staticmethod
    def _cylinder_points(z0: float, z1: float, r: float, n: int = 40) -> np.ndarray:
        t = np.linspace(0, 2 * math.pi, n, endpoint=False)
        ring = np.stack([r * np.cos(t), r * np.sin(t), np.zeros(n)], axis=1)
        a, b = ring.copy(), ring.copy()
        a[:, 2], b[:, 2] = z0, z1
        return np.vstack([a, b])

    @staticmethod
    def _mandrel_points(sch: Schematic, n: int = 40) -> np.ndarray:
        t = np.linspace(0, 2 * math.pi, n, endpoint=False)
        ring = np.stack([sch.mandrel_radius * np.cos(t), sch.mandrel_radius * np.sin(t), np.zeros(n)], axis=1)
        a, b = ring.copy(), ring.copy()
        a[:, 2], b[:, 2] = sch.mandrel_z
        return np.vstack([a, b])

    @staticmethod
    def _linear_ends(g: AxisGlyph, sch: Schematic) -> np.ndarray:
        if g.ends3 is not None:
            return g.ends3
        return np.array([g.origin3 - 0.15 * sch.size * g.dir3, g.origin3 + 0.15 * sch.size * g.dir3])

    def _poly(self, pts3: np.ndarray) -> QPolygonF:
        return QPolygonF([self.to_pixels(p) for p in project(pts3)])

    def paintEvent(self, _ev: Any) -> None:  # noqa: N802 - Qt API
        p = QPainter(self)
        p.setRenderHint(QPainter.RenderHint.Antialiasing)
        p.fillRect(self.rect(), QColor("#fbfbfb"))
        p.setPen(QPen(QColor("#d0d0d0")))
        p.drawRect(self.rect().adjusted(0, 0, -1, -1))
        sch = self.schematic
        if sch is None:
            p.setPen(QColor("#c01010") if self.message else QColor("#777"))
            p.drawText(QRectF(self.rect()).adjusted(8, 8, -8, -8),
                       Qt.AlignmentFlag.AlignCenter | Qt.TextFlag.TextWordWrap,
                       self.message or "no machine template")
            p.end()
            return
        self._fit(sch)
        font = QFont(self.font())
        font.setPointSizeF(max(7.0, min(9.0, self.height() / 26.0)))
        p.setFont(font)
        self._draw_mandrel(p, sch)
        self._draw_structure(p, sch)
        order = sorted(sch.axes, key=lambda g: g.name == self.highlighted)   # the highlighted one last
        boxes: list[QRectF] = []
        self._queued = []
        z0, z1 = sch.mandrel_z
        c = self.to_pixels(project(np.array([0, -sch.mandrel_radius, z1 - 0.15 * (z1 - z0)])))
        self._label(p, "mandrel", QPointF(c.x(), c.y() + 10), boxes, QColor("#555"))
        for g in order:
            self._draw_axis(p, sch, g, boxes)
        self._draw_head(p, sch)
        # the eye
        e = self.to_pixels(sch.eye)
        tip = self.to_pixels(project(sch.eye3 + 0.06 * sch.size * sch.eye_axis3))
        p.setPen(QPen(QColor(EYE_COLOUR), 1.2, Qt.PenStyle.DashLine))
        p.drawLine(e, tip)
        p.setPen(QPen(QColor("#7a1010"), 1.0))
        p.setBrush(QBrush(QColor(EYE_COLOUR)))
        p.drawEllipse(e, 4.5, 4.5)
        p.setPen(QColor(EYE_COLOUR))
        self._label(p, "eye", QPointF(e.x() + 6, e.y() + 12), boxes, QColor(EYE_COLOUR))
        self._draw_labels(p, [QRectF(e.x() - 6, e.y() - 6, 12, 12)])
        p.end()

    def _draw_head(self, p: QPainter, sch: Schematic) -> None:
        """The set-up's head body: a capsule from the eye along the roll axis, at the scheme's pose."""
        self.head_pixels = None
        radius, length = self.head_mm
        if radius <= 0.0 and length <= 0.0:
            return
        from engine.machine_setup import head_axis_q

        u = head_axis_q(sch.machine, np.atleast_2d(sch.q))[0]
        # head_axis_q gives the mandrel frame; the scheme draws the machine frame (the pose's mandrel angle)
        th = float(sch.machine.to_internal(np.atleast_2d(sch.q))[0, sch.machine.axis_index("mandrel")])
        c, s = math.cos(th), math.sin(th)
        u = np.array([c * u[0] - s * u[1], s * u[0] + c * u[1], u[2]])
        a = self.to_pixels(project(sch.eye3))
        b = self.to_pixels(project(sch.eye3 + length * u))
        width = max(2.0 * radius * self._map[0], 2.0)
        pen = QPen(_alpha("#e3a21a", 150), width)
        pen.setCapStyle(Qt.PenCapStyle.RoundCap)
        p.setPen(pen)
        p.drawLine(a, b)
        self.head_pixels = (a, b, width)

    def _draw_mandrel(self, p: QPainter, sch: Schematic) -> None:
        pts = self._mandrel_points(sch)
        z0, z1 = sch.mandrel_z
        s = 1.3 * sch.mandrel_radius
        zh = z0 - 0.04 * sch.size
        box = np.array([[-s, -s, zh], [s, -s, zh], [s, s, zh], [-s, s, zh]])
        behind = float(VIEW_DIR[2]) > 0          # the headstock (low z) is the far end

        def headstock() -> None:
            p.setPen(QPen(QColor("#777"), 1.0))
            p.setBrush(QBrush(QColor("#d9d9d9")))
            p.drawPolygon(self._poly(box))

        if behind:
            headstock()
        for _n, sz0, sz1, sr in sch.supports:          # shafts, chuck, tailstock
            p.setPen(QPen(QColor("#777"), 0.8))
            p.setBrush(QBrush(_alpha("#b0b0b0", 200)))
            p.drawPolygon(QPolygonF([self.to_pixels(q) for q in _hull(project(self._cylinder_points(sz0, sz1, sr,
                                                                                                   24)))]))
        hull = _hull(project(pts))
        p.setPen(QPen(QColor("#6c7a88"), 1.0))
        p.setBrush(QBrush(_alpha(MANDREL_COLOUR, 170)))
        p.drawPolygon(QPolygonF([self.to_pixels(q) for q in hull]))
        n = pts.shape[0] // 2
        p.setBrush(QBrush(_alpha(MANDREL_COLOUR, 220)))
        p.drawPolygon(self._poly(pts[n:] if behind else pts[:n]))
        if not behind:
            headstock()
        # spindle centre line (dash-dot) beyond both ends
        ext = 0.16 * sch.size
        p.setPen(QPen(QColor("#555"), 0.9, Qt.PenStyle.DashDotLine))
        p.drawLine(self.to_pixels(project(np.array([0, 0, z0 - ext]))),
                   self.to_pixels(project(np.array([0, 0, z1 + 0.5 * ext]))))

    def _draw_structure(self, p: QPainter, sch: Schematic) -> None:
        if sch.machine.kind == "robot":
            pen = QPen(QColor(STRUCTURE_COLOUR), 5.0)
            pen.setCapStyle(Qt.PenCapStyle.RoundCap)
            pen.setJoinStyle(Qt.PenJoinStyle.RoundJoin)
            p.setPen(pen)
            p.setBrush(Qt.BrushStyle.NoBrush)
            p.drawPolyline(QPolygonF([self.to_pixels(q) for q in sch.links]))
            p.setPen(QPen(QColor("#555"), 1.0))
            p.setBrush(QBrush(QColor("#cfcfcf")))
            b = self.to_pixels(sch.links[0])
            p.drawRect(QRectF(b.x() - 9, b.y() - 3, 18, 6))

    def _draw_axis(self, p: QPainter, sch: Schematic, g: AxisGlyph, boxes: list[QRectF]) -> None:
        hl = g.name == self.highlighted
        col = QColor(axis_colour(g.index))
        width = 3.4 if hl else 1.8
        if hl:   # a soft halo first
            halo = QPen(QColor(col.red(), col.green(), col.blue(), 70), 10.0)
            halo.setCapStyle(Qt.PenCapStyle.RoundCap)
            p.setPen(halo)
            p.setBrush(Qt.BrushStyle.NoBrush)
            self._axis_path(p, sch, g)
        pen = QPen(col, width)
        pen.setCapStyle(Qt.PenCapStyle.RoundCap)
        p.setPen(pen)
        p.setBrush(Qt.BrushStyle.NoBrush)
        anchor = self._axis_path(p, sch, g, heads=True, colour=col, width=width)
        f = QFont(p.font())
        f.setBold(hl)
        p.setFont(f)
        self._label(p, g.label, anchor, boxes, col)
        f.setBold(False)
        p.setFont(f)

    def _axis_path(self, p: QPainter, sch: Schematic, g: AxisGlyph, heads: bool = False,
                   colour: QColor | None = None, width: float = 1.8) -> QPointF:
        """Draw the axis's line/arc (and arrow heads); return where its label goes."""
        if g.type == "linear":
            e = self._linear_ends(g, sch)
            a, b = self.to_pixels(project(e[0])), self.to_pixels(project(e[1]))
            p.drawLine(a, b)
            if heads:
                self._head(p, a, b, colour, width)
                self._head(p, b, a, colour, width)
                o = self.to_pixels(g.origin)      # the slide's saddle at the neutral pose
                p.save()
                p.setPen(QPen(colour.darker(130), 1.0))
                p.setBrush(QBrush(colour.lighter(150)))
                p.drawRect(QRectF(o.x() - 5, o.y() - 4, 10, 8))
                p.restore()
            # the label goes to the free end: the one farther from the other slides' saddles
            others = [self.to_pixels(o.origin) for o in sch.axes if o.type == "linear" and o is not g]
            if not others:
                return b

            def clearance(pt: QPointF) -> float:
                return min(math.hypot(pt.x() - o.x(), pt.y() - o.y()) for o in others)

            return b if clearance(b) >= clearance(a) - 1.0 else a
        arc = _circle3(g.origin3, g.dir3, self._arc_radius(g), 0.0, 1.6 * math.pi)
        poly = self._poly(arc)
        p.drawPolyline(poly)
        if heads:
            self._head(p, poly[-1], poly[-4], colour, width)
            # the rotation axis itself, dash-dot, through the arc
            half = 1.5 * self._arc_radius(g) * g.dir3
            ax = np.array([g.origin3 - half, g.origin3 + half])
            pen = QPen(colour, 0.9, Qt.PenStyle.DashDotLine)
            p.save()
            p.setPen(pen)
            p.drawPolyline(self._poly(ax))
            p.restore()
        top = max(range(poly.size()), key=lambda i: -poly[i].y())
        return QPointF(poly[top].x(), poly[top].y() - 2)

    def _arc_radius(self, g: AxisGlyph) -> float:
        """A rotary glyph's arc radius, mm, at least 10 px on screen."""
        return max(g.radius, 10.0 / max(self._map[0], 1e-9))

    @staticmethod
    def _head(p: QPainter, tip: QPointF, frm: QPointF, colour: QColor | None, width: float) -> None:
        dx, dy = tip.x() - frm.x(), tip.y() - frm.y()
        n = math.hypot(dx, dy)
        if n < 1e-6 or colour is None:
            return
        ux, uy = dx / n, dy / n
        size = 6.0 + width
        path = QPainterPath(tip)
        path.lineTo(tip.x() - size * ux + 0.5 * size * uy, tip.y() - size * uy - 0.5 * size * ux)
        path.lineTo(tip.x() - size * ux - 0.5 * size * uy, tip.y() - size * uy + 0.5 * size * ux)
        path.closeSubpath()
        p.save()
        p.setPen(Qt.PenStyle.NoPen)
        p.setBrush(QBrush(colour))
        p.drawPath(path)
        p.restore()

    def _label(self, p: QPainter, text: str, at: QPointF, boxes: list[QRectF], colour: QColor) -> None:
        """Queue label ``text`` for the point ``at``; :meth:`_draw_labels` places and draws them all."""
        fm = QFontMetricsF(p.font())
        self._queued.append((text, QPointF(at), QColor(colour), QFont(p.font()),
                             fm.horizontalAdvance(text) + 4, fm.height()))

    def _draw_labels(self, p: QPainter, obstacles: list[QRectF]) -> None:
        """Place the queued labels (:func:`place_labels`: none overlaps another or an obstacle such as
        the eye, all inside the widget) and draw them, with a leader line when moved off their point."""
        q = self._queued
        anchors = [(a.x(), a.y()) for _t, a, _c, _f, _w, _h in q]
        sizes = [(w, h) for *_x, w, h in q]
        obs = [(r.left(), r.top(), r.width(), r.height()) for r in obstacles]
        rects = place_labels(anchors, sizes, obs, (self.width(), self.height()))
        self.label_rects = {}
        for (text, at, colour, font, _w, _h), (x, y, w, h) in zip(q, rects, strict=True):
            rect = QRectF(x, y, w, h)
            self.label_rects[text] = rect
            p.save()
            p.setFont(font)
            near = QPointF(min(max(at.x(), rect.left()), rect.right()), min(max(at.y(), rect.top()), rect.bottom()))
            if math.hypot(near.x() - at.x(), near.y() - at.y()) > 6.0:  # a leader line from its point
                p.setPen(QPen(_alpha(colour.name(), 150), 0.8))
                p.drawLine(at, near)
            p.setPen(Qt.PenStyle.NoPen)
            p.setBrush(QBrush(QColor(255, 255, 255, 215)))
            p.drawRect(rect)
            p.setPen(colour.darker(115))
            p.drawText(rect, Qt.AlignmentFlag.AlignCenter, text)
            p.restore()
        self._queued = []

    def mousePressEvent(self, ev: Any) -> None:  # noqa: N802 - Qt API
        if self.schematic is None:
            return
        pos = ev.position()
        best, dist = None, 14.0
        for g in self.schematic.axes:
            if g.type == "linear":
                e = self._linear_ends(g, self.schematic)
                pts = project(np.linspace(e[0], e[1], 20))
            else:
                pts = project(_circle3(g.origin3, g.dir3, self._arc_radius(g), 0, 2 * math.pi, 24))
            for q in pts:
                px = self.to_pixels(q)
                d = math.hypot(px.x() - pos.x(), px.y() - pos.y())
                if d < dist:
                    best, dist = g.name, d
        if best is not None:
            self.axis_clicked.emit(best)
