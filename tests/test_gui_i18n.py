"""Every user-visible text of the GUI goes through Qt's translation (issue 18, point 5).

An AST scan of ``winder_gui/``: a string literal (or f-string) with words in it, handed to a Qt text
API (widget constructors, setText, setWindowTitle, addAction, setToolTip, setHeaderLabels, message
boxes, file dialogs, plot titles and labels, ...) or to a local helper that forwards it there, must
be wrapped in ``winder_gui.i18n.tr``; a module constant with texts must be marked ``QT_TR_NOOP`` and
passed through ``tr`` where shown.  A run-time check then installs a pseudo-translator that brackets
every text it is asked for and reads back what the main window shows: menus, actions, buttons,
labels, tooltips, headers, tabs.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
GUI = ROOT / "winder_gui"

# Qt / pyqtgraph text APIs: name -> argument positions that carry text (None: every positional argument)
_ALL = None
TEXT_CALLS: dict[str, tuple[int, ...] | None] = {
    # constructors
    "QLabel": (0,), "QPushButton": (0,), "QToolButton": (0,), "QCheckBox": (0,), "QRadioButton": (0,),
    "QGroupBox": (0,), "QAction": (0,), "QMenu": (0,), "QTableWidgetItem": (0,), "QListWidgetItem": (0,),
    "QTreeWidgetItem": _ALL, "QMessageBox": (1, 2), "QProgressDialog": (0, 1), "QDockWidget": (0,),
    "QCommandLinkButton": (0, 1), "TextItem": (0,), "LabelItem": (0,), "QToolBar": (),
    # setters
    "setText": (0,), "setWindowTitle": (0,), "setToolTip": (0,), "setStatusTip": (0,), "setWhatsThis": (0,),
    "setHeaderLabels": (0,), "setHorizontalHeaderLabels": (0,), "setVerticalHeaderLabels": (0,),
    "setPlaceholderText": (0,), "setTitle": (0,), "setTabText": (1,), "setTabToolTip": (1,),
    "setLabelText": (0,), "setSuffix": (0,), "setPrefix": (0,), "setSpecialValueText": (0,),
    "setItemText": (1,), "setInformativeText": (0,), "setDetailedText": (0,), "setHtml": (0,),
    "setCancelButtonText": (0,), "setButtonText": (1,), "setNameFilter": (0,), "setNameFilters": (0,),
    "setLabel": (1,), "setLabels": _ALL, "showMessage": (0,), "setFormat": (0,),
    # adders
    "addAction": (0,), "addMenu": (0,), "addTab": (1,), "insertTab": (2,), "addRow": (0,), "insertRow": (1,),
    "addItem": (0,), "addItems": (0,), "insertItem": (1,), "insertItems": (1,), "addButton": (0,),
    "addSection": (0,), "createUndoAction": (1,), "createRedoAction": (1,),
    # static dialogs (parent, title, text/caption, ...)
    "information": (1, 2), "warning": (1, 2), "critical": (1, 2), "question": (1, 2), "about": (1, 2),
    "getOpenFileName": (1, 3), "getSaveFileName": (1, 3), "getExistingDirectory": (1,),
    "getText": (1, 2), "getItem": (1, 2), "getDouble": (1, 2), "getInt": (1, 2),
}
TEXT_KEYWORDS: dict[str, tuple[str, ...]] = {
    # pyqtgraph legend names and plot titles
    "plot": ("name", "title"), "PlotDataItem": ("name",), "ScatterPlotItem": ("name",),
    "PlotCurveItem": ("name",), "BarGraphItem": ("name",), "addPlot": ("title",), "PlotWidget": ("title",),
    "PlotItem": ("title",), "setLabel": ("text",), "TextItem": ("text",), "addLegend": (),
}
TR_NAMES = {"tr", "translate"}
WORDS = re.compile(r"[A-Za-z\u00c0-\uffff]{2,}")
# Strings that are not texts although a text API receives them (a short, explicit list).
ALLOWED = {
    "Main",          # QToolBar's window title, never shown (the tool bar cannot be moved or floated)
    "winder",        # the program's name
}


DATA_CONSTANTS = {
    "DOMES",   # dome kinds of the job file ([mandrel] dome = "hemisphere" ...), listed as they are written
    "TYPES",   # segment types of a sketched generatrix (line, arc, ...), as written in the job file
}


def _is_texty(s: str) -> bool:
    return bool(WORDS.search(re.sub(r"<[^>]*>", "", s))) and s.strip() not in ALLOWED


def _call_name(node: ast.Call) -> str:
    f = node.func
    return f.id if isinstance(f, ast.Name) else f.attr if isinstance(f, ast.Attribute) else ""


def _text_consts(tree: ast.Module) -> dict[str, ast.AST]:
    """Module-level NAME = <literal with texts> (not marked): their use as a text is a finding."""
    out: dict[str, ast.AST] = {}
    for st in tree.body:
        if isinstance(st, ast.Assign | ast.AnnAssign) and st.value is not None:
            targets = st.targets if isinstance(st, ast.Assign) else [st.target]
            for t in targets:
                if isinstance(t, ast.Name) and t.id.isupper() and t.id not in DATA_CONSTANTS:
                    out[t.id] = st.value
    return out


def _raw(node: ast.AST, consts: dict[str, ast.AST], seen: frozenset = frozenset()) -> list[ast.AST]:
    """The untranslated text literals inside the expression ``node``."""
    if isinstance(node, ast.Constant):
        return [node] if isinstance(node.value, str) and _is_texty(node.value) else []
    if isinstance(node, ast.JoinedStr):
        return [node] if any(isinstance(v, ast.Constant) and _is_texty(str(v.value)) for v in node.values) else []
    if isinstance(node, ast.Call):
        name = _call_name(node)
        if name in TR_NAMES:
            return []
        if name == "QT_TR_NOOP":  # marked but not translated where shown
            return [node]
        f = node.func
        return _raw(f.value, consts, seen) if isinstance(f, ast.Attribute) else []  # "...".format(), "".join()
    if isinstance(node, ast.Name | ast.Attribute):
        ident = node.id if isinstance(node, ast.Name) else node.attr
        if ident in consts and ident not in seen:
            return [node] if _raw(consts[ident], consts, seen | {ident}) else []
        return []
    if isinstance(node, ast.Lambda | ast.comprehension):
        return []
    if isinstance(node, ast.Dict):  # keys are not shown
        return [b for v in node.values if v is not None for b in _raw(v, consts, seen)]
    if isinstance(node, ast.Subscript):
        return _raw(node.value, consts, seen)
    if isinstance(node, ast.Compare):
        return []
    out: list[ast.AST] = []
    for ch in ast.iter_child_nodes(node):
        out += _raw(ch, consts, seen)
    return out


Sinks = dict[str, tuple[tuple[int, ...] | None, tuple[str, ...]]]


def _sink_args(node: ast.Call, sinks: Sinks) -> list[ast.AST]:
    name = _call_name(node)
    if name not in sinks:
        return []
    pos, kws = sinks[name]
    args = list(node.args) if pos is None else [node.args[i] for i in pos if i < len(node.args)]
    args += [k.value for k in node.keywords if k.arg in kws]
    return args


def _qt_sinks() -> Sinks:
    sinks: Sinks = {k: (v, TEXT_KEYWORDS.get(k, ())) for k, v in TEXT_CALLS.items()}
    for k, v in TEXT_KEYWORDS.items():
        sinks.setdefault(k, ((), v))
    return sinks


def _flows(node: ast.AST) -> list[ast.AST]:
    """The sub-expressions whose value ends up in the text ``node`` (not conditions, keys or indices)."""
    if isinstance(node, ast.IfExp):
        return _flows(node.body) + _flows(node.orelse)
    if isinstance(node, ast.BinOp):
        return _flows(node.left) + _flows(node.right)
    if isinstance(node, ast.JoinedStr):
        return [n for v in node.values if isinstance(v, ast.FormattedValue) for n in _flows(v.value)]
    if isinstance(node, ast.List | ast.Tuple | ast.Starred):
        elts = node.elts if not isinstance(node, ast.Starred) else [node.value]
        return [n for e in elts for n in _flows(e)]
    if isinstance(node, ast.Call):
        return [node] + [n for a in [*node.args, *(k.value for k in node.keywords)] for n in _flows(a)]
    return [node]


def _helper_sinks(trees: dict[Path, ast.Module]) -> dict[Path, Sinks]:
    """Per module: Qt's text APIs plus every function that hands one of its parameters to a text API
    (a function defined in the module hides its namesakes elsewhere)."""
    local: dict[Path, Sinks] = {p: {} for p in trees}
    defined = {p: {fn.name for fn in ast.walk(t) if isinstance(fn, ast.FunctionDef)} for p, t in trees.items()}
    glob: Sinks = {}

    def view(p: Path) -> Sinks:
        return {**_qt_sinks(), **{k: v for k, v in glob.items() if k not in defined[p]}, **local[p]}

    for _round in range(3):
        for p, tree in trees.items():
            sinks = view(p)
            for fn in ast.walk(tree):
                if not isinstance(fn, ast.FunctionDef) or fn.name.startswith("__"):
                    continue
                params = [a.arg for a in fn.args.args]
                kwarg = fn.args.kwarg.arg if fn.args.kwarg else None
                offset = 1 if params and params[0] in ("self", "cls") else 0
                hit: set[str] = set()
                kws: set[str] = set()
                for call in ast.walk(fn):
                    if not isinstance(call, ast.Call):
                        continue
                    for a in _sink_args(call, sinks):
                        for n in _flows(a):
                            if isinstance(n, ast.Name) and n.id in params:
                                hit.add(n.id)
                            if (kwarg and isinstance(n, ast.Call) and isinstance(n.func, ast.Attribute)
                                    and isinstance(n.func.value, ast.Name) and n.func.value.id == kwarg
                                    and n.func.attr in ("pop", "get") and n.args
                                    and isinstance(n.args[0], ast.Constant)):
                                kws.add(str(n.args[0].value))   # kw.pop("legend") handed to a text API
                    if kwarg and _call_name(call) in sinks and any(
                            k.arg is None and isinstance(k.value, ast.Name) and k.value.id == kwarg
                            for k in call.keywords):
                        kws |= set(sinks[_call_name(call)][1])  # **kw forwarded to a text API
                if hit or kws:
                    idx = tuple(sorted(params.index(q) - offset for q in hit if params.index(q) >= offset))
                    entry = (idx, tuple(sorted(hit | kws)))
                    local[p][fn.name] = entry
                    glob.setdefault(fn.name, entry)
    return {p: view(p) for p in trees}


def untranslated_texts(root: Path = GUI) -> list[str]:
    """``file:line: call: text`` for every literal text handed to Qt without ``tr``."""
    trees = {p: ast.parse(p.read_text("utf-8"), str(p)) for p in sorted(root.rglob("*.py"))}
    consts: dict[str, ast.AST] = {}
    for tree in trees.values():
        consts.update(_text_consts(tree))
    sinks = _helper_sinks(trees)
    found = []
    for p, tree in trees.items():
        for node in ast.walk(tree):
            if isinstance(node, ast.Call):
                for a in _sink_args(node, sinks[p]):
                    for b in _raw(a, consts):
                        where = f"{p.relative_to(root.parent)}:{b.lineno}"
                        found.append(f"{where}: {_call_name(node)}: {ast.unparse(b)[:80]}")
    return sorted(set(found))


def test_every_text_handed_to_qt_is_translatable() -> None:
    bad = untranslated_texts()
    assert not bad, f"{len(bad)} untranslated texts (wrap them in winder_gui.i18n.tr):\n" + "\n".join(bad)


def test_the_scan_finds_what_it_should(tmp_path: Path) -> None:
    """The scanner itself: it flags raw texts (directly, via a helper, via a constant) and passes tr()."""
    (tmp_path / "m.py").write_text(
        "from winder_gui.i18n import tr, QT_TR_NOOP\n"
        "TITLE = 'Open job'\n"
        "MARKED = QT_TR_NOOP('Save job')\n"
        "def add(menu, key, text):\n"
        "    menu.addAction(text)\n"
        "def build(w, x):\n"
        "    w.setWindowTitle('Raw title')\n"
        "    w.setToolTip(f'Raw {x} tip')\n"
        "    add(w, 'key_is_data', 'Raw via helper')\n"
        "    w.setText(TITLE)\n"
        "    w.setText(MARKED)\n"
        "    w.setText(tr(MARKED))\n"
        "    w.setText(tr('Fine'))\n"
        "    w.setText(tr('Fine {x}').format(x=x))\n"
        "    w.setObjectName('notAText')\n"
        "    w.setText(f'{x:.3f}')\n"
        "    w.plot([1], [2], name='Raw legend')\n")
    bad = untranslated_texts(tmp_path)
    texts = " ".join(bad)
    for raw in ("Raw title", "Raw {x} tip", "Raw via helper", ":10:", ":11:", "Raw legend"):
        assert raw in texts, (raw, bad)
    assert len(bad) == 6, bad
    assert "key_is_data" not in texts and "Fine" not in texts and "notAText" not in texts


def _shown_texts(root) -> list[tuple[str, str]]:  # noqa: ANN001 - a QWidget
    from PySide6.QtWidgets import (
        QAbstractButton,
        QComboBox,
        QGroupBox,
        QLabel,
        QMenu,
        QTableWidget,
        QTabWidget,
        QWidget,
    )

    shown: list[tuple[str, str]] = []
    for m in root.findChildren(QMenu):
        shown.append(("menu", m.title()))
        shown += [("action", a.text()) for a in m.actions() if not a.isSeparator()]
    shown.append(("window title", root.windowTitle() if root.isWindow() and root.parent() is None else ""))
    for wid in root.findChildren(QWidget):
        items = [wid.itemText(i) for i in range(wid.count())] if isinstance(wid, QComboBox) else []
        if wid.toolTip() not in items:  # a combo's tooltip repeating its (data) item is data
            shown.append((f"tooltip of {type(wid).__name__}", wid.toolTip()))
        if isinstance(wid, QAbstractButton):
            shown.append(("button", wid.text()))
        if isinstance(wid, QGroupBox):
            shown.append(("group", wid.title()))
        if isinstance(wid, QTabWidget):
            shown += [("tab", wid.tabText(i)) for i in range(wid.count())]
        if isinstance(wid, QTableWidget):
            shown += [("header", wid.horizontalHeaderItem(j).text()) for j in range(wid.columnCount())
                      if wid.horizontalHeaderItem(j)]
        if isinstance(wid, QLabel):
            shown.append(("label", re.sub(r"<[^>]*>", "", wid.text())))
    return shown


# data shown as is (job and axis names, numbers, units, file names) is not a text to translate
DATA = re.compile(r"^[\s\d.,:;+\-−×x·/()\[\]°%*…_A-Z0-9]*$|^(mm|s|rad|deg|rpm|mm/s|[A-Za-z]\d?|job|lathe\w*)$")


def _bypassing(shown: list[tuple[str, str]]) -> list[str]:
    return sorted({f"{kind}: {t!r}" for kind, t in shown
                   if t and "⟦" not in t and WORDS.search(t) and not DATA.match(t.replace("&", ""))})


@pytest.fixture
def pseudo_translator(qapp):  # noqa: ANN001, ANN201
    """Install a translator that brackets every text it is asked for (⟦text⟧)."""
    from PySide6.QtCore import QTranslator

    class Pseudo(QTranslator):
        def translate(self, context, source, disambiguation=None, n=-1):  # noqa: ANN001, ANN201
            return f"⟦{source}⟧" if source else source

    pseudo = Pseudo()
    qapp.installTranslator(pseudo)
    yield pseudo
    qapp.removeTranslator(pseudo)


def test_a_catalogue_translates_the_window(qtbot, pseudo_translator) -> None:
    """Every menu, action, button, label, tooltip, tab and header of the main window comes from the
    catalogue: nothing bypasses tr()."""
    from winder_gui.main_window import MainWindow

    w = MainWindow()
    qtbot.addWidget(w)
    bad = _bypassing(_shown_texts(w))
    assert not bad, "texts that bypass tr():\n" + "\n".join(bad)


@pytest.mark.parametrize("dialog", ["slotting.SlotDialog", "turning.TurningDialog"])
def test_a_catalogue_translates_the_tool_dialogs(qtbot, pseudo_translator, dialog: str) -> None:
    import importlib

    mod, cls = dialog.split(".")
    d = getattr(importlib.import_module(f"winder_gui.dialogs.{mod}"), cls)()
    qtbot.addWidget(d)
    if hasattr(d, "wait_idle"):
        assert d.wait_idle()
    bad = _bypassing(_shown_texts(d))
    assert not bad, "texts that bypass tr():\n" + "\n".join(bad)


@pytest.mark.parametrize("lang", ["xx"])
def test_install_translator_without_a_catalogue_keeps_english(qtbot, lang: str) -> None:
    from winder_gui.i18n import install_translator, tr

    assert install_translator(lang) is None
    assert tr("Open job") == "Open job"


def test_the_documented_translation_workflow(qtbot, tmp_path: Path) -> None:
    """pyside6-lupdate extracts the texts (tr and QT_TR_NOOP), pyside6-lrelease compiles a catalogue,
    and install_translator makes the window show it (the recipe in winder_gui/i18n.py)."""
    import shutil
    import subprocess
    import sys
    import xml.etree.ElementTree as ET

    from PySide6.QtCore import QCoreApplication

    from winder_gui import i18n

    bindir = Path(sys.executable).parent
    lupdate = shutil.which("pyside6-lupdate", path=str(bindir)) or shutil.which("pyside6-lupdate")
    lrelease = shutil.which("pyside6-lrelease", path=str(bindir)) or shutil.which("pyside6-lrelease")
    if not (lupdate and lrelease):
        pytest.skip("pyside6-lupdate/lrelease are not installed")
    ts = tmp_path / "winder_xx.ts"
    sources = [str(p) for p in sorted(GUI.rglob("*.py"))]
    subprocess.run([lupdate, *sources, "-ts", str(ts)], check=True, capture_output=True, timeout=120)
    tree = ET.parse(ts)
    contexts = tree.getroot().findall("context")
    assert [c.findtext("name") for c in contexts] == [""], "one flat catalogue (the empty context)"
    sources_found = {m.findtext("source") for m in contexts[0].findall("message")}
    for text in ("&File", "Open job", "Band width [mm]", "Program time <b>{total_s:.2f} s</b> ({total_min:.2f} min); "
                 "without the speed-jump limits {without_jumps_s:.2f} s", "Winding β, C, λ (z)"):
        assert text in sources_found, text
    assert len(sources_found) > 400
    for m in contexts[0].findall("message"):  # a German-ish catalogue: translate two texts
        if m.findtext("source") in ("&File", "Open job"):
            tnode = m.find("translation")
            tnode.text = {"&File": "&Datei", "Open job": "Auftrag öffnen"}[m.findtext("source")]
            tnode.attrib.pop("type", None)
    tree.write(ts, encoding="utf-8")
    qm = tmp_path / "winder_xx.qm"
    subprocess.run([lrelease, str(ts), "-qm", str(qm)], check=True, capture_output=True, timeout=120)
    app = QCoreApplication.instance()
    orig = i18n.catalogue_dir
    try:
        i18n.catalogue_dir = lambda: tmp_path  # type: ignore[assignment]
        assert i18n.install_translator("xx") == str(qm)
        from winder_gui.main_window import MainWindow

        w = MainWindow()
        qtbot.addWidget(w)
        assert w.menu_file.title() == "&Datei"
        assert i18n.tr("Open job") == "Auftrag öffnen"
        assert i18n.tr("Save job as") == "Save job as"  # untranslated: English
    finally:
        i18n.catalogue_dir = orig  # type: ignore[assignment]
        for t in i18n._installed:
            app.removeTranslator(t)
        i18n._installed.clear()
