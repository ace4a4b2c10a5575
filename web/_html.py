"""Every HTML and markdown text the dashboard shows, built in this one module.

Pure functions of the contract's documents and the dashboard's records (no viser): the view's
parts hand them what they show and assign the string to a GUI handle. Every value that comes from
outside (ids, messages, names) is escaped here.
"""

from __future__ import annotations

import datetime as _dt
import html
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from contract import AlarmDocument, ModeMap, StatusDocument, StructuresDocument, StructureSummaryDocument

from ._data import LoadsRecord, WindowRecord

if TYPE_CHECKING:
    from ._context import DashboardStats
    from ._feed import Estimate, Snapshot

__all__ = [
    "HeaderInfo",
    "MARKER_LEGEND",
    "SPECTRA_INTRO",
    "alarms_html",
    "angles_html",
    "fmt_time",
    "header_html",
    "hot_spots_html",
    "level_badge",
    "message_html",
    "orbit_intro",
    "overview_html",
    "rates_text",
    "severity",
    "status_html",
    "trend_info_html",
]

#: Sensor marker colours by state (RGB); the 3-D markers use the same.
STATE_COLOURS = {
    "ok": (40, 167, 69),
    "degraded": (255, 170, 0),
    "rejected": (220, 38, 38),
    "unknown": (140, 140, 140),
}
OVERVIEW_ROWS = 60
ALARM_ROWS = 30

SPECTRA_INTRO = ("Amplitude spectra of the deformation variables b<sub>χ</sub> (latest window, µm, log scale). "
                 "Solid spike: tracked eigenfrequency; dashed spike: baseline.")
MODES_SHOWN = "**Modes shown** (spectra and trends)"
MARKER_LEGEND = ("Marker colours: <span style='color:#28a745'>●</span> ok, <span style='color:#ffaa00'>●</span> degraded, "
                 "<span style='color:#dc2626'>●</span> rejected samples. Circles: IMUs, squares: ToFs, diamonds: strain gauges.")
LOADS_INTRO = ("Virtual strain and nominal stress from the estimated curvature (ε = −c κ, σ = E ε) at the hot spots and "
               "along the beam; Palmgren–Miner damage on each hot spot's S–N curve (with its stress concentration and "
               "partial factors). Remaining life = (1 − D) / damage rate, its band from the windows' scatter.")
_TONES = {"info": "#333", "ok": "#15803d", "warn": "#b45309", "error": "#dc2626"}


def message_html(text: str, tone: str = "info") -> str:
    """One short paragraph (``tone``: info, ok, warn or error)."""
    if tone not in _TONES:
        raise ValueError(f"tone={tone!r} must be one of {sorted(_TONES)}")
    return f"<p style='color:{_TONES[tone]};font-size:12px'>{html.escape(text)}</p>"


def fmt_time(t: float | None) -> str:
    """UNIX seconds as UTC clock time; small values (seconds since the start) as seconds."""
    if t is None or not math.isfinite(t):
        return "–"
    if t > 1e9:
        return _dt.datetime.fromtimestamp(t, tz=_dt.timezone.utc).strftime("%Y-%m-%d %H:%M:%S UTC")
    return f"{t:.1f} s"


def _fmt(v: Any, fmt: str = "{:.3g}", none: str = "–") -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return none
    if isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool):
        return fmt.format(v)
    return html.escape(str(v))


def level_badge(level: str | None) -> str:
    """A chart level's badge; "not charted" for a mode without a chart (no baseline, too few cycles)."""
    if level is None:
        return "<span style='color:#888'>not charted</span>"
    colours = {"alarm": ("#dc2626", "white"), "warning": ("#ffaa00", "black"), "ok": ("#15803d", "white")}
    bg, fg = colours.get(level, ("#888", "white"))
    return f"<span style='background:{bg};color:{fg};padding:0 5px;border-radius:3px'>{html.escape(level)}</span>"


def _rgb(state: Any) -> str:
    r, g, b = STATE_COLOURS.get(str(state), STATE_COLOURS["unknown"])
    return f"rgb({r},{g},{b})"


# -- the header -------------------------------------------------------------------------------


