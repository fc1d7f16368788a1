"""BRDF families written in numpy: the :class:`CustomModel` base class and its registration.

A family is a subclass that declares its parameters exactly like the built-in ones (``name``,
``PARAMS`` of :class:`~brdf.models.base.Param` and :class:`~brdf.models.base.Choice`,
``citation``) and writes its formula once, vectorised, as :meth:`CustomModel.formula`. After
:func:`register_model` the family is a model like any other: ``brdf.parse`` reads it in specs and
sums (``"mine(k=2) + lambert(albedo=0.3)"``), models print and round-trip through JSON, and
``brdf.check``, ``brdf.measure``, ``brdf.fit``, ``brdf.mcmc`` and ``brdf.render`` accept it.

>>> import numpy as np, brdf
>>> @brdf.register_model
... class Flat(brdf.CustomModel):
...     '''f = k / pi: Lambert again, to show the shape of a family.'''
...     name = "flat-doc"
...     citation = "Lambert 1760, Photometria; f = rho / pi"
...     PARAMS = (brdf.models.Param("k", 0.5, (0.0, 1.0), per_channel=True),)
...     reciprocal = energy_conserving = isotropic = True
...     def formula(self, wi, wo):
...         return np.broadcast_to(self["k"] / np.pi, (len(wi), self.channels))
>>> m = brdf.parse("flat-doc(k=[0.2,0.4,0.6]) + ggx(alpha=0.3)")
>>> bool(brdf.check(m).passed)
True
>>> _ = brdf.unregister_model("flat-doc")

Such a family has no compiled kernel (``kind`` -1): it runs at numpy speed, which is fine for
checks, fits of gonioreflectometer tables and the examples; sums of built-in lobes alone keep
their kernels.
"""

import importlib
import importlib.util
import math
import os
import re
import sys

import numpy as np

from ..errors import InputError, SpecError
from ..geometry import direction_array, flat_pairs
from ._registry import MODELS
from .base import (GAUSS_RULES, Choice, Model, Nested, Param, gauss_legendre_unit,
                   cubature_options, sample_inputs)

__all__ = ["CustomModel", "register_model", "unregister_model", "load_plugin", "plugin_sources",
           "ensure_plugins",
           "square_to_cosine_hemisphere", "cosine_hemisphere_pdf", "START_GRID", "HINT_POINTS"]

INV_PI = 1.0 / math.pi
#: The largest double below 1: uniform numbers lie in [0, 1).
BELOW_ONE = 1.0 - 2.0 ** -53
#: Panels per side of the albedo cubature's starting grid (as in the kernels' ``_lobe_albedo``).
START_GRID = 4
#: Gauss-Legendre points per side of the rule behind the default :meth:`CustomModel.hint`.
HINT_POINTS = 4
#: Integrand nodes evaluated per call of the formula in the albedo cubature: bounds memory.
CHUNK = 1 << 17
#: What a model name may look like: the NAME token of the spec syntax (brdf/spec.py).
_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_\-]*")


def square_to_cosine_hemisphere(u):
    """Directions ``(n, 3)`` with density cos(theta) / pi from uniform numbers ``u`` ``(n, 2)``.

    The numpy counterpart of the kernels' :func:`brdf.sampling.square_to_cosine_hemisphere`:
    Shirley & Chiu 1997, "A Low Distortion Map Between Disk and Square", section 3 (the
    concentric disk), then Malley's method, z = sqrt(1 - x^2 - y^2) (PBR 4th ed. 13.6.3).
    """
    a = 2.0 * u[:, 0] - 1.0
    b = 2.0 * u[:, 1] - 1.0
    wide = a * a > b * b
    r = np.where(wide, a, b)
    with np.errstate(divide="ignore", invalid="ignore"):
        phi = np.where(wide, (math.pi / 4.0) * (b / a), math.pi / 2.0 - (math.pi / 4.0) * (a / b))
    phi = np.where((a == 0.0) & (b == 0.0), 0.0, phi)
    x, y = r * np.cos(phi), r * np.sin(phi)
    return np.stack([x, y, np.sqrt(np.maximum(0.0, 1.0 - x * x - y * y))], axis=-1)


