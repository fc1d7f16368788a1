"""The warps' building blocks against numpy: the polynomial sin, cos and arctangent, the
concentric disk."""

import math

import numpy as np
import pytest

from brdf import sampling


def _ulps(got, want):
    return np.abs(got - want) / np.spacing(np.maximum(np.abs(want), np.finfo(float).tiny))


def test_sincos_octant_within_an_ulp_or_two_of_numpy():
    x = np.concatenate([np.linspace(-math.pi / 4, math.pi / 4, 200_001), [0.0, 1e-300, -1e-8]])
    s, c = np.array([sampling.sincos_octant(v) for v in x]).T
    assert _ulps(s, np.sin(x)).max() <= 2.0
    assert _ulps(c, np.cos(x)).max() <= 2.0


@pytest.mark.parametrize("u", [0.0, 0.125, 0.25, 0.375, 0.5, 0.625, 0.75, 0.875, 1.0, 1.3, -0.2])
def test_sincos_turn_at_octant_edges_and_beyond(u):
    s, c = sampling.sincos_turn(u)
    turn = 2 * math.pi * (u - math.floor(u))  # u's fraction is exact; 2 pi u past a turn is not
    assert s == pytest.approx(math.sin(turn), abs=4e-16)
    assert c == pytest.approx(math.cos(turn), abs=4e-16)


def test_sincos_turn_over_a_turn():
    u = np.random.default_rng(7).random(100_000)
    s, c = np.array([sampling.sincos_turn(v) for v in u]).T
    # 2 pi u rounds once (relative 1e-16 of up to 2 pi) before numpy's sin and cos see it
    assert np.abs(s - np.sin(2 * np.pi * u)).max() < 1e-15
    assert np.abs(c - np.cos(2 * np.pi * u)).max() < 1e-15
    assert np.abs(s * s + c * c - 1.0).max() < 3e-16


def test_concentric_disk_matches_shirley_chiu_with_numpy_trig():
    u = np.random.default_rng(8).random((50_000, 2))
    got = np.array([sampling.square_to_disk_concentric(a, b) for a, b in u])
    a, b = 2 * u[:, 0] - 1, 2 * u[:, 1] - 1
    wide = a * a > b * b
    r = np.where(wide, a, b)
    phi = np.where(wide, np.pi / 4 * b / np.where(wide, a, 1.0),
                   np.pi / 2 - np.pi / 4 * a / np.where(wide, 1.0, b))
    # Shirley & Chiu 1997, section 3
    assert np.abs(got - np.stack([r * np.cos(phi), r * np.sin(phi)], axis=1)).max() < 1e-15
    assert sampling.square_to_disk_concentric(0.5, 0.5) == (0.0, 0.0)
    # the square's edges land on the circle
    edge = np.array([sampling.square_to_disk_concentric(1.0 - 1e-17, t) for t in u[:100, 1]])
    assert np.allclose(np.hypot(edge[:, 0], edge[:, 1]), 1.0, atol=1e-15)


def _quadrants(n, seed):
    """Points over every direction and many scales, and on and near the axes."""
    rng = np.random.default_rng(seed)
    angle = rng.uniform(-math.pi, math.pi, n)
    radius = np.exp(rng.uniform(-40.0, 40.0, n))
    y, x = radius * np.sin(angle), radius * np.cos(angle)
    y[: n // 20] *= 1e-12
    x[n // 20: n // 10] *= 1e-12
    return y, x


def test_arctan2_within_three_ulp_of_libm():
    y, x = _quadrants(200_000, 11)
    got = np.array([sampling.arctan2(a, b) for a, b in zip(y, x)])
    want = np.arctan2(y, x)
    assert _ulps(got, want).max() <= 3.0
    assert np.mean(got == want) > 0.8  # most to the last bit


@pytest.mark.parametrize("y, x", [(0.0, 0.0), (-0.0, 0.0), (0.0, -0.0), (-0.0, -0.0), (1.0, 0.0),
                                  (-1.0, 0.0), (0.0, 1.0), (0.0, -1.0), (-0.0, -1.0), (2.0, 2.0),
                                  (-3.0, -3.0), (1e-310, 1.0), (5e-324, -1.0), (1.0, 1e-300),
                                  (1e300, -1e-300)])
def test_arctan2_on_axes_diagonals_signed_zeros_and_subnormals(y, x):
    got, want = sampling.arctan2(y, x), math.atan2(y, x)
    assert got == want and math.copysign(1.0, got) == math.copysign(1.0, want)


@pytest.mark.parametrize("tangent", [math.sqrt(2.0) - 1.0, np.nextafter(math.sqrt(2.0) - 1.0, 0)])
def test_arctan2_either_side_of_its_range_reduction(tangent):
    # the polynomial serves below tan(pi/8), the shifted ratio above it
    assert _ulps(sampling.arctan2(tangent, 1.0), math.atan2(tangent, 1.0)) <= 3.0


def test_arctan2_coefficients_are_the_chebyshev_interpolant_named_in_its_comment():
    t_max = math.tan(math.pi / 8) ** 2

    def remainder(t):  # (atan s - s) / s^3 in t = s^2, its Taylor series (A&S 4.4.42)
        acc = np.zeros_like(t)
        for k in range(60, 0, -1):
            acc = (-1) ** k / (2 * k + 1) + t * acc
        return acc

    cheb = np.polynomial.chebyshev.Chebyshev.interpolate(remainder, 10, domain=[0.0, t_max])
    np.testing.assert_allclose(cheb.convert(kind=np.polynomial.Polynomial).coef,
                               sampling._ATAN, rtol=1e-12, atol=0.0)


def test_arccos_within_three_ulp_of_libm_and_clamped():
    z = np.concatenate([np.random.default_rng(12).uniform(-1.0, 1.0, 100_000),
                        [-1.0, -0.5, 0.0, 0.5, 1.0, 1.0 - 2.0 ** -52, -1.0 + 2.0 ** -53]])
    got = np.array([sampling.arccos(v) for v in z])
    assert _ulps(got, np.arccos(z)).max() <= 3.0
    assert sampling.arccos(1.0 + 1e-12) == 0.0 and sampling.arccos(-1.0 - 1e-12) == math.pi
