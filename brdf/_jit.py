"""The one place that decides how numba compiles the library's kernels.

Kernels are cached to disk (:func:`brdf._kernel_cache.quick_loading`) so only the first run in
an environment pays for compilation. Fast-math flags exclude ``nnan`` and ``ninf``: kernels test
for NaN and rely on ``inf`` (the pdf of a delta lobe), which the full fast-math set would let
LLVM discard. Division follows IEEE (``error_model="numpy"``): a zero divisor gives inf or NaN,
which the kernels treat as an invalid sample, instead of raising, and the loops stay free of
checks that block SIMD.

Where the cache lives, when it is stale and how it loads is :mod:`brdf._kernel_cache`.

The typing hooks below, the private linkage of callees, ``_nrt=False``, the twins that take
Python's calls of kernels without CPython wrappers, the removal of numba's LLVM-lock
callbacks, the quicker array-operator typing and IR variable lists, and the remembered call
types reach into numba internals, so ``pyproject.toml`` pins numba to the minor release
``tests/test_jit.py`` has passed on; widen the pin only after that test passes on the new one.
"""

import contextlib
import functools
import inspect
import itertools
import platform
import threading

import llvmlite.binding as ll
from llvmlite import ir
import numba
import numpy as np
from numba.core import cgutils, codegen, compiler, datamodel, types
from numba.core import ir as numba_ir
from numba.core.typing import npydecl
from numba.core.compiler_lock import global_compiler_lock
from numba.extending import intrinsic

from ._kernel_cache import quick_loading
from ._threads import ROWS_PER_THREAD, thread_count

FASTMATH = {"nsz", "arcp", "contract", "afn", "reassoc"}
#: numba's options for every kernel. Without a C-callable wrapper (``no_cfunc_wrapper``: the
#: entry point of numba's first-class functions, which no kernel is passed as): numba made one
#: for every kernel and inline kernel, and lowering, optimising and compiling them was 7 % of
#: compiling every kernel in one process. Nor with numba's ``cache=True``: :func:`quick_loading`
#: gives each kernel a disk cache made on first use.
_OPTIONS = dict(fastmath=FASTMATH, error_model="numpy", no_cfunc_wrapper=True)


def _target_features():
    """The CPU features numba compiles kernels for, as numba chooses them:
    ``NUMBA_CPU_FEATURES`` where set, else the host's."""
    if numba.config.CPU_FEATURES is not None:
        return numba.config.CPU_FEATURES.split(",")
    return ll.get_host_cpu_features().flatten().split(",")


#: Whether the kernels' target multiplies 64-bit integers in SIMD lanes (AVX-512DQ's
#: ``vpmullq``; AVX2 has no such instruction): then the random streams' SplitMix64 hashes
#: run in SIMD lanes too. Kernels read it as a constant when they compile, and numba's disk
#: cache keeps their machine code per CPU and feature set.
SIMD_INT64_PRODUCTS = "+avx512dq" in _target_features()


def _private_copies(codegen_library):
    """Patch numba's ``CPUCodeLibrary`` so that the functions linked into a library that holds
    any of this package's code get internal linkage before it is optimised.

    numba links every called function into its caller's module as a weak (``linkonce_odr``,
    or ``weak_odr`` for a parallel loop's body) definition, and the process's dynamic linker
    binds all calls to a function to the first definition it loaded. Two copies of a function
    are not the same machine code: each is optimised again in its caller's module, under
    fast-math reassociation. So a render's bytes depended on what ran before it in the
    process: on tracing rays from Python first, or on whether its parallel loop had just
    been compiled or came from the disk cache (the image moved by 1e-16). With private
    copies, each kernel runs its own code, whatever was loaded before. The library's own
    functions keep their linkage, so other modules still link against them. Copies of an
    :func:`inline_kernel` are marked ``alwaysinline`` here too. A kernel linked AS_LOWERED
    (see :func:`kernel`) is left as it is: its callers do both to its code."""
    finalize, optimize = codegen_library.finalize, codegen_library._optimize_final_module

    def finalize_owning(library):
        library._brdf_own = {fn.name for fn in library._final_module.functions
                             if not fn.is_declaration}
        finalize(library)

    def optimize_private(library):
        if getattr(library, "brdf_linked", None) == AS_LOWERED:
            return  # its callers set the linkage of its functions and optimise them
        own = getattr(library, "_brdf_own", None)
        module = library._final_module
        linked = [fn for fn in module.functions
                  if not fn.is_declaration and own is not None and fn.name not in own]
        if _holds_package_code(module):
            for fn in linked:
                fn.linkage = ll.Linkage.internal
                if fn.name in _ALWAYS_INLINE:
                    fn.add_function_attribute("alwaysinline")
        optimize(library)

    codegen_library.finalize = finalize_owning
    codegen_library._optimize_final_module = optimize_private
    codegen_library._brdf_private_copies = True


# numba's mangled names spell each part of a qualified name as <length><part>
_SYMBOL_PREFIX = "_ZN4brdf"


def _holds_package_code(module):
    """Whether the LLVM ``module`` defines or calls any of this package's functions."""
    return any(fn.name.startswith(_SYMBOL_PREFIX) for fn in module.functions)


#: Qualified names of the kernels compiled for numba's own target machine, not
#: :func:`package_machine` (:func:`narrow_vectors`); numba names a kernel's code library by
#: its name qualified within its module.
_NARROW = set()


