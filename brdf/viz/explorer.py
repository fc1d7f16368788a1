"""The interactive BRDF explorer: a local web app (Panel and Bokeh) with sliders for every
parameter and linked views that follow them live, for several materials at once.

Views: the 3-D lobe (rotate and zoom in the browser), the in-plane polar plot, the directional
albedo against theta_i with the energy limit 1, the theta_h / theta_d slice, and a lit sphere
under a key light and an environment (direct lighting from the model's kernels while sliders
move, path traced once they rest). The arrays behind them come from
:mod:`brdf.viz.view_data`; this module only lays them out and wires the widgets.

Panel, Bokeh and their JavaScript are the optional extra ``brdf[explore]``; the page loads
every script from the local server (nothing is downloaded at run time).

>>> import brdf
>>> from brdf.viz.explorer import Explorer
>>> app = Explorer(["lambert(albedo=0.5) + ggx(alpha=0.2)"])   # doctest: +SKIP
"""

import math
import os
import time
from dataclasses import dataclass, field

import numpy as np

from ..errors import BRDFError, InputError
from . import view_data
from .samples import incidence, is_table

__all__ = ["Explorer", "explore", "material_from", "EXTRA"]

#: The install command of the optional dependencies, said when they are missing.
EXTRA = 'pip install "brdf[explore]"'
#: The spec a measured material's fit box starts with.
DEFAULT_FIT = "lambert + ggx"
#: Seconds between two progress updates of a running fit sent to the page.
PROGRESS_EVERY = 0.2
#: Colours of the materials, in the order they are added (matplotlib's tab10, as the plots).
COLOURS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2",
           "#7f7f7f", "#bcbd22", "#17becf")
#: Incidence angles of the albedo curve, degrees: when a slider is let go, and while it moves
#: (a draft that keeps every view live; ``benchmarks/bench_explore.py`` times both).
ALBEDO_THETA = np.linspace(0.0, 89.0, 46)
DRAFT_ALBEDO_THETA = np.linspace(0.0, 89.0, 16)
#: The albedo cubature's tolerance, full and draft (view_data.albedo_curve): a draft's at
#: 1e-2 is within 2e-3 of the exact curve for lambert + ggx (alpha 0.05 to 0.35), under a
#: pixel of the plot, at half the cost.
ALBEDO_TOL, DRAFT_ALBEDO_TOL = 1e-3, 1e-2
#: Polar steps of the 3-D lobe (azimuth steps are twice as many), full and draft: the page
#: draws 2 n^2 triangles per lobe on a canvas, about 10 microseconds each in headless chromium.
LOBE_RESOLUTION = 24
DRAFT_LOBE_RESOLUTION = 16
#: Pixels across each lit-sphere preview.
SPHERE_SIZE = 128
DRAFT_SPHERE_SIZE = 64
#: Pixels across the theta_h / theta_d slice, full and draft, and the decades its log colours
#: span under the peak (as brdf.viz.slice_plot).
SLICE_SIZE, DRAFT_SLICE_SIZE, SLICE_DECADES = 90, 45, 4.0
#: The slice's colours end at its peak rounded up to a multiple of this many decades.
SLICE_STEP = 0.25
#: The slice selector's entry that follows the first material shown.
FIRST_SHOWN = "first material shown"
#: The previews' lighting choices: the key light and a uniform environment, or the bundled
#: sky map (brdf.viz.view_data.sky_map), previewed with this many median-cut regions
#: (view_data.MapStrata; fewer while a slider moves: each costs an evaluation per pixel); a map the user gives
#: (:meth:`Explorer.set_environment`) adds the choice ``"map"``, labelled MAP_LABEL + its name.
LIGHTING = {"key light + environment": "key", "sky map": "sky"}
MAP_LABEL = "map: "
SKY_LIGHTS, DRAFT_SKY_LIGHTS = 32, 16
#: Samples per pixel of the path-traced sphere that replaces the preview once the sliders
#: rest (64 at 128 x 128: about 0.25 s for lambert + ggx on this machine).
REFINE_SPP = 64
#: Screen pixels across each lit sphere.
SPHERE_PIXELS = 200


def require_panel():
    """Import Panel, or raise :class:`~brdf.errors.InputError` saying how to install it."""
    try:
        import bokeh  # noqa: F401
        import panel
    except ImportError:
        raise InputError(f"the explorer needs Panel and Bokeh: {EXTRA}") from None
    return panel


def live_slider_class():
    """Panel's float slider whose moves reach the explorer at once: Panel waits 50 ms before
    it hands a widget's change from the page to Python (to gather a burst of them), which
    was half the time from a slider's move to the redrawn views (benchmarks/
    bench_explore.py). Moves that come while an update runs still merge into one."""
    global _SLIDER
    if _SLIDER is None:
        pn = require_panel()

        class LiveSlider(pn.widgets.FloatSlider):
            # the change still runs as a callback of the document (under its lock, so that
            # Bokeh sends its changes), only with no wait
            _debounce = 0

        _SLIDER = LiveSlider
    return _SLIDER


_SLIDER = None


def material_from(subject):
    """A model or table from what the explorer is given: a model, a table, the path of a JSON
    fit report or of a measured file, or a model spec."""
    import brdf
    if not isinstance(subject, (str, os.PathLike)):
        if not (hasattr(subject, "eval") and hasattr(subject, "albedo")):
            raise InputError(f"{subject!r}: expected a model, a table, a spec or a path")
        return subject
    text = os.fspath(subject).strip()
    if text.lower().endswith(".json"):
        return brdf.load_report(text).model
    if os.path.exists(text):
        return brdf.read(text)
    return brdf.parse(text)


@dataclass(eq=False)  # the same material is the same object (the slice selector's values)
class Material:
    """One material in the explorer: what it draws, its label and colour, whether it shows."""

    model: object
    label: str
    colour: str
    visible: bool = True
    solo: bool = False
    widgets: list = field(default_factory=list)
    albedo_cache: tuple = None
    #: a table's previews by (lighting, size, phi_i under the key light): (lights, images)
    preview_cache: dict = field(default_factory=dict)


def _short_name(material):
    """A material's name that its sliders do not change: its lobes' families, or the table's
    file name."""
    model = material.model
    if is_table(model):
        return os.path.basename(material.label)[:40]
    names = model.lobe_names() if hasattr(model, "lobe_names") else [model.name]
    return " + ".join(names)[:40]


