"""Data sources of the service. A simulation, replay or followed file is a generator of
``Batch`` objects (``Source.items``: a float instead says "nothing now, look again in that many
seconds"), stepped on the service's scheduler by a ``SourceLane``: it makes the next batch, hands
it to the pipeline's bounded queue once due at its pace and with room (back-pressure: a replay
slows down to the pipeline's pace, a simulation too), and never waits on a pool thread. Without a
scheduler (``start()``) a thread of its own runs the same items. The HTTP ingest source has no
thread: requests put their batches directly, waiting a bounded time for room.
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from collections import Counter
from pathlib import Path
from collections.abc import Iterator
from typing import Any

import numpy as np

from contract import RigDescription, row_layout

from ...recording import FollowBlock, RecordingError, RecordingFollower, classify_topic, read_recording
from ._settings import SourceConfig
from ._ingest import IngestResult, IngestValidator
from ...recording._plausibility import SourceClock, ValueLimits
from ..stages._pipeline import Batch

__all__ = ["FileSource", "IngestSource", "SimSource", "Source", "SourceLane", "END", "data_lag_s", "newest_ns",
           "simulation_settings"]

log = logging.getLogger("shm.serve.source")

END = object()  # put into the queue when a source has ended
_NS = 1_000_000_000


def data_lag_s(data_time_ns: int | None, now_s: float, *, speed: float | None = 1.0,
               origin: tuple[float, int] | None = None) -> float | None:
    """How far a source's data are behind where its clock says they should be, s.

    A live source (``origin`` None: follow, ingest) runs on the wall clock: ``now_s`` (UNIX s)
    minus the newest data time. A paced source (sim, replay) has its own clock that started at
    ``origin`` = (wall s, data ns) of its first data and runs at ``speed`` × real time: the lag
    is ``speed`` × wall time since then minus data time since then (0 on schedule, > 0 when
    the pipeline holds it back); ``now_s`` is then on the clock of ``origin[0]``. A source at max
    speed (``speed`` None) has no schedule: None, as before any data.
    """
    if data_time_ns is None:
        return None
    if origin is None:
        return round(now_s - data_time_ns / _NS, 3)
    if speed is None:
        return None
    wall0, data0 = origin
    return round(speed * (now_s - wall0) - (data_time_ns - data0) / _NS, 3)


class Source:
    """Common state: counters and a stop flag. ``state``: starting, running, finished, failed."""

    kind = "source"

    def __init__(self, source_id: str, out: queue.Queue) -> None:
        self.id = source_id
        self.out = out
        self.state = "starting"
        self.error: str | None = None
        self.messages = 0
        self.rejected: Counter = Counter()
        self.dropped = 0
        self.problems: list[str] = []
        self.data_time_ns: int | None = None
        # paced sources (sim, replay): their pace (None: max) and (monotonic s, data ns) of the first data
        self.paced = False
        self.speed: float | None = None
        self._clock_origin: tuple[float, int] | None = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._rate: list[tuple[float, int]] = []
        self.rig: RigDescription | None = None

    # -- lifecycle ------------------------------------------------------------------------------

    def start(self) -> None:
        """Run on a thread of its own (without a scheduler: ``start_on``)."""
        self._thread = threading.Thread(target=self._main, name=f"source-{self.kind}", daemon=True)
        self._thread.start()

    def start_on(self, scheduler: Any) -> None:
        """Run on ``scheduler``'s pool (a ``SourceLane``) instead of a thread of its own."""
        self.state = "running"
        scheduler.add(SourceLane(self))

    def stop(self) -> None:
        self._stop.set()

    def join(self, timeout: float | None = None) -> None:
        if self._thread is not None:
            self._thread.join(timeout)

    def _main(self) -> None:
        try:
            self.state = "running"
            self.run()
            if self.state == "running":
                self.state = "finished"
        except Exception as exc:  # a source failing must not take the service down
            log.exception("source %s failed", self.id)
            self.state = "failed"
            self.error = f"{type(exc).__name__}: {exc}"
        finally:
            self._put(END)

    def items(self) -> Iterator[Batch | float]:
        """The source's batches in order, unpaced; a float: nothing now, look again in that many s.
        The generator sets ``state`` (finished, failed, stopped) when it ends otherwise than running."""
        raise NotImplementedError

    def run(self) -> None:
        """The items on this thread: each batch held to the pace, counted and put (blocking)."""
        pacer = _Pacer(self.speed, self._stop)
        for item in self.items():
            if self._stop.is_set():
                break
            if isinstance(item, float):
                self._stop.wait(item)
                continue
            newest = newest_ns(item, None)
            if newest is not None:
                pacer.wait(newest)
            self._count(item.blocks)
            if not self._put(item):
                break
        if self._stop.is_set() and self.state == "running":
            self.state = "stopped"

    def _put(self, item: Any) -> bool:
        """Blocking put that still notices ``stop()``."""
        while True:
            try:
                self.out.put(item, timeout=0.2)
                return True
            except queue.Full:
                if self._stop.is_set() and item is not END:
                    return False

    def _count(self, blocks: list[FollowBlock]) -> None:
        n = sum(len(b) for b in blocks)
        self.messages += n
        for b in blocks:
            if len(b):
                last = int(b.log_time_ns[-1])
                self.data_time_ns = last if self.data_time_ns is None else max(self.data_time_ns, last)
        now = time.monotonic()
        if self._clock_origin is None and self.data_time_ns is not None:
            self._clock_origin = (now, self.data_time_ns)
        self._rate.append((now, self.messages))
        while len(self._rate) > 2 and now - self._rate[0][0] > 10.0:
            self._rate.pop(0)

    @property
    def rate_hz(self) -> float:
        if len(self._rate) < 2:
            return 0.0
        (t0, n0), (t1, n1) = self._rate[0], self._rate[-1]
        if time.monotonic() - t1 > 5.0:
            return 0.0
        return (n1 - n0) / max(t1 - t0, 1e-9)

    def health_problems(self) -> list[str]:
        """Why the source's data cannot be trusted right now (empty: it can)."""
        return []

    def status(self) -> dict[str, Any]:
        if self.paced:
            lag = data_lag_s(self.data_time_ns, time.monotonic(), speed=self.speed, origin=self._clock_origin)
        else:
            lag = data_lag_s(self.data_time_ns, time.time())
        return {
            "id": self.id, "kind": self.kind, "state": self.state, "error": self.error, "messages": self.messages,
            "rate_hz": round(self.rate_hz, 1),
            "data_time_s": None if self.data_time_ns is None else self.data_time_ns / _NS,
            "lag_s": lag,
            "rejected": sum(self.rejected.values()), "rejected_by_reason": dict(self.rejected),
            "dropped": self.dropped, "problems": self.problems[-20:] + self.health_problems(),
        }


