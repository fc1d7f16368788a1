"""Memory a request needs, checked before it is allocated.

Functions that allocate in proportion to an argument (image size, sample count, mesh
resolution) estimate the bytes they will hold at their peak and call :func:`require` first: a
request that this machine cannot hold is refused with :class:`~brdf.errors.InputError` saying
how much it would need and how much is available, instead of swapping or dying on
``MemoryError`` part-way.

The memory available is ``MemAvailable`` of ``/proc/meminfo`` (the kernel's estimate of what
can be allocated without swapping), or the free physical pages where that file is missing,
and never more than the address space left under ``RLIMIT_AS``.
"""

import os
import resource

from .errors import InputError

__all__ = ["available", "require", "format_bytes"]


def format_bytes(n):
    """``n`` bytes for a message: ``512 B``, ``3.4 MB``, ``26.0 GB`` (powers of 1000)."""
    for unit, scale in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if n >= scale:
            return f"{n / scale:.1f} {unit}"
    return f"{int(n)} B"


def _meminfo_available():
    try:
        with open("/proc/meminfo", encoding="ascii") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, AttributeError):
        return None


def _address_space_left():
    soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    if soft == resource.RLIM_INFINITY:
        return None
    try:
        with open("/proc/self/statm", encoding="ascii") as f:
            used = int(f.read().split()[0]) * resource.getpagesize()
    except (OSError, ValueError, IndexError):
        return None
    return max(soft - used, 0)


def available():
    """Bytes this process can allocate now without swapping (None when unknown)."""
    known = [n for n in (_meminfo_available(), _address_space_left()) if n is not None]
    return min(known) if known else None


def require(nbytes, what):
    """Raise :class:`InputError` unless ``nbytes`` can be allocated now.

    ``what`` names the request for the message (``"render --size 16384x16384"``).
    """
    nbytes = int(nbytes)
    free = available()
    if free is not None and nbytes > free:
        raise InputError(f"{what} needs about {format_bytes(nbytes)} of memory; this machine "
                         f"has {format_bytes(free)} available")
