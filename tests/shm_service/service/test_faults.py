"""Sensor faults injected for real into the running service, in-process and batch by batch
(the long campaign is ``python -m benchmarks.fault_campaign``):
what the service shows (health, status, /metrics) and how soon it recovers, in data seconds."""

from __future__ import annotations

import pytest

from benchmarks.fault_campaign import PHI_OK_RAD, D_OK_M, Scenario, evaluate, run
from shm_service.service.http._app import _metrics

FAULT_AT = 65.0  # after the 60 s rest: the rig moves


def test_absurd_imu_values_at_D_restart_the_filter_and_it_recovers():
    """One second of 100 m/s² across the beam at D (in range, absurd): the filter used to run
    away (d = −2.4·10⁷ m, every aiding update refused, 0 restarts, /healthz ok)."""
    spec = f"spike:/imu/D.accel_y@{FAULT_AT}+1:100"
    observations, status = run("sim", (spec,), FAULT_AT + 35.0)
    before = [o for o in observations if o.t_s < FAULT_AT]
    assert before and all(o.restarts == 0 and o.health == "ok" for o in before)
    during = [o for o in observations if FAULT_AT <= o.t_s < FAULT_AT + 8]
    assert any(o.estimator != "ok" and o.health == "degraded" and any("estimator" in r for r in o.reasons) for o in during)
    # |d| < 5 cm and |φ| < 0.01 rad again within 30 s, and for good
    end = FAULT_AT + 1.0
    late = [o for o in observations if o.t_s >= end + 30.0]
    assert late and all(abs(o.d) < D_OK_M and abs(o.phi) < PHI_OK_RAD and o.estimator == "ok" for o in late)
    outcome = evaluate(Scenario("spike", spec, "/imu/D", FAULT_AT, end), observations, "sim")
    assert outcome.detect_s is not None and outcome.detect_s <= 3.0 and outcome.recover_s is not None and outcome.recover_s <= 30.0
    est = status.pipeline.estimator
    assert est.filter_restarts >= 1 and sum(est.filter_restarts_by_reason.values()) == est.filter_restarts
    assert est.health == "ok" and est.last_estimate is not None
    assert abs(est.last_estimate.d_m) < D_OK_M and abs(est.last_estimate.phi_rad) < PHI_OK_RAD
    assert est.last_estimate.t_s == pytest.approx(status.pipeline.data_time_s, abs=2.0)
    text = _metrics(status)
    restarts = [line for line in text.splitlines() if line.startswith("shm_filter_restarts_total{")]
    assert sum(float(line.split()[-1]) for line in restarts) == est.filter_restarts
    assert "shm_estimator_healthy 1" in text
    # the windows holding the diverged filter's b were not analysed (skipped while it settled)
    assert status.pipeline.windows_skipped_warmup > 0


QUIET_AT = 20.0  # after the 10 s calibration, the rig still at rest: short runs


@pytest.mark.parametrize("source, spec, topic, reason", [
    ("ingest", f"clock:/imu/s2@{QUIET_AT}+1:3.15576e+08", "/imu/s2", "implausible_time"),  # +10 years
    ("sim", f"nan:/tof/s1@{QUIET_AT}+1", "/tof/s1", "nonfinite"),
])
def test_a_sensor_fault_is_detected_counted_and_the_valid_data_go_on(source, spec, topic, reason):
    observations, status = run(source, (spec,), QUIET_AT + 12.0)
    outcome = evaluate(Scenario("x", spec, topic, QUIET_AT, QUIET_AT + 1.0), observations, source)
    assert outcome.detect_s is not None and outcome.detect_s <= 1.5, outcome.row()
    assert outcome.recover_s is not None and outcome.recover_s <= 5.0, outcome.row()
    src = status.sources[0]
    assert src.rejected_by_reason.get(reason, 0) > 0 and outcome.rejected == src.rejected
    assert f'shm_source_rejected_total{{source="{src.id}",reason="{reason}"}}' in _metrics(status)
    assert status.pipeline.late_samples == 0  # nothing stalled behind the fault
