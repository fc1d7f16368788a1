"""Cornell spectral BRDF measurements in pbrt-v2's irregular isotropic text format (``.brdf``).

The Cornell University Program of Computer Graphics distributed its gonioreflectometer paint
measurements in this layout; pbrt-v2's ``measured`` material reads it (Pharr and Humphreys,
"Physically Based Rendering", 2nd ed., 2010). The description followed here:

- white-space separated numbers, read as one stream (line breaks carry no meaning); ``#``
  starts a comment that runs to the end of the line;
- the number of wavelengths ``n``, then the ``n`` wavelengths in nm;
- then records of ``4 + n`` numbers: ``theta_i phi_i theta_s phi_s`` in radians (incidence and
  scattered directions, both pointing away from the surface: the mirror direction of
  ``phi_i = 0`` is ``phi_s = pi``) followed by ``n`` BRDF values.

The files do not state units; pbrt uses the values as BRDF in 1/sr, and so does this reader.
Comment lines are kept in ``metadata["comments"]``; those before the first number that are
separated from it by a blank line (the material's description and credit line, as opposed to
the ``# num wls`` label right above the count) form ``metadata["description"]``, one line each.
"""

import numpy as np

from ..errors import FormatError
from ..geometry import spherical_to_cartesian
from ..table import Table
from . import _text, read_bytes, source_of
from .files import MAX_BYTES

FORMAT = "cornell"
EXTENSIONS = (".brdf",)

ANGLES = ("theta_i", "phi_i", "theta_s", "phi_s")
#: Plausible wavelengths (nm) for content sniffing: ultraviolet to far infrared.
_SNIFF_NM = (100.0, 100000.0)
_EXPECTED = "the number of wavelengths, the wavelengths (nm), then records of 4 angles + values"


def sniff(head):
    """True when the numbers in ``head`` start with a count ``n`` followed by increasing
    wavelengths in nm (comments skipped)."""
    text = head.decode("utf-8", "replace")
    if not text[-1:].isspace():
        text = text.rsplit(None, 1)[0] if text.strip() else ""  # the last number may be cut
    tokens = [t for line in text.split("\n") for t in line.split("#", 1)[0].split()]
    n = _positive_integer(tokens[0]) if tokens else None
    if n is None or len(tokens) < 2:
        return False
    try:
        nm = np.array(tokens[1:1 + n], dtype=float)
    except ValueError:
        return False
    plausible = (nm >= _SNIFF_NM[0]) & (nm <= _SNIFF_NM[1])
    return bool(np.all(plausible) and np.all(np.diff(nm) > 0))


def read(path):
    """Read a Cornell/pbrt ``.brdf`` file into a :class:`~brdf.table.Table`.

    Returns
    -------
    Table
        One sample per record, ``values`` shaped ``(N, n)`` (1/sr) with ``wavelengths`` in nm;
        ``isotropic=True`` (the format stores isotropic BRDFs).

    Raises
    ------
    FormatError
        Naming the line of the first bad input: not UTF-8, empty, a count that is not a
        positive integer, too few or non-increasing wavelengths, a token that is not a finite
        number, an angle out of range, no records, or an incomplete last record (naming the line
        where it starts).
    """
    data = read_bytes(path, MAX_BYTES, "a Cornell .brdf file")
    lines = _text.decode_lines(path, data, _EXPECTED)
    tokens, token_lines, comments = _tokens(lines)
    if not tokens:
        raise FormatError(path, "", f"no numbers, only comments; expected {_EXPECTED}")
    n = _count(path, tokens[0], token_lines[0])
    wavelengths = _wavelengths(path, tokens, token_lines, n)
    angles, values = _records(path, tokens[n + 1:], token_lines[n + 1:], n, lines)
    wi = spherical_to_cartesian(angles[:, 0], angles[:, 1])
    wo = spherical_to_cartesian(angles[:, 2], angles[:, 3])
    metadata = {"units": "1/sr (not stated in the file; pbrt reads the values as BRDF)",
                "description": "\n".join(_description(comments, token_lines[0])),
                "comments": [text for _, text in comments]}
    table = Table(wi, wo, values, wavelengths=wavelengths, isotropic=True, metadata=metadata,
                  source=source_of(path, data, FORMAT))
    table.format = FORMAT
    return table


