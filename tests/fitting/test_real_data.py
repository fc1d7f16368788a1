"""Fits to the real measured data in ../shared/measured: they converge, and the fitted figures
say what is known of each material (skipped, with the reason, where the data are absent).

Oracles are physical, not our own earlier output: sintered PTFE is a near-perfect diffuse
reflector (Germer 2017: hemispherical reflectance about 0.99 across 350-1064 nm, nearly
Lambertian at small incidence); a paint's diffuse albedo spectrum peaks at its colour; the RGL
paper is a bright, rough, diffuse-dominated material.
"""

import numpy as np
import pytest

import brdf
from measured_data import measured

LAMBERT_GGX = "lambert(albedo=0.5) + ggx(alpha=0.2, ks=0.1)"


def _channels(result, name, n):
    return np.array([result.params[f"{name}[{c}]"] for c in range(n)])


@pytest.fixture(scope="module")
def ptfe():
    return brdf.read(measured("nist-ptfe/PTFE.data.csv"))


def test_ptfe_is_lambertian_with_albedo_just_below_one(ptfe):
    r = brdf.fit(ptfe, "lambert(albedo=0.5)")
    albedo = _channels(r, "lambert.albedo", ptfe.channels)
    assert r.converged, r.status
    assert np.all((albedo > 0.97) & (albedo < 1.0)), albedo
    assert r.energy["holds"]
    # a Lambertian model explains PTFE to within a few percent: root-mean-square residual of
    # f cos(theta_i) against its mean
    assert np.sqrt(r.metrics["cosine-l2"]) < 0.05 * np.mean(ptfe.values)


def test_ptfe_gloss_is_a_small_correction_that_keeps_energy(ptfe):
    diffuse = brdf.fit(ptfe, "lambert(albedo=0.5)")
    r = brdf.fit(ptfe, LAMBERT_GGX, shared=["ggx.alpha"])
    assert r.converged, r.status
    assert r.loss < diffuse.loss
    assert np.all(_channels(r, "ggx.ks", ptfe.channels) < 0.2)
    assert np.all(_channels(r, "lambert.albedo", ptfe.channels) > 0.85)
    assert r.energy["holds"] and r.energy["worst_albedo"] <= 1.0


@pytest.mark.parametrize("paint, band", [("acryl_blue", (430, 490)), ("krylon_blue", (430, 490)),
                                         ("garnet_red", (600, 700))])
def test_a_paints_diffuse_albedo_peaks_at_its_colour(paint, band):
    t = brdf.read(measured(f"cornell-paints/{paint}.brdf"))
    r = brdf.fit(t, LAMBERT_GGX, shared=["ggx.alpha"])
    albedo = _channels(r, "lambert.albedo", t.channels)
    assert r.converged, r.status
    assert band[0] <= t.wavelengths[np.argmax(albedo)] <= band[1]
    assert r.energy["holds"]


def test_rgl_white_paper_is_bright_rough_and_diffuse():
    t = brdf.read(measured("rgl/paper_white_rgb.bsdf"))
    r = brdf.fit(t, LAMBERT_GGX, shared=["ggx.alpha"], energy_constraint=True,
                 optimizer="LD_SLSQP")
    assert r.converged, r.status
    albedo = _channels(r, "lambert.albedo", 3)
    assert np.all((albedo > 0.6) & (albedo < 1.0)), albedo
    assert r.params["ggx.alpha"] > 0.3
    assert np.all(_channels(r, "ggx.ks", 3) < albedo)
    assert r.energy["holds"]


def test_rgl_car_paint_is_glossy():
    t = brdf.read(measured("rgl/cc_ibiza_sunset_rgb.bsdf"))
    r = brdf.fit(t, LAMBERT_GGX, shared=["ggx.alpha"])
    assert r.converged, r.status
    assert r.params["ggx.alpha"] < 0.15
    assert r.energy["holds"]
