"""The ``direct`` method: pixels of known geometry under known direct light become measured BRDF
samples (Marschner et al. 1999, "Image-based BRDF measurement including human skin", EGWR:
each pixel of a photographed convex object gives a reflectance sample f = L / E at the
(wi, wo) its geometry and the light fix).

For each pixel whose footprint lies on the unknown BRDF's shapes, the renderer's camera casts a
ray through its centre and through :data:`SUBPIXELS` stratified points of its area (a box
filter, as the photograph's pixel integrates), and every hit gathers its **incidence records**
(wi, E): the direction towards a source and the irradiance it delivers, receiver cosine and
shadow ray included, one record per

- point light (E = I cos(theta_i) / (a r^2 + b r + c), the renderer's attenuation), spot light
  (times cos^n of the angle to its axis inside the cone) and directional light (E cos);
- point of a fixed, seeded, stratified quadrature over each emissive quad or sphere (area
  lights: E_q = L_e cos(theta_i) cos(theta_l) A / (N r^2), the direct-light integral over the
  emitter's area with d(omega) = dA cos(theta_l) / r^2, Pharr et al., PBR 3rd ed., 5.5.3);
- direction of a fixed stratified cosine-weighted set over the hemisphere (a constant
  environment: E_q = L pi / M, the estimator of L cos over a density cos / pi, PBR 3rd ed.,
  13.6.3); these set
  the environment's share and mean direction only.

The model predicts a pixel as P = sum over records of f(wi, wo) E (averaged over the
footprint), plus, for a constant environment of radiance L, L a(wo) - sum over its blocked
directions of f E: by reciprocity the integral of f cos over all wi is the albedo a towards wo
(the model's own cubature, tabulated over theta_o), so only what other shapes hide goes
through the coarse direction set (64 directions alone missed a GGX lobe of alpha 0.22 by
enough to bias the albedo 6 % under a sky a third as bright as the sun).
A sample needs a single (wi, wo) per pixel: the centre's direction towards the pixel's
**dominant source** (the one whose predicted share of the pixel is largest; its E-weighted mean
direction for an area light or the environment) and that source's irradiance E*. The sample is

    f_sample = f_prev(wi*, wo*) + (L - P_prev) / E*,

with f_prev the previous fit: the pixel's residual carried onto the dominant source's term
(a fixed-point iteration whose fixed point leaves the residuals L - P with zero weighted mean;
:func:`brdf.capture.fit_images` runs it). Under one point or directional light the first pass
is Marschner's f = L / E at the pixel centre, and the further passes only remove the pixel
footprint's averaging; several lights, area lights and the environment are handled by the same
correction, so long as one source dominates each pixel kept (:data:`DOMINANT_SHARE`); pixels
the environment dominates are left out when the scene has another source (a sample at its
mean direction stands for a whole hemisphere). The first pass takes f = L / (sum of every
source's E), a Lambertian guess exact for one source; each pass then closes in on the fixed
point by a factor of about -0.4 under a sky a third as bright as the sun.

What ``direct`` leaves out: light reflected by other surfaces (interreflection: a diffuse floor
under the object adds light the method attributes to the BRDF, a bias
``benchmarks/bench_inverse.py`` measures) and light through the object (subsurface).
"""

import math
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..memory import require

__all__ = ["Incidence", "ViewPixels", "sources_of", "gather", "pixels_of", "predict", "samples",
           "SUBPIXELS", "BORDER", "AREA_POINTS", "ENV_DIRECTIONS", "DOMINANT_SHARE"]

#: Points per pixel side of the footprint's stratified grid (2: four points at the quarter
#: positions; the midpoint rule's error over a pixel is a quarter of the centre's).
SUBPIXELS = 2
#: Points of a pixel's border (corners and edge midpoints, in pixel units) that must agree with
#: its centre on the shape hit and on the hard shadows (:func:`pixels_of`).
BORDER = ((0.0, 0.0), (0.5, 0.0), (1.0, 0.0), (0.0, 0.5), (1.0, 0.5), (0.0, 1.0), (0.5, 1.0),
          (1.0, 1.0))
