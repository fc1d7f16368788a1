"""Physical checks of a BRDF: non-negativity, Helmholtz reciprocity and energy conservation.

:func:`check` works on anything with ``eval(wi, wo)`` returning ``(..., C)`` values in 1/sr,
``albedo(wi, return_error=True)`` returning the directional albedo and a quadrature error
estimate, and a ``channels`` attribute: every parametric model, sums of lobes, and measured
tables. Each check reports its worst value, where it happens (angles in degrees and the
channel), its tolerance and a one-line detail; the whole report prints as a table and converts
to JSON. Results are deterministic for a given ``seed``.

>>> import brdf
>>> brdf.check("lambert(albedo=0.5) + ggx(ks=0.4, alpha=0.2)").passed
True
>>> report = brdf.check("phong(n=10)")  # the original Phong lobe has a 1/cos(theta_i)
>>> report["reciprocity"].passed, report["reciprocity"].worst > 0.5
(False, True)
"""

import math
from dataclasses import dataclass, field

import numpy as np

from . import arguments
from .errors import InputError
from .formatting import format_table, json_ready
from .geometry import spherical_to_cartesian

__all__ = ["check", "CheckReport", "CheckResult", "direction_pairs", "incidence_grid",
           "RECIPROCITY_TOL", "RECIPROCITY_FLOOR", "ENERGY_TOL",
           "VERDICT_TOL"]

#: Largest accepted relative difference |f(wi,wo) - f(wo,wi)| / max(|f|, floor). Reciprocal
#: formulas evaluated in a different operand order differ by a few ulps (~1e-15); 1e-6 leaves
#: room for measured tables interpolated in float32 while any real asymmetry (the 1/cos(theta_i)
#: of the original Phong model) shows up as an error of order one.
RECIPROCITY_TOL = 1e-6
#: The denominator of the relative error never drops below this fraction of the channel's
#: largest value, so any pair with |f - g| <= RECIPROCITY_TOL * 1e-10 * peak = 1e-16 * peak
#: passes: that is the rounding level of the peak itself. Without it, values in the far tail of
#: a sharp lobe (exp(-tan^2/alpha^2) near underflow) would fail on relative differences that
#: measure rounding, not symmetry; tying the floor to the peak keeps the check independent of
#: the BRDF's scale.
RECIPROCITY_FLOOR = 1e-10
#: Slack on top of the quadrature error estimate when comparing albedo with 1 (rounding of the
#: quadrature sum is ~1e-15; a measured table may carry more).
ENERGY_TOL = 1e-6
#: Cubature tolerance of the energy check's first pass. An albedo whose error estimate leaves
#: no doubt about ``albedo <= 1 + ENERGY_TOL + error`` keeps this precision (the estimate is
#: conservative: actual errors run about ten times smaller); the directions where it does leave
#: doubt are integrated again at the model's default tolerance (1e-5). On a microfacet lobe,
#: whose horizon cut drives the refinement, the first pass takes a third of the panels.
VERDICT_TOL = 1e-4
#: Measured tables: largest accepted 95th percentile of the relative reciprocity error. Real
#: gonioreflectometer data carry a few per cent of noise and calibration drift (Cornell's notes
#: on their paints, NIST's stated uncertainties), so pairs measured both ways agree to a few
#: per cent at best; a table that breaks reciprocity (a wrongly swapped angle convention, a
#: missing cosine) is off by tens of per cent on most pairs.
TABLE_RECIPROCITY_TOL = 0.1
#: Measured tables: the denominator of the relative reciprocity error never drops below this
#: fraction of the channel's mean value. Instruments clip or zero what is below their noise
#: floor (Cornell's paints hold exact zeros beside 1e-5 values), so relative differences of
#: values far below the typical one measure noise, not asymmetry.
TABLE_RECIPROCITY_FLOOR = 0.01
#: Two measured directions closer than this (degrees, on the sphere) count as the same.
TABLE_PAIR_DEG = 1.0
#: Measured tables: a sample and the measured sample nearest to its swap are grossly asymmetric,
#: and fail the check whatever the 95th percentile, when their relative difference exceeds
#: this (they differ by more than a factor of 10: a missing or extra cosine reaches that beyond
#: 84 degrees) and their absolute difference exceeds :data:`TABLE_GROSS_MEAN` times the
#: channel's mean value. Noise at an instrument's floor differs by large factors but little in
#: absolute terms (Cornell's paints hold zeros at 80 degrees incidence beside 0.014 1/sr a
#: degree away, a quarter of the channel mean); a broken region of a table differs by both.
#: Measured samples are compared, not the interpolant: linear interpolation across Cornell's
#: 10-degree incidence steps smears a specular peak into its neighbours (0.55 1/sr against
#: measured 0.034 on both sides), an interpolation error rather than an asymmetry.
TABLE_GROSS_RELATIVE = 0.9
#: See :data:`TABLE_GROSS_RELATIVE`.
TABLE_GROSS_MEAN = 1.0
#: Measured tables: the lookup at a swap is gross too when it leaves the range of the measured
#: values by more than this factor (interpolating measured values cannot; a lookup that divides
#: by a vanishing cosine does: 953,474 1/sr against at most 2.85 measured, paper_white before
#: its eval was made finite).
TABLE_GROSS_RANGE = 2.0
#: Measured tables: polar angles (degrees) at which the energy check probes the albedo towards
#: the horizon, beyond any measured incidence. An integrand bounded at the horizon gives an
#: albedo that is continuous there; one that grows like 1/cos(theta) (the divided-out cosine
#: of a one-sided lookup) gives an albedo growing without bound, which no incidence grid
#: stopping at 89.9 degrees sees.
HORIZON_PROBE_DEG = (90.0 - 1e-2, 90.0 - 1e-4, 90.0 - 1e-6)
#: The probe fails when the albedo closest to the horizon exceeds the one at the first probe
#: angle by more than this factor (plus the energy tolerance).
HORIZON_GROWTH = 2.0
#: Measured tables: a quadrature error estimate above this (albedo units) at the largest
#: albedo means the integral was not resolved, and ``albedo <= 1 + error`` would be vacuous:
#: the energy check fails instead (the real tables' estimates stay below 0.02).
ENERGY_UNRESOLVED = 0.1
#: Most grazing polar angle tested, in degrees (exactly 90 puts a direction in the horizon).
GRAZING_DEG = 89.9
#: Most random pairs ``check`` accepts: each costs about 200 bytes at its peak (angles,
#: directions, values both ways), so 10 million take some 2 GB.
MAX_PAIRS = 10_000_000
#: Most incidence angles (or azimuths) of the energy check's grid, each an albedo integral.
MAX_STEPS = 10_000

