"""The monitoring service: wires a source, the pipeline, storage, notifications, the HTTP API
and the dashboard, and implements the ``contract.ServicePort`` the API and the dashboard read."""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Mapping
from typing import Any


from contract import (
    AlarmDocument,
    BaselineRequestDocument,
    FatigueDocument,
    HealthDocument,
    IngestResultDocument,
    LiveEstimatesDocument,
    Page,
    RigDescription,
    SpectrumDocument,
    StatusDocument,
    StructuresDocument,
    TrendRow,
    WindowDocument,
)

from .._config import ServiceSettings, SettingsError, StructureSettings, resolve_token
from ._dashboard_port import StructureModel, start_dashboard
from ._operator import acknowledge_alarm, check_token
from ..http._metrics import fleet_metrics
from ..alarms._notify import Notifier, notify_targets
from ..storage._retention import RetentionWorker
from ._scheduler import Scheduler, SchedulerSettings
from ..alarms._sinks import SinkGuard
from ..sources._sources import IngestSource
from ..storage._storage import Storage, is_transient
from ..storage._fatigue import fatigue_document
from ..storage._writer import open_storage
from ._status import service_state, status_of
from ._structure import (
    SingleStructureView,
    NotSingleStructure,
    RigPending,
    ServiceError,
    Structure,
    StructureUnavailable,
    _FailedStructure,
    _ModelCache,
)

__all__ = ["MonitoringService", "NotSingleStructure", "RigPending", "ServiceError", "Structure", "StructureUnavailable"]

log = logging.getLogger("shm.serve")


class _StoredRows:
    """The stored trend rows and alarms, of all structures or of one: what a service and the
    front of its worker processes answer alike from the one database. ``_known`` raises
    KeyError naming an id the service does not have."""

    storage: Storage

    def _known(self, structure_id: str) -> None:
        raise NotImplementedError

    def trends(self, from_s: float | None, to_s: float | None, mode: int | None = None, source: str | None = None,
               limit: int = 100_000) -> list[TrendRow]:
        return self.storage.trends(from_s=from_s, to_s=to_s, mode=mode, source=source, limit=limit)

    def structure_trends(self, structure_id: str, from_s: float | None, to_s: float | None, mode: int | None = None,
                         limit: int = 100_000) -> list[TrendRow]:
        self._known(structure_id)
        return self.storage.trends(from_s=from_s, to_s=to_s, mode=mode, source=structure_id, limit=limit)

    def trends_page(self, from_s: float | None, to_s: float | None, mode: int | None = None, source: str | None = None,
                    *, limit: int = 1000, cursor: str | None = None) -> Page[TrendRow]:
        return self.storage.trends_page(from_s=from_s, to_s=to_s, mode=mode, source=source, limit=limit, cursor=cursor)

    def structure_trends_page(self, structure_id: str, from_s: float | None, to_s: float | None, mode: int | None = None,
                              *, limit: int = 1000, cursor: str | None = None) -> Page[TrendRow]:
        self._known(structure_id)
        return self.storage.trends_page(from_s=from_s, to_s=to_s, mode=mode, source=structure_id, limit=limit, cursor=cursor)

    def alarms_page(self, state: str | None = None, *, limit: int = 1000, cursor: str | None = None) -> Page[AlarmDocument]:
        return self.storage.alarms_page(state=state, limit=limit, cursor=cursor)

    def structure_alarms_page(self, structure_id: str, state: str | None = None, *, limit: int = 1000,
                              cursor: str | None = None) -> Page[AlarmDocument]:
        self._known(structure_id)
        return self.storage.alarms_page(state=state, source=structure_id, limit=limit, cursor=cursor)

    def alarms(self, state: str | None = None) -> list[AlarmDocument]:
        return self.storage.alarms(state=state)

    def structure_alarms(self, structure_id: str, state: str | None = None) -> list[AlarmDocument]:
        self._known(structure_id)
        return self.storage.alarms(state=state, source=structure_id)

    def structure_fatigue(self, structure_id: str, from_s: float | None = None, to_s: float | None = None,
                          limit: int = 100_000) -> FatigueDocument:
        """Its hot spots' loads and life from the stored windows."""
        self._known(structure_id)
        return fatigue_document(structure_id, *self.storage.fatigue_windows(structure_id, from_s=from_s, to_s=to_s, limit=limit),
                                design_life_years=self._design_life(structure_id))

    def _design_life(self, structure_id: str) -> float | None:
        """The rig's ``fatigue.design_life_years`` of structure ``structure_id`` (None: not given, or
        its rig not known yet: a structure that failed to start, a worker not up)."""
        try:
            rig = self.structure_rig(structure_id)  # type: ignore[attr-defined]
        except Exception:  # noqa: BLE001 - no rig: the stored hot spots' design life stands
            return None
        return rig.fatigue.design_life_years if rig.fatigue is not None else None

    def fatigue(self, structure_id: str | None = None, from_s: float | None = None, to_s: float | None = None,
                limit: int = 100_000) -> FatigueDocument:
        """As ``structure_fatigue``; None: the single structure (NotSingleStructure for a fleet)."""
        if structure_id is None:
            if getattr(self, "fleet", False):
                raise NotSingleStructure("this service monitors a fleet ([[structures]]): use /api/structures/{id}/fatigue")
            structure_id = next(iter(self.structures))  # type: ignore[attr-defined]
        return self.structure_fatigue(structure_id, from_s, to_s, limit)


