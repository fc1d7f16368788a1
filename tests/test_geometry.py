"""Known values, regressions and an independent rotation oracle for brdf.geometry."""

import warnings

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.spatial.transform import Rotation

from brdf.errors import InputError
from brdf.geometry import (
    cartesian_to_spherical, degrees_from_directions, directions_from_degrees,
    directions_from_half_diff, frame_from_normal, half_diff_from_directions, half_vector,
    reflect, spherical_to_cartesian, to_local, to_world,
)

TWO_PI = 2.0 * np.pi


def test_spherical_known_values():
    assert_allclose(spherical_to_cartesian(0.0, 1.3), [0.0, 0.0, 1.0], atol=1e-15)
    assert_allclose(spherical_to_cartesian(np.pi / 2, np.pi / 2), [0.0, 1.0, 0.0], atol=1e-15)
    assert_allclose(spherical_to_cartesian(np.pi / 2, np.pi), [-1.0, 0.0, 0.0], atol=1e-15)
    theta, phi = cartesian_to_spherical([[0.0, -2.0, 0.0], [3.0, 0.0, 3.0]])  # any length
    assert_allclose(theta, [np.pi / 2, np.pi / 4])
    assert_allclose(phi, [1.5 * np.pi, 0.0])


def test_azimuth_stays_below_two_pi():
    # mod(-1e-17, 2 pi) rounds to 2 pi; the half-open range [0, 2 pi) must hold anyway
    _, phi = cartesian_to_spherical([1.0, -1e-17, 0.0])
    assert 0.0 <= phi < TWO_PI


def test_small_polar_angles_keep_their_digits():
    theta, phi = cartesian_to_spherical(spherical_to_cartesian(1e-9, 0.3))
    assert_allclose(theta, 1e-9, rtol=1e-12)
    assert_allclose(phi, 0.3, rtol=1e-12)


def test_zero_vector_maps_to_the_pole():
    theta, phi = cartesian_to_spherical([0.0, 0.0, 0.0])
    assert theta == 0.0 and phi == 0.0


def test_degree_helpers():
    assert_allclose(directions_from_degrees(90.0, 180.0), [-1.0, 0.0, 0.0], atol=1e-15)
    assert_allclose(directions_from_degrees([0.0, 60.0], 0.0),
                    [[0.0, 0.0, 1.0], [np.sqrt(3) / 2, 0.0, 0.5]], atol=1e-15)
    theta, phi = degrees_from_directions(directions_from_degrees(35.0, 300.0))
    assert_allclose([theta, phi], [35.0, 300.0])
    _, phi = degrees_from_directions([1.0, -1e-17, 0.0])
    assert 0.0 <= phi < 360.0


def test_frame_of_plus_z_is_the_identity():
    t, b, n = frame_from_normal([0.0, 0.0, 1.0])
    assert_allclose(np.stack([t, b, n]), np.eye(3), atol=1e-15)


@pytest.mark.parametrize("normal", [[0.0, 0.0, -1.0], [0.6, 0.8, -0.0], [1.0, 0.0, 0.0],
                                    [0.3, -0.4, -0.8], [1e-9, 0.0, -1.0]])
def test_frame_is_right_handed_and_orthonormal(normal):
    t, b, n = frame_from_normal(normal)
    assert_allclose(np.stack([t, b, n]) @ np.stack([t, b, n]).T, np.eye(3), atol=1e-14)
    assert_allclose(np.cross(t, b), n, atol=1e-14)
    assert_allclose(n, np.asarray(normal) / np.linalg.norm(normal), atol=1e-15)


def test_frame_with_tangent_projects_it():
    t, b, n = frame_from_normal([0.0, 0.0, 2.0], tangent=[1.0, 0.0, 5.0])
    assert_allclose(np.stack([t, b, n]), np.eye(3), atol=1e-15)
    normals = spherical_to_cartesian([0.2, 0.7, 1.1], [0.0, 2.0, 4.0])
    t, b, n = frame_from_normal(normals, tangent=[1.0, 1.0, 0.0])
    assert t.shape == b.shape == n.shape == (3, 3)
    assert_allclose(np.sum(t * n, -1), 0.0, atol=1e-15)
    assert_allclose(np.cross(t, b), n, atol=1e-14)
    assert np.all(np.sum(t * [1.0, 1.0, 0.0], -1) > 0)  # keeps the side of the given tangent


@pytest.mark.parametrize("normal, tangent", [
    ([0.0, 0.0, 0.0], None), ([np.nan, 0.0, 1.0], None), ([np.inf, 0.0, 1.0], None),
    ([0.0, 0.0, 1.0], [0.0, 0.0, -3.0]), ([0.0, 0.0, 1.0], [1e-12, 0.0, 1.0]),
    ([0.0, 0.0, 1.0], [0.0, 0.0, 0.0]),
])
def test_frame_rejects_degenerate_input(normal, tangent):
    with pytest.raises(InputError, match="frame_from_normal"):
        frame_from_normal(normal, tangent)


def test_to_local_and_to_world_on_a_known_frame():
    frame = frame_from_normal([1.0, 0.0, 0.0], tangent=[0.0, 1.0, 0.0])  # t=y, b=z, n=x
    assert_allclose(to_local([1.0, 2.0, 3.0], frame), [2.0, 3.0, 1.0], atol=1e-15)
    assert_allclose(to_world([2.0, 3.0, 1.0], frame), [1.0, 2.0, 3.0], atol=1e-15)