# Structured direction pairs, in degrees. Azimuth differences cluster around 0 (retro-reflection)
# and 180 (the specular plane), where sharp lobes and their asymmetries live.
GRID_THETA = (0.0, 1.0, 10.0, 30.0, 45.0, 60.0, 75.0, 85.0, 89.0, GRAZING_DEG)
GRID_PHI_I = (0.0, 30.0, 90.0, 135.0)
GRID_DPHI = (0.0, 0.5, 2.0, 10.0, 45.0, 90.0, 135.0, 170.0, 178.0, 179.5, 180.0, 180.5, 182.0,
             190.0, 270.0, 359.5)
ANGLES = ("theta_i", "phi_i", "theta_o", "phi_o")


@dataclass(frozen=True)
class CheckResult:
    """Outcome of one check.

    Attributes
    ----------
    name : str
        ``"non-negativity"``, ``"reciprocity"`` or ``"energy"``.
    passed : bool or None
        Whether the worst value is within the tolerance; None when the subject cannot be
        tested this way (an in-plane scan has no albedo), which the report shows as "n/a".
    worst : float
        Most negative BRDF value (1/sr), largest relative reciprocity error, or largest albedo.
    where : dict
        Where ``worst`` happens: ``theta_i``, ``phi_i``, ``theta_o``, ``phi_o`` in degrees (the
        outgoing angles are ``None`` for the energy check) and ``channel``.
    tolerance : float
        The tolerance ``worst`` is compared with (see :func:`check`).
    limit : str
        The passing condition on ``worst`` as text, e.g. ``"<= 1 + 1.2e-06"``.
    detail : str
        One line explaining the numbers.
    data : dict
        Extras merged into :meth:`to_dict`: the albedo curve and the quadrature error at the
        worst angle (energy), the floor and both values at the worst pair (reciprocity).
    """

    name: str
    passed: bool
    worst: float
    where: dict
    tolerance: float
    limit: str
    detail: str
    data: dict = field(default_factory=dict)

    def to_dict(self):
        """JSON-ready dictionary (non-finite numbers become ``None``)."""
        return json_ready({"name": self.name, "passed": self.passed, "worst": self.worst,
                            "where": self.where, "tolerance": self.tolerance,
                            "limit": self.limit, "detail": self.detail, **self.data})


