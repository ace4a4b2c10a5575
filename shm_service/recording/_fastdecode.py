"""Compiled kernels of the recording reader: the record scan of an MCAP data section and the
decoding of JSON payloads laid out like a known template, a whole block at a time.

Reading message by message in Python costs about 3 µs a message (8 M messages an hour); these
kernels walk the bytes once. What they accept is exactly what the reader's reference path
(orjson, then the stdlib for NaN) would accept, and they leave everything else to it:

- ``scan_messages`` lists the message records of a buffer (channel id, times, payload span) and
  stops at every other record the reader must see (schemas, channels, chunks, attachments,
  metadata, the end of the data section) or at an incomplete record.
- ``decode_template`` matches each payload against the template's skeleton (JSON whitespace
  allowed between tokens, the keys in the template's order) and parses its numbers with the JSON
  grammar into float64. A number is converted exactly (correctly rounded, as orjson and
  ``float()`` do): Clinger's fast path when mantissa and power of ten are exact doubles, else
  the Eisel–Lemire algorithm with 128-bit truncated powers of ten; the rare inputs that neither
  decides (more than 19 significant digits, halfway ambiguities, overflow, subnormals) mark the
  message for the reference path, as does any mismatch of the skeleton.
"""

from __future__ import annotations

import math
from typing import Final

import numba
import numpy as np

__all__ = ["MESSAGE_CAPACITY", "decode_template", "scan_messages", "template_codes"]

#: Message slots per call of ``scan_messages`` (bounds the index arrays for a large buffer).
MESSAGE_CAPACITY: Final = 1 << 16

_OP_MESSAGE: Final = 5
# Records the reader ignores (header, message/chunk/attachment/metadata indexes, statistics,
# summary offsets): skipped here without a round trip to Python.
_IGNORED = np.zeros(256, dtype=np.bool_)
_IGNORED[[1, 7, 8, 10, 11, 13, 14]] = True
_IGNORED[16:] = True  # unknown opcodes (the reader skips them too)

_NUMBER_SLOT: Final = 0x23  # '#' marks a number in a template skeleton


def _powers_of_ten_128() -> np.ndarray:
    """128-bit mantissas of 10^e for e in [-348, 347], truncated, normalised to [2^127, 2^128):
    rows (low 64 bits, high 64 bits)."""
    rows = np.empty((696, 2), dtype=np.uint64)
    mask = (1 << 64) - 1
    for i, e in enumerate(range(-348, 348)):
        if e >= 0:
            v = 10**e
            shift = v.bit_length() - 128
            t = v >> shift if shift > 0 else v << -shift
        else:
            d = 10**-e
            k = 127 + d.bit_length()
            t = (1 << k) // d
            while t.bit_length() > 128:
                k -= 1
                t = (1 << k) // d
            while t.bit_length() < 128:
                k += 1
                t = (1 << k) // d
        rows[i, 0] = t & mask
        rows[i, 1] = t >> 64
    return rows


_POW10_128: Final = _powers_of_ten_128()
_EXACT_POW10: Final = np.array([10.0**k for k in range(23)])


@numba.njit(cache=True, nogil=True, inline="always")
def _u64(buf, p):
    v = np.uint64(0)
    for k in range(8):
        v |= np.uint64(buf[p + k]) << np.uint64(8 * k)
    return v


@numba.njit(cache=True, nogil=True)
def scan_messages(buf, pos, end, ignored, cids, logs, pubs, starts, stops):
    """Scan the records of ``buf[pos:end]`` (uint8). Message records go into the arrays
    (channel id, log and publish time, payload start and stop) until they are full; the scan
    stops at a record the reader handles itself, at an incomplete record or at ``end``.

    Returns (messages, position, state): state 0 at ``end``, 1 at a record to hand over
    (``position`` is its start), 2 at an incomplete record (``position`` is its start), 3 with
    the arrays full.
    """
    n = 0
    cap = cids.shape[0]
    while True:
        if end - pos < 9:
            return n, pos, 0 if pos >= end else 2
        opcode = buf[pos]
        length = _u64(buf, pos + 1)
        if length > np.uint64(end - pos - 9):
            return n, pos, 2
        following = pos + 9 + np.int64(length)
        if opcode == _OP_MESSAGE and length >= np.uint64(22):
            if n == cap:
                return n, pos, 3
            b = pos + 9
            cids[n] = np.int64(buf[b]) | (np.int64(buf[b + 1]) << 8)
            logs[n] = np.int64(_u64(buf, b + 6))
            pubs[n] = np.int64(_u64(buf, b + 14))
            starts[n] = b + 22
            stops[n] = following
            n += 1
        elif not ignored[opcode]:
            return n, pos, 1
        pos = following


