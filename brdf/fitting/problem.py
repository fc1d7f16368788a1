"""The fitting problem: a vector x of free parameters -> a model -> the loss on a table.

:class:`Problem` takes a spec and a table and decides what is free: every numeric parameter the
spec's model holds (given or defaulted; optional ones left unset stay tied to the parameter
they fall back to), minus the fixed ones. A per-channel parameter (an albedo) gets one free
value per channel of the table, or one for all channels when listed in ``shared``. Bounds come
from the declarations (``fit_bounds``, a finite box inside ``bounds``), optionally narrowed; a
parameter declared with a log prior (roughness, exponents) is optimised as its logarithm, so
that a step means the same relative change at 0.01 as at 1.

The loss runs in one compiled pass over the samples for several parameter vectors at once
(:meth:`Problem.channel_losses`): the samples are read once per block while every model
variant is evaluated and scored, and per-block partial sums are added in a fixed order, so the
value does not depend on the number of threads. The gradient is analytic, in the same kind of
pass (:meth:`Problem.loss_and_gradient`): each family's kernel gives f with its derivatives in
the packed parameters, and the chain rule runs through the loss terms and the x -> parameter map.
"""

import math
import re
from dataclasses import dataclass

import numpy as np

from .._jit import (AS_LOWERED, fetch_add, inline_kernel, kernel, narrow_vectors, nogil_kernel,
                     share_queue, sparse_product)
from ..errors import InputError, ParameterError
from ..models import _kinds as K
from ..models._kernels import (family_namespace, lobe_derivatives, lobe_eval_block,
                                lobe_grad_rows, rows_dispatcher, specialising, stack_array,
                                with_last_axis)
from ..models.base import Component, Param, Sum
from . import losses

__all__ = ["Problem", "FreeParameter", "STEP", "resolve_name", "parameter_names", "names_apply"]

#: Relative step of the central differences: it balances the truncation error (~h^2) against
#: rounding (~eps / h), h = eps^(1/3) (Nocedal & Wright 2006, Numerical Optimization, 8.1).
STEP = np.finfo(float).eps ** (1.0 / 3.0)
#: Samples per block of the compiled loss: the block's directions and terms stay in cache while
#: every parameter vector of a batch is evaluated on it.
BLOCK = 2048
#: Samples per block of the loss-and-gradient pass, at most: its block of derivatives
#: (parameters x samples x channels) stays in cache (lambert + ggx, RGB: 16 x 512 x 3 doubles,
#: 196 kB). Models with more parameters or channels take fewer samples per block, down to
#: MIN_GRADIENT_BLOCK (a 31-channel lambert + ggx packs 128 parameters: 8 samples).
GRADIENT_BLOCK = 512
GRADIENT_BLOCK_BYTES = 16 * GRADIENT_BLOCK * 3 * 8
MIN_GRADIENT_BLOCK = 8
#: Blocks of the loss-and-gradient pass per group sharing work arrays (zeroed once per group).
GRADIENT_GROUP = 16
_INDEXED = re.compile(r"^(?P<base>.+)\[(?P<index>\d+)\]$")


@dataclass(frozen=True)
class FreeParameter:
    """One coordinate of x.

    Attributes
    ----------
    name : str
        Flat name (``"ggx.alpha"``, ``"lambert.albedo[1]"``; no index when shared).
    declared : str
        Flat name of the declaration (``"lambert.albedo"``).
    channel : int or None
        The one channel this coordinate affects, or None for all of them.
    log : bool
        Whether x holds the logarithm of the value (declared prior ``log``).
    lower, upper : float
        Bounds of the value (not of its logarithm).
    slots : ndarray of int
        Positions in the packed parameter array the kernels read (a parameter another one
        falls back to fills both).
    """

    name: str
    declared: str
    channel: object
    log: bool
    lower: float
    upper: float
    slots: np.ndarray

    def to_x(self, value):
        return math.log(value) if self.log else float(value)

    def from_x(self, x):
        return np.exp(x) if self.log else x


@dataclass
class _Declared:
    """A numeric parameter of the spec's model: its place, declaration and working value."""

    name: str
    lobe: int
    path: tuple
    decl: Param
    value: np.ndarray
    fixed: np.ndarray
    box: tuple = None


def _numeric(component, path=()):
    """``(path, declaration, value)`` of each numeric parameter a component holds, nested
    components (Fresnel terms) included."""
    values = component.values
    for decl in component.PARAMS:
        value = values.get(decl.name)
        if isinstance(value, Component):
            yield from _numeric(value, path + (decl.name,))
        elif isinstance(decl, Param) and value is not None:
            yield path + (decl.name,), decl, value


def _replace_path(component, path, value):
    """A copy of ``component`` with the parameter at ``path`` (nested names) set to ``value``."""
    if len(path) == 1:
        return component.replace(**{path[0]: value})
    return component.replace(**{path[0]: _replace_path(component[path[0]], path[1:], value)})


def _declarations(model):
    """``(flat name, lobe index, path, declaration, value)`` of every numeric parameter."""
    from ..models.base import Sum
    lobes = model.lobes
    prefixes = model.lobe_names() if isinstance(model, Sum) else [model.name]
    for l, (prefix, lobe) in enumerate(zip(prefixes, lobes)):
        for path, decl, value in _numeric(lobe):
            yield f"{prefix}.{'.'.join(path)}", l, path, decl, value


def parameter_names(model):
    """Flat names (without channel indices) of a model's numeric parameters, as fits name
    them: ``("lambert.albedo", "ggx.ks", "ggx.alpha", ...)``."""
    return tuple(d[0] for d in _declarations(model))


def names_apply(name, names):
    """Whether ``--shared``/``--fix`` name ``name`` (indexed or not) refers to one of
    ``names``; an ambiguous name is an error as in :func:`resolve_name`."""
    m = _INDEXED.match(name)
    base = m["base"] if m else name
    try:
        resolve_name(base, names, "")
    except InputError as exc:
        if "ambiguous" in str(exc):
            raise
        return False
    return True