@dataclass(frozen=True)
class CheckReport:
    """The three checks of one BRDF; ``str(report)`` is a table, :meth:`to_dict` is JSON-ready."""

    subject: str
    channels: int
    checks: tuple
    declared: dict

    @property
    def passed(self):
        """True when no check failed (checks that could not be run do not count)."""
        return all(c.passed is not False for c in self.checks)

    def __getitem__(self, name):
        for c in self.checks:
            if c.name == name:
                return c
        names = ", ".join(c.name for c in self.checks)
        raise KeyError(f"no check named {name!r}; checks: {names}")

    def to_dict(self):
        return json_ready({"subject": self.subject, "channels": self.channels,
                           "passed": self.passed, "declared": self.declared,
                           "checks": [c.to_dict() for c in self.checks]})

    def __str__(self):
        status = {True: "pass", False: "FAIL", None: "n/a"}
        rows = [(c.name, status[c.passed], f"{c.worst:.7g}", c.limit,
                 _where_text(c.where)) for c in self.checks]
        lines = [f"checks of {self.subject} ({self.channels} channel"
                 f"{'' if self.channels == 1 else 's'})",
                 format_table(("check", "result", "worst", "limit", "where"), rows, "llrll")]
        lines += [f"  {c.name}: {c.detail}" for c in self.checks]
        failed = [c.name for c in self.checks if c.passed is False]
        lines.append(f"result: FAIL ({', '.join(failed)})" if failed else "result: pass")
        return "\n".join(lines)


def _where_text(where):
    parts = [f"{k}={where[k]:g}" for k in ANGLES if where.get(k) is not None]
    if where.get("channel") is not None:
        parts.append(f"channel={where['channel']}")
    return " ".join(parts)


# --- where to look ---------------------------------------------------------------------------

def direction_pairs(n_random=200_000, seed=0):
    """Angles ``(n, 4)`` in degrees (theta_i, phi_i, theta_o, phi_o) of the pairs tested.

    The structured grid (:data:`GRID_THETA` for both polar angles, up to 89.9 degrees, times
    :data:`GRID_PHI_I` times the azimuth differences :data:`GRID_DPHI`) comes first, then
    ``n_random`` pairs with both directions uniform in solid angle over the upper hemisphere.
    """
    ti, pi_, to, dphi = np.meshgrid(GRID_THETA, GRID_PHI_I, GRID_THETA, GRID_DPHI, indexing="ij")
    grid = np.stack([ti, pi_, to, np.mod(pi_ + dphi, 360.0)], -1).reshape(-1, 4)
    u = np.random.default_rng(seed).random((int(n_random), 4))
    # cos(theta) uniform in (0, 1] is uniform in solid angle (PBR 3rd ed. 13.6.1)
    theta = np.degrees(np.arccos(1.0 - u[:, 0::2]))
    rand = np.stack([theta[:, 0], 360.0 * u[:, 1], theta[:, 1], 360.0 * u[:, 3]], -1)
    return np.concatenate([grid, rand])


def incidence_grid(theta_steps, phi_steps=1):
    """Incidence angles in degrees for the energy check: ``(theta, phi)`` 1-D arrays.

    ``theta`` runs from 0 to 89.9 degrees as 89.9 sin(pi t / 2) over evenly spaced t, so steps
    shrink towards grazing where albedos of rough and Fresnel-free lobes change fastest;
    ``phi`` splits the full circle into ``phi_steps`` equal parts.
    """
    t = np.linspace(0.0, 1.0, theta_steps)
    return GRAZING_DEG * np.sin(0.5 * math.pi * t), np.arange(phi_steps) * (360.0 / phi_steps)


