"""Virtual gonioreflectometer: sample any BRDF at a measurement geometry with a stated noise model.

Geometries (:func:`geometry_directions`):

``merl``
    the 90 x 90 x 180 MERL half/difference grid (1,458,000 samples; returns a MERL table);
``inplane:STEP``
    incidence and exitance in the plane of incidence, polar angles 0, STEP, ... below 90
    degrees, exitance on both sides of the normal;
``grid:DTHETA,DPHI``
    polar angles every DTHETA and azimuths every DPHI degrees for both directions (the incident
    azimuth is fixed at 0 for isotropic models, where it adds nothing);
``random:N`` or ``random:N:cosine``
    N pairs with both directions uniform in solid angle, or cosine-weighted;
a CSV file of angles
    columns ``theta_i,phi_i,theta_o,phi_o`` in degrees (a gonioreflectometer's own schedule).

Noise models (:func:`parse_noise`): ``none``; ``relative:S`` (sigma = S f); ``additive:S``
(sigma = S, in 1/sr); ``poisson:S`` (photon-counting-like: sigma = S sqrt(f), S in
sqrt(1/sr)). Noisy values are ``f + sigma z`` with z standard normal from ``seed``, so the same
seed gives the same bytes; the stated sigma is stored with the samples, and noise may make
small values negative as real measurements do.
"""

import math
import os
from pathlib import Path

import numpy as np

from . import arguments
from .arguments import shown
from .errors import FormatError, InputError
from .geometry import directions_from_degrees

__all__ = ["measure", "geometry_directions", "geometry_angles", "parse_noise", "NOISE_MODELS"]

NOISE_MODELS = ("none", "relative", "additive", "poisson")
ANGLE_COLUMNS = ("theta_i", "phi_i", "theta_o", "phi_o")


def measure(model, geometry="inplane:5", noise="none", seed=0, *, name=None):
    """Measure ``model`` like a gonioreflectometer would.

    Parameters
    ----------
    model : Model, str or Table
        What to measure: a parametric model, a spec, or a measured table (resampling it).
    geometry : str
        ``merl``, ``inplane:STEP``, ``grid:DTHETA,DPHI``, ``random:N[:cosine]`` or the path of
        a CSV file of angles (see the module docstring).
    noise : str
        ``none``, ``relative:S``, ``additive:S`` or ``poisson:S``.
    seed : int or numpy.random.Generator
        Seeds the random geometry and the noise.

    Returns
    -------
    brdf.table.Table
        The samples, with ``sigma`` from the noise model (None without noise) and metadata
        recording the model, geometry, noise and seed.
    """
    from .spec import parse
    from .table import AngleTable
    if isinstance(model, str):
        model = parse(model)
    if not (callable(getattr(model, "eval", None)) and hasattr(model, "channels")):
        raise InputError(f"measure: model must be a model, a spec or a measured table, got "
                         f"{type(model).__name__}")
    if not isinstance(geometry, (str, os.PathLike)):
        raise InputError(f"measure: geometry must be a string or a path, got {shown(geometry)}")
    if not isinstance(noise, str):
        raise InputError(f"measure: noise must be a string, got {shown(noise)}")
    if not (name is None or isinstance(name, str)):
        raise InputError(f"measure: name must be a string, got {shown(name)}")
    kind, scale = parse_noise(noise)
    rng = arguments.rng(seed, "measure: seed")
    isotropic = not getattr(model, "is_anisotropic", True)
    channels = int(getattr(model, "channels", 3) or 3)
    merl = str(geometry).strip().lower() == "merl"
    if merl:
        from .io.merl import SIZE, check_rgb
        check_rgb(model)  # the grid's table stores r, g, b: never wavelengths under those names
        _require_samples(geometry, SIZE, channels)
        wi, wo = geometry_directions(geometry)
    else:
        angles = geometry_angles(geometry, rng, isotropic, channels)
        wi = directions_from_degrees(angles[:, 0], angles[:, 1])
        wo = directions_from_degrees(angles[:, 2], angles[:, 3])
    values = np.asarray(model.eval(wi, wo), dtype=float)
    values, sigma = add_noise(values, kind, scale, rng)
    metadata = {"generator": "brdf.measure", "model": str(model), "geometry": str(geometry),
                "noise": noise, "seed": None if isinstance(seed, np.random.Generator) else int(seed),
                "units": "1/sr"}
    name = name or f"measured {model}"
    if merl:
        from .io.merl import MerlTable
        return MerlTable.from_grid_values(values, sigma=sigma, metadata=metadata, name=name)
    # the geometry's degrees are kept as given, so a CSV of the table shows 15, not 14.99...
    return AngleTable(wi, wo, values, angles=angles, sigma=sigma, isotropic=isotropic,
                      metadata=metadata, name=name,
                      wavelengths=getattr(model, "wavelengths", None),
                      channel_names=getattr(model, "channel_names", None))


