"""Shared parsing steps of the plain-text readers (NIST PTFE, Cornell, CUReT).

Each step raises :class:`~brdf.errors.FormatError` naming the line (and the field) of the first
bad input, so every text format reports errors the same way. The fast path converts all tokens
at once with numpy; the line-by-line search only runs once a conversion has failed.
"""

import math

import numpy as np

from ..errors import FormatError

#: Slack on angle limits for files that print angles rounded to a few decimals (pi printed as
#: 3.141593 exceeds pi by 3.5e-7 rad): half a unit of the 5th decimal, 5e-6 rad (0.0003 deg).
RADIAN_ROUNDING = 5e-6


def decode_lines(path, data, expected):
    """The lines of UTF-8 ``data`` without line endings (LF or CRLF).

    A byte-order mark is dropped and so are trailing blank lines (a final line ending is not
    an extra row). ``expected`` says what the file should hold, for the empty-file message.

    Raises
    ------
    FormatError
        Text that is not UTF-8 (naming the line and byte offset of the first bad byte) or holds
        nothing but white space.
    """
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as e:
        line = data.count(b"\n", 0, e.start) + 1
        raise FormatError(path, f"line {line}",
                          f"byte {e.start} ({data[e.start:e.start + 1]!r}) is not UTF-8; "
                          "expected UTF-8 text") from None
    text = text.removeprefix("\ufeff").rstrip()
    if not text:
        raise FormatError(path, "", f"empty file; expected {expected}")
    # split on "\n" only: str.splitlines also breaks at form feeds and other separators, which
    # would shift every line number after them
    return [line.removesuffix("\r") for line in text.split("\n")]


def floats(path, tokens, locate):
    """Float64 array of a flat list of number tokens.

    Parameters
    ----------
    tokens : list of str
    locate : callable
        ``locate(k) -> (where, label)`` for token ``k``: the place for the error (``"line 12"``)
        and a prefix naming the field (``"column phir: "``, or ``""``).

    Raises
    ------
    FormatError
        At the first token that is not a number, or is NaN or infinite.
    """
    try:
        # float() also takes other scripts' digits, full-width ones and underscores
        joined = "".join(tokens)
        if not joined.isascii() or "_" in joined:
            raise ValueError(joined)
        values = np.array(tokens, dtype=np.float64)
    except ValueError:
        k = next(k for k, t in enumerate(tokens) if not is_number(t))
        where, label = locate(k)
        shown = f"{tokens[k]!r} is not a number" if tokens[k].strip() else "is empty"
        raise FormatError(path, where, f"{label}{shown}; expected a number") from None
    bad = ~np.isfinite(values)
    if bad.any():
        k = int(np.argmax(bad))
        where, label = locate(k)
        raise FormatError(path, where, f"{label}{tokens[k]!r} is not finite; expected a number "
                                       "(NaN and infinity are not allowed)")
    return values


def parse_float(token):
    """``float(token)`` for decimal notation in ASCII only (``float`` also takes other scripts'
    digits, full-width digits and underscores, which no data file means); ValueError otherwise."""
    if not token.isascii() or "_" in token:
        raise ValueError(token)
    return float(token)


def is_number(token):
    """Whether :func:`parse_float` accepts ``token``."""
    try:
        parse_float(token)
    except ValueError:
        return False
    return True


def check_range(path, values, low, high, locate, unit=""):
    """Raise :class:`FormatError` at the first of ``values`` outside ``[low, high]``.

    ``locate(k)`` names the place and field of ``values[k]`` as for :func:`floats`.
    """
    bad = (values < low) | (values > high)
    if bad.any():
        k = int(np.argmax(bad))
        where, label = locate(k)
        raise FormatError(path, where, f"{label}{values[k]:.10g}{unit} is outside the range "
                                       f"[{low:.10g}, {high:.10g}]{unit}")


def check_positive(path, values, locate, unit):
    """Raise :class:`FormatError` at the first of ``values`` (a wavelength) that is not > 0."""
    bad = values <= 0.0
    if bad.any():
        k = int(np.argmax(bad))
        where, label = locate(k)
        raise FormatError(path, where, f"{label}{values[k]:.10g} {unit}; expected a positive "
                                       "wavelength")


def check_polar(path, theta, locate):
    """Check polar angles in radians (``[0, pi/2]`` give or take rounding); return them clipped
    to ``[0, pi/2]`` so that a rounded 90 degrees does not dip below the horizon."""
    check_range(path, theta, -RADIAN_ROUNDING, 0.5 * math.pi + RADIAN_ROUNDING, locate, " rad")
    return np.clip(theta, 0.0, 0.5 * math.pi)


def check_azimuth(path, phi, locate):
    """Check azimuths in radians: any convention spanning one turn, signed or not."""
    check_range(path, phi, -2.0 * math.pi - RADIAN_ROUNDING, 2.0 * math.pi + RADIAN_ROUNDING,
                locate, " rad")


def check_sequence(path, numbers, locate, what):
    """Check that the tokens ``numbers`` are the integers 1, 2, ... in order (sample or
    measurement numbers in the first column)."""
    for k, token in enumerate(numbers):
        if token != str(k + 1) and not _equals_integer(token, k + 1):
            where, label = locate(k)
            raise FormatError(path, where, f"{label}{what} is {token!r}; expected {k + 1} "
                                           f"({what}s run 1, 2, ... in order)")


def _equals_integer(token, n):
    try:
        return float(token) == n
    except ValueError:
        return False
