"""Latency of the explorer after a slider moves (target: under 100 ms for an analytic model).

Run: ``python benchmarks/bench_explore.py [--repeats 40] [--no-browser]``

Two figures for ``lambert + ggx``, each against the 100 ms budget:

- server side: ``Explorer.set_parameter`` (a new model from the slider's value, then every
  view's arrays recomputed and pushed to the document: lobe mesh, in-plane curve, albedo curve,
  lit-sphere and lit-object previews, theta_h / theta_d slice), with the time of each view, for the draft the
  page asks for while the slider moves and for the full update when it is let go;
- in the browser (headless chromium through selenium, when chromium and chromedriver are
  installed): from the slider's value set in the page (as a drag moves it) to every view's
  new data drawn (the lobe redrawn, and the plots and previews painted at the next animation
  frame), the round trip through the websocket included; and, as the floor under it, the
  same round trip when the server changes one two-point curve and computes nothing;
- server side, the draft update as the incident arrow is dragged on the 3-D lobe (theta_i
  and phi_i change at once), and the draft with the previews under the sky map, alone and
  with a measured table (RGL's paper white) shown beside the model.

Each sets ``ggx.alpha`` to a new value every time (alternating between two values would let
nothing be cached either, but a fresh value rules it out).
"""

import argparse
import math
import shutil
import statistics
import sys
import time
from pathlib import Path

SPEC = "lambert(albedo=[0.5,0.4,0.3]) + ggx(alpha=0.2, ks=[0.6,0.5,0.4])"
TABLE = str(Path(__file__).resolve().parent.parent / "measurements" / "rgl"
            / "paper_white_rgb.bsdf")
BUDGET = 0.100


def _alphas(n):
    return [0.05 + 0.3 * (k % 17) / 17 + 1e-4 * k for k in range(n)]


def server_side(repeats, draft, lighting="key", also=()):
    from brdf.viz.explorer import Explorer
    app = Explorer([SPEC, *also])
    app.set_lighting(lighting)
    # the path-traced sphere that follows a full update runs in a thread of its own: timed
    # here it would only compete with the next update for the two cores
    app.refine = False
    app.set_parameter(0, "ggx.alpha", 0.3, draft)  # warm-up: kernels, first pushes
    totals, views = [], {}
    for alpha in _alphas(repeats):
        start = time.perf_counter()
        app.set_parameter(0, "ggx.alpha", alpha, draft)
        totals.append(time.perf_counter() - start)
        for key, value in app.timings.items():
            views.setdefault(key, []).append(value)
    return totals, views


def arrow_drag(repeats):
    """Server side, seconds per draft update as the incident arrow is dragged on the 3-D lobe
    (both angles change: one update, not one per slider)."""
    from brdf.viz.explorer import Explorer
    app = Explorer([SPEC])
    app.refine = False
    app.lobe.drag = [31.0, 10.0, 0, 0]  # warm-up
    totals = []
    for k in range(repeats):
        start = time.perf_counter()
        app.lobe.drag = [20.0 + 40.0 * (k % 13) / 13, 7.0 * k % 360, 0, k + 1]
        totals.append(time.perf_counter() - start)
    return totals


# JavaScript: set the slider's value in the page as a drag does, then wait for the data of
# every view's source to change (the in-plane and albedo curves, the spheres, the objects, the
# slice; only the in-plane curve when timing the floor) and the lobe to be redrawn (unless
# timing the floor, which leaves the lobe as it is), and one animation frame more, in which
# Bokeh paints the plots; answer the milliseconds taken
_ROUND_TRIP = """
const [title, value, canvas, floor, done] = arguments;
const models = [...Bokeh.documents[0]._all_models.values()];
const slider = models.find(m => m.title === title && 'value' in m);
const names = floor ? ['polar-0'] : ['polar-0', 'albedo-0', 'spheres', 'objects', 'slice-image'];
const sources = names.map(name => models.find(m => m.name === name));
const before = sources.map(s => s.data), drawn = canvas.dataset.drawn;
const start = performance.now();
slider.value = value;
(function poll() {
  if (sources.every((s, k) => s.data !== before[k])
      && (floor || canvas.dataset.drawn !== drawn)) {
    requestAnimationFrame(() => done(performance.now() - start));
  } else {
    setTimeout(poll, 1);
  }
})();"""