def narrow_vectors(dispatcher):
    """``dispatcher`` (a kernel), optimised and compiled for numba's own target machine,
    whose tuning may prefer 256-bit vectors to the 512-bit ones of :func:`package_machine`.
    For kernels that ran slower with the wider vectors (the fit's loss pass). Its callees are
    compiled as they are anywhere else."""
    _NARROW.add(dispatcher.py_func.__qualname__)
    return dispatcher


#: Target machines for this package's code, by (numba codegen, optimisation level).
_MACHINES = {}


def package_machine(codegen_, opt):
    """The LLVM target machine this package's kernels are optimised and compiled for: numba's
    own (its CPU, features, relocation and code models) at optimisation level ``opt``, except
    that on a CPU with AVX-512 it prefers 512-bit vectors.

    LLVM tunes Intel's server cores (``prefer-256-bit``, Skylake-SP and later) to vectorise
    with 256-bit vectors, since the first AVX-512 cores slowed their clocks for wider ones.
    On an Intel ``emeraldrapids`` host, alternating runs: the fit's loss-and-gradient pass
    (``bench_fit.py``, two threads) went from 228-263 to 321-342 M samples/s; evaluation,
    renders and compile times were the same within noise, and so were the render's bytes.
    The loss pass alone ran about a tenth slower with the wider vectors, so its kernels keep
    numba's machine (:func:`narrow_vectors`). Only this package's code is affected: numba's
    machine, which compiles everything else in the process, is left as it is."""
    key = (id(codegen_), opt)
    machine = _MACHINES.get(key)
    if machine is None:
        options = {"opt": opt}
        codegen_._customize_tm_options(options)  # numba's CPU, features, relocation
        if "+avx512f" in options.get("features", "").split(","):
            options["features"] += ",-prefer-256-bit"
        machine = _MACHINES[key] = ll.Target.from_triple(
            ll.get_process_triple()).create_target_machine(**options)
    return machine


def _wide(library, module):
    """Whether ``library``, whose LLVM module is ``module``, is optimised and compiled for
    :func:`package_machine`: it holds this package's code and is no :func:`narrow_vectors`
    kernel's."""
    return _holds_package_code(module) and library.name not in _NARROW


@contextlib.contextmanager
def _tuned(library, module):
    """Within the block, numba's pass builders take :func:`package_machine` if ``library``
    is :func:`_wide` (LLVM's vectorisers read the preferred vector width from the machine).
    Compiling holds numba's compiler lock, so no other thread builds passes meanwhile."""
    codegen_ = library.codegen
    saved = codegen_._tm
    if _wide(library, module):
        codegen_._tm = package_machine(codegen_, numba.config.OPT)
    try:
        yield
    finally:
        codegen_._tm = saved


def _tuned_passes(codegen_library):
    """Patch numba's ``CPUCodeLibrary`` so that the function and module passes over a
    :func:`_wide` library run for :func:`package_machine` (its machine code is generated for
    it, in :func:`_package_machine_code`)."""
    optimize_functions = codegen_library._optimize_functions
    optimize_final_module = codegen_library._optimize_final_module

    def optimize_functions_tuned(library, ll_module):
        with _tuned(library, ll_module):
            optimize_functions(library, ll_module)

    def optimize_final_module_tuned(library):
        with _tuned(library, library._final_module):
            optimize_final_module(library)

    codegen_library._optimize_functions = optimize_functions_tuned
    codegen_library._optimize_final_module = optimize_final_module_tuned
    codegen_library._brdf_tuned_passes = True


# the module passes' patch wraps the private copies', whose linkage it keeps
if not getattr(codegen.CPUCodeLibrary, "_brdf_private_copies", False):
    _private_copies(codegen.CPUCodeLibrary)
if not getattr(codegen.CPUCodeLibrary, "_brdf_tuned_passes", False):
    _tuned_passes(codegen.CPUCodeLibrary)


#: How a kernel that only other kernels call is linked into them (``linked=`` of
#: :func:`kernel` and :func:`allocating_kernel`; an :func:`inline_kernel` is OPTIMISED): its
#: module optimised first, as any kernel's (OPTIMISED), or as numba lowered it (AS_LOWERED),
#: left for each caller's optimisation to do once over the whole.
OPTIMISED, AS_LOWERED = "optimised", "as lowered"


class _LinkedCompiler(compiler.Compiler):
    """numba's compiler, marking the code library it makes as that of a kernel only other
    kernels call (``brdf_linked``: how it is linked into them; see :func:`kernel`)."""

    linked = OPTIMISED

    def compile_extra(self, func):
        if self.state.library is None:  # as numba's lowering would make it
            library = self.state.targetctx.codegen().create_library(func.__qualname__)
            library.enable_object_caching()
            library.brdf_linked = self.linked
            self.state.library = library
        return super().compile_extra(func)


class _LinkedAsLoweredCompiler(_LinkedCompiler):
    linked = AS_LOWERED


_COMPILERS = {OPTIMISED: _LinkedCompiler, AS_LOWERED: _LinkedAsLoweredCompiler}


def _njit(fn, linked, **options):
    """numba's dispatcher of ``fn`` with :data:`_OPTIONS` and ``options``, for a kernel linked
    ``linked`` into its callers (None: one Python calls, compiled as numba would).

    A kernel only kernels call is compiled without numba's CPython wrapper, the function that
    unboxes Python's arguments, calls the kernel and boxes its result: numba lowered and
    optimised one for every such kernel, and callers linked them in, though only tests called
    them (every kernel in one process, on an empty cache: 82-85 s with them, 75 s without).
    Python calls of such a kernel run a twin (:func:`_twin_for_python`)."""
    if linked is None:
        return numba.njit(fn, **_OPTIONS, **options)
    return _twin_for_python(numba.njit(fn, **_OPTIONS, **options, no_cpython_wrapper=True,
                                       pipeline_class=_COMPILERS[linked]), options)


