"""beam.bending = "biaxial" in rig.json: the clamp it needs, the ξ section properties, angles
around the section and the point an angle names on the outline (recording-format.md, "Bending in
two planes")."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from contract import RigError, parse_rig

E, RHO = 2.1e11, 7850.0
GAUGES = [{"name": "D", "kind": "imu", "position": 0.0}, {"name": "g", "kind": "strain", "position": 1.0}]


def rig(beam: dict, *, support: str = "clamped", sensors=None, hot_spots=()) -> dict:
    return {"beam": {"length": 2.0, **beam}, "gravity": 0.0, "support": support, "sensors": sensors or GAUGES,
            "hot_spots": list(hot_spots)}


RECTANGLE = {"width": 0.06, "thickness": 0.02, "youngs_modulus": E, "density": RHO}
TUBE = {"youngs_modulus": E, "density": RHO,
        "sections": [{"position": 0.0, "shape": "tube", "outer_diameter": 0.1, "wall_thickness": 0.004},
                     {"position": 2.0, "shape": "tube", "outer_diameter": 0.1, "wall_thickness": 0.004}]}


def table(**xi) -> dict:
    station = {"shape": "table", "bending_stiffness": 6.0e4, "mass_per_length": 5.0, "fibre_distance": 0.02}
    return {"sections": [{"position": 0.0, **station, **xi}, {"position": 2.0, **station, **xi}]}


TABLE_XI = {"bending_stiffness_xi": 2.4e5, "fibre_distance_xi": 0.01}


def test_bending_defaults_to_planar_and_a_planar_description_reads_and_writes_as_before():
    planar = parse_rig(rig(RECTANGLE))
    assert planar.beam.bending == "planar" and not planar.beam.biaxial
    assert planar.sensors[1].angle_deg == 0.0
    written = json.loads(planar.to_json())
    assert "bending" not in written["beam"]
    assert all("angle_deg" not in sensor for sensor in written["sensors"])
    biaxial = parse_rig(rig(RECTANGLE | {"bending": "biaxial"}, sensors=[*GAUGES, {"name": "g90", "kind": "strain",
                                                                                  "position": 1.0, "angle_deg": 90}]))
    assert parse_rig(biaxial.to_json()) == biaxial


def test_a_pinned_biaxial_beam_is_refused_naming_the_keys():
    with pytest.raises(RigError, match=r"beam.bending='biaxial' needs support='clamped', got support='pinned'"):
        parse_rig(rig(RECTANGLE | {"bending": "biaxial"}, support="pinned"))


def test_another_bending_is_refused_naming_the_key():
    with pytest.raises(RigError, match=r"beam.bending: Input should be 'planar' or 'biaxial'"):
        parse_rig(rig(RECTANGLE | {"bending": "torsional"}))


def test_a_table_station_of_a_biaxial_beam_without_its_xi_keys_is_refused_naming_station_and_key():
    data = rig(table(**TABLE_XI) | {"bending": "biaxial"})
    del data["beam"]["sections"][1]["fibre_distance_xi"]
    with pytest.raises(RigError, match=r"beam.sections\[1\].fibre_distance_xi is required"):
        parse_rig(data)
    with pytest.raises(RigError, match=r"beam.sections\[0\].bending_stiffness_xi is required"):
        parse_rig(rig(table(fibre_distance_xi=0.01) | {"bending": "biaxial"}))
    # a planar beam ignores them
    assert parse_rig(rig(table())).beam.bending == "planar"


def test_a_planar_beam_accepts_only_the_angles_0_and_180():
    parse_rig(rig(RECTANGLE, sensors=[*GAUGES, {"name": "under", "kind": "strain", "position": 1.0, "angle_deg": 180}]))
    with pytest.raises(RigError, match=r"sensors\[2\] \(strain 'side'\): angle_deg=90, but a planar beam accepts only 0 and 180"):
        parse_rig(rig(RECTANGLE, sensors=[*GAUGES, {"name": "side", "kind": "strain", "position": 1.0, "angle_deg": 90}]))
    spot = {"name": "weld", "position": 0.1, "curve": "EN1993-1-9:71"}
    parse_rig(rig(RECTANGLE, hot_spots=[spot | {"angle_deg": 180}]))
    for angle in (45, "all"):
        with pytest.raises(RigError, match=rf"hot_spots\[0\] \('weld'\): angle_deg={angle!r}, but a planar beam"):
            parse_rig(rig(RECTANGLE, hot_spots=[spot | {"angle_deg": angle}]))
    biaxial = parse_rig(rig(TUBE | {"bending": "biaxial"}, hot_spots=[spot | {"angle_deg": "all"}, spot | {"name": "b", "angle_deg": 45}]))
    assert [s.angle_deg for s in biaxial.hot_spots] == ["all", 45.0]


def test_the_xi_stiffness_of_a_rectangle_lies_across_its_width_a_tube_is_round_a_table_gives_it():
    rectangle = parse_rig(rig(RECTANGLE | {"bending": "biaxial"})).beam
    assert rectangle.bending_stiffness_xi(1.0) == pytest.approx(E * 0.02 * 0.06**3 / 12, rel=1e-15)
    assert rectangle.bending_stiffness(1.0) == pytest.approx(E * 0.06 * 0.02**3 / 12, rel=1e-15)
    assert rectangle.fibre_distance_xi(1.0) == 0.03
    tube = parse_rig(rig(TUBE | {"bending": "biaxial"})).beam
    np.testing.assert_array_equal(tube.bending_stiffness_xi([0.0, 1.0, 2.0]), tube.bending_stiffness([0.0, 1.0, 2.0]))
    tapered = table(**TABLE_XI) | {"bending": "biaxial"}
    tapered["sections"][1] |= {"bending_stiffness_xi": 4.4e5, "fibre_distance_xi": 0.03}
    blade = parse_rig(rig(tapered)).beam
    assert blade.bending_stiffness_xi(1.0) == pytest.approx(3.4e5, rel=1e-15)  # linear between the stations
    assert blade.fibre_distance_xi(1.0) == pytest.approx(0.02, rel=1e-15)
    assert blade.bending_stiffness_xi(1.0, 120.0) == pytest.approx(3.4e5 * (1 - 3e-4 * 100), rel=1e-14)


ROOT_HALF = math.sqrt(0.5)


@pytest.mark.parametrize("beam, expected", [
    # rectangle: c = 0.01 along ζ, c_ξ = 0.03 along ξ: the 45° ray leaves through the ζ face
    (RECTANGLE, {0: (0.01, 0.0), 45: (0.01, 0.01), 90: (0.0, 0.03), 180: (-0.01, 0.0), 225: (-0.01, -0.01)}),
    # tube: the outer circle of radius 0.05
    (TUBE, {0: (0.05, 0.0), 45: (0.05 * ROOT_HALF, 0.05 * ROOT_HALF), 90: (0.0, 0.05), 180: (-0.05, 0.0),
            225: (-0.05 * ROOT_HALF, -0.05 * ROOT_HALF)}),
    # table: c = 0.02, c_ξ = 0.01: the 45° ray leaves through the ξ face
    (table(**TABLE_XI), {0: (0.02, 0.0), 45: (0.01, 0.01), 90: (0.0, 0.01), 180: (-0.02, 0.0), 225: (-0.01, -0.01)}),
], ids=["rectangle", "tube", "table"])
def test_section_point_is_where_the_ray_at_the_angle_meets_the_outline(beam, expected):
    described = parse_rig(rig(beam | {"bending": "biaxial"})).beam
    for angle, (zeta_p, xi_p) in expected.items():
        point = described.section_point(1.0, angle)
        assert point == pytest.approx((zeta_p, xi_p), rel=1e-12, abs=1e-18), angle
    # the faces are exact: a gauge at 0 reads −c·κζ bit for bit as on a planar beam
    assert described.section_point(1.0, 0) == (described.fibre_distance(1.0), 0.0)
    zeta_p, xi_p = described.section_point([0.5, 1.0, 1.5], [0, 90, 180])
    assert zeta_p.shape == xi_p.shape == (3,)


def test_section_point_of_a_planar_beam_is_a_zeta_face_and_refuses_other_angles():
    planar = parse_rig(rig(RECTANGLE)).beam
    assert planar.section_point(1.0, 0.0) == (0.01, 0.0)
    assert planar.section_point(1.0, 180.0) == (-0.01, 0.0)
    with pytest.raises(RigError, match=r"angle_deg=90: a planar beam accepts only 0 and 180"):
        planar.section_point(1.0, 90.0)
    with pytest.raises(RigError, match="outside the beam"):
        planar.section_point(3.0, 0.0)