def _message(exc):
    """The one line the page shows for an error (the library's own message when it is one)."""
    if isinstance(exc, BRDFError):
        return " ".join(str(exc).split())
    if isinstance(exc, OSError):
        return f"{exc.filename}: {exc.strerror}" if exc.filename else str(exc)
    return f"internal error: {type(exc).__name__}: {exc}"


class Explorer:
    """The explorer's state, widgets and views.

    Parameters
    ----------
    materials : iterable
        Models, tables, specs, fit-report or measured-file paths (see :func:`material_from`).
    theta_i, phi_i : float
        The incident direction, degrees.
    environment : str, path or ndarray, optional
        An environment map to light the previews with (:meth:`set_environment`).
    environment_label : str, optional
        Its name in the page (default: the file's name).

    Attributes
    ----------
    layout : panel.viewable.Viewable
        The page (serve it, or show it in a notebook).
    timings : dict
        Seconds each view took to recompute in the last update, and ``"total"``.
    """

    def __init__(self, materials=(), *, theta_i=30.0, phi_i=0.0, environment=None,
                 environment_label=None):
        pn = require_panel()
        self._doc = pn.state.curdoc  # the browser session's document, when served
        self.materials = []
        self.theta_i, self.phi_i = float(theta_i), float(phi_i)
        self.cosine, self.log = True, False
        #: Path trace the spheres after each full update (off: the direct-lighting preview).
        self.refine = True
        self.refine_thread = None
        self.timings = {}
        #: The user's environment map (radiance (h, w, 3)), its name, its lights by count.
        self.environment, self.environment_label, self._map_lights = None, None, {}
        self._build(pn)
        for subject in materials:
            self.add(subject)
        if environment is not None:
            self.set_environment(environment, environment_label, update=False)
        self.update()

    # -- materials --------------------------------------------------------------------------

    def add(self, subject, label=None):
        """Add a material (see :func:`material_from`), a table under ``label`` if given (else
        its path); errors propagate."""
        model = material_from(subject)
        colour = COLOURS[len(self.materials) % len(COLOURS)]
        label = (label or str(subject)) if is_table(model) else str(model)
        material = Material(model, label, colour)
        self.materials.append(material)
        self._material_card(material)
        self._add_glyphs(material)
        self._slice_options()
        return material

    def add_from_text(self, text, label=None, hide=None):
        """Add the material ``text`` names, as the page's text box does: an error shows its one
        line in the page instead of raising (less the text ``hide``, a folder the user never
        saw). True when the material was added."""
        count = len(self.materials)
        try:
            self.add(text, label)
            self.update()
        except Exception as exc:  # noqa: BLE001  (any bad input becomes the page's message)
            if len(self.materials) > count:  # added, but its views cannot be drawn
                self.remove(count)
            return self._show_error(exc, hide)
        return self._show_error(None)

    def _show_error(self, exc, hide=None):
        """Show ``exc``'s one line in the page, less the text ``hide`` (None: clear the
        message); returns whether there was none."""
        message = "" if exc is None else _message(exc)
        self.error.object = message.replace(hide, "") if hide else message
        self.error.visible = exc is not None
        return exc is None

    def upload(self, filename, data):
        """Add the measured file or JSON fit report ``data`` (bytes) uploaded from the browser
        as ``filename``, as :meth:`add_from_text` does with a path: saved under its own name
        in this explorer's folder of uploads (formats are told by extension, then content),
        a bad file's one line in the page. True when the material was added."""
        path, folder = self._save_upload(filename, data)
        return self.add_from_text(path, label=os.path.basename(path), hide=folder)

    def _upload_from_page(self, event):
        """The file input's file, added on the document's next tick (see _add_from_page)."""
        self._from_file_input(self.upload_input, event, self.upload)

    def _environment_from_page(self, event):
        """The map input's file, loaded on the document's next tick."""
        self._from_file_input(self.environment_input, event, self.upload_environment)

    def _from_file_input(self, widget, event, take):
        if event.new is None:
            return
        name, data = widget.filename, event.new

        def add():
            take(name, data)
            # forget it, here and in the page, so that the same file can come again
            widget.param.update(value=None, filename=None)
            widget.clear()
        self._soon(add)

    def _save_upload(self, filename, data):
        """Save ``data`` uploaded as ``filename`` under its own name in this explorer's folder
        of uploads; returns (path, the folder to hide in messages)."""
        import shutil
        import tempfile
        import weakref
        if self._uploads is None:
            # removed with the explorer (and at exit): tables may read their file lazily. A
            # TemporaryDirectory left to the collector warns (ResourceWarning) into whatever
            # runs at that moment, so the folder is removed by a finaliser of our own
            self._uploads = tempfile.mkdtemp(prefix="brdf-explore-")
            weakref.finalize(self, shutil.rmtree, self._uploads, True)
        name = os.path.basename(str(filename or "").replace("\\", "/")) or "upload"
        folder = tempfile.mkdtemp(dir=self._uploads)  # two uploads of one name coexist
        path = os.path.join(folder, name)
        with open(path, "wb") as out:
            out.write(bytes(data or b""))
        return path, folder + os.sep

    # -- the environment map ----------------------------------------------------------------

    def set_environment(self, source, label=None, update=True):
        """Light the previews with the environment map ``source`` (a lat-long OpenEXR path or a
        radiance array, :func:`brdf.viz.view_data.environment_map`), named ``label`` in the
        page (default: the file's name): median-cut lights while sliders move, the path tracer
        under the map once they rest. Errors propagate; the lighting stays as it was."""
        radiance = view_data.environment_map(source)
        if label is None:
            label = (os.path.basename(os.fspath(source))
                     if isinstance(source, (str, os.PathLike)) else "array")
        # both strata now, from one sum of the map: a large map's first draft need not wait
        lights = view_data.map_strata_of_counts(radiance, (DRAFT_SKY_LIGHTS, SKY_LIGHTS))
        self.environment, self.environment_label = radiance, str(label)
        self._map_lights = lights
        options = {**LIGHTING, MAP_LABEL + self.environment_label[:40]: "map"}
        self._lighting_options = options
        self._syncing_lighting = True  # the old choice may be gone: no update from the list
        try:
            self.lighting_select.options = list(options)
        finally:
            self._syncing_lighting = False
        self.set_lighting("map", update=update)

    def environment_from_text(self, path, label=None, hide=None):
        """Load the environment map at ``path`` as the page does: an error shows its one line
        in the page (less the text ``hide``) instead of raising. True when it was loaded."""
        try:
            self.set_environment(path, label)
        except Exception as exc:  # noqa: BLE001  (any bad input becomes the page's message)
            return self._show_error(exc, hide)
        return self._show_error(None)

    def upload_environment(self, filename, data):
        """Light the previews with the map ``data`` (bytes) uploaded as ``filename``, as
        :meth:`environment_from_text` does with a path. True when it was loaded."""
        path, folder = self._save_upload(filename, data)
        return self.environment_from_text(path, label=os.path.basename(path), hide=folder)

    def remove(self, index):
        """Remove material number ``index`` (its card and glyphs) and update."""
        m = self.materials.pop(index)
        self.cards.remove(m.card)
        for glyph in (m.polar_glyph, m.albedo_glyph, m.albedo_band, m.samples_glyph):
            glyph.visible = False
        self._slice_options()
        self.update()

    def _slice_options(self):
        """The slice selector's entries: the first material shown, then every material by
        number and name (its families or file, which stay as its sliders move); a removed
        material's choice falls back to the first."""
        chosen = self._slice_entries.get(self.slice_select.value)
        # the page's list holds labels: Panel sends the browser strings, not Python objects
        self._slice_entries = {f"{k + 1}: {_short_name(m)}": m
                               for k, m in enumerate(self.materials)}
        value = next((label for label, m in self._slice_entries.items() if m is chosen),
                     FIRST_SHOWN)
        self._syncing_slice = True
        try:
            self.slice_select.param.update(options=[FIRST_SHOWN, *self._slice_entries],
                                           value=value)
        finally:
            self._syncing_slice = False

    def _add_from_page(self):
        """The text box's material, added on the document's next tick: new plot glyphs must be
        made while the server holds the document's lock, which a widget's event does not."""
        text = self.spec_input.value
        self._soon(lambda: self.add_from_text(text))

    def set_parameter(self, material, name, value, draft=False):
        """Set the flat-named parameter ``name`` of ``material`` (a :class:`Material` or its
        index) and update (a ``draft`` while a slider moves, see :meth:`update`)."""
        m = self.materials[material] if isinstance(material, int) else material
        model = view_data.with_parameter(m.model, name, value)
        if model == m.model and not draft:
            self.update()  # a slider let go where its last move left it: refine the draft
            return
        m.model, m.label = model, str(model)
        self.update(draft)

    def _shown(self):
        solo = any(m.solo for m in self.materials)
        return [m for m in self.materials if (m.solo if solo else m.visible)]

    # -- computation ------------------------------------------------------------------------

    def view_data(self, material, draft=False):
        """The arrays every view draws for ``material`` at the current incidence (timed),
        but the slice (:meth:`slice_material`); a ``draft`` has a coarser albedo curve and a
        smaller sphere."""
        thetas = DRAFT_ALBEDO_THETA if draft else ALBEDO_THETA
        wi = incidence(self.theta_i, self.phi_i)
        model, out, times = material.model, {}, {}
        start = time.perf_counter()
        out["lobe"] = view_data.lobe_mesh(model, wi, cosine=self.cosine, log=self.log,
                                          resolution=DRAFT_LOBE_RESOLUTION if draft
                                          else LOBE_RESOLUTION)
        times["lobe"] = time.perf_counter() - start
        start = time.perf_counter()
        out["polar"] = view_data.polar_curve(model, wi, cosine=self.cosine)
        if is_table(model):  # its samples over its interpolant (and the other curves)
            out["samples"] = view_data.measured_in_plane(model, wi, cosine=self.cosine)
            out["near"] = view_data.measured_near(model, wi, cosine=self.cosine)
        times["polar"] = time.perf_counter() - start
        start = time.perf_counter()
        # the curve does not depend on theta_i: kept while the model and phi_i stay
        key = (str(model), self.phi_i, len(thetas))
        if material.albedo_cache is None or material.albedo_cache[0] != key:
            material.albedo_cache = key, view_data.albedo_curve(
                model, thetas, self.phi_i, tol=DRAFT_ALBEDO_TOL if draft else ALBEDO_TOL)
        out["albedo"] = thetas, material.albedo_cache[1]
        times["albedo"] = time.perf_counter() - start
        # the environment's term needs the albedo at theta_o: the curve just computed
        # under a map: its median-cut lights, fewer in a draft
        lights = self.lights(draft)
        size = DRAFT_SPHERE_SIZE if draft else SPHERE_SIZE
        # a table's previews change with nothing a slider moves but phi_i (its albedo curve,
        # under the key light): kept per lighting, as they cost a table's slow lookups
        key = (self.lighting, size, self.phi_i if lights is None else None)
        kept = material.preview_cache.get(key) if is_table(model) else None
        for name, preview in (("sphere", view_data.sphere_preview),
                              ("object", view_data.object_preview)):
            start = time.perf_counter()
            if kept is not None and kept[0] is lights:
                out[name] = kept[1][name]
            else:
                out[name] = preview(model, size, albedo=out["albedo"], lights=lights)
            times[name] = time.perf_counter() - start
        if is_table(model) and (kept is None or kept[0] is not lights):
            material.preview_cache[key] = lights, {k: out[k] for k in ("sphere", "object")}
        return out, times

    def lights(self, draft=False):
        """The previews' lights under the chosen map: its median cut's strata
        (:class:`~brdf.viz.view_data.MapStrata`, fewer in a ``draft``), None under the key
        light."""
        count = DRAFT_SKY_LIGHTS if draft else SKY_LIGHTS
        if self.lighting == "sky":
            return view_data.sky_strata(count)
        if self.lighting == "map":
            if count not in self._map_lights:
                self._map_lights[count] = view_data.map_strata(self.environment, count)
            return self._map_lights[count]
        return None

    def slice_material(self):
        """The material the theta_h / theta_d slice shows: the one chosen in the page's
        *slice of* list (shown or not), else the first material shown; None when none is."""
        chosen = self._slice_entries.get(self.slice_select.value)
        if chosen is not None and any(m is chosen for m in self.materials):
            return chosen
        shown = self._shown()
        return shown[0] if shown else None

    def update(self, draft=False):
        """Recompute every view of every material and push the arrays to the page.

        While a slider moves the page asks for ``draft`` updates (the albedo curve at
        16 angles, a 64-pixel sphere, a coarser lobe), and for a full one when it is let go."""
        from .._threads import serial_below
        start = time.perf_counter()
        timings = {}
        shown = self._shown()
        data = {}
        # every view evaluates a few thousand directions: one thread does that faster than
        # waking numba's pool, and far faster on a busy machine
        with serial_below(SPHERE_SIZE ** 2):
            for m in self.materials:
                if m in shown:
                    data[id(m)], times = self.view_data(m, draft)
                    for key, value in times.items():
                        timings[key] = timings.get(key, 0.0) + value
            sliced, image = self.slice_material(), None
            if sliced is not None:
                begin = time.perf_counter()
                image = view_data.slice_image(sliced.model, self.phi_d,
                                              DRAFT_SLICE_SIZE if draft else SLICE_SIZE)
                timings["slice"] = time.perf_counter() - begin
        self._draw(data, shown)
        self._draw_slice(sliced, image)
        timings["total"] = time.perf_counter() - start
        self._refines = getattr(self, "_refines", 0) + 1
        if not draft and shown and self.refine:
            self.refine_thread = self._refine(
                [m.model for m in shown], self._refines,
                self.environment if self.lighting == "map" else self.lighting)
        self.timings = timings

    # -- the page ---------------------------------------------------------------------------

    def _build(self, pn):
        from bokeh.models import ColumnDataSource, Span
        from bokeh.plotting import figure
        from .lobe_canvas import lobe_canvas_class
        pn.extension()
        self._pn = pn
        self._Slider = live_slider_class()
        self.theta_slider = self._Slider(label="theta_i [deg]", start=0.0, end=89.0,
                                         step=0.5, value=self.theta_i)
        self.phi_slider = self._Slider(label="phi_i [deg]", start=0.0, end=360.0, step=1.0,
                                       value=self.phi_i)
        for slider, key in ((self.theta_slider, "theta"), (self.phi_slider, "phi")):
            slider.param.watch(lambda e, key=key: self._incidence(
                draft=e.name == "value", **{key: e.new}), ["value", "value_throttled"])
        self.cosine_box = pn.widgets.Checkbox(label="f cos(theta_o)", value=self.cosine)
        self.log_box = pn.widgets.Checkbox(label="log radius", value=self.log)
        self.cosine_box.param.watch(lambda e: self._option(cosine=e.new), "value")
        self.log_box.param.watch(lambda e: self._option(log=e.new), "value")
        self.lighting = "key"
        self.lighting_select = pn.widgets.RadioButtonGroup(options=list(LIGHTING),
                                                           value=next(iter(LIGHTING)))
        self._lighting_options = dict(LIGHTING)
        self.lighting_select.param.watch(
            lambda e: None if getattr(self, "_syncing_lighting", False) else
            self.set_lighting(self._lighting_options[e.new]), "value")
        self.spec_input = pn.widgets.TextInput(label="add a material",
                                               placeholder="spec, fit report or measured file")
        self.add_button = pn.widgets.Button(label="add", color="primary")
        self.add_button.on_click(lambda e: self._add_from_page())
        self.spec_input.param.watch(lambda e: self._add_from_page(), "enter_pressed")
        self._uploads = None
        self.upload_input = pn.widgets.FileInput(multiple=False, width=300)
        self.upload_input.param.watch(self._upload_from_page, "value")
        self.environment_input = pn.widgets.FileInput(accept=".exr", multiple=False, width=300)
        self.environment_input.param.watch(self._environment_from_page, "value")
        self.error = pn.pane.Alert("", alert_type="danger", visible=False,
                                   css_classes=["brdf-error"])
        self.cards = pn.Column(sizing_mode="stretch_width")

        # no pan tool: dragging in the plot moves the incident direction (_drag_incidence)
        self.polar = figure(title="in-plane: r = f cos(theta_o)", width=420, height=260,
                            match_aspect=True, x_range=(-1.1, 1.1), y_range=(-0.05, 1.1),
                            tools="wheel_zoom,reset,save", name="polar")
        from bokeh.events import Pan, PanEnd, Tap
        self.polar.on_event(Tap, lambda e: self._drag_incidence(e.x, e.y, draft=False))
        self.polar.on_event(Pan, lambda e: self._drag_incidence(e.x, e.y, draft=True))
        self.polar.on_event(PanEnd, lambda e: self._drag_incidence(e.x, e.y, draft=False))
        self.polar.xaxis.axis_label = "incident side  <  theta_o  >  specular side"
        self.albedo = figure(title="directional albedo", width=420, height=260,
                             x_range=(0, 90), y_range=(0, 1.08),
                             tools="pan,wheel_zoom,reset,save", name="albedo")
        self.albedo.xaxis.axis_label = "theta_i [deg]"
        self.albedo.yaxis.axis_label = "a(theta_i)"
        self.albedo.add_layout(Span(location=1.0, dimension="width", line_dash="dashed",
                                    line_color="black"))
        self.albedo_marker = Span(location=self.theta_i, dimension="height",
                                  line_color="#888888", line_dash="dotted")
        self.albedo.add_layout(self.albedo_marker)
        self.incident_source = ColumnDataSource({"x": [0.0, 0.0], "y": [0.0, 0.0]},
                                                name="incident")
        self.polar.line("x", "y", source=self.incident_source, line_dash="dotted",
                        line_color="#e07b00")
        t = np.linspace(-math.pi / 2, math.pi / 2, 91)
        self.polar.line(np.sin(t), np.cos(t), line_color="#cccccc")
        self.sphere = figure(title="lit sphere (direct light)", frame_width=SPHERE_PIXELS,
                             frame_height=SPHERE_PIXELS, tools="save", name="sphere",
                             x_range=(0, 1), y_range=(0, 1), min_border=0)
        self.sphere.axis.visible = False
        self.sphere.grid.visible = False
        self.sphere_source = ColumnDataSource({"image": [], "x": [], "dw": []}, name="spheres")
        self.sphere.image_rgba("image", x="x", y=0, dw="dw", dh=1, source=self.sphere_source)
        self.object_view = figure(title="lit object (direct light)", frame_width=SPHERE_PIXELS,
                                  frame_height=SPHERE_PIXELS, tools="save", name="object",
                                  x_range=(0, 1), y_range=(0, 1), min_border=0)
        self.object_view.axis.visible = False
        self.object_view.grid.visible = False
        self.object_source = ColumnDataSource({"image": [], "x": [], "dw": []}, name="objects")
        self.object_view.image_rgba("image", x="x", y=0, dw="dw", dh=1,
                                    source=self.object_source)

        self._build_slice(pn)
        self.lobe = lobe_canvas_class()(size=420, width=420, height=420)
        self.lobe.param.watch(lambda e: self._aim(*e.new[:3]) if e.new else None, "drag")
        self.lobe_title = pn.pane.Markdown("**3-D lobe**: drag to turn, wheel to zoom; drag "
                                           "the orange tip (or Shift-drag) to move the light",
                                           margin=(0, 10))

        controls = pn.Column(
            pn.pane.Markdown("### Incidence"), self.theta_slider, self.phi_slider,
            pn.Row(self.cosine_box, self.log_box),
            pn.pane.Markdown("### Materials"), pn.Row(self.spec_input, self.add_button),
            pn.pane.Markdown("or upload a measured file or a JSON fit report:",
                             margin=(0, 10)), self.upload_input,
            pn.pane.Markdown("light the previews with your own map (lat-long OpenEXR):",
                             margin=(0, 10)), self.environment_input,
            self.error, self.cards, width=380)
        views = pn.Column(pn.Row(pn.Column(self.lobe_title, self.lobe),
                                 pn.Column(self.polar, self.albedo)),
                          pn.Row(pn.Column(self.lighting_select, self.sphere,
                                           self.object_view),
                                 pn.Column(self.slice_select, self.phi_d_slider, self.slice)))
        self.layout = pn.Row(controls, views, name="brdf explorer")

    def _build_slice(self, pn):
        """The theta_h / theta_d image of a material (:meth:`slice_material`), log colour, in
        the MERL layout (sqrt theta_h across), with its material selector and phi_d slider."""
        from bokeh.models import ColorBar, ColumnDataSource, LogColorMapper
        from bokeh.palettes import Magma256
        from bokeh.plotting import figure
        self.phi_d = 90.0
        self.phi_d_slider = self._Slider(label="slice phi_d [deg]", start=0.0, end=180.0,
                                         step=1.0, value=self.phi_d, width=300)
        self.phi_d_slider.param.watch(self._phi_d, ["value", "value_throttled"])
        self._slice_entries = {}
        self.slice_select = pn.widgets.Select(label="slice of", options=[FIRST_SHOWN],
                                              value=FIRST_SHOWN, width=300)
        self.slice_select.param.watch(
            lambda e: None if getattr(self, "_syncing_slice", False) else self.update(), "value")
        self.slice = figure(title="theta_h / theta_d slice", width=340, height=300,
                            x_range=(0, 1), y_range=(0, 90), tools="save,hover",
                            name="slice", tooltips=[("f_r", "@image")])
        ticks = [0, 1, 5, 10, 20, 45, 90]
        self.slice.xaxis.ticker = [math.sqrt(t / 90.0) for t in ticks]
        self.slice.xaxis.major_label_overrides = {math.sqrt(t / 90.0): str(t) for t in ticks}
        self.slice.xaxis.axis_label = "theta_h [deg] (sqrt spacing)"
        self.slice.yaxis.axis_label = "theta_d [deg]"
        self.slice_mapper = LogColorMapper(palette=Magma256, low=1e-3, high=1.0,
                                           nan_color="#dddddd")
        self.slice_source = ColumnDataSource({"image": []}, name="slice-image")
        self.slice.image("image", x=0, y=0, dw=1, dh=90, source=self.slice_source,
                         color_mapper=self.slice_mapper)
        self.slice.add_layout(ColorBar(color_mapper=self.slice_mapper, width=8,
                                       title="f_r [1/sr]"), "right")

    def _phi_d(self, event):
        self.phi_d = float(event.new)
        self.update(draft=event.name == "value")

    def _material_card(self, material, replace=None):
        """The material's card: colour, show, solo, then sliders and exports (a model) or
        the fit box (a table); in place of the card ``replace`` when given."""
        pn = self._pn
        from bokeh.models import CustomJSTickFormatter
        swatch = pn.pane.HTML(f'<span style="display:inline-block;width:14px;height:14px;'
                              f'background:{material.colour}"></span>', width=20)
        show = pn.widgets.Checkbox(label="show", value=True, width=60)
        solo = pn.widgets.Toggle(label="solo", value=False, width=60)
        show.param.watch(lambda e: self._visibility(material, visible=e.new), "value")
        solo.param.watch(lambda e: self._visibility(material, solo=e.new), "value")
        widgets = [pn.Row(swatch, show, solo)]
        if is_table(material.model):
            widgets += self._fit_widgets(material)
        else:
            widgets += self._export_widgets(material)
            log_format = CustomJSTickFormatter(code="return (10 ** tick).toPrecision(3)")
            for s in view_data.parameter_sliders(material.model):
                if s.log:
                    w = self._Slider(label=s.name, start=math.log10(s.low),
                                     end=math.log10(s.high), value=math.log10(s.value),
                                     step=0.01, format=log_format)
                else:
                    w = self._Slider(label=s.name, start=s.low, end=s.high,
                                     value=s.value, step=(s.high - s.low) / 500)
                w.param.watch(self._slider_callback(material, s), ["value", "value_throttled"])
                if s.splits:
                    split = pn.widgets.Button(label="RGB", width=50, margin=(18, 0, 0, 0),
                                              description="one value per channel")
                    split.on_click(lambda e, name=s.name: self.split_channels(material, name))
                    w = pn.Row(w, split)
                widgets.append(w)
        material.widgets = widgets
        card = pn.Card(*widgets, title=material.label[:60], header_color=material.colour,
                       sizing_mode="stretch_width")
        if replace is None:
            self.cards.append(card)
        else:
            self.cards[list(self.cards).index(replace)] = card
        material.card = card

    def split_channels(self, material, name):
        """Give the per-channel parameter ``name`` of ``material`` (a :class:`Material` or its
        index) one value per channel, each the value it held (three, RGB, for a model of one
        channel), with a slider each."""
        if isinstance(material, int):
            material = self.materials[material]
        channels = material.model.channels if material.model.channels > 1 else 3
        value = material.model.params[name]
        material.model = view_data.with_parameter(material.model, name, [value] * channels)
        material.label = str(material.model)
        self._material_card(material, replace=material.card)
        self.update()

    def _fit_widgets(self, material):
        """A measured material's fit box: a spec, a button, progress and the outcome."""
        pn = self._pn
        material.fit_spec = pn.widgets.TextInput(value=DEFAULT_FIT, width=220,
                                                 placeholder="a spec to fit")
        material.fit_button = pn.widgets.Button(label="fit", width=60)
        material.fit_progress = pn.indicators.Progress(active=False, value=-1, max=100,
                                                       visible=False, width=280)
        material.fit_status = pn.pane.Markdown("", css_classes=["brdf-fit-status"])
        material.fit_button.on_click(lambda e: self.start_fit(material))
        return [pn.Row(material.fit_spec, material.fit_button), material.fit_progress,
                material.fit_status]

    def _export_widgets(self, material):
        """Download buttons for the model in the library's export formats."""
        pn = self._pn
        buttons = []
        for fmt, suffix in (("mitsuba", ".xml"), ("gltf", ".gltf")):
            buttons.append(pn.widgets.FileDownload(
                callback=self._export_callback(material, fmt), filename=f"material{suffix}",
                label=f"export {fmt}", embed=False, width=140))
        return [pn.Row(*buttons)]

    def _export_callback(self, material, fmt):
        def export():
            import io

            import brdf
            try:
                result = brdf.export(material.model, fmt)
            except Exception as exc:  # noqa: BLE001  (the page says it; the server stays up)
                self.error.object, self.error.visible = _message(exc), True
                return io.StringIO("")
            self.error.object, self.error.visible = "", False
            return io.StringIO(result.text)
        return export

    # -- fitting ----------------------------------------------------------------------------

    def _soon(self, fn):
        """Run ``fn`` where it may change the page: on the document's next tick when served
        (from any thread), at once otherwise."""
        doc = getattr(self, "_doc", None)
        if doc is not None and doc.session_context is not None:
            doc.add_next_tick_callback(fn)
        else:
            fn()

    def start_fit(self, material, spec=None, **options):
        """Fit ``spec`` (default: the material's fit box) to measured ``material`` (a
        :class:`Material` or its index) in a background thread, with progress in the page;
        the fitted model is added as a new material when it ends. ``options`` go to
        :func:`brdf.fit` (default ``seed=0``). Returns the thread."""
        import threading
        if isinstance(material, int):
            material = self.materials[material]
        if not is_table(material.model):
            raise InputError(f"{material.label}: a fit needs a measured table")
        spec = material.fit_spec.value if spec is None else spec
        options.setdefault("seed", 0)
        material.fit_button.disabled = True
        # indeterminate until the first fraction arrives
        material.fit_progress.param.update(visible=True, active=True, value=-1)
        material.fit_status.object = f"fitting `{spec}` ..."
        state = {"last": 0.0, "start": time.perf_counter()}

        def progress(done, total):
            # done / total: the fraction of the fit's planned runs behind it (brdf.progress;
            # an energy refinement after them stays at 100)
            now = time.perf_counter()
            percent = min(100, int(100 * done / total)) if total else 0
            if now - state["last"] >= PROGRESS_EVERY or (percent == 100 != state.get("sent")):
                state["last"], state["sent"] = now, percent
                text = f"fitting `{spec}`: {percent}% ({now - state['start']:.1f} s)"
                self._soon(lambda: self._fit_progress(material, percent, text))

        def run():
            import brdf
            try:
                result = brdf.fit(material.model, spec, progress=progress, **options)
            except Exception as exc:  # noqa: BLE001  (the page says it; the server stays up)
                message = _message(exc)
                self._soon(lambda: self._fit_ended(material, None, message))
                return
            self._soon(lambda: self._fit_ended(material, result, None))

        thread = threading.Thread(target=run, name="brdf-explorer-fit", daemon=True)
        material.fit_thread = thread
        thread.start()
        return thread

    def _fit_progress(self, material, percent, text):
        if material.fit_thread is None or not material.fit_thread.is_alive():
            return  # a late update from a fit that has ended
        material.fit_progress.param.update(value=percent, active=False)
        material.fit_status.object = text

    def _fit_ended(self, material, result, message):
        material.fit_button.disabled = False
        material.fit_progress.param.update(visible=False, active=False)
        if result is None:
            material.fit_status.object = ""
            self.error.object, self.error.visible = message, True
            return
        fitted = self.add(result.model)
        fitted.fit = result
        warnings = f" ({len(result.warnings)} warnings)" if result.warnings else ""
        material.fit_status.object = (
            f"fitted in {result.timing['total_s']:.1f} s: loss {result.loss:.4g}, "
            f"verdict {result.verdict}{warnings}; shown as material {len(self.materials)}")
        self.update()

    def _refine(self, models, token, lighting="key"):
        """Path trace the shown materials' spheres, then objects, under ``lighting`` in a
        background thread; they replace the previews unless another update came first
        (``token``). Returns the thread."""
        import threading

        def run():
            # the spheres first (a quarter of the time): they replace their previews sooner
            for name, render in (("sphere", view_data.sphere_render),
                                 ("object", view_data.object_render)):
                if token != self._refines:
                    return  # superseded: its own refinement follows
                try:
                    images = [view_data.to_rgba(render(m, SPHERE_SIZE, REFINE_SPP,
                                                       lighting=lighting))
                              for m in models]
                except Exception as exc:  # noqa: BLE001  (the preview stays; the page says why)
                    message = _message(exc)
                    self._soon(lambda: self._refined(token, name, None, message))
                    return
                self._soon(lambda name=name, images=images:
                           self._refined(token, name, images, None))

        thread = threading.Thread(target=run, name="brdf-explorer-refine", daemon=True)
        thread.start()
        return thread

    def _refined(self, token, name, images, message):
        if token != self._refines:
            return  # a slider moved on since: that update's own refinement follows
        view, source = ((self.sphere, self.sphere_source) if name == "sphere"
                        else (self.object_view, self.object_source))
        if images is None:
            view.title.text = f"lit {name} (direct light; path tracing failed: {message})"
            return
        source.data = dict(source.data, image=images)
        view.title.text = f"lit {name} (path traced, {REFINE_SPP} spp)"

    def _slider_callback(self, material, slider):
        def moved(event):
            value = 10.0 ** event.new if slider.log else event.new
            try:
                # "value" while the slider moves, "value_throttled" once it is let go
                self.set_parameter(material, slider.name, value, draft=event.name == "value")
            except Exception as exc:  # noqa: BLE001  (the page says it; the server stays up)
                self.error.object, self.error.visible = _message(exc), True
        return moved

    def _drag_incidence(self, x, y, draft):
        """A tap or a drag at (x, y) in the polar plot: theta_i is the angle of that point from
        the normal, on either side (the curve's incident side is drawn on the left)."""
        if x is None or y is None:
            return
        theta = min(89.0, math.degrees(math.atan2(abs(x), max(y, 0.0))))
        # the slider follows (its step), and its watcher makes the draft update
        self.theta_slider.value = round(theta * 2) / 2
        if not draft:
            self.update()

    def _aim(self, theta, phi, final):
        """The incident arrow dragged on the 3-D lobe to (theta, phi) degrees: both sliders
        follow (at their steps) and the views make one update, a draft until it is let go."""
        theta = min(89.0, max(0.0, round(float(theta) * 2) / 2))
        phi = round(float(phi)) % 360
        self._syncing = True  # the sliders' own watchers would update once each
        try:
            self.theta_slider.value, self.phi_slider.value = theta, float(phi)
        finally:
            self._syncing = False
        self.theta_i, self.phi_i = theta, float(phi)
        self.update(draft=not final)

    def _incidence(self, theta=None, phi=None, draft=False):
        if getattr(self, "_syncing", False):
            return
        if theta is not None:
            self.theta_i = float(theta)
        if phi is not None:
            self.phi_i = float(phi)
        self.update(draft)

    def set_lighting(self, lighting, update=True):
        """Light the sphere and the object with ``"key"`` (the key light and a uniform
        environment), ``"sky"`` (the bundled sky map) or ``"map"`` (the map given to
        :meth:`set_environment`), and update."""
        if lighting not in self._lighting_options.values():
            raise InputError(f"lighting {lighting!r}: expected one of "
                             f"{', '.join(self._lighting_options.values())}"
                             + ("" if self.environment is not None else
                                " ('map' once an environment map is loaded)"))
        self.lighting = lighting
        label = next(k for k, v in self._lighting_options.items() if v == lighting)
        if self.lighting_select.value != label:
            self._syncing_lighting = True
            try:
                self.lighting_select.value = label
            finally:
                self._syncing_lighting = False
        if update:
            self.update()

    def _option(self, **changes):
        for key, value in changes.items():
            setattr(self, key, bool(value))
        self.update()

    def _visibility(self, material, **changes):
        for key, value in changes.items():
            setattr(material, key, bool(value))
        self.update()

    def _add_glyphs(self, material):
        from bokeh.models import ColumnDataSource
        material.polar_source = ColumnDataSource({"x": [], "y": []},
                                                 name=f"polar-{len(self.materials) - 1}")
        material.albedo_source = ColumnDataSource({"theta": [], "a": [], "low": [], "high": []},
                                                  name=f"albedo-{len(self.materials) - 1}")
        material.polar_glyph = self.polar.line("x", "y", source=material.polar_source,
                                               line_color=material.colour, line_width=2)
        material.samples_source = ColumnDataSource({"x": [], "y": []},
                                                   name=f"samples-{len(self.materials) - 1}")
        material.samples_glyph = self.polar.scatter("x", "y", source=material.samples_source,
                                                    line_color=material.colour,
                                                    fill_color=None, size=6)
        material.albedo_band = self.albedo.varea("theta", "low", "high",
                                                 source=material.albedo_source,
                                                 fill_color=material.colour, fill_alpha=0.2)
        material.albedo_glyph = self.albedo.line("theta", "a", source=material.albedo_source,
                                                 line_color=material.colour, line_width=2)

    def _draw(self, data, shown):
        from .lobe_canvas import ARROW, lobe_entry
        wi = incidence(self.theta_i, self.phi_i)
        self.polar.title.text = "in-plane: r = " + ("f cos(theta_o)" if self.cosine else "f") \
            + (" (log)" if self.log else "")
        images, objects, xs, lobes, triangles = [], [], [], [], None
        peak = max([d["lobe"][3] for d in data.values()], default=1.0)
        top = 1.0
        curves = [d["polar"][1].mean(axis=-1) for d in data.values()]
        curves += [d["samples"][1].mean(axis=-1) for d in data.values()
                   if "samples" in d and len(d["samples"][0])]
        polar_peak = max([float(np.nanmax(c)) for c in curves] + [1e-300])
        for m in self.materials:
            on = m in shown
            m.polar_glyph.visible = m.albedo_glyph.visible = m.albedo_band.visible = on
            m.samples_glyph.visible = on
            if not on:
                continue
            d = data[id(m)]
            angles, f = d["polar"]
            r = f.mean(axis=-1)
            r = view_data.lobe_radius(np.maximum(np.nan_to_num(r), 0.0), polar_peak, self.log)
            signed = np.radians(angles)
            # the incident side on the left: x = sin(signed theta_o), as in brdf.viz.inplane_plot
            m.polar_source.data = {"x": r * np.sin(signed), "y": r * np.cos(signed)}
            if "samples" in d:
                angles, f = d["samples"]
                r = view_data.lobe_radius(np.maximum(f.mean(axis=-1), 0.0), polar_peak,
                                          self.log)
                signed = np.radians(angles)
                m.samples_source.data = {"x": r * np.sin(signed), "y": r * np.cos(signed)}
            thetas, a = d["albedo"]
            top = max(top, float(np.nanmax(a)))
            m.albedo_source.data = {"theta": thetas, "a": a.mean(axis=-1),
                                    "low": a.min(axis=-1), "high": a.max(axis=-1)}
            # every lobe to the scale of the largest, as BRDF Explorer draws them
            _, triangles, values, _, directions = d["lobe"]
            points = directions * view_data.lobe_radius(values, peak, self.log)[:, None]
            lobe = lobe_entry(points, m.colour)
            if "near" in d:  # measured samples at the incidence, on the same scale
                wo, f = d["near"]
                r = view_data.lobe_radius(np.maximum(np.nan_to_num(f.mean(axis=-1)), 0.0),
                                          peak, self.log)
                lobe["samples"] = lobe_entry(wo * r[:, None], m.colour)["points"]
            lobes.append(lobe)
            images.append(view_data.to_rgba(d["sphere"]))
            objects.append(view_data.to_rgba(d["object"]))
            xs.append(float(len(xs)))
        self.albedo.y_range.end = 1.08 * top
        self.albedo_marker.location = self.theta_i
        incident = {"x": [0.0, -1.1 * math.sin(math.radians(self.theta_i))],
                    "y": [0.0, 1.1 * wi[2]]}
        if incident != self.incident_source.data:  # Bokeh would send it again
            self.incident_source.data = incident
        changes = {"lobes": lobes, "incident": (ARROW * wi).tolist()}
        if triangles is not None and len(triangles) * 3 != len(self.lobe.triangles):
            # sent when the grid changes (a draft's is coarser), with the points it indexes
            changes["triangles"] = triangles.ravel().tolist()
        self.lobe.param.update(**changes)
        count = max(len(images), 1)
        self.sphere.x_range.end = count
        self.sphere.frame_width = SPHERE_PIXELS * count
        self.sphere_source.data = {"image": images, "x": xs, "dw": [1.0] * len(images)}
        self.sphere.title.text = "lit sphere (direct light)"
        self.object_view.x_range.end = count
        self.object_view.frame_width = SPHERE_PIXELS * count
        self.object_source.data = {"image": objects, "x": xs, "dw": [1.0] * len(objects)}
        self.object_view.title.text = "lit object (direct light)"

    def _draw_slice(self, material, image):
        if image is None:
            self.slice_source.data = {"image": []}
            self.slice.title.text = "theta_h / theta_d slice"
            return
        f = image.mean(axis=-1)
        f = np.where(f > 0, f, np.nan)  # a log scale has no place for f <= 0: grey
        peak = float(np.nanmax(f)) if np.isfinite(f).any() else 1.0
        # the top of the colours at the peak rounded up to a step of SLICE_STEP decades: a new
        # range makes the page lay out the colour bar again (15-20 ms in headless chromium),
        # so a slider's move changes it only when the peak crosses a step
        high = 10.0 ** (math.ceil(math.log10(peak) / SLICE_STEP - 1e-9) * SLICE_STEP)
        if (self.slice_mapper.low, self.slice_mapper.high) != (high * 10.0 ** -SLICE_DECADES,
                                                               high):
            self.slice_mapper.update(low=high * 10.0 ** -SLICE_DECADES, high=high)
        self.slice_source.data = {"image": [f]}
        # the material by number: a title that changes length as a slider moves would have
        # the page lay the figure out again at every move
        number = next(k for k, m in enumerate(self.materials) if m is material) + 1
        self.slice.title.text = f"slice of material {number}, phi_d = {self.phi_d:g}"

    def _repr_mimebundle_(self, include=None, exclude=None):
        return self.layout._repr_mimebundle_(include, exclude)


