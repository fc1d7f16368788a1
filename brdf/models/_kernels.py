"""Compiled evaluation of any model: lobe dispatch and the array drivers.

A model reaches the kernels as ``(kinds, offsets, params, nch)`` (see ``Model.compile``): lobe
``l`` has family ``kinds[l]`` and reads its packed parameters ``params[offsets[l]:offsets[l+1]]``.
Every family is one row of the table ``_kinds.FAMILIES`` and one module that provides these
scalar kernels (wi, wo in the local frame; the dispatchers below are generated from the table):

- ``eval_(q, nch, ix, iy, iz, ox, oy, oz, out, k)``: add f(wi, wo) to ``out[k, :nch]``;
- ``grad_(q, nch, ix, iy, iz, ox, oy, oz, out, k, d)``: the same, and set ``d[j, k, c]`` to the
  analytic df_c / dq[j] for the packed parameters f depends on (fitting's gradients). ``eval_``
  and ``grad_`` take f from one function of the family that returns the formula's value with
  its partial derivatives (LLVM drops the derivatives from ``eval_``), so they cannot drift;
- ``sample_(q, nch, ix, iy, iz, u1, u2) -> (ox, oy, oz, pdf)``: pdf 0 marks an invalid sample;
- ``pdf_(q, nch, ix, iy, iz, ox, oy, oz) -> pdf`` (solid angle, 0 below the horizon);
- ``hint_(q, nch, ix, iy, iz) -> float``: a cheap estimate of the albedo (channel mean), used only
  to choose lobes when sampling a sum, so it changes variance, never the expected value;
- optionally ``albedo_weight_(q, nch, term, ix, iy, iz, u1, u2, out) -> (cos_o, piece)``, the
  albedo's integrand f cos / pdf in closed form (see ``lobe_weight``), where that is cheaper
  than ``eval`` and ``pdf`` or the albedo integrates the lobe's terms apart (``ALBEDO_TERMS``);
- for a delta lobe, ``reflectance_(q, nch, ch, iz)`` instead of ``eval_``, ``grad_`` and ``pdf_``;
- optionally ``eval_rows_(q, nch, wi, wo, out) -> bool`` and ``grad_rows_(q, nch, wi, wo, out,
  d) -> bool``: ``eval_`` and ``grad_`` at every row k of a block (``wi``, ``wo`` (m, 3)), where
  the family has tests of constant parameters to take out of the loop over rows so that it
  vectorises (see ``lobe_eval_block``); False leaves the rows to ``eval_`` and ``grad_``.
- optionally ``rows_split_(q, nch) -> bool``: that test of constant parameters itself, for loops
  over rows generated elsewhere (``rows_dispatcher``), which are then written once under each
  outcome of the test.

A kernel may take any of these parameters by name, and a module serving several families (GGX
and Beckmann, Phong's two forms) takes the row's variant as an extra first parameter.

The same scalar functions serve checks, fitting, plots and the renderer: there is no second copy
of any formula. (The closed-form albedo weights are ratios of a family's formulas, simplified;
tests hold them to ``eval`` cos / ``pdf``.)
"""

import contextlib
import importlib
import os

import numpy as np
from llvmlite import ir
from numba.core import cgutils, types
from numba.core.datamodel.models import IntegerModel
from numba.core.datamodel.registry import register_default
from numba.core.imputils import impl_ret_borrowed
from numba.core.typeconv import Conversion
from numba.core.typing.typeof import typeof_impl
from numba.extending import intrinsic

from .._jit import (AS_LOWERED, OPTIMISED, allocating_kernel, inline_kernel, kernel,
                    parameter_names, threaded_kernel, when_made)
from .._generated import compiled
from .._kernel_cache import stamped_marker
from . import _kinds as K
from . import lambert, microfacet


#: The largest double below 1: uniform numbers lie in [0, 1).
BELOW_ONE = 1.0 - 2.0 ** -53
#: Samples with cos(theta_o) below -HORIZON_MARGIN count as below the horizon (see lobe_weight).
HORIZON_MARGIN = 1e-9


# --- dispatchers, generated from the family table -------------------------------------------
#
# Each dispatcher below is a chain of ``if kind == K.NAME:`` tests, one per family of
# ``K.FAMILIES`` (families whose code is the same share a test), written out as source
# and compiled here: LLVM then inlines each family's kernel into its branch (see
# ``brdf._jit.inline_kernel``), and numba caches the dispatchers like any kernel of this file
# (their source is a function of this file, the table and the family modules, all in the
# cache stamp). A hook receives the dispatcher's arguments of the same names; a first parameter of
# another name (``dist``, ``form``) receives the row's variant. ``DISPATCH_SOURCE`` holds the
# generated source.
#
# Hooks and their fallbacks, the same for every family:
#
# - ``reflectance_`` makes the family a delta lobe: its eval, grad and pdf are 0 by this
#   declaration (it may not define ``eval_``, ``grad_`` or ``pdf_``);
# - ``eval_``, ``grad_``, ``pdf_`` (non-delta families), ``sample_`` and ``hint_``: required;
# - ``albedo_weight_``: optional, else the albedo's weight is eval cos / pdf (``lobe_weight``);
# - ``ALBEDO_TERMS``: optional, else 1.

_DISPATCHERS = (
    # name, decorator, parameters, hook, statement or expression, delta body, fallback, doc
    ("lobe_eval", "inline_kernel", "kind, q, nch, ix, iy, iz, ox, oy, oz, out, k", "eval_",
     "{call}", "pass  # a delta lobe has no density with respect to solid angle", None,
     "Add f(wi, wo) to ``out[k, :nch]`` (nothing for an unknown kind)."),
    ("lobe_grad", "inline_kernel", "kind, q, nch, ix, iy, iz, ox, oy, oz, out, k, d", "grad_",
     "{call}", "pass  # a delta lobe's eval is 0, and so are its derivatives", None,
     "Add f(wi, wo) to ``out[k, :nch]`` and set ``d[j, k, c]`` to df_c / dq[j] for each packed\n"
     "    parameter q[j] that f depends on; other entries of ``d`` are left alone (the caller\n"
     "    zeroes them once)."),
    ("lobe_sample", "kernel", "kind, q, nch, ix, iy, iz, u1, u2", "sample_",
     "return {call}", None, "return 0.0, 0.0, 1.0, 0.0",
     "Draw wo given wi: ``(ox, oy, oz, pdf)``, pdf 0 for no sample, inf for a delta lobe."),
    ("lobe_pdf", "kernel", "kind, q, nch, ix, iy, iz, ox, oy, oz", "pdf_",
     "return {call}", "return 0.0  # a delta lobe has no density with respect to solid angle",
     "return 0.0", "Solid-angle density of ``lobe_sample``'s wo (0 below the horizon)."),
    ("lobe_hint", "kernel", "kind, q, nch, ix, iy, iz", "hint_",
     "return {call}", None, "return 0.0",
     "A cheap estimate of the albedo at wi, for choosing lobes when sampling a sum."),
    ("delta_reflectance", "kernel", "kind, q, nch, ch, iz", "reflectance_",
     "return {call}", None, "return 0.0",
     "Reflectance of a delta lobe in channel ``ch`` (its albedo and its sampling weight)."),
)


def _hook_call(row, module, hook, params):
    """Source of the call of ``module.hook`` with the dispatcher's ``params`` by name."""
    kind, _, name, variant = row
    fn = getattr(module, hook)
    args = []
    for i, arg in enumerate(parameter_names(fn.py_func)):
        if arg in params:
            args.append(arg)
        elif i == 0 and variant is not None:
            args.append(f"{name}.{variant}")
        else:
            raise ImportError(f"family {kind}: brdf.models.{name}.{hook} takes {arg!r}, which "
                              f"is neither a variant nor one of {', '.join(params)}")
    return f"{name}.{hook}({', '.join(args)})"


def _is_delta_family(kind, module):
    if not hasattr(module, "reflectance_"):
        return False
    extra = [h for h in ("eval_", "grad_", "pdf_") if hasattr(module, h)]
    if extra:
        raise ImportError(f"family {kind}: a delta lobe (it has reflectance_) has eval, grad and "
                          f"pdf 0 by declaration; remove {', '.join(extra)}")
    return True


def _branches(hook, params, template, delta_body, optional, families=K.FAMILIES):
    """``(condition, body)`` for each family of ``families`` (rows of the table) that the hook
    concerns, neighbours with the same body merged into one condition."""
    out = []
    for row in families:
        kind, _, name, _ = row
        module = _FAMILY_MODULES[name]
        if delta_body is not None and _is_delta_family(kind, module):
            body = delta_body
        elif hasattr(module, hook):
            body = template.format(call=_hook_call(row, module, hook, params))
        elif optional:
            continue
        else:
            raise ImportError(f"family {kind}: brdf.models.{name} lacks the kernel {hook}")
        out.append((kind, body))
    return _merged(out)


