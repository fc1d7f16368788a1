"""Measured BRDF tables: samples, provenance, interpolation and albedo.

A :class:`Table` holds what a gonioreflectometer measured: incident and outgoing directions, the
BRDF value per channel (1/sr, ``NaN`` where a sample is missing), optional per-sample standard
deviations, the channels' wavelengths, metadata and provenance. It answers ``eval(wi, wo)`` by
interpolation and ``albedo(wi)`` by quadrature over that interpolant, so :func:`brdf.check`, the
fitter, the renderer and the plots take it like a parametric model. Format readers (``brdf.io``)
return tables; grid formats subclass :class:`Table` with their own lookup.

>>> import numpy as np, brdf
>>> from brdf.geometry import directions_from_degrees
>>> wi = directions_from_degrees(np.zeros(3), np.zeros(3))
>>> wo = directions_from_degrees([0.0, 30.0, 60.0], [0.0, 0.0, 0.0])
>>> t = Table(wi, wo, [[0.3], [0.3], [0.3]], name="three samples")
>>> t.channels, len(t)
(1, 3)
"""

import math
from collections.abc import Iterable, Mapping

import numpy as np

from .arguments import integer, shown
from .errors import InputError
from .geometry import (broadcast_shape, degrees_from_directions, direction_array,
                       directions_from_degrees, flat_pairs, real_array, uniform_array)

__all__ = ["Table", "AngleTable", "ScatteredInterpolant", "regular_grid", "half_vector_rule",
           "channel_names_for", "sample_values", "summary_rows"]

#: Directions may dip this far below the horizon (z) and still count as measured: angles stored
#: in degrees with a few digits put theta = 90 at z ~ 1e-17 either side.
HORIZON_SLACK = 1e-9
#: Polar angle (radians) below which a direction's azimuth is taken as undefined.
POLE_ANGLE = 1e-9
#: Largest ``resolution`` of :meth:`Table.albedo`: 2 n^2 half vectors per direction (2 million
#: at 1024), each an interpolation.
MAX_RESOLUTION = 1024


def channel_names_for(channels, wavelengths=None):
    """Default channel names: ``r, g, b`` for 3 channels, ``value`` for 1, ``<w>nm`` spectral."""
    if wavelengths is not None:
        return tuple(f"{w:g}nm" for w in wavelengths)
    if channels == 3:
        return ("r", "g", "b")
    if channels == 1:
        return ("value",)
    return tuple(f"c{k}" for k in range(channels))


def summary_rows(summary, digits=6):
    """``(field, text)`` rows of a :meth:`Table.summary` for people, numbers rounded to
    ``digits`` significant digits (``brdf-fit info`` and the demo's report print these).

    Samples (direction pairs) and values (a sample's entries, one per channel) are counted
    apart: ``samples 1,458,000 x 3 channels = 4,374,000 values``, then the missing samples,
    the partially missing ones and the missing values."""
    from .formatting import round_numbers, significant
    source = summary["source"] or {}
    n, c = summary["samples"], summary["channels"]
    rows = [("file", source["path"]) if source.get("path") else ("name", summary["name"]),
            ("format", summary["format"])]
    if source:
        rows += [("size", f"{source.get('size', 0):,} bytes"), ("sha256", source.get("sha256", ""))]
    if summary["wavelengths_nm"]:
        w = summary["wavelengths_nm"]
        channels = (f"{c} wavelengths, {significant(w[0], digits)} .. "
                    f"{significant(w[-1], digits)} nm")
    else:
        channels = f"{c} ({', '.join(summary['channel_names'])})"
    rows += [("samples", f"{n:,} direction pairs x {c} channel{'s' if c != 1 else ''} = "
                         f"{n * c:,} values"),
             ("channels", channels),
             ("isotropic", ("yes" if summary["isotropic"] else "no")
              + (" (in-plane scan)" if summary["in_plane"] else "")),
             ("sigma", "per sample" if summary["sigma"] else "none"),
             ("missing samples", f"{summary['missing_samples']:,} of {n:,} (no value in any "
                                 "channel)"),
             ("partially missing samples", f"{summary['partially_missing_samples']:,} (a value "
                                           "missing in some channels)"),
             ("missing values", f"{summary['missing_values']:,} of {n * c:,}"),
             ("negative values", f"{summary['negative_values']:,} of {n * c:,}")]
    lo, hi = summary["value_range"]
    if lo <= hi:
        rows.append(("range", f"{significant(lo, digits)} .. {significant(hi, digits)} 1/sr"))
    rows += [(f"{name} [deg]", f"{significant(a, digits)} .. {significant(b, digits)}")
             for name, (a, b) in ((k, v) for k, v in summary["angles_deg"].items()
                                  if v is not None)]
    # metadata strings stay as written (a version "1.0" is not a measurement)
    rows += [(f"meta {k}", v if isinstance(v, str) else round_numbers(v, digits))
             for k, v in summary["metadata"].items()]
    return rows


