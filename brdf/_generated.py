"""Source the package generates at import, compiled once and kept beside its bytecode.

``brdf.models._kernels`` generates the dispatchers over the family table as Python source at
each import; compiling it took 6 ms of every command. :func:`compiled` keeps the code object in
the module's ``__pycache__`` (as ``marshal`` data, the format of Python's own bytecode files),
named by a digest of the source, the file name it is compiled under and the interpreter's
bytecode version, so a changed table or another Python compiles anew.
"""

import hashlib
import importlib.util
import marshal
import os
import sys

_CODE = type(compile("", "", "exec"))


def cache_path(source, filename):
    """Where :func:`compiled` keeps the code of ``source`` compiled under ``filename`` (a
    module's file): beside its bytecode, or None where the interpreter keeps none."""
    try:
        pyc = importlib.util.cache_from_source(filename)
    except (NotImplementedError, ValueError):  # no cache tag, or a name it cannot place
        return None
    digest = hashlib.sha256(b"\0".join([importlib.util.MAGIC_NUMBER, filename.encode(),
                                        source.encode()])).hexdigest()[:20]
    return f"{pyc[:-len('.pyc')]}.generated-{digest}.bin"


def compiled(source, filename):
    """The code object of ``source`` compiled under ``filename`` (as ``compile(source,
    filename, "exec")``), read from :func:`cache_path` when an earlier process kept it there.

    A missing, unreadable or damaged file compiles the source again, and the code is written
    (atomically, replacing the file's older versions) unless Python writes no bytecode
    (``sys.dont_write_bytecode``) or the directory is read-only."""
    path = cache_path(source, filename)
    if path is not None:
        try:
            with open(path, "rb") as f:
                code = marshal.loads(f.read())
            if isinstance(code, _CODE) and code.co_filename == filename:
                return code
        except (OSError, ValueError, EOFError, TypeError):
            pass
    code = compile(source, filename, "exec")
    if path is not None and not sys.dont_write_bytecode:
        _keep(path, marshal.dumps(code))
    return code


def _keep(path, data):
    """Write ``data`` to ``path`` as the package writes any output
    (:class:`brdf.io.files.atomic_output`: atomically, readable as a plain ``open()`` makes a
    file, a killed writer's temporary removed by the next) and remove the file's other
    versions (other digests); a folder that cannot be written is left as it is."""
    from .io.files import atomic_output
    folder, name = os.path.split(path)
    stem = name[:name.rindex("-") + 1]
    try:
        os.makedirs(folder, exist_ok=True)
        with atomic_output(path, force=True) as tmp:
            tmp.write_bytes(data)
        for other in os.listdir(folder):
            if other.startswith(stem) and other != name and other.endswith(".bin"):
                os.unlink(os.path.join(folder, other))
    except OSError:  # brdf.errors.OutputError included
        pass
