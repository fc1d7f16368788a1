"""Where numba keeps this package's compiled kernels, when they are stale, and how they load.

numba keys a cached kernel on its own source file only, but our kernels inline functions from
other modules of the package (a model's formula into the dispatcher), so an edit to one file
could leave stale machine code behind. The cache locators below stamp every kernel of this
package with a fingerprint of the source of all its kernel modules instead; they keep numba's
order of places (``NUMBA_CACHE_DIR`` when it is set, the package's ``__pycache__`` folders,
the user's cache folder).

numba loads a cached kernel only after it has imported and registered every implementation it
could ever compile (``BaseContext.refresh``: its numpy, math, random, typed-container and linear
algebra support, which imports scipy.linalg): 0.3-0.45 s of each command's start on the 2-core
development host, for machine code that needs none of it. :func:`quick_loading` makes a kernel
load without it, without compiling numba's runtime functions (:func:`_runtime_ready`) and
without importing numba's modules to rebuild environments no kernel reads
(:func:`_rebuild_env`) and without parsing the module kept for linking it into other kernels
until one does (:func:`_unserialize`); a kernel that does compile still gets all of it, from
numba's compiler.

This module holds no kernels and compiles none, so editing it leaves the cache valid; these
hooks reach into numba internals (see :mod:`brdf._jit` for the version pin).
"""

import hashlib
import os
import re
import struct
import sys
import threading

import llvmlite.binding as ll
import numpy as np
from numba.core import caching, codegen, environment, errors, types
from numba.core.typing.typeof import Purpose, typeof, typeof_impl
from numba.np import numpy_support

_PACKAGE = os.path.dirname(os.path.abspath(__file__))
_JIT = os.path.join(_PACKAGE, "_jit.py")
_KERNEL_MODULE = re.compile(rb"^from \.+_jit import|^import brdf\._jit", re.M)
#: Modules that kernels are generated from without compiling any (the family table).
_GENERATED_FROM = (os.path.join(_PACKAGE, "models", "_kinds.py"),)


def _package_stamp():
    """Hash of the source of every module that compiles kernels (imports :mod:`brdf._jit`), of
    the modules kernels are generated from, and of ``_jit`` itself: a kernel can only inline
    code from such modules. Modules without kernels (plots, scenes, the demo, the command line,
    this one) are left out, so editing them keeps the cache (recompiling everything costs
    minutes on two cores)."""
    h = hashlib.sha256()
    for root, dirs, files in os.walk(_PACKAGE):
        dirs[:] = sorted(d for d in dirs if d != "__pycache__")
        for name in sorted(f for f in files if f.endswith(".py")):
            path = os.path.join(root, name)
            with open(path, "rb") as f:
                source = f.read()
            # the substring test first: the regular expression alone, tried at every line of
            # the package's 1.4 MB of source, was 5 of the stamp's 6.4 ms in every command
            if (path == _JIT or path in _GENERATED_FROM
                    or b"_jit" in source and _KERNEL_MODULE.search(source)):
                h.update(os.path.relpath(path, _PACKAGE).encode() + b"\0" + source + b"\0")
    return h.hexdigest()


_STAMP = _package_stamp()


class _PackageStamp:
    """Mixin: invalidate cached kernels of this package when any of its files changes."""

    def get_source_stamp(self):
        return _STAMP

    @classmethod
    def from_function(cls, py_func, py_file):
        if not os.path.abspath(py_file).startswith(_PACKAGE + os.sep):
            return None
        return super().from_function(py_func, py_file)


class _UserProvided(_PackageStamp, caching.UserProvidedCacheLocator):
    pass


class _InTree(_PackageStamp, caching.InTreeCacheLocator):
    pass


class _UserWide(_PackageStamp, caching.UserWideCacheLocator):
    pass


# in numba's order: NUMBA_CACHE_DIR when it is set, else beside the source, else the user's
# cache folder (numba's own locators stay behind them, for other packages' functions)
if _InTree not in caching.CacheImpl._locator_classes:
    caching.CacheImpl._locator_classes[:0] = [_UserProvided, _InTree, _UserWide]


