"""``render(..., stats=True)``: the path tracer's stages timed in its own kernels
(:mod:`brdf.render.stats`)."""

import numpy as np
import pytest

import brdf._jit
from brdf import render
from brdf.render import _integrator
from brdf.errors import InputError
from brdf.render.stats import STAGE_WORK

from pixels import hits_on_ground

W, H = 24, 16
needs_ticks = pytest.mark.skipif(not brdf._jit.HAS_TICKS,
                                 reason="the stages are timed with x86-64's time-stamp counter")


@needs_ticks
def test_stats_count_what_the_paths_did_and_leave_the_image_alone(monkeypatch):
    """A plane under a point light, max depth 2, pixel centres: each camera ray that meets the
    plane shades one vertex and casts one shadow ray (the light is above every point of it),
    and the rays that miss do neither, so the counts are exact. The image is the same to the
    bit with the timing and without. (The timers are the packet's: a scene the block tracer
    covers renders through the packet when timed, the same image to rounding.)"""
    scene = render.builtin("plane-point", "lambert(albedo=0.7)")
    scene.camera = render.Camera(origin=(0, 3.0, 3.0), target=(0, 0, 0), fov=90.0)  # and sky
    kw = dict(spp=2, size=(W, H), seed=3, jitter=False, max_depth=2, threads=2, progress=False)
    blocks = render.render(scene, **kw)
    monkeypatch.setattr(_integrator, "use_blocks", False)
    plain = render.render(scene, **kw)
    timed = render.render(scene, **kw, stats=True)
    assert plain.stats is None
    assert timed.image.tobytes() == plain.image.tobytes()
    assert np.abs(blocks.image - plain.image).max() <= 1e-12 * np.abs(plain.image).max()
    d, p = hits_on_ground(scene.camera, W, H)
    hits = int(((d[..., 1] < 0) & (np.abs(p[..., 0]) < 2) & (np.abs(p[..., 2]) < 2)).sum())
    assert 0 < hits < W * H  # both kinds of ray
    s = timed.stats
    assert (s.samples, s.shaded, s.shadow_rays) == (W * H * 2, 2 * hits, 2 * hits)
    assert s.steps >= 2  # a camera ray's step, then the bounce that escapes


@needs_ticks
def test_stages_account_for_the_kernels_time():
    """Every stage is timed and the stages fill the kernel's time: what no stage counts
    (tiles set up and handed out) is a small part of it, and the threads' summed time in the
    kernel is at most the sampling's wall time per thread."""
    scene = render.builtin("sphere", "lambert(albedo=0.5) + ggx(alpha=0.3)")
    r = render.render(scene, spp=8, size=(64, 64), seed=1, threads=2, progress=False,
                      stats=True)
    s = r.stats
    assert list(s.seconds) == list(STAGE_WORK)
    assert all(v >= 0 for v in s.seconds.values())
    for stage in ("paths", "rays", "numbers", "vertices", "shading"):
        assert s.seconds[stage] > 0, stage
    assert s.seconds["other"] < 0.2 * s.thread_seconds
    assert 0 < s.shadow_rays < s.shaded  # the light is below some vertices' horizons
    assert sum(s.seconds.values()) == pytest.approx(s.thread_seconds, rel=1e-9)
    assert 0.3 * r.seconds < s.thread_seconds <= 2 * r.seconds * 1.05
    table = s.table()
    assert all(name in table for name in STAGE_WORK)
    assert f"{64 * 64 * 8} samples" in table


def test_stats_need_a_time_stamp_counter(monkeypatch):
    """Where the CPU has no time-stamp counter the kernels may read, one line says so."""
    monkeypatch.setattr(brdf._jit, "HAS_TICKS", False)
    scene = render.builtin("plane-point", "lambert(albedo=0.7)")
    with pytest.raises(InputError, match="time-stamp counter"):
        render.render(scene, spp=1, size=(4, 4), progress=False, stats=True)
