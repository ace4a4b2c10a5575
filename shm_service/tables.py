"""Measured channels from the files engineers bring: one reader per format, one result type.

``read_table`` gives a :class:`Table` (samples × channels, names, sample rate) from
- text: CSV, TSV, whitespace- or semicolon-separated, with a header row naming the channels,
  including LabVIEW-style exports (preamble lines before the header, a units row and padding
  rows after it); a ``Time``/``time``/``t`` column gives the sample rate;
- NumPy ``.npy`` (1-D or samples × channels; channels named by column index) and ``.npz``;
- MATLAB ``.mat`` (v5 with scipy.io; v7.3 is HDF5) and HDF5 ``.h5``/``.hdf5`` (h5py);
- a contract recording ``.mcap``: its raw IMU accelerations and strains.

Used by ``shm oma`` and meant for ``shm import``: nothing here knows about modal analysis.
Bad input raises :class:`TableError` with a message that names the file, column or value.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Sequence

import numpy as np

__all__ = ["Table", "TableError", "read_table", "select_channels", "TIME_NAMES"]

#: Column names (case-insensitive, units in brackets ignored) that hold the time in s.
TIME_NAMES = ("time", "t", "times", "time_s", "timestamp")
#: Relative scatter of the time steps above which a time column is not a uniform sample clock.
_CLOCK_TOLERANCE = 0.01


class TableError(ValueError):
    """A file that cannot be read as measured channels (the message names what is wrong)."""


@dataclass(frozen=True, eq=False)
class Table:
    """Measured channels.

    data : (N, k) float, one column per channel, in the file's units.
    channels : the k channel names. units : the k units where the file gives them, else None.
    fs_hz : sample rate (Hz), from a time column, the file, or the caller; None if unknown.
    start_s : time of the first sample in the file's time base (s), 0 without one.
    path : the file; format : "text", "labview", "npy", "npz", "mat", "hdf5" or "mcap".
    """

    data: np.ndarray
    channels: tuple[str, ...]
    units: tuple[str, ...] | None
    fs_hz: float | None
    start_s: float
    path: Path
    format: str

    @property
    def duration_s(self) -> float | None:
        return None if self.fs_hz is None else self.data.shape[0] / self.fs_hz


def _is_time(name: str) -> bool:
    base = re.sub(r"[\(\[].*?[\)\]]", "", name).strip().lower()
    return base in TIME_NAMES


def _rate_from_time(t: np.ndarray, where: str) -> tuple[float, float]:
    if t.size < 2:
        raise TableError(f"{where}: the time column has {t.size} value(s); a sample rate needs two")
    dt = np.diff(t)
    step = float(np.median(dt))
    if not np.isfinite(step) or step <= 0:
        raise TableError(f"{where}: the time column does not increase (median step {step!r} s)")
    if np.max(np.abs(dt - step)) > _CLOCK_TOLERANCE * step:
        k = int(np.argmax(np.abs(dt - step)))
        raise TableError(f"{where}: the time column is not a uniform clock (step {dt[k]!r} s at row {k + 1}, median {step!r} s)")
    return 1.0 / step, float(t[0])


def _finish(data: np.ndarray, names: list[str], units: list[str] | None, fs: float | None, path: Path, fmt: str,
            time: np.ndarray | None = None) -> Table:
    where = str(path)
    start = 0.0
    if time is not None:
        rate, start = _rate_from_time(time, where)
        if fs is not None and abs(rate / fs - 1) > _CLOCK_TOLERANCE:
            raise TableError(f"{where}: --fs {fs} Hz disagrees with the time column's {rate:.6g} Hz")
        fs = rate if fs is None else fs
    if fs is not None and (not np.isfinite(fs) or fs <= 0):
        raise TableError(f"{fs=} must be a positive finite sample rate in Hz")
    for j, name in enumerate(names):
        col = data[:, j]
        bad = np.flatnonzero(~np.isfinite(col))
        if bad.size:
            raise TableError(f"{where}: channel {name!r} has {bad.size} NaN or infinite value(s), the first at sample {int(bad[0])}")
    seen = set()
    for name in names:
        if name in seen:
            raise TableError(f"{where}: channel name {name!r} appears twice")
        seen.add(name)
    return Table(np.ascontiguousarray(data, dtype=float), tuple(names), None if units is None else tuple(units), fs, start, path, fmt)


# -- text ------------------------------------------------------------------------------------
_NUM = re.compile(r"^[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?$|^[+-]?(nan|inf|infinity)$", re.IGNORECASE)


def _split(line: str, delim: str | None) -> list[str]:
    return [f.strip() for f in (line.split() if delim is None else line.split(delim))]


def _numeric(fields: list[str]) -> bool:
    return bool(fields) and all(_NUM.match(f) for f in fields)


def _delimiter(lines: list[str]) -> str | None:
    sample = [ln for ln in lines[-50:] if ln.strip()]
    for d in ("\t", ",", ";"):
        counts = {ln.count(d) for ln in sample}
        if len(counts) == 1 and counts.pop() > 0:
            return d
    return None


def _read_text(path: Path, fs: float | None) -> Table:
    where = str(path)
    text = path.read_text(errors="replace")
    lines = text.splitlines()
    if not any(ln.strip() for ln in lines):
        raise TableError(f"{where}: the file is empty")
    delim = _delimiter(lines)
    # the data block: the trailing run of numeric rows with one field count
    end = len(lines)
    while end > 0 and not lines[end - 1].strip():
        end -= 1
    k = None
    start = end
    while start > 0:
        ln = lines[start - 1]
        if not ln.strip():
            break
        fields = _split(ln, delim)
        if delim is not None and fields and fields[-1] == "" and k is not None and len(fields) == k + 1:
            fields = fields[:-1]  # a trailing delimiter
        if not _numeric(fields) or (k is not None and len(fields) != k):
            break
        k = len(fields)
        start -= 1
    if k is None or end - start < 2:
        raise TableError(f"{where}: found no block of numeric rows with the same number of columns at the end of the file")
    # the header: the first line above the data with k fields, not all numeric, every field named
    header_at = units_at = None
    for j in range(start):
        fields = _split(lines[j], delim)
        if len(fields) == k and not _numeric(fields) and any(fields):
            header_at = j
            break
    if header_at is None:
        raise TableError(f"{where}: no header row names the {k} columns (a row of {k} names above the data)")
    names = _split(lines[header_at], delim)
    empty = [i for i, n in enumerate(names) if not n]
    if empty:
        raise TableError(f"{where}: the header row (line {header_at + 1}) leaves column(s) {empty} without a name")
    if _numeric(names) or all(_NUM.match(n) for n in names if n):
        raise TableError(f"{where}: the header row (line {header_at + 1}) holds numbers, not channel names")
    for j in range(header_at + 1, start):
        fields = _split(lines[j], delim)
        if len(fields) == k and not _numeric(fields) and all(fields):
            units_at = j
            break
    rows = lines[start:end]
    try:
        data = np.array([_split(r, delim)[:k] for r in rows], dtype=float)
    except ValueError as exc:
        raise TableError(f"{where}: a data row is not numeric ({exc})") from None
    fmt = "labview" if header_at > 0 and units_at is not None else "text"
    units = _split(lines[units_at], delim) if units_at is not None else None
    tcols = [i for i, n in enumerate(names) if _is_time(n)]
    time = data[:, tcols[0]] if tcols else None
    if time is None and fs is None:
        raise TableError(f"{where}: no time column ({'/'.join(('Time', 'time', 't'))}) gives the sample rate: give --fs (the sample rate in Hz)")
    keep = [i for i in range(k) if i not in tcols]
    if not keep:
        raise TableError(f"{where}: the file holds only a time column")
    return _finish(data[:, keep], [names[i] for i in keep], None if units is None else [units[i] for i in keep], fs, path, fmt, time)


# -- arrays ----------------------------------------------------------------------------------
def _from_arrays(arrays: dict[str, np.ndarray], fs: float | None, path: Path, fmt: str) -> Table:
    where = str(path)
    scalars = {k.lower(): v for k, v in arrays.items() if np.ndim(v) == 0 or np.size(v) == 1}
    for key in ("fs", "fs_hz", "sample_rate", "samplerate", "sampling_frequency", "rate"):
        if key in scalars and fs is None:
            fs = float(np.asarray(scalars[key]).ravel()[0])
    # MATLAB keeps vectors as 1 × N or N × 1 matrices
    series = {k: (np.asarray(v).ravel() if 1 in np.shape(v) else np.asarray(v)) for k, v in arrays.items()
              if np.ndim(v) >= 1 and np.size(v) > 1 and np.issubdtype(np.asarray(v).dtype, np.number)}
    time = None
    for k in list(series):
        if _is_time(k) and series[k].ndim == 1:
            time = series.pop(k).astype(float)
            break
    two_d = {k: v for k, v in series.items() if v.ndim == 2}
    if len(two_d) == 1 and all(v.ndim == 2 for v in series.values()):
        (key, a), = two_d.items()
        if a.shape[0] < a.shape[1]:
            raise TableError(f"{where}: array {key!r} has shape {a.shape}; expected samples × channels (more rows than columns)")
        names = [str(j) for j in range(a.shape[1])]
        data = a.astype(float)
    else:
        ones = {k: v.ravel() for k, v in series.items() if v.ndim == 1 or 1 in v.shape}
        if not ones:
            raise TableError(f"{where}: holds no numeric channel arrays (found {sorted(arrays)})")
        lengths = {k: v.size for k, v in ones.items()}
        if len(set(lengths.values())) != 1:
            raise TableError(f"{where}: channel arrays differ in length {lengths}")
        names = list(ones)
        data = np.column_stack([ones[k].astype(float) for k in names])
    if time is not None and time.size != data.shape[0]:
        raise TableError(f"{where}: the time array has {time.size} samples, the channels {data.shape[0]}")
    if time is None and fs is None:
        raise TableError(f"{where}: no sample rate in the file (a 'fs' value or a time array): give --fs (the sample rate in Hz), fs=None")
    return _finish(data, names, None, fs, path, fmt, time)


def _read_npy(path: Path, fs: float | None) -> Table:
    a = np.load(path, allow_pickle=False)
    if not np.issubdtype(a.dtype, np.number):
        raise TableError(f"{path}: array of dtype {a.dtype} is not numeric")
    if a.ndim == 1:
        if fs is None:
            raise TableError(f"{path}: a 1-D array of {a.size} samples needs its sample rate: give --fs (fs=None)")
        a = a[:, None]
    elif a.ndim != 2:
        raise TableError(f"{path}: array of shape {a.shape} must be 1-D or 2-D (samples × channels)")
    if fs is None:
        raise TableError(f"{path}: a .npy array carries no sample rate: give --fs (fs=None)")
    if a.shape[0] < a.shape[1]:
        raise TableError(f"{path}: array of shape {a.shape} has more columns than rows; expected samples × channels")
    return _finish(a.astype(float), [str(j) for j in range(a.shape[1])], None, fs, path, "npy")


def _read_npz(path: Path, fs: float | None) -> Table:
    with np.load(path, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    return _from_arrays(arrays, fs, path, "npz")


def _read_hdf5(path: Path, fs: float | None, fmt: str = "hdf5") -> Table:
    try:
        import h5py
    except ImportError:
        raise TableError(f"{path}: reading HDF5 (and MATLAB v7.3) needs h5py: pip install h5py") from None
    arrays: dict[str, np.ndarray] = {}
    with h5py.File(path, "r") as h:
        def visit(name, obj):
            if isinstance(obj, h5py.Dataset) and np.issubdtype(obj.dtype, np.number):
                a = np.asarray(obj[()])
                # MATLAB v7.3 stores arrays transposed (column-major)
                arrays[name.split("/")[-1]] = a.T if fmt == "mat" and a.ndim == 2 else a
        h.visititems(visit)
        for k, v in h.attrs.items():
            if np.ndim(v) == 0 and np.issubdtype(np.asarray(v).dtype, np.number):
                arrays.setdefault(k, np.asarray(v))
    return _from_arrays(arrays, fs, path, fmt)


def _read_mat(path: Path, fs: float | None) -> Table:
    from scipy import io

    try:
        raw = io.loadmat(path, squeeze_me=False)
    except NotImplementedError:  # v7.3: HDF5
        return _read_hdf5(path, fs, "mat")
    except ValueError as exc:
        raise TableError(f"{path}: not a MATLAB file scipy can read ({exc})") from None
    arrays = {k: v for k, v in raw.items() if not k.startswith("__") and isinstance(v, np.ndarray) and np.issubdtype(v.dtype, np.number)}
    return _from_arrays(arrays, fs, path, "mat")


def _read_mcap(path: Path, fs: float | None) -> Table:
    from .recording import read_recording

    rec = read_recording(path)
    chans = []
    for topic in sorted(rec.channels):
        c = rec.channels[topic]
        if c.kind == "imu":
            for axis, j in (("x", 0), ("y", 1), ("z", 2)):
                chans.append((f"{c.name}.accel_{axis}", "m/s^2", c, j))
        elif c.kind == "strain":
            chans.append((f"{c.name}.strain", "m/m", c, 0))
    if not chans:
        raise TableError(f"{path}: the recording has no IMU or strain channel")
    # one uniform clock: the median step of the first channel, over the span all channels cover
    t0 = max(int(c.log_time_ns[0]) for _, _, c, _ in chans if len(c))
    t1 = min(int(c.log_time_ns[-1]) for _, _, c, _ in chans if len(c))
    step = float(np.median(np.diff(chans[0][2].log_time_ns)))
    rate = 1e9 / step if fs is None else fs
    n = int(np.floor((t1 - t0) / 1e9 * rate)) + 1
    if n < 2:
        raise TableError(f"{path}: the channels share no common time span")
    grid = t0 + np.arange(n) * (1e9 / rate)
    data = np.column_stack([np.interp(grid, c.log_time_ns.astype(float), c.values[:, j]) for _, _, c, j in chans])
    table = _finish(data, [n_ for n_, *_ in chans], [u for _, u, *_ in chans], rate, path, "mcap")
    return replace(table, start_s=(t0 - rec.start_ns) / 1e9)


_READERS = {
    ".npy": _read_npy, ".npz": _read_npz, ".mat": _read_mat, ".h5": _read_hdf5, ".hdf5": _read_hdf5, ".mcap": _read_mcap,
}
_TEXT = (".csv", ".tsv", ".txt", ".dat", ".lvm", ".asc")


def read_table(path: str | Path, *, fs: float | None = None) -> Table:
    """Read measured channels from ``path`` (format from the suffix; see the module docstring).

    Parameters
    ----------
    path : str or Path
    fs : float, optional
        Sample rate (Hz); required where the file has none (.npy, text without a time column).

    Returns
    -------
    Table

    Raises
    ------
    TableError
        For an unknown suffix, a file without a header naming its columns, a missing sample
        rate, a non-uniform time column, NaN in a channel, or a malformed file.
    FileNotFoundError
        If the file does not exist.
    """
    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(f"{p}: no such file")
    if fs is not None and (isinstance(fs, bool) or not np.isfinite(fs) or fs <= 0):
        raise TableError(f"{fs=} must be a positive finite sample rate in Hz")
    suffix = p.suffix.lower()
    if suffix in _READERS:
        return _READERS[suffix](p, fs)
    if suffix in _TEXT:
        return _read_text(p, fs)
    raise TableError(f"{p}: unknown format {suffix!r} (known: {', '.join(sorted((*_READERS, *_TEXT)))})")


def select_channels(table: Table, channels: Sequence[str] | None) -> Table:
    """The table restricted to ``channels`` (names, or column indices as text), in that order.

    Raises
    ------
    TableError
        For a name that is not a channel of the table (the message lists the channels).
    """
    if not channels:
        return table
    idx = []
    for name in channels:
        if name in table.channels:
            idx.append(table.channels.index(name))
        elif name.isdigit() and int(name) < len(table.channels):
            idx.append(int(name))
        else:
            raise TableError(f"{table.path}: unknown channel {name!r}; the file has {list(table.channels)}")
    return replace(table, data=table.data[:, idx], channels=tuple(table.channels[i] for i in idx),
                   units=None if table.units is None else tuple(table.units[i] for i in idx))