def _directions(theta_deg, phi_deg):
    return spherical_to_cartesian(np.radians(theta_deg), np.radians(phi_deg))


def _values(obj, wi, wo, channels):
    f = np.asarray(obj.eval(wi, wo), dtype=float)
    return f.reshape(wi.shape[0], channels)


def _pair_where(angles, k, c):
    return {**{name: float(angles[k, j]) for j, name in enumerate(ANGLES)}, "channel": int(c)}


# --- the three checks ------------------------------------------------------------------------

def _non_negativity(f, angles, n_random, delta):
    """Most negative value of f; a NaN or infinite value fails with its place."""
    suffix = "; delta lobes eval to 0 and are covered by the energy check" if delta else ""
    counts = f"{len(angles)} direction pairs ({len(angles) - n_random} grid, {n_random} random)"
    bad = np.argwhere(~np.isfinite(f))
    if len(bad):
        k, c = bad[0]
        return CheckResult("non-negativity", False, float(f[k, c]), _pair_where(angles, k, c),
                           0.0, ">= 0", f"eval returned {f[k, c]} (not finite) among {counts}")
    k, c = np.unravel_index(np.argmin(f), f.shape)
    worst = float(f[k, c])
    return CheckResult("non-negativity", worst >= 0.0, worst, _pair_where(angles, k, c), 0.0,
                       ">= 0", f"min f = {worst:.6g} 1/sr over {counts}{suffix}")


def _reciprocity(f, g, angles, tol):
    """Largest relative difference between f(wi, wo) and f(wo, wi), per channel floor."""
    finite = np.isfinite(f) & np.isfinite(g)
    scale = np.max(np.where(finite, np.maximum(np.abs(f), np.abs(g)), 0.0), axis=0)
    floor = np.maximum(RECIPROCITY_FLOOR * scale, np.finfo(float).tiny)
    with np.errstate(invalid="ignore"):
        err = np.abs(f - g) / np.maximum(np.maximum(np.abs(f), np.abs(g)), floor)
    err = np.where(finite, err, math.inf)
    k, c = np.unravel_index(np.argmax(err), err.shape)
    worst = float(err[k, c])
    detail = (f"max |f(wi,wo) - f(wo,wi)| / max(|f|, floor) = {worst:.3g} where "
              f"f(wi,wo) = {f[k, c]:.6g} and f(wo,wi) = {g[k, c]:.6g} 1/sr; "
              f"floor = {RECIPROCITY_FLOOR:g} x channel max")
    return CheckResult("reciprocity", worst <= tol, worst, _pair_where(angles, k, c), tol,
                       f"<= {tol:.3g}", detail,
                       {"floor": floor.tolist(), "f_wi_wo": float(f[k, c]),
                        "f_wo_wi": float(g[k, c])})


def _albedo_for_verdict(obj, wi, tol):
    """Albedo and error estimate at ``wi`` (p, t, 3), to :data:`VERDICT_TOL` where that settles
    ``albedo <= 1 + tol + error`` either way, to the model's default tolerance where not."""
    from .models.base import Model
    if not isinstance(obj, Model):
        return (np.asarray(v, dtype=float) for v in obj.albedo(wi, return_error=True))
    a, err = obj.albedo(wi, tol=VERDICT_TOL, return_error=True)
    open_ = (np.abs(a - (1.0 + tol)) <= err).any(axis=-1)
    if open_.any():
        a[open_], err[open_] = obj.albedo(wi[open_], return_error=True)
    return a, err


