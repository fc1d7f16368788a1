"""Gonioreflectometer CSV, the project's plain-text table (docs/conventions.md §5).

A file looks like this::

    # units: 1/sr
    # instrument: goniometer 2, 633 nm laser
    theta_i,phi_i,theta_o,phi_o,brdf,sigma
    30,0,30,180,0.52,0.01
    30,0,40,180,0.31,0.01

Rules (the reader enforces them; the writer follows them):

- UTF-8 text (a leading byte-order mark is ignored), ``\\n`` or ``\\r\\n`` line ends, fields
  separated by commas, spaces around a field ignored, blank lines skipped anywhere.
- Before the header: ``#`` comment lines. ``# key: value`` (a key without colons, then a colon
  and a space) goes to ``Table.metadata[key]`` as a string; repeating a key continues its value
  on a new line (``"\\n"``). Other comments are skipped. ``# isotropic: false`` declares an
  anisotropic material (default ``true``); it sets ``Table.isotropic`` rather than metadata.
- The header names the columns, in any order: ``theta_i, phi_i, theta_o, phi_o`` in degrees
  (``0 <= theta <= 90``, ``phi`` any finite value) and the values in 1/sr, one of

  * ``brdf`` (one channel),
  * ``brdf_r, brdf_g, brdf_b`` (RGB),
  * ``brdf`` and ``wavelength_nm`` (spectral long form: one row per geometry and wavelength);

  optionally with standard deviations matching the values: ``sigma`` or
  ``sigma_r, sigma_g, sigma_b`` (non-negative). Any other column is an error.
- Every data row holds a finite number in every column. A row that does not (an empty field, a
  non-number, NaN, inf, a wrong number of fields, a polar angle outside [0, 90]) is an error
  naming its line: samples that were not measured are left out, never written as NaN.

A spectral file becomes a table with one sample per distinct ``(theta_i, phi_i, theta_o,
phi_o)`` (as written in the file, in order of first appearance) and one channel per distinct
wavelength (ascending). A geometry measured at some wavelengths only gets ``NaN`` (missing) at
the others; the same geometry and wavelength twice is an error naming both lines.

Writing is the inverse: numbers in the shortest form that reads back to the same float64
(Python's ``repr``), so read -> write -> read is bit-exact; the angles of a table read from a
CSV are written exactly as they were read (:class:`AngleTable`), those of any other table are
computed from its directions. Spectral tables are written in long form. Samples missing in every
channel are left out (missing in a CSV means absent), and so are grid nodes below the horizon
(:func:`above_horizon`). Metadata is written as ``# key: value``
lines (non-string values as JSON), with a ``source`` entry recording the file the samples were
first read from.
"""

import difflib
import json
import re
from dataclasses import dataclass

import numpy as np

from ..errors import FormatError, InputError
from ..table import HORIZON_SLACK, AngleTable
from . import read_bytes, source_of
from .files import MAX_BYTES
from . import _text
from ._text import decode_lines

__all__ = ["read", "write", "sniff", "provenance_metadata", "metadata_comment_lines", "above_horizon",
           "FORMAT", "EXTENSIONS", "COLUMNS"]

FORMAT = "gonio-csv"
EXTENSIONS = (".csv",)
#: A .csv that no format's sniff recognises is read as a gonio CSV, whose errors say why.
EXTENSION_FALLBACK = True

ANGLES = ("theta_i", "phi_i", "theta_o", "phi_o")
SINGLE, SINGLE_SIGMA = ("brdf",), ("sigma",)
RGB, RGB_SIGMA = ("brdf_r", "brdf_g", "brdf_b"), ("sigma_r", "sigma_g", "sigma_b")
WAVELENGTH = "wavelength_nm"
#: Every column a gonio CSV may have.
COLUMNS = ANGLES + SINGLE + RGB + (WAVELENGTH,) + SINGLE_SIGMA + RGB_SIGMA
LAYOUTS_TEXT = ("theta_i, phi_i, theta_o, phi_o and the values: brdf, or brdf_r, brdf_g, "
                "brdf_b, or brdf with wavelength_nm")
#: Metadata key that carries ``Table.isotropic`` through a CSV file.
ISOTROPIC_KEY = "isotropic"

