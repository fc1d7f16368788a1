"""Lafortune generalised cosine lobes (Lafortune, Foo, Torrance & Greenberg 1997, eqs. 3-4).

Oracles: the lobe written out in numpy from the paper; the default lobe as cos^n of the angle to
the mirror direction computed by the reflection formula; the closed-form normal-incidence albedo
2 pi / (n + 2) of the mirror lobe; adaptive quadrature of f cos and of the pdf over the
hemisphere (tests/chi2.py ``integrate_cells``); the share of valid samples as the pdf's integral;
a Monte Carlo albedo, unbiased only if ``sample`` follows ``pdf``; and reciprocity by swapping.
"""

import math

import numpy as np
import pytest

import brdf
from brdf.errors import SpecError
from brdf.models import Lafortune
from brdf.models import lafortune as lafortune_module
from lobes import (assert_monte_carlo_albedo, assert_valid_share_matches_pdf,
                   hemisphere_integral, incident)


def unit(rng, n, upper=True):
    v = rng.normal(size=(n, 3))
    if upper:
        v[:, 2] = np.abs(v[:, 2]) + 1e-3
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def definition(wi, wo, cx, cy, cz, n):
    """Lafortune et al. 1997, eq. 4 per channel (arrays ``(C,)``), 0 below the horizon: (m, C)."""
    wi, wo = np.atleast_2d(wi)[:, None, :], np.atleast_2d(wo)[:, None, :]
    d = cx * wi[..., 0] * wo[..., 0] + cy * wi[..., 1] * wo[..., 1] + cz * wi[..., 2] * wo[..., 2]
    with np.errstate(invalid="ignore"):
        f = np.where(d > 0.0, np.abs(d) ** n, 0.0)
    return np.where((wi[..., 2] > 0.0) & (wo[..., 2] > 0.0), f, 0.0)


# --- declarations and specs -------------------------------------------------------------------

@pytest.mark.parametrize("spec", ["lafortune", "lafortune(cx=-0.8, cy=-0.7, cz=0.9, n=35.5)",
                                  "lafortune(cx=[-1,-0.9,-0.8], cz=[0.9,1,1.1], n=[10,20,30])",
                                  "lafortune(cx=0.5, cy=0.5, cz=0.5, n=0)"])
def test_spec_round_trip(spec):
    m = brdf.parse(spec)
    assert brdf.parse(str(m)) == m
    assert brdf.from_dict(m.to_dict()) == m


def test_declarations():
    m = brdf.parse("lafortune")
    assert str(m) == "lafortune(cx=-1, cy=-1, cz=1, n=20)"
    assert m.reciprocal and not m.energy_conserving and not m.is_anisotropic
    assert brdf.parse("lafortune(cx=-1, cy=-0.5)").is_anisotropic
    assert brdf.parse("lafortune(cx=[-1,-0.9], cy=[-1,-0.8])").is_anisotropic
    for name in ("cx", "cy", "cz"):
        d = Lafortune.declaration(name)
        assert d.per_channel and d.bounds == (-math.inf, math.inf) and d.fit_bounds == (-5, 5)
    n = Lafortune.declaration("exponent")
    assert n.name == "n" and n.per_channel and n.prior == "log"
    assert n.bounds == (0.0, 1e5) and n.fit_bounds == (1e-2, 1e4)
    # kernel layout: cx, cy, cz, n, each per channel
    assert brdf.parse("lafortune(cx=[-1,-2], n=5)").pack(2) == [-1, -2, -1, -1, 1, 1, 5, 5]
    with pytest.raises(SpecError, match="bounds"):
        brdf.parse("lafortune(n=-1)")


# --- eval -------------------------------------------------------------------------------------

def test_default_lobe_is_cos_power_of_the_angle_to_the_mirror_direction():
    rng = np.random.default_rng(1)
    wi, wo = unit(rng, 20000), unit(rng, 20000)
    normal = np.array([0.0, 0.0, 1.0])
    mirror = 2.0 * (wi @ normal)[:, None] * normal - wi
    cos_angle = np.clip(np.sum(mirror * wo, -1), -1.0, 1.0)
    expected = np.where(cos_angle > 0.0, cos_angle, 0.0) ** 20
    np.testing.assert_allclose(brdf.parse("lafortune").eval(wi, wo)[:, 0], expected,
                               rtol=1e-12, atol=1e-300)
    assert np.count_nonzero(expected > 1e-2) > 200  # the points see the lobe


