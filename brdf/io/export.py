"""Export of a model (a fit's result) to renderers: Mitsuba 3 BSDFs and glTF 2.0 materials.

``brdf.export(model_or_report, format, path=None, force=False) -> Export``. Each conversion
states what is exact and what is approximate, in the written file (an XML comment for Mitsuba,
the material's ``extras`` for glTF) and in the :class:`Export` it returns, with a measured
figure: ``deviation``, the largest relative difference between our BRDF and the one the target
evaluates (see :func:`relative_deviation`).

Mitsuba 3 (``format="mitsuba"``, a ``<scene>`` holding one ``<bsdf id="material">``)
    * ``lambert`` -> ``diffuse`` (exact).
    * ``ggx``/``beckmann`` -> ``roughconductor`` with ``distribution``, ``alpha`` or
      ``alpha_u``/``alpha_v`` (along our x and y; Mitsuba's u is the surface tangent),
      ``specular_reflectance`` = ks. Fresnel ``none`` -> ``material="none"`` (eta 0, k 1: F = 1),
      ``conductor`` -> its eta, k, ``dielectric`` -> eta and k = 0 (all exact: Mitsuba's
      conductor Fresnel is the exact complex-index one, which at k = 0 is the dielectric one; a
      ``roughdielectric`` would add transmission, which a BRDF does not describe).
      ``schlick`` -> the conductor index that Gulbrandsen's mapping gives for F0 with the edge
      tint fitted to Schlick's curve (approximate). Mitsuba's Smith masking is separable:
      ``masking=height-correlated`` is approximate; its Beckmann G1 is Walter et al.'s rational
      approximation (within 0.31 %), so Beckmann lobes are approximate too.
    * ``mirror`` -> ``conductor`` with ``specular_reflectance`` and the Fresnel as above.
    * Sums -> nested ``blendbsdf``. A blend is convex, (1 - w) f1 + w f2, so each lobe is written
      with its scale divided by its weight: exact, as long as the scales fit in Mitsuba's [0, 1]
      reflectances (weights proportional to each lobe's largest scale: possible when those add
      up to at most 1). ``roughplastic`` is never equivalent: its diffuse part carries Fresnel
      transmittance factors and an internal-reflection normalisation (Mitsuba 3 docs,
      roughplastic), so it is not used.

glTF 2.0 (``format="gltf"``, a minimal valid ``.gltf``: ``asset`` and one material; the BRDF
is the one of the glTF 2.0 specification's Appendix B with the Smith height-correlated
visibility of the Khronos glTF Sample Viewer)
    * roughness = sqrt(GGX alpha) (glTF's alpha = roughness^2); anisotropy through
      ``KHR_materials_anisotropy`` (alpha_t = mix(alpha, 1, strength^2), exact).
    * ``lambert`` -> metallic 0, baseColor = albedo, ``KHR_materials_specular`` specular 0
      (exact: no specular layer; without the extension a viewer adds glTF's 4 % layer).
    * ``ggx`` alone -> metallic 1, baseColor = ks F(normal incidence); glTF's metal Fresnel is
      Schlick's with F90 = 1, so this is exact for ``schlick`` with ks = 1 only.
    * ``lambert + ggx`` -> metallic 0, ``KHR_materials_specular`` with ``KHR_materials_ior``
      ior = 0 (F0 = specular x specularColor, F90 = specular), baseColor = albedo / (1 - F0):
      glTF's dielectric is (1 - F) diffuse + F specular, exact where F is constant (Fresnel
      ``none`` with a grey ks), otherwise the diffuse part is right at normal incidence only.
    * Beckmann lobes have no glTF equivalent (glTF is GGX only), nor have the other families.
"""

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import InputError

__all__ = ["export", "Export", "check_families", "FORMATS", "EXPORTABLE", "gltf_eval", "relative_deviation"]

#: Formats and the extension of the file each writes.
FORMATS = {"mitsuba": ".xml", "gltf": ".gltf", "materialx": ".mtlx",
           "materialx-standard-surface": ".mtlx"}
#: Model families each format takes (sums of them where the format says).
EXPORTABLE = {"mitsuba": ("lambert", "ggx", "beckmann", "mirror"),
              "gltf": ("lambert", "ggx", "lambert + ggx"),
              "materialx": ("lambert", "oren-nayar", "ggx", "beckmann", "lambert + ggx",
                            "lambert + beckmann", "oren-nayar + ggx", "oren-nayar + beckmann")}