class Server:
    """The explorer served on ``localhost``: every browser tab gets its own :class:`Explorer`
    on the same materials (listed in ``explorers``, newest last).

    Attributes
    ----------
    url : str
        The page's address.
    explorers : list of Explorer
    """

    def __init__(self, materials, port=0, show=True, threaded=True, environment=None):
        pn = require_panel()
        self.materials = [material_from(m) for m in materials]
        # read once, before serving: a bad map is refused here, not in every tab
        self.environment = None
        if environment is not None:
            label = (os.path.basename(os.fspath(environment))
                     if isinstance(environment, (str, os.PathLike)) else "array")
            self.environment = label, view_data.environment_map(environment)
        self.explorers = []
        # Bokeh's and Panel's scripts come from this server, never from a CDN
        os.environ["BOKEH_RESOURCES"] = "server"
        self.port = _bindable(int(port)) if port else _free_port()
        self.url = f"http://localhost:{self.port}/"
        self.server = pn.serve(self._session, port=self.port, show=show, threaded=threaded,
                               title="brdf explorer", address="localhost",
                               websocket_origin=f"localhost:{self.port}", verbose=False)
        if threaded:
            _wait_for(self.port)

    def _session(self):
        pn = require_panel()
        label, radiance = self.environment or (None, None)
        explorer = Explorer(self.materials, environment=radiance, environment_label=label)
        self.explorers.append(explorer)
        doc = pn.state.curdoc
        pn.state.onload(lambda: _send_at_once(doc))
        return explorer.layout

    def stop(self):
        """Stop serving (a threaded server)."""
        self.server.stop()


