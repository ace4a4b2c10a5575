"""A fleet's dashboard: what it reads from the service's port, and the overview it shows.

One poller thread reads, while a browser is connected, the overview (``structures_document``:
every structure's state, lag, windows and active alarms) every few seconds and, only for the structures some browser shows
(or has just chosen), their model once (``structure_model``: rig and unit deformations), their
estimates a few times a second (``live``), their status, alarms and, after a new window, their new
trend rows and spectra. A structure nobody shows any more is read no more at once and its feed
forgotten after ``DROP_AFTER_S``: the cost of a fleet of hundreds is the overview and the few
structures on screen.
"""

from __future__ import annotations

import html
import logging
import math
import threading
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from contract import AlarmDocument, StatusDocument, StructuresDocument, StructureSummaryDocument

from ._data import windows_from_trend_rows
from ._feed import StructureFeed

if TYPE_CHECKING:
    from ._dashboard import Dashboard

__all__ = ["FleetPoller", "overview_html", "severity"]

log = logging.getLogger(__name__)
TICK_S = 0.25
OVERVIEW_S = 3.0
LIVE_S = 0.25
STATUS_S = 2.0
ALARMS_S = 5.0
SPECTRA_S = 15.0  # at the latest (sooner after a new window)
RETRY_S = 5.0  # a structure whose model could not be read is tried again after this
SHOWN_S = 1.0  # a structure no browser asked for within this is not read (the views ask every frame)
DROP_AFTER_S = 30.0  # and its feed (its history) is forgotten after this
OVERVIEW_ROWS = 60

#: Sort order of the overview: what needs an operator first.
_RANK = {"failed": 0, "alarm": 1, "degraded": 2, "warning": 3, "starting": 4, "stopped": 5, "finished": 6, "running": 7}


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


def _sort_key(s: StructureSummaryDocument) -> tuple:
    return (_RANK.get(severity(s), 9), -(s.lag_s or 0.0), s.id)


_ROW_STYLE = {"failed": "background:#fecaca", "alarm": "background:#fee2e2", "degraded": "background:#fef3c7",
              "warning": "background:#fef9c3"}
_BADGE = {"failed": ("#7f1d1d", "white"), "alarm": ("#dc2626", "white"), "degraded": ("#b45309", "white"),
          "warning": ("#ffaa00", "black"), "running": ("#15803d", "white"), "starting": ("#64748b", "white"),
          "finished": ("#334155", "white"), "stopped": ("#334155", "white")}


def overview_html(doc: StructuresDocument | None, error: str | None, selected: str | None) -> str:
    """The overview: counts by state, then one row per structure, problems first (failed, alarm,
    degraded, warning; then by lag), the selected one in bold; at most ``OVERVIEW_ROWS`` rows."""
    if doc is None:
        return f"<p style='font-size:12px'>{html.escape(error or 'Waiting for the fleet…')}</p>"
    rows = sorted(doc.structures, key=_sort_key)
    counts: dict[str, int] = {}
    for s in rows:
        counts[severity(s)] = counts.get(severity(s), 0) + 1
    summary = " · ".join(
        f"<span style='color:{_BADGE.get(k, ('#333',))[0]}'><b>{n}</b> {html.escape(k)}</span>"
        for k, n in sorted(counts.items(), key=lambda kv: _RANK.get(kv[0], 9))
    )
    cells = []
    for s in rows[:OVERVIEW_ROWS]:
        sev = severity(s)
        bg, fg = _BADGE.get(s.state, ("#888", "white"))  # the state's badge; the row's colour: its severity
        alarms = ", ".join(f"{html.escape(c)}: {html.escape(v)}" for c, v in sorted(s.active_alarms.items())) or "–"
        name = html.escape(s.id)
        if s.id == selected:
            name = f"<b>▶ {name}</b>"
        why = f" title='{html.escape(s.error)}'" if s.error else ""
        cells.append(
            f"<tr style='{_ROW_STYLE.get(sev, '')}'{why}><td>{name}</td>"
            f"<td><span style='background:{bg};color:{fg};padding:0 4px;border-radius:3px'>{html.escape(s.state)}</span></td>"
            f"<td style='text-align:right'>{'–' if s.lag_s is None else f'{s.lag_s:.1f}'}</td>"
            f"<td style='text-align:right'>{s.windows}</td><td>{alarms}</td></tr>"
        )
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


@dataclass
class _Watch:
    """What the poller reads for one structure a browser shows."""

    feed: StructureFeed
    seen_s: float  # monotonic: last time a browser wanted it
    after: int = 0
    windows: int = -1  # the overview's committed windows when the rows and spectra were last read
    last: dict[str, float] = field(default_factory=dict)


