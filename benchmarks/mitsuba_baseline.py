"""Mitsuba 3 as a performance baseline and independent oracle.

Evaluates a Lambertian + GGX (Fresnel-free) BRDF with Mitsuba's vectorised
BSDF API on the Dr.Jit LLVM backend (variant ``llvm_ad_rgb``). This module
deliberately imports nothing from the ``brdf`` package so that it stays an
independent reference.

Mitsuba's ``roughconductor`` with ``material='none'`` uses the complex index
of refraction ``eta = 0 + 1j``, for which its conductor Fresnel term is
exactly 1. Its GGX shadowing-masking term is the separable (uncorrelated)
Smith product ``G1(wi) * G1(wo)``.

Examples
--------
>>> mi = setup_llvm()
>>> f = eval_lambert_ggx(mi, wi, wo, albedo=(0.5, 0.4, 0.3), alpha=0.3, ks=1.0)
>>> stats = time_eval(mi, wi, wo, (0.5, 0.4, 0.3), 0.3, 1.0, repeats=10)
"""

import glob
import os
import statistics
import time

import numpy as np

VARIANT = "llvm_ad_rgb"
LIBLLVM_ENV = "DRJIT_LIBLLVM_PATH"
LIBLLVM_PATTERNS = (
    "/usr/lib/llvm-19/lib/libLLVM-19.so",
    "/usr/lib/x86_64-linux-gnu/libLLVM-19.so*",
    "/usr/lib/aarch64-linux-gnu/libLLVM-19.so*",
)


def find_libllvm():
    """Locate the LLVM 19 shared library used by Dr.Jit's LLVM backend.

    Returns
    -------
    str
        The value of ``DRJIT_LIBLLVM_PATH`` if set, otherwise the first
        existing match among the usual Debian install paths.

    Raises
    ------
    RuntimeError
        If no libLLVM-19 shared library can be found.
    """
    configured = os.environ.get(LIBLLVM_ENV)
    if configured:
        return configured
    for pattern in LIBLLVM_PATTERNS:
        matches = sorted(glob.glob(pattern))
        if matches:
            return matches[0]
    raise RuntimeError(
        "libLLVM-19.so not found: install it (apt-get install libllvm19) "
        f"or set {LIBLLVM_ENV}"
    )


def setup_llvm():
    """Import Mitsuba and select the ``llvm_ad_rgb`` variant.

    Sets ``DRJIT_LIBLLVM_PATH`` (see :func:`find_libllvm`) before importing
    Mitsuba so that Dr.Jit can load its LLVM backend.

    Returns
    -------
    module
        The ``mitsuba`` module with variant ``llvm_ad_rgb`` active.

    Raises
    ------
    RuntimeError
        If Mitsuba is not installed or the LLVM backend cannot be loaded.
    """
    os.environ[LIBLLVM_ENV] = find_libllvm()
    try:
        import mitsuba as mi
    except ImportError as exc:
        raise RuntimeError("mitsuba is not installed (pip install mitsuba)") from exc
    try:
        mi.set_variant(VARIANT)
    except Exception as exc:
        raise RuntimeError(
            f"cannot load Mitsuba variant {VARIANT} with {os.environ[LIBLLVM_ENV]}"
        ) from exc
    return mi


def _rgb(value):
    """Return ``value`` (scalar or 3-sequence) as a Mitsuba RGB texture dict."""
    rgb = np.broadcast_to(np.asarray(value, dtype=float), (3,))
    return {"type": "rgb", "value": [float(c) for c in rgb]}


def make_bsdfs(mi, albedo, alpha, ks):
    """Build the diffuse and Fresnel-free GGX conductor BSDFs.

    Parameters
    ----------
    mi : module
        Mitsuba module returned by :func:`setup_llvm`.
    albedo : float or array_like, shape (3,)
        Diffuse reflectance (RGB).
    alpha : float
        Isotropic GGX roughness (Mitsuba's ``alpha``, not squared).
    ks : float or array_like, shape (3,)
        Specular reflectance scaling the GGX lobe.

    Returns
    -------
    tuple of mitsuba.BSDF
        ``(diffuse, conductor)``.
    """
    diffuse = mi.load_dict({"type": "diffuse", "reflectance": _rgb(albedo)})
    conductor = mi.load_dict({
        "type": "roughconductor",
        "material": "none",
        "distribution": "ggx",
        "alpha": float(alpha),
        "specular_reflectance": _rgb(ks),
    })
    return diffuse, conductor


def _vector3f(mi, v):
    """Convert an (N, 3) numpy array to a float32 ``mi.Vector3f``."""
    v = np.asarray(v, dtype=np.float32)
    return mi.Vector3f(*(mi.Float(np.ascontiguousarray(v[:, k])) for k in range(3)))


