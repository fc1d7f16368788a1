"""Pools of spawned worker processes (``brdf.batch``, ``brdf.precompile``), and the one-line
error for a script that starts one from its top level.

Workers are spawned, not forked (numba's threads and fork do not mix), so each imports the
calling script again as it starts. A script that starts the pool at its top level starts it
again in every worker, which multiprocessing refuses with a traceback per worker and then
``BrokenProcessPool``. The functions here end such workers quietly and give the script one
:class:`~brdf.errors.MainGuardError` saying what to add."""

import os
import sys

from .errors import MainGuardError

__all__ = ["starting_a_worker", "pool", "unguarded_main"]


def starting_a_worker():
    """Whether this process is a spawned worker still importing its parent's main module
    (the script): it reached the caller from the script's top level. multiprocessing marks
    that phase with this attribute, and refuses to start processes in it."""
    import multiprocessing
    return bool(getattr(multiprocessing.current_process(), "_inheriting", False))


def _init_worker(started, initializer, initargs):
    if initializer is not None:
        initializer(*initargs)
    with started.get_lock():
        started.value += 1


def pool(processes, initializer=None, initargs=()):
    """A ``ProcessPoolExecutor`` of ``processes`` spawned workers, each running
    ``initializer(*initargs)`` as it starts, and the shared count of its workers that
    finished starting (read by :func:`unguarded_main`'s callers)."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor
    context = multiprocessing.get_context("spawn")
    started = context.Value("i", 0)
    return ProcessPoolExecutor(processes, mp_context=context, initializer=_init_worker,
                               initargs=(started, initializer, initargs)), started


def unguarded_main(call):
    """The error for a pool whose workers all died while starting: each ran the script's top
    level again, which must not make ``call``."""
    script = getattr(sys.modules.get("__main__"), "__file__", None)
    return MainGuardError(f"worker processes stopped as they started: each runs the top level "
                          f"of {os.path.basename(script) if script else 'the main script'} "
                          f"again, so {call} must be called under "
                          "'if __name__ == \"__main__\":'")
