"""IES LM-63 photometric files (the 1995 and 2002 formats): luminous intensity over direction.

An LM-63 file (ANSI/IES LM-63-2002, "Standard File Format for the Electronic Transfer of
Photometric Data") holds, after a first line naming the format and ``[KEYWORD]`` lines:

- ``TILT=NONE`` (tilt tables, for lamps whose output changes with their tilt, are not read);
- ten numbers: lamps, lumens per lamp, candela multiplier, number of vertical angles, number of
  horizontal angles, photometric type (1: C, 2: B, 3: A), units, width, length, height;
- three numbers: ballast factor, a value for future use, input watts;
- the vertical angles, the horizontal angles, then the candela values, one run of vertical
  angles per horizontal angle. Numbers are separated by blanks, commas or line ends, and runs
  may wrap over any number of lines.

Type C photometry only: vertical angles from the nadir (0) to the zenith (180), horizontal
angles about the vertical axis, counterclockwise seen from above (LM-63-2002, section 3). The
horizontal range says the symmetry of the distribution: 0 (one plane: symmetric about the
axis), 0-90 (symmetric in each quadrant), 0-180 (symmetric about the 0-180 plane), 90-270
(symmetric about the 90-270 plane, LM-63-1995) or 0-360 (none).
"""

import re
from pathlib import Path

import numpy as np

from ..errors import FormatError
from ..io._text import parse_float

__all__ = ["read_ies"]

#: Photometric type of Type C goniometry (LM-63-2002, section 5.6)
TYPE_C = 1
#: Largest IES file read: 16 MB (a 1-degree grid over the sphere is 65,000 numbers, 500 kB).
IES_BYTES = 16 << 20
_NUMBER = re.compile(r"[^\s,]+")


def read_ies(path):
    """Read an IES LM-63 file (Type C, ``TILT=NONE``).

    Parameters
    ----------
    path : str or path-like

    Returns
    -------
    table : ndarray (n_theta, n_phi)
        Luminous intensity in candela (the file's values times its candela multiplier), over
        the full circle of horizontal angles whatever the file's symmetry.
    theta_deg : ndarray (n_theta,)
        Vertical angles in degrees from the nadir, increasing.
    phi_deg : ndarray (n_phi,)
        Horizontal angles in degrees, increasing from 0 to 360 (both included: the first and
        last columns are the same plane).

    Raises
    ------
    FormatError
        For a file that is not LM-63 Type C with ``TILT=NONE``, or whose numbers are missing,
        malformed or out of range; the message names the file and line.
    """
    from ..io.files import read_bytes
    path = Path(path)
    # LM-63 files are ASCII; latin-1 decodes any byte, so a stray one is reported where it
    # breaks a number
    lines = read_bytes(path, IES_BYTES, "an IES LM-63 file").decode("latin-1").splitlines()
    tokens = _tokens_after_tilt(path, lines)
    header = _take(path, tokens, 13, "the 13 numbers of the lamp and ballast header")
    (n_lamps, _lumens, multiplier, n_v, n_h, ptype, _units, _w, _l, _h, _ballast, _future,
     _watts) = (value for value, _line in header)
    line_of = {k: line for k, (_v, line) in zip(("n_v", "n_h", "type", "mult"),
                                                  (header[3], header[4], header[5], header[2]))}
    if ptype != TYPE_C:
        raise FormatError(path, line_of["type"], f"photometric type {ptype:g}: only Type C (1) "
                          "is supported")
    for key, n in (("n_v", n_v), ("n_h", n_h)):
        if n != int(n) or n < 1:
            raise FormatError(path, line_of[key], f"expected a positive whole number of angles, "
                              f"got {n:g}")
    if not multiplier > 0:
        raise FormatError(path, line_of["mult"], f"candela multiplier must be positive, got "
                          f"{multiplier:g}")
    n_v, n_h = int(n_v), int(n_h)
    theta = _angles(path, _take(path, tokens, n_v, f"{n_v} vertical angles"), "vertical", 180.0)
    phi = _angles(path, _take(path, tokens, n_h, f"{n_h} horizontal angles"), "horizontal", 360.0)
    values = _take(path, tokens, n_v * n_h, f"{n_v * n_h} candela values")
    cd = np.array([v for v, _ in values], float).reshape(n_h, n_v).T
    bad = np.flatnonzero(cd.T.ravel() < 0)
    if bad.size:
        raise FormatError(path, values[bad[0]][1], f"negative candela value "
                          f"{values[bad[0]][0]:g}")
    if tokens:
        raise FormatError(path, tokens[0][1], f"unexpected number {tokens[0][0]!r} after the "
                          "candela values")
    table, full_phi = _full_circle(path, header[4][1], cd, phi)
    return table * multiplier, theta, full_phi