@dataclass(frozen=True)
class HeaderInfo:
    """What the header line shows: the label, the structure shown (a fleet's), whether this
    browser paused, and whether φ is a state (not for a clamp)."""

    label: str
    fleet: bool
    structure_id: str | None = None
    summary: StructureSummaryDocument | None = None
    paused: bool = False
    clamped: bool = False


def _title(h: HeaderInfo) -> str:
    """The label; for a fleet, the structure shown with its state and lag (as the overview lists it)."""
    title = f"<b>{html.escape(h.label)}</b>"
    if not h.fleet or h.structure_id is None:
        return title
    extra = ""
    if h.summary is not None:
        lag = "" if h.summary.lag_s is None else f", lag {h.summary.lag_s:.1f} s"
        extra = f" ({html.escape(h.summary.state)}{lag})"
    return f"{title}<br><b style='font-size:14px'>Structure {html.escape(h.structure_id)}</b>{extra}"


def rates_text(snap: "Snapshot") -> str:
    """The estimator's rate (estimates per second of data), its pace against real time and how
    often the picture gets a new state (the live view is a decimated copy, not every estimate)."""
    drawn = f"drawn {snap.estimate_rate_hz:.0f} Hz"
    if snap.filter_rate_hz is None:
        return f"estimates: waiting for the filter's progress · {drawn}"
    return f"estimates {snap.filter_rate_hz:.0f} Hz · {snap.realtime_factor:.1f}× real time · {drawn}"


def _motion(h: HeaderInfo, snap: "Snapshot", est: "Estimate | None") -> tuple[str, str | None]:
    """(the motion line, the service's progress line or None)."""
    # what the service is doing now (compiling, calibrating at rest, waiting for the first window, ...)
    progress = None if snap.status is None else getattr(snap.status.service, "progress", None)
    if est is None:
        return (html.escape(progress) if progress else "waiting for estimates"), None
    s = est.state
    phi = "φ ≡ 0 (clamped)" if h.clamped else f"φ = {1e3 * s.phi:+.2f} mrad"
    return (f"t = {fmt_time(est.t_s)} · d = {1e3 * s.d:+.1f} mm · {phi} · "
            f"b = [{', '.join(f'{v:+.2e}' for v in s.b)}]"), progress


def _alarm_badges(alarms: Sequence[AlarmDocument]) -> str:
    active = [a for a in alarms if a.active]
    n_alarm = sum(1 for a in active if a.level == "alarm")
    n_warn = len(active) - n_alarm
    pill = "padding:1px 6px;border-radius:4px"
    warn = f"<span style='background:#ffaa00;color:black;{pill}'>{n_warn} warning</span>"
    if n_alarm:
        badge = f"<span style='background:#dc2626;color:white;{pill}'>{n_alarm} ALARM</span>"
        return badge + (f" {warn}" if n_warn else "")
    if n_warn:
        return warn
    return f"<span style='background:#15803d;color:white;{pill}'>no active alarms</span>"


def header_html(h: HeaderInfo, snap: "Snapshot | None", est: "Estimate | None") -> str:
    """The line above the controls: title, LIVE/PAUSED, alarm badges, the drawn estimate, rates,
    degraded sensors and the service's progress (``snap`` None: nothing read yet)."""
    if snap is None:
        waiting = "Choose a structure (loading the fleet…)" if h.fleet else "Connecting to the data…"
        return f"<div style='font-size:13px'>{_title(h)}<br>{waiting}</div>"
    live = ("<span style='color:#b45309;font-weight:bold'>■ PAUSED</span>" if h.paused
            else "<span style='color:#15803d;font-weight:bold'>● LIVE</span>")
    motion, progress = _motion(h, snap, est)
    if snap.status is not None:
        degraded = list(snap.status.degraded_sensors)
    else:
        degraded = [t for t, v in snap.estimate.sensor_states.items() if v != "ok"] if snap.estimate is not None else []
    sensors = (f"<span style='color:#b45309'>degraded/rejected: {html.escape(', '.join(degraded))}</span>"
               if degraded else "all sensors ok")
    error = f"<br><span style='color:#dc2626'>service: {html.escape(snap.status_error)}</span>" if snap.status_error else ""
    return (
        f"<div style='font-size:12.5px;line-height:1.45'>{_title(h)} {live} {_alarm_badges(snap.alarms)}<br>"
        f"{motion}<br>{rates_text(snap)} · {sensors}{error}"
        f"{'' if not progress else '<br><i>' + html.escape(progress) + '</i>'}</div>"
    )


