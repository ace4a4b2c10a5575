"""The beam from ``beam.sections``: section properties, FE modes against a shooting reference."""

from __future__ import annotations

import copy
import itertools
import math

import numpy as np
import pytest
from section_reference import frequencies as shooting_frequencies

from contract import RigError, parse_rig
from estimator import BucklingError, assemble_beam, natural_modes

E, RHO = 2.1e11, 7850.0


def _rig(length, sections, *, gravity=0.0, support="clamped", orientation="hanging", point_masses=(), **beam):
    return parse_rig({
        "beam": {"length": length, "youngs_modulus": E, "density": RHO, "sections": sections, **beam},
        "gravity": gravity, "support": support, "orientation": orientation, "point_masses": list(point_masses),
        "sensors": [{"name": "D", "kind": "imu", "position": 0.0}, {"name": "g", "kind": "strain", "position": 1.0}],
    })


def tube(position, outer, wall):
    return {"position": position, "shape": "tube", "outer_diameter": outer, "wall_thickness": wall}


def rectangle(position, width, thickness):
    return {"position": position, "shape": "rectangle", "width": width, "thickness": thickness}


def table(position, stiffness, mass, fibre):
    return {"position": position, "shape": "table", "bending_stiffness": stiffness, "mass_per_length": mass,
            "fibre_distance": fibre}


# -- section properties ------------------------------------------------------------------
def test_tube_section_properties_are_the_closed_form():
    beam = _rig(2.0, [tube(0.0, 0.5, 0.01), tube(2.0, 0.5, 0.01)]).beam
    # D = 0.5, d = 0.48: A = π/4 (D² − d²) = π/4·0.0196, I = π/64 (D⁴ − d⁴) = π/64·0.00941584
    area = math.pi / 4 * 0.0196
    inertia = math.pi / 64 * 0.00941584
    assert beam.mass_per_length_at(1.0) == pytest.approx(RHO * area, rel=1e-13)
    assert beam.bending_stiffness(1.0) == pytest.approx(E * inertia, rel=1e-13)
    assert beam.fibre_distance(0.3) == pytest.approx(0.25, rel=1e-15)
    assert beam.mass == pytest.approx(2.0 * RHO * area, rel=1e-13)


def test_a_taper_varies_every_dimension_linearly():
    beam = _rig(10.0, [tube(0.0, 0.6, 0.02), tube(10.0, 0.2, 0.01)]).beam
    # at 2.5 m: D = 0.5, t = 0.0175, d = 0.465
    outer, inner = 0.5, 0.465
    assert beam.bending_stiffness(2.5) == pytest.approx(E * math.pi / 64 * (outer**4 - inner**4), rel=1e-13)
    assert beam.mass_per_length_at(2.5) == pytest.approx(RHO * math.pi / 4 * (outer**2 - inner**2), rel=1e-13)
    assert beam.fibre_distance(np.array([0.0, 2.5, 10.0])) == pytest.approx([0.3, 0.25, 0.1], rel=1e-14)
    # ∫ ρ π t (D − t) dx with D, t linear: a quadratic, Simpson's rule is exact
    f = lambda x: RHO * math.pi * (0.02 - 0.001 * x) * (0.6 - 0.04 * x - (0.02 - 0.001 * x))
    assert beam.mass == pytest.approx(10.0 / 6 * (f(0) + 4 * f(5) + f(10)), rel=1e-13)


def test_rectangle_taper_and_table_step():
    beam = _rig(4.0, [rectangle(0.0, 0.3, 0.02), rectangle(2.0, 0.1, 0.01), table(2.0, 100.0, 5.0, 0.004),
                      table(4.0, 20.0, 1.0, 0.002)]).beam
    # at 1 m: w = 0.2, h = 0.015
    assert beam.bending_stiffness(1.0) == pytest.approx(E * 0.2 * 0.015**3 / 12, rel=1e-13)
    assert beam.mass_per_length_at(1.0) == pytest.approx(RHO * 0.2 * 0.015, rel=1e-13)
    assert beam.fibre_distance(1.0) == pytest.approx(0.0075, rel=1e-13)
    # at the step the section beyond it (the station listed later)
    assert beam.bending_stiffness(2.0) == pytest.approx(100.0, rel=1e-15)
    assert beam.fibre_distance(2.0) == pytest.approx(0.004, rel=1e-15)
    assert beam.bending_stiffness(1.9999999) == pytest.approx(E * 0.1 * 0.01**3 / 12, rel=1e-5)
    assert beam.bending_stiffness(3.0) == pytest.approx(60.0, rel=1e-14)
    assert beam.mass_per_length_at(3.0) == pytest.approx(3.0, rel=1e-14)


