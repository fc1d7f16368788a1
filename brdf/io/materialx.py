"""Export of a model to MaterialX: an OpenPBR Surface (``open_pbr_surface``) document.

``to_materialx(model) -> Export`` writes a MaterialX 1.39 document holding one
``<open_pbr_surface>`` shader (the node of MaterialX's standard library, OpenPBR Surface 1.1)
and a ``<surfacematerial>`` that references it; ``brdf.export(model, "materialx", path)`` is
the usual way in. The mapping and the measured deviation (the largest relative difference of
f, :func:`brdf.io.export.relative_deviation`, against :func:`openpbr_eval`) are stated in an
XML comment and in the shader's ``doc`` attribute.

The mapping (OpenPBR Surface specification 1.1, academysoftwarefoundation.github.io/OpenPBR;
"spec" below):

* roughness: ``specular_roughness`` r and ``specular_roughness_anisotropy`` a with
  alpha_t = r^2 sqrt(2 / (1 + (1 - a)^2)), alpha_b = (1 - a) alpha_t (spec, "Microfacet model",
  eq. openpbr-anisotropy-formula), inverted exactly: r = ((alpha_t^2 + alpha_b^2) / 2)^(1/4).
  OpenPBR stretches along the tangent; a lobe rougher along our y has ``geometry_tangent``
  connected to a ``<bitangent>`` node (the highlight is the same for either tangent sign, spec).
  r is capped at 1 (the spec's range): alpha above 1 is approximate.
* ``lambert``: base_weight 1, base_color = albedo, base_diffuse_roughness 0, specular_weight 0
  (no specular layer: exact).
* ``oren-nayar``: the same with base_diffuse_roughness: OpenPBR's diffuse is the energy-
  preserving Oren-Nayar (EON) of Portsmouth et al. 2025 (Fujii's form plus a multiple-
  scattering term), ours the qualitative model of Oren & Nayar 1994 eq. 30. They differ on the
  backscattering side and by EON's compensation term, so base_diffuse_roughness and base_color
  are the pair (roughness on a grid of 41) with the smallest relative deviation (approximate).
* ``ggx`` alone (a metal): base_metalness 1 with OpenPBR's F82-tint Fresnel (spec, "Metal",
  Kutz et al. 2021): specular_weight = max ks, base_color = ks F(1) / specular_weight,
  specular_color = the tint that makes F82(1/7) = ks F(1/7). Exact for ``schlick`` with a grey
  ks (F82 with tint 1 is Schlick's), approximate for the other Fresnel terms. A ``ggx`` lobe with
  a ``dielectric`` Fresnel is a dielectric instead: base_weight 0, specular_ior = eta,
  specular_color = ks (exact).
* ``lambert + ggx`` (a plastic): base_metalness 0; the specular lobe becomes the dielectric's
  reflection specular_color F(mu, specular_ior) D G2 / (4 cos cos), and OpenPBR weighs the
  diffuse layer by 1 - E_spec(wo), E_spec the directional albedo of the untinted lobe (spec,
  "Glossy-diffuse" with the albedo scaling of "Layering"; specular_color does not tint the
  light into the base, "Dielectric base"), which ``lambert + ggx`` does not have. So the pair
  (specular_ior, specular_color) is the best of 25 for the whole material: the dielectric
  closest to the lobe (``dielectric`` -> its eta and ks; ``none`` -> F0 = 0.9999 and ks;
  ``schlick``/``conductor`` -> the same F0) and one per F0 on a grid, with specular_color =
  ks F(1) / F0; base_color = albedo c, c the minimax compensation of 1 - E_spec over the
  viewing directions, clamped to [0, 1] (approximate).
* ``beckmann`` -> GGX with the same alpha (OpenPBR is GGX only: approximate); separable Smith
  masking -> OpenPBR's height-correlated Smith G2 (Heitz 2014, eq. 99: approximate).
* Other families (phong, ward, lafortune, ...), mirrors and sums of more than one diffuse and
  one specular lobe have no counterpart here and are refused.

OpenPBR leaves multiple scattering between microfacets to the renderer ("should ideally account
for this"); :func:`openpbr_eval` evaluates the single-scattering lobes the spec writes, like
our models, so renderers that add an energy-compensation lobe (MaterialX's GLSL) are brighter
for rough lobes than the deviation says.

``to_materialx(model, "standard_surface")`` (``format="materialx-standard-surface"``) writes
an Autodesk Standard Surface instead, measured against :func:`standard_surface_eval`, which
follows MaterialX's graph of that node (the Standard Surface document leaves the anisotropy,
Oren-Nayar and layering details to implementations). There ``oren-nayar`` (sigma <= 1) and
``ggx`` conductors are exact: MaterialX's Oren-Nayar is eq. 30 with sigma = diffuse_roughness,
and its metal is the exact conductor Fresnel of Gulbrandsen's index for (base_color,
specular_color), which we invert; roughness r^2 = sqrt(alpha_x alpha_y), anisotropy
1 - alpha_min / alpha_max, specular_rotation 0.25 for a lobe rougher along y; a plastic's
specular weight also scales E_spec in the layering, so a Fresnel-free lobe maps closely.
"""

import functools
import math
from xml.sax.saxutils import quoteattr

import numpy as np

from ..errors import InputError
from .export import EXACT, Export, NoCounterpart, relative_deviation

__all__ = ["to_materialx", "openpbr_eval", "standard_surface_eval", "check_materialx",
           "EXPORTABLE", "NODE", "SS_NODE", "MATERIALX_VERSION"]

#: The standard-library node written (nodedef ``ND_open_pbr_surface_surfaceshader``).
NODE = "open_pbr_surface"
#: The MaterialX document version written.
MATERIALX_VERSION = "1.39"
#: Our RGB channels as they are: linear, Rec. 709 primaries (MaterialX's default working space,
#: stated so that no reader converts them).
COLORSPACE = "lin_rec709"
SHADER_NAME, MATERIAL_NAME, BITANGENT_NAME = "brdf_shader", "brdf_material", "brdf_bitangent"
DIFFUSE, SPECULAR = ("lambert", "oren-nayar"), ("ggx", "beckmann")
#: Model shapes that export (a sum's lobes in any order).
EXPORTABLE = (*DIFFUSE, *SPECULAR, *(f"{d} + {s}" for d in DIFFUSE for s in SPECULAR))
#: F0 that stands for Fresnel ``none`` (F = 1) in a dielectric: F is within 1e-4 of 1 at every
#: angle (MaterialX's reference graph clamps the modulated F0 at 0.99999).
F0_NONE = 0.9999
#: The F82-tint model's reference cosine (spec, "Metal": mu-bar = 1/7, about 82 degrees).
MU_BAR = 1.0 / 7.0
#: Inputs of open_pbr_surface this module writes or reads, with the nodedef's defaults.
DEFAULTS = {"base_weight": 1.0, "base_color": (0.8, 0.8, 0.8), "base_diffuse_roughness": 0.0,
            "base_metalness": 0.0, "specular_weight": 1.0, "specular_color": (1.0, 1.0, 1.0),
            "specular_roughness": 0.3, "specular_ior": 1.5, "specular_roughness_anisotropy": 0.0}
#: Inputs whose non-default values open_pbr_eval does not evaluate (their defaults switch them
#: off: no coat, fuzz, transmission, subsurface, thin film or emission).
OFF = ("coat_weight", "fuzz_weight", "transmission_weight", "subsurface_weight",
       "thin_film_weight", "emission_luminance")
