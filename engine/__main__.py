"""``python -m engine`` is the ``winder`` command."""

from engine.cli import entry

if __name__ == "__main__":  # a spawned child process (engine.sandbox) imports this module as __mp_main__
    entry()
