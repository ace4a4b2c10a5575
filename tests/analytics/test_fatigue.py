"""Streaming rainflow, S–N curves, Miner damage, DELs and remaining life."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import rainflow
from hypothesis import given, settings
from hypothesis import strategies as st

from analytics import (
    SECONDS_PER_YEAR,
    Cycles,
    FatigueDetail,
    HotSpotFatigue,
    RainflowCounter,
    RainflowResidue,
    cycles_by_range,
    damage_equivalent_range,
    miner_damage,
    rainflow_cycles,
    remaining_life,
    sn_curve,
)

ASTM = [-2, 1, -3, 5, -1, 3, -4, 4, -2]


def _histogram(c: Cycles) -> dict[float, float]:
    out: dict[float, float] = {}
    for r, n in zip(c.ranges.tolist(), c.counts.tolist()):
        out[round(r, 9)] = out.get(round(r, 9), 0.0) + n
    return out


def _reference(x: np.ndarray) -> dict[float, float]:
    out: dict[float, float] = {}
    for r, _mean, n, _i, _j in rainflow.extract_cycles(x):
        out[round(r, 9)] = out.get(round(r, 9), 0.0) + n
    return out


def _split_count(x: np.ndarray, cuts: list[int], *, persist: bool) -> Cycles:
    """Count in batches; with ``persist`` the counter is rebuilt from its JSON residue at each cut."""
    counter, parts = RainflowCounter(), []
    for a, b in zip([0, *cuts], [*cuts, x.size]):
        parts.append(counter.push(x[a:b]))
        if persist:
            counter = RainflowCounter(RainflowResidue.from_dict(json.loads(json.dumps(counter.residue.as_dict()))))
    parts.append(counter.residue.half_cycles())
    assert counter.samples == x.size
    return Cycles.concatenate(parts)


# -- rainflow -------------------------------------------------------------------------------------
def test_astm_e1049_worked_example_exactly():
    pairs, width = cycles_by_range(rainflow_cycles(ASTM))
    assert width is None
    assert pairs == [[3.0, 0.5], [4.0, 1.5], [6.0, 0.5], [8.0, 1.0], [9.0, 0.5]]


@pytest.mark.parametrize("cuts", [[1], [4], [5, 6], [2, 3, 4, 5, 6, 7, 8]])
def test_astm_example_split_anywhere(cuts):
    for persist in (False, True):
        assert cycles_by_range(_split_count(np.asarray(ASTM, float), cuts, persist=persist))[0] == \
            [[3.0, 0.5], [4.0, 1.5], [6.0, 0.5], [8.0, 1.0], [9.0, 0.5]]


def test_half_cycle_policies():
    full = cycles_by_range(rainflow_cycles(ASTM, half_cycles="full"))[0]
    assert full == [[3.0, 1.0], [4.0, 2.0], [6.0, 1.0], [8.0, 2.0], [9.0, 1.0]]
    assert cycles_by_range(rainflow_cycles(ASTM, half_cycles="ignore"))[0] == [[4.0, 1.0]]
    with pytest.raises(ValueError, match="'quarter'"):
        rainflow_cycles(ASTM, half_cycles="quarter")


@settings(max_examples=30, deadline=None, derandomize=True)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(3, 5000), walk=st.booleans(), quantised=st.booleans(),
       cuts=st.lists(st.floats(0.0, 1.0), max_size=12))
def test_against_rainflow_package_whole_and_split(seed, n, walk, quantised, cuts):
    rng = np.random.default_rng(seed)
    x = rng.normal(size=n)
    if walk:
        x = np.cumsum(x)
    if quantised:  # plateaus and repeated values, as an ADC gives
        x = np.round(4 * x) / 4
    ref = _reference(x)
    idx = sorted({int(c * (n - 1)) + 1 for c in cuts} - {n})
    assert _histogram(rainflow_cycles(x)) == pytest.approx(ref)
    assert _histogram(_split_count(x, idx, persist=False)) == pytest.approx(ref)
    assert _histogram(_split_count(x, idx, persist=True)) == pytest.approx(ref)


def test_two_samples_are_one_half_cycle():
    # ASTM: the record's ends are reversals (the `rainflow` package yields nothing for two samples,
    # hence n >= 3 above)
    assert cycles_by_range(rainflow_cycles([0.0, 2.5]))[0] == [[2.5, 0.5]]
    assert cycles_by_range(rainflow_cycles([1.0]))[0] == []


def test_cycles_by_range_bins_above_the_limit():
    c = rainflow_cycles(np.random.default_rng(3).normal(size=20_000))
    pairs, width = cycles_by_range(c, limit=100, bins=50)
    assert width == pytest.approx(c.ranges.max() / 50)
    assert sum(n for _, n in pairs) == pytest.approx(c.total)
    assert all(r > 0 for r, _ in pairs) and len(pairs) <= 50


def test_rainflow_rejects_nan_naming_the_sample():
    with pytest.raises(ValueError, match=r"signal\[2\] = nan"):
        rainflow_cycles([0.0, 1.0, math.nan, 2.0])
    counter = RainflowCounter()
    counter.push([0.0, 1.0])
    with pytest.raises(ValueError, match=r"strain\[0\] = inf"):
        counter.push([math.inf], name="strain")
    assert counter.samples == 2  # the bad batch was not counted
    with pytest.raises(ValueError, match="not a rainflow residue"):
        RainflowResidue.from_dict({"values": [1.0]})
    with pytest.raises(ValueError, match="closes"):
        RainflowCounter(RainflowResidue((0.0, 1.0, 0.5, 0.9, 0.0), 5))


# -- S–N curves -----------------------------------------------------------------------------------
def test_en1993_knees():
    c = sn_curve("EN1993-1-9:71")
    d = 71e6 * (2 / 5) ** (1 / 3)
    cut = d * (5 / 100) ** (1 / 5)
    assert c.cycles_to_failure(71e6)[0] == pytest.approx(2e6, rel=1e-12)
    assert c.cycles_to_failure(d)[0] == pytest.approx(5e6, rel=1e-12)
    assert c.cycles_to_failure(d * (1 - 1e-9))[0] == pytest.approx(5e6, rel=1e-8)  # continuous at the CAFL
    assert c.cycles_to_failure(cut)[0] == pytest.approx(1e8, rel=1e-12)
    assert c.cycles_to_failure(cut * 0.999)[0] == math.inf
    assert d / 1e6 == pytest.approx(52.3, abs=0.05) and cut / 1e6 == pytest.approx(28.7, abs=0.05)  # EN 1993-1-9 Table
    assert c.cycles_to_failure(2 * 71e6)[0] == pytest.approx(2e6 / 8, rel=1e-12)  # m = 3
    assert c.stress_range_at(2e6) == pytest.approx(71e6)
    s = sn_curve("EN1993-1-9:shear:80")
    assert s.cycles_to_failure(80e6)[0] == pytest.approx(2e6) and s.cycles_to_failure(80e6 * 0.5)[0] == pytest.approx(64e6)
    assert sn_curve("EN1993-1-9:36*").cycles_to_failure(36e6)[0] == pytest.approx(2e6)


@pytest.mark.parametrize("name, n_knee, s_knee_mpa, m1", [
    ("DNV-RP-C203:D:air", 1e7, 52.63, 3.0), ("DNV-RP-C203:B1:air", 1e7, 106.97, 4.0),
    ("DNV-RP-C203:W3:air", 1e7, 21.05, 3.0), ("DNV-RP-C203:D:seawater-cp", 1e6, 83.4, 3.0),
])
def test_dnv_curves_at_their_knees(name, n_knee, s_knee_mpa, m1):
    c = sn_curve(name)
    assert c.knees_pa[0] / 1e6 == pytest.approx(s_knee_mpa, rel=2e-3)
    # both printed lines meet at the knee (the table's rounding: within 0.3 % in N)
    assert c.cycles_to_failure(c.knees_pa[0])[0] == pytest.approx(n_knee, rel=1e-9)
    assert c.cycles_to_failure(c.knees_pa[0] * (1 - 1e-12))[0] == pytest.approx(n_knee, rel=3e-3)
    assert c.slopes == (m1, 5.0) and c.cutoff_pa == 0.0
    # D in air, log ā1 = 12.164: N at 100 MPa = 10^(12.164 − 6)
    if name == "DNV-RP-C203:D:air":
        assert c.cycles_to_failure(100e6)[0] == pytest.approx(10 ** 6.164, rel=1e-12)
        assert c.cycles_to_failure(30e6)[0] == pytest.approx(10 ** (15.606 - 5 * math.log10(30)), rel=1e-12)


def test_dnv_tables_cover_the_contracts_names():
    from analytics import DNV_RP_C203_CURVES
    from contract import DNV_RP_C203_CURVE_NAMES, DNV_RP_C203_ENVIRONMENTS

    assert set(DNV_RP_C203_CURVES) == set(DNV_RP_C203_ENVIRONMENTS)
    for table, _n in DNV_RP_C203_CURVES.values():
        assert set(table) == set(DNV_RP_C203_CURVE_NAMES)


def test_user_curve():
    c = sn_curve({"points": [[1e4, 400e6], [1e7, 80e6], [1e9, 50e6]]})
    assert c.cycles_to_failure([400e6, 80e6, 50e6]).tolist() == pytest.approx([1e4, 1e7, 1e9], rel=1e-12)
    assert c.cycles_to_failure(49e6)[0] == math.inf
    m = math.log10(1e7 / 1e4) / math.log10(400 / 80)
    assert c.cycles_to_failure(800e6)[0] == pytest.approx(1e4 / 2**m, rel=1e-12)


@pytest.mark.parametrize("spec, match", [
    ("EN1993-1-9:72", "unknown EN 1993-1-9 detail category '72'"), ("DNV-RP-C203:Q:air", "unknown DNV-RP-C203 curve 'Q'"),
    ("DNV-RP-C203:D:freshwater", "unknown DNV-RP-C203 environment 'freshwater'"), ("IIW:FAT90", "unknown standard 'IIW'"),
    ({"points": [[1e4, 100e6], [1e3, 50e6]]}, "N increasing"), ({"points": [[1e4, -1]]}, "at least two"), (71, "must be a name"),
])
def test_bad_curves_name_the_value(spec, match):
    with pytest.raises(ValueError, match=match):
        sn_curve(spec)


# -- damage, DEL, life ----------------------------------------------------------------------------
def test_miner_damage_with_factors():
    c = sn_curve("EN1993-1-9:71")
    assert miner_damage([71e6], [1.0], c) == pytest.approx(1 / 2e6, rel=1e-12)
    # γ_Ff·γ_Mf·SCF = 2 on the m = 3 branch: 8 times the damage
    assert miner_damage([71e6], [1.0], c, scf=1.6, gamma_ff=1.0, gamma_mf=1.25) == pytest.approx(8 / 2e6, rel=1e-12)
    assert miner_damage([20e6], [1e9], c) == 0.0  # below the cut-off nothing is consumed
    for name, kw in (("scf", {"scf": 0.0}), ("gamma_Ff", {"gamma_ff": -1.0}), ("gamma_Mf", {"gamma_mf": math.nan})):
        with pytest.raises(ValueError, match=name):
            miner_damage([71e6], [1.0], c, **kw)


def test_damage_equivalent_range():
    # one cycle of 2 and one of 4 over 10 s at 1 Hz: ((2³ + 4³)/10)^(1/3)
    assert damage_equivalent_range([2.0, 4.0], [1.0, 1.0], 3, 10.0) == pytest.approx((72 / 10) ** (1 / 3), rel=1e-12)
    assert damage_equivalent_range([], [], 5, 1.0) == 0.0
    with pytest.raises(ValueError, match="m=0"):
        damage_equivalent_range([1.0], [1.0], 0, 1.0)
    with pytest.raises(ValueError, match="n_eq=-1"):
        damage_equivalent_range([1.0], [1.0], 3, -1)


def test_remaining_life_and_cutoff():
    r = remaining_life(0.25, [1e-8, 3e-8], [10.0, 10.0], design_life_years=20)
    rate = 4e-8 / 20 * SECONDS_PER_YEAR
    assert r.verdict == "finite" and r.rate_per_year == pytest.approx(rate)
    assert r.remaining_years == pytest.approx(0.75 / rate)
    lo, hi = r.rate_band_per_year
    assert lo < rate < hi and r.remaining_band_years[0] == pytest.approx(0.75 / hi)
    assert r.exhausts_design_life_early is (1 / rate < 20)
    below = remaining_life(0.0, [0.0, 0.0], [10.0, 10.0], design_life_years=20)
    assert below.verdict == "no_damage_below_cutoff" and below.remaining_years is None
    assert remaining_life(1.2, [1e-3], [1.0]).verdict == "exhausted"
    with pytest.raises(ValueError, match="design_life_years=0"):
        remaining_life(0.0, [0.0], [1.0], design_life_years=0)


def test_hot_spot_streaming_equals_whole_and_survives_a_restart():
    rng = np.random.default_rng(7)
    stress = 60e6 * np.cumsum(rng.normal(size=36_000)) / 60  # a wandering 60 MPa-ish signal
    detail = FatigueDetail(sn_curve("EN1993-1-9:71"), scf=1.3, gamma_mf=1.35)
    whole = rainflow_cycles(stress)
    expected = detail.damage(whole)
    assert expected > 0
    spot = HotSpotFatigue(detail)
    for k, a in enumerate(range(0, stress.size, 200)):
        spot.push(stress[a:a + 200], 1.0, start_s=float(k))
        if k % 37 == 0:  # a restart: the state goes through JSON
            spot = HotSpotFatigue(detail, state=json.loads(json.dumps(spot.state_dict())))
    assert spot.consumed == pytest.approx(expected, rel=1e-12)
    life = spot.life(design_life_years=20)
    assert life.verdict == "finite" and life.remaining_years > 0
    with pytest.raises(ValueError, match="exponent m=-3"):
        HotSpotFatigue(detail, exponents=(-3,))
    with pytest.raises(ValueError, match="scf=0"):
        FatigueDetail(sn_curve("EN1993-1-9:71"), scf=0)
