"""`report.html` of a bag: one self-contained, interactive page.

Plotly, its JavaScript inlined, so it opens offline and can be mailed as one file.

Figures: the orbit in 3D (truth and the filter's estimates, GCRF km, the gap highlighted);
the ground tracks of truth and estimate with the run's stations and the visibility circle of
each station's elevation mask (longitude/latitude, deg);
each arm's position error over the gap with its ±3σ; the surrogate's forecasts against the
withheld measurements, with their ±3σ; each arm's NEES over the gap against the χ² band; the
filter's NIS over the run against its χ² band. Tables: the arms, and for a station network
(the real sky) the filter after each pass. Units: the core's (km, km/s, rad, s); times are
hours; the ground track's longitude and latitude are deg.
"""

from __future__ import annotations

import html
from pathlib import Path

import numpy as np
import plotly.graph_objects as go
from plotly.subplots import make_subplots

from ssa_fusion.apps import evaluate
from ssa_fusion.core.base import metrics, types
from ssa_fusion.core.base.constants import R_EARTH
from ssa_fusion.core.earth.frames import Station
from ssa_fusion.core.earth.stations import NETWORKS, SENSORS, STATIONS
from ssa_fusion.core.gaps.estimator import EstimatorConfig
from ssa_fusion.evaluation.arms import ArmName
from ssa_fusion.evaluation.passes import PassReport
from ssa_fusion.ros import foxglove_scene

COLORS = {ArmName.PLACEHOLDER: "#7f7f7f", ArmName.COAST: "#1f77b4",
          ArmName.J2_COAST: "#2ca02c", ArmName.BATCH_FIT: "#8c564b",
          ArmName.DMD_EKF: "#d62728",
          ArmName.HYPOTHETICAL_EKF: "#9467bd"}
"""One colour per arm, the same in every figure."""
AXIS_COLORS = ("#1f77b4", "#ff7f0e", "#2ca02c")
"""Colours of the x, y, z components."""
MEASUREMENT_LABELS: dict[int, tuple[str, ...]] = {
    types.Kind.POSITION: ("x GCRF [km]", "y GCRF [km]", "z GCRF [km]"),
    types.Kind.RANGE_AZ_EL: ("range [km]", "azimuth [rad]", "elevation [rad]"),
    types.Kind.RA_DEC: ("right ascension [rad]", "declination [rad]"),
}
"""Axis titles of a measurement's components, by kind."""
WRAPPED_COMPONENT: dict[int, int] = {types.Kind.RANGE_AZ_EL: 1, types.Kind.RA_DEC: 0}
"""The component that wraps at 2π (azimuth, right ascension), by measurement kind."""
MAX_POINTS = 4000
"""Longest line drawn (points); longer series are thinned evenly (the page stays small)."""
CONFIG = {"displaylogo": False, "responsive": True}

# A script error (a plot that failed to draw) shows on the page, not only in the console.
ERROR_HOOK = """<script>
window.addEventListener("error", function (e) {
  var d = document.createElement("div"); d.className = "render-error";
  d.textContent = "Error while drawing this report: " + e.message;
  document.body.insertBefore(d, document.body.firstChild);
});
</script>"""

STYLE = """<style>
body { font-family: sans-serif; margin: 1.5em; color: #222; }
table { border-collapse: collapse; margin: 0.5em 0 1em; }
th, td { border: 1px solid #bbb; padding: 0.25em 0.6em; text-align: right; }
th { background: #eee; } td:first-child { text-align: left; }
.note { color: #555; max-width: 70em; }
.render-error { background: #fdd; color: #900; padding: 0.5em; font-weight: bold; }
</style>"""


def _thin(n: int) -> np.ndarray:
    """Return indices of at most `MAX_POINTS` of `n` samples, evenly spread, ends kept."""
    if n <= MAX_POINTS:
        return np.arange(n)
    return np.unique(np.linspace(0, n - 1, MAX_POINTS).round().astype(int))


def _hours(t: np.ndarray, t0: float) -> np.ndarray:
    """Epochs `t` (s) as hours after `t0` (s)."""
    return (np.asarray(t, float) - t0) / 3600.0