def parse_noise(text):
    """``(kind, scale)`` from ``none``, ``relative:S``, ``additive:S`` or ``poisson:S``."""
    kind, _, arg = str(text).strip().lower().partition(":")
    if kind not in NOISE_MODELS:
        raise InputError(f"noise {text!r}: unknown model; expected one of "
                         f"none, relative:S, additive:S, poisson:S")
    if kind == "none":
        if arg:
            raise InputError(f"noise {text!r}: 'none' takes no value")
        return kind, 0.0
    try:
        scale = float(arg)
    except ValueError:
        raise InputError(f"noise {text!r}: expected {kind}:S with a number S >= 0") from None
    if not (math.isfinite(scale) and scale >= 0.0):
        raise InputError(f"noise {text!r}: S must be a finite number >= 0")
    return kind, scale


def add_noise(values, kind, scale, rng):
    """``(noisy values, sigma or None)`` for a parsed noise model."""
    if kind == "none":
        return values, None
    magnitude = np.abs(values)
    with np.errstate(over="ignore", invalid="ignore"):
        sigma = {"relative": lambda: scale * magnitude,
                 "additive": lambda: np.full_like(values, scale),
                 "poisson": lambda: scale * np.sqrt(magnitude)}[kind]()
        noisy = values + sigma * rng.standard_normal(values.shape)
    if not (np.isfinite(noisy).all() and np.isfinite(sigma).all()):
        raise InputError(f"noise {kind}:{scale:g}: the noisy values overflow float64; "
                         "expected a smaller S")
    return noisy, sigma


def geometry_directions(geometry, rng=None, isotropic=True):
    """``(wi, wo)`` unit directions ``(N, 3)`` of a measurement geometry (see :func:`measure`)."""
    if str(geometry).strip().lower() == "merl":
        from .io.merl import grid_directions
        return grid_directions()
    angles = geometry_angles(geometry, rng, isotropic)
    return (directions_from_degrees(angles[:, 0], angles[:, 1]),
            directions_from_degrees(angles[:, 2], angles[:, 3]))


#: Peak bytes per sample of :func:`measure`, besides 4 float64 per channel: the geometry's
#: random numbers, angles and directions, the model's temporaries and the table's copies
#: (measured: random:1000000 of a 3-channel lambert + ggx peaks at about 0.4 kB per sample).
SAMPLE_BYTES = 8 * 48


def _require_samples(geometry, n, channels):
    """Refuse (before allocating) a geometry of ``n`` samples that memory cannot hold."""
    from .memory import require
    require(n * (SAMPLE_BYTES + 32 * channels), f"geometry {geometry!r} ({n:,} samples)")


def geometry_angles(geometry, rng=None, isotropic=True, channels=3):
    """Angles ``(N, 4)`` in degrees (theta_i, phi_i, theta_o, phi_o) of a measurement geometry
    other than ``merl`` (whose nodes are defined in half/difference angles). A geometry whose
    samples (of ``channels`` values each) would not fit in memory is refused before any is
    made."""
    text = str(geometry).strip()
    kind, _, arg = text.partition(":")
    kind = kind.lower()
    if kind == "inplane":
        (step,) = _numbers(text, arg, 1, "inplane:STEP")
        n = len(_polar_steps(step, text, channels))
        _require_samples(text, n * (2 * n - 1), channels)
        return _inplane(step)
    if kind == "grid":
        dtheta, dphi = _numbers(text, arg, 2, "grid:DTHETA,DPHI")
        n_theta = len(_polar_steps(dtheta, text, channels))
        n_phi = math.ceil((360.0 - 1e-9) / dphi)
        n_out = 1 + (n_theta - 1) * n_phi
        _require_samples(text, (n_theta if isotropic else n_out) * n_out, channels)
        return _grid(dtheta, dphi, isotropic=isotropic)
    if kind == "random":
        count, _, weighting = arg.partition(":")
        try:
            n = int(count) if count.strip().isascii() and "_" not in count else 0
        except ValueError:
            n = 0
        if n > 0:
            _require_samples(text, n, channels)
        return _random(text, count, weighting or "uniform",
                       rng if rng is not None else np.random.default_rng(0))
    if Path(text).suffix.lower() == ".csv" or Path(text).is_file():
        return _angles_file(text)
    raise InputError(f"geometry {text!r}: expected merl, inplane:STEP, grid:DTHETA,DPHI, "
                     "random:N[:cosine] or a CSV file of angles")


def _numbers(text, arg, count, form):
    parts = [p for p in arg.split(",")] if arg else []
    try:
        values = [float(p) if p.strip().isascii() and "_" not in p else math.nan
                  for p in parts]
    except ValueError:
        values = []
    if len(values) != count or not all(math.isfinite(v) and 0.0 < v <= 90.0 for v in values):
        raise InputError(f"geometry {text!r}: expected {form} with step(s) in (0, 90] degrees")
    return values


