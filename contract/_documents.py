"""Typed documents exchanged at the seams: pipeline → storage, HTTP API, dashboard, notifiers.

Every document is a frozen pydantic model that refuses unknown keys, so a field added on one
side and not the other fails loudly instead of drifting. Measured quantities that may be
undefined (no peak found, no baseline yet) are ``None``; non-finite numbers become ``None`` on
the way in, so every document serialises to strict JSON.

Times are UNIX seconds (``*_s``) unless a name says otherwise; units are 1-based (b1 is unit
deformation 1) and modes are numbered as in :class:`contract.ModeMap`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Annotated, Any, Final, Literal

import numpy as np
from pydantic import AfterValidator, BaseModel, BeforeValidator, ConfigDict, Field, model_validator

from ._payloads import PAYLOAD_FIELDS
from ._state import StateLayout

__all__ = [
    "CURVATURE_CHART",
    "SENSOR_STATES",
    "AidingChannelDocument",
    "AlarmCountsDocument",
    "AlarmDocument",
    "AlarmEvent",
    "AlarmEventDocument",
    "AlarmLevel",
    "AlarmsDocument",
    "ArchiveStatusDocument",
    "BaselineModeDocument",
    "BaselineRequestDocument",
    "BaselineStatusDocument",
    "ChartDocument",
    "ChartKind",
    "ChartLevelsDocument",
    "CurvatureDocument",
    "DegradedImuDocument",
    "EstimateDocument",
    "ErrorDocument",
    "FATIGUE_CONDITIONS",
    "FatigueDocument",
    "HotSpotLoadsDocument",
    "LoadsWindowDocument",
    "StationLoadsDocument",
    "EstimatorStatusDocument",
    "FlagDocument",
    "HealthDocument",
    "IngestErrorDocument",
    "IngestResultDocument",
    "LastEstimateDocument",
    "LiveEstimatesDocument",
    "Level",
    "LocationDocument",
    "ModeDocument",
    "ModelDocument",
    "NotificationStatusDocument",
    "PipelineStatusDocument",
    "RestCalibrationDocument",
    "SensorState",
    "ServiceStatusDocument",
    "SinkStatusDocument",
    "BrokerStatusDocument",
    "SourceStatusDocument",
    "SpectrumDocument",
    "StatusDocument",
    "StorageStatusDocument",
    "ThresholdsDocument",
    "TrendRow",
    "TrendsDocument",
    "WindowDocument",
    "WindowKind",
    "chart_name",
    "estimate_payloads",
]

Level = Literal["ok", "warning", "alarm"]
AlarmLevel = Literal["warning", "alarm"]
ChartKind = Literal["frequency", "curvature", "fatigue"]
#: Conditions of a hot spot's fatigue charts: the damage rate against the design life,
#: the DEL against its baseline, the consumed life.
FATIGUE_CONDITIONS: Final[tuple[str, ...]] = ("rate", "del", "consumed")
WindowKind = Literal["forced", "free_decay", "ambient", "quiet"]
SensorState = Literal["ok", "degraded", "rejected"]
#: What a sensor can be: delivering ("ok"), silent or left out of the solution ("degraded"),
#: or with its samples refused ("rejected").
SENSOR_STATES: Final[tuple[str, ...]] = ("ok", "degraded", "rejected")

#: Name of the curvature control chart (the frequency charts are ``chart_name("frequency", m)``).
CURVATURE_CHART: Final = "curvature"


def chart_name(kind: ChartKind, mode: int | None = None, *, hot_spot: str | None = None, condition: str | None = None) -> str:
    """The stored name of a control chart: ``mode3`` for mode 3's frequency, ``curvature``, and
    ``fatigue:<hot spot>:<condition>`` for a hot spot's fatigue condition (rate, del, consumed)."""
    if kind == "frequency":
        if isinstance(mode, bool) or not isinstance(mode, (int, np.integer)) or mode < 1:
            raise ValueError(f"a frequency chart needs a 1-based integer mode, got {mode=}")
        return f"mode{int(mode)}"
    if kind == "curvature":
        if mode is not None:
            raise ValueError(f"the curvature chart has no mode, got {mode=}")
        return CURVATURE_CHART
    if kind == "fatigue":
        if mode is not None or not hot_spot or condition not in FATIGUE_CONDITIONS:
            raise ValueError(f"a fatigue chart needs a hot spot and a condition in {FATIGUE_CONDITIONS}, no mode; got "
                             f"{mode=}, {hot_spot=}, {condition=}")
        return f"fatigue:{hot_spot}:{condition}"
    raise ValueError(f"{kind=} must be 'frequency', 'curvature' or 'fatigue'")


def _expected_chart(name: str, kind: ChartKind, mode: int | None) -> str:
    if kind == "fatigue":
        spot, _, condition = name.removeprefix("fatigue:").rpartition(":")
        return chart_name(kind, mode, hot_spot=spot or None, condition=condition)
    return chart_name(kind, mode)


