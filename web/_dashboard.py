"""The viser dashboard: live deformed beam, spectra, trends, alarms and status, of one
structure or of a fleet.

Threads: the service calls the ``push_*`` methods from its own threads; they validate, copy and
store the newest data under a lock and return at once. One render thread of the dashboard draws
the newest data into every connected browser at ``render_hz`` (updates assigned to existing
handles, grouped per client in ``client.atomic()``; nothing is re-created per frame, so memory
stays flat). It also polls the service for its status and alarm list. viser runs its own thread
and asyncio loop; GUI callbacks run on viser's threads.

Every browser (client) gets its own GUI and its own copy of the live scene, so one operator's
pause, overscale, mode choice or token never changes what another sees. The scene's static
parts (rail, reflector, grid) are shared for one structure.

A fleet (``fleet=True``): each browser chooses the structure it shows (its rig, scene, spectra,
trends and alarms are rebuilt on a switch; the rig's parts are then per browser) under an
overview of every structure; ``web._fleet.FleetPoller`` reads the service's port for the
overview and, only for the structures some browser shows, their estimates, status, rows and
spectra.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from typing import Any

import numpy as np
import viser

from contract import (
    SENSOR_STATES,
    AlarmDocument,
    ServicePort,
    SpectrumDocument,
    StateLayout,
    StatusDocument,
    WindowDocument,
    is_loopback,
)

from ._data import windows_from_trend_rows
from ._feed import Snapshot, StructureFeed, _Store  # noqa: F401  (_Store: the tests' rates)
from ._fleet import FleetPoller
from ._gate import TokenGate
from ._view import ClientView

__all__ = ["Dashboard", "SENSOR_STATES"]

log = logging.getLogger(__name__)
STATUS_POLL_S = 1.0
ALARM_POLL_S = 5.0
_SINGLE = ("status", "trends", "alarms", "acknowledge", "set_paused")
_FLEET = ("structures_document", "structure_model", "structure_status", "structure_trends", "structure_alarms",
          "structure_spectra", "live", "acknowledge", "set_paused")


class Dashboard:
    """The live SHM dashboard, served by viser at :attr:`url`.

    Parameters
    ----------
    host, port : where viser listens (``port=0`` picks a free port; a taken port is replaced by
        the next free one; :attr:`url` and :attr:`port` give the real one).
    rig : ``contract.RigDescription`` (beam length and width, reflector distance, sensors; support and
        orientation: a pin or a clamp at D, the beam hanging or standing upright).
    units : ``estimator.UnitDeformations`` (shape/slope of the Γ unit deformations; their
        ``modes`` label trends and spectra).
    layout : ``contract.StateLayout`` of the estimator's state vector (how ``push_estimate`` reads x).
    stations : η (m) of the curvature-change index (and of ``truth_deflection``).
    service : the runtime's ``contract.ServicePort`` (one structure: status, trends, alarms,
        acknowledge, set_paused are used).
        With ``fleet=True`` a ``FleetDashboardService`` (structures_document, structure_model,
        structure_status, structure_trends, structure_alarms, structure_spectra, live,
        acknowledge, set_paused), and no rig, units, layout or stations: each structure's come
        from ``structure_model``.
    render_hz : frames per second drawn into each browser (10–60).
    token : the operator token. Required off loopback: viser then listens on a free loopback
        port and ``web._gate.TokenGate`` on ``host:port`` lets only requests with the token pass
        (a browser asks for it: the token as the password; ValueError without one).
    fleet : the dashboard of a fleet: an overview of every structure and a structure selector.
    """

    def __init__(
        self,
        *,
        host: str,
        port: int,
        service: ServicePort,
        rig: Any = None,
        units: Any = None,
        layout: StateLayout | None = None,
        stations: np.ndarray | None = None,
        render_hz: float = 20.0,
        label: str = "IMMS structural health monitor",
        token: str | None = None,
        fleet: bool = False,
    ) -> None:
        off_loopback = not is_loopback(host)
        if off_loopback and not token:
            raise ValueError(f"dashboard host {host!r} is not loopback: a token is required (server.token_file or "
                             "SHM_TOKEN); viser itself has no authentication")
        self.fleet = bool(fleet)
        self.primary: StructureFeed | None = None
        if self.fleet:
            given = [n for n, v in (("rig", rig), ("units", units), ("layout", layout), ("stations", stations)) if v is not None]
            if given:
                raise ValueError(f"a fleet's dashboard takes each structure's model from the service: {', '.join(given)} "
                                 "must not be given")
        else:
            if rig is None or units is None or layout is None or stations is None:
                raise ValueError("rig, units, layout and stations are required (or fleet=True)")
            self.primary = StructureFeed(rig=rig, units=units, layout=layout, stations=stations)
        for name in _FLEET if self.fleet else _SINGLE:
            if not callable(getattr(service, name, None)):
                raise TypeError(f"service must implement {'FleetDashboardService' if self.fleet else 'DashboardService'}: "
                                f"missing {name}()")
        if not 1.0 <= render_hz <= 60.0:
            raise ValueError(f"{render_hz=} must be within [1, 60]")
        self.service = service
        self.render_hz = float(render_hz)
        self.label = label
        self.frames = 0
        self.last_frame_s = 0.0
        self._views: dict[int, ClientView] = {}
        self._views_lock = threading.Lock()
        self._service_paused: bool | None = None
        self._stop = threading.Event()
        self.poller = FleetPoller(self) if self.fleet else None

        self.gate = None
        if off_loopback:
            # viser on a free loopback port; the token gate (web._gate) on the public address
            self.server = viser.ViserServer(host="127.0.0.1", port=0, label=label, verbose=False)
            try:
                self.gate = TokenGate(host=host, port=port, upstream_port=int(self.server.get_port()), token=token)
            except BaseException:
                self.server.stop()
                raise
            self.port = self.gate.port
        else:
            self.server = viser.ViserServer(host=host, port=port, label=label, verbose=False)
            self.port = int(self.server.get_port())
        shown_host = "localhost" if host in ("0.0.0.0", "::", "") else host
        self.url = f"http://{shown_host}:{self.port}/"
        try:
            ClientView.setup_shared(self)
            self.server.on_client_connect(self._on_connect)
            self.server.on_client_disconnect(self._on_disconnect)
            self._thread = threading.Thread(target=self._loop, name="shm-dashboard-render", daemon=True)
            self._thread.start()
            if self.poller is not None:
                self.poller.start()
        except BaseException:
            self.server.stop()
            if self.gate is not None:
                self.gate.stop()
            raise

    # the single structure's drawing (what the tests and the service's sink read)
    rig = property(lambda self: self._one().rig)
    units = property(lambda self: self._one().units)
    layout = property(lambda self: self._one().layout)
    mode_map = property(lambda self: self._one().mode_map)
    gamma = property(lambda self: self._one().gamma)
    stations = property(lambda self: self._one().stations)
    length = property(lambda self: self._one().length)
    width = property(lambda self: self._one().width)
    clamped = property(lambda self: self._one().clamped)
    standing = property(lambda self: self._one().standing)

    def _one(self) -> StructureFeed:
        if self.primary is None:
            raise AttributeError("a fleet's dashboard draws each browser's structure: use its feeds")
        return self.primary

    # ------------------------------------------------------------------ pushes (service side)
    def push_estimate(
        self,
        t_s: float,
        x: np.ndarray,
        sensor_states: dict[str, str],
        truth_deflection: np.ndarray | None = None,
    ) -> None:
        """The newest state estimate (called ≥ 10 Hz). Raises ValueError on malformed input."""
        self._one().push_estimate(t_s, x, sensor_states, truth_deflection)

    def push_spectra(self, spectrum: SpectrumDocument) -> None:
        """Amplitude spectra (n_freq, Γ) of b1..bΓ of the latest window, with the tracked and
        baseline eigenfrequencies per unit deformation (before a baseline: tracked only)."""
        self._one().push_spectra(spectrum)

    def push_window(self, window: WindowDocument) -> None:
        """One analysis window (its modes, charts and curvature change along ``stations``)."""
        self._one().push_window(window)

    def push_alarm(self, alarm: AlarmDocument) -> None:
        """An alarm raised, updated, acknowledged or cleared; a raised alarm notifies every browser."""
        self._one().push_alarm(alarm)

    def stop(self) -> None:
        """Stop the render thread, the fleet's poller and the web server (idempotent)."""
        if self._stop.is_set():
            return
        self._stop.set()
        if self._thread.is_alive() and threading.current_thread() is not self._thread:
            self._thread.join(timeout=5.0)
        if self.poller is not None:
            self.poller.stop()
        if self.gate is not None:
            self.gate.stop()
        self.server.stop()

    def __enter__(self) -> "Dashboard":
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    # ------------------------------------------------------------------ internals
    def snapshot(self) -> Snapshot:
        return self._one().snapshot()

    @property
    def client_count(self) -> int:
        with self._views_lock:
            return len(self._views)

    def views(self) -> list[ClientView]:
        with self._views_lock:
            return list(self._views.values())

    def set_view_paused(self) -> None:
        """Pause the service's pushes only when every connected browser is paused."""
        views = self.views()
        paused = bool(views) and all(v.paused for v in views)
        if paused != self._service_paused:
            try:
                self.service.set_paused(paused)
                self._service_paused = paused
            except Exception:  # the service's problem must not break the page
                log.exception("service.set_paused(%s) failed", paused)

    def _on_connect(self, client: viser.ClientHandle) -> None:
        view = ClientView(self, client, self.primary)
        with self._views_lock:
            self._views[client.client_id] = view
        what = "every structure's state, the chosen one's live beam, spectra, trends and alarms" if self.fleet else \
            "live beam, spectra, trends and alarms"
        client.add_notification(
            "Connected to the SHM dashboard",
            f"{self.label}: {what}. Acknowledging an alarm needs the operator token.",
            auto_close_seconds=6.0,
            color="blue",
        )
        if self.primary is not None:
            snap = self.snapshot()
            active = [a for a in snap.alarms if a.active and not a.acknowledged]
            if active:
                client.add_notification(
                    f"{len(active)} active alarm(s)",
                    "; ".join(f"#{a.id} {a.level}: {a.message}" for a in active[:3]),
                    color="red" if any(a.level == "alarm" for a in active) else "yellow",
                    auto_close_seconds=None,
                )
        elif self.poller is not None:
            self.poller.greet(client)
        self.set_view_paused()

    def _on_disconnect(self, client: viser.ClientHandle) -> None:
        with self._views_lock:
            view = self._views.pop(client.client_id, None)
        if view is not None:
            view.closed = True
        self.set_view_paused()

    def _poll(self, now: float, last: dict[str, float]) -> None:
        """The single structure's status, alarms and (once) stored trend history."""
        feed = self._one()
        store = feed.store
        if "history" not in last:  # once, at start: the stored trend history
            last["history"] = now
            try:
                records = windows_from_trend_rows(self.service.trends(None, None) or [])
                if records:
                    feed.add_windows(records)
            except Exception as exc:
                log.warning("service.trends() failed: %s", exc)
        if now - last.get("status", -math.inf) >= STATUS_POLL_S:
            last["status"] = now
            try:
                status = self.service.status()
                error = None if isinstance(status, StatusDocument) else f"status() returned {type(status).__name__}"
            except Exception as exc:
                status, error = None, f"{type(exc).__name__}: {exc}"
            store.set_status(now, status, error)
        if now - last.get("alarms", -math.inf) >= ALARM_POLL_S:
            last["alarms"] = now
            try:
                for item in self.service.alarms() or []:
                    if isinstance(item, AlarmDocument):
                        store.upsert_alarm(item)
                    else:
                        log.warning("ignoring an alarm that is not a contract.AlarmDocument: %r", type(item).__name__)
            except Exception as exc:
                log.warning("service.alarms() failed: %s", exc)

    def _notify(self) -> None:
        if self.primary is None:
            return
        store = self.primary.store
        with store.lock:
            pending = list(store.notify)
            store.notify.clear()
        if not pending:
            return
        clients = list(self.server.get_clients().values())
        for rec in pending:
            mode = f" (mode {rec.mode})" if rec.mode is not None else ""
            if rec.active:
                title = f"{'ALARM' if rec.level == 'alarm' else 'Warning'} #{rec.id} raised{mode}"
                color = "red" if rec.level == "alarm" else "yellow"
                close = None if rec.level == "alarm" else 30.0
            else:
                title = f"Alarm #{rec.id} cleared{mode}"
                color, close = "green", 10.0
            for client in clients:
                try:
                    client.add_notification(title, rec.message or "-", color=color, auto_close_seconds=close)
                except Exception:
                    log.exception("notification to client %s failed", client.client_id)

    def _loop(self) -> None:
        period = 1.0 / self.render_hz
        last: dict[str, float] = {}
        next_t = time.monotonic()
        while not self._stop.is_set():
            now = time.monotonic()
            try:
                if self.primary is not None:
                    self._poll(now, last)
                    self._notify()
                views = self.views()
                if self.fleet:
                    for view in views:  # a structure chosen and ready: that browser switches to it
                        try:
                            view.sync_selection()
                        except UserWarning as exc:  # viser (as an error under -W error): the browser just left
                            log.debug("client %s: %s", view.client.client_id, exc)
                        except Exception:
                            if not view.closed:
                                log.exception("switching the structure of client %s failed", view.client.client_id)
                snaps: dict[int, Snapshot] = {}
                for view in views:  # one snapshot per structure shown (a fleet's estimates played out first)
                    feed = view.feed
                    if feed is not None and id(feed) not in snaps:
                        if self.fleet:
                            feed.play(now)
                        snaps[id(feed)] = feed.snapshot()
                t0 = time.perf_counter()
                for view in views:
                    try:
                        view.render(None if view.feed is None else snaps.get(id(view.feed)))
                    except UserWarning as exc:  # viser (as an error under -W error): the browser just left
                        log.debug("client %s: %s", view.client.client_id, exc)
                    except Exception:
                        if not view.closed:
                            log.exception("rendering for client %s failed", view.client.client_id)
                self.last_frame_s = time.perf_counter() - t0
                self.frames += 1
            except Exception:
                log.exception("dashboard render loop error")
            next_t += period
            delay = next_t - time.monotonic()
            if delay < 0:
                next_t = time.monotonic()
                delay = 0.0
            self._stop.wait(delay)
