"""One monitored structure of a service: its source, bounded queue, model and pipeline, whose
lanes run on the service's scheduler (``runtime._scheduler``), with its own errors and state."""

from __future__ import annotations

import logging
import queue
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any


from contract import (
    ChartLevelsDocument,
    ModelDocument,
    NotSingleStructure,
    RigDescription,
    StructureHost,
    StructureSummaryDocument,
    StructureUnavailable,
    ThresholdsDocument,
    load_rig,
)
from estimator import build_model

from ...recording import RecordingError
from ..stages._archive import Archive
from .._config import ServiceSettings
from .._delegate import ReadThrough
from ._live import LiveRing
from ..stages._pipeline import Batch, Pipeline
from ...recording._plausibility import SourceClock
from ..alarms._sinks import SinkGuard
from ..sources._sources import END, FileSource, IngestSource, SimSource, Source
from ..stages._commit import CommitSettings
from ..storage._storage import Storage

__all__ = ["NotSingleStructure", "SingleStructureView", "RigPending", "ServiceError", "Structure", "StructureUnavailable"]

log = logging.getLogger("shm.serve")


class _WakingQueue(queue.Queue):
    """The source's bounded queue; a put wakes the scheduler (``on_put``)."""

    on_put: Callable[[], None] | None = None

    def put(self, item: Any, block: bool = True, timeout: float | None = None) -> None:
        super().put(item, block, timeout)
        if self.on_put is not None:
            self.on_put()


class _DataLane:
    """A structure's data lane on the scheduler: ready when its queue holds a batch (or it is
    stopping) and its analysis inbox has room."""

    def __init__(self, structure: "Structure") -> None:
        self.structure, self.name, self.finished = structure, f"data-{structure.id}", False

    def ready(self) -> bool:
        s = self.structure
        inbox = s.pipeline.inbox
        return (inbox is None or not inbox.full) and (s.queue.qsize() > 0 or s._stopping)

    def step(self) -> None:
        self.structure.step_data()


class _AnalysisLane:
    """A structure's analysis lane: its estimator chunks analysed, its windows committed. A
    background lane: the scheduler steps it when no source or data lane is ready."""

    background = True

    def __init__(self, structure: "Structure") -> None:
        self.structure, self.name, self.finished = structure, f"analysis-{structure.id}", False

    def ready(self) -> bool:
        pipeline = self.structure.pipeline
        return pipeline.lane_started and pipeline.inbox is not None and pipeline.inbox.ready()

    def step(self) -> None:
        self.structure.pipeline.step_analysis()


class ServiceError(RuntimeError):
    """The service cannot start (the message says why)."""


class RigPending(ServiceError):
    """``follow:``: the file (or its rig.json) is not there yet; the service can be made once it is."""


class _ModelCache:
    """``build_model`` once per distinct rig and estimator settings: identical structures of a
    fleet share one (immutable) model, its FE matrices and unit deformations."""

    def __init__(self) -> None:
        self._models: dict[str, Any] = {}
        self._lock = threading.Lock()

    def get(self, rig: RigDescription, est: Any) -> Any:
        key = rig.model_dump_json() + "|" + est.model_dump_json(include={"peripheral", "modes", "modes_xi", "imus", "tofs", "gauges"})
        with self._lock:
            model = self._models.get(key)
            if model is None:
                biaxial = rig.beam.biaxial
                # a biaxial beam's gauges hold two planes: the default count is four per plane
                gauges = 2 * est.gauges if biaxial and "gauges" not in est.model_fields_set else est.gauges
                model = build_model(rig, peripheral=est.peripheral, modes=est.modes, imus=est.imus, tofs=est.tofs,
                                    gauges=gauges, **({"modes_xi": est.modes_xi} if biaxial else {}))
                self._models[key] = model
            return model


