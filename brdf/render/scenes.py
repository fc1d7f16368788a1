"""Built-in scenes and the scene file format (JSON or TOML).

Built-in scenes take the material to show (a model, spec, report path or table):

- ``cornell``: Mitsuba 3's ``cornell_box()`` (same geometry, diffuse colours, light, camera),
  the material on the two boxes (white diffuse when None, as in Mitsuba's);
- ``sphere``: the lit sphere of BRDF Explorer: a unit sphere under a key light (directional,
  from the upper left front) and a dim constant environment;
- ``furnace``: a unit sphere inside a uniform environment of radiance 1: every pixel on the
  sphere converges to the material's directional albedo towards the camera;
- ``plane-point``: a 4 x 4 plane (y = 0) under a point light 1 unit above its centre: radiance
  f I cos(theta) / r^2 in closed form.

Scene files hold ``camera``, ``materials`` (name -> spec, path or {brdf, textures}),
``shapes``, ``lights`` and ``environment``; see :func:`load` for the keys. A shape whose
material is ``"@material"`` takes the material given on the command line.
"""

import math
from pathlib import Path

import numpy as np

from ..errors import BRDFError, FormatError, InputError
from .scene import (Camera, DirectionalLight, Environment, GoniometricLight, Material, Mesh,
                    PointLight, Quad, Scene, Sphere, SpotLight, box, rectangle)

__all__ = ["BUILTIN", "builtin", "cornell", "lit_sphere", "furnace", "plane_point", "load"]

#: Mitsuba 3's cornell_box(): colours of its diffuse BSDFs and the light's radiance
CORNELL_WHITE = (0.885809, 0.698859, 0.666422)
CORNELL_GREEN = (0.105421, 0.37798, 0.076425)
CORNELL_RED = (0.570068, 0.0430135, 0.0443706)
CORNELL_LIGHT = (18.387, 13.9873, 6.75357)


def _rotation_x(deg):
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def _rotation_y(deg):
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def _affine(rot=np.eye(3), scale=(1.0, 1.0, 1.0), translate=(0.0, 0.0, 0.0)):
    """4 x 4 matrix: translate . rotate . scale (Mitsuba's composition order)."""
    T = np.eye(4)
    T[:3, :3] = np.asarray(rot) @ np.diag(scale)
    T[:3, 3] = translate
    return T


def cornell(material=None):
    """Mitsuba 3's ``cornell_box()`` scene (its transforms, written out)."""
    from ..models import Lambert
    white = Lambert(albedo=list(CORNELL_WHITE))
    green = Lambert(albedo=list(CORNELL_GREEN))
    red = Lambert(albedo=list(CORNELL_RED))
    boxes = white if material is None else material
    shapes = [
        rectangle(_affine(_rotation_x(-90), translate=(0, -1, 0)), white),          # floor
        rectangle(_affine(_rotation_x(90), translate=(0, 1, 0)), white),            # ceiling
        rectangle(_affine(translate=(0, 0, -1)), white),                            # back
        rectangle(_affine(_rotation_y(-90), translate=(1, 0, 0)), green),           # green wall
        rectangle(_affine(_rotation_y(90), translate=(-1, 0, 0)), red),             # red wall
        rectangle(_affine(_rotation_x(90), (0.23, 0.19, 0.19), (0, 0.99, 0.01)), white,
                  emission=CORNELL_LIGHT),                                            # light
    ]
    shapes += box(_affine(_rotation_y(-17), (0.3, 0.3, 0.3), (0.335, -0.7, 0.38)), boxes)
    shapes += box(_affine(_rotation_y(18.25), (0.3, 0.61, 0.3), (-0.33, -0.4, -0.28)), boxes)
    camera = Camera(origin=(0, 0, 3.9), target=(0, 0, 0), up=(0, 1, 0), fov=39.3077,
                    fov_axis="smaller")
    return Scene(camera, shapes)


def lit_sphere(material):
    """BRDF Explorer's lit-sphere view: key light plus a dim environment."""
    camera = Camera(origin=(0, 0, 4.0), target=(0, 0, 0), up=(0, 1, 0), fov=32.0)
    key = DirectionalLight(direction=-np.array([-1.0, 1.0, 1.0]) / math.sqrt(3.0),
                           irradiance=3.0)
    return Scene(camera, [Sphere((0, 0, 0), 1.0, material)], [key], Environment(0.1))


