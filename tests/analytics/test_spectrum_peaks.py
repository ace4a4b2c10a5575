import numpy as np
import pytest

from analytics import amplitude_spectrum, averaged_spectrum, cross_spectra, find_peaks, interpolate_peak

FS = 200.0


def test_sinusoid_amplitude_and_subbin_frequency():
    t = np.arange(int(60 * FS)) / FS
    f0, A = 1.9064 + 0.37 / 60, 0.02  # deliberately between resolution bins
    s = amplitude_spectrum(A * np.sin(2 * np.pi * f0 * t + 0.3), FS, pad_factor=4)
    assert s.resolution_hz == pytest.approx(FS / t.size)
    assert s.bin_spacing_hz == pytest.approx(FS / (4 * t.size))
    assert s.coherent_gain == pytest.approx(0.54, abs=1e-3)
    assert s.enbw_bins == pytest.approx(1.36, abs=0.01)
    p = find_peaks(s, fmin=0.5, fmax=5)[0]
    assert p.frequency_hz == pytest.approx(f0, abs=1e-3 * s.resolution_hz)
    assert p.amplitude == pytest.approx(A, rel=2e-3)


def test_pad1_bias_small_and_two_columns():
    t = np.arange(4000) / FS
    x = np.column_stack([np.sin(2 * np.pi * 3.3337 * t), 0.5 * np.cos(2 * np.pi * 5.61 * t)])
    s = amplitude_spectrum(x, FS, pad_factor=1)
    assert s.amplitude.shape[1] == 2
    p = find_peaks(s, column=1, fmin=4)[0]
    assert abs(p.frequency_hz - 5.61) < 0.05 * s.resolution_hz
    assert p.amplitude == pytest.approx(0.5, rel=0.02)


def test_two_close_tones_resolved():
    t = np.arange(int(100 * FS)) / FS  # resolution 0.01 Hz, tones 0.05 Hz apart
    x = np.sin(2 * np.pi * 3.50 * t) + 0.6 * np.sin(2 * np.pi * 3.55 * t + 1)
    pk = sorted(find_peaks(amplitude_spectrum(x, FS), fmin=3.3, fmax=3.8)[:2], key=lambda p: p.frequency_hz)
    assert pk[0].frequency_hz == pytest.approx(3.50, abs=1e-3)
    assert pk[1].frequency_hz == pytest.approx(3.55, abs=1e-3)
    assert pk[0].amplitude == pytest.approx(1.0, rel=0.03)
    assert pk[1].amplitude == pytest.approx(0.6, rel=0.03)


def test_averaged_spectrum_and_cross_spectra():
    rng = np.random.default_rng(1)
    t = np.arange(int(300 * FS)) / FS
    x = 0.1 * np.sin(2 * np.pi * 2.0 * t) + 0.01 * rng.standard_normal(t.size)
    s = averaged_spectrum(x, FS, 30.0)
    assert s.averages == 19
    assert find_peaks(s, fmin=1, fmax=3)[0].amplitude == pytest.approx(0.1, rel=0.02)
    c = cross_spectra(np.column_stack([x, -2 * x]), FS, [2.0])
    assert abs(c[0, 0]) == pytest.approx(0.1, rel=0.02)
    assert c[0, 1] / c[0, 0] == pytest.approx(-2.0)


@pytest.mark.parametrize(
    "call, match",
    [
        (lambda: amplitude_spectrum(np.ones(100), FS, pad_factor=0), "pad_factor=0"),
        (lambda: amplitude_spectrum(np.ones(100), -1.0), "fs=-1.0"),
        (lambda: amplitude_spectrum([1.0, np.nan, 2, 3, 4], FS), "NaN"),
        (lambda: amplitude_spectrum(np.ones(100), FS, window="kaiserx"), "window="),
        (lambda: averaged_spectrum(np.ones(100), FS, 10.0), "segment_s=10.0"),
        (lambda: averaged_spectrum(np.ones(1000), FS, 1.0, overlap=1.0), "overlap=1.0"),
        (lambda: cross_spectra(np.ones((100, 2)), FS, [150.0]), "frequencies_hz"),
        (lambda: find_peaks(np.ones(10)), "Spectrum"),
        (lambda: find_peaks(amplitude_spectrum(np.ones(100), FS), min_prominence=0.5), "min_prominence=0.5"),
        (lambda: interpolate_peak(np.arange(5.0), np.ones(5), 7), "index=7"),
    ],
)
def test_bad_inputs(call, match):
    with pytest.raises(ValueError, match=match):
        call()
