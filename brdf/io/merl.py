"""MERL binary BRDF tables (Matusik et al. 2003, "A Data-Driven Reflectance Model").

Layout (docs/conventions.md §6): three little-endian int32 dimensions ``(90, 90, 180)``, then
``3 x 1,458,000`` little-endian float64 in channel-major order R, G, B; sample
``i_phi_d + 180 i_theta_d + 16200 i_theta_h`` of a channel times the channel's scale
``(1/1500, 1.15/1500, 1.66/1500)`` is the BRDF in 1/sr; negative stored values mark missing
samples. The grid lives in Rusinkiewicz half/difference angles of an isotropic BRDF: node
``(i, j, k)`` sits at ``theta_h = (i/90)^2 pi/2`` (square-root spacing, dense near the specular
peak), ``theta_d = j (pi/2)/90`` and ``phi_d = k pi/180``; ``phi_d`` covers ``[0, pi)`` only,
since swapping ``wi`` and ``wo`` adds ``pi`` to it (reciprocity).

:class:`MerlTable` keeps the stored array as read, so ``read`` then ``write`` gives back the same
bytes, and looks values up with a compiled trilinear (or nearest-node) kernel.
"""

import functools
import math

import numpy as np

from .._jit import OPTIMISED, kernel, prefetch, threaded_kernel
from ..errors import FormatError, InputError
from ..geometry import POLE_SINE, directions_from_half_diff, flat_pairs
from ..sampling import arctan2
from ..table import HORIZON_SLACK, Table, sample_values
from . import read_bytes, source_of

__all__ = ["FORMAT", "EXTENSIONS", "sniff", "read", "write", "MerlTable", "check_rgb",
           "grid_directions", "grid_angles", "fill_missing", "SHAPE", "SCALE"]

FORMAT = "merl"
EXTENSIONS = (".binary",)
#: write() takes a model too and resamples it at the grid nodes
WRITES_MODELS = True

#: Grid resolution (theta_h, theta_d, phi_d), docs/conventions.md §6.
SHAPE = (90, 90, 180)
#: Samples per channel.
SIZE = SHAPE[0] * SHAPE[1] * SHAPE[2]
#: Stored value x scale = BRDF in 1/sr, per channel R, G, B (docs/conventions.md §6).
SCALE = np.array([1.0 / 1500.0, 1.15 / 1500.0, 1.66 / 1500.0])
SCALE.setflags(write=False)
CHANNELS = ("r", "g", "b")
#: Stored value written for a missing sample (any negative value marks one).
MISSING = -1.0

_HEADER = np.array(SHAPE, dtype="<i4").tobytes()
HEADER_BYTES = len(_HEADER)
FILE_BYTES = HEADER_BYTES + 3 * SIZE * 8  # 34,992,012 (docs/conventions.md §6)

_HALF_PI = 0.5 * math.pi


# --- the file format ----------------------------------------------------------------------------

def sniff(head):
    """True when ``head`` starts with the MERL dimensions 90, 90, 180 (little-endian int32)."""
    return bytes(head[:HEADER_BYTES]) == _HEADER


def read(path):
    """Read a MERL ``.binary`` file.

    Returns
    -------
    MerlTable

    Raises
    ------
    brdf.errors.FormatError
        Wrong dimensions, truncated or oversized file, NaN or infinite stored values; the
        message names the byte offset.
    """
    # twice the exact size: files of other dimensions or with trailing bytes are still read,
    # so that the message says which dimensions or how many bytes too many
    data = read_bytes(path, 2 * FILE_BYTES, "a MERL .binary file")
    raw = _parse(path, data)
    return MerlTable(raw, source=source_of(path, data, FORMAT))


def _parse(path, data):
    """The stored array ``(3, 90, 90, 180)`` of ``data``, a read-only view of its bytes."""
    if len(data) < HEADER_BYTES:
        raise FormatError(path, f"byte {len(data)}",
                          f"truncated: {len(data)} bytes, shorter than the 12-byte header of "
                          f"three int32 dimensions (expected 90, 90, 180)")
    dims = np.frombuffer(data, dtype="<i4", count=3)
    if tuple(dims) != SHAPE:
        raise FormatError(path, f"byte {4 * int(np.argmax(dims != SHAPE))}", _dims_message(dims))
    if len(data) != FILE_BYTES:
        raise FormatError(path, f"byte {min(len(data), FILE_BYTES)}", _size_message(len(data)))
    raw = np.frombuffer(data, dtype="<f8", offset=HEADER_BYTES).reshape((3,) + SHAPE)
    if not np.isfinite(raw).all():
        raise FormatError(path, *_non_finite(raw))
    check_measured(path, raw, f"byte {HEADER_BYTES}")
    return raw


