"""The runtime's stages on their own and the scheduler that steps them (item 4):
small inputs, exact expectations."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest
from pydantic import ValidationError
from svc_helpers import wait_for

from shm_service.service import StorageUnavailable, WindowCommit
from shm_service.service.stages._pipeline import AnalysisInbox
from shm_service.service.runtime._scheduler import Scheduler, SchedulerSettings
from shm_service.service.stages._commit import CommitSettings, CommitStage, PendingCommit
from shm_service.service.stages._estimate import EstimateSettings, calibration_from_dict, calibration_to_dict
from shm_service.service.stages._archive import ArchiveSettings

# -- the scheduler ------------------------------------------------------------------------------


class _Lane:
    """``work`` steps of ``cost_s`` each; records how many threads step it at once."""

    def __init__(self, name: str, work: int, cost_s: float = 0.0, log: list | None = None) -> None:
        self.name, self.work, self.cost_s, self.finished = name, work, cost_s, False
        self.steps = 0
        self.inside = 0
        self.most_inside = 0
        self.log = log
        self.lock = threading.Lock()

    def ready(self) -> bool:
        return self.steps < self.work

    def step(self) -> None:
        with self.lock:
            self.inside += 1
            self.most_inside = max(self.most_inside, self.inside)
        if self.cost_s:
            time.sleep(self.cost_s)
        self.steps += 1
        if self.log is not None:
            self.log.append(self.name)
        with self.lock:
            self.inside -= 1
        if self.steps >= self.work:
            self.finished = True




def test_the_scheduler_takes_the_lanes_round_robin():
    log: list[str] = []
    lanes = [_Lane(f"s{k}", work=3 + k % 2, log=log) for k in range(4)]
    scheduler = Scheduler(SchedulerSettings(threads=1))
    with scheduler._cv:  # added together: the first round sees them all
        for lane in lanes:
            scheduler._lanes.append(lane)
    scheduler._start()
    wait_for(lambda: all(lane.finished for lane in lanes))
    scheduler.stop()
    assert log == ["s0", "s1", "s2", "s3"] * 3 + ["s1", "s3"]  # each in turn; a finished lane leaves the rotation
    assert scheduler.lanes == 0 and scheduler.steps == 14


def test_each_lane_is_stepped_by_one_thread_at_a_time():
    lanes = [_Lane(f"s{k}", work=20, cost_s=0.001) for k in range(5)]
    scheduler = Scheduler(SchedulerSettings(threads=3))
    for lane in lanes:
        scheduler.add(lane)
    wait_for(lambda: all(lane.finished for lane in lanes))
    scheduler.stop()
    assert [lane.steps for lane in lanes] == [20] * 5
    assert max(lane.most_inside for lane in lanes) == 1  # a lane's steps never overlap: its data stay in order


def test_a_slow_lane_holds_one_thread_and_the_others_go_on():
    slow = _Lane("slow", work=1, cost_s=2.0)
    fast = [_Lane(f"f{k}", work=50) for k in range(4)]
    scheduler = Scheduler(SchedulerSettings(threads=2))
    scheduler.add(slow)
    time.sleep(0.05)
    for lane in fast:
        scheduler.add(lane)
    wait_for(lambda: all(lane.finished for lane in fast))
    assert not slow.finished  # the fast lanes finished while the slow one was still in its step
    wait_for(lambda: slow.finished)
    scheduler.stop()


def test_a_lane_that_fails_is_logged_and_the_pool_goes_on(caplog):
    class Bad(_Lane):
        def step(self) -> None:
            self.steps += 1
            raise RuntimeError("boom")

        def ready(self) -> bool:
            return self.steps < 3

    bad, good = Bad("bad", 3), _Lane("good", 10)
    scheduler = Scheduler(SchedulerSettings(threads=1))
    scheduler.add(bad)
    scheduler.add(good)
    wait_for(lambda: good.finished and bad.steps == 3)
    scheduler.stop()
    assert "lane bad failed a step" in caplog.text


def test_background_lanes_wait_for_the_pace_lanes_and_take_at_most_their_threads():
    log: list[str] = []

    class Background(_Lane):
        background = True

    slow = [Background(f"a{k}", work=2, cost_s=0.2, log=log) for k in range(3)]
    pace = [_Lane(f"d{k}", work=2, log=log) for k in range(2)]
    scheduler = Scheduler(SchedulerSettings(threads=3, background_threads=1))
    with scheduler._cv:  # added together, the background lanes first in the rotation
        scheduler._lanes.extend([*slow, *pace])
    scheduler._start()
    wait_for(lambda: all(lane.finished for lane in [*slow, *pace]))
    scheduler.stop()
    assert set(log[:4]) == {"d0", "d1"}  # the pace lanes' steps first, though behind in the rotation
    assert max(lane.most_inside for lane in slow) == 1
    assert sorted(log[4:]) == sorted(["a0", "a1", "a2"] * 2)  # one background step at a time: in rotation order
    assert log[4:] == ["a0", "a1", "a2"] * 2


def test_scheduler_settings_are_validated():
    with pytest.raises(ValidationError, match="threads"):
        SchedulerSettings(threads=0)
    with pytest.raises(ValidationError, match="extra"):
        SchedulerSettings(thread=2)
    with pytest.raises(ValidationError, match="background_threads"):
        SchedulerSettings(background_threads=0)


# -- the analysis lane's inbox ----------------------------------------------------------------


def test_the_inbox_handles_items_in_order_holds_the_data_back_when_full_and_retries_when_idle():
    handled: list[int] = []
    idles: list[float] = []
    inbox = AnalysisInbox(lambda item: handled.append(item[1]), lambda: idles.append(time.monotonic()) or True,
                          capacity=3, idle_s=0.05)
    for k in range(4):
        inbox.items.append(("chunk", k))
    assert inbox.full and inbox.ready()
    inbox.step()
    assert handled == [0] and inbox.full  # 3 left: still full (capacity 3)
    inbox.step()
    assert not inbox.full
    inbox.drain()
    assert handled == [0, 1, 2, 3] and not idles
    time.sleep(0.06)
    assert inbox.ready()  # empty, and the idle retry is due
    inbox.step()
    assert len(idles) == 1 and not inbox.ready()


# -- the commit stage ---------------------------------------------------------------------------


class _Storage:
    """Refuses ``fail`` commits (the database unavailable), then writes them in order."""

    def __init__(self, fail: int) -> None:
        self.fail = fail
        self.written: list[float] = []

    def commit_window(self, commit: WindowCommit, *, retry_s: float | None = None) -> list[int]:
        if self.fail:
            self.fail -= 1
            raise StorageUnavailable("database is locked")
        self.written.append(commit.window_start_s)
        return []


def _pending(start: float, raised: dict[str, str]) -> PendingCommit:
    return PendingCommit(WindowCommit("s", start, start + 20.0, [], {"monitor": None}, None), raised)


def test_windows_wait_for_the_database_in_order_and_their_alarms_count_once_written():
    storage = _Storage(fail=2)
    written: list[float] = []
    stage = CommitStage(storage, "s", {}, CommitSettings(retry_s=0.0), on_written=lambda p: written.append(p.commit.window_start_s))
    stage.pending.append(_pending(0.0, {"frequency-1": "warning"}))
    assert stage.flush() is False and stage.storage_errors == 1 and "1 window(s) wait" in stage.storage_error
    assert stage.committed_alarms == {}  # not written: not the database's state
    stage.pending.append(_pending(10.0, {"frequency-1": "alarm"}))
    assert stage.flush() is False and stage.storage_errors == 2
    assert stage.flush() is True
    assert storage.written == written == [0.0, 10.0] and stage.storage_error is None
    assert stage.committed_alarms == {"frequency-1": "alarm"}


def test_a_bad_transaction_is_dropped_and_raised_not_retried_forever():
    class Broken(_Storage):
        def commit_window(self, commit, *, retry_s=None):
            raise ValueError("trend row of source 'x' in a commit of source 's'")

    stage = CommitStage(Broken(0), "s", {})
    stage.pending.append(_pending(0.0, {}))
    with pytest.raises(ValueError, match="trend row"):
        stage.flush()
    assert not stage.pending


def test_stage_settings_name_the_bad_value():
    with pytest.raises(ValidationError, match="calibration_s"):
        EstimateSettings(calibration_s=1.0)
    with pytest.raises(ValidationError, match="max_pending"):
        CommitSettings(max_pending=0)
    with pytest.raises(ValidationError, match="estimate_decimation"):
        ArchiveSettings(estimate_decimation=0)


def test_a_calibration_survives_its_stored_form():
    from estimator import RestCalibration

    fields = RestCalibration.__dataclass_fields__
    values = {}
    for name in fields:
        values[name] = np.arange(3.0) if name not in ("rest_end", "rested", "bearing_std") else None
    values.update(rest_end=60.0, rested=True, bearing_std=float("nan"))
    cal = RestCalibration(**values)  # every field set: a new field of RestCalibration fails here, not skips
    back = calibration_from_dict(calibration_to_dict(cal))
    assert back.rest_end == 60.0 and back.rested is True and np.isnan(back.bearing_std)
    assert all(np.array_equal(getattr(back, name), np.arange(3.0)) for name in fields
               if name not in ("rest_end", "rested", "bearing_std"))


# -- a structure behind its pace takes its queued batches as one ----------------------------------


def test_queued_batches_are_joined_per_topic_in_order():
    from shm_service.recording import FollowBlock
    from shm_service.service.stages._pipeline import Batch

    def block(topic: str, times: list[int]) -> FollowBlock:
        t = np.asarray(times, dtype=np.int64)
        return FollowBlock(topic, "strain", topic, t, t + 1, t[:, None] * 0.5)

    first = Batch([block("/a", [1, 2]), block("/b", [1])], raw=[("/a", 1, b"x", 2)], received=10.0, refused={"/a": 1})
    second = Batch([block("/a", [3]), block("/c", [2, 3])], raw=[("/a", 3, b"y", 4)], received=11.0, refused={"/a": 2})
    joined = Batch.joined([first, second])
    assert [b.topic for b in joined.blocks] == ["/a", "/b", "/c"]
    a = joined.blocks[0]
    assert a.log_time_ns.tolist() == [1, 2, 3] and a.publish_time_ns.tolist() == [2, 3, 4]
    assert a.values[:, 0].tolist() == [0.5, 1.0, 1.5]
    assert joined.raw == [("/a", 1, b"x", 2), ("/a", 3, b"y", 4)]
    assert joined.received == 10.0 and joined.refused == {"/a": 3} and joined.truth is None
    assert Batch.joined([first]) is first


# -- a source on the pool ----------------------------------------------------------------------


def test_a_source_lane_hands_batches_on_at_their_pace_and_waits_when_told_without_a_thread():
    import queue

    from shm_service.recording import FollowBlock
    from shm_service.service.stages._pipeline import Batch
    from shm_service.service.sources._sources import END, Source, SourceLane

    def batch(t_s: float) -> Batch:
        t = np.asarray([int(t_s * 1e9)], dtype=np.int64)
        return Batch([FollowBlock("/s", "strain", "s", t, t, np.zeros((1, 1)))])

    class Items(Source):
        def items(self):
            yield batch(100.0)
            yield 0.3  # a followed file at its end: look again in 0.3 s
            yield batch(100.5)  # due 0.25 s after the first at speed 2
            self.state = "finished"

    out: queue.Queue = queue.Queue(maxsize=1)
    src = Items("s", out)
    src.speed, src.state = 2.0, "running"
    lane = SourceLane(src)
    started = time.monotonic()
    assert lane.ready()
    lane.step()  # made and, due at once (the pace's origin), handed on
    assert out.get_nowait().blocks[0].log_time_ns[0] == int(100e9) and src.messages == 1
    lane.step()  # told to wait
    assert not lane.ready()
    wait_for(lane.ready, 5.0)
    assert time.monotonic() - started >= 0.3
    lane.step()  # made; due 0.25 s after the origin: already, handed on in the same step
    assert out.qsize() == 1 and src.messages == 2
    assert lane.ready()
    lane.step()  # the items ended: finished
    assert src.state == "finished" and not lane.ready()  # its END waits for room in the queue
    out.get_nowait()
    assert lane.ready()
    lane.step()
    assert out.get_nowait() is END and lane.finished
