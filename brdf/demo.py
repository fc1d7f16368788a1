"""The main job end to end: ``brdf-fit demo`` / :func:`run`.

On a bundled real measurement (RGL's white paper, a CC0 isotropic RGB table in
``measurements/rgl``) and a MERL-size synthetic table made on the fly (a known model measured by
the virtual gonioreflectometer with 2 % noise), it runs every stage the library offers:

info -> physical checks -> nlopt fits of candidate models with the energy constraint ->
comparison (BIC) -> emcee posterior of the best fit of the real data -> validation renders
(:func:`brdf.render.validate`: measured versus fitted, false-colour difference, FLIP, in one
figure) -> 3-D lobes and 2-D plots; then a material recovered from rendered photographs
(:func:`brdf.fit_images`, the path method: truth, estimate and 95 % interval) ->
``results/`` with the JSON reports, the images and one self-contained ``report.html``.
"""

import base64
import contextlib
import html
import json
import time
from pathlib import Path

import numpy as np

from .errors import InputError, OutputError

__all__ = ["run", "DATASETS", "CANDIDATES", "VALIDATION_FIGURE"]

#: Candidate models fitted to each data set (BIC picks among them)
CANDIDATES = ("lambert", "lambert + ggx", "lambert + beckmann")
#: The synthetic material: its true model and the noise of its virtual measurement
SYNTHETIC_TRUTH = "lambert(albedo=[0.35,0.2,0.1]) + ggx(alpha=0.18, ks=[0.5,0.5,0.5])"
SYNTHETIC_NOISE = "relative:0.02"
#: Validation renders (pixels, samples per pixel): the lit sphere's noise comes mostly from
#: choosing between the key light and the environment, so it falls only as 1/sqrt(spp). Five
#: times the paths of 160 x 160 at 32 spp cut the noise per pixel by 30 % (relative standard
#: error 6.2 % instead of 8.7 %) and make the shading large enough to judge, for a few seconds
#: more: the four renders are most of the validation stages' time, the emcee chain most of
#: the demo's.
RENDER_SIZE, RENDER_SPP = (256, 256), 64
#: The photographed material: a sphere of this BRDF beside a diffuse floor (albedo
#: CAPTURE_FLOOR) under a point light, so that light passes between them
CAPTURE_TRUTH = "lambert(albedo=[0.45,0.3,0.18]) + ggx(alpha=0.22, ks=0.35)"
CAPTURE_FLOOR = 0.6
#: The photograph's pixels and samples per pixel, and the path method's samples per pixel
CAPTURE_SIZE, CAPTURE_PHOTO_SPP, CAPTURE_FIT_SPP = (64, 48), 1024, 128
#: The report's label of the composite validation figure (brdf.viz.validation_figure)
VALIDATION_FIGURE = "validation: measured | fitted | difference | FLIP"


def _bundled(name):
    """A file of the bundled measurements (the repository's measurements/ folder, installed
    as the ``brdf_measurements`` package)."""
    from importlib import resources
    try:
        path = Path(str(resources.files("brdf_measurements") / name))
    except ModuleNotFoundError:
        path = None
    if path is None or not path.exists():
        raise InputError(f"bundled measurement {name} not found: install brdf from its source "
                         "tree (pip install .), which ships measurements/")
    return path


DATASETS = {"paper-white": "rgl/paper_white_rgb.bsdf"}


def _compile_ahead(render_ready):
    """The second process's work (:func:`_start_compiling`): the fits' and the renderer's
    kernels, then, with ``render_ready`` set, the rest of the model kernels over every
    family (sampling, densities, albedo without its gradient), which the demo does not call
    but the commands a user runs next do (``export``'s albedo comparison, ``sample``)."""
    from .precompile import compile_groups
    compile_groups(["fitting", "render"])
    render_ready.set()
    compile_groups(["models"])


