"""Blinn-Phong lobe with the exact (Giesen 2009) and approximate ((n+8)/(8 pi)) normalisations.

Oracles: the definition written out in numpy, scipy quadrature of the model's own ``eval`` and
``pdf`` in plain spherical coordinates (adaptive ``scipy.integrate.cubature`` and ``quad``, not
the half-vector warp that ``Model.albedo`` integrates over), and the analytic mean of
cos(theta_h) under the cos^n half-vector density.
"""

import math

import numpy as np
import pytest
from scipy import integrate

import brdf
from brdf.geometry import spherical_to_cartesian
from brdf.models import BlinnPhong
from brdf.models import blinn_phong as blinn_module
from lobes import upper_directions

Z = np.array([0.0, 0.0, 1.0])


def hemisphere_integral(fn, rtol=1e-8):
    """Integral of ``fn(wo)`` (vectorised over ``(N, 3)``) over the upper hemisphere."""
    def integrand(x):
        return fn(spherical_to_cartesian(x[:, 0], x[:, 1])) * np.sin(x[:, 0])

    res = integrate.cubature(integrand, [0.0, 0.0], [math.pi / 2, 2 * math.pi], rtol=rtol,
                             atol=1e-12)
    assert res.status == "converged"
    return float(res.estimate)


def normal_incidence_albedo(m):
    """2 pi times the scipy integral of f(z, wo) cos(theta_o) sin(theta_o) over theta_o."""
    def integrand(t):
        return float(m.eval(Z, spherical_to_cartesian(t, 0.0))[0]) * math.cos(t) * math.sin(t)

    value, _ = integrate.quad(integrand, 0.0, math.pi / 2, epsabs=1e-13, epsrel=1e-11)
    return 2.0 * math.pi * value


@pytest.mark.parametrize("spec", ["blinn-phong(ks=[0.1,0.2,0.3], n=12.5)",
                                  "blinn-phong(ks=1, n=0, normalization=approx)",
                                  "blinn-phong(n=4000)"])
def test_spec_round_trip(spec):
    m = brdf.parse(spec)
    assert brdf.parse(str(m)) == m
    assert brdf.from_dict(m.to_dict()) == m


def test_declarations():
    assert BlinnPhong()["normalization"] == "exact"
    assert str(BlinnPhong(n=5)) == "blinn-phong(ks=1, n=5)"  # the default choice is left out
    assert BlinnPhong().energy_conserving and BlinnPhong().reciprocal
    assert not BlinnPhong(normalization="approx").energy_conserving
    assert not (BlinnPhong() + BlinnPhong(normalization="approx")).energy_conserving
    with pytest.raises(brdf.SpecError, match="exact, approx"):
        brdf.parse("blinn-phong(normalization=physical)")


@pytest.mark.parametrize("normalization", ["exact", "approx"])
def test_eval_matches_definition_and_is_non_negative(normalization):
    rng = np.random.default_rng(5)
    wi = rng.normal(size=(4000, 3))
    wo = rng.normal(size=(4000, 3))
    wi /= np.linalg.norm(wi, axis=-1, keepdims=True)
    wo /= np.linalg.norm(wo, axis=-1, keepdims=True)
    n, ks = 6.5, np.array([0.2, 0.7])
    if normalization == "exact":
        norm = (n + 2) * (n + 4) / (8 * math.pi * (2 ** (-n / 2) + n))
    else:
        norm = (n + 8) / (8 * math.pi)
    h = wi + wo
    cos_h = h[:, 2] / np.linalg.norm(h, axis=-1)
    above = (wi[:, 2] > 0) & (wo[:, 2] > 0)
    expected = np.where(above, norm * np.abs(cos_h) ** n, 0.0)[:, None] * ks
    f = BlinnPhong(ks=ks, n=n, normalization=normalization).eval(wi, wo)
    assert np.all(f >= 0.0) and np.all(f[~above] == 0.0)
    np.testing.assert_allclose(f, expected, rtol=1e-12, atol=0)


def test_reciprocal():
    rng = np.random.default_rng(6)
    wi, wo = upper_directions(rng, 2000), upper_directions(rng, 2000)
    for normalization in ("exact", "approx"):
        m = BlinnPhong(ks=[0.5, 1.0], n=17.0, normalization=normalization)
        np.testing.assert_allclose(m.eval(wi, wo), m.eval(wo, wi), rtol=1e-12, atol=0)