class DeferredKernel:
    """A kernel that only kernels call, its numba dispatcher made when it is first needed:
    when a caller that is compiling types its call, or on any other use (a call from Python,
    an attribute of the dispatcher), all of which it passes on to the dispatcher.

    ``import brdf.render`` defines 207 kernels, and a command loads the machine code of a few
    that Python calls; the others' dispatchers took 20 ms of every command's start to make
    (numba reads each function's signature twice, registers its type, sets up its compiler).
    Python names, its function (``py_func``) and :func:`when_made` need no dispatcher. To
    replace one of the dispatcher's attributes for a while (a test's monkeypatch), replace it
    on ``made()``: pytest restores an attribute through the object's own ``__dict__``, so its
    undo here deletes the dispatcher's attribute, and without the hook that hands Python's
    calls to the twin the next such call crashes."""

    def __init__(self, fn, make):
        vars(self).update(py_func=fn, _make=make, _made=None, _patches=[], __wrapped__=fn,
                          __module__=fn.__module__, __name__=fn.__name__,
                          __qualname__=fn.__qualname__, __doc__=fn.__doc__)

    def made(self):
        """The dispatcher, made now if it is not yet (with every :func:`when_made` patch)."""
        dispatcher = vars(self)["_made"]
        if dispatcher is None:
            with global_compiler_lock:  # held already where a caller's typing makes it
                dispatcher = vars(self)["_made"]
                if dispatcher is None:
                    dispatcher = self._make()
                    for patch in self._patches:
                        patch(dispatcher)
                    vars(self)["_made"] = dispatcher
        return dispatcher

    def __getattr__(self, name):
        return getattr(self.made(), name)

    def __setattr__(self, name, value):
        setattr(self.made(), name, value)

    def __delattr__(self, name):
        delattr(self.made(), name)

    def __call__(self, *args, **kwargs):
        return self.made()(*args, **kwargs)

    def __reduce__(self):
        return self.made().__reduce__()

    def __repr__(self):
        return f"<deferred kernel {self.__module__}.{self.__qualname__}>"


def _deferred(fn, linked, make):
    """A :class:`DeferredKernel` of ``fn`` made by ``make()`` where ``linked`` (a kernel only
    kernels call), else the dispatcher ``make()`` itself."""
    if linked is None:
        return make()
    if linked not in _COMPILERS:
        raise ValueError(f"linked={linked!r}: expected None, {OPTIMISED!r} or {AS_LOWERED!r}")
    return DeferredKernel(fn, make)


def when_made(kernel, patch):
    """Apply ``patch(dispatcher)`` to the dispatcher of ``kernel`` (a :class:`DeferredKernel`
    or a dispatcher): now if it is made, else when it is."""
    if isinstance(kernel, DeferredKernel) and vars(kernel)["_made"] is None:
        vars(kernel)["_patches"].append(patch)
    else:
        patch(kernel.made() if isinstance(kernel, DeferredKernel) else kernel)
    return kernel


#: Appended to the qualified name of a :func:`_twin_for_python` kernel's function.
TWIN_SUFFIX = "__from_python"


def _twin_for_python(dispatcher, options):
    """``dispatcher`` (compiled without CPython wrappers), its calls from Python running a
    twin: ``dispatcher.for_python()``, the same function compiled as numba would with
    ``options``, made on the first call from Python.

    numba's dispatcher calls from Python the overload its table of argument types matches,
    through its wrapper. Overloads without one stay out of the table, so a call from Python
    always asks the dispatcher to compile (``_compile_for_args``), which hands the call to the
    twin. The twin's function is a copy of the kernel's named with :data:`TWIN_SUFFIX`, so
    that numba caches and names its machine code apart; it calls the same kernels, and LLVM
    optimises it as any kernel's code (tests call it)."""
    def add_overload(cres):
        # numba's add_overload without the table entry (whose function pointer would be 0)
        dispatcher.overloads[tuple(cres.signature.args)] = cres

    twin = []

    def for_python():
        if not twin:
            fn = dispatcher.py_func
            copy = type(fn)(fn.__code__, fn.__globals__, fn.__name__, fn.__defaults__,
                            fn.__closure__)
            copy.__qualname__, copy.__module__ = fn.__qualname__ + TWIN_SUFFIX, fn.__module__
            copy.__doc__ = fn.__doc__
            twin.append(_inputs_as_writable(quick_loading(
                numba.njit(copy, **_OPTIONS, **options))))
        return twin[0]

    assert "add_overload" not in vars(dispatcher)  # numba's own, not yet wrapped
    dispatcher.add_overload = add_overload
    dispatcher._compile_for_args = lambda *args, **kws: for_python()
    dispatcher.for_python = for_python
    return dispatcher


def _environments_only(module):
    """An LLVM module that defines the environment pointers of ``module`` (numba's ``common``
    globals, which its engine looks up by name to fill in) and nothing else."""
    lines = [f'target triple = "{module.triple}"', f'target datalayout = "{module.data_layout}"']
    lines += [str(gv) for gv in module.global_variables
              if not gv.is_declaration and gv.linkage == ll.Linkage.common]
    return ll.parse_assembly("\n".join(lines))


