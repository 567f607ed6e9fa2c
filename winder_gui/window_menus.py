"""Menus, toolbar and the dialogs of the main window's commands (open/save/export file choosers,
About, keyboard shortcuts, tool dialogs).  The commands themselves are methods of the window."""

from __future__ import annotations

import importlib
from pathlib import Path
from typing import TYPE_CHECKING, Any

from PySide6.QtCore import Qt
from PySide6.QtGui import QAction, QKeySequence
from PySide6.QtWidgets import QFileDialog, QMessageBox, QToolBar, QWidget

from engine import __version__
from winder_gui.autosave import autosave_origin
from winder_gui.i18n import QT_TR_NOOP, tr
from winder_gui.panels.steps import STEPS
from winder_gui.settings import apply_memory_budget, recent_files, set_memory_budget

if TYPE_CHECKING:
    from winder_gui.main_window import MainWindow

NC_FILTER = QT_TR_NOOP("NC programs (*.ngc *.nc *.gcode *.mpf *.csv *.txt);;All files (*)")
JOB_FILTER = QT_TR_NOOP("Winding jobs (*.toml);;All files (*)")
PROFILE_FILTER = QT_TR_NOOP("Generatrix profiles (*.csv *.txt *.dxf *.step *.stp);;All files (*)")
EXPORT_FILTER = QT_TR_NOOP("STEP solid (*.step *.stp);;STL mesh (*.stl)")
REPORT_FILTER = QT_TR_NOOP("PDF report (*.pdf);;HTML report (*.html)")


def build_menus(w: MainWindow) -> None:
    """The menu bar; every command is also in ``w.actions`` by key."""
    mb = w.menuBar()
    w.menu_file = mb.addMenu(tr("&File"))
    w.actions = {}

    def add(menu: Any, key: str, text: str, slot: Any, shortcut: Any = None) -> QAction:
        act = QAction(text, w)
        if shortcut is not None:
            act.setShortcut(QKeySequence(shortcut))
        act.triggered.connect(slot)
        menu.addAction(act)
        w.actions[key] = act
        return act

    f = w.menu_file
    add(f, "new", tr("&New"), w.action_new, QKeySequence.StandardKey.New)
    add(f, "open", tr("&Open…"), lambda: action_open(w), QKeySequence.StandardKey.Open)
    w.menu_recent = f.addMenu(tr("Open &Recent"))
    add(f, "save", tr("&Save"), lambda: w.save_job(), QKeySequence.StandardKey.Save)
    add(f, "save_as", tr("Save &As…"), w._action_save_as, QKeySequence.StandardKey.SaveAs)
    f.addSeparator()
    add(f, "import", tr("&Import generatrix…"), lambda: action_import(w), "Ctrl+I")
    add(f, "export", tr("&Export mandrel…"), lambda: action_export_mandrel(w), "Ctrl+E")
    add(f, "export_nc", tr("Export &NC program…"), w.action_export_nc, "Ctrl+Shift+E")
    add(f, "export_plot", tr("Export current &plot…"), lambda: action_export_plot(w), "Ctrl+Shift+P")
    add(f, "open_nc", tr("Open NC program (read back)…"), lambda: action_open_nc(w), "Ctrl+Shift+O")
    add(f, "export_report", tr("Export/print &report (PDF, HTML)…"), w.action_export_report, "Ctrl+P")
    f.addSeparator()
    add(f, "quit", tr("&Quit"), w.close, QKeySequence.StandardKey.Quit)

    w.menu_edit = mb.addMenu(tr("&Edit"))
    undo = w.undo_stack.createUndoAction(w, tr("&Undo"))
    undo.setShortcut(QKeySequence.StandardKey.Undo)
    redo = w.undo_stack.createRedoAction(w, tr("&Redo"))
    redo.setShortcuts([QKeySequence.StandardKey.Redo, QKeySequence("Ctrl+Shift+Z")])
    w.menu_edit.addAction(undo)
    w.menu_edit.addAction(redo)
    w.actions["undo"], w.actions["redo"] = undo, redo

    w.menu_run = mb.addMenu(tr("&Run"))
    add(w.menu_run, "run", tr("&Run pipeline"), lambda: w.run_pipeline_now(), "F5")
    add(w.menu_run, "cancel", tr("&Cancel"), w.cancel_run, "Esc")
    add(w.menu_run, "timelaw", tr("Compute &time law"), w.compute_timelaw, "F6")
    auto = add(w.menu_run, "auto_run", tr("Re-run &automatically after edits"), w._toggle_auto_run)
    auto.setCheckable(True)
    auto.setChecked(True)

    w.menu_view = mb.addMenu(tr("&View"))
    for i, (key, title) in enumerate(STEPS):
        add(w.menu_view, f"step_{key}", f"&{i + 1} {tr(title)}", lambda _c=False, k=key: w.go_to_step(k),
            f"Ctrl+{i + 1}")
    w.menu_view.addSeparator()
    add(w.menu_view, "play", tr("&Play / pause the winding"), w._toggle_play, "Space")
    machine = add(w.menu_view, "show_machine", tr("Show the &machine in 3D (carriage, head)"),
                  lambda on: w.view3d.set_machine_visible(on))
    machine.setCheckable(True)
    machine.setChecked(True)
    if getattr(w, "view3d", None) is not None:   # the action follows the 3D view's box
        w.view3d.machine_check.toggled.connect(machine.setChecked)

    w.menu_tools = mb.addMenu(tr("&Tools"))
    add(w.menu_tools, "turning", tr("&Turning optimiser…"),
        lambda: open_tool(w, "turning", "winder_gui.dialogs.turning", "TurningDialog"))
    add(w.menu_tools, "slotting", tr("&Slot forming…"),
        lambda: open_tool(w, "slotting", "winder_gui.dialogs.slotting", "SlotDialog"))
    w.menu_tools.addSeparator()
    add(w.menu_tools, "memory_budget", tr("&Memory budget…"), lambda: ask_memory_budget(w))
    apply_memory_budget()

    w.menu_help = mb.addMenu(tr("&Help"))
    add(w.menu_help, "shortcuts", tr("&Keyboard shortcuts"), lambda: show_box(w, "shortcuts", tr("Keyboard shortcuts"),
                                                                          shortcuts_text(w)), "F1")
    add(w.menu_help, "about", tr("&About winder"), lambda: show_box(
        w, "about", tr("About winder"),
            tr("<b>winder {__version__}</b><br>Open CAD/CAM for filament winding:<br>mandrel → "
               "winding line → payout eye → machine axes → NC.<br><br>GPL-3.0-or-later")
            .format(__version__=__version__),
        QMessageBox.Icon.Information))


