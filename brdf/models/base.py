"""Parameter declarations, the model base class and additive mixtures.

A model family declares its parameters once (:class:`Param`, :class:`Choice`, :class:`Nested`);
that declaration drives spec parsing and printing, validation, JSON, flat ``"lobe.param"`` names,
and the bounds and priors that fitting uses. Evaluation, sampling and the albedo quadrature run in
compiled kernels (:mod:`brdf.models._kernels`) that every built-in family, and every sum of
them, goes through. Families written in numpy (:class:`brdf.models.custom.CustomModel`) have no
kernel (``kind`` -1); a sum holding one is evaluated lobe by lobe (:mod:`brdf.models.mixed`).
"""

import math

import numpy as np

from .. import memory
from ..arguments import integer, real
from ..errors import InputError, ParameterError, SpecError
from ..geometry import UNIT_SQ, broadcast_shape, direction_array, flat_pairs, uniform_array

__all__ = ["Param", "Choice", "Nested", "Start", "Component", "Model", "Sum", "Compiled", "Layout",
           "sample_inputs"]


class Param:
    """A numeric parameter.

    Parameters
    ----------
    name : str
        Name in specs, JSON and flat names.
    default : float or None
        Value when the spec omits it; ``None`` makes the parameter optional, and then it takes
        the value of ``fallback`` (another parameter of the same model) when packed for kernels.
    bounds : (float, float)
        Closed interval of valid values; fitting uses it as the box.
    units : str
        Units shown in ``brdf-fit models`` and reports (``""`` for dimensionless).
    per_channel : bool
        Whether the value may hold one entry per channel (1, 3 or n wavelengths).
    prior : {"linear", "log"}
        Scale of the uniform prior used by MCMC and of multi-start draws.
    doc : str
        One line shown in help.
    aliases : tuple of str
        Other names accepted in specs.
    fallback : str or None
        For optional parameters: the parameter whose value stands in when this one is not given.
    fit_bounds : (float, float) or None
        A narrower box for fitting where ``bounds`` is unbounded (e.g. Phong exponents).
    """

    kind = "number"

    def __init__(self, name, default, bounds=(-math.inf, math.inf), units="", per_channel=False,
                 prior="linear", doc="", aliases=(), fallback=None, fit_bounds=None):
        self.name, self.default, self.bounds = name, default, tuple(float(b) for b in bounds)
        self.units, self.per_channel, self.prior, self.doc = units, per_channel, prior, doc
        self.aliases, self.fallback = tuple(aliases), fallback
        self.fit_bounds = tuple(fit_bounds) if fit_bounds is not None else self.bounds

    def coerce(self, value, where):
        """Validated float array (shape ``()`` or ``(C,)``) from a spec or Python value."""
        what = "a number or a list of per-channel numbers" if self.per_channel else "a number"
        try:
            arr = np.array(value, dtype=float)
        except (TypeError, ValueError):  # a name or other text where a number belongs
            raise ParameterError(f"{where}: {self.name} must be {what}, got {value!r}") from None
        if arr.ndim > 1 or (arr.ndim == 1 and (not self.per_channel or arr.size == 0)):
            raise ParameterError(f"{where}: {self.name} must be {what}, got {value!r}")
        if not np.all(np.isfinite(arr)):
            raise ParameterError(f"{where}: {self.name} must be finite, got {value!r}")
        lo, hi = self.bounds
        if np.any(arr < lo) or np.any(arr > hi):
            raise ParameterError(f"{where}: {self.name}={_fmt(arr)} is outside its bounds "
                                 f"[{_fmt(lo)}, {_fmt(hi)}]")
        if arr.ndim == 1 and arr.size == 1:
            arr = arr.reshape(())
        arr.setflags(write=False)
        return arr

    def describe(self):
        """Dictionary for ``brdf-fit models --json`` and help text."""
        return {"name": self.name, "kind": self.kind, "default": self.default,
                "bounds": list(self.bounds), "units": self.units,
                "per_channel": self.per_channel, "prior": self.prior, "doc": self.doc,
                "aliases": list(self.aliases)}


