"""GGX and Beckmann lobes against independent oracles: numerical integrals (scipy), analytic
albedos, and closed forms written here in spherical angles rather than the library's slopes."""

import math

import numba
import numpy as np
import pytest
from scipy import integrate, optimize, special

import brdf
from brdf.models import microfacet
from brdf.models.microfacet import BECKMANN, GGX

DISTRIBUTIONS = {"ggx": GGX, "beckmann": BECKMANN}
ROUGHNESS = [(0.05, 0.05), (0.3, 0.3), (1.0, 1.0), (0.1, 0.6), (0.8, 0.25)]


def _xyz(theta, phi):
    """Unit vector as a tuple of floats (fast inside scalar quadrature integrands)."""
    s = math.sin(theta)
    return s * math.cos(phi), s * math.sin(phi), math.cos(theta)


def _unit(theta, phi):
    return np.array(_xyz(theta, phi))


def _random_hemisphere(rng, n):
    z = rng.uniform(0.02, 1.0, n)
    phi = rng.uniform(0.0, 2.0 * math.pi, n)
    s = np.sqrt(1.0 - z * z)
    return np.stack([s * np.cos(phi), s * np.sin(phi), z], -1)


# --- independent closed forms (angles, scipy's erf) ----------------------------------------

def _alpha_along(phi, ax, ay):
    """Roughness seen along azimuth phi (Heitz 2014, eq. 80)."""
    return np.sqrt(np.cos(phi) ** 2 * ax ** 2 + np.sin(phi) ** 2 * ay ** 2)


def reference_ndf(name, h, ax, ay):
    """D(h) from theta_h and phi_h (Heitz 2014, eq. 84 Beckmann, eq. 85 GGX)."""
    theta = np.arccos(h[..., 2])
    phi = np.arctan2(h[..., 1], h[..., 0])
    t2 = np.tan(theta) ** 2 * (np.cos(phi) ** 2 / ax ** 2 + np.sin(phi) ** 2 / ay ** 2)
    if name == "ggx":
        return 1.0 / (np.pi * ax * ay * np.cos(theta) ** 4 * (1.0 + t2) ** 2)
    return np.exp(-t2) / (np.pi * ax * ay * np.cos(theta) ** 4)


def reference_lambda(name, w, ax, ay):
    """Smith Lambda from a = 1 / (alpha(phi) tan theta) (Heitz 2014, eqs. 83 and 86)."""
    theta = np.arccos(w[..., 2])
    phi = np.arctan2(w[..., 1], w[..., 0])
    with np.errstate(divide="ignore"):
        a = 1.0 / (_alpha_along(phi, ax, ay) * np.tan(theta))
    if name == "ggx":
        return 0.5 * (-1.0 + np.sqrt(1.0 + 1.0 / a ** 2))
    return 0.5 * (special.erf(a) - 1.0) + np.exp(-a * a) / (2.0 * a * np.sqrt(np.pi))


def reference_eval(name, wi, wo, ax, ay, correlated=False, f0=None):
    """Cook-Torrance f = F D G2 / (4 cos_i cos_o) (Walter et al. 2007, eq. 20); G2 separable
    (Heitz 2014, eq. 98) or height-correlated (eq. 99); Schlick F (Schlick 1994, eq. 15)."""
    h = wi + wo
    h = h / np.linalg.norm(h, axis=-1, keepdims=True)
    li, lo = reference_lambda(name, wi, ax, ay), reference_lambda(name, wo, ax, ay)
    g2 = 1.0 / (1.0 + li + lo) if correlated else 1.0 / ((1.0 + li) * (1.0 + lo))
    f = 1.0 if f0 is None else f0 + (1.0 - f0) * (1.0 - np.sum(wi * h, -1)) ** 5
    return f * reference_ndf(name, h, ax, ay) * g2 / (4.0 * wi[..., 2] * wo[..., 2])