def _merged(bodies):
    """``(condition, body)`` from ``(kind, body)`` in table order, neighbours with the same
    body merged into one condition."""
    out = []
    for kind, body in bodies:
        if out and out[-1][1] == body:
            out[-1] = (out[-1][0] + f" or kind == K.{kind}", body)
        else:
            out.append((f"kind == K.{kind}", body))
    return out


def _chain(branches, fallback, indent="    "):
    """if/elif lines of ``branches``; statement chains end without else, returning chains with
    ``fallback`` (a list of lines: the else branch)."""
    lines = []
    returns = fallback is not None and not isinstance(fallback, list)
    for i, (cond, body) in enumerate(branches):
        head = "if" if (returns or i == 0) else "elif"
        lines += [f"{indent}{head} {cond}:"] + [f"{indent}    {b}" for b in body.split("\n")]
    if returns:
        lines.append(f"{indent}{fallback}")
    elif fallback:
        if branches:
            lines += [f"{indent}else:"] + [f"{indent}    {b}" for b in fallback]
        else:
            lines += [f"{indent}{b}" for b in fallback]
    return lines


def _function(decorator, name, params, doc, lines):
    return "\n".join([f"@{decorator}", f"def {name}({params}):", f'    """{doc}"""', *lines, ""])


# what lobe_weight does for a family without albedo_weight_: eval cos / pdf at the sample
_WEIGHT_FROM_EVAL = """\
ox, oy, oz, pdf = lobe_sample(kind, q, nch, ix, iy, iz, u1, u2)
piece = 1 if (pdf > 0.0 and oz > 0.0) else 0
if piece:
    for c in range(nch):
        out[0, c] = 0.0
    lobe_eval(kind, q, nch, ix, iy, iz, ox, oy, oz, out, 0)
    s = oz / pdf
    for c in range(nch):
        out[0, c] *= s""".split("\n")

_WEIGHT_DOC = """\
The albedo's integrand: f cos(theta_o) / pdf of term ``term`` of a lobe at the sample drawn
    from (u1, u2), into ``out[0, :nch]``. Returns the sample's zone: -1 below the horizon (past
    a margin: samplers map the square's edges onto the horizon itself), 0 otherwise invalid (no
    weight), or the smooth piece of the integrand that holds the sample, 1 or more; where
    neighbouring samples differ in zone the integrand may jump between them.

    Families with a cheaper closed form of the ratio, with terms integrated apart or with
    several pieces provide ``albedo_weight_``, which returns cos(theta_o) and the piece (0 when
    invalid); for the others the weight is ``eval`` times cos / ``pdf`` at the sample."""


# Dispatchers over a block of rows (wi, wo (m, 3)): the family is tested once per block, and
# the loop over the rows then holds one formula, which LLVM can vectorise (see
# ``lobe_eval_block``). A family may provide the rows hook (``eval_rows_``, ``grad_rows_``,
# taking the dispatcher's arguments by name) to take its own tests of constant parameters out
# of that loop, as microfacet lobes do with their Fresnel term (it returns False to leave the
# rows to the loop below). Otherwise the loop calls the family's per-pair hook at each row.
_ROW_DISPATCHERS = (
    # name, parameters, rows hook, per-pair hook, doc
    ("lobe_eval_rows", "kind, q, nch, wi, wo, out", "eval_rows_", "eval_",
     "Add f(wi_k, wo_k) to ``out[k, :nch]`` at every row k of ``wi`` and ``wo``."),
    ("lobe_grad_rows", "kind, q, nch, wi, wo, out, d", "grad_rows_", "grad_",
     "Add f(wi_k, wo_k) to ``out[k, :nch]`` and set ``d[j, k, c]`` as :func:`lobe_grad` does,\n"
     "    at every row k of ``wi`` and ``wo``."),
)
_ROW = "ix, iy, iz, ox, oy, oz = wi[k, 0], wi[k, 1], wi[k, 2], wo[k, 0], wo[k, 1], wo[k, 2]"


_DELTA_ROW = "pass  # a delta lobe's eval is 0, and so are its derivatives"


def _row_calls(hook, params, families=K.FAMILIES):
    """``(row, module, call)`` for each family of ``families``: the source of its ``hook``
    called with ``params`` by name, or None for a delta lobe (whose eval and derivatives are
    0)."""
    for row in families:
        kind, _, name, _ = row
        module = _FAMILY_MODULES[name]
        if _is_delta_family(kind, module):
            yield row, module, None
        elif hasattr(module, hook):
            yield row, module, _hook_call(row, module, hook, params)
        else:
            raise ImportError(f"family {kind}: brdf.models.{name} lacks the kernel {hook}")


def _row_branches(rows_hook, hook, params, families=K.FAMILIES):
    """``(condition, body)`` of a rows dispatcher for each family, as :func:`_branches`."""
    out = []
    for row, module, call in _row_calls(hook, params + ["k", *_ROW.split(" = ")[0].split(", ")],
                                        families):
        if call is None:
            body = _DELTA_ROW
        else:
            body = f"for k in range(wi.shape[0]):\n    {_ROW}\n    {call}"
            if hasattr(module, rows_hook):
                loop = "\n".join("    " + line for line in body.split("\n"))
                body = f"if not {_hook_call(row, module, rows_hook, params)}:\n{loop}"
        out.append((row[0], body))
    return _merged(out)


def rows_dispatcher(name, params, hook, loop, doc, families=K.FAMILIES):
    """Source of an inline kernel ``name(params)`` that runs ``loop`` for the family ``kind`` (a
    parameter): for callers whose loop over rows does more per row than one hook can, such as
    fitting's loss-and-gradient pass, which folds each row's derivatives into its sums at once.

    ``loop`` is Python source whose ``{call}`` stands for the family's ``hook`` called with the
    names of its parameters (a variant as first parameter, as in the dispatchers above): the
    loop defines those it does not receive. A delta family's call is ``pass`` (its eval and
    derivatives are 0). A family with ``rows_split_``, a test of its constant parameters that
    its per-pair kernels make (a Fresnel term or none), gets the loop twice, under each outcome
    of the test: inlined below it, the test in the loop is known and folded away, so the loop
    holds no branch and vectorises.

    ``families`` (rows of the family table, all by default) are the families the loop is
    written for: see :func:`specialising`."""
    names = params.split(", ")
    out = []
    for row, module, call in _row_calls(hook, names + ["k", "ix", "iy", "iz", "ox", "oy", "oz",
                                                       "out", "d"], families):
        body = loop.format(call=_DELTA_ROW if call is None else call)
        if call is not None and hasattr(module, "rows_split_"):
            inner = "\n".join("    " + line for line in body.split("\n"))
            body = f"if {_hook_call(row, module, 'rows_split_', names)}:\n{inner}\nelse:\n{inner}"
        out.append((row[0], body))
    return _function("inline_kernel", name, params, doc, _chain(_merged(out), None))


def family_namespace():
    """The names generated sources use: ``K`` (the family table) and each family module."""
    return {"K": K, **_FAMILY_MODULES}


def _generate(families=K.FAMILIES):
    """Source of every dispatcher over ``families`` (rows of the family table: all of them by
    default, or a model's own, see :func:`specialising`)."""
    parts = []
    for name, decorator, params, hook, template, delta_body, fallback, doc in _DISPATCHERS:
        names = params.split(", ")
        optional = hook == "reflectance_"
        lines = _chain(_branches(hook, names, template, delta_body, optional, families),
                       fallback)
        parts.append(_function(decorator, name, params, doc, lines or ["    pass"]))
    for name, params, rows_hook, hook, doc in _ROW_DISPATCHERS:
        lines = _chain(_row_branches(rows_hook, hook, params.split(", "), families), None)
        parts.append(_function("inline_kernel", name, params, doc, lines or ["    pass"]))
    delta = [f"kind == K.{kind}" for kind, _, name, _ in families
             if _is_delta_family(kind, _FAMILY_MODULES[name])]
    parts.append(_function("kernel", "is_delta", "kind", "Whether ``kind`` is a delta lobe.",
                           [f"    return {' or '.join(delta) if delta else 'False'}"]))
    terms = [(f"kind == K.{kind}", f"return {name}.ALBEDO_TERMS")
             for kind, _, name, _ in families if hasattr(_FAMILY_MODULES[name], "ALBEDO_TERMS")]
    parts.append(_function("kernel", "lobe_terms", "kind", "Number of terms the albedo "
                           "integrates apart, each over its own sampler's unit square.",
                           _chain(terms, "return 1")))
    params = "kind, q, nch, term, ix, iy, iz, u1, u2, out"
    weights = _branches("albedo_weight_", params.split(", "), "oz, piece = {call}", None, True,
                        families)
    lines = _chain(weights, _WEIGHT_FROM_EVAL)
    lines += ["    if piece > 0:", "        return piece",
              "    return -1 if oz < -HORIZON_MARGIN else 0"]
    # a kernel, not an inline one: the cubature's loop over nodes with every family's weights
    # forced into it ran the albedo 11-16 % slower than with the weight left to LLVM (kernels
    # over every family, one thread); over a model's own families the albedo is the same
    parts.append(_function("kernel(linked=OPTIMISED)", "lobe_weight", params, _WEIGHT_DOC,
                           lines))
    return "\n\n".join(parts)