def template_codes(skeleton: bytes) -> np.ndarray:
    """A template for ``decode_template``: the compact JSON of a payload with ``#`` for each
    number (``{"accel":[#,#,#],"gyro":[#,#,#]}``)."""
    if b"#" not in skeleton:
        raise ValueError(f"{skeleton=} has no number slot '#'")
    return np.frombuffer(skeleton, dtype=np.uint8).copy()


@numba.njit(cache=True, nogil=True, inline="always")
def _is_space(c):
    return c == 0x20 or c == 0x0A or c == 0x0D or c == 0x09


@numba.njit(cache=True, nogil=True, inline="always")
def _mul64(a, b):
    """The 128-bit product of two uint64 as (high, low)."""
    m32 = np.uint64(0xFFFFFFFF)
    s32 = np.uint64(32)
    a_lo, a_hi = a & m32, a >> s32
    b_lo, b_hi = b & m32, b >> s32
    p0 = a_lo * b_lo
    p1 = a_lo * b_hi
    p2 = a_hi * b_lo
    p3 = a_hi * b_hi
    mid = (p0 >> s32) + (p1 & m32) + (p2 & m32)
    lo = (p0 & m32) | (mid << s32)
    hi = p3 + (p1 >> s32) + (p2 >> s32) + (mid >> s32)
    return hi, lo


@numba.njit(cache=True, nogil=True, inline="always")
def _leading_zeros(v):
    n = 0
    top = np.uint64(1) << np.uint64(63)
    while (v & top) == np.uint64(0):
        v <<= np.uint64(1)
        n += 1
    return n


@numba.njit(cache=True, nogil=True, inline="always")
def _eisel_lemire(man, exp10, neg, table):
    """man × 10^exp10 correctly rounded to float64 (man > 0), or ok = False when undecided."""
    if exp10 < -348 or exp10 > 347:
        return 0.0, False
    clz = _leading_zeros(man)
    man = man << np.uint64(clz)
    ret_exp2 = np.int64(((217706 * exp10) >> 16) + 64 + 1023 - clz)
    row = exp10 + 348
    x_hi, x_lo = _mul64(man, table[row, 1])
    m9 = np.uint64(0x1FF)
    if (x_hi & m9) == m9 and x_lo + man < man:
        y_hi, y_lo = _mul64(man, table[row, 0])
        merged_hi, merged_lo = x_hi, x_lo + y_hi
        if merged_lo < x_lo:
            merged_hi += np.uint64(1)
        if (merged_hi & m9) == m9 and merged_lo + np.uint64(1) == np.uint64(0) and y_lo + man < man:
            return 0.0, False
        x_hi, x_lo = merged_hi, merged_lo
    msb = x_hi >> np.uint64(63)
    mantissa = x_hi >> (msb + np.uint64(9))
    ret_exp2 -= np.int64(1) ^ np.int64(msb)
    if x_lo == np.uint64(0) and (x_hi & m9) == np.uint64(0) and (mantissa & np.uint64(3)) == np.uint64(1):
        return 0.0, False
    mantissa += mantissa & np.uint64(1)
    mantissa >>= np.uint64(1)
    if (mantissa >> np.uint64(53)) > np.uint64(0):
        mantissa >>= np.uint64(1)
        ret_exp2 += 1
    if ret_exp2 <= 0 or ret_exp2 >= 0x7FF:  # subnormal, infinite: the reference path decides
        return 0.0, False
    # mantissa has 53 bits (exact as a double) and the result is normal: ldexp is exact.
    # numba compiles ldexp of an int64 exponent as it is; an int() for the stubs would be extra code in the kernel
    v = math.ldexp(np.float64(mantissa), ret_exp2 - 1075)  # type: ignore[arg-type]
    return (-v if neg else v), True


