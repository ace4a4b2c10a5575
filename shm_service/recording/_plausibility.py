"""What a source may plausibly deliver: time stamps near the source's clock, values a sensor can
physically read. Pure logic, used by the ingest validator (per message, so the response says
what was refused) and by the pipeline for the other sources (per block).

Time. A source's clock is the newest stamp of each of its topics; for a live source (ingest) it
runs on with the wall clock while the source is silent. A stamp is rejected when

- ``implausible_time``: it lies more than ``window_s`` before the source's newest stamp or more
  than ``window_s`` after the source's current time; for a live source also when it lies beyond
  the wall clock plus ``future_tolerance_s``;
- ``ahead_of_source``: its topic's stamps jump forward (by more than ``max_ahead_s`` after the
  topic's previous sample) to beyond every other topic of the source (by more than
  ``max_ahead_s``): one sensor's clock jumped. Taking it would make every other sensor's
  samples late, and its own later samples "backwards". A topic merely delivered ahead of the
  others (a file's chunk, a client's batch) runs on without a jump and is taken.

A stamp of a live source within ``future_tolerance_s`` of the wall clock is never ``ahead`` (the
wall clock is the better reference: a device whose clock was just corrected is on time) — while
the source's clock is itself near the wall clock (within ``window_s``). In a backfill (the source
delivers data of 1970, or of last year), a stamp of the present is far from its stream's time: it
is a clock jump of its sensor, rejected like any other, and never its channel's new reference
(else every later sample of that channel would be "backwards"). When
most topics of a batch jump together (a recording resumed after a pause, a source's clock
stepped), the batch is taken and the jump reported: the source's clock moved, not one sensor's.
Rejected stamps never move the clock, so the valid data that follow are processed.

Values. ``ValueLimits`` bound what each sensor kind can read (an accelerometer beyond 2000 m/s²
is broken, not measuring); such a sample is rejected as ``implausible_value``.
"""

from __future__ import annotations

import math
import time
from collections import Counter, deque
from dataclasses import dataclass

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator

__all__ = ["ClockJump", "SourceClock", "StampJudge", "ValueLimits", "all_plausible", "implausible_row", "implausible_values"]

_NS = 1_000_000_000