_FAMILY_MODULES = {name: importlib.import_module(f".{name}", __package__)
                   for name in K.MODULES}
for _name, _module in _FAMILY_MODULES.items():
    if globals().setdefault(_name, _module) is not _module:
        raise ImportError(f"family module name {_name!r} is taken in brdf.models._kernels")
#: The generated source of the dispatchers (compiled under this file's name, so that numba
#: caches them beside the file's other kernels; its code is kept beside this file's bytecode).
DISPATCH_SOURCE = _generate()
exec(compiled(DISPATCH_SOURCE, __file__), globals())


# --- kernels specialised to a model's families -----------------------------------------------
#
# Compiled for a plain int64 kind, each dispatcher holds every family's formulas, and so does
# every kernel that calls one: a first ``check`` of ``lambert + ggx`` compiled every family
# into its two kernels (31 s of CPU). A model's kinds reach the kernels as a
# :func:`family_kinds` array instead, whose numba type names the families it holds (its items
# are :class:`FamilyKind`). numba compiles a kernel once per set of argument types, so once
# per family set, and caches it on disk like any other signature; a dispatcher called with such
# a kind compiles a copy of itself generated for those families only (:func:`specialising`):
# the first check compiles in 9 s. Plain int64 kinds (the renderer's materials, calls from
# Python, and every model once brdf.precompile has cached them) keep the dispatchers over
# every family. A family's branch holds the same code either way; compiled with fast-math
# contraction into other surroundings, a formula may round differently in the last bit
# (tests hold the two to 4e-15).

class FamilyKind(types.Integer):
    """numba type of a lobe's kind read from a :func:`family_kinds` array: an int64 known to be
    one of ``families`` (sorted codes of the family table).

    Its name is ``int64``, which numba's numpy typing of comparisons reads; its key and its
    mangled name hold the families, so that each set is typed, compiled and cached apart."""

    def __init__(self, families):
        self.families = tuple(families)
        super().__init__("int64", bitwidth=64, signed=True)

    @property
    def key(self):
        return "kind", self.families

    @property
    def mangling_args(self):
        return "kind", self.families

    def can_convert_to(self, typingctx, other):
        # to plain integers (arithmetic, indexing), never to another family set's kind
        if isinstance(other, types.Integer) and not isinstance(other, FamilyKind):
            return max(typingctx.can_convert(types.int64, other) or Conversion.promote,
                       Conversion.promote)
        return None


register_default(FamilyKind)(IntegerModel)


class _FamilyKinds(np.ndarray):
    """An array of kinds whose dtype, one int64 field named after the family set, tells numba
    its type (:func:`family_kinds`). numba dispatches a call on a fingerprint of each array's
    dtype, never its values: a dtype per family set makes one (plain int64 arrays of other
    sets would all match the first set's kernels)."""

    __numba_array_subtype_dispatch__ = True  # numba types it with typeof_impl, not as ndarray


@typeof_impl.register(_FamilyKinds)
def _typeof_family_kinds(value, context):
    return types.Array(FamilyKind(int(c) for c in value.dtype.names[0].split("_")[1:]), 1, "C")


#: The dtype of each family set's kinds arrays.
_FAMILY_DTYPES = {}


_EVERY_FAMILY = {"forced": 0, "cached": None, "record": False}


@contextlib.contextmanager
def every_family(record=True):
    """Within this context :func:`family_kinds` gives plain kinds: kernels compile over every
    family, as :mod:`brdf.precompile` compiles them. For work that spans many families (a
    comparison of models, the demo), where compiling once for all beats once per family set.
    When the outermost context ends, if ``record``, :func:`record_every_family`: the kernels
    over every family that the work compiled serve every later model, in this process and the
    next ones. Work that compiles no model kernels (the renderer's alone) passes False."""
    _EVERY_FAMILY["forced"] += 1
    _EVERY_FAMILY["record"] |= bool(record)
    try:
        yield
    finally:
        _EVERY_FAMILY["forced"] -= 1
        if not _EVERY_FAMILY["forced"]:
            record, _EVERY_FAMILY["record"] = _EVERY_FAMILY["record"], False
            if record:
                record_every_family()


def _marker():
    return stamped_marker(eval_array, "every-family-kernels")


def record_every_family():
    """Record in the kernel cache that kernels over every family are in it: from then on, in
    every process, :func:`family_kinds` gives plain kinds and models use those kernels (one
    that is not yet cached compiles over every family, after its notice)."""
    _EVERY_FAMILY["cached"] = True
    path = _marker()
    if path is not None and not os.path.exists(path):
        try:
            os.makedirs(os.path.dirname(path), exist_ok=True)
            with open(path, "w"):
                pass
        except OSError:  # a read-only cache: this process still keeps to those kernels
            pass


def every_family_cached():
    """Whether :func:`record_every_family` was called on this kernel cache (looked up once per
    process)."""
    if _EVERY_FAMILY["cached"] is None:
        path = _marker()
        _EVERY_FAMILY["cached"] = path is not None and os.path.exists(path)
    return _EVERY_FAMILY["cached"]


def family_kinds(kinds):
    """``kinds`` (lobe kinds, codes of the family table) as the kernels take a model's.

    Once :mod:`brdf.precompile` has put the kernels over every family in the cache
    (:func:`every_family_cached`), or within :func:`every_family`, these are the plain kinds,
    and every model shares those kernels. Otherwise their numba type holds the model's set of
    families, and the kernels compile for that set alone: a first ``check`` of ``lambert +
    ggx`` on an empty cache compiles in 9 s of CPU instead of 31 s, each further family set
    in less (the families' own kernels are cached apart and shared).
    """
    kinds = np.ascontiguousarray(kinds, dtype=np.int64)
    if _EVERY_FAMILY["forced"] or every_family_cached():
        return kinds
    return kinds_of_families(kinds)


def kinds_of_families(kinds):
    """``kinds`` (int64) typed with their set of families, whatever the cache holds: the
    kernels called with them compile for that set alone (:class:`FamilyKind`)."""
    kinds = np.ascontiguousarray(kinds, dtype=np.int64)
    families = tuple(sorted(set(kinds.tolist())))
    dtype = _FAMILY_DTYPES.get(families)
    if dtype is None:
        dtype = np.dtype([("kind_" + "_".join(map(str, families)), "<i8")])
        _FAMILY_DTYPES[families] = dtype
    return kinds.view(dtype).view(_FamilyKinds)


def specialising(dispatcher, source_of, namespace):
    """``dispatcher`` (generated source: a chain of tests of its first parameter, the kind),
    compiling a call whose kind is a :class:`FamilyKind` from ``source_of(rows)`` instead: the
    source of the same function over those families' rows of the family table only, compiled
    under the file name of ``namespace`` (a module's globals) into it as ``NAME__f<codes>``
    (a name of its own, so that numba caches each family set apart). Its compiled overload
    joins ``dispatcher``'s, where the caller's typing finds it. A :class:`DeferredKernel`
    gets this when its dispatcher is made."""
    name = dispatcher.py_func.__name__
    variants = {}

    def specialise(made):
        resolve = made.get_call_template

        def get_call_template(args, kws):
            kind = types.unliteral(args[0]) if args else None
            if isinstance(kind, FamilyKind):
                variant = variants.get(kind.families)
                if variant is None:
                    rows = tuple(r for r in K.FAMILIES if r[1] in kind.families)
                    own = f"{name}__f{'_'.join(map(str, kind.families))}"
                    source = source_of(rows).replace(f"def {name}(", f"def {own}(", 1)
                    exec(compile(source, namespace["__file__"], "exec"), namespace)
                    variant = variants[kind.families] = namespace[own]
                variant.get_call_template(args, kws)  # compiles it, or loads it from the cache
                for key, cres in list(variant.overloads.items()):
                    if key not in made.overloads:
                        made.add_overload(cres)
            return resolve(args, kws)

        made.get_call_template = get_call_template

    return when_made(dispatcher, specialise)


