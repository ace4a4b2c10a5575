"""`shm loads` around the section of a beam that bends in two planes: strain at any angle from both
curvatures, the worst point of a girth weld, the root moment per plane with its resultant; checked
against the biaxial virtual rig's truth (its gauges at 0°, 90° and 45° are exact, ideal and noiseless)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import pytest

from analytics import around_angles, section_strain, signal_loads
from contract import parse_rig
from estimator import assemble_beam, unit_deformations
from shm_service.commands.loads import LoadsError, loads_of_recording, parse_stations
from shm_service.processing.estimation import DeformationRecord
from shm_service.virtual_rig import SensorErrors, SimulationSettings, VirtualRig

NO_ERRORS = SensorErrors(**{name: 0.0 for name in SensorErrors.model_fields if name != "bias_correlation_time"})
LENGTH, HALF = 3.0, 1.5
STATIONS = [round(0.25 * k, 9) for k in range(1, 13)]  # the truth's stations, every 0.25 m
WIND_DEG = 30.0
RADIUS = 0.05


def tube_rig(*, bending: str = "biaxial", hot_spots=()):
    """A uniform steel tube, clamped, standing, IMUs at L/2 and L, gauges at L/2 around the section."""
    gauges = [{"name": "g0", "kind": "strain", "position": HALF}]
    if bending == "biaxial":
        gauges += [{"name": "g90", "kind": "strain", "position": HALF, "angle_deg": 90},
                   {"name": "g45", "kind": "strain", "position": HALF, "angle_deg": 45}]
    tube = {"shape": "tube", "outer_diameter": 2 * RADIUS, "wall_thickness": 0.004}
    return parse_rig({
        "beam": {"length": LENGTH, "youngs_modulus": 2.1e11, "density": 7850.0, "bending": bending,
                 "sections": [{"position": 0.0, **tube}, {"position": LENGTH, **tube}]},
        "gravity": 9.81, "support": "clamped", "orientation": "standing",
        "sensors": [{"name": "D", "kind": "imu", "position": 0.0}, {"name": "m", "kind": "imu", "position": HALF},
                    {"name": "tip", "kind": "imu", "position": LENGTH}, *gauges],
        "truth_stations": STATIONS, "hot_spots": list(hot_spots),
    })


@dataclass(frozen=True)
class Channel:
    log_time_ns: np.ndarray
    values: np.ndarray

    def __len__(self) -> int:
        return self.values.shape[0]


@dataclass(frozen=True)
class Record:
    """What ``loads_of_recording`` reads of a recording: its rig and gauges (an estimate's b is given)."""

    rig: object
    channels: dict
    start_ns: int = 0
    metadata: dict = field(default_factory=dict)
    path: str = "the virtual rig"


@pytest.fixture(scope="module")
def biaxial():
    """60 s of the tube in a wind acting at 30° (no veer): the recording's gauges, the truth, and a record
    of b, b_ξ fitted to the truth's curvature in each plane."""
    rig = tube_rig(hot_spots=[{"name": "girth", "position": HALF, "curve": "EN1993-1-9:71", "angle_deg": "all"},
                              {"name": "base", "position": 0.25, "curve": "EN1993-1-9:71", "angle_deg": 45}])
    settings = SimulationSettings(duration=60.0, rest=1.0, ideal=True, seed=7, errors=NO_ERRORS, excitation="ambient",
                                  support="clamped", orientation="standing", length=LENGTH,
                                  wind_direction={"mean_deg": WIND_DEG, "veer_deg": 0.0})
    blocks = list(VirtualRig(settings, rig).blocks(20.0))
    times = np.concatenate([b.times for b in blocks])
    kappa, kappa_xi = (np.concatenate([b.truth[key] for b in blocks]) for key in ("curvature", "curvature_xi"))
    channels = {}
    for sensor in rig.sensors_of("strain"):
        t = np.concatenate([b.measurements[sensor.topic][0] for b in blocks])
        channels[sensor.topic] = Channel(np.round(t * 1e9).astype(np.int64),
                                         np.concatenate([b.measurements[sensor.topic][1] for b in blocks]).reshape(t.size, -1))
    units = unit_deformations(assemble_beam(rig), 4)
    units_xi = unit_deformations(assemble_beam(rig, plane="xi"), 4)
    b = np.linalg.lstsq(units.curvature(np.array(STATIONS)), kappa.T, rcond=None)[0].T
    b_xi = np.linalg.lstsq(units_xi.curvature(np.array(STATIONS)), kappa_xi.T, rcond=None)[0].T
    record = DeformationRecord(times, b, units, np.array(STATIONS), None, None, None, False, rest_end_s=1.0, b_xi=b_xi,
                               units_xi=units_xi)
    return Record(rig, channels), times, kappa, kappa_xi, record


def test_the_strain_at_a_gauge_at_any_angle_is_minus_the_point_times_both_curvatures(biaxial):
    rec, times, kappa, kappa_xi, _ = biaxial
    j = STATIONS.index(HALF)
    for name in ("g0", "g90", "g45"):
        sensor = next(s for s in rec.rig.sensors_of("strain") if s.name == name)
        zeta_p, xi_p = rec.rig.beam.section_point(HALF, sensor.angle_deg)
        channel = rec.channels[sensor.topic]
        measured = np.interp(times, (channel.log_time_ns - rec.start_ns) * 1e-9, channel.values[:, 0])
        virtual = section_strain(kappa[:, j:j + 1], [zeta_p], kappa_xi[:, j:j + 1], [xi_p])[:, 0]
        assert np.abs(measured).max() > 1e-6
        # the rig's gauges read the exact (large-rotation) kinematics: they differ from the linear −(ζp κζ + ξp κξ)
        # of the truth's curvature by second-order terms, 2e-4 of the peak here; a wrong sign or plane is O(1)
        np.testing.assert_allclose(virtual, measured, rtol=0, atol=1e-3 * np.abs(measured).max())


def _doc(rec, record, stations):
    return loads_of_recording(rec, record=record, model_args={}, stations=stations, curve=None, exponents=(3.0, 5.0), n_eq=None,
                              half_cycles="half", start_s=None, leave_one_out=False)


def test_stations_at_angles_carry_them_and_their_strain_comes_from_both_planes(biaxial):
    rec, _, _, _, record = biaxial
    doc = _doc(rec, record, parse_stations("1.0@90,1.0@45,1.0@225,2.0", LENGTH))
    by = {(s["position_m"], s["angle_deg"], s["hot_spot"]): s for s in doc["stations"]}
    assert (1.0, 90.0, None) in by and (2.0, 0.0, None) in by and "warnings" not in doc
    keep = record.times >= 1.0
    kappa_xi = record.b_xi[keep] @ record.units_xi.curvature(np.array([1.0])).T
    assert by[(1.0, 90.0, None)]["strain_rms"] == pytest.approx(RADIUS * float(np.sqrt(np.mean(kappa_xi**2))), rel=1e-12)
    # 225° is the point opposite 45°: the same strain with the other sign, the same RMS and cycles
    assert by[(1.0, 225.0, None)]["strain_rms"] == pytest.approx(by[(1.0, 45.0, None)]["strain_rms"], rel=1e-12)
    assert by[(1.0, 225.0, None)]["del"][0]["strain_range"] == pytest.approx(by[(1.0, 45.0, None)]["del"][0]["strain_range"], rel=1e-9)
    # the wind acts at 30°: the point at 45° strains by cos 15° of the worst, the one at 90° by cos 60°
    assert by[(1.0, 90.0, None)]["strain_rms"] / by[(1.0, 45.0, None)]["strain_rms"] == pytest.approx(
        math.cos(math.radians(60)) / math.cos(math.radians(15)), rel=0.02)
    hot = by[(0.25, 45.0, "base")]
    assert hot["curve"] == "EN1993-1-9:71" and hot["damage"] is not None


def test_a_girth_weld_is_judged_at_its_worst_point_around_the_section(biaxial):
    rec, _, _, _, record = biaxial
    doc = _doc(rec, record, (HALF,))
    girth = next(s for s in doc["stations"] if s["hot_spot"] == "girth")
    assert girth["angle_spec"] == "all" and girth["angles_evaluated"] == around_angles().size == 72
    # the wind's direction (or the point opposite it, the same ranges): on the 5° grid
    assert girth["angle_deg"] in (WIND_DEG, WIND_DEG + 180.0)
    assert "the largest Miner damage" in girth["worst_by"]
    at_zero = next(s for s in doc["stations"] if s["hot_spot"] is None and s["position_m"] == HALF)
    assert girth["damage"] > at_zero["damage"] if at_zero["damage"] else girth["damage"] > 0
    assert girth["del"][1]["strain_range"] == pytest.approx(at_zero["del"][1]["strain_range"] / math.cos(math.radians(WIND_DEG)), rel=0.02)


def test_the_root_moment_per_plane_and_its_resultant(biaxial):
    rec, _, _, _, record = biaxial
    root = _doc(rec, record, (1.0,))["root_bending_moment"]
    assert root["rms_nm"] == root["zeta"]["rms_nm"]
    resultant = root["resultant"]
    assert resultant["max_nm"] == pytest.approx(math.hypot(resultant["moment_zeta_at_max_nm"], resultant["moment_xi_at_max_nm"]), rel=1e-12)
    assert resultant["rms_nm"] == pytest.approx(math.hypot(root["zeta"]["rms_nm"], root["xi"]["rms_nm"]), rel=1e-12)
    # a wind at 30°: Mξ/Mζ = tan 30° (the tube is the same in both planes)
    assert root["xi"]["rms_nm"] / root["zeta"]["rms_nm"] == pytest.approx(math.tan(math.radians(WIND_DEG)), rel=0.02)
    ei0 = float(rec.rig.beam.bending_stiffness(0.0))
    keep = record.times >= 1.0
    m_xi = ei0 * (record.b_xi[keep] @ record.units_xi.curvature(np.array([0.0])).T)[:, 0]
    assert root["xi"]["rms_nm"] == pytest.approx(signal_loads(m_xi, n_eq=1.0).rms, rel=1e-12)


def test_a_biaxial_estimate_without_its_xi_plane_says_what_it_leaves_out(biaxial):
    rec, _, _, _, record = biaxial
    planar_only = DeformationRecord(record.times, record.b, record.units, record.stations, None, None, None, False, rest_end_s=1.0)
    doc = _doc(rec, planar_only, (1.0,))
    assert "no b_xi" in doc["warnings"][0] and "xi" not in doc["root_bending_moment"]


def test_stations_parse_as_eta_at_angle_and_a_planar_beam_refuses_other_angles(biaxial):
    assert parse_stations("5.0@45, 12.5@225,3", 20.0) == ((5.0, 45.0), (12.5, 225.0), (3.0, 0.0))
    for bad, message in (("5.0@", "no angle after '@'"), ("5.0@x", "is not η"), ("25@0", "outside the beam"), ("", "names no station")):
        with pytest.raises(LoadsError, match=message):
            parse_stations(bad, 20.0)
    rec, _, _, _, record = biaxial
    planar = rec.rig.model_copy(update={"beam": rec.rig.beam.model_copy(update={"bending": "planar"}), "hot_spots": ()})
    with pytest.raises(LoadsError, match="angle_deg=90: a planar beam accepts only 0 and 180"):
        loads_of_recording(Record(planar, {}),
                           record=DeformationRecord(record.times, record.b, record.units, record.stations, None, None, None, False),
                           model_args={}, stations=((1.0, 90.0),), curve=None, exponents=(3.0,), n_eq=None, half_cycles="half",
                           start_s=None, leave_one_out=False)


def test_the_text_table_names_each_station_s_angle_and_the_root_planes(biaxial, capsys):
    from shm_service.commands.loads import _print_table

    rec, _, _, _, record = biaxial
    _print_table(_doc(rec, record, parse_stations("1.0@90,2.0", LENGTH)))
    text = capsys.readouterr().out
    assert "1.000 m @90°" in text and "1.500 m @30° (worst around) girth" in text and "root bending moment: Mζ rms" in text
    assert "2.000 m  " in text  # the +ζ face as on a planar beam
