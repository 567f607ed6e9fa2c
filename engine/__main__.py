"""``python -m engine`` is the ``winder`` command."""

import sys

from engine.cli import main

if __name__ == "__main__":  # a spawned child process (engine.sandbox) imports this module as __mp_main__
    sys.exit(main())