def _one_dispatcher(name):
    """Source of the generated dispatcher ``name`` over the given family rows."""
    def source_of(rows):
        part = [p for p in _generate(rows).split("\n\n\n") if f"\ndef {name}(" in p]
        return part[0]
    return source_of


for _name in [line.split("(")[0][4:] for line in DISPATCH_SOURCE.split("\n")
              if line.startswith("def ")]:
    specialising(globals()[_name], _one_dispatcher(_name), globals())

# --- mixtures ---------------------------------------------------------------------------------
#
# A sum of lobes is sampled by one-sample MIS (Veach 1997, thesis, sec. 9.2.4): a lobe is
# picked with probability proportional to its hint at wi, and the mixture's density is the sum
# of the continuous lobes' densities weighted by those probabilities. The kernels work on a
# batch: items ``idx[:n]`` index the direction and output arrays, and item j reads its packed
# parameters from row ``j * step`` of ``p`` (step 0: one parameter set for the whole batch, as
# the array drivers use it; step 1: a row per item, as the renderer's paths, each on its own
# material or texel). Each pass runs one lobe over the batch, so the family's formula is chosen
# once per pass rather than once per direction (the renderer's Lambertian sampling went from
# about 90 ns a direction, dispatched one at a time, to the formula's own 25 ns).


@inline_kernel
def mixture_selection(kinds, offs, p, step, nch, idx, n, ix, iy, iz, sel):
    """``sel[j, l]``: the probability of picking lobe l at wi_j, its hint over the sum of the
    hints (each clipped at 0), uniform where they are all 0."""
    nl = kinds.shape[0]
    for l in range(nl):
        kind, o0, o1 = kinds[l], offs[l], offs[l + 1]
        for t in range(n):
            j = idx[t]
            sel[j, l] = max(0.0, lobe_hint(kind, p[j * step][o0:o1], nch, ix[j], iy[j], iz[j]))
    for t in range(n):
        j = idx[t]
        total = 0.0
        for l in range(nl):
            total += sel[j, l]
        for l in range(nl):
            sel[j, l] = sel[j, l] / total if total > 0.0 else 1.0 / nl


@kernel(linked=OPTIMISED)
def lobe_value(kind, q, nch, ix, iy, iz, ox, oy, oz, out, k):
    """:func:`lobe_eval` as a kernel of its own, for loops over directions that the formula
    cannot be vectorised in anyway: inlined into such a loop, the nine families took LLVM
    10 s more to compile, for 5 % of the renderer's time."""
    lobe_eval(kind, q, nch, ix, iy, iz, ox, oy, oz, out, k)


@kernel(linked=OPTIMISED)
def lobe_derivatives(kind, q, nch, ix, iy, iz, ox, oy, oz, out, k, d):
    """:func:`lobe_grad` as a kernel of its own (see :func:`lobe_value`), for loops over pairs
    that are not vectorised: one compiled copy of every family's derivatives serves them."""
    lobe_grad(kind, q, nch, ix, iy, iz, ox, oy, oz, out, k, d)


@kernel(linked=AS_LOWERED)
def mixture_gradient(kinds, offs, p, ix, iy, iz, ox, oy, oz, out, d):
    """f(wi, wo) in RGB of the sum of the lobes on the one parameter vector ``p`` into
    ``out[0]``, and df_c / dp[j] into ``d[j, 0, c]`` for every packed parameter (0 where f does
    not depend on it): the renderer's derivative images."""
    for c in range(3):
        out[0, c] = 0.0
    for j in range(offs[kinds.shape[0]]):
        for c in range(3):
            d[j, 0, c] = 0.0
    for l in range(kinds.shape[0]):
        lobe_derivatives(kinds[l], p[offs[l]:offs[l + 1]], 3, ix, iy, iz, ox, oy, oz, out, 0,
                         d[offs[l]:offs[l + 1]])


@inline_kernel
def mixture_eval(kinds, offs, p, step, nch, idx, n, ix, iy, iz, ox, oy, oz, out):
    """Add f(wi_j, wo_j), the sum of the lobes, to ``out[j, :nch]`` for each item j."""
    for l in range(kinds.shape[0]):
        kind, o0, o1 = kinds[l], offs[l], offs[l + 1]
        if kind == K.LAMBERT:  # the commonest lobe, inlined: its formula costs less than a call
            for t in range(n):
                j = idx[t]
                lambert.eval_(p[j * step][o0:o1], nch, ix[j], iy[j], iz[j], ox[j], oy[j], oz[j],
                              out, j)
            continue
        if kind == K.GGX and step == 0 and microfacet.rows_split_(p[0][o0:o1], nch):
            _ggx_values(p[0][o0:o1], nch, idx, n, ix, iy, iz, ox, oy, oz, out)
            continue
        for t in range(n):
            j = idx[t]
            lobe_value(kind, p[j * step][o0:o1], nch, ix[j], iy[j], iz[j], ox[j], oy[j], oz[j],
                       out, j)


@inline_kernel
def mixture_pdf(kinds, offs, p, step, nch, idx, n, ix, iy, iz, ox, oy, oz, sel, pdf):
    """``pdf[j]``: the density of the continuous part of the mixture at wo_j (delta lobes have
    none), with the selection probabilities ``sel`` of :func:`mixture_selection` (not read
    for a single lobe, which is picked with probability 1)."""
    nl = kinds.shape[0]
    for t in range(n):
        pdf[idx[t]] = 0.0
    for l in range(nl):
        kind, o0, o1 = kinds[l], offs[l], offs[l + 1]
        if is_delta(kind):
            continue
        lam = kind == K.LAMBERT
        if kind == K.GGX and step == 0:
            _ggx_densities(p[0][o0:o1], nch, idx, n, ix, iy, iz, ox, oy, oz, sel, l, nl, pdf)
            continue
        for t in range(n):
            j = idx[t]
            w = sel[j, l] if nl > 1 else 1.0
            if w > 0.0:
                q = p[j * step][o0:o1]
                pdf[j] += w * (lambert.pdf_(q, nch, ix[j], iy[j], iz[j], ox[j], oy[j], oz[j])
                               if lam else lobe_pdf(kind, q, nch, ix[j], iy[j], iz[j], ox[j],
                                                    oy[j], oz[j]))


#: Items per block of :func:`_lane_draws`, :func:`_ggx_values` and :func:`_ggx_densities`.
DRAW_BLOCK = 64


@inline_kernel
def _ggx_values(q, nch, idx, n, ix, iy, iz, ox, oy, oz, out):
    """:func:`mixture_eval`'s GGX lobe without a Fresnel term, on one parameter row ``q`` for
    every item: in blocks of DRAW_BLOCK items, the factor D G2 / (4 cos_i cos_o) into work
    space on the stack in a loop without branches or stores to the caller's arrays, which LLVM
    runs in SIMD lanes; then times the colour into ``out``."""
    s = stack_array(1, DRAW_BLOCK, 1)
    for t0 in range(0, n, DRAW_BLOCK):
        m = min(DRAW_BLOCK, n - t0)
        for k in range(m):
            j = idx[t0 + k]
            s[0, k, 0] = microfacet.plain_in_lanes(microfacet.GGX, q, nch, ix[j], iy[j], iz[j],
                                                   ox[j], oy[j], oz[j])
        for k in range(m):
            j = idx[t0 + k]
            for c in range(nch):
                out[j, c] += q[c] * s[0, k, 0]  # Walter et al. 2007, eq. 20 with F = 1


@inline_kernel
def _ggx_densities(q, nch, idx, n, ix, iy, iz, ox, oy, oz, sel, l, nl, pdf):
    """:func:`mixture_pdf`'s GGX lobe l on one parameter row ``q`` for every item, in blocks
    as :func:`_ggx_values`."""
    s = stack_array(1, DRAW_BLOCK, 1)
    for t0 in range(0, n, DRAW_BLOCK):
        m = min(DRAW_BLOCK, n - t0)
        for k in range(m):
            j = idx[t0 + k]
            s[0, k, 0] = microfacet.pdf_in_lanes(microfacet.GGX, q, nch, ix[j], iy[j], iz[j],
                                                 ox[j], oy[j], oz[j])
        for k in range(m):
            j = idx[t0 + k]
            w = sel[j, l] if nl > 1 else 1.0
            if w > 0.0:
                pdf[j] += w * s[0, k, 0]