def check_measured(path, raw, where):
    """Raise :class:`FormatError` at ``where`` if a channel of the stored array ``raw``
    ``(3, 90, 90, 180)`` holds no measured value (all negative: missing); such a table has
    nothing to interpolate, check or fit."""
    measured = (raw >= 0.0).reshape(3, -1).any(axis=1)
    if not measured.all():
        c = int(np.argmin(measured))
        raise FormatError(path, where, f"every stored value of channel {CHANNELS[c]} is "
                                       "negative (missing); expected at least one measured "
                                       "value per channel")


def _dims_message(dims):
    found = ", ".join(str(int(d)) for d in dims)
    hint = " (a big-endian file?)" if tuple(dims.byteswap()) == SHAPE else ""
    return (f"MERL dimensions are {found}{hint}; expected 90, 90, 180 (theta_h, theta_d, phi_d "
            f"as little-endian int32)")


def _size_message(size):
    what = "truncated" if size < FILE_BYTES else "oversized"
    return (f"{what}: {size:,} bytes, expected {FILE_BYTES:,} (12-byte header + 3 x "
            f"{SIZE:,} float64 samples)")


def _non_finite(raw):
    """``(where, expected)`` for the first NaN or infinite stored value."""
    flat = raw.reshape(-1)
    n = int(np.flatnonzero(~np.isfinite(flat))[0])
    c, i, j, k = np.unravel_index(n, raw.shape)
    return (f"byte {HEADER_BYTES + 8 * n}",
            f"stored value is {flat[n]} (channel {CHANNELS[c]}, i_theta_h {i}, i_theta_d {j}, "
            f"i_phi_d {k}); expected a finite number (negative marks a missing sample)")


def write(table, path):
    """Write ``table`` as a MERL ``.binary`` file at ``path``.

    A :class:`MerlTable` is written as stored (``read`` then ``write`` gives the same bytes). Any
    other 3-channel RGB table or model is first resampled at the grid nodes by its ``eval``
    (:meth:`MerlTable.from_table`); its standard deviations have no place in the format.

    Raises
    ------
    brdf.errors.InputError
        When ``table`` is not RGB (1 channel, spectral, ...).
    """
    if not isinstance(table, MerlTable):
        table = MerlTable.from_table(table)
    with open(path, "wb") as f:
        f.write(_HEADER)
        table.raw.astype("<f8", copy=False).tofile(f)


def check_rgb(subject):
    """Raise :class:`InputError` unless ``subject`` (a table or model) has exactly 3 channels
    that are not wavelengths: what a MERL file can store as r, g, b."""
    channels = getattr(subject, "channels", None)
    if channels != 3 or getattr(subject, "wavelengths", None) is not None:
        kind = "spectral" if getattr(subject, "wavelengths", None) is not None else "non-RGB"
        raise InputError(f"MERL stores RGB (3 channels r, g, b); {subject} is {kind} with "
                         f"{channels} channel(s): write it as .npz or .csv instead")


# --- the grid -----------------------------------------------------------------------------------

def grid_angles():
    """Rusinkiewicz angles ``(theta_h, theta_d, phi_d)`` of every node, each ``(1458000,)``, in
    index order ``i_phi_d + 180 i_theta_d + 16200 i_theta_h``."""
    i, j, k = np.meshgrid(*(np.arange(n, dtype=float) for n in SHAPE), indexing="ij")
    theta_h = (i.reshape(-1) / SHAPE[0]) ** 2 * _HALF_PI  # square-root mapping, inverted
    theta_d = j.reshape(-1) * (_HALF_PI / SHAPE[1])
    phi_d = k.reshape(-1) * (math.pi / SHAPE[2])
    return theta_h, theta_d, phi_d


@functools.lru_cache(maxsize=1)
def grid_directions():
    """Directions ``(wi, wo)``, each ``(1458000, 3)`` and read-only, of every grid node in index
    order (``phi_h = 0``). About a quarter of the nodes put ``wi`` or ``wo`` below the horizon:
    the layout covers every angle combination, not only the measurable ones."""
    theta_h, theta_d, phi_d = grid_angles()
    wi, wo = directions_from_half_diff(theta_h, 0.0, theta_d, phi_d)
    for a in (wi, wo):
        a.setflags(write=False)
    return wi, wo


