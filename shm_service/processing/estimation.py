"""Wiring between recordings and the estimator: measurements in, estimates and scores out."""

from __future__ import annotations

from dataclasses import dataclass

from typing import Any

import numpy as np

from contract import (
    ESTIMATE_LOADS_TOPIC,
    BEARING_TOPIC,
    IMU_BIAXIAL_COLUMNS,
    IMU_PLANAR_COLUMNS,
    TEMPERATURE_TOPIC,
    TRUTH_TOPIC,
    row_layout,
)
from contract import estimate_payloads as _estimate_payloads
from estimator import EstimateResult, Measurements, SensorSeries, UnitDeformations

from ..recording import Recording

__all__ = [
    "outside_shapes",
    "DeformationRecord",
    "TruthSeries",
    "deformation_record",
    "estimate_payloads",
    "estimate_recording",
    "measurements_from_recording",
    "score_against_truth",
    "sensor_count_problem",
    "truth_from_recording",
    "write_estimates",
]

_NS = 1e-9

_SENSOR_LABELS = {"imus": "peripheral IMUs", "tofs": "ToFs", "gauges": "strain gauges"}


def sensor_count_problem(rig, kind: str, wanted: int, *, modes: int) -> str | None:
    """Why a count of ``kind`` ("imus", "tofs", "gauges") cannot be chosen on ``rig``, with the valid
    range, or None when it can. The estimator caps a count to what the rig has; an explicit request
    beyond it is the user's mistake and must be refused, not capped."""
    if kind == "imus":
        names = [s.name for s in rig.sensors_of("imu") if s.name != "D" and (s.position or 0) > 0]
        low = modes
    elif kind == "tofs":
        names, low = [s.name for s in rig.sensors_of("tof")], 0
    elif kind == "gauges":
        names, low = [s.name for s in rig.sensors_of("strain")], 0
    else:
        raise ValueError(f"{kind=} must be imus, tofs or gauges")
    if low <= wanted <= len(names):
        return None
    need = f"; Γ = {modes} needs at least {modes}" if kind == "imus" else ""
    valid = "none" if low > len(names) else str(low) if low == len(names) else f"{low}..{len(names)}"
    return (f"the rig has {len(names)} {_SENSOR_LABELS[kind]} ({', '.join(names) or '-'}){need}: "
            f"valid counts: {valid}")


def measurements_from_recording(rec: Recording) -> Measurements:
    """The measurements of a recording (times in s from the recording's start): a biaxial beam's IMUs
    with accel z and gyro y too (``IMU_BIAXIAL_COLUMNS``)."""
    start = rec.start_ns

    def series(channel, columns) -> SensorSeries:
        return SensorSeries((channel.log_time_ns - start) * _NS, channel.values[:, columns])

    imu, tof, strain, bearing = {}, {}, {}, None
    imu_columns = IMU_BIAXIAL_COLUMNS if rec.rig.beam.biaxial else IMU_PLANAR_COLUMNS
    for channel in rec.channels.values():
        if channel.kind == "imu":
            imu[channel.name] = series(channel, imu_columns)
        elif channel.kind == "tof":
            tof[channel.name] = series(channel, [0])
        elif channel.kind == "strain":
            strain[channel.name] = series(channel, [0])
        elif channel.kind == "bearing":
            bearing = series(channel, [0])
    if "D" not in imu:
        raise ValueError(f"{rec.path}: no samples of /imu/D, the IMU at the bearing")
    return Measurements(imu=imu, tof=tof, strain=strain, bearing=bearing)


@dataclass(frozen=True)
class TruthSeries:
    t: np.ndarray
    d: np.ndarray
    h: np.ndarray
    phi: np.ndarray
    e: np.ndarray
    deflection: np.ndarray
    curvature: np.ndarray
    e_xi: np.ndarray | None = None  # a biaxial recording's ξ plane
    deflection_xi: np.ndarray | None = None
    curvature_xi: np.ndarray | None = None


def estimate_recording(rec: Recording, model, settings=None) -> EstimateResult:
    """Run the streaming estimator (``estimator.StreamingEstimator``, the service's policy) over a
    raw recording, on the samples' own UNIX ns stamps as ``shm serve`` sees them: the same b(t)
    as a replay of the file in the service. The result's ``t`` are s from the recording's start.

    Raises
    ------
    ValueError
        The recording has no samples of the reference IMU D.
    """
    from dataclasses import replace

    from estimator import estimate_stream, rig_topics

    topics = rig_topics(model)
    samples = {topic: (ch.log_time_ns, ch.values) for topic, ch in rec.channels.items() if topic in topics and len(ch)}
    result = estimate_stream(samples, model, settings, topics=topics)
    if not samples:
        return result
    first = min(int(t[0]) for t, _ in samples.values())
    epoch = first - first % 1_000_000_000  # as the service's estimator takes it
    return replace(result, t=result.t + (epoch - int(rec.start_ns)) * _NS)