class Structure:
    """One monitored structure: its source, bounded queue, model, pipeline and pipeline thread,
    with its own errors and state. A service of one structure holds one; a fleet many, each
    isolated from the others (its own threads; what it raises is caught and shown on it)."""

    def __init__(self, service: StructureHost, settings: ServiceSettings, *, models: _ModelCache | None = None) -> None:
        self.service = service
        self.settings = settings
        src = settings.source
        self.kind = src.kind
        self.queue = _WakingQueue(maxsize=settings.queue_batches)
        self.source = _make_source(self)
        self.id = self.source.id
        self.rig: RigDescription = self.source.rig  # type: ignore[assignment]
        est = settings.estimator
        _check_sensor_counts(self.rig, est)
        try:
            self.model = (models or _ModelCache()).get(self.rig, est)
        except ValueError as exc:
            raise ServiceError(f"estimator model: {exc}") from None
        speed = src.speed
        self.speed = None if speed == "max" or self.kind in ("follow", "ingest", "mqtt") else float(speed)
        self.started_wall: float | None = None
        self.first_data_ns: int | None = None
        self.pipeline_error: str | None = None  # the last batch's error; None once a batch succeeds again
        self.pipeline_errors = 0
        self.last_pipeline_error: str | None = None
        self._touched_samples = 0
        self._stopping = False
        self._done = threading.Event()
        self._started = False
        self._lanes: tuple[Any, ...] = ()
        a = settings.analytics
        self.thresholds = ThresholdsDocument(
            frequency=ChartLevelsDocument(**dict(zip(("warning_sigma", "alarm_sigma"), a.chart_levels("frequency")))),
            curvature=ChartLevelsDocument(**dict(zip(("warning_sigma", "alarm_sigma"), a.chart_levels("curvature")))),
            clear_sigma=a.clear_sigma,
        )
        m = self.model
        self.model_document = ModelDocument(peripheral=m.selection.peripheral, support=m.rig.support, gamma=m.gamma,
                                            state_names=list(m.state_layout.names),
                                            unit_modes=[list(g) for g in m.mode_map.unit_modes])
        self._pipeline: Pipeline | None = None  # created by attach
        self.archive: Archive | None = None
        # its estimates for a live view, kept while watched, with their virtual strain, stress and moment
        self.live = LiveRing(self.id, list(m.state_layout.names), loads=_virtual_loads(self.rig, m))

    def attach(self, storage: Storage, sink_guard: SinkGuard) -> None:
        """Create the pipeline on the shared ``storage`` (after the source, so a bad source fails first)."""
        settings, src, est = self.settings, self.settings.source, self.settings.estimator
        storage.touch_source(self.id, self.source.kind, src.spec, time.time())
        if settings.archive.enabled:
            self.archive = Archive(settings.archive, self.rig, self.id, getattr(self.source, "metadata", None))
        raw = settings.archive.raw == "always" or (settings.archive.raw == "auto" and self.source.kind in ("sim", "ingest", "mqtt"))
        self._pipeline = Pipeline(
            # the alarm hysteresis of [alarms] is in the engine's configuration (one place: engine_config)
            model=self.model, source_id=self.id, storage=storage, analysis=settings.engine_config(),
            # the sections are the stages' settings: [estimator] the estimate stage's, [source] the merge's
            # and the checks', [archive] the outputs'
            estimate=est, merge=src, checks=src, outputs=settings.archive, record_raw=raw,
            commits=CommitSettings(retry_s=settings.storage_retry_s),
            archive=self.archive, sink_guard=sink_guard,
            # ingest and mqtt are judged per message by their validator (which counts what it refused)
            clock=None if self.source.kind in ("ingest", "mqtt") else self._clock(live=False), limits=src.limits, analysis_lane=True,
        )
        self.pipeline.live = self.live
        if self.source.kind == "mqtt":
            self.source.committed_until_s = _committed_until(self, storage)  # type: ignore[attr-defined]

    @property
    def attached(self) -> bool:
        """Whether ``attach`` created the pipeline."""
        return self._pipeline is not None

    @property
    def pipeline(self) -> Pipeline:
        """The structure's stages, wired (created by ``attach``, which comes before anything asks)."""
        if self._pipeline is None:
            raise RuntimeError(f"structure {self.id!r}: its pipeline is created by attach()")
        return self._pipeline

    # -- construction -----------------------------------------------------------------------

    def _clock(self, *, live: bool) -> SourceClock:
        src = self.settings.source
        return SourceClock(window_s=src.time_window_s, max_ahead_s=src.max_ahead_s or src.lateness_s, live=live,
                           future_tolerance_s=src.future_tolerance_s)

    # -- running ----------------------------------------------------------------------------

    def start(self) -> None:
        """Its lanes join the service's scheduler; its source starts."""
        self.pipeline.on_analysis_error = lambda exc: self._batch_failed(exc, what="analysis error; the chunk's windows skipped")
        self.pipeline.start_lane()
        scheduler = self.service.scheduler
        self.queue.on_put = scheduler.wake
        self._lanes = (_DataLane(self), _AnalysisLane(self))
        for lane in self._lanes:
            scheduler.add(lane)
        self._started = True
        if isinstance(self.source, IngestSource):  # its requests put their batches themselves
            self.source.start()
        else:  # a simulation, replay or followed file is stepped on the pool too
            self.source.start_on(scheduler)

    def step_data(self, most: int = 8) -> None:
        """The data lane's step: the batches waiting in the source's queue (at most ``most``, joined:
        ``Batch.joined``) through the pipeline, or its end."""
        pipeline = self.pipeline
        items: list[Any] = []
        while len(items) < most:
            try:
                items.append(self.queue.get_nowait())
            except queue.Empty:
                break
            if items[-1] is END:
                break
        ended = bool(items) and items[-1] is END
        batches = items[:-1] if ended else items
        if not batches:
            if ended or self._stopping:  # stopped, nothing left (a full queue may have kept its END out)
                self._end()
            return
        if pipeline.past_stop_deadline():
            for batch in batches:
                pipeline.set_batch_aside(batch)
        else:
            try:
                pipeline.process(Batch.joined(batches))
            except Exception as exc:
                # the joined batches went as one: each is counted as skipped (the loss is counted,
                # not hidden behind one error)
                self._batch_failed(exc, batches=len(batches))
            else:
                # None once a batch succeeds and nothing waits for the database
                self.pipeline_error = pipeline.storage_error
        if self.first_data_ns is None and pipeline.newest_ns is not None:
            # the pace's origin: the first batch, as the source's pacer held it when it made it (the
            # start-up before the first data, compiling and building models, is not lag; its wait
            # in the queue is)
            first = batches[0]
            self.first_data_ns = max((int(b.log_time_ns[-1]) for b in first.blocks if len(b)), default=pipeline.newest_ns)
            self.started_wall = time.time() - (time.monotonic() - first.received)
        self.service.notifier.wake()
        if ended:
            self._end()

    def _end(self) -> None:
        pipeline = self.pipeline
        try:
            pipeline.finish()
            self.pipeline_error = pipeline.storage_error
            left = pipeline.set_aside.describe()
            if left:
                log.warning("%s%s", f"structure {self.id}: " if self.service.fleet else "", left)
        except Exception as exc:
            self._batch_failed(exc, what="pipeline failed at the end of the source")
        finally:
            for lane in self._lanes:
                lane.finished = True
            self.service.notifier.wake()
            self._done.set()

    def _batch_failed(self, exc: Exception, what: str = "pipeline error on a batch; batch skipped", batches: int = 1) -> None:
        text = f"{type(exc).__name__}: {exc}"
        # the text before the count: a status read in between sees the count with its error
        self.pipeline_error = self.last_pipeline_error = text
        self.pipeline_errors += batches
        if batches > 1:
            what = f"pipeline error on {batches} joined batches; all {batches} skipped"
        # The same error on every batch would flood the log: its first time with the traceback.
        if self.pipeline_errors <= 3:
            log.exception("%s%s", f"structure {self.id}: " if self.service.fleet else "", what)
        else:
            log.error("%s%s: %s (%d batches failed so far)", f"structure {self.id}: " if self.service.fleet else "", what,
                      text, self.pipeline_errors)

    def untouched(self) -> tuple[int, tuple[str, str, str]] | None:
        """(samples, (id, kind, spec)) when the source delivered since it was last noted in the
        database (``Storage.touch_sources``, then ``touched(samples)``), else None."""
        samples = sum(self.pipeline.samples.values())
        if samples == self._touched_samples:
            return None
        return samples, (self.id, self.source.kind, self.settings.source.spec)

    def touched(self, samples: int) -> None:
        self._touched_samples = samples

    def wait(self, timeout: float | None = None) -> bool:
        return self._done.wait(timeout)

    def skip(self) -> None:
        """The service stopped before this structure started: it is done without running."""
        self.source.state = "stopped"
        self._done.set()

    @property
    def done(self) -> bool:
        return self._done.is_set()

    @property
    def started(self) -> bool:
        return self._started

    def stop_source(self) -> None:
        """Stop the source; the backlog is estimated and analysed for ``stop_drain_s`` more, the rest set aside."""
        if self._pipeline is not None:
            self._pipeline.stop_deadline = time.monotonic() + self.settings.stop_drain_s
        self.source.stop()  # returns once no request of an ingest source is putting a batch any more
        self._stopping = True

    # -- what it reports --------------------------------------------------------------------

    def health_reasons(self) -> list[str]:
        reasons: list[str] = []
        if self.pipeline_error is not None:
            reasons.append(f"pipeline: {self.pipeline_error}")
        if self.pipeline.storage_error is not None and self.pipeline.storage_error != self.pipeline_error:
            reasons.append(self.pipeline.storage_error)
        if self.pipeline.analysis_error is not None and self.pipeline.analysis_error != self.pipeline_error:
            reasons.append(f"analysis: {self.pipeline.analysis_error}")
        reasons.extend(self.pipeline.health_problems())
        src = self.source
        if src.state == "failed":
            reasons.append(f"source {src.id} failed: {src.error}")
        reasons.extend(src.health_problems())
        return reasons

    def lag_s(self, now: float | None = None) -> float | None:
        """How far the processed data is behind its pace (see ``StructureSummaryDocument.lag_s``)."""
        newest = self.pipeline.newest_ns
        if newest is None:
            return None
        now = time.time() if now is None else now
        if self.kind in ("follow", "ingest", "mqtt"):
            return round(now - newest / 1e9, 3)
        if self.speed is None or self.started_wall is None or self.first_data_ns is None:
            return None
        if self.done:  # the source ended: nothing more is due
            return 0.0
        return round(self.speed * (now - self.started_wall) - (newest - self.first_data_ns) / 1e9, 3)

    def state(self) -> tuple[str, str | None]:
        src = self.source
        if src.state == "failed":
            return "failed", src.error
        reasons = self.health_reasons()
        if self.done:
            # what was wrong with the data (a damaged file read up to the damage) stays shown
            problems = reasons or list(src.problems)
            return ("finished" if src.state == "finished" else "stopped"), problems[-1] if problems else None
        if src.state in ("starting", "waiting for the file"):
            return "starting", reasons[0] if reasons else None
        if reasons:
            return "degraded", reasons[0]
        return "running", None

    def summary(self) -> StructureSummaryDocument:
        state, error = self.state()
        return StructureSummaryDocument(id=self.id, kind=self.source.kind, state=state, error=error,
                                        data_time_s=None if self.pipeline.newest_ns is None else self.pipeline.newest_ns / 1e9,
                                        lag_s=self.lag_s(), windows=self.pipeline.windows_committed,
                                        active_alarms=dict(self.pipeline.committed_alarms))


