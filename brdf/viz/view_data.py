"""What the interactive explorer (:mod:`brdf.viz.explorer`) draws, as plain arrays.

Each function takes a model (or anything with ``eval`` and ``albedo``) and returns numpy arrays,
with no browser and no plotting library involved, so every view is tested on its own and the
explorer's update after a slider moves costs only these evaluations (``benchmarks/
bench_explore.py``): the lobe mesh, the in-plane curve, the directional albedo curve, the lit
sphere's and lit object's direct-lighting previews, and the sliders a model's declarations
call for.
"""

import functools
import math
import os
from dataclasses import dataclass

import numpy as np

from ..errors import BRDFError, InputError
from ..geometry import (directions_from_half_diff, frame_from_normal, spherical_to_cartesian,
                        to_local)
from .lobes import LOG_DECADES, lobe_values
from .samples import in_plane, in_plane_directions, is_table, samples_near

__all__ = ["Slider", "parameter_sliders", "with_parameter", "lobe_mesh", "lobe_radius",
           "polar_curve", "measured_in_plane", "measured_near", "slice_image", "albedo_curve",
           "sphere_preview", "sphere_render", "object_preview", "object_render", "lit_object",
           "torus_mesh", "to_rgba", "KEY_LIGHT", "KEY_IRRADIANCE", "ENVIRONMENT",
           "CAMERA_DISTANCE", "CAMERA_FOV", "TORUS_RADII", "TORUS_TILT", "TORUS_SEGMENTS",
           "sky_map", "sky_lights", "map_lights", "map_lights_of", "MapStrata", "map_strata",
           "map_strata_of_counts",
           "sky_strata", "TableSampler", "table_sampler", "environment_map", "SKY_SHAPE",
           "SKY_LIGHTS"]

#: The preview's key light: towards the light from the sphere, upper left in front, and its
#: irradiance normal to it (the path tracer's ``lit_sphere`` scene, brdf.render.scenes).
KEY_LIGHT = np.array([-1.0, 1.0, 1.0]) / math.sqrt(3.0)
KEY_IRRADIANCE = 3.0
#: Radiance of the uniform environment around the sphere (``lit_sphere``'s Environment(0.1)).
ENVIRONMENT = 0.1
#: The preview's pinhole camera: on +z at this distance from the unit sphere's centre, looking
#: at it, with this horizontal field of view in degrees (``lit_sphere``'s camera).
CAMERA_DISTANCE, CAMERA_FOV = 4.0, 32.0
#: Slider range of a parameter whose fit box is unbounded: this factor either side of its value.
OPEN_RANGE = 10.0


# -- sliders ----------------------------------------------------------------------------------

@dataclass(frozen=True)
class Slider:
    """One slider: the flat parameter name (``"ggx.alpha"``, ``"lambert.albedo[1]"``), its
    value, range and scale (``log`` where the declaration's prior is log); ``splits`` when the
    parameter is declared per channel but holds one value (it can become one per channel)."""

    name: str
    value: float
    low: float
    high: float
    log: bool
    units: str = ""
    doc: str = ""
    splits: bool = False


def _components(model):
    """``(prefix, component)`` of every lobe and nested component (a Fresnel term), with the
    prefix of its flat names (``"ggx."``, ``"ggx.fresnel."``)."""
    from ..models.base import Component
    names = model.lobe_names() if hasattr(model, "lobe_names") else [model.name]
    stack = [(f"{name}.", lobe) for name, lobe in zip(names, model.lobes)]
    while stack:
        prefix, component = stack.pop(0)
        yield prefix, component
        for key, value in component.values.items():
            if isinstance(value, Component):
                stack.append((f"{prefix}{key}.", value))


def _range(decl, value):
    """Slider range: the declaration's fit box, closed where it is open, inside its bounds."""
    low, high = decl.fit_bounds
    low, high = max(low, decl.bounds[0]), min(high, decl.bounds[1])
    scale = max(abs(value), 1e-3)
    if not math.isfinite(low):
        low = min(value, -scale * OPEN_RANGE)
    if not math.isfinite(high):
        high = max(value, scale * OPEN_RANGE)
    if decl.prior == "log" and low <= 0.0:
        low = min(value, high) / OPEN_RANGE ** 3 if value > 0 else high * 1e-4
    # a value outside the fit box (fits may leave it within the bounds) widens the slider
    return min(low, value), max(high, value)


def parameter_sliders(model):
    """The sliders of ``model``'s numeric parameters, from its families' declarations.

    One slider per scalar value and one per channel of a per-channel value given per channel
    (``lambert.albedo[0]`` ...); the range is the declaration's fit box (finite where fitting
    searches), log-scaled where the prior is log. Optional parameters left unset (``alpha_y``)
    and choices have no slider.
    """
    from ..models.base import Param
    sliders = []
    for prefix, component in _components(model):
        for decl in component.PARAMS:
            value = component.values.get(decl.name)
            if not isinstance(decl, Param) or value is None:
                continue
            entries = ([(f"{prefix}{decl.name}", float(value))] if value.ndim == 0 else
                       [(f"{prefix}{decl.name}[{i}]", float(v)) for i, v in enumerate(value)])
            for name, v in entries:
                low, high = _range(decl, v)
                sliders.append(Slider(name, v, low, high, decl.prior == "log", decl.units,
                                      decl.doc, decl.per_channel and value.ndim == 0))
    return sliders


def with_parameter(model, name, value):
    """A copy of ``model`` with the numeric parameter under flat name ``name`` set to
    ``value`` (validated as in a spec: out of bounds raises :class:`~brdf.errors.SpecError`)."""
    from ..models.base import Sum
    base, _, index = name.partition("[")
    head, _, rest = base.partition(".")
    names = model.lobe_names() if isinstance(model, Sum) else [model.name]
    if head not in names or not rest:
        raise InputError(f"{model}: no parameter {name!r}; parameters: "
                         f"{', '.join(model.params)}")
    k = names.index(head)

    def replace(component, path):
        key, _, deeper = path.partition(".")
        if deeper:
            return component.replace(**{key: replace(component[key], deeper)})
        if index:
            current = np.array(component[key], dtype=float)
            current[int(index.rstrip("]"))] = value
            return component.replace(**{key: current})
        return component.replace(**{key: value})

    lobes = list(model.lobes)
    lobes[k] = replace(lobes[k], rest)
    return Sum(lobes) if isinstance(model, Sum) else lobes[0]


# -- lobe, curves -----------------------------------------------------------------------------

def _hemisphere(resolution):
    theta = np.linspace(0.0, 0.5 * math.pi * (1 - 1e-6), resolution + 1)
    phi = np.linspace(0.0, 2.0 * math.pi, 2 * resolution, endpoint=False)
    return theta, phi


def lobe_radius(values, peak, log=False):
    """Radius drawn for values r >= 0: r / peak, or with ``log`` the decades above
    ``peak 10^-LOG_DECADES`` over LOG_DECADES (0 at and below that floor)."""
    if not log:
        return values / peak
    floor = peak * 10.0 ** -LOG_DECADES
    return np.clip(np.log10(np.maximum(values, floor) / floor) / LOG_DECADES, 0.0, None)


