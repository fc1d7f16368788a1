"""How brdf._jit compiles: one machine-code specialisation per kernel, whatever callers pass,
and kernels that borrow their arrays without counting references to them.

Each duplicate specialisation of a library kernel cost tens of seconds on a cold cache; these
toy kernels hold the ways they arose (literal constants, read-only arrays) to one
specialisation each. Threads share work through a queue (``in_threads``, ``share_queue``).
"""

import itertools
import math
import operator
import shutil
import subprocess
import sys
import threading
import time
from collections import namedtuple

import llvmlite.binding
import numba
import numpy as np
import pytest
from numba import typeof
from numba.core import types

from brdf._jit import (AS_LOWERED, OPTIMISED, allocating_kernel, fetch_add, in_threads,
                       inline_kernel, kernel, nogil_kernel, prefetch, share_queue,
                       threaded_kernel)
from brdf._threads import SERIAL_SAMPLES, serial_below, thread_count, using_threads


@kernel
def _scaled(a, n, k):
    return a[k] * n


@kernel
def _with_constants(a):
    return _scaled(a, 3, 0)


@kernel
def _with_variables(a, n, k):
    return _scaled(a, n, k)


@nogil_kernel
def _doubled(a, out):
    for k in range(a.shape[0]):
        out[k] = 2.0 * a[k]


def test_constant_and_variable_arguments_share_one_specialisation():
    a = np.arange(4.0)
    assert _with_constants(a) == _with_variables(a, 3, 0) == 0.0
    assert _with_variables(a, 2, 3) == 6.0
    # what a calling kernel's typing asks for: the constants' literal types are dropped (the
    # callers above may have come from the cache, which leaves _scaled itself uncompiled)
    _, _, args, _ = _scaled.get_call_template((typeof(a), types.literal(3), types.literal(0)),
                                              {})
    assert tuple(args) == (typeof(a), types.int64, types.int64)
    assert all("Literal" not in str(sig) for sig in _scaled.signatures)
    assert len(_scaled.overloads) == 1


@inline_kernel
def _channels_scaled(a, nch, k):
    return a[k] * nch


@kernel
def _inline_with_constants(a):
    return _channels_scaled(a, 3, 0)


@kernel
def _inline_with_variables(a, nch, k):
    return _channels_scaled(a, nch, k)


def test_an_inline_kernel_keeps_only_a_constant_channel_count_literal():
    a = np.arange(4.0)
    assert _inline_with_constants(a) == 0.0
    assert _inline_with_variables(a, 2, 3) == 6.0
    # nch=3 specialises the callee's loops over channels; a constant row index gains nothing
    _, _, args, _ = _channels_scaled.get_call_template(
        (typeof(a), types.literal(3), types.literal(0)), {})
    assert tuple(args) == (typeof(a), types.literal(3), types.int64)
    _, _, args, _ = _channels_scaled.get_call_template((typeof(a), types.int64, types.int64), {})
    assert tuple(args) == (typeof(a), types.int64, types.int64)


def test_read_only_inputs_share_the_writable_specialisation():
    a = np.arange(5.0)
    out = np.empty(5)
    _doubled(a, out)
    view = a.view()
    view.flags.writeable = False
    for source in (view, np.broadcast_to(a, (5,))):
        out[:] = 0.0
        _doubled(source, out)
        np.testing.assert_array_equal(out, 2.0 * a)
    assert len(_doubled.overloads) == 1
    # the arrays themselves keep their flag
    assert not view.flags.writeable and a.flags.writeable


_Pair = namedtuple("_Pair", "x y")


@kernel
def _pair_sum(p, t):
    return p.x.sum() + p.y.sum() + t[0].sum() + t[1]


def test_read_only_arrays_in_tuples_share_the_writable_specialisation():
    """The renderer passes its scene as named tuples of arrays, some of them a table's
    read-only arrays."""
    a, b = np.arange(3.0), np.ones(2)
    frozen = a.view()
    frozen.flags.writeable = False
    assert _pair_sum(_Pair(a, b), (a, 2.0)) == 3.0 + 2.0 + 3.0 + 2.0
    for pair, plain in ((_Pair(frozen, b), (a, 2.0)), (_Pair(a, frozen[:2]), (frozen, 2.0)),
                        (_Pair(frozen, frozen[:2]), (frozen, 2.0))):
        assert _pair_sum(pair, plain) == pair.x.sum() + pair.y.sum() + 3.0 + 2.0
    assert len(_pair_sum.overloads) == 1


