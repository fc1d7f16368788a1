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

import json
import math
from pathlib import Path

import numpy as np

from ..errors import FormatError, InputError
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

_SHAPES = ("sphere", "quad", "rectangle", "box", "mesh")
_LIGHTS = ("point", "spot", "directional", "goniometric")


def load(path, material=None):
    """A :class:`Scene` from a JSON or TOML file (relative paths are relative to the file).

    Keys: ``camera`` {origin, target, up, fov, fov_axis}; ``materials`` {name: spec or path, or
    {brdf, textures: {"lobe.param": image}}}; ``shapes`` [{type: sphere (centre, radius) | quad
    (corner, edge1, edge2) | rectangle (to_world) | box (to_world) | mesh (file, to_world),
    material, emission, sides}]; ``lights`` [{type: point (position, intensity, attenuation) |
    spot (+ direction, cutoff, exponent) | directional (direction, irradiance) | goniometric
    (position, ies, intensity, axis, phi_axis)}]; ``environment`` {radiance, map, up}.
    """
    path = Path(path)
    if not path.exists():
        raise InputError(f"{path}: no such scene file")
    text = path.read_text(encoding="utf-8")
    try:
        if path.suffix.lower() == ".toml":
            import tomllib
            doc = tomllib.loads(text)
        else:
            doc = json.loads(text)
    except json.JSONDecodeError as e:
        raise FormatError(path, e.lineno, f"not valid JSON ({e.msg})") from None
    except Exception as e:  # tomllib.TOMLDecodeError
        raise FormatError(path, "", f"not valid TOML ({e})") from None
    if not isinstance(doc, dict):
        raise FormatError(path, "", "expected a table of camera, materials, shapes, lights")
    return _SceneFile(path, doc, material).scene()


class _SceneFile:
    def __init__(self, path, doc, material):
        self.path, self.doc, self.cli_material = path, doc, material
        self.base = path.parent
        unknown = set(doc) - {"camera", "materials", "shapes", "lights", "environment"}
        if unknown:
            self.fail("top level", f"unknown keys {sorted(unknown)}; expected camera, materials, "
                      "shapes, lights, environment")

    def fail(self, where, expected):
        raise FormatError(self.path, where, expected)

    def file(self, name):
        p = Path(name)
        return str(p if p.is_absolute() else self.base / p)

    def scene(self):
        cam = self.doc.get("camera", {})
        try:
            camera = Camera(**cam)
        except TypeError as e:
            self.fail("camera", f"{e}; keys: origin, target, up, fov, fov_axis")
        mats = {name: self.material(name, m) for name, m in self.doc.get("materials", {}).items()}
        shapes = []
        for i, s in enumerate(self.doc.get("shapes", [])):
            shapes.extend(self.shape(i, s, mats))
        lights = [self.light(i, x) for i, x in enumerate(self.doc.get("lights", []))]
        env = self.doc.get("environment")
        if env is not None:
            env = dict(env)
            if "map" in env:
                env["map"] = self.file(env["map"])
            try:
                env = Environment(**env)
            except TypeError as e:
                self.fail("environment", f"{e}; keys: radiance, map, up")
        return Scene(camera, shapes, lights, env)

    def material(self, name, m):
        def brdf_of(b):
            return self.file(b) if isinstance(b, str) and "(" not in b and (
                self.base / b).exists() else b
        if isinstance(m, str):
            return Material(brdf_of(m))
        if isinstance(m, dict) and "brdf" in m:
            tex = {k: self.file(v) for k, v in m.get("textures", {}).items()}
            return Material(brdf_of(m["brdf"]), tex)
        self.fail(f"materials.{name}", "expected a spec, a path or {brdf, textures}")

    def typed(self, where, entry, kinds):
        """``(type, the other keys)`` of a shape or light entry whose type is one of ``kinds``."""
        kind = entry.get("type") if isinstance(entry, dict) else None
        if kind not in kinds:
            self.fail(where, f"type must be one of {', '.join(kinds)}, got {kind!r}")
        rest = dict(entry)
        rest.pop("type")
        return kind, rest

    def shape(self, i, s, mats):
        where = f"shapes[{i}]"
        kind, s = self.typed(where, s, _SHAPES)
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
        try:
            if kind == "sphere":
                return [Sphere(material=mat, **s)]
            if kind == "quad":
                return [Quad(material=mat, **s)]
            if kind == "rectangle":
                return [rectangle(material=mat, **s)]
            if kind == "box":
                return box(material=mat, **s)
            return [Mesh.read(self.file(s.pop("file")), mat, s.pop("to_world", None))]
        except (TypeError, KeyError) as e:
            self.fail(where, f"bad keys for a {kind} ({e})")

    def light(self, i, x):
        where = f"lights[{i}]"
        kind, x = self.typed(where, x, _LIGHTS)
        try:
            if kind == "point":
                return PointLight(**x)
            if kind == "spot":
                return SpotLight(**x)
            if kind == "directional":
                return DirectionalLight(**x)
            return GoniometricLight.from_ies(self.file(x.pop("ies")), **x)
        except (TypeError, KeyError) as e:
            self.fail(where, f"bad keys for a {kind} light ({e})")
