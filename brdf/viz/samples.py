"""What the pictures draw from a subject: channel reduction, incidence directions, and the
measured samples of a table that lie near a chosen incidence (or in its plane)."""

import math

import numpy as np

from ..errors import InputError
from ..geometry import spherical_to_cartesian

__all__ = ["label", "channel_count", "in_plane_directions", "channel_values", "channel_label", "incidence", "samples_near", "in_plane",
           "is_table", "thin", "MAX_POINTS", "TOLERANCE_DEG"]

#: Largest number of measured samples drawn in one view (a MERL table has 1.46 million): more
#: hide the lobe or the curves under them without telling more.
MAX_POINTS = 600
#: Samples whose incidence lies within this many degrees of the asked one count as taken there.
TOLERANCE_DEG = 2.5
#: Tighter tolerances tried first, so dense tables (MERL) show samples taken at the incidence
#: itself rather than a band around it, where a sharp lobe has moved.
TIGHTER_DEG = (0.25, 1.0)
#: Enough samples to draw a lobe or a curve with.
ENOUGH = 30


def is_table(subject):
    """True for a measured table (it holds samples), False for a model."""
    return hasattr(subject, "values") and hasattr(subject, "wi")


def label(subject, digits=4):
    """A short name for titles: a table's name, or a model's spec with its numbers rounded to
    ``digits`` significant digits (a fit's spec carries all 17)."""
    from ..formatting import round_numbers
    if is_table(subject):
        return str(subject)
    return round_numbers(subject, digits)


def channel_count(subject):
    channels = subject.channels
    return int(channels() if callable(channels) else channels)


def channel_values(values, channel=None):
    """``values (..., C)`` reduced to ``(...)``: channel ``channel``, or the mean over channels
    (an unweighted grey: spectral and RGB tables alike) when ``None``."""
    values = np.asarray(values, dtype=float)
    if channel is None:
        return values.mean(axis=-1)
    if not -values.shape[-1] <= channel < values.shape[-1]:
        raise InputError(f"channel {channel} does not exist; the subject has "
                         f"{values.shape[-1]} channels (0 to {values.shape[-1] - 1})")
    return values[..., channel]


def channel_label(subject, channel=None):
    """How the channel choice reads in a legend: ``mean of 3 channels`` or ``channel g``."""
    count = channel_count(subject)
    if channel is None:
        return "" if count == 1 else f"mean of {count} channels"
    names = getattr(subject, "channel_names", None)
    name = names[channel] if names is not None and -count <= channel < count else channel
    return f"channel {name}"


def incidence(theta_i_deg, phi_i_deg=0.0):
    """Unit incident direction (towards the light) from angles in degrees; theta in [0, 90)."""
    theta = float(theta_i_deg)
    if not (math.isfinite(theta) and 0.0 <= theta < 90.0):
        raise InputError(f"theta_i {theta:g} must be in [0, 90) degrees (at 90 the "
                         "light grazes the surface and the lobe is empty)")
    if not math.isfinite(float(phi_i_deg)):
        raise InputError(f"phi_i {phi_i_deg!r} must be a finite number of degrees")
    return spherical_to_cartesian(math.radians(theta), math.radians(float(phi_i_deg)))


def thin(n, max_points):
    """Evenly spread indices of at most ``max_points`` out of ``n`` (deterministic); all of
    them when ``max_points`` is None."""
    if max_points is None or n <= max_points:
        return np.arange(n)
    return np.unique(np.linspace(0, n - 1, max_points).round().astype(int))


def samples_near(table, wi, tol_deg=None, max_points=MAX_POINTS, plane=False):
    """The table's measured samples taken within ``tol_deg`` of the incidence ``wi``, at most
    ``max_points`` of them (evenly spread; None: all).

    An isotropic table's samples at the same polar angle but another azimuth are rotated about
    the normal onto ``wi``'s azimuth (only the difference of azimuths matters for them).
    By default the tolerance is the smallest of :data:`TIGHTER_DEG` and :data:`TOLERANCE_DEG`
    that finds :data:`ENOUGH` samples; ``plane`` keeps only those within it of the plane of
    incidence too.

    Returns
    -------
    wo : ndarray, shape (n, 3)
        Outgoing directions, in ``wi``'s frame of azimuth for isotropic tables.
    values : ndarray, shape (n, C)
        The measured BRDF in 1/sr (rows with any missing channel are left out).
    """
    swi, swo = np.asarray(table.wi, float), np.asarray(table.wo, float)
    values = np.asarray(table.values, float)
    if table.isotropic:
        distance = np.abs(np.arccos(np.clip(swi[:, 2], -1, 1)) - math.acos(min(wi[2], 1.0)))
    else:
        distance = np.arccos(np.clip(swi @ wi, -1, 1))
    usable = np.isfinite(values).all(axis=1) & (swo[:, 2] > 0.0)
    for tol in ([tol_deg] if tol_deg is not None else [*TIGHTER_DEG, TOLERANCE_DEG]):
        rows = np.nonzero(usable & (distance <= math.radians(tol)))[0]
        wo = _turned(table, swi[rows], swo[rows], wi)
        if plane:
            keep = in_plane(wi, wo, tol)[0]
            rows, wo = rows[keep], wo[keep]
        if len(rows) >= ENOUGH:
            break
    pick = thin(len(rows), max_points)
    return wo[pick], values[rows[pick]]


def _turned(table, swi, wo, wi):
    """``wo`` turned about the normal by the azimuth from ``swi`` to ``wi`` (isotropic)."""
    if not table.isotropic:
        return wo
    turn = math.atan2(wi[1], wi[0]) - np.arctan2(swi[:, 1], swi[:, 0])
    # the azimuth is undefined at normal incidence: nothing to turn
    turn = np.where(np.hypot(swi[:, 0], swi[:, 1]) < 1e-9, 0.0, turn)
    c, s = np.cos(turn), np.sin(turn)
    return np.stack([c * wo[:, 0] - s * wo[:, 1], s * wo[:, 0] + c * wo[:, 1], wo[:, 2]],
                    axis=-1)


def in_plane(wi, wo, tol_deg=TOLERANCE_DEG):
    """Which ``wo (n, 3)`` lie within ``tol_deg`` of the plane of incidence of ``wi``, and their
    signed polar angle in degrees: negative on the incident side, positive on the specular side
    (the convention of :meth:`brdf.fitting.mcmc.Posterior.predictive`)."""
    u = np.array([wi[0], wi[1], 0.0])
    norm = np.hypot(u[0], u[1])
    u = u / norm if norm > 1e-9 else np.array([1.0, 0.0, 0.0])
    v = np.array([-u[1], u[0], 0.0])
    keep = np.abs(wo @ v) <= math.sin(math.radians(tol_deg))
    signed = np.degrees(np.arctan2(-(wo @ u), wo[:, 2]))
    return keep, signed


def in_plane_directions(wi, signed_deg):
    """Outgoing directions in the plane of incidence of ``wi`` at signed polar angles (degrees,
    negative on the incident side), the inverse of :func:`in_plane`."""
    phi_i = math.atan2(wi[1], wi[0]) if np.hypot(wi[0], wi[1]) > 1e-9 else 0.0
    signed = np.radians(np.asarray(signed_deg, float))
    return spherical_to_cartesian(np.abs(signed), np.where(signed < 0, phi_i, phi_i + math.pi))