class Choice:
    """An option chosen by name among fixed strings (e.g. ``variant=gmd``)."""

    kind = "choice"

    def __init__(self, name, default, choices, doc="", aliases=()):
        self.name, self.default, self.choices = name, default, tuple(choices)
        self.doc, self.aliases = doc, tuple(aliases)

    def coerce(self, value, where):
        if not isinstance(value, str) or value not in self.choices:
            raise ParameterError(f"{where}: {self.name} must be one of "
                                 f"{', '.join(self.choices)}; got {value!r}")
        return value

    def describe(self):
        return {"name": self.name, "kind": self.kind, "default": self.default,
                "choices": list(self.choices), "doc": self.doc, "aliases": list(self.aliases)}


class Nested:
    """A parameter whose value is a component of another registry (e.g. a Fresnel term)."""

    kind = "component"

    def __init__(self, name, default, registry, doc="", aliases=()):
        self.name, self.default, self.registry = name, default, registry
        self.doc, self.aliases = doc, tuple(aliases)

    def coerce(self, value, where):
        from ..spec import component_from_dict, parse_component
        if isinstance(value, str):
            value = parse_component(value, self.registry)
        elif isinstance(value, dict) and "model" in value:
            value = component_from_dict(value, self.registry)
        if not isinstance(value, Component) or value.name not in self.registry.names():
            raise ParameterError(f"{where}: {self.name} must be one of "
                                 f"{', '.join(self.registry.names())}; got {value!r}")
        return value

    def describe(self):
        return {"name": self.name, "kind": self.kind, "default": self.default,
                "choices": self.registry.names(), "doc": self.doc, "aliases": list(self.aliases)}


class Start:
    """What a family tells the fitter's data-driven start (:mod:`brdf.fitting.starts`).

    Parameters
    ----------
    scale : tuple of str
        Parameters f is proportional to, each channel on its own: with the others held, their
        best values follow from bounded linear least squares (variable projection, Golub &
        Pereyra 1973). Several names move together as one factor (Lafortune's cx, cy, cz).
    shape : tuple of str
        Nonlinear parameters (widths, exponents) searched on a grid over their fit box (log
        spaced for a log prior): the lobe's angular spread, which the grid must span.
    power : str or None
        When f scales as (scale factor)^p with p this parameter (Lafortune's exponent n), the
        scale parameters are multiplied by k^(1/p) to scale f by k.
    directions : tuple of tuples
        For a power law, the patterns of the scale parameters (up to their common factor) the
        start tries besides the spec's own, one more grid dimension: Lafortune's forward,
        retro-reflective and diffuse-like lobes. A lobe's orientation is no width, and no
        least squares finds it: without these the start only knows the spec's orientation.

    A family that declares nothing keeps its spec values in the start.
    """

    def __init__(self, scale=(), shape=(), power=None, directions=()):
        self.scale, self.shape, self.power = tuple(scale), tuple(shape), power
        self.directions = tuple(tuple(float(v) for v in d) for d in directions)


def _fmt(x):
    """Shortest round-tripping text of a number or a per-channel array."""
    arr = np.asarray(x, dtype=float)
    if arr.ndim == 0:
        v = float(arr)
        return repr(int(v)) if v.is_integer() and abs(v) < 1e15 else repr(v)
    return "[" + ",".join(_fmt(v) for v in arr) + "]"