def newest_ns(batch: Batch, default: int | None) -> int | None:
    """The newest data time of ``batch`` (``default``: without samples), ns."""
    return max((int(b.log_time_ns[-1]) for b in batch.blocks if len(b)), default=default)


class _Pacer:
    """Holds data time to ``speed`` × wall time (None: as fast as the pipeline takes it)."""

    def __init__(self, speed: float | None, stop: threading.Event) -> None:
        self.speed = speed
        self.stop = stop
        self.origin: tuple[float, int] | None = None

    def wait(self, data_ns: int) -> None:
        if self.speed is None:
            return
        if self.origin is None:
            self.origin = (time.monotonic(), data_ns)
            return
        wall0, data0 = self.origin
        due = wall0 + (data_ns - data0) / _NS / self.speed
        delay = due - time.monotonic()
        if delay > 0:
            self.stop.wait(delay)

    def due_in(self, data_ns: int) -> float:
        """Seconds until ``data_ns`` is due (<= 0: now); the first call sets the origin."""
        if self.speed is None:
            return 0.0
        if self.origin is None:
            self.origin = (time.monotonic(), data_ns)
            return 0.0
        wall0, data0 = self.origin
        return wall0 + (data_ns - data0) / _NS / self.speed - time.monotonic()


def simulation_settings(settings: SourceConfig):
    """The virtual rig's settings for ``--source sim`` (``sim`` section of the service settings)."""
    from ...virtual_rig import SimulationSettings

    s = settings.sim
    common = {"duration": s.duration_s, "seed": s.seed, "excitation": s.excitation,
              "damage": tuple(s.damage) if s.damage_at_s is not None else (), "damage_at": s.damage_at_s,
              "temperature_mean": s.temperature_mean_c, "temperature_swing": s.temperature_swing_k,
              "wind_load_rms": s.wind_load_rms,
              "wind_storm": None if s.storm_start_s is None else
              {"start_s": s.storm_start_s, "end_s": s.storm_end_s, "peak": s.storm_peak}}
    rig = simulated_rig(settings)
    if rig is None:
        return SimulationSettings(layout=s.layout, support=s.support, orientation=s.orientation, length=s.length_m, **common)
    from ...virtual_rig import settings_for_rig

    # the rig file's own simulator settings, then the service's (support and orientation the rig's)
    given = {k for k, v in common.items() if v is not None}
    return settings_for_rig(rig, SimulationSettings(**common), given)