def furnace(material):
    """White furnace: a unit sphere in a uniform environment of radiance 1."""
    camera = Camera(origin=(0, 0, 4.0), target=(0, 0, 0), up=(0, 1, 0), fov=32.0)
    return Scene(camera, [Sphere((0, 0, 0), 1.0, material)], [], Environment(1.0))


def plane_point(material, height=1.0, intensity=1.0, attenuation=(1.0, 0.0, 0.0)):
    """A 4 x 4 plane at y = 0 under a point light ``height`` above its centre, seen from above
    at 45 degrees."""
    camera = Camera(origin=(0, 3.0, 3.0), target=(0, 0, 0), up=(0, 1, 0), fov=40.0)
    plane = Quad((-2.0, 0.0, 2.0), (4.0, 0.0, 0.0), (0.0, 0.0, -4.0), material)
    return Scene(camera, [plane], [PointLight((0, height, 0), intensity, attenuation)])


BUILTIN = {"cornell": cornell, "sphere": lit_sphere, "furnace": furnace,
           "plane-point": plane_point}


def builtin(name, material=None):
    """Built-in scene ``name`` showing ``material``."""
    if name not in BUILTIN:
        raise InputError(f"unknown scene {name!r}; built-in scenes: {', '.join(BUILTIN)} (or a "
                         ".json/.toml scene file)")
    if material is None and name != "cornell":
        raise InputError(f"scene {name}: needs a material")
    return BUILTIN[name](material)


# --- scene files --------------------------------------------------------------------------------

#: Largest scene file read (scenes are small; meshes and images live in their own files).
SCENE_BYTES = 16 << 20

_TOP = ("camera", "materials", "shapes", "lights", "environment")
_CAMERA = {"origin": "vector", "target": "vector", "up": "vector", "fov": "number",
           "fov_axis": "text"}
_SURFACE = {"material": "text", "emission": "colour", "sides": "text"}
#: The keys of each shape type and what their values must be.
_SHAPE_KEYS = {
    "sphere": {"centre": "vector", "radius": "number", **_SURFACE},
    "quad": {"corner": "vector", "edge1": "vector", "edge2": "vector", **_SURFACE},
    "rectangle": {"to_world": "matrix", **_SURFACE},
    "box": {"to_world": "matrix", "material": "text"},
    "mesh": {"file": "text", "to_world": "matrix", "material": "text"},
}
_SHAPE_REQUIRED = {"sphere": ("centre", "radius"), "quad": ("corner", "edge1", "edge2"),
                   "rectangle": ("to_world",), "box": ("to_world",), "mesh": ("file",)}
_POINT = {"position": "vector", "intensity": "colour", "attenuation": "vector"}
_LIGHT_KEYS = {
    "point": _POINT,
    "spot": {**_POINT, "direction": "vector", "cutoff": "number", "exponent": "number"},
    "directional": {"direction": "vector", "irradiance": "colour"},
    "goniometric": {**_POINT, "ies": "text", "axis": "vector", "phi_axis": "vector"},
}
_LIGHT_REQUIRED = {"point": ("position",), "spot": ("position", "direction"),
                   "directional": ("direction",), "goniometric": ("position", "ies")}
_ENVIRONMENT = {"radiance": "colour", "map": "text", "up": "vector"}
_MATERIAL = {"brdf": "text", "textures": "table"}
_SHAPES = tuple(_SHAPE_KEYS)
_LIGHTS = tuple(_LIGHT_KEYS)
#: What a value of each kind must be, for the messages.
_EXPECTED = {"vector": "a list of 3 finite numbers", "number": "a finite number",
             "colour": "a non-negative number or a list of 3", "text": "a string",
             "matrix": "a 4 x 4 matrix (a list of 4 lists of 4 finite numbers)",
             "table": "a table of names to image paths"}
