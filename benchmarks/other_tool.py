"""A stand-in for an outside tool that writes recordings to the contract.

It shares nothing with the project's writer: the plain ``mcap`` library writer, ``json.dumps``
with its own spacing and key order, one channel written after the other (not interleaved in
time), lz4 chunks, and ToF samples stamped a few milliseconds off the IMU grid. The samples come
from the virtual rig (the plant), so the truth is known.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from mcap.writer import CompressionType, Writer

from shm_service.virtual_rig import SimulationSettings, VirtualRig

_TITLES = {"imu": "shm.Imu", "tof": "shm.Distance", "bearing": "shm.Distance", "strain": "shm.Strain",
           "env": "shm.Temperature", "truth": "shm.TruthState"}


def write_other_tool_recording(path: str | Path, settings: SimulationSettings) -> VirtualRig:
    """Simulate ``settings`` and write it the way another logger would."""
    vr = VirtualRig(settings)
    blocks = list(vr.blocks(60.0))
    start_ns = 1_700_000_000_123_456_789  # another epoch, not on a round second
    with open(path, "wb") as f:
        writer = Writer(f, compression=CompressionType.LZ4)
        writer.start(profile="", library="other-tool 0.9")
        rig_json = json.dumps(vr.nominal_rig.model_dump(mode="json"), sort_keys=True).encode()
        writer.add_attachment(create_time=start_ns, log_time=start_ns, name="rig.json", media_type="application/json", data=rig_json)
        schemas: dict[str, int] = {}
        topics = list(blocks[0].measurements) + ["/truth/state"]
        for topic in sorted(topics, reverse=True):
            family = topic.split("/")[1]
            title = _TITLES[family]
            if title not in schemas:
                schemas[title] = writer.register_schema(title, "jsonschema", json.dumps({"title": title, "type": "object"}).encode())
            channel = writer.register_channel(topic, "json", schemas[title])
            for block in blocks:
                if topic == "/truth/state":
                    times = block.times
                    tr = block.truth
                    rows = [{"phi": tr["phi"][i], "e": tr["e"][i], "d": tr["d"][i], "h": tr["h"][i],
                             "curvature": tr["curvature"][i].tolist(), "deflection": tr["deflection"][i].tolist()}
                            for i in range(times.size)]
                else:
                    times, values = block.measurements[topic]
                    if family == "imu":
                        rows = [{"gyro": v[3:].tolist(), "accel": v[:3].tolist()} for v in values]
                    elif family in ("tof", "bearing"):
                        rows = [{"distance": float(v[0])} for v in values]
                    elif family == "strain":
                        rows = [{"strain": float(v[0])} for v in values]
                    else:
                        rows = [{"celsius": float(v[0])} for v in values]
                stamps = start_ns + np.round(times * 1e9).astype(np.int64)
                for seq, (stamp, row) in enumerate(zip(stamps.tolist(), rows)):
                    writer.add_message(channel, log_time=stamp, data=json.dumps(row).encode(), publish_time=stamp + 1_000_000, sequence=seq)
        writer.add_metadata("truth", vr.truth_metadata())
        writer.finish()
    return vr
