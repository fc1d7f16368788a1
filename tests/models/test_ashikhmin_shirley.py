"""Ashikhmin & Shirley 2000, "An Anisotropic Phong BRDF Model" (JGT 5(2)).

Oracles: the specular (eq. 4) and diffuse (eq. 5) terms written out in numpy from the paper in
their angle form (phi_h from atan2, the exponent nu cos^2 + nv sin^2); scipy integration of the
half-vector density of eq. 8; eqs. 9-10 in the first quadrant against the sampler; adaptive
quadrature of f cos and of the pdf over the hemisphere (tests/chi2.py ``integrate_cells``); the
share of valid samples as the pdf's integral; a Monte Carlo albedo, unbiased only if ``sample``
follows ``pdf``; reciprocity by swapping; and the 90-degree rotation that swaps nu and nv.

Energy: the specular albedo is at most 1 (f_s cos(theta_o) = F p(wo) cos(theta_o) / max(cos_i,
cos_o) <= p(wo), p the sampling density of eq. 8 / 4 (k.h)), the diffuse albedo is exactly
rd (1 - rs) (1 - (1 - cos_i / 2)^5), and the albedo is linear in rd and in rs; the scans below
find its largest value 0.9996 (rs = 1, nu = nv = 1e4, normal incidence), so the family conserves
energy for all rd, rs in [0, 1], not only for rd + rs <= 1.
"""

import math

import numpy as np
import pytest
from scipy import integrate

import brdf
from brdf.errors import SpecError
from brdf.models import AshikhminShirley
from brdf.models import ashikhmin_shirley as as_module
from brdf.sampling import square_to_cosine_hemisphere
from lobes import (assert_monte_carlo_albedo, assert_valid_share_matches_pdf,
                   hemisphere_integral, incident)


def unit(rng, n, upper=True):
    v = rng.normal(size=(n, 3))
    if upper:
        v[:, 2] = np.abs(v[:, 2]) + 1e-3
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def specular(wi, wo, rs, nu, nv):
    """Eq. 4 with Schlick's F = rs + (1 - rs)(1 - k.h)^5, shaped (m, C) for rs shaped (C,)."""
    wi, wo = np.broadcast_arrays(np.atleast_2d(wi), np.atleast_2d(wo))
    h = wi + wo
    h = h / np.linalg.norm(h, axis=-1, keepdims=True)
    phi = np.arctan2(h[:, 1], h[:, 0])
    e = nu * np.cos(phi) ** 2 + nv * np.sin(phi) ** 2
    kh = np.sum(wi * h, -1)
    ci, co = wi[:, 2], wo[:, 2]
    with np.errstate(invalid="ignore", divide="ignore"):
        lobe = math.sqrt((nu + 1) * (nv + 1)) / (8 * math.pi) * h[:, 2] ** e \
            / (kh * np.maximum(ci, co))
    fresnel = rs + (1 - rs) * (1 - kh[:, None]) ** 5
    return np.where(((ci > 0) & (co > 0))[:, None], lobe[:, None] * fresnel, 0.0)


def diffuse(wi, wo, rd, rs):
    """Eq. 5, shaped (m, C) for rd, rs shaped (C,)."""
    ci, co = np.atleast_2d(wi)[:, 2:], np.atleast_2d(wo)[:, 2:]
    f = 28 * rd / (23 * math.pi) * (1 - rs) * (1 - (1 - ci / 2) ** 5) * (1 - (1 - co / 2) ** 5)
    return np.where((ci > 0) & (co > 0), f, 0.0)


# --- declarations and specs -------------------------------------------------------------------

@pytest.mark.parametrize("spec", ["ashikhmin-shirley", "ashikhmin-shirley(nu=10, nv=1000)",
                                  "ashikhmin-shirley(rd=[0.5,0.4,0.3], rs=[0.04,0.05,0.06], "
                                  "nu=250.5)",
                                  "ashikhmin-shirley(rd=0, rs=1, nu=0, nv=0)"])
def test_spec_round_trip(spec):
    m = brdf.parse(spec)
    assert brdf.parse(str(m)) == m
    assert brdf.from_dict(m.to_dict()) == m


