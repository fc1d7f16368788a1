"""ALTA's data format, text and binary (the ALTA BRDF library, github.com/belcour/alta).

Written from ALTA's description, ``documents/data-formats.dox``, and from what its sources do:
the header parser ``arguments::parse_header`` (``sources/core/args.h``), the text reader
``load_data_from_text`` (``sources/core/data_storage.cpp``) and the parameterisations
``params::to_cartesian`` / ``from_cartesian`` (``sources/core/params.h``, ``params.cpp``). A
file looks like this::

    #DIM 3 1
    #PARAM_IN  ISOTROPIC_TV_TL_DPHI
    #PARAM_OUT INV_STERADIAN
    #VS 1
    0.5235987755982988 0.7853981633974483 3.141592653589793 0.4183 0.012
    ...

Rules (the reader enforces them; the writer follows them):

- UTF-8 text, white-space separated numbers, ``\\n`` or ``\\r\\n`` line ends.
- The header is the run of ``#`` lines at the top of the file. ``#KEY value`` (a letter right
  after the ``#``) is a header entry; ``# ...`` is a comment. It ends at the first line that is
  not a ``#`` line, or at ``#ALTA END HEADER`` (also ``#ALTA_END_HEADER``, ``#ALTA_HEADER_END``).
  Other ``#ALTA...`` marker lines are skipped.
- ``#DIM N P``: N input numbers (the parameterisation's dimension) and P outputs per sample.
- ``#PARAM_IN NAME``: how the N numbers place the sample; one of :data:`PARAMS` (angles in
  radians; ALTA's "view" V is our ``wo``, its "light" L our ``wi``, both pointing away from the
  surface). Required: without it the samples have no geometry.
- ``#PARAM_OUT NAME``: the meaning of the P outputs, one of :data:`OUTPUTS`. A file without one
  (or with ``UNKNOWN_OUTPUT``) is read as ``INV_STERADIAN``, BRDF in 1/sr, and
  ``metadata["param_out"]`` says so (``brdf-fit info`` shows it). ``ENERGY`` has no unit ALTA
  defines and is refused.
- ``#VS k`` or ``#VS k_1 ... k_P`` (default 0): the "vertical segment" (confidence interval) of
  each output. 0: none; 1: one number after the outputs, a radius r, interval [y - r, y + r];
  2: two numbers a, b, interval [y - a, y + b] (ALTA reads them as distances below and above
  since its commit 302c046 of 2017). One value applies to every output. Intervals follow the
  P outputs in output order. They become ``Table.sigma``: sigma = r, or (a + b) / 2, i.e. the
  interval is read as one standard deviation either side; ``metadata["vs"]`` states it. (ALTA's
  own reader takes the interval of the first output only and gives the others its ``--dt``
  default; rows laid out that way, with P > 1, are refused as ambiguous. It reads the files
  written here, whose ``#VS 1 1 1`` it takes as 1, with the first output's radius.)
- Other header entries (``#SAMPLE``, ``#URL``, ...) and ``# key: value`` comments go to
  ``Table.metadata``.
- After the header, each non-blank line that does not start with ``#`` is one sample: exactly N +
  P (+ the interval numbers) finite numbers. Anything else (a missing or extra number, NaN, a
  polar angle outside [0, pi/2], a direction below the horizon, a negative radius) is an error
  naming the line.

ALTA's binary data format is read too: the same header with ``#FORMAT binary``, ``#VERSION 0``,
``#PRECISION ieee754-double``, ``#SAMPLE_COUNT n``, ``#ENDIAN little|big``, ending with
``#BEGIN_STREAM`` (or ``#ALTA END HEADER``); then n rows of N + P doubles, optionally followed by
``#END_STREAM``. Binary files with ``#VS`` intervals are refused: ALTA's binary writer stores
each output's interval bounds, its reader expects a number of offsets per sample.

Writing (``brdf.write(table, "x.alta")``) stores 1-channel tables as ``INV_STERADIAN``, RGB as
``RGB_COLOR`` (channels named X, Y, Z as ``XYZ_COLOR``), in ``ISOTROPIC_TV_TL_DPHI`` for isotropic
tables and ``CARTESIAN`` otherwise (``param=`` picks another), with ``#VS 1`` radii equal to
sigma when the table has sigma, numbers in the shortest form that reads back to the same
float64. Samples missing in every channel and samples below the horizon are left out; a value
missing in some channels only, spectral tables and other channel counts are refused.
"""

import re
from dataclasses import dataclass

import numpy as np

from ..errors import FormatError, InputError
from ..geometry import (cartesian_to_spherical, directions_from_half_diff,
                        half_diff_from_directions, spherical_to_cartesian)