@functools.lru_cache(maxsize=1)
def _unmeasurable():
    """Mask of the nodes whose ``wi`` or ``wo`` is not above the horizon, ``(1458000,)``."""
    wi, wo = grid_directions()
    return np.minimum(wi[:, 2], wo[:, 2]) < HORIZON_SLACK


# --- the table ----------------------------------------------------------------------------------

class MerlTable(Table):
    """A MERL table: isotropic RGB samples on the half/difference grid.

    Parameters
    ----------
    raw : array_like, shape (3, 90, 90, 180)
        Stored values (channel, i_theta_h, i_theta_d, i_phi_d), BRDF / channel scale; negative
        marks a missing sample. Kept read-only as given, so writing it back is bit-exact.
    sigma : array_like, shape (1458000, 3), optional
        Standard deviations in 1/sr, in memory only (the file format has no place for them).
    metadata, source, name
        As for :class:`brdf.table.Table`.

    Notes
    -----
    ``wi``, ``wo`` and ``values`` (one row per node, in index order) are computed on first use:
    the lookup needs only the grid. Nodes below the horizon are rows too (their directions have
    ``z < 0``); they hold whatever the file stores there, and are missing in tables made by
    :meth:`from_grid_values`.
    """

    format = FORMAT
    reciprocal_by_layout = True

    def __init__(self, raw, *, sigma=None, metadata=None, source=None, name=None):
        raw = np.asarray(raw, dtype=np.float64)
        if raw.shape != (3,) + SHAPE:
            raise InputError(f"MERL stored array must be shaped (3, 90, 90, 180), got {raw.shape}")
        if not np.isfinite(raw).all():
            raise InputError("MERL stored array holds NaN or infinite values; missing samples are "
                             "negative")
        if raw.flags.writeable:
            raw = raw.copy()
            raw.setflags(write=False)
        self.raw = raw
        self._sigma = None if sigma is None else sample_values(sigma, "sigma", SIZE)
        if self._sigma is not None and self._sigma.shape != (SIZE, 3):
            raise InputError(f"sigma must be shaped ({SIZE}, 3), got {self._sigma.shape}")
        info = {"units": "1/sr", "grid": list(SHAPE), "channel_scale": SCALE.tolist()}
        info.update(metadata or {})
        self._init_common(3, None, CHANNELS, True, info, source, name or (
            source.name if source is not None else "merl"))

    @classmethod
    def from_grid_values(cls, values, *, sigma=None, metadata=None, source=None, name=None):
        """A table from BRDF values at the grid nodes.

        Parameters
        ----------
        values : array_like, shape (1458000, 3)
            BRDF in 1/sr at the nodes of :func:`grid_directions`, in index order. NaN or
            negative values are stored as missing (the format has no other way to say so), and
            so are the nodes whose ``wi`` or ``wo`` is not above the horizon: no instrument
            measures there, and the zero a model gives there would pull interpolation near
            grazing angles down.
        sigma, metadata, source, name
            As for :class:`MerlTable`.
        """
        values = sample_values(values, "values", SIZE)
        if values.shape[1] != 3:
            raise InputError(f"MERL grid values must be shaped ({SIZE}, 3) (r, g, b), got "
                             f"{values.shape}")
        raw = values.T / SCALE[:, None]  # stored = BRDF / channel scale (docs/conventions.md §6)
        raw[~(raw >= 0.0)] = MISSING     # NaN and negative values alike
        raw[:, _unmeasurable()] = MISSING
        return cls(raw.reshape((3,) + SHAPE), sigma=sigma, metadata=metadata, source=source,
                   name=name)

    @classmethod
    def from_table(cls, table):
        """Resample an RGB table (or model) at the grid nodes through its ``eval``.

        Raises
        ------
        brdf.errors.InputError
            When ``table`` does not have exactly 3 non-spectral channels.
        """
        check_rgb(table)
        wi, wo = grid_directions()
        measurable = ~_unmeasurable()
        values = np.full((SIZE, 3), np.nan)
        values[measurable] = np.asarray(table.eval(wi[measurable], wo[measurable]))
        return cls.from_grid_values(values, metadata=getattr(table, "metadata", None),
                                    name=getattr(table, "name", None))

    def with_values(self, values, sigma=None, **changes):
        """A :class:`MerlTable` with new node ``values`` (1458000, 3); see
        :meth:`from_grid_values`."""
        options = dict(metadata=self.metadata, name=self.name)
        options.update(changes)
        return MerlTable.from_grid_values(values, sigma=sigma, **options)

    # -- samples (computed on first use) -----------------------------------------------------
    def __len__(self):
        return SIZE

    @functools.cached_property
    def values(self):
        """BRDF at the nodes in 1/sr, ``(1458000, 3)`` in index order; NaN where missing."""
        v = self.raw.reshape(3, SIZE).T * SCALE  # docs/conventions.md §6
        v[self.raw.reshape(3, SIZE).T < 0.0] = np.nan
        v = np.ascontiguousarray(v)
        v.setflags(write=False)
        return v

    @property
    def wi(self):
        """Incident direction of each node, ``(1458000, 3)`` (:func:`grid_directions`)."""
        return grid_directions()[0]

    @property
    def wo(self):
        """Outgoing direction of each node, ``(1458000, 3)`` (:func:`grid_directions`)."""
        return grid_directions()[1]

    @functools.cached_property
    def grid(self):
        """``values`` as the lookup grid ``(90, 90, 180, 3)`` (a view)."""
        return self.values.reshape(SHAPE + (3,))

    @functools.cached_property
    def filled(self):
        """The grid with each missing sample replaced by the nearest valid one in index space
        (the lookup's fallback when a whole cell is missing)."""
        return fill_missing(self.grid)

    # -- evaluation ------------------------------------------------------------------------------
    def eval(self, wi, wo, method="linear"):
        """BRDF ``(..., 3)`` in 1/sr looked up in the grid; 0 below the horizon.

        Parameters
        ----------
        method : {"linear", "nearest"}
            ``linear``: trilinear in (theta_h index, theta_d, phi_d) over the valid corners of
            the cell, weights renormalised; the nearest valid sample where the whole cell is
            missing. ``nearest``: the nearest node (or the valid sample nearest to it).
        """
        wi, wo, shape = flat_pairs(wi, wo)
        out, _ = self._lookup(wi, wo, method)
        return out.reshape(shape + (3,))

    def eval_one_sided(self, wi, wo, method="linear"):
        """``(values (n, 3), inside (n,))``; ``inside`` is False where no valid sample was
        within reach (the nearest valid one stood in) or below the horizon. The layout is
        reciprocal, so this is :meth:`eval`."""
        wi, wo, _ = flat_pairs(wi, wo)
        return self._lookup(wi, wo, method)

    def _lookup(self, wi, wo, method):
        if method not in ("linear", "nearest"):
            raise InputError(f"method must be 'linear' or 'nearest', got {method!r}")
        out = np.empty((len(wi), 3))
        inside = np.empty(len(wi), dtype=np.bool_)
        if method == "linear":
            _trilinear(self.grid, self.filled, wi, wo, out, inside)
        else:
            _nearest(self.grid, self.filled, wi, wo, out, inside)
        return out, inside