def _finite_or_none(value: Any) -> Any:
    if value is None or isinstance(value, bool):
        return value
    if isinstance(value, (int, float, np.integer, np.floating)):
        f = float(value)
        return f if math.isfinite(f) else None
    return value


def _finite(value: float) -> float:
    if not math.isfinite(value):
        raise ValueError(f"{value} must be finite")
    return value


#: A measured number that may be undefined: non-finite values become None.
Num = Annotated[float | None, BeforeValidator(_finite_or_none)]
#: A number that must be defined.
Finite = Annotated[float, AfterValidator(_finite)]
Count = Annotated[int, Field(ge=0)]


class _Document(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


# -- estimates -----------------------------------------------------------------------------


class EstimateDocument(_Document):
    """One ``/estimate/state`` payload (the contract's ``shm.EstimateState``): the body state,
    the tip deflection e = Δ(L), b, Δ and its curvature at the rig's truth stations (body frame),
    and the diagonal of the state covariance in the order of the estimator's StateLayout."""

    d: float = Field(description="ζ position of the support D, m")
    h: float = Field(description="η position of the support D, m")
    phi: float = Field(description="attitude of the body frame, rad (0 for a support that fixes it)")
    e: float = Field(description="tip deflection Δ(L) in the body frame, m")
    b: list[float] = Field(description="amplitudes of the unit deformations")
    deflection: list[float] = Field(description="Δ(η_k) at truth_stations, m")
    curvature: list[float] = Field(description="Δ''(η_k) at truth_stations, 1/m")
    covariance_diagonal: list[float] = Field(description="diagonal of the state covariance (StateLayout order)")


if tuple(EstimateDocument.model_fields) != tuple(f.name for f in PAYLOAD_FIELDS["shm.EstimateState"]):
    raise ImportError("EstimateDocument and PAYLOAD_FIELDS['shm.EstimateState'] disagree on the payload keys")


def estimate_payloads(layout: StateLayout, x: np.ndarray, covariance_diagonal: np.ndarray, e: np.ndarray,
                      deflection: np.ndarray, curvature: np.ndarray,
                      xi: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None) -> list[dict[str, Any]]:
    """``EstimateDocument`` payloads as plain dicts (for bulk writing: no per-sample validation).

    Parameters
    ----------
    layout : the estimator's state layout.
    x, covariance_diagonal : (N, n) states and covariance diagonals.
    e : (N,) tip deflection, m. deflection, curvature : (N, k) at the truth stations.
    xi : a biaxial estimate's (e_xi (N,), deflection_xi (N, k), curvature_xi (N, k)): the payloads then
        add ``b_xi``, ``e_xi``, ``deflection_xi`` and ``curvature_xi`` after the planar keys.

    Returns
    -------
    N dicts with the keys of :class:`EstimateDocument`, in its order.

    Raises
    ------
    ValueError
        When the shapes do not agree with each other or with the layout.
    """
    x = layout.check(x)
    P = layout.check(covariance_diagonal, name="covariance_diagonal")
    x, P = np.atleast_2d(x), np.atleast_2d(P)
    e = np.asarray(e, dtype=float).reshape(-1)
    deflection = np.atleast_2d(np.asarray(deflection, dtype=float))
    curvature = np.atleast_2d(np.asarray(curvature, dtype=float))
    n = x.shape[0]
    if not (P.shape[0] == e.shape[0] == deflection.shape[0] == curvature.shape[0] == n):
        raise ValueError(f"x ({n}), covariance_diagonal ({P.shape[0]}), e ({e.shape[0]}), deflection ({deflection.shape[0]}) "
                         f"and curvature ({curvature.shape[0]}) need one row per estimate")
    d, h, phi = x[:, layout.d].tolist(), x[:, layout.h].tolist(), layout.phi_of(x).tolist()
    b = layout.b_of(x).tolist()
    rows = [
        {"d": dd, "h": hh, "phi": pp, "e": ee, "b": bb, "deflection": w, "curvature": k, "covariance_diagonal": c}
        for dd, hh, pp, ee, bb, w, k, c in zip(d, h, phi, e.tolist(), b, deflection.tolist(), curvature.tolist(), P.tolist())
    ]
    if xi is not None:
        e_xi = np.asarray(xi[0], dtype=float).reshape(-1)
        w_xi, k_xi = (np.atleast_2d(np.asarray(a, dtype=float)) for a in xi[1:])
        if not (e_xi.shape[0] == w_xi.shape[0] == k_xi.shape[0] == n):
            raise ValueError(f"e_xi ({e_xi.shape[0]}), deflection_xi ({w_xi.shape[0]}) and curvature_xi ({k_xi.shape[0]}) "
                             f"need one row per estimate ({n})")
        for row, bb, ee, w, k in zip(rows, layout.b_xi_of(x).tolist(), e_xi.tolist(), w_xi.tolist(), k_xi.tolist()):
            row.update(b_xi=bb, e_xi=ee, deflection_xi=w, curvature_xi=k)
    return rows


# -- analysis windows ----------------------------------------------------------------------


class ModeDocument(_Document):
    """One eigenmode in one window."""

    mode: int = Field(ge=1, description="eigenmode number (1-based)")
    unit: int = Field(ge=1, description="unit deformation that carries the mode (1-based)")
    frequency_hz: Num = Field(None, description="identified eigenfrequency, Hz (None: no peak)")
    amplitude: Num = Field(None, description="spectral amplitude of the carrying unit deformation at the mode, unit of b")
    confidence: float = Field(0.0, ge=0.0, le=1.0, description="confidence of the estimate, 0..1")
    damping_ratio: Num = Field(None, description="damping ratio of the window's subspace pole, 1")
    score_sigma: Num = Field(None, description="EWMA score of the frequency chart, σ (None before a baseline)")
    level: Level | None = Field(None, description="level of the mode's frequency chart (None: not charted)")
    frequency_std_hz: Num = Field(None, description="1σ of frequency_hz, Hz")
    damping_std: Num = Field(None, description="1σ of damping_ratio")
    mpc: Num = Field(None, description="modal phase collinearity of the mode's shape, 0..1")
    mac: Num = Field(None, description="MAC of the shape against the baseline's, 0..1 (None before a baseline)")
    method: Literal["ssi", "spectrum"] | None = Field(
        None, description="ssi: the subspace identification (cross-checked against the spectrum); spectrum: the spectral peak alone")
    track: int | None = Field(None, ge=0, description="id of the subspace mode's track across windows (analytics.ModeTracker; None without one)")
    plane: Literal["zeta", "xi"] = Field("zeta", description="the bending plane of the mode (a biaxial beam's ξ modes: \"xi\")")


class ChartDocument(_Document):
    """One control chart's state after a window, with the levels it was judged against."""

    name: str = Field(description="stored chart name (alarms.chart): mode<k> or curvature")
    kind: ChartKind
    mode: int | None = Field(None, ge=1, description="eigenmode of a frequency chart")
    unit: int | None = Field(None, ge=1, description="unit deformation of a frequency chart's mode")
    level: Level
    score_sigma: Num = None
    warning_sigma: Finite = Field(description="warning level of this chart, σ")
    alarm_sigma: Finite = Field(description="alarm level of this chart, σ")

    @model_validator(mode="after")
    def _named(self) -> "ChartDocument":
        expected = _expected_chart(self.name, self.kind, self.mode)
        if self.name != expected:
            raise ValueError(f"chart name {self.name!r} does not match kind={self.kind!r}, mode={self.mode!r} ({expected!r})")
        return self


class CurvatureDocument(_Document):
    """Change of the curvature shapes against the baseline along the beam."""

    index: list[Num] = Field(description="curvature-change index per truth station (dimensionless)")
    total: Num = Field(description="RMS of the index over the stations")
    eta_m: Num = Field(description="η of the largest change, m from the support")
    third: Literal["upper", "middle", "lower"] | None = None
    score_sigma: Num = Field(None, description="score of the curvature chart, σ (None while its average settles)")


class LocationDocument(_Document):
    """The model-assisted location of a change (``analytics.DamageLocation``)."""

    eta_m: Num
    kind: str | None
    third: Literal["upper", "middle", "lower"] | None
    match: Num
    severity: Num
    next_best_other_third: Num


class FlagDocument(_Document):
    """A chart in alarm, with where the change points to."""

    kind: ChartKind
    mode: int | None = None
    unit: int | None = None
    level: AlarmLevel
    sigma: Num = None
    percent: Num = None
    since_s: Num = None
    eta_m: Num = None
    third: Literal["upper", "middle", "lower"] | None = None
    located_by: Literal["signatures", "curvature"] | None = None
    damage_kind: str | None = None
    location_match: Num = None


class WindowDocument(_Document):
    """The figures of one analysis window (live to the dashboard; the API's trends hold its rows)."""

    source: str
    start_s: Finite
    end_s: Finite
    kind: WindowKind
    trusted: bool = Field(description="used for eigenfrequencies (free decay or ambient)")
    temperature_c: Num = None
    modes: list[ModeDocument]
    charts: list[ChartDocument] = Field(default_factory=list, description="charts judged in this window")
    curvature: CurvatureDocument | None = None
    flags: list[FlagDocument] = Field(default_factory=list)
    location: LocationDocument | None = None


class TrendRow(_Document):
    """One mode of one window as stored and exported (``GET /api/trends``)."""

    source: str
    window_start_s: Finite
    window_end_s: Finite
    mode: int = Field(ge=1)
    unit: int = Field(ge=1)
    kind: WindowKind
    frequency_hz: Num = None
    damping_ratio: Num = None
    amplitude: Num = None
    confidence: Num = None
    temperature_c: Num = None
    curvature_index: Num = Field(None, description="RMS curvature-change index of the window")
    score_sigma: Num = None
    level: Level | None = None
    plane: Literal["zeta", "xi"] = Field("zeta", description="the bending plane of the mode (a biaxial beam's ξ modes: \"xi\")")


class TrendsDocument(_Document):
    """Trend rows in window order (window start, source, mode): one page of ``total`` rows that
    match. ``truncated``: rows come after this page; ask again with ``cursor=next_cursor`` for
    them (the ``Link: <...>; rel="next"`` header holds that URL)."""

    rows: list[TrendRow]
    count: Count = Field(description="rows in this page")
    total: Count = Field(0, description="rows that match the query, on every page (with the rows before the cursor)")
    truncated: bool = Field(False, description="more rows follow this page")
    next_cursor: str | None = Field(None, description="pass as cursor= for the next page (null: this is the last)")


class SpectrumDocument(_Document):
    """Amplitude spectra of b of the latest window, with the tracked and baseline
    eigenfrequencies of each unit deformation (several for the combimode)."""

    source: str
    window_start_s: Finite
    window_end_s: Finite
    frequencies_hz: list[Finite]
    amplitudes: list[list[Num]] = Field(description="(len(frequencies_hz), Γ) amplitudes of b, unit of b")
    tracked_hz: list[list[Finite]] = Field(description="per unit deformation the tracked frequencies of its modes")
    baseline_hz: list[list[Finite]] | None = Field(None, description="per unit deformation the baseline frequencies; None before a baseline")

    @model_validator(mode="after")
    def _shapes(self) -> "SpectrumDocument":
        f = self.frequencies_hz
        gamma = len(self.tracked_hz)
        if len(f) < 2 or any(b <= a for a, b in zip(f, f[1:])):
            raise ValueError(f"frequencies_hz needs at least 2 strictly increasing values, got {len(f)}")
        if gamma < 1:
            raise ValueError("tracked_hz needs one entry per unit deformation (Γ >= 1)")
        if len(self.amplitudes) != len(f) or any(len(row) != gamma for row in self.amplitudes):
            raise ValueError(f"amplitudes must be (len(frequencies_hz), Γ) = ({len(f)}, {gamma})")
        if self.baseline_hz is not None and len(self.baseline_hz) != gamma:
            raise ValueError(f"baseline_hz has {len(self.baseline_hz)} entries for Γ={gamma}")
        return self

    @classmethod
    def from_arrays(cls, *, source: str, window_start_s: float, window_end_s: float, frequencies_hz: np.ndarray,
                    amplitudes: np.ndarray, tracked_hz: Sequence[Sequence[float]],
                    baseline_hz: Sequence[Sequence[float]] | None) -> "SpectrumDocument":
        """From numpy spectra: frequencies (n,), amplitudes (n, Γ)."""
        a = np.asarray(amplitudes, dtype=float)
        if a.ndim == 1:
            a = a[:, None]
        return cls(source=source, window_start_s=window_start_s, window_end_s=window_end_s,
                   frequencies_hz=np.asarray(frequencies_hz, dtype=float).tolist(), amplitudes=a.tolist(),
                   tracked_hz=[list(g) for g in tracked_hz],
                   baseline_hz=None if baseline_hz is None else [list(g) for g in baseline_hz])

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """(frequencies (n,), amplitudes (n, Γ)) with undefined amplitudes as NaN."""
        a = np.array([[np.nan if v is None else v for v in row] for row in self.amplitudes], dtype=float)
        return np.asarray(self.frequencies_hz, dtype=float), a.reshape(len(self.frequencies_hz), len(self.tracked_hz))


# -- alarms --------------------------------------------------------------------------------


class AlarmDocument(_Document):
    """An alarm of one chart (``GET /api/alarms``)."""

    id: int = Field(ge=1)
    source: str
    chart: str = Field(description="the chart's name: mode<k> or curvature")
    kind: ChartKind
    mode: int | None = Field(None, ge=1)
    level: AlarmLevel
    state: Literal["active", "cleared"]
    raised_at_s: Finite
    cleared_at_s: Num = None
    acknowledged_at_s: Num = None
    acknowledged_by: str | None = None
    value: Num = Field(None, description="the chart's score when raised or escalated, σ")
    threshold: Num = Field(None, description="the chart's level the score crossed, σ")
    message: str
    stale: bool = Field(False, description="the alarm's source has gone silent: its state is no longer being judged")

    @model_validator(mode="after")
    def _named(self) -> "AlarmDocument":
        expected = _expected_chart(self.chart, self.kind, self.mode)
        if self.chart != expected:
            raise ValueError(f"alarm chart {self.chart!r} does not match kind={self.kind!r}, mode={self.mode!r} ({expected!r})")
        return self

    @property
    def acknowledged(self) -> bool:
        return self.acknowledged_at_s is not None

    @property
    def active(self) -> bool:
        return self.state == "active"


class AlarmsDocument(_Document):
    """Alarms, newest first: one page of ``total`` (paged as ``TrendsDocument``)."""

    alarms: list[AlarmDocument]
    count: Count = Field(description="alarms in this page")
    total: Count = Field(0, description="alarms that match the query, on every page")
    truncated: bool = Field(False, description="more alarms follow this page")
    next_cursor: str | None = Field(None, description="pass as cursor= for the next page (null: this is the last)")


AlarmEvent = Literal["raised", "escalated", "cleared", "acknowledged", "repeated", "stale"]


class AlarmEventDocument(_Document):
    """A notification of an alarm event (webhook body; e-mail attachment). ``id`` is stable
    across retries and unique for ever (a random instance id and the event's UUID): receivers
    recognise a repeat by it (also the ``Idempotency-Key`` header). ``sequence`` numbers the
    events of one alarm 1, 2, 3, …: each target receives them in that order (a repeat of an
    event already received may come again; a receiver keeps the highest one it saw)."""

    id: str
    event: AlarmEvent = Field(description="raised, escalated, cleared, acknowledged; repeated: the alarm still fires "
                                          "(re-notification); stale: its source went silent")
    sequence: int = Field(1, ge=1, description="number of this event among the alarm's events (1-based)")
    level: AlarmLevel
    at_s: Finite
    alarm: AlarmDocument


# -- status --------------------------------------------------------------------------------


class ChartLevelsDocument(_Document):
    warning_sigma: Finite
    alarm_sigma: Finite


class ThresholdsDocument(_Document):
    """The configured levels of the control charts (σ), as the analytics apply them."""

    frequency: ChartLevelsDocument
    curvature: ChartLevelsDocument
    clear_sigma: Finite

    def of(self, kind: ChartKind) -> ChartLevelsDocument:
        if kind == "frequency":
            return self.frequency
        if kind == "curvature":
            return self.curvature
        raise ValueError(f"{kind=} must be 'frequency' or 'curvature'")


class ServiceStatusDocument(_Document):
    version: str
    started_at: Finite = Field(description="UNIX s")
    uptime_s: Finite
    done: bool = Field(description="the source ended and everything was processed")
    pipeline_error: str | None = Field(None, description="the error of the last batch, None once a batch succeeds again")
    pipeline_errors: Count = Field(0, description="batches that failed since the start")
    last_pipeline_error: str | None = None
    progress: str | None = Field(
        None, description="what the service is doing now, in words: compiling the filter (first run only), "
        "calibrating at rest and the time left, waiting for the first analysis window, learning the baseline, monitoring")


class BrokerStatusDocument(_Document):
    """An MQTT source's connection: where it subscribes, whether the broker holds its session."""

    url: str = Field(description="the broker (mqtt.url)")
    topic: str = Field(description="the topic subscribed with QoS 1: TOPIC_PREFIX/ID/ingest")
    client_id: str = Field(description="the persistent session's client id")
    connected: bool
    session_present: bool | None = Field(None, description="whether the broker still held the session at the last "
                                         "connect (False: what was published before was not kept for it)")
    connects: Count = Field(0, description="connections made since the start")
    bodies: Count = Field(0, description="bodies taken and acknowledged")
    refused_bodies: Count = Field(0, description="bodies that were not an ingest body as a whole (acknowledged, counted "
                                  "as rejected malformed_body)")
    redelivered: Count = Field(0, description="bodies the broker sent again after a reconnect that had been taken "
                               "already (acknowledged, not counted again)")
    unacknowledged: Count = Field(0, description="bodies handed to the pipeline whose window is not committed yet "
                                  "(acknowledged then; until then the broker keeps them for the next holder)")
    acked_early: Count = Field(0, description="bodies acknowledged before their window was committed, because more "
                               "than mqtt.receive_maximum / 2 waited")
    error: str | None = Field(None, description="why the broker cannot be reached, while it cannot")


class SourceStatusDocument(_Document):
    id: str
    kind: Literal["sim", "replay", "follow", "ingest", "mqtt"]
    state: str
    error: str | None = None
    messages: Count
    rate_hz: Finite
    data_time_s: Num = None
    lag_s: Num = None
    rejected: Count
    rejected_by_reason: dict[str, Count]
    dropped: Count
    problems: list[str]
    latency_s: Num = None
    clock_jumps: Count = Field(0, description="stamps (or batches) found off the source's clock since the start")
    broker: BrokerStatusDocument | None = Field(None, description="mqtt: the connection to the broker")


class RestCalibrationDocument(_Document):
    rest_end_s: Finite
    rested: bool
    gyro_bias_D_rad_s: Num
    accel_bias_D_m_s2: list[Num]
    gyro_bias_peripheral_rad_s: list[Num]
    tof_offset_m: list[Num]
    strain_offset: list[Num]


class AidingChannelDocument(_Document):
    accepted: Count
    rejected: Count
    mean_nis: Num = None


class DegradedImuDocument(_Document):
    sensor: str
    silent_s: Finite
    active: bool


class LastEstimateDocument(_Document):
    """The newest state estimate of the rigid motion and the tip deflection."""

    t_s: Finite = Field(description="UNIX s")
    d_m: Num = Field(description="ζ position of the support D, m")
    phi_rad: Num = Field(description="attitude, rad")
    e_m: Num = Field(description="tip deflection Δ(L) in the body frame, m")


class EstimatorStatusDocument(_Document):
    state: str
    dropped_samples: Count
    filter_restarts: Count = Field(description="restarts of the filter since the start (divergence, a gap at D)")
    filter_restarts_by_reason: dict[str, Count] = Field(default_factory=dict)
    health: Literal["ok", "diverged", "recovering"] = Field(
        "ok", description="diverged: the last check found the filter diverged (it restarts); recovering: restarted "
                          "and not yet confirmed healthy")
    health_reason: str | None = Field(None, description="what the last divergence check found")
    last_estimate: LastEstimateDocument | None = None
    rest_calibration: RestCalibrationDocument | None = None
    aiding: dict[str, AidingChannelDocument] = Field(default_factory=dict)
    rejected: Count = 0
    degraded_imus: list[DegradedImuDocument] = Field(default_factory=list)
    gauge_std: dict[str, Finite] | None = Field(
        None, description="gauge -> the 1σ (m/m) the filter gives it, once raised above its rest calibration's because "
                          "it reads strain outside the unit deformations (None: none raised)")
    gauge_note: str | None = Field(None, description="why the gauges' 1σ was raised, and what would carry that motion")


class HotSpotLoadsDocument(_Document):
    """One hot spot in one analysis window: the window's loads and the hot spot's life so far.

    Stresses are nominal (before the SCF) in Pa; damage is Miner's sum with the SCF and partial factors.
    """

    name: str
    position_m: Finite
    curve: str
    del_pa: dict[str, Num] = Field(description="damage-equivalent stress range of the window per Wöhler exponent m ('3', '5'), Pa")
    n_eq: Finite = Field(description="equivalent cycles of the DELs")
    max_range_pa: Num
    damage_increment: Num = Field(description="Miner damage of the cycles the window closed")
    consumed: Num = Field(description="consumed life D so far (closed cycles plus the open residue as half cycles)")
    rate_per_year: Num = None
    rate_band_per_year: list[Num] | None = None
    remaining_years: Num = Field(None, description="(1 − D)/rate; None when nothing is consumed (below the cut-off) or no rate yet")
    remaining_band_years: list[Num] | None = None
    verdict: Literal["finite", "no_damage_below_cutoff", "exhausted", "no_data"]
    design_life_years: Num = None
    del_band_pa: dict[str, list[Num]] | None = Field(None, description="[low, high] of each DEL: where the true DEL lies "
                                                     "(None: no measured strain gauge to judge the virtual strain by)")
    damage_band: list[Num] | None = Field(None, description="[low, high] of the damage increment, the closed cycles' ranges "
                                          "scaled by the DEL band's ends")
    band_method: str | None = Field(None, description="how the band was found")


class PipelineStatusDocument(_Document):
    queue_depth: Count
    queue_capacity: Count
    samples: Count
    samples_by_topic: dict[str, Count]
    late_samples: Count
    late_by_topic: dict[str, Count]
    estimates: Count
    estimator: EstimatorStatusDocument
    windows: Count
    windows_committed: Count
    windows_skipped_incomplete: Count
    windows_skipped_warmup: Count
    windows_usable: Count = Field(0, description="analysed windows with an identified mode (those that learn the baseline and feed "
                                                 "the charts)")
    windows_rejected: dict[str, Count] = Field(default_factory=dict, description="analysed windows that are not usable, by reason "
                                               "(quiet, forced, no_mode_identified: analytics.WINDOW_REJECTIONS)")
    no_usable_window: str | None = Field(None, description="when windows were analysed or skipped but none is usable: why (each "
                                         "reason counted) and what to change; None otherwise")
    baseline: Literal["learning", "active"]
    data_time_s: Num = None
    processed_data_s: Num = None
    realtime_factor: Num = None
    pipeline_latency_s: Finite
    busy_fraction: Finite
    active_alarms: dict[str, AlarmLevel]
    hot_spots: list[HotSpotLoadsDocument] = Field(default_factory=list,
                                                description="the hot spots' loads and life after the last committed window")


class BaselineModeDocument(_Document):
    mode: int = Field(ge=1)
    unit: int = Field(ge=1)
    f_ref_hz: Finite
    temperature_ref_c: Finite
    slope_per_k: Finite
    sigma_rel: Finite
    plane: Literal["zeta", "xi"] = "zeta"


class BaselineStatusDocument(_Document):
    state: Literal["learning", "active"]
    modes: list[BaselineModeDocument] | None = None


class AlarmCountsDocument(_Document):
    active: dict[AlarmLevel, Count]


class NotificationStatusDocument(_Document):
    pending: Count = 0
    sent: Count = 0
    failed: Count = 0
    sent_this_run: Count
    failed_attempts_this_run: Count
    outcomes_this_run: dict[str, Count] = Field(
        default_factory=dict, description="delivery attempts by outcome: sent, retry (temporary failure), permanent "
                                          "(refused by the target: 4xx), given_up")
    last_error: str | None = None


class ArchiveStatusDocument(_Document):
    directory: str
    current: str | None
    files: Count
    messages: Count
    errors: Count


class StorageStatusDocument(_Document):
    db: str
    schema_version: Count
    trend_rows: Count
    archive: ArchiveStatusDocument | None
    write_retries: Count = Field(0, description="writes retried after a transient error (locked, disk full) since the start")
    write_failures: Count = Field(0, description="writes given up after the retry period (their windows wait in memory)")
    windows_waiting: Count = Field(0, description="analysed windows waiting to be written")
    last_error: str | None = None


class SinkStatusDocument(_Document):
    """Failures of one sink (the dashboard, the notifier), counted by what was being done."""

    errors: Count = 0
    errors_by_kind: dict[str, Count] = Field(default_factory=dict)
    last_error: str | None = None


class ModelDocument(_Document):
    """The estimator's model: how to read a state vector and which modes b carries."""

    peripheral: Literal["gyro", "acc"]
    support: Literal["pinned", "clamped"]
    gamma: int = Field(ge=1)
    state_names: list[str]
    unit_modes: list[list[int]]


class StatusDocument(_Document):
    """``GET /api/status`` (and the dashboard's status)."""

    service: ServiceStatusDocument
    sources: list[SourceStatusDocument]
    pipeline: PipelineStatusDocument
    degraded_sensors: list[str]
    sensors: dict[str, SensorState]
    baseline: BaselineStatusDocument
    alarms: AlarmCountsDocument
    notifications: NotificationStatusDocument
    storage: StorageStatusDocument
    sinks: dict[str, SinkStatusDocument]
    thresholds: ThresholdsDocument
    model: ModelDocument


class HealthDocument(_Document):
    status: Literal["ok", "degraded"]
    uptime_s: Finite
    reasons: list[str] = Field(default_factory=list, description="why the service is degraded (empty when ok)")


class BaselineRequestDocument(_Document):
    baseline_id: int = Field(ge=1)
    state: Literal["learning"]
    source: str
    learn_s: Finite


StructureState = Literal["starting", "running", "degraded", "failed", "finished", "stopped"]


class StructureSummaryDocument(_Document):
    """One structure of a fleet as ``GET /api/structures`` lists it."""

    id: str = Field(description="the structure id: the source of its trend rows, alarms and notifications")
    kind: Literal["sim", "replay", "follow", "ingest", "mqtt"]
    state: StructureState = Field(
        description="starting, running, degraded (running, but its batches fail, its filter diverged or its database "
        "writes wait), failed (its source or its start failed: see error), finished, stopped")
    error: str | None = Field(None, description="why the structure is failed or degraded")
    data_time_s: Num = Field(None, description="newest sample the pipeline has processed, UNIX s")
    lag_s: Num = Field(
        None, description="how far the data is behind its pace, s: for sim and replay at speed k, k x the wall time since "
        "the first batch minus the data time since it (the pacer's origin); for follow and ingest, the wall clock minus "
        "the data time; None before the first data (and at speed max); 0 once a replay or simulation has ended")
    windows: Count = Field(0, description="analysis windows committed to the database")
    active_alarms: dict[str, AlarmLevel] = Field(default_factory=dict, description="chart -> level of its active alarm")
    node: str | None = Field(None, description="the node that runs it (shm serve --node): its lease's holder; null: no "
                             "node holds it now (one takes it within the lease), or the service has no nodes")


class StructuresDocument(_Document):
    """``GET /api/structures``: the structures in their configured order, one page of ``total``
    (paged as ``TrendsDocument``; a document of the whole fleet has every structure)."""

    structures: list[StructureSummaryDocument]
    count: Count | None = Field(None, description="structures in this page (null: all of them)")
    total: Count | None = Field(None, description="structures of the service, on every page (null: as many as listed)")
    truncated: bool = Field(False, description="more structures follow this page")
    next_cursor: str | None = Field(None, description="pass as cursor= for the next page (null: this is the last)")


class LiveEstimatesDocument(_Document):
    """``GET /api/structures/{id}/live``: a structure's newest state estimates, decimated in data
    time, for a live view (the dashboard of a fleet polls it for the structure it shows). A
    structure keeps them only while someone reads them: a read starts (or extends) a watch of
    ``watch_s``; before the first read, and once nobody read for ``watch_s``, nothing is kept."""

    source: str
    seq: Count = Field(description="number of the newest estimate kept (pass it as after= to get only newer ones)")
    state_names: list[str] = Field(description="the names of x's entries: the estimator's StateLayout")
    t_s: list[Finite] = Field(default_factory=list, description="data time of each estimate, UNIX s, increasing")
    x: list[list[Finite]] = Field(default_factory=list, description="the state vector of each estimate")
    sensors: dict[str, SensorState] = Field(default_factory=dict, description="topic -> state, now")
    watch_s: Finite = Field(description="how long the structure keeps estimates after this read, s")
    # virtual loads of each estimate: the hot spots, then a grid from the support
    loads_stations_m: list[Finite] = Field(default_factory=list, description="stations of strain, stress and moment, m")
    loads_station_names: list[str] = Field(default_factory=list, description="the hot spot at each station, '' for a grid station")
    strain: list[list[Finite]] = Field(default_factory=list, description="bending strain ε = −c κ per estimate and station, m/m")
    stress_pa: list[list[Finite]] | None = Field(None, description="nominal stress E ε per estimate and station, Pa, at the "
                                                               "reference temperature's E (None: a beam of table sections has no E)")
    moment_nm: list[list[Finite]] = Field(default_factory=list, description="bending moment EI κ per estimate and station, N·m")
    root_moment_nm: list[Finite] | None = Field(None, description="the root bending moment per estimate, N·m (clamped support only)")
    # a biaxial beam (beam.bending = "biaxial") only; empty or None for a planar one
    loads_angles_deg: list[Finite] = Field(default_factory=list, description="a biaxial beam: the angle around the section "
                                           "(degrees from +ζ towards +ξ) each station is evaluated at; an 'all' hot spot's "
                                           "worst point found over the estimates kept")
    loads_worst_around: list[bool] = Field(default_factory=list, description="a biaxial beam: per station, whether it is "
                                           "a hot spot of angle_deg 'all' (its angle is the worst found, not given)")
    moment_xi_nm: list[list[Finite]] | None = Field(None, description="a biaxial beam: bending moment EIξ κξ per estimate "
                                                    "and station, N·m")
    root_moment_xi_nm: list[Finite] | None = Field(None, description="a biaxial beam: the root bending moment in ξ per estimate, N·m")
    root_moment_resultant_nm: list[Finite] | None = Field(None, description="a biaxial beam: the root moment's resultant "
                                                          "√(Mζ² + Mξ²) per estimate, N·m")
    truth_deflection: list[list[Finite] | None] | None = Field(
        None, description="a simulated source only: the true deflection (m) at the structure's stations at each estimate "
                          "(None where the simulation gave none near it); None for measured data")


class ErrorDocument(_Document):
    """The body of every error response: a sentence saying what is wrong, or (for a request
    that does not match the API's parameter types) FastAPI's list of validation errors."""

    detail: str | list[dict[str, Any]]


class IngestErrorDocument(_Document):
    index: Count = Field(description="position of the message in the request")
    reason: str
    detail: str


class IngestResultDocument(_Document):
    accepted: Count
    rejected: Count
    rejected_by_reason: dict[str, Count]
    errors: list[IngestErrorDocument]


# -- loads and fatigue ------------------------------------------------------------


class StationLoadsDocument(_Document):
    """Virtual strain and stress at one station along the beam (ε = −c κ on the +ζ face, σ = E(T) ε)
    over a span: a window's, or (``FatigueDocument.envelope``) the windows' envelope."""

    position_m: Finite
    strain_rms: Num = Field(description="RMS of the bending strain, m/m")
    strain_range_max: Num = Field(description="largest peak-to-peak strain range, m/m")
    stress_range_max_pa: Num = Field(description="largest peak-to-peak nominal stress range, Pa")


class LoadsWindowDocument(_Document):
    """The loads of one analysis window over the hot spots (``MonitoringEngine`` with loads)."""

    start_s: Finite
    duration_s: Finite
    temperature_c: Num = None
    hot_spots: list[HotSpotLoadsDocument]
    charts: list[ChartDocument] = Field(default_factory=list, description="the hot spots' fatigue charts judged in this window")
    stations: list[StationLoadsDocument] = Field(default_factory=list, description="virtual strain along the beam in the window")


class FatigueDocument(_Document):
    """``GET /api/fatigue`` and ``GET /api/structures/{id}/fatigue``: a structure's loads and life.

    ``hot_spots``: each hot spot's state after the newest window of the period (consumed life D,
    damage rate, remaining life, verdict); ``windows``: the per-window trend, oldest first (DEL per
    Wöhler exponent, maximum range, damage increment); ``envelope``: along the beam, the period's
    largest strain and stress ranges and its strain RMS. Stresses are nominal (before the SCF), Pa."""

    structure_id: str
    design_life_years: Num = None
    hot_spots: list[HotSpotLoadsDocument]
    windows: list[LoadsWindowDocument]
    envelope: list[StationLoadsDocument]
    total: Count = Field(description="windows of the period stored")
    truncated: bool = Field(False, description="more windows than ``limit`` returned: ask again from the last one's start")
