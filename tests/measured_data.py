"""Access to the real data sets in ../shared/measured for the reader tests.

Tests call :func:`measured` to get a file's path (the test is skipped, with the reason, when the
folder is not on this machine) and :func:`published_sha256` for the SHA-256 the folder's
``SHA256SUMS.txt`` lists, an independent record of the bytes a reader's ``Source`` must name.
"""

import functools
import os
from pathlib import Path

import pytest

def _folder():
    """BRDF_MEASURED if set, else ../shared/measured next to the checkout, else the one of
    this workplace (a fresh clone elsewhere still finds it)."""
    if os.environ.get("BRDF_MEASURED"):
        return Path(os.environ["BRDF_MEASURED"])
    beside = Path(__file__).resolve().parents[2] / "shared" / "measured"
    return beside if beside.is_dir() else Path("/work/shared/measured")


MEASURED = _folder()


def measured(relative):
    """Path of ``MEASURED/relative``; skips the test when the file is absent."""
    path = MEASURED / relative
    if not path.is_file():
        pytest.skip(f"real data not available: {path} is missing")
    return path


@functools.cache
def _sums():
    listing = measured("SHA256SUMS.txt").read_text(encoding="utf-8")
    # sha256sum lines: "<hex>  <path>" (a '*' before the path marks binary mode)
    return {name.lstrip("*"): digest
            for digest, name in (line.split(None, 1) for line in listing.splitlines() if line)}


def published_sha256(relative):
    """The SHA-256 that SHA256SUMS.txt lists for ``relative`` (a path inside MEASURED)."""
    return _sums()[relative]
