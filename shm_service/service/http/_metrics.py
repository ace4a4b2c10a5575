"""``/metrics``: Prometheus text, of one structure (as before) or of a fleet, where every
structure's own samples carry a ``structure="ID"`` label (Prometheus' convention for one target
exposing many instances) and the service's (database, notifier, sinks) appear once. The front of
a fleet's worker processes merges its workers' expositions (``merge_expositions``).
"""

from __future__ import annotations

import re
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

from contract import StatusDocument, StructuresDocument

__all__ = ["fleet_metrics", "merge_expositions", "metrics_text"]

#: Of a fleet's merged exposition: families whose service-level samples every worker reads from the one
#: database (the same value; the newest, largest, is taken), the others (counters of each process) are summed.
SHARED_FAMILIES = frozenset({"shm_uptime_seconds", "shm_notifications", "shm_trend_rows", "shm_structures"})


@dataclass
class _Family:
    name: str
    kind: str
    help: str
    samples: list[tuple[dict[str, Any], float, bool]]  # (labels, value, the structure's own)


def metrics_text(service: Any) -> str:
    """The exposition of ``service``: a fleet's (``fleet_metrics()``) or the single structure's."""
    if getattr(service, "fleet", False) is True:
        return service.fleet_metrics()
    return _metrics(service.status())


def _sample(name: str, labels: dict[str, Any], value: float) -> str:
    text = ",".join(f'{k}="{_label(v)}"' for k, v in labels.items())
    return f"{name}{{{text}}} {value:.17g}" if text else f"{name} {value:.17g}"


def _render(families: Iterable[_Family]) -> str:
    lines: list[str] = []
    for f in families:
        lines.append(f"# HELP {f.name} {f.help}")
        lines.append(f"# TYPE {f.name} {f.kind}")
        lines.extend(_sample(f.name, labels, value) for labels, value, _ in f.samples)
    return "\n".join(lines) + "\n"


def _metrics(st: StatusDocument) -> str:
    """One structure's exposition (a service without ``[[structures]]``)."""
    return _render(_families(st))


def fleet_metrics(structures: StructuresDocument, statuses: dict[str, StatusDocument]) -> str:
    """A fleet's exposition: each structure's samples labelled ``structure``, the service's once
    (from the first status), and per structure its state and lag (``structures``)."""
    merged: dict[str, _Family] = {}
    first = True
    for sid, st in statuses.items():
        for f in _families(st):
            target = merged.setdefault(f.name, _Family(f.name, f.kind, f.help, []))
            for labels, value, own in f.samples:
                if own:
                    target.samples.append(({"structure": sid, **labels}, value, True))
                elif first:
                    target.samples.append((labels, value, False))
        first = False
    counts: dict[str, int] = {}
    for s in structures.structures:
        counts[s.state] = counts.get(s.state, 0) + 1
    extra = [
        _Family("shm_structures", "gauge", "structures of the fleet by state", [({"state": k}, float(v), False)
                                                                               for k, v in sorted(counts.items())]),
        _Family("shm_structure_state", "gauge", "1 for the structure's state (starting, running, degraded, failed, "
                "finished, stopped)", [({"structure": s.id, "state": s.state}, 1.0, True) for s in structures.structures]),
        _Family("shm_structure_lag_seconds", "gauge", "how far the structure's processed data is behind its pace",
                [({"structure": s.id}, float(s.lag_s), True) for s in structures.structures if s.lag_s is not None]),
        _Family("shm_structure_windows_committed", "gauge", "analysis windows of the structure committed to the database",
                [({"structure": s.id}, float(s.windows), True) for s in structures.structures]),
    ]
    return _render([*merged.values(), *extra])


_SAMPLE = re.compile(r"^([a-zA-Z_:][a-zA-Z0-9_:]*)(\{.*\})? (\S+)$")


