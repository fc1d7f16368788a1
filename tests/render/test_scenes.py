"""Scene content of the path tracer: textures, triangle meshes (arrays and PLY files) and the
JSON/TOML scene files with their error messages."""

import json
from pathlib import Path

import numpy as np
import pytest

import brdf
from brdf import render
from brdf.errors import FormatError, InputError
from brdf.render.image import read_image, write_exr, write_png
from pixels import ground_local, hits_on_ground

W = H = 16
SPEC = "lambert(albedo=0.6) + ggx(alpha=0.3)"


def _plane_point(material):
    """The built-in plane under its point light (intensity 2), traced at pixel centres."""
    scene = render.builtin("plane-point", material)
    scene.lights[0].intensity = 2.0
    return scene


def _trace(scene, size=(W, H)):
    return render.render(scene, spp=2, size=size, seed=0, jitter=False, max_depth=2)


def _ground(scene, w=W, h=H):
    """Per pixel: plane hit mask, texture coordinates (a along edge1 = +x, b along edge2 = -z),
    and the light's direction, distance and cosine."""
    d, p = hits_on_ground(scene.camera, w, h)
    inside = (np.abs(p[..., 0]) < 1.99) & (np.abs(p[..., 2]) < 1.99)
    u, v = (p[..., 0] + 2) / 4, (2 - p[..., 2]) / 4
    to_light = np.array([0.0, 1.0, 0.0]) - p
    r = np.linalg.norm(to_light, axis=-1)
    l = to_light / r[..., None]
    return d, inside, u, v, l, r


# --- textures ---------------------------------------------------------------------------------

def _cells(n, texels):
    """An n x n grid of distinct values (0.1 to 0.85), each cell ``texels`` texels wide; row 0
    of the image is its top (v = 1)."""
    values = 0.1 + 0.75 * np.arange(n * n).reshape(n, n) / (n * n - 1)
    return values, np.kron(values, np.ones((texels, texels)))


def _cell_of(u, v, n):
    """Cell (row from the image top, column) holding (u, v), and whether the point is farther
    than ``margin`` (in cell units) from the cell's edges, where bilinear filtering blends."""
    x, y = u * n, (1 - v) * n
    margin = 0.1
    clear = (np.abs(x - np.round(x)) > margin) & (np.abs(y - np.round(y)) > margin)
    return np.clip(y.astype(int), 0, n - 1), np.clip(x.astype(int), 0, n - 1), clear


def test_texel_square_is_bilinear_with_wrapping_against_numpy():
    """The renderer's bilinear lookup (:func:`brdf.render._materials.texel_square`) against a
    numpy twin, at coordinates across several periods, on texel centres and on the edges where
    the square wraps."""
    from brdf.render._materials import texel_square
    h, w, nc = 5, 7, 3
    image = np.random.default_rng(4).random((h, w, nc))
    tex, meta = np.concatenate([np.zeros(11), image.ravel()]), np.array([[11, w, h, nc]])
    rng = np.random.default_rng(5)
    uv = np.concatenate([rng.uniform(-2.0, 3.0, (2000, 2)),
                         np.array([[0.0, 0.0], [1.0, 1.0], [-1e-17, 1e-17], [0.5 / w, 1 - 0.5 / h],
                                   [1 - 0.5 / w, 0.5 / h], [0.999999, 0.000001]])])
    for u, v in uv:
        k00, k01, k10, k11, w00, w01, w10, w11 = texel_square(meta, 0, u, v)
        x = (u - np.floor(u)) * w - 0.5
        y = (1.0 - (v - np.floor(v))) * h - 0.5
        x0, y0 = int(np.floor(x)), int(np.floor(y))
        fx, fy = x - x0, y - y0
        ya, yb, xa, xb = y0 % h, (y0 + 1) % h, x0 % w, (x0 + 1) % w
        want = ((1 - fx) * (1 - fy) * image[ya, xa] + fx * (1 - fy) * image[ya, xb]
                + (1 - fx) * fy * image[yb, xa] + fx * fy * image[yb, xb])
        got = (w00 * tex[k00:k00 + nc] + w01 * tex[k01:k01 + nc] + w10 * tex[k10:k10 + nc]
               + w11 * tex[k11:k11 + nc])
        np.testing.assert_allclose(got, want, rtol=1e-13, atol=1e-15)
        assert w00 + w01 + w10 + w11 == pytest.approx(1.0)