def _start_compiling():
    """On a cold cache the kernels take minutes to compile; a second process compiles the
    fits' kernels and then the renderer's on the other core while this one compiles the
    models' (evaluation, albedo: :func:`_compile_albedo`) and then reads, checks and fits
    (from the cache it only loads them). A kernel the demo needs before that process has
    cached it is compiled here as well, and the demo renders once the process has the
    renderer's: either way the results are the same. Returns a function that waits for
    that (or for the process to end)."""
    import multiprocessing
    context = multiprocessing.get_context("spawn")
    render_ready = context.Event()
    worker = context.Process(target=_compile_ahead, args=(render_ready,), daemon=True)
    worker.start()

    def wait_for_render():
        while worker.is_alive() and not render_ready.wait(0.5):
            pass

    return wait_for_render


def _compile_albedo():
    """Compile (or load) the albedo kernel, with its gradient, here and now: every fit needs
    it and the loss kernels at once, and the second process is compiling those meanwhile
    (each takes about a minute on a cold cache)."""
    from .geometry import directions_from_degrees
    from .spec import parse
    parse("lambert + ggx").albedo_gradient(directions_from_degrees([30.0], [0.0]))


#: Stages of a run: reading and synthesising, then per data set its info and checks, fits,
#: renders and plots, the posterior of the real measurement, and the material from photographs
STAGES = 1 + 4 * 2 + 1 + 1


class _Stages:
    """Numbers, times and reports the stages (:func:`brdf.progress.stage`), recording their
    seconds in ``times`` (``summary.json``'s ``stages``: the first run's include numba's
    compilation)."""

    def __init__(self, progress, times):
        self.progress, self.times, self.number = progress, times, 0

    @contextlib.contextmanager
    def __call__(self, name):
        from .progress import stage
        self.number += 1
        with stage(f"demo: {name}", self.progress, self.number, STAGES) as timing:
            yield
        self.times[name] = timing["seconds"]


def _prepare(outdir, force):
    out = Path(outdir)
    if out.exists() and not out.is_dir():
        raise OutputError(f"{out}: exists and is not a folder")
    if out.exists() and any(out.iterdir()) and not force:
        raise OutputError(f"{out}: exists and is not empty; pass --force (force=True) to "
                          "write into it")
    out.mkdir(parents=True, exist_ok=True)
    return out


def _write_json(path, doc):
    from .io import atomic_output
    from .formatting import json_ready
    with atomic_output(path, force=True) as tmp:
        tmp.write_text(json.dumps(json_ready(doc), indent=2, allow_nan=False) + "\n",
                       encoding="utf-8")


def _subsample(table, n, seed):
    """At most n random samples of a table (the posterior's likelihood runs over them)."""
    from .table import Table
    if len(table) <= n:
        return table
    idx = np.sort(np.random.default_rng(seed).choice(len(table), n, replace=False))
    return Table(table.wi[idx], table.wo[idx], table.values[idx],
                 sigma=None if table.sigma is None else table.sigma[idx],
                 channel_names=table.channel_names, metadata=dict(table.metadata))


def _datasets(seed):
    import brdf
    real = brdf.read(_bundled(DATASETS["paper-white"]))
    synth = brdf.measure(brdf.parse(SYNTHETIC_TRUTH), "merl", SYNTHETIC_NOISE, seed)
    return {"paper-white": real, "synthetic-merl": synth}