def to_drjit(mi, wi, wo):
    """Convert direction pairs to Dr.Jit inputs and evaluate them.

    Parameters
    ----------
    mi : module
        Mitsuba module returned by :func:`setup_llvm`.
    wi, wo : ndarray, shape (N, 3)
        Directions in the local shading frame (z = normal), pointing away
        from the surface.

    Returns
    -------
    tuple
        ``(si, wo)``: a ``SurfaceInteraction3f`` of width N with ``wi`` set
        and an identity shading frame, and ``wo`` as ``mi.Vector3f``.
    """
    import drjit as dr

    si = dr.zeros(mi.SurfaceInteraction3f, len(wi))
    si.wi = _vector3f(mi, wi)
    si.n = mi.Normal3f(0.0, 0.0, 1.0)
    si.sh_frame = mi.Frame3f(si.n)
    wo_dr = _vector3f(mi, wo)
    dr.eval(si, wo_dr)
    dr.sync_thread()
    return si, wo_dr


def eval_drjit(mi, bsdfs, si, wo):
    """Lazily evaluate the summed BRDF without the cosine factor.

    Parameters
    ----------
    mi : module
        Mitsuba module returned by :func:`setup_llvm`.
    bsdfs : tuple of mitsuba.BSDF
        BSDFs from :func:`make_bsdfs`; their values are summed.
    si : mitsuba.SurfaceInteraction3f
        Interaction from :func:`to_drjit`.
    wo : mitsuba.Vector3f
        Outgoing directions from :func:`to_drjit`.

    Returns
    -------
    mitsuba.Color3f
        Unevaluated BRDF values ``f`` (Mitsuba's ``f * cos(theta_o)``
        divided by ``wo.z``).
    """
    ctx = mi.BSDFContext()
    f_cos = sum(bsdf.eval(ctx, si, wo) for bsdf in bsdfs)
    return f_cos / wo.z


def eval_lambert_ggx(mi, wi, wo, albedo, alpha, ks, bsdfs=None):
    """Evaluate ``albedo / pi + ks * D * G1(wi) * G1(wo) / (4 cos_i cos_o)``.

    Parameters
    ----------
    mi : module
        Mitsuba module returned by :func:`setup_llvm`.
    wi, wo : ndarray, shape (N, 3)
        Directions in the local shading frame (z = normal), pointing away
        from the surface.
    albedo : float or array_like, shape (3,)
        Diffuse reflectance (RGB).
    alpha : float
        Isotropic GGX roughness.
    ks : float or array_like, shape (3,)
        Specular reflectance.
    bsdfs : tuple of mitsuba.BSDF, optional
        The BSDFs of :func:`make_bsdfs` for these parameters, built once by
        a caller that evaluates them many times; built here by default.

    Returns
    -------
    ndarray, shape (N, 3), float64
        BRDF values without the cosine factor (computed in float32); zero
        where either direction is below the surface.
    """
    si, wo_dr = to_drjit(mi, wi, wo)
    if bsdfs is None:
        bsdfs = make_bsdfs(mi, albedo, alpha, ks)
    f = eval_drjit(mi, bsdfs, si, wo_dr)
    return np.array(f, dtype=np.float64).T


def time_eval(mi, wi, wo, albedo, alpha, ks, repeats=10):
    """Time :func:`eval_drjit`, excluding numpy conversions.

    Inputs are converted to Dr.Jit arrays first. One warm-up evaluation
    compiles and caches the kernel; each timed repeat then traces the
    expression again, launches it with ``dr.eval`` and waits for it with
    ``dr.sync_thread``.

    Parameters
    ----------
    mi : module
        Mitsuba module returned by :func:`setup_llvm`.
    wi, wo : ndarray, shape (N, 3)
        Directions in the local shading frame.
    albedo, alpha, ks
        As in :func:`eval_lambert_ggx`.
    repeats : int, optional
        Number of timed evaluations after the warm-up.

    Returns
    -------
    dict
        ``best_s`` and ``median_s`` wall times in seconds, and
        ``pairs_per_s`` computed from ``best_s``.
    """
    import drjit as dr

    bsdfs = make_bsdfs(mi, albedo, alpha, ks)
    si, wo_dr = to_drjit(mi, wi, wo)
    times = []
    for _ in range(repeats + 1):
        start = time.perf_counter()
        f = eval_drjit(mi, bsdfs, si, wo_dr)
        dr.eval(f)
        dr.sync_thread()
        times.append(time.perf_counter() - start)
        del f
    best = min(times[1:])
    return {
        "best_s": best,
        "median_s": statistics.median(times[1:]),
        "pairs_per_s": len(wi) / best,
    }