@pytest.mark.parametrize("fmt", ["png", "exr"])
def test_albedo_texture_follows_the_image(tmp_path, fmt):
    """A 4 x 4 grid of albedos on the plane: away from cell edges every pixel is
    albedo(cell) / pi E, E = I cos / r^2; the image's top row lies at v = 1 (the far edge)."""
    n = 4
    values, img = _cells(n, 16)
    rgb = np.stack([img, 0.5 * img, img[::-1]], axis=-1)
    path = tmp_path / f"albedo.{fmt}"
    if fmt == "png":
        write_png(path, np.round(rgb * 255).astype(np.uint8))
    else:
        write_exr(path, rgb.astype(np.float32))
    texels = read_image(path, channels=3)  # sRGB-decoded for the PNG
    mat = render.Material("lambert", {"lambert.albedo": str(path)})
    scene = _plane_point(mat)
    r = _trace(scene, (32, 32))
    d, inside, u, v, l, dist = _ground(scene, 32, 32)
    row, col, clear = _cell_of(u, v, n)
    keep = inside & clear
    albedo = texels[row * 16 + 8, col * 16 + 8]
    expected = albedo / np.pi * (2.0 * l[..., 1] / dist ** 2)[..., None]
    assert keep.sum() > 300
    np.testing.assert_allclose(r.image[keep], expected[keep], rtol=1e-6)
    # every cell value shows up: the texture is not just sampled at one place
    assert len(np.unique(np.round(albedo[keep][:, 0], 6))) == n * n


def test_scalar_parameter_texture(tmp_path):
    """ggx.alpha from a grey EXR, 0.1 on the left half of the plane and 0.6 on the right:
    each half renders as the model with that alpha (alpha_y follows alpha), away from the
    texel where bilinear filtering blends the halves (at u = 0.5, and at u = 0 where the
    texture repeats)."""
    img = np.full((8, 8), 0.1, np.float32)
    img[:, 4:] = 0.6
    path = tmp_path / "alpha.exr"
    write_exr(path, np.repeat(img[..., None], 3, axis=2))
    mat = render.Material("ggx(alpha=0.3, ks=0.8)", {"ggx.alpha": str(path)})
    scene = _plane_point(mat)
    r = _trace(scene)
    d, inside, u, v, l, dist = _ground(scene)
    for side, alpha in (((u > 0.07) & (u < 0.43), 0.1), ((u > 0.57) & (u < 0.93), 0.6)):
        keep = inside & side
        f = brdf.parse(f"ggx(alpha={alpha}, ks=0.8)").eval(ground_local(l), ground_local(-d))
        expected = np.broadcast_to(f * (2.0 * l[..., 1] / dist ** 2)[..., None], r.image.shape)
        assert keep.sum() > 40
        np.testing.assert_allclose(r.image[keep], expected[keep], rtol=1e-6)


def test_texture_errors(tmp_path):
    with pytest.raises(InputError, match="LOBE.PARAM"):
        render.Scene(shapes=[render.Quad((0, 0, 0), (1, 0, 0), (0, 0, 1),
                                         render.Material("lambert", {"ggx.alpha": np.ones((2, 2))}))
                             ]).compile()
    with pytest.raises(InputError, match="no such file"):
        render.Scene(shapes=[render.Quad((0, 0, 0), (1, 0, 0), (0, 0, 1), render.Material(
            "lambert", {"lambert.albedo": str(tmp_path / "missing.png")}))]).compile()


# --- triangle meshes --------------------------------------------------------------------------

