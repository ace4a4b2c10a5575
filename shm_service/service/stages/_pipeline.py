"""A structure's pipeline: the wiring of its stages, in data order.

    checks (plausibility, stuck sensors; ``stages._checks``) → merge on one clock (``stages._merge``) →
    streaming estimator (``stages._estimate``) → windowing and analysis (``stages._analysis``,
    with the loads of the engine's windows) → commits (``stages._commit``) → outputs: the
    recording and live ring (``stages._outputs``).

``process(batch)`` (the data lane) and ``step_analysis()`` (the analysis lane) are each called by
one thread at a time — a worker's scheduler (``runtime._scheduler``) steps them on its pool; without an
analysis lane (replays into a database, tests, benchmarks) the windows are analysed within
``process``. Memory is bounded: the merge holds at most ``lateness_s`` of samples, the estimator a
few seconds, the analysis one window of b(t) and its inbox ``analysis_inbox`` chunks.
"""

from __future__ import annotations

import logging
import os
import threading
import time
from collections import Counter, deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Generic, TypeVar

import numpy as np
from threadpoolctl import threadpool_limits

from analytics import AnalysisConfig
from contract import PipelineStatusDocument
from estimator import ImmsModel

from ...recording import FollowBlock
from ._archive import Archive, ArchiveSettings
from ._checks import CheckSettings, SampleChecks
from .._delegate import ReadThrough
from ._merge import MergeSettings, MergeStage
from ...recording._plausibility import SourceClock, ValueLimits
from ..alarms._sinks import SinkGuard
from ._analysis import AnalysisStage
from ._commit import CommitSettings, CommitStage
from ._estimate import EstimateSettings, EstimateStage, stored_calibration
from ._outputs import OutputStage
from ..storage._storage import Storage

_Item = TypeVar("_Item")

__all__ = ["Batch", "Pipeline"]

log = logging.getLogger("shm.serve.pipeline")

_NS = 1_000_000_000


@dataclass
class Batch:
    """What a source hands the pipeline: new accepted samples per topic, optionally the raw
    messages for the recordings (topic, log_time_ns, payload, publish_time_ns) and the truth
    deflection (simulation)."""

    blocks: list[FollowBlock]
    raw: list[tuple[str, int, bytes, int]] | None = None
    truth: tuple[np.ndarray, np.ndarray] | None = None
    received: float = field(default_factory=time.monotonic)
    refused: dict[str, int] | None = None  # samples per topic the source refused (its sensor is degraded meanwhile)

    @classmethod
    def joined(cls, batches: list["Batch"]) -> "Batch":
        """Consecutive batches of one source as one (each topic's samples concatenated in order):
        what the source would have handed on as one bigger block. A structure behind its pace
        takes its queued batches in one step, so the per-batch costs (checks, merge, the
        estimator's call) are paid once."""
        if len(batches) == 1:
            return batches[0]
        parts: dict[str, list[FollowBlock]] = {}
        for batch in batches:
            for block in batch.blocks:
                parts.setdefault(block.topic, []).append(block)
        blocks = [b[0] if len(b) == 1 else
                  FollowBlock(b[0].topic, b[0].kind, b[0].name, np.concatenate([x.log_time_ns for x in b]),
                              np.concatenate([x.publish_time_ns for x in b]), np.concatenate([x.values for x in b]))
                  for b in parts.values()]
        raws = [b.raw for b in batches if b.raw is not None]
        truths = [b.truth for b in batches if b.truth is not None]
        refused: Counter = Counter()
        for b in batches:
            refused.update(b.refused or {})
        return cls(blocks, [m for r in raws for m in r] if raws else None,
                   (np.concatenate([t for t, _ in truths]), np.concatenate([d for _, d in truths])) if truths else None,
                   min(b.received for b in batches), dict(refused) if any(b.refused is not None for b in batches) else None)


_blas_limit = None


def _no_usable(usability: dict) -> str | None:
    """Why none of the windows so far is usable and what to change, or None (some are, or none ended
    yet, or only the filter's warm-up was skipped: the normal start)."""
    if usability["usable"] or not set(usability["rejected"]) - {"warmup"}:
        return None
    return f"{usability['why_none']}; change: " + "; ".join(usability["change"])


