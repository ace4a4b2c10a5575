"""The dashboard's status line gives the estimator's rate (estimates per second of data) and its
pace against real time, from the service's status, not how often a state is handed to the picture
(one per batch: "estimates 1 Hz" for a 200 Hz filter)."""

from __future__ import annotations

from web import rates_text
from web._feed import _Store


def test_the_rates_come_from_the_estimators_progress_between_status_polls():
    store = _Store()
    assert store.snapshot().filter_rate_hz is None
    assert rates_text(store.snapshot()).startswith("estimates: waiting")
    # (monotonic s, estimates, processed data s): 4000 estimates over 20 s of data in 5 s of wall time
    store.progress.extend([(100.0, 10_000, 50.0), (102.5, 12_000, 60.0), (105.0, 14_000, 70.0)])
    store.drawn_times.extend([100.0, 101.0, 102.0, 103.0, 104.0])  # a state drawn once a second
    snap = store.snapshot()
    assert snap.filter_rate_hz == 200.0 and snap.realtime_factor == 4.0 and snap.estimate_rate_hz == 1.0
    assert rates_text(snap) == "estimates 200 Hz · 4.0× real time · drawn 1 Hz"


def test_no_progress_gives_no_rate():
    store = _Store()
    store.progress.extend([(100.0, 10_000, 50.0), (105.0, 10_000, 50.0)])  # the source has ended
    assert store.snapshot().filter_rate_hz is None and store.snapshot().realtime_factor is None