# "# key: value": the key has no colon; the colon is followed by white space or the line's end
# (so "# see http://x" or "# at 12:30" stay plain comments)
_KEY_VALUE = re.compile(r"#\s*([^:\s][^:\r\n]*?)\s*:(?:\s+(.*?))?\s*")

#: Rows formatted per write call (bounds the memory of writing a MERL-size table).
WRITE_CHUNK = 65536


def provenance_metadata(table):
    """``table.metadata`` plus ``source``: the file its samples were read from (path, SHA-256,
    format, size), unless an earlier write already recorded the original there."""
    metadata = dict(table.metadata)
    if table.source is not None and "source" not in metadata:
        metadata["source"] = table.source.to_dict()
    return metadata


def above_horizon(table):
    """Mask (N,) of the samples whose directions are both above the horizon (within the slack
    a table allows). Grid formats such as MERL also have nodes below it, which no instrument
    measures and a plain table cannot hold; writers leave them out."""
    return (table.wi[:, 2] >= -HORIZON_SLACK) & (table.wo[:, 2] >= -HORIZON_SLACK)


# -- reading -------------------------------------------------------------------------------------

@dataclass(frozen=True)
class _Layout:
    """Column indices of a header: angles (4), values (1 or 3), sigmas (same count or none) and
    the wavelength (spectral long form) or None."""

    names: tuple
    angles: list
    values: list
    sigma: list
    wavelength: int | None


def sniff(head):
    """Whether the first bytes look like a gonio CSV: the first line that is neither blank nor a
    comment names the four angle columns."""
    for line in head.decode("utf-8", errors="replace").splitlines():
        text = line.strip().lstrip("\ufeff")
        if text and not text.startswith("#"):
            return set(ANGLES) <= {c.strip() for c in text.split(",")}
    return False


def read(path):
    """Read a gonio CSV file (rules in the module docstring).

    Returns
    -------
    AngleTable
        Values ``(N, C)`` in 1/sr (C = 1, 3, or the number of wavelengths; ``NaN`` where a
        spectral geometry lacks a wavelength), ``sigma`` when the file has uncertainty columns,
        ``metadata`` from the ``# key: value`` lines, ``source`` with the file's SHA-256.

    Raises
    ------
    brdf.errors.FormatError
        On the first violation of the rules, naming the line (and the byte offset for text that
        is not UTF-8) and what was expected.
    """
    data = read_bytes(path, MAX_BYTES, "a gonioreflectometer CSV file")
    lines = decode_lines(path, data, f"a header line naming the columns ({LAYOUTS_TEXT})")
    metadata, key_lines, header = _preamble(lines, path)
    isotropic = _isotropic(metadata, key_lines, path)
    names = tuple(c.strip() for c in lines[header].split(","))
    layout = _layout(names, header + 1, path)
    texts, line_numbers = _data_lines(lines, header, path)
    numbers = _numbers(texts, line_numbers, names, path)
    _check_rows(numbers, texts, line_numbers, layout, path)
    angles = numbers[:, layout.angles]
    values = numbers[:, layout.values]
    sigma = numbers[:, layout.sigma] if layout.sigma else None
    wavelengths = None
    if layout.wavelength is not None:
        angles, values, sigma, wavelengths = _long_to_wide(
            angles, values[:, 0], None if sigma is None else sigma[:, 0],
            numbers[:, layout.wavelength], line_numbers, path)
    table = AngleTable.from_degrees(angles, values, sigma=sigma, wavelengths=wavelengths,
                                    isotropic=isotropic, metadata=metadata,
                                    source=source_of(path, data, FORMAT))
    table.format = FORMAT
    return table


def _preamble(lines, path):
    """``(metadata, line of each key, index of the header line)`` from the lines before it."""
    metadata, key_lines = {}, {}
    for index, line in enumerate(lines):
        text = line.strip()
        if not text:
            continue
        if not text.startswith("#"):
            return metadata, key_lines, index
        match = _KEY_VALUE.fullmatch(text)
        if match:
            key, value = match.group(1), match.group(2) or ""
            metadata[key] = f"{metadata[key]}\n{value}" if key in metadata else value
            key_lines.setdefault(key, index + 1)
    raise FormatError(path, f"line {len(lines) + 1}", f"end of file after the comments; expected "
                                                      f"a header line naming the columns "
                                                      f"({LAYOUTS_TEXT})")