EXPORTABLE["materialx-standard-surface"] = EXPORTABLE["materialx"]
#: Relative deviation below which a conversion is called exact (float32 renderers round at 1e-7).
EXACT = 1e-9
#: Direction grid of :func:`relative_deviation`, degrees: up to the fits' default cutoff.
GRID_THETA, GRID_PHI_I, GRID_PHI_O = np.arange(0.0, 81.0, 5.0), (0.0, 45.0), np.arange(0, 360, 15)
#: Pairs where f is below this fraction of its peak do not count in the relative deviation.
FLOOR = 1e-3
#: A Mitsuba ``<bsdf>`` in a ``<scene>`` so that ``<include filename="..."/>`` merges it.
MITSUBA_VERSION = "3.0.0"
MITSUBA_ID = "material"


@dataclass(frozen=True)
class Export:
    """What :func:`export` wrote (or would write).

    Attributes
    ----------
    format : str
        ``"mitsuba"`` or ``"gltf"``.
    text : str
        The file's content.
    spec : str
        The exported model.
    exact : bool
        Whether the target evaluates our BRDF exactly (up to its float precision).
    notes : tuple of str
        One statement per conversion: what maps to what, exact or approximate and why.
    deviation : float
        Largest relative difference between our BRDF and the target's (:func:`relative_deviation`).
    equivalent : object
        What the target evaluates: a model (Mitsuba) or the glTF material object.
    path : str or None
        Where the file was written.
    """

    format: str
    text: str
    spec: str
    exact: bool
    notes: tuple
    deviation: float
    equivalent: object = field(repr=False)
    path: str = None

    def to_dict(self):
        return {"format": self.format, "path": self.path, "spec": self.spec, "exact": self.exact,
                "deviation": self.deviation, "notes": list(self.notes)}

    def __str__(self):
        verdict = "exact" if self.exact else f"approximate (deviation {self.deviation:.3g})"
        head = f"{self.format} export of {self.spec}: {verdict}"
        if self.path:
            head += f"; wrote {self.path}"
        return "\n".join([head, *(f"  - {n}" for n in self.notes)])


def export(obj, format, path=None, force=False):
    """Convert a model to a Mitsuba 3 BSDF or a glTF 2.0 material, and write it.

    Parameters
    ----------
    obj : Model, FitResult, FitReport, str or path
        A model, anything with a ``.model`` (a fit's result or a loaded report), a spec, or the
        path of a JSON fit report.
    format : {"mitsuba", "gltf"}
    path : str or Path, optional
        Where to write (atomically; an existing file only with ``force``). Without it nothing is
        written and the text is in the result.
    force : bool

    Returns
    -------
    Export

    Raises
    ------
    InputError
        For an unknown format, or a model without an equivalent in it (the message says which
        models export).
    """
    from . import atomic_output
    model = _model_of(obj)
    if format not in FORMATS:
        raise InputError(f"unknown export format {format!r}; use one of {', '.join(FORMATS)}")
    _refuse_custom(model, format)
    if model.channels not in (1, 3):
        raise InputError(f"{model}: {model.channels} channels; {format} takes one channel or "
                         "RGB (spectral models have no wavelengths to convert)")
    result = {"mitsuba": _mitsuba, "gltf": _gltf, "materialx": _materialx,
              "materialx-standard-surface": _materialx_standard_surface}[format](model)
    if path is not None:
        with atomic_output(path, force) as tmp:
            tmp.write_text(result.text, encoding="utf-8")
        result = Export(**{**result.__dict__, "path": str(path)})
    return result


def _model_of(obj):
    from ..models.base import Model
    from ..spec import parse
    if isinstance(obj, Model):
        return obj
    if hasattr(obj, "model"):
        return obj.model
    if isinstance(obj, (str, Path)) and str(obj).lower().endswith(".json"):
        from ..fitting.report import load_report
        return load_report(obj).model
    if isinstance(obj, str):
        return parse(obj)
    raise InputError(f"export takes a model, a fit result or report, or a spec; got "
                     f"{type(obj).__name__}")