def run(outdir="results", *, seed=0, force=False, quick=False, progress=None):
    """Run the demo into ``outdir``; returns the summary dictionary also written to
    ``summary.json``. ``quick`` shrinks renders and chains (for tests).

    ``progress`` None (default): on a terminal, a line as each of the :data:`STAGES` stages
    starts and ends, with the fits' and renders' bars between them; otherwise one line on
    stderr as each stage ends (``demo: paper-white: validation renders (5 of 10) in 9.3 s``)
    and one when the run is done; nothing when :func:`brdf.progress.reporting` is quiet.
    True: as on a terminal; False: nothing."""
    import brdf
    from .models._kernels import every_family
    from .progress import mode, note
    from .render import validate
    from .viz import albedo_plot, inplane_plot, plot_lobes, residual_plot, save_figure, slice_plot
    shown = mode(progress)
    # the bars of the fits and renders within a stage, on a terminal only: elsewhere the
    # stage's own line says enough
    inner = shown == "bar"
    out = _prepare(outdir, force)
    t_start = time.perf_counter()
    wait_for_render = _start_compiling()
    size, spp = ((48, 48), 8) if quick else (RENDER_SIZE, RENDER_SPP)
    summary = {"seed": seed, "datasets": {}, "stages": {}}
    stage = _Stages(progress, summary["stages"])
    with stage("read and synthesise"):
        data = _datasets(seed)
        with every_family():  # the demo fits and draws many families: one compile for all
            _compile_albedo()
    for name, table in data.items():
        entry = summary["datasets"][name] = {"images": {}}
        with stage(f"{name}: info and checks"):
            entry["info"] = table.summary()
            entry["check"] = brdf.check(table).to_dict()
        with stage(f"{name}: fit {len(CANDIDATES)} models (energy constraint), compare"):
            comparison = brdf.compare(table, list(CANDIDATES), by="bic", energy_constraint=True,
                                      shared=["ks"] if name == "synthetic-merl" else [],
                                      seed=seed, progress=inner)
        _write_json(out / f"{name}-compare.json", comparison.to_dict())
        entry["compare"] = comparison.to_dict()["models"]
        best = comparison.best
        _write_json(out / f"{name}-fit.json", best.to_dict())
        entry["best"] = str(best.model)
        if name == "paper-white":
            with stage(f"{name}: emcee posterior of the best fit"):
                # the chain runs on a random subset (the fit starts from the full fit's values)
                post = brdf.mcmc(_subsample(table, 2000 if quick else 5000, seed),
                                 str(best.model), seed=seed, max_steps=600 if quick else 6000,
                                 progress=False)
                post.corner(out / f"{name}-corner.png", force=True)
                entry["posterior"] = post.to_dict()
                entry["images"]["posterior (corner)"] = f"{name}-corner.png"
        with stage(f"{name}: validation renders"):
            wait_for_render()
            # brdf-fit validate's renders and pictures, named after the data set
            entry["image_metrics"] = validate(table, best.model, out, spp=spp, size=size,
                                              seed=seed, force=True, prefix=f"{name}-",
                                              progress=inner)
            entry["images"][VALIDATION_FIGURE] = f"{name}-comparison.png"
        with stage(f"{name}: lobes and plots"):
            plot_lobes(best.model, (30.0, 60.0), data=table, path=out / f"{name}-lobes.png",
                       force=True)
            entry["images"]["3-D lobes of the fit (measured samples as points)"] = \
                f"{name}-lobes.png"
            figures = {"in-plane": inplane_plot(best.model, data=table),
                       "albedo": albedo_plot(best.model, table),
                       "residuals": residual_plot(best.model, table)}
            if name == "synthetic-merl":
                figures["theta_h / theta_d slice"] = slice_plot(table)
            for label, fig in figures.items():
                path = f"{name}-{label.split()[0].replace('/', '')}.png"
                save_figure(fig, out / path, force=True)
                entry["images"][label] = path
    with stage("photographs: a material recovered by inverse rendering"):
        summary["capture"] = _capture(out, seed, quick)
    summary["seconds"] = time.perf_counter() - t_start
    _write_json(out / "summary.json", summary)
    _write_report(out, summary)
    if shown is not None:
        note(f"demo: done in {summary['seconds']:.0f} s: {out / 'report.html'}")
    return summary


