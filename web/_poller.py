"""What the dashboard reads from the service's port, for one structure or a fleet alike.

One poller thread reads, while a browser is connected, the overview (``structures_document``:
every structure's state, lag, windows and active alarms) every few seconds and, only for the
structures some browser shows (or has just chosen), their model once (``structure_model``: rig
and unit deformations), their estimates a few times a second (``live``), their status and alarms
and, after a new window, their new trend rows, the window itself (``structure_window``: charts and
the curvature along the stations) and spectra, and for a rig with hot spots its fatigue
(``structure_fatigue``). A structure nobody shows any more is read no more at once and its feed
forgotten after ``DROP_AFTER_S``: the cost of a fleet of hundreds is the overview and the few
structures on screen. A service of one structure is read the same way (nothing is pushed).
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal, Protocol

from contract import AlarmDocument, ServicePort, StatusDocument, StructuresDocument, StructureSummaryDocument

from ._data import loads_record, windows_from_trend_rows
from ._feed import StructureFeed
from ._html import severity, severity_key

__all__ = ["PortPoller"]

log = logging.getLogger(__name__)
TICK_S = 0.25
OVERVIEW_S = 3.0
LIVE_S = 0.25
STATUS_S = 1.0
ALARMS_S = 2.0
SPECTRA_S = 15.0  # at the latest (sooner after a new window)
LOADS_S = 30.0  # at the latest (sooner after a new window)
LOADS_MIN_S = 5.0  # at the soonest
RETRY_S = 5.0  # a structure whose model could not be read is tried again after this
SHOWN_S = 1.0  # a structure no browser asked for within this is not read (the views ask every frame)
DROP_AFTER_S = 30.0  # and its feed (its history) is forgotten after this


class Watcher(Protocol):
    """A browser's view as the poller sees it: the feed it shows and whether it paused."""

    @property
    def feed(self) -> StructureFeed | None: ...

    @property
    def paused(self) -> bool: ...


@dataclass
class _Watch:
    """What the poller reads for one structure a browser shows."""

    feed: StructureFeed
    seen_s: float  # monotonic: last time a browser wanted it
    after: int = 0
    windows: int = -1  # the overview's committed windows when the rows and spectra were last read
    alarms_read: bool = False
    last: dict[str, float] = field(default_factory=dict)


@dataclass
class Notice:
    """A notification for the browsers (title, body, colour, seconds it stays; None: until closed)."""

    title: str
    body: str
    color: Literal["red", "yellow", "green", "blue"]
    close_s: float | None


def alarm_notice(rec: AlarmDocument) -> Notice:
    """An alarm of the structure shown newly raised or cleared."""
    mode = f" (mode {rec.mode})" if rec.mode is not None else ""
    if rec.active:
        title = f"{'ALARM' if rec.level == 'alarm' else 'Warning'} #{rec.id} raised{mode}"
        return Notice(title, rec.message or "-", "red" if rec.level == "alarm" else "yellow",
                      None if rec.level == "alarm" else 30.0)
    return Notice(f"Alarm #{rec.id} cleared{mode}", rec.message or "-", "green", 10.0)


def active_notice(alarms: Sequence[AlarmDocument]) -> Notice | None:
    """The active alarms no operator acknowledged yet, in one notice (None: there are none)."""
    active = [a for a in alarms if a.active and not a.acknowledged]
    if not active:
        return None
    return Notice(f"{len(active)} active alarm(s)", "; ".join(f"#{a.id} {a.level}: {a.message}" for a in active[:3]),
                  "red" if any(a.level == "alarm" for a in active) else "yellow", None)