def _package_machine_code(codegen_library):
    """Patch numba's ``JITCodeLibrary`` so that the machine code of a library of this package's
    code is generated by :func:`package_machine`, and a kernel only other kernels call (an
    :func:`inline_kernel`, or one compiled with ``linked=``) gets none: its object defines
    only its environment pointers (:func:`_environments_only`).

    Nothing runs such a kernel's own code: callers link its IR and compile it with theirs, and
    Python calls run its twin (:func:`_twin_for_python`); numba asks the engine only for the
    CPython wrapper, which it lacks, and for the environment pointer, which it fills in.
    Generating its code with LLVM's ``-O0`` code generator, on a copy of its module, took
    1.5-2 s of the 67 s in which every kernel compiled in one process (with the optimising
    one, a fifth of LLVM's code generation). The object is cached as numba caches any:
    numba's engine loads the object its cache hook hands it instead of compiling."""
    finalize_specific = codegen_library._finalize_specific

    def finalize_package_code(library):
        # numba's engine takes an object only from a library that caches its object (as all
        # kernels' do), and one loaded from the cache has its object already
        linked = getattr(library, "brdf_linked", None) is not None
        if (not library._object_caching_enabled or library._compiled_object is not None
                or not (linked or _wide(library, library._final_module))):
            finalize_specific(library)
            return
        if linked:
            code = package_machine(library.codegen, 0).emit_object(
                _environments_only(library._final_module))
        else:
            code = package_machine(library.codegen, numba.config.OPT).emit_object(
                library._final_module)
        # the hook forgets the object it hands over, and numba's cache saves it afterwards
        library._compiled_object = code
        finalize_specific(library)
        library._compiled_object, library._compiled = code, True

    codegen_library._finalize_specific = finalize_package_code
    codegen_library._brdf_package_machine_code = True


if not getattr(codegen.JITCodeLibrary, "_brdf_package_machine_code", False):
    _package_machine_code(codegen.JITCodeLibrary)


def _numba_lock_events():
    """The (acquire, release) callbacks by which numba raises its ``numba:llvm_lock`` events
    at every call into LLVM (``numba.core.base``), as llvmlite's lock holds them."""
    return [pair for pair in list(ll.ffi.lib._lock._cblist)
            if all(getattr(fn, "__module__", None) == "numba.core.base" for fn in pair)]


def _quiet_llvm_lock():
    """Stop numba's ``numba:llvm_lock`` events: numba raised two at each of the 290,000 calls
    into LLVM that compiling every kernel makes, and each event ran every timer of the
    compiles nested at that point. Compiling every kernel in one process on an empty cache
    took 70.5-72.0 s without them, 74.6-75.6 s with them. What is lost is the ``llvm_lock``
    time in a compiled overload's ``metadata["timers"]`` (0 from then on), in this process."""
    for pair in _numba_lock_events():
        ll.ffi.unregister_lock_callback(*pair)


_quiet_llvm_lock()


def _array_operators_for_arrays():
    """Patch numba's typing of NumPy's array operators (``npydecl.NumpyRulesArrayOperator``:
    ``+``, ``*``, ``<`` ... of arrays) to decline operands none of which is an array at once.

    numba tries every binary operator against that template, and it matched the operands to
    one of the ufunc's loops (NumPy's casting rules, type by type) before it declined scalars:
    each scalar ``+`` or ``<`` a kernel holds, at every round of type inference and again when
    it was lowered. It declines the same operands as before (its unpatched code returns None
    when, once ``Optional`` types are unwrapped, no operand is an array), so kernels are typed
    and compiled as before; the unary and in-place templates already test this first."""
    template = npydecl.NumpyRulesArrayOperator
    generic = template.generic

    def arrays_only(self, args, kws):
        if not any(isinstance(a.type if isinstance(a, types.Optional) else a,
                              types.ArrayCompatible) for a in args):
            return None
        return generic(self, args, kws)

    template.generic = arrays_only
    template._brdf_arrays_only = True


if not getattr(npydecl.NumpyRulesArrayOperator, "_brdf_arrays_only", False):
    _array_operators_for_arrays()


def _ir_variable_lists():
    """Patch numba's ``ir.Inst._rec_list_vars``, which lists the variables an IR statement
    reads or writes, to walk a statement's attributes in one loop.

    numba's analyses list every statement's variables again at each pass (its use-def maps
    alone: ten times per kernel), and its helper called itself for every attribute: a
    statement's location, its strings and numbers each cost a call and four ``isinstance``
    tests (4.7 million calls in a cold compile of every kernel). This one sorts each type once
    into variable, instruction, sequence, mapping or other, and recurses only into sequences
    and mappings. It lists the same variables in the same order: a ``Var``, an ``Inst``'s own
    ``list_vars()``, a list's or tuple's items and a dict's values in turn, nothing else."""
    var, inst = numba_ir.Var, numba_ir.Inst
    kinds = {}

    def kind(t):
        k = kinds[t] = (1 if issubclass(t, var) else 2 if issubclass(t, inst)
                        else 3 if issubclass(t, (list, tuple)) else 4 if issubclass(t, dict)
                        else 0)
        return k

    def collect(items, out):
        for v in items:
            k = kinds.get(type(v))
            if k is None:
                k = kind(type(v))
            if k == 1:
                out.append(v)
            elif k == 2:
                out.extend(v.list_vars())
            elif k == 3:
                collect(v, out)
            elif k == 4:
                collect(v.values(), out)

    def rec_list_vars(self, val):
        out = []
        collect((val,), out)
        return out

    numba_ir.Inst._rec_list_vars = rec_list_vars
    numba_ir.Inst._brdf_variable_lists = True


