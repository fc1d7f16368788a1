"""The ``brdf-fit`` command line, a thin layer over the :mod:`brdf` library.

Installed as ``brdf_cli`` (see pyproject.toml). Only the standard library is imported at start-up
so that ``brdf-fit --help`` is instant; each subcommand imports :mod:`brdf` when it runs.
"""

# first, so that its exit handler runs after every other one (see the module)
from . import process_exit  # noqa: E402,F401
