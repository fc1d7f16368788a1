"""Physical checks: non-negativity, reciprocity and energy reports.

Oracles: analytic albedos (Lambert; GGX at normal incidence, where alpha = 1 gives 1 - ln 2),
scipy quadrature of the GGX normal-incidence albedo in plain spherical coordinates, duck-typed toy
BRDFs whose worst values and their places are known in closed form, and each family's declared
``reciprocal`` / ``energy_conserving`` flags.
"""

import json
import math

import numpy as np
import pytest
from scipy import integrate

import brdf
from brdf import properties
from brdf.errors import InputError, SpecError
from brdf.geometry import spherical_to_cartesian
from brdf.models import MODELS

FAST = {"pairs": 20_000, "theta_steps": 8, "anisotropic_steps": (4, 4)}


class Toy:
    """A duck-typed BRDF f(wi, wo) = fn(cos_i, cos_o) with a cosine-weighted albedo quadrature
    (no ``is_anisotropic``, as a measured table may lack it)."""

    channels = 1

    def __init__(self, fn):
        self.fn = fn

    def eval(self, wi, wo):
        return self.fn(wi[..., 2], wo[..., 2])[..., None]

    def albedo(self, wi, return_error=False):
        x, w = np.polynomial.legendre.leggauss(64)
        c, w = 0.5 * (x + 1.0), math.pi * w  # 2 pi * (1/2) from mapping [-1, 1] to [0, 1]
        a = np.sum(self.fn(wi[..., 2, None], c) * c * w, axis=-1)[..., None]
        return a, np.zeros_like(a)


def ggx_normal_incidence_albedo(alpha):
    """Integral of D G1(wo) / 4 over wo (wi = normal, so G1(wi) = 1; Walter et al. 2007 eqs. 20,
    33, 34) with theta_h = theta_o / 2, by scipy quadrature over cos(theta_o)."""
    def integrand(c):
        t2o = (1.0 - c * c) / (c * c)
        ch2 = 0.5 * (1.0 + c)  # cos^2(theta_o / 2)
        t2h = (1.0 - ch2) / ch2
        d = alpha ** 2 / (math.pi * ch2 ** 2 * (alpha ** 2 + t2h) ** 2)
        g1 = 2.0 / (1.0 + math.sqrt(1.0 + alpha ** 2 * t2o))
        return 2.0 * math.pi * d * g1 / 4.0
    return integrate.quad(integrand, 0.0, 1.0, epsabs=1e-12, epsrel=1e-12)[0]


def energy_at(report, theta_i, phi_i=0.0):
    curve = report["energy"].data["curve"]
    t = int(np.argmin(np.abs(np.asarray(curve["theta_i"]) - theta_i)))
    p = int(np.argmin(np.abs(np.asarray(curve["phi_i"]) - phi_i)))
    return np.asarray(curve["albedo"])[p, t]


# --- energy ----------------------------------------------------------------------------------

def test_lambert_albedo_is_exact():
    report = brdf.check("lambert(albedo=0.8)")
    curve = report["energy"].data["curve"]
    assert len(curve["theta_i"]) == 90 and len(curve["phi_i"]) == 1
    np.testing.assert_allclose(curve["albedo"], 0.8, rtol=0, atol=1e-12)
    assert abs(report["energy"].worst - 0.8) < 1e-12
    assert report.passed


@pytest.mark.parametrize("alpha, expected", [(0.3, 0.877), (1.0, 1.0 - math.log(2.0))])
def test_ggx_normal_incidence_albedo(alpha, expected):
    report = brdf.check(f"ggx(alpha={alpha})", pairs=1000)
    a0 = energy_at(report, 0.0)[0]
    assert abs(a0 - expected) < 1e-3
    assert abs(a0 - ggx_normal_incidence_albedo(alpha)) < 1e-4
    assert report["energy"].passed


def test_energy_excess_fails_and_says_where():
    report = brdf.check("lambert(albedo=1) + ggx(alpha=0.5)", pairs=1000)
    energy = report["energy"]
    assert not energy.passed and not report.passed
    assert energy.worst > 1.0
    where = energy.where
    assert where["theta_o"] is None and where["channel"] == 0
    # the worst value is the albedo at the reported angle, which is the largest on the curve
    wi = spherical_to_cartesian(math.radians(where["theta_i"]), math.radians(where["phi_i"]))
    # far above 1, the first pass's tolerance settles the verdict
    ggx_albedo = brdf.parse("ggx(alpha=0.5)").albedo(wi, tol=properties.VERDICT_TOL)[0]
    assert abs(energy.worst - 1.0 - ggx_albedo) < 1e-9
    assert energy.worst == np.max(energy.data["curve"]["albedo"])
    assert energy.tolerance == pytest.approx(properties.ENERGY_TOL
                                             + energy.data["quadrature_error"])
    assert "FAIL (energy)" in str(report)