_runtime = {"ready": False}


def _runtime_ready(target_context):
    """What a loaded kernel's machine code links against, set up once per process: the C entry
    points of numba's reference-counting runtime (``NRT_*``). numba's C helpers (``numba_*``)
    and Python's exception objects are registered when the target context is made; a parallel
    kernel starts its threading layer itself, from the cached kernel's own ``reload_init``
    hooks.

    numba's own set-up (``rtsys.initialize``) also compiles the runtime's LLVM functions
    (reference counts, atomic adds) to machine code: 0.03 s of every command's start. A kernel
    does not call that machine code: every kernel links its own private copy of those functions
    (:func:`brdf._jit._private_copies`). So only the C entry points are registered here, as
    numba registers them; numba's compiler still runs its full set-up before it compiles."""
    if not _runtime["ready"]:
        from numba.core.runtime import _nrt_python, rtsys
        if not rtsys._init:
            for name, address in _nrt_python.c_helpers.items():
                ll.add_symbol(name if name.startswith("_") else "NRT_" + name, address)
        _arraymath_without_blas_probe()
        _runtime["ready"] = True


class _ArraymathWithoutBlasProbe:
    """Import hook: ``numba.np.arraymath`` imports without its import-time probe for BLAS.

    numba imports ``numba.np.arraymath`` when it registers its implementations to compile (and
    when it loads another package's cached function that holds one of its array functions), and
    the module probes for BLAS on import by importing all of ``scipy.linalg``: 0.1-0.25 s on
    the 2-core development host. scipy is a dependency of this package, so the probe's answer
    is known (BLAS is there); numba's linear algebra still imports scipy's BLAS when a kernel
    using it compiles. The hook waits for that import (importing the module ahead cost a
    ``check`` 0.04 s) and then leaves ``sys.meta_path``."""

    def find_spec(self, name, path=None, target=None):
        if name != "numba.np.arraymath":
            return None
        sys.meta_path.remove(self)
        import importlib.util
        spec = importlib.util.find_spec(name)
        run = spec.loader.exec_module

        def exec_module(module):
            from numba.np import linalg
            probe = linalg.ensure_blas
            linalg.ensure_blas = lambda: None
            try:
                run(module)
            finally:
                linalg.ensure_blas = probe
            module.ensure_blas = probe

        spec.loader.exec_module = exec_module
        return spec


def _arraymath_without_blas_probe():
    """Have ``numba.np.arraymath`` import without its probe for BLAS when it first imports
    (:class:`_ArraymathWithoutBlasProbe`)."""
    if "numba.np.arraymath" not in sys.modules and not any(
            isinstance(f, _ArraymathWithoutBlasProbe) for f in sys.meta_path):
        sys.meta_path.insert(0, _ArraymathWithoutBlasProbe())


_loading = threading.local()


def _rebuild_env(modname, consts, env_name):
    """numba's ``environment._rebuild_env``, which unpickles a cached function's environment,
    except that while one of this package's kernels loads, a numba module that is not imported
    yet is not imported for it.

    An environment keeps its module's globals for object-mode code only (numba's
    ``pylowering``); the package's kernels are all nopython, so theirs are never read. Yet a
    kernel that allocates an array holds numba's implementation of ``np.zeros``, whose module,
    ``numba.np.arrayobj``, took 0.06 s of a warm ``check`` to import for nothing. Its
    environment gets a stand-in namespace holding only the module's name (what numba saves of
    it again)."""
    if (getattr(_loading, "kernel", False) and modname.startswith("numba.")
            and modname not in sys.modules
            and environment.lookup_environment(env_name) is None):
        env = environment.Environment({"__name__": modname})
        env.consts[:] = consts
        env.env_name = env_name
        environment.Environment._memo[env_name] = env
        return env
    return _numba_rebuild_env(modname, consts, env_name)


# pickled cache entries name the function by module and name, so it is replaced there
_numba_rebuild_env = getattr(environment._rebuild_env, "__wrapped__", environment._rebuild_env)
_rebuild_env.__wrapped__ = _numba_rebuild_env
environment._rebuild_env = _rebuild_env