from ..table import Table
from . import _text, read_bytes, source_of
from .files import MAX_BYTES
from .gonio_csv import above_horizon, metadata_comment_lines

__all__ = ["read", "write", "sniff", "FORMAT", "EXTENSIONS", "PARAMS", "OUTPUTS"]

FORMAT = "alta"
# ALTA data files are also named .dat or .txt, too generic to claim: those are read by content
EXTENSIONS = (".alta",)

#: Slack on directions' z (and unit length) for files that print angles or vectors rounded:
#: the angle rounding of the other text readers (its sine, to the digits that matter).
DIRECTION_ROUNDING = _text.RADIAN_ROUNDING
#: Smallest cos(theta_o) an ``INV_STERADIAN_COSINE_FACTOR`` value is divided by; at grazing view
#: (within the angle rounding of 90 degrees) the BRDF is left missing rather than made huge.
MIN_COSINE = DIRECTION_ROUNDING
#: Metadata keys the reader writes about the file itself (the writer does not copy them).
OWN_KEYS = ("param_in", "param_out", "vs")


# -- parameterisations ---------------------------------------------------------------------------

@dataclass(frozen=True)
class Param:
    """One of ALTA's input parameterisations: its column names, the kind of each column
    (``polar``, ``azimuth``, ``projected`` or ``vector``) and whether it holds isotropic
    materials only (no absolute azimuth)."""

    name: str
    columns: tuple
    kinds: tuple
    isotropic: bool

    @property
    def dimension(self):
        return len(self.columns)


PARAMS = {p.name: p for p in (
    # params.h: "We always pack the view vector first: [V.x, V.y, V.z, L.x, L.y, L.z]"
    Param("CARTESIAN", ("V.x", "V.y", "V.z", "L.x", "L.y", "L.z"), ("vector",) * 6, False),
    # params.cpp to_cartesian: V = (theta_v, phi_v) = (invec[2], invec[3]), L = (invec[0], invec[1])
    Param("SPHERICAL_TL_PL_TV_PV", ("theta_l", "phi_l", "theta_v", "phi_v"),
          ("polar", "azimuth", "polar", "azimuth"), False),
    # params.cpp: half_to_cartesian(theta_h, phi_h, theta_d, phi_d), the difference vector is V
    Param("RUSIN_TH_PH_TD_PD", ("theta_h", "phi_h", "theta_d", "phi_d"),
          ("polar", "azimuth", "polar", "azimuth"), False),
    # params.cpp: half_to_cartesian(theta_h, 0, theta_d, phi_d)
    Param("RUSIN_TH_TD_PD", ("theta_h", "theta_d", "phi_d"), ("polar", "polar", "azimuth"),
          True),
    # params.cpp: classical_to_cartesian(invec[0], 0, invec[1], invec[2]): V = (theta_v, 0),
    # L = (theta_l, delta_phi); from_cartesian: delta_phi = phi_l - phi_v
    Param("ISOTROPIC_TV_TL_DPHI", ("theta_v", "theta_l", "delta_phi"),
          ("polar", "polar", "azimuth"), True),
    # params.h: [theta_l, theta_v cos(dphi), theta_v sin(dphi)]; to_cartesian puts L at phi = 0
    # and V at azimuth atan2(y, x), so dphi = phi_v - phi_l (from_cartesian uses phi_l - phi_v,
    # the mirror image, the same for isotropic materials; this module follows to_cartesian)
    Param("ISOTROPIC_TL_TV_PROJ_DPHI", ("theta_l", "theta_v cos(dphi)", "theta_v sin(dphi)"),
          ("polar", "projected", "projected"), True),
)}

#: Every input parameterisation name of ALTA's params.cpp (to tell "not read" from "unknown").
ALTA_PARAMS = ("COS_TH", "COS_TK", "COS_TLV", "COS_TLR", "RUSIN_TH_TD", "COS_TH_TD",
               "ISOTROPIC_TV_PROJ_DPHI", "STARK_2D", "NEUMANN_2D", "RUSIN_TH_TD_PD",
               "ISOTROPIC_TV_TL_DPHI", "RUSIN_VH", "SCHLICK_VH", "ISOTROPIC_TL_TV_PROJ_DPHI",
               "SCHLICK_TL_TK_PROJ_DPHI", "RETRO_TL_TVL_PROJ_DPHI", "STARK_3D", "NEUMANN_3D",
               "RUSIN_TH_PH_TD_PD", "SPHERICAL_TL_PL_TV_PV", "STEREOGRAPHIC", "CARTESIAN",
               "RUSIN_TH_PH_TD", "ISOTROPIC_TV_TL", "UNKNOWN_INPUT", "UNKNOWN")