def simulated_rig(settings: SourceConfig):
    """The rig description ``sim.rig`` names (None: the built-in sheet)."""
    if settings.sim.rig is None:
        return None
    from estimator import load_rig

    return load_rig(settings.sim.rig)


class SimSource(Source):
    """The virtual rig, live."""

    kind = "sim"

    def __init__(self, source_id: str, out: queue.Queue, settings: SourceConfig, *, raw: bool, truth: bool,
                 rig: RigDescription | None = None) -> None:
        super().__init__(source_id, out)
        from ...virtual_rig import VirtualRig, settings_for_rig

        s = settings.sim
        self.settings = simulation_settings(settings)
        sim_rig = simulated_rig(settings)
        if sim_rig is None and rig is not None:
            # source.rig (`shm serve --source sim --rig FILE`): simulate that rig, its simulator settings
            # under the service's sim section
            given = {name for name in ("duration", "seed", "excitation", "damage", "damage_at", "temperature_mean",
                                       "temperature_swing") if name in self.settings.model_fields_set}
            self.settings = settings_for_rig(rig, self.settings, given)
            sim_rig = rig
        self.rigsim = VirtualRig(self.settings, sim_rig)
        self.rig = self.rigsim.nominal_rig
        self.block_s = s.block_s
        speed = settings.source.speed
        self.paced = True
        self.speed = None if speed == "max" else float(speed)
        self.raw = raw
        self.truth = truth
        self.metadata = {"truth": self.rigsim.truth_metadata()}
        from ._faults import parse_fault

        self.faults = tuple(parse_fault(spec) for spec in s.faults)
        self._fault_state: dict = {}

    def batches(self, block_s: float | None = None) -> Any:
        """The simulation as the pipeline's batches (with the configured faults), unpaced."""
        from ...virtual_rig._record import encode_payloads

        start_ns = self.settings.start_time_ns
        sensors = self.rig.sensor_by_topic()
        kinds: dict[str, tuple[str, str]] = {}  # topic -> (kind, name): the same for every block
        for block in self.rigsim.blocks(block_s or self.block_s):
            blocks, raw = [], [] if self.raw else None
            for topic, (times, values) in block.measurements.items():
                stamps = start_ns + np.round(times * _NS).astype(np.int64)
                delays = np.round(block.delays[topic] * _NS).astype(np.int64)
                if self.faults:
                    from ._faults import apply_faults

                    kept, stamps, values, dropped = apply_faults(self.faults, topic, times, stamps, values, self._fault_state)
                    delays = delays[kept]
                    self.rejected.update(dropped)
                if not len(stamps):
                    continue
                if topic not in kinds:
                    sensor = sensors.get(topic)
                    kinds[topic] = (classify_topic(topic).kind, sensor.name if sensor else topic)
                kind, name = kinds[topic]
                blocks.append(FollowBlock(topic, kind, name, stamps, stamps + delays, np.asarray(values, dtype=float)))
                if raw is not None:
                    raw.extend(zip([topic] * len(stamps), stamps.tolist(), encode_payloads(topic, values), (stamps + delays).tolist()))
            if raw is not None:
                raw.sort(key=lambda m: m[3])
            truth = None
            if self.truth:
                truth = (start_ns + np.round(block.times * _NS).astype(np.int64), block.truth["deflection"])
            yield Batch(blocks, raw, truth)

    def items(self) -> Iterator[Batch | float]:
        block_s = self.block_s if self.speed is not None else max(self.block_s, 10.0)  # bigger blocks at max speed
        yield from self.batches(block_s)
        if self.state == "running":
            self.state = "finished"