def test_reflect_about_normal_and_half_vector():
    v = spherical_to_cartesian(0.4, 1.0)
    assert_allclose(reflect(v), spherical_to_cartesian(0.4, 1.0 + np.pi), atol=1e-15)
    wi, wo = spherical_to_cartesian(0.3, 0.2), spherical_to_cartesian(1.2, 2.9)
    assert_allclose(reflect(wi, half_vector(wi, wo)), wo, atol=1e-15)


def test_half_vector_normalises_its_inputs():
    assert_allclose(half_vector([2.0, 0.0, 0.0], [0.0, 0.0, 0.5]),
                    [np.sqrt(0.5), 0.0, np.sqrt(0.5)], atol=1e-15)


def test_normal_incidence_retro_reflection_is_all_zeros():
    z = np.array([0.0, 0.0, 1.0])
    assert_allclose(half_diff_from_directions(z, z), [0.0] * 4, atol=0.0)


@pytest.mark.parametrize("theta, phi", [(0.3, 0.0), (1.2, 2.5), (1.5, 5.0)])
def test_in_plane_mirror_pair(theta, phi):
    wi = spherical_to_cartesian(theta, phi)
    theta_h, phi_h, theta_d, phi_d = half_diff_from_directions(wi, reflect(wi))
    assert_allclose([theta_h, phi_h], [0.0, 0.0], atol=1e-15)  # phi_h = 0 by the pole rule
    assert_allclose([theta_d, phi_d], [theta, phi], atol=1e-14)


@pytest.mark.parametrize("theta, phi", [(0.3, 0.0), (1.2, 2.5), (1.5, 5.0)])
def test_retro_reflection(theta, phi):
    wi = spherical_to_cartesian(theta, phi)
    assert_allclose(half_diff_from_directions(wi, wi), [theta, phi, 0.0, 0.0], atol=1e-14)


def test_phi_d_is_zero_when_wi_tilts_beyond_the_half_vector():
    # in the plane of h and the normal: wi further from the normal than h -> phi_d = 0,
    # nearer -> phi_d = pi (the binormal is the rotation axis, Rusinkiewicz 1998 sec. 3)
    theta_h, theta_d, phi_h = 0.5, 0.2, 1.0
    far, near = (spherical_to_cartesian(a, phi_h) for a in (theta_h + theta_d, theta_h - theta_d))
    assert_allclose(half_diff_from_directions(far, near), [theta_h, phi_h, theta_d, 0.0],
                    atol=1e-14)
    assert_allclose(half_diff_from_directions(near, far), [theta_h, phi_h, theta_d, np.pi],
                    atol=1e-14)


def test_half_diff_matches_an_independent_rotation_oracle():
    rng = np.random.default_rng(4)
    theta_h, theta_d = rng.uniform(0.05, 1.5, 50), rng.uniform(0.05, 1.5, 50)
    phi_h, phi_d = rng.uniform(0, TWO_PI, 50), rng.uniform(0, TWO_PI, 50)
    # the frame whose pole is h: rotate about z by phi_h after rotating about y by theta_h
    to_h = Rotation.from_euler("ZY", np.stack([phi_h, theta_h], -1))
    d = spherical_to_cartesian(theta_d, phi_d)
    wi = to_h.apply(d)
    wo = to_h.apply(d * [-1.0, -1.0, 1.0])  # d mirrored about the half-vector pole
    assert_allclose(np.stack(half_diff_from_directions(wi, wo)),
                    np.stack([theta_h, phi_h, theta_d, phi_d]), atol=1e-12)
    back_i, back_o = directions_from_half_diff(theta_h, phi_h, theta_d, phi_d)
    assert_allclose(back_i, wi, atol=1e-14)
    assert_allclose(back_o, wo, atol=1e-14)


def test_grazing_opposite_pair_has_no_warning_and_inverts():
    wi = np.array([1.0, 0.0, 0.0])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        angles = half_diff_from_directions(wi, -wi)
    assert_allclose(angles, [0.0, 0.0, np.pi / 2, 0.0], atol=1e-15)
    back_i, back_o = directions_from_half_diff(*angles)
    assert_allclose([back_i, back_o], [wi, -wi], atol=1e-15)


def test_half_diff_is_vectorised_and_broadcasts():
    rng = np.random.default_rng(0)
    wi = spherical_to_cartesian(rng.uniform(0, 1.5, (4, 5)), rng.uniform(0, TWO_PI, (4, 5)))
    angles = half_diff_from_directions(wi, [0.0, 0.0, 1.0])
    assert all(a.shape == (4, 5) for a in angles)
    back_i, back_o = directions_from_half_diff(*angles)
    assert_allclose(back_i, wi, atol=1e-14)
    assert_allclose(back_o, np.broadcast_to([0.0, 0.0, 1.0], wi.shape), atol=1e-14)


def test_half_diff_normalises_its_inputs():
    wi, wo = spherical_to_cartesian(0.3, 0.2), spherical_to_cartesian(1.0, 2.0)
    assert_allclose(half_diff_from_directions(3.0 * wi, 0.2 * wo),
                    half_diff_from_directions(wi, wo), atol=1e-15)
