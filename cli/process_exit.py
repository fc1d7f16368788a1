"""How the ``brdf-fit`` process ends: without the interpreter's teardown of its modules.

Once a command has returned, Python joins the process's threads, runs the exit handlers
(llvmlite's, numba's, logging's, weakref finalizers such as temporary folders' clean-up, ...)
and then frees every module's objects one at a time. That last part frees nothing the system
would not take back anyway, and it costs 0.07-0.1 s in a process that has loaded numpy, numba
and the kernels: a sixth of a warm ``brdf-fit check``.

The exit handler here is registered when :mod:`brdf_cli` is imported, before any other module
of the process has registered one (the console script imports it first), so it runs after all
of them. Armed by :func:`arm` (only the console script's entry point, :func:`brdf_cli.main.run`,
arms it; importing :mod:`brdf_cli` or calling :func:`brdf_cli.main.main` in a Python session
leaves the session's exit as it was), it flushes the standard streams and ends the process with
the command's status through :func:`os._exit`, skipping only the freeing of modules.
"""

import atexit
import os
import sys

_status = None


def arm(status):
    """End the process with ``status`` (an int, or None for 0, as :func:`sys.exit` takes them)
    after every other exit handler has run; any other status leaves the exit to Python."""
    global _status
    if status is None or isinstance(status, int):
        _status = status or 0


def _end():
    if _status is None:
        return
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # a closed stream or a reader gone: nothing left to say
            pass
    os._exit(_status)


atexit.register(_end)
