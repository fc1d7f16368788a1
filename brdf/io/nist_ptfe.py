"""NIST sintered PTFE BRDF data (Germer 2017), ``PTFE.data.csv``.

T. A. Germer, "Full four-dimensional and reciprocal Mueller matrix bidirectional reflectance
distribution function of sintered polytetrafluoroethylene," Applied Optics 56(33), 9333 (2017).
The layout follows NIST's ``README.txt`` for the data release:

- comma-separated, one header line, 21 columns; NIST's README spells them
  ``lambda,thetai,phii,thetar,phir,fr11,m12,...,m44`` and the file itself
  ``lambda,thetai,phi,thetar,phir,f_r11,f_r12/f_r11,...,f_r44/f_r11`` (both are accepted,
  column by column, in any letter case);
- ``lambda`` in micrometres; angles in degrees; ``fr11`` the unpolarised BRDF in 1/sr; the other
  15 columns the Mueller matrix normalised by ``fr11``.

The table holds the unpolarised BRDF only: the normalised Mueller elements are checked to be
finite numbers and then ignored. Rows are grouped by geometry across wavelengths into one sample
per geometry with one channel per wavelength (nm); a geometry missing at some wavelength is NaN
there.

Angle convention: a negative polar angle at azimuth ``phi`` is the direction at ``|theta|`` and
``phi + 180``, the usual reading of in-plane goniometer angles; NIST's incidence angles are
-75 ... -0.001 degrees at ``phii = 0``. With this reading the forward-scattering maximum lies
near the mirror direction of the incidence (``phir`` near 0), as expected of PTFE's forward
lobe at grazing incidence; ``tests/io/test_nist_ptfe.py`` checks it.
"""

import numpy as np

from ..errors import FormatError
from ..geometry import directions_from_degrees
from ..table import Table
from . import _text, read_bytes, source_of
from .files import MAX_BYTES

FORMAT = "nist-ptfe"
# .csv is shared with the gonioreflectometer CSV: the header decides (sniff)
EXTENSIONS = (".csv",)

_MUELLER = tuple(f"{i}{j}" for i in range(1, 5) for j in range(1, 5) if (i, j) != (1, 1))
#: Accepted names per column: (as written in PTFE.data.csv, as in NIST's README.txt).
COLUMNS = (("lambda", "lambda"), ("thetai", "thetai"), ("phi", "phii"), ("thetar", "thetar"),
           ("phir", "phir"), ("f_r11", "fr11")) + tuple((f"f_r{m}/f_r11", f"m{m}")
                                                        for m in _MUELLER)
_LAMBDA, _THETA_I, _PHI_I, _THETA_R, _PHI_R, _FR11 = range(6)
#: Polar angles may be signed (see the module docstring); azimuths span one turn either way.
_THETA_LIMIT = 90.0
_PHI_LIMIT = 360.0
_EXPECTED = "NIST PTFE BRDF data: a header 'lambda,thetai,phi,...' and 21 numbers per row"


def sniff(head):
    """True when the first line starts like a NIST PTFE header (``lambda,thetai,phi[i],``)."""
    first = head.split(b"\n", 1)[0].decode("utf-8", "replace").removeprefix("\ufeff")
    names = [n.strip().lower() for n in first.split(",")]
    return len(names) > 3 and all(n in COLUMNS[c] for c, n in enumerate(names[:3]))


