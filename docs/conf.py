"""Sphinx configuration of the brdf documentation (built by tests/test_docs.py with warnings
as errors: ``python -m sphinx -W -b html docs docs/_build/html``)."""

import os
import sys

# the checkout's package, not an installed copy, is what the pages describe
sys.path.insert(0, os.path.abspath(".."))

import brdf  # noqa: E402

project = "brdf"
author = "brdf developers"
release = version = brdf.__version__
copyright = "2026, brdf developers"

extensions = [
    "myst_parser",          # the pages are Markdown, read like the README
    "sphinx.ext.autodoc",   # the API reference from the docstrings
    "numpydoc",             # ... written in numpy's docstring style
    "sphinxarg.ext",        # the command-line reference from brdf-fit's own parser
]
source_suffix = {".md": "markdown", ".rst": "restructuredtext"}
exclude_patterns = ["_build"]
myst_heading_anchors = 3
numpydoc_show_class_members = False
numpydoc_class_members_toctree = False
autodoc_member_order = "bysource"
autodoc_typehints = "none"
html_theme = "furo"
html_title = f"brdf {release}"
smartquotes = False  # option names such as --json stay as typed