class SourceLane:
    """A source stepped by the scheduler instead of a thread of its own: each step takes its next
    item, or hands the batch on once it is due (paced) and the queue has room. Ready only then
    (and not while the source said to look again later), so a pool thread never waits for the
    pace, for room or for a file to grow."""

    def __init__(self, source: Source) -> None:
        self.source, self.name, self.finished = source, f"source-{source.id}", False
        self.pacer = _Pacer(source.speed, source._stop)
        self._items = iter(source.items())
        self._next: Batch | None = None
        self._newest: int | None = None  # of the batch held (None: no samples yet: due at once)
        self._idle_until = 0.0
        self._ending = False

    def ready(self) -> bool:
        src = self.source
        if self._ending or src._stop.is_set():
            return not src.out.full()
        if self._next is None:
            return time.monotonic() >= self._idle_until
        return not src.out.full() and self._due()

    def step(self) -> None:
        src = self.source
        if src._stop.is_set() and not self._ending:
            self._ending = True
            if src.state == "running":
                src.state = "stopped"
        if self._ending:
            self._end()
            return
        if self._next is None:
            self._take()  # and, when it is due already (the source is behind), handed on in this step
        if self._next is None or not self._due():
            return
        try:
            src.out.put_nowait(self._next)
        except queue.Full:
            return
        src._count(self._next.blocks)
        self._next = None

    def _due(self) -> bool:
        return self._newest is None or self.pacer.due_in(self._newest) <= 0

    def _take(self) -> None:
        src = self.source
        try:
            item = next(self._items, None)
        except Exception as exc:  # a source failing must not take the service down
            log.exception("source %s failed", src.id)
            src.state, src.error, self._ending = "failed", f"{type(exc).__name__}: {exc}", True
            return
        if item is None:
            self._ending = True
            if src.state == "running":
                src.state = "finished"
        elif isinstance(item, float):
            self._idle_until = time.monotonic() + item
        else:
            self._next, self._newest = item, newest_ns(item, self._newest)

    def _end(self) -> None:
        try:
            self.source.out.put_nowait(END)
        except queue.Full:
            return  # once the pipeline made room
        self.finished = True


