"""Operational modal identification of one window (or a record and its windows).

The engine behind ``shm oma`` (and, next, ``shm analyze``/``shm serve``): SSI-cov over model
orders (:mod:`._ssi`), stabilisation and clustering (:mod:`._stabilisation`), segment-jackknife
uncertainties, harmonic rejection, MPC and MAC against reference shapes; with a measured input,
the excitation class of the window (:mod:`._frf`).

Layering as pyOMA-2: pure functions; :class:`OperationalModalAnalysis` holds a configuration and
its ``run()`` only calls them and returns an :class:`OmaResult`.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, replace
from typing import Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator
from scipy import linalg, signal, stats

from ._damping import DampingEstimate
from ._moving import subwindow_frequencies
from ._tracks import ModeTrack, ModeTracker
from ._frf import ExcitationClass, Frf, FrfMode, classify_excitation, frf_h1, frf_modes
from ._ssi import PoleSet, SsiModel, modal_assurance, ssi_poles, toeplitz_from_data
from ._stabilisation import PoleCluster, StabilisationDiagram, cluster_poles, stabilisation_diagram
from ._validate import as_signal, check_fs, positive

__all__ = [
    "IdentifiedMode",
    "ModalIdentification",
    "OmaConfig",
    "OmaResult",
    "OmaWindow",
    "OperationalModalAnalysis",
    "identify_modes",
    "identify_windows",
    "prepare_band",
    "damping_estimates",
    "subspace_damping",
    "tracked_frequency",
    "track_windows",
    "local_visibility",
]


class OmaConfig(BaseModel):
    """Settings of the SSI-cov identification (defaults in brackets)."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    fmin_hz: float = Field(0.0, ge=0, description="lower edge of the analysed band, Hz [0]")
    fmax_hz: float | None = Field(None, gt=0, description="upper edge of the analysed band, Hz [None: 0.4·fs]; the data are decimated to ≈ 3·fmax")
    block_rows: int | None = Field(None, ge=2, description="block rows i [None: the lags span 1/f_low, at least 2·max_order/l]")
    max_order: int | None = Field(None, ge=2, description="largest model order [None: 40, at most (i-1)·l]")
    min_cycles: float = Field(8.0, gt=0, description="the lowest frequency resolved is min_cycles/T of a window of T s [8]")
    segments: int = Field(8, ge=3, le=64, description="data segments of the jackknife uncertainty [8, fewer if the window is short]")
    freq_rel: float = Field(0.01, gt=0, le=1, description="stability: relative frequency change between orders [0.01]")
    damping_rel: float = Field(0.3, gt=0, le=10, description="stability: relative damping change between orders [0.3]")
    mac_min: float = Field(0.95, gt=0, le=1, description="stability: MAC between orders [0.95]")
    max_damping: float = Field(0.2, gt=0, le=1, description="poles damped more are numerical [0.2]")
    min_damping: float = Field(-0.01, gt=-1, le=0, description="apparent damping of a mode building up in a short window, down to this, is admitted [-0.01]")
    cluster_distance: float = Field(0.02, gt=0, le=1, description="clustering cut-off in |Δf|/f + (1 − MAC) [0.02]")
    min_orders: float = Field(0.3, gt=0, le=1, description="a mode holds poles of this fraction of the orders [0.3]")
    sure_orders: float = Field(0.5, gt=0, le=1, description="a cluster with poles at fewer than this fraction of the orders is a mode only if it carries min_contribution of the response [0.5]")
    min_contribution: float = Field(0.05, ge=0, le=1, description="see sure_orders: a drifting mode split in two carries a large share, a noise pole next to nothing [0.05]")
    harmonic_kurtosis: float = Field(2.0, gt=1.5, lt=3, description="band-passed kurtosis below this with ζ < harmonic_damping: a harmonic [2.0]")
    harmonic_damping: float = Field(0.002, ge=0, lt=1, description="see harmonic_kurtosis [0.002]")
    min_visibility: float = Field(0.8, ge=0, le=1, description="a mode must carry this share of the modelled response spectrum at its own frequency in some channel, else it is buried under a neighbour [0.8]")
    resolution_cycles: float = Field(2.0, ge=0, le=10, description="poles of one shape closer than resolution_cycles/T to a stronger mode are that mode, unresolved by a window of T s (the half-width of a Hann window's main lobe) [2]")
    min_share: float = Field(0.01, ge=0, le=1, description="a mode carries at least this share of the response in some channel [0.01]")
    moving_modes: bool = Field(True, description="follow each mode through sub-windows; one that moves is listed once with its start and end frequency [True]")
    uncertainty: Literal["jackknife", "batch", "delete-one"] = Field(
        "jackknife", description="statistical 1σ of a pole: 'jackknife', the first-order segment jackknife (a window); 'batch', "
                                 "batch means of the segments' own poles (the spread over √segments); 'delete-one', the "
                                 "jackknife with each left-out record identified anew (a long record, whose slow modes the "
                                 "first-order jackknife underrates); the last two widened by Student's t to a 68.3 % interval "
                                 "[jackknife]")

    @model_validator(mode="after")
    def _band(self) -> "OmaConfig":
        if self.fmax_hz is not None and self.fmax_hz <= self.fmin_hz:
            raise ValueError(f"fmax_hz={self.fmax_hz} must exceed fmin_hz={self.fmin_hz}")
        return self


@dataclass(frozen=True)
class IdentifiedMode:
    """One mode of one window.

    frequency_hz : undamped natural frequency (Hz); frequency_std_hz its 1σ (Hz), None where the
        window gives no measure of it (frequency_std_note then says why).
    damping_ratio : ζ (0.01 = 1 %); damping_std its 1σ, None likewise (damping_std_note).
    mpc : modal phase collinearity 0 … 1 of the shape.
    shape : (l,) real mode shape over the channels (unit norm, largest component positive).
    mac : MAC of the shape against the best-matching reference shape (None without references);
        reference : that reference's index.
    contribution : share of all pole clusters' summed correlation amplitude (0 … 1): which mode dominates.
    orders : model orders the mode was stable at; order : the representative pole's order.
    statistical_std_hz, order_spread_hz : the two parts of frequency_std_hz (segment jackknife,
        scatter across model orders), combined in quadrature; statistical_std_hz is None when the
        window is too short for three segments.
    frequency_std_note, damping_std_note : why a 1σ is withheld (None) or only partly measured
        (the scatter across orders alone); None when both parts are in it.
    damping_method : "ssi" (the subspace pole).
    visibility : the mode's share (0 … 1) of the modelled response spectrum at its own frequency,
        in the channel where it is largest.
    moving : the mode's frequency changed within the window (sub-window estimates); then
        frequency_hz is its time average, start_hz/end_hz the straight line through the
        sub-window estimates at the window's start and end, sweep the (time s, frequency Hz) of
        each sub-window; the damping of a moving mode is that of its spread pole (an upper bound).
    track : id of the physical mode followed across windows (None outside a windowed run).
    """

    frequency_hz: float
    damping_ratio: float
    frequency_std_hz: float | None
    damping_std: float | None
    mpc: float
    shape: tuple[float, ...]
    mac: float | None
    reference: int | None
    contribution: float
    orders: int
    order: int
    statistical_std_hz: float | None
    order_spread_hz: float
    damping_method: str = "ssi"
    visibility: float = 1.0
    moving: bool = False
    start_hz: float | None = None
    end_hz: float | None = None
    sweep: tuple[tuple[float, float], ...] = ()
    track: int | None = None
    frequency_std_note: str | None = None
    damping_std_note: str | None = None

    def as_dict(self) -> dict:
        return {
            "frequency_hz": self.frequency_hz, "damping_ratio": self.damping_ratio,
            "frequency_std_hz": self.frequency_std_hz, "damping_std": self.damping_std,
            "mpc": self.mpc, "shape": list(self.shape), "mac": self.mac, "contribution": self.contribution,
            "orders": self.orders, "damping_method": self.damping_method, "visibility": self.visibility,
            "moving": self.moving, "start_hz": self.start_hz, "end_hz": self.end_hz,
            "sweep": [list(p) for p in self.sweep], "track": self.track,
            "frequency_std_note": self.frequency_std_note, "damping_std_note": self.damping_std_note,
        }


