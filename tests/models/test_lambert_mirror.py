"""Lambert and the perfect mirror: values, albedo and sampling in closed form."""

import math

import numpy as np
import pytest
from scipy import stats

import brdf
from brdf.models.fresnel import conductor_reflectance, dielectric_reflectance

RHO = [0.8, 0.5, 0.2]


def _unit(theta, phi):
    return np.array([math.sin(theta) * math.cos(phi), math.sin(theta) * math.sin(phi),
                     math.cos(theta)])


def _random_hemisphere(rng, n, sign=1.0):
    z = rng.uniform(1e-3, 1.0, n)
    phi = rng.uniform(0.0, 2.0 * math.pi, n)
    s = np.sqrt(1.0 - z * z)
    return np.stack([s * np.cos(phi), s * np.sin(phi), sign * z], -1)


INCIDENT = np.stack([_unit(math.radians(t), 0.7) for t in (0.0, 30.0, 60.0, 85.0, 89.9)])


# --- Lambert ---------------------------------------------------------------------------------

def test_lambert_value_is_albedo_over_pi():
    rng = np.random.default_rng(1)
    wi, wo = _random_hemisphere(rng, 100), _random_hemisphere(rng, 100)
    f = brdf.parse("lambert(albedo=[0.8,0.5,0.2])").eval(wi, wo)
    np.testing.assert_allclose(f, np.broadcast_to(np.array(RHO) / math.pi, (100, 3)), rtol=1e-15)


def test_lambert_is_zero_below_the_horizon():
    rng = np.random.default_rng(2)
    up, down = _random_hemisphere(rng, 50), _random_hemisphere(rng, 50, sign=-1.0)
    model = brdf.parse("lambert(albedo=0.5)")
    assert not model.eval(up, down).any() and not model.eval(down, up).any()
    assert not model.pdf(up, down).any() and not model.pdf(down, up).any()


def test_lambert_albedo_is_rho_exactly():
    albedo = brdf.parse("lambert(albedo=[0.8,0.5,0.2])").albedo(INCIDENT)
    np.testing.assert_allclose(albedo, np.broadcast_to(RHO, albedo.shape), rtol=1e-12)


def test_lambert_samples_the_cosine_distribution():
    """For cosine-weighted directions cos^2(theta) and phi / (2 pi) are independent uniforms
    (Malley's method: the projection onto the disk is uniform)."""
    model = brdf.parse("lambert(albedo=[0.8,0.5,0.2])")
    u = np.random.default_rng(3).random((200_000, 2))
    wi = _unit(1.0, 2.0)
    wo, pdf, weight = model.sample_weighted(wi, u)
    np.testing.assert_allclose(np.linalg.norm(wo, axis=-1), 1.0, rtol=1e-12)
    np.testing.assert_allclose(pdf, wo[:, 2] / math.pi, rtol=1e-12)
    np.testing.assert_allclose(model.pdf(wi, wo), pdf, rtol=1e-12)
    np.testing.assert_allclose(weight, np.broadcast_to(RHO, weight.shape), rtol=1e-12)
    phi = np.mod(np.arctan2(wo[:, 1], wo[:, 0]), 2 * math.pi) / (2 * math.pi)
    assert stats.kstest(wo[:, 2] ** 2, "uniform").pvalue > 1e-3
    assert stats.kstest(phi, "uniform").pvalue > 1e-3


def test_lambert_sampling_from_below_is_invalid():
    wo, pdf = brdf.parse("lambert").sample(_unit(2.0, 0.0), np.array([[0.3, 0.6]]))
    assert pdf[0] == 0.0


# --- mirror ----------------------------------------------------------------------------------

MIRRORS = {
    "mirror": lambda c: 1.0,
    "mirror(reflectance=0.9, fresnel=dielectric(eta=1.5))":
        lambda c: 0.9 * dielectric_reflectance(c, 1.5),
    "mirror(reflectance=0.7, fresnel=schlick(f0=0.04))":
        lambda c: 0.7 * (0.04 + 0.96 * (1.0 - c) ** 5),  # Schlick 1994, eq. 15
    "mirror(reflectance=[0.9,0.8,0.7], fresnel=conductor(eta=[0.2,0.9,1.1], k=[3.9,2.4,2.2]))":
        lambda c: np.array([r * conductor_reflectance(c, e, k) for r, e, k in
                            zip([0.9, 0.8, 0.7], [0.2, 0.9, 1.1], [3.9, 2.4, 2.2])]),
}


@pytest.mark.parametrize("spec", MIRRORS)
def test_mirror_samples_the_reflection_with_fresnel_weight(spec):
    model = brdf.parse(spec)
    u = np.random.default_rng(4).random((len(INCIDENT), 2))
    wo, pdf, weight = model.sample_weighted(INCIDENT, u)
    np.testing.assert_allclose(wo, INCIDENT * [-1.0, -1.0, 1.0], atol=1e-15)
    assert np.all(np.isinf(pdf))
    expected = np.array([np.broadcast_to(MIRRORS[spec](c), (model.channels,))
                         for c in INCIDENT[:, 2]])
    np.testing.assert_allclose(weight, expected, rtol=1e-12)
    np.testing.assert_allclose(model.albedo(INCIDENT), expected, rtol=1e-12)


def test_mirror_has_no_density():
    rng = np.random.default_rng(5)
    wi = _random_hemisphere(rng, 50)
    model = brdf.parse("mirror(reflectance=0.8)")
    assert not model.eval(wi, wi * [-1.0, -1.0, 1.0]).any()
    assert not model.pdf(wi, wi * [-1.0, -1.0, 1.0]).any()


def test_mirror_from_below_is_invalid():
    wo, pdf = brdf.parse("mirror").sample(_unit(2.0, 0.0), np.array([[0.3, 0.6]]))
    assert pdf[0] == 0.0