def merge_expositions(texts: Iterable[str], overrides: dict[str, list[tuple[dict[str, Any], float]]] | None = None,
                      front: str = "") -> str:
    """One exposition of several processes' (a fleet's workers, each its own structures): the
    families in their first order, every structure's samples (they carry ``structure=``) as they
    are, the service's samples combined: those of ``SHARED_FAMILIES`` (read from the one database)
    the largest, the others (each process's counters) summed. ``overrides`` replaces the
    service's samples of a family (what the front itself knows: its notifier's deliveries); the
    families of ``front`` (the front's own exposition: the fleet's structures as it lists them)
    replace the texts' families of the same name whole."""
    overrides = overrides or {}
    front_names = {m.group(1) for m in map(_SAMPLE.match, front.splitlines()) if m is not None}
    texts = [*(_without(t, front_names) for t in texts), front]
    meta: dict[str, list[str]] = {}
    own: dict[str, list[str]] = {}
    service: dict[str, dict[str, float]] = {}
    for text in texts:
        for line in text.splitlines():
            if line.startswith("# HELP ") or line.startswith("# TYPE "):
                name = line.split()[2]
                entry = meta.setdefault(name, [])
                if len(entry) < 2 and line not in entry:
                    entry.append(line)
                continue
            m = _SAMPLE.match(line)
            if m is None:
                continue
            name, labels, value = m.group(1), m.group(2) or "", float(m.group(3))
            meta.setdefault(name, [])
            if 'structure="' in labels:
                own.setdefault(name, []).append(line)
            else:
                values = service.setdefault(name, {})
                if name in SHARED_FAMILIES:
                    values[labels] = max(values.get(labels, value), value)
                else:
                    values[labels] = values.get(labels, 0.0) + value
    lines: list[str] = []
    for name, header in meta.items():
        lines.extend(header)
        if name in overrides:
            lines.extend(_sample(name, labels, value) for labels, value in overrides[name])
        else:
            lines.extend(f"{name}{labels} {value:.17g}" for labels, value in service.get(name, {}).items())
        lines.extend(own.get(name, []))
    return "\n".join(lines) + "\n"


def _label(value: Any) -> str:
    return str(value).replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n")


def _families(st: StatusDocument) -> list[_Family]:
    """The metric families of one structure's status: each sample marked as the structure's own
    (labelled ``structure`` in a fleet) or the service's (the database, the notifier, the sinks:
    the same for every structure of one process)."""
    out: list[_Family] = []

    def metric(name: str, kind: str, help_text: str, samples: list[tuple[dict[str, Any], Any]],
               service: tuple[str, ...] = ()) -> None:
        """``service``: the label values (of ``component``/``sink``) or, for a whole family, ``("*",)`` that are the service's."""
        marked = []
        for labels, value in samples:
            if value is None:
                continue
            own = not ("*" in service or any(v in service for v in labels.values()))
            marked.append((labels, float(value), own))
        out.append(_Family(name, kind, help_text, marked))

    p = st.pipeline
    srcs = st.sources
    n = st.notifications
    metric("shm_uptime_seconds", "gauge", "seconds since the service started", [({}, st.service.uptime_s)], service=("*",))
    sinks = st.sinks
    metric("shm_pipeline_errors_total", "counter", "batches the pipeline failed on (skipped)", [({}, st.service.pipeline_errors)])
    metric("shm_errors_total", "counter", "errors by component; the monitoring goes on (a failed batch is skipped, a "
           "failed write waits in memory and is retried, a failing sink is isolated)",
           [({"component": "pipeline"}, st.service.pipeline_errors), ({"component": "storage"}, st.storage.write_failures),
            *[({"component": "source"}, int(s.state == "failed")) for s in srcs[:1]],
            *[({"component": name}, sink.errors) for name, sink in sinks.items()]],
           service=("storage", *sinks))
    metric("shm_batches_skipped_total", "counter", "batches of samples skipped because the pipeline failed on them",
           [({}, st.service.pipeline_errors)])
    metric("shm_source_messages_total", "counter", "samples accepted from the source",
           [({"source": s.id, "kind": s.kind}, s.messages) for s in srcs])
    metric("shm_source_rejected_total", "counter", "samples rejected, by reason (malformed, nonfinite, duplicate, backwards, "
           "implausible_time, ahead_of_source, implausible_value, ...)",
           [({"source": s.id, "reason": r}, v) for s in srcs for r, v in s.rejected_by_reason.items()])
    metric("shm_source_dropped_total", "counter", "samples dropped (late, or without the reference IMU)",
           [({"source": s.id}, s.dropped) for s in srcs])
    metric("shm_samples_dropped_total", "counter", "samples accepted but not estimated, by reason",
           [({"reason": "late"}, p.late_samples), ({"reason": "reference_imu_silent"}, p.estimator.dropped_samples)])
    metric("shm_source_clock_jumps_total", "counter", "stamps or batches found off the source's clock",
           [({"source": s.id}, s.clock_jumps) for s in srcs])
    metric("shm_source_rate_hz", "gauge", "incoming samples per second", [({"source": s.id}, s.rate_hz) for s in srcs])
    metric("shm_source_data_time_seconds", "gauge", "newest sample time (UNIX s)", [({"source": s.id}, s.data_time_s) for s in srcs])
    metric("shm_pipeline_latency_seconds", "gauge", "time from a batch's arrival to its processing", [({}, p.pipeline_latency_s)])
    metric("shm_queue_depth", "gauge", "batches waiting in the pipeline queue", [({}, p.queue_depth)])
    metric("shm_estimates_total", "counter", "estimator outputs", [({}, p.estimates)])
    metric("shm_windows_total", "counter", "analysis windows processed", [({}, p.windows)])
    metric("shm_windows_skipped_total", "counter", "analysis windows not analysed, by reason (incomplete data; warmup: "
           "the filter converging after the start or a restart)",
           [({"reason": "incomplete"}, p.windows_skipped_incomplete), ({"reason": "warmup"}, p.windows_skipped_warmup)])
    est = p.estimator
    metric("shm_filter_restarts_total", "counter", "restarts of the estimator's filter, by reason (bounds, nis, rejections, "
           "nonfinite: diverged; gap: the reference IMU fell silent)",
           [({"reason": r}, v) for r, v in sorted(est.filter_restarts_by_reason.items())] or [({"reason": "none"}, 0)])
    metric("shm_estimator_healthy", "gauge", "1 while the estimator's health check finds it tracking, 0 while it is diverged "
           "or recovering", [({}, int(est.health == "ok"))])
    metric("shm_notifications_total", "counter", "notification delivery attempts this run, by outcome (sent; retry: a "
           "temporary failure; permanent: refused by the target; given_up)",
           [({"outcome": k}, n.outcomes_this_run.get(k, 0)) for k in ("sent", "retry", "permanent", "given_up")], service=("*",))
    metric("shm_storage_write_retries_total", "counter", "database writes retried after a transient error",
           [({}, st.storage.write_retries)], service=("*",))
    metric("shm_storage_windows_waiting", "gauge", "analysed windows waiting for the database", [({}, st.storage.windows_waiting)])
    metric("shm_sensor_degraded", "gauge", "1 when a sensor is degraded or silent",
           [({"topic": t}, 0 if v == "ok" else 1) for t, v in st.sensors.items()])
    metric("shm_alarms_active", "gauge", "active alarms by level", [({"level": k}, v) for k, v in st.alarms.active.items()])
    metric("shm_notifications", "gauge", "notifications in the outbox by status",
           [({"status": "pending"}, n.pending), ({"status": "sent"}, n.sent), ({"status": "failed"}, n.failed)],
           service=("*",))
    metric("shm_sink_errors_total", "counter", "failures of a sink (dashboard, notifier) by what it was doing",
           [({"sink": name, "kind": kind}, v) for name, sink in st.sinks.items() for kind, v in sink.errors_by_kind.items()],
           service=("*",))
    metric("shm_trend_rows", "gauge", "trend rows stored", [({}, st.storage.trend_rows)], service=("*",))
    _fatigue_families(metric, p.hot_spots)  # the hot spots after the last committed window
    return out



