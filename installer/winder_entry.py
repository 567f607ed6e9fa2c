"""Entry script of the frozen ``winder`` executable (PyInstaller analyses this file).

It is the ``winder`` console script: no arguments (or one ``JOB.toml``) opens the desktop
application, anything else is a sub-command (``winder --help``).
"""

import multiprocessing

from engine.cli import entry

if __name__ == "__main__":
    multiprocessing.freeze_support()  # no-op unless a library starts worker processes
    entry()
