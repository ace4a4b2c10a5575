"""Modal analytics of the deformation variables b(t): spectra, eigenfrequency tracking, damping,
curvature change and damage flags (paper Section 3.5). Pure numerics: arrays in, small frozen
results out; no I/O. Lower layer: imports neither the service nor the web."""

from ._alarms import AlarmEvent, AlarmLogic
from ._analyze import AnalysisResult, ModeSummary, analyze, learn_baseline
from ._chart import EwmaChart, chart_level
from ._config import AnalysisConfig
from ._curvature import (CurvatureChange, CurvatureStatistic, beam_third, curvature_change, curvature_field, curvature_shape,
                         curvature_statistic, mode_shape_curvature)
from ._damping import DampingEstimate, bandpass, combine_estimates, envelope_decay, find_decay_segments, log_decrement, random_decrement
from ._frf import ExcitationClass, Frf, FrfMode, classify_excitation, frf_h1, frf_modes
from ._planes import DEGENERATE_REL, DegeneratePair, combine_planes, degenerate_pairs, with_plane
from ._location import DamageLocation, locate_damage
from ._engine import EngineWindow, MonitoringEngine
from ._fatigue import SECONDS_PER_YEAR, FatigueDetail, HotSpotFatigue, LifeEstimate, LoadsWindow, remaining_life
from ._loads_monitor import GaugeSpec, HotSpotSpec, LoadsConfig, LoadsMonitor
from ._loads import BAND_COVERAGE, BAND_FLOOR, UNKNOWN_LEVERAGE, WITHHOLD_HALF_WIDTH, DelBand, OutsideBasis, outside_basis_bands, SignalLoads, VirtualLoads, bending_moment, gauge_bands, signal_loads, virtual_strain
from ._section_loads import AROUND_STEP_DEG, BiaxialVirtualLoads, around_angles, outline_corners, resultant_moment, section_strain, worst_around
from ._rainflow import Cycles, HalfCyclePolicy, RainflowCounter, RainflowResidue, cycles_by_range, rainflow_cycles
from ._sn_curves import DNV_RP_C203_CURVES, EN1993_DETAIL_CATEGORIES, SnCurve, damage_equivalent_range, miner_damage, sn_curve
from ._monitor import Baseline, BaselineError, BaselineMode, ModalMonitor, ModeEstimate, WindowResult, fit_temperature_model, support_acceleration
from ._oma import (
    IdentifiedMode, ModalIdentification, OmaConfig, OmaResult, OmaWindow, OperationalModalAnalysis, damping_estimates, identify_modes,
    identify_windows, local_visibility, prepare_band, subspace_damping, track_windows, tracked_frequency,
)
from ._moving import SubwindowTrack, subwindow_frequencies
from ._tracks import ModeTrack, ModeTracker
from ._usability import WINDOW_REJECTIONS, usability_document, window_rejection
from ._peaks import Peak, find_peaks, interpolate_peak
from ._spectrum import Spectrum, amplitude_spectrum, averaged_spectrum, cross_spectra
from ._ssi import (
    PoleSet, SsiModel, block_toeplitz, modal_assurance, modal_phase_collinearity, output_correlations, segment_correlations,
    ssi_cov, ssi_poles, toeplitz_from_data,
)
from ._stabilisation import PoleCluster, StabilisationDiagram, cluster_poles, stabilisation_diagram

__all__ = [
    # the one engine: window loop, monitor, alarm path
    "AlarmEvent", "AlarmLogic", "BaselineError", "EngineWindow", "MonitoringEngine", "chart_level", "learn_baseline",
    "support_acceleration", "WINDOW_REJECTIONS", "usability_document", "window_rejection",
    "AnalysisConfig", "AnalysisResult", "Baseline", "BaselineMode", "CurvatureChange", "DamageLocation", "DampingEstimate",
    "EwmaChart", "ModalMonitor", "ModeEstimate", "ModeSummary", "Peak", "Spectrum", "WindowResult",
    "amplitude_spectrum", "analyze", "averaged_spectrum", "bandpass", "beam_third", "combine_estimates",
    "cross_spectra", "curvature_change", "curvature_field", "curvature_shape", "curvature_statistic", "envelope_decay",
    "mode_shape_curvature", "CurvatureStatistic",
    "find_decay_segments", "find_peaks", "fit_temperature_model", "interpolate_peak", "locate_damage", "log_decrement",
    "random_decrement",
    # operational modal analysis (SSI-cov, stabilisation, clustering, FRFs)
    "ExcitationClass", "Frf", "FrfMode", "IdentifiedMode", "ModalIdentification", "OmaConfig", "OmaResult", "OmaWindow",
    "OperationalModalAnalysis", "PoleCluster", "PoleSet", "SsiModel", "StabilisationDiagram", "block_toeplitz",
    "classify_excitation", "cluster_poles", "damping_estimates", "frf_h1", "frf_modes", "identify_modes", "identify_windows", "modal_assurance",
    "modal_phase_collinearity", "output_correlations", "prepare_band", "segment_correlations", "ssi_cov", "ssi_poles",
    "stabilisation_diagram", "subspace_damping", "toeplitz_from_data", "tracked_frequency",
    # physical modes, moving modes, tracks across windows
    "ModeTrack", "ModeTracker", "SubwindowTrack", "local_visibility", "subwindow_frequencies", "track_windows",
    # loads and fatigue: streaming rainflow, S–N curves, Miner damage, remaining life
    "Cycles", "DNV_RP_C203_CURVES", "EN1993_DETAIL_CATEGORIES", "FatigueDetail", "HalfCyclePolicy", "HotSpotFatigue",
    "LifeEstimate", "LoadsWindow", "RainflowCounter", "RainflowResidue", "SECONDS_PER_YEAR", "SnCurve", "cycles_by_range",
    "damage_equivalent_range", "miner_damage", "rainflow_cycles", "remaining_life", "sn_curve",
    "BAND_COVERAGE", "BAND_FLOOR", "UNKNOWN_LEVERAGE", "WITHHOLD_HALF_WIDTH", "DelBand", "OutsideBasis", "outside_basis_bands", "SignalLoads", "VirtualLoads", "bending_moment", "gauge_bands", "signal_loads", "virtual_strain",
    # both bending planes: per-plane modes, degenerate pairs of a symmetric section
    "DEGENERATE_REL", "DegeneratePair", "combine_planes", "degenerate_pairs", "with_plane",
    "AROUND_STEP_DEG", "BiaxialVirtualLoads", "around_angles", "outline_corners", "resultant_moment", "section_strain", "worst_around", "GaugeSpec", "HotSpotSpec", "LoadsConfig", "LoadsMonitor",
]
