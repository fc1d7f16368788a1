"""``brdf.fit_images``: a BRDF from photographs of known scenes, through the existing fitter.

The ``direct`` method (:mod:`brdf.capture.direct`) turns the pixels into measured samples
(wi, wo, f, sigma), a :class:`brdf.Table`, and :func:`brdf.fit` fits them unchanged (energy
constraint, multi-start, and :func:`brdf.mcmc` for the posterior). Its correction of each
pixel's residual onto its dominant source is a fixed-point iteration: the samples are rebuilt
with the latest fit and fitted again until the parameters move by less than
:data:`ITERATION_TOL` (relative), at most ``iterations`` times.

Noise: each pixel's standard deviation combines, in quadrature, photon (Poisson) noise
value / gain with ``gain`` the photons per unit of the image's linear value, the quantisation
of an 8-bit file (one code's linear width / sqrt(12), the variance of a uniform rounding error)
and a stated absolute ``sigma``; samples get sigma / E*. With any of these the fit's loss is
chi-square (the likelihood of the stated noise); without, it is the fitter's default
(cosine-l2).

Free scale (uncalibrated exposure or light power): the photograph is k times the calibrated
image. k is degenerate with the BRDF's amplitudes (albedo, ks) unless something of known
reflectance is in view, as the white reference target of a lab capture is: the pixels of
every shape with a known, untextured material (not ``@material``, not emitting) inside the
mask estimate k
by weighted linear least squares against their direct-light prediction, k = sum(w y P) /
sum(w P^2), var(k) = 1 / sum(w P^2) with w = 1 / sigma^2 (the Gauss-Markov estimate; from the
residual scatter when no sigma is stated). The material's pixels are divided by k before the
fit. Since f is linear in each lobe's amplitudes, the amplitudes a = u / k with u what the
divided data determine, so the posterior draws of the amplitudes are multiplied by k / k' with
k' drawn from N(k, var(k)) independently (the reference and the material pixels are disjoint
data): the report's 95 % intervals carry the exposure's uncertainty.

The ``path`` method (:mod:`brdf.capture.path`) starts from the direct fit and fits the
image itself through the path tracer: interreflection included, the free scale fitted jointly
on the rendered reference pixels, and Laplace (Gauss-Newton) intervals instead of a posterior.
"""

import math
import os
import time
from dataclasses import dataclass

import numpy as np

from ..arguments import integer, real
from ..errors import InputError
from ..fitting.nlopt_fit import FitResult
from ..io.files import file_sha256

__all__ = ["fit_images", "ImageFitResult", "METHODS", "ITERATION_TOL", "DEFAULT_ITERATIONS"]

METHODS = ("direct", "path")
#: Largest relative change of any parameter between two passes that ends the iteration: a
#: tenth of a per cent, well below what pixel noise leaves (with a sky a third of the light, the
#: passes close in by a factor of about -0.4 each, so 1e-4 took three passes more).
ITERATION_TOL = 1e-3
#: Passes of the direct method's fixed-point iteration at most.
DEFAULT_ITERATIONS = 8