def fleet_notices(old: StructuresDocument | None, new: StructuresDocument) -> list[Notice]:
    """A structure of the fleet that newly failed, raised or cleared an alarm (several: one notice)."""
    if old is None:
        return []
    before = {s.id: s for s in old.structures}
    notices = []
    for s in new.structures:
        prev = before.get(s.id)
        if prev is None:
            continue
        if s.state == "failed" and prev.state != "failed":
            notices.append(Notice(f"{s.id} failed", s.error or "-", "red", None))
        for chart, level in sorted(s.active_alarms.items()):
            if prev.active_alarms.get(chart) != level:
                notices.append(Notice(f"{s.id}: {'ALARM' if level == 'alarm' else 'Warning'} ({chart})",
                                      f"{chart} chart at {level} level", "red" if level == "alarm" else "yellow",
                                      None if level == "alarm" else 30.0))
        for chart in sorted(set(prev.active_alarms) - set(s.active_alarms)):
            notices.append(Notice(f"{s.id}: {chart} alarm cleared", "-", "green", 10.0))
    if len(notices) > 3:  # many at once (a fleet): one notification naming them
        red = any(n.color == "red" for n in notices)
        body = "; ".join(n.title for n in notices[:8]) + (" …" if len(notices) > 8 else "")
        notices = [Notice(f"{len(notices)} changes in the fleet", body, "red" if red else "yellow", None if red else 30.0)]
    return notices


