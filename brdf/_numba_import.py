"""numba, imported without its check of an installed scipy's version.

At its import numba imports scipy, if installed, only to refuse a release older than 1.0: the
scipy package alone, 15 ms of a command's start on a 2-core AMD host, in commands (a render, a
check) that never use scipy otherwise. The package requires a far newer scipy
(``pyproject.toml``), so the check is held off while numba loads: ``scipy`` reads as absent
for that import, and numba's later uses of scipy (its linear algebra, extensions set up at the
first compile) import it as usual. Nothing changes where numba or scipy is imported already.
"""

import sys

if "numba" not in sys.modules and "scipy" not in sys.modules:
    sys.modules["scipy"] = None  # an import of it raises ImportError meanwhile
    try:
        import numba  # noqa: F401
    finally:
        if sys.modules.get("scipy", 0) is None:
            del sys.modules["scipy"]