def orbit_3d(data: evaluate.BagData, ev: evaluate.Evaluation) -> go.Figure:
    """Return the 3D orbit: truth and the filter's fused estimates in GCRF (km), the Earth.

    The truth over the gap drawn thick, and the DMD-EKF arm over the gap.
    """
    fig = go.Figure()
    u, v = np.mgrid[0:2 * np.pi:37j, 0:np.pi:19j]
    fig.add_trace(go.Surface(
        x=R_EARTH * np.cos(u) * np.sin(v), y=R_EARTH * np.sin(u) * np.sin(v),
        z=R_EARTH * np.cos(v), showscale=False, opacity=0.25, hoverinfo="skip",
        colorscale=[[0, "#6baed6"], [1, "#6baed6"]], name="Earth"))
    truth = np.array([e.x[:3] for e in data.truth])
    k = _thin(len(truth))
    fig.add_trace(go.Scatter3d(x=truth[k, 0], y=truth[k, 1], z=truth[k, 2], mode="lines",
                               line={"color": "#444", "width": 2}, name="truth"))
    est = np.array([e.x[:3] for e in data.estimates
                    if e.update_source != types.UpdateSource.NONE])
    if len(est):
        k = _thin(len(est))
        fig.add_trace(go.Scatter3d(x=est[k, 0], y=est[k, 1], z=est[k, 2], mode="markers",
                                   marker={"size": 1.5, "color": "#1f77b4"},
                                   name="estimate (fused epochs)"))
    g = ev.gap
    fig.add_trace(go.Scatter3d(x=g.truth[:, 0], y=g.truth[:, 1], z=g.truth[:, 2],
                               mode="lines", line={"color": "#ff7f0e", "width": 8},
                               name=f"truth over the gap ({len(g.t)} epochs)"))
    dmd = g.arms.get(ArmName.DMD_EKF)
    if dmd is not None:
        fig.add_trace(go.Scatter3d(x=dmd.x[:, 0], y=dmd.x[:, 1], z=dmd.x[:, 2],
                                   mode="lines", line={"color": COLORS[ArmName.DMD_EKF],
                                                       "width": 4, "dash": "dash"},
                                   name="dmd_ekf over the gap"))
    h = np.cross(data.truth[0].x[:3], data.truth[0].x[3:6])  # look down on the orbit plane
    eye = 1.8 * h / np.linalg.norm(h) + np.array([0.3, 0.3, 0.0])
    fig.update_layout(
        title="Orbit in GCRF (truth, estimates; the gap highlighted)", height=650,
        scene={"xaxis_title": "x GCRF [km]", "yaxis_title": "y GCRF [km]",
               "zaxis_title": "z GCRF [km]", "aspectmode": "data",
               "camera": {"eye": dict(zip("xyz", eye.tolist(), strict=True))}},
        legend={"x": 0, "y": 1}, margin={"l": 0, "r": 0, "t": 40, "b": 0})
    return fig


NO_MASK_DEG = -90.0
"""Elevation mask (deg) of a station without one: the paper's idealised sensor, which
measures through the Earth (`stations.SENSORS["columbus_paper"]`)."""


def run_stations(c: EstimatorConfig) -> list[tuple[Station, float]]:
    """Return the stations of a run and each one's elevation mask (deg).

    From its estimator settings (the bag's ``/ssa/config``): for a network (the real sky)
    each sensor's ``min_elevation_deg`` (`stations.SENSORS`, by sensor or station id); for
    one station (a paper scenario, whose simulated sensor has no horizon) `NO_MASK_DEG`;
    none for positions.
    """
    if c.kind == types.Kind.POSITION:
        return []
    if not c.is_network:
        return [(STATIONS[c.station], NO_MASK_DEG)] if c.station in STATIONS else []
    ids = NETWORKS.get(c.station) or tuple(x.strip() for x in c.station.split(",") if x.strip())
    out: dict[str, tuple[Station, float]] = {}
    for i in ids:
        sensor = SENSORS.get(i)
        if sensor is not None:
            out[sensor.station.name] = (sensor.station, sensor.min_elevation_deg)
        elif i in STATIONS:
            out[i] = (STATIONS[i], NO_MASK_DEG)
    return list(out.values())


