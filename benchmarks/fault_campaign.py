"""The sensor-fault campaign: faults injected into ``sim`` (the virtual
rig's samples, before the service sees them) and into ``ingest`` (the same samples, faulted,
sent as ingest requests through the validator), with the time to detect and to recover of each.

The service runs in-process and batch by batch (no threads, no pacing), so the times are in
DATA seconds and do not depend on the machine: after every batch the service's own indicators
are read — what ``/api/status`` and ``/healthz`` would show at that instant:

- detected: the first batch after the fault began at which the service shows it: the faulty
  sensor degraded, its samples rejected (counted), the source's clock jump reported, or the
  estimator diverged (restarting);
- recovered: the first batch after the fault ended from which on every indicator is back (the
  sensor ok, no new rejection, the estimator healthy, |d| < 5 cm and |φ| < 0.01 rad) for good.

``python -m benchmarks.fault_campaign`` prints the table (``make bench`` runs it);
``tests/shm_service/service/test_faults.py`` runs a few of its scenarios.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

_NS = 1_000_000_000

#: Fast analytics (the estimator is what is faulted; the alarms are tested elsewhere).
FAST = {
    "analytics": {"window_s": 20.0, "overlap": 0.5, "baseline_s": 40.0, "baseline_min_windows": 3},
    "estimator": {"calibration_s": 10.0, "warmup_s": 5.0, "chunk_s": 1.0},
    "dashboard": {"enabled": False},
    "archive": {"enabled": False},
    "server": {"port": 0},
}

D_OK_M = 0.05
PHI_OK_RAD = 0.01


@dataclass
class Observation:
    """What the service shows after one batch (data time ``t_s`` after the source's first sample)."""

    t_s: float
    health: str
    reasons: list[str]
    estimator: str
    restarts: int
    d: float | None
    phi: float | None
    degraded: set[str]
    rejected: int
    clock_jumps: bool


@dataclass
class Scenario:
    name: str
    fault: str  # a sim fault spec (service._faults)
    topic: str
    start_s: float
    end_s: float


@dataclass
class Outcome:
    scenario: Scenario
    source: str
    detect_s: float | None
    recover_s: float | None
    how: str
    restarts: int
    rejected: int
    extra: dict = field(default_factory=dict)

    def row(self) -> dict:
        return {"source": self.source, "fault": self.scenario.name, "spec": self.scenario.fault,
                "detect_s": None if self.detect_s is None else round(self.detect_s, 2),
                "recover_s": None if self.recover_s is None else round(self.recover_s, 2),
                "detected_by": self.how, "filter_restarts": self.restarts, "rejected": self.rejected}


def settings(tmp: Path, *, source: str, faults: tuple[str, ...], duration_s: float, seed: int = 3) -> Any:
    from shm_service.service import load_settings

    cfg = json.loads(json.dumps(FAST))
    cfg.update({"db": str(tmp / "shm.sqlite"), "source": {"spec": source},
                "sim": {"duration_s": duration_s, "faults": list(faults) if source == "sim" else [], "seed": seed,
                        "damage_at_s": None}})
    return load_settings(None, cfg)


def _observe(service: Any, start_ns: int, fault_topic: str | None) -> Observation:
    p = service.pipeline
    health = service.health()
    est = p.estimator
    last = est.last_estimate
    status = service.source.status()
    rejected = sum(p.rejected.values()) + status["rejected"]
    states = p.sensor_states()
    return Observation(
        t_s=((p.newest_ns or start_ns) - start_ns) / _NS, health=health.status, reasons=health.reasons,
        estimator=est.health, restarts=est.resets, d=None if last is None else last[1],
        phi=None if last is None else last[2], degraded={t for t, v in states.items() if v != "ok"},
        rejected=rejected, clock_jumps=any("clock jump" in r for r in health.reasons))


def _ingest_document(batch: Any) -> bytes:
    """The batch's samples as an ingest request body (JSON with NaN tokens, as a client sends them)."""
    from contract import PAYLOAD_FIELDS, classify_topic

    messages = []
    for b in batch.blocks:
        fields = PAYLOAD_FIELDS[classify_topic(b.topic).title]
        for t, row in zip(b.log_time_ns.tolist(), b.values.tolist()):
            payload, k = {}, 0
            for spec in fields:
                width = spec.size or 1
                payload[spec.name] = row[k] if spec.size == 0 else row[k:k + width]
                k += width
            messages.append({"topic": b.topic, "log_time_ns": t, "payload": payload})
    return json.dumps({"messages": messages}).encode()


def run(source: str, faults: tuple[str, ...], duration_s: float, *, fault_topic: str | None = None,
        seed: int = 3) -> tuple[list[Observation], Any]:
    """Run a simulated rig with ``faults`` through the service (``source`` "sim" or "ingest"),
    observing after every 1 s batch. Returns the observations and the final status document."""
    from shm_service.service.sources._ingest import parse_body
    from shm_service.service import MonitoringService
    from shm_service.service.sources._sources import SimSource

    with tempfile.TemporaryDirectory() as tmp:
        s = settings(Path(tmp), source=source, faults=faults, duration_s=duration_s, seed=seed)
        service = MonitoringService(s, environ={})
        if source == "sim":
            sim = service.source
        else:  # the same simulation, faulted, sent as ingest requests
            import queue

            sim_settings = settings(Path(tmp), source="sim", faults=faults, duration_s=duration_s, seed=seed)
            sim = SimSource("sim", queue.Queue(), sim_settings, raw=False, truth=False)
        start_ns = sim.settings.start_time_ns
        observations = []
        try:
            for batch in sim.batches(1.0):
                if source == "sim":
                    service.pipeline.process(batch)
                else:
                    service.source.submit(parse_body(_ingest_document(batch)))
                    while not service.queue.empty():
                        service.pipeline.process(service.queue.get_nowait())
                observations.append(_observe(service, start_ns, fault_topic))
            service.pipeline.finish()
            status = service.status()
        finally:
            service.storage.close()
        return observations, status


def _indicated(o: Observation, topic: str, rejected_before: int) -> str | None:
    if o.estimator != "ok":
        return "estimator " + o.estimator
    if o.clock_jumps:
        return "clock jump reported"
    if topic in o.degraded:
        return "sensor degraded"
    if o.rejected > rejected_before:
        return "samples rejected"
    return None


def _normal(o: Observation, topic: str, rejected_prev: int) -> bool:
    # A clock jump stays reported for a while by design (source degraded): recovered means the
    # valid data are processed again, the report may still stand.
    return (o.estimator == "ok" and topic not in o.degraded and o.rejected == rejected_prev
            and o.d is not None and abs(o.d) < D_OK_M and abs(o.phi) < PHI_OK_RAD)


def evaluate(scenario: Scenario, observations: list[Observation], source: str) -> Outcome:
    """Time to detect (from the fault's start) and to recover (from its end), in data seconds."""
    before = [o for o in observations if o.t_s < scenario.start_s]
    base = before[-1].rejected if before else 0
    detect, how = None, "not detected"
    for o in observations:
        if o.t_s >= scenario.start_s:
            why = _indicated(o, scenario.topic, base)
            if why is not None:
                detect, how = o.t_s - scenario.start_s, why
                break
    recover = None
    after = [(i, o) for i, o in enumerate(observations) if o.t_s >= scenario.end_s]
    for k, (_, o) in enumerate(after):
        if all(_normal(q, scenario.topic, observations[j - 1].rejected) for j, q in after[k:]):
            recover = max(o.t_s - scenario.end_s, 0.0)
            break
    last = observations[-1]
    cleared = next((o.t_s - scenario.end_s for o in observations if o.t_s >= scenario.end_s and o.health == "ok"
                    and all(q.health == "ok" for q in observations if q.t_s >= o.t_s)), None)
    outcome = Outcome(scenario, source, detect, recover, how, last.restarts, last.rejected - base)
    outcome.extra["healthz_ok_after_s"] = None if cleared is None else round(max(cleared, 0.0), 2)
    return outcome


def scenarios(at_s: float = 80.0) -> list[Scenario]:
    """Every fault kind once, the clock jumps from ±1 s to ±10 years (IMU D: the estimator's
    reference; /tof/s1 for NaN and stuck: a sensor the others can do without)."""
    year = 365.25 * 86400
    out = [
        Scenario("silence 5 s", f"silence:/imu/s2@{at_s}+5", "/imu/s2", at_s, at_s + 5),
        Scenario("NaN 1 s", f"nan:/imu/s2@{at_s}+1", "/imu/s2", at_s, at_s + 1),
        Scenario("spike 100 m/s² 1 s", f"spike:/imu/D.accel_y@{at_s}+1:100", "/imu/D", at_s, at_s + 1),
        Scenario("spike 10⁶ m/s² 1 s", f"spike:/imu/D.accel_y@{at_s}+1:1e6", "/imu/D", at_s, at_s + 1),
        Scenario("stuck 5 s", f"stuck:/strain/g2@{at_s}+5", "/strain/g2", at_s, at_s + 5),
    ]
    for label, shift in (("+1 s", 1.0), ("-1 s", -1.0), ("+1 h", 3600.0), ("-1 h", -3600.0), ("+10 y", 10 * year),
                         ("-10 y", -10 * year)):
        out.append(Scenario(f"clock {label} for 1 s", f"clock:/imu/s2@{at_s}+1:{shift:g}", "/imu/s2", at_s, at_s + 1))
    return out


def campaign(sources: tuple[str, ...] = ("sim", "ingest"), at_s: float = 80.0, after_s: float = 40.0,
             only: str | None = None) -> list[Outcome]:
    outcomes = []
    for sc in scenarios(at_s):
        if only and only not in sc.name:
            continue
        for source in sources:
            began = time.perf_counter()
            observations, _ = run(source, (sc.fault,), sc.end_s + after_s, fault_topic=sc.topic)
            outcome = evaluate(sc, observations, source)
            outcome.extra["wall_s"] = round(time.perf_counter() - began, 1)
            outcomes.append(outcome)
            print(json.dumps({**outcome.row(), **outcome.extra}), flush=True)
    return outcomes


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.fault_campaign", description=__doc__.splitlines()[0])
    ap.add_argument("--sources", default="sim,ingest", help="comma-separated: sim, ingest")
    ap.add_argument("--only", help="only the scenarios whose name contains this")
    ap.add_argument("--at", type=float, default=80.0, help="data time the fault begins, s (after the 60 s rest)")
    args, _ = ap.parse_known_args(argv)
    outcomes = campaign(tuple(args.sources.split(",")), at_s=args.at, only=args.only)
    print("\n| source | fault | detected after | by | recovered after | /healthz ok after | filter restarts | rejected |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    for o in outcomes:
        r = o.row()
        fmt = lambda v: "–" if v is None else f"{v:.1f} s"  # noqa: E731
        print(f"| {r['source']} | {r['fault']} | {fmt(r['detect_s'])} | {r['detected_by']} | {fmt(r['recover_s'])} | "
              f"{fmt(o.extra.get('healthz_ok_after_s'))} | {r['filter_restarts']} | {r['rejected']} |")
    # the bar: every fault is shown by the service and every one is recovered from
    missed = [f"{o.source}: {o.scenario.name}" for o in outcomes if o.detect_s is None or o.recover_s is None]
    print(f"\n{len(outcomes) - len(missed)} of {len(outcomes)} faults detected and recovered from"
          + (f"; not: {', '.join(missed)}" if missed else ""))
    return 1 if missed or not outcomes else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
