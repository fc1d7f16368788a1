"""The adaptive parameterisation of an isotropic BRDF (Dupuy & Jakob 2018), built from its eval.

What :func:`brdf.io.rgl_bsdf.write` stores, computed from any isotropic source that evaluates
f_r at arbitrary direction pairs (a model or a table):

1. **The NDF D(h)**, extracted from the backscattering values f_r(k, k) by power iteration
   (Dupuy, Heitz, Iehl, Poulin & Ostromoukhov 2015, "Extracting Microfacet-based BRDF
   Parameters from Arbitrary Materials with Power Iterations", Sec. 3-4). For a microfacet BRDF
   with Smith masking the retro-reflection is f_r(k, k) = F D(k) / (4 cos(theta_k) sigma(k)),
   since masking and shadowing coincide there and G1(k) = cos(theta_k) / sigma(k); with
   sigma(k) = int <k, h> D(h) dh (the projected area of the microsurface) this makes D the
   eigenvector of the positive operator (K D)(k) = 4 cos(theta_k) f_r(k, k) int <k, h> D(h) dh
   for its largest eigenvalue (F, assumed constant, is that eigenvalue's inverse), found by
   repeated application of K. For a pure Smith microfacet lobe the result is its own NDF; for
   anything else it is the NDF of the microfacet BRDF closest to it, which is all the
   parameterisation needs (it decides where the samples go, and the samples store the rest).
   D is normalised so that int D(h) cos(theta_h) dh = 1, so sigma(normal) = 1, as in the RGL
   files.
2. **sigma(theta_i)**, the projected area, on the same nodes.
3. **The incident angles theta_i**: equally spaced in sigma from sigma(0) = 1 to
   sigma(pi/2), which reproduces the angles of three of the four RGL files of
   ``measurements/rgl`` to float32 rounding (the fourth, vch_golden_yellow, spaces its first
   seven angles from 0 to 85 degrees that way and adds 90 degrees).
4. **The visible NDF** per incident angle, on the unit square (u, v) = (sqrt(theta_h / (pi/2)),
   (phi_h - phi_i + pi) / (2 pi)): D_wi(h) = <wi, h> D(h) / sigma(wi) times the Jacobian
   2 pi^2 u sin(theta_h) of (u, v) -> h, normalised to sum 1 per slice (what the RGL files
   hold, to float32 rounding).
5. **The samples**: at node s of an n x n grid the forward warp by the (float32) VNDF gives h,
   wo = wi mirrored about h, and the stored value is f_r(wi, wo) cos(theta_o) divided by the
   density D(h) / (4 sigma(wi)) of wo (module notes of :mod:`brdf.io.rgl_bsdf`), with D and
   sigma the stored float32 tables interpolated exactly as readers interpolate them, so that a
   reader gives back f_r cos(theta_o) at every node up to float32 rounding. A node whose wo
   falls below the horizon (never looked up by itself) stores the value of the nearest node
   above it, so that the cells beside the horizon interpolate the quotient instead of pulling
   it to 0.
"""

import math

import numpy as np

from ..errors import InputError
from ..geometry import reflect, spherical_to_cartesian

__all__ = ["Parameterization", "build", "backscatter_ndf", "projected_area",
           "incident_angles_for", "visible_ndf", "resolution", "RESOLUTION_LIMITS",
           "THETA_MAX"]

_HALF_PI = 0.5 * math.pi
#: The largest float32 not above pi/2: the last incident angle (three RGL files store it).
THETA_MAX = float(np.nextafter(np.float32(_HALF_PI), np.float32(0.0)))
#: Power iteration stops when the normalised iterate changes by less than this (max norm).
POWER_TOLERANCE = 1e-12
POWER_ITERATIONS = 10000
#: NDF values are kept at or above this fraction of the peak: the samples are divided by D.
NDF_FLOOR = 1e-7
#: Allowed ranges of the resolution options (at least 2 nodes; at most what stays small).
RESOLUTION_LIMITS = {"incident_angles": (2, 90), "samples": (2, 256),
                     "vndf_resolution": (2, 1024), "ndf_resolution": (3, 4096)}