class FileSource(Source):
    """``replay:FILE`` (read to the end, paced or at max speed) or ``follow:FILE`` (a file being
    written; new chunks are read as the writer flushes them)."""

    def __init__(self, source_id: str, out: queue.Queue, settings: SourceConfig, *, follow: bool,
                 rig: RigDescription | None, truth: bool) -> None:
        super().__init__(source_id, out)
        self.kind = "follow" if follow else "replay"
        self.path = Path(settings.source.path or "")
        self.follow = follow
        speed = settings.source.speed
        self.paced = not follow
        self.speed = None if (follow or speed == "max") else float(speed)
        self.poll_s = settings.source.follow_poll_s
        self.idle_s = settings.source.follow_idle_s
        self.truth = truth
        topics = {s.topic for s in rig.sensors} if rig is not None else None
        self._rig_override = rig
        self._topics = topics
        self.rotations = settings.source.follow_rotations
        self.follower: RecordingFollower | None = None
        self._counted_rejects: dict[str, int] = {}
        self._early: list[FollowBlock] = []
        if not follow and not self.path.is_file():
            raise FileNotFoundError(f"replay: {self.path} does not exist")
        # follow: a missing file is waited for (the follower notes it once, with a count)
        self._open()

    def _kinds(self) -> tuple[str, ...]:
        """What the pipeline uses: the sensors, and the truth only when it is shown."""
        return ("imu", "tof", "strain", "bearing", "temperature", *(("truth",) if self.truth else ()))

    def _open(self) -> None:
        self.follower = RecordingFollower(self.path, rig=self._rig_override, kinds=self._kinds(),
                                          reopen_finished=self.follow and self.rotations)
        self._early = self.follower.poll(max_bytes=1 << 16)  # rig.json comes with the first records
        self.rig = self.follower.rig
        if self.rig is None and not self.follow:
            raise RecordingError(f"{self.path}: rig.json is missing: no 'rig.json' attachment at the start of the file")

    def wait_for_rig(self, timeout: float) -> RigDescription | None:
        """Follow: look (until ``timeout``, s; 0: once) for the file and its rig.json."""
        deadline = time.monotonic() + timeout
        while True:
            if self.follower is None:
                self._open()
            elif self.rig is None:
                self._early.extend(self.follower.poll(max_bytes=1 << 16))
                self.rig = self.follower.rig
            if self.rig is not None:
                return self.rig
            if time.monotonic() >= deadline or self._stop.wait(self.poll_s):
                return None

    def health_problems(self) -> list[str]:
        f = self.follower
        if self.follow and f is not None and f.missing:
            return [f"follow: {self.path} does not exist (not yet written, or deleted); waiting for it"]
        return []

    def _update_rejects(self) -> None:
        f = self.follower
        for topic, r in f.topic_reports.items():
            for reason in ("malformed", "nonfinite", "duplicate", "backwards"):
                key = f"{topic}:{reason}"
                value = getattr(r, reason)
                before = self._counted_rejects.get(key, 0)
                if value > before:
                    self.rejected[reason] += value - before
                    self._counted_rejects[key] = value
        self.problems = list(f.report.problems)

    def _batch(self, blocks: list[FollowBlock]) -> Batch | None:
        """The data blocks of ``blocks`` (and the truth, when shown) as a batch (None: no data)."""
        blocks = [b for b in blocks if len(b)]
        truth_block = None
        data_blocks = []
        for b in blocks:
            if b.kind == "truth":
                truth_block = b
            elif b.kind != "estimate":
                data_blocks.append(b)
        if not data_blocks:
            return None
        truth = None
        if truth_block is not None and self.truth and self.rig is not None:
            layout = row_layout("shm.TruthState", stations=len(self.rig.truth_stations), biaxial=self.rig.beam.biaxial)
            if truth_block.values.shape[1] == layout.width:
                truth = (truth_block.log_time_ns, truth_block.values[:, layout.columns("deflection")])
        return Batch(data_blocks, None, truth)

    def _polled(self, blocks: list[FollowBlock]) -> Iterator[Batch]:
        """What the follower read: its rejects counted, its data as a batch."""
        self._update_rejects()
        batch = self._batch(blocks)
        if batch is not None:
            yield batch

    def _interleaved(self) -> bool:
        """True when the finished file's chunks come in time order (as a logger writes them).

        The contract does not promise that: another tool may write one channel after the other.
        Such a file (or one without a summary, cut off mid-write) is replayed from one bulk read,
        merged by log_time, instead of streamed; streaming it would find every channel but the
        first one late.
        """
        from mcap.reader import make_reader

        try:
            with open(self.path, "rb") as f:
                summary = make_reader(f).get_summary()
        except Exception:  # noqa: BLE001 - no readable summary (cut off, damaged): read in bulk
            return False
        if summary is None or not summary.chunk_indexes:
            return False
        newest = -1
        for index in sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset):
            if index.message_start_time < newest - _NS:  # more than a second back in time
                return False
            newest = max(newest, index.message_end_time)
        return True

    def _replay_in_bulk(self) -> Iterator[Batch]:
        """Replay a whole recording read at once, in 10 s slices of data time across all channels."""
        rec = read_recording(self.path, rig=self._rig_override, kinds=self._kinds())
        self.problems = list(rec.report.problems)
        for report in rec.report.topics.values():
            for reason in ("malformed", "nonfinite", "duplicate", "backwards"):
                self.rejected[reason] += getattr(report, reason)
        channels = [c for c in rec.channels.values() if c.kind != "estimate" and len(c)]
        step = 10 * _NS
        start = rec.start_ns
        while start <= rec.end_ns and not self._stop.is_set():
            blocks = []
            for c in channels:
                lo, hi = np.searchsorted(c.log_time_ns, [start, start + step])
                if hi > lo:
                    blocks.append(FollowBlock(c.topic, c.kind, c.name, c.log_time_ns[lo:hi], c.publish_time_ns[lo:hi], c.values[lo:hi]))
            batch = self._batch(blocks)
            if batch is not None:
                yield batch
            start += step

    def items(self) -> Iterator[Batch | float]:
        if not self.follow and not self._interleaved():
            self.state = "running"
            yield from self._replay_in_bulk()
            self.state = "stopped" if self._stop.is_set() else "finished"
            return
        f = self.follower
        assert f is not None
        self.state = "running"
        yield from self._polled(self._early)
        idle_since = time.monotonic()
        replaced = f.replaced
        while not self._stop.is_set():
            before = f.bytes_read
            blocks = f.poll(max_bytes=2 << 20)
            self.state = "waiting for the file" if f.missing else "running"
            self.problems = list(f.report.problems)  # a missing file's entry counts on without data
            if blocks:
                yield from self._polled(blocks)
            if f.replaced != replaced:  # a new file under the name: reading it is progress
                replaced, before = f.replaced, -1
            if f.finished and not (self.follow and self.rotations):
                break
            if f.damaged:
                self.state = "failed"
                self.error = f.report.problems[-1] if f.report.problems else "file damaged"
                break
            if f.bytes_read == before or f.finished:  # at the end of what exists now
                if not self.follow or (self.idle_s is not None and time.monotonic() - idle_since > self.idle_s):
                    yield from self._polled(f.finish())
                    break
                yield float(self.poll_s)
            else:
                idle_since = time.monotonic()
        self._update_rejects()
        if self._stop.is_set():
            self.state = "stopped"
        elif self.state in ("running", "waiting for the file"):
            self.state = "finished"