#: Quadrature points per emissive shape (a jittered 8 x 8 grid over a quad's parameters or
#: stratified over a sphere's area).
AREA_POINTS = 64
#: Directions of the environment's cosine-weighted hemisphere set (a jittered 8 x 8 grid).
ENV_DIRECTIONS = 64
#: A pixel is kept when its dominant source carries at least this share of its predicted value.
DOMINANT_SHARE = 0.5
#: Peak bytes per incidence record while a view's records are gathered and turned local: the
#: record (owner, source, wi, E: 8 numbers), its ray and shadow test, its local directions and
#: the model's values (an upper bound, counted from the arrays gather and pixels_of make).
RECORD_BYTES = 8 * 32
#: Luminance weights (ITU-R BT.709) that rank sources and weight mean directions.
LUMA = np.array([0.2126, 0.7152, 0.0722])


@dataclass
class Incidence:
    """Incidence records of a set of surface points: record k belongs to point ``owner[k]``
    and source ``source[k]``, arrives from world direction ``wi[k]`` with RGB irradiance
    ``E[k]`` (receiver cosine and visibility included)."""

    owner: np.ndarray
    source: np.ndarray
    wi: np.ndarray
    E: np.ndarray


def _stratified(n, rng):
    """``n`` jittered points of the unit square on a sqrt(n) x sqrt(n) grid (n a square)."""
    k = int(round(math.sqrt(n)))
    i, j = np.meshgrid(np.arange(k), np.arange(k), indexing="ij")
    u = (np.stack([i.ravel(), j.ravel()], axis=1) + rng.random((k * k, 2))) / k
    return u


def sources_of(scene, seed):
    """The direct sources of a scene: ``(kind, data, name)`` per source, area quadratures and
    environment directions drawn once from ``seed``."""
    from ..render.scene import (DirectionalLight, GoniometricLight, PointLight, Quad, Sphere,
                                SpotLight, rgb_value)
    rng = np.random.default_rng(seed)
    out = []
    for k, light in enumerate(scene.lights):
        name = getattr(light, "label", None) or f"lights[{k}]"
        if isinstance(light, GoniometricLight):
            raise InputError(f"{name}: the direct method takes point, spot, directional and area "
                             "lights and a constant environment; goniometric lights are not "
                             "supported yet")
        if isinstance(light, (PointLight, SpotLight)):
            att = np.asarray(light.attenuation, float)
            data = {"position": np.asarray(light.position, float),
                    "intensity": rgb_value(light.intensity, name), "attenuation": att}
            if isinstance(light, SpotLight):
                axis = np.asarray(light.direction, float)
                data.update(axis=axis / np.linalg.norm(axis),
                            cos_cutoff=math.cos(math.radians(float(light.cutoff))),
                            exponent=float(light.exponent))
            out.append(("point", data, name))
        elif isinstance(light, DirectionalLight):
            d = np.asarray(light.direction, float)
            out.append(("directional", {"direction": d / np.linalg.norm(d),
                                        "irradiance": rgb_value(light.irradiance, name)}, name))
    for k, s in enumerate(scene.shapes):
        if getattr(s, "emission", None) is None:
            continue
        name = getattr(s, "label", None) or f"shapes[{k}]"
        radiance = rgb_value(s.emission, name + " emission")
        sides = {"front": 1, "back": 2, "both": 3}[s.sides]
        u = _stratified(AREA_POINTS, rng)
        if isinstance(s, Quad):
            c, e1, e2 = (np.asarray(v, float) for v in (s.corner, s.edge1, s.edge2))
            n = np.cross(e1, e2)
            area = float(np.linalg.norm(n))
            pts = c + u[:, :1] * e1 + u[:, 1:] * e2
            normals = np.broadcast_to(n / area, pts.shape)
        elif isinstance(s, Sphere):
            z = 1.0 - 2.0 * u[:, 0]
            r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
            phi = 2.0 * math.pi * u[:, 1]
            normals = np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)
            pts = np.asarray(s.centre, float) + float(s.radius) * normals
            area = 4.0 * math.pi * float(s.radius) ** 2
        else:  # the renderer refuses emissive meshes already
            continue
        out.append(("area", {"points": pts, "normals": normals, "area": area,
                             "radiance": radiance, "sides": sides}, name))
    env = scene.environment
    if env is not None:
        if env.map is not None:
            raise InputError("environment: the direct method takes a constant environment; "
                             "an environment map is not supported yet")
        u = _stratified(ENV_DIRECTIONS, rng)
        # cosine-weighted directions about +z (Malley's method, PBR 3rd ed., 13.6.3)
        r = np.sqrt(u[:, 0])
        phi = 2.0 * math.pi * u[:, 1]
        local = np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(1.0 - u[:, 0])], axis=1)
        out.append(("environment", {"local": local,
                                    "radiance": rgb_value(env.radiance, "environment radiance")},
                    "environment"))
    if not out:
        raise InputError("scene: no light source (lights, emissive shapes or an environment)")
    return out