class Component:
    """Something with declared parameters that prints as a spec: a model or a Fresnel term."""

    name = ""
    aliases = ()
    PARAMS = ()
    citation = ""
    summary = ""

    def __init__(self, *args, **kwargs):
        decls = self.PARAMS
        if len(args) > len(decls):
            raise SpecError(f"{self.name}: takes at most {len(decls)} positional values, "
                            f"got {len(args)}")
        given = dict(zip((d.name for d in decls), args))
        for key, value in kwargs.items():
            decl = self.declaration(key)
            if decl.name in given:
                raise SpecError(f"{self.name}: {decl.name} is given twice")
            given[decl.name] = value
        values = {}
        for decl in decls:
            where = self.name
            if decl.name in given:
                values[decl.name] = decl.coerce(given[decl.name], where)
            elif decl.default is not None:
                values[decl.name] = decl.coerce(decl.default, where)
        self._values = values
        _ = self.channels  # per-channel parameters, nested ones included, must agree
        self._check()

    #: ``admissible(q, nch) -> bool`` for a family that refuses some values inside its
    #: parameters' bounds (see :meth:`_check`), given its packed block ``q``; None otherwise.
    admissible = None

    def _check(self):
        """Cross-parameter validation; families override it (e.g. channel counts)."""

    @classmethod
    def declaration(cls, key):
        """The declaration named ``key`` (or one of its aliases)."""
        for decl in cls.PARAMS:
            if key == decl.name or key in decl.aliases:
                return decl
        names = ", ".join(d.name for d in cls.PARAMS) or "none"
        raise SpecError(f"{cls.name}: unknown parameter {key!r}; parameters: {names}")

    @property
    def values(self):
        """Parameter values as given or defaulted: arrays, choice strings or components."""
        return dict(self._values)

    def __getitem__(self, name):
        return self._values[self.declaration(name).name]

    def get(self, name, default=None):
        decl = self.declaration(name)
        return self._values.get(decl.name, default)

    def replace(self, **changes):
        """A copy with some parameter values changed (validated like a new instance)."""
        merged = {k: v for k, v in self._values.items()}
        for key, value in changes.items():
            merged[self.declaration(key).name] = value
        return type(self)(**merged)

    @property
    def channels(self):
        """Number of channels the per-channel parameters hold (1 when all are scalar)."""
        counts = {1}
        for decl in self.PARAMS:
            value = self._values.get(decl.name)
            if isinstance(value, Component):
                counts.add(value.channels)
            elif isinstance(decl, Param) and value is not None and value.ndim == 1:
                counts.add(value.size)
        counts.discard(1)
        if len(counts) > 1:
            raise ParameterError(f"{self.name}: per-channel parameters disagree on the number of "
                                 f"channels ({', '.join(map(str, sorted(counts)))})")
        return counts.pop() if counts else 1

    def __str__(self):
        parts = []
        for decl in self.PARAMS:
            if decl.name not in self._values:
                continue
            value = self._values[decl.name]
            if isinstance(value, Component):
                text = str(value)
                if text == decl.default:
                    continue  # options left at their defaults keep specs short
            elif isinstance(value, str):
                text = value
                if text == decl.default:
                    continue
            else:
                text = _fmt(value)
            parts.append(f"{decl.name}={text}")
        return f"{self.name}({', '.join(parts)})" if parts else self.name

    def __repr__(self):
        return f"brdf.parse({str(self)!r})"

    def __eq__(self, other):
        if type(self) is not type(other) or self._values.keys() != other._values.keys():
            return False
        for key, value in self._values.items():
            theirs = other._values[key]
            if isinstance(value, np.ndarray):
                if not (isinstance(theirs, np.ndarray) and value.shape == theirs.shape
                        and np.array_equal(value, theirs)):
                    return False
            elif value != theirs:
                return False
        return True

    __hash__ = None

    def to_dict(self):
        """JSON-ready description: ``{"model": name, "params": {...}}``."""
        params = {}
        for key, value in self._values.items():
            if isinstance(value, Component):
                params[key] = value.to_dict()
            elif isinstance(value, np.ndarray):
                params[key] = value.tolist()
            else:
                params[key] = value
        return {"model": self.name, "params": params}

    def flat(self, prefix=""):
        """Numeric parameters under flat names (``"alpha"``, ``"albedo[1]"``, ``"fresnel.f0"``)."""
        out = {}
        for decl in self.PARAMS:
            value = self._values.get(decl.name)
            if isinstance(value, Component):
                out.update(value.flat(f"{prefix}{decl.name}."))
            elif isinstance(decl, Param) and value is not None:
                if value.ndim == 0:
                    out[f"{prefix}{decl.name}"] = float(value)
                else:
                    out.update({f"{prefix}{decl.name}[{i}]": float(v)
                                for i, v in enumerate(value)})
        return out

    def layout(self, nch):
        """The flat float64 block this family's kernels read (declaration order), with the map
        from each numeric parameter to its positions in it (:class:`Layout`).

        A per-channel parameter packs ``nch`` floats, a scalar one, a choice its index, a
        nested component (a Fresnel term) its own block. An unset parameter packs the value of
        the one it falls back to (GGX's ``alpha_y`` -> ``alpha``), so the positions it fills
        belong to that one: moving ``alpha`` moves both."""
        layout = Layout()
        for decl in self.PARAMS:
            value, owner = self._values.get(decl.name), decl.name
            if value is None and isinstance(decl, Param):
                owner = decl.fallback
                value = self._values[owner]
            layout.append(decl, owner, value, nch)
        return layout

    def pack(self, nch):
        """Flat float64 parameter block read by this family's kernels (see :meth:`layout`)."""
        return self.layout(nch).values


