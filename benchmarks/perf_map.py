"""Name numba's kernels in ``perf`` profiles, including kernels loaded from the disk cache.

Run: ``perf record -g python benchmarks/perf_map.py SCRIPT [ARGS ...]``, then
``perf report --no-children --sort symbol``.

``perf`` names just-in-time code from ``/tmp/perf-PID.map`` (lines ``START SIZE NAME``).
numba writes no such map, and ``NUMBA_ENABLE_PROFILING``, which registers LLVM's listener
instead, compiles everything anew and slowed renders fourfold in our runs. This script runs
SCRIPT as ``__main__`` after recording the machine code of every numba library the process
loads from the cache or compiles; at exit it reads each one's function symbols (offsets and
sizes in its object file, by ``nm``), finds where one of them was loaded, and writes the map.
A kernel's callees that LLVM inlined count as the kernel's own time, as in any profile.

It reaches into numba's code library (``CPUCodeLibrary``), so it is a development tool, not
part of the package.
"""

import atexit
import os
import runpy
import subprocess
import sys
import tempfile

from numba.core import codegen

_LIBRARIES = []


def _recording():
    """Patch numba's code library to remember each library and, for one loaded from the
    cache, its object code."""
    unserialize = codegen.CPUCodeLibrary._unserialize.__func__
    finalize = codegen.CPUCodeLibrary.finalize

    def unserialize_recorded(cls, cg, state):
        library = unserialize(cls, cg, state)
        if state[1] == "object":
            _LIBRARIES.append((library, state[2][0]))
        return library

    def finalize_recorded(library):
        finalize(library)
        _LIBRARIES.append((library, None))

    codegen.CPUCodeLibrary._unserialize = classmethod(unserialize_recorded)
    codegen.CPUCodeLibrary.finalize = finalize_recorded


def _symbols(obj):
    """``(offset, size, name)`` of the functions defined in object code ``obj``."""
    with tempfile.NamedTemporaryFile(suffix=".o", delete=False) as f:
        f.write(obj)
    try:
        out = subprocess.run(["nm", "-S", "--defined-only", f.name], capture_output=True,
                             text=True, check=True).stdout
    finally:
        os.unlink(f.name)
    rows = (line.split() for line in out.splitlines())
    return [(int(r[0], 16), int(r[1], 16), r[3]) for r in rows if len(r) == 4 and r[2] in "tT"]


def _lines(library, obj):
    if obj is None:
        try:
            obj = library._get_compiled_object()
        except Exception:  # a library without object code of its own (nothing to map)
            return []
    symbols = _symbols(obj)
    for offset, _, name in symbols:
        try:
            address = library.get_pointer_to_function(name)
        except Exception:
            continue
        if address:
            base = address - offset  # one text section: every function moved together
            return [f"{base + o:x} {size:x} {n}" for o, size, n in symbols]
    return []


def write_map():
    """Write ``/tmp/perf-PID.map`` for the libraries recorded so far."""
    seen, lines = set(), []
    for library, obj in _LIBRARIES:
        if id(library) not in seen:
            seen.add(id(library))
            lines += _lines(library, obj)
    with open(f"/tmp/perf-{os.getpid()}.map", "w") as f:
        f.write("\n".join(lines) + "\n")


def main():
    if len(sys.argv) < 2:
        raise SystemExit(__doc__)
    _recording()
    atexit.register(write_map)
    script = sys.argv[1]
    sys.argv = sys.argv[1:]
    sys.path.insert(0, os.path.dirname(os.path.abspath(script)))
    runpy.run_path(script, run_name="__main__")


if __name__ == "__main__":
    main()