def _spec(name, ax, ay, correlated=False, fresnel=None):
    masking = "height-correlated" if correlated else "separable"
    text = f"{name}(alpha={ax!r}, alpha_y={ay!r}, masking={masking}"
    return brdf.parse(text + (f", fresnel=schlick(f0={fresnel!r}))" if fresnel else ")"))


def _hemisphere_integral(fn, theta_points=()):
    """Integral of fn(theta, phi) sin(theta) over the upper hemisphere by nested adaptive
    quadrature (scipy QUADPACK), with break points in theta where fn is sharp."""
    def over_theta(phi):
        return integrate.quad(lambda t: fn(t, phi) * math.sin(t), 0.0, math.pi / 2,
                              points=theta_points or None, epsabs=1e-11, epsrel=1e-10,
                              limit=200)[0]
    return integrate.quad(over_theta, 0.0, 2.0 * math.pi, epsabs=1e-10, epsrel=1e-9,
                          limit=200)[0]


# --- distributions and masking ---------------------------------------------------------------

@pytest.mark.parametrize("name", DISTRIBUTIONS)
@pytest.mark.parametrize("ax, ay", ROUGHNESS)
def test_ndf_projected_area_is_one(name, ax, ay):
    """The integral of D(h) cos(theta_h) over the hemisphere is 1 (Walter et al. 2007, eq. 4)."""
    dist = DISTRIBUTIONS[name]

    def d_cos(theta, phi):
        hx, hy, hz = _xyz(theta, phi)
        return microfacet.ndf(dist, ax, ay, hx, hy, hz) * hz

    total = _hemisphere_integral(d_cos, theta_points=(min(ax, ay), max(ax, ay)))
    assert total == pytest.approx(1.0, abs=2e-7)


@pytest.mark.parametrize("name", DISTRIBUTIONS)
@pytest.mark.parametrize("ax, ay", [(0.1, 0.1), (0.5, 0.5), (0.1, 0.6), (1.0, 0.3)])
@pytest.mark.parametrize("theta_i, phi_i", [(0.0, 0.0), (45.0, 30.0), (80.0, 120.0)])
def test_visible_normals_are_normalised(name, ax, ay, theta_i, phi_i):
    """G1(wi) times the integral of max(0, wi.h) D(h) over h is cos(theta_i) (Heitz 2014,
    eq. 10): the Smith G1 is exactly the projected area of the visible microfacets."""
    dist = DISTRIBUTIONS[name]
    ix, iy, iz = _xyz(math.radians(theta_i), math.radians(phi_i))
    g1 = 1.0 / (1.0 + microfacet.smith_lambda(dist, ax, ay, ix, iy, iz))

    def visible(theta, phi):
        hx, hy, hz = _xyz(theta, phi)
        cos = max(0.0, ix * hx + iy * hy + iz * hz)
        return cos * microfacet.ndf(dist, ax, ay, hx, hy, hz)

    total = g1 * _hemisphere_integral(visible, theta_points=(min(ax, ay), max(ax, ay))) / iz
    assert total == pytest.approx(1.0, abs=1e-6)


@pytest.mark.parametrize("name", DISTRIBUTIONS)
@pytest.mark.parametrize("ax, ay", ROUGHNESS)
def test_smith_lambda_matches_closed_form(name, ax, ay):
    w = _random_hemisphere(np.random.default_rng(7), 200)
    ours = [microfacet.smith_lambda(DISTRIBUTIONS[name], ax, ay, *v) for v in w]
    np.testing.assert_allclose(ours, reference_lambda(name, w, ax, ay), rtol=1e-10, atol=1e-15)