if not getattr(numba_ir.Inst, "_brdf_variable_lists", False):
    _ir_variable_lists()


def _call_types_remembered():
    """Patch numba's typing of calls of functions (``types.Function.get_call_type``: operators,
    ``math`` and NumPy functions, ``@overload`` templates) to remember the signature that a
    function type resolved for each argument types, per typing context and target.

    Type inference resolves every call of a kernel again at each of its rounds until the types
    settle, and each resolution tried the function's templates in turn until one matched (a
    kernel's ``a[i]`` tries the ``getitem`` templates before the array's): in a cold compile
    of the renderer's kernels, 14,177 of 14,716 resolutions repeated one made before and took
    3.0 of its 28.4 s. A function type holds its templates (templates registered later for a
    function make a new type), and its templates' answer depends on the argument types, so the
    remembered signature is the one numba finds again: every cached object's machine code is
    byte-identical with and without it. Failures are not remembered: numba raises them, with
    its own message, each time."""
    function = types.Function
    get_call_type = function.get_call_type
    from numba.core.target_extension import get_local_target
    remembered = {}

    def get_call_type_remembered(self, context, args, kws):
        key = (self, context, get_local_target(context), tuple(args),
               tuple(sorted(kws.items())) if kws else ())
        try:
            return remembered[key]
        except KeyError:
            pass
        except TypeError:  # an argument type that cannot be hashed
            return get_call_type(self, context, args, kws)
        sig = get_call_type(self, context, args, kws)
        if sig is not None:
            remembered[key] = sig
        return sig

    function.get_call_type = get_call_type_remembered
    function._brdf_remembered = remembered  # for the tests


if getattr(types.Function, "_brdf_remembered", None) is None:
    _call_types_remembered()


def parameter_names(fn):
    """Names of the positional parameters of the plain function ``fn``, read from its code:
    ``inspect.signature`` took 6 ms of each command's start over the package's kernels."""
    code = fn.__code__
    return code.co_varnames[:code.co_argcount]


def _without_literals(dispatcher, keep=()):
    """``dispatcher``, typed for non-literal arguments wherever a kernel calls it, except the
    parameters named in ``keep``.

    numba compiles a called function once per set of argument types, and a constant argument
    (``nch=3``, a lobe index 0, a family code) has its own literal type: the same kernel was
    compiled again for each mix of constants and variables its callers passed. Constants gain
    nothing from it here, since LLVM inlines the callee and folds them all the same."""
    resolve = dispatcher.get_call_template
    kept = {i for i, name in enumerate(parameter_names(dispatcher.py_func)) if name in keep}

    def get_call_template(args, kws):
        return resolve(tuple(a if i in kept else types.unliteral(a) for i, a in enumerate(args)),
                       {k: v if k in keep else types.unliteral(v) for k, v in kws.items()})

    dispatcher.get_call_template = get_call_template
    return _inputs_as_writable(dispatcher)


def _writable(t):
    """Type ``t`` with every read-only array in it, within tuples too, typed writable."""
    if isinstance(t, types.Array):
        return t.copy(readonly=False) if not t.mutable else t
    if not isinstance(t, types.BaseTuple):
        return t
    members = [_writable(m) for m in t.types]
    if all(a is b for a, b in zip(members, t.types)):
        return t
    uniform = all(m == members[0] for m in members)
    if isinstance(t, types.BaseNamedTuple):
        return (types.NamedUniTuple(members[0], len(members), t.instance_class) if uniform
                else types.NamedTuple(members, t.instance_class))
    return types.UniTuple(members[0], len(members)) if uniform else types.Tuple(members)


def _inputs_as_writable(dispatcher):
    """``dispatcher``, typing a read-only array argument from Python as a writable one, within
    a tuple too (the renderer's scene arrays).

    numba compiles a kernel again for each array flagged read-only (a broadcast view, a table
    read with ``np.frombuffer``, a MERL table's grid), and callers mixed both, so kernels were
    compiled two to four times. Kernels write only the output arrays their drivers allocate,
    never an input, so the flag changes nothing in the machine code."""
    typeof = dispatcher.typeof_pyval

    def typeof_pyval(value):
        return _writable(typeof(value))

    dispatcher.typeof_pyval = typeof_pyval
    return dispatcher


def _borrowing(dispatcher):
    """``dispatcher``, refusing any signature that returns a reference-counted value.

    A kernel compiled without reference counting (see :func:`kernel`) borrows its arrays
    from the caller. Returning one would hand the caller a reference it never got, and the
    caller's release of it would free the array under its owner; numba itself refuses only
    arrays the kernel did not receive."""
    add = dispatcher.add_overload

    def add_overload(cres):
        ret = cres.signature.return_type
        if datamodel.default_manager[ret].contains_nrt_meminfo():
            raise TypeError(f"kernel {dispatcher.py_func.__qualname__} returns {ret}: "
                            "a kernel compiled by brdf._jit.kernel may return only scalars")
        add(cres)

    dispatcher.add_overload = add_overload
    return dispatcher