def load(path, material=None):
    """A :class:`Scene` from a JSON or TOML file (relative paths are relative to the file).

    Keys: ``camera`` {origin, target, up, fov, fov_axis}; ``materials`` {name: spec or path, or
    {brdf, textures: {"lobe.param": image}}}; ``shapes`` [{type: sphere (centre, radius) | quad
    (corner, edge1, edge2) | rectangle (to_world) | box (to_world) | mesh (file, to_world),
    material, emission, sides}]; ``lights`` [{type: point (position, intensity, attenuation) |
    spot (+ direction, cutoff, exponent) | directional (direction, irradiance) | goniometric
    (position, ies, intensity, axis, phi_axis)}]; ``environment`` {radiance, map, up}.

    The file is read as TOML when its name ends in ``.toml``, as JSON otherwise. Every key and
    value is checked here, and the materials are resolved (specs parsed, files read): errors
    name the file and the place (``scene.json:shapes[0].radius: ...``,
    ``scene.json:materials.paint: ...``). Errors found when the scene is compiled for
    rendering name the file and the shape or material too (see :attr:`Scene.source`).
    """
    from ..io.files import parse_json, parse_toml, read_text
    path = Path(path)
    toml = path.suffix.lower() == ".toml"
    what = f"a {'TOML' if toml else 'JSON'} scene file"
    text = read_text(path, SCENE_BYTES, what)
    doc = (parse_toml if toml else parse_json)(path, text, what)
    if not isinstance(doc, dict):
        raise FormatError(path, "", "expected a table of camera, materials, shapes, lights")
    return _SceneFile(path, doc, material).scene()