def check_families(model, format):
    """Raise the error :func:`export` would give for a model whose families ``format`` lacks,
    without converting anything (``brdf-fit fit --export`` asks before it fits)."""
    model = _model_of(model)
    _refuse_custom(model, format)
    if format.startswith("materialx"):
        from .materialx import check_materialx
        return check_materialx(model)
    shape = " + ".join(lobe.name for lobe in _gltf_lobes(model)[0])
    if format == "gltf" and shape not in EXPORTABLE["gltf"]:
        raise _unsupported(model, "gltf", ": glTF's microfacet lobe is GGX only"
                           if "beckmann" in shape else "")
    for lobe in model.lobes:
        if format == "mitsuba" and lobe.name not in EXPORTABLE["mitsuba"]:
            raise _unsupported(lobe, "mitsuba")


def _materialx(model):
    from .materialx import to_materialx  # brdf/io/materialx.py: OpenPBR Surface documents
    return to_materialx(model)


def _materialx_standard_surface(model):
    from .materialx import to_materialx
    return to_materialx(model, "standard_surface")


def _refuse_custom(model, format):
    """Custom (numpy-written) lobes have no counterpart in either format."""
    custom = sorted({lobe.name for lobe in model.lobes if lobe.kind < 0})
    if custom:
        raise InputError(f"{model}: the custom lobe(s) {', '.join(custom)} have no {format} "
                         "equivalent; tabulate the model with brdf.measure(model, 'merl') and "
                         "use the MERL table instead")


def _unsupported(model, format, why=""):
    names = ", ".join(EXPORTABLE[format])
    return InputError(f"{model}: no {format} equivalent{why}; {format} export takes {names}")


# --- the measured figure ------------------------------------------------------------------------

def relative_deviation(ours, theirs):
    """Largest |theirs - ours| / ours over direction pairs up to 80 degrees from the normal
    (incidence azimuths 0 and 45 degrees, outgoing every 15), counting pairs where ``ours`` is
    at least :data:`FLOOR` of its peak. ``ours`` and ``theirs`` are callables f(wi, wo)."""
    from ..geometry import directions_from_degrees
    ti, pi, to, po = np.meshgrid(GRID_THETA, GRID_PHI_I, GRID_THETA, GRID_PHI_O, indexing="ij")
    wi, wo = directions_from_degrees(ti.ravel(), pi.ravel()), directions_from_degrees(
        to.ravel(), po.ravel())
    f, g = np.broadcast_arrays(np.asarray(ours(wi, wo), float), np.asarray(theirs(wi, wo), float))
    peak = f.max() if f.size else 0.0
    if peak <= 0.0:
        return float(np.abs(g).max(initial=0.0))
    keep = f >= FLOOR * peak
    return float((np.abs(g - f)[keep] / f[keep]).max())


# --- Mitsuba 3 ----------------------------------------------------------------------------------

def _mi_value(name, value, kind=None):
    """A Mitsuba property element: ``<float>`` for one value, ``<rgb>`` for three."""
    arr = np.atleast_1d(np.asarray(value, float))
    if arr.size == 1:
        return f'<float name="{name}" value="{float(arr[0])!r}"/>'
    return f'<rgb name="{name}" value="{",".join(repr(float(v)) for v in arr)}"/>'


def _beckmann_g1_error():
    """Largest relative error of the rational Beckmann G1 (Walter et al. 2007, eq. 27, the form
    Mitsuba 3 evaluates for a < 1.6; exact 1 above) against 1 / (1 + Lambda) with the exact
    Lambda (Heitz 2014, eq. 83), on a grid of a = cot(theta) / alpha."""
    worst = 0.0
    for a in np.linspace(1e-3, 1.6, 1601):
        lam = 0.5 * (math.erf(a) - 1.0) + math.exp(-a * a) / (2.0 * a * math.sqrt(math.pi))
        rational = (3.535 * a + 2.181 * a * a) / (1.0 + 2.276 * a + 2.577 * a * a)
        worst = max(worst, abs(rational * (1.0 + lam) - 1.0))
    return worst


#: Measured: 0.31 % (at a = 1.34); a separable G2 of two such terms is within (1 + e)^2 - 1.
BECKMANN_G1_ERROR = _beckmann_g1_error()


