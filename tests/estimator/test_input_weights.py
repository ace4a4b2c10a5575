"""The interpolation of the IMU inputs between samples (``input_weights``): exact for a quadratic."""

import numpy as np
import pytest

from estimator._imms import input_weights

DT = 0.005


def test_quadratic_through_three_evenly_spaced_samples_is_exact():
    # u(t) = 2 − 3t + 40t²: the weights at any tau in [t_held, t_next] reproduce it exactly.
    u = lambda t: 2.0 - 3.0 * t + 40.0 * t**2  # noqa: E731
    t_prev, t_held, t_next = 1.0, 1.0 + DT, 1.0 + 2 * DT
    for tau in (t_held, t_held + 0.25 * DT, t_held + 0.5 * DT, t_next):
        w = input_weights(tau, t_prev, t_held, t_next)
        assert sum(w) == pytest.approx(1.0, abs=1e-12)
        assert w[0] * u(t_prev) + w[1] * u(t_held) + w[2] * u(t_next) == pytest.approx(u(tau), abs=1e-9)
    # Half way: the classic (−1, 6, 3)/8.
    np.testing.assert_allclose(input_weights(t_held + 0.5 * DT, t_prev, t_held, t_next), [-1 / 8, 6 / 8, 3 / 8], atol=1e-9)


def test_jittered_spacing_is_still_the_quadratic():
    t_prev, t_held, t_next = 0.0, 0.0051, 0.0098
    u = lambda t: 1.0 + t + 500.0 * t**2  # noqa: E731
    tau = 0.007
    w = input_weights(tau, t_prev, t_held, t_next)
    assert w[0] * u(t_prev) + w[1] * u(t_held) + w[2] * u(t_next) == pytest.approx(u(tau), abs=1e-12)


@pytest.mark.parametrize("t_prev", [np.nan, 0.0 - 3 * DT, 0.0 - DT / 3])
def test_without_a_previous_sample_like_the_others_it_is_the_straight_line(t_prev):
    # No previous sample (NaN), one after a gap (3 periods back) or one too close: the line.
    t_held, t_next = 0.0, DT
    np.testing.assert_allclose(input_weights(0.5 * DT, t_prev, t_held, t_next), [0.0, 0.5, 0.5], atol=1e-15)
    np.testing.assert_allclose(input_weights(0.2 * DT, t_prev, t_held, t_next), [0.0, 0.8, 0.2], atol=1e-15)


def test_tau_outside_the_interval_is_clipped():
    assert input_weights(-1.0, np.nan, 0.0, DT) == pytest.approx((0.0, 1.0, 0.0))
    assert input_weights(1.0, -DT, 0.0, DT) == pytest.approx((0.0, 0.0, 1.0), abs=1e-12)