@kernel
def _add_one(a):
    a[0] += 1.0
    return a[0] + a[-1]


@kernel
def _hand_back(a):
    return a


@kernel
def _hand_back_in_tuple(a):
    return a, 1.0


@kernel
def _summed_copy(a):
    return np.copy(a).sum()


@allocating_kernel
def _copied(a):
    return np.copy(a)


def test_kernels_borrow_arrays_and_may_write_them():
    a = np.ones(3)
    for _ in range(1000):
        _add_one(a)
    assert a[0] == 1001.0 and _add_one(a) == 1003.0


@pytest.mark.parametrize("fn", [_hand_back, _hand_back_in_tuple])
def test_a_kernel_returning_an_array_is_refused(fn):
    # without reference counts, the caller would release a reference it never got
    with pytest.raises(TypeError, match="may return only scalars"):
        fn(np.zeros(3))


def test_a_kernel_cannot_allocate_but_an_allocating_kernel_can():
    with pytest.raises(Exception, match="returning of array passed into the function"):
        _summed_copy(np.ones(3))
    a = np.arange(3.0)
    b = _copied(a)
    b[0] = 7.0
    assert a[0] == 0.0 and b.sum() == 10.0


def _doubled_into(a, out):
    for k in range(a.shape[0]):
        out[k] = 2.0 * a[k]


_LINKED = (inline_kernel, kernel(linked=OPTIMISED), kernel(linked=AS_LOWERED),
           allocating_kernel(linked=AS_LOWERED))


@pytest.mark.parametrize("compile_with", [kernel, nogil_kernel, allocating_kernel,
                                          threaded_kernel("a", "out"), *_LINKED])
def test_kernels_are_compiled_without_a_c_callable_wrapper(compile_with):
    """numba made a ``cfunc`` wrapper (numba's first-class function entry) for every kernel, which
    no kernel is passed as; compiling them was 7 % of compiling every kernel."""
    compiled = compile_with(_doubled_into)
    dispatcher = getattr(compiled, "dispatcher", compiled)
    dispatcher._cache = numba.core.caching.NullCache()  # compile here, so the IR is there
    linked = compile_with in _LINKED
    if linked:  # compiled as a caller's typing compiles it; Python calls run its twin
        dispatcher.compile((typeof(np.zeros(4)),) * 2)
        dispatcher.for_python()._cache = numba.core.caching.NullCache()
    out = np.zeros(4)
    compiled(np.arange(4.0), out)
    assert out.tolist() == [0.0, 2.0, 4.0, 6.0]
    (cres,) = dispatcher.overloads.values()
    names = [fn.name for fn in cres.library.get_defined_functions()]
    assert cres.fndesc.llvm_func_name in names
    # only a kernel that Python calls has numba's CPython wrapper
    assert (cres.fndesc.llvm_cpython_wrapper_name in names) == (not linked)
    assert cres.fndesc.llvm_cfunc_wrapper_name not in names
    # marked for the unoptimised code generator (test_an_inline_kernel_is_cached_...) or not
    assert (getattr(cres.library, "brdf_linked", None) is not None) == linked


@pytest.mark.parametrize("compile_with", _LINKED)
def test_python_calls_of_a_linked_kernel_run_its_twin(compile_with):
    """A kernel only kernels call has no CPython wrapper, so its overloads stay out of numba's
    table of argument types, and every call from Python goes to its twin: the same function,
    under a name of its own, compiled with a wrapper. The kernel's own overloads are those its
    callers' typing asked for."""
    compiled = compile_with(_doubled_into)
    compiled._cache = numba.core.caching.NullCache()
    twin = compiled.for_python()
    twin._cache = numba.core.caching.NullCache()
    assert twin is compiled.for_python() and twin is not compiled
    assert twin.py_func.__qualname__ == "_doubled_into__from_python"
    assert twin.py_func.__code__ is _doubled_into.__code__
    a = np.arange(4.0)
    for _ in range(2):  # the second call too: no table entry of the kernel's matches it
        out = np.zeros(4)
        compiled(a, out)
        np.testing.assert_array_equal(out, 2.0 * a)
    assert not compiled.overloads and len(twin.overloads) == 1
    frozen = a.view()
    frozen.flags.writeable = False
    out = np.zeros(4)
    compiled(frozen, out)  # read-only inputs share the twin's writable specialisation
    np.testing.assert_array_equal(out, 2.0 * a)
    assert len(twin.overloads) == 1
    compiled.compile((typeof(a), typeof(out)))
    out = np.zeros(4)
    compiled(a, out)
    np.testing.assert_array_equal(out, 2.0 * a)
    assert len(compiled.overloads) == 1 and len(twin.overloads) == 1


