"""Modal and modeless tool dialogs (turning optimiser, slot-forming calculator, ...)."""
