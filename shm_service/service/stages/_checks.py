"""The stage after the sources: plausibility and stuck sensors.

Samples off the source's clock, beyond the sensors' limits, non-finite, duplicated or going
backwards are refused and counted by reason; a sensor whose samples are being refused is degraded
for ``silent_after_s``; an IMU's or strain gauge's reading that stays exactly the same for
``stuck_after_s`` marks it stuck (their noise never lets a working one repeat a value for long).
"""

from __future__ import annotations

import time
from collections import Counter

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from ...recording import FollowBlock
from ...recording._plausibility import SourceClock, ValueLimits, all_plausible, implausible_values

__all__ = ["CheckSettings", "SampleChecks"]

_NS = 1_000_000_000


class CheckSettings(BaseModel):
    """When a sensor counts as stuck or degraded."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    silent_after_s: float = Field(2.0, gt=0, description="a sensor without data this long is reported degraded, s")
    stuck_after_s: float = Field(
        1.0, gt=0, description="a sensor whose readings stay exactly the same this long is reported degraded (stuck), s")


class SampleChecks:
    """Plausibility and stuck sensors of one source.

    Parameters
    ----------
    settings : CheckSettings
    clock : SourceClock, optional
        The source's clock (None: the stamps are not judged).
    limits : ValueLimits, optional
        The sensors' physical limits (None, with ``clock`` None: the source judged its samples
        itself, as ingest does, and they pass unchanged).
    """

    def __init__(self, settings: CheckSettings | None = None, clock: SourceClock | None = None,
                 limits: ValueLimits | None = None) -> None:
        self.settings = settings or CheckSettings()
        self.clock = clock
        self.limits = limits
        self.rejected: Counter[str] = Counter()  # samples rejected here, by reason
        self.stuck_after_ns = int(round(self.settings.stuck_after_s * _NS))
        self.silent_after_ns = int(round(self.settings.silent_after_s * _NS))
        self._stuck: dict[str, tuple[np.ndarray, int, int]] = {}  # topic -> (last row, run start ns, last ns)
        self.refused_at: dict[str, int] = {}  # topic -> data time when a sample of it was last refused
        self._order: dict[str, int] = {}  # topic -> newest stamp handed on

    def note_refused(self, topics: list[str] | tuple[str, ...], newest_ns: int | None) -> None:
        """Topics the source refused samples of (its own checks) at data time ``newest_ns``."""
        for topic in topics:
            self.refused_at[topic] = newest_ns if newest_ns is not None else 0

    def degraded(self, newest_ns: int | None) -> set[str]:
        """Topics stuck, or refused within ``silent_after_s`` before ``newest_ns``."""
        out = set(self.stuck_sensors())
        if newest_ns is not None:
            out.update(t for t, at in self.refused_at.items() if newest_ns - at <= self.silent_after_ns)
        return out

    def judge(self, blocks: list[FollowBlock], newest_ns: int | None = None) -> list[FollowBlock]:
        """The samples of ``blocks`` on the source's clock, within the sensors' limits and in time
        order per topic; the others are counted (``rejected``, by reason) and their clock jumps
        noted (``SourceClock``). ``newest_ns``: the newest data time handed on so far (when a
        refused sample marks its sensor degraded)."""
        if self.clock is None and self.limits is None:  # judged by the source (ingest)
            return blocks
        blocks = [b for b in blocks if len(b)]
        clock = self.clock
        mono = time.monotonic()
        whole = False
        if clock is not None and blocks:
            firsts = {b.topic: int(b.log_time_ns[0]) for b in blocks}
            whole = clock.source_jump(firsts, mono)
            # The first batch has no clock yet: the topics that agree with most others are taken
            # first, so one sensor stamped years off cannot become the source's time.
            median = float(np.median(list(firsts.values())))
            blocks = sorted(blocks, key=lambda b: abs(firsts[b.topic] - median))
        out = []
        for b in blocks:
            keep = None
            if clock is not None:
                ok, codes = clock.judge(b.topic, b.log_time_ns, mono=mono, whole_source=whole)
                if not ok.all():
                    self.rejected.update(clock.count(b.topic, codes, b.log_time_ns, mono=mono))
                    keep = ok
            if self.limits is not None and b.kind in ("imu", "tof", "strain", "bearing", "temperature") \
                    and not all_plausible(b.kind, b.values, self.limits):
                taken = np.ones(len(b), dtype=bool) if keep is None else keep
                nonfinite = ~np.all(np.isfinite(b.values.reshape(len(b), -1)), axis=1)
                bad = implausible_values(b.kind, b.values, self.limits) & ~nonfinite
                if nonfinite.any() or bad.any():
                    self.rejected["nonfinite"] += int(np.count_nonzero(nonfinite & taken))
                    self.rejected["implausible_value"] += int(np.count_nonzero(bad & taken))
                    keep = taken & ~bad & ~nonfinite
            if keep is not None:
                b = FollowBlock(b.topic, b.kind, b.name, b.log_time_ns[keep], b.publish_time_ns[keep], b.values[keep])
            # Each topic in time order whatever the source did (a sensor's clock stepping back):
            # samples stamped at or before the topic's previous one are dropped, counted.
            t = b.log_time_ns
            previous = self._order.get(b.topic)
            if len(t) and (previous is not None and t[0] <= previous or (len(t) > 1 and np.any(t[1:] <= t[:-1]))):
                running = np.maximum.accumulate(np.concatenate([[previous if previous is not None else t[0] - 1], t[:-1]]))
                ok = t > running
                self.rejected["duplicate"] += int(np.count_nonzero(t == running))
                self.rejected["backwards"] += int(np.count_nonzero(t < running))
                b = FollowBlock(b.topic, b.kind, b.name, t[ok], b.publish_time_ns[ok], b.values[ok])
                keep = np.zeros(1, dtype=bool)  # something was refused
            if keep is not None and not keep.all():
                # the sensor is degraded while its samples are being refused (data time of the refusal)
                self.refused_at[b.topic] = newest_ns if newest_ns is not None else 0
            if len(b):
                self._order[b.topic] = int(b.log_time_ns[-1])
            if clock is not None and len(b):
                clock.take(b.topic, int(b.log_time_ns[-1]), mono)
            out.append(b)
        if whole and clock is not None:  # a source jump is only found by a clock
            clock.record(None, "source_jump", sum(len(b) for b in out), clock.offset_s(None, min(firsts.values()), mono))
        return out

    def watch_stuck(self, block: FollowBlock) -> None:
        """Track how long an IMU's or a strain gauge's readings have not changed at all (their
        noise never lets a working one read the same value twice for long)."""
        if block.kind not in ("imu", "strain"):
            return
        v, t = block.values, block.log_time_ns
        previous = self._stuck.get(block.topic)
        same = np.all(v[1:] == v[:-1], axis=1) if len(v) > 1 else np.zeros(0, dtype=bool)
        changed = np.nonzero(~same)[0]
        if len(changed):
            start = int(t[changed[-1] + 1])
        elif previous is not None and np.array_equal(previous[0], v[0]):
            start = previous[1]
        else:
            start = int(t[0])
        self._stuck[block.topic] = (v[-1].copy(), start, int(t[-1]))

    def stuck_sensors(self) -> list[str]:
        """Topics whose readings have stayed exactly the same for ``stuck_after_s`` and more."""
        return sorted(topic for topic, (_, start, last) in self._stuck.items() if last - start >= self.stuck_after_ns)