def _energy(obj, theta, phi, tol):
    """Largest directional albedo over the incidence grid, against 1 + tol + quadrature error."""
    wi = _directions(theta[None, :], phi[:, None])
    a, err = _albedo_for_verdict(obj, wi, tol)
    a = a.reshape(len(phi), len(theta), -1)
    err = err.reshape(a.shape)
    key = np.where(np.isfinite(a), a, math.inf)
    p, t, c = np.unravel_index(np.argmax(key), a.shape)
    worst, tolerance = float(a[p, t, c]), tol + float(err[p, t, c])
    where = {"theta_i": float(theta[t]), "phi_i": float(phi[p]), "theta_o": None,
             "phi_o": None, "channel": int(c)}
    detail = (f"max albedo {worst:.6f} (quadrature error estimate {err[p, t, c]:.1e}) over "
              f"{a.shape[0] * a.shape[1]} incidence directions; largest error estimate "
              f"{np.nanmax(err):.1e}")
    curve = {"theta_i": theta, "phi_i": phi, "albedo": a, "error": err}
    return CheckResult("energy", worst <= 1.0 + tolerance, worst, where, tolerance,
                       f"<= 1 + {tolerance:.3g}", detail,
                       {"quadrature_error": float(err[p, t, c]), "curve": curve})


def check(obj, *, seed=0, pairs=200_000, theta_steps=90, anisotropic_steps=(24, 8),
          reciprocity_tol=RECIPROCITY_TOL, energy_tol=ENERGY_TOL,
          table_reciprocity_tol=TABLE_RECIPROCITY_TOL):
    """Check non-negativity, Helmholtz reciprocity and energy conservation of a BRDF.

    Parameters
    ----------
    obj : Model, str or measured table
        A model, a spec string (parsed with :func:`brdf.parse`), or any object with
        ``eval(wi, wo)``, ``albedo(wi, return_error=True)`` and ``channels``.
    seed : int or numpy.random.Generator
        Seed of the random direction pairs.
    pairs : int
        Number of random direction pairs added to the structured grid (see
        :func:`direction_pairs`) for the non-negativity and reciprocity checks.
    theta_steps : int
        Incidence polar angles for the energy check of an isotropic BRDF (0 to 89.9 degrees,
        denser near grazing; see :func:`incidence_grid`).
    anisotropic_steps : (int, int)
        Polar angles and azimuths of the incidence grid used instead when ``obj`` is
        anisotropic (or does not say, having no ``is_anisotropic``): a 2-D grid costs
        ``phi`` times more albedo integrals, so it is coarser in theta.
    reciprocity_tol : float
        Largest accepted relative reciprocity error (see :data:`RECIPROCITY_TOL`).
    energy_tol : float
        Slack added to the quadrature error estimate at the largest albedo: the energy check
        passes when ``max albedo <= 1 + energy_tol + error estimate there``.
    table_reciprocity_tol : float
        For measured tables: largest accepted 95th percentile of the relative difference
        between reciprocal pairs (see :func:`table_reciprocity`).

    Measured tables (objects with ``values``, ``wi`` and ``wo`` samples) are checked on their
    samples rather than on random pairs: non-negativity counts the negative samples,
    reciprocity compares samples whose swapped pair was measured too, and the energy check
    integrates the interpolant over the incidence angles the table covers.

    Returns
    -------
    CheckReport
    """
    from .spec import parse
    if isinstance(obj, str):
        obj = parse(obj)
    for name in ("eval", "albedo"):
        if not callable(getattr(obj, name, None)):
            raise InputError(f"check: expected a model, a spec or a measured table with "
                             f"eval() and albedo(), got {type(obj).__name__}")
    _require_counts(pairs=(pairs, 0, MAX_PAIRS), theta_steps=(theta_steps, 2, MAX_STEPS),
                    anisotropic_steps=(anisotropic_steps, (2, 1), (MAX_STEPS, MAX_STEPS)))
    arguments.seed(seed, "check: seed")
    for name, tol in (("reciprocity_tol", reciprocity_tol), ("energy_tol", energy_tol),
                      ("table_reciprocity_tol", table_reciprocity_tol)):
        arguments.real(tol, f"check: {name}", 0.0)
    channels = int(obj.channels)
    declared = {k: bool(getattr(obj, k)) for k in ("reciprocal", "energy_conserving", "delta",
                                                   "is_anisotropic") if hasattr(obj, k)}
    if _is_table(obj):
        return _check_table(obj, declared, theta_steps, anisotropic_steps, table_reciprocity_tol,
                            energy_tol)
    angles = direction_pairs(pairs, seed)
    wi = _directions(angles[:, 0], angles[:, 1])
    wo = _directions(angles[:, 2], angles[:, 3])
    f = _values(obj, wi, wo, channels)
    g = _values(obj, wo, wi, channels)
    grid = (theta_steps, 1) if declared.get("is_anisotropic") is False else anisotropic_steps
    theta, phi = incidence_grid(*grid)
    checks = (_non_negativity(f, angles, pairs, declared.get("delta", False)),
              _reciprocity(f, g, angles, reciprocity_tol),
              _energy(obj, theta, phi, energy_tol))
    return CheckReport(str(obj), channels, checks, declared)


