"""The Loads tab's parts without a browser: a structure's fatigue document read into what the tab
draws (envelope along the beam, DEL and consumed-life trends), the hot spots' table with the
remaining life and its band, and "no damage: below the cut-off" instead of an infinite life."""

from __future__ import annotations

import numpy as np
import pytest

from contract import FatigueDocument, HotSpotLoadsDocument, LoadsWindowDocument, StationLoadsDocument
from web import envelope_plot, hot_spots_html, loads_record


def _spot(name, position, *, consumed, verdict="finite", remaining=None, band=None, dels=(10e6, 12e6), rate=None):
    return HotSpotLoadsDocument(
        name=name, position_m=position, curve="EN 1993-1-9 71", del_pa={"3": dels[0], "5": dels[1]}, n_eq=3600.0,
        max_range_pa=30e6, damage_increment=1e-7, consumed=consumed, rate_per_year=rate, remaining_years=remaining,
        remaining_band_years=band, verdict=verdict, design_life_years=25.0,
    )


def _document(total=2):
    windows = [
        LoadsWindowDocument(start_s=1000.0 + 120 * k, duration_s=120.0, hot_spots=[
            _spot("flange", 0.5, consumed=1e-6 * (k + 1), dels=(10e6 + k, 12e6)),
            _spot("door", 3.0, consumed=0.0, verdict="no_damage_below_cutoff", dels=(1e6, 1.2e6)),
        ]) for k in range(total)
    ]
    hot = [_spot("flange", 0.5, consumed=2e-6, remaining=40.0, band=[30.0, 55.0], rate=2.5e-2),
           _spot("door", 3.0, consumed=0.0, verdict="no_damage_below_cutoff")]
    envelope = [StationLoadsDocument(position_m=p, strain_range_max=1e-4 / (1 + p), stress_range_max_pa=2.1e7 / (1 + p),
                                     strain_rms=2e-5 / (1 + p)) for p in (4.0, 0.0, 1.0, 2.0)]  # not in order: sorted
    return FatigueDocument(structure_id="mast", design_life_years=25.0, hot_spots=hot, windows=windows, envelope=envelope,
                           total=total, truncated=False)


def test_a_fatigue_document_becomes_the_tabs_record():
    rec = loads_record(_document())
    np.testing.assert_array_equal(rec.positions_m, [0.0, 1.0, 2.0, 4.0])
    np.testing.assert_allclose(rec.stress_range_max_pa, 2.1e7 / (1 + rec.positions_m), rtol=1e-12)
    np.testing.assert_array_equal(rec.t_s, [1120.0, 1240.0])  # each window at its end
    np.testing.assert_array_equal(rec.dels_pa["3"]["flange"], [10e6, 10e6 + 1])
    np.testing.assert_array_equal(rec.consumed["flange"], [1e-6, 2e-6])
    assert sorted(rec.dels_pa) == ["3", "5"] and rec.windows == 2 and not rec.truncated


def test_the_envelope_marks_the_hot_spots_on_the_beam():
    rec = loads_record(_document())
    x, stress, marker = envelope_plot(rec, [("flange", 0.5), ("door", 3.0)])
    np.testing.assert_array_equal(x, [0.0, 0.5, 1.0, 2.0, 3.0, 4.0])
    # between stations the range is interpolated linearly: at 0.5 m halfway between 21 and 10.5 MPa
    assert stress[1] == pytest.approx(0.5 * (21.0 + 10.5)) and stress[0] == pytest.approx(21.0)
    assert np.isfinite(marker).sum() == 2 and marker[1] == stress[1] and marker[4] == stress[4]


def test_the_table_says_remaining_life_with_its_band_and_no_damage_below_the_cut_off():
    text = hot_spots_html(loads_record(_document()))
    assert "40.0 years" in text and "(30.0 years – 55.0 years)" in text  # the remaining life and its band
    assert "no damage: below the cut-off" in text and "inf" not in text.lower()
    assert "design life 25.0 years" in text and "2 window(s) counted" in text
    assert "DEL<sub>3</sub> 10.00" in text and "max 30.00" in text  # the latest window's DEL and largest range, MPa
    empty = FatigueDocument(structure_id="m", design_life_years=None, hot_spots=[], windows=[], envelope=[], total=0)
    assert "No loads yet" in hot_spots_html(loads_record(empty))
    assert "boom" in hot_spots_html(loads_record(empty), "the loads could not be read: boom")


def test_a_life_shorter_than_the_design_life_is_marked():
    doc = _document()
    doc.hot_spots[0] = _spot("flange", 0.5, consumed=0.5, remaining=3.0, band=[2.0, 4.5], rate=0.1)
    text = hot_spots_html(loads_record(doc))
    assert "color:#dc2626;font-weight:bold'>3.0 years" in text
    # a life shorter than a year in days, shorter than a day in hours (never "0.0 years")
    day = 1 / 365.25
    doc.hot_spots[0] = _spot("flange", 0.5, consumed=0.5, remaining=10 * day, band=[5 * day / 24, 30 * day], rate=20.0)
    text = hot_spots_html(loads_record(doc))
    assert ">10.0 days</span>" in text and "(5.0 hours – 30.0 days)" in text


def test_a_document_without_the_fields_is_refused():
    with pytest.raises(ValueError, match="FatigueDocument"):
        loads_record({"hot_spots": []})
