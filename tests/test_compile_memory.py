"""The process's memory while kernels compile (brdf._compile_memory): the frame stack's freed
chunks kept for reuse, and fewer full collections."""

import gc
import json
import subprocess
import sys
import textwrap

import pytest
from numba.core.event import EventStatus

from brdf import _compile_memory
from brdf._compile_memory import CompileMemory
from test_precompile import compile_event

# A recursion 300 frames deep crosses the start of a 16 KiB chunk twice, each way: without the
# list, every call maps two chunks and unmaps them on return, and the first touch of each
# fresh page is a page fault. The same script with and without the list, in fresh processes.
_SCRIPT = textwrap.dedent("""
    import gc, json, resource, sys
    from brdf import _compile_memory as S
    installed = S.keep_freed_chunks() if sys.argv[1] == "keep" else False

    def deep(n):
        return 0 if n == 0 else 1 + deep(n - 1)

    deep(300)
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    total = sum(deep(300) for _ in range(20000))
    faults = resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before
    kept = S.kept_chunks()
    # other sizes (the object allocator's 1 MiB arenas, tens of them) still come and go
    # through the allocator: the list neither takes nor gives them
    junk = [[float(i)] * 8 for i in range(400000)]
    del junk
    kept_after = S.kept_chunks()
    # the functions outlive every reference the module holds (the interpreter calls them
    # until it exits, after the module's globals are cleared)
    if installed:
        S._installed = False
        gc.collect()
        total += sum(deep(300) for _ in range(100)) - 100 * 300
    print(json.dumps({"installed": installed, "total": total, "faults": faults,
                      "kept": kept, "kept_after": kept_after}))
""")


def _run(mode):
    done = subprocess.run([sys.executable, "-c", _SCRIPT, mode], capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


@pytest.mark.skipif(not _compile_memory._supported(),
                    reason="no frame-stack chunks to keep on this interpreter")
def test_freed_chunks_are_kept_and_taken_back():
    plain, kept = _run("plain"), _run("keep")
    assert plain["installed"] is False and kept["installed"] is True
    assert plain["total"] == kept["total"] == 20000 * 300
    # without the list every crossing faults in fresh pages; with it, the same chunks return
    assert plain["faults"] > 20000, plain
    assert kept["faults"] < 2000, kept
    assert 0 < kept["kept"] <= _compile_memory.KEPT
    assert kept["kept_after"] == kept["kept"]


def test_a_package_compile_keeps_chunks_and_collects_less_until_it_returns(monkeypatch):
    """From the first compile of a package kernel on (not other code's, and never in a
    command whose kernels are cached): the chunk list, and while the compile runs, callees'
    compiles within it included, the oldest generation's threshold raised; the process's
    own back when it returns."""
    calls = []
    monkeypatch.setattr(_compile_memory, "keep_freed_chunks", lambda: calls.append(1))
    monkeypatch.setattr(gc, "get_threshold", lambda: (700, 10, 10))
    set_to = []
    monkeypatch.setattr(gc, "set_threshold", lambda *t: set_to.append(t))
    listener = CompileMemory()
    listener.notify(compile_event("numba.np.arraymath", EventStatus.START))
    listener.notify(compile_event("numba.np.arraymath", EventStatus.END))
    assert calls == [] and set_to == []
    listener.notify(compile_event("brdf.render._integrator", EventStatus.START))
    listener.notify(compile_event("brdf.models._kernels", EventStatus.START))
    listener.notify(compile_event("brdf.models._kernels", EventStatus.END))
    assert set_to == [(700, 10, _compile_memory.FULL_AFTER)]
    listener.notify(compile_event("brdf.render._integrator", EventStatus.END))
    assert set_to[-1] == (700, 10, 10) and len(set_to) == 2
    assert calls == [1] and listener.depth == 0
