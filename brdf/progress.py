"""Progress of long work: the one factory of the library's progress bars.

Fits, posteriors, batches and renders show a tqdm bar on standard error while they run, by
default only when standard error is a terminal (``progress=None``); ``progress=True`` forces
the bar, ``False`` silences it.
"""

import sys

__all__ = ["bar"]


def bar(total, desc, unit, enabled=None):
    """A tqdm bar of ``total`` ``unit`` labelled ``desc`` on standard error, or None when
    progress is off (``enabled`` False, or None and standard error not a terminal)."""
    if enabled is None:
        enabled = sys.stderr.isatty()
    if not enabled:
        return None
    from tqdm import tqdm
    return tqdm(total=total, desc=desc, unit=unit, file=sys.stderr, leave=False)
