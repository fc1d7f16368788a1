"""Memory a request needs, checked before it is allocated.

Functions that allocate in proportion to an argument (image size, sample count, mesh
resolution) estimate the bytes they will hold at their peak and call :func:`require` first: a
request that this machine cannot hold is refused with :class:`~brdf.errors.InputError` saying
how much it would need and how much is available, instead of swapping or dying on
``MemoryError`` part-way.

The memory available is ``MemAvailable`` of ``/proc/meminfo`` (the kernel's estimate of what
can be allocated without swapping), or the free physical pages where that file is missing,
and never more than the address space left under ``RLIMIT_AS``.

Large results (a model's values over a MERL-size batch) come from :func:`empty`, which lends
blocks that earlier results have given back: the system zeroes a new block's pages as they are
first written, which costs as much as evaluating a simple model into them, while a block given
back is written at once. :func:`trim` returns the blocks held to the system.
"""

import math
import os
import resource
import threading
from collections import deque

import numpy as np

from .errors import InputError

__all__ = ["available", "require", "format_bytes", "empty", "trim", "POOL_MIN", "POOL_BYTES"]

#: The smallest request :func:`empty` serves from its pool: below it the C allocator reuses
#: freed memory itself (glibc does up to 32 MiB once a block of that size has been freed).
POOL_MIN = 8 << 20
#: Most bytes held in blocks given back and not lent again; the oldest go first beyond it.
POOL_BYTES = 512 << 20
_GRAIN = 2 << 20  # block sizes are rounded up to whole huge pages, so close sizes share blocks
_ALIGN = 64  # a cache line, for the kernels' vector stores
_free = deque()  # blocks given back, oldest first: uint8 arrays of _GRAIN multiples + _ALIGN
_lock = threading.Lock()


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


class _Lease:
    """A pool block lent to one array (the array's ``base``): the block goes back to the pool
    when the array and every view of it are gone."""

    __slots__ = ("block", "__array_interface__")

    def __init__(self, block, shape, dtype):
        self.block = block
        start = block.ctypes.data
        start += -start % _ALIGN
        self.__array_interface__ = {"shape": shape, "typestr": dtype.str,
                                    "data": (start, False), "version": 3}

    def __del__(self):
        # Never blocks: a collection that drops a lease while this thread holds the lock (or
        # an interpreter shutting down) lets the block go to the system instead.
        lock = _lock
        if lock is not None and lock.acquire(blocking=False):
            try:
                _free.append(self.block)
                held = sum(b.nbytes for b in _free)
                while held > POOL_BYTES:
                    held -= _free.popleft().nbytes
            finally:
                lock.release()


def empty(shape, dtype=np.float64):
    """An uninitialised C-contiguous array, as :func:`numpy.empty`; requests of
    :data:`POOL_MIN` bytes or more reuse a block an earlier such array has given back."""
    shape = (int(shape),) if isinstance(shape, (int, np.integer)) else tuple(shape)
    dtype = np.dtype(dtype)
    nbytes = dtype.itemsize * math.prod(shape)
    if nbytes < POOL_MIN:
        return np.empty(shape, dtype)
    size = -(-nbytes // _GRAIN) * _GRAIN + _ALIGN
    block = None
    with _lock:
        for i, b in enumerate(_free):
            if b.nbytes == size:
                block = b
                del _free[i]
                break
    if block is None:
        block = np.empty(size, np.uint8)
    return np.asarray(_Lease(block, shape, dtype))


def trim():
    """Return every block :func:`empty` holds to the system; the bytes returned."""
    with _lock:
        held = sum(b.nbytes for b in _free)
        _free.clear()
    return held
