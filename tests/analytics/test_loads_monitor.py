"""Loads in the one engine: every sample counted once whatever the chunking, the same damage as the
record counted whole, a restart through the state, fatigue alarms through AlarmLogic."""

from __future__ import annotations

import json

import numpy as np
import pytest

from analytics import (
    FatigueDetail, HotSpotSpec, LoadsConfig, LoadsMonitor, ModalMonitor, MonitoringEngine, rainflow_cycles, sn_curve,
)
from contract import ChartDocument, LoadsWindowDocument

FS = 50.0
ETA = np.linspace(0.5, 4.0, 8)
S2 = np.column_stack([np.cos(np.pi * ETA / 8), np.sin(np.pi * ETA / 4), np.cos(3 * np.pi * ETA / 8)])
EXPECTED = ((1.0,), (2.5,), (4.0,))
ORIGIN_NS = 1_767_225_600_000_000_000  # on the step: the windows' grid is the samples' (no resampling)
E = 2.1e11


def _spots():
    # s'' at the hot spot (1/m per unit b) and c = 5 mm: stress = −c·E·(b @ s'')
    return [HotSpotSpec("weld", 1.0, FatigueDetail(sn_curve("EN1993-1-9:71"), scf=1.0, gamma_mf=1.35), np.array([1.0, 0.5, -0.2]), 0.005),
            HotSpotSpec("door", 2.0, FatigueDetail(sn_curve("DNV-RP-C203:D:air")), np.array([0.3, -1.0, 0.4]), 0.005)]


