"""Plain-text tables and JSON-ready values: how reports print, whoever makes them (checks,
fits, comparisons, posteriors, batches, the command line)."""

import math
import re

import numpy as np

__all__ = ["format_table", "json_ready", "significant", "round_numbers", "DECIMAL"]

#: A decimal number written with a point or an exponent (``0.0794696``, ``-1.5e-05``), not
#: inside a word or after a point (``r2``, ``1.2.3``, a SHA-256 ``...9e5a...``); integers
#: (counts, indices) do not match.
DECIMAL = re.compile(r"(?<![\w.])-?(?:\d+\.\d+(?:[eE][-+]?\d+)?|\d+[eE][-+]?\d+)(?!\w)")


def format_table(header, rows, align=None):
    """Plain-text table, columns padded to their widest cell.

    Parameters
    ----------
    header : sequence of str
    rows : sequence of sequences of str
    align : str, optional
        One letter per column, ``"l"`` or ``"r"`` (default: all left).
    """
    align = align or "l" * len(header)
    cells = [list(map(str, header))] + [list(map(str, r)) for r in rows]
    widths = [max(len(r[j]) for r in cells) for j in range(len(header))]
    pad = [str.rjust if a == "r" else str.ljust for a in align]
    return "\n".join("  ".join(pad[j](r[j], widths[j]) for j in range(len(r))).rstrip()
                     for r in cells)


def json_ready(x):
    """Plain JSON types from nested dicts, sequences and numpy values; non-finite numbers (NaN,
    an unbounded parameter's inf) become ``None`` so that strict JSON parsers accept the output."""
    if isinstance(x, dict):
        return {k: json_ready(v) for k, v in x.items()}
    if isinstance(x, (list, tuple, np.ndarray)):
        return [json_ready(v) for v in x]
    if isinstance(x, (bool, np.bool_)):
        return bool(x)
    if isinstance(x, (int, np.integer)):
        return int(x)
    if isinstance(x, (float, np.floating)):
        return float(x) if math.isfinite(x) else None
    return x


def significant(x, digits=4):
    """``x`` written with at most ``digits`` significant digits (``f"{x:.4g}"``): what reports
    for people show of a fitted parameter or a metric, whose later digits are noise."""
    return f"{float(x):.{int(digits)}g}"


def round_numbers(text, digits=4):
    """``text`` with every decimal number in it (:data:`DECIMAL`) rounded to ``digits``
    significant digits: a fit's spec carries all 17 (``str(model)`` round-trips), which a
    title or a table has no room for."""
    return DECIMAL.sub(lambda m: significant(m.group(), digits), str(text))