class Parameterization:
    """The fields of an isotropic adaptive parameterisation (float32 arrays as stored).

    Attributes
    ----------
    theta_i : ndarray (T,)
    ndf, sigma : ndarray (2, N)
        Rows: the azimuth coordinate v (two equal rows: isotropic), columns: u.
    vndf : ndarray (1, T, H, W)
    samples : ndarray (1, T, C, n, n)
        f_r cos(theta_o) / (D(h) / (4 sigma(wi))) per channel.
    above : ndarray (T, n, n) bool
        Whether each node's wo lies above the horizon.
    """

    def __init__(self, theta_i, ndf, sigma, vndf, samples, above):
        self.theta_i, self.ndf, self.sigma = theta_i, ndf, sigma
        self.vndf, self.samples, self.above = vndf, samples, above


def resolution(name, value):
    """``value`` as an int after checking it against :data:`RESOLUTION_LIMITS` ``[name]``."""
    lo, hi = RESOLUTION_LIMITS[name]
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or \
            not lo <= value <= hi:
        raise InputError(f"{name} must be an integer in [{lo}, {hi}], got {value!r}")
    return int(value)


def build(evaluate, channels, *, incident_angles=8, samples=32, vndf_resolution=128,
          ndf_resolution=128, horizon=0.0):
    """The parameterisation of the isotropic BRDF ``evaluate(wi, wo) -> (n, channels)``.

    Parameters
    ----------
    evaluate : callable
        f_r in 1/sr (no cosine) of direction pairs ``(n, 3)``, ``(n, channels)``.
    channels : int
    incident_angles, samples, vndf_resolution, ndf_resolution : int
        T incident angles, n x n samples per angle, the VNDF's H = W and the NDF's nodes; the
        defaults are those of the RGL files.
    horizon : float
        A node's wo counts as above the horizon when its z exceeds this.

    Raises
    ------
    brdf.errors.InputError
        Bad resolutions; a BRDF with non-finite values or no backscattering at all.
    """
    t = resolution("incident_angles", incident_angles)
    n = resolution("samples", samples)
    h = resolution("vndf_resolution", vndf_resolution)
    m = resolution("ndf_resolution", ndf_resolution)
    u = np.linspace(0.0, 1.0, m)
    d = backscatter_ndf(evaluate, u)
    sigma = projected_area(d, u)
    ndf32 = np.repeat(d[None, :].astype(np.float32), 2, axis=0)
    sigma32 = np.repeat(sigma[None, :].astype(np.float32), 2, axis=0)
    # what readers see: the float32 tables, interpolated linearly in u
    d_stored, sigma_stored = ndf32[0].astype(np.float64), sigma32[0].astype(np.float64)
    theta = incident_angles_for(sigma_stored, u, t)
    theta32 = theta.astype(np.float32)
    theta = theta32.astype(np.float64)
    vndf32 = np.stack([visible_ndf(th, d_stored, u, h) for th in theta]).astype(np.float32)
    stored, above = _samples(evaluate, channels, theta, vndf32, d_stored, sigma_stored, u, n,
                             horizon)
    return Parameterization(theta32, ndf32, sigma32, vndf32[None], stored[None], above)


