"""Shared test configuration: the test helpers (``chi2``, ``model_cases``) import from tests/,
and hypothesis runs derandomised so a failure reproduces on every run and machine."""

import os
import sys

from hypothesis import settings

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

settings.register_profile("brdf", derandomize=True, deadline=None, print_blob=True)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "brdf"))
