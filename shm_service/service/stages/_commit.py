"""The commit stage of a structure's pipeline: each window's transaction (trend rows, the engine's
state, alarm changes, a new baseline or calibration) written in window order, waiting in memory
while the database is unavailable, and what a written window makes visible (its alarms, the
dashboard's window)."""

from __future__ import annotations

import logging
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

from pydantic import BaseModel, ConfigDict, Field

from analytics import WindowResult
from contract import (
    AlarmDocument,
    ChartDocument,
    CurvatureDocument,
    FlagDocument,
    LoadsWindowDocument,
    LocationDocument,
    ModeDocument,
    TrendRow,
    WindowDocument,
)

from ..alarms._changes import clear_changes
from ._analysis import LazySpectrum, WindowOutput
from ..storage._storage import Storage, WindowCommit, is_transient

__all__ = ["CommitSettings", "CommitStage", "PendingCommit", "window_document"]

log = logging.getLogger("shm.serve.pipeline")


class CommitSettings(BaseModel):
    """How windows wait for the database."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    retry_s: float = Field(
        10.0, ge=0, le=3600, description="how long a write is retried on a transient database error (locked by another "
        "process, disk full, I/O error) before the window waits in memory for the next attempt, s")
    max_pending: int = Field(20_000, ge=1, description="windows kept waiting with their trend rows; beyond, the oldest "
                             "waiting windows' rows are dropped (their alarms and state kept)")


@dataclass
class PendingCommit:
    """A window's transaction not yet written (the database was unavailable), with the alarm
    state it leads to and what goes to the dashboard once it is written."""

    commit: WindowCommit
    raised: dict[str, str]  # chart -> level of the alarms standing once it is written
    document: WindowDocument | None = None
    spectrum: LazySpectrum | None = None


class CommitStage:
    """Writes one structure's windows in their order; ``committed_alarms`` is the alarm state the
    database holds (the engine's alarm logic runs ahead of it while windows wait).
    ``on_written(pending)`` is called for each window once written (the outputs)."""

    def __init__(self, storage: Storage, source_id: str, committed_alarms: dict[str, str],
                 settings: CommitSettings | None = None,
                 on_written: Callable[[PendingCommit], None] | None = None) -> None:
        self.settings = settings or CommitSettings()
        self.storage = storage
        self.source_id = source_id
        self.committed_alarms = dict(committed_alarms)
        self.pending: deque[PendingCommit] = deque()
        self.on_written = on_written
        self.storage_error: str | None = None  # set while windows wait for the database
        self.storage_errors = 0  # commits that failed (and wait to be retried)
        self.trend_rows_dropped = 0  # rows of waiting windows dropped beyond max_pending (their alarms kept)
        self.windows_committed = 0
        # the lease's fencing token of a node's structure (None: no nodes): each window's transaction checks it
        self.fencing_token: int | None = None
        self.last_window: WindowDocument | None = None
        self.last_loads: LoadsWindowDocument | None = None  # of the newest written window

    def add(self, window: WindowOutput, *, monitor_state: dict, raised: dict[str, str], baseline: dict | None,
            calibration: dict | None) -> None:
        """Queue ``window``'s transaction and write what waits."""
        res = window.result
        charts = list(res.charts)
        document = window_document(self.source_id, res, window.rows, charts)
        commit = WindowCommit(
            source=self.source_id, window_start_s=window.start_s, data_time_s=res.end_s, rows=window.rows,
            monitor_state=monitor_state, calibration=calibration, alarm_changes=window.alarm_changes, baseline=baseline,
            loads=window.loads, fencing_token=self.fencing_token,
        )
        self.pending.append(PendingCommit(commit, raised, document, window.spectrum))
        if len(self.pending) > self.settings.max_pending:
            oldest = self.pending[0]
            self.trend_rows_dropped += len(oldest.commit.rows)
            oldest.commit.rows = []
        self.flush()

    def clear_for_new_baseline(self, at_s: float, window_start_s: float, state: dict) -> None:
        """A new baseline: every chart starts over and every active alarm of the source clears
        (those stored and those raised by windows still waiting for the database); ``state`` is
        the engine state to store with it (the monitor's None: it starts over)."""
        # the fatigue alarms stay: a new modal baseline does not change what the hot spots consumed
        active = {a.chart: a for a in self.storage.alarms(state="active") if a.source == self.source_id and a.kind != "fatigue"}
        for pending in self.pending:
            for c in pending.commit.alarm_changes:
                if c.kind == "fatigue":
                    continue
                if c.action == "raise":
                    active[c.chart] = AlarmDocument(id=1, source=self.source_id, chart=c.chart, kind=c.kind, mode=c.mode,
                                                    level=c.level, state="active", raised_at_s=c.at_s, message=c.message)
                elif c.action == "clear":
                    active.pop(c.chart, None)
        changes = clear_changes(active.values(), at_s)
        commit = WindowCommit(self.source_id, window_start_s, at_s, [], {**state, "monitor": None}, None, changes,
                              fencing_token=self.fencing_token)
        self.pending.append(PendingCommit(commit, {}))
        self.flush()

    def flush(self, retry_s: float | None = None) -> bool:
        """Write the waiting windows in their order. Alarm state changes take effect (and reach
        the dashboard) only once their window is written; a transient database error leaves the
        window waiting for the next attempt (the storage already retried it for ``retry_s``).
        Returns True when nothing waits any more."""
        while self.pending:
            pending = self.pending[0]
            try:
                self.storage.commit_window(pending.commit, retry_s=self.settings.retry_s if retry_s is None else retry_s)
            except Exception as exc:
                if not is_transient(exc):
                    # Not a passing fault but a bad transaction: retrying it would stop every later window.
                    self.pending.popleft()
                    raise
                self.storage_errors += 1
                self.storage_error = (f"storage: {exc}; {len(self.pending)} window(s) wait to be written "
                                      "(retried with every batch)")
                if self.storage_errors <= 3 or self.storage_errors % 100 == 0:
                    log.error("%s", self.storage_error)
                return False
            self.pending.popleft()
            self.committed_alarms = dict(pending.raised)
            if pending.document is not None:
                self.windows_committed += 1
                self.last_window = pending.document
            if pending.commit.loads is not None:
                self.last_loads = pending.commit.loads
            if self.on_written is not None:
                self.on_written(pending)
        self.storage_error = None
        return True


def window_document(source: str, res: WindowResult, rows: list[TrendRow] | tuple = (),
                    charts: list[ChartDocument] | tuple = ()) -> WindowDocument:
    """The window as the dashboard shows it: the engine's result with each mode's estimate
    (frequency, damping and their 1σ, MPC, MAC), its chart, and the curvature change along η."""
    damping = {row.mode: row.damping_ratio for row in rows}
    by_mode = {c.mode: c for c in charts if c.kind == "frequency"}
    modes = []
    for i, e in enumerate(res.estimates):
        chart = by_mode.get(e.mode)
        modes.append(ModeDocument(
            mode=e.mode, unit=e.unit, frequency_hz=e.frequency_hz, amplitude=e.amplitude, confidence=round(e.confidence, 4),
            damping_ratio=damping.get(e.mode, e.damping_ratio), score_sigma=res.frequency_scores[i] if i < len(res.frequency_scores) else None,
            level=None if chart is None else chart.level, frequency_std_hz=e.frequency_std_hz, damping_std=e.damping_std,
            mpc=e.mpc, mac=e.mac, method=e.method, track=e.track,
        ))
    curvature = None
    if res.curvature is not None:
        c = res.curvature
        curvature = CurvatureDocument(index=[float(v) for v in c.index], total=float(c.total), eta_m=float(c.eta_m),
                                      third=c.third, score_sigma=res.curvature_score)
    return WindowDocument(
        source=source, start_s=res.start_s, end_s=res.end_s, kind=res.kind, trusted=res.trusted,
        temperature_c=res.temperature_c, modes=modes, charts=list(charts), curvature=curvature,
        flags=[FlagDocument(**f) for f in res.flags],
        location=None if res.location is None else LocationDocument(**res.location.as_dict()),
    )