def kernel(fn=None, *, linked=None):
    """Compile a scalar or serial kernel (cached, fast-math without nnan/ninf), without
    reference counting; ``@kernel`` or ``@kernel(linked=...)``.

    A kernel whose arguments are all scalars needs nothing more to be fast where it is called:
    LLVM inlines it into its callers once their code is linked, and their loops still
    vectorise across it. A kernel that takes arrays only borrows them from its caller, which
    holds them for the whole call, so counting references to them is pure cost: with it, every
    array argument cost two atomic operations per call (a Cornell-box path at depth 8, one
    thread: 2.23 us with them, 1.30 us without). Such a kernel may slice and write its
    arrays but not allocate one (numba refuses to compile it) nor return one
    (:func:`_borrowing` refuses); kernels that allocate use :func:`allocating_kernel`.

    ``linked`` declares a kernel that only other kernels call, and how its code is linked into
    theirs: OPTIMISED (its module optimised first, as any kernel's) or AS_LOWERED (as numba
    lowered it, for each caller's optimisation to do once over the whole). It has no CPython
    wrapper and no machine code of its own (:func:`_package_machine_code`): a call from
    Python compiles and runs a twin (:func:`_twin_for_python`), so declare only kernels that
    nothing but kernels (and tests) calls. Declaring the renderer's passes and the model and
    fitting kernels AS_LOWERED left the bytes of images, evaluations, densities and albedos
    as they were and their speed within noise, and cut a cold compile of every kernel in one
    process by about a sixth (``docs/performance.md``). Inline kernels stay OPTIMISED: linked
    as lowered too, they moved the renders' bytes, rendered the white furnace about 4 %
    slower and the fit's loss and gradient at a third of its speed."""
    if fn is None:
        return functools.partial(kernel, linked=linked)
    return _deferred(fn, linked, lambda: _borrowing(_without_literals(quick_loading(
        _njit(fn, linked, _nrt=False)))))


def nogil_kernel(fn):
    """Compile an :func:`allocating_kernel` that runs without the GIL, for Python threads
    that call it side by side (:func:`in_threads`, :func:`share_queue`): a parallel loop's
    speed without a numba ``prange`` loop's outlined body, which links everything the loop
    calls once more and optimises it anew (the renderer's ``render_pass``: 29 s of the render
    group's 89 s of compile CPU on an empty cache; :func:`brdf.render._integrator.trace_tiles`,
    which replaced it, 8 s). Read-only arrays are typed as writable
    (:func:`_inputs_as_writable`)."""
    return _inputs_as_writable(_without_literals(quick_loading(
        numba.njit(fn, **_OPTIONS, nogil=True))))


def allocating_kernel(fn=None, *, linked=None):
    """Compile a serial kernel that allocates work arrays (reference counted, as numba's
    default; otherwise as :func:`kernel`, ``linked`` included)."""
    if fn is None:
        return functools.partial(allocating_kernel, linked=linked)
    return _deferred(fn, linked, lambda: _without_literals(quick_loading(_njit(fn, linked))))


def inline_kernel(fn):
    """Compile a kernel that LLVM inlines into every caller (otherwise as :func:`kernel`).

    For functions that take arrays (a lobe's packed parameters, the output row) on hot paths,
    and the dispatchers that call a family's kernel by its kind: their callers' loops vectorise
    only with them inlined. numba's own inlining (``inline="always"``) typed and lowered each
    inlined copy again, in every caller: each driver typed the whole chain of families, and a
    cold cache compiled for minutes. Compiled once and marked ``alwaysinline`` where its code
    is linked into a caller (:data:`_ALWAYS_INLINE`), each is typed once per set of argument
    types, and the caller's machine code is the same (``lambert + ggx`` eval bit for bit).

    Unlike :func:`kernel`, a constant channel count keeps its literal type (``nch=3``): the
    callee's own loops over channels are then specialised before LLVM inlines it (with ``nch``
    read at run time, ``lambert + ggx`` eval ran at 0.4 times the speed). Other constants (a
    row index 0, a flag, a family's variant) are typed as variables, as :func:`kernel` does:
    LLVM folds them once the callee is inlined, whereas their literal types compiled the same
    functions up to four times (a first ``check`` of ``lambert + ggx`` spent 13.0 s compiling
    with them, 11.7 s without).

    As a kernel declared ``linked=`` (:func:`kernel`), it has no CPython wrapper and no
    machine code of its own (:func:`_package_machine_code`), and calls from Python run a twin
    (:func:`_twin_for_python`)."""
    return _deferred(fn, OPTIMISED, lambda: _always_inlined(_borrowing(_without_literals(
        quick_loading(_njit(fn, OPTIMISED, _nrt=False)), keep=_LITERAL))))


#: The parameters of an :func:`inline_kernel` whose constant arguments keep their literal type.
_LITERAL = ("nch",)


#: Native (mangled) names of the overloads of :func:`inline_kernel` compiled or loaded in this
#: process: their copies linked into a caller get LLVM's ``alwaysinline``.
_ALWAYS_INLINE = set()


def _always_inlined(dispatcher):
    """``dispatcher``, its overloads' names recorded in :data:`_ALWAYS_INLINE` as they are
    compiled or loaded from the cache (a caller links only overloads it has typed)."""
    add = dispatcher.add_overload

    def add_overload(cres):
        _ALWAYS_INLINE.add(cres.fndesc.mangled_name)
        add(cres)

    dispatcher.add_overload = add_overload
    return dispatcher


