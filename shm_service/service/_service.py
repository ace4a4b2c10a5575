"""The monitoring service: wires a source, the pipeline, storage, notifications, the HTTP API
and the dashboard, and implements the dashboard's ``DashboardService`` port."""

from __future__ import annotations

import hmac
import logging
import queue
import threading
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from contract import (
    AlarmCountsDocument,
    AlarmDocument,
    BaselineModeDocument,
    BaselineRequestDocument,
    BaselineStatusDocument,
    ChartLevelsDocument,
    HealthDocument,
    IngestResultDocument,
    ModelDocument,
    NotificationStatusDocument,
    RigDescription,
    ServiceStatusDocument,
    SourceStatusDocument,
    SpectrumDocument,
    StatusDocument,
    StorageStatusDocument,
    ThresholdsDocument,
    TrendRow,
    WindowDocument,
    load_rig,
)
from estimator import build_model

from ..recording import RecordingError
from ._archive import Archive
from ._config import ServiceSettings, SettingsError, resolve_token
from ._notify import Notifier, notify_targets
from ._pipeline import Pipeline
from ._plausibility import SourceClock
from ._retention import RetentionWorker
from ._sinks import SinkGuard
from ._sources import END, FileSource, IngestSource, SimSource, Source
from ._storage import Storage

__all__ = ["MonitoringService", "ServiceError"]

log = logging.getLogger("shm.serve")
VERSION = "0.1.0"


class ServiceError(RuntimeError):
    """The service cannot start (the message says why)."""


class RigPending(ServiceError):
    """``follow:``: the file (or its rig.json) is not there yet; the service can be made once it is."""


class _DashboardSink:
    """Adapts the pipeline's pushes to ``web.Dashboard`` (the pipeline's ``SinkGuard`` counts
    and isolates what it raises). Nothing is pushed while every browser has paused."""

    def __init__(self, dashboard: Any, service: "MonitoringService") -> None:
        self.dashboard = dashboard
        self.service = service

    def estimate(self, t_s: float, x: np.ndarray, truth: np.ndarray | None) -> None:
        if self.service.paused:
            return
        pipeline = self.service.pipeline
        states = pipeline.sensor_states() if pipeline is not None else {}
        self.dashboard.push_estimate(t_s, x, states, truth)

    def spectra(self, spectrum: SpectrumDocument) -> None:
        if not self.service.paused:
            self.dashboard.push_spectra(spectrum)

    def window(self, window: WindowDocument) -> None:
        if not self.service.paused:
            self.dashboard.push_window(window)

    def alarm(self, alarm: AlarmDocument) -> None:
        # Alarms reach the dashboard while paused too: pausing freezes the picture, not the alarms.
        self.dashboard.push_alarm(alarm)


