"""Measured tables: construction, interpolation (grid, sliced, scattered), reciprocity of eval,
albedo by quadrature over the interpolant, and the summary ``brdf-fit info`` prints."""

import math

import numpy as np
import pytest

import brdf
from brdf.errors import InputError
from brdf.geometry import directions_from_degrees
from brdf.gonioreflectometer import geometry_directions
from brdf.table import ScatteredInterpolant, Table, half_vector_rule

SMOOTH = "lambert(albedo=[0.5,0.4,0.3]) + ggx(ks=0.4, alpha=0.4)"


def random_pairs(n, seed, max_theta=75.0):
    """Direction pairs uniform in solid angle up to ``max_theta`` degrees."""
    rng = np.random.default_rng(seed)
    cos_max = math.cos(math.radians(max_theta))
    theta = np.degrees(np.arccos(1.0 - rng.random((n, 2)) * (1.0 - cos_max)))
    phi = 360.0 * rng.random((n, 2))
    return (directions_from_degrees(theta[:, 0], phi[:, 0]),
            directions_from_degrees(theta[:, 1], phi[:, 1]))


def relative_error(table, model, n=4000, seed=3):
    wi, wo = random_pairs(n, seed)
    f, g = table.eval(wi, wo), model.eval(wi, wo)
    return np.abs(f - g) / g


@pytest.fixture(scope="module")
def model():
    return brdf.parse(SMOOTH)


def test_constructor_rejects_bad_samples():
    wi = directions_from_degrees([0.0, 10.0], [0.0, 0.0])
    with pytest.raises(InputError, match="not a unit vector"):
        Table(2.0 * wi, wi, [1.0, 1.0])
    with pytest.raises(InputError, match="below the horizon"):
        Table(wi, wi * [1, 1, -1], [1.0, 1.0])
    with pytest.raises(InputError, match="N = 2"):
        Table(wi, wi, [1.0, 1.0, 1.0])
    with pytest.raises(InputError, match="infinite"):
        Table(wi, wi, [1.0, math.inf])
    with pytest.raises(InputError, match="wavelengths"):
        Table(wi, wi, [[1.0, 2.0]] * 2, wavelengths=[500.0])


def test_channel_names_and_angles():
    wi = directions_from_degrees([30.0], [90.0])
    wo = directions_from_degrees([60.0], [270.0])
    t = Table(wi, wo, [[0.1, 0.2, 0.3]])
    assert t.channel_names == ("r", "g", "b")
    np.testing.assert_allclose(t.angles, [[30.0, 90.0, 60.0, 270.0]], atol=1e-12)
    spectral = Table(wi, wo, [[0.1, 0.2]], wavelengths=[450.0, 550.0])
    assert spectral.channel_names == ("450nm", "550nm")


def test_grid_table_is_multilinear_and_accurate(model):
    """An isotropic (theta_i, theta_o, delta phi) grid every 5 degrees reproduces a smooth model
    to about the square of the step: linear interpolation errs by h^2/8 f'' (about 1% here)."""
    t = brdf.measure(model, "grid:5,5")
    err = relative_error(t, model)
    assert np.median(err) < 0.01
    assert np.percentile(err, 95) < 0.05
    assert t.eval_one_sided(*random_pairs(10, 1))[1].all()


def test_grid_nodes_are_reproduced_exactly(model):
    t = brdf.measure(model, "grid:10,30")
    # grid axes are rounded to 1e-9 rad to merge angles that differ by rounding only
    np.testing.assert_allclose(t.eval(t.wi, t.wo), t.values, rtol=1e-7)