@numba.njit(cache=True, nogil=True, inline="always")
def _number(buf, p, stop, table, exact):
    """Parse a JSON number at ``buf[p]``; returns (value, position after it, ok)."""
    neg = False
    if p < stop and buf[p] == 0x2D:  # '-'
        neg = True
        p += 1
    if p >= stop:
        return 0.0, p, False
    c = buf[p]
    man = np.uint64(0)
    digits = 0  # significant digits taken into man
    exp10 = 0
    integer = True
    ten = np.uint64(10)
    if c == 0x30:  # '0' must stand alone
        p += 1
        if p < stop and 0x30 <= buf[p] <= 0x39:
            return 0.0, p, False
    elif 0x31 <= c <= 0x39:
        while p < stop and 0x30 <= buf[p] <= 0x39:
            if digits < 19:
                man = man * ten + np.uint64(buf[p] - 0x30)
                digits += 1
            else:
                return 0.0, p, False  # more digits than a uint64 holds: the reference path
            p += 1
    else:
        return 0.0, p, False
    if p < stop and buf[p] == 0x2E:  # '.'
        integer = False
        p += 1
        first = p
        while p < stop and 0x30 <= buf[p] <= 0x39:
            d = buf[p] - 0x30
            if digits == 0 and d == 0:
                exp10 -= 1  # a leading zero of the fraction: not significant
            elif digits < 19:
                man = man * ten + np.uint64(d)
                digits += 1
                exp10 -= 1
            else:
                return 0.0, p, False
            p += 1
        if p == first:
            return 0.0, p, False
    if p < stop and (buf[p] == 0x65 or buf[p] == 0x45):  # 'e' 'E'
        integer = False
        p += 1
        eneg = False
        if p < stop and (buf[p] == 0x2B or buf[p] == 0x2D):
            eneg = buf[p] == 0x2D
            p += 1
        first = p
        e = 0
        while p < stop and 0x30 <= buf[p] <= 0x39:
            if e < 100000:
                e = e * 10 + (buf[p] - 0x30)
            p += 1
        if p == first:
            return 0.0, p, False
        exp10 += -e if eneg else e
    if man == np.uint64(0):
        # orjson reads an integer -0 as the integer 0, a float -0.0 as negative zero.
        return (-0.0 if (neg and not integer) else 0.0), p, True
    if man <= np.uint64(1 << 53) and -22 <= exp10 <= 22:
        v = np.float64(man)
        v = v * exact[exp10] if exp10 >= 0 else v / exact[-exp10]
        return (-v if neg else v), p, True
    v, ok = _eisel_lemire(man, exp10, neg, table)
    return v, p, ok


@numba.njit(cache=True, nogil=True)
def _decode_templates(buf, starts, stops, template, values, ok, table, exact):
    n_msg = starts.shape[0]
    n_t = template.shape[0]
    for m in range(n_msg):
        p = starts[m]
        stop = stops[m]
        col = 0
        good = True
        in_key = False
        for k in range(n_t):
            c = template[k]
            if not in_key:
                while p < stop and _is_space(buf[p]):
                    p += 1
            if c == _NUMBER_SLOT:
                v, p, fine = _number(buf, p, stop, table, exact)
                if not fine:
                    good = False
                    break
                values[m, col] = v
                col += 1
                continue
            if p >= stop or buf[p] != c:
                good = False
                break
            if c == 0x22:  # '"': keys carry no whitespace or escapes of their own
                in_key = not in_key
            p += 1
        if good:
            while p < stop and _is_space(buf[p]):
                p += 1
            good = p == stop
        ok[m] = good


def decode_template(buf: np.ndarray, starts: np.ndarray, stops: np.ndarray, template: np.ndarray,
                    width: int) -> tuple[np.ndarray, np.ndarray]:
    """The numbers of the payloads ``buf[starts[i]:stops[i]]`` (uint8 buffer, int64 spans) that
    follow ``template`` (``template_codes``) as rows (n, width) float64, and the mask (n,) of the
    payloads decoded; rows of the others are undefined (the caller decodes those its own way)."""
    n = len(starts)
    values = np.empty((n, width), dtype=np.float64)
    ok = np.empty(n, dtype=np.bool_)
    if n:
        _decode_templates(buf, starts, stops, template, values, ok, _POW10_128, _EXACT_POW10)
    return values, ok


def scan_buffer(buf: np.ndarray, pos: int, end: int, capacity: int = MESSAGE_CAPACITY):
    """``scan_messages`` with fresh arrays: (messages, position, state, cids, logs, pubs, starts, stops)."""
    cap = max(1, min(capacity, (end - pos) // 31 + 1))
    cids = np.empty(cap, dtype=np.int64)
    logs = np.empty(cap, dtype=np.int64)
    pubs = np.empty(cap, dtype=np.int64)
    starts = np.empty(cap, dtype=np.int64)
    stops = np.empty(cap, dtype=np.int64)
    n, position, state = scan_messages(buf, pos, end, _IGNORED, cids, logs, pubs, starts, stops)
    return n, position, state, cids[:n], logs[:n], pubs[:n], starts[:n], stops[:n]
