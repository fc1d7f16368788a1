"""Captures rendered by Mitsuba 3, the independent renderer, for the inverse-rendering tests and
``benchmarks/bench_inverse.py``: a ``lambert + ggx`` sphere (a) alone under a point light and
(b) on a diffuse floor under an area light, with our scene file describing the same camera,
geometry and lights.

The correspondence (checked pixel by pixel against our renderer): Mitsuba's ``perspective``
sensor with ``look_at(origin, target, up)``, ``fov`` along ``fov_axis`` x, is our ``Camera``;
a ``box`` reconstruction filter makes each pixel the mean over its area, as our camera's
jittered rays; a ``point`` emitter's ``intensity`` is our point light's W/sr; an ``area``
emitter's ``radiance`` on a ``rectangle`` (our ``rectangle``, both facing +z of ``to_world``)
is our emission. The BRDF is Mitsuba's ``blendbsdf`` of ``diffuse`` and ``roughconductor``
(GGX, material none: F = 1, separable Smith masking) with weight 1/2 and each reflectance
doubled: f = albedo / pi + ks D G1 G1 / (4 cos cos), our ``lambert + ggx`` (Fresnel none,
masking separable), written here from Mitsuba's plugin documentation, not from our export.
"""

import json
import math

import numpy as np

#: The truth of both cases.
ALBEDO = (0.45, 0.30, 0.18)
KS = (0.35, 0.35, 0.35)
ALPHA = 0.22
TRUTH_SPEC = (f"lambert(albedo=[{','.join(map(str, ALBEDO))}]) + "
              f"ggx(alpha={ALPHA}, ks=[{','.join(map(str, KS))}], masking=separable, "
              "fresnel=none)")
TRUTH = {**{f"lambert.albedo[{c}]": v for c, v in enumerate(ALBEDO)},
         **{f"ggx.ks[{c}]": v for c, v in enumerate(KS)}, "ggx.alpha": ALPHA}
#: The floor's known diffuse albedo in case (b) and in the reference-target captures.
FLOOR_ALBEDO = 0.6

CAMERA = {"origin": [0.0, 0.6, 4.0], "target": [0.0, 0.0, 0.0], "up": [0.0, 1.0, 0.0],
          "fov": 36.0, "fov_axis": "x"}
POINT = {"position": [2.5, 2.5, 3.0], "intensity": 12.0}


def _mitsuba():
    import mitsuba as mi
    mi.set_variant("scalar_rgb")
    return mi


def _bsdf():
    rgb = lambda v: {"type": "rgb", "value": [2.0 * x for x in v]}  # noqa: E731
    return {"type": "blendbsdf", "weight": 0.5,
            "a": {"type": "diffuse", "reflectance": rgb(ALBEDO)},
            "b": {"type": "roughconductor", "distribution": "ggx", "alpha": ALPHA,
                  "material": "none", "specular_reflectance": rgb(KS)}}


def _sensor(mi, width, height, spp):
    return {"type": "perspective", "fov": CAMERA["fov"], "fov_axis": CAMERA["fov_axis"],
            "to_world": mi.ScalarTransform4f().look_at(origin=CAMERA["origin"],
                                                       target=CAMERA["target"],
                                                       up=CAMERA["up"]),
            "film": {"type": "hdrfilm", "width": width, "height": height,
                     "rfilter": {"type": "box"}, "pixel_format": "rgb"},
            "sampler": {"type": "independent", "sample_count": spp}}


def _floor_matrix():
    """to_world of the floor: the square [-1, 1]^2 scaled to 3 x 3, turned to face +y, at
    y = -1 (under the unit sphere)."""
    return [[3.0, 0.0, 0.0, 0.0], [0.0, 0.0, 3.0, -1.0], [0.0, -3.0, 0.0, 0.0],
            [0.0, 0.0, 0.0, 1.0]]


def _light_matrix():
    """to_world of the area light: a 0.6 x 0.6 square 3 above the floor, facing down."""
    return [[0.3, 0.0, 0.0, 0.8], [0.0, 0.0, -0.3, 2.2], [0.0, 0.3, 0.0, 1.0],
            [0.0, 0.0, 0.0, 1.0]]


AREA_RADIANCE = 30.0


def render_case(case, width=64, height=48, spp=512, seed=0, max_depth=-1, floor=None):
    """Mitsuba's image (h, w, 3) of case ``"a"`` (sphere, point light) or ``"b"`` (sphere on
    a diffuse floor, area light); ``floor`` adds the diffuse floor to case a (a reference
    target of known albedo); ``max_depth`` 2 renders direct light only."""
    mi = _mitsuba()
    d = scene_dict(mi, case, width, height, spp, max_depth, floor)
    img = mi.render(mi.load_dict(d), spp=spp, seed=seed)
    return np.array(img, dtype=float)[..., :3]


