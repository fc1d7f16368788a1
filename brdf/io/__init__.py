"""Reading and writing measured BRDF tables.

:func:`read` picks the format from the file's extension, or from its content when the extension
is unknown or shared by several formats; :func:`write` picks it from the output's extension and
writes atomically (a temporary file in the same folder, then a rename), never replacing an
existing file unless ``force=True``. Each format is one module of this package defining
``FORMAT``, ``EXTENSIONS``, ``sniff(head)``, ``read(path)`` and, when it can store tables,
``write(table, path, **options)`` (keyword-only options, which :func:`write` passes on);
``WRITES_MODELS = True`` marks writers that also take a model and evaluate it where their
format needs values (MERL, RGL ``.bsdf``); ``EXTENSION_FALLBACK = True`` marks the reader of a
shared extension that reads (and reports the errors of) files of that extension whose content
no format recognises.

>>> import brdf
>>> sorted(brdf.io.formats())[:3]
['alta', 'cornell', 'curet']
"""

import hashlib
import importlib
import os
from dataclasses import dataclass
from pathlib import Path

from ..errors import FormatError, InputError
from .files import atomic_output, read_bytes, read_head

__all__ = ["read", "write", "formats", "format_of", "Source", "source_of", "read_bytes",
           "atomic_output", "as_table"]

#: Format modules, in the order content sniffing tries them.
_MODULES = ("merl", "nist_ptfe", "cornell", "curet", "alta", "gonio_csv", "npz", "rgl_bsdf")

#: Bytes of the file head passed to each format's ``sniff``.
SNIFF_BYTES = 4096


@dataclass(frozen=True)
class Source:
    """Provenance of a table read from a file."""

    path: str
    sha256: str
    format: str
    size: int

    @property
    def name(self):
        """The file name without its folder."""
        return Path(self.path).name

    def to_dict(self):
        return {"path": self.path, "sha256": self.sha256, "format": self.format,
                "size": self.size}


def source_of(path, data, format):
    """:class:`Source` of ``data`` (the bytes read from ``path``) in ``format``."""
    return Source(str(path), hashlib.sha256(data).hexdigest(), format, len(data))


def formats():
    """``{format name: module}`` of every registered format."""
    modules = (importlib.import_module(f"{__name__}.{m}") for m in _MODULES)
    return {m.FORMAT: m for m in modules}


def _named(format):
    known = formats()
    if not isinstance(format, str) or format not in known:
        raise InputError(f"unknown format {format!r}; formats: {', '.join(sorted(known))}")
    return known[format]


def format_of(path, head=None):
    """The format module for ``path``: by extension, then by sniffing the first bytes.

    ``head`` (the file's first bytes) is read from ``path`` when not given and needed.
    """
    known = formats()
    suffix = "".join(Path(path).suffixes[-1:]).lower()
    by_extension = [m for m in known.values() if suffix in m.EXTENSIONS]
    if len(by_extension) == 1:
        return by_extension[0]
    if head is None:
        head = read_head(path, SNIFF_BYTES)
    for module in by_extension or known.values():
        if module.sniff(head):
            return module
    # the extension names formats but the content matches none: the extension's general
    # reader says what is wrong (a misspelt column, say), not "unrecognised format"
    fallback = [m for m in by_extension if getattr(m, "EXTENSION_FALLBACK", False)]
    if fallback:
        return fallback[0]
    extensions = sorted({e for m in known.values() for e in m.EXTENSIONS})
    raise FormatError(path, "", f"unrecognised format (extension {suffix or 'none'!r}, content "
                                f"matches none); known extensions: {', '.join(extensions)}")


def read(path, format=None, **options):
    """Read a measured BRDF table.

    Parameters
    ----------
    path : str or path-like
    format : str, optional
        A name from :func:`formats`; by default chosen by extension, then content.
    **options
        Passed to the format's reader (e.g. ``sample=`` for CUReT).

    Returns
    -------
    brdf.table.Table
    """
    path = _path_argument(path, "read")
    module = _named(format) if format is not None else format_of(path)
    try:
        return module.read(path, **options)
    except FormatError:
        raise
    except InputError as e:
        # a reader's samples refused by Table (all NaN, below the horizon, ...): name the file
        if path in str(e):
            raise
        raise InputError(f"{path}: {e}") from e


def as_table(data):
    """``data`` itself, or the table read from it when it is a path (``str`` or path-like)."""
    if isinstance(data, (str, os.PathLike)):
        return read(data)
    return data


def _path_argument(path, what):
    """``path`` as a ``str`` if it is a non-empty path (``str`` or ``os.PathLike``)."""
    text = os.fspath(path) if isinstance(path, os.PathLike) else path
    if not isinstance(text, str) or not text or "\0" in text:
        shown = repr(text) if isinstance(text, (str, bytes)) else type(path).__name__
        raise InputError(f"{what}: path must be a non-empty file path (str or os.PathLike "
                         f"without NUL characters), got {shown}")
    return text


def write(table, path, format=None, force=False, **options):
    """Write ``table`` to ``path`` in the format its extension names (or ``format``).

    The file appears complete or not at all; an existing file is kept unless ``force``.
    ``options`` go to the format's writer (e.g. ``param=`` for ALTA files, ``samples=64``
    for ``.bsdf``).
    """
    from ..models.base import Model
    from ..table import Table
    path = _path_argument(path, "write")
    if not isinstance(force, bool):
        raise InputError(f"write: force must be True or False, got {force!r}")
    module = _named(format) if format is not None else format_of_output(path)
    if not hasattr(module, "write"):
        writable = sorted(name for name, m in formats().items() if hasattr(m, "write"))
        raise InputError(f"format {module.FORMAT} is read-only; write one of: "
                         f"{', '.join(writable)}")
    # a fixed-grid format (MERL) resamples a model at its nodes; the others need samples
    if not (isinstance(table, Table) or (isinstance(table, Model)
                                         and getattr(module, "WRITES_MODELS", False))):
        hint = ("; write saves measured tables: measure the model first (brdf.measure) or save "
                "its spec (str(model)) or model.to_dict()" if hasattr(table, "to_dict") else "")
        raise InputError(f"write: table must be a brdf.Table, got {type(table).__name__}{hint}")
    _check_options(module, module.write, options, "write")
    with atomic_output(path, force) as tmp:
        module.write(table, tmp, **options)
    return Path(path)


def _check_options(module, function, options, what):
    """InputError naming the first of ``options`` that ``function`` does not take."""
    import inspect
    taken = [name for name, p in inspect.signature(function).parameters.items()
             if p.kind is p.KEYWORD_ONLY or (p.kind is p.POSITIONAL_OR_KEYWORD
                                             and p.default is not p.empty)]
    unknown = [name for name in options if name not in taken]
    if unknown:
        offered = f"options: {', '.join(taken)}" if taken else "no options"
        raise InputError(f"{what}: format {module.FORMAT} takes no option {unknown[0]!r} "
                         f"({offered})")


def format_of_output(path):
    """The format module an output file's extension names (writable formats first)."""
    suffix = Path(path).suffix.lower()
    candidates = [m for m in formats().values() if suffix in m.EXTENSIONS]
    candidates.sort(key=lambda m: not hasattr(m, "write"))
    if not candidates:
        extensions = sorted({e for m in formats().values() if hasattr(m, "write")
                             for e in m.EXTENSIONS})
        raise InputError(f"{path}: cannot tell the format from the extension "
                         f"{suffix or '(none)'!r}; use one of {', '.join(extensions)}")
    return candidates[0]
