"""Validation renders: a numba path tracer for any model of the library or measured table.

>>> from brdf import render
>>> scene = render.builtin("sphere", "lambert(albedo=0.8) + ggx(alpha=0.2)")
>>> result = render.render(scene, spp=16, size=(128, 128), seed=1)
>>> result.save("sphere.exr")

The integrator is path tracing with next-event estimation and multiple importance sampling
(power heuristic), Russian roulette and a maximum depth counted as Mitsuba 3's ``path``
integrator counts it (1: emitters seen directly; 2: direct lighting; ...). The estimate of
each pixel averages ``spp`` paths whose random streams depend only on the seed, the pixel and
the sample index, so the same seed gives the same bytes whatever the number of threads.
"""

import math
import platform
import time
from dataclasses import dataclass
from typing import Optional

import numpy as np

from .. import arguments
from .._threads import thread_count, using_threads
from ..arguments import integer, shown
from ..errors import InputError
from ..progress import task
from ..memory import require
from .scene import (Camera, DirectionalLight, Environment, GoniometricLight, Material, Mesh,
                    PointLight, Quad, Scene, Sphere, SpotLight, box, rectangle)
from .scenes import BUILTIN, builtin, load
from .validate import validate
from .derivatives import Derivatives
from .stats import CLOCK_ROWS, RenderStats, from_clock

__all__ = ["render", "RenderResult", "Scene", "Camera", "Sphere", "Quad", "Mesh", "box",
           "rectangle", "Material", "PointLight", "SpotLight", "DirectionalLight",
           "GoniometricLight", "Environment", "builtin", "load", "validate", "BUILTIN",
           "STRATEGIES", "Derivatives", "RenderStats", "traced_in_blocks"]

STRATEGIES = {"mis": 0, "bsdf": 1, "light": 2}
#: Pixels along a side of the square tiles that the threads share out. A tile's packet runs
#: dry at its end (its last paths finish with lanes idle), so large tiles waste less: 32 gave
#: 5 % over 16 on the Cornell box (64 tiles in a 256 x 256 image, enough to share out).
TILE = 32
#: Paths (pixels times samples) a pass traces before the progress bar moves.
PASS_PATHS = 2 ** 22
#: Peak bytes per pixel of a render with layers: the kernel's sums (RGB, RGB squared, albedo
#: and normal: 12 float64), the result's mean, variance, albedo and normal and the variance's
#: temporary (15 float64), then the EXR writer's float32 copies of 12 channels. An upper
#: bound: the peak resident growth of a 2048 x 2048 render and its EXR, measured 2026-12-04,
#: was 191 bytes a pixel with layers and 48 without (some temporaries are freed before others
#: are made).
PIXEL_BYTES = 8 * (12 + 15) + 4 * 12
#: The same without layers: the sum and the mean (6 float64) and an 8-bit RGB copy.
PIXEL_BYTES_RGB = 8 * 6 + 3