#: The rows a chunk of a :func:`threaded_kernel`'s call starts at a multiple of, unless the
#: kernel names its own: more than one trip of a vectorised loop's body covers (AVX-512's 8
#: float64 lanes times LLVM's interleave of 4, and its vector epilogue). A row's bits depend
#: on whether it falls in the body or the scalar remainder of such a loop (on AVX-512 hosts
#: the two round some formulas differently), so the rows of every chunk must fall where they
#: fall in one call over all rows.
VECTOR_ROWS = 64


def threaded_kernel(*rows, rows_per_thread=ROWS_PER_THREAD, chunks_per_thread=8,
                    align=VECTOR_ROWS):
    """Compile an array kernel whose loop over rows is serial and runs without the GIL, and
    call it on chunks of those rows in the threads of :func:`brdf._threads.thread_count`
    (which :func:`brdf._threads.serial_below` lowers to one): a ``prange`` loop's speed
    without numba's parallel compile (its outlined loop body and gufunc wrapper: a third of a
    first ``check``'s compile).

    A call gives each thread it uses at least ``rows_per_thread`` rows (waking a thread costs
    more than a few thousand evaluations), and cuts its rows into up to ``chunks_per_thread``
    chunks per thread, which the threads, the caller's included, take in turn as they finish
    one (1: one chunk each). ``rows`` names the arguments whose first axis is the loop's; one
    whose first axis has another length (an empty placeholder), or None, goes whole to every
    chunk. Every chunk but the first starts at a multiple of ``align`` rows: a kernel that
    works in batches of rows (lists of the lanes that chose a lobe, drawn in SIMD lanes)
    passes its batch, so that a row falls in the same place of the same batch however the
    rows are cut. The call returns the sum of the chunks' results in chunk order (None for a
    kernel without one); each row's values do not depend on the chunks."""
    def compile_rows(fn):
        names = list(inspect.signature(fn).parameters)
        dispatcher = _inputs_as_writable(quick_loading(numba.njit(fn, **_OPTIONS, nogil=True)))
        return RowThreads(dispatcher, tuple(names.index(r) for r in rows), rows_per_thread,
                          chunks_per_thread, align)
    return compile_rows


