"""Kernel dispatch numbers of the built-in lobe families (see ``_kernels.py``)."""

LAMBERT = 0
MIRROR = 1
PHONG = 2
MODIFIED_PHONG = 3
BLINN_PHONG = 4
WARD = 5
GGX = 6
BECKMANN = 7
LAFORTUNE = 8
ASHIKHMIN_SHIRLEY = 9
