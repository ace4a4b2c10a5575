"""Fatigue of a hot spot: damage-equivalent ranges, Palmgren–Miner damage accumulated batch by
batch, consumed and remaining life.

The algorithm object :class:`HotSpotFatigue` only calls the pure functions of
:mod:`analytics._rainflow` and :mod:`analytics._sn_curves`; its state (the rainflow residue, the
closed cycles' damage, the recent windows) is plain data, so a restarted service continues the
count exactly (:meth:`HotSpotFatigue.state_dict`).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from ._rainflow import Cycles, HalfCyclePolicy, RainflowCounter, RainflowResidue, _half_weight
from ._sn_curves import SnCurve, damage_equivalent_range, miner_damage

__all__ = ["FatigueDetail", "HotSpotFatigue", "LifeEstimate", "LoadsWindow", "remaining_life", "SECONDS_PER_YEAR"]

SECONDS_PER_YEAR = 365.25 * 86400.0
LifeVerdict = Literal["finite", "no_damage_below_cutoff", "exhausted", "no_data"]


def _positive(name: str, value: object) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)) or not math.isfinite(value) or value <= 0:
        raise ValueError(f"{name}={value!r} must be a finite number > 0")
    return float(value)


@dataclass(frozen=True)
class FatigueDetail:
    """A detail's S–N curve with its stress concentration and partial factors (all > 0)."""

    curve: SnCurve
    scf: float = 1.0
    gamma_ff: float = 1.0
    gamma_mf: float = 1.0

    def __post_init__(self) -> None:
        _positive("scf", self.scf)
        _positive("gamma_Ff", self.gamma_ff)
        _positive("gamma_Mf", self.gamma_mf)

    def damage(self, cycles: Cycles, scale: float = 1.0) -> float:
        """Miner damage of cycles of nominal stress (Pa), their ranges times ``scale``."""
        return miner_damage(cycles.ranges * scale, cycles.counts, self.curve, scf=self.scf, gamma_ff=self.gamma_ff,
                            gamma_mf=self.gamma_mf)


@dataclass(frozen=True)
class LifeEstimate:
    """Consumed and remaining life of a hot spot.

    consumed : Miner's D so far. rate_per_year : damage per year over the trailing period, with
    ``rate_band_per_year`` (the mean of the windows' rates ± 2 standard errors, the windows'
    scatter). remaining_years : (1 − D)/rate, with ``remaining_band_years`` (the rate band's ends;
    None for an unbounded end). verdict : "finite"; "no_damage_below_cutoff" (no range over the
    trailing period reached the curve's cut-off: the life is not limited by these loads, no number
    is given); "exhausted" (D ≥ 1); "no_data". exhausts_design_life_early : 1/rate below the
    design life (None without a design life or a rate).
    """

    consumed: float
    rate_per_year: float | None
    rate_band_per_year: tuple[float, float] | None
    remaining_years: float | None
    remaining_band_years: tuple[float | None, float | None] | None
    verdict: LifeVerdict
    design_life_years: float | None
    exhausts_design_life_early: bool | None
    method: str = "rate over the trailing windows; band: mean window rate ± 2 standard errors"


def remaining_life(consumed: float, increments: object, durations_s: object, *, design_life_years: float | None = None) -> LifeEstimate:
    """Remaining life from the consumed damage and the trailing windows' damage increments.

    Parameters
    ----------
    consumed : D ≥ 0. increments : (W,) damage per window ≥ 0. durations_s : (W,) window lengths, s > 0.
    design_life_years : optional, > 0.

    Examples
    --------
    >>> r = remaining_life(0.5, [1e-9, 1e-9], [1.0, 1.0])
    >>> round(r.remaining_years, 3)
    15.844
    """
    if not (math.isfinite(consumed) and consumed >= 0):
        raise ValueError(f"consumed={consumed!r} must be finite and >= 0")
    inc = np.asarray(increments, dtype=float).ravel()
    dur = np.asarray(durations_s, dtype=float).ravel()
    if inc.shape != dur.shape:
        raise ValueError(f"increments {inc.shape} and durations_s {dur.shape} disagree")
    if not np.all(np.isfinite(inc)) or np.any(inc < 0):
        raise ValueError("increments must be finite and >= 0")
    if not np.all(np.isfinite(dur)) or np.any(dur <= 0):
        raise ValueError("durations_s must be finite and > 0")
    design = None if design_life_years is None else _positive("design_life_years", design_life_years)
    if consumed >= 1.0:
        return LifeEstimate(consumed, None, None, 0.0, (0.0, 0.0), "exhausted", design, True if design else None)
    if inc.size == 0:
        return LifeEstimate(consumed, None, None, None, None, "no_data", design, None)
    total = float(inc.sum())
    if total == 0.0:
        return LifeEstimate(consumed, 0.0, (0.0, 0.0), None, None, "no_damage_below_cutoff", design, False if design else None)
    rate = total / float(dur.sum()) * SECONDS_PER_YEAR
    rates = inc / dur * SECONDS_PER_YEAR
    se = float(np.std(rates, ddof=1) / math.sqrt(rates.size)) if rates.size > 1 else rate
    lo, hi = max(rate - 2 * se, 0.0), rate + 2 * se
    left = 1.0 - consumed
    band = (left / hi, None if lo == 0 else left / lo)
    early = None if design is None else bool(1.0 / rate < design)
    return LifeEstimate(consumed, rate, (lo, hi), left / rate, band, "finite", design, early)


