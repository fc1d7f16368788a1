"""Phong (1975, as a BRDF) and modified Phong (Lafortune & Willems 1994) lobes.

Oracles: closed-form values of the definitions, scipy quadrature in plain spherical coordinates
(independent of the lobe-warped quadrature that ``Model.albedo`` uses), the analytic albedo of
the modified lobe at normal incidence (= ks) and the analytic mean of cos(alpha) under the
cos^n sampling density.
"""

import math

import numpy as np
import pytest
from scipy import integrate, special

import brdf
from brdf.errors import SpecError
from brdf.geometry import spherical_to_cartesian
from brdf.models import ModifiedPhong, Phong
from brdf.models import phong as phong_module
from lobes import upper_directions

Z = np.array([0.0, 0.0, 1.0])


def hemisphere_grid(order=384):
    """Directions and solid-angle weights of a Gauss-Legendre product rule in (theta, phi)."""
    x, w = special.roots_legendre(order)
    theta, wt = 0.25 * math.pi * (x + 1.0), 0.25 * math.pi * w
    phi, wp = math.pi * (x + 1.0), math.pi * w
    t, p = np.meshgrid(theta, phi, indexing="ij")
    return spherical_to_cartesian(t, p), np.outer(wt * np.sin(theta), wp)


def definition(wi, wo, ks, n, original):
    """The two Phong BRDFs written out from their papers, in numpy."""
    mirror = wi * np.array([-1.0, -1.0, 1.0])
    cos_a = np.clip(np.sum(mirror * wo, -1), 0.0, None)
    lobe = np.where(cos_a > 0.0, cos_a ** n, 0.0)
    scale = 1.0 / wi[..., 2] if original else (n + 2.0) / (2.0 * math.pi)
    above = (wi[..., 2] > 0.0) & (wo[..., 2] > 0.0)
    return np.where(above, scale * lobe, 0.0)[..., None] * np.asarray(ks)


@pytest.mark.parametrize("spec", ["phong(ks=[0.2,0.3,0.45], n=35.5)", "phong(ks=3, n=0)",
                                  "modified-phong(ks=0.7, n=3)",
                                  "modified-phong(ks=[1,0.5,0], n=10000)"])
def test_spec_round_trip(spec):
    m = brdf.parse(spec)
    assert brdf.parse(str(m)) == m
    assert brdf.from_dict(m.to_dict()) == m


def test_declarations():
    assert (Phong.reciprocal, Phong.energy_conserving) == (False, False)
    assert (ModifiedPhong.reciprocal, ModifiedPhong.energy_conserving) == (True, True)
    n = Phong.declaration("n")
    assert (n.bounds, n.fit_bounds, n.prior) == ((0.0, math.inf), (1.0, 1e4), "log")
    assert Phong.declaration("ks").fit_bounds == (0.0, 1.0)
    assert brdf.parse("phong(ks=5)")["ks"] == 5.0  # the original lobe has no upper bound on ks
    with pytest.raises(SpecError, match="bounds"):
        brdf.parse("modified-phong(ks=1.5)")
    with pytest.raises(SpecError, match="bounds"):
        brdf.parse("phong(n=-1)")


@pytest.mark.parametrize("original", [True, False])
def test_eval_matches_definition_and_is_non_negative(original):
    rng = np.random.default_rng(1)
    wi = rng.normal(size=(4000, 3))
    wo = rng.normal(size=(4000, 3))
    wi /= np.linalg.norm(wi, axis=-1, keepdims=True)
    wo /= np.linalg.norm(wo, axis=-1, keepdims=True)
    ks, n = [0.3, 0.6, 0.9], 7.5
    m = (Phong if original else ModifiedPhong)(ks=ks, n=n)
    f = m.eval(wi, wo)
    assert f.shape == (4000, 3)
    assert np.all(f >= 0.0)
    below = (wi[:, 2] <= 0.0) | (wo[:, 2] <= 0.0)
    assert np.all(f[below] == 0.0) and np.any(f[~below] > 0.0)
    np.testing.assert_allclose(f, definition(wi, wo, ks, n, original), rtol=1e-12, atol=0)


def test_phong_is_not_reciprocal():
    wi = spherical_to_cartesian(np.radians(20.0), 0.0)
    wo = spherical_to_cartesian(np.radians(60.0), math.pi)  # 40 degrees from the mirror of wi
    m = Phong(ks=1.0, n=2.0)
    forward, backward = float(m.eval(wi, wo)[0]), float(m.eval(wo, wi)[0])
    lobe = math.cos(math.radians(40.0)) ** 2
    assert forward == pytest.approx(lobe / math.cos(math.radians(20.0)), rel=1e-12)
    assert backward == pytest.approx(lobe / math.cos(math.radians(60.0)), rel=1e-12)
    assert backward > 1.8 * forward


def test_modified_phong_is_reciprocal():
    rng = np.random.default_rng(2)
    wi, wo = upper_directions(rng, 2000), upper_directions(rng, 2000)
    m = ModifiedPhong(ks=[0.2, 0.9], n=4.0)
    np.testing.assert_allclose(m.eval(wi, wo), m.eval(wo, wi), rtol=1e-12, atol=0)


@pytest.mark.parametrize("n", [0.0, 1.0, 20.0, 500.0])
def test_modified_phong_albedo_at_normal_incidence_is_ks(n):
    ks = np.array([0.25, 0.6, 1.0])
    a = ModifiedPhong(ks=ks, n=n).albedo(Z, tol=1e-7)
    np.testing.assert_allclose(a, ks, rtol=0, atol=1e-6)


