"""The default layout of a run's recording: the 3D scene and the summary on the left; the joints'
signals, residuals, loops and FRF in tabs on the right (docs/visualisation.md)."""

from __future__ import annotations

from .rrd_data import RunContents
from .rrd_plots import PLOT_H, PLOT_W

__all__ = ["run_blueprint"]


def _plot_view(rrb, origin: str, name: str):
    return rrb.Spatial2DView(origin=origin, name=name,
                             visual_bounds=rrb.VisualBounds2D(x_range=[-40, PLOT_W + 20], y_range=[-20, PLOT_H + 30]))


def run_blueprint(contents: RunContents):
    """The rerun Blueprint of a run: one tab per joint (angles, deflection, torques, residuals,
    loop), one for the FRF when there is one."""
    import rerun.blueprint as rrb

    left = [rrb.Spatial3DView(origin="/", contents=["+ /world/**", "+ /robot/**"], name="scene")]
    left.append(rrb.TextDocumentView(origin="/summary", name="summary"))
    tabs = []
    resid_joints = {k.rsplit("_r_", 1)[0] for k in (contents.residuals or {}) if "_r_" in k}
    for j in contents.joints:
        b = f"/plots/{j.name}"
        views = [rrb.TimeSeriesView(origin=f"{b}/angle", name=f"{j.name} angles (rad)")]
        if "delta" in j.angles:
            views.append(rrb.TimeSeriesView(origin=f"{b}/deflection", name=f"{j.name} deflection (rad)"))
        if "tau" in j.angles:
            views.append(rrb.TimeSeriesView(origin=f"{b}/torque", name=f"{j.name} torques (N m)"))
        if j.name in resid_joints:
            views.append(rrb.TimeSeriesView(origin=f"{b}/residuals/delta", name=f"{j.name} deflection residual (rad)"))
            views.append(rrb.TimeSeriesView(origin=f"{b}/residuals/u", contents=[f"+ {b}/residuals/u/**",
                                                                                 f"+ {b}/residuals/located/**"],
                                            name=f"{j.name} torque residual (N m), located windows"))
        tab = [rrb.Vertical(*views, name=f"{j.name} signals")]
        if "tau" in j.angles:
            tab.append(_plot_view(rrb, f"/loops/{j.name}", f"{j.name} deflection vs spring torque"))
        tabs.append(rrb.Horizontal(*tab, column_shares=[3, 2][:len(tab)], name=j.name))
    if contents.frf is not None or contents.frf_lines is not None:
        tabs.append(rrb.Vertical(_plot_view(rrb, "/frf/magnitude", "FRF magnitude"),
                                 _plot_view(rrb, "/frf/phase", "FRF phase"), name="FRF"))
    if contents.discovery is not None:
        tabs.append(rrb.TextLogView(origin="/discovery", name="discovery"))
    main = rrb.Horizontal(rrb.Vertical(*left, row_shares=[4, 1]), rrb.Tabs(*tabs) if tabs else
                          rrb.TextDocumentView(origin="/summary"), column_shares=[1, 1])
    return rrb.Blueprint(main, rrb.TimePanel(timeline="time"), collapse_panels=True)
