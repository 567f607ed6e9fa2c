"""The widgets of the main window and their layout, and the layout's persistence in the settings."""

from __future__ import annotations

from typing import TYPE_CHECKING

from PySide6.QtCore import QByteArray, Qt
from PySide6.QtWidgets import (
    QLabel,
    QProgressBar,
    QPushButton,
    QScrollArea,
    QSplitter,
    QStackedWidget,
    QTabWidget,
    QVBoxLayout,
    QWidget,
)

from winder_gui import texts
from winder_gui.i18n import tr
from winder_gui.panels.layers_panel import LayersPanel
from winder_gui.panels.machine_panel import MachinePanel
from winder_gui.panels.mandrel_panel import MandrelPanel
from winder_gui.panels.nc_panel import NCPanel, TimeLawPanel
from winder_gui.panels.section_panel import SectionPanel, payout_panel, winding_panel
from winder_gui.panels.steps import STEPS, StepBar
from winder_gui.settings import app_settings
from winder_gui.views.axes_plot import AxesPlot
from winder_gui.views.coverage_plot import CoveragePlot
from winder_gui.views.laminate_plot import LaminatePlots
from winder_gui.views.plots import EyePlot, PullSpeedPlot, WindingPlots
from winder_gui.views.profile_plot import ProfilePlot
from winder_gui.views.timelaw_plot import TimeLawPlot
from winder_gui.views.view3d import MandrelView3D

if TYPE_CHECKING:
    from winder_gui.main_window import MainWindow


def build_layout(w: MainWindow) -> None:
    """Make and lay out the window's widgets (``w.steps``, ``w.view3d``, the plots, the panels, the
    properties stack and the status bar)."""
    w.steps = StepBar()
    w.view3d = MandrelView3D()
    acts = getattr(w, "actions", None)
    if isinstance(acts, dict) and "show_machine" in acts:   # View -> Show the machine follows the 3D view's box
        w.view3d.machine_check.toggled.connect(acts["show_machine"].setChecked)
    w.plot = ProfilePlot()
    w.plot_tabs = QTabWidget()
    w.plot_tabs.setDocumentMode(True)
    w.plot_tabs.addTab(w.plot, tr("Generatrix r(z)"))
    w.winding_plots = WindingPlots()
    w.eye_plot = EyePlot()
    w.pull_plot = PullSpeedPlot()
    w.axes_plot = AxesPlot()
    w.timelaw_plot = TimeLawPlot()
    w.coverage_plot = CoveragePlot()
    w.laminate_plot = LaminatePlots()
    w.tabs: dict[str, QWidget] = {"generatrix": w.plot}
    for key, page, title in (("winding", w.winding_plots, tr("Winding β, C, λ (z)")),
                             ("eye", w.eye_plot, tr("Eye path Z–R")),
                             ("pull_speed", w.pull_plot, tr("Pull speed u(x)")),
                             ("axes", w.axes_plot, tr("Axes q(t), v(t)")),
                             ("time_law", w.timelaw_plot, tr("Time law ṡ")),
                             ("coverage", w.coverage_plot, tr("Coverage v(z)")),
                             ("laminate", w.laminate_plot, tr("Laminate r(z), β, t"))):
        w.plot_tabs.addTab(page, title)
        w.tabs[key] = page

    center = QSplitter(Qt.Orientation.Vertical)
    center.addWidget(w.view3d)
    center.addWidget(w.plot_tabs)
    center.setStretchFactor(0, 3)
    center.setStretchFactor(1, 2)
    center.setSizes([470, 380])
    w.center_splitter = center

    w.mandrel_panel = MandrelPanel()
    w.winding_panel = winding_panel()
    w.layers_panel = LayersPanel()
    w.payout_panel = payout_panel()
    w.machine_panel = MachinePanel()
    w.timelaw_panel = TimeLawPanel()
    w.nc_panel = NCPanel()
    w.section_panels: dict[str, SectionPanel] = {
        "winding": w.winding_panel, "payout": w.payout_panel, "machine": w.machine_panel,
        "timelaw": w.timelaw_panel,
    }
    w.properties = QStackedWidget()
    w.properties.setMinimumWidth(330)
    w.step_pages: dict[str, int] = {}
    winding_page = QWidget()  # the layer table above the defaults every layer inherits ([band], [winding])
    box = QVBoxLayout(winding_page)
    box.setContentsMargins(0, 0, 0, 0)
    box.addWidget(w.layers_panel)
    defaults = QLabel(tr("<b>Defaults</b> — inherited by every layer that leaves a field blank"))
    defaults.setWordWrap(True)
    box.addWidget(defaults)
    box.addWidget(w.winding_panel)
    pages = {"mandrel": w.mandrel_panel, **w.section_panels, "nc": w.nc_panel, "winding": winding_page}
    for key in ("mandrel", *w.section_panels, "nc"):
        add_step_page(w, key, pages[key], horizontal_scroll=key == "mandrel")

    main = QSplitter(Qt.Orientation.Horizontal)
    main.addWidget(w.steps)
    main.addWidget(center)
    main.addWidget(w.properties)
    main.setStretchFactor(1, 1)
    main.setCollapsible(0, False)
    main.setSizes([118, 920, 362])
    w.setCentralWidget(main)

    w.status_msg = QLabel("")
    w.status_msg.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
    w.summary_label = QLabel("")
    w.stale_label = QLabel(tr("results out of date"))
    w.stale_label.setObjectName("staleResults")
    w.stale_label.setToolTip(tr(texts.STALE_RESULTS))
    w.stale_label.setStyleSheet("color: #a05a00; font-weight: bold;")
    w.stale_label.hide()
    w.busy_bar = QProgressBar()
    w.busy_bar.setMaximumWidth(140)
    w.busy_bar.setTextVisible(False)
    w.busy_bar.hide()
    w.progress_bar = QProgressBar()
    w.progress_bar.setObjectName("pipelineProgress")
    w.progress_bar.setRange(0, 1000)
    w.progress_bar.setMinimumWidth(240)  # its text names the stage: narrower, it wrapped onto two clipped lines
    w.progress_bar.setMaximumWidth(360)
    w.progress_bar.setFormat("%p%")
    w.progress_bar.hide()
    w.cancel_button = QPushButton(tr("Cancel"))
    w.cancel_button.setObjectName("cancelRun")
    w.cancel_button.setToolTip(tr("Stop the computation (Esc)"))
    w.cancel_button.hide()
    sb = w.statusBar()
    sb.addWidget(w.status_msg, 1)
    for item in (w.stale_label, w.summary_label, w.progress_bar, w.cancel_button, w.busy_bar):
        sb.addPermanentWidget(item)
    w.steps.set_available({k for k, _ in STEPS})


