"""The free list of CPython's frame-stack chunks that compiles keep (brdf._stack_chunks)."""

import json
import subprocess
import sys
import textwrap

import pytest

from brdf import _stack_chunks

# A recursion 300 frames deep crosses the start of a 16 KiB chunk twice, each way: without the
# list, every call maps two chunks and unmaps them on return, and the first touch of each
# fresh page is a page fault. The same script with and without the list, in fresh processes.
_SCRIPT = textwrap.dedent("""
    import json, resource, sys
    from brdf import _stack_chunks as S
    installed = S.keep_freed_chunks() if sys.argv[1] == "keep" else False

    def deep(n):
        return 0 if n == 0 else 1 + deep(n - 1)

    deep(300)
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    total = sum(deep(300) for _ in range(20000))
    faults = resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before
    kept = S.kept_chunks()
    # other sizes (the object allocator's arenas) still come and go through the allocator
    junk = [[float(i)] * 8 for i in range(400000)]
    del junk
    print(json.dumps({"installed": installed, "total": total, "faults": faults,
                      "kept": kept, "kept_after": S.kept_chunks()}))
""")


def _run(mode):
    done = subprocess.run([sys.executable, "-c", _SCRIPT, mode], capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


@pytest.mark.skipif(not _stack_chunks._supported(),
                    reason="no frame-stack chunks to keep on this interpreter")
def test_freed_chunks_are_kept_and_taken_back():
    plain, kept = _run("plain"), _run("keep")
    assert plain["installed"] is False and kept["installed"] is True
    assert plain["total"] == kept["total"] == 20000 * 300
    # without the list every crossing faults in fresh pages; with it, the same chunks return
    assert plain["faults"] > 20000, plain
    assert kept["faults"] < 2000, kept
    assert 0 < kept["kept"] <= _stack_chunks.KEPT
    assert kept["kept_after"] <= _stack_chunks.KEPT

