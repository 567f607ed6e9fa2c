"""The VTK render widget of the 3D view: pyvistaqt's interactor rendering once per frame, and the
background import of VTK (kept apart from :mod:`winder_gui.views.view3d`'s view logic)."""

from __future__ import annotations

from typing import Any


def _scene_stamp(render_window: Any) -> tuple[int, ...]:
    """What the picture of ``render_window`` depends on: its size and the modification times of its renderers,
    cameras and props (``GetRedrawMTime`` includes the mapper and its input data).  Unchanged stamp: a new
    render would draw the same picture."""
    stamp = [*render_window.GetSize(), render_window.GetMTime()]
    renderers = render_window.GetRenderers()
    renderers.InitTraversal()
    for _ in range(renderers.GetNumberOfItems()):
        ren = renderers.GetNextItem()
        stamp += [ren.GetMTime(), ren.GetActiveCamera().GetMTime()]
        props = ren.GetViewProps()
        props.InitTraversal()
        for _ in range(props.GetNumberOfItems()):
            prop = props.GetNextProp()
            stamp += [prop.GetMTime(), prop.GetRedrawMTime(), prop.GetVisibility()]
    return tuple(stamp)


_INTERACTOR_CLASS: Any = None


def interactor_class() -> Any:
    """pyvistaqt's ``QtInteractor`` that renders once per frame instead of twice (imports pyvistaqt).

    pyvistaqt's widget renders in VTK first (``plotter.render()``, or the interactor style on every mouse
    move), which schedules a Qt paint, and its ``paintGL`` then always renders again before it blits VTK's
    frame into the widget: every frame cost two renders (``benchmarks/bench_gui_3d.py``).  Here the paint
    only blits when the frame VTK finished last is still current: rendered since the last paint, the
    widget not resized or its GL context re-made since, and :func:`_scene_stamp` unchanged (pyvista may
    move the camera or change an actor without rendering: then the paint renders, as before).  A paint
    that is not preceded by a render (exposure, ``update()``, the animation) renders as before.  A mouse-drag
    frame of a million-point program: ~100 -> ~60 ms, a full-detail frame ~225 -> ~125 ms on llvmpipe.
    """
    global _INTERACTOR_CLASS
    if _INTERACTOR_CLASS is not None:
        return _INTERACTOR_CLASS
    from pyvistaqt import QtInteractor

    class SingleRenderInteractor(QtInteractor):
        def __init__(self, *args: Any, **kwargs: Any) -> None:
            self._fresh_stamp: tuple[int, ...] | None = None
            self.paint_renders = 0
            """Renders done by Qt paints (the others were done before the paint, which only blitted)."""
            self.blit_only_paints = 0
            """Paints that only copied VTK's last frame to the widget."""
            super().__init__(*args, **kwargs)
            rw = self.GetRenderWindow()
            tag = rw.AddObserver("EndEvent", self._on_render_end)
            if isinstance(getattr(self, "_vtk_observers", None), list):
                self._vtk_observers.append((rw, tag))  # pyvistaqt removes its observers on close

        def _on_render_end(self, *_args: Any) -> None:
            # a render outside paintGL: VTK's display framebuffer holds this picture
            in_paint = getattr(self, "_in_paint", False)
            self._fresh_stamp = None if in_paint else _scene_stamp(self.GetRenderWindow())

        def initializeGL(self) -> None:  # noqa: N802 - Qt override
            self._fresh_stamp = None
            super().initializeGL()

        def resizeGL(self, w: int, h: int) -> None:  # noqa: N802 - Qt override
            self._fresh_stamp = None
            super().resizeGL(w, h)
            callback = getattr(self, "resized_callback", None)
            if callback is not None:
                callback(w, h)

        def paintGL(self) -> None:  # noqa: N802 - Qt override
            rw = self.GetRenderWindow()
            fresh = (self._fresh_stamp is not None and rw is not None and "_in_paint" in self.__dict__
                     and not self._in_paint and self._fresh_stamp == _scene_stamp(rw))
            self._fresh_stamp = None
            if not fresh:
                self.paint_renders += 1
                super().paintGL()
                return
            self.blit_only_paints += 1
            self._in_paint = True  # pyvistaqt's paintGL then blits VTK's last frame without rendering
            try:
                super().paintGL()
            finally:
                self._in_paint = False

    _INTERACTOR_CLASS = SingleRenderInteractor
    return _INTERACTOR_CLASS


def _preload_vtk(*, state: Any) -> bool:
    """Import pyvista/pyvistaqt (seconds of VTK loading) off the GUI thread."""
    import pyvista  # noqa: F401
    import pyvistaqt  # noqa: F401

    return True
