"""RGL material database ``.bsdf`` files (Dupuy & Jakob 2018).

Reference: J. Dupuy and W. Jakob, "An Adaptive Parameterization for Efficient Material
Acquisition and Rendering", ACM Transactions on Graphics 37(6), SIGGRAPH Asia 2018. Format
description: ``../shared/measured/README.md`` (section ``rgl/``).

Container ("tensor_file", little-endian): the 12-byte magic ``tensor_file\\0``, the format
version as two bytes (1, 0), a uint32 field count, then per field a uint16 name length, the
name (UTF-8), a uint16 number of dimensions, a uint8 data type, a uint64 byte offset of the data
from the start of the file and one uint64 extent per dimension; the data are C-ordered arrays.

Fields of an isotropic RGB material (P = 1 incident azimuth, T incident polar angles, n x n
samples per incident direction): ``description`` uint8 text, ``phi_i`` float32 (P,), ``theta_i``
float32 (T,) in radians, ``ndf`` and ``sigma`` float32 2-D tables, ``vndf`` float32
(P, T, H, W), ``luminance`` float32 (P, T, n, n) (for importance sampling; evaluation does not
need it), ``rgb`` float32 (P, T, 3, n, n) (a spectral file has ``spectra`` (P, T, L, n, n) and
``wavelengths`` (L,) in nm instead), ``jacobian`` uint8 (1,); optional ``version`` (uint32 (2,)) and ``valid`` (uint8 bit mask, one bit per
sample). The format description does not say what ``valid`` marks, and the RGL files disagree:
in three of the four it flags the points the warp sends below the horizon, in the fourth the
other points. It is checked for its type and otherwise ignored.

The parameterisation (Dupuy & Jakob 2018, the adaptive VNDF parameterisation): for an incident
direction wi, a point s of the unit square is warped to a microfacet normal h by inverting the
CDFs of the tabulated visible NDF (``vndf``), and wo is wi mirrored about h. Angles map to the
unit square as u = sqrt(theta / (pi/2)) and v = (phi + pi) / (2 pi), with phi_h measured from
phi_i for isotropic materials. The sample stored at s is f_r cos(theta_o) divided by the density
of wo, which is D(h) / (4 sigma(wi)) (the visible NDF <wi.h> D(h) / sigma(wi) times the
reflection Jacobian 1 / (4 wi.h), Walter et al. 2007 eq. 14), so ``jacobian = 1`` files give
f_r cos(theta_o) = sample(s) D(h) / (4 sigma(wi)). :class:`RglTable` evaluates f_r itself (no
cosine) from the measured f_r cos(theta_o) of both orders (wi, wo) and (wo, wi), so that it
stays reciprocal and finite up to the horizon (see :meth:`RglTable.eval`).

:func:`write` stores any isotropic model or table that evaluates at arbitrary directions in
this format: :mod:`brdf.io.adaptive_parameterization` extracts the NDF by power iteration
(Dupuy et al. 2015), places the incident angles and warps the sample grid as the RGL files do,
and the fields are written in the order and 8-byte alignment of the RGL files, so Mitsuba 3's
``measured`` plugin and this reader read the result.
"""

import math
import struct
from dataclasses import dataclass

import numpy as np

from .._jit import inline_kernel, threaded_kernel
from ..errors import FormatError, InputError
from ..geometry import flat_pairs, reflect, spherical_to_cartesian
from ..table import Table
from . import read_bytes, source_of
from .files import MAX_BYTES

__all__ = ["FORMAT", "EXTENSIONS", "sniff", "read", "write", "RglTable", "parse_tensor_file",
           "tensor_file_bytes", "warp_tables", "warp_forward"]

FORMAT = "rgl-bsdf"
EXTENSIONS = (".bsdf",)
#: write() takes a model too: it evaluates it wherever the parameterisation puts a sample
WRITES_MODELS = True
#: Most dimensions a field may have (numpy's arrays have at most 64).
MAX_RANK = 32

MAGIC = b"tensor_file\x00"
#: Magic, version (major, minor), field count.
_PREAMBLE = struct.Struct("<12sBBI")
_NAME_LENGTH = struct.Struct("<H")
#: Number of dimensions, data type code, byte offset of the data.
_ENTRY = struct.Struct("<HBQ")
_EXTENT = struct.Struct("<Q")

#: Data type codes of the tensor_file format (the order of Mitsuba's Struct types).
DTYPES = {1: "uint8", 2: "int8", 3: "uint16", 4: "int16", 5: "uint32", 6: "int32",
          7: "uint64", 8: "int64", 9: "float16", 10: "float32", 11: "float64"}

#: Required fields of a material: name -> (data type, number of dimensions).
_COMMON = {"description": ("uint8", 1), "phi_i": ("float32", 1), "theta_i": ("float32", 1),
           "sigma": ("float32", 2), "ndf": ("float32", 2), "vndf": ("float32", 4),
           "luminance": ("float32", 4), "jacobian": ("uint8", 1)}
_RGB = {**_COMMON, "rgb": ("float32", 5)}
_SPECTRAL = {**_COMMON, "spectra": ("float32", 5), "wavelengths": ("float32", 1)}
#: Optional fields that are checked when present.
_OPTIONAL = {"version": ("uint32", 1), "valid": ("uint8", 1)}

_HALF_PI = 0.5 * math.pi
#: theta_i may exceed pi/2 by the rounding of pi/2 to float32 (spacing 1.2e-7 there).
_FLOAT32_SLACK = 1e-6
#: A sample's wo with cos(theta_o) below this lies on the horizon up to float32 rounding: at
#: theta_i = pi/2 the mirror direction has cos(theta_o) = cos(float32(pi/2)) = 7.5e-8, where
#: f_r = (f_r cos(theta_o)) / cos(theta_o) is rounding noise of order 1e6 1/sr.
_HORIZON = _FLOAT32_SLACK


@dataclass(frozen=True)
class Field:
    """One array of a tensor file: where its entry and data are, and the data as read."""

    name: str
    entry: int          # byte offset of the field's entry in the header
    offset: int         # byte offset of the data
    dtype: str
    shape: tuple
    array: np.ndarray   # read-only view of the data, little-endian


# --- the container ------------------------------------------------------------------------------