def _defined_in_object(obj):
    """Names of the functions and data that an ELF64 little-endian object file defines (the
    symbols of its symbol table with a section, other than sections' and files' own), or None
    for any other format."""
    if obj[:6] != b"\x7fELF\x02\x01":
        return None
    # ELF-64 Object File Format 1.5: e_shoff at 0x28, e_shentsize and e_shnum at 0x3a; a
    # section header (name, type, flags, address, offset, size, link, ...); a symbol (name,
    # info, other, section index, value, size)
    shoff, = struct.unpack_from("<Q", obj, 0x28)
    entsize, count = struct.unpack_from("<HH", obj, 0x3A)
    sections = [struct.unpack_from("<IIQQQQIIQQ", obj, shoff + i * entsize)
                for i in range(count)]
    names = set()
    for _, kind, _, _, offset, size, link, _, _, _ in sections:
        if kind != 2:  # SHT_SYMTAB
            continue
        strings = sections[link][4]
        for name, info, _, section, _, _ in struct.iter_unpack("<IBBHQQ",
                                                                obj[offset:offset + size]):
            # defined (not SHN_UNDEF), and not STT_SECTION (3) nor STT_FILE (4)
            if name and section != 0 and (info & 0xF) not in (3, 4):
                start = strings + name
                names.add(obj[start:obj.index(b"\0", start)].decode())
    return names


# numba's own, also if this module is imported again (as for _rebuild_env above)
_numba_unserialize = codegen.CPUCodeLibrary._unserialize.__func__
_numba_unserialize = getattr(_numba_unserialize, "__wrapped__", _numba_unserialize)
_numba_module_for_linking = getattr(codegen.CPUCodeLibrary._get_module_for_linking,
                                    "__wrapped__", codegen.CPUCodeLibrary._get_module_for_linking)


def _unserialize(cls, target_codegen, state):
    """numba's ``CPUCodeLibrary._unserialize``, except that for this package's kernels stored as
    machine code (ELF) the module for linking into other kernels is parsed from its bitcode
    when a kernel first links it (:func:`_get_module_for_linking`), not at every load, and the
    symbols the library defines are read from the machine code's symbol table.

    Parsing the Cornell box's ``trace_tiles`` module (0.5 MB of bitcode) and walking its
    symbols were 22 ms of the 31 ms its load took, in every ``brdf-fit render``; nothing links
    an entry kernel at run time. The symbol table names the same 265 symbols as the module's
    definitions (numba keeps them to answer which functions the library holds)."""
    name, kind, data = state
    names = None
    if kind == "object" and getattr(_loading, "kernel", False):
        names = _defined_in_object(data[0])
    if names is None:
        return _numba_unserialize(cls, target_codegen, state)
    object_code, linking_bitcode = data
    self = target_codegen.create_library(name)
    self.enable_object_caching()
    self._set_compiled_object(object_code)
    self._linking_bitcode = linking_bitcode
    self._finalize_final_module()
    target_codegen._engine._defined_symbols |= names
    return self


def _get_module_for_linking(self):
    """numba's ``CPUCodeLibrary._get_module_for_linking``, parsing first the bitcode that
    :func:`_unserialize` left unparsed."""
    bitcode = self.__dict__.pop("_linking_bitcode", None)
    if bitcode is not None:
        self._shared_module = ll.parse_bitcode(bitcode)
    return _numba_module_for_linking(self)


_unserialize.__wrapped__ = _numba_unserialize
_get_module_for_linking.__wrapped__ = _numba_module_for_linking
codegen.CPUCodeLibrary._unserialize = classmethod(_unserialize)
codegen.CPUCodeLibrary._get_module_for_linking = _get_module_for_linking


class _QuickLoad(caching.FunctionCache):
    """numba's cache of one function, loading without first registering all of numba's
    implementations, and without importing numba's modules to rebuild environments no kernel
    reads (see the module docstring and :func:`_rebuild_env`)."""

    def load_overload(self, sig, target_context):
        _runtime_ready(target_context)
        _loading.kernel = True
        try:
            with self._guard_against_spurious_io_errors():
                return self._load_overload(sig, target_context)
        finally:
            _loading.kernel = False


