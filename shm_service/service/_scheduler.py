"""A worker's scheduler: its structures' pipelines run on a small pool of threads, not on
threads of their own.

Each structure has two lanes — the data lane (take a batch from the source's queue: checks,
merge, estimator, windowing) and the analysis lane (analyse the estimator's chunks, commit the
windows) — each stepped by one pool thread at a time, so a structure's data stay in order while
its analysis runs beside its estimator. The pool takes the lanes round-robin: a lane that was
stepped goes to the back, so every structure gets its turn however busy the others are.

The lanes that keep a structure on its pace (its source, its data lane) go first: a **background**
lane (the analysis) is taken only when no pace lane is ready, and by at most
``background_threads`` pool threads at a time. A window's analysis is long (a few hundred ms of
Python and small LAPACK calls) and falls due on many structures at once; run on every pool thread
it held the GIL against the data lanes and the fleet fell seconds behind its pace. The analysis
has its inbox to wait in (``AnalysisInbox``); when that fills, the data lane is held back and the
analysis gets the pool.

A lane that is not ready may say when it falls due by the clock alone (``wait_s``: a paced
source's next batch, the analysis inbox's retry; ``inf``: only an event makes it ready, as a data
lane waiting for its queue); the scheduler does not ask it again before then unless it is woken
(``poke`` when a batch is put, ``wakes`` of a lane whose step may have made it ready, ``expire``
on a stop), and an idle pool thread sleeps until the earliest such instant. A lane without
``wait_s`` is asked on every scan. Why: asking every lane every 50 ms took a tenth
of a worker's CPU (17 000 ``ready()`` calls a second for 50 structures).

Why: a process of many structures with three threads each (source, pipeline, analysis) had ~75
threads convoying on one GIL; when the OS descheduled the thread holding it (a CPU-bound
process beside it), all of them waited, and the fleet fell minutes behind its pace.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections import deque
from typing import Callable, Protocol

from pydantic import BaseModel, ConfigDict, Field

__all__ = ["Lane", "Scheduler", "SchedulerSettings"]

log = logging.getLogger("shm.serve.scheduler")


class SchedulerSettings(BaseModel):
    """The pool a worker runs its structures' pipelines on."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    threads: int = Field(3, ge=1, le=64, description="pool threads stepping the structures' pipelines")
    idle_s: float = Field(0.5, gt=0, le=5, description="longest sleep of an idle pool thread (it is woken by new data and when a lane falls due), s")
    background_threads: int = Field(1, ge=1, le=64, description="most pool threads stepping background lanes (the analysis) at once")


class Lane(Protocol):
    """One lane of a structure: ``ready()`` (cheap, called under the scheduler's lock) says whether
    ``step()`` has work; ``step()`` does one unit of it (and handles its own errors);
    ``finished`` removes the lane for good; ``background`` (optional, default False): taken only
    when no other lane is ready (see the module); ``wait_s()`` (optional, called under the lock
    when ``ready()`` said no): seconds until the lane falls due by the clock alone (``inf``: only
    when it is woken), or None to be asked again on every scan (a lane without it is);
    ``wakes`` (optional): the lanes a step of this one may make ready before the instant they gave
    (asked again after each of its steps)."""

    name: str
    finished: bool

    def ready(self) -> bool: ...
    def step(self) -> None: ...


class _Entry:
    """A lane in the rotation, with what the scheduler knows of it."""

    __slots__ = ("lane", "background", "not_before", "wait_s")

    def __init__(self, lane: Lane) -> None:
        self.lane = lane
        self.background: bool = bool(getattr(lane, "background", False))
        self.wait_s: Callable[[], float | None] | None = getattr(lane, "wait_s", None)
        self.not_before = 0.0  # monotonic instant before which ready() is not asked