def lobe_mesh(model, wi, *, cosine=True, log=False, resolution=32, channel=None, peak=None):
    """The 3-D lobe of ``model`` at incidence ``wi`` as a triangle mesh (the picture of
    :func:`brdf.viz.lobe_surface`, without pyvista).

    The outgoing hemisphere on a (theta, phi) grid, each direction wo pushed out to r(wo) wo:
    r = f cos(theta_o) (``cosine``) or f, over ``peak`` (default: its maximum), or with ``log``
    the decades above ``peak 10^-LOG_DECADES`` over LOG_DECADES.

    Returns
    -------
    points : ndarray, shape (n, 3)
    triangles : ndarray of int, shape (m, 3)
        Indices into ``points``; the pole is one point, the azimuth closes without a seam.
    values : ndarray, shape (n,)
        r(wo) in 1/sr before scaling (the colour).
    peak : float
        The value drawn at radius 1.
    directions : ndarray, shape (n, 3)
        The unit directions wo of the points (to redraw at another peak: :func:`lobe_radius`).
    """
    theta, phi = _hemisphere(int(resolution))
    nt, nphi = len(theta), len(phi)
    wo = spherical_to_cartesian(theta[1:, None], phi[None, :]).reshape(-1, 3)
    wo = np.concatenate([[[0.0, 0.0, 1.0]], wo])
    values = lobe_values(model, np.asarray(wi, float), wo, cosine, channel)
    values = np.maximum(np.nan_to_num(values, nan=0.0), 0.0)
    top = float(values.max()) if peak is None else float(peak)
    if not top > 0.0:
        top = 1.0  # a lobe that is zero everywhere is drawn as a point, not refused
    points = wo * lobe_radius(values, top, log)[:, None]
    # rings of nphi points from index 1; ring k at 1 + k nphi
    j = np.arange(nphi)
    fan = np.stack([np.zeros(nphi, int), 1 + j, 1 + (j + 1) % nphi], axis=1)
    k = np.arange(nt - 2)[:, None]
    a = 1 + k * nphi + j
    b = 1 + k * nphi + (j + 1) % nphi
    quads = np.concatenate([np.stack([a, a + nphi, b], -1).reshape(-1, 3),
                            np.stack([b, a + nphi, b + nphi], -1).reshape(-1, 3)])
    return points, np.concatenate([fan, quads]), values, top, wo


def polar_curve(model, wi, *, cosine=False, step=1.0):
    """The BRDF in the plane of incidence of ``wi``: signed theta_o in degrees (negative on
    the incident side, as :func:`brdf.viz.inplane_plot`) and the values ``(n, C)``."""
    angles = np.arange(-89.0, 89.0 + step / 2, step)
    wi = np.asarray(wi, float)
    wo = in_plane_directions(wi, angles)
    f = np.asarray(model.eval(np.broadcast_to(wi, wo.shape), wo), float)
    return angles, f * wo[:, 2:3] if cosine else f


def measured_in_plane(table, wi, *, cosine=False):
    """A measured table's samples taken at the incidence ``wi`` and in its plane (those
    :func:`brdf.viz.samples.samples_near` finds, as :func:`brdf.viz.inplane_plot` draws them):
    signed theta_o in degrees (negative on the incident side) and the values ``(n, C)``, times
    cos(theta_o) with ``cosine``."""
    wi = np.asarray(wi, float)
    wo, values = samples_near(table, wi, plane=True)
    if not len(wo):
        return np.zeros(0), np.zeros((0, np.asarray(table.values).shape[-1]))
    signed = in_plane(wi, wo)[1]
    return signed, values * wo[:, 2:3] if cosine else values


def slice_image(model, phi_d=90.0, resolution=90):
    """The theta_h / theta_d image at a fixed phi_d (degrees) in the MERL layout, the picture of
    :func:`brdf.viz.slice_plot`: rows theta_d from 0 to 90 degrees (linear), columns theta_h
    with sqrt(theta_h / 90 deg) linear, as the MERL table spaces it (Matusik et al. 2003;
    docs/conventions.md section 6), pixel centres.

    Returns
    -------
    ndarray, shape (resolution, resolution, C)
        f_r in 1/sr, row 0 at theta_d = 0; NaN where a direction is below the horizon.
    """
    n = int(resolution)
    u = (np.arange(n) + 0.5) / n
    theta_h = 0.5 * math.pi * u ** 2
    theta_d = 0.5 * math.pi * u
    wi, wo = directions_from_half_diff(theta_h[None, :], 0.0, theta_d[:, None],
                                       math.radians(phi_d))
    f = np.asarray(model.eval(wi, wo), float)
    below = (wi[..., 2] <= 0) | (wo[..., 2] <= 0)
    f[below] = np.nan
    return f


def measured_near(table, wi, *, cosine=True):
    """A measured table's samples taken at the incidence ``wi`` (as
    :func:`brdf.viz.samples.samples_near` finds them, at most MAX_POINTS): their directions
    ``(n, 3)`` and r = f cos(theta_o) (or f) ``(n, C)``, the quantity of :func:`lobe_mesh`."""
    wo, values = samples_near(table, np.asarray(wi, float))
    return wo, values * wo[:, 2:3] if cosine else values


def albedo_curve(model, theta_deg, phi_deg=0.0, tol=1e-3, resolution=24):
    """Directional albedo ``(n, C)`` at incidence angles ``theta_deg`` (degrees), through
    ``model.albedo`` at tolerance ``tol`` (a live curve needs 3 digits, not 5), or for a
    measured table its quadrature over the interpolant at ``resolution`` nodes."""
    theta = np.radians(np.asarray(theta_deg, float))
    wi = spherical_to_cartesian(theta, np.full_like(theta, math.radians(phi_deg)))
    if is_table(model):
        return np.asarray(model.albedo(wi, resolution=resolution), float)
    return np.asarray(model.albedo(wi, tol=tol), float)


# -- lit sphere -------------------------------------------------------------------------------

def _sphere_hits(size):
    """Per pixel of a ``size`` x ``size`` image (row 0 at the top): the unit sphere's normal
    where the camera ray hits it, the direction towards the camera, and the hit mask."""
    half = math.tan(math.radians(CAMERA_FOV) / 2)
    s = (np.arange(size) + 0.5) / size * 2 - 1
    x, y = np.meshgrid(s * half, -s * half)
    d = np.stack([x, y, -np.ones_like(x)], -1)
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    o = np.array([0.0, 0.0, CAMERA_DISTANCE])
    # |o + t d| = 1: t^2 + 2 (o.d) t + |o|^2 - 1 = 0, nearest root
    b = d @ o
    disc = b * b - (o @ o - 1.0)
    hit = disc > 0
    t = -b - np.sqrt(np.where(hit, disc, 0.0))
    n = o + t[..., None] * d
    return n[hit], -d[hit], hit