# -- trends, alarms, status -------------------------------------------------------------------


def trend_info_html(w: WindowRecord, count: int, mode_map: ModeMap) -> str:
    """The latest window's figures per mode and its curvature-change index."""
    cells = []
    for m in mode_map.modes:
        if m not in w.frequency_hz:
            continue
        zeta = w.damping_ratio.get(m)
        cells.append(
            f"<tr><td>{html.escape(mode_map.mode_label(m))}</td><td>{_fmt(w.frequency_hz.get(m), '{:.4f}')}</td>"
            f"<td>{_fmt(None if zeta is None else 100 * zeta, '{:.2f}')}</td>"
            f"<td>{_fmt(w.score_sigma.get(m), '{:+.1f}')}</td><td>{level_badge(w.level.get(m))}</td></tr>"
        )
    where = ""
    if w.curvature_eta_m is not None:
        where = f" — largest change at η = {w.curvature_eta_m:.2f} m ({html.escape(w.curvature_third or '')} third)"
    trusted = "" if w.trusted is None else (", trusted" if w.trusted else ", untrusted")
    return (
        f"<div style='font-size:12px'><b>Latest window</b> {fmt_time(w.start_s)} → {fmt_time(w.end_s)} "
        f"({html.escape(w.kind or '–')}{trusted}), T = {_fmt(w.temperature_c, '{:.1f}')} °C, {count} windows stored."
        "<table style='width:100%;font-size:12px'><tr><th>mode</th><th>f Hz</th><th>ζ %</th><th>score σ</th><th>chart</th></tr>"
        + "".join(cells)
        + f"</table>Curvature-change index {_fmt(w.curvature_total, '{:.3g}')}"
        f" (score {_fmt(w.curvature_score_sigma, '{:+.1f}')} σ, {level_badge(w.curvature_level)}){where}</div>"
    )


def _alarm_style(a: AlarmDocument) -> str:
    if not a.active:
        return "color:#777"
    return "background:#fee2e2" if a.level == "alarm" else "background:#fef3c7"


def alarms_html(alarms: Sequence[AlarmDocument], label_of: Callable[[AlarmDocument], str]) -> str:
    """The alarm list, newest first (at most ``ALARM_ROWS``); ``label_of`` names an alarm's chart."""
    if not alarms:
        return "<p>No alarms.</p>"
    rows = []
    for a in alarms[:ALARM_ROWS]:
        state = "active" if a.active else "cleared"
        if a.acknowledged:
            by = f" by {a.acknowledged_by}" if a.acknowledged_by else ""
            state += f", acknowledged{by} {fmt_time(a.acknowledged_at_s)}"
        rows.append(
            f"<tr style='{_alarm_style(a)}'><td>#{a.id}</td><td>{level_badge(a.level)}</td>"
            f"<td>{html.escape(label_of(a))}</td><td>{html.escape(state)}</td><td>{fmt_time(a.raised_at_s)}</td>"
            f"<td>{html.escape(a.message)}</td></tr>"
        )
    active = sum(1 for a in alarms if a.active)
    return (
        f"<div style='font-size:12px'><b>{active} active</b>, {len(alarms)} in the list."
        "<table style='width:100%;font-size:12px;border-collapse:collapse'>"
        "<tr><th>id</th><th>level</th><th>chart</th><th>state</th><th>since</th><th>message</th></tr>"
        + "".join(rows) + "</table></div>"
    )