_CORNERS = np.array([[-2.0, 0, 2], [2.0, 0, 2], [2.0, 0, -2], [-2.0, 0, -2]])


def _two_triangles():
    return _CORNERS, np.array([[0, 1, 2], [0, 2, 3]])


def test_two_triangles_render_like_the_quad():
    quad = _trace(_plane_point(SPEC))
    scene = _plane_point(SPEC)
    v, f = _two_triangles()
    scene.shapes = [render.Mesh(v, f, SPEC)]
    mesh = _trace(scene)
    assert quad.image.max() > 0
    # the two take different routes to the same hit point (Moller-Trumbore versus plane and
    # edge tests), which differ in the last bits
    np.testing.assert_allclose(mesh.image, quad.image, rtol=1e-9, atol=1e-15)


def test_mesh_uv_carries_textures():
    """Per-vertex uv on the triangles give the quad's texture mapping."""
    values, img = _cells(2, 8)
    mat = render.Material("lambert", {"lambert.albedo": img})
    quad = _trace(_plane_point(mat))
    scene = _plane_point(mat)
    v, f = _two_triangles()
    scene.shapes = [render.Mesh(v, f, mat, uv=np.array([[0, 0], [1, 0], [1, 1], [0, 1.0]]))]
    np.testing.assert_allclose(_trace(scene).image, quad.image, rtol=1e-9, atol=1e-15)


def test_ply_mesh_through_pyvista(tmp_path):
    """A PLY file written by pyvista, read by Mesh.read with a transform (a shift by +1 in x,
    undone by the vertices' -1): it renders like the quad."""
    pv = pytest.importorskip("pyvista")
    v, f = _two_triangles()
    shifted = v - [1.0, 0.0, 0.0]
    faces = np.hstack([np.full((len(f), 1), 3), f]).ravel()
    path = tmp_path / "plane.ply"
    pv.PolyData(shifted, faces).save(str(path))
    T = np.eye(4)
    T[0, 3] = 1.0
    mesh = render.Mesh.read(str(path), SPEC, transform=T)
    assert mesh.faces.shape == (2, 3)
    scene = _plane_point(SPEC)
    scene.shapes = [mesh]
    np.testing.assert_allclose(_trace(scene).image, _trace(_plane_point(SPEC)).image,
                               rtol=1e-9, atol=1e-15)


def test_mesh_errors(tmp_path):
    with pytest.raises(InputError, match="no such mesh"):
        render.Mesh.read(str(tmp_path / "none.ply"))
    bad = tmp_path / "bad.ply"
    bad.write_text("ply\nformat nonsense\n")
    with pytest.raises(InputError, match="bad.ply"):
        render.Mesh.read(str(bad))
    with pytest.raises(InputError, match="face indices"):
        render.Scene(shapes=[render.Mesh(_CORNERS, np.array([[0, 1, 7]]))]).compile()


def test_shapes_compiled_again_share_their_geometry_until_it_moves(monkeypatch):
    """A scene compiled again (with other materials: an inverse method's passes) takes its
    shapes' arrays from the last compile, read-only and equal to the bit to a compile from
    scratch; a vertex moved in place, a shape added or another label is noticed by content."""
    from brdf.render import scene as S
    v, f = _two_triangles()
    mesh = render.Mesh(v.copy(), f, material=SPEC)
    ball = render.Sphere((0.0, 1.0, 0.0), 0.5, material="lambert(albedo=0.2)")
    first = render.Scene(shapes=[mesh, ball]).compile()
    again = render.Scene(shapes=[render.Mesh(v.copy(), f.tolist(), material="mirror"),
                                 ball]).compile()
    assert again.geo.tri is first.geo.tri and again.geo.planes is first.geo.planes
    assert not first.geo.tri.flags.writeable and not first.geo.box.flags.writeable
    assert again.geo.prim is not first.geo.prim and again.geo.prim.flags.writeable
    assert np.array_equal(again.geo.prim[:, :2], first.geo.prim[:, :2])
    monkeypatch.setattr(S, "_GEOMETRIES", S._Recent(4, 1 << 29, S._GEOMETRIES.size))
    fresh = render.Scene(shapes=[mesh, ball]).compile()
    assert fresh.geo.tri is not first.geo.tri
    for a, b in zip(fresh.geo, first.geo):
        assert a.tobytes() == b.tobytes()
    mesh.vertices[0, 1] += 0.25
    moved = render.Scene(shapes=[mesh, ball]).compile()
    assert moved.geo.tri[0, 0, 1] == fresh.geo.tri[0, 0, 1] + 0.25
    assert render.Scene(shapes=[mesh, ball, ball]).compile().geo.sph.shape == (2, 4)
    # a shape that is not plain numbers is built again, and refused as before
    with pytest.raises(InputError, match="centre"):
        render.Scene(shapes=[render.Sphere(("a", 0, 0), 1.0)]).compile()


