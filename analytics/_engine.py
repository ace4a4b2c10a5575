"""The one engine: a window loop in data time around :class:`analytics.ModalMonitor`.

``shm analyze`` (a whole recording at once), ``shm serve`` (chunks as they arrive) and
``shm reprocess`` feed the same :class:`MonitoringEngine`, so they analyse the same windows
with the same code and raise the same alarms. Windows are aligned to multiples of the step in
data time (UNIX time for the contract's recordings), so a replay of a period gives the windows
the live service had, whatever the chunking: a window is cut when b reaches its last sample,
resampled onto the window's own grid (linear interpolation; the estimator's samples usually sit
on it) and handed to the monitor with the support displacement and temperature of the window.

Times are handled as an integer-nanosecond origin plus float seconds relative to it, so the
grid of a window is computed to ~1e-13 s whatever the magnitude of UNIX time.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from ._loads_monitor import LoadsMonitor
from ._monitor import ModalMonitor, WindowResult
from ._usability import usability_document, window_rejection
from ._validate import as_signal

__all__ = ["EngineWindow", "MonitoringEngine"]

_NS = 1_000_000_000


@dataclass(frozen=True)
class EngineWindow:
    """One analysed window: its result, its start in data time (ns, a multiple of the step) and
    its data on the window's grid (b (n, Γ), support displacement (n,) or None)."""

    result: WindowResult
    start_ns: int
    b: np.ndarray
    support: np.ndarray | None
    loads: object | None = None  # contract.LoadsWindowDocument of the hot spots, when the engine has loads
    loads_events: tuple = ()  # the fatigue charts' AlarmEvents of this window


class _Series:
    """Time-stamped chunks (t (n,), values (n, k)), trimmed from the front."""

    def __init__(self) -> None:
        self.parts: deque[tuple[np.ndarray, np.ndarray]] = deque()

    def add(self, t: np.ndarray, v: np.ndarray) -> None:
        if len(t):
            if self.parts and t[0] <= self.parts[-1][0][-1]:
                keep = t > self.parts[-1][0][-1]  # a repeated or late stamp: the first one counts
                t, v = t[keep], v[keep]
                if not len(t):
                    return
            self.parts.append((t, v))

    def trim(self, before: float) -> None:
        while len(self.parts) > 1 and self.parts[0][0][-1] < before:
            self.parts.popleft()

    def span(self, lo: float, hi: float) -> tuple[np.ndarray, np.ndarray] | None:
        sel = [p for p in self.parts if p[0][-1] >= lo and p[0][0] <= hi]
        if not sel:
            return None
        t = np.concatenate([p[0] for p in sel]) if len(sel) > 1 else sel[0][0]
        v = np.concatenate([p[1] for p in sel]) if len(sel) > 1 else sel[0][1]
        k0, k1 = int(np.searchsorted(t, lo, side="left")), int(np.searchsorted(t, hi, side="right"))
        return t[k0:k1], v[k0:k1]

    @property
    def newest(self) -> float | None:
        return float(self.parts[-1][0][-1]) if self.parts else None

    @property
    def oldest(self) -> float | None:
        return float(self.parts[0][0][0]) if self.parts else None

    def next_time(self, lo: float) -> float | None:
        """The first sample time at or after ``lo`` (None: none held)."""
        for t, _ in self.parts:
            if t[-1] >= lo:
                return float(t[int(np.searchsorted(t, lo, side="left"))])
        return None


