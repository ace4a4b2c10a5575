"""The input–output path: H1 FRFs with coherence, their modal fit, and the excitation class."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from analytics import OmaConfig, classify_excitation, frf_h1, frf_modes, identify_modes

FS = 100.0


def base_excited(fn: float = 3.0, zeta: float = 0.02, seconds: float = 1200.0, seed: int = 1):
    """A 1-DOF oscillator on a moving base: x'' + 2ζω x' + ω² x = −a_g, with a coloured base
    acceleration a_g (a low-pass random process, as a support's own dynamics give). Returns
    (a_g, absolute acceleration of the mass + 5 % noise, relative displacement x)."""
    rng = np.random.default_rng(seed)
    n = int(seconds * FS)
    ag = signal.lfilter([1.0], [1.0, -0.8], rng.standard_normal(n))
    w = 2 * np.pi * fn
    A = np.array([[0.0, 1.0], [-w * w, -2 * zeta * w]])
    B = np.array([[0.0], [-1.0]])
    C = np.array([[1.0, 0.0], [-w * w, -2 * zeta * w]])  # x and the absolute acceleration
    sysd = signal.cont2discrete((A, B, C, np.zeros((2, 1))), 1 / FS, method="foh")
    _, out, _ = signal.dlsim(signal.dlti(*sysd[:4], dt=1 / FS), ag)
    acc = out[:, 1] + 0.05 * out[:, 1].std() * rng.standard_normal(n)
    return ag, acc, out[:, 0]


def test_frf_h1_of_a_base_excited_oscillator_matches_the_transmissibility():
    ag, acc, _ = base_excited()
    frf = frf_h1(ag, acc, FS, segment_s=50.0)
    f = frf.frequencies
    w, wn, z = 2 * np.pi * f, 2 * np.pi * 3.0, 0.02
    T = (wn**2 + 2j * z * wn * w) / (wn**2 - w**2 + 2j * z * wn * w)
    band = (f > 0.5) & (f < 6) & (np.abs(f - 3.0) > 0.3)  # off the peak, where leakage is small
    assert frf.coherence[band].mean() > 0.95
    good = band & (frf.coherence[:, 0] > 0.95)
    # H1 is unbiased by output noise; its scatter is sqrt((1 − γ²)/(2·γ²·averages)) ≈ 2 %
    np.testing.assert_allclose(np.abs(frf.h[good, 0, 0]), np.abs(T[good]), rtol=0.08)
    assert np.median(np.abs(np.abs(frf.h[good, 0, 0]) / np.abs(T[good]) - 1)) < 0.02


def test_frf_modal_fit_and_output_only_agree_on_the_oscillator():
    ag, acc, _ = base_excited()
    frf = frf_h1(ag, acc, FS, segment_s=100.0)
    modes = frf_modes(frf, fmin_hz=1.0, fmax_hz=8.0)
    assert len(modes) == 1
    m = modes[0]
    assert m.method == "frf_plscf"
    assert m.frequency_hz == pytest.approx(3.0, rel=2e-3)
    assert abs(m.frequency_hz - 3.0) < 4 * m.frequency_std_hz + 1e-3
    assert m.damping_ratio == pytest.approx(0.02, rel=0.2)
    assert m.coherence > 0.8
    # the subspace on the outputs finds the mode; the coloured support motion adds poles the
    # output-only fit cannot tell from modes, which the FRFs of the measured input refute
    alone = identify_modes(acc, FS, config=OmaConfig(fmin_hz=1.0, fmax_hz=8.0))
    assert any(abs(x.frequency_hz - 3.0) < 0.03 for x in alone.modes)
    oo = identify_modes(acc, FS, config=OmaConfig(fmin_hz=1.0, fmax_hz=8.0), inputs=ag)
    f = [x.frequency_hz for x in oo.modes]
    assert len(f) == 1 and f[0] == pytest.approx(3.0, rel=0.01), f
    # what the outputs alone still list beside the mode, the measured input refutes; the poles that
    # fail on physical grounds are rejected with their own reasons either way
    refuted = [why for _, why in oo.rejected if why.startswith("input")]
    assert len(refuted) == len(alone.modes) - 1
    assert oo.excitation is not None and oo.excitation.kind == "broadband"
    # and the input–output cross-check of the same call fits the FRFs to the same mode
    assert len(oo.frf_modes) == 1 and oo.frf_modes[0].frequency_hz == pytest.approx(3.0, rel=5e-3)


def test_excitation_classes_from_the_input_spectrum():
    rng = np.random.default_rng(4)
    n = 6000
    t = np.arange(n) / FS
    burst = np.sin(2 * np.pi * 3.02 * t) + 0.05 * rng.standard_normal(n)
    c = classify_excitation(burst, FS, [3.0, 7.0])
    assert c.kind == "deterministic_near_mode" and c.line_hz == pytest.approx(3.02, abs=0.02) and c.nearest_mode_hz == 3.0
    off = np.sin(2 * np.pi * 5.0 * t) + 0.05 * rng.standard_normal(n)
    assert classify_excitation(off, FS, [3.0, 7.0]).kind == "deterministic"
    broad = signal.lfilter([1.0], [1.0, -0.8], rng.standard_normal(n))
    assert classify_excitation(broad, FS, [3.0]).kind == "broadband"
    # a moving support is not a reason to distrust: a large broadband motion is still broadband
    assert classify_excitation(100 * broad, FS, [3.0]).kind == "broadband"
    assert classify_excitation(np.zeros(n), FS, [3.0]).kind == "quiet"


@pytest.mark.parametrize("call, match", [
    (lambda: frf_h1(np.zeros(100), np.zeros(99), FS, segment_s=0.5), "u has 100"),
    (lambda: frf_h1(np.zeros(100), np.zeros(100), FS, segment_s=5.0), "segment_s=5.0"),
    (lambda: frf_modes("frf", fmin_hz=1, fmax_hz=2), "Frf"),
    (lambda: classify_excitation(np.zeros(100), FS, [-1.0]), "tracked_hz"),
    (lambda: classify_excitation(np.zeros(100), FS, line_fraction=1.5), "line_fraction=1.5"),
])
def test_bad_input_names_the_value(call, match):
    with pytest.raises(ValueError, match=match):
        call()