def _isotropic(metadata, key_lines, path):
    """The ``# isotropic:`` flag (default true), removed from the metadata."""
    if ISOTROPIC_KEY not in metadata:
        return True
    text = metadata.pop(ISOTROPIC_KEY)
    if text.lower() not in ("true", "false"):
        raise FormatError(path, f"line {key_lines[ISOTROPIC_KEY]}",
                          f"isotropic: {text!r}; expected true or false")
    return text.lower() == "true"


def _did_you_mean(name):
    close = difflib.get_close_matches(name.lower(), COLUMNS, n=1)
    if close:
        return f"{name!r} (did you mean {close[0]}?)"
    if ";" in name or "\t" in name:
        return f"{name!r} (fields must be separated by commas)"
    return repr(name)


def _layout(names, line, path):
    """Resolve the header ``names`` (on ``line``) into a :class:`_Layout`."""
    def fail(expected):
        raise FormatError(path, f"line {line}", expected)

    if "" in names:
        fail(f"column {names.index('') + 1} of the header has no name; expected {LAYOUTS_TEXT}")
    repeated = [n for k, n in enumerate(names) if n in names[:k]]
    if repeated:
        fail(f"column {repeated[0]} appears twice; expected each column once")
    unknown = [n for n in names if n not in COLUMNS]
    if unknown:
        fail(f"unknown column{'s' * (len(unknown) > 1)} "
             f"{', '.join(_did_you_mean(n) for n in unknown)}; valid columns: {', '.join(COLUMNS)}")
    has = set(names)
    rgb = bool(has & set(RGB))
    if rgb and "brdf" in has:
        fail("both brdf and brdf_r/brdf_g/brdf_b; expected one value layout: brdf (single "
             "channel or spectral with wavelength_nm) or brdf_r, brdf_g, brdf_b")
    if rgb and WAVELENGTH in has:
        fail("wavelength_nm with brdf_r/brdf_g/brdf_b; the spectral long form has one brdf "
             "column")
    value_names, sigma_names = (RGB, RGB_SIGMA) if rgb else (SINGLE, SINGLE_SIGMA)
    stray = [n for n in names if n.startswith("sigma") and n not in sigma_names]
    if stray:
        fail(f"column {stray[0]} does not match the value column{'s' * rgb} "
             f"{', '.join(value_names)}; expected {', '.join(sigma_names)}")
    missing = [n for n in ANGLES + value_names if n not in has]
    if missing:
        fail(f"missing column{'s' * (len(missing) > 1)} {', '.join(missing)}; expected "
             f"{LAYOUTS_TEXT}")
    sigma = [n for n in sigma_names if n in has]
    if sigma and len(sigma) < len(sigma_names):
        absent = [n for n in sigma_names if n not in has]
        fail(f"missing column {', '.join(absent)}; uncertainty columns come for every value "
             f"column ({', '.join(sigma_names)}) or for none")
    index = names.index
    return _Layout(names, [index(n) for n in ANGLES], [index(n) for n in value_names],
                   [index(n) for n in sigma], index(WAVELENGTH) if WAVELENGTH in has else None)


def _data_lines(lines, header, path):
    """Non-blank lines after the header and their 1-based line numbers."""
    numbered = [(n, s) for n, s in enumerate(lines[header + 1:], header + 2) if s.strip()]
    if not numbered:
        raise FormatError(path, f"line {header + 2}", f"end of file after the header (line "
                                                      f"{header + 1}); expected rows of numbers")
    return [s for _, s in numbered], np.array([n for n, _ in numbered])


def _numbers(texts, line_numbers, names, path):
    """The rows as a float array ``(N, len(names))``.

    numpy's C parser reads 100k rows in a fraction of a second but cannot say where a row is
    bad; only when it fails are the lines parsed one by one to name the first bad one.
    """
    try:
        numbers = np.loadtxt(texts, delimiter=",", comments=None, ndmin=2, dtype=np.float64)
        if numbers.shape[1] == len(names):
            return numbers
    except ValueError:
        pass
    return np.array([_parse_line(s, n, names, path) for s, n in zip(texts, line_numbers)])