def _to_directions(param, x):
    """``(wi, wo)`` (n, 3) of the input numbers ``x`` (n, N) in ``param`` (ALTA's
    ``params::to_cartesian``), not yet checked against the horizon."""
    name = param.name
    if name == "CARTESIAN":
        return x[:, 3:6], x[:, 0:3]
    if name == "SPHERICAL_TL_PL_TV_PV":
        return spherical_to_cartesian(x[:, 0], x[:, 1]), spherical_to_cartesian(x[:, 2], x[:, 3])
    if name in ("RUSIN_TH_PH_TD_PD", "RUSIN_TH_TD_PD"):
        th, ph, td, pd = (x.T if name == "RUSIN_TH_PH_TD_PD"
                          else (x[:, 0], np.zeros(len(x)), x[:, 1], x[:, 2]))
        # Rusinkiewicz 1998 section 3; ALTA rotates the difference vector into V (params.h
        # half_to_cartesian), where geometry.directions_from_half_diff returns it first
        view, light = directions_from_half_diff(th, ph, td, pd)
        return light, view
    if name == "ISOTROPIC_TV_TL_DPHI":
        return (spherical_to_cartesian(x[:, 1], x[:, 2]),
                spherical_to_cartesian(x[:, 0], np.zeros(len(x))))
    if name == "ISOTROPIC_TL_TV_PROJ_DPHI":
        theta_v = np.hypot(x[:, 1], x[:, 2])
        # at theta_v = 0 the azimuth is undefined: V is the normal (params.cpp)
        phi_v = np.where(theta_v > 0.0, np.arctan2(x[:, 2], x[:, 1]), 0.0)
        return (spherical_to_cartesian(x[:, 0], np.zeros(len(x))),
                spherical_to_cartesian(theta_v, phi_v))
    raise AssertionError(name)


def _from_directions(param, wi, wo):
    """The input numbers (n, N) of the sample directions in ``param`` (the inverse of
    :func:`_to_directions`)."""
    name = param.name
    if name == "CARTESIAN":
        return np.hstack([wo, wi])
    theta_l, phi_l = cartesian_to_spherical(wi)
    theta_v, phi_v = cartesian_to_spherical(wo)
    theta_l, theta_v = np.clip(theta_l, 0.0, np.pi / 2), np.clip(theta_v, 0.0, np.pi / 2)
    if name == "SPHERICAL_TL_PL_TV_PV":
        return np.stack([theta_l, phi_l, theta_v, phi_v], axis=1)
    if name in ("RUSIN_TH_PH_TD_PD", "RUSIN_TH_TD_PD"):
        # the difference vector is V's (params.cpp from_cartesian rotates invec[0..2])
        th, ph, td, pd = half_diff_from_directions(wo, wi)
        columns = [th, ph, td, pd] if name == "RUSIN_TH_PH_TD_PD" else [th, td, pd]
        return np.stack(columns, axis=1)
    if name == "ISOTROPIC_TV_TL_DPHI":
        return np.stack([theta_v, theta_l, np.mod(phi_l - phi_v, 2 * np.pi)], axis=1)
    if name == "ISOTROPIC_TL_TV_PROJ_DPHI":
        dphi = phi_v - phi_l
        return np.stack([theta_l, theta_v * np.cos(dphi), theta_v * np.sin(dphi)], axis=1)
    raise AssertionError(name)


# -- output kinds --------------------------------------------------------------------------------

@dataclass(frozen=True)
class Output:
    """One of ALTA's output kinds: the channel count it holds (None: any) and channel names."""

    name: str
    channels: int | None
    names: tuple | None
    cosine: bool = False


OUTPUTS = {o.name: o for o in (
    # params.h: "Output values in inverse steradian (sr-1). This is the standard definition"
    Output("INV_STERADIAN", None, None),
    # params.h: "in inverse steradian (sr-1) weighted by the cosine factor of the output
    # direction": f cos(theta_o), theta_o the view direction V's (ALTA's diffuse plugin
    # bootstraps its albedo dividing by both cosines; the declaration is followed here)
    Output("INV_STERADIAN_COSINE_FACTOR", None, None, cosine=True),
    Output("RGB_COLOR", 3, ("r", "g", "b")),
    Output("XYZ_COLOR", 3, ("X", "Y", "Z")),
)}
#: ``#PARAM_OUT`` values read as "not stated" (ALTA's parse_output falls back to UNKNOWN_OUTPUT).
UNSTATED_OUTPUTS = ("UNKNOWN_OUTPUT", "UNKNOWN", "UNKNOWN_PARAMETRIZATION")
DEFAULT_OUTPUT = "INV_STERADIAN"


def _channel_names(output, count):
    if output.names is not None:
        return output.names
    return ("value",) if count == 1 else tuple(f"c{k}" for k in range(count))


# -- reading -------------------------------------------------------------------------------------

