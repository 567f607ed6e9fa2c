"""Render ``resources/icons/winder.svg`` to PNG with Qt's SVG renderer.

The PNG is committed (PyInstaller converts it to ``.ico``/``.icns`` on Windows/macOS, and the
hicolor theme on Linux wants a bitmap too); run this again after editing the SVG::

    QT_QPA_PLATFORM=offscreen .venv/bin/python installer/render_icon.py
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

ICONS = Path(__file__).resolve().parents[1] / "resources" / "icons"


def render(svg: Path, png: Path, size: int) -> None:
    """Write ``svg`` rasterised to a ``size`` x ``size`` PNG with a transparent background."""
    from PySide6.QtCore import Qt
    from PySide6.QtGui import QGuiApplication, QImage, QPainter
    from PySide6.QtSvg import QSvgRenderer

    _app = QGuiApplication.instance() or QGuiApplication([sys.argv[0]])
    renderer = QSvgRenderer(str(svg))
    if not renderer.isValid():
        raise SystemExit(f"render_icon: {svg} is not a valid SVG")
    img = QImage(size, size, QImage.Format.Format_ARGB32)
    img.fill(Qt.GlobalColor.transparent)
    painter = QPainter(img)
    painter.setRenderHint(QPainter.RenderHint.Antialiasing)
    renderer.render(painter)
    painter.end()
    if not img.save(str(png)):
        raise SystemExit(f"render_icon: could not write {png}")


def main() -> int:
    os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
    render(ICONS / "winder.svg", ICONS / "winder.png", 256)
    print(f"wrote {ICONS / 'winder.png'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
