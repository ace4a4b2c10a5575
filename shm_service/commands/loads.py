"""``shm loads``: strain, stress, rainflow cycles, DELs and fatigue damage of a record.

DATA is either a contract recording — raw (the estimator runs first, with ``shm estimate``'s
options) or an estimate — whose virtual strain ε(η, t) = −c(η)·Σ b s''(η) is counted at the
stations (the rig's hot spots plus a grid, or ``--stations``), with the recording's strain gauges
counted as measured channels; or plain measured strain or stress channels in any format
``shm oma`` reads, counted directly.

The band of a virtual station (leave-one-gauge-out residuals, ``analytics.gauge_bands``): the strain
at unmeasured points comes from the unit deformations and misses what the structure does outside
their span. The gauges see it: at each gauge the DEL of the measured strain is compared with the
DEL of the virtual strain there from an estimate that did not use that gauge. On a raw recording
the estimator runs once more per gauge it used, without that gauge (an out-of-sample virtual
strain); on an estimate recording (no re-run possible) a gauge that aided the estimate is taken in
sample, its residual r widened to r/(1 − h) with the leverage h = ``UNKNOWN_LEVERAGE``. A gauge's
half-width a is max(ρ, 1/ρ) − 1 of the measured/virtual DEL factor ρ; a station at a gauge takes
its a; elsewhere no gauge sees the truncation, and the gauges' a are a sample of it: between two
gauges the larger of the two and the 80 % Student-t prediction from the gauges' a, beyond the
outermost the largest and the prediction, at least 2 %: [DEL/(1 + a), DEL·(1 + a)]; the damage
band is the damage of the counted cycles with their ranges scaled by those two factors. Without
gauges no band can be given, and the output says so.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypedDict

from .._argtypes import number
from ._around import XI_MISSING, parse_station_points, root_planes, station_points, station_signals, virtual_at_gauge, xi_of
from ._common import add_model_arguments

if TYPE_CHECKING:
    import numpy as np

    from analytics import HalfCyclePolicy

__all__ = ["add_loads_parser", "loads_of_recording", "loads_of_table", "parse_stations"]

#: The band's method, in the document (each station's a in its band).
_BAND_METHOD = ("calibrated on the gauges' cross-validated residuals (analytics.outside_basis_bands): at each gauge the "
                "virtual strain from an estimate without that gauge (raw recording: the estimator run again per gauge; each "
                "station then takes the wider of that band and the in-sample one) or the in-sample residual r/(1-h), "
                "h = {h:g} (estimate recording); the missing strain along the beam from the rig's "
                "modes above the basis and a floor fitted to the gauges' residual variances; the log-DEL error per unit relative "
                "residual, its 90 % conformal quantile over the gauges; ln(1+a) = that times the station's relative missing "
                "strain, at least the bracketing gauges' own (beyond them the largest), at least 2 %; band [DEL/(1+a), DEL*(1+a)]")
#: Young's modulus for plain strain channels without a rig (structural steel, Pa).
STEEL_YOUNGS_MODULUS = 2.1e11


class LoadsError(ValueError):
    """Bad input to ``shm loads`` (names the value)."""


def parse_stations(text: str, length: float) -> tuple[tuple[float, float], ...]:
    """'0.5,1.0@90,2' → stations (η m within [0, length], angle degrees; a plain η is at 0, the +ζ face)."""
    return parse_station_points(text, length, LoadsError)


def _exponents(text: str) -> tuple[float, ...]:
    try:
        values = tuple(float(p) for p in text.split(",") if p.strip())
    except ValueError:
        raise LoadsError(f"--exponents {text!r} must list numbers, e.g. 3,5") from None
    bad = [v for v in values if not (math.isfinite(v) and v > 0)]
    if not values or bad:
        raise LoadsError(f"--exponents {text!r}: Wöhler exponents must be > 0" + (f", got {bad[0]}" if bad else ""))
    return values


def _detail(curve: Any, scf: float = 1.0, gamma_ff: float = 1.0, gamma_mf: float = 1.0):
    from analytics import FatigueDetail, sn_curve

    try:
        return FatigueDetail(sn_curve(curve), scf=scf, gamma_ff=gamma_ff, gamma_mf=gamma_mf)
    except ValueError as exc:
        raise LoadsError(str(exc)) from None


def _life(damage: float | None, duration_s: float, design_life_years: float | None) -> dict[str, Any]:
    """The life the counted span's load would give if it went on: duration/D, or no damage below the cut-off."""
    from analytics import SECONDS_PER_YEAR

    if damage is None:
        return {"life_at_this_load_years": None, "life_verdict": None}
    if damage == 0.0:
        return {"life_at_this_load_years": None, "life_verdict": "no_damage_below_cutoff"}
    years = duration_s / damage / SECONDS_PER_YEAR
    return {"life_at_this_load_years": years, "life_verdict": "finite",
            "exhausts_design_life_early": None if design_life_years is None else bool(years < design_life_years)}


