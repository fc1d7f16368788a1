"""The table of built-in lobe families: the one place a compiled family is added.

Each row is a family's kind and its dispatch number (``kinds`` arrays hold it; a new family
takes the next number), the module of ``brdf.models`` that holds its class and its scalar
kernels (the hooks listed in ``_kernels``), and, for a module that serves several families, the name of the module constant
passed to its hooks as the variant. ``_kernels`` generates every dispatcher from the table (a
missing optional hook falls back the same way for every family), ``brdf.models`` imports each
module (which registers its classes), and the cache stamp of ``brdf._jit`` covers this file.
The order is the dispatchers' order of tests: the commonest families first.

A new family is a module like ``lambert.py`` (class with ``kind = _kinds.NAME``, kernels) plus
one row here.
"""

FAMILIES = (
    # kind                 code  module               variant
    ("LAMBERT",             0,    "lambert",           None),
    ("MIRROR",              1,    "mirror",            None),
    ("GGX",                 6,    "microfacet",        "GGX"),
    ("BECKMANN",            7,    "microfacet",        "BECKMANN"),
    ("PHONG",               2,    "phong",             "ORIGINAL"),
    ("MODIFIED_PHONG",      3,    "phong",             "MODIFIED"),
    ("BLINN_PHONG",         4,    "blinn_phong",       None),
    ("WARD",                5,    "ward",              None),
    ("LAFORTUNE",           8,    "lafortune",         None),
    ("ASHIKHMIN_SHIRLEY",   9,    "ashikhmin_shirley", None),
    ("OREN_NAYAR",          10,   "oren_nayar",        None),
)

#: Kind name -> dispatch number (also module constants: ``_kinds.GGX``).
CODES = {name: code for name, code, _, _ in FAMILIES}
#: The family modules, each once, in table order.
MODULES = tuple(dict.fromkeys(module for _, _, module, _ in FAMILIES))

if sorted(CODES.values()) != list(range(len(FAMILIES))):
    raise ImportError("brdf.models._kinds: the codes must number the families 0, 1, 2, ...")

globals().update(CODES)