def sphere_preview(model, size=128, *, light=KEY_LIGHT, irradiance=KEY_IRRADIANCE,
                   environment=ENVIRONMENT, albedo=None, lights=None):
    """A unit sphere of ``model`` under a directional key light and a uniform environment,
    direct lighting only (no interreflection; a sphere has none): the preview shown while a
    slider moves.

    Outgoing radiance per pixel L = f(wi, wo) E cos(theta_i) + L_env a(wo): the first term is
    the reflection equation for a parallel light of irradiance E normal to it (Pharr et al.,
    PBR 4th ed., eq. 4.14 with a delta light), the second the environment's, since a uniform
    radiance L_env reflects L_env times the integral of f cos over the incident hemisphere,
    which by reciprocity is the directional albedo at wo. That albedo is interpolated in
    cos(theta_o) from ``albedo``, a pair (theta in degrees, albedo ``(n, C)``) such as the
    explorer's albedo curve already holds, by default 24 angles at phi = 0 (exact for isotropic
    models up to the interpolation).

    ``lights``, the directional lights of an environment map (:func:`sky_lights`) or its
    strata (:class:`MapStrata`: sampled per pixel, then a 3 x 3 tent filter), replace the key
    light and the uniform environment when given.

    Returns
    -------
    ndarray, shape (size, size, C)
        Radiance, NaN where the camera ray misses the sphere. The camera and lights are those
        of :func:`brdf.render.scenes.lit_sphere`; the shading frame's tangent is that of
        :func:`brdf.geometry.frame_from_normal`.
    """
    size = int(size)
    if size < 2:
        raise InputError(f"sphere_preview: size {size} must be at least 2 pixels")
    normal, view, hit = _sphere_hits(size)
    if lights is not None:
        radiance = _shade_lights(model, normal, view, lights)
        out = np.full((size, size, radiance.shape[-1]), np.nan)
        out[hit] = radiance
        return _tent(out) if _sampled(model, lights) else out
    light = np.asarray(light, float) / np.linalg.norm(light)
    radiance = _shade(model, normal, view, light, irradiance, environment, albedo)
    out = np.full((size, size, radiance.shape[-1]), np.nan)
    out[hit] = radiance
    return out


def _sampled(model, lights):
    """Whether the previews sample ``lights`` per pixel for ``model`` (:class:`MapStrata`
    and a material with a sampler, or a measured table: :class:`TableSampler`), and so
    filter the noise."""
    return isinstance(lights, MapStrata) and (hasattr(model, "sample_weighted")
                                              or is_table(model))


def _tent(image):
    """``image`` ``(h, w, C)`` under a 3 x 3 tent filter ([1 2 1] / 4 each way) over its
    pixels that are not NaN, which stay NaN: the per-pixel samples of :class:`MapStrata`
    averaged with their neighbours' (a reconstruction filter, PBR 4th ed. section 8.8.2)."""
    weight = np.where(np.isnan(image[..., :1]), 0.0, 1.0)

    def blur(a):
        a = np.pad(a, ((1, 1), (1, 1), (0, 0)))
        a = a[:-2] + 2 * a[1:-1] + a[2:]
        return a[:, :-2] + 2 * a[:, 1:-1] + a[:, 2:]
    out = blur(np.nan_to_num(image) * weight) / np.maximum(blur(weight), 1e-300)
    out[np.isnan(image)] = np.nan
    return out


def _shade_lights(model, normal, view, lights, visible=None):
    """Radiance towards ``view`` at points of ``normal`` (world, (m, 3)) lit by directional
    ``lights`` ``(directions (k, 3), irradiance (k, C))``: the reflection equation's sum over
    delta lights (Pharr et al., PBR 4th ed., eq. 4.14); ``visible`` (k, m) masks shadows."""
    frame = frame_from_normal(normal)
    wo = to_local(view, frame)
    wo[:, 2] = np.maximum(wo[:, 2], 1e-9)  # the silhouette's rays graze the surface
    wo /= np.linalg.norm(wo, axis=-1, keepdims=True)
    m = len(normal)
    extra = None
    if isinstance(lights, MapStrata) and not _sampled(model, lights):
        lights = lights.points  # a material that cannot sample: the median cut's point lights
    if isinstance(lights, MapStrata):  # a direction per region and point
        directions, irradiance = lights.sample(m)
        extra = lights.material_term(model, wo, frame)  # the dim cells
        wi = np.stack([np.einsum("kmc,mc->km", directions, axis) for axis in frame], -1)
    else:
        directions, irradiance = lights
        # every light in every point's frame at once: (k, m, 3)
        wi = np.stack([np.asarray(directions, float) @ axis.T for axis in frame], -1)
    k = len(directions)
    cos = np.maximum(wi[..., 2], 0.0)
    if visible is not None:
        cos = cos * visible
    # only the pairs a light reaches: about half of them on a sphere
    light, point = np.nonzero(cos > 0.0)
    f = np.asarray(model.eval(wi[light, point], wo[point]), float)
    irradiance = np.asarray(irradiance, float)
    irradiance = (irradiance[light, point] if irradiance.ndim == 3 else
                  irradiance.reshape(k, -1)[light])
    terms = f.reshape(len(point), -1) * (cos[light, point][:, None] * irradiance)
    out = np.stack([np.bincount(point, terms[:, c], minlength=m)
                    for c in range(terms.shape[1])], -1)
    return out if extra is None else out + extra


def _shade(model, normal, view, light, irradiance, environment, albedo):
    """Direct-lighting radiance towards ``view`` at surface points of ``normal`` (world,
    (m, 3)): see :func:`sphere_preview`. ``irradiance`` may be per point (0 in shadow)."""
    frame = frame_from_normal(normal)
    wi = to_local(np.broadcast_to(light, normal.shape), frame)
    wo = to_local(view, frame)
    wo[:, 2] = np.maximum(wo[:, 2], 1e-9)  # the silhouette's rays graze the surface
    wo /= np.linalg.norm(wo, axis=-1, keepdims=True)
    f = np.asarray(model.eval(wi, wo), float)
    radiance = f * (irradiance * np.maximum(wi[:, 2], 0.0))[..., None]
    if environment:
        if albedo is None:
            theta = np.degrees(np.arccos(np.linspace(1.0, 0.0, 24)))
            albedo = theta, albedo_curve(model, theta)
        theta, a = np.asarray(albedo[0], float), np.asarray(albedo[1], float)
        cos_o = np.cos(np.radians(theta))[::-1]  # increasing, as np.interp needs
        a = a[::-1]
        env = np.stack([np.interp(wo[:, 2], cos_o, a[:, c]) for c in range(a.shape[1])], -1)
        radiance = radiance + environment * env
    return radiance


# -- lit object: a torus ----------------------------------------------------------------------

#: The lit object beside the sphere: a ring torus of these radii about its own y axis (inside
#: the unit sphere, so the sphere's camera frames it), turned this many degrees about x to
#: show its hole and have the key light cast its shadow inside the ring; its mesh for the
#: path tracer has this many segments around the ring and around the tube (smooth vertex
#: normals).
TORUS_RADII = (0.68, 0.3)
TORUS_TILT = -60.0
TORUS_SEGMENTS = (96, 48)
#: Sphere-tracing steps of the preview and the distance that counts as on the surface.
_MARCH_STEPS, _MARCH_EPS = 96, 1e-5


def _torus_rotation():
    """World from the torus's frame: a turn of TORUS_TILT degrees about x."""
    c, s = math.cos(math.radians(TORUS_TILT)), math.sin(math.radians(TORUS_TILT))
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _torus_distance(p):
    """Signed distance to the torus of points ``p`` (m, 3) in its own frame (Hart 1996,
    "Sphere tracing", the torus's distance |(rho - R, y)| - r)."""
    big, small = TORUS_RADII
    rho = np.hypot(p[:, 0], p[:, 2])
    return np.hypot(rho - big, p[:, 1]) - small


