"""A beam that bends in two planes on the dashboard: the ξ deflection in the world (+y standing,
−y hanging), the sheet offset by it, the state's bξ, and the tip orbit's uPlot data."""

from __future__ import annotations

import numpy as np
import pytest

from contract import StateLayout
from web._geometry import BeamState, lateral, parse_state, ribbon
from web._orbit import orbit_plot


class Linear:
    """One unit deformation s(η) = η (m per unit b)."""

    count = 1

    def shape(self, eta):
        return np.atleast_1d(np.asarray(eta, dtype=float))[:, None]


def test_the_xi_deflection_is_world_plus_y_standing_and_minus_y_hanging_overscaled():
    state = BeamState(0.0, 0.0, 0.0, np.zeros(1), b_xi=np.array([0.01]))
    eta = np.array([0.0, 1.0, 2.0])
    assert lateral(state, Linear(), eta, elastic_scale=10.0, standing=True).tolist() == pytest.approx([0.0, 0.1, 0.2])
    assert lateral(state, Linear(), eta, elastic_scale=10.0, standing=False).tolist() == pytest.approx([0.0, -0.1, -0.2])
    assert lateral(state, None, eta).tolist() == [0.0, 0.0, 0.0]  # a planar beam
    assert lateral(BeamState(0.0, 0.0, 0.0, np.zeros(1)), Linear(), eta).tolist() == [0.0, 0.0, 0.0]


def test_the_sheet_is_offset_by_the_xi_deflection():
    plane = np.array([[0.0, 0.0], [1.0, 0.5]])
    verts = ribbon(plane, 0.2, standing=True, offset=np.array([0.0, 0.3]))
    assert verts[:, 1].tolist() == pytest.approx([-0.1, 0.1, 0.2, 0.4])
    assert ribbon(plane, 0.2, standing=True).tolist() == ribbon(plane, 0.2, standing=True, offset=np.zeros(2)).tolist()
    with pytest.raises(ValueError, match="offset has shape"):
        ribbon(plane, 0.2, offset=np.zeros(3))


def test_a_biaxial_state_carries_b_xi_and_a_planar_one_none():
    layout = StateLayout("gyro", 2, 1, attitude=False, gamma_xi=1)
    x = np.arange(layout.size, dtype=float)
    state = parse_state(x, layout)
    assert state.b.tolist() == x[layout.b].tolist() and state.b_xi.tolist() == x[layout.b_xi].tolist()
    assert parse_state(np.zeros(StateLayout("gyro", 2, 1).size), StateLayout("gyro", 2, 1)).b_xi.size == 0


def test_the_orbit_is_drawn_sorted_by_xi_with_the_newest_position_marked_on_one_square_range():
    (x, zeta, newest), scales = orbit_plot(np.array([1.0, -2.0, 3.0]), np.array([0.5, -1.0, 0.0]))
    assert x.tolist() == [-1.0, 0.0, 0.5] and zeta.tolist() == [-2.0, 3.0, 1.0]
    assert np.isnan(newest[[0, 2]]).all() and newest[1] == 3.0  # the last position given: ξ 0, ζ 3
    assert scales["x"]["range"] == scales["y"]["range"] == pytest.approx([-3.3, 3.3])
    assert scales["x"]["time"] is False
    (x, zeta, newest), _ = orbit_plot(np.zeros(0), np.zeros(0))
    assert x.size == 2 and np.isnan(zeta).all()
