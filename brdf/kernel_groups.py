"""The library's numba kernels in groups, and the line printed before a group first compiles.

numba compiles a kernel on its first call unless its disk cache holds it; on a cold cache a
group's kernels take a minute or more, and the process looks hung meanwhile.
:class:`CompileNotice`, which :mod:`brdf._jit` installs, prints one line on stderr before
that happens, once per group and process, saying what compiles and about how long it takes.
It hears of compiles from numba's ``numba:compile`` events, which numba raises only when a
kernel is not in its disk cache: a warm cache prints nothing and costs nothing.
:mod:`brdf.precompile` compiles the groups ahead of use.

This module imports no kernels, so editing it leaves the cache valid (see :mod:`brdf._jit`).
"""

from numba.core import event

__all__ = ["KERNELS", "COLD_SECONDS", "group_of", "compiling_group", "CompileNotice", "listening",
           "announce_first_compiles"]

#: What each group's kernels are called in the notice, and the modules that hold them (a
#: module name, or a package's prefix ending in a dot).
KERNELS = {"models": ("the model kernels", ("brdf.models.", "brdf.sampling", "brdf._directions")),
           "fitting": ("the fitting kernels", ("brdf.fitting.",)),
           "tables": ("the measured-table kernels", ("brdf.io.", "brdf.triangulation")),
           "render": ("the renderer's kernels", ("brdf.render.",))}

#: Seconds a cold compile of each group alone takes on one idle core, rounded up to 5 s: the
#: CPU seconds of ``brdf.precompile.compile_groups([group])`` in a fresh process with an empty
#: cache (NUMBA_CACHE_LOCATOR_CLASSES=UserProvidedCacheLocator, a new NUMBA_CACHE_DIR), one
#: group after another, on the 2-core Intel development host (2026-12-06, load average 1.1):
#: models 30.9 s, fitting 22.7 s, tables 9.6 s, render 36.5 s. A first command compiles only
#: the kernels it calls, for its model's families alone (see
#: ``brdf.models._kernels.family_kinds``): a first ``check`` of ``lambert + ggx`` 7.4 s.
COLD_SECONDS = {"models": 35, "fitting": 25, "tables": 10, "render": 40}


def group_of(module):
    """The kernel group of a module's kernels (``"brdf.models.lambert"``: ``"models"``), or
    None for a module outside them."""
    for group, (_, modules) in KERNELS.items():
        if any(module.startswith(m) if m.endswith(".") else module == m for m in modules):
            return group
    return None


def compiling_group(compile_event):
    """The group of the kernel a ``numba:compile`` event is about (:func:`group_of` of its
    function's module), or None for a function that is not one of the package's kernels."""
    function = getattr(compile_event.data.get("dispatcher"), "py_func", None)
    return group_of(getattr(function, "__module__", None) or "")


class CompileNotice(event.Listener):
    """Listens to numba's compiles of this package's kernels (``numba:compile`` events, which
    numba raises only when a kernel is not in its disk cache).

    Before the first compile of each group in this process, one line on stderr
    (:func:`brdf.progress.note`, silenced by ``quiet``): ``compiling the model kernels once
    for this machine (up to about 35 s) ...``, the group's :data:`COLD_SECONDS` (a command
    may need only part of the group). A kernel's callees compile within its own compile;
    they count as its work and print nothing of their own.

    Attributes
    ----------
    compiled : int
        Kernels of this package numba compiled in this process (callees included).
    announced : set of str
        Groups whose notice was printed.
    """

    def __init__(self):
        self.compiled, self.announced, self.depth = 0, set(), 0

    def on_start(self, compile_event):
        group = compiling_group(compile_event)
        if group is None:
            return
        if self.depth == 0 and group not in self.announced:
            from .progress import note
            self.announced.add(group)
            note(f"compiling {KERNELS[group][0]} once for this machine "
                 f"(up to about {COLD_SECONDS[group]} s) ...")
        self.depth += 1
        self.compiled += 1

    def on_end(self, compile_event):
        if compiling_group(compile_event) is not None:
            self.depth -= 1


_listeners = {}


def listening(kind):
    """The process's one listener of class ``kind`` to numba's compiles (``numba:compile``
    events), made and registered at the first call."""
    if kind not in _listeners:
        _listeners[kind] = kind()
        event.register("numba:compile", _listeners[kind])
    return _listeners[kind]


def announce_first_compiles():
    """The process's :class:`CompileNotice`, listening to numba from the first call on."""
    return listening(CompileNotice)
