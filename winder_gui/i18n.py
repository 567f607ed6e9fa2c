"""Translation of the GUI's user-visible texts (issue 18, point 5): Qt Linguist, one catalogue.

Every text the user reads (labels, buttons, menus, tooltips, column headers, dialog titles, plot
titles and axis labels, messages) goes through :func:`tr` (or is marked with :func:`QT_TR_NOOP` where
it is a module-level constant, and passed through :func:`tr` where it is shown).  All texts share one
translation context, the empty one, so a translator sees one flat catalogue.
``tests/test_gui_i18n.py`` scans ``winder_gui/`` and fails on a literal text handed to Qt without
:func:`tr`.

Adding a translation (e.g. German, ``de``)::

    pyside6-lupdate $(git ls-files 'winder_gui/*.py') -ts resources/i18n/winder_de.ts   # extract / update
    pyside6-linguist resources/i18n/winder_de.ts                                        # translate
    pyside6-lrelease resources/i18n/winder_de.ts -qm resources/i18n/winder_de.qm        # compile

The GUI loads ``resources/i18n/winder_<lang>.qm`` at start-up for the language named by the
environment variable ``WINDER_LANG`` (e.g. ``de``), else for the system locale; English (the source
texts) when there is no catalogue.  Texts built from data are written as ``tr("… {name} …").format(
name=...)`` so the translator can move the placeholders.
"""

from __future__ import annotations

import os
from pathlib import Path

from PySide6.QtCore import QCoreApplication, QLocale, QTranslator

CONTEXT = ""
"""The one translation context of winder's texts (what ``pyside6-lupdate`` gives a bare ``tr(...)``)."""

_installed: list[QTranslator] = []


def tr(text: str, disambiguation: str | None = None, n: int = -1) -> str:
    """The user's-language version of the English ``text`` (itself when there is no translation)."""
    return QCoreApplication.translate(CONTEXT, text, disambiguation, n)


def QT_TR_NOOP(text: str) -> str:  # noqa: N802 - the name pyside6-lupdate looks for
    """Mark a module-level constant text for extraction; translate it with :func:`tr` where shown."""
    return text


def catalogue_dir() -> Path:
    """The folder of the compiled catalogues (``winder_<lang>.qm``)."""
    from engine.resources import resource_path

    return resource_path("i18n")


def install_translator(lang: str | None = None) -> str | None:
    """Install the catalogue for ``lang`` (default: ``$WINDER_LANG``, else the system locale) into the
    running application; return the path loaded, or None (English) when there is none."""
    app = QCoreApplication.instance()
    if app is None:
        return None
    lang = lang or os.environ.get("WINDER_LANG") or QLocale.system().name()
    for name in (lang, lang.split("_")[0]):
        qm = catalogue_dir() / f"winder_{name}.qm"
        if qm.is_file():
            t = QTranslator(app)
            if t.load(str(qm)):
                app.installTranslator(t)
                _installed.append(t)
                return str(qm)
    return None