def test_the_kept_geometry_is_bounded_in_bytes(monkeypatch):
    from brdf.render import scene as S
    monkeypatch.setattr(S, "_GEOMETRIES", S._Recent(4, 1, S._GEOMETRIES.size))
    balls = [render.Scene(shapes=[render.Sphere((0.0, 0.0, float(k)), 1.0)]) for k in range(3)]
    for scene in balls:
        scene.compile()
    assert len(S._GEOMETRIES) == 1  # the newest, whatever its size
    monkeypatch.setattr(S._GEOMETRIES, "limit", 1 << 29)
    for scene in balls:
        scene.compile()
    assert len(S._GEOMETRIES) == 3


# --- scene files ------------------------------------------------------------------------------

def _scene_document(tmp_path):
    """A scene using every shape and light type, with its side files."""
    pv = pytest.importorskip("pyvista")
    v, f = _two_triangles()
    pv.PolyData(v * 0.2, np.hstack([np.full((2, 1), 3), f]).ravel()).save(
        str(tmp_path / "tri.ply"))
    (tmp_path / "lamp.ies").write_text("IESNA:LM-63-2002\nTILT=NONE\n1 -1 1 2 1 1 2 0 0 0\n"
                                       "1 1 0\n0 90\n0\n50 25\n")
    write_exr(tmp_path / "env.exr", np.full((4, 8, 3), 0.2, np.float32))
    write_exr(tmp_path / "alb.exr", np.full((2, 2, 3), 0.4, np.float32))
    return {
        "camera": {"origin": [0, 1, 5], "target": [0, 0, 0], "fov": 45},
        "materials": {"white": "lambert(albedo=0.7)",
                      "tex": {"brdf": "lambert", "textures": {"lambert.albedo": "alb.exr"}}},
        "shapes": [
            {"type": "sphere", "centre": [0, 0.5, 0], "radius": 0.5, "material": "@material"},
            {"type": "quad", "corner": [-2, 0, 2], "edge1": [4, 0, 0], "edge2": [0, 0, -4],
             "material": "tex"},
            {"type": "rectangle", "to_world": np.diag([0.3, 0.3, 1, 1]).tolist(),
             "material": "white", "emission": [2, 2, 2], "sides": "both"},
            {"type": "box", "to_world": [[0.2, 0, 0, 1], [0, 0.2, 0, 0.2], [0, 0, 0.2, 0],
                                         [0, 0, 0, 1]], "material": "white"},
            {"type": "mesh", "file": "tri.ply", "material": "white"},
            {"type": "sphere", "centre": [0, 3, 0], "radius": 0.2, "emission": 5},
        ],
        "lights": [
            {"type": "point", "position": [1, 2, 1], "intensity": 3,
             "attenuation": [1, 0.1, 0]},
            {"type": "spot", "position": [0, 3, 0], "direction": [0, -1, 0], "intensity": 5,
             "cutoff": 25, "exponent": 3},
            {"type": "directional", "direction": [0, -1, -1], "irradiance": [1, 0.9, 0.8]},
            {"type": "goniometric", "position": [-1, 2, 0], "ies": "lamp.ies", "intensity": 0.1},
        ],
        "environment": {"radiance": 0.5, "map": "env.exr", "up": [0, 1, 0]},
    }