def _offset(p, n):
    """Shadow-ray origins pushed off the surface (as the renderer's offset)."""
    eps = 1e-7 * (1.0 + np.max(np.abs(p), axis=1, keepdims=True))
    return p + eps * n


def gather(compiled, scene, hits, sources):
    """:class:`Incidence` of the surface points ``hits`` (a :class:`brdf.render.rays.Hits`
    subset that all hit) from ``sources`` (:func:`sources_of`), and the environment's blocked
    directions (as an :class:`Incidence` of the irradiance they would bring)."""
    from ..render.rays import occluded
    dark = []
    n_pts = len(hits.t)
    p, ng, s = hits.position, hits.normal, hits.shading
    origin = _offset(p, ng)
    owners, kinds, wis, Es = [], [], [], []
    for index, (kind, data, _) in enumerate(sources):
        if kind == "point":
            v = data["position"] - p
            r = np.linalg.norm(v, axis=1)
            wi = v / r[:, None]
            a, b, c = data["attenuation"]
            scale = 1.0 / (a * r * r + b * r + c)
            if "axis" in data:
                ca = -(wi @ data["axis"])
                scale = np.where(ca >= data["cos_cutoff"],
                                 scale * np.maximum(ca, 0.0) ** data["exponent"], 0.0)
            E = scale[:, None] * data["intensity"]
            length = r * (1.0 - 1e-7)
            owner = np.arange(n_pts)
        elif kind == "directional":
            wi = np.broadcast_to(-data["direction"], p.shape).copy()
            E = np.broadcast_to(data["irradiance"], p.shape).copy()
            length = np.full(n_pts, np.inf)
            owner = np.arange(n_pts)
        elif kind == "area":
            q, nq = data["points"], data["normals"]
            m = len(q)
            v = q[None, :, :] - p[:, None, :]
            r2 = np.sum(v * v, axis=2)
            r = np.sqrt(r2)
            wi = (v / r[..., None]).reshape(-1, 3)
            cos_l = -np.sum((v / r[..., None]) * nq[None], axis=2)
            sides = data["sides"]
            emits = ((cos_l > 0.0) & bool(sides & 1)) | ((cos_l < 0.0) & bool(sides & 2))
            g = np.where(emits, np.abs(cos_l) * data["area"] / (m * r2), 0.0).reshape(-1)
            E = g[:, None] * data["radiance"]
            length = r.reshape(-1) * (1.0 - 1e-6)
            owner = np.repeat(np.arange(n_pts), m)
        else:  # environment: cosine-weighted directions in each point's shading frame
            loc = data["local"]
            m = len(loc)
            wi = (loc[None, :, 0:1] * hits.tangent[:, None] + loc[None, :, 1:2] *
                  hits.bitangent[:, None] + loc[None, :, 2:3] * s[:, None]).reshape(-1, 3)
            E = np.broadcast_to(data["radiance"] * math.pi / m, (n_pts * m, 3)).copy()
            length = np.full(n_pts * m, np.inf)
            owner = np.repeat(np.arange(n_pts), m)
        cos_i = np.sum(wi * s[owner], axis=1)
        if kind != "environment":
            E = E * np.maximum(cos_i, 0.0)[:, None]
        lit = (cos_i > 0.0) & (np.sum(wi * ng[owner], axis=1) > 0.0) & np.any(E > 0.0, axis=1)
        idx = np.flatnonzero(lit)
        if len(idx):
            blocked = occluded(compiled, origin[owner[idx]], wi[idx], length[idx])
            if kind == "environment":
                out = np.concatenate([np.flatnonzero(~lit), idx[blocked]])
                dark.append(Incidence(owner[out], np.full(len(out), index), wi[out], E[out]))
            idx = idx[~blocked]
        owners.append(owner[idx])
        kinds.append(np.full(len(idx), index))
        wis.append(wi[idx])
        Es.append(E[idx])
    inc = Incidence(np.concatenate(owners), np.concatenate(kinds), np.concatenate(wis),
                    np.concatenate(Es))
    return inc, (dark[0] if dark else None)