TYPES = {"base_color": "color3", "specular_color": "color3"}
#: Quadrature of the specular lobe's directional albedo: midpoints of an N x N grid over the
#: square that samples D(h) cos(theta_h) (see specular_albedo).
ALBEDO_GRID = 192


# --- the evaluator --------------------------------------------------------------------------------

def openpbr_eval(params, wi, wo, albedo_grid=None):
    """The BRDF (no cosine) an ``open_pbr_surface`` with ``params`` describes, shaped (..., 3).

    OpenPBR Surface 1.1 with coat, fuzz, transmission, subsurface, thin film and emission off
    (the base substrate): mix(glossy-diffuse, metal, base_metalness), where glossy-diffuse is
    f_spec + (1 - E_spec(wo)) f_diffuse (spec, "Glossy-diffuse", the non-reciprocal albedo
    scaling; wo is the viewer), f_spec the GGX dielectric reflection tinted by specular_color
    with the ior modulated by specular_weight (spec, eq. modulated_ior), f_diffuse the EON
    diffuse (Portsmouth et al. 2025) and the metal GGX with the F82-tint Fresnel. Masking is
    Smith's height-correlated G2 (Heitz 2014, eq. 99); single scattering only. E_spec is the
    albedo of the untinted lobe: specular_color tints the first reflection only, the light
    transmitted into the base is not (spec, "Dielectric base"; MaterialX's dielectric_bsdf,
    which the spec's reference graph layers over the base, weighs it so too).

    Parameters
    ----------
    params : dict
        Input names of ``open_pbr_surface`` to values (floats, or 3 floats for colors); missing
        inputs take the nodedef's defaults. ``"geometry_tangent": "bitangent"`` turns the
        anisotropy's tangent to our y axis (the document's ``<bitangent>`` connection).
    wi, wo : array_like, shape (..., 3)
        Directions towards the light and the viewer in the local frame.
    albedo_grid : int, optional
        Quadrature size of E_spec (default :data:`ALBEDO_GRID`).

    Returns
    -------
    ndarray, shape (..., 3)
    """
    p = {**DEFAULTS, **params}
    on = [name for name in OFF if float(p.get(name, 0.0)) != 0.0]
    if on:
        raise InputError(f"openpbr_eval evaluates the base and specular layers only; "
                         f"{', '.join(on)} must be 0")
    wi, wo = np.broadcast_arrays(np.asarray(wi, float), np.asarray(wo, float))
    if p.get("geometry_tangent") == "bitangent":  # tangent along y: rotate the frame by 90 deg
        wi, wo = _quarter_turn(wi), _quarter_turn(wo)
    at, ab = openpbr_alphas(p["specular_roughness"], p["specular_roughness_anisotropy"])
    mu, above, dg = _ggx_terms(wi, wo, at, ab)
    metalness = float(p["base_metalness"])
    out = 0.0
    if metalness > 0.0:
        f0 = float(p["base_weight"]) * _rgb(p["base_color"])
        fresnel = float(p["specular_weight"]) * f82_tint(f0, _rgb(p["specular_color"]),
                                                         mu[..., None])
        out = out + metalness * fresnel * dg
    if metalness < 1.0:
        eta = modulated_ior(p["specular_ior"], p["specular_weight"])
        tint = _rgb(p["specular_color"])
        spec = tint * dielectric_fresnel(mu, eta)[..., None] * dg
        albedo = (specular_albedo(wo, at, ab, eta, albedo_grid)[..., None]
                  if float(p["base_weight"]) != 0.0 else 0.0)  # no base: E_spec weighs nothing
        diffuse = eon_eval(p["base_color"], p["base_diffuse_roughness"], wi, wo) * float(
            p["base_weight"])
        out = out + (1.0 - metalness) * (spec + (1.0 - albedo) * diffuse)
    return np.where(above[..., None], out, 0.0)


def _rgb(value):
    return np.broadcast_to(np.asarray(value, float), (3,)).copy()


def _quarter_turn(v):
    """Coordinates in the frame whose tangent is our y (x' = y, y' = -x)."""
    return np.stack([v[..., 1], -v[..., 0], v[..., 2]], axis=-1)


def openpbr_alphas(roughness, anisotropy):
    """(alpha_t, alpha_b) of OpenPBR's roughness and anisotropy (spec 1.1, "Microfacet model",
    eq. openpbr-anisotropy-formula), floored at 1e-4 as our models are."""
    r, a = float(roughness), float(anisotropy)
    at = r * r * math.sqrt(2.0 / (1.0 + (1.0 - a) ** 2))
    return max(at, 1e-4), max((1.0 - a) * at, 1e-4)


def openpbr_roughness(alpha_t, alpha_b):
    """(roughness, anisotropy) with :func:`openpbr_alphas` = (alpha_t, alpha_b), alpha_t >=
    alpha_b: alpha_t^2 + alpha_b^2 = 2 r^4 and 1 - a = alpha_b / alpha_t (the same equation)."""
    r = ((alpha_t ** 2 + alpha_b ** 2) / 2.0) ** 0.25
    return r, 1.0 - alpha_b / alpha_t


def _ggx_terms(wi, wo, at, ab):
    """``(mu, above, D G2 / (4 cos_i cos_o))`` of a GGX lobe shared by both shaders: mu is
    wo.h clipped to [0, 1], ``above`` where both directions are above the horizon, and the
    microfacet term shaped (..., 1), 0 below it."""
    h = wi + wo
    h = h / np.linalg.norm(h, axis=-1, keepdims=True)
    mu = np.clip(np.sum(wo * h, axis=-1), 0.0, 1.0)
    ci, co = wi[..., 2], wo[..., 2]
    above = (ci > 0.0) & (co > 0.0)
    dg = np.where(above, _ggx_d(h, at, ab) * _ggx_g2(wi, wo, at, ab)
                  / (4.0 * np.where(above, ci * co, 1.0)), 0.0)[..., None]
    return mu, above, dg


def _ggx_d(h, at, ab):
    # anisotropic GGX normal distribution (Heitz 2014, eq. 85)
    return 1.0 / (math.pi * at * ab * ((h[..., 0] / at) ** 2 + (h[..., 1] / ab) ** 2
                                       + h[..., 2] ** 2) ** 2)


def _ggx_lambda(v, at, ab):
    # Smith Lambda of anisotropic GGX (Heitz 2014, eqs. 72 and 86)
    z2 = np.maximum(v[..., 2] ** 2, 1e-300)
    a2 = ((at * v[..., 0]) ** 2 + (ab * v[..., 1]) ** 2) / z2
    return 0.5 * (np.sqrt(1.0 + a2) - 1.0)


def _ggx_g2(wi, wo, at, ab):
    # height-correlated masking-shadowing (Heitz 2014, eq. 99)
    return 1.0 / (1.0 + _ggx_lambda(wi, at, ab) + _ggx_lambda(wo, at, ab))


def modulated_ior(ior, weight):
    """The dielectric's ior ratio after specular_weight (spec 1.1, "Dielectric base", eqs.
    unmodulated_fresnel and modulated_ior, with the weight clamped to [0, 1 / F_s]); inf when
    the modulated F0 is 1."""
    eta = float(ior)
    fs = ((1.0 - eta) / (1.0 + eta)) ** 2
    xi = min(max(float(weight), 0.0), 1.0 / fs if fs > 0.0 else math.inf)
    eps = math.copysign(math.sqrt(xi * fs), eta - 1.0)
    return math.inf if eps >= 1.0 else (1.0 + eps) / (1.0 - eps)


def ior_of_f0(f0):
    """The ior ratio above 1 whose dielectric reflectance at normal incidence is ``f0``."""
    s = math.sqrt(min(max(float(f0), 0.0), F0_NONE))
    return (1.0 + s) / (1.0 - s)