def test_eval_matches_definition_per_channel():
    """Random signs and fractional exponents, so many points have a negative dot product."""
    cx, cy, cz = np.array([-1.2, 0.7, -0.3]), np.array([-0.8, 0.7, 0.9]), np.array([1.1, 0.7, 0.6])
    n = np.array([2.5, 0.5, 7.25])
    m = Lafortune(cx=cx, cy=cy, cz=cz, n=n)
    rng = np.random.default_rng(2)
    wi, wo = unit(rng, 20000, upper=False), unit(rng, 20000, upper=False)
    expected = definition(wi, wo, cx, cy, cz, n)
    # a dot product near 0 loses relative precision to cancellation: an absolute floor
    np.testing.assert_allclose(m.eval(wi, wo), expected, rtol=1e-12, atol=1e-14)
    assert np.all((expected > 0).sum(0) > 1000)  # every channel's lobe is seen


def test_non_negative_and_reciprocal():
    m = brdf.parse("lafortune(cx=[-1.5,0.8,-0.2], cy=[-0.5,0.8,-1], cz=[1.2,0.4,-0.7], "
                   "n=[3.5,0.3,12])")
    rng = np.random.default_rng(3)
    wi, wo = unit(rng, 50000, upper=False), unit(rng, 50000, upper=False)
    f = m.eval(wi, wo)
    assert np.all(np.isfinite(f)) and np.all(f >= 0.0)
    assert np.all(np.count_nonzero(f, axis=0) > 1000)
    np.testing.assert_array_equal(m.eval(wo, wi), f)
    # the negative-dot configuration exactly: wo on the far side of the mirror lobe
    wi1 = incident(60.0)  # wo = wi is 120 degrees from the mirror direction: the dot is -1/2
    assert np.all(brdf.parse("lafortune(n=2.5)").eval(wi1, wi1) == 0.0)


def test_below_the_horizon_is_zero():
    m = brdf.parse("lafortune(cx=1, cy=1, cz=-1, n=1)")  # positive for wo = -wi reflected down
    up, down = incident(30.0), incident(150.0)
    assert np.all(m.eval(up, down) == 0.0) and np.all(m.eval(down, up) == 0.0)
    assert m.pdf(up, down) == 0.0 and m.pdf(down, up) == 0.0
    assert m.sample(down, np.array([0.3, 0.6]))[1] == 0.0


# --- albedo -----------------------------------------------------------------------------------

@pytest.mark.parametrize("n", [0.0, 1.0, 20.0, 1000.0])
def test_normal_incidence_albedo_closed_form(n):
    """At wi = normal the mirror lobe is cos^n(theta_o): albedo = 2 pi / (n + 2) exactly, which is
    also what the hint estimates there."""
    m = brdf.parse(f"lafortune(n={n})")
    wi = incident(0.0)
    exact = 2.0 * math.pi / (n + 2.0)
    # the integrand (1 - u)^(1/(n+1)) of the sampler's square has a branch point at u = 1, so
    # the quadrature converges slowly; it must agree within its own error estimate
    albedo, error = m.albedo(wi, return_error=True)
    error = np.max(error)  # one incident direction, one channel
    # the cubature's tolerance: 1e-5 of max(1, albedo)
    assert abs(albedo[0] - exact) <= error + 1e-14 and error <= 1e-5 * max(1.0, exact)
    assert lafortune_module.hint_(np.array(m.pack(1)), 1, *wi) == pytest.approx(exact, rel=1e-12)