@dataclass(frozen=True, eq=False)
class ModalIdentification:
    """The modes of one window and how they were found.

    modes : physical modes, lowest frequency first.
    rejected : clusters dropped as harmonics (a line, not a resonance), with their frequency (Hz) and reason.
    diagram : the stabilisation diagram (poles of every order and their flags).
    clusters : the pole clusters behind ``modes``.
    fs_hz : rate the identification ran at (after decimation); block_rows, orders as used.
    excitation : class of the measured input (None without one).
    frf_modes : with a measured input, the modes of a pLSCF fit to the H1 FRFs from it to the
        outputs (:func:`analytics.frf_modes`): the input–output cross-check, which a support's
        own coloured motion cannot fake.
    """

    modes: tuple[IdentifiedMode, ...]
    rejected: tuple[tuple[float, str], ...]
    diagram: StabilisationDiagram
    clusters: tuple[PoleCluster, ...]
    fs_hz: float
    block_rows: int
    orders: tuple[int, ...]
    excitation: ExcitationClass | None = None
    frf_modes: tuple[FrfMode, ...] = ()


def _stages(q: int) -> list[int]:
    """Split a decimation factor into stages of at most 10 (each with its own anti-alias filter)."""
    out = []
    while q > 10:
        for d in range(10, 1, -1):
            if q % d == 0:
                out.append(d)
                q //= d
                break
        else:
            out.append(10)
            q = int(math.ceil(q / 10))
    if q > 1:
        out.append(q)
    return out


@functools.lru_cache(maxsize=32)
def _antialias(q: int) -> np.ndarray:
    # scipy.signal.decimate's default: Chebyshev I, order 8, 0.05 dB ripple, edge at 0.8·Nyquist/q
    return signal.cheby1(8, 0.05, 0.8 / q, output="sos")


@functools.lru_cache(maxsize=32)
def _highpass(edge: float) -> np.ndarray:
    # 2nd-order Butterworth at ``edge`` cycles per sample
    return signal.butter(2, 2 * edge, btype="highpass", output="sos")


