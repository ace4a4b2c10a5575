"""A whole recording's b(t) through the one engine, the way ``shm analyze`` does it.

``shm analyze``, the benchmarks and ``shm reprocess`` call these; ``shm serve`` feeds the same
engine (``analytics.MonitoringEngine``) chunk by chunk. Windows are aligned in data time (the
recording's UNIX time), so a recording analysed here gives the windows the live service had.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from analytics import AnalysisConfig, AnalysisResult, Baseline, analyze, learn_baseline

from .estimation import DeformationRecord, deformation_record

__all__ = ["DEFAULT_WARMUP_S", "RecordAnalysis", "trend_rows", "analyze_deformations", "analyze_recording", "baseline_from_deformations",
           "baseline_xi_from_deformations", "biaxial",
           "recording_gauges",
           "baseline_from_recording"]

#: windows starting less than this after the rest phase are not analysed (the filter converging);
#: the same default as ``shm serve``'s ``estimator.warmup_s``
DEFAULT_WARMUP_S = 120.0


@dataclass(frozen=True)
class RecordAnalysis:
    """The analysis of one recording and the deformation record it ran on."""

    result: AnalysisResult
    data: DeformationRecord


def _signatures(rig, data: DeformationRecord):
    from estimator import damage_signatures

    # FE-predicted damage signatures of the rig: the model-assisted location of flags
    return damage_signatures(rig, data.stations, gamma=data.b.shape[1])


def _not_before(data: DeformationRecord, warmup_s: float | None, not_before_s: float | None) -> float | None:
    if not_before_s is not None:
        return float(not_before_s)
    if warmup_s is None or data.rest_end_s is None:
        return None
    return data.rest_end_s + warmup_s


def _rate_hz(times_s: np.ndarray) -> float:
    """The sample rate of b: the estimator's 200 Hz, or what a recording kept of it (``shm serve``
    archives every ``archive.estimate_decimation``-th estimate: 50 Hz by default)."""
    steps = np.diff(np.asarray(times_s, dtype=float))
    steps = steps[steps > 0]
    if not steps.size:
        raise ValueError("b has fewer than two distinct times: no sample rate")
    # to a µHz: the estimator's 200 Hz is 200.0 exactly, as in shm serve (the engine's grid is fs's)
    return round(float(1.0 / np.median(steps)), 6)


def _kwargs(rig, data: DeformationRecord, config: AnalysisConfig | None, warmup_s: float | None, not_before_s: float | None,
            signatures, *, located: bool = True) -> dict:
    return dict(
        fs=_rate_hz(data.times),
        temperature=data.temperature, bearing=data.support if data.support is not None else data.bearing,
        expected_hz=data.units.frequencies_hz, config=config, beam_length=rig.beam.length,
        signatures=(_signatures(rig, data) if located else None) if signatures is None else signatures, time_origin_ns=data.origin_ns,
        not_before_s=_not_before(data, warmup_s, not_before_s),
    )


def _xi_kwargs(rig, data: DeformationRecord, kw: dict) -> dict:
    """The ξ plane's engine arguments: its own eigenfrequencies; no FE damage signatures of the
    plane (the flags are located by the curvature change instead)."""
    return {**kw, "expected_hz": _units_xi(data).frequencies_hz, "signatures": None}


def _units_xi(data: DeformationRecord) -> Any:
    """The ξ plane's unit deformations (``estimator.UnitDeformations``) of a biaxial record."""
    if data.units_xi is None:
        raise ValueError("a planar deformation record has no xi plane")
    return data.units_xi


def biaxial(data: DeformationRecord) -> bool:
    """Whether the record carries the ξ plane's b(t) (a biaxial beam's estimate)."""
    return data.b_xi is not None and data.units_xi is not None


def analyze_deformations(rig, data: DeformationRecord, *, config: AnalysisConfig | None = None, baseline: Baseline | None = None,
                         warmup_s: float | None = DEFAULT_WARMUP_S, not_before_s: float | None = None,
                         signatures=None, loads_tap: list | None = None,
                         gauges: dict | None = None, baseline_xi: Baseline | None = None) -> AnalysisResult:
    """The engine over a deformation record (b(t), the support displacement, temperature) of ``rig``.

    Windows starting before ``not_before_s`` (s after the recording's first message; default the
    rest phase's end plus ``warmup_s``, when the record knows it) are not analysed, as in ``shm serve``.
    ``loads_tap``: a list that receives each window's loads input (``LoadsMonitor.tap``).
    ``gauges``: the strain gauges' measured strain (``recording_gauges``) for the loads' DEL bands
    (each gauge taken as in sample: the estimate may have used it), or None: no band.
    A biaxial record (``data.b_xi``): the ξ plane analysed on its own too (``baseline_xi``, or learnt
    from the record's start as a missing ζ baseline is), both in one result (``analytics.combine_planes``)."""
    kw = _kwargs(rig, data, config, warmup_s, not_before_s, signatures)
    loads = None
    if rig.hot_spots:  # the hot spots' loads and fatigue in the same engine
        from analytics import LoadsMonitor

        from .estimation import outside_shapes

        loads = LoadsMonitor.from_rig(rig, data.units.curvature, outside_at=outside_shapes(rig, data.units))
        loads.tap = loads_tap
    result = analyze(data.times, data.b, data.units.curvature(data.stations), data.stations, baseline=baseline, loads=loads,
                     gauges=gauges if loads is not None else None, **kw)
    if not biaxial(data):
        return result
    from analytics import combine_planes

    xi = analyze(data.times, data.b_xi, _units_xi(data).curvature(data.stations), data.stations, baseline=baseline_xi,
                 **_xi_kwargs(rig, data, kw))
    combined: AnalysisResult = combine_planes(result, xi)
    return combined