def test_bending_stiffness_follows_the_temperature_coefficient_tables_too():
    beam = _rig(4.0, [table(0.0, 100.0, 5.0, 0.004), table(4.0, 100.0, 5.0, 0.004)],
                youngs_modulus_temperature_coefficient=-3e-4, reference_temperature=20.0).beam
    assert beam.bending_stiffness(1.0, temperature_c=30.0) == pytest.approx(100.0 * (1 - 3e-3), rel=1e-14)
    assert beam.bending_stiffness([1.0], temperature_c=None) == pytest.approx([100.0], rel=1e-15)


def test_the_uniform_sheet_is_a_single_rectangle():
    sheet = parse_rig({"beam": {"length": 4.0, "width": 0.2, "thickness": 0.002, "youngs_modulus": E, "density": RHO},
                       "gravity": 9.81, "reflector_distance": 0.5, "sensors": []}).beam
    x = np.array([0.0, 1.0, 4.0])
    assert sheet.bending_stiffness(x) == pytest.approx(E * 0.2 * 0.002**3 / 12 * np.ones(3), rel=1e-15)
    assert sheet.mass_per_length_at(x) == pytest.approx(RHO * 0.2 * 0.002 * np.ones(3), rel=1e-15)
    assert sheet.fibre_distance(x) == pytest.approx(0.001 * np.ones(3), rel=1e-15)


# -- bad input ------------------------------------------------------------------------------
def _mast():
    return {"beam": {"length": 20.0, "youngs_modulus": E, "density": RHO,
                     "sections": [tube(0.0, 0.6, 0.012), tube(5.0, 0.5, 0.01), tube(10.0, 0.45, 0.01),
                                  tube(20.0, 0.3, 0.006)]},
            "gravity": 9.81, "support": "clamped", "orientation": "standing",
            "sensors": [{"name": "D", "kind": "imu", "position": 0.0}]}


@pytest.mark.parametrize(("change", "message"), [
    (lambda d: d["beam"]["sections"][3].update(outer_diameter=-0.3), r"beam\.sections\[3\]\.outer_diameter"),
    (lambda d: d["beam"]["sections"][3].update(outer_diameter=float("nan")), r"beam\.sections\[3\]\.outer_diameter"),
    (lambda d: d["beam"]["sections"][2].pop("wall_thickness"), r"beam\.sections\[2\]\.wall_thickness"),
    (lambda d: d["beam"]["sections"][1].update(wall_thickness=0.3), r"beam\.sections\[1\].*wall_thickness"),
    (lambda d: d["beam"]["sections"][1].update(shape="box"), r"beam\.sections\[1\].*'box'"),
    (lambda d: d["beam"].update(width=0.2), r"beam\.width is not allowed together with beam\.sections"),
    (lambda d: d["beam"].update(thickness=0.2), r"beam\.thickness is not allowed"),
    (lambda d: d["beam"]["sections"][0].update(position=0.5), r"beam\.sections\[0\]\.position=0\.5 must be 0"),
    (lambda d: d["beam"]["sections"][3].update(position=19.0), r"beam\.sections\[3\]\.position=19.0 must equal"),
    (lambda d: d["beam"]["sections"][2].update(position=4.0), r"beam\.sections\[2\]\.position=4.0 is before"),
    (lambda d: d["beam"]["sections"].__setitem__(1, rectangle(5.0, 0.5, 0.01)), r"beam\.sections\[1\]\.shape='rectangle'"),
    (lambda d: d["beam"].update(sections=[tube(0.0, 0.6, 0.012), tube(5.0, 0.5, 0.01), tube(5.0, 0.4, 0.01),
                                          tube(5.0, 0.4, 0.008), tube(20.0, 0.3, 0.006)]),
     r"beam\.sections\[3\]\.position=5.0: three stations at one position"),
    (lambda d: d["beam"].update(sections=[tube(0.0, 0.6, 0.012)]), r"at least two stations"),
    (lambda d: d["beam"].pop("youngs_modulus"), r"beam\.youngs_modulus is required"),
    (lambda d: d["sensors"].append({"name": "t", "kind": "tof", "position": 1.0}), r"reflector_distance is required"),
])
def test_bad_sections_are_refused_naming_the_key(change, message):
    data = copy.deepcopy(_mast())
    change(data)
    with pytest.raises(RigError, match=message):
        parse_rig(data)