def sniff(head):
    """True when ``head`` starts with the tensor_file magic."""
    return bytes(head[:len(MAGIC)]) == MAGIC


def read(path, clip=True):
    """Read an RGL ``.bsdf`` file (isotropic, RGB or spectral).

    Parameters
    ----------
    clip : bool
        Default of :meth:`RglTable.eval`: negative interpolated samples (out-of-gamut colours)
        become 0, as in the reference reader. The table's ``values`` are never clipped.

    Returns
    -------
    RglTable

    Raises
    ------
    brdf.errors.FormatError
        Bad container (magic, version, truncated or overlapping field data, unknown data type,
        trailing bytes), missing or misshapen fields, NaN or infinite numbers, non-UTF-8 text,
        anisotropic materials; the message names the byte offset and the field.
    """
    data = read_bytes(path, MAX_BYTES, "an RGL .bsdf tensor file")
    fields = parse_tensor_file(path, data)
    return _table_from_fields(path, fields, clip, source_of(path, data, FORMAT))


def parse_tensor_file(path, data):
    """The fields of a tensor file, ``{name: Field}``, every extent checked against the file.

    Raises
    ------
    brdf.errors.FormatError
    """
    if data[:len(MAGIC)] != MAGIC[:len(data)]:
        raise FormatError(path, "byte 0", f"magic is {bytes(data[:len(MAGIC)])!r}; expected "
                                          f"{MAGIC!r} (an RGL .bsdf tensor file)")
    if len(data) < _PREAMBLE.size:
        raise FormatError(path, f"byte {len(data)}",
                          f"truncated header: {len(data)} bytes, a tensor_file starts with "
                          f"{_PREAMBLE.size} (magic, version, field count)")
    _, major, minor, count = _PREAMBLE.unpack_from(data, 0)
    if (major, minor) != (1, 0):
        raise FormatError(path, "byte 12", f"tensor_file version {major}.{minor}; expected 1.0")
    fields, pos = {}, _PREAMBLE.size
    for k in range(count):
        field, pos = _field_entry(path, data, pos, k, count)
        if field.name in fields:
            raise FormatError(path, f"byte {field.entry}", f"field {field.name!r} appears twice")
        fields[field.name] = field
    _check_layout(path, fields, pos, len(data))
    return fields


def _field_entry(path, data, pos, k, count):
    """The ``k``-th field entry starting at byte ``pos``; ``(Field, end of the entry)``."""
    entry = pos

    def take(layout, what):
        nonlocal pos
        if pos + layout.size > len(data):
            raise FormatError(path, f"byte {pos}",
                              f"truncated header: field entry {k + 1} of {count} needs {what} "
                              f"({layout.size} bytes), the file ends at byte {len(data)}")
        values = layout.unpack_from(data, pos)
        pos += layout.size
        return values

    (length,) = take(_NAME_LENGTH, "a name length")
    raw_name = take(struct.Struct(f"{length}s"), "the field name")[0]
    try:
        name = raw_name.decode("utf-8")
    except UnicodeDecodeError as e:
        raise FormatError(path, f"byte {entry + 2 + e.start}",
                          f"field name {raw_name!r} is not UTF-8") from None
    ndim, code, offset = take(_ENTRY, f"the dimensions, data type and offset of {name!r}")
    dtype_at = pos - 9
    if ndim > MAX_RANK:
        raise FormatError(path, f"byte {dtype_at - 2}",
                          f"field {name!r} has {ndim} dimensions; expected at most {MAX_RANK} "
                          "(the fields of a BSDF have at most 5)")
    shape = tuple(take(_EXTENT, f"extent {d + 1} of {name!r}")[0] for d in range(ndim))
    if code not in DTYPES:
        known = ", ".join(f"{c} {t}" for c, t in DTYPES.items())
        raise FormatError(path, f"byte {dtype_at}",
                          f"field {name!r} has unknown data type {code}; expected one of {known}")
    dtype = np.dtype(DTYPES[code]).newbyteorder("<")
    size = math.prod(shape) * dtype.itemsize  # Python integers: no overflow on huge extents
    if offset + size > len(data):
        raise FormatError(path, f"byte {dtype_at + 1}",
                          f"field {name!r} data (offset {offset}, {size} bytes) runs past the "
                          f"end of the file ({len(data)} bytes): truncated or corrupt")
    array = np.frombuffer(data, dtype=dtype, count=math.prod(shape), offset=offset)
    return Field(name, entry, offset, DTYPES[code], shape, array.reshape(shape)), pos


def _check_layout(path, fields, header_end, size):
    """Field data must not overlap the header or each other, nor leave bytes after the last."""
    end, previous = header_end, "the header"
    for f in sorted(fields.values(), key=lambda f: f.offset):
        if f.offset < end:
            raise FormatError(path, f"byte {f.offset}",
                              f"field {f.name!r} data overlaps {previous} (which ends at byte "
                              f"{end})")
        end, previous = f.offset + f.array.nbytes, f"field {f.name!r}"
    if size > end:
        raise FormatError(path, f"byte {end}",
                          f"oversized: {size - end} bytes after the last field's data")


# --- writing ------------------------------------------------------------------------------------

#: Data type codes by numpy type (the inverse of DTYPES).
_CODES = {np.dtype(name): code for code, name in DTYPES.items()}
#: Field data start on multiples of this many bytes, as in the RGL files.
_ALIGN = 8
#: Rec. 709 luminance weights of linear sRGB: the ``luminance`` field of the RGL files is this
#: combination of their ``rgb`` samples (to float32 rounding), clipped at 0.
_LUMINANCE = np.array([0.2126, 0.7152, 0.0722])
#: A scattered table is written only when at least this fraction of a coarse grid of direction
#: pairs lies within COVER_RADIUS (radians, in Table.coordinates) of one of its samples;
#: elsewhere its interpolant can only copy the nearest sample.
MIN_INSIDE = 0.5
COVER_RADIUS = math.radians(15.0)