class MonitoringService(_StoredRows, SingleStructureView):
    """One running ``shm serve``: one structure (``[source]``), or a fleet (``[[structures]]``)
    sharing one database, notifier, retention and API. ``environ`` is the environment the token
    is read from (default ``os.environ``; tests pass a dict)."""

    def __init__(self, settings: ServiceSettings, *, environ: Mapping[str, str] | None = None, deliver: bool = True,
                 rig_wait_s: float = 0.0) -> None:
        self.settings = settings
        self.deliver = deliver  # False in a worker process: the front delivers the fleet's notifications
        self.rig_wait_s = rig_wait_s
        self.token = resolve_token(settings, environ)
        if not settings.server.loopback and self.token is None:
            raise ServiceError(f"server.host {settings.server.host} is not loopback: a token is required "
                               "(server.token_file or SHM_TOKEN)")
        if settings.dashboard.enabled and not settings.dashboard.loopback and self.token is None:
            raise ServiceError(f"dashboard.host {settings.dashboard.host} is not loopback: a token is required "
                               "(server.token_file or SHM_TOKEN), which the dashboard then asks for; or bind it to "
                               "127.0.0.1, or --no-dashboard")
        self.started_at = time.time()
        self.fleet = settings.fleet
        self.models = _ModelCache()
        self.structures: dict[str, Structure | _FailedStructure] = self._build_structures(settings)
        # a worker of a fleet writes through its front (one writer per database: storage._writer)
        self.storage = open_storage(settings.db_path, notify_targets=notify_targets(settings.notify),
                                    notify_levels=settings.alarms.notify_levels, notify_cleared=settings.alarms.notify_cleared,
                                    notify_stale=settings.alarms.notify_stale, sync=settings.storage_sync,
                                    alarm_sync=settings.storage_alarm_sync, retry_s=settings.storage_retry_s)
        self.dashboard = None
        self.dashboard_guard = SinkGuard("dashboard", log)
        shown = next((s for s in self.structures.values() if isinstance(s, Structure)), None)
        if settings.dashboard.enabled and shown is not None:
            # the dashboard reads the structure each browser shows through the port (live ring, status, rows,
            # latest window and spectra), one structure as a fleet: nothing is pushed into it
            self.dashboard = start_dashboard(self, self.settings, self.token)
        for structure in self.running_structures():
            structure.attach(self.storage, self.dashboard_guard)
        self.notifier = Notifier(self.storage, settings.notify, dict(environ) if environ is not None else None)
        archives = [s.archive for s in self.running_structures() if s.archive is not None]
        self.retention = RetentionWorker(settings.retention, storage=self.storage,
                                         directory=archives[0].directory if archives else None,
                                         current=lambda: [a.current for a in archives if a.current is not None])
        self.housekeeping_guard = SinkGuard("housekeeping", log)
        # the structures' pipelines run on a small pool of threads (not three threads per structure)
        self.scheduler = Scheduler(SchedulerSettings(threads=settings.pipeline_threads), name="pipelines")
        self._lock = threading.Lock()
        self._done = threading.Event()
        self._stopping = threading.Event()
        self._starting = threading.Lock()
        self.api = None

    def _build_structures(self, settings: ServiceSettings) -> dict[str, Structure | _FailedStructure]:
        """The structures this service runs: the one of [source], or every one of the fleet."""
        if not self.fleet:
            primary = Structure(self, settings, models=self.models)
            return {primary.id: primary}
        return {st.id: self.build_structure(st) for st in settings.structures}

    def build_structure(self, st: StructureSettings) -> Structure | _FailedStructure:
        """One structure of the fleet (its failure to start as a ``_FailedStructure``)."""
        try:
            return Structure(self, self.settings.for_structure(st), models=self.models)
        except (ServiceError, SettingsError, OSError, ValueError) as exc:
            # One structure's bad file or rig must not keep the others from monitoring.
            log.error("structure %s cannot start: %s", st.id, exc)
            return _FailedStructure(st.id, st.source.partition(":")[0], str(exc))

    def running_structures(self) -> list[Structure]:
        return [s for s in self.structures.values() if isinstance(s, Structure)]

    # -- the single structure (a service without [[structures]]) ----------------------------

    @property
    def primary(self) -> Structure:
        """The structure of a single-structure service (NotSingleStructure for a fleet)."""
        if self.fleet:
            raise NotSingleStructure("this service monitors a fleet ([[structures]]): use /api/structures and "
                                     "/api/structures/{id}/...")
        return next(iter(self.structures.values()))  # type: ignore[return-value]

    def structure(self, structure_id: str) -> Structure:
        """The running structure ``structure_id`` (KeyError naming it when there is none,
        StructureUnavailable when its start failed)."""
        found = self.structures.get(structure_id)
        if found is None:
            known = ", ".join(sorted(self.structures)[:20])
            raise KeyError(f"no structure {structure_id!r} (this service monitors: {known})")
        if isinstance(found, _FailedStructure):
            raise StructureUnavailable(f"structure {structure_id!r} failed to start: {found.error}")
        return found

    # -- running ----------------------------------------------------------------------------

    def start(self) -> None:
        if self.deliver:
            self.notifier.start()
        self.retention.start()
        threading.Thread(target=self._housekeeping_loop, name="housekeeping", daemon=True).start()
        paced = [s for s in self.running_structures() if s.kind in ("sim", "replay") and s.speed is not None]
        for structure in self.structures.values():
            if structure not in paced:
                structure.start()
        delay = self.start_stagger_s(paced)
        if delay > 0:
            paced[0].start()
            threading.Thread(target=self._start_staggered, args=(paced[1:], delay), name="starting", daemon=True).start()
        else:
            for structure in paced:
                structure.start()
        threading.Thread(target=self._watch_done, name="done", daemon=True).start()

    @staticmethod
    def start_stagger_s(paced: list[Structure], most_s: float = 0.5, span_s: float = 30.0) -> float:
        """Seconds between the starts of the paced structures (sim, replay at a speed) of a fleet.

        Started together, they would run in step: their rest calibrations end, and their windows
        fall due, at the same wall instant, and each such burst of work (a calibration and the
        filter's first minute, ~0.2 s of CPU; a window's analysis) hits every structure at once.
        Spread over one window step of wall time (at most ``span_s``), at most ``most_s`` apart,
        the bursts come one structure after the other. Nothing of the data changes: a paced
        structure's data time and pace start with its own first batch."""
        if len(paced) < 2:
            return 0.0
        step_wall = max(s.settings.analytics.window_s * (1 - s.settings.analytics.overlap) / s.speed for s in paced if s.speed)
        return min(most_s, min(step_wall, span_s) / len(paced))

    def _start_staggered(self, structures: list[Structure], delay_s: float) -> None:
        for k, structure in enumerate(structures):
            self._stopping.wait(delay_s)
            with self._starting:  # stop() sees a structure either started or skipped
                if self._stopping.is_set():
                    for rest in structures[k:]:
                        rest.skip()  # stopped before it started: it is done
                    return
                structure.start()

    def _watch_done(self) -> None:
        for structure in self.structures.values():
            structure.wait()
        self._done.set()

    def _housekeeping_loop(self, period_s: float = 2.0) -> None:
        while not self._stopping.wait(period_s):
            self.housekeeping()

    def housekeeping(self, now: float | None = None) -> None:
        """Every few seconds: note that the sources deliver (``sources.last_seen_s``), mark stale
        the alarms of sources silent for ``alarms.stale_after_s``, re-notify alarms that still
        fire after ``alarms.repeat_interval_s``. A failure is counted and tried again next time."""
        now = time.time() if now is None else now
        a = self.settings.alarms
        try:
            # one transaction for all the structures (each its own would take the database's lock)
            due = [(s, u) for s, u in ((s, s.untouched()) for s in self.running_structures()) if u is not None]
            self.storage.touch_sources([row for _, (_, row) in due], now)
            for structure, (samples, _) in due:
                structure.touched(samples)
            stale = self.storage.mark_stale(now - a.stale_after_s, now)
            if stale:
                log.warning("alarm(s) %s marked stale: their source has delivered no data for %.0f s", stale, a.stale_after_s)
            if a.repeat_interval_s is not None:  # queues a re-notification of each alarm still firing since then
                self.storage.renotify_due(a.repeat_interval_s, now)
            self.notifier.wake()
        except Exception as exc:
            if is_transient(exc):  # the database locked or full for a while: expected, no traceback
                self.housekeeping_guard.record("storage", f"{type(exc).__name__}: {exc}")
            else:
                self.housekeeping_guard.record("housekeeping", exc)

    def wait(self, timeout: float | None = None) -> bool:
        """Wait until every source ended and everything was processed and stored."""
        return self._done.wait(timeout)

    @property
    def done(self) -> bool:
        return self._done.is_set()

    def stop(self, *, drain_s: float = 2.0) -> None:
        if self._stopping.is_set():
            return
        self._stopping.set()
        with self._starting:
            pass  # a structure being started (staggered) is started now
        for structure in self.structures.values():
            structure.stop_source()
        deadline = time.monotonic() + 30.0
        for structure in self.structures.values():
            if structure.started:
                structure.wait(max(0.0, deadline - time.monotonic()))
        self.scheduler.stop()
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
        check_token(self.token, token)

    def health(self) -> HealthDocument:
        """``/healthz``: cheap (no query of the database), "degraded" with the reasons why (of a
        fleet: each reason names its structure)."""
        reasons: list[str] = []
        for structure in self.structures.values():
            prefix = f"{structure.id}: " if self.fleet else ""
            reasons.extend(prefix + r for r in structure.health_reasons())
        return HealthDocument(status="degraded" if reasons else "ok", uptime_s=round(time.time() - self.started_at, 1),
                              reasons=reasons)

    def status(self, structure_id: str | None = None) -> StatusDocument:
        """The status of the single structure, or of ``structure_id`` of a fleet."""
        structure = self.primary if structure_id is None else self.structure(structure_id)
        return status_of(self, structure, service_state(self))

    def statuses(self) -> dict[str, StatusDocument]:
        """The status of every running structure (the database read once)."""
        shared = service_state(self)
        return {s.id: status_of(self, s, shared) for s in self.running_structures()}

    def fleet_metrics(self) -> str:
        """``/metrics`` of a fleet: every structure's samples labelled ``structure``."""
        return fleet_metrics(self.structures_document(), self.statuses())

    def structures_document(self) -> StructuresDocument:
        """``GET /api/structures``: every structure's state, lag, windows and active alarms."""
        return StructuresDocument(structures=[s.summary() for s in self.structures.values()])

    def _known(self, structure_id: str) -> None:
        """KeyError naming ``structure_id`` unless the service has such a structure (a failed
        one still has its stored history)."""
        if structure_id not in self.structures:
            self.structure(structure_id)

    def acknowledge(self, alarm_id: int, token: str, by: str) -> AlarmDocument:
        self.check_token(token)
        return acknowledge_alarm(self.storage, alarm_id, by, self.settings.storage_retry_s)

    def request_baseline(self, structure_id: str | None = None) -> BaselineRequestDocument:
        """Learn a new baseline of the single structure (or of ``structure_id``) from its next windows."""
        structure = self.primary if structure_id is None else self.structure(structure_id)
        # An operator's request waits a few seconds for the database at most (then 503: retry).
        baseline_id = self.storage.request_baseline(structure.id, retry_s=min(self.settings.storage_retry_s, 3.0))
        structure.pipeline.request_baseline()
        return BaselineRequestDocument(baseline_id=baseline_id, state="learning", source=structure.id,
                                       learn_s=structure.settings.analytics.baseline_s)

    def spectra(self, structure_id: str | None = None) -> SpectrumDocument | None:
        structure = self.primary if structure_id is None else self.structure(structure_id)
        return structure.pipeline.analytics.latest_spectrum

    # -- the fleet's dashboard port (FleetDashboardService) and its routes --------------------

    def structure_status(self, structure_id: str) -> StatusDocument:
        return self.status(structure_id)

    def structure_spectra(self, structure_id: str) -> SpectrumDocument | None:
        return self.spectra(structure_id)

    def structure_window(self, structure_id: str) -> WindowDocument | None:
        """Its latest committed window (``GET /api/structures/{id}/windows/latest``)."""
        return self.structure(structure_id).pipeline.last_window

    def structure_rig(self, structure_id: str) -> RigDescription:
        """The rig structure ``structure_id`` is monitored with (``GET /api/structures/{id}/rig``)."""
        return self.structure(structure_id).rig

    def structure_model(self, structure_id: str) -> StructureModel:
        structure = self.structure(structure_id)
        m = structure.model
        return StructureModel(id=structure.id, rig=structure.rig, units=m.units, layout=m.state_layout, stations=m.stations,
                              units_xi=getattr(m, "units_xi", None))

    def live(self, structure_id: str, after: int = 0) -> LiveEstimatesDocument:
        """The structure's newest estimates after ``after`` (``GET /api/structures/{id}/live``); starts its watch."""
        structure = self.structure(structure_id)
        return structure.live.document(after, structure.pipeline.sensor_states())

    def ingest(self, document: Any, structure_id: str | None = None) -> IngestResultDocument | None:
        structure = self.primary if structure_id is None else self.structure(structure_id)
        if not isinstance(structure.source, IngestSource):
            what = "the service's source" if structure_id is None else f"the source of structure {structure_id!r}"
            raise LookupError(f"{what} is {structure.source.kind}, not ingest")
        result = structure.source.submit(document)
        return None if result is None else IngestResultDocument(**result.as_dict())