def _march(origin, direction, t0, t1):
    """Sphere tracing (Hart 1996) of rays ``origin + t direction`` (torus frame) from ``t0``
    to ``t1``: the hit distance per ray, NaN where it misses."""
    t = np.array(t0, float)
    hit = np.full(len(t), np.nan)
    live = np.arange(len(t))
    for _ in range(_MARCH_STEPS):
        d = _torus_distance(origin[live] + t[live, None] * direction[live])
        done = d < _MARCH_EPS
        hit[live[done]] = t[live[done]]
        t[live] += d
        live = live[~done & (t[live] < t1[live])]
        if not len(live):
            break
    return hit


def _object_hits(size):
    """Per pixel of the sphere's camera: the torus's normal where the ray hits it, the
    direction towards the camera, the hit points (all world), and the hit mask."""
    half = math.tan(math.radians(CAMERA_FOV) / 2)
    s = (np.arange(size) + 0.5) / size * 2 - 1
    x, y = np.meshgrid(s * half, -s * half)
    d = np.stack([x, y, -np.ones_like(x)], -1).reshape(-1, 3)
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    rot = _torus_rotation()
    o = np.array([0.0, 0.0, CAMERA_DISTANCE]) @ rot  # to the torus's frame: rot^T v
    dl = d @ rot
    # march inside the bounding sphere of radius R + r only
    b = dl @ o
    disc = b * b - (o @ o - sum(TORUS_RADII) ** 2)
    near = np.where(disc > 0, -b - np.sqrt(np.maximum(disc, 0)), np.inf)
    far = np.where(disc > 0, -b + np.sqrt(np.maximum(disc, 0)), -np.inf)
    t = np.full(len(d), np.nan)
    inside = disc > 0
    t[inside] = _march(np.broadcast_to(o, (inside.sum(), 3)), dl[inside], near[inside],
                       far[inside])
    hit = ~np.isnan(t)
    p = o + t[hit, None] * dl[hit]
    # the normal: from the nearest point of the tube's centre circle
    rho = np.hypot(p[:, 0], p[:, 2])
    centre = np.stack([TORUS_RADII[0] * p[:, 0] / rho, np.zeros(len(p)),
                       TORUS_RADII[0] * p[:, 2] / rho], -1)
    n = p - centre
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    return n @ rot.T, -d[hit], p @ rot.T, hit.reshape(size, size)


def _in_shadow(points, normals, light):
    """Whether the torus hides the direction ``light`` from each world point (a march from
    just off the surface)."""
    rot = _torus_rotation()
    origin = (points + 1e-3 * normals) @ rot
    direction = np.broadcast_to(light @ rot, origin.shape)
    return ~np.isnan(_march(origin, direction, np.zeros(len(origin)),
                            np.full(len(origin), 2.0 * sum(TORUS_RADII))))


@functools.lru_cache(maxsize=8)
def _object_geometry(size, light):
    """The torus's normals, view directions, key-light visibility and hit mask at ``size``:
    the same for every model, so traced once (30-50 ms) and kept."""
    normal, view, points, hit = _object_hits(size)
    lit = ~_in_shadow(points, normal, np.array(light))
    for a in (normal, view, lit, hit):
        a.flags.writeable = False
    return normal, view, lit, hit


def object_preview(model, size=128, *, light=KEY_LIGHT, irradiance=KEY_IRRADIANCE,
                   environment=ENVIRONMENT, albedo=None, lights=None):
    """The lit object (a torus, :data:`TORUS_RADII`, turned :data:`TORUS_TILT` degrees about
    x) of ``model`` under the sphere's key light and environment, direct lighting as
    :func:`sphere_preview` with the key light's shadows (a torus shadows itself): found by
    sphere tracing its distance function. The environment term does not see the torus hide
    part of the sky from itself, nor light between its sides (the path tracer does).

    Returns
    -------
    ndarray, shape (size, size, C)
        Radiance, NaN where the camera ray misses the torus.
    """
    size = int(size)
    if size < 2:
        raise InputError(f"object_preview: size {size} must be at least 2 pixels")
    if lights is not None:  # an environment map's lights, without their shadows
        normal, view, _, hit = _object_geometry(size, tuple(KEY_LIGHT))
        radiance = _shade_lights(model, normal, view, lights)
        out = np.full((size, size, radiance.shape[-1]), np.nan)
        out[hit] = radiance
        return _tent(out) if _sampled(model, lights) else out
    light = np.asarray(light, float) / np.linalg.norm(light)
    normal, view, lit, hit = _object_geometry(size, tuple(light))
    radiance = _shade(model, normal, view, light, irradiance * lit, environment, albedo)
    out = np.full((size, size, radiance.shape[-1]), np.nan)
    out[hit] = radiance
    return out


def torus_mesh(material=None, segments=TORUS_SEGMENTS):
    """The lit object as a :class:`brdf.render.Mesh` for the path tracer: ``segments``
    (around the ring, around the tube) quads in two triangles each, with the torus's exact
    normals at the vertices."""
    from ..render import Mesh
    big, small = TORUS_RADII
    nu, nv = segments
    u = 2 * np.pi * np.arange(nu) / nu
    v = 2 * np.pi * np.arange(nv) / nv
    U, V = np.meshgrid(u, v, indexing="ij")
    # the torus about y: (R + r cos v) (cos u, 0, sin u) + r sin v y
    normal = np.stack([np.cos(V) * np.cos(U), np.sin(V), np.cos(V) * np.sin(U)], -1)
    ring = np.stack([np.cos(U), np.zeros_like(U), np.sin(U)], -1)
    points = big * ring + small * normal
    rot = _torus_rotation()
    i, j = np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij")
    a, b = i * nv + j, ((i + 1) % nu) * nv + j
    c, d = ((i + 1) % nu) * nv + (j + 1) % nv, i * nv + (j + 1) % nv
    # counter-clockwise seen from outside (the normal's side)
    faces = np.concatenate([np.stack([a, d, c], -1).reshape(-1, 3),
                            np.stack([a, c, b], -1).reshape(-1, 3)])
    return Mesh(points.reshape(-1, 3) @ rot.T, faces, material,
                normals=normal.reshape(-1, 3) @ rot.T)


def lit_object(material, environment=ENVIRONMENT):
    """The path tracer's scene of the lit object: the torus of :func:`torus_mesh` under the
    camera, key light and environment of ``brdf.render.builtin("sphere")``."""
    from ..render import Camera, DirectionalLight, Environment, Scene
    camera = Camera(origin=(0, 0, CAMERA_DISTANCE), target=(0, 0, 0), up=(0, 1, 0),
                    fov=CAMERA_FOV)
    key = DirectionalLight(direction=-KEY_LIGHT, irradiance=KEY_IRRADIANCE)
    return Scene(camera, [torus_mesh(material)], [key],
                 Environment(environment) if environment else None)


def object_render(material, size=128, spp=64, seed=0, environment=ENVIRONMENT, lighting="key",
                  **options):
    """The lit object path traced (:func:`lit_object`; under :func:`sky_map` alone when
    ``lighting="sky"``, under a map alone when ``lighting`` is its radiance array), NaN off the torus as :func:`object_preview` (its mask: the mesh's
    silhouette differs by under a pixel). ``options`` go to :func:`brdf.render.render`
    (``max_depth=2``: direct light only)."""
    from .. import render
    scene = (lit_object(material, environment) if _is_key(lighting) else
             _scene(torus_mesh(material), material, lighting))
    image = np.array(render.render(scene, spp=int(spp),
                                   size=(int(size), int(size)), seed=seed, progress=False,
                                   **options).image, dtype=float)
    image[~_object_hits(int(size))[3]] = np.nan
    return image