def _write_toml(doc, path):
    """TOML by hand (the standard library reads TOML but does not write it)."""
    def value(x):
        if isinstance(x, str):
            return json.dumps(x)
        if isinstance(x, (list, tuple)):
            return "[" + ", ".join(value(v) for v in x) + "]"
        if isinstance(x, dict):
            return "{" + ", ".join(f"{json.dumps(k)} = {value(v)}" for k, v in x.items()) + "}"
        return repr(x)
    lines = ["[camera]"] + [f"{k} = {value(v)}" for k, v in doc["camera"].items()]
    lines += ["[materials]"] + [f"{k} = {value(v)}" for k, v in doc["materials"].items()]
    lines += ["[environment]"] + [f"{k} = {value(v)}" for k, v in doc["environment"].items()]
    for key in ("shapes", "lights"):
        for item in doc[key]:
            lines += [f"[[{key}]]"] + [f"{k} = {value(v)}" for k, v in item.items()]
    path.write_text("\n".join(lines) + "\n")


@pytest.mark.parametrize("suffix", ["json", "toml"])
def test_scene_file_with_every_shape_and_light(tmp_path, suffix):
    doc = _scene_document(tmp_path)
    path = tmp_path / f"scene.{suffix}"
    if suffix == "json":
        path.write_text(json.dumps(doc))
    else:
        _write_toml(doc, path)
    scene = render.load(path, "ggx(alpha=0.2)")
    kinds = [type(s).__name__ for s in scene.shapes]
    # the box is six quads
    assert kinds == ["Sphere", "Quad", "Quad"] + ["Quad"] * 6 + ["Mesh", "Sphere"]
    assert scene.shapes[0].material == "ggx(alpha=0.2)"  # the command line's material
    assert scene.shapes[1].material.textures["lambert.albedo"] == str(tmp_path / "alb.exr")
    assert scene.shapes[2].emission == [2, 2, 2] and scene.shapes[2].sides == "both"
    np.testing.assert_allclose(scene.shapes[9].vertices, _CORNERS * 0.2, atol=1e-6)
    assert [type(x).__name__ for x in scene.lights] == [
        "PointLight", "SpotLight", "DirectionalLight", "GoniometricLight"]
    assert scene.lights[1].cutoff == 25 and scene.lights[1].exponent == 3
    np.testing.assert_array_equal(scene.lights[3].table[:, 0], [50, 25])
    assert scene.environment.map == str(tmp_path / "env.exr")
    assert scene.camera.fov == 45
    r = render.render(scene, spp=2, size=8, seed=0)
    assert np.all(np.isfinite(r.image)) and r.image.mean() > 0


@pytest.mark.parametrize("change, where, fragment", [
    (lambda d: d.update(cameras={}), "top level", "unknown keys"),
    (lambda d: d["shapes"][1].update(type="cone"), "shapes[1]", "type must be one of"),
    (lambda d: d["shapes"][1].update(colour=1), "shapes[1]", "bad keys for a quad"),
    (lambda d: d["shapes"][2].update(material="gold"), "shapes[2]", "'gold' is not in materials"),
    (lambda d: d["lights"][2].update(type="laser"), "lights[2]", "type must be one of"),
    (lambda d: d["lights"][0].pop("position"), "lights[0]", "bad keys for a point light"),
    (lambda d: d["camera"].update(zoom=2), "camera", "keys: origin"),
    (lambda d: d["environment"].update(sky=1), "environment", "keys: radiance"),
    (lambda d: d["materials"].update(odd=3), "materials.odd", "expected a spec"),
])
def test_scene_file_errors_name_file_and_place(tmp_path, change, where, fragment):
    doc = _scene_document(tmp_path)
    change(doc)
    path = tmp_path / "scene.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(FormatError) as e:
        render.load(path, "lambert")
    assert str(e.value).startswith(f"{path}:{where}: "), str(e.value)
    assert fragment in str(e.value)


