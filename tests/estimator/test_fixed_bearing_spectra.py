"""The paper's Figures 12–14 (Section 3.5): with the bearing fixed, each unit deformation's amplitude
spectrum is dominated by its own mode; the pendulum's unit deformations are coupled.

Both rigs run the same ambient excitation (random loads along the beam, the bearing still: the
operating condition the analytics take eigenfrequencies from). Under the paper's forced input
the clamped b_k also carry the forcing lines' off-resonance response — the truth's modal
coordinates show the same, so it is the plant, not coupling — which leaves less margin
(``benchmarks/bench_estimator.py`` reports both).
"""

import json

import numpy as np
import pytest
from simdata import simulate

from analytics import amplitude_spectrum
from estimator import build_model, estimate


def _other_mode_ratios(support: str) -> tuple[np.ndarray, tuple[tuple[int, ...], ...]]:
    """(Γ, M): each b's amplitude spectrum near each plant eigenfrequency (±3 %, the largest bin)
    over its largest own-mode peak; own modes set to 0."""
    meas, _, vr = simulate(duration=150.0, rest=10.0, seed=1, ideal=False, support=support, excitation="ambient")
    model = build_model(vr.nominal_rig, peripheral="gyro", modes=4)
    result = estimate(meas, model)
    keep = result.t > result.calibration.rest_end
    spectrum = amplitude_spectrum(result.b[keep], 200.0, pad_factor=8)  # Hamming window, zero padding
    f, A = spectrum.frequencies, spectrum.amplitude
    plant_hz = np.array(json.loads(vr.truth_metadata()["eigenfrequencies_hz"]))
    modes = model.units.modes
    n_modes = modes[-1][-1]
    peaks = np.array([[A[(f > 0.97 * fm) & (f < 1.03 * fm), k].max() for fm in plant_hz[:n_modes]]
                      for k in range(len(modes))])
    ratios = peaks / np.array([max(peaks[k, m - 1] for m in group) for k, group in enumerate(modes)])[:, None]
    for k, group in enumerate(modes):
        ratios[k, [m - 1 for m in group]] = 0.0
    return ratios, modes


@pytest.fixture(scope="module")
def clamped():
    return _other_mode_ratios("clamped")


def test_fixed_bearing_each_unit_deformation_shows_its_own_mode(clamped):
    ratios, modes = clamped
    assert modes == ((1,), (2,), (3,), (4,))  # no combimode: b_k is mode k
    # Own-mode peak ≥ 10× every other mode's (measured: worst 0.052, b4 at mode 2: 19×).
    assert ratios.max() <= 0.1, np.round(ratios, 3)


def test_pendulum_unit_deformations_are_coupled(clamped):
    ratios, modes = _other_mode_ratios("pinned")
    assert modes == ((1, 2), (3,), (4,), (5,))  # b1 is the combimode
    # The paper's Figure 12: other modes show in the pendulum's b (measured: b3 shows mode 2 at
    # 0.21 of its own peak, b2 mode 2 at 0.16, b4 mode 1 at 0.14), where the clamped worst is 0.052.
    assert ratios.max() >= 0.1, np.round(ratios, 3)
    assert ratios.max() >= 2 * clamped[0].max()