class _SceneFile:
    def __init__(self, path, doc, material):
        self.path, self.doc, self.cli_material = path, doc, material
        self.base = path.parent
        unknown = set(doc) - set(_TOP)
        if unknown:
            self.fail("top level", f"unknown keys {sorted(unknown)}; expected camera, materials, "
                      "shapes, lights, environment")

    def fail(self, where, expected):
        raise FormatError(self.path, where, expected)

    def file(self, name):
        p = Path(name)
        return str(p if p.is_absolute() else self.base / p)

    def section(self, key, kind):
        """The top-level ``key``: a table (``dict``) or a list, empty when missing."""
        value = self.doc.get(key, kind())
        if not isinstance(value, kind):
            self.fail(key, f"expected {'a table' if kind is dict else 'a list'}, got "
                      f"{type(value).__name__}")
        return value

    def values(self, where, entry, keys, what, required=()):
        """``entry`` (a table) with each value checked against ``keys`` (name -> kind)."""
        if not isinstance(entry, dict):
            self.fail(where, f"expected a table, got {type(entry).__name__}")
        unknown = sorted(set(entry) - set(keys))
        if unknown:
            self.fail(where, f"bad keys for {what} (unknown {', '.join(map(repr, unknown))}); "
                      f"keys: {', '.join(keys)}")
        missing = [k for k in required if k not in entry]
        if missing:
            self.fail(where, f"bad keys for {what} (missing {', '.join(map(repr, missing))}); "
                      f"keys: {', '.join(keys)}")
        for key, value in entry.items():
            if not _is(keys[key], value):
                self.fail(f"{where}.{key}", f"expected {_EXPECTED[keys[key]]}, got "
                          f"{_shown(value)}")
        return dict(entry)

    def scene(self):
        cam = self.values("camera", self.section("camera", dict), _CAMERA, "the camera")
        camera = Camera(**cam)
        mats = {name: self.material(name, m)
                for name, m in self.section("materials", dict).items()}
        shapes = []
        for i, s in enumerate(self.section("shapes", list)):
            shapes.extend(self.shape(i, s, mats))
        lights = [self.light(i, x) for i, x in enumerate(self.section("lights", list))]
        env = self.doc.get("environment")
        if env is not None:
            env = self.values("environment", env, _ENVIRONMENT, "the environment")
            if "map" in env:
                env["map"] = self.file(env["map"])
            env = Environment(**env)
        return Scene(camera, shapes, lights, env, source=str(self.path))

    def material(self, name, m):
        where = f"materials.{name}"
        if isinstance(m, dict):
            m = self.values(where, m, _MATERIAL, "a material", ("brdf",))
            textures = m.get("textures", {})
            for k, v in textures.items():
                if not isinstance(v, str):
                    self.fail(f"{where}.textures.{k}", f"expected an image path, got "
                              f"{_shown(v)}")
            brdf, tex = m["brdf"], {k: self.file(v) for k, v in textures.items()}
        elif isinstance(m, str):
            brdf, tex = m, {}
        else:
            self.fail(where, "expected a spec, a path or {brdf, textures}")
        try:
            return Material(self.subject(brdf), tex, name=name)
        except BRDFError as e:
            self.fail(where, str(e))

    def subject(self, text):
        """The model or table a material's ``brdf`` names: a file beside the scene (a table or
        a fit report, by its extension), else a spec."""
        from ..io import formats
        from ..spec import parse
        suffix = Path(text).suffix.lower()
        names_file = "(" not in text and (
            suffix == ".json" or any(suffix in m.EXTENSIONS for m in formats().values())
            or (self.base / text).exists())
        if not names_file:
            return parse(text)
        return Material(self.file(text)).resolve()

    def typed(self, where, entry, kinds):
        """``(type, the other keys)`` of a shape or light entry whose type is one of ``kinds``."""
        kind = entry.get("type") if isinstance(entry, dict) else None
        if not isinstance(kind, str) or kind not in kinds:
            self.fail(where, f"type must be one of {', '.join(kinds)}, got {_shown(kind)}")
        rest = dict(entry)
        rest.pop("type")
        return kind, rest

    def shape(self, i, s, mats):
        where = f"shapes[{i}]"
        kind, s = self.typed(where, s, _SHAPES)
        s = self.values(where, s, _SHAPE_KEYS[kind], f"a {kind}", _SHAPE_REQUIRED[kind])
        name = s.pop("material", None)
        if name == "@material":
            mat = self.cli_material
            if mat is None:
                self.fail(where, "uses @material, but no material was given")
        elif name is None:
            mat = None
        elif name in mats:
            mat = mats[name]
        else:
            self.fail(where, f"material {name!r} is not in materials ({', '.join(mats) or 'none'})")
        if kind == "sphere":
            if not s["radius"] > 0:
                self.fail(f"{where}.radius", f"must be positive, got {s['radius']}")
            return [Sphere(material=mat, label=where, **s)]
        if kind == "quad":
            return [Quad(material=mat, label=where, **s)]
        if kind == "rectangle":
            return [rectangle(material=mat, label=where, **s)]
        if kind == "box":
            return box(material=mat, label=where, **s)
        file = self.file(s["file"])
        try:
            mesh = Mesh.read(file, mat, s.get("to_world"))
        except BRDFError as e:
            self.fail(f"{where}.file", str(e))
        mesh.label = where
        return [mesh]

    def light(self, i, x):
        where = f"lights[{i}]"
        kind, x = self.typed(where, x, _LIGHTS)
        x = self.values(where, x, _LIGHT_KEYS[kind], f"a {kind} light", _LIGHT_REQUIRED[kind])
        if kind == "point":
            return PointLight(label=where, **x)
        if kind == "spot":
            return SpotLight(label=where, **x)
        if kind == "directional":
            return DirectionalLight(label=where, **x)
        ies = self.file(x.pop("ies"))
        try:
            return GoniometricLight.from_ies(ies, label=where, **x)
        except BRDFError as e:
            self.fail(f"{where}.ies", str(e))


def _is(kind, value):
    """Whether a scene file's ``value`` is of ``kind`` (see :data:`_EXPECTED`)."""
    def finite(x):
        return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)
    if kind == "number":
        return finite(value)
    if kind == "vector":
        return isinstance(value, list) and len(value) == 3 and all(map(finite, value))
    if kind == "colour":
        return (finite(value) and value >= 0) or (
            isinstance(value, list) and len(value) == 3 and all(finite(v) and v >= 0
                                                                 for v in value))
    if kind == "matrix":
        return (isinstance(value, list) and len(value) == 4 and all(
            isinstance(row, list) and len(row) == 4 and all(map(finite, row)) for row in value))
    if kind == "table":
        return isinstance(value, dict)
    return isinstance(value, str)


def _shown(value):
    """A value for a message, cut to 60 characters."""
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."
