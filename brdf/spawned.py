"""Pools of spawned worker processes (``brdf.batch``, ``brdf.precompile``), and the one-line
error for a script that starts one from its top level.

Workers are spawned, not forked (numba's threads and fork do not mix), so each imports the
calling script again as it starts. A script that starts the pool at its top level starts it
again in every worker, which multiprocessing refuses with a traceback per worker and then
``BrokenProcessPool``. The functions here end such workers quietly and give the script one
:class:`~brdf.errors.MainGuardError` saying what to add."""

import contextlib
import os
import sys

from .errors import MainGuardError

__all__ = ["stop_if_starting", "pool", "main_guarded"]


def stop_if_starting():
    """End this process quietly (exit status 1) if it is a spawned worker still importing its
    parent's main module (the script), which reached the caller from its top level: its
    parent then raises the one line of :func:`main_guarded`, rather than multiprocessing's
    traceback per worker. multiprocessing marks that phase with ``_inheriting``, and refuses
    to start processes in it."""
    import multiprocessing
    if getattr(multiprocessing.current_process(), "_inheriting", False):
        raise SystemExit(1)


def _init_worker(started, initializer, initargs):
    if initializer is not None:
        initializer(*initargs)
    with started.get_lock():
        started.value += 1


def pool(processes, initializer=None, initargs=()):
    """A ``ProcessPoolExecutor`` of ``processes`` spawned workers, each running
    ``initializer(*initargs)`` as it starts, and the shared count of its workers that
    finished starting (for :func:`main_guarded`)."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor
    context = multiprocessing.get_context("spawn")
    started = context.Value("i", 0)
    return ProcessPoolExecutor(processes, mp_context=context, initializer=_init_worker,
                               initargs=(started, initializer, initargs)), started


@contextlib.contextmanager
def main_guarded(started, call):
    """Within the block, a pool whose workers all died while starting (``started``, the count
    :func:`pool` gives, still 0) raises MainGuardError: each ran the script's top level again,
    which must not make ``call``. A pool broken after a worker started raises as it was."""
    from concurrent.futures.process import BrokenProcessPool
    try:
        yield
    except BrokenProcessPool:
        if started.value:  # a worker died after starting: not the main module's doing
            raise
        script = getattr(sys.modules.get("__main__"), "__file__", None)
        script = os.path.basename(script) if script else "the main script"
        raise MainGuardError(f"worker processes stopped as they started: each runs the top "
                             f"level of {script} again, so {call} must be called under "
                             "'if __name__ == \"__main__\":'") from None