@dataclass(frozen=True)
class LoadsWindow:
    """One window of a hot spot's stress (Pa, nominal, before SCF).

    del_pa : {m: DEL_m} of the window counted on its own (half cycles as half, N_eq = n_eq_per_s ·
    duration). max_range_pa : its largest range. damage_increment : Miner damage of the cycles the
    window closed in the streaming count. consumed : D so far (closed cycles plus the open residue
    as half cycles).
    """

    start_s: float
    duration_s: float
    del_pa: dict[float, float]
    max_range_pa: float
    damage_increment: float
    consumed: float
    cycles: float


class HotSpotFatigue:
    """Streaming fatigue of one hot spot: ``push(stress_pa, duration_s)`` per window.

    Parameters
    ----------
    detail : the curve and factors. exponents : Wöhler exponents of the DELs (> 0).
    n_eq_per_s : equivalent cycles per second (default 1, "1 Hz equivalent").
    half_cycles : policy of the residue ("half", "full", "ignore"). trailing_windows : windows
    the damage rate is taken over. state : from :meth:`state_dict`.
    """

    def __init__(self, detail: FatigueDetail, *, exponents: tuple[float, ...] = (3.0, 5.0), n_eq_per_s: float = 1.0,
                 half_cycles: HalfCyclePolicy = "half", trailing_windows: int = 360, state: dict[str, Any] | None = None) -> None:
        self.detail = detail
        self.exponents = tuple(_positive("exponent m", m) for m in exponents)
        self.n_eq_per_s = _positive("n_eq_per_s", n_eq_per_s)
        _half_weight(half_cycles)
        self.half_cycles = half_cycles
        if isinstance(trailing_windows, bool) or not isinstance(trailing_windows, int) or trailing_windows < 1:
            raise ValueError(f"{trailing_windows=} must be an integer >= 1")
        self._recent: deque[tuple[float, float]] = deque(maxlen=trailing_windows)
        self.closed_damage = 0.0
        residue = None
        if state is not None:
            try:
                residue = RainflowResidue.from_dict(state["residue"])
                self.closed_damage = float(state["closed_damage"])
                self._recent.extend((float(a), float(b)) for a, b in state["recent"])
            except (KeyError, TypeError, ValueError) as exc:
                raise ValueError(f"hot-spot fatigue state is malformed: {exc}") from None
        self._counter = RainflowCounter(residue)
        self.last_closed = Cycles.empty()

    def state_dict(self) -> dict[str, Any]:
        return {"residue": self._counter.residue.as_dict(), "closed_damage": self.closed_damage,
                "recent": [list(r) for r in self._recent]}

    @property
    def consumed(self) -> float:
        return self.closed_damage + self.detail.damage(self._counter.residue.half_cycles(self.half_cycles))

    def push(self, stress_pa: object, duration_s: float, *, start_s: float = 0.0) -> LoadsWindow:
        x = np.asarray(stress_pa, dtype=float)
        duration_s = _positive("duration_s", duration_s)
        closed = self._counter.push(x, name="stress_pa")
        self.last_closed = closed  # the cycles this window closed (the damage band scales their ranges)
        increment = self.detail.damage(closed)
        self.closed_damage += increment
        self._recent.append((increment, duration_s))
        # the window counted on its own for its DEL (the per-window DEL of IEC 61400 practice)
        own = RainflowCounter()
        own_closed = own.push(x, name="stress_pa")
        cycles = Cycles.concatenate([own_closed, own.residue.half_cycles(self.half_cycles)])
        n_eq = self.n_eq_per_s * duration_s
        dels = {m: damage_equivalent_range(cycles.ranges, cycles.counts, m, n_eq) for m in self.exponents}
        return LoadsWindow(float(start_s), duration_s, dels, float(cycles.ranges.max()) if cycles.ranges.size else 0.0,
                           increment, self.consumed, cycles.total)

    def life(self, design_life_years: float | None = None) -> LifeEstimate:
        inc = [a for a, _ in self._recent]
        dur = [b for _, b in self._recent]
        return remaining_life(min(self.consumed, 1e300), inc, dur, design_life_years=design_life_years)
