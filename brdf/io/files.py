"""Opening input files safely, and writing output files atomically.

Every reader takes its bytes through :func:`read_bytes` (or :func:`read_text`): the file is
opened without blocking, checked to be a regular file on the open descriptor (a FIFO, a device
such as ``/dev/zero`` or a socket is refused, never read), and read up to a size cap, the most
that its format can hold; a larger file is refused before it is read. Every writer goes through
:class:`atomic_output`: a temporary file beside the target, renamed over it when complete.

Temporary files are named ``.STEM.PID.RANDOM.SUFFIX``. A process killed before its rename
(SIGKILL, a crash) leaves its temporary file behind; the next :class:`atomic_output` for the
same target removes every temporary file of that target whose process is no longer running.
"""

import errno
import json
import os
import re
import stat
import tempfile
import threading
from pathlib import Path

from ..errors import FormatError, OutputError
from ..memory import format_bytes

__all__ = ["check_file", "read_bytes", "read_head", "read_text", "read_json", "parse_json", "parse_toml",
           "atomic_output", "remove_stale_temporaries", "file_sha256", "openexr", "MAX_BYTES"]

#: Size cap of a reader that names none: 1 GiB, far above any measured table in a text or
#: archive format (MERL's binary files are 35 MB, RGL's spectral .bsdf files a few MB).
MAX_BYTES = 1 << 30

