"""numba, imported without the modules its import loads for features a command does not use.

At its import numba loads three modules that a render or a check never needs, 40 ms of a
command's start on a 2-core AMD host:

- ``scipy``, if installed, only to refuse a release older than 1.0. The package requires a far
  newer scipy (``pyproject.toml``), so ``scipy`` reads as absent for that import; numba's later
  uses of scipy (its linear algebra) import it as usual.
- ``yaml`` (PyYAML, where installed), to read a ``.numba_config.yaml`` in the working directory
  at each compile, and ``importlib.metadata``, to look up numba's extensions at the first
  compile. numba receives a stand-in (:class:`_OnFirstUse`) for each, which imports the module
  the first time numba reads from it; a warm command, which compiles nothing, never does.

The stand-ins are in ``sys.modules`` only while numba loads, so an import of these modules
afterwards gets the module itself. Nothing changes where numba is imported already, or where
a module is imported already.
"""

import importlib
import importlib.util
import sys
import types


class _OnFirstUse(types.ModuleType):
    """Stands in for the module of the same name: the first attribute read of it imports the
    module and reads the attribute there, as do all later reads."""

    def __getattr__(self, attr):
        if sys.modules.get(self.__name__) is self:  # read while numba loads
            del sys.modules[self.__name__]
        return getattr(importlib.import_module(self.__name__), attr)


def _import_numba():
    held = {}
    if "scipy" not in sys.modules:
        held["scipy"] = None  # an import of it raises ImportError meanwhile
    for name in ("yaml", "importlib.metadata"):
        # a stand-in only for an installed module: numba reads an absent one as absent
        if name not in sys.modules and importlib.util.find_spec(name) is not None:
            held[name] = _OnFirstUse(name)
    sys.modules.update(held)
    try:
        import numba  # noqa: F401
    finally:
        for name, value in held.items():
            if name in sys.modules and sys.modules[name] is value:
                del sys.modules[name]


if "numba" not in sys.modules:
    _import_numba()