def test_sliced_table_interpolates_between_incidence_angles(model):
    """A gonioreflectometer scan at a few incidence angles, each over a random set of outgoing
    directions: interpolated per slice and linearly across theta_i."""
    theta_i = np.repeat(np.arange(0.0, 80.0, 10.0), 1500)
    wi = directions_from_degrees(theta_i, np.zeros_like(theta_i))
    _, wo = random_pairs(len(theta_i), 5, max_theta=89.0)
    t = Table(wi, wo, model.eval(wi, wo))
    wq, woq = random_pairs(3000, 6, max_theta=70.0)
    err = np.abs(t.eval(wq, woq) - model.eval(wq, woq)) / model.eval(wq, woq)
    assert np.median(err) < 0.02


def test_scattered_table_reproduces_model(model):
    t = brdf.measure(model, "random:20000", seed=2)
    err = relative_error(t, model)
    assert np.median(err) < 0.02
    assert np.percentile(err, 90) < 0.08


def test_anisotropic_table_uses_four_dimensions():
    m = brdf.parse("ggx(ks=0.5, alpha=0.3, alpha_y=0.6)")
    t = brdf.measure(m, "random:20000", seed=1)
    assert t.is_anisotropic and t.coordinates(t.wi[:2], t.wo[:2]).shape == (2, 4)
    wi, wo = random_pairs(2000, 7, max_theta=60.0)
    err = np.abs(t.eval(wi, wo) - m.eval(wi, wo)) / m.eval(wi, wo)
    assert np.median(err) < 0.1


@pytest.mark.parametrize("dim", [2, 3, 4])
def test_barycentric_transforms_are_scipys(dim):
    from scipy.spatial import Delaunay
    from brdf.triangulation import _barycentric_transforms
    points = np.random.default_rng(dim).random((400, dim))
    points[:4] = points[4]  # repeated points: flat simplices, NaN in both
    tri = Delaunay(points, qhull_options="QJ Qbb")
    mine, theirs = _barycentric_transforms(tri.points, tri.simplices), tri.transform
    np.testing.assert_array_equal(np.isnan(mine), np.isnan(theirs))
    np.testing.assert_allclose(mine, theirs, rtol=1e-9, atol=1e-9)


def test_eval_is_reciprocal_even_when_the_samples_are_not():
    """eval averages the interpolant at (wi, wo) and (wo, wi)."""
    t = brdf.measure("phong(ks=1, n=5)", "grid:10,30")
    wi, wo = random_pairs(500, 8)
    np.testing.assert_allclose(t.eval(wi, wo), t.eval(wo, wi), rtol=1e-12)
    assert not np.allclose(t.eval_one_sided(wi, wo)[0], t.eval_one_sided(wo, wi)[0])


def test_missing_samples_are_never_used(model):
    """A table with NaN samples interpolates exactly like the table without those rows, and a
    poisoned value under the NaN would change nothing."""
    t = brdf.measure(model, "grid:10,30")
    hole = (t.angles[:, 0] == 30.0) & (np.abs(t.angles[:, 2] - 40.0) < 1e-9)
    values = t.values.copy()
    values[hole] = np.nan
    holed = t.with_values(values)
    dropped = Table(t.wi[~hole], t.wo[~hole], t.values[~hole])
    wi, wo = random_pairs(2000, 9)
    f = holed.eval(wi, wo)
    assert np.all(np.isfinite(f)) and np.all(f > 0)
    np.testing.assert_array_equal(f, dropped.eval(wi, wo))


def test_outside_the_measured_range_uses_the_nearest_sample():
    wi = directions_from_degrees(np.full(3, 20.0), np.zeros(3))
    wo = directions_from_degrees([10.0, 20.0, 30.0], [180.0] * 3)
    t = Table(wi, wo, [[1.0], [2.0], [3.0]])
    far_i = directions_from_degrees([20.0], [0.0])
    far_o = directions_from_degrees([85.0], [180.0])
    value, inside = t.eval_one_sided(far_i, far_o)
    assert not inside[0] and value[0, 0] == 3.0


def test_below_horizon_is_zero(model):
    t = brdf.measure(model, "grid:10,30")
    wi = directions_from_degrees([30.0], [0.0])
    below = np.array([[0.0, 0.6, -0.8]])
    assert np.all(t.eval(wi, below) == 0.0)