class Table:
    """Measured BRDF samples with interpolation.

    Parameters
    ----------
    wi, wo : array_like, shape (N, 3)
        Unit incident (towards the light) and outgoing (towards the detector) directions in the
        local frame, both in the upper hemisphere.
    values : array_like, shape (N, C) or (N,)
        BRDF in 1/sr. ``NaN`` marks a missing sample: it is never used by the interpolant.
        Negative values are kept (the non-negativity check reports them).
    sigma : array_like, shape (N, C), optional
        Standard deviation of each value (1/sr), e.g. from the noise model of
        :func:`brdf.measure` or a CSV ``sigma`` column.
    wavelengths : array_like, shape (C,), optional
        Wavelength of each channel in nm (spectral tables).
    channel_names : sequence of str, optional
        One name per channel (default from :func:`channel_names_for`).
    isotropic : bool
        Whether the material is rotation invariant about the normal. Isotropic tables are
        interpolated in 3 dimensions (theta_i and wo seen from the plane of incidence),
        anisotropic ones in 4.
    metadata : dict, optional
        JSON-ready facts about the measurement (units, source, description, comments).
    source : brdf.io.Source, optional
        Provenance of the file the table was read from (path, SHA-256, format, size).
    name : str, optional
        Short label used in reports (default: the file name, or ``"table"``).
    """

    #: Format of the file the table came from; readers' subclasses override it.
    format = "table"
    #: True when the layout stores one value per reciprocal pair (wi, wo) ~ (wo, wi), so the
    #: table cannot disagree with itself under the swap (the MERL parameterisation).
    reciprocal_by_layout = False

    def __init__(self, wi, wo, values, *, sigma=None, wavelengths=None, channel_names=None,
                 isotropic=True, metadata=None, source=None, name=None):
        self._wi = _sample_directions(wi, "wi")
        self._wo = _sample_directions(wo, "wo")
        if self._wi.shape != self._wo.shape:
            raise InputError(f"wi and wo must have the same shape, got {self._wi.shape} and "
                             f"{self._wo.shape}")
        if not len(self._wi):
            raise InputError("wi: a table needs at least one sample, got shape (0, 3)")
        self._values = sample_values(values, "values", len(self._wi))
        if np.isnan(self._values).all():
            raise InputError(f"values: all {self._values.size} are NaN (missing); a table "
                             "needs at least one measured value")
        self._sigma = None if sigma is None else sample_values(sigma, "sigma", len(self._wi))
        if self._sigma is not None:
            if self._sigma.shape != self._values.shape:
                raise InputError(f"sigma must be shaped like values {self._values.shape}, got "
                                 f"{self._sigma.shape}")
            if (self._sigma < 0.0).any():  # NaN (a missing sigma) passes
                k, c = np.argwhere(self._sigma < 0.0)[0]
                raise InputError(f"sigma[{k}, {c}] = {float(self._sigma[k, c])!r}; a standard "
                                 "deviation must be >= 0 (NaN where missing)")
        self._init_common(self._values.shape[1], wavelengths, channel_names, isotropic,
                          metadata, source, name)

    def _init_common(self, channels, wavelengths, channel_names, isotropic, metadata, source,
                     name):
        """Channel description, flags and provenance (shared with lazy subclasses)."""
        if wavelengths is not None:
            wavelengths = np.asarray(wavelengths, dtype=float).reshape(-1)
            if len(wavelengths) != channels or not np.all(np.isfinite(wavelengths) &
                                                          (wavelengths > 0)):
                raise InputError(f"wavelengths must be {channels} positive numbers (nm), got "
                                 f"{wavelengths.tolist()}")
        if isinstance(channel_names, str) or not (
                channel_names is None or isinstance(channel_names, Iterable)):
            raise InputError(f"channel_names must be a list of {channels} names, got "
                             f"{shown(channel_names)}")
        names = tuple(channel_names) if channel_names is not None else channel_names_for(
            channels, wavelengths)
        if len(names) != channels or not all(isinstance(n, str) for n in names):
            raise InputError(f"channel_names must be {channels} strings, got {shown(names)}")
        if not (metadata is None or isinstance(metadata, Mapping)):
            raise InputError(f"metadata must be a dict, got {shown(metadata)}")
        if not (name is None or isinstance(name, str)):
            raise InputError(f"name must be a string, got {shown(name)}")
        self._channels = int(channels)
        self.wavelengths = wavelengths
        self.channel_names = names
        self.isotropic = bool(isotropic)
        self.metadata = dict(metadata or {})
        self.source = source
        self.name = name or (source.name if source is not None else "table")
        self._interpolants = {}

    # -- samples ---------------------------------------------------------------------------------
    wi = property(lambda self: self._wi, doc="Incident directions of the samples, (N, 3).")
    wo = property(lambda self: self._wo, doc="Outgoing directions of the samples, (N, 3).")
    values = property(lambda self: self._values, doc="BRDF samples in 1/sr, (N, C); NaN missing.")
    sigma = property(lambda self: self._sigma, doc="Standard deviations (N, C) or None.")
    channels = property(lambda self: self._channels, doc="Number of channels C.")
    is_anisotropic = property(lambda self: not self.isotropic)

    def __len__(self):
        return len(self.values)

    def __str__(self):
        return self.name

    def __repr__(self):
        return (f"<{type(self).__name__} {self.name!r}: {len(self)} samples x {self.channels} "
                f"channels, format {self.format}>")

    @property
    def angles(self):
        """Sample angles in degrees, (N, 4): theta_i, phi_i, theta_o, phi_o."""
        ti, pi_ = degrees_from_directions(self.wi)
        to, po = degrees_from_directions(self.wo)
        return np.stack([ti, pi_, to, po], axis=-1)

    @property
    def in_plane(self):
        """True when every sample lies in its plane of incidence (an in-plane scan): such a
        table says nothing about out-of-plane scattering, so its albedo is not defined."""
        if not self.isotropic:
            return False
        return bool(np.all(np.abs(self.coordinates(self.wi, self.wo)[:, 2]) <= 1e-9))

    @property
    def missing(self):
        """Mask (N, C) of missing samples."""
        return np.isnan(self.values)

    def summary(self):
        """JSON-ready facts about the table (what ``brdf-fit info`` prints; :func:`summary_rows`
        words them).

        A sample is one (wi, wo) pair with a value per channel. ``missing_samples`` counts the
        samples missing in every channel, ``partially_missing_samples`` those missing in some
        channels but not all, and ``missing_values`` the missing entries over all channels
        (a MERL table's 346,570 unmeasurable samples are 1,039,710 values in RGB).
        ``negative_values`` counts entries below 0."""
        values = np.asarray(self.values, dtype=float)
        measured = np.isfinite(values)
        per_sample = measured.sum(axis=1)
        # coverage of what was measured (a grid layout may hold nodes nothing can measure)
        angles = self.angles[measured.any(axis=1)]
        coverage = {name: ([float(angles[:, j].min()), float(angles[:, j].max())]
                           if len(angles) else None)
                    for j, name in enumerate(("theta_i", "phi_i", "theta_o", "phi_o"))}
        per_channel = [{"name": name,
                        "min": float(np.min(values[measured[:, c], c], initial=math.inf)),
                        "max": float(np.max(values[measured[:, c], c], initial=-math.inf)),
                        "missing_values": int((~measured[:, c]).sum()),
                        "negative_values": int((values[measured[:, c], c] < 0).sum())}
                       for c, name in enumerate(self.channel_names)]
        return {
            "name": self.name, "format": self.format,
            "source": self.source.to_dict() if self.source is not None else None,
            "samples": len(self), "channels": self.channels,
            "channel_names": list(self.channel_names),
            "wavelengths_nm": None if self.wavelengths is None else self.wavelengths.tolist(),
            "isotropic": self.isotropic, "in_plane": self.in_plane,
            "sigma": self.sigma is not None, "units": "1/sr",
            "angles_deg": coverage,
            "value_range": [float(np.min(values[measured], initial=math.inf)),
                            float(np.max(values[measured], initial=-math.inf))],
            "missing_samples": int((per_sample == 0).sum()),
            "partially_missing_samples": int(((per_sample > 0)
                                              & (per_sample < self.channels)).sum()),
            "missing_values": int((~measured).sum()),
            "negative_values": int((values[measured] < 0).sum()),
            "per_channel": per_channel, "metadata": self.metadata,
        }

    def with_values(self, values, sigma=None, **changes):
        """A table with the same directions and channels but new ``values`` (and ``sigma``)."""
        options = dict(wavelengths=self.wavelengths, channel_names=self.channel_names,
                       isotropic=self.isotropic, metadata=self.metadata, source=None,
                       name=self.name)
        options.update(changes)
        return Table(self.wi, self.wo, values, sigma=sigma, **options)

    # -- evaluation --------------------------------------------------------------------------------
    def eval(self, wi, wo, method="linear"):
        """Interpolated BRDF ``(..., C)`` in 1/sr, symmetric under swapping ``wi`` and ``wo``.

        The value is the mean of the interpolant at ``(wi, wo)`` and at ``(wo, wi)`` (Helmholtz
        reciprocity lets a measurement at one stand for the other); where only one of the two
        lies inside the measured region, that one is used, and where neither does, the nearest
        measured sample. Directions below the horizon give 0.

        Parameters
        ----------
        method : {"linear", "nearest"}
            ``linear``: multilinear on a full grid of angles, otherwise barycentric over a
            Delaunay triangulation of the samples; ``nearest``: the closest sample.
        """
        wi, wo, shape = flat_pairs(wi, wo)
        value, inside = self.eval_one_sided(wi, wo, method)
        swapped, inside_swapped = self.eval_one_sided(wo, wi, method)
        both = (inside & inside_swapped)[:, None]
        out = np.where(both, 0.5 * (value + swapped),
                       np.where(inside_swapped[:, None] & ~inside[:, None], swapped, value))
        above = (wi[:, 2] > 0.0) & (wo[:, 2] > 0.0)
        out[~above] = 0.0
        return out.reshape(shape + (self.channels,))

    def eval_one_sided(self, wi, wo, method="linear"):
        """The interpolant at ``(wi, wo)`` as measured, without the reciprocal average.

        Returns ``(values (n, C), inside (n,))``: ``inside`` is False where the point lies outside
        the measured region and the nearest sample's value was used. The reciprocity check
        compares this with the samples at swapped directions.
        """
        wi, wo, _ = flat_pairs(wi, wo)
        return self._interpolant(method)(wi, wo)

    def coordinates(self, wi, wo):
        """Interpolation coordinates ``(n, 3)`` (isotropic) or ``(n, 4)`` of direction pairs,
        angles in radians: theta_i and wo's polar angle projected on the disk
        in the frame of wi's azimuth (isotropic: folded to one side of the plane of incidence);
        anisotropic tables use both directions' projected disks (4-D). Unlike raw angles these
        do not tear at the pole, where the azimuth is undefined."""
        ti, pi_ = _polar(wi)
        to, po = _polar(wo)
        if self.isotropic:
            dphi = po - pi_
            return np.stack([ti, to * np.cos(dphi), to * np.abs(np.sin(dphi))], axis=-1)
        return np.stack([ti * np.cos(pi_), ti * np.sin(pi_), to * np.cos(po), to * np.sin(po)],
                        axis=-1)

    def _grid_coordinates(self, wi, wo):
        """(theta_i, theta_o, |phi_o - phi_i| folded to [0, pi]) of an isotropic table: the
        axes of a gonioreflectometer's regular grid."""
        ti, pi_ = _polar(wi)
        to, po = _polar(wo)
        dphi = np.abs(np.mod(po - pi_ + math.pi, 2.0 * math.pi) - math.pi)
        return np.stack([ti, to, dphi], axis=-1)

    def _interpolant(self, method):
        if method not in ("linear", "nearest"):
            raise InputError(f"method must be 'linear' or 'nearest', got {method!r}")
        if method not in self._interpolants:
            grid = None
            if self.isotropic and method == "linear":
                coords = self._grid_coordinates(self.wi, self.wo)
                pole = (coords[:, 0] < POLE_ANGLE) | (coords[:, 1] < POLE_ANGLE)
                grid = regular_grid(coords, self.values, free_last=pole)
            if grid is not None:
                self._interpolants[method] = lambda w1, w2: grid(self._grid_coordinates(w1, w2))
                return self._interpolants[method]
            coords = self.coordinates(self.wi, self.wo)
            if self.isotropic and _sliced(coords[:, 0]):
                scattered = SlicedInterpolant(coords, self.values, method)
            else:
                scattered = ScatteredInterpolant(coords, self.values, method)
            self._interpolants[method] = lambda w1, w2: scattered(self.coordinates(w1, w2))
        return self._interpolants[method]

    # -- albedo ------------------------------------------------------------------------------------
    def albedo(self, wi, return_error=False, resolution=48):
        """Directional albedo ``(..., C)`` by quadrature over the interpolant.

        The outgoing hemisphere is parameterised by the half vector h (wo = wi reflected about
        h, d(wo) = 4 (wi . h) d(h), Walter et al. 2007 eq. 14) with theta_h = (pi/2) t^2, the
        square-root spacing of the MERL table, so specular peaks get as many nodes as the
        tables resolve there. Gauss-Legendre in t (``resolution`` nodes) times the trapezoid
        rule in phi_h (``2 resolution`` nodes, exact for periodic integrands).

        Returns
        -------
        albedo : ndarray, shape (..., C)
        error : ndarray, shape (..., C)
            With ``return_error``: the difference from the same rule at half the resolution.
        """
        resolution = integer(resolution, "albedo: resolution", 2, MAX_RESOLUTION)
        wi = direction_array(wi, "wi")
        shape = wi.shape[:-1]
        flat = wi.reshape(-1, 3)
        fine = self._albedo_rule(flat, resolution)
        if not return_error:
            return fine.reshape(shape + (self.channels,))
        coarse = self._albedo_rule(flat, max(resolution // 2, 2))
        return (fine.reshape(shape + (self.channels,)),
                np.abs(fine - coarse).reshape(shape + (self.channels,)))

    def _albedo_rule(self, wi, n):
        h, weight = half_vector_rule(n)
        cos_ih = wi @ h.T                                        # (n_wi, m)
        wo = 2.0 * cos_ih[..., None] * h - wi[:, None, :]        # wi reflected about h
        # only half vectors facing wi reflect it into the upper hemisphere
        ok = (cos_ih > 0.0) & (wo[..., 2] > 0.0)
        rows = np.nonzero(ok)[0]
        f = self.eval(wi[rows], wo[ok])
        # d(wo) = 4 (wi . h) d(h)  (Walter et al. 2007, eq. 14)
        w = np.broadcast_to(weight, ok.shape)[ok] * 4.0 * cos_ih[ok] * wo[ok][:, 2]
        out = np.zeros((len(wi), self.channels))
        np.add.at(out, rows, w[:, None] * f)
        return out

    # -- sampling (cosine-weighted; the renderer may importance-sample a fitted lobe instead) ----
    def sample(self, wi, u):
        """Cosine-weighted ``wo`` for each ``wi``: ``(wo, pdf)`` with pdf = cos(theta_o)/pi."""
        u = uniform_array(u, "u")
        wi = direction_array(wi, "wi")
        shape = broadcast_shape(wi, u, "wi", "u")
        u = np.broadcast_to(u, shape + (2,))
        # a uniform point on the unit disk lifted to the hemisphere has density cos/pi
        # (Malley's method, PBR 4th ed. 13.6.3)
        r, phi = np.sqrt(u[..., 0]), 2.0 * math.pi * u[..., 1]
        wo = np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(np.maximum(0.0, 1.0 - r * r))],
                      axis=-1)
        return wo, self.pdf(np.broadcast_to(wi, shape + (3,)), wo)

    def pdf(self, wi, wo):
        """Solid-angle density of :meth:`sample`: cos(theta_o)/pi above the horizon."""
        wi, wo, shape = flat_pairs(wi, wo)
        return (np.where((wi[:, 2] > 0) & (wo[:, 2] > 0), wo[:, 2] / math.pi, 0.0)
                .reshape(shape))