class MonitoringEngine:
    """Windows of ``monitor.config.window_s`` every ``window_s·(1 − overlap)``, aligned in data
    time, analysed by ``monitor``.

    Parameters
    ----------
    monitor : ModalMonitor
        The per-window analytics (its state carries on across windows and restarts).
    origin_ns : int
        Data time (ns) that the times given to :meth:`add` count from (UNIX ns of the estimator's
        epoch in ``shm serve``, of the recording's first message in ``shm analyze``).
    time_zero_ns : int
        Data time (ns) that the reported window times count from (0: UNIX seconds; the
        recording's first sample: seconds into the recording).
    not_before_ns : int, optional
        Windows starting earlier are not analysed (the estimator converging); counted.
    next_start_ns : int, optional
        Start of the next window (resuming after a restart); default: the first multiple of the
        step at or after the first sample.
    min_coverage : float
        A window needs samples over this fraction of its length, else it is skipped (counted).
    loads : LoadsMonitor, optional
        The hot spots' loads and fatigue: each window's first step of samples (every sample once)
        is counted; a failure there is counted (``loads_errors``) and never stops the modal path.

    Raises
    ------
    ValueError
        For a window not holding 16 samples, a step that is not a whole number of nanoseconds,
        or a coverage outside (0, 1].
    """

    def __init__(self, monitor: ModalMonitor, *, origin_ns: int = 0, time_zero_ns: int = 0, not_before_ns: int | None = None,
                 next_start_ns: int | None = None, min_coverage: float = 0.8, loads: LoadsMonitor | None = None) -> None:
        if not isinstance(monitor, ModalMonitor):
            raise ValueError(f"monitor must be a ModalMonitor, got {type(monitor).__name__}")
        if not 0 < min_coverage <= 1:
            raise ValueError(f"{min_coverage=} must be in (0, 1]")
        self.monitor = monitor
        c = monitor.config
        self.fs = monitor.fs
        self.n = int(round(c.window_s * self.fs))
        if self.n < 16:
            raise ValueError(f"config.window_s={c.window_s} holds {self.n} samples at {self.fs:g} Hz; needs 16")
        step = c.window_s * (1 - c.overlap)
        self.step_ns = int(round(step * _NS))
        if self.step_ns <= 0 or abs(self.step_ns - step * _NS) > 1e-3:
            raise ValueError(f"the window step {step} s must be a positive whole number of nanoseconds")
        self.origin_ns, self.time_zero_ns = int(origin_ns), int(time_zero_ns)
        self.not_before_ns = None if not_before_ns is None else int(not_before_ns)
        self.next_start_ns = None if next_start_ns is None else int(next_start_ns)
        self.min_coverage = float(min_coverage)
        if loads is not None and not isinstance(loads, LoadsMonitor):
            raise ValueError(f"loads must be a LoadsMonitor, got {type(loads).__name__}")
        self.loads = loads
        self.loads_errors = 0
        self.b = _Series()
        self.temperature = _Series()
        self.gauges: dict[str, _Series] = {}  # measured strain by gauge name: the loads' band
        self.windows = 0
        self.skipped_incomplete = 0
        self.skipped_warmup = 0
        self.usable = 0  # analysed windows that carry an identified mode
        self.rejected: dict[str, int] = {}  # analysed windows that do not, by reason (analytics.window_rejection)
        self._gamma: int | None = None
        self._with_support: bool | None = None

    # -- time ---------------------------------------------------------------------------------
    def _rel(self, ns: int) -> float:
        """Data time ns as seconds relative to the origin (exact integer difference, one rounding)."""
        return (ns - self.origin_ns) / _NS

    def report_time(self, ns: int) -> float:
        """Data time ns as the reported seconds (relative to time_zero_ns)."""
        return (ns - self.time_zero_ns) / _NS

    # -- data ---------------------------------------------------------------------------------
    def add(self, t: object, b: object, *, support: object | None = None,
            temperature: tuple[object, object] | None = None,
            gauges: dict[str, tuple[object, object]] | None = None) -> list[EngineWindow]:
        """Feed samples; returns the windows they complete, in order.

        t : (n,) s relative to ``origin_ns``, increasing; b : (n, Γ); support : (n,) support
        displacement (m) on the same times, or None; temperature : (times (m,) s relative to the
        origin, values (m,) °C) or None (temperature samples may run ahead of b); gauges : measured
        strain by gauge name, (times s relative to the origin, values m/m), for the loads' band."""
        for name, (gt, gv) in (gauges or {}).items():
            tt = as_signal(f"gauge {name} times", gt, min_len=1, ndim=(1,))
            tv = np.asarray(gv, dtype=float).reshape(-1)
            if tt.size != tv.size:
                raise ValueError(f"gauge {name} has {tt.size} times and {tv.size} values")
            self.gauges.setdefault(name, _Series()).add(tt, tv[:, None])
        if temperature is not None:
            tt = as_signal("temperature times", temperature[0], min_len=1, ndim=(1,))
            tv = as_signal("temperature values", temperature[1], min_len=1, ndim=(1,))
            if tt.size != tv.size:
                raise ValueError(f"temperature has {tt.size} times and {tv.size} values")
            self.temperature.add(tt, tv[:, None])
        tb = np.asarray(t, dtype=float)
        if tb.size == 0:
            return []
        tb = as_signal("t", tb, min_len=1, ndim=(1,))
        B = as_signal("b", b, min_len=1, ndim=(2,))
        if B.shape[0] != tb.size:
            raise ValueError(f"b has {B.shape[0]} samples, t has {tb.size}")
        if tb.size > 1 and np.any(np.diff(tb) <= 0):
            raise ValueError("t must be strictly increasing")
        if self._gamma is None:
            self._gamma = B.shape[1]
        elif B.shape[1] != self._gamma:
            raise ValueError(f"b has {B.shape[1]} columns, earlier chunks {self._gamma}")
        has_support = support is not None
        if self._with_support is None:
            self._with_support = has_support
        if has_support != self._with_support:
            raise ValueError("support must be given with every chunk or with none")
        if has_support:
            d = as_signal("support", support, min_len=1, ndim=(1,))
            if d.size != tb.size:
                raise ValueError(f"support has {d.size} samples, t has {tb.size}")
            B = np.column_stack([B, d])
        self.b.add(tb, B)
        return self._cut()

    def _cut(self) -> list[EngineWindow]:
        newest = self.b.newest
        if newest is None:
            return []
        if self.next_start_ns is None:
            first_ns = self.origin_ns + int(round(self.b.oldest * _NS))
            self.next_start_ns = -(-first_ns // self.step_ns) * self.step_ns  # ceil to the step
        out: list[EngineWindow] = []
        while True:
            start_ns = self.next_start_ns
            start = self._rel(start_ns)
            last = start + (self.n - 1) / self.fs
            if newest < last:
                break
            if self._skip_gap(start_ns, start):
                continue
            self.next_start_ns = start_ns + self.step_ns
            if self.not_before_ns is not None and start_ns < self.not_before_ns:
                self.skipped_warmup += 1
                continue
            w = self._window(start_ns, start)
            if w is not None:
                out.append(w)
        keep = self._rel(self.next_start_ns)
        self.b.trim(keep - 2.0 / self.fs)
        self.temperature.trim(keep - 600.0)
        for series in self.gauges.values():
            series.trim(keep - 2.0 / self.fs)
        return out

    def _skip_gap(self, start_ns: int, start: float) -> bool:
        """Skip at once the windows of a gap in the data (no sample in the window and its margins),
        counted as one by one (warm-up, else incomplete): a clock that jumped years ahead costs
        one step, not one per window of the years between."""
        after = self.b.next_time(start - 2.0 / self.fs)
        if after is None or after <= start + (self.n + 1) / self.fs:
            return False
        # windows j = 0, 1, ... whose end and margin lie before ``after`` hold no sample
        room_ns = self.origin_ns + int(round((after - (self.n + 1) / self.fs) * _NS)) - start_ns
        k = max(1, -(-room_ns // self.step_ns))
        warm = 0
        if self.not_before_ns is not None and start_ns < self.not_before_ns:
            warm = min(k, -(-(self.not_before_ns - start_ns) // self.step_ns))
        self.skipped_warmup += warm
        self.skipped_incomplete += k - warm
        self.next_start_ns = start_ns + k * self.step_ns
        return True

    def _window(self, start_ns: int, start: float) -> EngineWindow | None:
        end = start + self.n / self.fs
        span = self.b.span(start - 2.0 / self.fs, end + 1.0 / self.fs)
        if span is None:
            self.skipped_incomplete += 1
            return None
        t, v = span
        inside = int(np.count_nonzero((t >= start) & (t < end)))
        if inside < self.min_coverage * self.n or t[0] > start + 1.0 / self.fs:
            self.skipped_incomplete += 1
            return None
        local = t - start
        grid = np.arange(self.n) / self.fs
        X = np.column_stack([np.interp(grid, local, v[:, k]) for k in range(v.shape[1])])
        B = X[:, : self._gamma]
        d = X[:, self._gamma] if self._with_support else None
        temp = self.temperature.span(start, end)
        T = None
        if temp is not None and len(temp[0]) and temp[0][0] < end:
            inside_t = temp[0] < end
            if np.any(inside_t):
                T = float(np.mean(temp[1][inside_t, 0]))
        if T is None:
            before = self.temperature.span(start - 600.0, start)
            if before is not None and len(before[0]):
                T = float(before[1][-1, 0])
        times = self.report_time(start_ns) + grid
        try:
            res = self.monitor.process_window(times, B, T, d)
        except ValueError:
            self.skipped_incomplete += 1
            return None
        self.windows += 1
        reason = window_rejection(res, self.monitor.config)
        if reason is None:
            self.usable += 1
        else:
            self.rejected[reason] = self.rejected.get(reason, 0) + 1
        loads, events = None, ()
        if self.loads is not None:
            n_step = min(self.n, int(round(self.step_ns * self.fs / _NS)))
            try:
                measured = self._gauges_on(start, grid[:n_step]) if self.loads.gauges else None
                loads = self.loads.process_window(float(times[0]), B[:n_step], self.fs, T, measured)
                events = tuple(self.loads.events)
            except ValueError:
                self.loads_errors += 1
        return EngineWindow(res, start_ns, B, d, loads, events)

    def _gauges_on(self, start: float, grid: np.ndarray) -> dict[str, np.ndarray]:
        """The measured strain of each gauge that covers the grid (s after ``start``), interpolated onto it."""
        out = {}
        for name, series in self.gauges.items():
            span = series.span(start - 2.0 / self.fs, start + grid[-1] + 2.0 / self.fs)
            if span is None or len(span[0]) < 2 or span[0][0] > start + 1.0 / self.fs or span[0][-1] < start + grid[-1] - 1.0 / self.fs:
                continue
            out[name] = np.interp(grid, span[0] - start, span[1][:, 0])
        return out

    # -- persistence ---------------------------------------------------------------------------
    def reset(self, monitor: ModalMonitor) -> None:
        """Continue the window loop with a new monitor (a new baseline is learnt)."""
        if not isinstance(monitor, ModalMonitor):
            raise ValueError(f"monitor must be a ModalMonitor, got {type(monitor).__name__}")
        self.monitor = monitor

    def usability(self) -> dict:
        """The windows so far: usable, each rejection reason counted (the skipped ones too) and, when
        none is usable, why and what to change (:func:`analytics.usability_document`)."""
        return usability_document(self.usable, {"warmup": self.skipped_warmup, "incomplete": self.skipped_incomplete, **self.rejected})

    @property
    def step_s(self) -> float:
        return self.step_ns / _NS

    @property
    def window_s(self) -> float:
        return self.n / self.fs

    def expected_windows(self, duration_s: float) -> int:
        """Windows a record of ``duration_s`` seconds holds at most."""
        return max(0, int(math.floor((duration_s - self.window_s) / self.step_s)) + 1)