def _service_html(status: StatusDocument) -> list[str]:
    parts = []
    service = status.service
    error = ""
    if service.pipeline_errors:
        now = ", now: " + html.escape(service.pipeline_error) if service.pipeline_error else " (recovered)"
        error = f" · <span style='color:#dc2626'>{service.pipeline_errors} failed batches{now}</span>"
    parts.append(f"<p><b>Service</b> {html.escape(service.version)} · up {_fmt(service.uptime_s, '{:.0f}')} s{error}</p>")
    if status.sources:
        rows = "".join(
            f"<tr><td>{html.escape(s.id)}</td><td>{html.escape(s.kind)}</td>"
            f"<td>{html.escape(s.state)}</td><td>{_fmt(s.rate_hz, '{:.0f}')}</td>"
            f"<td>{_fmt(s.latency_s, '{:.3f}')}</td><td>{_fmt(s.messages, '{:.0f}')}</td>"
            f"<td>{_fmt(s.dropped, '{:.0f}')}</td><td>{_fmt(s.rejected, '{:.0f}')}</td></tr>"
            for s in status.sources
        )
        parts.append(
            "<table style='width:100%;font-size:12px'><tr><th>source</th><th>kind</th><th>state</th><th>msg/s</th>"
            "<th>latency s</th><th>messages</th><th>dropped</th><th>rejected</th></tr>" + rows + "</table>"
        )
    p = status.pipeline
    parts.append(
        f"<p><b>Pipeline</b> samples {p.samples} · estimates {p.estimates} ({html.escape(p.estimator.state)}) · "
        f"windows {p.windows_committed} committed, {p.windows_skipped_warmup} warm-up, "
        f"{p.windows_skipped_incomplete} incomplete · queue {p.queue_depth}/{p.queue_capacity} · "
        f"latency {_fmt(p.pipeline_latency_s, '{:.3f}')} s · {_fmt(p.realtime_factor, '{:.1f}')}× real time</p>"
    )
    return parts


def _health_html(status: StatusDocument) -> list[str]:
    parts = []
    sinks = [f"{html.escape(name)}: {sink.errors} ({html.escape(', '.join(f'{k} {v}' for k, v in sink.errors_by_kind.items()))})"
             for name, sink in status.sinks.items() if sink.errors]
    if sinks:
        parts.append(f"<p><b>Sink failures</b> <span style='color:#b45309'>{'; '.join(sinks)}</span></p>")
    if status.sensors:
        cells = " ".join(f"<span style='color:{_rgb(v)}'>●</span>&nbsp;{html.escape(t)}" for t, v in sorted(status.sensors.items()))
        parts.append(f"<p><b>Sensors</b> {cells}</p>")
    th = status.thresholds
    parts.append(
        f"<p><b>Baseline</b> {html.escape(status.baseline.state)} · charts: frequency warning "
        f"{th.frequency.warning_sigma:g} σ, alarm {th.frequency.alarm_sigma:g} σ; curvature warning "
        f"{th.curvature.warning_sigma:g} σ, alarm {th.curvature.alarm_sigma:g} σ</p>"
    )
    st = status.storage
    parts.append(f"<p><b>Storage</b> {html.escape(st.db)} · schema {st.schema_version} · {st.trend_rows} trend rows</p>")
    return parts


def status_html(snap: "Snapshot", stats: "DashboardStats") -> str:
    """The Status tab: the service, its sources and pipeline, sinks, sensors, baseline, storage,
    and the dashboard's own figures."""
    parts = []
    if snap.status_error:
        parts.append(f"<p style='color:#dc2626'>Service status unavailable: {html.escape(snap.status_error)}</p>")
    if snap.status is None:
        parts.append("<p>No status from the service yet.</p>")
    else:
        parts += _service_html(snap.status) + _health_html(snap.status)
    parts.append(
        f"<p style='color:#666'>Dashboard: {stats.clients} browser(s), {1 / max(stats.last_frame_s, 1e-3):.0f} frames/s "
        f"possible (last frame {1e3 * stats.last_frame_s:.1f} ms), states arriving at {snap.estimate_rate_hz:.0f} Hz.</p>"
    )
    return "<div style='font-size:12px'>" + "".join(parts) + "</div>"


# -- a fleet's overview -----------------------------------------------------------------------

#: Sort order of the overview: what needs an operator first.
_RANK = {"failed": 0, "alarm": 1, "degraded": 2, "warning": 3, "starting": 4, "stopped": 5, "finished": 6, "running": 7}
_ROW_STYLE = {"failed": "background:#fecaca", "alarm": "background:#fee2e2", "degraded": "background:#fef3c7",
              "warning": "background:#fef9c3"}
