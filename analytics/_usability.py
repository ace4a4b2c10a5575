"""Why the analysis windows of a record are not usable: each window's rejection reason, counted,
and what to change when none is usable.

A window is *usable* when it is trusted (operational or free-decay data) and its subspace
identification gave at least one tracked mode with a confidence of at least
``AnalysisConfig.min_confidence``: only such windows carry eigenfrequencies, learn a baseline and
feed the charts. Every other window has one reason, the first that applies of

* ``warmup``: it starts before the filter has converged (``not_before``; not analysed);
* ``incomplete``: b(t) does not cover it (a gap: the estimator restarted its filter, or samples
  are missing; not analysed);
* ``quiet``: b barely moves (RMS below ``quiet_rms``);
* ``forced``: the measured input is deterministic with a line at or near a tracked mode (the
  forced response, not the modes);
* ``no_mode_identified``: trusted, but no tracked mode was identified with enough confidence.
"""

from __future__ import annotations

from ._config import AnalysisConfig

__all__ = ["WINDOW_REJECTIONS", "usability_document", "window_rejection"]

#: per rejection reason: what it means, and what to change
WINDOW_REJECTIONS: dict[str, tuple[str, str]] = {
    "warmup": ("starts before the estimator's warm-up ended (the filter converging)",
               "record longer than the rest phase, the warm-up and one window; or start earlier (shm analyze --not-before, the "
               "configuration's estimator.warmup_s) if the filter converges sooner"),
    "incomplete": ("b(t) has a gap there: the estimator restarted its filter or samples are missing",
                   "see shm estimate's restarts and health: when the filter restarts because modes above the basis carry "
                   "the motion, use more unit deformations (--modes), more IMUs, or a band-limit on the gauges' aiding; "
                   "when samples are missing, repair the recording (shm inspect)"),
    "quiet": ("b barely moves (RMS below analytics quiet_rms)",
              "the structure needs excitation (ambient or operational); lower quiet_rms only if b is in other units"),
    "forced": ("the support motion is deterministic at or near a tracked mode: the forced response, not the modes",
               "analyse operational (random) or free-decay periods: --not-before past the forcing, or a recording without it"),
    "no_mode_identified": ("trusted, but no tracked mode was identified with confidence >= min_confidence",
                           "check the expected modes (--modes; the rig's model), make windows longer (window_s: at least "
                           "chart_min_cycles of the slowest mode) or lower min_confidence"),
}


def window_rejection(result: object, config: AnalysisConfig) -> str | None:
    """Why one analysed window (an ``analytics.WindowResult``) is not usable, or None when it is.

    Parameters
    ----------
    result : WindowResult
        The window's figures (its kind, trust and per-mode estimates).
    config : AnalysisConfig
        Gives ``min_confidence``.

    Returns
    -------
    str or None
        "quiet", "forced" or "no_mode_identified" (the keys of :data:`WINDOW_REJECTIONS`), or None.
    """
    if not isinstance(config, AnalysisConfig):
        raise ValueError(f"config must be an AnalysisConfig, got {type(config).__name__}")
    kind = getattr(result, "kind", None)
    if kind in ("quiet", "forced"):
        return kind
    if not getattr(result, "trusted", False):
        raise ValueError(f"a window of kind {kind!r} is either trusted or quiet/forced")
    for e in getattr(result, "estimates", ()):
        if e.frequency_hz is not None and e.method == "ssi" and e.confidence >= config.min_confidence:
            return None
    return "no_mode_identified"


def usability_document(usable: int, rejected: dict[str, int]) -> dict:
    """The windows' usability as a JSON document: the usable count, each rejection reason's count
    and, when no window is usable, why (the reasons by count, each with its meaning) and what to change.

    Parameters
    ----------
    usable : windows usable (>= 0).
    rejected : reason (a key of :data:`WINDOW_REJECTIONS`) → windows (>= 0).

    Returns
    -------
    dict
        {"usable": int, "rejected": {reason: count}, "why_none": str | None, "change": [str]}.

    Examples
    --------
    >>> d = usability_document(0, {"quiet": 3})
    >>> d["usable"], d["rejected"], d["why_none"]
    (0, {'quiet': 3}, 'no usable window: 3 quiet (b barely moves (RMS below analytics quiet_rms))')
    """
    if isinstance(usable, bool) or not isinstance(usable, int) or usable < 0:
        raise ValueError(f"{usable=} must be an integer >= 0")
    for k, n in rejected.items():
        if k not in WINDOW_REJECTIONS:
            raise ValueError(f"rejection reason {k!r} must be one of {sorted(WINDOW_REJECTIONS)}")
        if isinstance(n, bool) or not isinstance(n, int) or n < 0:
            raise ValueError(f"rejected[{k!r}]={n!r} must be an integer >= 0")
    counts = {k: int(rejected[k]) for k in WINDOW_REJECTIONS if rejected.get(k)}
    why = change = None
    if usable == 0:
        ranked = sorted(counts.items(), key=lambda kv: -kv[1])
        if ranked:
            why = "no usable window: " + "; ".join(f"{n} {k} ({WINDOW_REJECTIONS[k][0]})" for k, n in ranked)
            change = [f"{k}: {WINDOW_REJECTIONS[k][1]}" for k, _ in ranked]
        else:
            why = "no usable window: the record holds no complete analysis window (shorter than window_s after the warm-up)"
            change = ["record longer than the warm-up plus one analysis window (window_s), or shorten window_s"]
    return {"usable": int(usable), "rejected": counts, "why_none": why, "change": change or []}