def _local(hits, owner, v):
    """World vectors v in the shading frames of points ``owner``."""
    return np.stack([np.sum(v * hits.tangent[owner], axis=1),
                     np.sum(v * hits.bitangent[owner], axis=1),
                     np.sum(v * hits.shading[owner], axis=1)], axis=1)


@dataclass
class ViewPixels:
    """The pixels of one view that a fit uses, and what predicts them.

    Attributes
    ----------
    yx : ndarray (n, 2)
        Row and column of each pixel.
    value : ndarray (n, 3)
        Linear values.
    step : ndarray (n, 3) or None
        Linear width of one code step at each value (integer photographs).
    footprint : tuple
        ``(pixel (m,), wi (m, 3), wo (m, 3), E (m, 3))``: local-frame records of the footprint's
        points, E already divided by the number of points, so that P = sum f E per pixel.
    centre : tuple
        ``(wi (n, G, 3), wo (n, 3), E (n, G, 3))``: per source, the centre's E-weighted mean
        local direction and total irradiance (zeros where a source does not reach).
    shape : ndarray (n,)
        The scene shape under each pixel's centre.
    kinds : tuple of str
        The kind of each source (point, directional, area, environment).
    environment : tuple or None
        ``(pixel (p,), wo (p, 3), L (p, 3))`` per footprint point: the constant environment's
        share L a(wo) of the prediction (L divided by the number of points), a the albedo; its
        blocked directions are in ``footprint`` with negative E.
    """

    yx: np.ndarray
    value: np.ndarray
    step: object
    footprint: tuple
    centre: tuple
    shape: np.ndarray
    kinds: tuple = ()
    environment: object = None

    def __len__(self):
        return len(self.yx)


def _centre_groups(inc, hits, n, n_sources):
    """Per point and source: E-weighted mean local direction and total E (see ViewPixels)."""
    E = np.zeros((n, n_sources, 3))
    acc = np.zeros((n, n_sources, 3))
    loc = _local(hits, inc.owner, inc.wi)
    np.add.at(E, (inc.owner, inc.source), inc.E)
    w = inc.E @ LUMA
    np.add.at(acc, (inc.owner, inc.source), w[:, None] * loc)
    norm = np.linalg.norm(acc, axis=2, keepdims=True)
    wi = np.where(norm > 0.0, acc / np.where(norm > 0.0, norm, 1.0), 0.0)
    return wi, E