def recording_gauges(rec) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """The recording's strain gauges' measured strain by name: (s after the recording's start, m/m)."""
    out = {}
    for sensor in rec.rig.sensors_of("strain"):
        channel = rec.channels.get(sensor.topic)
        if channel is not None and len(channel) >= 2:
            out[sensor.name] = ((channel.log_time_ns - rec.start_ns) * 1e-9, channel.values[:, 0])
    return out


def baseline_from_deformations(rig, data: DeformationRecord, *, config: AnalysisConfig | None = None,
                               warmup_s: float | None = DEFAULT_WARMUP_S, not_before_s: float | None = None,
                               signatures=None) -> Baseline:
    """A baseline learnt from every trusted window of a healthy deformation record
    (``analytics.learn_baseline``; raises ``analytics.BaselineError`` naming what each mode lacked)."""
    kw = _kwargs(rig, data, config, warmup_s, not_before_s, signatures)
    return learn_baseline(data.times, data.b, data.units.curvature(data.stations), data.stations, **kw)


def baseline_xi_from_deformations(rig, data: DeformationRecord, *, config: AnalysisConfig | None = None,
                                  warmup_s: float | None = DEFAULT_WARMUP_S, not_before_s: float | None = None) -> Baseline | None:
    """The ξ plane's baseline of a healthy biaxial deformation record (as :func:`baseline_from_deformations`
    for ζ), or None for a planar record."""
    if not biaxial(data):
        return None
    kw = _xi_kwargs(rig, data, _kwargs(rig, data, config, warmup_s, not_before_s, None, located=False))
    return learn_baseline(data.times, data.b_xi, _units_xi(data).curvature(data.stations), data.stations, **kw)


def analyze_recording(path, *, config: AnalysisConfig | None = None, baseline: Baseline | None = None, rig=None,
                      model_args: dict | None = None, warmup_s: float | None = DEFAULT_WARMUP_S,
                      not_before_s: float | None = None) -> RecordAnalysis:
    """Read a recording (estimates, or raw samples: the estimator runs first) and analyse it."""
    from ..recording import read_recording

    rec = read_recording(path, rig=rig)
    data = deformation_record(rec, model_args=model_args)
    return RecordAnalysis(analyze_deformations(rec.rig, data, config=config, baseline=baseline, warmup_s=warmup_s,
                                               not_before_s=not_before_s), data)


def baseline_from_recording(path, *, config: AnalysisConfig | None = None, rig=None, model_args: dict | None = None,
                            warmup_s: float | None = DEFAULT_WARMUP_S, not_before_s: float | None = None) -> Baseline:
    """A baseline learnt from a whole healthy recording (see :func:`baseline_from_deformations`)."""
    from ..recording import read_recording

    rec = read_recording(path, rig=rig)
    data = deformation_record(rec, model_args=model_args)
    return baseline_from_deformations(rec.rig, data, config=config, warmup_s=warmup_s, not_before_s=not_before_s)


def trend_rows(source: str, result, start_s: float, end_s: float, plane: str = "zeta") -> list:
    """The storage rows (``contract.TrendRow``, one per mode estimate) of one analysed window
    (``analytics.WindowResult``) of ``source`` from ``start_s`` to ``end_s`` (UNIX s): what
    ``shm serve`` stores live and ``shm reprocess`` stores from archives; ``plane``: the bending
    plane whose b(t) the window analysed ("zeta", or a biaxial beam's "xi")."""
    from contract import TrendRow, chart_name

    rows = []
    for i, e in enumerate(result.estimates):
        score = result.frequency_scores[i] if i < len(result.frequency_scores) else None
        rows.append(TrendRow(
            source=source, window_start_s=start_s, window_end_s=end_s, mode=e.mode, unit=e.unit, kind=result.kind,
            frequency_hz=e.frequency_hz, damping_ratio=e.damping_ratio, amplitude=e.amplitude, confidence=e.confidence,
            temperature_c=result.temperature_c, curvature_index=None if result.curvature is None else result.curvature.total,
            score_sigma=score, level=result.levels.get(chart_name("frequency", e.mode)), plane=plane,
        ))
    return rows