def _gulbrandsen(f0, tint):
    """Conductor index (n, k) with normal reflectance ``f0`` and edge tint ``tint``: Gulbrandsen
    2014, "Artist Friendly Metallic Fresnel", JCGT 3(4), eqs. 4 and 5 (inverted)."""
    r = np.clip(f0, 0.0, 0.9999)
    sr = np.sqrt(r)
    n = tint * (1.0 - r) / (1.0 + r) + (1.0 - tint) * (1.0 + sr) / (1.0 - sr)
    k = np.sqrt(np.maximum(0.0, (r * (n + 1.0) ** 2 - (n - 1.0) ** 2) / (1.0 - r)))
    return n, k


def _conductor_curve(cos, n, k):
    from ..models.fresnel import conductor_reflectance
    return np.array([conductor_reflectance(c, n, k) for c in cos])


def schlick_as_conductor(f0):
    """(eta, k) per channel whose exact conductor Fresnel best follows Schlick's curve for
    ``f0``: same reflectance at normal incidence (Gulbrandsen's mapping), the edge tint chosen
    on a grid of 51 to minimise the largest difference over cos in [0, 1]."""
    from ..models.fresnel import schlick
    cos = np.linspace(0.0, 1.0, 33)
    etas, ks = [], []
    for r in np.atleast_1d(np.asarray(f0, float)):
        target = np.array([schlick(r, c) for c in cos])
        best = min(np.linspace(0.0, 1.0, 51), key=lambda g: np.abs(
            _conductor_curve(cos, *_gulbrandsen(r, g)) - target).max())
        n, k = _gulbrandsen(r, best)
        etas.append(float(n))
        ks.append(float(k))
    return np.array(etas), np.array(ks)


def _mi_fresnel(fresnel, notes, where):
    """Mitsuba conductor properties for one of our Fresnel terms, and the term Mitsuba evaluates."""
    from ..models.fresnel import Conductor
    if fresnel.name == "none":
        notes.append(f"{where}: fresnel none -> material \"none\" (eta 0, k 1: F = 1), exact")
        return ['<string name="material" value="none"/>'], fresnel
    if fresnel.name == "conductor":
        notes.append(f"{where}: conductor Fresnel -> eta, k (Mitsuba's exact conductor Fresnel), "
                     "exact")
        return [_mi_value("eta", fresnel["eta"]), _mi_value("k", fresnel["k"])], fresnel
    if fresnel.name == "dielectric":
        notes.append(f"{where}: dielectric Fresnel -> conductor eta with k = 0 (the exact "
                     "dielectric reflectance, without roughdielectric's transmission), exact")
        eta = fresnel["eta"]
        return [_mi_value("eta", eta), _mi_value("k", np.zeros_like(eta))], Conductor(
            eta=eta, k=np.zeros_like(eta))
    eta, k = schlick_as_conductor(fresnel["f0"])
    size = np.asarray(fresnel["f0"]).size
    eta, k = (eta, k) if size > 1 else (eta[0], k[0])
    notes.append(f"{where}: Schlick Fresnel (not in Mitsuba's conductors) -> conductor eta, k "
                 "with the same F0 and Gulbrandsen 2014's edge tint fitted to Schlick's curve, "
                 "approximate")
    return [_mi_value("eta", eta), _mi_value("k", k)], Conductor(eta=eta, k=k)


