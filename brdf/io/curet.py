"""CUReT BRDF table (Columbia-Utrecht Reflectance and Texture database): ``abrdf.dat``.

K. J. Dana, B. van Ginneken, S. K. Nayar, J. J. Koenderink, "Reflectance and texture of
real-world surfaces," ACM Transactions on Graphics 18(1), 1-34 (1999). Two files, as published
on CUReT's BRDF page:

- ``abrdf.dat``: one line per sample, the sample number (1, 2, ...) then its BRDF at every
  geometry, averaged over red, green and blue;
- ``table.txt`` (looked for next to it): one line per geometry, the measurement number then
  ``theta_v phi_v theta_i phi_i`` in radians (viewing, then illumination direction; both point
  away from the surface, so ``theta_v = theta_i`` with azimuths half a turn apart is the mirror
  configuration).

A table is one material, so :func:`read` returns one sample (``sample=1`` by default; the
metadata says how many the file holds) and :func:`read_all` every sample. The table has one
channel, ``"mean"``; values are in 1/sr (CUReT derives them from calibrated radiance; the file
states no unit). The samples are not assumed isotropic (``isotropic=False``): CUReT's 205
geometries span all four angles. Negative values (measurement noise, 29 in the published
table) are kept: the non-negativity check reports them.
"""

from pathlib import Path

from ..errors import FormatError
from ..geometry import spherical_to_cartesian
from ..table import Table
from .. import arguments
from . import SNIFF_BYTES, _text, read_bytes, source_of
from .files import MAX_BYTES

FORMAT = "curet"
# ".dat" is too generic to claim: CUReT files are recognised by content
EXTENSIONS = ()

GEOMETRY_FILE = "table.txt"
GEOMETRY_COLUMNS = ("theta_v", "phi_v", "theta_i", "phi_i")
CHANNEL = "mean"
#: Fewest numbers on the first line for :func:`sniff` (a geometry table line has 5).
_SNIFF_MIN_FIELDS = 6


def sniff(head):
    """True when the first line is sample number 1 followed by numbers (more than a geometry
    line's four angles)."""
    first, newline, _ = head.partition(b"\n")
    tokens = first.decode("utf-8", "replace").split()
    cut = not newline and len(head) >= SNIFF_BYTES  # the first line does not fit in the head
    if cut or len(tokens) < _SNIFF_MIN_FIELDS or tokens[0] != "1":
        return False
    return all(_text.is_number(t) for t in tokens[1:])


def read(path, sample=1, geometry=None):
    """Read one sample of a CUReT ``abrdf.dat`` into a :class:`~brdf.table.Table`.

    Parameters
    ----------
    path : str or path-like
        The BRDF file (``abrdf.dat``).
    sample : int
        Sample number, 1 to the number of lines of the file (61 in CUReT).
    geometry : str or path-like, optional
        The geometry table; by default ``table.txt`` in the folder of ``path``.

    Returns
    -------
    Table
        One sample per geometry, one channel ``"mean"``; ``metadata["sample"]`` and
        ``metadata["samples"]`` (how many the file holds), and the geometry file's path and
        SHA-256 in ``metadata["geometry"]``.

    Raises
    ------
    FormatError
        Naming the file and line of the first bad input in either file (see :func:`read_all`).
    InputError
        ``sample`` is not one of the file's sample numbers.
    """
    wi, wo, values, common = _load(path, geometry)
    sample = arguments.integer(sample, "sample", 1, len(values))
    return _table(wi, wo, values, common, sample)


def read_all(path, geometry=None):
    """Every sample of a CUReT ``abrdf.dat``: a list of tables, sample 1 first.

    Raises
    ------
    FormatError
        A missing geometry table (naming the path looked for), text that is not UTF-8, an empty
        file, a line with the wrong number of fields, a field that is not a finite number,
        sample or measurement numbers out of sequence, an angle out of range.
    """
    wi, wo, values, common = _load(path, geometry)
    return [_table(wi, wo, values, common, k) for k in range(1, len(values) + 1)]


def _table(wi, wo, values, common, k):
    metadata = dict(common[0], sample=k, samples=len(values))
    table = Table(wi, wo, values[k - 1][:, None], channel_names=(CHANNEL,), isotropic=False,
                  metadata=metadata, source=common[1], name=f"curet sample {k}")
    table.format = FORMAT
    return table


def _load(path, geometry):
    """``(wi, wo, values (samples, geometries), (metadata, source))`` from both files."""
    table_path = Path(geometry) if geometry is not None else Path(path).with_name(GEOMETRY_FILE)
    if not table_path.is_file():
        raise FormatError(table_path, "", f"CUReT geometry table not found; expected "
                                          f"{GEOMETRY_FILE} next to {Path(path).name} (or pass "
                                          "geometry=PATH)")
    table_data = read_bytes(table_path, MAX_BYTES, "a CUReT geometry table")
    angles = _geometry(table_path, table_data)
    data = read_bytes(path, MAX_BYTES, "a CUReT abrdf.dat file")
    values = _values(path, data, len(angles), table_path.name)
    metadata = {
        "units": "1/sr (not stated in the file; CUReT derives BRDF from calibrated radiance)",
        "channel": "BRDF averaged over red, green and blue",
        "geometry": source_of(table_path, table_data, "curet-geometry").to_dict(),
    }
    wo = spherical_to_cartesian(angles[:, 0], angles[:, 1])  # viewing
    wi = spherical_to_cartesian(angles[:, 2], angles[:, 3])  # illumination
    return wi, wo, values, (metadata, source_of(path, data, FORMAT))


def _geometry(path, data):
    """Angles ``(M, 4)`` in radians, columns :data:`GEOMETRY_COLUMNS`."""
    rows = _rows(path, data, len(GEOMETRY_COLUMNS), "a measurement number and 4 angles",
                 "measurement number", lambda c: f"column {GEOMETRY_COLUMNS[c]}")
    for c, name in enumerate(GEOMETRY_COLUMNS):
        locate = (lambda k, name=name: (f"line {k + 1}", f"column {name}: "))
        if name.startswith("theta"):
            rows[:, c] = _text.check_polar(path, rows[:, c], locate)
        else:
            _text.check_azimuth(path, rows[:, c], locate)
    return rows


def _values(path, data, geometries, table_name):
    """BRDF values ``(samples, geometries)``."""
    return _rows(path, data, geometries,
                 f"a sample number and {geometries} values (one per geometry in {table_name})",
                 "sample number", lambda c: f"value {c + 1}")


def _rows(path, data, width, layout, number_name, field_name):
    """The numbers after the leading sequence number of each line, ``(lines, width)``.

    ``layout`` describes a line for error messages; ``field_name(c)`` names column ``c``.
    """
    lines = _text.decode_lines(path, data, f"lines of {layout}")
    fields = [line.split() for line in lines]
    for r, row in enumerate(fields):
        if len(row) != width + 1:
            raise FormatError(path, f"line {r + 1}", f"{len(row)} fields; expected {width + 1}: "
                                                     f"{layout}")
    _text.check_sequence(path, [row[0] for row in fields],
                         lambda r: (f"line {r + 1}", ""), number_name)

    def locate(k):
        return f"line {k // width + 1}", f"{field_name(k % width)}: "

    return _text.floats(path, [f for row in fields for f in row[1:]], locate).reshape(-1, width)