class Layout:
    """A component's packed parameter block: ``values`` (floats) and ``slots``, a dict from a
    numeric parameter's name (``"alpha"``, nested ones as ``"fresnel.f0"``) to one list of
    positions in ``values`` per channel (a per-channel parameter) or a single list (a scalar
    one)."""

    __slots__ = ("values", "slots")

    def __init__(self):
        self.values, self.slots = [], {}

    def claim(self, name, positions):
        """Give ``name`` the positions ``positions[c]`` of each of its entries ``c`` (a
        parameter filling a fallback's slots adds to that one's)."""
        have = self.slots.setdefault(name, [[] for _ in positions])
        for entry, more in zip(have, positions):
            entry.extend(more)

    def append(self, decl, owner, value, nch):
        """Pack parameter ``decl`` holding ``value`` whose positions belong to ``owner``."""
        at = len(self.values)
        if isinstance(decl, Choice):
            self.values.append(float(decl.choices.index(value)))
        elif isinstance(value, Component):
            inner = value.layout(nch)
            self.values.extend(inner.values)
            for name, positions in inner.slots.items():
                self.claim(f"{decl.name}.{name}", [[at + k for k in p] for p in positions])
        elif decl.per_channel:
            self.values.extend(np.broadcast_to(value, (nch,)).astype(float).tolist())
            self.claim(owner, [[at + c] for c in range(nch)])
        else:
            self.values.append(float(value))
            self.claim(owner, [[at]])

    def pad(self, n):
        """``n`` zeros no parameter owns."""
        self.values.extend([0.0] * n)


class Compiled:
    """What the kernels see of a model: lobe kinds, parameter offsets, packed parameters, and
    where each lobe's parameters sit among them.

    ``slots[l][name]`` lists, per entry of lobe l's parameter ``name`` (one per channel, or a
    single one for a scalar parameter), its positions in ``params`` (see :class:`Layout`)."""

    __slots__ = ("kinds", "offsets", "params", "nch", "slots")

    def __init__(self, kinds, layouts, nch):
        self.kinds = np.asarray(kinds, dtype=np.int64)
        self.offsets = np.concatenate([[0], np.cumsum([len(b.values) for b in layouts])]
                                      ).astype(np.int64)
        self.params = np.asarray([v for b in layouts for v in b.values], dtype=np.float64)
        self.nch = int(nch)
        self.slots = tuple({name: [np.sort(np.asarray(p, dtype=np.int64)) + offset for p in positions]
                            for name, positions in b.slots.items()}
                           for b, offset in zip(layouts, self.offsets))

    @property
    def args(self):
        """What the array drivers of ``_kernels`` take: the kinds typed with the model's family
        set (``_kernels.family_kinds``: the kernels compile for those families alone), the
        offsets, the packed parameters and the channel count."""
        from ._kernels import family_kinds
        return family_kinds(self.kinds), self.offsets, self.params, self.nch


def gauss_legendre_unit(n):
    """Nodes and weights of the n-point Gauss-Legendre rule on [0, 1]."""
    x, w = np.polynomial.legendre.leggauss(n)
    return 0.5 * (x + 1.0), 0.5 * w


