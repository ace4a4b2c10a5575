"""Hot spots and fatigue settings of rig.json, the uniform beam's c(η) and EI(η, T)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from contract import RigError, parse_rig
from shm_service.rig_layouts import default_rig

HOT_SPOTS = [
    {"name": "base_flange_weld", "position": 0.15, "curve": "EN1993-1-9:71", "scf": 1.0, "gamma_Ff": 1.0, "gamma_Mf": 1.35},
    {"name": "door_opening", "position": 2.0, "curve": "EN1993-1-9:90", "scf": 2.4},
    {"name": "root_flange", "position": 0.1, "curve": "DNV-RP-C203:D:air"},
    {"name": "custom", "position": 1.0, "curve": {"points": [[1e4, 400e6], [1e7, 80e6], [1e9, 50e6]]}},
]


def _rig(**changes) -> dict:
    data = json.loads(default_rig().to_json())
    data.update(changes)
    return data


def test_hot_spots_as_in_the_interface():
    rig = parse_rig(_rig(hot_spots=HOT_SPOTS, fatigue={"design_life_years": 20}))
    assert [h.name for h in rig.hot_spots] == ["base_flange_weld", "door_opening", "root_flange", "custom"]
    assert rig.hot_spots[1].scf == 2.4 and rig.hot_spots[1].gamma_Mf == 1.0 and rig.hot_spots[0].gamma_Mf == 1.35
    assert rig.fatigue.design_life_years == 20
    assert parse_rig(rig.to_json()) == rig  # round trip
    assert parse_rig(_rig()).hot_spots == () and parse_rig(_rig()).fatigue is None


@pytest.mark.parametrize("spot, message", [
    ({"position": 4.5}, r"hot_spots\[0\] \('s'\): position=4.5 is outside the beam \[0, 4.0\]"),
    ({"position": -0.1}, r"position=-0.1 is outside the beam"),
    ({"curve": "EN1993-1-9:72"}, r"hot_spots\[0\]\.curve: .*unknown EN 1993-1-9 detail category '72'"),
    ({"curve": "DNV-RP-C203:D:lake"}, r"hot_spots\[0\]\.curve: .*unknown DNV-RP-C203 environment 'lake'"),
    ({"curve": {"points": [[1e6, 50e6]]}}, r"hot_spots\[0\]\.curve: .*at least two"),
    ({"scf": 0}, r"hot_spots\[0\]\.scf: Input should be greater than 0"),
    ({"gamma_Ff": -1.0}, r"hot_spots\[0\]\.gamma_Ff: Input should be greater than 0"),
    ({"gamma_Mf": 0.0}, r"hot_spots\[0\]\.gamma_Mf: Input should be greater than 0"),
])
def test_bad_hot_spots_name_the_key(spot, message):
    with pytest.raises(RigError, match=message):
        parse_rig(_rig(hot_spots=[{"name": "s", "position": 1.0, "curve": "EN1993-1-9:71", **spot}]))


def test_duplicate_hot_spot_and_bad_design_life():
    with pytest.raises(RigError, match=r"hot_spots\[1\]: name 'a' is not unique"):
        parse_rig(_rig(hot_spots=[{"name": "a", "position": 1.0, "curve": "EN1993-1-9:71"}] * 2))
    with pytest.raises(RigError, match=r"fatigue.design_life_years: Input should be greater than 0"):
        parse_rig(_rig(fatigue={"design_life_years": 0}))


def test_uniform_fibre_distance_and_bending_stiffness():
    beam = default_rig().beam
    eta = np.array([0.0, 1.0, beam.length])
    assert beam.fibre_distance(eta).tolist() == [beam.thickness / 2] * 3
    ei = beam.width * beam.thickness**3 / 12 * beam.youngs_modulus
    assert beam.bending_stiffness(eta) == pytest.approx([ei] * 3, rel=1e-12)
    warm = beam.bending_stiffness(1.0, temperature_c=beam.reference_temperature + 10)
    assert warm == pytest.approx(ei * (1 + 10 * beam.youngs_modulus_temperature_coefficient), rel=1e-12)
    with pytest.raises(RigError, match=r"position 5.0 is outside the beam \[0, 4.0\] m"):
        beam.fibre_distance([1.0, 5.0])