_HEADER_KEY = re.compile(r"#([A-Za-z][^\s]*)\s*(.*?)\s*")
_COMMENT_KEY_VALUE = re.compile(r"#\s+([^:\s][^:]*?)\s*:(?:\s+(.*?))?\s*")
_END_MARKERS = ("ALTA_END_HEADER", "ALTA_HEADER_END")
_OWN_HEADER = ("DIM", "PARAM_IN", "PARAM_OUT", "VS", "FORMAT", "VERSION", "PRECISION",
               "SAMPLE_COUNT", "ENDIAN")


def sniff(head):
    """True when the ``#`` lines at the top of the file (blank lines before them skipped)
    include a ``#DIM`` entry of two integers."""
    text = head.decode("utf-8", "replace").removeprefix("\ufeff")
    for line in text.split("\n"):
        line = line.strip()
        if not line:
            continue
        if not line.startswith("#"):
            return False
        match = _HEADER_KEY.fullmatch(line)
        if match and match.group(1) == "DIM":
            return bool(re.fullmatch(r"\d+\s+\d+", match.group(2)))
    return False


@dataclass
class _Header:
    entries: dict          # key -> (value, line)
    metadata: dict
    end: int               # index of the first line after the header


def _header(path, lines):
    entries, metadata = {}, {}
    index = 0
    while index < len(lines) and not lines[index].strip():
        index += 1
    while index < len(lines):
        text = lines[index].strip()
        number = index + 1
        if not text.startswith("#"):
            break
        index += 1
        words = text[1:].split()
        if words[:1] == ["ALTA"] and words[1:3] == ["END", "HEADER"] or (
                words[:1] and words[0] in _END_MARKERS):
            break
        match = _HEADER_KEY.fullmatch(text)
        if match is None:  # a comment
            pair = _COMMENT_KEY_VALUE.fullmatch(text)
            if pair:
                key, value = pair.group(1), pair.group(2) or ""
                metadata[key] = f"{metadata[key]}\n{value}" if key in metadata else value
            continue
        key, value = match.group(1), match.group(2)
        if key.startswith("ALTA") or key in ("BEGIN_STREAM", "END_STREAM"):  # markers
            continue
        if key in _OWN_HEADER:
            if key in entries:
                raise FormatError(path, f"line {number}", f"#{key} appears twice (lines "
                                                          f"{entries[key][1]} and {number}); "
                                                          "expected it once")
            entries[key] = (value, number)
        else:
            metadata[key] = f"{metadata[key]}\n{value}" if key in metadata else value
    return _Header(entries, metadata, index)


def _dim(path, header):
    if "DIM" not in header.entries:
        raise FormatError(path, "header", "no #DIM line; expected '#DIM N P' (N input numbers, "
                                          "P outputs per sample) at the top of the file")
    value, line = header.entries["DIM"]
    match = re.fullmatch(r"(\d+)\s+(\d+)", value)
    if not match or int(match.group(2)) < 1:
        raise FormatError(path, f"line {line}", f"#DIM {value!r}; expected two integers N P "
                                                "(input numbers, outputs; P >= 1)")
    return int(match.group(1)), int(match.group(2))


def _param_in(path, header, n):
    supported = ", ".join(PARAMS)
    if "PARAM_IN" not in header.entries:
        raise FormatError(path, "header", f"no #PARAM_IN line; expected the input "
                                          f"parameterisation, one of {supported}")
    value, line = header.entries["PARAM_IN"]
    if value not in PARAMS:
        what = "is not read" if value in ALTA_PARAMS else "is unknown"
        raise FormatError(path, f"line {line}", f"#PARAM_IN {value!r} {what}; expected one of "
                                                f"{supported}")
    param = PARAMS[value]
    if n != param.dimension:
        dim_line = header.entries["DIM"][1]
        raise FormatError(path, f"line {dim_line}", f"#DIM gives {n} input numbers; {value} has "
                                                    f"{param.dimension} "
                                                    f"({', '.join(param.columns)})")
    return param


def _param_out(path, header, p):
    """``(Output, note)``: the output kind and what ``metadata["param_out"]`` says."""
    value, line = header.entries.get("PARAM_OUT", ("", None))
    if value in ("",) + UNSTATED_OUTPUTS:
        shown = "none in the file" if not value else f"{value} in the file"
        return OUTPUTS[DEFAULT_OUTPUT], (f"{shown}; read as {DEFAULT_OUTPUT} (BRDF in 1/sr, no "
                                         "cosine factor)")
    if value not in OUTPUTS:
        why = ("ALTA defines no unit for ENERGY" if value == "ENERGY" else "unknown")
        raise FormatError(path, f"line {line}", f"#PARAM_OUT {value!r}: {why}; expected one of "
                                                f"{', '.join(OUTPUTS)}")
    output = OUTPUTS[value]
    if output.channels is not None and output.channels != p:
        raise FormatError(path, f"line {line}", f"#PARAM_OUT {value} holds {output.channels} "
                                                f"outputs but #DIM gives {p}; expected "
                                                f"#DIM N {output.channels}")
    return output, value