def build_toolbar(w: MainWindow) -> None:
    tb = QToolBar("Main")
    tb.setObjectName("mainToolbar")
    tb.setMovable(False)
    for key in ("new", "open", "save", None, "undo", "redo", None, "run", "cancel", "export_nc"):
        if key is None:
            tb.addSeparator()
        else:
            tb.addAction(w.actions[key])
    w.toolbar = tb
    w.addToolBar(tb)
    rebuild_recent_menu(w)


def rebuild_recent_menu(w: MainWindow) -> None:
    w.menu_recent.clear()
    rec = recent_files()
    for i, p in enumerate(rec):
        act = w.menu_recent.addAction(f"&{i + 1} {Path(p).name}")
        act.setToolTip(p)
        act.triggered.connect(lambda _c=False, path=p: w._may_discard() and w.open_job(path))
    w.menu_recent.setEnabled(bool(rec))


def show_box(w: MainWindow, key: str, title: str, text: str,
             icon: QMessageBox.Icon = QMessageBox.Icon.NoIcon) -> None:
    box = QMessageBox(icon, title, text, QMessageBox.StandardButton.Ok, w)
    box.setAttribute(Qt.WidgetAttribute.WA_DeleteOnClose)
    box.open()
    w.dialogs[key] = box


def shortcuts_text(w: MainWindow) -> str:
    """Every menu command with a keyboard shortcut, as an HTML table."""
    rows = []
    for act in w.actions.values():
        keys = ", ".join(k.toString(QKeySequence.SequenceFormat.NativeText) for k in act.shortcuts())
        if keys:
            rows.append(f"<tr><td><b>{keys}</b></td><td>{act.text().replace('&', '').rstrip('…')}</td></tr>")
    return "<table cellspacing=4>" + "".join(rows) + "</table>"


def open_tool(w: MainWindow, key: str, module: str, cls_name: str) -> QWidget | None:
    """Open a tool dialog ``module.cls_name(parent)`` (imported lazily); a message if unavailable."""
    dlg = w.dialogs.get(key)
    if dlg is not None:
        try:
            dlg.show()
            dlg.raise_()
            return dlg
        except RuntimeError:  # deleted by Qt
            w.dialogs.pop(key, None)
    try:
        cls = getattr(importlib.import_module(module), cls_name)
        dlg = cls(w)
    except Exception as exc:  # noqa: BLE001 - a tool that cannot load must not take the app down
        w.report_dialog(tr("Tool not available"), f"{cls_name} could not be loaded ({type(exc).__name__}: {exc}).")
        return None
    w.dialogs[key] = dlg
    dlg.show()
    return dlg