def _tokens(lines):
    """``(tokens, line number of each token, [(line number, comment text)])``."""
    tokens, token_lines, comments = [], [], []
    for number, line in enumerate(lines, start=1):
        content, hash_, comment = line.partition("#")
        if hash_:
            comments.append((number, comment.strip()))
        fields = content.split()
        tokens += fields
        token_lines += [number] * len(fields)
    return tokens, token_lines, comments


def _description(comments, first_number_line):
    """Comment lines before the first number, except the block directly above it (its label)."""
    header = [(number, text) for number, text in comments if number < first_number_line]
    label_start = first_number_line
    while header and header[-1][0] == label_start - 1:
        label_start = header.pop()[0]
    return [text for _, text in header if text]


def _count(path, token, line):
    n = _positive_integer(token)
    if n is None:
        raise FormatError(path, f"line {line}", f"number of wavelengths is {token!r}; "
                                                "expected a positive integer")
    return n


def _positive_integer(token):
    """``int(token)`` for a token of ASCII digits worth at least 1, else None."""
    ok = token.isascii() and token.isdigit() and int(token) >= 1
    return int(token) if ok else None


def _wavelengths(path, tokens, token_lines, n):
    if len(tokens) < n + 1:
        raise FormatError(path, f"line {token_lines[-1]}", f"the file ends after "
                                                           f"{len(tokens) - 1} of {n} wavelengths")

    def locate(k):
        return f"line {token_lines[k + 1]}", f"wavelength {k + 1}: "

    nm = _text.floats(path, tokens[1:n + 1], locate)
    _text.check_positive(path, nm, locate, "nm")
    if np.any(np.diff(nm) <= 0.0):
        k = int(np.argmax(np.diff(nm) <= 0.0)) + 1
        where, label = locate(k)
        raise FormatError(path, where, f"{label}{nm[k]:g} nm does not exceed the previous "
                                       f"{nm[k - 1]:g} nm; expected increasing wavelengths")
    return nm


def _records(path, tokens, token_lines, n, lines):
    """Angles ``(N, 4)`` in radians and values ``(N, n)`` of the records."""
    width = 4 + n
    if not tokens:
        raise FormatError(path, f"line {len(lines)}", f"no records after the wavelengths; "
                                                      f"expected records of {width} numbers")
    if len(tokens) % width:
        start, found = _incomplete_record(token_lines, width)
        raise FormatError(path, f"line {token_lines[start]}",
                          f"record {start // width + 1}, which starts on this line, has {found} "
                          f"numbers; expected {width} (4 angles + {n} values)")

    def locate(k):
        name = ANGLES[k % width] if k % width < 4 else f"value {k % width - 3}"
        return f"line {token_lines[k]}", f"record {k // width + 1}, {name}: "

    numbers = _text.floats(path, tokens, locate).reshape(-1, width)
    angles = numbers[:, :4].copy()
    for c in (0, 2):
        angles[:, c] = _text.check_polar(path, angles[:, c], lambda k, c=c: locate(k * width + c))
    for c in (1, 3):
        _text.check_azimuth(path, angles[:, c], lambda k, c=c: locate(k * width + c))
    return angles, numbers[:, 4:]


def _incomplete_record(token_lines, width):
    """``(index of the first token, count)`` of the record that is cut short.

    The stream itself cannot tell where a number went missing, only that the last record is
    short. When the file is laid out one record per line (its first record fills its line
    exactly, as in Cornell's files), the first line holding another count is where the bad
    record starts; otherwise it is the last, partial record.
    """
    lines = np.asarray(token_lines)
    starts = np.flatnonzero(np.r_[True, lines[1:] != lines[:-1]])
    counts = np.diff(np.r_[starts, len(lines)])
    if counts[0] == width and np.any(counts != width):
        j = int(np.argmax(counts != width))
        return int(starts[j]), int(counts[j])
    found = len(lines) % width
    return len(lines) - found, found