def _tokens_after_tilt(path, lines):
    """The whitespace- or comma-separated tokens after the TILT line, with their line numbers."""
    first = lines[0].strip() if lines else ""
    if not lines or not (first.upper().startswith(("IESNA", "TILT=")) or first.startswith("[")):
        raise FormatError(path, 1, "expected an IES LM-63 file (a first line 'IESNA:LM-63-2002' "
                          "or 'IESNA:LM-63-1995', or a 1986 file's keywords)")
    for i, line in enumerate(lines):
        text = line.strip()
        if text.upper().startswith("TILT"):
            value = text.partition("=")[2].strip().upper()
            if value != "NONE":
                raise FormatError(path, i + 1, f"TILT={value or '?'}: only TILT=NONE is "
                                  "supported")
            return [(tok, j + 1) for j in range(i + 1, len(lines))
                    for tok in _NUMBER.findall(lines[j])]
    raise FormatError(path, len(lines), "no TILT= line before the photometric data")


def _take(path, tokens, n, what):
    """Pop n numbers (value, line) off the front of ``tokens``."""
    if len(tokens) < n:
        where = tokens[-1][1] if tokens else "end"
        raise FormatError(path, where, f"file ends early: expected {what}, found only "
                          f"{len(tokens)} more numbers")
    out = []
    for tok, line in tokens[:n]:
        try:
            value = parse_float(tok)
        except ValueError:
            raise FormatError(path, line, f"expected a number ({what}), got {tok!r}") from None
        if not np.isfinite(value):
            raise FormatError(path, line, f"expected a finite number ({what}), got {tok!r}")
        out.append((value, line))
    del tokens[:n]
    return out


def _angles(path, values, kind, top):
    a = np.array([v for v, _ in values], float)
    if a.size > 1 and np.any(np.diff(a) <= 0):
        k = int(np.flatnonzero(np.diff(a) <= 0)[0]) + 1
        raise FormatError(path, values[k][1], f"{kind} angles must increase, got {a[k - 1]:g} "
                          f"then {a[k]:g}")
    if a[0] < 0 or a[-1] > top:
        line = values[0][1] if a[0] < 0 else values[-1][1]
        raise FormatError(path, line, f"{kind} angles must lie in [0, {top:g}] degrees, got "
                          f"{a[0]:g} to {a[-1]:g}")
    return a


def _full_circle(path, line, cd, phi):
    """Expand the file's horizontal range to 0-360 by its symmetry (LM-63-2002, 5.8.3)."""
    first, last = phi[0], phi[-1]
    if phi.size == 1 and first == 0:
        # one plane: the same intensity at every horizontal angle
        return np.repeat(cd, 2, axis=1), np.array([0.0, 360.0])
    if first == 0 and last == 90:
        # quadrant symmetry: phi, 180 - phi, 180 + phi and 360 - phi see the same intensity
        images = [(phi, slice(None)), (180.0 - phi[::-1], slice(None, None, -1)),
                  (180.0 + phi, slice(None)), (360.0 - phi[::-1], slice(None, None, -1))]
    elif first == 0 and last == 180:
        # bilateral symmetry about the 0-180 plane: phi and 360 - phi
        images = [(phi, slice(None)), (360.0 - phi[::-1], slice(None, None, -1))]
    elif first == 90 and last == 270:
        # bilateral symmetry about the 90-270 plane (LM-63-1995): phi and 180 - phi (mod 360)
        lower = phi <= 180.0
        upper = phi >= 180.0
        images = [(180.0 - phi[lower][::-1], np.flatnonzero(lower)[::-1]), (phi, slice(None)),
                  (540.0 - phi[upper][::-1], np.flatnonzero(upper)[::-1])]
    elif first == 0 and last == 360:
        return cd, phi
    else:
        raise FormatError(path, line, f"horizontal angles {first:g} to {last:g}: expected 0 "
                          "(one plane), 0-90, 0-180, 90-270 or 0-360")
    angles = np.concatenate([a for a, _ in images])
    cols = np.concatenate([cd[:, s] for _, s in images], axis=1)
    order = np.argsort(angles, kind="stable")
    angles, cols = angles[order], cols[:, order]
    # the mirror images meet at the planes of symmetry: keep one column of each angle
    keep = np.concatenate([[True], np.diff(angles) > 1e-9])
    return cols[:, keep], angles[keep]
