"""EWMA control chart with warning/alarm levels and hysteresis."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

from ._validate import positive

__all__ = ["EwmaChart", "ChartState"]


@dataclass
class ChartState:
    ewma: float = 0.0
    n: int = 0
    level: str = "ok"  # "ok" | "warning" | "alarm"
    above: int = 0
    below: int = 0
    since_s: float | None = None


class EwmaChart:
    """EWMA chart on standardised values z (unit variance when healthy, dimensionless).

    E_k = (1−λ)E_{k−1} + λz_k; its σ is √(λ/(2−λ)·(1−(1−λ)^{2k}))·inflation (inflation accounts for
    correlated inputs, e.g. overlapping windows). The level becomes "alarm" after ``hold``
    consecutive |E|/σ ≥ alarm and returns to "ok" only after ``hold`` consecutive |E|/σ < clear
    (hysteresis); "warning" is shown while |E|/σ ≥ warning without an alarm. ``since_s`` is the
    time the current excursion first left "ok" (the onset of a change, before the alarm).
    """

    def __init__(self, lam: float = 0.2, warning: float = 3.0, alarm: float = 5.0, clear: float = 2.0, hold: int = 3, inflation: float = 1.0):
        positive("lam", lam)
        if lam > 1:
            raise ValueError(f"{lam=} must be <= 1")
        positive("inflation", inflation)
        if not (0 <= clear < warning <= alarm):
            raise ValueError(f"need 0 <= clear < warning <= alarm, got {clear=}, {warning=}, {alarm=}")
        if not isinstance(hold, int) or hold < 1:
            raise ValueError(f"{hold=} must be an integer >= 1")
        self.lam, self.warning, self.alarm, self.clear, self.hold, self.inflation = lam, warning, alarm, clear, hold, inflation
        self.state = ChartState()

    def sigma(self) -> float:
        k = max(self.state.n, 1)
        return math.sqrt(self.lam / (2 - self.lam) * (1 - (1 - self.lam) ** (2 * k))) * self.inflation

    def update(self, z: float, time_s: float = 0.0) -> tuple[float, str]:
        """Feed one standardised value; returns (|E|/σ signed as E, level)."""
        if not math.isfinite(z):
            raise ValueError(f"{z=} must be finite")
        s = self.state
        s.ewma = (1 - self.lam) * s.ewma + self.lam * z
        s.n += 1
        score = s.ewma / self.sigma()
        a = abs(score)
        if s.level != "alarm":
            s.above = s.above + 1 if a >= self.alarm else 0
            if s.above >= self.hold:
                s.level, s.below = "alarm", 0
                s.since_s = time_s if s.since_s is None else s.since_s
            else:
                s.level = "warning" if a >= self.warning else "ok"
            if s.level == "ok":
                s.since_s = None
            elif s.since_s is None:
                s.since_s = time_s
        else:
            s.below = s.below + 1 if a < self.clear else 0
            if s.below >= self.hold:
                s.level, s.above = ("warning" if a >= self.warning else "ok"), 0
                s.since_s = None if s.level == "ok" else time_s
        return score, s.level

    def state_dict(self) -> dict:
        return {"params": [self.lam, self.warning, self.alarm, self.clear, self.hold, self.inflation], "state": asdict(self.state)}

    @classmethod
    def from_state_dict(cls, d: dict) -> "EwmaChart":
        lam, w, a, c, h, inf = d["params"]
        ch = cls(lam, w, a, c, int(h), inf)
        ch.state = ChartState(**d["state"])
        return ch