@pytest.mark.parametrize("name", DISTRIBUTIONS)
@pytest.mark.parametrize("alpha", [0.05, 0.3, 1.0, 2.5])
@pytest.mark.parametrize("theta", [10.0, 45.0, 70.0, 85.0, 89.0])
def test_smith_lambda_from_slope_distribution(name, alpha, theta):
    """Lambda = (1/mu) integral over q > mu of (q - mu) P(q), with mu = cot(theta) and P the
    marginal slope density (Heitz 2014, eq. 72; P from eqs. 84/85 integrated over one slope)."""
    mu = 1.0 / math.tan(math.radians(theta))
    if name == "ggx":
        def marginal(q):
            return 1.0 / (2.0 * alpha * (1.0 + (q / alpha) ** 2) ** 1.5)
    else:
        def marginal(q):
            return math.exp(-(q / alpha) ** 2) / (alpha * math.sqrt(math.pi))
    tail = integrate.quad(lambda q: (q - mu) * marginal(q), mu, math.inf, epsabs=1e-14,
                          epsrel=1e-11)[0]
    ours = microfacet.smith_lambda(DISTRIBUTIONS[name], alpha, alpha, math.sin(math.radians(theta)),
                                   0.0, math.cos(math.radians(theta)))
    assert ours == pytest.approx(tail / mu, rel=1e-8, abs=1e-14)


# --- the BRDF --------------------------------------------------------------------------------

@pytest.mark.parametrize("name", DISTRIBUTIONS)
@pytest.mark.parametrize("ax, ay", ROUGHNESS)
@pytest.mark.parametrize("correlated", [False, True])
@pytest.mark.parametrize("f0", [None, 0.04])
def test_eval_matches_reference(name, ax, ay, correlated, f0):
    rng = np.random.default_rng(3)
    wi, wo = _random_hemisphere(rng, 500), _random_hemisphere(rng, 500)
    model = _spec(name, ax, ay, correlated, f0)
    expected = reference_eval(name, wi, wo, ax, ay, correlated, f0)
    np.testing.assert_allclose(model.eval(wi, wo)[:, 0], expected, rtol=1e-9, atol=1e-300)


def test_eval_is_zero_below_the_horizon():
    model = brdf.parse("ggx(alpha=0.3)")
    up, down = _unit(0.5, 0.2), _unit(2.0, 1.0)
    assert model.eval(up, down)[0] == 0.0 and model.eval(down, up)[0] == 0.0


def test_albedo_at_normal_incidence_with_unit_roughness_is_one_minus_ln2():
    """GGX, alpha = 1, F = 1, separable masking: D = 1/pi and G1(wo) = 2 cos / (1 + cos), so
    the albedo at normal incidence is 2 * integral over [0, pi/4] of cos(2t) tan(t) dt, which
    is 1 - ln 2."""
    albedo = brdf.parse("ggx(alpha=1)").albedo(np.array([0.0, 0.0, 1.0]))
    assert albedo[0] == pytest.approx(1.0 - math.log(2.0), rel=1e-6)


def test_albedo_at_normal_incidence_matches_scipy():
    wi = np.array([0.0, 0.0, 1.0])
    reference = 2.0 * math.pi * integrate.quad(
        lambda t: reference_eval("ggx", wi, _unit(t, 0.0), 0.3, 0.3) * math.cos(t) * math.sin(t),
        0.0, math.pi / 2, epsabs=1e-13, epsrel=1e-12, limit=200)[0]
    assert reference == pytest.approx(0.8774, abs=5e-4)  # the figure usually quoted
    assert brdf.parse("ggx(alpha=0.3)").albedo(wi)[0] == pytest.approx(reference, rel=1e-6)


@pytest.mark.parametrize("name", DISTRIBUTIONS)
@pytest.mark.parametrize("ax, ay, theta_i, phi_i", [(0.3, 0.3, 60.0, 0.0), (0.5, 0.15, 45.0, 70.0),
                                                   (1.0, 1.0, 80.0, 10.0)])
def test_oblique_albedo_matches_scipy(name, ax, ay, theta_i, phi_i):
    wi = _unit(math.radians(theta_i), math.radians(phi_i))
    reference = _hemisphere_integral(
        lambda t, p: reference_eval(name, wi, _unit(t, p), ax, ay) * math.cos(t))
    assert _spec(name, ax, ay).albedo(wi)[0] == pytest.approx(reference, rel=1e-5)