def _mi_lobe(lobe, where, notes):
    """(scale, function of the scale divisor -> XML, the lobe as Mitsuba evaluates it)."""
    if lobe.name == "lambert":
        albedo = lobe["albedo"]
        notes.append(f"{where}: lambert -> diffuse, reflectance = albedo, exact")
        return albedo, lambda w: (f'<bsdf type="diffuse">{_mi_value("reflectance", albedo / w)}'
                                  '</bsdf>'), lobe
    if lobe.name in ("ggx", "beckmann"):
        ks = lobe["ks"]
        fresnel_xml, fresnel = _mi_fresnel(lobe["fresnel"], notes, where)
        ax, ay = lobe["alpha"], lobe.get("alpha_y")
        if ay is None or float(ay) == float(ax):
            rough = [_mi_value("alpha", ax)]
        else:
            rough = [_mi_value("alpha_u", ax), _mi_value("alpha_v", ay)]
        notes.append(f"{where}: {lobe.name} -> roughconductor, distribution {lobe.name}, "
                     + ("alpha_u/alpha_v = alpha/alpha_y (u: the surface tangent)"
                        if len(rough) == 2 else "alpha = alpha") + ", specular_reflectance = ks, "
                     "exact")
        if lobe.name == "beckmann":
            notes.append(f"{where}: Mitsuba's Beckmann G1 is Walter et al. 2007's rational "
                         f"approximation (eq. 27), within {BECKMANN_G1_ERROR:.2%} of the exact "
                         "erf form, approximate")
        if lobe["masking"] == "height-correlated":
            notes.append(f"{where}: height-correlated Smith masking -> Mitsuba's separable "
                         "G1(wi) G1(wo), approximate")
        seen = lobe.replace(masking="separable", fresnel=fresnel)
        body = [f'<string name="distribution" value="{lobe.name}"/>', *rough, *fresnel_xml]
        return ks, lambda w: ('<bsdf type="roughconductor">' + "".join(body)
                              + _mi_value("specular_reflectance", ks / w) + "</bsdf>"), seen
    if lobe.name == "mirror":
        r = lobe["reflectance"]
        fresnel_xml, fresnel = _mi_fresnel(lobe["fresnel"], notes, where)
        notes.append(f"{where}: mirror -> conductor, specular_reflectance = reflectance, exact")
        return r, lambda w: ('<bsdf type="conductor">' + "".join(fresnel_xml)
                             + _mi_value("specular_reflectance", r / w) + "</bsdf>"), \
            lobe.replace(fresnel=fresnel)
    raise _unsupported(lobe, "mitsuba")


def _mitsuba(model):
    from ..models.base import Sum
    check_families(model, "mitsuba")
    lobes = list(model.lobes)
    names = model.lobe_names() if isinstance(model, Sum) else [model.name]
    notes, parts = [], []
    for name, lobe in zip(names, lobes):
        scale, xml, seen = _mi_lobe(lobe, name, notes)
        top = float(np.max(scale))
        if top <= 0.0:
            notes.append(f"{name}: zero scale, reflects nothing: left out, exact")
            continue
        parts.append((name, top, xml, seen))
    total = sum(p[1] for p in parts)
    if total > 1.0 + 1e-12:
        raise InputError(f"{model}: no mitsuba equivalent: the lobes' largest scales add up to "
                         f"{total:.6g} > 1, and Mitsuba's reflectances must lie in [0, 1]")
    if not parts:
        body, seen = f'<bsdf type="diffuse">{_mi_value("reflectance", 0.0)}</bsdf>', None
    else:
        weights = [p[1] / total for p in parts]  # each lobe's scale / weight stays <= total <= 1
        body = _mi_blend([(xml, w) for (_, _, xml, _), w in zip(parts, weights)])
        if len(parts) > 1:
            notes.append("sum -> nested blendbsdf (convex blends) with each lobe's scale divided "
                         "by its weight (" + ", ".join(f"{p[0]} {w:.6g}" for p, w in
                                                       zip(parts, weights)) + "), exact")
        seen = _sum([p[3] for p in parts])
    body = body.replace("<bsdf ", f'<bsdf id="{MITSUBA_ID}" ', 1)
    equivalent = seen if seen is not None else model
    deviation = _model_deviation(model, equivalent) if seen is not None else 0.0
    if any(lobe.name == "beckmann" for lobe in lobes):  # not in the equivalent: bound G1 G1
        deviation = max(deviation, (1.0 + BECKMANN_G1_ERROR) ** 2 - 1.0)
    exact = deviation <= EXACT and not any("approximate" in n for n in notes)
    comment = [f"brdf {_version()} export of {model}",
               f"{'exact' if exact else 'APPROXIMATE'}: largest relative difference of f over "
               f"directions up to 80 degrees {deviation:.3g}", *notes]
    text = ('<?xml version="1.0" encoding="utf-8"?>\n<!--\n'
            + "".join(f"  {_xml_comment(line)}\n" for line in comment)
            + f'-->\n<scene version="{MITSUBA_VERSION}">\n    {body}\n</scene>\n')
    return Export("mitsuba", text, str(model), exact, tuple(notes), deviation, equivalent)