def _vs(path, header, p):
    """Interval kind (0, 1 or 2) of the outputs (the same for all) and the #VS line."""
    value, line = header.entries.get("VS", ("0", None))
    words = value.split()
    if not words or any(w not in ("0", "1", "2") for w in words) or len(words) not in (1, p):
        raise FormatError(path, f"line {line}", f"#VS {value!r}; expected 0, 1 or 2, once or "
                                                f"once per output ({p})")
    if len(set(words)) > 1:
        raise FormatError(path, f"line {line}", f"#VS {value!r} mixes interval kinds; expected "
                                                "the same kind for every output (each needs a "
                                                "sigma or none does)")
    return int(words[0]), line


def read(path, isotropic=None):
    """Read an ALTA data file, text or binary (rules in the module docstring).

    Parameters
    ----------
    path : str or path-like
    isotropic : bool, optional
        Declare the material isotropic or not; by default isotropic for the parameterisations
        without an absolute azimuth (``RUSIN_TH_TD_PD``, ``ISOTROPIC_*``), anisotropic for the
        others (``CARTESIAN``, ``SPHERICAL_TL_PL_TV_PV``, ``RUSIN_TH_PH_TD_PD``).

    Returns
    -------
    Table
        Values ``(N, P)`` in 1/sr (``INV_STERADIAN_COSINE_FACTOR`` divided by cos theta_o;
        ``NaN`` where theta_o is 90 degrees), ``sigma`` from the ``#VS`` intervals,
        ``metadata["param_in"]``, ``["param_out"]`` (with the default when the file names
        none), ``["vs"]`` and the file's other header entries.

    Raises
    ------
    brdf.errors.FormatError
        The first violation of the rules, naming the line and what was expected.
    """
    if isotropic is not None and not isinstance(isotropic, bool):
        raise InputError(f"isotropic must be True, False or None, got {isotropic!r}")
    data = read_bytes(path, MAX_BYTES, "an ALTA data file")
    stream = _binary_stream_start(path, data)
    expected = "an ALTA header (#DIM N P, #PARAM_IN ...) and rows of numbers"
    lines = _text.decode_lines(path, data if stream is None else data[:stream], expected)
    header = _header(path, lines)
    value, line = header.entries.get("FORMAT", ("text", None))
    if value not in ("text", "binary"):
        raise FormatError(path, f"line {line}", f"#FORMAT {value!r}; expected text or binary")
    if (value == "binary") != (stream is not None):  # a #FORMAT line _binary_stream_start missed
        raise FormatError(path, f"line {line}", f"#FORMAT {value} after text that does not look "
                                                "like an ALTA header; expected it among the "
                                                "# lines at the top of the file")
    n, p = _dim(path, header)
    param = _param_in(path, header, n)
    output, out_note = _param_out(path, header, p)
    kind, vs_line = _vs(path, header, p)
    if stream is None:
        numbers, line_numbers = _numbers(path, lines, header.end, param, p, kind)

        def place(k):
            return f"line {line_numbers[k]}"
    else:
        if kind:
            raise FormatError(path, f"line {vs_line}", "#VS in a binary file: ALTA's binary "
                                                       "writer and reader disagree on where "
                                                       "the intervals go; expected #VS 0")
        numbers = _binary_numbers(path, data, stream, header, n + p)

        def place(k):
            return f"sample {k + 1} (byte {stream + 8 * (n + p) * k})"

    wi, wo = _directions(path, numbers[:, :n], place, param)
    values = numbers[:, n:n + p]
    sigma = _sigma(path, numbers[:, n + p:], place, p, kind)
    metadata = {"param_in": param.name, "param_out": out_note}
    if kind:
        metadata["vs"] = (f"{kind}: radius r per output read as sigma = r" if kind == 1 else
                          f"{kind}: interval [y - a, y + b] per output read as sigma = (a + b) / 2")
    if output.cosine:
        values, sigma, grazing = _divide_cosine(path, values, sigma, wo, place)
        metadata["param_out"] += (": values divided by cos theta_o" + (
            f"; {grazing} samples at grazing view (theta_o = 90 deg) left missing"
            if grazing else ""))
    for key, value in header.metadata.items():
        metadata.setdefault(key, value)
    table = Table(wi, wo, values, sigma=sigma, channel_names=_channel_names(output, p),
                  isotropic=param.isotropic if isotropic is None else isotropic,
                  metadata=metadata, source=source_of(path, data, FORMAT))
    table.format = FORMAT
    return table