def prepare_band(y: object, fs: float, *, fmin_hz: float = 0.0, fmax_hz: float | None = None) -> tuple[np.ndarray, float]:
    """Decimate y to about 3·fmax (an anti-aliased, zero-phase IIR per stage of ≤ 10) and remove
    content below fmin/2 (zero-phase Butterworth); SSI is then fitted to the band of interest.

    Parameters
    ----------
    y : array_like, shape (N,) or (N, l)
    fs : float
        Sample rate (Hz).
    fmin_hz, fmax_hz : float
        Band of interest (Hz); fmax None keeps the rate.

    Returns
    -------
    (y_band, fs_band) : ndarray (M, l), float (Hz)

    Raises
    ------
    ValueError
        If fmax is above 0.45·fs or the record is too short to filter.
    """
    fs = check_fs(fs)
    a = as_signal("y", y, min_len=8)
    a = a.reshape(a.shape[0], -1)
    positive("fmin_hz", fmin_hz, allow_zero=True)
    if fmax_hz is not None:
        positive("fmax_hz", fmax_hz)
        if fmax_hz > 0.45 * fs:
            raise ValueError(f"{fmax_hz=} must be at most 0.45·fs = {0.45 * fs} Hz")
        q = int(fs // (3.0 * fmax_hz))
        for d in _stages(q):
            if a.shape[0] < 30 * d:
                raise ValueError(f"y has {a.shape[0]} samples at this stage, too few to decimate by {d} (fmax_hz={fmax_hz})")
            a = signal.sosfiltfilt(_antialias(d), a, axis=0)[::d]
            fs = fs / d
    if fmin_hz > 0:
        if fmin_hz / 2 >= fs / 2:
            raise ValueError(f"{fmin_hz=} is above the Nyquist frequency {fs / 2} Hz")
        sos = _highpass(round(fmin_hz / 2 / fs, 12))
        if a.shape[0] > 15:
            a = signal.sosfiltfilt(sos, a, axis=0)
    return a - a.mean(axis=0), float(fs)


#: largest Toeplitz dimension i·l chosen automatically: the data product and the SVD grow as (i·l)²
#: and (i·l)³; on 60 s windows of the rig-like benchmark 120 lost no accuracy against 200 (the
#: statistical error of a window dominates), see benchmarks/bench_oma.py
_AUTO_ROWS_CAP = 120


def _auto_block_rows(n: int, l: int, fs: float, f_low: float, max_order: int) -> int:
    # lags spanning half a period of the lowest frequency of interest (Rainieri & Fabbrocino),
    # at least enough block rows for the largest order, within the SVD budget and short
    # against the record (N ≥ 5·i)
    i = int(math.ceil(fs / (2 * f_low)))
    i = max(i, int(math.ceil(max_order / l)) + 2, 4)
    i = min(i, max(4, _AUTO_ROWS_CAP // l, int(math.ceil(max_order / l)) + 2))
    return int(min(i, max(4, n // 5)))


def identify_modes(
    y: object,
    fs: float,
    *,
    config: OmaConfig | None = None,
    inputs: object | None = None,
    reference_shapes: object | None = None,
    tracked_hz: object | None = None,
    band_ready: bool = False,
    frf_uncertainty: bool = True,
) -> ModalIdentification:
    """Modes of one window of outputs y by SSI-cov with automated pole selection.

    Parameters
    ----------
    y : array_like, shape (N,) or (N, l)
        Output channels (deformation variables b, accelerations, strains …), sampled at fs.
    fs : float
        Sample rate (Hz).
    config : OmaConfig, optional
        Band, orders and criteria.
    inputs : array_like, shape (N,) or (N, m), optional
        Measured excitation (support acceleration) at fs: classified (:func:`classify_excitation`).
    reference_shapes : array_like, shape (k, l), optional
        Reference mode shapes (a baseline): each mode reports its best MAC.
    tracked_hz : sequence of float, optional
        Frequencies (Hz) the excitation classifier checks lines against (default: the modes found).
    band_ready : bool
        y is already decimated/filtered to the band (:func:`prepare_band`), skip that step.
    frf_uncertainty : bool
        With a measured input, give the FRF modes their jackknife 1σ [True]; False fits the FRFs
        only to cross-check the output-only modes (fewer orders, no jackknife: the monitor's use).

    Returns
    -------
    ModalIdentification

    Raises
    ------
    ValueError
        If y is not finite, too short for the band, or an argument is invalid.

    Examples
    --------
    Two channels of a free decay of two modes (3 Hz at 1 %, 7 Hz at 2 % damping) with a little
    seeded noise:

    >>> import numpy as np
    >>> from analytics import OmaConfig, identify_modes
    >>> fs = 100.0
    >>> t = np.arange(0.0, 20.0, 1 / fs)
    >>> def decay(f, zeta):
    ...     return np.exp(-zeta * 2 * np.pi * f * t) * np.cos(2 * np.pi * f * np.sqrt(1 - zeta**2) * t)
    >>> y = np.column_stack([decay(3.0, 0.01) + 0.5 * decay(7.0, 0.02),
    ...                      0.6 * decay(3.0, 0.01) - 0.8 * decay(7.0, 0.02)])
    >>> y += 1e-4 * np.random.default_rng(1).standard_normal(y.shape)
    >>> result = identify_modes(y, fs, config=OmaConfig(fmin_hz=1.0, fmax_hz=10.0))
    >>> [(round(m.frequency_hz, 2), round(m.damping_ratio, 3)) for m in result.modes]
    [(3.0, 0.01), (7.0, 0.02)]
    """
    cfg = OmaConfig() if config is None else config
    if not isinstance(cfg, OmaConfig):
        raise ValueError(f"config must be an OmaConfig, got {type(cfg).__name__}")
    fs = check_fs(fs)
    raw = as_signal("y", y, min_len=16)
    raw = raw.reshape(raw.shape[0], -1)
    if band_ready:
        yb, fsb = raw - raw.mean(axis=0), fs
    else:
        yb, fsb = prepare_band(raw, fs, fmin_hz=cfg.fmin_hz, fmax_hz=cfg.fmax_hz)
    n, l = yb.shape
    scale = yb.std(axis=0)
    if np.all(scale == 0):
        raise ValueError("y is constant in every channel: nothing to identify")
    # channels of different kinds (accelerations, strains, volts) enter with unit RMS, else the
    # largest-valued channel alone would shape the SVD; shapes are returned in the input units
    scale = np.where(scale > 0, scale, 1.0)
    yb = yb / scale
    T = n / fsb
    fmax = cfg.fmax_hz if cfg.fmax_hz is not None else 0.4 * fs
    f_low = max(cfg.fmin_hz, cfg.min_cycles / T)
    max_order = cfg.max_order or 40
    i = cfg.block_rows or _auto_block_rows(n, l, fsb, f_low, max_order)
    max_order = min(max_order, (i - 1) * l)
    if max_order < 2:
        raise ValueError(f"{l} channel(s) with block_rows={i} allow no model order")
    if n <= 4 * i + 2:
        raise ValueError(f"the window has {n} samples at {fsb:g} Hz, too short for block_rows={i}: lengthen it")
    segs = int(max(1, min(cfg.segments, (n - 2 * i) // (4 * i))))
    Tm, Tsegs = toeplitz_from_data(yb, i, segments=segs)
    orders = np.arange(2, max_order + 1, 2)
    model = ssi_poles(Tm, l, fsb, orders)
    diag = stabilisation_diagram(model.poles, fmin_hz=max(cfg.fmin_hz, 0.0), fmax_hz=min(fmax, 0.49 * fsb), freq_rel=cfg.freq_rel,
                                 damping_rel=cfg.damping_rel, mac_min=cfg.mac_min, max_damping=cfg.max_damping,
                                 min_damping=cfg.min_damping)
    clusters = cluster_poles(diag, distance=cfg.cluster_distance, min_orders=cfg.min_orders)
    jack = _jackknife(model, Tm, Tsegs) if segs >= 3 else None
    modes, kept, rejected = [], [], []
    orders_cache: dict = {}
    batch_cache: dict = {}
    lam_c, amp_c = _residues(model, clusters, orders_cache)
    tot_c = float(np.linalg.norm(amp_c, axis=1).sum()) if len(clusters) else 0.0
    contrib = [float(np.linalg.norm(a)) / tot_c if tot_c > 0 else 0.0 for a in amp_c]
    # poles of one shape closer than the window resolves are one mode split, not neighbours
    fr_c = np.abs(lam_c) / (2 * np.pi)
    sh_c = np.array([model.poles.shapes[c.representative] for c in clusters]) if clusters else np.zeros((0, l))
    together = (np.abs(fr_c[:, None] - fr_c[None, :]) < cfg.resolution_cycles / T)
    if l > 1 and len(clusters):
        together &= modal_assurance(sh_c, sh_c) >= 0.9
    visible = local_visibility(lam_c, amp_c, T, together)
    # a steady line and a lightly damped mode look alike until the window spans many of the
    # mode's correlation times 1/(ζω): test only windows that long (Brincker et al. 2000)
    harmonic = np.array([abs(c.damping_ratio) < cfg.harmonic_damping and 2 * np.pi * c.frequency_hz * cfg.harmonic_damping * T >= 20
                         and _kurtosis_near(yb, fsb, c.frequency_hz, T) < cfg.harmonic_kurtosis for c in clusters], bool)
    # the structure's response: the shares leave out forced lines
    with np.errstate(invalid="ignore", divide="ignore"):
        resp = amp_c[~harmonic].sum(axis=0, keepdims=True) if len(clusters) else np.zeros((1, l))
        chan_share = np.nan_to_num(amp_c / resp).max(axis=1) if len(clusters) else np.zeros(0)
    refs = None if reference_shapes is None else np.atleast_2d(np.asarray(reference_shapes, dtype=float))
    if refs is not None and refs.shape[1] != l:
        raise ValueError(f"reference_shapes has {refs.shape[1]} components, y has {l} channels")
    n_orders = len(orders)
    for c, share, vis, cshare in zip(clusters, contrib, visible, chan_share):
        f, z = c.frequency_hz, c.damping_ratio
        if harmonic[clusters.index(c)]:
            rejected.append((f, "harmonic: a steady line (band-passed kurtosis ≈ 1.5), not a resonance"))
            continue
        if cshare < cfg.min_share:
            rejected.append((f, f"negligible: {100 * cshare:.1f} % of the response in any channel, {100 * cfg.min_share:g} % needed"))
            continue
        if c.orders < cfg.sure_orders * n_orders and share < cfg.min_contribution:
            rejected.append((f, f"noise: stable at {c.orders} of {n_orders} orders and {100 * share:.1f} % of the response"))
            continue
        if vis < cfg.min_visibility:
            sig = np.maximum(np.maximum(np.abs(lam_c.real), 1e-3 * np.abs(lam_c)), np.pi / T)
            at_f = np.linalg.norm(amp_c, axis=1) * sig / (sig ** 2 + (2 * np.pi * f - np.abs(lam_c.imag)) ** 2)
            at_f[clusters.index(c)] = -1.0
            j = int(np.argmax(at_f))
            rejected.append((f, f"buried: {100 * vis:.0f} % of the modelled response at its frequency, under the mode at "
                                f"{clusters[j].frequency_hz:.3f} Hz ({100 * contrib[j]:.0f} % of the response)"))
            continue
        sf: float | None
        sz: float | None
        why_not: str | None = None
        if jack is None:
            sf = sz = None
            why_not = (f"the window ({n} samples at {fsb:g} Hz, block rows {i}) holds {segs} segment(s): the statistical part "
                       f"needs at least 3")
        elif cfg.uncertainty in ("batch", "delete-one"):
            if not batch_cache:  # each segment identified once, at the orders of the clusters' representatives
                loo = cfg.uncertainty == "delete-one"
                mats = (Tsegs.sum(axis=0)[None] - Tsegs) / (Tsegs.shape[0] - 1) if loo else Tsegs
                batch_cache["poles"] = _segment_poles(mats, model, sorted({int(model.poles.order[x.representative]) for x in clusters}))
            sf, sz = _batch_std(model, c, batch_cache["poles"], [x.frequency_hz for x in clusters if x is not c],
                                delete_one=cfg.uncertainty == "delete-one")
        else:
            sf, sz = _pole_std(model, c, jack, orders_cache)
        if jack is not None and not (sf is not None and sz is not None and math.isfinite(sf) and math.isfinite(sz)):
            sf = sz = None
            why_not = f"the {segs} segments do not re-identify the mode at {f:.3f} Hz: no statistical part"
        spread_f = c.frequency_spread_hz if c.orders > 1 else 0.0
        spread_z = c.damping_spread if c.orders > 1 else 0.0
        if cfg.uncertainty != "jackknife" and c.orders > 2:
            # a record's many orders: their scatter measured robustly, so one unconverged low order does not set it
            spread_f = _robust_scale(model.poles.frequency_hz[c.members])
            spread_z = _robust_scale(model.poles.damping_ratio[c.members])
        fstd, fnote = _combined_std(sf, spread_f, c.orders, why_not)
        zstd, znote = _combined_std(sz, spread_z, c.orders, why_not)
        shape_c = model.poles.shapes[c.representative] * scale
        shape_c = shape_c / np.linalg.norm(shape_c)
        shape = _real_shape(shape_c)
        mac = ref = None
        if refs is not None:
            m = modal_assurance(shape_c[None], refs)[0]
            ref = int(np.argmax(m))
            mac = float(m[ref])
        modes.append(IdentifiedMode(f, z, fstd, zstd, float(model.poles.mpc[c.representative]), tuple(float(v) for v in shape), mac, ref,
                                    float(share), c.orders, int(model.poles.order[c.representative]), sf, float(spread_f),
                                    visibility=float(vis), frequency_std_note=fnote, damping_std_note=znote))
        kept.append(c)
    if modes:
        modes, kept, merged = _one_mode_each(modes, kept, yb * scale, fsb, T, cfg, max(cfg.fmin_hz, 0.0), min(fmax, 0.49 * fsb))
        rejected.extend(merged)
    exc, io_modes = None, ()
    if inputs is not None:
        u = as_signal("inputs", inputs, min_len=16)
        u = u.reshape(u.shape[0], -1)
        if u.shape[0] != raw.shape[0]:
            raise ValueError(f"inputs has {u.shape[0]} samples, y has {raw.shape[0]}")
        ub = u - u.mean(axis=0) if band_ready else prepare_band(u, fs, fmin_hz=cfg.fmin_hz, fmax_hz=cfg.fmax_hz)[0]
        track = [m.frequency_hz for m in modes] if tracked_hz is None else list(np.atleast_1d(tracked_hz))
        exc = classify_excitation(ub, fsb, track)
        frf, io_modes = _io_modes(ub, yb * scale, fsb, T, cfg, fmax, [m.frequency_hz for m in modes], full=frf_uncertainty)
        if frf is not None:
            modes, dropped = _confirmed_by_frf(modes, io_modes, frf, resolved_from_hz=3.0 / (T / 6))
            rejected.extend(dropped)
            kept = [c for c in kept if any(abs(c.frequency_hz - m.frequency_hz) < 1e-12 for m in modes)]
    return ModalIdentification(tuple(modes), tuple(rejected), diag, tuple(kept), fsb, i, tuple(int(o) for o in orders), exc, io_modes)


def _combined_std(statistical: float | None, spread: float, orders: int, why_not: str | None) -> tuple[float | None, str | None]:
    """A pole's 1σ from its statistical part and its scatter across model orders (in quadrature),
    and a note when a part is missing: the scatter alone (a partial 1σ, said so), or None when
    neither part was measured (a mode stable at one order has no scatter: a zero would claim an
    exact value)."""
    if statistical is not None:
        return math.hypot(statistical, spread), None
    if orders > 1 and math.isfinite(spread) and spread > 0:
        return float(spread), f"scatter across {orders} model orders only: {why_not}"
    return None, f"withheld: {why_not}, and the mode is stable at {orders} model order(s), no scatter across orders to measure"


def _same_shape(a: IdentifiedMode, b: IdentifiedMode, mac_min: float = 0.9) -> bool:
    if len(a.shape) < 2:
        return True
    return bool(modal_assurance(np.array(a.shape)[None], np.array(b.shape)[None])[0, 0] >= mac_min)


def _one_mode_each(modes: list[IdentifiedMode], kept: list[PoleCluster], y: np.ndarray, fs: float, T: float, cfg: OmaConfig,
                   band_lo: float, band_hi: float) -> tuple[list[IdentifiedMode], list[PoleCluster], list[tuple[float, str]]]:
    """One entry per physical mode. Strongest first, each mode takes in the weaker poles of its
    shape that it explains: those within resolution_cycles/T of it (a window of T s cannot
    separate them: leakage, beating, a ring-down's modulation), and, if its sub-window estimates
    show it moving, those inside the range it swept (a time-varying mode spread over several
    poles of the window's time-invariant model). A mode that moved is listed once, with its
    time-averaged frequency and its frequency at the start and the end of the window."""
    order = sorted(range(len(modes)), key=lambda j: -modes[j].contribution)
    gone: dict[int, str] = {}
    out: dict[int, IdentifiedMode] = {}
    res = cfg.resolution_cycles / T
    for j in order:
        if j in gone:
            continue
        m = modes[j]
        others = [k for k in order if k != j and k not in gone and k not in out]
        mine = [k for k in others if _same_shape(m, modes[k])]
        # the search band stops halfway to a mode it cannot take in (another shape, or stronger)
        lo, hi = max(band_lo, m.frequency_hz / 1.35), min(band_hi, m.frequency_hz * 1.35)
        for k in range(len(modes)):
            if k == j or (k in mine) or k in gone:
                continue
            mid = 0.5 * (modes[k].frequency_hz + m.frequency_hz)
            if modes[k].frequency_hz < m.frequency_hz:
                lo = max(lo, mid)
            else:
                hi = min(hi, mid)
        track = None
        if cfg.moving_modes and lo < m.frequency_hz < hi:
            x = y @ np.array(m.shape) if y.shape[1] == len(m.shape) else y[:, 0]
            track = subwindow_frequencies(x, fs, m.frequency_hz, lo_hz=lo, hi_hz=hi)
        moving = track is not None and track.moving(m.frequency_hz)
        span_lo, span_hi = m.frequency_hz - res, m.frequency_hz + res
        if moving:
            span_lo = min(span_lo, min(track.start_hz, track.end_hz) - 0.5 * res)
            span_hi = max(span_hi, max(track.start_hz, track.end_hz) + 0.5 * res)
        for k in mine:
            fk = modes[k].frequency_hz
            if span_lo <= fk <= span_hi and lo <= fk <= hi or abs(fk - m.frequency_hz) < res:
                if moving:
                    gone[k] = (f"moving: part of the mode that moved {track.start_hz:.3f} → {track.end_hz:.3f} Hz within the "
                               f"window (listed at {track.mean_hz:.3f} Hz)")
                else:
                    gone[k] = (f"unresolved: {abs(fk - m.frequency_hz):.3f} Hz from the stronger mode at {m.frequency_hz:.3f} Hz "
                               f"of the same shape, within the window's resolution {cfg.resolution_cycles:g}/T = {res:.3f} Hz")
        if moving:
            share = m.contribution + sum(modes[k].contribution for k in gone if k in mine)
            # moving() holds only for a track with a measured scatter (mean_std_hz not None)
            track_std = float(track.mean_std_hz or 0.0)
            std = math.hypot(track_std, m.statistical_std_hz) if m.statistical_std_hz is not None else track_std
            fnote = None if m.statistical_std_hz is not None else (
                f"scatter of the time average over {track.standing} sub-windows (that across model orders where larger) only: "
                "no statistical part from the window's segments")
            m = replace(m, frequency_hz=track.mean_hz, frequency_std_hz=max(std, m.frequency_std_hz or 0.0), contribution=share, moving=True,
                        frequency_std_note=fnote,
                        start_hz=track.start_hz, end_hz=track.end_hz,
                        sweep=tuple((float(t), float(f)) for t, f in zip(track.times_s, track.frequency_hz)))
        out[j] = m
    keep = sorted(out)
    return ([out[j] for j in keep], [kept[j] for j in keep],
            [(modes[k].frequency_hz, why) for k, why in sorted(gone.items())])


def _io_modes(ub: np.ndarray, yb: np.ndarray, fs: float, T: float, cfg: OmaConfig, fmax: float,
              check_hz: list[float] | None = None, coherence: float = 0.5, full: bool = True) -> tuple[Frf | None, tuple[FrfMode, ...]]:
    """The H1 FRFs from the (first) measured input to the outputs (segments of T/6: about 11
    Hann averages at 50 % overlap) and the modes fitted to them; (None, ()) if the window is too
    short for a fit or the input is flat. With ``check_hz``, the fit runs only if the input
    explains the outputs (coherence >= ``coherence``) at one of those frequencies in the resolved
    band: elsewhere the FRFs could not overrule an output-only mode anyway."""
    seg = T / 6
    lo = max(cfg.fmin_hz, 2.0 / seg)
    hi = min(fmax, 0.45 * fs)
    if ub.std() == 0 or lo >= hi:
        return None, ()
    try:
        frf = frf_h1(ub[:, :1], yb, fs, segment_s=seg)
        if check_hz is not None:
            resolved = [f for f in check_hz if 3.0 / seg <= f <= hi]
            coh = [float(frf.coherence[int(np.argmin(np.abs(frf.frequencies - f)))].mean()) for f in resolved]
            if not coh or max(coh) < coherence:
                return frf, ()
        order = min(24 if full else 4 * len(check_hz or ()) + 4, max(2, int((hi - lo) * seg) // 2 * 2 // 2))
        return frf, frf_modes(frf, fmin_hz=lo, fmax_hz=hi, max_order=max(2, order // 2 * 2), groups=6 if full else 2)
    except (ValueError, np.linalg.LinAlgError):
        return None, ()


def _confirmed_by_frf(modes: list[IdentifiedMode], io_modes: tuple[FrfMode, ...], frf: Frf, *, coherence: float = 0.8,
                      rel: float = 0.02, resolved_from_hz: float = 0.0) -> tuple[list[IdentifiedMode], list[tuple[float, str]]]:
    """Output-only modes where the measured input explains the outputs (coherence >= 0.8, the
    level at which :func:`frf_modes` lists an FRF mode at all) must show in the FRFs too (the
    nearest to an FRF mode, within 2 % or 3σ): otherwise the pole is the input's own colour (a
    support's motion spectrum), not the structure's. Where the coherence is lower the response
    has another, unmeasured excitation as well (a distributed load), the FRFs could not show a
    resonance there anyway, and the output-only mode stands; so does a mode
    below ``resolved_from_hz``, where the FRFs' segments hold too few of its cycles to fit it (a
    pendulum mode the support drives)."""
    keep, dropped = [], []
    # each FRF mode confirms one output-only mode at most: the nearest within the tolerance
    confirmed = set()
    for x in io_modes:
        if modes:
            j = int(np.argmin([abs(m.frequency_hz - x.frequency_hz) for m in modes]))
            if abs(modes[j].frequency_hz - x.frequency_hz) <= max(rel * x.frequency_hz, 3 * (modes[j].frequency_std_hz or 0.0)):
                confirmed.add(j)
    for j, m in enumerate(modes):
        k = int(np.argmin(np.abs(frf.frequencies - m.frequency_hz)))
        coh = float(frf.coherence[k].mean())
        if coh >= coherence and j not in confirmed and m.frequency_hz >= resolved_from_hz:
            dropped.append((m.frequency_hz, f"input: the measured input explains the response here (coherence {coh:.2f}) and its FRFs show no resonance"))
        else:
            keep.append(m)
    return keep, dropped


def _real_shape(s: np.ndarray) -> np.ndarray:
    # the real shape nearest the complex one: rotate so the largest component is real, take Re
    k = int(np.argmax(np.abs(s)))
    r = np.real(s * np.exp(-1j * np.angle(s[k])))
    nrm = np.linalg.norm(r)
    return r / nrm if nrm > 0 else r


@dataclass
class _OrderModel:
    """One model order's state matrix, its eigen-decomposition (left and right) and what the
    first-order perturbation of its poles needs."""

    A: np.ndarray
    mu: np.ndarray
    left: np.ndarray
    right: np.ndarray
    lam: np.ndarray
    Oup_pinv: np.ndarray
    gram_inv: np.ndarray
    residual: np.ndarray


def _order_model(model: SsiModel, n: int, cache: dict) -> _OrderModel:
    if n in cache:
        return cache[n]
    l = model.channels
    O = model.observability[:, :n]
    Oup, Odown = O[:-l], O[l:]
    Oup_pinv = np.linalg.pinv(Oup)
    A = Oup_pinv @ Odown
    mu, W, V = linalg.eig(A, left=True, right=True)
    # an eigenvalue μ = 0 (a rank-deficient state matrix: a constant or clipped channel) is no
    # vibration: its continuous pole is −∞, never the nearest to a mode's (log(0)·fs would be NaN,
    # and a NaN distance is the one argmin picks)
    zero = mu == 0
    lam = np.log(np.where(zero, 1.0, mu).astype(complex)) * model.fs_hz
    lam[zero] = -np.inf
    om = _OrderModel(A, mu, W, V, lam, Oup_pinv, np.linalg.inv(Oup.T @ Oup), Odown - Oup @ A)
    cache[n] = om
    return om


@dataclass
class _Jackknife:
    """Leave-one-segment-out perturbations of the observability matrix, δO_j = (T_j − T) V S^{-1/2}
    for the largest order (each order takes its first columns)."""

    dO: np.ndarray  # (S, il, n_max)
    segments: int


def _jackknife(model: SsiModel, Tfull: np.ndarray, Ts: np.ndarray) -> _Jackknife:
    segs = Ts.shape[0]
    total = Ts.sum(axis=0)
    loo = (total[None] - Ts) / (segs - 1)
    W = model.right_vectors / np.sqrt(model.singular_values[: model.right_vectors.shape[1]])[None, :]
    return _Jackknife(np.matmul(loo - Tfull[None], W), segs)


def _pole_std(model: SsiModel, c: PoleCluster, jack: _Jackknife, cache: dict) -> tuple[float, float]:
    """Jackknife 1σ of the representative pole's frequency (Hz) and damping ratio.

    Each leave-one-out matrix moves the pole to first order by δμ = wᴴ δA v / (wᴴ v) with
    δA = O_up⁺ (δO_down − δO_up A) + (O_upᵀ O_up)⁻¹ δO_upᵀ (O_down − O_up A): no eigenproblem
    per segment and no pole matching (Reynders, Pintelon & De Roeck 2008)."""
    n = int(model.poles.order[c.representative])
    om = _order_model(model, n, cache)
    l = model.channels
    k = int(np.argmin(np.abs(om.lam - model.poles.eigenvalue[c.representative])))
    dO = jack.dO[:, :, :n]
    dA = om.Oup_pinv[None] @ (dO[:, l:] - dO[:, :-l] @ om.A[None]) + om.gram_inv[None] @ np.swapaxes(dO[:, :-l], 1, 2) @ om.residual[None]
    w, v = om.left[:, k], om.right[:, k]
    dmu = np.einsum("i,sij,j->s", np.conj(w), dA, v) / (np.conj(w) @ v)
    lam = np.log(om.mu[k] + dmu) * model.fs_hz
    fj = np.abs(lam) / (2 * np.pi)
    zj = -lam.real / np.abs(lam)
    S = jack.segments
    var_f = (S - 1) / S * np.sum((fj - fj.mean()) ** 2)
    var_z = (S - 1) / S * np.sum((zj - zj.mean()) ** 2)
    return float(np.sqrt(var_f)), float(np.sqrt(var_z))


def _robust_scale(x: np.ndarray) -> float:
    """The normal-consistent median absolute deviation of x (its standard deviation when x is normal)."""
    return float(1.4826 * np.median(np.abs(x - np.median(x))))


def _segment_poles(Ts: np.ndarray, model: SsiModel, orders: list[int]) -> list[PoleSet | None]:
    """The poles of each segment's own Toeplitz matrix at ``orders`` (None where it fails)."""
    out: list[PoleSet | None] = []
    for T in Ts:
        try:
            out.append(ssi_poles(T, model.channels, model.fs_hz, orders).poles)
        except (ValueError, np.linalg.LinAlgError):
            out.append(None)
    return out


def _batch_std(model: SsiModel, c: PoleCluster, segment_poles: list[PoleSet | None], others_hz: list[float], *,
               delete_one: bool = False) -> tuple[float, float]:
    """1σ of the representative pole's frequency (Hz) and damping ratio from re-identified parts:
    each segment's Toeplitz matrix (batch means) or each leave-one-segment-out matrix
    (``delete_one``) identified on its own (:func:`_segment_poles`); at the pole's order the pole
    of the same shape nearest in frequency (within half the distance to any other mode) taken; the
    spread of those over √K (batch means) or times (K − 1)/√K (the jackknife), widened by
    Student's t so the ±1σ interval holds 68.3 % for few segments. Unlike the first-order
    jackknife it holds when a segment moves the pole beyond the linear regime (a slow mode, a few
    tens of its cycles per segment)."""
    n = int(model.poles.order[c.representative])
    f0 = float(model.poles.frequency_hz[c.representative])
    shape0 = model.poles.shapes[c.representative]
    gap = min((abs(math.log(f / f0)) for f in others_hz if f > 0), default=math.inf)
    reach = min(0.1, 0.5 * gap)
    fs_j, zs_j = [], []
    for seg in segment_poles:
        if seg is None:
            continue
        poles = seg.take(seg.order == n)
        if len(poles) == 0:
            continue
        dev = np.abs(np.log(np.maximum(poles.frequency_hz, 1e-12) / f0))
        mac = modal_assurance(poles.shapes, shape0[None])[:, 0]
        ok = (dev <= reach) & (mac >= 0.8) & (poles.damping_ratio > -0.05) & (poles.damping_ratio < 0.5)
        if ok.any():
            k = int(np.argmin(np.where(ok, dev + (1 - mac), np.inf)))
            fs_j.append(float(poles.frequency_hz[k]))
            zs_j.append(float(poles.damping_ratio[k]))
    K = len(fs_j)
    if K < 3:
        return float("nan"), float("nan")
    widen = float(stats.t.ppf(0.5 + 0.6826894921370859 / 2, K - 1))
    # batch means: the spread of K independent estimates over √K; delete-one: the jackknife's (K − 1)/√K
    scale = widen * ((K - 1) / math.sqrt(K) if delete_one else 1 / math.sqrt(K))
    return scale * float(np.std(fs_j, ddof=1)), scale * float(np.std(zs_j, ddof=1))


def _residues(model: SsiModel, clusters: tuple[PoleCluster, ...], cache: dict) -> tuple[np.ndarray, np.ndarray]:
    """Per cluster the representative's continuous pole λ (rad/s) and the per-channel amplitude
    |φ_c|·|g| of its term in the output correlations, g = ψ⁻¹G from the controllability part of
    the SVD (T = O·[A^{i-1}G … G]): R(τ) = Σ_k φ_k g_kᴴ μ_k^τ."""
    l = model.channels
    lam = np.zeros(len(clusters), complex)
    amp = np.zeros((len(clusters), l))
    if not clusters:
        return lam, amp
    r = model.right_vectors.shape[0] // model.block_rows
    for j, c in enumerate(clusters):
        n = int(model.poles.order[c.representative])
        om = _order_model(model, n, cache)
        k = int(np.argmin(np.abs(om.lam - model.poles.eigenvalue[c.representative])))
        G = (np.sqrt(model.singular_values[:n])[:, None] * model.right_vectors[:, :n].T)[:, -r:]
        w, v = om.left[:, k], om.right[:, k]
        g = (np.conj(w) @ G) / (np.conj(w) @ v)  # the k-th row of ψ⁻¹G
        phi = model.observability[:l, :n] @ v
        lam[j] = om.lam[k]
        amp[j] = np.abs(phi) * np.linalg.norm(g)
    return lam, amp


def _contributions(model: SsiModel, clusters: tuple[PoleCluster, ...], cache: dict) -> list[float]:
    """Each cluster's share of the correlation amplitude: |φ|·|g| of its representative pole."""
    _, amp = _residues(model, clusters, cache)
    vals = np.linalg.norm(amp, axis=1) if len(amp) else np.zeros(0)
    tot = float(vals.sum())
    return [float(v) / tot if tot > 0 else 0.0 for v in vals]


def local_visibility(lam: np.ndarray, amp: np.ndarray, window_s: float | None = None, together: np.ndarray | None = None) -> np.ndarray:
    """Each mode's share of the modelled response spectrum at its own frequency, in the channel
    where that share is largest (0 … 1).

    A pole λ = −σ + iω_d whose term in a channel's correlations has amplitude a adds the
    Lorentzian a·σ/(σ² + (ω − ω_d)²) (and its mirror at −ω_d) to that channel's spectrum; a pole
    whose own peak is buried under a neighbour's at its own frequency is nothing the window's
    response shows: a numerical or noise pole, or the fringe of a mode that moved.

    Parameters
    ----------
    lam : (K,) complex continuous-time poles (rad/s), upper half-plane.
    amp : (K, l) per-channel amplitudes of each pole's term (any unit).
    window_s : float, optional
        Length T of the window (s): its response shows no peak narrower than its resolution,
        so each pole is taken at least π/T rad/s wide (half-power half-width 1/(2T) Hz).
    together : (K, K) bool, optional
        Poles that are one mode (a mode split by the window into poles it cannot resolve):
        their terms count as the mode's own.

    Returns
    -------
    (K,) float
    """
    lam = np.asarray(lam, complex)
    amp = np.asarray(amp, float)
    if lam.size == 0:
        return np.zeros(0)
    wd = np.abs(lam.imag)
    # a growing pole (a short window's build-up) is taken at the width of a lightly damped one
    sig = np.maximum(np.abs(lam.real), 1e-3 * np.abs(lam))
    if window_s is not None:
        sig = np.maximum(sig, np.pi / window_s)
    w = wd[None, :]
    M = sig[:, None] / (sig[:, None] ** 2 + (w - wd[:, None]) ** 2) + sig[:, None] / (sig[:, None] ** 2 + (w + wd[:, None]) ** 2)
    S = M[:, :, None] * amp[:, None, :]  # (pole j, at mode k's frequency, channel)
    tot = S.sum(axis=0)
    if together is None:
        own = S[np.arange(lam.size), np.arange(lam.size)]
    else:
        g = np.asarray(together, bool) | np.eye(lam.size, dtype=bool)
        own = np.einsum("jk,jkc->kc", g.astype(float), S)
    with np.errstate(invalid="ignore", divide="ignore"):
        share = np.where(tot > 0, own / tot, 0.0)
    return share.max(axis=1)


def _kurtosis_near(yb: np.ndarray, fs: float, f: float, T: float) -> float:
    """Kurtosis (Pearson, normal = 3, sinusoid = 1.5) of the channels' band-passed response near f."""
    half = max(3.0 / T, 0.05 * f)
    lo, hi = f - half, f + half
    if lo <= 0 or hi >= fs / 2 or yb.shape[0] < 30:
        return 3.0
    sos = signal.butter(2, [lo, hi], btype="bandpass", fs=fs, output="sos")
    x = signal.sosfiltfilt(sos, yb, axis=0)
    edge = min(x.shape[0] // 10, int(2 * fs / half))
    x = x[edge: x.shape[0] - edge] if x.shape[0] > 2 * edge + 10 else x
    k = stats.kurtosis(x, axis=0, fisher=False)
    w = x.std(axis=0)
    return float(np.sum(k * w) / np.sum(w)) if np.sum(w) > 0 else 3.0


def subspace_damping(mode: IdentifiedMode) -> DampingEstimate:
    """The damping of an identified mode as a :class:`DampingEstimate` (method "ssi").

    Parameters
    ----------
    mode : IdentifiedMode

    Returns
    -------
    DampingEstimate
        damping_ratio and damping_std of the subspace pole, its frequency (Hz), cycles = 0.

    Raises
    ------
    ValueError
        If mode is not an IdentifiedMode, or its damping has no 1σ (damping_std None: the note says why).
    """
    if not isinstance(mode, IdentifiedMode):
        raise ValueError(f"mode must be an IdentifiedMode, got {type(mode).__name__}")
    if mode.damping_std is None:
        raise ValueError(f"the damping of the mode at {mode.frequency_hz:.4f} Hz has no 1σ: {mode.damping_std_note}")
    return DampingEstimate(mode.damping_ratio, mode.damping_std, mode.frequency_hz, "ssi", 0.0)


def tracked_frequency(modes: tuple[IdentifiedMode, ...], fmin_hz: float, fmax_hz: float, *, mac_min: float = 0.9) -> float | None:
    """The frequency (Hz) of the mode tracked in a band of one window, None if none is there.

    The mode carrying the largest share of the response in [fmin_hz, fmax_hz], merged with the
    other modes of the band whose shape matches it (MAC >= mac_min), weighted by their shares:
    a mode that drifts within the window (a structure changing, a support moving) splits into
    poles on either side of its mean frequency with the same shape, and their weighted mean
    follows it; a different mode in the band has another shape and is left out. With one
    channel shapes cannot tell modes apart, so the dominant mode alone is tracked.

    Parameters
    ----------
    modes : tuple of IdentifiedMode
    fmin_hz, fmax_hz : float
        The tracked mode's band (Hz).
    mac_min : float
        Shapes this alike are one mode [0.9].

    Raises
    ------
    ValueError
        If the band is empty or negative, or mac_min is not in (0, 1].
    """
    if not (0 <= fmin_hz < fmax_hz):
        raise ValueError(f"{fmin_hz=} and {fmax_hz=} must satisfy 0 <= fmin_hz < fmax_hz")
    if not (0 < mac_min <= 1):
        raise ValueError(f"{mac_min=} must be in (0, 1]")
    inband = [m for m in modes if fmin_hz <= m.frequency_hz <= fmax_hz]
    if not inband:
        return None
    top = max(inband, key=lambda m: m.contribution)
    if len(top.shape) < 2:
        return top.frequency_hz
    ref = np.array(top.shape)[None]
    same = [m for m in inband if modal_assurance(np.array(m.shape)[None], ref)[0, 0] >= mac_min]
    w = np.array([max(m.contribution, 1e-12) for m in same])
    return float(np.sum(w * np.array([m.frequency_hz for m in same])) / w.sum())


def damping_estimates(y: object, fs: float, mode: IdentifiedMode, *, rd_cycles: float = 20.0) -> tuple[DampingEstimate, ...]:
    """The damping of one identified mode by every method the record allows.

    "ssi": the subspace pole (:func:`subspace_damping`); "random_decrement": the random
    decrement signature (:func:`analytics.random_decrement`) of the channels projected on the
    mode's shape (a spatial filter that favours the mode before the band-pass). A method the
    record cannot serve (too few triggers, a band beyond Nyquist) is left out.

    Parameters
    ----------
    y : array_like, shape (N,) or (N, l)
        The outputs the mode was identified from, at fs.
    fs : float
        Sample rate (Hz).
    mode : IdentifiedMode
    rd_cycles : float
        Length of the random decrement signature in periods [20].

    Returns
    -------
    tuple of DampingEstimate, each with its method and 1σ ("ssi" left out when the pole's 1σ is withheld).

    Raises
    ------
    ValueError
        If y does not have the mode's channels, or an argument is invalid.
    """
    from ._damping import random_decrement

    fs = check_fs(fs)
    a = as_signal("y", y, min_len=16)
    a = a.reshape(a.shape[0], -1)
    if not isinstance(mode, IdentifiedMode):
        raise ValueError(f"mode must be an IdentifiedMode, got {type(mode).__name__}")
    if a.shape[1] != len(mode.shape):
        raise ValueError(f"y has {a.shape[1]} channels, the mode shape {len(mode.shape)}")
    out = [subspace_damping(mode)] if mode.damping_std is not None else []
    try:
        out.append(random_decrement((a - a.mean(axis=0)) @ np.array(mode.shape), fs, mode.frequency_hz, duration_cycles=rd_cycles))
    except ValueError:
        pass
    return tuple(out)


@dataclass(frozen=True, eq=False)
class OmaWindow:
    """The identification of one window: start_s, end_s (s from the first sample) and its modes."""

    start_s: float
    end_s: float
    identification: ModalIdentification

    @property
    def modes(self) -> tuple[IdentifiedMode, ...]:
        return self.identification.modes


@dataclass(frozen=True, eq=False)
class OmaResult:
    """Modes of the whole record (``record``, None if not asked) and of each window; the windows'
    modes carry their ``track``, and ``tracks`` lists each physical mode followed across them."""

    fs_hz: float
    record: ModalIdentification | None
    windows: tuple[OmaWindow, ...]
    tracks: tuple[ModeTrack, ...] = ()


def identify_windows(
    y: object,
    fs: float,
    window_s: float,
    step_s: float,
    *,
    config: OmaConfig | None = None,
    inputs: object | None = None,
    reference_shapes: object | None = None,
) -> tuple[OmaWindow, ...]:
    """Modes of consecutive windows of y (window_s long, every step_s seconds).

    The band is prepared once for the whole record (no filter edges inside windows), then each
    window is identified by :func:`identify_modes`.

    Parameters
    ----------
    y : array_like, shape (N,) or (N, l)
    fs : float
        Sample rate (Hz).
    window_s, step_s : float
        Window length and step (s), both > 0; the record must hold one window.
    config, inputs, reference_shapes
        As :func:`identify_modes`.

    Returns
    -------
    tuple of OmaWindow

    Raises
    ------
    ValueError
        If the record is shorter than one window, or an argument is invalid.
    """
    cfg = OmaConfig() if config is None else config
    fs = check_fs(fs)
    positive("window_s", window_s)
    positive("step_s", step_s)
    raw = as_signal("y", y, min_len=2)
    raw = raw.reshape(raw.shape[0], -1)
    if raw.shape[0] < int(round(window_s * fs)):
        raise ValueError(f"the record is {raw.shape[0] / fs:g} s long, shorter than one window ({window_s=} s)")
    u = None if inputs is None else as_signal("inputs", inputs, min_len=2)
    if u is not None and u.shape[0] != raw.shape[0]:
        raise ValueError(f"inputs has {u.shape[0]} samples, y has {raw.shape[0]}")
    yb, fsb = prepare_band(raw, fs, fmin_hz=cfg.fmin_hz, fmax_hz=cfg.fmax_hz)
    ub = None if u is None else prepare_band(u, fs, fmin_hz=cfg.fmin_hz, fmax_hz=cfg.fmax_hz)[0]
    nw = int(round(window_s * fsb))
    step = step_s * fsb
    out = []
    k = 0
    while True:
        a = int(round(k * step))
        if a + nw > yb.shape[0]:
            break
        ident = identify_modes(yb[a: a + nw], fsb, config=cfg, reference_shapes=reference_shapes, band_ready=True,
                               inputs=None if ub is None else ub[a: a + nw])
        out.append(OmaWindow(a / fsb, (a + nw) / fsb, ident))
        k += 1
    out = _confirm_by_neighbours(out, cfg, nw / fsb)
    return track_windows(out)[0]


def _confirm_by_neighbours(windows: list[OmaWindow], cfg: OmaConfig, T: float) -> list[OmaWindow]:
    """A mode stable at fewer than sure_orders of the orders must recur in a neighbouring window
    (a listed mode, its sweep, or a rejected pole within 1/T): a physical mode does not vanish in
    the next half window, a noise pole does."""
    cand = []
    for w in windows:
        fs = [f for f, _ in w.identification.rejected]
        for m in w.modes:
            fs.extend([m.frequency_hz] + ([m.start_hz, m.end_hz] if m.moving else []))
        cand.append(np.array(fs))
    out = []
    for k, w in enumerate(windows):
        ident = w.identification
        n_orders = len(ident.orders)
        keep, dropped, kept = [], [], []
        aligned = len(ident.clusters) == len(ident.modes)
        for m, c in zip(ident.modes, ident.clusters if aligned else [None] * len(ident.modes)):
            if m.orders < cfg.sure_orders * n_orders:
                near = [c for j in (k - 1, k + 1) if 0 <= j < len(windows) for c in cand[j]]
                lo = min(m.frequency_hz, m.start_hz or m.frequency_hz, m.end_hz or m.frequency_hz) - 1.0 / T
                hi = max(m.frequency_hz, m.start_hz or m.frequency_hz, m.end_hz or m.frequency_hz) + 1.0 / T
                if not any(lo <= c <= hi for c in near):
                    dropped.append((m.frequency_hz, f"isolated: stable at {m.orders} of {n_orders} orders and seen in neither "
                                                    f"neighbouring window (within 1/T = {1 / T:.3f} Hz)"))
                    continue
            keep.append(m)
            kept.append(c)
        if dropped:
            ident = replace(ident, modes=tuple(keep), rejected=ident.rejected + tuple(dropped),
                            clusters=tuple(kept) if aligned else ident.clusters)
            w = OmaWindow(w.start_s, w.end_s, ident)
        out.append(w)
    return out


def track_windows(windows: list[OmaWindow] | tuple[OmaWindow, ...], tracker: ModeTracker | None = None) -> tuple[tuple[OmaWindow, ...], tuple[ModeTrack, ...]]:
    """The windows with each mode's ``track`` set by a :class:`analytics.ModeTracker`, and the tracks.

    Parameters
    ----------
    windows : sequence of OmaWindow, in time order
    tracker : ModeTracker, optional
        Continue this tracker's tracks [a new one].

    Returns
    -------
    (windows, tracks)

    Raises
    ------
    ValueError
        If an element is not an OmaWindow.
    """
    tr = ModeTracker() if tracker is None else tracker
    out = []
    for w in windows:
        if not isinstance(w, OmaWindow):
            raise ValueError(f"windows must hold OmaWindow, got {type(w).__name__}")
        ms = w.modes
        ids = tr.assign(w.start_s, [(m.frequency_hz, m.start_hz if m.moving else m.frequency_hz, m.end_hz if m.moving else m.frequency_hz,
                                     m.shape, m.contribution) for m in ms])
        ident = replace(w.identification, modes=tuple(replace(m, track=i) for m, i in zip(ms, ids)))
        out.append(OmaWindow(w.start_s, w.end_s, ident))
    return tuple(out), tr.tracks()


class OperationalModalAnalysis:
    """The SSI-cov identification as an algorithm object: configure once, ``run()`` per record.

    Parameters
    ----------
    config : OmaConfig, optional
    window_s, step_s : float, optional
        With both: the modes of each window as well as of the whole record.
    whole_record : bool
        Identify the whole record too [True].
    """

    def __init__(self, config: OmaConfig | None = None, *, window_s: float | None = None, step_s: float | None = None,
                 whole_record: bool = True) -> None:
        self.config = OmaConfig() if config is None else config
        if not isinstance(self.config, OmaConfig):
            raise ValueError(f"config must be an OmaConfig, got {type(self.config).__name__}")
        if (window_s is None) != (step_s is None):
            raise ValueError(f"{window_s=} and {step_s=} must be given together")
        self.window_s, self.step_s, self.whole_record = window_s, step_s, whole_record

    def run(self, y: object, fs: float, *, inputs: object | None = None, reference_shapes: object | None = None) -> OmaResult:
        """Identify the record y (N, l) sampled at fs Hz; see :func:`identify_modes`."""
        record = identify_modes(y, fs, config=self.config, inputs=inputs, reference_shapes=reference_shapes) if self.whole_record else None
        windows = () if self.window_s is None else identify_windows(y, fs, self.window_s, self.step_s, config=self.config, inputs=inputs,
                                                                    reference_shapes=reference_shapes)
        tracks = track_windows(windows)[1] if windows else ()
        fsb = record.fs_hz if record is not None else (windows[0].identification.fs_hz if windows else float(fs))
        return OmaResult(fsb, record, windows, tracks)