def tensor_file_bytes(fields):
    """The bytes of a tensor_file holding ``fields`` (name -> numpy array), in order, each
    array's data starting at a multiple of 8 bytes (zero padding), little-endian."""
    arrays = {name: np.ascontiguousarray(a) for name, a in fields.items()}
    head = bytearray(_PREAMBLE.pack(MAGIC, 1, 0, len(arrays)))
    offsets = {}
    for name, a in arrays.items():
        raw = name.encode("utf-8")
        head += _NAME_LENGTH.pack(len(raw)) + raw
        offsets[name] = len(head) + 3  # after the dimension count and the type code
        head += _ENTRY.pack(a.ndim, _CODES[a.dtype.newbyteorder("=")], 0)
        head += b"".join(_EXTENT.pack(e) for e in a.shape)
    out = head
    for name, a in arrays.items():
        out += bytes(-len(out) % _ALIGN)
        struct.pack_into("<Q", out, offsets[name], len(out))
        out += a.astype(a.dtype.newbyteorder("<"), copy=False).tobytes()
    return bytes(out)


def write(table, path, *, incident_angles=8, samples=32, vndf_resolution=128,
          ndf_resolution=128, description=None):
    """Write an isotropic model or table as an RGL ``.bsdf`` tensor file at ``path``.

    The parameterisation is computed from the source's ``eval`` (NDF by power iteration,
    projected area, incident angles, visible NDF and warped samples:
    :mod:`brdf.io.adaptive_parameterization`); the fields are ``version`` (1, 0),
    ``description``, ``phi_i`` (0), ``theta_i``, ``sigma``, ``ndf``, ``vndf``, ``luminance``,
    ``rgb`` (or ``spectra`` and ``wavelengths``), ``jacobian`` (1) and ``valid``, in the RGL
    files' order. Three channels are written as ``rgb``, one as grey ``rgb`` (the value in all
    three), channels with wavelengths as ``spectra``. ``luminance`` is the Rec. 709 luminance
    of the rgb samples (the mean of the spectral ones), clipped at 0 (it only steers importance
    sampling). ``valid`` has one bit per sample, most significant bit first, set where the
    sample's wo lies above the horizon by more than float32 rounding (the samples this reader
    keeps; what the name says, though the RGL files disagree, see the module notes). The same
    input gives the same bytes.

    Parameters
    ----------
    table : brdf.Table or brdf.models.Model
    incident_angles, samples, vndf_resolution, ndf_resolution : int
        T incident angles, n x n samples per angle, the VNDF's resolution and the NDF's nodes
        (defaults: those of the RGL files, 8, 32, 128, 128; about 660 KB for RGB).
    description : str, optional
        Stored text (default: the model's spec, or the table's description or name).

    Raises
    ------
    brdf.errors.InputError
        Anisotropic sources, delta lobes, channel counts other than 1 or 3 without
        wavelengths, scattered tables that cannot be interpolated where the samples go, bad
        resolutions, non-finite values.
    """
    from . import adaptive_parameterization
    options = {"incident_angles": incident_angles, "samples": samples,
               "vndf_resolution": vndf_resolution, "ndf_resolution": ndf_resolution}
    for name, value in options.items():
        adaptive_parameterization.resolution(name, value)
    if not (description is None or isinstance(description, str)):
        raise InputError(f"description must be a string, got {type(description).__name__}")
    what, evaluate, channels, wavelengths, text = _writable(table)
    text = text if description is None else description
    _check_inside(table, what)
    try:
        p = adaptive_parameterization.build(evaluate, channels, horizon=_HORIZON, **options)
    except InputError as e:
        raise InputError(f"{what}: {e}") from None
    stored = p.samples.astype(np.float32)
    if wavelengths is None and channels == 1:
        stored = np.repeat(stored, 3, axis=2)  # grey: the value in r, g and b
    lum = (np.einsum("ptcyx,c->ptyx", stored.astype(np.float64), _LUMINANCE)
           if wavelengths is None else stored.astype(np.float64).mean(axis=2))
    lum = np.maximum(lum, 0.0)
    flat = lum.reshape(len(p.theta_i), -1)
    # a black slice has nothing to steer sampling by: uniform, so its CDF stays defined
    flat[~(flat.sum(axis=1) > 0.0)] = 1.0
    fields = {"version": np.array([1, 0], dtype=np.uint32),
              "description": np.frombuffer(text.encode("utf-8"), dtype=np.uint8),
              "phi_i": np.zeros(1, dtype=np.float32), "theta_i": p.theta_i,
              "sigma": p.sigma, "ndf": p.ndf, "vndf": p.vndf,
              "luminance": flat.reshape(lum.shape).astype(np.float32)}
    if wavelengths is None:
        fields["rgb"] = stored
    else:
        fields["spectra"] = stored
        fields["wavelengths"] = np.asarray(wavelengths, dtype=np.float32)
    fields["jacobian"] = np.ones(1, dtype=np.uint8)
    fields["valid"] = np.packbits(p.above.reshape(-1))  # most significant bit first
    with open(path, "wb") as f:
        f.write(tensor_file_bytes(fields))


def _writable(source):
    """``(what, evaluate, channels, wavelengths, description)`` of a model or table the format
    can hold (``what`` names it in messages), else :class:`InputError` saying why not."""
    from ..models.base import Model
    what = f"{source}"
    if isinstance(source, Model):
        deltas = [lobe.name for lobe in source.lobes if lobe.delta]
        if deltas:
            raise InputError(f"{what}: delta lobes ({', '.join(deltas)}) have no finite BRDF to "
                             f"tabulate; the .bsdf format holds diffuse and glossy reflection: "
                             f"write the model without them")
        if source.is_anisotropic:
            raise InputError(f"{what} is anisotropic; the .bsdf writer stores isotropic "
                             f"materials (one incident azimuth): make alpha_y (nv) equal to "
                             f"alpha (nu)")
        wavelengths, default = None, what
    elif isinstance(source, Table):
        what = f"table {source.name}"
        if not source.isotropic:
            raise InputError(f"{what} is anisotropic; the .bsdf writer stores isotropic "
                             f"materials (one incident azimuth)")
        wavelengths = source.wavelengths
        default = source.metadata.get("description") or source.name
        if not isinstance(default, str):
            default = source.name
    else:
        raise InputError(f"write: expected a brdf.Table or a model, got "
                         f"{type(source).__name__}")
    channels = source.channels
    if wavelengths is None and channels not in (1, 3):
        raise InputError(f"{what} has {channels} channels without wavelengths; the .bsdf format "
                         f"holds rgb (3 channels), grey (1, written as rgb) or spectra with "
                         f"wavelengths")

    def evaluate(wi, wo):
        try:
            return source.eval(wi, wo)
        except InputError as e:
            if isinstance(source, Model):
                raise
            raise InputError(f"cannot interpolate its samples where the .bsdf parameterisation "
                             f"needs values ({e}); fit a model to it (brdf-fit fit) and write "
                             f"the model") from None

    return what, evaluate, channels, wavelengths, default


