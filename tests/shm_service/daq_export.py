"""Export a contract recording's sensor channels to the files a DAQ writes (text, .npy, .npz, MATLAB
v5 and v7.3, HDF5) with the channel map that imports them back: the round trip of ``shm import``.

Topics sharing their sample times form one clock (the virtual rig has three: IMUs and gauges at
200 Hz, ToFs and the bearing at 33.33 Hz, the temperature at 1 Hz). Times are written in s from
the recording's start, with ``start_ns`` in the map, so every ns survives the trip; numbers are
written with ``repr`` (shortest round-trip form) in text.
"""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import tomli_w
from scipy import io

from shm_service.recording import Recording

AXES = "xyz"


def columns_of(rec: Recording) -> dict[str, dict]:
    """Per clock (named by rate): the times (s from the start) and the columns {name: (values, entry)}."""
    groups: dict[bytes, list[str]] = {}
    for topic, channel in sorted(rec.channels.items()):
        if channel.kind in ("truth", "estimate"):
            continue
        groups.setdefault(channel.log_time_ns.tobytes(), []).append(topic)
    clocks: dict[str, dict] = {}
    for topics in groups.values():
        first = rec.channels[topics[0]]
        rate = 1e9 / float(np.median(np.diff(first.log_time_ns)))
        name = "fast" if rate > 100 else "slow" if rate > 10 else "temp"
        columns: dict[str, tuple[np.ndarray, dict]] = {}
        for topic in topics:
            channel = rec.channels[topic]
            if channel.kind == "imu":
                for f, field in enumerate(("accel", "gyro")):
                    for i in range(3):
                        columns[f"imu_{channel.name}_{field}_{AXES[i]}"] = (
                            channel.values[:, 3 * f + i], {"topic": topic, "field": field, "index": i})
            else:
                field = {"tof": "distance", "bearing": "distance", "strain": "strain", "temperature": "celsius"}[channel.kind]
                label = channel.kind if channel.kind in ("bearing", "temperature") else f"{channel.kind}_{channel.name}"
                columns[label] = (channel.values[:, 0], {"topic": topic, "field": field})
        clocks[name] = {"time": (first.log_time_ns - rec.start_ns) / 1e9, "columns": columns}
    return clocks


def _map(rec: Recording, clocks: dict[str, dict], clock_keys: dict[str, dict], column_key=None) -> dict:
    doc: dict = {"clocks": {}, "columns": {}}
    for name, keys in clock_keys.items():
        doc["clocks"][name] = {"start_ns": int(rec.start_ns), **keys}
    for name, clock in clocks.items():
        for j, (label, (_, entry)) in enumerate(clock["columns"].items()):
            key, extra = (label, {}) if column_key is None else column_key(name, j, label)
            doc["columns"][key] = {**entry, "clock": name, **extra}
    return doc


def export(rec: Recording, fmt: str, folder: Path) -> tuple[list[Path], Path]:
    """Write ``rec`` in ``fmt`` to ``folder``; returns the DATA files and the map (TOML)."""
    folder.mkdir(parents=True, exist_ok=True)
    clocks = columns_of(rec)
    if fmt == "text":
        # one file a clock, each with its own delimiter; strain in µε and the temperature in K,
        # so the map's scale and offset take part in the trip
        files, keys = {}, {}
        for (name, clock), (suffix, sep) in zip(clocks.items(), ((".csv", ","), (".tsv", "\t"), (".txt", " "))):
            labels = ["time", *clock["columns"]]
            values = [clock["time"]]
            for label, (v, entry) in clock["columns"].items():
                values.append(v * 1e6 if entry["topic"].startswith("/strain/") else v + 273.15 if label == "temperature" else v)
            rows = [sep.join(labels)] + [sep.join(repr(x) for x in row) for row in np.column_stack(values).tolist()]
            files[name] = folder / f"{name}{suffix}"
            files[name].write_text("\n".join(rows) + "\n")
            keys[name] = {"file": files[name].name, "column": "time"}
        doc = _map(rec, clocks, keys)
        for key, entry in doc["columns"].items():
            if entry["topic"].startswith("/strain/"):
                entry["scale"] = 1e-6
            if key == "temperature":
                entry["offset"] = -273.15
        data = list(files.values())
    elif fmt == "npy":
        # one samples × channels array a clock, the time in column 0; columns named by index
        data, keys = [], {}
        for name, clock in clocks.items():
            path = folder / f"{name}.npy"
            np.save(path, np.column_stack([clock["time"], *(v for v, _ in clock["columns"].values())]))
            data.append(path)
            keys[name] = {"file": path.name, "column": "0", "unit": "s"}
        doc = _map(rec, clocks, keys, lambda clock, j, label: (f"{clock}_{j + 1}", {"name": str(j + 1)}))
    elif fmt in ("npz", "mat", "mat73"):
        arrays = {}
        for name, clock in clocks.items():
            arrays[f"t_{name}"] = clock["time"]
            arrays.update({label: v for label, (v, _) in clock["columns"].items()})
        path = folder / ("rec.npz" if fmt == "npz" else "rec.mat")
        if fmt == "npz":
            np.savez(path, **arrays)
        elif fmt == "mat":
            io.savemat(path, arrays)
        else:
            import hdf5storage

            hdf5storage.savemat(str(path), arrays, format="7.3", matlab_compatible=True)
        data = [path]
        doc = _map(rec, clocks, {name: {"column": f"t_{name}"} for name in clocks})
    elif fmt == "hdf5":
        # a group a clock, each with a dataset "time": the leaves collide, so names are paths
        path = folder / "rec.h5"
        with h5py.File(path, "w") as h:
            for name, clock in clocks.items():
                group = h.create_group(name)
                group["time"] = clock["time"]
                for label, (v, _) in clock["columns"].items():
                    group[label] = v
        data = [path]
        doc = _map(rec, clocks, {name: {"column": f"{name}/time"} for name in clocks})
    else:
        raise ValueError(f"{fmt=} is not a format of this exporter")
    map_path = folder / "channels.toml"
    map_path.write_text(tomli_w.dumps(doc))
    return data, map_path