def test_a_beam_of_tables_needs_no_material_and_a_step_may_change_shape():
    data = {"beam": {"length": 2.0, "sections": [table(0.0, 10.0, 1.0, 0.01), table(2.0, 1.0, 0.5, 0.005)]},
            "gravity": 0.0, "support": "clamped", "sensors": []}
    beam = parse_rig(data).beam
    assert beam.youngs_modulus is None
    with pytest.raises(RigError, match="youngs_modulus is not given"):
        beam.youngs_modulus_at(20.0)
    mixed = parse_rig({**_mast(), "beam": {**_mast()["beam"], "sections": [
        tube(0.0, 0.6, 0.01), tube(5.0, 0.6, 0.01), rectangle(5.0, 0.3, 0.05), rectangle(20.0, 0.2, 0.05)]}})
    assert mixed.beam.fibre_distance([4.0, 5.0]) == pytest.approx([0.3, 0.025], rel=1e-15)


def test_uniform_properties_of_a_sectioned_beam_are_refused():
    beam = parse_rig(_mast()).beam
    for name in ("area", "second_moment_of_area", "mass_per_length"):
        with pytest.raises(RigError, match=f"beam.{name} is a property of the uniform rectangle"):
            getattr(beam, name)


@pytest.mark.parametrize("function", ["bending_stiffness", "mass_per_length_at", "fibre_distance"])
@pytest.mark.parametrize("positions", [-0.1, 20.5, float("nan"), [[1.0, 2.0]], "a"])
def test_properties_off_the_beam_are_refused(function, positions):
    beam = parse_rig(_mast()).beam
    with pytest.raises(RigError, match="positions"):
        getattr(beam, function)(positions)


@pytest.mark.parametrize("temperature", [float("nan"), float("inf"), "20", 4000.0])
def test_bending_stiffness_refuses_a_bad_temperature(temperature):
    with pytest.raises(RigError, match="temperature_c"):
        parse_rig(_mast()).beam.bending_stiffness(1.0, temperature_c=temperature)


# -- modes against the shooting reference --------------------------------------------------------
def _tube_profile(length, d0, d1, t0, t1):
    def outer(x):
        return d0 + (d1 - d0) * x / length

    def wall(x):
        return t0 + (t1 - t0) * x / length

    EI = lambda x: E * math.pi / 64 * (outer(x) ** 4 - (outer(x) - 2 * wall(x)) ** 4)
    mu = lambda x: RHO * math.pi / 4 * (outer(x) ** 2 - (outer(x) - 2 * wall(x)) ** 2)
    return EI, mu


def test_tapered_clamped_free_tube_matches_the_shooting_method_and_converges_with_the_mesh():
    rig = _rig(12.0, [tube(0.0, 0.4, 0.01), tube(12.0, 0.15, 0.004)])
    EI, mu = _tube_profile(12.0, 0.4, 0.15, 0.01, 0.004)
    fe = {n: natural_modes(assemble_beam(rig, elements=n), 4).frequencies_hz for n in (10, 20, 40)}
    ref = shooting_frequencies(4, f_max=1.3 * fe[40][-1], samples=150, length=12.0, EI=EI, mu=mu)
    assert fe[40] == pytest.approx(ref, rel=1e-4)
    errors = [np.max(np.abs(fe[n] / ref - 1)) for n in (10, 20, 40)]
    # a taper integrated over each element converges like the uniform beam, h⁴ (not as a staircase, h)
    assert errors[1] < errors[0] / 8 and errors[2] < errors[1] / 8


