"""``python -m engine`` is the ``winder`` command."""

import sys

from engine.cli import main

sys.exit(main())