def scene_dict(mi, case, width, height, spp, max_depth=-1, floor=None, integrator="path"):
    """Mitsuba's scene dictionary of :func:`render_case` (``integrator`` ``prb`` for its
    differentiable rendering), in the variant ``mi`` has set."""
    d = {"type": "scene", "integrator": {"type": integrator, "max_depth": max_depth},
         "sensor": _sensor(mi, width, height, spp),
         "sphere": {"type": "sphere", "center": [0, 0, 0], "radius": 1.0, "bsdf": _bsdf()}}
    if case == "a":
        d["light"] = {"type": "point", "position": POINT["position"],
                      "intensity": {"type": "rgb", "value": [POINT["intensity"]] * 3}}
    if case == "b" or floor:
        d["floor"] = {"type": "rectangle", "to_world": mi.ScalarTransform4f(_floor_matrix()),
                      "bsdf": {"type": "diffuse",
                               "reflectance": {"type": "rgb", "value": [FLOOR_ALBEDO] * 3}}}
    if case == "b":
        d["light"] = {"type": "rectangle", "to_world": mi.ScalarTransform4f(_light_matrix()),
                      "emitter": {"type": "area", "radiance": {"type": "rgb",
                                                                "value": [AREA_RADIANCE] * 3}}}
    return d


def scene_file(path, case, floor=None):
    """Write our JSON scene file of the case (the sphere's material ``@material``)."""
    doc = {"camera": CAMERA, "materials": {"floor": f"lambert(albedo={FLOOR_ALBEDO})"},
           "shapes": [{"type": "sphere", "centre": [0, 0, 0], "radius": 1.0,
                       "material": "@material"}], "lights": []}
    if case == "a":
        doc["lights"].append({"type": "point", **POINT})
    if case == "b" or floor:
        doc["shapes"].append({"type": "rectangle", "to_world": _floor_matrix(),
                              "material": "floor"})
    if case == "b":
        doc["shapes"].append({"type": "rectangle", "to_world": _light_matrix(),
                              "emission": AREA_RADIANCE})
    with open(path, "w") as f:
        json.dump(doc, f, indent=1)
    return path


def photograph(linear, photons, exposure, seed=0):
    """A noisy 8-bit sRGB photograph (h, w, 3) uint8 of a linear image taken with an exposure
    ``exposure`` times the calibrated one: Poisson photon counts with ``photons`` expected at
    linear value 1 and calibrated exposure (the camera's gain: ``photons`` counts per unit
    value), then the sRGB encoding (IEC 61966-2-1) and rounding to 8 bits."""
    rng = np.random.default_rng(seed)
    counts = rng.poisson(np.maximum(linear, 0.0) * exposure * photons)
    v = np.clip(counts / photons, 0.0, 1.0)
    c = np.where(v <= 0.0031308, 12.92 * v, 1.055 * v ** (1.0 / 2.4) - 0.055)
    return np.round(c * 255.0).astype(np.uint8)


def max_relative_error(params, truth=TRUTH):
    return max(abs(params[k] - v) / v for k, v in truth.items())


__all__ = ["render_case", "scene_dict", "scene_file", "photograph", "max_relative_error", "TRUTH", "TRUTH_SPEC",
           "FLOOR_ALBEDO"]


def render_sky(direction, width=48, height=36, spp=256, sky=0.3, irradiance=3.0, seed=0,
               origin=None):
    """Mitsuba's image of the sphere under a directional light (``direction`` of travel,
    ``irradiance`` W/m^2) and a constant environment of radiance ``sky``, direct light only;
    ``origin`` moves the camera (a second view)."""
    mi = _mitsuba()
    sensor = _sensor(mi, width, height, spp)
    if origin is not None:
        sensor["to_world"] = mi.ScalarTransform4f().look_at(origin=origin, target=[0, 0, 0],
                                                             up=[0, 1, 0])
    d = {"type": "scene", "integrator": {"type": "path", "max_depth": 2}, "sensor": sensor,
         "sphere": {"type": "sphere", "center": [0, 0, 0], "radius": 1.0, "bsdf": _bsdf()},
         "sun": {"type": "directional", "direction": list(direction),
                 "irradiance": {"type": "rgb", "value": [irradiance] * 3}},
         "sky": {"type": "constant", "radiance": {"type": "rgb", "value": [sky] * 3}}}
    return np.array(mi.render(mi.load_dict(d), spp=spp, seed=seed), dtype=float)[..., :3]


def sky_file(path, direction, sky=0.3, irradiance=3.0, origin=None):
    """Our scene file of :func:`render_sky`."""
    camera = dict(CAMERA, origin=list(origin)) if origin is not None else CAMERA
    doc = {"camera": camera,
           "shapes": [{"type": "sphere", "centre": [0, 0, 0], "radius": 1.0,
                       "material": "@material"}],
           "lights": [{"type": "directional", "direction": list(direction),
                       "irradiance": irradiance}],
           "environment": {"radiance": sky}}
    with open(path, "w") as f:
        json.dump(doc, f, indent=1)
    return path