@inline_kernel
def _lane_draws(lam, p, step, nch, idx, n, ix, iy, iz, u2, ox, oy, oz, pdf, work, chosen, l,
                o0, o1):
    """The draws of :func:`mixture_draw`'s lobe l, Lambertian (``lam``) or GGX, in blocks: the
    items of up to DRAW_BLOCK of the list that chose lobe l, listed on the stack; their
    samples into work space on the stack, in a loop without branches or stores to the caller's
    arrays that LLVM runs in SIMD lanes (the last item repeated up to a whole vector); then
    into place. Drawn one item at a time, GGX's chain of square roots and divisions was a fifth
    of a GGX furnace's render (sampled with perf), and the cosine-weighted warp's division and
    square root a twentieth of the point light's; in lanes each costs half as much per sample."""
    s = stack_array(1, DRAW_BLOCK, 4)
    ids = stack_array(1, DRAW_BLOCK, 1)  # item numbers, exact in float64
    for t0 in range(0, n, DRAW_BLOCK):
        m = 0
        for t in range(t0, min(t0 + DRAW_BLOCK, n)):
            # no branch: which lobe an item chose is a coin toss that a branch predictor
            # misses (a tenth of a point light's shading, sampled with perf)
            j = idx[t]
            ids[0, m, 0] = j
            m += chosen[j] == l
        if m == 0:
            continue
        top = (m + 3) & -4
        if lam:
            for k in range(top):
                j = int(ids[0, min(k, m - 1), 0])
                s[0, k, 0], s[0, k, 1], s[0, k, 2], s[0, k, 3] = lambert.sample_in_lanes(
                    iz[j], work[j, 1], u2[j])
        else:
            for k in range(top):
                j = int(ids[0, min(k, m - 1), 0])
                s[0, k, 0], s[0, k, 1], s[0, k, 2], s[0, k, 3] = microfacet.sample_in_lanes(
                    microfacet.GGX, p[j * step][o0:o1], nch, ix[j], iy[j], iz[j], work[j, 1],
                    u2[j])
        for k in range(m):
            j = int(ids[0, k, 0])
            ox[j], oy[j], oz[j], pdf[j] = s[0, k, 0], s[0, k, 1], s[0, k, 2], s[0, k, 3]


@inline_kernel
def mixture_draw(kinds, offs, p, step, nch, idx, n, ix, iy, iz, u1, u2, ox, oy, oz, pdf, weight,
                 sel, work, chosen):
    """Draw wo_j given wi_j: pick a lobe with ``u1`` (then reuse ``u1`` rescaled within its
    share), sample it with ``(u1', u2)``.

    Writes wo and ``pdf``: the chosen lobe's density (the mixture's only for a single lobe; see
    :func:`mixture_batch`), inf for a delta lobe, 0 for no sample. Zeroes ``weight[j, :nch]``,
    but for a delta lobe, whose weight is its reflectance over the probability of picking it.
    ``sel`` holds the selection probabilities (:func:`mixture_selection`; not read for a
    single lobe); ``work`` (rows of 2) and ``chosen`` are work space indexed like the items.
    """
    nl = kinds.shape[0]
    for t in range(n):
        j = idx[t]
        c, w, lo, u = nl - 1, 1.0, 0.0, u1[j]
        if nl > 1:
            # the first lobe l with u < sel[0] + ... + sel[l] (the last if none), without
            # branches on u, a coin toss that a branch predictor misses: the sums only grow,
            # so the lobes passed are the first c
            c, acc = 0, 0.0
            for l in range(nl - 1):
                acc += sel[j, l]
                past = u >= acc
                c += past
                lo = acc if past else lo
            w = sel[j, c]
            u = min(max((u - lo) / w, 0.0), BELOW_ONE) if w > 0.0 else u
        chosen[j], work[j, 0], work[j, 1] = c, w, u
    for l in range(nl):
        kind, o0, o1 = kinds[l], offs[l], offs[l + 1]
        if kind == K.GGX or kind == K.LAMBERT:
            _lane_draws(kind == K.LAMBERT, p, step, nch, idx, n, ix, iy, iz, u2, ox, oy, oz,
                        pdf, work, chosen, l, o0, o1)
            continue
        for t in range(n):
            j = idx[t]
            if chosen[j] == l:
                q = p[j * step][o0:o1]
                ox[j], oy[j], oz[j], pdf[j] = lobe_sample(kind, q, nch, ix[j], iy[j], iz[j],
                                                          work[j, 1], u2[j])
    for t in range(n):
        j = idx[t]
        for c in range(nch):
            weight[j, c] = 0.0
        w = work[j, 0]
        if pdf[j] == 0.0 or w <= 0.0:
            pdf[j] = 0.0
        elif pdf[j] == np.inf:
            l = chosen[j]
            q = p[j * step][offs[l]:offs[l + 1]]
            for c in range(nch):
                weight[j, c] = delta_reflectance(kinds[l], q, nch, c, iz[j]) / w


@inline_kernel
def continuous(idx, n, pdf, ids):
    """Gather the items with a continuous sample (0 < pdf < inf) into ``ids``; their count."""
    m = 0
    for t in range(n):
        j = idx[t]
        if pdf[j] > 0.0 and pdf[j] < np.inf:
            ids[m] = j
            m += 1
    return m


@inline_kernel
def cosine_over_pdf(idx, n, oz, pdf, weight):
    """``weight[j]`` (f at the sample) times cos(theta_o) / pdf: the sample's weight."""
    for t in range(n):
        j = idx[t]
        s = oz[j] / pdf[j]
        for c in range(weight.shape[1]):
            weight[j, c] *= s


#: Rows of a query set ``q[s] (QUERY_ROWS, n)`` of :func:`mixture_batch`, an item per column:
#: the direction drawn (set DRAW) or weighed (set PAIR) given the GIVEN one, each a unit vector
#: in the local frame (3 rows), and the density of DRAWN given GIVEN (PDF). The query sets, the
#: first index of ``q`` and of the values ``f``: a given pair, and a draw.
DRAWN, GIVEN, PDF, QUERY_ROWS = 0, 3, 6, 7
PAIR, DRAW = 0, 1


@kernel(linked=AS_LOWERED)
def mixture_batch(kinds, offs, p, step, nch, q, f, u1, u2, sel, work, chosen, lists, counts,
                  forward):
    """One pass of a mixture over a batch of items: what sampling, the densities and f need.

    A query set ``q[s]`` holds the given direction wi (rows GIVEN), the other direction wo
    (rows DRAWN) and a density (row PDF); ``lists[k][:counts[k]]`` are item lists:

    - at the items ``lists[0]``: the lobes' selection probabilities at wi (set PAIR) into
      ``sel``;
    - at ``lists[1]``: draw wo in set DRAW with the uniform pair (u1_j, u2_j) (see
      :func:`mixture_draw`); its row PDF receives the mixture's density, ``f[DRAW, j]`` the
      weight f cos / pdf of continuous samples (``lists[4]`` collects them);
    - in set PAIR, at ``lists[2]``: f into ``f[PAIR, j]``; at ``lists[3]``: the density of wo.

    f is evaluated as f(wi, wo) with ``forward``, else as f(wo, wi) (the renderer's order, which
    draws the direction towards the light given the one towards the viewer). One kernel serves
    the array drivers and the renderer's shading, compiled once for both, and a batch costs
    one call.
    """
    if kinds.shape[0] > 1:
        g = q[PAIR]
        mixture_selection(kinds, offs, p, step, nch, lists[0], counts[0], g[GIVEN],
                          g[GIVEN + 1], g[GIVEN + 2], sel)
    d = q[DRAW]
    mixture_draw(kinds, offs, p, step, nch, lists[1], counts[1], d[GIVEN], d[GIVEN + 1],
                 d[GIVEN + 2], u1, u2, d[DRAWN], d[DRAWN + 1], d[DRAWN + 2], d[PDF], f[DRAW], sel,
                 work, chosen)
    sampled = continuous(lists[1], counts[1], d[PDF], lists[4])
    a, b = (GIVEN, DRAWN) if forward else (DRAWN, GIVEN)
    # both query sets through one call of each: each call site inlines every family
    for s in (PAIR, DRAW):
        ev, nev = (lists[2], counts[2]) if s == PAIR else (lists[4], sampled)
        pd, npd = (lists[3], counts[3]) if s == PAIR else (lists[4], sampled)
        if s == DRAW and kinds.shape[0] == 1:
            npd = 0  # a single lobe's draw has its density already
        g = q[s]
        mixture_pdf(kinds, offs, p, step, nch, pd, npd, g[GIVEN], g[GIVEN + 1], g[GIVEN + 2],
                    g[DRAWN], g[DRAWN + 1], g[DRAWN + 2], sel, g[PDF])
        for t in range(nev):
            for c in range(nch):
                f[s, ev[t], c] = 0.0
        mixture_eval(kinds, offs, p, step, nch, ev, nev, g[a], g[a + 1], g[a + 2], g[b],
                     g[b + 1], g[b + 2], f[s])
    cosine_over_pdf(lists[4], sampled, d[DRAWN + 2], d[PDF], f[DRAW])


