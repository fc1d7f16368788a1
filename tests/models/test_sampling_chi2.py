"""Chi-square tests of every family's importance sampling against its pdf (see tests/chi2.py).

Each case draws 10^6 samples for one incident direction (normal, 45 deg, the grazing 80, 85
and 89 deg, and an oblique azimuth for anisotropic models) and is tested at 1 % overall
significance with a Sidak correction for the number of cases. At grazing incidence the cells
crowd toward the mirror direction (``Grid.focused``), so that lobes squeezed against the horizon
span many cells. Negative controls prove the harness rejects wrong densities, on both grids.
"""

import math
import zlib

import numpy as np
import pytest

import brdf
from brdf.models import MODELS
from chi2 import Grid, chi2_test, directions, histogram, integrate_cells, sidak
from model_cases import CASES, SUMS, all_specs

N_SAMPLES = 1_000_000
SIGNIFICANCE = 0.01
SHAPE = (50, 100)
#: (theta_i, phi_i) in degrees: every model gets these, anisotropic ones also INCIDENT_ANISO,
#: and the STEEP_SPECS also STEEP.
INCIDENT = [(0.0, 0.0), (45.0, 0.0), (80.0, 0.0)]
INCIDENT_ANISO = (60.0, 50.0)
STEEP = [(85.0, 0.0), (89.0, 0.0)]
#: Every microfacet spec (the family whose sampler had grazing bands), the first and the last
#: of each other family (its broadest and sharpest or most optioned lobes), Ward's sharpest,
#: and the first and last mixture: every family at 85 and 89 deg within the suite's budget.
STEEP_SPECS = (
    [spec for family in ("ggx", "beckmann") for spec in CASES[family]]
    + [specs[i] for family, specs in CASES.items() if family not in ("ggx", "beckmann")
       for i in sorted({0, len(specs) - 1})]
    + ["ward(rho_s=0.5, alpha=0.05, alpha_y=0.25)", SUMS[0], SUMS[-1]])
#: From this incidence on, the cells crowd toward the mirror direction.
GRAZING = 80.0


def _has_delta(spec):
    return any(lobe.delta for lobe in brdf.parse(spec).lobes)


def _incident(spec):
    model = brdf.parse(spec)
    return (INCIDENT + ([INCIDENT_ANISO] if model.is_anisotropic else [])
            + (STEEP if spec in STEEP_SPECS else []))


def _wi(theta_deg, phi_deg):
    return directions(math.cos(math.radians(theta_deg)), math.radians(phi_deg))


def _seed(*key):
    return zlib.crc32(repr(key).encode())


def _grid(theta_i, phi_i):
    if theta_i < GRAZING:
        return Grid.uniform(SHAPE)
    return Grid.focused(SHAPE, _wi(theta_i, phi_i) * [-1.0, -1.0, 1.0])


def _cases(select):
    """``(spec, theta_i, phi_i)`` for the specs ``select`` accepts; a spec that does not parse
    yet (its family is being written) still yields its three basic directions, so it fails."""
    out = []
    for _, spec in all_specs():
        try:
            if not select(spec):
                continue
            incident = _incident(spec)
        except brdf.SpecError:
            incident = INCIDENT
        out.extend(pytest.param(spec, t, p, id=f"{spec}@{t:g},{p:g}") for t, p in incident)
    return out


CONTINUOUS = _cases(lambda spec: not all(lobe.delta for lobe in brdf.parse(spec).lobes))
WITH_DELTA = _cases(_has_delta)
LEVEL = sidak(SIGNIFICANCE, len(CONTINUOUS))


def test_every_registered_family_has_cases():
    missing = [name for name in MODELS.names() if not CASES.get(name)]
    assert not missing, f"families without cases in tests/model_cases.py: {missing}"


@pytest.mark.parametrize("family, spec", all_specs())
def test_cases_parse_to_their_family(family, spec):
    model = brdf.parse(spec)
    if family == "sum":
        assert len(model.lobes) > 1
    else:
        assert model.name == family


@pytest.mark.slow
@pytest.mark.parametrize("spec, theta_i, phi_i", CONTINUOUS)
def test_sampling_follows_pdf(spec, theta_i, phi_i):
    model = brdf.parse(spec)
    wi = _wi(theta_i, phi_i)
    result = chi2_test(lambda u: model.sample(wi, u), lambda wo: model.pdf(wi, wo),
                       N_SAMPLES, _grid(theta_i, phi_i), seed=_seed(spec, theta_i, phi_i))
    print(f"chi2 {spec} @ {theta_i:g},{phi_i:g}: p = {result.p_value:.4g}, dof {result.dof}")
    assert result.pdf_integral <= 1.0 + 1e-6, result.describe()
    assert not result.rejected(LEVEL), result.describe()


@pytest.mark.parametrize("spec, theta_i, phi_i", WITH_DELTA)
def test_delta_samples_mirror_and_carry_reflectance(spec, theta_i, phi_i):
    """Delta samples go to the mirror direction, and their weights average to the delta lobes'
    reflectance times Fresnel (each weight is that over the chance of picking the lobe)."""
    model = brdf.parse(spec)
    wi = _wi(theta_i, phi_i)
    n = 200_000
    u = np.random.default_rng(_seed(spec, theta_i)).random((n, 2))
    wo, pdf, weight = model.sample_weighted(wi, u)
    delta = np.isinf(pdf)
    assert delta.any()
    np.testing.assert_allclose(wo[delta], np.broadcast_to(wi * [-1, -1, 1], wo[delta].shape),
                               atol=1e-12)
    expected = sum(lobe.albedo(wi) for lobe in model.lobes if lobe.delta)
    mean = weight[delta].sum(0) / n
    if delta.all():
        np.testing.assert_allclose(weight, np.broadcast_to(expected, weight.shape), rtol=1e-12)
    else:  # the count of delta samples is binomial: allow 5 standard deviations
        p = delta.mean()
        np.testing.assert_allclose(mean, expected, rtol=5.0 * math.sqrt((1 - p) / (n * p)))


