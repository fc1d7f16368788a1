"""The block tracer (:func:`brdf.render._integrator.trace_blocks`) against the packet's passes:
the same estimator, so the same image to rounding, for every scene it covers; and the scenes it
leaves to the packet."""

import numpy as np
import pytest

import brdf
from brdf import render
from brdf.render import _integrator as I


def _sphere_on_floor(spec, floor="lambert(albedo=0.5)", environment=None, lights=(),
                     shapes=()):
    """A sphere on a floor quad in front of the camera, lit by an environment (constant by
    default, none if False) and ``lights``."""
    floor_quad = render.Quad((-4.0, -1.0, 4.0), (8.0, 0.0, 0.0), (0.0, 0.0, -8.0), floor)
    return render.Scene(
        shapes=[render.Sphere((0.0, 0.0, 0.0), 1.0, spec), floor_quad, *shapes],
        camera=render.Camera((0.0, 0.5, 4.0), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0), fov=40.0),
        lights=list(lights),
        environment=(render.Environment() if environment is None
                     else environment if environment is not False else None))


_PLASTIC = "lambert(albedo=0.4) + ggx(alpha=0.2, ks=0.5)"


def _sky():
    """An environment map with a bright sun-like patch (importance sampling matters)."""
    h, w = 16, 32
    img = np.full((h, w, 3), 0.2)
    img[3:5, 10:13] = (40.0, 30.0, 20.0)
    img[10:, :, 1] = 0.6
    return render.Environment(map=img)


def _both(scene, **kw):
    """The same render by the blocks and by the packet; checks the blocks cover it."""
    assert render.traced_in_blocks(scene)
    out = []
    for flag in (True, False):
        old, I.use_blocks = I.use_blocks, flag
        try:
            out.append(render.render(scene, progress=False, **kw))
        finally:
            I.use_blocks = old
    return out


SCENES = {
    "ggx furnace": lambda: render.builtin("furnace", "ggx(alpha=0.5)"),
    "lambert furnace": lambda: render.builtin("furnace", "lambert(albedo=0.8)"),
    "lambert + ggx on a floor": lambda: _sphere_on_floor(
        "lambert(albedo=[0.6, 0.4, 0.2]) + ggx(alpha=0.2, ks=0.5)"),
    "ggx + lambert, anisotropic": lambda: _sphere_on_floor(
        "ggx(alpha=0.1, alpha_y=0.4, ks=[0.9, 0.7, 0.5]) + lambert(albedo=0.3)"),
    "height-correlated under a map": lambda: _sphere_on_floor(
        "ggx(alpha=0.3, masking=height-correlated)", floor="ggx(alpha=0.6, ks=0.4)",
        environment=_sky()),
    "lambert + ggx under a map": lambda: _sphere_on_floor(_PLASTIC, environment=_sky()),
    "point and spot lights": lambda: _sphere_on_floor(
        _PLASTIC, environment=False,
        lights=[render.PointLight((1.0, 3.0, 1.0), 20.0, attenuation=(1.0, 0.2, 0.0)),
                render.SpotLight((-1.0, 3.0, 1.0), (1.0, -3.0, -1.0), (5.0, 8.0, 12.0),
                                 cutoff=25.0, exponent=3.0)]),
    "directional light and a map": lambda: _sphere_on_floor(
        "ggx(alpha=0.3, ks=0.8) + lambert(albedo=0.2)", environment=_sky(),
        lights=[render.DirectionalLight((0.3, -1.0, -0.2), 2.0)]),
    "area lights, a quad and a sphere": lambda: _sphere_on_floor(
        _PLASTIC, environment=False,
        shapes=[render.rectangle(np.diag([0.3, 0.3, 0.3, 1.0]) @ _above(3.0), None,
                                 emission=(40.0, 40.0, 40.0), sides="both"),
                render.Sphere((2.0, 1.5, -1.0), 0.3, "lambert", emission=(8.0, 6.0, 3.0))]),
    "goniometric light": lambda: _sphere_on_floor(
        _PLASTIC, environment=False, lights=[_goniometric()]),
    "cornell box": lambda: render.builtin("cornell"),
    "textures on a sphere and a floor": lambda: _sphere_on_floor(
        render.Material(brdf.parse("ggx(alpha=0.3, ks=0.8) + lambert(albedo=0.2)"),
                        {"ggx.alpha": _pattern(1, 0.05, 0.6), "ggx.ks": _pattern(3, 0.2, 0.9),
                         "lambert.albedo": _pattern(3, 0.1, 0.7)}),
        floor=render.Material(brdf.parse("lambert"), {"lambert.albedo": _pattern(3, 0.0, 1.0)}),
        lights=[render.PointLight((1.0, 3.0, 1.0), 20.0)]),
}


def _goniometric():
    """A light brighter towards its nadir and to one side."""
    theta = np.array([0.0, 45.0, 90.0, 135.0, 180.0])
    phi = np.array([0.0, 90.0, 180.0, 270.0, 360.0])
    table = np.outer(0.6 + 0.5 * np.cos(np.radians(theta)), 1.0 + 0.3 * np.sin(np.radians(phi)))
    return render.GoniometricLight((0.5, 3.0, 1.0), table, theta, phi, intensity=15.0)