class Scheduler:
    """Steps its lanes on ``settings.threads`` threads, round-robin, each lane by one thread at a time."""

    def __init__(self, settings: SchedulerSettings | None = None, name: str = "pipelines") -> None:
        self.settings = settings or SchedulerSettings()
        self.name = name
        self._pace: deque[_Entry] = deque()
        self._background: deque[_Entry] = deque()
        self._entries: dict[int, _Entry] = {}  # id(lane) -> its entry, for poke
        self._cv = threading.Condition()
        self._stopping = False
        self._threads: list[threading.Thread] = []
        self._background_running = 0
        self._timer_at = math.inf  # the instant a pool thread sleeps until (inf: none does)
        self.steps = 0
        self.scans = 0
        self.asked = 0  # ready() calls

    def add(self, *lanes: Lane) -> None:
        """``lanes`` join the rotation at its back, together (the pool's next scan sees them all)."""
        with self._cv:
            for lane in lanes:
                entry = _Entry(lane)
                self._entries[id(lane)] = entry
                (self._background if entry.background else self._pace).append(entry)
            self._cv.notify_all()
        self._start()

    def wake(self) -> None:
        """New work arrived (a source put a batch)."""
        with self._cv:
            self._cv.notify()

    def poke(self, lane: Lane) -> None:
        """``lane`` may be ready before the instant it gave (its inbox got an item): ask it again."""
        with self._cv:
            entry = self._entries.get(id(lane))
            if entry is not None:
                entry.not_before = 0.0
            self._cv.notify()

    def expire(self) -> None:
        """Ask every lane again and wake every pool thread (something stops)."""
        with self._cv:
            for entry in self._entries.values():
                entry.not_before = 0.0
            self._cv.notify_all()

    def _start(self) -> None:
        with self._cv:
            if self._threads or self._stopping:
                return
            self._threads = [threading.Thread(target=self._run, name=f"{self.name}-{k}", daemon=True)
                             for k in range(self.settings.threads)]
        for thread in self._threads:
            thread.start()

    def stop(self, timeout: float = 5.0) -> None:
        with self._cv:
            self._stopping = True
            self._cv.notify_all()
        for thread in self._threads:
            thread.join(timeout)

    @property
    def lanes(self) -> int:
        with self._cv:
            return len(self._pace) + len(self._background)

    def _take(self) -> _Entry | None:
        """The next ready lane, taken out of the rotation while it is stepped (None: stopping): the
        first ready pace lane in rotation order, else the first ready background lane while fewer
        than ``background_threads`` step one; else sleep until woken or the earliest lane falls due."""
        with self._cv:
            while not self._stopping:
                now = time.monotonic()
                self.scans += 1
                entry, earliest = self._first_ready(self._pace, now, math.inf)
                if entry is None and self._background_running < self.settings.background_threads:
                    entry, earliest = self._first_ready(self._background, now, earliest)
                    if entry is not None:
                        self._background_running += 1
                if entry is not None:
                    return entry
                self._sleep(now, earliest)
            return None

    def _first_ready(self, lanes: deque[_Entry], now: float, earliest: float) -> tuple[_Entry | None, float]:
        """The first ready entry of ``lanes`` (taken out of it) and the earliest instant one of the
        others falls due; finished lanes leave the rotation."""
        finished = False
        for k, entry in enumerate(lanes):
            if entry.not_before > now:
                earliest = min(earliest, entry.not_before)
                continue
            lane = entry.lane
            if lane.finished:
                finished = True
                continue
            self.asked += 1
            if self._ready(lane):
                del lanes[k]
                if finished:
                    self._drop_finished(lanes)
                return entry, earliest
            if entry.wait_s is not None:
                wait = self._wait_s(entry)
                if wait is not None and wait > 0:
                    entry.not_before = now + wait
                    earliest = min(earliest, entry.not_before)
        if finished:
            self._drop_finished(lanes)
        return None, earliest

    def _drop_finished(self, lanes: deque[_Entry]) -> None:
        for entry in [e for e in lanes if e.lane.finished]:
            lanes.remove(entry)
            self._entries.pop(id(entry.lane), None)

    def _sleep(self, now: float, earliest: float) -> None:
        """Wait to be woken; the first thread to see an instant no thread sleeps until sleeps until it
        (the others sleep ``idle_s`` at most), so one thread wakes when a lane falls due."""
        if earliest < self._timer_at:
            self._timer_at = earliest
            self._cv.wait(min(self.settings.idle_s, max(earliest - now, 0.0) + 0.001))
            if self._timer_at == earliest:
                self._timer_at = math.inf
        else:
            self._cv.wait(self.settings.idle_s)

    @staticmethod
    def _ready(lane: Lane) -> bool:
        try:
            return lane.ready()
        except Exception:  # a lane that cannot say is tried again next round
            log.exception("lane %s: ready() failed", lane.name)
            return False

    @staticmethod
    def _wait_s(entry: _Entry) -> float | None:
        try:
            return entry.wait_s() if entry.wait_s is not None else None
        except Exception:  # asked again on the next scan
            log.exception("lane %s: wait_s() failed", entry.lane.name)
            return None

    def _run(self) -> None:
        while True:
            entry = self._take()
            if entry is None:
                return
            lane = entry.lane
            try:
                lane.step()
            except Exception:  # a lane's own handling failed: logged, the pool goes on
                log.exception("lane %s failed a step", lane.name)
            finally:
                with self._cv:
                    self.steps += 1
                    if entry.background:
                        self._background_running -= 1
                    for other in getattr(lane, "wakes", ()):
                        woken = self._entries.get(id(other))
                        if woken is not None:
                            woken.not_before = 0.0
                    if lane.finished:
                        self._entries.pop(id(lane), None)
                    else:
                        entry.not_before = 0.0  # stepped: asked on the next scan
                        (self._background if entry.background else self._pace).append(entry)  # to the back
                    self._cv.notify()