def _one_blas_thread() -> None:
    """Run BLAS/LAPACK single-threaded in this process (once; an explicit OPENBLAS_NUM_THREADS or
    OMP_NUM_THREADS is left alone).

    The analysis multiplies and decomposes small matrices (a 120 × 120 block Toeplitz per window)
    while the source thread decodes on the other core: OpenBLAS's worker threads then spin for
    the cores and one SSI-cov window took 4-10× the CPU of a single thread (measured on the
    2-core machine under load). Results are the same bits: each output element is computed by
    the same kernel either way."""
    global _blas_limit
    if _blas_limit is None and not {"OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS"} & set(os.environ):
        _blas_limit = threadpool_limits(1, user_api="blas")


@dataclass
class _SetAside:
    """What a stop under a backlog left unanalysed: samples (and how many of them went to the
    recording), their data time span, analysis chunks."""

    samples: int = 0
    recorded: int = 0
    first_ns: int | None = None
    last_ns: int | None = None
    chunks: int = 0

    def add(self, batch: Batch) -> None:
        for block in batch.blocks:
            if len(block):
                self.samples += len(block)
                lo, hi = int(block.log_time_ns[0]), int(block.log_time_ns[-1])
                self.first_ns = lo if self.first_ns is None else min(self.first_ns, lo)
                self.last_ns = hi if self.last_ns is None else max(self.last_ns, hi)

    def describe(self) -> str | None:
        if not self.samples and not self.chunks:
            return None
        span = "" if self.first_ns is None or self.last_ns is None else f" ({(self.last_ns - self.first_ns) / _NS:.1f} s of data from {self.first_ns / _NS:.3f})"
        where = (f"{self.recorded} of them in the recording" if self.recorded
                 else "not recorded (their source's file holds them, or the recording of raw samples is off)")
        return (f"stopped under a backlog: {self.samples} samples{span} not estimated, {where}; "
                f"{self.chunks} estimator chunk(s) not analysed")


@dataclass(frozen=True)
class EstimatorChunk:
    """The analysis lane's message of one estimator chunk: its b(t) (times ``t`` in s after
    ``epoch_ns``; ``b`` (n, Γ)), the support displacement ``d`` (n,) or None, the temperature
    samples, ``first_s`` (UNIX s of its first estimate; None for a chunk without estimates, which
    carries its temperature only) and the released gauge samples by name."""

    epoch_ns: int
    t: np.ndarray
    b: np.ndarray
    d: np.ndarray | None
    temperature: Any
    first_s: float | None
    gauges: dict | None = None


@dataclass(frozen=True)
class NotBefore:
    """The analysis lane's message that no window may start before ``ns`` (UNIX ns): a filter restart."""

    ns: int


#: What the data lane hands the analysis lane, in order.
AnalysisItem = EstimatorChunk | NotBefore


class AnalysisInbox(Generic[_Item]):
    """The analysis lane's items in order (estimator chunks, not-before instants), handled by
    ``handle`` one per ``step``; ``full`` holds the data lane back (back-pressure). While it is
    empty, ``idle`` (the waiting windows' retry) is due every ``idle_s``."""

    def __init__(self, handle: Callable[[_Item], None], idle: Callable[[], bool], capacity: int = 256,
                 idle_s: float = 1.0) -> None:
        self.items: deque[_Item] = deque()
        self.handle, self.idle, self.capacity, self.idle_s = handle, idle, capacity, idle_s
        self.lock = threading.Lock()  # one stepper at a time (the lane, or the data lane's finish)
        self._idle_at = time.monotonic() + idle_s

    @property
    def full(self) -> bool:
        return len(self.items) >= self.capacity

    def ready(self) -> bool:
        return bool(self.items) or time.monotonic() >= self._idle_at

    def step(self) -> None:
        with self.lock:
            if self.items:
                self.handle(self.items.popleft())
                return
            self._idle_at = time.monotonic() + self.idle_s
            self.idle()

    def drain(self) -> None:
        with self.lock:
            while self.items:
                self.handle(self.items.popleft())


