"""Shared test configuration: the test helpers (``chi2``, ``model_cases``) import from tests/,
and hypothesis runs derandomised so a failure reproduces on every run and machine."""

import os
import signal
import sys

import pytest
from hypothesis import settings

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
# Subprocesses (scripts, the installed brdf-fit, spawned workers) import the checkout's brdf,
# as this process does (python -m pytest puts it first on sys.path): its kernels are the ones
# the suite compiles before it starts, so a subprocess never compiles one on first use and
# says so on its stderr. The installed copy is the same code.
_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
os.environ["PYTHONPATH"] = os.pathsep.join(
    p for p in (_ROOT, os.environ.get("PYTHONPATH")) if p)

settings.register_profile("brdf", derandomize=True, deadline=None, print_blob=True)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "brdf"))


def pytest_configure(config):
    """Under pytest-xdist (``-n``), compile numba's kernels before the workers start, the
    groups side by side in two processes (brdf.precompile): otherwise every worker compiles
    the same kernels itself when its tests first call them, which on a cold cache is most of
    the suite's time. On a warm cache this only starts two processes. Then, in every test
    process, the compile notices are taken as said (see below)."""
    if getattr(config.option, "numprocesses", None) and not hasattr(config, "workerinput"):
        from brdf.precompile import precompile
        precompile(processes=2)
    # Tests compare stderr exactly, and a kernel compiled on first use in the test process (a
    # cold cache without -n, a kernel no group compiles) would add its one-line notice there:
    # take every group's notice as said. Tests of the notice use their own CompileNotice, or
    # a subprocess.
    from brdf.kernel_groups import KERNELS, announce_first_compiles
    announce_first_compiles().announced.update(KERNELS)


def pytest_collection_modifyitems(config, items):
    """Slow tests first: under xdist the workers then end on short tests together, instead of
    one worker finishing a long test while the other waits."""
    items.sort(key=lambda item: item.get_closest_marker("slow") is None)


_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


def _signal_state():
    """Python's handler of each of :data:`_SIGNALS`, and whether the process ignores it (the
    kernel's mask, which a subprocess inherits, whoever set it)."""
    with open("/proc/self/status") as f:
        ignored = int(next(line for line in f if line.startswith("SigIgn:")).split()[1], 16)
    return {signal.Signals(s).name: (signal.getsignal(s), bool(ignored >> (s - 1) & 1))
            for s in _SIGNALS}


@pytest.fixture(autouse=True)
def _signals_as_found():
    """Every test leaves the signal handlers as it found them: a SIGINT left ignored is
    inherited by every later subprocess of the worker (``brdf-fit explore`` then never stops
    on Ctrl-C), and a handler left installed outlives its test."""
    if not os.path.exists("/proc/self/status"):
        yield
        return
    before = _signal_state()
    yield
    after = _signal_state()
    assert after == before, f"the test changed the signal handlers: {before} -> {after}"
