"""Design mode: the cheapest configurations of a study that meet accuracy targets."""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field, model_validator

from ._study import ConfigurationResult


class DesignTargets(BaseModel):
    """Accuracy targets against the simulator truth (RMSE after the rest phase). A configuration
    meets a target when its mean plus one standard deviation over the seeds stays within it."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    phi_deg: float | None = Field(None, gt=0, le=90, description="attitude RMSE target, degrees")
    e_m: float | None = Field(None, gt=0, le=4, description="pseudo-elastic deformation RMSE target, m")

    @model_validator(mode="after")
    def _some(self) -> "DesignTargets":
        if self.phi_deg is None and self.e_m is None:
            raise ValueError("give at least one target: phi_deg or e_m")
        return self

    def margins(self, row: ConfigurationResult) -> dict[str, float]:
        """Upper bound (mean + std) / target for each given target; ≤ 1 meets it."""
        out = {}
        for key, target in (("phi_deg", self.phi_deg), ("e_m", self.e_m)):
            if target is not None:
                out[key] = (row.rmse_truth[key] + row.rmse_truth_std[key]) / target
        return out

    def met_by(self, row: ConfigurationResult) -> bool:
        return all(m <= 1.0 for m in self.margins(row).values())


def cheapest(rows: tuple[ConfigurationResult, ...], targets: DesignTargets) -> list[ConfigurationResult]:
    """Every configuration that meets the targets, cheapest first: fewest strain gauges, then
    fewest IMU/ToF boards, then fewest sensors, then the largest margin to the targets."""
    ok = [r for r in rows if targets.met_by(r)]
    return sorted(ok, key=lambda r: (r.config.gauges, r.boards, r.config.imus + r.config.tofs,
                                     max(targets.margins(r).values())))