@pytest.mark.parametrize("n", [0.0, 2.5, 40.0])
def test_normalisation_constant_by_scipy(n):
    """2 pi times the integral of the model's f cos(theta_o) at normal incidence is ks (modified)
    and 2 pi ks / (n + 2) (original, as Phong 1975 reflects that much of the irradiance)."""
    for original, expected in ((False, 0.8), (True, 0.8 * 2.0 * math.pi / (n + 2.0))):
        m = (Phong if original else ModifiedPhong)(ks=0.8, n=n)

        def integrand(t, m=m):
            return float(m.eval(Z, spherical_to_cartesian(t, 0.3))[0]) * math.cos(t) * math.sin(t)

        value, _ = integrate.quad(integrand, 0.0, math.pi / 2, epsabs=1e-12, epsrel=1e-10)
        assert 2.0 * math.pi * value == pytest.approx(expected, rel=1e-8)


@pytest.mark.parametrize("theta_deg", [0.0, 35.0, 70.0])
@pytest.mark.parametrize("original", [True, False])
def test_albedo_agrees_with_spherical_quadrature(theta_deg, original):
    wi = spherical_to_cartesian(np.radians(theta_deg), 0.4)
    m = (Phong if original else ModifiedPhong)(ks=0.9, n=12.0)
    wo, w = hemisphere_grid()
    reference = np.sum(m.eval(wi, wo)[..., 0] * wo[..., 2] * w)
    assert float(m.albedo(wi)[0]) == pytest.approx(reference, rel=1e-5)


def test_modified_phong_albedo_is_largest_at_normal_incidence():
    theta = np.radians(np.linspace(0.0, 89.0, 30))
    wi = spherical_to_cartesian(theta, 0.0)
    for n in (0.5, 5.0, 100.0):
        a, err = ModifiedPhong(ks=1.0, n=n).albedo(wi, return_error=True)
        assert np.all(a - err <= 1.0)
        assert np.all(np.diff(a[:, 0]) <= 1e-9)  # falls as the lobe sinks below the horizon


@pytest.mark.parametrize("theta_deg, n, expected", [(0.0, 60.0, "one"), (30.0, 300.0, "one"),
                                                    (60.0, 3.0, "less"), (85.0, 20.0, "less")])
def test_pdf_integrates_to_at_most_one(theta_deg, n, expected):
    wi = spherical_to_cartesian(np.radians(theta_deg), 1.0)
    wo, w = hemisphere_grid()
    total = np.sum(Phong(n=n).pdf(wi, wo) * w)
    if expected == "one":
        assert total == pytest.approx(1.0, abs=1e-6)
    else:
        assert 0.3 < total < 0.99  # the part of the lobe below the horizon is rejected


@pytest.mark.parametrize("n", [0.0, 3.0, 150.0])
def test_sample_returns_its_pdf(n):
    rng = np.random.default_rng(3)
    wi = upper_directions(rng, 5000)
    u = rng.random((5000, 2))
    m = ModifiedPhong(ks=0.5, n=n)
    wo, pdf = m.sample(wi, u)
    np.testing.assert_allclose(np.linalg.norm(wo, axis=-1), 1.0, atol=1e-12)
    valid = pdf > 0.0
    assert valid.sum() > 1000
    assert np.all(wo[~valid, 2] <= 0.0)
    np.testing.assert_allclose(m.pdf(wi, wo)[valid], pdf[valid], rtol=1e-9)
    assert np.all(m.pdf(wi[~valid], wo[~valid]) == 0.0)
    mirror = wi * np.array([-1.0, -1.0, 1.0])
    cos_a = np.sum(wo * mirror, -1)
    np.testing.assert_allclose(pdf[valid], (n + 1) / (2 * math.pi) * cos_a[valid] ** n, rtol=1e-9)


def test_samples_follow_cosine_power_about_the_mirror_direction():
    """E[cos(alpha)] = (n + 1) / (n + 2) under the density (n + 1) / (2 pi) cos^n(alpha)."""
    n = 9.0
    rng = np.random.default_rng(4)
    wi = spherical_to_cartesian(np.radians(25.0), 2.0)
    wo, _ = Phong(n=n).sample(wi, rng.random((200_000, 2)))  # rejected samples count too
    cos_a = wo @ (wi * np.array([-1.0, -1.0, 1.0]))
    assert cos_a.mean() == pytest.approx((n + 1) / (n + 2), abs=4 * cos_a.std() / math.sqrt(2e5))


def test_below_the_horizon_is_empty():
    wi = np.array([0.3, 0.0, -0.9539392014169456])
    for m in (Phong(), ModifiedPhong()):
        assert np.all(m.eval(wi, Z) == 0.0) and m.pdf(wi, Z) == 0.0
        assert m.sample(wi, [0.5, 0.5])[1] == 0.0
        assert m.pdf(Z, -Z) == 0.0


@pytest.mark.parametrize("original", [True, False])
def test_hint_is_the_albedo_at_normal_incidence(original):
    m = (Phong if original else ModifiedPhong)(ks=[0.2, 0.4, 0.9], n=30.0)
    form = phong_module.ORIGINAL if original else phong_module.MODIFIED
    hint = phong_module.hint_(form, np.asarray(m.pack(3)), 3, 0.0, 0.0, 1.0)
    assert hint == pytest.approx(float(m.albedo(Z).mean()), rel=1e-5)