def fill_missing(grid):
    """``grid`` ``(..., C)`` with every NaN replaced by the nearest valid value of its channel
    (Euclidean distance in index space, scipy's exact distance transform); a channel with no
    valid value stays NaN. Returns ``grid`` itself when nothing is missing."""
    missing = np.isnan(grid)
    if not missing.any():
        return grid
    from scipy.ndimage import distance_transform_edt
    filled = grid.copy()
    nearest = {}  # channels usually share one pattern of missing samples: one transform for all
    for c in range(grid.shape[-1]):
        mask = missing[..., c]
        if not mask.any() or mask.all():
            continue
        key = mask.tobytes()
        if key not in nearest:
            nearest[key] = tuple(distance_transform_edt(mask, return_distances=False,
                                                        return_indices=True))
        filled[..., c] = grid[nearest[key] + (c,)]
    filled.setflags(write=False)
    return filled


# --- compiled lookup ----------------------------------------------------------------------------

@kernel(linked=OPTIMISED)
def grid_coordinates(ix, iy, iz, ox, oy, oz):
    """Continuous grid coordinates ``(u, v, w)`` of a pair of directions above the horizon.

    Rusinkiewicz 1998, section 3 (as :func:`brdf.geometry.half_diff_from_directions`): the half
    vector gives theta_h; wi rotated by -phi_h about z and -theta_h about y gives the difference
    vector. Then u = sqrt(theta_h / (pi/2)) 90, v = theta_d / (pi/2) 90 and w = phi_d / pi 180
    with phi_d folded into [0, pi) (docs/conventions.md §6). The pair is put in a fixed order
    first, so that swapping ``wi`` and ``wo`` gives the same coordinates to the last bit.
    """
    if ix > ox or (ix == ox and (iy > oy or (iy == oy and iz > oz))):
        ix, iy, iz, ox, oy, oz = ox, oy, oz, ix, iy, iz
    ni = math.sqrt(ix * ix + iy * iy + iz * iz)
    no = math.sqrt(ox * ox + oy * oy + oz * oz)
    ix, iy, iz = ix / ni, iy / ni, iz / ni
    hx, hy, hz = ix + ox / no, iy + oy / no, iz + oz / no
    nh = math.sqrt(hx * hx + hy * hy + hz * hz)
    hx, hy, hz = hx / nh, hy / nh, hz / nh
    sin_h = math.sqrt(hx * hx + hy * hy)
    theta_h = arctan2(sin_h, hz)
    cos_p, sin_p = 1.0, 0.0  # phi_h = 0 at the pole (geometry.POLE_SINE convention)
    if sin_h >= POLE_SINE:
        cos_p, sin_p = hx / sin_h, hy / sin_h
    a = ix * cos_p + iy * sin_p                  # rotation by -phi_h about z ...
    dx = a * hz - iz * sin_h                     # ... then by -theta_h about y
    dy = iy * cos_p - ix * sin_p
    dz = a * sin_h + iz * hz
    sin_d = math.sqrt(dx * dx + dy * dy)
    theta_d = arctan2(sin_d, dz)
    phi_d = arctan2(dy, dx) if sin_d >= POLE_SINE else 0.0
    # reciprocity: swapping wi and wo adds pi to phi_d, so phi_d is periodic over pi
    # phi_d % pi without fmod's call: atan2 lies in [-pi, pi] (pi itself folds to 0 below)
    phi_d = phi_d + math.pi if phi_d < 0.0 else phi_d
    u = math.sqrt(theta_h / _HALF_PI) * SHAPE[0]
    v = theta_d / _HALF_PI * SHAPE[1]
    w = phi_d / math.pi * SHAPE[2]
    if w >= SHAPE[2]:  # phi_d within rounding of pi is phi_d = 0
        w -= SHAPE[2]
    return u, v, w