def test_standing_tapered_mast_under_its_weight_matches_the_shooting_method():
    rig = _rig(20.0, [tube(0.0, 0.6, 0.012), tube(20.0, 0.3, 0.006)], gravity=9.81, orientation="standing",
               point_masses=[{"position": 20.0, "mass": 150.0}, {"position": 8.0, "mass": 60.0}])
    EI, mu = _tube_profile(20.0, 0.6, 0.3, 0.012, 0.006)
    model = assemble_beam(rig)
    fe = natural_modes(model, 4).frequencies_hz
    ref = shooting_frequencies(4, f_max=1.3 * fe[-1], samples=150, length=20.0, EI=EI, mu=mu,
                               masses=[(20.0, 150.0), (8.0, 60.0)], axial_gravity=-9.81)
    assert fe == pytest.approx(ref, rel=1e-4)
    # the compression softens it: without gravity every mode is stiffer
    weightless = natural_modes(assemble_beam(_rig(20.0, [tube(0.0, 0.6, 0.012), tube(20.0, 0.3, 0.006)],
                                                   point_masses=[{"position": 20.0, "mass": 150.0},
                                                                 {"position": 8.0, "mass": 60.0}])), 4).frequencies_hz
    assert np.all(weightless > fe)
    assert 1.0 < model.critical_load_factor < np.inf


def test_pinned_hanging_tapered_rectangle_matches_the_shooting_method():
    rig = _rig(4.0, [rectangle(0.0, 0.2, 0.004), rectangle(4.0, 0.1, 0.002)], gravity=9.81, support="pinned")

    def EI(x):
        return E * (0.2 - 0.025 * x) * (0.004 - 0.0005 * x) ** 3 / 12

    def mu(x):
        return RHO * (0.2 - 0.025 * x) * (0.004 - 0.0005 * x)

    fe = natural_modes(assemble_beam(rig), 5).frequencies_hz
    ref = shooting_frequencies(5, f_max=1.3 * fe[-1], samples=150, length=4.0, EI=EI, mu=mu, axial_gravity=9.81,
                               support="pinned")
    assert fe == pytest.approx(ref, rel=1e-4)


BLADE_STATIONS = [  # x (m), EI (N·m²), μ (kg/m), c (m): a stiffness falling 100-fold, a step at 2 m
    (0.0, 4.0e7, 120.0, 0.25), (2.0, 2.0e7, 80.0, 0.2), (2.0, 1.2e7, 60.0, 0.18), (5.0, 2.0e6, 25.0, 0.1),
    (8.0, 4.0e5, 8.0, 0.04),
]


def _table_profile(stations):
    xs = [s[0] for s in stations]

    def pick(x, column):
        # the stretch that holds x (the integration never evaluates exactly at a step)
        for (xa, *a), (xb, *b) in itertools.pairwise(stations):
            if xb > xa and xa <= x <= xb:
                return a[column] + (b[column] - a[column]) * (x - xa) / (xb - xa)
        raise ValueError(x)

    return (lambda x: pick(x, 0)), (lambda x: pick(x, 1)), xs


def test_table_section_blade_with_a_step_matches_the_shooting_method():
    rig = _rig(8.0, [table(*s) for s in BLADE_STATIONS], gravity=9.81)
    EI, mu, breaks = _table_profile(BLADE_STATIONS)
    assert 2.0 in assemble_beam(rig).nodes  # a node at every station
    fe = natural_modes(assemble_beam(rig), 6).frequencies_hz
    ref = shooting_frequencies(6, f_max=1.3 * fe[-1], samples=200, length=8.0, EI=EI, mu=mu, breaks=breaks,
                               axial_gravity=9.81)
    assert fe == pytest.approx(ref, rel=1e-4)


