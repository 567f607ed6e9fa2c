"""Laminate benchmark (issue 14): a 10-layer vessel, 2000 points per pass, `winder run` end to end, then an edit
of the last layer re-run with the previous result (target: < 15 s, and the edit < 20 % of that).

Prints the wall times, their ratio to the targets, the per-layer times, and the volume check.
Run: python benchmarks/bench_laminate.py
"""

from __future__ import annotations

import time

from engine.job import parse_job
from engine.laminate import run_laminate

JOB = """schema_version = 2
name = "10-layer vessel"
[mandrel]
kind = "vessel"
radius_mm = 100.0
cylinder_length_mm = 300.0
dome = "isotensoid"
pole_radius_mm = [25.0, 40.0]
[band]
width_mm = 8.0
thickness_mm = 0.3
friction = 0.2
material = "carbon T700 / epoxy"
[winding]
points_per_pass = 2000
[machine]
template = "lathe4"
""" + "".join(
    f"\n[[layer]]\n{body}\n"
    for body in (
        'kind = "polar"\nname = "polar 1"',
        'kind = "hoop"\nname = "hoop 1"\npasses = 2',
        'kind = "helical"\nname = "helical 40"\nangle_deg = 40.0\nclose_by = "angle"',
        'kind = "hoop"\nname = "hoop 2"',
        'kind = "helical"\nname = "helical 50"\nangle_deg = 50.0\nclose_by = "angle"',
        'kind = "hoop"\nname = "hoop 3"',
        'kind = "skip"\nangle_deg = 90.0',
        'kind = "helical"\nname = "helical 60"\nangle_deg = 60.0\nclose_by = "angle"',
        'kind = "hoop"\nname = "hoop 4"',
        'kind = "hoop"\nname = "hoop 5"\nterminal = true',
    )
)

TARGET_S = 15.0


def main() -> None:
    job = parse_job(JOB)
    t0, c0 = time.perf_counter(), time.process_time()
    res = run_laminate(job)
    full, cpu = time.perf_counter() - t0, time.process_time() - c0
    lay = res.layup()
    for r in lay["layers"]:
        lr = res.layer(r["index"] - 1)
        st = lr.result.stage_times if lr.result is not None else {}
        print(f"  layer {r['index']:>2} {r['name']:<12} {r['kind']:<8} program {r['time_s']:8.1f} s  "
              f"fibre {r['fibre_length_m']:7.2f} m  t_cyl {r['thickness_cyl_mm']:.3f} mm  compute "
              + " ".join(f"{k} {v:.2f}" for k, v in st.items() if v > 0.005))
    print("stage times (s): " + ", ".join(f"{k} {v:.2f}" for k, v in res.stage_times.items()))
    print(f"10-layer vessel run: {full:.2f} s wall, {cpu:.2f} s CPU (target {TARGET_S:.0f} s wall): ratio "
          f"{full / TARGET_S:.3f} (CPU {cpu / TARGET_S:.3f}; the CPU ratio is the one to trust on a loaded machine)")
    print(f"volume laid {lay['volume_laid_mm3']:.6g} mm3, between surfaces {lay['volume_between_surfaces_mm3']:.6g} "
          f"mm3: error {100 * lay['volume_error']:+.3f} %")
    last = job.layers[-1]
    edited = job.model_copy(update={"layers": [*job.layers[:-1], last.model_copy(update={"overlap": 0.2})]})
    t0 = time.perf_counter()
    res2 = run_laminate(edited, previous=res)
    edit = time.perf_counter() - t0
    print(f"edit of the last layer: {edit:.2f} s wall, {len(res2.reused)} layers re-used: "
          f"{100 * edit / full:.1f} % of the full run (target < 20 %)")


if __name__ == "__main__":
    main()
