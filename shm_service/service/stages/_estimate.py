"""The estimation stage of a structure's pipeline: the streaming estimator (``estimator.
StreamingEstimator``, the one policy that ``estimate()``, ``shm estimate`` and ``shm analyze``
run too) over the merged samples, and the instants before which its output is not analysed
(the filter converging after its rest calibration, or after a restart)."""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from contract import TEMPERATURE_TOPIC
from estimator import FilterOutput, ImmsModel, RestCalibration, StreamingEstimator, StreamingSettings

__all__ = ["EstimateSettings", "EstimateStage", "Estimates", "calibration_from_dict", "calibration_to_dict"]

log = logging.getLogger("shm.serve.pipeline")

_NS = 1_000_000_000


class EstimateSettings(BaseModel):
    """The streaming estimator's settings as the service sets them (``[estimator]``)."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    calibration_s: float = Field(60.0, ge=5, le=600, description="data gathered for the rest calibration before filtering, s")
    chunk_s: float = Field(2.0, gt=0, le=60, description="data per estimator call, s")
    warmup_s: float = Field(120.0, ge=0, le=3600, description="windows starting less than this after the rest phase are "
                            "not analysed (the filter converges), s")


def calibration_to_dict(cal: RestCalibration) -> dict:
    return {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in vars(cal).items()}


def calibration_from_dict(d: dict) -> RestCalibration:
    fields = RestCalibration.__dataclass_fields__
    kw: dict[str, Any] = {}
    for name in fields:
        value = d[name]
        kw[name] = np.asarray(value, dtype=float) if isinstance(value, list) else value
    kw["rest_end"] = float(kw["rest_end"])
    kw["rested"] = bool(kw["rested"])
    kw["bearing_std"] = float("nan") if kw["bearing_std"] is None else float(kw["bearing_std"])
    return RestCalibration(**kw)


def stored_calibration(stored: dict) -> RestCalibration | None:
    """The rest calibration of a structure's stored state (None: none, or unusable: calibrate again)."""
    cal = stored.get("calibration")
    if cal is None:
        return None
    try:
        return calibration_from_dict(cal)
    except (KeyError, TypeError, ValueError) as exc:
        log.warning("stored calibration unusable (%s); calibrating again", exc)
        return None


@dataclass
class Estimates:
    """What one step of the estimator gives: its output ``out`` (times ``out.t`` s after
    ``epoch_ns``; None: nothing yet), the temperature samples released with it (times s after
    ``epoch_ns``, °C) and instants (UNIX ns) before which windows are not to be analysed."""

    epoch_ns: int
    out: FilterOutput | None
    temperature: tuple[np.ndarray, np.ndarray] | None
    not_before_ns: list[int]


class EstimateStage:
    """The streaming estimator of one structure. ``step(released)`` takes the merge's released
    samples (per topic: times ns, values) and returns ``Estimates`` (None before the estimator
    has an epoch)."""

    def __init__(self, model: ImmsModel, settings: EstimateSettings | None = None,
                 calibration: RestCalibration | None = None) -> None:
        self.settings = settings or EstimateSettings()
        self.model = model
        self.estimator = StreamingEstimator(model, StreamingSettings(calibration_s=self.settings.calibration_s,
                                                                     chunk_s=self.settings.chunk_s), calibration)
        self._warmup_set = False

    def step(self, released: dict[str, tuple[np.ndarray, np.ndarray]], final: bool = False) -> Estimates | None:
        est = self.estimator
        restarts = est.resets
        out = est.feed(released) if released else None
        if final:
            tail = est.finish()
            if tail is not None and out is not None:
                out = FilterOutput.concatenate([out, tail], self.model.state_size)
            elif tail is not None:
                out = tail
        not_before: list[int] = []
        if est.resets != restarts and est.restarted_at_s is not None and est.epoch_ns:
            # Windows that would hold the diverged filter's b (or the new one's first seconds) are not analysed.
            not_before.append(est.epoch_ns + int(round((est.restarted_at_s + est.health_config.settle_s) * _NS)))
        epoch = est.epoch_ns
        if epoch is None:
            return None
        temp = released.get(TEMPERATURE_TOPIC)
        # times after the estimator's epoch (whole UNIX seconds): the engine aligns its windows
        # in data time from there to the nanosecond
        temperature = None if temp is None else ((temp[0] - epoch) * 1e-9, temp[1][:, 0])
        if out is not None and len(out.t) and not self._warmup_set and est.calibration is not None:
            self._warmup_set = True
            not_before.append(epoch + int(round((float(est.calibration.rest_end) + self.settings.warmup_s) * _NS)))
        return Estimates(epoch, out if out is not None and len(out.t) else None, temperature, not_before)

    def new_calibration(self) -> dict | None:
        """The rest calibration to store with the next window (once after each new one), else None."""
        est = self.estimator
        if est.new_calibration and est.calibration is not None:
            est.new_calibration = False
            return calibration_to_dict(est.calibration)
        return None