def resolve_name(name, names, what):
    """The declared name ``name`` refers to: itself, or the unique declared name ending in
    ``.name`` (``alpha`` for ``ggx.alpha``). Raises InputError listing ``names`` otherwise."""
    if name in names:
        return name
    matches = [n for n in names if n.endswith("." + name)]
    if len(matches) == 1:
        return matches[0]
    why = f"ambiguous ({', '.join(matches)})" if matches else "unknown parameter"
    raise InputError(f"{what}: {why} {name!r}; parameters: {', '.join(names)} (per-channel "
                     f"ones also as NAME[i])")


class Problem:
    """Fitting ``spec`` to ``data``: parameter vectors to models, losses and gradients.

    Parameters
    ----------
    data : Table, losses.Samples or object with ``wi``, ``wo``, ``values``
    spec : str or Model
        The model; its parameter values are the starting point.
    loss : str
        A metric of :data:`brdf.fitting.losses.LOSSES`.
    cutoff : float
        Grazing cutoff in degrees (see :func:`brdf.fitting.losses.prepare`).
    shared : sequence of str
        Per-channel parameters fitted as one value for all channels (``"ggx.ks"``, or
        ``"ks"`` when unique). Naming a scalar parameter is allowed and changes nothing.
    fix : dict, optional
        ``{name: value}`` held fixed: a declared name fixes every channel, ``NAME[i]`` one.
    bounds : dict, optional
        ``{name: (lower, upper)}`` narrowing the declared box (within the declared bounds).

    Notes
    -----
    :meth:`gradient` is analytic. One compiled pass (:func:`_loss_gradient_sums`) evaluates f
    with its derivatives df/dq_j in every packed parameter q_j (each family's ``grad_`` kernel,
    see brdf.models._kernels), turns the residuals into dL/df (see :class:`~brdf.fitting.losses.
    Terms`) and sums dL/dq_j = sum_k sum_c dL/df_kc df_kc/dq_j in blocks; then dL/dx_i adds the
    q_j that coordinate i fills (a shared parameter fills every channel's slot, an unset
    ``alpha_y`` mirrors ``alpha``) times dq/dx (q for a log-scaled parameter, 1 otherwise).
    A gradient costs about one evaluation of the loss.

    :meth:`difference_rows` and :meth:`difference_jacobian` remain for quantities without
    analytic derivatives (the albedo integrals of the energy constraint): for each group of
    coordinates, x is moved up and down by h = ``step`` max(1, |x|) (kept inside the bounds, the
    step then shrinks on that side). The model's channels are independent (a channel's value
    depends on that channel's entry of a per-channel parameter and on the scalar ones), so the
    channel entries of one per-channel parameter are moved together and told apart by the
    per-channel outputs: 2 G + 1 evaluations for G groups, not 2 n + 1.
    """

    def __init__(self, data, spec, *, loss="cosine-l2", cutoff=losses.DEFAULT_CUTOFF, shared=(),
                 fix=None, bounds=None):
        from ..spec import parse
        losses.check_loss(loss)
        self.samples = data if isinstance(data, losses.Samples) else losses.prepare(data, cutoff)
        self.loss_name = loss
        self.channels = nch = self.samples.channels
        model = parse(spec)
        if model.channels not in (1, nch):
            raise InputError(f"the model has {model.channels} channels and the data {nch}")
        self._is_sum = isinstance(model, Sum)
        self._lobes = tuple(model.lobes)
        self._declared = self._declare(model, shared)
        self._apply_fix(fix or {})
        self._apply_bounds(bounds or {})
        self.base = self._build({})
        compiled = self.base.compile(nch)
        self._kinds, self._offsets, self._packed = compiled.kinds, compiled.offsets, compiled.params
        self._family_kinds = compiled.args[0]  # the kernels compile for the model's families
        self._slots = compiled.slots
        self._admissible = [(type(lobe).admissible, a, b) for lobe, a, b in
                            zip(self.base.lobes, self._offsets[:-1], self._offsets[1:])
                            if type(lobe).admissible is not None]
        self.free = tuple(self._free_parameters())
        self.names = tuple(p.name for p in self.free)
        self.lower = np.array([p.to_x(p.lower) for p in self.free])
        self.upper = np.array([p.to_x(p.upper) for p in self.free])
        self.x0 = np.array([p.to_x(np.clip(self._value_of(p), p.lower, p.upper))
                            for p in self.free])
        self._groups = self._difference_groups()
        self._needed = np.zeros(len(self._packed), dtype=np.bool_)
        for p in self.free:
            self._needed[p.slots] = True
        # the one channel each packed entry acts on (an entry of a per-channel parameter: the
        # model's channels are independent, see the class notes), or -1
        self._chan = np.full(len(self._packed), -1, dtype=np.int64)
        for lobe in self._slots:
            for positions in lobe.values():
                if len(positions) == nch > 1:
                    for c, slots in enumerate(positions):
                        self._chan[slots] = c
        # the one lobe besides Lambertian ones whose derivatives the pass folds into its sums
        # row by row (see _fold_blocks), or -1
        others = [l for l, kind in enumerate(self._kinds) if kind != K.LAMBERT]
        self._fold_lobe = others[0] if (nch == 3 and len(others) == 1 and self._offsets[
            others[0] + 1] - self._offsets[others[0]] <= SLOTS) else -1
        per_sample = 8 * len(self._packed) * nch
        self._gradient_block = int(np.clip(GRADIENT_BLOCK_BYTES // per_sample,
                                           MIN_GRADIENT_BLOCK, GRADIENT_BLOCK))
        self.terms = losses.terms(loss, self.samples, len(self.free))

    def restricted(self, samples):
        """This problem on other samples (a subsample of its own, :func:`brdf.fitting.starts.
        subsample`): the same free parameters, bounds and x -> model map; the loss's terms
        recomputed on ``samples``."""
        import copy
        if samples is self.samples:
            return self
        other = copy.copy(self)
        other.samples = samples
        other.terms = losses.terms(self.loss_name, samples, len(self.free))
        return other

    # -- what is free --------------------------------------------------------------------------
    def _declare(self, model, shared):
        declared = [_Declared(name, l, path, decl, np.asarray(value, dtype=float), None)
                    for name, l, path, decl, value in _declarations(model)]
        names = [d.name for d in declared]
        shared_names = {resolve_name(s, names, "shared") for s in shared}
        self.shared = tuple(n for n in names if n in shared_names)
        for d in declared:
            if d.decl.per_channel and d.name not in shared_names and self.channels > 1:
                d.value = np.broadcast_to(d.value, (self.channels,)).copy()
            else:
                d.value = np.asarray(d.value.mean())
            d.fixed = np.zeros(d.value.shape, dtype=bool)
        return declared

    def _lookup(self, name, what):
        """``(declared, channel or None)`` for a flat name, indexed or not."""
        names = [d.name for d in self._declared]
        m = _INDEXED.match(name)
        base, index = (m["base"], int(m["index"])) if m else (name, None)
        d = self._declared[names.index(resolve_name(base, names, what))]
        if index is not None and (d.value.ndim == 0 or index >= d.value.size):
            detail = ("is shared or scalar: name it without an index" if d.value.ndim == 0
                      else f"has channels 0 to {d.value.size - 1}")
            raise InputError(f"{what}: {name!r}: {d.name} {detail}")
        return d, index

    def _apply_fix(self, fix):
        for name, value in fix.items():
            d, index = self._lookup(name, "fix")
            v = np.asarray(value, dtype=float)
            target = d.value if index is None else d.value[index:index + 1]
            if v.size not in (1, target.size) or not np.all(np.isfinite(v)):
                raise InputError(f"fix {name}: expected a finite number or {target.size} "
                                 f"numbers, got {value!r}")
            lo, hi = d.decl.bounds
            if np.any(v < lo) or np.any(v > hi):
                raise ParameterError(f"fix {name}={value}: outside the bounds [{lo:g}, {hi:g}] "
                                     f"of {d.name}")
            target[...] = v.reshape(target.shape) if v.size == target.size else v.reshape(())
            (d.fixed if index is None else d.fixed[index:index + 1])[...] = True

    def _apply_bounds(self, bounds):
        for d in self._declared:
            lo, hi = d.decl.bounds
            flo, fhi = d.decl.fit_bounds
            d.box = (max(lo, flo), min(hi, fhi))
        for name, box in bounds.items():
            d, index = self._lookup(name, "bounds")
            if index is not None:
                raise InputError(f"bounds {name}: give bounds for {d.name} as a whole")
            try:
                lo, hi = (float(b) for b in box)
            except (TypeError, ValueError):
                raise InputError(f"bounds {name}: expected (lower, upper), got {box!r}") from None
            dlo, dhi = d.decl.bounds
            if not (math.isfinite(lo) and math.isfinite(hi) and dlo <= lo < hi <= dhi):
                raise InputError(f"bounds {name}: [{lo:g}, {hi:g}] must be finite with lower < "
                                 f"upper, inside the declared [{dlo:g}, {dhi:g}] (fix equal "
                                 "values with fix=)")
            d.box = (lo, hi)
        for d in self._declared:
            if not all(math.isfinite(b) for b in d.box) or (d.decl.prior == "log"
                                                              and d.box[0] <= 0.0):
                raise InputError(f"{d.name}: no finite fitting box (declared {d.box}); pass "
                                 f"bounds={{'{d.name}': (lower, upper)}}")

    def _free_parameters(self):
        for d in self._declared:
            if d.fixed.all():
                continue
            slots = self._locate(d)
            log = d.decl.prior == "log"
            if d.value.ndim == 0:
                yield FreeParameter(d.name, d.name, None, log, *d.box, slots[0])
            else:
                for c in np.flatnonzero(~d.fixed):
                    yield FreeParameter(f"{d.name}[{c}]", d.name, int(c), log, *d.box, slots[c])

    def _locate(self, d):
        """Positions in the packed array of each entry of ``d`` (one per channel, or one for a
        shared or scalar parameter), from the layout packing wrote (:class:`~brdf.models.base.
        Layout`): a parameter another one falls back to (``alpha`` for an unset ``alpha_y``)
        holds both positions."""
        positions = self._slots[d.lobe][".".join(d.path)]
        if d.value.ndim == 0:
            return [np.sort(np.concatenate(positions))]
        return positions

    def _difference_groups(self):
        """Coordinates moved together by the central differences: the channel entries of one
        per-channel parameter (each affects only its channel), every other coordinate alone."""
        groups = {}
        for i, p in enumerate(self.free):
            key = p.declared if p.channel is not None else p.name
            groups.setdefault(key, []).append(i)
        return [np.array(g) for g in groups.values()]

    def _value_of(self, p):
        d = next(d for d in self._declared if d.name == p.declared)
        return float(d.value if p.channel is None else d.value[p.channel])

    # -- x -> model ----------------------------------------------------------------------------
    def _build(self, values):
        """The model with each declared parameter at its value in ``values``, or else at its
        working value (starting, expanded or fixed), clipped into its declared bounds (which
        exp(log(upper)) may exceed by an ulp)."""
        lobes = list(self._lobes)
        for d in self._declared:
            v = np.clip(np.asarray(values.get(d.name, d.value), dtype=float), *d.decl.bounds)
            lobes[d.lobe] = _replace_path(lobes[d.lobe], d.path, v)
        return Sum(lobes) if self._is_sum else lobes[0]

    def values(self, x):
        """``{flat declared name: value}`` (scalar or per-channel array) at ``x``."""
        x = np.asarray(x, dtype=float)
        out = {d.name: d.value.copy() for d in self._declared}
        for xi, p in zip(x, self.free):
            v = float(p.from_x(xi))
            if p.channel is None:
                out[p.declared] = np.asarray(v)
            else:
                out[p.declared][p.channel] = v
        return out

    def model(self, x):
        """The model at parameter vector ``x``."""
        return self._build(self.values(x))

    def natural(self, x):
        """``{free name: value}`` at ``x`` (values, not their logarithms)."""
        return {p.name: float(p.from_x(xi)) for p, xi in zip(self.free, np.asarray(x, float))}

    def to_x(self, values):
        """The vector x of ``{free name: value}`` (names missing keep the starting value)."""
        return np.array([p.to_x(values[p.name]) if p.name in values else x0
                         for p, x0 in zip(self.free, self.x0)])

    def packed(self, X):
        """Packed parameter arrays ``(K, P)`` the kernels read, one row per row of ``X``."""
        X = np.atleast_2d(np.asarray(X, dtype=float))
        out = np.repeat(self._packed[None, :], len(X), axis=0)
        for i, p in enumerate(self.free):
            out[:, p.slots] = p.from_x(X[:, i])[:, None]
        return out

    def random_x(self, rng, n):
        """``n`` vectors drawn uniformly in the box of x (log-uniform for log parameters)."""
        return self.lower + (self.upper - self.lower) * rng.random((n, len(self.free)))

    # -- losses ----------------------------------------------------------------------------------
    def _refused(self, P):
        """Rows of packed parameters ``P`` (K, n) holding values a lobe's family refuses though
        they lie in the fit box (a Lafortune lobe whose peak overflows): no model exists there,
        so their loss is inf (and the posterior's density 0)."""
        return np.array([not all(ok(p[a:b], self.channels) for ok, a, b in self._admissible)
                         for p in P], dtype=bool)

    def channel_losses(self, X, terms=None):
        """Per-channel contributions ``(K, C)`` to the loss of each row of ``X`` (they sum to
        the loss), from one compiled pass over the samples; the lobes whose parameters are those
        of the first row are evaluated once. ``terms`` scores another metric than the loss."""
        P = self.packed(X)
        s, t = self.samples, terms or self.terms
        blocks = -(-len(s.wi) // BLOCK)
        lobes = np.array([np.any(P[:, a:b] != P[0, a:b], axis=1)
                          for a, b in zip(self._offsets[:-1], self._offsets[1:])]).T
        lobes = np.ascontiguousarray(lobes)  # one kernel type, C layout, for any lobe count
        out = np.zeros((blocks, len(P), self.channels))
        _loss_sums(self._family_kinds, self._offsets, P, lobes, self._fold_lobe, self.channels,
                   s.wi, s.wo, t.scale, t.target, t.weight, t.offset, BLOCK, out)
        losses = out.sum(axis=0) / t.norm
        if self._admissible:
            losses[self._refused(P)] = np.inf
        return losses

    def loss(self, x):
        """The loss at ``x``."""
        return float(self.channel_losses(x)[0].sum())

    def difference_rows(self, x, step=STEP):
        """The points of the central differences at ``x``: ``(rows, width)``.

        ``rows`` is ``(1 + 2 G, n)``: x, then for each group of coordinates moved together x
        with the group moved up and x with it moved down by h = ``step`` max(1, |x|), kept
        inside the bounds; ``width`` ``(n,)`` is each coordinate's distance between its two
        points. :meth:`difference_jacobian` turns outputs at these rows into derivatives.
        """
        x = np.asarray(x, dtype=float)
        h = step * np.maximum(1.0, np.abs(x))
        up, down = np.minimum(self.upper, x + h), np.maximum(self.lower, x - h)
        rows = [x]
        for g in self._groups:
            for side in (up, down):
                row = x.copy()
                row[g] = side[g]
                rows.append(row)
        return np.array(rows), up - down

    def difference_jacobian(self, outputs, width):
        """Derivatives ``(..., C, n)`` of per-channel outputs ``(1 + 2 G, ..., C)`` computed at
        :meth:`difference_rows` (a coordinate of one channel moves only that channel's outputs;
        its derivatives for the other channels are 0)."""
        outputs = np.asarray(outputs, dtype=float)
        jac = np.zeros(outputs.shape[1:] + (len(width),))
        for k, g in enumerate(self._groups):
            diff = outputs[1 + 2 * k] - outputs[2 + 2 * k]
            for i in g:
                c = self.free[i].channel
                if c is None:
                    jac[..., i] = diff / width[i]
                else:
                    jac[..., c, i] = diff[..., c] / width[i]
        return jac

    def loss_and_gradient(self, x, terms=None):
        """``(loss, gradient)`` at ``x``, the gradient analytic (see the class notes), from one
        compiled pass over the samples; ``terms`` scores another metric than the loss."""
        x = np.asarray(x, dtype=float)
        params = self.packed(x)[0]
        if self._admissible and self._refused(params[None])[0]:
            return math.inf, np.zeros(len(x))
        s, t = self.samples, terms or self.terms
        block = self._gradient_block
        blocks = -(-len(s.wi) // block)
        loss = np.zeros((blocks, self.channels))
        dq = np.zeros((blocks, len(params)))
        _loss_gradient_sums(self._family_kinds, self._offsets, params, self._needed,
                            self._chan, self._fold_lobe, self.channels, s.wi, s.wo, t.scale,
                            t.target, t.weight, t.offset, block, loss, dq)
        grad = self._in_x(dq.sum(axis=0) / t.norm, x)
        return float(loss.sum(axis=0).sum() / t.norm), grad

    def albedo_jacobian(self, x, wi):
        """Albedo ``(m, C)`` of the model at ``x`` in directions ``wi`` (m, 3) and its Jacobian
        ``(m, C, n)`` in x, analytic (:meth:`Model.albedo_gradient`); None for a model that is
        not :attr:`~brdf.models.base.Model.albedo_gradient_ready`."""
        model = self.model(x)
        if not model.albedo_gradient_ready:
            return None
        a, dq = model.albedo_gradient(wi, nch=self.channels)
        return a, self._in_x(dq, x, axis=1)

    def _in_x(self, dq, x, axis=-1):
        """Derivatives in x, on the last axis, of derivatives ``dq`` in the packed parameters
        (on ``axis``): summed over each free parameter's slots, times dq/dx = q for the
        log-scaled ones."""
        dq = np.moveaxis(np.asarray(dq), axis, -1)
        return np.stack([dq[..., p.slots].sum(axis=-1) * (p.from_x(xi) if p.log else 1.0)
                         for p, xi in zip(self.free, np.asarray(x, dtype=float))], axis=-1)

    def gradient(self, x):
        """Gradient of the loss at ``x`` (analytic, see the class notes)."""
        return self.loss_and_gradient(x)[1]

    def metrics(self, x):
        """Every metric of :data:`brdf.fitting.losses.LOSSES` the data allow, at ``x``: the
        model is evaluated once and each metric's terms score those values."""
        names = [n for n in losses.LOSSES if n != "chi-square" or self.samples.sigma is not None]
        f = self.model_values(x)
        out = {}
        for name in names:
            t = self.terms if name == self.loss_name else losses.terms(name, self.samples,
                                                                       len(self.free))
            out[name] = float(self.score(f, t).sum())
        return out

    def model_values(self, x):
        """The model's values ``(n, C)`` at the samples for parameter vector ``x``."""
        from ..models._kernels import eval_array
        s = self.samples
        f = np.empty(s.values.shape)
        eval_array(self._family_kinds, self._offsets, self.packed(x)[0], self.channels, s.wi,
                   s.wo, f, 0.0, np.inf)  # the samples' directions were screened when read
        return f

    @staticmethod
    def score(f, terms):
        """Per-channel loss ``(C,)`` of model values ``f`` under ``terms``."""
        sums = np.zeros((-(-len(f) // BLOCK), f.shape[1]))
        _score_sums(f, terms.scale, terms.target, terms.weight, terms.offset, BLOCK, sums)
        return sums.sum(axis=0) / terms.norm


def _loss_sums(kinds, offs, params, lobes, lobe, nch, wi, wo, scale, target, weight, offset,
               block, out):
    """``out[b, j, c]`` = sum over the samples k of block ``b`` of
    weight_k (g(scale_kc f_j(wi_k, wo_k)_c) - target_kc)^2, for each parameter row ``j``; g is
    the identity when ``offset`` is 0, else log(offset + .) (see brdf.fitting.losses.Terms).
    The blocks are shared out to threads (:func:`_sum_loss_blocks`)."""
    share_queue(_sum_loss_blocks, out.shape[0], kinds, offs, params, lobes, lobe, nch, wi, wo,
                scale, target, weight, offset, block, out)


@narrow_vectors
@nogil_kernel
def _sum_loss_blocks(kinds, offs, params, lobes, lobe, nch, wi, wo, scale, target, weight,
                     offset, block, out, queue):
    """:func:`_loss_sums` of the blocks this thread takes from the queue (``queue[0]``, the next
    block's number).

    With three channels, no logarithm and Lambertian lobes besides the one lobe ``lobe`` (>= 0),
    each row's f is folded into its terms as it comes (:func:`_fold_loss_blocks`). Otherwise a
    block's f is stored, then scored; a model is a sum of lobes, so row j > 0 evaluates only
    the lobes ``lobes[j]`` marks (those whose parameters differ from row 0's) and reuses row
    0's values of the others.
    """
    n = wi.shape[0]
    nl = kinds.shape[0]
    fold = nch == 3 and lobe >= 0 and offset == 0.0
    while True:
        b = fetch_add(queue, 1)
        if b >= out.shape[0]:
            return
        lo = b * block
        hi = min(n, lo + block)
        if fold:
            _fold_loss_blocks(kinds, offs, params, lobe, wi[lo:hi], wo[lo:hi], scale[lo:hi],
                              target[lo:hi], weight[lo:hi], out[b])
            continue
        base = np.zeros((nl, hi - lo, nch))
        f = np.empty((hi - lo, nch))
        for j in range(params.shape[0]):
            f[:, :] = 0.0
            for l in range(nl):
                own = j > 0 and lobes[j, l]
                if j == 0 or own:
                    # one call site: the block kernel is called once per lobe
                    dst = f if own else base[l]
                    lobe_eval_block(kinds[l], params[j, offs[l]:offs[l + 1]], nch, wi[lo:hi],
                                    wo[lo:hi], dst)
                if not own:
                    f += base[l]
            for c in range(nch):
                out[b, j, c] = _block_score(f, lo, hi, c, scale, target, weight, offset)


@inline_kernel
def _block_score(f, lo, hi, c, scale, target, weight, offset):
    """Sum over samples k in [lo, hi) of weight_k (g(scale_kc f_c) - target_kc)^2, with the block's
    values ``f[k - lo, c]`` and g as in :func:`_loss_sums` (brdf.fitting.losses.Terms)."""
    acc = 0.0
    if offset > 0.0:
        for k in range(lo, hi):
            r = math.log(offset + scale[k, c] * f[k - lo, c]) - target[k, c]
            acc += weight[k] * r * r
    else:
        for k in range(lo, hi):
            r = scale[k, c] * f[k - lo, c] - target[k, c]
            acc += weight[k] * r * r
    return acc


def _score_sums(f, scale, target, weight, offset, block, out):
    """``out[b, c]``: the terms' sum over block b of model values ``f`` (n, C) computed before
    (the blocks shared out to threads, :func:`_sum_score_blocks`)."""
    share_queue(_sum_score_blocks, out.shape[0], f, scale, target, weight, offset, block, out)


@nogil_kernel
def _sum_score_blocks(f, scale, target, weight, offset, block, out, queue):
    """:func:`_score_sums` of the blocks this thread takes from the queue (``queue[0]``)."""
    n = f.shape[0]
    while True:
        b = fetch_add(queue, 1)
        if b >= out.shape[0]:
            return
        lo = b * block
        hi = min(n, lo + block)
        for c in range(f.shape[1]):
            out[b, c] = _block_score(f[lo:hi], lo, hi, c, scale, target, weight, offset)


def _loss_gradient_sums(kinds, offs, params, needed, chan, lobe, nch, wi, wo, scale, target,
                        weight, offset, block, loss, grad):
    """For the one packed parameter vector ``params``: ``loss[b, c]`` as in :func:`_loss_sums`,
    and ``grad[b, j]`` = its derivative, summed over channels, in ``params[j]`` for each j with
    ``needed[j]`` (``chan[j]``: the one channel that params[j] acts on, or -1; ``lobe``: see
    :func:`_group_loss_gradient`).

    The blocks run in groups of :data:`GRADIENT_GROUP`, shared out to threads
    (:func:`_sum_loss_gradient_groups`). The sums of a block do not depend on its group.
    """
    groups = -(-loss.shape[0] // GRADIENT_GROUP)
    share_queue(_sum_loss_gradient_groups, groups, kinds, offs, params, needed, chan, lobe, nch,
                wi, wo, scale, target, weight, offset, block, loss, grad)


@nogil_kernel
def _sum_loss_gradient_groups(kinds, offs, params, needed, chan, lobe, nch, wi, wo, scale,
                              target, weight, offset, block, loss, grad, queue):
    """:func:`_loss_gradient_sums` of the groups of blocks this thread takes from the queue
    (``queue[0]``, the next group's number), with one set of work arrays for all of them (see
    :func:`_group_loss_gradient`)."""
    n = wi.shape[0]
    npar = params.shape[0]
    blocks = loss.shape[0]
    fast = nch == 3 and npar <= SLOTS
    rows = 0 if fast else block  # the other channel counts' work arrays (on the heap)
    fs = np.empty((rows, nch))
    terms = np.empty((rows, nch))
    ds = np.zeros((npar, rows, nch))
    while True:
        g = fetch_add(queue, 1)
        b0 = g * GRADIENT_GROUP
        if b0 >= blocks:
            return
        b1 = min(blocks, b0 + GRADIENT_GROUP)
        lo, hi = b0 * block, min(n, b1 * block)
        _group_loss_gradient(kinds, offs, params, needed, chan, lobe, nch, wi[lo:hi],
                             wo[lo:hi], scale[lo:hi], target[lo:hi], weight[lo:hi], offset,
                             block, loss[b0:b1], grad[b0:b1], fs, terms, ds)


#: Rows of a sub-block of :func:`_group_loss_gradient` and the packed parameters its work
#: space on the stack holds (16 x 64 x 3 doubles of derivatives, 24 kB: in the first-level
#: cache with the rows it reads).
SUB_ROWS, SLOTS = 64, 16
#: Sums of a block of :func:`_fold_rows` (see :func:`_fold_row`).
FOLD_SUMS = 6 + SLOTS


@inline_kernel
def _residual(f, s, t, w, offset):
    """A sample's term w (g(s f) - t)^2 and its derivative in f, 2 w r g'(s f) s, with
    r = g(s f) - t and g' = 1, or 1 / (offset + s f) for g = log(offset + .)
    (brdf.fitting.losses.Terms)."""
    if offset > 0.0:
        v = offset + s * f
        r = math.log(v) - t
        return w * r * r, 2.0 * w * r * s / v
    r = s * f - t
    return w * r * r, 2.0 * w * r * s


@inline_kernel
def _residual_weights(f, scale, target, weight, offset, m, nch, acc, g):
    """Add the term (:func:`_residual`) of each sample k < m and channel c < nch to
    ``acc[k, c]`` and set ``g[k, c]`` to its derivative in f; ``g`` may be ``f``. The test of
    the offset stands outside the loops (the same test inside is then folded away), which then
    vectorise."""
    if offset > 0.0:
        for k in range(m):
            for c in range(nch):
                term, g[k, c] = _residual(f[k, c], scale[k, c], target[k, c], weight[k], offset)
                acc[k, c] += term
    else:
        for k in range(m):
            for c in range(nch):
                term, g[k, c] = _residual(f[k, c], scale[k, c], target[k, c], weight[k], offset)
                acc[k, c] += term


@inline_kernel
def _column_sums(x, m, out):
    """Set ``out[c]`` to the sum of ``x[k, c]`` over the rows k < m, in row order."""
    for c in range(out.shape[0]):
        total = 0.0
        for k in range(m):
            total += x[k, c]
        out[c] = total


@inline_kernel
def _fold_start(iz, oz, diffuse, out, d):
    """Start a row of :func:`_fold_rows`: ``out[0]`` = the Lambertian lobes' f (their summed
    albedos ``diffuse`` times f per unit albedo), ``d`` zeroed; returns f per unit albedo."""
    v = lambert.per_albedo(iz, oz)
    for c in range(3):
        out[0, c] = diffuse[c] * v
    for j in range(SLOTS):
        for c in range(3):
            d[j, 0, c] = 0.0
    return v


@inline_kernel
def _fold_row(row, v, out, d, scale, target, weight, offset, sums):
    """Fold a row's f ``out[0]`` and derivatives ``d[j, 0, c]`` of the lobe into ``sums``: the
    terms (:func:`_residual`) into ``sums[c]``, their derivative in the Lambertian albedo of
    channel c (f per unit albedo ``v``) into ``sums[3 + c]`` and in the lobe's packed
    parameter j into ``sums[6 + j]`` (channels summed)."""
    for c in range(3):
        term, g = _residual(out[0, c], scale[row, c], target[row, c], weight[row], offset)
        sums[c] += term
        sums[3 + c] += g * v
        out[0, c] = g
    for j in range(SLOTS):
        sums[6 + j] += (sparse_product(out[0, 0], d[j, 0, 0])
                        + sparse_product(out[0, 1], d[j, 0, 1])
                        + sparse_product(out[0, 2], d[j, 0, 2]))


@inline_kernel
def _lambert_albedos(kinds, offs, p, diffuse):
    """Set ``diffuse[c]`` to the summed albedos of channel c of the Lambertian lobes of the
    packed parameters ``p`` (three channels)."""
    for c in range(3):
        diffuse[c] = 0.0
    for l in range(kinds.shape[0]):
        if kinds[l] == K.LAMBERT:
            for c in range(3):
                diffuse[c] += p[offs[l] + c]


#: The loop of :func:`_fold_rows` over a block's rows, for each family (``{call}``: its
#: ``grad_`` at the row, into ``out[0]`` and ``d[:, 0]``, which stay in registers).
_FOLD_LOOP = """\
k = 0
for row in range(wi.shape[0]):
    ix, iy, iz = wi[row, 0], wi[row, 1], wi[row, 2]
    ox, oy, oz = wo[row, 0], wo[row, 1], wo[row, 2]
    v = _fold_start(iz, oz, diffuse, out, d)
    {call}
    _fold_row(row, v, out, d, scale, target, weight, offset, sums)"""

for _name, _value in family_namespace().items():
    if globals().setdefault(_name, _value) is not _value:
        raise ImportError(f"family module name {_name!r} is taken in brdf.fitting.problem")
#: What :func:`rows_dispatcher` writes :func:`_fold_rows` from.
_FOLD_ARGS = (
    "_fold_rows", "kind, q, nch, wi, wo, diffuse, scale, target, weight, offset, out, d, sums",
    "grad_", _FOLD_LOOP,
    "Add to ``sums`` (see :func:`_fold_row`) every row of a block of a model of Lambertian\n"
    "    lobes (summed albedos ``diffuse``) and one lobe of family ``kind``: f and its\n"
    "    derivatives at a row are folded into the sums at once, never stored.")


def _define_rows(args):
    """Compile the inline kernel that ``rows_dispatcher(*args)`` writes into this module, under
    this file's name (so that numba caches it beside the file's other kernels), give it its
    copies for a model's families (:func:`specialising`), and return its source."""
    source = rows_dispatcher(*args)
    exec(compile(source, __file__, "exec"), globals())
    specialising(globals()[args[0]], lambda rows: rows_dispatcher(*args, families=rows),
                 globals())
    return source


#: The generated source of :func:`_fold_rows`.
FOLD_SOURCE = _define_rows(_FOLD_ARGS)


#: The loop of :func:`_fold_loss_rows` over a block's rows, for each family (``{call}``: its
#: ``eval_`` at the row, adding to ``out[0]``, which stays in registers).
_FOLD_LOSS_LOOP = """\
k = 0
for row in range(wi.shape[0]):
    ix, iy, iz = wi[row, 0], wi[row, 1], wi[row, 2]
    ox, oy, oz = wo[row, 0], wo[row, 1], wo[row, 2]
    v = lambert.per_albedo(iz, oz)
    for c in range(3):
        out[0, c] = diffuse[c] * v
    {call}
    for c in range(3):
        sums[c] += _residual(out[0, c], scale[row, c], target[row, c], weight[row], 0.0)[0]"""

#: What :func:`rows_dispatcher` writes :func:`_fold_loss_rows` from.
_FOLD_LOSS_ARGS = (
    "_fold_loss_rows", "kind, q, nch, wi, wo, diffuse, scale, target, weight, out, sums",
    "eval_", _FOLD_LOSS_LOOP,
    "Add to ``sums[c]`` the terms (:func:`_residual`, no logarithm) of every row of a block of\n"
    "    a model of Lambertian lobes (summed albedos ``diffuse``) and one lobe of family\n"
    "    ``kind``: f at a row is scored at once, never stored.")
#: The generated source of :func:`_fold_loss_rows`.
FOLD_LOSS_SOURCE = _define_rows(_FOLD_LOSS_ARGS)


@narrow_vectors
@kernel(linked=AS_LOWERED)
def _fold_loss_blocks(kinds, offs, params, lobe, wi, wo, scale, target, weight, out):
    """``out[j, c]``: the terms of one block (the rows of ``wi``) for each parameter row j of
    ``params``, by :func:`_fold_loss_rows` (three channels, Lambertian lobes and the one lobe
    ``lobe``, no logarithm), whose loop over the rows vectorises. The sums run over the rows in
    a fixed order whatever the number of threads."""
    diffuse = stack_array(1, 1, 3)[0, 0]
    f = stack_array(1, 1, 3)[0]
    sums = stack_array(1, 1, 3)[0, 0]
    a = with_last_axis(wi, 3)
    e = with_last_axis(wo, 3)
    s = with_last_axis(scale, 3)
    t = with_last_axis(target, 3)
    for j in range(params.shape[0]):
        for c in range(3):
            sums[c] = 0.0
        _lambert_albedos(kinds, offs, params[j], diffuse)
        q = params[j, offs[lobe]:offs[lobe + 1]]
        _fold_loss_rows(kinds[lobe], q, 3, a, e, diffuse, s, t, weight, f, sums)
        for c in range(3):
            out[j, c] = sums[c]


@kernel(linked=AS_LOWERED)
def _fold_blocks(kinds, offs, params, needed, lobe, wi, wo, scale, target, weight, block, loss,
                 grad):
    """:func:`_group_loss_gradient` for three channels and a model of Lambertian lobes and one
    lobe ``lobe`` of at most SLOTS packed parameters: ``loss[b, c]`` and ``grad[b, j]`` of each
    block by :func:`_fold_rows`, whose loop over the rows holds the whole chain rule, each
    row's derivatives in registers, and vectorises.

    For the metrics without a logarithm (offset 0, which LLVM folds into the terms: with the
    logarithm, the loop holds a call of log and does not vectorise anyway). Each block's sums
    run over its rows in a fixed order whatever the number of threads."""
    n = wi.shape[0]
    diffuse = stack_array(1, 1, 3)[0, 0]
    out = stack_array(1, 1, 3)[0]
    d = stack_array(SLOTS, 1, 3)
    sums = stack_array(1, 1, FOLD_SUMS)[0, 0]
    _lambert_albedos(kinds, offs, params, diffuse)
    kind = kinds[lobe]
    q = params[offs[lobe]:offs[lobe + 1]]
    for b in range(loss.shape[0]):
        for i in range(FOLD_SUMS):
            sums[i] = 0.0
        lo = b * block
        hi = min(n, lo + block)
        a = with_last_axis(wi[lo:hi], 3)
        e = with_last_axis(wo[lo:hi], 3)
        s = with_last_axis(scale[lo:hi], 3)
        t = with_last_axis(target[lo:hi], 3)
        w = weight[lo:hi]
        _fold_rows(kind, q, 3, a, e, diffuse, s, t, w, 0.0, out, d, sums)
        for c in range(3):
            loss[b, c] = sums[c]
        for j in range(params.shape[0]):
            grad[b, j] = 0.0
        for l in range(kinds.shape[0]):
            if kinds[l] == K.LAMBERT:
                for c in range(3):
                    if needed[offs[l] + c]:
                        grad[b, offs[l] + c] = sums[3 + c]
        for j in range(offs[lobe + 1] - offs[lobe]):
            if needed[offs[lobe] + j]:
                grad[b, offs[lobe] + j] = sums[6 + j]


@kernel(linked=AS_LOWERED)
def _group_loss_gradient(kinds, offs, params, needed, chan, lobe, nch, wi, wo, scale, target,
                         weight, offset, block, loss, grad, fs, terms, ds):
    """Blocks of :func:`_loss_gradient_sums` (``block`` rows each, from the first row of
    ``wi``): ``loss[b, c]`` and ``grad[b, j]``.

    With three channels, a metric without a logarithm (``offset`` 0) and Lambertian lobes
    besides the one lobe ``lobe`` (>= 0) that holds at most SLOTS packed parameters,
    :func:`_fold_blocks` runs. Otherwise one pass per lobe
    gives f with its derivatives df/dq_j (each family's ``grad_`` kernel:
    one evaluation of each formula), then the chain rule through the terms
    (:func:`_residual_weights`) times df/dq_j. With three channels and at most SLOTS packed
    parameters that runs on SUB_ROWS rows at a time in work space on the stack, where LLVM
    knows that the stores alias none of the inputs and vectorises the loops over rows; the
    sums run per row (each row's terms added apart, reduced at the end of the block), so
    they keep no chain of dependent additions, and a parameter of one channel (``chan[j]``
    >= 0) is multiplied with that channel's derivatives only. Other models go one pair at
    a time through the work arrays ``fs``, ``terms`` (block, C) and ``ds`` (P, block, C),
    ``ds`` zeroed (every family's ``grad_`` sets the same entries at every pair, so the
    others stay 0).
    """
    n = wi.shape[0]
    npar = params.shape[0]
    if nch == 3 and lobe >= 0 and offset == 0.0:
        _fold_blocks(kinds, offs, params, needed, lobe, wi, wo, scale, target, weight, block,
                     loss, grad)
        return
    if nch == 3 and npar <= SLOTS:
        f = stack_array(1, SUB_ROWS, 3)[0]
        g = stack_array(1, SUB_ROWS, 3)[0]
        acc = stack_array(1, SUB_ROWS, 3)[0]
        d = stack_array(SLOTS, SUB_ROWS, 3)
        dacc = stack_array(SLOTS, SUB_ROWS, 1)
        for j in range(npar):  # zeroed once: every pass sets the same entries again
            for c in range(3):
                for k in range(SUB_ROWS):
                    d[j, k, c] = 0.0
        for b in range(loss.shape[0]):
            for c in range(3):
                for k in range(SUB_ROWS):
                    acc[k, c] = 0.0
            for j in range(npar):
                for k in range(SUB_ROWS):
                    dacc[j, k, 0] = 0.0
            end = min(n, (b + 1) * block)
            for lo in range(b * block, end, SUB_ROWS):
                m = min(end - lo, SUB_ROWS)
                for c in range(3):
                    for k in range(m):
                        f[k, c] = 0.0
                a = with_last_axis(wi[lo:lo + m], 3)
                e = with_last_axis(wo[lo:lo + m], 3)
                for l in range(kinds.shape[0]):
                    lobe_grad_rows(kinds[l], params[offs[l]:offs[l + 1]], 3, a, e, f,
                                   d[offs[l]:offs[l + 1]])
                s = with_last_axis(scale[lo:lo + m], 3)
                t = with_last_axis(target[lo:lo + m], 3)
                w = weight[lo:lo + m]
                _residual_weights(f, s, t, w, offset, m, 3, acc, g)
                for j in range(npar):
                    if needed[j]:
                        c = chan[j]
                        if c >= 0:
                            for k in range(m):
                                dacc[j, k, 0] += g[k, c] * d[j, k, c]
                        else:
                            for k in range(m):
                                dacc[j, k, 0] += (g[k, 0] * d[j, k, 0] + g[k, 1] * d[j, k, 1]
                                                  + g[k, 2] * d[j, k, 2])
            _column_sums(acc, SUB_ROWS, loss[b])
            for j in range(npar):
                total = 0.0
                for k in range(SUB_ROWS):
                    total += dacc[j, k, 0]
                grad[b, j] = total
        return
    for b in range(loss.shape[0]):  # one pair at a time (see lobe_eval_block)
        lo = b * block
        m = min(n - lo, block)
        for k in range(m):
            for c in range(nch):
                fs[k, c] = 0.0
        for l in range(kinds.shape[0]):
            q = params[offs[l]:offs[l + 1]]
            for k in range(m):
                lobe_derivatives(kinds[l], q, nch, wi[lo + k, 0], wi[lo + k, 1], wi[lo + k, 2],
                                 wo[lo + k, 0], wo[lo + k, 1], wo[lo + k, 2], fs, k,
                                 ds[offs[l]:offs[l + 1]])
        for k in range(m):
            for c in range(nch):
                terms[k, c] = 0.0
        # fs becomes dL/df
        _residual_weights(fs, scale[lo:lo + m], target[lo:lo + m], weight[lo:lo + m], offset, m,
                          nch, terms, fs)
        _column_sums(terms, m, loss[b])
        for j in range(npar):
            total = 0.0
            if needed[j]:
                for k in range(m):
                    for c in range(nch):
                        total += fs[k, c] * ds[j, k, c]
            grad[b, j] = total
