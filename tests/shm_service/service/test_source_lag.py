"""``lag_s`` of ``/api/status``: a live source is measured against the wall clock, a paced one
(sim, replay at k × real time) against its own clock, which starts with its first data (the
simulator's clock starts in 2026: wall clock minus data time would be months)."""

from __future__ import annotations

import queue
import time

import pytest

from shm_service.service.sources._sources import Source, data_lag_s

_NS = 1_000_000_000
SIM_START_NS = 1_767_225_600 * _NS  # 2026-01-01T00:00:00Z, the virtual rig's clock


def test_a_live_source_lags_by_wall_clock_minus_data_time():
    assert data_lag_s(1_700_000_000 * _NS, 1_700_000_002.5) == pytest.approx(2.5)
    assert data_lag_s(None, 1_700_000_002.5) is None


def test_a_paced_source_lags_by_speed_times_wall_minus_data_since_its_start():
    origin = (100.0, SIM_START_NS)  # (monotonic s, data ns) of the first data
    # 4x real time: 10 s of wall should have brought 40 s of data; 40 s came: on schedule
    assert data_lag_s(SIM_START_NS + 40 * _NS, 110.0, speed=4.0, origin=origin) == pytest.approx(0.0)
    # 30 s came: 10 s of data behind (the pipeline held the source back)
    assert data_lag_s(SIM_START_NS + 30 * _NS, 110.0, speed=4.0, origin=origin) == pytest.approx(10.0)
    # at max speed there is no schedule to lag behind
    assert data_lag_s(SIM_START_NS + 30 * _NS, 110.0, speed=None, origin=origin) is None


def test_a_simulated_source_reports_no_lag_of_months():
    src = Source("sim", queue.Queue())
    src.paced, src.speed = True, 4.0
    src.data_time_ns = SIM_START_NS + 12 * _NS
    src._clock_origin = (time.monotonic() - 3.0, SIM_START_NS)  # started 3 s ago at 4x: 12 s of data is on schedule
    lag = src.status()["lag_s"]
    assert lag is not None and 0.0 <= lag < 12.0  # what time has passed since, not 2026-01-01 minus today