def _times_three(a, k):
    return _scaled(a, 3, k)


@pytest.mark.parametrize("linked", [OPTIMISED, AS_LOWERED])
def test_a_kernel_linked_as_lowered_leaves_its_module_to_its_callers(linked):
    """A kernel linked OPTIMISED has its callees inlined in its own module, as any kernel;
    one linked AS_LOWERED keeps its module as numba lowered it, calls included, for each
    caller's optimisation to do once. Both compute the same."""
    compiled = kernel(linked=linked)(_times_three)
    compiled._cache = numba.core.caching.NullCache()  # compile here, so the IR is there
    compiled.for_python()._cache = numba.core.caching.NullCache()
    assert compiled(np.arange(4.0), 2) == 6.0
    compiled.compile((typeof(np.arange(4.0)), types.int64))  # as a caller's typing does
    (cres,) = compiled.overloads.values()
    callee = next(iter(_scaled.overloads.values())).fndesc.mangled_name
    calls = [line for line in str(cres.library._final_module).splitlines()
             if " call " in line and callee in line]
    assert bool(calls) == (linked == AS_LOWERED)


def _gathered(a, idx):
    s = 0.0
    for k in range(idx.shape[0]):
        prefetch(a, (idx[k], 1))
    for k in range(idx.shape[0]):
        s += a[idx[k], 1]
    return s


def test_prefetch_asks_llvm_for_the_line_and_changes_no_result():
    compiled = kernel(_gathered)
    compiled._cache = numba.core.caching.NullCache()  # compile here, so the IR is there
    a = np.arange(40.0).reshape(20, 2)
    idx = np.array([3, 17, 0, 19])
    assert compiled(a, idx) == a[idx, 1].sum()
    (cres,) = compiled.overloads.values()
    calls = [line for line in str(cres.library._final_module).splitlines()
             if "call" in line and "llvm.prefetch" in line]
    assert calls and "i32 0, i32 3, i32 1" in calls[0]


def test_prefetch_takes_one_integer_index_per_axis():
    with pytest.raises(numba.core.errors.TypingError):
        kernel(lambda a: prefetch(a, (1,)))(np.zeros((2, 2)))
    with pytest.raises(numba.core.errors.TypingError):
        kernel(lambda a: prefetch(a, (1, 0.5)))(np.zeros((2, 2)))


@pytest.mark.parametrize("linked", ["optimized", "", True])
def test_an_unknown_way_of_linking_is_refused(linked):
    with pytest.raises(ValueError, match="linked="):
        kernel(linked=linked)(_doubled_into)


# Toy kernels for fresh processes: an inline kernel, and callers in a module of their own
# (numba's cache of a kernel outside the package is dropped when its file changes)
_INLINE_TOY = """
import numpy as np
from brdf._jit import AS_LOWERED, OPTIMISED, allocating_kernel, inline_kernel, kernel

@inline_kernel
def scaled(a, k):
    return 3.0 * a[k] + 1.0

@kernel(linked=OPTIMISED)
def summed(a, k):
    s = 0.0
    for j in range(k + 1):
        s += a[j]
    return s

@allocating_kernel(linked=AS_LOWERED)
def squares(a, k):
    b = np.empty(a.shape[0])
    for j in range(a.shape[0]):
        b[j] = a[j] * a[j]
    return b[k] + summed(a, k)
"""
_CALLERS = """
from brdf._jit import allocating_kernel
from toy_inline import scaled, squares, summed

@allocating_kernel
def {name}(a):
    return scaled(a, {index}) + 10.0 * summed(a, {index}) + 100.0 * squares(a, {index})
"""
_RUN = """
import json, sys
import numpy as np
sys.path.insert(0, sys.argv[1])
import toy_inline, toy_callers
a = np.arange(4.0)
caller = getattr(toy_callers, sys.argv[2])
callees = ("scaled", "summed", "squares")
values = {"caller": caller(a), **{k: getattr(toy_inline, k)(a, 2) for k in callees}}
stats = {"caller": caller.stats, **{k: getattr(toy_inline, k).stats for k in callees}}


def code_bytes(dispatcher):  # machine code in the objects of the overloads compiled here
    import llvmlite.binding as ll
    objects = [c.library._compiled_object for c in dispatcher.overloads.values()]
    return sum(section.size() for o in objects if o
               for section in ll.ObjectFileRef.from_data(o).sections() if section.is_text())


print(json.dumps({"values": values,
                  "code": {k: code_bytes(getattr(toy_inline, k).made()) for k in callees},
                  "caller_code": code_bytes(caller),
                  "compiled": {k: len(s.cache_misses) for k, s in stats.items()},
                  "loaded": {k: len(s.cache_hits) for k, s in stats.items()}}))
"""


