"""numba, imported without its check of an installed scipy's version.

At its import numba imports scipy, if installed, only to refuse a release older than 1.0. That
was 15 ms of every command's start (the package base, nothing numba uses later), while most
commands (a render, a check) never import scipy otherwise. The package requires a far newer
scipy (``pyproject.toml``), so the check is held off while numba loads: ``scipy`` reads as
absent for that import, and numba's later uses of scipy (its linear algebra) import it as
usual. Nothing changes where numba or scipy is imported already.
"""

import sys

if "numba" not in sys.modules and "scipy" not in sys.modules:
    sys.modules["scipy"] = None  # an import of it raises ImportError meanwhile
    try:
        import numba  # noqa: F401
    finally:
        if sys.modules.get("scipy", 0) is None:
            del sys.modules["scipy"]