def _check_inside(source, what):
    """Refuse a table whose samples leave most of the parameterisation's domain far from any
    sample, where its generic interpolant can only copy the nearest one (sparse, scattered or
    in-plane scans): at the nodes of a coarse grid of (theta_i, theta_o, phi) up to 80
    degrees, a pair counts as covered when a sample of either order (reciprocity) lies within
    :data:`COVER_RADIUS` in the table's interpolation coordinates (:meth:`Table.coordinates`).
    Tables with their own lookup (MERL, RGL) cover their domain by construction."""
    if not isinstance(source, Table) or type(source).eval_one_sided is not \
            Table.eval_one_sided:
        return
    from scipy.spatial import cKDTree
    theta = np.radians(np.arange(0.0, 81.0, 10.0))
    ti, to, phi = (a.reshape(-1) for a in np.meshgrid(theta, theta, np.radians(
        np.arange(0.0, 181.0, 30.0)), indexing="ij"))
    wi = spherical_to_cartesian(ti, 0.0)
    wo = spherical_to_cartesian(to, phi)
    measured = ~np.isnan(source.values).all(axis=1)
    points = np.concatenate([source.coordinates(source.wi[measured], source.wo[measured]),
                             source.coordinates(source.wo[measured], source.wi[measured])])
    distance = cKDTree(points).query(source.coordinates(wi, wo))[0]
    share = float(np.mean(distance <= COVER_RADIUS))
    if share < MIN_INSIDE:
        raise InputError(f"{what}: only {share:.0%} of the direction pairs the .bsdf "
                         f"parameterisation samples lie within {math.degrees(COVER_RADIUS):g} "
                         f"degrees of a measured sample (the rest would copy the nearest one); "
                         f"fit a model to it (brdf-fit fit) and write the model, or measure it "
                         f"more densely")


# --- the material's arrays ----------------------------------------------------------------------

def _table_from_fields(path, fields, clip, source):
    spectral = "wavelengths" in fields  # as Mitsuba 3's measured plugin decides
    required = _SPECTRAL if spectral else _RGB
    missing = [name for name in required if name not in fields]
    if missing:
        kind = "spectral (it has 'wavelengths')" if spectral else "RGB"
        raise FormatError(path, f"byte {_PREAMBLE.size}",
                          f"missing field(s) {', '.join(map(repr, missing))}; an {kind} .bsdf "
                          f"material needs {', '.join(required)}")
    for name, (dtype, ndim) in {**required, **_OPTIONAL}.items():
        if name in fields:
            _expect_type(path, fields[name], dtype, ndim)
    arrays = {name: _finite(path, f) for name, f in fields.items() if name in required}
    _check_shapes(path, fields, "spectra" if spectral else "rgb")
    description = _text(path, fields["description"])
    theta_i = _incident_angles(path, fields["theta_i"])
    jacobian = _jacobian_flag(path, fields["jacobian"])
    for name in ("ndf", "sigma", "vndf"):
        _non_negative(path, fields[name], positive=name == "sigma")
    _warpable(path, fields["vndf"])
    samples = arrays["spectra" if spectral else "rgb"][0]
    wavelengths = _wavelengths(path, fields["wavelengths"]) if spectral else None
    metadata = {"description": description, "theta_i_deg": np.degrees(theta_i).tolist(),
                "phi_i_deg": math.degrees(float(arrays["phi_i"][0])), "units": "1/sr",
                "version": _version(fields.get("version")), "jacobian": jacobian,
                "resolution": list(samples.shape[-2:]), "vndf_resolution":
                list(fields["vndf"].shape[-2:])}
    if not spectral:
        metadata["color_space"] = "linear sRGB"
    return RglTable(theta_i, float(arrays["phi_i"][0]), arrays["ndf"], arrays["sigma"],
                    arrays["vndf"][0], samples, jacobian=jacobian, wavelengths=wavelengths,
                    clip=clip, metadata=metadata, source=source)


def _expect_type(path, field, dtype, ndim):
    if field.dtype != dtype or len(field.shape) != ndim:
        raise FormatError(path, f"byte {field.entry}",
                          f"field {field.name!r} is {field.dtype} with {len(field.shape)} "
                          f"dimension(s) {list(field.shape)}; expected {dtype} with {ndim} "
                          f"dimension(s)")


def _finite(path, field):
    """The field as float64 (integers as they are), after checking floats are finite."""
    a = field.array
    if a.dtype.kind != "f":
        return a
    a = a.astype(np.float64)
    if not np.isfinite(a).all():
        n = int(np.flatnonzero(~np.isfinite(a.reshape(-1)))[0])
        index = tuple(int(i) for i in np.unravel_index(n, a.shape))
        raise FormatError(path, f"byte {field.offset + n * field.array.itemsize}",
                          f"field {field.name!r} holds {a.reshape(-1)[n]} at index {index}; "
                          f"expected finite numbers")
    return a


def _check_shapes(path, fields, values_name):
    """Extents that must agree between fields (the reference reader's structure checks)."""
    p = fields["phi_i"].shape[0]
    t = fields["theta_i"].shape[0]
    n = fields[values_name].shape[-1]
    if p != 1:
        raise FormatError(path, f"byte {fields['phi_i'].entry}",
                          f"phi_i has {p} incident azimuths; only isotropic materials (one "
                          f"azimuth) are supported")
    if t < 2:
        raise FormatError(path, f"byte {fields['theta_i'].entry}",
                          f"theta_i has {t} value(s); expected at least 2 incident angles")
    channels = fields["wavelengths"].shape[0] if values_name == "spectra" else 3
    expect = {"vndf": (p, t) + fields["vndf"].shape[2:], "luminance": (p, t, n, n),
              values_name: (p, t, channels, n, n), "jacobian": (1,)}
    for name, shape in expect.items():
        if fields[name].shape != shape:
            raise FormatError(path, f"byte {fields[name].entry}",
                              f"field {name!r} has shape {list(fields[name].shape)}; expected "
                              f"{list(shape)} (phi_i {p}, theta_i {t}, {n} x {n} samples)")
    for name in ("vndf", "ndf", "sigma", values_name):
        if min(fields[name].shape[-2:]) < 2:
            raise FormatError(path, f"byte {fields[name].entry}",
                              f"field {name!r} has shape {list(fields[name].shape)}; a bilinear "
                              f"table needs at least 2 x 2 nodes")


