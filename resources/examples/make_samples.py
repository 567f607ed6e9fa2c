"""Regenerate the sample mandrel input files in this folder.

Run from the repository root::

    .venv/bin/python resources/examples/make_samples.py

* ``bottle_profile.csv``: a generatrix table (z_mm, r_mm) of ``Mandrel.bottle()``.
* ``vessel_profile.dxf``: a vessel profile drawn with an ARC (hemispherical dome), a LINE
  (cylinder), a SPLINE (elliptical dome), end-face LINEs and an axis LINE, x = axial z, y = radius.
* ``vessel.step``: the solid of ``Mandrel.vessel(60, 120, dome="ellipse", dome_ratio=0.7,
  pole_radii=15)`` revolved about Z.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parents[1]))

from engine.fileio import atomic_write_text, atomic_write_with  # noqa: E402
from engine.mandrel import Mandrel  # noqa: E402
from engine.mandrel_io import export_step  # noqa: E402

# vessel profile in the DXF (mm)
R = 60.0  # cylinder radius
L = 120.0  # cylinder length
POLE_LEFT = 15.0  # hemispherical dome at z < 0
POLE_RIGHT = 20.0  # elliptical dome at z > L
ELLIPSE_A = 40.0  # axial semi-axis of the right dome


def make_csv(path: Path) -> None:
    m = Mandrel.bottle()
    bottom = m.segments[0]  # elliptical bottom: points uniform in the ellipse angle (steep near the pole)
    t = np.linspace(math.acos((bottom.z0 - bottom.zc) / bottom.a), 0.5 * math.pi, 41)
    z = np.concatenate([bottom.zc + bottom.a * np.cos(t), np.linspace(0.0, m.z_max, 161)[1:]])
    r = m.r(z)
    lines = [
        "# winder sample: generatrix of Mandrel.bottle() (elliptical bottom, body, waisted neck)",
        "# z along the axis, r the radius, both in mm; the first and last rows are the pole openings",
        "z_mm,r_mm",
    ]
    lines += [f"{a:.6f},{b:.6f}" for a, b in zip(z, r)]
    atomic_write_text(path, "\n".join(lines) + "\n")


def make_dxf(path: Path) -> None:
    import ezdxf
    from scipy.interpolate import make_interp_spline

    doc = ezdxf.new("R2010")
    doc.header["$INSUNITS"] = 4  # mm
    doc.layers.add("PROFILE", color=1)
    doc.layers.add("AXIS", color=5)
    msp = doc.modelspace()
    # left hemispherical dome: arc centred on the axis at z = 0, from the pole opening to the cylinder
    t0 = math.degrees(math.pi - math.asin(POLE_LEFT / R))
    msp.add_arc((0.0, 0.0), R, 90.0, t0, dxfattribs={"layer": "PROFILE"})
    msp.add_line((0.0, R), (L, R), dxfattribs={"layer": "PROFILE"})
    # right elliptical dome as an interpolating cubic B-spline r(z), slope 0 at the cylinder
    zr = L + ELLIPSE_A * math.sqrt(1.0 - (POLE_RIGHT / R) ** 2)
    u = np.linspace(0.0, 1.0, 41)
    z = L + (zr - L) * np.sin(0.5 * math.pi * u)  # denser near the pole
    r = R * np.sqrt(np.clip(1.0 - ((z - L) / ELLIPSE_A) ** 2, 0.0, None))
    uz = (zr - L) / ELLIPSE_A
    slope_pole = -R * uz / (ELLIPSE_A * math.sqrt(1.0 - uz * uz))
    bs = make_interp_spline(z, r, k=3, bc_type=([(1, 0.0)], [(1, slope_pole)]))
    greville = [float(np.mean(bs.t[i + 1: i + 4])) for i in range(len(bs.c))]
    msp.add_open_spline([(g, float(c)) for g, c in zip(greville, bs.c)], degree=3, knots=list(map(float, bs.t)),
                        dxfattribs={"layer": "PROFILE"})
    # end faces and axis (dropped by the importer)
    zl = -math.sqrt(R * R - POLE_LEFT**2)
    msp.add_line((zl, 0.0), (zl, POLE_LEFT), dxfattribs={"layer": "PROFILE"})
    msp.add_line((zr, POLE_RIGHT), (zr, 0.0), dxfattribs={"layer": "PROFILE"})
    msp.add_line((zr, 0.0), (zl, 0.0), dxfattribs={"layer": "PROFILE"})
    msp.add_text("winder sample vessel profile: x = axial z, y = radius (mm)",
                 dxfattribs={"layer": "AXIS", "height": 3.0}).set_placement((zl, -10.0))
    atomic_write_with(path, lambda tmp: doc.saveas(tmp))


def make_step(path: Path) -> None:
    export_step(Mandrel.vessel(60.0, 120.0, dome="ellipse", dome_ratio=0.7, pole_radii=15.0, name="vessel"), path)


def main() -> None:
    make_csv(HERE / "bottle_profile.csv")
    make_dxf(HERE / "vessel_profile.dxf")
    make_step(HERE / "vessel.step")
    for name in ("bottle_profile.csv", "vessel_profile.dxf", "vessel.step"):
        print(f"{name}: {(HERE / name).stat().st_size} bytes")


if __name__ == "__main__":
    main()