def _mi_blend(items):
    """Nested blendbsdf of ``(xml(w), w)`` with weights summing to 1: lobe k is written with
    its scale over w_k, and the blend of lobe k with the rest weighs the rest by their share."""
    (xml, w), rest = items[0], items[1:]
    if not rest:
        return xml(w)
    share = sum(r[1] for r in rest)
    return (f'<bsdf type="blendbsdf"><float name="weight" value="{share / (w + share)!r}"/>'
            f"{xml(w)}{_mi_blend(rest)}</bsdf>")


def _sum(lobes):
    from ..models.base import Sum
    return lobes[0] if len(lobes) == 1 else Sum(lobes)


def _model_deviation(model, seen):
    """Relative deviation of eval, and of the directional albedo at a few incidence angles (the
    only measure of delta lobes, whose eval is 0)."""
    from ..geometry import directions_from_degrees
    dev = relative_deviation(model.eval, seen.eval)
    if any(lobe.delta for lobe in model.lobes):
        wi = directions_from_degrees(np.arange(0.0, 81.0, 10.0), np.zeros(9))
        a, b = model.albedo(wi), seen.albedo(wi)
        dev = max(dev, float((np.abs(b - a) / np.maximum(a, 1e-300)).max()))
    return dev


def _xml_comment(text):
    return text.replace("--", "- -")  # the one sequence an XML comment cannot hold


def _version():
    from .. import __version__
    return __version__


# --- glTF 2.0 -----------------------------------------------------------------------------------

def _rgb(value):
    arr = np.broadcast_to(np.asarray(value, float), (3,))
    return [float(v) for v in arr]


def _fresnel_f0(fresnel):
    """Our Fresnel term at normal incidence (F0), per channel."""
    from ..models.fresnel import conductor_reflectance, dielectric_reflectance
    if fresnel.name == "none":
        return np.ones(1)
    if fresnel.name == "schlick":
        return np.atleast_1d(np.asarray(fresnel["f0"], float))
    if fresnel.name == "dielectric":
        return np.array([dielectric_reflectance(1.0, e) for e in np.atleast_1d(fresnel["eta"])])
    eta, k = np.broadcast_arrays(np.atleast_1d(fresnel["eta"]), np.atleast_1d(fresnel["k"]))
    return np.array([conductor_reflectance(1.0, e, kk) for e, kk in zip(eta, k)])


def _gltf_roughness(lobe, material, notes, where):
    """roughnessFactor (and KHR_materials_anisotropy) from a GGX lobe's alpha and alpha_y."""
    ax = float(lobe["alpha"])
    ay = float(lobe.get("alpha_y")) if lobe.get("alpha_y") is not None else ax
    low, high = min(ax, ay), max(ax, ay)
    if high > 1.0:
        raise InputError(f"{lobe}: no gltf equivalent: alpha {high:g} > 1, and glTF's "
                         "roughness = sqrt(alpha) lies in [0, 1]")
    material["pbrMetallicRoughness"]["roughnessFactor"] = math.sqrt(low)
    notes.append(f"{where}: roughnessFactor = sqrt(alpha) (glTF: alpha = roughness^2), exact")
    if high > low:
        # alpha_t = mix(alpha, 1, strength^2) (KHR_materials_anisotropy, "Implementation")
        strength = math.sqrt((high - low) / (1.0 - low))
        material.setdefault("extensions", {})["KHR_materials_anisotropy"] = {
            "anisotropyStrength": strength, "anisotropyRotation": 0.0 if ax > ay else math.pi / 2}
        notes.append(f"{where}: anisotropy -> KHR_materials_anisotropy (strength from "
                     "alpha_t = mix(alpha_b, 1, strength^2), rotation from the tangent), exact")
    if lobe["masking"] == "separable":
        notes.append(f"{where}: separable Smith masking -> glTF's height-correlated visibility "
                     "(Khronos Sample Viewer), approximate")


def _gltf_lobes(model):
    """The lobes with the diffuse one first (``ggx + lambert`` exports like ``lambert + ggx``),
    and their flat-name prefixes."""
    from ..models.base import Sum
    names = model.lobe_names() if isinstance(model, Sum) else [model.name]
    pairs = sorted(zip(names, model.lobes), key=lambda p: p[1].name != "lambert")
    return [p[1] for p in pairs], [p[0] for p in pairs]