def _capture(out, seed, quick):
    """Photograph :data:`CAPTURE_TRUTH` with the path tracer and recover it with
    :func:`brdf.fit_images` (path method, its own seed): the rows truth | estimate | 95 %
    interval, and the files."""
    import brdf
    from .render import load
    from .spec import parse
    doc = {"camera": {"origin": [0, 0.6, 4], "target": [0, 0, 0], "fov": 36},
           "materials": {"floor": f"lambert(albedo={CAPTURE_FLOOR})"},
           "shapes": [{"type": "sphere", "centre": [0, 0, 0], "radius": 1,
                       "material": "@material"},
                      {"type": "rectangle", "material": "floor",
                       "to_world": [[3, 0, 0, 0], [0, 0, 3, -1], [0, -3, 0, 0], [0, 0, 0, 1]]}],
           "lights": [{"type": "point", "position": [2.5, 2.5, 3], "intensity": 12}]}
    _write_json(out / "capture-scene.json", doc)
    size = (32, 24) if quick else CAPTURE_SIZE
    photo_spp, fit_spp = (128, 32) if quick else (CAPTURE_PHOTO_SPP, CAPTURE_FIT_SPP)
    truth = parse(CAPTURE_TRUTH)
    scene = load(out / "capture-scene.json", material=truth)
    photo = brdf.render.render(scene, spp=photo_spp, size=size, seed=seed + 1, progress=False)
    photo.save(out / "capture-photo.exr", force=True, layers=False)
    photo.save(out / "capture-photo.png", force=True)
    fit = brdf.fit_images("lambert + ggx", [(out / "capture-scene.json",
                                             out / "capture-photo.exr")],
                          method="path", spp=fit_spp, seed=seed, progress=False)
    fit.save(out / "capture-fit.json", force=True)
    rows = []
    for name in fit.free:
        # a scalar of the truth (ks) is fitted per channel
        true = float(truth.params.get(name, truth.params.get(name.partition("[")[0])))
        lo, hi = fit.interval(name)
        rows.append({"parameter": name, "truth": true, "estimate": fit.params[name],
                     "relative_error": (fit.params[name] - true) / true,
                     "interval_95": [lo, hi]})
    return {"truth": CAPTURE_TRUTH, "size": list(size), "photo_spp": photo_spp,
            "fit_spp": fit_spp, "renders": fit.capture["renders"],
            "pixels": fit.capture["pixels_used"], "rows": rows,
            "images": {"the photograph (path tracer, every bounce)": "capture-photo.png"}}


# --- the HTML report --------------------------------------------------------------------------

_STYLE = """body{font-family:system-ui,sans-serif;max-width:1100px;margin:2em auto;color:#222}
table{border-collapse:collapse;margin:0.5em 0 1.5em}td,th{border:1px solid #ccc;padding:3px 8px;
text-align:right;white-space:nowrap}th{background:#f3f3f3}td.l,th.l{text-align:left;
white-space:normal}
.figures{display:flex;flex-wrap:wrap;gap:1em;align-items:flex-start;margin:1em 0}
figure{margin:0;flex:0 1 calc(50% - 0.5em);max-width:calc(50% - 0.5em)}
figure.wide{flex-basis:100%;max-width:100%}
figure img{display:block;max-width:100%;height:auto;border:1px solid #ddd}
a.zoom{cursor:zoom-in}figcaption{font-size:0.85em;color:#555;margin-top:0.3em}
code{background:#f6f6f6}
#viewer{position:fixed;inset:0;z-index:9;display:flex;overflow:auto;
background:rgba(25,25,25,0.92);cursor:zoom-out}#viewer[hidden]{display:none}
#viewer img{margin:auto;max-width:none;background:#fff}
#viewer p{position:fixed;top:0;left:0;margin:0;padding:4px 10px;color:#eee;
background:rgba(0,0,0,0.6);font-size:0.85em}"""