@dataclass(frozen=True)
class ImageFitResult(FitResult):
    """A :class:`~brdf.fitting.FitResult` from photographs: its report (:meth:`to_dict`, schema
    ``brdf.fit/1``) has a ``capture`` section (views, pixels used, method, scale, image-space
    loss) and, when the posterior was sampled, ``posterior``.

    Attributes
    ----------
    capture : dict
    posterior : Posterior or None
        With ``mcmc=True``: :func:`brdf.mcmc` of the last pass's samples, amplitudes widened
        by the free scale's uncertainty (see the module docstring).
    table : Table
        The samples of the last pass.
    """

    capture: dict = None
    posterior: object = None
    table: object = None

    def to_dict(self):
        d = super().to_dict()
        timing = d.pop("timing")
        d["capture"] = self.capture
        if self.posterior is not None:
            d["posterior"] = self._posterior_dict()
            timing = {**timing, "mcmc_s": self.posterior.seconds}
        d["timing"] = timing
        from ..formatting import json_ready
        return json_ready(d)

    def _posterior_dict(self):
        post = self.posterior.to_dict()
        widened = (self.capture.get("scale") or {}).get("posterior_percentiles")
        if widened:
            post["percentiles"] = {**post["percentiles"], **widened}
        return post

    def interval(self, name, level=95):
        """Central credible interval of parameter ``name``, the free scale's uncertainty
        included: of the posterior (``mcmc=True``), or of the path method's Laplace
        approximation."""
        laplace = (self.capture or {}).get("laplace")
        if self.posterior is None and laplace is None:
            raise InputError("interval: fit_images(..., mcmc=True) samples the posterior")
        pct = (self._posterior_dict()["percentiles"] if self.posterior is not None
               else laplace["percentiles"])[name]
        lo, hi = {68: ("16", "84"), 95: ("2.5", "97.5")}[level]
        return pct[lo], pct[hi]

    def __str__(self):
        c = self.capture
        lines = [super().__str__(),
                 f"capture: {c['method']}, {len(c['views'])} view(s), {c['pixels_used']:,} "
                 f"pixels, {c['iterations']} pass(es); image-space relative RMSE "
                 f"{c['image_loss']['relative_rmse']:.4g}"]
        if c["scale"]["free"]:
            s = c["scale"]
            lines.append(f"scale (exposure): {s['value']:.6g} +- {s['sigma']:.2g} from "
                         f"{s['reference_pixels']:,} reference pixels")
        laplace = c.get("laplace")
        if laplace is not None:
            lines.append("95 % intervals (Laplace): " + ", ".join(
                f"{n} [{p['2.5']:.6g}, {p['97.5']:.6g}]"
                for n, p in laplace["percentiles"].items()))
        if self.posterior is not None:
            lines.append(str(self.posterior))
            widened = c["scale"].get("posterior_percentiles") or {}
            if widened:
                lines.append("95 % intervals with the scale's uncertainty (the report's): " +
                             ", ".join(f"{n} [{p['2.5']:.6g}, {p['97.5']:.6g}]"
                                       for n, p in widened.items()))
        return "\n".join(lines)


def _as_views(views, response, mask):
    from .views import View, read_view
    if isinstance(views, (View, tuple)) or (isinstance(views, list) and views and
                                            isinstance(views[0], (str, os.PathLike))):
        views = [views]
    if not isinstance(views, (list, tuple)) or not views:
        raise InputError("fit_images: views must be a list of (scene, image) or (scene, image, "
                         "mask) pairs")
    masks = mask if isinstance(mask, (list, tuple)) else [mask] * len(views)
    if len(masks) != len(views):
        raise InputError(f"fit_images: {len(masks)} masks for {len(views)} views; give one per "
                         "view or one for all")
    out = []
    for k, v in enumerate(views):
        if isinstance(v, View):
            out.append(v)
            continue
        if not isinstance(v, (list, tuple)) or len(v) not in (2, 3):
            raise InputError(f"fit_images: view {k}: expected (scene, image) or (scene, image, "
                             f"mask), got {v!r}")
        m = v[2] if len(v) == 3 else masks[k]
        out.append(read_view(v[0], v[1], m, response))
    return out


def _refuse_existing_residuals(folder, n, force):
    """OutputError when a residual image of ``n`` views would replace a file without
    ``force``."""
    if folder is None or force:
        return
    from pathlib import Path
    from ..errors import OutputError
    for k in range(n):
        if (Path(folder) / f"view{k}.exr").exists():
            raise OutputError(f"{Path(folder) / f'view{k}.exr'}: exists; pass force=True "
                              "(--force) to replace it")


def _describe(v):
    """The report's entry of view ``v``: its files (with their SHA-256), size, response and
    mask counts."""
    return {"scene": str(v.scene_path), "image": v.photo.path, "mask": v.mask_path,
            "sha256": {k: file_sha256(p) for k, p in (("scene", v.scene_path),
                                                  ("image", v.photo.path),
                                                  ("mask", v.mask_path))
                       if p is not None and os.path.isfile(p)},
            "size": list(v.size), "response": str(v.photo.response), "bits": v.photo.bits,
            "pixels_masked": int(v.mask.sum()),
            "pixels_saturated": int((v.mask & v.photo.saturated).sum())}