def cosine_hemisphere_pdf(wo):
    """Solid-angle density of :func:`square_to_cosine_hemisphere`: cos(theta) / pi."""
    return np.maximum(wo[:, 2], 0.0) * INV_PI


def _edge_warp(t):
    """u = 10t^3 - 15t^4 + 6t^5 and du/dt = 30 t^2 (1 - t)^2 (Perlin 2002, "Improving Noise"):
    the numpy twin of the kernels' ``_edge_warp`` (see there why), odd about t = 1/2 so that
    1 - u keeps its digits near u = 1."""
    s = np.minimum(t, 1.0 - t)
    g = s * s * s * (10.0 + s * (6.0 * s - 15.0))
    return (np.where(t <= 0.5, g, np.minimum(1.0 - g, BELOW_ONE)),
            30.0 * s * s * (1.0 - s) * (1.0 - s))


class CustomModel(Model):
    """Base class of a BRDF family written in numpy.

    Subclasses set ``name`` (a spec name: letters, digits, ``_`` and ``-``), ``PARAMS``
    (:class:`~brdf.models.base.Param` and :class:`~brdf.models.base.Choice` declarations, which
    feed spec parsing, validation, bounds, priors, flat names and JSON), ``citation`` and
    ``summary``, and define :meth:`formula`. Parameter values are read as ``self["name"]``
    (float arrays shaped ``()`` or ``(C,)``; choices as strings).

    Attributes
    ----------
    reciprocal, energy_conserving : bool
        Set by a family: what it claims (default False: nothing claimed); ``brdf.check`` tests both
        whatever they say, and ``brdf-fit models`` shows them.
    isotropic : bool
        Set by a family: True when f depends on the azimuths only through their difference. Default False:
        checks then integrate the albedo over incident azimuths too, and the renderer, which
        tabulates custom families on the isotropic MERL grid, refuses the model.

    Methods
    -------
    sample_formula(wi, u), pdf_formula(wi, wo)
        A family may override: importance sampling (both or neither); the default is
        cosine-weighted.
    hint(wi)
        A family may override: a cheap albedo estimate for choosing lobes when sampling a sum.
    albedo(wi, ...)
        A family may override: the default integrates over the sampler's unit square (see :meth:`albedo`).

    Notes
    -----
    :meth:`formula` is called only with both directions strictly above the horizon (z > 0);
    every other pair evaluates to 0 and has density 0, whatever the formula would give. Channel
    c of the formula should depend on channel c of per-channel parameters and on the scalar
    ones only, as in every built-in family: fitting's difference quotients move the channels
    of a parameter together.
    """

    kind = -1  # no compiled kernel: brdf.models.mixed evaluates sums that hold one
    reciprocal = False
    energy_conserving = False
    isotropic = False

    # -- what a family writes -------------------------------------------------------------------
    def formula(self, wi, wo):
        """f_r(wi, wo) in 1/sr, without the cosine, for unit directions ``(n, 3)`` above the
        horizon: an array ``(n, C)`` (C = ``self.channels``), or ``(n,)`` for all channels."""
        raise NotImplementedError(f"{type(self).__name__} must define formula(self, wi, wo)")

    def sample_formula(self, wi, u):
        """Directions ``wo`` ``(n, 3)`` drawn for ``wi`` ``(n, 3)`` from uniform numbers ``u``
        ``(n, 2)``, and their solid-angle density ``(n,)``; the default draws cosine-weighted
        (density cos(theta_o) / pi), which suits near-diffuse families."""
        wo = square_to_cosine_hemisphere(u)
        return wo, cosine_hemisphere_pdf(wo)

    def pdf_formula(self, wi, wo):
        """Solid-angle density ``(n,)`` of :meth:`sample_formula` at ``wo``, for directions
        above the horizon."""
        return cosine_hemisphere_pdf(wo)

    def hint(self, wi):
        """A cheap estimate ``(n,)`` of the albedo at ``wi`` ``(n, 3)`` (mean over channels):
        a sum picks its lobes for sampling in proportion to their hints, so a poor hint costs
        variance, never bias. The default is a fixed :data:`HINT_POINTS` squared Gauss rule
        over the sampler's unit square."""
        wi = np.asarray(wi, dtype=float).reshape(-1, 3)
        xs, ws = gauss_legendre_unit(HINT_POINTS)
        t1, t2 = (g.ravel() for g in np.meshgrid(xs, xs, indexing="ij"))
        w = np.outer(ws, ws).ravel()
        (u1, j1), (u2, j2) = _edge_warp(t1), _edge_warp(t2)
        k = len(w)
        u = np.tile(np.stack([u1, u2], axis=-1), (len(wi), 1))
        g = self._weight(np.repeat(wi, k, axis=0), u).reshape(len(wi), k, -1)
        return np.einsum("nkc,k->n", g, w * j1 * j2) / g.shape[-1]

    # -- the Model interface, built on them ------------------------------------------------------
    @property
    def is_anisotropic(self):
        return not self.isotropic or super().is_anisotropic

    def eval(self, wi, wo):
        """BRDF value f_r(wi, wo) in 1/sr without the cosine, shaped ``(..., C)``; 0 unless both
        directions are above the horizon."""
        wi, wo, shape = flat_pairs(wi, wo)
        return self._eval_flat(wi, wo).reshape(shape + (self.channels,))

    def pdf(self, wi, wo):
        """Solid-angle density of :meth:`sample` at ``wo``, shaped ``(...)``."""
        wi, wo, shape = flat_pairs(wi, wo)
        out = np.zeros(len(wi))
        up = _above(wi, wo)
        if up.any():
            sel = slice(None) if up.all() else up
            out[sel] = self._vector(self.pdf_formula(wi[sel], wo[sel]), "pdf_formula",
                                    len(out[sel]))
        return out.reshape(shape)

    def sample_weighted(self, wi, u):
        """``(wo, pdf, weight)`` for each ``wi`` from uniform numbers ``u`` ``(..., 2)``; the
        weight is f cos(theta_o) / pdf ``(..., C)``, and pdf and weight are 0 where the sample
        is invalid (either direction at or below the horizon)."""
        wi, u, shape = sample_inputs(wi, u)
        wo, pdf = self._sampled(wi, u)
        weight = self._ratio(self._eval_flat(wi, wo), wo, pdf)
        return (wo.reshape(shape + (3,)), pdf.reshape(shape),
                weight.reshape(shape + (self.channels,)))

    def albedo(self, wi, tol=1e-5, return_error=False, max_panels=1024):
        """Directional albedo a(wi) = integral of f cos(theta_o) over the hemisphere, ``(..., C)``.

        The integrand f cos / pdf is integrated over the unit square of :meth:`sample_formula`
        (through the same edge warp as the kernels) by adaptive cubature, all directions at
        once: square panels, each with a 6 x 6 Gauss-Legendre rule and an embedded 3 x 3 one;
        while a direction's summed differences exceed ``tol`` times max(1, albedo), its panels
        holding the largest differences (half of its total, the worst at least) split in four,
        until ``max_panels`` are used.

        Returns
        -------
        albedo : ndarray, shape (..., C)
        error : ndarray, shape (..., C)
            With ``return_error``: the summed panel differences, an estimate of the absolute
            error (a jump of the integrand inside a panel, e.g. where a custom sampler's samples
            fall below the horizon, may escape it).
        """
        tol, max_panels = cubature_options(tol, max_panels)
        wi = direction_array(wi, "wi")
        shape = wi.shape[:-1]
        out, err = _cubature(self, wi.reshape(-1, 3), tol, max_panels)
        out = out.reshape(shape + (self.channels,))
        err = err.reshape(out.shape)
        return (out, err) if return_error else out

    # -- helpers ---------------------------------------------------------------------------------
    def _eval_flat(self, wi, wo):
        """:meth:`formula` on pairs above the horizon, 0 elsewhere: ``(n, C)``."""
        out = np.zeros((len(wi), self.channels))
        up = _above(wi, wo)
        if up.any():
            sel = slice(None) if up.all() else up
            n = len(out[sel])
            out[sel] = self._values_of(self.formula(wi[sel], wo[sel]), n)
        return out

    def _sampled(self, wi, u):
        """:meth:`sample_formula` with the horizon enforced: ``(wo (n, 3), pdf (n,))``."""
        n = len(wi)
        wo, pdf = self.sample_formula(wi, u)
        wo = np.asarray(wo, dtype=float)
        if wo.shape != (n, 3):
            raise InputError(f"{self.name}.sample_formula returned directions shaped {wo.shape};"
                             f" expected ({n}, 3)")
        pdf = self._vector(pdf, "sample_formula", n)
        valid = _above(wi, wo) & np.isfinite(pdf) & (pdf > 0.0)
        return wo, np.where(valid, pdf, 0.0)

    def _weight(self, wi, u):
        """The albedo's integrand f cos(theta_o) / pdf at the samples of ``u``: ``(n, C)``."""
        wo, pdf = self._sampled(wi, u)
        return self._ratio(self._eval_flat(wi, wo), wo, pdf)

    @staticmethod
    def _ratio(f, wo, pdf):
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where((pdf > 0.0)[:, None], f * (wo[:, 2] / pdf)[:, None], 0.0)

    def _values_of(self, value, n):
        """The formula's output as ``(n, C)``, or a one-line error naming the family."""
        arr = np.asarray(value, dtype=float)
        nch = self.channels
        if arr.shape == (n,):
            arr = arr[:, None]
        if arr.shape not in ((n, 1), (n, nch)):
            raise InputError(f"{self.name}.formula returned shape {arr.shape}; expected ({n},) "
                             f"or ({n}, {nch}) for {n} direction pairs and {nch} channel(s)")
        return np.broadcast_to(arr, (n, nch))

    def _vector(self, value, method, n):
        arr = np.asarray(value, dtype=float)
        if arr.shape != (n,):
            raise InputError(f"{self.name}.{method} returned densities shaped {arr.shape}; "
                             f"expected ({n},)")
        return arr