def read(path):
    """Read ``PTFE.data.csv`` into a :class:`~brdf.table.Table`.

    Returns
    -------
    Table
        One sample per distinct ``(thetai, phii, thetar, phir)``; ``values`` shaped
        ``(N, 4)`` for the four wavelengths (351, 532, 633, 1064 nm), in 1/sr;
        ``isotropic=True``.

    Raises
    ------
    FormatError
        Naming the line (and column) of the first bad input: not UTF-8, empty, a misspelt or
        missing column, a row with the wrong number of fields, a field that is not a finite
        number, an angle out of range, a non-positive wavelength, or a geometry listed twice at
        one wavelength.
    """
    data = read_bytes(path, MAX_BYTES, "a NIST PTFE file")
    lines = _text.decode_lines(path, data, _EXPECTED)
    _check_header(path, lines[0])
    rows = _numbers(path, lines[1:])
    wavelengths, geometry, values = _group(path, rows)
    wi = directions_from_degrees(*_signed_polar(geometry[:, 0], geometry[:, 1]))
    wo = directions_from_degrees(*_signed_polar(geometry[:, 2], geometry[:, 3]))
    metadata = {
        "units": "1/sr",
        "quantity": "unpolarised BRDF fr11; the 15 normalised Mueller matrix elements are "
                    "not read",
        "rows": len(rows),
    }
    table = Table(wi, wo, values, wavelengths=wavelengths, isotropic=True, metadata=metadata,
                  source=source_of(path, data, FORMAT))
    table.format = FORMAT
    return table


def _check_header(path, line):
    names = [n.strip().lower() for n in line.split(",")]
    if len(names) != len(COLUMNS):
        raise FormatError(path, "line 1", f"header has {len(names)} columns; expected "
                                          f"{len(COLUMNS)}: {','.join(c[0] for c in COLUMNS)}")
    for c, (name, valid) in enumerate(zip(names, COLUMNS)):
        if name not in valid:
            spellings = " or ".join(dict.fromkeys(f"'{v}'" for v in valid))
            raise FormatError(path, "line 1", f"column {c + 1} is '{name}'; expected {spellings}")


def _numbers(path, lines):
    """The data rows as a float array ``(n, 21)``."""
    if not lines:
        raise FormatError(path, "line 2", "no data rows after the header")
    width = len(COLUMNS)
    fields = [line.split(",") for line in lines]
    for r, row in enumerate(fields):
        if len(row) != width:
            raise FormatError(path, f"line {r + 2}",
                              f"{len(row)} fields; expected {width} (as many as the header)")

    def locate(k):
        return f"line {k // width + 2}", f"column {COLUMNS[k % width][0]}: "

    values = _text.floats(path, [f for row in fields for f in row], locate).reshape(-1, width)
    for column, limit in ((_THETA_I, _THETA_LIMIT), (_THETA_R, _THETA_LIMIT),
                          (_PHI_I, _PHI_LIMIT), (_PHI_R, _PHI_LIMIT)):
        _text.check_range(path, values[:, column], -limit, limit,
                          lambda k, c=column: locate(k * width + c), " deg")
    _text.check_positive(path, values[:, _LAMBDA], lambda k: locate(k * width + _LAMBDA), "um")
    return values


def _group(path, rows):
    """``(wavelengths nm (W,), geometry degrees (G, 4), values (G, W))`` from the rows.

    Geometries keep the order of their first appearance in the file.
    """
    microns, channel = np.unique(rows[:, _LAMBDA], return_inverse=True)
    unique, first, geometry_index = np.unique(rows[:, _THETA_I:_FR11], axis=0,
                                              return_index=True, return_inverse=True)
    order = np.argsort(first)
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    sample = rank[geometry_index.reshape(-1)]
    _check_unique(path, sample * len(microns) + channel)
    values = np.full((len(unique), len(microns)), np.nan)
    values[sample, channel] = rows[:, _FR11]
    # the file gives micrometres; Table wavelengths are nm (rounded: 0.351 * 1000 is not 351)
    return np.round(microns * 1000.0, 6), unique[order], values


def _check_unique(path, cell):
    """FormatError at the second row that repeats a (wavelength, geometry) pair."""
    _, first, inverse = np.unique(cell, return_index=True, return_inverse=True)
    original = first[inverse]
    if np.all(original == np.arange(len(cell))):
        return
    r = int(np.argmax(original != np.arange(len(cell))))
    raise FormatError(path, f"line {r + 2}", f"repeats the wavelength and geometry of line "
                                             f"{original[r] + 2}; expected one row per pair")


def _signed_polar(theta, phi):
    """``(|theta|, phi + 180 where theta < 0)`` in degrees: a negative polar angle points to the
    opposite azimuth (in-plane goniometer convention, see the module docstring)."""
    return np.abs(theta), np.where(theta < 0.0, phi + 180.0, phi)