@pytest.mark.parametrize("excess", [3e-5, -3e-5])
def test_energy_refines_where_the_first_pass_leaves_doubt(excess):
    # albedo 1 + excess at the worst angle: within the first pass's error estimate (~1e-4), so
    # the verdict needs the second pass at the default tolerance (error estimate <= 1e-5)
    wi = spherical_to_cartesian(math.radians(properties.GRAZING_DEG), 0.0)
    exact = brdf.parse("ggx(alpha=0.5)").albedo(wi, tol=1e-8, max_panels=20000)[0]
    rho = 1.0 - float(exact) + excess
    energy = brdf.check(f"lambert(albedo={rho!r}) + ggx(alpha=0.5)", pairs=1000)["energy"]
    assert energy.where["theta_i"] == properties.GRAZING_DEG
    assert energy.passed == (excess < 0)
    assert energy.data["quadrature_error"] <= 1e-5
    assert abs(energy.worst - (1.0 + excess)) < 1e-5
    # angles whose verdict was plain keep the first pass's precision
    assert np.max(energy.data["curve"]["error"]) > 2e-5


def test_energy_names_the_worst_channel():
    report = brdf.check("lambert(albedo=[0.2,0.9,0.5])", **FAST)
    assert report.channels == 3
    assert report["energy"].where["channel"] == 1
    assert report["energy"].worst == pytest.approx(0.9, abs=1e-12)


def test_blinn_phong_approximate_normalization_is_flagged():
    approx = brdf.check("blinn-phong(n=10, normalization=approx)", pairs=1000)
    assert not approx["energy"].passed
    assert approx["energy"].where["theta_i"] == 0.0
    assert approx["energy"].worst == pytest.approx(1.075, abs=1e-3)
    assert brdf.check("blinn-phong(n=10, normalization=exact)", pairs=1000)["energy"].passed


def test_ward_duer_gains_energy_at_grazing_gmd_does_not():
    duer = brdf.check("ward(alpha=0.3, variant=duer)", pairs=1000)
    assert not duer["energy"].passed
    assert duer["energy"].where["theta_i"] > 80.0
    assert brdf.check("ward(alpha=0.3, variant=gmd)", pairs=1000)["energy"].passed


def test_anisotropic_models_get_an_azimuth_grid():
    report = brdf.check("ggx(alpha=0.1, alpha_y=0.5)", pairs=1000, anisotropic_steps=(6, 8))
    curve = report["energy"].data["curve"]
    assert len(curve["phi_i"]) == 8 and len(curve["theta_i"]) == 6
    albedo = np.asarray(curve["albedo"])
    assert np.ptp(albedo[:, -1, 0]) > 1e-3  # grazing albedo depends on the azimuth


@pytest.mark.parametrize("name", MODELS.names())
def test_energy_conserving_families_pass_at_defaults(name):
    model = MODELS.get(name)()
    if model.energy_conserving:
        assert brdf.check(model, pairs=1000, theta_steps=30)["energy"].passed


# --- non-negativity and reciprocity ----------------------------------------------------------

@pytest.mark.parametrize("name", MODELS.names())
def test_reciprocity_matches_the_declared_flag(name):
    model = MODELS.get(name)()
    report = brdf.check(model, **FAST)
    assert report["non-negativity"].passed
    assert report["reciprocity"].passed == model.reciprocal


def test_original_phong_fails_reciprocity():
    report = brdf.check("phong(n=10)", **FAST)
    rec = report["reciprocity"]
    assert not rec.passed and rec.worst > 0.5
    # the reported place reproduces the reported error: f ~ 1/cos(theta_i) is not symmetric
    w = rec.where
    wi = spherical_to_cartesian(math.radians(w["theta_i"]), math.radians(w["phi_i"]))
    wo = spherical_to_cartesian(math.radians(w["theta_o"]), math.radians(w["phi_o"]))
    m = brdf.parse("phong(n=10)")
    f, g = m.eval(wi, wo)[0], m.eval(wo, wi)[0]
    assert rec.worst == pytest.approx(abs(f - g) / max(f, g), rel=1e-9)


def test_negative_values_are_found_where_they_are():
    report = brdf.check(Toy(lambda ci, co: (0.5 - ci * co) / math.pi), **FAST)
    nn = report["non-negativity"]
    assert not nn.passed
    assert nn.worst == pytest.approx(-0.5 / math.pi, rel=1e-12)
    assert nn.where["theta_i"] == 0.0 and nn.where["theta_o"] == 0.0


