"""Helpers shared by the model-family tests: directions, hemisphere integrals, and the two
statistical checks that tie ``sample`` to ``pdf`` and to ``eval``."""

import math

import numpy as np

from chi2 import integrate_cells


def incident(theta_deg, phi_deg=0.0):
    """Unit direction from degrees."""
    t, p = math.radians(theta_deg), math.radians(phi_deg)
    return np.array([math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t)])


def upper_directions(rng, n):
    """Random directions strictly above the horizon."""
    v = rng.normal(size=(n, 3))
    v[:, 2] = np.abs(v[:, 2]) + 1e-3
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def hemisphere_integral(fn):
    """Integral over the upper hemisphere of ``fn(wo)`` by adaptive Gauss-Legendre cells."""
    cells, converged = integrate_cells(fn, (16, 32))
    assert converged
    return cells.sum()


def assert_valid_share_matches_pdf(m, wi, seed, n=200_000):
    """The share of valid samples equals the integral of the pdf (within 5 sigma); returns it."""
    total = hemisphere_integral(lambda wo: m.pdf(wi, wo))
    assert total <= 1.0 + 1e-9
    u = np.random.default_rng(seed).random((n, 2))
    share = np.mean(m.sample(wi, u)[1] > 0.0)
    sigma = math.sqrt(max(0.0, total * (1.0 - total)) / n)
    assert abs(share - total) < 5.0 * sigma + 1e-9
    return total


def assert_monte_carlo_albedo(m, wi, seed, n=400_000):
    """The mean of f cos / pdf over samples is the albedo only if ``sample`` follows ``pdf``."""
    u = np.random.default_rng(seed).random((n, 2))
    _, _, weight = m.sample_weighted(np.broadcast_to(wi, (n, 3)), u)
    mean, sem = weight[:, 0].mean(), weight[:, 0].std() / math.sqrt(n)
    exact = hemisphere_integral(lambda wo: m.eval(wi, wo)[:, 0] * wo[:, 2])
    assert abs(mean - exact) < 5.0 * sem