def _above(wi, wo):
    return (wi[:, 2] > 0.0) & (wo[:, 2] > 0.0)


# --- the albedo cubature ----------------------------------------------------------------------

def _panel_rules(model, wi, owner, x0, y0, h):
    """Values ``(P, C)`` of the 6 x 6 Gauss rule over each panel (owner's direction, corner
    (x0, y0), side h) of the sampling square, and their differences to the 3 x 3 rule."""
    xs_hi, ws_hi, xs_lo, ws_lo = GAUSS_RULES
    out = []
    for xs, ws in ((xs_hi, ws_hi), (xs_lo, ws_lo)):
        n = len(xs)
        t1 = (x0[:, None, None] + h[:, None, None] * xs[None, :, None]).repeat(n, axis=2)
        t2 = (y0[:, None, None] + h[:, None, None] * xs[None, None, :]).repeat(n, axis=1)
        (u1, j1), (u2, j2) = _edge_warp(t1.ravel()), _edge_warp(t2.ravel())
        u = np.stack([u1, u2], axis=-1)
        rows = np.repeat(owner, n * n)
        g = np.concatenate([model._weight(wi[rows[s:s + CHUNK]], u[s:s + CHUNK])
                            for s in range(0, len(u), CHUNK)])
        w = (j1 * j2 * np.outer(ws, ws).ravel()[None, :].repeat(len(owner), 0).ravel())
        out.append(np.einsum("pkc,pk->pc", g.reshape(len(owner), n * n, -1),
                             w.reshape(len(owner), n * n)) * (h * h)[:, None])
    return out[0], np.abs(out[0] - out[1])