def test_declarations():
    m = brdf.parse("ashikhmin")
    assert str(m) == "ashikhmin-shirley(rd=0.5, rs=0.05, nu=100)"
    assert m.reciprocal and m.energy_conserving and not m.is_anisotropic
    assert brdf.parse("ashikhmin-shirley(nu=10, nv=100)").is_anisotropic
    assert not brdf.parse("ashikhmin-shirley(nu=10, nv=10)").is_anisotropic
    for name in ("rd", "rs"):
        d = AshikhminShirley.declaration(name)
        assert d.per_channel and d.bounds == (0.0, 1.0)
    for name in ("nu", "nv"):
        d = AshikhminShirley.declaration(name)
        assert not d.per_channel and d.prior == "log"
        assert d.bounds == (0.0, 1e5) and d.fit_bounds == (1.0, 1e4)
    # kernel layout: rd[C], rs[C], nu, nv (nv falls back to nu)
    assert brdf.parse("ashikhmin-shirley(rd=[0.1,0.2], rs=0.3, nu=7)").pack(2) == \
        [0.1, 0.2, 0.3, 0.3, 7.0, 7.0]
    with pytest.raises(SpecError, match="bounds"):
        brdf.parse("ashikhmin-shirley(rs=1.5)")


# --- eval -------------------------------------------------------------------------------------

PARAMS = dict(rd=np.array([0.7, 0.4, 0.1]), rs=np.array([0.05, 0.3, 0.9]), nu=40.0, nv=400.0)


def test_specular_term_matches_eq_4():
    m = AshikhminShirley(rd=0.0, rs=PARAMS["rs"], nu=PARAMS["nu"], nv=PARAMS["nv"])
    rng = np.random.default_rng(1)
    wi, wo = unit(rng, 20000, upper=False), unit(rng, 20000, upper=False)
    expected = specular(wi, wo, PARAMS["rs"], PARAMS["nu"], PARAMS["nv"])
    np.testing.assert_allclose(m.eval(wi, wo), expected, rtol=1e-10, atol=1e-300)
    assert np.count_nonzero(expected[:, 0] > 0.01) > 200  # the points see the lobe


def test_diffuse_term_matches_eq_5():
    """The diffuse term is what rd adds (the specular term does not depend on rd)."""
    m = AshikhminShirley(**PARAMS)
    no_diffuse = m.replace(rd=0.0)
    rng = np.random.default_rng(2)
    wi, wo = unit(rng, 20000, upper=False), unit(rng, 20000, upper=False)
    expected = diffuse(wi, wo, PARAMS["rd"], PARAMS["rs"])
    np.testing.assert_allclose(m.eval(wi, wo) - no_diffuse.eval(wi, wo), expected,
                               rtol=1e-9, atol=1e-12)
    assert np.count_nonzero(expected[:, 0]) > 4000


def test_value_by_hand_at_the_mirror_configuration():
    """theta_i = theta_o = 60 deg in the plane of incidence: h = n, k.h = 1/2 and
    F = rs + (1 - rs) / 32."""
    m = brdf.parse("ashikhmin-shirley(rd=0.5, rs=0.1, nu=30, nv=70)")
    wi = incident(60.0)
    wo = wi * [-1.0, 1.0, 1.0]
    spec = math.sqrt(31 * 71) / (8 * math.pi) / (0.5 * 0.5) * (0.1 + 0.9 / 32)
    diff = 28 * 0.5 / (23 * math.pi) * 0.9 * (1 - 0.75 ** 5) ** 2
    assert m.eval(wi, wo)[0] == pytest.approx(spec + diff, rel=1e-12)


def test_non_negative_and_reciprocal():
    m = AshikhminShirley(**PARAMS)
    rng = np.random.default_rng(3)
    wi, wo = unit(rng, 50000, upper=False), unit(rng, 50000, upper=False)
    f = m.eval(wi, wo)
    assert np.all(np.isfinite(f)) and np.all(f >= 0.0)
    assert np.all(np.count_nonzero(f, axis=0) > 10000)
    np.testing.assert_allclose(m.eval(wo, wi), f, rtol=1e-12, atol=0.0)


def test_rotation_by_90_degrees_swaps_exponents():
    a = brdf.parse("ashikhmin-shirley(nu=10, nv=300)")
    b = brdf.parse("ashikhmin-shirley(nu=300, nv=10)")
    rng = np.random.default_rng(4)
    wi, wo = unit(rng, 5000), unit(rng, 5000)

    def turn(v):  # 90 degrees about z: (x, y) -> (-y, x)
        return np.stack([-v[:, 1], v[:, 0], v[:, 2]], -1)

    np.testing.assert_allclose(a.eval(turn(wi), turn(wo)), b.eval(wi, wo), rtol=1e-10)
    assert not np.allclose(a.eval(wi, wo), b.eval(wi, wo))