def pixels_of(view, compiled, shapes, sources):
    """The :class:`ViewPixels` of ``view`` whose whole footprint lies on one of ``shapes`` (a
    set of scene shape indices), on one side of every point, spot or directional light's
    shadow edge, within the view's mask and not saturated.

    The footprint is tested at its centre, its stratified points, and its four corners and
    four edge midpoints (:data:`BORDER`): a silhouette or a hard shadow edge that crosses the
    pixel separates some of these, and such a pixel, a mix the few points would predict
    poorly, is left out (in a 96 x 72 view of a sphere on a floor, the pixels along the
    sphere's shadow that only the centre and 2 x 2 points missed set the exposure 0.5 % low)."""
    from ..render.rays import camera_rays, first_hits
    w, h = view.size
    k = SUBPIXELS
    grid = [((i + 0.5) / k, (j + 0.5) / k) for j in range(k) for i in range(k)]
    points = 1 + k * k
    dirs, origin = camera_rays(view.scene.camera, w, h, [(0.5, 0.5)] + grid + list(BORDER))
    allowed = view.mask & ~view.photo.saturated
    ys, xs = np.nonzero(allowed)
    npx = len(ys)
    if npx == 0:
        return None
    every = points + len(BORDER)
    d = dirs[:, ys, xs].reshape(-1, 3)
    hits = first_hits(compiled, origin, d)
    shape = hits.shape.reshape(every, npx)
    keep = np.all(np.isin(shape, list(shapes)), axis=0) & np.all(shape == shape[0], axis=0)
    delta = [i for i, (kind, _, _) in enumerate(sources) if kind in ("point", "directional")]
    if delta and keep.any():
        cand = np.flatnonzero(keep)
        rows = np.concatenate([cand + j * npx for j in range(every)])
        inc, _ = gather(compiled, view.scene, _subset(hits, rows), [sources[i] for i in delta])
        lit = np.zeros((len(cand), len(delta)), dtype=np.int64)
        np.add.at(lit, (inc.owner % len(cand), inc.source), 1)
        keep[cand[np.any((lit > 0) & (lit < every), axis=1)]] = False
    if not keep.any():
        return None
    sel = np.flatnonzero(keep)
    n = len(sel)
    # the centre rays come first, then each grid point's rays
    rows = np.concatenate([sel + j * npx for j in range(points)])
    per_point = sum(1 if kind in ("point", "directional") else len(data.get("points", data.get(
        "local", ()))) for kind, data, _ in sources)
    require(len(rows) * per_point * RECORD_BYTES,
            f"{view.photo.path}: the direct method's light records of {n:,} pixels (mask fewer "
            "pixels or halve the image's resolution)")
    sub = _subset(hits, rows)
    inc, dark = gather(compiled, view.scene, sub, sources)
    wo_world = -d[rows]
    centre = inc.owner < n
    ci = Incidence(inc.owner[centre], inc.source[centre], inc.wi[centre], inc.E[centre])
    wi_c, E_c = _centre_groups(ci, sub, n, len(sources))
    wo_c = _local(sub, np.arange(n), wo_world[:n])
    kinds = tuple(kind for kind, _, _ in sources)
    # the footprint's records; a constant environment enters as L times the albedo towards wo
    # (reciprocity: the integral of f cos over wi), less its blocked directions' records
    fp = (inc.owner >= n) & (inc.source != kinds.index("environment") if "environment" in
                             kinds else True)
    owner, wi_l, E = inc.owner[fp], _local(sub, inc.owner[fp], inc.wi[fp]), inc.E[fp]
    env = None
    if dark is not None:
        d_fp = dark.owner >= n
        owner = np.concatenate([owner, dark.owner[d_fp]])
        wi_l = np.concatenate([wi_l, _local(sub, dark.owner[d_fp], dark.wi[d_fp])])
        E = np.concatenate([E, -dark.E[d_fp]])
        points = np.arange(n, len(rows))
        radiance = sources[kinds.index("environment")][1]["radiance"]
        env = (points % n, _local(sub, points, wo_world[points]),
               np.broadcast_to(radiance / (k * k), (len(points), 3)))
    footprint = (owner % n, wi_l, _local(sub, owner, wo_world[owner]), E / (k * k))
    yx = np.stack([ys[sel], xs[sel]], axis=1)
    value = view.photo.linear[yx[:, 0], yx[:, 1]]
    step = None if view.photo.step is None else view.photo.step[yx[:, 0], yx[:, 1]]
    return ViewPixels(yx, value, step, footprint, (wi_c, wo_c, E_c), hits.shape[sel], kinds,
                      env)


def _subset(hits, rows):
    from ..render.rays import Hits
    return Hits(*(getattr(hits, f)[rows] for f in ("hit", "t", "primitive", "shape",
                                                   "position", "normal", "shading", "tangent",
                                                   "bitangent")))


def _rgb(model, wi, wo):
    """``model.eval`` as (n, 3) (a grey model repeated), 0 for no pairs."""
    if len(wi) == 0:
        return np.zeros((0, 3))
    # a source that does not reach a point leaves a zero direction: f is 0 there
    ni, no = np.linalg.norm(wi, axis=1), np.linalg.norm(wo, axis=1)
    real = (ni > 0.0) & (no > 0.0)
    up = np.array([0.0, 0.0, 1.0])
    wi = np.where(real[:, None], wi / np.where(ni > 0.0, ni, 1.0)[:, None], up)
    wo = np.where(real[:, None], wo / np.where(no > 0.0, no, 1.0)[:, None], up)
    f = np.asarray(model.eval(np.ascontiguousarray(wi), np.ascontiguousarray(wo)), float)
    if f.ndim == 1:
        f = f[:, None]
    f = np.broadcast_to(f, (len(wi), 3)) if f.shape[1] == 1 else f
    return np.where(real[:, None], f, 0.0)


#: Polar angles (degrees) of the albedo table that the environment's term interpolates, and
#: azimuths for anisotropic models: the albedo is smooth in theta_o (its cubature costs 4 ms a
#: direction, so a table beats one per pixel).
ALBEDO_THETA = np.linspace(0.0, 90.0, 91)
ALBEDO_PHI = np.linspace(0.0, 360.0, 25)


