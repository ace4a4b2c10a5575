"""Write the virtual rig's samples as a recording that follows the contract."""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import orjson

from estimator import RigDescription

from ..recording import RecordingWriter
from ..recording._writer import encode_payloads_json
from ._settings import SimulationSettings
from ._virtual_rig import SampleBlock, VirtualRig

__all__ = ["SimulationSummary", "simulate", "encode_payloads"]

_NS = 1_000_000_000


@dataclass(frozen=True)
class SimulationSummary:
    path: str
    duration_s: float
    messages: dict[str, int]
    eigenfrequencies_hz: list[float]
    eigenfrequencies_after_damage_hz: list[float] | None
    wall_time_s: float
    #: the ξ plane's eigenfrequencies of a biaxial beam (None: planar)
    eigenfrequencies_xi_hz: list[float] | None = None

    def as_dict(self) -> dict:
        return {
            "path": self.path,
            "duration_s": self.duration_s,
            "messages": self.messages,
            "total_messages": sum(self.messages.values()),
            "eigenfrequencies_hz": self.eigenfrequencies_hz,
            "eigenfrequencies_after_damage_hz": self.eigenfrequencies_after_damage_hz,
            "wall_time_s": round(self.wall_time_s, 3),
        } | ({} if self.eigenfrequencies_xi_hz is None else {"eigenfrequencies_xi_hz": self.eigenfrequencies_xi_hz})


def encode_payloads(topic: str, values: np.ndarray) -> list[bytes]:
    """JSON payloads of the contract for the rows of ``values`` of ``topic`` (exact-size bytes)."""
    rows = values.tolist()
    if topic.startswith("/imu/"):
        objects = [{"accel": r[:3], "gyro": r[3:]} for r in rows]
    elif topic.startswith("/tof/") or topic == "/bearing/displacement":
        objects = [{"distance": r[0]} for r in rows]
    elif topic.startswith("/strain/"):
        objects = [{"strain": r[0]} for r in rows]
    elif topic == "/env/temperature":
        objects = [{"celsius": r[0]} for r in rows]
    else:
        raise ValueError(f"no payload encoding for topic {topic!r}")
    return encode_payloads_json(objects)


def _truth_payloads(truth: dict[str, np.ndarray]) -> list[bytes]:
    if "e_xi" in truth:  # a biaxial beam: the ξ plane's keys after the planar ones (the contract's order)
        return encode_payloads_json([
            {"d": d, "h": h, "phi": p, "e": e, "deflection": w, "curvature": k, "e_xi": ex, "deflection_xi": wx,
             "curvature_xi": kx}
            for d, h, p, e, w, k, ex, wx, kx in zip(
                truth["d"].tolist(), truth["h"].tolist(), truth["phi"].tolist(), truth["e"].tolist(),
                truth["deflection"].tolist(), truth["curvature"].tolist(), truth["e_xi"].tolist(),
                truth["deflection_xi"].tolist(), truth["curvature_xi"].tolist(),
            )
        ])
    return encode_payloads_json([
        {"d": d, "h": h, "phi": p, "e": e, "deflection": w, "curvature": k}
        for d, h, p, e, w, k in zip(
            truth["d"].tolist(), truth["h"].tolist(), truth["phi"].tolist(), truth["e"].tolist(),
            truth["deflection"].tolist(), truth["curvature"].tolist(),
        )
    ])


def write_block(writer: RecordingWriter, block: SampleBlock, start_time_ns: int) -> dict[str, int]:
    """Write one block in the order a logger receives it (by publish time)."""
    topics: list[str] = []
    log_ns: list[np.ndarray] = []
    pub_ns: list[np.ndarray] = []
    payloads: list[bytes] = []
    for topic, (times, values) in block.measurements.items():
        stamps = start_time_ns + np.round(times * _NS).astype(np.int64)
        topics.append(topic)
        log_ns.append(stamps)
        pub_ns.append(stamps + np.round(block.delays[topic] * _NS).astype(np.int64))
        payloads.extend(encode_payloads(topic, values))
    truth_stamps = start_time_ns + np.round(block.times * _NS).astype(np.int64)
    topics.append("/truth/state")
    log_ns.append(truth_stamps)
    pub_ns.append(truth_stamps)
    payloads.extend(_truth_payloads(block.truth))
    counts = [len(s) for s in log_ns]
    topic_index = np.repeat(np.arange(len(topics)), counts)
    all_log = np.concatenate(log_ns)
    all_pub = np.concatenate(pub_ns)
    order = np.lexsort((all_log, all_pub))
    write = writer.write
    for i, lt, pt in zip(order.tolist(), all_log[order].tolist(), all_pub[order].tolist()):
        write(topics[topic_index[i]], lt, payloads[i], pt)
    return dict(zip(topics, counts))


def simulate(settings: SimulationSettings, out: str | Path, *, block_seconds: float = 60.0,
             rig: RigDescription | None = None) -> SimulationSummary:
    """Simulate ``settings`` and write the recording to ``out`` (rig.json and truth included);
    ``rig``: a rig description to simulate instead of the settings' layout."""
    started = time.perf_counter()
    virtual = VirtualRig(settings, rig)
    metadata = virtual.truth_metadata()
    totals: dict[str, int] = {}
    with RecordingWriter(out, virtual.nominal_rig, metadata={"truth": metadata}) as writer:
        for block in virtual.blocks(block_seconds):
            for topic, count in write_block(writer, block, settings.start_time_ns).items():
                totals[topic] = totals.get(topic, 0) + count
    after = metadata.get("eigenfrequencies_after_damage_hz")
    return SimulationSummary(
        path=str(out),
        duration_s=virtual.n_samples / 200.0,
        messages=totals,
        eigenfrequencies_hz=orjson.loads(metadata["eigenfrequencies_hz"]),
        eigenfrequencies_after_damage_hz=None if after is None else orjson.loads(after),
        wall_time_s=time.perf_counter() - started,
        eigenfrequencies_xi_hz=None if "eigenfrequencies_xi_hz" not in metadata else orjson.loads(metadata["eigenfrequencies_xi_hz"]),
    )