def _text(path, field):
    raw = field.array.tobytes()
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as e:
        raise FormatError(path, f"byte {field.offset + e.start}",
                          f"field {field.name!r} is not UTF-8 text (byte 0x{raw[e.start]:02x})"
                          ) from None


def _incident_angles(path, field):
    """theta_i in radians, strictly increasing within [0, pi/2] (float32 pi/2 clamped)."""
    theta = field.array.astype(np.float64)
    bad = (theta < 0.0) | (theta > _HALF_PI + _FLOAT32_SLACK)
    bad[1:] |= np.diff(theta) <= 0.0
    if bad.any():
        k = int(np.argmax(bad))
        raise FormatError(path, f"byte {field.offset + 4 * k}",
                          f"theta_i[{k}] = {theta[k]}; expected increasing angles in [0, pi/2] "
                          f"radians")
    return np.minimum(theta, _HALF_PI)


def _jacobian_flag(path, field):
    flag = int(field.array[0])
    if flag not in (0, 1):
        raise FormatError(path, f"byte {field.offset}", f"jacobian is {flag}; expected 0 or 1")
    return bool(flag)


def _non_negative(path, field, positive=False):
    a = field.array
    bad = a <= 0.0 if positive else a < 0.0
    if bad.any():
        n = int(np.flatnonzero(bad.reshape(-1))[0])
        index = tuple(int(i) for i in np.unravel_index(n, a.shape))
        sign = "positive" if positive else "non-negative"
        raise FormatError(path, f"byte {field.offset + n * a.itemsize}",
                          f"field {field.name!r} holds {a.reshape(-1)[n]} at index {index}; "
                          f"expected {sign} numbers")


def _warpable(path, field):
    """Every VNDF slice needs a positive integral to be normalised into a warp."""
    slices = field.array.reshape(-1, math.prod(field.shape[2:]))
    empty = ~(slices.max(axis=1) > 0.0)
    if empty.any():
        k = int(np.argmax(empty))
        raise FormatError(path, f"byte {field.offset + k * slices[0].nbytes}",
                          f"field 'vndf' slice {k} (theta_i index) is zero everywhere; "
                          f"expected a density to warp by")


def _wavelengths(path, field):
    w = field.array.astype(np.float64)
    bad = ~(w > 0.0)
    bad[1:] |= np.diff(w) <= 0.0
    if bad.any():
        k = int(np.argmax(bad))
        raise FormatError(path, f"byte {field.offset + 4 * k}",
                          f"wavelengths[{k}] = {w[k]}; expected increasing positive nm")
    return w


def _version(field):
    return None if field is None else ".".join(str(int(v)) for v in field.array)


# --- the table ----------------------------------------------------------------------------------

