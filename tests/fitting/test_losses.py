"""Fitting losses: each metric against values worked out by hand, the cutoff and missing values,
and the MERL solid-angle weights against the measures of the sets of direction pairs they cover.
"""

import math

import numpy as np
import pytest

import brdf
from brdf.errors import InputError
from brdf.fitting import losses
from brdf.geometry import directions_from_degrees
from brdf.io.merl import grid_directions


def two_samples(values, sigma=None, theta_i=(0.0, 60.0)):
    """Two samples: wi at theta_i (cos 1 and 0.5 by default), wo at the normal."""
    wi = directions_from_degrees(np.array(theta_i), np.zeros(2))
    wo = directions_from_degrees(np.zeros(2), np.zeros(2))
    return brdf.Table(wi, wo, values, sigma=sigma)


# y = (0.2, 0.4) measured, f = (0.3, 0.1) modelled; residuals f - y = (0.1, -0.3); cos_i = (1, 0.5)
Y, F, SIGMA = [[0.2], [0.4]], np.array([[0.3], [0.1]]), [[0.05], [0.1]]
HAND = {
    "l2": (0.1 ** 2 + 0.3 ** 2) / 2,                                   # 0.05
    "cosine-l2": ((1.0 * 0.1) ** 2 + (0.5 * 0.3) ** 2) / 2,           # 0.01625
    "relative-l2": ((0.1 / 0.2) ** 2 + (0.3 / 0.4) ** 2) / 2,         # 0.40625
    "log": ((math.log(1.3) - math.log(1.2)) ** 2
            + (math.log(1.0 + 0.5 * 0.1) - math.log(1.0 + 0.5 * 0.4)) ** 2) / 2,
    "chi-square": ((0.1 / 0.05) ** 2 + (0.3 / 0.1) ** 2) / 2,         # 6.5
}


@pytest.mark.parametrize("name", list(losses.LOSSES))
def test_each_metric_matches_the_hand_computed_value(name):
    samples = losses.prepare(two_samples(Y, SIGMA))
    assert losses.evaluate(losses.terms(name, samples), F) == pytest.approx(HAND[name],
                                                                            rel=1e-12)


def test_chi_square_divides_by_the_degrees_of_freedom():
    samples = losses.prepare(two_samples(Y, SIGMA))
    value = losses.evaluate(losses.terms("chi-square", samples, n_free=1), F)
    assert value == pytest.approx(4.0 + 9.0, rel=1e-12)
    with pytest.raises(InputError, match="more measured values"):
        losses.terms("chi-square", samples, n_free=2)


def test_every_metric_is_zero_at_the_data():
    samples = losses.prepare(two_samples(Y, SIGMA))
    for name in losses.LOSSES:
        assert losses.evaluate(losses.terms(name, samples), np.array(Y)) == 0.0


def test_zero_measurements_get_a_floored_relative_weight():
    samples = losses.prepare(two_samples([[0.0], [0.4]]))
    # floor = 1e-3 x mean |y| = 2e-4 for the zero sample
    expected = ((0.3 / 2e-4) ** 2 + (0.3 / 0.4) ** 2) / 2
    value = losses.evaluate(losses.terms("relative-l2", samples), F)
    assert value == pytest.approx(expected, rel=1e-12)


def test_the_cutoff_drops_grazing_samples():
    table = two_samples(Y, theta_i=(0.0, 85.0))
    assert len(losses.prepare(table).values) == 1
    assert len(losses.prepare(table, cutoff=85.0).values) == 2
    assert losses.prepare(table).describe()["samples_total"] == 2


def test_missing_values_are_dropped_channel_by_channel():
    table = two_samples([[0.2, np.nan], [np.nan, np.nan]])
    samples = losses.prepare(table, cutoff=90.0)
    assert len(samples.values) == 1  # the sample with no measured channel is gone
    f = np.array([[0.3, 123.0]])
    # only channel 0 of sample 0 counts: the mean over measured values is 0.1^2
    assert losses.evaluate(losses.terms("l2", samples), f) == pytest.approx(0.01, rel=1e-12)


def test_bad_options_are_one_line_errors():
    table = two_samples(Y)
    with pytest.raises(InputError, match="losses: cosine-l2"):
        losses.check_loss("l3")
    with pytest.raises(InputError, match="no per-sample sigma|needs per-sample sigma"):
        losses.terms("chi-square", losses.prepare(table))
    for cutoff in (0.0, 95.0):
        with pytest.raises(InputError, match="cutoff"):
            losses.prepare(table, cutoff=cutoff)


# --- solid-angle weights -------------------------------------------------------------------------

def test_merl_weights_sum_to_the_measure_of_the_grid_domain():
    # theta_h and theta_d in [0, 90) degrees, phi_h and phi_d over the full circle: 8 pi^2
    # (16 pi^2 for all pairs of directions on the sphere, half of which have theta_d above 90)
    w = losses.merl_solid_angles()
    assert w.shape == (1_458_000,) and np.all(w > 0.0)
    assert w.sum() == pytest.approx(8.0 * math.pi ** 2, rel=1e-12)


def test_merl_weights_integrate_over_the_upper_hemisphere_pairs():
    w = losses.merl_solid_angles()
    wi, wo = grid_directions()
    zi, zo = np.clip(wi[:, 2], 0.0, None), np.clip(wo[:, 2], 0.0, None)
    upper = (zi > 0.0) & (zo > 0.0)
    # both directions in the upper hemisphere: (2 pi)^2
    assert w[upper].sum() == pytest.approx(4.0 * math.pi ** 2, rel=2e-3)
    # integral of cos(theta_i) cos(theta_o) over those pairs: pi^2
    assert (w * zi * zo).sum() == pytest.approx(math.pi ** 2, rel=1e-3)
    # both within 80 degrees of the normal: (2 pi (1 - cos 80))^2
    c = math.cos(math.radians(80.0))
    inside = (zi >= c) & (zo >= c)
    assert w[inside].sum() == pytest.approx((2.0 * math.pi * (1.0 - c)) ** 2, rel=1e-3)


def test_merl_tables_are_weighted_by_solid_angle_and_others_uniformly():
    merl = brdf.measure("lambert(albedo=[0.5,0.4,0.3])", "merl")
    samples = losses.prepare(merl)
    assert samples.weighting == "merl-solid-angle"
    assert samples.weights.sum() == pytest.approx(1.0, rel=1e-12)
    assert samples.weights.max() / samples.weights.min() > 100.0  # far from uniform
    scattered = losses.prepare(brdf.measure("lambert", "random:50", seed=1))
    assert scattered.weighting == "uniform"
    assert np.all(scattered.weights == scattered.weights[0])