def test_below_the_horizon_is_zero():
    m = brdf.parse("ashikhmin-shirley(nu=5)")
    up, down = incident(30.0), incident(150.0)
    assert np.all(m.eval(up, down) == 0.0) and np.all(m.eval(down, up) == 0.0)
    assert m.pdf(up, down) == 0.0 and m.pdf(down, up) == 0.0
    assert m.sample(down, np.array([0.3, 0.6]))[1] == 0.0


# --- the half-vector density and its sampler ----------------------------------------------

@pytest.mark.parametrize("nu, nv", [(0.0, 0.0), (10.0, 10.0), (1.0, 1000.0), (100.0, 5.0)])
def test_half_vector_density_integrates_to_one(nu, nv):
    """Eq. 8 over the hemisphere of half vectors, in (cos theta_h, phi_h)."""
    def integrand(mu, phi):
        s = math.sqrt(1.0 - mu * mu)
        return as_module.half_pdf(nu, nv, s * math.cos(phi), s * math.sin(phi), mu)

    total, _ = integrate.dblquad(integrand, 0.0, 2.0 * math.pi, 0.0, 1.0,
                                 epsabs=1e-10, epsrel=1e-10)
    assert total == pytest.approx(1.0, abs=1e-8)


@pytest.mark.parametrize("nu, nv", [(10.0, 10.0), (1.0, 1000.0), (300.0, 20.0)])
def test_half_vector_sampler_is_eqs_9_and_10(nu, nv):
    """In the first quadrant (u1 < 1/4) phi is eq. 9 with xi1 = 4 u1, cos(theta) eq. 10; the
    other quadrants mirror it (phi -> pi - phi, pi + phi, 2 pi - phi)."""
    rng = np.random.default_rng(5)
    for xi1, xi2 in rng.random((200, 2)):
        phi = math.atan(math.sqrt((nu + 1) / (nv + 1)) * math.tan(math.pi * xi1 / 2))
        cos_t = (1 - xi2) ** (1 / (nu * math.cos(phi) ** 2 + nv * math.sin(phi) ** 2 + 1))
        sin_t = math.sqrt(1 - cos_t ** 2)
        for quadrant, (sx, sy) in enumerate([(1, 1), (-1, 1), (-1, -1), (1, -1)]):
            xi = xi1 if quadrant % 2 == 0 else 1 - xi1
            h = as_module.sample_half(nu, nv, (quadrant + xi) / 4, xi2)
            expected = (sx * sin_t * math.cos(phi), sy * sin_t * math.sin(phi), cos_t)
            np.testing.assert_allclose(h, expected, atol=1e-12)


# --- sampling of the lobe -------------------------------------------------------------------

@pytest.mark.parametrize("spec", ["ashikhmin-shirley(rd=[0.7,0.4,0.1], rs=[0.05,0.3,0.9], "
                                  "nu=40, nv=400)",
                                  "ashikhmin-shirley(rd=0, rs=0.5, nu=1000)",
                                  "ashikhmin-shirley(rd=0.8, rs=0, nu=2, nv=0.5)",
                                  "ashikhmin-shirley(rd=0.4, rs=0.1, nu=50, nv=5) "
                                  "+ ggx(alpha=0.6)"])
def test_sample_pdf_and_eval_agree(spec):
    m = brdf.parse(spec)
    rng = np.random.default_rng(6)
    wi = unit(rng, 20000)
    u = rng.random((20000, 2))
    wo, pdf, weight = m.sample_weighted(wi, u)
    valid = pdf > 0.0
    assert 0.5 < valid.mean() <= 1.0
    assert np.all(wo[~valid, 2] <= 0.0) and np.all(wo[valid, 2] > 0.0)
    np.testing.assert_allclose(np.linalg.norm(wo, axis=-1), 1.0, atol=1e-12)
    np.testing.assert_allclose(m.pdf(wi[valid], wo[valid]), pdf[valid], rtol=1e-10)
    expected = m.eval(wi[valid], wo[valid]) * (wo[valid, 2] / pdf[valid])[:, None]
    np.testing.assert_allclose(weight[valid], expected, rtol=1e-10)


