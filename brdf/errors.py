"""Errors with one-line messages.

Every error the library raises on bad input derives from :class:`BRDFError`; its ``str`` is one
line that names the place (file and line or byte offset, or the spec and column) and what was
expected, so the command line can print it as is and exit with status 2.
"""


class BRDFError(Exception):
    """Base class of every error caused by bad input (a spec, a file, a parameter)."""


class SpecError(BRDFError, ValueError):
    """A model spec that does not parse, names an unknown model or parameter, or is out of bounds."""


class ParameterError(SpecError):
    """A parameter value that is not allowed (out of bounds, NaN, wrong number of channels)."""


class InputError(BRDFError, ValueError):
    """Arrays or options passed to a library function that do not fit (shapes, NaN, ranges)."""


class FormatError(BRDFError, ValueError):
    """A data file that is truncated, malformed or holds values outside what its format allows."""

    def __init__(self, path, where, expected):
        self.path, self.where, self.expected = str(path), where, expected
        place = f"{self.path}:{where}" if where not in (None, "") else self.path
        super().__init__(f"{place}: {expected}")


class OutputError(BRDFError, OSError):
    """An output that cannot be written: it exists (and overwriting was not asked for) or its
    folder is missing."""


class MainGuardError(BRDFError, RuntimeError):
    """A script that starts the library's worker processes (``brdf.batch`` with local jobs)
    from its top level: each spawned worker imports the script again as it starts, so the
    call must sit under ``if __name__ == "__main__":``."""
