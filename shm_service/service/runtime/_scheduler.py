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

Why: a process of many structures with three threads each (source, pipeline, analysis) had ~75
threads convoying on one GIL; when the OS descheduled the thread holding it (a CPU-bound
process beside it), all of them waited, and the fleet fell minutes behind its pace.
"""

from __future__ import annotations

import logging
import threading
from collections import deque

from pydantic import BaseModel, ConfigDict, Field

from contract import Lane

__all__ = ["Lane", "Scheduler", "SchedulerSettings"]

log = logging.getLogger("shm.serve.scheduler")


class SchedulerSettings(BaseModel):
    """The pool a worker runs its structures' pipelines on."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    threads: int = Field(3, ge=1, le=64, description="pool threads stepping the structures' pipelines")
    idle_s: float = Field(0.05, gt=0, le=5, description="longest sleep of an idle pool thread (it is woken by new data), s")
    background_threads: int = Field(1, ge=1, le=64, description="most pool threads stepping background lanes (the analysis) at once")


class Scheduler:
    """Steps its lanes on ``settings.threads`` threads, round-robin, each lane by one thread at a time."""

    def __init__(self, settings: SchedulerSettings | None = None, name: str = "pipelines") -> None:
        self.settings = settings or SchedulerSettings()
        self.name = name
        self._lanes: deque[Lane] = deque()
        self._cv = threading.Condition()
        self._stopping = False
        self._threads: list[threading.Thread] = []
        self._background_running = 0
        self.steps = 0

    def add(self, lane: Lane) -> None:
        with self._cv:
            self._lanes.append(lane)
            self._cv.notify()
        self._start()

    def wake(self) -> None:
        """New work arrived (a source put a batch)."""
        with self._cv:
            self._cv.notify()

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
            return len(self._lanes)

    def _take(self) -> Lane | None:
        """The next ready lane, taken out of the rotation while it is stepped (None: stopping): the
        first ready pace lane in rotation order, else the first ready background lane while fewer
        than ``background_threads`` step one."""
        with self._cv:
            while not self._stopping:
                if any(lane.finished for lane in self._lanes):
                    self._lanes = deque(lane for lane in self._lanes if not lane.finished)
                room = self._background_running < self.settings.background_threads
                background: int | None = None
                for k, lane in enumerate(self._lanes):
                    behind = getattr(lane, "background", False)
                    if behind and (background is not None or not room):
                        continue
                    if not self._ready(lane):
                        continue
                    if not behind:
                        del self._lanes[k]
                        return lane
                    background = k
                if background is not None:
                    lane = self._lanes[background]
                    del self._lanes[background]
                    self._background_running += 1
                    return lane
                self._cv.wait(self.settings.idle_s)
            return None

    @staticmethod
    def _ready(lane: Lane) -> bool:
        try:
            return lane.ready()
        except Exception:  # a lane that cannot say is tried again next round
            log.exception("lane %s: ready() failed", lane.name)
            return False

    def _run(self) -> None:
        while True:
            lane = self._take()
            if lane is None:
                return
            try:
                lane.step()
            except Exception:  # a lane's own handling failed: logged, the pool goes on
                log.exception("lane %s failed a step", lane.name)
            finally:
                with self._cv:
                    self.steps += 1
                    if getattr(lane, "background", False):
                        self._background_running -= 1
                    if not lane.finished:
                        self._lanes.append(lane)  # to the back: the others' turn first
                    self._cv.notify()