@dataclass
class RenderResult:
    """A rendered image and its per-pixel statistics.

    Attributes
    ----------
    image : ndarray (h, w, 3)
        Mean radiance per pixel (linear RGB).
    variance : ndarray (h, w, 3) or None
        Variance of that mean (sample variance over spp); its square root is the pixel's
        standard error. None when rendered without layers.
    albedo, normal : ndarray (h, w, 3) or None
        First-hit layers: a one-sample-per-path estimate of the directional albedo towards
        the camera, averaged; the mean shading normal (world space). None when rendered
        without layers.
    spp, seed : int
    seconds : float
        Wall time of the sampling itself.
    compile_seconds : float
        Time of the first call's compilation or cache load (0 when already loaded).
    derivatives : ndarray (h, w, 3, K) or None
        The derivative images asked for (:class:`Derivatives`), in the order of its
        parameters.
    stats : RenderStats or None
        Where the sampling's time went, stage by stage (``render(..., stats=True)``).
    tracer : str
        Which of the path tracer's kernels traced the paths: ``"blocks"`` (blocks of SIMD
        lanes; see :func:`traced_in_blocks`) or ``"packet"``.
    """

    image: np.ndarray
    variance: Optional[np.ndarray]
    albedo: Optional[np.ndarray]
    normal: Optional[np.ndarray]
    spp: int
    seed: int
    seconds: float
    compile_seconds: float
    derivatives: Optional[np.ndarray] = None
    stats: Optional[RenderStats] = None
    tracer: str = "packet"

    @property
    def samples_per_second(self):
        h, w, _ = self.image.shape
        return h * w * self.spp / self.seconds if self.seconds > 0 else math.inf

    def save(self, path, force=False, layers=True):
        """Write an OpenEXR file (float32 RGB, with ``albedo``, ``normal`` and ``variance``
        layers unless ``layers`` is False or the render has none), or an sRGB preview when
        ``path`` ends in .png."""
        from .image import tonemap, write_exr, write_png
        if str(path).lower().endswith(".png"):
            return write_png(path, tonemap(self.image), force)
        extra = ({"albedo": self.albedo, "normal": self.normal, "variance": self.variance}
                 if layers and self.variance is not None else None)
        return write_exr(path, self.image, extra, force)

    def preview(self, path, exposure=0.0, force=False):
        """Tone-mapped sRGB PNG (``exposure`` in stops)."""
        from .image import tonemap, write_png
        return write_png(path, tonemap(self.image, exposure), force)


#: Largest image side in pixels.
MAX_SIZE = 16384
#: Most samples per pixel: sample indices (the random streams' keys) stay well inside int64.
MAX_SPP = 1 << 31
#: Deepest path accepted, and the depth that max_depth=-1 (no limit) stands for.
MAX_DEPTH = 1 << 20


def _options(size, spp, max_depth, rr_depth, strategy, threads):
    """Checked ``(w, h, spp, depth, rr_depth, threads or None)``: each reaches the kernel as
    an int64, which would wrap or index past its arrays where Python's ints do not."""
    sides = (size, size) if np.ndim(size) == 0 else size
    if isinstance(sides, (str, bytes)) or not (np.ndim(sides) == 1 and len(sides) == 2):
        raise InputError(f"render: size must be W or (W, H) in pixels, got {shown(size)}")
    w, h = (integer(v, "render: size", 1, MAX_SIZE) for v in sides)
    spp = integer(spp, "render: spp", 1, MAX_SPP)
    depth = MAX_DEPTH if max_depth is None or (arguments.is_integer(max_depth) and max_depth == -1) else \
        integer(max_depth, "render: max_depth (or -1 for no limit)", 1, MAX_DEPTH)
    rr_depth = integer(rr_depth, "render: rr_depth", 1, MAX_DEPTH)
    if not isinstance(strategy, str) or strategy not in STRATEGIES:
        raise InputError(f"render: strategy must be one of {', '.join(STRATEGIES)}, got "
                         f"{shown(strategy)}")
    if threads is not None:
        threads = integer(threads, "render: threads", 1)
    return w, h, spp, depth, rr_depth, threads


def traced_in_blocks(scene, strategy="mis"):
    """Whether :func:`render` traces ``scene`` (a :class:`Scene`) in blocks of SIMD lanes, the
    faster of its two tracers (see ``docs/guide/rendering.md``), rather than in the packet of
    paths: True for scenes of up to 32 spheres and quads whose materials are a Lambertian lobe,
    a GGX lobe without a Fresnel term, or one of each, with at least one light, rendered with
    ``strategy="mis"`` and without derivative images or ``stats``. Both give the same image
    to rounding."""
    from ._integrator import STRATEGY, block_scene
    if not isinstance(scene, Scene):
        raise InputError(f"traced_in_blocks: scene must be a brdf.render.Scene, got "
                         f"{type(scene).__name__}")
    if not isinstance(strategy, str) or strategy not in STRATEGIES:
        raise InputError(f"traced_in_blocks: strategy must be one of {', '.join(STRATEGIES)}, "
                         f"got {shown(strategy)}")
    compiled = scene.compile()
    opts = np.zeros(STRATEGY + 1, np.int64)
    opts[STRATEGY] = STRATEGIES[strategy]
    return block_scene(compiled.geo, compiled.mats, compiled.lights, opts) is not None