# --- array drivers ---------------------------------------------------------------------------

@intrinsic
def with_last_axis(typingctx, arr, size):
    """``arr``, a C-contiguous array whose last axis has ``size`` entries (a constant; the
    caller vouches for it), with that length and the strides made constants of the code.

    numba addresses ``a[k, c]`` of a C array with the shape it reads at run time, so LLVM sees
    rows of an unknown stride: it vectorises no loop that writes such rows (``out[k, c]``).
    With the length a constant the rows are interleaved groups it vectorises. The view
    shares ``arr``'s memory (a reference of its own where numba counts references)."""
    if not (isinstance(arr, types.Array) and arr.layout == "C" and arr.ndim >= 1
            and isinstance(size, types.IntegerLiteral)):
        return None
    n = size.literal_value

    def codegen(context, builder, signature, args):
        src = context.make_array(signature.args[0])(context, builder, args[0])
        view = context.make_array(signature.return_type)(context, builder)
        cgutils.copy_struct(view, src)
        shape = cgutils.unpack_tuple(builder, src.shape)
        shape[-1] = context.get_constant(types.intp, n)
        step = context.get_constant(types.intp, context.get_abi_sizeof(
            context.get_data_type(arr.dtype)))
        strides = [step]
        for extent in reversed(shape[1:]):
            strides.insert(0, builder.mul(strides[0], extent))
        view.shape = cgutils.pack_array(builder, shape)
        view.strides = cgutils.pack_array(builder, strides)
        # a new reference to arr's memory (a no-op in kernels without reference counting)
        return impl_ret_borrowed(context, builder, signature.return_type, view._getvalue())

    return arr(arr, size), codegen


@kernel(linked=AS_LOWERED)
def lobe_eval_block(kind, q, nch, wi, wo, out):
    """:func:`lobe_eval_rows` on a block of rows: ``wi``, ``wo`` (m, 3) and ``out`` (m, nch),
    C-contiguous.

    Three channels (RGB) are compiled apart with nch a constant: then each family's loop over
    the rows is free of the loop over channels it holds, and LLVM vectorises it (with nch read
    at run time the channels stay an inner loop of unknown length, and the rows do not
    vectorise). Other channel counts go one pair at a time through :func:`lobe_value`, so that
    the families' formulas are not compiled into this kernel a second time."""
    wi = with_last_axis(wi, 3)
    wo = with_last_axis(wo, 3)
    if nch == 3:
        lobe_eval_rows(kind, q, 3, wi, wo, with_last_axis(out, 3))
    else:
        for k in range(wi.shape[0]):
            lobe_value(kind, q, nch, wi[k, 0], wi[k, 1], wi[k, 2], wo[k, 0], wo[k, 1], wo[k, 2],
                       out, k)


@intrinsic(prefer_literal=True)
def stack_array(typingctx, n0, n1, n2):
    """A float64 array (n0, n1, n2), the lengths constants, on the stack of the kernel that the
    call is compiled into (one array per call site, whatever loop it stands in), its values
    undefined: work space that LLVM knows no other array to alias. The middle axis is the
    contiguous one (``a[i, :, c]`` are adjacent), so that a loop over it, writing ``a[i, k, c]``
    for a few fixed i and c as the families' derivatives do, stores whole vectors."""
    if not all(isinstance(n, types.IntegerLiteral) for n in (n0, n1, n2)):
        return None
    shape = [n0.literal_value, n1.literal_value, n2.literal_value]
    array = types.Array(types.float64, 3, "A")

    def codegen(context, builder, signature, args):
        item = context.get_data_type(types.float64)
        data = cgutils.alloca_once(builder, ir.ArrayType(item, shape[0] * shape[1] * shape[2]))
        view = context.make_array(array)(context, builder)
        intp = [context.get_constant(types.intp, v) for v in
                shape + [8 * shape[1] * shape[2], 8, 8 * shape[1]]]
        context.populate_array(view, data=builder.bitcast(data, view.data.type),
                               shape=cgutils.pack_array(builder, intp[:3]),
                               strides=cgutils.pack_array(builder, intp[3:]),
                               itemsize=intp[4], meminfo=None)
        return view._getvalue()

    return array(n0, n1, n2), codegen


#: Rows per block of :func:`eval_array`: a block of wi, wo and out (12 kB) stays in the
#: first-level cache while each lobe in turn adds to it.
ROWS = 256


@inline_kernel
def _off_unit(a, b, k, low, high):
    """1 if the squared length of row k of ``a`` or ``b`` is outside [low, high] (NaN
    included), else 0 (a select, not a branch)."""
    si = a[k, 0] * a[k, 0] + a[k, 1] * a[k, 1] + a[k, 2] * a[k, 2]
    so = b[k, 0] * b[k, 0] + b[k, 1] * b[k, 1] + b[k, 2] * b[k, 2]
    return 0 if (si >= low and si <= high and so >= low and so <= high) else 1


@kernel(linked=AS_LOWERED)
def eval_rows(kinds, offs, p, nch, wi, wo, out, low, high):
    """Set ``out[k, :nch]`` to f(wi_k, wo_k), the sum of the lobes, at every row of a block
    (see :func:`lobe_eval_block`); returns the number of rows where the squared length of wi
    or wo is outside [low, high] (NaN included).

    With three channels, the Lambertian lobes are summed into one albedo that sets ``out``
    in the pass that screens the lengths, which reads every coordinate of the rows anyway
    (as a pass of its own, the Lambertian term ran one row at a time and cost as much as
    the screen: a sixth of ``lambert + ggx``); without a Lambertian lobe that albedo is 0."""
    a = with_last_axis(wi, 3)
    b = with_last_axis(wo, 3)
    bad = 0
    if nch == 3:
        d0 = d1 = d2 = 0.0
        for l in range(kinds.shape[0]):
            if kinds[l] == K.LAMBERT:
                d0 += p[offs[l]]
                d1 += p[offs[l] + 1]
                d2 += p[offs[l] + 2]
        o = with_last_axis(out, 3)
        for k in range(a.shape[0]):
            bad += _off_unit(a, b, k, low, high)
            v = lambert.per_albedo(a[k, 2], b[k, 2])  # f = rho / pi
            o[k, 0] = d0 * v
            o[k, 1] = d1 * v
            o[k, 2] = d2 * v
        for l in range(kinds.shape[0]):
            if kinds[l] != K.LAMBERT:
                lobe_eval_block(kinds[l], p[offs[l]:offs[l + 1]], 3, wi, wo, out)
        return bad
    for k in range(out.shape[0]):
        for c in range(nch):
            out[k, c] = 0.0
    for l in range(kinds.shape[0]):
        lobe_eval_block(kinds[l], p[offs[l]:offs[l + 1]], nch, wi, wo, out)
    for k in range(a.shape[0]):
        bad += _off_unit(a, b, k, low, high)
    return bad