class AngleTable(Table):
    """A :class:`~brdf.table.Table` whose sample angles were given in degrees.

    ``angles`` returns those degrees exactly as given (e.g. as written in a CSV file, ``phi``
    not normalised), so writing the table back reproduces the file's numbers bit for bit; the
    directions ``wi``, ``wo`` are computed from them (or given, when restored from ``.npz``).

    Parameters
    ----------
    wi, wo, values, **options
        As for :class:`~brdf.table.Table`.
    angles : array_like, shape (N, 4)
        theta_i, phi_i, theta_o, phi_o in degrees, the angles of ``wi`` and ``wo``.
    """

    def __init__(self, wi, wo, values, *, angles, **options):
        super().__init__(wi, wo, values, **options)
        angles = np.array(angles, dtype=np.float64)
        if angles.shape != (len(self.wi), 4) or not np.all(np.isfinite(angles)):
            raise InputError(f"angles must be {len(self.wi)} rows of 4 finite numbers (degrees), "
                             f"got shape {angles.shape}")
        angles.setflags(write=False)
        self._angles = angles

    @classmethod
    def from_degrees(cls, angles, values, **options):
        """Table of samples at ``angles`` (N, 4) in degrees: theta_i, phi_i, theta_o, phi_o."""
        angles = np.asarray(angles, dtype=np.float64)
        wi = directions_from_degrees(angles[:, 0], angles[:, 1])
        wo = directions_from_degrees(angles[:, 2], angles[:, 3])
        return cls(wi, wo, values, angles=angles, **options)

    @property
    def angles(self):
        """Sample angles in degrees as given, (N, 4): theta_i, phi_i, theta_o, phi_o."""
        return self._angles

    def with_values(self, values, sigma=None, **changes):
        """Like :meth:`Table.with_values`, keeping the angles as given."""
        options = dict(wavelengths=self.wavelengths, channel_names=self.channel_names,
                       isotropic=self.isotropic, metadata=self.metadata, name=self.name)
        options.update(changes)
        return AngleTable(self.wi, self.wo, values, angles=self._angles, sigma=sigma, **options)


