"""A fleet across worker processes (``workers = N`` with ``[[structures]]``): one GIL hosts only
so many structures, so ``shm serve`` starts N worker processes (one per core), each a service of
every N-th structure on the one shared database, and serves one API over them. The worker
processes run the sources, pipelines, retention and housekeeping of their structures; this front
process delivers the notifications of all (one deliverer per outbox) and answers the API: the
database's rows (trends, alarms, acknowledgements) itself, a structure's live state (status,
spectra, ingest, baseline) from the worker that hosts it. It is the database's one writer: the
workers hand it their window commits and other writes (``storage._writer``) and only read it."""

from __future__ import annotations

import logging
import os
import signal
import subprocess
import threading
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import httpx

from contract import (
    AlarmDocument,
    BaselineRequestDocument,
    HealthDocument,
    IngestResultDocument,
    LiveEstimatesDocument,
    RigDescription,
    SpectrumDocument,
    StatusDocument,
    StructuresDocument,
    StructureSummaryDocument,
    WindowDocument,
)

from .._config import ServiceSettings, render_toml, resolve_token
from ._dashboard_port import StructureModel, start_dashboard
from ._operator import acknowledge_alarm, check_token
from ..http._metrics import fleet_metrics, merge_expositions
from ..sources._ingest import IngestError
from ._launch import ServeProcess, ServeStartError, start_serve
from ..alarms._notify import Notifier, notify_targets
from ._processes import StaleWorkers, record_workers, stop_stale_workers
from ._service import NotSingleStructure, ServiceError, StructureUnavailable, _StoredRows
from ._structure import _ModelCache
from ..storage._storage import Storage
from ..storage._writer import WriterServer

__all__ = ["WorkerFleet", "part_of"]

log = logging.getLogger("shm.serve.workers")


def part_of(settings: ServiceSettings, index: int, count: int) -> ServiceSettings:
    """The settings of worker ``index`` of ``count``: every ``count``-th structure from ``index``."""
    if not (0 <= index < count):
        raise ValueError(f"worker {index=} must lie within 0..{count - 1}")
    return settings.model_copy(update={"structures": settings.structures[index::count]})


class _Worker:
    def __init__(self, index: int, process: subprocess.Popen, url: str, ids: list[str]) -> None:
        self.index = index
        self.process = process
        self.url = url
        self.ids = ids
        self.summary: str | None = None  # its last stdout line (the --json summary)