@kernel(linked=OPTIMISED)
def _clamped_cell(x, n):
    """Lower node and fraction of a coordinate on nodes 0..n-1, clamped to the end nodes."""
    x = min(max(x, 0.0), n - 1.0)
    i = min(int(x), n - 2)
    return i, x - i


@kernel(linked=OPTIMISED)
def _nearest_node(u, v, w, shape):
    """Indices of the node nearest to (u, v, w); theta indices clamped, phi_d periodic."""
    i = min(int(u + 0.5), shape[0] - 1)
    j = min(int(v + 0.5), shape[1] - 1)
    k = int(w + 0.5) % shape[2]
    return i, j, k


@kernel(linked=OPTIMISED)
def _add_corner(grid, i, j, p, wt, acc):
    """``acc`` = (sums r, g, b, weights r, g, b) plus node (i, j, p) weighted by ``wt``; missing
    (NaN) samples are left out."""
    r, g, b = grid[i, j, p, 0], grid[i, j, p, 1], grid[i, j, p, 2]
    sr, sg, sb, wr, wg, wb = acc
    if r == r:
        sr += wt * r
        wr += wt
    if g == g:
        sg += wt * g
        wg += wt
    if b == b:
        sb += wt * b
        wb += wt
    return sr, sg, sb, wr, wg, wb


@kernel(linked=OPTIMISED)
def _pair_coordinates(wi, wo, k, out, inside):
    """``(above, u, v, w)``: pair k's continuous grid coordinates, or ``above`` False (and
    ``out[k]`` zero, ``inside[k]`` False) when a direction is below the horizon."""
    iz, oz = wi[k, 2], wo[k, 2]
    if iz <= 0.0 or oz <= 0.0:
        out[k, :] = 0.0
        inside[k] = False
        return False, 0.0, 0.0, 0.0
    u, v, w = grid_coordinates(wi[k, 0], wi[k, 1], iz, wo[k, 0], wo[k, 1], oz)
    return True, u, v, w


