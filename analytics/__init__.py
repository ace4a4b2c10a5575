"""Modal analytics of the deformation variables b(t): spectra, eigenfrequency tracking, damping,
curvature change and damage flags (paper Section 3.5). Pure numerics: arrays in, small frozen
results out; no I/O. Lower layer: imports neither the service nor the web."""

from ._analyze import AnalysisResult, ModeSummary, analyze
from ._chart import EwmaChart
from ._config import AnalysisConfig
from ._curvature import CurvatureChange, beam_third, curvature_change, curvature_field, curvature_shape
from ._damping import DampingEstimate, bandpass, combine_estimates, envelope_decay, find_decay_segments, log_decrement, random_decrement
from ._location import DamageLocation, locate_damage
from ._monitor import Baseline, BaselineMode, ModalMonitor, ModeEstimate, WindowResult, fit_temperature_model
from ._peaks import Peak, find_peaks, interpolate_peak
from ._spectrum import Spectrum, amplitude_spectrum, averaged_spectrum, cross_spectra

__all__ = [
    "AnalysisConfig", "AnalysisResult", "Baseline", "BaselineMode", "CurvatureChange", "DamageLocation", "DampingEstimate",
    "EwmaChart", "ModalMonitor", "ModeEstimate", "ModeSummary", "Peak", "Spectrum", "WindowResult",
    "amplitude_spectrum", "analyze", "averaged_spectrum", "bandpass", "beam_third", "combine_estimates",
    "cross_spectra", "curvature_change", "curvature_field", "curvature_shape", "envelope_decay",
    "find_decay_segments", "find_peaks", "fit_temperature_model", "interpolate_peak", "locate_damage", "log_decrement",
    "random_decrement",
]