def backscatter_ndf(evaluate, u):
    """NDF D at theta_h = u^2 pi/2 (``u`` equally spaced over [0, 1]) from the backscattering
    luminance of ``evaluate`` by power iteration (module notes, step 1), normalised to
    int D cos(theta_h) dh = 1 by the quadrature of :func:`projected_area`."""
    theta = u * u * _HALF_PI
    # f_r(k, k) below grazing; the node at 90 degrees copies its neighbour's D below
    k = spherical_to_cartesian(theta[:-1], 0.0)
    f = np.asarray(evaluate(k, k), dtype=np.float64)
    if not np.isfinite(f).all():
        raise InputError("the BRDF is not finite at retro-reflection (wi = wo); expected "
                         "finite values to extract its NDF from")
    retro = _grey(f)
    if not np.any(retro > 0.0):
        raise InputError("the BRDF is 0 at retro-reflection (wi = wo) for every angle; the "
                         "adaptive parameterisation extracts its NDF from there")
    area = _area_operator(u)[:-1]
    kernel = 4.0 * np.cos(theta[:-1])[:, None] * np.maximum(retro, 0.0)[:, None] * area
    d = np.ones(len(u))
    for _ in range(POWER_ITERATIONS):
        # Dupuy et al. 2015: D <- K D, the power iteration for the dominant eigenvector
        nxt = np.empty_like(d)
        nxt[:-1] = kernel @ d
        nxt[-1] = nxt[-2]
        nxt /= nxt.max()
        done = np.max(np.abs(nxt - d)) < POWER_TOLERANCE
        d = nxt
        if done:
            break
    d = np.maximum(d, NDF_FLOOR * d.max())
    return d / projected_area(d, u)[0]  # sigma(normal) = int D cos = 1


def _grey(values):
    """One value per pair: the Rec. 709 luminance of 3 channels, else the channel mean."""
    if values.shape[-1] == 3:
        return values @ np.array([0.2126, 0.7152, 0.0722])
    return values.mean(axis=-1)


def _area_operator(u):
    """Matrix A with (A D)_i = int <k_i, h> D(h) dh for an isotropic D at the nodes ``u``
    (trapezoid rule in u, dtheta = pi u du, and the azimuthal integral in closed form)."""
    theta = u * u * _HALF_PI
    w = np.full(len(u), u[1] - u[0])
    w[[0, -1]] *= 0.5
    weight = w * math.pi * u * np.sin(theta)  # dh = sin(theta) dtheta dphi, dtheta = pi u du
    return _azimuthal(theta[:, None], theta[None, :]) * weight[None, :]


def _azimuthal(theta_k, theta_h):
    """int_0^{2 pi} max(0, cos(theta_k) cos(theta_h) + sin(theta_k) sin(theta_h) cos(phi)) dphi:
    2 pi a when a >= b, else 2 (a phi0 + sqrt(b^2 - a^2)) with phi0 = arccos(-a / b), where
    a = cos cos and b = sin sin (the clipped cosine integrated over the azimuth)."""
    a = np.cos(theta_k) * np.cos(theta_h)
    b = np.sin(theta_k) * np.sin(theta_h)
    a, b = np.broadcast_arrays(a, b)
    out = 2.0 * math.pi * a
    cut = b > a
    ratio = np.clip(-a[cut] / b[cut], -1.0, 1.0)
    out[cut] = 2.0 * (a[cut] * np.arccos(ratio) + np.sqrt(b[cut] ** 2 - a[cut] ** 2))
    return out


def projected_area(d, u):
    """sigma(theta_k) = int <k, h> D(h) dh at theta_k = u^2 pi/2 for the NDF ``d`` on ``u``."""
    return _area_operator(u) @ d


def incident_angles_for(sigma, u, count):
    """``count`` incident angles equally spaced in sigma from 1 (normal) to sigma(pi/2), the
    last at the largest float32 below pi/2 (module notes, step 3); equally spaced in u where
    sigma is not strictly decreasing enough to tell angles apart."""
    theta = u * u * _HALF_PI
    # sigma decreases with theta for any NDF; the running minimum guards against rounding
    s = np.minimum.accumulate(sigma)
    targets = np.linspace(s[0], s[-1], count)
    # np.interp needs increasing abscissae: interpolate u over -sigma
    with np.errstate(invalid="ignore"):
        nodes = np.interp(-targets, -s, u) if s[0] > s[-1] else np.linspace(0.0, 1.0, count)
    out = nodes * nodes * _HALF_PI
    out[0], out[-1] = 0.0, THETA_MAX
    if np.any(np.diff(out.astype(np.float32)) <= 0.0):
        out = np.linspace(0.0, 1.0, count) ** 2 * _HALF_PI
        out[-1] = THETA_MAX
    return out