def _send_at_once(doc):
    """Have the websocket of ``doc``'s session send each message at once (TCP_NODELAY).

    Tornado leaves Nagle's algorithm on: an update's message, written while the page has not
    yet acknowledged the server's previous small reply, waited for the page's delayed ACK
    (40 ms on Linux), which was most of the time from a slider's move to the redrawn views
    when moves follow each other (benchmarks/bench_explore.py). Panel and Bokeh offer no
    setting for it; their session's connections are reached as Panel itself reaches them,
    and nothing is changed when that fails."""
    session = getattr(getattr(doc, "session_context", None), "session", None)
    for connection in getattr(session, "_subscribed_connections", ()):
        socket = getattr(connection, "_socket", None)
        try:
            socket.set_nodelay(True)
        except Exception:  # noqa: BLE001  (a closed or other socket: it stays as it was)
            pass


def _wait_for(port, timeout=60.0):
    """Return once ``localhost:port`` accepts connections (a threaded server binds in its own
    thread, after :func:`panel.serve` returns)."""
    import socket
    end = time.monotonic() + timeout
    while True:
        try:
            socket.create_connection(("localhost", port), timeout=1.0).close()
            return
        except OSError:
            if time.monotonic() > end:
                raise InputError(f"the explorer's server did not start on port {port} "
                                 f"within {timeout:g} s") from None
            time.sleep(0.05)


def _bindable(port):
    """``port``, or :class:`~brdf.errors.InputError` when this machine cannot serve on it."""
    import socket
    with socket.socket() as s:
        try:
            s.bind(("localhost", port))
        except OSError as exc:
            raise InputError(f"--port {port}: cannot serve there ({exc.strerror}); choose "
                             "another port or leave --port out for a free one") from None
    return port


def _free_port():
    import socket
    with socket.socket() as s:
        s.bind(("localhost", 0))
        return s.getsockname()[1]


def explore(*materials, port=None, show=True, environment=None):
    """Open the explorer on ``materials`` (models, tables, specs or paths) in a local web page,
    its previews lit by ``environment`` when given (a lat-long OpenEXR path or a radiance
    array: :meth:`Explorer.set_environment`).

    In a script: serves the page in a background thread on ``port`` (default: a free one),
    opens it in the browser when ``show``, and returns the :class:`Server` (``.url``,
    ``.stop()``). In Jupyter: ``port=False`` returns an :class:`Explorer` to display in the
    notebook instead of a server.
    """
    if port is False:
        return Explorer(materials, environment=environment)
    return Server(materials, port=port or 0, show=show, environment=environment)
