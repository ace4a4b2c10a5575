"""AnalysisConfig: every tunable of the modal analytics, typed, closed and documented."""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field, model_validator

__all__ = ["AnalysisConfig"]


class AnalysisConfig(BaseModel):
    """Settings of :func:`analytics.analyze` and :class:`analytics.ModalMonitor` (defaults in brackets)."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    window_s: float = Field(60.0, gt=0, description="analysis window length, s [60]")
    overlap: float = Field(0.5, ge=0, lt=1, description="overlap of successive windows, fraction [0.5]")
    pad_factor: int = Field(4, ge=1, le=64, description="zero padding factor of the spectra [4]")
    window: str = Field("hamming", description="spectral window [hamming]")
    search_rel: float = Field(0.08, gt=0, lt=0.5, description="peak search half-band around the tracked frequency, relative [0.08]")
    min_prominence: float = Field(2.0, ge=1, description="minimum peak prominence, amplitude ratio [2]")
    track_gain: float = Field(0.2, gt=0, le=1, description="gain of the tracked reference frequency update [0.2]")
    min_confidence: float = Field(0.3, ge=0, le=1, description="estimates below this confidence are not used [0.3]")
    forced_fraction: float = Field(0.05, ge=0, le=1, description="a window is a free decay only if the support moves at most this fraction of it [0.05]")
    bearing_threshold_m: float = Field(5e-4, gt=0, description="support displacement counted as motion, m [5e-4]")
    excitation_floor_ratio: float = Field(
        30.0, gt=1, description="a window is 'forced' (distrusted) when the support acceleration's spectrum has a line within "
        "excitation_tolerance of a tracked mode standing this many times above its own floor there, or one line holding half its "
        "power [30: broadband noise peaks at ~6, at most ~12, over its median in 60 s windows]")
    excitation_tolerance: float = Field(0.05, gt=0, lt=0.5, description="a line this close (relative) to a tracked mode is 'near' it [0.05]")
    band_low_fraction: float = Field(0.5, gt=0, lt=1, description="the identification band starts at this fraction of the lowest tracked mode [0.5]")
    band_high_fraction: float = Field(1.3, gt=1, description="… and ends at this multiple of the highest (at most 0.45·fs) [1.3]")
    max_order: int | None = Field(None, ge=4, le=200, description="largest SSI model order [None: 4 per tracked mode + 4, 16 … 40]")
    cross_check_bins: float = Field(1.5, gt=0, description="a subspace mode is confirmed by a spectral peak of its unit deformation within this "
                                    "many resolution bins (1/window) or 3σ [1.5]")
    track_similarity_min: float = Field(0.3, ge=0, le=1, description="a subspace mode is assigned to a tracked mode only if its shape's MAC with "
                                        "the baseline shape (before one: its energy share on the carrying unit deformation) reaches this [0.3]")
    decay_ratio: float = Field(0.6, gt=0, lt=1, description="RMS(last quarter)/RMS(first quarter) below this: 'free_decay' [0.6]")
    quiet_rms: float = Field(1e-9, ge=0, description="RMS of b below this: 'quiet' window, untrusted [1e-9]")
    bandpass_rel: float = Field(0.2, gt=0, lt=1, description="band-pass half width for damping, relative to f [0.2]")
    decay_min_cycles: float = Field(8.0, gt=0, description="minimum cycles of a usable free decay [8]")
    rd_cycles: float = Field(20.0, gt=0, description="random-decrement signature length, cycles [20]")
    baseline_s: float = Field(480.0, gt=0, description="healthy period learnt as baseline from the first trusted window, s [480]")
    baseline_min_windows: int = Field(8, ge=3, description="trusted windows a mode needs in the baseline [8]")
    youngs_temperature_coefficient: float = Field(-3.0e-4, description="relative change of E per K (steel) [-3e-4]")
    slope_prior_fraction: float = Field(0.5, ge=0, le=1, description="prior mean of df/f per K as a fraction of coefficient/2 [0.5]")
    slope_prior_std_fraction: float = Field(0.5, gt=0, description="prior std of the slope, same unit [0.5]")
    gravity_mode_below_hz: float = Field(0.5, gt=0, description="modes below this are gravity dominated: slope prior 0 [0.5]")
    ewma_lambda: float = Field(0.2, gt=0, le=1, description="EWMA smoothing of the control charts [0.2]")
    warning_sigma: float = Field(3.0, gt=0, description="warning level of the charts, σ of the EWMA [3]")
    alarm_sigma: float = Field(5.0, gt=0, description="alarm level, σ of the EWMA [5]")
    curvature_alarm_sigma: float = Field(6.0, gt=0, description="alarm level of the curvature chart, σ of its statistic Q (mean (Δ/σ)², its healthy std from the "
                                         "baseline's error covariance over the stations) [6]: above the frequency charts' 5 because Q's upper tail "
                                         "is longer than a normal one (healthy simulated 30 min runs, ideal and realistic: at most 3.6 with the "
                                         "χ²/p std; an independent simulation's healthy record against another's baseline: at most 4.4)")
    clear_sigma: float = Field(2.0, ge=0, description="an alarm clears below this level, σ of the EWMA [2]")
    hold_windows: int = Field(3, ge=1, description="consecutive windows at or beyond a chart's warning (alarm) line to raise a warning (an alarm) [3]")
    clear_windows: int = Field(3, ge=1, description="consecutive windows below clear_sigma to clear a raised alarm [3]")
    chart_min_cycles: float = Field(30.0, ge=0, description="a mode enters its frequency chart only if a window holds this many of its cycles [30]: "
                                    "with fewer (the 0.3 Hz pendulum mode in a 60 s window: 18) the peak is biased by the window's low-frequency "
                                    "leakage and its scatter heavy-tailed; the mode is still tracked and reported")
    min_sigma_rel: float = Field(2e-4, gt=0, description="floor of a mode's frequency scatter, relative [2e-4]")
    curvature_memory_windows: float = Field(10.0, ge=1, description="time constant of the average of each mode's identified mode-shape "
                                            "curvature, windows [10]")
    curvature_min_std: float = Field(0.015, gt=0, description="tolerance of the curvature chart, per station (unit-RMS curvature shape) [0.015]: "
                                     "the 1σ by which a healthy structure's averaged mode-shape curvature may differ from the baseline's "
                                     "beyond the baseline's own scatter, added in quadrature to it (on the 20 m mast: two healthy 30 min "
                                     "recordings differ by up to 0.008 RMS, a storm of 4 x the ambient wind load moved it by 0.011; a 1 % "
                                     "tip mass by 0.038, a 30 % stiffness loss over 2 m by a few per cent)")
    curvature_mac_min: float = Field(0.9, gt=0, le=1, description="a window's identified mode shape enters the curvature index only if its "
                                     "MAC with the baseline's shape reaches this [0.9]")
    spectrum_memory_windows: float = Field(1.0, ge=1, description="time constant of the power-spectra average the spectral fallback reads a mode from when the subspace identification finds none, windows [1: each window alone]")

    def chart_levels(self, kind: str) -> tuple[float, float]:
        """(warning, alarm) levels in σ of the ``"frequency"`` or ``"curvature"`` control charts."""
        if kind == "frequency":
            return self.warning_sigma, self.alarm_sigma
        if kind == "curvature":
            return self.warning_sigma, max(self.curvature_alarm_sigma, self.warning_sigma)
        raise ValueError(f"{kind=} must be 'frequency' or 'curvature'")

    @model_validator(mode="after")
    def _levels(self) -> "AnalysisConfig":
        if not self.clear_sigma < self.warning_sigma <= self.alarm_sigma:
            raise ValueError(f"need clear_sigma < warning_sigma <= alarm_sigma, got {self.clear_sigma}, {self.warning_sigma}, {self.alarm_sigma}")
        if self.window not in ("hamming", "hann", "boxcar", "blackman", "flattop"):
            raise ValueError(f"window={self.window!r} is not a known window")
        return self