def dielectric_fresnel(cos, eta):
    """Unpolarised Fresnel reflectance of a dielectric interface with ior ratio ``eta`` (Walter
    et al. 2007, eq. 22; total internal reflection gives 1)."""
    c = np.abs(np.asarray(cos, float))
    if math.isinf(eta):
        return np.ones_like(c)
    g2 = eta * eta - 1.0 + c * c
    g = np.sqrt(np.maximum(g2, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        a = (g - c) / (g + c)
        b = (c * (g + c) - 1.0) / (c * (g - c) + 1.0)
        f = 0.5 * a * a * (1.0 + b * b)
    return np.where(g2 > 0.0, np.nan_to_num(f, nan=1.0), 1.0)


def f82_tint(f0, tint, mu):
    """The F82-tint metal Fresnel with specular_weight 1 (spec 1.1, "Metal"; Kutz et al. 2021,
    after Hoffman 2019): Schlick's curve minus a mu (1 - mu)^6 term that brings it to tint x
    Schlick at mu-bar = 1/7."""
    def schlick(m):
        return f0 + (1.0 - f0) * (1.0 - m) ** 5
    mu = np.asarray(mu, float)
    b = MU_BAR * (1.0 - MU_BAR) ** 6
    return schlick(mu) - mu * (1.0 - mu) ** 6 / b * (schlick(MU_BAR) - tint * schlick(MU_BAR))


def specular_albedo(wo, at, ab, eta, grid=None):
    """Directional albedo at ``wo`` of the untinted dielectric reflection lobe F D G2 / (4 cos
    cos), by midpoint quadrature over the square that samples D(h) cos(theta_h) (slope-space
    stretching of the isotropic GGX, Heitz 2014, sec. 5.3): E = mean of F G2 (wo.h) /
    (cos_o cos_h). Computed once per distinct wo."""
    if eta == 1.0:
        return np.zeros(wo.shape[:-1])
    n = grid or ALBEDO_GRID
    flat = np.ascontiguousarray(wo, dtype=float).reshape(-1, 3)
    if at == ab:  # isotropic: E depends on cos(theta_o) only
        z = np.clip(flat[:, 2], -1.0, 1.0)
        flat = np.stack([np.sqrt(1.0 - z * z), np.zeros_like(z), z], axis=-1)
    unique, inverse = np.unique(flat, axis=0, return_inverse=True)
    if len(unique) > TABULATE_ABOVE:  # many directions (random pairs): interpolate a table
        return _tabulated_albedo(flat, at, ab, eta, n).reshape(wo.shape[:-1])
    albedo = _albedo_of_unique(unique.tobytes(), float(at), float(ab), float(eta), n)
    return albedo[inverse.ravel()].reshape(wo.shape[:-1])


#: Beyond this many distinct directions, :func:`specular_albedo` interpolates a table of
#: TABLE_Z cos(theta_o) nodes from Z_MIN (E jumps to 0 at the horizon itself) times TABLE_PHI
#: azimuths when anisotropic (with a coarser quadrature, TABLE_GRID); E is smooth there, and the
#: interpolation stays within 1.1e-4 of the quadrature (isotropic; 0.016 anisotropic, median
#: 8e-5, measured on 6,000 random directions).
TABULATE_ABOVE, TABLE_Z, TABLE_PHI, TABLE_GRID, Z_MIN = 4096, 257, 32, 96, 1e-4


def _tabulated_albedo(flat, at, ab, eta, n):
    z_nodes = np.linspace(Z_MIN, 1.0, TABLE_Z)
    z = np.clip(flat[:, 2], Z_MIN, 1.0)
    s = np.sqrt(1.0 - z_nodes ** 2)
    if at == ab:
        nodes = np.stack([s, np.zeros_like(s), z_nodes], axis=-1)
        table = _albedo_of_unique(nodes.tobytes(), float(at), float(ab), float(eta), n)
        return np.interp(z, z_nodes, table)
    z_nodes = np.linspace(Z_MIN, 1.0, 65)
    phi_nodes = np.linspace(0.0, 2.0 * math.pi, TABLE_PHI + 1)
    zz, pp = np.meshgrid(z_nodes, phi_nodes, indexing="ij")
    ss = np.sqrt(1.0 - zz ** 2)
    nodes = np.stack([ss * np.cos(pp), ss * np.sin(pp), zz], axis=-1).reshape(-1, 3)
    table = _albedo_of_unique(nodes.tobytes(), float(at), float(ab), float(eta),
                              min(n, TABLE_GRID)).reshape(zz.shape)
    phi = np.mod(np.arctan2(flat[:, 1], flat[:, 0]), 2.0 * math.pi)
    fz = (z - Z_MIN) / (1.0 - Z_MIN) * (len(z_nodes) - 1)
    fp = phi / (2.0 * math.pi) * TABLE_PHI
    i = np.minimum(fz.astype(int), len(z_nodes) - 2)
    j = np.minimum(fp.astype(int), TABLE_PHI - 1)
    tz, tp = fz - i, fp - j
    return ((1 - tz) * ((1 - tp) * table[i, j] + tp * table[i, j + 1])
            + tz * ((1 - tp) * table[i + 1, j] + tp * table[i + 1, j + 1]))


@functools.lru_cache(maxsize=64)
def _albedo_of_unique(directions, at, ab, eta, n):
    """specular_albedo's quadrature for distinct directions (given as float64 bytes); cached,
    as a plastic's search asks for the same directions twice per candidate."""
    unique = np.frombuffer(directions, float).reshape(-1, 3)
    u = (np.arange(n) + 0.5) / n
    u1, u2 = np.meshgrid(u, u, indexing="ij")
    radius = np.sqrt(u1 / (1.0 - u1)).ravel()  # slope radius of the unit GGX: P(r) = r^2/(1+r^2)
    phi = 2.0 * math.pi * u2.ravel()
    m = np.stack([-at * radius * np.cos(phi), -ab * radius * np.sin(phi),
                  np.ones_like(radius)], axis=-1)
    m /= np.linalg.norm(m, axis=-1, keepdims=True)
    albedo = np.zeros(len(unique))
    step = max(1, 400_000 // len(m))  # directions per chunk: arrays of about 400k pairs
    for start in range(0, len(unique), step):
        v = unique[start:start + step, None, :]  # (c, 1, 3)
        vh = np.sum(v * m, axis=-1)  # (c, N)
        wi = 2.0 * vh[..., None] * m - v
        ok = (vh > 0.0) & (wi[..., 2] > 0.0) & (v[..., 2] > 0.0)
        term = np.where(ok, dielectric_fresnel(vh, eta) * _ggx_g2(wi, np.broadcast_to(
            v, wi.shape), at, ab) * vh / np.maximum(v[..., 2] * m[:, 2], 1e-300), 0.0)
        albedo[start:start + step] = term.sum(axis=-1) / len(m)
    albedo.flags.writeable = False
    return albedo


#: Fujii's constant in A = 1 / (1 + FUJII sigma) (spec 1.1, footnote to eq. FON_brdf).
FUJII = 0.5 - 2.0 / (3.0 * math.pi)


def fon_albedo(mu, sigma):
    """Directional albedo of Fujii's Oren-Nayar with rho = 1 at cosine ``mu``, in closed form
    (Portsmouth et al. 2025, "EON: A practical energy-preserving rough diffuse BRDF", JCGT
    14(1), E_FON): A + B G(theta) / pi."""
    a = 1.0 / (1.0 + FUJII * sigma)
    mu = np.clip(np.asarray(mu, float), 1e-12, 1.0)
    si = np.sqrt(1.0 - mu * mu)
    g = si * (np.arccos(mu) - si * mu) + 2.0 / 3.0 * ((si / mu) * (1.0 - si ** 3) - si)
    return a + sigma * a * g / math.pi


def fon_average_albedo(sigma):
    """Cosine-weighted average of :func:`fon_albedo`, 2 int E mu dmu, in closed form (Portsmouth
    et al. 2025): A (1 + (2/3 - 28 / (15 pi)) sigma)."""
    return (1.0 + (2.0 / 3.0 - 28.0 / (15.0 * math.pi)) * sigma) / (1.0 + FUJII * sigma)


def eon_eval(rho, sigma, wi, wo):
    """The energy-preserving Oren-Nayar BRDF (EON) with base_weight 1, shaped (..., 3):
    Fujii's form rho / pi (A + B s / t) plus the multiple-scattering term rho_ms / pi
    (1 - E(wi)) (1 - E(wo)) / (1 - <E>), rho_ms = rho^2 <E> / (1 - rho (1 - <E>)) (Portsmouth
    et al. 2025, "EON", JCGT 14(1), the BRDF of its listing; spec 1.1 eqs. FON_brdf and
    EON_comp, whose printed rho_ms carries an extra 1 / pi: with it a white EON would reflect
    1 / pi of what the compensation must add, against the furnace test the spec states).
    sigma = 0 is Lambert's rho / pi exactly."""
    rho, sigma = _rgb(rho), float(sigma)
    ci, co = wi[..., 2], wo[..., 2]
    if sigma == 0.0:
        return np.broadcast_to(rho / math.pi, (*ci.shape, 3)).copy()
    a = 1.0 / (1.0 + FUJII * sigma)
    s = np.sum(wi * wo, axis=-1) - ci * co
    t = np.where(s > 0.0, np.maximum(ci, co), 1.0)
    fon = (a + sigma * a * s / t)[..., None] * rho / math.pi
    ei, eo, e_avg = fon_albedo(ci, sigma), fon_albedo(co, sigma), fon_average_albedo(sigma)
    rho_ms = rho * rho * e_avg / (1.0 - rho * (1.0 - e_avg))
    ms = ((1.0 - ei) * (1.0 - eo) / (1.0 - e_avg))[..., None] * rho_ms / math.pi
    return fon + ms


# --- the mapping ----------------------------------------------------------------------------------

def _lobes(model):
    """(diffuse lobe or None, specular lobe or None, their flat names)."""
    from ..models.base import Sum
    names = model.lobe_names() if isinstance(model, Sum) else [model.name]
    diffuse = [(n, lobe) for n, lobe in zip(names, model.lobes) if lobe.name in DIFFUSE]
    specular = [(n, lobe) for n, lobe in zip(names, model.lobes) if lobe.name in SPECULAR]
    return (diffuse[0] if diffuse else (None, None)), (specular[0] if specular else (None, None))


def check_materialx(model):
    """Raise the one-line error :func:`to_materialx` gives for a model without a counterpart in
    either shader, converting nothing (``brdf-fit fit --export`` asks before it fits)."""
    (dn, diffuse), (sn, specular) = _lobes(model)
    count = (diffuse is not None) + (specular is not None)
    if count != len(model.lobes):
        others = sorted({lobe.name for lobe in model.lobes} - set(DIFFUSE) - set(SPECULAR))
        why = (f": {', '.join(others)} not in the base and specular layers of OpenPBR or "
               "Standard Surface" if others else
               ": these shaders have one diffuse and one specular lobe (a second specular lobe "
               "would be a coat, not written yet)")
        raise NoCounterpart(f"{model}: no materialx equivalent{why}; materialx maps "
                            f"{', '.join(EXPORTABLE)}")


def _fresnel_at(fresnel, cos):
    """Our Fresnel term at one cosine, per channel."""
    from ..models.fresnel import conductor_reflectance, dielectric_reflectance, schlick
    if fresnel.name == "none":
        return np.ones(1)
    if fresnel.name == "schlick":
        return np.array([schlick(f, cos) for f in np.atleast_1d(fresnel["f0"])])
    if fresnel.name == "dielectric":
        return np.array([dielectric_reflectance(cos, e) for e in np.atleast_1d(fresnel["eta"])])
    eta, k = np.broadcast_arrays(np.atleast_1d(fresnel["eta"]), np.atleast_1d(fresnel["k"]))
    return np.array([conductor_reflectance(cos, e, kk) for e, kk in zip(eta, k)])


def _grey(value):
    arr = np.atleast_1d(np.asarray(value, float))
    return bool(np.all(arr == arr[0]))


def _roughness(lobe, name, params, notes):
    ax = float(lobe["alpha"])
    ay = float(lobe.get("alpha_y")) if lobe.get("alpha_y") is not None else ax
    at, ab = max(ax, ay), min(ax, ay)
    r, a = openpbr_roughness(at, ab)
    capped = r > 1.0
    params["specular_roughness"] = min(r, 1.0)
    if a > 0.0:
        params["specular_roughness_anisotropy"] = a
    if ay > ax:
        params["geometry_tangent"] = "bitangent"
    notes.append(f"{name}: specular_roughness = ((alpha_t^2 + alpha_b^2) / 2)^(1/4)"
                 + (", specular_roughness_anisotropy = 1 - alpha_b / alpha_t" if a > 0 else "")
                 + (", geometry_tangent = the bitangent (rougher along y)" if ay > ax else "")
                 + (f" (OpenPBR: alpha_t = r^2 sqrt(2 / (1 + (1 - a)^2)), alpha_b = (1 - a) "
                    f"alpha_t), " + ("approximate: roughness capped at 1" if capped else "exact")))
    _ggx_only_notes(lobe, name, "OpenPBR", "OpenPBR", notes)


def _ggx_only_notes(lobe, name, shader, owner, notes):
    """Notes on what a GGX-only shader with height-correlated masking approximates of a
    microfacet lobe: Beckmann normals, separable masking."""
    if lobe.name == "beckmann":
        notes.append(f"{name}: Beckmann normals -> GGX with the same alpha ({shader} is GGX "
                     "only), approximate")
    if lobe["masking"] == "separable":
        notes.append(f"{name}: separable Smith masking -> {owner}'s height-correlated G2, "
                     "approximate")


def _metal(lobe, name, params, notes):
    """base_metalness 1 with the F82-tint Fresnel fitted at mu = 1 and mu = 1/7."""
    ks = np.atleast_1d(np.asarray(lobe["ks"], float))
    fresnel = lobe["fresnel"]
    f_normal, f_edge = ks * _fresnel_at(fresnel, 1.0), ks * _fresnel_at(fresnel, MU_BAR)
    weight = float(ks.max())
    params.update(base_metalness=1.0, specular_weight=weight)
    if weight == 0.0:
        params.update(base_color=(0.0, 0.0, 0.0))
        notes.append(f"{name}: ks 0, reflects nothing: specular_weight 0, exact")
        return
    base = np.minimum(_rgb(f_normal / weight), 1.0)
    schlick_edge = base + (1.0 - base) * (1.0 - MU_BAR) ** 5
    tint = np.clip(_rgb(f_edge / weight) / schlick_edge, 0.0, 1.0)
    params.update(base_color=tuple(base), specular_color=tuple(tint))
    exact = fresnel.name in ("schlick", "none") and _grey(ks)
    notes.append(f"{name}: base_metalness 1, specular_weight = max ks, base_color = ks F(1) / "
                 "specular_weight, specular_color = the F82 tint matching ks F(1/7) (OpenPBR's "
                 "F82-tint Schlick Fresnel), " + (
                     "exact" if exact else "approximate (exact for schlick or none with a grey "
                                           "ks)"))


def _dielectric(lobe, name, params, notes):
    """The specular lobe as OpenPBR's dielectric reflection: specular_ior and specular_color."""
    ks = np.atleast_1d(np.asarray(lobe["ks"], float))
    fresnel = lobe["fresnel"]
    if fresnel.name == "dielectric" and _grey(fresnel["eta"]):
        ior, color = float(np.atleast_1d(fresnel["eta"])[0]), _rgb(ks)
        how, exact = "specular_ior = eta, specular_color = ks", True
    elif fresnel.name == "none":
        ior, color = ior_of_f0(F0_NONE), _rgb(ks)
        how, exact = (f"Fresnel none -> specular_ior {ior_of_f0(F0_NONE):.6g} (F0 = {F0_NONE}: "
                      "F within 1e-4 of 1), specular_color = ks"), False
    else:
        f0 = _rgb(_fresnel_at(fresnel, 1.0))
        top = float(f0.max())
        ior, color = ior_of_f0(top), _rgb(ks) * (f0 / top if top > 0.0 else 1.0)
        how, exact = ("specular_ior with the same F0 (the dielectric Fresnel curve), "
                      "specular_color = ks F0 / max F0"), False
    clipped = bool(np.any(color > 1.0))
    params.update(specular_weight=1.0, specular_ior=ior,
                  specular_color=tuple(np.clip(color, 0.0, 1.0)))
    notes.append(f"{name}: dielectric specular layer, {how}, " + (
        "approximate: specular_color clamped to [0, 1]" if clipped else
        "exact" if exact else "approximate"))


def _diffuse(lobe, name, params, notes):
    """base_color and base_diffuse_roughness of the diffuse lobe alone."""
    rho = _rgb(lobe["albedo"])
    if lobe.name == "oren-nayar" and float(lobe["sigma"]) == 0.0:
        notes.append(f"{name}: oren-nayar with sigma 0 is Lambert: base_color = albedo, "
                     "base_diffuse_roughness 0, exact")
    elif lobe.name == "oren-nayar":
        sigma, rho = _eon_match(lobe)
        params["base_diffuse_roughness"] = sigma
        notes.append(f"{name}: oren-nayar -> base_diffuse_roughness and base_color minimising "
                     "the relative deviation of OpenPBR's energy-preserving Oren-Nayar (EON, "
                     "Portsmouth et al. 2025) from Oren & Nayar's eq. 30 (they differ on the "
                     "backscattering side and by EON's multiple-scattering term), approximate")
    else:
        notes.append(f"{name}: lambert -> base_color = albedo, base_diffuse_roughness 0 "
                     "(OpenPBR's EON diffuse is Lambert at 0), exact")
    clipped = bool(np.any(rho > 1.0))
    params.update(base_weight=1.0, base_color=tuple(np.clip(rho, 0.0, 1.0)))
    if clipped:
        notes.append(f"{name}: base_color clamped to [0, 1], approximate")


def _eon_match(lobe):
    """(base_diffuse_roughness, base_color) of the EON lobe closest to an ``oren-nayar`` lobe:
    for each roughness on a grid of 41 in [0, 1], the colour that minimises the largest
    relative difference per channel (2 / (min + max) of the ratio, EON being nearly linear in
    rho); the pair with the smallest :func:`relative_deviation` wins. The grid starts from
    rho A_ON / A_FON, which matches Fujii's form to eq. 30 on the forward side."""
    from ..geometry import directions_from_degrees
    from .export import GRID_PHI_I, GRID_PHI_O, GRID_THETA
    ti, pi_, to, po = np.meshgrid(GRID_THETA, GRID_PHI_I, GRID_THETA, GRID_PHI_O, indexing="ij")
    wi, wo = directions_from_degrees(ti.ravel(), pi_.ravel()), directions_from_degrees(
        to.ravel(), po.ravel())
    ours = np.broadcast_to(lobe.eval(wi, wo), (len(wi), 3))
    keep = ours.max(axis=1) >= 1e-3 * ours.max()
    ours = ours[keep]
    wi, wo = wi[keep], wo[keep]
    s2 = float(lobe["sigma"]) ** 2
    a_on = 1.0 - 0.5 * s2 / (s2 + 0.33)  # Oren & Nayar 1994, eq. 30
    best = None
    for sigma in np.linspace(0.0, 1.0, 41):
        rho = np.minimum(_rgb(lobe["albedo"]) * a_on * (1.0 + FUJII * sigma), 1.0)
        q = eon_eval(rho, sigma, wi, wo) / np.maximum(ours, 1e-300)
        rho = np.clip(rho * 2.0 / np.maximum(q.min(axis=0) + q.max(axis=0), 1e-300), 0.0, 1.0)
        dev = float((np.abs(eon_eval(rho, sigma, wi, wo) - ours) / np.maximum(ours, 1e-300))
                    .max())
        if best is None or dev < best[0]:
            best = (dev, float(sigma), rho)
    return best[1], best[2]


def _mapping(model, shader=NODE):
    """(params, notes) of the ``shader`` node for ``model``: floats, and tuples of 3 floats for
    colours."""
    params, notes = (_inputs if shader == NODE else _ss_inputs)(model)
    return {k: v if isinstance(v, str) else tuple(float(c) for c in v) if np.ndim(v) else
            float(v) for k, v in params.items()}, notes


def _inputs(model):
    """The inputs (numpy values) and notes, before _mapping makes them plain floats."""
    check_materialx(model)
    (dn, diffuse), (sn, specular) = _lobes(model)
    params, notes = {}, []
    if specular is None:
        params.update(specular_weight=0.0)
        notes.append(f"{dn}: specular_weight 0 (no specular layer), exact")
        _diffuse(diffuse, dn, params, notes)
        return params, notes
    _roughness(specular, sn, params, notes)
    if diffuse is None and specular["fresnel"].name != "dielectric":
        _metal(specular, sn, params, notes)
        return params, notes
    params.update(base_metalness=0.0)
    if diffuse is None:
        _dielectric(specular, sn, params, notes)
        params.update(base_weight=0.0)
        notes.append(f"{sn}: base_weight 0 (no diffuse layer under the dielectric), exact")
        return params, notes
    _diffuse(diffuse, dn, params, notes)
    _plastic(model, specular, sn, params, notes)
    return params, notes


def _plastic(model, lobe, name, params, notes):
    """specular_ior, specular_color and the compensated base_color of a diffuse + specular
    model, the most faithful of 25 candidates: the dielectric closest to the lobe alone (see
    _dielectric) and one per F0 on a geometric grid from 0.02 to F0_NONE, with specular_color
    = ks F(1) / F0 (clamped); each with base_color divided per the minimax of the 1 - E_spec(wo)
    weight over relative_deviation's viewing directions. The smallest deviation wins."""
    from ..geometry import directions_from_degrees
    from .export import GRID_PHI_O, GRID_THETA
    t, p = np.meshgrid(GRID_THETA, GRID_PHI_O, indexing="ij")
    wo = directions_from_degrees(t.ravel(), p.ravel())
    at, ab = openpbr_alphas(params["specular_roughness"],
                            params.get("specular_roughness_anisotropy", 0.0))
    if params.get("geometry_tangent") == "bitangent":
        wo = _quarter_turn(wo)
    rho = np.asarray(params["base_color"])
    first = []
    _dielectric(lobe, name, params, first)
    ks = _rgb(np.atleast_1d(np.asarray(lobe["ks"], float)) * _fresnel_at(lobe["fresnel"], 1.0))
    candidates = [(params["specular_ior"], np.asarray(params["specular_color"]))] + [
        (ior_of_f0(f0), np.clip(ks / f0, 0.0, 1.0)) for f0 in np.geomspace(0.02, F0_NONE, 24)]
    best = None
    for ior, color in candidates:
        e = specular_albedo(wo, at, ab, modulated_ior(ior, 1.0), 48)
        weight = 1.0 - e
        base = np.clip(rho * 2.0 / max(weight.min() + weight.max(), 1e-300), 0.0, 1.0)
        trial = {**params, "specular_ior": ior, "specular_color": tuple(color),
                 "base_color": tuple(base)}
        dev = relative_deviation(model.eval, lambda wi, wo_: openpbr_eval(trial, wi, wo_, 48))
        if best is None or dev < best[0]:
            best = (dev, trial, ior, color, rho * 2.0 / max(weight.min() + weight.max(), 1e-300))
    _, trial, ior, color, base = best
    params.update(trial)
    if ior == candidates[0][0] and np.array_equal(color, candidates[0][1]):
        notes.extend(first)
    else:
        notes.append(f"{name}: dielectric specular layer, specular_ior {ior:.6g} (F0 "
                     f"{float(dielectric_fresnel(1.0, ior)):.4g}) and specular_color = ks F(1) / "
                     "F0, the F0 of 24 on a grid (and the dielectric closest to the lobe alone) "
                     "that gives the whole material the smallest deviation, approximate")
    notes.append(f"{name}: base_color divided by the mean of the extreme 1 - E_spec(wo) weights "
                 "OpenPBR's albedo scaling puts on the diffuse layer, approximate")
    if np.any(base > 1.0):
        notes.append(f"{name}: base_color clamped to [0, 1], approximate")


# --- the document -----------------------------------------------------------------------------

def _value(value):
    arr = np.atleast_1d(np.asarray(value, float))
    return ", ".join(repr(float(v)) for v in arr)


def to_materialx(model, shader=NODE, source=None, lead=(), closest=None):
    """Convert ``model`` to a MaterialX document with an ``open_pbr_surface`` (or a
    ``standard_surface``) and the ``surfacematerial`` that uses it.

    Parameters
    ----------
    model : Model
    shader : {"open_pbr_surface", "standard_surface"}
    source : Model, optional
        What ``model`` stands for (the model a closest material was fitted to): the figures
        and the file's comment are about it. Default: ``model``.
    lead : sequence of str
        Notes that come before the mapping's.
    closest : str, optional
        The fitted family, when ``model`` is a closest material.

    Returns
    -------
    Export
        ``format`` ``"materialx"`` (``"materialx-standard-surface"``), the document's text, and
        ``equivalent``: the shader's inputs as :func:`openpbr_eval`
        (:func:`standard_surface_eval`) takes them.

    Raises
    ------
    InputError
        For a model without a counterpart (the message lists the shapes that export).
    """
    from .. import __version__
    from .closest_material import relative_rms
    source = model if source is None else source
    title, order, evaluate = SHADERS[shader]  # defined at the end, after Standard Surface
    params, notes = _mapping(model, shader)
    notes = [*lead, *notes]

    def theirs(wi, wo):
        return evaluate(params, wi, wo)
    deviation = relative_deviation(source.eval, theirs)
    exact = deviation <= EXACT and not any("approximate" in n for n in notes)
    error = 0.0 if exact else relative_rms(source, theirs)
    verdict = ("exact" if exact else "APPROXIMATE") + (
        f": largest relative difference of f over directions up to 80 degrees {deviation:.3g}; "
        f"relative RMS difference (projected solid angle) {error:.3g}")
    comment = [f"brdf {__version__} export of {source} as {title}", verdict, *notes,
               "multiple scattering between microfacets, if the renderer compensates it, is not "
               "counted"]
    lines = ['<?xml version="1.0" encoding="UTF-8"?>', "<!--",
             *(f"  {_comment(line)}" for line in comment), "-->",
             f'<materialx version="{MATERIALX_VERSION}" colorspace="{COLORSPACE}">']
    tangent = params.get("geometry_tangent") == "bitangent"
    if tangent:
        lines += [f'  <bitangent name="{BITANGENT_NAME}" type="vector3">',
                  '    <input name="space" type="string" value="world" />', "  </bitangent>"]
    doc = f"brdf export of {source}: {verdict}"
    lines.append(f'  <{shader} name="{SHADER_NAME}" type="surfaceshader" doc={quoteattr(doc)}>')
    for name in order:
        if name in params:
            lines.append(f'    <input name="{name}" type="{TYPES.get(name, "float")}" '
                         f'value="{_value(params[name])}" />')
    if tangent:
        lines.append(f'    <input name="geometry_tangent" type="vector3" '
                     f'nodename="{BITANGENT_NAME}" />')
    lines += [f"  </{shader}>", f'  <surfacematerial name="{MATERIAL_NAME}" type="material">',
              f'    <input name="surfaceshader" type="surfaceshader" nodename="{SHADER_NAME}" />',
              "  </surfacematerial>", "</materialx>", ""]
    fmt = "materialx" if shader == NODE else "materialx-standard-surface"
    return Export(fmt, "\n".join(lines), str(source), exact, tuple(notes), deviation, params,
                  error=error, closest=closest)


def _comment(text):
    return text.replace("--", "- -")  # the one sequence an XML comment cannot hold


# --- Standard Surface -----------------------------------------------------------------------------
# Autodesk Standard Surface (autodesk.github.io/standard-surface) leaves the anisotropy mapping,
# the Oren-Nayar roughness and the layering weights to the implementation; these follow
# MaterialX's graph of the node (libraries/bxdf/standard_surface.mtlx, MaterialX 1.39), which
# renderers reading a .mtlx use: roughness_anisotropy, artistic_ior + conductor_bsdf for metals,
# dielectric_bsdf (weight specular, tint specular_color) layered over oren_nayar_diffuse_bsdf.

#: The Standard Surface node (nodedef ``ND_standard_surface_surfaceshader``).
SS_NODE = "standard_surface"
#: Its inputs this module writes or reads, with the nodedef's defaults.
SS_DEFAULTS = {"base": 1.0, "base_color": (0.8, 0.8, 0.8), "diffuse_roughness": 0.0,
               "metalness": 0.0, "specular": 1.0, "specular_color": (1.0, 1.0, 1.0),
               "specular_roughness": 0.2, "specular_IOR": 1.5, "specular_anisotropy": 0.0,
               "specular_rotation": 0.0}
SS_OFF = ("transmission", "subsurface", "sheen", "coat", "thin_film_thickness", "emission")
#: MaterialX's roughness_anisotropy clamps the anisotropy here (an aspect ratio of 50).
SS_MAX_ANISOTROPY = 0.98
#: artistic_ior clamps the reflectivity here.
SS_MAX_REFLECTIVITY = 0.99


def standard_surface_eval(params, wi, wo, albedo_grid=None):
    """The BRDF (no cosine) a ``standard_surface`` with ``params`` describes, shaped (..., 3),
    as MaterialX's graph of the node evaluates it with transmission, subsurface, sheen, coat,
    thin film and emission off and single scattering: mix(specular layer, metal, metalness);
    the metal a GGX conductor with the exact Fresnel of the index artistic_ior gives for
    (base base_color, specular specular_color) (Gulbrandsen 2014); the specular layer
    specular specular_color F(mu, specular_IOR) D G2 / (4 cos cos) over base base_color
    times Oren-Nayar's eq. 30 with sigma = diffuse_roughness, the latter weighted by
    1 - specular E_spec(wo) (MaterialX's dielectric_bsdf throughput: the untinted albedo).
    Roughness: alpha_x = min(r^2 / sqrt(1 - a), 1), alpha_y = r^2 sqrt(1 - a) along the
    tangent turned by specular_rotation x 360 degrees (roughness_anisotropy, rotate3d)."""
    p = {**SS_DEFAULTS, **params}
    on = [name for name in SS_OFF if float(p.get(name, 0.0)) != 0.0]
    if on:
        raise InputError(f"standard_surface_eval evaluates the base, metal and specular layers "
                         f"only; {', '.join(on)} must be 0")
    wi, wo = np.broadcast_arrays(np.asarray(wi, float), np.asarray(wo, float))
    anisotropy = float(p["specular_anisotropy"])
    ax, ay = standard_surface_alphas(p["specular_roughness"], anisotropy)
    if anisotropy > 0.0 and float(p["specular_rotation"]) != 0.0:
        turn = 2.0 * math.pi * float(p["specular_rotation"])
        wi, wo = _rotated(wi, turn), _rotated(wo, turn)
    mu, above, dg = _ggx_terms(wi, wo, ax, ay)
    metalness = float(p["metalness"])
    out = 0.0
    if metalness > 0.0:
        n, k = artistic_ior(float(p["base"]) * _rgb(p["base_color"]),
                            float(p["specular"]) * _rgb(p["specular_color"]))
        out = out + metalness * conductor_fresnel(mu[..., None], n, k) * dg
    if metalness < 1.0:
        weight, eta = float(p["specular"]), float(p["specular_IOR"])
        spec = weight * _rgb(p["specular_color"]) * dielectric_fresnel(mu, eta)[..., None] * dg
        throughput = (1.0 - weight * specular_albedo(wo, ax, ay, eta, albedo_grid)[..., None]
                      if float(p["base"]) != 0.0 else 1.0)  # no base: nothing to weigh
        ci, co = wi[..., 2], wo[..., 2]
        s = np.sum(wi * wo, axis=-1) - ci * co
        sigma2 = float(p["diffuse_roughness"]) ** 2
        a = 1.0 - 0.5 * sigma2 / (sigma2 + 0.33)  # Oren & Nayar 1994, eq. 30
        b = 0.45 * sigma2 / (sigma2 + 0.09)
        shape = a + b * np.where(s > 0.0, s / np.maximum(np.maximum(ci, co), 1e-300), 0.0)
        diffuse = float(p["base"]) * _rgb(p["base_color"]) * shape[..., None] / math.pi
        out = out + (1.0 - metalness) * (spec + throughput * diffuse)
    return np.where(above[..., None], out, 0.0)


def _rotated(v, angle):
    """Coordinates in the frame whose tangent is turned by ``angle`` about the normal."""
    c, s = math.cos(angle), math.sin(angle)
    return np.stack([c * v[..., 0] + s * v[..., 1], -s * v[..., 0] + c * v[..., 1], v[..., 2]],
                    axis=-1)


def standard_surface_alphas(roughness, anisotropy):
    """(alpha_x, alpha_y) of MaterialX's roughness_anisotropy: r^2 (clamped to [1e-4, 1]),
    stretched by the aspect sqrt(1 - a) (a clamped to 0.98), alpha_x capped at 1."""
    r2 = min(max(float(roughness) ** 2, 1e-4), 1.0)
    a = float(anisotropy)
    if a <= 0.0:
        return r2, r2
    aspect = math.sqrt(1.0 - min(a, SS_MAX_ANISOTROPY))
    return min(r2 / aspect, 1.0), max(r2 * aspect, 1e-4)


def artistic_ior(reflectivity, edge):
    """(n, k) of Gulbrandsen 2014, "Artist Friendly Metallic Fresnel", JCGT 3(4), eqs. 4 and 5
    (n between the indices of k = 0 and of edge 0, k from the normal reflectance), with the
    reflectivity clamped to [0, 0.99] as MaterialX's artistic_ior does."""
    r = np.clip(np.asarray(reflectivity, float), 0.0, SS_MAX_REFLECTIVITY)
    sr = np.sqrt(r)
    n = edge * (1.0 - r) / (1.0 + r) + (1.0 - edge) * (1.0 + sr) / (1.0 - sr)
    k = np.sqrt(np.maximum((r * (n + 1.0) ** 2 - (n - 1.0) ** 2) / (1.0 - r), 0.0))
    return n, k


def artistic_ior_inverse(n, k):
    """(reflectivity, edge) with :func:`artistic_ior` = (n, k): the normal reflectance of the
    index and the position of n between Gulbrandsen's bounds (edge outside [0, 1] when n is
    outside them)."""
    n, k = np.asarray(n, float), np.asarray(k, float)
    r = ((n - 1.0) ** 2 + k * k) / ((n + 1.0) ** 2 + k * k)
    sr = np.sqrt(r)
    n_min, n_max = (1.0 - r) / (1.0 + r), (1.0 + sr) / (1.0 - sr)
    return r, (n_max - n) / (n_max - n_min)


def conductor_fresnel(cos, n, k):
    """Unpolarised Fresnel reflectance of a conductor of index n + i k (Born & Wolf 14.2, as in
    PBR 3rd ed. 8.2.1, FrConductor), broadcasting over channels."""
    c = np.clip(np.asarray(cos, float), 0.0, 1.0)
    c2, s2 = c * c, 1.0 - c * c
    t0 = n * n - k * k - s2
    a2b2 = np.sqrt(t0 * t0 + 4.0 * n * n * k * k)
    a = np.sqrt(np.maximum(0.5 * (a2b2 + t0), 0.0))
    t1, t2 = a2b2 + c2, 2.0 * c * a
    rs = (t1 - t2) / (t1 + t2)
    t3, t4 = c2 * a2b2 + s2 * s2, t2 * s2
    return 0.5 * (rs + rs * (t3 - t4) / (t3 + t4))


def _ss_roughness(lobe, name, params, notes):
    """specular_roughness, specular_anisotropy and specular_rotation inverting
    :func:`standard_surface_alphas`: r^2 = sqrt(alpha_x alpha_y), a = 1 - alpha_y / alpha_x."""
    ax = float(lobe["alpha"])
    ay = float(lobe.get("alpha_y")) if lobe.get("alpha_y") is not None else ax
    at, ab = max(ax, ay), min(ax, ay)
    r2, a = math.sqrt(at * ab), 1.0 - ab / at
    approximate = at > 1.0 or a > SS_MAX_ANISOTROPY
    params["specular_roughness"] = min(math.sqrt(r2), 1.0)
    if a > 0.0:
        params["specular_anisotropy"] = min(a, SS_MAX_ANISOTROPY)
    if ay > ax:
        params["specular_rotation"] = 0.25  # the tangent turned by 90 degrees: along our y
    notes.append(f"{name}: specular_roughness = (alpha_x alpha_y)^(1/4)"
                 + (", specular_anisotropy = 1 - alpha_min / alpha_max" if a > 0 else "")
                 + (", specular_rotation 0.25 (rougher along y)" if ay > ax else "")
                 + " (MaterialX's roughness_anisotropy), " + (
                     "approximate: alpha above 1 or anisotropy above 0.98 clamped"
                     if approximate else "exact"))
    _ggx_only_notes(lobe, name, "Standard Surface", "MaterialX", notes)


def _ss_metal(lobe, name, params, notes):
    """metalness 1: reflectivity and edge colour of the artistic_ior conductor. A conductor
    Fresnel with ks = 1 maps exactly (Gulbrandsen's map inverted); otherwise base_color = ks F(1)
    and the edge colour (of 101) closest to ks F over cos in [cos 85 deg, 1], relatively."""
    ks = _rgb(lobe["ks"])
    fresnel = lobe["fresnel"]
    params.update(metalness=1.0, base=1.0, specular=1.0)
    if fresnel.name == "conductor" and np.all(ks == 1.0):
        n, k = np.broadcast_arrays(_rgb(fresnel["eta"]), _rgb(fresnel["k"]))
        r, g = artistic_ior_inverse(n, k)
        if np.all(r <= SS_MAX_REFLECTIVITY) and np.all((g >= 0.0) & (g <= 1.0)):
            params.update(base_color=tuple(r), specular_color=tuple(g))
            notes.append(f"{name}: metalness 1, base_color and specular_color = Gulbrandsen's "
                         "reflectivity and edge tint of the conductor's index (artistic_ior "
                         "inverted), exact")
            return
    cos = np.linspace(math.cos(math.radians(85.0)), 1.0, 33)
    target = np.array([ks * _rgb(_fresnel_at(fresnel, c)) for c in cos])  # (33, 3)
    r = np.clip(target[-1], 0.0, SS_MAX_REFLECTIVITY)
    edges = np.linspace(0.0, 1.0, 101)
    best = []
    for ch in range(3):
        n, k = artistic_ior(np.full(edges.shape, r[ch]), edges)
        curves = conductor_fresnel(cos[:, None], n[None, :], k[None, :])  # (33, 101)
        err = np.abs(curves - target[:, ch:ch + 1]) / np.maximum(target[:, ch:ch + 1], 1e-300)
        best.append(edges[int(np.argmin(err.max(axis=0)))])
    params.update(base_color=tuple(r), specular_color=tuple(best))
    notes.append(f"{name}: metalness 1, base_color = ks F(1), specular_color = the edge tint "
                 "(of 101) whose artistic_ior conductor Fresnel is closest to ks F, "
                 "approximate")


def _ss_specular(lobe, ior, weight, color):
    """The Standard Surface specular inputs for one candidate."""
    return {"specular_IOR": float(ior), "specular": float(weight), "specular_color": tuple(
        float(c) for c in np.clip(color, 0.0, 1.0))}


def _ss_candidates(lobe):
    """(specular_IOR, specular, specular_color) candidates for a dielectric specular layer:
    first the one closest to the lobe alone (a grey dielectric's eta with specular = 1 and
    specular_color = ks; Fresnel none: F0 = 0.9999, specular = max ks; otherwise the same F0),
    then one per F0 on a geometric grid, specular x specular_color x F0 = ks F(1)."""
    ks = _rgb(lobe["ks"])
    fresnel = lobe["fresnel"]
    normal = ks * _rgb(_fresnel_at(fresnel, 1.0))
    if fresnel.name == "dielectric" and _grey(fresnel["eta"]):
        first = (float(np.atleast_1d(fresnel["eta"])[0]), 1.0, ks)
    elif fresnel.name == "none":
        top = float(ks.max())
        first = (ior_of_f0(F0_NONE), min(top, 1.0), ks / top if top > 0.0 else ks)
    else:
        f0 = _rgb(_fresnel_at(fresnel, 1.0))
        first = (ior_of_f0(float(f0.max())), 1.0, ks * f0 / max(float(f0.max()), 1e-300))
    out = [first]
    for f0 in np.geomspace(0.02, F0_NONE, 24):
        weight = min(float(normal.max()) / f0, 1.0)
        out.append((ior_of_f0(f0), weight, normal / max(weight * f0, 1e-300)))
    return out


def _ss_inputs(model):
    """The standard_surface inputs (numpy values) and notes."""
    from ..geometry import directions_from_degrees
    from .export import GRID_PHI_O, GRID_THETA
    check_materialx(model)
    (dn, diffuse), (sn, specular) = _lobes(model)
    params, notes = {}, []
    if diffuse is not None:
        params.update(base=1.0, base_color=tuple(_rgb(diffuse["albedo"])))
        if diffuse.name == "oren-nayar":
            sigma = float(diffuse["sigma"])
            params["diffuse_roughness"] = min(sigma, 1.0)
            notes.append(f"{dn}: base_color = albedo, diffuse_roughness = sigma (MaterialX's "
                         "oren_nayar_diffuse_bsdf is eq. 30 of Oren & Nayar), " + (
                             "approximate: sigma capped at 1" if sigma > 1.0 else "exact"))
        else:
            notes.append(f"{dn}: base_color = albedo, diffuse_roughness 0, exact")
    if specular is None:
        params.update(specular=0.0)
        notes.append(f"{dn}: specular 0 (no specular layer), exact")
        return params, notes
    _ss_roughness(specular, sn, params, notes)
    if diffuse is None and specular["fresnel"].name != "dielectric":
        _ss_metal(specular, sn, params, notes)
        return params, notes
    params.update(metalness=0.0)
    candidates = _ss_candidates(specular)
    if diffuse is None:
        ior, weight, color = candidates[0]
        params.update(base=0.0, **_ss_specular(specular, ior, weight, color))
        exact = _grey(specular["fresnel"]["eta"]) and np.all(np.asarray(color) <= 1.0)
        notes.append(f"{sn}: base 0, specular_IOR = eta, specular_color = ks (the dielectric "
                     "reflection alone), " + ("exact" if exact else "approximate"))
        return params, notes
    t, p = np.meshgrid(GRID_THETA, GRID_PHI_O, indexing="ij")
    wo = directions_from_degrees(t.ravel(), p.ravel())
    ax, ay = standard_surface_alphas(params["specular_roughness"],
                                     params.get("specular_anisotropy", 0.0))
    if params.get("specular_rotation"):
        wo = _rotated(wo, 2.0 * math.pi * params["specular_rotation"])
    rho = _rgb(diffuse["albedo"])
    best = None
    for ior, weight, color in candidates:
        throughput = 1.0 - weight * specular_albedo(wo, ax, ay, float(ior), 48)
        scale = 2.0 / max(throughput.min() + throughput.max(), 1e-300)
        trial = {**params, **_ss_specular(specular, ior, weight, color),
                 "base_color": tuple(np.clip(rho * scale, 0.0, 1.0))}
        dev = relative_deviation(model.eval,
                                 lambda wi, wo_: standard_surface_eval(trial, wi, wo_, 48))
        if best is None or dev < best[0]:
            best = (dev, trial, ior, rho * scale)
    _, trial, ior, base = best
    params.update(trial)
    notes.append(f"{sn}: dielectric specular layer, specular_IOR {ior:.6g}, specular and "
                 "specular_color = ks F(1) / F0: of the dielectric closest to the lobe and 24 "
                 "F0 on a grid, the one that gives the whole material the smallest deviation, "
                 "approximate")
    notes.append(f"{dn}: base_color divided by the mean of the extreme 1 - specular E_spec(wo) "
                 "weights of MaterialX's layer, approximate")
    if np.any(base > 1.0):
        notes.append(f"{dn}: base_color clamped to [0, 1], approximate")
    return params, notes


#: The shaders :func:`to_materialx` writes: (title, inputs in document order, evaluator).
SHADERS = {NODE: ("OpenPBR Surface 1.1", DEFAULTS, lambda p, wi, wo: openpbr_eval(p, wi, wo)),
           SS_NODE: ("Autodesk Standard Surface (as MaterialX's graph evaluates it)",
                     SS_DEFAULTS, lambda p, wi, wo: standard_surface_eval(p, wi, wo))}
