"""Hypothesis properties of brdf.geometry: round trips, orthonormal frames, reciprocity."""

import numpy as np
from hypothesis import given
from hypothesis import strategies as st
from numpy.testing import assert_allclose

from brdf.geometry import (
    cartesian_to_spherical, directions_from_half_diff, frame_from_normal,
    half_diff_from_directions, half_vector, spherical_to_cartesian, to_local, to_world,
)

TWO_PI = 2.0 * np.pi

polar = st.floats(0.0, np.pi)
upper_polar = st.floats(0.0, np.pi / 2)
azimuth = st.floats(0.0, TWO_PI, exclude_max=True)
# difference angles stop short of pi/2, where wo = -wi and the half vector vanishes
diff_polar = st.floats(0.0, np.pi / 2 - 1e-3)


@st.composite
def directions(draw, theta=polar):
    return spherical_to_cartesian(draw(theta), draw(azimuth))


def angle_gap(a, b):
    """Distance between two azimuths on the circle."""
    return np.abs(np.angle(np.exp(1j * (np.asarray(a) - np.asarray(b)))))


@given(directions())
def test_spherical_round_trip(v):
    assert_allclose(spherical_to_cartesian(*cartesian_to_spherical(v)), v, atol=1e-15)


@given(directions(), st.floats(1e-3, 1e3))
def test_spherical_angles_are_in_range(v, scale):
    theta, phi = cartesian_to_spherical(scale * v)
    assert 0.0 <= theta <= np.pi and 0.0 <= phi < TWO_PI


@given(directions())
def test_frame_is_orthonormal_and_right_handed(n):
    t, b, m = frame_from_normal(n)
    basis = np.stack([t, b, m])
    assert_allclose(basis @ basis.T, np.eye(3), atol=1e-13)
    assert_allclose(np.cross(t, b), m, atol=1e-13)
    assert_allclose(m, n, atol=1e-15)


@given(directions(), directions())
def test_frame_with_tangent_is_orthonormal(n, tangent):
    if np.linalg.norm(np.cross(n, tangent)) < 1e-3:
        return  # a (nearly) parallel tangent is rejected, tested elsewhere
    t, b, m = frame_from_normal(n, tangent)
    basis = np.stack([t, b, m])
    assert_allclose(basis @ basis.T, np.eye(3), atol=1e-13)
    assert_allclose(np.cross(t, b), m, atol=1e-13)


@given(directions(), directions())
def test_to_local_and_to_world_invert(n, v):
    frame = frame_from_normal(n)
    local = to_local(v, frame)
    assert_allclose(to_world(local, frame), v, atol=1e-14)
    assert_allclose(local[2], np.dot(v, n), atol=1e-14)
    assert_allclose(np.linalg.norm(local), 1.0, atol=1e-14)


@given(directions(upper_polar), directions(upper_polar))
def test_directions_to_half_diff_and_back(wi, wo):
    theta_h, phi_h, theta_d, phi_d = half_diff_from_directions(wi, wo)
    assert 0.0 <= theta_h <= np.pi / 2 and 0.0 <= theta_d <= np.pi / 2
    assert 0.0 <= phi_h < TWO_PI and 0.0 <= phi_d < TWO_PI
    if np.linalg.norm(wi + wo) < 1e-6:
        return  # a grazing pair with wo = -wi: the half vector is undefined
    back_i, back_o = directions_from_half_diff(theta_h, phi_h, theta_d, phi_d)
    assert_allclose(back_i, wi, atol=1e-9)
    assert_allclose(back_o, wo, atol=1e-9)


@given(upper_polar, azimuth, diff_polar, azimuth)
def test_half_diff_to_directions_and_back(theta_h, phi_h, theta_d, phi_d):
    wi, wo = directions_from_half_diff(theta_h, phi_h, theta_d, phi_d)
    h = spherical_to_cartesian(theta_h, phi_h)
    assert_allclose(half_vector(wi, wo), h, atol=1e-12)
    assert_allclose(np.dot(wi, h), np.cos(theta_d), atol=1e-14)
    got = half_diff_from_directions(wi, wo)
    assert_allclose([got[0], got[2]], [theta_h, theta_d], atol=1e-9)
    # azimuths are defined away from their poles (their error grows like 1 / sin(theta)); at
    # theta_h = 0 only phi_h + phi_d (the azimuth of wi) is, and at theta_d = 0 phi_d is not
    if np.sin(theta_h) > 1e-3:
        assert angle_gap(got[1], phi_h) < 1e-9
    if np.sin(theta_d) > 1e-3:
        pole = np.sin(theta_h) <= 1e-3
        assert angle_gap(got[3] + pole * got[1], phi_d + pole * phi_h) < 1e-9


@given(directions(upper_polar), directions(upper_polar))
def test_half_diff_reciprocity(wi, wo):
    theta_h, phi_h, theta_d, phi_d = half_diff_from_directions(wi, wo)
    swapped = half_diff_from_directions(wo, wi)
    assert_allclose([swapped[0], swapped[2]], [theta_h, theta_d], atol=1e-12)
    if np.sin(theta_h) > 1e-9:
        assert angle_gap(swapped[1], phi_h) < 1e-9
    if np.sin(theta_d) > 1e-9:
        assert angle_gap(swapped[3], phi_d + np.pi) < 1e-9