def _signal_doc(loads, *, to_stress: float | None, band=None) -> dict[str, Any]:
    """The per-station / per-channel JSON of the issue: strain in m/m, stress in Pa (None without E)."""
    pairs, width = loads.cycles_by_range()
    dels = []
    for m, n_eq, value in loads.dels:
        entry = {"m": m, "n_eq": n_eq, "strain_range": value, "stress_range_pa": None if to_stress is None else value * to_stress,
                 "band": None if band is None else [value * band.low, value * band.high]}
        if band is not None and to_stress is not None:
            entry["stress_band_pa"] = [value * band.low * to_stress, value * band.high * to_stress]
        dels.append(entry)
    return {"strain_rms": loads.rms, "strain_range_max": loads.range_max, "del": dels, "damage": loads.damage,
            "damage_band": None if loads.damage_band is None else list(loads.damage_band),
            "cycles": loads.cycles.total, "cycles_by_range": pairs, "cycles_bin_width": width}


def _time_span(times: np.ndarray, start: float) -> tuple[np.ndarray, float, float]:
    import numpy as np

    keep = times >= start
    if not np.any(keep):
        raise LoadsError(f"nothing to count at or after {start} s (the record ends at {times[-1]:.3f} s)")
    t = times[keep]
    dt = float(np.median(np.diff(t))) if t.size > 1 else 0.0
    return keep, float(t[0] - times[0]), float(t[-1] - t[0] + dt)


def gauge_band(gauges: list[tuple[str, float, Any, Any, float]], stations: Any, *, exponents: tuple[float, ...],
               n_eq: float, half_cycles: Any = "half", outside_at: Any = None, station_rms: Any = None) -> tuple[Any, list[dict]]:
    """The bands of the virtual stations from the gauges: calibrated on their cross-validated residuals
    and carried along the beam by the modes above the basis (``analytics.outside_basis_bands``) when
    ``outside_at`` and the stations' virtual strain RMS are given, else ``analytics.gauge_bands``."""
    import numpy as np

    from analytics import OutsideBasis, gauge_bands, outside_basis_bands

    if outside_at is None or station_rms is None or not gauges:
        return gauge_bands(gauges, stations, exponents=exponents, n_eq=n_eq, half_cycles=half_cycles)
    outside = OutsideBasis(outside_at(np.array([p for _, p, *_ in gauges])), outside_at(np.asarray(stations, dtype=float)),
                           np.asarray(station_rms, dtype=float))
    return outside_basis_bands(gauges, stations, outside, exponents=exponents, n_eq=n_eq, half_cycles=half_cycles)


#: A gauge whose measured strain and the virtual strain there differ by more than this (RMS of the difference
#: over the measured RMS) says the estimate does not hold the structure's curvature: no damage or life figure.
WITHHOLD_DISCREPANCY = 1.0
#: What to change when the virtual strain does not hold (the reason's second half).
WITHHOLD_REMEDY = ("more unit deformations (--modes), more IMUs (--imus), or a band-limit on the gauges' aiding "
                   "(--aided: aid only the unit deformations whose modes the gauges resolve)")