_KINDS = ((stat.S_ISFIFO, "a FIFO (named pipe)"), (stat.S_ISCHR, "a character device"),
          (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"))


_openexr_pool = threading.Lock()


def openexr():
    """The ``OpenEXR`` module, its process-wide pool of threads (which compresses and
    decompresses a file's blocks of scanlines in parallel) sized the first time, unless
    something has set a size: to the package's thread count (:func:`brdf._threads.thread_count`)
    once numba is imported, else to the cores the process may run on (not importing numba for
    it, 0.15 s).

    The pool is empty by default, and a file is then compressed on one thread: a rendered
    256 x 256 image with its three layers (ZIP) took 26 ms to write, 15 ms with two threads."""
    import sys
    import OpenEXR
    if OpenEXR.global_thread_count() == 0:
        from .._threads import thread_count
        with _openexr_pool:
            if OpenEXR.global_thread_count() == 0:
                count = (thread_count() if "numba" in sys.modules
                         else len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity")
                         else os.cpu_count() or 1)
                OpenEXR.set_global_thread_count(max(1, count))
    return OpenEXR


def _open(path, what):
    """A file object of the regular file ``path``, open for reading, and its size."""
    try:
        # O_NONBLOCK: opening a FIFO for reading would otherwise wait for a writer forever
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    except FileNotFoundError:
        raise FormatError(path, "", "no such file") from None
    except IsADirectoryError:
        raise FormatError(path, "", f"is a folder; expected {what}") from None
    except OSError as e:
        raise FormatError(path, "", f"cannot be read ({e.strerror})") from None
    try:
        info = os.fstat(fd)
        if stat.S_ISDIR(info.st_mode):
            raise FormatError(path, "", f"is a folder; expected {what}")
        if not stat.S_ISREG(info.st_mode):
            kind = next((k for test, k in _KINDS if test(info.st_mode)), "not a regular file")
            raise FormatError(path, "", f"is {kind}, not a regular file; expected {what}")
        os.set_blocking(fd, True)
        return os.fdopen(fd, "rb"), info.st_size
    except BaseException:
        os.close(fd)
        raise


def _too_large(path, size, limit, what):
    return FormatError(path, "", f"is {format_bytes(size)} ({size:,} bytes); {what} holds at "
                                 f"most {format_bytes(limit)} ({limit:,} bytes)")


def file_sha256(path):
    """SHA-256 (hex) of a file's bytes, read in 1 MB blocks (photographs and tables are
    large); for provenance, not for reading the file's content."""
    import hashlib
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def check_file(path, limit=MAX_BYTES, what="a data file"):
    """Check, without reading it, that ``path`` is a regular file of at most ``limit`` bytes,
    for libraries that open a path themselves (images, meshes); its size in bytes.

    Raises the :class:`FormatError` of :func:`read_bytes`.
    """
    f, size = _open(path, what)
    f.close()
    if size > limit:
        raise _too_large(path, size, limit, what)
    return size


def read_bytes(path, limit=MAX_BYTES, what="a data file"):
    """The whole regular file ``path`` as bytes, refused if larger than ``limit`` bytes.

    ``what`` names what the file should be, for the messages (``"a MERL .binary file"``).

    Raises
    ------
    FormatError
        A missing or unreadable file, a folder, a FIFO, device or socket, or a file larger
        than ``limit``; the message names the file.
    """
    f, size = _open(path, what)
    with f:
        if size > limit:
            raise _too_large(path, size, limit, what)
        try:
            data = f.read(limit + 1)
        except OSError as e:
            raise FormatError(path, "", f"cannot be read ({e.strerror})") from None
    if len(data) > limit:  # the file grew while it was read
        raise _too_large(path, len(data), limit, what)
    return data


def read_head(path, n, what="a data file"):
    """The first ``n`` bytes of the regular file ``path`` (for sniffing its format)."""
    f, _ = _open(path, what)
    with f:
        try:
            return f.read(n)
        except OSError as e:
            raise FormatError(path, "", f"cannot be read ({e.strerror})") from None


def decode_utf8(path, data, what):
    """``data`` decoded as UTF-8 (a byte-order mark dropped); :class:`FormatError` naming the
    line and byte offset of the first byte that is not UTF-8."""
    try:
        return data.decode("utf-8").removeprefix("\ufeff")
    except UnicodeDecodeError as e:
        line = data.count(b"\n", 0, e.start) + 1
        raise FormatError(path, f"line {line}",
                          f"byte {e.start} ({data[e.start:e.start + 1]!r}) is not UTF-8; "
                          f"expected {what} in UTF-8") from None


def read_text(path, limit=MAX_BYTES, what="a text file"):
    """The regular file ``path`` decoded as UTF-8, with the checks of :func:`read_bytes`."""
    return decode_utf8(path, read_bytes(path, limit, what), what)


#: Deepest nesting of arrays and objects accepted in a JSON or TOML document; the documents
#: of this package nest five levels or so, and Python's parsers recurse once per level.
MAX_DEPTH = 100


def nesting_error(path, text, what):
    """A :class:`FormatError` if ``text`` (JSON or TOML) nests brackets deeper than
    :data:`MAX_DEPTH` outside strings, else None (checked before parsing, which recurses)."""
    depth = 0
    quote = None
    escaped = False
    line = 1
    for ch in text:
        if ch == "\n":
            line += 1
        if quote:
            if escaped:
                escaped = False
            elif ch == "\\" and quote == '"':
                escaped = True
            elif ch == quote:
                quote = None
        elif ch in "\"'":
            quote = ch
        elif ch in "[{":
            depth += 1
            if depth > MAX_DEPTH:
                return FormatError(path, f"line {line}", f"nested more than {MAX_DEPTH} levels "
                                                         f"deep; expected {what}")
        elif ch in "]}":
            depth -= 1
    return None


def read_json(path, limit=MAX_BYTES, what="a JSON document"):
    """The JSON document in the regular file ``path``: UTF-8, at most ``limit`` bytes, nested
    at most :data:`MAX_DEPTH` levels; :class:`FormatError` naming the file and line otherwise."""
    text = read_text(path, limit, what)
    return parse_json(path, text, what)


def parse_json(path, text, what):
    """``json.loads(text)`` with the nesting check; errors name ``path`` and the line."""
    # only documents with many brackets can be too deep: skip the scan for the rest
    if text.count("[") + text.count("{") > MAX_DEPTH:
        error = nesting_error(path, text, what)
        if error:
            raise error
    try:
        return json.loads(text)
    except json.JSONDecodeError as e:
        raise FormatError(path, f"line {e.lineno}", f"not valid JSON ({e.msg}); expected "
                                                    f"{what}") from None
    except RecursionError:
        raise FormatError(path, "", f"nested too deeply; expected {what}") from None


def parse_toml(path, text, what):
    """``tomllib.loads(text)`` with the nesting check; errors name ``path`` and the place."""
    import tomllib
    if text.count("[") + text.count("{") > MAX_DEPTH:
        error = nesting_error(path, text, what)
        if error:
            raise error
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        # the message ends "(at line L, column C)"
        raise FormatError(path, "", f"not valid TOML ({e}); expected {what}") from None
    except RecursionError:
        raise FormatError(path, "", f"nested too deeply; expected {what}") from None


# --- atomic output ---------------------------------------------------------------------------

def _temp_pattern(path):
    """The names of :class:`atomic_output`'s temporary files for ``path``, PID as group 1."""
    return re.compile(re.escape(f".{path.stem}.") + r"(\d+)\.[a-z0-9_]{8}"
                      + re.escape(path.suffix) + r"\Z")


def _running(pid):
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process
        return True
    return True


def remove_stale_temporaries(path):
    """Remove the temporary files that :class:`atomic_output` left beside ``path`` in processes
    that are no longer running (killed before their rename); the names removed."""
    path = Path(path)
    pattern = _temp_pattern(path)
    removed = []
    try:
        entries = list(os.scandir(path.parent))
    except OSError:
        return removed
    for entry in entries:
        m = pattern.match(entry.name)
        if m and int(m.group(1)) != os.getpid() and not _running(int(m.group(1))):
            try:
                os.unlink(entry.path)
                removed.append(entry.name)
            except OSError:
                pass
    return removed


class atomic_output:
    """Context manager yielding a temporary path next to ``path``; on success the temporary
    file replaces ``path``, on failure (an exception, or SIGINT/SIGTERM turned into one by the
    command line) it is removed. Refuses an existing ``path`` unless ``force``, and a ``path``
    that is a folder. The temporary name ``.STEM.PID.RANDOM.SUFFIX`` keeps the extension so
    writers that look at it still work; temporary files of ``path`` left by processes that
    are gone are removed first (see :func:`remove_stale_temporaries`)."""

    def __init__(self, path, force=False):
        self.path = Path(path)
        self.force = force

    def __enter__(self):
        if self.path.is_dir():
            raise OutputError(f"{self.path}: is a folder; expected a file name to write")
        if self.path.exists() and not self.force:
            raise OutputError(f"{self.path}: exists; pass --force (force=True) to replace it")
        if not self.path.parent.is_dir():
            raise OutputError(f"{self.path}: folder {self.path.parent} does not exist")
        remove_stale_temporaries(self.path)
        try:
            fd, name = tempfile.mkstemp(prefix=f".{self.path.stem}.{os.getpid()}.",
                                        suffix=self.path.suffix, dir=self.path.parent)
        except OSError as e:
            raise OutputError(f"{self.path}: cannot write in {self.path.parent} "
                              f"({e.strerror})") from None
        os.close(fd)
        # mkstemp makes the file private (0600); give it the permissions a plain open() would
        mask = os.umask(0)
        os.umask(mask)
        os.chmod(name, 0o666 & ~mask)
        self.tmp = Path(name)
        return self.tmp

    def __exit__(self, kind, value, traceback):
        if kind is None:
            try:
                os.replace(self.tmp, self.path)
            except OSError as e:
                self.tmp.unlink(missing_ok=True)
                if e.errno in (errno.EISDIR, errno.ENOTEMPTY, errno.EEXIST):
                    raise OutputError(f"{self.path}: is a folder; expected a file name to "
                                      "write") from None
                raise OutputError(f"{self.path}: cannot be written ({e.strerror})") from None
        else:
            self.tmp.unlink(missing_ok=True)
        return False