_BADGE = {"failed": ("#7f1d1d", "white"), "alarm": ("#dc2626", "white"), "degraded": ("#b45309", "white"),
          "warning": ("#ffaa00", "black"), "running": ("#15803d", "white"), "starting": ("#64748b", "white"),
          "finished": ("#334155", "white"), "stopped": ("#334155", "white")}


def severity(s: StructureSummaryDocument) -> str:
    """``failed``, ``alarm`` / ``warning`` (an active alarm of that level), ``degraded``, or the state."""
    if s.state == "failed":
        return "failed"
    levels = set(s.active_alarms.values())
    if "alarm" in levels:
        return "alarm"
    if s.state == "degraded":
        return "degraded"
    if "warning" in levels:
        return "warning"
    return s.state


def severity_key(s: StructureSummaryDocument) -> tuple:
    """Sort key: what needs an operator first, then the largest lag, then the id."""
    return (_RANK.get(severity(s), 9), -(s.lag_s or 0.0), s.id)


def _overview_row(s: StructureSummaryDocument, selected: str | None) -> str:
    bg, fg = _BADGE.get(s.state, ("#888", "white"))  # the state's badge; the row's colour: its severity
    alarms = ", ".join(f"{html.escape(c)}: {html.escape(v)}" for c, v in sorted(s.active_alarms.items())) or "–"
    name = html.escape(s.id)
    if s.id == selected:
        name = f"<b>▶ {name}</b>"
    why = f" title='{html.escape(s.error)}'" if s.error else ""
    return (
        f"<tr style='{_ROW_STYLE.get(severity(s), '')}'{why}><td>{name}</td>"
        f"<td><span style='background:{bg};color:{fg};padding:0 4px;border-radius:3px'>{html.escape(s.state)}</span></td>"
        f"<td style='text-align:right'>{'–' if s.lag_s is None else f'{s.lag_s:.1f}'}</td>"
        f"<td style='text-align:right'>{s.windows}</td><td>{alarms}</td></tr>"
    )


def overview_html(doc: StructuresDocument | None, error: str | None, selected: str | None) -> str:
    """The overview: counts by state, then one row per structure, problems first (failed, alarm,
    degraded, warning; then by lag), the selected one in bold; at most ``OVERVIEW_ROWS`` rows."""
    if doc is None:
        return f"<p style='font-size:12px'>{html.escape(error or 'Waiting for the fleet…')}</p>"
    rows = sorted(doc.structures, key=severity_key)
    counts: dict[str, int] = {}
    for s in rows:
        counts[severity(s)] = counts.get(severity(s), 0) + 1
    summary = " · ".join(
        f"<span style='color:{_BADGE.get(k, ('#333',))[0]}'><b>{n}</b> {html.escape(k)}</span>"
        for k, n in sorted(counts.items(), key=lambda kv: _RANK.get(kv[0], 9))
    )
    cells = [_overview_row(s, selected) for s in rows[:OVERVIEW_ROWS]]
    more = ""
    if len(rows) > OVERVIEW_ROWS:
        rest = rows[OVERVIEW_ROWS:]
        states = sorted({severity(s) for s in rest}, key=lambda k: _RANK.get(k, 9))
        more = f"<p>… {len(rest)} more ({html.escape(', '.join(states))}): choose one above.</p>"
    stale = f"<p style='color:#dc2626'>{html.escape(error)}</p>" if error else ""
    return (
        f"<div style='font-size:12px'><b>{len(rows)} structures</b>: {summary}{stale}"
        "<table style='width:100%;font-size:12px;border-collapse:collapse'>"
        "<tr><th style='text-align:left'>structure</th><th>state</th><th>lag s</th><th>windows</th>"
        "<th style='text-align:left'>active alarms</th></tr>" + "".join(cells) + f"</table>{more}</div>"
    )


# -- loads ------------------------------------------------------------------------------------

_VERDICT = {"finite": ("#15803d", "finite life"), "no_damage_below_cutoff": ("#2563eb", "no damage: below the cut-off"),
            "exhausted": ("#dc2626", "life exhausted"), "no_data": ("#888", "no data yet")}