class MonitoringService:
    """One running ``shm serve``. ``environ`` is the environment the token is read from
    (default ``os.environ``; tests pass a dict)."""

    def __init__(self, settings: ServiceSettings, *, environ: Mapping[str, str] | None = None,
                 rig_wait_s: float = 0.0) -> None:
        self.settings = settings
        self._rig_wait_s = rig_wait_s
        self.token = resolve_token(settings, environ)
        if not settings.server.loopback and self.token is None:
            raise ServiceError(f"server.host {settings.server.host} is not loopback: a token is required "
                               "(server.token_file or SHM_TOKEN)")
        if settings.dashboard.enabled and not _loopback(settings.dashboard.host) and self.token is None:
            raise ServiceError(f"dashboard.host {settings.dashboard.host} is not loopback: a token is required "
                               "(server.token_file or SHM_TOKEN), which the dashboard then asks for; or bind it to "
                               "127.0.0.1, or --no-dashboard")
        self.started_at = time.time()
        self.paused = False
        self.queue: queue.Queue = queue.Queue(maxsize=settings.queue_batches)
        src = settings.source
        self.source = self._make_source()
        self.rig: RigDescription = self.source.rig  # type: ignore[assignment]
        est = settings.estimator
        _check_sensor_counts(self.rig, est)
        try:
            self.model = build_model(self.rig, peripheral=est.peripheral, modes=est.modes, imus=est.imus, tofs=est.tofs,
                                     gauges=est.gauges)
        except ValueError as exc:
            raise ServiceError(f"estimator model: {exc}") from None
        self.storage = Storage(settings.db, notify_targets=notify_targets(settings.notify),
                               notify_levels=settings.alarms.notify_levels, notify_cleared=settings.alarms.notify_cleared,
                               notify_stale=settings.alarms.notify_stale, sync=settings.storage_sync,
                               alarm_sync=settings.storage_alarm_sync, retry_s=settings.storage_retry_s)
        self.storage.touch_source(self.source.id, self.source.kind, src.spec, time.time())
        archive = None
        if settings.archive.enabled:
            archive = Archive(settings.archive, self.rig, self.source.id, getattr(self.source, "metadata", None))
        raw = settings.archive.raw == "always" or (settings.archive.raw == "auto" and self.source.kind in ("sim", "ingest"))
        self.dashboard = None
        sink = None
        self.dashboard_guard = SinkGuard("dashboard", log)
        if settings.dashboard.enabled:
            self.dashboard = self._start_dashboard()
            if self.dashboard is not None:
                sink = _DashboardSink(self.dashboard, self)
        self.pipeline = Pipeline(
            model=self.model, source_id=self.source.id, storage=self.storage, analysis=settings.analytics,
            calibration_s=est.calibration_s, chunk_s=est.chunk_s, lateness_s=src.lateness_s,
            silent_after_s=src.silent_after_s, raise_windows=settings.alarms.raise_windows,
            clear_windows=settings.alarms.clear_windows, archive=archive, archive_raw=raw,
            archive_estimates=settings.archive.estimates, estimate_decimation=settings.archive.estimate_decimation,
            sink=sink, sink_guard=self.dashboard_guard, sink_estimate_hz=settings.dashboard.estimate_hz, warmup_s=est.warmup_s,
            commit_retry_s=settings.storage_retry_s,
            # ingest is judged per message by its validator (its response says what was refused)
            clock=None if self.source.kind == "ingest" else self._clock(live=False), limits=src.limits,
            stuck_after_s=src.stuck_after_s,
        )
        self.notifier = Notifier(self.storage, settings.notify, dict(environ) if environ is not None else None)
        self.retention = RetentionWorker(settings.retention, storage=self.storage,
                                         directory=archive.directory if archive is not None else None,
                                         current=lambda: archive.current if archive is not None else None)
        self.housekeeping_guard = SinkGuard("housekeeping", log)
        self._touched_samples = 0
        self._lock = threading.Lock()
        self._done = threading.Event()
        self._stopping = threading.Event()
        self._thread: threading.Thread | None = None
        self.pipeline_error: str | None = None  # the last batch's error; None once a batch succeeds again
        self.pipeline_errors = 0
        self.last_pipeline_error: str | None = None
        a = settings.analytics
        self.thresholds = ThresholdsDocument(
            frequency=ChartLevelsDocument(**dict(zip(("warning_sigma", "alarm_sigma"), a.chart_levels("frequency")))),
            curvature=ChartLevelsDocument(**dict(zip(("warning_sigma", "alarm_sigma"), a.chart_levels("curvature")))),
            clear_sigma=a.clear_sigma,
        )
        m = self.model
        self.model_document = ModelDocument(peripheral=m.selection.peripheral, support=m.rig.support, gamma=m.gamma,
                                            state_names=list(m.state_layout.names),
                                            unit_modes=[list(g) for g in m.mode_map.unit_modes])
        self.api = None

    # -- construction -----------------------------------------------------------------------

    def _make_source(self) -> Source:
        s = self.settings
        src = s.source
        kind = src.kind
        truth = s.dashboard.enabled
        rig_override = None
        if src.rig:
            try:
                rig_override = load_rig(src.rig)
            except (OSError, ValueError) as exc:
                raise ServiceError(f"source.rig: {exc}") from None
        try:
            if kind == "sim":
                return SimSource(src.id or "sim", self.queue, s, raw=s.archive.enabled and s.archive.raw != "never", truth=truth)
            if kind in ("replay", "follow"):
                path = Path(src.path or "")
                source = FileSource(src.id or path.stem, self.queue, s, follow=kind == "follow", rig=rig_override, truth=truth)
                if source.rig is None:
                    if kind == "follow":
                        # The model needs the rig: without source.rig, wait for the file's rig.json
                        # (``shm serve`` serves the API meanwhile and retries; see RigPending).
                        if source.wait_for_rig(timeout=self._rig_wait_s) is None:
                            raise RigPending(f"follow: waiting for {path} and its rig.json "
                                             "(or give the rig with source.rig)")
                    else:
                        raise ServiceError(f"{path}: no rig.json")
                return source
            if kind == "ingest":
                from ..rig_layouts import default_rig

                rig = rig_override or default_rig(src.layout)
                return IngestSource(src.id or "ingest", self.queue, rig, max_messages=s.server.max_ingest_messages,
                                    wait_s=s.server.ingest_wait_s, raw=s.archive.enabled and s.archive.raw != "never",
                                    clock=self._clock(live=True), limits=src.limits)
        except (RecordingError, FileNotFoundError, ValueError) as exc:
            raise ServiceError(str(exc)) from None
        raise ServiceError(f"unknown source {src.spec!r}")

    def _clock(self, *, live: bool) -> SourceClock:
        src = self.settings.source
        return SourceClock(window_s=src.time_window_s, max_ahead_s=src.max_ahead_s or src.lateness_s, live=live,
                           future_tolerance_s=src.future_tolerance_s)

    def _start_dashboard(self) -> Any:
        try:
            import web

            Dashboard = getattr(web, "Dashboard")
        except (ImportError, AttributeError):
            log.warning("dashboard: web.Dashboard is not available; running without the dashboard")
            return None
        d = self.settings.dashboard
        try:
            dashboard = Dashboard(host=d.host, port=d.port, rig=self.rig, units=self.model.units,
                                  layout=self.model.state_layout, stations=self.model.stations, service=self,
                                  token=self.token)
        except Exception as exc:
            log.warning("dashboard failed to start (%s); running without it", exc)
            return None
        log.info("dashboard at %s", getattr(dashboard, "url", "?"))
        return dashboard

    # -- running ----------------------------------------------------------------------------

    def start(self) -> None:
        self.notifier.start()
        self.retention.start()
        self._thread = threading.Thread(target=self._pipeline_loop, name="pipeline", daemon=True)
        self._thread.start()
        threading.Thread(target=self._housekeeping_loop, name="housekeeping", daemon=True).start()
        self.source.start()

    def _housekeeping_loop(self, period_s: float = 2.0) -> None:
        while not self._stopping.wait(period_s):
            self.housekeeping()

    def housekeeping(self, now: float | None = None) -> None:
        """Every few seconds: note that the source delivers (``sources.last_seen_s``), mark stale
        the alarms of sources silent for ``alarms.stale_after_s``, re-notify alarms that still
        fire after ``alarms.repeat_interval_s``. A failure is counted and tried again next time."""
        now = time.time() if now is None else now
        a = self.settings.alarms
        try:
            samples = sum(self.pipeline.samples.values())
            if samples != self._touched_samples:
                self.storage.touch_source(self.source.id, self.source.kind, self.settings.source.spec, now)
                self._touched_samples = samples
            stale = self.storage.mark_stale(now - a.stale_after_s, now)
            if stale:
                log.warning("alarm(s) %s marked stale: their source has delivered no data for %.0f s", stale, a.stale_after_s)
            if a.repeat_interval_s is not None and self.storage.renotify_due(a.repeat_interval_s, now):
                pass
            self.notifier.wake()
        except Exception as exc:
            self.housekeeping_guard.record("housekeeping", exc)

    def _pipeline_loop(self) -> None:
        try:
            while True:
                try:
                    item = self.queue.get(timeout=1.0)
                except queue.Empty:
                    # No data: windows that wait for the database are tried again meanwhile.
                    if self.pipeline.pending_commits:
                        try:
                            self.pipeline.flush_commits()
                        except Exception as exc:
                            self._batch_failed(exc, what="pipeline error writing a window")
                        self.pipeline_error = self.pipeline.storage_error
                        self.notifier.wake()
                    continue
                if item is END:
                    break
                try:
                    self.pipeline.process(item)
                except Exception as exc:
                    self._batch_failed(exc)
                else:
                    # None once a batch succeeds and nothing waits for the database
                    self.pipeline_error = self.pipeline.storage_error
                self.notifier.wake()
            self.pipeline.finish()
            self.pipeline_error = self.pipeline.storage_error
        except Exception as exc:
            self._batch_failed(exc, what="pipeline failed at the end of the source")
        finally:
            self.notifier.wake()
            self._done.set()

    def _batch_failed(self, exc: Exception, what: str = "pipeline error on a batch; batch skipped") -> None:
        text = f"{type(exc).__name__}: {exc}"
        self.pipeline_errors += 1
        self.pipeline_error = self.last_pipeline_error = text
        # The same error on every batch would flood the log: its first time with the traceback.
        if self.pipeline_errors <= 3:
            log.exception(what)
        else:
            log.error("%s: %s (%d batches failed so far)", what, text, self.pipeline_errors)

    def wait(self, timeout: float | None = None) -> bool:
        """Wait until the source ended and everything was processed and stored."""
        return self._done.wait(timeout)

    @property
    def done(self) -> bool:
        return self._done.is_set()

    def stop(self, *, drain_s: float = 2.0) -> None:
        if self._stopping.is_set():
            return
        self._stopping.set()
        self.source.stop()
        if self._thread is not None:
            self._done.wait(30.0)
        self.notifier.stop(drain_s=drain_s)
        self.retention.stop()
        if self.dashboard is not None:
            try:
                self.dashboard.stop()
            except Exception as exc:
                log.warning("dashboard stop failed: %s", exc)
        self.storage.close()

    # -- DashboardService and API -----------------------------------------------------------

    def check_token(self, token: str | None) -> None:
        """Raise PermissionError unless ``token`` is the configured one."""
        if self.token is None:
            raise PermissionError("no API token is configured (server.token_file or SHM_TOKEN); this action is disabled")
        if not token or not hmac.compare_digest(token.encode(), self.token.encode()):
            raise PermissionError("missing or wrong token")

    def health(self) -> HealthDocument:
        """``/healthz``: cheap (no query of the database), "degraded" with the reasons why."""
        reasons: list[str] = []
        if self.pipeline_error is not None:
            reasons.append(f"pipeline: {self.pipeline_error}")
        if self.pipeline.storage_error is not None and self.pipeline.storage_error != self.pipeline_error:
            reasons.append(self.pipeline.storage_error)
        reasons.extend(self.pipeline.health_problems())
        src = self.source
        if src.state == "failed":
            reasons.append(f"source {src.id} failed: {src.error}")
        reasons.extend(src.health_problems())
        return HealthDocument(status="degraded" if reasons else "ok", uptime_s=round(time.time() - self.started_at, 1),
                              reasons=reasons)

    def status(self) -> StatusDocument:
        p = self.pipeline.status(queue_depth=self.queue.qsize(), queue_capacity=self.queue.maxsize)
        src = self.source.status()
        src["dropped"] = src["dropped"] + p.late_samples + p.estimator.dropped_samples
        if self.pipeline.rejected:  # judged by the pipeline (off the clock, implausible values)
            by_reason = dict(src["rejected_by_reason"])
            for reason, n in self.pipeline.rejected.items():
                by_reason[reason] = by_reason.get(reason, 0) + n
            src["rejected_by_reason"] = by_reason
            src["rejected"] = sum(by_reason.values())
        src["problems"] = src["problems"] + self.pipeline.health_problems()
        src["clock_jumps"] = src.get("clock_jumps", 0) + (self.pipeline.clock.jump_count if self.pipeline.clock else 0)
        src["latency_s"] = p.pipeline_latency_s
        states = self.pipeline.sensor_states()
        counts = {"warning": 0, "alarm": 0}
        for a in self.storage.alarms(state="active"):
            counts[a.level] += 1
        return StatusDocument(
            service=ServiceStatusDocument(
                version=VERSION, started_at=self.started_at, uptime_s=round(time.time() - self.started_at, 1),
                paused=self.paused, done=self.done, pipeline_error=self.pipeline_error, pipeline_errors=self.pipeline_errors,
                last_pipeline_error=self.last_pipeline_error),
            sources=[SourceStatusDocument(**src)],
            pipeline=p,
            degraded_sensors=sorted(t for t, s in states.items() if s != "ok"),
            sensors=states,
            baseline=BaselineStatusDocument(state=p.baseline, modes=self._baseline_modes()),
            alarms=AlarmCountsDocument(active=counts),
            notifications=NotificationStatusDocument(**self.storage.outbox_counts(), sent_this_run=self.notifier.sent,
                                                     failed_attempts_this_run=self.notifier.failed_attempts,
                                                     outcomes_this_run=dict(self.notifier.outcomes),
                                                     last_error=self.notifier.last_error),
            storage=StorageStatusDocument(db=str(self.settings.db), schema_version=self.storage.schema_version,
                                          trend_rows=self.storage.count("trends"),
                                          archive=None if self.pipeline.archive is None else self.pipeline.archive.status(),
                                          write_retries=self.storage.retries, write_failures=self.storage.failures,
                                          windows_waiting=self.pipeline.pending_commits, last_error=self.storage.last_error),
            sinks={"dashboard": self.dashboard_guard.status(), "notifier": self.notifier.guard.status(),
                   "housekeeping": self.housekeeping_guard.status()},
            thresholds=self.thresholds,
            model=self.model_document,
        )

    def _baseline_modes(self) -> list[BaselineModeDocument] | None:
        bl = self.pipeline.analytics.monitor.baseline
        if bl is None:
            return None
        return [BaselineModeDocument(mode=m.mode, unit=m.unit + 1, f_ref_hz=m.f_ref_hz, temperature_ref_c=m.temperature_ref_c,
                                     slope_per_k=m.slope_per_k, sigma_rel=m.sigma_rel) for m in bl.modes]

    def trends(self, from_s: float | None, to_s: float | None, mode: int | None = None, source: str | None = None,
               limit: int = 100_000) -> list[TrendRow]:
        return self.storage.trends(from_s=from_s, to_s=to_s, mode=mode, source=source, limit=limit)

    def alarms(self, state: str | None = None) -> list[AlarmDocument]:
        return self.storage.alarms(state=state)

    def acknowledge(self, alarm_id: int, token: str, by: str) -> AlarmDocument:
        self.check_token(token)
        alarm = self.storage.acknowledge(alarm_id, by, retry_s=min(self.settings.storage_retry_s, 3.0))
        if alarm is None:
            raise KeyError(f"alarm {alarm_id} does not exist")
        return alarm

    def set_paused(self, paused: bool) -> None:
        self.paused = bool(paused)

    def request_baseline(self) -> BaselineRequestDocument:
        # An operator's request waits a few seconds for the database at most (then 503: retry).
        baseline_id = self.storage.request_baseline(self.source.id, retry_s=min(self.settings.storage_retry_s, 3.0))
        self.pipeline.request_baseline()
        return BaselineRequestDocument(baseline_id=baseline_id, state="learning", source=self.source.id,
                                       learn_s=self.settings.analytics.baseline_s)

    def spectra(self) -> SpectrumDocument | None:
        return self.pipeline.analytics.latest_spectrum

    def ingest(self, document: Any) -> IngestResultDocument | None:
        if not isinstance(self.source, IngestSource):
            raise LookupError(f"the service's source is {self.source.kind}, not ingest")
        result = self.source.submit(document)
        return None if result is None else IngestResultDocument(**result.as_dict())


def _check_sensor_counts(rig: RigDescription, est: Any) -> None:
    """A count set in the configuration must exist on the rig (the defaults are capped to it)."""
    from ..estimation import sensor_count_problem

    for kind in ("imus", "tofs", "gauges"):
        if kind in est.model_fields_set:
            problem = sensor_count_problem(rig, kind, getattr(est, kind), modes=est.modes)
            if problem:
                raise ServiceError(f"estimator.{kind} = {getattr(est, kind)}: {problem}")


def _check(settings: ServiceSettings) -> None:
    if settings.source.kind == "replay" and not Path(settings.source.path or "").is_file():
        raise SettingsError(f"replay: {settings.source.path} does not exist")


def _loopback(host: str) -> bool:
    import ipaddress

    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False
