"""PySide6 desktop application of winder. All mathematics lives in :mod:`engine`."""