# -- environment map --------------------------------------------------------------------------

#: Size of the bundled sky map (rows, columns) and the directional lights its preview uses.
SKY_SHAPE, SKY_LIGHTS = (64, 128), 64
#: Where the sky map's sun is (towards it) and its radiance over a cone of SUN_WIDTH degrees
#: (a smooth falloff), on a blue sky over a dark ground.
SUN = np.array([-0.6, 0.55, 0.58]) / np.linalg.norm([-0.6, 0.55, 0.58])
SUN_RADIANCE, SUN_WIDTH = (30.0, 26.0, 20.0), 6.0


def _map_directions(shape):
    """World directions of an equirectangular map's pixel centres in Mitsuba 3's envmap
    layout (+y up; u = atan2(x, -z) / 2 pi, v = acos(y) / pi, row 0 at the top) and each
    pixel's solid angle (2 pi^2 sin(theta) / (h w), PBR 3rd ed. eq. 14.9)."""
    h, w = shape
    theta = np.pi * (np.arange(h) + 0.5) / h
    phi = 2 * np.pi * (np.arange(w) + 0.5) / w
    T, P = np.meshgrid(theta, phi, indexing="ij")
    d = np.stack([np.sin(T) * np.sin(P), np.cos(T), -np.sin(T) * np.cos(P)], -1)
    return d, 2 * np.pi ** 2 * np.sin(T) / (h * w)


def sky_map(shape=SKY_SHAPE):
    """The bundled environment map: a sun (:data:`SUN`) in a blue sky graded to the horizon
    over a dark ground, radiance ``(h, w, 3)`` in Mitsuba 3's envmap layout (the path tracer's
    :class:`brdf.render.Environment` takes it as ``map``)."""
    d, _ = _map_directions(shape)
    up = d[..., 1:2]
    sky = np.array([0.25, 0.42, 0.8]) * (0.35 + 0.65 * np.clip(up, 0, 1)) \
        + np.array([0.5, 0.5, 0.45]) * np.exp(-8.0 * abs(up))  # a bright haze at the horizon
    ground = np.broadcast_to(np.array([0.12, 0.1, 0.08]), sky.shape)
    radiance = np.where(up > 0, sky, ground)
    cone = np.degrees(np.arccos(np.clip(d @ SUN, -1, 1)))[..., None]
    return radiance + np.array(SUN_RADIANCE) * np.exp(-0.5 * (cone / SUN_WIDTH) ** 2)


@functools.lru_cache(maxsize=4)
def sky_lights(count=SKY_LIGHTS, shape=SKY_SHAPE):
    """The sky map (:func:`sky_map`) as ``count`` directional lights (:func:`map_lights`).

    Returns
    -------
    directions : ndarray (count, 3)
    irradiance : ndarray (count, 3)
    """
    return map_lights(sky_map(shape), count)


#: Rows the median cut of a larger map works on: blocks of its pixels summed (their power and
#: energy-weighted direction kept), so a 2k map's lights cost what a 256-row map's do.
CUT_ROWS = 256
#: Luminance of linear RGB, ITU-R BT.709.
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])


