"""The viser dashboard: live deformed beam, spectra, trends, loads, alarms and status of the
structures of a running service, read through its port.

Threads: the poller (``web._poller.PortPoller``) reads the service's ``contract.ServicePort``
— the overview, and for the structures some browser shows their estimates, status, alarms, rows,
latest window, spectra and loads — into one ``StructureFeed`` per structure. One render thread
draws the newest data into every connected browser at ``render_hz`` (updates assigned to
existing handles, grouped per client in ``client.atomic()``; nothing is re-created per frame, so
memory stays flat). viser runs its own thread and asyncio loop; GUI callbacks run on its threads.
A service of one structure is read like a fleet of one: nothing is pushed into the dashboard.

Every browser (client) gets its own GUI, scene and view settings, so one operator's pause,
overscale, mode choice, structure or token never changes what another sees. A fleet's browsers
each choose the structure they show under an overview of every structure.
"""

from __future__ import annotations

import logging
import threading
import time

import viser

from contract import SENSOR_STATES, AlarmDocument, ServicePort, is_loopback

from ._context import DashboardStats, ViewContext
from ._feed import Snapshot, StructureFeed
from ._gate import TokenGate
from ._poller import Notice, PortPoller
from ._view import ClientView

__all__ = ["Dashboard", "SENSOR_STATES"]

log = logging.getLogger(__name__)


class _ProbeFilter(logging.Filter):
    """A client that opens the dashboard's port and closes it without a request (a browser's
    speculative preconnect, a TCP health check, a port scan) makes the websockets server log
    "opening handshake failed" at ERROR with three tracebacks. Nothing failed: such a record is
    logged at DEBUG, without the tracebacks. A handshake that did send something stays an error.
    (viser drops every "opening handshake failed" once its server answered a first HTTP request;
    before that, a browser's preconnect to a freshly started dashboard was logged as an error.)"""

    def filter(self, record: logging.LogRecord) -> bool:
        if record.getMessage() != "opening handshake failed" or not record.exc_info:
            return True
        cause = record.exc_info[1]
        while cause is not None and not (isinstance(cause, EOFError) and "after 0 bytes" in str(cause)):
            cause = cause.__cause__
        if cause is None:  # not the closed-before-a-byte case
            return True
        if not logging.getLogger(record.name).isEnabledFor(logging.DEBUG):
            return False
        record.levelno, record.levelname, record.exc_info, record.exc_text = logging.DEBUG, "DEBUG", None, None
        record.msg, record.args = "a client opened the dashboard's port and closed it without a request", ()
        return True


_PROBES = _ProbeFilter()
#: What the dashboard reads of the port (a missing one is refused at construction).
PORT_METHODS = ("structures_document", "structure_model", "structure_status", "structure_trends", "structure_alarms",
                "structure_window", "structure_spectra", "structure_fatigue", "live", "acknowledge")