@pytest.mark.parametrize("name", DISTRIBUTIONS)
@pytest.mark.parametrize("alpha", [0.1, 0.5, 1.0])
def test_height_correlated_albedo_is_at_least_separable(name, alpha):
    """1 / (1 + Li + Lo) >= 1 / ((1 + Li)(1 + Lo)) pointwise, hence for the albedo too."""
    wi = np.stack([_unit(math.radians(t), 0.3) for t in (0.0, 45.0, 80.0, 89.0)])
    separable = _spec(name, alpha, alpha).albedo(wi)
    correlated = _spec(name, alpha, alpha, correlated=True).albedo(wi)
    assert np.all(correlated >= separable - 1e-9)
    assert correlated[-1, 0] > separable[-1, 0]  # strictly at grazing incidence


# --- numerics --------------------------------------------------------------------------------

def test_erfinv_matches_scipy():
    y = np.concatenate([np.linspace(-1.0 + 1e-6, 1.0 - 1e-6, 4001), [0.0, 1e-300, -1e-12]])
    ours = np.array([microfacet.erfinv(v) for v in y])
    np.testing.assert_allclose(ours, special.erfinv(y), rtol=1e-12, atol=1e-12)


def test_beckmann_sampling_at_the_edges_of_the_unit_square():
    """u = 0 is a valid uniform number: erfinv(2u - 1) = erfinv(-1) must not turn into NaN."""
    model = brdf.parse("beckmann(alpha=0.3)")
    u = np.array([[0.0, 0.0], [0.0, 0.5], [0.5, 0.0], [1.0 - 2 ** -53, 1.0 - 2 ** -53]])
    for wi in (np.array([0.0, 0.0, 1.0]), _unit(1.0, 0.5)):
        wo, pdf = model.sample(wi, u)
        assert np.all(np.isfinite(wo)) and not np.any(np.isnan(pdf)), (wo, pdf)


def _visible_slope_reference(mu, u):
    """The root of C(x) = u C(mu) for the CDF of (mu - x) exp(-x^2) on x < mu (Heitz & d'Eon
    2014, section 5.2), by scipy's brentq on scipy's erfc; above u = 1/2 on the complement
    C(mu) - C(x), integrated by quad, whose digits do not cancel near mu."""
    k = 0.5 * math.sqrt(math.pi) * mu
    total = k * special.erfc(-mu) + 0.5 * math.exp(-mu * mu)
    if u <= 0.5:
        def gap(x):
            return math.log(k * special.erfc(-x) + 0.5 * math.exp(-x * x)) - math.log(u * total)
    else:
        def gap(x):
            # beyond max(x, 0) + 12 the integrand is below e^-144 of the tail
            end = min(mu, max(x, 0.0) + 12.0)
            tail = integrate.quad(lambda t: (mu - t) * math.exp(-t * t), x, end, epsabs=0.0,
                                  epsrel=1e-13, limit=200)[0]
            return math.log((1.0 - u) * total) - math.log(tail)
    # past x = 9 the tail underflows; the roots for u < 1 - 1e-12 lie below 8
    hi = min(mu, 9.0) - 1e-13 * (1.0 + mu) if u > 0.5 else mu
    return optimize.brentq(gap, -9.0, hi, xtol=1e-15, rtol=1e-15)


@pytest.mark.parametrize("mu", [0.0, 0.01, 0.3, 1.0, 3.0, 30.0, 1e4])
def test_beckmann_visible_slope_matches_scipy(mu):
    """The inversion of the visible-slope CDF over the body and both tails of u (down to the
    2^-54 that erfinv's clamp allows, up to within 1e-12 of 1)."""
    u = np.concatenate([np.linspace(0.01, 0.99, 25), [2.0 ** -54, 1e-12, 1e-6, 0.4999, 0.5001,
                                                      1 - 1e-6, 1 - 1e-9, 1 - 1e-12]])
    for v in u:
        x = microfacet.beckmann_visible_slope_x(mu, v)
        assert x == pytest.approx(_visible_slope_reference(mu, v), rel=1e-9, abs=1e-9), (mu, v)