def visibility_central_angle(h_km: float, el_rad: float, r_km: float = R_EARTH) -> float:
    """Return the Earth-central angle (rad) of a station's visibility circle.

    The angle between a station and the sub-satellite point of an object at altitude `h_km`
    (km) seen at elevation `el_rad` (rad) from it, on a spherical Earth of radius `r_km`:
    λ = arccos(R cos(el) / (R + h)) − el. Below λ the object is above that elevation; π for
    el = −90° (visible from everywhere).
    """
    return float(np.arccos(r_km * np.cos(el_rad) / (r_km + h_km)) - el_rad)


def small_circle(lat_rad: float, lon_rad: float, radius_rad: float,
                 n: int = 361) -> tuple[np.ndarray, np.ndarray]:
    """Return `n` points (latitude, longitude in (−π, π], rad) of a circle on a sphere.

    The circle at central angle `radius_rad` around (`lat_rad`, `lon_rad`), bearing 0 to 2π
    from north.
    """
    b = np.linspace(0.0, 2.0 * np.pi, n)
    sl, cl, sr, cr = np.sin(lat_rad), np.cos(lat_rad), np.sin(radius_rad), np.cos(radius_rad)
    lat = np.arcsin(np.clip(sl * cr + cl * sr * np.cos(b), -1.0, 1.0))
    lon = lon_rad + np.arctan2(np.sin(b) * sr * cl, cr - sl * np.sin(lat))
    return lat, np.angle(np.exp(1j * lon))