def _parse_line(text, line, names, path):
    """The numbers of one data line, or a FormatError saying what is wrong with it."""
    fields = text.split(",")
    if text.lstrip().startswith("#"):
        raise FormatError(path, f"line {line}", "comment after the header; comments are only "
                                                "allowed before the header line")
    if len(fields) != len(names):
        raise FormatError(path, f"line {line}", f"{len(fields)} fields; expected {len(names)} "
                                                f"({','.join(names)})")
    numbers = []
    for name, field in zip(names, fields):
        field = field.strip()
        if not field:
            raise FormatError(path, f"line {line}", f"empty value in column {name}; expected a "
                                                    "number (leave out samples not measured)")
        try:
            numbers.append(_text.parse_float(field))
        except ValueError:
            raise FormatError(path, f"line {line}", f"{name} = {field!r} is not a number; "
                                                    "expected a decimal number") from None
    return numbers


def _check_rows(numbers, texts, line_numbers, layout, path):
    """Raise a FormatError naming the first row that breaks a rule on the values."""
    theta = [layout.angles[0], layout.angles[2]]
    wavelength = [] if layout.wavelength is None else [layout.wavelength]
    rules = (  # (columns, which values are bad, what was expected)
        (list(range(numbers.shape[1])), lambda x: ~np.isfinite(x),
         "expected a finite number (leave out samples not measured)"),
        (theta, lambda x: (x < 0.0) | (x > 90.0), "expected a polar angle in [0, 90] degrees"),
        (layout.sigma, lambda x: x < 0.0, "expected a standard deviation >= 0"),
        (wavelength, lambda x: x <= 0.0, "expected a wavelength > 0 nm"),
    )
    first = None
    for columns, bad, expected in rules:
        if not columns:
            continue
        mask = bad(numbers[:, columns])
        rows = np.flatnonzero(mask.any(axis=1))
        if rows.size and (first is None or rows[0] < first[0]):
            first = (rows[0], columns[int(np.argmax(mask[rows[0]]))], expected)
    if first is not None:
        row, column, expected = first
        field = texts[row].split(",")[column].strip()
        raise FormatError(path, f"line {line_numbers[row]}",
                          f"{layout.names[column]} = {field}; {expected}")


def _long_to_wide(angles, brdf, sigma, wavelength, line_numbers, path):
    """Group spectral long-form rows by geometry: ``(angles (G, 4), values (G, C), sigma,
    wavelengths (C,))`` with NaN where a geometry lacks a wavelength."""
    wavelengths, channel = np.unique(wavelength, return_inverse=True)
    # + 0.0 turns -0.0 into 0.0, the same angle
    _, first, geometry = np.unique(angles + 0.0, axis=0, return_index=True,
                                   return_inverse=True)
    # number geometries by first appearance so that a rewrite keeps the file's order
    rank = np.empty_like(first)
    rank[np.argsort(first)] = np.arange(len(first))
    geometry = rank[geometry.reshape(-1)]
    cell = geometry * len(wavelengths) + channel
    _, first_row, which = np.unique(cell, return_index=True, return_inverse=True)
    repeats = np.flatnonzero(first_row[which] != np.arange(len(cell)))
    if repeats.size:
        row = repeats[0]
        raise FormatError(path, f"line {line_numbers[row]}",
                          f"same geometry and wavelength as line "
                          f"{line_numbers[first_row[which[row]]]}; expected one row per "
                          f"theta_i, phi_i, theta_o, phi_o and wavelength_nm")
    shape = (len(first), len(wavelengths))
    values = np.full(shape, np.nan)
    values[geometry, channel] = brdf
    if sigma is not None:
        sigma_wide = np.full(shape, np.nan)
        sigma_wide[geometry, channel] = sigma
        sigma = sigma_wide
    return angles[np.sort(first)], values, sigma, wavelengths


# -- writing -------------------------------------------------------------------------------------