#: Panel rules of the albedo cubature: 6-point Gauss-Legendre and the embedded 3-point estimate.
GAUSS_RULES = (*gauss_legendre_unit(6), *gauss_legendre_unit(3))
#: What the albedo kernel takes: those rules, then a panel's corners as the nodes of a 2 x 2
#: "rule" (just inside it, as samplers map the square's edges onto the horizon; an argument,
#: not a global constant, whose read-only type would compile the panel kernel twice)
_KERNEL_RULES = (*GAUSS_RULES, np.array([1e-9, 1.0 - 1e-9]))
#: Panels the albedo cubature starts from (``_kernels._refine``: a 4 x 4 grid): the least
#: ``max_panels`` its arrays can hold.
_INITIAL_PANELS = 16
#: The most ``max_panels`` accepted: each thread allocates (4 + 2 C) * 8 bytes per panel
#: (80 MB at a million panels and 3 channels), and a million panels (49 million samples for
#: one direction) is far beyond what any tolerance needs.
MAX_PANELS = 1 << 20


class Model(Component):
    """A BRDF: ``eval``, ``sample``, ``pdf`` and ``albedo`` over arrays of directions.

    Subclasses are lobe families; they set ``name``, ``PARAMS``, ``citation`` and the ``kind``
    their kernels are dispatched on. Directions are unit vectors in the local shading frame
    (z = normal) shaped ``(..., 3)``, both pointing away from the surface.
    """

    kind = -1
    #: True for families that conserve energy for every valid parameter value.
    energy_conserving = True
    #: True for families that obey Helmholtz reciprocity.
    reciprocal = True
    #: True for delta lobes (eval is 0; all the energy is in ``sample``).
    delta = False
    #: True when f(M wi, M wo) = f(wi, wo) for the mirrors M = diag(-1, 1, 1) and diag(1, -1, 1):
    #: then a(M wi) = a(wi) (substitute M wo in the albedo integral), and ``albedo`` integrates
    #: mirror-image incident directions once. Families that depend on x and y only through x^2,
    #: y^2, products wi_x wo_x, wi_y wo_y, or rotation-invariant terms set it.
    mirror_symmetric = False
    #: How the fitter's data-driven start treats this family (:class:`Start`).
    START = Start()

    # -- composition ---------------------------------------------------------------------------
    def __add__(self, other):
        if not isinstance(other, Model):
            return NotImplemented
        return Sum(list(self.lobes) + list(other.lobes))

    @property
    def lobes(self):
        """The lobes of this model (itself for a single lobe)."""
        return (self,)

    @property
    def params(self):
        """Every numeric parameter under its flat ``"lobe.param"`` name."""
        return {f"{self.name}.{k}": v for k, v in self.flat().items()}

    @property
    def is_anisotropic(self):
        """True when an optional parameter (``alpha_y``, ``nv``) differs from the one it falls
        back to: the lobe then depends on the azimuth of wi (tables answer the same name)."""
        return any(isinstance(d, Param) and d.fallback and d.name in self._values
                   and not np.array_equal(self._values[d.name], self._values[d.fallback])
                   for d in self.PARAMS)

    @property
    def uses_kernels(self):
        """True when every lobe is a built-in family with compiled kernels (``kind`` >= 0); a
        model with a numpy-written lobe (:class:`~brdf.models.custom.CustomModel`) is evaluated
        by :mod:`brdf.models.mixed` instead."""
        return all(lobe.kind >= 0 for lobe in self.lobes)

    def compile(self, nch=None):
        """Kernel representation of this model with ``nch`` channels (default: its own)."""
        if nch is None:
            nch = self.channels
        else:  # the kernels index nch channels of every per-channel block they are given
            nch = integer(nch, "compile: nch", 1)
            if self.channels not in (1, nch):
                raise InputError(f"compile: nch={nch} but {self} has {self.channels} channels;"
                                 " expected nch equal to it (or a 1-channel model)")
        return Compiled([lobe.kind for lobe in self.lobes],
                        [lobe.layout(nch) for lobe in self.lobes], nch)

    def _compiled(self):
        cached = self.__dict__.get("_compiled_cache")
        if cached is None:
            cached = self.compile()
            self.__dict__["_compiled_cache"] = cached
        return cached

    # -- evaluation ----------------------------------------------------------------------------
    def eval(self, wi, wo, out=None):
        """BRDF value f_r(wi, wo) in 1/sr without the cosine, shaped ``(..., C)``.

        ``out``, if given, is a C-contiguous float64 array of that shape that receives the
        values and is returned (as numpy's ``out=``). Without it, a result of
        :data:`brdf.memory.POOL_MIN` bytes or more takes the memory of one dropped before
        (:func:`brdf.memory.empty`): a fresh array's first writes fault its pages in, which
        took as long as the evaluation itself for a MERL-size batch."""
        if not self.uses_kernels:
            from . import mixed
            return _filled(out, mixed.eval(self, wi, wo), wi, wo)
        from . import _kernels
        given = wi, wo
        wi, wo, shape = flat_pairs(wi, wo, screen=False)  # the kernel screens the lengths
        c = self._compiled()
        res = _result(out, shape + (c.nch,), wi, wo)
        if _kernels.eval_array(*c.args, wi, wo, res.reshape(-1, c.nch), *UNIT_SQ):
            direction_array(given[0], "wi")  # raise, naming the first row refused
            direction_array(given[1], "wo")
        return res

    def pdf(self, wi, wo, out=None):
        """Solid-angle density of :meth:`sample` at ``wo``, shaped ``(...)``; ``out`` as in
        :meth:`eval`."""
        if not self.uses_kernels:
            from . import mixed
            return _filled(out, mixed.pdf(self, wi, wo), wi, wo)
        from . import _kernels
        wi, wo, shape = flat_pairs(wi, wo)
        res = _result(out, shape, wi, wo)
        _kernels.pdf_array(*self._compiled().args, wi, wo, res.reshape(-1))
        return res

    def sample(self, wi, u):
        """Draw ``wo`` for each ``wi`` from uniform numbers ``u`` shaped ``(..., 2)``.

        Returns ``(wo, pdf)``; ``pdf`` is 0 where the sample is invalid (below the horizon) and
        ``inf`` where a delta lobe was chosen.
        """
        wo, pdf, _ = self.sample_weighted(wi, u)
        return wo, pdf

    def sample_weighted(self, wi, u):
        """Like :meth:`sample`, also returning the weight ``f cos(theta_o) / pdf`` ``(..., C)``.

        For a delta lobe the weight is its reflectance divided by the probability of picking it.
        """
        wi, u, shape = sample_inputs(wi, u)
        if not self.uses_kernels:
            from . import mixed
            wo, pdf, weight = mixed.sample_weighted(self, wi, u)
            return (wo.reshape(shape + (3,)), pdf.reshape(shape),
                    weight.reshape(shape + (weight.shape[-1],)))
        from . import _kernels
        c = self._compiled()
        wo = np.empty_like(wi)
        pdf = np.empty(wi.shape[0])
        weight = np.empty((wi.shape[0], c.nch))
        _kernels.sample_array(*c.args, wi, u, wo, pdf, weight)
        return wo.reshape(shape + (3,)), pdf.reshape(shape), weight.reshape(shape + (c.nch,))

    def albedo(self, wi, tol=1e-5, return_error=False, max_panels=1024):
        """Directional albedo a(wi) = integral of f cos(theta_o) over the hemisphere, ``(..., C)``.

        Each lobe is integrated over the unit square of its own importance sampler (wo = warp(u),
        so the integrand is f cos / pdf and a sharp lobe is as easy as a broad one) by adaptive
        cubature: square panels with a 6 x 6 Gauss-Legendre rule and an embedded 3 x 3 one, the
        panel where they differ most split in four until the summed differences are below
        ``tol`` (relative to max(1, albedo)) or ``max_panels`` are used. Delta lobes are exact.
        For a :attr:`mirror_symmetric` model, incident directions that are mirror images of
        each other (equal up to the signs of x and y, to 1e-12) share one integral.

        Returns
        -------
        albedo : ndarray, shape (..., C)
        error : ndarray, shape (..., C)
            With ``return_error``: the summed panel error estimates, a conservative estimate of
            the absolute error.
        """
        tol, max_panels = cubature_options(tol, max_panels)
        if not self.uses_kernels:
            from . import mixed
            out, err = mixed.albedo(self, wi, tol, max_panels)
        else:
            out, err, _ = self._albedo_cubature(wi, tol, max_panels)
        return (out, err) if return_error else out

    @property
    def albedo_gradient_ready(self):
        """Whether :meth:`albedo_gradient` applies: every lobe has kernels, is not a delta
        lobe and integrates its albedo as one term."""
        from . import _kernels
        return self.uses_kernels and all(
            not _kernels.is_delta(lobe.kind) and _kernels.lobe_terms(lobe.kind) == 1
            for lobe in self.lobes)

    def albedo_gradient(self, wi, tol=1e-5, max_panels=1024, nch=None):
        """Directional albedo ``(..., C)`` and its derivatives ``(..., P, C)`` in the packed
        kernel parameters (``self.compile(nch).params``, P of them), from one cubature.

        The derivative of the albedo is the integral of df/dp cos(theta_o), evaluated with the
        families' analytic gradients (those fits use) on the panels :meth:`albedo` refines;
        for :attr:`albedo_gradient_ready` models. Energy-constrained fits take their
        constraint's Jacobian from it.
        """
        if not self.albedo_gradient_ready:
            raise InputError(f"albedo_gradient: {self} has a delta, multi-term or custom lobe; "
                             "differentiate its albedo numerically")
        cubature_options(tol, max_panels, "albedo_gradient")
        out, _, _, grad = self._albedo_cubature(wi, tol, max_panels, gradient=True, nch=nch)
        return out, grad

    def _albedo_cubature(self, wi, tol=1e-5, max_panels=1024, gradient=False, nch=None):
        """:meth:`albedo`, its error estimate, and the number of cubature panels spent on each
        direction (49 samples each; 0 where a mirror image's integral is shared): a measure of
        the work that machine load does not skew, for ``benchmarks/bench_check.py``. With
        ``gradient``, also the derivatives of :meth:`albedo_gradient`; ``nch`` channels
        (default: the model's own)."""
        from .._threads import thread_count
        from . import _kernels
        tol, max_panels = cubature_options(tol, max_panels)
        wi = direction_array(wi, "wi")
        shape = wi.shape[:-1]
        flat = wi.reshape(-1, 3)
        if self.mirror_symmetric:
            key = np.round(np.column_stack([np.abs(flat[:, :2]), flat[:, 2]]), 12)
            _, first, shared = np.unique(key, axis=0, return_index=True, return_inverse=True)
            shared = shared.reshape(-1)
        else:
            first = shared = np.arange(len(flat))
        # each thread gets a contiguous chunk of the directions: dealing them out like
        # cards gives every thread its share of the costly grazing ones, wherever they cluster
        deal = np.argsort(np.arange(len(first)) % thread_count(), kind="stable")
        c = self._compiled() if nch is None else self.compile(nch)
        n = len(first)
        dealt = (np.zeros((n, c.nch)), np.zeros((n, c.nch)), np.zeros(n, dtype=np.int64))
        grad = np.zeros((n, len(c.params), c.nch)) if gradient else None
        _kernels.albedo_array(*c.args, np.ascontiguousarray(flat[first[deal]]), _KERNEL_RULES,
                              tol, max_panels, *dealt, grad)
        out, err, panels = (np.empty_like(a) for a in dealt)
        for mine, theirs in zip((out, err, panels), dealt):
            mine[deal] = theirs
        work = np.zeros(len(flat), dtype=np.int64)
        work[first] = panels
        result = (out[shared].reshape(shape + (c.nch,)), err[shared].reshape(shape + (c.nch,)),
                  work.reshape(shape))
        if not gradient:
            return result
        mine = np.empty_like(grad)
        mine[deal] = grad
        return result + (mine[shared].reshape(shape + grad.shape[1:]),)


