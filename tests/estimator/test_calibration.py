"""Model updating and its identifiability figures on a beam with closed-form sensitivities."""

import numpy as np
import pytest

from estimator import CalibrationParameter, calibrate, calibration_identifiability, modal_frequencies, parse_rig

G_TRUE = 9.7
NOMINAL, LOWER, UPPER = 9.81, 9.0, 10.5
SCALE = UPPER - LOWER


def chain(values):
    """The hanging-chain limit (EI → 0): every eigenfrequency is ∝ √(g / L) (zeros of J₀), so
    ∂ ln f_k / ∂ ln g = 1/2. ``unused`` is a parameter the model ignores."""
    return parse_rig({
        "beam": {"length": 4.0, "width": 0.2, "thickness": 0.002, "youngs_modulus": 1e4, "density": 7850.0},
        "gravity": values["gravity"], "reflector_distance": 0.5,
        "sensors": [{"name": "D", "kind": "imu", "position": 0.0}],
    })


PARAMETERS = (
    CalibrationParameter("gravity", NOMINAL, LOWER, UPPER),
    CalibrationParameter("unused", 1.0, 0.0, 2.0),
)
TARGETS = modal_frequencies(chain({"gravity": G_TRUE}), 3)
WEIGHTS = (1.0, 0.8, 0.5)
LAMBDA = 0.02
S2 = np.sum(np.square(WEIGHTS)) * (0.5 * SCALE / G_TRUE) ** 2  # squared data sensitivity to z = (g - nominal) / range


def test_update_finds_the_determined_parameter_and_leaves_the_unseen_one_at_its_prior():
    result = calibrate(chain, PARAMETERS, TARGETS, weights=WEIGHTS, regularisation=LAMBDA)
    # The prior pulls g a little towards its nominal value: z ≈ s² z_true / (s² + λ²) (linearised).
    z_true = (G_TRUE - NOMINAL) / SCALE
    assert result.values["gravity"] == pytest.approx(NOMINAL + SCALE * z_true * S2 / (S2 + LAMBDA**2), rel=1e-4)
    assert result.values["unused"] == pytest.approx(1.0, abs=1e-6)
    np.testing.assert_allclose(result.frequencies_hz, TARGETS, rtol=1e-3)
    assert result.identifiability.undetermined == ("unused",)


def test_identifiability_matches_the_closed_form():
    ident = calibration_identifiability(chain, PARAMETERS, {"gravity": G_TRUE, "unused": 1.0},
                                        TARGETS, weights=WEIGHTS, regularisation=LAMBDA, frequency_std=0.01)
    np.testing.assert_allclose(ident.sensitivity[:, 0], 0.5, rtol=1e-5)
    np.testing.assert_array_equal(ident.sensitivity[:, 1], 0.0)
    assert ident.resolution[0] == pytest.approx(S2 / (S2 + LAMBDA**2), rel=1e-4)
    assert ident.resolution[1] == pytest.approx(0.0, abs=1e-12)
    # posterior σ of g: σ_f / √(s² + λ²) of the range; the unseen parameter keeps its prior σ_f / λ.
    assert ident.std[0] == pytest.approx(0.01 / np.sqrt(S2 + LAMBDA**2) * SCALE, rel=1e-4)
    assert ident.std[1] == pytest.approx(ident.prior_std[1], rel=1e-9)
    assert ident.prior_std[1] == pytest.approx(0.01 / LAMBDA * 2.0, rel=1e-12)
    # singular values of diag(w) S: ‖w‖/2 for ln g, 0 for the unseen parameter
    np.testing.assert_allclose(ident.singular_values, [0.5 * np.linalg.norm(WEIGHTS), 0.0], rtol=1e-5, atol=1e-12)
    assert ident.undetermined == ("unused",)
    assert ident.combination_text(0) == "+1.00 ln gravity"
    assert ident.combination_text(1) == "+1.00 ln unused"
    assert ident.cost == pytest.approx(0.5 * LAMBDA**2 * ((G_TRUE - NOMINAL) / SCALE) ** 2, rel=1e-6)
    assert ident.effective_parameters == pytest.approx(ident.resolution[0], rel=1e-9)
    data = ident.as_dict()
    assert data["undetermined"] == ["unused"] and set(data["parameters"]) == {"gravity", "unused"}


def test_frequency_std_defaults_to_the_residual_scale():
    values = {"gravity": 1.05 * G_TRUE, "unused": 1.0}
    ident = calibration_identifiability(chain, PARAMETERS, values, TARGETS, weights=WEIGHTS, regularisation=LAMBDA)
    residual = np.asarray(WEIGHTS) * (np.sqrt(1.05) - 1.0)
    dof = len(TARGETS) - ident.effective_parameters
    assert ident.frequency_std == pytest.approx(np.sqrt(residual @ residual / dof), rel=1e-6)


@pytest.mark.parametrize("kwargs, match", [
    ({"targets_hz": []}, "targets_hz"),
    ({"targets_hz": [1.0, -2.0]}, "targets_hz"),
    ({"weights": (1.0, 1.0)}, "weights"),
    ({"weights": (1.0, 1.0, -1.0)}, "weights"),
    ({"regularisation": 0.0}, "regularisation"),
    ({"frequency_std": -0.1}, "frequency_std"),
])
def test_bad_input_is_refused_naming_the_value(kwargs, match):
    args = {"targets_hz": TARGETS, "weights": WEIGHTS, "regularisation": LAMBDA, **kwargs}
    with pytest.raises(ValueError, match=match):
        calibration_identifiability(chain, PARAMETERS, {"gravity": G_TRUE, "unused": 1.0}, **args)
    with pytest.raises(ValueError, match="unused"):
        calibration_identifiability(chain, PARAMETERS, {"gravity": G_TRUE}, TARGETS)
    with pytest.raises(ValueError, match="nominal"):
        CalibrationParameter("x", 3.0, 0.0, 2.0)
    with pytest.raises(ValueError, match="at least one"):
        calibrate(chain, (), TARGETS)