def _require_counts(**options):
    """Raise InputError unless each option is an integer (or a tuple of integers) from its
    low to its high."""
    for name, (value, low, high) in options.items():
        values, lows, highs = (value, low, high) if isinstance(low, tuple) else (
            (value,), (low,), (high,))
        if not (isinstance(values, (tuple, list)) and len(values) == len(lows)
                and all(arguments.is_integer(v) and lo <= v <= hi for v, lo, hi in zip(values, lows, highs))):
            expected = (f"{len(lows)} integers from {lows} to {highs}" if len(lows) > 1
                        else f"an integer from {low} to {high:,}")
            raise InputError(f"check: {name} must be {expected}, got {value!r}")


# --- measured tables -------------------------------------------------------------------------

def _is_table(obj):
    return all(hasattr(obj, k) for k in ("values", "wi", "wo"))


def _check_table(table, declared, theta_steps, anisotropic_steps, reciprocity_tol, energy_tol):
    values = np.asarray(table.values, dtype=float)
    angles = np.asarray(table.angles)
    checks = (_table_non_negativity(values, angles),
              table_reciprocity(table, reciprocity_tol),
              _table_energy(table, angles, theta_steps, anisotropic_steps, energy_tol))
    return CheckReport(str(table), int(table.channels), checks, declared)


def _table_non_negativity(values, angles):
    """Negative samples: how many, which fraction of the measured ones, the worst and where."""
    measured = np.isfinite(values)
    negative = measured & (values < 0.0)
    count, total = int(negative.sum()), int(measured.sum())
    key = np.where(measured, values, math.inf)
    k, c = np.unravel_index(np.argmin(key), key.shape)
    worst = float(values[k, c])
    missing = values.size - total
    detail = (f"{count} of {total} measured values negative ({count / max(total, 1):.3%})"
              f"{f'; {missing} missing' if missing else ''}; min f = {worst:.6g} 1/sr")
    return CheckResult("non-negativity", count == 0, worst, _pair_where(angles, k, c), 0.0,
                       ">= 0", detail, {"negative": count, "measured": total,
                                        "fraction": count / max(total, 1), "missing": missing})