class RglTable(Table):
    """An isotropic RGL material: the samples of the adaptive parameterisation and its lookup.

    Parameters
    ----------
    theta_i : array_like, shape (T,)
        Incident polar angles of the slices, increasing, radians.
    phi_i : float
        The incident azimuth at which the material was measured (radians).
    ndf, sigma : array_like, shape (rows, cols)
        NDF D(h) and projected area sigma(wi) on the unit square (u from theta, v from phi).
    vndf : array_like, shape (T, H, W)
        Visible NDF per incident angle on the unit square (rows v, columns u), any scale.
    samples : array_like, shape (T, C, n, n)
        The stored samples per slice and channel (rows: second unit-square coordinate); the
        table's ``values`` are these converted to f_r.
    jacobian : bool
        Whether samples are divided by the density D(h) / (4 sigma(wi)) (the file's flag).
    wavelengths : array_like, shape (C,), optional
        Spectral files: the channels' wavelengths in nm.
    clip : bool
        Default of :meth:`eval`: clip negative interpolated samples to 0 (reference reader).
    metadata, source, name
        As for :class:`brdf.table.Table`.

    Notes
    -----
    The table's samples are the T x n x n stored points: wi at each theta_i (azimuth phi_i), wo
    the forward VNDF warp of node (j, i) / (n - 1) of the unit square, and values the samples
    converted to f_r in 1/sr exactly as :meth:`eval_one_sided` converts them, never clipped.
    Points whose wo falls below the horizon, or on it within float32 rounding, are left out
    (``metadata["horizon_samples_left_out"]``).

    The measured elevation range is theta in [0, ``valid_theta``], ``valid_theta`` the largest
    incident angle of the file below 90 degrees (``metadata["valid_theta_deg"]``): a slice at
    90 degrees cannot be measured (no irradiance reaches the sample there) and only serves the
    interpolation.
    """

    format = FORMAT

    def __init__(self, theta_i, phi_i, ndf, sigma, vndf, samples, *, jacobian=True,
                 wavelengths=None, clip=True, metadata=None, source=None, name=None):
        self._theta = np.ascontiguousarray(theta_i, dtype=np.float64)
        if self._theta.ndim != 1 or len(self._theta) < 2 or np.any(np.diff(self._theta) <= 0):
            raise InputError(f"theta_i must hold at least 2 increasing angles, got {theta_i}")
        self._phi_i = float(phi_i)
        self._ndf = _bilinear_table(ndf, "ndf")
        self._sigma_table = _bilinear_table(sigma, "sigma")
        self._pdf, self._cond, self._marg = warp_tables(vndf)
        self._stored = np.ascontiguousarray(samples, dtype=np.float64)
        if self._stored.ndim != 4 or min(self._stored.shape[2:]) < 2 or \
                self._stored.shape[0] != len(self._theta) or len(self._pdf) != len(self._theta):
            raise InputError(f"samples (T, C, n, n) and vndf (T, H, W) must have T = "
                             f"{len(self._theta)} slices and n, H, W >= 2, got "
                             f"{self._stored.shape} and {self._pdf.shape}")
        self.jacobian = bool(jacobian)
        self.clip = bool(clip)
        measured = self._theta[self._theta < _HALF_PI - _FLOAT32_SLACK]
        self.valid_theta = float(measured[-1] if len(measured) else self._theta[0])
        self._cos_valid = math.cos(self.valid_theta)
        wi, wo, f = self._node_samples()
        info = dict(metadata or {})
        info["horizon_samples_left_out"] = int(self._stored[:, 0].size - len(wi))
        info["valid_theta_deg"] = math.degrees(self.valid_theta)
        super().__init__(wi, wo, f, wavelengths=wavelengths, isotropic=True, metadata=info,
                         source=source, name=name)

    def _node_samples(self):
        """``(wi, wo, f_r)`` of the stored samples whose wo is clearly above the horizon."""
        t, c, n, _ = self._stored.shape
        grid = np.linspace(0.0, 1.0, n)
        sy, sx = (a.reshape(-1) for a in np.meshgrid(grid, grid, indexing="ij"))
        wi_all, wo_all, f_all = [], [], []
        for k, theta in enumerate(self._theta):
            ux, uy = warp_forward(self._pdf[k], self._cond[k], self._marg[k], sx, sy)
            # unit square -> half vector: theta_h = u^2 pi/2, phi_h = (2 v - 1) pi + phi_i
            h = spherical_to_cartesian(ux * ux * _HALF_PI, (2.0 * uy - 1.0) * math.pi +
                                       self._phi_i)
            wi = spherical_to_cartesian(np.full(n * n, theta), self._phi_i)
            wo = reflect(wi, h)
            keep = wo[:, 2] > _HORIZON
            wi_all.append(wi[keep])
            wo_all.append(wo[keep] / np.linalg.norm(wo[keep], axis=-1, keepdims=True))
            f_all.append(self._stored[k].reshape(c, -1).T[keep])
        wi, wo, stored = (np.concatenate(a) for a in (wi_all, wo_all, f_all))
        return wi, wo, stored * self._scale(wi, wo)

    def _scale(self, wi, wo):
        """Factor from stored sample to f_r: D(h) / (4 sigma(wi)) / cos(theta_o), (n, 1).

        The one-sided lookup of a table whose samples are all 1 gives it, computed exactly as
        :meth:`eval_one_sided` computes it."""
        wi, wo, _ = flat_pairs(wi, wo)  # the arrays eval passes: one compiled specialisation
        out = np.empty((len(wi), 1))
        _eval_kernel(wi, wo, self._theta, self._pdf, self._cond, self._marg,
                     np.ones((len(self._theta), 1, 2, 2)), self._ndf, self._sigma_table,
                     self.jacobian, False, False, self._cos_valid, out,
                     np.empty(len(wi), dtype=np.bool_))
        return out

    # -- evaluation ------------------------------------------------------------------------------
    def eval(self, wi, wo, method="linear", clip=None):
        """BRDF f_r ``(..., C)`` in 1/sr (no cosine), reciprocal and finite up to the horizon;
        0 when either direction is below it.

        The file measures g = f_r cos(theta_o) (:meth:`eval_one_sided` divides it by
        cos(theta_o), as the reference reader does, which diverges at the horizon where g need
        not vanish). ``eval`` combines the measurements of both orders,

            f_r = (g(wi, wo) + g(wo, wi)) / max(cos theta_i + cos theta_o, cos valid_theta),

        the cosine-weighted mean of the two one-sided values (each weighted by the cosine it
        is divided by; the weighted least-squares f_r for errors in g of variance proportional
        to g's cosine). Where one direction nears the horizon its ill-conditioned one-sided
        value loses its weight and f_r tends to the other order's measurement; only where both
        directions lie beyond the measured elevation range does the denominator stop at
        cos(valid_theta), so f_r stays bounded by (g + g) / cos(valid_theta) there. Inside
        the range f_r differs from the one-sided value by the file's own asymmetry (median
        0.2 % for paper_white below 60 degrees).

        Parameters
        ----------
        method : {"linear"}
            The format defines one interpolation; accepted for the :class:`Table` interface.
        clip : bool, optional
            Clip negative interpolated samples to 0 (default: the table's ``clip``).
        """
        return self._lookup(wi, wo, method, self.clip if clip is None else bool(clip), True)[0]

    def eval_one_sided(self, wi, wo, method="linear", clip=False):
        """``(values (..., C), inside (...))``: the measurement at (wi, wo) as the reference
        reader evaluates it, unclipped by default.

        wo is mapped back to its point s of the unit square by inverting the VNDF warp at
        theta_i (the CDF tables of the two nearest incident angles interpolated linearly), the
        stored samples are interpolated bilinearly at s (and linearly in theta_i), multiplied by
        D(h) / (4 sigma(wi)) when the file's ``jacobian`` flag is set, and divided by
        cos(theta_o) (Mitsuba 3's ``measured`` plugin returns this times cos(theta_o)). It
        grows like 1 / cos(theta_o) in the last degree (paper_white at 30 degrees incidence:
        0.55 1/sr at theta_o = 89 degrees, 3.0 at 89.9, 28 at 89.99). ``inside`` is True where
        both directions lie within the measured elevation range (``valid_theta``).
        """
        return self._lookup(wi, wo, method, bool(clip), False)

    def _lookup(self, wi, wo, method, clip, reciprocal):
        if method != "linear":
            raise InputError(f"method must be 'linear' for an RGL table, got {method!r}")
        wi, wo, shape = flat_pairs(wi, wo)
        out = np.empty((len(wi), self.channels))
        inside = np.empty(len(wi), dtype=np.bool_)
        _eval_kernel(wi, wo, self._theta, self._pdf, self._cond, self._marg, self._stored,
                     self._ndf, self._sigma_table, self.jacobian, clip, reciprocal,
                     self._cos_valid, out, inside)
        return out.reshape(shape + (self.channels,)), inside.reshape(shape)

    def unit_square(self, wi, wo):
        """Point s ``(..., 2)`` of the unit square whose forward warp gives ``wo`` from ``wi``
        (the coordinates at which the stored samples are interpolated)."""
        wi, wo, shape = flat_pairs(wi, wo)
        out = np.empty((len(wi), 2))
        _unit_square_kernel(wi, wo, self._theta, self._pdf, self._cond, self._marg, out)
        return out.reshape(shape + (2,))


