"""Loads per analysis window and hot spot, inside the one engine (:class:`analytics.MonitoringEngine`).

Each window's new samples (its first step: the windows overlap, the count must see every
sample once) become the hot spots' nominal stress σ = E(T)·(−c κ); a :class:`HotSpotFatigue`
per hot spot counts them in a stream, so a reprocessed archive accumulates the same damage as
the live service did (windows are aligned in data time). Alarm conditions go through
:class:`analytics.AlarmLogic` as charts of kind "fatigue", each scored in units of its warning
line (1 = the warning line; the alarm line and the clear line are multiples of it):

* ``rate``: the design-life usage at the trailing damage rate, rate × design life (warning 1:
  the design life would be exhausted early; alarm 2: in half of it). Needs a design life.
* ``del``: the window's DEL (m = the first exponent) against its baseline, the median of the first
  ``baseline_windows`` windows: score (ratio − 1)/(del_warning_ratio − 1).
* ``consumed``: D / consumed_warning (alarm at consumed_alarm / consumed_warning).

With strain gauges (``GaugeSpec``) and their measured strain in a window, each hot spot's DELs
and damage increment carry a band, the modal truncation seen at the gauges
(:func:`analytics.gauge_bands`: leave-one-gauge-out residuals, a gauge that aided the estimate
taken in sample with ``UNKNOWN_LEVERAGE``; per hot spot by its position), with the method stated.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator

from contract import ChartDocument, HotSpotLoadsDocument, LoadsWindowDocument, StationLoadsDocument, chart_name

from ._alarms import AlarmEvent, AlarmLogic
from ._fatigue import FatigueDetail, HotSpotFatigue
from ._loads import UNKNOWN_LEVERAGE, OutsideBasis, gauge_bands, outside_basis_bands
from ._rainflow import HalfCyclePolicy

__all__ = ["GaugeSpec", "HotSpotSpec", "LoadsConfig", "LoadsMonitor"]


class LoadsConfig(BaseModel):
    """Settings of the loads in the engine (closed: unknown keys are refused)."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    exponents: tuple[float, ...] = Field((3.0, 5.0), min_length=1)
    n_eq_per_s: float = Field(1.0, gt=0.0, description="equivalent cycles per second of the DELs (1 Hz equivalent)")
    half_cycles: HalfCyclePolicy = "half"
    trailing_windows: int = Field(360, ge=1, description="windows the damage rate is taken over")
    baseline_windows: int = Field(30, ge=1, description="windows whose median DEL is the DEL baseline")
    del_warning_ratio: float = Field(1.5, gt=1.0)
    del_alarm_ratio: float = Field(2.0, gt=1.0)
    consumed_warning: float = Field(0.5, gt=0.0)
    consumed_alarm: float = Field(0.8, gt=0.0)
    rate_alarm_usage: float = Field(2.0, gt=1.0, description="alarm when rate × design life exceeds this (warning at 1)")
    raise_windows: int = Field(3, ge=1)
    clear_windows: int = Field(3, ge=1)
    clear_fraction: float = Field(0.8, gt=0.0, lt=1.0, description="clear below this fraction of the warning line")
    envelope_stations: int = Field(16, ge=0, le=400, description="stations of the strain envelope along the beam "
                                   "(evenly spaced from the support, the free end left out: its curvature is zero)")

    @model_validator(mode="after")
    def _ordered(self) -> "LoadsConfig":
        if any(not m > 0 for m in self.exponents):
            raise ValueError(f"exponents={self.exponents} must all be > 0")
        if self.del_alarm_ratio < self.del_warning_ratio:
            raise ValueError(f"del_alarm_ratio={self.del_alarm_ratio} is below del_warning_ratio={self.del_warning_ratio}")
        if self.consumed_alarm < self.consumed_warning:
            raise ValueError(f"consumed_alarm={self.consumed_alarm} is below consumed_warning={self.consumed_warning}")
        return self


