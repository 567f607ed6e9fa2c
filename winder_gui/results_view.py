"""The result views of a window: plots, 3D paths, NC page and time-law page fed from the run controller.

:class:`ResultsPresenter` observes the :class:`~winder_gui.document.JobDocument` and the
:class:`~winder_gui.run_controller.RunController` and draws what they computed.  View updates are
queued and run one per event-loop turn, so the window stays responsive; each stage is redrawn only
when its cache key changed.  When the job changes after a run, the NC page and the plots are marked
out of date (greyed, labelled) until the next run finishes.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from PySide6.QtCore import QObject, QTimer, Signal

from winder_gui import texts
from winder_gui.document import JobDocument
from winder_gui.i18n import QT_TR_NOOP, tr
from winder_gui.run_controller import RunController
from winder_gui.tasks import JobTimeLawResult


class ResultsPresenter(QObject):
    """Shows the pipeline's results in the window's views (``views``: the window, for its plot widgets)."""

    laws_shown = Signal(object)
    timelaw_shown = Signal(object)
    status = Signal(str, bool)

    def __init__(self, doc: JobDocument, ctl: RunController, views: Any) -> None:
        super().__init__(views)
        self.doc, self.ctl, self.v = doc, ctl, views
        self.laws: dict[str, Any] | None = None
        self.timelaw: Any = None
        """The paper example's time laws (Time law step, "paper example")."""
        self.job_timelaw: JobTimeLawResult | None = None
        """The chosen job time law with its DP / TOPP-RA comparison (Time law step, "job: …")."""
        self._tl_laws: tuple[Any, ...] = ()
        self._shown: dict[str, str] = {}
        self._paths_key: str | None = None
        self._queue: list[Callable[[], Any]] = []
        self._timer = QTimer(self)
        self._timer.setInterval(0)
        self._timer.timeout.connect(self._next)
        ctl.partial.connect(self.show_result)
        ctl.run_done.connect(self._on_run_done)
        ctl.laws_done.connect(self._on_laws_done)
        ctl.timelaw_done.connect(self._on_timelaw_done)
        doc.stale_changed.connect(self._on_stale)

    # -- queue -------------------------------------------------------------------------------------
    def queue(self, *updates: Callable[[], Any]) -> None:
        self._queue.extend(updates)
        self._timer.start()

    def _next(self) -> None:
        if self._queue:
            self._queue.pop(0)()
        if not self._queue:
            self._timer.stop()

    def pending(self) -> bool:
        """True while queued view updates are still to be drawn."""
        return bool(self._queue)

    # -- results -------------------------------------------------------------------------------------
    def clear(self) -> None:
        """No results (a new document)."""
        v = self.v
        self.laws = None
        self._paths_key = None
        self._shown.clear()
        self._queue.clear()
        for page in (v.winding_plots, v.eye_plot, v.axes_plot, v.coverage_plot):
            page.clear_data(tr(texts.NO_DATA))
        v.pull_plot.set_laws({}, "", "s")
        v.pull_plot.set_message(tr(texts.NO_DATA))
        v.nc_panel.set_result(None)
        v.view3d.set_paths(None)
        self._tl_laws = ()
        self.job_timelaw = None
        v.timelaw_plot.set_law_choices([], -1)

    def show_result(self, res: Any) -> None:
        """Update the views of every stage of ``res`` that changed since they were last drawn."""
        if not hasattr(res, "keys"):  # a laminate: drawn by winder_gui.laminate_view
            return
        keys = res.keys
        v = self.v
        todo: list[Any] = []

        def fresh(stage: str, have: Any) -> bool:
            if have is None or stage not in keys or self._shown.get(stage) == keys[stage]:
                return False
            self._shown[stage] = keys[stage]
            return True

        if fresh("winding", res.line):
            todo += [lambda: v.winding_plots.set_line(res.line), lambda: v.coverage_plot.set_line(res.line)]
        if fresh("payout", res.eye):
            todo.append(lambda: v.eye_plot.set_eye(res.eye_circuit, res.mandrel))
        if fresh("blocks", res.blocks):
            todo += v.axes_plot.updates(res.blocks, res.machine)
        if todo:
            self.queue(*todo)

    def _on_run_done(self, out: Any) -> None:
        res = out.result
        v = self.v
        if not hasattr(res, "keys"):  # a laminate (LaminateOutput): winder_gui.laminate_view draws it
            self._shown.clear()
            self._paths_key = None
            warns = list(self.doc.run_warnings)
            self.queue(*v.laminate.output_updates(out), lambda: v.nc_panel.set_result(res, warns),
                       *v.axes_plot.updates(res.blocks, res.machine),  # the joined program's axes
                       lambda: self._on_stale(self.doc.is_stale()),
                       lambda: v.machine_panel.show_placement(res.machine, getattr(res, "placement", None)),
                       lambda: v.view3d.set_supports(_supports(res)))  # the one placement of every layer
            self.status.emit(v.laminate.summary(out, time.monotonic() - self.ctl.run_t0, len(warns)), False)
            return
        self.show_result(res)
        if out.coverage is not None:
            self.queue(lambda: v.coverage_plot.set_coverage(out.coverage))
        if out.paths is not None and (v.view3d.paths is None or self._paths_key != res.keys.get("payout")):
            self._paths_key = res.keys.get("payout")
            self.queue(lambda: v.view3d.set_paths(out.paths))
        warns = list(self.doc.run_warnings)
        self.queue(lambda: v.nc_panel.set_result(res, warns), lambda: self._on_stale(self.doc.is_stale()),
                   lambda: v.machine_panel.show_placement(res.machine, getattr(res, "placement", None),
                                                          getattr(res, "mandrel", None)),
                   lambda: v.view3d.set_supports(_supports(res)))
        took = time.monotonic() - self.ctl.run_t0
        reused = f" (re-used: {', '.join(res.reused)})" if res.reused else ""
        program = f"; program time {res.blocks.total:.2f} s" if res.blocks is not None else ""
        n = len(warns)
        self.status.emit(f"Pipeline done in {took:.1f} s{reused}{program}"
                         + (f"; {n} warning{'s' if n != 1 else ''} (NC step)" if n else ""), False)
        info = getattr(res, "timelaw", None)  # the time law that set the block times (method tube/dp/toppra)
        v.timelaw_panel.program_label.setText(
            tr("Program block times: {v0} law over the job's axis path, {v1:.2f} s, {v2} iterations")
            .format(v0=info.get(QT_TR_NOOP('method')), v1=float(info.get('total_time_s', 0.0)),
                    v2=info.get('iterations', 0))
            if isinstance(info, dict) else
            tr("Program block times: (17)/(18), {total:.2f} s")
            .format(total=res.blocks.total) if res.blocks is not None else "")
        self.offer_job_laws(res)

    def _on_stale(self, stale: bool) -> None:
        """Grey and label the NC page and the plots while the results do not describe the job shown."""
        self.v.nc_panel.set_stale(stale)
        for page in (self.v.winding_plots, self.v.eye_plot, self.v.axes_plot, self.v.coverage_plot,
                     self.v.pull_plot):
            page.setToolTip(tr(texts.STALE_RESULTS) if stale else "")
        self.v.stale_label.setVisible(stale)

    def _on_laws_done(self, laws: dict[str, Any]) -> None:
        self.laws = laws
        res = self.doc.result
        v = self.v
        if res is not None and not hasattr(res, "keys"):  # a laminate: the laws of the layer shown
            res = v.laminate.shown_result()
        job_law = res.eye_circuit.law if res is not None and res.eye_circuit is not None else ""
        param = res.job.payout.parameter if res is not None else "s"
        self.queue(*v.pull_plot.plan(list(laws)), *v.pull_plot.updates(laws, job_law, param),
                   lambda: self.laws_shown.emit(laws))

    # -- time law ------------------------------------------------------------------------------------
    def law_result(self) -> Any:
        """The single-line result whose time laws the Time law step offers: the run's own, or for a
        laminate the :class:`~engine.pipeline.PipelineResult` of the layer shown (``None``: none)."""
        res = self.doc.result
        if res is not None and not hasattr(res, "keys"):
            res = self.v.laminate.shown_result()
        return res

    def offer_shown_layer_laws(self, _index: int = -1) -> None:
        """A laminate's layer was shown: offer its time laws in the Law chooser."""
        res = self.law_result()
        if res is not None:
            self.offer_job_laws(res)

    def offer_job_laws(self, res: Any) -> None:
        """Offer the job's time laws of ``res`` in the Law chooser (default: the main law); the chosen
        law is shown at once when the Time law step is open."""
        laws = tuple(getattr(res, "timelaw_laws", ()) or ())
        if len(laws) == len(self._tl_laws) and all(a is b for a, b in zip(laws, self._tl_laws, strict=True)):
            return
        self._tl_laws = laws
        self.v.timelaw_plot.set_law_choices(res.timelaw_labels if laws else [], res.timelaw_main if laws else -1)
        if laws and self.v.steps.current_step() == "timelaw":
            self.show_chosen_law()

    def show_chosen_law(self) -> None:
        """Show the law of the chooser: a job law is (re-)computed unless shown already."""
        i = self.v.timelaw_plot.selected_law()
        if i < 0:
            if self.timelaw is not None:
                self._on_timelaw_done(self.timelaw)
            return
        jt = self.job_timelaw
        res = self.law_result()
        if jt is not None and jt.index == i and res is not None and i < len(res.timelaw_laws) \
                and jt.law is res.timelaw_laws[i]:
            self._on_timelaw_done(jt)
            return
        self.compute_timelaw()

    def law_shown(self) -> bool:
        """True when the chosen job law of the current result is the one shown."""
        jt, res = self.job_timelaw, self.law_result()
        return jt is not None and res is not None and any(jt.law is x for x in res.timelaw_laws)

    def compute_timelaw(self) -> None:
        """Run the time parametrization (tube, DP, TOPP-RA) of the chosen law in the worker: the paper
        example, or the job's law with the classical DP and TOPP-RA on its path and limits."""
        i = self.v.timelaw_plot.selected_law()
        res = self.law_result()
        panel = self.v.timelaw_panel
        if i >= 0 and res is not None and i < len(getattr(res, "timelaw_laws", ())):
            panel.summary.setText(tr("computing…"))
            if not self.v.timelaw_plot.has_data():
                self.v.timelaw_plot.set_message(tr(texts.COMPUTING_TIMELAW))
            self.ctl.compute_job_timelaw(i, res)
            self.status.emit("Computing DP and TOPP-RA on the job's time-law path…", False)
            return
        if panel.errors():
            self.status.emit(f"Time law: {panel.errors()}", True)
            return
        panel.summary.setText(tr("computing…"))
        if not self.v.timelaw_plot.has_data():
            self.v.timelaw_plot.set_message(tr(texts.COMPUTING_TIMELAW))
        self.ctl.compute_paper_timelaw()
        self.status.emit("Computing the time law…", False)

    def _on_timelaw_done(self, r: Any) -> None:
        v = self.v
        if isinstance(r, JobTimeLawResult):
            self.job_timelaw = r
            label = tr("job {method}").format(method=r.law.method)
            self.queue(*v.timelaw_plot.updates(r.law, r.dp, r.toppra, r.source, label, r.s_offset))
            v.timelaw_panel.summary.setText(
                tr("{source}: {method} {total_time_s:.3f} s in {v3} iterations; single DP {v4:.3f} "
                   "s; TOPP-RA reference {v5:.3f} s")
                .format(source=r.source, method=r.law.method, total_time_s=r.law.total_time_s,
                        v3=len(r.law.iterations), v4=r.dp.total_time_s, v5=r.toppra.total_time_s)
                + _sweep_note(r.law) + _toppra_note(r.toppra))
            self.status.emit("Time law comparison computed", False)
        else:
            self.timelaw = r
            self.queue(*v.timelaw_plot.updates(r.tube, r.dp, r.toppra, r.source))
            v.timelaw_panel.summary.setText(
                tr("{source}: tube {total_time_s:.3f} s in {v2} iterations; single DP {v3:.3f} s; "
                   "TOPP-RA reference {v4:.3f} s")
                .format(source=r.source, total_time_s=r.tube.total_time_s, v2=len(r.tube.iterations),
                        v3=r.dp.total_time_s, v4=r.toppra.total_time_s)
                + _sweep_note(r.tube) + _toppra_note(r.toppra))
            self.status.emit("Time law computed", False)
        self.queue(lambda: self.timelaw_shown.emit(r))


def _sweep_note(law: Any) -> str:
    """"; the final sweep saved X s" when the tube's law was bettered by the final sweep, else ""."""
    gain = law.sweep_gain_s
    return tr("; the final sweep saved {gain:.4f} s").format(gain=gain) if gain > 0 else ""


def _toppra_note(law: Any) -> str:
    """"; TOPP-RA's law breaks the limits between its nodes (...)" where its worst ratios inside the intervals
    exceed 1 (it checks them at the nodes only), else ""."""
    acc, spd = float(law.max_accel_ratio), float(law.max_speed_ratio)
    if max(acc, spd) <= 1.0 + 1e-6:
        return ""
    return tr("; TOPP-RA's law breaks the limits between its nodes (axis acceleration ×{acc:.3g}, axis speed "
              "×{spd:.3g})").format(acc=acc, spd=spd)


def _supports(res: Any) -> list[tuple[str, float, float, float]]:
    """The run's shafts, chuck and tailstock for the 3D view (engine.machine_setup.support_obstacles)."""
    from engine.machine_setup import support_obstacles

    if res.mandrel is None:
        return []
    return [(o.name, o.z0, o.z1, o.radius) for o in support_obstacles(res.mandrel, res.job.machine.setup)]