def _gltf_diffuse(model, lobes, names, material, notes):
    material["pbrMetallicRoughness"].update(baseColorFactor=_rgb(lobes[0]["albedo"]) + [1.0],
                                            metallicFactor=0.0, roughnessFactor=1.0)
    material["extensions"]["KHR_materials_specular"] = {"specularFactor": 0.0}
    notes.append(f"{names[0]}: metallic 0, baseColor = albedo, KHR_materials_specular "
                 "specularFactor 0 (no specular layer), exact")


def _gltf_metal(model, lobes, names, material, notes):
    lobe = lobes[0]
    f0 = np.asarray(lobe["ks"], float) * _fresnel_f0(lobe["fresnel"])
    if np.any(f0 > 1.0):
        raise InputError(f"{model}: no gltf equivalent: ks F0 = {np.max(f0):.6g} > 1, and "
                         "glTF's baseColor lies in [0, 1]")
    material["pbrMetallicRoughness"].update(baseColorFactor=_rgb(f0) + [1.0], metallicFactor=1.0)
    exact = lobe["fresnel"].name == "schlick" and np.all(np.asarray(lobe["ks"]) == 1.0)
    notes.append(f"{names[0]}: metallic 1, baseColor = ks F0 with glTF's Schlick Fresnel "
                 "(F90 = 1), " + ("exact" if exact else "approximate (exact for schlick with "
                                                        "ks = 1)"))
    _gltf_roughness(lobe, material, notes, names[0])


def _gltf_plastic(model, lobes, names, material, notes):
    """``lambert + ggx``: glTF's dielectric (1 - F) diffuse + F specular with F0 and F90 set
    through KHR_materials_specular and KHR_materials_ior (ior 0 makes F0 = specular x
    specularColor, as in the extension's specular-glossiness conversion)."""
    diffuse, lobe = lobes
    ks = np.asarray(lobe["ks"], float)
    f0 = np.broadcast_to(ks * _fresnel_f0(lobe["fresnel"]), (3,))
    specular = float(ks.max())
    if specular > 1.0:
        raise InputError(f"{model}: no gltf equivalent: ks {specular:g} > 1, and "
                         "KHR_materials_specular's specularFactor lies in [0, 1]")
    base = np.broadcast_to(diffuse["albedo"], (3,)) / np.maximum(1.0 - np.minimum(f0, 1.0),
                                                                 1e-12)
    if np.any(base > 1.0):
        raise InputError(f"{model}: no gltf equivalent: albedo / (1 - ks F0) = "
                         f"{base.max():.6g} > 1, and glTF's baseColor lies in [0, 1]")
    material["pbrMetallicRoughness"].update(baseColorFactor=_rgb(base) + [1.0],
                                            metallicFactor=0.0)
    material["extensions"].update(
        KHR_materials_specular={"specularFactor": specular, "specularColorFactor": _rgb(
            np.zeros(3) if specular == 0.0 else f0 / specular)},
        KHR_materials_ior={"ior": 0.0})
    grey = bool(np.all(ks == specular))
    schlick_like = lobe["fresnel"].name in ("none", "schlick")
    notes.append(f"{names[1]}: KHR_materials_ior ior 0 and KHR_materials_specular: F0 = "
                 "specular x specularColor = ks F0, F90 = specular = max ks, "
                 + ("exact" if schlick_like and grey else
                    "approximate (glTF's Fresnel is Schlick's with F90 = specular)"))
    constant = lobe["fresnel"].name == "none" and grey
    notes.append(f"{names[0]}: metallic 0, baseColor = albedo / (1 - ks F0) against glTF's "
                 "(1 - F) diffuse weight, " + ("exact (F is constant)" if constant else
                                               "approximate (exact at normal incidence)"))
    _gltf_roughness(lobe, material, notes, names[1])


_GLTF_SHAPES = {"lambert": _gltf_diffuse, "ggx": _gltf_metal, "lambert + ggx": _gltf_plastic}


