"""Native ``.npz`` tables: every array of a :class:`~brdf.table.Table`, stored losslessly.

An uncompressed numpy archive (``numpy.savez``) holding

================  ===============  ==================================================
array             shape, dtype     contents
================  ===============  ==================================================
format_version    (), int64        :data:`FORMAT_VERSION`; newer files are refused
wi, wo            (N, 3), float64  unit sample directions (local frame, z = normal)
values            (N, C), float64  BRDF in 1/sr, NaN = missing sample
channel_names     (C,), unicode    one name per channel
metadata          (), unicode      a JSON object (``Table.metadata`` + ``source``)
isotropic         (), bool         ``Table.isotropic``
sigma             (N, C), float64  optional: standard deviations
wavelengths       (C,), float64    optional: nm per channel (spectral tables)
angles            (N, 4), float64  optional: the degrees of an :class:`AngleTable`
                                   (a table read from a CSV), kept so a CSV written
                                   from the ``.npz`` reproduces the original file
================  ===============  ==================================================

A MERL table (:class:`~brdf.io.merl.MerlTable`) is stored as its grid instead: the array
``merl_raw`` (3, 90, 90, 180) of stored values (and ``sigma`` when it has one) replaces ``wi``,
``wo`` and ``values``, so MERL -> .npz -> MERL is bit-exact and reading gives back a MERL table
with its fast lookup.

Reading never unpickles (``allow_pickle=False``): a file holding Python objects is refused, so
an ``.npz`` from an untrusted source cannot run code. A table of a grid format (e.g. MERL) is
of another grid format is stored as its plain samples, without grid nodes below the horizon
that a plain table cannot hold (:func:`~brdf.io.gonio_csv.above_horizon`); the file it came from
stays recorded in ``metadata["source"]``.

Why uncompressed: the low mantissa bits of measured float64 values are noise that deflate cannot
shrink, so ``numpy.savez_compressed`` saves a third of the space (a MERL-size table, 1.458 M
samples x 3 channels with 1 % noise: 105 MB -> 68 MB) while writing takes 30 times longer
(3.3 s instead of 0.11 s, reading 0.65 s instead of 0.3 s). The format is for fast lossless round
trips; a lab archiving files can compress them with any tool.
"""

import io
import json
import math
import zipfile
import zlib

import numpy as np

from ..errors import BRDFError, FormatError, InputError
from ..geometry import directions_from_degrees
from ..table import AngleTable, Table
from . import read_bytes, source_of
from .files import MAX_BYTES
from .gonio_csv import above_horizon, provenance_metadata

__all__ = ["read", "write", "sniff", "FORMAT", "EXTENSIONS", "FORMAT_VERSION"]

FORMAT = "npz"
EXTENSIONS = (".npz",)
#: Version of the layout written here; a reader refuses files with a larger number.
FORMAT_VERSION = 1

REQUIRED = ("format_version", "wi", "wo", "values", "channel_names", "metadata", "isotropic")
OPTIONAL = ("sigma", "wavelengths", "angles")
#: The MERL grid layout: the stored grid replaces the samples.
GRID_REQUIRED = ("format_version", "merl_raw", "channel_names", "metadata", "isotropic")
GRID_OPTIONAL = ("sigma",)
#: Largest distance between a stored direction and the one its stored angles give (rounding of
#: sin/cos in degrees is ~1e-16; anything near this is a different direction).
ANGLE_TOL = 1e-9

_ZIP_MAGIC = b"PK\x03\x04"
_KINDS = {"f": "floating point", "i": "integer", "U": "unicode text", "b": "boolean"}


def sniff(head):
    """Whether the first bytes are a brdf ``.npz``: a zip archive whose first member (named at
    byte 30 of the local file header, PKWARE APPNOTE 4.3.7) is ``format_version.npy``."""
    name = b"format_version.npy"
    return head.startswith(_ZIP_MAGIC) and head[30:30 + len(name)] == name


