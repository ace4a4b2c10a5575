"""The live ring's virtual loads of a beam that bends in two planes: each station at its angle
from both planes' curvature, the root moment per plane with its resultant, and an "all" hot spot
at the worst point found over the estimates kept (s'' = 1 per unit b: hand-computable)."""

from __future__ import annotations

import math

import numpy as np
from analytics import BiaxialVirtualLoads
from contract import parse_rig
from shm_service.service.runtime._live import LiveRing

RADIUS, WALL, E = 0.05, 0.004, 2.1e11
EI = E * math.pi / 64.0 * ((2 * RADIUS) ** 4 - (2 * RADIUS - 2 * WALL) ** 4)


def loads():
    tube = {"shape": "tube", "outer_diameter": 2 * RADIUS, "wall_thickness": WALL}
    rig = parse_rig({
        "beam": {"length": 3.0, "youngs_modulus": E, "density": 7850.0, "bending": "biaxial",
                 "sections": [{"position": 0.0, **tube}, {"position": 3.0, **tube}]},
        "gravity": 0.0, "support": "clamped", "orientation": "standing",
        "sensors": [{"name": "tip", "kind": "imu", "position": 3.0}],
        "hot_spots": [{"name": "w90", "position": 1.0, "curve": "EN1993-1-9:71", "angle_deg": 90},
                      {"name": "girth", "position": 0.5, "curve": "EN1993-1-9:71", "angle_deg": "all"}],
    })
    ones = lambda eta: np.ones((np.size(eta), 1))  # noqa: E731
    virtual = BiaxialVirtualLoads.from_rig_biaxial(rig, ones, ones, grid=0)
    return virtual, lambda x: (np.asarray(x)[..., 0:1], np.asarray(x)[..., 1:2])


def test_the_live_document_of_a_biaxial_beam_carries_angles_moments_per_plane_and_the_resultant():
    ring = LiveRing("s", ["b1", "bxi1"], hz=10.0, loads=loads())
    ring.read()  # a watch starts
    t = 1000.0 + 0.1 * np.arange(60)
    # bending along the +ξ axis (90°): ε(θ) = −R s(t) sin θ, largest at 90° and 270°
    s = 1e-3 * np.sin(2 * np.pi * 0.3 * (t - t[0]))
    ring.add(t, np.stack([0.0 * s, s], axis=1))
    doc = ring.document(0, {})
    assert doc.loads_station_names == ["w90", "girth"]
    assert doc.loads_worst_around == [False, True]
    assert doc.loads_angles_deg[0] == 90.0 and doc.loads_angles_deg[1] in (90.0, 270.0)
    sign = -1.0 if doc.loads_angles_deg[1] == 90.0 else 1.0
    np.testing.assert_allclose(np.array(doc.strain)[:, 0], -RADIUS * s, rtol=1e-12, atol=1e-18)
    np.testing.assert_allclose(np.array(doc.strain)[:, 1], sign * RADIUS * s, rtol=1e-12, atol=1e-18)
    np.testing.assert_allclose(doc.root_moment_nm, 0.0, atol=0.0)
    np.testing.assert_allclose(doc.root_moment_xi_nm, EI * s, rtol=1e-12)
    np.testing.assert_allclose(doc.root_moment_resultant_nm, EI * np.abs(s), rtol=1e-12)
    np.testing.assert_allclose(np.array(doc.moment_xi_nm)[:, 0], EI * s, rtol=1e-12)


def test_a_planar_live_document_has_no_biaxial_keys():
    from analytics import VirtualLoads

    rig = parse_rig({"beam": {"length": 3.0, "width": 0.06, "thickness": 0.02, "youngs_modulus": E, "density": 7850.0},
                     "gravity": 0.0, "support": "clamped", "sensors": [{"name": "tip", "kind": "imu", "position": 3.0}]})
    virtual = VirtualLoads.from_rig(rig, lambda eta: np.ones((np.size(eta), 1)), grid=2)
    ring = LiveRing("s", ["b1"], loads=(virtual, lambda x: np.asarray(x)[..., 0:1]))
    ring.read()
    ring.add(np.array([1000.0, 1000.1]), np.array([[1e-3], [2e-3]]))
    doc = ring.document(0, {})
    np.testing.assert_allclose(doc.strain, [[-0.01e-3, -0.01e-3], [-0.02e-3, -0.02e-3]], rtol=1e-12)
    assert doc.loads_angles_deg == [] and doc.loads_worst_around == []
    assert doc.moment_xi_nm is None and doc.root_moment_xi_nm is None and doc.root_moment_resultant_nm is None


def test_the_estimate_loads_of_a_biaxial_record_are_judged_over_the_whole_record():
    """/estimate/loads of a biaxial estimate: the payload's ξ figures, the girth weld at the worst
    point over every estimate (bending along −ζ, 180°: largest at 0° and 180°)."""
    from types import SimpleNamespace

    from shm_service.processing.estimation import _loads_of, _xi_loads

    virtual, _ = loads()
    layout = SimpleNamespace(b_of=lambda x: x[:, 0:1], b_xi_of=lambda x: x[:, 1:2])
    s = 1e-3 * np.sin(np.linspace(0.0, 30.0, 301))
    result = SimpleNamespace(model=SimpleNamespace(state_layout=layout), x=np.stack([-s, 0.0 * s], axis=1))
    out = _loads_of(virtual, result)
    assert out["angles_deg"][0] == 90.0 and out["angles_deg"][1] in (0.0, 180.0)
    np.testing.assert_allclose(out["strain"][:, 0], 0.0, atol=1e-20)  # the +ξ face does not strain in ζ bending
    payload = _xi_loads(out, 7)
    assert payload["root_moment_xi_nm"] == 0.0
    assert payload["root_moment_resultant_nm"] == abs(float(out["root_moment_nm"][7]))
    assert payload["moment_xi_nm"] == [0.0, 0.0]
    assert _xi_loads({"strain": out["strain"]}, 7) == {}