def test_non_reciprocal_toy_reports_its_relative_error():
    rec = brdf.check(Toy(lambda ci, co: ci / math.pi + 0.0 * co), **FAST)["reciprocity"]
    w = rec.where
    ci, co = math.cos(math.radians(w["theta_i"])), math.cos(math.radians(w["theta_o"]))
    assert not rec.passed
    assert rec.worst == pytest.approx(abs(ci - co) / max(ci, co), rel=1e-9)
    assert rec.worst > 1.0 - math.cos(math.radians(89.9)) - 1e-12  # grid pair (0, 89.9)


@pytest.mark.parametrize("tail, passes", [(1e-200, True), (1e-3, False)])
def test_reciprocity_floor_ignores_only_rounding_level_tails(tail, passes):
    # a symmetric core of height 1 and a non-reciprocal tail tail * cos(theta_i)
    def fn(ci, co):
        return np.where((ci > 0.5) & (co > 0.5), 1.0, tail * ci + 0.0 * co)
    assert brdf.check(Toy(fn), **FAST)["reciprocity"].passed is passes


def test_non_finite_values_fail_and_serialize():
    report = brdf.check(Toy(lambda ci, co: np.where(ci * co > 0.99, np.nan, 0.1)), **FAST)
    assert not report["non-negativity"].passed
    assert "not finite" in report["non-negativity"].detail
    assert not report["reciprocity"].passed
    data = report.to_dict()
    json.dumps(data, allow_nan=False)
    assert data["checks"][0]["worst"] is None


def test_duck_typed_subject_without_isotropy_flag_gets_azimuths():
    report = brdf.check(Toy(lambda ci, co: 0.3 / math.pi + 0.0 * ci * co), **FAST)
    assert len(report["energy"].data["curve"]["phi_i"]) == FAST["anisotropic_steps"][1]
    assert "is_anisotropic" not in report.declared


# --- report, determinism, inputs -------------------------------------------------------------

def test_report_is_json_ready_and_deterministic():
    a = brdf.check("lambert(albedo=0.3) + ggx(ks=0.5, alpha=0.2)", seed=7, **FAST).to_dict()
    b = brdf.check(brdf.parse("lambert(albedo=0.3) + ggx(ks=0.5, alpha=0.2)"), seed=7,
                   **FAST).to_dict()
    assert a == b
    back = json.loads(json.dumps(a, allow_nan=False))
    assert [c["name"] for c in back["checks"]] == ["non-negativity", "reciprocity", "energy"]
    assert back["passed"] is True and back["declared"]["reciprocal"] is True
    curve = back["checks"][2]["curve"]
    assert np.shape(curve["albedo"]) == (1, FAST["theta_steps"], 1)
    assert set(back["checks"][1]["where"]) == {"theta_i", "phi_i", "theta_o", "phi_o", "channel"}


def test_report_table_lists_every_check():
    text = str(brdf.check("lambert(albedo=0.5)", **FAST))
    lines = text.splitlines()
    assert lines[0] == "checks of lambert(albedo=0.5) (1 channel)"
    assert lines[1].split() == ["check", "result", "worst", "limit", "where"]
    assert [line.split()[0] for line in lines[2:5]] == ["non-negativity", "reciprocity", "energy"]
    assert lines[-1] == "result: pass"


def test_direction_pairs_cover_grazing_and_the_specular_plane():
    angles = properties.direction_pairs(1000, seed=1)
    assert angles.shape == (6400 + 1000, 4)
    np.testing.assert_array_equal(angles, properties.direction_pairs(1000, seed=1))
    assert np.max(angles[:, [0, 2]]) < 90.0 and 89.9 in angles[:6400, 0]
    dphi = np.mod(angles[:6400, 3] - angles[:6400, 1], 360.0)
    assert np.isclose(dphi, 180.0).any() and np.isclose(dphi, 0.0).any()


def test_incidence_grid_is_denser_near_grazing():
    theta, phi = properties.incidence_grid(90, 4)
    assert theta[0] == 0.0 and theta[-1] == pytest.approx(89.9) and len(theta) == 90
    assert np.all(np.diff(np.diff(theta)) < 0)
    np.testing.assert_array_equal(phi, [0.0, 90.0, 180.0, 270.0])


def test_bad_inputs_raise_library_errors():
    with pytest.raises(SpecError, match="unknown model"):
        brdf.check("nosuch(a=1)")
    with pytest.raises(InputError, match="pairs"):
        brdf.check("lambert", pairs=-1)
    with pytest.raises(InputError, match="theta_steps"):
        brdf.check("lambert", theta_steps=1.5)
    with pytest.raises(InputError, match="anisotropic_steps"):
        brdf.check("lambert", anisotropic_steps=(8,))
    with pytest.raises(InputError, match="eval"):
        brdf.check(42)