@threaded_kernel("wi", "wo", "out", align=ROWS)
def eval_array(kinds, offs, p, nch, wi, wo, out, low, high):
    """Set ``out`` (n, C) to f(wi, wo); returns the number of pairs where the squared length of
    wi or wo is outside [low, high] (NaN included): the screen of unit vectors, made here
    while the rows are in cache (as a pass of its own it cost a sixth of the time).

    Blocks of :data:`ROWS` rows, on all cores; per block, one pass per lobe over its rows,
    each a loop over a single formula that LLVM vectorises (see :func:`lobe_eval_block`).
    ``out`` is written before it is read, so a freshly allocated array costs one page fault
    per page (adding to the zeros of ``np.zeros`` cost two: the read maps the shared zero
    page, the write then copies it)."""
    n = wi.shape[0]
    bad = 0
    for b in range((n + ROWS - 1) // ROWS):
        lo = b * ROWS
        hi = min(n, lo + ROWS)
        bad += eval_rows(kinds, offs, p, nch, wi[lo:hi], wo[lo:hi], out[lo:hi], low, high)
    return bad


@kernel(linked=OPTIMISED)
def grad_array(kinds, offs, p, nch, wi, wo, out, d):
    """Add f(wi, wo) to ``out`` (n, C) and set ``d[j, k, c]`` (P, n, C), zeroed by the caller, to
    df_c / dp[j] at pair k for every packed parameter p[j] (0 for choice codes), one pair at a
    time on one thread: the tests' oracle for the fit's gradient pass, which uses the same
    per-family kernels."""
    for k in range(wi.shape[0]):
        ix, iy, iz, ox, oy, oz = wi[k, 0], wi[k, 1], wi[k, 2], wo[k, 0], wo[k, 1], wo[k, 2]
        for l in range(kinds.shape[0]):
            lobe_derivatives(kinds[l], p[offs[l]:offs[l + 1]], nch, ix, iy, iz, ox, oy, oz, out,
                             k, d[offs[l]:offs[l + 1]])


#: Directions per batch of the threaded drivers of :func:`mixture_batch`.
BATCH = 256


@kernel(linked=AS_LOWERED)
def _pdf_batch(kinds, offs, p, nch, wi, wo, out, k0, m, space):
    """:func:`pdf_array` for the m directions from k0 on, in the work space ``space``
    (:func:`_batch_space`)."""
    q, f, u, sel, work, chosen, lists, counts = space
    for t in range(m):
        for a in range(3):
            q[PAIR, GIVEN + a, t], q[PAIR, DRAWN + a, t] = wi[k0 + t, a], wo[k0 + t, a]
        lists[0, t] = lists[3, t] = t
    counts[0] = counts[3] = m
    mixture_batch(kinds, offs, p.reshape((1, p.shape[0])), 0, nch, q, f, u[0], u[1], sel, work,
                  chosen, lists, counts, True)
    for t in range(m):
        out[k0 + t] = q[PAIR, PDF, t]


@kernel(linked=AS_LOWERED)
def _sample_batch(kinds, offs, p, nch, wi, u, wo, pdf, weight, k0, m, space):
    """:func:`sample_array` for the m directions from k0 on (see :func:`_pdf_batch`)."""
    q, f, uu, sel, work, chosen, lists, counts = space
    for t in range(m):
        for a in range(3):
            q[PAIR, GIVEN + a, t] = q[DRAW, GIVEN + a, t] = wi[k0 + t, a]
        uu[0, t], uu[1, t] = u[k0 + t, 0], u[k0 + t, 1]
        lists[0, t] = lists[1, t] = t
    counts[0] = counts[1] = m
    mixture_batch(kinds, offs, p.reshape((1, p.shape[0])), 0, nch, q, f, uu[0], uu[1], sel, work,
                  chosen, lists, counts, True)
    for t in range(m):
        for a in range(3):
            wo[k0 + t, a] = q[DRAW, DRAWN + a, t]
        pdf[k0 + t] = q[DRAW, PDF, t]
        for c in range(nch):
            weight[k0 + t, c] = f[DRAW, t, c]


@allocating_kernel(linked=AS_LOWERED)
def _batch_space(nl, nch):
    """Work space of :func:`mixture_batch` for BATCH items of ``nl`` lobes: query sets, values,
    the uniform pair, selection, work and chosen, five lists and their counts. One serves a
    driver's batches in turn: every batch writes what it reads of it (allocated and zeroed per
    batch, it was a quarter of ``Model.pdf``'s time on one thread)."""
    return (np.zeros((2, QUERY_ROWS, BATCH)), np.zeros((2, BATCH, nch)), np.zeros((2, BATCH)),
            np.zeros((BATCH, nl)), np.zeros((BATCH, 2)), np.zeros(BATCH, np.int64),
            np.zeros((5, BATCH), np.int64), np.zeros(4, np.int64))


@threaded_kernel("wi", "wo", "out", align=BATCH)
def pdf_array(kinds, offs, p, nch, wi, wo, out):
    n = wi.shape[0]
    space = _batch_space(kinds.shape[0], nch)
    for b in range((n + BATCH - 1) // BATCH):
        _pdf_batch(kinds, offs, p, nch, wi, wo, out, b * BATCH, min(BATCH, n - b * BATCH),
                   space)


@threaded_kernel("wi", "u", "wo", "pdf", "weight", align=BATCH)
def sample_array(kinds, offs, p, nch, wi, u, wo, pdf, weight):
    n = wi.shape[0]
    space = _batch_space(kinds.shape[0], nch)
    for b in range((n + BATCH - 1) // BATCH):
        _sample_batch(kinds, offs, p, nch, wi, u, wo, pdf, weight, b * BATCH,
                      min(BATCH, n - b * BATCH), space)


@kernel(linked=OPTIMISED)
def _edge_warp(t):
    """u = 10t^3 - 15t^4 + 6t^5 and du/dt = 30 t^2 (1 - t)^2 (the fade curve of Perlin 2002,
    "Improving Noise", SIGGRAPH): samplers have sqrt-like or logarithmic behaviour at the edges
    of their square (theta_h ~ sqrt(1 - u); Beckmann and Ward slopes grow like sqrt(-ln u)),
    and where they are unbounded their edges meet the horizon. A Jacobian with a double zero at
    the edges flattens both and shrinks the integrand in those edge strips, so a cut there
    costs little: against 3t^2 - 2t^3 (a simple zero), Beckmann lobes need half the panels
    (measured on the energy check's grids), other families about as many.

    The curve is odd about t = 1/2, u(1 - t) = 1 - u(t): above 1/2 it is evaluated as 1 minus
    the lower half, which keeps the digits of 1 - u that samplers use near u = 1, and u stays
    below 1 as uniform numbers must.
    """
    s = min(t, 1.0 - t)
    g = s * s * s * (10.0 + s * (6.0 * s - 15.0))
    return (g if t <= 0.5 else min(1.0 - g, BELOW_ONE)), 30.0 * s * s * (1.0 - s) * (1.0 - s)


@kernel(linked=AS_LOWERED)
def _panel(kind, q, nch, term, ix, iy, iz, x0, y0, h, xs, ws, f, acc, zone, node):
    """Tensor Gauss rule (xs, ws on [0, 1]) of f cos / pdf over one square panel into ``acc``.

    Node (a, b) leaves its zone (see ``lobe_weight``) in ``zone[a, b]`` and its integrand in
    ``node[a, b, :nch]`` (0 where invalid). Returns a bit mask of the zones seen (bit zone + 1),
    the largest step of the integrand between 4-neighbours in two nonzero zones (the jump that
    the rule sees across a cut) and the largest |integrand| at any node.
    """
    n = xs.shape[0]
    for c in range(nch):
        acc[c] = 0.0
    seen = 0
    peak = 0.0
    for a in range(n):
        u1, j1 = _edge_warp(x0 + h * xs[a])
        for b in range(n):
            u2, j2 = _edge_warp(y0 + h * xs[b])
            z = lobe_weight(kind, q, nch, term, ix, iy, iz, u1, u2, f)
            zone[a, b] = z
            seen |= 1 << (z + 1)
            for c in range(nch):
                node[a, b, c] = f[0, c] * j1 * j2 if z > 0 else 0.0  # f is stale where z <= 0
                acc[c] += node[a, b, c] * ws[a] * ws[b] * h * h
                peak = max(peak, abs(node[a, b, c]))
    step = 0.0
    if _straddles(seen):
        for a in range(n):
            for b in range(n):
                if zone[a, b] > 0:
                    step = max(step, _step(zone, node, nch, n, a, b, a - 1, b),
                               _step(zone, node, nch, n, a, b, a + 1, b),
                               _step(zone, node, nch, n, a, b, a, b - 1),
                               _step(zone, node, nch, n, a, b, a, b + 1))
    return seen, step, peak


@kernel(linked=AS_LOWERED)
def _straddles(seen):
    """Whether a zone mask (bit zone + 1) holds two zones other than 0: samples invalid for
    another reason than the horizon mark no cut."""
    rest = seen & ~2
    return rest & (rest - 1) != 0


@kernel(linked=AS_LOWERED)
def _step(zone, node, nch, n, a, b, a2, b2):
    """Largest change of the integrand from node (a, b) to node (a2, b2) if the latter is inside
    the n x n grid and in another nonzero zone, else 0."""
    if not (0 <= a2 < n and 0 <= b2 < n) or zone[a2, b2] == 0 or zone[a2, b2] == zone[a, b]:
        return 0.0
    d = 0.0
    for c in range(nch):
        d = max(d, abs(node[a, b, c] - node[a2, b2, c]))
    return d


@kernel(linked=AS_LOWERED)
def _estimate(kind, q, nch, term, ix, iy, iz, x0, y0, h, rules, f, val, lo, e, zone, node):
    """High-order value of a panel into ``val``, its per-channel error estimate into ``e``.

    The estimate is the difference to the embedded low-order rule, unless the panel straddles a
    cut: where its nodes and corners fall in two zones (see ``lobe_weight``: the horizon, or a
    seam between two pieces of the integrand) it may jump along the cut, which the two rules
    can miss alike. Such a panel's estimate is at least a tenth of its area times the jump seen
    across the cut: the largest change of the integrand between neighbouring nodes, or between
    a corner and its nearest node, in two zones (0 on the invalid side; failing such pairs, the
    largest value seen). A jump costs at most the panel's area times its size; where the
    integrand is continuous across the cut (a microfacet's G1(wo) falls to 0 at the horizon, a
    kink joins two pieces) neighbours across it differ little, and less as panels shrink, so
    refinement follows the cut only until its panels are small enough.
    """
    xs_hi, ws_hi, xs_lo, ws_lo, corners = rules
    seen, step, peak = _panel(kind, q, nch, term, ix, iy, iz, x0, y0, h, xs_hi, ws_hi, f, val,
                              zone, node)
    # the corners as a 2 x 2 "rule" of _panel (one copy of the inlined integrand per kernel,
    # not two), into rows 1 and 2 of zone and node (C-contiguous views, so _panel compiles
    # once), which hold none of the high rule's corners
    m = xs_hi.shape[0] - 1
    zc, nc = zone[1:3], node[1:3]
    seen_c, _, peak_c = _panel(kind, q, nch, term, ix, iy, iz, x0, y0, h, corners, corners,
                               f, lo, zc, nc)
    seen |= seen_c
    peak = max(peak, peak_c)
    for ca in range(2):
        for cb in range(2):
            z, a, b = zc[ca, cb], m * ca, m * cb
            if z != 0 and zone[a, b] != 0 and z != zone[a, b]:
                for c in range(nch):
                    step = max(step, abs(nc[ca, cb, c] - node[a, b, c]))
    seen_lo, step_lo, peak_lo = _panel(kind, q, nch, term, ix, iy, iz, x0, y0, h, xs_lo, ws_lo,
                                       f, lo, zone, node)
    jump = 0.0
    if _straddles(seen | seen_lo):
        seen_step = max(step, step_lo)
        jump = 0.1 * h * h * (seen_step if seen_step > 0.0 else max(peak, peak_lo))
    worst = 0.0
    for c in range(nch):
        e[c] = max(abs(val[c] - lo[c]), jump)
        worst = max(worst, e[c])
    return worst


@kernel(linked=AS_LOWERED)
def _refine(kind, q, nch, term, ix, iy, iz, rules, tol, geo, val, perr, pe, f, lo, zone, node):
    """Adaptive cubature of one term of a lobe's albedo over its sampling square: the panels
    ``geo[:n]`` (corner x, y and size), their values ``val`` and error estimates ``pe``;
    returns n.

    Panels carry a high-order and an embedded low-order Gauss-Legendre estimate; the panel with
    the largest error estimate (see ``_estimate``) is split in four until the summed estimates
    fall below ``tol`` times max(1, albedo) or the arrays are full. Where the horizon or a seam
    between pieces cuts the square (see ``_estimate``), refinement follows the cut.
    """
    capacity = geo.shape[0]
    grid = 4
    n = grid * grid
    for j in range(n):
        geo[j, 0] = (j // grid) / grid
        geo[j, 1] = (j % grid) / grid
        geo[j, 2] = 1.0 / grid
        perr[j] = _estimate(kind, q, nch, term, ix, iy, iz, geo[j, 0], geo[j, 1], geo[j, 2],
                            rules, f, val[j], lo, pe[j], zone, node)
    while n + 3 <= capacity:
        total = 0.0
        worst = 0
        for j in range(n):
            total += perr[j]
            if perr[j] > perr[worst]:
                worst = j
        peak = 0.0
        for c in range(nch):
            s = 0.0
            for j in range(n):
                s += val[j, c]
            peak = max(peak, abs(s))
        if total <= tol * max(1.0, peak):
            break
        x0, y0, h = geo[worst, 0], geo[worst, 1], 0.5 * geo[worst, 2]
        for child in range(4):
            j = worst if child == 0 else n + child - 1
            geo[j, 0] = x0 + h * (child % 2)
            geo[j, 1] = y0 + h * (child // 2)
            geo[j, 2] = h
            perr[j] = _estimate(kind, q, nch, term, ix, iy, iz, geo[j, 0], geo[j, 1], h, rules,
                                f, val[j], lo, pe[j], zone, node)
        n += 3
    return n


@allocating_kernel(linked=AS_LOWERED)
def _gradient_over_panels(kind, q, nch, ix, iy, iz, geo, n, xs, ws, dout):
    """Add the integral of df/dq_j cos(theta_o) over the outgoing hemisphere to ``dout[j, c]``
    for the lobe's packed parameters q_j, by the high-order rule on panels ``geo[:n]`` of its
    sampling square.

    The albedo's derivative is the integral of the derivative (the hemisphere does not depend
    on q); the lobe's sampler at the current q is a change of variables like any other, so
    the integrand is df/dq cos / pdf at the warped nodes, on the panels refined for f itself.
    """
    m = xs.shape[0]
    g = np.zeros((1, nch))
    d = np.zeros((q.shape[0], 1, nch))
    for j in range(n):
        x0, y0, h = geo[j, 0], geo[j, 1], geo[j, 2]
        for a in range(m):
            u1, j1 = _edge_warp(x0 + h * xs[a])
            for b in range(m):
                u2, j2 = _edge_warp(y0 + h * xs[b])
                ox, oy, oz, pdf = lobe_sample(kind, q, nch, ix, iy, iz, u1, u2)
                if not (pdf > 0.0 and pdf < np.inf and oz > 0.0):
                    continue
                lobe_grad(kind, q, nch, ix, iy, iz, ox, oy, oz, g, 0, d)
                s = oz / pdf * j1 * j2 * ws[a] * ws[b] * h * h
                for i in range(q.shape[0]):
                    for c in range(nch):
                        dout[i, c] += d[i, 0, c] * s


@allocating_kernel(linked=AS_LOWERED)
def _lobe_albedo(kind, q, nch, term, ix, iy, iz, rules, tol, capacity, out, err, dout):
    """One term of a lobe's albedo into ``out`` and ``err`` (see ``_refine``), and unless
    ``dout`` is None its derivatives in the lobe's packed parameters into ``dout`` (P, C)
    (single-term, non-delta lobes: see ``_gradient_over_panels``); returns the number of
    panels used."""
    geo = np.empty((capacity, 3))
    val = np.empty((capacity, nch))
    perr = np.empty(capacity)
    pe = np.empty((capacity, nch))
    f = np.zeros((1, nch))
    lo = np.empty(nch)
    zone = np.empty((rules[0].shape[0], rules[0].shape[0]), dtype=np.int64)
    node = np.empty((rules[0].shape[0], rules[0].shape[0], nch))
    n = _refine(kind, q, nch, term, ix, iy, iz, rules, tol, geo, val, perr, pe, f, lo, zone,
                node)
    for j in range(n):
        for c in range(nch):
            out[c] += val[j, c]
            err[c] += pe[j, c]
    if dout is not None:
        _gradient_over_panels(kind, q, nch, ix, iy, iz, geo, n, rules[0], rules[1], dout)
    return n


# a row is a whole cubature; Model.albedo deals the rows out to one chunk per thread
@threaded_kernel("wi", "out", "err", "panels", "grad", rows_per_thread=1, chunks_per_thread=1,
                 align=1)
def albedo_array(kinds, offs, p, nch, wi, rules, tol, capacity, out, err, panels, grad):
    """Directional albedo per incident direction: delta lobes exactly, others adaptively.

    ``panels[k]`` receives the number of cubature panels spent on direction k (each costs 49
    samples: 36 + 9 Gauss nodes and 4 corners), a measure of work that load does not skew.
    Unless ``grad`` is None, it receives (n, P, C) the derivatives in the packed parameters
    ``p`` (models of single-term, non-delta lobes only: ``Model.albedo_gradient``). None is a
    type of its own, so numba leaves the derivatives out of that compilation (a first
    ``check`` compiles the albedo without them, 1.8 s less).
    """
    for k in range(wi.shape[0]):
        ix, iy, iz = wi[k, 0], wi[k, 1], wi[k, 2]
        for l in range(kinds.shape[0]):
            kind = kinds[l]
            q = p[offs[l]:offs[l + 1]]
            if is_delta(kind):
                for c in range(nch):
                    out[k, c] += delta_reflectance(kind, q, nch, c, iz)
            elif iz > 0.0:
                for term in range(lobe_terms(kind)):
                    # two calls: one variable holding None or a slice would be typed Optional,
                    # and numba would compile the derivatives into both
                    if grad is None:
                        panels[k] += _lobe_albedo(kind, q, nch, term, ix, iy, iz, rules, tol,
                                                  capacity, out[k], err[k], None)
                    else:
                        panels[k] += _lobe_albedo(kind, q, nch, term, ix, iy, iz, rules, tol,
                                                  capacity, out[k], err[k],
                                                  grad[k, offs[l]:offs[l + 1]])