def _per_direction(owner, values, m):
    """Sums over panels of ``values`` ``(P, C)`` per direction: ``(m, C)``."""
    return np.stack([np.bincount(owner, values[:, c], minlength=m)
                     for c in range(values.shape[1])], axis=-1)


def _cubature(model, wi, tol, max_panels):
    """Albedo and error estimate ``(m, C)`` of every direction of ``wi`` ``(m, 3)``."""
    m, nch = len(wi), model.channels
    dirs = np.flatnonzero(wi[:, 2] > 0.0)
    if not len(dirs):
        return np.zeros((m, nch)), np.zeros((m, nch))
    g = START_GRID
    cell = np.arange(g * g)
    owner = np.repeat(dirs, g * g)
    x0 = np.tile((cell // g) / g, len(dirs))
    y0 = np.tile((cell % g) / g, len(dirs))
    h = np.full(len(owner), 1.0 / g)
    val, diff = _panel_rules(model, wi, owner, x0, y0, h)
    while True:
        worst = diff.max(axis=1)
        total = np.bincount(owner, worst, minlength=m)
        peak = np.abs(_per_direction(owner, val, m)).max(axis=1)
        count = np.bincount(owner, minlength=m)
        active = (total > tol * np.maximum(1.0, peak)) & (count + 3 <= max_panels)
        candidates = np.flatnonzero(active[owner])
        if not len(candidates):
            break
        # within each direction, its worst panels first; split those holding half its error
        order = candidates[np.lexsort((-worst[candidates], owner[candidates]))]
        o, e = owner[order], worst[order]
        first = np.searchsorted(o, o, side="left")
        rank = np.arange(len(o)) - first
        cum = np.cumsum(e)
        before = cum - e - (cum[first] - e[first])
        split = order[(before < 0.5 * total[o]) & (rank < (max_panels - count[o]) // 3)]
        half = 0.5 * h[split]
        kids = [(x0[split] + half * (k % 2), y0[split] + half * (k // 2)) for k in range(4)]
        cx = np.concatenate([k[0] for k in kids])
        cy = np.concatenate([k[1] for k in kids])
        co, ch = np.tile(owner[split], 4), np.tile(half, 4)
        cval, cdiff = _panel_rules(model, wi, co, cx, cy, ch)
        keep = np.ones(len(owner), dtype=bool)
        keep[split] = False
        owner = np.concatenate([owner[keep], co])
        x0, y0, h = (np.concatenate([a[keep], b]) for a, b in ((x0, cx), (y0, cy), (h, ch)))
        val, diff = np.concatenate([val[keep], cval]), np.concatenate([diff[keep], cdiff])
    return _per_direction(owner, val, m), _per_direction(owner, diff, m)


# --- registration -----------------------------------------------------------------------------

def register_model(cls):
    """Register a :class:`CustomModel` subclass under its ``name`` and ``aliases`` (a class
    decorator; returns ``cls``), so that specs, JSON, fit reports and ``brdf-fit models`` know it.

    Defining the same class again (a re-run notebook cell: same module and qualified name)
    replaces the earlier definition.

    Raises
    ------
    SpecError
        When ``cls`` is not a CustomModel subclass with a spec name, a ``formula`` and
        declarations in ``PARAMS``, defines only one of ``sample_formula`` and ``pdf_formula``,
        or when its name or an alias is taken by a built-in family or another custom one.
    """
    if not (isinstance(cls, type) and issubclass(cls, CustomModel)):
        raise SpecError(f"register_model takes a subclass of brdf.CustomModel, got {cls!r}")
    where = f"custom model {cls.__qualname__}"
    for key in (cls.name, *cls.aliases):
        if not (isinstance(key, str) and _NAME.fullmatch(key)):
            raise SpecError(f"{where}: name {key!r} must start with a letter or _ and hold only "
                            "letters, digits, _ and -")
    if cls.formula is CustomModel.formula:
        raise SpecError(f"{where}: define formula(self, wi, wo)")
    if (cls.sample_formula is CustomModel.sample_formula) != \
            (cls.pdf_formula is CustomModel.pdf_formula):
        raise SpecError(f"{where}: define both sample_formula and pdf_formula, or neither (the "
                        "default is cosine-weighted)")
    bad = [d for d in cls.PARAMS if not isinstance(d, (Param, Choice, Nested))]
    if bad:
        raise SpecError(f"{where}: PARAMS must hold Param or Choice declarations, got {bad[0]!r}")
    for key in (cls.name, *cls.aliases):
        other = MODELS.owner(key)
        if other is None or other is cls:
            continue
        if not issubclass(other, CustomModel):
            raise SpecError(f"{where}: the name {key!r} is taken by the built-in family "
                            f"{other.name!r}; choose another name")
        if (other.__module__, other.__qualname__) != (cls.__module__, cls.__qualname__):
            raise SpecError(f"{where}: the name {key!r} is taken by the custom family "
                            f"{other.__module__}.{other.__qualname__}; choose another name or "
                            f"unregister_model({other.name!r}) first")
        MODELS.unregister(other.name)
    return MODELS.register(cls)


def unregister_model(name):
    """Remove the custom family registered as ``name`` (or an alias); returns its class."""
    cls = MODELS.get(name)
    if not issubclass(cls, CustomModel):
        raise SpecError(f"{name!r} is a built-in family; only custom ones can be unregistered")
    return MODELS.unregister(cls.name)


def plugin_sources():
    """What another process must import to know the registered custom families, in order of
    registration: module names, or the files :func:`load_plugin` read. Families defined in a
    script's ``__main__`` are left out: spawned workers run the script's top level again."""
    out = []
    for cls in MODELS.classes():
        if not issubclass(cls, CustomModel) or cls.__module__ in ("__main__", "__mp_main__"):
            continue
        source = cls.__module__
        if source.startswith(_PLUGIN_PREFIX):
            source = getattr(sys.modules.get(source), "__file__", None)
        if source and source not in out:
            out.append(source)
    return out


def ensure_plugins(sources):
    """Load each of ``sources`` (see :func:`plugin_sources`) not yet imported here: a worker's
    first task imports them, later tasks and the parent process find them loaded."""
    for source in sources:
        if _module_name(source) not in sys.modules:
            load_plugin(source)


#: Module names of plugin files read by :func:`load_plugin` start with this.
_PLUGIN_PREFIX = "brdf_plugin_"


def _module_name(source):
    source = os.fspath(source)
    if source.endswith(".py") or os.sep in source:
        return _PLUGIN_PREFIX + re.sub(r"\W", "_", os.path.splitext(os.path.basename(source))[0])
    return source


def load_plugin(source):
    """Import the Python file or module ``source`` whose import registers custom families
    (``brdf-fit --plugin``); returns the module.

    Raises
    ------
    InputError
        When the file does not exist or the module cannot be found.
    """
    source = os.fspath(source)
    if source.endswith(".py") or os.sep in source:
        if not os.path.isfile(source):
            raise InputError(f"plugin {source}: no such file (expected a .py file or a module "
                             "name)")
        name = _module_name(source)
        spec = importlib.util.spec_from_file_location(name, source)
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        spec.loader.exec_module(module)
        return module
    try:
        return importlib.import_module(source)
    except ModuleNotFoundError as exc:
        if exc.name and source.startswith(exc.name):
            raise InputError(f"plugin {source!r}: no module named {exc.name!r} (expected a .py "
                             "file or an importable module name)") from None
        raise
