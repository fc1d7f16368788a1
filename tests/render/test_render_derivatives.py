"""Derivative images (:class:`brdf.render.Derivatives`): exactly the derivatives of the render
with a fixed proposal (central differences, same streams), unbiased for the derivatives of the
image (the white furnace, whose pixels are the directional albedo and its analytic gradient),
the plain render's image unchanged, and clear refusals."""

import numpy as np
import pytest

import brdf
from brdf import render
from brdf.errors import InputError
from brdf.render import Camera, Derivatives, Environment, Quad, Scene, Sphere, rectangle
from brdf.render.rays import camera_rays

ALBEDO, KS, ALPHA = (0.45, 0.3, 0.18), (0.35, 0.3, 0.25), 0.22
NAMES = ["lambert.albedo[0]", "lambert.albedo[1]", "lambert.albedo[2]", "ggx.ks[0]",
         "ggx.ks[1]", "ggx.ks[2]", "ggx.alpha"]


def material(albedo=ALBEDO, ks=KS, alpha=ALPHA):
    v = lambda x: "[" + ",".join(repr(float(c)) for c in x) + "]"  # noqa: E731
    return brdf.parse(f"lambert(albedo={v(albedo)}) + ggx(alpha={alpha!r}, ks={v(ks)})")


def moved(name, h):
    """The material with parameter ``name`` moved by h."""
    albedo, ks, alpha = list(ALBEDO), list(KS), ALPHA
    if name == "ggx.alpha":
        alpha += h
    else:
        c = int(name[-2])
        (albedo if name.startswith("lambert") else ks)[c] += h
    return material(albedo, ks, alpha)


def floor_scene(model):
    """The sphere on a diffuse floor under an area light, in a dim environment: light reaches
    it directly, through the floor and from emitters its BSDF samples hit (MIS)."""
    camera = Camera(origin=(0.0, 0.6, 4.0), target=(0, 0, 0), up=(0, 1, 0), fov=36.0)
    floor = Quad((-3.0, -1.0, 3.0), (6.0, 0.0, 0.0), (0.0, 0.0, -6.0), "lambert(albedo=0.6)")
    light = rectangle([[0.3, 0, 0, 0.8], [0, 0, -0.3, 2.2], [0, 0.3, 0, 1.0], [0, 0, 0, 1]],
                      emission=30.0)
    return Scene(camera, [Sphere((0, 0, 0), 1.0, model), floor, light], [], Environment(0.2))


def test_derivatives_are_those_of_the_render_with_a_fixed_proposal():
    model = material()
    scene = floor_scene(model)
    kw = dict(spp=6, size=(24, 18), seed=11, max_depth=6, progress=False, layers=False)
    r = render.render(scene, derivatives=Derivatives(model, NAMES), **kw)
    assert r.derivatives.shape == (18, 24, 3, len(NAMES))
    h = 1e-4
    for k, name in enumerate(NAMES):
        up, down = (render.render(scene, derivatives=Derivatives(model, [name],
                                                                 evaluate=moved(name, s)),
                                  **kw).image for s in (h, -h))
        cd = (up - down) / (2 * h)
        got = r.derivatives[..., k]
        # exact up to the central difference's h^2 (measured: 2e-5 of the largest, alpha)
        assert np.abs(cd - got).max() <= 1e-3 * np.abs(got).max(), name
        assert np.abs(got).max() > 0
    # the albedo of channel 0 moves channel 0 only; the floor bounce makes it reach pixels off
    # the sphere
    assert np.all(r.derivatives[..., 1:, 0] == 0.0)
    on_floor = r.derivatives[-1, :, 0, 0]
    assert np.any(on_floor > 0.0)


def test_the_image_does_not_change_when_derivatives_are_estimated():
    model = material()
    scene = floor_scene(model)
    kw = dict(spp=4, size=(16, 12), seed=2, max_depth=3, rr_depth=8, progress=False)
    a = render.render(scene, **kw)
    b = render.render(scene, derivatives=Derivatives(model, ["ggx.alpha"]), **kw)
    np.testing.assert_allclose(b.image, a.image, rtol=1e-12, atol=1e-15)
    assert a.derivatives is None