def test_linked_kernels_are_cached_and_linked_from_their_cache(tmp_path):
    """A kernel only kernels call (an inline kernel, or one declared ``linked=``) has no
    machine code of its own (``_package_machine_code``), and one linked AS_LOWERED has its
    module left unoptimised for its callers; each must be saved to the disk cache and load
    from it to be linked into a caller compiled later, and still run from Python (through
    its twin, cached too)."""
    import json
    import os
    (tmp_path / "toy_inline.py").write_text(_INLINE_TOY)
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache")}

    def run(name, index):
        (tmp_path / "toy_callers.py").write_text(_CALLERS.format(name=name, index=index))
        done = subprocess.run([sys.executable, "-c", _RUN, str(tmp_path), name], env=env,
                              capture_output=True, text=True, timeout=300)
        assert done.returncode == 0, done.stderr
        return json.loads(done.stdout.splitlines()[-1])

    # from Python, at a = (0, 1, 2, 3), k = 2: scaled 7, summed 3, squares 4 + 3
    callees = {"scaled": 7.0, "summed": 3.0, "squares": 7.0}
    cold = run("first", "0")  # scaled 1, summed 0, squares 0
    assert cold["values"] == {"caller": 1.0, **callees}
    assert cold["compiled"] == {"caller": 1, "scaled": 1, "summed": 1, "squares": 1}
    assert cold["code"] == {"scaled": 0, "summed": 0, "squares": 0}
    assert cold["caller_code"] > 0  # the callees' code is the caller's
    warm = run("last", "a.shape[0] - 1")  # a caller new to the cache: 10 + 60 + 1500
    assert warm["values"] == {"caller": 1570.0, **callees}
    assert warm["compiled"] == {"caller": 1, "scaled": 0, "summed": 0, "squares": 0}
    assert warm["loaded"] == {"caller": 0, "scaled": 1, "summed": 1, "squares": 1}


_WIDE = """
import json, re, subprocess, sys, tempfile
import numpy as np
from numba.core.registry import cpu_target
import brdf
from brdf.models import _kernels

codegen = cpu_target.target_context.codegen()
machine = codegen._tm
wi = np.tile([0.36, 0.48, 0.8], (64, 1))
brdf.parse("ggx(alpha=0.3)").eval(wi, wi)


def roots(library):
    with tempfile.NamedTemporaryFile(suffix=".o") as f:
        f.write(library._compiled_object)
        f.flush()
        asm = subprocess.run(["objdump", "-d", "--no-show-raw-insn", f.name],
                             capture_output=True, text=True, check=True).stdout
    return sorted(set(re.findall(r"vsqrtpd\\s+%([xyz]mm)", asm)))


print(json.dumps({"eval": [roots(c.library)
                           for c in _kernels.eval_array.dispatcher.overloads.values()],
                  "numba_machine_kept": codegen._tm is machine,
                  "numba_features": codegen._tm_features}))
"""


@pytest.mark.skipif("+avx512f" not in llvmlite.binding.get_host_cpu_features().flatten()
                    .split(",") or numba.config.CPU_FEATURES is not None
                    or shutil.which("objdump") is None,
                    reason="a CPU without AVX-512 (or features set by hand), or no objdump")