def _years(v: float | None) -> str:
    """A life in years, or in days or hours when it is shorter than a year or a day."""
    if v is None or not math.isfinite(v):
        return "–"
    if v >= 100:
        return f"{v:,.0f} years"
    if v >= 1:
        return f"{v:.1f} years"
    days = v * 365.25
    return f"{days:.1f} days" if days >= 1 else f"{24 * days:.1f} hours"


def _remaining(rec: Any) -> str:
    """Remaining life with its band; the verdict instead of a number where there is none."""
    colour, words = _VERDICT.get(rec.verdict, ("#888", rec.verdict))
    if rec.verdict != "finite" or rec.remaining_years is None:
        return f"<span style='color:{colour}'>{html.escape(words)}</span>"
    band = ""
    if rec.remaining_band_years and len(rec.remaining_band_years) == 2:
        lo, hi = rec.remaining_band_years
        band = f" <span style='color:#666'>({_years(lo)} – {_years(hi)})</span>"
    design = rec.design_life_years
    warn = design is not None and rec.remaining_years is not None and rec.remaining_years < design
    style = "color:#dc2626;font-weight:bold" if warn else ""
    return f"<span style='{style}'>{_years(rec.remaining_years)}</span>{band}"


def hot_spots_html(record: LoadsRecord, error: str | None = None) -> str:
    """The Loads tab's table: per hot spot its S–N curve, the consumed life D, the damage rate,
    the remaining life with its band (or why there is none), the latest DELs and the largest range."""
    stale = f"<p style='color:#dc2626'>{html.escape(error)}</p>" if error else ""
    if not record.hot_spots:
        return f"<div style='font-size:12px'>{stale}<p>No loads yet: the first analysis window brings them.</p></div>"
    rows = []
    grey = "<span style='color:#666'>"
    for h in record.hot_spots:
        dels = "<br>".join(f"DEL<sub>{html.escape(m)}</sub> {_fmt(None if v is None else v / 1e6, '{:.2f}')}"
                           for m, v in sorted(h.del_pa.items(), key=lambda kv: float(kv[0])))
        peak = _fmt(None if h.max_range_pa is None else h.max_range_pa / 1e6, "{:.2f}")
        rows.append(
            f"<tr><td><b>{html.escape(h.name)}</b><br>{grey}η = {h.position_m:.2f} m · {html.escape(h.curve)}</span></td>"
            f"<td>{_fmt(h.consumed, '{:.3e}')}<br>{grey}{_fmt(h.rate_per_year, '{:.2e}')} /year</span></td>"
            f"<td>{_remaining(h)}</td><td>{dels}<br>{grey}max {peak}</span></td></tr>"
        )
    design = f"design life {_years(record.design_life_years)} · " if record.design_life_years else ""
    return (
        f"<div style='font-size:12px'>{stale}<b>{len(record.hot_spots)} hot spot(s)</b> · {design}"
        f"{record.windows} window(s) counted{' (the oldest left out)' if record.truncated else ''}."
        "<table style='width:100%;font-size:12px;border-collapse:collapse'><tr><th style='text-align:left'>hot spot</th>"
        "<th>consumed D, rate</th><th>remaining life</th><th>latest window, MPa</th></tr>" + "".join(rows) + "</table></div>"
    )


def angles_html(hot_spots: list[Any], found: dict[str, float]) -> str:
    """Where around the section each hot spot of a biaxial beam sits (degrees from +ζ towards +ξ):
    its given angle, or for a girth weld (``angle_deg = "all"``) the worst point found so far."""
    rows = []
    for h in hot_spots:
        if h.angle_deg == "all":
            worst = found.get(h.name)
            at = "all around the section: worst at " + ("…" if worst is None else f"{worst:g}°") + " (of the live estimates)"
        else:
            at = f"at {float(h.angle_deg):g}°"
        rows.append(f"<li><b>{html.escape(h.name)}</b> (η = {h.position:.2f} m) {at}</li>")
    return ("<div style='font-size:12px'>Around the section (degrees from +ζ towards +ξ):<ul style='margin:2px 0'>"
            + "".join(rows) + "</ul></div>")


def orbit_intro(span_s: float) -> str:
    """The Orbit tab's introduction (markdown)."""
    return ("**Tip orbit**: the tip's deflection across the beam, ζ against ξ (mm, body frame), "
            f"over the last {span_s / 60:g} minutes; the newest position is the black dot.")
