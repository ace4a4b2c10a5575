"""Both bending planes: degenerate pairs of a symmetric section and the per-plane result of a record."""

from __future__ import annotations

import numpy as np
import pytest

from analytics import AnalysisResult, ModeSummary, combine_planes, degenerate_pairs, with_plane


def test_a_pair_within_the_combined_sigma_or_half_a_percent_is_degenerate():
    # mode 1: 1.000 vs 1.004 Hz, 1σ 0.003 and 0.004 -> combined 0.005 >= 0.004: "sigma"
    # mode 2: 6.00 vs 6.02 Hz (0.333 %), 1σ 0.001 each -> outside 1σ, inside 0.5 %: "relative"
    # mode 3: 17.0 vs 17.2 Hz (1.18 %), 1σ 0.01 each: not a pair
    pairs = degenerate_pairs([1.0, 6.0, 17.0], [1.004, 6.02, 17.2], [0.003, 0.001, 0.01], [0.004, 0.001, 0.01])
    assert [(p.mode, p.within) for p in pairs] == [(1, "sigma"), (2, "relative")]
    assert pairs[0].frequency_zeta_hz == 1.0 and pairs[0].frequency_xi_hz == 1.004
    assert pairs[0].relative_difference == pytest.approx(0.004, rel=1e-12)
    assert pairs[1].relative_difference == pytest.approx(0.02 / 6.0, rel=1e-12)
    assert pairs[1].as_dict() == {"mode": 2, "frequency_zeta_hz": 6.0, "frequency_xi_hz": 6.02,
                                  "relative_difference": pytest.approx(0.02 / 6.0, rel=1e-12), "within": "relative"}


def test_without_sigmas_only_the_relative_tolerance_counts_and_unidentified_modes_pair_with_none():
    # mode 1 within 0.5 %; mode 2 not identified in ξ; mode 3 0.6 % apart; mode 4 only in ζ
    pairs = degenerate_pairs([2.0, 12.0, 30.0, 50.0], [2.009, None, 30.18])
    assert [p.mode for p in pairs] == [1]
    assert degenerate_pairs([30.0], [30.18], rel_tol=0.01)[0].within == "relative"
    # a non-finite 1σ leaves the mode to the relative tolerance
    assert degenerate_pairs([2.0], [2.02], [float("nan")], [0.1]) == ()


def test_bad_input_is_refused_naming_the_value():
    with pytest.raises(ValueError, match="rel_tol"):
        degenerate_pairs([1.0], [1.0], rel_tol=-0.1)
    with pytest.raises(ValueError, match="std_xi_hz has 2 values for 1 frequencies"):
        degenerate_pairs([1.0], [1.0], [0.1], [0.1, 0.2])
    with pytest.raises(ValueError, match="frequency_zeta_hz must be > 0"):
        degenerate_pairs([0.0], [1.0])


def _summary(mode, f, std):
    return ModeSummary(mode, mode, f, std, 0.01, 0.001, "ssi", 0.9, 10)


def _result(modes, flags=()):
    return AnalysisResult(tuple(modes), (), tuple(flags), None, {"incomplete": 0, "warmup": 0})


def test_a_planar_result_lists_its_modes_in_the_zeta_plane_and_nothing_else_changes():
    out = _result([_summary(1, 1.0, 0.01)]).as_dict()
    assert out["modes"][0]["plane"] == "zeta"
    assert set(out) == {"modes", "windows", "flags", "baseline", "skipped_windows", "tracks", "usability"}
    with pytest.raises(ValueError, match="plane='y'"):
        with_plane((), "y")


def test_both_planes_in_one_result_each_mode_and_flag_naming_its_plane():
    zeta = _result([_summary(1, 1.0, 0.002), _summary(2, 6.0, 0.01)], [{"kind": "frequency", "mode": 1, "since_s": 60.0}])
    xi = _result([_summary(1, 1.001, 0.002), _summary(2, 7.0, 0.01)], [{"kind": "curvature", "mode": None, "since_s": 90.0}])
    out = combine_planes(zeta, xi).as_dict()
    assert [(m["plane"], m["mode"], m["frequency_hz"]) for m in out["modes"]] == [
        ("zeta", 1, 1.0), ("zeta", 2, 6.0), ("xi", 1, 1.001), ("xi", 2, 7.0)]
    assert [(f["plane"], f["kind"]) for f in out["flags"]] == [("zeta", "frequency"), ("xi", "curvature")]
    # mode 1: 0.001 Hz apart, combined 1σ 0.00283 Hz; mode 2 is 17 % apart
    assert [(p["mode"], p["within"]) for p in out["degenerate_pairs"]] == [(1, "sigma")]
    assert out["degenerate_pairs"][0]["relative_difference"] == pytest.approx(0.001, rel=1e-9)
    assert out["windows_xi"] == [] and out["baseline_xi"] is None
    np.testing.assert_equal(out["skipped_windows_xi"], {"incomplete": 0, "warmup": 0})