def _pattern(channels, lo, hi):
    """A 16 x 8 texture of stripes and a gradient between lo and hi."""
    y, x = np.mgrid[0:8, 0:16]
    img = lo + (hi - lo) * (0.5 + 0.5 * np.sin(x[..., None] * np.arange(1, channels + 1)
                                               + 0.7 * y[..., None]))
    return img[..., 0] if channels == 1 else img


def _above(height):
    """A matrix turning the rectangle to face down, at ``height``."""
    m = np.eye(4)
    m[1, 1] = m[2, 2] = -1.0
    m[:3, 3] = (0.0, height, 0.0)
    return m


@pytest.mark.parametrize("name", list(SCENES))
def test_blocks_render_the_packets_image(name):
    """Every layer (radiance, its variance, first-hit albedo and normal) equals the packet's to
    rounding: the same numbers feed the same estimator."""
    a, b = _both(SCENES[name](), spp=3, size=(40, 32), seed=7, threads=2)
    scale = max(np.abs(b.image).max(), 1.0)
    assert np.abs(a.image - b.image).max() <= 1e-12 * scale
    assert np.abs(a.variance - b.variance).max() <= 1e-10 * scale * scale
    assert np.abs(a.albedo - b.albedo).max() <= 1e-12
    assert np.abs(a.normal - b.normal).max() <= 1e-12
    assert b.image.mean() > 0.05  # not an empty picture


def test_blocks_with_other_options_render_the_packets_image():
    """Without jitter or layers, with short paths and early Russian roulette."""
    scene = SCENES["lambert + ggx on a floor"]()
    for kw in (dict(jitter=False), dict(layers=False), dict(max_depth=2),
               dict(max_depth=12, rr_depth=1)):
        a, b = _both(scene, spp=2, size=(24, 20), seed=11, threads=1, **kw)
        assert np.abs(a.image - b.image).max() <= 1e-12 * max(np.abs(b.image).max(), 1.0), kw


def test_blocks_same_seed_same_bytes_any_thread_count():
    scene = SCENES["height-correlated under a map"]()
    one = render.render(scene, spp=4, size=(33, 17), seed=2, threads=1, progress=False)
    two = render.render(scene, spp=4, size=(33, 17), seed=2, threads=2, progress=False)
    assert one.image.tobytes() == two.image.tobytes()
    assert one.variance.tobytes() == two.variance.tobytes()


def _covered(scene, strategy="mis"):
    return render.traced_in_blocks(scene, strategy)


def test_what_the_blocks_leave_to_the_packet():
    """Triangles, measured tables, other lobes, a Fresnel term, many shapes, no light and
    estimators other than MIS are the packet's."""
    assert _covered(SCENES["ggx furnace"]())
    assert not _covered(SCENES["ggx furnace"](), strategy="bsdf")
    assert not _covered(SCENES["ggx furnace"](), strategy="light")
    assert not _covered(_sphere_on_floor("lambert", environment=False))
    assert not _covered(_sphere_on_floor("beckmann(alpha=0.2)"))
    assert not _covered(_sphere_on_floor("ggx(alpha=0.2, fresnel=schlick)"))
    assert not _covered(_sphere_on_floor("lambert + ggx(alpha=0.1) + ggx(alpha=0.5)"))
    assert not _covered(_sphere_on_floor("mirror"))
    many = _sphere_on_floor("lambert")
    many.shapes += [render.Sphere((3.0 * i, 0.0, -5.0), 0.5, "lambert")
                    for i in range(I.BLOCK_PRIMS)]
    assert not _covered(many)
    mesh = _sphere_on_floor("lambert")
    mesh.shapes.append(render.Mesh(np.eye(3), np.array([[0, 1, 2]]), "lambert"))
    assert not _covered(mesh)


def test_derivatives_and_stats_stay_with_the_packet():
    """Renders with derivative images or stage timers use the packet, whatever the scene."""
    model = brdf.parse("ggx(alpha=0.5)")
    scene = render.builtin("furnace", model)
    assert _covered(scene)
    r = render.render(scene, spp=1, size=8, progress=False,
                      derivatives=render.Derivatives(model, ("alpha",)))
    assert r.derivatives is not None and np.isfinite(r.derivatives).all()
    assert np.abs(r.derivatives).max() > 0.0
    s = render.render(scene, spp=1, size=8, progress=False, stats=True)
    assert s.stats.shaded > 0
    assert r.tracer == s.tracer == "packet"
    assert render.render(scene, spp=1, size=8, progress=False).tracer == "blocks"
    assert render.render(scene, spp=1, size=8, progress=False, strategy="bsdf").tracer == "packet"


def test_the_command_line_says_which_tracer(tmp_path):
    from brdf_cli.main import main
    import json
    import contextlib
    import io
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        code = main(["render", "lambert + ggx(alpha=0.2)", "--scene", "furnace", "--spp", "1",
                     "--size", "8x8", "-o", str(tmp_path / "f.exr"), "--json", "-q"])
    assert code == 0
    assert json.loads(buf.getvalue())["tracer"] == "blocks"


def test_traced_in_blocks_refuses_what_is_not_a_scene_or_a_strategy():
    from brdf.errors import InputError
    with pytest.raises(InputError, match="must be a brdf.render.Scene"):
        render.traced_in_blocks("cornell")
    with pytest.raises(InputError, match="strategy must be one of"):
        render.traced_in_blocks(render.builtin("cornell"), strategy="both")