def truth_from_recording(rec: Recording) -> TruthSeries | None:
    channel = rec.channels.get(TRUTH_TOPIC)
    if channel is None or len(channel) == 0:
        return None
    v = channel.values
    biaxial = rec.rig.beam.biaxial
    layout = row_layout("shm.TruthState", stations=len(rec.rig.truth_stations), biaxial=biaxial)
    if v.shape[1] != layout.width:
        raise ValueError(f"{rec.path}: {TRUTH_TOPIC} rows have {v.shape[1]} values; rig.json's {len(rec.rig.truth_stations)} "
                         f"truth stations give {layout.width}")
    col = layout.columns
    xi = (v[:, col("e_xi")].ravel(), v[:, col("deflection_xi")], v[:, col("curvature_xi")]) if biaxial else (None, None, None)
    return TruthSeries((channel.log_time_ns - rec.start_ns) * _NS, v[:, col("d")].ravel(), v[:, col("h")].ravel(),
                       v[:, col("phi")].ravel(), v[:, col("e")].ravel(), v[:, col("deflection")], v[:, col("curvature")], *xi)


def score_against_truth(result: EstimateResult, truth: TruthSeries, *, after: float) -> dict:
    """RMSE of the estimates against the truth at common sample times after ``after`` (s)."""
    idx = np.searchsorted(truth.t, result.t)
    idx = np.clip(idx, 0, truth.t.size - 1)
    match = (np.abs(truth.t[idx] - result.t) < 1e-6) & (result.t >= after)
    if not np.any(match):
        # A recording that never leaves its rest phase has nothing to score.
        keys: tuple[str, ...] = ("phi_deg", "e_m", "d_m", "deflection_m", "curvature_per_m")
        if truth.e_xi is not None and result.model.biaxial:
            keys += ("e_xi_m", "deflection_xi_m", "curvature_xi_per_m")
        return {"rmse": dict.fromkeys(keys), "nees": {"phi": None, "e": None}, "scored_samples": 0}
    i = idx[match]
    rms = lambda a: float(np.sqrt(np.mean(np.square(a))))  # noqa: E731
    phi_err = result.phi[match] - truth.phi[i]
    e_err = result.e[match] - truth.e[i]
    i_phi = result.model.state_layout.phi
    xi = {}
    if truth.e_xi is not None and truth.deflection_xi is not None and truth.curvature_xi is not None and result.model.biaxial:
        xi = {"e_xi_m": rms(result.e_xi[match] - truth.e_xi[i]),
              "deflection_xi_m": rms(result.deflection_xi()[match] - truth.deflection_xi[i]),
              "curvature_xi_per_m": rms(result.curvature_xi()[match] - truth.curvature_xi[i])}
    return {
        "rmse": {
            "phi_deg": rms(np.degrees(phi_err)),
            "e_m": rms(e_err),
            "d_m": rms(result.d[match] - truth.d[i]),
            "deflection_m": rms(result.deflection()[match] - truth.deflection[i]),
            "curvature_per_m": rms(result.curvature()[match] - truth.curvature[i]),
            **xi,
        },
        "nees": {
            "phi": None if i_phi is None else float(np.mean(phi_err**2 / result.P_diag[match, i_phi])),
            "e": float(np.mean(e_err**2 / result.var_e[match])),
        },
        "scored_samples": int(match.sum()),
    }


def estimate_payloads(result: EstimateResult) -> list[bytes]:
    """``/estimate/state`` payloads (contract's shm.EstimateState) for every estimate sample."""
    import orjson

    xi = (result.e_xi, result.deflection_xi(), result.curvature_xi()) if result.model.biaxial else None
    rows = _estimate_payloads(result.model.state_layout, result.x, result.P_diag, result.e, result.deflection(),
                              result.curvature(), xi)
    return [orjson.dumps(row) for row in rows]


def _virtual_loads(rig, model):
    """analytics.VirtualLoads of the rig's hot spots and a 16-station grid (BiaxialVirtualLoads for a
    model of both planes: each at its angle around the section), or None (no station to give)."""
    from analytics import BiaxialVirtualLoads, VirtualLoads

    try:
        if getattr(model, "units_xi", None) is not None:
            return BiaxialVirtualLoads.from_rig_biaxial(rig, model.units.curvature, model.units_xi.curvature)
        return VirtualLoads.from_rig(rig, model.units.curvature)
    except ValueError:
        return None