#: The header lines after which a binary stream starts (data-formats.dox, and ALTA's tests).
_STREAM_MARKERS = (b"#BEGIN_STREAM", b"#ALTA END HEADER", b"#ALTA_END_HEADER",
                   b"#ALTA_HEADER_END")
#: Most header lines looked at for ``#FORMAT binary``.
_MAX_HEADER_LINES = 1000


def _binary_stream_start(path, data):
    """Byte offset of the binary stream when the ``#`` lines at the top of ``data`` say
    ``#FORMAT binary`` (the stream follows the line ``#BEGIN_STREAM`` or ``#ALTA END
    HEADER``), else None (a text file)."""
    binary, start = False, 0
    for number in range(1, _MAX_HEADER_LINES + 1):
        end = data.find(b"\n", start)
        line = (data[start:] if end < 0 else data[start:end]).strip()
        if line and not line.startswith(b"#"):
            break
        if re.fullmatch(rb"#FORMAT\s+binary", line):
            binary = True
        elif binary and (line in _STREAM_MARKERS or re.fullmatch(rb"#ALTA\s+END\s+HEADER", line)):
            return end + 1
        if end < 0:
            break
        start = end + 1
    if binary:
        raise FormatError(path, f"line {number}", "#FORMAT binary without #BEGIN_STREAM (or "
                                                  "#ALTA END HEADER) before the stream; expected "
                                                  "the header to end with one")
    return None


def _binary_numbers(path, data, start, header, width):
    """The samples of a binary stream, ``(SAMPLE_COUNT, width)`` float64 (ALTA's
    load_data_from_binary: row order, one IEEE 754 double per number)."""
    checks = (("VERSION", ("0",)), ("PRECISION", ("ieee754-double",)),
              ("ENDIAN", ("little", "big")))
    for key, allowed in checks:
        value, line = header.entries.get(key, (None, None))
        if value is None:
            raise FormatError(path, "header", f"no #{key} line in a binary file; expected "
                                              f"#{key} {' or '.join(allowed)}")
        if value not in allowed:
            raise FormatError(path, f"line {line}", f"#{key} {value!r}; expected "
                                                    f"{' or '.join(allowed)}")
    value, line = header.entries.get("SAMPLE_COUNT", (None, None))
    if value is None or not re.fullmatch(r"[1-9]\d{0,15}", value):
        where = "header" if line is None else f"line {line}"
        raise FormatError(path, where, f"#SAMPLE_COUNT {value!r}; expected the number of "
                                       "samples, a positive integer")
    count = int(value)
    need = 8 * width * count
    stream = data[start:]
    if len(stream) < need:
        raise FormatError(path, f"byte {len(data)}", f"binary stream of {len(stream):,} bytes; "
                                                     f"expected {need:,} ({count:,} samples x "
                                                     f"{width} doubles): truncated")
    rest = stream[need:].strip()
    if rest not in (b"", b"#END_STREAM"):
        raise FormatError(path, f"byte {start + need}", f"{len(stream) - need:,} bytes after "
                                                        f"the {count:,} samples; expected "
                                                        "#END_STREAM or the end of the file")
    order = "<" if header.entries["ENDIAN"][0] == "little" else ">"
    numbers = np.frombuffer(stream, dtype=f"{order}f8", count=width * count)
    numbers = numbers.astype(np.float64).reshape(count, width)
    bad = ~np.isfinite(numbers)
    if bad.any():
        k, c = np.argwhere(bad)[0]
        raise FormatError(path, f"sample {k + 1} (byte {start + 8 * (width * k + c)})",
                          f"number {c + 1} is {float(numbers[k, c])!r}; expected a finite number")
    return numbers