#: numba's typing of tuples, named tuples and any tuple subclass without one of its own
_TUPLE_TYPEOF = typeof_impl.dispatch(tuple)


def _argument_type(value):
    """numba's type of a kernel's argument, with exact ``np.ndarray`` values (also within
    tuples and named tuples) typed here (dtype, dimensions, layout, read-only flag); None where
    numba's ``typeof`` has to say (an unsupported value, with its own error)."""
    if isinstance(value, tuple) and typeof_impl.dispatch(type(value)) is _TUPLE_TYPEOF:
        items = [_argument_type(v) for v in value]
        return None if None in items else types.BaseTuple.from_types(items, type(value))
    if type(value) is np.ndarray:
        try:
            dtype = numpy_support.from_dtype(value.dtype)
        except errors.NumbaNotImplementedError:
            return None
        return types.Array(dtype, value.ndim, numpy_support.map_layout(value),
                           readonly=not value.flags.writeable)
    if isinstance(value, np.ndarray):  # a subclass: a masked array, which numba refuses
        return None
    try:
        return typeof(value, Purpose.argument)
    except (errors.NumbaError, ValueError):
        return None


def _typing_arrays_directly(dispatcher):
    """``dispatcher``, typing numpy array arguments (and tuples of them) itself rather than
    through numba's ``typeof``, whose first array imports ``numpy.ma`` (15 ms of each
    command's start) to refuse masked arrays: an exact ``np.ndarray`` is not one. Other values
    go to ``typeof``."""
    numba_typeof = dispatcher.typeof_pyval

    def typeof_pyval(value):
        t = _argument_type(value)
        if t is None:
            return numba_typeof(value)
        dispatcher._types_active_call.add(t)  # as numba's typeof_pyval does
        return t

    dispatcher.typeof_pyval = typeof_pyval
    return dispatcher


def stamped_marker(dispatcher, name):
    """Path of a marker file ``name`` beside the cached kernels of ``dispatcher``, stamped with
    the package's kernel sources (an edit of any of them leaves the marker behind, unread), or
    None for a dispatcher without a disk cache. A marker says something of the cache that
    numba does not record, such as which kernels a command compiled ahead of use."""
    folder = getattr(getattr(dispatcher, "_cache", None), "_cache_path", None)
    return None if folder is None else os.path.join(folder, f"{name}-{_STAMP[:20]}")


def _extensions_when_compiling(dispatcher):
    """``dispatcher``, leaving numba's third-party extensions (the ``numba_extensions`` entry
    points) to be set up when a kernel compiles, not on a kernel's first call: finding them
    reads every installed distribution's metadata (0.013 s with 118 installed, each command's
    start), and a kernel loaded from the cache needs none. A compile still sets them up first
    (numba's compiler refreshes its target context, which calls ``entrypoints.init_all``)."""
    dispatcher._compilation_chain_init_hook = lambda: None
    return dispatcher


class _CacheOnFirstUse:
    """A dispatcher's disk cache until numba first reads it: then the function's
    :class:`_QuickLoad` cache, which takes its place in the dispatcher.

    Making the cache finds its folder, checks that it is writable by creating a file in it and
    stamps it: 17 ms of each command's start for the 207 kernels ``import brdf.render``
    defines, of which a render loads a handful."""

    __slots__ = ("_dispatcher",)

    def __init__(self, dispatcher):
        self._dispatcher = dispatcher

    def __getattr__(self, name):
        cache = self._dispatcher._cache = _QuickLoad(self._dispatcher.py_func)
        return getattr(cache, name)


def quick_loading(dispatcher):
    """``dispatcher`` (made without numba's ``cache=True``) cached to disk, its cache made on
    first use (:class:`_CacheOnFirstUse`), loading its cached machine code without numba's
    full set-up, and typing its array arguments without importing ``numpy.ma``."""
    dispatcher._cache = _CacheOnFirstUse(dispatcher)
    return _extensions_when_compiling(_typing_arrays_directly(dispatcher))