def test_package_kernels_vectorise_with_512_bit_vectors(tmp_path):
    """On a CPU with AVX-512, the package's kernels are optimised and compiled for 512-bit
    vectors (:func:`brdf._jit.package_machine`): the GGX evaluation's loop takes its square
    roots eight at a time, in zmm registers (LLVM's tuning of Intel's server cores gave it
    ymm ones, four at a time). numba's own target machine, which compiles every other
    function in the process, is left as it was."""
    import json
    import os
    # an empty cache of its own: the kernels compile, and their machine code is at hand
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache"),
           "NUMBA_CACHE_LOCATOR_CLASSES": "UserProvidedCacheLocator"}
    done = subprocess.run([sys.executable, "-c", _WIDE], env=env, capture_output=True,
                          text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    out = json.loads(done.stdout.splitlines()[-1])
    assert out["eval"] and all(r == ["zmm"] for r in out["eval"]), out
    assert out["numba_machine_kept"]
    assert "prefer-256-bit" not in out["numba_features"]


@nogil_kernel
def _take_items(taken, queue):
    """Take items off ``queue`` until none is left, counting in ``taken`` how often each was
    taken."""
    while True:
        k = fetch_add(queue, 1)
        if k >= taken.shape[0]:
            return
        taken[k] += 1


@nogil_kernel
def _wait_for_the_other(flag, turns):
    """Say it is running (flag 1), then wait up to ``turns`` checks for another thread to
    answer (flag 2): whether it did. The flag is read atomically, so no check is skipped."""
    fetch_add(flag, 1)
    for _ in range(turns):
        if fetch_add(flag, 0) == 2:
            return True
    return False


def test_threads_share_a_queue_of_items():
    queue, taken = np.zeros(1, np.int64), np.zeros(20_000, np.int64)
    in_threads(3, lambda: _take_items(taken, queue))
    assert (taken == 1).all()
    assert queue[0] == taken.shape[0] + 3  # each thread's last turn finds the queue empty


@pytest.mark.parametrize("threads", [1, 2])
def test_a_shared_queue_hands_each_item_to_exactly_one_call(threads):
    taken = np.zeros(20_000, np.int64)
    with using_threads(threads):
        share_queue(_take_items, taken.shape[0], taken)
    assert (taken == 1).all()


def test_a_shared_queue_runs_from_a_pool_thread_too():
    # a call from the pool's own thread (one thread on two cores) cannot wait on that thread:
    # its share, never started, is dropped, and this thread takes every item
    from concurrent.futures import ThreadPoolExecutor
    taken = np.zeros(1000, np.int64)

    def from_pool():
        with using_threads(2):
            share_queue(_take_items, taken.shape[0], taken)

    with ThreadPoolExecutor(1) as pool:
        pool.submit(from_pool).result(timeout=60)
    assert (taken == 1).all()


@pytest.mark.parametrize("short", [False, True])
def test_in_threads_raises_what_a_thread_raised(short):
    calls, lock, failing = itertools.count(), threading.Lock(), threading.Event()

    def work():
        with lock:
            turn = next(calls)
        if turn == 1:
            failing.set()
            raise ValueError("one thread failed")
        assert failing.wait(30)  # a short call not started when this one ends is dropped

    with pytest.raises(ValueError, match="one thread failed"):
        in_threads(2, work, short=short)


def test_a_nogil_kernel_lets_another_thread_run_meanwhile():
    # one thread waits inside the kernel for the other to answer from Python: with the GIL
    # held by the kernel, the answer could only come after it gave up
    flag, roles, answered = np.zeros(1, np.int64), itertools.count(), []

    def work():
        if next(roles) == 0:
            answered.append(_wait_for_the_other(flag, 10 ** 9))
            return
        while flag[0] < 1:
            time.sleep(1e-4)
        flag[0] = 2

    in_threads(2, work)
    assert answered == [True]


_VIEWS = """
import numba, numpy as np
from brdf.models._kernels import with_last_axis

@numba.njit  # reference counted, as numba's default
def copied_rows(a, out):
    for lo in range(0, a.shape[0], 2):
        v = with_last_axis(a[lo:lo + 2], 3)
        o = with_last_axis(out[lo:lo + 2], 3)
        for k in range(v.shape[0]):
            for c in range(3):
                o[k, c] = v[k, c]

a = np.arange(30.0).reshape(10, 3)
for _ in range(100):
    out = np.zeros_like(a)
    copied_rows(a, out)
    assert (out == a).all()
print(np.ones(10_000).sum())
"""


def test_a_view_with_a_constant_last_axis_counts_its_reference():
    # a view sharing the array's memory without a reference of its own released that memory
    # once per call: the allocator aborted the process ("unaligned tcache chunk"), in a
    # subprocess here so that the failure cannot take the test session with it
    done = subprocess.run([sys.executable, "-c", _VIEWS], capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0 and done.stdout.split() == ["10000.0"], done.stderr[-2000:]


@threaded_kernel("a", "out", rows_per_thread=1, align=1)
def _rows_doubled(a, scale, out):
    n = 0
    for k in range(a.shape[0]):
        out[k] = 2.0 * a[k] + scale[0]
        n += a[k] < 0.0
    return n


@pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2, reason="one thread")
@pytest.mark.parametrize("n", [1, 2, 7, 1001])
def test_a_threaded_kernel_splits_its_rows_and_sums_its_results(n):
    """Rows go to chunks, one per thread; an argument of another length goes whole to each
    (``scale``); the counts add up; one thread gives the same bytes."""
    a = np.linspace(-1.0, 2.0, n)
    out2, out1 = np.empty(n), np.empty(n)
    with using_threads(2):
        negative = _rows_doubled(a, np.array([0.5]), out2)
    with using_threads(1):
        assert _rows_doubled(a, np.array([0.5]), out1) == negative == np.sum(a < 0.0)
    np.testing.assert_array_equal(out2, 2.0 * a + 0.5)
    assert out1.tobytes() == out2.tobytes()


@pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2, reason="one thread")
def test_a_threaded_kernel_wakes_no_thread_for_fewer_rows_than_it_gives_one(monkeypatch):
    """Below two threads' worth of rows the call runs on the caller's thread alone (the pool
    is not asked), whatever the thread count; from there on it is split."""
    from brdf import _jit
    asked = []
    pool = _jit._row_pool()
    monkeypatch.setattr(_jit, "_row_pool", lambda: asked.append(1) or pool)
    kernel = threaded_kernel("a", "out", rows_per_thread=4, align=1)(_rows_doubled.py_func)
    with using_threads(2):
        for n, split in [(1, False), (7, False), (8, True), (9, True)]:
            a, out = np.linspace(-1.0, 2.0, n), np.empty(n)
            asked.clear()
            assert kernel(a, np.array([0.5]), out) == np.sum(a < 0.0)
            np.testing.assert_array_equal(out, 2.0 * a + 0.5)
            assert bool(asked) == split, n


@pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2, reason="one thread")
def test_a_threaded_kernel_does_not_wait_for_a_busy_pool():
    """The calling thread takes every chunk the pool's threads have not started: with all of
    them busy, the call returns (equal shares waited for the pool), with the same values."""
    from brdf import _jit
    pool = _jit._row_pool()
    release = threading.Event()
    busy = [pool.submit(release.wait, 60) for _ in range(pool._max_workers)]
    try:
        a, out = np.linspace(-1.0, 2.0, 1001), np.full(1001, np.nan)
        done = []

        def call():
            with using_threads(2):  # this thread's count
                done.append(_rows_doubled_in_chunks(a, np.array([0.5]), out))

        caller = threading.Thread(target=call)
        caller.start()
        caller.join(30)
        assert done == [np.sum(a < 0.0)], "the call waited for the busy pool"
        np.testing.assert_array_equal(out, 2.0 * a + 0.5)
    finally:
        release.set()
        for f in busy:
            f.result()


_rows_doubled_in_chunks = threaded_kernel("a", "out", rows_per_thread=1, chunks_per_thread=4,
                                           align=1)(
    _rows_doubled.py_func)


@pytest.mark.parametrize("n, chunks, align", [(32769, 2, 256), (1001, 16, 64), (7, 7, 1),
                                               (100, 8, 64), (65, 3, 64), (5000, 16, 1)])