def _furnace_oracle(model, names, w, h):
    """Per pixel of the furnace (pixel centres): the directional albedo towards the camera and
    its derivatives in each of ``names`` (the analytic gradient of the model's albedo, an
    independent cubature), and which pixels see the sphere."""
    scene = render.builtin("furnace", model)
    d, o = camera_rays(scene.camera, w, h)
    d = d[0]
    b = d @ o
    disc = b * b - (o @ o - 1.0)
    hit = disc > 0
    t = -b - np.sqrt(np.where(hit, disc, 0.0))
    n = o + t[..., None] * d
    cos = np.clip(-(d * n).sum(axis=-1), 0.0, 1.0)[hit]
    wi = np.stack([np.sqrt(1.0 - cos ** 2), np.zeros_like(cos), cos], axis=-1)
    albedo, grad = model.albedo_gradient(wi, nch=3)   # (m, 3), (m, P, 3)
    slots = Derivatives(model, names).slots()
    dalb = np.stack([sum(grad[:, s, :] for s in row if s >= 0) for row in slots], axis=-1)
    return scene, hit, albedo, dalb


@pytest.mark.slow
def test_derivative_images_are_unbiased_in_the_white_furnace():
    """A convex sphere in a uniform environment of radiance 1: each pixel centre's value is
    the directional albedo towards the camera, and its derivatives are the albedo's. The
    estimates of eight seeds give the mean and its standard error."""
    model = material()
    names = ["lambert.albedo[0]", "ggx.ks[1]", "ggx.alpha"]
    w = h = 24
    scene, hit, albedo, dalb = _furnace_oracle(model, names, w, h)
    runs = [render.render(scene, spp=512, size=(w, h), seed=seed, jitter=False,
                          progress=False, derivatives=Derivatives(model, names))
            for seed in range(8)]
    image = np.mean([r.image[hit].mean(axis=0) for r in runs], axis=0)
    np.testing.assert_allclose(image, albedo.mean(axis=0), rtol=2e-3)
    got = np.array([r.derivatives[hit].mean(axis=0) for r in runs])      # (seeds, 3, K)
    mean, se = got.mean(axis=0), got.std(axis=0, ddof=1) / np.sqrt(len(runs))
    want = dalb.mean(axis=0)
    for k, name in enumerate(names):
        c = int(np.argmax(np.abs(want[:, k])))
        # measured: the alpha derivative's standard error is 0.5 % of it (heavy tails near
        # the peak), the others' below 0.1 %
        assert se[c, k] < 0.01 * abs(want[c, k]), name
        assert abs(mean[c, k] - want[c, k]) < 4.0 * se[c, k] + 1e-4 * abs(want[c, k]), (
            name, mean[c, k], want[c, k], se[c, k])
    assert all(np.all(r.derivatives[..., 1:, 0] == 0.0) for r in runs)


def test_derivatives_refuse_what_they_cannot_follow(tmp_path):
    model = material()
    scene = floor_scene(model)
    kw = dict(spp=1, size=(4, 4), progress=False)
    cases = [
        (Derivatives(material(), ["ggx.alpha"]), "no shape of the scene holds"),
        (Derivatives(model, ["ggx.beta"]), "'ggx.beta' is not a parameter"),
        (Derivatives(model, ["lambert.albedo[3]"]), "has 3 channels"),
        (Derivatives(model, []), "non-empty list"),
        (Derivatives(model, [[99]]), "slots must be integers in [0, 16)"),
        (Derivatives(model, ["ggx.alpha"], evaluate=brdf.parse("lambert + beckmann")),
         "must have the lobes and layout"),
    ]
    for d, message in cases:
        with pytest.raises(InputError) as e:  # noqa: PT011 (message checked below)
            render.render(scene, derivatives=d, **kw)
        assert message in str(e.value) and "\n" not in str(e.value)
    mirror = brdf.parse("lambert + mirror")
    with pytest.raises(InputError, match="delta lobe"):
        render.render(floor_scene(mirror), derivatives=Derivatives(mirror, ["lambert.albedo"]),
                      **kw)
    with pytest.raises(InputError, match="brdf.render.Derivatives"):
        render.render(scene, derivatives=["ggx.alpha"], **kw)
