"""EWMA control chart: the statistic and its instantaneous level (the hysteresis that raises and
clears alarms is :class:`analytics.AlarmLogic`, the one alarm path of ``shm analyze`` and ``shm serve``)."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

from ._validate import positive

__all__ = ["EwmaChart", "ChartState", "chart_level"]


def chart_level(score: float | None, warning: float, alarm: float) -> str:
    """"alarm" if |score| ≥ alarm, "warning" if ≥ warning, else "ok" (None: "ok")."""
    if score is None or not math.isfinite(score):
        return "ok"
    a = abs(score)
    return "alarm" if a >= alarm else ("warning" if a >= warning else "ok")


@dataclass
class ChartState:
    ewma: float = 0.0
    n: int = 0


class EwmaChart:
    """EWMA chart on standardised values z (unit variance when healthy, dimensionless).

    E_k = (1−λ)E_{k−1} + λz_k; its σ is √(λ/(2−λ)·(1−(1−λ)^{2k}))·inflation (inflation accounts for
    correlated inputs, e.g. overlapping windows). ``update`` returns the score E/σ and its level
    against the warning and alarm lines; when a level becomes an alarm is decided by
    :class:`analytics.AlarmLogic` (consecutive windows, clearing with hysteresis).
    """

    def __init__(self, lam: float = 0.2, warning: float = 3.0, alarm: float = 5.0, inflation: float = 1.0):
        positive("lam", lam)
        if lam > 1:
            raise ValueError(f"{lam=} must be <= 1")
        positive("inflation", inflation)
        if not (0 < warning <= alarm):
            raise ValueError(f"need 0 < warning <= alarm, got {warning=}, {alarm=}")
        self.lam, self.warning, self.alarm, self.inflation = lam, warning, alarm, inflation
        self.state = ChartState()

    def sigma(self) -> float:
        k = max(self.state.n, 1)
        return math.sqrt(self.lam / (2 - self.lam) * (1 - (1 - self.lam) ** (2 * k))) * self.inflation

    def update(self, z: float) -> tuple[float, str]:
        """Feed one standardised value; returns (E/σ, its level "ok" | "warning" | "alarm")."""
        if not math.isfinite(z):
            raise ValueError(f"{z=} must be finite")
        s = self.state
        s.ewma = (1 - self.lam) * s.ewma + self.lam * z
        s.n += 1
        score = s.ewma / self.sigma()
        return score, chart_level(score, self.warning, self.alarm)

    def state_dict(self) -> dict:
        return {"params": [self.lam, self.warning, self.alarm, self.inflation], "state": asdict(self.state)}

    @classmethod
    def from_state_dict(cls, d: dict) -> "EwmaChart":
        try:
            lam, w, a, inf = d["params"]
            ch = cls(lam, w, a, inf)
            ch.state = ChartState(**d["state"])
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"chart state is malformed: {exc}") from exc
        return ch