def write(table, path):
    """Write every array of ``table`` to exactly ``path`` (no ``.npz`` appended).

    Raises
    ------
    brdf.errors.InputError
        When the metadata is not JSON.
    """
    try:
        metadata = json.dumps(provenance_metadata(table), ensure_ascii=False)
    except TypeError as e:
        raise InputError(f"{table.name}: metadata is not JSON ({e})") from None
    from .merl import MerlTable
    if isinstance(table, MerlTable):
        arrays = {"format_version": np.int64(FORMAT_VERSION), "merl_raw": table.raw,
                  "channel_names": np.array(table.channel_names, dtype=str),
                  "metadata": np.array(metadata), "isotropic": np.bool_(True)}
        if table.sigma is not None:
            arrays["sigma"] = np.asarray(table.sigma, dtype=np.float64)
        with open(path, "wb") as f:
            np.savez(f, **arrays)
        return
    keep = above_horizon(table)
    rows = slice(None) if keep.all() else keep  # a slice: no copy of the arrays

    def samples(a):
        return np.asarray(a, dtype=np.float64)[rows]

    # format_version first: sniff() recognises the file by its first member
    arrays = {"format_version": np.int64(FORMAT_VERSION), "wi": samples(table.wi),
              "wo": samples(table.wo), "values": samples(table.values),
              "channel_names": np.array(table.channel_names, dtype=str),
              "metadata": np.array(metadata), "isotropic": np.bool_(table.isotropic)}
    if table.sigma is not None:
        arrays["sigma"] = samples(table.sigma)
    if table.wavelengths is not None:
        arrays["wavelengths"] = np.asarray(table.wavelengths, dtype=np.float64)
    if isinstance(table, AngleTable):
        arrays["angles"] = samples(table.angles)
    # a file object, because savez appends ".npz" to a path that lacks it
    with open(path, "wb") as f:
        np.savez(f, **arrays)


def read(path):
    """Read a table written by :func:`write`.

    Returns
    -------
    Table
        An :class:`~brdf.table.AngleTable` when the file keeps the original degrees,
        otherwise a plain :class:`~brdf.table.Table`; ``source`` describes the ``.npz`` file.

    Raises
    ------
    brdf.errors.FormatError
        For a file that is not a zip archive, is truncated or corrupt, holds pickled objects,
        lacks arrays (all named), has arrays of the wrong shape or type, non-finite directions
        or angles, or a format version newer than :data:`FORMAT_VERSION`.
    """
    data = read_bytes(path, MAX_BYTES, "a .npz table")
    arrays = _arrays(data, path)
    version = _array(arrays, "format_version", path, "iu", (), "()")
    if not 1 <= int(version) <= FORMAT_VERSION:
        raise FormatError(path, "array format_version",
                          f"version {int(version)}; this reader knows versions 1 to "
                          f"{FORMAT_VERSION} (a newer brdf wrote the file?)")
    if "merl_raw" in arrays:
        return _merl_table(arrays, path, data)
    wi = _directions(arrays, "wi", path, None)
    n = len(wi)
    wo = _directions(arrays, "wo", path, n)
    values = _array(arrays, "values", path, "f", (n, None), f"({n}, C), one row per sample")
    c = values.shape[1]
    per_channel = f"({c},), one per channel"
    options = {
        "channel_names": tuple(_array(arrays, "channel_names", path, "U", (c,), per_channel)
                               .tolist()),
        "isotropic": bool(_array(arrays, "isotropic", path, "b", (), "()")),
        "metadata": _metadata(arrays, path),
        "source": source_of(path, data, FORMAT),
    }
    if "sigma" in arrays:
        options["sigma"] = _array(arrays, "sigma", path, "f", (n, c), f"({n}, {c}) like values")
    if "wavelengths" in arrays:
        options["wavelengths"] = _array(arrays, "wavelengths", path, "f", (c,), per_channel)
    try:
        if "angles" in arrays:
            table = AngleTable(wi, wo, values, angles=_angles(arrays, wi, wo, path), **options)
        else:
            table = Table(wi, wo, values, **options)
    except InputError as e:
        raise FormatError(path, "", str(e)) from None
    table.format = FORMAT
    return table


def _merl_table(arrays, path, data):
    """The MERL grid layout back as a :class:`~brdf.io.merl.MerlTable`."""
    from .merl import SHAPE, SIZE, MerlTable, check_measured
    raw = _array(arrays, "merl_raw", path, "f", (3,) + SHAPE, f"(3,) + {SHAPE}")
    if not np.isfinite(raw).all():
        raise FormatError(path, "array merl_raw", "holds NaN or infinite values; expected "
                                                  "finite stored values (negative = missing)")
    check_measured(path, raw, "array merl_raw")
    sigma = (_array(arrays, "sigma", path, "f", (SIZE, 3), f"({SIZE}, 3)")
             if "sigma" in arrays else None)
    metadata = _metadata(arrays, path)
    return MerlTable(raw, sigma=sigma, metadata=metadata, source=source_of(path, data, FORMAT))


def _arrays(data, path):
    """``{name: array}`` of every member, after checking that the expected ones are there."""
    if not data.startswith(_ZIP_MAGIC):
        raise FormatError(path, "byte 0", "not a zip archive; expected a .npz written by brdf")
    try:
        archive = np.load(io.BytesIO(data), allow_pickle=False)
    except (zipfile.BadZipFile, ValueError, EOFError) as e:
        raise FormatError(path, "", f"truncated or corrupt .npz archive ({e})") from None
    with archive:
        names = set(archive.files)
        required, optional = ((GRID_REQUIRED, GRID_OPTIONAL) if "merl_raw" in names
                              else (REQUIRED, OPTIONAL))
        missing = [name for name in required if name not in names]
        if missing:
            raise FormatError(path, "", f"missing array{'s' * (len(missing) > 1)} "
                                        f"{', '.join(missing)}; a brdf .npz holds "
                                        f"{', '.join(required)} (and optionally "
                                        f"{', '.join(optional)})")
        unknown = sorted(names - set(required) - set(optional))
        if unknown:
            raise FormatError(path, "", f"unexpected array {', '.join(unknown)}; a brdf .npz "
                                        f"holds {', '.join(required + optional)}")
        return {name: _member(archive, name, path) for name in archive.files}