class Pipeline:
    """The stages of one structure, wired (see the module). ``status()`` may be called from any thread."""

    def __init__(self, *, model: ImmsModel, source_id: str, storage: Storage, analysis: AnalysisConfig,
                 estimate: EstimateSettings | None = None, merge: MergeSettings | None = None,
                 checks: CheckSettings | None = None, commits: CommitSettings | None = None,
                 outputs: ArchiveSettings | None = None, archive: Archive | None = None, record_raw: bool = False,
                 sink_guard: SinkGuard | None = None, clock: SourceClock | None = None, limits: ValueLimits | None = None,
                 analysis_lane: bool = False) -> None:
        _one_blas_thread()
        self.model, self.rig, self.source_id, self.storage = model, model.rig, source_id, storage
        stored = storage.load_state(source_id) or {}
        blob = stored.get("monitor") or {}
        self.resumed = bool(stored)
        # plausibility of what the source delivers (clock None: judged by the source itself, as ingest is)
        self.checks = SampleChecks(checks or CheckSettings(), clock, limits)
        self.merger = MergeStage(merge)
        self.estimate = EstimateStage(model, estimate, stored_calibration(stored))
        # Without a monitor to resume, the source's active baseline (shm baseline learn) arms a new one;
        # one alarm path: the engine's (the service's [alarms] hysteresis is in it: ServiceSettings.engine_config)
        baseline = None if blob.get("monitor") else storage.active_baseline(source_id)
        self.analytics = AnalysisStage(model, analysis, blob.get("monitor"), stored.get("last_window_start_s"), source_id,
                                       baseline=baseline, loads_state=blob.get("loads"))
        self.outputs = OutputStage(model, source_id, storage, outputs, archive=archive, sink_guard=sink_guard,
                                   record_raw=record_raw)
        self.commits = CommitStage(storage, source_id, self.analytics.active(), commits)
        # the analysis lane (None: analysed inline, within ``process``)
        self.inbox: AnalysisInbox[AnalysisItem] | None = AnalysisInbox(self._handle, self._retry_commits) if analysis_lane else None
        self.lane_started = False  # until ``start_lane``, the windows are analysed inline (as without a lane)
        self.on_analysis_error: Callable[[Exception], None] | None = None
        self.analysis_error: str | None = None  # the last chunk's analysis error; None once one analyses fine
        self._reset_requested = False
        self.stop_deadline: float | None = None  # a stop under a backlog: what is left then is set aside
        self.set_aside = _SetAside()
        self.samples: Counter = Counter()
        self.last_time_ns: dict[str, int] = {}
        self.silent_after_ns = int(self.checks.settings.silent_after_s * _NS)
        self.estimates = 0
        self.newest_ns: int | None = None
        self.processed_ns: int | None = None
        self.latency_s = self.busy_s = 0.0
        self.started = time.monotonic()
        self.latest_x: np.ndarray | None = None

    # -- the data lane ------------------------------------------------------------------------

    def process(self, batch: Batch) -> None:
        began = time.monotonic()
        if self.commits.pending and not self.lane_started:
            self.commits.flush()
        for block in self.checks.judge(batch.blocks, self.newest_ns):
            if not len(block):
                continue
            self.checks.watch_stuck(block)
            self.samples[block.topic] += len(block)
            last = int(block.log_time_ns[-1])
            self.last_time_ns[block.topic] = max(self.last_time_ns.get(block.topic, last), last)
            self.newest_ns = last if self.newest_ns is None else max(self.newest_ns, last)
            self.merger.add(block)
        self.checks.note_refused(tuple(batch.refused or ()), self.newest_ns)
        if batch.truth is not None:
            self.outputs.truth.append(batch.truth)
        self.outputs.raw(batch.raw)
        self._advance(self.merger.release())
        self.outputs.maybe_flush()
        done = time.monotonic()
        self.latency_s = done - batch.received
        self.busy_s += done - began

    def _advance(self, released: dict[str, tuple[np.ndarray, np.ndarray]], final: bool = False) -> None:
        if released:
            self.processed_ns = max(int(t[-1]) for t, _ in released.values())
        elif not final:
            return
        step = self.estimate.step(released, final)
        if step is None:
            return
        for ns in step.not_before_ns:
            self._to_analysis(NotBefore(ns))
        out = step.out
        if out is None:
            if step.temperature is not None:
                self._to_analysis(EstimatorChunk(step.epoch_ns, np.zeros(0), np.zeros((0, self.model.gamma)), None,
                                                 step.temperature, None))
            return
        self.estimates += len(out.t)
        t_abs = step.epoch_ns / _NS + out.t
        layout = self.model.state_layout
        self.latest_x = out.x[-1]
        self.outputs.estimates(step.epoch_ns, t_abs, out)
        # b(t) and the support displacement d(t), the measured input of the identification; the
        # gauges' samples for the loads' band
        self._to_analysis(EstimatorChunk(step.epoch_ns, out.t, layout.b_of(out.x), out.x[:, layout.d], step.temperature,
                                         float(t_abs[0]), self._gauges(released, step.epoch_ns)))

    def _gauges(self, released: dict, epoch_ns: int) -> dict | None:
        """The released strain gauge samples by gauge name (times s after ``epoch_ns``, values): the
        loads' band."""
        loads = self.analytics.loads
        if loads is None or not loads.gauges:
            return None
        topics = {f"/strain/{g.name}": g.name for g in loads.gauges}
        return {topics[k]: ((v[0] - epoch_ns) * 1e-9, v[1][:, 0]) for k, v in released.items()
                if k in topics and len(v[0])} or None

    def finish(self) -> None:
        """The source ended: release everything, flush the filter, analyse what is left, close the recording."""
        self._advance(self.merger.release(final=True), final=True)
        if self.inbox is not None:
            self.inbox.drain()
        if self.commits.pending:
            self.commits.flush(retry_s=max(self.commits.settings.retry_s, 30.0))
        self.outputs.close()

    # -- the analysis lane ----------------------------------------------------------------------

    def _to_analysis(self, item: AnalysisItem) -> None:
        if self.lane_started and self.inbox is not None:  # a lane is started only with an inbox
            self.inbox.items.append(item)
        else:
            self._handle(item)

    def start_lane(self) -> None:
        """From now on the windows are analysed in the analysis lane (``step_analysis``)."""
        if self.inbox is None:
            raise ValueError("this pipeline was made without an analysis lane (analysis_lane=False)")
        self.lane_started = True

    def step_analysis(self) -> None:
        """Analyse the next chunk of the inbox (or retry the windows waiting for the database)."""
        assert self.inbox is not None
        self.inbox.step()

    def _handle(self, item: AnalysisItem) -> None:
        if isinstance(item, NotBefore):
            self.analytics.set_not_before(max(self.analytics.not_before_ns or item.ns, item.ns))
        elif not isinstance(item, EstimatorChunk):
            raise TypeError(f"unknown analysis item {item!r}")
        elif self.past_stop_deadline():
            self.set_aside.chunks += 1
        elif not self.lane_started:
            self._analyse(item)
        elif self._guarded(self._analyse, item):
            self.analysis_error = None

    def _retry_commits(self) -> bool:
        return not self.commits.pending or self._guarded(self.commits.flush)

    def _analyse(self, chunk: EstimatorChunk) -> None:
        epoch, t, b, d, temperature, first_s, gauges = (chunk.epoch_ns, chunk.t, chunk.b, chunk.d, chunk.temperature,
                                                         chunk.first_s, chunk.gauges)
        if self.commits.pending and self.lane_started:
            self.commits.flush()
        if first_s is not None and self._reset_requested:
            self._reset_requested = False
            self.analytics.reset()
            nxt = self.analytics.next_start
            self.commits.clear_for_new_baseline(first_s, nxt - self.analytics.step_s if nxt else first_s,
                                                self.analytics.state())
        for window in self.analytics.add(epoch, t, b, d, temperature, gauges):
            monitor = self.analytics.monitor
            self.commits.add(window, monitor_state=self.analytics.state(), raised=self.analytics.active(),
                             baseline=monitor.baseline.to_dict() if window.new_baseline and monitor.baseline else None,
                             calibration=self.estimate.new_calibration())

    def _guarded(self, fn: Callable[..., object], *args: object) -> bool:
        try:
            fn(*args)
            return True
        except Exception as exc:  # one chunk's failure must not stop the analysis of the next
            self.analysis_error = f"{type(exc).__name__}: {exc}"
            if self.on_analysis_error is not None:
                self.on_analysis_error(exc)
            else:
                log.exception("%s: analysis error; chunk skipped", self.source_id)
            return False

    # -- control ----------------------------------------------------------------------------------

    def request_baseline(self) -> None:
        """Learn a new baseline from the next windows (called from the API thread)."""
        self._reset_requested = True

    def past_stop_deadline(self) -> bool:
        return self.stop_deadline is not None and time.monotonic() > self.stop_deadline

    def set_batch_aside(self, batch: Batch) -> None:
        """A batch of the backlog left at the stop's deadline: recorded (when the recording takes
        the raw samples; a file source's data are in its file), not estimated."""
        self.set_aside.add(batch)
        if self.outputs.archive_raw and batch.raw:
            self.outputs.raw(batch.raw)
            self.set_aside.recorded += sum(len(b) for b in batch.blocks)

    # -- what the stages hold ---------------------------------------------------------------------

    @property
    def estimator(self):  # the streaming estimator (its diagnostics, its progress)
        return self.estimate.estimator

    @property
    def archive(self) -> Archive | None:
        return self.outputs.archive

    @property
    def live(self):
        return self.outputs.live

    @live.setter
    def live(self, ring) -> None:
        self.outputs.live = ring

    # the stages' counters and state, read through (``ReadThrough``)
    clock: ReadThrough[SourceClock | None] = ReadThrough("checks")
    rejected: ReadThrough[Counter] = ReadThrough("checks")
    committed_alarms: ReadThrough[dict[str, str]] = ReadThrough("commits")
    windows_committed: ReadThrough[int] = ReadThrough("commits")
    last_window: ReadThrough[Any] = ReadThrough("commits")
    storage_error: ReadThrough[str | None] = ReadThrough("commits")
    storage_errors: ReadThrough[int] = ReadThrough("commits")
    trend_rows_dropped: ReadThrough[int] = ReadThrough("commits")

    @property
    def pending_commits(self) -> int:
        return len(self.commits.pending)

    def stuck_sensors(self) -> list[str]:
        """Topics whose readings have stayed exactly the same for ``stuck_after_s`` and more."""
        return self.checks.stuck_sensors()

    # -- status -------------------------------------------------------------------------------

    def health_problems(self) -> list[str]:
        """Why the pipeline's output cannot be trusted right now (empty: it can)."""
        problems = self.estimator.health_problems()
        if self.clock is not None:
            problems.extend(self.clock.problems())
        return problems

    def sensor_states(self) -> dict[str, str]:
        newest = self.newest_ns
        diag = self.estimator.filter.diagnostics() if self.estimator.filter is not None else {}
        inactive = {d["sensor"] for d in diag.get("degraded_imus", []) if not d.get("active", True)}
        inactive.update(self.checks.degraded(newest))
        states: dict[str, str] = {}
        for sensor in self.rig.sensors:
            last = self.last_time_ns.get(sensor.topic)
            silent = last is None or (newest is not None and newest - last > self.silent_after_ns)
            states[sensor.topic] = "degraded" if silent or sensor.topic in inactive else "ok"
        return states

    def status(self, *, queue_depth: int, queue_capacity: int) -> PipelineStatusDocument:
        elapsed = max(time.monotonic() - self.started, 1e-9)
        epoch = self.estimator.epoch_ns
        span = None if epoch is None or self.processed_ns is None else (self.processed_ns - epoch) / _NS
        a = self.analytics
        usability = a.usability()
        return PipelineStatusDocument(
            queue_depth=queue_depth, queue_capacity=queue_capacity,
            samples=sum(self.samples.values()), samples_by_topic=dict(self.samples),
            late_samples=sum(self.merger.late.values()), late_by_topic=dict(self.merger.late),
            estimates=self.estimates, estimator=self.estimator.diagnostics(),
            windows=a.windows, windows_committed=self.windows_committed,
            windows_skipped_incomplete=a.skipped_incomplete, windows_skipped_warmup=a.skipped_warmup,
            windows_usable=usability["usable"], windows_rejected=usability["rejected"], no_usable_window=_no_usable(usability),
            baseline="learning" if a.learning_baseline else "active",
            data_time_s=None if self.newest_ns is None else self.newest_ns / _NS, processed_data_s=span,
            realtime_factor=None if span is None else round(span / elapsed, 2),
            pipeline_latency_s=round(self.latency_s, 4), busy_fraction=round(self.busy_s / elapsed, 3),
            active_alarms=dict(self.committed_alarms),
            hot_spots=[] if self.commits.last_loads is None else list(self.commits.last_loads.hot_spots),
        )