def _b(seconds: float, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    n = int(seconds * FS)
    t = np.arange(n) / FS
    # about 60 MPa of stress: b of a few 1e-2 m with s'' ~ 1 and c·E ~ 1e9
    return 0.05 * np.column_stack([np.sin(2 * np.pi * 1.0 * t) * (1 + 0.5 * rng.standard_normal(n).cumsum() / np.sqrt(n)),
                                   np.sin(2 * np.pi * 2.5 * t + 1), 0.3 * rng.standard_normal(n)])


def _engine(state=None, config=None, design=20.0):
    mon = ModalMonitor(EXPECTED, S2, ETA, fs=FS)
    loads = LoadsMonitor(_spots(), youngs_modulus=E, design_life_years=design, config=config, state=state)
    return MonitoringEngine(mon, origin_ns=ORIGIN_NS, time_zero_ns=ORIGIN_NS, loads=loads)


def test_engine_counts_every_sample_once_and_matches_the_whole_record():
    b = _b(600.0)
    t = np.arange(b.shape[0]) / FS
    engine = _engine()
    windows = engine.add(t, b)
    assert engine.loads_errors == 0 and windows and all(isinstance(w.loads, LoadsWindowDocument) for w in windows)
    # the counted samples: each window's first step, contiguous from the first window's start
    step = int(round(engine.step_s * FS))
    first = int(round((windows[0].start_ns - ORIGIN_NS) / 1e9 * FS))
    counted = b[first:first + step * len(windows)]
    for spot in _spots():
        stress = -spot.fibre_distance_m * (counted @ spot.curvature_shape) * E
        expected = spot.detail.damage(rainflow_cycles(stress))
        got = windows[-1].loads.hot_spots[[s.name for s in windows[-1].loads.hot_spots].index(spot.name)].consumed
        assert expected > 0 and got == pytest.approx(expected, rel=1e-12)
    # chunked, with a restart in the middle through JSON: the same windows and damage
    engine2, got2 = _engine(), []
    for k in range(0, b.shape[0], 137):
        got2 += engine2.add(t[k:k + 137], b[k:k + 137])
        if k == 137 * 80:
            state = json.loads(json.dumps(engine2.loads.state_dict()))
            engine2.loads = LoadsMonitor(_spots(), youngs_modulus=E, design_life_years=20.0, state=state)
    assert [w.start_ns for w in got2] == [w.start_ns for w in windows]
    assert [h.consumed for h in got2[-1].loads.hot_spots] == pytest.approx([h.consumed for h in windows[-1].loads.hot_spots], rel=1e-12)
    doc = windows[-1].loads.hot_spots[0]
    assert set(doc.del_pa) == {"3", "5"} and doc.verdict == "finite" and doc.remaining_years > 0
    assert doc.n_eq == pytest.approx(engine.step_s)


def test_fatigue_alarms_through_the_alarm_logic():
    b = _b(600.0)
    t = np.arange(b.shape[0]) / FS
    # no design life: no rate chart; the DEL baseline from the first 3 windows
    config = LoadsConfig(baseline_windows=3, raise_windows=2, clear_windows=2, consumed_warning=1e-30, consumed_alarm=1e-29)
    engine = _engine(config=config, design=None)
    events = []
    for w in engine.add(t[:15000], b[:15000]):
        events += w.loads_events
    # the load triples: the DEL jumps against its baseline
    for w in engine.add(t[15000:], 3.0 * b[15000:]):
        events += w.loads_events
    charts = {e.chart for e in events if e.action in ("raise", "escalate")}
    assert "fatigue:weld:del" in charts and "fatigue:weld:consumed" in charts and "fatigue:weld:rate" not in charts
    e = next(e for e in events if e.chart == "fatigue:weld:del")
    assert e.kind == "fatigue" and "DEL jumped" in e.message()
    # a chart document of a fatigue chart is validated by its name
    with pytest.raises(ValueError, match="condition"):
        ChartDocument(name="fatigue:weld:wobble", kind="fatigue", level="ok", warning_sigma=1.0, alarm_sigma=2.0)


def test_rate_alarm_when_the_design_life_would_be_exhausted_early():
    b = _b(300.0)
    t = np.arange(b.shape[0]) / FS
    # about 0.4 of life a year at these ~60 MPa: a 20-year design life would be exhausted early
    engine = _engine(config=LoadsConfig(raise_windows=1), design=20.0)
    events = []
    for w in engine.add(t, b):
        events += w.loads_events
    assert any(e.chart == "fatigue:weld:rate" and e.level == "alarm" for e in events)


def test_bad_loads_input():
    with pytest.raises(ValueError, match="hot_spots is empty"):
        LoadsMonitor([], youngs_modulus=E)
    with pytest.raises(ValueError, match="youngs_modulus=-1"):
        LoadsMonitor(_spots(), youngs_modulus=-1)
    with pytest.raises(ValueError, match="consumed_alarm=0.1 is below"):
        LoadsConfig(consumed_warning=0.5, consumed_alarm=0.1)
    with pytest.raises(ValueError, match="exponents"):
        LoadsConfig(exponents=(3.0, -5.0))
    with pytest.raises(ValueError, match="LoadsMonitor"):
        MonitoringEngine(ModalMonitor(EXPECTED, S2, ETA, fs=FS), loads="loads")


def test_analyze_carries_the_loads_of_the_same_engine():
    from analytics import analyze

    b = _b(240.0)
    t = np.arange(b.shape[0]) / FS
    live = _engine().add(t, b)
    result = analyze(t, b, S2, ETA, fs=FS, expected_hz=EXPECTED, time_origin_ns=ORIGIN_NS,
                     loads=LoadsMonitor(_spots(), youngs_modulus=E, design_life_years=20.0))
    doc = result.as_dict()
    assert len(doc["loads"]) == len(result.windows) == len(live)
    assert doc["loads"][-1]["hot_spots"][0]["consumed"] == pytest.approx(live[-1].loads.hot_spots[0].consumed, rel=1e-12)
    assert "loads" not in analyze(t, b, S2, ETA, fs=FS, expected_hz=EXPECTED, time_origin_ns=ORIGIN_NS).as_dict()


def test_the_band_of_each_window_from_the_gauges_through_the_engine():
    """Gauges measuring exactly the virtual strain: the band is the 2 % floor; a gauge whose DEL the
    virtual strain's exceeds by 10 % (it reads 1/1.1 of it: DELs scale with the strain) has a = 10 %
    when it did not aid the estimate, 20 % when it did (in sample, leverage 0.5: the residual
    doubled), and the hot spots away from it take the prediction from one gauge; without gauges no
    band is claimed."""
    from analytics import GaugeSpec

    shape = np.array([0.8, 0.2, 0.1])
    b = _b(200.0)
    t = np.arange(b.shape[0]) / FS
    virtual = -0.005 * (b @ shape)

    def run(scale: float, in_sample: bool, with_gauges: bool = True):
        mon = ModalMonitor(EXPECTED, S2, ETA, fs=FS)
        gauge = GaugeSpec("g1", 1.5, shape, 0.005, in_sample)
        loads = LoadsMonitor(_spots(), youngs_modulus=E, gauges=[gauge] if with_gauges else None)
        engine = MonitoringEngine(mon, origin_ns=ORIGIN_NS, time_zero_ns=ORIGIN_NS, loads=loads)
        return [w.loads for w in engine.add(t, b, gauges={"g1": (t, scale * virtual)})]

    exact = run(1.0, False)
    assert exact
    for doc in exact:
        for h in doc.hot_spots:
            for m, (low, high) in h.del_band_pa.items():
                assert high == pytest.approx(1.02 * h.del_pa[m], rel=1e-12) and low == pytest.approx(h.del_pa[m] / 1.02, rel=1e-12)
            assert "leave-one-gauge-out DEL residuals at the strain gauges (g1 1.5 m; out of sample)" in h.band_method
    # the hot spots (1 m, 2 m) lie beyond the one gauge (1.5 m): the gauge's a and the Student-t prediction
    # from one gauge, t(0.9, 1 dof)·sqrt(2)·a = 4.352502·a
    high = run(1 / 1.10, False)[0].hot_spots[0]
    assert high.del_band_pa["3"][1] / high.del_pa["3"] == pytest.approx(1 + 4.352502 * 0.10, rel=1e-6)
    aided = run(1 / 1.10, True)[0].hot_spots[0]
    assert aided.del_band_pa["3"][1] / aided.del_pa["3"] == pytest.approx(1 + 4.352502 * 0.20, rel=1e-6)
    assert aided.damage_band[0] <= aided.damage_increment <= aided.damage_band[1]
    assert all(h.del_band_pa is None and h.band_method is None for h in run(1.0, False, with_gauges=False)[0].hot_spots)


def test_virtual_loads_by_hand_and_bad_input():
    from analytics import VirtualLoads

    class Beam:
        youngs_modulus = 2.0e11

        def youngs_modulus_at(self, t):
            return 2.0e11 if t is None else 2.0e11 * (1 - 3e-4 * (t - 20.0))

        def bending_stiffness(self, eta, t=None):
            return np.full(np.shape(eta), 1000.0) if np.ndim(eta) else 1000.0

    v = VirtualLoads([0.0, 1.0], ["root", ""], [[1.0, 0.0], [0.0, 2.0]], [0.01, 0.02], Beam(), root_shape=[1.0, 0.0])
    out = v([[1e-4, 1e-4]])
    np.testing.assert_allclose(out["strain"], [[-1e-6, -4e-6]], rtol=1e-12)
    np.testing.assert_allclose(out["stress_pa"], [[-2e5, -8e5]], rtol=1e-12)
    np.testing.assert_allclose(out["moment_nm"], [[0.1, 0.2]], rtol=1e-12)  # EI κ
    np.testing.assert_allclose(out["root_moment_nm"], [0.1], rtol=1e-12)
    np.testing.assert_allclose(v([[1e-4, 1e-4]], 30.0)["stress_pa"], [[-2e5 * 0.997, -8e5 * 0.997]], rtol=1e-12)
    with pytest.raises(ValueError, match="unit deformations"):
        v([[1.0, 2.0, 3.0]])
    with pytest.raises(ValueError, match="must agree"):
        VirtualLoads([0.0], ["a", "b"], [[1.0]], [0.01], Beam())
    with pytest.raises(ValueError, match="fibre_distance"):
        VirtualLoads([0.0], ["a"], [[1.0]], [-0.01], Beam())


def test_the_calibrated_band_through_the_engine():
    """With the modes above the basis given (none here: K = 0, the missing strain a floor), the engine's
    band is ``outside_basis_bands``': a gauge reading 1/1.1 of the virtual strain out of sample has the
    relative residual q = 1 − 1/1.1 and score ln(1.1)/q (one gauge: the largest), so a hot spot whose virtual
    strain has the gauge's RMS r times over gets ln(1 + a) = ln(1.1)·(RMS_g/RMS_h), at least the gauge's own
    ln(1.1) and the 2 % floor."""
    from analytics import GaugeSpec

    shape = np.array([0.8, 0.2, 0.1])
    b = _b(200.0)
    t = np.arange(b.shape[0]) / FS
    virtual = -0.005 * (b @ shape)
    spots = _spots()
    mon = ModalMonitor(EXPECTED, S2, ETA, fs=FS)
    loads = LoadsMonitor(spots, youngs_modulus=E, gauges=[GaugeSpec("g1", 1.5, shape, 0.005, False)],
                         outside=(np.zeros((1, 0)), np.zeros((len(spots), 0))))
    engine = MonitoringEngine(mon, origin_ns=ORIGIN_NS, time_zero_ns=ORIGIN_NS, loads=loads)
    docs = [w.loads for w in engine.add(t, b, gauges={"g1": (t, virtual / 1.1)})]
    assert docs
    h, spot = docs[0].hot_spots[0], spots[0]
    assert h.band_method.startswith("calibrated on the gauges' cross-validated residuals (g1 1.5 m)")
    # the window's counted samples: the engine's first step; the gauge's RMS and the hot spot's over them
    n = round(docs[0].duration_s * FS)
    first = b[:n]
    rms_g = np.sqrt(np.mean((0.005 * (first @ shape)) ** 2))
    rms_h = np.sqrt(np.mean((spot.fibre_distance_m * (first @ spot.curvature_shape)) ** 2))
    # and at least what the one gauge saw (a hot spot beyond it takes the largest gauge's own factor)
    expected = max(0.02, np.expm1(max(np.log(1.1) * rms_g / rms_h, np.log(1.1))))
    assert h.del_band_pa["3"][1] / h.del_pa["3"] == pytest.approx(1 + expected, rel=1e-6)
    with pytest.raises(ValueError, match="disagree with 1 gauges"):
        LoadsMonitor(spots, youngs_modulus=E, gauges=[GaugeSpec("g1", 1.5, shape, 0.005, False)],
                     outside=(np.zeros((2, 0)), np.zeros((len(spots), 0))))