def table_reciprocity(table, tol=TABLE_RECIPROCITY_TOL, pair_deg=TABLE_PAIR_DEG):
    """Reciprocity of a measured table: samples against the table at the swapped directions.

    For every sample (wi, wo) whose swap (wo, wi) lies within ``pair_deg`` degrees of a
    measured sample, the table's one-sided interpolant at (wo, wi) is compared with the
    sample; pairs where the interpolant is outside the measured region (``inside`` False:
    beyond the hull, or an RGL table's measured elevation range) are left out. The relative
    difference is taken against at least :data:`TABLE_RECIPROCITY_FLOOR` times the channel's
    mean value. The check passes when the 95th percentile of the relative difference is
    within ``tol`` and no pair is grossly asymmetric (:data:`TABLE_GROSS_RELATIVE` and
    :data:`TABLE_GROSS_MEAN` for the sample against the measured sample nearest to the swap,
    :data:`TABLE_GROSS_RANGE` for the lookup at the swap). Layouts that store one value per
    reciprocal pair (MERL) pass by construction.

    The result's ``data`` holds ``pairs``, ``median``, ``p95``, ``gross`` (the number of grossly
    asymmetric pair-channels), ``excluded`` (pairs outside the measured region), ``floor`` and
    ``worst_pair``: ``wi`` and ``wo`` (theta, phi in degrees) of the worst sample, its value
    ``f_wi_wo``, the table at the swap ``f_wo_wi``, the measured sample nearest to the swap
    ``nearest_swapped`` and the ``channel``; ``where`` gives the same angles. The worst pair is
    the gross one with the largest difference when there is one.
    """
    from scipy.spatial import cKDTree
    limit = f"p95 <= {tol:g}, no gross pair"
    if getattr(table, "reciprocal_by_layout", False):
        return CheckResult("reciprocity", True, 0.0, {}, tol, limit,
                           "the layout stores one value per reciprocal pair (reciprocal by "
                           "construction)", {"pairs": 0})
    wi, wo = np.asarray(table.wi), np.asarray(table.wo)
    values = np.asarray(table.values, dtype=float)
    # in the table's own coordinates an isotropic table's swapped pair is found whatever
    # azimuth it was measured at
    distance, nearest = cKDTree(table.coordinates(wi, wo)).query(
        table.coordinates(wo, wi), distance_upper_bound=math.radians(pair_deg))
    paired = np.isfinite(distance) & ~np.all(np.isclose(wi, wo, atol=1e-12), axis=1)
    if not paired.any():
        return CheckResult("reciprocity", None, math.nan, {}, tol, limit,
                           f"not testable: no sample's swapped pair was measured within "
                           f"{pair_deg:g} degrees", {"pairs": 0})
    swapped, inside = table.eval_one_sided(wo[paired], wi[paired])
    f = values[paired]
    ok = np.isfinite(f) & inside[:, None]
    mean = np.nanmean(np.abs(values), axis=0)
    floor = TABLE_RECIPROCITY_FLOOR * mean
    floor = np.maximum(floor, RECIPROCITY_FLOOR * np.nanmax(np.abs(values), axis=0))
    with np.errstate(invalid="ignore", divide="ignore"):
        diff = np.abs(f - swapped)
        err = diff / np.maximum(np.maximum(np.abs(f), np.abs(swapped)), floor)
    err = np.where(ok, err, np.nan)
    excluded = int((np.isfinite(f).any(axis=1) & ~inside).sum())
    if not np.isfinite(err).any():
        return CheckResult("reciprocity", None, math.nan, {}, tol, limit,
                           "not testable: no measured reciprocal pair", {"pairs": 0,
                                                                        "excluded": excluded})
    near = values[nearest[paired]]
    with np.errstate(invalid="ignore"):
        near_diff = np.abs(f - near)
        near_err = near_diff / np.maximum(np.maximum(np.abs(f), np.abs(near)), floor)
        out_of_range = ~(np.abs(swapped) <= TABLE_GROSS_RANGE * np.nanmax(np.abs(values), axis=0))
    gross = ok & (((near_err > TABLE_GROSS_RELATIVE) & (near_diff > TABLE_GROSS_MEAN * mean))
                  | out_of_range)
    p95 = float(np.nanpercentile(err, 95))
    median = float(np.nanmedian(err))
    # the worst pair: the largest difference among the gross ones, else the largest relative
    key = (np.where(gross, np.maximum(np.nan_to_num(diff, nan=np.inf), near_diff), -1.0)
           if gross.any() else np.where(ok, err, -1.0))
    k, c = np.unravel_index(np.argmax(key), err.shape)
    worst = float(err[k, c])
    rows = np.nonzero(paired)[0]
    angles = np.asarray(table.angles)[rows]
    n_pairs = int(np.isfinite(err).any(axis=1).sum())
    n_gross = int(gross.sum())
    pair = {"wi": {"theta": float(angles[k, 0]), "phi": float(angles[k, 1])},
            "wo": {"theta": float(angles[k, 2]), "phi": float(angles[k, 3])},
            "f_wi_wo": float(f[k, c]), "f_wo_wi": float(swapped[k, c]),
            "nearest_swapped": float(near[k, c]), "channel": int(c)}
    detail = (f"{n_pairs} samples with the swapped pair measured (within {pair_deg:g} deg"
              f"{f'; {excluded} outside the measured region left out' if excluded else ''}): "
              f"relative difference median {median:.3g}, p95 {p95:.3g}; "
              f"{'gross' if n_gross else 'worst'} pair wi = ({angles[k, 0]:.4g}, "
              f"{angles[k, 1]:.4g}) deg, wo = ({angles[k, 2]:.4g}, {angles[k, 3]:.4g}) deg, "
              f"channel {c}: f(wi,wo) = {f[k, c]:.6g}, f(wo,wi) = {swapped[k, c]:.6g} 1/sr "
              f"(relative {worst:.3g}; nearest swapped sample {near[k, c]:.6g}); {n_gross} "
              f"grossly asymmetric (against the nearest swapped sample relative > "
              f"{TABLE_GROSS_RELATIVE:g} and difference > {TABLE_GROSS_MEAN:g} x channel "
              f"mean, or the lookup beyond {TABLE_GROSS_RANGE:g} x the largest sample)")
    return CheckResult("reciprocity", p95 <= tol and n_gross == 0, worst,
                       _pair_where(angles, k, c), tol, limit, detail,
                       {"pairs": n_pairs, "median": median, "p95": p95, "gross": n_gross,
                        "excluded": excluded, "floor": floor.tolist(), "worst_pair": pair,
                        "f_wi_wo": pair["f_wi_wo"], "f_wo_wi": pair["f_wo_wi"]})


