"""brdf.radiometry against independent numeric integrals and analytic results."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from numpy.testing import assert_allclose
from scipy import integrate

import brdf
from brdf import radiometry as rad
from brdf.errors import InputError
from brdf.geometry import frame_from_normal, spherical_to_cartesian, to_world

QUAD = {"epsabs": 0.0, "epsrel": 1e-11}


def sphere_integral(f, theta_max):
    """int_0^{2 pi} int_0^{theta_max} f(theta) sin(theta) dtheta dphi by adaptive quadrature."""
    value, _ = integrate.dblquad(lambda theta, phi: f(theta) * np.sin(theta), 0.0, 2 * np.pi,
                                 0.0, theta_max, **QUAD)
    return value


# --- solid angles ------------------------------------------------------------------------------

@pytest.mark.parametrize("alpha", [1e-3, 0.3, 1.0, np.pi / 2, 2.5, np.pi])
def test_cone_solid_angle_is_the_integral_of_sin_theta(alpha):
    assert_allclose(rad.solid_angle_cone(alpha), sphere_integral(lambda t: 1.0, alpha),
                    rtol=1e-10)


def test_cone_solid_angle_vectorised_and_narrow():
    assert_allclose(rad.solid_angle_cone([0.0, np.pi / 2, np.pi]), [0.0, 2 * np.pi, 4 * np.pi])
    # 2 pi (1 - cos a) computed naively loses every digit here; pi a^2 is the small-angle limit
    assert_allclose(rad.solid_angle_cone(1e-9), np.pi * 1e-18, rtol=1e-9)


def rectangle_by_area_integral(point, corner, u, v):
    """Solid angle as int cos(theta') / r^2 dA over the parallelogram (independent oracle)."""
    normal = np.cross(u, v) / np.linalg.norm(np.cross(u, v))
    jacobian = np.linalg.norm(np.cross(u, v))

    def integrand(b, a):
        r = corner + a * u + b * v - point
        dist = np.linalg.norm(r)
        return abs(np.dot(r, normal)) / dist**3 * jacobian

    value, _ = integrate.dblquad(integrand, 0.0, 1.0, 0.0, 1.0, **QUAD)
    return value


@pytest.mark.parametrize("point, corner, u, v", [
    ([0.0, 0.0, 0.0], [-0.5, -0.2, 1.0], [1.0, 0.0, 0.0], [0.0, 0.7, 0.0]),
    ([0.3, -0.1, 0.2], [0.0, 0.0, 1.0], [1.0, 0.0, 0.5], [0.0, 2.0, 0.0]),
    ([0.0, 0.0, 0.0], [2.0, -1.0, -1.0], [0.0, 2.0, 0.0], [0.0, 0.0, 3.0]),   # seen from behind
    ([0.0, 0.0, 0.0], [-3.0, -3.0, 0.5], [6.0, 0.0, 0.0], [0.0, 6.0, 0.0]),   # close: > pi sr
])
def test_rectangle_solid_angle_matches_the_area_integral(point, corner, u, v):
    exact = rad.solid_angle_rectangle(point, corner, u, v)
    assert_allclose(exact, rectangle_by_area_integral(*map(np.asarray, (point, corner, u, v))),
                    rtol=1e-8)


def test_known_solid_angles():
    # a cube face seen from the cube's centre is a sixth of the sphere
    assert_allclose(rad.solid_angle_rectangle([0, 0, 0], [-1, -1, 1], [2, 0, 0], [0, 2, 0]),
                    4 * np.pi / 6, rtol=1e-14)
    # the octant triangle is an eighth of the sphere
    assert_allclose(rad.solid_angle_triangle([0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]),
                    4 * np.pi / 8, rtol=1e-14)
    # a huge square just above the point fills almost the whole hemisphere
    assert_allclose(rad.solid_angle_rectangle([0, 0, 0], [-1e4, -1e4, 1], [2e4, 0, 0],
                                              [0, 2e4, 0]), 2 * np.pi, rtol=1e-4)


def test_rectangle_solid_angle_broadcasts_over_points():
    points = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, -1.0], [5.0, 0.0, 0.0]])
    got = rad.solid_angle_rectangle(points, [-1, -1, 1], [2, 0, 0], [0, 2, 0])
    each = [rad.solid_angle_rectangle(p, [-1, -1, 1], [2, 0, 0], [0, 2, 0]) for p in points]
    assert got.shape == (3,)
    assert_allclose(got, each)


