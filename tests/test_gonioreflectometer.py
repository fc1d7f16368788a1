"""The virtual gonioreflectometer: geometries, noise models, determinism."""

import math

import numpy as np
import pytest

import brdf
from brdf.errors import FormatError, InputError
from brdf.gonioreflectometer import geometry_directions, parse_noise

MODEL = "lambert(albedo=[0.5,0.4,0.3]) + ggx(ks=0.3, alpha=0.25)"


def polar_deg(w):
    return np.degrees(np.arccos(np.clip(w[:, 2], -1.0, 1.0)))


def test_inplane_geometry_lies_in_the_plane_of_incidence():
    wi, wo = geometry_directions("inplane:10")
    assert np.all(np.abs(wi[:, 1]) < 1e-12) and np.all(np.abs(wo[:, 1]) < 1e-12)
    # 9 incidence angles (0..80) x 17 signed exitance angles (-80..80)
    assert len(wi) == 9 * 17
    assert polar_deg(wo).max() == pytest.approx(80.0)
    assert np.all(wo[:, 2] > 0) and np.all(wi[:, 2] > 0)


def test_grid_geometry_counts_the_pole_once():
    wi, wo = geometry_directions("grid:30,90", isotropic=True)
    # theta 0, 30, 60 for wi (phi_i = 0); wo: the pole + 2 rings x 4 azimuths
    assert len(wi) == 3 * 9
    wi_a, _ = geometry_directions("grid:30,90", isotropic=False)
    assert len(wi_a) == 9 * 9
    assert len(np.unique(np.round(wo, 12), axis=0)) == 9


def test_random_geometries_have_the_stated_distributions():
    """Uniform in solid angle: cos(theta) uniform, mean 1/2; cosine-weighted: mean 2/3
    (PBR 4th ed. 13.6); both within 5 standard errors."""
    n = 200_000
    rng = np.random.default_rng(1)
    wi, _ = geometry_directions(f"random:{n}", rng=rng)
    assert abs(wi[:, 2].mean() - 0.5) < 5 * math.sqrt(1 / 12 / n)
    wi, wo = geometry_directions(f"random:{n}:cosine", rng=rng)
    # cos(theta) has density 2c on [0, 1]: mean 2/3, variance 1/18
    assert abs(wo[:, 2].mean() - 2 / 3) < 5 * math.sqrt(1 / 18 / n)
    assert np.all(wi[:, 2] >= 0)


def test_angles_file_geometry(tmp_path):
    path = tmp_path / "schedule.csv"
    path.write_text("# my goniometer\ntheta_i,phi_i,theta_o,phi_o\n0,0,30,180\n45,90,45,270\n")
    wi, wo = geometry_directions(str(path))
    np.testing.assert_allclose(polar_deg(wo), [30.0, 45.0])
    np.testing.assert_allclose(wi[1], [0.0, math.sqrt(0.5), math.sqrt(0.5)], atol=1e-12)
    bad = tmp_path / "bad.csv"
    bad.write_text("theta_i,phi_i,theta_o,phi_o\n0,0,95,0\n")
    with pytest.raises(FormatError, match=r"bad.csv:line 2: .*0 <= theta <= 90"):
        geometry_directions(str(bad))
    missing = tmp_path / "missing.csv"
    missing.write_text("theta_i,phi_i,theta_out,phi_o\n0,0,5,0\n")
    with pytest.raises(FormatError, match="missing column.*theta_o"):
        geometry_directions(str(missing))


@pytest.mark.parametrize("text", ["inplane", "inplane:0", "inplane:abc", "grid:5", "grid:5,x",
                                  "random:0", "random:10:gauss", "sphere:3"])
def test_bad_geometries_name_the_valid_forms(text):
    with pytest.raises(InputError, match="geometry"):
        geometry_directions(text)


def test_noiseless_measurement_equals_the_model():
    m = brdf.parse(MODEL)
    t = brdf.measure(m, "grid:15,45")
    np.testing.assert_array_equal(t.values, m.eval(t.wi, t.wo))
    assert t.sigma is None
    assert t.metadata["model"] == str(m) and t.metadata["geometry"] == "grid:15,45"


@pytest.mark.parametrize("noise, sigma", [
    ("relative:0.05", lambda f: 0.05 * f),
    ("additive:0.01", lambda f: np.full_like(f, 0.01)),
    ("poisson:0.02", lambda f: 0.02 * np.sqrt(f)),
])
def test_noise_models_state_their_sigma_and_have_it(noise, sigma):
    m = brdf.parse(MODEL)
    t = brdf.measure(m, "random:40000", noise=noise, seed=5)
    f = m.eval(t.wi, t.wo)
    np.testing.assert_allclose(t.sigma, sigma(f), rtol=1e-12)
    z = (t.values - f) / t.sigma
    # standardised residuals are N(0, 1): mean within 5 standard errors, variance within 3%
    assert abs(z.mean()) < 5.0 / math.sqrt(z.size)
    assert abs(z.var() - 1.0) < 0.03


def test_same_seed_same_bytes_other_seed_other_bytes():
    a = brdf.measure(MODEL, "random:1000", "relative:0.02", seed=11)
    b = brdf.measure(MODEL, "random:1000", "relative:0.02", seed=11)
    c = brdf.measure(MODEL, "random:1000", "relative:0.02", seed=12)
    assert a.values.tobytes() == b.values.tobytes() and a.wi.tobytes() == b.wi.tobytes()
    assert a.values.tobytes() != c.values.tobytes()


@pytest.mark.parametrize("text", ["gauss:0.1", "relative", "relative:-1", "relative:nan",
                                  "none:3"])
def test_bad_noise_is_rejected(text):
    with pytest.raises(InputError, match="noise"):
        parse_noise(text)


def test_resampling_a_table():
    m = brdf.parse(MODEL)
    fine = brdf.measure(m, "grid:5,5")
    coarse = brdf.measure(fine, "grid:15,45")
    np.testing.assert_allclose(coarse.values, m.eval(coarse.wi, coarse.wo), rtol=0.05)