def _result(out, shape, *inputs):
    """The array a result of ``shape`` is written to: a new one (:func:`brdf.memory.empty`,
    which reuses the blocks of results dropped before), or ``out`` once it is checked
    (InputError naming ``out``): float64, C-contiguous (the kernels write its rows in
    place), writable, of ``shape``, and sharing no memory with the ``inputs`` the kernel
    reads while it writes."""
    if out is None:
        return memory.empty(shape)
    if not isinstance(out, np.ndarray):
        raise InputError(f"out: expected a float64 numpy array shaped {shape}, got "
                         f"{type(out).__name__}")
    if out.dtype != np.float64 or out.shape != shape:
        raise InputError(f"out: expected a float64 array shaped {shape}, got {out.dtype} "
                         f"shaped {out.shape}")
    if not (out.flags.c_contiguous and out.flags.writeable):
        raise InputError("out: expected a writable C-contiguous array (np.empty makes one); "
                         "got a read-only or strided one")
    if any(np.may_share_memory(out, a) for a in inputs):
        raise InputError("out: shares memory with wi or wo; expected an array of its own")
    return out


def _filled(out, values, *inputs):
    """``values``, a result computed in numpy, delivered as :func:`_result` would: ``values``
    itself without ``out``, else copied into ``out`` once it is checked."""
    if out is None:
        return values
    res = _result(out, values.shape, *inputs)
    res[...] = values
    return res