def _unwrapped(lat_deg: np.ndarray, lon_deg: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Return a lat/lon (deg) line with NaN inserted where it crosses the ±180° meridian.

    So no segment is drawn across the map.
    """
    jump = np.flatnonzero(np.abs(np.diff(lon_deg)) > 180.0) + 1
    return np.insert(lat_deg, jump, np.nan), np.insert(lon_deg, jump, np.nan)


def _track(states: list[types.StateEstimate]) -> tuple[np.ndarray, np.ndarray]:
    """Return the geodetic latitude and longitude (deg) of the sub-satellite points of `states`.

    The states are GCRF km at their Unix epochs; at most `MAX_POINTS`, broken at the ±180°
    meridian.
    """
    k = _thin(len(states))
    ll = np.array([foxglove_scene.gcrs_to_geodetic(states[i].x[:3], states[i].t)[:2]
                   for i in k]).reshape(-1, 2)
    return _unwrapped(np.degrees(ll[:, 0]), np.degrees(ll[:, 1]))


def ground_track(data: evaluate.BagData, stations: list[tuple[Station, float]]) -> go.Figure:
    """Return the ground tracks of the truth and of the filter's fused estimates, with stations.

    Geodetic longitude and latitude, deg; the run's stations, and each station's visibility
    circle: the sub-satellite points from which the object, at its mean altitude over the run
    (‖r‖ − R_EARTH of the truth, spherical Earth), is above the station's elevation mask
    (`visibility_central_angle`). A station without a mask gets its geometric horizon
    (0°) dotted instead: its sensor sees the object from anywhere.
    """
    fig = go.Figure()
    lat, lon = _track(data.truth)
    fig.add_trace(go.Scatter(x=lon, y=lat, mode="lines", line={"color": "#444", "width": 1},
                             name="truth"))
    est = [e for e in data.estimates if e.update_source != types.UpdateSource.NONE]
    if est:
        lat, lon = _track(est)
        fig.add_trace(go.Scatter(x=lon, y=lat, mode="markers", name="estimate (fused epochs)",
                                 marker={"size": 2, "color": "#1f77b4"}))
    h = float(np.mean([np.linalg.norm(e.x[:3]) for e in data.truth])) - R_EARTH
    for station, mask_deg in stations:
        masked = mask_deg > NO_MASK_DEG
        el = np.radians(mask_deg if masked else 0.0)
        lam = visibility_central_angle(h, float(el))
        clat, clon = small_circle(station.lat_rad, station.lon_rad, lam)
        clat, clon = _unwrapped(np.degrees(clat), np.degrees(clon))
        label = (f"{station.name}: above its {mask_deg:g}° mask" if masked else
                 f"{station.name}: horizon (no mask: its sensor sees through the Earth)")
        fig.add_trace(go.Scatter(x=clon, y=clat, mode="lines", name=f"{label}, λ = "
                                 f"{np.degrees(lam):.1f}° at h = {h:.0f} km",
                                 line={"color": "#d62728", "width": 1.5,
                                       "dash": "solid" if masked else "dot"}))
        fig.add_trace(go.Scatter(x=[np.degrees(station.lon_rad)],
                                 y=[np.degrees(station.lat_rad)], mode="markers+text",
                                 text=[station.name], textposition="top center",
                                 marker={"size": 9, "color": "#d62728", "symbol": "triangle-up"},
                                 name=station.name, showlegend=False))
    fig.update_xaxes(title_text="longitude [deg]", range=[-180, 180], dtick=30,
                     constrain="domain")
    fig.update_yaxes(title_text="latitude [deg]", range=[-90, 90], dtick=30,
                     scaleanchor="x", scaleratio=1)
    fig.update_layout(title="Ground track (WGS-84 geodetic) with the stations' visibility "
                            "circles", height=560, legend={"orientation": "h", "y": -0.15})
    return fig


def arm_errors(ev: evaluate.Evaluation) -> go.Figure:
    """Return, per arm, its position error along x, y, z GCRF (km) over the gap, with ±3σ.

    The ±3σ of its covariance dashed, against hours into the gap.
    """
    g = ev.gap
    names = [a for a in ArmName if a in g.arms]
    fig = make_subplots(rows=len(names), cols=1, shared_xaxes=True, vertical_spacing=0.04,
                        subplot_titles=[f"{a}: ε = {g.scores[a].epsilon:.2e}, mean |Δr| = "
                                        f"{g.scores[a].pos_err_mean_km:.3g} km"
                                        for a in names])
    hours = _hours(g.t, float(g.t[0]))
    for row, name in enumerate(names, start=1):
        arm = g.arms[name]
        err = arm.x[:, :3] - g.truth[:, :3]
        sig = np.sqrt(np.abs(np.diagonal(arm.P, axis1=1, axis2=2)[:, :3]))
        for i, axis in enumerate("xyz"):
            c = AXIS_COLORS[i]
            first = row == 1
            fig.add_trace(go.Scatter(x=hours, y=err[:, i], mode="lines", name=f"Δ{axis}",
                                     line={"color": c, "width": 1.5}, legendgroup=axis,
                                     showlegend=first), row=row, col=1)
            for sign in (1, -1):
                fig.add_trace(go.Scatter(x=hours, y=sign * 3 * sig[:, i], mode="lines",
                                         name=f"±3σ {axis}", legendgroup=axis,
                                         line={"color": c, "width": 1, "dash": "dash"},
                                         showlegend=first and sign == 1), row=row, col=1)
        fig.update_yaxes(title_text="error [km]", row=row, col=1)
    fig.update_xaxes(title_text="hours into the gap [h]", row=len(names), col=1)
    fig.update_layout(title="Position error of each arm over the gap, with ±3σ",
                      height=230 * len(names) + 80)
    return fig


def forecasts(data: evaluate.BagData) -> go.Figure | None:
    """Return the surrogate's forecasts against the withheld measurements of the same epochs.

    With ±3σ of their covariance, per component, in the measurement's units; None without
    both.
    """
    withheld = {m.t: m for m in data.withheld}
    f = sorted((m for m in data.forecasts if m.t in withheld), key=lambda m: m.t)
    if not f:
        return None
    t0 = min(withheld)
    t = _hours(np.array([m.t for m in f]), t0)
    zf = np.array([m.z for m in f])
    sf = np.sqrt(np.abs(np.array([np.diag(m.R) for m in f])))
    tw = sorted(withheld)
    zw = np.array([withheld[s].z for s in tw])
    kind = int(f[0].kind)  # an unknown kind gets z[i] axis titles, not an error
    labels = MEASUREMENT_LABELS.get(kind, ())
    n = zf.shape[1]
    wrapped = WRAPPED_COMPONENT.get(kind)
    if wrapped is not None:  # azimuth / right ascension wrap at 2π: no line across a wrap
        jump = np.flatnonzero(np.abs(np.diff(zf[:, wrapped])) > np.pi) + 1
        t, sf = np.insert(t, jump, np.nan), np.insert(sf, jump, np.nan, axis=0)
        zf = np.insert(zf, jump, np.nan, axis=0)
    fig = make_subplots(rows=n, cols=1, shared_xaxes=True, vertical_spacing=0.05)
    for i in range(n):
        first = i == 0
        fig.add_trace(go.Scatter(x=_hours(np.array(tw), t0), y=zw[:, i], mode="markers",
                                 marker={"size": 4, "color": "#222"}, legendgroup="w",
                                 name="withheld (sensor)", showlegend=first), row=i + 1, col=1)
        fig.add_trace(go.Scatter(x=t, y=zf[:, i], mode="lines", legendgroup="f",
                                 line={"color": COLORS[ArmName.DMD_EKF]}, name="forecast",
                                 showlegend=first), row=i + 1, col=1)
        for sign in (1, -1):
            fig.add_trace(go.Scatter(x=t, y=zf[:, i] + sign * 3 * sf[:, i], mode="lines",
                                     line={"color": COLORS[ArmName.DMD_EKF], "width": 1,
                                           "dash": "dot"}, legendgroup="s",
                                     name="forecast ±3σ", showlegend=first and sign == 1),
                          row=i + 1, col=1)
        fig.update_yaxes(title_text=labels[i] if i < len(labels) else f"z[{i}]",
                         row=i + 1, col=1)
    fig.update_xaxes(title_text="hours into the gap [h]", row=n, col=1)
    fig.update_layout(title="Forecasts against the withheld measurements", height=220 * n + 80)
    return fig


def _band(fig: go.Figure, x0: float, x1: float, lo: float, hi: float) -> None:
    """Draw the 95 % χ² band [lo, hi] from x0 to x1 (h), shaded, as one legend entry.

    Traces, not shapes: their data coordinates hold on log axes.
    """
    style = {"color": "#2ca02c", "dash": "dash", "width": 1}
    fig.add_trace(go.Scatter(x=[x0, x1], y=[lo, lo], mode="lines", line=style,
                             legendgroup="band", showlegend=False, hoverinfo="skip"))
    fig.add_trace(go.Scatter(x=[x0, x1], y=[hi, hi], mode="lines", line=style, fill="tonexty",
                             fillcolor="rgba(44, 160, 44, 0.15)", legendgroup="band",
                             name=f"95 % χ² band [{lo:.2f}, {hi:.2f}]"))


def nees_plot(ev: evaluate.Evaluation) -> go.Figure:
    """Return each arm's NEES (dimensionless, log scale) over the gap against the χ² band.

    The 95 % band of one epoch's NEES (dof: the state dimension).
    """
    g = ev.gap
    dof = g.truth.shape[1]
    lo, hi = metrics.chi2_bounds(dof)
    hours = _hours(g.t, float(g.t[0]))
    fig = go.Figure()
    _band(fig, float(hours[0]), float(hours[-1]), lo, hi)
    for name in ArmName:
        sc = g.scores.get(name)
        if sc is None or sc.nees is None:
            continue
        fig.add_trace(go.Scatter(x=hours, y=np.maximum(sc.nees, 1e-6), mode="lines",
                                 line={"color": COLORS[name]}, name=str(name)))
    fig.update_yaxes(type="log", title_text="NEES [-]", exponentformat="power", dtick=1)
    fig.update_xaxes(title_text="hours into the gap [h]")
    fig.update_layout(title=f"NEES over the gap against the 95 % χ² band ({dof} dof)",
                      height=450)
    return fig


def nis_plot(data: evaluate.BagData) -> go.Figure | None:
    """Return the filter's NIS (dimensionless, log scale) at each fused epoch over the run.

    Sensor and forecast updates apart, against the 95 % χ² band of one update's NIS (dof:
    the measurement dimension); None without fused epochs. Epochs with NIS 0 (the initial
    orbit determination: no innovation) are left out.
    """
    est = [e for e in data.estimates
           if e.update_source != types.UpdateSource.NONE and e.nis > 0]
    if not est:
        return None
    dof = len(data.measurements[0].z) if data.measurements else 3
    lo, hi = metrics.chi2_bounds(dof)
    t0 = min(e.t for e in est)
    fig = go.Figure()
    _band(fig, 0.0, float(_hours(np.array([est[-1].t]), t0)[0]), lo, hi)
    for source, label, color in ((types.UpdateSource.SENSOR, "sensor update", "#1f77b4"),
                                 (types.UpdateSource.FORECAST, "forecast update",
                                  COLORS[ArmName.DMD_EKF])):
        sel = [e for e in est if e.update_source == source]
        if sel:
            fig.add_trace(go.Scatter(x=_hours(np.array([e.t for e in sel]), t0),
                                     y=[e.nis for e in sel], mode="markers",
                                     marker={"size": 3, "color": color}, name=label))
    fig.update_yaxes(type="log", title_text="NIS [-]", exponentformat="power", dtick=1)
    fig.update_xaxes(title_text="hours since the first estimate [h]")
    fig.update_layout(title=f"NIS of the filter against the 95 % χ² band ({dof} dof; "
                            f"[{lo:.2f}, {hi:.2f}])", height=400)
    return fig


def _table(header: list[str], rows: list[list[str]]) -> str:
    """Return an HTML table (cells escaped)."""
    head = "".join(f"<th>{html.escape(h)}</th>" for h in header)
    body = "".join("<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in r) + "</tr>"
                   for r in rows)
    return f'<table class="arms"><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>'


def arms_table(ev: evaluate.Evaluation) -> str:
    """Return the arms table of `evaluate.table` in HTML, with its notes."""
    g = ev.gap
    rows = evaluate.arm_rows(g)
    lo, hi = metrics.chi2_bounds(g.truth.shape[1])
    notes = (f"gap: {len(g.t)} epochs; live DMD-EKF estimates at {100 * g.coverage:.0f} % of "
             f"them" + (f"; dmd_ekf at the other {g.predicted} scored from the filter's "
                        "prediction" if g.predicted else "")
             + f". A consistent filter's per-epoch NEES lies in [{lo:.2f}, {hi:.2f}] 95 % of "
               f"the time. Settings: {ev.settings.origin}.")
    return (_table(list(evaluate.ARM_COLUMNS), rows)
            + f'<p class="note">{html.escape(notes)}</p>')


def passes_table(passes: PassReport) -> str:
    """Return the per-pass table of a station network's run (`PassReport`) in HTML."""
    rows = [[f"{(t_end - passes.t_start) / 3600:.2f}", who, str(n), f"{err:.3f}",
             f"{sig:.3f}"] for t_end, who, n, err, sig in passes.passes]
    lo, hi = passes.nees_band
    notes = (f"through the run ({len(passes.nees)} truth epochs): position error mean "
             f"{np.mean(passes.pos_err_km):.3f} km, max {np.max(passes.pos_err_km):.3f} km; "
             f"the per-epoch 95 % NEES band [{lo:.2f}, {hi:.2f}] holds "
             f"{100 * passes.nees_in_band:.0f} % of epochs.")
    return (_table(["pass end [h after start]", "stations", "measurements",
                    "position error after the pass [km]", "its σ [km]"], rows)
            + f'<p class="note">{html.escape(notes)}</p>')