def _loads_of(loads, result: EstimateResult) -> dict:
    """The virtual loads of every estimate; a model of both planes' at each station's angle, an
    "all" hot spot at its worst point over the whole record."""
    layout = result.model.state_layout
    b = layout.b_of(result.x)
    if not hasattr(loads, "judge"):
        return loads(b)
    b_xi = layout.b_xi_of(result.x)
    loads.judge(b, b_xi)
    return loads(b, b_xi=b_xi)


def _xi_loads(out: dict, k: int) -> dict:
    """Estimate k's ξ figures of a biaxial /estimate/loads payload (none for a planar one)."""
    if "moment_xi_nm" not in out:
        return {}
    return {"moment_xi_nm": out["moment_xi_nm"][k].tolist(), "root_moment_xi_nm": float(out["root_moment_xi_nm"][k]),
            "root_moment_resultant_nm": float(out["root_moment_resultant_nm"][k])}


def write_estimates(path, rec: Recording, result: EstimateResult, *, extra_metadata: dict[str, str] | None = None) -> int:
    """Write the estimates (with rig.json, the truth metadata and the temperature, bearing and strain
    gauge channels of the source) into a new recording; returns the number of estimate messages."""
    import json

    from ..recording import ESTIMATE_TOPIC, RecordingWriter

    metadata = {name: dict(values) for name, values in rec.metadata.items()}
    metadata["estimator"] = {
        "selection": json.dumps(result.model.selection.as_dict()),
        "modes": str(result.model.gamma),
        **({"modes_xi": str(result.model.gamma_xi)} if result.model.biaxial else {}),
        "state_names": json.dumps(result.model.state_names),
        "calibration": json.dumps(result.calibration.as_dict()),
        **(extra_metadata or {}),
    }
    stamps = rec.start_ns + np.round(result.t * 1e9).astype(np.int64)
    loads = _virtual_loads(rec.rig, result.model)
    out = None if loads is None else _loads_of(loads, result)
    if loads is not None and out is not None:
        metadata["loads"] = {"stations_m": json.dumps(loads.positions.tolist()), "names": json.dumps(loads.names),
                             "youngs_modulus_pa": json.dumps(rec.rig.beam.youngs_modulus),
                             "note": "stress = youngs_modulus_pa x strain (reference temperature); moments at the reference temperature"}
        if "angles_deg" in out:  # both planes: each station's point around the section ("all": the worst found)
            metadata["loads"].update(angles_deg=json.dumps(out["angles_deg"].tolist()),
                                     worst_around=json.dumps(loads.worst_around.tolist()))
    with RecordingWriter(path, rec.rig, metadata=metadata) as writer:
        # the strain gauges too: `shm loads` of an estimate sees the modal truncation at them
        gauge_topics = tuple(s.topic for s in rec.rig.sensors_of("strain"))
        for topic in (TEMPERATURE_TOPIC, BEARING_TOPIC, *gauge_topics):
            channel = rec.channels.get(topic)
            if channel is None:
                continue
            key = "celsius" if topic == TEMPERATURE_TOPIC else "distance" if topic == BEARING_TOPIC else "strain"
            for lt, pt, value in zip(channel.log_time_ns.tolist(), channel.publish_time_ns.tolist(), channel.values[:, 0].tolist()):
                writer.write(topic, lt, {key: value}, pt)
        for stamp, payload in zip(stamps.tolist(), estimate_payloads(result)):
            writer.write(ESTIMATE_TOPIC, stamp, payload)
        if out is not None:  # each estimate's strain and moments at the hot spots and the grid
            root = out["root_moment_nm"] if out["root_moment_nm"] is not None else np.zeros(len(stamps))
            for k, (stamp, strain, moment, m0) in enumerate(zip(stamps.tolist(), out["strain"].tolist(), out["moment_nm"].tolist(),
                                                                root.tolist())):
                writer.write(ESTIMATE_LOADS_TOPIC, stamp, {"strain": strain, "moment_nm": moment, "root_moment_nm": m0,
                                                           **_xi_loads(out, k)})
    return len(stamps)


@dataclass(frozen=True)
class DeformationRecord:
    """What the analytics need from a recording: b(t) and its context (times in s from the start).

    support : the estimator's support displacement d(t) (m) on the times of b (the fused bearing
    sensor and IMU at D: the measured input of the identification), or None. origin_ns : data
    time of times = 0 (the recording's first message, UNIX ns). rest_end_s : end of the rest
    phase the estimator calibrated on (s), when known.
    """

    times: np.ndarray
    b: np.ndarray
    units: UnitDeformations
    stations: np.ndarray
    temperature: tuple[np.ndarray, np.ndarray] | None
    bearing: np.ndarray | None
    truth_metadata: dict[str, str] | None
    estimated_here: bool
    support: np.ndarray | None = None
    origin_ns: int = 0
    rest_end_s: float | None = None
    #: a biaxial beam's ξ plane: b_ξ(t) on ``times`` and its unit deformations (None: planar, or an
    #: estimate that did not estimate ξ)
    b_xi: np.ndarray | None = None
    units_xi: object | None = None