def _gltf(model):
    check_families(model, "gltf")
    lobes, names = _gltf_lobes(model)
    notes = []
    material = {"name": "brdf", "pbrMetallicRoughness": {}, "extensions": {}}
    _GLTF_SHAPES[" + ".join(lobe.name for lobe in lobes)](model, lobes, names, material, notes)
    if not material["extensions"]:
        del material["extensions"]
    used = sorted(material.get("extensions", {}))
    deviation = relative_deviation(model.eval, lambda wi, wo: gltf_eval(material, wi, wo))
    exact = deviation <= EXACT and not any("approximate" in n for n in notes)
    material["extras"] = {"brdf": {"version": _version(), "spec": str(model), "exact": exact,
                                   "deviation": deviation, "notes": notes}}
    document = {"asset": {"version": "2.0", "generator": f"brdf {_version()}"},
                **({"extensionsUsed": used} if used else {}), "materials": [material]}
    text = json.dumps(document, indent=2, allow_nan=False) + "\n"
    return Export("gltf", text, str(model), exact, tuple(notes), deviation, material)


def gltf_eval(material, wi, wo):
    """The BRDF (no cosine) a glTF 2.0 metallic-roughness material describes, shaped (..., 3).

    glTF 2.0 specification, Appendix B (material = mix(dielectric, metal, metallic); Schlick
    Fresnel; GGX D) with the height-correlated Smith visibility of the Khronos glTF Sample
    Viewer (Heitz 2014, eq. 99), KHR_materials_specular and KHR_materials_ior (F0 and F90 of
    the dielectric, "Implementation" sections) and KHR_materials_anisotropy (alpha_t =
    mix(alpha, 1, strength^2) along the rotated tangent). Textures are not read.
    """
    pbr = material.get("pbrMetallicRoughness", {})
    ext = material.get("extensions", {})
    base = np.asarray(pbr.get("baseColorFactor", [1.0, 1.0, 1.0, 1.0])[:3], float)
    metallic = float(pbr.get("metallicFactor", 1.0))
    alpha = float(pbr.get("roughnessFactor", 1.0)) ** 2
    wi, wo = np.asarray(wi, float), np.asarray(wo, float)
    h = wi + wo
    h /= np.linalg.norm(h, axis=-1, keepdims=True)
    aniso = ext.get("KHR_materials_anisotropy", {})
    strength = float(aniso.get("anisotropyStrength", 0.0))
    rot = float(aniso.get("anisotropyRotation", 0.0))
    at, ab = alpha + strength ** 2 * (1.0 - alpha), alpha  # mix(alpha, 1, strength^2)
    t = np.array([math.cos(rot), math.sin(rot), 0.0])
    b = np.array([-math.sin(rot), math.cos(rot), 0.0])

    def stretched(v):  # sqrt(at^2 (t.v)^2 + ab^2 (b.v)^2 + (n.v)^2) of Heitz 2014, eq. 86
        return np.sqrt((at * (v @ t)) ** 2 + (ab * (v @ b)) ** 2 + v[..., 2] ** 2)

    # D_GGX anisotropic (Heitz 2014, eq. 85) and V = G2 / (4 cos_i cos_o), height-correlated
    d = 1.0 / (math.pi * at * ab * ((h @ t) ** 2 / at ** 2 + (h @ b) ** 2 / ab ** 2
                                    + h[..., 2] ** 2) ** 2)
    v = 0.5 / (wi[..., 2] * stretched(wo) + wo[..., 2] * stretched(wi))
    vh = np.abs(np.sum(wo * h, axis=-1))[..., None]
    spec = (d * v)[..., None]
    s = ext.get("KHR_materials_specular", {})
    weight = float(s.get("specularFactor", 1.0))
    ior = float(ext.get("KHR_materials_ior", {}).get("ior", 1.5))
    ior_f0 = 1.0 if ior == 0.0 or math.isinf(ior) else ((ior - 1.0) / (ior + 1.0)) ** 2
    f0_d = np.minimum(ior_f0 * np.asarray(s.get("specularColorFactor", [1.0] * 3)), 1.0) * weight
    fd = f0_d + (weight - f0_d) * (1.0 - vh) ** 5  # KHR_materials_specular: F0, F90 = specular
    dielectric = (1.0 - fd) * base / math.pi + fd * spec  # fresnel_mix (Appendix B)
    metal = spec * (base + (1.0 - base) * (1.0 - vh) ** 5)  # conductor_fresnel (Appendix B)
    out = (1.0 - metallic) * dielectric + metallic * metal
    above = (wi[..., 2] > 0.0) & (wo[..., 2] > 0.0)
    return np.where(above[..., None], out, 0.0)