def test_tube_rectangle_and_table_with_equal_EI_and_mu_give_the_same_modes():
    area, inertia = 0.004, 2.0e-5  # m², m⁴
    outer = math.sqrt((16 * inertia / area + 4 * area / math.pi) / 2)
    inner = math.sqrt((16 * inertia / area - 4 * area / math.pi) / 2)
    depth = math.sqrt(12 * inertia / area)
    shapes = {
        "tube": [tube(0.0, outer, (outer - inner) / 2), tube(6.0, outer, (outer - inner) / 2)],
        "rectangle": [rectangle(0.0, area / depth, depth), rectangle(6.0, area / depth, depth)],
        "table": [table(0.0, E * inertia, RHO * area, 0.1), table(6.0, E * inertia, RHO * area, 0.1)],
    }
    found = {name: natural_modes(assemble_beam(_rig(6.0, s, gravity=9.81, orientation="standing")), 6).frequencies_hz
             for name, s in shapes.items()}
    uniform = parse_rig({"beam": {"length": 6.0, "width": area / depth, "thickness": depth, "youngs_modulus": E,
                                  "density": RHO}, "gravity": 9.81, "support": "clamped", "orientation": "standing",
                         "sensors": []})
    found["uniform"] = natural_modes(assemble_beam(uniform), 6).frequencies_hz
    # equal to rounding: the lowest eigenvalue of the generalised problem carries eps·‖K‖, ~1e-8 of it here
    for name, f in found.items():
        assert f == pytest.approx(found["table"], rel=1e-6), name


def test_a_standing_tapered_beam_that_buckles_is_refused_with_its_critical_load_factor():
    sections = [tube(0.0, 0.12, 0.004), tube(40.0, 0.05, 0.002)]
    critical = assemble_beam(_rig(40.0, sections, gravity=0.1, orientation="standing")).critical_load_factor
    g_cr = 0.1 * critical
    assert 0.5 < g_cr < 9.81  # it buckles under earth's gravity
    with pytest.raises(BucklingError, match=r"λ_cr = .*beam\.sections") as caught:
        assemble_beam(_rig(40.0, sections, gravity=9.81, orientation="standing"))
    assert caught.value.critical_load_factor == pytest.approx(g_cr / 9.81, rel=1e-9)
    assemble_beam(_rig(40.0, sections, gravity=0.99 * g_cr, orientation="standing"))
    with pytest.raises(BucklingError):
        assemble_beam(_rig(40.0, sections, gravity=1.01 * g_cr, orientation="standing"))
    # the mode softens to zero at the critical load
    f = natural_modes(assemble_beam(_rig(40.0, sections, gravity=0.999 * g_cr, orientation="standing")), 1)
    f0 = natural_modes(assemble_beam(_rig(40.0, sections, gravity=0.0, orientation="standing")), 1)
    assert f.frequencies_hz[0] < 0.05 * f0.frequencies_hz[0]


def test_sectioned_beam_frequencies_follow_the_temperature():
    rig = _rig(12.0, [tube(0.0, 0.4, 0.01), tube(12.0, 0.15, 0.004)])
    f20 = natural_modes(assemble_beam(rig, temperature_c=20.0), 3).frequencies_hz
    f50 = natural_modes(assemble_beam(rig, temperature_c=50.0), 3).frequencies_hz
    assert f50 / f20 == pytest.approx(np.sqrt(1 - 3e-4 * 30) * np.ones(3), rel=1e-7)


# -- the estimator and the damage signatures on a sectioned beam --------------------------------------
def _example_mast_with_bearing():
    from example_mast import planar_mast_data

    data = planar_mast_data()  # the planar estimator's strain rows (Eq. 19)
    data["sensors"].append({"name": "bearing", "kind": "bearing"})
    return parse_rig(data)


def test_strain_aiding_uses_the_fibre_distance_of_the_section():
    from estimator import build_model

    rig = _example_mast_with_bearing()
    model = build_model(rig, modes=4, imus=4, tofs=0, gauges=4)
    eta = model.gauge_eta
    # Eq. (19) with c(η) = D(η)/2 of the tube at each gauge instead of h*/2
    outer = np.interp(eta, [0.0, 8.0, 20.0], [0.5, 0.38, 0.2])  # the example's taper (the step at 8 m is in t only)
    expected = -0.5 * outer[:, None] * model.modal.curvature(eta)
    np.testing.assert_allclose(model.strain_matrix(), expected, rtol=1e-13, atol=0)