def _committed_until(structure: "Structure", storage: Storage) -> Callable[[], float | None]:
    """The data time (UNIX s) before which ``structure``, resumed from its committed state, needs
    no sample again (None: nothing committed yet): it analyses from the window after the last one
    committed, and a resumed estimator skips the windows of its first rest_end + warmup_s (its
    filter converging), so its data must begin that much before."""
    resumed = (storage.load_state(structure.id) or {}).get("last_window_start_s")
    a = structure.settings.engine_config()
    step_s = a.window_s * (1 - a.overlap)
    warmup_s = structure.settings.estimator.warmup_s
    pipeline = structure.pipeline

    def until() -> float | None:
        last = pipeline.commits.last_window
        start = last.start_s if last is not None else resumed
        calibration = pipeline.estimate.estimator.calibration
        if start is None or calibration is None:
            return None
        return float(start) + step_s - float(calibration.rest_end) - warmup_s

    return until


def _make_source(self: Structure) -> Source:
    """The source of a structure's settings (a ServiceError naming what is wrong)."""
    s = self.settings
    src = s.source
    kind = src.kind
    truth = s.dashboard.enabled and not self.service.fleet  # the truth shape is drawn for one structure only
    rig_override = None
    if src.rig:
        try:
            rig_override = load_rig(src.rig)
        except (OSError, ValueError) as exc:
            raise ServiceError(f"source.rig: {exc}") from None
    try:
        if kind == "sim":
            return SimSource(src.id or "sim", self.queue, s, raw=s.archive.enabled and s.archive.raw != "never", truth=truth,
                             rig=rig_override)
        if kind in ("replay", "follow"):
            path = Path(src.path or "")
            source = FileSource(src.id or path.stem, self.queue, s, follow=kind == "follow", rig=rig_override, truth=truth)
            if source.rig is None:
                if kind == "follow":
                    # The model needs the rig: without source.rig, wait for the file's rig.json
                    # (``shm serve`` serves the API meanwhile and retries; see RigPending).
                    if source.wait_for_rig(timeout=self.service.rig_wait_s) is None:
                        raise RigPending(f"follow: waiting for {path} and its rig.json "
                                         "(or give the rig with source.rig)")
                else:
                    raise ServiceError(f"{path}: no rig.json")
            return source
        if kind == "ingest":
            from ...rig_layouts import default_rig

            rig = rig_override or default_rig(src.layout)
            return IngestSource(src.id or "ingest", self.queue, rig, max_messages=s.server.max_ingest_messages,
                                wait_s=s.server.ingest_wait_s, raw=s.archive.enabled and s.archive.raw != "never",
                                clock=self._clock(live=True), limits=src.limits)
        if kind == "mqtt":
            from ...rig_layouts import default_rig
            from ..sources._mqtt import MqttSource

            return MqttSource(src.id or "mqtt", self.queue, rig_override or default_rig(src.layout), s.mqtt,
                              max_messages=s.server.max_ingest_messages,
                              raw=s.archive.enabled and s.archive.raw != "never", clock=self._clock(live=True),
                              limits=src.limits, password=s.mqtt.password())
    except (RecordingError, FileNotFoundError, ValueError) as exc:
        raise ServiceError(str(exc)) from None
    raise ServiceError(f"unknown source {src.spec!r}")