def _bilinear_table(a, name):
    a = np.ascontiguousarray(a, dtype=np.float64)
    if a.ndim != 2 or min(a.shape) < 2:
        raise InputError(f"{name} must be a 2-D table of at least 2 x 2 nodes, got shape "
                         f"{a.shape}")
    return a


# --- the 2-D warp -------------------------------------------------------------------------------

def warp_tables(vndf):
    """Normalised density, conditional and marginal CDFs of piecewise-bilinear 2-D densities.

    Each slice ``vndf[k]`` (rows y, columns x on equally spaced nodes over the unit square) is
    a bilinear density; cell widths count as 1, so ``cond[k, y, x]`` integrates row y from node
    0 to node x by the trapezoid rule (exact for linear rows) and ``marg[k, y]`` integrates the
    row totals ``cond[k, :, -1]`` over rows 0 to y; all three are divided by the slice total.

    Returns
    -------
    pdf, cond : ndarray, shape (T, H, W)
    marg : ndarray, shape (T, H)
    """
    d = np.ascontiguousarray(vndf, dtype=np.float64)
    if d.ndim != 3 or min(d.shape[1:]) < 2:
        raise InputError(f"vndf must be shaped (T, H, W) with H, W >= 2, got {d.shape}")
    cond = np.zeros_like(d)
    cond[..., 1:] = np.cumsum(0.5 * (d[..., 1:] + d[..., :-1]), axis=-1)
    rows = cond[..., -1]
    marg = np.zeros(rows.shape)
    marg[:, 1:] = np.cumsum(0.5 * (rows[:, 1:] + rows[:, :-1]), axis=-1)
    total = marg[:, -1]
    if not np.all(total > 0.0):
        k = int(np.argmin(total > 0.0))
        raise InputError(f"vndf slice {k} is zero everywhere; expected a density to warp by")
    scale = 1.0 / total
    return d * scale[:, None, None], cond * scale[:, None, None], marg * scale[:, None]


def warp_forward(pdf, cond, marg, sx, sy):
    """Forward warp of unit-square points ``(sx, sy)`` by one slice of :func:`warp_tables`.

    The marginal CDF picks the row, then the conditional CDF (linear between the two rows)
    picks the column; within a cell the CDF of a linear density is quadratic and is inverted
    in closed form. Returns ``(ux, uy)`` distributed with the bilinear density.
    """
    h, w = pdf.shape
    row = np.clip(np.searchsorted(marg, sy, side="left") - 1, 0, h - 2)
    r0, r1 = cond[row, -1], cond[row + 1, -1]
    ty = _solve_linear_cdf(r0, r1, sy - marg[row])
    # conditional CDF at the fractional row, then the same inversion along x
    target = sx * ((1.0 - ty) * r0 + ty * r1)
    blended = (1.0 - ty)[:, None] * cond[row] + ty[:, None] * cond[row + 1]
    col = np.clip(np.sum(blended < target[:, None], axis=1) - 1, 0, w - 2)
    c0 = (1.0 - ty) * pdf[row, col] + ty * pdf[row + 1, col]
    c1 = (1.0 - ty) * pdf[row, col + 1] + ty * pdf[row + 1, col + 1]
    tx = _solve_linear_cdf(c0, c1, target - blended[np.arange(len(col)), col])
    return (col + tx) / (w - 1), (row + ty) / (h - 1)


def _solve_linear_cdf(a, b, p):
    """t in [0, 1] with t a + t^2 (b - a) / 2 = p: the CDF, from 0, of a density going
    linearly from a to b over one cell. Written as 2p / (a + sqrt(a^2 + 2 (b - a) p)), the
    root without cancellation, valid also for b = a; an empty cell gives t = 0."""
    p = np.maximum(p, 0.0)
    root = np.sqrt(np.maximum(a * a + 2.0 * (b - a) * p, 0.0))
    denom = a + root
    t = np.divide(2.0 * p, denom, out=np.zeros_like(denom), where=denom > 0.0)
    return np.clip(t, 0.0, 1.0)


# --- compiled lookup ----------------------------------------------------------------------------

@inline_kernel
def _cell(u, n):
    """Lower node and fraction of ``u`` in [0, 1] on ``n`` equally spaced nodes."""
    x = min(max(u, 0.0), 1.0) * (n - 1)
    i = min(int(x), n - 2)
    return i, x - i


@inline_kernel
def _bilinear(grid, ux, uy):
    """Bilinear interpolation of ``grid`` (rows: uy, columns: ux) on the unit square."""
    iy, fy = _cell(uy, grid.shape[0])
    ix, fx = _cell(ux, grid.shape[1])
    return ((1.0 - fy) * ((1.0 - fx) * grid[iy, ix] + fx * grid[iy, ix + 1])
            + fy * ((1.0 - fx) * grid[iy + 1, ix] + fx * grid[iy + 1, ix + 1]))


@inline_kernel
def _slice_interval(nodes, x):
    """Slice ``k`` and weight ``w`` of ``x`` between ``nodes[k]`` and ``nodes[k + 1]``, both
    clamped to the table (constant extrapolation)."""
    k = min(max(np.searchsorted(nodes, x, side="right") - 1, 0), nodes.shape[0] - 2)
    w = (x - nodes[k]) / (nodes[k + 1] - nodes[k])
    return k, min(max(w, 0.0), 1.0)


@inline_kernel
def _mix(a, k, w, i, j):
    """``a[., i, j]`` interpolated linearly between slices k and k + 1."""
    return (1.0 - w) * a[k, i, j] + w * a[k + 1, i, j]