def half_vector_rule(n):
    """Half-vector quadrature nodes ``(h (m, 3), weights (m,))`` over the upper hemisphere.

    theta_h = (pi/2) t^2 with t on an n-point Gauss-Legendre rule over [0, 1] (so
    d(theta_h) = pi t dt), phi_h on 2n equally spaced nodes; the weights include sin(theta_h)
    and both Jacobians, so ``weights.sum()`` is 2 pi.
    """
    x, w = np.polynomial.legendre.leggauss(n)
    t, wt = 0.5 * (x + 1.0), 0.5 * w
    theta = 0.5 * math.pi * t * t
    phi = (np.arange(2 * n) + 0.5) * (math.pi / n)
    st, ct = np.sin(theta), np.cos(theta)
    h = np.stack([np.outer(st, np.cos(phi)), np.outer(st, np.sin(phi)),
                  np.outer(ct, np.ones_like(phi))], axis=-1).reshape(-1, 3)
    weight = np.outer(wt * math.pi * t * st, np.full(2 * n, math.pi / n)).reshape(-1)
    return h, weight


class ScatteredInterpolant:
    """Linear or nearest interpolation of samples at scattered points, channel by channel.

    Linear: barycentric over a Delaunay triangulation of the samples (qhull, joggled so that
    the co-planar points of gonioreflectometer scans give no flat simplices). Outside the
    convex hull the nearest sample is used and reported as such. Missing (NaN) values are left
    out: channels that share a pattern of missing samples share one triangulation.

    Calling the interpolant on points ``(n, d)`` returns ``(values (n, C), inside (n,))``.
    """

    def __init__(self, points, values, method="linear"):
        from .triangulation import Simplices
        points, values = _merge_duplicates(np.asarray(points, float), np.asarray(values, float))
        valid = np.isfinite(values)
        patterns = {}
        for c in range(values.shape[1]):
            patterns.setdefault(valid[:, c].tobytes(), []).append(c)
        self._groups = []
        for channels in patterns.values():
            keep = valid[:, channels[0]]
            if not keep.any():
                raise InputError(f"channel {channels[0]} has no valid samples to interpolate")
            self._groups.append((channels, Simplices(points[keep], method),
                                 values[keep][:, channels]))
        self._channels = values.shape[1]

    def __call__(self, points):
        out = np.empty((len(points), self._channels))
        inside = np.ones(len(points), dtype=bool)
        for channels, simplices, values in self._groups:
            vertices, weights, found = simplices.locate(points)
            out[:, channels] = np.einsum("nk,nkc->nc", weights, values[vertices])
            inside &= found
        return out, inside