class _FailedStructure:
    """A structure of a fleet whose start failed (a missing file, a bad rig): listed with its
    error; the others run."""

    def __init__(self, structure_id: str, kind: str, error: str) -> None:
        self.id = structure_id
        self.kind = kind
        self.error = error
        self.done = True
        self.started = False

    def start(self) -> None:
        pass

    def stop_source(self) -> None:
        pass

    def wait(self, timeout: float | None = None) -> bool:
        return True

    def health_reasons(self) -> list[str]:
        return [f"failed to start: {self.error}"]

    def summary(self) -> StructureSummaryDocument:
        return StructureSummaryDocument(id=self.id, kind=self.kind, state="failed", error=self.error)


def _virtual_loads(rig: RigDescription, model: Any) -> tuple[Any, Any] | None:
    """(analytics.VirtualLoads of the rig's hot spots and a 16-station grid, b of states) for the live view."""
    from analytics import BiaxialVirtualLoads, VirtualLoads

    try:
        if getattr(model, "units_xi", None) is not None:  # both planes: each station at its point of the section
            layout = model.state_layout
            return (BiaxialVirtualLoads.from_rig_biaxial(rig, model.units.curvature, model.units_xi.curvature),
                    lambda x: (layout.b_of(x), layout.b_xi_of(x)))
        return VirtualLoads.from_rig(rig, model.units.curvature), model.state_layout.b_of
    except ValueError as exc:  # never stops the service: the live view goes without loads
        log.warning("no virtual loads in the live view: %s", exc)
        return None