@pytest.mark.parametrize("name", DISTRIBUTIONS)
@pytest.mark.parametrize("ax, ay", [(0.3, 0.3), (0.05, 0.6)])
@pytest.mark.parametrize("correlated", [False, True])
@pytest.mark.parametrize("f0", [None, 0.04])
def test_albedo_weight_is_f_cos_over_pdf(name, ax, ay, correlated, f0):
    """The albedo's integrand in closed form, ks F G2 / G1(wi), is the reference f times
    cos(theta_o) over the pdf at the direction that ``sample`` draws from the same u, and the
    sample is valid exactly when it is above the horizon."""
    model = _spec(name, ax, ay, correlated, f0).replace(ks=[0.5, 0.7])
    q = np.array(model.pack(2))
    rng = np.random.default_rng(12)
    wi, u = _random_hemisphere(rng, 300), rng.random((300, 2))
    wo, pdf = model.sample(wi, u)
    out = np.zeros((1, 2))
    valid = 0
    for k in range(300):
        oz, piece = microfacet.albedo_weight_(DISTRIBUTIONS[name], q, 2, *wi[k], *u[k], out)
        assert oz == pytest.approx(wo[k, 2], abs=1e-12) and piece == (wo[k, 2] > 0.0)
        if piece:
            f = reference_eval(name, wi[k], wo[k], ax, ay, correlated, f0)
            np.testing.assert_allclose(out[0], np.array([0.5, 0.7]) * f * wo[k, 2] / pdf[k],
                                       rtol=1e-9)
            valid += 1
    assert valid > 150


# (theta_i deg, alpha) where the Halley iteration without a bracket once failed in bands of u
# 1e-6 to 5e-6 wide near 1 (e.g. 80 deg, alpha 0.2: u in [0.9980233, 0.9980261]), and the
# grazing incidences 85 and 89 deg
OLD_BANDS = [(80.0, 0.2), (85.0, 0.05), (45.0, 0.5), (55.0, 0.5), (60.0, 0.5), (70.0, 0.5),
             (80.0, 0.1), (75.0, 0.1), (89.0, 0.01), (89.0, 0.2), (85.0, 0.5), (89.0, 1.0)]


@numba.njit(cache=False)
def _slope_sweep(mu, u, halley, x, steps, width):
    for i in range(u.size):
        x[i], steps[i], width[i] = microfacet.beckmann_visible_slope_search(mu, u[i], halley)


def _sweep(mu, u, halley=True):
    x, steps, width = np.empty(u.size), np.empty(u.size, np.int64), np.empty(u.size)
    _slope_sweep(mu, u, halley, x, steps, width)
    return x, steps, width


def _cdf_tail(mu, x):
    """C(mu) - C(x) over C(mu) in closed form with scipy's erfc (digits cancel only for
    1 - u below ~1e-9, which the sweep stays above)."""
    k = 0.5 * math.sqrt(math.pi) * mu
    total = k * special.erfc(-mu) + 0.5 * math.exp(-mu * mu)
    return (k * (special.erfc(x) - special.erfc(mu)) + 0.5 * (math.exp(-mu * mu)
                                                              - np.exp(-x * x))) / total


@pytest.mark.parametrize("theta, alpha", OLD_BANDS)
def test_beckmann_visible_slope_inverts_the_cdf_at_every_u_near_1(theta, alpha):
    """A dense sweep of u in [0.99, 1) at steps of 2e-7, a fifth of the narrowest band the
    unbracketed iteration failed in, and on to 1 - u = 1e-9: every slope solves
    S(x) = (1 - u) C(mu) to 1e-7 of 1 - u, and x rises with u."""
    mu = 1.0 / math.tan(math.radians(theta)) / alpha
    u = np.concatenate([0.99 + 2e-7 * np.arange(49_999), 1.0 - np.geomspace(1e-8, 1e-9, 20)])
    x, steps, _ = _sweep(mu, u)
    tail = _cdf_tail(mu, x)
    worst = np.max(np.abs(tail - (1.0 - u)) / (1.0 - u))
    assert worst < 1e-7, (theta, alpha, worst, u[np.argmax(np.abs(tail - (1.0 - u)) / (1.0 - u))])
    assert np.all(np.diff(x) >= -1e-12), (theta, alpha)
    assert steps.max() <= 12, steps.max()


