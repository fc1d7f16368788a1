"""How the process's memory is handled while numba compiles this package's kernels.

A cold compile of every kernel spent an eighth of its time on memory housekeeping that the
compiler's way of working sets off (perf and ``gc.callbacks``, one process, 58-60 s):

- **frame-stack chunks.** Since Python 3.11 a thread's Python frames live on a stack of memory
  chunks of 16 KiB, each mapped from the system when a call needs room past the last chunk
  and unmapped when the first frame in it returns (CPython's ``_PyThreadState_PushFrame`` and
  ``_PyThreadState_PopFrame``, through the arena allocator). numba's compiler recurses deeply
  and often, and its calls cross a chunk's start over and over: 259,067 ``munmap`` and
  259,911 ``mmap`` calls and 404,102 page faults, 3.0-3.4 s of system time.
  :func:`keep_freed_chunks` puts a free list of up to :data:`KEPT` such chunks in front of
  the interpreter's arena allocator (``PyObject_SetArenaAllocator``): a freed 16 KiB block is
  kept, and the next request of that size takes it back; any other size, or a full list,
  goes to the allocator as before, which also frees what it made before the list was there.
  The two functions are a few lines of LLVM IR compiled by llvmlite (numba's own
  dependency); they run with the GIL held, as every call of the arena allocator does, so the
  list needs no lock. Interpreters without a GIL, other than CPython, or before 3.11 are
  left alone. Side by side (every kernel in one process, empty caches, one process per core):
  59.6, 59.4 and 59.9 s without, 56.9, 56.0 and 54.2 s with.
- **full collections.** The compiler's objects pile up (types, IR, code libraries), and
  CPython's cyclic collector ran a full collection each time the old generation had grown by a
  quarter: 24 of them, 4.0 of its 4.8 s. While a kernel compiles, the oldest generation's
  threshold is :data:`FULL_AFTER` collections of the middle one instead of 10 (6 full
  collections, 1.6 s), and the process's own thresholds come back when the compile returns.
  Side by side, with the chunk list on both sides: 56.3 and 56.2 s before, 53.7 and 54.6 s
  after; peak 703 MB against 729 MB.

:class:`CompileMemory` does both from the first compile of one of the package's kernels
(``numba:compile`` events, which numba raises only for a kernel not in its disk cache), so a
command whose kernels are all cached never does either.
"""

import ctypes
import gc
import sys
import sysconfig

from numba.core import event

from .kernel_groups import compiling_group, listening

__all__ = ["keep_freed_chunks", "kept_chunks", "CompileMemory", "manage_compile_memory",
           "KEPT", "CHUNK", "FULL_AFTER"]

#: The size of CPython's frame-stack chunks (``DATA_STACK_CHUNK_SIZE``, 3.11 on); a frame
#: larger than a chunk gets a chunk of its own, of a power-of-two multiple, which is left to
#: the allocator.
CHUNK = 16384
#: Chunks kept at most (1 MiB).
KEPT = 64
#: The oldest generation's threshold while a kernel compiles: a full collection after this
#: many collections of the middle generation (CPython's default 10; 100 saved 0.4 s more than
#: 50 but kept 38 MB more, and none at all kept 290 MB more than the default).
FULL_AFTER = 50

_IR = """
@orig_ctx = global i8* null
@orig_alloc = global i8* (i8*, i64)* null
@orig_free = global void (i8*, i8*, i64)* null
@kept = global [{kept} x i8*] zeroinitializer
@count = global i64 0

define i8* @brdf_chunk_alloc(i8* %ctx, i64 %size) {{
entry:
  %n = load i64, i64* @count
  %chunk = icmp eq i64 %size, {chunk}
  %some = icmp sgt i64 %n, 0
  %reuse = and i1 %chunk, %some
  br i1 %reuse, label %pop, label %allocator
pop:
  %m = sub i64 %n, 1
  store i64 %m, i64* @count
  %slot = getelementptr [{kept} x i8*], [{kept} x i8*]* @kept, i64 0, i64 %m
  %p = load i8*, i8** %slot
  ret i8* %p
allocator:
  %c = load i8*, i8** @orig_ctx
  %f = load i8* (i8*, i64)*, i8* (i8*, i64)** @orig_alloc
  %r = call i8* %f(i8* %c, i64 %size)
  ret i8* %r
}}

define void @brdf_chunk_free(i8* %ctx, i8* %ptr, i64 %size) {{
entry:
  %n = load i64, i64* @count
  %chunk = icmp eq i64 %size, {chunk}
  %room = icmp slt i64 %n, {kept}
  %keep = and i1 %chunk, %room
  br i1 %keep, label %push, label %allocator
push:
  %slot = getelementptr [{kept} x i8*], [{kept} x i8*]* @kept, i64 0, i64 %n
  store i8* %ptr, i8** %slot
  %m = add i64 %n, 1
  store i64 %m, i64* @count
  ret void
allocator:
  %c = load i8*, i8** @orig_ctx
  %f = load void (i8*, i8*, i64)*, void (i8*, i8*, i64)** @orig_free
  call void %f(i8* %c, i8* %ptr, i64 %size)
  ret void
}}
"""