def figures(data: evaluate.BagData, ev: evaluate.Evaluation) -> list[go.Figure]:
    """Return the report's figures, in page order (those without data left out)."""
    figs = [orbit_3d(data, ev), ground_track(data, run_stations(ev.settings.estimator)),
            arm_errors(ev), forecasts(data), nees_plot(ev), nis_plot(data)]
    return [f for f in figs if f is not None]


def build(data: evaluate.BagData, ev: evaluate.Evaluation,
          title: str = "ssa_fusion report") -> str:
    """Return the page: figures (plotly.js inlined once, with the first) and tables."""
    parts = [f"<h1>{html.escape(title)}</h1>", "<h2>Arms over the gap</h2>", arms_table(ev)]
    if ev.passes is not None:
        parts += ["<h2>After each pass</h2>", passes_table(ev.passes)]
    for i, fig in enumerate(figures(data, ev)):
        fig.update_layout(template="plotly_white")
        parts.append(fig.to_html(full_html=False, include_plotlyjs=i == 0, config=CONFIG))
    return ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            f"<title>{html.escape(title)}</title>{STYLE}</head>\n<body>{ERROR_HOOK}\n"
            + "\n".join(parts) + "\n</body></html>\n")


def write(data: evaluate.BagData, ev: evaluate.Evaluation, path: Path,
          title: str = "ssa_fusion report") -> None:
    """Write the page (`build`) to `path` (UTF-8)."""
    path.write_text(build(data, ev, title), encoding="utf-8")
