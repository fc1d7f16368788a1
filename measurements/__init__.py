"""The bundled measurements (installed as ``brdf_measurements``): CC0 RGL materials, the
public-domain MERL fit tables and synthetic tables with their true models; see README.md.

>>> from importlib import resources
>>> path = resources.files("brdf_measurements") / "rgl/paper_white_rgb.bsdf"
"""