class RowThreads:
    """A :func:`threaded_kernel`: called like its dispatcher (``dispatcher``), whose other
    attributes it passes on."""

    def __init__(self, dispatcher, rows, rows_per_thread, chunks_per_thread, align):
        self.dispatcher, self.rows = dispatcher, rows
        self.rows_per_thread, self.chunks_per_thread = rows_per_thread, chunks_per_thread
        self.align = align
        functools.update_wrapper(self, dispatcher.py_func)

    def __getattr__(self, name):
        return getattr(self.dispatcher, name)

    def __call__(self, *args):
        n = args[self.rows[0]].shape[0]
        threads = min(thread_count(), n // self.rows_per_thread)
        if threads <= 1:
            return self.dispatcher(*args)
        # several chunks per thread, each thread taking the next as it finishes one: equal
        # shares waited on the slower core of a shared host, and on the woken thread's start
        chunks = min(n // self.rows_per_thread, threads * self.chunks_per_thread)
        cuts = chunk_cuts(n, chunks, self.align)
        chunks = len(cuts) - 1
        if chunks == 1:
            return self.dispatcher(*args)
        threads = min(threads, chunks)
        results = [None] * chunks
        taken = itertools.count()  # next() of a count is atomic under the GIL

        def work():
            while True:
                t = next(taken)
                if t >= chunks:
                    return
                a, b = cuts[t], cuts[t + 1]
                results[t] = self.dispatcher(*(arg[a:b] if i in self.rows and arg is not None
                                               and arg.shape[0] == n else arg
                                               for i, arg in enumerate(args)))

        in_threads(threads, work, short=True)  # what the pool has not started is dropped
        return None if results[0] is None else sum(results)


def chunk_cuts(n, chunks, align=1):
    """Where ``chunks`` chunks of ``n`` rows start and end (``chunks + 1`` numbers from 0 to
    n, or fewer where chunks would be empty): chunk t ends at ceil(n t / chunks) rounded up
    to a multiple of ``align``. With ``align`` 1, rows dealt out to the threads like cards
    (Model.albedo's) and sorted by hand make exactly one hand per chunk when there is one
    chunk per thread."""
    cuts = [0]
    for t in range(1, chunks + 1):
        end = -(-n * t // chunks)
        end = min(n, -(-end // align) * align)
        if end > cuts[-1]:
            cuts.append(end)
    return cuts


_ROW_POOL = []


def _row_pool():
    """The threads :class:`RowThreads` hands chunks to (made on first use)."""
    if not _ROW_POOL:
        from concurrent.futures import ThreadPoolExecutor
        _ROW_POOL.append(ThreadPoolExecutor(max(1, numba.config.NUMBA_NUM_THREADS - 1),
                                            thread_name_prefix="brdf-rows"))
    return _ROW_POOL[0]


def in_threads(count, work, short=False):
    """Call ``work()`` in ``count`` threads at once, this one and ``count - 1`` others, and
    return when every call has; an exception raised in any of them is raised here.

    The others are started for the call, unless the calls are ``short`` (a fit's loss pass,
    which a fit makes thousands of times): then they are :class:`RowThreads`' pool's. A long
    call (a render) starts its own, so as not to keep another thread's kernels waiting on the
    pool meanwhile (the explorer's sliders, while a render refines its view in the
    background). ``work`` must then take its share from a queue (:func:`fetch_add`), since a
    call the pool has not started when this thread's is done is dropped."""
    errors = []

    def run():
        try:
            work()
        except BaseException as exc:  # raised again in the calling thread
            errors.append(exc)

    if short:
        others = [_row_pool().submit(run) for _ in range(count - 1)]
        try:
            work()
        finally:
            for f in others:
                if not f.cancel():  # started: wait for its share
                    f.result()
    else:
        others = [threading.Thread(target=run, daemon=True) for _ in range(count - 1)]
        for t in others:
            t.start()
        try:
            work()
        finally:
            for t in others:
                t.join()
    if errors:
        raise errors[0]


def share_queue(kernel, items, *args):
    """Call ``kernel(*args, queue)`` in ``min(items, thread_count())`` threads at
    once (:func:`in_threads`, ``short``): ``queue`` is a new counter (an int64 array of one)
    from which the calls take the numbers of items 0 .. ``items`` - 1 with :func:`fetch_add`
    until none is left. For a :func:`nogil_kernel` whose items' results do not depend on who
    computed them (the fit's loss passes, whose blocks' sums are added up afterwards)."""
    queue = np.zeros(1, np.int64)
    in_threads(max(1, min(items, thread_count())), lambda: kernel(*args, queue),
               short=True)


@intrinsic
def fetch_add(typingctx, counter, value):
    """Atomically add ``value`` to ``counter[0]`` (an int64 array) and return its old value:
    the threads of a parallel loop take turns at a shared queue of work with it."""
    if not (isinstance(counter, types.Array) and counter.dtype == types.int64
            and isinstance(value, types.Integer)):
        return None

    def codegen(context, builder, signature, args):
        ary = context.make_array(signature.args[0])(context, builder, args[0])
        first = cgutils.get_item_pointer(context, builder, signature.args[0], ary,
                                         [context.get_constant(types.intp, 0)])
        step = context.cast(builder, args[1], signature.args[1], types.int64)
        return builder.atomic_rmw("add", first, step, "monotonic")

    return types.int64(counter, value), codegen


@intrinsic
def prefetch(typingctx, array, index):
    """Ask the caches for the line holding ``array[index]`` (a tuple of ``ndim`` indices, within
    bounds: none is checked) and go on without waiting (LLVM's ``llvm.prefetch``, for reading,
    to every level). A lookup at scattered places of a large table prefetches its next items'
    lines in a pass of their own, so that their waits on memory overlap."""
    if not (isinstance(array, types.Array) and isinstance(index, types.BaseTuple)
            and len(index) == array.ndim
            and all(isinstance(t, types.Integer) for t in index)):
        return None

    def codegen(context, builder, signature, args):
        aryty, idxty = signature.args
        ary = context.make_array(aryty)(context, builder, args[0])
        idx = [context.cast(builder, v, t, types.intp) for v, t in
               zip(cgutils.unpack_tuple(builder, args[1], count=len(idxty)), idxty)]
        ptr = cgutils.get_item_pointer(context, builder, aryty, ary, idx, wraparound=False)
        i32 = ir.IntType(32)
        fn = cgutils.get_or_insert_function(
            builder.module, ir.FunctionType(ir.VoidType(), [ptr.type, i32, i32, i32]),
            "llvm.prefetch.p0")
        builder.call(fn, [ptr, i32(0), i32(3), i32(1)])  # read, keep in all levels, data
        return context.get_dummy_value()

    return types.none(array, index), codegen


#: Whether :func:`ticks` counts time here: x86-64's time-stamp counter, which ticks at a
#: constant rate whatever the core's clock; other CPUs' cycle counters may be closed to user
#: code (AArch64's traps), so nothing reads one there.
HAS_TICKS = platform.machine().lower() in ("x86_64", "amd64")


@intrinsic
def ticks(typingctx):
    """The time-stamp counter (``llvm.readcyclecounter``: ``rdtsc``), for timing the stages of
    a kernel in its own code; only where :data:`HAS_TICKS`."""
    def codegen(context, builder, signature, args):
        fn = cgutils.get_or_insert_function(builder.module, ir.FunctionType(ir.IntType(64), []),
                                            "llvm.readcyclecounter")
        return builder.call(fn, [])

    return types.int64(), codegen


@kernel
def tick_count():
    """:func:`ticks` read from Python: two readings around a render and the nanoseconds
    between them give the counter's rate, without the time Python spends calling kernels."""
    return ticks()


@intrinsic
def sparse_product(typingctx, a, b):
    """``a * b`` of two float64, which LLVM may take as 0 where it knows a factor to be 0 (the
    product's ``nnan`` and ``ninf`` flags say that neither is NaN or infinite): where a loop
    contracts a row of derivatives that a kernel sets only in part (the rest zeroed, ``d[j, k,
    c]`` of a family's ``grad_``), the products with the entries never set drop out of it.
    The caller vouches that a NaN or infinite factor meeting such a 0 may count as 0."""
    if not (a == types.float64 and b == types.float64):
        return None

    def codegen(context, builder, signature, args):
        return builder.fmul(args[0], args[1], flags=("nnan", "ninf", *sorted(FASTMATH)))

    return types.float64(types.float64, types.float64), codegen


# One line on stderr before a group of kernels first compiles in a process, since that takes
# a minute and looks hung (brdf.kernel_groups), and the memory housekeeping that compiles set
# off made cheaper (brdf._compile_memory): numba tells of compiles only on a disk-cache miss,
# so a warm cache runs as before.
from ._compile_memory import manage_compile_memory  # noqa: E402
from .kernel_groups import announce_first_compiles  # noqa: E402

announce_first_compiles()
manage_compile_memory()
