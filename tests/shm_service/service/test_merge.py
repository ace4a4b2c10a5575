"""The merge stage (``MergeStage``) on small hand-made streams (times in ms)."""

from __future__ import annotations

import numpy as np
import pytest
from pydantic import ValidationError

from shm_service.recording import FollowBlock
from shm_service.service.stages._merge import MergeSettings, MergeStage

_MS = 1_000_000


def _block(topic: str, times_ms) -> FollowBlock:
    t = np.asarray(times_ms, dtype=np.int64) * _MS
    return FollowBlock(topic, "imu", topic.rsplit("/", 1)[-1], t, t.copy(), np.arange(len(t), dtype=float)[:, None])


def _ms(released, topic):
    return (released[topic][0] // _MS).tolist()


def test_it_waits_for_the_slowest_sensor_up_to_the_lateness():
    merge = MergeStage(MergeSettings(lateness_s=0.010))  # 10 ms
    merge.add(_block("/imu/D", [0, 5, 10, 15, 20]))
    merge.add(_block("/imu/s1", [0, 5]))
    # cutoff max(20 - 10, 5 + 1) = 10 ms: D up to 5 ms, s1 all
    out = merge.release()
    assert _ms(out, "/imu/D") == [0, 5] and _ms(out, "/imu/s1") == [0, 5]
    assert merge.release() == {}  # nothing new
    merge.add(_block("/imu/s1", [10, 15, 20]))
    out = merge.release()  # cutoff max(20 - 10, 20 + 1) = 21 ms
    assert _ms(out, "/imu/D") == [10, 15, 20] and _ms(out, "/imu/s1") == [10, 15, 20]


def test_a_sample_older_than_what_was_released_is_late_and_counted():
    merge = MergeStage(MergeSettings(lateness_s=0.001))  # 1 ms
    merge.add(_block("/imu/D", [0, 5, 10]))
    merge.add(_block("/imu/s1", [0, 5, 10]))
    assert _ms(merge.release(), "/imu/D") == [0, 5, 10]  # cutoff max(10 - 1, 10 + 1) = 11 ms
    merge.add(_block("/imu/s2", [8, 12]))
    assert merge.late == {"/imu/s2": 1}
    assert _ms(merge.release(final=True), "/imu/s2") == [12]


def test_the_final_release_gives_everything():
    merge = MergeStage(MergeSettings(lateness_s=1.0))
    merge.add(_block("/imu/D", [0, 5, 10]))
    merge.add(_block("/imu/s1", [0]))
    assert _ms(merge.release(), "/imu/D") == [0]  # waiting for s1 (cutoff 1 ms)
    out = merge.release(final=True)
    assert _ms(out, "/imu/D") == [5, 10] and "/imu/s1" not in out


def test_one_sensor_waits_for_no_other():
    merge = MergeStage(MergeSettings(lateness_s=1.0))
    merge.add(_block("/imu/D", [0, 5, 10]))
    assert _ms(merge.release(), "/imu/D") == [0, 5, 10]


def test_the_settings_refuse_a_negative_lateness():
    with pytest.raises(ValidationError, match="lateness_s"):
        MergeSettings(lateness_s=-1.0)


def test_the_settings_refuse_no_lateness():
    # [source] lateness_s is also the default of max_ahead_s, which must be > 0
    with pytest.raises(ValidationError, match="lateness_s"):
        MergeSettings(lateness_s=0.0)
