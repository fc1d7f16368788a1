"""Progress of long work, as a user sees it: the library's one place that reports it.

Long calls (fits, posteriors, batches, renders, the demo's stages) take ``progress``:

- ``None`` (the default): when standard error is a terminal, a tqdm bar while the work runs;
  otherwise (a file, a pipe, a CI log) one plain line on standard error when it ends, such as
  ``brdf: render: 64 spp in 3.1 s``. Nothing at all while :func:`reporting` is quiet.
- ``True``: the bar, wherever standard error goes (and even when quiet: it was asked for).
- ``False``: nothing.
- a callable: nothing on standard error; it is called as ``progress(done, total)`` each time
  units are done (a fit's evaluations) or forgone (the rest of a run's evaluation budget when
  it converges early), from the thread doing the work, so that ``done / total`` is the
  fraction of the work behind (the explorer's page shows it as a percentage). Work beyond
  the planned total (a fit's energy refinement) can take ``done`` past ``total``.

Lines start with the program's name: ``brdf``, or what :func:`reporting` sets (the command
line sets ``brdf-fit`` and its ``--quiet``). Everything here goes to standard error, never
to standard output, which carries results (``--json``).
"""

import contextlib
import sys
import time
from typing import NamedTuple

__all__ = ["Reporting", "reporting", "configure", "current", "note", "mode", "bar", "task",
           "Task", "stage"]


class Reporting(NamedTuple):
    """How this process reports: the name lines start with, and whether automatic progress
    (``progress=None``) and notes are silenced. A plain tuple, so that a parent process can
    hand it to its workers."""

    prog: str = "brdf"
    quiet: bool = False


_current = Reporting()


def current():
    """This process's :class:`Reporting`."""
    return _current


def configure(prog=None, quiet=None):
    """Set the name lines start with and/or the quiet switch for this process (None keeps
    the current value); returns the previous :class:`Reporting`. Worker processes call it
    with their parent's :func:`current`."""
    global _current
    previous = _current
    _current = Reporting(previous.prog if prog is None else str(prog),
                         previous.quiet if quiet is None else bool(quiet))
    return previous


@contextlib.contextmanager
def reporting(prog=None, quiet=None):
    """:func:`configure` for the duration of a ``with`` block, restored after it."""
    previous = configure(prog, quiet)
    try:
        yield _current
    finally:
        configure(*previous)


def note(message):
    """One line ``PROG: message`` on standard error, unless quiet."""
    if not _current.quiet:
        print(f"{_current.prog}: {message}", file=sys.stderr, flush=True)


def mode(progress=None):
    """How ``progress`` shows here: ``"bar"``, ``"lines"`` or None (nothing)."""
    if progress is None:
        if _current.quiet:
            return None
        return "bar" if sys.stderr.isatty() else "lines"
    if callable(progress):
        return None
    return "bar" if progress else None


def bar(total, desc, unit, enabled=None):
    """A tqdm bar of ``total`` ``unit`` labelled ``desc`` on standard error, or None when
    progress is off (``enabled`` False, or None and standard error not a terminal or
    reporting quiet)."""
    if mode(enabled) != "bar":
        return None
    from tqdm import tqdm
    return tqdm(total=total, desc=desc, unit=unit, file=sys.stderr, leave=False)


def _seconds(t):
    return f"{t:.1f} s"


class Task:
    """Progress of one long call, counted in units (evaluations, steps, samples per pixel,
    files); made by :func:`task`. Use it as a context manager: the bar closes, or the line
    is printed, when the block ends without an exception (an error is reported instead).

    Attributes
    ----------
    count : int
        Units done so far.
    forgone : int
        Units of the total that will not be needed (see :meth:`forgo`).
    """

    def __init__(self, total, desc, unit, progress=None, units=None):
        self.total, self.desc, self.unit = total, desc, unit
        self.units = units or f"{unit}s"
        self.count = self.forgone = 0
        self.callback = progress if callable(progress) else None
        self.mode = mode(progress)
        self.bar = bar(total, desc, unit, True) if self.mode == "bar" else None
        self.start = time.perf_counter()

    def update(self, n=1):
        self.count += n
        if self.bar is not None:
            self.bar.update(n)
        if self.callback is not None:
            self.callback(self.count + self.forgone, self.total)

    def forgo(self, n):
        """``n`` units of the total will not be needed (a run that converged before its
        budget): the bar and a callback's ``done`` move on, the count of units done does
        not (lines report what was done)."""
        if n <= 0:
            return
        self.forgone += n
        if self.bar is not None:
            self.bar.update(n)
        if self.callback is not None:
            self.callback(self.count + self.forgone, self.total)

    def set_postfix(self, **values):
        """Values shown after the bar (the loss of a fit); lines leave them out."""
        if self.bar is not None:
            self.bar.set_postfix(refresh=False, **values)

    def done(self, label):
        """One unit is done: the bar moves; in lines, one line naming it and how many of
        the total are done, ``batch: t1.csv fitted (2 of 3) after 4.1 s``."""
        self.update(1)
        if self.mode == "lines":
            note(f"{self.desc}: {label} ({self.count} of {self.total}) after "
                 f"{_seconds(time.perf_counter() - self.start)}")

    def close(self, finished=True):
        """Close the bar; in lines, print ``desc: N units in T s`` if ``finished``."""
        if self.bar is not None:
            self.bar.close()
            self.bar = None
        elif self.mode == "lines" and finished:
            units = self.unit if self.count == 1 else self.units
            note(f"{self.desc}: {self.count} {units} in "
                 f"{_seconds(time.perf_counter() - self.start)}")
        self.mode = None

    def __enter__(self):
        return self

    def __exit__(self, kind, value, tb):
        self.close(finished=kind is None)
        return False


def task(total, desc, unit, progress=None, units=None):
    """A :class:`Task` of ``total`` ``unit`` (plural ``units``, default ``unit + "s"``)
    labelled ``desc``, shown as ``progress`` says (see the module's docstring)."""
    return Task(total, desc, unit, progress, units)


@contextlib.contextmanager
def stage(name, progress=None, number=None, of=None):
    """Time one stage of a longer job (the demo's). On a terminal, a line ``name ...`` when
    it starts; on a terminal and in lines, ``name (3 of 8) in 41.2 s`` when it ends without
    an exception; nothing when ``progress`` is off. Yields a dict whose ``seconds`` is set
    when the stage ends."""
    shown = mode(progress)
    where = f" ({number} of {of})" if number is not None and of is not None else ""
    if shown == "bar":
        note(f"{name}{where} ...")
    timing = {"seconds": None}
    start = time.perf_counter()
    yield timing
    timing["seconds"] = time.perf_counter() - start
    if shown is not None:
        note(f"{name}{where} in {_seconds(timing['seconds'])}")