def _numbers(path, lines, start, param, p, kind):
    """The sample rows as floats ``(M, N + P + interval numbers)`` and their line numbers."""
    n = param.dimension
    width = n + p + kind * p
    body = [(k, s) for k, s in enumerate(lines[start:], start + 1)
            if s.strip() and not s.lstrip().startswith("#")]
    if not body:
        raise FormatError(path, f"line {len(lines) + 1}", f"end of file after the header; "
                                                          f"expected rows of {width} numbers")
    texts = [s for _, s in body]
    line_numbers = np.array([k for k, _ in body])
    # numpy's parser is fast but cannot say where a row is bad: only on failure are the rows
    # split one by one to name the first bad one
    try:
        numbers = np.loadtxt(texts, comments=None, ndmin=2, dtype=np.float64)
        if numbers.shape[1] == width and np.isfinite(numbers).all():
            return numbers, line_numbers
    except ValueError:
        pass
    def column(c):  # named on demand: #DIM may announce any number of outputs
        if c < n:
            return param.columns[c]
        if c < n + p:
            return f"output {c - n + 1}"
        m = c - n - p
        return f"{'radius' if kind == 1 else ('a', 'b')[m % 2]} of output {m // kind + 1}"

    rows = [s.split() for s in texts]
    for row, line in zip(rows, line_numbers):
        if len(row) != width:
            if kind and p > 1 and len(row) == n + p + kind:
                raise FormatError(path, f"line {line}", f"{len(row)} numbers: an interval for "
                                                        f"the first output only; expected "
                                                        f"{width}, an interval per output")
            shown = ", ".join(column(c) for c in range(min(width, 12)))
            raise FormatError(path, f"line {line}", f"{len(row)} numbers; expected {width}: "
                                                    f"{shown}{', ...' * (width > 12)}")

    def locate(k):
        return f"line {line_numbers[k // width]}", f"{column(k % width)}: "

    tokens = [t for row in rows for t in row]
    return _text.floats(path, tokens, locate).reshape(-1, width), line_numbers


def _directions(path, x, place, param):
    """``(wi, wo)`` of the input numbers, after checking their ranges and the horizon."""
    def locate_column(c):
        return lambda k: (place(k), f"{param.columns[c]}: ")

    x = x.copy()
    with np.errstate(over="ignore"):  # a huge number overflows to inf, refused by its range
        return _checked_directions(path, x, place, param, locate_column)


def _checked_directions(path, x, place, param, locate_column):
    for c, kind in enumerate(param.kinds):
        if kind == "polar":
            x[:, c] = _text.check_polar(path, x[:, c], locate_column(c))
        elif kind == "azimuth":
            _text.check_azimuth(path, x[:, c], locate_column(c))
    if "projected" in param.kinds:
        radius = np.hypot(x[:, 1], x[:, 2])
        _text.check_range(path, radius, 0.0, 0.5 * np.pi + _text.RADIAN_ROUNDING,
                          lambda k: (place(k), "theta_v = hypot of the "
                                                                "projected pair: "), " rad")
        scale = np.minimum(1.0, 0.5 * np.pi / np.maximum(radius, 1e-300))
        x[:, 1:3] *= scale[:, None]
    if param.name == "CARTESIAN":
        for c, what in ((0, "V"), (3, "L")):
            length = np.linalg.norm(x[:, c:c + 3], axis=1)
            _text.check_range(path, length, 1.0 - DIRECTION_ROUNDING, 1.0 + DIRECTION_ROUNDING,
                              lambda k, what=what: (place(k),
                                                    f"|{what}| (a unit vector): "))
            # vectors printed with few digits are normalised; full-precision ones are kept
            # bit for bit (a written table reads back exactly)
            rounded = np.abs(length - 1.0) > 1e-12
            x[rounded, c:c + 3] /= length[rounded, None]
    wi, wo = _to_directions(param, x)
    for w, what in ((wo, "view direction V"), (wi, "light direction L")):
        below = w[:, 2] < -DIRECTION_ROUNDING
        if below.any():
            k = int(np.argmax(below))
            values = ", ".join(f"{c} = {v:.10g}" for c, v in zip(param.columns, x[k]))
            raise FormatError(path, place(k), f"{values} puts the {what} below "
                                                               f"the horizon (z = {w[k, 2]:.3g});"
                                                               " expected both directions above "
                                                               "it")
    return _onto_hemisphere(wi), _onto_hemisphere(wo)


def _onto_hemisphere(w):
    """Directions a rounding error below the horizon moved onto it (z = 0, renormalised)."""
    w = np.array(w, dtype=np.float64)
    low = w[:, 2] < 0.0
    if low.any():
        w[low, 2] = 0.0
        w[low] /= np.linalg.norm(w[low], axis=1, keepdims=True)
    return w


def _sigma(path, intervals, place, p, kind):
    """Sigma ``(M, P)`` of the interval numbers (None without intervals)."""
    if not kind:
        return None
    bad = intervals < 0.0
    if bad.any():
        k, c = np.argwhere(bad)[0]
        what = "radius" if kind == 1 else ("a (distance below)", "b (distance above)")[c % 2]
        raise FormatError(path, place(k), f"{what} of output {c // kind + 1} "
                                                           f"is {intervals[k, c]:.10g}; expected "
                                                           "a distance >= 0")
    if kind == 1:
        return intervals
    return 0.5 * (intervals[:, 0::2] + intervals[:, 1::2])


