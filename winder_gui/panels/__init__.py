"""Side panels of the main window: the step bar and one properties panel per workflow step."""