class FleetPoller:
    """Reads the fleet's port for a ``Dashboard(fleet=True)`` (see the module docstring)."""

    def __init__(self, dash: "Dashboard") -> None:
        self.dash = dash
        self.service = dash.service
        self.lock = threading.Lock()
        self.overview: StructuresDocument | None = None
        self.overview_error: str | None = None
        self.overview_version = 0
        self._watches: dict[str, _Watch] = {}
        self._errors: dict[str, tuple[float, str]] = {}  # id -> (monotonic s, why its model could not be read)
        self._wanted: dict[str, float] = {}  # id -> monotonic s it was last asked for
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, name="shm-dashboard-fleet", daemon=True)
        self._last_overview = -math.inf
        self.polls: dict[str, int] = {}  # calls of the port by method (what the dashboard costs the service)

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread.is_alive() and threading.current_thread() is not self._thread:
            self._thread.join(timeout=5.0)

    # ------------------------------------------------------------------ for the views
    def ids(self) -> list[str]:
        doc = self.overview
        return [] if doc is None else [s.id for s in doc.structures]

    def summary(self, structure_id: str | None) -> StructureSummaryDocument | None:
        doc = self.overview
        if doc is None or structure_id is None:
            return None
        return next((s for s in doc.structures if s.id == structure_id), None)

    def feed(self, structure_id: str) -> StructureFeed | str | None:
        """The feed of ``structure_id`` (asked for: the poller builds it), the error why it cannot
        be drawn, or None while it is being read."""
        now = time.monotonic()
        with self.lock:
            self._wanted[structure_id] = now
            watch = self._watches.get(structure_id)
            if watch is not None:
                watch.seen_s = now
                return watch.feed
            error = self._errors.get(structure_id)
        return None if error is None else error[1]

    def greet(self, client: Any) -> None:
        """On connect: the structures with active alarms or failed, in one notification."""
        doc = self.overview
        if doc is None:
            return
        bad = [s for s in sorted(doc.structures, key=_sort_key) if severity(s) in ("failed", "alarm", "degraded", "warning")]
        if bad:
            client.add_notification(
                f"{len(bad)} structure(s) need attention",
                "; ".join(f"{s.id}: {severity(s)}" for s in bad[:5]) + (" …" if len(bad) > 5 else ""),
                color="red" if any(severity(s) in ("failed", "alarm") for s in bad) else "yellow",
                auto_close_seconds=None,
            )

    # ------------------------------------------------------------------ the thread
    def _call(self, name: str, *args: Any) -> Any:
        self.polls[name] = self.polls.get(name, 0) + 1
        return getattr(self.service, name)(*args)

    def _loop(self) -> None:
        while not self._stop.is_set():
            now = time.monotonic()
            try:
                if not self._looked_at(now):  # nobody looks: read nothing (at once when a browser comes)
                    self._last_overview = -math.inf
                    self._stop.wait(TICK_S)
                    continue
                if now - self._last_overview >= OVERVIEW_S:
                    self._last_overview = now
                    self._read_overview()
                self._build_wanted(now)
                with self.lock:
                    watches = list(self._watches.items())
                for sid, watch in watches:
                    if now - watch.seen_s > DROP_AFTER_S:
                        with self.lock:
                            self._watches.pop(sid, None)
                    elif now - watch.seen_s <= SHOWN_S:  # shown now: read; else only kept for a switch back
                        self._read_structure(sid, watch, now)
            except Exception:
                log.exception("fleet dashboard poll failed")
            self._stop.wait(TICK_S)

    def _looked_at(self, now: float) -> bool:
        """A browser is connected, or a structure was asked for just now."""
        with self.lock:
            asked = any(now - t <= SHOWN_S for t in self._wanted.values())
        return asked or self.dash.client_count > 0

    def _read_overview(self) -> None:
        try:
            doc = self._call("structures_document")
            if not isinstance(doc, StructuresDocument):
                raise TypeError(f"structures_document() returned {type(doc).__name__}")
            error = None
        except Exception as exc:
            doc, error = None, f"the fleet's overview could not be read: {type(exc).__name__}: {exc}"
        old = self.overview
        if doc is not None:
            self._notify_changes(old, doc)
            self.overview = doc
        self.overview_error = error
        self.overview_version += 1

    def _notify_changes(self, old: StructuresDocument | None, new: StructuresDocument) -> None:
        """Every browser hears of a structure that newly fails or raises an alarm (any structure)."""
        if old is None:
            return
        before = {s.id: s for s in old.structures}
        messages = []
        for s in new.structures:
            prev = before.get(s.id)
            if prev is None:
                continue
            if s.state == "failed" and prev.state != "failed":
                messages.append((f"{s.id} failed", s.error or "-", "red", None))
            for chart, level in sorted(s.active_alarms.items()):
                if prev.active_alarms.get(chart) != level:
                    messages.append((f"{s.id}: {'ALARM' if level == 'alarm' else 'Warning'} ({chart})",
                                     f"{chart} chart at {level} level", "red" if level == "alarm" else "yellow",
                                     None if level == "alarm" else 30.0))
            for chart in sorted(set(prev.active_alarms) - set(s.active_alarms)):
                messages.append((f"{s.id}: {chart} alarm cleared", "-", "green", 10.0))
        if not messages:
            return
        if len(messages) > 3:  # many at once (a fleet): one notification naming them
            red = any(color == "red" for _, _, color, _ in messages)
            messages = [(f"{len(messages)} changes in the fleet", "; ".join(title for title, *_ in messages[:8])
                         + (" …" if len(messages) > 8 else ""), "red" if red else "yellow", None if red else 30.0)]
        for client in list(self.dash.server.get_clients().values()):
            for title, body, color, close in messages:
                try:
                    client.add_notification(title, body, color=color, auto_close_seconds=close)
                except Exception:
                    log.exception("notification to client %s failed", client.client_id)

    def _build_wanted(self, now: float) -> None:
        with self.lock:
            wanted = [sid for sid, t in self._wanted.items() if now - t <= DROP_AFTER_S and sid not in self._watches]
            for sid in [sid for sid, t in self._wanted.items() if now - t > DROP_AFTER_S]:
                del self._wanted[sid]
        for sid in wanted:
            error = self._errors.get(sid)
            if error is not None and now - error[0] < RETRY_S:
                continue
            try:
                model = self._call("structure_model", sid)
                feed = StructureFeed(rig=model.rig, units=model.units, layout=model.layout, stations=model.stations,
                                     structure_id=sid)
            except Exception as exc:
                self._errors[sid] = (now, f"{sid}: cannot be drawn: {type(exc).__name__}: {exc}")
                continue
            self._errors.pop(sid, None)
            watch = _Watch(feed=feed, seen_s=now)
            self._read_rows(sid, watch)
            with self.lock:
                self._watches[sid] = watch

    def _read_rows(self, sid: str, watch: _Watch) -> None:
        """The structure's trend rows after the last window drawn (all of them the first time)."""
        last = watch.feed.last_window_start_s
        try:
            rows = self._call("structure_trends", sid, None if last is None else last + 1e-3, None) or []
            records = windows_from_trend_rows(rows)
            if records:
                watch.feed.add_windows(records)
        except Exception as exc:
            log.warning("structure_trends(%s) failed: %s", sid, exc)

    def _due(self, watch: _Watch, what: str, period: float, now: float) -> bool:
        if now - watch.last.get(what, -math.inf) >= period:
            watch.last[what] = now
            return True
        return False

    def _read_structure(self, sid: str, watch: _Watch, now: float) -> None:
        feed, store = watch.feed, watch.feed.store
        showing = [v for v in self.dash.views() if v.feed is feed]
        paused = bool(showing) and all(v.paused for v in showing)  # every browser showing it paused: no live reads
        if not paused and self._due(watch, "live", LIVE_S, now):
            try:
                doc = self._call("live", sid, watch.after)
                feed.add_live(doc, now)
                watch.after = doc.seq
            except Exception as exc:
                log.debug("live(%s) failed: %s", sid, exc)
        if self._due(watch, "status", STATUS_S, now):
            try:
                status = self._call("structure_status", sid)
                error = None if isinstance(status, StatusDocument) else f"status returned {type(status).__name__}"
            except Exception as exc:
                status, error = None, f"{type(exc).__name__}: {exc}"
            store.set_status(now, status, error)
        if self._due(watch, "alarms", ALARMS_S, now):
            try:
                for item in self._call("structure_alarms", sid) or []:
                    if isinstance(item, AlarmDocument):
                        store.upsert_alarm(item)
            except Exception as exc:
                log.debug("structure_alarms(%s) failed: %s", sid, exc)
        summary = self.summary(sid)
        windows = summary.windows if summary is not None else watch.windows
        if paused:
            return
        if windows != watch.windows or self._due(watch, "spectra", SPECTRA_S, now):
            watch.windows = windows
            watch.last["spectra"] = now
            self._read_rows(sid, watch)
            try:
                spectrum = self._call("structure_spectra", sid)
                if spectrum is not None:
                    feed.push_spectra(spectrum)
            except Exception as exc:
                log.debug("structure_spectra(%s) failed: %s", sid, exc)