# --- the harness itself --------------------------------------------------------------------

def test_cell_integration_of_a_sharp_lobe_is_exact():
    """Cosine-power lobe (n + 1)/(2 pi) cos^n about the normal with n = 1000: each cell holds
    (c1^(n+1) - c0^(n+1)) dphi / (2 pi)."""
    n = 1000.0
    cells, converged = integrate_cells(lambda w: (n + 1) / (2 * math.pi) * w[:, 2] ** n, (50, 100))
    c = np.linspace(0.0, 1.0, 51)
    exact = np.diff(c ** (n + 1))[:, None] / 100.0
    assert converged
    np.testing.assert_allclose(cells, np.broadcast_to(exact, cells.shape), rtol=1e-6, atol=1e-12)


def _rejects(sample, pdf, seed=1):
    result = chi2_test(sample, pdf, N_SAMPLES, seed=seed)
    assert result.rejected(LEVEL), result.describe()
    return result


def test_harness_rejects_a_slightly_wrong_roughness():
    wi = _wi(45.0, 0.0)
    right, wrong = brdf.parse("ggx(alpha=0.2)"), brdf.parse("ggx(alpha=0.22)")
    _rejects(lambda u: right.sample(wi, u), lambda wo: wrong.pdf(wi, wo))


def test_focused_grid_cells_tile_the_hemisphere():
    """Edges rise over [0, 1] and one turn, the cells crowd toward the mirror direction at 89
    deg, and a lobe's cell integrals on the focused grid sum to its integral (1 for the
    normalised cosine power about the normal, whose cells are exact)."""
    toward = _wi(89.0, 0.0) * [-1.0, -1.0, 1.0]
    grid = Grid.focused(SHAPE, toward)
    assert grid.shape == SHAPE
    assert grid.cos_edges[0] == 0.0 and grid.cos_edges[-1] == 1.0
    assert np.all(np.diff(grid.cos_edges) > 0.0) and np.all(np.diff(grid.phi_edges) > 0.0)
    assert grid.phi_edges[-1] - grid.phi_edges[0] == pytest.approx(2.0 * math.pi)
    near = np.searchsorted(grid.cos_edges, toward[2])
    assert np.diff(grid.cos_edges)[near - 1] < 1e-3 < 1.0 / SHAPE[0]
    assert np.diff(grid.phi_edges).min() < 2e-3
    n = 50.0
    cells, converged = integrate_cells(lambda w: (n + 1) / (2 * math.pi) * w[:, 2] ** n, grid)
    c = grid.cos_edges
    exact = np.diff(c ** (n + 1))[:, None] * np.diff(grid.phi_edges)[None, :] / (2 * math.pi)
    assert converged
    np.testing.assert_allclose(cells, exact, rtol=1e-6, atol=1e-12)
    wo = directions(np.array([0.5 * (c[near - 1] + c[near])]), np.array([math.pi]))
    assert histogram(wo, grid)[near - 1].sum() == 1.0


def test_harness_rejects_a_slightly_wrong_roughness_at_grazing_incidence():
    wi = _wi(85.0, 0.0)
    right, wrong = brdf.parse("ggx(alpha=0.05)"), brdf.parse("ggx(alpha=0.055)")
    result = chi2_test(lambda u: right.sample(wi, u), lambda wo: wrong.pdf(wi, wo), N_SAMPLES,
                       _grid(85.0, 0.0), seed=2)
    assert result.rejected(LEVEL), result.describe()


def test_harness_rejects_a_tilted_pdf():
    """The right pdf times (1 + 0.3 cos theta_o), renormalised over the hemisphere."""
    wi = _wi(45.0, 0.0)
    model = brdf.parse("ggx(alpha=0.5)")

    def tilted(wo):
        return model.pdf(wi, wo) * (1.0 + 0.3 * wo[:, 2])

    # keep the integral (the share of valid samples) of the original pdf
    scale = (integrate_cells(lambda wo: model.pdf(wi, wo), (50, 100))[0].sum()
             / integrate_cells(tilted, (50, 100))[0].sum())
    _rejects(lambda u: model.sample(wi, u), lambda wo: tilted(wo) * scale)


def test_harness_rejects_a_sampler_that_loses_samples():
    """1 % of the valid samples are reported invalid: only the extra cell can tell."""
    wi = _wi(45.0, 0.0)
    model = brdf.parse("ggx(alpha=0.3)")

    def lossy(u):
        wo, pdf = model.sample(wi, u)
        return wo, np.where(u[:, 1] < 0.01, 0.0, pdf)

    result = _rejects(lossy, lambda wo: model.pdf(wi, wo))
    assert result.observed_extra > result.expected_extra + 5.0 * math.sqrt(result.expected_extra)


def test_sidak_level():
    assert sidak(0.01, 1) == pytest.approx(0.01)
    assert 1.0 - (1.0 - sidak(0.01, 167)) ** 167 == pytest.approx(0.01)

