"""brdf._kernel_cache: cached kernels load without numba's full set-up, and still run right;
a kernel compiled after them in the same process gets that set-up from numba's compiler."""

import json
import subprocess
import sys

import numpy as np

import brdf

# A fresh process: evaluate (a parallel kernel, whose threading layer starts from the cache's
# hooks), check (kernels that allocate, through numba's runtime) and say whether numba loaded
# its registry of implementations (numba.np.polynomial is one of its modules) or scipy.linalg
# (numba's probe for BLAS), then compile a function that needs both (np.dot, through scipy's
# BLAS).
_FRESH = """
import json, sys
import numpy as np
import brdf
from brdf.geometry import directions_from_degrees
m = brdf.parse("lambert(albedo=0.5) + ggx(alpha=0.3)")
t = np.linspace(0.0, 80.0, 9)
f = m.eval(directions_from_degrees(t, 0.0 * t), directions_from_degrees(t, 180.0 + 0.0 * t))
report = brdf.check(m)
loaded_registry = [m for m in ("numba.np.polynomial.polynomial_functions", "scipy.linalg")
                   if m in sys.modules]
import numba
dot = numba.njit(lambda a: np.dot(a, a))(np.arange(3.0))
print(json.dumps({"f": f.tolist(), "passed": bool(report.passed),
                  "registry": loaded_registry, "dot": dot}))
"""


def test_a_warm_process_loads_kernels_without_numbas_registry():
    m = brdf.parse("lambert(albedo=0.5) + ggx(alpha=0.3)")
    from brdf.geometry import directions_from_degrees
    t = np.linspace(0.0, 80.0, 9)
    expected = m.eval(directions_from_degrees(t, 0.0 * t),
                      directions_from_degrees(t, 180.0 + 0.0 * t))
    passed = brdf.check(m).passed  # also puts the kernels in the cache for the process below
    done = subprocess.run([sys.executable, "-c", _FRESH], capture_output=True, text=True,
                          timeout=600)
    assert done.returncode == 0, done.stderr
    out = json.loads(done.stdout)
    assert out["registry"] == []
    assert np.array_equal(np.array(out["f"]), expected)
    assert out["passed"] == passed
    assert out["dot"] == 5.0