def _write_residuals(folder, views, per_view, preds, force):
    """Write each view's residual image (see :func:`fit_images`); their paths."""
    from pathlib import Path
    from ..render.image import write_exr
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    out = []
    for k, (v, px, p) in enumerate(zip(views, per_view, preds)):
        w, h = v.size
        pred = np.zeros((h, w, 3))
        used = np.zeros((h, w, 3))
        pred[px.yx[:, 0], px.yx[:, 1]] = p
        used[px.yx[:, 0], px.yx[:, 1]] = 1.0
        resid = np.where(used > 0.0, v.photo.linear - pred, 0.0)
        path = folder / f"view{k}.exr"
        write_exr(path, resid, {"prediction": pred, "used": used}, force)
        out.append(str(path))
    return out


def _noise(gain, sigma):
    """sigma(value, step) of a pixel (module docstring), or a function returning None."""
    if gain is None and sigma is None:
        return lambda value, step: None if step is None else step / math.sqrt(12.0)

    def noise(value, step):
        var = np.zeros_like(value)
        if gain is not None:
            var += np.maximum(value, 0.0) / gain          # Poisson: var(N / g) = (v g) / g^2
        if step is not None:
            var += step * step / 12.0                     # uniform rounding over one code
        if sigma is not None:
            var += sigma * sigma
        return np.sqrt(var)
    return noise


def _fixed_noise(noise, views):
    """The noise function, or None when some view has no stated noise (neither gain nor
    sigma, and a float image without quantisation): then no sample has sigma."""
    if noise(np.ones(3), None) is None and any(v.photo.step is None for v in views):
        return None
    return noise


def _scale_of(refs, noise):
    """``(k, sigma_k, n)`` from reference pixels ``[(values, step, predicted)]``: weighted
    least squares, the weights from the noise at k P (refined three times from k = the
    unweighted estimate; at the observed values they would bias k low, see
    :func:`brdf.capture.direct.samples`)."""
    y = np.concatenate([r[0] for r in refs])
    P = np.concatenate([r[2] for r in refs])
    steps = [r[1] for r in refs]
    step = None if any(s is None for s in steps) else np.concatenate(steps)
    ok = np.isfinite(y) & (P > 0.0)
    if ok.sum() < 2:
        raise InputError("free scale: the reference pixels receive no direct light")
    k = float(np.sum(y[ok] * P[ok]) / np.sum(P[ok] ** 2))
    w = np.ones_like(y)
    for _ in range(3 if noise is not None else 0):
        sig = noise(np.maximum(k * P, 0.0), step)
        w = 1.0 / np.maximum(sig, 1e-12 * max(k * float(P.max()), 1e-300)) ** 2
        k = float(np.sum((w * y * P)[ok]) / np.sum((w * P * P)[ok]))
    info = float(np.sum((w * P * P)[ok]))
    if noise is None:
        var = float(np.sum(((y - k * P) ** 2)[ok])) / max(int(ok.sum()) - 1, 1) / info
    else:
        var = 1.0 / info
    return k, math.sqrt(var), int(ok.sum())


def _amplitude_names(model):
    """Flat names of the parameters f is linear in (each lobe's declared scale parameters,
    power-law lobes left out): the exposure's uncertainty goes onto these."""
    names = model.lobe_names() if len(model.lobes) > 1 else [model.name]
    out = []
    for prefix, lobe in zip(names, model.lobes):
        start = getattr(type(lobe), "START", None)
        if start is None or start.power is not None:
            continue
        for p in start.scale:
            base = f"{prefix}.{p}"
            out += [n for n in model.params if n == base or n.startswith(base + "[")]
    return out


