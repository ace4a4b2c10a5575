"""`shm loads`: measured channels counted directly, virtual strain of an estimate recording."""

from __future__ import annotations

import json

import numpy as np
import pytest

from analytics import FatigueDetail, HotSpotFatigue, bending_moment, rainflow_cycles, signal_loads, sn_curve, virtual_strain
from shm_service.cli import main
from shm_service.recording import read_recording

ASTM = [-2, 1, -3, 5, -1, 3, -4, 4, -2]


def run(capsys, *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_astm_example_through_shm_loads_on_a_one_column_csv(capsys, tmp_path):
    path = tmp_path / "astm.csv"
    path.write_text("strain\n" + "\n".join(map(str, ASTM)) + "\n")
    code, out, err = run(capsys, "loads", str(path), "--fs", "1", "--json")
    assert code == 0, err
    doc = json.loads(out)
    assert doc["start_s"] == 0.0 and doc["duration_s"] == 9.0 and doc["stations"] == []
    (channel,) = doc["channels"]
    assert channel["name"] == "strain"
    assert channel["cycles_by_range"] == [[3.0, 0.5], [4.0, 1.5], [6.0, 0.5], [8.0, 1.0], [9.0, 0.5]]
    assert channel["cycles"] == 4.0 and channel["cycles_bin_width"] is None and channel["strain_range_max"] == 9.0
    # DEL_3 = (Σ n S³ / N_eq)^(1/3) with N_eq = 9 s · 1 Hz, by hand
    by_hand = ((0.5 * 27 + 1.5 * 64 + 0.5 * 216 + 1.0 * 512 + 0.5 * 729) / 9) ** (1 / 3)
    del3 = next(d for d in channel["del"] if d["m"] == 3.0)
    assert del3["strain_range"] == pytest.approx(by_hand, rel=1e-12) and del3["n_eq"] == 9.0
    assert del3["stress_range_pa"] == pytest.approx(by_hand * 2.1e11, rel=1e-12)
    # --neq and the half-cycle policy
    code, out, _ = run(capsys, "loads", str(path), "--fs", "1", "--json", "--neq", "1e7", "--half-cycles", "full")
    channel = json.loads(out)["channels"][0]
    assert channel["cycles_by_range"] == [[3.0, 1.0], [4.0, 2.0], [6.0, 1.0], [8.0, 2.0], [9.0, 1.0]]
    assert channel["del"][0]["n_eq"] == 1e7


def test_stress_channels_give_damage_on_a_curve(capsys, tmp_path):
    path = tmp_path / "stress.csv"
    # one 71 MPa cycle and back: half cycles 71, 71 MPa = one cycle at Δσ_C: D = 1/2e6
    path.write_text("sigma\n0\n71e6\n0\n")
    code, out, err = run(capsys, "loads", str(path), "--fs", "10", "--quantity", "stress", "--curve", "EN1993-1-9:71", "--json")
    assert code == 0, err
    (channel,) = json.loads(out)["channels"]
    assert channel["damage"] == pytest.approx(1 / 2e6, rel=1e-12)
    code, out, _ = run(capsys, "loads", str(path), "--fs", "10", "--quantity", "stress", "--curve", "EN1993-1-9:71")
    assert code == 0 and "sigma" in out


@pytest.mark.parametrize("content, argv, message", [
    ("strain\n0\nnan\n1\n", [], "channel 'strain' has 1 rejected value(s) (NaN, infinite, blank or not a number), the first at sample 1"),
    ("strain\n0\n1\n", ["--curve", "EN1993-1-9:72"], "unknown EN 1993-1-9 detail category '72'"),
    ("strain\n0\n1\n", ["--exponents", "3,0"], "Wöhler exponents must be > 0, got 0.0"),
    ("strain\n0\n1\n", ["--stations", "1.0"], "--stations needs a contract recording"),
    ("strain\n0\n1\n", ["--curve", '{"points": [[1e6, 5e7]]}'], "at least two"),
])
def test_bad_input_names_the_value(capsys, tmp_path, content, argv, message):
    path = tmp_path / "x.csv"
    path.write_text(content)
    code, out, err = run(capsys, "loads", str(path), "--fs", "1", *argv)
    assert code == 2 and out == ""
    assert message in err


def test_a_30_minute_record_whole_and_in_1_s_batches_gives_the_same_damage():
    fs, rng = 100, np.random.default_rng(11)
    n = 30 * 60 * fs
    # a narrow-band stress process about 40 MPa RMS plus slow swell: ranges across both EN slopes and the cut-off
    white = rng.normal(size=n)
    stress = 40e6 * np.convolve(white, np.hanning(25) / np.sqrt(np.sum(np.hanning(25) ** 2)), mode="same")
    stress += 20e6 * np.sin(2 * np.pi * 0.01 * np.arange(n) / fs)
    detail = FatigueDetail(sn_curve("EN1993-1-9:71"), scf=1.2, gamma_ff=1.0, gamma_mf=1.35)
    whole = signal_loads(stress, n_eq=n / fs, detail=detail)
    spot = HotSpotFatigue(detail)
    for k in range(0, n, fs):
        spot.push(stress[k:k + fs], 1.0, start_s=k / fs)
    assert whole.damage > 0
    assert spot.consumed == pytest.approx(whole.damage, rel=1e-12, abs=0)
    assert rainflow_cycles(stress).total == pytest.approx(whole.cycles.total)


def test_virtual_strain_and_moment_by_hand():
    b = np.array([[1e-3, -2e-3], [0.0, 1e-3]])
    shapes = np.array([[2.0, 1.0], [0.5, -1.0]])  # s'' at two stations, 1/m per unit b
    eps = virtual_strain(b, shapes, [0.005, 0.01])
    # κ = b·s'': (0, 2.5e-3) and (1e-3, -1e-3) 1/m; ε = −c κ
    np.testing.assert_allclose(eps, [[0.0, -2.5e-5], [-5e-6, 1e-5]], rtol=1e-12, atol=1e-20)
    np.testing.assert_allclose(bending_moment(b @ shapes.T, [100.0, 200.0]), [[0.0, 0.5], [0.1, -0.2]], rtol=1e-12, atol=1e-18)
    with pytest.raises(ValueError, match="bending_stiffness must be finite and > 0"):
        bending_moment(b @ shapes.T, [100.0, -1.0])
    with pytest.raises(ValueError, match="fibre_distance must be > 0"):
        virtual_strain(b, shapes, [0.005, 0.0])
    with pytest.raises(ValueError, match="3 columns"):
        virtual_strain(b, np.ones((2, 3)), [0.005, 0.005])


@pytest.fixture(scope="module")
def estimate_file(tmp_path_factory):
    folder = tmp_path_factory.mktemp("loads")
    raw, est = folder / "raw.mcap", folder / "est.mcap"
    assert main(["simulate", "--duration", "80", "--seed", "5", "--ideal", "--out", str(raw)]) == 0
    assert main(["estimate", str(raw), "--out", str(est)]) == 0
    return raw, est


def _true_dels(raw, doc) -> dict[float, float]:
    """The truth's strain DEL (m = 3) over the document's span at its stations that are truth stations."""
    from shm_service.processing.estimation import truth_from_recording

    rec = read_recording(raw)
    truth = truth_from_recording(rec)
    span = (truth.t >= doc["start_s"]) & (truth.t <= doc["start_s"] + doc["duration_s"])
    stations = list(rec.rig.truth_stations)
    c = rec.rig.beam.thickness / 2
    return {s["position_m"]: signal_loads(-c * truth.curvature[span, stations.index(s["position_m"])], n_eq=doc["duration_s"]).dels[0][2]
            for s in doc["stations"] if s["position_m"] in stations}


def test_virtual_strain_of_an_estimate_recording(capsys, estimate_file, tmp_path):
    raw, est = estimate_file
    rig = json.loads(read_recording(raw).rig.to_json())
    rig["hot_spots"] = [{"name": "weld", "position": 1.1, "curve": "EN1993-1-9:71", "scf": 2.0, "gamma_Mf": 1.35}]
    rig_path = tmp_path / "rig.json"
    rig_path.write_text(json.dumps(rig))
    capsys.readouterr()
    code, out, err = run(capsys, "loads", str(est), "--rig", str(rig_path), "--stations", "1.0,2.0,3.0", "--json")
    assert code == 0, err
    doc = json.loads(out)
    assert [s["position_m"] for s in doc["stations"]] == [1.0, 1.1, 2.0, 3.0]
    assert [s["hot_spot"] for s in doc["stations"]] == [None, "weld", None, None]
    assert doc["stations"][1]["curve"] == "EN1993-1-9:71" and doc["stations"][1]["damage"] is not None
    assert doc["stations"][0]["damage"] is None  # no --curve: no damage where there is no hot spot
    assert doc["band_method"].startswith("calibrated on the gauges' cross-validated residuals")
    assert doc["withheld"] == []  # the band is narrow: the damage is given
    # an estimate recording: its gauges aided it and cannot be left out here, so they are in sample
    assert all(not g["out_of_sample"] and g["leverage"] == 0.5 for g in doc["gauges"])
    assert [c["name"] for c in doc["channels"]] == ["g1", "g2", "g3", "g4"]
    assert doc["start_s"] > 0 and doc["duration_s"] > 10  # from the rest phase's end
    # against the truth's curvature over the same span: the estimate follows the strain
    true_dels = _true_dels(raw, doc)
    assert true_dels
    for s in doc["stations"]:
        if s["position_m"] in true_dels:
            true_del = true_dels[s["position_m"]]
            est_del = s["del"][0]["strain_range"]
            assert est_del == pytest.approx(true_del, rel=0.1)
            low, high = s["del"][0]["band"]
            assert low < est_del < high and high / est_del - 1 <= 0.05  # the ideal paper excitation: a narrow band
    # per window: each window counted on its own, with the band of its gauges
    code, out, err = run(capsys, "loads", str(est), "--stations", "2.0", "--window", "5", "--json")
    assert code == 0, err
    windows = json.loads(out)["windows"]
    assert len(windows) >= 2 and all(w["duration_s"] == pytest.approx(5.0) for w in windows)
    assert all(w["band_half_width"] >= 0.02 and w["stations"][0]["del"][0]["band"] is not None for w in windows)
    code, _, err = run(capsys, "loads", str(est), "--stations", "4.5")
    assert code == 2 and "--stations: 4.5 is outside the beam [0, 4.0]" in err


def test_a_raw_recording_leaves_each_gauge_out(capsys, estimate_file):
    """On a raw recording the estimator runs again without each gauge: every gauge is out of sample,
    the bands of the ideal paper excitation are narrow and hold the true DEL."""
    raw, _est = estimate_file
    capsys.readouterr()
    code, out, err = run(capsys, "loads", str(raw), "--stations", "0.5,1.5,2.5,3.5", "--json")
    assert code == 0, err
    doc = json.loads(out)
    assert [g["name"] for g in doc["gauges"]] == ["g1", "g2", "g3", "g4"]
    assert all(g["out_of_sample"] and g["leverage"] == 0.0 and g["half_width"] >= 0 for g in doc["gauges"])
    true_dels = _true_dels(raw, doc)
    assert true_dels
    for s in doc["stations"]:
        assert 0.02 <= s["band_half_width"] <= 0.05  # the floor, and narrow on the ideal paper excitation
        if s["position_m"] in true_dels:
            low, high = s["del"][0]["band"]
            assert low <= true_dels[s["position_m"]] <= high


def test_no_gauge_can_be_left_out_of_an_estimate_recording(estimate_file):
    from shm_service.commands.loads import LoadsError, loads_of_recording

    _raw, est = estimate_file
    with pytest.raises(LoadsError, match="is an estimate recording: no gauge can be left out of it"):
        loads_of_recording(read_recording(est), model_args={}, stations=(1.0,), curve=None, exponents=(3.0,), n_eq=None,
                           half_cycles="half", start_s=None, leave_one_out=True)


def test_shm_analyze_says_what_the_loads_band_rests_on(capsys, estimate_file, tmp_path):
    """shm analyze passes the recording's gauges to the engine: each window's hot spots carry a band
    with its method; a rig without gauges gets no band, and the output says why."""
    raw, est = estimate_file
    rig = json.loads(read_recording(raw).rig.to_json())
    rig["hot_spots"] = [{"name": "weld", "position": 1.1, "curve": "EN1993-1-9:71"}]
    with_gauges, without = tmp_path / "rig.json", tmp_path / "rig_without_gauges.json"
    with_gauges.write_text(json.dumps(rig))
    without.write_text(json.dumps(dict(rig, sensors=[s for s in rig["sensors"] if s["kind"] != "strain"])))
    config = tmp_path / "short.toml"
    config.write_text("[analytics]\nwindow_s = 5.0\noverlap = 0.5\nbaseline_s = 10.0\nbaseline_min_windows = 3\n")
    common = (str(est), "--config", str(config), "--not-before", "58")
    code, out, err = run(capsys, "analyze", *common, "--rig", str(with_gauges), "--json")
    assert code == 0, err
    doc = json.loads(out)
    assert doc["loads"] and doc["loads_band"].startswith("calibrated on the gauges' cross-validated residuals (g1 ")
    assert all(h["del_band_pa"] is not None for w in doc["loads"] for h in w["hot_spots"])
    code, out, err = run(capsys, "analyze", *common, "--rig", str(without))
    assert code == 0, err
    assert "(no band)" in out and "band: no band: no strain gauge measured over the analysed windows" in out


def test_channels_in_volts_are_counted_with_a_warning(capsys):
    from pathlib import Path

    path = next((Path(__file__).parents[1] / "data" / "dropbear" / "random-dwell").glob("*.txt"))
    code, out, err = run(capsys, "loads", str(path), "--channels", "SG_300_a", "--json")
    assert code == 0, err
    doc = json.loads(out)
    assert doc["warnings"] == ["channel 'SG_300_a' is in 'Voltage (unscaled)', not m/m: the figures are in that unit; "
                               "scale it first (shm import's channel map has scale and offset)"]
    assert doc["channels"][0]["cycles"] > 1000


def test_estimate_analyze_and_loads_take_one_definition_of_the_model_options():
    """`shm loads` and `shm analyze` take `shm estimate`'s model options as it defines them (one
    ``add_model_arguments``), with the same defaults, choices and help."""
    from shm_service.cli import build_parser

    sub = next(a for a in build_parser()._actions if a.__class__.__name__ == "_SubParsersAction")

    def options(command: str) -> dict:
        return {a.dest: (a.option_strings, a.default, a.choices, a.help) for a in sub.choices[command]._actions
                if a.dest in ("rig", "peripheral", "modes", "imus", "tofs", "gauges", "aided")}

    estimate = options("estimate")
    assert set(estimate) == {"rig", "peripheral", "modes", "imus", "tofs", "gauges", "aided"}
    assert options("loads") == estimate
    analyze = options("analyze")
    assert analyze == {k: v for k, v in estimate.items() if k != "aided"}  # analyze builds no aided model
    assert options("reprocess") == analyze


def test_the_estimate_recording_carries_each_estimates_virtual_loads(estimate_file):
    """`shm estimate --out` writes /estimate/loads: per estimate the strain and bending moment at the
    stations its metadata names (the rig's hot spots, then 16 stations from the support), and the
    moment at the support; ε = −c Σ b s'' and M = EI κ of the estimate's own b."""
    from contract import ESTIMATE_LOADS_TOPIC, ESTIMATE_TOPIC
    from estimator import build_model
    from shm_service.recording import read_recording

    _, est = estimate_file
    rec = read_recording(est)
    meta = rec.metadata["loads"]
    eta = np.array(json.loads(meta["stations_m"]))
    assert json.loads(meta["names"]) == [""] * 16 and eta[0] == 0.0 and eta.size == 16  # the lab rig names no hot spot
    assert json.loads(meta["youngs_modulus_pa"]) == rec.rig.beam.youngs_modulus
    loads, state = rec.channels[ESTIMATE_LOADS_TOPIC], rec.channels[ESTIMATE_TOPIC]
    assert np.array_equal(loads.log_time_ns, state.log_time_ns)
    b = state.values[:, [k for k, f in enumerate(state.fields) if f.startswith("b[")]]
    assert loads.fields[0] == "strain[0]" and loads.fields[-1] == "root_moment_nm"
    units = build_model(rec.rig, modes=b.shape[1]).units
    c, ei = rec.rig.beam.fibre_distance(eta), rec.rig.beam.bending_stiffness(eta)
    kappa = b @ units.curvature(eta).T
    strain, moment, root = loads.values[:, :16], loads.values[:, 16:32], loads.values[:, 32]
    np.testing.assert_allclose(strain, -kappa * c, rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(moment, kappa * ei, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(root, 0.0, atol=1e-9)  # the lab sheet's pinned bearing carries no moment
    assert np.std(strain[:, 1]) > 1e-7


def test_damage_and_life_are_withheld_where_the_virtual_strain_does_not_hold():
    """A station whose band is wider than ±50 %, or every station once a gauge's strain disagrees with the
    virtual strain by more than its own RMS, has no damage or life figure: null, with the reason and what to change."""
    from shm_service.commands.loads import withhold_figures

    def station(pos, width):
        return {"position_m": pos, "hot_spot": None, "band_half_width": width, "damage": 1e-6, "damage_band": [1e-7, 1e-5],
                "life_at_this_load_years": 3.0, "life_verdict": "finite"}

    stations = [station(1.0, 0.04), station(2.0, 0.8)]
    out = withhold_figures(stations, [{"name": "g1", "strain_rms_discrepancy": 0.2}])
    assert [w["position_m"] for w in out] == [2.0] and "±80%" in out[0]["reason"] and "--modes" in out[0]["reason"]
    assert stations[0]["damage"] == 1e-6 and stations[1]["damage"] is None and stations[1]["life_verdict"] == "withheld"
    stations = [station(1.0, 0.04)]
    out = withhold_figures(stations, [{"name": "g3", "strain_rms_discrepancy": 10.0}])
    assert "strain gauge g3 by 1000%" in out[0]["reason"] and stations[0]["life_at_this_load_years"] is None


@pytest.mark.slow
def test_a_mast_with_as_many_gauges_as_modes_keeps_its_band_in_sample(capsys, tmp_path):
    """Without ToFs, leaving one of Γ gauges out leaves the unit deformations unobservable: each
    gauge's residual stays in sample (widened by the leverage bound), and shm loads says so."""
    from pathlib import Path

    from analytics import UNKNOWN_LEVERAGE

    rig = Path(__file__).resolve().parents[2] / "examples" / "mast" / "rig.json"
    recording = tmp_path / "mast.mcap"
    assert main(["simulate", "--rig", str(rig), "--duration", "120", "--seed", "3", "--out", str(recording)]) == 0
    capsys.readouterr()
    code, out, err = run(capsys, "loads", str(recording), "--json")
    assert code == 0, err
    doc = json.loads(out)
    assert [(g["name"], g["out_of_sample"], g["leverage"]) for g in doc["gauges"]] == [
        (f"g{j}", False, UNKNOWN_LEVERAGE) for j in range(1, 5)]
    assert all(s["band_half_width"] is not None for s in doc["stations"])
