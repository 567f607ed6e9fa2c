"""What the main window shows when a mandrel build (open, new, import, edit, undo, restore) ends."""

from __future__ import annotations

import sys
from typing import TYPE_CHECKING, Any

from engine.errors import InputError
from engine.job import PointsSpec, SegmentsSpec
from winder_gui import window_menus
from winder_gui.i18n import QT_TR_NOOP, tr
from winder_gui.panels.segments_table import segment_handles

if TYPE_CHECKING:
    from winder_gui.main_window import MainWindow

BUILD_ERROR_TITLES = {"open": QT_TR_NOOP("Could not open the job"),
                      "import": QT_TR_NOOP("Could not import the generatrix"),
                      "new": QT_TR_NOOP("Could not create a job"),
                      "restore": QT_TR_NOOP("Could not restore the autosaved job"),
                      "undo": QT_TR_NOOP("Could not undo")}


def on_built(w: MainWindow, purpose: str, res: Any) -> None:
    old_kind = w.job.mandrel.kind
    fresh = w.doc.commit_build(res, purpose)
    if fresh:
        w.ctl.clear()
        w.results.clear()
        if purpose == "open":
            window_menus.rebuild_recent_menu(w)
    if purpose != "edit":  # the panel already shows what the user typed
        w.mandrel_panel.set_spec(res.job.mandrel)
    else:
        w.mandrel_panel.clear_errors()
    w.mandrel_panel.spec = res.job.mandrel
    w.mandrel_panel.hint = (res.mandrel.r_max, res.mandrel.length)
    w.mandrel_panel.show_built(res.mandrel)
    reset = purpose in ("open", "new", "import", "restore")
    w.plot.set_data(res.data, sketch=isinstance(res.job.mandrel, PointsSpec), reset_view=reset)
    if isinstance(res.job.mandrel, SegmentsSpec):
        hz, hr, _ = segment_handles(res.job.mandrel)
        w.plot.set_segment_handles(hz, hr)
    w.plot.show_message("")
    w.view3d.set_data(res.data, reset_camera=reset)
    w.machine_panel.set_mandrel(res.mandrel)   # the Machine step's schematic draws the part and its supports
    m = res.mandrel
    zones = len(res.data.concave)
    w.summary_label.setText(
        tr("L {length:.1f} mm · r {r_min:.1f}…{r_max:.1f} mm · poles {v3:.1f}/{v4:.1f} mm · {zones} "
           "concave zone{v6}")
        .format(length=m.length, r_min=m.r_min, r_max=m.r_max, v3=m.pole_radii[0], v4=m.pole_radii[1], zones=zones,
                v6='s' if zones != 1 else ''))
    spec = res.job.mandrel
    w._status({"open": tr("Opened {path}").format(path=res.path), "new": tr("New job"),
                  "import": tr("Imported the generatrix from {v0}").format(v0=getattr(spec, 'path', '')),
                  "restore": tr("Restored the autosaved copy of {name} (not saved yet)").format(name=res.job.name)}.get(
        purpose,
        f"The mandrel is now a sketched generatrix (kind \"points\", {len(getattr(spec, 'z_mm', []))} points); "
        f"it was a \"{old_kind}\" template" if purpose == "points" and old_kind != "points" else "Mandrel updated"))
    if fresh:
        w.job_loaded.emit()
    w.mandrel_updated.emit(res.data)
    w._update_run_state()
    if not fresh:
        w.ctl.after_edit()


def on_build_failed(w: MainWindow, purpose: str, exc: BaseException, tb: str) -> None:
    if not isinstance(exc, InputError):
        print(tb, file=sys.stderr)
    w._update_run_state()
    if purpose in ("edit", "points") and isinstance(exc, InputError):
        if purpose == "edit":
            w.mandrel_panel.show_error(exc.location.field, exc.message)
            w._update_run_state()
        else:
            w.plot.revert_points()
            w.plot.show_message(tr("Not applied: {message}").format(message=exc.message))
        w._status(tr("Not applied: {message}").format(message=exc.message), error=True)
        w.error_reported.emit(exc.message)
        return
    w.report_dialog(tr(BUILD_ERROR_TITLES.get(purpose, QT_TR_NOOP("Error"))), exc)
    if w.mandrel is not None:
        w.mandrel_panel.set_spec(w.job.mandrel)