def _widened(post, k, sigma_k, names, seed):
    """Percentiles of the amplitude ``names`` with the scale's uncertainty (module docstring)."""
    from ..fitting.mcmc import PERCENTILES
    rng = np.random.default_rng(seed)
    draws = k + sigma_k * rng.standard_normal(len(post.samples))
    factor = k / np.maximum(draws, 1e-300)
    out = {}
    for name in names:
        if name in post.names:
            col = post.samples[:, post.names.index(name)] * factor
            out[name] = {f"{q:g}": float(v) for q, v in zip(PERCENTILES,
                                                           np.percentile(col, PERCENTILES))}
    return out


def _change(a, b):
    return max(abs(a[n] - b[n]) / max(abs(b[n]), 1e-12) for n in b)


def fit_images(spec, views, *, method="direct", free_scale=False, mcmc=False, seed=0,
               response="linear", mask=None, gain=None, sigma=None,
               iterations=DEFAULT_ITERATIONS, spp=None, max_depth=None, walkers=None,
               max_steps=None, residuals=None, force=False, progress=None, **fit_options):
    """Fit ``spec`` to photographs of known scenes (see the module docstring).

    Parameters
    ----------
    spec : str or Model
        The model to fit; its values start the fit.
    views : list
        ``(scene, image)`` or ``(scene, image, mask)`` per view (paths; a scene may also be a
        :class:`brdf.render.Scene` whose unknown shapes have the material ``"@material"``), or
        :class:`brdf.capture.View` objects (:func:`brdf.capture.read_view`).
    method : {"direct", "path"}
        ``direct`` (Marschner et al. 1999: pixels to samples under the direct light); ``path``
        (image-space least squares through the path tracer, :mod:`brdf.capture.path`).
    free_scale : bool
        Fit one overall scale (exposure or light power) from pixels of known materials in view.
    mcmc : bool
        Sample the posterior with :func:`brdf.mcmc` (its 95 % intervals in the report).
    seed : int
        Seeds the fit, the posterior and the light quadrature.
    response : str
        Inverse camera response of PNG/TIFF photographs: ``linear``, ``srgb`` or ``gamma:G``.
    mask : path or list of paths, optional
        A mask for every view (or one per view), where views do not give their own.
    gain : float, optional
        Photons per unit of linear pixel value (Poisson noise); sigma : float, optional,
        absolute noise per pixel value.
    iterations : int
        Passes of the fixed-point iteration at most.
    spp, max_depth : int, optional
        Samples per pixel and longest path of the ``path`` method's renders (default: about
        two million paths per view, :func:`brdf.capture.path.default_spp`; 8).
    walkers, max_steps : int, optional
        Passed to :func:`brdf.mcmc`.
    residuals : path, optional
        A folder (created if missing) for one OpenEXR file per view, ``view<k>.exr``: the
        photograph minus the fitted model's prediction on the pixels used (0 elsewhere), with
        layers ``prediction`` and ``used`` (1 on the pixels used); existing files are replaced
        only with ``force``.
    force : bool
    progress : bool, optional
    **fit_options
        Passed to :func:`brdf.fit` (loss, optimizer, starts, energy_constraint, cutoff,
        shared, fix, bounds, max_evals, tol).

    Returns
    -------
    ImageFitResult
    """
    from ..fitting import fit as _fit, mcmc as _mcmc
    from ..render.scene import Material
    from ..spec import parse
    from ..table import Table
    from . import direct
    began = time.perf_counter()
    if not isinstance(method, str) or method not in METHODS:
        raise InputError(f"fit_images: method must be one of {', '.join(METHODS)}, got "
                         f"{method!r}")
    if method == "path":
        return _fit_path(spec, views, free_scale=free_scale, mcmc=mcmc, seed=seed,
                         response=response, mask=mask, gain=gain, sigma=sigma,
                         iterations=iterations, spp=spp, max_depth=max_depth,
                         residuals=residuals, force=force, progress=progress,
                         began=began, **fit_options)
    seed = integer(seed, "fit_images: seed", 0)
    iterations = integer(iterations, "fit_images: iterations", 1, 100)
    if gain is not None:
        gain = real(gain, "fit_images: gain (photons per unit value)", 0.0, low_open=True)
    if sigma is not None:
        sigma = real(sigma, "fit_images: sigma", 0.0, low_open=True)
    base = parse(spec) if isinstance(spec, str) else spec
    views = _as_views(views, response, mask)
    _refuse_existing_residuals(residuals, len(views), force)
    noise = _fixed_noise(_noise(gain, sigma), views)
    per_view, refs, described = [], [], []
    for v in views:
        compiled = v.scene.compile()
        sources = direct.sources_of(v.scene, seed)
        shapes = set(v.material_shapes)
        px = direct.pixels_of(v, compiled, shapes, sources)
        if px is None:
            raise InputError(f"{v.photo.path}: no pixel of the mask sees only "
                             f'"@material" shapes (check the scene file {v.scene_path}, the '
                             "camera and the mask)")
        n_ref = 0
        if free_scale:
            for k, s in enumerate(v.scene.shapes):
                if k in shapes or s.material is None or getattr(s, "emission", None) is not None:
                    continue
                known = s.material if isinstance(s.material, Material) else Material(s.material)
                if known.textures:
                    continue  # its prediction would need the texture lookups of the renderer
                rp = direct.pixels_of(v, compiled, {k}, sources)
                if rp is None:
                    continue
                refs.append((rp.value, rp.step, direct.predict(rp, known.resolve())))
                n_ref += len(rp)
        per_view.append(px)
        described.append({**_describe(v), "pixels_on_material": len(px),
                          "reference_pixels": n_ref, "sources": [s[2] for s in sources]})
    scale = {"free": bool(free_scale), "value": 1.0, "sigma": 0.0, "reference_pixels": 0}
    k = 1.0
    if free_scale:
        if not refs:
            raise InputError("free scale: no pixel of a known material (a reference target, "
                             "e.g. a diffuse floor or a white standard) in view; without one "
                             "the exposure cannot be told from the BRDF's albedo and ks")
        k, sk, nref = _scale_of(refs, noise)
        scale.update(value=k, sigma=sk, reference_pixels=nref,
                     method="weighted least squares on the direct light of known materials")
    loss_given = "loss" in fit_options
    if noise is not None and not loss_given:
        fit_options["loss"] = "chi-square"
    model, result, history, table = None, None, [], None
    current = base
    for it in range(iterations):
        parts = [direct.samples(px, model, k, noise) for px in per_view]
        keep = [p[4] & np.all(np.isfinite(p[2]), axis=1) for p in parts]
        wi = np.concatenate([p[0][m] for p, m in zip(parts, keep)])
        wo = np.concatenate([p[1][m] for p, m in zip(parts, keep)])
        f = np.concatenate([p[2][m] for p, m in zip(parts, keep)])
        sig = None if noise is None else np.concatenate([p[3][m] for p, m in zip(parts, keep)])
        if not len(wi):
            raise InputError("fit_images: no pixel gives a sample (no direct light reaches the "
                             "material's pixels)")
        wi /= np.linalg.norm(wi, axis=1, keepdims=True)
        wo /= np.linalg.norm(wo, axis=1, keepdims=True)
        table = Table(wi, wo, f, sigma=sig, name="capture", metadata={"method": method})
        opts = dict(fit_options)
        if it > 0:
            opts["starts"] = 1
        result = _fit(table, current, seed=seed, progress=progress, **opts)
        history.append({"pass": it + 1, "samples": len(wi), "loss": result.loss,
                        "params": dict(result.params)})
        done = model is not None and _change(result.params, model.params) < ITERATION_TOL
        model = result.model
        current = result.model
        if done:
            break
    preds = [direct.predict(px, model) * k for px in per_view]
    for d, px, p in zip(described, per_view, preds):
        r = px.value - p
        d["image_loss"] = {"rmse": float(np.sqrt(np.mean(r ** 2))),
                           "relative_rmse": float(np.sqrt(np.mean(r ** 2)) / max(
                               float(np.sqrt(np.mean(px.value ** 2))), 1e-300))}
    if residuals is not None:
        written = _write_residuals(residuals, views, per_view, preds, force)
    value = np.concatenate([px.value for px in per_view])
    pred = np.concatenate(preds)
    resid = value - pred
    image_loss = {"rmse": float(np.sqrt(np.mean(resid ** 2))),
                  "relative_rmse": float(np.sqrt(np.mean(resid ** 2)) /
                                         max(float(np.sqrt(np.mean(value ** 2))), 1e-300)),
                  "mean_relative_bias": float(np.sum(resid) / max(float(np.sum(pred)), 1e-300)),
                  "what": "photograph minus the fitted model's direct-light prediction, over "
                          "every pixel on the material (linear values)"}
    if noise is not None:
        s = np.concatenate([noise(np.maximum(p, 0.0), px.step) for p, px in zip(preds, per_view)])
        image_loss["chi2_per_value"] = float(np.mean((resid / np.maximum(s, 1e-300)) ** 2))
    post = None
    if mcmc:
        mopts = {k_: v_ for k_, v_ in (("walkers", walkers), ("max_steps", max_steps))
                 if v_ is not None}
        post = _mcmc(table, result, seed=seed, progress=progress, **mopts)
        if free_scale:
            scale["posterior_percentiles"] = _widened(post, k, scale["sigma"],
                                                      _amplitude_names(model), seed)
    capture = {
        "method": method,
        "method_reference": "Marschner et al. 1999, Image-based BRDF measurement including "
                            "human skin (direct light only: interreflection is not modelled)",
        "views": described, "pixels_used": int(len(table.values)),
        "iterations": len(history), "passes": history,
        "footprint_points": direct.SUBPIXELS ** 2, "area_points": direct.AREA_POINTS,
        "environment_directions": direct.ENV_DIRECTIONS,
        "dominant_share": direct.DOMINANT_SHARE,
        "noise": {"gain": gain, "sigma": sigma,
                  "quantisation": any(v.photo.step is not None for v in views),
                  "model": "none stated" if noise is None else
                  "sqrt(value / gain + step^2 / 12 + sigma^2) per pixel value"},
        "scale": scale, "image_loss": image_loss,
        "options": {"spp": spp, "max_depth": max_depth, "seed": seed},
    }
    if residuals is not None:
        capture["residual_images"] = written
    timing = {**result.timing, "total_s": time.perf_counter() - began}
    provenance = {**result.provenance, "spec": str(base),
                  "input": {"name": "capture", "views": [d["image"] for d in described],
                            "sha256": None}}
    fields = {f: getattr(result, f) for f in FitResult.__dataclass_fields__}
    fields.update(timing=timing, provenance=provenance)
    return ImageFitResult(**fields, capture=capture, posterior=post, table=table)