@pytest.mark.parametrize("spec, theta", [("ashikhmin-shirley(rd=0.5, rs=0.2, nu=30)", 0.0),
                                         ("ashikhmin-shirley(rd=0, rs=0.9, nu=3, nv=60)", 70.0),
                                         ("ashikhmin-shirley(rd=0.3, rs=0.3, nu=1)", 85.0)])
def test_pdf_integrates_to_the_share_of_valid_samples(spec, theta):
    assert assert_valid_share_matches_pdf(brdf.parse(spec), incident(theta, 25.0), seed=7) > 0.5


def test_monte_carlo_albedo_matches_quadrature():
    assert_monte_carlo_albedo(brdf.parse("ashikhmin-shirley(rd=0.6, rs=0.2, nu=20, nv=120)"),
                              incident(50.0, 35.0), seed=8)


# --- energy -----------------------------------------------------------------------------------

@pytest.mark.parametrize("theta", [0.0, 40.0, 75.0, 89.0])
def test_diffuse_albedo_closed_form(theta):
    """The integral of eq. 5 times cos(theta_o) is rd (1 - rs) (1 - (1 - cos_i / 2)^5); the
    sampler's weights use it."""
    wi = incident(theta)
    exact = 0.6 * 0.7 * (1 - (1 - wi[2] / 2) ** 5)
    assert hemisphere_integral(lambda wo: diffuse(wi, wo, 0.6, 0.3)[:, 0] * wo[:, 2]) == \
        pytest.approx(exact, rel=1e-7)
    q = np.array(brdf.parse("ashikhmin-shirley(rd=0.6, rs=0.3)").pack(1))
    assert as_module.albedo_parts(q, 1, wi[2])[1] == pytest.approx(exact, rel=1e-12)


@pytest.mark.parametrize("spec, theta", [("ashikhmin-shirley(rd=0.5, rs=0.2, nu=30)", 0.0),
                                         ("ashikhmin-shirley(rd=0.5, rs=0.2, nu=30)", 80.0),
                                         ("ashikhmin-shirley(rd=0.2, rs=0.6, nu=8, nv=90)", 60.0),
                                         ("ashikhmin-shirley(rd=0, rs=1, nu=100)", 45.0)])
def test_albedo_matches_adaptive_quadrature(spec, theta):
    """Within the cubature's own error estimate (the horizon cut at grazing incidence makes it
    larger there)."""
    m = brdf.parse(spec)
    wi = incident(theta, 15.0)
    rd, rs, nu, nv = m.pack(1)
    exact = hemisphere_integral(lambda wo: (specular(wi, wo, rs, nu, nv)
                                            + diffuse(wi, wo, rd, rs))[:, 0] * wo[:, 2])
    albedo, error = m.albedo(wi, return_error=True)
    error = np.max(error)  # one incident direction, one channel
    assert abs(albedo[0] - exact) <= error + 1e-7 and error < 1e-3


THETAS = [0.0, 15.0, 30.0, 45.0, 60.0, 70.0, 80.0, 85.0, 88.0, 89.9]


def half_density(h, nu, nv):
    """Eq. 8 in its angle form, for unit half vectors h shaped (m, 3)."""
    phi = np.arctan2(h[:, 1], h[:, 0])
    e = nu * np.cos(phi) ** 2 + nv * np.sin(phi) ** 2
    return math.sqrt((nu + 1) * (nv + 1)) / (2 * math.pi) * h[:, 2] ** e