class SlicedInterpolant:
    """Interpolation of an isotropic table measured at a few incidence angles.

    Gonioreflectometers scan the outgoing hemisphere at fixed incident polar angles. Each such
    slice is interpolated over wo's projected disk (a 2-D triangulation, well shaped, unlike a
    3-D one spanning flat slices) and the result is linear in theta_i between the two slices
    around the query; outside the measured theta_i range the nearest slice is used and the
    query reported as outside.

    Calling it on coordinates ``(n, 3)`` (theta_i, disk x, disk y) returns
    ``(values (n, C), inside (n,))``.
    """

    def __init__(self, points, values, method="linear"):
        key = np.round(points[:, 0], 9)
        self.theta = np.unique(key)
        self.slices = [ScatteredInterpolant(points[key == t, 1:], values[key == t], method)
                       for t in self.theta]
        self.channels = values.shape[1]

    def __call__(self, q):
        n = len(q)
        ti = np.clip(q[:, 0], self.theta[0], self.theta[-1])
        upper = np.clip(np.searchsorted(self.theta, ti), 1, len(self.theta) - 1)
        lower = upper - 1
        w = (ti - self.theta[lower]) / (self.theta[upper] - self.theta[lower])
        out = np.zeros((n, self.channels))
        inside = np.abs(ti - q[:, 0]) <= 1e-9
        for s, interpolant in enumerate(self.slices):
            for rows, weight in ((lower == s, 1.0 - w), (upper == s, w)):
                rows = np.nonzero(rows & ((weight > 0.0) | (len(self.theta) == 1)))[0]
                if len(rows):
                    v, ok = interpolant(q[rows, 1:])
                    out[rows] += weight[rows, None] * v
                    inside[rows] &= ok
        return out, inside