def _model_table(model, seed):
    """A small table of ``model``'s own values (RGB): it only gives :class:`~brdf.fitting.
    problem.Problem` its channels when the direct method gives no samples to start from."""
    from ..table import Table
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(2, 256, 3))
    d[..., 2] = np.abs(d[..., 2]) + 0.1
    wi, wo = d / np.linalg.norm(d, axis=-1, keepdims=True)
    f = np.broadcast_to(np.asarray(model.eval(wi, wo), float).reshape(256, -1), (256, 3))
    return Table(wi, wo, np.ascontiguousarray(f), name="start")


def _fit_path(spec, views, *, free_scale, mcmc, seed, response, mask, gain, sigma, iterations,
              spp, max_depth, residuals, force, progress, began, **fit_options):
    """``fit_images(method="path")``: the direct fit (where it applies) refined through the
    path tracer (:mod:`brdf.capture.path`)."""
    from ..fitting.mixed_problem import problem_for
    from ..progress import stage
    from ..properties import check
    from ..render.scene import Material
    from ..spec import parse
    from . import path
    if mcmc:
        raise InputError("fit_images: method 'path' gives Gauss-Newton intervals widened by "
                         "its renders' noise; sampling its posterior would take tens of "
                         "thousands of renders (mcmc is for method 'direct')")
    if spp is not None:
        spp = integer(spp, "fit_images: spp", 1)
    max_depth = integer(max_depth if max_depth is not None else path.DEFAULT_MAX_DEPTH,
                        "fit_images: max_depth", -1)
    base = parse(spec) if isinstance(spec, str) else spec
    if not base.uses_kernels or any(lobe.delta for lobe in base.lobes):
        raise InputError(f"fit_images: method 'path' differentiates renders through the "
                         f"families' kernels; {base} has a custom (numpy) or delta lobe: use "
                         "method 'direct'")
    views = _as_views(views, response, mask)
    _refuse_existing_residuals(residuals, len(views), force)
    noise = _fixed_noise(_noise(gain, sigma), views)
    problem_options = {k: fit_options[k] for k in ("shared", "fix", "bounds") if k in fit_options}
    try:
        with stage("fit-images: direct start", progress):
            start = fit_images(base, views, method="direct", free_scale=free_scale, seed=seed,
                               gain=gain, sigma=sigma, iterations=iterations, spp=spp,
                               max_depth=max_depth, progress=progress, **fit_options)
        model0, k0, table = start.model, start.capture["scale"]["value"], start.table
        start_note = "the direct method's fit"
    except InputError as e:
        start, model0, k0, table = None, base, 1.0, _model_table(base, seed)
        start_note = f"the spec's values (the direct method does not apply: {e})"
    problem = problem_for(table, model0, **problem_options)
    yx, values, steps, described, n_ref = [], [], [], [], 0
    for v in views:
        compiled = v.scene.compile()
        mats = set(v.material_shapes)
        refs = set()
        if free_scale:
            for k, s in enumerate(v.scene.shapes):
                if k in mats or s.material is None or getattr(s, "emission", None) is not None:
                    continue
                refs.add(k)
        p, shape = path.material_pixels(v, compiled, mats | refs)
        if not np.isin(shape, list(mats)).any():
            raise InputError(f"{v.photo.path}: no pixel of the mask sees only "
                             f'"@material" shapes (check the scene file {v.scene_path}, the '
                             "camera and the mask)")
        n_ref += int(np.isin(shape, list(refs)).sum())
        yx.append(p)
        values.append(v.photo.linear[p[:, 0], p[:, 1]])
        steps.append(None if v.photo.step is None else v.photo.step[p[:, 0], p[:, 1]])
        described.append({**_describe(v),
                          "pixels_on_material": int(np.isin(shape, list(mats)).sum()),
                          "reference_pixels": int(np.isin(shape, list(refs)).sum())})
    if free_scale and not n_ref:
        raise InputError("free scale: no pixel of a known material (a reference target, "
                         "e.g. a diffuse floor or a white standard) in view; without one "
                         "the exposure cannot be told from the BRDF's albedo and ks")
    with stage("fit-images: path", progress):
        pf = path.fit_path(problem, views, yx, values, scale=k0, free_scale=free_scale,
                           noise=noise, steps=steps, spp=spp, max_depth=max_depth, seed=seed,
                           progress=progress)
    model = pf.model
    x = pf.x[:len(problem.free)]
    for d, vals, pred in zip(described, values, pf.predictions):
        r = vals - pred
        d["image_loss"] = {"rmse": float(np.sqrt(np.mean(r ** 2))),
                           "relative_rmse": float(np.sqrt(np.mean(r ** 2)) / max(
                               float(np.sqrt(np.mean(vals ** 2))), 1e-300))}
    value, pred = np.concatenate(values), np.concatenate(pf.predictions)
    resid = value - pred
    image_loss = {"rmse": float(np.sqrt(np.mean(resid ** 2))),
                  "relative_rmse": float(np.sqrt(np.mean(resid ** 2)) /
                                         max(float(np.sqrt(np.mean(value ** 2))), 1e-300)),
                  "mean_relative_bias": float(np.sum(resid) / max(float(np.sum(pred)), 1e-300)),
                  "chi2_per_value": pf.chi2_per_value,
                  "what": "photograph minus the path tracer's render with the fitted model "
                          "(times the scale), over every pixel used (linear values)"}
    if residuals is not None:
        per_view = [_Pixels(p) for p in yx]
        written = _write_residuals(residuals, views, per_view, pf.predictions, force)
    natural = problem.natural(x)
    scale = {"free": bool(free_scale), "value": pf.scale, "sigma": pf.scale_sigma,
             "reference_pixels": n_ref}
    if free_scale:
        scale["method"] = "fitted jointly with the BRDF on the rendered reference pixels"
    laplace = {"percentiles": pf.percentiles(problem),
               "standard_errors": pf.standard_errors(problem),
               "names": list(problem.names), "covariance_x": pf.covariance.tolist(),
               "x": "each free parameter, the logarithm of log-scaled ones (roughness)",
               "method": "Gauss-Newton sandwich covariance (J^T J)^-1 J^T diag(r^2) J "
                         "(J^T J)^-1 of the weighted residuals r at the optimum (HC3), plus "
                         f"the covariance of the optimum over {path.STREAM_DRAWS} other random "
                         "streams (the renders' own Monte Carlo error)"}
    capture = {
        "method": "path",
        "method_reference": "image-space least squares through brdf's path tracer, common "
                            "random numbers, a fixed proposal per solve (detached sampling) "
                            "and forward-mode derivatives along the paths (brdf.capture.path)",
        "start": start_note,
        "views": described, "pixels_used": int(sum(len(p) for p in yx)),
        "iterations": pf.iterations, "renders": pf.renders, "solves": pf.rounds,
        "noise": {"gain": gain, "sigma": sigma,
                  "quantisation": any(v.photo.step is not None for v in views),
                  "model": ("none stated (unit weights)" if noise is None else
                            "sqrt(value / gain + step^2 / 12 + sigma^2) per pixel value") +
                           ", and the render's Monte Carlo variance"},
        "scale": scale, "image_loss": image_loss, "laplace": laplace,
        "options": {"spp": pf.spp, "max_depth": max_depth, "seed": seed},
    }
    if residuals is not None:
        capture["residual_images"] = written
    report = check(model)
    energy = report["energy"]
    run = {"run": "path", "optimizer": "least_squares (trf)", "status": pf.status,
           "loss": pf.loss, "evaluations": pf.renders, "start": problem.natural(problem.x0),
           "end": natural}
    base_runs = tuple(start.runs) if start is not None else ()
    provenance = dict(start.provenance) if start is not None else {
        "input": {}, "seed": int(seed), "options": {}}
    provenance.update(spec=str(base), input={"name": "capture", "sha256": None,
                                             "views": [d["image"] for d in described]})
    params = model.params
    timing = {"total_s": time.perf_counter() - began, "path_s": pf.seconds}
    return ImageFitResult(
        params=params, model=model, spec=str(model), loss=pf.loss,
        loss_name="image chi-square" if noise is not None else "image least squares",
        metrics={"image_relative_rmse": image_loss["relative_rmse"],
                 "image_chi2_per_value": pf.chi2_per_value},
        status=pf.status, converged=pf.converged, evaluations=pf.renders,
        free=problem.names, fixed={k: v for k, v in params.items() if k not in problem.names},
        bounds={p.name: [p.lower, p.upper] for p in problem.free},
        runs=base_runs + (run,),
        data={"samples_used": capture["pixels_used"],
              "samples_total": int(sum(d["pixels_masked"] for d in described)),
              "cutoff_deg": 90.0, "weighting": "unit" if noise is None else "1/sigma^2",
              "what": "pixels (RGB) of the photographs"},
        energy={"constrained": False, "holds": energy.passed, "worst_albedo": energy.worst,
                "theta_i": energy.where["theta_i"], "phi_i": energy.where["phi_i"],
                "channel": energy.where["channel"], "tolerance": energy.tolerance},
        checks=report.to_dict(), provenance=provenance, timing=timing,
        capture=capture, posterior=None, table=table)


@dataclass
class _Pixels:
    """The pixel rows and columns :func:`_write_residuals` reads (``yx``)."""

    yx: np.ndarray