def test_albedo_terms_are_f_cos_over_their_own_pdf():
    """The albedo integrates the two terms apart: the specular term (eq. 4) over h drawn from
    eq. 8 (pdf p_h / 4 k.h after reflection), the diffuse term (eq. 5) over cosine-weighted wo
    (pdf cos / pi); each weight is its term's f cos / pdf, and the specular one says on which
    side of cos_o = cos_i (where eq. 4's max switches) the sample lies."""
    m = AshikhminShirley(**PARAMS)
    q = np.array(m.pack(3))
    rng = np.random.default_rng(11)
    out = np.zeros((1, 3))
    checked = [0, 0, 0]
    for wi, (u1, u2) in zip(unit(rng, 400), rng.random((400, 2))):
        oz, piece = as_module.albedo_weight_(q, 3, 0, *wi, u1, u2, out)
        h = np.array(as_module.sample_half(PARAMS["nu"], PARAMS["nv"], u1, u2))[None]
        kh = float(np.sum(wi * h))
        wo = 2 * kh * h - wi
        assert oz == pytest.approx(wo[0, 2], abs=1e-12)
        if wo[0, 2] <= 0:
            assert piece == 0
            continue
        assert piece == (1 if wo[0, 2] >= wi[2] else 2)
        pdf = half_density(h, PARAMS["nu"], PARAMS["nv"]) / (4 * kh)
        expected = specular(wi, wo, PARAMS["rs"], PARAMS["nu"], PARAMS["nv"]) * wo[0, 2] / pdf
        np.testing.assert_allclose(out, expected, rtol=1e-10)
        checked[piece] += 1
        oz, piece = as_module.albedo_weight_(q, 3, 1, *wi, u1, u2, out)
        wo = np.array(square_to_cosine_hemisphere(u1, u2))[None]
        assert piece == 1 and oz == wo[0, 2]
        expected = diffuse(wi, wo, PARAMS["rd"], PARAMS["rs"]) * math.pi  # cos / (cos / pi)
        np.testing.assert_allclose(out, expected, rtol=1e-12)
    assert min(checked[1:]) > 10  # both pieces of the specular weight were seen


@pytest.mark.parametrize("phi", [0.0, 30.0, 90.0])
def test_grazing_albedo_within_its_error_at_every_azimuth(phi):
    """nu = nv: the lobe is isotropic, so the albedo at 89 degrees is the same at every azimuth,
    while the cut by the horizon (and the seam cos_o = cos_i beside it, a ramp as steep as a
    jump) crosses the sampler's square differently: at 30 degrees it leaves a thin valid strip
    along a panel edge that no node of the panel sees, at 90 degrees it runs along a panel
    edge. The cubature must stay within its own error estimate of the integral here."""
    m = brdf.parse("ashikhmin-shirley(rd=1, rs=0, nu=1)")
    wi = incident(89.0, phi)
    exact = hemisphere_integral(lambda wo: (specular(wi, wo, np.array([0.0]), 1.0, 1.0)
                                            + diffuse(wi, wo, np.array([1.0]),
                                                      np.array([0.0])))[:, 0] * wo[:, 2])
    albedo, error = m.albedo(wi, return_error=True)
    assert abs(albedo[0] - exact) <= error[0] + 1e-7 and error[0] < 3e-3


@pytest.mark.slow
def test_conserves_energy_for_random_parameters():
    """100 random lobes with rd + rs <= 1 per channel, exponents log-uniform in [0.1, 1e4],
    incident directions over theta and phi: every albedo stays below 1 by more than the
    cubature's error."""
    rng = np.random.default_rng(9)
    t, p = np.meshgrid(np.radians(THETAS), np.radians([0.0, 45.0, 90.0]), indexing="ij")
    wi = brdf.geometry.spherical_to_cartesian(t.ravel(), p.ravel())
    worst = 0.0
    for _ in range(100):
        rs = rng.random(3)
        rd = rng.random(3) * (1.0 - rs)
        nu, nv = 10.0 ** rng.uniform(-1.0, 4.0, 2)
        m = AshikhminShirley(rd=rd, rs=rs, nu=nu, nv=nv)
        albedo, error = m.albedo(wi, tol=1e-4, return_error=True)
        worst = max(worst, np.max(albedo + np.reshape(error, (albedo.shape[0], -1))))
    assert 0.9 < worst <= 1.0


@pytest.mark.parametrize("nu, nv", [(0.1, 0.1), (1.0, 1.0), (30.0, 30.0), (1e4, 1e4), (1.0, 1e4)])
def test_worst_corners_conserve_energy(nu, nv):
    """The albedo is linear in rd and rs, so its maximum over [0, 1]^2 lies at rd = 1 and rs = 0
    or rs = 1 (where rd has no effect); both stay below 1 at every incidence, and the check
    agrees."""
    t, p = np.meshgrid(np.radians(THETAS), np.radians([0.0, 60.0]), indexing="ij")
    wi = brdf.geometry.spherical_to_cartesian(t.ravel(), p.ravel())
    m = AshikhminShirley(rd=[1.0, 1.0], rs=[0.0, 1.0], nu=nu, nv=nv)
    albedo, error = m.albedo(wi, return_error=True)
    assert np.all(albedo + np.reshape(error, (albedo.shape[0], -1)) <= 1.0)
    assert brdf.check(m, pairs=2000, theta_steps=30).passed