def test_a_threaded_kernels_chunks_start_at_multiples_of_its_alignment(n, chunks, align):
    """Chunks cover the rows once, in order, none empty, each but the first starting at a
    multiple of ``align`` (where a batched kernel's batches, and a vectorised loop's
    body, start in a call over all rows), and none longer than an even share plus one
    ``align``."""
    from brdf._jit import chunk_cuts
    cuts = chunk_cuts(n, chunks, align)
    assert cuts[0] == 0 and cuts[-1] == n and len(cuts) - 1 <= chunks
    assert all(a < b for a, b in zip(cuts, cuts[1:]))
    assert all(c % align == 0 for c in cuts[:-1])
    assert max(b - a for a, b in zip(cuts, cuts[1:])) <= -(-n // chunks) + align
    if align == 1:  # the cards' chunks: ceil(n t / chunks)
        assert cuts == [-(-n * t // chunks) for t in range(chunks + 1)]


@pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2, reason="one thread")
def test_the_model_kernels_give_the_same_bytes_on_one_thread_and_two():
    """eval, pdf, sample and albedo (threaded kernels) of a mixture, on an odd number of
    rows, enough for two threads: each row's values do not depend on which thread computed
    them."""
    import brdf
    from brdf._threads import ROWS_PER_THREAD
    from brdf.geometry import directions_from_degrees
    m = brdf.parse("lambert(albedo=[0.5,0.4,0.3]) + ggx(alpha=0.2, fresnel=schlick(f0=0.04))")
    rng = np.random.default_rng(0)
    n = 2 * ROWS_PER_THREAD + 1
    t, p = rng.uniform(0.0, 89.0, (2, n)), rng.uniform(0.0, 360.0, (2, n))
    wi, wo = directions_from_degrees(t[0], p[0]), directions_from_degrees(t[1], p[1])
    u = rng.random((n, 2))

    def run(threads):
        with using_threads(threads):
            return (m.eval(wi, wo), m.pdf(wi, wo), *m.sample(wi, u), m.albedo(wi[:9]))

    for one, two in zip(run(1), run(2)):
        assert one.tobytes() == two.tobytes()


def test_the_thread_count_is_numbas_until_a_block_sets_its_own():
    most = numba.config.NUMBA_NUM_THREADS
    before = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        assert thread_count() == 1
        with using_threads(2):
            assert thread_count() == min(2, most)
            with serial_below(10):
                assert thread_count() == 1
            with serial_below(SERIAL_SAMPLES):
                assert thread_count() == min(2, most)
            # the count is this thread's: another sees numba's own for it
            seen = []
            other = threading.Thread(target=lambda: seen.append(
                (thread_count(), numba.get_num_threads())))
            other.start()
            other.join()
            assert seen[0][0] == seen[0][1]
        assert thread_count() == 1
        with using_threads(10 ** 6):
            assert thread_count() == most
        with using_threads(0):
            assert thread_count() == 1
    finally:
        numba.set_num_threads(before)


def test_numba_raises_no_event_at_each_call_into_llvm():
    """numba's ``numba:llvm_lock`` events, two at each of the 290,000 calls into LLVM of a cold
    compile of every kernel, each running the timers of every compile in progress, are
    stopped (about 6 % of that compile); compiling still works."""
    import brdf._jit as jit
    from numba.core import event
    assert jit._numba_lock_events() == []
    heard = []

    class Listener(event.Listener):
        def on_start(self, e):
            heard.append(e.kind)

        def on_end(self, e):
            pass

    compiled = kernel(_doubled_into)
    compiled._cache = numba.core.caching.NullCache()
    with event.install_listener("numba:llvm_lock", Listener()):
        out = np.zeros(3)
        compiled(np.arange(3.0), out)
    assert out.tolist() == [0.0, 2.0, 4.0] and heard == []


def _scalar_and_array_operators(x, a, b):
    return x - 1.0 < 3.0, a + b, a * x


@pytest.fixture
def calls_typed_anew():
    """The remembered call types (``brdf._jit._call_types_remembered``) forgotten for the
    test, so that it sees numba type its calls, and restored after it."""
    remembered = types.Function._brdf_remembered
    saved = dict(remembered)
    remembered.clear()
    yield
    remembered.clear()
    remembered.update(saved)


def test_numpys_array_operators_decline_scalars_without_matching_a_loop(monkeypatch,
                                                                          calls_typed_anew):
    """numba tries each binary operator against NumPy's array-operator template; it declines
    operands none of which is an array before it matches them to a ufunc's loops (which cost
    a few per cent of a cold compile), and still types array operands, an ``Optional`` array
    included, as NumPy's rules have them."""
    from numba.core.typing import npydecl
    from numba.np import numpy_support
    matched = []
    find = numpy_support.ufunc_find_matching_loop

    def counted(ufunc, arg_types):
        matched.append((ufunc.__name__, tuple(arg_types)))
        return find(ufunc, arg_types)

    monkeypatch.setattr(npydecl, "ufunc_find_matching_loop", counted)
    compiled = numba.njit(_scalar_and_array_operators)
    compiled._cache = numba.core.caching.NullCache()
    less, total, scaled = compiled(0.5, np.arange(3.0), np.ones(3))
    assert less and total.tolist() == [1.0, 2.0, 3.0] and scaled.tolist() == [0.0, 0.5, 1.0]
    # the array operands' loops only: none for the scalars' - and <
    assert {name for name, _ in matched} == {"add", "multiply"}

    added = type("Added", (npydecl.NumpyRulesArrayOperator,), {"key": operator.add})
    template = added(numba.core.registry.cpu_target.typing_context)
    array = types.float64[::1]
    assert template.generic((types.float64, types.float64), {}) is None
    assert template.generic((types.Optional(array), types.float64), {}).return_type == array
    assert template.generic((array, types.float64), {}).return_type == array


def _numbas_variable_list(val):
    """numba 0.68's ``ir.Inst._rec_list_vars`` (which ``Stmt.list_vars`` applies to the
    statement's attributes and ``Expr.list_vars`` to its operands), as a reference."""
    from numba.core import ir
    if isinstance(val, ir.Var):
        return [val]
    if isinstance(val, ir.Inst):
        own = type(val).list_vars
        if own is ir.Stmt.list_vars:
            return _numbas_variable_list(vars(val))
        if own is ir.Expr.list_vars:
            return _numbas_variable_list(val._kws)
        return val.list_vars()
    if isinstance(val, (list, tuple)):
        return [v for item in val for v in _numbas_variable_list(item)]
    if isinstance(val, dict):
        return [v for item in val.values() for v in _numbas_variable_list(item)]
    return []


def test_ir_statements_list_the_variables_numba_lists():
    """The one-loop listing of an IR statement's variables (numba's use-def maps call it for
    every statement at every pass) gives numba's own list, item for item, over the statements
    of the renderer's, the models' and the fit's kernels."""
    from numba.core import compiler, ir
    from brdf.fitting import problem
    from brdf.models import _kernels
    from brdf.render import _integrator, _materials
    assert ir.Inst._brdf_variable_lists
    statements = 0
    for module in (_integrator, _materials, _kernels, problem):
        for value in list(vars(module).values()):
            fn = getattr(value, "py_func", None)
            if getattr(fn, "__module__", None) != module.__name__:
                continue
            for block in compiler.run_frontend(fn).blocks.values():
                for stmt in block.body:
                    mine, numbas = stmt.list_vars(), _numbas_variable_list(stmt)
                    assert [v.name for v in mine] == [v.name for v in numbas], stmt
                    assert all(a is b for a, b in zip(mine, numbas))
                    statements += 1
    assert statements > 10_000


def _typed_calls(a, out, k):
    total = 0.0
    for i in range(len(a)):
        out[i] = math.sqrt(a[i]) * k + math.copysign(1.0, a[i] - k)
        total += out[i] if i % 2 == 0 else -out[i]
    return max(total, abs(out[k])) + np.float32(a[0]) + min(k, 3)


def test_a_call_is_typed_once_per_argument_types_and_as_numba_types_it(monkeypatch):
    """A function type's call is resolved through its templates once per argument types (type
    inference asks again at every round), to the signature numba's own resolution gives;
    a call no template accepts is refused each time, with numba's error."""
    from numba.core import errors, utils
    from numba.core.types.functions import BaseFunction
    context = numba.core.registry.cpu_target.typing_context
    compiled = numba.njit(_typed_calls)
    compiled._cache = numba.core.caching.NullCache()  # typed here, whatever the disk holds
    out = np.zeros(4)
    assert compiled(np.arange(4.0), out, 2) == pytest.approx(_typed_calls(np.arange(4.0),
                                                                           np.zeros(4), 2))
    remembered = types.Function._brdf_remembered
    assert len(remembered) >= 10
    for (fnty, ctx, _, args, kws), sig in list(remembered.items()):
        if ctx is context:
            assert BaseFunction.get_call_type(fnty, context, args, dict(kws)) == sig

    orders = []
    order = utils.order_by_target_specificity

    def counted(*args, **kwargs):
        orders.append(args)
        return order(*args, **kwargs)

    monkeypatch.setattr(utils, "order_by_target_specificity", counted)
    copysign = context.resolve_value_type(math.copysign)
    args = (types.float32, types.int16)
    first = copysign.get_call_type(context, args, {})
    tried = len(orders)
    assert copysign.get_call_type(context, args, {}) == first
    assert copysign.get_call_type(context, args, {}) == first
    assert first is not None and len(orders) == tried
    for _ in range(2):
        before = len(orders)
        with pytest.raises(errors.TypingError):
            copysign.get_call_type(context, (types.unicode_type, types.float64), {})
        assert len(orders) > before


def test_the_target_features_are_numbas(monkeypatch):
    """The features kernels are compiled for are NUMBA_CPU_FEATURES where set, else the
    host's, as numba's own code generator takes them: SIMD_INT64_PRODUCTS follows them."""
    import llvmlite.binding as ll
    from brdf import _jit
    assert _jit.SIMD_INT64_PRODUCTS == ("+avx512dq" in _jit._target_features())
    monkeypatch.setattr(numba.config, "CPU_FEATURES", "+avx2,+avx512f,+avx512dq")
    assert "+avx512dq" in _jit._target_features()
    monkeypatch.setattr(numba.config, "CPU_FEATURES", "+avx2,-avx512dq")
    assert "+avx512dq" not in _jit._target_features()
    monkeypatch.setattr(numba.config, "CPU_FEATURES", None)
    assert _jit._target_features() == ll.get_host_cpu_features().flatten().split(",")
