"""The laminate in the window: the layer table, the laminate plot tab and the selected layer in 3D.

:class:`LaminatePresenter` observes the :class:`~winder_gui.document.JobDocument` and the
:class:`~winder_gui.run_controller.RunController`.  After a run of a layered job
(:class:`~winder_gui.laminate_tasks.LaminateOutput`) it fills the table's figures and totals, the
cross-section / angle / thickness plots, and shows the selected layer: the surface it was wound on
(its own grown mandrel) and its line in the 3D view, its single-line results (winding β, C, λ and
coverage) in the plot tabs.  Selecting another row switches all of that at once (the data were
prepared in the worker).  A single-line result clears the laminate views.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from PySide6.QtCore import QObject, Signal

from winder_gui.i18n import tr
from winder_gui.laminate_tasks import LaminateOutput, is_laminate

_SHOW_STEPS = 5
"""Steps of :meth:`LaminatePresenter.show_layer_steps`."""


class LaminatePresenter(QObject):
    """Draws the laminate of the latest run (``views``: the window, for its widgets).

    Signals: ``layer_shown(int)`` — job layer ``index`` is shown in the 3D view and the plots.
    """

    layer_shown = Signal(int)

    def __init__(self, doc: Any, ctl: Any, views: Any) -> None:
        super().__init__(views)
        self.doc, self.ctl, self.v = doc, ctl, views
        self.output: LaminateOutput | None = None
        self.shown_layer = -1
        self._laws_key: tuple[str, Any] | None = None
        self.coverage: dict[str, Any] = {}
        """Coverage maps of the layers shown so far, by layer key (computed on demand in a worker)."""
        v = views
        ctl.layer_data_done.connect(self._on_coverage)
        v.layers_panel.layer_selected.connect(self.show_layer)
        v.view3d.layer_requested.connect(self._on_layer_requested)
        v.view3d.play_button.toggled.connect(self._on_play_toggled)
        self._after_play: dict[str, Callable[[], None]] = {}
        """The shown layer's plot steps put off while the 3D view plays (run at the pause)."""
        doc.results_changed.connect(self._on_results)
        doc.stale_changed.connect(self._on_stale)
        v.steps.step_selected.connect(self._on_step)

    def _on_step(self, key: str) -> None:
        # the Winding step of a layered job shows the laminate tab (queued: after the window's own choice)
        if key == "winding" and self.output is not None:
            from PySide6.QtCore import QTimer

            QTimer.singleShot(0, lambda: self.v.plot_tabs.setCurrentWidget(self.v.laminate_plot))

    def _on_results(self, result: Any) -> None:
        if not is_laminate(result):
            self.clear()

    def clear(self) -> None:
        """No laminate results (a single-line job, a new document): the 3D view shows the job's mandrel."""
        if self.output is not None and self.doc.view_data is not None:
            self.v.view3d.set_data(self.doc.view_data)
        self.v.view3d.prepare_scenes([], build=False)   # the layers' kept 3D scenes go
        self.output = None
        self.shown_layer = -1
        self._laws_key = None
        self.v.layers_panel.set_layup(None, None)
        self.v.laminate_plot.set_output(None)
        self.v.view3d.set_layers([], None)
        self.v.view3d.set_layer_shown(-1)

    def set_output(self, out: LaminateOutput) -> None:
        """Show the laminate of a finished run at once (GUI thread; the data were prepared in the worker)."""
        for step in self.output_updates(out):
            step()

    def output_updates(self, out: LaminateOutput) -> list[Callable[[], Any]]:
        """:meth:`set_output` as short GUI-thread steps for the results presenter's queue (the table, the
        laminate plot layer by layer, then the selected layer in 3D and its plots, step by step)."""
        panel = self.v.layers_panel
        sel = panel.selected_layer()
        if out.view(sel) is None and out.views:
            sel = out.views[-1].index
        pending: list[Callable[[], Any]] = []

        def table() -> None:
            self.output = out
            panel.set_layup(out.layup, out.figures_by_key())
            self.shown_layer = -1
            res = out.result
            total = float(res.blocks.total) if res.blocks is not None else None
            starts = {lr.index: float(lr.t0) for lr in res.layers}
            self.v.view3d.set_layers([(lv.index, f"layer {lv.index + 1} {lv.name}", starts.get(lv.index, 0.0))
                                      for lv in out.views if lv.paths is not None], total)

        def show(k: int) -> None:
            if k == 0:  # the layer's steps are made once the table and the plot show this output
                pending[:] = self.show_layer_steps(sel) if self.output is out else []
            if k < len(pending):
                pending[k]()

        scenes = [(lv.surface, lv.paths) for lv in out.views if lv.paths is not None]

        def prepare(k: int, part: int) -> None:  # every layer's 3D scenes made ahead: playing or jumping swaps only
            if self.output is out:
                if k == 0 and part == 0:
                    self.v.view3d.prepare_scenes(scenes, build=False)
                data, paths = scenes[k]
                self.v.view3d.prepare_scene(data if part == 0 else None, paths if part == 1 else None)

        return [table, *self.v.laminate_plot.updates(out, sel), *[lambda k=k: show(k) for k in range(_SHOW_STEPS)],
                *[lambda k=k, part=part: prepare(k, part) for k in range(len(scenes)) for part in (0, 1)]]

    def _on_layer_requested(self, index: int) -> None:
        """The 3D view asks for layer ``index`` (its layer chooser, or playback going on to the next layer):
        select it in the table, which shows it everywhere."""
        self.v.layers_panel.select_layer(index)
        self.show_layer(index)

    @staticmethod
    def summary(out: LaminateOutput, took_s: float, n_warnings: int) -> str:
        """The status line after a run of a layered job."""
        res = out.result
        reused = f" (re-used layers: {', '.join(str(i + 1) for i in res.reused)})" if res.reused else ""
        warn = f"; {n_warnings} warning{'s' if n_warnings != 1 else ''} (NC step)" if n_warnings else ""
        prog = f"; program time {res.blocks.total:.2f} s" if res.blocks is not None else ""
        return f"Laminate of {len(res.layers)} layers done in {took_s:.1f} s{reused}{prog}{warn}"

    def show_layer(self, index: int) -> None:
        """Show job layer ``index`` (0-based): its grown surface and line in 3D, its single-line plots."""
        for step in self.show_layer_steps(index):
            step()

    def show_layer_steps(self, index: int) -> list[Callable[[], Any]]:
        """:meth:`show_layer` as short GUI-thread steps (3D surface, 3D paths, line plots, eye plot); a
        step does nothing once another layer or run is shown."""
        out = self.output
        v = self.v
        v.laminate_plot.select_layer(index)
        if out is None:
            return []
        lv = out.view(index)
        if lv is None or index == self.shown_layer:
            return []
        self.shown_layer = index
        lr = self._layer_result(index)

        def current() -> bool:
            return self.output is out and self.shown_layer == index

        def surface() -> None:
            if current():
                v.view3d.set_data(lv.surface)

        def paths() -> None:
            if current():
                v.view3d.set_paths(lv.paths)
                v.view3d.set_layer_shown(index)

        def line_plots() -> None:
            if not current() or lr is None or lr.result is None or lr.result.line is None:
                return
            line = lr.result.line
            v.winding_plots.set_line(line)
            v.coverage_plot.set_line(line)
            if lv.key in self.coverage:
                v.coverage_plot.set_coverage(self.coverage[lv.key])
            else:
                from winder_gui.laminate_tasks import coverage_task

                self.ctl.layer_runner.submit(coverage_task, lv.key, line, lr.surface)

        def eye() -> None:
            if not current() or lr is None or lr.result is None or lr.result.eye_circuit is None:
                return
            v.eye_plot.set_eye(lr.result.eye_circuit, lr.surface)
            key = (lr.key, lr.result.keys.get("payout"))
            if key != self._laws_key:  # the payout laws compared on this layer's first circuit (worker)
                from winder_gui.tasks import laws_task

                self._laws_key = key
                self.ctl.laws_runner.submit(laws_task, lr.result)

        def done() -> None:
            if not current():
                return
            if v.steps.current_step() == "winding":
                v.plot_tabs.setCurrentWidget(v.laminate_plot)
            self.layer_shown.emit(index)

        def after_play(step: Callable[[], None]) -> Callable[[], None]:
            """While the 3D view plays, a layer's plots wait for the pause (the next layer's frames first)."""
            def run() -> None:
                if v.view3d.is_playing():
                    self._after_play[step.__name__] = step
                else:
                    step()
            return run

        steps = [surface, paths, after_play(line_plots), after_play(eye), done]
        assert len(steps) == _SHOW_STEPS
        return steps

    def _on_play_toggled(self, playing: bool) -> None:
        if not playing:
            pending, self._after_play = self._after_play, {}
            for step in pending.values():
                step()

    def _on_coverage(self, out: tuple[str, Any]) -> None:
        key, cov = out
        self.coverage[key] = cov
        if len(self.coverage) > 32:  # layers of old runs
            self.coverage.pop(next(iter(self.coverage)))
        lv = self.output.view(self.shown_layer) if self.output is not None else None
        if lv is not None and lv.key == key:
            self.v.coverage_plot.set_coverage(cov)

    def coverage_of(self, index: int) -> Any:
        """The coverage map of job layer ``index`` when computed (``None`` before)."""
        lv = self.output.view(index) if self.output is not None else None
        return self.coverage.get(lv.key) if lv is not None else None

    def shown_result(self) -> Any:
        """The single-line :class:`~engine.pipeline.PipelineResult` of the layer shown (``None``: none)."""
        lr = self._layer_result(self.shown_layer)
        return lr.result if lr is not None else None

    def _layer_result(self, index: int) -> Any:
        out = self.output
        if out is None:
            return None
        try:
            return out.result.layer(index)
        except KeyError:
            return None

    def _on_stale(self, stale: bool) -> None:
        from winder_gui import texts

        self.v.laminate_plot.setToolTip(tr(texts.STALE_RESULTS) if stale else "")