@pytest.mark.parametrize("tilt", [0.0, 0.6, 1.3])
def test_patch_approximation_converges_to_the_exact_rectangle(tilt):
    # a square of side s centred at distance r, its normal tilted by `tilt` from the sight line
    r = 2.0
    normal = spherical_to_cartesian(tilt, 0.4)
    frame = frame_from_normal(normal)
    centre = np.array([0.0, 0.0, r])
    errors = []
    for side in (0.2, 0.02, 0.002):
        u, v = side * frame[0], side * frame[1]
        exact = rad.solid_angle_rectangle([0, 0, 0], centre - 0.5 * (u + v), u, v)
        approx = rad.solid_angle_patch(side**2, np.cos(tilt), r)
        errors.append(abs(approx / exact - 1.0))
    assert errors[-1] < 1e-6
    # second order in side / r: each tenfold shrink cuts the error about a hundredfold
    assert errors[1] < errors[0] / 50 and errors[2] < errors[1] / 50


def test_patch_solid_angle_ignores_which_side_faces_the_point():
    assert_allclose(rad.solid_angle_patch(2.0, [-0.5, 0.5], 4.0), [2.0 * 0.5 / 16] * 2)


# --- point lights and Lambertian emitters ------------------------------------------------------

def disc_irradiance(radiance, radius, distance, receiver_normal, emitter_normal):
    """E at the origin from a Lambertian disc centred on +z: int L cos cos' / s^2 dA."""
    centre = np.array([0.0, 0.0, distance])
    frame = frame_from_normal(emitter_normal)

    def integrand(rho, psi):
        p = centre + to_world([rho * np.cos(psi), rho * np.sin(psi), 0.0], frame)
        s = np.linalg.norm(p)
        cos_receiver = max(np.dot(p, receiver_normal) / s, 0.0)
        cos_emitter = max(-np.dot(p, emitter_normal) / s, 0.0)
        return radiance * cos_receiver * cos_emitter / s**2 * rho

    value, _ = integrate.dblquad(integrand, 0.0, 2 * np.pi, 0.0, radius, **QUAD)
    return value


@pytest.mark.parametrize("receiver_tilt, emitter_tilt", [(0.0, 0.0), (0.7, 0.0), (0.4, 1.0)])
def test_point_light_is_the_limit_of_a_small_disc_emitter(receiver_tilt, emitter_tilt):
    radiance, distance = 3.0, 2.0
    receiver = spherical_to_cartesian(receiver_tilt, 1.0)
    emitter = -spherical_to_cartesian(emitter_tilt, 2.0)  # faces the origin
    errors = []
    for radius in (0.2, 0.02, 0.002):
        intensity = rad.lambertian_intensity(radiance, np.pi * radius**2, np.cos(emitter_tilt))
        point = rad.point_light_irradiance(intensity, distance, np.cos(receiver_tilt))
        area = disc_irradiance(radiance, radius, distance, receiver, emitter)
        errors.append(abs(point / area - 1.0))
    assert errors[-1] < 1e-5
    assert errors[1] < errors[0] / 50 and errors[2] < errors[1] / 50


def test_uniform_cone_irradiance_matches_disc_and_sphere_integrals():
    radiance, radius, distance = 2.5, 1.3, 0.8
    alpha = np.arctan2(radius, distance)
    up = np.array([0.0, 0.0, 1.0])
    expected = rad.irradiance_from_radiance(radiance, alpha)
    assert_allclose(expected, disc_irradiance(radiance, radius, distance, up, -up), rtol=1e-9)
    assert_allclose(expected, sphere_integral(lambda t: radiance * np.cos(t), alpha), rtol=1e-9)


def test_uniform_sky_irradiance_is_pi_times_radiance():
    assert_allclose(rad.irradiance_from_radiance(2.0),
                    sphere_integral(lambda t: 2.0 * np.cos(t), np.pi / 2), rtol=1e-10)
    assert_allclose(rad.irradiance_from_radiance([1.0, 2.0]), [np.pi, 2 * np.pi])


def test_lambertian_emitter_flux_is_the_hemisphere_integral_times_area():
    radiance, area = 1.7, 0.25
    integral = area * sphere_integral(lambda t: radiance * np.cos(t), np.pi / 2)
    assert_allclose(rad.lambertian_emitter_flux(radiance, area), integral, rtol=1e-10)
    # and the flux is the intensity integrated over all directions (Lambert's cosine law)
    by_intensity = sphere_integral(lambda t: rad.lambertian_intensity(radiance, area, np.cos(t)),
                                   np.pi)
    assert_allclose(rad.lambertian_emitter_flux(radiance, area), by_intensity, rtol=1e-8)


def test_point_light_known_values():
    assert_allclose(rad.point_light_irradiance(8.0, [1.0, 2.0, 4.0], 1.0), [8.0, 2.0, 0.5])
    assert_allclose(rad.point_light_irradiance(8.0, 2.0, [0.5, -0.5]), [1.0, 0.0])
    # OpenGL-style falloff 1 / (a r^2 + b r + c)
    assert_allclose(rad.point_light_irradiance(6.0, 2.0, 1.0, attenuation=(0.5, 1.0, 1.0)), 1.2)
    assert_allclose(rad.point_light_irradiance(6.0, 0.0, 1.0, attenuation=(0.0, 0.0, 3.0)), 2.0)


