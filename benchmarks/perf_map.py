"""Name numba's kernels in ``perf`` profiles, including kernels loaded from the disk cache.

Run: ``perf record -g python benchmarks/perf_map.py SCRIPT [ARGS ...]``, then
``perf report --no-children --sort symbol``.

Within a kernel: ``perf report`` cannot disassemble just-in-time code, and a kernel inlines its
callees, so one symbol may hold most of a profile. With ``PERF_MAP_OBJECTS=DIR`` set, the run
also saves each library's object code in DIR (``N.o``, with ``index.tsv``: file, symbol, its
offset in the file); then ``python benchmarks/perf_map.py --annotate perf.data DIR NAME``
counts the samples at each instruction of the functions whose symbol contains NAME, prints
the hottest 512-byte windows and writes ``NAME.annotated.s`` (samples, offset, instruction;
``objdump``'s Intel syntax), where the calls, constants and square roots say which source
lines a window holds.

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
    cache, its object code (handed to the library by ``_set_compiled_object``, whichever
    code unserialises it: :mod:`brdf._kernel_cache` loads the package's kernels its own way)."""
    set_compiled = codegen.CPUCodeLibrary._set_compiled_object
    finalize = codegen.CPUCodeLibrary.finalize

    def set_compiled_recorded(library, value):
        set_compiled(library, value)
        _LIBRARIES.append((library, value))

    def finalize_recorded(library):
        finalize(library)
        _LIBRARIES.append((library, None))

    codegen.CPUCodeLibrary._set_compiled_object = set_compiled_recorded
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
    _save(obj, symbols)
    for offset, _, name in symbols:
        try:
            address = library.get_pointer_to_function(name)
        except Exception:
            continue
        if address:
            base = address - offset  # one text section: every function moved together
            return [f"{base + o:x} {size:x} {n}" for o, size, n in symbols]
    return []


def _save(obj, symbols):
    """Keep ``obj`` and its functions' offsets in $PERF_MAP_OBJECTS, if set (see --annotate)."""
    folder = os.environ.get("PERF_MAP_OBJECTS")
    if not folder or not symbols:
        return
    os.makedirs(folder, exist_ok=True)
    name = f"{len([f for f in os.listdir(folder) if f.endswith('.o')])}.o"
    with open(os.path.join(folder, name), "wb") as f:
        f.write(obj)
    with open(os.path.join(folder, "index.tsv"), "a") as f:
        f.writelines(f"{name}\t{sym}\t{offset:x}\n" for offset, _, sym in symbols)


def annotate(data, folder, name, window=512):
    """Samples of ``perf record``'s ``data`` at each instruction of the functions whose symbol
    contains ``name``, from the object code saved in ``folder`` (see the module's notes)."""
    # perf resolves symbols only with the address asked for too: lines "ADDRESS SYMBOL+0xOFF"
    out = subprocess.run(["perf", "script", "-i", data, "-F", "ip,sym,symoff"],
                         capture_output=True, text=True, check=True).stdout
    hits = {}
    for line in out.splitlines():
        sym, _, off = (line.split() or [""])[-1].rpartition("+0x")
        if name in sym:
            key = (sym, int(off, 16))
            hits[key] = hits.get(key, 0) + 1
    with open(os.path.join(folder, "index.tsv")) as f:
        rows = [line.rstrip("\n").split("\t") for line in f]
    done = set()
    for obj, sym, offset in rows:
        if name not in sym or sym in done:  # a symbol in several libraries: the first's code
            continue
        done.add(sym)
        start = int(offset, 16)
        asm = subprocess.run(["objdump", "-d", "--no-show-raw-insn", "-M", "intel",
                              f"--disassemble={sym}", os.path.join(folder, obj)],
                             capture_output=True, text=True, check=True).stdout
        listing, windows = [], {}
        for line in asm.splitlines():
            head, sep, instruction = line.partition(":\t")
            if not sep or not head.strip().isalnum():
                continue
            at = int(head, 16) - start
            n = hits.get((sym, at), 0)
            windows[at // window] = windows.get(at // window, 0) + n
            listing.append(f"{n:6d} {at:6x}: {instruction.split('<')[0].rstrip()}")
        total = sum(windows.values())
        print(f"{sym[:80]}: {total} samples")
        for w, n in sorted(windows.items(), key=lambda kv: -kv[1])[:12]:
            if n:
                print(f"  {w * window:6x}-{(w + 1) * window:6x} {n:6d} {100.0 * n / total:5.1f} %")
        path = f"{name}.annotated.s"
        with open(path, "a" if len(done) > 1 else "w") as f:
            f.write(f"# {sym}\n" + "\n".join(listing) + "\n")
        print(f"  listing in {path}")


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
    if sys.argv[1] == "--annotate":
        if len(sys.argv) != 5:
            raise SystemExit("usage: perf_map.py --annotate PERF_DATA OBJECT_DIR NAME")
        annotate(*sys.argv[2:])
        return
    _recording()
    atexit.register(write_map)
    script = sys.argv[1]
    sys.argv = sys.argv[1:]
    sys.path.insert(0, os.path.dirname(os.path.abspath(script)))
    runpy.run_path(script, run_name="__main__")


if __name__ == "__main__":
    main()