class WorkerFleet(_StoredRows):
    """The front of a fleet hosted by worker processes (implements what the API needs)."""

    def __init__(self, settings: ServiceSettings, *, environ: Mapping[str, str] | None = None, json_summary: bool = False) -> None:
        if not settings.fleet or settings.worker_count < 2:
            raise ServiceError("worker processes need [[structures]] and workers >= 2")
        self.settings = settings
        self.fleet = True
        self.token = resolve_token(settings, environ)
        if not settings.server.loopback and self.token is None:
            raise ServiceError(f"server.host {settings.server.host} is not loopback: a token is required "
                               "(server.token_file or SHM_TOKEN)")
        self.started_at = time.time()
        self.order = [s.id for s in settings.structures]
        # the database exists (and is migrated) before the workers open it
        self.storage = Storage(settings.db_path, notify_targets=notify_targets(settings.notify),
                               notify_levels=settings.alarms.notify_levels, notify_cleared=settings.alarms.notify_cleared,
                               notify_stale=settings.alarms.notify_stale, sync=settings.storage_sync,
                               alarm_sync=settings.storage_alarm_sync, retry_s=settings.storage_retry_s)
        self.notifier = Notifier(self.storage, settings.notify, dict(environ) if environ is not None else None)
        self.workers: list[_Worker] = []
        self.owner: dict[str, _Worker] = {}
        self._json = json_summary
        self._environ = dict(os.environ if environ is None else environ)
        self._client = httpx.Client(timeout=30.0)
        # the dashboard polls the structure it shows a few times a second: not a line each in the log
        logging.getLogger("httpx").setLevel(max(logging.WARNING, logging.getLogger("httpx").getEffectiveLevel()))
        self._done = threading.Event()
        self._starting = False
        # the dashboard lives here (it serves every structure); the workers run none
        self.dashboard: Any = None
        self._models = _ModelCache()
        self._structure_models: dict[str, StructureModel] = {}
        self.writer: WriterServer | None = None

    # -- running ----------------------------------------------------------------------------

    def start(self) -> None:
        n = self.settings.worker_count
        directory = Path(self.settings.data_dir or ".")
        directory.mkdir(parents=True, exist_ok=True)
        config = directory / "fleet-workers.toml"
        # an earlier front's workers (it was killed and they did not notice yet) leave the database first
        try:
            ended = stop_stale_workers(self.settings.lock_path, str(config))
        except StaleWorkers as exc:
            raise ServiceError(str(exc)) from None
        if ended:
            log.warning("ended %d workers of an earlier front on %s (pids %s)", len(ended), self.settings.db, ended)
        config.write_text(render_toml(self.settings), encoding="utf-8")
        # this process is the database's one writer: the workers hand it their writes
        self.writer = WriterServer(self.storage)
        environ = {**self._environ, **self.writer.environ()}
        self._starting = True
        launched: list[tuple[int, list[str], ServeProcess]] = []
        try:
            # all at once (the database exists already): they import and build in parallel
            for i in range(n):
                ids = self.order[i::n]
                if not ids:
                    continue
                args = ["--config", str(config), "--worker-of", f"{i}/{n}", "--host", "127.0.0.1", "--port", "0",
                        "--no-dashboard"]  # the front's dashboard reads each structure from its worker
                if self._json:
                    args.append("--json")
                launched.append((i, ids, start_serve(args, env=environ, stdout=subprocess.PIPE,
                                                     ready_file=directory / f"fleet-worker-{i}.ready.json", timeout=None)))
            record_workers(self.settings.lock_path, [started.pid for _, _, started in launched])
            pending = [(_Worker(i, started.process, "", ids), started) for i, ids, started in launched]
            for worker, _ in pending:
                threading.Thread(target=self._drain, args=(worker,), name=f"worker-{worker.index}-out", daemon=True).start()
            for worker, started in pending:
                try:
                    worker.url = started.wait_ready(timeout=600.0)["api"]
                except ServeStartError as exc:
                    code = started.process.wait(60)
                    raise ServiceError(f"worker process {worker.index} of {n} did not start (exit code {code}; its log "
                                       f"is above): {exc}") from None
                self.workers.append(worker)
                for sid in worker.ids:
                    self.owner[sid] = worker
                log.info("worker %d of %d (pid %d): %d structures at %s", worker.index, n, started.pid, len(worker.ids),
                         worker.url)
        except BaseException:
            for _, _, started in launched:
                started.kill()
            raise
        finally:
            self._starting = False
        self.notifier.start()
        threading.Thread(target=self._watch, name="workers", daemon=True).start()
        if self.settings.dashboard.enabled:
            self.dashboard = start_dashboard(self, self.settings, self.token)

    def _drain(self, worker: _Worker) -> None:
        stdout = worker.process.stdout
        assert stdout is not None, "a worker is started with stdout=PIPE"
        with stdout:  # closed at its end: no pipe left to the GC
            for line in stdout:
                line = line.strip()
                if line:
                    worker.summary = line
                    if not self._json:
                        print(line, flush=True)

    def _watch(self) -> None:
        for worker in self.workers:
            worker.process.wait()
        self._done.set()

    def wait(self, timeout: float | None = None) -> bool:
        return self._done.wait(timeout)

    @property
    def done(self) -> bool:
        return self._done.is_set()

    def _terminate(self, wait_s: float) -> None:
        for worker in self.workers:
            if worker.process.poll() is None:
                worker.process.send_signal(signal.SIGTERM)
        deadline = time.monotonic() + wait_s
        for worker in self.workers:
            try:
                worker.process.wait(max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                worker.process.kill()
                worker.process.wait(5.0)

    def stop(self, *, drain_s: float = 2.0) -> int:
        """Stop the workers (each drains and prints its summary) and the notifier; the worst exit code."""
        if self.dashboard is not None:
            try:
                self.dashboard.stop()
            except Exception as exc:
                log.warning("dashboard stop failed: %s", exc)
        self._terminate(wait_s=60.0)  # the workers' last windows are written before the writer stops
        if self.writer is not None:
            self.writer.stop()
        self.notifier.stop(drain_s=drain_s)
        self._client.close()
        self.storage.close()
        return max((w.process.returncode or 0 for w in self.workers), default=0)

    # -- forwarding -------------------------------------------------------------------------

    def _forward(self, method: str, structure_id: str, path: str, **kwargs: Any) -> httpx.Response:
        worker = self.structure(structure_id)
        headers = {"Authorization": f"Bearer {self.token}"} if self.token else {}
        try:
            r = self._client.request(method, f"{worker.url}/api/structures/{structure_id}/{path}", headers=headers, **kwargs)
        except httpx.HTTPError as exc:
            raise StructureUnavailable(f"structure {structure_id!r}: its worker process does not answer ({exc})") from None
        if r.status_code == 404 and path not in ("spectra/latest", "windows/latest"):
            raise KeyError(r.json().get("detail", f"no structure {structure_id!r}"))
        if r.status_code == 409:
            raise StructureUnavailable(r.json().get("detail"))
        return r

    def structure(self, structure_id: str) -> _Worker:
        worker = self.owner.get(structure_id)
        if worker is None:
            if structure_id in self.order:
                raise StructureUnavailable(f"structure {structure_id!r}: its worker process "
                                           f"{'is starting' if self._starting else 'did not start'}")
            known = ", ".join(sorted(self.order)[:20])
            raise KeyError(f"no structure {structure_id!r} (this service monitors: {known})")
        if worker.process.poll() is not None:
            raise StructureUnavailable(f"structure {structure_id!r}: its worker process exited with code "
                                       f"{worker.process.returncode}")
        return worker

    # -- what the API needs -----------------------------------------------------------------

    def check_token(self, token: str | None) -> None:
        check_token(self.token, token)

    def health(self) -> HealthDocument:
        return _fleet_health(self)

    def status(self, structure_id: str | None = None) -> StatusDocument:
        if structure_id is None:
            raise NotSingleStructure("this service monitors a fleet ([[structures]]): use /api/structures and "
                                     "/api/structures/{id}/...")
        r = self._forward("GET", structure_id, "status")
        r.raise_for_status()
        return StatusDocument.model_validate(r.json())

    def structures_document(self) -> StructuresDocument:
        found: dict[str, StructureSummaryDocument] = {}
        for worker in self.workers:
            try:
                doc = self._client.get(f"{worker.url}/api/structures",
                                       headers={"Authorization": f"Bearer {self.token}"} if self.token else {}).json()
                for s in doc["structures"]:
                    found[s["id"]] = StructureSummaryDocument.model_validate(s)
            except (httpx.HTTPError, ValueError, KeyError) as exc:
                code = worker.process.poll()
                why = f"its worker process exited with code {code}" if code is not None else f"its worker does not answer: {exc}"
                for sid in worker.ids:
                    found[sid] = StructureSummaryDocument(id=sid, kind=self._kind(sid), state="failed", error=why)
        for sid in self.order:
            if sid not in found:
                found[sid] = (StructureSummaryDocument(id=sid, kind=self._kind(sid), state="starting") if self._starting else
                              StructureSummaryDocument(id=sid, kind=self._kind(sid), state="failed",
                                                       error="its worker process did not start"))
        return StructuresDocument(structures=[found[sid] for sid in self.order])

    def _kind(self, structure_id: str) -> Any:
        return next(s.source for s in self.settings.structures if s.id == structure_id).partition(":")[0]

    def _known(self, structure_id: str) -> None:
        if structure_id not in self.order:
            self.structure(structure_id)

    def acknowledge(self, alarm_id: int, token: str, by: str) -> AlarmDocument:
        self.check_token(token)
        return acknowledge_alarm(self.storage, alarm_id, by, self.settings.storage_retry_s)

    def request_baseline(self, structure_id: str | None = None) -> BaselineRequestDocument:
        if structure_id is None:
            self.status(None)
        r = self._forward("POST", structure_id, "baseline")  # type: ignore[arg-type]
        r.raise_for_status()
        return BaselineRequestDocument.model_validate(r.json())

    def spectra(self, structure_id: str | None = None) -> SpectrumDocument | None:
        if structure_id is None:
            self.status(None)
        r = self._forward("GET", structure_id, "spectra/latest")  # type: ignore[arg-type]
        if r.status_code == 404:
            return None
        r.raise_for_status()
        return SpectrumDocument.model_validate(r.json())

    def ingest(self, document: Any, structure_id: str | None = None) -> IngestResultDocument | None:
        if structure_id is None:
            self.status(None)
        r = self._forward("POST", structure_id, "ingest", json=document)  # type: ignore[arg-type]
        if r.status_code == 503:
            return None
        if r.status_code == 400:
            raise IngestError(r.json().get("detail", "bad batch"))
        r.raise_for_status()
        return IngestResultDocument.model_validate(r.json())

    def fleet_metrics(self) -> str:
        """``/metrics``: the workers' expositions merged (each structure's samples as its worker gives
        them, the processes' counters summed); the notifications are the front's (it delivers them)."""
        return _fleet_exposition(self)

    # -- the dashboard's port (FleetDashboardService) ---------------------------------------

    def structure_status(self, structure_id: str) -> StatusDocument:
        return self.status(structure_id)

    def structure_spectra(self, structure_id: str) -> SpectrumDocument | None:
        return self.spectra(structure_id)

    def structure_window(self, structure_id: str) -> WindowDocument | None:
        r = self._forward("GET", structure_id, "windows/latest")
        if r.status_code == 404:
            return None
        r.raise_for_status()
        return WindowDocument.model_validate(r.json())

    def structure_rig(self, structure_id: str) -> RigDescription:
        r = self._forward("GET", structure_id, "rig")
        r.raise_for_status()
        return RigDescription.model_validate(r.json())

    def live(self, structure_id: str, after: int = 0) -> LiveEstimatesDocument:
        r = self._forward("GET", structure_id, "live", params={"after": int(after)})
        r.raise_for_status()
        return LiveEstimatesDocument.model_validate(r.json())

    def structure_model(self, structure_id: str) -> StructureModel:
        """The structure's rig from its worker and the model built here from it with the
        structure's estimator settings, as its worker built it (once per distinct rig and
        settings; only for a structure a browser selects)."""
        found = self._structure_models.get(structure_id)
        if found is not None:
            return found
        rig = self.structure_rig(structure_id)
        settings = next(s for s in self.settings.structures if s.id == structure_id)
        model = self._models.get(rig, self.settings.for_structure(settings).estimator)
        found = StructureModel(id=structure_id, rig=rig, units=model.units, layout=model.state_layout, stations=model.stations,
                               units_xi=getattr(model, "units_xi", None))
        self._structure_models[structure_id] = found
        return found


def _fleet_exposition(fleet: WorkerFleet) -> str:
    """The merged exposition of ``WorkerFleet.fleet_metrics``."""
    texts = []
    headers = {"Authorization": f"Bearer {fleet.token}"} if fleet.token else {}
    for worker in fleet.workers:
        if worker.process.poll() is not None:
            continue
        try:
            r = fleet._client.get(f"{worker.url}/metrics", headers=headers)
            r.raise_for_status()
            texts.append(r.text)
        except httpx.HTTPError as exc:
            log.warning("worker %d: /metrics failed: %s", worker.index, exc)
    outcomes, _ = fleet.notifier.snapshot()
    overrides: dict[str, list[tuple[dict[str, Any], float]]] = {"shm_notifications_total": [({"outcome": k}, float(outcomes.get(k, 0)))
                                             for k in ("sent", "retry", "permanent", "given_up")],
                 "shm_uptime_seconds": [({}, round(time.time() - fleet.started_at, 1))]}
    # the structures as the front lists them (a worker that died: its structures failed)
    return merge_expositions(texts, overrides, front=fleet_metrics(fleet.structures_document(), {}))


def _fleet_health(fleet: WorkerFleet) -> HealthDocument:
    """``WorkerFleet.health``: the reasons of every worker, or that it does not answer."""
    reasons: list[str] = []
    for worker in fleet.workers:
        try:
            doc = fleet._client.get(f"{worker.url}/healthz",
                                    headers={"Authorization": f"Bearer {fleet.token}"} if fleet.token else {}).json()
            reasons.extend(doc.get("reasons", []))
        except (httpx.HTTPError, ValueError) as exc:
            reasons.append(f"worker process {worker.index} ({', '.join(worker.ids[:3])}, ...) does not answer: {exc}")
    return HealthDocument(status="degraded" if reasons else "ok", uptime_s=round(time.time() - fleet.started_at, 1),
                          reasons=reasons)