def withhold_figures(stations: list[dict[str, Any]], gauges: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Null the damage and life figures of stations whose virtual strain disagrees with the measured
    gauges by more than its band (in place); the list of what was withheld, each with its reason.

    A station is withheld when its band is wider than ±``analytics.WITHHOLD_HALF_WIDTH`` of the DEL,
    or every station is when a gauge's strain RMS discrepancy exceeds ``WITHHOLD_DISCREPANCY``."""
    from analytics import WITHHOLD_HALF_WIDTH

    worst = max(((g.get("strain_rms_discrepancy") or 0.0, g["name"]) for g in gauges), default=(0.0, None))
    out = []
    for s in stations:
        width = s.get("band_half_width")
        reason = None
        if worst[0] > WITHHOLD_DISCREPANCY:
            reason = (f"the virtual strain differs from strain gauge {worst[1]} by {worst[0]:.0%} of its RMS "
                      f"(more than {WITHHOLD_DISCREPANCY:.0%}): the estimate does not hold the structure's curvature")
        elif width is not None and width > WITHHOLD_HALF_WIDTH:
            reason = (f"the DEL band is ±{width:.0%} (wider than ±{WITHHOLD_HALF_WIDTH:.0%}): virtual and measured strain "
                      "disagree beyond what a damage figure can carry")
        if reason is None:
            continue
        reason = f"{reason}; change: {WITHHOLD_REMEDY}"
        s.update(damage=None, damage_band=None, life_at_this_load_years=None, life_verdict="withheld",
                 exhausts_design_life_early=None, withheld_reason=reason)
        out.append({"position_m": s["position_m"], "hot_spot": s.get("hot_spot"), "reason": reason})
    return out


def loads_of_recording(rec, *, record=None, model_args: dict, stations: tuple[Any, ...] | None, curve: Any, exponents: tuple[float, ...],
                       n_eq: float | None, half_cycles: HalfCyclePolicy, start_s: float | None, window_s: float | None = None,
                       leave_one_out: bool | None = None) -> dict[str, Any]:
    """The ``shm loads`` document of a contract recording (raw or estimate); with ``window_s`` also
    per window of that length (each counted on its own, its band from that window's gauges).

    ``leave_one_out``: re-run the estimator on ``rec`` (raw: its IMUs and aiding) with ``model_args``
    once per gauge the estimate used, without that gauge, for the band; default: when the estimate
    is made here. ``stations``: positions (m, the +ζ face) or (η, angle in degrees) pairs."""
    import numpy as np

    from analytics import UNKNOWN_LEVERAGE
    from contract import RigError

    from ..processing.estimation import deformation_record

    rig = rec.rig
    beam = rig.beam
    if record is None:
        try:
            record = deformation_record(rec, model_args=model_args)
        except ValueError as exc:
            raise LoadsError(str(exc)) from None
    times, b, units = record.times, record.b, record.units
    start = start_s if start_s is not None else (record.rest_end_s or 0.0)
    keep, span_start, duration = _time_span(times, start)
    t = times[keep]
    n_eq_value = n_eq if n_eq is not None else duration  # 1 Hz equivalent

    points, spots = station_points(rig, stations)
    positions = [p for p, _ in points]
    xi = xi_of(record, keep)
    # E(T) and EI(T) follow the temperature through the beam's coefficient
    factor = np.ones(t.size)
    if record.temperature is not None:
        temp = np.interp(t, *record.temperature)
        factor = 1.0 + beam.youngs_modulus_temperature_coefficient * (temp - beam.reference_temperature)
    # stress is E·ε for rectangles and tubes; a beam of table sections only has no E: strain and moment only
    youngs = None if beam.youngs_modulus is None else beam.youngs_modulus * factor
    default_detail = None if curve is None else _detail(curve)
    try:
        strain, moment, around = station_signals(
            beam, b[keep], units, xi, points, spots, factor, exponents=exponents, n_eq=n_eq_value, half_cycles=half_cycles,
            detail_of=lambda spot: default_detail if spot is None else _detail(spot.curve, spot.scf, spot.gamma_Ff, spot.gamma_Mf))
    except RigError as exc:  # an angle a planar beam does not have
        raise LoadsError(f"--stations: {exc}") from None

    compared, gauge_masks = _gauge_comparisons(rec, t, b[keep], units, beam, xi)
    judged, bands, gauge_rows, beyond = _station_bands(rec, record, model_args, leave_one_out, compared, gauge_masks, t, units, positions,
                                                       np.sqrt(np.mean(strain**2, axis=0)), exponents=exponents, n_eq=n_eq_value,
                                                       half_cycles=half_cycles)

    design = rig.fatigue.design_life_years if rig.fatigue is not None else None
    stress_of = _StressOf(youngs=youngs, exponents=exponents, n_eq=n_eq_value, half_cycles=half_cycles, duration=duration, design=design)
    out_stations = [{**_station_doc(pos, spots.get(key), strain[:, j], moment[:, j], beam, default_detail,
                                   band=None if bands is None else bands[j], **stress_of), **around[j]}
                    for j, (pos, key) in enumerate(zip(positions, points))]

    channels = _channel_docs(judged, beam, default_detail, exponents=exponents, n_eq=n_eq_value, half_cycles=half_cycles,
                             duration=duration, design=design)

    withheld = withhold_figures(out_stations, gauge_rows)
    root = _root_moment(b[keep], units, beam, factor, exponents, n_eq_value, half_cycles) if rig.support == "clamped" else None
    if root is not None and xi is not None:
        root = root_planes(root, b[keep], units, xi, beam, factor, exponents, n_eq_value, half_cycles)
    return {
        "start_s": span_start, "duration_s": duration, "source": "virtual strain from the estimate" + (
            " (estimated here)" if record.estimated_here else ""),
        "half_cycles": half_cycles,
        "band_method": _BAND_METHOD.format(h=UNKNOWN_LEVERAGE) if bands is not None else ("no strain gauge samples in the recording (an estimate written before it carried the gauges, or a rig "
                                                                   "without gauges): the modal truncation cannot be seen, no band"),
        "gauges": gauge_rows,
        "stations": out_stations,
        "withheld": withheld,
        "channels": channels,
        "root_bending_moment": root,
        "windows": None if window_s is None else _windows(t, strain, judged, gauge_masks, positions, window_s, exponents=exponents, outside_at=beyond,
                                                          half_cycles=half_cycles, origin=float(times[0]), angles=[a["angle_deg"] for a in around]),
        **({"warnings": [XI_MISSING]} if beam.biaxial and xi is None else {}),
    }


def _station_bands(rec: Any, record: Any, model_args: dict, leave_one_out: bool | None, compared: list, gauge_masks: list, t: Any,
                   units: Any, positions: list[float], station_rms: Any, *, exponents: tuple[float, ...], n_eq: float,
                   half_cycles: HalfCyclePolicy) -> tuple[list, Any, Any, Any]:
    """The gauges as judged (out of sample where the estimate is made here), the stations' bands, the
    gauges' rows and the modes above the basis at the stations."""
    from analytics import UNKNOWN_LEVERAGE

    from ..processing.estimation import outside_shapes

    beam = rec.rig.beam
    used = _gauges_used(rec, record, model_args)
    loo = record.estimated_here if leave_one_out is None else leave_one_out
    own = [(n, p, v, m, UNKNOWN_LEVERAGE if n in used else 0.0) for n, p, v, m in compared]
    judged = _out_of_sample(rec, compared, gauge_masks, t, used, model_args, beam) if loo else own
    beyond = outside_shapes(rec.rig, units)
    bands, gauge_rows = gauge_band(judged, positions, exponents=exponents, n_eq=n_eq, half_cycles=half_cycles,
                                   outside_at=beyond, station_rms=station_rms)
    if loo and bands is not None:
        # the estimate's own residuals too (in sample, widened by 1/(1 - h)): an estimate without a gauge
        # errs otherwise than the one with all of them; each station takes the wider of the two bands
        inside, _rows = gauge_band(own, positions, exponents=exponents, n_eq=n_eq, half_cycles=half_cycles,
                                   outside_at=beyond, station_rms=station_rms)
        if inside is not None:
            bands = [x if x.high >= y.high else y for x, y in zip(bands, inside)]
    return judged, bands, gauge_rows, beyond


def _channel_docs(judged: list, beam: Any, default_detail: Any, *, exponents: tuple[float, ...], n_eq: float, half_cycles: HalfCyclePolicy,
                  duration: float, design: float | None) -> list[dict[str, Any]]:
    """The measured gauges' own loads and life, beside the virtual ones."""
    from analytics import signal_loads

    channels = []
    for name, position, _virtual, measured, _h in judged:
        gl = signal_loads(measured, exponents=exponents, n_eq=n_eq, half_cycles=half_cycles, name=f"strain gauge {name}",
                          detail=default_detail if beam.youngs_modulus is not None else None, to_stress=beam.youngs_modulus or 1.0)
        gdoc = _signal_doc(gl, to_stress=beam.youngs_modulus)
        channels.append({"name": name, "position_m": position, **gdoc, **_life(gdoc["damage"], duration, design)})
    return channels


def _gauge_comparisons(rec: Any, t: Any, b: Any, units: Any, beam: Any,
                       xi: tuple[Any, Any] | None = None) -> tuple[list[tuple[str, float, Any, Any]], list[Any]]:
    """The gauges' measured strain against the virtual strain at their points of the section, on the
    estimate's times ``t`` (s) inside each gauge's span: ([(name, position, virtual, measured)], [masks of t]);
    ``xi``: (b_ξ, ξ unit deformations) of a biaxial estimate."""
    import numpy as np

    gauges, gauge_masks = [], []
    for sensor in rec.rig.sensors_of("strain"):
        channel = rec.channels.get(sensor.topic)
        if channel is None or len(channel) < 2:
            continue
        tg = (channel.log_time_ns - rec.start_ns) * 1e-9
        inside = (t >= tg[0]) & (t <= tg[-1])
        if inside.sum() < 2:
            continue
        measured = np.interp(t[inside], tg, channel.values[:, 0])
        virtual = virtual_at_gauge(beam, sensor, b[inside], units, None if xi is None else (xi[0][inside], xi[1]))
        gauges.append((sensor.name, float(sensor.position), virtual, measured))
        gauge_masks.append(inside)
    return gauges, gauge_masks



class _StressOf(TypedDict):
    """The keywords every station's ``_station_doc`` shares."""

    youngs: Any
    exponents: Any
    n_eq: float
    half_cycles: HalfCyclePolicy
    duration: float
    design: float | None


def _station_doc(pos: float, spot: Any, strain: Any, moment: Any, beam: Any, default_detail: Any, *, youngs: Any, exponents: Any,
                 n_eq: float, half_cycles: HalfCyclePolicy, band: Any, duration: float, design: float | None) -> dict[str, Any]:
    """One station's entry of the ``shm loads`` document: strain counted, and stress counted on its
    own when the beam has an E (E follows the temperature sample by sample)."""
    import numpy as np

    from analytics import signal_loads

    detail = _detail(spot.curve, spot.scf, spot.gamma_Ff, spot.gamma_Mf) if spot is not None else default_detail
    el = signal_loads(strain, exponents=exponents, n_eq=n_eq, half_cycles=half_cycles, name=f"strain at {pos} m")
    doc = _signal_doc(el, to_stress=beam.youngs_modulus, band=band)
    stress_rms = None
    if youngs is not None:
        sl = signal_loads(strain * youngs, exponents=exponents, n_eq=n_eq, half_cycles=half_cycles, detail=detail,
                          band=band, name=f"stress at {pos} m")
        for entry, (_, _, s_del) in zip(doc["del"], sl.dels):
            entry["stress_range_pa"] = s_del
            if band is not None:
                entry["stress_band_pa"] = [s_del * band.low, s_del * band.high]
        doc.update(damage=sl.damage, damage_band=None if sl.damage_band is None else list(sl.damage_band))
        stress_rms = sl.rms
    return {"position_m": pos, "hot_spot": None if spot is None else spot.name,
            "band_half_width": None if band is None else band.high - 1.0,
            "curve": None if detail is None else detail.curve.name, **doc, **_life(doc["damage"], duration, design),
            "stress_rms_pa": stress_rms, "bending_moment_rms_nm": float(np.sqrt(np.mean(moment ** 2))),
            "bending_moment_range_max_nm": float(np.ptp(moment))}


def _root_moment(b: Any, units: Any, beam: Any, factor: Any, exponents: Any, n_eq: float, half_cycles: HalfCyclePolicy) -> dict[str, Any]:
    """The root bending moment of a clamped support, counted (N·m)."""
    import numpy as np

    from analytics import bending_moment, signal_loads

    k0 = b @ units.curvature(np.array([0.0])).T
    m0 = bending_moment(k0, beam.bending_stiffness([0.0]))[:, 0] * factor
    rl = signal_loads(m0, exponents=exponents, n_eq=n_eq, half_cycles=half_cycles, name="root bending moment")
    return {"position_m": 0.0, "rms_nm": rl.rms, "range_max_nm": rl.range_max,
            "del": [{"m": m, "n_eq": n, "moment_range_nm": v} for m, n, v in rl.dels]}


def _windows(t, strain, gauges, gauge_masks, positions, window_s: float, *, exponents, half_cycles: HalfCyclePolicy, origin: float,
             outside_at: Any = None, angles: Any = None) -> list[dict[str, Any]]:
    """Per window of ``window_s`` (1 Hz equivalent): each station's strain DEL with the band of that window's gauges."""
    import numpy as np

    from analytics import signal_loads

    out = []
    edges = np.arange(t[0], t[-1] + 1e-9, window_s)
    for a in edges:
        sel = (t >= a) & (t < a + window_s)
        if sel.sum() < 2 or (t[sel][-1] - t[sel][0]) < 0.5 * window_s:
            continue
        duration = float(sel.sum()) * float(np.median(np.diff(t)))
        # each gauge's samples lie on t[mask]: its part of the window is sel[mask]
        g = [(n, p, v[sel[mask]], m[sel[mask]], h) for (n, p, v, m, h), mask in zip(gauges, gauge_masks) if sel[mask].sum() >= 2]
        bands, _rows = gauge_band(g, positions, exponents=exponents, n_eq=duration, half_cycles=half_cycles, outside_at=outside_at,
                                  station_rms=np.sqrt(np.mean(strain[sel] ** 2, axis=0))) if g else (None, [])
        rows = []
        for j, pos in enumerate(positions):
            band = None if bands is None else bands[j]
            sl = signal_loads(strain[sel, j], exponents=exponents, n_eq=duration, half_cycles=half_cycles, name=f"strain at {pos} m")
            rows.append({"position_m": pos, **({} if angles is None else {"angle_deg": angles[j]}),
                         "band_half_width": None if band is None else band.high - 1.0,
                         "del": [{"m": m, "n_eq": n, "strain_range": v, "band": None if band is None else [v * band.low, v * band.high]}
                                 for m, n, v in sl.dels]})
        out.append({"start_s": float(a - origin), "duration_s": duration,
                    "band_half_width": None if bands is None else max(x.high for x in bands) - 1.0, "stations": rows})
    return out


def _out_of_sample(rec: Any, gauges: list, gauge_masks: list, t: Any, used: tuple[str, ...], model_args: dict,
                   beam: Any) -> list[tuple[str, float, Any, Any, float]]:
    """The gauges with the virtual strain at each from an estimate that did not use it: the estimator
    run again on ``rec`` without that gauge (the rest of ``model_args`` kept; the aided unit
    deformations left to the estimator, which picks them for the gauges it has). A gauge the
    estimate did not use is out of sample already. (name, position, virtual, measured, leverage 0)."""

    from analytics import UNKNOWN_LEVERAGE
    from estimator import UnobservableRig

    from ..processing.estimation import deformation_record

    sensors = {s.name: s for s in rec.rig.sensors_of("strain")}
    out = []
    for (name, position, virtual, measured), mask in zip(gauges, gauge_masks):
        if name in used:
            others = tuple(g for g in used if g != name)
            args = {k: v for k, v in model_args.items() if k != "aided"}
            try:
                again = deformation_record(rec, model_args=dict(args, gauges=others))
            except UnobservableRig:
                # the other gauges alone cannot hold the unit deformations (a mast without ToFs and
                # as many gauges as modes): this gauge's residual stays in sample, widened by the
                # leverage bound, and its row says so ("out_of_sample": false)
                out.append((name, position, virtual, measured, UNKNOWN_LEVERAGE))
                continue
            except ValueError as exc:
                raise LoadsError(f"the band's re-estimate without gauge {name}: {exc}") from None
            if not again.estimated_here:  # an estimate recording gives its own b again: that is not out of sample
                raise LoadsError(f"{rec.path} is an estimate recording: no gauge can be left out of it (give the raw recording)")
            xi = xi_of(again)
            virtual = virtual_at_gauge(beam, sensors[name], _resampled(t[mask], again.times, again.b), again.units,
                                       None if xi is None else (_resampled(t[mask], again.times, xi[0]), xi[1]))
        out.append((name, position, virtual, measured, 0.0))
    return out


def _resampled(t: Any, times: Any, values: Any) -> Any:
    """Columns of ``values`` (on ``times``) interpolated onto ``t`` (s)."""
    import numpy as np

    return np.column_stack([np.interp(t, times, values[:, k]) for k in range(values.shape[1])])


def _gauges_used(rec, record, model_args: dict) -> tuple[str, ...]:
    """The gauges the estimate was aided by (their discrepancy is in-sample), from the estimator's
    metadata of an estimate recording or from the model the estimator ran with here."""
    if not record.estimated_here:
        try:
            return tuple(json.loads(rec.metadata["estimator"]["selection"]).get("gauges", ()))
        except (KeyError, TypeError, ValueError):
            return tuple(s.name for s in rec.rig.sensors_of("strain"))  # unknown: assume in-sample (wider band)
    from estimator import build_model

    return tuple(build_model(rec.rig, **model_args).selection.gauges)


def loads_of_table(table, *, curve: Any, exponents: tuple[float, ...], n_eq: float | None, half_cycles: HalfCyclePolicy,
                   quantity: str, youngs_modulus: float, start_s: float | None) -> dict[str, Any]:
    """The ``shm loads`` document of plain measured channels (strain m/m or stress Pa), counted directly."""
    import numpy as np

    from analytics import signal_loads

    if quantity not in ("strain", "stress"):
        raise LoadsError(f"--quantity {quantity!r} must be strain or stress")
    n = table.data.shape[0]
    times = table.time - table.time[0] if table.time is not None else np.arange(n) / float(table.fs_hz)
    keep, span_start, duration = _time_span(np.asarray(times, dtype=float), start_s or 0.0)
    n_eq_value = n_eq if n_eq is not None else duration
    detail = None if curve is None else _detail(curve)
    channels = []
    for j, name in enumerate(table.channels):
        x = table.data[keep, j]
        strain = x if quantity == "strain" else x / youngs_modulus
        sl = signal_loads(strain, exponents=exponents, n_eq=n_eq_value, half_cycles=half_cycles, detail=detail,
                          to_stress=youngs_modulus, name=f"channel {name}")
        cdoc = _signal_doc(sl, to_stress=youngs_modulus)
        channels.append({"name": name, **cdoc, **_life(cdoc["damage"], duration, None)})
    # a unit row that says the channel is not in the quantity's SI unit (volts, µε, MPa): say so, do not guess a scale
    expected = {"strain": ("m/m", "strain", "-", "1", ""), "stress": ("pa", "n/m2", "n/m²")}[quantity]
    warnings = [f"channel {name!r} is in {unit!r}, not {'m/m' if quantity == 'strain' else 'Pa'}: the figures are in that unit; "
                "scale it first (shm import's channel map has scale and offset)"
                for name, unit in zip(table.channels, table.units or ()) if unit is not None and unit.strip().lower() not in expected]
    return {"start_s": span_start, "duration_s": duration, "source": f"measured {quantity} channels ({table.format})",
            "half_cycles": half_cycles, "youngs_modulus_pa": youngs_modulus, "stations": [], "channels": channels,
            "warnings": warnings}


def _cmd_loads(args: argparse.Namespace) -> int:
    from ._common import CliError, model_kwargs
    from ..formats.tables import TableError, read_table, select_channels

    try:
        exponents = _exponents(args.exponents)
        curve = None
        if args.curve:
            curve = json.loads(args.curve) if args.curve.lstrip().startswith("{") else args.curve
            _detail(curve)
        doc = None
        if Path(args.data).suffix.lower() == ".mcap" and not args.channels:
            from ..recording import read_recording
            from ..recording._reader import RecordingError

            try:
                rec = read_recording(args.data, rig=args.rig)
            except RecordingError as exc:
                if "rig.json" not in str(exc):
                    raise
                rec = None  # a plain MCAP of channels: counted as a table
            if rec is not None:
                stations = parse_stations(args.stations, rec.rig.beam.length) if args.stations else None
                model_args = model_kwargs(rec.rig, args)
                if args.aided:
                    model_args["aided"] = tuple(int(a) for a in args.aided.split(","))
                doc = loads_of_recording(rec, model_args=model_args, stations=stations, curve=curve, exponents=exponents,
                                         n_eq=args.neq, half_cycles=args.half_cycles, start_s=args.start, window_s=args.window)
        if doc is None:
            if args.stations:
                raise LoadsError("--stations needs a contract recording (plain channels are counted where they were measured)")
            table = read_table(args.data, fs=args.fs)
            names = [c.strip() for c in args.channels.split(",") if c.strip()] if args.channels else None
            table = select_channels(table, names)
            doc = loads_of_table(table, curve=curve, exponents=exponents, n_eq=args.neq, half_cycles=args.half_cycles,
                                 quantity=args.quantity, youngs_modulus=args.youngs_modulus, start_s=args.start)
    except (LoadsError, TableError, json.JSONDecodeError) as exc:
        raise CliError(str(exc)) from None
    except ValueError as exc:  # a NaN sample, a bad curve: the message names it
        raise CliError(str(exc)) from None
    if args.json:
        print(json.dumps(doc, indent=2, allow_nan=False))
        return 0
    _print_table(doc)
    return 0


def _print_table(doc: dict[str, Any]) -> None:
    print(f"{doc['source']}: {doc['duration_s']:.3f} s counted from {doc['start_s']:.3f} s; half cycles: {doc['half_cycles']}")
    if doc.get("band_method"):
        print(f"band: {doc['band_method']}")
    for warning in doc.get("warnings") or ():
        print(f"warning: {warning}")
    withheld = doc.get("withheld") or ()
    if withheld:
        print(f"withheld: damage and life of {len(withheld)} station(s): {withheld[0]['reason']}")

    def row(label: str, s: dict[str, Any]) -> str:
        dels = "  ".join(
            f"DEL{e['m']:g} {1e6 * e['strain_range']:.3f} µε"
            + ("" if e["stress_range_pa"] is None else f" {e['stress_range_pa'] / 1e6:.3f} MPa")
            + (f" [{1e6 * e['band'][0]:.3f}, {1e6 * e['band'][1]:.3f}] µε" if e["band"] else "")
            for e in s["del"])
        damage = "-" if s["damage"] is None else f"{s['damage']:.3e}"
        if s.get("life_verdict") == "finite":
            damage += f" (life at this load {s['life_at_this_load_years']:.3g} years)"
        elif s.get("life_verdict") == "withheld":
            damage += " (withheld: see above)"
        elif s.get("life_verdict") == "no_damage_below_cutoff":
            damage += " (below the cut-off: nothing consumed)"
        return (f"{label:>22}  rms {1e6 * s['strain_rms']:9.3f} µε  max range {1e6 * s['strain_range_max']:9.3f} µε  {dels}  "
                f"D {damage}  cycles {s['cycles']:g}")

    for s in doc["stations"]:
        # a planar station on the +ζ face reads as before; another point of the section names its angle
        at = f" @{s['angle_deg']:g}°" + (" (worst around)" if s.get("angle_spec") == "all" else "") if s.get("angle_deg") else ""
        print(row(f"{s['position_m']:.3f} m{at}" + (f" {s['hot_spot']}" if s["hot_spot"] else ""), s))
    root = doc.get("root_bending_moment") or {}
    if "resultant" in root:
        print(f"root bending moment: Mζ rms {root['zeta']['rms_nm']:.4g} N·m, Mξ rms {root['xi']['rms_nm']:.4g} N·m, "
              f"resultant rms {root['resultant']['rms_nm']:.4g} N·m, max {root['resultant']['max_nm']:.4g} N·m")
    for c in doc["channels"]:
        print(row(str(c["name"]), c))


def add_loads_parser(sub) -> None:
    """Register ``shm loads`` (called by shm_service.cli.build_parser)."""
    p = sub.add_parser("loads", help="strain, stress, rainflow cycles, DELs and fatigue damage: virtual strain at stations of a "
                                     "contract recording, or measured channels in any format shm oma reads")
    p.add_argument("data", help="a contract recording (raw or estimate .mcap) or measured channels (.npy/.npz, CSV/TSV/text, .mat, HDF5, .mcap)")
    p.add_argument("--stations", default=None, metavar="η[@θ],...",
                   help="stations, m from D, each optionally @ its angle around the section in degrees from +ζ towards +ξ "
                        "(5.0@45; a plain 5.0 is the +ζ face; a planar beam has only 0 and 180) (default: the rig's hot spots "
                        "and 15 stations at L/16 steps)")
    p.add_argument("--channels", default=None, help="measured channels to count, names or column indices: A,B,...")
    p.add_argument("--fs", type=number(low=0, low_open=True, unit="Hz"), default=None, help="sample rate, Hz (without a time column)")
    p.add_argument("--quantity", choices=("strain", "stress"), default="strain", help="what plain channels hold: strain (m/m) or stress (Pa)")
    p.add_argument("--youngs-modulus", type=number(low=0, low_open=True, unit="Pa"), default=STEEL_YOUNGS_MODULUS, metavar="PA",
                   help="E for plain channels, Pa (default 2.1e11, steel)")
    p.add_argument("--curve", default=None, help="S-N curve for stations without a hot spot and for channels: EN1993-1-9:71, "
                                                 "DNV-RP-C203:D:air, or JSON {\"points\": [[N, Pa], ...]} (default: no damage)")
    p.add_argument("--neq", type=number(low=0, low_open=True), default=None, metavar="N",
                   help="equivalent cycles of the DELs (default: 1 Hz equivalent, the counted duration in s)")
    p.add_argument("--exponents", default="3,5", metavar="m,...", help="Wöhler exponents of the DELs (default 3,5)")
    p.add_argument("--half-cycles", choices=("half", "full", "ignore"), default="half",
                   help="the residue's half cycles: half (ASTM E1049, default), full (conservative) or ignore")
    p.add_argument("--window", type=number(low=0, low_open=True, unit="s"), default=None, metavar="S",
                   help="also per window of S s (a contract recording): each station's DEL with its window's band")
    p.add_argument("--start", type=number(low=0, unit="s"), default=None, metavar="S",
                   help="count from S seconds into the record (default: the estimator's rest-phase end, else 0)")
    add_model_arguments(p)  # shm estimate's options, for raw recordings
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_cmd_loads)