def _check_sensor_counts(rig: RigDescription, est: Any) -> None:
    """A count set in the configuration must exist on the rig (the defaults are capped to it)."""
    from ...processing.estimation import sensor_count_problem

    for kind in ("imus", "tofs", "gauges"):
        if kind in est.model_fields_set:
            problem = sensor_count_problem(rig, kind, getattr(est, kind), modes=est.modes)
            if problem:
                raise ServiceError(f"estimator.{kind} = {getattr(est, kind)}: {problem}")


class SingleStructureView:
    """What a service of one structure answers of it (``primary``: its structure; a fleet's raises
    ``NotSingleStructure``)."""

    @property
    def primary(self) -> Structure:
        raise NotImplementedError

    # the single structure's parts, read through (``ReadThrough``)
    source: ReadThrough[Source] = ReadThrough("primary")
    pipeline: ReadThrough[Pipeline] = ReadThrough("primary")
    queue: ReadThrough[queue.Queue] = ReadThrough("primary")
    model: ReadThrough[Any] = ReadThrough("primary")
    rig: ReadThrough[RigDescription] = ReadThrough("primary")
    thresholds: ReadThrough[ThresholdsDocument] = ReadThrough("primary")
    model_document: ReadThrough[ModelDocument] = ReadThrough("primary")
    pipeline_error: ReadThrough[str | None] = ReadThrough("primary")
    pipeline_errors: ReadThrough[int] = ReadThrough("primary")
    last_pipeline_error: ReadThrough[str | None] = ReadThrough("primary")