class _ArenaAllocator(ctypes.Structure):
    """CPython's ``PyObjectArenaAllocator``."""
    _fields_ = [("ctx", ctypes.c_void_p), ("alloc", ctypes.c_void_p),
                ("free", ctypes.c_void_p)]


#: The installed list's engine (never released), module and allocators, or False where it
#: cannot be installed; None before the first call.
_installed = None


def _supported():
    return (sys.implementation.name == "cpython" and sys.version_info >= (3, 11)
            and not sysconfig.get_config_var("Py_GIL_DISABLED"))


def _install():
    import llvmlite.binding as llvm
    llvm.initialize_native_target()
    llvm.initialize_native_asmprinter()
    module = llvm.parse_assembly(_IR.format(kept=KEPT, chunk=CHUNK))
    machine = llvm.Target.from_default_triple().create_target_machine()
    engine = llvm.create_mcjit_compiler(module, machine)
    engine.finalize_object()
    before = _ArenaAllocator()
    ctypes.pythonapi.PyObject_GetArenaAllocator(ctypes.byref(before))
    for name, value in (("orig_ctx", before.ctx), ("orig_alloc", before.alloc),
                        ("orig_free", before.free)):
        ctypes.c_void_p.from_address(engine.get_global_value_address(name)).value = value
    after = _ArenaAllocator(None, engine.get_function_address("brdf_chunk_alloc"),
                            engine.get_function_address("brdf_chunk_free"))
    ctypes.pythonapi.PyObject_SetArenaAllocator(ctypes.byref(after))
    # the interpreter frees chunks through these functions until the process ends, after the
    # module's globals are gone: the engine that holds their code is never released
    ctypes.pythonapi.Py_IncRef(ctypes.py_object(engine))
    return engine, module, machine, before, after


def keep_freed_chunks():
    """Put the free list of frame-stack chunks in front of the interpreter's arena allocator,
    once per process; whether it is there."""
    global _installed
    if _installed is None:
        _installed = False
        if _supported():
            try:
                _installed = _install()
            except Exception:  # an llvmlite or interpreter this was not made for: leave it
                _installed = False
    return _installed is not False


def kept_chunks():
    """How many freed chunks the list holds now (0 where it is not installed)."""
    if not _installed:
        return 0
    engine = _installed[0]
    return ctypes.c_int64.from_address(engine.get_global_value_address("count")).value


class CompileMemory(event.Listener):
    """Listens to numba's compiles (``numba:compile`` events): at the first one of a package
    kernel, :func:`keep_freed_chunks`; while one runs (callees' compiles within it), the
    oldest generation's threshold at :data:`FULL_AFTER`, the process's own put back when it
    returns."""

    def __init__(self):
        self.depth, self.saved = 0, None

    def on_start(self, compile_event):
        if compiling_group(compile_event) is None:
            return
        if self.depth == 0:
            keep_freed_chunks()
            self.saved = gc.get_threshold()
            gc.set_threshold(self.saved[0], self.saved[1], max(self.saved[2], FULL_AFTER))
        self.depth += 1

    def on_end(self, compile_event):
        if compiling_group(compile_event) is None:
            return
        self.depth -= 1
        if self.depth == 0 and self.saved is not None:
            gc.set_threshold(*self.saved)


def manage_compile_memory():
    """The process's :class:`CompileMemory`, listening to numba from the first call on."""
    return listening(CompileMemory)
