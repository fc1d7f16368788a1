"""brdf._kernel_cache: cached kernels load without numba's full set-up, and still run right;
a kernel compiled after them in the same process gets that set-up from numba's compiler."""

import json
import subprocess
import sys

import numpy as np

import brdf

# A fresh process: evaluate (a kernel run in threads), check (kernels that allocate, through
# numba's runtime), render on two threads, and say whether numba loaded its registry of
# implementations (numba.np.polynomial is one of its modules), scipy.linalg (numba's probe for
# BLAS), numba.np.arrayobj (the module of numba's np.zeros, which the check's kernels hold,
# imported only to rebuild its environment), compiled its runtime's LLVM functions or started
# its threading layer (none of the package's kernels runs in it), then compile a function
# that needs all of them (np.dot, through scipy's BLAS, added to an array numba allocates).
_FRESH = """
import json, sys
import numpy as np
import brdf
from brdf.geometry import directions_from_degrees
m = brdf.parse("lambert(albedo=0.5) + ggx(alpha=0.3)")
t = np.linspace(0.0, 80.0, 9)
f = m.eval(directions_from_degrees(t, 0.0 * t), directions_from_degrees(t, 180.0 + 0.0 * t))
report = brdf.check(m)
from brdf import render
image = render.render(render.builtin("cornell"), spp=1, size=(8, 8), threads=2,
                      progress=False).image
from numba.np.ufunc import parallel
layer_started = parallel._is_initialized
loaded_registry = [m for m in ("numba.np.polynomial.polynomial_functions", "scipy.linalg",
                                "numba.np.arrayobj") if m in sys.modules]
from numba.core.runtime import rtsys
runtime_compiled = rtsys._init
from numba.core.registry import CPUDispatcher
from brdf._jit import DeferredKernel, RowThreads
from brdf._kernel_cache import _CacheOnFirstUse
kernels = {id(k): k for name, module in list(sys.modules.items()) if name.startswith("brdf")
           for k in (v.dispatcher if isinstance(v, RowThreads) else v
                     for v in vars(module).values())
           if isinstance(k, (CPUDispatcher, DeferredKernel))}
made = [vars(k)["_made"] if isinstance(k, DeferredKernel) else k for k in kernels.values()]
caches = [type(vars(k)["_cache"]) is not _CacheOnFirstUse for k in made if k is not None]
import numba
dot = numba.njit(lambda a: np.dot(a, a) + np.zeros(2))(np.arange(3.0))
print(json.dumps({"f": f.tolist(), "passed": bool(report.passed), "registry": loaded_registry,
                  "runtime_compiled": runtime_compiled, "layer_started": layer_started,
                  "rendered": bool(np.isfinite(image).all() and image.mean() > 0),
                  "dot": dot.tolist(), "caches": [sum(caches), len(caches), len(made)]}))
"""


def test_a_warm_process_loads_kernels_without_numbas_registry():
    m = brdf.parse("lambert(albedo=0.5) + ggx(alpha=0.3)")
    from brdf.geometry import directions_from_degrees
    t = np.linspace(0.0, 80.0, 9)
    expected = m.eval(directions_from_degrees(t, 0.0 * t),
                      directions_from_degrees(t, 180.0 + 0.0 * t))
    passed = brdf.check(m).passed  # also puts the kernels in the cache for the process below
    done = subprocess.run([sys.executable, "-c", _FRESH], capture_output=True, text=True,
                          timeout=600)
    assert done.returncode == 0, done.stderr
    out = json.loads(done.stdout)
    assert out["registry"] == []
    assert out["runtime_compiled"] is False
    assert out["layer_started"] is False and out["rendered"]
    assert np.array_equal(np.array(out["f"]), expected)
    assert out["passed"] == passed
    assert out["dot"] == [5.0, 5.0]
    # only the kernels it loaded made their disk caches (each one's folder found and tested),
    # and most of those only kernels call never made a dispatcher
    caches, dispatchers, kernels = out["caches"]
    assert 1 <= caches <= 12 and dispatchers <= kernels - 60 and kernels >= 150, out["caches"]


def test_a_kernel_makes_its_disk_cache_on_first_use():
    """A kernel's disk cache is made when numba first reads it, and loads as quickly as
    before: making one for each of the 207 kernels ``import brdf.render`` defines was 17 ms of
    each command's start."""
    from numba.core import caching
    from brdf import _jit, _kernel_cache

    def doubled(x):
        return 2.0 * x

    k = _jit.kernel(doubled)
    assert type(vars(k)["_cache"]) is _kernel_cache._CacheOnFirstUse
    assert k(1.5) == 3.0
    cache = vars(k)["_cache"]
    assert type(cache) is _kernel_cache._QuickLoad and isinstance(cache, caching.FunctionCache)
    assert k.stats.cache_path == cache._cache_path