def test_nearest_method_returns_sample_values(model):
    t = brdf.measure(model, "random:500", seed=1)
    f, inside = t.eval_one_sided(t.wi, t.wo, method="nearest")
    np.testing.assert_array_equal(f, t.values)
    with pytest.raises(InputError, match="method"):
        t.eval(t.wi, t.wo, method="cubic")


def test_half_vector_rule_integrates_the_hemisphere():
    h, w = half_vector_rule(16)
    assert w.sum() == pytest.approx(2.0 * math.pi, rel=1e-12)
    # integral of cos(theta_h) over the hemisphere is pi
    assert (w * h[:, 2]).sum() == pytest.approx(math.pi, rel=1e-10)


def test_albedo_of_a_lambert_table_is_its_reflectance():
    t = brdf.measure("lambert(albedo=[0.2,0.5,0.9])", "grid:15,30")
    wi = directions_from_degrees([0.0, 30.0, 60.0], [0.0] * 3)
    a, err = t.albedo(wi, return_error=True)
    np.testing.assert_allclose(a, np.broadcast_to([0.2, 0.5, 0.9], a.shape), rtol=2e-3)
    assert np.all(err < 2e-3)


def test_albedo_over_interpolant_tracks_model(model):
    """Albedo of a 5-degree grid of a glossy model versus the model's own adaptive cubature."""
    t = brdf.measure(model, "grid:5,5")
    wi = directions_from_degrees([0.0, 30.0, 60.0], [0.0] * 3)
    a, err = t.albedo(wi, return_error=True)
    np.testing.assert_allclose(a, model.albedo(wi), rtol=0.01)
    assert np.all(err < 0.01)


def test_summary_reports_counts_and_coverage(model):
    t = brdf.measure(model, "grid:30,90", noise="relative:0.5", seed=3)
    values = t.values.copy()
    values[0, 1] = np.nan
    values[2, :] = np.nan
    values[1, 2] = -0.25
    s = t.with_values(values, sigma=t.sigma).summary()
    assert s["samples"] == len(t) and s["channels"] == 3 and s["sigma"]
    # a sample is a direction pair, a value one of its channels: counted apart
    assert s["missing_values"] == 4
    assert s["missing_samples"] == 1 and s["partially_missing_samples"] == 1
    assert s["negative_values"] >= 1
    assert s["value_range"][0] <= -0.25
    assert s["angles_deg"]["theta_i"] == pytest.approx([0.0, 60.0], abs=1e-9)
    assert s["per_channel"][1]["missing_values"] == 2


def test_summary_rows_name_samples_and_values_apart(model):
    from brdf.table import summary_rows
    t = brdf.measure(model, "grid:30,90", seed=3)
    values = t.values.copy()
    values[:3, :] = np.nan
    rows = dict(summary_rows(t.with_values(values).summary(), digits=4))
    n = len(t)
    assert rows["samples"] == f"{n:,} direction pairs x 3 channels = {3 * n:,} values"
    assert rows["missing samples"].startswith(f"3 of {n:,}")
    assert rows["partially missing samples"].startswith("0 ")
    assert rows["missing values"] == f"9 of {3 * n:,}"
    assert rows["range"].endswith(" 1/sr")


def test_interpolant_merges_duplicate_points():
    points = np.array([[0.0, 0.0], [0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    values = np.array([[1.0], [3.0], [0.0], [0.0]])
    f, inside = ScatteredInterpolant(points, values)(np.array([[0.0, 0.0]]))
    assert f[0, 0] == pytest.approx(2.0) and inside[0]


def test_in_plane_scan_is_flagged(model):
    t = brdf.measure(model, "inplane:10")
    assert t.in_plane
    wi = directions_from_degrees([30.0], [0.0])
    wo = directions_from_degrees([30.0], [180.0])
    assert t.eval(wi, wo)[0] == pytest.approx(model.eval(wi, wo)[0], rel=1e-9)