@pytest.mark.parametrize("change, where, fragment", [
    (lambda d: d.update(materials=["lambert"]), "materials", "expected a table, got list"),
    (lambda d: d["shapes"][0].update(centre="0,0,0"), "shapes[0].centre", "3 finite numbers"),
    (lambda d: d["shapes"][0].update(centre={"x": 0}), "shapes[0].centre", "3 finite numbers"),
    (lambda d: d["shapes"][0].update(emission="hot"), "shapes[0].emission", "non-negative"),
    (lambda d: d["shapes"][0].update(radius=-1), "shapes[0].radius", "must be positive"),
    (lambda d: d["shapes"][4].update(scale=2), "shapes[4]", "unknown 'scale'"),
    (lambda d: d["materials"].update(gold="gold.binary"), "materials.gold", "no such file"),
    (lambda d: d["materials"].update(gold="lambert(albedo=2)"), "materials.gold", "albedo"),
])
def test_scene_values_of_the_wrong_type_name_file_and_path(tmp_path, change, where, fragment):
    doc = _scene_document(tmp_path)
    change(doc)
    path = tmp_path / "scene.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(FormatError) as e:
        render.load(path, "lambert")
    assert str(e.value).startswith(f"{path}:{where}: "), str(e.value)
    assert fragment in str(e.value), str(e.value)


def test_scene_compile_errors_name_the_file_and_the_material(tmp_path):
    doc = _scene_document(tmp_path)
    doc["materials"]["spectral"] = str(tmp_path / "spectral.csv")
    (tmp_path / "spectral.csv").write_bytes(
        (Path(__file__).parents[1] / "data" / "gonio_spectral.csv").read_bytes())
    doc["shapes"][0]["material"] = "spectral"
    path = tmp_path / "scene.json"
    path.write_text(json.dumps(doc))
    scene = render.load(path, "lambert")
    with pytest.raises(InputError) as e:
        scene.compile()
    assert str(e.value).startswith(f"{path}: material 'spectral': "), str(e.value)


def test_mesh_shapes_refuse_images_and_deep_json(tmp_path):
    doc = _scene_document(tmp_path)
    doc["shapes"][4]["file"] = "alb.png"
    path = tmp_path / "scene.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(FormatError, match=r"shapes\[4\]\.file: .*expected a mesh file"):
        render.load(path, "lambert")
    path.write_text('{"shapes": ' + "[" * 5000 + "]" * 5000 + "}")
    with pytest.raises(FormatError, match=r"scene\.json:line 1: nested more than 100"):
        render.load(path, "lambert")
    toml = tmp_path / "scene.toml"
    toml.write_text("shapes = " + "[" * 5000 + "]" * 5000 + "\n")
    with pytest.raises(FormatError, match=r"scene\.toml:line 1: nested more than 100"):
        render.load(toml, "lambert")


def test_scene_file_syntax_errors(tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text('{"camera": {}\n,,}')
    with pytest.raises(FormatError, match=r"bad\.json:line 2: not valid JSON"):
        render.load(bad)
    bad = tmp_path / "bad.toml"
    bad.write_text("[camera\nfov = 3\n")
    with pytest.raises(FormatError, match=r"bad\.toml: not valid TOML"):
        render.load(bad)
    with pytest.raises(FormatError, match=r"none\.json: no such file"):
        render.load(tmp_path / "none.json")
    doc = tmp_path / "uses.json"
    doc.write_text(json.dumps({"shapes": [{"type": "sphere", "centre": [0, 0, 0], "radius": 1,
                                           "material": "@material"}]}))
    with pytest.raises(FormatError, match=r"shapes\[0\]: uses @material"):
        render.load(doc)