@pytest.mark.parametrize("n", [0.0, 1.0, 10.0, 64.5, 1000.0])
def test_exact_normalisation_by_scipy(n):
    m = BlinnPhong(ks=1.0, n=n)
    assert normal_incidence_albedo(m) == pytest.approx(1.0, rel=1e-8)
    assert float(m.albedo(Z, tol=1e-7)[0]) == pytest.approx(1.0, abs=1e-6)


def test_approx_normalisation_overshoots_at_n_10():
    m = BlinnPhong(ks=1.0, n=10.0, normalization="approx")
    reference = normal_incidence_albedo(m)
    assert reference == pytest.approx(1.075, abs=1e-3) and reference > 1.07
    assert float(m.albedo(Z, tol=1e-7)[0]) == pytest.approx(reference, rel=1e-6)


@pytest.mark.parametrize("theta_deg", [30.0, 75.0])
@pytest.mark.parametrize("normalization", ["exact", "approx"])
def test_albedo_agrees_with_scipy_at_oblique_incidence(theta_deg, normalization):
    wi = spherical_to_cartesian(np.radians(theta_deg), -0.7)
    m = BlinnPhong(ks=1.0, n=8.0, normalization=normalization)
    reference = hemisphere_integral(lambda wo: m.eval(wi, wo)[:, 0] * wo[:, 2])
    assert float(m.albedo(wi)[0]) == pytest.approx(reference, rel=1e-4)


def test_exact_albedo_never_exceeds_ks():
    wi = spherical_to_cartesian(np.radians(np.linspace(0.0, 89.0, 30)), 0.0)
    for n in (0.5, 4.0, 40.0, 400.0):
        a, err = BlinnPhong(ks=1.0, n=n).albedo(wi, return_error=True)
        assert np.all(a - err <= 1.0)


@pytest.mark.parametrize("theta_deg, n, expected", [(0.0, 200.0, "one"), (20.0, 500.0, "one"),
                                                    (0.0, 2.0, "less"), (70.0, 10.0, "less")])
def test_pdf_integrates_to_at_most_one(theta_deg, n, expected):
    wi = spherical_to_cartesian(np.radians(theta_deg), 0.5)
    m = BlinnPhong(n=n)
    total = hemisphere_integral(lambda wo: m.pdf(wi, wo), rtol=1e-7)
    if expected == "one":
        assert total == pytest.approx(1.0, abs=1e-5)
    else:
        assert 0.3 < total < 0.99  # half vectors that reflect wi below the horizon are rejected


@pytest.mark.parametrize("n", [0.0, 5.0, 300.0])
def test_sample_returns_its_pdf(n):
    rng = np.random.default_rng(7)
    wi = upper_directions(rng, 5000)
    m = BlinnPhong(ks=0.5, n=n, normalization="approx")
    wo, pdf = m.sample(wi, rng.random((5000, 2)))
    np.testing.assert_allclose(np.linalg.norm(wo, axis=-1), 1.0, atol=1e-12)
    valid = pdf > 0.0
    assert valid.sum() > 1000
    assert np.all(wo[~valid, 2] <= 0.0)
    np.testing.assert_allclose(m.pdf(wi, wo)[valid], pdf[valid], rtol=1e-9)
    assert np.all(m.pdf(wi[~valid], wo[~valid]) == 0.0)


def test_half_vectors_follow_cosine_power():
    """E[cos(theta_h)] = (n + 1) / (n + 2) under (n + 1) / (2 pi) cos^n(theta_h)."""
    n = 30.0
    rng = np.random.default_rng(8)
    wi = spherical_to_cartesian(np.radians(40.0), 1.0)
    wo, _ = BlinnPhong(n=n).sample(wi, rng.random((200_000, 2)))
    h = wi + wo
    cos_h = h[:, 2] / np.linalg.norm(h, axis=-1)
    assert cos_h.mean() == pytest.approx((n + 1) / (n + 2), abs=4 * cos_h.std() / math.sqrt(2e5))


def test_below_the_horizon_is_empty():
    wi = np.array([0.6, 0.0, -0.8])
    m = BlinnPhong()
    assert np.all(m.eval(wi, Z) == 0.0) and m.pdf(wi, Z) == 0.0 and m.pdf(Z, wi) == 0.0
    assert m.sample(wi, [0.5, 0.5])[1] == 0.0


@pytest.mark.parametrize("normalization", ["exact", "approx"])
def test_hint_is_the_albedo_at_normal_incidence(normalization):
    m = BlinnPhong(ks=[0.3, 0.9], n=10.0, normalization=normalization)
    hint = blinn_module.hint_(np.asarray(m.pack(2)), 2, 0.0, 0.0, 1.0)
    assert hint == pytest.approx(float(m.albedo(Z, tol=1e-7).mean()), rel=1e-6)