def visible_ndf(theta_i, d, u, resolution):
    """VNDF of incidence ``theta_i`` (azimuth 0) on a ``resolution`` squared grid of the unit
    square (rows v, columns u), normalised to sum 1: <wi, h> D(h) 2 pi^2 u sin(theta_h) (module
    notes, step 4; sigma(wi) drops out in the normalisation)."""
    g = np.linspace(0.0, 1.0, resolution)
    uu, vv = np.meshgrid(g, g)  # rows v, columns u
    theta_h = uu * uu * _HALF_PI
    h = spherical_to_cartesian(theta_h, (2.0 * vv - 1.0) * math.pi)
    wi = spherical_to_cartesian(theta_i, 0.0)
    density = np.maximum(h @ wi, 0.0) * np.interp(uu, u, d) * uu * np.sin(theta_h)
    return density / density.sum()


def _samples(evaluate, channels, theta, vndf32, d, sigma, u, n, horizon):
    """Stored samples ``(T, C, n, n)`` and ``above`` ``(T, n, n)`` (module notes, step 5)."""
    from .rgl_bsdf import warp_forward, warp_tables
    pdf, cond, marg = warp_tables(vndf32)
    g = np.linspace(0.0, 1.0, n)
    sy, sx = (a.reshape(-1) for a in np.meshgrid(g, g, indexing="ij"))
    wi_all, wo_all, scale_all = [], [], []
    for k, th in enumerate(theta):
        ux, uy = warp_forward(pdf[k], cond[k], marg[k], sx, sy)
        h = spherical_to_cartesian(ux * ux * _HALF_PI, (2.0 * uy - 1.0) * math.pi)
        wi = spherical_to_cartesian(np.full(n * n, th), 0.0)
        wo = reflect(wi, h)
        wo /= np.linalg.norm(wo, axis=-1, keepdims=True)
        # 1 / density of wo = 4 sigma(wi) / D(h), the tables interpolated linearly in u
        scale = 4.0 * np.interp(math.sqrt(th / _HALF_PI), u, sigma) / np.interp(ux, u, d)
        wi_all.append(wi)
        wo_all.append(wo)
        scale_all.append(scale * wo[:, 2])
    wi, wo, scale = (np.concatenate(a) for a in (wi_all, wo_all, scale_all))
    above = wo[:, 2] > horizon
    values = np.zeros((len(wi), channels))
    if above.any():
        values[above] = np.asarray(evaluate(wi[above], wo[above]), dtype=np.float64)
    if not np.isfinite(values).all():
        bad = int(np.flatnonzero(~np.isfinite(values).all(axis=1))[0])
        raise InputError(f"the BRDF is not finite at wi {np.round(wi[bad], 6).tolist()}, wo "
                         f"{np.round(wo[bad], 6).tolist()}; expected finite values")
    stored = (values * scale[:, None]).reshape(len(theta), n, n, channels)
    above = above.reshape(len(theta), n, n)
    _extend_below_horizon(stored, above)
    return stored.transpose(0, 3, 1, 2), above


def _extend_below_horizon(stored, above):
    """Give each node whose wo lies below the horizon the stored value of the nearest node
    above it in the same slice (in place). The stored quotient f_r cos(theta_o) / density is
    smooth where the density's tail stretches one cell of the grid over many degrees of h (the
    last cell before the horizon); a 0 there would pull the whole cell towards 0."""
    from scipy.ndimage import distance_transform_edt
    for k in range(len(stored)):
        if above[k].all() or not above[k].any():
            continue
        # indices of the nearest above-horizon node (ties broken by scipy, deterministically)
        _, (iy, ix) = distance_transform_edt(~above[k], return_indices=True)
        stored[k] = stored[k][iy, ix]