class Dashboard:
    """The live SHM dashboard of a running service, served by viser at :attr:`url`.

    Parameters
    ----------
    host, port : where viser listens (``port=0`` picks a free port; a taken port is replaced by
        the next free one; :attr:`url` and :attr:`port` give the real one).
    service : the running service's ``contract.ServicePort`` (a single structure's service or a
        fleet; ``service.fleet`` adds the structure selector and the overview). Its structures'
        models (rig, unit deformations, state layout, stations) come from ``structure_model``;
        a rig with hot spots is also read through ``structure_fatigue`` (the Loads tab).
    render_hz : frames per second drawn into each browser (1–60).
    label : the title above the controls.
    token : the operator token. Required off loopback: viser then listens on a free loopback
        port and ``web._gate.TokenGate`` on ``host:port`` lets only requests with the token pass
        (a browser asks for it: the token as the password).

    Raises
    ------
    ValueError
        Off loopback without a token; ``render_hz`` outside [1, 60].
    TypeError
        ``service`` lacks a method of the port the dashboard reads (named).
    """

    def __init__(self, *, host: str, port: int, service: ServicePort, render_hz: float = 20.0,
                 label: str = "IMMS structural health monitor", token: str | None = None) -> None:
        off_loopback = not is_loopback(host)
        if off_loopback and not token:
            raise ValueError(f"dashboard host {host!r} is not loopback: a token is required (server.token_file or "
                             "SHM_TOKEN); viser itself has no authentication")
        missing = [name for name in PORT_METHODS if not callable(getattr(service, name, None))]
        if missing:
            raise TypeError(f"service must implement contract.ServicePort: missing {', '.join(f'{m}()' for m in missing)}")
        if not 1.0 <= render_hz <= 60.0:
            raise ValueError(f"{render_hz=} must be within [1, 60]")
        self.service = service
        self.fleet = bool(getattr(service, "fleet", False))
        self.render_hz = float(render_hz)
        self.label = label
        self.frames = 0
        self.last_frame_s = 0.0
        self._views: dict[int, ClientView] = {}
        self._views_lock = threading.Lock()
        self._stop = threading.Event()
        self.poller = PortPoller(service, self.views, self.notify)
        self.context = ViewContext(label=label, fleet=self.fleet, structures=self.poller,
                                   acknowledge=self._acknowledge, stats=self._stats)
        self.gate = None
        probes = logging.getLogger("websockets.server")
        if _PROBES not in probes.filters:
            probes.addFilter(_PROBES)
        if off_loopback:  # viser on a free loopback port; the token gate (web._gate) on the public address
            self.server = viser.ViserServer(host="127.0.0.1", port=0, label=label, verbose=False)
            try:
                self.gate = TokenGate(host=host, port=port, upstream_port=int(self.server.get_port()), token=token or "")
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
            self._setup_server()
            self.server.on_client_connect(self._on_connect)
            self.server.on_client_disconnect(self._on_disconnect)
            self._thread = threading.Thread(target=self._loop, name="shm-dashboard-render", daemon=True)
            self._thread.start()
            self.poller.start()
        except BaseException:
            self.server.stop()
            if self.gate is not None:
                self.gate.stop()
            raise

    def stop(self) -> None:
        """Stop the render thread, the poller and the web server (idempotent)."""
        if self._stop.is_set():
            return
        self._stop.set()
        if self._thread.is_alive() and threading.current_thread() is not self._thread:
            self._thread.join(timeout=5.0)
        self.poller.stop()
        if self.gate is not None:
            self.gate.stop()
        self.server.stop()

    def __enter__(self) -> "Dashboard":
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    @property
    def client_count(self) -> int:
        with self._views_lock:
            return len(self._views)

    def views(self) -> list[ClientView]:
        with self._views_lock:
            return list(self._views.values())

    def notify(self, notice: Notice, feed: StructureFeed | None) -> None:
        """Show ``notice`` in every browser (``feed`` None) or in those showing ``feed``."""
        clients = [v.client for v in self.views() if feed is None or v.feed is feed]
        for client in clients:
            try:
                client.add_notification(notice.title, notice.body, color=notice.color, auto_close_seconds=notice.close_s)
            except Exception:
                log.exception("notification to client %s failed", client.client_id)

    # ------------------------------------------------------------------ internals
    def _acknowledge(self, alarm_id: int, token: str) -> AlarmDocument:
        return self.service.acknowledge(alarm_id, token, by="dashboard")

    def _stats(self) -> DashboardStats:
        return DashboardStats(clients=self.client_count, last_frame_s=self.last_frame_s)

    def _setup_server(self) -> None:
        server = self.server
        server.gui.configure_theme(control_width="large", show_logo=False, show_share_button=False, brand_color=(30, 100, 200))
        server.scene.set_up_direction("+z")
        # Shadows and the HDR environment cost a software-rendered browser (no GPU) 10× its frame
        # rate, and a hanging sheet needs neither: plain default lights.
        server.scene.configure_default_lights(enabled=True, cast_shadow=False)
        server.scene.configure_environment_map(None)
        server.scene.add_light_ambient("/lights/ambient", intensity=1.6)
        server.scene.add_light_hemisphere("/lights/sky", sky_color=(255, 255, 255), ground_color=(200, 205, 215), intensity=1.2)

    def _on_connect(self, client: viser.ClientHandle) -> None:
        view = ClientView(self.context, client)
        with self._views_lock:
            self._views[client.client_id] = view
        what = ("every structure's state, the chosen one's live beam, spectra, trends and alarms" if self.fleet
                else "live beam, spectra, trends and alarms")
        client.add_notification("Connected to the SHM dashboard",
                                f"{self.label}: {what}. Acknowledging an alarm needs the operator token.",
                                auto_close_seconds=6.0, color="blue")
        greeting = self.poller.greeting()
        if greeting is not None:
            client.add_notification(greeting.title, greeting.body, color=greeting.color, auto_close_seconds=greeting.close_s)

    def _on_disconnect(self, client: viser.ClientHandle) -> None:
        with self._views_lock:
            view = self._views.pop(client.client_id, None)
        if view is not None:
            view.closed = True

    def _each_view(self, views: list[ClientView], what: str, call: str, *args: object) -> None:
        for view in views:
            try:
                getattr(view, call)(*args)
            except UserWarning as exc:  # viser (as an error under -W error): the browser just left
                log.debug("client %s: %s", view.client.client_id, exc)
            except Exception:
                if not view.closed:
                    log.exception("%s for client %s failed", what, view.client.client_id)

    def _frame(self, now: float) -> None:
        views = self.views()
        self._each_view(views, "switching the structure", "sync_selection")
        snaps: dict[int, Snapshot] = {}
        for view in views:  # one snapshot per structure shown (its estimates played out first)
            feed = view.feed
            if feed is not None and id(feed) not in snaps:
                feed.play(now)
                snaps[id(feed)] = feed.snapshot()
        t0 = time.perf_counter()
        for view in views:
            try:
                view.render(None if view.feed is None else snaps.get(id(view.feed)))
            except UserWarning as exc:
                log.debug("client %s: %s", view.client.client_id, exc)
            except Exception:
                if not view.closed:
                    log.exception("rendering for client %s failed", view.client.client_id)
        self.last_frame_s = time.perf_counter() - t0
        self.frames += 1

    def _loop(self) -> None:
        period = 1.0 / self.render_hz
        next_t = time.monotonic()
        while not self._stop.is_set():
            try:
                self._frame(time.monotonic())
            except Exception:
                log.exception("dashboard render loop error")
            next_t += period
            delay = next_t - time.monotonic()
            if delay < 0:
                next_t = time.monotonic()
                delay = 0.0
            self._stop.wait(delay)