@kernel(linked=OPTIMISED)
def _cell(u, v, w, shape):
    """Lower corner (i0, j0, p0) of the cell holding grid coordinates (u, v, w), the fractions
    within it, and the upper phi_d index p1 (wrapping over pi)."""
    n0, n1, n2 = shape[0], shape[1], shape[2]
    i0, fu = _clamped_cell(u, n0)
    j0, fv = _clamped_cell(v, n1)
    p0 = min(int(w), n2 - 1)
    p1 = p0 + 1 if p0 + 1 < n2 else 0  # phi_d wraps over pi
    return i0, j0, p0, p1, fu, fv, w - p0


@kernel(linked=OPTIMISED)
def fetch_cell(grid, ix, iy, iz, ox, oy, oz, out, k):
    """The first half of a trilinear lookup of a pair above the horizon: its grid coordinates
    into ``out[k, :3]``, and its cell's corners asked of the caches (prefetched) without
    waiting for them; :func:`trilinear_at` finishes it. A lookup waits on memory for its
    corners (the grid is 35 MB), so a batch of lookups fetches every cell first, and the waits
    overlap."""
    u, v, w = grid_coordinates(ix, iy, iz, ox, oy, oz)
    out[k, 0], out[k, 1], out[k, 2] = u, v, w
    i0, j0, p0, p1, _, _, _ = _cell(u, v, w, grid.shape)
    for di in range(2):
        for dj in range(2):
            prefetch(grid, (i0 + di, j0 + dj, p0, 0))
            prefetch(grid, (i0 + di, j0 + dj, p1, 2))


@kernel(linked=OPTIMISED)
def trilinear_at(grid, filled, out, k):
    """Trilinear lookup at the grid coordinates in ``out[k, :3]`` (:func:`fetch_cell`) into
    ``out[k, :3]``, over the valid corners of its cell (weights renormalised), the nearest
    valid sample (``filled``) where no corner with positive weight is valid. Returns whether
    every channel had a valid corner."""
    u, v, w = out[k, 0], out[k, 1], out[k, 2]
    i0, j0, p0, p1, fu, fv, fw = _cell(u, v, w, grid.shape)
    acc = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    for di in range(2):
        wu = fu if di else 1.0 - fu
        for dj in range(2):
            wv = wu * (fv if dj else 1.0 - fv)
            acc = _add_corner(grid, i0 + di, j0 + dj, p0, wv * (1.0 - fw), acc)
            acc = _add_corner(grid, i0 + di, j0 + dj, p1, wv * fw, acc)
    ok = True
    for c in range(3):
        if acc[3 + c] > 0.0:
            out[k, c] = acc[c] / acc[3 + c]
        else:
            i, j, p = _nearest_node(u, v, w, grid.shape)
            out[k, c] = filled[i, j, p, c]
            ok = False
    return ok


#: Pairs a lookup's thread fetches (:func:`fetch_cell`) before it looks them up: their cells'
#: 512 lines fit the first-level cache
FETCHED = 64


@threaded_kernel("wi", "wo", "out", "inside")
def _trilinear(grid, filled, wi, wo, out, inside):
    """Trilinear lookup of every pair (:func:`fetch_cell`, then :func:`trilinear_at`); 0 below
    the horizon."""
    n = wi.shape[0]
    for k0 in range(0, n, FETCHED):
        k1 = min(k0 + FETCHED, n)
        for k in range(k0, k1):
            inside[k] = wi[k, 2] > 0.0 and wo[k, 2] > 0.0
            if inside[k]:
                fetch_cell(grid, wi[k, 0], wi[k, 1], wi[k, 2], wo[k, 0], wo[k, 1], wo[k, 2], out,
                           np.int64(k))
        for k in range(k0, k1):
            if inside[k]:
                inside[k] = trilinear_at(grid, filled, out, np.int64(k))
            else:
                out[k, 0] = out[k, 1] = out[k, 2] = 0.0


@threaded_kernel("wi", "wo", "out", "inside")
def _nearest(grid, filled, wi, wo, out, inside):
    """Value of the nearest node (the nearest valid sample where that node is missing)."""
    nch = grid.shape[3]
    for k in range(wi.shape[0]):
        above, u, v, w = _pair_coordinates(wi, wo, np.int64(k), out, inside)
        if not above:
            continue
        i, j, p = _nearest_node(u, v, w, grid.shape)
        ok = True
        for c in range(nch):
            out[k, c] = filled[i, j, p, c]
            ok = ok and grid[i, j, p, c] == grid[i, j, p, c]
        inside[k] = ok