@pytest.mark.parametrize("spec, theta", [
    ("lafortune(cx=-1, cy=-1, cz=1, n=20)", 60.0),
    ("lafortune(cx=-0.9, cy=-0.5, cz=0.8, n=8)", 75.0),
    ("lafortune(cx=0.8, cy=0.8, cz=0.8, n=3)", 45.0),
    ("lafortune(cx=[-1,-0.9,-1.1], cy=[-1,-0.95,-1], cz=[1,0.9,0.8], n=[30,20,10])", 50.0),
])
def test_albedo_matches_adaptive_quadrature(spec, theta):
    m = brdf.parse(spec)
    wi = incident(theta, 30.0)
    v = m.values
    exact = [hemisphere_integral(lambda wo: definition(wi, wo, *(np.broadcast_to(v[k], (3,))[c]
                                                                 for k in ("cx", "cy", "cz", "n"))
                                                       )[:, 0] * wo[:, 2])
             for c in range(m.channels)]
    np.testing.assert_allclose(m.albedo(wi), exact, rtol=1e-5)


def test_hint_is_capped_for_an_unnormalised_lobe():
    """|s|^n = 5^400 is finite but huge; the hint is capped so a sum's weights stay finite."""
    m = brdf.parse("lafortune(cx=-5, cy=-5, cz=5, n=400)")
    assert lafortune_module.hint_(np.array(m.pack(1)), 1, *incident(10.0)) == \
        lafortune_module.HINT_MAX


def test_a_lobe_whose_peak_overflows_is_rejected():
    with pytest.raises(brdf.ParameterError, match="overflows double precision"):
        brdf.parse("lafortune(cx=-5, cy=-5, cz=5, n=100000)")


# --- sampling ---------------------------------------------------------------------------------

@pytest.mark.parametrize("spec", ["lafortune(cx=-1, cy=-0.5, cz=0.8, n=15)",
                                  "lafortune(cx=0.6, cy=0.6, cz=0.8, n=3)",
                                  "lafortune(cx=[-1,-0.95,-0.9], cz=[1,0.9,0.8], n=[30,20,10])",
                                  "lambert(albedo=0.3) + lafortune(n=50) "
                                  "+ lafortune(cx=-0.5, cy=-0.5, cz=0.6, n=4)"])
def test_sample_pdf_and_eval_agree(spec):
    m = brdf.parse(spec)
    rng = np.random.default_rng(4)
    wi = unit(rng, 20000)
    u = rng.random((20000, 2))
    wo, pdf, weight = m.sample_weighted(wi, u)
    valid = pdf > 0.0
    assert valid.mean() > 0.5
    assert np.all(wo[~valid, 2] <= 0.0) and np.all(wo[valid, 2] > 0.0)
    np.testing.assert_allclose(np.linalg.norm(wo, axis=-1), 1.0, atol=1e-12)
    np.testing.assert_allclose(m.pdf(wi[valid], wo[valid]), pdf[valid], rtol=1e-10)
    expected = m.eval(wi[valid], wo[valid]) * (wo[valid, 2] / pdf[valid])[:, None]
    np.testing.assert_allclose(weight[valid], expected, rtol=1e-10)


def test_pdf_is_a_cosine_power_about_the_lobe_axis():
    cx, cy, cz, n = -0.7, -0.4, 0.9, 12.0
    m = Lafortune(cx=cx, cy=cy, cz=cz, n=n)
    rng = np.random.default_rng(5)
    wi, wo = unit(rng, 5000), unit(rng, 5000)
    s = wi * [cx, cy, cz]
    cos_a = np.sum(s * wo, -1) / np.linalg.norm(s, axis=-1)
    expected = np.where(cos_a > 0.0, (n + 1.0) / (2.0 * math.pi) * np.abs(cos_a) ** n, 0.0)
    np.testing.assert_allclose(m.pdf(wi, wo), expected, rtol=1e-10, atol=1e-300)


@pytest.mark.parametrize("spec, theta", [("lafortune(n=20)", 0.0), ("lafortune(n=20)", 70.0),
                                         ("lafortune(cx=-1, cy=-0.3, cz=0.5, n=4)", 50.0)])
def test_pdf_integrates_to_the_share_of_valid_samples(spec, theta):
    total = assert_valid_share_matches_pdf(brdf.parse(spec), incident(theta, 20.0), seed=6)
    if theta == 0.0:  # the lobe about the normal lies wholly above the horizon
        assert total == pytest.approx(1.0, abs=1e-8)


def test_monte_carlo_albedo_matches_quadrature():
    assert_monte_carlo_albedo(brdf.parse("lafortune(cx=-0.9, cy=-0.6, cz=0.85, n=10)"),
                              incident(55.0, 40.0), seed=7)
