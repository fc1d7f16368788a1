"""Where a render's time goes: the path tracer's stages, timed in its own kernels
(:func:`brdf.render.render` with ``stats=True``).

The kernel advances a packet of paths a vertex at a time through named stages (pbrt-v4's
wavefront work items are the model): each stage's time-stamp ticks are summed over the threads
and turned into seconds at the counter's rate, measured over the same render.
"""

from dataclasses import dataclass

#: The stages of :func:`brdf.render._integrator.trace_tiles` that its clock times, in the
#: order of the clock's rows, and what each does.
STAGES = (
    ("paths", "paths bounced, ended into their pixels, started (camera rays)"),
    ("rays", "path rays traced through the scene"),
    ("numbers", "each vertex's uniform numbers drawn"),
    ("vertices", "emission seen, frames, light samples, escaped rays' environment"),
    ("shadow rays", "shadow rays traced"),
    ("shading", "BSDFs sampled and evaluated"),
)
#: The rows of a render's clock (an int64 array of CLOCK_ROWS that
#: :func:`brdf.render._integrator.render_pass` adds to): each stage's time-stamp ticks, in the
#: order of :data:`STAGES`; then the ticks of the threads' whole time in the kernel, the packet
#: steps, the vertices shaded and the shadow rays traced.
PATHS, RAYS, NUMBERS, VERTICES, SHADOW_RAYS, SHADING = range(len(STAGES))
CLOCK_TOTAL, CLOCK_STEPS, CLOCK_SHADED, CLOCK_SHADOWS = range(len(STAGES), len(STAGES) + 4)
CLOCK_ROWS = CLOCK_SHADOWS + 1
#: What each stage of a :class:`RenderStats` does, by its name: :data:`STAGES`, then the rest
#: of the threads' time in the kernel.
STAGE_WORK = dict(STAGES, other="tiles handed out and set up, work space, timing")


@dataclass(frozen=True)
class RenderStats:
    """CPU seconds of each stage of the path tracer (summed over its threads) and what the
    stages did, for one render.

    Attributes
    ----------
    seconds : dict
        Stage name (:data:`STAGE_WORK`, in order) to CPU seconds; ``other`` is the rest of the
        threads' time in the kernel.
    thread_seconds : float
        The time its threads spent in the kernel, summed (the stages' sum).
    samples : int
        Paths traced (pixels times samples per pixel).
    steps : int
        Packet steps: each moves every path of a packet on by one vertex.
    shaded : int
        Vertices shaded (a BSDF sample drawn).
    shadow_rays : int
        Shadow rays traced.
    """

    seconds: dict
    thread_seconds: float
    samples: int
    steps: int
    shaded: int
    shadow_rays: int

    def table(self):
        """A text table: each stage's CPU seconds, share and nanoseconds per sample."""
        n = max(self.samples, 1)
        total = self.thread_seconds if self.thread_seconds > 0 else 1.0
        lines = [f"{'stage':<12} {'CPU s':>8} {'share':>6} {'ns/sample':>10}  what"]
        for name, sec in self.seconds.items():
            lines.append(f"{name:<12} {sec:8.3f} {100 * sec / total:5.1f}% {1e9 * sec / n:10.1f}"
                         f"  {STAGE_WORK[name]}")
        lines.append(f"{'all':<12} {self.thread_seconds:8.3f} {100.0:5.1f}% "
                     f"{1e9 * self.thread_seconds / n:10.1f}  {self.samples} samples, "
                     f"{self.shaded} vertices shaded, {self.shadow_rays} shadow rays, "
                     f"{self.steps} packet steps")
        return "\n".join(lines)

    def to_dict(self):
        """The figures as JSON-ready numbers (``brdf-fit render --stats --json``'s ``stages``),
        the stages' CPU seconds under ``cpu_seconds``."""
        return {"cpu_seconds": dict(self.seconds), "thread_seconds": self.thread_seconds,
                "samples": self.samples, "steps": self.steps, "shaded": self.shaded,
                "shadow_rays": self.shadow_rays}

    def __str__(self):
        return self.table()


def from_clock(clock, samples, seconds_per_tick):
    """The :class:`RenderStats` of a render's ``clock`` (its rows: :data:`CLOCK_ROWS`) for
    ``samples`` paths, its ticks turned into seconds at ``seconds_per_tick``."""
    seconds = {name: float(clock[k]) * seconds_per_tick for k, (name, _) in enumerate(STAGES)}
    thread_seconds = float(clock[CLOCK_TOTAL]) * seconds_per_tick
    # each thread's total encloses its stages: the rest is what no stage counts
    seconds["other"] = max(thread_seconds - sum(seconds.values()), 0.0)
    return RenderStats(seconds, thread_seconds, int(samples), int(clock[CLOCK_STEPS]),
                       int(clock[CLOCK_SHADED]), int(clock[CLOCK_SHADOWS]))
