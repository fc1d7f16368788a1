"""The warps' building blocks against numpy: the polynomial sin and cos, the concentric disk."""

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