def _slope_grid():
    mu = np.concatenate([[0.0, 1e-9, 1e-4], np.geomspace(1e-3, 1e6, 120)])
    k = np.arange(1, 17)
    u = np.unique(np.concatenate([np.linspace(0.0, 1.0, 801)[:-1], 10.0 ** -k, 1.0 - 10.0 ** -k,
                                  [2.0 ** -54, 1.0 - 2.0 ** -53]]))
    return mu, u


def test_beckmann_visible_slope_search_ends_converged():
    """Over mu from 0 to 1e6 and u down to 1e-16 of either end, the search ends on a Halley
    step below 1e-4 of the scale of x or on a bracket below SLOPE_TOL, never on its cap; and
    pure bisection, the worst case the cap is sized for, reaches SLOPE_TOL within
    log2((SLOPE_HI - SLOPE_LO) / SLOPE_TOL) + 1 evaluations and lands on the same slope (for
    1 - u >= 1e-12: closer to 1, S(x) has too few digits to steer a bisection that far)."""
    mu_grid, u = _slope_grid()
    worst = 0
    for mu in mu_grid:
        x, steps, width = _sweep(mu, u)
        worst = max(worst, steps.max())
        xb, steps_b, width_b = _sweep(mu, u, halley=False)
        assert np.all(width_b <= microfacet.SLOPE_TOL), mu
        span = microfacet.SLOPE_HI - microfacet.SLOPE_LO
        assert steps_b.max() <= math.ceil(math.log2(span / microfacet.SLOPE_TOL)) + 1
        # 1e-9 of the scale of x: Halley's stop leaves errors ~1e-12, the bisection 4.5e-13
        body = u <= 1.0 - 1e-12
        np.testing.assert_allclose(x[body], xb[body], rtol=0.0, atol=1e-9, err_msg=mu)
    assert worst < microfacet.MAX_STEPS
    assert worst <= 30, worst  # measured: 22, in u within 1e-14 of 1 where S has no digits


def test_beckmann_visible_slope_cap_follows_from_halving():
    """MAX_STEPS evaluations halve the initial bracket 44 times (at least once in every three)
    and 44 halvings bring it below SLOPE_TOL."""
    span = microfacet.SLOPE_HI - microfacet.SLOPE_LO
    halvings = (microfacet.MAX_STEPS - 1) // 3
    assert span * 2.0 ** -halvings <= microfacet.SLOPE_TOL


@pytest.mark.parametrize("mu", [0.0, 1e-3, 0.5, 2.0, 7.0, 8.0, 100.0, 1e6])
def test_beckmann_visible_slope_bracket_holds_every_root(mu):
    """C(SLOPE_LO) < 2^-54 C(mu), the smallest u the search takes, and C(mu) - C(SLOPE_HI) <
    2^-53 C(mu), the smallest 1 - u of a double u < 1, with scipy's erfc and quad."""
    k = 0.5 * math.sqrt(math.pi) * mu
    total = k * special.erfc(-mu) + 0.5 * math.exp(-mu * mu)
    lo = microfacet.SLOPE_LO
    assert k * special.erfc(-lo) + 0.5 * math.exp(-lo * lo) < 2.0 ** -54 * total
    if mu > microfacet.SLOPE_HI:
        hi = microfacet.SLOPE_HI
        tail = integrate.quad(lambda t: (mu - t) * math.exp(-t * t), hi, min(mu, hi + 12.0),
                              epsabs=0.0, epsrel=1e-10)[0]
        assert tail < 2.0 ** -53 * total