def deformation_record(rec: Recording, *, model_args: dict | None = None, settings=None) -> DeformationRecord:
    """b(t) of a recording: from its ``/estimate/state`` if it has one, else by running the estimator.

    ``model_args`` are passed to ``estimator.build_model`` when the estimator runs (and give Γ);
    ``settings`` (``estimator.StreamingSettings``) are its calibration, chunks and restart policy.
    """
    from estimator import assemble_beam, build_model, unit_deformations

    from ..recording import ESTIMATE_TOPIC

    estimates = rec.channels.get(ESTIMATE_TOPIC)
    rest_end = None
    b_xi = units_xi = None
    if estimates is not None and len(estimates):
        import json

        columns = [i for i, name in enumerate(estimates.fields) if name.startswith("b[")]
        if not columns:
            raise ValueError(f"{rec.path}: {ESTIMATE_TOPIC} carries no b")
        times = (estimates.log_time_ns - rec.start_ns) * _NS
        b = estimates.values[:, columns]
        support = estimates.values[:, estimates.fields.index("d")] if "d" in estimates.fields else None
        units = unit_deformations(assemble_beam(rec.rig), len(columns))
        # a biaxial estimate's ξ plane: its b_xi columns on the ξ beam's unit deformations
        columns_xi = [i for i, name in enumerate(estimates.fields) if name.startswith("b_xi[")]
        if columns_xi and rec.rig.beam.biaxial:
            b_xi = estimates.values[:, columns_xi]
            units_xi = unit_deformations(assemble_beam(rec.rig, plane="xi"), len(columns_xi))
        estimated_here = False
        try:  # written by `shm estimate --out`: the rest phase the estimator calibrated on
            calibration = json.loads(rec.metadata["estimator"]["calibration"])  # estimator.Calibration.as_dict()
            rest_end = float(calibration["rest_end_s"] if "rest_end_s" in calibration else calibration["rest_end"])
        except (KeyError, TypeError, ValueError):
            rest_end = None
    else:
        model = build_model(rec.rig, **(model_args or {}))
        result = estimate_recording(rec, model, settings)
        times, b, units = result.t, result.b, model.units
        # a biaxial model's ξ plane (ImmsModel.units_xi, EstimateResult.b_xi); a planar model has none
        units_xi = getattr(model, "units_xi", None)
        b_xi = None if units_xi is None else result.b_xi
        support = result.d
        estimated_here = True
        rest_end = float(result.calibration.rest_end)
    temperature = None
    channel = rec.channels.get(TEMPERATURE_TOPIC)
    if channel is not None and len(channel) >= 2:
        temperature = ((channel.log_time_ns - rec.start_ns) * _NS, channel.values[:, 0])
    bearing = None
    channel = rec.channels.get(BEARING_TOPIC)
    if channel is not None and len(channel) >= 2:
        bearing = np.interp(times, (channel.log_time_ns - rec.start_ns) * _NS, channel.values[:, 0])
    return DeformationRecord(times, b, units, np.asarray(rec.rig.truth_stations, dtype=float) if rec.rig.truth_stations
                             else np.linspace(0.0, rec.rig.beam.length, 9)[1:], temperature, bearing,
                             rec.metadata.get("truth"), estimated_here, support, int(rec.start_ns), rest_end, b_xi, units_xi)


#: Modes above the basis the band's missing strain is fitted with (at most the gauges less one).
OUTSIDE_MODES = 2


def outside_shapes(rig: Any, units: Any, count: int = OUTSIDE_MODES) -> Any:
    """``at(η) -> (len(η), K)``: the strain per unit amplitude −c ψ''_j of the rig's first ``count``
    natural modes above the unit deformations' highest frequency (those the basis does not hold)."""
    import numpy as np

    from estimator import assemble_beam, natural_modes

    top = max(float(np.max(np.atleast_1d(f))) for f in units.frequencies_hz)
    model = assemble_beam(rig)
    free = len(model.free_dofs)
    modes = natural_modes(model, min(free, len(units.frequencies_hz) + 2 + count))
    above = [j for j, f in enumerate(modes.frequencies_hz) if f > 1.02 * top][:count]
    beam = rig.beam

    def at(eta: Any) -> Any:
        x = np.atleast_1d(np.asarray(eta, dtype=float))
        psi = modes.shapes.evaluate(x, 2)[:, above]
        return -psi * np.asarray(beam.fibre_distance(x), dtype=float)[:, None]

    return at