def _albedo(model, wo):
    """Directional albedo (n, 3) of ``model`` towards local directions ``wo``, linear in a
    table over theta_o (and phi_o for anisotropic models)."""
    from ..geometry import directions_from_degrees
    theta = np.degrees(np.arccos(np.clip(wo[:, 2], 0.0, 1.0)))
    aniso = getattr(model, "is_anisotropic", not getattr(model, "isotropic", True))
    if not aniso:
        nodes = directions_from_degrees(ALBEDO_THETA, np.zeros_like(ALBEDO_THETA))
        a = np.asarray(model.albedo(nodes), float).reshape(len(nodes), -1)
        a = np.broadcast_to(a, (len(nodes), 3)) if a.shape[1] == 1 else a
        return np.stack([np.interp(theta, ALBEDO_THETA, a[:, c]) for c in range(3)], axis=1)
    from scipy.interpolate import RegularGridInterpolator
    t, p = np.meshgrid(ALBEDO_THETA, ALBEDO_PHI, indexing="ij")
    a = np.asarray(model.albedo(directions_from_degrees(t.ravel(), p.ravel())), float)
    a = a.reshape(len(ALBEDO_THETA), len(ALBEDO_PHI), -1)
    a = np.broadcast_to(a, a.shape[:2] + (3,)) if a.shape[2] == 1 else a
    phi = np.degrees(np.arctan2(wo[:, 1], wo[:, 0])) % 360.0
    return RegularGridInterpolator((ALBEDO_THETA, ALBEDO_PHI), a)(np.stack([theta, phi], 1))


def predict(pixels, model):
    """Predicted linear values (n, 3) of the pixels under ``model``: sum over the footprint's
    records of f(wi, wo) E, plus a constant environment's L a(wo) (the direct light only)."""
    pix, wi, wo, E = pixels.footprint
    out = np.zeros((len(pixels), 3))
    np.add.at(out, pix, _rgb(model, wi, wo) * E)
    if pixels.environment is not None:
        epix, ewo, L = pixels.environment
        np.add.at(out, epix, _albedo(model, ewo) * L)
    return out


def samples(pixels, model, scale=1.0, noise=None):
    """BRDF samples of the pixels: ``(wi, wo, f, sigma, keep)`` with the dominant source's
    direction pair per pixel and f from the fixed-point correction (module docstring); the
    first pass (``model`` None) ranks sources by their irradiance and takes f = L / sum E.
    ``scale`` divides the pixels (a fitted exposure); ``keep`` marks the pixels kept.

    ``noise(value, step)`` gives a pixel's standard deviation (None: no sigma). It is taken at
    the predicted value once there is a model (Pearson's chi-square): at the observed value,
    pixels that came out low would get smaller sigma and pull the fit down (Neyman's
    chi-square bias, about -1 / counts relative: -0.6 % at 170 photons)."""
    wi_c, wo_c, E_c = pixels.centre
    n, G = E_c.shape[:2]
    value = pixels.value / scale
    if model is None:
        share = E_c @ LUMA
        P = None
    else:
        f_g = _rgb(model, wi_c.reshape(-1, 3), np.repeat(wo_c, G, axis=0)).reshape(n, G, 3)
        share = np.einsum("ngc,ngc->ng", f_g, E_c * LUMA)
        P = predict(pixels, model)
    dom = np.argmax(share, axis=1)
    total = share.sum(axis=1)
    top = share[np.arange(n), dom]
    keep = (total > 0.0) & (top >= DOMINANT_SHARE * total)
    if "environment" in pixels.kinds and len(set(pixels.kinds)) > 1:
        # a sample at the environment's mean direction stands for an integral over the whole
        # hemisphere: with another source in the scene, such pixels are left out
        keep &= dom != pixels.kinds.index("environment")
    wi = wi_c[np.arange(n), dom]
    E = E_c[np.arange(n), dom]
    keep &= np.all(E > 0.0, axis=1) & (wi[:, 2] > 0.0) & (wo_c[:, 2] > 0.0)
    Es = np.where(E > 0.0, E, 1.0)
    if model is None:
        # a Lambertian guess: the pixel's light from every source, f = L / sum E (exact for a
        # diffuse surface, and for one source f = L / E*)
        Eall = E_c.sum(axis=1)
        f = value / np.where(Eall > 0.0, Eall, 1.0)
    else:
        f = f_g[np.arange(n), dom] + (value - P) / Es
    sigma = None
    if noise is not None:
        sigma = noise(pixels.value if model is None else np.maximum(P * scale, 0.0),
                      pixels.step)
        sigma = None if sigma is None else sigma / scale / Es
    return wi, wo_c, f, sigma, keep