class IngestSource(Source):
    """``POST /api/ingest``: validated messages go straight into the queue."""

    kind = "ingest"

    def __init__(self, source_id: str, out: queue.Queue, rig: RigDescription, *, max_messages: int, wait_s: float,
                 raw: bool, clock: SourceClock | None = None, limits: ValueLimits | None = None) -> None:
        super().__init__(source_id, out)
        self.rig = rig
        self.validator = IngestValidator(rig, max_messages=max_messages, clock=clock, limits=limits)
        self.wait_s = wait_s
        self.raw = raw
        self._lock = threading.Lock()
        self.requests = 0
        self.refused = 0

    def start(self) -> None:
        self.state = "running"

    def stop(self) -> None:
        with self._lock:  # a request putting its batch now completes first; later ones are refused
            super().stop()
        if self.state == "running":
            self.state = "finished"
            try:
                self.out.put(END, timeout=1.0)
            except queue.Full:
                pass

    def submit(self, document: Any) -> IngestResult | None:
        """Validate and enqueue; returns the result, or None when the pipeline had no room
        within ``wait_s`` (nothing of the request was taken: the client retries)."""
        with self._lock:  # one request at a time keeps each topic's time order
            if self._stop.is_set():  # stopping: nothing more is taken (the client retries with the next service)
                self.refused += 1
                return None
            self.requests += 1
            result = self.validator.validate(document)
            batch = Batch(result.blocks, result.raw if self.raw else None, refused=dict(result.refused_by_topic))
            try:
                if result.blocks or result.refused_by_topic:
                    self.out.put(batch, timeout=self.wait_s)
            except queue.Full:
                self.refused += 1
                return None
            # Only now, with the batch handed on, do the topics' last times move (a refused
            # request's retry is not a duplicate).
            self.validator.commit(result)
            self._count(result.blocks)
            self.rejected.update(result.rejected)
            return result

    def health_problems(self) -> list[str]:
        return self.validator.clock.problems()

    def status(self) -> dict[str, Any]:
        return {**super().status(), "clock_jumps": self.validator.clock.jump_count}
