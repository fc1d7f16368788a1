"""The radiosity solver on its own (exact cases), and the path tracer's Cornell box against it."""

import numpy as np
import pytest

from brdf import render
from brdf.errors import InputError
from brdf.render import radiosity


def _form_factors(scene, patches, samples):
    quads, rho, emission = radiosity._quads_of(scene)
    mesh = radiosity._mesh(quads, rho, emission, patches)
    return mesh, radiosity._form_factors(mesh, quads, samples)


@pytest.mark.parametrize("samples, tol", [(4, 1e-3), (8, 2e-4)])
def test_perpendicular_unit_squares(samples, tol):
    """Two unit squares sharing an edge at a right angle: F = 0.20004 (Hottel's tabulated
    value; Howell, A Catalog of Radiation Heat Transfer Configuration Factors, C-14), both
    ways; the quadrature over the first square converges as samples grow."""
    squares = [render.Quad((0, 0, 0), (1, 0, 0), (0, 1, 0), "lambert"),
               render.Quad((0, 0, 0), (0, 0, 1), (1, 0, 0), "lambert")]
    mesh, F = _form_factors(render.Scene(shapes=squares), 1, samples)
    front = mesh["side"] == 1
    pair = F[np.ix_(front, front)]
    np.testing.assert_allclose(pair[[0, 1], [1, 0]], 0.20004, atol=tol)
    # the back sides face away from each other: nothing
    assert F[~front].sum() == 0 and F[:, ~front].sum() == 0


def test_closed_box_row_sums_and_radiance():
    """Inside a closed cube every patch sees the whole enclosure (form factors sum to 1), and
    with emission Le on every inner face and albedo rho, radiance is Le / (1 - rho)."""
    faces = render.box(np.eye(4), "lambert(albedo=0.6)")
    for f in faces:
        f.emission, f.sides = [1.0, 2.0, 0.5], "back"
    scene = render.Scene(shapes=faces)
    mesh, F = _form_factors(scene, 3, 2)
    inner = mesh["side"] == -1
    np.testing.assert_allclose(F[inner].sum(axis=1), 1.0, atol=1e-9)
    sol = radiosity.solve(scene, patches=3)
    expected = np.broadcast_to(np.array([1.0, 2.0, 0.5]) / 0.4, sol.radiance[inner].shape)
    np.testing.assert_allclose(sol.radiance[inner], expected, rtol=1e-7)
    np.testing.assert_array_equal(sol.radiance[~inner], 0.0)


def test_buried_points_are_left_out():
    """A box standing on a floor: the floor under the box's bottom face sees nothing, so
    the solution converges (it would not if the floor saw the box's inside through it)."""
    floor = render.Quad((-2, 0, 2), (4, 0, 0), (0, 0, -4), "lambert(albedo=0.9)")
    T = np.diag([0.5, 0.5, 0.5, 1.0])
    T[1, 3] = 0.5
    light = render.Quad((-0.5, 3, -0.5), (1, 0, 0), (0, 0, 1), None, emission=10.0)
    scene = render.Scene(shapes=[floor, light] + render.box(T, "lambert(albedo=0.9)"))
    sol = radiosity.solve(scene, patches=4)
    assert sol.iterations < 1000 and np.all(np.isfinite(sol.radiance))


def test_bad_scenes():
    with pytest.raises(InputError, match="Lambertian"):
        radiosity.solve(render.Scene(shapes=[render.Quad((0, 0, 0), (1, 0, 0), (0, 1, 0),
                                                         "ggx")]))
    with pytest.raises(InputError, match="Quad"):
        radiosity.solve(render.Scene(shapes=[render.Sphere((0, 0, 0), 1, "lambert")]))
    with pytest.raises(InputError, match="lights"):
        radiosity.solve(render.builtin("plane-point", "lambert"))


@pytest.mark.slow
def test_cornell_box_agrees_with_radiosity():
    """Mitsuba's Cornell box (all Lambertian) by the path tracer (no depth limit, pixel
    centres) against radiosity with 4 x 4 patches a quad. Tolerance 2 % of the mean over the
    pixels that do not see the light: the radiosity mesh error, piecewise constant radiance
    and leaks along patches the boxes cut, is of that order (the mean changes by 1.2 % from
    4 x 4 to 6 x 6 patches); the path tracer's standard error is 0.1 %. The emitter's few
    pixels are left out: at 64 x 64 they are a sliver whose share is a matter of sampling."""
    scene = render.builtin("cornell")
    pt = render.render(scene, spp=256, size=64, seed=1, max_depth=-1, jitter=False)
    sol = radiosity.solve(scene, patches=4)
    img = sol.image(scene.camera, 64, 64)
    keep = img.max(axis=-1) < 5.0
    assert (~keep).sum() < 40
    mean_pt, mean_rad = pt.image[keep].mean(axis=0), img[keep].mean(axis=0)
    se = np.sqrt(pt.variance[keep].sum(axis=0)) / keep.sum()
    assert np.all(se < 0.002 * mean_pt)
    np.testing.assert_allclose(mean_rad, mean_pt, rtol=0.02)
    # the walls' colours bleed: the red wall is redder than green, the green one greener
    w = img.shape[1]
    left, right = pt.image[20:44, 2:6].mean(axis=(0, 1)), pt.image[20:44, w - 6:w - 2].mean(
        axis=(0, 1))
    left_r, right_r = img[20:44, 2:6].mean(axis=(0, 1)), img[20:44, w - 6:w - 2].mean(axis=(0, 1))
    np.testing.assert_allclose(left_r, left, rtol=0.1)
    np.testing.assert_allclose(right_r, right, rtol=0.1)
