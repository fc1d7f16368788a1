"""A small render, to the last bit: the guard of changes to the renderer's kernels that must
not change what they compute (see :mod:`brdf.render._integrator`).

The image's bytes depend on the compiler as well as on the code (the kernels are compiled with
fast-math contraction and reassociation), so their digests are stored per numba version,
llvmlite version and processor model in ``render_digests.json``. Every run also checks what
holds on any compiler: one thread and two give the same bytes, and the image matches the
committed reference image ``data/digest_scene.npy`` to within the rounding a different compiler
may move (most pixels to 1e-9, the mean to 1e-6; a change of the estimator moves them all).

A change that is meant to move the image's bits: say why in its commit and run
``python tests/render/test_render_digest.py --record`` (``--reference`` too where the image
changes beyond rounding). On a compiler without a stored digest the test warns, and
``--record`` adds one.
"""

import argparse
import hashlib
import json
import platform
import sys
import warnings
from pathlib import Path

import llvmlite
import llvmlite.binding
import numba
import numpy as np

HERE = Path(__file__).parent
DIGESTS = HERE / "render_digests.json"
REFERENCE = HERE / "data" / "digest_scene.npy"
# the processor model, not only the architecture: numba compiles for the host's own
# instruction set, so an AVX-512 machine and an AVX2 one round the same source differently
KEY = (f"numba {numba.__version__}, llvmlite {llvmlite.__version__}, {platform.machine()} "
       f"{llvmlite.binding.get_host_cpu_name()}")


def _uv_sphere(centre, radius, rows=16, cols=32):
    """A triangulated sphere with vertex normals (the poles' degenerate triangles are dropped
    when the scene compiles)."""
    theta = np.linspace(0.0, np.pi, rows + 1)
    phi = np.linspace(0.0, 2.0 * np.pi, cols, endpoint=False)
    T, P = np.meshgrid(theta, phi, indexing="ij")
    n = np.stack([np.sin(T) * np.cos(P), np.cos(T), np.sin(T) * np.sin(P)], -1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(rows), np.arange(cols), indexing="ij")
    a, b = i * cols + j, i * cols + (j + 1) % cols
    c, d = a + cols, b + cols
    faces = np.concatenate([np.stack([a, c, b], -1).reshape(-1, 3),
                            np.stack([b, c, d], -1).reshape(-1, 3)])
    return np.asarray(centre) + radius * n, faces, n


def scene():
    """The Cornell box with a glossy triangle mesh, a mirror sphere and an environment: quads,
    triangles and spheres, packet and single-ray traversal, area and environment light, and
    diffuse, glossy and specular lobes."""
    from brdf import render
    s = render.builtin("cornell")
    v, f, n = _uv_sphere((0.3, -0.3, 0.2), 0.35)
    s.shapes.append(render.Mesh(v, f, "beckmann(alpha=0.3) + lambert(albedo=0.4)", normals=n))
    s.shapes.append(render.Sphere((-0.4, 0.3, 0.3), 0.2, "mirror"))
    s.environment = render.Environment(0.2)
    return s


def _render(threads):
    from brdf import render
    return render.render(scene(), spp=4, size=(24, 20), seed=17, threads=threads,
                         progress=False).image


def _digest(image):
    return hashlib.sha256(np.ascontiguousarray(image).tobytes()).hexdigest()


def _stored():
    return json.loads(DIGESTS.read_text()) if DIGESTS.exists() else {}


def test_small_render_keeps_its_bits():
    one, two = _render(1), _render(2)
    assert one.tobytes() == two.tobytes(), "the image depends on the number of threads"
    ref = np.load(REFERENCE)
    assert one.shape == ref.shape
    close = np.isclose(one, ref, rtol=1e-9, atol=1e-12).all(axis=-1)
    assert close.mean() >= 0.95, f"{close.mean():.1%} of the pixels match the reference"
    assert abs(one.mean() - ref.mean()) <= 1e-6 * ref.mean(), (one.mean(), ref.mean())
    stored = _stored()
    if KEY not in stored:
        warnings.warn(f"no stored digest for {KEY}: checked against the reference image only "
                      f"(add one: python {Path(__file__).relative_to(HERE.parent.parent)} "
                      "--record)")
        return
    assert _digest(one) == stored[KEY], (
        f"the render's bytes changed on {KEY}; if the change is meant to move them, say why in "
        "the commit and record the new digest (--record)")


# Traces rays through the traversal kernel from Python, then renders: numba once bound the
# path tracer's calls to whichever copy of a shared function the process loaded first.
_TRACE_FIRST = """
import sys
import numpy as np
sys.path.insert(0, {here!r})
import test_render_digest as T
from brdf.render import _intersect as X
geo = T.scene().compile().geo
m = 64
ray = np.zeros((X.RAY_ROWS, m))
ray[X.ORIGIN:X.ORIGIN + 3] = np.array([[0.0], [0.0], [3.0]])
d = np.random.default_rng(0).normal(size=(3, m))
d[2] = -abs(d[2])
ray[X.DIRECTION:X.DIRECTION + 3] = d / np.linalg.norm(d, axis=0)
hit, tmax = np.full(m, -1), np.full(m, np.inf)
X.trace_packet(geo, np.zeros(2 * X.STACK, dtype=np.int64), np.zeros(X.LANES), ray,
               np.zeros((3, m)), np.zeros(m, dtype=np.int64), tmax, hit, False, m)
assert (hit >= 0).any()
print(T._digest(T._render(1)))
"""


def test_render_bits_do_not_depend_on_what_ran_before():
    import subprocess
    out = subprocess.run([sys.executable, "-c", _TRACE_FIRST.format(here=str(HERE))],
                         capture_output=True, text=True, check=True).stdout.split()
    assert out[-1] == _digest(_render(1)), "tracing rays from Python first moved the render"


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--record", action="store_true", help=f"store the digest for {KEY}")
    ap.add_argument("--reference", action="store_true", help="rewrite the reference image")
    args = ap.parse_args()
    one, two = _render(1), _render(2)
    if one.tobytes() != two.tobytes():
        sys.exit("the image depends on the number of threads: nothing recorded")
    print(KEY, _digest(one))
    if args.record:
        stored = _stored()
        stored[KEY] = _digest(one)
        DIGESTS.write_text(json.dumps(stored, indent=1, sort_keys=True) + "\n")
    if args.reference:
        np.save(REFERENCE, one)


if __name__ == "__main__":
    main()