def sample_inputs(wi, u):
    """Validated ``wi`` and uniform numbers ``u`` broadcast together and flattened:
    ``(wi (n, 3), u (n, 2), shape)``."""
    wi = direction_array(wi, "wi")
    u = uniform_array(u, "u")
    shape = broadcast_shape(wi, u, "wi", "u")
    wi = np.ascontiguousarray(np.broadcast_to(wi, shape + (3,)).reshape(-1, 3))
    u = np.ascontiguousarray(np.broadcast_to(u, shape + (2,)).reshape(-1, 2))
    return wi, u, shape


def cubature_options(tol, max_panels, what="albedo"):
    """``(tol, max_panels)`` of an albedo cubature, checked: the kernel starts from
    :data:`_INITIAL_PANELS` panels in arrays of ``max_panels`` rows and does not check their
    bounds, so fewer rows would be written past."""
    tol = real(tol, f"{what}: tol", 0.0, low_open=True)
    max_panels = integer(max_panels, f"{what}: max_panels", _INITIAL_PANELS, MAX_PANELS)
    return tol, max_panels


class Sum(Model):
    """An additive mixture of lobes; sampling picks a lobe in proportion to its albedo estimate."""

    name = "sum"

    def __init__(self, lobes):
        lobes = list(lobes)
        if not lobes or not all(isinstance(lobe, Model) and not isinstance(lobe, Sum)
                                for lobe in lobes):
            raise SpecError("a sum needs one or more lobes")
        self._lobes = tuple(lobes)
        self._values = {}
        _ = self.channels  # validates that channel counts agree

    @property
    def lobes(self):
        return self._lobes

    @property
    def channels(self):
        counts = {lobe.channels for lobe in self._lobes} - {1}
        if len(counts) > 1:
            raise ParameterError("lobes of a sum disagree on the number of channels "
                                 f"({', '.join(map(str, sorted(counts)))})")
        return counts.pop() if counts else 1

    # a sum of energy-conserving lobes can still reflect more than it receives (lambert(1) + ggx)
    energy_conserving = property(lambda self: len(self._lobes) == 1
                                 and self._lobes[0].energy_conserving)
    reciprocal = property(lambda self: all(l.reciprocal for l in self._lobes))
    delta = property(lambda self: all(l.delta for l in self._lobes))
    mirror_symmetric = property(lambda self: all(l.mirror_symmetric for l in self._lobes))
    is_anisotropic = property(lambda self: any(l.is_anisotropic for l in self._lobes))

    def lobe_names(self):
        """Flat-name prefix of each lobe: its name, or name and index when a name repeats."""
        names = [lobe.name for lobe in self._lobes]
        return [n if names.count(n) == 1 else f"{n}{i}" for i, n in enumerate(names)]

    @property
    def params(self):
        out = {}
        for prefix, lobe in zip(self.lobe_names(), self._lobes):
            out.update({f"{prefix}.{k}": v for k, v in lobe.flat().items()})
        return out

    def __str__(self):
        return " + ".join(str(lobe) for lobe in self._lobes)

    def __eq__(self, other):
        return isinstance(other, Sum) and self._lobes == other._lobes

    __hash__ = None

    def to_dict(self):
        return {"sum": [lobe.to_dict() for lobe in self._lobes]}

    def replace(self, **changes):
        raise SpecError("replace() works on single lobes; rebuild the sum from its lobes")


