"""Oren-Nayar (Oren & Nayar 1994, eq. 30), the built-in compiled family: the paper's formula
term by term, Lambert at sigma = 0, reciprocity, the albedo against numeric integration
(exceeding rho at grazing incidence, as the formula implies), sampling against its pdf, fitting
and the CLI. Gradients (tests/models/test_gradients.py) and the chi-square of the sampler at
every incidence including grazing (tests/models/test_sampling_chi2.py) run on its cases in
tests/model_cases.py. Mitsuba 3 has no rough diffuse plugin ("roughdiffuse" is unknown to
3.9.1), so there is no independent oracle; the paper's formula serves as one."""

import math

import numpy as np
import pytest

import brdf
from brdf.models.oren_nayar import OrenNayar
from lobes import (assert_monte_carlo_albedo, assert_valid_share_matches_pdf,
                   hemisphere_integral, incident, upper_directions)


def _paper(albedo, sigma, ti, pi_, to, po):
    """Oren & Nayar 1994 eq. 30 evaluated from the angles (degrees), term by term."""
    ti, pi_, to, po = (math.radians(v) for v in (ti, pi_, to, po))
    a = 1.0 - 0.5 * sigma ** 2 / (sigma ** 2 + 0.33)
    b = 0.45 * sigma ** 2 / (sigma ** 2 + 0.09)
    alpha, beta = max(ti, to), min(ti, to)
    return albedo / math.pi * (a + b * max(0.0, math.cos(pi_ - po)) * math.sin(alpha)
                               * math.tan(beta))


def test_registered_under_its_names():
    for name in ("oren-nayar", "oren_nayar", "rough-diffuse"):
        assert isinstance(brdf.parse(f"{name}(sigma=0.2)"), OrenNayar)
    assert brdf.parse("oren-nayar").uses_kernels


@pytest.mark.parametrize("angles", [(30, 0, 60, 0), (60, 0, 30, 180), (45, 10, 45, 100),
                                    (80, 0, 20, 30), (0, 0, 50, 90), (70, 200, 75, 10),
                                    (5, 45, 85, 60)])
def test_is_the_papers_formula(angles):
    m = OrenNayar(albedo=0.7, sigma=0.6)
    ti, pi_, to, po = angles
    f = m.eval(incident(ti, pi_), incident(to, po))[0]
    assert f == pytest.approx(_paper(0.7, 0.6, *angles), rel=1e-12)


def test_at_sigma_zero_is_lambert_exactly_and_is_reciprocal():
    rng = np.random.default_rng(7)
    wi, wo = upper_directions(rng, 2000), upper_directions(rng, 2000)
    albedo = [0.8, 0.5, 0.2]
    lambert = brdf.models.Lambert(albedo=albedo)
    assert np.array_equal(OrenNayar(albedo=albedo, sigma=0.0).eval(wi, wo), lambert.eval(wi, wo))
    assert np.array_equal(OrenNayar(albedo=albedo, sigma=0.0).albedo(wi[:20]),
                          lambert.albedo(wi[:20]))
    m = OrenNayar(albedo=albedo, sigma=0.9)
    assert np.array_equal(m.eval(wi, wo), m.eval(wo, wi))
    below = wo * [1.0, 1.0, -1.0]
    assert not m.eval(wi, below).any() and not m.pdf(wi, below).any()


@pytest.mark.parametrize("sigma", [0.0, 0.2, 0.6, 1.5])
@pytest.mark.parametrize("theta_i", [0.0, 45.0, 80.0, 89.0])
def test_albedo_matches_numeric_integration(sigma, theta_i):
    m = OrenNayar(albedo=0.9, sigma=sigma)
    wi = incident(theta_i, 30.0)
    exact = hemisphere_integral(lambda wo: m.eval(wi, wo)[:, 0] * wo[:, 2])
    # to the cubature's absolute tolerance: the integrand has kinks (max(0, cos dphi), the
    # larger cosine), where both rules converge slowly
    assert m.albedo(wi[None])[0, 0] == pytest.approx(exact, abs=1e-5)


def test_albedo_exceeds_rho_at_grazing_incidence_for_small_sigma():
    """Towards grazing incidence the albedo tends to rho (A + B / 2) (the B term integrates to
    B sin(theta_i) / 2 over theta_o < theta_i), above rho for small sigma: the family does not
    claim energy conservation, and the check must find it."""
    sigma = 0.2
    s2 = sigma * sigma
    limit = 1.0 - 0.5 * s2 / (s2 + 0.33) + 0.5 * 0.45 * s2 / (s2 + 0.09)
    a = OrenNayar(albedo=1.0, sigma=sigma).albedo(incident(89.9)[None])[0, 0]
    assert a == pytest.approx(limit, rel=2e-3) and a > 1.0
    assert not OrenNayar.energy_conserving
    report = brdf.check("oren-nayar(albedo=1, sigma=0.2)", pairs=2000, theta_steps=30)
    assert not {c.name: c for c in report.checks}["energy"].passed


@pytest.mark.parametrize("theta_i", [10.0, 60.0, 88.0])
def test_sampler_follows_its_pdf(theta_i):
    m = OrenNayar(albedo=[0.6, 0.5, 0.4], sigma=0.7)
    wi = incident(theta_i, 20.0)
    assert assert_valid_share_matches_pdf(m, wi, seed=1) == pytest.approx(1.0, abs=1e-6)
    assert_monte_carlo_albedo(m, wi, seed=2)


def test_fit_recovers_sigma():
    truth = brdf.parse("oren-nayar(albedo=[0.62,0.48,0.33], sigma=0.45)")
    table = brdf.measure(truth, "grid:10,30", noise="none", seed=1)
    fit = brdf.fit(table, "oren-nayar")
    assert fit.params["oren-nayar.sigma"] == pytest.approx(0.45, rel=1e-3)
    assert fit.params["oren-nayar.albedo[0]"] == pytest.approx(0.62, rel=1e-3)


def test_cli_fits_and_exports_the_closest_material(tmp_path, capsys):
    from brdf_cli.main import main
    path = tmp_path / "on.csv"
    brdf.write(brdf.measure("oren-nayar(albedo=0.5, sigma=0.4)", "grid:10,30"), path)
    assert main(["fit", str(path), "oren_nayar", "--json"]) == 0
    assert "oren-nayar.sigma" in capsys.readouterr().out
    # Mitsuba 3 has no Oren-Nayar: the closest diffuse + roughconductor, within 10 % RMS
    result = brdf.export("oren-nayar(sigma=0.3)", "mitsuba")
    assert not result.exact and result.closest and 0.0 < result.error < 0.1
