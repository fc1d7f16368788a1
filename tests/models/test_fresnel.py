"""Fresnel terms against the complex-amplitude Fresnel equations and their limits."""

import math

import numpy as np
import pytest

from brdf.models import Conductor, Dielectric, NoFresnel, Schlick
from brdf.models.fresnel import conductor_reflectance, dielectric_reflectance, fresnel

COSINES = np.concatenate([np.linspace(1e-4, 1.0, 400), [1e-9, 0.5 ** 0.5, 1.0]])


def amplitude_reflectance(cos_i, n):
    """Unpolarised reflectance from the complex amplitude coefficients (Born & Wolf,
    Principles of Optics, 1.5.2 eq. 21a; 14.2 for a complex index n = eta + i k).

    n cos(theta_t) = sqrt(n^2 - sin^2(theta_i)) on the principal branch, which for k > 0 has a
    positive imaginary part (a wave decaying into the conductor) and for total internal
    reflection is imaginary, so |r| = 1.
    """
    n = np.asarray(n, dtype=complex)
    c = np.asarray(cos_i, dtype=complex)
    n_cos_t = np.sqrt(n * n - (1.0 - c * c))
    rs = (c - n_cos_t) / (c + n_cos_t)
    rp = (n * n * c - n_cos_t) / (n * n * c + n_cos_t)
    return 0.5 * (np.abs(rs) ** 2 + np.abs(rp) ** 2)


def packed_fresnel(term, cosines):
    """Evaluate a Fresnel component through its kernel block, per channel: ``(C, len(cos))``."""
    nch = term.channels
    q = np.array(term.pack(nch))
    return np.array([[fresnel(q, 0, nch, ch, c) for c in cosines] for ch in range(nch)])


@pytest.mark.parametrize("eta", [1.0001, 1.33, 1.5, 2.4, 4.0, 0.9, 1 / 1.5, 0.3])
def test_dielectric_matches_amplitudes(eta):
    ours = np.array([dielectric_reflectance(c, eta) for c in COSINES])
    np.testing.assert_allclose(ours, amplitude_reflectance(COSINES, eta), rtol=1e-10, atol=1e-13)


@pytest.mark.parametrize("eta, k", [(0.2, 3.0), (0.05, 4.0), (1.2, 6.0), (2.5, 0.5), (1.5, 0.0),
                                    (0.14, 3.98), (3.0, 18.0)])
def test_conductor_matches_amplitudes(eta, k):
    ours = np.array([conductor_reflectance(c, eta, k) for c in COSINES])
    np.testing.assert_allclose(ours, amplitude_reflectance(COSINES, eta + 1j * k),
                               rtol=1e-9, atol=1e-13)


@pytest.mark.parametrize("eta", [1.33, 1.5, 2.4])
def test_dielectric_at_normal_incidence(eta):
    expected = ((eta - 1) / (eta + 1)) ** 2
    assert dielectric_reflectance(1.0, eta) == pytest.approx(expected, rel=1e-12)


@pytest.mark.parametrize("eta, k", [(0.2, 3.0), (1.2, 6.0), (2.5, 0.5)])
def test_conductor_at_normal_incidence(eta, k):
    expected = ((eta - 1) ** 2 + k ** 2) / ((eta + 1) ** 2 + k ** 2)
    assert conductor_reflectance(1.0, eta, k) == pytest.approx(expected, rel=1e-12)


@pytest.mark.parametrize("reflectance", [lambda c: dielectric_reflectance(c, 1.5),
                                         lambda c: conductor_reflectance(c, 0.2, 3.0),
                                         lambda c: dielectric_reflectance(c, 0.7)])
def test_grazing_incidence_reflects_everything(reflectance):
    assert reflectance(1e-9) == pytest.approx(1.0, abs=1e-7)


def test_total_internal_reflection():
    """From inside glass (eta = 1/1.5) every angle beyond asin(eta) reflects fully."""
    eta = 1.0 / 1.5
    critical = math.sqrt(1.0 - eta * eta)  # cos of the critical angle
    below = np.linspace(1e-6, critical * (1 - 1e-9), 50)
    assert all(dielectric_reflectance(c, eta) == 1.0 for c in below)
    assert dielectric_reflectance(critical * 1.01, eta) < 1.0


def test_schlick_per_channel():
    term = Schlick(f0=[0.04, 0.5, 0.95])
    f0 = np.array([0.04, 0.5, 0.95])[:, None]
    expected = f0 + (1.0 - f0) * (1.0 - COSINES) ** 5  # Schlick 1994, eq. 15
    np.testing.assert_allclose(packed_fresnel(term, COSINES), expected, rtol=1e-13)


def test_packed_terms_match_their_formulas():
    """The kernel block of each component reaches the right formula with the right channel."""
    cos = np.array([0.1, 0.6, 1.0])
    etas, ks = [1.3, 1.5, 1.7], [2.0, 3.0, 4.0]
    np.testing.assert_array_equal(packed_fresnel(NoFresnel(), cos), np.ones((1, 3)))
    np.testing.assert_allclose(packed_fresnel(Dielectric(eta=etas), cos),
                               [amplitude_reflectance(cos, e) for e in etas], rtol=1e-10)
    np.testing.assert_allclose(packed_fresnel(Conductor(eta=[0.2, 0.9, 1.1], k=ks), cos),
                               [amplitude_reflectance(cos, e + 1j * k)
                                for e, k in zip([0.2, 0.9, 1.1], ks)], rtol=1e-9)


def test_scalar_term_broadcasts_to_channels():
    q = np.array(Dielectric(eta=1.5).pack(3))
    values = {fresnel(q, 0, 3, ch, 0.3) for ch in range(3)}
    assert len(values) == 1
    # called from Python, an inline kernel runs its own unoptimised machine code, which may
    # round the last bit apart from another kernel's
    assert values.pop() == pytest.approx(dielectric_reflectance(0.3, 1.5), rel=1e-15)