def _map_grid(radiance):
    """The median cut's grid of ``radiance`` (:func:`_cut_grid`): its pixels, or blocks of
    them for a map of more than :data:`CUT_ROWS` rows (the largest factor of its size up to
    rows / CUT_ROWS)."""
    radiance = np.asarray(radiance, float)
    shape = radiance.shape[:2]
    factor = max(1, shape[0] // CUT_ROWS)
    while factor > 1 and (shape[0] % factor or shape[1] % factor):
        factor -= 1
    return _cut_grid(radiance, factor)


def _cut_grid(radiance, factor):
    """The grid a median cut of ``radiance`` ``(h, w, 3)`` works on: blocks of ``factor`` x
    ``factor`` pixels (``factor`` divides both sides), each with the sums over its pixels of
    power (radiance times solid angle, ``(H, W, 3)``), energy (the power's luminance, ITU-R
    BT.709, ``(H, W)``), energy-weighted direction ``(H, W, 3)`` and solid angle ``(H, W)``.

    A pixel's solid angle depends on its row only and its direction's azimuth on its column
    (:func:`_map_directions`), and luminance is linear in radiance: so the map is summed
    over each block's rows once, weighted by the solid angle times 1, sin theta and cos
    theta (one matrix product), and all else is done on those row sums, a ``factor`` times
    smaller (35 ms for a 1024 x 2048 map where per-pixel directions took 0.6 s)."""
    h, w = radiance.shape[:2]
    rows, cols = h // factor, w // factor
    theta = np.pi * (np.arange(h) + 0.5) / h
    phi = 2 * np.pi * (np.arange(w) + 0.5) / w
    omega = 2 * np.pi ** 2 * np.sin(theta) / (h * w)  # PBR 3rd ed. eq. 14.9, per row
    weights = np.stack([omega, omega * np.sin(theta), omega * np.cos(theta)])
    summed = (weights.reshape(3, rows, factor).transpose(1, 0, 2)
              @ np.ascontiguousarray(radiance).reshape(rows, factor, w * 3))
    summed = summed.reshape(rows, 3, w, 3)
    power = summed[:, 0].reshape(rows, cols, factor, 3).sum(2)
    # luminance over the rows, times sin theta and cos theta: (rows, w) each
    lum_sin, lum_cos = summed[:, 1] @ LUMINANCE, summed[:, 2] @ LUMINANCE
    by_column = lambda a, weight: (a.reshape(rows, cols, factor)
                                   * weight.reshape(cols, factor)).sum(-1)
    # the direction (sin theta sin phi, cos theta, -sin theta cos phi), Mitsuba 3's layout
    weighted = np.stack([by_column(lum_sin, np.sin(phi)), lum_cos.reshape(rows, cols, factor)
                         .sum(-1), -by_column(lum_sin, np.cos(phi))], -1)
    solid = np.repeat(factor * omega.reshape(rows, factor).sum(1)[:, None], cols, axis=1)
    return power, power @ LUMINANCE, weighted, solid


def _median_cut(radiance, count, grid=None):
    """Debevec's median cut of ``radiance`` into ``count`` regions (see :func:`map_lights`):
    the grid it cut (the map's pixels, or blocks of them), as its cells' power ``(h, w, 3)``,
    energy ``(h, w)``, energy-weighted direction sums ``(h, w, 3)`` and solid angles
    ``(h, w)`` (:func:`_map_grid`, or ``grid`` when given), and the regions as (row, row end,
    column, column end) on that grid."""
    power, energy, weighted, omega = _map_grid(radiance) if grid is None else grid
    shape = energy.shape
    regions = [(0, shape[0], 0, shape[1])]
    while len(regions) < count:
        split = []
        for r0, r1, c0, c1 in regions:
            rows = np.arange(r0, r1)
            width = (c1 - c0) * np.sin(np.pi * (rows.mean() + 0.5) / shape[0])
            e = energy[r0:r1, c0:c1]
            if (r1 - r0) >= width and r1 - r0 > 1 or c1 - c0 == 1:
                cut = r0 + 1 + int(np.searchsorted(np.cumsum(e.sum(1)), e.sum() / 2)
                                   .clip(0, r1 - r0 - 2))
                split += [(r0, cut, c0, c1), (cut, r1, c0, c1)]
            else:
                cut = c0 + 1 + int(np.searchsorted(np.cumsum(e.sum(0)), e.sum() / 2)
                                   .clip(0, c1 - c0 - 2))
                split += [(r0, r1, c0, cut), (r0, r1, cut, c1)]
        regions = split
    return power, energy, weighted, omega, regions


def map_lights(radiance, count=SKY_LIGHTS):
    """An environment map ``radiance`` ``(h, w, 3)`` in Mitsuba 3's envmap layout as ``count``
    (a power of 2) directional lights for the previews: Debevec's median cut (2005, "A Median
    Cut Algorithm for Light Probe Sampling"): regions of the map split in two of equal energy
    (luminance times solid angle) across their longer side (the width scaled by sin(theta))
    until there are ``count``; each becomes a light at its energy centroid carrying the
    region's irradiance (sum of radiance times solid angle). A map of more than
    :data:`CUT_ROWS` rows is cut on blocks of its pixels (sums of power), when its size
    divides.

    Returns
    -------
    directions : ndarray (count, 3)
    irradiance : ndarray (count, 3)
    """
    power, energy, weighted, _, regions = _median_cut(radiance, count)
    return map_lights_of(power, energy, weighted, regions)


def map_lights_of(power, energy, weighted, regions):
    """:func:`map_lights` of a cut grid and its regions (:func:`_median_cut`)."""
    directions, irradiance = [], []
    for r0, r1, c0, c1 in regions:
        centre = weighted[r0:r1, c0:c1].sum((0, 1))
        if not np.any(centre):  # a black region: its middle cell's direction
            centre = _map_directions(energy.shape)[0][(r0 + r1) // 2, (c0 + c1) // 2]
        directions.append(centre / np.linalg.norm(centre))
        irradiance.append(power[r0:r1, c0:c1].sum((0, 1)))
    return np.array(directions), np.array(irradiance)


#: A map's cells brighter than this many times its mean radiance (luminance) are sampled as
#: lights by :class:`MapStrata`, the others through the material's sampler.
BRIGHT = 3.0
#: Directions per pixel :meth:`MapStrata.material_term` draws from the material's sampler.
MATERIAL_SAMPLES = 8


class MapStrata:
    """An environment map split for the previews, so that a glossy highlight under the map
    has its shape rather than the dots of a few point lights:

    - its bright cells (over :data:`BRIGHT` times the map's mean radiance: a sun, lamps),
      within each region of the median cut (:func:`map_lights`), give each pixel one
      direction drawn in proportion to their energy, instead of the region's one centroid:
      structured importance sampling (Agarwal et al. 2003, "Structured Importance Sampling
      of Environment Maps": strata of the map, importance sampled within);
    - the rest (dim and smooth: a sky, whose point lights make dots on a glossy lobe) is
      integrated by sampling the material instead (:meth:`material_term`:
      :data:`MATERIAL_SAMPLES` directions per pixel from the model's own sampler, the map
      looked up there).

    Each cell of the map by one technique: a partition of the integral, so the sum stays
    unbiased (PBR 4th ed., section 2.2). A measured table is sampled by its tabulation
    (:class:`TableSampler`); a material that cannot sample at all is lit by the median
    cut's point lights instead (``points``). The previews apply a 3 x 3
    tent filter to soften the noise; the draws are kept per pixel count, so the noise stands
    still while a slider moves. Made by :func:`map_strata`; the previews take it as
    ``lights``.
    """

    def __init__(self, power, energy, weighted, omega, regions):
        radiance = np.divide(power, omega[..., None], out=np.zeros_like(power),
                             where=omega[..., None] > 0)
        luminance = radiance @ np.array([0.2126, 0.7152, 0.0722])  # ITU-R BT.709
        bright = luminance > BRIGHT * energy.sum() / omega.sum()
        cells = [(slice(r0, r1), slice(c0, c1)) for r0, r1, c0, c1 in regions]
        flat = lambda a: np.concatenate([a[r, c].reshape(-1, *a.shape[2:]) for r, c in cells])
        e, p, w = flat(energy * bright), flat(power), flat(weighted)
        norm = np.linalg.norm(w, axis=-1, keepdims=True)
        self.cell_directions = np.divide(w, norm, out=np.zeros_like(w), where=norm > 0)
        # a cell's radiance over its luminance (its colour), 0 where it is black
        self.cell_colour = np.divide(p, flat(energy)[:, None], out=np.zeros_like(p),
                                     where=flat(energy)[:, None] > 0)
        self.cumulative = np.cumsum(e)
        sizes = np.array([(r.stop - r.start) * (c.stop - c.start) for r, c in cells])
        self.last = np.cumsum(sizes) - 1
        self.first = self.last - sizes + 1
        self.region_energy = np.array([e[a:b + 1].sum() for a, b in zip(self.first, self.last)])
        self.start = np.concatenate([[0.0], self.cumulative[self.last[:-1]]])
        #: the median cut's point lights (:func:`map_lights`), for a material without sampler
        self.points = map_lights_of(power, energy, weighted, regions)
        #: the map's radiance per cell of the cut grid where it is not bright, (h, w, 3)
        self.dim_radiance = radiance * ~bright[..., None]
        self._samples = {}

    def __len__(self):
        return len(self.region_energy)

    def material_term(self, model, wo, frame, seed=1):
        """Radiance towards local ``wo`` ``(m, 3)`` from the map's dim cells, by
        :data:`MATERIAL_SAMPLES` draws per point from ``model.sample_weighted`` (weights
        f cos / pdf; by reciprocity drawn from the outgoing side) times the map's dim radiance
        in the drawn direction (world, through ``frame``): ``(m, 3)``."""
        m, n = len(wo), MATERIAL_SAMPLES
        key = ("u", m, seed)
        if key not in self._samples:
            # stratified in u: n jittered rows of the unit square per point (PBR 4th ed. 8.5)
            rng = np.random.default_rng(seed)
            u = np.stack([(np.arange(n) + rng.random((m, n))) / n, rng.random((m, n))], -1)
            self._samples[key] = u
        u = self._samples[key]
        sampler = table_sampler(model) if is_table(model) else model
        wi, pdf, weight = sampler.sample_weighted(np.broadcast_to(wo[:, None], (m, n, 3)), u)
        t, b, normal = frame
        world = (wi[..., :1] * t[:, None] + wi[..., 1:2] * b[:, None]
                 + wi[..., 2:] * normal[:, None])
        h, w = self.dim_radiance.shape[:2]
        # Mitsuba 3's envmap layout (as _map_directions): v = acos(y) / pi, u = atan2(x, -z) / 2 pi
        row = np.clip((np.arccos(np.clip(world[..., 1], -1, 1)) / np.pi * h).astype(int),
                      0, h - 1)
        col = (np.mod(np.arctan2(world[..., 0], -world[..., 2]), 2 * np.pi) / (2 * np.pi)
               * w).astype(int) % w
        ok = (pdf > 0) & (wi[..., 2] > 0)
        terms = np.where(ok[..., None], np.nan_to_num(weight), 0.0) * self.dim_radiance[row, col]
        return terms.mean(1)

    def sample(self, m, seed=0):
        """Directions ``(k, m, 3)`` (one per region and pixel, in the region's bright cells)
        and the irradiance each stands for ``(k, m, 3)``: the drawn cell's colour times its
        region's bright energy, the estimator L omega / p of a cell drawn with probability p =
        its energy over the region's (PBR 4th ed., eq. 2.7); zero in a region with no bright
        cell. Kept per (m, seed)."""
        key = (int(m), seed)
        if key not in self._samples:
            rng = np.random.default_rng(seed)
            k = len(self)
            u = 1.0 - rng.random((k, int(m)))  # in (0, 1]: never a black cell at a region's start
            target = self.start[:, None] + u * self.region_energy[:, None]
            cell = np.searchsorted(self.cumulative, target, side="left")
            cell = np.clip(cell, self.first[:, None], self.last[:, None])
            directions = self.cell_directions[cell]
            directions[np.linalg.norm(directions, axis=-1) == 0] = (0.0, 1.0, 0.0)
            irradiance = self.cell_colour[cell] * self.region_energy[:, None, None]
            for a in (directions, irradiance):
                a.flags.writeable = False
            if len(self._samples) > 8:
                self._samples.clear()
            self._samples[key] = directions, irradiance
        return self._samples[key]


#: A measured table's tabulation for :class:`TableSampler`: bins of the view's theta_o
#: (uniform in theta), cells of the drawn direction's theta and phi (phi from the view's
#: azimuth), and the share of cosine-weighted draws mixed in.
TABLE_BINS, TABLE_THETA, TABLE_PHI, TABLE_DEFENSIVE = 12, 24, 48, 0.2


class TableSampler:
    """Importance sampling of a measured table for the previews' :meth:`MapStrata.
    material_term`, which models do with their own samplers: f cos(theta) of the table
    tabulated once on a coarse grid of cells per bin of the view's theta_o (its value at each
    cell's centre, the view at the bin's centre, phi measured from the view's azimuth: exact
    for an isotropic table), drawn as a piecewise-constant density (PBR 4th ed., section
    A.5.1: a cell by its share, uniform in cos(theta) and phi within it) mixed with
    cosine-weighted draws (a defensive mixture, Hesterberg 1995: every direction the table
    reflects into keeps a density). Each draw's weight is the table's own f cos / pdf, so the
    estimate is unbiased however coarse the cells; the path tracer samples a table in the
    same way on a finer grid (brdf.render).
    """

    def __init__(self, table):
        self.table = table
        b, t, p = TABLE_BINS, TABLE_THETA, TABLE_PHI
        view = (np.arange(b) + 0.5) * (0.5 * np.pi) / b
        theta = (np.arange(t) + 0.5) * (0.5 * np.pi) / t
        phi = (np.arange(p) + 0.5) * (2.0 * np.pi) / p
        T, P = np.meshgrid(theta, phi, indexing="ij")
        lo = spherical_to_cartesian(T, P).reshape(-1, 3)
        edges = np.arange(t + 1) * (0.5 * np.pi) / t
        # a cell's solid angle: (cos theta0 - cos theta1) dphi
        self.omega = np.repeat((np.cos(edges[:-1]) - np.cos(edges[1:])) * (2 * np.pi / p), p)
        v = spherical_to_cartesian(view, np.zeros(b))
        f = np.asarray(table.eval(np.broadcast_to(lo, (b,) + lo.shape),
                                  np.broadcast_to(v[:, None], (b,) + lo.shape)), float)
        f = np.nan_to_num(np.maximum(f.mean(axis=-1), 0.0)) * lo[:, 2] * self.omega
        total = f.sum(axis=1, keepdims=True)
        share = np.where(total > 0, f / np.where(total > 0, total, 1.0), 1.0 / f.shape[1])
        self.cdf = np.concatenate([np.zeros((b, 1)), np.cumsum(share, axis=1)], axis=1)
        self.cdf[:, -1] = 1.0
        self.share = share

    def _bin(self, wo):
        theta = np.arccos(np.clip(wo[..., 2], 0.0, 1.0))
        return np.minimum((theta / (0.5 * np.pi) * TABLE_BINS).astype(int), TABLE_BINS - 1)

    def pdf(self, wo, wi):
        """Solid-angle density of :meth:`sample_weighted`'s ``wi`` given ``wo``."""
        b = self._bin(wo)
        theta = np.arccos(np.clip(wi[..., 2], -1.0, 1.0))
        phi = np.mod(np.arctan2(wi[..., 1], wi[..., 0]) - np.arctan2(wo[..., 1], wo[..., 0]),
                     2 * np.pi)
        it = np.minimum((theta / (0.5 * np.pi) * TABLE_THETA).astype(int), TABLE_THETA - 1)
        ip = np.minimum((phi / (2 * np.pi) * TABLE_PHI).astype(int), TABLE_PHI - 1)
        cell = it * TABLE_PHI + ip
        tabulated = self.share[b, cell] / self.omega[cell]
        cos = np.maximum(wi[..., 2], 0.0)
        return np.where(wi[..., 2] > 0, (1 - TABLE_DEFENSIVE) * tabulated
                        + TABLE_DEFENSIVE * cos / np.pi, 0.0)

    def sample_weighted(self, wo, u):
        """Directions ``wi`` drawn given ``wo`` (local, ``(..., 3)``) from uniform ``u``
        ``(..., 2)``, their density and the weight f(wi, wo) cos(theta_i) / pdf
        ``(..., C)``: as a model's ``sample_weighted``, by reciprocity from the view's side."""
        wo = np.asarray(wo, float)
        u = np.broadcast_to(np.asarray(u, float), wo.shape[:-1] + (2,))
        u1, u2 = u[..., 0], u[..., 1]
        cosine = u1 < TABLE_DEFENSIVE
        # the cosine-weighted share: Malley's method (PBR 4th ed., section A.5.3)
        r = np.sqrt(np.clip(u1 / TABLE_DEFENSIVE, 0.0, 1.0))
        a = 2 * np.pi * u2
        disc = np.stack([r * np.cos(a), r * np.sin(a), np.sqrt(np.maximum(1 - r * r, 0.0))],
                        -1)
        # the tabulated share: the cell whose CDF interval holds u1 (rows offset by 2 per bin,
        # so one sorted search serves every bin), then uniform within the cell
        b = self._bin(wo)
        rest = np.clip((u1 - TABLE_DEFENSIVE) / (1 - TABLE_DEFENSIVE), 0.0, 1.0)
        rows = (self.cdf + 2.0 * np.arange(TABLE_BINS)[:, None]).ravel()
        width = self.cdf.shape[1]
        cell = np.searchsorted(rows, rest + 2.0 * b, side="right") - 1 - b * width
        cell = np.clip(cell, 0, width - 2)
        low, high = self.cdf[b, cell], self.cdf[b, cell + 1]
        s = np.clip(np.where(high > low, (rest - low) / np.where(high > low, high - low, 1.0),
                             0.5), 0.0, 1.0)
        it, ip = cell // TABLE_PHI, cell % TABLE_PHI
        c0 = np.cos(it * (0.5 * np.pi) / TABLE_THETA)
        c1 = np.cos((it + 1) * (0.5 * np.pi) / TABLE_THETA)
        z = c0 + (c1 - c0) * s
        phi = (ip + u2) / TABLE_PHI * 2 * np.pi + np.arctan2(wo[..., 1], wo[..., 0])
        rz = np.sqrt(np.maximum(1 - z * z, 0.0))
        drawn = np.stack([rz * np.cos(phi), rz * np.sin(phi), z], -1)
        wi = np.where(cosine[..., None], disc, drawn)
        pdf = self.pdf(wo, wi)
        f = np.asarray(self.table.eval(wi, wo), float)
        weight = np.where((pdf > 0)[..., None], np.nan_to_num(f) * (wi[..., 2] / np.where(
            pdf > 0, pdf, 1.0))[..., None], 0.0)
        return wi, pdf, weight


def table_sampler(table):
    """The :class:`TableSampler` of ``table``, made once per table (kept while it lives)."""
    import weakref
    global _TABLE_SAMPLERS
    if _TABLE_SAMPLERS is None:
        _TABLE_SAMPLERS = weakref.WeakKeyDictionary()
    try:
        sampler = _TABLE_SAMPLERS.get(table)
    except TypeError:  # a table that cannot be held weakly: made each time
        return TableSampler(table)
    if sampler is None:
        sampler = _TABLE_SAMPLERS[table] = TableSampler(table)
    return sampler


_TABLE_SAMPLERS = None


def map_strata(radiance, count=SKY_LIGHTS):
    """The :class:`MapStrata` of ``radiance``'s median cut into ``count`` regions."""
    return MapStrata(*_median_cut(radiance, count))


def map_strata_of_counts(radiance, counts):
    """``{count: map_strata(radiance, count)}`` for each of ``counts``, the map summed into
    its cut grid once (most of the work for a large map)."""
    grid = _map_grid(radiance)
    return {int(count): MapStrata(*_median_cut(radiance, count, grid)) for count in counts}


@functools.lru_cache(maxsize=4)
def sky_strata(count=SKY_LIGHTS, shape=SKY_SHAPE):
    """The :class:`MapStrata` of the sky map (:func:`sky_map`)."""
    return map_strata(sky_map(shape), count)


def environment_map(source):
    """A user's environment map for the previews and the path tracer: radiance ``(h, w, 3)``
    from a lat-long (equirectangular) OpenEXR file in Mitsuba 3's envmap layout, read by the
    renderer's own reader (:func:`brdf.render.image.read_image`, as
    :class:`brdf.render.Environment` reads its ``map``), or from an array.

    Refused with one line (:class:`~brdf.errors.FormatError` for a file,
    :class:`~brdf.errors.InputError` for an array): a file that is not ``.exr`` or not
    readable, a map that is not twice as wide as high, NaN or infinite values, negative
    radiance, a map that is black everywhere.
    """
    from ..errors import FormatError
    from ..render.image import read_image
    is_path = isinstance(source, (str, os.PathLike))
    what = "environment map"
    if is_path and not os.fspath(source).lower().endswith(".exr"):
        if not os.path.exists(source):
            raise InputError(f"{os.fspath(source)}: {what}: no such file")
        raise FormatError(source, "", f"{what}: expected a lat-long OpenEXR file (.exr)")

    def refuse(where, message):
        if is_path:
            raise FormatError(source, where, f"{what}: {message}")
        raise InputError(f"{what}{' at ' + where if where else ''}: {message}")

    try:
        radiance = read_image(source, what, channels=3)
    except BRDFError as exc:  # an array's refusal: said as the others
        if is_path:
            raise
        refuse("", str(exc).split(": ", 2)[-1])
    h, w = radiance.shape[:2]
    if w != 2 * h:
        refuse("", f"expected a lat-long map twice as wide as high, got {w} x {h} pixels")
    if radiance.min() < 0:  # where, only then (a search of every pixel)
        row, column, channel = np.argwhere(radiance < 0)[0]
        refuse(f"row {row}, column {column}",
               f"radiance {radiance[row, column, channel]:g} is negative (expected >= 0)")
    if not radiance.any():
        refuse("", "black everywhere (expected some light)")
    return radiance


def _scene(shape, material, lighting):
    """The previews' scene for the path tracer: ``shape`` under the key light and uniform
    environment (``lighting == "key"``), under :func:`sky_map` alone (``"sky"``), or under
    an environment map alone (``lighting`` its radiance array, :func:`environment_map`)."""
    from ..render import Camera, DirectionalLight, Environment, Scene
    camera = Camera(origin=(0, 0, CAMERA_DISTANCE), target=(0, 0, 0), up=(0, 1, 0),
                    fov=CAMERA_FOV)
    if not isinstance(lighting, str):
        return Scene(camera, [shape], [], Environment(1.0, map=np.asarray(lighting, float)))
    if lighting == "sky":
        return Scene(camera, [shape], [], Environment(1.0, map=sky_map()))
    key = DirectionalLight(direction=-KEY_LIGHT, irradiance=KEY_IRRADIANCE)
    return Scene(camera, [shape], [key], Environment(ENVIRONMENT))


def _is_key(lighting):
    return isinstance(lighting, str) and lighting == "key"


def sphere_render(material, size=128, spp=64, seed=0, lighting="key", **options):
    """The sphere of :func:`sphere_preview` path traced (:func:`brdf.render.render` of the
    ``sphere`` scene, :func:`brdf.render.scenes.lit_sphere`): the same camera and lights, with
    the renderer's importance sampling, so the two agree up to its noise. ``material`` is a
    model or a measured table. ``lighting="sky"``: under :func:`sky_map` instead, or under
    an environment map given as its radiance array (:func:`environment_map`);
    ``options`` go to :func:`brdf.render.render`.

    Returns
    -------
    ndarray, shape (size, size, 3)
        Radiance, NaN where the camera ray misses the sphere (as the preview).
    """
    from .. import render
    scene = (render.builtin("sphere", material) if _is_key(lighting) else
             _scene(render.Sphere((0, 0, 0), 1.0, material), material, lighting))
    image = np.array(render.render(scene, spp=int(spp), size=(int(size), int(size)), seed=seed,
                                   progress=False, **options).image, dtype=float)
    image[~_sphere_hits(int(size))[2]] = np.nan
    return image


def to_rgba(image, exposure=0.0):
    """Radiance ``(h, w, C)`` to display pixels ``(h, w)`` of packed uint32 RGBA (Bokeh's
    ``image_rgba``, row 0 at the bottom): sRGB-encoded (IEC 61966-2-1), clipped at 1, scaled by
    2^exposure; one channel is grey, more than 3 their mean; NaN is transparent."""
    image = np.asarray(image, float) * 2.0 ** float(exposure)
    if image.shape[-1] == 3:
        rgb = image
    else:
        rgb = np.repeat(np.nanmean(image, axis=-1, keepdims=True) if image.shape[-1] > 1
                        else image, 3, axis=-1)
    missing = np.isnan(rgb).any(-1)
    c = np.clip(np.nan_to_num(rgb), 0.0, 1.0)
    # sRGB transfer function, IEC 61966-2-1 section 5.2
    c = np.where(c <= 0.0031308, 12.92 * c, 1.055 * c ** (1 / 2.4) - 0.055)
    rgba = np.empty(c.shape[:-1] + (4,), np.uint8)
    rgba[..., :3] = np.round(c * 255)
    rgba[..., 3] = np.where(missing, 0, 255)
    return rgba[::-1].copy().view(np.uint32)[..., 0]
