"""The status documents of a service's structures (``/api/status``, ``/metrics``)."""

from __future__ import annotations

import logging
import time
from typing import Any, Protocol

from contract import (
    AlarmCountsDocument,
    BaselineModeDocument,
    BaselineStatusDocument,
    NotificationStatusDocument,
    ServiceStatusDocument,
    SourceStatusDocument,
    StatusDocument,
    StorageStatusDocument,
)

from .._config import ServiceSettings
from ..alarms._notify import Notifier
from ..alarms._sinks import SinkGuard
from ..storage._storage import Storage
from ..storage._url import redact
from ._progress import describe_progress
from ._structure import Structure

__all__ = ["VERSION", "StatusHost", "baseline_modes", "service_state", "status_of"]

log = logging.getLogger("shm.serve")
VERSION = "0.1.0"


class StatusHost(Protocol):
    """What a structure's status reads of the service that runs it (its database, notifier,
    sinks, life time), and nothing more: the status knows this, not the service."""

    settings: ServiceSettings
    fleet: bool
    started_at: float
    storage: Storage
    notifier: Notifier
    dashboard_guard: SinkGuard
    housekeeping_guard: SinkGuard

    @property
    def done(self) -> bool: ...


def service_state(service: StatusHost) -> dict[str, Any]:
    """What every structure's status shares: the database's counts and the notifier's (read once
    for all structures of ``/metrics``)."""
    storage = service.storage
    return {"active": storage.alarms(state="active"), "outbox": storage.outbox_counts(),
            "trend_rows": storage.count("trends"), "notifier": service.notifier.snapshot()}


def status_of(service: StatusHost, structure: Structure, shared: dict[str, Any]) -> StatusDocument:
    """``structure``'s status document (``shared``: ``service_state``)."""
    pipeline = structure.pipeline
    p = pipeline.status(queue_depth=structure.queue.qsize(), queue_capacity=structure.queue.maxsize)
    src = structure.source.status()
    src["dropped"] = src["dropped"] + p.late_samples + p.estimator.dropped_samples
    if pipeline.rejected:  # judged by the pipeline (off the clock, implausible values)
        by_reason = dict(src["rejected_by_reason"])
        for reason, n in pipeline.rejected.items():
            by_reason[reason] = by_reason.get(reason, 0) + n
        src["rejected_by_reason"] = by_reason
        src["rejected"] = sum(by_reason.values())
    src["problems"] = src["problems"] + pipeline.health_problems()
    src["clock_jumps"] = src.get("clock_jumps", 0) + (pipeline.clock.jump_count if pipeline.clock else 0)
    src["latency_s"] = p.pipeline_latency_s
    states = pipeline.sensor_states()
    counts = {"warning": 0, "alarm": 0}
    for a in shared["active"]:
        if not service.fleet or a.source == structure.id:
            counts[a.level] += 1
    outcomes, notifier_sink = shared["notifier"]
    return StatusDocument(
        service=ServiceStatusDocument(
            version=VERSION, started_at=service.started_at, uptime_s=round(time.time() - service.started_at, 1),
            done=structure.done if service.fleet else service.done,
            pipeline_error=structure.pipeline_error, pipeline_errors=structure.pipeline_errors,
            last_pipeline_error=structure.last_pipeline_error,
            progress=_progress(service, structure, p)),
        sources=[SourceStatusDocument(**src)],
        pipeline=p,
        degraded_sensors=sorted(t for t, s in states.items() if s != "ok"),
        sensors=states,
        baseline=BaselineStatusDocument(state=p.baseline, modes=baseline_modes(structure)),
        alarms=AlarmCountsDocument(active=counts),
        notifications=NotificationStatusDocument(**shared["outbox"], sent_this_run=outcomes["sent"],
                                                 failed_attempts_this_run=outcomes["retry"] + outcomes["permanent"]
                                                 + outcomes["given_up"],
                                                 outcomes_this_run=dict(outcomes),
                                                 last_error=service.notifier.last_error),
        storage=StorageStatusDocument(db=redact(str(service.settings.db)), schema_version=service.storage.schema_version,
                                      trend_rows=shared["trend_rows"],
                                      archive=None if pipeline.archive is None else pipeline.archive.status(),
                                      write_retries=service.storage.retries, write_failures=service.storage.failures,
                                      windows_waiting=pipeline.pending_commits, last_error=service.storage.last_error),
        sinks={"dashboard": service.dashboard_guard.status(), "notifier": notifier_sink,
               "housekeeping": service.housekeeping_guard.status()},
        thresholds=structure.thresholds,
        model=structure.model_document,
    )

def _progress(service: StatusHost, structure: Structure, p: Any) -> str | None:
    """What ``structure`` is doing now (``runtime._progress``); never breaks the status."""
    try:
        return describe_progress(structure, p, getattr(service, "compiling_since", None))
    except Exception as exc:
        log.debug("progress of %s: %s", structure.id, exc)
        return None





def baseline_modes(structure: Structure) -> list[BaselineModeDocument] | None:
    """The modes of ``structure``'s active baseline (None while it learns one)."""
    bl = structure.pipeline.analytics.monitor.baseline
    if bl is None:
        return None
    return [BaselineModeDocument(mode=m.mode, unit=m.unit + 1, f_ref_hz=m.f_ref_hz, temperature_ref_c=m.temperature_ref_c,
                                 slope_per_k=m.slope_per_k, sigma_rel=m.sigma_rel) for m in bl.modes]