def _table_energy(table, angles, theta_steps, anisotropic_steps, tol):
    """The energy check over the incident polar angles the table measured (the interpolant is
    clamped beyond them, so albedos there would repeat the edge), a probe of the albedo towards
    the horizon (:data:`HORIZON_PROBE_DEG`) and a resolved quadrature
    (:data:`ENERGY_UNRESOLVED`)."""
    if getattr(table, "in_plane", False):
        return CheckResult("energy", None, math.nan, {}, tol, "<= 1",
                           "not testable: an in-plane scan holds no out-of-plane scattering, "
                           "so the albedo integral is undefined")
    low, high = float(np.min(angles[:, 0])), float(np.max(angles[:, 0]))
    if getattr(table, "reciprocal_by_layout", False) or high - low < 1e-9:
        low, high = 0.0, GRAZING_DEG
    high = min(high, GRAZING_DEG)
    steps = theta_steps if table.isotropic else anisotropic_steps[0]
    theta = low + (high - low) * np.sin(0.5 * math.pi * np.linspace(0.0, 1.0, steps))
    _, phi = incidence_grid(2, 1 if table.isotropic else anisotropic_steps[1])
    result = _energy(table, theta, phi, tol)
    detail = result.detail + f"; theta_i from {low:g} to {high:g} degrees (the measured range)"
    passed, data = result.passed, dict(result.data)
    # towards the horizon: the albedo of a bounded integrand levels off
    probe, _ = (np.asarray(v, dtype=float) for v in table.albedo(
        _directions(np.asarray(HORIZON_PROBE_DEG)[None, :], phi[:, None]), return_error=True))
    first, last = probe[:, 0].max(), probe[:, -1].max()
    data["horizon_albedo"] = {"theta_i": list(HORIZON_PROBE_DEG),
                              "albedo": probe.max(axis=(0, 2)).tolist()}
    if not last <= HORIZON_GROWTH * first + tol:
        passed = False
        detail += (f"; FAIL: the albedo grows towards the horizon, {first:.6g} at "
                   f"{HORIZON_PROBE_DEG[0]:g} deg to {last:.6g} at {HORIZON_PROBE_DEG[-1]:.9g} "
                   f"deg (more than {HORIZON_GROWTH:g}x): the integrand diverges there")
    if not result.data["quadrature_error"] <= ENERGY_UNRESOLVED:
        passed = False
        detail += (f"; FAIL: quadrature error estimate {result.data['quadrature_error']:.3g} "
                   f"> {ENERGY_UNRESOLVED:g} at the largest albedo: the integral is unresolved")
    return CheckResult(result.name, passed, result.worst, result.where, result.tolerance,
                       result.limit, detail, data)
