"""Measured channels from the files engineers bring: one reader per format, one result type.

``read_table`` gives a :class:`Table` (samples × channels, names, sample rate) from
- text: CSV, TSV, whitespace- or semicolon-separated, with a header row naming the channels,
  including LabVIEW-style exports (preamble lines before the header, a units row and padding
  rows after it); a ``Time``/``time``/``t`` column gives the sample rate;
- NumPy ``.npy`` (1-D or samples × channels; channels named by column index) and ``.npz``;
- MATLAB ``.mat`` (v5 with scipy.io; v7.3 is HDF5) and HDF5 ``.h5``/``.hdf5`` (h5py);
- a contract recording ``.mcap``: its raw IMU accelerations and strains.

Used by ``shm oma`` and ``shm import``: nothing here knows about modal analysis or the contract's
topics. ``read_table`` can read a subset of the channels (``channels``), take the time from a named
column (``time_column``, in ``time_unit``) and keep NaN/infinite values for the caller to count
(``nonfinite="keep"``); arrays of other lengths in the same file (another clock) are then ignored.
Bad input raises :class:`TableError` with a message that names the file, column or value.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Sequence

import numpy as np

from .rejections import REASONS, Rejections

__all__ = ["Table", "TableError", "read_table", "select_channels", "TIME_NAMES", "TIME_UNITS"]

#: Column names (case-insensitive, units in brackets ignored) that hold the time in s.
TIME_NAMES = ("time", "t", "times", "time_s", "timestamp")
#: Units a time column may be in, with their length in s.
TIME_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9}
#: Relative scatter of the time steps above which a time column is not a uniform sample clock.
_CLOCK_TOLERANCE = 0.01


class TableError(ValueError):
    """A file that cannot be read as measured channels (the message names what is wrong).

    ``channel`` is the asked-for channel that the file lacks, when that is the problem."""

    def __init__(self, message: str, *, channel: str | None = None) -> None:
        super().__init__(message)
        self.channel = channel




@dataclass(frozen=True, eq=False)
class Table:
    """Measured channels.

    data : (N, k) float, one column per channel, in the file's units.
    channels : the k channel names. units : the k units where the file gives them, else None.
    fs_hz : sample rate (Hz), from a time column, the file, or the caller; None if unknown.
    start_s : time of the first sample in the file's time base (s), 0 without one.
    path : the file; format : "text", "labview", "npy", "npz", "mat", "hdf5" or "mcap".
    time : (N,) the time column's values in s where the file has one (checked to be a uniform
        clock), else None.
    other_channels : the file's channels that were not asked for (``read_table(channels=...)``).
    rejections : the samples rejected per channel and reason (blank, unparsable, nonfinite,
        truncated, time); a rejected sample is NaN in ``data`` (and in ``time`` for ``time``).
    problems : what a recording's reader reported (a cut, gaps), for ``.mcap``.
    codes : (N, k) int8, each value's reason of rejection (0: kept, else ``REASONS[code - 1]``).
    """

    data: np.ndarray
    channels: tuple[str, ...]
    units: tuple[str, ...] | None
    fs_hz: float | None
    start_s: float
    path: Path
    format: str
    time: np.ndarray | None = None
    other_channels: tuple[str, ...] = ()
    rejections: Rejections = field(default_factory=Rejections)
    problems: tuple[str, ...] = ()
    codes: np.ndarray | None = None

    @property
    def duration_s(self) -> float | None:
        return None if self.fs_hz is None else self.data.shape[0] / self.fs_hz


@dataclass(frozen=True)
class _Options:
    """What the caller asked of ``read_table`` (see there)."""

    fs: float | None = None
    channels: tuple[str, ...] | None = None
    time_column: str | None = None
    time_scale: float = 1.0
    keep_nonfinite: bool = False


def _is_time(name: str) -> bool:
    base = re.sub(r"[\(\[].*?[\)\]]", "", name).strip().lower()
    return base in TIME_NAMES


def _rate_from_time(t: np.ndarray, where: str, name: str | None = None) -> tuple[float, float, np.ndarray]:
    """Sample rate, first time and the rows whose stamp is off the clock, of a time column whose
    rejected rows are NaN.

    A step between two valid rows may span the rows rejected between them (a missing or repeated
    stamp): ``j`` steps with ``1 <= j <=`` the rows' distance. Stamps off the clock between rows
    that are on it (the clock comes back: the stamps were wrong, not the samples' times) cost
    their rows, returned for a ``time`` rejection. A clock that does not come back is a jump
    (samples missing without rows) and refused, naming the rows."""
    column = "the time column" if name is None else f"the time column {name!r}"
    rows = np.flatnonzero(np.isfinite(t))
    if rows.size < 2:
        raise TableError(f"{where}: {column} has {rows.size} valid value(s); a sample rate needs two")
    tv = t[rows]
    dt = np.diff(tv)
    span = np.diff(rows)
    single = dt[span == 1]
    step = float(np.median(single if single.size else dt / span))
    if not np.isfinite(step) or step <= 0:
        raise TableError(f"{where}: {column} does not increase (median step {step!r} s)")
    multiple = np.rint(dt / step)
    bad = (np.abs(dt - multiple * step) > _CLOCK_TOLERANCE * step) | (multiple < 1) | (multiple > span)
    off = np.zeros(t.size, bool)
    if bad.any():
        keep = _on_the_clock(rows, tv, step)
        if isinstance(keep, tuple):
            a, b = keep
            raise TableError(f"{where}: {column} is not a uniform clock (step {float(tv[b] - tv[a])!r} s from sample {int(rows[a])} to "
                             f"{int(rows[b])}, median {step!r} s)")
        off[rows[~keep]] = True
        tv = tv[keep]
    return 1.0 / step, float(tv[0]), off


#: Valid rows looked ahead for the clock to come back after an off-grid stamp.
_CLOCK_LOOKAHEAD = 64


def _on_the_clock(rows: np.ndarray, tv: np.ndarray, step: float) -> np.ndarray | tuple[int, int]:
    """Which valid rows (stamps ``tv`` at ``rows``) to keep so every step between kept rows is
    consistent: the fewest rows dropped, each between kept rows (the first and the last valid
    row are never dropped: there a wrong stamp and a jump of the clock look alike). Returns the
    keep mask, or the (indices into ``rows`` of the) step where the clock jumps and does not come back."""

    def fits(a: int, b: int) -> bool:
        d = tv[b] - tv[a]
        m = round(d / step)
        return abs(d - m * step) <= _CLOCK_TOLERANCE * step and 1 <= m <= rows[b] - rows[a]

    n = rows.size
    keep = np.ones(n, bool)
    kept = [0]  # indices into rows of the kept rows so far
    j = 1
    while j < n:
        p = kept[-1]
        if fits(p, j):
            kept.append(j)
            j += 1
            continue
        # the last kept row's stamp was the wrong one: its predecessor and j agree (and j goes on)
        if len(kept) >= 2 and fits(kept[-2], j) and (j + 1 >= n or fits(j, j + 1)):
            keep[kept.pop()] = False
            continue
        # rows j … q-1 off the clock, which comes back at q (never past the last valid row)
        q = next((q for q in range(j + 1, min(n, j + 1 + _CLOCK_LOOKAHEAD)) if fits(p, q) and (q + 1 >= n or fits(q, q + 1))), None)
        if q is None:
            return int(p), int(j)
        keep[j:q] = False
        kept.append(q)
        j = q + 1
    return keep


def _reject_time_rows(time: np.ndarray, codes: np.ndarray) -> np.ndarray:
    """Mark rows whose time is not a number, repeated or earlier than a previous valid row's as
    ``time`` rejections of every channel; returns the time with those rows NaN."""
    time = np.array(time, dtype=float, copy=True)
    bad = ~np.isfinite(time)
    valid = np.flatnonzero(~bad)
    if valid.size:
        tv = time[valid]
        previous = np.maximum.accumulate(np.concatenate([[-np.inf], tv[:-1]]))
        bad[valid[tv <= previous]] = True
    time[bad] = np.nan
    codes[bad, :] = _CODE["time"]
    return time


#: Reason codes of a cell (0: kept; ``REASONS[code - 1]``).
_CODE = {reason: k + 1 for k, reason in enumerate(REASONS)}
_REASON = {v: k for k, v in _CODE.items()}


def _select(names: list[str], wanted: Sequence[str] | None, where: str, time_name: str | None = None) -> list[int]:
    """Indices of ``wanted`` in ``names`` (all when ``wanted`` is None)."""
    if wanted is None:
        return list(range(len(names)))
    idx = []
    for name in wanted:
        if name in names:
            idx.append(names.index(name))
        elif time_name is not None and name == time_name:
            raise TableError(f"{where}: column {name!r} is the time column, not a channel")
        else:
            raise TableError(f"{where}: unknown channel {name!r}; the file has {names}", channel=name)
    return idx


def _finish(data: np.ndarray, names: list[str], units: list[str] | None, opts: _Options, path: Path, fmt: str,
            time: np.ndarray | None = None, time_name: str | None = None, other_channels: Sequence[str] = (),
            codes: np.ndarray | None = None, line_of: np.ndarray | None = None) -> Table:
    """The table of the asked-for channels, its rejections counted. ``codes`` (N, k) gives each
    cell's reason code (0 kept, ``_CODE``) where the reader knows one (text); NaN/∞ values and
    rows without a valid time are added here."""
    where = str(path)
    fs = opts.fs
    start = 0.0
    seen = set()
    for name in names:
        if name in seen:
            raise TableError(f"{where}: channel name {name!r} appears twice")
        seen.add(name)
    keep = _select(names, opts.channels, where, time_name)
    others = tuple(other_channels) + tuple(n for i, n in enumerate(names) if i not in keep)
    data, names = np.array(data[:, keep], dtype=float), [names[i] for i in keep]
    codes = np.zeros(data.shape, dtype=np.int8) if codes is None else np.array(codes[:, keep], dtype=np.int8)
    units = None if units is None else [units[i] for i in keep]
    if time is not None:
        time = _reject_time_rows(np.asarray(time, dtype=float) * opts.time_scale, codes)
        rate, start, off = _rate_from_time(time, where, time_name)
        time[off] = np.nan
        codes[off, :] = _CODE["time"]
        if fs is not None and abs(rate / fs - 1) > _CLOCK_TOLERANCE:
            raise TableError(f"{where}: the given sample rate {fs} Hz disagrees with the time column's {rate:.6g} Hz")
        fs = rate if fs is None else fs
    if fs is not None and (not np.isfinite(fs) or fs <= 0):
        raise TableError(f"{fs=} must be a positive finite sample rate in Hz")
    codes[(codes == 0) & ~np.isfinite(data)] = _CODE["nonfinite"]
    data[codes != 0] = np.nan
    rejections = Rejections()
    rejections.line_of = line_of
    for j, name in enumerate(names):
        for code in np.unique(codes[:, j]).tolist():
            if code:
                rejections.add(name, _REASON[code], np.flatnonzero(codes[:, j] == code))
    if not opts.keep_nonfinite and rejections.total:
        name = rejections.channels()[0]
        first = rejections.as_dict()["channels"][name]["first"][0]
        raise TableError(f"{where}: channel {name!r} has {rejections.of(name)} rejected value(s) (NaN, infinite, blank or "
                         f"not a number), the first at sample {first['sample']} ({first['reason']})")
    return Table(np.ascontiguousarray(data, dtype=float), tuple(names), None if units is None else tuple(units), fs, start,
                 path, fmt, None if time is None else np.ascontiguousarray(time), others, rejections, (), codes)


# -- text ------------------------------------------------------------------------------------
_NUM = re.compile(r"^[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?$|^[+-]?(nan|inf|infinity)$", re.IGNORECASE)


def _split(line: str, delim: str | None) -> list[str]:
    return [f.strip() for f in (line.split() if delim is None else line.split(delim))]


def _numeric(fields: list[str]) -> bool:
    return bool(fields) and all(_NUM.match(f) for f in fields)


def _delimiter(lines: list[str]) -> str | None:
    """The separator that appears equally often in at least 90 % of the last 50 non-empty lines
    (a last line cut short differs); ';' before ',' (decimal commas with ';' separators)."""
    sample = [ln for ln in lines[-50:] if ln.strip()]
    for d in ("\t", ";", ","):
        counts = np.bincount([ln.count(d) for ln in sample])
        mode = int(np.argmax(counts))
        if mode > 0 and counts[mode] >= 0.9 * len(sample):
            return d
    return None


_DECIMAL_COMMA = re.compile(r"^[+-]?\d+,\d+([eE][+-]?\d+)?$")


def _field_count(lines: list[str], delim: str | None) -> int:
    """The field count of most of the last 200 non-empty lines (the data rows')."""
    sample = [len(_split(ln, delim)) for ln in lines[-200:] if ln.strip()]
    counts = np.bincount(sample)
    return int(np.argmax(counts))


def _numeric_share(fields: list[str]) -> float:
    return sum(1 for f in fields if f and _NUM.match(f)) / max(len(fields), 1)


def _parse_rows(rows: list[list[str]], k: int) -> tuple[np.ndarray, np.ndarray]:
    """Values (N, k) and reason codes of the data rows, cell by cell where a row does not parse whole."""
    try:
        if all(len(r) == k for r in rows):
            data = np.array(rows, dtype=float)
            return data, np.zeros(data.shape, dtype=np.int8)
    except ValueError:
        pass
    data = np.full((len(rows), k), np.nan)
    codes = np.zeros((len(rows), k), dtype=np.int8)
    for i, r in enumerate(rows):
        if len(r) == k:
            try:
                data[i] = np.array(r, dtype=float)
                continue
            except ValueError:
                pass
        if len(r) > k:
            codes[i] = _CODE["unparsable"]
            continue
        for j in range(k):
            if j >= len(r):
                codes[i, j] = _CODE["truncated"]
                continue
            cell = r[j]
            if not cell:
                codes[i, j] = _CODE["blank"]
            elif _NUM.match(cell):
                data[i, j] = float(cell)
            else:
                codes[i, j] = _CODE["unparsable"]
    return data, codes


def _refuse_comma_decimals(lines: list[str], where: str) -> None:
    """A comma-separated file whose numbers use decimal commas: each data row has twice the
    header's fields (every value split in two). Refused with that said."""
    filled = [ln for ln in lines if ln.strip()]
    if len(filled) < 2:
        return
    header = filled[0].count(",") + 1
    counts = np.bincount([ln.count(",") + 1 for ln in filled[-50:]])
    data = int(np.argmax(counts))
    if header > 1 and data == 2 * header and not _numeric(_split(filled[0], ",")):
        raise TableError(f"{where}: the numbers seem to use decimal commas in a comma-separated file (the header names "
                         f"{header} columns, the rows hold {data} fields): separate the columns with ';' or tabs, or write "
                         "decimal points")


def _read_text(path: Path, opts: _Options) -> Table:
    """A header row naming k columns (above it a preamble, below it a units row and padding), then
    the data rows. Every row after the first data row is a sample: a blank, non-numeric or missing
    cell (a row cut short) is rejected in its column only; a row of no numbers at all (a repeated
    header) in every column. Decimal commas are read where the separator is not a comma."""
    where = str(path)
    text = path.read_text(errors="replace")
    lines = text.splitlines()
    if not any(ln.strip() for ln in lines):
        raise TableError(f"{where}: the file is empty")
    delim = _delimiter(lines)
    _refuse_comma_decimals(lines, where)
    decimal_comma = False
    if delim != ",":
        sample = [f for ln in lines[-50:] for f in _split(ln, delim)]
        if any(_DECIMAL_COMMA.match(f) for f in sample) and not any(re.match(r"^[+-]?\d+\.\d+", f) for f in sample):
            decimal_comma = True
            lines = [ln.replace(",", ".") for ln in lines]
    k = _field_count(lines, delim)
    split = [_split(ln, delim) for ln in lines]
    for fields in split:  # a trailing delimiter
        if delim is not None and len(fields) == k + 1 and fields[-1] == "":
            fields.pop()
    # the header: the first row of k fields, every one a name (no number)
    header_at = next((j for j, f in enumerate(split) if len(f) == k and any(f) and _numeric_share(f) == 0), None)
    if header_at is None:
        numeric = sum(1 for f in split if f and _numeric_share(f) > 0.5)
        if numeric and delim == "," and any(_DECIMAL_COMMA.match(c) for f in split for c in f if c):
            raise TableError(f"{where}: the numbers seem to use decimal commas in a comma-separated file: separate the "
                             "columns with ';' or tabs, or write decimal points")
        raise TableError(f"{where}: no header row names the {k} columns (a row of {k} names above the data; "
                         f"{numeric} data row(s) found)")
    names = split[header_at]
    empty = [i for i, n in enumerate(names) if not n]
    if empty:
        raise TableError(f"{where}: the header row (line {header_at + 1}) leaves column(s) {empty} without a name")
    if all(_NUM.match(n) for n in names if n):
        raise TableError(f"{where}: the header row (line {header_at + 1}) holds numbers, not channel names")
    # the first data row: mostly numbers; before it a units row (k names) and padding
    first = next((j for j in range(header_at + 1, len(split)) if split[j] and _numeric_share(split[j]) >= 0.5
                  and len(split[j]) <= k), None)
    if first is None:
        raise TableError(f"{where}: no data row below the header row (line {header_at + 1})")
    units_at = next((j for j in range(header_at + 1, first) if len(split[j]) == k and all(split[j])), None)
    rows_at = [j for j in range(first, len(split)) if lines[j].strip()]
    data, codes = _parse_rows([split[j] for j in rows_at], k)
    line_of = np.asarray(rows_at, dtype=np.int64) + 1
    fmt = "labview" if header_at > 0 and units_at is not None else "text"
    units = split[units_at] if units_at is not None else None
    tcols = _time_columns(names, opts, where)
    time = None
    if tcols:
        time = data[:, tcols[0]].copy()
        time[codes[:, tcols[0]] != 0] = np.nan
    if time is None and opts.fs is None:
        raise TableError(f"{where}: no time column ({'/'.join(('Time', 'time', 't'))}) gives the sample rate: give --fs (the sample rate in Hz)")
    if data.shape[0] < 2:
        raise TableError(f"{where}: {data.shape[0]} data row(s): a record needs at least two samples")
    keep = [i for i in range(k) if i not in tcols]
    if not keep:
        raise TableError(f"{where}: the file holds only a time column")
    table = _finish(data[:, keep], [names[i] for i in keep], None if units is None else [units[i] for i in keep], opts, path, fmt,
                    time, names[tcols[0]] if tcols else None, codes=codes[:, keep], line_of=line_of)
    return replace(table, problems=("decimal commas read as decimal points",)) if decimal_comma else table


def _time_columns(names: Sequence[str], opts: _Options, where: str) -> list[int]:
    """The time column: the one the caller names, else every column with a time name that the
    caller did not ask for as a channel (a temperature ``T``)."""
    if opts.time_column is None:
        return [i for i, n in enumerate(names) if _is_time(n) and n not in (opts.channels or ())]
    if opts.time_column not in names:
        raise TableError(f"{where}: no time column {opts.time_column!r}; the file has {list(names)}", channel=opts.time_column)
    return [list(names).index(opts.time_column)]


# -- arrays ----------------------------------------------------------------------------------
def _leaf_names(paths: Sequence[str]) -> list[str]:
    """Each array by its last path component where that is unique in the file, else by its
    whole path (``fast/time`` and ``slow/time``)."""
    leaves = [p.rsplit("/", 1)[-1] for p in paths]
    return [leaf if leaves.count(leaf) == 1 else p for p, leaf in zip(paths, leaves)]


def _from_arrays(arrays: dict[str, np.ndarray], opts: _Options, path: Path, fmt: str) -> Table:
    where = str(path)
    fs = opts.fs
    scalars = {k.lower(): v for k, v in arrays.items() if np.ndim(v) == 0 or np.size(v) == 1}
    for key in ("fs", "fs_hz", "sample_rate", "samplerate", "sampling_frequency", "rate"):
        if key in scalars and fs is None:
            fs = float(np.asarray(scalars[key]).ravel()[0])
    # MATLAB keeps vectors as 1 × N or N × 1 matrices
    series = {k: (np.asarray(v).ravel() if 1 in np.shape(v) else np.asarray(v)) for k, v in arrays.items()
              if np.ndim(v) >= 1 and np.size(v) > 1 and np.issubdtype(np.asarray(v).dtype, np.number)}
    time = time_name = None
    if opts.time_column is not None:
        if opts.time_column not in series:
            raise TableError(f"{where}: no time array {opts.time_column!r}; the file has {sorted(series)}", channel=opts.time_column)
        time_name = opts.time_column
        time = series.pop(time_name)
        if time.ndim != 1:
            raise TableError(f"{where}: the time array {time_name!r} has shape {time.shape}; expected a vector")
    else:
        for k in list(series):
            if _is_time(k) and series[k].ndim == 1 and k not in (opts.channels or ()):
                time_name, time = k, series.pop(k)
                break
    two_d = {k: v for k, v in series.items() if v.ndim == 2}
    if len(two_d) == 1 and all(v.ndim == 2 for v in series.values()):
        (key, a), = two_d.items()
        if a.shape[0] < a.shape[1]:
            raise TableError(f"{where}: array {key!r} has shape {a.shape}; expected samples × channels (more rows than columns)")
        names = [str(j) for j in range(a.shape[1])]
        data = a.astype(float)
        others = []
    else:
        ones = {k: v.ravel() for k, v in series.items() if v.ndim == 1 or 1 in v.shape}
        others = [k for k in series if opts.channels is not None and k not in opts.channels]
        if opts.channels is not None:
            # only the asked-for arrays: the file may hold other clocks' arrays of other lengths
            for name in opts.channels:
                if name not in ones:
                    what = f"array {name!r} has shape {series[name].shape}, not a vector" if name in series else f"unknown channel {name!r}"
                    raise TableError(f"{where}: {what}; the file has the vectors {sorted(ones)}", channel=name)
            ones = {name: ones[name] for name in opts.channels}
        if not ones:
            shapes = {k: tuple(v.shape) for k, v in series.items()}
            if shapes:
                raise TableError(f"{where}: holds no channel vectors: its numeric arrays {shapes} are not vectors; give one "
                                 "samples × channels array, or one vector per channel")
            raise TableError(f"{where}: holds no numeric channel arrays (found {sorted(arrays)})")
        lengths = {k: v.size for k, v in ones.items()}
        if len(set(lengths.values())) != 1:
            raise TableError(f"{where}: channel arrays differ in length {lengths}")
        names = list(ones)
        data = np.column_stack([ones[k].astype(float) for k in names])
    if time is not None and time.size != data.shape[0]:
        raise TableError(f"{where}: the time array {time_name!r} has {time.size} samples, the channels {data.shape[0]}")
    if time is None and fs is None:
        raise TableError(f"{where}: no sample rate in the file (a 'fs' value or a time array): give --fs (the sample rate in Hz), fs=None")
    return _finish(data, names, None, replace(opts, fs=fs), path, fmt, time, time_name, others)


def _read_npy(path: Path, opts: _Options) -> Table:
    a = np.load(path, allow_pickle=False)
    if not np.issubdtype(a.dtype, np.number):
        raise TableError(f"{path}: array of dtype {a.dtype} is not numeric")
    if a.ndim == 1:
        if opts.fs is None:
            raise TableError(f"{path}: a 1-D array of {a.size} samples needs its sample rate: give --fs (fs=None)")
        a = a[:, None]
    elif a.ndim != 2:
        raise TableError(f"{path}: array of shape {a.shape} must be 1-D or 2-D (samples × channels)")
    if a.shape[0] < a.shape[1]:
        raise TableError(f"{path}: array of shape {a.shape} has more columns than rows; expected samples × channels")
    names = [str(j) for j in range(a.shape[1])]
    tcols = _time_columns(names, opts, str(path)) if opts.time_column is not None else []
    if not tcols and opts.fs is None:
        raise TableError(f"{path}: a .npy array carries no sample rate: give --fs (fs=None)")
    keep = [j for j in range(a.shape[1]) if j not in tcols]
    time = a[:, tcols[0]] if tcols else None
    return _finish(a[:, keep].astype(float), [names[j] for j in keep], None, opts, path, "npy", time,
                   names[tcols[0]] if tcols else None)


def _read_npz(path: Path, opts: _Options) -> Table:
    with np.load(path, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    return _from_arrays(arrays, opts, path, "npz")


def _read_hdf5(path: Path, opts: _Options, fmt: str = "hdf5") -> Table:
    try:
        import h5py
    except ImportError:
        raise TableError(f"{path}: reading HDF5 (and MATLAB v7.3) needs h5py: pip install h5py") from None
    found: dict[str, np.ndarray] = {}
    try:
        h = h5py.File(path, "r")
    except OSError as exc:
        raise TableError(f"{path}: not an HDF5 file h5py can read ({exc})") from None
    with h:
        def visit(name, obj):
            if not isinstance(obj, h5py.Dataset) or not np.issubdtype(obj.dtype, np.number):
                return
            if fmt == "mat" and (name.startswith("#") or obj.attrs.get("MATLAB_class", b"double") in (b"char", b"logical")):
                return  # MATLAB's references and its text and logical arrays are not channels
            a = np.asarray(obj[()])
            # MATLAB v7.3 stores arrays transposed (column-major)
            found[name] = a.T if fmt == "mat" and a.ndim == 2 else a
        h.visititems(visit)
        arrays = dict(zip(_leaf_names(list(found)), found.values()))
        for k, v in h.attrs.items():
            if np.ndim(v) == 0 and np.issubdtype(np.asarray(v).dtype, np.number):
                arrays.setdefault(k, np.asarray(v))
    return _from_arrays(arrays, opts, path, fmt)


def _mat_arrays(raw: dict, prefix: str = "") -> dict[str, np.ndarray]:
    """The numeric arrays of a loaded v5 file, the fields of 1 × 1 structs as ``struct/field``."""
    out: dict[str, np.ndarray] = {}
    for k, v in raw.items():
        if k.startswith("__") or not isinstance(v, np.ndarray):
            continue
        if v.dtype.names and v.size == 1:
            out.update(_mat_arrays({f: v.ravel()[0][f] for f in v.dtype.names}, f"{prefix}{k}/"))
        elif np.issubdtype(v.dtype, np.number):
            out[prefix + k] = v
    return out


def _read_mat(path: Path, opts: _Options) -> Table:
    from scipy import io

    try:
        raw = io.loadmat(path, squeeze_me=False)
    except NotImplementedError:  # v7.3: HDF5
        return _read_hdf5(path, opts, "mat")
    except ValueError as exc:
        raise TableError(f"{path}: not a MATLAB file scipy can read ({exc})") from None
    found = _mat_arrays(raw)
    return _from_arrays(dict(zip(_leaf_names(list(found)), found.values())), opts, path, "mat")


def _read_mcap(path: Path, opts: _Options) -> Table:
    from ..recording import read_recording

    rec = read_recording(path)
    sensors = rec.rig.sensor_by_topic()
    chans = []
    for topic in sorted(rec.channels):
        c = rec.channels[topic]
        if c.kind == "imu":
            # an IMU whose rig.json lists its ``axes`` (an extension key: a single-axis
            # accelerometer imported by ``shm import``) gives only those; the others are fill
            sensor = sensors.get(topic)
            axes = None if sensor is None else (sensor.model_extra or {}).get("axes")
            for axis, j in (("x", 0), ("y", 1), ("z", 2)):
                if axes is None or f"accel_{axis}" in axes:
                    chans.append((f"{c.name}.accel_{axis}", "m/s^2", c, j))
        elif c.kind == "strain":
            chans.append((f"{c.name}.strain", "m/m", c, 0))
    if not chans:
        raise TableError(f"{path}: the recording has no IMU or strain channel")
    # one uniform clock: the median step of the first channel, over the span all channels cover
    t0 = max(int(c.log_time_ns[0]) for _, _, c, _ in chans if len(c))
    t1 = min(int(c.log_time_ns[-1]) for _, _, c, _ in chans if len(c))
    step = float(np.median(np.diff(chans[0][2].log_time_ns)))
    rate = 1e9 / step if opts.fs is None else opts.fs
    n = int(np.floor((t1 - t0) / 1e9 * rate)) + 1
    if n < 2:
        raise TableError(f"{path}: the channels share no common time span")
    grid = t0 + np.arange(n) * (1e9 / rate)
    data = np.column_stack([np.interp(grid, c.log_time_ns.astype(float), c.values[:, j]) for _, _, c, j in chans])
    table = _finish(data, [n_ for n_, *_ in chans], [u for _, u, *_ in chans], replace(opts, fs=rate), path, "mcap")
    return replace(table, start_s=(t0 - rec.start_ns) / 1e9, problems=tuple(rec.report.problems))


_READERS = {
    ".npy": _read_npy, ".npz": _read_npz, ".mat": _read_mat, ".h5": _read_hdf5, ".hdf5": _read_hdf5, ".mcap": _read_mcap,
}
_TEXT = (".csv", ".tsv", ".txt", ".dat", ".lvm", ".asc")


def read_table(path: str | Path, *, fs: float | None = None, channels: Sequence[str] | None = None,
               time_column: str | None = None, time_unit: str = "s", nonfinite: str = "raise") -> Table:
    """Read measured channels from ``path`` (format from the suffix; see the module docstring).

    Parameters
    ----------
    path : str or Path
    fs : float, optional
        Sample rate (Hz); required where the file has none (.npy, text without a time column).
    channels : sequence of str, optional
        The channels to read, in this order (default: all). For ``.npz``/``.mat``/HDF5 only these
        arrays are read, so arrays of another length (another clock) may share the file.
    time_column : str, optional
        The column (array, or ``.npy`` column index as text) holding the sample times; default:
        the first column named like a time (``TIME_NAMES``).
    time_unit : {"s", "ms", "us", "ns"}
        Unit of the time column; ``Table.time`` and ``fs_hz`` are in s and Hz.
    nonfinite : {"raise", "keep"}
        What a NaN or infinite channel value does: raise, or stay in ``data`` for the caller to
        count and skip.

    Returns
    -------
    Table

    Raises
    ------
    TableError
        For an unknown suffix, a file without a header naming its columns, a missing sample
        rate, a non-uniform time column, NaN in a channel (with ``nonfinite="raise"``), an
        unknown channel, arrays of different lengths, or a malformed file.
    FileNotFoundError
        If the file does not exist.
    """
    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(f"{p}: no such file")
    if fs is not None and (isinstance(fs, bool) or not np.isfinite(fs) or fs <= 0):
        raise TableError(f"{fs=} must be a positive finite sample rate in Hz")
    if time_unit not in TIME_UNITS:
        raise TableError(f"{time_unit=} is not one of {sorted(TIME_UNITS)}")
    if nonfinite not in ("raise", "keep"):
        raise TableError(f"{nonfinite=} must be 'raise' or 'keep'")
    if channels is not None:
        channels = tuple(channels)
        if not channels or len(set(channels)) != len(channels):
            raise TableError(f"{channels=} must name at least one channel, each once")
    opts = _Options(fs, channels, time_column, TIME_UNITS[time_unit], nonfinite == "keep")
    suffix = p.suffix.lower()
    if suffix in _READERS:
        return _READERS[suffix](p, opts)
    if suffix in _TEXT:
        return _read_text(p, opts)
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
                   units=None if table.units is None else tuple(table.units[i] for i in idx),
                   codes=None if table.codes is None else table.codes[:, idx])