def _polar_steps(step, geometry=None, channels=3):
    """0, step, 2 step, ... strictly below 90 degrees (at 90 a direction lies in the horizon);
    with ``geometry``, refused first if memory cannot hold the steps themselves."""
    if geometry is not None:
        _require_samples(geometry, math.ceil((90.0 - 1e-9) / step), channels)
    return np.arange(0.0, 90.0 - 1e-9, step)


def _inplane(step):
    theta = _polar_steps(step)
    # exitance at signed angles in the plane of incidence: phi_o = 0 (retro side) and 180
    signed = np.concatenate([-theta[:0:-1], theta])
    ti, to = np.meshgrid(theta, signed, indexing="ij")
    ti, to = ti.ravel(), to.ravel()
    return np.stack([ti, np.zeros_like(ti), np.abs(to), np.where(to < 0.0, 180.0, 0.0)], -1)


def _hemisphere_angles(dtheta, dphi):
    """(theta, phi) in degrees covering the hemisphere once: the pole appears a single time."""
    theta = _polar_steps(dtheta)[1:]
    phi = np.arange(0.0, 360.0 - 1e-9, dphi)
    t, p = np.meshgrid(theta, phi, indexing="ij")
    return np.concatenate([[0.0], t.ravel()]), np.concatenate([[0.0], p.ravel()])


def _grid(dtheta, dphi, isotropic):
    to, po = _hemisphere_angles(dtheta, dphi)
    if isotropic:
        ti, pi_ = _polar_steps(dtheta), np.zeros(1)
        ti, pi_ = np.meshgrid(ti, pi_, indexing="ij")
        ti, pi_ = ti.ravel(), pi_.ravel()
    else:
        ti, pi_ = _hemisphere_angles(dtheta, dphi)
    i = np.repeat(np.arange(len(ti)), len(to))
    o = np.tile(np.arange(len(to)), len(ti))
    return np.stack([ti[i], pi_[i], to[o], po[o]], axis=-1)


def _random(text, count, weighting, rng):
    try:
        n = int(count) if count.strip().isascii() and "_" not in count else 0
    except ValueError:
        n = 0
    if n <= 0 or weighting not in ("uniform", "cosine"):
        raise InputError(f"geometry {text!r}: expected random:N or random:N:cosine with N >= 1")
    u = rng.random((n, 4))
    # uniform in solid angle: cos(theta) uniform; cosine-weighted: cos^2(theta) uniform
    # (PBR 4th ed. 13.6.1 and 13.6.3)
    cos_theta = 1.0 - u[:, 0::2] if weighting == "uniform" else np.sqrt(1.0 - u[:, 0::2])
    theta = np.degrees(np.arccos(cos_theta))
    return np.stack([theta[:, 0], 360.0 * u[:, 1], theta[:, 1], 360.0 * u[:, 3]], axis=-1)


def _angles_file(path):
    """Directions from a CSV with the columns theta_i, phi_i, theta_o, phi_o (degrees)."""
    from .io import read_bytes
    from .io._text import parse_float
    data = read_bytes(path, what="a CSV file of angles")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as e:
        line = data[:e.start].count(b"\n") + 1
        raise FormatError(path, f"line {line}", f"byte {e.start} is not UTF-8") from None
    rows = [(k + 1, line) for k, line in enumerate(text.splitlines())
            if line.strip() and not line.lstrip().startswith("#")]
    if not rows:
        raise FormatError(path, "", f"empty; expected a header {','.join(ANGLE_COLUMNS)}")
    header_line, header = rows[0]
    names = [h.strip() for h in header.split(",")]
    missing = [c for c in ANGLE_COLUMNS if c not in names]
    if missing:
        raise FormatError(path, f"line {header_line}",
                          f"missing column(s) {', '.join(missing)}; expected "
                          f"{','.join(ANGLE_COLUMNS)} (degrees)")
    columns = [names.index(c) for c in ANGLE_COLUMNS]
    angles = np.empty((len(rows) - 1, 4))
    for k, (line_no, line) in enumerate(rows[1:]):
        fields = line.split(",")
        if len(fields) != len(names):
            raise FormatError(path, f"line {line_no}",
                              f"{len(fields)} fields; expected {len(names)} like the header")
        try:
            angles[k] = [parse_float(fields[c].strip()) for c in columns]
        except ValueError:
            raise FormatError(path, f"line {line_no}", "expected numbers (degrees)") from None
        if not np.all(np.isfinite(angles[k])) or not (0.0 <= angles[k, 0] <= 90.0
                                                      and 0.0 <= angles[k, 2] <= 90.0):
            raise FormatError(path, f"line {line_no}",
                              "expected finite angles with 0 <= theta <= 90 degrees")
    if not len(angles):
        raise FormatError(path, "", "no rows after the header")
    return angles
