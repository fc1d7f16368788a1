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
      with its scale divided by its weight (weights proportional to each lobe's largest scale):
      exact. Reflectances above 1 (scales adding up to more than 1) are ``srgb`` textures with
      ``unbounded``, since Mitsuba refuses an ``<rgb>`` reflectance outside [0, 1]. ``roughplastic`` is never equivalent: its diffuse part carries Fresnel
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

Models a format has no counterpart for (other families, parameters beyond its ranges) are
written as the closest material of its family (:mod:`brdf.io.closest_material`: Mitsuba's
diffuse + roughconductor, glTF's parameters), with ``error``, the relative RMS difference, in
the file and the result; only custom lobes, spectral models, delta lobes in glTF and models
farther than ``max_error`` from anything the format holds are refused.
"""

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import InputError

__all__ = ["export", "measured_mitsuba", "Export", "NoCounterpart", "check_families", "FORMATS",
           "EXPORTABLE", "gltf_eval", "relative_deviation"]

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
    error : float
        Relative RMS difference weighted by projected solid angle
        (:func:`brdf.io.closest_material.relative_rms`); 0 for an exact export.
    closest : str or None
        For a model without a counterpart in the format: what the closest material is (the
        fitted family), None otherwise.
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
    error: float = 0.0
    closest: str = None

    def to_dict(self):
        return {"format": self.format, "path": self.path, "spec": self.spec, "exact": self.exact,
                "deviation": self.deviation, "error": self.error, "closest": self.closest,
                "notes": list(self.notes)}

    def __str__(self):
        verdict = "exact" if self.exact else (f"approximate (relative RMS difference "
                                              f"{self.error:.3g}, largest {self.deviation:.3g})")
        head = f"{self.format} export of {self.spec}: {verdict}"
        if self.path:
            head += f"; wrote {self.path}"
        return "\n".join([head, *(f"  - {n}" for n in self.notes)])


def export(obj, format, path=None, force=False, max_error=None, measured=False):
    """Convert a model to a Mitsuba 3 BSDF or a glTF 2.0 material, and write it.

    A model the format has no counterpart for (a family it lacks, or parameters beyond its
    ranges) is written as the closest material of the format's family, fitted to the model
    (:mod:`brdf.io.closest_material`), with how far it is stated in ``notes``, ``error`` and
    ``deviation``.

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
    max_error : float, optional
        Largest relative RMS difference of a closest material that is written (default
        :data:`brdf.io.closest_material.MAX_ERROR`); beyond it the model is refused.
    measured : bool
        Mitsuba only: write the model as an RGL tensor beside ``path`` (same name, ``.bsdf``)
        and a ``<bsdf type="measured">`` that reads it, for any isotropic model, whatever its
        families (:func:`measured_mitsuba`).

    Returns
    -------
    Export

    Raises
    ------
    InputError
        For an unknown format, custom lobes, spectral models, delta lobes in glTF, and models
        whose closest material in the format differs by more than ``max_error`` (the message
        says which format holds them).
    """
    from . import atomic_output
    model = _model_of(obj)
    if format not in FORMATS:
        raise InputError(f"unknown export format {format!r}; use one of {', '.join(FORMATS)}")
    check_families(model, format)
    if model.channels not in (1, 3):
        raise InputError(f"{model}: {model.channels} channels; {format} takes one channel or "
                         "RGB (spectral models have no wavelengths to convert)")
    from .closest_material import MAX_ERROR
    limit = MAX_ERROR if max_error is None else _positive(max_error, "max_error")
    if measured:
        if format != "mitsuba":
            raise InputError(f"measured=True writes Mitsuba's measured plugin; {format} has "
                             "no tabulated material")
        return measured_mitsuba(model, path, force)
    try:
        result = _EXACT[format](model)
    except NoCounterpart as reason:
        from ..progress import stage
        with stage(f"export: closest {format} material"):
            result = _CLOSEST[format](model, str(reason))
        if result.error > limit:
            raise _unreasonable(model, format, result, limit) from None
    if path is not None:
        with atomic_output(path, force) as tmp:
            tmp.write_text(result.text, encoding="utf-8")
        result = Export(**{**result.__dict__, "path": str(path)})
    return result


class NoCounterpart(InputError):
    """The format has no exact counterpart for a model (a family it lacks, or parameters
    beyond its ranges); :func:`export` then writes the closest material."""


def _positive(value, name):
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not value > 0.0:
        raise InputError(f"export: {name} must be a positive number, got {value!r}")
    return float(value)


def _unreasonable(model, format, result, limit):
    from .closest_material import smooth_part
    smooth, _ = smooth_part(model)
    holds = ("; Mitsuba 3's measured plugin reads any isotropic model as an RGL tensor "
             "(export measured=True, brdf-fit export --measured)" if smooth is not None
             and not model.is_anisotropic and not any(lobe.delta for lobe in model.lobes)
             else "")
    return InputError(f"{model}: no reasonable {format} counterpart: the closest {result.closest} "
                      f"differs by {result.error:.3g} relative RMS (more than max_error "
                      f"{limit:.3g}){holds}")


def measured_mitsuba(model, path, force=False):
    """A Mitsuba file whose ``<bsdf id="material" type="measured">`` reads ``model`` tabulated
    as an RGL tensor (Dupuy & Jakob 2018), written beside ``path`` with the suffix ``.bsdf``
    (:func:`brdf.io.rgl_bsdf.write`). Any isotropic model without delta lobes has one; the
    figures compare our reader of the tensor, which evaluates like Mitsuba's plugin, with the
    model."""
    from . import atomic_output, read, write
    model = _model_of(model)
    if path is None:
        raise InputError("measured=True writes a tensor file beside the Mitsuba file: give "
                         "the path")
    xml_path = Path(path)
    tensor = xml_path.with_suffix(".bsdf")
    if xml_path.suffix.lower() == ".bsdf":
        raise InputError(f"{path}: the Mitsuba file needs another extension (.xml); the "
                         "tensor goes beside it as .bsdf")
    for target in (xml_path, tensor):
        if target.exists() and not force:
            from ..errors import OutputError
            raise OutputError(f"{target}: exists; pass --force (force=True) to replace it")
    write(model, tensor, force=force)
    table = read(tensor)
    deviation = relative_deviation(model.eval, table.eval)
    error = _rms(model, table.eval)
    notes = (f"{model} -> an RGL tensor ({tensor.name}, Dupuy & Jakob 2018) read by Mitsuba's "
             "measured plugin: tabulated, approximate",)
    comment = [f"brdf {_version()} export of {model}",
               f"APPROXIMATE: {_figures(deviation, error)}", *notes]
    text = ('<?xml version="1.0" encoding="utf-8"?>\n<!--\n'
            + "".join(f"  {_xml_comment(line)}\n" for line in comment)
            + f'-->\n<scene version="{MITSUBA_VERSION}">\n    <bsdf id="{MITSUBA_ID}" '
            f'type="measured"><string name="filename" value="{tensor.name}"/></bsdf>\n'
            "</scene>\n")
    with atomic_output(xml_path, force) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return Export("mitsuba", text, str(model), False, notes, deviation, table, path=str(path),
                  error=error, closest="RGL tensor")


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
    """Raise the error :func:`export` would give for a model whose lobes ``format`` cannot
    hold even approximately (custom lobes; delta lobes in glTF), without converting anything
    (``brdf-fit fit --export`` asks before it fits)."""
    model = _model_of(model)
    _refuse_custom(model, format)
    if format != "mitsuba":
        _refuse_deltas(model, format)


def _refuse_deltas(model, format):
    deltas = sorted({lobe.name for lobe in model.lobes if lobe.delta})
    if deltas:
        raise InputError(f"{model}: no {format} equivalent for the delta lobe(s) "
                         f"{', '.join(deltas)} ({format}'s materials are GGX-rough); export to "
                         "mitsuba, whose conductor holds them")


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
    return NoCounterpart(f"{model}: no {format} equivalent{why}; {format} maps {names} exactly")


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

def _mi_value(name, value):
    """A Mitsuba property element: ``<float>`` for one value, ``<rgb>`` for three. Mitsuba
    refuses an ``<rgb>`` reflectance beyond [0, 1] (SRGBReflectanceSpectrum); an ``srgb``
    texture with ``unbounded`` holds it (exact in RGB variants; spectral variants upsample it
    as an emitter's colour)."""
    arr = np.atleast_1d(np.asarray(value, float))
    if arr.size == 1:
        return f'<float name="{name}" value="{float(arr[0])!r}"/>'
    rgb = ",".join(repr(float(v)) for v in arr)
    if arr.max() <= 1.0:
        return f'<rgb name="{name}" value="{rgb}"/>'
    return (f'<texture type="srgb" name="{name}"><rgb name="color" value="{rgb}"/>'
            '<boolean name="unbounded" value="true"/></texture>')


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


def _mitsuba(model, source=None, lead=(), closest=None):
    """The Mitsuba file of ``model``, whose families Mitsuba holds; ``source`` (default
    ``model``) is what the deviation is measured against and the comment names, ``lead`` the
    notes that come first, ``closest`` the fitted family when ``model`` stands for it."""
    from ..models.base import Sum
    unmapped = [lobe for lobe in model.lobes if lobe.name not in EXPORTABLE["mitsuba"]]
    if unmapped:
        raise _unsupported(unmapped[0], "mitsuba")
    source = model if source is None else source
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
    if total > 1.0:
        notes.append(f"the lobes' largest scales add up to {total:.6g} > 1: reflectances "
                     "above 1 are written as unbounded srgb textures (an <rgb> reflectance "
                     "must lie in [0, 1]), exact in Mitsuba's RGB variants")
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
    notes = [*lead, *notes]
    equivalent = seen if seen is not None else model
    deviation = _model_deviation(source, equivalent) if seen is not None else 0.0
    exact = deviation <= EXACT and not any("approximate" in n for n in notes)
    error = 0.0 if exact else _rms(source, equivalent.eval)
    if any(lobe.name == "beckmann" for lobe in lobes):  # not in the equivalent: bound G1 G1
        bound = (1.0 + BECKMANN_G1_ERROR) ** 2 - 1.0  # pointwise, so of the RMS too
        deviation, error = max(deviation, bound), max(error, bound)
    comment = [f"brdf {_version()} export of {source}",
               f"{'exact' if exact else 'APPROXIMATE'}: {_figures(deviation, error)}", *notes]
    text = ('<?xml version="1.0" encoding="utf-8"?>\n<!--\n'
            + "".join(f"  {_xml_comment(line)}\n" for line in comment)
            + f'-->\n<scene version="{MITSUBA_VERSION}">\n    {body}\n</scene>\n')
    return Export("mitsuba", text, str(source), exact, tuple(notes), deviation, equivalent,
                  error=error, closest=closest)


def _figures(deviation, error):
    return (f"largest relative difference of f over directions up to 80 degrees "
            f"{deviation:.3g}; relative RMS difference (projected solid angle) {error:.3g}")


def _rms(model, other):
    from .closest_material import relative_rms
    return relative_rms(model, other)


def _closest_note(model, format, family, reason):
    lacking = sorted({lobe.name for lobe in model.lobes
                      if lobe.name not in EXPORTABLE[format] and not lobe.delta})
    why = (f"{', '.join(lacking)}: no {format} counterpart" if lacking else
           reason.split(": ", 1)[-1])
    return (f"{why} -> the closest {family} (least squares over direction pairs up to 80 "
            "degrees weighted by projected solid angle), approximate")


def _closest_mitsuba(model, reason):
    """``lambert + ggx`` (separable masking, Fresnel none: Mitsuba's diffuse and
    roughconductor) fitted to the smooth lobes; delta lobes map as they are."""
    from .closest_material import fit_lambert_ggx, smooth_part
    _, deltas = smooth_part(model)
    fitted = fit_lambert_ggx(model, masking="separable")
    family = "lambert + ggx (separable masking)"
    written = _sum([lobe for lobe in fitted.lobes if np.max(_scale_of(lobe)) > 0.0] + deltas
                   or list(fitted.lobes))
    lead = [_closest_note(model, "mitsuba", family, reason),
            f"closest: {written}"]
    return _mitsuba(written, source=model, lead=lead, closest=family)


def _scale_of(lobe):
    return lobe["albedo"] if lobe.name == "lambert" else lobe["ks"]


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
        raise NoCounterpart(f"{lobe}: no gltf equivalent: alpha {high:g} > 1, and glTF's "
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
        raise NoCounterpart(f"{model}: no gltf equivalent: ks F0 = {np.max(f0):.6g} > 1, and "
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
        raise NoCounterpart(f"{model}: no gltf equivalent: ks {specular:g} > 1, and "
                         "KHR_materials_specular's specularFactor lies in [0, 1]")
    base = np.broadcast_to(diffuse["albedo"], (3,)) / np.maximum(1.0 - np.minimum(f0, 1.0),
                                                                 1e-12)
    if np.any(base > 1.0):
        raise NoCounterpart(f"{model}: no gltf equivalent: albedo / (1 - ks F0) = "
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
    shape = " + ".join(lobe.name for lobe in lobes)
    if shape not in _GLTF_SHAPES:
        raise _unsupported(model, "gltf", ": glTF's microfacet lobe is GGX only"
                           if "beckmann" in shape else "")
    notes = []
    material = {"name": "brdf", "pbrMetallicRoughness": {}, "extensions": {}}
    _GLTF_SHAPES[shape](model, lobes, names, material, notes)
    return _gltf_document(model, material, notes)


def _gltf_document(model, material, notes, closest=None):
    """The glTF file of ``material`` standing for ``model``, with the measured figures."""
    if not material["extensions"]:
        del material["extensions"]
    used = sorted(material.get("extensions", {}))

    def theirs(wi, wo):
        return gltf_eval(material, wi, wo)
    deviation = relative_deviation(model.eval, theirs)
    exact = deviation <= EXACT and not any("approximate" in n for n in notes)
    error = 0.0 if exact else _rms(model, theirs)
    material["extras"] = {"brdf": {"version": _version(), "spec": str(model), "exact": exact,
                                   "deviation": deviation, "error": error, "notes": notes}}
    document = {"asset": {"version": "2.0", "generator": f"brdf {_version()}"},
                **({"extensionsUsed": used} if used else {}), "materials": [material]}
    text = json.dumps(document, indent=2, allow_nan=False) + "\n"
    return Export("gltf", text, str(model), exact, tuple(notes), deviation, material,
                  error=error, closest=closest)


#: Direction pairs of the closest glTF material's least squares (gltf_eval is numpy).
GLTF_CLOSEST_PAIRS = 8_000


def _closest_gltf(model, reason):
    """glTF's metallic-roughness parameters (with KHR_materials_specular, _ior 0 and
    _anisotropy) fitted by bounded least squares (scipy's trust-region reflective) to the
    model on the pairs of :func:`~brdf.io.closest_material.weighted_pairs`, from the closest
    ``lambert + ggx`` mapped as a dielectric and as a metal; the better of the two."""
    from scipy.optimize import least_squares
    from .closest_material import fit_lambert_ggx, weighted_pairs
    start = fit_lambert_ggx(model, masking="height-correlated")
    wi, wo, weight = weighted_pairs(model, GLTF_CLOSEST_PAIRS)
    y = np.broadcast_to(np.asarray(model.eval(wi, wo), float), (len(wi), 3))
    root = np.sqrt(weight)[:, None]
    diffuse, lobe = start.lobes
    ax = float(lobe["alpha"])
    ay = float(lobe.get("alpha_y")) if lobe.get("alpha_y") is not None else ax
    anisotropic = ax != ay
    rotation = 0.0 if ax >= ay else math.pi / 2

    def material(x):
        m = {"name": "brdf", "pbrMetallicRoughness": {
            "baseColorFactor": [float(v) for v in x[0:3]] + [1.0], "metallicFactor": float(x[3]),
            "roughnessFactor": float(x[4])}, "extensions": {
            "KHR_materials_specular": {"specularFactor": float(x[5]),
                                       "specularColorFactor": [float(v) for v in x[6:9]]},
            "KHR_materials_ior": {"ior": 0.0}}}
        if anisotropic:
            m["extensions"]["KHR_materials_anisotropy"] = {
                "anisotropyStrength": float(x[9]), "anisotropyRotation": rotation}
        return m

    def residuals(x):
        return (root * (gltf_eval(material(x), wi, wo) - y)).ravel()

    ks = np.broadcast_to(np.asarray(lobe["ks"], float), (3,))
    top = max(float(ks.max()), 1e-6)
    base = np.broadcast_to(np.asarray(diffuse["albedo"], float), (3,)) / max(1.0 - top, 1e-3)
    rough = math.sqrt(min(ax, ay, 1.0))
    strength = math.sqrt(max(max(ax, ay) - min(ax, ay), 0.0) / max(1.0 - min(ax, ay), 1e-6))
    tail = [min(strength, 1.0)] if anisotropic else []
    starts = [[*np.clip(base, 0, 1), 0.0, rough, min(top, 1.0), *(ks / top), *tail],
              [*np.clip(ks, 0, 1), 1.0, rough, 1.0, 1.0, 1.0, 1.0, *tail]]
    low = [0.0] * 4 + [0.01] + [0.0] * (len(starts[0]) - 5)  # roughness 0.01: alpha 1e-4
    fits = [least_squares(residuals, np.clip(x0, low, 1.0), bounds=(low, 1.0), x_scale="jac",
                          tr_solver="lsmr", ftol=1e-6, xtol=1e-6)
            for x0 in starts]
    best = min(fits, key=lambda r: r.cost)
    family = "glTF metallic-roughness material (KHR_materials_specular, KHR_materials_ior)"
    notes = [_closest_note(model, "gltf", family, reason),
             "closest: " + ", ".join(f"{k} {v:.4g}" for k, v in zip(
                 ("base r", "base g", "base b", "metallic", "roughness", "specular",
                  "specularColor r", "specularColor g", "specularColor b",
                  "anisotropyStrength"), best.x))]
    return _gltf_document(model, material(best.x), notes, closest="glTF metallic-roughness")


def _closest_materialx(model, reason, shader="open_pbr_surface"):
    """The closest ``lambert + ggx`` (height-correlated masking, as OpenPBR's and Standard
    Surface's specular lobes) mapped to the shader like any such sum."""
    from .closest_material import fit_lambert_ggx
    from .materialx import to_materialx
    fitted = fit_lambert_ggx(model, masking="height-correlated")
    family = f"lambert + ggx (height-correlated masking) as {shader}"
    fmt = "materialx" if shader == "open_pbr_surface" else "materialx-standard-surface"
    lead = [_closest_note(model, fmt, family, reason), f"closest: {fitted}"]
    return to_materialx(fitted, shader, source=model, lead=lead, closest=family)


def _closest_standard_surface(model, reason):
    return _closest_materialx(model, reason, "standard_surface")


#: Converters of the models each format holds, and of the closest material for the rest.
_EXACT = {"mitsuba": _mitsuba, "gltf": _gltf, "materialx": _materialx,
          "materialx-standard-surface": _materialx_standard_surface}
_CLOSEST = {"mitsuba": _closest_mitsuba, "gltf": _closest_gltf, "materialx": _closest_materialx,
            "materialx-standard-surface": _closest_standard_surface}


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