class ValueLimits(BaseModel):
    """Physical limits of the sensor readings; a sample beyond them is rejected (``implausible_value``)."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    accel_m_s2: float = Field(2000.0, gt=0, description="largest |acceleration| of any axis, m/s² (≈ 200 g)")
    gyro_rad_s: float = Field(200.0, gt=0, description="largest |rotation rate| of any axis, rad/s")
    distance_min_m: float = Field(0.0, description="shortest ToF distance, m")
    distance_max_m: float = Field(100.0, gt=0, description="longest ToF distance, m")
    strain: float = Field(0.05, gt=0, description="largest |strain|, m/m (steel yields far below)")
    bearing_m: float = Field(100.0, gt=0, description="largest |bearing displacement|, m")
    temperature_min_c: float = Field(-100.0, description="lowest temperature, °C")
    temperature_max_c: float = Field(200.0, description="highest temperature, °C")

    @model_validator(mode="after")
    def _ranges(self) -> "ValueLimits":
        if not self.distance_min_m < self.distance_max_m:
            raise ValueError(f"distance_min_m={self.distance_min_m} must be below distance_max_m={self.distance_max_m}")
        if not self.temperature_min_c < self.temperature_max_c:
            raise ValueError(f"temperature_min_c={self.temperature_min_c} must be below "
                             f"temperature_max_c={self.temperature_max_c}")
        return self


def implausible_values(kind: str, values: np.ndarray, limits: ValueLimits) -> np.ndarray:
    """Which samples of a sensor of ``kind`` read beyond ``limits``.

    Parameters
    ----------
    kind : {"imu", "tof", "strain", "bearing", "temperature"}
        The sensor kind (``contract.classify_topic``).
    values : (n, k) array
        Rows in the payload layout of the kind (imu: accel x, y, z in m/s², gyro x, y, z in rad/s;
        the others: one value, in m, m/m, m or °C).
    limits : ValueLimits

    Returns
    -------
    (n,) bool array
        True where the sample is implausible (NaN counts as implausible too).

    Raises
    ------
    ValueError
        For an unknown kind or values of the wrong width.
    """
    v = np.asarray(values, dtype=float)
    if v.ndim == 1:
        v = v[:, None]
    width = 6 if kind == "imu" else 1
    if v.ndim != 2 or v.shape[1] != width:
        raise ValueError(f"values of kind {kind!r} must have shape (n, {width}), got {v.shape}")
    with np.errstate(invalid="ignore"):
        if kind == "imu":
            ok = np.all(np.abs(v[:, :3]) <= limits.accel_m_s2, axis=1) & np.all(np.abs(v[:, 3:]) <= limits.gyro_rad_s, axis=1)
        elif kind == "tof":
            ok = (v[:, 0] >= limits.distance_min_m) & (v[:, 0] <= limits.distance_max_m)
        elif kind == "strain":
            ok = np.abs(v[:, 0]) <= limits.strain
        elif kind == "bearing":
            ok = np.abs(v[:, 0]) <= limits.bearing_m
        elif kind == "temperature":
            ok = (v[:, 0] >= limits.temperature_min_c) & (v[:, 0] <= limits.temperature_max_c)
        else:
            raise ValueError(f"{kind=} is not a sensor kind (imu, tof, strain, bearing, temperature)")
    return ~ok


def all_plausible(kind: str, values: np.ndarray, limits: ValueLimits) -> bool:
    """True when no sample of ``values`` is implausible or non-finite (``implausible_values`` all
    False), from the extremes of the block: the usual block is decided without per-sample masks.
    False only means that ``implausible_values`` has to look (NaN, infinity or a value beyond
    the limits is there); it also answers False for a kind it does not know."""
    v = np.asarray(values, dtype=float)
    if not v.size:
        return True
    if v.ndim == 1:
        v = v[:, None]
    with np.errstate(invalid="ignore"):
        if kind == "imu" and v.ndim == 2 and v.shape[1] == 6:
            a = np.abs(v)
            return bool(a[:, :3].max() <= limits.accel_m_s2 and a[:, 3:].max() <= limits.gyro_rad_s)
        bounds = {"tof": (limits.distance_min_m, limits.distance_max_m), "strain": (-limits.strain, limits.strain),
                  "bearing": (-limits.bearing_m, limits.bearing_m),
                  "temperature": (limits.temperature_min_c, limits.temperature_max_c)}.get(kind)
        if bounds is None or v.ndim != 2 or v.shape[1] != 1:
            return False
        # NaN fails both comparisons, so a NaN anywhere answers False
        return bool(v.min() >= bounds[0] and v.max() <= bounds[1])


def implausible_row(kind: str, row: list[float], limits: ValueLimits) -> bool:
    """``implausible_values`` of one sample (a list in the payload layout), without numpy."""
    if kind == "imu":
        a, g = limits.accel_m_s2, limits.gyro_rad_s
        return not (all(-a <= x <= a for x in row[:3]) and all(-g <= x <= g for x in row[3:]))
    x = row[0]
    if kind == "tof":
        return not limits.distance_min_m <= x <= limits.distance_max_m
    if kind == "strain":
        return not -limits.strain <= x <= limits.strain
    if kind == "bearing":
        return not -limits.bearing_m <= x <= limits.bearing_m
    if kind == "temperature":
        return not limits.temperature_min_c <= x <= limits.temperature_max_c
    raise ValueError(f"{kind=} is not a sensor kind (imu, tof, strain, bearing, temperature)")


@dataclass(frozen=True)
class ClockJump:
    """A stamp (or a batch) off the source's clock: of one topic (``topic``) or of the whole
    source (``topic`` None, taken). ``offset_s`` is the stamp's distance from the reference,
    ``samples`` how many were concerned, ``at`` the wall-clock time it was seen (UNIX s), ``at_ns`` the
    source's clock then."""

    topic: str | None
    reason: str
    offset_s: float
    samples: int
    at: float
    at_ns: int | None = None  # the source's clock then (data time)

    def describe(self) -> str:
        what = "the source's clock jumped" if self.topic is None else f"{self.topic}: stamps"
        taken = "taken as the source's new time" if self.topic is None else f"{self.samples} sample(s) rejected ({self.reason})"
        return f"clock jump: {what} {self.offset_s:+.3g} s off the source's clock; {taken}"