def _seed(seed):
    seed = arguments.seed(seed, "render: seed")
    if isinstance(seed, np.random.Generator):
        return int(seed.integers(0, 2 ** 63))
    return int(seed) % (2 ** 64)


def render(scene, spp=64, size=(256, 256), seed=0, max_depth=8, rr_depth=5, strategy="mis",
           jitter=True, threads=None, progress=None, layers=True, derivatives=None,
           stats=False):
    """Render ``scene`` (a :class:`Scene`) with the path tracer.

    Parameters
    ----------
    scene : Scene
    spp : int
        Samples (paths) per pixel.
    size : int or (int, int)
        Width and height in pixels.
    seed : int or numpy.random.Generator
    max_depth : int
        Longest path in segments, as Mitsuba 3 counts it (-1: no limit, Russian roulette ends
        paths).
    rr_depth : int
        Depth from which Russian roulette may end a path (survival probability: the
        throughput's largest channel, at most 0.95).
    strategy : {"mis", "bsdf", "light"}
        Multiple importance sampling of emitters (default), BSDF sampling only (delta lights
        still by light sampling), or light sampling only (emitters hit after a delta bounce
        still count). All three converge to the same image.
    jitter : bool
        Random positions within each pixel (a box filter); False traces pixel centres.
    threads : int, optional
        Worker threads, at least 1 (default: numba's count, all cores unless
        ``numba.set_num_threads`` lowered it; more than ``NUMBA_NUM_THREADS`` means that
        many). The image does not depend on it.
    progress : bool, optional
        None (default): a bar on stderr when it is a terminal, otherwise one line when the
        render ends (``render: 64 spp in 3.1 s``); True: the bar; False: nothing (see
        :mod:`brdf.progress`).
    layers : bool
        Also estimate the per-pixel variance and the first-hit albedo and normal (default).
        False leaves them None and renders a few per cent faster; the image is the same to
        the bit.
    derivatives : Derivatives, optional
        Also estimate the derivatives of the image in a material's parameters (see
        :mod:`brdf.render.derivatives`); Russian roulette is then off.
    stats : bool
        Also time the path tracer's stages in its own kernels (:class:`RenderStats`, in
        ``result.stats``; x86-64 only, whose time-stamp counter they read). The stages are
        those of the packet of paths: a scene that the block tracer covers
        (:func:`traced_in_blocks`) is traced in the packet when timed, the same image to
        rounding; any other scene's image is the same to the bit. The timing costs well under
        1 % (a second compile of the kernel the first time).

    Returns
    -------
    RenderResult
    """
    from ._integrator import Gradient, Sums, render_pass
    from .._jit import HAS_TICKS, tick_count
    if not isinstance(scene, Scene):
        raise InputError(f"render: scene must be a brdf.render.Scene (see builtin() and "
                         f"load()), got {type(scene).__name__}")
    if derivatives is not None and not isinstance(derivatives, Derivatives):
        raise InputError(f"render: derivatives must be a brdf.render.Derivatives, got "
                         f"{type(derivatives).__name__}")
    if stats and not HAS_TICKS:
        raise InputError(f"render: stats=True reads an x86-64 CPU's time-stamp counter; this "
                         f"one is {platform.machine() or 'unknown'}")
    w, h, spp, depth, rr_depth, threads = _options(size, spp, max_depth, rr_depth, strategy,
                                                   threads)
    seed = _seed(seed)
    slots = derivatives.slots() if derivatives is not None else np.zeros((0, 1), np.int64)
    require(w * h * ((PIXEL_BYTES if layers else PIXEL_BYTES_RGB) + 8 * 3 * len(slots)),
            f"a {w} x {h} render{' with layers' if layers else ''}"
            f"{f' and {len(slots)} derivative images' if len(slots) else ''}")
    target = evaluate = -1
    if derivatives is None:
        compiled = scene.compile()
    else:
        compiled = scene.compile(extra=[derivatives.evaluate if derivatives.evaluate is not None
                                        else derivatives.material])
        target, evaluate = derivatives.check(compiled)
        rr_depth = MAX_DEPTH  # see brdf.render.derivatives
    dacc = np.zeros((h, w, 3, len(slots)))
    cam = scene.camera.pack(w, h)
    acc = np.zeros((h, w, 3))
    # without layers the kernel never touches these
    acc2, aov = (np.zeros((h, w, 3)), np.zeros((h, w, 6))) if layers else (
        np.zeros((1, 1, 3)), np.zeros((1, 1, 6)))
    args = (cam, compiled.geo, compiled.mats, compiled.lights)
    # every kernel call of the render (the material drivers' too) uses the same count
    with using_threads(thread_count() if threads is None else threads):
        opts = np.array([w, h, depth, rr_depth, STRATEGIES[strategy], int(bool(jitter)),
                         TILE, thread_count(), int(bool(layers)), target, evaluate],
                        dtype=np.int64)
        t0 = time.perf_counter()
        # the first call compiles (or loads the cache); time it apart, on a 1-pixel image
        probe = opts.copy()
        probe[0] = probe[1] = 1
        render_pass(*args, probe, seed, 0, 1, Sums(np.zeros((1, 1, 3)), np.zeros((1, 1, 3)),
                                                   np.zeros((1, 1, 6))),
                    None if derivatives is None else
                    Gradient(slots, np.zeros((1, 1, 3, len(slots)))),
                    np.zeros(CLOCK_ROWS, np.int64) if stats else None)
        compile_seconds = time.perf_counter() - t0
        clock = np.zeros(CLOCK_ROWS, np.int64) if stats else None
        if stats:  # the counter's rate, over the sampling (ticks first: the first call compiles)
            began = tick_count(), time.perf_counter_ns()
        with task(int(spp), "render", "spp", progress, units="spp") as meter:
            t0 = time.perf_counter()
            # fewer, longer passes spend less on each tile's last bounces, when its packet runs
            # part-empty (2^20 paths a pass: 4-7 % slower at 256 x 256 x 64). The passes never
            # depend on the bar: a path's packet mates change its last bits
            chunk = max(1, min(int(spp), PASS_PATHS // max(w * h, 1)))
            for s0 in range(0, int(spp), chunk):
                s1 = min(int(spp), s0 + chunk)
                in_blocks = render_pass(*args, opts, seed, s0, s1, Sums(acc, acc2, aov),
                                        None if derivatives is None else Gradient(slots, dacc),
                                        clock)
                meter.update(s1 - s0)
            seconds = time.perf_counter() - t0
        timed = None
        if stats:
            ended = tick_count(), time.perf_counter_ns()
            timed = from_clock(clock, w * h * int(spp),
                               1e-9 * (ended[1] - began[1]) / max(ended[0] - began[0], 1))
    n = float(spp)
    mean = acc / n
    grad = dacc / n if derivatives is not None else None
    tracer = "blocks" if in_blocks else "packet"
    if not layers:
        return RenderResult(mean, None, None, None, int(spp), seed, seconds, compile_seconds,
                            grad, timed, tracer)
    var = np.maximum(acc2 / n - mean * mean, 0.0) / max(n - 1.0, 1.0)
    return RenderResult(mean, var, aov[..., :3] / n, aov[..., 3:] / n, int(spp), seed, seconds,
                        compile_seconds, grad, timed, tracer)