def add_step_page(w: MainWindow, key: str, panel: QWidget, horizontal_scroll: bool = False) -> None:
    """Add ``panel`` as the properties page of step ``key`` (in a scroll area)."""
    sc = QScrollArea()
    sc.setWidgetResizable(True)
    if not horizontal_scroll:
        sc.setHorizontalScrollBarPolicy(Qt.ScrollBarPolicy.ScrollBarAlwaysOff)
    sc.setWidget(panel)
    w.step_pages[key] = w.properties.addWidget(sc)


def restore_layout(w: MainWindow) -> None:
    """Restore the window layout and options from the settings."""
    st = app_settings()
    geo = st.value("window/geometry")
    if isinstance(geo, QByteArray | bytes):
        w.restoreGeometry(QByteArray(geo))
    state = st.value("window/state")
    if isinstance(state, QByteArray | bytes):
        w.restoreState(QByteArray(state))
    for name, spl in (("main", w.centralWidget()), ("center", w.center_splitter)):
        val = st.value(f"window/splitter_{name}")
        if isinstance(val, QByteArray | bytes) and isinstance(spl, QSplitter):
            spl.restoreState(QByteArray(val))
    w.auto_run = str(st.value("run/auto", True)).lower() not in ("false", "0")
    w.actions["auto_run"].setChecked(w.auto_run)
    colour = st.value("view/colour_by", "")
    if colour:
        try:
            w.view3d.set_colour_by(str(colour))
        except ValueError:
            pass
    # a new window opens on the first step and its plot (the generatrix), whatever tab was open last:
    # the result tabs are empty until the pipeline has run
    w.go_to_step("mandrel")


def save_layout(w: MainWindow) -> None:
    """Write the window layout and options to the settings."""
    st = app_settings()
    st.setValue("window/geometry", w.saveGeometry())
    st.setValue("window/state", w.saveState())
    st.setValue("window/splitter_main", w.centralWidget().saveState())
    st.setValue("window/splitter_center", w.center_splitter.saveState())
    st.setValue("run/auto", w.auto_run)
    st.setValue("view/colour_by", w.view3d.colour_by)
    st.sync()