def _divide_cosine(path, values, sigma, wo, place):
    """``values / cos(theta_o)`` (and sigma), NaN at grazing view; and how many are missing."""
    cosine = wo[:, 2:3]
    grazing = cosine[:, 0] < MIN_COSINE
    safe = np.where(grazing[:, None], 1.0, cosine)
    with np.errstate(over="ignore"):
        values = np.where(grazing[:, None], np.nan, values / safe)
        if sigma is not None:
            sigma = np.where(grazing[:, None], np.nan, sigma / safe)
    for what, array in (("output", values), ("interval of output", sigma)):
        if array is not None and np.isinf(array).any():
            k, c = np.argwhere(np.isinf(array))[0]
            raise FormatError(path, place(k), f"{what} {c + 1} divided by "
                                                               f"cos theta_o = {safe[k, 0]:.3g} "
                                                               "overflows; expected a BRDF "
                                                               "cosine below 1e308")
    return values, sigma, int(grazing.sum())


# -- writing -------------------------------------------------------------------------------------

#: Rows formatted per write call (bounds the memory of writing a MERL-size table).
WRITE_CHUNK = 65536


def write(table, path, param=None):
    """Write ``table`` to ``path`` as an ALTA text data file (see the module docstring).

    Parameters
    ----------
    param : str, optional
        A name of :data:`PARAMS`; by default ``ISOTROPIC_TV_TL_DPHI`` for an isotropic table
        and ``CARTESIAN`` for an anisotropic one.

    Raises
    ------
    brdf.errors.InputError
        A parameterisation that is not one of :data:`PARAMS`, or an isotropic one for an
        anisotropic table; a spectral table, a channel count other than 1 or 3; a value missing
        in some channels only, or a missing sigma; metadata that is not JSON.
    """
    param = _write_param(table, param)
    output = _write_output(table)
    samples = np.flatnonzero(~np.isnan(table.values).all(axis=1) & above_horizon(table))
    if not len(samples):
        raise InputError(f"{table.name}: every sample is missing or below the horizon; nothing "
                         "to write")
    values = table.values[samples]
    columns = [_from_directions(param, _onto_hemisphere(table.wi[samples]),
                                _onto_hemisphere(table.wo[samples])), values]
    if table.sigma is not None:
        columns.append(table.sigma[samples])
    numbers = np.hstack(columns)
    bad = ~np.isfinite(numbers).all(axis=1)
    if bad.any():
        k = samples[np.argmax(bad)]
        raise InputError(f"{table.name}: sample {k} has a value missing in some channels only or "
                         "a missing sigma; an ALTA row needs every number (write .npz)")
    p = table.channels
    head = [f"#DIM {param.dimension} {p}", f"#PARAM_IN {param.name}", f"#PARAM_OUT {output}"]
    if table.sigma is not None:
        head.append("#VS " + " ".join(["1"] * p))
    head += _metadata_lines(table)
    row = " ".join(["%r"] * numbers.shape[1]) + "\n"
    with open(path, "w", encoding="utf-8", newline="\n") as f:
        f.write("\n".join(head) + "\n")
        for start in range(0, len(numbers), WRITE_CHUNK):
            block = numbers[start:start + WRITE_CHUNK]
            f.write((row * len(block)) % tuple(block.ravel().tolist()))


def _write_param(table, param):
    if param is None:
        return PARAMS["ISOTROPIC_TV_TL_DPHI" if table.isotropic else "CARTESIAN"]
    if not isinstance(param, str) or param not in PARAMS:
        raise InputError(f"param {param!r} is not an ALTA parameterisation this writer knows; "
                         f"expected one of {', '.join(PARAMS)}")
    if PARAMS[param].isotropic and not table.isotropic:
        full = ", ".join(name for name, p in PARAMS.items() if not p.isotropic)
        raise InputError(f"{table.name}: {param} holds isotropic materials only (no absolute "
                         f"azimuth) and the table is anisotropic; use one of {full}")
    return PARAMS[param]


def _write_output(table):
    """The #PARAM_OUT name for the table's channels."""
    if table.wavelengths is not None:
        raise InputError(f"{table.name}: {table.channels} wavelengths; ALTA's output kinds hold "
                         "one channel (INV_STERADIAN) or three colours (RGB_COLOR, XYZ_COLOR), "
                         "not spectra (write .csv or .npz)")
    if table.channels == 1:
        return "INV_STERADIAN"
    if table.channels == 3:
        return "XYZ_COLOR" if tuple(table.channel_names) == ("X", "Y", "Z") else "RGB_COLOR"
    raise InputError(f"{table.name}: {table.channels} channels; ALTA's output kinds hold one "
                     "channel (INV_STERADIAN) or three colours (RGB_COLOR, XYZ_COLOR) (write .npz)")


def _metadata_lines(table):
    """``# key: value`` comment lines (ALTA skips them; :func:`read` takes them back)."""
    return metadata_comment_lines(table, _COMMENT_KEY_VALUE, skip=OWN_KEYS)