@inline_kernel
def _angles(wi, wo):
    """``(theta_i, phi_i, u_h, v_h, cos_o)`` of a pair above the horizon: the unit-square
    coordinates u = sqrt(theta_h / (pi/2)), v = (phi_h - phi_i + pi) / (2 pi) mod 1 of the half
    vector (Dupuy & Jakob 2018: phi relative to phi_i for isotropic materials)."""
    ni = math.sqrt(wi[0] * wi[0] + wi[1] * wi[1] + wi[2] * wi[2])
    no = math.sqrt(wo[0] * wo[0] + wo[1] * wo[1] + wo[2] * wo[2])
    ix, iy, iz = wi[0] / ni, wi[1] / ni, wi[2] / ni
    ox, oy, oz = wo[0] / no, wo[1] / no, wo[2] / no
    hx, hy, hz = ix + ox, iy + oy, iz + oz  # half vector, unnormalised: angles only
    theta_i = math.atan2(math.sqrt(ix * ix + iy * iy), iz)
    phi_i = math.atan2(iy, ix)
    theta_h = math.atan2(math.sqrt(hx * hx + hy * hy), hz)
    v = (math.atan2(hy, hx) - phi_i + math.pi) / (2.0 * math.pi)
    return theta_i, phi_i, math.sqrt(theta_h / _HALF_PI), v - math.floor(v), oz


@inline_kernel
def _invert(pdf, cond, marg, k, w, ux, uy):
    """Unit-square point ``(sx, sy)`` whose forward warp is ``(ux, uy)``, with the tables
    interpolated between slices k and k + 1 (inverse of :func:`warp_forward`): the
    conditional CDF at (ux, uy), normalised by the row total, and the marginal CDF at uy."""
    iy, fy = _cell(uy, pdf.shape[1])
    ix, fx = _cell(ux, pdf.shape[2])
    last = pdf.shape[2] - 1
    c0 = (1.0 - fy) * _mix(pdf, k, w, iy, ix) + fy * _mix(pdf, k, w, iy + 1, ix)
    c1 = (1.0 - fy) * _mix(pdf, k, w, iy, ix + 1) + fy * _mix(pdf, k, w, iy + 1, ix + 1)
    x = (fx * (c0 + 0.5 * fx * (c1 - c0)) + (1.0 - fy) * _mix(cond, k, w, iy, ix)
         + fy * _mix(cond, k, w, iy + 1, ix))
    r0 = _mix(cond, k, w, iy, last)
    r1 = _mix(cond, k, w, iy + 1, last)
    total = (1.0 - fy) * r0 + fy * r1
    # an empty row has a flat CDF: every point of it warps to the same place
    sx = x / total if total > 0.0 else ux
    sy = fy * (r0 + 0.5 * fy * (r1 - r0)) + (1.0 - w) * marg[k, iy] + w * marg[k + 1, iy]
    return sx, sy


@threaded_kernel("wi", "wo", "out")
def _unit_square_kernel(wi, wo, theta_nodes, pdf, cond, marg, out):
    for n in range(wi.shape[0]):
        theta_i, _, uh, vh, _ = _angles(wi[n], wo[n])
        k, w = _slice_interval(theta_nodes, theta_i)
        out[n, 0], out[n, 1] = _invert(pdf, cond, marg, k, w, uh, vh)


@inline_kernel
def _add_measured(wi, wo, theta_nodes, pdf, cond, marg, stored, ndf, sigma, jacobian, clip,
                  weight, out, n):
    """Add ``weight`` times the measured f_r cos(theta_o) of the pair (wi, wo), both above the
    horizon, to ``out[n, :]``: the stored samples at the inverted point, linear in theta_i,
    times D(h) / (4 sigma(wi)) when ``jacobian`` is set (module notes)."""
    theta_i, phi_i, uh, vh, _ = _angles(wi, wo)
    k, w = _slice_interval(theta_nodes, theta_i)
    sx, sy = _invert(pdf, cond, marg, k, w, uh, vh)
    scale = weight
    if jacobian:
        # f_r cos(theta_o) = sample D(h) / (4 sigma(wi))  (density of wo, module notes)
        ui = math.sqrt(theta_i / _HALF_PI)
        vi = (phi_i + math.pi) / (2.0 * math.pi)
        scale *= _bilinear(ndf, uh, vh) / (4.0 * _bilinear(sigma, ui, vi))
    for c in range(stored.shape[1]):
        value = ((1.0 - w) * _bilinear(stored[k, c], sx, sy)
                 + w * _bilinear(stored[k + 1, c], sx, sy))
        if clip and value < 0.0:
            value = 0.0
        out[n, c] += value * scale


@threaded_kernel("wi", "wo", "out", "inside")
def _eval_kernel(wi, wo, theta_nodes, pdf, cond, marg, stored, ndf, sigma, jacobian, clip,
                 reciprocal, cos_valid, out, inside):
    """f_r of each pair into ``out`` (n, C), 0 below the horizon; ``inside[n]`` says whether
    both directions lie within the measured elevation range (cos theta >= ``cos_valid``).

    One-sided (``reciprocal`` False): the measured f_r cos(theta_o) over cos(theta_o), the
    reference reader's value. Reciprocal: (g(wi, wo) + g(wo, wi)) / max(cos theta_i +
    cos theta_o, cos_valid) with g the measured f_r cos(theta_o) of each order (RglTable.eval).
    """
    for n in range(wi.shape[0]):
        out[n, :] = 0.0
        if wi[n, 2] <= 0.0 or wo[n, 2] <= 0.0:
            inside[n] = False
            continue
        cos_i = wi[n, 2] / math.sqrt(wi[n, 0] ** 2 + wi[n, 1] ** 2 + wi[n, 2] ** 2)
        cos_o = wo[n, 2] / math.sqrt(wo[n, 0] ** 2 + wo[n, 1] ** 2 + wo[n, 2] ** 2)
        inside[n] = min(cos_i, cos_o) >= cos_valid
        if reciprocal:
            # cosine-weighted mean of the two one-sided values (RglTable.eval)
            weight = 1.0 / max(cos_i + cos_o, cos_valid)
            _add_measured(wi[n], wo[n], theta_nodes, pdf, cond, marg, stored, ndf, sigma,
                          jacobian, clip, weight, out, n)
            _add_measured(wo[n], wi[n], theta_nodes, pdf, cond, marg, stored, ndf, sigma,
                          jacobian, clip, weight, out, n)
        else:
            _add_measured(wi[n], wo[n], theta_nodes, pdf, cond, marg, stored, ndf, sigma,
                          jacobian, clip, 1.0 / cos_o, out, n)