def test_arguments_are_typed_as_numba_types_them():
    """A kernel types numpy arrays (and tuples of them) itself, without numba's ``typeof``
    (which imports numpy.ma on its first array); the types must be numba's own."""
    import collections
    from numba.core.typing.typeof import Purpose, typeof
    from brdf._kernel_cache import _argument_type
    pair = collections.namedtuple("pair", "a b")
    a = np.arange(24.0).reshape(2, 3, 4)
    read_only = np.frombuffer(np.arange(6.0).tobytes()).reshape(2, 3)
    values = [a, a[:, ::2], a.T, np.asfortranarray(a), a[0], np.zeros(0), np.array(3.0),
              read_only, np.broadcast_to(np.ones(3), (4, 3)), np.arange(3), np.zeros(2, bool),
              np.zeros(2, np.complex64), np.zeros(3, np.float32)[::-1], (a, read_only),
              pair(a, 1.5), (a, 3, True), 2.5, 7, (np.zeros((1, 0)),),
              np.zeros(2, dtype=[("x", "f8"), ("y", "i4")])]
    for value in values:
        assert _argument_type(value) == typeof(value, Purpose.argument), value
    # left to numba, which refuses them or says why
    assert _argument_type(np.ma.masked_array([1.0])) is None
    assert _argument_type(np.zeros(2, "datetime64[Y]")[:0]) == typeof(
        np.zeros(2, "datetime64[Y]")[:0], Purpose.argument)


def test_a_loaded_kernel_names_its_symbols_and_parses_its_module_when_linked():
    """A kernel loaded from the cache takes the names it defines from its machine code's
    symbol table (the module for linking it is parsed only when a caller links it); both must
    give what numba's own load gives."""
    import llvmlite.binding as ll
    from numba.core.registry import cpu_target
    from brdf import _kernel_cache
    from brdf.models import _kernels
    wi = np.tile([0.36, 0.48, 0.8], (4, 1))
    brdf.parse("ggx(alpha=0.3)").eval(wi, wi)
    dispatcher = _kernels.eval_array.dispatcher
    cache = dispatcher._cache
    codegen = cpu_target.target_context.codegen()
    sig = next(iter(dispatcher.overloads.values())).signature.args
    stored = cache._cache_file.load(cache._index_key(sig, codegen))  # as numba saved it
    _, kind, (obj, bitcode) = stored[0]
    defined = set()
    module = ll.parse_bitcode(bitcode)
    for values in (module.functions, module.global_variables):
        defined |= {v.name for v in values if not v.is_declaration}
    assert kind == "object" and defined
    assert _kernel_cache._defined_in_object(obj) == defined
    assert _kernel_cache._defined_in_object(b"\xcf\xfa\xed\xfe" + obj[4:]) is None  # Mach-O
    # into an engine of its own, where its symbols are defined once
    from numba.core.codegen import JITCPUCodegen
    engine = JITCPUCodegen("test_kernel_cache")
    _kernel_cache._loading.kernel = True
    try:
        library = engine.unserialize_library(stored[0])
    finally:
        _kernel_cache._loading.kernel = False
    assert "_linking_bitcode" in library.__dict__  # not parsed yet
    assert all(engine._engine.is_symbol_defined(n) for n in defined)
    assert library.get_pointer_to_function(stored[1].llvm_func_name) != 0  # its entry
    linked = library._get_module_for_linking()
    assert {f.name for f in linked.functions if not f.is_declaration} == {
        f.name for f in module.functions if not f.is_declaration}
    assert "_linking_bitcode" not in library.__dict__


def test_numba_cache_dir_is_honoured_and_stamped(monkeypatch, tmp_path):
    """With NUMBA_CACHE_DIR set (a read-only install, a container), the package's kernels are
    cached there, as numba caches any function, and stamped with the package's sources."""
    from numba.core import caching, config
    from brdf import _kernel_cache
    from brdf.models import _kernels
    py_func = _kernels.eval_array.dispatcher.py_func
    monkeypatch.setattr(config, "CACHE_DIR", str(tmp_path))
    locator = caching.FunctionCache(py_func)._impl.locator
    assert type(locator) is _kernel_cache._UserProvided
    assert locator.get_cache_path().startswith(str(tmp_path))
    assert locator.get_source_stamp() == _kernel_cache._STAMP
    monkeypatch.setattr(config, "CACHE_DIR", "")
    locator = caching.FunctionCache(py_func)._impl.locator
    assert type(locator) in (_kernel_cache._InTree, _kernel_cache._UserWide)
