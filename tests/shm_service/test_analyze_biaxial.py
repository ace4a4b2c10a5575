"""`shm analyze` of a beam that bends in two planes: each plane's modes identified on their own, every
mode naming its plane, and a round tube's two planes reported as degenerate pairs."""

from __future__ import annotations

import numpy as np
import pytest

from analytics import AnalysisConfig
from contract import TrendRow, parse_rig
from estimator import assemble_beam, unit_deformations
from shm_service.processing.analysis import analyze_deformations, trend_rows
from shm_service.processing.estimation import DeformationRecord
from shm_service.virtual_rig import SensorErrors, SimulationSettings, VirtualRig

NO_ERRORS = SensorErrors(**{name: 0.0 for name in SensorErrors.model_fields if name != "bias_correlation_time"})
LENGTH = 3.0
STATIONS = [round(0.25 * k, 9) for k in range(1, 13)]


def tube_rig():
    """A uniform round steel tube, clamped, standing, biaxial: the same frequencies in both planes."""
    tube = {"shape": "tube", "outer_diameter": 0.1, "wall_thickness": 0.004}
    return parse_rig({
        "beam": {"length": LENGTH, "youngs_modulus": 2.1e11, "density": 7850.0, "bending": "biaxial",
                 "sections": [{"position": 0.0, **tube}, {"position": LENGTH, **tube}]},
        "gravity": 9.81, "support": "clamped", "orientation": "standing",
        "sensors": [{"name": "D", "kind": "imu", "position": 0.0}, {"name": "tip", "kind": "imu", "position": LENGTH},
                    {"name": "g0", "kind": "strain", "position": 1.5}, {"name": "g90", "kind": "strain", "position": 1.5,
                                                                        "angle_deg": 90}],
        "truth_stations": STATIONS,
    })


@pytest.fixture(scope="module")
def analysed():
    """240 s of the round tube in a wind at 30° (ξ about 0.58 of ζ); b and b_ξ fitted to the truth's curvature."""
    rig = tube_rig()
    settings = SimulationSettings(duration=240.0, rest=1.0, ideal=True, seed=5, errors=NO_ERRORS, excitation="ambient",
                                  support="clamped", orientation="standing", length=LENGTH,
                                  wind_direction={"mean_deg": 30.0, "veer_deg": 0.0})
    vr = VirtualRig(settings, rig)
    blocks = list(vr.blocks(20.0))
    times = np.concatenate([b.times for b in blocks])
    kappa, kappa_xi = (np.concatenate([b.truth[key] for b in blocks]) for key in ("curvature", "curvature_xi"))
    units = unit_deformations(assemble_beam(rig), 2)
    units_xi = unit_deformations(assemble_beam(rig, plane="xi"), 2)
    stations = np.array(STATIONS)
    b = np.linalg.lstsq(units.curvature(stations), kappa.T, rcond=None)[0].T
    b_xi = np.linalg.lstsq(units_xi.curvature(stations), kappa_xi.T, rcond=None)[0].T
    record = DeformationRecord(times, b, units, stations, None, None, None, False, rest_end_s=1.0, b_xi=b_xi, units_xi=units_xi)
    config = AnalysisConfig(window_s=30.0, baseline_s=120.0)
    result = analyze_deformations(rig, record, config=config, warmup_s=0.0)
    return vr, units, units_xi, result


def test_each_plane_lists_its_modes_near_its_own_eigenfrequencies(analysed):
    vr, units, units_xi, result = analysed
    out = result.as_dict()
    planes = [m["plane"] for m in out["modes"]]
    assert planes == ["zeta"] * len(result.modes) + ["xi"] * len(result.xi.modes)
    assert len(out["windows_xi"]) == len(out["windows"]) > 0
    for plane, model in (("zeta", units), ("xi", units_xi)):
        first = next(m for m in out["modes"] if m["plane"] == plane and m["mode"] == 1)
        assert first["frequency_hz"] == pytest.approx(float(np.ravel(model.frequencies_hz[0])[0]), rel=0.01)


def test_a_round_tube_is_a_degenerate_pair_in_its_first_mode(analysed):
    _, _, _, result = analysed
    pairs = result.as_dict()["degenerate_pairs"]
    assert pairs and pairs[0]["mode"] == 1
    f_zeta = next(m.frequency_hz for m in result.modes if m.mode == 1)
    f_xi = next(m.frequency_hz for m in result.xi.modes if m.mode == 1)
    assert (pairs[0]["frequency_zeta_hz"], pairs[0]["frequency_xi_hz"]) == (f_zeta, f_xi)
    assert pairs[0]["relative_difference"] == pytest.approx(f_xi / f_zeta - 1, rel=1e-12)


def test_the_xi_planes_trend_rows_say_so_and_a_planar_row_keeps_the_default(analysed):
    _, _, _, result = analysed
    w = result.xi.windows[-1]
    rows = trend_rows("mast", w, 100.0, 130.0, plane="xi")
    assert rows and {r.plane for r in rows} == {"xi"}
    assert {r.plane for r in trend_rows("mast", result.windows[-1], 100.0, 130.0)} == {"zeta"}
    assert TrendRow(source="s", window_start_s=0.0, window_end_s=1.0, mode=1, unit=1, kind="ambient").plane == "zeta"