def _sliced(theta_i):
    """Whether incident polar angles come in slices: few distinct values, each shared by at
    least 8 samples (enough to triangulate the outgoing disk)."""
    _, counts = np.unique(np.round(theta_i, 9), return_counts=True)
    return 2 <= len(counts) and counts.min() >= 8


def regular_grid(points, values, free_last=None):
    """A multilinear interpolant if ``points`` (n, d) form a full tensor grid, else None.

    ``free_last`` (n,) marks points whose last coordinate does not matter (the azimuth of a
    direction at the pole): such a point fills its whole row along the last axis. The returned
    callable maps query points to ``(values (n, C), inside (n,))``; outside the grid's box the
    query is clamped to the box (the nearest face), reported as not inside. Missing values make
    the grid unusable (None is returned; the triangulation masks them instead).
    """
    from scipy.interpolate import RegularGridInterpolator
    # angles computed from directions carry rounding noise that would split a grid axis
    points = np.round(points, 9)
    free = np.zeros(len(points), bool) if free_last is None else np.asarray(free_last, bool)
    if not np.all(np.isfinite(values)) or free.all():
        return None
    axes = [np.unique(points[:, d]) for d in range(points.shape[1] - 1)]
    axes.append(np.unique(points[~free, -1]))
    if any(len(a) < 2 for a in axes) or math.prod(map(len, axes)) > 4 * len(points) + 64:
        return None
    index = [np.searchsorted(a, points[:, d]) for d, a in enumerate(axes)]
    if not np.array_equal(axes[-1][np.minimum(index[-1], len(axes[-1]) - 1)][~free],
                          points[~free, -1]):
        return None
    sums = np.zeros(tuple(len(a) for a in axes) + (values.shape[1],))
    counts = np.zeros(sums.shape[:-1])
    fixed = tuple(i[~free] for i in index)
    np.add.at(sums, fixed, values[~free])
    np.add.at(counts, fixed, 1.0)
    # a pole sample stands for every azimuth of its row
    row = tuple(i[free] for i in index[:-1])
    np.add.at(sums, row, values[free][:, None, :])
    np.add.at(counts, row, 1.0)
    if (counts == 0).any():
        return None
    grid = sums / counts[..., None]
    rgi = RegularGridInterpolator(axes, grid, method="linear")
    low = np.array([a[0] for a in axes])
    high = np.array([a[-1] for a in axes])

    def interpolate(q):
        clamped = np.clip(q, low, high)
        inside = np.all(np.abs(clamped - q) <= 1e-9, axis=1)
        return rgi(clamped), inside
    return interpolate