def test_damage_signatures_of_a_tapered_mast_match_an_exact_fe_solve():
    from estimator import PointMass, StiffnessSegment, damage_signatures

    rig = _example_mast_with_bearing()
    sig = damage_signatures(rig, step=2.0, segment_length=2.0)
    pick = lambda kind, eta: int(np.flatnonzero((np.array(sig.kind) == kind) & np.isclose(sig.eta, eta))[0])
    seg = StiffnessSegment(start=2.0, end=4.0, factor=0.8)
    damaged = rig.model_copy(update={"beam": rig.beam.model_copy(update={"stiffness_segments": (seg,)})})
    f0 = natural_modes(assemble_beam(rig, extra_nodes=(2.0, 4.0)), 4).frequencies_hz
    f1 = natural_modes(assemble_beam(damaged, extra_nodes=(2.0, 4.0)), 4).frequencies_hz
    np.testing.assert_allclose(sig.frequency_shift[pick("stiffness", 3.0)], f1 / f0 - 1, rtol=2e-3, atol=1e-7)
    tip = PointMass(position=20.0, mass=0.01 * rig.beam.mass)
    heavy = rig.model_copy(update={"point_masses": tuple(rig.point_masses) + (tip,)})
    f2 = natural_modes(assemble_beam(heavy, extra_nodes=(20.0,)), 4).frequencies_hz
    np.testing.assert_allclose(sig.frequency_shift[pick("mass", 20.0)], f2 / f0 - 1, rtol=2e-3, atol=1e-7)


@pytest.mark.parametrize(("start", "end"), [(1.0, 1.0), (-0.1, 1.0), (1.0, 20.5), (float("nan"), 1.0)])
def test_element_bending_stiffness_refuses_a_bad_element(start, end):
    from estimator._beam import element_bending_stiffness

    with pytest.raises(ValueError, match="element"):
        element_bending_stiffness(parse_rig(_mast()).beam, start, end)


def test_element_bending_stiffness_of_a_uniform_stretch_is_the_textbook_matrix():
    from estimator._beam import element_bending_stiffness

    beam = _rig(2.0, [table(0.0, 50.0, 1.0, 0.01), table(2.0, 50.0, 1.0, 0.01)]).beam
    l = 0.5
    textbook = 50.0 / l**3 * np.array([[12, 6 * l, -12, 6 * l], [6 * l, 4 * l * l, -6 * l, 2 * l * l],
                                       [-12, -6 * l, 12, -6 * l], [6 * l, 2 * l * l, -6 * l, 4 * l * l]])
    np.testing.assert_allclose(element_bending_stiffness(beam, 0.5, 1.0), textbook, rtol=1e-13, atol=1e-11)


def test_to_json_leaves_out_what_is_not_given_and_round_trips():
    import json

    rig = parse_rig({"beam": {"length": 2.0, "sections": [table(0.0, 10.0, 1.0, 0.01), table(2.0, 1.0, 0.5, 0.005)]},
                     "gravity": 9.81, "support": "clamped", "sensors": []})
    data = json.loads(rig.to_json())
    assert not {"width", "thickness", "youngs_modulus", "density"} & set(data["beam"])
    assert "reflector_distance" not in data
    assert parse_rig(rig.to_json()) == rig
    sheet = parse_rig({"beam": {"length": 4.0, "width": 0.2, "thickness": 0.002, "youngs_modulus": E, "density": RHO},
                       "gravity": 9.81, "reflector_distance": 0.5, "sensors": []})
    assert "sections" not in json.loads(sheet.to_json())["beam"]



def test_the_loads_of_hot_spots_on_a_beam_of_tables_need_the_youngs_modulus_of_their_material():
    from analytics import LoadsMonitor

    data = {"beam": {"length": 2.0, "sections": [table(0.0, 10.0, 1.0, 0.01), table(2.0, 1.0, 0.5, 0.005)]},
            "gravity": 9.81, "support": "clamped", "sensors": [],
            "hot_spots": [{"name": "root", "position": 0.1, "curve": "EN1993-1-9:71"}]}
    rig = parse_rig(data)  # the rig itself is valid: estimation and modes need no E
    curvature = lambda eta: np.ones((len(eta), 2))
    with pytest.raises(ValueError, match="beam.youngs_modulus is not given"):
        LoadsMonitor.from_rig(rig, curvature)
    data["beam"]["youngs_modulus"] = 2.1e11
    assert LoadsMonitor.from_rig(parse_rig(data), curvature).youngs_modulus == 2.1e11