def _floor_update(full_update):
    """An update that computes nothing and changes the in-plane curve to two random points
    (after the page's first, full one)."""
    import random

    def update(self, draft=False):
        if not getattr(self, "_first_done", False):
            self._first_done = True
            return full_update(self, draft)
        self.materials[0].polar_source.data = {"x": [0.0, 1.0], "y": [0.0, random.random()]}
    return update


def in_browser(repeats, floor=False):
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    driver_path = shutil.which("chromedriver")
    if not (chromium and driver_path):
        print("browser: skipped (no chromium or chromedriver; Debian: apt-get install -y "
              "chromium chromium-driver)")
        return None
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service
    from brdf.viz import explorer
    full_update = explorer.Explorer.update
    if floor:
        explorer.Explorer.update = _floor_update(full_update)
    options = webdriver.ChromeOptions()
    for flag in ("--headless=new", "--no-sandbox", "--disable-gpu", "--use-angle=swiftshader",
                 "--enable-unsafe-swiftshader", "--window-size=1400,1000"):
        options.add_argument(flag)
    options.binary_location = chromium
    driver = webdriver.Chrome(service=Service(driver_path), options=options)
    server = explorer.explore(SPEC, show=False)
    try:
        driver.set_script_timeout(30)
        driver.get(server.url)
        end = time.monotonic() + 60
        while not driver.execute_script(
                "return window.Bokeh && Bokeh.documents.length > 0 && [...Bokeh.documents[0]"
                "._all_models.values()].some(m => m.name === 'polar-0')"):
            if time.monotonic() > end:
                raise RuntimeError("the page did not load in 60 s")
            time.sleep(0.1)
        time.sleep(1.0)
        canvas = driver.execute_script("""
            const found = [];
            (function walk(root) {
              root.querySelectorAll('canvas.brdf-lobe').forEach(e => found.push(e));
              root.querySelectorAll('*').forEach(e => { if (e.shadowRoot) walk(e.shadowRoot); });
            })(document);
            return found[0];""")
        times, server_side = [], []
        # the slider moves log10(alpha)
        for alpha in [0.3] + _alphas(repeats):
            times.append(driver.execute_async_script(_ROUND_TRIP, "ggx.alpha",
                                                     math.log10(alpha), canvas, floor) / 1e3)
            server_side.append(server.explorers[-1].timings.get("total", 0.0))
        in_browser.server_side = server_side[1:]  # the update's own time in each round trip
        return times[1:]
    finally:
        explorer.Explorer.update = full_update
        driver.quit()
        server.stop()


def _row(name, times):
    p95 = sorted(times)[max(0, math.ceil(0.95 * len(times)) - 1)]
    median = statistics.median(times)
    print(f"{name:34s} {1e3 * min(times):8.1f} {1e3 * median:8.1f} {1e3 * p95:8.1f} "
          f"{median / BUDGET:10.2f}")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=40)
    parser.add_argument("--no-browser", action="store_true", help="server side only")
    args = parser.parse_args()
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
    print(f"{SPEC}: {args.repeats} slider moves of ggx.alpha")
    print(f"{'':34s} {'best ms':>8s} {'median':>8s} {'p95':>8s} {'/ 100 ms':>10s}")
    for draft, name in ((True, "while moving"), (False, "let go")):
        totals, views = server_side(args.repeats, draft)
        _row(f"server, {name}: all views", totals)
        for key in ("lobe", "polar", "albedo", "sphere", "object", "slice"):
            _row(f"  of which {key}", views[key])
    _row("server, arrow dragged on the lobe", arrow_drag(args.repeats))
    totals, views = server_side(args.repeats, True, "sky")
    _row("server, sky map, while moving", totals)
    for key in ("sphere", "object"):
        _row(f"  of which {key}", views[key])
    # a measured table shown beside the model: its previews are made once per lighting
    totals, views = server_side(args.repeats, True, "sky", also=[TABLE])
    _row("server, sky map, + an RGL table", totals)
    for key in ("sphere", "object"):
        _row(f"  of which {key}", views[key])
    if not args.no_browser:
        times = in_browser(args.repeats)
        if times:
            _row("browser, while moving: all redrawn", times)
            _row("  of which the server's update", in_browser.server_side)
            _row("browser, computing nothing (floor)", in_browser(args.repeats, floor=True))


if __name__ == "__main__":
    main()
