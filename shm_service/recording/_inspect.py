"""A summary of a recording for people and scripts (``shm inspect FILE [--json]``)."""

from __future__ import annotations

from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np

from contract import RigDescription

from ._reader import read_recording

__all__ = ["format_inspection", "inspect_recording"]


def inspect_recording(path: str | Path, *, rig: RigDescription | str | Path | None = None) -> dict[str, Any]:
    """Read ``path`` and summarise it as a JSON-ready dict.

    Per topic: schema title, message count, accepted count, rate (Hz, from the median time
    step), first and last sample (s from the recording's start), gaps, missing samples and the
    rejected messages by reason. Also the duration (s), the rig (sensor counts by kind, beam
    length in m), metadata and attachment names, the truncated flag and the problems.
    """
    recording = read_recording(path, rig=rig)
    start = recording.start_ns
    topics: dict[str, Any] = {}
    for topic, report in recording.report.topics.items():
        times = recording.channels[topic].log_time_ns
        steps = np.diff(times)
        topics[topic] = {
            "schema": report.schema,
            "messages": report.messages,
            "accepted": report.accepted,
            "rate_hz": float(1e9 / np.median(steps)) if len(steps) else None,
            "first_s": (int(times[0]) - start) / 1e9 if len(times) else None,
            "last_s": (int(times[-1]) - start) / 1e9 if len(times) else None,
            "gaps": report.gaps,
            "missing_samples": report.missing_samples,
            "silent_after_s": report.silent_after_s,
            "rejected": {
                "malformed": report.malformed,
                "nonfinite": report.nonfinite,
                "implausible": report.implausible,
                "duplicate": report.duplicate,
                "backwards": report.backwards,
            },
        }
    return {
        "path": str(path),
        "duration_s": recording.duration_s,
        "topics": topics,
        "skipped_topics": dict(recording.report.skipped_topics),
        "rig": {
            "beam_length_m": recording.rig.beam.length,
            "sensors": dict(Counter(sensor.kind for sensor in recording.rig.sensors)),
            "truth_stations": len(recording.rig.truth_stations),
        },
        "metadata": sorted(recording.metadata),
        "attachments": list(recording.attachments),
        "truncated": recording.report.truncated,
        "problems": list(recording.report.problems),
    }


def _cell(value: Any, digits: int) -> str:
    if value is None:
        return "-"
    return f"{value:.{digits}f}" if isinstance(value, float) else str(value)


def format_inspection(summary: dict[str, Any]) -> str:
    """A human-readable table of ``inspect_recording``'s result."""
    rig = summary["rig"]
    sensors = ", ".join(f"{count} {kind}" for kind, count in sorted(rig["sensors"].items()))
    lines = [
        f"recording {summary['path']}: {summary['duration_s']:.3f} s"
        + ("  (TRUNCATED: cut off mid-write)" if summary["truncated"] else ""),
        f"rig: beam {rig['beam_length_m']} m, sensors: {sensors or 'none'}, {rig['truth_stations']} truth stations",
        f"metadata: {', '.join(summary['metadata']) or 'none'}; attachments: {', '.join(summary['attachments']) or 'none'}",
        "",
    ]
    header = ("topic", "schema", "messages", "accepted", "rate Hz", "first s", "last s", "gaps", "missing", "rejected")
    rows = [header]
    for topic, info in summary["topics"].items():
        rejected = ", ".join(f"{count} {reason}" for reason, count in info["rejected"].items() if count) or "0"
        rows.append(
            (
                topic,
                info["schema"],
                str(info["messages"]),
                str(info["accepted"]),
                _cell(info["rate_hz"], 2),
                _cell(info["first_s"], 3),
                _cell(info["last_s"], 3),
                str(info["gaps"]),
                str(info["missing_samples"]),
                rejected,
            )
        )
    for topic, count in summary["skipped_topics"].items():
        rows.append((topic, "(skipped)", str(count), "0", "-", "-", "-", "-", "-", "-"))
    widths = [max(len(row[i]) for row in rows) for i in range(len(header))]
    for row in rows:
        lines.append("  ".join(cell.ljust(width) for cell, width in zip(row, widths)).rstrip())
    if summary["problems"]:
        lines.append("")
        lines.append("problems:")
        lines.extend(f"  - {problem}" for problem in summary["problems"])
    return "\n".join(lines)