def _fatigue_families(metric: Callable[..., None], spots: list[Any]) -> None:
    """The hot spots' fatigue families; none without hot spots."""
    if not spots:
        return
    metric("shm_fatigue_consumed_ratio", "gauge", "consumed fatigue life D of a hot spot (Palmgren-Miner; 1 = exhausted)",
           [({"hot_spot": h.name}, h.consumed) for h in spots])
    metric("shm_fatigue_del_pascals", "gauge", "damage-equivalent nominal stress range of the last window, per Woehler exponent m",
           [({"hot_spot": h.name, "m": m}, v) for h in spots for m, v in sorted(h.del_pa.items())])
    metric("shm_fatigue_max_range_pascals", "gauge", "largest nominal stress range of the last window",
           [({"hot_spot": h.name}, h.max_range_pa) for h in spots])
    metric("shm_fatigue_damage_rate_per_year", "gauge", "damage per year over the trailing windows",
           [({"hot_spot": h.name}, h.rate_per_year) for h in spots])
    metric("shm_fatigue_remaining_life_years", "gauge", "remaining life (1 - D)/rate; absent while nothing is consumed "
           "(below the S-N curve's cut-off) or no rate is known", [({"hot_spot": h.name}, h.remaining_years) for h in spots])


def _without(text: str, names: set[str]) -> str:
    """``text`` without the families ``names`` (their HELP, TYPE and samples)."""
    keep = []
    for line in text.splitlines():
        if line.startswith("# "):
            parts = line.split()
            if len(parts) > 2 and parts[2] in names:
                continue
        else:
            m = _SAMPLE.match(line)
            if m is not None and m.group(1) in names:
                continue
        keep.append(line)
    return "\n".join(keep)