class SourceClock:
    """The clock of one source and the time judgement of its samples (see the module).

    ``live``: the clock runs on with the wall clock while the source is silent and stamps are
    bounded by the wall clock plus ``future_tolerance_s`` (ingest); otherwise only the data's own
    clock counts (sim, replay, follow). Not thread-safe: one caller at a time.
    """

    def __init__(self, *, window_s: float, max_ahead_s: float, live: bool, future_tolerance_s: float = 60.0,
                 keep_jumps: int = 20) -> None:
        for name, value in (("window_s", window_s), ("max_ahead_s", max_ahead_s), ("future_tolerance_s", future_tolerance_s)):
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name}={value} must be a positive number of seconds")
        self.window_ns = int(window_s * _NS)
        self.ahead_ns = int(max_ahead_s * _NS)
        self.tolerance_ns = int(future_tolerance_s * _NS)
        self.live = live
        self.last: dict[str, int] = {}  # newest taken stamp per topic
        self.seen: dict[str, float] = {}  # wall time (monotonic s) of that
        self.rejected: Counter = Counter()  # reason -> samples
        self.jumps: deque[ClockJump] = deque(maxlen=keep_jumps)
        self.jump_count = 0
        self.last_jump_at: float | None = None

    # -- the clock ------------------------------------------------------------------------------

    def _now(self, topic: str, mono: float) -> int:
        """Stamp of ``topic``'s clock now (a live source's clock runs on while it is silent)."""
        t = self.last[topic]
        if self.live:
            t += int(max(mono - self.seen[topic], 0.0) * _NS)
        return t

    def newest(self) -> int | None:
        return max(self.last.values()) if self.last else None

    def reference(self, topic: str, mono: float | None = None) -> int | None:
        """The newest time of the source's OTHER topics now (None while there is none)."""
        if not self.live:  # the stamps themselves (called per topic and batch: no call per topic)
            return max((v for t, v in self.last.items() if t != topic), default=None)
        mono = time.monotonic() if mono is None else mono
        others = [self._now(t, mono) for t in self.last if t != topic]
        return max(others) if others else None

    def current(self, mono: float | None = None) -> int | None:
        if not self.live:
            return max(self.last.values()) if self.last else None
        mono = time.monotonic() if mono is None else mono
        return max(self._now(t, mono) for t in self.last) if self.last else None

    def _span(self, mono: float) -> tuple[int, int]:
        """(newest, current) of a source that has a stamp (``last`` not empty)."""
        newest, current = self.newest(), self.current(mono)
        if newest is None or current is None:
            raise RuntimeError("the source's clock has no stamp yet")
        return newest, current

    # -- judgement ------------------------------------------------------------------------------

    def source_jump(self, firsts: dict[str, int], mono: float | None = None) -> bool:
        """Whether the batch whose topics start at ``firsts`` moves the whole source: most of the
        source's topics (at least two) run ahead of the others together."""
        mono = time.monotonic() if mono is None else mono
        known = set(self.last) | set(firsts)
        if len(known) < 2 or not self.last:
            return False
        newest, current = self._span(mono)
        off = [t for t, first in firsts.items() if first > current + self.ahead_ns or first < newest - self.window_ns]
        return len(off) >= 2 and 2 * len(off) >= len(known)

    def judge(self, topic: str, stamps: np.ndarray, *, wall_ns: int | None = None, mono: float | None = None,
              whole_source: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """Which of ``stamps`` (one topic, increasing) to take. Returns (accepted bool mask,
        reason codes: 0 taken, 1 implausible_time, 2 ahead_of_source). Does not move the clock
        (``take`` does, once the samples are handed on). ``whole_source``: the batch moves the
        whole source (``source_jump``): only the wall-clock bound applies."""
        t = np.asarray(stamps, dtype=np.int64)
        mono = time.monotonic() if mono is None else mono
        if self._all_taken(topic, t, wall_ns, mono, whole_source):
            return np.ones(len(t), dtype=bool), np.zeros(len(t), dtype=np.int8)
        code = np.zeros(len(t), dtype=np.int8)
        if self.live:
            wall = time.time_ns() if wall_ns is None else wall_ns
            code[t > wall + self.tolerance_ns] = 1
            live = (np.abs(t - wall) <= self.tolerance_ns) & self._near_wall(wall, mono)
        else:
            live = np.zeros(len(t), dtype=bool)
        if self.last and not whole_source:
            newest, current = self._span(mono)
            off = ((t < newest - self.window_ns) | (t > current + self.window_ns)) & ~live
            code[(code == 0) & off] = 1
            ref = self.reference(topic, mono)
            own = self.last.get(topic)
            if ref is not None and own is not None:
                suspect = (code == 0) & (t > ref + self.ahead_ns) & ~live
                if suspect.any():
                    # ahead of the others: a jump only if the topic's own stamps stepped there
                    code[self._jumped(t, suspect, own)] = 2
        return code == 0, code

    def _near_wall(self, wall_ns: int, mono: float) -> bool:
        """Whether the source's clock runs near the wall clock (within ``window_s``), so that a stamp
        near the wall clock is on time whatever its topic's past (not so in a backfill)."""
        current = self.current(mono)
        return current is None or abs(current - wall_ns) <= self.window_ns

    def _all_taken(self, topic: str, t: np.ndarray, wall_ns: int | None, mono: float, whole_source: bool) -> bool:
        """Whether every stamp of ``t`` passes ``judge``, decided from its first and last (the
        usual block: on the clock, nothing ahead) without the per-stamp masks."""
        if not len(t):
            return True
        lo, hi = int(t.min()), int(t.max())
        if self.live and hi > (time.time_ns() if wall_ns is None else wall_ns) + self.tolerance_ns:
            return False
        if not self.last or whole_source:
            return True
        newest, current = self._span(mono)
        if lo < newest - self.window_ns or hi > current + self.window_ns:
            return False
        ref = self.reference(topic, mono)
        return ref is None or topic not in self.last or hi <= ref + self.ahead_ns

    def _jumped(self, t: np.ndarray, suspect: np.ndarray, own: int) -> np.ndarray:
        """Which suspect stamps lie more than ``max_ahead_s`` after the topic's latest taken one."""
        steps = np.diff(np.concatenate([[own], t]))
        if not np.any(steps > self.ahead_ns):  # a continuous run: delivered early, not jumped
            return np.zeros(len(t), dtype=bool)
        out = np.zeros(len(t), dtype=bool)
        latest = own
        for i in range(len(t)):
            if suspect[i] and t[i] - latest > self.ahead_ns:
                out[i] = True
            else:
                latest = max(latest, int(t[i]))
        return out

    def judge_one(self, topic: str, stamp: int, *, wall_ns: int, mono: float, whole_source: bool = False) -> int:
        """``judge`` of one stamp (the ingest validator's per-message path): 0 taken, 1
        implausible_time, 2 ahead_of_source."""
        if self.live and stamp > wall_ns + self.tolerance_ns:
            return 1
        if not self.last or whole_source:
            return 0
        nows = {other: last + int(max(mono - self.seen[other], 0.0) * _NS) if self.live else last
                for other, last in self.last.items()}
        newest, current = max(self.last.values()), max(nows.values())
        ref = max((now for other, now in nows.items() if other != topic), default=None)
        if self.live and abs(stamp - wall_ns) <= self.tolerance_ns and abs(current - wall_ns) <= self.window_ns:
            return 0  # the source runs on the wall clock: a stamp near it is on time
        if stamp < newest - self.window_ns or stamp > current + self.window_ns:
            return 1
        own = self.last.get(topic)
        if ref is not None and own is not None and stamp > ref + self.ahead_ns and stamp - own > self.ahead_ns:
            return 2
        return 0

    def judge_stamps(self, *, wall_ns: int, mono: float, whole_source: bool = False) -> "StampJudge":
        """A judge of single stamps at one instant (``judge_one`` in O(1) per stamp: the
        validator's per-message path); its ``take`` moves this clock too."""
        return StampJudge(self, wall_ns=wall_ns, mono=mono, whole_source=whole_source)

    def copy(self) -> "SourceClock":
        """An independent copy (judge a request on it; keep it once the request is taken)."""
        other = object.__new__(SourceClock)
        other.__dict__.update(self.__dict__)
        other.last, other.seen, other.rejected = dict(self.last), dict(self.seen), Counter(self.rejected)
        other.jumps = deque(self.jumps, maxlen=self.jumps.maxlen)
        return other

    def record(self, topic: str | None, reason: str, samples: int, offset_s: float) -> None:
        """Count ``samples`` rejected for ``reason`` (or a source-wide jump: reason "source_jump") and note the jump."""
        if reason != "source_jump":
            self.rejected[reason] += samples
        self.note(ClockJump(topic, reason, offset_s, samples, time.time(), self.current()))

    def take(self, topic: str, stamp: int, mono: float | None = None) -> None:
        """``stamp`` is the newest taken sample of ``topic``."""
        if stamp > self.last.get(topic, -(2**62)):
            self.last[topic] = int(stamp)
            self.seen[topic] = time.monotonic() if mono is None else mono

    def offset_s(self, topic: str | None, stamp: int, mono: float | None = None) -> float:
        """How far ``stamp`` lies from the source's clock (from the other topics' for a topic), s."""
        ref = None if topic is None else self.reference(topic, mono)
        ref = self.current(mono) if ref is None else ref
        return float("nan") if ref is None else (int(stamp) - ref) / _NS

    def count(self, topic: str, codes: np.ndarray, stamps: np.ndarray, *, mono: float | None = None) -> dict[str, int]:
        """Record the rejections of ``judge`` (reason -> samples) and note the jump."""
        out: dict[str, int] = {}
        for code, reason in ((1, "implausible_time"), (2, "ahead_of_source")):
            bad = codes == code
            n = int(np.count_nonzero(bad))
            if n:
                out[reason] = n
                self.record(topic, reason, n, self.offset_s(topic, int(np.asarray(stamps)[bad][0]), mono))
        return out

    def note(self, jump: ClockJump) -> None:
        self.jumps.append(jump)
        self.jump_count += 1
        self.last_jump_at = jump.at

    def problems(self, recent_s: float = 30.0) -> list[str]:
        """The clock jumps of the source's last ``recent_s`` (its own clock; the wall clock before it
        has one): while there are any, the source is degraded."""
        if self.last_jump_at is None:
            return []
        now_ns = self.current()
        recent_ns = int(recent_s * _NS)

        def fresh(j: ClockJump) -> bool:
            if j.at_ns is not None and now_ns is not None:
                return now_ns - j.at_ns <= recent_ns
            return time.time() - j.at <= recent_s

        recent = [j for j in self.jumps if fresh(j)]
        if not recent:
            return []
        return [j.describe() for j in recent[-3:]] + ([f"({self.jump_count} clock jumps since the start)"]
                                                      if self.jump_count > 3 else [])


class StampJudge:
    """``SourceClock.judge_one`` at one instant, kept up to date as stamps are taken."""

    def __init__(self, clock: SourceClock, *, wall_ns: int, mono: float, whole_source: bool) -> None:
        self.clock, self.wall_ns, self.mono, self.whole = clock, wall_ns, mono, whole_source
        live = clock.live
        self.now = {t: last + (int(max(mono - clock.seen[t], 0.0) * _NS) if live else 0) for t, last in clock.last.items()}
        self.newest = max(clock.last.values()) if clock.last else None
        self._rank()
        # the source runs near the wall clock (not a backfill): a stamp near the wall clock is on time
        self.near_wall = self.first is None or abs(self.first[1] - wall_ns) <= clock.window_ns

    def _rank(self) -> None:
        best = sorted(self.now.items(), key=lambda kv: kv[1], reverse=True)[:2]
        self.first = best[0] if best else None
        self.second = best[1] if len(best) > 1 else None

    def judge(self, topic: str, stamp: int) -> int:
        """0 taken, 1 implausible_time, 2 ahead_of_source (as ``SourceClock.judge``)."""
        c = self.clock
        if c.live:
            if stamp > self.wall_ns + c.tolerance_ns:
                return 1
            if self.near_wall and abs(stamp - self.wall_ns) <= c.tolerance_ns:
                return 0
        if self.first is None or self.newest is None or self.whole:  # (a first topic: a newest stamp)
            return 0
        if stamp < self.newest - c.window_ns or stamp > self.first[1] + c.window_ns:
            return 1
        ref = self.second if self.first[0] == topic else self.first
        own = c.last.get(topic)
        if ref is not None and own is not None and stamp > ref[1] + c.ahead_ns and stamp - own > c.ahead_ns:
            return 2
        return 0

    def take(self, topic: str, stamp: int) -> None:
        c = self.clock
        if stamp <= c.last.get(topic, -(2**62)):
            return
        c.take(topic, stamp, self.mono)
        self.now[topic] = stamp
        self.newest = stamp if self.newest is None else max(self.newest, stamp)
        if self.first is not None and self.first[0] == topic:
            self.first = (topic, stamp)
        elif self.first is None or stamp > self.first[1]:
            self.second, self.first = self.first, (topic, stamp)
        elif self.second is None or self.second[0] == topic or stamp > self.second[1]:
            self.second = (topic, stamp)