# A click on a picture shows it at its full size in a viewer over the page (a click or Esc
# closes it); report.html#view-N opens picture N so. The pictures are data URIs inside this one
# file, and browsers refuse to open a data URI as a page of its own, hence the viewer. The
# load handler also counts the pictures that decoded and what the viewer shows, for a headless
# browser to read back (tests/test_demo.py).
_SCRIPT = """function view(id){var v=document.getElementById('viewer'),
a=id?document.querySelector('a.zoom[href="#'+id+'"]'):null;if(!a){v.hidden=true;return;}
var big=v.querySelector('img'),small=a.querySelector('img');
big.onload=function(){var b=document.body;b.setAttribute('data-viewing',id);
b.setAttribute('data-viewer-width',big.width);
b.setAttribute('data-viewer-natural',big.naturalWidth);};
big.src=small.src;big.alt=small.alt;v.querySelector('p').textContent=small.alt+': '+
small.naturalWidth+' x '+small.naturalHeight+' pixels, full size; a click or Esc closes it';
v.hidden=false;v.scrollTop=0;v.scrollLeft=0;}
window.addEventListener('load',function(){var n=0,imgs=document.querySelectorAll('figure img');
for(var i=0;i<imgs.length;i++){if(imgs[i].complete&&imgs[i].naturalWidth>0)n++;}
document.body.setAttribute('data-images-loaded',n);
document.body.setAttribute('data-images-total',imgs.length);
document.querySelectorAll('a.zoom').forEach(function(a){a.addEventListener('click',function(e){
if(e.ctrlKey||e.metaKey||e.shiftKey||e.button)return;e.preventDefault();
view(a.getAttribute('href').slice(1));});});
document.getElementById('viewer').addEventListener('click',function(){this.hidden=true;});
document.addEventListener('keydown',function(e){if(e.key==='Escape')
document.getElementById('viewer').hidden=true;});
view(location.hash.slice(1));});"""

#: What a picture's lines and colours mean, where the picture itself does not say
_CAPTIONS = {
    VALIDATION_FIGURE: "the table and its fit rendered on the lit sphere with the same seed; "
                       "each colour bar says what its panel's colours stand for and how many "
                       "pixels it clips",
    "posterior (corner)": "1-D and 2-D marginals of the posterior; dashed lines: 16th, 50th "
                          "and 84th percentiles; blue lines: the optimum of the fit",
}


def _img(path):
    data = base64.b64encode(Path(path).read_bytes()).decode("ascii")
    return f'<img alt="{html.escape(Path(path).name)}" src="data:image/png;base64,{data}">'


def _png_size(path):
    """(width, height) of a PNG, from its header (IHDR, the first chunk)."""
    import struct
    with open(path, "rb") as f:
        return struct.unpack(">II", f.read(24)[16:24])


def _figure(path, label, number, wide=False):
    """A picture that opens at full size on a click (the viewer of :data:`_SCRIPT`)."""
    note = _CAPTIONS.get(label)
    caption = html.escape(label) + (f": {html.escape(note)}" if note else "")
    return (f'<figure{" class=wide" if wide else ""}><a class="zoom" href="#view-{number}" '
            f'title="full size">{_img(path)}</a><figcaption>{caption}</figcaption></figure>')


def _table(head, rows, left=1):
    cls = lambda i: ' class="l"' if i < left else ""  # noqa: E731
    h = "".join(f"<th{cls(i)}>{html.escape(str(c))}</th>" for i, c in enumerate(head))
    b = "".join("<tr>" + "".join(f"<td{cls(i)}>{html.escape(str(c))}</td>"
                                 for i, c in enumerate(r)) + "</tr>" for r in rows)
    return f"<table><tr>{h}</tr>{b}</table>"


def _check_rows(check):
    from .formatting import significant
    rows = []
    for c in check["checks"]:
        where = ", ".join(f"{k} {significant(v)}" if isinstance(v, float) else f"{k} {v}"
                          for k, v in (c.get("where") or {}).items() if v is not None)
        worst = c.get("worst")
        rows.append([c["name"], "n/a" if c.get("passed") is None else
                     ("pass" if c["passed"] else "FAIL"),
                     significant(worst) if isinstance(worst, (int, float)) else "", where])
    return rows