def action_open(w: MainWindow) -> None:
    if not w._may_discard():
        return
    path, _ = QFileDialog.getOpenFileName(w, tr("Open job"), str(w.doc.start_dir()), tr(JOB_FILTER))
    if path:
        w.open_job(path)


def action_open_nc(w: MainWindow) -> None:
    path, _ = QFileDialog.getOpenFileName(w, tr("Open NC program (read back on the job's machine)"),
                                          str(w.doc.start_dir()), tr(NC_FILTER))
    if path:
        w.open_nc(path)


def ask_save_path(w: MainWindow) -> str:
    start = str(w.job_path) if w.job_path else str(w.doc.start_dir() / "job.toml")
    path, _ = QFileDialog.getSaveFileName(w, tr("Save job as"), start, tr(JOB_FILTER))
    return path


def action_import(w: MainWindow) -> None:
    path, _ = QFileDialog.getOpenFileName(w, tr("Import generatrix"), str(w.doc.start_dir()), tr(PROFILE_FILTER))
    if path:
        w.import_generatrix(path)
    else:
        w.mandrel_panel.set_spec(w.job.mandrel)


def action_export_mandrel(w: MainWindow) -> None:
    stem = w.job_path.stem if w.job_path else "mandrel"
    path, _ = QFileDialog.getSaveFileName(w,
        tr("Export mandrel"), str(w.doc.start_dir() / f"{stem}.step"), tr(EXPORT_FILTER))
    if path:
        w.export_mandrel(path)


def ask_nc_path(w: MainWindow, extension: str) -> str:
    path, _ = QFileDialog.getSaveFileName(w, tr("Export NC program"),
                                          str(w.doc.start_dir() / f"{w.doc.file_stem()}{extension}"), tr(NC_FILTER))
    return path


def ask_report_path(w: MainWindow) -> str:
    path, _ = QFileDialog.getSaveFileName(w, tr("Export job report"),
                                          str(w.doc.start_dir() / f"{w.doc.file_stem()}-report.pdf"), tr(REPORT_FILTER))
    return path


def action_export_plot(w: MainWindow) -> None:
    page = w.plot_tabs.currentWidget()
    if hasattr(page, "_ask_export"):
        page._ask_export()


def offer_autosaves(w: MainWindow) -> None:
    """Ask, for each leftover autosave copy, whether to restore it (the first accepted is loaded).

    A copy is locked while the question is open, so two instances starting together never both
    restore or delete it; the live copies of other running instances are not offered.
    """
    owner = w.doc.autosave_owner
    for p in w.pending_autosaves():
        owned = owner.holds(p)
        if not owned and not owner.claim(p):
            continue  # another instance took it meanwhile
        origin = autosave_origin(p)
        ans = QMessageBox.question(
            w, tr("Restore autosaved job?"),
            tr("winder found unsaved changes from an earlier session:\n{name}").format(name=p.name)
            + (tr(" (job {origin})")
               .format(origin=origin) if origin else tr(" (never saved)")) + tr("\n\nRestore them?"),
            QMessageBox.StandardButton.Yes | QMessageBox.StandardButton.Discard | QMessageBox.StandardButton.Ignore,
            QMessageBox.StandardButton.Yes)
        if ans == QMessageBox.StandardButton.Yes:
            w.restore_autosave(p)
            return
        if ans == QMessageBox.StandardButton.Discard:
            try:
                p.unlink(missing_ok=True)
            except OSError as exc:
                w._status(tr("Could not delete the autosaved copy {p}: {exc}").format(p=p, exc=exc), error=True)
        if not owned:
            owner.release(p)


def ask_memory_budget(w: MainWindow) -> None:
    """Tools → Memory budget: the largest job the engine accepts (engine.budget), kept in the settings."""
    from PySide6.QtWidgets import QInputDialog

    from engine import budget
    from engine.errors import InputError

    cur = budget.fmt_bytes(budget.max_memory_bytes()).replace(" ", "")
    text, ok = QInputDialog.getText(
        w, tr("Memory budget"),
        tr("Largest memory a computation may use (e.g. 4G, 12G; empty = the default {v0}).\nLarger "
           "jobs are refused before they start.").format(v0=budget.fmt_bytes(budget.DEFAULT_MAX_MEMORY_BYTES)),
        text=cur)
    if not ok:
        return
    try:
        n = set_memory_budget(text)
    except InputError as exc:
        w._report_dialog("Memory budget", exc)
        return
    w.statusBar().showMessage(tr("Memory budget {v0}").format(v0=budget.fmt_bytes(n)), 5000)