@given(st.floats(0.0, 10.0), st.floats(0.0, 10.0), st.floats(1e-3, 10.0),
       st.floats(0.0, 1e3), st.floats(0.0, 1e3))
def test_attenuated_irradiance_decreases_with_distance(a, b, c, r1, r2):
    near, far = sorted((r1, r2))
    e_near, e_far = rad.point_light_irradiance(5.0, [near, far], 0.8, attenuation=(a, b, c))
    assert e_far <= e_near


@given(st.floats(1e-3, 1e3), st.floats(1.0 + 1e-6, 1e3))
def test_inverse_square_law_is_the_default(r, k):
    e1, ek = rad.point_light_irradiance(1.0, [r, k * r], 1.0)
    assert_allclose(ek * k**2, e1, rtol=1e-12)
    assert ek < e1


# --- reflection: ties radiometry to the Lambert model -----------------------------------------

def reflected_radiance(model, incident_radiance, wo, order=64):
    """L_o(wo) = int f(wi, wo) L_i cos(theta_i) d omega_i, Gauss-Legendre in theta, midpoint in
    phi (independent of radiometry.py)."""
    x, w = np.polynomial.legendre.leggauss(order)
    theta, w_theta = np.pi / 4 * (x + 1.0), np.pi / 4 * w
    phi = (np.arange(2 * order) + 0.5) * np.pi / order
    tt, pp = np.meshgrid(theta, phi, indexing="ij")
    wi = spherical_to_cartesian(tt, pp)
    f = model.eval(wi, np.broadcast_to(wo, wi.shape))[..., 0]
    weights = w_theta[:, None] * np.sin(tt) * np.cos(tt) * (np.pi / order)
    return np.sum(f * incident_radiance * weights)


@pytest.mark.parametrize("theta_o", [0.0, 0.8, 1.45])
def test_lambertian_reflected_radiance_is_rho_e_over_pi(theta_o):
    model = brdf.parse("lambert(albedo=0.7)")
    sky = 1.9
    wo = spherical_to_cartesian(theta_o, 0.3)
    expected = rad.radiance_from_irradiance(rad.irradiance_from_radiance(sky), 0.7)
    assert_allclose(reflected_radiance(model, sky, wo), expected, rtol=1e-12)
    assert_allclose(expected, 0.7 * sky)


# --- validation --------------------------------------------------------------------------------

@pytest.mark.parametrize("call, pattern", [
    (lambda: rad.point_light_irradiance(1.0, -1.0, 1.0), "distance must be in"),
    (lambda: rad.point_light_irradiance(np.nan, 1.0, 1.0), "intensity must be in .* got nan"),
    (lambda: rad.point_light_irradiance(1.0, 1.0, 1.5), "cos_theta"),
    (lambda: rad.point_light_irradiance(1.0, 0.0, 1.0), "must be > 0"),
    (lambda: rad.point_light_irradiance(1.0, 1.0, 1.0, attenuation=(1.0, 2.0)), "three"),
    (lambda: rad.point_light_irradiance(1.0, 1.0, 1.0, attenuation=(-1, 0, 1)), "attenuation"),
    (lambda: rad.solid_angle_cone(4.0), "half_angle"),
    (lambda: rad.solid_angle_patch(1.0, 1.0, 0.0), r"distance must be in \(0"),
    (lambda: rad.solid_angle_patch(-1.0, 1.0, 1.0), "area"),
    (lambda: rad.solid_angle_patch("big", 1.0, 1.0), "area must be a number"),
    (lambda: rad.solid_angle_triangle([0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]), r"\(\.\.\., 3\)"),
    (lambda: rad.solid_angle_rectangle([0, 0, np.nan], [1, 0, 0], [0, 1, 0], [0, 0, 1]), "NaN"),
    (lambda: rad.radiance_from_irradiance(1.0, 1.2), "albedo"),
    (lambda: rad.irradiance_from_radiance(1.0, 2.0), "half_angle"),
    (lambda: rad.lambertian_emitter_flux([1.0, -2.0], 1.0), "got -2.0"),
])
def test_bad_input_raises_a_one_line_input_error(call, pattern):
    with pytest.raises(InputError, match=pattern) as info:
        call()
    assert "\n" not in str(info.value)


def test_cosines_a_few_ulps_past_one_are_accepted():
    assert_allclose(rad.point_light_irradiance(1.0, 1.0, 1.0 + 1e-15), 1.0)