def write(table, path):
    """Write ``table`` to ``path`` as a gonio CSV (see the module docstring).

    Raises
    ------
    brdf.errors.InputError
        When the table cannot be stored: channels other than 1, RGB or spectral; a sample
        missing in some channels only, or with a missing sigma; repeated wavelengths; metadata
        keys that would not read back.
    """
    names, numbers = _rows_of(table)
    head = "\n".join([*_metadata_lines(table), ",".join(names)]) + "\n"
    # %r is Python's shortest repr that reads back to the same float64
    row = ",".join(["%r"] * len(names)) + "\n"
    with open(path, "w", encoding="utf-8", newline="\n") as f:
        f.write(head)
        for start in range(0, len(numbers), WRITE_CHUNK):
            block = numbers[start:start + WRITE_CHUNK]
            f.write((row * len(block)) % tuple(block.ravel().tolist()))


def _writable_angles(table):
    """The table's angles in degrees, polar angles clipped to [0, 90]: directions computed by a
    model may sit a rounding error below the horizon (accepted by the table)."""
    angles = np.array(table.angles, dtype=np.float64)
    angles[:, [0, 2]] = np.clip(angles[:, [0, 2]], 0.0, 90.0)
    return angles


def _rows_of(table):
    """``(column names, numbers (M, k))`` of the rows that store ``table``."""
    angles, values, sigma = _writable_angles(table), table.values, table.sigma
    measured = above_horizon(table)
    if table.wavelengths is not None:
        wavelengths = np.asarray(table.wavelengths, dtype=np.float64)
        if len(np.unique(wavelengths)) < len(wavelengths):
            raise InputError(f"{table.name}: repeated wavelengths {wavelengths.tolist()}; a gonio "
                             "CSV holds one value per geometry and wavelength")
        order = np.argsort(wavelengths, kind="stable")
        samples, k = np.nonzero(~np.isnan(values[:, order]) & measured[:, None])
        channel = order[k]
        names = ANGLES + SINGLE + (WAVELENGTH,)
        columns = [angles[samples], values[samples, channel][:, None],
                   wavelengths[channel][:, None]]
        if sigma is not None:
            names += SINGLE_SIGMA
            columns.append(sigma[samples, channel][:, None])
    else:
        layouts = {1: (SINGLE, SINGLE_SIGMA), 3: (RGB, RGB_SIGMA)}
        if table.channels not in layouts:
            raise InputError(f"{table.name}: {table.channels} channels without wavelengths; a "
                             "gonio CSV holds 1 channel, RGB or spectral tables (write .npz)")
        value_names, sigma_names = layouts[table.channels]
        samples = np.flatnonzero(~np.isnan(values).all(axis=1) & measured)
        names = ANGLES + value_names
        columns = [angles[samples], values[samples]]
        if sigma is not None:
            names += sigma_names
            columns.append(sigma[samples])
    numbers = np.hstack(columns)
    if not len(numbers):
        raise InputError(f"{table.name}: every sample is missing; nothing to write")
    bad = ~np.isfinite(numbers).all(axis=1)
    if bad.any():
        k = samples[np.argmax(bad)]
        raise InputError(f"{table.name}: sample {k} has a value missing in some channels only or "
                         "a missing sigma; a gonio CSV row needs every number (write .npz)")
    return names, numbers


def _metadata_lines(table):
    """``# key: value`` lines: the isotropy flag, then the metadata with its provenance."""
    return [f"# {ISOTROPIC_KEY}: {'true' if table.isotropic else 'false'}",
            *metadata_comment_lines(table, _KEY_VALUE, skip=(ISOTROPIC_KEY,))]


def metadata_comment_lines(table, pattern, skip=()):
    """``# key: value`` lines of :func:`provenance_metadata` but the keys in ``skip``, values
    that are not text as JSON; ``pattern`` is the reader's regular expression of such a line,
    which every key must match back (its group 1)."""
    lines = []
    for key, value in provenance_metadata(table).items():
        if key in skip:
            continue
        match = pattern.fullmatch(f"# {key}: x")
        if not match or match.group(1) != key:
            raise InputError(f"{table.name}: metadata key {key!r} cannot be written as a "
                             "'# key: value' line (keys have no colon, newline or surrounding "
                             "spaces)")
        if not isinstance(value, str):
            try:
                value = json.dumps(value, ensure_ascii=False)
            except TypeError as e:
                raise InputError(f"{table.name}: metadata[{key!r}] is not JSON ({e})") from None
        lines.extend(f"# {key}: {part}" for part in value.split("\n"))
    return lines