def _write_report(out, summary):
    """report.html: every table and picture of the run in one file; numbers for people with
    four significant digits (the JSON files beside it hold them in full)."""
    from .formatting import round_numbers, significant as sig
    from .io import atomic_output
    from .table import summary_rows
    parts = ["<!DOCTYPE html><html><head><meta charset='utf-8'><title>brdf demo report</title>",
             f"<style>{_STYLE}</style><script>{_SCRIPT}</script></head><body>",
             "<h1>brdf demo report</h1>",
             f"<p>Seed {summary['seed']}; {summary['seconds']:.0f} s end to end. Every number "
             "and picture below was made by this run; numbers show four significant digits, "
             "and the JSON files beside this page hold them in full. A click on a picture "
             "shows it at full size.</p>"]
    number = 0
    for name, e in summary["datasets"].items():
        parts.append(f"<h2>{html.escape(name)}</h2>")
        parts.append("<h3>The measurement (brdf-fit info)</h3>")
        parts.append(_table(["property", "value"], summary_rows(e["info"], digits=4), left=2))
        rows = _check_rows(e["check"])
        if rows:
            parts.append("<h3>Physical checks of the measurement</h3>")
            parts.append(_table(["check", "verdict", "worst", "where"], rows))
        parts.append("<h3>Model comparison (BIC, energy-constrained fits)</h3>")
        parts.append(_table(["rank", "model", "k", "loss", "BIC", "dBIC", "weight", "checks"],
                            [[i + 1, round_numbers(r["fitted"]), r["k"], sig(r["loss"]),
                              sig(r["bic"]), sig(r["delta"]), sig(r["weight"]),
                              "pass" if r["checks_pass"] else "FAIL"]
                             for i, r in enumerate(e["compare"])], left=2))
        if "posterior" in e:
            p = e["posterior"]
            parts.append("<h3>Posterior of the best fit (emcee)</h3>")
            parts.append(_table(["parameter", "median", "16 %", "84 %", "2.5 %", "97.5 %"],
                                [[k] + [sig(v[q]) for q in ("50", "16", "84", "2.5", "97.5")]
                                 for k, v in p["percentiles"].items()]))
            parts.append(f"<p>{html.escape(round_numbers(p['verdict']))}; acceptance "
                         f"{sig(p['acceptance_fraction'])}, {p['walkers']} walkers x "
                         f"{p['steps']} steps</p>")
        m = e.get("image_metrics", {})
        if m:
            parts.append("<h3>Validation render: fitted against measured</h3>")
            parts.append(_table(["scene", "size", "samples per pixel", "RMSE", "relative MSE",
                                 "FLIP"],
                                [[m.get("scene", ""), " x ".join(map(str, m.get("size", []))),
                                  m.get("spp", ""), sig(m["rmse"]), sig(m["relmse"]),
                                  sig(m.get("flip", float("nan")))]], left=1))
        parts.append('<div class="figures">')
        # pictures of panels side by side (at least twice as wide as tall) take the full
        # width, which they need to be read: the validation figure first, then the others,
        # then the rest two in a row
        shapes = {label: _png_size(out / path) for label, path in e["images"].items()}
        wide = {label for label, (w, h) in shapes.items() if w >= 2 * h}
        for label in sorted(e["images"], key=lambda k: (k != VALIDATION_FIGURE, k not in wide)):
            parts.append(_figure(out / e["images"][label], label, number, wide=label in wide))
            number += 1
        parts.append("</div>")
    c = summary.get("capture")
    if c:
        parts.append("<h2>A material from photographs (brdf.fit_images, path method)</h2>")
        parts.append(f"<p>A sphere of <code>{html.escape(c['truth'])}</code> beside a diffuse "
                     f"floor under a point light, photographed by the path tracer "
                     f"({c['size'][0]} x {c['size'][1]}, {c['photo_spp']} spp, every bounce), "
                     f"then recovered from {c['pixels']:,} pixels through {c['renders']} "
                     f"renders of {c['fit_spp']} spp with other random streams. The intervals "
                     "are Gauss-Newton's, widened by the renders' own Monte Carlo error.</p>")
        parts.append(_table(["parameter", "truth", "estimate", "error", "95 % interval"],
                            [[r["parameter"], sig(r["truth"]), sig(r["estimate"]),
                              f"{100 * r['relative_error']:+.2f} %",
                              f"[{sig(r['interval_95'][0])}, {sig(r['interval_95'][1])}]"]
                             for r in c["rows"]]))
        parts.append('<div class="figures">')
        for label, path in c["images"].items():
            parts.append(_figure(out / path, label, number))
            number += 1
        parts.append("</div>")
    parts.append('<div id="viewer" hidden><p></p><img alt=""></div></body></html>')
    with atomic_output(out / "report.html", force=True) as tmp:
        tmp.write_text("\n".join(parts), encoding="utf-8")