def _merge_duplicates(points, values):
    """Average samples taken at the same interpolation coordinates (e.g. an isotropic table
    measured at several incident azimuths), ignoring missing values."""
    key = np.round(points, 9)
    unique, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    if len(unique) == len(points):
        return points, values
    inverse = inverse.reshape(-1)
    sums = np.zeros((len(unique), values.shape[1]))
    n = np.zeros_like(sums)
    valid = np.isfinite(values)
    np.add.at(sums, inverse, np.where(valid, values, 0.0))
    np.add.at(n, inverse, valid)
    with np.errstate(invalid="ignore", divide="ignore"):
        merged = np.where(n > 0, sums / n, np.nan)
    return unique, merged


def _polar(w):
    """Polar angle and azimuth (radians) of unit vectors (n, 3)."""
    return np.arctan2(np.hypot(w[:, 0], w[:, 1]), w[:, 2]), np.arctan2(w[:, 1], w[:, 0])


def _sample_directions(x, name):
    arr = direction_array(x, name)  # unit vectors (within geometry.UNIT_TOL), finite
    if arr.ndim != 2:
        raise InputError(f"{name} must be shaped (N, 3), got shape {arr.shape}")
    if len(arr) and arr[:, 2].min() < -HORIZON_SLACK:
        k = int(np.argmin(arr[:, 2]))
        raise InputError(f"{name}[{k}] = {arr[k].tolist()} is below the horizon (z < 0)")
    return arr


def sample_values(x, name, n):
    """``x`` as float64 ``(n, C)`` values of ``n`` samples (a 1-D array is one channel): NaN
    marks a missing sample, infinities are refused (InputError naming ``name``)."""
    arr = real_array(x, name)
    if arr.ndim == 1:
        arr = arr[:, None]
    if arr.ndim != 2 or arr.shape[0] != n:
        raise InputError(f"{name} must be shaped (N, C) with N = {n} samples, got shape "
                         f"{arr.shape}")
    if np.isinf(arr).any():
        k, c = np.argwhere(np.isinf(arr))[0]
        raise InputError(f"{name}[{k}, {c}] is infinite; missing samples are NaN")
    return arr
