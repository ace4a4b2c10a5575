"""The outputs of a structure's pipeline: its recording (the raw samples and the estimates) and
its live ring (what the dashboard and ``/live`` read through the port; nothing is pushed).
Whatever the live ring raises is counted by its guard and never stops the pipeline."""

from __future__ import annotations

import logging
from collections import deque
from typing import Any, Protocol

import numpy as np


from contract import estimate_payloads
from estimator import FilterOutput, ImmsModel

from ...recording import encode_payloads_json
from ._archive import Archive, ArchiveSettings
from ..alarms._sinks import SinkGuard
from ..storage._storage import Storage

__all__ = ["LiveRingLike", "OutputStage"]

log = logging.getLogger("shm.serve.pipeline")


class LiveRingLike(Protocol):
    """A structure's live ring (``runtime._live.LiveRing``): takes every batch's estimates (``t_s`` (n,), ``x`` (n, nx))
    and, from a simulated source, a lookup of the true deflection at given times."""

    def add(self, t_s: np.ndarray, x: np.ndarray, truth: Any = None) -> None: ...


class OutputStage:
    """The recording and live ring of one structure."""

    def __init__(self, model: ImmsModel, source_id: str, storage: Storage, settings: ArchiveSettings | None = None, *,
                 archive: Archive | None = None, sink_guard: SinkGuard | None = None, record_raw: bool = False) -> None:
        self.settings = s = settings or ArchiveSettings()
        self.model = model
        self.source_id = source_id
        self.storage = storage
        self.archive = archive
        # whether the incoming samples are recorded is the structure's to say ([archive] raw and its source's kind)
        self.archive_raw = record_raw and archive is not None
        self.archive_estimates = s.estimates and archive is not None
        self.live: LiveRingLike | None = None  # set by the service: the batches' estimates for a live view
        # A failing live ring is counted and logged once per kind; it never stops a batch.
        self.sink_guard = sink_guard or SinkGuard("dashboard", log)
        self.truth: deque[tuple[np.ndarray, np.ndarray]] = deque(maxlen=8)
        self._estimate_maps: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None

    def raw(self, messages: list[tuple[str, int, bytes, int]] | None) -> None:
        if self.archive_raw and messages and self.archive is not None:
            self.archive.write_many(messages)

    def maybe_flush(self) -> None:
        if self.archive is not None:
            self.archive.maybe_flush()

    def close(self) -> None:
        if self.archive is not None:
            self.archive.close()

    def estimates(self, epoch_ns: int, t_abs: np.ndarray, out: FilterOutput) -> None:
        """A step's estimates (``t_abs`` UNIX s; ``out.t`` s after ``epoch_ns``): recorded and to the live ring."""
        if self.archive_estimates:
            self._archive_estimates(epoch_ns, out)
        if self.live is not None:  # the structure's live ring: keeps them (decimated) only while watched
            self.sink_guard.call("live", self.live.add, t_abs, out.x, self._truth_at if self.truth else None)

    def _truth_at(self, t_abs: np.ndarray) -> list[np.ndarray | None]:
        """The simulation's true deflection at the stations nearest each time (UNIX s; None farther than 50 ms)."""
        tt = np.concatenate([t for t, _ in self.truth])
        defl = np.concatenate([d for _, d in self.truth])
        target = np.round(np.asarray(t_abs, dtype=float) * 1e9).astype(np.int64)
        k = np.clip(np.searchsorted(tt, target), 0, len(tt) - 1)
        return [defl[j] if abs(int(tt[j]) - int(want)) < 50_000_000 else None for j, want in zip(k, target)]

    def _archive_estimates(self, epoch_ns: int, out: FilterOutput) -> None:
        if self.archive is None:  # archive_estimates says there is one
            return
        k = self.settings.estimate_decimation
        t, x, P = out.t[::k], out.x[::k], out.P_diag[::k]
        if not len(t):
            return
        layout = self.model.state_layout
        if self._estimate_maps is None:  # b → tip deflection, deflection and curvature at the stations
            m = self.model
            self._estimate_maps = (m.tip_row(), m.units.shape(m.stations).T, m.units.curvature(m.stations).T)
        tip, shape, curvature = self._estimate_maps
        b = layout.b_of(x)
        xi = None
        if self.model.biaxial:  # the ξ plane's keys too: a biaxial rig's reader expects them
            m, b_xi = self.model, layout.b_xi_of(x)
            units = m.units_xi
            assert units is not None, "a biaxial model has the ξ plane's unit deformations"
            xi = (b_xi @ units.shape(m.rig.beam.length), b_xi @ units.shape(m.stations).T, b_xi @ units.curvature(m.stations).T)
        rows = estimate_payloads(layout, x, P, b @ tip, b @ shape, b @ curvature, xi)
        stamps = epoch_ns + np.round(t * 1e9).astype(np.int64)
        self.archive.write_estimates(stamps, encode_payloads_json(rows))