class PortPoller:
    """Reads a ``contract.ServicePort`` for the dashboard (see the module docstring).

    Parameters
    ----------
    service : the running service's port.
    watchers : the connected browsers' views, now.
    notify : hands a notice to the browsers: ``notify(notice, feed)`` (``feed`` None: every
        browser; else those showing it).
    """

    def __init__(self, service: ServicePort, watchers: Callable[[], Sequence[Watcher]],
                 notify: Callable[[Notice, StructureFeed | None], None]) -> None:
        self.service = service
        self.fleet = bool(getattr(service, "fleet", False))
        self._watchers = watchers
        self._notify = notify
        self.lock = threading.Lock()
        self.overview: StructuresDocument | None = None
        self.overview_error: str | None = None
        self.overview_version = 0
        self._watches: dict[str, _Watch] = {}
        self._errors: dict[str, tuple[float, str]] = {}  # id -> (monotonic s, why its model could not be read)
        self._wanted: dict[str, float] = {}  # id -> monotonic s it was last asked for
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, name="shm-dashboard-poller", daemon=True)
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

    def greeting(self) -> Notice | None:
        """On connect: the structures that need attention (a fleet), or the active alarms of the one."""
        doc = self.overview
        if self.fleet and doc is not None:
            bad = [s for s in sorted(doc.structures, key=severity_key) if severity(s) in ("failed", "alarm", "degraded", "warning")]
            if not bad:
                return None
            return Notice(f"{len(bad)} structure(s) need attention",
                          "; ".join(f"{s.id}: {severity(s)}" for s in bad[:5]) + (" …" if len(bad) > 5 else ""),
                          "red" if any(severity(s) in ("failed", "alarm") for s in bad) else "yellow", None)
        with self.lock:
            watches = list(self._watches.values())
        return active_notice([a for w in watches if w.alarms_read for a in w.feed.snapshot().alarms])

    # ------------------------------------------------------------------ the thread
    def _call(self, name: str, *args: Any) -> Any:
        self.polls[name] = self.polls.get(name, 0) + 1
        return getattr(self.service, name)(*args)

    def _loop(self) -> None:
        while not self._stop.is_set():
            now = time.monotonic()
            try:
                self._tick(now)
            except Exception:
                log.exception("dashboard poll failed")
            self._stop.wait(TICK_S)

    def _tick(self, now: float) -> None:
        if not self._looked_at(now):  # nobody looks: read nothing (at once when a browser comes)
            self._last_overview = -math.inf
            return
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

    def _looked_at(self, now: float) -> bool:
        """A browser is connected, or a structure was asked for just now."""
        with self.lock:
            asked = any(now - t <= SHOWN_S for t in self._wanted.values())
        return asked or bool(self._watchers())

    def _read_overview(self) -> None:
        try:
            doc = self._call("structures_document")
            if not isinstance(doc, StructuresDocument):
                raise TypeError(f"structures_document() returned {type(doc).__name__}")
            error = None
        except Exception as exc:
            doc, error = None, f"the overview could not be read: {type(exc).__name__}: {exc}"
        if doc is not None:
            if self.fleet:  # every browser hears of any structure's change; one structure's alarms come with it
                for notice in fleet_notices(self.overview, doc):
                    self._notify(notice, None)
            self.overview = doc
        self.overview_error = error
        self.overview_version += 1

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
                                     structure_id=sid, units_xi=getattr(model, "units_xi", None))
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
        showing = [v for v in self._watchers() if v.feed is watch.feed]
        paused = bool(showing) and all(v.paused for v in showing)  # every browser showing it paused: no live reads
        if not paused and self._due(watch, "live", LIVE_S, now):
            self._read_live(sid, watch, now)
        if self._due(watch, "status", STATUS_S, now):
            self._read_status(sid, watch, now)
        if self._due(watch, "alarms", ALARMS_S, now):
            self._read_alarms(sid, watch)
        summary = self.summary(sid)
        windows = summary.windows if summary is not None else watch.windows
        if paused:
            return
        fresh = windows != watch.windows
        if fresh or self._due(watch, "spectra", SPECTRA_S, now):
            watch.windows = windows
            watch.last["spectra"] = now
            self._read_rows(sid, watch)
            self._read_window(sid, watch)
        # the fatigue document holds every window's trend: after a new window, but not more often than LOADS_MIN_S
        since = now - watch.last.get("loads", -math.inf)
        if watch.feed.rig.hot_spots and (since >= LOADS_S or (fresh and since >= LOADS_MIN_S)):
            watch.last["loads"] = now
            self._read_loads(sid, watch)

    def _read_live(self, sid: str, watch: _Watch, now: float) -> None:
        try:
            doc = self._call("live", sid, watch.after)
            watch.feed.add_live(doc, now)
            watch.after = doc.seq
        except Exception as exc:
            log.debug("live(%s) failed: %s", sid, exc)

    def _read_status(self, sid: str, watch: _Watch, now: float) -> None:
        try:
            status = self._call("structure_status", sid)
            error = None if isinstance(status, StatusDocument) else f"status returned {type(status).__name__}"
        except Exception as exc:
            status, error = None, f"{type(exc).__name__}: {exc}"
        watch.feed.store.set_status(now, status, error)

    def _read_alarms(self, sid: str, watch: _Watch) -> None:
        """The structure's alarms; one newly raised or cleared after the first read is a notice for
        the browsers showing it (a fleet's come with the overview)."""
        store = watch.feed.store
        try:
            for item in self._call("structure_alarms", sid) or []:
                if isinstance(item, AlarmDocument):
                    store.upsert_alarm(item)
                else:
                    log.warning("ignoring an alarm that is not a contract.AlarmDocument: %r", type(item).__name__)
        except Exception as exc:
            log.debug("structure_alarms(%s) failed: %s", sid, exc)
            return
        with store.lock:
            changed = list(store.notify)
            store.notify.clear()
        if not self.fleet:
            notices = [alarm_notice(a) for a in changed] if watch.alarms_read else [active_notice(store.alarms_tuple)]
            for notice in notices:
                if notice is not None:
                    self._notify(notice, watch.feed)
        watch.alarms_read = True

    def _read_window(self, sid: str, watch: _Watch) -> None:
        """The latest window (its charts and curvature along the stations) and its spectra."""
        for name, take in (("structure_window", watch.feed.add_window), ("structure_spectra", watch.feed.set_spectra)):
            try:
                doc = self._call(name, sid)
                if doc is not None:
                    take(doc)
            except Exception as exc:
                log.debug("%s(%s) failed: %s", name, sid, exc)

    def _read_loads(self, sid: str, watch: _Watch) -> None:
        try:
            record = loads_record(self._call("structure_fatigue", sid))
        except Exception as exc:
            watch.feed.set_loads(None, f"the loads could not be read: {type(exc).__name__}: {exc}")
            return
        watch.feed.set_loads(record)
