"""The live view's virtual loads of a beam that bends in two planes: each station at its point of
the section, ε = −(ζp κζ + ξp κξ), the moments per plane with the root's resultant, and a girth
weld of angle "all" at its worst point around the section. Hand-made curvature shapes (s'' = 1 per
unit b), so every figure is hand-computable."""

from __future__ import annotations

import math

import numpy as np
import pytest

from analytics import BiaxialVirtualLoads, VirtualLoads
from contract import parse_rig

RADIUS, WALL, E = 0.05, 0.004, 2.1e11
EI = E * math.pi / 64.0 * ((2 * RADIUS) ** 4 - (2 * RADIUS - 2 * WALL) ** 4)


def tube_rig(hot_spots=(), bending="biaxial"):
    tube = {"shape": "tube", "outer_diameter": 2 * RADIUS, "wall_thickness": WALL}
    return parse_rig({
        "beam": {"length": 3.0, "youngs_modulus": E, "density": 7850.0, "bending": bending,
                 "sections": [{"position": 0.0, **tube}, {"position": 3.0, **tube}]},
        "gravity": 0.0, "support": "clamped", "orientation": "standing",
        "sensors": [{"name": "tip", "kind": "imu", "position": 3.0}], "hot_spots": list(hot_spots),
    })


def spot(name, position, angle):
    return {"name": name, "position": position, "curve": "EN1993-1-9:71", "angle_deg": angle}


def unit(eta):
    """s'' = 1 everywhere: κ = b."""
    return np.ones((np.size(eta), 1))


def test_a_station_at_45_degrees_strains_with_both_curvatures():
    rig = tube_rig([spot("w45", 1.0, 45.0), spot("w90", 2.0, 90.0)])
    loads = BiaxialVirtualLoads.from_rig_biaxial(rig, unit, unit, grid=2)
    assert loads.names == ["w45", "w90", "", ""]
    assert loads.angles_deg.tolist() == [45.0, 90.0, 0.0, 0.0]
    out = loads(np.array([[1e-3]]), b_xi=np.array([[2e-3]]))
    c = RADIUS / math.sqrt(2.0)
    expected = [-(c * 1e-3 + c * 2e-3), -RADIUS * 2e-3, -RADIUS * 1e-3, -RADIUS * 1e-3]
    assert out["strain"][0].tolist() == pytest.approx(expected, rel=1e-12)
    assert out["stress_pa"][0].tolist() == pytest.approx([E * v for v in expected], rel=1e-12)
    assert out["moment_nm"][0].tolist() == pytest.approx([EI * 1e-3] * 4, rel=1e-12)
    assert out["moment_xi_nm"][0].tolist() == pytest.approx([EI * 2e-3] * 4, rel=1e-12)
    assert out["root_moment_nm"].tolist() == pytest.approx([EI * 1e-3], rel=1e-12)
    assert out["root_moment_xi_nm"].tolist() == pytest.approx([EI * 2e-3], rel=1e-12)
    assert out["root_moment_resultant_nm"].tolist() == pytest.approx([EI * math.sqrt(5.0) * 1e-3], rel=1e-12)


def test_the_grid_at_zero_degrees_is_the_planar_figure_when_the_beam_does_not_bend_in_xi():
    rig = tube_rig()
    b = np.array([[1e-3], [-2e-3]])
    biaxial = BiaxialVirtualLoads.from_rig_biaxial(rig, unit, unit, grid=4)(b, b_xi=np.zeros((2, 1)))
    planar = VirtualLoads.from_rig(tube_rig(bending="planar"), unit, grid=4)(b)
    for key in ("strain", "stress_pa", "moment_nm", "root_moment_nm"):
        assert biaxial[key].tolist() == planar[key].tolist()


def test_an_all_hot_spot_is_evaluated_at_its_worst_point_around_the_section():
    """Bending along 100°: ε(θ) = −R s(t) cos(θ − 100°), largest at 100° and its opposite, 280°."""
    rig = tube_rig([spot("girth", 1.0, "all")])
    loads = BiaxialVirtualLoads.from_rig_biaxial(rig, unit, unit, grid=0)
    assert loads.worst_around.tolist() == [True]
    s = 1e-3 * np.sin(np.linspace(0.0, 40.0, 4001))[:, None]
    direction = math.radians(100.0)
    b, b_xi = math.cos(direction) * s, math.sin(direction) * s
    angle = float(loads.judge(b, b_xi)[0])
    assert angle in (100.0, 280.0)
    out = loads(b, b_xi=b_xi)
    assert out["angles_deg"].tolist() == [angle]
    assert np.max(np.abs(out["strain"][:, 0])) == pytest.approx(RADIUS * 1e-3 * np.max(np.abs(s[:, 0])) / 1e-3, rel=1e-9)


def test_bad_input_is_named():
    rig = tube_rig()
    with pytest.raises(ValueError, match="bending = 'biaxial'"):
        BiaxialVirtualLoads.from_rig_biaxial(tube_rig(bending="planar"), unit, unit)
    loads = BiaxialVirtualLoads.from_rig_biaxial(rig, unit, unit, grid=2)
    with pytest.raises(ValueError, match="need b_xi"):
        loads(np.zeros((1, 1)))
    with pytest.raises(ValueError, match="b_xi"):
        loads(np.zeros((1, 1)), b_xi=np.zeros((1, 2)))
