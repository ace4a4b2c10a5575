import numpy as np
import pytest
from scipy import signal

from analytics import bandpass, combine_estimates, envelope_decay, find_decay_segments, log_decrement, random_decrement

FS = 200.0


def decay(f=1.9, zeta=0.005, T=60.0, A=1.0):
    t = np.arange(int(T * FS)) / FS
    wn = 2 * np.pi * f
    return t, A * np.exp(-zeta * wn * t) * np.cos(wn * np.sqrt(1 - zeta**2) * t)


def test_log_decrement_exact():
    _, x = decay(zeta=0.005)
    e = log_decrement(x, FS)
    assert e.damping_ratio == pytest.approx(0.005, rel=1e-3)
    assert e.frequency_hz == pytest.approx(1.9 * np.sqrt(1 - 0.005**2), rel=1e-4)
    assert e.damping_std < 1e-5


def test_envelope_fit_exact_and_bandpassed():
    _, x = decay(f=3.5, zeta=0.006, T=40)
    e = envelope_decay(x, FS, trim_s=2.0)
    assert e.damping_ratio == pytest.approx(0.006, rel=0.01)
    # with a second mode mixed in, the band-pass isolates the first
    t, y = decay(f=0.86, zeta=0.005, T=200)
    mixed = y + 0.5 * decay(f=0.3, zeta=0.006, T=200)[1]
    z = bandpass(mixed, FS, 0.86)
    e2 = envelope_decay(z, FS, trim_s=10.0)
    assert e2.damping_ratio == pytest.approx(0.005, rel=0.03)


def test_decay_segments_from_bearing_and_envelope():
    t, x = decay(f=2.0, zeta=0.005, T=40)
    rest = np.zeros(int(10 * FS))
    sig = np.concatenate([rest, x, x])
    bearing = np.zeros(sig.size)
    n0 = rest.size
    bearing[n0 - 100 : n0] = 0.01  # a pluck right before each decay
    bearing[n0 + x.size - 100 : n0 + x.size] = 0.01
    segs = find_decay_segments(sig, FS, 2.0, bearing=bearing)
    assert len(segs) == 2
    assert all((e - s) / FS > 30 for s, e in segs)
    segs2 = find_decay_segments(sig, FS, 2.0)
    assert segs2 and sum(e - s for s, e in segs2) / FS > 30
    ests = [envelope_decay(bandpass(sig, FS, 2.0)[s:e], FS, trim_s=2) for s, e in segs]
    c = combine_estimates(ests)
    assert c.damping_ratio == pytest.approx(0.005, rel=0.02) and c.segments == 2


def test_random_decrement_sdof_white_noise():
    rng = np.random.default_rng(7)
    f, zeta = 2.0, 0.01
    wn = 2 * np.pi * f
    A = np.array([[0.0, 1.0], [-(wn**2), -2 * zeta * wn]])
    Ad, Bd, *_ = signal.cont2discrete((A, np.array([[0.0], [1.0]]), np.eye(2), np.zeros((2, 1))), 1 / FS)
    u = rng.standard_normal(int(1200 * FS))
    x = np.zeros(2)
    y = np.empty(u.size)
    for k in range(u.size):  # SDOF under white noise, exact zero-order-hold discretisation
        x = Ad @ x + Bd[:, 0] * u[k]
        y[k] = x[0]
    e = random_decrement(y, FS, f)
    assert e.damping_ratio == pytest.approx(zeta, rel=0.25)
    assert e.frequency_hz == pytest.approx(f, rel=0.01)
    assert 0 < e.damping_std < 0.5 * zeta


@pytest.mark.parametrize(
    "call, match",
    [
        (lambda: log_decrement(np.zeros(100), FS), "peaks"),
        (lambda: envelope_decay(np.ones(100), FS, trim_s=-1), "trim_s=-1"),
        (lambda: bandpass(np.ones(100), FS, 99.0), "f_center=99.0"),
        (lambda: find_decay_segments(np.ones(100), FS, 0.0), "f_center=0.0"),
        (lambda: find_decay_segments(np.ones(100), FS, 1.0, bearing=np.ones(50)), "bearing"),
        (lambda: random_decrement(np.ones(100), FS, 1.0, groups=1), "groups=1"),
        (lambda: combine_estimates([]), "empty"),
    ],
)
def test_bad_inputs(call, match):
    with pytest.raises(ValueError, match=match):
        call()