#: Largest total of the arrays unpacked from one .npz (a MERL grid with sigma is 70 MB).
MAX_UNPACKED = 4 << 30


def _check_member_size(archive, name, path):
    """Refuse, before numpy allocates it, an array whose header declares more bytes than its
    member holds (a corrupt header would allocate any size) or more than memory can hold."""
    from ..memory import require
    info = archive.zip.getinfo(f"{name}.npy")
    with archive.zip.open(info) as f:
        version = np.lib.format.read_magic(f)
        read_header = (np.lib.format.read_array_header_1_0 if version == (1, 0)
                       else np.lib.format.read_array_header_2_0)
        shape, _, dtype = read_header(f)
        header = f.tell()
    nbytes = math.prod(shape) * dtype.itemsize
    if nbytes > info.file_size - header:
        raise FormatError(path, f"array {name}", f"its header declares shape {shape} "
                                                 f"({nbytes:,} bytes) but the member holds "
                                                 f"{info.file_size - header:,} bytes")
    if nbytes > MAX_UNPACKED:
        raise FormatError(path, f"array {name}", f"{nbytes:,} bytes unpacked; a .npz table "
                                                 f"holds at most {MAX_UNPACKED:,}")
    require(nbytes, f"{path}: array {name}")


def _member(archive, name, path):
    try:
        _check_member_size(archive, name, path)
        return archive[name]
    except BRDFError:
        raise
    except (zipfile.BadZipFile, ValueError, EOFError, OSError, zlib.error, NotImplementedError,
            RuntimeError) as e:
        # zlib.error: corrupt compressed data; NotImplementedError: an unknown compression
        # method; RuntimeError: an encrypted member
        # ValueError includes "Object arrays cannot be loaded when allow_pickle=False"
        raise FormatError(path, f"array {name}", f"cannot be read ({e})") from None


def _array(arrays, name, path, kinds, shape, expected):
    """``arrays[name]`` checked for dtype kind and shape (None = any length)."""
    a = arrays[name]
    if a.dtype.kind not in kinds:
        wanted = " or ".join(_KINDS[k] for k in kinds if k in _KINDS)
        raise FormatError(path, f"array {name}", f"dtype {a.dtype}; expected {wanted}")
    if a.ndim != len(shape) or any(s is not None and s != t for s, t in zip(shape, a.shape)):
        raise FormatError(path, f"array {name}", f"shape {a.shape}; expected {expected}")
    return a


def _directions(arrays, name, path, n):
    """Sample directions ``(n, 3)`` (any n >= 1 when None), all finite."""
    w = _array(arrays, name, path, "f", (n, 3), "(N, 3), one row per sample" if n is None else
               f"({n}, 3) like wi")
    if not len(w):
        raise FormatError(path, f"array {name}", "no samples; expected at least one")
    _finite(w, name, path)
    return w


def _finite(a, name, path):
    bad = ~np.isfinite(a).all(axis=1)
    if bad.any():
        k = int(np.argmax(bad))
        raise FormatError(path, f"array {name}", f"row {k} = {a[k].tolist()} is not finite; "
                                                 "expected finite numbers")


def _angles(arrays, wi, wo, path):
    """The stored degrees, checked against the directions they must describe."""
    angles = _array(arrays, "angles", path, "f", (len(wi), 4), f"({len(wi)}, 4) like wi")
    _finite(angles, "angles", path)
    for w, (theta, phi) in ((wi, (0, 1)), (wo, (2, 3))):
        gap = np.abs(directions_from_degrees(angles[:, theta], angles[:, phi]) - w).max(axis=1)
        if gap.max() > ANGLE_TOL:
            k = int(np.argmax(gap > ANGLE_TOL))
            raise FormatError(path, "array angles", f"row {k} = {angles[k].tolist()} does not "
                                                    "describe the directions wi, wo of that row")
    return angles


def _metadata(arrays, path):
    text = str(_array(arrays, "metadata", path, "U", (), "() text"))
    try:
        metadata = json.loads(text)
    except json.JSONDecodeError as e:
        raise FormatError(path, "array metadata", f"not JSON ({e})") from None
    if not isinstance(metadata, dict):
        raise FormatError(path, "array metadata", f"JSON {type(metadata).__name__}; expected "
                                                  "a JSON object")
    return metadata