@dataclass(frozen=True)
class HotSpotSpec:
    """A hot spot as the engine needs it: where, the detail, and the unit deformations' s'' there (Γ,) (1/m)."""

    name: str
    position_m: float
    detail: FatigueDetail
    curvature_shape: np.ndarray
    fibre_distance_m: float


@dataclass(frozen=True)
class GaugeSpec:
    """A strain gauge as the band needs it: where, s'' there (Γ,) (1/m), c (m), and whether it aided the estimate."""

    name: str
    position_m: float
    curvature_shape: np.ndarray
    fibre_distance_m: float
    in_sample: bool


class LoadsMonitor:
    """Per-window loads of the hot spots (see the module docstring).

    Parameters
    ----------
    hot_spots : the hot spots. youngs_modulus : E at the reference temperature (Pa).
    temperature_coefficient : 1/K; reference_temperature : °C. design_life_years : or None.
    config : LoadsConfig. state : from :meth:`state_dict`.
    """

    def __init__(self, hot_spots: list[HotSpotSpec], *, youngs_modulus: float, temperature_coefficient: float = 0.0,
                 reference_temperature: float = 20.0, design_life_years: float | None = None, config: LoadsConfig | None = None,
                 state: dict[str, Any] | None = None, stations: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
                 gauges: list[GaugeSpec] | None = None, outside: tuple[np.ndarray, np.ndarray] | None = None) -> None:
        if not hot_spots:
            raise ValueError("hot_spots is empty: the rig description names no hot spot")
        names = [h.name for h in hot_spots]
        if len(set(names)) != len(names):
            raise ValueError(f"hot spot names {names} are not unique")
        if not (np.isfinite(youngs_modulus) and youngs_modulus > 0):
            raise ValueError(f"{youngs_modulus=} must be > 0")
        if design_life_years is not None and not design_life_years > 0:
            raise ValueError(f"{design_life_years=} must be > 0")
        self.config = config or LoadsConfig()
        self.hot_spots = list(hot_spots)
        self.youngs_modulus = float(youngs_modulus)
        self.temperature_coefficient = float(temperature_coefficient)
        self.reference_temperature = float(reference_temperature)
        self.design_life_years = design_life_years
        state = state or {}
        c = self.config
        self.fatigue = {h.name: HotSpotFatigue(h.detail, exponents=c.exponents, n_eq_per_s=c.n_eq_per_s, half_cycles=c.half_cycles,
                                               trailing_windows=c.trailing_windows, state=state.get("spots", {}).get(h.name))
                        for h in self.hot_spots}
        self.del_history: dict[str, list[float]] = {k: [float(v) for v in vals] for k, vals in state.get("del_history", {}).items()}
        self.alarms = AlarmLogic(raise_windows=c.raise_windows, clear_windows=c.clear_windows, clear_sigma=c.clear_fraction,
                                 state=state.get("alarms"))
        self.events: list[AlarmEvent] = []
        # the strain envelope's stations: (η (S,), s'' (S, Γ), c (S,)), or None
        self.stations: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        if stations is not None:
            eta, shapes, fibre = (np.asarray(a, dtype=float) for a in stations)
            if eta.ndim != 1 or shapes.shape[0] != eta.size or fibre.shape != eta.shape or np.any(fibre <= 0):
                raise ValueError(f"stations must be η (S,), s'' (S, Γ) and c (S,) > 0; got {eta.shape}, {shapes.shape}, {fibre.shape}")
            self.stations = (eta, shapes, fibre)
        #: when a list, each window's input is appended to it as the arguments of :meth:`process_stress`
        #: (start_s, stress (n, hot spots) Pa at the reference E, duration_s, temperature_c, stations):
        #: ``shm reprocess`` chains the files of an archive through one monitor with it
        self.tap: list[tuple] | None = None
        self.gauges = list(gauges or [])
        #: the strain per unit amplitude of the modes above the basis at the gauges (G, K) and the hot spots
        #: (H, K), for the calibrated band (``analytics.outside_basis_bands``), or None: the plain gauge band
        self.outside = None
        if outside is not None:
            at_gauges, at_spots = (np.asarray(a, dtype=float) for a in outside)
            if at_gauges.shape[0] != len(self.gauges) or at_spots.shape[0] != len(self.hot_spots) or at_gauges.shape[1:] != at_spots.shape[1:]:
                raise ValueError(f"outside: {at_gauges.shape} at the gauges and {at_spots.shape} at the hot spots disagree with "
                                 f"{len(self.gauges)} gauges and {len(self.hot_spots)} hot spots")
            self.outside = (at_gauges.reshape(len(self.gauges), -1), at_spots.reshape(len(self.hot_spots), -1))

    @classmethod
    def from_rig(cls, rig: Any, curvature_at: Any, *, config: LoadsConfig | None = None, state: dict[str, Any] | None = None,
                 gauges_in_sample: tuple[str, ...] | None = None, outside_at: Any = None) -> "LoadsMonitor":
        """The monitor of a rig description's ``hot_spots`` (contract.RigDescription); ``curvature_at(η)`` gives the
        unit deformations' s'' at positions η (len(η), Γ) (``estimator.UnitDeformations.curvature``).
        The rig's strain gauges judge the band; ``gauges_in_sample`` names those that aided the estimate
        (None: unknown, all of them are taken as in-sample: the wider band). ``outside_at(η)`` gives the
        strain per unit amplitude of the modes above the basis (len(η), K) for the calibrated band
        (``shm_service.commands.loads.outside_shapes``), or None: the plain gauge band."""
        from ._sn_curves import sn_curve

        beam = rig.beam
        eta = np.array([h.position for h in rig.hot_spots], dtype=float)
        if eta.size == 0:
            raise ValueError("the rig description names no hot_spots")
        if beam.youngs_modulus is None:
            raise ValueError("beam.youngs_modulus is not given (a beam of table sections): the hot spots' stress is "
                             "E·ε, give the E of the material at the hot spots (e.g. a steel root flange)")
        shapes = np.asarray(curvature_at(eta), dtype=float)
        c = beam.fibre_distance(eta)
        spots = [HotSpotSpec(h.name, float(h.position), FatigueDetail(sn_curve(h.curve), h.scf, h.gamma_Ff, h.gamma_Mf), shapes[i],
                             float(c[i])) for i, h in enumerate(rig.hot_spots)]
        design = rig.fatigue.design_life_years if rig.fatigue is not None else None
        n = (config or LoadsConfig()).envelope_stations
        stations = None
        if n:
            grid = np.linspace(0.0, beam.length, n + 1)[:-1]
            stations = (grid, np.asarray(curvature_at(grid), dtype=float), np.asarray(beam.fibre_distance(grid), dtype=float))
        gauges = []
        sensors = list(rig.sensors_of("strain"))
        if sensors:
            at = np.array([g.position for g in sensors], dtype=float)
            g_shapes, g_c = np.asarray(curvature_at(at), dtype=float), np.asarray(beam.fibre_distance(at), dtype=float)
            gauges = [GaugeSpec(g.name, float(g.position), g_shapes[k], float(g_c[k]),
                                gauges_in_sample is None or g.name in gauges_in_sample) for k, g in enumerate(sensors)]
        outside = None
        if outside_at is not None and gauges:
            outside = (np.asarray(outside_at(np.array([g.position_m for g in gauges])), dtype=float),
                       np.asarray(outside_at(eta), dtype=float))
        return cls(spots, youngs_modulus=beam.youngs_modulus, temperature_coefficient=beam.youngs_modulus_temperature_coefficient,
                   reference_temperature=beam.reference_temperature, design_life_years=design, config=config, state=state,
                   stations=stations, gauges=gauges, outside=outside)

    def state_dict(self) -> dict[str, Any]:
        # copies: a window's state may be serialised after later windows ran (a commit waiting for the database)
        return {"spots": {k: f.state_dict() for k, f in self.fatigue.items()},
                "del_history": {k: list(v) for k, v in self.del_history.items()}, "alarms": self.alarms.state_dict()}

    def _chart(self, spot: str, condition: str, score: float | None, warning: float, alarm: float) -> ChartDocument:
        level = "ok" if score is None or score < warning else ("alarm" if score >= alarm else "warning")
        return ChartDocument(name=chart_name("fatigue", hot_spot=spot, condition=condition), kind="fatigue", level=level,
                             score_sigma=score, warning_sigma=warning, alarm_sigma=alarm)

    def process_window(self, start_s: float, b: object, fs: float, temperature_c: float | None,
                       measured: dict[str, np.ndarray] | None = None) -> LoadsWindowDocument:
        """Count one window's new samples b (n, Γ) at ``fs`` Hz (the part no earlier window counted);
        ``measured``: the gauges' strain on the same samples (name → (n,)), for the band."""
        B = np.asarray(b, dtype=float)
        if B.ndim != 2 or B.shape[0] < 1:
            raise ValueError(f"b must be (n, Γ) with n >= 1, got shape {B.shape}")
        if not np.all(np.isfinite(B)):
            raise ValueError("b contains NaN or inf")
        # nominal stress at the reference E: σ = −c E (b · s''); E(T) is applied per window
        stress = np.column_stack([-h.fibre_distance_m * (B @ h.curvature_shape) * self.youngs_modulus for h in self.hot_spots])
        stations = None
        if self.stations is not None:
            eta, shapes, c = self.stations
            strain = -(B @ shapes.T) * c
            stations = (eta, np.sqrt(np.mean(strain**2, axis=0)), np.ptp(strain, axis=0))
        band = self._band(B, measured, B.shape[0] / float(fs))
        return self.process_stress(start_s, stress, B.shape[0] / float(fs), temperature_c, stations=stations, band=band)

    def _band(self, B: np.ndarray, measured: dict[str, np.ndarray] | None,
              duration: float) -> list[tuple[float, float, str]] | None:
        """(low, high, method) per hot spot of the window's DEL bands from the gauges measured over all of it, else None."""
        if not measured or not self.gauges:
            return None
        pairs, rows = [], []
        for k, g in enumerate(self.gauges):
            m = measured.get(g.name)
            if m is None or len(m) != B.shape[0] or not np.all(np.isfinite(m)):
                continue
            rows.append(k)
            # a gauge that aided the estimate is in sample, its leverage unknown here
            pairs.append((g.name, g.position_m, -g.fibre_distance_m * (B @ g.curvature_shape), np.asarray(m, dtype=float),
                          UNKNOWN_LEVERAGE if g.in_sample else 0.0))
        if not pairs:
            return None
        positions = [h.position_m for h in self.hot_spots]
        kw = dict(exponents=self.config.exponents, n_eq=self.config.n_eq_per_s * duration, half_cycles=self.config.half_cycles)
        if self.outside is not None:
            strain = np.column_stack([-h.fibre_distance_m * (B @ h.curvature_shape) for h in self.hot_spots])
            outside = OutsideBasis(self.outside[0][rows], self.outside[1], np.sqrt(np.mean(strain**2, axis=0)))
            found, _rows = outside_basis_bands(pairs, positions, outside, **kw)  # type: ignore[arg-type]
        else:
            found, _rows = gauge_bands(pairs, positions, **kw)  # type: ignore[arg-type]
        return None if found is None else [(f.low, f.high, f.method) for f in found]

    def process_stress(self, start_s: float, stress: object, duration_s: float, temperature_c: float | None, *,
                       stations: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
                       band: tuple[float, float, str] | list[tuple[float, float, str]] | None = None) -> LoadsWindowDocument:
        """Count one window's hot-spot stress (n, hot spots) in Pa at the reference E, lasting ``duration_s``;
        ``stations``: (η, strain RMS, strain range) of the window's envelope, or None; ``band``: (low, high,
        method) of the DELs relative to their value (one for all hot spots, or a list of one per hot
        spot), or None."""
        S = np.asarray(stress, dtype=float)
        if S.ndim != 2 or S.shape[1] != len(self.hot_spots) or S.shape[0] < 1:
            raise ValueError(f"stress must be (n, {len(self.hot_spots)}) with n >= 1, got shape {S.shape}")
        if self.tap is not None:
            self.tap.append((float(start_s), S.copy(), float(duration_s), temperature_c, stations, band))
        duration = float(duration_s)
        factor = 1.0
        if temperature_c is not None:
            factor = 1.0 + self.temperature_coefficient * (temperature_c - self.reference_temperature)
        c = self.config
        bands: list[tuple[float, float, str] | None] = list(band) if isinstance(band, list) else [band] * len(self.hot_spots)
        if len(bands) != len(self.hot_spots):
            raise ValueError(f"{len(bands)} bands for {len(self.hot_spots)} hot spots")
        docs, charts = [], []
        m0 = str(int(c.exponents[0])) if float(c.exponents[0]).is_integer() else str(c.exponents[0])
        for k, h in enumerate(self.hot_spots):
            w = self.fatigue[h.name].push(S[:, k] * factor, duration, start_s=start_s)
            life = self.fatigue[h.name].life(self.design_life_years)
            dels = {(str(int(m)) if float(m).is_integer() else str(m)): v for m, v in w.del_pa.items()}
            banded: dict[str, Any] = {}
            spot_band = bands[k]
            if spot_band is not None:
                low, high, method = spot_band
                fatigue = self.fatigue[h.name]
                banded = {"del_band_pa": {k: [v * low, v * high] for k, v in dels.items()}, "band_method": method,
                          "damage_band": [fatigue.detail.damage(fatigue.last_closed, low),
                                          fatigue.detail.damage(fatigue.last_closed, high)]}
            docs.append(HotSpotLoadsDocument(
                name=h.name, position_m=h.position_m, curve=h.detail.curve.name, del_pa=dels, n_eq=c.n_eq_per_s * duration,
                max_range_pa=w.max_range_pa, damage_increment=w.damage_increment, consumed=w.consumed,
                rate_per_year=life.rate_per_year, rate_band_per_year=None if life.rate_band_per_year is None else list(life.rate_band_per_year),
                remaining_years=life.remaining_years,
                remaining_band_years=None if life.remaining_band_years is None else list(life.remaining_band_years),
                verdict=life.verdict, design_life_years=self.design_life_years, **banded))
            # DEL against its baseline (the median of the first windows)
            history = self.del_history.setdefault(h.name, [])
            score_del = None
            if len(history) >= c.baseline_windows:
                base = float(np.median(history[: c.baseline_windows]))
                if base > 0:
                    score_del = (dels[m0] / base - 1.0) / (c.del_warning_ratio - 1.0)
            else:
                history.append(dels[m0])
            charts.append(self._chart(h.name, "del", score_del, 1.0, (c.del_alarm_ratio - 1.0) / (c.del_warning_ratio - 1.0)))
            charts.append(self._chart(h.name, "consumed", w.consumed / c.consumed_warning, 1.0, c.consumed_alarm / c.consumed_warning))
            if self.design_life_years is not None:
                usage = None if life.rate_per_year is None else life.rate_per_year * self.design_life_years
                charts.append(self._chart(h.name, "rate", usage, 1.0, c.rate_alarm_usage))
        self.events = self.alarms.update(charts, start_s + duration)
        envelope = []
        if stations is not None:
            e_t = self.youngs_modulus * factor
            envelope = [StationLoadsDocument(position_m=float(x), strain_rms=float(r), strain_range_max=float(p),
                                             stress_range_max_pa=float(p * e_t)) for x, r, p in zip(*stations)]
        return LoadsWindowDocument(start_s=start_s, duration_s=duration, temperature_c=temperature_c, hot_spots=docs, charts=charts,
                                   stations=envelope)
