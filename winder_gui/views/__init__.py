"""Views of the GUI: the 3D mandrel view (pyvistaqt, created lazily) and the pyqtgraph plots."""
