"""What ``shm oma`` identifies from a table of plain channels whose bad samples were rejected.

A plain channel (a CSV column) has no sensor kind, so what is implausible is judged two ways:
``max_abs`` (a limit in the file's units, for every channel, when given) and the channel's own
scale (:func:`shm_service.formats.rejections.outliers`: ``|x - median| > outlier_factor · P90``; a DAQ's
overflow code or a corrupted float, never a response).

A spectrum, a correlation and a mode shape need every channel at every instant. The policy:

- a run of at most ``max_fill`` rejected samples inside a channel is filled by linear
  interpolation between its neighbours (counted per channel and reported: at 200 Hz one sample
  is 5 ms, far shorter than any period the band holds, so the fill changes no mode);
- a longer run (or one at either end) cannot be filled without inventing a response: the
  identification then uses the longest span in which every channel is valid, and says which
  span, and how many samples it left out.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .rejections import Rejections, fill_short_gaps, longest_clean_span, outliers
from .tables import Table, TableError

__all__ = ["CleanRecord", "clean_for_identification"]


@dataclass(frozen=True)
class CleanRecord:
    """The outputs and inputs to identify (finite everywhere), what was rejected and filled,
    the rows used (``start``, ``stop``) of the table's ``rows``."""

    outputs: np.ndarray
    inputs: np.ndarray | None
    rejections: Rejections
    interpolated: dict[str, int]
    start: int
    stop: int
    rows: int

    def as_dict(self, fs: float) -> dict[str, Any]:
        return {"rejected_samples": self.rejections.as_dict(), "interpolated": dict(self.interpolated),
                "used_span_s": [self.start / fs, self.stop / fs], "left_out_samples": self.rows - (self.stop - self.start)}

    def format(self, fs: float) -> list[str]:
        lines = []
        if self.rejections.total:
            lines.append(f"{self.rejections.total} sample(s) rejected:")
            lines.extend(self.rejections.format())
        if self.interpolated:
            lines.append("filled by linear interpolation (runs of a few samples): "
                         + ", ".join(f"{name} {n}" for name, n in self.interpolated.items())
                         + f"; {sum(self.interpolated.values())} filled by linear interpolation")
        if self.stop - self.start < self.rows:
            lines.append(f"a gap too long to fill: identified on {self.start / fs:.3f}-{self.stop / fs:.3f} s, the longest span "
                         f"with every channel valid ({self.rows - (self.stop - self.start)} of {self.rows} samples left out)")
        return lines


def clean_for_identification(table: Table, outputs: list[str], inputs: list[str] | None = None, *,
                             outlier_factor: float = 1000.0, max_abs: float | None = None, max_fill: int = 4) -> CleanRecord:
    """Reject the implausible samples of ``table``'s ``outputs`` and ``inputs`` channels, fill
    short runs, and cut to the longest span of valid rows (see the module docstring).

    Parameters
    ----------
    table : Table
        Read with ``nonfinite="keep"`` (rejected samples NaN, counted in ``table.rejections``).
    outputs, inputs : lists of channel names of ``table``.
    outlier_factor : float >= 0
        0 turns the outlier test off.
    max_abs : float, optional
        Largest |value| in the file's units.
    max_fill : int >= 0
        Longest run of rejected samples filled.

    Raises
    ------
    TableError
        If no span of at least two samples has every channel valid.
    """
    if outlier_factor < 0 or not np.isfinite(outlier_factor):
        raise ValueError(f"{outlier_factor=} must be >= 0 (0: no outlier test)")
    if max_abs is not None and not (np.isfinite(max_abs) and max_abs > 0):
        raise ValueError(f"{max_abs=} must be a positive number")
    if max_fill < 0:
        raise ValueError(f"{max_fill=} must be >= 0")
    names = list(outputs) + list(inputs or [])
    data = np.column_stack([table.data[:, table.channels.index(n)] for n in names]).astype(float)
    rejections = Rejections()
    rejections.line_of = table.rejections.line_of
    for j, name in enumerate(names):
        rejections.merge(table.rejections.only(name))
        column = data[:, j]
        if max_abs is not None:
            with np.errstate(invalid="ignore"):
                beyond = np.abs(column) > max_abs
            rejections.add(name, "implausible", np.flatnonzero(beyond), limit=f"|x| <= {max_abs:g} (--max-abs)")
            column[beyond] = np.nan
        if outlier_factor:
            far = outliers(column, outlier_factor)
            rejections.add(name, "implausible", np.flatnonzero(far),
                           limit=f"|x - median| <= {outlier_factor:g} x the 90th percentile of |x - median| (--outlier-factor)")
            column[far] = np.nan
    filled, count = fill_short_gaps(data, max_fill)
    interpolated = {name: int(n) for name, n in zip(names, count) if n}
    start, stop = longest_clean_span(filled)
    if stop - start < 2:
        raise TableError(f"{table.path}: no span of two samples has every channel valid ({rejections.total} samples rejected)")
    k = len(outputs)
    return CleanRecord(filled[start:stop, :k], filled[start:stop, k:] if inputs else None, rejections, interpolated,
                       start, stop, data.shape[0])
